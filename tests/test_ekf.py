"""Eqs. (10)-(12) and Theorem 1, Eqs. (19)-(24): the extended Kalman filter."""

import numpy as np
import pytest
from hypothesis import given, settings
from numpy.testing import assert_allclose

from depthcore import paper_prior
from depthcore.kalman import ekf as ekf_module
from depthcore.kalman import second_order
from depthcore.kalman.ekf import predict, run, update
from depthcore.problem import model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import noise_free_state
from depthcore.problem.scenarios import MU_17, SCENARIOS

from helpers import bearings, states


def test_eq10_predict_is_the_linear_motion():
    m = np.array([1.0, 4.0, 0.5])
    P = np.diag([1.0, 2.0, 3.0])
    n, C = predict(m, P)
    assert_allclose(n, model.G(m))
    assert_allclose(C, model.F @ P @ model.F.T)


def test_eq12_update_is_bayes_for_the_linearised_measurement():
    # Information form of the exact posterior for mu = h.x + (n1/n2 - h.n) + w.
    rng = np.random.default_rng(2)
    n = np.array([1.0, 5.0, 0.3])
    A = rng.normal(size=(3, 3))
    C = A @ A.T + 0.5 * np.eye(3)
    rho, mu = 0.02, 0.25
    h = model.observation_vector(n)
    info = np.linalg.inv(C) + np.outer(h, h) / rho**2
    P = np.linalg.inv(info)
    m = P @ (np.linalg.solve(C, n) + h * (mu - n[0] / n[1] + h @ n) / rho**2)
    got = update(n, C, mu, rho)
    assert_allclose(got.mean, m, rtol=1e-10)
    assert_allclose(got.cov, P, rtol=1e-9, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(got.cov) > 0)


def test_eq12_update_matches_the_joseph_form():
    n = np.array([0.4, 3.0, -0.2])
    C = np.diag([4.0, 9.0, 1.0]) + 0.5
    rho = 0.01
    h = model.observation_vector(n)
    K = C @ h / (rho**2 + h @ C @ h)
    joseph = (np.eye(3) - np.outer(K, h)) @ C @ (np.eye(3) - np.outer(K, h)).T + rho**2 * np.outer(
        K, K
    )
    assert_allclose(update(n, C, 0.1, rho).cov, joseph, rtol=1e-8, atol=1e-12)


def test_run_is_batched_like_a_loop():
    rng = np.random.default_rng(7)
    x1 = np.array([-1.2, 4.0, 1.2])
    mu = model.simulate(x1, 3, 0.005, 0.0, rng, size=5, frame=1).mu
    prior = paper_prior(noise_free_state(MU_17))
    means, covs = run(mu, 0.005, prior.mean, prior.cov)
    for i in range(5):
        h = run(mu[i], 0.005, prior.mean, prior.cov)
        assert_allclose(means[i], h.means, rtol=1e-13)
        assert_allclose(covs[i], h.covs, rtol=1e-12)


def test_ekf_history_shapes():
    s = SCENARIOS["fig2"]
    h = run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    assert h.means.shape == (3, 3) and h.covs.shape == (3, 3, 3)
    assert_allclose(h.posterior.mean, h.means[-1])


@settings(max_examples=50, deadline=None)
@given(states())
def test_theorem1_eq19_eq24_ekf_equals_second_order_when_prior_mean_is_exact(c):
    mu = bearings(c)
    c = noise_free_state(mu)
    prior = Gaussian(model.G(c, -2), 1000 * np.eye(3))
    rho = 1 / 200
    hist = run(mu, rho, prior.mean, prior.cov)
    # Eq. (19): every innovation is zero, so the means are G^-2 c, G^-1 c, c.
    assert_allclose(hist.means, [model.G(c, -2), model.G(c, -1), c], rtol=1e-9, atol=1e-9)
    ps = second_order.run(mu, rho, prior.mean, prior.cov)
    assert_allclose(ps.mean, c, rtol=1e-7, atol=1e-7)
    # Eq. (24): the covariances agree (condition numbers reach 1e8: rtol 1e-6).
    assert_allclose(hist.posterior.cov, ps.cov, rtol=1e-6, atol=1e-9 * np.abs(ps.cov).max())


def test_theorem1_eq24_fails_for_the_printed_covariance():
    c = noise_free_state(MU_17)
    prior = Gaussian(model.G(c, -2), 1000 * np.eye(3))
    pe = run(MU_17, 1 / 200, prior.mean, prior.cov).posterior
    printed = second_order.run(MU_17, 1 / 200, prior.mean, prior.cov, reading="printed")
    assert printed.cov[1, 1] == pytest.approx(pe.cov[1, 1] / 2, rel=1e-3)


def test_ekf_rejects_prior_mean_behind_the_camera():
    prior = Gaussian([0.0, -3.0, 0.0], np.eye(3))
    with pytest.raises(ValueError, match="prior_mean leads the EKF to a predicted depth"):
        run(MU_17, 0.01, prior.mean, prior.cov)


def test_run_rejects_bad_rho():
    with pytest.raises(ValueError, match="rho must be positive"):
        ekf_module.run(np.array(MU_17), -0.1, np.zeros(3) + [0, 4, 0], np.eye(3))


