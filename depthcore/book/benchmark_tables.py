"""The benchmarks' recorded numbers as the book and the README print them.

Recommended import: ``from depthcore.book import benchmark_tables``.

:func:`bench_texts` gives one benchmark record's (:mod:`depthcore.provenance.benchmarks`)
numbers as texts, :func:`bench_tables` the tables of the costs chapter,
:func:`bench_blocks` every table with its notes (the page "Reproducing this book") and
:func:`bench_origin` the machine and date a record was measured on.
"""

from __future__ import annotations

import numpy as np

from depthcore.book.notebook import MarkdownTable
from depthcore.formatting import sci
from depthcore.problem.scenarios import SCENARIOS

# --- the benchmarks' records -----------------------------------------------------------------


def bench_origin(record: dict) -> str:
    """When and where a benchmark's record was measured, as the book states it.

    Parameters
    ----------
    record : dict
        From :func:`depthcore.provenance.benchmarks.read`.

    Returns
    -------
    str
        E.g. ``"2026-11-26 on 2 cores (AMD EPYC, family 25, model 17; scipy-openblas
        0.3.31.188.0, SkylakeX kernels), Python 3.11.7, NumPy 2.4.6, SciPy 1.17.1"``
    """
    m = record["machine"]
    return (
        f"{record['date'][:10]} on {m['cores']} cores ({m['cpu']}, {m['processor']}; "
        f"{m['blas']}), Python {m['python']}, "
        f"NumPy {m['numpy']}, SciPy {m['scipy']}"
    )


def _optimal_bench_texts(r: dict) -> dict[str, str]:
    m, t = r["results"]["moments"], r["results"]["per_triple"]
    out = {
        "one_d_ms": f"{m['one_d_ms']:.2f}",
        "one_d_error": sci(m["one_d_error_sd"]),
        "one_d_estimate": sci(m["one_d_estimate_sd"]),
        "grid_rule": f"{m['grid_panels']} x 8 depth, {m['grid_order']}^2 (x, v) nodes",
        "grid_ms": f"{m['grid_ms']:.0f}",
        "grid_error": sci(m["grid_error_sd"]),
        "grid_ratio": f"{m['grid_ratio']:,.0f}",
    }
    if "nquad_one_integral_s" in m:
        out.update(
            nquad_s=f"{m['nquad_one_integral_s']:.1f}",
            nquad_error=sci(m["nquad_relative_error"]),
            nquad_ratio=f"{m['nquad_ratio']:,.0f}",
            nquad_all_s=f"{m['nquad_all_s']:.0f}",
            nquad_all_ratio=f"{m['nquad_all_ratio']:,.0f}",
        )
    opt, so, ekf = (np.array(t[f"{n}_ms"]) for n in ("optimal", "second_order", "ekf"))
    nodes, brute = np.array(t["nodes"]), np.array(t["brute_force_evaluations"])
    for i, key in enumerate(t["keys"]):
        out[f"{key}_figure"] = f"Figure {SCENARIOS[key].figure}"
        out[f"{key}_optimal_ms"] = f"{opt[i]:.3f}"
        out[f"{key}_second_order_ms"] = f"{so[i]:.3f}"
        out[f"{key}_ekf_ms"] = f"{ekf[i]:.3f}"
        out[f"{key}_optimal_ekf"] = f"{opt[i] / ekf[i]:.1f}"
        out[f"{key}_second_order_ekf"] = f"{so[i] / ekf[i]:.2f}"
        out[f"{key}_optimal_second_order"] = f"{opt[i] / so[i]:.1f}"
        out[f"{key}_nodes"] = f"{nodes[i]}"
        out[f"{key}_brute"] = f"{brute[i]:,}"
    for name, ratio, fmt in (
        ("optimal_ekf", opt / ekf, ".1f"),
        ("second_order_ekf", so / ekf, ".2f"),
        ("optimal_second_order", opt / so, ".1f"),
    ):
        out[f"{name}_min"], out[f"{name}_max"] = (format(f(ratio), fmt) for f in (np.min, np.max))
    out["nodes_min"], out["nodes_max"] = f"{nodes.min()}", f"{nodes.max()}"
    out["brute_max"] = f"{brute.max():,}"
    out["brute_per_node"] = f"{brute.min() / nodes.max():,.0f}"
    return out


