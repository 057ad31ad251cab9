"""A camera that approaches the point: signed steps in every filter, online and in batch.

A step is the depth's signed change between frames (negative: the camera moves towards
the point). The motion is the same straight line, ``x += s v``; the process noise grows
with ``|s|``; the depth must stay positive at every frame seen, so the exact filter
gives no weight to depths at frame 1 below the floor ``max(0, -min_k e_k)``
(:func:`depthcore.problem.frames.depth_floor`). The independent routes are the batch
exact filter (checked against a dense grid in ``tests/test_exact_tracks.py``) and the
EKF's batch door.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.exact import online, posterior
from depthcore.kalman import ekf, ukf
from depthcore.problem import frames, model
from depthcore.registry import online as registry_online

PRIOR_MEAN = np.array([0.0, 10.0, 0.0])
PRIOR_COV = np.diag([4.0, 16.0, 1.0])
RHO = 0.002


def _track(steps, y1=12.0, q=0.0, seed=1):
    """Bearings of a point at depth ``y1`` at frame 1 moved by ``steps`` (frame 1 first)."""
    rng = np.random.default_rng(seed)
    n = len(steps) + 1
    return model.simulate(np.array([1.0, y1, 0.3]), n, RHO, q, rng, frame=1, steps=steps)


def test_depth_floor_is_where_the_point_comes_nearest():
    assert frames.depth_floor([0.0, 1.0, 2.5]) == 0.0  # receding: frame 1 is the nearest
    assert frames.depth_floor([0.0, -1.0, -0.5, -3.0, -2.0]) == 3.0
    f = frames.check([0.1, 0.2, 0.3, 0.4], 0.01, [-1.0, 2.0, -4.0])
    assert f.floor == 3.0  # elapsed 0, -1, 1, -3
    with pytest.raises(ValueError, match="^steps must be nonzero"):
        frames.check([0.1, 0.2, 0.3, 0.4], 0.01, [-1.0, 0.0, 1.0])


def test_process_noise_grows_with_the_distance_moved_either_way():
    assert_allclose(frames.velocity_variance(0.1, [-2.0, 2.0]), [0.02, 0.02])
    m, P = np.array([0.5, 10.0, 0.1]), np.diag([1.0, 1.0, 0.2])
    forward, back = ekf.predict(m, P, 0.3, 2.0), ekf.predict(m, P, 0.3, -2.0)
    assert forward.cov[2, 2] == back.cov[2, 2] == pytest.approx(0.2 + 0.09 * 2.0)
    assert_allclose(back.mean, [0.5 - 0.2, 8.0, 0.1])


@pytest.mark.parametrize("q", [0.0, 0.01])
@pytest.mark.parametrize(
    "steps",
    [np.full(39, -0.2), np.r_[np.full(20, -0.3), np.full(19, 0.25)]],
    ids=["approaching", "there-and-back"],
)
def test_the_online_exact_filter_is_the_batch_filter_at_every_frame(steps, q):
    """Frame by frame within 1e-9 of an SD of the batch filter of the frames so far, though
    the approach raises the floor every frame (nodes dropped or re-placed above it)."""
    sim = _track(steps, q=q)
    f = online.Online(PRIOR_MEAN, PRIOR_COV, RHO, q)
    for k in range(len(sim.mu)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            est = f.update(sim.mu[k], step=1.0 if k == 0 else steps[k - 1])
        if k in (2, 10, 20, len(sim.mu) - 1):
            b = posterior.moments(
                sim.mu[: k + 1], RHO, PRIOR_MEAN, PRIOR_COV, q, steps=steps[:k] if k else None
            )
            sd = np.sqrt(np.diagonal(b.cov[0]))
            assert abs(est.depth_mean - b.mean[0, 1]) < 1e-9 * sd[1]
            assert abs(est.depth_sd / sd[1] - 1) < 1e-9
            assert abs(est.velocity_mean - b.mean[0, 2]) < 1e-9 * sd[2]
    assert f.floor == pytest.approx(max(0.0, -np.min(np.cumsum(steps))))


def test_a_step_past_every_depth_the_filter_holds_is_refused_by_name():
    f = online.Online(PRIOR_MEAN, PRIOR_COV, RHO)
    f.update(0.1)
    f.update(0.12, step=-0.5)
    with pytest.raises(ValueError, match="^step: it brings the point to the camera"):
        f.update(0.2, step=-1e4)
    with pytest.raises(ValueError, match="^step must be nonzero"):
        f.update(0.2, step=0.0)


@pytest.mark.parametrize("name", ["ekf", "ukf", "optimal"])
def test_every_online_filter_takes_negative_steps(name):
    """The EKF and the UKF online are their batch doors frame by frame; the exact filter's
    answer is within 4 of its SDs of the truth."""
    steps = np.full(29, -0.25)
    sim = _track(steps)
    f = registry_online.start(name, PRIOR_MEAN, PRIOR_COV, RHO)
    for k in range(len(sim.mu)):
        est = f.update(sim.mu[k], step=1.0 if k == 0 else steps[k - 1])
    if name == "optimal":
        assert abs(est.depth_mean - sim.states[-1, 1]) < 4 * est.depth_sd
        return
    door = {"ekf": ekf.run, "ukf": ukf.run}[name]
    batch = door(sim.mu, RHO, PRIOR_MEAN, PRIOR_COV, steps=steps)
    assert_allclose(est.mean, batch.means[-1], rtol=1e-9)
    assert_allclose(est.cov, batch.covs[-1], rtol=1e-7, atol=1e-14)


def test_reading_an_approach_as_a_recession_is_many_sds_off():
    """The direction matters: the same bearings with the steps' signs flipped."""
    steps = np.full(39, -0.2)
    sim = _track(steps)
    right = posterior.moments(sim.mu, RHO, PRIOR_MEAN, PRIOR_COV, steps=steps)
    wrong = posterior.moments(sim.mu, RHO, PRIOR_MEAN, PRIOR_COV, steps=-steps)
    sd = np.sqrt(right.cov[0, 1, 1])
    assert abs(right.mean[0, 1] - sim.states[-1, 1]) < 4 * sd
    assert abs(wrong.mean[0, 1] - sim.states[-1, 1]) > 20 * sd
