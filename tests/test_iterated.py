"""Tests of the iterated EKF and the iterated extended Kalman smoother (textbook 19.3)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import least_squares, minimize

from depthcore.exact import optimal
from depthcore.kalman import ekf, iterated
from depthcore.kalman.second_order import bearing_residuals, trajectory_map
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS


def trajectory_residuals(z, mu, rho, prior_mean, prior_cov, process_noise):
    """The trajectory's stacked whitened residuals (negative log posterior) and Jacobian.

    ``z = (x_1, y_1, v_1, a_1 .. a_{K-1})`` (K + 2,); the residuals (2 K + 2,)
    are ``L^{-1} (x_1 - m)``, ``(x_k / y_k - mu_k) / rho`` and ``a_k / q``
    (:func:`depthcore.kalman.iterated.smoother`, textbook 19.3): half their
    squared norm is the negative log posterior up to a constant.

    Returns
    -------
    r : ndarray, shape (2 K + 2,)
    M : ndarray, shape (2 K + 2, K + 2)
    """
    K = mu.shape[-1]
    L_inv = np.linalg.inv(np.linalg.cholesky(prior_cov))
    bearing, J = bearing_residuals(z, mu, trajectory_map(K))
    M = np.zeros((2 * K + 2, K + 2))
    M[:3, :3] = L_inv
    M[3 : K + 3] = J / rho
    M[K + 3 :, 3:] = np.eye(K - 1) / process_noise
    r = np.concatenate([L_inv @ (z[:3] - prior_mean), bearing / rho, z[3:] / process_noise])
    return r, M


def _one_step_objective(x, n, C, mu, rho):
    d = x - n
    return d @ np.linalg.solve(C, d) + (mu - x[0] / x[1]) ** 2 / rho**2


@pytest.mark.parametrize("key", ["fig2", "fig3", "fig6"])
def test_iterated_update_is_the_mode_of_the_one_step_posterior(key):
    """The iterated update's fixed point is the mode of the one-step posterior.

    It minimises |x - n|_C^2 + (mu - h(x))^2 / rho^2 [bell1993].
    """
    s = SCENARIOS[key]
    m1, P1 = ekf.update(s.prior.mean, s.prior.cov, s.mu[0], s.rho)
    n, C = ekf.predict(m1, P1)
    out = iterated.update(n, C, s.mu[1], s.rho)
    best = minimize(
        _one_step_objective,
        out.mean,
        args=(n, C, s.mu[1], s.rho),
        method="BFGS",
        options={"gtol": 1e-10},
    )
    assert _one_step_objective(out.mean, n, C, s.mu[1], s.rho) <= best.fun + 1e-9
    grad = np.array(
        [
            (
                _one_step_objective(out.mean + e, n, C, s.mu[1], s.rho)
                - _one_step_objective(out.mean - e, n, C, s.mu[1], s.rho)
            )
            / (2 * np.linalg.norm(e))
            for e in 1e-6 * np.eye(3)
        ]
    )
    assert np.max(np.abs(grad)) < 1e-3 * np.max(np.abs(np.linalg.solve(C, out.mean - n)) + 1)


def test_an_update_stops_at_the_rounding_of_its_objective():
    """At small noise the iterated update (textbook 19.3) stops within a few dozen iterations.

    Near the mode the Gauss-Newton steps can go back and forth by a unit in
    the last place, more than ``STEP_TOL`` SDs where the SDs are tiny; the
    update stops when a step no longer lowers the objective, at the mode to
    within the objective's rounding, found here independently by
    ``scipy.optimize.least_squares``.
    """
    from depthcore.studies import trials

    rng = np.random.default_rng(3)  # a draw where a step of one unit in the last place recurs
    drawn = trials.simulate(np.array([2.4, 6.0, 2.4]), 1e-4, 60, rng, "paper", frames=3)
    m, P = ekf.update(drawn.prior_mean, drawn.prior_cov, drawn.mu[:, 0], drawn.rho)
    n, C = ekf.predict(m, P)
    out = iterated.update(n, C, drawn.mu[:, 1], drawn.rho)
    assert out.iterations.max() < 20 < iterated.MAX_ITERATIONS
    sd = np.sqrt(np.diagonal(out.cov, axis1=-2, axis2=-1))
    for i in range(len(n)):
        L_inv = np.linalg.inv(np.linalg.cholesky(C[i]))

        def residuals(x, i=i, L_inv=L_inv):
            return np.append(L_inv @ (x - n[i]), (drawn.mu[i, 1] - x[0] / x[1]) / drawn.rho)

        mode = least_squares(residuals, out.mean[i], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        assert np.max(np.abs(out.mean[i] - mode) / sd[i]) < 1e-6
        f = np.sum(residuals(out.mean[i]) ** 2)
        assert f <= np.sum(residuals(mode) ** 2) * (1 + 1e-12)


def test_one_iteration_is_the_ekf_update_eq_12():
    """With one iteration (and an objective that the EKF step decreases) the update is Eq. (12)."""
    s = SCENARIOS["fig2"]
    n, C = ekf.predict(*ekf.update(s.prior.mean, s.prior.cov, s.mu[0], s.rho))
    e = ekf.update(n, C, s.mu[1], s.rho)
    assert _one_step_objective(e.mean, n, C, s.mu[1], s.rho) < _one_step_objective(
        n, n, C, s.mu[1], s.rho
    )
    one = iterated.update(n, C, s.mu[1], s.rho, max_iterations=1)
    np.testing.assert_allclose(one.mean, e.mean, rtol=1e-12)
    np.testing.assert_allclose(one.cov, e.cov, rtol=1e-10, atol=1e-12 * np.max(np.abs(e.cov)))


def test_linear_measurement_needs_one_iteration():
    """At a state the projection maps linearly near (a tiny covariance).

    There the iteration stops at once.
    """
    n = np.array([1.0, 5.0, 0.5])
    out = iterated.update(n, 1e-12 * np.eye(3), 0.2, 0.01)
    assert out.iterations <= 3


@pytest.mark.parametrize("key", ["fig2", "fig3", "fig5", "fig6"])
def test_smoother_converges_to_the_mode_of_eq_6(key):
    """The iterated smoother's fixed point is the mode of the optimal posterior, Eq. (6)."""
    s = SCENARIOS[key]
    sm = iterated.smoother(np.array(s.mu), s.rho, s.prior.mean, s.prior.cov)
    assert sm.converged

    def f(x3):
        return -optimal.log_posterior(x3, s.mu, s.rho, s.prior)

    best = minimize(
        f, sm.mean, method="Nelder-Mead", options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 20000}
    )
    assert f(sm.mean) <= best.fun + 1e-8
    np.testing.assert_allclose(sm.mean, best.x, atol=1e-5)


