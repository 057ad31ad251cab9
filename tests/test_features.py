"""Many features at once: the batched exact filter against the online exact filter, the
batched Kalman filters against the single ones, and the registry's door to both."""

from __future__ import annotations

import numpy as np
import pytest

from depthcore.exact import features as exact_features
from depthcore.exact.online import Online
from depthcore.kalman import features as kalman_features
from depthcore.kalman import online as kalman_online
from depthcore.registry import online as registry

#: The accuracy the batched exact filter is held to, in units of each feature's depth SD.
TOLERANCE = 1e-3


def scene(B: int, N: int, dim: int, seed: int = 0):
    """Tracks of ``B`` points: a third receding, a third approaching, a third both ways,
    uneven steps, noise per frame, a tenth of the frames missing, ``q`` 0 or 0.01."""
    rng = np.random.default_rng(seed)
    y1 = rng.uniform(5.0, 50.0, B)
    kind = np.arange(B) % 3
    size = rng.uniform(0.05, 0.4, (B, N - 1))
    sign = np.where(kind[:, None] == 0, 1.0, -1.0) * np.ones((B, N - 1))
    sign[kind == 2] = np.sign(rng.normal(size=(int(np.sum(kind == 2)), N - 1)) + 0.3)
    steps = sign * np.where(kind[:, None] == 1, size * y1[:, None] / (3.0 * N), size)
    q = np.where(np.arange(B) % 2 == 0, 0.0, 0.01)
    v = rng.normal(0, 0.3, (B, 2))
    depth = y1[:, None] + np.concatenate([np.zeros((B, 1)), np.cumsum(steps, 1)], 1)
    lateral = rng.normal(0, 0.3, (B, 2)) * y1[:, None]
    moved = lateral[:, None, :] + np.concatenate(
        [np.zeros((B, 1, 2)), np.cumsum(steps[..., None] * v[:, None, :], 1)], 1
    )
    rho = rng.uniform(0.002, 0.004, B)
    rhos = rho[:, None] * rng.uniform(0.7, 1.4, (B, N))
    obs = moved / depth[..., None] + rhos[..., None] * rng.normal(size=(B, N, 2))
    obs[rng.uniform(size=(B, N)) < 0.1] = np.nan
    m_y = y1 * rng.uniform(0.7, 1.3, B)
    x1 = lateral[:, 0] + rng.normal(0, 0.5, B)
    mean = np.stack([x1, m_y, 0 * m_y, lateral[:, 1], 0 * m_y], 1)
    cov = np.zeros((B, 5, 5))
    cov[:, [0, 1, 2, 3, 4], [0, 1, 2, 3, 4]] = np.stack(
        [(0.3 * m_y) ** 2, (0.4 * m_y) ** 2, 0.09 + 0 * m_y, (0.3 * m_y) ** 2, 0.09 + 0 * m_y], 1
    )
    cov[:, 0, 1] = cov[:, 1, 0] = 0.3 * 0.3 * 0.4 * m_y**2
    if dim == 3:
        return mean[:, :3], cov[:, :3, :3], rho, rhos, obs[..., 0], steps, q
    return mean, cov, rho, rhos, obs, steps, q


def run(f, obs, rhos, steps):
    """Every frame through the batched filter ``f``: its answers."""
    return [
        f.update(obs[:, k], rhos[:, k], 1.0 if k == 0 else steps[:, k - 1])
        for k in range(obs.shape[1])
    ]


def worst_against_online(answers, mean, cov, rho, rhos, obs, steps, q, rows):
    """The largest depth mean and SD differences from Online (rtol 1e-10), in its depth SDs,
    and the largest log predictive difference."""
    worst = np.zeros(3)
    for b in rows:
        f = Online(mean[b], cov[b], rho[b], q[b], rtol=1e-10)
        for k, a in enumerate(answers):
            e = f.update(obs[b, k], rhos[b, k], 1.0 if k == 0 else steps[b, k - 1])
            lp = 0.0 if np.isnan(e.log_predictive) else abs(a.log_predictive[b] - e.log_predictive)
            assert np.isnan(a.log_predictive[b]) == np.isnan(e.log_predictive)
            worst = np.maximum(
                worst,
                [
                    abs(a.depth_mean[b] - e.depth_mean) / e.depth_sd,
                    abs(a.depth_sd[b] - e.depth_sd) / e.depth_sd,
                    lp,
                ],
            )
    return worst


