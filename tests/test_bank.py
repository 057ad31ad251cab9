"""The exact optimal filter for N frames and process noise q.

It is computed as a bank of Kalman filters over depth.

Independent routes: at N = 3, q = 0, the one-dimensional route of Eqs. (14)-(16)
(:func:`depthcore.exact.optimal.moments`); at a fixed depth, the batch least-squares
solution for the whole lateral trajectory given all bearings; overall, a
brute-force three-dimensional quadrature of the posterior (q = 0, N = 5) and
importance sampling of the depth (q > 0).
"""

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats
from scipy.special import logsumexp

from depthcore.exact import bank as bk
from depthcore.exact import mixture as bmix
from depthcore.exact import optimal
from depthcore.exact import posterior as bpost
from depthcore.kalman import linear
from depthcore.problem import model
from depthcore.problem.gaussian import paper_prior
from depthcore.problem.model import noise_free_state
from depthcore.problem.scenarios import MU_17, RHO_200, SCENARIOS

ORDER = 20  # Gauss-Legendre points per panel


def log_depth_rule(panels, lo=-12.0, hi=14.0):
    """Nodes and weights for integrals over y_1 > 0: composite Gauss-Legendre in t = log(y_1)
    over [lo, hi] (depths 6e-6 to 1.2e6), with the Jacobian dy/dt = y folded into the weights."""
    x, w = np.polynomial.legendre.leggauss(ORDER)
    edges = np.linspace(lo, hi, panels + 1)
    half = 0.5 * np.diff(edges)
    t = (0.5 * (edges[1:] + edges[:-1])[:, None] + half[:, None] * x).ravel()
    wt = (half[:, None] * w).ravel()
    return np.exp(t), wt * np.exp(t)


def key_moments(mx):
    return np.array([mx.depth_mean, mx.depth_sd, mx.velocity_mean, mx.velocity_sd])


def converged_mixture(mu, rho, prior_mean, prior_cov, q=0.0, tol=1e-11, v_probe=None):
    """The bank's mixture on the log-depth rule, panels doubled until the key moments
    change by at most ``tol`` relative (the rounding floor is a few 1e-12), and the
    velocity CDF at ``v_probe`` too if given (it needs more nodes than the moments)."""
    panels, previous = 20, None
    while True:
        y, w = log_depth_rule(panels)
        mx = bmix.mixture(bk.filter_bank(y, mu, rho, prior_mean, prior_cov, q), w)
        now = key_moments(mx)
        if v_probe is not None:
            now = np.concatenate([now, mx.velocity_cdf(v_probe)])
        if previous is not None and np.all(np.abs(now - previous) <= tol * np.abs(now)):
            return mx
        assert panels < 2000, "the test's depth rule did not converge"
        previous, panels = now, 2 * panels


# --- the model at a fixed depth: batch least squares --------------------------------


def lateral_map(N):
    """The lateral states as a linear map of z = (x_1, v_1, a_1 .. a_{N-1}):
    rows 2k, 2k+1 give x_{k+1}, v_{k+1}."""
    A = np.zeros((2 * N, N + 1))
    for k in range(N):
        A[2 * k, 0] = 1.0
        A[2 * k, 1] = k  # x_{k+1} = x_1 + k v_1 + sum_{j<k} (k - j) a_j
        A[2 * k + 1, 1] = 1.0
        for j in range(1, k + 1):  # a_j enters v from frame j + 1 and x from frame j + 2
            A[2 * k + 1, 1 + j] = 1.0
            A[2 * k, 1 + j] = k - j
    return A


def batch_least_squares(y, mu, rho, q, prior_mean, prior_cov):
    """At one depth y_1 = y, the whole lateral trajectory at once, with no Kalman recursion.

    The unknowns are z = (x_1, v_1, a_1 .. a_{N-1}) (just (x_1, v_1) when q = 0), with the
    prior N(m, P) conditioned on y_1 = y on (x_1, v_1) and N(0, q**2) on each a_k; the
    bearings are mu = G z + w with G = H A (H picks x_k / y_k, A = :func:`lateral_map`).
    The whitened residuals r(z) = ((mu - G z) / rho, R^-1 (z - m_z)), Z = R R^T, are
    minimised by least squares, and

        log p(mu | y) = -N/2 log(2 pi) - N log rho - log det R - 1/2 log det M - 1/2 |r(z*)|^2

    with M the normal matrix; z | mu ~ N(z*, M^-1). Returns the log weight
    log N(y; m_y, P_yy) + log p(mu | y) and the means (N, 2) and covariances (N, 2, 2) of
    (x_k, v_k) given all bearings.
    """
    N = len(mu)
    u = [0, 2]
    P_yy = prior_cov[1, 1]
    mean_1 = prior_mean[u] + prior_cov[u, 1] * (y - prior_mean[1]) / P_yy
    cov_1 = prior_cov[np.ix_(u, u)] - np.outer(prior_cov[u, 1], prior_cov[u, 1]) / P_yy
    d = N + 1 if q > 0 else 2
    A = lateral_map(N)[:, :d]
    m_z = np.concatenate([mean_1, np.zeros(d - 2)])
    R = np.zeros((d, d))
    R[:2, :2] = np.linalg.cholesky(cov_1)
    R[2:, 2:] = q * np.eye(d - 2)
    H = np.zeros((N, 2 * N))
    H[np.arange(N), 2 * np.arange(N)] = 1.0 / (y + np.arange(N))
    R_inv = np.linalg.inv(R)
    design = np.vstack([H @ A / rho, R_inv])
    target = np.concatenate([mu / rho, R_inv @ m_z])
    z, *_ = np.linalg.lstsq(design, target, rcond=None)
    residual = design @ z - target
    M = design.T @ design
    log_like = (
        -0.5 * N * np.log(2 * np.pi)
        - N * np.log(rho)
        - np.sum(np.log(np.diag(R)))
        - 0.5 * np.linalg.slogdet(M)[1]
        - 0.5 * residual @ residual
    )
    log_weight = stats.norm.logpdf(y, prior_mean[1], np.sqrt(P_yy)) + log_like
    mean = (A @ z).reshape(N, 2)
    cov = A @ np.linalg.inv(M) @ A.T
    return log_weight, mean, np.stack([cov[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] for k in range(N)])


