"""MonoSLAM's depth hypotheses (depthcore.particles.depth_hypotheses) against the exact filter.

On the exact filter's own depth nodes and quadrature weights, and without a collapse, the
hypotheses are the exact filter's bank: the same mixture, to rounding. On their own grid
they tend to it as their number grows; they collapse at the first frame whose depth SD over
mean falls below the ratio, and the EKF carries that Gaussian on.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.special import ndtr

from depthcore.exact import posterior
from depthcore.exact.mixture import mixture_moments
from depthcore.kalman import ekf
from depthcore.particles import depth_hypotheses as dh
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import ALL_NAMES, FILTERS, names
from depthcore.studies import atlas

FIG2 = SCENARIOS["fig2"]
Q = 0.01


def _ten_frames():
    """A track of 10 frames of Figure 2's point with process noise ``Q``, and its prior."""
    sim = model.simulate(np.asarray(FIG2.c), 10, FIG2.rho, Q, np.random.default_rng(5))
    return sim.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, Q


def _fig2():
    return FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, 0.0


PROBLEMS = {"fig2": _fig2, "ten_frames_with_process_noise": _ten_frames}


def _relative(a, b) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def _misfit(problem, weights=None) -> tuple:
    """The hypotheses on the exact filter's nodes, against the registry's exact filter.

    ``weights``: the log weights given to the nodes (default the quadrature's own).
    Returns the largest relative differences of the mean and of the covariance.
    """
    mu, rho, mean, cov, q = problem
    exact_post = posterior.posterior(mu, rho, mean, cov, q)
    log_w = exact_post.log_weights if weights is None else weights(exact_post.log_weights)
    h = dh.filter_nodes(exact_post.bank.nodes, log_w, mu, rho, mean, cov, q, collapse_ratio=0)
    exact = FILTERS["optimal"](mu, rho, mean, cov, process_noise=q)
    assert not h.collapsed
    return _relative(h.mean, exact.mean), _relative(h.cov, exact.cov)


# --- (a) on the exact filter's nodes it is the exact filter -------------------------------


@pytest.mark.parametrize("key", sorted(PROBLEMS))
def test_on_the_exact_filters_nodes_and_weights_the_mixture_is_the_exact_filters(key):
    """With w_j the exact quadrature's weights, p_j ~ w_j N(y_j; m_y, P_yy) L(y_j) is the
    exact filter's mixture (bank module docstring), so mean and covariance agree to rounding
    (measured: at most 6e-16 relative)."""
    mean_misfit, cov_misfit = _misfit(PROBLEMS[key]())
    assert mean_misfit <= 1e-10 and cov_misfit <= 1e-10


@pytest.mark.parametrize("key", sorted(PROBLEMS))
def test_the_agreement_fails_with_uniform_weights_in_place_of_the_quadratures(key):
    """Mutation of the check above: equal weights on the same nodes drop the quadrature's
    cell widths w_j, and the mixture moves far beyond the tolerance."""
    mean_misfit, cov_misfit = _misfit(PROBLEMS[key](), weights=np.zeros_like)
    assert max(mean_misfit, cov_misfit) > 1e-4


# --- (b) on its own grid it tends to the exact filter -------------------------------------


@pytest.mark.parametrize("spacing", dh.SPACINGS)
@pytest.mark.parametrize("key", sorted(PROBLEMS))
def test_the_grids_riemann_sum_tends_to_the_exact_filter_as_the_hypotheses_grow(key, spacing):
    """sum_j h_j N(y_j; m_y, P_yy) L(y_j) over the range about m_y is a Riemann sum of the
    exact filter's depth integral: 1,000 hypotheses are much nearer the exact moments than
    10. On Figure 2 what is left is the tail beyond the range's ends (the error stops near
    1e-5 of the mean, 1e-3 of the covariance); ten frames pin the depth well inside it."""
    mu, rho, mean, cov, q = PROBLEMS[key]()
    exact = FILTERS["optimal"](mu, rho, mean, cov, process_noise=q)
    errors = {}
    for J in (10, 1000):
        h = dh.run(mu, rho, mean, cov, q, n_hypotheses=J, spacing=spacing, collapse_ratio=0)
        errors[J] = max(_relative(h.mean, exact.mean), _relative(h.cov, exact.cov))
    assert errors[1000] < errors[10] / 50
    if key == "ten_frames_with_process_noise":
        assert errors[1000] < 1e-6 < errors[10]


