"""The benchmarks' recorded numbers as the book and the README print them.

Recommended import: ``from depthbook import benchmark_tables``.

:func:`bench_texts` gives a record's (:mod:`depthbook.provenance.benchmarks`) numbers as
texts, :func:`bench_tables` the costs chapter's tables, :func:`bench_blocks` every table with
its notes (the page "Reproducing this book"), :func:`bench_origin` the machine and date a
record was measured on (:func:`bench_machine` the machine alone).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from depthbook.formatting import sci
from depthbook.notebook import MarkdownTable
from depthcore.problem.scenarios import SCENARIOS

# --- the benchmarks' records -----------------------------------------------------------------


def bench_machine(record: dict) -> str:
    """The machine a benchmark's record was measured on, as the book states it.

    Parameters
    ----------
    record : dict
        A benchmark's record (:func:`depthbook.provenance.benchmarks.read`); its ``"machine"``.

    Returns
    -------
    str
        E.g. ``"2 cores (AMD EPYC, family 25, model 17; scipy-openblas
        0.3.31.188.0, SkylakeX kernels), Python 3.11.7, NumPy 2.4.6, SciPy 1.17.1"``
    """
    m = record["machine"]
    return (
        f"{m['cores']} cores ({m['cpu']}, {m['processor']}; {m['blas']}), "
        f"Python {m['python']}, NumPy {m['numpy']}, SciPy {m['scipy']}"
    )


def bench_origin(record: dict) -> str:
    """When and where a benchmark's record was measured, as the book states it.

    Parameters
    ----------
    record : dict
        A benchmark's record (:func:`depthbook.provenance.benchmarks.read`), of
        which ``"date"`` and ``"machine"`` are read.

    Returns
    -------
    str
        The date and :func:`bench_machine`: ``"2026-11-26 on 2 cores (AMD EPYC, ...), ..."``
    """
    return f"{record['date'][:10]} on {bench_machine(record)}"


# --- the records' numbers as texts, read by the tables of fields below ---------------------


class _Group(NamedTuple):
    """Fields read from one part of a record, their keys prefixed with ``name``.

    A field is ``(key, path, spec)``: the text of key ``"<prefix>_<key>"`` is
    the value at ``path`` as ``spec`` prints it (:func:`_text`). A path is
    dotted keys into the part (``"results.ratio"``; an integer indexes a list,
    ``""`` is the part itself) or a function of the part.

    Attributes
    ----------
    name : str
        Prefix of the group's keys ("" for none).
    path : str or callable
        Where the part is, as a field's path.
    fields : tuple
        Fields and groups, read from the part.
    rows : bool
        The part is a list: its fields are read from each item, prefix ``"<name>_<label>"``.
    label : str, optional
        The item's field that labels it; default its index.
    when : str, optional
        The group is read only where its part has this key.
    """

    name: str
    path: str | Callable
    fields: tuple
    rows: bool = False
    label: str | None = None
    when: str | None = None


def _key(*parts: str) -> str:
    """The non-empty ``parts`` joined by underscores: a glued name."""
    return "_".join(p for p in parts if p)


def _read(part, path):
    """The value at ``path`` (dotted keys or a function) in ``part``."""
    if callable(path):
        return path(part)
    for step in filter(None, path.split(".")):
        part = part[int(step)] if step.lstrip("-").isdigit() else part[step]
    return part


def _text(value, spec: str) -> str:
    """``value`` by ``spec``: a format spec, or ``"sci"`` for :func:`sci` (``"sci2"``: 2 digits)."""
    if spec.startswith("sci"):
        return sci(value, int(spec[3:] or 1))
    return format(value, spec)


def _texts(part, fields, prefix: str = "") -> dict[str, str]:
    """The texts of ``fields`` (and groups, :class:`_Group`) read from ``part``, in order."""
    out = {}
    for field in fields:
        if isinstance(field, _Group):
            out.update(_group_texts(part, field, prefix))
        else:
            key, path, spec = field
            out[_key(prefix, key)] = _text(_read(part, path), spec)
    return out


def _group_texts(part, group: _Group, prefix: str) -> dict[str, str]:
    """The texts of one :class:`_Group` of ``part``: of its part, or of each of its rows."""
    inner = _read(part, group.path)
    if group.when is not None and group.when not in inner:
        return {}
    if not group.rows:
        return _texts(inner, group.fields, _key(prefix, group.name))
    out = {}
    for i, row in enumerate(inner):
        label = str(i) if group.label is None else row[group.label]
        out.update(_texts(row, group.fields, _key(prefix, group.name, label)))
    return out


def _columns_as_rows(columns: dict, names) -> list[dict]:
    """Lists of equal length ``columns[name]`` as one dict per row."""
    return [
        dict(zip(names, row, strict=True)) for row in zip(*(columns[n] for n in names), strict=True)
    ]


def _extreme_ratio(values) -> float:
    """The largest of ``values`` over the least."""
    return max(values) / min(values)


def _time_ratios(record: dict) -> list[float]:
    """``bench_rbpf``'s resample-move time over the RBPF's, at equal cost, per problem."""
    return [r["resample_move_time_s"] / r["rbpf_time_s"] for r in record["results"]["equal_cost"]]


#: The three times of ``bench_optimal``'s triples, and the ratios of pairs of them with their
#: formats.
_TIMES = ("optimal", "second_order", "ekf")
_RATIOS = (
    ("optimal", "ekf", ".1f"),
    ("second_order", "ekf", ".2f"),
    ("optimal", "second_order", ".1f"),
)
#: The tolerances of ``bench_range_ekf`` and its problems, as the tables name them.
_TOLERANCES = ("1e-02", "1e-03")
_RANGE_EKF_PROBLEMS = {"fig2": "Figure 2 (3 frames)", "ten_frames": "a 10-frame track"}


def _triples(record: dict) -> list[dict]:
    """``bench_optimal``'s rows of the paper's triples, one dict each."""
    t = record["results"]["per_triple"]
    return _columns_as_rows(
        t, ["keys", "nodes", "brute_force_evaluations", *(f"{n}_ms" for n in _TIMES)]
    )


def _triple_column(record: dict, name: str) -> np.ndarray:
    """One column of ``bench_optimal``'s rows of triples."""
    return np.array(record["results"]["per_triple"][name])


