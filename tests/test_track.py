"""One track in one call: :func:`depthcore.registry.tracking.track` and the pixels' bearings.

The function's outputs are checked against the routes it calls (the bank's
track, the registry's Gaussian filters), the Gaussian smoother against
filterpy's Rauch-Tung-Striebel smoother (textbook 19.2.6) and, without process
noise, against the closed form of a deterministic motion; the exact filter's
filtered and smoothed SDs are checked for calibration over tracks whose truths
are drawn from the prior (Monte Carlo, with standard errors).
"""

from __future__ import annotations

import contextlib
import io
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from filterpy.kalman import rts_smoother
from numpy.testing import assert_allclose, assert_array_equal

import depthcore
from depthcore.exact import smoother
from depthcore.problem import checks, model
from depthcore.problem.gaussian import Gaussian
from depthcore.registry.filters import FILTERS, SMOOTHED
from depthcore.registry.tracking import PROCESS_NOISE_MAX, RHO_RANGE, track

ROOT = Path(__file__).resolve().parents[1]
#: A point at depth 10 at frame 1, seen with a bearing noise of 0.002 (one pixel at f = 500).
STATE_1 = np.array([2.0, 10.0, 0.1])
RHO = 0.002
PRIOR = Gaussian([1.0, 10.0, 0.1], np.diag([1.0, 4.0, 0.04]))


def _mu(n_frames=8, q=0.0, seed=0):
    rng = np.random.default_rng(seed)
    return model.simulate(STATE_1, n_frames, RHO, q, rng, frame=1).mu


def test_the_registry_says_which_filters_smooth():
    assert SMOOTHED == ("optimal", "ekf", "ukf")
    for name, f in FILTERS.items():
        assert (f.smoother is not None) == (name in SMOOTHED)


@pytest.mark.parametrize("q", [0.0, 0.02])
def test_the_exact_filter_is_the_banks_track(q):
    mu = _mu(8, q)
    t = track(mu, RHO, PRIOR, q, "optimal")
    direct = smoother.track(mu, RHO, PRIOR.mean, PRIOR.cov, q)
    assert_array_equal(t.filtered.mean, direct.filtered.mean)
    assert_array_equal(t.filtered.cov, direct.filtered.cov)
    assert_array_equal(t.smoothed.mean, direct.interval.mean)
    assert_array_equal(t.smoothed.cov, direct.interval.cov)
    assert t.filtered.depth_mean.shape == t.smoothed.velocity_sd.shape == (8,)
    assert_array_equal(t.frames, np.arange(1, 9))
    # the last frame's smoothed state is the filtered one (the same mixture)
    assert_allclose(t.smoothed.mean[-1], t.filtered.mean[-1], rtol=1e-12)
    assert_allclose(t.smoothed.cov[-1], t.filtered.cov[-1], rtol=1e-10)
    # the filtered state at frame N is the registry's estimate
    est = FILTERS["optimal"](mu, RHO, PRIOR.mean, PRIOR.cov, process_noise=q)
    assert_allclose(t.filtered.mean[-1], est.mean, rtol=1e-9)


@pytest.mark.parametrize("name", ["ekf", "ukf"])
@pytest.mark.parametrize("q", [0.0, 0.02])
def test_a_gaussian_filter_is_the_registrys_history_smoothed_by_filterpys_rts(name, q):
    mu = _mu(8, q, seed=1)
    t = track(mu, RHO, PRIOR, q, name)
    history = FILTERS[name](mu, RHO, PRIOR.mean, PRIOR.cov, process_noise=q).detail
    assert_array_equal(t.filtered.mean, history.means)
    assert_array_equal(t.filtered.cov, history.covs)
    assert_array_equal(t.smoothed.mean[-1], t.filtered.mean[-1])
    # filterpy's Rauch-Tung-Striebel smoother on the states less the known drift of
    # the depth (y_k - k follows x_{k+1} = F x_k, without the offset e)
    drift = np.zeros((8, 3))
    drift[:, 1] = np.arange(8)
    Q = np.diag([0.0, 0.0, q**2])
    xs, ps, _, _ = rts_smoother(history.means - drift, history.covs, [model.F] * 8, [Q] * 8)
    scale = np.sqrt(np.diagonal(t.smoothed.cov, axis1=1, axis2=2))
    assert np.max(np.abs(xs + drift - t.smoothed.mean) / scale) < 1e-9
    assert_allclose(ps, t.smoothed.cov, rtol=1e-8, atol=1e-12 * np.max(np.abs(ps)))


