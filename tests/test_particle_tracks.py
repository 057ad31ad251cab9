"""The particle filters on tracks as they come: gaps, noise per frame, steps, gates, updates.

The reference is a dense grid over the depth at frame 1: given the depth, the
bearings are linear in ``(x_1, v_1)`` (``mu_k = (x_1 + t_k v_1) / (y_1 + t_k)``
plus noise, ``t_k`` the depth travelled to frame ``k``), so the present
bearings' marginal likelihood and the lateral posterior are Gaussian, built
here by batch least squares from the present bearings alone (no Kalman
recursion, no ``depthcore.exact``).
"""

from __future__ import annotations

import numpy as np
import pytest

from depthcore.particles import importance, resample_move

M = np.array([0.0, 6.0, 0.0])
P = np.diag([4.0, 20.0, 1.0])
K = np.arange(6.0)
#: A six-frame track (state (-1.2, 4, 1.2) at frame 1) with fixed noise.
MU = (-1.2 + 1.2 * K) / (4.0 + K) + np.array([0.004, -0.003, 0.002, 0.005, -0.004, 0.001])
RHO = 0.01


def grid_posterior(mu, rho, steps=None, m=None):
    """Depth and velocity means and SDs at the last frame from a dense grid over ``y_1``.

    ``m``: the prior mean (default ``M``); the prior covariance is ``P``.
    """
    m = M if m is None else m
    mu = np.asarray(mu, float)
    n = mu.size
    steps = np.ones(n - 1) if steps is None else np.asarray(steps, float)
    t = np.concatenate([[0.0], np.cumsum(steps)])
    # depths at frame 1 keeping the point in front of the camera at every frame
    nodes = max(0.0, -t.min()) + np.linspace(1e-3, 60.0, 60001)
    rho = np.broadcast_to(np.asarray(rho, float), mu.shape)
    keep = ~np.isnan(mu)
    mu, t, rho = mu[keep], t[keep], rho[keep]
    y = nodes[:, None]
    # (x_1, v_1) given y_1: the prior conditioned on the depth
    u = [0, 2]
    Puu, Puy, Pyy = P[np.ix_(u, u)], P[u, 1], P[1, 1]
    m_u = m[u] + np.outer(nodes - m[1], Puy / Pyy)  # (G, 2)
    C_u = Puu - np.outer(Puy, Puy) / Pyy
    H = np.stack([1.0 / (y + t), t / (y + t)], axis=-1)  # (G, n, 2)
    S = H @ C_u @ H.transpose(0, 2, 1) + np.diag(rho**2)
    r = mu - np.einsum("gni,gi->gn", H, m_u)
    Sinv_r = np.linalg.solve(S, r[..., None])[..., 0]
    _, logdet = np.linalg.slogdet(S)
    log_w = -0.5 * (logdet + np.sum(r * Sinv_r, -1)) - 0.5 * (nodes - m[1]) ** 2 / Pyy
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    gain = C_u @ H.transpose(0, 2, 1)  # (G, 2, n)
    v_mean = m_u[:, 1] + np.einsum("gn,gn->g", gain[:, 1], Sinv_r)
    v_var = C_u[1, 1] - np.einsum(
        "gn,gn->g", gain[:, 1], np.linalg.solve(S, gain[:, 1][..., None])[..., 0]
    )
    depth = nodes + t[-1] if keep[-1] else nodes + np.sum(steps)
    dm = np.sum(w * depth)
    vm = np.sum(w * v_mean)
    return (
        dm,
        np.sqrt(np.sum(w * (depth - dm) ** 2)),
        vm,
        np.sqrt(np.sum(w * (v_var + (v_mean - vm) ** 2))),
    )


def _agrees(moments, errors, exact, z=4.5):
    for value, error, reference in zip(moments, errors, exact, strict=True):
        assert abs(value - reference) < z * error, (value, reference, error)


