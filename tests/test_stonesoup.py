"""The paper's problem in Stone Soup's types: its models, Stone Soup's own filters on them.

Stone Soup's EKF and UKF with :class:`~depthcore.stonesoup.models.DepthStep` and
:class:`~depthcore.stonesoup.models.TangentBearing` equal depthcore's
(:func:`depthcore.kalman.ekf.run`, :func:`depthcore.kalman.ukf.run`) on the same
track; the exact filter in a Stone Soup loop equals the batch exact filter.
"""

from __future__ import annotations

import datetime

import numpy as np
import pytest

pytest.importorskip("stonesoup")

from scipy.stats import norm  # noqa: E402
from stonesoup.functions import jacobian as numerical_jacobian  # noqa: E402
from stonesoup.predictor.kalman import (  # noqa: E402
    ExtendedKalmanPredictor,
    KalmanPredictor,
    UnscentedKalmanPredictor,
)
from stonesoup.types.array import StateVectors  # noqa: E402
from stonesoup.types.detection import Detection  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import GaussianState, State  # noqa: E402
from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater  # noqa: E402

from depthcore.exact import optimal  # noqa: E402
from depthcore.kalman import ekf, ukf  # noqa: E402
from depthcore.problem import frames, model  # noqa: E402
from depthcore.problem.scenarios import SCENARIOS  # noqa: E402
from depthcore.registry.filters import FILTERS  # noqa: E402
from depthcore.stonesoup import exact, models, tracks  # noqa: E402

SECOND = datetime.timedelta(seconds=1)
FIG2 = SCENARIOS["fig2"]


def relative(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="module")
def track30():
    """A 30-frame track with process noise, from a prior near its start."""
    q, rho = 0.01, 0.005
    sim = model.simulate([0.5, 8.0, 0.05], 30, rho, q, np.random.default_rng(1), frame=1)
    prior_mean = sim.states[0] + [0.1, 1.0, 0.0]
    return sim.mu, rho, q, prior_mean, np.diag([1.0, 4.0, 0.01])


def stone_soup(predictor, updater, mu, rho, prior_mean, prior_cov, steps=None):
    track = tracks.detections(mu, rho, steps)
    prior = GaussianState(prior_mean, prior_cov, timestamp=track[0].timestamp)
    return tracks.moments(tracks.run(predictor, updater, prior, track))


# --- the models -------------------------------------------------------------------------


def test_depth_step_moves_by_eq_1_with_the_step():
    step = models.DepthStep(process_noise=0.3, speed=2.0)
    state = State([1.0, 5.0, 0.2])
    moved = step.function(state, time_interval=1.5 * SECOND)  # s = 3
    np.testing.assert_array_equal(np.asarray(moved)[:, 0], model.G([1.0, 5.0, 0.2], 3.0))
    np.testing.assert_array_equal(step.matrix(time_interval=1.5 * SECOND), frames.transition(3.0))
    np.testing.assert_array_equal(
        np.asarray(step.matrix(time_interval=1.5 * SECOND) @ state.state_vector)
        + step.offset(time_interval=1.5 * SECOND),
        moved,
    )
    np.testing.assert_array_equal(step.covar(time_interval=1.5 * SECOND), np.diag([0, 0, 0.27]))
    np.testing.assert_array_equal(step.jacobian(state, time_interval=SECOND), frames.transition(2))


def test_the_step_is_speed_times_seconds_or_a_fixed_depth():
    assert models.DepthStep(speed=2.0).step(2.5 * SECOND) == 5.0
    fixed = models.DepthStep(depth_per_step=0.5)
    assert fixed.step(7 * SECOND) == fixed.step(None) == 0.5
    assert fixed.step(0 * SECOND) == models.DepthStep(speed=1.0).step(0 * SECOND) == 0.0
    with pytest.raises(ValueError, match="^time_interval: a speed needs timestamps"):
        models.DepthStep(speed=1.0).step(None)
    with pytest.raises(ValueError, match="^process_noise"):
        models.DepthStep(process_noise=-1.0)
    for bad in (0.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="^speed"):
            models.DepthStep(speed=bad)
        with pytest.raises(ValueError, match="^depth_per_step"):
            models.DepthStep(depth_per_step=bad)
    with pytest.raises(ValueError, match="^time_interval: .* beyond the floating-point range"):
        models.DepthStep(speed=1e308).step(datetime.timedelta(days=10))