@pytest.mark.parametrize("dim", [3, 5])
def test_every_feature_is_the_full_accuracy_online_filter_at_every_frame(dim):
    # receding, approaching and mixed steps, uneven; missing frames; noise per frame; q 0 and not
    mean, cov, rho, rhos, obs, steps, q = scene(24, 80, dim)
    f = exact_features.Features(mean, cov, rho, q)
    answers = run(f, obs, rhos, steps)
    worst = worst_against_online(answers, mean, cov, rho, rhos, obs, steps, q, range(24))
    assert worst[0] < TOLERANCE and worst[1] < TOLERANCE, worst
    assert worst[2] < 1e-3, worst
    assert not f.unresolved.any()
    assert f.replacements.sum() > 0  # the densities narrowed: the check re-placed nodes


def test_a_feature_answers_the_same_alone_and_in_a_batch():
    mean, cov, rho, rhos, obs, steps, q = scene(9, 40, 5, seed=3)
    together = run(exact_features.Features(mean, cov, rho, q), obs, rhos, steps)
    for b in (0, 4, 8):
        alone = run(
            exact_features.Features(mean[b : b + 1], cov[b : b + 1], rho[b : b + 1], q[b]),
            obs[b : b + 1],
            rhos[b : b + 1],
            steps[b : b + 1],
        )
        for a, t in zip(alone, together, strict=True):
            np.testing.assert_allclose(a.mean[0], t.mean[b], rtol=1e-12, atol=0)
            np.testing.assert_allclose(a.cov[0], t.cov[b], rtol=1e-12, atol=1e-300)


def test_a_wide_prior_whose_density_moves_beyond_the_first_nodes_stays_exact():
    """Four features on wide priors (depth SD up to 0.8 of the depth, velocity SD up to 2),
    drawn as a fuzzing run drew them: one's posterior climbs above where the prior put the
    nodes. End nodes held only 16 log units below the largest (64 nodes) let its density
    leave the grid, and its answer drifted by 0.66 SD at frame 13 with every check passing;
    the nodes' margins (40, ends at 30) and 128 nodes keep it within the tolerance."""
    rng = np.random.default_rng([3, 3])
    rng.choice([3, 5])
    y0 = rng.uniform(2, 50, 4)
    mean, cov = np.zeros((4, 3)), np.zeros((4, 3, 3))
    mean[:, 1] = y0
    for b in range(4):
        cov[b] = np.diag(rng.uniform(0.1, 4, 3))
        cov[b, 1, 1] = (y0[b] * rng.uniform(0.1, 0.8)) ** 2
    rho = np.full(4, 10 ** rng.uniform(-4, -1))
    rng.choice([0.0, 0.01]), rng.choice([1.0, -0.05, 0.3]), rng.integers(3, 40)
    x1, y1, v = rng.normal(0, 2, 4), y0 * rng.uniform(0.7, 1.3, 4), rng.normal(0, 0.3, 4)
    k = np.arange(13)
    x, y = x1[:, None] + 0.3 * k * v[:, None], y1[:, None] + 0.3 * k
    obs = np.empty((4, 13))
    for j in range(13):
        obs[:, j] = x[:, j] / y[:, j] + rho * rng.standard_normal(4)
    rhos, steps, q = np.broadcast_to(rho[:, None], obs.shape), np.full((4, 12), 0.3), np.zeros(4)
    answers = run(exact_features.Features(mean, cov, rho, q), obs, rhos, steps)
    worst = worst_against_online(answers, mean, cov, rho, rhos, obs, steps, q, range(4))
    assert max(worst[:2]) < TOLERANCE, worst