def long_track(N, q, seed, rho=RHO_200):
    """Fig. 2's point continued for N frames with process noise q, and the paper's prior."""
    c = noise_free_state(MU_17)
    x1 = model.G(c, -2)
    sim = model.simulate(x1, N, rho, q, np.random.default_rng(seed), frame=1)
    prior = paper_prior(c)
    return sim, prior


# --- N = 3, q = 0: the paper's problem -------------------------------------------------


def test_eq14_16_bank_moments_equal_the_one_dimensional_route(scenario):
    s = scenario
    prior = s.prior
    ref = optimal.moments(np.array([s.mu]), s.rho, prior.mean, prior.cov)
    mx = converged_mixture(s.mu, s.rho, prior.mean, prior.cov)
    expected = np.array(
        [ref.depth_mean[0], ref.depth_sd[0], ref.velocity_mean[0], ref.velocity_sd[0]]
    )
    # both routes are converged to ~1e-12; the requirement is 1e-10 relative
    assert_allclose(key_moments(mx), expected, rtol=1e-10, atol=0)
    scale = np.sqrt(np.diag(ref.cov[0]))
    assert_allclose(mx.mean, ref.mean[0], rtol=0, atol=1e-10 * scale.max())
    assert_allclose(mx.cov, ref.cov[0], rtol=0, atol=1e-10 * np.outer(scale, scale).max())


def test_eq16_bank_depth_density_is_the_one_dimensional_one_up_to_a_constant(scenario):
    # log p(y_1) + log L(y_1) of the bank against Eq. (16)'s log p_oy at y = y_1 + 2.
    s = scenario
    y1 = np.array([0.05, 0.7, 2.0, 4.5, 6.3, 11.0, 40.0, 300.0])
    b = bk.filter_bank(y1, s.mu, s.rho, s.prior.mean, s.prior.cov)
    log_oy, mean, cov = optimal.conditional(y1 + 2.0, s.mu, s.rho, s.prior)
    diff = b.log_weight - log_oy
    assert np.ptp(diff) < 1e-9 * np.max(np.abs(b.log_weight))
    # and the Gaussian of (x_3, v_3) given the depth is Eq. (15)'s
    assert_allclose(b.mean, mean, rtol=1e-9, atol=1e-12)
    assert_allclose(b.cov, cov, rtol=1e-7, atol=1e-14)


def test_eq13_16_densities_and_cdfs_match_the_one_dimensional_route():
    s = SCENARIOS["fig3"]
    prior = s.prior
    v = np.array([-1.0, 2.0, 4.4, 7.0, 12.0])
    mx = converged_mixture(s.mu, s.rho, prior.mean, prior.cov, v_probe=v[1:])
    assert mx.velocity_gap < 1.0  # converged nodes resolve the velocity
    ref = optimal.batch_marginals(np.array([s.mu]), s.rho, prior.mean, prior.cov)
    opt = optimal.run(s.mu, s.rho, prior.mean, prior.cov)
    y = np.array([2.5, 5.0, 10.0, 20.0, 45.0, 120.0])
    assert_allclose(mx.depth_pdf(y), opt.depth_pdf(y), rtol=1e-9, atol=1e-15)
    assert_allclose(mx.depth_cdf(y), ref.depth_cdf(y), rtol=0, atol=1e-9)
    assert_allclose(mx.velocity_cdf(v), ref.velocity_cdf(v), rtol=0, atol=1e-9)
    assert_allclose(mx.velocity_pdf(v), opt.velocity_pdf(v), rtol=1e-8, atol=1e-14)
    # the log normaliser is a log density of the bearings: the same constant offset as Eq. (16)
    assert np.isfinite(mx.log_normaliser)


def test_velocity_gap_tells_when_the_nodes_resolve_the_velocity():
    # Fig. 3: 40 panels give the moments to 1e-13 but not the velocity CDF (4e-4 off);
    # 160 panels give both. The gap diagnoses the difference.
    s = SCENARIOS["fig3"]
    v = np.array([2.0, 7.0])
    mixtures = {}
    for panels in (40, 160, 320):
        y, w = log_depth_rule(panels)
        mixtures[panels] = bmix.mixture(
            bk.filter_bank(y, s.mu, s.rho, s.prior.mean, s.prior.cov), w
        )
    coarse, fine, finer = mixtures[40], mixtures[160], mixtures[320]
    assert_allclose(key_moments(coarse), key_moments(finer), rtol=1e-11)
    # gaps of 3.2 and 0.8 SD: relative ripples 2 exp(-2 pi^2 / h^2) of 0.3 and 9e-14
    assert coarse.velocity_gap > 3.0 and fine.velocity_gap < 1.0
    assert np.max(np.abs(coarse.velocity_cdf(v) - finer.velocity_cdf(v))) > 1e-4
    assert_allclose(fine.velocity_cdf(v), finer.velocity_cdf(v), rtol=0, atol=1e-12)


def test_depth_pdf_integrates_to_one_and_the_cdf_is_its_integral():
    sim, prior = long_track(6, 0.02, seed=3)
    mx = converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov, q=0.02)
    y, w = log_depth_rule(160)
    N = 6
    assert_allclose(np.sum(mx.depth_pdf(y + N - 1) * w), 1.0, rtol=1e-10)
    grid = mx.depth_mean + mx.depth_sd * np.array([-2.0, -0.5, 0.0, 1.0, 3.0])
    h = 1e-4 * mx.depth_sd
    slope = (mx.depth_cdf(grid + h) - mx.depth_cdf(grid - h)) / (2 * h)
    assert_allclose(slope, mx.depth_pdf(grid), rtol=1e-5)  # central difference, O(h^2)
    cdf = mx.depth_cdf(np.array([N - 1.0, 1e9]))
    assert_allclose(cdf, [0.0, 1.0], atol=1e-10)
    v = mx.velocity_mean + mx.velocity_sd * np.array([-1.0, 0.3, 2.0])
    hv = 1e-5 * mx.velocity_sd
    assert_allclose(
        (mx.velocity_cdf(v + hv) - mx.velocity_cdf(v - hv)) / (2 * hv),
        mx.velocity_pdf(v),
        rtol=1e-6,
    )


# --- N > 3 and q > 0 -------------------------------------------------------------------