def test_without_process_noise_the_gaussian_smoother_moves_the_last_estimate_back():
    """q = 0: the motion is deterministic, so frame k's smoothed state is G^(k - N) of frame N's."""
    mu = _mu(8, seed=2)
    t = track(mu, RHO, PRIOR, 0.0, "ekf")
    for k in range(1, 9):
        A = model.G_linear(k - 8)
        assert_allclose(t.smoothed.mean[k - 1], model.G(t.filtered.mean[-1], k - 8), rtol=1e-10)
        assert_allclose(t.smoothed.cov[k - 1], A @ t.filtered.cov[-1] @ A.T, rtol=1e-8)


@pytest.mark.parametrize("name", ["ekf", "ukf"])
def test_the_gaussian_smoothed_sd_is_at_most_the_filtered_sd(name):
    """Rauch-Tung-Striebel: the smoothed covariance is at most the filtered one, at every frame."""
    for seed in range(5):
        t = track(_mu(12, 0.02, seed), RHO, PRIOR, 0.02, name)
        for a, b in (
            (t.smoothed.depth_sd, t.filtered.depth_sd),
            (t.smoothed.lateral_sd, t.filtered.lateral_sd),
            (t.smoothed.velocity_sd, t.filtered.velocity_sd),
        ):
            assert np.all(a <= b * (1 + 1e-12))


def test_the_exact_filter_and_smoother_are_calibrated_over_tracks_from_the_prior():
    """Monte Carlo: E[(truth - mean)**2 / var] = 1 for the exact posterior, at every frame.

    Truths are drawn from the prior at frame 1 (its depth SD is 2 at depth 10,
    so the truncation at depth 0 has no weight in double precision), followed
    for 8 frames with process noise; for each track the ratio is averaged over
    the frames, and its mean over 200 tracks is compared with 1 within three
    standard errors (six tests, each at about 0.3 %). Here the means are 1.05
    to 1.26 and the SEs 0.05 to 0.15 (the ratio of a Gaussian has SE
    sqrt(2 / 200) = 0.1). Power: with SEs below 0.15, the SDs understated by
    25 % (a mean ratio of 1.78) or overstated by 40 % (0.51) would fail.
    The tracks come from the exact smoother itself, which
    :func:`test_the_exact_filter_is_the_banks_track` shows is ``track``'s
    answer bit for bit (``track`` also runs the registry's filter and the
    online filter, which add nothing here).
    """
    rng = np.random.default_rng(2026)
    n_tracks, n_frames, q = 200, 8, 0.02
    truths = rng.multivariate_normal(PRIOR.mean, PRIOR.cov, n_tracks)
    assert np.all(truths[:, 1] > 0)
    sim = model.simulate(truths, n_frames, RHO, q, rng, frame=1)
    ratios = {"filtered": [], "smoothed": []}
    var_gap = []
    for mu, states in zip(sim.mu, sim.states, strict=True):
        t = smoother.track(mu, RHO, PRIOR.mean, PRIOR.cov, q)
        for key in ratios:
            s = getattr(t, "interval" if key == "smoothed" else key)
            var = np.diagonal(s.cov, axis1=1, axis2=2)
            ratios[key].append(np.mean((states - s.mean) ** 2 / var, axis=0))
        var_gap.append(
            np.mean(
                np.diagonal(t.filtered.cov - t.interval.cov, axis1=1, axis2=2)
                / np.diagonal(t.filtered.cov, axis1=1, axis2=2),
                axis=0,
            )
        )
    # the first track's answer through ``track`` is the smoother's, bit for bit
    t0 = track(sim.mu[0], RHO, PRIOR, q, "optimal")
    first = smoother.track(sim.mu[0], RHO, PRIOR.mean, PRIOR.cov, q)
    for a, b in ((t0.filtered, first.filtered), (t0.smoothed, first.interval)):
        assert_array_equal(a.mean, b.mean)
        assert_array_equal(a.cov, b.cov)
    for key, r in ratios.items():
        r = np.array(r)  # (tracks, 3): x, y, v
        mean, se = r.mean(axis=0), r.std(axis=0, ddof=1) / np.sqrt(n_tracks)
        assert np.all(se < 0.15), (key, se)
        assert np.all(np.abs(mean - 1) < 3 * se), (key, mean, se)
    # on average over the data the smoothed variance is below the filtered one
    gap = np.array(var_gap)
    g_mean, g_se = gap.mean(axis=0), gap.std(axis=0, ddof=1) / np.sqrt(n_tracks)
    assert np.all(g_mean > 4 * g_se), (g_mean, g_se)