def test_ekf_matches_filterpy_trial_by_trial():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_ekf_filterpy import filterpy_run

    s = SCENARIOS["fig2"]
    rng = np.random.default_rng(4)
    mu = model.simulate(s.c, 3, s.rho, 0.0, rng, size=20).mu
    prior = paper_prior(noise_free_state(MU_17))
    means, covs = run(mu, s.rho, prior.mean, prior.cov)
    for i in range(20):
        fm, fP = filterpy_run(mu[i], s.rho, prior.mean, prior.cov)
        sd = np.sqrt(np.einsum("kii->ki", fP))
        assert np.max(np.abs(means[i] - fm) / sd) < 1e-10
        # cond(P) ~ 1e7 after the first measurement: rounding of that order times eps
        assert (
            np.max(np.linalg.norm(covs[i] - fP, axis=(1, 2)) / np.linalg.norm(fP, axis=(1, 2)))
            < 1e-9
        )


def test_a_predicted_depth_whose_gradient_eq_11_overflows_is_refused():
    """n2 = 1e-300 passes n2 > 0, but n1 / n2**2 overflows: a one-line refusal naming prior_mean."""
    with pytest.raises(ValueError, match="prior_mean .* overflows"):
        run([-0.3, 0.0, 0.2], 0.005, [-1.0, 1e-300, 0.0], 1000 * np.eye(3))
    with pytest.raises(ValueError, match="prior_mean .* overflows"):
        update([-1.0, 1e-300, 0.0], np.eye(3), -0.3, 0.005)


# --- N frames and process noise ---------------------------------------------------------

X1 = np.array([-1.0, 6.0, 0.4])  # state at frame 1 of an N-frame track


def linearised_recursion(mu, rho, m, P, q):
    """The textbook EKF in covariance form, loop by loop (Prince 19.3, Eqs. (10)-(12)).

    Predict ``n = (x + v, y + 1, v)``, ``C = F P F^T + diag(0, 0, q**2)``;
    update with the gradient of ``x / y`` at ``n``.
    """
    F = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    means, covs = [], []
    for k, z in enumerate(mu):
        if k:
            m = np.array([m[0] + m[2], m[1] + 1.0, m[2]])
            P = F @ P @ F.T + np.diag([0.0, 0.0, q**2])
        h = np.array([1.0 / m[1], -m[0] / m[1] ** 2, 0.0])
        s = rho**2 + h @ P @ h
        K = P @ h / s
        m = m + K * (z - m[0] / m[1])
        P = (np.eye(3) - np.outer(K, h)) @ P
        means.append(m)
        covs.append(P)
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("n_frames", [4, 6, 9])
@pytest.mark.parametrize("q", [0.0, 0.01])
def test_n_frame_ekf_with_process_noise_is_the_linearised_recursion(n_frames, q):
    # A small noise and the exact prior mean keep the linearisation near the track;
    # the recursion above is the covariance form, the EKF's the square-root information form.
    rng = np.random.default_rng(n_frames)
    rho = 1e-4
    mu = model.simulate(X1, n_frames, rho, 0.0, rng, frame=1).mu
    P0 = np.diag([0.5, 2.0, 0.05])
    got = run(mu, rho, X1, P0, process_noise=q)
    means, covs = linearised_recursion(mu, rho, X1, P0, q)
    assert got.means.shape == (n_frames, 3) and got.covs.shape == (n_frames, 3, 3)
    assert_allclose(got.means, means, rtol=1e-10, atol=1e-12)
    for k in range(n_frames):
        assert_allclose(got.covs[k], covs[k], rtol=0, atol=1e-7 * np.abs(covs[k]).max())


def test_process_noise_zero_and_three_frames_are_the_papers_ekf():
    s = SCENARIOS["fig2"]
    paper = run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    again = run(s.mu, s.rho, s.prior.mean, s.prior.cov, process_noise=0.0)
    assert np.array_equal(paper.means, again.means) and np.array_equal(paper.covs, again.covs)


def test_process_noise_widens_the_velocity_and_is_checked():
    mu = model.simulate(X1, 6, 1e-3, 0.0, np.random.default_rng(1), frame=1).mu
    P0 = np.diag([0.5, 2.0, 0.05])
    still = run(mu, 1e-3, X1, P0).covs[-1]
    moving = run(mu, 1e-3, X1, P0, process_noise=0.05).covs[-1]
    assert moving[2, 2] > still[2, 2]
    for bad in (-0.1, np.nan, [0.1, 0.2]):
        with pytest.raises(ValueError, match="process_noise"):
            run(mu, 1e-3, X1, P0, process_noise=bad)


def test_n_frame_ekf_is_batched_like_a_loop():
    rng = np.random.default_rng(5)
    mu = model.simulate(X1, 7, 1e-3, 0.0, rng, size=4, frame=1).mu
    P0 = np.diag([0.5, 2.0, 0.05])
    many = run(mu, 1e-3, X1, P0, process_noise=0.02)
    for i in range(4):
        one = run(mu[i], 1e-3, X1, P0, process_noise=0.02)
        assert_allclose(many.means[i], one.means, rtol=1e-13)
        assert_allclose(many.covs[i], one.covs, rtol=1e-11, atol=1e-16)