def _triple_ratios(record: dict, a: str, b: str) -> np.ndarray:
    """Time ``a`` over time ``b`` of each triple."""
    return _triple_column(record, f"{a}_ms") / _triple_column(record, f"{b}_ms")


def _particles_label(row: dict) -> str:
    """A filter of ``bench_frames`` with its particles, where it draws them."""
    if not row["options"]:
        return row["filter"]
    return f"{row['filter']} ({row['options']['n_particles']:,} particles)"


def _range_ekf_group(key: str, label: str, tol: str) -> _Group:
    """``bench_range_ekf``'s fields of one problem at one tolerance."""
    return _Group(
        f"{key}_{tol}",
        f"results.{key}.{tol}",
        (
            ("problem", lambda _: label, ""),
            ("tolerance", lambda _: float(tol), "g"),
            ("components", "components", ","),
            ("range_ms", "range_ekf_ms", ".1f"),
            ("bank_ms", "bank_ms", ".1f"),
            ("ratio", "ratio", ".1f"),
        ),
    )


def _against_filterpy(time: str, other_time: str, ratio: str) -> tuple:
    """The fields of a timing against filterpy: both times and the ratio with its range."""
    return (
        ("depthcore_ms", "results.depthcore_ms", time),
        ("filterpy_ms", "results.filterpy_ms", other_time),
        *((key, f"results.{key}", ratio) for key in ("ratio", "ratio_min", "ratio_max")),
    )


#: The fields of filterpy's and depthcore's results' agreement.
_AGREEMENT = (
    ("mean_difference", "results.mean_difference_sd", "sci"),
    ("cov_max", "results.covariance_difference_max", "sci"),
)