def _trials_bench_texts(r: dict) -> dict[str, str]:
    x, s = r["results"], r["sizes"]
    return {
        "trials": f"{s['trials']:,}",
        "timed": f"{s['timed_one_by_one']}",
        "vectorised_s": f"{x['vectorised_s']:.2f}",
        "per_trial_ms": f"{1e3 * x['vectorised_s'] / s['trials']:.3f}",
        "loop_s": f"{x['trial_by_trial_s']:.2f}",
        "ratio": f"{x['ratio']:.1f}",
        "estimate": sci(x["estimate_sd"]),
        "difference": sci(x["difference_sd"]),
    }


def _ekf_bench_texts(r: dict) -> dict[str, str]:
    x = r["results"]
    return {
        "trials": f"{r['sizes']['trials']:,}",
        "depthcore_ms": f"{x['depthcore_ms']:.1f}",
        "filterpy_ms": f"{x['filterpy_ms']:,.0f}",
        "ratio": f"{x['ratio']:,.0f}",
        "ratio_min": f"{x['ratio_min']:,.0f}",
        "ratio_max": f"{x['ratio_max']:,.0f}",
        "pairs": f"{r['sizes']['pairs']}",
        "mean_difference": sci(x["mean_difference_sd"]),
        "cov_max": sci(x["covariance_difference_max"]),
        "cov_median": sci(x["covariance_difference_median"]),
    }


def _kalman_bench_texts(r: dict) -> dict[str, str]:
    x = r["results"]
    return {
        "steps": f"{r['sizes']['steps']:,}",
        "pairs": f"{r['sizes']['pairs']}",
        "depthcore_ms": f"{x['depthcore_ms']:.1f}",
        "filterpy_ms": f"{x['filterpy_ms']:.1f}",
        "ratio": f"{x['ratio']:.2f}",
        "ratio_min": f"{x['ratio_min']:.2f}",
        "ratio_max": f"{x['ratio_max']:.2f}",
        "mean_difference": sci(x["mean_difference_sd"]),
        "cov_max": sci(x["covariance_difference_max"]),
    }


def _frames_bench_texts(r: dict) -> dict[str, str]:
    x = r["results"]
    out = {
        "trials": f"{r['sizes']['trials']}",
        "q": f"{r['sizes']['process_noise']:g}",
        "n_filters": f"{len(x['filters'])}",
        "growth_max": f"{max(row['growth'] for row in x['filters']):.2f}",
    }
    for j, n in enumerate(x["frames"]):
        out[f"n_{j}"] = f"{n:,}"
    for i, row in enumerate(x["filters"]):
        out[f"{i}_filter"] = row["filter"] + (
            f" ({row['options']['n_particles']:,} particles)" if row["options"] else ""
        )
        out[f"{i}_q"] = f"{row['process_noise']:g}"
        for j, t in enumerate(row["ms_per_trial"]):
            out[f"{i}_{j}_ms"] = f"{t:,.1f}"
        out[f"{i}_growth"] = f"{row['growth']:.2f}"
    return out


def _import_bench_texts(r: dict) -> dict[str, str]:
    x = r["results"]
    return {
        "numpy_s": f"{x['numpy_s']:.3f}",
        "depthcore_s": f"{x['depthcore_after_numpy_s']:.3f}",
        "target_s": f"{x['target_s']:.2f}",
        "runs": f"{r['sizes']['runs']}",
    }


