"""Benchmark: the exact filter in Stone Soup's loop against the exact filter online, per frame.

Three tables:

1. **Per update.** One track of Figure 2's point followed from frame 1 with
   process noise, a missed detection every seventh frame: Stone Soup's loop
   with :class:`depthcore.stonesoup.exact.ExactPredictor` and
   :class:`~depthcore.stonesoup.exact.ExactUpdater` (a prediction and an update
   per frame, the states appended to a ``Track``) against
   :class:`depthcore.exact.online.Online` fed the same bearings, timed
   alternately, the pair repeated (:data:`PAIRS`); the median over the pairs
   of the ratio of their times per frame (each pair measured back to back, so
   that a change of the machine's load between pairs changes both), against
   the target :data:`TARGET_RATIO`.
2. **A long track.** 10,000 frames of a receding point through Stone Soup's
   loop: the time per frame and the memory left allocated per frame
   (tracemalloc, reference cycles collected) over frames 1-1,000 and
   9,001-10,000, with the ``Track``
   kept whole (the memory per frame is that of the states it keeps) and with
   only its last state kept, in a new ``Track`` each frame (Stone Soup's
   ``Track`` keeps a copy of its metadata for every state appended, even once
   the state is deleted).
3. **In a tracker.** Stone Soup's ``MultiTargetTracker`` (global nearest
   neighbour on a distance hypothesiser, tracks started from four bearings)
   on four points with clutter and missed detections: the time per frame with
   the exact filter (each pair of a track and a detection scored by the exact
   predictive) and with Stone Soup's EKF.

Every time is the process's CPU time (one thread), so that other work on a
shared machine does not enter it.

Usage: ``python benchmarks/bench_stonesoup.py [--quick]``; the full run
writes its record ``depthbook/provenance/benchmark_records/bench_stonesoup.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (smaller sizes) writes
outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import gc  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402
from stonesoup.dataassociator.neighbour import GNNWith2DAssignment  # noqa: E402
from stonesoup.deleter.time import UpdateTimeStepsDeleter  # noqa: E402
from stonesoup.hypothesiser.distance import DistanceHypothesiser  # noqa: E402
from stonesoup.initiator.simple import MultiMeasurementInitiator, SinglePointInitiator  # noqa: E402
from stonesoup.measures import Mahalanobis  # noqa: E402
from stonesoup.predictor.kalman import ExtendedKalmanPredictor  # noqa: E402
from stonesoup.tracker.simple import MultiTargetTracker  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import GaussianState  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402
from stonesoup.updater.kalman import ExtendedKalmanUpdater  # noqa: E402

from depthbook.provenance import benchmarks  # noqa: E402
from depthcore.exact import online  # noqa: E402
from depthcore.problem import model  # noqa: E402
from depthcore.problem.scenarios import SCENARIOS  # noqa: E402
from depthcore.stonesoup import association, exact, models, tracks  # noqa: E402

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("stonesoup.exact", "stonesoup.association", "stonesoup.tracks", "exact.online")
FIG2 = SCENARIOS["fig2"]
#: Process noise of the tracks (the SD of the velocity's change per unit of depth).
Q = 0.005
#: The pairs of runs (Stone Soup's loop, then the online filter) timed alternately.
PAIRS = 7
#: The most the Stone Soup loop may cost per frame, as a multiple of the online filter's.
TARGET_RATIO = 2.0
SEED = 11


def one_track(frames: int, q: float = Q, seed: int = SEED):
    """Figure 2's point from frame 1 for ``frames`` frames: bearings (a seventh missing)."""
    x1 = model.G(np.array(FIG2.c), -2)
    states = model.G(x1, np.arange(float(frames)))
    rng = np.random.default_rng(seed)
    velocity = np.concatenate([[0.0], np.cumsum(q * rng.standard_normal(frames - 1))])
    states[:, 0] += np.concatenate([[0.0], np.cumsum(velocity[:-1])])
    mu = model.project(states) + FIG2.rho * rng.standard_normal(frames)
    mu[6::7] = np.nan
    return mu


