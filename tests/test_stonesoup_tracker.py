"""The exact filter in Stone Soup's data association and trackers, and Stone Soup's own filters.

The exact updater's ``predict_measurement`` feeds Stone Soup's distance and PDA
hypothesisers; the exact predictive's density and tail at a detection are those of the
batch exact filter (its log marginal likelihood's increment; the density integrated);
a multi-target tracker with clutter keeps each track exact given its associations;
PDA's merge is the Gaussian of the hypotheses' exact moments. The particle filter's
start and resampling draw the same whatever order a tracker visits its tracks in.
"""

from __future__ import annotations

import datetime

import numpy as np
import pytest

pytest.importorskip("stonesoup")

from scipy.special import ndtri  # noqa: E402
from stonesoup.dataassociator.neighbour import GNNWith2DAssignment  # noqa: E402
from stonesoup.dataassociator.probability import JPDA  # noqa: E402
from stonesoup.deleter.time import UpdateTimeStepsDeleter  # noqa: E402
from stonesoup.hypothesiser.distance import DistanceHypothesiser  # noqa: E402
from stonesoup.hypothesiser.probability import PDAHypothesiser  # noqa: E402
from stonesoup.initiator.simple import MultiMeasurementInitiator, SinglePointInitiator  # noqa: E402
from stonesoup.measures import Mahalanobis  # noqa: E402
from stonesoup.predictor.particle import ParticlePredictor  # noqa: E402
from stonesoup.tracker.simple import MultiTargetMixtureTracker, MultiTargetTracker  # noqa: E402
from stonesoup.types.array import StateVectors  # noqa: E402
from stonesoup.types.detection import Clutter, Detection, MissedDetection  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis, SingleProbabilityHypothesis  # noqa: E402
from stonesoup.types.multihypothesis import MultipleHypothesis  # noqa: E402
from stonesoup.types.state import GaussianState, ParticleState  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402
from stonesoup.types.update import Update  # noqa: E402
from stonesoup.updater.kalman import ExtendedKalmanUpdater  # noqa: E402
from stonesoup.updater.particle import ParticleUpdater  # noqa: E402

from depthcore.exact import optimal, posterior  # noqa: E402
from depthcore.problem import model  # noqa: E402
from depthcore.problem.scenarios import SCENARIOS  # noqa: E402
from depthcore.stonesoup import association, exact, models, particles, tracks  # noqa: E402

FIG2 = SCENARIOS["fig2"]
SECOND = datetime.timedelta(seconds=1)
RHO = 0.005
#: A scene: four points (x, y, v) at frame 1, their bearings crossing as the camera recedes.
POINTS = np.array([[1.2, 4.0, 1.2], [-1.0, 5.0, -0.8], [0.5, 6.0, -0.5], [-0.5, 3.0, 0.6]])
PRIOR = GaussianState([0.0, 5.0, 0.0], np.diag([9.0, 9.0, 1.0]))
STEP = models.DepthStep(speed=1.0)


def a_scene(frames=12, clutter=2.0, detect=0.9, seed=0):
    rng = np.random.default_rng(seed)
    states = np.stack([model.G(x, np.arange(float(frames))) for x in POINTS])
    mu = model.project(states) + RHO * rng.standard_normal(states.shape[:2])
    mu[rng.random(mu.shape) > detect] = np.nan
    false = [rng.uniform(-1.2, 1.2, rng.poisson(clutter)) for _ in range(frames)]
    return tracks.scene(states, mu, RHO, false, seed=seed), mu


def fig2_prediction():
    """Figure 2's exact filter after its three bearings, predicted to frame 4."""
    frames = tracks.detections(FIG2.mu, FIG2.rho)
    predictor = exact.ExactPredictor(STEP)
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[FIG2.rho**2]]))
    start = exact.ExactState(FIG2.prior.mean, FIG2.prior.cov, timestamp=frames[0].timestamp)
    last = tracks.run(predictor, updater, start, frames)[-1]
    later = last.timestamp + SECOND
    return predictor.predict(last, timestamp=later), updater, later


# --- the measurement prediction ------------------------------------------------------------