@pytest.mark.filterwarnings("error")
def test_importance_regular_track_unchanged_by_the_keywords():
    """Unit steps given, rho per frame constant: draw for draw today's answer."""
    a = importance.run(MU, RHO, M, P, 3000, np.random.default_rng(1))
    b = importance.run(MU, np.full(6, RHO), M, P, 3000, np.random.default_rng(1), steps=np.ones(5))
    np.testing.assert_array_equal(a.log_weights, b.log_weights)
    np.testing.assert_array_equal(a.particles, b.particles)
    assert a.updates.log_predictive.shape == (6,) and not np.any(a.updates.gated)


GAP = np.where(np.isin(np.arange(6), [1, 3]), np.nan, MU)
RHO_FRAMES = np.array([0.01, 0.02, 0.005, 0.01, 0.03, 0.01])
STEPS = np.array([1.0, 0.5, 2.0, 1.0, 1.5])
OUTLIER = np.where(np.arange(6) == 2, 0.5, MU)
WITHOUT = np.where(np.arange(6) == 2, np.nan, MU)


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("rho, steps", [(RHO, None), (RHO_FRAMES, STEPS)])
def test_importance_with_gaps_agrees_with_the_grid(rho, steps):
    """40,000 draws: within 4.5 delta-method errors of the dense grid (errors ~0.003 in depth)."""
    exact = grid_posterior(GAP, rho, steps)
    r = importance.run(GAP, rho, M, P, 40000, np.random.default_rng(1), steps=steps)
    assert r.distinct_ess() > 5000
    _agrees(r.moments(), r.standard_errors(), exact)
    assert np.all(np.isnan(r.updates.log_predictive[[1, 3]]))
    assert np.all(np.isfinite(r.updates.log_predictive[[0, 2, 4, 5]]))


@pytest.mark.filterwarnings("error")
def test_resample_move_with_gaps_rho_and_steps_agrees_with_the_grid():
    """4 replicas of 3,000: within 4.5 replica errors of the grid (error ~0.0017 in depth)."""
    exact = grid_posterior(GAP, RHO_FRAMES, STEPS)
    r = resample_move.replicated(GAP, RHO_FRAMES, M, P, 3000, np.random.default_rng(1), steps=STEPS)
    errors, collapsed = r.errors()
    assert not collapsed[0]
    m = r.moments()
    for name, reference in zip(
        ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd"), exact, strict=True
    ):
        assert abs(m[name][0] - reference) < 4.5 * errors[name][0], name
    assert np.array_equal(np.isnan(r.updates.tail[0]), np.isnan(GAP))


