"""Benchmark: the Kalman filter and fixed-interval smoother against filterpy, one sequence.

A constant-velocity model (position and velocity, the position measured),
with process noise on the velocity alone (a singular ``Sigma_p``, as in the
bank's lateral filters), simulated for 1,000 steps; then

* :func:`depthcore.kalman.linear.run` followed by
  :func:`depthcore.kalman.linear.fixed_interval_smoother` (textbook 19.2.3, 19.2.6), and
* filterpy's ``KalmanFilter`` (``update`` for the first measurement, then
  ``predict`` and ``update`` for each later one) followed by its
  ``rts_smoother``,

timed alternately, the pair repeated; the ratio is the median over the pairs
of filterpy's time over depthcore's (each pair measured back to back, so a
change of the machine's load between pairs changes both). The two routes'
smoothed means and covariances are compared.

Usage: ``python benchmarks/bench_kalman.py [--quick]``; the full run writes its
record ``depthcore/provenance/benchmark_records/bench_kalman.json``
(:mod:`depthcore.provenance.benchmarks`),
``--quick`` (200 steps, 3 pairs) writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from filterpy.kalman import KalmanFilter, rts_smoother  # noqa: E402

from depthcore.kalman import linear
from depthcore.provenance import benchmarks

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("kalman.linear",)
STEPS, PAIRS, SEED = 1000, 11, 3
PSI = np.array([[1.0, 1.0], [0.0, 1.0]])
SIGMA_P = np.diag([0.0, 1e-4])
PHI = np.array([[1.0, 0.0]])
SIGMA_M = np.array([[0.01]])
PRIOR_MEAN, PRIOR_COV = np.zeros(2), np.eye(2)


def sequence(steps: int) -> np.ndarray:
    """Measurements (T, 1) of the model, simulated from the prior."""
    rng = np.random.default_rng(SEED)
    w = PRIOR_MEAN + np.linalg.cholesky(PRIOR_COV) @ rng.standard_normal(2)
    x = np.empty((steps, 1))
    for t in range(steps):
        x[t] = PHI @ w + np.sqrt(SIGMA_M[0, 0]) * rng.standard_normal(1)
        w = PSI @ w + np.array([0.0, np.sqrt(SIGMA_P[1, 1]) * rng.standard_normal()])
    return x


def depthcore_route(x):
    filtered = linear.run(x, PRIOR_MEAN, PRIOR_COV, PSI, SIGMA_P, PHI, SIGMA_M)
    return linear.fixed_interval_smoother(filtered, PSI)


def filterpy_route(x):
    f = KalmanFilter(dim_x=2, dim_z=1)
    f.x, f.P = PRIOR_MEAN.copy(), PRIOR_COV.copy()
    f.F, f.Q, f.H, f.R = PSI, SIGMA_P, PHI, SIGMA_M
    means, covs = np.empty((len(x), 2)), np.empty((len(x), 2, 2))
    for t, z in enumerate(x):
        if t > 0:
            f.predict()
        f.update(z)
        means[t], covs[t] = f.x, f.P
    T = len(x)
    smoothed = rts_smoother(
        means, covs, np.broadcast_to(PSI, (T, 2, 2)), np.broadcast_to(SIGMA_P, (T, 2, 2))
    )
    return smoothed[0], smoothed[1]


def timed(route, x):
    t = time.perf_counter()
    out = route(x)
    return time.perf_counter() - t, out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="200 steps, 3 pairs (not recorded)")
    args = p.parse_args(argv)
    steps, pairs = (200, 3) if args.quick else (STEPS, PAIRS)
    x = sequence(steps)
    ours, theirs = [], []
    for _ in range(pairs):
        t_ours, smoothed = timed(depthcore_route, x)
        t_theirs, (means, covs) = timed(filterpy_route, x)
        ours.append(t_ours)
        theirs.append(t_theirs)
    ratios = np.array(theirs) / np.array(ours)
    sd = np.sqrt(np.einsum("...ii->...i", covs))
    d_mean = float(np.max(np.abs(smoothed.mean - means) / sd))
    d_cov = float(
        np.max(
            np.linalg.norm(smoothed.cov - covs, axis=(-2, -1)) / np.linalg.norm(covs, axis=(-2, -1))
        )
    )
    print(f"Kalman filter and fixed-interval smoother, one sequence of {steps} steps, one core")
    print(f"{pairs} pairs timed alternately; medians")
    print("| route | time |")
    print("|---|---:|")
    print(f"| depthcore kalman.run + fixed_interval_smoother | {1e3 * np.median(ours):.1f} ms |")
    print(f"| filterpy KalmanFilter + rts_smoother | {1e3 * np.median(theirs):.1f} ms |")
    print(
        f"median ratio filterpy / depthcore over the pairs: {np.median(ratios):.2f} "
        f"(from {ratios.min():.2f} to {ratios.max():.2f})"
    )
    print(f"smoothed means differ by {d_mean:.1e} SDs, covariances by {d_cov:.1e} of their norm")
    if not (d_mean < 1e-9 and d_cov < 1e-9):
        raise SystemExit("depthcore and filterpy disagree beyond rounding")
    results = {
        "depthcore_ms": 1e3 * float(np.median(ours)),
        "filterpy_ms": 1e3 * float(np.median(theirs)),
        "ratio": float(np.median(ratios)),
        "ratio_min": float(ratios.min()),
        "ratio_max": float(ratios.max()),
        "mean_difference_sd": d_mean,
        "covariance_difference_max": d_cov,
    }
    sizes = {"steps": steps, "pairs": pairs, "seed": SEED, "state_dimension": 2}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