def _bank_bench_texts(r: dict) -> dict[str, str]:
    x = r["results"]
    three, online, many, matched = (
        x[k] for k in ("three_frames", "online", "many_trials", "matched_accuracy")
    )
    out = {
        "three_trials": f"{three['trials']:,}",
        "three_one_d_ms": f"{three['one_d_ms_per_trial']:.3f}",
        "three_bank_ms": f"{three['bank_ms_per_trial']:.3f}",
        "three_ratio": f"{three['ratio']:.2f}",
        "three_difference": sci(three["difference_sd"]),
        "three_target": f"{x['targets']['three_frames_ratio']:g}",
        "online_trials": f"{online['trials']:,}",
        "online_frames": f"{online['frames']:,}",
        "online_windows": f"{len(online['windows'])}",
        "many_trials": f"{many['trials']:,}",
        "many_frames": f"{many['frames']}",
        "many_s": f"{many['time_s']:.1f}",
        "many_target_s": f"{many['target_s']:g}",
        "many_met": "met" if many["time_s"] < many["target_s"] else "not met",
        "many_worst": sci(many["worst_error_estimate_sd"]),
        "matched_trials": f"{matched['trials']}",
        "matched_frames": f"{matched['frames']}",
        "matched_replicas": f"{matched['replicas']}",
        "matched_bank_s": f"{matched['bank_time_s']:.3f}",
        "matched_ratio": f"{matched['ratio']:,.0f}",
        "matched_target_ratio": f"{matched['target_ratio']:g}",
        "matched_largest": f"{matched['particles'][-1]:,}",
        "matched_largest_s": f"{matched['time_per_run_s'][-1]:.2f}",
        "matched_largest_error": sci(matched["error_sd"][-1], 2),
        "matched_target_error": sci(matched["target_error_sd"], 0),
        "matched_extrapolated_needed": sci(matched["extrapolated_particles_needed"]),
        "matched_extrapolated_s": sci(matched["extrapolated_time_s"]),
        "matched_extrapolated_ratio": sci(matched["extrapolated_ratio"]),
    }
    per = np.array([w["ms_per_update"] for w in online["windows"]])
    for i, w in enumerate(online["windows"]):
        out[f"online_{i}_frames"] = f"{w['first_frame']}–{w['last_frame']}"
        out[f"online_{i}_ms"] = f"{w['ms_per_update']:.2f}"
        out[f"online_{i}_ratio"] = f"{w['ratio_to_first']:.2f}"
        out[f"online_{i}_nodes"] = f"{w['median_nodes']}"
        out[f"online_{i}_sd"] = f"{w['median_depth_sd']:.4f}"
    out["online_max_ratio"] = f"{per.max() / per.min():.1f}"
    for i, (m, e, t) in enumerate(
        zip(matched["particles"], matched["error_sd"], matched["time_per_run_s"], strict=True)
    ):
        out[f"matched_{i}_particles"] = f"{m:,}"
        out[f"matched_{i}_error"] = sci(e, 2)
        out[f"matched_{i}_s"] = f"{t:.2f}"
    return out


def _rbpf_bench_texts(r: dict) -> dict[str, str]:
    x = r["results"]
    out = {"repeats": f"{r['sizes']['repeats']}"}
    for i, row in enumerate(x["equal_cost"]):
        p = f"equal_{i}"
        out[f"{p}_problem"] = row["problem"]
        out[f"{p}_rbpf_particles"] = f"{row['rbpf_particles']:,}"
        out[f"{p}_rbpf_s"] = f"{row['rbpf_time_s']:.2f}"
        out[f"{p}_rbpf_error"] = f"{row['rbpf_error_sd']:.4f}"
        out[f"{p}_rm_particles"] = f"{row['resample_move_particles']:,}"
        out[f"{p}_rm_s"] = f"{row['resample_move_time_s']:.2f}"
        out[f"{p}_rm_error"] = f"{row['resample_move_error_sd']:.4f}"
        out[f"{p}_ratio"] = f"{row['error_ratio']:.1f}"
    times = [r["resample_move_time_s"] / r["rbpf_time_s"] for r in x["equal_cost"]]
    out["equal_time_ratio_min"], out["equal_time_ratio_max"] = (
        f"{f(times):.1f}" for f in (min, max)
    )
    for i, row in enumerate(x["convergence"]):
        p = f"conv_{i}"
        out[f"{p}_problem"] = row["problem"]
        out[f"{p}_particles"] = f"{row['particles']:,}"
        out[f"{p}_s"] = f"{row['time_s']:.2f}"
        out[f"{p}_error"] = f"{row['error_sd']:.4f}"
        out[f"{p}_se"] = f"{row['standard_error_sd']:.4f}"
        out[f"{p}_scaled"] = f"{row['error_times_sqrt_particles_sd']:.2f}"
    return out


#: The problems of ``bench_range_ekf`` and how the tables name them.
_RANGE_EKF_PROBLEMS = {"fig2": "Figure 2 (3 frames)", "ten_frames": "a 10-frame track"}


def _range_ekf_bench_texts(record: dict) -> dict[str, str]:
    out = {}
    for key, label in _RANGE_EKF_PROBLEMS.items():
        r = record["results"][key]
        for tol in ("1e-02", "1e-03"):
            row = r[tol]
            p = f"{key}_{tol}"
            out[f"{p}_problem"] = label
            out[f"{p}_tolerance"] = f"{float(tol):g}"
            out[f"{p}_components"] = f"{row['components']:,}"
            out[f"{p}_range_ms"] = f"{row['range_ekf_ms']:.1f}"
            out[f"{p}_bank_ms"] = f"{row['bank_ms']:.1f}"
            out[f"{p}_ratio"] = f"{row['ratio']:.1f}"
    return out