@pytest.mark.parametrize("N, q", [(1, 0.0), (2, 0.03), (8, 0.0), (8, 0.03)])
def test_textbook_19_2_3_each_node_is_the_batch_least_squares_at_its_depth(N, q):
    sim, prior = long_track(N, q, seed=5)
    y1 = np.array([0.3, 2.0, 3.7, 5.5, 20.0])
    b = bk.filter_bank(y1, sim.mu, RHO_200, prior.mean, prior.cov, q, history=True)
    for j, y in enumerate(y1):
        log_weight, mean, cov = batch_least_squares(y, sim.mu, RHO_200, q, prior.mean, prior.cov)
        # The Joseph update meets a prior variance of 1000 with a bearing variance of
        # (rho y_k)**2: relative rounding up to 1e-16 * 1000 / (rho y)**2 in the covariances,
        # ~4e-8 at y = 0.3, whose log weight (-3867) is then right to 5e-10 relative; near
        # the posterior's mode (y ~ 4) everything agrees to ~1e-12.
        sd = np.sqrt(np.diag(cov[-1]))
        assert_allclose(b.log_weight[j], log_weight, rtol=1e-9, atol=1e-11)
        assert_allclose(b.mean[j], mean[-1], rtol=0, atol=1e-7 * sd.max())
        assert_allclose(b.cov[j], cov[-1], rtol=1e-8, atol=1e-8 * np.outer(sd, sd).max())
        assert_allclose(b.history.means[j, -1], b.mean[j], rtol=0, atol=0)


@pytest.mark.parametrize("q", [0.0, 0.03])
def test_textbook_19_2_6_smoothed_single_node_is_the_batch_least_squares(q):
    # One node with weight 1: the mixture's smoothed states are that node's smoother.
    N = 7
    sim, prior = long_track(N, q, seed=6)
    y = 4.2
    mx = bmix.mixture(bk.filter_bank([y], sim.mu, RHO_200, prior.mean, prior.cov, q), [1.0])
    sm = mx.smoothed()
    _, mean, cov = batch_least_squares(y, sim.mu, RHO_200, q, prior.mean, prior.cov)
    assert_allclose(sm.lateral_mean, mean[:, 0], rtol=1e-8, atol=1e-12)
    assert_allclose(sm.velocity_mean, mean[:, 1], rtol=1e-8, atol=1e-12)
    assert_allclose(sm.cov[:, [0, 2]][:, :, [0, 2]], cov, rtol=1e-6, atol=1e-13)
    assert_allclose(sm.depth_mean, y + np.arange(N), rtol=1e-15)
    assert_allclose(sm.depth_sd, 0.0, atol=1e-15)


def brute_force_q0(mu, rho, prior, panels=60, order=48, width=12.0):
    """Moments at frame N and smoothed lateral means by a 3-D Gauss-Legendre rule for q = 0.

    Coordinates (t, a, b): t = log(y_1), a = x_1 / y_1 and b = x_N / y_N, the noise-free
    bearings at the first and last frames, over a +-width rho box around mu_1 and mu_N,
    where the likelihood of those two bearings alone is negligible outside. Then
    x_1 = a y_1, v = (b y_N - a y_1) / (N - 1), and dx_1 dy_1 dv = y_1**2 y_N / (N - 1) dt da db.
    The posterior is Eq. (6)'s for N bearings: the prior times the N likelihoods.
    """
    N = len(mu)
    t, wt = log_depth_rule(panels, lo=-6.0, hi=8.0)
    g, wg = np.polynomial.legendre.leggauss(order)
    a, wa = mu[0] + width * rho * g, width * rho * wg
    b, wb = mu[-1] + width * rho * g, width * rho * wg
    y1 = t[:, None, None]
    A, B = a[None, :, None], b[None, None, :]
    yN = y1 + N - 1
    x1 = A * y1
    v = (B * yN - x1) / (N - 1)
    X = np.stack(np.broadcast_arrays(x1, y1, v), axis=-1)
    log_p = stats.multivariate_normal(prior.mean, prior.cov).logpdf(X)
    for k in range(N):
        log_p = log_p + stats.norm(mu[k], rho).logpdf((x1 + k * v) / (y1 + k))
    log_p = log_p + np.log(y1 * yN / (N - 1)) + np.log(wt)[:, None, None]  # wt = y_1 dt
    log_p = log_p + np.log(wa)[None, :, None] + np.log(wb)[None, None, :]
    W = np.exp(log_p - logsumexp(log_p)).ravel()
    state_N = np.stack(np.broadcast_arrays(x1 + (N - 1) * v, yN, v), axis=-1).reshape(-1, 3)
    mean = W @ state_N
    d = state_N - mean
    cov = (W[:, None] * d).T @ d
    lateral = np.array([W @ np.broadcast_to(x1 + k * v, log_p.shape).ravel() for k in range(N)])
    return mean, cov, lateral


def test_q0_n5_moments_and_smoothing_match_brute_force_3d_quadrature():
    N = 5
    sim, prior = long_track(N, 0.0, seed=7)
    mx = converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov)
    mean, cov, lateral = brute_force_q0(sim.mu, RHO_200, prior)
    # this 3-D rule is within 3e-11 in the means and 2e-10 in the covariance of a finer
    # one (90 panels, 64 points, which is 1e-13 from the bank): tolerances 1e-9 of the
    # largest SD and 1e-8 of the largest variance leave room
    scale = np.sqrt(np.diag(cov))
    assert_allclose(mx.mean, mean, rtol=0, atol=1e-9 * scale.max())
    assert_allclose(mx.cov, cov, rtol=0, atol=1e-8 * np.outer(scale, scale).max())
    assert_allclose(mx.smoothed().lateral_mean, lateral, rtol=0, atol=1e-9 * scale.max())


