"""The bank's posterior frame by frame: node densities, filtered and smoothed series.

Independent routes: the depth density at the nodes against Eqs. (14)-(16) at
N = 3 (:func:`depthcore.exact.optimal.marginals`); the filtered series against a
bank on a fixed dense rule in log depth rerun from scratch at each frame; the
fixed-lag smoother (the textbook's augmented-state filter, 19.2.6) against the
fixed-interval (Rauch-Tung-Striebel) smoother of the posterior after the
bearings it uses, and against the augmented filter rerun from frame 1 for
every frame, mixed by hand.
"""

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthbook import reference
from depthcore.exact import bank as bk
from depthcore.exact import mixture as bmix
from depthcore.exact import optimal
from depthcore.exact import posterior as bpost
from depthcore.exact import smoother as btrack
from depthcore.problem import model
from depthcore.problem.scenarios import RHO_200, SCENARIOS

ORDER = 20


def log_depth_rule(panels, lo=-12.0, hi=14.0):
    """Composite Gauss-Legendre nodes and weights for integrals over y_1 > 0, in t = log(y_1)."""
    x, w = np.polynomial.legendre.leggauss(ORDER)
    edges = np.linspace(lo, hi, panels + 1)
    half = 0.5 * np.diff(edges)
    t = (0.5 * (edges[1:] + edges[:-1])[:, None] + half[:, None] * x).ravel()
    return np.exp(t), (half[:, None] * w).ravel() * np.exp(t)


def fig2_track(N, q, seed):
    s = SCENARIOS["fig2"]
    sim = model.simulate(model.G(s.c, -2), N, RHO_200, q, np.random.default_rng(seed), frame=1)
    return sim, s.prior


def test_eq16_node_density_is_the_one_dimensional_depth_density(scenario):
    s = scenario
    post = bpost.posterior(s.mu, s.rho, s.prior.mean, s.prior.cov)
    depths, density = bpost.node_density(post)
    opt = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    assert depths.shape == density.shape == post.probabilities.shape
    assert_allclose(depths, post.bank.nodes + 2.0, rtol=0, atol=0)
    assert_allclose(density, opt.depth_pdf(depths), rtol=0, atol=1e-9 * density.max())
    # the probabilities are the densities times the quadrature weights
    assert_allclose(density * np.exp(post.log_weights), post.probabilities, rtol=1e-12, atol=0)


def test_node_density_at_later_frames_is_the_depth_pdf():
    sim, prior = fig2_track(9, 0.02, seed=4)
    post = bpost.posterior(sim.mu, RHO_200, prior.mean, prior.cov, 0.02)
    depths, density = bpost.node_density(post)
    assert np.min(depths) > 8.0  # nodes are depths at frame 1 > 0, shifted by N - 1 = 8
    assert_allclose(density, post.depth_pdf(depths), rtol=1e-10, atol=1e-12 * density.max())


@pytest.mark.parametrize("q", [0.0, 0.02])
def test_textbook_19_2_3_filtered_series_is_the_bank_rerun_at_each_frame(q):
    N = 7
    sim, prior = fig2_track(N, q, seed=5)
    tr = btrack.track(sim.mu, RHO_200, prior.mean, prior.cov, q, lag=2)
    y, w = log_depth_rule(160)
    assert tr.filtered.mean.shape == (N, 3) and tr.filtered.cov.shape == (N, 3, 3)
    assert len(tr.posteriors) == N and tr.lag == 2
    for k in range(1, N + 1):
        ref = bmix.mixture(bk.filter_bank(y, sim.mu[:k], RHO_200, prior.mean, prior.cov, q), w)
        sd = np.sqrt(np.diag(ref.cov))
        assert_allclose(tr.filtered.mean[k - 1], ref.mean, rtol=0, atol=1e-8 * sd.max())
        assert_allclose(tr.filtered.cov[k - 1], ref.cov, rtol=0, atol=1e-8 * np.outer(sd, sd).max())
    # the fixed-interval smoother: the dense rule's mixture smoothed
    ref = bmix.mixture(bk.filter_bank(y, sim.mu, RHO_200, prior.mean, prior.cov, q), w).smoothed()
    sd = np.sqrt(np.max(ref.cov[:, [0, 1, 2], [0, 1, 2]]))
    assert_allclose(tr.interval.mean, ref.mean, rtol=0, atol=1e-8 * sd)
    assert_allclose(tr.interval.cov, ref.cov, rtol=0, atol=1e-8 * sd**2)


@pytest.mark.parametrize("lag", [1, 3])
def test_textbook_19_2_6_fixed_lag_is_the_fixed_interval_smoother_of_the_prefix(lag):
    N = 8
    sim, prior = fig2_track(N, 0.03, seed=6)
    tr = btrack.track(sim.mu, RHO_200, prior.mean, prior.cov, 0.03, lag=lag)
    for s in range(N):
        t = min(s + lag, N - 1)
        ref = tr.posteriors[t].smoothed()  # the Rauch-Tung-Striebel route on the same nodes
        sd = np.sqrt(np.diag(ref.cov[s]))
        assert_allclose(tr.lagged.mean[s], ref.mean[s], rtol=0, atol=1e-9 * sd.max())
        assert_allclose(tr.lagged.cov[s], ref.cov[s], rtol=1e-7, atol=1e-9 * sd.max() ** 2)
    # smoothing never loses information: the lateral SD is at most the filtered one
    assert np.all(tr.lagged.lateral_sd <= tr.filtered.lateral_sd * (1 + 1e-9))
    assert np.all(tr.interval.lateral_sd <= tr.lagged.lateral_sd * (1 + 1e-9))