def test_monoslams_grid_is_100_depths_equally_spaced_over_half_a_metre_to_five():
    """MonoSLAM's initialisation: 100 depths uniform over 0.5 to 5 m, each cell 4.5 / 100
    wide, from the span 10 about m_y = 5 / sqrt(10); in inverse depth the cells are equal in
    1 / y and their widths still add up to the range."""
    prior_mean = np.array([0.0, 5.0 / np.sqrt(10.0), 0.0])
    nodes, log_widths = dh.grid(prior_mean)
    assert_allclose(nodes, 0.5 + 0.045 * (np.arange(100) + 0.5), rtol=1e-13)
    assert_allclose(np.exp(log_widths), 0.045, rtol=1e-12)
    nodes, log_widths = dh.grid(prior_mean, spacing="inverse")
    assert_allclose(np.diff(1.0 / nodes), (0.2 - 2.0) / 100, rtol=1e-12)
    assert_allclose(np.sum(np.exp(log_widths)), 4.5, rtol=1e-13)


# --- (c), (d) the collapse and the EKF after it -------------------------------------------


def _long_track(steps=None):
    """12 tracks of 30 frames whose depth ratio falls below 0.3 at frames 4 to 6."""
    c = np.array([0.0, 6.0, 0.05])  # the state at frame 1
    rng = np.random.default_rng(2)
    sim = model.simulate(c, 30, 0.03, Q, rng, size=12, frame=1, steps=steps)
    return sim.mu, 0.03, np.array([0.0, 5.0, 0.0]), np.diag([0.01, 25.0, 0.01])


def test_the_hypotheses_collapse_at_the_first_frame_whose_depth_ratio_is_below_the_ratio():
    """MonoSLAM's rule: collapse after the first frame k with sd(y_k) / E[y_k] < 0.3, read off
    the ratios of the run that never collapses; with ratio 0 the hypotheses never do."""
    mu, rho, mean, cov = _long_track()
    never = dh.run(mu, rho, mean, cov, Q, collapse_ratio=0)
    assert not np.any(never.collapsed) and np.all(np.isfinite(never.ratio))
    assert np.min(never.ratio) < 0.1  # well below 0.3 by the end, yet no collapse
    below = never.ratio < dh.COLLAPSE_RATIO
    first = np.argmax(below, axis=1) + 1
    h = dh.run(mu, rho, mean, cov, Q)
    assert_array_equal(h.collapsed_at, first)
    assert len(set(first.tolist())) >= 3  # the rows collapse at different frames
    frames = np.arange(1, 31)
    upto = frames <= first[:, None]
    assert_allclose(h.ratio[upto], never.ratio[upto], rtol=1e-12)
    assert np.all(np.isnan(h.ratio[~upto]))
    assert np.all(h.ratio[upto & (frames < first[:, None])] >= dh.COLLAPSE_RATIO)


@pytest.mark.parametrize("irregular", [False, True])
def test_after_the_collapse_the_answer_is_the_ekf_run_from_the_collapsed_gaussian(irregular):
    """After a collapse at frame k: N(m_k, P_k) moment-matched, predicted by Eq. (10) to frame
    k + 1, then ekf.run over mu_{k+1} .. mu_N (Eqs. (10)-(12)); the same numbers. Irregular:
    steps of 0.8 and a missing bearing at frame 12."""
    steps = np.full(29, 0.8) if irregular else None
    mu, rho, mean, cov = _long_track(steps)
    if irregular:
        mu[:, 11] = np.nan
    h = dh.run(mu, rho, mean, cov, Q, steps=steps)
    assert np.all(h.collapsed)
    for k in np.unique(h.collapsed_at):
        rows = h.collapsed_at == k
        s = None if steps is None else steps[k - 1]
        pred = ekf.predict(
            h.collapsed_mean[rows], h.collapsed_cov[rows], Q, 1.0 if s is None else s
        )
        more = {} if steps is None else {"steps": steps[k:]}
        run = ekf.run(mu[rows, k:], rho, pred.mean, pred.cov, Q, **more)
        assert_allclose(h.mean[rows], run.means[..., -1, :], rtol=1e-12, atol=1e-14)
        assert_allclose(h.cov[rows], run.covs[..., -1, :, :], rtol=1e-10, atol=1e-16)
    # and the Gaussian it collapsed to is the hypotheses' moments at that frame
    upto = dh.run(mu[:, :5], rho, mean, cov, Q, steps=None if steps is None else steps[:4])
    rows = h.collapsed_at == 5
    assert np.any(rows)
    assert_allclose(h.collapsed_mean[rows], upto.mean[rows], rtol=1e-12)


