"""estimate on points in 3-D: pairs from mu,nu or u,v columns (or --mu with --nu)."""

import numpy as np
import pytest

from depthcore.cli.main import FRAMES_MAX
from depthcore.registry import online, track_runs
from depthcore.registry.filters import FILTERS

from helpers import cli_json, cli_refused, run_cli

# a point at (x, y, v, h, w) = (-2, 10, 0.5, 1.5, -0.1) seen for 8 frames at unit steps
E = np.arange(8.0)
PAIRS = np.stack([-2.0 + 0.5 * E, 1.5 - 0.1 * E], axis=-1) / (10.0 + E)[:, None]
PAIRS = PAIRS + 0.002 * np.random.default_rng(7).standard_normal(PAIRS.shape)
RHO = 0.002
FOCAL, CX, CY = 500.0, 320.0, 240.0
PRIOR = ["--prior-mean", "-2", "10", "0", "1", "0", "--prior-cov", "4"]


def _file(tmp_path, text, name="pairs.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8", newline="")
    return str(path)


def _mu_nu(pairs) -> str:
    return "mu,nu\n" + "".join(
        ",\n" if np.isnan(m) else f"{m!r},{n!r}\n" for m, n in pairs.tolist()
    )


def _pixels(pairs) -> str:
    return "frame,u,v\n" + "".join(
        f"{k + 1},,\n" if np.isnan(m) else f"{k + 1},{CX + FOCAL * m!r},{CY + FOCAL * n!r}\n"
        for k, (m, n) in enumerate(pairs.tolist())
    )


# --- the summary ------------------------------------------------------------------------------


def test_a_pairs_file_gives_each_filters_five_coordinates(tmp_path, capsys):
    out = cli_json(
        ["estimate", "--mu-file", _file(tmp_path, _mu_nu(PAIRS)), "--rho", "0.002", *PRIOR], capsys
    )
    mean, cov = np.array([-2.0, 10.0, 0.0, 1.0, 0.0]), 4.0 * np.eye(5)
    assert out["coordinates"] == ["x", "y", "v", "h", "w"] and out["prior_mean"] == mean.tolist()
    assert list(out["filters"]) == list(track_runs.spatial_names())
    for name in out["filters"]:
        est = FILTERS[name](PAIRS, RHO, mean, cov)
        for key, i in track_runs.SPACE:
            assert out["filters"][name][key]["mean"] == est.mean[i]
            assert out["filters"][name][key]["sd"] == np.sqrt(est.cov[i, i])
    # the same pairs from pixels, and from --mu with --nu
    pixels = _file(tmp_path, _pixels(PAIRS), "pixels.csv")
    argv = ["estimate", "--mu-file", pixels, "--focal", "500", "--cx", "320", "--cy", "240"]
    from_pixels = cli_json([*argv, "--rho", "0.002", *PRIOR], capsys)
    d = (
        from_pixels["filters"]["optimal"]["height"]["mean"]
        - out["filters"]["optimal"]["height"]["mean"]
    )
    assert abs(d) < 1e-9
    values = ["--mu", *map(repr, PAIRS[:, 0].tolist()), "--nu", *map(repr, PAIRS[:, 1].tolist())]
    assert (
        cli_json(["estimate", *values, "--rho", "0.002", *PRIOR], capsys)["filters"]
        == out["filters"]
    )


def test_the_default_prior_of_pairs_is_the_planes_rule_and_the_height_on_the_first_sight(
    tmp_path, capsys
):
    out = cli_json(
        ["estimate", "--mu-file", _file(tmp_path, _mu_nu(PAIRS)), "--rho", "0.002"], capsys
    )
    c = PAIRS[:3, 0]
    y1 = 2 * (c[0] - c[1]) / (c[0] + c[2] - 2 * c[1]) - 2  # Eq. (7)'s c2, moved to frame 1
    assert out["prior_mean"][1] == pytest.approx(y1, rel=1e-12)
    assert out["prior_mean"][3] == pytest.approx(PAIRS[0, 1] * y1, rel=1e-12)
    assert out["prior_mean"][4] == 0.0 and out["prior_mean"][2] == 0.0
    assert out["prior_cov"] == (1000.0 * np.eye(5)).tolist()
    assert out["c"][1] == pytest.approx(y1 + 2, rel=1e-12)


def test_prior_depth_with_pairs_puts_x_and_h_on_the_first_line_of_sight(tmp_path, capsys):
    path = _file(tmp_path, _mu_nu(PAIRS))
    out = cli_json(
        ["estimate", "--mu-file", path, "--rho", "0.002", "--prior-depth", "12", "3"], capsys
    )
    assert out["prior_mean"] == [PAIRS[0, 0] * 12.0, 12.0, 0.0, PAIRS[0, 1] * 12.0, 0.0]
    assert np.diag(out["prior_cov"]).tolist() == [1000.0, 9.0, 1000.0, 1000.0, 1000.0]