def test_the_predictive_density_is_the_increment_of_the_batch_marginal_likelihood():
    # log p(mu_4 | mu_1..3) = log p(mu_1..4) - log p(mu_1..3), each the batch exact filter's
    # log normaliser (its quadrature to 1e-10): an independent route to the same number
    prediction, updater, later = fig2_prediction()
    measured = updater.predict_measurement(prediction)
    assert isinstance(measured, association.ExactMeasurementPrediction)
    mu4 = float(model.project(model.G(FIG2.c, 1.0)))
    for bearing in (mu4, mu4 + 0.02, mu4 - 0.05):
        detection = Detection([bearing], timestamp=later)
        four = posterior.posterior(
            np.append(FIG2.mu, bearing), FIG2.rho, FIG2.prior.mean, FIG2.prior.cov
        )
        three = posterior.posterior(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
        increment = float(four.log_normaliser - three.log_normaliser)
        assert measured.log_predictive(detection) == pytest.approx(increment, abs=1e-7)


def test_the_tail_is_the_density_integrated():
    prediction, updater, later = fig2_prediction()
    measured = updater.predict_measurement(prediction)
    grid = np.linspace(-1.0, 3.0, 1601)
    density = np.exp([measured.log_predictive(Detection([z], timestamp=later)) for z in grid])
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(grid))])
    assert cdf[-1] == pytest.approx(1.0, abs=1e-4)  # the grid holds the predictive
    for k in (500, 640, 800, 1000):
        expected = 2 * min(cdf[k], 1 - cdf[k])
        assert measured.tail(Detection([grid[k]], timestamp=later)) == pytest.approx(
            expected, abs=2e-4
        )


def test_the_exact_distance_is_the_normal_quantile_of_the_exact_tail():
    prediction, updater, later = fig2_prediction()
    measured = updater.predict_measurement(prediction)
    detection = Detection([float(measured.state_vector[0, 0]) + 0.05], timestamp=later)
    d = association.ExactMahalanobis()(measured, detection)
    assert d == pytest.approx(float(ndtri(1 - measured.tail(detection) / 2)), rel=1e-12)
    # after three bearings the predictive is skewed: a bearing 0.1 below the summary's mean
    # is further out than one 0.1 above it, which the summary puts at one distance
    centre = float(measured.state_vector[0, 0])
    below, above = (Detection([centre + d], timestamp=later) for d in (-0.1, 0.1))
    exact_d = [association.ExactMahalanobis()(measured, z) for z in (below, above)]
    summary_d = [Mahalanobis()(measured, z) for z in (below, above)]
    assert exact_d[0] - exact_d[1] > 1.0 and summary_d[0] == pytest.approx(summary_d[1])
    gaussian = GaussianState([[0.3]], [[0.04]])
    assert association.ExactMahalanobis()(gaussian, Detection([0.5])) == pytest.approx(1.0)


def test_scoring_a_far_detection_does_not_move_the_filter_and_updating_reuses_the_run():
    prediction, updater, later = fig2_prediction()
    near = Detection([float(updater.predict_measurement(prediction).state_vector[0, 0])])
    far = Detection([5.0], timestamp=later)
    scored = updater.predictive_at(prediction, far)
    assert scored.gated and scored.tail < exact.SCORE_GATE  # scored, not incorporated
    run = updater.filter_through(prediction, near)
    assert updater.update(SingleHypothesis(prediction, near)).filter is run[0]
    update = updater.update(SingleHypothesis(prediction, far))  # the tracker's choice: run it
    assert not update.estimate.gated and update.estimate.tail == scored.tail


# --- trackers ------------------------------------------------------------------------------


def gnn_tracker(predictor, updater, measure, initiator=None):
    hypothesiser = DistanceHypothesiser(predictor, updater, measure, missed_distance=3)
    initiator = initiator or SinglePointInitiator(PRIOR, None, updater)
    holding = MultiMeasurementInitiator(
        PRIOR,
        UpdateTimeStepsDeleter(2),
        GNNWith2DAssignment(hypothesiser),
        updater,
        initiator=initiator,
        min_points=4,
    )
    return MultiTargetTracker(
        holding, UpdateTimeStepsDeleter(3), None, GNNWith2DAssignment(hypothesiser), updater
    )


def run_tracker(tracker, scene):
    seen = set()
    for frame in scene.frames:
        seen |= tracker.update_tracker(frame.timestamp, frame.detections)[1]
    return seen


def used_bearings(track, times):
    """The bearings a track's updates used, NaN at its other frames, from its first."""
    mu = np.full(len(times), np.nan)
    for state in track:
        if isinstance(state, Update) and state.hypothesis and state.hypothesis.measurement:
            mu[times.index(state.timestamp)] = float(
                state.hypothesis.measurement.state_vector[0, 0]
            )
    return mu


def test_a_multi_target_tracker_keeps_each_exact_track_exact_given_its_associations():
    scene, _ = a_scene()
    tracker = gnn_tracker(
        exact.ExactPredictor(STEP), exact.ExactUpdater(None), association.ExactMahalanobis()
    )
    found = run_tracker(tracker, scene)
    times = [f.timestamp for f in scene.frames]
    true_tracks = 0
    for track in found:
        mu = used_bearings(track, times)
        first = int(np.flatnonzero(np.isfinite(mu))[0])
        last = times.index(track[-1].timestamp)
        mu = mu[first : last + 1]
        reference = optimal.run(mu, RHO, PRIOR.state_vector[:, 0], PRIOR.covar)
        np.testing.assert_allclose(track[-1].state_vector[:, 0], reference.mean, rtol=1e-8)
        np.testing.assert_allclose(track[-1].covar, reference.cov, rtol=1e-7, atol=1e-12)
        sources = {
            state.hypothesis.measurement.metadata.get("point")
            for state in track
            if isinstance(state, Update) and state.hypothesis
        }
        true_tracks += len(sources) == 1 and None not in sources
    assert true_tracks >= 3  # of the four points, with clutter and missed detections


