"""The independent routes of :mod:`depthbook.reference`, each against its closed form."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthbook import reference
from depthcore import SCENARIOS
from depthcore.exact import optimal
from depthcore.kalman.second_order import hessian
from depthcore.problem import model
from depthcore.problem.model import f, noise_free_state
from depthcore.problem.scenarios import MU_17, MU_18


def random_states(rng, c, n=50):
    """States near c, in front of the camera at all three frames."""
    x = c + rng.normal(scale=[0.3, 1.0, 0.1], size=(n, 3))
    x[:, 1] = np.maximum(x[:, 1], 2.5)
    return x


@pytest.mark.parametrize("key", ["fig2", "fig3", "fig6"])
def test_bayes_filter_recursion_gives_eq6_up_to_a_constant(key):
    s = SCENARIOS[key]
    rng = np.random.default_rng(1)
    x = random_states(rng, s.c)
    log_p3 = reference.bayes_filter(s.mu, s.rho, s.prior)[2](x)
    diff = log_p3 - optimal.log_posterior(x, s.mu, s.rho, s.prior)
    # the log densities are O(1e4) at rho = 1/200; rounding is ~1e-12 of that
    assert np.ptp(diff) < 1e-9 * np.max(np.abs(log_p3))


def test_bayes_filter_first_step_is_bayes_rule_on_the_prior():
    s = SCENARIOS["fig2"]
    x = random_states(np.random.default_rng(2), model.G(s.c, -2), 10)
    first = reference.bayes_filter(s.mu, s.rho, s.prior)[0](x)
    expected = s.prior.logpdf(x) + model.log_likelihood(s.mu[0], x, s.rho)
    assert_allclose(first, expected, rtol=1e-14)


def test_bayes_filter_rejects_bad_measurements():
    with pytest.raises(ValueError, match="mu"):
        reference.bayes_filter([], 0.01, SCENARIOS["fig2"].prior)


def test_numerical_derivatives_of_a_quadratic_are_exact():
    A = np.array([[2.0, 0.5, 0.0], [0.5, 3.0, -1.0], [0.0, -1.0, 4.0]])
    b = np.array([1.0, -2.0, 0.5])
    x = np.array([0.3, -0.7, 1.1])

    def q(z):
        return 0.5 * z @ A @ z + b @ z

    # central differences are exact on quadratics up to rounding ~ eps / step**2
    assert_allclose(reference.numerical_gradient(q, x), A @ x + b, rtol=1e-8)
    assert_allclose(reference.numerical_hessian(q, x, step=1e-3), A, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("mu", [MU_17, MU_18])
def test_numerical_hessian_of_f_matches_eq8(mu):
    c = noise_free_state(mu)
    fd = reference.numerical_hessian(lambda z: f(z, mu), c, step=1e-4 * c[1])
    # truncation O(step**2) relative
    assert_allclose(fd, hessian(mu), rtol=1e-5, atol=1e-7 * np.abs(fd).max())


def test_numerical_gradient_of_projection_is_eq11():
    n = np.array([1.3, 5.0, 0.8])
    assert_allclose(
        reference.numerical_gradient(model.project, n),
        model.observation_vector(n),
        rtol=1e-8,
        atol=1e-12,
    )


@pytest.mark.parametrize(
    "M, l",
    [
        (np.array([[2.0, 0.3], [0.3, 0.5]]), np.array([1.0, -2.0])),
        (np.array([[4e4, -1e4], [-1e4, 9e3]]), np.array([-3e4, 2e3])),
    ],
)
def test_log_gaussian_integral_brute_matches_the_closed_form_of_eq16(M, l):
    closed = np.log(2 * np.pi) + l @ np.linalg.solve(M, l) / 8 - 0.5 * np.log(np.linalg.det(M))
    # the trapezoid rule on a Gaussian converges geometrically: 1e-10 is loose
    assert reference.log_gaussian_integral_brute(M, l) == pytest.approx(closed, abs=1e-10)


def test_log_gaussian_integral_brute_rejects_an_indefinite_M():
    with pytest.raises(ValueError, match="positive definite"):
        reference.log_gaussian_integral_brute(np.array([[1.0, 2.0], [2.0, 1.0]]), np.zeros(2))


@pytest.mark.parametrize("key", ["fig2", "fig3"])
def test_trapezoid_depth_moments_converge_to_the_marginals(key):
    s = SCENARIOS[key]
    m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    mean, sd, n = reference.trapezoid_depth_moments(s.mu, s.rho, s.prior, 1 / 16)
    assert n == 257
    # the geometric convergence of the rule leaves rounding only at this step
    assert mean == pytest.approx(m.depth_mean, abs=1e-9 * m.depth_sd)
    assert sd == pytest.approx(m.depth_sd, abs=1e-9 * m.depth_sd)
    coarse = reference.trapezoid_depth_moments(s.mu, s.rho, s.prior, 1.0)
    assert abs(coarse[0] - m.depth_mean) > 1e-3


def test_trapezoid_depth_moments_printed_reading():
    s = SCENARIOS["fig3"]
    mean, sd, _ = reference.trapezoid_depth_moments(s.mu, s.rho, s.prior, 1 / 16, reading="printed")
    assert mean == pytest.approx(67.4516, abs=1e-4)


def test_trapezoid_depth_moments_rejects_a_bad_range():
    s = SCENARIOS["fig2"]
    with pytest.raises(ValueError, match="t_range"):
        reference.trapezoid_depth_moments(s.mu, s.rho, s.prior, 0.1, t_range=(1.0, -1.0))
