"""The Kalman filter and its smoothers (Prince, section 19.2).

They are checked against filterpy and exact conditioning.

Every test names the textbook section it checks: the prediction (19.2.1), the
gain form of the measurement incorporation with its Joseph covariance (19.2.2),
the filter over a sequence and its marginal likelihood (19.2.3), the
nonstationary measurement model of the second example (19.2.5), and the
fixed-interval and fixed-lag smoothers (19.2.6).

The independent route is the whole trajectory as one Gaussian: the states
``W = (w_1 .. w_T)`` are an affine function of the independent Gaussians
``(w_1 - mu_0, eps_p2 .. eps_pT)``, the measurements an affine function of
``W`` plus independent noise, and the filtered, smoothed and likelihood
quantities are exact Gaussian conditioning and a multivariate normal density
of all the measurements.
"""

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter, rts_smoother
from numpy.testing import assert_allclose
from scipy import stats

from depthcore.kalman import linear
from depthcore.kalman.linear import (
    FilterResult,
    augment,
    fixed_interval_smoother,
    fixed_lag_smoother,
    predict,
    run,
    update,
)
from depthcore.problem.gaussian import MeanAndCov


def random_spd(rng, n, scale=1.0):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.3 * np.eye(n))


def random_model(rng, n=3, m=2, T=7, time_varying=False, offsets=True, singular_noise=False):
    """A random linear-Gaussian model with its prior and measurements."""
    Psi = rng.normal(size=(n, n)) / np.sqrt(n) + 0.5 * np.eye(n)
    if singular_noise:  # noise on the last component only, as in the depth model's velocity
        Sigma_p = np.zeros((n, n))
        Sigma_p[-1, -1] = 0.2
    else:
        Sigma_p = random_spd(rng, n, 0.2)
    Phi = rng.normal(size=(T, m, n)) if time_varying else rng.normal(size=(m, n))
    Sigma_m = random_spd(rng, m, 0.3)
    mu_p = rng.normal(size=n) if offsets else None
    mu_m = rng.normal(size=m) if offsets else None
    prior_mean = rng.normal(size=n)
    prior_cov = random_spd(rng, n, 2.0)
    x = rng.normal(size=(T, m)) * 2.0
    return dict(
        x=x,
        prior_mean=prior_mean,
        prior_cov=prior_cov,
        Psi=Psi,
        Sigma_p=Sigma_p,
        Phi=Phi,
        Sigma_m=Sigma_m,
        mu_p=mu_p,
        mu_m=mu_m,
    )


def step_matrices(model, T):
    """Per-step model arrays of a (non-batched) model dict."""
    n = model["prior_mean"].size
    m = model["x"].shape[-1]

    def per_step(a, steps, core):
        a = np.asarray(a, dtype=float)
        return [a if a.ndim == core else a[min(t, a.shape[0] - 1)] for t in range(steps)]

    mu_p = np.zeros(n) if model["mu_p"] is None else model["mu_p"]
    mu_m = np.zeros(m) if model["mu_m"] is None else model["mu_m"]
    return (
        per_step(model["Psi"], T - 1, 2),
        per_step(model["Sigma_p"], T - 1, 2),
        per_step(mu_p, T - 1, 1),
        per_step(model["Phi"], T, 2),
        per_step(model["Sigma_m"], T, 2),
        per_step(mu_m, T, 1),
    )


def dense_gaussian(model):
    """The trajectory and the measurements as one Gaussian.

    Returns (mean_W, cov_W, mean_X, cov_X, cov_WX).
    """
    x = model["x"]
    T, m = x.shape
    n = model["prior_mean"].size
    Psis, Qs, mu_ps, Phis, Rs, mu_ms = step_matrices(model, T)
    # W = A e + b with e = (w_1 - mu_0, eps_p2, .., eps_pT) ~ N(0, blockdiag(P0, Q..)).
    A = np.zeros((T * n, T * n))
    b = np.zeros(T * n)
    A[:n, :n] = np.eye(n)
    b[:n] = model["prior_mean"]
    for t in range(1, T):
        rows, prev = slice(t * n, (t + 1) * n), slice((t - 1) * n, t * n)
        A[rows] = Psis[t - 1] @ A[prev]
        A[rows, rows] += np.eye(n)
        b[rows] = Psis[t - 1] @ b[prev] + mu_ps[t - 1]
    E = np.zeros((T * n, T * n))
    E[:n, :n] = model["prior_cov"]
    for t in range(1, T):
        E[t * n : (t + 1) * n, t * n : (t + 1) * n] = Qs[t - 1]
    cov_W = A @ E @ A.T
    H = np.zeros((T * m, T * n))
    R = np.zeros((T * m, T * m))
    for t in range(T):
        H[t * m : (t + 1) * m, t * n : (t + 1) * n] = Phis[t]
        R[t * m : (t + 1) * m, t * m : (t + 1) * m] = Rs[t]
    mean_X = H @ b + np.concatenate(mu_ms)
    return b, cov_W, mean_X, H @ cov_W @ H.T + R, cov_W @ H.T


