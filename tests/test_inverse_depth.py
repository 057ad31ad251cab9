"""Tests of the inverse-depth EKF [civera2008]."""

import numpy as np
import pytest

from depthcore.kalman import ekf, inverse_depth
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS


def _map(x):
    return np.array([x[0] / x[1], 1.0 / x[1], x[2] / x[1]])


def _back(z, k):
    return np.array([z[0] / z[1], 1.0 / z[1] + k - 1, z[2] / z[1]])


def _jacobian(f, x, step=1e-6):
    return np.stack([(f(x + e) - f(x - e)) / (2 * step) for e in step * np.eye(3)], axis=1)


def test_prior_is_linearised_at_its_mean():
    m, P = np.array([-1.2, 4.0, 0.3]), np.array([[2.0, 0.3, 0.1], [0.3, 1.0, 0.2], [0.1, 0.2, 0.5]])
    z, S = inverse_depth.prior(m, P)
    np.testing.assert_allclose(z, _map(m), rtol=1e-14)
    J = _jacobian(_map, m)
    np.testing.assert_allclose(S, J @ P @ J.T, rtol=1e-7)


def test_to_state_is_linearised_at_its_mean():
    z, S = np.array([0.3, 0.2, 0.25]), np.diag([1e-3, 2e-4, 5e-4])
    out = inverse_depth.to_state(z, S, 3)
    np.testing.assert_allclose(out.mean, _back(z, 3), rtol=1e-14)
    J = _jacobian(lambda u: _back(u, 3), z)
    np.testing.assert_allclose(out.cov, J @ S @ J.T, rtol=1e-7)


def test_first_bearing_is_linear_so_its_update_is_exact_conditioning():
    """mu_1 = a_1 + w_1: the update equals the Gaussian conditional of (a, w, s) given mu_1."""
    z, S = inverse_depth.prior([-1.2, 4.0, 0.0], 1000 * np.eye(3))
    rho, mu = 0.005, -0.3
    out = inverse_depth.update(z, S, mu, rho, 1)
    h = np.array([1.0, 0.0, 0.0])
    joint = np.block([[S, (S @ h)[:, None]], [(h @ S)[None, :], np.array([[h @ S @ h + rho**2]])]])
    gain = joint[:3, 3] / joint[3, 3]
    np.testing.assert_allclose(out.mean, z + gain * (mu - z[0]), rtol=1e-12)
    np.testing.assert_allclose(out.cov, S - np.outer(gain, joint[3, :3]), rtol=1e-9, atol=1e-12)


def test_update_gradient_by_finite_differences():
    z = np.array([0.1, 0.2, 0.3])
    for k in (1, 2, 5):
        num = _jacobian(lambda u, k=k: np.array([u[0] / (1 + (k - 1) * u[1])] * 3), z)[0]
        np.testing.assert_allclose(
            inverse_depth.observation_vector(z, k), num, rtol=1e-7, atol=1e-12
        )


def test_prediction_is_linear_with_process_noise_on_s():
    z, S = np.array([0.1, 0.2, 0.3]), np.diag([1.0, 2.0, 3.0])
    out = inverse_depth.predict(z, S, 0.5)
    F = model.G_linear(1)
    np.testing.assert_allclose(out.mean, F @ z)
    np.testing.assert_allclose(out.cov, F @ S @ F.T + np.diag([0, 0, (0.2 * 0.5) ** 2]))


def test_bearings_from_a_far_point_over_many_frames_recover_it():
    truth = np.array([10.0, 60.0, 1.0])
    mu = model.project(np.stack([model.G(truth, k) for k in range(30)]))
    est = inverse_depth.estimate(mu, 1e-4, [8.0, 50.0, 0.0], np.diag([100.0, 400.0, 4.0]))
    np.testing.assert_allclose(est.mean, model.G(truth, 29), rtol=1e-3)


def test_depends_on_the_prior_mean_less_than_the_ekf_on_fig6():
    """Fig. 6 raises the prior's depth by 2.

    The EKF's depth moves by > 2, the inverse-depth EKF's by < 1.
    """
    a, b = SCENARIOS["fig2"], SCENARIOS["fig6"]
    moved = (
        inverse_depth.estimate(np.array(b.mu), b.rho, b.prior.mean, b.prior.cov).mean[1]
        - inverse_depth.estimate(np.array(a.mu), a.rho, a.prior.mean, a.prior.cov).mean[1]
    )
    ekf_moved = (
        ekf.run(np.array(b.mu), b.rho, b.prior.mean, b.prior.cov)[0][-1, 1]
        - ekf.run(np.array(a.mu), a.rho, a.prior.mean, a.prior.cov)[0][-1, 1]
    )
    assert ekf_moved > 2.0 and 0 < moved < 1.0


def test_batched_equals_looped():
    s = SCENARIOS["fig2"]
    mu = np.array([s.mu, SCENARIOS["fig3"].mu])
    both = inverse_depth.estimate(mu, s.rho, s.prior.mean, s.prior.cov, process_noise=0.01)
    for i in range(2):
        one = inverse_depth.estimate(mu[i], s.rho, s.prior.mean, s.prior.cov, process_noise=0.01)
        np.testing.assert_allclose(both.mean[i], one.mean, rtol=1e-13)
        np.testing.assert_allclose(both.cov[i], one.cov, rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"mu": [np.nan, 0.0]}, "mu"),
        ({"rho": -1.0}, "rho"),
        ({"process_noise": -0.1}, "process_noise"),
        ({"prior_mean": [0.0, 0.0, 0.0]}, "prior_mean"),
        ({"prior_mean": [0.0, np.inf, 0.0]}, "prior_mean"),
    ],
)
def test_bad_input_is_refused(kwargs, name):
    s = SCENARIOS["fig2"]
    args = {"mu": s.mu, "rho": s.rho, "prior_mean": s.prior.mean, "prior_cov": s.prior.cov}
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        inverse_depth.estimate(**args)


def test_an_estimate_at_infinity_is_refused():
    """Bearings that drive the mean inverse depth below zero get a one-line refusal, not a NaN."""
    with pytest.raises(ValueError, match="inverse depth"):
        inverse_depth.to_state(np.array([0.1, -0.01, 0.0]), np.eye(3), 3)


def test_the_depth_interval_is_the_exact_image_of_the_inverse_depths():
    # Monte Carlo of the filter's own Gaussian on w: the depth 1/w + k - 1 lies
    # below the median with probability 1/2 and inside the interval with the
    # level's probability (200,000 draws: binomial SE about 0.001).
    s = SCENARIOS["fig2"]
    means, covs = inverse_depth.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    z, S = means[-1], covs[-1]
    median, low, high = inverse_depth.depth_interval(z, S, 3, 0.68)
    w = np.random.default_rng(0).normal(z[1], np.sqrt(S[1, 1]), 200_000)
    y = np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0) + 2, np.inf)
    assert np.mean(y < median) == pytest.approx(0.5, abs=0.005)
    assert np.mean((low <= y) & (y <= high)) == pytest.approx(0.68, abs=0.005)
    # the delta method's mean lies at the median's depth: both are 1/w + 2 at the mean w
    delta = inverse_depth.to_state(z, S, 3)
    assert delta.mean[1] == pytest.approx(median, rel=1e-14)
    # a wide Gaussian whose interval reaches w = 0: the depth's interval is unbounded
    wide = S.copy()
    wide[1, 1] = (2 * z[1]) ** 2
    assert inverse_depth.depth_interval(z, wide, 3)[2] == np.inf
    with pytest.raises(ValueError, match="level must lie in"):
        inverse_depth.depth_interval(z, S, 3, 1.0)
