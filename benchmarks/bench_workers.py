"""Benchmark: one study of fixed size in this process and on local clusters of 1, 2, all cores.

Times :func:`depthcore.studies.monte_carlo.study` (:data:`TRIALS` trials of
Figure 2's point over :data:`FRAMES` frames, the filters :data:`NAMES`, in
chunks of :data:`CHUNK`) side by side in one run: in this process, then on a
local cluster (:func:`depthcore.studies.tasks.cluster`) of one worker, of two,
and of every core of the machine, each worker a process of one thread. Each
cluster is started, warmed by a small study (its workers import depthcore) and
then timed on the study alone; the results on every cluster are checked equal
to the one in process, bit for bit. The ratios are the time in process over
each cluster's. Usage: ``python benchmarks/bench_workers.py [--quick]``; the
full run writes its record ``depthbook/provenance/benchmark_records/bench_workers.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (a tenth of the trials)
writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

from depthbook.provenance import benchmarks  # noqa: E402
from depthcore.studies import monte_carlo, tasks  # noqa: E402

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("studies.monte_carlo", "studies.tasks")
TRIALS, FRAMES, CHUNK, SEED = 2000, 10, 100, 1
NAMES = ("optimal", "second_order", "ekf", "ukf", "iterated", "inverse_depth")


def _timed(study: dict, client=None) -> tuple[float, str]:
    start = time.perf_counter()
    result = monte_carlo.study(**study, client=client)
    return time.perf_counter() - start, json.dumps(result, sort_keys=True)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a tenth of the trials (not recorded)")
    args = p.parse_args(argv)
    trials = TRIALS // 10 if args.quick else TRIALS
    study = dict(trials=trials, seed=SEED, names=NAMES, frames=FRAMES, chunk=CHUNK)
    warm = {**study, "trials": 2 * CHUNK}
    cores = os.cpu_count() or 1
    here, reference = _timed(study)
    counts = {"one": 1, "two": 2, "cores": cores}
    seconds = {}
    for key, n in counts.items():
        with tasks.cluster(workers=n) as client:
            client.wait_for_workers(n)
            monte_carlo.study(**warm, client=client)
            seconds[key], there = _timed(study, client)
        if there != reference:
            raise SystemExit(f"the study on {n} workers differs from the one in process")
    print(
        f"monte_carlo.study, {trials:,} trials of Figure 2 over {FRAMES} frames, "
        f"{len(NAMES)} filters, chunks of {CHUNK}; {cores} cores"
    )
    print("| where | workers | time | speed-up over in process |")
    print("|---|---:|---:|---:|")
    print(f"| in this process | - | {here:.1f} s | 1 |")
    for key, n in counts.items():
        print(f"| local cluster | {n} | {seconds[key]:.1f} s | {here / seconds[key]:.2f} |")
    print("the results on every cluster equal the one in process, bit for bit")
    results = {
        "in_process_s": here,
        **{f"{key}_s": s for key, s in seconds.items()},
        **{f"speedup_{key}": here / s for key, s in seconds.items()},
        "two_over_one": seconds["one"] / seconds["two"],
        "workers": counts,
    }
    sizes = {"trials": trials, "frames": FRAMES, "chunk": CHUNK, "seed": SEED, "filters": NAMES}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