def test_smoother_covariance_is_the_gauss_newton_inverse_at_the_mode():
    """cov = F^2 (P^-1 + sum J_k^T J_k / rho^2)^-1 F^2T.

    J is taken by central differences of the bearings.
    """
    s = SCENARIOS["fig3"]
    sm = iterated.smoother(np.array(s.mu), s.rho, s.prior.mean, s.prior.cov)
    x1 = model.G(sm.mean, -2)

    def bearings(x):
        return np.array([model.project(model.G(x, k)) for k in range(3)])

    J = np.stack([(bearings(x1 + e) - bearings(x1 - e)) / 2e-6 for e in 1e-6 * np.eye(3)], axis=1)
    info = np.linalg.inv(s.prior.cov) + J.T @ J / s.rho**2
    F2 = model.G_linear(2)
    np.testing.assert_allclose(sm.cov, F2 @ np.linalg.inv(info) @ F2.T, rtol=1e-6)


def test_iterated_ekf_removes_most_of_the_prior_mean_dependence_on_fig6():
    """Fig. 6 moves the prior's depth by 2.

    The EKF's depth moves by over 2, the iterated EKF's by < 0.01.
    """
    a, b = SCENARIOS["fig2"], SCENARIOS["fig6"]
    it_a = iterated.run(np.array(a.mu), a.rho, a.prior.mean, a.prior.cov)[0][-1]
    it_b = iterated.run(np.array(b.mu), b.rho, b.prior.mean, b.prior.cov)[0][-1]
    e_a = ekf.run(np.array(a.mu), a.rho, a.prior.mean, a.prior.cov)[0][-1]
    e_b = ekf.run(np.array(b.mu), b.rho, b.prior.mean, b.prior.cov)[0][-1]
    assert abs(e_b[1] - e_a[1]) > 2.0
    assert abs(it_b[1] - it_a[1]) < 0.01


