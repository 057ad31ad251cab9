"""Tests of the self-calibration (simulation-based calibration) of the optimal filter."""

import numpy as np
import pytest

from depthbook import beyond_study
from depthcore.analysis import calibration
from depthcore.cli import text as cli_text
from depthcore.problem import model
from depthcore.studies import scores

PRIOR_MEAN = np.array([-1.2, 4.0, 0.0])
PRIOR_COV = np.diag([1.0, 1.0, 0.25])
RHO = 1 / 200


def test_draws_come_from_the_prior_in_front_of_the_camera():
    """Truths at time 3 are G^2 of prior draws with y_1 > 0, and their bearings are Eq. (4)'s."""
    d = calibration.draw_from_prior(
        PRIOR_MEAN, 4.0 * np.eye(3), RHO, 4000, np.random.default_rng(0)
    )
    x1 = model.G(d.truth, -2)
    assert np.all(x1[:, 1] > 0)
    assert d.n_behind > 0  # the prior's depth SD is 2 about a mean of 4: about 2 % lie behind
    # The depth's mean is that of a normal N(4, 4) truncated at 0 (closed form).
    from scipy.stats import truncnorm

    assert abs(np.mean(x1[:, 1]) - truncnorm.mean(-2.0, np.inf, loc=4.0, scale=2.0)) < 0.1
    residual = d.mu - model.project(np.stack([model.G(x1, k) for k in range(3)], axis=1))
    assert abs(np.std(residual) / RHO - 1.0) < 0.05


def test_coverage_and_uniformity_definitions():
    """Central intervals: |u - 1/2| <= p/2.

    Uniform PITs cover at the nominal rate; KS rejects a spike.
    """
    u = (np.arange(10_000) + 0.5) / 10_000
    np.testing.assert_allclose(calibration.coverage(u, (0.5, 0.9)), [0.5, 0.9], atol=1e-4)
    assert calibration.uniformity(u)["ks_pvalue"] > 0.99
    assert calibration.uniformity(np.full(100, 0.5))["ks_pvalue"] < 1e-10


def test_the_optimal_filter_is_calibrated_over_its_prior():
    """PIT values of the depth and velocity pass KS and chi-square tests.

    The tests are run at a 0.1 % false-alarm rate.
    """
    r = calibration.self_calibration(PRIOR_MEAN, PRIOR_COV, RHO, 120, np.random.default_rng(1))
    s = r.summary()
    assert s["trials"] > 100
    for q in ("depth", "velocity"):
        assert s[q]["ks_pvalue"] > 1e-3 and s[q]["chi2_pvalue"] > 1e-3