def test_the_table_names_the_height_and_its_velocity(tmp_path, capsys):
    path = _file(tmp_path, _mu_nu(PAIRS))
    status, out, err = run_cli(["estimate", "--mu-file", path, "--rho", "0.002", *PRIOR], capsys)
    assert status == 0 and err == ""
    assert "mean (x, y, v, h, w) = (-2.000, 10.00, 0.000, 1.000, 0.000)" in out
    assert "height mean  height sd vert. vel. mean vert. vel. sd" in out
    assert "height mean, sd       the same of the height h" in out
    status, plane, _ = run_cli(
        ["estimate", "--mu", *map(repr, PAIRS[:, 0].tolist()), "--rho", "0.002"], capsys
    )
    assert status == 0 and "height" not in plane


def test_with_gaps_steps_and_a_rho_column_the_filters_take_them(tmp_path, capsys):
    pairs = PAIRS.copy()
    pairs[4] = np.nan
    steps = np.array([1.0, 2.0, 1.0, 1.0, 0.5, 1.0, 1.0])
    rho = np.linspace(0.002, 0.004, 8)
    text = "mu,nu,rho,step\n" + "".join(
        f"{'' if np.isnan(m) else repr(m)},{'' if np.isnan(n) else repr(n)},"
        f"{'' if np.isnan(m) else repr(r)},{'' if k == 0 else repr(steps.tolist()[k - 1])}\n"
        for k, ((m, n), r) in enumerate(zip(pairs.tolist(), rho.tolist(), strict=True))
    )
    path = _file(tmp_path, text)
    out = cli_json(["estimate", "--mu-file", path, "--direction", "approaching", *PRIOR], capsys)
    est = FILTERS["ekf"](pairs, rho, [-2, 10, 0, 1, 0], 4 * np.eye(5), steps=-steps)
    assert out["filters"]["ekf"]["depth"]["mean"] == est.mean[1]
    assert out["steps"] == (-steps).tolist() and out["mu"][4] is None
    assert out["c"] is None and "receding" in out["c_reason"]


# --- frame by frame ----------------------------------------------------------------------------


@pytest.mark.parametrize("gate", [None, "0.01"])
def test_per_frame_streams_pairs_through_the_online_filters(tmp_path, capsys, gate):
    pairs = PAIRS.copy()
    pairs[5] += [0.05, 0.0]  # an outlier
    path = _file(tmp_path, _mu_nu(pairs))
    base = ["estimate", "--mu-file", path, "--rho", "0.002", *PRIOR, "--per-frame"]
    argv = [*base, "--filters", "ekf", "ukf"] + ([] if gate is None else ["--gate", gate])
    out = cli_json(argv, capsys)
    assert out["smoothed"] is False and "do not smooth" in out["smoothed_reason"]
    for name in ("ekf", "ukf"):
        live = online.start(name, [-2, 10, 0, 1, 0], 4 * np.eye(5), RHO, 0.0, gate and float(gate))
        for k, pair in enumerate(pairs):
            est = live.update(pair)
            row = out["filters"][name][k]
            assert row["nu"] == pair[1] and row["gated"] == est.gated
            assert row["filtered_height_mean"] == est.mean[3]
            assert row["filtered_vertical_velocity_sd"] == np.sqrt(est.cov[4, 4])
        assert out["filters"][name][5]["gated"] == (gate is not None)
    status, table, _ = run_cli([*base, "--filters", "optimal"], capsys)
    assert status == 0 and "height filtered vert. vel. filtered" in table and "nu" in table
    status, text, _ = run_cli([*base, "--csv"], capsys)
    assert status == 0 and text.splitlines()[0].startswith("filter,frame,bearing,mu,nu,rho")


def test_a_long_file_of_pairs_streams_past_the_held_limit(tmp_path, capsys):
    n = FRAMES_MAX + 5
    e = np.arange(n, dtype=float)
    pairs = np.stack([-2.0 + 0.5 * e, 1.5 - 0.1 * e], axis=-1) / (10.0 + e)[:, None]
    path = _file(tmp_path, _mu_nu(pairs))
    argv = ["estimate", "--mu-file", path, "--rho", "0.002", *PRIOR, "--per-frame"]
    out = cli_json([*argv, "--filters", "ekf"], capsys)
    assert out["frames"] == n and len(out["filters"]["ekf"]) == n
    assert out["filters"]["ekf"][-1]["filtered_height_mean"] == pytest.approx(
        1.5 - 0.1 * (n - 1), rel=1e-3
    )
    cli_refused(argv[:-1], capsys, "more than 1000 frames")