def stone_soup_loop(frames, q: float, keep_history: bool = True):
    """Stone Soup's loop over ``frames`` with the exact filter; returns the Track."""
    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[FIG2.rho**2]]))
    prior = FIG2.prior
    track = Track([exact.ExactState(prior.mean, prior.cov, timestamp=frames[0].timestamp)])
    for frame in frames:
        prediction = predictor.predict(track, timestamp=frame.timestamp)
        if frame.detection is None:
            track.append(prediction)
        else:
            track.append(updater.update(SingleHypothesis(prediction, frame.detection)))
        if not keep_history:
            del track[:-1]
    return track


def online_loop(mu, q: float):
    f = online.Online(FIG2.prior.mean, FIG2.prior.cov, FIG2.rho, process_noise=q)
    for m in mu:
        f.update(m, step=1.0)
    return f


def per_update(n_frames: int, pairs: int) -> dict:
    mu = one_track(n_frames)
    frames = tracks.detections(mu, FIG2.rho)
    ratios, ss, on = [], [], []
    for _ in range(pairs):
        t = time.process_time()
        track = stone_soup_loop(frames, Q)
        t_ss = (time.process_time() - t) / n_frames
        t = time.process_time()
        f = online_loop(mu, Q)
        t_on = (time.process_time() - t) / n_frames
        ss.append(t_ss)
        on.append(t_on)
        ratios.append(t_ss / t_on)
    gap = np.max(np.abs(np.asarray(track[-1].state_vector)[:, 0] - f.current.mean))
    out = {
        "frames": n_frames,
        "stone_soup_ms_per_frame": 1e3 * float(np.median(ss)),
        "online_ms_per_frame": 1e3 * float(np.median(on)),
        "ratio": float(np.median(ratios)),
        "ratio_min": float(np.min(ratios)),
        "ratio_max": float(np.max(ratios)),
        "target_ratio": TARGET_RATIO,
        "difference_sd": float(gap / np.sqrt(f.current.cov[1, 1])),
    }
    print(f"1. Per update, {n_frames} frames, q = {Q}, {pairs} pairs (target: <= {TARGET_RATIO}x)")
    print(
        f"   Stone Soup's loop {out['stone_soup_ms_per_frame']:.3f} ms, online "
        f"{out['online_ms_per_frame']:.3f} ms per frame: ratio {out['ratio']:.2f} "
        f"({out['ratio_min']:.2f}-{out['ratio_max']:.2f}); final states differ by "
        f"{out['difference_sd']:.1e} SD"
    )
    return out


def _window(run_frames):
    """Time per frame and bytes left allocated per frame (cycles collected) over a window."""
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        t = time.process_time()
        n = run_frames()
        elapsed = time.process_time() - t
        gc.collect()
        after = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    return elapsed / n, (after - before) / n


class Loop:
    """Stone Soup's loop with the exact filter, run a stretch of frames at a time."""

    def __init__(self, frames, keep_history: bool, prior_mean):
        self.frames, self.keep = frames, keep_history
        self.predictor = exact.ExactPredictor(models.DepthStep(speed=1.0))
        self.updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[FIG2.rho**2]]))
        prior = exact.ExactState(
            prior_mean, np.diag([1.0, 4.0, 0.01]), timestamp=frames[0].timestamp
        )
        self.track = Track([prior])

    def run(self, lo: int, hi: int):
        """A call that runs frames ``lo`` to ``hi`` (from 0) and returns their number."""

        def frames_between():
            for frame in self.frames[lo:hi]:
                prediction = self.predictor.predict(self.track, timestamp=frame.timestamp)
                if frame.detection is None:
                    self.track.append(prediction)
                else:
                    hypothesis = SingleHypothesis(prediction, frame.detection)
                    self.track.append(self.updater.update(hypothesis))
                if not self.keep:  # a new Track: Stone Soup's keeps each state's metadata
                    self.track = Track([self.track[-1]])
            return hi - lo

        return frames_between


