"""The chapter on several points: Stone Soup's multi-target tracker, the exact filter and others.

Recommended import: ``from depthbook import beyond_multitarget``.

* :func:`scene` draws one scene: the points of :data:`POINTS` seen by a
  receding camera, each detected with probability :data:`DETECT`, with
  Poisson clutter over the field of view (:func:`depthcore.stonesoup.tracks.scene`);
* :func:`tracker` builds Stone Soup's ``MultiTargetTracker`` for one filter
  (the exact filter, Stone Soup's EKF, UKF or particle filter): global
  nearest-neighbour association on a distance hypothesiser, tracks held by
  a multi-measurement initiator until :data:`MIN_POINTS` detections, deleted
  after :data:`DELETE_AFTER` frames without one;
* :func:`metrics` scores the tracks against the truth by Stone Soup's OSPA
  and SIAP metric generators, and :func:`study` does so over several scenes;
* :func:`exactness` compares each exact track with the batch exact filter on
  the bearings it was given.
"""

from __future__ import annotations

import numpy as np
from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
from stonesoup.dataassociator.tracktotrack import TrackToTruth
from stonesoup.deleter.time import UpdateTimeStepsDeleter
from stonesoup.hypothesiser.distance import DistanceHypothesiser
from stonesoup.initiator.simple import MultiMeasurementInitiator, SinglePointInitiator
from stonesoup.measures import Euclidean, Mahalanobis
from stonesoup.metricgenerator.manager import MultiManager
from stonesoup.metricgenerator.ospametric import OSPAMetric
from stonesoup.metricgenerator.tracktotruthmetrics import SIAPMetrics
from stonesoup.predictor.kalman import ExtendedKalmanPredictor, UnscentedKalmanPredictor
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.tracker.simple import MultiTargetTracker
from stonesoup.types.state import GaussianState
from stonesoup.types.update import Update
from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater
from stonesoup.updater.particle import ParticleUpdater

from depthcore.exact import optimal
from depthcore.problem import checks, model
from depthcore.stonesoup import association, exact, models, particles, tracks

#: The points' states (x, y, v) at frame 1, their bearings crossing as the camera recedes.
POINTS = np.array([[1.2, 4.0, 1.2], [-1.0, 5.0, -0.8], [0.5, 6.0, -0.5], [-0.5, 3.0, 0.6]])
#: The prior mean of a new track's (x, y, v), before its first bearing.
PRIOR_MEAN = np.array([0.0, 5.0, 0.0])
#: The prior covariance of a new track's (x, y, v).
PRIOR_COV = np.diag([9.0, 9.0, 1.0])
#: The bearings' noise SD (Figure 2's), the probability that a point is detected.
RHO, DETECT = 0.005, 0.9
#: False detections per frame (Poisson), uniform over bearings in [-FIELD, FIELD].
CLUTTER, FIELD = 2.0, 1.2
#: Frames per scene, one depth unit apart (one second at unit speed).
FRAMES = 20
#: Detections a held track needs to be confirmed; frames without one before deletion.
MIN_POINTS, DELETE_AFTER = 4, 3
#: The association gate, a distance of 3 (Mahalanobis, or the exact tail's normal quantile).
MISSED_DISTANCE = 3.0
#: OSPA's cut-off and SIAP's association distance, in units of depth, on (x, y).
OSPA_CUTOFF, ASSOCIATION_DISTANCE = 2.0, 2.0
#: The particle filter's particles per track.
PARTICLES = 1000
#: The filters, by the registry's names where they have one.
FILTERS = ("optimal", "ekf", "ukf", "particle")
#: The scores kept of each scene, OSPA averaged over the frames and SIAP's.
SCORES = {
    "ospa": None,
    "completeness": "SIAP Completeness",
    "ambiguity": "SIAP Ambiguity",
    "spuriousness": "SIAP Spuriousness",
    "position": "SIAP Position Accuracy",
    "velocity": "SIAP Velocity Accuracy",
    "longest": "SIAP Longest Track Segment",
}


def scene(seed) -> tracks.Scene:
    """One scene of :data:`FRAMES` frames (see the module docstring).

    Parameters
    ----------
    seed : int or numpy.random.SeedSequence
        Draws the bearings' noise, the missed detections and the clutter, and
        seeds the detections' measurement models.

    Returns
    -------
    depthcore.stonesoup.tracks.Scene
    """
    seq = checks.seed_sequence(seed)
    draws, models_seed = seq.spawn(2)
    rng = np.random.default_rng(draws)
    states = np.stack([model.G(x, np.arange(float(FRAMES))) for x in POINTS])
    mu = model.project(states) + RHO * rng.standard_normal(states.shape[:2])
    mu[rng.random(mu.shape) > DETECT] = np.nan
    clutter = [rng.uniform(-FIELD, FIELD, rng.poisson(CLUTTER)) for _ in range(FRAMES)]
    return tracks.scene(states, mu, RHO, clutter, seed=models_seed)