def condition(model, upto):
    """Means (T, n) and covariances (T, n, n) of every state given measurements 1 .. upto."""
    mean_W, cov_W, mean_X, cov_X, cov_WX = dense_gaussian(model)
    T, m = model["x"].shape
    n = model["prior_mean"].size
    k = upto * m
    gain = np.linalg.solve(cov_X[:k, :k], cov_WX[:, :k].T).T
    mean = mean_W + gain @ (model["x"].ravel()[:k] - mean_X[:k])
    cov = cov_W - gain @ cov_WX[:, :k].T
    means = mean.reshape(T, n)
    covs = np.stack([cov[t * n : (t + 1) * n, t * n : (t + 1) * n] for t in range(T)])
    return means, covs


def filterpy_run(model):
    """filterpy's KalmanFilter over the model's measurements.

    Returns means, covariances, log likelihoods.
    """
    x = model["x"]
    T, m = x.shape
    n = model["prior_mean"].size
    Psis, Qs, mu_ps, Phis, Rs, mu_ms = step_matrices(model, T)
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x = model["prior_mean"].reshape(n, 1).copy()
    kf.P = model["prior_cov"].copy()
    means, covs, lls = [], [], []
    for t in range(T):
        if t > 0:  # the offset mu_p enters as a control input B u with B = I
            kf.predict(u=mu_ps[t - 1].reshape(n, 1), B=np.eye(n), F=Psis[t - 1], Q=Qs[t - 1])
        # filterpy has no measurement offset: subtract it from the measurement
        kf.update((x[t] - mu_ms[t]).reshape(m, 1), R=Rs[t], H=Phis[t])
        means.append(kf.x[:, 0].copy())
        covs.append(kf.P.copy())
        lls.append(kf.log_likelihood)
    return np.array(means), np.array(covs), np.array(lls)


# --- 19.2.1 and 19.2.2: one step -------------------------------------------------------


