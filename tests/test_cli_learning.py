"""estimate --learn-noise on real tracks: the gate while learning, the profile likelihood's
intervals, a rho column's scale, --prior-depth, and why the noise-free state c is undefined."""

import numpy as np
import pytest

from depthcore.cli import text as cli_text
from depthcore.exact import learning
from depthcore.registry import track_runs, tracking
from depthcore.registry.filters import FILTERS

from helpers import cli_json, cli_refused, run_cli

E = np.arange(30.0)
CLEAN = (-2.0 + 0.5 * E) / (10.0 + E) + 0.002 * np.random.default_rng(0).standard_normal(30)
OUTLIERS = [13, 21]  # rows 14 and 22: 20 SDs off
MU = CLEAN.copy()
MU[OUTLIERS] += [0.04, -0.04]
FRAMES = 101 + np.arange(30)
TIMES = 0.25 * E  # at --speed 4: unit steps, exactly


def _file(tmp_path, mu, rho=None):
    """A track file with the frame numbers and times of FRAMES and TIMES."""
    head = "frame,time,mu" + ("" if rho is None else ",rho")
    rows = [
        f"{f},{t!r},{m!r}" + ("" if rho is None else f",{r!r}")
        for f, t, m, r in zip(
            FRAMES.tolist(), TIMES.tolist(), mu.tolist(), (rho or [0] * 30), strict=True
        )
    ]
    path = tmp_path / "track.csv"
    path.write_text("\n".join([head, *rows]) + "\n")
    return ["--mu-file", str(path), "--direction", "receding", "--speed", "4"]


def test_the_gate_keeps_outliers_out_of_the_fit_and_names_them_by_the_files_frames(
    tmp_path, capsys
):
    track = _file(tmp_path, MU)
    rho_only = ["--learn-noise", "--process-noise", "0"]
    out = cli_json(["estimate", *track, *rho_only, "--gate", "0.01"], capsys)
    gated = out["learned"]
    assert gated["gate_skipped"] == FRAMES[OUTLIERS].tolist()
    assert gated["gate_skipped_times"] == TIMES[OUTLIERS].tolist()
    # without the gate the two outliers inflate rho, which the gate's fit does not
    ungated = cli_json(["estimate", *track, *rho_only], capsys)["learned"]
    prior = tracking.default_prior(CLEAN)
    clean = learning.fit(CLEAN, prior.mean, prior.cov, process_noise=0.0)
    assert ungated["rho"] > 5 * gated["rho"] and "gate_skipped" not in ungated
    assert abs(gated["rho"] - clean.rho) < 0.2 * clean.rho
    text = cli_text.format_learned(out)
    assert "learning's gate skipped frames: 114 (t = 3.25 s), 122 (t = 5.25 s)" in text


def test_the_intervals_are_the_profile_likelihoods_and_the_output_says_so(capsys):
    mu = CLEAN[:12]
    learned = cli_json(["estimate", "--mu", *map(repr, mu.tolist()), "--learn-noise"], capsys)
    learned = learned["learned"]
    prior = tracking.default_prior(mu)
    profile = learning.fit(mu, prior.mean, prior.cov, intervals="profile")
    wald = learning.fit(mu, prior.mean, prior.cov, intervals="wald")
    assert learned["intervals"] == "profile"
    assert learned["rho_interval"] == list(profile.rho_interval)
    assert learned["rho_interval"] != list(wald.rho_interval)
    # q at the boundary 0: the profile likelihood's interval reaches it
    assert learned["process_noise"] == 0.0 and learned["process_noise_interval"][0] == 0.0
    assert learned["process_noise_interval"] == list(profile.process_noise_interval)
    text = cli_text.format_learned({"learned": learned})
    assert "rho = " in text and "95% profile-likelihood interval" in text
    assert "q = 0 (at 0; 95% profile-likelihood upper bound" in text


def test_a_rho_column_is_scaled_and_the_scale_is_named_so(tmp_path, capsys):
    column = np.where(E % 2 == 0, 0.002, 0.004)
    mu = (-2.0 + 0.5 * E) / (10.0 + E) + 1.5 * column * np.random.default_rng(1).standard_normal(30)
    track = _file(tmp_path, mu, column.tolist())
    out = cli_json(["estimate", *track, "--learn-noise", "--process-noise", "0"], capsys)
    learned = out["learned"]
    prior = tracking.default_prior(mu)
    fit = learning.fit(mu, prior.mean, prior.cov, process_noise=0.0, weights=column)
    assert "rho" not in learned and learned["rho_column_scale"] == fit.rho
    assert learned["estimated"] == ["rho_column_scale"]
    assert out["rho"] == (fit.rho * column).tolist()  # the filters ran with the scaled column
    assert cli_text.format_learned(out).startswith(
        f"learned by maximum likelihood: rho column scale = {fit.rho:.4g} ± {fit.rho_se:.2g}"
    )


# --- a prior on the depth, and the noise-free state c ---------------------------------------


