"""Benchmark: the optimal filter's moments for many Monte Carlo trials at once.

Draws 10,000 noisy triples of the Figure 2 scenario (each with the paper's
prior built from its own measurements) and times, on one core,
:func:`depthcore.exact.optimal.moments` vectorised over the trials against
:func:`depthcore.exact.optimal.run` called trial by trial on a subset, and
checks that the two agree. Usage: ``python benchmarks/bench_trials.py [--quick]``;
the full run writes its record ``depthbook/provenance/benchmark_records/bench_trials.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (1,000 trials) writes outside the
committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.exact import optimal
from depthcore.problem.scenarios import SCENARIOS
from depthcore.studies import trials

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("exact.optimal",)
TRIALS, LOOP, SEED = 10_000, 200, 1


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="1,000 trials (not recorded)")
    args = p.parse_args(argv)
    n_trials, n_loop = (1000, 50) if args.quick else (TRIALS, LOOP)
    s = SCENARIOS["fig2"]
    tr = trials.simulate(s.c, s.rho, n_trials, np.random.default_rng(SEED))
    t = time.perf_counter()
    m = optimal.moments(tr.mu, tr.rho, tr.prior_mean, tr.prior_cov)
    t_vec = time.perf_counter() - t
    n = min(n_loop, len(tr.mu))
    t = time.perf_counter()
    single = [optimal.run(tr.mu[i], tr.rho, tr.prior_mean[i], tr.prior_cov) for i in range(n)]
    t_loop = (time.perf_counter() - t) * len(tr.mu) / n
    diff = max(
        max(
            abs(a.depth_mean - m.depth_mean[i]) / m.depth_sd[i],
            abs(a.velocity_sd - m.velocity_sd[i]) / m.velocity_sd[i],
        )
        for i, a in enumerate(single)
    )
    est = float(np.max(np.maximum(m.depth_error / m.depth_sd, m.velocity_error / m.velocity_sd)))
    print(f"Optimal depth and velocity moments for {len(tr.mu):,} trials of Figure 2, one core")
    print("| route | time | ratio |")
    print("|---|---:|---:|")
    print(f"| optimal.moments, vectorised over trials | {t_vec:.2f} s | 1 |")
    print(
        f"| optimal.run, trial by trial ({n} timed, scaled) | {t_loop:.2f} s "
        f"| {t_loop / t_vec:.1f} |"
    )
    print(
        f"largest error estimate {est:.1e} of the SD; "
        f"vectorised and single routes differ by {diff:.1e} SDs"
    )
    results = {
        "vectorised_s": t_vec,
        "trial_by_trial_s": t_loop,
        "ratio": t_loop / t_vec,
        "estimate_sd": est,
        "difference_sd": diff,
    }
    sizes = {"trials": len(tr.mu), "timed_one_by_one": n, "seed": SEED, "scenario": "fig2"}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
