"""Benchmark: the exact filter for any number of frames, a bank of Kalman filters over depth.

Four tables, every ratio measured side by side in this run (one extrapolation,
recorded as such beside the measured ratio):

1. **Three frames.** :func:`depthcore.exact.posterior.moments` (a Kalman filter at each
   quadrature node) against :func:`depthcore.exact.optimal.moments` (the closed form
   of Eqs. (14)-(16) at the same nodes) on the same Monte Carlo trials of
   Figure 2; the largest difference of the moments in units of the SD.
2. **Online cost per frame.** Figure 2's point tracked for many frames by
   :func:`depthcore.exact.posterior.update`, a batch of trials at once; the mean time of
   one update in windows of frames, re-placements of the nodes included.
3. **Many trials.** 10,000 trials of 30 frames: :func:`depthcore.exact.posterior.posterior`
   at frame 3 and :func:`depthcore.exact.posterior.update` for each later frame (the
   exact filter at every frame), against the target of 10 s on one core.
4. **Against particles.** The causal particle filter with resample-move
   (:mod:`depthcore.particles.resample_move`) on 10 frames: the root-mean-square error
   of its depth mean against the bank's, in units of the exact SD, over
   independent runs, for growing particle counts, and its time per run. The
   ratio recorded is measured: the particle filter's time at the largest count
   over the bank's on the same trials (the bank exact, the particle filter
   still in error). Beside it, labelled as an extrapolation: from the largest
   count as ``C / sqrt(M)`` (time growing like ``M``), the particles and time
   the particle filter would need for an error of 1e-3 SD.

Usage: ``python benchmarks/bench_bank.py [--quick]``; the full run writes its
record ``depthbook/provenance/benchmark_records/bench_bank.json``
(:mod:`depthbook.provenance.benchmarks`),
``--quick`` (smaller sizes) writes outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from depthbook.provenance import benchmarks
from depthcore.exact import optimal, posterior
from depthcore.particles import resample_move
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS

FIG2 = SCENARIOS["fig2"]
#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("exact.posterior", "exact.optimal", "particles.resample_move")
#: Targets of the four tables: bank / 1-D route at three frames, seconds for
#: 10,000 trials x 30 frames, particle filter / bank at matched accuracy.
TARGETS = {"three_frames_ratio": 2.0, "many_trials_s": 10.0, "matched_accuracy_ratio": 100.0}


def track(n_trials: int, n_frames: int, seed: int, q: float = 0.0):
    """Figure 2's point continued for ``n_frames`` frames: bearings (B, N) and the prior."""
    x1 = model.G(np.array(FIG2.c), -2)
    sim = model.simulate(
        x1, n_frames, FIG2.rho, q, np.random.default_rng(seed), size=n_trials, frame=1
    )
    return sim.mu, FIG2.prior


