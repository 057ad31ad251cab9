"""The exact filter in Stone Soup's loop: a Track in, no copy per frame, any length, either way.

Stone Soup's predictors take a ``Track`` (its last state); the exact predictor does,
and predicts a track's state once per timestamp. An update runs the exact filter once,
on a copy that shares the prior's arrays, and leaves every earlier state as it was.
A track may be as long as the camera runs (past the 1,000 frames the online filter
once refused), and what its last state holds does not grow with it. A camera that
approaches the point (negative steps, a negative speed) gives the batch exact
filter's answer, and Stone Soup's EKF gives depthcore's.
"""

from __future__ import annotations

import copy
import datetime
import gc

import numpy as np
import pytest

pytest.importorskip("stonesoup")

from stonesoup.base import Base  # noqa: E402
from stonesoup.predictor.kalman import ExtendedKalmanPredictor  # noqa: E402
from stonesoup.types.detection import Detection  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import GaussianState  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402
from stonesoup.updater.kalman import ExtendedKalmanUpdater  # noqa: E402

from depthcore.exact import online, optimal  # noqa: E402
from depthcore.kalman import ekf  # noqa: E402
from depthcore.problem import model  # noqa: E402
from depthcore.stonesoup import exact, models, tracks  # noqa: E402

SECOND = datetime.timedelta(seconds=1)
Q, RHO = 0.01, 0.005
PRIOR_COV = np.diag([1.0, 4.0, 0.01])


@pytest.fixture(scope="module")
def sim():
    return model.simulate([0.5, 8.0, 0.05], 30, RHO, Q, np.random.default_rng(1), frame=1)


def loop(mu, prior_mean, steps=None, speed=1.0, q=Q, through_track=False):
    """Stone Soup's loop with the exact filter; ``through_track``: predict the Track itself."""
    frames = tracks.detections(mu, RHO, steps, speed=speed)
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=speed))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[RHO**2]]))
    track = Track([exact.ExactState(prior_mean, PRIOR_COV, timestamp=frames[0].timestamp)])
    for frame in frames:
        prediction = predictor.predict(
            track if through_track else track[-1], timestamp=frame.timestamp
        )
        if frame.detection is None:
            track.append(prediction)
        else:
            track.append(updater.update(SingleHypothesis(prediction, frame.detection)))
    return track, predictor, updater


def test_the_predictor_takes_a_track_as_stone_soups_own_do(sim):
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    mu = sim.mu[:12].copy()
    mu[[4, 9]] = np.nan
    by_track, predictor, _ = loop(mu, prior_mean, through_track=True)
    by_state, _, _ = loop(mu, prior_mean)
    for a, b in zip(by_track, by_state, strict=True):
        np.testing.assert_array_equal(a.state_vector, b.state_vector)
        np.testing.assert_array_equal(a.covar, b.covar)
    later = by_track[-1].timestamp + SECOND
    once = predictor.predict(by_track, timestamp=later)
    assert predictor.predict(by_track, timestamp=later) is once  # predicted once per timestamp
    assert predictor.predict(by_track[-1], timestamp=later) is once
    reference = optimal.run(mu, RHO, prior_mean, PRIOR_COV, process_noise=Q)
    np.testing.assert_allclose(by_track[-1].state_vector[:, 0], reference.mean, rtol=1e-9)
    with pytest.raises(ValueError, match="^prior: the track has no states$"):
        predictor.predict(Track(), timestamp=later)


def test_a_gaussian_state_is_a_gaussian_prior(sim):
    # an initiator's GaussianState, or a mixture merged by JPDA: the filter starts from it
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    frames = tracks.detections(sim.mu[:6], RHO)
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=Q, speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[RHO**2]]))
    start = GaussianState(prior_mean, PRIOR_COV, timestamp=frames[0].timestamp - 2 * SECOND)
    last = tracks.run(predictor, updater, start, frames)[-1]
    moved_mean, moved_cov = exact.moved_gaussian(prior_mean, PRIOR_COV, 2.0, Q)
    reference = optimal.run(sim.mu[:6], RHO, moved_mean, moved_cov, process_noise=Q)
    np.testing.assert_allclose(last.covar, reference.cov, rtol=1e-8, atol=1e-14)