def tracker(name: str, seed: int = 0) -> MultiTargetTracker:
    """Stone Soup's multi-target tracker with the filter ``name`` (one of :data:`FILTERS`).

    ``seed`` seeds the particle filter's start and resampling (the others are
    deterministic).
    """
    step = models.DepthStep(speed=1.0)
    prior = GaussianState(PRIOR_MEAN, PRIOR_COV)
    if name == "optimal":
        parts = (exact.ExactPredictor(step), exact.ExactUpdater(None))
        measure = association.ExactMahalanobis()
    elif name == "ekf":
        parts = (ExtendedKalmanPredictor(step), ExtendedKalmanUpdater(None))
        measure = Mahalanobis()
    elif name == "ukf":
        parts = (UnscentedKalmanPredictor(step), UnscentedKalmanUpdater(None))
        measure = Mahalanobis()
    elif name == "particle":
        resampler = particles.SystematicResampler(seed=seed)
        parts = (ParticlePredictor(step), ParticleUpdater(None, resampler=resampler))
        measure = Mahalanobis()
    else:
        raise ValueError(f"name must be one of {FILTERS}, got {name!r}")
    predictor, updater = parts
    if name == "particle":
        start = particles.BearingParticleInitiator(prior, number_particles=PARTICLES, seed=seed)
    else:
        start = SinglePointInitiator(prior, None, updater)
    hypothesiser = DistanceHypothesiser(predictor, updater, measure, MISSED_DISTANCE)
    holding = MultiMeasurementInitiator(
        prior,
        UpdateTimeStepsDeleter(DELETE_AFTER - 1),
        GNNWith2DAssignment(hypothesiser),
        updater,
        initiator=start,
        min_points=MIN_POINTS,
    )
    return MultiTargetTracker(
        holding,
        UpdateTimeStepsDeleter(DELETE_AFTER),
        None,
        GNNWith2DAssignment(hypothesiser),
        updater,
    )


def run(name: str, the_scene: tracks.Scene, seed: int = 0) -> set:
    """Every track the tracker ``name`` held at any frame of the scene."""
    found = set()
    t = tracker(name, seed)
    for frame in the_scene.frames:
        found |= t.update_tracker(frame.timestamp, frame.detections)[1]
    return found


def metrics(found, the_scene: tracks.Scene) -> dict:
    """The scores of :data:`SCORES`: Stone Soup's OSPA (mean over frames) and SIAP metrics.

    OSPA with cut-off :data:`OSPA_CUTOFF` and ``p = 1`` on ``(x, y)``; SIAP with
    tracks associated to the truth within :data:`ASSOCIATION_DISTANCE` on
    ``(x, y)``, position accuracy on ``(x, y)``, velocity accuracy on ``v``.
    """
    position = Euclidean((0, 1))
    generators = [
        OSPAMetric(
            c=OSPA_CUTOFF,
            p=1,
            measure=position,
            generator_name="ospa",
            tracks_key="tracks",
            truths_key="truths",
        ),
        SIAPMetrics(
            position_measure=position,
            velocity_measure=Euclidean((2,)),
            generator_name="siap",
            tracks_key="tracks",
            truths_key="truths",
        ),
    ]
    associator = TrackToTruth(association_threshold=ASSOCIATION_DISTANCE, measure=position)
    manager = MultiManager(generators, associator=associator)
    manager.add_data({"tracks": set(found), "truths": the_scene.truths})
    out = manager.generate_metrics()
    scores = {"ospa": float(np.mean([m.value for m in out["ospa"]["OSPA distances"].value]))}
    for key, title in SCORES.items():
        if title is not None:
            scores[key] = float(out["siap"][title].value)
    return scores


def exactness(found, the_scene: tracks.Scene) -> float:
    """The largest difference of an exact track's last state from the batch exact filter's.

    Each track's updates name the bearings it was given; the batch exact
    filter (:func:`depthcore.exact.optimal.run`) on those bearings, from the
    track's first detection to its last frame (``NaN`` where it was given
    none), from the prior :data:`PRIOR_MEAN`, :data:`PRIOR_COV`. Returns the
    largest difference of the mean, in units of the track's own SDs.
    """
    times = [f.timestamp for f in the_scene.frames]
    worst = 0.0
    for track in found:
        mu = np.full(len(times), np.nan)
        for state in track:
            if isinstance(state, Update) and state.hypothesis and state.hypothesis.measurement:
                mu[times.index(state.timestamp)] = state.hypothesis.measurement.state_vector[0, 0]
        first = int(np.flatnonzero(np.isfinite(mu))[0])
        mu = mu[first : times.index(track[-1].timestamp) + 1]
        if np.count_nonzero(np.isfinite(mu)) < 3:
            continue
        batch = optimal.run(mu, RHO, PRIOR_MEAN, PRIOR_COV)
        sd = np.sqrt(np.diag(track[-1].covar))
        gap = np.abs(np.asarray(track[-1].state_vector, dtype=float)[:, 0] - batch.mean) / sd
        worst = max(worst, float(np.max(gap)))
    return worst


def study(n_scenes: int, seed: int, names=FILTERS) -> dict:
    """Every filter's scores over ``n_scenes`` scenes (children of one SeedSequence).

    Returns
    -------
    dict
        ``scores``: ``{name: {score: ndarray (n_scenes,)}}``; ``exactness``: the
        largest difference of an exact track from the batch exact filter over
        the scenes, in SDs (:func:`exactness`); ``tracks``: ``{name: ndarray}``,
        the tracks held per scene.
    """
    children = checks.seed_sequence(seed).spawn(n_scenes)
    scores = {n: {k: np.zeros(n_scenes) for k in SCORES} for n in names}
    counts = {n: np.zeros(n_scenes, dtype=int) for n in names}
    worst = 0.0
    for i, child in enumerate(children):
        the_scene = scene(child)
        filter_seed = int(child.generate_state(1)[0])
        for name in names:
            found = run(name, the_scene, filter_seed)
            for key, value in metrics(found, the_scene).items():
                scores[name][key][i] = value
            counts[name][i] = len(found)
            if name == "optimal":
                worst = max(worst, exactness(found, the_scene))
    return {"scores": scores, "exactness": worst, "tracks": counts}


def mean_se(values) -> tuple[float, float]:
    """The mean over scenes and its standard error."""
    values = np.asarray(values, dtype=float)
    return float(np.mean(values)), float(np.std(values, ddof=1) / np.sqrt(values.size))