#: The fields of one model's row of ``bench_kalman``: both routes' filter and smoother.
_KALMAN_ROW = (
    ("n", "state_dimension", ""),
    ("m", "measurement_dimension", ""),
    *(
        (f"{r}_{s}_ms", f"{r}_{s}_ms", ".1f")
        for r in ("depthcore", "filterpy")
        for s in ("filter", "smoother")
    ),
    *(
        (key, key, ".2f")
        for key in ("filter_ratio", "smoother_ratio", "ratio", "ratio_min", "ratio_max")
    ),
)


def _kalman_rows(record: dict) -> list[dict]:
    """``bench_kalman``'s rows: the bank's case (the results themselves), then each plane model."""
    r = record["results"]
    return [r, *r["dimensions"]]


def _listed(values, spec: str) -> str:
    """``values`` printed by ``spec`` as a list in prose: ``"a, b and c"``."""
    texts = [format(v, spec) for v in values]
    return texts[0] if len(texts) == 1 else ", ".join(texts[:-1]) + " and " + texts[-1]


def _kalman_met(record: dict) -> str:
    """Whether every model's filter and smoother reach ``bench_kalman``'s target ratio."""
    target = record["results"]["target_ratio"]
    rows = _kalman_rows(record)
    met = all(row[k] >= target for row in rows for k in ("filter_ratio", "smoother_ratio"))
    return "met" if met else "not met"


