"""Benchmark: the optimal filter's depth and velocity moments for Figures 2-6.

Measures, side by side in one run, on one core:

* the 1-D route of :func:`depthcore.exact.optimal.moments` (Eqs. (14)-(16)), all five
  scenarios in one batch, at the default tolerance;
* a dense 3-D Gauss-Legendre grid over Eq. (6) itself
  (:func:`depthbook.reference.grid_moments`), refined until it agrees with
  its next refinement to 1e-8 of each SD;
* with ``--nquad``, scipy's adaptive ``nquad`` on Eq. (6) for one integral
  (the normaliser of Figure 2) at ``epsrel=1e-9``; the full set (five
  integrals per scenario, five scenarios) is that time multiplied by 25,
  marked as extrapolated;

and, per triple of measurements on Figures 2, 3, 5 and 6 (Figure 4 shares
Figure 2's problem), the cost of the paper's three filters, each the least
time of ``--repeat`` calls, made in five rounds that interleave the filters and
the scenarios: the optimal filter's moments
(:func:`depthcore.exact.optimal.moments`, Eqs. (13)-(16)), the second-order
approximation (:func:`depthcore.kalman.second_order.run`, Eqs. (7)-(8)) and
the EKF (:func:`depthcore.kalman.ekf.run`, Eqs. (10)-(12)), with the optimal
filter's quadrature nodes in the depth and the evaluations of Eq. (6) that
the brute-force grid (:func:`depthbook.reference.grid_moments`, its default
rule) spends on the same triple.

Accuracy is the largest difference, over scenarios and over the depth and
velocity means and SDs, from the 1-D route at ``rtol=1e-13``, divided by
the SD. Usage: ``python benchmarks/bench_optimal.py [--quick]``; the full run
writes its record ``depthbook/provenance/benchmark_records/bench_optimal.json``
(:mod:`depthbook.provenance.benchmarks`), ``--quick`` (no ``nquad``, fewer repeats) writes
outside the committed records.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
from scipy import integrate  # noqa: E402

from depthbook import reference
from depthbook.provenance import benchmarks
from depthcore.exact import optimal
from depthcore.kalman import ekf, second_order
from depthcore.problem.scenarios import SCENARIOS

#: The depthcore modules this benchmark measures (fingerprinted in its record).
MEASURES = ("exact.optimal", "depthbook.reference", "kalman.second_order", "kalman.ekf")
#: The scenarios of the per-triple table (Figure 4 shares Figure 2's problem).
TRIPLE_KEYS = ("fig2", "fig3", "fig5", "fig6")
LADDER = [(50, 12), (100, 16), (150, 20), (200, 24), (300, 28), (400, 32), (600, 40)]


def _inputs():
    keys = list(SCENARIOS)
    mus = np.array([SCENARIOS[k].mu for k in keys])
    rhos = np.array([SCENARIOS[k].rho for k in keys])
    means = np.array([SCENARIOS[k].prior.mean for k in keys])
    return keys, mus, rhos, means, 1000.0 * np.eye(3)


def _best_time(fn, repeat):
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def _as_array(m):
    return np.array([m.depth_mean, m.depth_sd, m.velocity_mean, m.velocity_sd]).T  # (5, 4)


def _rel_error(values, truth):
    sd = truth[:, [1, 1, 3, 3]]
    return float(np.max(np.abs(values - truth) / sd))


def _grid(keys, panels, order):
    return np.array(
        [
            list(
                reference.grid_moments(
                    SCENARIOS[k].mu,
                    SCENARIOS[k].rho,
                    SCENARIOS[k].prior,
                    panels=panels,
                    uv_order=order,
                )
            )[:4]
            for k in keys
        ]
    )


def _nquad_normaliser():
    """Normaliser of Eq. (6) for Figure 2 by nested adaptive quadrature."""
    s = SCENARIOS["fig2"]
    mu, rho, pm = np.array(s.mu), s.rho, s.prior.mean
    q = 1.0 / s.prior.cov[0, 0]

    def log_post(v, x, y):  # Eq. (6), scalar, with P = 1000 I
        r3, r2, r1 = x / y - mu[2], (x - v) / (y - 1) - mu[1], (x - 2 * v) / (y - 2) - mu[0]
        d0, d1, d2 = x - 2 * v - pm[0], y - 2 - pm[1], v - pm[2]
        return -(r1 * r1 + r2 * r2 + r3 * r3) / (2 * rho * rho) - 0.5 * q * (
            d0 * d0 + d1 * d1 + d2 * d2
        )

    shift = log_post(1.2, 1.2, 6.0)
    # Integration box: bearing x / y in [mu3 - 0.2, mu3 + 0.2], v within +-3 of x / y * y
    box = [
        lambda x, y: (x - 3.0, x + 3.0),
        lambda y: ((mu[2] - 0.2) * y, (mu[2] + 0.2) * y),
        (2.2, 60.0),
    ]
    opts = {"epsrel": 1e-9, "epsabs": 0, "limit": 200}
    z, _ = integrate.nquad(
        lambda v, x, y: math.exp(log_post(v, x, y) - shift),
        box,
        opts=[opts, opts, {**opts, "points": [6.0]}],
    )
    # The same integral from the 1-D route: 2 pi exp(log_normaliser), since the
    # inner Gaussian integral over (x, v) is 2 pi / sqrt(det M) exp(-S / 2).
    exact = (
        2
        * math.pi
        * math.exp(optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov).log_normaliser - shift)
    )
    return abs(z / exact - 1.0)


def per_triple(repeat, rounds=5):
    """Least time of ``repeat`` calls of each filter on each scenario, nodes, brute-force cost.

    The calls run in ``rounds`` interleaved rounds (every filter on every scenario
    in each), so that a slow spell of the machine cannot fall on one filter's calls alone.
    """
    calls = {
        "optimal": lambda s: optimal.moments(np.array([s.mu]), s.rho, s.prior.mean, s.prior.cov),
        "second_order": lambda s: second_order.run(s.mu, s.rho, s.prior.mean, s.prior.cov),
        "ekf": lambda s: ekf.run(s.mu, s.rho, s.prior.mean, s.prior.cov),
    }
    scenarios = [SCENARIOS[k] for k in TRIPLE_KEYS]
    out = {"keys": list(TRIPLE_KEYS)}
    best = {name: [math.inf] * len(scenarios) for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            for i, s in enumerate(scenarios):
                t = _best_time(lambda s=s, call=call: call(s), max(1, repeat // rounds))[0]
                best[name][i] = min(best[name][i], t)
    for name in calls:
        out[f"{name}_ms"] = [1e3 * t for t in best[name]]
    out["nodes"] = [optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov).n_nodes for s in scenarios]
    out["brute_force_evaluations"] = [
        reference.grid_moments(s.mu, s.rho, s.prior).n_evaluations for s in scenarios
    ]
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="no nquad, fewer repeats (not recorded)")
    args = p.parse_args(argv)
    args.nquad, args.repeat = not args.quick, 5 if args.quick else 50

    keys, mus, rhos, means, cov = _inputs()
    truth = _as_array(optimal.moments(mus, rhos, means, cov, rtol=1e-13))
    t_ours, ours = _best_time(lambda: optimal.moments(mus, rhos, means, cov), args.repeat)
    est = float(
        np.max(np.maximum(ours.depth_error / ours.depth_sd, ours.velocity_error / ours.velocity_sd))
    )
    err_ours = _rel_error(_as_array(ours), truth)

    previous, chosen = None, None
    for panels, order in LADDER:
        t, vals = _best_time(lambda p=panels, o=order: _grid(keys, p, o), 1)
        if previous is not None and _rel_error(previous[2], vals) <= 1e-8:
            chosen = previous
            break
        previous = (panels, order, vals, t)
    if chosen is None:
        raise SystemExit("the grid did not reach 1e-8 on the ladder")
    panels, order, vals, _ = chosen
    t_grid, vals = _best_time(lambda: _grid(keys, panels, order), 3)
    err_grid = _rel_error(vals, truth)
    moments = {
        "one_d_ms": 1e3 * t_ours,
        "one_d_error_sd": err_ours,
        "one_d_estimate_sd": est,
        "grid_panels": panels,
        "grid_order": order,
        "grid_ms": 1e3 * t_grid,
        "grid_error_sd": err_grid,
        "grid_ratio": t_grid / t_ours,
    }

    rows = [
        (
            "1-D route, Eqs. (14)-(16), one batch",
            f"{t_ours * 1e3:.2f} ms",
            f"{err_ours:.1e} (estimate {est:.1e})",
            "1",
        )
    ]
    rows.append(
        (
            f"3-D Gauss-Legendre grid of Eq. (6) ({panels} x 8 depth, {order}^2 (x, v) nodes)",
            f"{t_grid * 1e3:.0f} ms",
            f"{err_grid:.1e}",
            f"{t_grid / t_ours:,.0f}",
        )
    )
    if args.nquad:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", integrate.IntegrationWarning)
            t_nq, err_nq = _best_time(_nquad_normaliser, 1)
        total = 25 * t_nq
        moments.update(
            nquad_one_integral_s=t_nq,
            nquad_relative_error=err_nq,
            nquad_ratio=t_nq / t_ours,
            nquad_all_s=total,
            nquad_all_ratio=total / t_ours,
        )
        rows.append(
            (
                "scipy nquad of Eq. (6), epsrel 1e-9: 1 integral (Figure 2's normaliser)",
                f"{t_nq:.1f} s",
                f"{err_nq:.1e} (relative)",
                f"{t_nq / t_ours:,.0f}",
            )
        )
        rows.append(
            (
                "  x 25 integrals (5 moments x 5 scenarios), extrapolated",
                f"{total:.0f} s",
                "-",
                f"{total / t_ours:,.0f}",
            )
        )

    print(
        f"Optimal depth and velocity moments, Figures 2-6 ({len(keys)} scenarios, "
        "4 moments each), one core"
    )
    widths = [
        max(len(r[i]) for r in rows + [("route", "time", "rel. error / SD", "ratio")])
        for i in range(4)
    ]
    head = ("route", "time", "rel. error / SD", "ratio")
    fmt = f"| {{:<{widths[0]}}} | {{:>{widths[1]}}} | {{:>{widths[2]}}} | {{:>{widths[3]}}} |"
    print(fmt.format(*head))
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for r in rows:
        print(fmt.format(*r))

    triple = per_triple(args.repeat)
    print(
        f"\nThe paper's filters per triple of measurements, least of {args.repeat} calls, one core"
    )
    print("| figure | optimal | second order | EKF | optimal / EKF | nodes | brute force |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for i, key in enumerate(triple["keys"]):
        t_o, t_s, t_e = (triple[f"{n}_ms"][i] for n in ("optimal", "second_order", "ekf"))
        print(
            f"| {key} | {t_o:.3f} ms | {t_s:.3f} ms | {t_e:.3f} ms | {t_o / t_e:.1f} "
            f"| {triple['nodes'][i]} | {triple['brute_force_evaluations'][i]:,} |"
        )
    sizes = {
        "scenarios": keys,
        "repeat": args.repeat,
        "grid_repeat": 3,
        "nquad": args.nquad,
        "triple_scenarios": list(TRIPLE_KEYS),
    }
    path = benchmarks.write(
        __file__, MEASURES, sizes, {"moments": moments, "per_triple": triple}, full=not args.quick
    )
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
