"""More frames: the study at each N, the coverage test, the marginals, the conjecture."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from depthcore import SCENARIOS
from depthcore.book import beyond_conjecture, beyond_frames
from depthcore.problem import model
from depthcore.problem.gaussian import paper_prior_means
from depthcore.registry.filters import FILTERS
from depthcore.studies import frames, monte_carlo, scores

FIG2 = SCENARIOS["fig2"]


@pytest.fixture(scope="module")
def frames_run():
    return frames.frames_study(
        [3, 6],
        40,
        5,
        ("ekf", "second_order", "particle"),
        prior="fixed",
        particle_trials=20,
        n_particles=300,
    )


def test_frames_study_entries_are_the_direct_studies(frames_run):
    r = frames_run
    assert list(r["frames"]) == [3, 6]
    assert list(r)[3] == "optimal"  # the reference first, then the named filters
    for j, n in enumerate((3, 6)):
        plain = monte_carlo.study(
            trials=40, seed=5, prior="fixed", names=("optimal", "ekf", "second_order"), frames=n
        )
        for name in ("optimal", "ekf", "second_order"):
            f = plain["filters"][name]
            assert r[name]["rmse"][j] == f["depth"]["rmse"]
            assert r[name]["coverage_95"][j] == f["depth"]["coverage_95"]
            assert r[name]["nees"][j] == f["nees"]
            assert r[name]["hellinger"][j] == f["hellinger_depth"]["mean"]
            assert r[name]["trials"][j] == plain["valid_trials"]
        rand = monte_carlo.study(
            trials=20,
            seed=5,
            prior="fixed",
            names=("optimal", "particle"),
            frames=n,
            n_particles=300,
        )
        assert r["particle"]["bias"][j] == rand["filters"]["particle"]["depth"]["bias"]
        assert r["particle"]["trials"][j] == rand["valid_trials"]


def test_frames_study_with_process_noise_refuses_a_filter_without_it():
    with pytest.raises(ValueError, match="particle"):
        frames.frames_study([4], 5, 0, ("particle",), process_noise=0.01)


def test_coverage_test_is_the_normal_approximation_to_the_binomial():
    n = np.array([100, 400, 2000])
    k = np.array([60, 240, 1420])
    t = scores.coverage_test(k / n, 0.68, n)
    # independent route: the two-sided p-value of the standardised count
    z = (k - n * 0.68) / np.sqrt(n * 0.68 * 0.32)
    p = 2 * stats.norm.sf(np.abs(z))
    assert_allclose(t["z"], z, rtol=1e-12)
    assert_allclose(t["se"], np.sqrt(0.68 * 0.32 / n), rtol=1e-12)
    expected = np.where(p >= 0.01, "calibrated", np.where(z < 0, "overconfident", "underconfident"))
    assert list(t["verdict"]) == list(expected)
    assert list(t["verdict"]) == ["calibrated", "overconfident", "underconfident"]
    assert scores.coverage_test(0.99, 0.95, 1000)["verdict"] == "underconfident"


def test_coverage_test_flags_a_calibrated_filter_at_its_false_alarm_rate():
    rng = np.random.default_rng(0)
    n, level = 500, 0.95
    coverage = rng.binomial(n, level, size=20_000) / n
    flagged = np.mean(scores.coverage_test(coverage, level, n)["verdict"] != "calibrated")
    # the normal approximation at 1 %, within a few Monte Carlo SEs (and the lattice)
    assert 0.004 < flagged < 0.02


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"coverage": 1.2}, "coverage"),
        ({"level": 1.0}, "level"),
        ({"trials": 0}, "trials"),
        ({"z": -1.0}, "z"),
    ],
)
def test_coverage_test_rejects_bad_input(kwargs, match):
    args = {"coverage": 0.5, "level": 0.68, "trials": 10, **kwargs}
    with pytest.raises(ValueError, match=match):
        scores.coverage_test(**args)


@pytest.fixture(scope="module")
def track():
    rng = np.random.default_rng(3)
    return model.simulate(FIG2.c, 8, FIG2.rho, 0.0, rng).mu


def test_frame_marginals_are_the_filters_on_the_first_frames(track):
    m = beyond_frames.frame_marginals(track, FIG2.rho, [3, 8], ("ekf", "second_order"))
    pm = paper_prior_means(model.noise_free_states(track[None, :3]))[0]
    for r, n in zip(m, (3, 8), strict=True):
        assert r["frames"] == n
        e = FILTERS["ekf"](track[:n], FIG2.rho, pm, 1000 * np.eye(3))
        assert r["depth_mean"]["ekf"] == float(e.depth_mean)
        # the exact density integrates to one over its grid of mean +- 6 SD, up to the
        # heavy right tail beyond the grid at N = 3; its mean is the filter's, likewise
        mass = np.trapezoid(r["density"]["optimal"], r["grid"])
        assert abs(mass - 1) < (1e-2 if n == 3 else 2e-3)
        o = r["depth_mean"]["optimal"]
        on_grid = np.trapezoid(r["grid"] * r["density"]["optimal"], r["grid"])
        if n == 3:  # the right tail the grid leaves out (mass < 1e-2) lowers the mean
            assert o * (1 - 3e-2) < on_grid < o
        else:
            assert_allclose(on_grid, o, rtol=1e-4)
    fig = beyond_frames.frame_marginals_figure(m)
    assert fig.axes[0].get_title() == "N = 3"
    assert len(fig.axes) == 4
    plt.close(fig)


def test_frame_marginals_reject_bad_input(track):
    with pytest.raises(ValueError, match="frames"):
        beyond_frames.frame_marginals(track, FIG2.rho, [9])
    with pytest.raises(ValueError, match="rng"):
        beyond_frames.frame_marginals(track, FIG2.rho, [3], ("particle",))
    with pytest.raises(ValueError, match="mu"):
        beyond_frames.frame_marginals(track[:2], FIG2.rho, [3])


def test_track_marginals_draw_the_track_then_the_random_filters_from_one_generator():
    panels_names = ("ekf", "particle")
    got = beyond_frames.track_marginals(7, 6, [3, 6], panels_names, n_points=101)
    rng = np.random.default_rng(7)
    mu = model.simulate(FIG2.c, 6, FIG2.rho, 0.0, rng).mu
    want = beyond_frames.frame_marginals(mu, FIG2.rho, [3, 6], panels_names, rng=rng, n_points=101)
    assert_allclose(got["mu"], mu, rtol=0, atol=0)
    for g, w in zip(got["panels"], want, strict=True):
        assert g["frames"] == w["frames"]
        for name in ("optimal", *panels_names):  # the particle filter's draws follow the track's
            assert g["depth_mean"][name] == w["depth_mean"][name]
            assert_allclose(g["density"][name], w["density"][name], rtol=0, atol=0)
    other = beyond_frames.track_marginals(7, 6, [3], ("ekf",), scenario="fig3", n_points=101)
    assert not np.allclose(other["mu"][:3], got["mu"][:3])  # Figure 3's point, not Figure 2's


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"scenario": "fig9"}, "scenario must be one of fig2"),
        ({"frames": 2}, "frames must be an integer from 3"),
        ({"panel_frames": [7]}, "frames"),
    ],
)
def test_track_marginals_refuse_bad_input(kwargs, match):
    args = {"seed": 1, "frames": 6, "panel_frames": [3], "names": ("ekf",), **kwargs}
    with pytest.raises(ValueError, match=match):
        beyond_frames.track_marginals(**args)


def test_frames_study_texts_count_the_failed_coverage_tests(frames_run):
    texts = beyond_frames.frames_study_texts(frames_run, "f")
    assert texts["f_tests"] == "4"
    assert set(texts) == {"f_tests"} | {f"f_{n}_fails" for n in frames_run if n in FILTERS}
    for name in ("optimal", "ekf", "second_order", "particle"):
        r = frames_run[name]
        fails = sum(
            scores.coverage_test(r[f"coverage_{lv}"][i], lv / 100, r["trials"][i])["verdict"]
            != "calibrated"
            for lv in (68, 95)
            for i in range(2)
        )
        assert texts[f"f_{name}_fails"] == str(fails)


def test_frames_study_figure_draws_every_filter(frames_run):
    fig = beyond_frames.frames_study_figure(frames_run, title="a")
    assert len(fig.axes) == len(beyond_frames.FRAMES_ROWS)
    assert fig.get_suptitle() == "a"
    # the Hellinger panel leaves the reference out
    assert len(fig.axes[2].get_lines()) == 3
    assert len(fig.axes[0].get_lines()) == 4
    # the coverage panels shade the test's acceptance band for each number of trials
    trials = sorted({int(frames_run[k]["trials"][0]) for k in ("optimal", "particle")})
    assert len(trials) == 2
    for ax, level in zip(fig.axes[4:], (0.68, 0.95), strict=True):
        bands = sorted((p.get_y(), p.get_y() + p.get_height()) for p in ax.patches)
        half = scores.COVERAGE_Z * np.sqrt(level * (1 - level) / np.array(trials))
        assert_allclose(bands, np.stack([level - half, level + half], axis=1), rtol=1e-12)
    plt.close(fig)


def test_conjecture_study_entries_are_frames_study_entries():
    c = beyond_conjecture.conjecture_study([3, 5], [1 / 200, 1 / 100], [6.0, 12.0], 30, 2)
    assert c["ekf"]["hellinger"].shape == (2, 2, 2)
    assert_allclose(c["truth"], [FIG2.c, 2 * FIG2.c], rtol=1e-12)
    direct = frames.frames_study(
        [3, 5], 30, 2, ("second_order", "ekf"), "fixed", truth=c["truth"][1], rho=1 / 100
    )
    for name in ("second_order", "ekf"):
        assert_allclose(c[name]["rmse"][1, 1], direct[name]["rmse"], rtol=0, atol=0)
        assert_allclose(c[name]["nees"][1, 1], direct[name]["nees"], rtol=0, atol=0)
    with pytest.raises(ValueError, match="depths"):
        beyond_conjecture.conjecture_study([3], [0.01], [2.0], 5, 0)


def test_conjecture_wins_compare_cell_by_cell():
    c = beyond_conjecture.conjecture_study([3, 5], [1 / 500, 1 / 100], [6.0, 12.0], 40, 4)
    w = beyond_conjecture.conjecture_wins(c)
    so, ekf, pairs = c["second_order"], c["ekf"], c["paired"]
    z = scores.COVERAGE_Z
    # the paired comparisons are of the scores the study reports, over the same trials
    assert_allclose(pairs["rmse_ratio"], so["rmse"] / ekf["rmse"], rtol=1e-12)
    assert_allclose(pairs["ekf_rmse_ratio"] * pairs["rmse_ratio"], 1.0, rtol=1e-12)
    assert_allclose(pairs["hellinger_ratio"], ekf["hellinger"] / so["hellinger"], rtol=1e-12)
    assert_allclose(pairs["hellinger_difference"], so["hellinger"] - ekf["hellinger"], atol=1e-14)
    gap = np.abs(so["coverage_68"] - 0.68) - np.abs(ekf["coverage_68"] - 0.68)
    assert_allclose(pairs["coverage_68_gap"], gap, atol=1e-14)
    assert (pairs["trials"] == so["trials"]).all()
    for idx in np.ndindex(so["rmse"].shape):
        # three outcomes: 1 the second-order filter significantly better, -1 worse, 0 neither
        d, se = pairs["hellinger_difference"][idx], pairs["hellinger_difference_se"][idx]
        assert w["hellinger"][idx] == (1 if d < -z * se else -1 if d > z * se else 0)
        r, se = pairs["rmse_ratio"][idx], pairs["rmse_ratio_se"][idx] / pairs["rmse_ratio"][idx]
        assert w["rmse"][idx] == (1 if np.log(r) < -z * se else -1 if np.log(r) > z * se else 0)
        d, se = pairs["coverage_68_gap"][idx], pairs["coverage_68_gap_se"][idx]
        assert w["coverage_68"][idx] == (1 if d < -z * se else -1 if d > z * se else 0)
        se = np.sqrt(0.68 * 0.32 / so["trials"][idx])
        assert w["calibrated_68"]["ekf"][idx] == (
            abs(ekf["coverage_68"][idx] - 0.68) <= scores.COVERAGE_Z * se
        )
    assert set(np.unique(w["hellinger"])) <= {-1, 0, 1}
    # the EKF is never nearer the optimal filter, and at the lower noise p_s is, significantly
    assert (w["hellinger"] >= 0).all() and (w["hellinger"][0] == 1).all()
    # each mean Hellinger distance with its standard error, positive where trials differ
    h, h_se = so["hellinger"], so["hellinger_se"]
    assert h_se.shape == h.shape and (h_se > 0).all() and (h_se < h).all()
    texts = beyond_conjecture.conjecture_texts(c, w, "cj")
    assert texts["cj_cells"] == "4" and texts["cj_1_x"] == "5"
    for score in ("hellinger", "rmse", "coverage_68"):
        v = w[score][..., 0]
        counts = [int(np.sum(v == k)) for k in (1, 0, -1)]
        assert texts[f"cj_0_{score}"] == str(counts[0])
        assert texts[f"cj_0_{score}_ties"] == str(counts[1])
        assert texts[f"cj_0_{score}_losses"] == str(counts[2])
        assert texts[f"cj_0_{score}_table"] == " / ".join(map(str, counts)) and sum(counts) == 4
    # the paired tests' power: the largest over the cells of (2.576 + 0.842) SE
    d_h = (2.5758 + 0.8416) * w["hellinger_se"].max()
    assert float(texts["cj_detect_hellinger"]) == pytest.approx(d_h, abs=1e-3)
    d_r = (2.5758 + 0.8416) * w["rmse_se"].max()
    assert float(texts["cj_detect_rmse"]) == pytest.approx(np.exp(d_r), abs=0.01)
    # the verdicts' power: a 1 % test at the fewest trials of a cell, 80 % power
    # against the difference (2.576 + 0.842) sqrt(p (1 - p) / n)
    n = min(int(c[name]["trials"].min()) for name in ("optimal", "second_order", "ekf"))
    assert n <= 40 and texts["cj_test_trials_min"] == str(n) and texts["cj_test_trials"] == "40"
    assert texts["cj_test_size"] == "1 %" and texts["cj_test_power"] == "80 %"
    for trials, suffix in ((n, "_min"), (40, "")):
        d68 = (2.5758 + 0.8416) * np.sqrt(0.68 * 0.32 / trials)
        assert texts[f"cj_detect_68{suffix}"] == f"{100 * d68:.1f} points"
    fig = beyond_conjecture.conjecture_figure(c)
    assert len(fig.axes) == 6
    assert len(fig.axes[0].get_lines()) == 2 * 2  # two depths, two filters
    assert [t.get_text() for t in fig.legends[0].get_texts()] == [
        "depth 6",
        "depth 12",
        "second order $p_s$",
        "EKF $p_e$",
    ]
    plt.close(fig)


FIG2 = SCENARIOS["fig2"]


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: frames.frames_study([], 10, 1), "frames must hold at least one"),
        (lambda: frames.frames_study([2], 10, 1), "frames must be an integer from 3"),
        (lambda: frames.frames_study([5000], 10, 1), "frames must be an integer from 3"),
        (lambda: frames.frames_study([3.5], 10, 1), "frames must be an integer"),
        (lambda: frames.frames_study([3], 0, 1), "trials"),
        (lambda: frames.frames_study([3], 10, 1, prior="x"), "prior"),
        (lambda: frames.frames_study([4], 10, 1, process_noise=np.nan), "process_noise"),
        (lambda: frames.frames_study([4], 10, 1, rho=0.0), "rho"),
        (lambda: frames.frames_study([4], 10, 1, truth=[1, -5, 0]), "truth"),
        (lambda: beyond_frames.frame_marginals(FIG2.mu, FIG2.rho, []), "frames must hold"),
        (lambda: beyond_frames.frame_marginals(FIG2.mu, FIG2.rho, [4]), "frames must each be"),
        (lambda: beyond_frames.frame_marginals(FIG2.mu, FIG2.rho, [3], width=np.nan), "width"),
        (lambda: scores.coverage_test(0.5, 1.5, 100), "level"),
        (lambda: scores.coverage_test(np.nan, 0.68, 10), "coverage"),
        (lambda: beyond_conjecture.conjecture_study([3], [], [6], 10, 1), "rhos must hold"),
        (lambda: beyond_conjecture.conjecture_study([3], [0.005], [], 10, 1), "depths must hold"),
        (lambda: beyond_conjecture.conjecture_study([], [0.005], [6], 10, 1), "frames must hold"),
        (lambda: beyond_conjecture.conjecture_study([3], [0.005], [-1], 10, 1), "depths"),
        (
            lambda: beyond_conjecture.conjecture_study([3], [0.005], [6], 10, 1, bearing=np.nan),
            "bearing",
        ),
    ],
)
def test_odd_arguments_are_refused_in_one_line_naming_them(call, message):
    with pytest.raises(ValueError, match=message) as info:
        call()
    assert "\n" not in str(info.value)


def test_conjecture_extreme_text_gives_the_extreme_cell_with_its_own_se():
    result = {
        "paired": {
            "rmse_ratio": np.array([[[1.5, 0.9]], [[2.5, 0.8]]]),  # (R, D, F) = (2, 1, 2)
            "rmse_ratio_se": np.array([[[0.1, 0.02]], [[0.3, 0.04]]]),
        }
    }
    assert beyond_conjecture.extreme_text(result, "rmse_ratio", "min") == "0.80 ± 0.04"
    assert beyond_conjecture.extreme_text(result, "rmse_ratio", "max", (..., 0), 1) == "2.5 ± 0.3"
    with pytest.raises(ValueError, match="which"):
        beyond_conjecture.extreme_text(result, "rmse_ratio", "least")