def test_any_number_of_frames_and_process_noise():
    truth = np.array([-1.2, 4.0, 1.2])
    mu = model.project(np.stack([model.G(truth, k) for k in range(8)]))
    prior_mean, prior_cov = np.array([-1.0, 5.0, 0.0]), 10.0 * np.eye(3)
    means, covs = iterated.run(mu, 1e-3, prior_mean, prior_cov)
    assert means.shape == (8, 3) and covs.shape == (8, 3, 3)
    np.testing.assert_allclose(means[-1], model.G(truth, 7), atol=0.05)
    noisy = iterated.run(mu, 1e-3, prior_mean, prior_cov, process_noise=0.1)[1]
    assert noisy[-1][2, 2] > covs[-1][2, 2]
    sm = iterated.smoother(mu, 1e-3, prior_mean, prior_cov)
    np.testing.assert_allclose(sm.mean, model.G(truth, 7), atol=1e-3)


def test_batched_equals_looped():
    s = SCENARIOS["fig2"]
    mu = np.array([s.mu, SCENARIOS["fig3"].mu])
    means, covs = iterated.run(mu, s.rho, s.prior.mean, s.prior.cov)
    sm = iterated.smoother(mu, s.rho, s.prior.mean, s.prior.cov)
    for i in range(2):
        m1, c1 = iterated.run(mu[i], s.rho, s.prior.mean, s.prior.cov)
        np.testing.assert_allclose(means[i], m1, rtol=1e-12)
        np.testing.assert_allclose(covs[i], c1, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(
            sm.mean[i], iterated.smoother(mu[i], s.rho, s.prior.mean, s.prior.cov).mean, rtol=1e-10
        )


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"mu": [np.inf, 0.0, 0.2]}, "mu"),
        ({"mu": []}, "mu"),
        ({"rho": 0.0}, "rho"),
        ({"process_noise": -1.0}, "process_noise"),
        ({"prior_mean": [0.0, -3.0, 0.0]}, "prior_mean"),
    ],
)
def test_bad_input_is_refused(kwargs, name):
    s = SCENARIOS["fig2"]
    args = {"mu": s.mu, "rho": s.rho, "prior_mean": s.prior.mean, "prior_cov": s.prior.cov}
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        iterated.run(**args)


@pytest.mark.parametrize("n_frames", [3, 5, 8])
@pytest.mark.parametrize("q", [0.0, 0.03])
def test_one_iteration_per_update_is_the_ekf_for_any_frames_and_process_noise(n_frames, q):
    rng = np.random.default_rng(n_frames)
    x1 = np.array([-1.0, 6.0, 0.4])
    mu = model.simulate(x1, n_frames, 2e-3, 0.0, rng, size=3, frame=1).mu
    prior_mean = x1 + [0.1, -0.5, 0.05]
    prior_cov = np.diag([0.5, 2.0, 0.05])
    means, covs = iterated.run(mu, 2e-3, prior_mean, prior_cov, q, max_iterations=1)
    e = ekf.run(mu, 2e-3, prior_mean, prior_cov, process_noise=q)
    assert_allclose(means, e.means, rtol=1e-9)
    assert_allclose(covs, e.covs, rtol=1e-6, atol=1e-9 * np.abs(e.covs).max())


