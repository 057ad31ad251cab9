"""Eqs. (5), (7), (8): the noise-free state and the second-order approximation."""

import numpy as np
import pytest
from hypothesis import given, settings
from numpy.testing import assert_allclose

from depthcore import model, optimal, paper_prior
from depthcore.ekf import ekf
from depthcore.gaussian import Gaussian
from depthcore.scenarios import MU_17, MU_18
from depthcore.second_order import (
    f,
    hessian,
    likelihood_covariance,
    noise_free_state,
    noise_free_states,
    residuals,
    second_order,
    second_order_batch,
    theorem1_precision,
)

from helpers import bearings, states


def test_eq7_eq17_eq18_paper_values():
    assert_allclose(noise_free_state(MU_17), [6 / 5, 6, 6 / 5], rtol=1e-14)
    assert_allclose(noise_free_state(MU_18), [2, 10, 2], rtol=1e-14)


@settings(max_examples=60, deadline=None)
@given(states())
def test_eq7_recovers_the_state_from_noise_free_bearings(c):
    mu = bearings(c)
    assert_allclose(noise_free_state(mu), c, rtol=1e-7, atol=1e-9)
    assert f(noise_free_state(mu), mu) == pytest.approx(0.0, abs=1e-20)


def test_eq5_f_is_sum_of_squared_residuals_in_time_order():
    x = np.array([1.0, 5.0, 0.5])
    mu = np.array([-0.3, 0.0, 0.2])
    expected = [(x[0] - 2 * x[2]) / (x[1] - 2) - mu[0], (x[0] - x[2]) / (x[1] - 1) - mu[1],
                x[0] / x[1] - mu[2]]
    assert_allclose(residuals(x, mu), expected)
    assert f(x, mu) == pytest.approx(np.sum(np.square(expected)))


@pytest.mark.parametrize("mu", [MU_17, MU_18, tuple(bearings(np.array([1.0, 8.0, -0.5])))])
def test_eq8_hessian_matches_finite_differences(mu):
    c = noise_free_state(mu)
    h = 1e-4 * c[1]  # central second differences: truncation O(h^2) relative
    E = np.eye(3) * h
    fd = np.array([[(f(c + E[i] + E[j], mu) - f(c + E[i] - E[j], mu) - f(c - E[i] + E[j], mu)
                     + f(c - E[i] - E[j], mu)) / (4 * h * h) for j in range(3)] for i in range(3)])
    assert_allclose(hessian(mu), fd, rtol=1e-5, atol=1e-7 * np.abs(fd).max())


def test_eq8_derived_covariance_is_the_small_noise_limit_of_the_optimal_filter():
    # With a prior too broad to matter and small noise, the optimal filter's
    # depth SD approaches that of N(c, 2 rho^2 J^{-1}), not of N(c, rho^2 J^{-1}).
    mu = MU_17
    c = noise_free_state(mu)
    prior = Gaussian(paper_prior(c).mean, 1e8 * np.eye(3))
    rho = 1e-5
    exact = optimal.marginals(mu, rho, prior)
    derived = np.sqrt(likelihood_covariance(mu, rho, "derived")[1, 1])
    printed = np.sqrt(likelihood_covariance(mu, rho, "printed")[1, 1])
    assert exact.depth_sd == pytest.approx(derived, rel=1e-3)  # O(rho) skew corrections
    assert exact.depth_sd / printed == pytest.approx(np.sqrt(2), rel=1e-3)


def test_eq8_second_order_is_the_product_of_its_two_gaussians():
    mu, rho = MU_17, 1 / 200
    c = noise_free_state(mu)
    prior = paper_prior(c)
    ps = second_order(mu, rho, prior)
    lik = Gaussian(c, likelihood_covariance(mu, rho))
    rng = np.random.default_rng(3)
    x = ps.mean + rng.normal(scale=0.3, size=(50, 3))
    from depthcore import model
    diff = ps.logpdf(x) - lik.logpdf(x) - prior.logpdf(model.G(x, -2))
    assert np.ptp(diff) < 1e-9  # a constant: the log normaliser


def test_second_order_batch_matches_single():
    mus = np.array([MU_17, MU_18])
    means = np.array([paper_prior(noise_free_state(m)).mean for m in mus])
    m, P = second_order_batch(mus, 1 / 200, means, 1000 * np.eye(3))
    for i, mu in enumerate(mus):
        g = second_order(mu, 1 / 200, paper_prior(noise_free_state(mu)))
        # inverse versus Cholesky solve of a precision with condition number ~1e5
        assert_allclose(m[i], g.mean, rtol=1e-10)
        assert_allclose(P[i], g.cov, rtol=1e-9)


def test_noise_free_states_names_the_bad_row():
    with pytest.raises(ValueError, match=r"mu\[1\] is degenerate"):
        noise_free_states([MU_17, (0.1, 0.1, 0.1)])
    with pytest.raises(ValueError, match=r"mu\[0\] puts the point behind the camera"):
        noise_free_states([(0.2, 0.0, -0.3), MU_17])


def test_reading_must_be_known():
    with pytest.raises(ValueError, match="reading must be one of"):
        likelihood_covariance(MU_17, 0.01, "halved")


def test_eq20_eq21_eq22_residuals_are_linear_in_the_observation_vectors_near_c():
    from depthcore.second_order import residual_gradients

    mu = MU_17
    c = noise_free_state(mu)
    g = residual_gradients(c)
    rng = np.random.default_rng(2)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    rest = [np.max(np.abs(residuals(c + eps * d, mu) - g @ (eps * d))) for eps in (1e-2, 1e-3)]
    # the remainder is O(|x - c|^2): ten times closer, a hundred times smaller
    assert rest[1] / rest[0] == pytest.approx(1e-2, rel=0.05)


def test_eq23_second_order_density_is_the_linearised_posterior():
    from depthcore import model
    from depthcore.second_order import residual_gradients

    mu, rho = MU_17, 1 / 200
    c = noise_free_state(mu)
    prior = paper_prior(c)
    g = residual_gradients(c)
    ps = second_order(mu, rho, prior)
    x = ps.mean + np.random.default_rng(3).normal(scale=0.2, size=(40, 3))
    eq23 = -np.sum(((x - c) @ g.T) ** 2, axis=1) / (2 * rho**2) + prior.logpdf(model.G(x, -2))
    assert np.ptp(ps.logpdf(x) - eq23) < 1e-8


@pytest.mark.parametrize("mu", [MU_17, MU_18])
def test_theorem1_precision_is_the_inverse_of_the_ekf_and_second_order_covariances(mu):
    c = noise_free_state(mu)
    prior = Gaussian(model.G(c, -2), 1000.0 * np.eye(3))
    rho = 1 / 200
    D_inv = theorem1_precision(mu, rho, prior)
    P3 = ekf(mu, rho, prior).posterior.cov
    D = second_order(mu, rho, prior).cov
    # inverses of matrices with condition number ~1e6: 1e-8 relative
    assert_allclose(D_inv @ P3, np.eye(3), atol=1e-8)
    assert_allclose(D_inv @ D, np.eye(3), atol=1e-8)