def long_track(n_frames: int, window: int) -> dict:
    x1 = [0.5, 8.0, 0.05]
    states = model.G(x1, np.arange(float(n_frames)))
    mu = model.project(states) + FIG2.rho * np.random.default_rng(SEED).standard_normal(n_frames)
    mu[6::7] = np.nan
    frames = tracks.detections(mu, FIG2.rho)
    rows = {}
    print(f"\n2. A long track, {n_frames} frames (windows of {window}; time under tracemalloc)")
    for keep in (True, False):
        loop = Loop(frames, keep, np.add(x1, [0.2, 2.0, 0.0]))
        run = loop.run
        first = _window(run(0, window))
        run(window, n_frames - window)()
        last = _window(run(n_frames - window, n_frames))
        track = loop.track
        key = "whole_track" if keep else "last_state_only"
        rows[key] = {
            "first_ms_per_frame": 1e3 * first[0],
            "last_ms_per_frame": 1e3 * last[0],
            "time_ratio": last[0] / first[0],
            "first_bytes_per_frame": first[1],
            "last_bytes_per_frame": last[1],
            "states_kept": len(track),
            "depth_sd_last": float(track[-1].depth_sd),
        }
        r = rows[key]
        print(
            f"   {key:<16} ms per frame {r['first_ms_per_frame']:.3f} -> "
            f"{r['last_ms_per_frame']:.3f} (x{r['time_ratio']:.2f}); bytes kept per frame "
            f"{r['first_bytes_per_frame']:,.0f} -> {r['last_bytes_per_frame']:,.0f}"
        )
    return {"frames": n_frames, "window": window, **rows}


#: The tracker's scene, four points (x, y, v) at frame 1, their bearings crossing.
POINTS = np.array([[1.2, 4.0, 1.2], [-1.0, 5.0, -0.8], [0.5, 6.0, -0.5], [-0.5, 3.0, 0.6]])
TRACKER_PRIOR = GaussianState([0.0, 5.0, 0.0], np.diag([9.0, 9.0, 1.0]))


def in_a_tracker(n_frames: int, scenes: int) -> dict:
    step = models.DepthStep(speed=1.0)
    filters = {
        "exact": (
            exact.ExactPredictor(step),
            exact.ExactUpdater(None),
            association.ExactMahalanobis(),
        ),
        "ekf": (ExtendedKalmanPredictor(step), ExtendedKalmanUpdater(None), Mahalanobis()),
    }
    print(f"\n3. In Stone Soup's MultiTargetTracker, {scenes} scenes of {n_frames} frames")
    out = {"frames": n_frames, "scenes": scenes}
    for name, (predictor, updater, measure) in filters.items():
        total, frames_run = 0.0, 0
        for seed in range(scenes):
            rng = np.random.default_rng(seed)
            states = np.stack([model.G(x, np.arange(float(n_frames))) for x in POINTS])
            mu = model.project(states) + FIG2.rho * rng.standard_normal(states.shape[:2])
            mu[rng.random(mu.shape) > 0.9] = np.nan
            clutter = [rng.uniform(-1.2, 1.2, rng.poisson(2.0)) for _ in range(n_frames)]
            scene = tracks.scene(states, mu, FIG2.rho, clutter, seed=seed)
            hypothesiser = DistanceHypothesiser(predictor, updater, measure, missed_distance=3)
            holding = MultiMeasurementInitiator(
                TRACKER_PRIOR,
                UpdateTimeStepsDeleter(2),
                GNNWith2DAssignment(hypothesiser),
                updater,
                initiator=SinglePointInitiator(TRACKER_PRIOR, None, updater),
                min_points=4,
            )
            tracker = MultiTargetTracker(
                holding, UpdateTimeStepsDeleter(3), None, GNNWith2DAssignment(hypothesiser), updater
            )
            t = time.process_time()
            for frame in scene.frames:
                tracker.update_tracker(frame.timestamp, frame.detections)
            total += time.process_time() - t
            frames_run += n_frames
        out[f"{name}_ms_per_frame"] = 1e3 * total / frames_run
        print(f"   {name:<6} {out[f'{name}_ms_per_frame']:.2f} ms per frame")
    out["ratio"] = out["exact_ms_per_frame"] / out["ekf_ms_per_frame"]
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="smaller sizes (a check that it runs)")
    a = p.parse_args(argv)
    if a.quick:
        sizes = {"per_update": (100, 3), "long_track": (600, 200), "tracker": (10, 1)}
    else:
        sizes = {"per_update": (300, PAIRS), "long_track": (10_000, 1000), "tracker": (20, 4)}
    results = {
        "per_update": per_update(*sizes["per_update"]),
        "long_track": long_track(*sizes["long_track"]),
        "tracker": in_a_tracker(*sizes["tracker"]),
    }
    recorded = {key: list(value) for key, value in sizes.items()}
    path = benchmarks.write(__file__, MEASURES, recorded, results, full=not a.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
