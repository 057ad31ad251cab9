"""A depthcore track as Stone Soup detections, and Stone Soup's tracking loop over them.

Recommended import: ``from depthcore.stonesoup import tracks``.

A track of bearings ``mu`` (``NaN`` at a missing frame), noise ``rho`` (one
number or one per frame) and signed depth steps (as :mod:`depthcore.problem.frames`
describes them; any number of frames, :func:`one_track`) becomes one
:class:`Frame` per frame: its timestamp, ``start`` plus the depth travelled
since frame 1 over ``speed`` (the clock of
:class:`depthcore.stonesoup.models.DepthStep` with that ``speed``: a camera
that approaches the point has negative steps and a negative speed), and its
``stonesoup.types.detection.Detection``, ``None`` at a missing frame.
Each detection carries its own :class:`~depthcore.stonesoup.models.TangentBearing`
with that frame's ``rho``.

A scene of several points, with missed detections and false ones (clutter),
becomes Stone Soup's ground truth and one :class:`SceneFrame` per frame, the
set of detections a multi-target tracker reads (:func:`scene`).

:func:`run` is Stone Soup's loop: predict to each frame's timestamp, update
with the frame's detection if there is one (a
``stonesoup.types.hypothesis.SingleHypothesis``), or keep the prediction
(a missed detection). Stone Soup's timestamps carry whole microseconds, so a
depth step is kept to ``speed`` times a microsecond.
"""

from __future__ import annotations

import datetime
from typing import NamedTuple

import numpy as np
from stonesoup.types.detection import Clutter, Detection, TrueDetection
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.track import Track

from depthcore.problem import checks
from depthcore.stonesoup.models import TangentBearing

#: The timestamp of frame 1 unless told otherwise.
START = datetime.datetime(2000, 1, 1)


class Frame(NamedTuple):
    """One frame of a track: its timestamp and its detection (``None``: missed)."""

    timestamp: datetime.datetime
    detection: Detection | None


def detections(mu, rho, steps=None, *, speed: float = 1.0, start=START) -> list[Frame]:
    """One track's frames as Stone Soup detections.

    Parameters
    ----------
    mu : array_like, shape (N,)
        Bearings, ``NaN`` at a missing frame.
    rho : float or array_like, shape (N,)
        Noise SD, one number or one per frame.
    steps : array_like, shape (N - 1,), or None
        The depth's signed changes between frames (``None``: ones).
    speed : float
        The depth's signed change per second, of the steps' sign: frame ``k`` is
        ``elapsed_k / speed`` seconds after ``start``.
    start : datetime.datetime
        The timestamp of frame 1.

    Returns
    -------
    list of Frame, length N
    """
    mu, rho, elapsed = one_track(mu, rho, steps)
    seconds = clock(elapsed, speed)
    if not isinstance(start, datetime.datetime):
        raise ValueError(f"start must be a datetime.datetime, got {type(start).__name__}")
    out = []
    for k, t in enumerate(seconds):
        timestamp = start + datetime.timedelta(seconds=float(t))
        detection = None
        if np.isfinite(mu[k]):
            bearing = TangentBearing(noise_covar=[[float(rho[k]) ** 2]])
            detection = Detection([float(mu[k])], timestamp=timestamp, measurement_model=bearing)
        out.append(Frame(timestamp, detection))
    return out