#: Each benchmark's prefix of glued names and the function that formats its record.
_BENCH_TEXTS = {
    "bench_range_ekf": ("rekf", _range_ekf_bench_texts),
    "bench_optimal": ("opt", _optimal_bench_texts),
    "bench_trials": ("trials", _trials_bench_texts),
    "bench_ekf_filterpy": ("ekfpy", _ekf_bench_texts),
    "bench_import": ("import", _import_bench_texts),
    "bench_bank": ("bank", _bank_bench_texts),
    "bench_rbpf": ("rbpf", _rbpf_bench_texts),
    "bench_kalman": ("kalmanpy", _kalman_bench_texts),
    "bench_frames": ("frames", _frames_bench_texts),
}


def bench_texts(name: str, record: dict) -> dict[str, str]:
    """The numbers of a benchmark's record as the book and the README print them.

    Parameters
    ----------
    name : str
        The benchmark, e.g. ``"bench_optimal"``.
    record : dict
        Its record, from :func:`depthcore.provenance.benchmarks.read`.

    Returns
    -------
    dict of str to str
        ``"<prefix>_<quantity>"`` -> text, the prefix ``opt``, ``trials``,
        ``ekfpy``, ``import``, ``bank``, ``rbpf``, ``kalmanpy``, ``frames`` or
        ``rekf``;
        ``"<prefix>_origin"`` is :func:`bench_origin`. Times are in the unit that
        their record's key ends with.
    """
    if name not in _BENCH_TEXTS:
        raise ValueError(f"name must be one of {sorted(_BENCH_TEXTS)}, got {name!r}")
    prefix, texts = _BENCH_TEXTS[name]
    out = {f"{prefix}_{k}": v for k, v in texts(record).items()}
    out[f"{prefix}_origin"] = bench_origin(record)
    return out