def test_an_update_copies_nothing_deeply_and_changes_no_earlier_state(sim, monkeypatch):
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    track, predictor, updater = loop(sim.mu[:8], prior_mean)
    state = track[-1]
    frozen = (state.filter.current, state.filter.frame, state.filter.travelled)

    def refused(*args, **kwargs):
        raise AssertionError("a deep copy")

    monkeypatch.setattr(copy, "deepcopy", refused)
    later = state.timestamp + SECOND
    prediction = predictor.predict(state, timestamp=later)
    detections = [Detection([sim.mu[8] + d], timestamp=later) for d in (0.0, 0.01, -0.01)]
    updates = [updater.update(SingleHypothesis(prediction, d)) for d in detections]
    again = updater.update(SingleHypothesis(prediction, detections[0]))
    monkeypatch.undo()
    assert len({id(u.filter) for u in updates}) == 3 and again.filter is updates[0].filter
    assert (state.filter.current, state.filter.frame, state.filter.travelled) == frozen
    # the prior's filter, updated after all that, gives what a loop never forked gives
    reference, _, _ = loop(sim.mu[:9], prior_mean)
    fresh = exact.ExactUpdater(models.TangentBearing(noise_covar=[[RHO**2]]))
    redo = fresh.update(SingleHypothesis(prediction, detections[0]))
    np.testing.assert_array_equal(redo.covar, reference[-1].covar)
    np.testing.assert_array_equal(redo.state_vector, reference[-1].state_vector)


def _filters_reachable(state) -> int:
    """The exact filters that Stone Soup objects reachable from ``state`` hold.

    A breadth-first walk through Stone Soup objects and the containers they hold
    (not into functions, modules or classes, nor through the caches of predictors).
    """
    seen, todo, found = set(), [state], 0
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, online.Online):
            found += 1
        elif isinstance(obj, (Base, dict, list, tuple, set)):
            todo.extend(gc.get_referents(obj))
    return found


def test_a_track_runs_past_a_thousand_frames_and_its_state_holds_no_more_for_it():
    # 1,001 frames (frame 1,001 was refused). The last state holds as many exact filters
    # at frame 1,001 as the last state of the first 14 frames, whose frames before it
    # are alike (a missed frame, then a bearing): its own and its prediction's chain back
    # to the last update before it, however long the track (Stone Soup keeps earlier
    # priors by weak reference; a chain kept whole would hold a thousand).
    x1 = [0.5, 8.0, 0.05]
    states = model.G(x1, np.arange(1001.0))
    mu = model.project(states) + RHO * np.random.default_rng(2).standard_normal(1001)
    mu[5::7] = np.nan  # frames 13 and 1,000 (from 0) missed, 14 and 1,001 not
    prior_mean = np.add(x1, [0.1, 1.0, 0.0])
    track, _, _ = loop(mu, prior_mean, q=0.0)
    short, _, _ = loop(mu[:14], prior_mean, q=0.0)
    last, early = track[-1], short[-1]  # (plain values below: a track's repr is long)
    kinds = (type(last).__name__, type(early).__name__)
    assert len(track) == 1002 and kinds == ("ExactUpdate", "ExactUpdate")
    assert last.estimate.frame == 1001
    held = (_filters_reachable(last), _filters_reachable(early))
    assert held[0] == held[1] <= 4, held


def test_an_approaching_camera_in_stone_soups_loop_is_the_batch_exact_filter():
    # the camera moves towards the point: the depth falls by 0.5 a frame, from 24 to 12.5
    steps = np.full(23, -0.5)
    x1 = np.array([2.0, 24.0, -0.3])
    states = model.G(x1, np.concatenate([[0.0], np.cumsum(steps)]))
    mu = model.project(states) + RHO * np.random.default_rng(3).standard_normal(24)
    mu[[6, 15]] = np.nan
    prior_mean, prior_cov = x1 + [0.5, 4.0, 0.1], np.diag([4.0, 64.0, 0.25])
    frames = tracks.detections(mu, RHO, steps, speed=-2.0)  # half a second a frame
    step = models.DepthStep(process_noise=Q, speed=-2.0)
    start = exact.ExactState(prior_mean, prior_cov, timestamp=frames[0].timestamp)
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[RHO**2]]))
    means, covs = tracks.moments(tracks.run(exact.ExactPredictor(step), updater, start, frames))
    reference = optimal.run(mu, RHO, prior_mean, prior_cov, process_noise=Q, steps=steps)
    np.testing.assert_allclose(means[-1], reference.mean, rtol=1e-9)
    np.testing.assert_allclose(covs[-1], reference.cov, rtol=1e-8, atol=1e-14)
    assert abs(means[-1, 1] - states[-1, 1]) < 3 * np.sqrt(covs[-1, 1, 1])
    # Stone Soup's EKF on the same detections is depthcore's
    ekf_start = GaussianState(prior_mean, prior_cov, timestamp=frames[0].timestamp)
    ss = tracks.moments(
        tracks.run(ExtendedKalmanPredictor(step), ExtendedKalmanUpdater(None), ekf_start, frames)
    )
    dc = ekf.run(mu, RHO, prior_mean, prior_cov, Q, steps=steps)
    np.testing.assert_allclose(ss[0], dc.means, rtol=1e-10, atol=1e-12)