def test_too_few_nodes_fail_the_check_and_their_answers_are_withheld():
    # with 40 nodes some features' densities are not resolved: the check says so, and from
    # that frame on their answers are NaN, never wrong; the default 128 nodes resolve them
    mean, cov, rho, rhos, obs, steps, q = scene(6, 30, 3, seed=1)
    f = exact_features.Features(mean, cov, rho, q, nodes=40)
    answers = run(f, obs, rhos, steps)
    lost = np.flatnonzero(f.unresolved)
    assert lost.size and not f.unresolved.all()
    withheld = np.array([np.isnan(a.depth_mean) for a in answers])  # (N, B)
    for b in lost:
        first = np.argmax(withheld[:, b])
        assert first > 0 and withheld[first:, b].all()
    kept = [b for b in range(6) if b not in lost]
    worst = worst_against_online(answers, mean, cov, rho, rhos, obs, steps, q, kept)
    assert max(worst[:2]) < TOLERANCE
    fine = run(exact_features.Features(mean, cov, rho, q), obs, rhos, steps)
    assert not np.any([np.isnan(a.depth_mean) for a in fine])


def test_the_nodes_do_not_grow_with_the_frames():
    mean, cov, rho, rhos, obs, steps, q = scene(3, 300, 5, seed=2)
    f = exact_features.Features(mean, cov, rho, q, nodes=24)
    run(f, obs[:, :2], rhos[:, :2], steps)
    shapes = [a.shape for a in (f._y1, f._log_p, f._log_w, f._lat)]
    run(f, obs[:, 2:], rhos[:, 2:], steps[:, 1:])
    assert [a.shape for a in (f._y1, f._log_p, f._log_w, f._lat)] == shapes
    assert f.frame == 300


@pytest.mark.parametrize("dim, name", [(3, "ekf"), (3, "ukf"), (5, "ekf"), (5, "ukf")])
def test_each_row_of_the_batched_kalman_filter_is_the_single_filter(dim, name):
    mean, cov, rho, rhos, obs, steps, _ = scene(6, 40, dim, seed=4)
    behind = {"allow_behind_camera": True} if dim == 3 and name == "ukf" else {}
    f = kalman_features.Features(mean, cov, rho, 0.01, filter=name, **behind)
    answers = run(f, obs, rhos, steps)
    for b in range(6):
        if dim == 5:
            g = kalman_online.Spatial(mean[b], cov[b], rho[b], 0.01, filter=name)
        else:
            g = getattr(kalman_online, name.upper())(mean[b], cov[b], rho[b], 0.01, **behind)
        for k, a in enumerate(answers):
            e = g.update(obs[b, k], rhos[b, k], 1.0 if k == 0 else steps[b, k - 1])
            for mine, theirs in ((a.mean[b], e.mean), (a.cov[b], e.cov)):
                scale = np.max(np.abs(theirs))
                assert np.max(np.abs(mine - theirs)) <= 1e-12 * scale
            np.testing.assert_allclose(
                [a.log_predictive[b], a.tail[b]], [e.log_predictive, e.tail], rtol=1e-12
            )


@pytest.mark.parametrize("name", ["optimal", "ekf", "ukf"])
def test_start_with_a_batch_is_the_batched_class(name):
    mean, cov, rho, rhos, obs, steps, _ = scene(4, 12, 5, seed=5)
    f = registry.start(name, mean, cov, rho=rho, process_noise=0.01)
    assert f.batched and f.frame == 0
    cls = exact_features if name == "optimal" else kalman_features
    assert isinstance(f.detail, cls.Features)
    options = {} if name == "optimal" else {"filter": name}
    g = cls.Features(mean, cov, rho, 0.01, **options)
    for a, b in zip(run(f, obs, rhos, steps), run(g, obs, rhos, steps), strict=True):
        np.testing.assert_array_equal(a.mean, b.mean)
    assert f.frame == 12 and f.current.mean.shape == (4, 5)
    single = registry.start(name, mean[0], cov[0], rho=0.003)
    assert not single.batched


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda m, P: exact_features.Features(m[0], P[0], 0.003), "prior_mean"),
        (lambda m, P: exact_features.Features(m, P[:, :2, :2], 0.003), "prior_cov"),
        (lambda m, P: exact_features.Features(m, P, -1.0), "rho"),
        (lambda m, P: exact_features.Features(m, P, [0.003] * 3), "rho"),
        (lambda m, P: exact_features.Features(m, P, 0.003, process_noise=-1), "process_noise"),
        (lambda m, P: exact_features.Features(m, P, 0.003, nodes=4), "nodes"),
        (lambda m, P: exact_features.Features(m, P, 0.003, rtol=0), "rtol"),
        (lambda m, P: exact_features.Features(m, P, 0.003).update(np.zeros(4)), "mu"),
        (lambda m, P: exact_features.Features(m, P, 0.003).update([[0.1, np.nan]] * 4), "mu"),
        (lambda m, P: kalman_features.Features(m, P, 0.003, filter="pf"), "filter"),
        (lambda m, P: kalman_features.Features(m, P).update(np.zeros((4, 2))), "rho"),
        (lambda m, P: registry.start("ekf", m, P, rho=0.003, gate=1e-3), "gate"),
    ],
)
def test_every_argument_is_checked_in_one_line(call, name):
    mean, cov, *_ = scene(4, 3, 5)
    with pytest.raises(ValueError, match=f"^{name}") as info:
        call(mean, cov)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("cls", [exact_features.Features, kalman_features.Features])