def one_track(mu, rho, steps=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One track's bearings, noise and steps, checked frame by frame, of any length.

    Stone Soup's loop takes one frame at a time, so a track here has no
    limit of frames and no least number of bearings (the filters say what a
    track too short leaves undetermined).

    Parameters
    ----------
    mu : array_like, shape (N,)
        Finite or ``NaN`` (a missing frame), ``N >= 1``.
    rho : float or array_like, shape (N,)
        Positive and finite where a bearing is present.
    steps : array_like, shape (N - 1,), or None
        Finite and nonzero (``None``: ones).

    Returns
    -------
    mu : ndarray, shape (N,)
    rho : ndarray, shape (N,)
        1 where no bearing is present.
    elapsed : ndarray, shape (N,)
        The depth's signed change since frame 1, from 0.
    """
    mu = checks.as_float(mu, "mu")
    if mu.ndim != 1 or mu.size == 0:
        raise ValueError(f"mu must be one track, shape (N,) with N >= 1, got shape {mu.shape}")
    if np.any(np.isinf(mu)):
        raise ValueError("mu must be finite or NaN (a missing frame), got an infinite bearing")
    rho = checks.as_float(rho, "rho")
    if rho.shape not in ((), mu.shape):
        raise ValueError(f"rho must be a number or have shape {mu.shape}, got shape {rho.shape}")
    rho = np.where(np.isfinite(mu), np.broadcast_to(rho, mu.shape), 1.0)
    if not np.all(np.isfinite(rho) & (rho > 0)):
        raise ValueError("rho must be finite and positive at every frame with a bearing")
    n = mu.size
    steps = np.ones(n - 1) if steps is None else checks.finite_array(steps, "steps")
    if steps.shape != (n - 1,):
        raise ValueError(f"steps must have shape ({n - 1},), got shape {steps.shape}")
    if np.any(steps == 0):
        raise ValueError("steps must be nonzero (the depth's signed change between frames)")
    return mu, rho, travelled(steps)


def travelled(steps) -> np.ndarray:
    """The depth's signed change since frame 1 at each frame, from 0, shape (N,).

    Refused where the steps add up beyond the floating-point range.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        elapsed = np.concatenate([[0.0], np.cumsum(steps)])
    if not np.all(np.isfinite(elapsed)):
        raise ValueError("steps add up beyond the floating-point range")
    return elapsed


def clock(elapsed, speed) -> np.ndarray:
    """Seconds since frame 1 of frames the depth travelled ``elapsed`` apart at ``speed``.

    Parameters
    ----------
    elapsed : ndarray, shape (N,)
        The depth's signed change since frame 1, from 0.
    speed : float
        Nonzero, of the steps' sign (a camera moves one way at a time).

    Returns
    -------
    ndarray, shape (N,)
        Increasing, from 0.
    """
    speed = checks.number(speed, "speed")
    if speed == 0:
        raise ValueError("speed must be nonzero (negative: the camera approaches the point)")
    with np.errstate(over="ignore", invalid="ignore"):
        seconds = np.asarray(elapsed, dtype=float) / speed
    if not (np.all(np.isfinite(seconds)) and np.all(np.diff(seconds) > 0)):
        raise ValueError(
            f"steps must all have the sign of speed ({speed:g}), so that time moves on at "
            "every frame"
        )
    return seconds


class SceneFrame(NamedTuple):
    """One frame of a scene: its timestamp and its detections, true ones and clutter."""

    timestamp: datetime.datetime
    detections: set


class Scene(NamedTuple):
    """Several points seen together (:func:`scene`): the truth and the frames."""

    truths: set
    frames: list


def scene(
    states, mu, rho, clutter, steps=None, *, speed=1.0, start=START, seed=0, model=TangentBearing
) -> Scene:
    """Several points' bearings, missed detections and clutter as a multi-target tracker reads them.

    Parameters
    ----------
    states : array_like, shape (M, N, 3)
        The true state ``(x, y, v)`` of each of ``M`` points at each of ``N`` frames.
    mu : array_like, shape (M, N)
        Their bearings as detected, ``NaN`` where a point is not detected.
    rho : float
        The bearings' noise SD.
    clutter : sequence of array_like, length N
        The false bearings of each frame (any number, finite).
    steps : array_like, shape (N - 1,), or None
        The depth's signed changes between frames (``None``: ones), of ``speed``'s sign.
    speed : float
        The depth's signed change per second (:func:`clock`).
    start : datetime.datetime
    seed : int or numpy.random.SeedSequence
        Each detection's measurement model gets a seed of its own from it (in
        the order points, then clutter, frame by frame) and gives every caller
        the same draws (``common_draws``), so that a particle filter's
        predicted bearings do not depend on the order in which a tracker
        visits its tracks and detections.
    model : type
        The measurement model's class, built as ``model(noise_covar=[[rho**2]],
        seed=..., common_draws=True)``.

    Returns
    -------
    Scene
        ``truths``: one ``stonesoup.types.groundtruth.GroundTruthPath`` per
        point (its id ``"point i"``, its states' metadata ``{"point": i}``);
        ``frames``: one :class:`SceneFrame` per frame, its detections
        ``TrueDetection`` (metadata ``{"point": i}``) and ``Clutter``.
    """
    states = checks.finite_array(states, "states")
    if states.ndim != 3 or states.shape[-1] != 3 or 0 in states.shape:
        raise ValueError(f"states must have shape (M, N, 3), got shape {states.shape}")
    M, N = states.shape[:2]
    mu = checks.as_float(mu, "mu")
    if mu.shape != (M, N) or np.any(np.isinf(mu)):
        raise ValueError(f"mu must have shape {(M, N)}, finite or NaN, got shape {mu.shape}")
    rho = checks.positive_scalar(rho, "rho")
    if len(clutter) != N:
        raise ValueError(f"clutter must have one array per frame ({N}), got {len(clutter)}")
    clutter = [
        checks.finite_array(np.reshape(c, -1), f"clutter[{k}]") for k, c in enumerate(clutter)
    ]
    steps = np.ones(N - 1) if steps is None else checks.finite_array(steps, "steps")
    if steps.shape != (N - 1,):
        raise ValueError(f"steps must have shape ({N - 1},), got shape {steps.shape}")
    seconds = clock(travelled(steps), speed)
    if not isinstance(start, datetime.datetime):
        raise ValueError(f"start must be a datetime.datetime, got {type(start).__name__}")
    times = [start + datetime.timedelta(seconds=float(t)) for t in seconds]
    count = int(np.sum(np.isfinite(mu))) + sum(c.size for c in clutter)
    seeds = iter(checks.seed_sequence(seed).generate_state(max(count, 1)).tolist())
    noise = [[rho**2]]
    paths = [
        GroundTruthPath(
            [
                GroundTruthState(states[i, k], timestamp=times[k], metadata={"point": i})
                for k in range(N)
            ],
            id=f"point {i}",
        )
        for i in range(M)
    ]
    out = []
    for k in range(N):
        found = {
            TrueDetection(
                [mu[i, k]],
                timestamp=times[k],
                measurement_model=model(noise_covar=noise, seed=next(seeds), common_draws=True),
                groundtruth_path=paths[i],
                metadata={"point": i},
            )
            for i in range(M)
            if np.isfinite(mu[i, k])
        }
        found |= {
            Clutter(
                [z],
                timestamp=times[k],
                measurement_model=model(noise_covar=noise, seed=next(seeds), common_draws=True),
            )
            for z in clutter[k]
        }
        out.append(SceneFrame(times[k], found))
    return Scene(set(paths), out)


def run(predictor, updater, prior, track: list[Frame]) -> Track:
    """Stone Soup's tracking loop over a track's frames, from ``prior``.

    At each frame: ``prediction = predictor.predict(state, timestamp=...)``;
    with a detection, ``state = updater.update(SingleHypothesis(prediction,
    detection))``; without one, ``state = prediction``.

    Parameters
    ----------
    predictor, updater
        Stone Soup's (or :mod:`depthcore.stonesoup.exact`'s).
    prior : stonesoup.types.state.State
        The state at (or before) the first frame's timestamp.
    track : list of Frame

    Returns
    -------
    stonesoup.types.track.Track
        One state per frame (the prior not included).
    """
    out = Track()
    state = prior
    for frame in track:
        prediction = predictor.predict(state, timestamp=frame.timestamp)
        if frame.detection is None:
            state = prediction
        else:
            state = updater.update(SingleHypothesis(prediction, frame.detection))
        out.append(state)
    return out


def moments(track: Track) -> tuple[np.ndarray, np.ndarray]:
    """The means (N, 3) and covariances (N, 3, 3) of a track's states."""
    means = np.stack([np.asarray(s.state_vector, dtype=float)[:, 0] for s in track])
    covs = np.stack([np.asarray(s.covar, dtype=float) for s in track])
    return means, covs
