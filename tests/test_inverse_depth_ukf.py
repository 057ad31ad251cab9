"""The inverse-depth UKF: its linear steps, its process noise, its small-noise limit."""

import numpy as np
import pytest

from depthcore.kalman import inverse_depth, inverse_depth_ukf, ukf
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS

FIG2 = SCENARIOS["fig2"]
Z = np.array([0.2, 0.15, 0.05])
S = np.array([[0.01, 0.001, 0.002], [0.001, 0.0009, 0.0001], [0.002, 0.0001, 0.003]])


def test_first_frame_is_the_kalman_update():
    """At frame 1 the bearing ``a_1`` is linear: the unscented update is the Kalman filter's."""
    u = inverse_depth_ukf.update(Z, S, 0.21, 0.01, 1)
    e = inverse_depth.update(Z, S, 0.21, 0.01, 1)
    np.testing.assert_allclose(u.mean, e.mean, rtol=1e-13)
    np.testing.assert_allclose(u.cov, e.cov, rtol=1e-11, atol=1e-17)


def test_prediction_moments_by_monte_carlo():
    """Mean and covariance of ``(a + s, w, s + w a_noise)`` under the Gaussian, 400,000 draws.

    Each entry is within 5 standard errors (a false alarm about 6e-7 per entry).
    """
    q = 1.0
    rng = np.random.default_rng(7)
    n = 400_000
    z = rng.multivariate_normal(Z, S, size=n)
    a = rng.normal(0.0, q, size=n)
    new = np.stack([z[:, 0] + z[:, 2], z[:, 1], z[:, 2] + z[:, 1] * a], axis=-1)
    mean, cov = inverse_depth_ukf.predict(Z, S, q)
    d = new - mean
    np.testing.assert_array_less(np.abs(d.mean(0)), 5 * d.std(0) / np.sqrt(n))
    prods = d[:, :, None] * d[:, None, :]
    se = prods.std(0) / np.sqrt(n)
    assert np.all(np.abs(prods.mean(0) - cov) < 5 * se)
    # the EKF's variance w_bar**2 q**2 is short by S_ww q**2, many standard errors here
    ekf_cov = inverse_depth.predict(Z, S, q).cov
    assert abs(prods.mean(0)[2, 2] - ekf_cov[2, 2]) > 10 * se[2, 2]


@pytest.mark.parametrize("q", [0.0, 0.002])
def test_agrees_with_the_inverse_depth_ekf_in_the_small_noise_limit(q):
    """Prior spread and noise scaled by eps: the two filters' means differ by O(eps) SDs."""
    truth = np.array([1.2, 4.0, -0.2])
    mu = np.array([model.project(model.G(truth, k)) for k in range(5)])
    P0 = np.diag([1.0, 4.0, 0.25])
    ratios = []
    for eps in (1e-2, 1e-3, 1e-4):
        args = (mu, eps * FIG2.rho, truth, eps**2 * P0, eps * q)
        u = inverse_depth_ukf.estimate(*args)
        e = inverse_depth.estimate(*args)
        sd = np.sqrt(np.diag(e.cov))
        ratios.append(np.max(np.abs(u.mean - e.mean) / sd))
        np.testing.assert_allclose(np.sqrt(np.diag(u.cov)), sd, rtol=20 * eps)
    assert ratios[-1] < 1e-3
    assert ratios[1] < ratios[0] / 5 and ratios[2] < ratios[1] / 5


def test_the_paper_prior_puts_sigma_points_behind_the_camera():
    prior = FIG2.prior
    with pytest.raises(ValueError, match="^mu: a sigma point .* behind the camera at frame 2"):
        inverse_depth_ukf.estimate(np.array(FIG2.mu), FIG2.rho, prior.mean, prior.cov)
    est = FILTERS["inverse_depth_ukf"](np.array(FIG2.mu), FIG2.rho, prior.mean, prior.cov)
    assert np.isfinite(est.depth_mean) and est.depth_sd > 0


def test_registry_entry_and_batch():
    f = FILTERS["inverse_depth_ukf"]
    assert f.any_frames and f.with_process_noise and not f.default
    truth = np.array([1.2, 4.0, -0.2])
    mu = np.array([model.project(model.G(truth, k)) for k in range(4)])
    batch = np.stack([mu, mu + 0.003, mu - 0.002])
    P0 = np.diag([0.5, 1.0, 0.1])
    est = f(batch, 0.005, truth, P0, 0.01)
    for b in range(3):
        one = inverse_depth_ukf.estimate(batch[b], 0.005, truth, P0, 0.01)
        np.testing.assert_allclose(est.mean[b], one.mean, rtol=1e-12)
        np.testing.assert_allclose(est.cov[b], one.cov, rtol=1e-10)


def test_refusals():
    with pytest.raises(ValueError, match="sigma_points must be a SigmaPoints"):
        inverse_depth_ukf.run(np.array(FIG2.mu), FIG2.rho, [1, 4, 0], np.eye(3), sigma_points=1)
    with pytest.raises(ValueError, match="process_noise"):
        inverse_depth_ukf.run(np.array(FIG2.mu), FIG2.rho, [1, 4, 0], np.eye(3), -1.0)
    with pytest.raises(ValueError, match="prior_mean"):
        inverse_depth_ukf.run(np.array(FIG2.mu), FIG2.rho, [1, -4, 0], np.eye(3))
    with pytest.raises(ValueError, match="kappa"):
        ukf.SigmaPoints(kappa=-5)