def test_textbook_19_2_1_predict_matches_filterpy():
    rng = np.random.default_rng(1)
    n = 3
    mean, cov = rng.normal(size=n), random_spd(rng, n)
    Psi, Q, mu_p = rng.normal(size=(n, n)), random_spd(rng, n, 0.1), rng.normal(size=n)
    kf = KalmanFilter(dim_x=n, dim_z=1)
    kf.x, kf.P = mean.reshape(n, 1).copy(), cov.copy()
    kf.predict(u=mu_p.reshape(n, 1), B=np.eye(n), F=Psi, Q=Q)
    got = predict(mean, cov, Psi, Q, mu_p)
    assert isinstance(got, MeanAndCov)
    assert_allclose(got.mean, kf.x[:, 0], rtol=1e-13, atol=1e-14)
    assert_allclose(got.cov, kf.P, rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("m", [1, 2, 4])
def test_textbook_19_2_2_update_matches_filterpy(m):
    # filterpy's update is the same gain form with the Joseph covariance.
    rng = np.random.default_rng(2 + m)
    n = 3
    mean, cov = rng.normal(size=n), random_spd(rng, n)
    Phi, R, x = rng.normal(size=(m, n)), random_spd(rng, m, 0.5), rng.normal(size=m)
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x, kf.P = mean.reshape(n, 1).copy(), cov.copy()
    kf.update(x.reshape(m, 1), R=R, H=Phi)
    got = update(mean, cov, x, Phi, R)
    assert_allclose(got.mean, kf.x[:, 0], rtol=1e-12, atol=1e-14)
    assert_allclose(got.cov, kf.P, rtol=1e-12, atol=1e-14)
    assert_allclose(got.log_likelihood, kf.log_likelihood, rtol=1e-12)


def test_textbook_19_2_2_gain_form_equals_the_information_form_of_eq_19_10():
    # Eq. (19.10), before the matrix inversion lemma:
    # Sigma = (Sigma_+^-1 + Phi^T Sigma_m^-1 Phi)^-1,
    # mu = Sigma (Phi^T Sigma_m^-1 (x - mu_m) + Sigma_+^-1 mu_+); the Joseph form and
    # (I - K Phi) Sigma_+ are the same matrix.
    rng = np.random.default_rng(3)
    n, m = 4, 2
    mean, cov = rng.normal(size=n), random_spd(rng, n)
    Phi, R, x, mu_m = (
        rng.normal(size=(m, n)),
        random_spd(rng, m),
        rng.normal(size=m),
        rng.normal(size=m),
    )
    got = update(mean, cov, x, Phi, R, mu_m)
    info = np.linalg.inv(cov) + Phi.T @ np.linalg.solve(R, Phi)
    Sigma = np.linalg.inv(info)
    mu = Sigma @ (Phi.T @ np.linalg.solve(R, x - mu_m) + np.linalg.solve(cov, mean))
    assert_allclose(got.mean, mu, rtol=1e-12, atol=1e-13)
    assert_allclose(got.cov, Sigma, rtol=1e-11, atol=1e-13)
    K = cov @ Phi.T @ np.linalg.inv(R + Phi @ cov @ Phi.T)
    assert_allclose(got.cov, (np.eye(n) - K @ Phi) @ cov, rtol=1e-11, atol=1e-13)


def test_textbook_19_2_2_log_likelihood_is_the_innovation_density():
    rng = np.random.default_rng(4)
    n, m = 3, 2
    mean, cov = rng.normal(size=n), random_spd(rng, n)
    Phi, R, x, mu_m = (
        rng.normal(size=(m, n)),
        random_spd(rng, m),
        rng.normal(size=m),
        rng.normal(size=m),
    )
    expected = stats.multivariate_normal(mu_m + Phi @ mean, R + Phi @ cov @ Phi.T).logpdf(x)
    assert_allclose(update(mean, cov, x, Phi, R, mu_m).log_likelihood, expected, rtol=1e-13)


def test_textbook_19_2_2_joseph_form_stays_symmetric_positive_definite():
    # A broad prior and a precise measurement: the posterior variance along the measured
    # direction is 1e-12 of the prior's, where C - K S K^T loses most of its digits.
    prior_cov = np.array([[1e6, 0.3e6], [0.3e6, 1e6]])
    got = update(
        np.zeros(2), prior_cov, np.array([0.2]), np.array([[1.0, 0.5]]), np.array([[1e-6]])
    )
    assert_allclose(got.cov, got.cov.T, rtol=0, atol=0)
    assert np.all(np.linalg.eigvalsh(got.cov) > 0)


# --- 19.2.3: the filter over a sequence ------------------------------------------------


@pytest.mark.parametrize("m", [1, 2])
@pytest.mark.parametrize("time_varying", [False, True])
def test_textbook_19_2_3_filter_matches_filterpy(m, time_varying):
    model = random_model(
        np.random.default_rng(10 + m + 2 * time_varying), m=m, time_varying=time_varying
    )
    res = run(**model)
    assert isinstance(res, FilterResult)
    means, covs, lls = filterpy_run(model)
    assert_allclose(res.means, means, rtol=1e-11, atol=1e-12)
    assert_allclose(res.covs, covs, rtol=1e-11, atol=1e-12)
    assert_allclose(res.log_likelihoods, lls, rtol=1e-11)


@pytest.mark.parametrize("singular_noise", [False, True])
def test_textbook_19_2_3_filter_equals_dense_gaussian_conditioning(singular_noise):
    model = random_model(
        np.random.default_rng(20), time_varying=True, singular_noise=singular_noise
    )
    res = run(**model)
    T = model["x"].shape[0]
    for t in range(T):
        means, covs = condition(model, t + 1)
        assert_allclose(res.means[t], means[t], rtol=1e-9, atol=1e-10)
        assert_allclose(res.covs[t], covs[t], rtol=1e-9, atol=1e-10)
        if t + 1 < T:  # the prediction is the next state given the same measurements
            assert_allclose(res.predicted_means[t + 1], means[t + 1], rtol=1e-9, atol=1e-10)
            assert_allclose(res.predicted_covs[t + 1], covs[t + 1], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("m", [1, 3])
def test_textbook_19_2_3_log_likelihood_is_the_density_of_all_measurements(m):
    # The prediction-error decomposition: sum of the innovations' log densities equals
    # the multivariate normal log density of the stacked measurements.
    model = random_model(np.random.default_rng(30 + m), m=m, time_varying=True)
    _, _, mean_X, cov_X, _ = dense_gaussian(model)
    expected = stats.multivariate_normal(mean_X, cov_X).logpdf(model["x"].ravel())
    assert_allclose(run(**model).log_likelihood, expected, rtol=1e-11)


def test_textbook_19_2_5_alternating_scalar_measurements():
    # The second example: a 2-D Brownian state observed in its first coordinate at even
    # times and in its second at odd times (a nonstationary measurement model).
    rng = np.random.default_rng(40)
    T = 8
    Phi = np.stack([[[1.0, 0.0]] if t % 2 == 0 else [[0.0, 1.0]] for t in range(T)])
    model = dict(
        x=rng.normal(size=(T, 1)),
        prior_mean=np.zeros(2),
        prior_cov=10.0 * np.eye(2),
        Psi=np.eye(2),
        Sigma_p=0.1 * np.eye(2),
        Phi=Phi,
        Sigma_m=np.array([[0.2]]),
        mu_p=None,
        mu_m=None,
    )
    res = run(**model)
    means, covs, lls = filterpy_run(model)
    assert_allclose(res.means, means, rtol=1e-12, atol=1e-13)
    assert_allclose(res.covs, covs, rtol=1e-12, atol=1e-13)
    assert_allclose(res.log_likelihoods, lls, rtol=1e-12)
    # the measured coordinate's variance falls, the other's grows by the motion noise
    var = np.diagonal(res.covs, axis1=-2, axis2=-1)
    for t in range(1, T):
        seen, unseen = t % 2, 1 - t % 2
        assert var[t, seen] < var[t - 1, seen] + 0.1
        assert_allclose(var[t, unseen], var[t - 1, unseen] + 0.1, rtol=1e-12)


# --- 19.2.6: smoothers -----------------------------------------------------------------


def test_textbook_19_2_6_fixed_interval_smoother_matches_filterpy_rts():
    model = random_model(np.random.default_rng(50), offsets=False)
    res = run(**model)
    T = model["x"].shape[0]
    xs, Ps, _, _ = rts_smoother(res.means, res.covs, [model["Psi"]] * T, [model["Sigma_p"]] * T)
    got = fixed_interval_smoother(res, model["Psi"])
    assert_allclose(got.mean, xs, rtol=1e-11, atol=1e-12)
    assert_allclose(got.cov, Ps, rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("singular_noise", [False, True])
def test_textbook_19_2_6_fixed_interval_smoother_equals_dense_conditioning(singular_noise):
    model = random_model(
        np.random.default_rng(51), time_varying=True, singular_noise=singular_noise
    )
    T = model["x"].shape[0]
    Psi = np.broadcast_to(model["Psi"], (T - 1, 3, 3))  # given per step
    got = fixed_interval_smoother(run(**model), Psi)
    means, covs = condition(model, T)
    assert_allclose(got.mean, means, rtol=1e-9, atol=1e-10)
    assert_allclose(got.cov, covs, rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("lag", [0, 1, 2, 6, 20])
def test_textbook_19_2_6_fixed_lag_smoother_is_the_fixed_interval_marginal_at_the_lag(lag):
    # Entry s uses the measurements up to min(s + lag, T - 1) (0-based): the fixed-interval
    # smoother over that prefix, at s. lag = 0 is the filter; lag >= T - 1 the full smoother.
    model = random_model(np.random.default_rng(60), time_varying=True)
    T = model["x"].shape[0]
    got = fixed_lag_smoother(lag=lag, **model)
    for s in range(T):
        end = min(s + lag, T - 1) + 1
        prefix = dict(model, x=model["x"][:end], Phi=model["Phi"][:end])
        smoothed = fixed_interval_smoother(run(**prefix), model["Psi"])
        assert_allclose(got.mean[s], smoothed.mean[s], rtol=1e-9, atol=1e-11)
        assert_allclose(got.cov[s], smoothed.cov[s], rtol=1e-9, atol=1e-11)
    if lag == 0:
        res = run(**model)
        assert_allclose(got.mean, res.means, rtol=1e-12, atol=1e-14)


def test_textbook_19_2_6_augmented_model_copies_the_state_down():
    rng = np.random.default_rng(70)
    n, m, lag = 2, 1, 3
    Psi, Q, Phi, mu_p = (
        rng.normal(size=(n, n)),
        random_spd(rng, n),
        rng.normal(size=(m, n)),
        rng.normal(size=n),
    )
    Psi_a, Q_a, Phi_a, mu_pa = augment(Psi, Q, Phi, lag, mu_p)
    w = rng.normal(size=(lag + 1, n))  # (w_t, w_{t-1}, .., w_{t-lag})
    moved = (Psi_a @ w.ravel() + mu_pa).reshape(lag + 1, n)
    assert_allclose(moved[0], Psi @ w[0] + mu_p, rtol=1e-14)
    assert_allclose(moved[1:], w[:-1], rtol=0, atol=0)
    assert_allclose(Phi_a @ w.ravel(), Phi @ w[0], rtol=1e-14)
    assert_allclose(Q_a[:n, :n], Q)
    assert np.count_nonzero(Q_a) == np.count_nonzero(Q)


# --- the filter and smoother loops against their steps, at several dimensions ----------


def at_step(a, t, core):
    """Step ``t`` of a model array with ``core`` trailing axes (time on axis ``-core - 1``)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == core:
        return a
    return np.take(a, min(t, a.shape[-core - 1] - 1), axis=-core - 1)


def stepwise_filter(model):
    """Textbook 19.2.3 as its steps: :func:`update` (19.2.2) after :func:`predict` (19.2.1).

    Returns the filtered and predicted means and covariances and the log
    likelihoods, stacked on the time axis.
    """
    x = model["x"]
    T, n, m = x.shape[-2], model["prior_mean"].shape[-1], x.shape[-1]
    mu_p = np.zeros(n) if model["mu_p"] is None else model["mu_p"]
    mu_m = np.zeros(m) if model["mu_m"] is None else model["mu_m"]
    mean, cov = model["prior_mean"], model["prior_cov"]
    out = {k: [] for k in FilterResult._fields}
    for t in range(T):
        if t > 0:
            mean, cov = predict(
                mean,
                cov,
                at_step(model["Psi"], t - 1, 2),
                at_step(model["Sigma_p"], t - 1, 2),
                at_step(mu_p, t - 1, 1),
            )
        out["predicted_means"].append(mean)
        out["predicted_covs"].append(cov)
        mean, cov, ll = update(
            mean,
            cov,
            x[..., t, :],
            at_step(model["Phi"], t, 2),
            at_step(model["Sigma_m"], t, 2),
            at_step(mu_m, t, 1),
        )
        out["means"].append(mean)
        out["covs"].append(cov)
        out["log_likelihoods"].append(ll)
    stacked = {}
    for k, v in out.items():
        core = {"means": 1, "predicted_means": 1, "log_likelihoods": 0}.get(k, 2)
        v = np.broadcast_arrays(*v)
        stacked[k] = np.stack(v, axis=v[0].ndim - core)
    return FilterResult(**stacked)


def stepwise_smoother(filtered, Psi):
    """Textbook 19.2.6 as its steps: :func:`linear.smoother_step` from ``T`` back to 1."""
    T = filtered.means.shape[-2]
    gains = linear.smoother_gain(
        filtered.covs[..., :-1, :, :], filtered.predicted_covs[..., 1:, :, :], Psi
    )
    means, covs = [filtered.means[..., -1, :]], [filtered.covs[..., -1, :, :]]
    for t in range(T - 2, -1, -1):
        mean, cov = linear.smoother_step(
            gains[..., t, :, :],
            filtered.means[..., t, :],
            filtered.covs[..., t, :, :],
            filtered.predicted_means[..., t + 1, :],
            filtered.predicted_covs[..., t + 1, :, :],
            means[-1],
            covs[-1],
        )
        means.append(mean)
        covs.append(cov)
    return np.stack(means[::-1], axis=-2), np.stack(covs[::-1], axis=-3)


def batch_of(models):
    """Models stacked on a leading axis; the time-constant arrays get a time axis of length 1."""
    stack = {k: np.stack([md[k] for md in models]) for k in models[0]}
    for k, core in (
        ("Psi", 2),
        ("Sigma_p", 2),
        ("Phi", 2),
        ("Sigma_m", 2),
        ("mu_p", 1),
        ("mu_m", 1),
    ):
        if stack[k].ndim == core + 1:
            stack[k] = stack[k][:, None]
    return stack


def assert_relative(got, expected, rtol):
    """Every entry within ``rtol`` of the largest entry of ``expected`` along its last axes."""
    scale = np.max(np.abs(expected))
    assert np.max(np.abs(got - expected)) <= rtol * scale, np.max(np.abs(got - expected)) / scale


DIMENSIONS = [(n, m) for n in (2, 4, 6) for m in (1, 2, 3)]


@pytest.mark.parametrize(("n", "m"), DIMENSIONS)
@pytest.mark.parametrize("batched", [False, True])
def test_textbook_19_2_3_filter_is_its_steps_19_2_1_and_19_2_2(n, m, batched):
    # run's loop (time-first outputs, the log likelihoods scored after the loop; for a
    # single filter ndarray.dot and the closed-form 2 x 2 gain) against predict and update.
    rng = np.random.default_rng(100 + 10 * n + m)
    models = [random_model(rng, n=n, m=m, T=40, time_varying=True) for _ in range(3)]
    model = batch_of(models) if batched else models[0]
    res = run(**model)
    ref = stepwise_filter(model)
    for field in FilterResult._fields:
        assert getattr(res, field).shape == getattr(ref, field).shape
        assert_relative(getattr(res, field), getattr(ref, field), 1e-12)


@pytest.mark.parametrize(("n", "m"), DIMENSIONS)
def test_textbook_19_2_6_fixed_interval_smoother_is_its_steps(n, m):
    rng = np.random.default_rng(200 + 10 * n + m)
    for model, Psi in (
        (random_model(rng, n=n, m=m, T=40, singular_noise=True), None),
        (batch_of([random_model(rng, n=n, m=m, T=40) for _ in range(3)]), None),
    ):
        Psi = model["Psi"]
        res = run(**model)
        got = fixed_interval_smoother(res, Psi)
        means, covs = stepwise_smoother(res, Psi)
        assert_relative(got.mean, means, 1e-12)
        assert_relative(got.cov, covs, 1e-12)
        assert_allclose(got.cov, np.swapaxes(got.cov, -1, -2), rtol=0, atol=0)


@pytest.mark.parametrize(("n", "m"), DIMENSIONS)
def test_textbook_19_2_3_a_single_filter_equals_a_batch_of_one(n, m):
    # The single filter's route (ndarray.dot, the closed-form gain for m = 2) and the
    # batched one (matmul, LAPACK's solve) differ only by rounding.
    model = random_model(np.random.default_rng(300 + 10 * n + m), n=n, m=m, T=60)
    one, batch = run(**model), run(**batch_of([model]))
    for field in FilterResult._fields:
        assert_relative(getattr(one, field), getattr(batch, field)[0], 1e-12)
    s1 = fixed_interval_smoother(one, model["Psi"])
    sb = fixed_interval_smoother(batch, model["Psi"])
    assert_relative(s1.mean, sb.mean[0], 1e-12)
    assert_relative(s1.cov, sb.cov[0], 1e-12)


def plane_motion(n):
    """A point in the plane whose position, or velocity, or acceleration walks (``n = 2, 4, 6``).

    The state is the position and its first ``n / 2 - 1`` derivatives,
    ``Psi`` their Taylor step over one unit of time, ``Sigma_p`` noise on the
    highest derivative alone (singular for ``n > 2``, as in the depth model),
    and the measurement the position with correlated noise.
    """
    q = n // 2
    F = np.array(
        [[1.0 / math.factorial(j - i) if j >= i else 0.0 for j in range(q)] for i in range(q)]
    )
    Psi = np.kron(F, np.eye(2))
    Sigma_p = np.zeros((n, n))
    Sigma_p[-2:, -2:] = 1e-3 * np.eye(2)
    Phi = np.eye(2, n)
    Sigma_m = np.array([[0.04, 0.01], [0.01, 0.02]])
    return Psi, Sigma_p, Phi, Sigma_m


@pytest.mark.parametrize("n", [2, 4, 6])
def test_textbook_19_2_3_and_19_2_6_match_filterpy_over_a_long_sequence(n):
    # The benchmark's setting: 2-D measurements, 300 steps, filterpy's KalmanFilter and
    # rts_smoother as the independent route.
    T = 300
    Psi, Sigma_p, Phi, Sigma_m = plane_motion(n)
    rng = np.random.default_rng(500 + n)
    model = dict(
        x=np.cumsum(rng.normal(size=(T, 2)), axis=0) * 0.1,
        prior_mean=np.zeros(n),
        prior_cov=np.eye(n),
        Psi=Psi,
        Sigma_p=Sigma_p,
        Phi=Phi,
        Sigma_m=Sigma_m,
        mu_p=None,
        mu_m=None,
    )
    res = run(**model)
    means, covs, lls = filterpy_run(model)
    assert_relative(res.means, means, 1e-11)
    assert_relative(res.covs, covs, 1e-11)
    assert_allclose(res.log_likelihoods, lls, rtol=1e-11)
    xs, Ps, _, _ = rts_smoother(res.means, res.covs, [Psi] * T, [Sigma_p] * T)
    got = fixed_interval_smoother(res, Psi)
    assert_relative(got.mean, xs, 1e-11)
    assert_relative(got.cov, Ps, 1e-11)


@pytest.mark.parametrize("batched", [False, True])
def test_run_refuses_an_innovation_covariance_singular_to_working_precision(batched):
    # Both measurements see the first component, whose variance 1e155 leaves the
    # measurement noise below its rounding: S is singular in the doubles.
    x = np.ones((5, 2))
    args = (np.zeros(2), 1e155 * np.eye(2), np.eye(2), 1e155 * np.eye(2))
    with pytest.raises(ValueError, match=r"Sigma_m \(the measurement noise covariance\) is too"):
        run(x[None] if batched else x, *args, [[1.0, 0.0], [2.0, 0.0]], [[1.0, 0.2], [0.2, 1.0]])


# --- batching --------------------------------------------------------------------------


def test_batched_filter_and_smoothers_equal_a_loop():
    rng = np.random.default_rng(80)
    B, T, n, m = 4, 6, 3, 1
    models = [random_model(rng, n=n, m=m, T=T, time_varying=True) for _ in range(B)]
    stack = {k: np.stack([md[k] for md in models]) for k in models[0]}
    # Phi is (B, T, m, n), time on axis -3; the rest differ per trial but not in
    # time: a time axis of length 1 broadcasts over the steps.
    for k in ("Psi", "Sigma_p", "Sigma_m", "mu_p", "mu_m"):
        stack[k] = stack[k][:, None]
    res = run(**stack)
    smoothed = fixed_interval_smoother(res, stack["Psi"])
    lagged = fixed_lag_smoother(lag=2, **stack)
    for i, md in enumerate(models):
        one = run(**md)
        for field in FilterResult._fields:
            assert_allclose(getattr(res, field)[i], getattr(one, field), rtol=1e-13, atol=1e-14)
        s1 = fixed_interval_smoother(one, md["Psi"])
        assert_allclose(smoothed.mean[i], s1.mean, rtol=1e-13, atol=1e-14)
        assert_allclose(smoothed.cov[i], s1.cov, rtol=1e-13, atol=1e-14)
        l1 = fixed_lag_smoother(lag=2, **md)
        assert_allclose(lagged.mean[i], l1.mean, rtol=1e-13, atol=1e-14)
        assert_allclose(lagged.cov[i], l1.cov, rtol=1e-13, atol=1e-14)


def test_batched_steps_broadcast_a_shared_prior_over_measurements():
    # One prior, a (5, 7) grid of measurement matrices and measurements: every result
    # has the broadcast leading shape and equals the single-filter step.
    rng = np.random.default_rng(81)
    mean, cov = rng.normal(size=2), random_spd(rng, 2)
    Phi = rng.normal(size=(5, 7, 1, 2))
    x = rng.normal(size=(5, 7, 1))
    got = update(mean, cov, x, Phi, np.array([[0.3]]))
    assert got.mean.shape == (5, 7, 2) and got.cov.shape == (5, 7, 2, 2)
    assert got.log_likelihood.shape == (5, 7)
    one = update(mean, cov, x[3, 4], Phi[3, 4], np.array([[0.3]]))
    assert_allclose(got.mean[3, 4], one.mean, rtol=1e-14)
    assert_allclose(got.cov[3, 4], one.cov, rtol=1e-14)
    pred = predict(got.mean, got.cov, np.eye(2), np.zeros((2, 2)))
    assert pred.mean.shape == (5, 7, 2) and pred.cov.shape == (5, 7, 2, 2)


# --- refusals --------------------------------------------------------------------------


def bad(model, **changes):
    return dict(model, **changes)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(prior_mean=np.array([0.0, np.nan, 0.0])), "prior_mean must be finite"),
        (dict(x=np.full((7, 2), np.inf)), "x must be finite"),
        (dict(prior_cov=np.diag([1.0, -1.0, 1.0])), "prior_cov must be positive definite"),
        (dict(prior_cov=np.diag([1.0, 0.0, 1.0])), "prior_cov must be positive definite"),
        (
            dict(prior_cov=np.array([[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]])),
            "prior_cov must be symmetric",
        ),
        (
            dict(Sigma_m=np.diag([0.1, 0.0])),
            r"Sigma_m \(the measurement noise covariance\) must be positive definite",
        ),
        (dict(Sigma_p=-np.eye(3)), "Sigma_p must be positive semi-definite"),
        (dict(prior_cov=np.eye(2)), r"prior_cov must have trailing shape \(3, 3\)"),
        (dict(Psi=np.eye(2)), r"Psi must have trailing shape \(3, 3\)"),
        (dict(Phi=np.ones((2, 4))), r"Phi must have trailing shape \(m, 3\)"),
        (dict(x=np.ones((7, 3))), r"x must have trailing shape \(T, 2\)"),
        (dict(Phi=np.ones((5, 2, 3))), "Phi must have 7 \\(or 1\\) entries on its time axis"),
        (dict(mu_m=np.ones(3)), r"mu_m must have trailing shape \(2,\)"),
        (dict(x=np.ones(7)), "x must have at least 2 dimensions"),
        (dict(prior_mean="a"), "prior_mean must be numeric"),
    ],
)
def test_run_refuses_bad_input_naming_the_argument(change, message):
    model = random_model(np.random.default_rng(90))
    with pytest.raises(ValueError, match=message):
        run(**bad(model, **change))


def test_scalar_noise_variance_must_be_positive():
    for variance in (0.0, -1e-3):
        with pytest.raises(ValueError, match="Sigma_m .* must be positive definite"):
            update(
                np.zeros(2),
                np.eye(2),
                np.array([0.1]),
                np.array([[1.0, 0.0]]),
                np.array([[variance]]),
            )


@pytest.mark.parametrize("lag", [-1, 1.5, True, "2"])
def test_fixed_lag_smoother_refuses_a_bad_lag(lag):
    model = random_model(np.random.default_rng(91))
    with pytest.raises(ValueError, match="lag must be an integer >= 0"):
        fixed_lag_smoother(lag=lag, **model)


def test_fixed_interval_smoother_refuses_what_is_not_a_filter_result():
    with pytest.raises(ValueError, match="filtered must be a FilterResult"):
        fixed_interval_smoother((np.zeros((3, 2)), np.zeros((3, 2, 2))), np.eye(2))


def test_textbook_19_2_6_fixed_interval_smoother_with_a_singular_prediction():
    # Psi drops the second component and there is no motion noise: every predicted
    # covariance is singular, and the smoother's gain uses the pseudo-inverse.
    rng = np.random.default_rng(92)
    T = 5
    model = dict(
        x=rng.normal(size=(T, 1)),
        prior_mean=np.array([0.3, -0.2]),
        prior_cov=np.array([[2.0, 0.5], [0.5, 1.0]]),
        Psi=np.array([[1.0, 1.0], [0.0, 0.0]]),
        Sigma_p=np.zeros((2, 2)),
        Phi=np.array([[1.0, 0.5]]),
        Sigma_m=np.array([[0.3]]),
        mu_p=None,
        mu_m=None,
    )
    res = run(**model)
    assert np.all(np.abs(np.linalg.det(res.predicted_covs[1:])) < 1e-15)
    got = fixed_interval_smoother(res, model["Psi"])
    means, covs = condition(model, T)
    assert_allclose(got.mean, means, rtol=1e-9, atol=1e-11)
    assert_allclose(got.cov, covs, rtol=1e-9, atol=1e-11)


def test_module_docstring_cites_the_textbook():
    assert "19.2.2" in linear.__doc__ and "19.2.6" in linear.__doc__
