"""The unscented Kalman filter (Prince section 19.4) on the paper's problem."""

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from filterpy.kalman import unscented_transform as filterpy_unscented_transform
from numpy.testing import assert_allclose

from depthcore.kalman.ekf import predict as ekf_predict
from depthcore.kalman.ekf import run as ekf_run
from depthcore.kalman.ekf import update as ekf_update
from depthcore.kalman.ukf import (
    SigmaPoints,
    measurement_update,
    run,
    unscented_transform,
    update,
)
from depthcore.problem import model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import noise_free_state
from depthcore.problem.scenarios import MU_17, SCENARIOS

#: Sigma-point rules exercised throughout: the default, Wan and van der
#: Merwe's usual (alpha = 1e-3 is too extreme for the checks at 1e-12, so 0.1),
#: and a Julier-style positive kappa.
RULES = [
    SigmaPoints(),
    SigmaPoints(alpha=0.1, beta=2.0, kappa=0.0),
    SigmaPoints(alpha=0.5, beta=2.0, kappa=1.0),
    SigmaPoints(alpha=1.0, beta=0.0, kappa=2.0),
]

C_17 = noise_free_state(MU_17)
#: A prior tight enough that every sigma point stays in front of the camera.
TIGHT = Gaussian(model.G(C_17, -2) + [0.05, 0.4, -0.05], np.diag([0.04, 1.0, 0.02]))


def random_gaussian(rng, batch=()):
    mean = rng.normal(size=batch + (3,)) + [0.0, 5.0, 0.0]
    A = rng.normal(size=batch + (3, 3))
    return mean, A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(3)


def kalman_update(n, C, mu, rho, a, b):
    """The Kalman update for the linear measurement ``mu = a.x + b + w``."""
    s = rho**2 + a @ C @ a
    K = C @ a / s
    return n + K * (mu - a @ n - b), C - np.outer(K, K) * s


# --- sigma points and the unscented transform ------------------------------------------


@pytest.mark.parametrize("rule", RULES)
def test_sigma_points_reproduce_mean_and_covariance(rule):
    rng = np.random.default_rng(1)
    mean, cov = random_gaussian(rng, (4,))
    X = rule.points(mean, cov)
    Wm, Wc = rule.weights()
    assert X.shape == (4, 7, 3)
    assert_allclose(Wm.sum(), 1.0, rtol=0, atol=1e-12)
    # Mean with Wm, covariance with Wc (the centre's deviation is exactly zero).
    assert_allclose(np.einsum("i,bij->bj", Wm, X), mean, rtol=0, atol=1e-12 * np.abs(mean).max())
    d = X - mean[:, None, :]
    assert_allclose(
        np.einsum("i,bij,bik->bjk", Wc, d, d), cov, rtol=0, atol=1e-12 * np.abs(cov).max()
    )


@pytest.mark.parametrize("rule", RULES)
def test_sigma_points_match_filterpy(rule):
    mean, cov = random_gaussian(np.random.default_rng(2))
    theirs = MerweScaledSigmaPoints(3, alpha=rule.alpha, beta=rule.beta, kappa=rule.kappa)
    # filterpy's rows of the upper Cholesky factor are the columns of numpy's lower one.
    assert_allclose(rule.points(mean, cov), theirs.sigma_points(mean, cov), rtol=1e-13, atol=1e-13)
    Wm, Wc = rule.weights()
    assert_allclose(Wm, theirs.Wm, rtol=1e-14)
    assert_allclose(Wc, theirs.Wc, rtol=1e-14)


def test_sigma_points_broadcast_a_batch_of_means_against_one_covariance():
    mean, cov = random_gaussian(np.random.default_rng(10), (5,))
    X = SigmaPoints().points(mean, cov[0])
    assert X.shape == (5, 7, 3)
    assert_allclose(X[2], SigmaPoints().points(mean[2], cov[0]), rtol=1e-15)


