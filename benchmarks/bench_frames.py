"""Benchmark: the cost per trial of every N-frame filter against the number of frames N.

Figure 2's point followed from time 1 for N frames with lateral process
noise ``q`` (:func:`depthcore.problem.model.simulate`, from frame 1), with Figure 2's prior. Every
filter of the registry's ``ALL_NAMES`` that takes N frames (:mod:`depthcore.registry.filters`, with
``q`` where it supports process noise and 0 where it does not) and the
iterated extended Kalman smoother (:func:`depthcore.kalman.iterated.smoother`, not a
registry entry), each at its defaults, runs on the same trials at N = 30,
100, 300 and 1,000. Each time is the least of repeated calls on one batch of
trials, per trial; the growth column is the cost per frame at the largest N
relative to that at the smallest, 1 where the cost grows linearly with N
(below 1: slower than linearly). The resample-move filter is left out
(:data:`LEFT_OUT`): its moves revisit every earlier bearing, a cost growing
like N**2.

Usage: ``python benchmarks/bench_frames.py [--quick]``; the full run writes its
record ``depthbook/provenance/benchmark_records/bench_frames.json``
(:mod:`depthbook.provenance.benchmarks`),
``--quick`` (N = 10, 20, 40) writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.kalman import iterated
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import ALL_NAMES, FILTERS

FIG2 = SCENARIOS["fig2"]
#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("registry.filters", "kalman.iterated")
#: The process noise of the tracks (the SD of the velocity's change per frame).
Q = 0.005
SEED = 7
#: The label of the iterated extended Kalman smoother's row.
SMOOTHER = "iterated smoother"
#: Options other than the defaults (none at present; recorded with each row).
OPTIONS: dict = {}
#: Filters not timed here: the resample-move filter's Metropolis moves evaluate the
#: likelihood of every earlier bearing, so its cost grows like N**2 (a trial of 1,000
#: frames takes many minutes); that is the method's, on a static state.
LEFT_OUT = ("resample_move",)


def problems(n_trials: int, n_frames: int):
    """Bearings (B, N) of Figure 2's point followed for N frames, and Figure 2's prior."""
    x1 = model.G(np.array(FIG2.c), -2)
    rng = np.random.default_rng(SEED)
    sim = model.simulate(x1, n_frames, FIG2.rho, Q, rng, size=n_trials, frame=1)
    return sim.mu, FIG2.prior.mean, FIG2.prior.cov


def runner(name: str, mu, pm, pc):
    """A call of the filter ``name`` on the batch, for timing."""
    if name == SMOOTHER:
        return lambda: iterated.smoother(mu, FIG2.rho, pm, pc, process_noise=Q)
    f = FILTERS[name]
    q = Q if f.with_process_noise else 0.0
    options = {"rng": np.random.default_rng(1)} if f.random else {}
    options.update(OPTIONS.get(name, {}))
    return lambda: f(mu, FIG2.rho, pm, pc, process_noise=q, **options)


def least_time(call, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        call()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="N = 10, 20, 40 (not recorded)")
    a = p.parse_args(argv)
    frames = [10, 20, 40] if a.quick else [30, 100, 300, 1000]
    n_trials, repeats = (2, 1) if a.quick else (2, 2)
    # the filters the studies of every filter run; those registered after ALL_NAMES run by name
    names = [n for n in ALL_NAMES if FILTERS[n].any_frames and n not in LEFT_OUT] + [SMOOTHER]
    batches = {n: problems(n_trials, n) for n in frames}
    print(f"Cost per trial against the frames N, {n_trials} trials of Figure 2's point, q = {Q}")
    print(f"{'filter':<20}" + "".join(f"{f'N = {n}':>12}" for n in frames) + f"{'growth':>10}")
    rows = []
    for name in names:
        per_trial = [least_time(runner(name, *batches[n]), repeats) / n_trials for n in frames]
        per_frame = np.array(per_trial) / np.array(frames)
        growth = float(per_frame[-1] / per_frame[0])
        q = Q if name == SMOOTHER or FILTERS[name].with_process_noise else 0.0
        cells = "".join(f"{1e3 * t:>10.1f}ms" for t in per_trial)
        print(f"{name:<20}{cells}{growth:>10.2f}")
        rows.append(
            {
                "filter": name,
                "process_noise": q,
                "options": OPTIONS.get(name, {}),
                "ms_per_trial": [1e3 * t for t in per_trial],
                "growth": growth,
            }
        )
    results = {"frames": frames, "filters": rows, "left_out": list(LEFT_OUT)}
    sizes = {"trials": n_trials, "repeats": repeats, "frames": frames, "process_noise": Q}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not a.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