def test_the_paper_rule_is_the_default_prior():
    mu = [-0.3, 0.0, 0.2, 0.33, 0.43]
    t = track(mu, 0.005)
    prior = depthcore.paper_prior(model.noise_free_state(mu[:3]))
    assert_array_equal(t.prior.mean, prior.mean)
    assert_array_equal(t.prior.cov, prior.cov)
    assert_array_equal(t.filtered.mean, track(mu, 0.005, prior).filtered.mean)


def test_the_package_exposes_track_and_the_pixels_bearings():
    assert depthcore.track is track
    assert "track" in dir(depthcore) and "bearings_from_pixels" in depthcore.__all__


# --- refusals and odd inputs ---------------------------------------------------------------


def _refused(match, *args, **kwargs):
    with pytest.raises(ValueError, match=match):
        track(*args, **kwargs)


@pytest.mark.parametrize(
    "mu",
    [
        [0.1, np.nan, np.nan, 0.3],  # NaN is a missing frame: two present
        [0.1, np.inf, 0.2, 0.3],
        [],
        [0.1],
        [0.1, 0.2],
        np.array([0.1, 0.2, 0.25, 0.3], dtype=complex),
        [[0.1, 0.2, 0.25], [0.1, 0.2, 0.25]],
        "0.1 0.2 0.25",
        [0.1, 0.2, 0.3, 0.4],  # every second difference 0: degenerate
        np.zeros(checks.MAX_FRAMES + 1),
    ],
)
def test_bad_bearings_are_refused_by_name(mu):
    _refused("^mu", mu, RHO, PRIOR)


@pytest.mark.parametrize(
    "rho", [0.0, -1.0, np.nan, np.inf, 1j, True, "0.1", 1e-300, 1e300, [0.1, 0.2]]
)
def test_bad_noise_is_refused_by_name(rho):
    _refused("^rho", _mu(), rho, PRIOR)


@pytest.mark.parametrize("q", [-1.0, np.nan, np.inf, 1e-320, 1e300, PROCESS_NOISE_MAX * 1.01])
def test_bad_process_noise_is_refused_by_name(q):
    _refused("^process_noise", _mu(), RHO, PRIOR, q)


@pytest.mark.parametrize("name", ["particle", "second_order", "rbpf", "nope", 3, None])
def test_a_filter_without_a_smoother_is_refused_by_name(name):
    _refused("^filter must be one of", _mu(), RHO, PRIOR, filter=name)


@pytest.mark.parametrize("prior", ["paper", (np.zeros(3), np.eye(3)), np.eye(3)])
def test_a_prior_that_is_not_a_gaussian_is_refused(prior):
    _refused("^prior must be", _mu(), RHO, prior)


def test_without_a_prior_bearings_behind_the_camera_ask_for_one():
    _refused("^prior is needed", [0.3, 0.2, 0.2, 0.25], RHO)


