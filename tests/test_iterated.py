"""Tests of the iterated EKF and the iterated extended Kalman smoother (textbook 19.3)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import minimize

from depthcore import ekf, iterated, model, optimal
from depthcore.scenarios import SCENARIOS


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
    mu = model.simulate_measurements(x1, 2e-3, rng, n=n_frames, size=3)
    prior_mean = x1 + [0.1, -0.5, 0.05]
    prior_cov = np.diag([0.5, 2.0, 0.05])
    means, covs = iterated.run(mu, 2e-3, prior_mean, prior_cov, q, max_iterations=1)
    e = ekf.run(mu, 2e-3, prior_mean, prior_cov, process_noise=q)
    assert_allclose(means, e.means, rtol=1e-9)
    assert_allclose(covs, e.covs, rtol=1e-6, atol=1e-9 * np.abs(e.covs).max())