def test_the_pooled_law_has_the_results_mean_and_covariance():
    """The law a study reads (pooled): the hypotheses, or the collapsed filter's Gaussian on
    J depths at its normal quantiles; by the law of total variance its moments are the
    result's either way."""
    mu, rho, mean, cov = _long_track()
    for ratio in (0.0, dh.COLLAPSE_RATIO):
        h = dh.run(mu[:, :8], rho, mean, cov, Q, collapse_ratio=ratio)
        W, depths, means, covs = h.pooled()
        assert_allclose(np.sum(W, axis=-1), 1.0, rtol=1e-13)
        m, c = mixture_moments(W, means, covs, depths)
        assert_allclose(m, h.mean, rtol=1e-10)
        assert_allclose(c, h.cov, rtol=1e-9, atol=1e-14)
        assert np.any(h.collapsed) == (ratio > 0)


# --- (e) refusals ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("arg", "value"),
    [
        ("n_hypotheses", 1),
        ("n_hypotheses", 2.5),
        ("n_hypotheses", True),
        ("n_hypotheses", 10**7),
        ("spacing", "log"),
        ("spacing", None),
        ("span", 1.0),
        ("span", 0.5),
        ("span", np.inf),
        ("span", np.nan),
        ("span", "wide"),
        ("collapse_ratio", -0.1),
        ("collapse_ratio", np.inf),
        ("collapse_ratio", np.nan),
        ("prior_mean", np.array([0.0, 0.0, 0.0])),  # m_y = 0: no range about it
        ("prior_mean", np.array([0.0, -4.0, 0.0])),
    ],
)
def test_meaningless_options_are_refused_in_one_line_naming_the_argument(arg, value):
    mu, rho, mean, cov, _ = _fig2()
    if arg == "prior_mean":
        mean, options = value, {}
    else:
        options = {arg: value}
    for door in (dh.run, FILTERS["depth_hypotheses"]):  # the module's and the registry's
        with pytest.raises(ValueError) as info:
            door(mu, rho, mean, cov, **options)
        message = str(info.value)
        assert message.startswith(arg) and "\n" not in message, message


@pytest.mark.parametrize(
    ("prior_cov", "steps", "ratio", "message"),
    [
        # a depth SD of 1e-4 against cells of 0.11: all the weight on one hypothesis
        (np.diag([1000.0, 1e-8, 1000.0]), None, 0.3, "^n_hypotheses: .* rho and prior_cov pin"),
        # steps of -3 bring every depth of the range to the camera by frame 6
        (FIG2.prior.cov, np.full(5, -3.0), 0.0, r"^mu: every depth hypothesis has weight zero"),
        # a step of -30 after the collapse at frame 2 takes the EKF's depth behind the camera
        (FIG2.prior.cov, np.array([-1.0, -30, -1, -1, -1]), 0.3, r"^mu: after the depth .* <= 0"),
    ],
)
def test_problems_the_hypotheses_cannot_answer_are_refused_in_one_line(
    prior_cov, steps, ratio, message
):
    """Each refusal names what went wrong and the argument to change, in one line."""
    mu = FIG2.mu if steps is None else np.array([-0.3, -0.2, -0.05, 0.1, 0.3, 0.6])
    with pytest.raises(ValueError, match=message) as info:
        dh.run(mu, FIG2.rho, FIG2.prior.mean, prior_cov, steps=steps, collapse_ratio=ratio)
    assert "\n" not in str(info.value)
    if steps is not None and ratio == 0:  # with the default ratio it collapses first, and answers
        assert np.isfinite(dh.run(mu, FIG2.rho, FIG2.prior.mean, prior_cov, steps=steps).mean[1])


