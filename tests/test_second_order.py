"""Eqs. (8), (23), (24): the second-order approximation p_s."""

import numpy as np
import pytest
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
    second_order,
    second_order_batch,
    theorem1_precision,
)

from helpers import bearings


@pytest.mark.parametrize("mu", [MU_17, MU_18, tuple(bearings(np.array([1.0, 8.0, -0.5])))])
def test_eq8_hessian_matches_finite_differences(mu):
    c = noise_free_state(mu)
    h = 1e-4 * c[1]  # central second differences: truncation O(h^2) relative
    E = np.eye(3) * h
    fd = np.array(
        [
            [
                (
                    f(c + E[i] + E[j], mu)
                    - f(c + E[i] - E[j], mu)
                    - f(c - E[i] + E[j], mu)
                    + f(c - E[i] - E[j], mu)
                )
                / (4 * h * h)
                for j in range(3)
            ]
            for i in range(3)
        ]
    )
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


def test_reading_must_be_known():
    with pytest.raises(ValueError, match="reading must be one of"):
        likelihood_covariance(MU_17, 0.01, "halved")


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