#: Each benchmark's prefix of glued names and the fields of its record's texts.
_BENCHMARKS = {
    "bench_range_ekf": (
        "rekf",
        tuple(
            _range_ekf_group(key, label, tol)
            for key, label in _RANGE_EKF_PROBLEMS.items()
            for tol in _TOLERANCES
        ),
    ),
    "bench_optimal": (
        "opt",
        (
            _Group(
                "",
                "results.moments",
                (
                    ("one_d_ms", "one_d_ms", ".2f"),
                    ("one_d_error", "one_d_error_sd", "sci"),
                    ("one_d_estimate", "one_d_estimate_sd", "sci"),
                    (
                        "grid_rule",
                        lambda m: f"{m['grid_panels']} x 8 depth, {m['grid_order']}^2 (x, v) nodes",
                        "",
                    ),
                    ("grid_ms", "grid_ms", ".0f"),
                    ("grid_error", "grid_error_sd", "sci"),
                    ("grid_ratio", "grid_ratio", ",.0f"),
                ),
            ),
            _Group(
                "nquad",
                "results.moments",
                (
                    ("s", "nquad_one_integral_s", ".1f"),
                    ("error", "nquad_relative_error", "sci"),
                    ("ratio", "nquad_ratio", ",.0f"),
                    ("all_s", "nquad_all_s", ".0f"),
                    ("all_ratio", "nquad_all_ratio", ",.0f"),
                ),
                when="nquad_one_integral_s",
            ),
            _Group(
                "",
                _triples,
                (
                    ("figure", lambda row: f"Figure {SCENARIOS[row['keys']].figure}", ""),
                    *((f"{n}_ms", f"{n}_ms", ".3f") for n in _TIMES),
                    *(
                        (f"{a}_{b}", lambda row, a=a, b=b: row[f"{a}_ms"] / row[f"{b}_ms"], f)
                        for a, b, f in _RATIOS
                    ),
                    ("nodes", "nodes", ""),
                    ("brute", "brute_force_evaluations", ","),
                ),
                rows=True,
                label="keys",
            ),
            *(
                (f"{a}_{b}_{which}", lambda r, a=a, b=b, g=g: g(_triple_ratios(r, a, b)), f)
                for a, b, f in _RATIOS
                for which, g in (("min", np.min), ("max", np.max))
            ),
            ("nodes_min", lambda r: _triple_column(r, "nodes").min(), ""),
            ("nodes_max", lambda r: _triple_column(r, "nodes").max(), ""),
            ("brute_max", lambda r: _triple_column(r, "brute_force_evaluations").max(), ","),
            (
                "brute_per_node",
                lambda r: (
                    _triple_column(r, "brute_force_evaluations").min()
                    / _triple_column(r, "nodes").max()
                ),
                ",.0f",
            ),
        ),
    ),
    "bench_trials": (
        "trials",
        (
            ("trials", "sizes.trials", ","),
            ("timed", "sizes.timed_one_by_one", ""),
            ("vectorised_s", "results.vectorised_s", ".2f"),
            (
                "per_trial_ms",
                lambda r: 1e3 * r["results"]["vectorised_s"] / r["sizes"]["trials"],
                ".3f",
            ),
            ("loop_s", "results.trial_by_trial_s", ".2f"),
            ("ratio", "results.ratio", ".1f"),
            ("estimate", "results.estimate_sd", "sci"),
            ("difference", "results.difference_sd", "sci"),
        ),
    ),
    "bench_features": (
        "features",
        (
            ("target_ms", "results.target_ms", "g"),
            *(
                _Group(
                    name,
                    f"results.{name}",
                    (
                        ("features", "features", ","),
                        ("frames", "frames", ""),
                        ("nodes", "nodes", ""),
                        ("exact_ms", "exact_ms", ".1f"),
                        ("ekf_ms", "ekf_ms", ".2f"),
                        ("ratio", "ratio", ".1f"),
                        ("mean", "mean_difference_sd", "sci"),
                        ("sd", "sd_difference_sd", "sci"),
                    ),
                )
                for name in ("space", "plane")
            ),
        ),
    ),
    "bench_long_track": (
        "long",
        (
            ("frames", "results.frames", ","),
            _Group(
                "",
                "results.filters",
                (
                    ("first_ms", "first_ms", ".2f"),
                    ("last_ms", "last_ms", ".2f"),
                    ("held_first", "held_first_bytes", ","),
                    ("held_last", "held_last_bytes", ","),
                ),
                rows=True,
                label="filter",
            ),
        ),
    ),
    "bench_stonesoup": (
        "ss",
        (
            ("frames", "results.per_update.frames", ","),
            ("stone_soup_ms", "results.per_update.stone_soup_ms_per_frame", ".2f"),
            ("online_ms", "results.per_update.online_ms_per_frame", ".2f"),
            ("ratio", "results.per_update.ratio", ".2f"),
            ("target_ratio", "results.per_update.target_ratio", "g"),
            ("tracker_exact_ms", "results.tracker.exact_ms_per_frame", ".1f"),
            ("tracker_ekf_ms", "results.tracker.ekf_ms_per_frame", ".1f"),
        ),
    ),
    "bench_workers": (
        "workers",
        (("trials", "sizes.trials", ","), ("frames", "sizes.frames", ""))
        + (("filters", lambda r: len(r["sizes"]["filters"]), ""),)
        + (("cores", "results.workers.cores", ""), ("two_over_one", "results.two_over_one", ".2f"))
        + tuple((k, f"results.{k}", ".1f") for k in ("in_process_s", "one_s", "two_s", "cores_s"))
        + tuple((f"speedup_{k}", f"results.speedup_{k}", ".2f") for k in ("one", "two", "cores")),
    ),
    "bench_ekf_filterpy": (
        "ekfpy",
        (
            ("trials", "sizes.trials", ","),
            *_against_filterpy(".1f", ",.0f", ",.0f"),
            ("pairs", "sizes.pairs", ""),
            *_AGREEMENT,
            ("cov_median", "results.covariance_difference_median", "sci"),
        ),
    ),
    "bench_import": (
        "import",
        (
            ("numpy_s", "results.numpy_s", ".3f"),
            ("depthcore_s", "results.depthcore_after_numpy_s", ".3f"),
            ("target_s", "results.target_s", ".2f"),
            ("runs", "sizes.runs", ""),
        ),
    ),
    "bench_bank": (
        "bank",
        (
            _Group(
                "three",
                "results.three_frames",
                (
                    ("trials", "trials", ","),
                    ("one_d_ms", "one_d_ms_per_trial", ".3f"),
                    ("bank_ms", "bank_ms_per_trial", ".3f"),
                    ("ratio", "ratio", ".2f"),
                    ("difference", "difference_sd", "sci"),
                ),
            ),
            ("three_target", "results.targets.three_frames_ratio", "g"),
            _Group(
                "online",
                "results.online",
                (
                    ("trials", "trials", ","),
                    ("frames", "frames", ","),
                    ("windows", lambda online: len(online["windows"]), ""),
                ),
            ),
            _Group(
                "many",
                "results.many_trials",
                (
                    ("trials", "trials", ","),
                    ("frames", "frames", ""),
                    ("s", "time_s", ".1f"),
                    ("target_s", "target_s", "g"),
                    ("met", lambda m: "met" if m["time_s"] < m["target_s"] else "not met", ""),
                    ("worst", "worst_error_estimate_sd", "sci"),
                ),
            ),
            _Group(
                "matched",
                "results.matched_accuracy",
                (
                    ("trials", "trials", ""),
                    ("frames", "frames", ""),
                    ("replicas", "replicas", ""),
                    ("bank_s", "bank_time_s", ".3f"),
                    ("ratio", "ratio", ",.0f"),
                    ("target_ratio", "target_ratio", "g"),
                    ("largest", "particles.-1", ","),
                    ("largest_s", "time_per_run_s.-1", ".2f"),
                    ("largest_error", "error_sd.-1", "sci2"),
                    ("target_error", "target_error_sd", "sci0"),
                    ("extrapolated_needed", "extrapolated_particles_needed", "sci"),
                    ("extrapolated_s", "extrapolated_time_s", "sci"),
                    ("extrapolated_ratio", "extrapolated_ratio", "sci"),
                ),
            ),
            _Group(
                "online",
                "results.online.windows",
                (
                    ("frames", lambda w: f"{w['first_frame']}–{w['last_frame']}", ""),
                    ("ms", "ms_per_update", ".2f"),
                    ("ratio", "ratio_to_first", ".2f"),
                    ("nodes", "median_nodes", ""),
                    ("sd", "median_depth_sd", ".4f"),
                ),
                rows=True,
            ),
            (
                "online_max_ratio",
                lambda r: _extreme_ratio(
                    [w["ms_per_update"] for w in r["results"]["online"]["windows"]]
                ),
                ".1f",
            ),
            _Group(
                "matched",
                lambda r: _columns_as_rows(
                    r["results"]["matched_accuracy"], ("particles", "error_sd", "time_per_run_s")
                ),
                (
                    ("particles", "particles", ","),
                    ("error", "error_sd", "sci2"),
                    ("s", "time_per_run_s", ".2f"),
                ),
                rows=True,
            ),
        ),
    ),
    "bench_rbpf": (
        "rbpf",
        (
            ("repeats", "sizes.repeats", ""),
            _Group(
                "equal",
                "results.equal_cost",
                (
                    ("problem", "problem", ""),
                    ("rbpf_particles", "rbpf_particles", ","),
                    ("rbpf_s", "rbpf_time_s", ".2f"),
                    ("rbpf_error", "rbpf_error_sd", ".4f"),
                    ("rm_particles", "resample_move_particles", ","),
                    ("rm_s", "resample_move_time_s", ".2f"),
                    ("rm_error", "resample_move_error_sd", ".4f"),
                    ("ratio", "error_ratio", ".1f"),
                ),
                rows=True,
            ),
            *(
                (f"equal_time_ratio_{f.__name__}", lambda r, f=f: f(_time_ratios(r)), ".1f")
                for f in (min, max)
            ),
            _Group(
                "conv",
                "results.convergence",
                (
                    ("problem", "problem", ""),
                    ("particles", "particles", ","),
                    ("s", "time_s", ".2f"),
                    ("error", "error_sd", ".4f"),
                    ("se", "standard_error_sd", ".4f"),
                    ("scaled", "error_times_sqrt_particles_sd", ".2f"),
                ),
                rows=True,
            ),
        ),
    ),
    "bench_kalman": (
        "kalmanpy",
        (
            ("steps", "sizes.steps", ","),
            ("pairs", "sizes.pairs", ""),
            *_against_filterpy(".1f", ".1f", ".2f"),
            *_AGREEMENT,
            _Group("bank", "results", _KALMAN_ROW),
            _Group("dim", "results.dimensions", _KALMAN_ROW, rows=True),
            ("target_ratio", "results.target_ratio", "g"),
            ("met", _kalman_met, ""),
            (
                "dims",
                lambda r: _listed(
                    [row["state_dimension"] for row in r["results"]["dimensions"]], "d"
                ),
                "",
            ),
            *(
                (
                    f"dim_{key}s",
                    lambda r, key=key: _listed(
                        [row[key] for row in r["results"]["dimensions"]], ".2f"
                    ),
                    "",
                )
                for key in ("filter_ratio", "smoother_ratio", "ratio")
            ),
            *(
                (
                    f"worst_{name}",
                    lambda r, key=key: max(row[key] for row in _kalman_rows(r)),
                    "sci",
                )
                for name, key in (
                    ("mean_difference", "mean_difference_sd"),
                    ("cov_max", "covariance_difference_max"),
                )
            ),
            (
                "all_ratio_min",
                lambda r: min(row["ratio_min"] for row in _kalman_rows(r)),
                ".2f",
            ),
            (
                "all_ratio_max",
                lambda r: max(row["ratio_max"] for row in _kalman_rows(r)),
                ".2f",
            ),
        ),
    ),
    "bench_frames": (
        "frames",
        (
            ("trials", "sizes.trials", ""),
            ("q", "sizes.process_noise", "g"),
            ("n_filters", lambda r: len(r["results"]["filters"]), ""),
            ("growth_max", lambda r: max(row["growth"] for row in r["results"]["filters"]), ".2f"),
            _Group("n", "results.frames", (("", "", ","),), rows=True),
            _Group(
                "",
                "results.filters",
                (
                    ("filter", _particles_label, ""),
                    ("q", "process_noise", "g"),
                    _Group("", "ms_per_trial", (("ms", "", ",.1f"),), rows=True),
                    ("growth", "growth", ".2f"),
                ),
                rows=True,
            ),
        ),
    ),
}