def test_a_step_is_checked_after_the_first_frame(cls):
    mean, cov, *_ = scene(4, 3, 5)
    f = cls(mean, cov, 0.003)
    f.update(np.full((4, 2), 0.1), step=0.0)  # ignored at the first frame
    for bad in (0.0, [1.0, 0.0, 1.0, 1.0], [1.0, 1.0]):
        with pytest.raises(ValueError, match="^step"):
            f.update(np.full((4, 2), 0.1), step=bad)


def test_one_recursion_serves_both_blocks_where_the_prior_makes_them_one():
    """Given the depth the lateral and vertical blocks see the same geometry: where the
    prior conditions them to one covariance with none between (as the benchmark's prior
    does, to 1e-11), the shared recursion gives the full 4 x 4 recursion's answers to 1e-9
    of an SD; a prior whose blocks differ keeps the full recursion."""
    rng = np.random.default_rng(8)
    B, N = 6, 30
    m_y = rng.uniform(8.0, 30.0, B)
    mu, nu = rng.uniform(-0.3, 0.3, B), rng.uniform(-0.3, 0.3, B)
    mean = np.stack([mu * m_y, m_y, np.zeros(B), nu * m_y, np.zeros(B)], 1)
    cov = np.zeros((B, 5, 5))
    s2 = (0.3 * m_y) ** 2
    cov[:, 1, 1] = s2
    cov[:, 0, 1] = cov[:, 1, 0] = mu * s2
    cov[:, 3, 1] = cov[:, 1, 3] = nu * s2
    cov[:, 0, 3] = cov[:, 3, 0] = mu * nu * s2
    cov[:, 0, 0], cov[:, 3, 3] = mu**2 * s2 + 0.01, nu**2 * s2 + 0.01
    cov[:, 2, 2] = cov[:, 4, 4] = 0.01
    y = m_y[:, None] - 0.1 * np.arange(N)
    pairs = np.stack([mu[:, None] * m_y[:, None] / y, nu[:, None] * m_y[:, None] / y], -1)
    pairs += 0.003 * rng.standard_normal(pairs.shape)
    steps = np.full(B, -0.1)
    shared = exact_features.Features(mean, cov, 0.003, 1e-3)
    full = exact_features.Features(mean, cov, 0.003, 1e-3)
    for k in range(N):
        step = 1.0 if k == 0 else steps
        a = shared.update(pairs[:, k], step=step)
        if k == 0:
            assert shared._shares
            full._shares = False  # the 4 x 4 recursion from here on
        b = full.update(pairs[:, k], step=step)
        assert np.all(np.abs(a.depth_mean - b.depth_mean) <= 1e-9 * b.depth_sd)
        assert np.all(np.abs(a.depth_sd - b.depth_sd) <= 1e-9 * b.depth_sd)
        assert np.allclose(a.cov, b.cov, rtol=1e-8, atol=1e-12)
    cov[:, 4, 4] = 0.02  # the vertical velocity less certain: two covariances
    other = exact_features.Features(mean, cov, 0.003, 1e-3)
    other.update(pairs[:, 0])
    assert not other._shares