@pytest.mark.parametrize("q", [0.0, 0.02])
def test_textbook_19_2_6_fixed_lag_is_the_augmented_filter_rerun_for_every_frame(q):
    N = 12
    sim, prior = fig2_track(N, q, seed=1)
    # no lag, short ones, a window of half the track, and lags that reach its end and beyond
    for lag in (0, 1, 2, 6, N - 2, N - 1, N + 3):
        tr = btrack.track(sim.mu, RHO_200, prior.mean, prior.cov, q, lag=lag)
        nodes = [p.bank.nodes for p in tr.posteriors]
        # the nodes are re-placed along the track: the frames are smoothed on several sets
        assert sum(not np.array_equal(a, b) for a, b in zip(nodes, nodes[1:], strict=False)) >= 1
        mean, cov = reference.track_fixed_lag(tr)
        sd = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))  # (N, 3)
        # the track's fixed-lag states are the backward (Rauch-Tung-Striebel) recursions
        # over each window, as the fixed-interval smoother is: equal to rounding
        assert_allclose(tr.lagged.mean, mean, rtol=0, atol=1e-11 * sd.max())
        err = np.abs(tr.lagged.cov - cov) / (sd[:, :, None] * sd[:, None, :])
        # (the first frames' covariances have condition numbers near 1e7)
        assert np.max(err) < 1e-9, (lag, np.max(err))


def test_lag_zero_is_the_filter_and_a_long_lag_is_the_fixed_interval_smoother():
    N = 6
    sim, prior = fig2_track(N, 0.01, seed=7)
    zero = btrack.track(sim.mu, RHO_200, prior.mean, prior.cov, 0.01, lag=0)
    long = btrack.track(sim.mu, RHO_200, prior.mean, prior.cov, 0.01, lag=N + 3)
    scale = np.sqrt(np.max(zero.filtered.cov[:, [0, 1, 2], [0, 1, 2]], axis=1))
    assert_allclose(zero.lagged.mean, zero.filtered.mean, rtol=0, atol=1e-9 * scale.max())
    assert_allclose(long.lagged.mean, long.interval.mean, rtol=0, atol=1e-9 * scale.max())
    assert_allclose(long.lagged.cov, long.interval.cov, rtol=1e-7, atol=1e-12)
    # the depth advances by one per frame under the smoother, with one SD at every frame
    assert_allclose(np.diff(long.interval.depth_mean), 1.0, rtol=1e-12)
    assert_allclose(long.interval.depth_sd, long.filtered.depth_sd[-1], rtol=1e-9)


def test_track_and_node_density_refuse_bad_input():
    s = SCENARIOS["fig2"]
    args = (s.rho, s.prior.mean, s.prior.cov)
    with pytest.raises(ValueError, match=r"mu must have shape \(N,\)"):
        btrack.track(np.zeros((2, 3)), *args)
    with pytest.raises(ValueError, match="mu must be finite"):
        btrack.track([0.1, np.nan], *args)
    with pytest.raises(ValueError, match="lag must be an integer >= 0"):
        btrack.track(s.mu, *args, lag=-1)
    with pytest.raises(ValueError, match="rho must be"):
        btrack.track(s.mu, -1.0, s.prior.mean, s.prior.cov)
    with pytest.raises(ValueError, match="post must be a Mixture"):
        bpost.node_density(s.mu)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"mu": [-0.3, 0.0, np.nan]}, "mu must be finite"),
        ({"mu": [[-0.3, 0.0, 0.2]]}, "mu must have shape"),
        ({"rho": 0.0}, "rho must be positive"),
        ({"process_noise": -1.0}, "process_noise"),
        ({"lag": -1}, "lag"),
        ({"lag": 1.5}, "lag"),
        ({"rtol": 0.0}, "rtol"),
    ],
)
def test_track_refuses_odd_arguments_in_one_line(change, message):
    s = SCENARIOS["fig2"]
    args = {"mu": s.mu, "rho": s.rho, "prior_mean": s.prior.mean, "prior_cov": s.prior.cov}
    with pytest.raises(ValueError, match=message) as info:
        btrack.track(**{**args, **change})
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("rho", [1e-12, 1e3])
@pytest.mark.parametrize("scale", [1e-12, 1e12])
def test_track_answers_at_extreme_noise_and_priors_without_warnings(rho, scale):
    s = SCENARIOS["fig2"]
    # finite states, or (rho = 1e-12: the later bearings are billions of SDs off the
    # constant-velocity track) a one-line refusal of a marginal no float grid resolves
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            tr = btrack.track(np.r_[s.mu, 0.33, 0.43], rho, s.prior.mean, scale * np.eye(3), lag=2)
        except ValueError as e:
            assert rho == 1e-12 and "too narrow" in str(e) and "\n" not in str(e)
            return
    for part in (tr.filtered, tr.interval, tr.lagged):
        assert np.all(np.isfinite(part.mean)) and np.all(np.isfinite(part.cov))
