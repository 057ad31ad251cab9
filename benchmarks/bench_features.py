"""Benchmark: a thousand features at once through the batched exact filter and the batched EKF.

A camera moving forward through a scene of :data:`FEATURES` points in 3-D at depths 5
to 50 (each depth shrinking by :data:`STEP` per frame), each point seen as a pair
``(x / y, h / y)`` with noise of 1 to 2 pixels at a focal length of 500 (``rho``
0.002 to 0.004, one per feature), a few frames missed, the lateral and vertical
velocities random walks (process noise :data:`Q`). Each feature's prior at frame 1
comes from its first pair and a rough depth (within 30 per cent, SD 30 per cent of
it). :class:`depthcore.exact.features.Features` and
:class:`depthcore.kalman.features.Features` (the EKF) take the frames one at a time;
for each: the process's CPU time per frame (one thread) over :data:`FRAMES` frames,
and their ratio, against the target :data:`TARGET_MS` for the exact filter. The
accuracy: over :data:`CHECKED` features and every frame, the largest difference of
the batched exact filter's depth mean and SD from :class:`depthcore.exact.online.Online`
at ``rtol = 1e-10``, in units of that filter's depth SD. A plane line (bearings only,
the same points) is timed alike.

Usage: ``python benchmarks/bench_features.py [--quick]``; the full run writes its
record ``depthbook/provenance/benchmark_records/bench_features.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (200 features, 40 frames) writes
outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from depthbook.provenance import benchmarks  # noqa: E402
from depthcore.exact import features as exact_features  # noqa: E402
from depthcore.exact.online import Online  # noqa: E402
from depthcore.kalman import features as kalman_features  # noqa: E402

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = (
    "exact.features",
    "exact.online",
    "exact.online_nodes",
    "kalman.features",
    "kalman.spatial",
    "kalman.ekf",
    "problem.predictive",
)
#: Features, frames, the depth's change per frame (the camera approaches), noise levels.
FEATURES, FRAMES, STEP, Q = 1_000, 120, -0.04, 1e-3
#: The fraction of frames without a detection, per feature.
MISSING = 0.05
#: The features checked against the full-accuracy online filter.
CHECKED = 20
#: The exact 3-D batch's target, milliseconds per frame.
TARGET_MS = 33.0
SEED = 5


def scene(B: int, N: int):
    """Pairs (B, N, 2) with NaN rows where missed, noise SDs (B,), priors (B, 5), (B, 5, 5)."""
    rng = np.random.default_rng(SEED)
    y1 = rng.uniform(5.0, 50.0, B)
    x1, h1 = rng.uniform(-0.5, 0.5, B) * y1, rng.uniform(-0.4, 0.4, B) * y1
    v = np.cumsum(np.concatenate([rng.normal(0, 0.05, (B, 1)), rng.normal(0, Q, (B, N - 2))], 1), 1)
    w = np.cumsum(np.concatenate([rng.normal(0, 0.05, (B, 1)), rng.normal(0, Q, (B, N - 2))], 1), 1)
    x = x1[:, None] + np.concatenate([np.zeros((B, 1)), np.cumsum(STEP * v, 1)], 1)
    h = h1[:, None] + np.concatenate([np.zeros((B, 1)), np.cumsum(STEP * w, 1)], 1)
    y = y1[:, None] + STEP * np.arange(N)
    rho = rng.uniform(0.002, 0.004, B)
    pairs = np.stack([x / y, h / y], -1) + rho[:, None, None] * rng.normal(size=(B, N, 2))
    pairs[rng.uniform(size=(B, N)) < MISSING] = np.nan
    pairs[:, 0] = np.stack([x1 / y1, h1 / y1], -1) + rho[:, None] * rng.normal(size=(B, 2))
    m_y = y1 * rng.uniform(0.7, 1.3, B)
    s_y = 0.3 * m_y
    mu, nu = pairs[:, 0, 0], pairs[:, 0, 1]
    mean = np.stack([mu * m_y, m_y, np.zeros(B), nu * m_y, np.zeros(B)], 1)
    cov = np.zeros((B, 5, 5))
    cov[:, 1, 1] = s_y**2
    cov[:, 0, 1] = cov[:, 1, 0] = mu * s_y**2
    cov[:, 3, 1] = cov[:, 1, 3] = nu * s_y**2
    cov[:, 0, 3] = cov[:, 3, 0] = mu * nu * s_y**2
    cov[:, 0, 0] = mu**2 * s_y**2 + (4 * rho * m_y) ** 2
    cov[:, 3, 3] = nu**2 * s_y**2 + (4 * rho * m_y) ** 2
    cov[:, 2, 2] = cov[:, 4, 4] = 0.1**2
    return pairs, rho, mean, cov


def timed(f, obs, steps) -> tuple[float, list]:
    """Every frame through ``f``; the CPU milliseconds per frame and the estimates."""
    out = []
    t = time.process_time()
    for k in range(obs.shape[1]):
        out.append(f.update(obs[:, k], step=1.0 if k == 0 else steps))
    return 1e3 * (time.process_time() - t) / obs.shape[1], out


def accuracy(est, mean, cov, rho, obs, rows) -> dict:
    """The largest differences from the full-accuracy online filter, in its depth SDs."""
    worst_mean = worst_sd = 0.0
    for b in rows:
        f = Online(mean[b], cov[b], rho[b], Q, rtol=1e-10)
        for k in range(obs.shape[1]):
            e = f.update(obs[b, k], step=1.0 if k == 0 else STEP)
            worst_mean = max(worst_mean, abs(est[k].depth_mean[b] - e.depth_mean) / e.depth_sd)
            worst_sd = max(worst_sd, abs(est[k].depth_sd[b] - e.depth_sd) / e.depth_sd)
    return {"mean_difference_sd": worst_mean, "sd_difference_sd": worst_sd}


def measure(dim: int, pairs, rho, mean, cov) -> dict:
    """The batched exact filter and the batched EKF in 3-D (``dim`` 5) or the plane (3)."""
    B = len(rho)
    obs = pairs if dim == 5 else pairs[..., 0]
    mean, cov = mean[:, :dim], cov[:, :dim, :dim]
    steps = np.full(B, STEP)
    exact_features.Features(mean[:8], cov[:8], rho[:8], Q).update(obs[:8, 0])  # first use
    exact = exact_features.Features(mean, cov, rho, Q)
    exact_ms, est = timed(exact, obs, steps)
    ekf_ms, _ = timed(kalman_features.Features(mean, cov, rho, Q), obs, steps)
    rows = np.linspace(0, B - 1, CHECKED).astype(int)
    return {
        "features": B,
        "frames": obs.shape[1],
        "nodes": exact.nodes,
        "exact_ms": exact_ms,
        "ekf_ms": ekf_ms,
        "ratio": exact_ms / ekf_ms,
        "replacements_per_frame": float(exact.replacements.sum() / obs.shape[1]),
        "unresolved": int(exact.unresolved.sum()),
        **accuracy(est, mean, cov, rho, obs, rows),
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="200 features, 40 frames (not recorded)")
    a = p.parse_args(argv)
    B, N = (200, 40) if a.quick else (FEATURES, FRAMES)
    pairs, rho, mean, cov = scene(B, N)
    print(f"{B:,} features, {N} frames, step {STEP}, q {Q}; CPU ms per frame")
    print(f"{'':<6} {'exact':>8} {'EKF':>8} {'ratio':>6} {'mean':>9} {'SD':>9} {'re-placed':>9}")
    results = {"target_ms": TARGET_MS}
    for name, dim in (("space", 5), ("plane", 3)):
        r = measure(dim, pairs, rho, mean, cov)
        results[name] = r
        print(
            f"{name:<6} {r['exact_ms']:>8.2f} {r['ekf_ms']:>8.2f} {r['ratio']:>6.1f} "
            f"{r['mean_difference_sd']:>9.1e} {r['sd_difference_sd']:>9.1e} "
            f"{r['replacements_per_frame']:>9.1f}"
        )
    sizes = {"features": B, "frames": N, "step": STEP, "process_noise": Q, "checked": CHECKED}
    path = benchmarks.write(__file__, MEASURES, sizes, results, full=not a.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