def test_jpda_runs_the_exact_filter_with_exact_and_gaussian_probabilities():
    scene, _ = a_scene(frames=8)
    lam = 2.0 / 2.4
    for exactly in (True, False):
        predictor, updater = exact.ExactPredictor(STEP), exact.ExactUpdater(None)
        kind = association.ExactPDAHypothesiser if exactly else PDAHypothesiser
        pda = kind(predictor, updater, clutter_spatial_density=lam, prob_detect=0.9)
        gnn = DistanceHypothesiser(predictor, updater, association.ExactMahalanobis(), 3)
        holding = MultiMeasurementInitiator(
            PRIOR,
            UpdateTimeStepsDeleter(2),
            GNNWith2DAssignment(gnn),
            updater,
            initiator=SinglePointInitiator(PRIOR, None, updater),
            min_points=3,
        )
        tracker = MultiTargetMixtureTracker(
            holding, UpdateTimeStepsDeleter(3), None, JPDA(pda), updater
        )
        found = run_tracker(tracker, scene)
        assert found and all(np.all(np.isfinite(t[-1].covar)) for t in found)


def test_pda_probabilities_are_the_exact_densities_and_the_gate_the_exact_tail():
    prediction, updater, later = fig2_prediction()
    centre = float(updater.predict_measurement(prediction).state_vector[0, 0])
    found = [Detection([centre + d], timestamp=later) for d in (0.0, 0.03, 0.3, 3.0)]
    hypothesiser = association.ExactPDAHypothesiser(
        exact.ExactPredictor(STEP),
        updater,
        clutter_spatial_density=2.0,
        prob_detect=0.9,
        prob_gate=0.99,
        normalise=False,
    )
    track = Track([prediction.prior])
    hypotheses = hypothesiser.hypothesise(track, set(found), later)
    kept = {float(h.measurement.state_vector[0, 0]): h for h in hypotheses if h}
    measured = updater.predict_measurement(prediction)
    for detection in found:
        inside = measured.tail(detection) >= 0.01
        assert (float(detection.state_vector[0, 0]) in kept) == inside
        if inside:
            h = kept[float(detection.state_vector[0, 0])]
            expected = measured.log_predictive(detection) + np.log(0.9 / 2.0)
            assert float(h.probability.log_value) == pytest.approx(expected, rel=1e-12)
    missed = next(h for h in hypotheses if not h)
    assert float(missed.probability) == pytest.approx(1 - 0.9 * 0.99)
    with pytest.raises(ValueError, match="^clutter_spatial_density must be given"):
        association.ExactPDAHypothesiser(exact.ExactPredictor(STEP), updater)
    with pytest.raises(ValueError, match="^updater must be an ExactUpdater"):
        association.ExactPDAHypothesiser(
            exact.ExactPredictor(STEP), ExtendedKalmanUpdater(None), clutter_spatial_density=1
        )


def test_the_pda_merge_is_the_gaussian_of_the_exact_moments_and_a_certain_one_stays_exact():
    prediction, _, later = fig2_prediction()
    updater = association.ExactPDAUpdater(models.TangentBearing(noise_covar=[[FIG2.rho**2]]))
    centre = float(updater.predict_measurement(prediction).state_vector[0, 0])
    found = [Detection([centre + d], timestamp=later) for d in (0.0, 0.02)]
    hypotheses = hypothesis_set(prediction, found, [0.2, 0.5, 0.3])
    merged = updater.update(hypotheses)
    assert merged.filter is None  # a Gaussian from here: where the answer stops being exact
    states = [prediction] + [updater.update(SingleHypothesis(prediction, d)) for d in found]
    w = np.array([0.2, 0.5, 0.3])
    means = np.stack([np.asarray(s.state_vector, float)[:, 0] for s in states])
    mean = w @ means
    cov = sum(
        wi * (s.covar + np.outer(m - mean, m - mean))
        for wi, s, m in zip(w, states, means, strict=True)
    )
    np.testing.assert_allclose(merged.state_vector[:, 0], mean, rtol=1e-12)
    np.testing.assert_allclose(merged.covar, cov, rtol=1e-10)
    certain = updater.update(hypothesis_set(prediction, found, [0.0, 1.0, 0.0]))
    assert certain.filter is not None and certain.estimate.frame == 4