def bench_texts(name: str, record: dict) -> dict[str, str]:
    """The numbers of a benchmark's record as the book and the README print them.

    Parameters
    ----------
    name : str
        The benchmark, e.g. ``"bench_optimal"``.
    record : dict
        Its record, from :func:`depthbook.provenance.benchmarks.read`.

    Returns
    -------
    dict of str to str
        ``"<prefix>_<quantity>"`` -> text, the prefix ``opt``, ``trials``, ``ekfpy``,
        ``import``, ``bank``, ``rbpf``, ``kalmanpy``, ``frames``, ``rekf``, ``long``, ``ss``
        or ``workers``;
        ``"<prefix>_origin"`` is :func:`bench_origin`. Times in their key's unit.
    """
    if name not in _BENCHMARKS:
        raise ValueError(f"name must be one of {sorted(_BENCHMARKS)}, got {name!r}")
    prefix, fields = _BENCHMARKS[name]
    out = _texts(record, fields, prefix)
    out[f"{prefix}_origin"] = bench_origin(record)
    return out


def _all_texts(records: dict) -> dict[str, str]:
    """:func:`bench_texts` of every record of ``{name: record}``, in one dict."""
    return {k: v for name, record in records.items() for k, v in bench_texts(name, record).items()}


# --- the tables --------------------------------------------------------------------------------