# --- the iterated extended Kalman smoother with process noise (textbook 19.3) ---------


def _noisy_track(q=0.02, frames=8, seed=3):
    from depthcore.problem.gaussian import paper_prior
    from depthcore.problem.scenarios import RHO_200

    s = SCENARIOS["fig2"]
    sim = model.simulate(model.G(s.c, -2), frames, RHO_200, q, np.random.default_rng(seed), frame=1)
    return sim.mu, RHO_200, paper_prior(s.c)


def _negative_log_posterior_residuals(z, mu, rho, prior, q):
    """Written from the model alone: the recursion x_{k+1} = x_k + v_k, y_{k+1} = y_k + 1,
    v_{k+1} = v_k + a_k run frame by frame, the prior whitened by its Cholesky factor."""
    state = z[:3].copy()
    bearings = []
    for k in range(len(mu)):
        bearings.append(state[0] / state[1])
        if k < len(mu) - 1:
            state = np.array([state[0] + state[2], state[1] + 1.0, state[2] + z[3 + k]])
    L = np.linalg.cholesky(prior.cov)
    return np.concatenate(
        [
            np.linalg.solve(L, z[:3] - prior.mean),
            (np.array(bearings) - mu) / rho,
            z[3:] / q,
        ]
    )


def _as_z(trajectory):
    """(x_1, y_1, v_1, a_1 .. a_{K-1}) of a trajectory (K, 3)."""
    return np.concatenate([trajectory[0], np.diff(trajectory[:, 2])])


@pytest.mark.parametrize("q", [0.02, 0.2])
def test_smoother_with_process_noise_is_the_map_of_the_trajectory_gauss_newton(q):
    """Its fixed point is the MAP of the trajectory's posterior (textbook 19.3, Gauss-Newton):
    scipy's least_squares on independently written stacked residuals, from another start,
    finds the same trajectory, and the finite-difference gradient vanishes there."""
    mu, rho, prior = _noisy_track(q)
    sm = iterated.smoother(mu, rho, prior.mean, prior.cov, process_noise=q)
    assert sm.converged and sm.trajectory.shape == (len(mu), 3)
    assert_allclose(sm.trajectory[-1], sm.mean, rtol=1e-12)
    z = _as_z(sm.trajectory)

    def resid(w):
        return _negative_log_posterior_residuals(w, mu, rho, prior, q)

    start = z + np.concatenate([[0.3, 0.5, -0.05], np.zeros(len(mu) - 1)])
    best = least_squares(resid, start, xtol=1e-15, ftol=1e-15, gtol=1e-15, method="lm")

    def f(w):
        return 0.5 * np.sum(resid(w) ** 2)

    # the objective is flat to rounding within about sqrt(eps) relative of the mode
    assert f(z) <= f(best.x) * (1 + 1e-13)
    assert_allclose(z, best.x, rtol=1e-6, atol=1e-9)

    h = 1e-6
    grad = np.array([(f(z + e) - f(z - e)) / (2 * h) for e in h * np.eye(len(z))])
    # the scale of the terms of the gradient: |J^T| |r| with J taken by differences
    J = np.stack([(resid(z + e) - resid(z - e)) / (2 * h) for e in h * np.eye(len(z))], axis=1)
    assert np.max(np.abs(grad)) < 1e-6 * np.max(np.abs(J).T @ np.abs(resid(z)))