@pytest.mark.parametrize("name", SMOOTHED)
@pytest.mark.parametrize("rho", [RHO_RANGE[0], 1e-9, 1e-6, 10.0, RHO_RANGE[1]])
@pytest.mark.parametrize("q", [0.0, checks.MIN_PROCESS_NOISE, 1.0, PROCESS_NOISE_MAX])
def test_every_noise_in_range_gets_an_answer_or_a_refusal(name, rho, q):
    """Finite moments and SDs at every frame, or a ValueError naming an argument; no warning."""
    mu = _mu(8, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            t = track(mu, rho, PRIOR, q, name)
        except ValueError as exc:
            assert str(exc).startswith(("mu", "rho", "prior")), exc
            return
    for s in (t.filtered, t.smoothed):
        assert np.all(np.isfinite(s.mean))
        for sd in (s.lateral_sd, s.depth_sd, s.velocity_sd):
            assert np.all(np.isfinite(sd)) and np.all(sd >= 0)


@pytest.mark.parametrize("name", SMOOTHED)
def test_a_thousand_frames_and_three_frames(name):
    rng = np.random.default_rng(4)
    mu = model.simulate(STATE_1, checks.MAX_FRAMES, RHO, 0.01, rng, frame=1).mu
    t = track(mu, RHO, PRIOR, 0.01, name)
    assert t.smoothed.mean.shape == (checks.MAX_FRAMES, 3)
    assert np.all(np.isfinite(t.smoothed.cov))
    t3 = track([-0.3, 0.0, 0.2], 0.005, filter=name)  # the paper's three (Figure 2)
    assert t3.filtered.mean.shape == (3, 3) and t3.smoothed.cov.shape == (3, 3, 3)


# --- pixels ----------------------------------------------------------------------------------


def test_pixels_give_the_tangent_of_the_bearing():
    u = np.array([100.0, 320.0, 700.0])
    assert_allclose(depthcore.bearings_from_pixels(u, 320.0, 500.0), (u - 320.0) / 500.0)
    # a point at (x, y) in the camera's frame projects to column cx + f x / y
    x, y = 2.0, 10.0
    assert_allclose(depthcore.bearings_from_pixels([320 + 500 * x / y], 320, 500), [x / y])


@pytest.mark.parametrize(
    "args, name",
    [
        (([], 320, 500), "u"),
        (([[1.0, 2.0]], 320, 500), "u"),
        (([np.nan], 320, 500), "u"),
        (([1j], 320, 500), "u"),
        (("300", 320, 500), "u"),
        (([300.0], np.inf, 500), "cx"),
        (([300.0], [1, 2], 500), "cx"),
        (([300.0], 320, 0.0), "focal"),
        (([300.0], 320, -500), "focal"),
        (([300.0], 320, np.nan), "focal"),
        (([1e300], -1e300, 1e-300), "focal"),
    ],
)
def test_bad_pixels_are_refused_by_name(args, name):
    with pytest.raises(ValueError, match=f"^{name}"):
        depthcore.bearings_from_pixels(*args)


# --- the page "Using depthcore" ----------------------------------------------------------------


def using_track_example() -> str:
    """The code cell of book/using.md's section "One track, every frame" that runs ``track``."""
    text = (ROOT / "book" / "using.md").read_text(encoding="utf-8")
    section = text.split("## One track, every frame\n", 1)[1].split("\n## ", 1)[0]
    cells = re.findall(r"```\{code-cell\} ipython3\n(.*?)```", section, re.DOTALL)
    (code,) = [cell for cell in cells if "depthcore.track(" in cell and not cell.startswith(":")]
    return code


def test_the_using_pages_example_prints_the_track_of_eight_frames():
    code = using_track_example()
    assert "bearings_from_pixels" in code and "depthcore.track(" in code
    out = io.StringIO()
    namespace: dict = {}
    with contextlib.redirect_stdout(out):
        exec(compile(code, "book/using.md", "exec"), namespace)
    lines = out.getvalue().splitlines()
    t = namespace["track"]
    assert t.filtered.mean.shape == (8, 3) and len(lines) == 8
    for k, line in enumerate(lines):
        numbers = [float(v) for v in re.findall(r"-?\d+\.\d+", line)]
        expected = [
            t.filtered.depth_mean[k],
            t.filtered.depth_sd[k],
            t.smoothed.depth_mean[k],
            t.smoothed.depth_sd[k],
        ]
        assert_allclose(numbers, expected, atol=0.006)


def test_the_using_pages_quoted_depths_are_the_examples():
    """The page's sentence on the example pastes the exact and the EKF's smoothed depth,
    glued from the example's track and the EKF's run on the same bearings."""
    text = (ROOT / "book" / "using.md").read_text(encoding="utf-8")
    section = " ".join(text.split("## One track, every frame\n", 1)[1].split("\n## ", 1)[0].split())
    assert (
        "frame 1 is {eval}`use_exact` (the truth is {eval}`use_truth`" in section
        and 'with `filter="ekf"` it is {eval}`use_ekf`' in section
    )
    assert 'glue("use_exact", f"{s.depth_mean[0]:.2f} ± {s.depth_sd[0]:.2f}"' in section
    assert 'ekf = depthcore.track(mu, rho, prior=prior, filter="ekf").smoothed' in section
    assert 'glue("use_ekf", f"{ekf.depth_mean[0]:.2f} ± {ekf.depth_sd[0]:.2f}"' in section
    namespace: dict = {}
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(using_track_example(), "book/using.md", "exec"), namespace)
    exact = namespace["track"].smoothed
    ekf = track(namespace["mu"], namespace["rho"], namespace["prior"], filter="ekf").smoothed
    truth = namespace["truth"][1]
    # what the page asserts: the exact depth within two of its SDs of the truth, the EKF's
    # more than ten of its SDs from it
    assert abs(exact.depth_mean[0] - truth) < 2 * exact.depth_sd[0]
    assert abs(ekf.depth_mean[0] - truth) > 10 * ekf.depth_sd[0]
