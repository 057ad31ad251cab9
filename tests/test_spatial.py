"""The exact filter for a point in 3-D (``depthcore.exact.spatial``) against independent routes.

The route here is written from the model alone: given the depth at frame 1 the pairs
are linear in ``z = (x_1, v_1, h_1, w_1, a_1 .. a_{N-1}, b_1 .. b_{N-1})`` (the
accelerations of both velocities), so ``p(pairs | y_1)`` and the Gaussian of the state
at frame ``N`` are one regression with a four-dimensional prior block, and the depth is
integrated on a dense grid in ``log(y_1 - floor)``. No Kalman recursion, no quadrature.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.special import logsumexp

from depthcore.exact import posterior, spatial

MU = np.array([0.06, 0.055, np.nan, 0.048, 0.047, 0.04])
NU = np.array([0.02, 0.025, np.nan, 0.03, 0.031, 0.034])
PAIRS = np.stack([MU, NU], axis=-1)
RHO = np.array([0.01, 0.02, np.nan, 0.01, 0.015, 0.01])
STEPS = np.array([1.0, 0.5, 2.0, 1.0, 1.5])
PRIOR_MEAN = np.array([0.5, 8.0, 0.2, 0.1, 0.0])
PRIOR_COV = np.array(
    [
        [1.0, 0.3, 0.05, 0.1, 0.0],
        [0.3, 4.0, 0.0, 0.2, 0.0],
        [0.05, 0.0, 0.3, 0.0, 0.02],
        [0.1, 0.2, 0.0, 1.0, 0.05],
        [0.0, 0.0, 0.02, 0.05, 0.3],
    ]
)


def dense_posterior(pairs, rho, steps, q, m=PRIOR_MEAN, P=PRIOR_COV, n=8001):
    """Mean (5,) and covariance (5, 5) of ``(x, y, v, h, w)`` at frame N by a dense grid."""
    pairs = np.asarray(pairs, float)
    N = len(pairs)
    rho = np.broadcast_to(np.asarray(rho, float), (N,))
    e = np.concatenate([[0.0], np.cumsum(steps)])
    keep = ~np.isnan(pairs[:, 0])
    u = [0, 2, 3, 4]
    slope = P[u, 1] / P[1, 1]
    Cu = P[np.ix_(u, u)] - np.outer(slope, P[1, u])
    D = 4 + 2 * (N - 1)
    Cz = np.zeros((D, D))
    Cz[:4, :4] = Cu
    noise = q**2 * np.abs(np.asarray(steps, float))
    Cz[4 : 4 + N - 1, 4 : 4 + N - 1] = np.diag(noise)
    Cz[4 + N - 1 :, 4 + N - 1 :] = np.diag(noise)
    X = np.zeros((N, D))  # x_k as a row acting on z
    Hh = np.zeros((N, D))  # h_k
    X[:, 0], X[:, 1] = 1.0, e
    Hh[:, 2], Hh[:, 3] = 1.0, e
    for k in range(N):
        for j in range(k):
            X[k, 4 + j] = e[k] - e[j + 1]
            Hh[k, 4 + N - 1 + j] = e[k] - e[j + 1]
    vN, wN = np.zeros(D), np.zeros(D)
    vN[1], wN[3] = 1.0, 1.0
    vN[4 : 4 + N - 1] = 1.0
    wN[4 + N - 1 :] = 1.0
    floor = max(0.0, -e.min())
    t = np.linspace(np.log(1e-9), np.log(300.0), n)
    y = floor + np.exp(t)
    mz = np.zeros((n, D))
    mz[:, :4] = m[u] + np.outer(y - m[1], slope)
    rows = np.concatenate([X[keep], Hh[keep]])  # (2 n_present, D)
    depth = np.concatenate([e[keep], e[keep]])
    obs = np.concatenate([pairs[keep, 0], pairs[keep, 1]])
    r2 = np.concatenate([rho[keep], rho[keep]]) ** 2
    H = rows[None] / (y[:, None] + depth[None])[:, :, None]
    S = H @ Cz @ np.swapaxes(H, 1, 2) + np.diag(r2)
    r = obs[None] - np.einsum("nij,nj->ni", H, mz)
    sol = np.linalg.solve(S, r[..., None])[..., 0]
    log_f = (
        -0.5 * (np.log(2 * np.pi * P[1, 1]) + (y - m[1]) ** 2 / P[1, 1])
        - 0.5 * (np.linalg.slogdet(2 * np.pi * S)[1] + np.einsum("ni,ni->n", r, sol))
        + t
    )
    K = Cz @ np.swapaxes(H, 1, 2) @ np.linalg.inv(S)
    mpost = mz + np.einsum("nij,nj->ni", K, r)
    Cpost = Cz - K @ H @ Cz
    A = np.stack([X[-1], vN, Hh[-1], wN])  # (x, v, h, w) at frame N
    mu_u = np.einsum("ij,nj->ni", A, mpost)
    Cu_post = A @ Cpost @ A.T
    states = np.zeros((n, 5))
    states[:, u] = mu_u
    states[:, 1] = y + e[-1]
    second = np.zeros((n, 5, 5))
    second[:, np.ix_(u, u)[0], np.ix_(u, u)[1]] = Cu_post
    second += states[:, :, None] * states[:, None, :]
    w = np.exp(log_f - logsumexp(log_f))
    mean = w @ states
    return mean, np.einsum("i,ijk->jk", w, second) - np.outer(mean, mean)


@pytest.mark.parametrize("q", [0.0, 0.05])
@pytest.mark.parametrize(
    "steps",
    [STEPS, -STEPS, np.array([1.0, -0.5, -2.0, -1.0, 1.5])],
    ids=["away", "towards", "mixed"],
)
def test_the_exact_3d_filter_equals_the_dense_grid(steps, q):
    """Gaps, rho per frame, signed steps, a prior correlating every block: to 1e-8 of an SD."""
    post = spatial.posterior(PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, q, steps=steps)
    mean, cov = dense_posterior(PAIRS, RHO, steps, q)
    sd = np.sqrt(np.diag(cov))
    assert_allclose(post.mean, mean, atol=1e-8 * sd.max(), rtol=0)
    assert_allclose(np.sqrt(np.diag(post.cov)), sd, rtol=1e-8)
    assert_allclose(post.cov, cov, atol=1e-8 * sd.max() ** 2)
    assert np.all(post.error <= 1e-9 * sd)


def test_a_height_known_to_be_zero_gives_the_planes_filter():
    """The height's prior narrow at 0 (SD 1e-12), bearings nu = 0, q = 0: the plane's exact
    filter on mu, to 1e-10 of an SD."""
    m = np.array([0.5, 8.0, 0.2, 0.0, 0.0])
    P = np.diag([1.0, 4.0, 0.3, 1e-24, 1e-24])
    P[0, 1] = P[1, 0] = 0.3
    flat = np.stack([MU, np.where(np.isnan(MU), np.nan, 0.0)], axis=-1)
    post = spatial.posterior(flat, RHO, m, P, steps=STEPS)
    plane = posterior.moments(MU, RHO, m[:3], P[:3, :3], steps=STEPS)
    sd = np.sqrt(np.diag(plane.cov[0]))
    assert_allclose(post.mean[:3], plane.mean[0], atol=1e-10 * sd.max(), rtol=0)
    assert_allclose(np.sqrt(np.diag(post.cov))[:3], sd, rtol=1e-10)


def test_the_height_alone_fixes_the_depth():
    """A point known to move straight ahead (x and v narrow at 0, bearings mu = 0) but
    climbing: the vertical parallax alone fixes the depth, and the answer is the plane's
    filter run on the heights, to 1e-9."""
    k = np.arange(6.0)
    nu = (0.2 + 0.3 * k) / (6.0 + k) + np.array([0.003, -0.002, 0.001, 0.002, -0.003, 0.0])
    pairs = np.stack([np.zeros(6), nu], axis=-1)
    m = np.array([0.0, 6.0, 0.0, 0.0, 0.0])
    P = np.diag([1e-24, 9.0, 1e-24, 1.0, 1.0])
    post = spatial.posterior(pairs, 0.005, m, P)
    plane = posterior.moments(nu, 0.005, m[[3, 1, 4]], P[np.ix_([3, 1, 4], [3, 1, 4])])
    assert_allclose(post.mean[[3, 1, 4]], plane.mean[0], rtol=1e-9)


def test_a_batch_is_each_track_alone():
    batch = np.stack([PAIRS, PAIRS * [1.1, 0.9]])
    both = spatial.posterior(batch, 0.01, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
    for i in range(2):
        one = spatial.posterior(batch[i], 0.01, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
        assert_allclose(both.mean[i], one.mean, rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"mu": MU}, r"^mu must have shape \(N, 2\)"),
        (
            {"mu": np.stack([MU, np.where(np.arange(6) == 1, np.nan, NU)], -1)},
            "^mu.*one coordinate",
        ),
        ({"mu": np.zeros((6, 2))}, "^mu is degenerate"),
        ({"prior_mean": PRIOR_MEAN[:3]}, r"^prior_mean must have shape \(5,\)"),
        ({"prior_cov": -PRIOR_COV}, "^prior_cov"),
        ({"steps": np.zeros(5)}, "^steps must be nonzero"),
        ({"rho": -1.0}, "^rho"),
    ],
)
def test_refusals_name_the_argument_in_one_line(kwargs, message):
    args = {"mu": PAIRS, "rho": 0.01, "prior_mean": PRIOR_MEAN, "prior_cov": PRIOR_COV}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message) as info:
        spatial.posterior(**args)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("steps", [STEPS, -STEPS], ids=["away", "towards"])
def test_the_online_exact_filter_takes_pairs_and_is_the_batch_filter(steps):
    """A prior on five coordinates makes each update a pair: frame by frame within 1e-8 of
    an SD of the batch 3-D filter of the frames so far."""
    from depthcore.exact import online

    f = online.Online(PRIOR_MEAN, PRIOR_COV, rho=0.01)
    for k in range(len(PAIRS)):
        est = f.update(
            PAIRS[k], rho=None if np.isnan(RHO[k]) else RHO[k], step=1.0 if k == 0 else steps[k - 1]
        )
        if k >= 3:
            b = spatial.posterior(
                PAIRS[: k + 1], RHO[: k + 1], PRIOR_MEAN, PRIOR_COV, steps=steps[:k]
            )
            sd = np.sqrt(np.diag(b.cov))
            assert_allclose(est.mean, b.mean, atol=1e-8 * sd.max(), rtol=0)
            assert_allclose(np.sqrt(np.diag(est.cov)), sd, rtol=1e-8)
    with pytest.raises(ValueError, match="^mu must be one pair"):
        f.update(0.1)
    assert online.Online(PRIOR_MEAN, PRIOR_COV, rho=0.01, gate=1e-3).gate == 1e-3  # pairs gate