def test_q_positive_moments_match_importance_sampling_of_the_depth():
    # Self-normalised importance sampling of y_1 from a log-normal proposal, each draw
    # weighted by the prior depth density times p(mu | y_1) from batch least squares, and
    # carrying E[(x_N, v_N) | y_1, mu] from the same solution: no Kalman recursion.
    N, q = 9, 0.04
    sim, prior = long_track(N, q, seed=8)
    mx = converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov, q=q)
    rng = np.random.default_rng(9)
    n = 3000
    proposal = stats.t(df=3, loc=np.log(sim.states[0, 1]), scale=0.2)  # in log(y_1), heavy tails
    y = np.exp(proposal.rvs(size=n, random_state=rng))
    log_g = proposal.logpdf(np.log(y)) - np.log(y)
    rows = [batch_least_squares(yi, sim.mu, RHO_200, q, prior.mean, prior.cov) for yi in y]
    log_w = np.array([r[0] for r in rows]) - log_g
    W = np.exp(log_w - logsumexp(log_w))
    depth = y + N - 1
    v_mean = np.array([r[1][-1, 1] for r in rows])
    v_var = np.array([r[2][-1, 1, 1] for r in rows])
    ess = 1.0 / np.sum(W**2)
    assert ess > 0.15 * n  # the proposal, centred on the true depth, covers the posterior
    for values, target, _extra in ((depth, mx.depth_mean, 0.0), (v_mean, mx.velocity_mean, 0.0)):
        est = np.sum(W * values)
        se = np.sqrt(np.sum(W**2 * (values - est) ** 2))  # delta-method standard error
        assert abs(est - target) < 5 * se + 1e-12  # five SEs: a false alarm below 1e-6
    sd_depth = np.sqrt(np.sum(W * (depth - np.sum(W * depth)) ** 2))
    sd_v = np.sqrt(np.sum(W * (v_var + (v_mean - np.sum(W * v_mean)) ** 2)))
    assert sd_depth == pytest.approx(mx.depth_sd, rel=0.05)
    assert sd_v == pytest.approx(mx.velocity_sd, rel=0.05)


# --- online updates, batching, smoothing -----------------------------------------------


@pytest.mark.parametrize("q", [0.0, 0.05])
def test_textbook_19_2_3_online_step_equals_recomputing_from_scratch(q):
    N = 8
    sim, prior = long_track(N, q, seed=10)
    y, _ = log_depth_rule(10)
    b = bk.filter_bank(y, sim.mu[:3], RHO_200, prior.mean, prior.cov, q, history=True)
    for k in range(3, N):
        b = bk.step(b, sim.mu[k])
    fresh = bk.filter_bank(y, sim.mu, RHO_200, prior.mean, prior.cov, q, history=True)
    assert b.frames == N
    assert_allclose(b.mu, sim.mu, rtol=0, atol=0)
    assert_allclose(b.log_weight, fresh.log_weight, rtol=1e-13, atol=1e-11)
    assert_allclose(b.mean, fresh.mean, rtol=1e-13, atol=1e-14)
    assert_allclose(b.cov, fresh.cov, rtol=1e-13, atol=1e-18)
    for field in linear.FilterResult._fields:
        assert_allclose(
            getattr(b.history, field), getattr(fresh.history, field), rtol=1e-13, atol=1e-13
        )


def test_batched_bank_equals_a_loop_over_trials():
    # Four trials, each with its own nodes, bearings, noise and process noise.
    rng = np.random.default_rng(11)
    N, B = 6, 4
    c = noise_free_state(MU_17)
    prior = paper_prior(c)
    x1 = model.G(c, -2) + rng.normal(size=(B, 3)) * [0.2, 0.5, 0.1]
    rho = np.array([1 / 200, 1 / 500, 1 / 100, 1 / 200])
    q = np.array([0.0, 0.02, 0.05, 0.01])
    mu = np.stack([model.simulate(x1[i], N, rho[i], q[i], rng, frame=1).mu for i in range(B)])
    y, w = log_depth_rule(20)
    nodes = y[None, :] * (1.0 + 0.01 * np.arange(B))[:, None]
    b = bk.filter_bank(nodes, mu[:, :4], rho, prior.mean, prior.cov, q)
    b = bk.step(bk.step(b, mu[:, 4]), mu[:, 5])
    mx = bmix.mixture(b, w[None, :] * (1.0 + 0.01 * np.arange(B))[:, None])
    for i in range(B):
        one = bmix.mixture(
            bk.filter_bank(nodes[i], mu[i], rho[i], prior.mean, prior.cov, q[i]),
            w * (1.0 + 0.01 * i),
        )
        assert_allclose(mx.mean[i], one.mean, rtol=1e-12)
        assert_allclose(mx.cov[i], one.cov, rtol=1e-10, atol=1e-14)
        assert_allclose(mx.log_normaliser[i], one.log_normaliser, rtol=1e-13)
        ys = one.depth_mean + np.array([-1.0, 0.0, 1.0]) * one.depth_sd
        assert_allclose(mx.depth_pdf(np.tile(ys, (B, 1)))[i], one.depth_pdf(ys), rtol=1e-11)
        assert_allclose(mx.velocity_cdf(np.tile(ys, (B, 1)))[i], one.velocity_cdf(ys), rtol=1e-12)
        assert_allclose(mx.smoothed().mean[i], one.smoothed().mean, rtol=1e-11, atol=1e-13)


def test_smoothed_state_at_the_last_frame_is_the_filtered_mixture():
    sim, prior = long_track(6, 0.03, seed=12)
    y, w = log_depth_rule(40)
    b = bk.filter_bank(y, sim.mu, RHO_200, prior.mean, prior.cov, 0.03)
    mx = bmix.mixture(b, w)
    sm = mx.smoothed()
    assert_allclose(sm.mean[-1], mx.mean, rtol=1e-12)
    assert_allclose(sm.cov[-1], mx.cov, rtol=1e-9, atol=1e-14)
    # the depth advances by one per frame and its SD does not change
    assert_allclose(np.diff(sm.depth_mean), 1.0, rtol=1e-12)
    assert_allclose(sm.depth_sd, mx.depth_sd, rtol=1e-9)
    # with history kept, the smoother reuses it
    hist = bmix.mixture(
        bk.filter_bank(y, sim.mu, RHO_200, prior.mean, prior.cov, 0.03, history=True), w
    )
    # (its filters run in the textbook's matrix form, the others in closed form)
    assert_allclose(hist.smoothed().mean, sm.mean, rtol=1e-12, atol=1e-13)


