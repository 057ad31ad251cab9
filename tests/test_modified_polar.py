"""The modified-polar EKF (Aidala & Hammel 1983) and its relation to the inverse-depth EKF."""

import numpy as np
import pytest

from depthcore.kalman import inverse_depth, modified_polar
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS

FIG2 = SCENARIOS["fig2"]
TRUTH = np.array([1.2, 4.0, -0.2])
U = np.array([0.3, 0.25, -0.05])
Z = np.array([0.2, 0.15, 0.05])
S = np.array([[0.01, 0.001, 0.002], [0.001, 0.0009, 0.0001], [0.002, 0.0001, 0.003]])


def polar(state):
    """``(x, 1, v) / y`` of states (..., 3)."""
    state = np.asarray(state, dtype=float)
    return np.stack([state[..., 0], np.ones(state.shape[:-1]), state[..., 2]], -1) / state[..., 1:2]


def numerical_jacobian(f, u, h=1e-6):
    return np.stack([(f(u + h * e) - f(u - h * e)) / (2 * h) for e in np.eye(3)], axis=-1)


def test_transition_is_the_motion_of_eq_1():
    """``(x, 1, v) / y`` of ``G(state)`` is the transition of ``(x, 1, v) / y``."""
    for state in ([1.2, 4.0, -0.2], [-3.0, 0.5, 2.0], [0.0, 30.0, 0.1]):
        np.testing.assert_allclose(
            modified_polar.transition(polar(state)), polar(model.G(state, 1)), rtol=1e-14
        )


def test_jacobians_by_central_differences():
    np.testing.assert_allclose(
        modified_polar.transition_jacobian(U),
        numerical_jacobian(modified_polar.transition, U),
        rtol=1e-8,
        atol=1e-10,
    )
    for k in (1, 2, 5):
        np.testing.assert_allclose(
            modified_polar.anchor_jacobian(Z, k),
            numerical_jacobian(lambda z, k=k: modified_polar.anchor_map(z, k), Z),
            rtol=1e-8,
            atol=1e-10,
        )


def test_the_anchor_maps_compose_with_the_motions():
    """``phi_{k+1}`` of the inverse-depth motion is the transition of ``phi_k``."""
    for k in (1, 2, 7):
        moved = inverse_depth.predict(Z, S).mean
        np.testing.assert_allclose(
            modified_polar.anchor_map(moved, k + 1),
            modified_polar.transition(modified_polar.anchor_map(Z, k)),
            rtol=1e-14,
        )


@pytest.mark.parametrize("q", [0.0, 0.05])
@pytest.mark.parametrize("k", [2, 3, 6])
def test_one_step_from_corresponding_gaussians(k, q):
    """The docstring's relation, exact to rounding: predictions and updated covariances
    correspond through phi_k; the means differ by phi_k's remainder over the update's step."""
    J = modified_polar.anchor_jacobian(Z, k - 1)
    u, Uc = modified_polar.anchor_map(Z, k - 1), J @ S @ J.T
    # the inverse-depth EKF from (Z, S), the modified-polar EKF from its image
    z_bar, S_bar = inverse_depth.predict(Z, S, q)
    u_bar, U_bar = modified_polar.predict(u, Uc, q)
    Jk = modified_polar.anchor_jacobian(z_bar, k)
    np.testing.assert_allclose(u_bar, modified_polar.anchor_map(z_bar, k), rtol=1e-13)
    np.testing.assert_allclose(U_bar, Jk @ S_bar @ Jk.T, rtol=1e-11, atol=1e-16)
    mu = modified_polar.anchor_map(z_bar, k)[0] + 0.02
    z_new, S_new = inverse_depth.update(z_bar, S_bar, mu, 0.01, k)
    u_new, U_new = modified_polar.update(u_bar, U_bar, mu, 0.01)
    np.testing.assert_allclose(U_new, Jk @ S_new @ Jk.T, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(u_new, u_bar + Jk @ (z_new - z_bar), rtol=1e-11, atol=1e-15)
    # and the remainder is second order: not zero, and not the mapped mean
    assert np.max(np.abs(u_new - modified_polar.anchor_map(z_new, k))) > 1e-8


def test_equal_to_the_inverse_depth_ekf_at_frame_1():
    a = modified_polar.run([0.31], 0.01, TRUTH, np.diag([1.0, 2.0, 0.5]))
    b = inverse_depth.run([0.31], 0.01, TRUTH, np.diag([1.0, 2.0, 0.5]))
    np.testing.assert_allclose(a[0], b[0], rtol=1e-14)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-12, atol=1e-18)


def test_coincides_with_the_inverse_depth_ekf_as_the_depth_becomes_known():
    """Prior depth SD d: the estimates in (x, y, v) differ by O(d) SDs (10x per decade)."""
    mu = np.array([model.project(model.G(TRUTH, k)) for k in range(6)])
    mu = mu + np.random.default_rng(1).normal(0.0, 0.005, 6)
    diffs = []
    for d in (1e-2, 1e-3, 1e-4):
        P = np.diag([1.0, d**2, 0.25])
        a = modified_polar.estimate(mu, 0.005, TRUTH, P)
        b = inverse_depth.estimate(mu, 0.005, TRUTH, P)
        sd = np.sqrt(np.diag(b.cov))
        diffs.append(np.max(np.abs(a.mean - b.mean) / sd))
        np.testing.assert_allclose(np.sqrt(np.diag(a.cov)), sd, rtol=0.1 * d / 1e-2)
    assert diffs[2] < 2e-5
    assert diffs[1] < diffs[0] / 8 and diffs[2] < diffs[1] / 8


def test_registry_entry_and_batch():
    f = FILTERS["modified_polar"]
    assert f.any_frames and f.with_process_noise and not f.default
    mu = np.array([model.project(model.G(TRUTH, k)) for k in range(4)])
    batch = np.stack([mu, mu + 0.003, mu - 0.002])
    P0 = np.diag([0.5, 1.0, 0.1])
    est = f(batch, 0.005, TRUTH, P0, 0.01)
    for b in range(3):
        one = modified_polar.estimate(batch[b], 0.005, TRUTH, P0, 0.01)
        np.testing.assert_allclose(est.mean[b], one.mean, rtol=1e-12)
        np.testing.assert_allclose(est.cov[b], one.cov, rtol=1e-10)
    paper = f(np.array(FIG2.mu), FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    assert np.isfinite(paper.depth_mean) and paper.depth_sd > 0


def test_refusals():
    with pytest.raises(ValueError, match="prior_mean"):
        modified_polar.run(np.array(FIG2.mu), FIG2.rho, [1, -4, 0], np.eye(3))
    with pytest.raises(ValueError, match="process_noise"):
        modified_polar.run(np.array(FIG2.mu), FIG2.rho, TRUTH, np.eye(3), -0.1)
    with pytest.raises(ValueError, match="inverse depth is <= -1"):
        modified_polar.predict([0.0, -1.5, 0.0], np.eye(3))