def test_sigma_points_default_weights_are_julier_uhlmann():
    Wm, Wc = SigmaPoints().weights()
    # kappa = 3 - d = 0: the centre has no weight and the six points 1/6 each, sqrt(3) SDs out.
    assert_allclose(Wm, [0.0] + [1 / 6] * 6, atol=1e-15)
    assert_allclose(Wc, Wm, atol=1e-15)
    X = SigmaPoints().points(np.zeros(3), np.eye(3))
    assert_allclose(X[1:4], np.sqrt(3) * np.eye(3), rtol=1e-15)


@pytest.mark.parametrize("rule", RULES)
def test_unscented_transform_is_exact_for_linear_maps(rule):
    rng = np.random.default_rng(3)
    mean, cov = random_gaussian(rng)
    A = rng.normal(size=(2, 3))
    b = rng.normal(size=2)
    Wm, Wc = rule.weights()
    Q = np.diag([0.3, 0.7])
    got = unscented_transform(rule.points(mean, cov) @ A.T + b, Wm, Wc, Q)
    scale = np.abs(A @ cov @ A.T).max()
    assert_allclose(got.mean, A @ mean + b, rtol=1e-12, atol=1e-12)
    assert_allclose(got.cov, A @ cov @ A.T + Q, rtol=0, atol=1e-12 * scale)


def test_unscented_transform_matches_filterpy():
    rule = RULES[2]
    mean, cov = random_gaussian(np.random.default_rng(4))
    Z = model.project(rule.points(mean, cov))[:, None]
    Wm, Wc = rule.weights()
    ours = unscented_transform(Z, Wm, Wc, np.array([[1e-4]]))
    theirs = filterpy_unscented_transform(Z, Wm, Wc, np.array([[1e-4]]))
    assert_allclose(ours.mean, theirs[0], rtol=1e-13)
    assert_allclose(ours.cov, theirs[1], rtol=1e-13)


# --- the update -----------------------------------------------------------------------


@pytest.mark.parametrize("rule", RULES)
def test_update_on_a_linear_measurement_is_the_kalman_update(rule):
    rng = np.random.default_rng(5)
    n, C = random_gaussian(rng)
    a, b, rho, mu = rng.normal(size=3), 0.3, 0.2, 1.7
    got = measurement_update(n, C, mu, rho, lambda x: x @ a + b, rule)
    m, P = kalman_update(n, C, mu, rho, a, b)
    assert_allclose(got.mean, m, rtol=1e-12, atol=1e-12)
    assert_allclose(got.cov, P, rtol=0, atol=1e-12 * np.abs(C).max())


def test_ukf_ekf_comparison():
    # filterpy's test of the same name: on a linear model (here a linear
    # measurement, the motion being linear already) the UKF and the Kalman
    # filter agree at every step.
    rng = np.random.default_rng(6)
    a = np.array([0.2, -0.05, 0.1])
    x1 = np.array([0.5, 6.0, 0.2])
    rho = 0.01
    mu = [a @ model.G(x1, k) + rho * rng.standard_normal() for k in range(3)]
    m_u, P_u = np.array([0.0, 4.0, 0.0]), 10.0 * np.eye(3)
    m_k, P_k = m_u, P_u
    for k in range(3):
        if k:
            m_u, P_u = ekf_predict(m_u, P_u)
            m_k, P_k = model.F @ m_k + model.e, model.F @ P_k @ model.F.T
        m_u, P_u = measurement_update(m_u, P_u, mu[k], rho, lambda x: x @ a, RULES[1])
        m_k, P_k = kalman_update(m_k, P_k, mu[k], rho, a, 0.0)
        assert_allclose(m_u, m_k, rtol=1e-10, atol=1e-10)
        assert_allclose(P_u, P_k, rtol=0, atol=1e-10 * np.abs(P_k).max())