# --- refusals --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fig2_args():
    s = SCENARIOS["fig2"]
    return dict(
        nodes=[1.0, 4.0, 9.0], mu=s.mu, rho=s.rho, prior_mean=s.prior.mean, prior_cov=s.prior.cov
    )


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(nodes=[1.0, 0.0, 3.0]), "nodes must be positive"),
        (dict(nodes=[1.0, np.nan]), "nodes must be finite"),
        (dict(nodes=np.zeros((2, 0))), r"nodes must have shape \(..., J\) with J >= 1"),
        (dict(mu=[0.1, np.inf, 0.2]), "mu must be finite"),
        (dict(mu=np.zeros((3, 0))), r"mu must have shape \(..., N\) with N >= 1"),
        (dict(rho=0.0), "rho must be positive"),
        (dict(rho=-0.1), "rho must be positive"),
        (dict(process_noise=-0.01), "process_noise must be >= 0"),
        (dict(prior_cov=np.diag([1.0, -1.0, 1.0])), "prior_cov must be positive definite"),
        (dict(prior_cov=np.eye(2)), r"prior_cov must have shape \(..., 3, 3\)"),
        (dict(prior_mean=[0.0, 1.0]), r"prior_mean must have shape \(..., 3\)"),
        (
            dict(nodes=np.ones((2, 3)), mu=np.zeros((3, 3))),
            r"batch\) shapes do not broadcast: nodes \(2,\), mu \(3,\)",
        ),
    ],
)
def test_filter_bank_refuses_bad_input_naming_the_argument(fig2_args, change, message):
    with pytest.raises(ValueError, match=message):
        bk.filter_bank(**dict(fig2_args, **change))


