"""Eq. (13): Gaussian marginals, and the paper's prior."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.problem import gaussian
from depthcore.problem.gaussian import Gaussian, paper_prior
from depthcore.problem.scenarios import SCENARIOS


def test_eq13_marginals_match_samples():
    g = SCENARIOS["fig2"].prior
    A = np.array([[2.0, 0.3, 0.1], [0.3, 1.0, -0.2], [0.1, -0.2, 0.5]])
    g = Gaussian([1.0, 6.0, -0.5], A @ A.T)
    x = np.random.default_rng(0).multivariate_normal(g.mean, g.cov, size=200_000)
    for i, comp in enumerate("xyv"):
        mean, sd = g.marginal(comp)
        # 200000 draws: standard error of a mean sd/447, of an SD sd/632; 5 of them
        assert abs(x[:, i].mean() - mean) < 5 * sd / 447
        assert abs(x[:, i].std() - sd) < 5 * sd / 632


def test_eq13_marginal_pdf_is_normalised_and_logpdf_matches_scipy():
    from scipy.stats import multivariate_normal

    g = Gaussian([0.0, 4.0, 1.0], np.diag([1.0, 4.0, 0.25]))
    grid = np.linspace(-20, 30, 20001)
    assert np.trapezoid(g.marginal_pdf("y", grid), grid) == pytest.approx(1.0, abs=1e-10)
    x = np.array([[0.1, 3.0, 1.2], [1.0, 5.0, 0.0]])
    assert_allclose(g.logpdf(x), multivariate_normal(g.mean, g.cov).logpdf(x), rtol=1e-12)


def test_logpdf_with_one_covariance_per_point_matches_scipy():
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(3)
    A = rng.normal(size=(4, 3, 3))
    covs = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    means = rng.normal(size=(4, 3))
    x = rng.normal(size=(4, 5, 3))  # five points per covariance
    got = gaussian.gaussian_logpdf(x, means[:, None], covs[:, None])
    want = [multivariate_normal(means[i], covs[i]).logpdf(x[i]) for i in range(4)]
    assert got.shape == (4, 5)
    assert_allclose(got, want, rtol=1e-12)


def test_paper_prior_rule():
    c = SCENARIOS["fig2"].c
    p = paper_prior(c, depth_offset=2.0)
    assert_allclose(p.mean, [c[0] - 2 * c[2], c[1], 0.0])
    assert_allclose(p.cov, 1000 * np.eye(3))
    with pytest.raises(ValueError, match="scale must be positive"):
        paper_prior(c, scale=0.0)


def test_gaussian_is_immutable():
    g = Gaussian([0.0, 4.0, 1.0], np.eye(3))
    with pytest.raises(ValueError):
        g.mean[0] = 1.0


def test_correlation_of_a_known_covariance():
    cov = np.array([[4.0, -3.0], [-3.0, 9.0]])
    assert gaussian.correlation(cov) == pytest.approx(-0.5, rel=1e-15)
    with pytest.raises(ValueError, match="must be square"):
        gaussian.correlation(np.ones((2, 3)))
    with pytest.raises(ValueError, match="must be positive"):
        gaussian.correlation(np.diag([1.0, 0.0]))