def test_update_approaches_the_ekf_update_as_the_covariance_shrinks():
    # With covariance s**2 the sigma points sample x/y over a region of size s,
    # where it differs from its tangent (the EKF's Eq. (11)) by O(s**2).
    n = np.array([1.0, 5.0, 0.3])
    errors = []
    for s in (1e-1, 1e-2, 1e-3):
        C = s**2 * np.diag([1.0, 4.0, 1.0])
        u, e = update(n, C, 0.21, 1e-3), ekf_update(n, C, 0.21, 1e-3)
        errors.append(
            (np.abs(u.mean - e.mean).max() / s, np.abs(u.cov - e.cov).max() / np.abs(e.cov).max())
        )
    errors = np.array(errors)
    assert errors[-1, 0] < 1e-5 and errors[-1, 1] < 1e-8
    assert np.all(errors[1:] < errors[:-1] / 8)


# --- the filter -----------------------------------------------------------------------


def filterpy_run(mu, rho, prior, rule):
    """The same filter with filterpy's UnscentedKalmanFilter."""
    points = MerweScaledSigmaPoints(3, alpha=rule.alpha, beta=rule.beta, kappa=rule.kappa)
    f = UnscentedKalmanFilter(
        dim_x=3,
        dim_z=1,
        dt=1.0,
        points=points,
        fx=lambda x, dt: model.F @ x + model.e,
        hx=lambda x: np.array([x[0] / x[1]]),
    )
    f.x, f.P = prior.mean.copy(), prior.cov.copy()
    f.Q, f.R = np.zeros((3, 3)), np.array([[rho**2]])
    f.sigmas_f = points.sigma_points(f.x, f.P)  # the prior is the state at time 1: update first
    means, covs = [], []
    for k, z in enumerate(mu):
        if k:
            f.predict()
        f.update(np.array([z]))
        means.append(f.x.copy())
        covs.append(f.P.copy())
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("rule", RULES)
def test_ukf_matches_filterpy(rule):
    rng = np.random.default_rng(7)
    mu = model.simulate(C_17, 3, 0.005, 0.0, rng).mu
    ours = run(mu, 0.005, TIGHT.mean, TIGHT.cov, sigma_points=rule)
    means, covs = filterpy_run(mu, 0.005, TIGHT, rule)
    # Same arithmetic up to the order of summation; the covariances lose about
    # log10(cond) ~ 4 digits to cancellation in C - c c^T / s.
    assert_allclose(ours.means, means, rtol=1e-10, atol=1e-12)
    for k in range(3):
        assert_allclose(ours.covs[k], covs[k], rtol=0, atol=1e-10 * np.abs(covs[k]).max())


def test_ukf_matches_filterpy_on_the_paper_prior_across_the_pole():
    s = SCENARIOS["fig2"]
    ours = run(s.mu, s.rho, s.prior.mean, s.prior.cov, allow_behind_camera=True)
    means, covs = filterpy_run(s.mu, s.rho, s.prior, SigmaPoints())
    assert_allclose(ours.means, means, rtol=1e-9, atol=1e-9)
    for k in range(3):
        assert_allclose(ours.covs[k], covs[k], rtol=0, atol=1e-9 * np.abs(covs[k]).max())


def test_run_is_batched_like_a_loop():
    rng = np.random.default_rng(8)
    mu = model.simulate(C_17, 3, 0.005, 0.0, rng, size=6).mu
    means, covs = run(mu, 0.005, TIGHT.mean, TIGHT.cov)
    assert means.shape == (6, 3, 3) and covs.shape == (6, 3, 3, 3)
    for i in range(6):
        h = run(mu[i], 0.005, TIGHT.mean, TIGHT.cov)
        assert_allclose(means[i], h.means, rtol=1e-13, atol=1e-15)
        assert_allclose(covs[i], h.covs, rtol=1e-12, atol=1e-15)


def test_run_takes_two_batch_dimensions():
    rng = np.random.default_rng(9)
    mu = model.simulate(C_17, 3, 0.005, 0.0, rng, size=6).mu.reshape(2, 3, 3)
    means, covs = run(mu, 0.005, TIGHT.mean, TIGHT.cov)
    flat = run(mu.reshape(6, 3), 0.005, TIGHT.mean, TIGHT.cov)
    assert_allclose(means.reshape(6, 3, 3), flat[0], rtol=1e-15)
    assert_allclose(covs.reshape(6, 3, 3, 3), flat[1], rtol=1e-15)


