"""Benchmark: a track of 100,000 frames through the online exact filter and the online EKF.

A camera at 30 frames per second moving away from a point at 0.01 depth units
per frame (55 minutes of video; the depth from 5 to 1,005), the point's
lateral velocity a random walk (process noise ``Q`` per unit of depth), a
bearing at every frame with noise ``RHO``. Each filter of
:mod:`depthcore.registry.online` named in :data:`FILTERS` takes the frames one
at a time, as from a live camera. For each: the mean time per frame of the
first and of the last 1,000 frames (their ratio 1 when the cost does not grow;
the process's CPU time, one thread, so that other work on the machine does not
enter the comparison),
the memory a 1,000-frame stretch needs at its peak at the start and at the end
(tracemalloc, which slows those frames, so they are timed apart), the size of
what the filter holds (its pickled state) after the first and the last frames,
the exact filter's depth nodes and re-placements, the process's peak resident
memory after the first stretch and at the end, and the last frame's depth error
in units of the filter's SD. A first filter of each kind runs a few frames
before, so that the modules' first use is not counted.

Usage: ``python benchmarks/bench_long_track.py [--quick]``; the full run writes its
record ``depthbook/provenance/benchmark_records/bench_long_track.json``
(:mod:`depthbook.provenance.benchmarks`),
``--quick`` (5,000 frames) writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import pickle  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.registry import online

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("registry.online", "exact.online", "kalman.online", "problem.predictive")
#: The online filters run.
FILTERS = ("optimal", "ekf")
#: The state (x, y, v) at frame 1, the depth's change per frame, the noise levels.
STATE, STEP, RHO, Q = (1.0, 5.0, 0.3), 0.01, 0.002, 1e-3
#: The prior at frame 1: the state's neighbourhood, broad in depth.
PRIOR_MEAN, PRIOR_COV = (0.8, 6.0, 0.2), np.diag([1.0, 4.0, 0.1])
#: The frames timed, traced and compared at each end.
STRETCH = 1_000
#: The frames a first filter runs before the one measured (see :func:`measure`).
WARM = 100
SEED = 11


def track(frames: int):
    """The bearings (N,) and the true states (N, 3) of the point, seen from the camera."""
    rng = np.random.default_rng(SEED)
    x1, y1, v1 = STATE
    a = rng.normal(0.0, Q * np.sqrt(STEP), frames - 1)
    v = v1 + np.concatenate([[0.0], np.cumsum(a)])
    x = x1 + np.concatenate([[0.0], np.cumsum(STEP * v[:-1])])
    y = y1 + STEP * np.arange(frames)
    mu = x / y + rng.normal(0.0, RHO, frames)
    return mu, np.stack([x, y, v], -1)


def run(f, mu, start: int, stop: int, step: float) -> float:
    """Frames ``start + 1 .. stop`` through ``f``; the process's CPU seconds they took."""
    t = time.process_time()
    for k in range(start, stop):
        f.update(mu[k], step=1.0 if k == 0 else step)
    return time.process_time() - t


def traced_peak(f, mu, start: int, step: float) -> int:
    """The peak bytes allocated by frames ``start + 1 .. start + STRETCH`` (tracemalloc)."""
    tracemalloc.start()
    try:
        run(f, mu, start, start + STRETCH, step)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def peak_rss_mb() -> float:
    """The process's peak resident memory so far, in MB (Linux: ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(name: str, mu, truth) -> dict:
    """One filter over the whole track: the first and last stretches timed and traced.

    A first filter of the kind runs ``WARM`` frames before, so that what a first
    use of the modules imports and caches is not counted as the first frames' cost.
    """
    n = len(mu)
    run(online.start(name, PRIOR_MEAN, PRIOR_COV, rho=RHO, process_noise=Q), mu, 0, WARM, STEP)
    f = online.start(name, PRIOR_MEAN, PRIOR_COV, rho=RHO, process_noise=Q)
    first_s = run(f, mu, 0, STRETCH, STEP)
    held_first = len(pickle.dumps(f))
    rss_first = peak_rss_mb()
    peak_first = traced_peak(f, mu, STRETCH, STEP)
    run(f, mu, 2 * STRETCH, n - 2 * STRETCH, STEP)
    peak_last = traced_peak(f, mu, n - 2 * STRETCH, STEP)
    last_s = run(f, mu, n - STRETCH, n, STEP)
    est = f.current
    row = {
        "filter": name,
        "first_ms": 1e3 * first_s / STRETCH,
        "last_ms": 1e3 * last_s / STRETCH,
        "last_over_first": last_s / first_s,
        "traced_peak_first_bytes": peak_first,
        "traced_peak_last_bytes": peak_last,
        "held_first_bytes": held_first,
        "held_last_bytes": len(pickle.dumps(f)),
        "peak_rss_after_first_mb": rss_first,
        "peak_rss_at_end_mb": peak_rss_mb(),
        "frames_seen": f.frame,
        "last_depth_error_sd": (est.depth_mean - truth[-1, 1]) / est.depth_sd,
    }
    if name == "optimal":
        row["nodes_at_end"] = f.detail.node_count
        row["replacements"] = f.detail.replacements
    return row


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="5,000 frames (not recorded)")
    a = p.parse_args(argv)
    frames = 5_000 if a.quick else 100_000
    mu, truth = track(frames)
    print(
        f"{frames:,} frames, step {STEP} per frame (depth {truth[0, 1]:g} to "
        f"{truth[-1, 1]:g}), rho {RHO}, q {Q}; per frame, first and last {STRETCH:,} frames"
    )
    head = (
        f"{'filter':<8} {'first':>9} {'last':>9} {'ratio':>6} {'peak first':>11} "
        f"{'peak last':>10} {'held':>7} {'RSS MB':>13} {'error':>7}"
    )
    print(head)
    rows = []
    for name in FILTERS:
        r = measure(name, mu, truth)
        rows.append(r)
        print(
            f"{name:<8} {r['first_ms']:>7.3f}ms {r['last_ms']:>7.3f}ms "
            f"{r['last_over_first']:>6.2f} {r['traced_peak_first_bytes']:>11,} "
            f"{r['traced_peak_last_bytes']:>10,} {r['held_last_bytes']:>7,} "
            f"{r['peak_rss_after_first_mb']:>6.0f} {r['peak_rss_at_end_mb']:>6.0f} "
            f"{r['last_depth_error_sd']:>7.2f}"
        )
    results = {"frames": frames, "filters": rows}
    sizes = {"frames": frames, "stretch": STRETCH, "step": STEP, "rho": RHO, "process_noise": Q}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not a.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
