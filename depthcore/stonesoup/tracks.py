"""A depthcore track as Stone Soup detections, and Stone Soup's tracking loop over them.

Recommended import: ``from depthcore.stonesoup import tracks``.

A track of bearings ``mu`` (``NaN`` at a missing frame), noise ``rho`` (one
number or one per frame) and depth steps (:func:`depthcore.problem.frames.check`)
becomes one :class:`Frame` per frame: its timestamp, ``start`` plus the depth
travelled since frame 1 over ``speed`` (the clock of
:class:`depthcore.stonesoup.models.DepthStep` with that ``speed``), and its
``stonesoup.types.detection.Detection``, ``None`` at a missing frame.
Each detection carries its own :class:`~depthcore.stonesoup.models.TangentBearing`
with that frame's ``rho``.

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
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.track import Track

from depthcore.problem import checks, frames
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
        Depth steps between frames (``None``: ones).
    speed : float
        Depth per second: frame ``k`` is ``elapsed_k / speed`` seconds after ``start``.
    start : datetime.datetime
        The timestamp of frame 1.

    Returns
    -------
    list of Frame, length N
    """
    track = frames.check(mu, rho, steps)
    if track.mu.ndim != 1:
        raise ValueError(f"mu must be one track, shape (N,), got shape {track.mu.shape}")
    speed = checks.positive_scalar(speed, "speed")
    if not isinstance(start, datetime.datetime):
        raise ValueError(f"start must be a datetime.datetime, got {type(start).__name__}")
    out = []
    for k, elapsed in enumerate(track.elapsed):
        timestamp = start + datetime.timedelta(seconds=float(elapsed) / speed)
        detection = None
        if track.present[k]:
            bearing = TangentBearing(noise_covar=[[float(track.rho[k]) ** 2]])
            detection = Detection(
                [float(track.mu[k])], timestamp=timestamp, measurement_model=bearing
            )
        out.append(Frame(timestamp, detection))
    return out


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