def test_a_miscalibrated_filter_is_caught():
    """A filter that assumes half the true noise is overconfident: its intervals cover too rarely.

    With about a hundred trials the velocity's PIT values fail both tests; the
    depth's 90 % intervals cover under 80 % of the truths.
    """
    r = calibration.self_calibration(
        PRIOR_MEAN, PRIOR_COV, RHO, 120, np.random.default_rng(1), filter_rho=RHO / 2
    )
    s = r.summary()
    assert s["velocity"]["ks_pvalue"] < 1e-3 and s["velocity"]["chi2_pvalue"] < 1e-3
    assert s["depth"]["coverage"][s["levels"].index(0.9)] < 0.8


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"prior_mean": [0.0, 1.0]}, "prior_mean"),
        ({"prior_cov": np.zeros((3, 3))}, "prior_cov"),
        ({"rho": -1.0}, "rho"),
        ({"n": 0}, "trials"),
        ({"rng": 5}, "rng"),
        ({"prior_mean": [0.0, -1e6, 0.0]}, "prior_mean"),
    ],
)
def test_bad_input_is_refused(kwargs, name):
    args = {
        "prior_mean": PRIOR_MEAN,
        "prior_cov": PRIOR_COV,
        "rho": RHO,
        "n": 10,
        "rng": np.random.default_rng(0),
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        calibration.draw_from_prior(**args)


def test_prior_study_reports_coverage_at_every_level_and_the_tests():
    """``study --truth prior``: the fixed prior is the paper's rule at Figure 2's c, 1000 I.

    Coverage at every nominal level is the fraction of PIT values in the central
    interval, with the binomial standard error sqrt(p (1 - p) / n); the verdict
    is the Bonferroni rule at the stated false-alarm rate.
    """
    from depthcore.studies import monte_carlo

    r = monte_carlo.prior_study(trials=60, seed=3, false_alarm=0.05)
    np.testing.assert_allclose(r["prior_mean"], [-1.2, 4.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(r["prior_cov"], 1000.0 * np.eye(3))
    assert r["prior"] == "fixed" and r["truth"] == "prior"
    n = r["valid_trials"]
    assert n + r["rejected_trials"] == 60
    p = np.asarray(r["levels"])
    assert len(p) == len(scores.CALIBRATION_LEVELS)
    np.testing.assert_allclose(r["coverage_se"], np.sqrt(p * (1 - p) / n))
    # The same seed reproduces the PIT values: recompute them through the calibration module.
    prior_mean, prior_cov = np.array(r["prior_mean"]), np.array(r["prior_cov"])
    rng = np.random.default_rng(np.random.SeedSequence(3))
    direct = calibration.self_calibration(prior_mean, prior_cov, RHO, 60, rng)
    for q, pit in (("depth", direct.depth_pit), ("velocity", direct.velocity_pit)):
        np.testing.assert_allclose(r[q]["coverage"], calibration.coverage(pit, p))
        assert r[q]["ks_pvalue"] == calibration.uniformity(pit)["ks_pvalue"]
        assert r[q]["calibrated"] == (min(r[q]["ks_pvalue"], r[q]["chi2_pvalue"]) > 0.025)
        # A calibrated filter: every coverage within 4 binomial SEs of nominal.
        assert np.all(np.abs(np.asarray(r[q]["coverage"]) - p) <= 4 * np.asarray(r["coverage_se"]))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"false_alarm": 1.0}, "false_alarm"),
        ({"prior_scale": 0.0}, "prior_scale"),
        ({"trials": 0}, "trials"),
    ],
)
def test_prior_study_refuses_bad_input(kwargs, name):
    from depthcore.studies import monte_carlo

    with pytest.raises(ValueError, match=name):
        monte_carlo.prior_study(**kwargs)