def test_mixture_and_step_refuse_bad_input(fig2_args):
    b = bk.filter_bank(**fig2_args)
    with pytest.raises(ValueError, match="weights must be >= 0"):
        bmix.mixture(b, [1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="a positive one per problem"):
        bmix.mixture(b, [0.0, 0.0, 0.0])
    # a zero weight (padding) leaves the node out
    assert_allclose(bmix.mixture(b, [1.0, 0.0, 1.0]).probabilities[1], 0.0, atol=0)
    with pytest.raises(ValueError, match="weights must broadcast"):
        bmix.mixture(b, [1.0, 1.0])
    with pytest.raises(ValueError, match="bank must be a Bank"):
        bmix.mixture(tuple(b), [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="mu_next must be finite"):
        bk.step(b, np.nan)
    with pytest.raises(ValueError, match="bank must be a Bank"):
        bk.step(None, 0.1)
    two = bk.filter_bank(**dict(fig2_args, mu=np.tile(fig2_args["mu"], (2, 1))))
    with pytest.raises(ValueError, match=r"do not broadcast: bank \(2,\), mu_next \(3,\)"):
        bk.step(two, [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="rtol must be a positive scalar"):
        bmix.mixture(b, [1.0, 1.0, 1.0]).depth_cdf([5.0], rtol=0.0)


# --- nodes placed by the depth quadrature ----------------------------------------------


def key(m, i=0):
    return np.array([m.depth_mean[i], m.depth_sd[i], m.velocity_mean[i], m.velocity_sd[i]])


def test_eq14_16_placed_bank_moments_equal_the_one_dimensional_route(scenario):
    s = scenario
    prior = s.prior
    ref = optimal.moments(np.array([s.mu]), s.rho, prior.mean, prior.cov)
    got = bpost.moments(np.array([s.mu]), s.rho, prior.mean, prior.cov)
    assert_allclose(key(got), key(ref), rtol=1e-10, atol=0)
    assert_allclose(got.cov, ref.cov, rtol=1e-10, atol=1e-10 * ref.cov[0, 1, 1])
    assert got.depth_error[0] <= 1e-10 * got.depth_sd[0]
    assert got.velocity_error[0] <= 1e-10 * got.velocity_sd[0]


def test_eq14_16_placed_bank_equals_the_one_dimensional_route_over_noisy_batches():
    s = SCENARIOS["fig2"]
    prior = s.prior
    rng = np.random.default_rng(21)
    mu = np.array(s.mu) + 3 * s.rho * rng.standard_normal((40, 3))
    ref = optimal.moments(mu, s.rho, prior.mean, prior.cov)
    got = bpost.moments(mu, s.rho, prior.mean, prior.cov)
    for f in ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd"):
        assert_allclose(getattr(got, f), getattr(ref, f), rtol=1e-10, atol=0)
    # a batch does not depend on its order
    back = bpost.moments(mu[::-1], s.rho, prior.mean, prior.cov)
    assert_allclose(back.depth_mean[::-1], got.depth_mean, rtol=1e-15, atol=0)
    assert_allclose(back.velocity_sd[::-1], got.velocity_sd, rtol=1e-15, atol=0)


@pytest.mark.parametrize(("N", "q"), [(6, 0.0), (12, 0.03), (25, 0.0)])
def test_placed_moments_match_the_dense_depth_rule_within_their_error(N, q):
    sim, prior = long_track(N, q, seed=30 + N)
    ref = key_moments(converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov, q=q))
    got = bpost.moments(sim.mu, RHO_200, prior.mean, prior.cov, q)
    sd = np.array([got.depth_sd[0]] * 2 + [got.velocity_sd[0]] * 2)
    error = np.array([got.depth_error[0]] * 2 + [got.velocity_error[0]] * 2)
    # the reference is converged to 1e-11 relative; the placed nodes to 1e-10 of the SD
    assert np.all(error <= 1e-10 * sd)
    assert np.all(np.abs(key(got) - ref) <= error + 1e-10 * sd + 2e-11 * np.abs(ref))


def test_posterior_nodes_carry_the_quadrature_moments_and_errors():
    sim, prior = long_track(10, 0.02, seed=40)
    m = bpost.moments(sim.mu, RHO_200, prior.mean, prior.cov, 0.02)
    post = bpost.posterior(sim.mu, RHO_200, prior.mean, prior.cov, 0.02)
    assert post.log_normaliser.shape == ()
    assert_allclose(key_moments(post), key(m), rtol=0, atol=1e-12 * m.depth_sd[0])
    assert post.depth_error == m.depth_error[0] and post.rtol == 1e-10
    # the marginals on the placed nodes: the depth density integrates to its CDF's limits
    y = post.depth_mean + post.depth_sd * np.array([-30.0, 0.0, 30.0])
    cdf = post.depth_cdf(y)
    assert cdf[0] < 1e-12 and cdf[2] > 1 - 1e-12 and 0.3 < cdf[1] < 0.7
    # the smoothed state at every frame: the depth advances by one, the last frame is filtered
    sm = post.smoothed()
    assert_allclose(sm.depth_mean, post.depth_mean - np.arange(9, -1, -1), rtol=1e-13)
    assert_allclose(sm.mean[-1], post.mean, rtol=1e-11, atol=1e-13)


def test_online_update_matches_the_quadrature_from_scratch_and_rarely_re_places():
    N, q = 40, 0.0
    sim, prior = long_track(N, q, seed=41)
    post = bpost.posterior(sim.mu[:3], RHO_200, prior.mean, prior.cov, q)
    re_placed = 0
    for k in range(3, N):
        before = post.bank.nodes
        post = bpost.update(post, sim.mu[k])
        re_placed += not np.array_equal(post.bank.nodes, before)
        if k % 6 == 0 or k == N - 1:
            fresh = bpost.moments(sim.mu[: k + 1], RHO_200, prior.mean, prior.cov, q)
            tol = 3 * (post.depth_error + fresh.depth_error[0]) + 1e-12 * fresh.depth_sd[0]
            assert abs(post.depth_mean - fresh.depth_mean[0]) <= tol
            assert abs(post.depth_sd - fresh.depth_sd[0]) <= tol
            assert post.depth_error <= 1e-10 * post.depth_sd
            vtol = 3 * (post.velocity_error + fresh.velocity_error[0])
            assert abs(post.velocity_sd - fresh.velocity_sd[0]) <= vtol + 1e-12 * post.velocity_sd
    assert post.bank.frames == N
    # the posterior narrows by a factor of several over the frames; the nodes follow it
    # in a few re-placements, not one per frame
    assert 1 <= re_placed <= (N - 3) // 3


def test_online_update_of_a_batch_re_places_only_the_problems_that_need_it():
    N, q = 12, 0.0
    tracks = [long_track(N, q, seed=50 + i) for i in range(4)]
    mu = np.stack([t[0].mu for t in tracks])
    prior = tracks[0][1]
    post = bpost.posterior(mu[:, :3], RHO_200, prior.mean, prior.cov, q)
    for k in range(3, N):
        post = bpost.update(post, mu[:, k])
    fresh = bpost.moments(mu, RHO_200, prior.mean, prior.cov, q)
    tol = 3 * (post.depth_error + fresh.depth_error) + 1e-12 * fresh.depth_sd
    assert np.all(np.abs(post.depth_mean - fresh.depth_mean) <= tol)
    one = bpost.posterior(mu[2, :3], RHO_200, prior.mean, prior.cov, q)
    for k in range(3, N):
        one = bpost.update(one, mu[2, k])
    assert abs(one.depth_mean - post.depth_mean[2]) <= 3 * (one.depth_error + post.depth_error[2])


@pytest.mark.parametrize(
    ("truth", "N", "rho", "q", "prior_mean", "scale"),
    [
        ((0.0, 4.0, 1.0), 10, 1e-9, 0.0, (0.0, 4.0, 0.0), 1e3),  # tiny noise
        ((0.0, 4.0, 1.0), 300, 1e-9, 0.0, (0.0, 4.0, 0.0), 1e3),  # and many frames
        ((0.0, 4.0, 1.0), 10, 1.0, 0.05, (0.0, 4.0, 0.0), 1e3),  # huge noise
        ((0.0, 1e9, 1.0), 10, 1e-9, 0.0, (0.0, 1e9, 0.0), 1e12),  # far point, huge prior
        ((0.0, 4.0, 1.0), 30, 1 / 200, 0.05, (0.0, 4.0, 1.0), 1e-12),  # tiny prior
        ((0.0, 0.01, 1.0), 5, 1 / 200, 0.0, (0.0, 4.0, 0.0), 1e3),  # a point at the camera
    ],
)
def test_placed_bank_answers_extreme_inputs_with_finite_moments_and_errors(
    truth, N, rho, q, prior_mean, scale
):
    sim = model.simulate(np.array(truth), N, rho, q, np.random.default_rng(60), frame=1)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = bpost.moments(sim.mu, rho, prior_mean, scale * np.eye(3), q)
    values = np.concatenate([key(m), m.depth_error, m.velocity_error])
    assert np.all(np.isfinite(values)) and m.depth_sd[0] > 0 and m.velocity_sd[0] > 0
    # accurate to the tolerance, or to the roundoff floor where that is larger
    eps = np.finfo(float).eps
    assert m.depth_error[0] <= max(1e-10 * m.depth_sd[0], 1e5 * eps * abs(m.depth_mean[0]))


def test_placed_bank_refuses_what_double_precision_cannot_resolve():
    # a prior pinned to 1e-6 in conflict with bearings of noise 1e-9
    sim = model.simulate(
        np.array([0.0, 4.0, 1.0]), 3, 1e-9, 0.0, np.random.default_rng(61), frame=1
    )
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"mu\[0\] = .* too narrow"):
            bpost.moments(sim.mu, 1e-9, [-1e3, 1e3, 1e3], 1e-12 * np.eye(3))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(process_noise=-0.1), "process_noise must be >= 0"),
        (dict(process_noise=[0.1, 0.2]), "process_noise must be a scalar or have shape"),
        (dict(process_noise=np.nan), "process_noise must be finite"),
        (dict(mu=[0.1, np.inf, 0.3]), "mu must be finite"),
        (dict(rho=0.0), "rho must be positive"),
        (dict(prior_cov=-np.eye(3)), "prior_cov"),
        (dict(rtol=0.0), "rtol must be"),
        (dict(mu=np.zeros(bpost.MAX_FRAMES + 1)), f"at most {bpost.MAX_FRAMES} frames"),
    ],
)
def test_placed_bank_refuses_bad_input_naming_the_argument(kwargs, message):
    args = dict(mu=list(MU_17), rho=RHO_200, prior_mean=[0.0, 4.0, 0.0], prior_cov=np.eye(3) * 1e3)
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        bpost.moments(**args)


def test_update_refuses_bad_input():
    post = bpost.posterior(list(MU_17), RHO_200, [0.0, 4.0, 0.0], 1e3 * np.eye(3))
    with pytest.raises(ValueError, match="mu_next must be finite"):
        bpost.update(post, np.nan)
    with pytest.raises(ValueError, match="mu_next must be a scalar"):
        bpost.update(post, [0.1, 0.2])
    y, w = log_depth_rule(10)
    loose = bmix.mixture(
        bk.filter_bank(y, list(MU_17), RHO_200, [0.0, 4.0, 0.0], 1e3 * np.eye(3)), w
    )
    with pytest.raises(ValueError, match="post must be a Mixture from bank_posterior.posterior"):
        bpost.update(loose, 0.5)


