"""The book's helper computations (depthcore.walkthrough), each against an independent route."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore import SCENARIOS, model, optimal, walkthrough
from depthcore.ekf import ekf
from depthcore.gaussian import Gaussian
from depthcore.scenarios import MU_17, MU_18, REPORTED
from depthcore.second_order import f, hessian, noise_free_state, second_order


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
    log_p3 = walkthrough.bayes_filter(s.mu, s.rho, s.prior)[2](x)
    diff = log_p3 - optimal.log_posterior(x, s.mu, s.rho, s.prior)
    # the log densities are O(1e4) at rho = 1/200; rounding is ~1e-12 of that
    assert np.ptp(diff) < 1e-9 * np.max(np.abs(log_p3))


def test_bayes_filter_first_step_is_bayes_rule_on_the_prior():
    s = SCENARIOS["fig2"]
    x = random_states(np.random.default_rng(2), model.G(s.c, -2), 10)
    first = walkthrough.bayes_filter(s.mu, s.rho, s.prior)[0](x)
    expected = s.prior.logpdf(x) + model.log_likelihood(s.mu[0], x, s.rho)
    assert_allclose(first, expected, rtol=1e-14)


def test_bayes_filter_rejects_bad_measurements():
    with pytest.raises(ValueError, match="mu"):
        walkthrough.bayes_filter([], 0.01, SCENARIOS["fig2"].prior)


def test_numerical_derivatives_of_a_quadratic_are_exact():
    A = np.array([[2.0, 0.5, 0.0], [0.5, 3.0, -1.0], [0.0, -1.0, 4.0]])
    b = np.array([1.0, -2.0, 0.5])
    x = np.array([0.3, -0.7, 1.1])

    def q(z):
        return 0.5 * z @ A @ z + b @ z

    # central differences are exact on quadratics up to rounding ~ eps / step**2
    assert_allclose(walkthrough.numerical_gradient(q, x), A @ x + b, rtol=1e-8)
    assert_allclose(walkthrough.numerical_hessian(q, x, step=1e-3), A, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("mu", [MU_17, MU_18])
def test_numerical_hessian_of_f_matches_eq8(mu):
    c = noise_free_state(mu)
    fd = walkthrough.numerical_hessian(lambda z: f(z, mu), c, step=1e-4 * c[1])
    # truncation O(step**2) relative
    assert_allclose(fd, hessian(mu), rtol=1e-5, atol=1e-7 * np.abs(fd).max())


def test_numerical_gradient_of_projection_is_eq11():
    n = np.array([1.3, 5.0, 0.8])
    assert_allclose(walkthrough.numerical_gradient(model.project, n),
                    model.observation_vector(n), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("key", ["fig2", "fig3"])
def test_eq16_printed_matches_the_printed_reading_up_to_a_constant(key):
    s = SCENARIOS[key]
    y = np.linspace(2.5, 60.0, 40)
    coeffs = optimal.quadratic_coefficients(y, s.mu, s.rho, s.prior)
    printed = walkthrough.eq16_printed(coeffs)
    code, _, _ = optimal.conditional(y, s.mu, s.rho, s.prior, reading="printed")
    # both are O(1e4) at rho = 1/200 (l^T M^-1 l / 8 ~ K(y) / 2)
    assert np.ptp(printed - code) < 1e-9 * np.max(np.abs(printed))


@pytest.mark.parametrize("key", ["fig2", "fig3"])
def test_derived_reading_is_printed_minus_half_K(key):
    s = SCENARIOS[key]
    y = np.linspace(2.5, 60.0, 40)
    printed = walkthrough.eq16_printed(optimal.quadratic_coefficients(y, s.mu, s.rho, s.prior))
    K = walkthrough.prior_exponent(y, s.mu, s.rho, s.prior)
    derived, _, _ = optimal.conditional(y, s.mu, s.rho, s.prior, reading="derived")
    assert np.ptp(printed - 0.5 * K - derived) < 1e-9 * np.max(np.abs(printed))


def test_prior_exponent_is_the_priors_depth_term():
    s = SCENARIOS["fig3"]
    y = np.linspace(2.5, 60.0, 20)
    K = walkthrough.prior_exponent(y, s.mu, s.rho, s.prior)
    expected = (y - 2.0 - s.prior.mean[1]) ** 2 / s.prior.cov[1, 1]
    assert_allclose(K - K[0], expected - expected[0], rtol=1e-9, atol=1e-9)


def test_prior_exponent_drops_what_eq14_keeps():
    s = SCENARIOS["fig2"]
    rng = np.random.default_rng(3)
    y = rng.uniform(3.0, 12.0, 10)
    x, v = rng.normal(1.2, 0.3, 10), rng.normal(1.2, 0.2, 10)
    A, B, C, D, E = optimal.quadratic_coefficients(y, s.mu, s.rho, s.prior).T
    K = walkthrough.prior_exponent(y, s.mu, s.rho, s.prior)
    lp = optimal.log_posterior(np.stack([x, y, v], -1), s.mu, s.rho, s.prior)
    assert_allclose(lp, -0.5 * (A * x**2 + B * x * v + C * v**2 + D * x + E * v) - 0.5 * K,
                    rtol=1e-10)


@pytest.mark.parametrize("M, l", [
    (np.array([[2.0, 0.3], [0.3, 0.5]]), np.array([1.0, -2.0])),
    (np.array([[4e4, -1e4], [-1e4, 9e3]]), np.array([-3e4, 2e3])),
])
def test_log_gaussian_integral_brute_matches_the_closed_form_of_eq16(M, l):
    closed = np.log(2 * np.pi) + l @ np.linalg.solve(M, l) / 8 - 0.5 * np.log(np.linalg.det(M))
    # the trapezoid rule on a Gaussian converges geometrically: 1e-10 is loose
    assert walkthrough.log_gaussian_integral_brute(M, l) == pytest.approx(closed, abs=1e-10)


def test_log_gaussian_integral_brute_rejects_an_indefinite_M():
    with pytest.raises(ValueError, match="positive definite"):
        walkthrough.log_gaussian_integral_brute(np.array([[1.0, 2.0], [2.0, 1.0]]), np.zeros(2))


@pytest.mark.parametrize("mu", [MU_17, MU_18])
def test_theorem1_precision_is_the_inverse_of_the_ekf_and_second_order_covariances(mu):
    c = noise_free_state(mu)
    prior = Gaussian(model.G(c, -2), 1000.0 * np.eye(3))
    rho = 1 / 200
    D_inv = walkthrough.theorem1_precision(mu, rho, prior)
    P3 = ekf(mu, rho, prior).posterior.cov
    D = second_order(mu, rho, prior).cov
    # inverses of matrices with condition number ~1e6: 1e-8 relative
    assert_allclose(D_inv @ P3, np.eye(3), atol=1e-8)
    assert_allclose(D_inv @ D, np.eye(3), atol=1e-8)


@pytest.mark.parametrize("key", ["fig2", "fig3", "fig5"])
def test_depth_quantiles_are_consistent_with_the_moments(key):
    s = SCENARIOS[key]
    m = optimal.marginals(s.mu, s.rho, s.prior)
    q = walkthrough.depth_quantiles(m, [0.001, 0.25, 0.5, 0.75, 0.999])
    assert np.all(np.diff(q) > 0)
    assert q[0] > 2.0
    assert q[0] < m.depth_mean < q[-1]
    # interquartile range of a unimodal law of moderate skew: between 0.5 and 2 SDs
    assert 0.5 * m.depth_sd < q[3] - q[1] < 2.0 * m.depth_sd


def test_depth_quantiles_of_a_near_gaussian_marginal():
    # Figure 5 (rho = 1/500) is close to Gaussian: median near mean, quartiles near +-0.674 sd
    s = SCENARIOS["fig5"]
    m = optimal.marginals(s.mu, s.rho, s.prior)
    q1, q2, q3 = walkthrough.depth_quantiles(m, [0.25, 0.5, 0.75])
    assert q2 == pytest.approx(m.depth_mean, abs=0.1 * m.depth_sd)
    assert (q3 - q1) / 2 == pytest.approx(0.674 * m.depth_sd, rel=0.05)


def test_depth_quantiles_invert_the_cdf():
    s = SCENARIOS["fig2"]
    m = optimal.marginals(s.mu, s.rho, s.prior)
    (median,) = walkthrough.depth_quantiles(m, [0.5])
    y = np.linspace(2.0 + 1e-6, median, 200001)
    below = np.trapezoid(m.depth_pdf(y), y)
    assert below == pytest.approx(0.5, abs=1e-5)


def test_depth_quantiles_reject_bad_arguments():
    s = SCENARIOS["fig2"]
    with pytest.raises(ValueError, match="probs"):
        walkthrough.depth_quantiles(optimal.marginals(s.mu, s.rho, s.prior), [0.0, 0.5])
    with pytest.raises(ValueError, match="support"):
        walkthrough.depth_quantiles(optimal.marginals(s.mu, s.rho, s.prior, support="all"), [0.5])


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_filter_moments_agree_with_each_filter(key):
    s = SCENARIOS[key]
    got = walkthrough.filter_moments(s)
    m = optimal.marginals(s.mu, s.rho, s.prior)
    comp = {"depth": "y", "velocity": "v"}[s.quantity]
    opt = (m.depth_mean, m.depth_sd) if s.quantity == "depth" else (m.velocity_mean, m.velocity_sd)
    assert got["optimal"] == pytest.approx(opt, rel=1e-12)
    assert got["second_order"] == pytest.approx(second_order(s.mu, s.rho, s.prior).marginal(comp))
    assert got["ekf"] == pytest.approx(ekf(s.mu, s.rho, s.prior).posterior.marginal(comp))


def test_filter_moments_rejects_an_unknown_quantity():
    with pytest.raises(ValueError, match="quantity"):
        walkthrough.filter_moments(SCENARIOS["fig2"], "x")


def test_comparison_rows_of_figure_2():
    rows = {r["id"]: r for r in walkthrough.comparison("fig2")}
    assert list(rows) == [r[0] for r in walkthrough.TABLE_ROWS]
    assert rows["opt"]["reported_mean"] == REPORTED["fig2"]["optimal"]["depth"][0]
    assert rows["so"]["sd"] == pytest.approx(0.6163, abs=1e-4)
    assert rows["so_printed"]["sd"] == pytest.approx(0.4358, abs=1e-4)
    assert rows["so"]["sd_matches"] and not rows["so_printed"]["sd_matches"]
    texts = walkthrough.comparison_texts("fig2", list(rows.values()))
    assert texts["fig2_opt_mean"] == "6.4660"
    assert texts["fig2_opt_paper_mean"] == "6.47"
    assert texts["fig2_so_printed_agrees"] == "mean only"
    assert texts["fig2_ekf_agrees"] == "yes"


def test_comparison_rows_of_figure_3_and_4():
    rows = {r["id"]: r for r in walkthrough.comparison("fig3")}
    texts = walkthrough.comparison_texts("fig3", list(rows.values()))
    assert texts["fig3_opt_agrees"] == "no"
    assert texts["fig3_opt_printed_mean"] == "67.4516"
    assert texts["fig3_opt_printed_agrees"] == "mean only"
    rows4 = walkthrough.comparison("fig4")
    assert {r["quantity"] for r in rows4} == {"velocity"}
    texts4 = walkthrough.comparison_texts("fig4", rows4)
    assert texts4["fig4_opt_paper_mean"] == "—" and texts4["fig4_opt_agrees"] == "—"


def test_readings_figure_draws_both_readings():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = walkthrough.readings_figure("fig3", n=101)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels[0].startswith("from Eq. (6) (mean 20.74")
    assert any(label.startswith("Eq. (16) as printed (mean 67.45") for label in labels)
    plt.close(fig)
    with pytest.raises(ValueError, match="y_max"):
        walkthrough.readings_figure("fig3", y_max=1.0)


@pytest.mark.parametrize("key", ["fig2", "fig3"])
def test_trapezoid_depth_moments_converge_to_the_marginals(key):
    s = SCENARIOS[key]
    m = optimal.marginals(s.mu, s.rho, s.prior)
    mean, sd, n = walkthrough.trapezoid_depth_moments(s.mu, s.rho, s.prior, 1 / 16)
    assert n == 257
    # the geometric convergence of the rule leaves rounding only at this step
    assert mean == pytest.approx(m.depth_mean, abs=1e-9 * m.depth_sd)
    assert sd == pytest.approx(m.depth_sd, abs=1e-9 * m.depth_sd)
    coarse = walkthrough.trapezoid_depth_moments(s.mu, s.rho, s.prior, 1.0)
    assert abs(coarse[0] - m.depth_mean) > 1e-3


def test_trapezoid_depth_moments_printed_reading():
    s = SCENARIOS["fig3"]
    mean, sd, _ = walkthrough.trapezoid_depth_moments(s.mu, s.rho, s.prior, 1 / 16, reading="printed")
    assert mean == pytest.approx(67.4516, abs=1e-4)


def test_trapezoid_depth_moments_rejects_a_bad_range():
    s = SCENARIOS["fig2"]
    with pytest.raises(ValueError, match="t_range"):
        walkthrough.trapezoid_depth_moments(s.mu, s.rho, s.prior, 0.1, t_range=(1.0, -1.0))


def test_vec_formats_and_never_prints_negative_zero():
    assert walkthrough.vec([1.2, 6, -1.2]) == "(1.2000, 6.0000, -1.2000)"
    assert walkthrough.vec([-0.0, -1e-9, 0.25], 2) == "(0.00, 0.00, 0.25)"
    assert walkthrough.vec(np.array([2.0]), 0) == "(2)"
    with pytest.raises(ValueError, match="1-D"):
        walkthrough.vec(np.eye(2))
    with pytest.raises(ValueError, match="decimals"):
        walkthrough.vec([1.0], -1)