def bench_tables(records: dict) -> dict[str, MarkdownTable]:
    """The benchmarks' tables, from the records.

    Parameters
    ----------
    records : dict
        ``{name: record}`` for every benchmark of :func:`bench_texts`.

    Returns
    -------
    dict of str to MarkdownTable
        ``"optimal"``, ``"per_triple"``, ``"ekf"``, ``"trials"``, ``"bank"``,
        ``"rbpf_equal_cost"``, ``"rbpf_convergence"``, ``"kalman"``, ``"frames"``,
        ``"range_ekf"``, ``"import"``.
    """
    t = {}
    for name, record in records.items():
        t.update(bench_texts(name, record))
    ms, s = " ms", " s"
    rows = [
        [
            "1-D route, Eqs. (14)–(16), one batch",
            t["opt_one_d_ms"] + ms,
            f"{t['opt_one_d_error']} (estimate {t['opt_one_d_estimate']})",
            "1",
        ],
        [
            f"3-D Gauss–Legendre grid of Eq. (6) ({t['opt_grid_rule']})",
            t["opt_grid_ms"] + ms,
            t["opt_grid_error"],
            t["opt_grid_ratio"],
        ],
    ]
    if "opt_nquad_s" in t:
        rows += [
            [
                "scipy nquad of Eq. (6), epsrel 1e-9: 1 integral (Figure 2's normaliser)",
                t["opt_nquad_s"] + s,
                f"{t['opt_nquad_error']} (relative)",
                t["opt_nquad_ratio"],
            ],
            [
                "x 25 integrals (5 moments x 5 scenarios), extrapolated",
                t["opt_nquad_all_s"] + s,
                "-",
                t["opt_nquad_all_ratio"],
            ],
        ]
    tables = {"optimal": MarkdownTable(["route", "time", "error / SD", "ratio"], rows)}
    keys = records["bench_optimal"]["results"]["per_triple"]["keys"]
    tables["per_triple"] = MarkdownTable(
        ["figure", "optimal", "second order", "EKF", "optimal / EKF", "nodes", "brute force"],
        [
            [
                t[f"opt_{k}_figure"],
                t[f"opt_{k}_optimal_ms"] + ms,
                t[f"opt_{k}_second_order_ms"] + ms,
                t[f"opt_{k}_ekf_ms"] + ms,
                t[f"opt_{k}_optimal_ekf"],
                t[f"opt_{k}_nodes"],
                t[f"opt_{k}_brute"],
            ]
            for k in keys
        ],
    )
    tables["ekf"] = MarkdownTable(
        ["route", "time", "ratio"],
        [
            ["depthcore.kalman.ekf.run, vectorised", t["ekfpy_depthcore_ms"] + ms, "1"],
            [
                "filterpy ExtendedKalmanFilter, trial by trial",
                t["ekfpy_filterpy_ms"] + ms,
                t["ekfpy_ratio"],
            ],
        ],
    )
    tables["trials"] = MarkdownTable(
        ["route", "time", "ratio"],
        [
            ["optimal.moments, vectorised over trials", t["trials_vectorised_s"] + s, "1"],
            [
                f"optimal.marginals, trial by trial ({t['trials_timed']} timed, scaled)",
                t["trials_loop_s"] + s,
                t["trials_ratio"],
            ],
        ],
    )
    n_windows = int(t["bank_online_windows"])
    windows = [f"bank_online_{i}" for i in range(n_windows)]
    tables["bank"] = MarkdownTable(
        ["measurement", "result", "target"],
        [
            [
                f"three frames, {t['bank_three_trials']} trials: bank against the 1-D route "
                "of Eqs. (14)–(16)",
                f"{t['bank_three_bank_ms']} against {t['bank_three_one_d_ms']} ms per trial "
                f"(ratio {t['bank_three_ratio']}), moments equal to "
                f"{t['bank_three_difference']} SD",
                f"at most {t['bank_three_target']}x",
            ],
            [
                f"one online update, {t['bank_online_trials']} trials, frames "
                + " / ".join(t[f"{w}_frames"] for w in windows),
                " / ".join(t[f"{w}_ms"] for w in windows)
                + " ms (re-placements of the nodes included)",
                "flat",
            ],
            [
                f"{t['bank_many_trials']} trials x {t['bank_many_frames']} frames, "
                "the exact filter at every frame",
                f"{t['bank_many_s']} s, worst error estimate {t['bank_many_worst']} SD",
                f"under {t['bank_many_target_s']} s ({t['bank_many_met']})",
            ],
            [
                "causal particle filter (resample-move), "
                f"{t['bank_matched_largest']} particles, {t['bank_matched_trials']} trials of "
                f"{t['bank_matched_frames']} frames, against the bank on the same trials",
                f"measured: {t['bank_matched_largest_s']} s at a depth-mean error of "
                f"{t['bank_matched_largest_error']} SD; the bank: {t['bank_matched_bank_s']} s, "
                f"exact (ratio {t['bank_matched_ratio']}). Extrapolated as C/sqrt(M) to "
                f"{t['bank_matched_target_error']} SD, not measured: "
                f"{t['bank_matched_extrapolated_needed']} particles, "
                f"{t['bank_matched_extrapolated_s']} s "
                f"(ratio {t['bank_matched_extrapolated_ratio']})",
                f"bank at least {t['bank_matched_target_ratio']}x faster (measured)",
            ],
        ],
    )
    n_equal = len(records["bench_rbpf"]["results"]["equal_cost"])
    n_conv = len(records["bench_rbpf"]["results"]["convergence"])
    tables["rbpf_equal_cost"] = MarkdownTable(
        [
            "problem",
            "RBPF particles",
            "RBPF time",
            "RBPF error",
            "resample-move particles",
            "resample-move time",
            "resample-move error",
            "error ratio",
        ],
        [
            [
                t[f"rbpf_equal_{i}_{k}"] + (s if k.endswith("_s") else "")
                for k in (
                    "problem",
                    "rbpf_particles",
                    "rbpf_s",
                    "rbpf_error",
                    "rm_particles",
                    "rm_s",
                    "rm_error",
                    "ratio",
                )
            ]
            for i in range(n_equal)
        ],
    )
    tables["rbpf_convergence"] = MarkdownTable(
        ["problem", "particles", "time", "RMS error", "SE of the average", "RMS error x sqrt(J)"],
        [
            [
                t[f"rbpf_conv_{i}_{k}"] + (s if k == "s" else "")
                for k in ("problem", "particles", "s", "error", "se", "scaled")
            ]
            for i in range(n_conv)
        ],
    )
    tables["kalman"] = MarkdownTable(
        ["route", "time", "ratio"],
        [
            [
                "depthcore kalman.run and fixed_interval_smoother",
                t["kalmanpy_depthcore_ms"] + ms,
                "1",
            ],
            [
                "filterpy KalmanFilter and rts_smoother",
                t["kalmanpy_filterpy_ms"] + ms,
                t["kalmanpy_ratio"],
            ],
        ],
    )
    frames = records["bench_frames"]["results"]
    tables["frames"] = MarkdownTable(
        ["filter", "q"]
        + [f"N = {t[f'frames_n_{j}']}" for j in range(len(frames["frames"]))]
        + ["growth per frame"],
        [
            [t[f"frames_{i}_filter"], t[f"frames_{i}_q"]]
            + [t[f"frames_{i}_{j}_ms"] + ms for j in range(len(frames["frames"]))]
            + [t[f"frames_{i}_growth"]]
            for i in range(len(frames["filters"]))
        ],
    )
    tables["range_ekf"] = MarkdownTable(
        ["problem", "depth mean and SD within", "components", "range EKF", "bank", "ratio"],
        [
            [
                t[f"rekf_{key}_{tol}_problem"],
                t[f"rekf_{key}_{tol}_tolerance"],
                t[f"rekf_{key}_{tol}_components"],
                t[f"rekf_{key}_{tol}_range_ms"] + ms,
                t[f"rekf_{key}_{tol}_bank_ms"] + ms,
                t[f"rekf_{key}_{tol}_ratio"],
            ]
            for key in _RANGE_EKF_PROBLEMS
            for tol in ("1e-02", "1e-03")
        ],
    )
    tables["import"] = MarkdownTable(
        ["import", "median time"],
        [
            ["numpy", t["import_numpy_s"] + s],
            ["depthcore, after numpy", t["import_depthcore_s"] + s],
        ],
    )
    return tables


