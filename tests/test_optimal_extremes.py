"""Eqs. (13)-(16) at the extremes: the depth quadrature's accuracy and bounded cost."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthbook import reference
from depthcore.exact import optimal, quadrature
from depthcore.kalman import second_order
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import noise_free_state

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

#: Most nodes the quadrature may use for one problem on y > 2.
NODE_BOUND = 2 * quadrature.NODE_BUDGET


def _prior(mu, scale=1000.0):
    c = noise_free_state(mu)
    return Gaussian(np.array([c[0] - 2 * c[2], c[1] - 2, 0.0]), scale * np.eye(3))


def _exact(mu, rho, scale=1000.0):
    prior = _prior(mu, scale)
    return optimal.run(mu, rho, prior.mean, prior.cov)


def _key(m):
    return np.array([m.depth_mean, m.depth_sd, m.velocity_mean, m.velocity_sd])


def _brute_1d(mu, rho, prior, t_lo, t_hi, panels=20000):
    """Eqs. (13)-(16) by composite 16-point Gauss-Legendre in t = log(y - 2) on a fixed range."""
    x, w = np.polynomial.legendre.leggauss(16)
    edges = np.linspace(t_lo, t_hi, panels + 1)
    half = np.diff(edges) / 2
    t = ((edges[1:] + edges[:-1])[:, None] / 2 + half[:, None] * x).ravel()
    wt = (half[:, None] * w).ravel() * np.exp(t)
    y = 2 + np.exp(t)
    log_density, mean, cov = optimal.conditional(y, mu, rho, prior)
    p = np.exp(log_density - log_density.max()) * wt
    Z = p.sum()
    ey, ev = p @ y / Z, p @ mean[:, 1] / Z
    return np.array(
        [
            ey,
            np.sqrt(p @ (y - ey) ** 2 / Z),
            ev,
            np.sqrt(p @ ((mean[:, 1] - ev) ** 2 + cov[:, 1, 1]) / Z),
        ]
    )


EXTREMES = {
    "rho=1e-9": ([-0.3, 0, 0.2], 1e-9, 1e3),
    "rho=1e-5": ([-0.3, 0, 0.2], 1e-5, 1e3),
    "rho=1": ([-0.3, 0, 0.2], 1.0, 1e3),
    "prior scale 1e-12": ([-0.3, 0, 0.2], 1 / 200, 1e-12),
    "prior scale 1e-6": ([-0.3, 0, 0.2], 1 / 200, 1e-6),
    "prior scale 1e6": ([-0.3, 0, 0.2], 1 / 200, 1e6),
    "prior scale 1e12": ([-0.3, 0, 0.2], 1 / 200, 1e12),
    "depth 6e5": ([0.3, 0, -0.299999], 1 / 200, 1e3),
    "depth 1e9": ([0.3, 0, -0.3 + 6e-10], 1 / 200, 1e3),
    "|mu1+mu3-2mu2| = 2e-12": ([0.3, 0, -0.3 + 2e-12], 1 / 200, 1e3),
    "c2 - 2 = 0.009": ([0.1005, 0, -0.0005], 1 / 200, 1e3),
}


@pytest.mark.parametrize("name", list(EXTREMES))
def test_extremes_run_within_the_node_bound_with_finite_moments(name):
    mu, rho, scale = EXTREMES[name]
    m = _exact(mu, rho, scale)
    assert np.all(np.isfinite(_key(m))) and m.depth_sd > 0 and m.velocity_sd > 0
    assert 0 < m.n_nodes <= NODE_BOUND
    # below the tolerance, or at the roundoff floor where the depth itself is rounded
    floor = 1e3 * np.finfo(float).eps * (abs(m.depth_mean) + m.depth_sd)
    assert m.depth_error <= max(1e-6 * m.depth_sd, floor)


@pytest.mark.parametrize(
    "name", ["rho=1e-5", "rho=1", "prior scale 1e-6", "prior scale 1e6", "c2 - 2 = 0.009"]
)
def test_extremes_match_a_fixed_gauss_legendre_rule_in_log_depth(name):
    mu, rho, scale = EXTREMES[name]
    prior = _prior(mu, scale)
    m = optimal.run(mu, rho, prior.mean, prior.cov)
    got = _key(m)
    brute = _brute_1d(mu, rho, prior, -30.0, np.log(m.depth_mean + 1e4 * m.depth_sd))
    assert_allclose(got, brute, rtol=0, atol=1e-9 * got[[1, 1, 3, 3]].max())
    assert np.all(np.abs(got - brute) <= 1e-9 * got[[1, 1, 3, 3]])


def test_far_depth_matches_a_rule_centred_on_it():
    mu, rho, scale = EXTREMES["depth 6e5"]
    prior = _prior(mu, scale)
    m = optimal.run(mu, rho, prior.mean, prior.cov)
    t0, w = np.log(m.depth_mean - 2), 60 * m.depth_sd / m.depth_mean
    brute = _brute_1d(mu, rho, prior, t0 - w, t0 + 3 * w, panels=4000)
    sd = _key(m)[[1, 1, 3, 3]]
    assert np.all(np.abs(_key(m) - brute) <= 1e-9 * sd)
    # the reported error covers the difference
    assert abs(m.velocity_sd - brute[3]) <= m.velocity_error
    assert abs(m.depth_mean - brute[0]) <= m.depth_error


def test_moderate_extreme_matches_the_3d_grid_of_eq6():
    mu, rho, scale = [-0.3, 0, 0.2], 0.02, 1e3
    prior = _prior(mu, scale)
    m = optimal.run(mu, rho, prior.mean, prior.cov)
    b = reference.grid_moments(mu, rho, prior, panels=300, uv_order=32)
    assert_allclose(
        _key(m),
        [b.depth_mean, b.depth_sd, b.velocity_mean, b.velocity_sd],
        rtol=0,
        atol=1e-8 * m.depth_sd,
    )


def test_small_noise_limit_is_p_s_plus_a_term_linear_in_rho():
    """As rho -> 0 the optimal moments tend to those of p_s (Eq. (8)), the means
    differing by a multiple of rho times the SD: the ratio is the same at two noises."""
    mu = [-0.3, 0, 0.2]
    prior = _prior(mu)
    ratios, shift_errors = [], []
    for rho in (1e-7, 1e-8, 1e-9):
        m = optimal.run(mu, rho, prior.mean, prior.cov)
        s = second_order.run(mu, rho, prior.mean, prior.cov)
        sd = np.sqrt(np.diag(s.cov))
        assert m.depth_sd == pytest.approx(sd[1], rel=1e-7)
        assert m.velocity_sd == pytest.approx(sd[2], rel=1e-7)
        shift = np.array([m.depth_mean - s.mean[1], m.velocity_mean - s.mean[2]])
        ratios.append(shift / sd[1:] / rho)
        shift_errors.append(np.array([m.depth_error, m.velocity_error]) / sd[1:] / rho)
    ratios = np.array(ratios)
    assert np.all(np.abs(ratios) > 10)  # the skew term is resolved, not roundoff
    assert_allclose(ratios[1], ratios[0], rtol=2e-3)
    # at rho = 1e-9 the shift is 1e-7 SD: resolved within the reported error
    assert np.all(np.abs(ratios[2] - ratios[0]) <= shift_errors[2] + 2e-3 * np.abs(ratios[0]))


def test_batch_result_does_not_depend_on_row_order():
    mus = np.array([[0.192115, 0.239635, 0.278123], [1.497454, 4.308473, 6.919367]])
    a = optimal.moments(mus, 1 / 200, [-1.2, 4, 0], 1000 * np.eye(3))
    b = optimal.moments(mus[::-1], 1 / 200, [-1.2, 4, 0], 1000 * np.eye(3))
    for k in range(2):
        single = optimal.moments(mus[k : k + 1], 1 / 200, [-1.2, 4, 0], 1000 * np.eye(3))
        assert_allclose(a.depth_mean[k], single.depth_mean[0], rtol=1e-13)
        assert_allclose(a.velocity_sd[k], single.velocity_sd[0], rtol=1e-13)
    assert_allclose(a.depth_mean, b.depth_mean[::-1], rtol=1e-13)
    assert_allclose(a.depth_sd, b.depth_sd[::-1], rtol=1e-13)


def test_batch_of_extremes_matches_single_calls():
    names = ["rho=1e-5", "depth 6e5", "c2 - 2 = 0.009"]
    mus = np.array([EXTREMES[n][0] for n in names])
    rhos = np.array([EXTREMES[n][1] for n in names])
    means = np.array([_prior(mu).mean for mu in mus])
    batch = optimal.moments(mus, rhos, means, 1000 * np.eye(3))
    for k, _n in enumerate(names):
        single = _exact(mus[k], rhos[k])
        assert batch.depth_mean[k] == pytest.approx(single.depth_mean, rel=1e-12)
        assert batch.velocity_sd[k] == pytest.approx(single.velocity_sd, rel=1e-10)


def test_budget_exhausted_is_a_value_error_naming_the_input(monkeypatch):
    monkeypatch.setattr(quadrature, "NODE_BUDGET", 20)
    mu, rho, scale = EXTREMES["prior scale 1e6"]
    with pytest.raises(ValueError, match=r"mu\[0\] = .*did not reach rtol"):
        _exact(mu, rho, scale)


def test_velocity_error_estimate_includes_roundoff_at_a_far_depth():
    mu, rho, scale = EXTREMES["depth 6e5"]
    m = _exact(mu, rho, scale)
    assert m.velocity_error >= 64 * np.finfo(float).eps * m.velocity_sd
    assert m.depth_error >= 64 * np.finfo(float).eps * m.depth_mean


def test_batch_marginals_cdf_at_small_noise_matches_the_gaussian_limit():
    from scipy.stats import norm

    mu = np.array([[-0.3, 0, 0.2]])
    prior = _prior(mu[0])
    bm = optimal.batch_marginals(mu, 1e-7, prior.mean, prior.cov)
    s = second_order.run(mu[0], 1e-7, prior.mean, prior.cov)
    y = s.mean[1] + 0.7 * np.sqrt(s.cov[1, 1])
    assert bm.depth_cdf(np.array([y]))[0] == pytest.approx(norm.cdf(0.7), abs=1e-4)
    v = s.mean[2] - 0.4 * np.sqrt(s.cov[2, 2])
    assert bm.velocity_cdf(np.array([v]))[0] == pytest.approx(norm.cdf(-0.4), abs=1e-4)
