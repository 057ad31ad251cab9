"""Benchmark: the Kalman filter and fixed-interval smoother against filterpy, one sequence.

Four models, each simulated for 1,000 steps from its prior:

* the bank's case: a constant-velocity model (position and velocity, the
  position measured, a scalar measurement), with process noise on the
  velocity alone (a singular ``Sigma_p``, as in the bank's lateral filters);
* a point in the plane measured in 2-D with correlated noise, its state the
  position (``n = 2``, a random walk), position and velocity (``n = 4``) or
  position, velocity and acceleration (``n = 6``), the derivatives damped
  (kept at ``DAMPING`` of themselves each step, so that the position stays
  within a few thousand SDs of the origin and the two routes' rounding stays
  far below an SD), the noise on the highest derivative alone;

and for each, side by side in one run,

* :func:`depthcore.kalman.linear.run` followed by
  :func:`depthcore.kalman.linear.fixed_interval_smoother` (textbook 19.2.3, 19.2.6), and
* filterpy's ``KalmanFilter`` (``update`` for the first measurement, then
  ``predict`` and ``update`` for each later one: the loop of its
  ``batch_filter``, whose prior is at the first measurement as depthcore's is)
  followed by its ``rts_smoother``,

the four (filter and smoother of each route) timed in turn, the round repeated
over the models and the pairs; each ratio is the median over the pairs of
filterpy's time over depthcore's (each pair measured back to back, so a change
of the machine's load between pairs changes both; at least ``TARGET_RATIO``:
depthcore at least as fast). The two routes' smoothed means and covariances are
compared.

Usage: ``python benchmarks/bench_kalman.py [--quick]``; the full run writes its
record ``depthbook/provenance/benchmark_records/bench_kalman.json``
(:mod:`depthbook.provenance.benchmarks`),
``--quick`` (200 steps, 3 pairs) writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from filterpy.kalman import KalmanFilter, rts_smoother  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.kalman import linear

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("kalman.linear",)
STEPS, PAIRS, SEED = 1000, 11, 3
#: filterpy's time over depthcore's that the filter and the smoother should reach.
TARGET_RATIO = 1.0
#: The state dimensions of the plane's models, each measured in 2-D.
PLANE_DIMENSIONS = (2, 4, 6)
#: What a derivative of the plane's position keeps of itself over one step.
DAMPING = 0.95


def bank_model() -> dict:
    """The bank's case: constant velocity, the position measured (n = 2, m = 1)."""
    return dict(
        Psi=np.array([[1.0, 1.0], [0.0, 1.0]]),
        Sigma_p=np.diag([0.0, 1e-4]),
        Phi=np.array([[1.0, 0.0]]),
        Sigma_m=np.array([[0.01]]),
    )


def plane_model(n: int) -> dict:
    """A point in the plane: its position and next ``n / 2 - 1`` derivatives, measured in 2-D.

    ``Psi`` is the Taylor step over one unit of time with the derivatives
    damped by ``DAMPING``, ``Sigma_p`` noise on the highest derivative alone,
    the measurement the position with correlated noise (m = 2).
    """
    q = n // 2
    F = np.array(
        [[1.0 / math.factorial(j - i) if j >= i else 0.0 for j in range(q)] for i in range(q)]
    )
    F[range(1, q), range(1, q)] = DAMPING
    Sigma_p = np.zeros((n, n))
    Sigma_p[-2:, -2:] = 1e-4 * np.eye(2)
    return dict(
        Psi=np.kron(F, np.eye(2)),
        Sigma_p=Sigma_p,
        Phi=np.eye(2, n),
        Sigma_m=np.array([[0.01, 0.003], [0.003, 0.02]]),
    )


def sequence(model: dict, steps: int) -> np.ndarray:
    """Measurements (T, m) of ``model``, simulated from the prior ``N(0, I)``."""
    rng = np.random.default_rng(SEED)
    Psi, Phi = model["Psi"], model["Phi"]
    n, m = Phi.shape[1], Phi.shape[0]
    root_p = np.sqrt(np.diag(model["Sigma_p"]))  # the process noise is diagonal
    root_m = np.linalg.cholesky(model["Sigma_m"])
    w = rng.standard_normal(n)
    x = np.empty((steps, m))
    for t in range(steps):
        x[t] = Phi @ w + root_m @ rng.standard_normal(m)
        w = Psi @ w + root_p * rng.standard_normal(n)
    return x


def depthcore_filter(model, x):
    n = model["Psi"].shape[0]
    return linear.run(
        x, np.zeros(n), np.eye(n), model["Psi"], model["Sigma_p"], model["Phi"], model["Sigma_m"]
    )


def depthcore_smoother(model, filtered):
    return linear.fixed_interval_smoother(filtered, model["Psi"])


def filterpy_filter(model, x):
    n, m = model["Psi"].shape[0], x.shape[1]
    f = KalmanFilter(dim_x=n, dim_z=m)
    f.x, f.P = np.zeros(n), np.eye(n)
    f.F, f.Q, f.H, f.R = model["Psi"], model["Sigma_p"], model["Phi"], model["Sigma_m"]
    means, covs = np.empty((len(x), n)), np.empty((len(x), n, n))
    for t, z in enumerate(x):
        if t > 0:
            f.predict()
        f.update(z)
        means[t], covs[t] = f.x, f.P
    return means, covs