def test_history_and_posterior():
    h = run(MU_17, 0.005, TIGHT.mean, TIGHT.cov)
    assert h.means.shape == (3, 3) and h.covs.shape == (3, 3, 3)
    assert_allclose(h.posterior.mean, h.means[-1])
    assert_allclose(h.posterior.cov, h.covs[-1])
    for P in h.covs:
        assert_allclose(P, P.T, rtol=0, atol=0)
        assert np.all(np.linalg.eigvalsh(P) > 0)


def test_ukf_approaches_the_ekf_in_the_small_noise_tight_prior_limit():
    # The sigma points sample x/y over a region of size s; the UKF differs from
    # the EKF by the curvature over that region, O(s**2) relative to s.
    errors = []
    for s in (1e-1, 1e-2, 1e-3):
        prior = Gaussian(model.G(C_17, -2) + [0.01, 0.05, -0.01], s**2 * np.diag([1.0, 4.0, 1.0]))
        u, e = (
            run(MU_17, 0.05 * s, prior.mean, prior.cov),
            ekf_run(MU_17, 0.05 * s, prior.mean, prior.cov),
        )
        errors.append(
            (
                np.abs(u.means - e.means).max() / s,
                np.abs(u.covs - e.covs).max() / np.abs(e.covs).max(),
            )
        )
    errors = np.array(errors)
    assert errors[-1, 0] < 1e-3 and errors[-1, 1] < 1e-6
    assert np.all(errors[1:] < errors[:-1] / 8)  # shrinking like s (means) and s**2 (covs)


# --- bad input ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "mu, message",
    [
        ((0.1, 0.1, 0.1), "mu is degenerate"),
        ((np.nan, 0.0, 0.2), "mu has 2 bearings present"),
        ((np.inf, 0.0, 0.2), "mu must be finite"),
        ((0.2, 0.0, -0.3), "mu puts the point behind the camera"),
        ((-0.3, 0.0), r"mu must have shape (\(3,\)|\(\.\.\., N\) with N >= 3)"),
    ],
)
def test_ukf_rejects_bad_measurements(mu, message):
    with pytest.raises(ValueError, match=message):
        run(mu, 0.005, TIGHT.mean, TIGHT.cov)


@pytest.mark.parametrize("rho", [0.0, -0.005, np.nan])
def test_ukf_rejects_bad_rho(rho):
    with pytest.raises(ValueError, match="rho must be"):
        run(MU_17, rho, TIGHT.mean, TIGHT.cov)
    with pytest.raises(ValueError, match="rho must be"):
        run(np.array([MU_17]), rho, TIGHT.mean, TIGHT.cov)


def test_ukf_rejects_sigma_points_behind_the_camera_on_the_paper_prior():
    # Depth SD 31.6 times sqrt(3) = 54.8 against a prior mean depth of 4.
    s = SCENARIOS["fig2"]
    with pytest.raises(ValueError, match=r"measurement 1: sigma point 5 has depth -50.77.* behind"):
        run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    # A small enough alpha keeps every point in front.
    run(s.mu, s.rho, s.prior.mean, s.prior.cov, sigma_points=SigmaPoints(alpha=0.05, beta=2.0))


def test_ukf_across_the_pole_learns_nothing_about_depth_on_fig2():
    # The module docstring's account: after mu1 the EKF keeps the ray x = mu1 y
    # (correlation -1), the UKF's regression over +-55 units does not.
    s = SCENARIOS["fig2"]
    u = run(s.mu, s.rho, s.prior.mean, s.prior.cov, allow_behind_camera=True)
    e = ekf_run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    corr = [P[0, 1] / np.sqrt(P[0, 0] * P[1, 1]) for P in (u.covs[0], e.covs[0])]
    assert abs(corr[0]) < 0.2 and corr[1] < -0.999
    assert u.posterior.marginal("y")[1] > 30.0  # the prior's 31.6, hardly reduced
    assert e.posterior.marginal("y")[1] < 0.2