def test_online_update_stays_exact_over_hundreds_of_frames():
    # the mixture's moments are summed about its most probable node: the depth at
    # frame 300 is about 300 SDs of 0.04 from 0, and a normalisation error of one
    # rounding unit would otherwise move the mean by 1e-9 SD
    N = 300
    tracks = [long_track(N, 0.0, seed=70 + i) for i in range(3)]
    mu = np.stack([t[0].mu for t in tracks])
    prior = tracks[0][1]
    post = bpost.posterior(mu[:, :3], RHO_200, prior.mean, prior.cov)
    re_placed = 0
    for k in range(3, N):
        before = post.bank.nodes
        post = bpost.update(post, mu[:, k])
        re_placed += not np.array_equal(post.bank.nodes, before)
    fresh = bpost.moments(mu, RHO_200, prior.mean, prior.cov)
    tol = post.depth_error + fresh.depth_error
    assert np.all(np.abs(post.depth_mean - fresh.depth_mean) <= tol)
    assert np.all(np.abs(post.depth_sd - fresh.depth_sd) <= tol)
    assert re_placed <= 15  # a few re-placements early, none once the nodes have margin


# --- the online update's passes: closed forms and blocks ------------------------------


def test_closed_form_filter_with_shared_nodes_equals_the_kalman_route():
    # textbook 19.2.1-19.2.2 as 2 x 2 algebra (lateral_filter, step) against kalman.run
    # (history=True), with nodes, noise and prior shared by a batch of bearings
    rng = np.random.default_rng(80)
    sim, prior = long_track(9, 0.0, seed=80)
    mu = sim.mu + 1e-3 * rng.standard_normal((3, 9))
    y = np.array([0.3, 2.0, 3.7, 5.5, 20.0])
    for q in (0.0, 0.03):
        closed = bk.filter_bank(y, mu[:, :7], RHO_200, prior.mean, prior.cov, q)
        closed = bk.step(bk.step(closed, mu[:, 7]), mu[:, 8])
        route = bk.filter_bank(y, mu, RHO_200, prior.mean, prior.cov, q, history=True)
        # the covariance does not depend on the bearings: one per node, not per trial
        assert closed.cov.shape == (y.size, 2, 2) and closed.mean.shape == (3, y.size, 2)
        # the Joseph update's rounding at small depths, as in the batch least squares test
        sd = np.sqrt(np.diagonal(route.cov, axis1=-2, axis2=-1))
        # (a log weight is a sum of terms as large as the largest: its rounding scales with it)
        scale = np.max(np.abs(route.log_weight))
        assert_allclose(closed.log_weight, route.log_weight, rtol=1e-9, atol=1e-11 * scale)
        assert np.all(np.abs(closed.mean - route.mean) <= 1e-7 * sd)
        assert_allclose(np.broadcast_to(closed.cov, route.cov.shape), route.cov, rtol=1e-8)


def test_the_closed_form_update_is_defined_for_a_bearing_without_noise():
    """With r = 0 the updated Var[x] is 0 and Var[v] the limit c - b**2 / a, finite: the
    form (det + c r) / (a + r) of lateral_filter, where (det' + b'**2) / a' is 0 / 0."""
    y = np.array([2.0, 5.0])
    mean, cov = np.array([0.0, 4.0, 0.1]), np.diag([1.0, 4.0, 0.25]) + 0.1
    with np.errstate(all="raise"):
        _, _, (a, b, c) = bk.lateral_filter(y, np.array([[0.2]]), 0.0, 0.0, mean, cov)
    given = bk.conditional_prior(y, mean, cov)[0].cov[..., 0, :, :]
    a0, b0, c0 = given[..., 0, 0], given[..., 0, 1], given[..., 1, 1]
    assert np.all(a == 0.0) and np.all(b == 0.0)
    assert_allclose(np.broadcast_to(c, (1, 2))[0], c0 - b0**2 / a0, rtol=1e-12)


EPS = np.finfo(float).eps


def naive_mixture_moments(W, means, covs, depths):
    """The law of total variance node by node, in two passes (mean, then deviations)."""
    p = W / W.sum()
    m = np.column_stack([means[:, 0], depths, means[:, 1]])
    mean = p @ m
    cov = np.zeros((3, 3))
    for j in range(len(p)):
        c = np.zeros((3, 3))
        c[np.ix_([0, 2], [0, 2])] = covs[j]
        cov += p[j] * (c + np.outer(m[j] - mean, m[j] - mean))
    return mean, cov


@pytest.mark.parametrize("depth", [5.0, 3e3])
def test_stacked_mixture_moments_equal_the_naive_sum_node_by_node(depth):
    rng = np.random.default_rng(81)
    B, J = 3, 40
    W = np.exp(-0.5 * np.linspace(-6, 6, J) ** 2) * rng.uniform(0.5, 1.5, (B, 2, J))
    W[:, 1, ::2] = 0.0  # the second weighting: every other node
    means = rng.standard_normal((B, J, 2)) * [0.1, 0.01] + [0.3, 0.7]
    A = 1e-3 * rng.standard_normal((B, J, 2, 2))
    covs = A @ np.swapaxes(A, -1, -2)
    depths = depth + 0.02 * np.linspace(-1, 1, J) * rng.uniform(0.5, 1.5, (B, 1))
    mean, cov = bmix._stacked_moments(W, means, covs, depths)
    assert mean.shape == (B, 2, 3) and cov.shape == (B, 2, 3, 3)
    for i in range(B):
        for k in range(2):
            m, c = naive_mixture_moments(W[i, k], means[i], covs[i], depths[i])
            scale = np.sqrt(np.diag(c))
            # (the naive sum's own rounding: a few units of the depth's last place)
            assert np.all(np.abs(mean[i, k] - m) <= 1e-12 * scale + 8 * EPS * np.abs(m))
            assert np.all(np.abs(cov[i, k] - c) <= 1e-12 * np.outer(scale, scale))
        one = bmix.mixture_moments(W[i, 0], means[i], covs[i], depths[i])  # one weighting
        assert_allclose(one[0], mean[i, 0], rtol=1e-14)
        assert_allclose(one[1], cov[i, 0], rtol=1e-13, atol=1e-16)