def test_smoother_with_process_noise_covariance_is_the_gauss_newton_inverse():
    """cov = T (M^T M)^-1 T^T at the mode, M the Jacobian of the stacked residuals taken
    by central differences of the independently written residuals, T the map to frame K."""
    q = 0.05
    mu, rho, prior = _noisy_track(q, frames=6)
    sm = iterated.smoother(mu, rho, prior.mean, prior.cov, process_noise=q)
    z = _as_z(sm.trajectory)
    h = 1e-6
    M = np.stack(
        [
            (
                _negative_log_posterior_residuals(z + e, mu, rho, prior, q)
                - _negative_log_posterior_residuals(z - e, mu, rho, prior, q)
            )
            / (2 * h)
            for e in h * np.eye(len(z))
        ],
        axis=1,
    )
    r, M_analytic = trajectory_residuals(z, mu, rho, prior.mean, prior.cov, q)
    assert_allclose(M_analytic, M, rtol=1e-6, atol=1e-6)
    assert_allclose(r, _negative_log_posterior_residuals(z, mu, rho, prior, q), rtol=1e-12)
    K = len(mu)
    T = np.zeros((3, K + 2))  # x_K, y_K, v_K from (x_1, y_1, v_1, a)
    T[0, 0], T[0, 2], T[0, 3:] = 1.0, K - 1.0, K - 2.0 - np.arange(K - 1)
    T[1, 1], T[2, 2], T[2, 3:] = 1.0, 1.0, 1.0
    assert_allclose(sm.cov, T @ np.linalg.inv(M.T @ M) @ T.T, rtol=1e-5)


def test_smoother_with_process_noise_reduces_to_the_one_without_as_q_vanishes():
    mu, rho, prior = _noisy_track(0.02)
    none = iterated.smoother(mu, rho, prior.mean, prior.cov)
    for q, tol in ((1e-5, 1e-6), (1e-8, 1e-9)):
        sm = iterated.smoother(mu, rho, prior.mean, prior.cov, process_noise=q)
        assert_allclose(sm.mean, none.mean, rtol=tol)
        assert_allclose(sm.cov, none.cov, rtol=100 * tol)
        # relative to each coordinate's scale along the track: x passes near 0
        scale = np.abs(none.trajectory).max(axis=0)
        assert_allclose((sm.trajectory - none.trajectory) / scale, 0.0, atol=tol)
    # and the process noise matters where it is not small
    big = iterated.smoother(mu, rho, prior.mean, prior.cov, process_noise=0.05)
    assert big.cov[2, 2] > 2 * none.cov[2, 2]


def test_smoother_with_process_noise_batched_equals_looped_and_refuses_bad_noise():
    mu, rho, prior = _noisy_track(0.02)
    both = np.stack([mu, mu + 0.002])
    sm = iterated.smoother(both, rho, prior.mean, prior.cov, process_noise=0.02)
    for i in range(2):
        one = iterated.smoother(both[i], rho, prior.mean, prior.cov, process_noise=0.02)
        assert_allclose(sm.mean[i], one.mean, rtol=1e-12)
        assert_allclose(sm.cov[i], one.cov, rtol=1e-12)
    with pytest.raises(ValueError, match="process_noise must be >= 0"):
        iterated.smoother(mu, rho, prior.mean, prior.cov, process_noise=-0.1)


@pytest.mark.parametrize("frames", [3, 8, 20])
def test_smoother_with_process_noise_equals_the_dense_route(frames):
    """The linear-cost Gauss-Newton against
    :func:`depthbook.reference.iterated_smoother_dense`
    (every step a dense least-squares solve over the whole trajectory), to the resolution of
    their line searches, which stop where the objective no longer decreases in floating point."""
    from depthbook import reference

    q = 0.02
    mu, rho, prior = _noisy_track(q, frames=frames)
    sm = iterated.smoother(mu, rho, prior.mean, prior.cov, process_noise=q)
    mean, cov, _ = reference.iterated_smoother_dense(mu, rho, prior.mean, prior.cov, q)
    sd = np.sqrt(np.diag(cov))
    assert sm.converged
    assert np.max(np.abs(sm.mean - mean) / sd) < 1e-6
    assert np.max(np.abs(sm.cov - cov) / np.outer(sd, sd)) < 1e-6