def best_of(f, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def three_frames(n_trials: int) -> dict:
    mu, prior = track(n_trials, 3, seed=1)
    args = (mu, FIG2.rho, prior.mean, prior.cov)
    t_one = best_of(lambda: optimal.moments(*args))
    t_bank = best_of(lambda: posterior.moments(*args))
    a, b = optimal.moments(*args), posterior.moments(*args)
    diff = max(
        np.max(np.abs(a.depth_mean - b.depth_mean) / a.depth_sd),
        np.max(np.abs(a.depth_sd - b.depth_sd) / a.depth_sd),
        np.max(np.abs(a.velocity_mean - b.velocity_mean) / a.velocity_sd),
        np.max(np.abs(a.velocity_sd - b.velocity_sd) / a.velocity_sd),
    )
    print(f"\n1. Three frames, {n_trials} trials of Figure 2 (target: bank <= 2x the 1-D route)")
    print(f"{'route':<34}{'ms per trial':>14}")
    print(f"{'1-D route, Eqs. (14)-(16)':<34}{1e3 * t_one / n_trials:>14.3f}")
    print(f"{'bank of Kalman filters':<34}{1e3 * t_bank / n_trials:>14.3f}")
    print(f"ratio bank / 1-D: {t_bank / t_one:.2f}; largest difference: {diff:.1e} SD")
    return {
        "trials": n_trials,
        "one_d_ms_per_trial": 1e3 * t_one / n_trials,
        "bank_ms_per_trial": 1e3 * t_bank / n_trials,
        "ratio": t_bank / t_one,
        "difference_sd": float(diff),
    }


def online(n_trials: int, n_frames: int) -> dict:
    mu, prior = track(n_trials, n_frames, seed=2)
    post = posterior.posterior(mu[:, :3], FIG2.rho, prior.mean, prior.cov)
    edges = [3, 10, 30, 100, 300, 1000, 3000]
    edges = [e for e in edges if e < n_frames] + [n_frames]
    print(f"\n2. Online cost of one frame, {n_trials} trials tracked (target: flat)")
    print(f"{'frames':<14}{'ms per update':>15}{'ratio':>8}{'nodes':>8}{'depth SD':>11}")
    first = None
    windows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        t = time.perf_counter()
        for k in range(lo, hi):
            post = posterior.update(post, mu[:, k])
        per = (time.perf_counter() - t) / (hi - lo)
        first = first or per
        nodes = int(np.median(np.sum(post.probabilities > 0, axis=-1)))
        sd = float(np.median(post.depth_sd))
        print(f"{f'{lo + 1}-{hi}':<14}{1e3 * per:>15.2f}{per / first:>8.2f}{nodes:>8}{sd:>11.4f}")
        windows.append(
            {
                "first_frame": lo + 1,
                "last_frame": hi,
                "ms_per_update": 1e3 * per,
                "ratio_to_first": per / first,
                "median_nodes": nodes,
                "median_depth_sd": sd,
            }
        )
    return {"trials": n_trials, "frames": n_frames, "windows": windows}


def many_trials(n_trials: int, n_frames: int) -> dict:
    mu, prior = track(n_trials, n_frames, seed=3)

    def run():
        post = posterior.posterior(mu[:, :3], FIG2.rho, prior.mean, prior.cov)
        for k in range(3, n_frames):
            post = posterior.update(post, mu[:, k])
        return post

    t = time.perf_counter()
    post = run()
    elapsed = time.perf_counter() - t
    worst = float(np.max(post.depth_error / post.depth_sd))
    print(f"\n3. {n_trials} trials x {n_frames} frames, the exact filter at every frame")
    print(f"time: {elapsed:.2f} s (target: under 10 s on one core); worst error {worst:.1e} SD")
    return {
        "trials": n_trials,
        "frames": n_frames,
        "time_s": elapsed,
        "target_s": TARGETS["many_trials_s"],
        "worst_error_estimate_sd": worst,
    }


def matched_accuracy(n_trials: int, counts, replicas: int) -> dict:
    N = 10
    mu, prior = track(n_trials, N, seed=4)
    args = (mu, FIG2.rho, prior.mean, prior.cov)
    t_bank = best_of(lambda: posterior.moments(*args))
    exact = posterior.moments(*args)
    print(f"\n4. Matched accuracy, {n_trials} trials of {N} frames (target: bank >= 100x faster)")
    print(f"{'particles':>10}{'RMSE / SD':>12}{'s per run':>11}")
    seeds = np.random.SeedSequence(5).spawn(len(counts) * replicas)
    errors, times = [], []
    for i, M in enumerate(counts):
        sq, elapsed = [], 0.0
        for r in range(replicas):
            rng = np.random.default_rng(seeds[i * replicas + r])
            t = time.perf_counter()
            out = resample_move.run(*args, n_particles=M, rng=rng).moments()
            elapsed += time.perf_counter() - t
            sq.append(((out["depth_mean"] - exact.depth_mean) / exact.depth_sd) ** 2)
        rmse = float(np.sqrt(np.mean(sq)))
        errors.append(rmse)
        times.append(elapsed / replicas)
        print(f"{M:>10}{rmse:>12.2e}{elapsed / replicas:>11.3f}")
    # Measured side by side: the particle filter at its largest count against the bank,
    # on the same trials, with the error the particle filter reached there.
    measured = times[-1] / t_bank
    print(
        f"measured at {counts[-1]} particles: error {errors[-1]:.2e} SD, "
        f"{times[-1]:.3f} s per run; bank {t_bank:.3f} s; ratio {measured:.3g}"
    )
    # An extrapolation, labelled as such: error = C / sqrt(M) and time = D M from the
    # largest count (the smaller ones may not yet be in the 1 / sqrt(M) regime).
    C = errors[-1] * np.sqrt(counts[-1])
    D = times[-1] / counts[-1]
    needed = (C / 1e-3) ** 2
    t_pf = D * needed
    print(
        f"extrapolated to 1e-3 SD: {needed:.3g} particles, {t_pf:.3g} s, "
        f"ratio {t_pf / t_bank:.3g} (an extrapolation, not a measurement)"
    )
    return {
        "trials": n_trials,
        "frames": N,
        "replicas": replicas,
        "particles": list(counts),
        "error_sd": errors,
        "time_per_run_s": times,
        "bank_time_s": t_bank,
        "ratio": float(measured),
        "target_ratio": TARGETS["matched_accuracy_ratio"],
        "target_error_sd": 1e-3,
        "extrapolated_particles_needed": float(needed),
        "extrapolated_time_s": float(t_pf),
        "extrapolated_ratio": float(t_pf / t_bank),
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="smaller sizes (a check that it runs)")
    a = p.parse_args(argv)
    if a.quick:
        sizes = {"three_frames": 200, "online": (20, 100), "many_trials": (200, 30)}
        sizes["matched_accuracy"] = (5, (250, 1000), 2)
    else:
        sizes = {"three_frames": 2000, "online": (100, 1000), "many_trials": (10_000, 30)}
        sizes["matched_accuracy"] = (20, (1000, 4000, 16000), 4)
    n, counts, replicas = sizes["matched_accuracy"]
    results = {
        "three_frames": three_frames(sizes["three_frames"]),
        "online": online(*sizes["online"]),
        "many_trials": many_trials(*sizes["many_trials"]),
        "matched_accuracy": matched_accuracy(n, counts, replicas=replicas),
        "targets": TARGETS,
    }
    recorded = {
        "three_frames_trials": sizes["three_frames"],
        "online_trials_and_frames": list(sizes["online"]),
        "many_trials_trials_and_frames": list(sizes["many_trials"]),
        "matched_accuracy_trials": n,
        "matched_accuracy_particles": list(counts),
        "matched_accuracy_replicas": replicas,
    }
    path = benchmarks.write(__file__, MEASURES, recorded, results, full=not a.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