def test_a_step_is_signed_and_its_noise_grows_with_the_distance_moved():
    # a camera approaching the point: a negative speed (or depth per step), or a prediction
    # back in time; the motion x += s v for either sign, the variance q**2 |s| (never < 0)
    approaching = models.DepthStep(process_noise=0.3, speed=-2.0)
    assert approaching.step(1.5 * SECOND) == -3.0
    assert models.DepthStep(speed=2.0).step(-1.5 * SECOND) == -3.0
    assert models.DepthStep(depth_per_step=0.5).step(-SECOND) == -0.5
    assert models.DepthStep(depth_per_step=-0.5).step(None) == -0.5
    state = State([1.0, 5.0, 0.2])
    moved = approaching.function(state, time_interval=1.5 * SECOND)
    np.testing.assert_array_equal(np.asarray(moved)[:, 0], [1.0 - 3 * 0.2, 2.0, 0.2])
    np.testing.assert_array_equal(
        approaching.covar(time_interval=1.5 * SECOND), np.diag([0, 0, 0.27])
    )
    receding = models.DepthStep(process_noise=0.3, speed=2.0).covar(time_interval=1.5 * SECOND)
    np.testing.assert_array_equal(approaching.covar(time_interval=1.5 * SECOND), receding)
    noise = np.asarray(models.DepthStep(process_noise=0.2, depth_per_step=-4.0, seed=3).rvs(20000))
    assert abs(noise[2].var() / 0.16 - 1) < 4 * np.sqrt(2 / 20000)
    after = State([0.2 - 4 * 0.2, 1.0, 0.5])  # from (0.2, 5, 0.2) by s = -4, v + 0.3
    step = models.DepthStep(process_noise=0.2, depth_per_step=-4.0)
    assert step.logpdf(after, State([0.2, 5.0, 0.2])) == pytest.approx(
        norm.logpdf(0.3, 0.0, 0.4), rel=1e-14
    )


def test_extended_kalman_predictor_keeps_the_depth_step_that_the_kalman_predictor_drops():
    step = models.DepthStep(process_noise=0.1, speed=1.0)
    t0 = datetime.datetime(2000, 1, 1)
    prior = GaussianState([1.0, 5.0, 0.2], np.diag([1.0, 2.0, 0.5]), timestamp=t0)
    exact_mean = frames.transition(2.0) @ [1.0, 5.0, 0.2] + [0.0, 2.0, 0.0]
    exact_cov = frames.transition(2.0) @ prior.covar @ frames.transition(2.0).T
    exact_cov[2, 2] += 0.1**2 * 2.0
    for predictor in (ExtendedKalmanPredictor(step), UnscentedKalmanPredictor(step)):
        pred = predictor.predict(prior, timestamp=t0 + 2 * SECOND)
        np.testing.assert_allclose(np.asarray(pred.state_vector)[:, 0], exact_mean, rtol=1e-14)
        np.testing.assert_allclose(pred.covar, exact_cov, rtol=1e-13, atol=1e-13)
    dropped = KalmanPredictor(step).predict(prior, timestamp=t0 + 2 * SECOND)
    np.testing.assert_allclose(np.asarray(dropped.state_vector)[:, 0], exact_mean - [0, 2, 0])


def test_depth_step_draws_and_density():
    step = models.DepthStep(process_noise=0.2, depth_per_step=4.0, seed=3)
    noise = np.asarray(step.rvs(20000))
    assert noise.shape == (3, 20000) and not np.any(noise[:2])
    assert abs(noise[2].var() / 0.16 - 1) < 4 * np.sqrt(2 / 20000)  # the variance q**2 s
    before = State([1.0, 5.0, 0.2])
    after = State([1.8, 9.0, 0.5])  # x + 4 v, y + 4, v + 0.3
    assert step.logpdf(after, before) == pytest.approx(norm.logpdf(0.3, 0.0, 0.4), rel=1e-14)
    assert float(step.pdf(after, before)) == pytest.approx(norm.pdf(0.3, 0.0, 0.4), rel=1e-12)
    assert step.logpdf(State([1.9, 9.0, 0.5]), before) == -np.inf
    with pytest.raises(ValueError, match="^process_noise: with q = 0"):
        models.DepthStep().logpdf(after, before)


