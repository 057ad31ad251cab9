"""Theorem 1 at small noise: with prior mean G^-2 c the EKF equals p_s, Eqs. (19)-(24)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from depthcore.kalman import ekf, second_order
from depthcore.problem import model
from depthcore.problem.gaussian import Gaussian

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@st.composite
def triples(draw):
    """Valid measurement triples: noise-free depth c2 - 2 at the first frame in (0.05, 200)."""
    mu2 = draw(st.floats(-1.0, 1.0))
    d = draw(st.floats(0.01, 0.5)) * draw(st.sampled_from([-1.0, 1.0]))
    c2 = 2.0 + draw(st.floats(0.05, 200.0))
    mu1 = mu2 + c2 * d / 2.0  # c2 = 2 (mu1 - mu2) / d
    return np.array([mu1, mu2, d - mu1 + 2.0 * mu2])


def _information_solve_50_digits(mu, rho, scale):
    """Eq. (24) in 50-digit arithmetic: D = (g^T g / rho^2 + A2^T P^-1 A2)^-1 at c, P = scale I."""
    import mpmath as mp

    mp.mp.dps = 50
    m1, m2, m3 = (mp.mpf(float(v)) for v in mu)
    d = m3 + m1 - 2 * m2
    c = [2 * m3 * (m1 - m2) / d, 2 * (m1 - m2) / d, (2 * m1 * m3 - m2 * m3 - m1 * m2) / d]
    rows = []
    for k in range(3):
        s = k - 2
        n = [c[0] + s * c[2], c[1] + s]
        rows.append([1 / n[1], -n[0] / n[1] ** 2, s / n[1]])  # h^T F^s
    g = mp.matrix(rows)
    A2 = mp.matrix([[1, 0, -2], [0, 1, 0], [0, 0, 1]])
    D = mp.inverse(g.T * g / mp.mpf(rho) ** 2 + A2.T * (mp.eye(3) / mp.mpf(scale)) * A2)
    return np.array(D.tolist(), dtype=float)


@settings(max_examples=150, deadline=None)
@given(
    mu=triples(),
    log_rho=st.floats(np.log(1e-5), np.log(0.05)),
    log_scale=st.floats(np.log(1.0), np.log(1e4)),
)
def test_theorem1_small_noise_ekf_equals_p_s_and_the_exact_covariance(mu, log_rho, log_scale):
    """Theorem 1, Eqs. (19), (24): with prior mean G^-2 c, p_s and the EKF have the same
    mean (c, Eq. (19)) and covariance, the D of Eq. (24) from a 50-digit solve, to 1e-9
    relative."""
    rho, scale = float(np.exp(log_rho)), float(np.exp(log_scale))
    c = model.noise_free_state(mu)
    prior = Gaussian(second_order.A2 @ c + second_order.b2, scale * np.eye(3))
    p_s = second_order.run(mu, rho, prior.mean, prior.cov)
    p_e = ekf.run(mu, rho, prior.mean, prior.cov).posterior
    assert np.linalg.norm(p_s.mean - p_e.mean) <= 1e-9 * np.linalg.norm(p_e.mean)
    assert np.linalg.norm(p_s.mean - c) <= 1e-9 * np.linalg.norm(c)
    assert np.linalg.norm(p_s.cov - p_e.cov) <= 1e-9 * np.linalg.norm(p_e.cov)
    D = _information_solve_50_digits(mu, rho, scale)
    assert np.linalg.norm(p_s.cov - D) <= 1e-9 * np.linalg.norm(D)
    batch_mean, batch_cov = second_order.second_order_batch(mu[None], rho, prior.mean, prior.cov)
    assert np.linalg.norm(batch_cov[0] - D) <= 1e-9 * np.linalg.norm(D)


def test_p_s_matches_a_50_digit_information_solve_at_rho_1e_5():
    """Eq. (24) in 50-digit arithmetic: D = (g^T g / rho^2 + A2^T P^-1 A2)^-1 at c."""
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 50
    mu = ["-0.3", "0", "0.2"]
    m1, m2, m3 = (mp.mpf(v) for v in mu)
    d = m3 + m1 - 2 * m2
    c = [2 * m3 * (m1 - m2) / d, 2 * (m1 - m2) / d, (2 * m1 * m3 - m2 * m3 - m1 * m2) / d]
    rows = []
    for k in range(3):
        s = k - 2
        n = [c[0] + s * c[2], c[1] + s]
        h = [1 / n[1], -n[0] / n[1] ** 2, 0]
        rows.append([h[0], h[1], s * h[0]])  # h^T F^s
    g = mp.matrix(rows)
    A2 = mp.matrix([[1, 0, -2], [0, 1, 0], [0, 0, 1]])
    rho = mp.mpf("1e-5")
    D = mp.inverse(g.T * g / rho**2 + A2.T * (mp.eye(3) / 1000) * A2)
    D = np.array(D.tolist(), dtype=float)
    cf = np.array([float(v) for v in c])
    prior = Gaussian(second_order.A2 @ cf + second_order.b2, 1000 * np.eye(3))
    p_s = second_order.run(np.array([-0.3, 0, 0.2]), 1e-5, prior.mean, prior.cov)
    scale = np.sqrt(np.outer(np.diag(D), np.diag(D)))
    assert np.max(np.abs(p_s.cov - D) / scale) < 1e-12
    batch_mean, batch_cov = second_order.second_order_batch(
        np.array([[-0.3, 0, 0.2]]), 1e-5, prior.mean, prior.cov
    )
    assert np.max(np.abs(batch_cov[0] - D) / scale) < 1e-12
    assert np.allclose(batch_mean[0], cf, rtol=0, atol=1e-12)