@pytest.mark.parametrize(
    ("arg", "nodes", "log_widths"),
    [
        ("nodes", [1.0, -2.0], [0.0, 0.0]),
        ("nodes", [[1.0, 2.0], [3.0, 4.0]], [0.0, 0.0]),  # two rows for one problem
        ("log_widths", [1.0, 2.0], [0.0, np.nan]),
        ("log_widths", [1.0, 2.0], [0.0, np.inf]),
        ("log_widths", [1.0, 2.0], [-np.inf, -np.inf]),
        ("log_widths", [1.0, 2.0], [0.0, 0.0, 0.0]),
    ],
)
def test_given_nodes_and_weights_are_checked(arg, nodes, log_widths):
    mu, rho, mean, cov, _ = _fig2()
    with pytest.raises(ValueError, match=f"^{arg}") as info:
        dh.filter_nodes(nodes, log_widths, mu, rho, mean, cov)
    assert "\n" not in str(info.value)


# --- the registry ---------------------------------------------------------------------------


def test_the_registry_runs_it_by_name_and_the_atlas_does_not():
    """Its entry reads run's Gaussian summary; it is registered after ALL_NAMES, so the atlas
    (which runs ALL_NAMES but its costly filters) and its recorded run are without it."""
    entry = FILTERS["depth_hypotheses"]
    assert entry.any_frames and entry.with_process_noise and not entry.default
    assert "depth_hypotheses" in names() and "depth_hypotheses" not in ALL_NAMES
    for size in atlas.SIZES.values():
        assert "depth_hypotheses" not in size.names
    mu, rho, mean, cov, q = _ten_frames()
    est = entry(mu, rho, mean, cov, process_noise=q)
    h = dh.run(mu, rho, mean, cov, q)
    assert_array_equal(est.mean, h.mean)
    assert_array_equal(est.cov, h.cov)
    assert est.depth_sd == np.sqrt(h.cov[1, 1]) and est.detail is not None
    with pytest.raises(ValueError, match="^gate: the depth_hypotheses filter has no gate"):
        entry(mu, rho, mean, cov, gate=1e-3)


# --- the law it answers: the hypotheses, or the Gaussian once collapsed --------------------


def _mixed_batch():
    """Eight noisy copies of Figure 2's bearings at a collapse ratio of 0.14: some collapse at
    frame 3 and some never do."""
    rng = np.random.default_rng(3)
    mu = FIG2.mu + rng.normal(0.0, FIG2.rho, (8, 3))
    result = dh.run(mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, collapse_ratio=0.14)
    assert np.any(result.collapsed) and not np.all(result.collapsed)
    return result


@pytest.mark.parametrize("grid", [False, True])
def test_where_collapsed_the_marginal_cdfs_are_the_gaussians_and_elsewhere_the_hypotheses(grid):
    """A collapsed track's answer is the EKF's Gaussian, so its depth and velocity CDFs are
    Phi((value - m) / s) exactly, not its J-point stand-in; an uncollapsed track's depth CDF is
    the weighted hypotheses' step function and its velocity CDF their mixture's."""
    h = _mixed_batch()
    c = h.collapsed
    for k, cdf in ((1, h.depth_cdf), (2, h.velocity_cdf)):
        m, s = h.mean[:, k], np.sqrt(h.cov[:, k, k])
        value = (m + 0.3 * s)[:, None] + np.array([-1.0, 0.0, 1.0]) * s[:, None]
        got = cdf(value) if grid else cdf(value[:, 1])
        want = ndtr((value - m[:, None]) / s[:, None])
        want = want if grid else want[:, 1]
        assert_allclose(got[c], want[c], rtol=1e-14)
        if k == 1:  # the step function of the hypotheses where they never collapsed
            y = value if grid else value[:, 1:2]
            step = np.sum(h.probabilities[:, None, :] * (h.depths[:, None, :] <= y[..., None]), -1)
            assert_allclose(got[~c], (step if grid else step[:, 0])[~c], rtol=1e-14)
            assert np.any(np.abs(got[c] - (step if grid else step[:, 0])[c]) > 1e-6)


def test_where_collapsed_the_velocity_density_is_the_gaussians():
    h = _mixed_batch()
    c = h.collapsed
    m, s = h.mean[:, 2], np.sqrt(h.cov[:, 2, 2])
    v = m + 0.5 * s
    want = np.exp(-0.5 * 0.25) / (np.sqrt(2.0 * np.pi) * s)
    assert_allclose(h.velocity_pdf(v)[c], want[c], rtol=1e-13)
    # uncollapsed: the mixture's density integrates its CDF
    dv = 1e-6 * s
    slope = (h.velocity_cdf(v + dv) - h.velocity_cdf(v - dv)) / (2 * dv)
    assert_allclose(h.velocity_pdf(v)[~c], slope[~c], rtol=1e-5)