def test_prior_depth_is_a_range_prior_on_the_depth_used_by_filters_and_learning(capsys):
    argv = ["estimate", "--mu", *map(repr, CLEAN.tolist()), "--prior-depth", "12", "3"]
    out = cli_json([*argv, "--learn-noise", "--process-noise", "0"], capsys)
    mean, cov = [CLEAN[0] * 12.0, 12.0, 0.0], np.diag([1000.0, 9.0, 1000.0])
    assert out["prior_mean"] == mean and out["prior_cov"] == cov.tolist()
    fit = learning.fit(CLEAN, mean, cov, process_noise=0.0)
    assert out["learned"]["rho"] == fit.rho
    est = FILTERS["ekf"](CLEAN, fit.rho, mean, cov, fit.process_noise)
    assert out["filters"]["ekf"]["depth"]["mean"] == float(est.depth_mean)


TWO = ["--filters", "optimal", "ekf"]


@pytest.mark.parametrize(
    "mu, why",
    [
        (["0.1", "0.2", "0.3", "0.5", "0.6"], "mu is degenerate"),
        (["0.3", "0.1", "0.2", "0.3", "0.35"], "mu puts the point behind the camera"),
        (["0.3", "nan", "0.1", "0.2", "0.3"], "(frames 1, 3, 4) put the point behind the camera"),
    ],
)
def test_where_c_is_undefined_the_refusal_says_why_and_offers_both_priors(capsys, mu, why):
    for extra in (["--rho", "0.01"], ["--learn-noise"], ["--rho", "0.01", "--per-frame"]):
        cli_refused(
            ["estimate", "--mu", *mu, *extra],
            capsys,
            "--prior-mean or --prior-depth MEAN SD is needed",
            "no noise-free state c",
            why,
        )
    out = cli_json(
        ["estimate", "--mu", *mu, "--rho", "0.01", "--prior-depth", "5", "2", *TWO], capsys
    )
    assert out["c"] is None and out["c_reason"] == track_runs.noise_free(np.array(mu, float))[1]
    status, text, _ = run_cli(
        ["estimate", "--mu", *mu, "--rho", "0.01", "--prior-depth", "5", "2", *TWO], capsys
    )
    assert status == 0 and f"= undefined: {out['c_reason']}" in text.splitlines()[0]


def test_the_refusal_names_the_files_frames(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("frame,mu\n7,0.3\n9,0.1\n10,0.2\n11,0.3\n")
    cli_refused(["estimate", "--mu-file", str(path), "--rho", "0.01"], capsys, "(frames 7, 9, 10)")


@pytest.mark.parametrize(
    "extra, words",
    [
        (
            ["--prior-depth", "0", "1"],
            "--prior-depth takes the depth's mean (> 0) and SD (at least 1e-06)",
        ),
        (["--prior-depth", "5", "0"], "--prior-depth takes the depth's mean"),
        (["--prior-depth", "5", "1e-9"], "--prior-depth takes the depth's mean"),
        (["--prior-depth", "5", "nan"], "--prior-depth must be finite"),
        (["--prior-depth", "1e300", "1"], "--prior-depth must be at most 1000"),
        (["--prior-depth", "5", "abc"], "--prior-depth takes MEAN SD as numbers"),
        (["--prior-depth", "5"], "--prior-depth takes MEAN SD, got 1 value"),
        (
            ["--prior-depth", "5", "1", "--prior-mean", "0", "5", "0"],
            "--prior-depth: a prior of its own",
        ),
        (["--prior-depth", "5", "1", "--prior-cov", "3"], "--prior-depth: a prior of its own"),
        (["--prior-depth", "5", "1", "--prior-depth", "5", "1"], "given more than once"),
    ],
)
def test_prior_depth_is_refused_in_one_line_naming_it(capsys, extra, words):
    cli_refused(["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.01", *extra], capsys, words)


def test_a_fit_that_finds_no_maximum_is_refused_in_one_line_and_a_converged_one_is_not(capsys):
    """Five bearings leave the likelihood unbounded as rho -> 0 (q takes every bearing):
    the command says so instead of filtering with rho near 0; thirty bearings fit."""
    few = ["estimate", "--mu", "0.3", "0.1", "0.2", "0.3", "0.35", "--learn-noise"]
    cli_refused([*few, "--prior-depth", "3", "2"], capsys, "--learn-noise", "no maximum")
    fit = cli_json(["estimate", "--mu", *map(repr, CLEAN.tolist()), "--learn-noise"], capsys)
    assert fit["learned"]["converged"] and 0.001 < fit["learned"]["rho"] < 0.004


def test_the_learned_noise_text_reads_a_missing_interval_as_none():
    fit = {"level": 0.95, "intervals": "profile", "estimated": ["rho", "process_noise"]}
    fit |= {"rho": 0.002, "rho_se": None, "rho_interval": None}
    fit |= {"process_noise": 0.01, "process_noise_se": None, "process_noise_interval": None}
    text = cli_text.format_learned({"learned": fit})
    assert "rho = 0.002 (no interval)" in text and "q = 0.01 (no interval)" in text