def test_tangent_bearing_is_eq_4_with_the_gradient_of_eq_11():
    bearing = models.TangentBearing(noise_covar=[[0.01**2]], seed=5)
    state = State([1.2, 6.0, 0.3])
    assert bearing.ndim_meas == 1 and bearing.rho == pytest.approx(0.01)
    assert float(bearing.function(state)[0, 0]) == 1.2 / 6.0
    np.testing.assert_allclose(
        bearing.jacobian(state), numerical_jacobian(bearing.function, state), rtol=1e-6
    )
    np.testing.assert_array_equal(bearing.jacobian(state), [[1 / 6, -1.2 / 36, 0.0]])
    mu = State([0.21])
    assert bearing.logpdf(mu, state) == pytest.approx(norm.logpdf(0.21, 0.2, 0.01), rel=1e-14)
    assert bearing.logpdf(mu, State([1.2, -6.0, 0.3])) == -np.inf  # behind the camera
    many = State(StateVectors([[1.2, 1.2], [6.0, 4.0], [0.0, 0.0]]))
    np.testing.assert_allclose(
        bearing.logpdf(mu, many), norm.logpdf(0.21, [0.2, 0.3], 0.01), rtol=1e-14
    )
    assert np.asarray(bearing.rvs(4)).shape == (1, 4)
    with pytest.raises(ValueError, match="^noise_covar must be"):
        models.TangentBearing(noise_covar=[[0.0]])


# --- Stone Soup's Kalman filters equal depthcore's ---------------------------------------


def test_stone_soup_ekf_equals_depthcore_ekf_on_figure_2():
    prior = FIG2.prior
    means, covs = stone_soup(
        ExtendedKalmanPredictor(models.DepthStep(speed=1.0)),
        ExtendedKalmanUpdater(None),
        FIG2.mu,
        FIG2.rho,
        prior.mean,
        prior.cov,
    )
    reference = ekf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov)
    assert relative(means, reference.means) < 1e-12
    assert relative(covs, reference.covs) < 1e-12


def test_stone_soup_ekf_equals_depthcore_ekf_on_a_30_frame_track(track30):
    mu, rho, q, m, P = track30
    step = models.DepthStep(process_noise=q, speed=1.0)
    means, covs = stone_soup(
        ExtendedKalmanPredictor(step), ExtendedKalmanUpdater(None), mu, rho, m, P
    )
    reference = ekf.run(mu, rho, m, P, q)
    assert relative(means, reference.means) < 1e-10
    assert relative(covs, reference.covs) < 1e-10


def test_stone_soup_ekf_through_a_gap_and_uneven_steps_is_the_recursion_by_hand(track30):
    mu, rho, q, m, P = track30
    mu = mu[:8].copy()
    mu[4] = np.nan
    steps = np.array([1.0, 0.5, 1.5, 2.0, 1.0, 0.25, 1.0])
    rho_k = rho * np.linspace(1.0, 2.0, 8)
    step = models.DepthStep(process_noise=q, speed=2.0)
    track = tracks.detections(mu, rho_k, steps, speed=2.0)
    prior = GaussianState(m, P, timestamp=track[0].timestamp)
    means, covs = tracks.moments(
        tracks.run(ExtendedKalmanPredictor(step), ExtendedKalmanUpdater(None), prior, track)
    )
    n, C = np.asarray(m, float), np.asarray(P, float)
    for k in range(8):
        if k:
            F = frames.transition(steps[k - 1])
            n = F @ n + [0.0, steps[k - 1], 0.0]
            C = F @ C @ F.T + np.diag([0, 0, frames.velocity_variance(q, steps[k - 1])])
        if not np.isnan(mu[k]):
            n, C = ekf.update(n, C, mu[k], rho_k[k])
        np.testing.assert_allclose(means[k], n, rtol=1e-10)
        np.testing.assert_allclose(covs[k], C, rtol=1e-10, atol=1e-10 * np.max(np.abs(C)))


#: The sigma points of :func:`depthcore.kalman.ukf.run` by default, in Stone Soup's names.
SIGMA = {"alpha": 1.0, "beta": 0.0, "kappa": 0.0}


@pytest.mark.parametrize("predictor", [ExtendedKalmanPredictor, UnscentedKalmanPredictor])
def test_stone_soup_ukf_equals_depthcore_ukf_with_the_same_sigma_points(track30, predictor):
    mu, rho, q, m, P = track30
    options = SIGMA if predictor is UnscentedKalmanPredictor else {}
    step = models.DepthStep(process_noise=q, speed=1.0)
    means, covs = stone_soup(
        predictor(step, **options), UnscentedKalmanUpdater(None, **SIGMA), mu, rho, m, P
    )
    reference = ukf.run(mu, rho, m, P, q)
    assert relative(means, reference.means) < 1e-10
    assert relative(covs, reference.covs) < 1e-10