def test_command_line_truth_prior(capsys):
    """``study --truth prior`` prints the table or JSON; ``--prior paper`` is refused, status 2."""
    import json

    from depthcore.cli.main import main

    assert main(["study", "--truth", "prior", "--trials", "20", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["truth"] == "prior" and len(out["depth"]["coverage"]) == len(out["levels"])
    assert main(["study", "--truth", "prior", "--trials", "20"]) == 0
    text = capsys.readouterr().out
    assert "KS p" in text and "false-alarm rate 0.01" in text and "1000 I" in text
    assert main(["study", "--truth", "prior", "--prior", "paper", "--trials", "5"]) == 2
    assert "prior" in capsys.readouterr().err
    assert main(["study", "--truth", "1", "2", "--trials", "5"]) == 2
    assert "truth" in capsys.readouterr().err


def _fake_prior_study():
    levels = [0.5, 0.9, 0.95]
    return {
        "truth": "prior",
        "rho": 0.005,
        "prior": "fixed",
        "prior_mean": [-1.2, 4.0, 0.0],
        "prior_cov": (1000.0 * np.eye(3)).tolist(),
        "seed": 0,
        "trials": 110,
        "valid_trials": 100,
        "behind_camera_draws": 3,
        "rejected_trials": 10,
        "false_alarm": 0.01,
        "levels": levels,
        "coverage_se": np.sqrt(np.array(levels) * (1 - np.array(levels)) / 100).tolist(),
        "depth": {
            "coverage": [0.45, 0.93, 0.96],
            "ks_pvalue": 0.5,
            "chi2_pvalue": 0.004,
            "calibrated": False,
        },
        "velocity": {
            "coverage": [0.5, 0.9, 0.95],
            "ks_pvalue": 0.25,
            "chi2_pvalue": 0.75,
            "calibrated": True,
        },
    }


def test_prior_calibration_texts_and_figure_show_the_result():
    """Glue texts and the plot's drawn data come from the result, errors bars of 2 SE."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = _fake_prior_study()
    t = beyond_study.prior_study_texts(r, "x")
    assert t["x_depth_coverage_50"] == "0.45" and t["x_velocity_coverage_95"] == "0.95"
    # each coverage also with the binomial SE of a calibrated filter's, sqrt(p (1 - p) / n)
    assert t["x_depth_coverage_50_pm"] == "0.45 ± 0.05"
    assert t["x_depth_verdict"] == "fails" and t["x_velocity_verdict"] == "passes"
    assert t["x_false_alarm"] == "1 %" and t["x_test_level"] == "0.5 %"
    assert t["x_max_se"] == f"{0.05 / np.sqrt(0.25 / 100):.1f}"
    assert t["x_prior_mean"] == "(-1.2, 4.0, 0.0)" and t["x_prior_scale"] == "1000"
    text = cli_text.format_prior_study(r)
    assert "NOT calibrated" in text and "chi-square p 0.004" in text
    fig = beyond_study.prior_calibration(r)
    ax = fig.axes[0]
    depth, velocity = ax.containers
    np.testing.assert_allclose(
        np.asarray(depth.lines[0].get_ydata(), float), r["depth"]["coverage"]
    )
    np.testing.assert_allclose(
        np.asarray(velocity.lines[0].get_ydata(), float), r["velocity"]["coverage"]
    )
    segs = depth.lines[2][0].get_segments()
    np.testing.assert_allclose(
        [s[1, 1] - s[0, 1] for s in segs], 4 * np.asarray(r["coverage_se"]), rtol=1e-12
    )
    plt.close(fig)


# --- N frames with process noise: the bank of Kalman filters at frame N ----------------


def test_draws_over_n_frames_follow_the_motion_with_process_noise():
    """The truth is the state at frame N of a track from a prior draw: its depth is
    y_1 + N - 1 with y_1 > 0, the bearings are x_k / y_k plus noise of SD rho, and the
    velocity has spread by q**2 per frame (N - 1 changes) beyond the prior's variance."""
    q, frames = 0.1, 7
    d = calibration.draw_from_prior(
        PRIOR_MEAN,
        PRIOR_COV,
        RHO,
        4000,
        np.random.default_rng(0),
        frames=frames,
        process_noise=q,
    )
    assert d.mu.shape[1] == frames and np.all(d.truth[:, 1] > frames - 1)
    # the velocity at frame N: N(0, 0.25 + (N - 1) q**2) truncated only through y_1
    var = PRIOR_COV[2, 2] + (frames - 1) * q**2
    assert abs(np.var(d.truth[:, 2]) / var - 1) < 5 * np.sqrt(2 / len(d.truth))
    # the last bearing is the truth's projection plus noise
    residual = d.mu[:, -1] - d.truth[:, 0] / d.truth[:, 1]
    assert abs(np.std(residual) / RHO - 1.0) < 0.05


def test_the_bank_is_calibrated_over_its_prior_at_frame_n_and_a_wrong_one_is_caught():
    """Truths followed for 6 frames with q = 0.05: the bank's PIT values at frame 6 pass
    KS and chi-square at 1e-3; a bank that assumes no process noise is caught by both."""
    kw = dict(frames=6, process_noise=0.05)
    r = calibration.self_calibration(
        PRIOR_MEAN, PRIOR_COV, RHO, 150, np.random.default_rng(2), **kw
    )
    s = r.summary()
    assert s["trials"] > 120
    for q in ("depth", "velocity"):
        assert s[q]["ks_pvalue"] > 1e-3 and s[q]["chi2_pvalue"] > 1e-3
    wrong = calibration.self_calibration(
        PRIOR_MEAN, PRIOR_COV, RHO, 150, np.random.default_rng(2), filter_process_noise=0.0, **kw
    ).summary()
    assert wrong["velocity"]["ks_pvalue"] < 1e-3 and wrong["velocity"]["chi2_pvalue"] < 1e-3
    assert wrong["depth"]["coverage"][wrong["levels"].index(0.9)] < 0.8


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"frames": 2}, "frames"),
        ({"frames": 3.5}, "frames"),
        ({"process_noise": -1}, "process_noise"),
    ],
)
def test_frames_and_process_noise_are_checked(kwargs, name):
    with pytest.raises(ValueError, match=name):
        calibration.self_calibration(
            PRIOR_MEAN, PRIOR_COV, RHO, 10, np.random.default_rng(0), **kwargs
        )


def test_command_line_truth_prior_over_n_frames(capsys):
    import json

    from depthcore.cli.main import main

    argv = ["study", "--truth", "prior", "--trials", "30", "--frames", "5"]
    assert main([*argv, "--process-noise", "0.02", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 5 and out["process_noise"] == 0.02
    assert len(out["velocity"]["coverage"]) == len(out["levels"])
    assert main([*argv, "--process-noise", "0.02"]) == 0
    text = capsys.readouterr().out
    assert "5 frames, process noise 0.02" in text and "at frame 5" in text