# --- refusals ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--prior-mean", "0", "10", "0"], "--prior-mean takes 5 numbers X Y V H W for pairs"),
        (
            ["--prior-cov", *["1", "0", "0", "0", "1", "0", "0", "0", "1"]],
            "--prior-cov takes 1 value (S I) or 25",
        ),
        (["--smooth", "--per-frame"], "--smooth: --per-frame streams pairs"),
        (["--gate", "0.01"], "--gate: the summary of pairs (a point in 3-D) has no gate"),
        (["--filters", "second_order"], "--filters: second_order takes no pairs (a point in 3-D)"),
        (["--filters", "ekf", "particle"], "--filters: particle takes no pairs"),
        (["--filters", "ekf", "ekf"], "--filters names ekf more than once"),
        (["--per-frame", "--filters", "iterated"], "--filters: iterated has no smoother"),
        (["--prior-cov", "-1"], "--prior-cov must be positive definite"),
        (["--prior-mean", "0", "10", "0", "1", "inf"], "--prior-mean must be finite"),
        (["--prior-mean", "0", "10", "0", "1", "1e9"], "--prior-mean must be at most 1000"),
    ],
)
def test_what_pairs_cannot_have_is_refused_in_one_line(tmp_path, capsys, extra, words):
    path = _file(tmp_path, _mu_nu(PAIRS))
    cli_refused(["estimate", "--mu-file", path, "--rho", "0.002", *extra], capsys, words)


def test_learning_from_pairs_is_refused_by_name(tmp_path, capsys):
    path = _file(tmp_path, _mu_nu(PAIRS))
    cli_refused(
        ["estimate", "--mu-file", path, "--learn-noise"],
        capsys,
        "--learn-noise learns from the plane",
    )


@pytest.mark.parametrize(
    "argv, words",
    [
        (
            ["--mu", "0.1", "0.2", "0.35", "--rho", "1", "--prior-mean", "1", "2", "3", "4", "5"],
            "--prior-mean takes 3 numbers X Y V, got 5 (a nu or v column",
        ),
        (
            ["--mu", "0.1", "0.2", "0.35", "--rho", "1", "--prior-cov", *["1"] * 25],
            "--prior-cov takes 1 value (S I) or 9",
        ),
        (
            ["--mu", "0.1", "0.2", "0.3", "--nu", "0", "0", "--rho", "1"],
            "--nu takes one vertical bearing per --mu (3), got 2",
        ),
        (
            ["--mu", "0.1", "nan", "0.3", "0.4", "--nu", "0", "0", "0", "0", "--rho", "1"],
            "--nu must be nan exactly where --mu is",
        ),
        (
            ["--mu", "0.1", "0.2", "0.3", "--nu", "0", "0", "inf", "--rho", "1"],
            "--nu must be finite",
        ),
        (
            ["--mu", "0.1", "0.2", "0.3", "--nu", "0", "0", "1e300", "--rho", "1"],
            "--nu must be finite (or nan) and at most 1e+06",
        ),
        (["--mu", "0.1", "0.2", "0.3", "--cy", "3", "--rho", "1"], "--cy: not used by --mu"),
        (["--mu-file", "-", "--nu", "0", "--rho", "1"], "--nu: not used by --mu-file"),
    ],
)
def test_the_options_of_pairs_are_refused_in_one_line_naming_them(capsys, argv, words):
    cli_refused(["estimate", *argv], capsys, words)


@pytest.mark.parametrize(
    "text, flags, words",
    [
        (
            "u,v\n1,1\n2,2\n3,4\n",
            ["--focal", "1", "--cx", "0"],
            "a v column (pixel rows) needs --cy",
        ),
        ("u\n1\n2\n3\n", ["--focal", "1", "--cx", "0", "--cy", "0"], "--cy is for a v column"),
        ("mu\n1\n2\n3\n", ["--cy", "0"], "--cy is for a v column (pixel rows), with focal and cx"),
        ("mu,nu\n0.1,0\n0.2,\n0.3,0\n", [], ":3: a pair has one coordinate only"),
        (
            "u,v\n1,1\n2,abc\n3,4\n",
            ["--focal", "1", "--cx", "0", "--cy", "0"],
            ":3: v must be a number",
        ),
        (
            "u,v\n1,1\n2,2\n3,4\n",
            ["--focal", "1", "--cx", "0", "--cy", "inf"],
            "--cy must be finite",
        ),
    ],
)
def test_a_file_of_pairs_and_its_options_are_refused_in_one_line(
    tmp_path, capsys, text, flags, words
):
    path = _file(tmp_path, text)
    cli_refused(["estimate", "--mu-file", path, "--rho", "0.01", *flags], capsys, words)