def test_a_prediction_holds_one_step_however_many_detections_are_missed(sim):
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    mu = sim.mu[:14].copy()
    mu[5:12] = np.nan  # seven missed detections in a row
    track, _, _ = loop(mu, prior_mean)
    missed = track[6:13]
    assert all(isinstance(s, exact.ExactPrediction) and s.step == 1.0 for s in missed)
    assert [s.filter.frame for s in missed] == list(range(5, 12))
    reference = optimal.run(mu, RHO, prior_mean, PRIOR_COV, process_noise=Q)
    np.testing.assert_allclose(track[-1].covar, reference.cov, rtol=1e-8, atol=1e-14)
    # a prediction's moments are its filter's moved in closed form (the motion is affine)
    m, P = exact.moved_gaussian(track[5].state_vector, track[5].covar, 1.0, Q)
    np.testing.assert_allclose(track[6].covar, P, rtol=1e-12)


#: Odd inputs and the start of each one-line refusal.
REFUSALS = {
    "nan bearing": ("update", Detection([np.nan]), "^measurement: a detection's bearing"),
    "two values": ("update", Detection([0.1, 0.2]), "^measurement must be one bearing"),
    "no detection": ("update", None, "^hypothesis: a missed detection"),
    "huge interval": ("predict", datetime.timedelta(days=1e6), "^time_interval: .* beyond"),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_odd_inputs_get_one_line_refusals(sim, case):
    kind, value, message = REFUSALS[case]
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    track, _, updater = loop(sim.mu[:4], prior_mean)
    predictor = exact.ExactPredictor(models.DepthStep(speed=1e300))
    with pytest.raises(ValueError, match=message) as refused:
        if kind == "update":
            prediction = exact.ExactPredictor(models.DepthStep(process_noise=Q, speed=1.0)).predict(
                track, timestamp=track[-1].timestamp + SECOND
            )
            updater.update(SingleHypothesis(prediction, value))
        else:
            predictor.predict(track, timestamp=track[-1].timestamp + value)
    assert "\n" not in str(refused.value)


def test_numbers_beyond_the_floating_point_range_are_refused_in_one_line(sim):
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    track, _, updater = loop(sim.mu[:4], prior_mean)
    later = track[-1].timestamp + SECOND
    cases = [
        (
            lambda: exact.ExactPredictor(models.DepthStep(process_noise=Q, speed=1e300)).predict(
                track, later
            ),
            "^time_interval: a step of 1e\\+300 moves the state beyond",
        ),
        (lambda: models.DepthStep(process_noise=1e200), "^process_noise must be at most"),
        (
            lambda: models.DepthStep(process_noise=1e150, speed=1e200).covar(time_interval=SECOND),
            "^time_interval: the velocity's variance",
        ),
        (
            lambda: updater.predict_measurement(GaussianState([1e300, 1e-300, 0.0], np.eye(3))),
            "^predicted_state: its bearing's mean or variance overflows",
        ),
        (lambda: tracks.detections([0.1, 0.2, 0.3], RHO, [1e308, 1e308]), "^steps add up"),
    ]
    for call, message in cases:
        with (
            np.errstate(over="raise", divide="raise", invalid="raise"),
            pytest.raises(ValueError, match=message) as refused,
        ):
            call()
        assert "\n" not in str(refused.value)


def test_a_zero_or_negative_interval_is_a_zero_or_backward_step(sim):
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    track, predictor, updater = loop(sim.mu[:4], prior_mean)
    back = predictor.predict(track, timestamp=track[-1].timestamp - SECOND)
    assert back.step == -1.0
    np.testing.assert_allclose(back.state_vector[1, 0], track[-1].depth_mean - 1.0, rtol=1e-14)
    same = predictor.predict(track, timestamp=track[-1].timestamp)
    with pytest.raises(ValueError, match="^hypothesis: its prediction has not moved"):
        updater.update(SingleHypothesis(same, Detection([0.1], timestamp=same.timestamp)))
