"""Benchmark: the range-parametrised EKF against the exact bank it approximates.

For two problems, Figure 2's triple and Figure 2's point continued to a
10-frame track (one noisy track, seed 4), the range-parametrised EKF
(:func:`depthcore.kalman.range_ekf.posterior`, Peach 1995) runs with a growing number
of components ``n`` on a geometric grid (four per doubling, 1 to
:data:`depthcore.kalman.range_ekf.MAX_COMPONENTS`), and its depth mean and SD at the
last frame are compared with the exact filter's (:func:`depthcore.exact.posterior.posterior`).
A tolerance is met from ``n`` on when the relative error of both moments is
below it at ``n`` and at every larger ``n`` of the grid. For each tolerance
(1e-2 and 1e-3) the table gives that ``n`` and the time of one call with it,
measured side by side with the bank's time of one call on the same problem in
this run (the least of repeated calls), and their ratio.

Usage: ``python benchmarks/bench_range_ekf.py [--quick]``; the full run
writes its record ``depthbook/provenance/benchmark_records/bench_range_ekf.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (fewer repeats) writes outside the
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
from depthcore.exact import posterior
from depthcore.kalman import range_ekf
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS

FIG2 = SCENARIOS["fig2"]
#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("exact.posterior", "kalman.range_ekf")
#: The relative tolerances on the depth mean and SD.
TOLERANCES = (1e-2, 1e-3)
#: The numbers of components tried: four per doubling, 1 to MAX_COMPONENTS.
GRID = tuple(
    sorted(
        {int(round(2 ** (j / 4))) for j in range(4 * int(np.log2(range_ekf.MAX_COMPONENTS)) + 1)}
    )
)


def problems() -> dict:
    """Figure 2's triple and its point continued to 10 frames: ``{name: bearings}``."""
    x1 = model.G(np.array(FIG2.c), -2)
    sim = model.simulate(x1, 10, FIG2.rho, 0.0, np.random.default_rng(4), size=1, frame=1)
    return {"fig2": np.array(FIG2.mu), "ten_frames": sim.mu[0]}


def best_of(f, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def compare(mu, repeats: int) -> dict:
    prior = FIG2.prior
    args = (mu, FIG2.rho, prior.mean, prior.cov)
    exact = posterior.posterior(*args)
    errors = []
    for n in GRID:
        g = range_ekf.posterior(*args, n_components=n)
        errors.append(
            max(
                abs(g.mean[1] / exact.depth_mean - 1),
                abs(np.sqrt(g.cov[1, 1]) / exact.depth_sd - 1),
            )
        )
    errors = np.array(errors)
    out = {
        "frames": int(mu.shape[-1]),
        "exact_depth_mean": float(exact.depth_mean),
        "exact_depth_sd": float(exact.depth_sd),
        "components": list(GRID),
        "relative_error": errors.tolist(),
    }
    for tol in TOLERANCES:
        # the first grid point from which every larger one meets the tolerance
        bad = np.nonzero(errors >= tol)[0]
        first = 0 if bad.size == 0 else int(bad[-1]) + 1
        key = f"{tol:.0e}"
        if first == len(GRID):
            out[key] = {"components": None}
            continue
        n = GRID[first]
        t_bank = best_of(lambda: posterior.posterior(*args), repeats)
        t_range = best_of(lambda n=n: range_ekf.posterior(*args, n_components=n), repeats)
        out[key] = {
            "components": n,
            "range_ekf_ms": 1e3 * t_range,
            "bank_ms": 1e3 * t_bank,
            "ratio": t_range / t_bank,
        }
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repeats (a check that it runs)")
    a = p.parse_args(argv)
    repeats = 2 if a.quick else 7
    results = {}
    print("Components for the range-parametrised EKF to match the exact depth mean and SD")
    print(f"{'problem':<12}{'tolerance':>10}{'components':>12}{'ms, range':>11}{'ms, bank':>10}")
    for name, mu in problems().items():
        r = compare(mu, repeats)
        results[name] = r
        for tol in TOLERANCES:
            row = r[f"{tol:.0e}"]
            if row["components"] is None:
                print(f"{name:<12}{tol:>10.0e}{'> ' + str(GRID[-1]):>12}")
                continue
            print(
                f"{name:<12}{tol:>10.0e}{row['components']:>12}"
                f"{row['range_ekf_ms']:>11.2f}{row['bank_ms']:>10.2f}"
            )
    print("ms: the least of repeated calls on one problem, both measured in this run")
    path = benchmarks.write(
        __file__,
        MEASURES,
        {"repeats": repeats, "grid": list(GRID), "tolerances": list(TOLERANCES)},
        results,
        full=not a.quick,
    )
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
