"""The exact filter on tracks as they come: gaps, noise per frame, uneven steps.

Every number is checked against a route written here from the model alone: the
bearings given the depth at frame 1 are linear-Gaussian in
``(x_1, v_1, a_1 .. a_{N-1})`` (the motion of :mod:`depthcore.problem.frames`),
so ``p(mu | y_1)`` and the Gaussian of ``(x_N, v_N)`` given ``y_1`` are
closed-form regressions, and the depth is integrated on a dense grid.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.special import logsumexp

from depthcore.exact import bank as bk
from depthcore.exact import optimal, posterior, smoother

PRIOR_MEAN = np.array([0.5, 8.0, 0.2])
PRIOR_COV = np.array([[1.0, 0.3, 0.05], [0.3, 4.0, 0.0], [0.05, 0.0, 0.3]])
MU = np.array([0.06, 0.055, np.nan, 0.048, 0.047, 0.04])
RHO = np.array([0.01, 0.02, np.nan, 0.01, 0.015, 0.01])
STEPS = np.array([1.0, 0.5, 2.0, 1.0, 1.5])


def dense_posterior(mu, rho, steps, q, m=PRIOR_MEAN, P=PRIOR_COV, n=8001, frame=-1):
    """Mean (3,) and covariance (3, 3) of the state at ``frame`` (default N) by a dense grid.

    Given ``y_1 = y`` the present bearings are ``mu_k = x_k / y_k + w_k`` with
    ``x_k = x_1 + e_k v_1 + sum_{j < k} (e_k - e_{j+1}) a_j`` (``e_k`` the depth
    travelled to frame k, signed), linear in ``z = (x_1, v_1, a_1 .. a_{N-1})``; the
    depth ``y_1`` runs over a grid in ``log(y_1 - f)`` above the depth ``f`` at which
    the point would reach the camera at some frame (0 while it recedes).
    """
    mu, rho = np.asarray(mu, float), np.broadcast_to(np.asarray(rho, float), np.shape(mu))
    N = mu.size
    e = np.concatenate([[0.0], np.cumsum(steps)])
    keep = ~np.isnan(mu)
    # z's prior given y: (x_1, v_1) conditioned on y_1 = y; a_j ~ N(0, q**2 s_j)
    iu = [0, 2]
    slope = P[iu, 1] / P[1, 1]
    Cu = P[np.ix_(iu, iu)] - np.outer(slope, P[1, iu])
    D = 2 + N - 1
    Cz = np.zeros((D, D))
    Cz[:2, :2] = Cu
    Cz[2:, 2:] = np.diag(q**2 * np.abs(np.asarray(steps, float)))
    # x_k and v_N as rows acting on z
    X = np.zeros((N, D))
    X[:, 0], X[:, 1] = 1.0, e
    for k in range(N):
        for j in range(k):
            X[k, 2 + j] = e[k] - e[j + 1]
    frame = frame % N
    vN = np.zeros(D)
    vN[1] = 1.0
    vN[2 : 2 + frame] = 1.0
    t = np.linspace(np.log(1e-9), np.log(300.0), n)  # the density vanishes at the floor
    y = max(0.0, -e.min()) + np.exp(t)
    # every node at once: (n, ...) stacks of the regression at each depth
    mz = np.zeros((n, D))
    mz[:, :2] = m[iu] + np.outer(y - m[1], slope)
    H = X[keep][None] / (y[:, None] + e[keep][None])[:, :, None]
    S = H @ Cz @ np.swapaxes(H, 1, 2) + np.diag(rho[keep] ** 2)
    r = mu[keep][None] - np.einsum("nij,nj->ni", H, mz)
    sol = np.linalg.solve(S, r[..., None])[..., 0]
    log_f = (
        -0.5 * (np.log(2 * np.pi * P[1, 1]) + (y - m[1]) ** 2 / P[1, 1])
        - 0.5 * (np.linalg.slogdet(2 * np.pi * S)[1] + np.einsum("ni,ni->n", r, sol))
        + t  # dy = (y - f) dt
    )
    K = Cz @ np.swapaxes(H, 1, 2) @ np.linalg.inv(S)
    mpost = mz + np.einsum("nij,nj->ni", K, r)
    Cpost = Cz - K @ H @ Cz
    A = np.stack([X[frame], vN])  # (x_k, v_k) at the frame
    mxv = np.einsum("ij,nj->ni", A, mpost)
    Cxv = A @ Cpost @ A.T
    means = np.stack([mxv[:, 0], y + e[frame], mxv[:, 1]], axis=1)
    second = np.zeros((n, 3, 3))
    second[:, 0, 0], second[:, 0, 2] = Cxv[:, 0, 0], Cxv[:, 0, 1]
    second[:, 2, 0], second[:, 2, 2] = Cxv[:, 1, 0], Cxv[:, 1, 1]
    second += means[:, :, None] * means[:, None, :]
    w = np.exp(log_f - logsumexp(log_f))
    mean = w @ means
    cov = np.einsum("i,ijk->jk", w, second) - np.outer(mean, mean)
    return mean, cov


@pytest.mark.parametrize("q", [0.0, 0.05])
def test_gaps_noise_per_frame_and_steps_equal_a_dense_grid(q):
    post = optimal.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, process_noise=q, steps=STEPS)
    mean, cov = dense_posterior(MU, RHO, STEPS, q)
    sd = np.sqrt(np.diag(cov))
    assert_allclose(post.mean, mean, atol=1e-8 * sd.max(), rtol=0)
    assert_allclose(np.sqrt(np.diag(post.cov)), sd, rtol=1e-8)
    assert_allclose(post.cov, cov, atol=1e-8 * sd.max() ** 2)


def test_a_gap_is_the_posterior_given_the_present_bearings():
    """NaN at frame k equals the track without it, its two steps merged (q = 0)."""
    rho = 0.01
    with_gap = optimal.run(MU, rho, PRIOR_MEAN, PRIOR_COV)
    merged = optimal.run(np.delete(MU, 2), rho, PRIOR_MEAN, PRIOR_COV, steps=[1.0, 2.0, 1.0, 1.0])
    assert_allclose(with_gap.mean, merged.mean, rtol=1e-12, atol=1e-15)
    assert_allclose(with_gap.cov, merged.cov, rtol=1e-10, atol=1e-16)
    # the same nodes: the bank alone, frame by frame, equals the merged bank exactly
    nodes = with_gap.bank.nodes
    a = bk.filter_bank(nodes, MU, rho, PRIOR_MEAN, PRIOR_COV)
    b = bk.filter_bank(nodes, np.delete(MU, 2), rho, PRIOR_MEAN, PRIOR_COV, steps=[1, 2, 1, 1])
    assert_allclose(a.log_weight, b.log_weight, rtol=1e-13)
    assert_allclose(a.mean, b.mean, rtol=1e-12, atol=1e-15)


def test_two_unit_steps_without_the_middle_bearing_are_one_step_of_two_only_without_noise():
    mu = np.array([0.06, np.nan, 0.05, 0.046])
    nodes = np.linspace(3.0, 20.0, 7)
    a = bk.filter_bank(nodes, mu, 0.01, PRIOR_MEAN, PRIOR_COV, process_noise=0.0)
    b = bk.filter_bank(nodes, mu[[0, 2, 3]], 0.01, PRIOR_MEAN, PRIOR_COV, steps=[2.0, 1.0])
    assert_allclose(a.log_weight, b.log_weight, rtol=1e-13)
    # with process noise the velocity variance added over the gap is q**2 (1 + 1) = q**2 2
    # too, but the position also integrates the first step's acceleration over the second
    # step: the two differ
    a = bk.filter_bank(nodes, mu, 0.01, PRIOR_MEAN, PRIOR_COV, process_noise=0.1)
    b = bk.filter_bank(nodes, mu[[0, 2, 3]], 0.01, PRIOR_MEAN, PRIOR_COV, 0.1, steps=[2.0, 1.0])
    assert np.max(np.abs(a.log_weight - b.log_weight)) > 1e-6


def test_the_history_and_step_agree_with_the_closed_form():
    nodes = np.linspace(3.0, 20.0, 5)
    args = dict(nodes=nodes, rho=RHO, prior_mean=PRIOR_MEAN, prior_cov=PRIOR_COV)
    closed = bk.filter_bank(mu=MU, process_noise=0.05, steps=STEPS, **args)
    hist = bk.filter_bank(mu=MU, process_noise=0.05, steps=STEPS, history=True, **args)
    assert_allclose(hist.log_weight, closed.log_weight, rtol=1e-12)
    assert_allclose(hist.mean, closed.mean, rtol=1e-11, atol=1e-14)
    assert_allclose(hist.cov, closed.cov, rtol=1e-10, atol=1e-16)
    first = bk.filter_bank(nodes, MU[:3], RHO[:3], PRIOR_MEAN, PRIOR_COV, 0.05, steps=STEPS[:2])
    for k in range(3, MU.size):
        first = bk.step(first, MU[k], rho=RHO[k], step=STEPS[k - 1], gaps=True)
    assert_allclose(first.log_weight, closed.log_weight, rtol=1e-12)
    assert_allclose(first.mean, closed.mean, rtol=1e-11, atol=1e-14)


def test_noise_per_frame_equal_at_every_frame_is_the_paper_arithmetic():
    mu = np.array([0.06, 0.055, 0.05, 0.048])
    a = optimal.run(mu, 0.01, PRIOR_MEAN, PRIOR_COV)
    b = optimal.run(mu, np.full(4, 0.01), PRIOR_MEAN, PRIOR_COV, steps=np.ones(3))
    assert_allclose(b.mean, a.mean, rtol=0, atol=0)
    assert_allclose(b.cov, a.cov, rtol=0, atol=0)


def test_refusals_name_the_argument():
    with pytest.raises(ValueError, match="^steps must be nonzero"):
        optimal.run(MU, 0.01, PRIOR_MEAN, PRIOR_COV, steps=[1.0, 0.0, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="reading"):
        optimal.run(MU, 0.01, PRIOR_MEAN, PRIOR_COV, reading="printed")
    with pytest.raises(ValueError, match="mu"):
        optimal.run(np.array([0.1, np.nan, np.nan, 0.2]), 0.01, PRIOR_MEAN, PRIOR_COV)
    with pytest.raises(ValueError, match="gate"):
        optimal.run(MU, 0.01, PRIOR_MEAN, PRIOR_COV, gate=2.0)
    with pytest.raises(ValueError, match="mu_next must be finite"):
        bk.step(bk.filter_bank([5.0], [0.1], 0.01, PRIOR_MEAN, PRIOR_COV), np.nan)


def test_batches_of_tracks_with_different_gaps():
    mu = np.stack([MU, np.where(np.arange(6) == 4, np.nan, MU + 0.001)])
    mu[1, 2] = 0.052
    batch = posterior.posterior(mu, 0.01, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
    for i in range(2):
        one = posterior.posterior(mu[i], 0.01, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
        assert_allclose(batch.mean[i], one.mean, rtol=1e-12)


def test_the_smoothers_of_a_track_with_gaps_noise_per_frame_and_steps():
    """Filtered, fixed-lag and fixed-interval states against the dense grid (q > 0)."""
    q, lag = 0.05, 2
    res = smoother.track(MU, RHO, PRIOR_MEAN, PRIOR_COV, q, lag=lag, steps=STEPS)
    N = MU.size
    for k in (1, 2, 3, 5):
        cases = [
            (res.filtered, dense_posterior(MU[: k + 1], RHO[: k + 1], STEPS[:k], q)),
            (res.interval, dense_posterior(MU, RHO, STEPS, q, frame=k)),
        ]
        t = min(k + lag, N - 1)
        cases.append(
            (res.lagged, dense_posterior(MU[: t + 1], RHO[: t + 1], STEPS[:t], q, frame=k))
        )
        for series, (mean, cov) in cases:
            sd = np.sqrt(np.diag(cov))
            assert_allclose(series.mean[k], mean, rtol=0, atol=1e-8 * sd.max())
            assert_allclose(np.sqrt(np.diag(series.cov[k])), sd, rtol=1e-8)
    # the last frame's smoothed state is the filtered one
    assert_allclose(res.interval.mean[-1], res.filtered.mean[-1], rtol=1e-12)


def test_the_smoother_refuses_a_track_without_its_first_bearing():
    with pytest.raises(ValueError, match=r"mu\[0\] must be present"):
        smoother.track(np.r_[np.nan, MU[1:]], 0.01, PRIOR_MEAN, PRIOR_COV)
    with pytest.raises(ValueError, match="steps"):
        smoother.track(MU, 0.01, PRIOR_MEAN, PRIOR_COV, steps=[1.0, 2.0])


#: A camera that approaches the point (every step negative), and one that goes back and forth.
APPROACHING = -STEPS
BACK_AND_FORTH = np.array([1.0, -0.5, -2.0, -1.0, 1.5])


@pytest.mark.parametrize("q", [0.0, 0.05])
@pytest.mark.parametrize("steps", [APPROACHING, BACK_AND_FORTH], ids=["approaching", "mixed"])
def test_signed_steps_equal_a_dense_grid_above_the_nearest_depth(steps, q):
    """Negative steps (the camera approaches): the grid runs above the depth at frame 1 where
    the point would reach the camera, the process noise grows with |s|; to 1e-8 of an SD."""
    mu = MU.copy()
    post = optimal.run(mu, RHO, PRIOR_MEAN, PRIOR_COV, process_noise=q, steps=steps)
    mean, cov = dense_posterior(mu, RHO, steps, q)
    sd = np.sqrt(np.diag(cov))
    assert_allclose(post.mean, mean, atol=1e-8 * sd.max(), rtol=0)
    assert_allclose(np.sqrt(np.diag(post.cov)), sd, rtol=1e-8)
    # the filter one frame at a time (the smoother's filtered states) agrees at every frame
    track = smoother.track(mu, RHO, PRIOR_MEAN, PRIOR_COV, q, steps=steps)
    for k in (2, 4):
        mean_k, cov_k = dense_posterior(mu[: k + 1], RHO[: k + 1], steps[:k], q)
        sd_k = np.sqrt(np.diag(cov_k))
        assert_allclose(track.filtered.mean[k], mean_k, atol=1e-7 * sd_k.max(), rtol=0)


def test_no_node_below_the_floor_has_weight_and_the_wrong_direction_is_far_off():
    post = optimal.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, steps=APPROACHING)
    floor = float(np.sum(STEPS))  # the depth travelled towards the camera
    assert post.bank.floor == pytest.approx(floor)
    weighted = post.probabilities > 0
    assert np.all(post.bank.nodes[weighted] > floor) and np.sum(weighted) > 20
    # a filter given the nodes below the floor gives them no weight
    b = bk.filter_bank([floor / 2, floor + 1.0], MU, RHO, PRIOR_MEAN, PRIOR_COV, steps=APPROACHING)
    assert b.log_weight[0] == -np.inf and np.isfinite(b.log_weight[1])
    with pytest.raises(ValueError, match="^nodes: every node is at or behind the floor"):
        bk.filter_bank([1.0, 2.0], MU, RHO, PRIOR_MEAN, PRIOR_COV, steps=APPROACHING)
    # the same bearings read as a receding camera: another answer, many SDs away
    wrong = optimal.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
    assert abs(wrong.mean[1] - post.mean[1]) > 3 * np.sqrt(post.cov[1, 1])


def test_a_step_that_reaches_the_camera_takes_the_nodes_weight_online():
    """bank.step with a negative step: the nodes it brings to the camera lose their weight."""
    b = bk.filter_bank([0.8, 3.0, 6.0], MU[:2], RHO[:2], PRIOR_MEAN, PRIOR_COV, steps=[1.0])
    after = bk.step(b, 0.05, rho=0.01, step=-2.0)
    assert after.log_weight[0] == -np.inf and np.all(np.isfinite(after.log_weight[1:]))
    rerun = bk.filter_bank(
        [3.0, 6.0], after.mu, after.frame_noise, PRIOR_MEAN, PRIOR_COV, steps=[1.0, -2.0]
    )
    assert_allclose(after.log_weight[1:], rerun.log_weight, rtol=1e-12)
    assert_allclose(after.mean[1:], rerun.mean, rtol=1e-12)