def hypothesis_set(prediction, found, weights):
    """PDA's hypotheses with given weights: the missed detection's, then each detection's."""
    measurements = [MissedDetection(timestamp=found[0].timestamp)] + found
    return MultipleHypothesis(
        [
            SingleProbabilityHypothesis(prediction, m, w)
            for m, w in zip(measurements, weights, strict=True)
        ],
        normalise=False,
    )


# --- the scene and the particle filter -----------------------------------------------------


def test_a_scene_holds_the_truth_the_detections_and_the_clutter():
    scene, mu = a_scene(frames=6, seed=3)
    assert len(scene.truths) == 4 and len(scene.frames) == 6
    for k, frame in enumerate(scene.frames):
        true = [d for d in frame.detections if not isinstance(d, Clutter)]
        assert sorted(d.metadata["point"] for d in true) == list(
            np.flatnonzero(np.isfinite(mu[:, k]))
        )
        assert all(d.timestamp == frame.timestamp for d in frame.detections)
    seconds = [(f.timestamp - tracks.START).total_seconds() for f in scene.frames]
    assert seconds == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    with pytest.raises(ValueError, match="^clutter must have one array per frame"):
        tracks.scene(np.zeros((1, 3, 3)), np.zeros((1, 3)), RHO, [[]])
    with pytest.raises(ValueError, match="^steps must all have the sign of speed"):
        tracks.scene(np.zeros((1, 3, 3)), np.zeros((1, 3)), RHO, [[]] * 3, steps=[1.0, -1.0])


def test_common_draws_give_every_caller_the_same_noise():
    common = models.TangentBearing(noise_covar=[[RHO**2]], seed=4, common_draws=True)
    own = models.TangentBearing(noise_covar=[[RHO**2]], seed=4)
    np.testing.assert_array_equal(common.rvs(5), common.rvs(5))
    assert not np.array_equal(own.rvs(5), own.rvs(5))
    with pytest.raises(ValueError, match="^common_draws: a seed is needed"):
        models.TangentBearing(noise_covar=[[RHO**2]], common_draws=True)


def test_the_particle_start_is_the_posterior_after_one_bearing():
    # importance sampling of p(x, y, v | mu_1) against the exact filter after that bearing
    prior = GaussianState([0.2, 5.0, 0.1], np.diag([4.0, 4.0, 0.25]))
    detection = Detection([0.1], measurement_model=models.TangentBearing(noise_covar=[[1e-4]]))
    start = particles.BearingParticleInitiator(prior, number_particles=200_000, seed=7)
    cloud = start.particles(detection)
    w = np.exp(np.asarray(cloud.log_weight, float))
    x = np.asarray(cloud.state_vector, float)
    mean = x @ w
    reference = exact.ExactUpdater(None).filter_through(prior, detection)[1]
    ess = 1.0 / np.sum(w * w)
    sd = np.sqrt(np.diag(reference.cov))
    assert np.all(np.abs(mean - reference.mean) < 5 * sd / np.sqrt(ess))
    again = start.particles(detection)
    np.testing.assert_array_equal(again.state_vector, cloud.state_vector)  # keyed draws
    other = start.particles(Detection([0.12], measurement_model=detection.measurement_model))
    assert not np.array_equal(other.state_vector, cloud.state_vector)


def test_resampling_is_systematic_below_the_threshold_and_keyed_on_the_particles():
    rng = np.random.default_rng(0)
    cloud = ParticleState(
        StateVectors(rng.standard_normal((3, 400))),
        log_weight=np.log(rng.dirichlet(np.full(400, 0.05))),
    )
    resampler = particles.SystematicResampler(seed=1, threshold=0.5)
    out = resampler.resample(cloud)
    assert np.allclose(np.asarray(out.log_weight, float), -np.log(400))
    np.testing.assert_array_equal(resampler.resample(cloud).state_vector, out.state_vector)
    even = ParticleState(
        StateVectors(rng.standard_normal((3, 400))), log_weight=np.full(400, -np.log(400))
    )
    assert resampler.resample(even) is even  # the effective sample size is N
    with pytest.raises(ValueError, match="^threshold must lie in"):
        particles.SystematicResampler(threshold=0.0)


def test_stone_soups_particle_filter_tracks_the_scene_the_same_way_every_run():
    scene, _ = a_scene(frames=8, seed=2)
    outcomes = []
    for _ in range(2):
        updater = ParticleUpdater(None, resampler=particles.SystematicResampler(seed=1))
        start = particles.BearingParticleInitiator(PRIOR, number_particles=300, seed=2)
        tracker = gnn_tracker(ParticlePredictor(STEP), updater, Mahalanobis(), start)
        found = run_tracker(tracker, scene)
        outcomes.append(sorted(float(np.sum(t[-1].state_vector)) for t in found))
    assert outcomes[0] == outcomes[1] and outcomes[0]