def _cell(t: dict, key: str) -> str:
    """The text of ``key`` with its unit, where its key ends with one (``_s``, ``_ms``)."""
    unit = key.rsplit("_", 1)[-1]
    return t[key] + (f" {unit}" if unit in ("s", "ms") else "")


def _grid(t: dict, header, prefix: str, rows, columns) -> MarkdownTable:
    """A table of the texts ``"<prefix>_<row>_<column>"``, with their units."""
    return MarkdownTable(header, [[_cell(t, _key(prefix, r, c)) for c in columns] for r in rows])


def _routes(first: str, first_time: str, second: str, second_time: str, ratio: str):
    """A table of two routes' times, the second's as a ratio to the first's."""
    return MarkdownTable(
        ["route", "time", "ratio"], [[first, first_time, "1"], [second, second_time, ratio]]
    )


def _optimal_table(t: dict) -> MarkdownTable:
    """The routes to the optimal filter's moments (``bench_optimal``)."""
    rows = [
        [
            "1-D route, Eqs. (14)–(16), one batch",
            _cell(t, "opt_one_d_ms"),
            f"{t['opt_one_d_error']} (estimate {t['opt_one_d_estimate']})",
            "1",
        ],
        [
            f"3-D Gauss–Legendre grid of Eq. (6) ({t['opt_grid_rule']})",
            _cell(t, "opt_grid_ms"),
            t["opt_grid_error"],
            t["opt_grid_ratio"],
        ],
    ]
    if "opt_nquad_s" in t:
        rows += [
            [
                "scipy nquad of Eq. (6), epsrel 1e-9: 1 integral (Figure 2's normaliser)",
                _cell(t, "opt_nquad_s"),
                f"{t['opt_nquad_error']} (relative)",
                t["opt_nquad_ratio"],
            ],
            [
                "x 25 integrals (5 moments x 5 scenarios), extrapolated",
                _cell(t, "opt_nquad_all_s"),
                "-",
                t["opt_nquad_all_ratio"],
            ],
        ]
    return MarkdownTable(["route", "time", "error / SD", "ratio"], rows)