def test_stone_soup_ukf_on_figure_2_averages_across_the_pole_as_depthcore_allows():
    prior = FIG2.prior
    means, covs = stone_soup(
        ExtendedKalmanPredictor(models.DepthStep(speed=1.0)),
        UnscentedKalmanUpdater(None, **SIGMA),
        FIG2.mu,
        FIG2.rho,
        prior.mean,
        prior.cov,
    )
    with pytest.raises(ValueError, match="behind the camera"):
        ukf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov)
    reference = ukf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov, allow_behind_camera=True)
    assert relative(means, reference.means) < 1e-10
    assert relative(covs, reference.covs) < 1e-10


def test_detections_carry_the_frames_clock_gaps_and_noise():
    mu = [0.1, np.nan, 0.2, 0.25, 0.3]
    track = tracks.detections(mu, [0.01, np.nan, 0.02, 0.03, 0.04], [1.0, 2.0, 0.5, 1.5], speed=2)
    seconds = [(f.timestamp - tracks.START).total_seconds() for f in track]
    np.testing.assert_allclose(seconds, [0.0, 0.5, 1.5, 1.75, 2.5], rtol=0, atol=0)
    assert track[1].detection is None
    assert [f.detection.measurement_model.rho for f in track if f.detection] == pytest.approx(
        [0.01, 0.02, 0.03, 0.04]
    )
    with pytest.raises(ValueError, match="^mu must be one track"):
        tracks.detections([[0.1, 0.2, 0.4]] * 2, 0.01)


# --- the exact filter in Stone Soup's loop equals the batch exact filter -----------------


def exact_loop(mu, rho, prior_mean, prior_cov, q=0.0, steps=None, speed=1.0, gate=None):
    track = tracks.detections(mu, rho, steps, speed=speed)
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=speed))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[0.01]]), gate=gate)
    prior = exact.ExactState(prior_mean, prior_cov, timestamp=track[0].timestamp)
    return tracks.run(predictor, updater, prior, track)


def test_exact_filter_in_a_stone_soup_loop_is_figure_2s_optimal_filter():
    prior = FIG2.prior
    track = exact_loop(FIG2.mu, FIG2.rho, prior.mean, prior.cov)
    reference = FILTERS["optimal"](FIG2.mu, FIG2.rho, prior.mean, prior.cov)
    last = track[-1]
    assert isinstance(last, exact.ExactUpdate) and isinstance(last, GaussianState)
    assert relative(np.asarray(last.state_vector)[:, 0], reference.mean) < 1e-10
    assert relative(last.covar, reference.cov) < 1e-9
    assert last.depth_mean == pytest.approx(reference.depth_mean, rel=1e-10)
    assert last.estimate.depth_sd == pytest.approx(reference.depth_sd, rel=1e-9)
    assert last.estimate.frame == 3


def test_exact_filter_in_a_stone_soup_loop_equals_the_batch_along_30_frames(track30):
    mu, rho, q, m, P = track30
    means, covs = tracks.moments(exact_loop(mu, rho, m, P, q))
    for n in (5, 10, 30):
        reference = optimal.run(mu[:n], rho, m, P, process_noise=q)
        assert relative(means[n - 1], reference.mean) < 1e-9, n
        assert relative(covs[n - 1], reference.cov) < 1e-8, n


def test_exact_filter_through_missed_detections_uneven_steps_and_noise_per_frame(track30):
    mu, rho, q, m, P = track30
    mu = mu[:12].copy()
    mu[[4, 7, 11]] = np.nan  # missed detections, the last frame's too
    steps = np.array([1.0, 0.5, 1.5, 2.0, 1.0, 0.25, 1.0, 1.0, 0.5, 1.0, 2.0])
    rho_k = rho * np.linspace(1.0, 2.0, 12)
    track = exact_loop(mu, rho_k, m, P, q, steps, speed=2.0)
    assert [type(s).__name__ for s in track].count("ExactPrediction") == 3
    means, covs = tracks.moments(track)
    for n in (6, 11, 12):
        reference = optimal.run(mu[:n], rho_k[:n], m, P, process_noise=q, steps=steps[: n - 1])
        assert relative(means[n - 1], reference.mean) < 1e-9, n
        assert relative(covs[n - 1], reference.cov) < 1e-8, n


def test_two_steps_through_a_missed_frame_are_one_long_step_only_without_process_noise(track30):
    mu, rho, _, m, P = track30
    gap = mu[:6].copy()
    gap[3] = np.nan
    joined = np.delete(mu[:6], 3)
    for q, equal in ((0.0, True), (0.05, False)):
        through = exact_loop(gap, rho, m, P, q)[-1].covar
        once = exact_loop(joined, rho, m, P, q, steps=[1.0, 1.0, 2.0, 1.0])[-1].covar
        assert (relative(through, once) < 1e-9) == equal
    # with q > 0 the velocity's change at the missed frame moves x over the second step:
    # the answer is the batch's with that frame missing, not with one step of 2
    reference = optimal.run(gap, rho, m, P, process_noise=0.05)
    assert relative(exact_loop(gap, rho, m, P, 0.05)[-1].covar, reference.cov) < 1e-8