@pytest.mark.filterwarnings("error")
def test_importance_unit_steps_missing_middle_equal_one_step_of_two():
    """Without process noise (these filters have none) two unit steps with the middle
    bearing missing are one step of 2: the same prior draws, the same weights to rounding."""
    mu = np.array([MU[0], np.nan, MU[2], MU[3], MU[4]])
    a = importance.run(mu, RHO, M, P, 2000, np.random.default_rng(4), proposal="prior")
    b = importance.run(
        MU[[0, 2, 3, 4]],
        RHO,
        M,
        P,
        2000,
        np.random.default_rng(4),
        proposal="prior",
        steps=[2, 1, 1],
    )
    np.testing.assert_allclose(a.particles, b.particles, rtol=1e-13, atol=1e-13)
    finite = np.isfinite(a.log_weights)
    np.testing.assert_array_equal(finite, np.isfinite(b.log_weights))
    np.testing.assert_allclose(a.log_weights[finite], b.log_weights[finite], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(a.updates.tail[[0, 2, 3, 4]], b.updates.tail, rtol=1e-9)


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("proposal", ["second_order", "prior"])
def test_importance_gate_equals_the_bearing_missing(proposal):
    options = {"proposal": proposal, "ess_threshold": 0.5 if proposal == "prior" else 0.0}
    a = importance.run(OUTLIER, RHO, M, P, 5000, np.random.default_rng(3), gate=1e-3, **options)
    b = importance.run(WITHOUT, RHO, M, P, 5000, np.random.default_rng(3), gate=1e-3, **options)
    assert a.updates.gated.tolist() == [False, False, True, False, False, False]
    assert a.updates.tail[2] < 1e-3 and np.isnan(b.updates.tail[2])
    np.testing.assert_array_equal(a.particles, b.particles)
    np.testing.assert_array_equal(a.log_weights, b.log_weights)


@pytest.mark.filterwarnings("error")
def test_resample_move_gate_equals_the_bearing_missing():
    a = resample_move.replicated(OUTLIER, RHO, M, P, 1000, np.random.default_rng(3), gate=1e-3)
    b = resample_move.replicated(WITHOUT, RHO, M, P, 1000, np.random.default_rng(3), gate=1e-3)
    assert a.updates.gated[0].tolist() == [False, False, True, False, False, False]
    np.testing.assert_array_equal(a.runs.particles, b.runs.particles)
    np.testing.assert_array_equal(a.runs.log_weights, b.runs.log_weights)


def grid_log_evidence(mu, rho, nodes=None):
    """``log p(present bearings)`` under the prior restricted to ``y_1 > 0``, on a dense grid."""
    from scipy.special import logsumexp
    from scipy.stats import norm

    nodes = np.linspace(1e-4, 80.0, 200001) if nodes is None else nodes
    keep = ~np.isnan(mu)
    t, m = np.arange(mu.size, dtype=float)[keep], mu[keep]
    u = [0, 2]
    Puu, Puy, Pyy = P[np.ix_(u, u)], P[u, 1], P[1, 1]
    m_u = M[u] + np.outer(nodes - M[1], Puy / Pyy)
    C_u = Puu - np.outer(Puy, Puy) / Pyy
    y = nodes[:, None]
    H = np.stack([1 / (y + t), t / (y + t)], -1)
    S = H @ C_u @ H.transpose(0, 2, 1) + RHO**2 * np.eye(t.size)
    r = m - np.einsum("gni,gi->gn", H, m_u)
    _, logdet = np.linalg.slogdet(S)
    log_l = -0.5 * (logdet + np.sum(r * np.linalg.solve(S, r[..., None])[..., 0], -1))
    log_l -= 0.5 * t.size * np.log(2 * np.pi)
    log_prior = norm.logpdf(nodes, M[1], np.sqrt(Pyy)) - norm.logcdf(M[1] / np.sqrt(Pyy))
    return logsumexp(log_l + log_prior) + np.log(nodes[1] - nodes[0])


@pytest.mark.filterwarnings("error")
def test_log_predictive_sums_to_the_log_evidence():
    """Summed over the frames, the log predictive densities are the log evidence of the present
    bearings (3.11 on the grid). The importance sampler's estimate with 40,000 draws scatters
    by about 0.06 over seeds (its early frames weigh a proposal fitted to the last one), so
    the bound is 0.25."""
    r = importance.run(GAP, RHO, M, P, 40000, np.random.default_rng(2))
    assert abs(np.nansum(r.updates.log_predictive) - grid_log_evidence(GAP, RHO)) < 0.25
    rm = resample_move.replicated(GAP, RHO, M, P, 2000, np.random.default_rng(2))
    assert abs(np.nansum(rm.updates.log_predictive) - grid_log_evidence(GAP, RHO)) < 0.25


def test_refusals_name_the_argument():
    with pytest.raises(ValueError, match="^gate"):
        importance.run(MU, RHO, M, P, 100, np.random.default_rng(0), gate=2.0)
    with pytest.raises(ValueError, match="^steps"):
        resample_move.replicated(MU, RHO, M, P, 100, np.random.default_rng(0), steps=[1, 1])
    with pytest.raises(ValueError, match="^mu"):
        importance.run(
            np.where(np.arange(6) < 4, np.nan, MU), RHO, M, P, 100, np.random.default_rng(0)
        )


@pytest.mark.filterwarnings("error")
def test_rbpf_with_gaps_rho_and_steps_agrees_with_the_grid():
    """8 replicas of 500 particles: within 4.5 replica errors of the grid."""
    from depthcore.particles import rbpf

    exact = grid_posterior(GAP, RHO_FRAMES, STEPS)
    r = rbpf.run(GAP, RHO_FRAMES, M, P, 500, np.random.default_rng(1), replicas=8, steps=STEPS)
    _agrees(r.moments(), r.standard_errors(), exact)
    assert np.array_equal(np.isnan(r.updates.tail), np.isnan(GAP))
    # the summed log predictive estimates the log evidence (the grid's, to Monte Carlo error)
    r = rbpf.run(GAP, RHO, M, P, 500, np.random.default_rng(1), replicas=8)
    assert abs(np.nansum(r.updates.log_predictive) - grid_log_evidence(GAP, RHO)) < 0.25


@pytest.mark.filterwarnings("error")
def test_rbpf_gate_is_the_bearing_missing_draw_for_draw():
    from depthcore.particles import rbpf

    gated = rbpf.run(OUTLIER, RHO, M, P, 200, np.random.default_rng(2), replicas=2, gate=1e-3)
    missing = rbpf.run(WITHOUT, RHO, M, P, 200, np.random.default_rng(2), replicas=2)
    assert gated.updates.gated.tolist() == [False, False, True, False, False, False]
    np.testing.assert_array_equal(gated.log_weights, missing.log_weights)
    np.testing.assert_array_equal(gated.bank.nodes, missing.bank.nodes)


def test_rbpf_unit_steps_and_constant_rho_are_the_papers_draws():
    from depthcore.particles import rbpf

    a = rbpf.run(MU, RHO, M, P, 200, np.random.default_rng(3), replicas=2)
    b = rbpf.run(
        MU, np.full(6, RHO), M, P, 200, np.random.default_rng(3), replicas=2, steps=np.ones(5)
    )
    np.testing.assert_allclose(b.log_weights, a.log_weights, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b.state_moments()[0], a.state_moments()[0], rtol=1e-12)


#: A camera that approaches the point: the steps of STEPS towards it, from depth 10 at frame 1.
APPROACH_STEPS = -STEPS
APPROACH_MU = (-1.2 + 1.2 * np.concatenate([[0.0], np.cumsum(APPROACH_STEPS)])) / (
    10.0 + np.concatenate([[0.0], np.cumsum(APPROACH_STEPS)])
) + np.array([0.004, -0.003, 0.002, 0.005, -0.004, 0.001])
APPROACH_M = np.array([0.0, 9.0, 0.0])


@pytest.mark.filterwarnings("error")
def test_the_particle_filters_agree_with_the_grid_when_the_camera_approaches():
    """Negative steps: the particles that the steps bring to the camera lose their weight;
    importance sampling (40,000 draws), resample-move (4 x 3,000) and the RBPF (8 x 500)
    within 4.5 of their errors of the grid above the depth where the point would reach it."""
    from depthcore.particles import rbpf

    exact = grid_posterior(APPROACH_MU, RHO_FRAMES, APPROACH_STEPS, APPROACH_M)
    assert exact[0] > 0 and exact[0] < 10.0 + np.sum(APPROACH_STEPS) + 5 * exact[1]
    rng = np.random.default_rng(4)
    args = (APPROACH_MU, RHO_FRAMES, APPROACH_M, P)
    r = importance.run(*args, 40000, rng, steps=APPROACH_STEPS)
    _agrees(r.moments(), r.standard_errors(), exact)
    r = resample_move.replicated(*args, 3000, rng, steps=APPROACH_STEPS)
    errors, collapsed = r.errors()
    assert not collapsed[0]
    m = r.moments()
    names = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")
    _agrees([m[k][0] for k in names], [errors[k][0] for k in names], exact)
    r = rbpf.run(*args, 500, rng, replicas=8, steps=APPROACH_STEPS)
    _agrees(r.moments(), r.standard_errors(), exact)