def filterpy_smoother(model, filtered):
    means, covs = filtered
    T, n = means.shape
    Fs = np.broadcast_to(model["Psi"], (T, n, n))
    Qs = np.broadcast_to(model["Sigma_p"], (T, n, n))
    smoothed = rts_smoother(means, covs, Fs, Qs)
    return smoothed[0], smoothed[1]


def timed(route, *args):
    t = time.perf_counter()
    out = route(*args)
    return time.perf_counter() - t, out


def one_pair(model, x) -> tuple[np.ndarray, tuple, tuple]:
    """Times (4,) of depthcore's filter and smoother and filterpy's, and the smoothed results."""
    t1, ours = timed(depthcore_filter, model, x)
    t2, ours_smoothed = timed(depthcore_smoother, model, ours)
    t3, theirs = timed(filterpy_filter, model, x)
    t4, theirs_smoothed = timed(filterpy_smoother, model, theirs)
    return np.array([t1, t2, t3, t4]), ours_smoothed, theirs_smoothed


def summary(times: np.ndarray, ours, theirs, m: int) -> dict:
    """The medians, ratios and agreement of one model's pairs; ``times`` is (pairs, 4)."""
    ms = 1e3 * np.median(times, axis=0)
    both = (times[:, 2] + times[:, 3]) / (times[:, 0] + times[:, 1])
    means, covs = theirs
    sd = np.sqrt(np.einsum("...ii->...i", covs))
    d_mean = float(np.max(np.abs(ours.mean - means) / sd))
    d_cov = float(
        np.max(np.linalg.norm(ours.cov - covs, axis=(-2, -1)) / np.linalg.norm(covs, axis=(-2, -1)))
    )
    return {
        "state_dimension": int(ours.mean.shape[-1]),
        "measurement_dimension": m,
        "depthcore_ms": float(ms[0] + ms[1]),
        "filterpy_ms": float(ms[2] + ms[3]),
        "depthcore_filter_ms": float(ms[0]),
        "depthcore_smoother_ms": float(ms[1]),
        "filterpy_filter_ms": float(ms[2]),
        "filterpy_smoother_ms": float(ms[3]),
        "filter_ratio": float(np.median(times[:, 2] / times[:, 0])),
        "smoother_ratio": float(np.median(times[:, 3] / times[:, 1])),
        "ratio": float(np.median(both)),
        "ratio_min": float(both.min()),
        "ratio_max": float(both.max()),
        "mean_difference_sd": d_mean,
        "covariance_difference_max": d_cov,
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="200 steps, 3 pairs (not recorded)")
    args = p.parse_args(argv)
    steps, pairs = (200, 3) if args.quick else (STEPS, PAIRS)
    models = [bank_model(), *(plane_model(n) for n in PLANE_DIMENSIONS)]
    xs = [sequence(model, steps) for model in models]
    times = np.empty((len(models), pairs, 4))
    smoothed = [None] * len(models)  # each model's last pair: (depthcore's, filterpy's)
    for i in range(pairs):
        for j, (model, x) in enumerate(zip(models, xs, strict=True)):
            times[j, i], ours, theirs = one_pair(model, x)
            smoothed[j] = ours, theirs
    rows = [summary(times[j], *smoothed[j], xs[j].shape[1]) for j in range(len(models))]
    print(f"Kalman filter and fixed-interval smoother, one sequence of {steps} steps, one core")
    print(f"{pairs} pairs timed alternately; medians; ratios filterpy / depthcore")
    print("| n | m | depthcore filter | smoother | filterpy filter | smoother | ratios |")
    print("|---|---|---:|---:|---:|---:|---|")
    for r in rows:
        print(
            f"| {r['state_dimension']} | {r['measurement_dimension']} "
            f"| {r['depthcore_filter_ms']:.1f} ms | {r['depthcore_smoother_ms']:.1f} ms "
            f"| {r['filterpy_filter_ms']:.1f} ms | {r['filterpy_smoother_ms']:.1f} ms "
            f"| filter {r['filter_ratio']:.2f}, smoother {r['smoother_ratio']:.2f}, "
            f"both {r['ratio']:.2f} ({r['ratio_min']:.2f} to {r['ratio_max']:.2f}) |"
        )
    worst_mean = max(r["mean_difference_sd"] for r in rows)
    worst_cov = max(r["covariance_difference_max"] for r in rows)
    print(f"smoothed means differ by {worst_mean:.1e} SDs, covariances by {worst_cov:.1e}")
    if not (worst_mean < 1e-9 and worst_cov < 1e-9):
        raise SystemExit("depthcore and filterpy disagree beyond rounding")
    results = dict(rows[0])  # the bank's case, as before
    results["dimensions"] = rows[1:]
    results["target_ratio"] = TARGET_RATIO
    sizes = {
        "steps": steps,
        "pairs": pairs,
        "seed": SEED,
        "state_dimension": 2,
        "plane_state_dimensions": list(PLANE_DIMENSIONS),
        "damping": DAMPING,
    }
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
