"""The exact filter one bearing at a time (depthcore.exact.online) against the batch and by hand."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.special import log_ndtr, logsumexp, ndtr

from depthcore.exact import online, optimal

PRIOR_MEAN = np.array([0.5, 8.0, 0.2])
PRIOR_COV = np.array([[1.0, 0.3, 0.05], [0.3, 4.0, 0.0], [0.05, 0.0, 0.3]])


def track(N, noise, seed=3):
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.5, 1.5, N - 1)
    e = np.concatenate([[0.0], np.cumsum(steps)])
    rho = rng.uniform(0.5, 2.0, N) * noise
    mu = (0.6 + 0.05 * e) / (9.0 + e) + rho * rng.standard_normal(N)
    if N > 4:
        mu[4] = np.nan
    return mu, rho, steps


def run_online(mu, rho, steps, q, **options):
    f = online.Online(PRIOR_MEAN, PRIOR_COV, rho=0.01, process_noise=q, **options)
    states = [f.update(mu[0], rho=rho[0])]
    for k in range(1, mu.size):
        states.append(f.update(mu[k], rho=rho[k], step=steps[k - 1]))
    return f, states


@pytest.mark.parametrize("q", [0.0, 0.03])
@pytest.mark.parametrize("N", [3, 10, 30])
def test_after_n_frames_the_online_filter_is_the_batch_answer(N, q):
    mu, rho, steps = track(N, 0.01)
    f, states = run_online(mu, rho, steps, q)
    batch = optimal.run(mu, rho, PRIOR_MEAN, PRIOR_COV, process_noise=q, steps=steps)
    sd = np.sqrt(np.diag(batch.cov))
    assert states[-1].frame == N == f.frame
    assert_allclose(states[-1].mean, batch.mean, rtol=0, atol=1e-9 * sd.max())
    assert_allclose(np.sqrt(np.diag(states[-1].cov)), sd, rtol=1e-9)
    assert states[-1].depth_mean == states[-1].mean[1]
    # the predictive densities sum to the bank's log marginal likelihood, over the prior's
    # mass in front of the camera (where the nodes lie)
    log_front = log_ndtr(PRIOR_MEAN[1] / np.sqrt(PRIOR_COV[1, 1]))
    total = np.nansum([s.log_predictive for s in states])
    assert_allclose(total, batch.log_normaliser - log_front, rtol=1e-10)
    assert np.isnan(states[4].log_predictive) if N > 4 else True


def test_re_placed_nodes_keep_the_batch_answer_at_small_noise():
    mu, rho, steps = track(100, 1e-5)
    f, states = run_online(mu, rho, steps, 0.0)
    assert f.replacements >= 1
    assert f.node_count <= 4097
    batch = optimal.run(mu, rho, PRIOR_MEAN, PRIOR_COV, steps=steps)
    sd = np.sqrt(np.diag(batch.cov))
    assert_allclose(states[-1].mean, batch.mean, rtol=0, atol=1e-9 * sd.max())
    assert_allclose(np.sqrt(np.diag(states[-1].cov)), sd, rtol=1e-9)


def _evidence_and_predictive(mu, rho, steps, k, n=20001):
    """By hand, q = 0: p(mu_k | mu_1 .. mu_{k-1}) and its CDF at mu_k, on a dense depth grid.

    Given y_1 = y the bearings are linear in (x_1, v_1): mu_j = (x_1 + e_j v_1) / (y + e_j) + w_j.
    """
    e = np.concatenate([[0.0], np.cumsum(steps)])
    m, P = PRIOR_MEAN, PRIOR_COV
    iu = [0, 2]
    slope = P[iu, 1] / P[1, 1]
    Cu = P[np.ix_(iu, iu)] - np.outer(slope, P[1, iu])
    t = np.linspace(np.log(1e-12), np.log(300.0), n)
    log_post, pred_mean, pred_var = np.empty(n), np.empty(n), np.empty(n)
    past = [j for j in range(k) if not np.isnan(mu[j])]
    for i, y in enumerate(np.exp(t)):
        mz = m[iu] + slope * (y - m[1])
        Cz = Cu
        lp = -0.5 * (np.log(2 * np.pi * P[1, 1]) + (y - m[1]) ** 2 / P[1, 1]) + t[i]
        if past:
            H = np.stack([np.ones(len(past)), e[past]], -1) / (y + e[past])[:, None]
            S = H @ Cz @ H.T + np.diag(rho[past] ** 2)
            r = mu[past] - H @ mz
            lp += -0.5 * (np.linalg.slogdet(2 * np.pi * S)[1] + r @ np.linalg.solve(S, r))
            K = Cz @ H.T @ np.linalg.inv(S)
            mz, Cz = mz + K @ r, Cz - K @ H @ Cz
        h = np.array([1.0, e[k]]) / (y + e[k])
        log_post[i], pred_mean[i], pred_var[i] = lp, h @ mz, h @ Cz @ h + rho[k] ** 2
    w = np.exp(log_post - logsumexp(log_post))
    z = (mu[k] - pred_mean) / np.sqrt(pred_var)
    density = w @ (np.exp(-0.5 * z**2) / np.sqrt(2 * np.pi * pred_var))
    return np.log(density), w @ ndtr(z)


@pytest.mark.parametrize("k", [0, 2, 5, 9])
def test_the_predictive_density_and_tail_equal_a_numerical_integral(k):
    mu, rho, steps = track(10, 0.01)
    _, states = run_online(mu, rho, steps, 0.0)
    log_density, F = _evidence_and_predictive(mu, rho, steps, k)
    assert_allclose(states[k].log_predictive, log_density, rtol=0, atol=1e-8)
    assert_allclose(states[k].tail, 2 * min(F, 1 - F), rtol=1e-7)


def test_a_gated_bearing_is_a_missing_one():
    mu, rho, steps = track(12, 0.01)
    mu[7] += 0.2  # an outlier, 10 SDs and more out
    f, states = run_online(mu, rho, steps, 0.0, gate=1e-3)
    assert states[7].gated and states[7].tail < 1e-3
    assert not any(s.gated for s in states[:7] + states[8:])
    missing = mu.copy()
    missing[7] = np.nan
    _, plain = run_online(missing, rho, steps, 0.0)
    assert_allclose(states[-1].mean, plain[-1].mean, rtol=1e-13)
    assert_allclose(states[-1].cov, plain[-1].cov, rtol=1e-12)
    assert np.isnan(plain[7].tail) and not plain[7].gated


def test_refusals_name_the_argument():
    f = online.Online(PRIOR_MEAN, PRIOR_COV, rho=0.01)
    with pytest.raises(ValueError, match="step"):
        f.update(0.05, step=2.0)
    with pytest.raises(ValueError, match="mu"):
        f.update([0.05, 0.06])
    with pytest.raises(ValueError, match="mu"):
        f.update(np.inf)
    with pytest.raises(ValueError, match="rho"):
        f.update(0.05, rho=-1.0)
    with pytest.raises(ValueError, match="gate"):
        online.Online(PRIOR_MEAN, PRIOR_COV, rho=0.01, gate=1.5)
    with pytest.raises(ValueError, match="process_noise"):
        online.Online(PRIOR_MEAN, PRIOR_COV, rho=0.01, process_noise=-1.0)
    with pytest.raises(ValueError, match="prior_cov"):
        online.Online(PRIOR_MEAN, np.eye(2), rho=0.01)


def test_the_batch_door_reports_each_frame_and_gates_as_the_online_filter():
    mu, rho, steps = track(12, 0.01)
    mu[7] += 0.2
    post = optimal.run(mu, rho, PRIOR_MEAN, PRIOR_COV, steps=steps, gate=1e-3)
    _, states = run_online(mu, rho, steps, 0.0, gate=1e-3)
    u = post.updates
    assert u.gated.tolist() == [s.gated for s in states] and u.gated[7]
    assert_allclose(u.log_predictive, [s.log_predictive for s in states], rtol=1e-12)
    missing = mu.copy()
    missing[7] = np.nan
    plain = optimal.run(missing, rho, PRIOR_MEAN, PRIOR_COV, steps=steps)
    assert_allclose(post.mean, plain.mean, rtol=1e-13)
    # without a gate: the report of every frame, its sum the bank's log marginal likelihood
    ungated = plain.updates
    assert np.isnan(ungated.log_predictive[[4, 7]]).all() and not ungated.gated.any()
    log_front = log_ndtr(PRIOR_MEAN[1] / np.sqrt(PRIOR_COV[1, 1]))
    assert_allclose(np.nansum(ungated.log_predictive), plain.log_normaliser - log_front, rtol=1e-10)
    # a batch of tracks: one report per row
    batch = optimal.run(
        np.stack([mu, missing]), np.stack([rho, rho]), PRIOR_MEAN, PRIOR_COV, steps=steps, gate=1e-3
    )
    assert batch.updates.log_predictive.shape == (2, 12)
    assert_allclose(batch.mean[0], post.mean, rtol=1e-12)
    assert_allclose(batch.mean[1], post.mean, rtol=1e-12)
