"""Benchmark: the Rao-Blackwellised particle filter against the plain causal particle filter.

Measures, side by side in one run, on one core, on Figure 2's problem (three
frames) and on Figure 2's point followed for ten frames (``q = 0``, the
bootstrap filter's deterministic motion; bearings simulated with a fixed
seed, the paper's prior):

* at equal wall-clock cost, the error of the depth mean at the last frame of
  :func:`depthcore.particles.rbpf.run` (particles over depth, a Kalman filter each) and
  of :func:`depthcore.particles.resample_move.run` (particles over the whole state,
  resample-move), each with its default moves: the particles of the
  resample-move filter are scaled from a pilot run so that its time matches
  the RBPF's;
* the RBPF's error as its particles grow.

Errors are relative to the exact filter, the bank of Kalman filters
(:mod:`depthcore.exact.bank`) on a Gauss-Legendre rule in log depth refined until
its moments change by less than 1e-10 of themselves, in units of the exact
posterior SD of the depth; "RMS error" is the root mean square over
``--repeats`` independent runs, "SE" the RBPF's standard error of the
average of those runs from their spread (:meth:`depthcore.particles.rbpf.RBPF.standard_errors`).
Usage: ``python benchmarks/bench_rbpf.py [--quick]``; the full run writes its
record ``depthbook/provenance/benchmark_records/bench_rbpf.json``
(:mod:`depthbook.provenance.benchmarks`),
``--quick`` (fewer runs and particles) writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.exact import bank, mixture
from depthcore.particles import rbpf, resample_move
from depthcore.problem import model
from depthcore.problem.gaussian import paper_prior
from depthcore.problem.scenarios import SCENARIOS

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("particles.rbpf", "particles.resample_move", "exact.bank", "exact.mixture")
PILOT = 2000  # particles of the resample-move filter's pilot run
GROWTH = (250, 1000, 4000, 16000)
REPEATS, PARTICLES = (
    10,
    8000,
)  # RBPF particles at equal cost: enough that the plain filter does not collapse


def log_depth_rule(panels, order=20, lo=-12.0, hi=14.0):
    """Nodes and weights over ``y_1 > 0``: Gauss-Legendre panels in ``t = log(y_1)``."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(lo, hi, panels + 1)
    half = 0.5 * np.diff(edges)
    t = (0.5 * (edges[1:] + edges[:-1])[:, None] + half[:, None] * x).ravel()
    return np.exp(t), (half[:, None] * w).ravel() * np.exp(t)


def exact(mu, rho, prior):
    """The bank's depth mean and SD at the last frame, panels doubled until converged."""
    panels, previous = 20, None
    while True:
        y, w = log_depth_rule(panels)
        mx = mixture.mixture(bank.filter_bank(y, mu, rho, prior.mean, prior.cov), w)
        now = np.array([mx.depth_mean, mx.depth_sd])
        if previous is not None and np.all(np.abs(now - previous) <= 1e-10 * np.abs(now)):
            return float(now[0]), float(now[1])
        previous, panels = now, 2 * panels


def problems():
    s = SCENARIOS["fig2"]
    x1 = model.G(s.c, -2)
    sim = model.simulate(x1, 10, s.rho, 0.0, np.random.default_rng(2024), frame=1)
    return {
        "Figure 2, N = 3": (np.asarray(s.mu), s.rho, s.prior),
        "Figure 2's point, N = 10": (sim.mu, s.rho, paper_prior(s.c)),
    }


def time_rbpf(mu, rho, prior, J, R, seed):
    t = time.perf_counter()
    f = rbpf.run(mu, rho, prior.mean, prior.cov, J, np.random.default_rng(seed), replicas=R)
    return time.perf_counter() - t, f


def time_resample_move(mu, rho, prior, n, R, seed):
    t = time.perf_counter()
    b = resample_move.run(
        np.tile(mu, (R, 1)), rho, prior.mean, prior.cov, n, np.random.default_rng(seed)
    )
    return time.perf_counter() - t, b.moments()["depth_mean"]


def rms(estimates, mean, sd):
    return float(np.sqrt(np.mean((np.asarray(estimates) - mean) ** 2)) / sd)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer runs and particles (not recorded)")
    args = p.parse_args(argv)
    R, J0, growth = (2, 250, (100, 400)) if args.quick else (REPEATS, PARTICLES, GROWTH)
    equal_cost, convergence = [], []
    cases = problems()
    truth = {name: exact(*case) for name, case in cases.items()}

    print(f"Depth-mean error at the last frame, equal wall-clock cost, {R} runs, one core")
    print("(RMS error over the runs, in units of the exact posterior SD of the depth)")
    print(
        "| problem | RBPF particles | RBPF time | RBPF error | resample-move particles "
        "| resample-move time | resample-move error | error ratio |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, (mu, rho, prior) in cases.items():
        mean, sd = truth[name]
        t_rb, f = time_rbpf(mu, rho, prior, J0, R, seed=1)
        e_rb = rms(f.replica_moments().depth_mean, mean, sd)
        t_pilot, _ = time_resample_move(mu, rho, prior, PILOT, R, seed=2)
        n = max(2, int(round(PILOT * t_rb / t_pilot)))
        t_pf, est = time_resample_move(mu, rho, prior, n, R, seed=3)
        e_pf = rms(est, mean, sd)
        print(
            f"| {name} | {J0:,} | {t_rb:.2f} s | {e_rb:.4f} | {n:,} | {t_pf:.2f} s "
            f"| {e_pf:.4f} | {e_pf / e_rb:.1f} |"
        )
        equal_cost.append(
            {
                "problem": name,
                "rbpf_particles": J0,
                "rbpf_time_s": t_rb,
                "rbpf_error_sd": e_rb,
                "resample_move_particles": n,
                "resample_move_time_s": t_pf,
                "resample_move_error_sd": e_pf,
                "error_ratio": e_pf / e_rb,
            }
        )

    print()
    print(f"The RBPF converging to the bank: error as the particles grow, {R} runs, one core")
    print("| problem | particles | time | RMS error | SE of the average | RMS error x sqrt(J) |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (mu, rho, prior) in cases.items():
        mean, sd = truth[name]
        for J in growth:
            t, f = time_rbpf(mu, rho, prior, J, R, seed=J)
            e = rms(f.replica_moments().depth_mean, mean, sd)
            se = float(f.standard_errors().depth_mean) / sd
            print(f"| {name} | {J:,} | {t:.2f} s | {e:.4f} | {se:.4f} | {e * np.sqrt(J):.2f} |")
            convergence.append(
                {
                    "problem": name,
                    "particles": J,
                    "time_s": t,
                    "error_sd": e,
                    "standard_error_sd": se,
                    "error_times_sqrt_particles_sd": e * float(np.sqrt(J)),
                }
            )
    sizes = {
        "repeats": R,
        "rbpf_particles": J0,
        "pilot_particles": PILOT,
        "growth": list(growth),
        "problems": list(cases),
    }
    results = {
        "exact": {name: {"depth_mean": m, "depth_sd": sd} for name, (m, sd) in truth.items()},
        "equal_cost": equal_cost,
        "convergence": convergence,
    }
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
