"""Benchmark: the batched EKF of Eqs. (10)-(12) against filterpy, trial by trial.

Runs 10,000 Monte Carlo trials of the Figure 2 scenario (each with its own
measurements and the paper's prior built from them) through

* :func:`depthcore.kalman.ekf.run`, vectorised over the trials, and
* filterpy's ``ExtendedKalmanFilter``, one trial at a time (filterpy
  updates the covariance in Joseph form; the two agree algebraically),

timed alternately, the pair repeated (:data:`PAIRS`), checks that both give
the same means and covariances, and prints the median times and the median
over the pairs of their ratio (each pair measured back to back, so that a
change of the machine's load between pairs changes both).

Usage: ``python benchmarks/bench_ekf_filterpy.py [--quick]``; the full run
writes its record ``depthbook/provenance/benchmark_records/bench_ekf_filterpy.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (1,000 trials, 3 pairs) writes
outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from filterpy.kalman import ExtendedKalmanFilter  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.kalman import ekf
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.studies import trials as study_trials

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("kalman.ekf",)
TRIALS, SEED = 10_000, 1
#: The pairs of runs (depthcore, then filterpy) timed alternately.
PAIRS = 7


def filterpy_run(mu, rho, prior_mean, prior_cov):
    """filterpy's EKF over one triple; returns the mean and covariance after each measurement."""
    f = ExtendedKalmanFilter(dim_x=3, dim_z=1)
    f.x = np.array(prior_mean, dtype=float).reshape(3, 1)
    f.P = np.array(prior_cov, dtype=float)
    f.F = model.F.copy()
    f.B = model.e.reshape(3, 1)
    f.Q = np.zeros((3, 3))
    f.R = np.array([[rho**2]])

    def jacobian(x):
        return model.observation_vector(x[:, 0]).reshape(1, 3)

    def hx(x):
        return np.array([[x[0, 0] / x[1, 0]]])

    means, covs = [], []
    for i, m in enumerate(mu):
        if i > 0:
            f.predict(u=np.array([[1.0]]))
        f.update(np.array([[m]]), jacobian, hx)
        means.append(f.x[:, 0].copy())
        covs.append(f.P.copy())
    return np.array(means), np.array(covs)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="1,000 trials, 3 pairs (not recorded)")
    args = p.parse_args(argv)
    n_trials, pairs = (1000, 3) if args.quick else (TRIALS, PAIRS)
    s = SCENARIOS["fig2"]
    trials = study_trials.simulate(s.c, s.rho, n_trials, np.random.default_rng(SEED))
    mu, pm, pc = trials.mu, trials.prior_mean, trials.prior_cov

    # Alternate the two routes, pair by pair, so that a change of the machine's load
    # between pairs changes both; the ratio is the median over the pairs.
    ours, theirs = [], []
    for _ in range(pairs):
        t = time.perf_counter()
        means, covs = ekf.run(mu, s.rho, pm, pc)
        ours.append(time.perf_counter() - t)
        t = time.perf_counter()
        ref = [filterpy_run(mu[i], s.rho, pm[i], pc) for i in range(len(mu))]
        theirs.append(time.perf_counter() - t)
    ratios = np.array(theirs) / np.array(ours)
    t_ours, t_theirs, ratio = np.median(ours), np.median(theirs), float(np.median(ratios))
    ref_means = np.array([r[0] for r in ref])
    ref_covs = np.array([r[1] for r in ref])
    # Differences in units of each component's posterior SD: a mean near zero
    # (x passes through 0 on some trials) makes a plain relative difference meaningless.
    scale = np.sqrt(np.einsum("...ii->...i", ref_covs))
    d_mean = np.max(np.abs(means - ref_means) / scale)
    # Covariances relative to their own size (Frobenius norm): after the first
    # measurement P is nearly singular (correlations within 1e-8 of -1), so its
    # entries carry rounding of order eps * cond(P) whichever exact formula computes them.
    # Both routes lie about 1e-10 from an extended-precision evaluation in the worst
    # trials (cond(P) ~ 1e7 after the first measurement), so that is the agreement to expect.
    rel = np.linalg.norm(covs - ref_covs, axis=(-2, -1)) / np.linalg.norm(ref_covs, axis=(-2, -1))
    d_cov, d_cov_median = np.max(rel), np.median(rel)

    print(f"EKF over {len(mu):,} trials of Figure 2 (three measurements each), one core")
    print(f"{pairs} pairs timed alternately; median times, median of the pairs' ratios")
    print("| route | time | ratio |")
    print("|---|---:|---:|")
    print(f"| depthcore.kalman.ekf.run, vectorised | {t_ours * 1e3:.1f} ms | 1 |")
    print(
        f"| filterpy ExtendedKalmanFilter, trial by trial | {t_theirs * 1e3:,.0f} ms "
        f"| {ratio:,.0f} |"
    )
    print(f"the pairs' ratios range from {ratios.min():,.1f} to {ratios.max():,.1f}")
    print(
        f"largest difference after any measurement: means {d_mean:.1e} posterior SDs, "
        f"covariances {d_cov:.1e} of their Frobenius norm (median {d_cov_median:.1e})"
    )
    if not (d_mean < 1e-10 and d_cov < 1e-9):
        raise SystemExit("depthcore and filterpy disagree beyond rounding")
    results = {
        "depthcore_ms": 1e3 * float(t_ours),
        "filterpy_ms": 1e3 * float(t_theirs),
        "ratio": ratio,
        "ratio_min": float(ratios.min()),
        "ratio_max": float(ratios.max()),
        "mean_difference_sd": d_mean,
        "covariance_difference_max": d_cov,
        "covariance_difference_median": d_cov_median,
    }
    sizes = {"trials": len(mu), "seed": SEED, "pairs": pairs, "scenario": "fig2"}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