def test_run_names_the_trial_with_a_sigma_point_behind_the_camera():
    mean = np.array([TIGHT.mean, TIGHT.mean - [0.0, 3.5, 0.0]])
    with pytest.raises(ValueError, match=r"sigma point 5 of trial \(1,\) has depth"):
        run(np.array([MU_17, MU_17]), 0.005, mean, TIGHT.cov)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"alpha": 0.0}, "alpha must be positive"),
        ({"alpha": -1.0}, "alpha must be positive"),
        ({"kappa": -3.0}, "kappa must exceed -dim"),
        ({"beta": np.inf}, "beta must be finite"),
        ({"dim": 0}, "dim must be a positive integer"),
    ],
)
def test_sigma_points_reject_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SigmaPoints(**kwargs)


def test_sigma_points_reject_bad_shapes_and_covariances():
    with pytest.raises(ValueError, match="mean and cov must have shapes"):
        SigmaPoints().points(np.zeros(2), np.eye(3))
    with pytest.raises(ValueError, match="cov must be positive definite"):
        SigmaPoints().points(np.zeros(3), -np.eye(3))


def test_run_takes_rho_batched_like_the_ekf():
    mu = np.array([MU_17, MU_17, MU_17])
    rho = np.array([0.004, 0.005, 0.008])
    means, covs = run(mu, rho, TIGHT.mean, TIGHT.cov)
    for i in range(3):
        m, c = run(mu[i], rho[i], TIGHT.mean, TIGHT.cov)
        assert_allclose(means[i], m, rtol=1e-13, atol=1e-15)
        assert_allclose(covs[i], c, rtol=1e-12, atol=1e-18)
    with pytest.raises(ValueError, match=r"rho must be a scalar or have shape \(3,\)"):
        run(mu, rho[:2], TIGHT.mean, TIGHT.cov)


# --- N frames and process noise ---------------------------------------------------------


def filterpy_run_with_process_noise(mu, rho, prior, rule, q):
    """filterpy's UnscentedKalmanFilter with ``Q = diag(0, 0, q**2)``."""
    points = MerweScaledSigmaPoints(3, alpha=rule.alpha, beta=rule.beta, kappa=rule.kappa)
    f = UnscentedKalmanFilter(
        dim_x=3,
        dim_z=1,
        dt=1.0,
        points=points,
        fx=lambda x, dt: model.F @ x + model.e,
        hx=lambda x: np.array([x[0] / x[1]]),
    )
    f.x, f.P = prior.mean.copy(), prior.cov.copy()
    f.Q, f.R = np.diag([0.0, 0.0, q**2]), np.array([[rho**2]])
    f.sigmas_f = points.sigma_points(f.x, f.P)
    means, covs = [], []
    for k, z in enumerate(mu):
        if k:
            f.predict()
        f.update(np.array([z]))
        means.append(f.x.copy())
        covs.append(f.P.copy())
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("rule", RULES)
def test_six_frame_ukf_with_process_noise_matches_filterpy(rule):
    rng = np.random.default_rng(11)
    mu = model.simulate(TIGHT.mean, 6, 0.005, 0.0, rng, frame=1).mu
    q = 0.02
    ours = run(mu, 0.005, TIGHT.mean, TIGHT.cov, process_noise=q, sigma_points=rule)
    means, covs = filterpy_run_with_process_noise(mu, 0.005, TIGHT, rule, q)
    assert ours.means.shape == (6, 3)
    assert_allclose(ours.means, means, rtol=1e-10, atol=1e-12)
    for k in range(6):
        assert_allclose(ours.covs[k], covs[k], rtol=0, atol=1e-10 * np.abs(covs[k]).max())


def test_process_noise_zero_is_the_papers_ukf():
    h = run(MU_17, 0.005, TIGHT.mean, TIGHT.cov)
    again = run(MU_17, 0.005, TIGHT.mean, TIGHT.cov, process_noise=0.0)
    assert np.array_equal(h.means, again.means) and np.array_equal(h.covs, again.covs)