def test_online_update_by_blocks_equals_the_whole_batch_and_leaves_its_input_alone(
    monkeypatch,
):
    # update's passes by blocks of problems give the same numbers as the whole batch at
    # once, across re-placements (which overwrite update's own new arrays, never the input)
    N = 12
    tracks = [long_track(N, 0.0, seed=90 + i) for i in range(5)]
    mu = np.stack([t[0].mu for t in tracks])
    prior = tracks[0][1]
    start = bpost.posterior(mu[:, :3], RHO_200, prior.mean, prior.cov)
    runs = {}
    for block in (1, 10**9):  # one problem per block, and one block
        monkeypatch.setattr(bpost, "_BLOCK", block)
        post, re_placed = start, 0
        for k in range(3, N):
            before = post
            kept = {
                name: np.copy(a)
                for name, a in [
                    ("nodes", post.bank.nodes),
                    ("mean", post.bank.mean),
                    ("cov", post.bank.cov),
                    ("log_weight", post.bank.log_weight),
                    ("log_weights", post.log_weights),
                    ("probabilities", post.probabilities),
                    ("moments", post.mean),
                ]
            }
            post = bpost.update(post, mu[:, k])
            re_placed += not np.array_equal(post.bank.nodes, before.bank.nodes)
            assert_allclose(before.bank.nodes, kept["nodes"], rtol=0, atol=0)
            assert_allclose(before.bank.mean, kept["mean"], rtol=0, atol=0)
            assert_allclose(before.bank.cov, kept["cov"], rtol=0, atol=0)
            assert_allclose(before.bank.log_weight, kept["log_weight"], rtol=0, atol=0)
            assert_allclose(before.log_weights, kept["log_weights"], rtol=0, atol=0)
            assert_allclose(before.probabilities, kept["probabilities"], rtol=0, atol=0)
            assert_allclose(before.mean, kept["moments"], rtol=0, atol=0)
        assert re_placed >= 1
        runs[block] = post
    a, b = runs.values()
    for field in ("log_weights", "probabilities", "log_normaliser", "mean", "cov"):
        assert_allclose(getattr(a, field), getattr(b, field), rtol=0, atol=0)
    for field in ("depth_error", "velocity_error"):
        assert_allclose(getattr(a, field), getattr(b, field), rtol=0, atol=0)
    for field in ("nodes", "mean", "cov", "log_weight", "mu"):
        assert_allclose(getattr(a.bank, field), getattr(b.bank, field), rtol=0, atol=0)


def test_placed_batches_joined_keep_each_problems_mixture():
    # more problems than the quadrature places together: the chunks' mixtures are joined
    # (their node counts padded with zero weights), not recomputed; recomputing agrees
    rng = np.random.default_rng(91)
    B = bpost._CHUNK + 6
    sim, prior = long_track(3, 0.0, seed=91)
    mu = sim.mu + 2e-3 * rng.standard_normal((B, 3))
    post = bpost.posterior(mu, RHO_200, prior.mean, prior.cov)
    assert np.any(~np.isfinite(post.log_weights))  # some rows padded
    shift = np.max(post.log_weights, axis=-1, keepdims=True)
    again = bmix.mixture(post.bank, np.exp(post.log_weights - shift))
    assert_allclose(post.probabilities, again.probabilities, rtol=1e-12, atol=1e-300)
    assert_allclose(post.log_normaliser, again.log_normaliser + shift[:, 0], rtol=1e-14)
    assert_allclose(post.mean, again.mean, rtol=1e-13)
    assert_allclose(post.cov, again.cov, rtol=1e-11, atol=1e-16)
    one = bpost.posterior(mu[B - 1], RHO_200, prior.mean, prior.cov)
    assert_allclose(post.mean[B - 1], one.mean, rtol=1e-14)


def test_update_of_a_posterior_on_one_node_re_places_it_without_warnings():
    # rho = 1e-12: after the second bearing the posterior sits on one node, so every
    # other node carries no weight and the halved moments are undefined; the update
    # must re-place the nodes (not divide by zero) and answer with finite moments
    fig2 = SCENARIOS["fig2"]
    mu = np.asarray(fig2.mu)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        post = bpost.posterior(mu[:1], 1e-12, fig2.prior.mean, fig2.prior.cov)
        for m in mu[1:]:
            post = bpost.update(post, m)
    direct = bpost.posterior(mu, 1e-12, fig2.prior.mean, fig2.prior.cov)
    assert np.isfinite(post.depth_sd) and post.depth_sd < 1e-9
    assert abs(post.depth_mean - direct.depth_mean) < 1e-6 * direct.depth_mean


@pytest.mark.parametrize("rho", [1e-12, 1e-10])
def test_depth_cdf_at_a_tiny_noise_level_settles_at_its_roundoff_floor(rho):
    # the problem scales with rho: the truth's offset from the mean is a fixed number of
    # SDs, so the CDF at the truth is the same as at rho = 1e-8, where the quadrature
    # reaches its tolerance; at rho = 1e-12 the floor is about 1e-5
    fig2 = SCENARIOS["fig2"]
    x1 = model.G(np.asarray(fig2.c), -2)

    def cdf_at_truth(r):
        sim = model.simulate(x1, 4, r, 0.0, np.random.default_rng(1), size=3, frame=1)
        post = bpost.posterior(sim.mu, r, fig2.prior.mean, fig2.prior.cov)
        return post.depth_cdf(sim.states[:, -1, 1:2])[:, 0]

    assert_allclose(cdf_at_truth(rho), cdf_at_truth(1e-8), rtol=0, atol=1e-4)


@pytest.mark.parametrize("scale", [1.0, 1e12])
def test_update_re_places_a_posterior_that_narrowed_onto_one_node(scale):
    # rho = 1e-12: the third bearing narrows the depth from about 1 to 1e-10, far below
    # the nodes' step, so all the mass falls on one node; the halved mixture reproduces
    # it when that node is kept, so only the one-node rule catches it (before it, the
    # online posterior was 5.97 with SD 0 against the exact 6.0 with SD 1.2e-10)
    fig2 = SCENARIOS["fig2"]
    mu = np.asarray(fig2.mu)
    post = bpost.posterior(mu[:1], 1e-12, fig2.prior.mean, scale * np.eye(3))
    for m in mu[1:]:
        post = bpost.update(post, m)
    direct = bpost.posterior(mu, 1e-12, fig2.prior.mean, scale * np.eye(3))
    assert_allclose(post.depth_mean, direct.depth_mean, rtol=1e-12)
    assert_allclose(post.depth_sd, direct.depth_sd, rtol=1e-6)
    assert np.max(post.probabilities) < 0.5