def bench_blocks(records: dict) -> dict[str, str]:
    """Every benchmark table with its notes: each table of :func:`bench_tables` as a block.

    Parameters
    ----------
    records : dict
        ``{name: record}`` for every benchmark of :func:`bench_texts`.

    Returns
    -------
    dict of str to str
        The keys of :func:`bench_tables`; each block is Markdown: the table,
        then the sentences that quote the record's other numbers and where and
        when it was measured.
    """
    t = {}
    for name, record in records.items():
        t.update(bench_texts(name, record))
    notes = {
        "ekf": f"Times and ratio are medians over {t['ekfpy_pairs']} pairs timed alternately "
        f"(the pairs' ratios from {t['ekfpy_ratio_min']} to {t['ekfpy_ratio_max']}). "
        f"The two agree to {t['ekfpy_mean_difference']} posterior SDs in the means; "
        f"the covariances agree to {t['ekfpy_cov_median']} of their norm in the median "
        f"trial and {t['ekfpy_cov_max']} in the worst.",
        "trials": f"The largest error estimate is {t['trials_estimate']} of the SD; the "
        f"vectorised and single routes differ by {t['trials_difference']} SDs.",
        "kalman": f"Times and ratio are medians over {t['kalmanpy_pairs']} pairs timed "
        f"alternately (the pairs' ratios from {t['kalmanpy_ratio_min']} to "
        f"{t['kalmanpy_ratio_max']}); the smoothed means agree to "
        f"{t['kalmanpy_mean_difference']} SDs, the covariances to {t['kalmanpy_cov_max']} of "
        "their norm.",
        "range_ekf": "The fewest components (of a grid of four per doubling) whose mixture's "
        "depth mean and SD are within the tolerance, relative to the exact filter's, and the "
        "time of one call of each filter, the least of repeated calls, measured side by side.",
        "frames": f"Milliseconds per trial, the least of repeated calls on "
        f"{t['frames_trials']} trials; growth per frame: the cost per frame at the largest N "
        "over that at the smallest (1: linear growth).",
    }
    sources = {
        "optimal": "bench_optimal",
        "per_triple": "bench_optimal",
        "ekf": "bench_ekf_filterpy",
        "trials": "bench_trials",
        "bank": "bench_bank",
        "rbpf_equal_cost": "bench_rbpf",
        "rbpf_convergence": "bench_rbpf",
        "kalman": "bench_kalman",
        "frames": "bench_frames",
        "range_ekf": "bench_range_ekf",
        "import": "bench_import",
    }
    prefixes = {name: prefix for name, (prefix, _) in _BENCH_TEXTS.items()}
    blocks = {}
    for key, table in bench_tables(records).items():
        name = sources[key]
        lines = [table.markdown().rstrip("\n"), ""]
        if key in notes:
            lines += [notes[key], ""]
        lines.append(
            f"Measured {t[prefixes[name] + '_origin']} "
            f"(`depthcore/provenance/benchmark_records/{name}.json`)."
        )
        blocks[key] = "\n".join(lines)
    return blocks