def test_a_gated_outlier_is_a_missed_detection(track30):
    mu, rho, q, m, P = track30
    outlier = mu[:8].copy()
    outlier[5] += 0.2  # forty noise SDs off
    gated = exact_loop(outlier, rho, m, P, q, gate=1e-3)
    missing = outlier.copy()
    missing[5] = np.nan
    reference = exact_loop(missing, rho, m, P, q)
    assert gated[5].estimate.gated and gated[5].estimate.tail < 1e-3
    assert not any(s.estimate.gated for i, s in enumerate(gated) if i != 5)
    assert relative(gated[-1].covar, reference[-1].covar) < 1e-12
    assert isinstance(reference[5], exact.ExactPrediction)  # the missed frame: predicted
    assert np.isfinite(gated[5].estimate.log_predictive)


def test_a_state_is_never_changed_by_predicting_or_updating_it(track30):
    mu, rho, q, m, P = track30
    track = exact_loop(mu[:5], rho, m, P, q)
    state = track[-1]
    before = (state.filter.current, state.filter.frame)
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[rho**2]]))
    later = state.timestamp + SECOND
    detection = tracks.detections(mu[:6], rho)[-1].detection
    answers = [
        updater.update(SingleHypothesis(predictor.predict(state, timestamp=later), detection))
        for _ in range(2)
    ]
    np.testing.assert_array_equal(answers[0].covar, answers[1].covar)
    assert (state.filter.current, state.filter.frame) == before
    assert state.filter is not answers[0].filter


def test_a_prior_before_the_first_detection_is_moved_in_closed_form(track30):
    mu, rho, q, m, P = track30
    track = tracks.detections(mu[:6], rho)
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[rho**2]]))
    early = exact.ExactState(m, P, timestamp=track[0].timestamp - 2 * SECOND)
    last = tracks.run(predictor, updater, early, track)[-1]
    moved_mean, moved_cov = exact.moved_gaussian(m, P, 2.0, q)
    reference = optimal.run(mu[:6], rho, moved_mean, moved_cov, process_noise=q)
    assert relative(last.covar, reference.cov) < 1e-8


def test_the_exact_updater_refuses_by_name():
    prior = FIG2.prior
    track = tracks.detections(FIG2.mu, FIG2.rho)
    predictor = exact.ExactPredictor(models.DepthStep(speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[FIG2.rho**2]]))
    state = tracks.run(
        predictor,
        updater,
        exact.ExactState(prior.mean, prior.cov, timestamp=track[0].timestamp),
        track,
    )[-1]
    same_time = predictor.predict(state, timestamp=state.timestamp)
    with pytest.raises(ValueError, match="^hypothesis: its prediction has not moved"):
        updater.update(SingleHypothesis(same_time, track[-1].detection))
    with pytest.raises(ValueError, match="^prior must be a Track or a GaussianState"):
        predictor.predict(State([1.0, 2.0, 3.0]), timestamp=None)
    with pytest.raises(ValueError, match="^prior: the state must be"):
        predictor.predict(GaussianState([1.0, 2.0], np.eye(2)), timestamp=None)
    with pytest.raises(ValueError, match="^gate must be None or a probability"):
        exact.ExactUpdater(None, gate=2.0)
    with pytest.raises(ValueError, match="^transition_model must be a DepthStep"):
        exact.ExactPredictor(None)


def test_without_timestamps_each_prediction_moves_by_the_fixed_depth_per_step(track30):
    mu, rho, q, m, P = track30
    moved_mean, moved_cov = exact.moved_gaussian(m, P, 0.5, q)
    timed = exact_loop(mu[:6], rho, moved_mean, moved_cov, q, steps=[0.5] * 5, speed=1.0)
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, depth_per_step=0.5))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[rho**2]]))
    state = exact.ExactState(m, P)  # no timestamps: every prediction moves by 0.5
    for k in range(6):
        prediction = predictor.predict(state, timestamp=None)
        state = updater.update(SingleHypothesis(prediction, Detection([mu[k]])))
    assert relative(state.covar, timed[-1].covar) < 1e-12
    assert relative(state.state_vector, timed[-1].state_vector) < 1e-12