def _bank_table(t: dict) -> MarkdownTable:
    """The exact filter's bank against its targets (``bench_bank``)."""
    windows = [f"bank_online_{i}" for i in range(int(t["bank_online_windows"]))]
    return MarkdownTable(
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


def _frames_table(t: dict, records: dict) -> MarkdownTable:
    """Each filter's time per trial at each number of frames (``bench_frames``)."""
    frames = range(len(records["bench_frames"]["results"]["frames"]))
    return _grid(
        t,
        ["filter", "q", *(f"N = {t[f'frames_n_{j}']}" for j in frames), "growth per frame"],
        "frames",
        [f"{i}" for i in range(int(t["frames_n_filters"]))],
        ["filter", "q", *(f"{j}_ms" for j in frames), "growth"],
    )


def _row_tables(t: dict, records: dict) -> dict[str, MarkdownTable]:
    """The tables of one row per problem or triple: header, the texts' prefix, rows, columns."""
    rbpf = records["bench_rbpf"]["results"]
    return {
        "per_triple": _grid(
            t,
            ["figure", "optimal", "second order", "EKF", "optimal / EKF", "nodes", "brute force"],
            "opt",
            records["bench_optimal"]["results"]["per_triple"]["keys"],
            ["figure", "optimal_ms", "second_order_ms", "ekf_ms", "optimal_ekf", "nodes", "brute"],
        ),
        "rbpf_equal_cost": _grid(
            t,
            ["problem", "RBPF particles", "RBPF time", "RBPF error", "resample-move particles"]
            + ["resample-move time", "resample-move error", "error ratio"],
            "rbpf_equal",
            [f"{i}" for i in range(len(rbpf["equal_cost"]))],
            ["problem", "rbpf_particles", "rbpf_s", "rbpf_error", "rm_particles", "rm_s"]
            + ["rm_error", "ratio"],
        ),
        "rbpf_convergence": _grid(
            t,
            ["problem", "particles", "time", "RMS error", "SE of the average"]
            + ["RMS error x sqrt(J)"],
            "rbpf_conv",
            [f"{i}" for i in range(len(rbpf["convergence"]))],
            ["problem", "particles", "s", "error", "se", "scaled"],
        ),
        "kalman": _grid(
            t,
            ["n", "m", "depthcore filter", "depthcore smoother", "filterpy filter"]
            + ["filterpy smoother", "ratio, filter", "ratio, smoother", "ratio, both"],
            "kalmanpy",
            [
                "bank",
                *(f"dim_{i}" for i in range(len(records["bench_kalman"]["results"]["dimensions"]))),
            ],
            ["n", "m", "depthcore_filter_ms", "depthcore_smoother_ms", "filterpy_filter_ms"]
            + ["filterpy_smoother_ms", "filter_ratio", "smoother_ratio", "ratio"],
        ),
        "range_ekf": _grid(
            t,
            ["problem", "depth mean and SD within", "components", "range EKF", "bank", "ratio"],
            "rekf",
            [f"{key}_{tol}" for key in _RANGE_EKF_PROBLEMS for tol in _TOLERANCES],
            ["problem", "tolerance", "components", "range_ms", "bank_ms", "ratio"],
        ),
    }


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
    t = _all_texts(records)
    rows = _row_tables(t, records)
    return {
        "optimal": _optimal_table(t),
        "per_triple": rows["per_triple"],
        "ekf": _routes(
            "depthcore.kalman.ekf.run, vectorised",
            _cell(t, "ekfpy_depthcore_ms"),
            "filterpy ExtendedKalmanFilter, trial by trial",
            _cell(t, "ekfpy_filterpy_ms"),
            t["ekfpy_ratio"],
        ),
        "trials": _routes(
            "optimal.moments, vectorised over trials",
            _cell(t, "trials_vectorised_s"),
            f"optimal.run, trial by trial ({t['trials_timed']} timed, scaled)",
            _cell(t, "trials_loop_s"),
            t["trials_ratio"],
        ),
        "bank": _bank_table(t),
        "rbpf_equal_cost": rows["rbpf_equal_cost"],
        "rbpf_convergence": rows["rbpf_convergence"],
        "kalman": rows["kalman"],
        "frames": _frames_table(t, records),
        "range_ekf": rows["range_ekf"],
        "import": MarkdownTable(
            ["import", "median time"],
            [
                ["numpy", _cell(t, "import_numpy_s")],
                ["depthcore, after numpy", _cell(t, "import_depthcore_s")],
            ],
        ),
    }


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
    t = _all_texts(records)
    notes = {
        "ekf": f"Times and ratio are medians over {t['ekfpy_pairs']} pairs timed alternately "
        f"(the pairs' ratios from {t['ekfpy_ratio_min']} to {t['ekfpy_ratio_max']}). "
        f"The two agree to {t['ekfpy_mean_difference']} posterior SDs in the means; "
        f"the covariances agree to {t['ekfpy_cov_median']} of their norm in the median "
        f"trial and {t['ekfpy_cov_max']} in the worst.",
        "trials": f"The largest error estimate is {t['trials_estimate']} of the SD; the "
        f"vectorised and single routes differ by {t['trials_difference']} SDs.",
        "kalman": f"Times and ratios are medians over {t['kalmanpy_pairs']} pairs, each "
        "pair depthcore's filter and smoother and then filterpy's on one sequence, the models "
        "in turn; a ratio is filterpy's time over depthcore's. n is the state's dimension, m "
        "the measurement's: the first row is the bank's case (constant velocity, the position "
        "measured), the others a point in the plane measured in 2-D, its state the position "
        "and its derivatives. The pairs' ratios of both range from "
        f"{t['kalmanpy_all_ratio_min']} to {t['kalmanpy_all_ratio_max']}; the target, filter "
        f"and smoother each at least {t['kalmanpy_target_ratio']} (depthcore at least as "
        f"fast), is {t['kalmanpy_met']}. The smoothed means agree with filterpy's to "
        f"{t['kalmanpy_worst_mean_difference']} SDs, the covariances to "
        f"{t['kalmanpy_worst_cov_max']} of their norm.",
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
    prefixes = {name: prefix for name, (prefix, _) in _BENCHMARKS.items()}
    blocks = {}
    for key, table in bench_tables(records).items():
        name = sources[key]
        lines = [table.markdown().rstrip("\n"), ""]
        if key in notes:
            lines += [notes[key], ""]
        lines.append(
            f"Measured {t[prefixes[name] + '_origin']} "
            f"(`depthbook/provenance/benchmark_records/{name}.json`)."
        )
        blocks[key] = "\n".join(lines)
    return blocks
