"""Every text the command line and the book show: tables, vectors, glued numbers.

Recommended import: ``from depthcore import report``.

Nothing here computes an estimate: the functions format what
:mod:`depthcore.reproduce`, :mod:`depthcore.study` and
:mod:`depthcore.experiments` return.

* :func:`format_table`, :func:`format_summary`, :func:`format_study`: the
  command line's plain-text tables;
* :func:`vec`: a vector as the book prints it;
* :func:`comparison`, :func:`comparison_texts`, :func:`comparison_table`: the
  reported-versus-reproduced tables of the figure pages;
* :func:`moments_texts`, :func:`study_texts`, :func:`sweep_texts`,
  :func:`noise_study_texts`, :func:`rbpf_texts`, :func:`rho_label`: the texts the chapters beyond
  the paper glue into their tables;
* :func:`page_text`, :func:`page_tables`, :func:`paste_table`, :class:`PastedTable`:
  a page's tables of glued numbers, with the numbers pasted in, for a notebook;
* :func:`bench_texts`, :func:`bench_tables`, :func:`bench_readme_blocks`,
  :func:`bench_origin`: the benchmarks' recorded numbers
  (:mod:`depthcore.benchmarks`) as the book and the README print them;
* :class:`MarkdownTable`, :class:`GlueLog`: what a page shows when it runs as a
  plain notebook in Jupyter, which displays neither the values nor the figures
  that the page glues into the book's text.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np

from . import _checks
from .crossref import BookReferences
from .estimates import QUANTITIES
from .filters import NAMES
from .reproduce import scenario_rows
from .scenarios import REPORTED_DECIMALS, SCENARIOS

#: Rows of the figure pages' tables, as (row id, filter, reading, support, label).
#: The optimal filter with Eq. (16) as derived and as printed; the second-order
#: filter with the covariance ``2 rho**2 J^{-1}`` of the expansion (8) and with
#: the printed ``rho**2 J^{-1}``; the EKF. A label's ``%s`` is the quantity's
#: letter, ``y`` or ``v``, as in the paper's marginals ``p_oy`` and ``p_ov``.
TABLE_ROWS = (
    ("opt", "optimal", "derived", "front", "optimal $p_{o%s}$"),
    ("opt_printed", "optimal", "printed", "front", "optimal, Eq. (16) as printed"),
    ("so", "second_order", "derived", "all", r"second order $p_{s%s}$, $2\rho^2 J^{-1}$"),
    ("so_printed", "second_order", "printed", "all", r"second order, $\rho^2 J^{-1}$ as printed"),
    ("ekf", "ekf", "printed", "all", "EKF $p_{e%s}$"),
    ("iter", "iterated", "-", "all", "iterated EKF"),
    ("inv", "inverse_depth", "-", "all", "inverse-depth EKF, delta method"),
)

#: The letter of each quantity in the paper's names of the marginals.
QUANTITY_LETTERS = {"depth": "y", "velocity": "v"}

#: Decimal places of the reproduced means and SDs in the book's tables.
DECIMALS = 4


#: Scores of :func:`depthcore.study_scores.scores` per quantity, with their decimals in the book's
#: tables.
STUDY_DECIMALS = {"bias": 3, "rmse": 3, "mean_sd": 3, "coverage_68": 2, "coverage_95": 2}
#: (text key, score, decimals) of the rows of several studies' texts.
SCORE_TEXTS = (
    ("bias", "bias", 3),
    ("rmse", "rmse", 3),
    ("mean_sd", "mean_sd", 3),
    ("cov68", "coverage_68", 2),
    ("cov95", "coverage_95", 2),
    ("nees", "nees", 1),
)


# --- the command line's tables ------------------------------------------------------------

#: The key of :func:`format_table`'s columns.
TABLE_KEY = """\
key: fig      the paper's figure (its scenario: bearings, noise and prior)
     filter   the filter (python -m depthcore study --help lists them)
     reading  derived = Eq. (16) or the second-order covariance as derived;
              printed = as printed in the paper
     support  front = the optimal filter's depth restricted to y > 2 (in front of
              the camera at every frame); all = no restriction
     quantity depth y or velocity v of the state at time 3
     mean, sd the filter's posterior mean and standard deviation of the quantity
     error    error estimate of the optimal filter's quadrature, standard error of the
              particle filter's Monte Carlo estimate; 0 for the Gaussian filters
     paper mean, paper sd  the numbers printed in the paper (blank where it prints none)
     agrees   whether the mean and the SD round to the paper's printed numbers"""

#: The legend of :func:`format_summary`'s columns.
SUMMARY_LEGEND = """\
legend: depth mean, depth sd  the filter's posterior mean and SD of the depth y at frame N
        vel. mean, vel. sd    the same of the velocity v (the x-velocity; the y-velocity is 1)
        error estimates       the optimal filter's numerical error of its mean and SD"""

#: The legend of :func:`format_summary`'s smoothed columns.
SMOOTHED_LEGEND = """\
        frame                 1 .. N; depth mean, depth sd and x mean, x sd: the optimal
                              filter's mean and SD of the depth y and the lateral position x
                              at that frame given all N bearings"""

#: The legend of :func:`format_prior_study`'s columns.
PRIOR_STUDY_LEGEND = """\
legend: nominal     probability of the central interval of the optimal filter's marginal
        depth, velocity  fraction of trials whose interval holds the true value (its
                    binomial standard error in brackets); equal to nominal if calibrated
        KS p, chi-square p  p-values of the Kolmogorov-Smirnov and chi-square tests of
                    uniformity of the PIT values (the marginal CDF at the truth)"""

#: The legend of :func:`format_study`'s columns.
STUDY_LEGEND = """\
legend: bias, rmse  mean and root mean square of estimate - truth over the trials
        mean sd     mean of the filter's reported standard deviation
        cover 68/95 fraction of trials whose central 68% / 95% interval holds the truth
        NEES        mean normalized estimation error squared of (x, y, v); 3 if calibrated
        Hellinger   mean Hellinger distance from the depth marginal to the optimal one
                    (0 = the same density, 1 = disjoint); a dash: not computed, as the
                    optimal filter, the reference, runs only when it is among the filters
        (se)        under each row: the Monte Carlo standard error of each number above it"""


def format_table(result: dict) -> str:
    """A plain-text table of :func:`~depthcore.reproduce.reproduce`'s result."""
    head = (
        f"{'fig':>3}  {'filter':<12} {'reading':<8} {'support':<7} {'quantity':<8} "
        f"{'mean':>10} {'sd':>10} {'error':>8}  {'paper mean':>10} {'paper sd':>9}  agrees"
    )
    lines = [head, "-" * len(head)]
    for sc in result["scenarios"]:
        for r in sc["rows"]:
            rep_m = "" if r["reported_mean"] is None else f"{r['reported_mean']:.2f}"
            rep_s = "" if r["reported_sd"] is None else f"{r['reported_sd']:.2f}"
            match = (
                ""
                if r["mean_matches"] is None
                else (
                    f"mean {'yes' if r['mean_matches'] else 'no'}, "
                    f"sd {'yes' if r['sd_matches'] else 'no'}"
                )
            )
            lines.append(
                f"{sc['figure']:>3}  {r['filter']:<12} {r['reading']:<8} {r['support']:<7} "
                f"{r['quantity']:<8} {r['mean']:>10.4f} {r['sd']:>10.4f} {r['error']:>8.1e}  "
                f"{rep_m:>10} {rep_s:>9}  {match}"
            )
        lines.append("")
    compared = [
        (sc["figure"], r)
        for sc in result["scenarios"]
        for r in sc["rows"]
        if r["mean_matches"] is not None
    ]
    matched = sum(bool(r["mean_matches"]) + bool(r["sd_matches"]) for _, r in compared)
    differ = [
        f"Fig. {fig} {r['filter']} {r['reading']} {r['support']} {r['quantity']}"
        for fig, r in compared
        if not (r["mean_matches"] and r["sd_matches"])
    ]
    lines += [
        TABLE_KEY,
        "",
        f"{matched} of the paper's {2 * len(compared)} printed means and SDs are matched"
        + (f"; differing: {', '.join(differ)}" if differ else "")
        + " (the book's page on the discrepancies explains each).",
    ]
    return "\n".join(lines).rstrip() + "\n"


def format_summary(summary: dict) -> str:
    """A plain-text rendering of :func:`~depthcore.reproduce.summarize`'s result."""
    c = summary["c"]
    m, cov = summary["prior_mean"], np.asarray(summary["prior_cov"])
    if np.array_equal(cov, cov[0, 0] * np.eye(3)):
        cov_text = f"{cov[0, 0]:.4g} I"
    else:
        cov_text = "[" + "; ".join(" ".join(f"{v:.4g}" for v in row) for row in cov) + "]"
    N = summary.get("frames", 3)
    q = summary.get("process_noise", 0.0)
    lines = [
        "noise-free state c = (x, y, v) at time 3 = "
        + ("undefined" if c is None else f"({c[0]:#.4g}, {c[1]:#.4g}, {c[2]:#.4g})"),
        f"prior at time 1: mean (x, y, v) = ({m[0]:#.4g}, {m[1]:#.4g}, {m[2]:#.4g}), "
        f"covariance {cov_text}",
    ]
    if N != 3 or q > 0:
        lines.append(f"{N} frames, process noise q = {q:g}; every filter at frame {N}")
    w = max([13, *(len(n) + 1 for n in [*summary["filters"], *summary.get("not_run", {})])])
    lines.append(
        f"{'filter':<{w}} {'depth mean':>11} {'depth sd':>10} {'vel. mean':>10} {'vel. sd':>10}"
    )
    for name in summary["filters"]:
        f = summary["filters"][name]
        lines.append(
            f"{name:<{w}} {f['depth']['mean']:>#11.4g} {f['depth']['sd']:>#10.4g} "
            f"{f['velocity']['mean']:>#10.4g} {f['velocity']['sd']:>#10.4g}"
        )
    for name, reason in summary.get("not_run", {}).items():
        lines.append(f"{name:<{w}} not run: {reason}")
    o = summary["filters"].get("optimal")
    if o is not None:
        text = (
            f"optimal error estimates: depth {_error(o['depth'].get('error'))}, "
            f"velocity {_error(o['velocity'].get('error'))}"
        )
        if "prob_behind_camera_all_depths" in o:
            text += (
                "; probability behind the camera if depths y <= 2 are allowed: "
                f"{o['prob_behind_camera_all_depths']:.3g}"
            )
        lines.append(text)
    if "smoothed" in summary:
        sm = summary["smoothed"]
        lines.append(
            f"{'frame':>5} {'depth mean':>11} {'depth sd':>10} {'x mean':>10} {'x sd':>10}"
            "   (optimal, smoothed)"
        )
        for k, row in enumerate(
            zip(
                sm["depth_mean"], sm["depth_sd"], sm["lateral_mean"], sm["lateral_sd"], strict=True
            ),
            1,
        ):
            lines.append(f"{k:>5} " + " ".join(f"{v:>#10.4g}" for v in row).replace(" ", "  ", 1))
    lines.append(SUMMARY_LEGEND)
    if "smoothed" in summary:
        lines.append(SMOOTHED_LEGEND)
    return "\n".join(lines) + "\n"


def _error(value) -> str:
    """An error estimate in a table: ``n/a`` where there is none or it is not finite."""
    return "n/a" if value is None or not np.isfinite(value) else f"{value:.1e}"


def format_study(result: dict) -> str:
    """A plain-text table of :func:`~depthcore.study.study`'s result."""
    lines = [
        f"truth {tuple(round(v, 6) for v in result['truth'])}, rho {result['rho']:.6g}, "
        f"prior {result['prior']}, seed {result['seed']}: {result['valid_trials']} trials "
        f"({result['rejected_trials']} without a noise-free solution in front of the camera "
        "left out)"
    ]
    if result.get("frames", 3) != 3 or result.get("process_noise", 0.0) > 0:
        lines.append(
            f"{result['frames']} frames, process noise q = {result['process_noise']:g}: "
            f"every filter scored on the true state at frame {result['frames']}"
        )
    head = (
        f"{'filter':<13} {'quantity':<9} {'bias':>9} {'rmse':>9} {'mean sd':>9} "
        f"{'cover 68':>8} {'cover 95':>8} {'NEES':>8} {'Hellinger':>9}"
    )
    lines += [head, "-" * len(head)]
    for name, f in result["filters"].items():
        for q in ("depth", "velocity"):
            r = f[q]
            h = f["hellinger_depth"]
            extra = (
                f"{f['nees']:>8.2f} " + ("-".rjust(9) if h is None else f"{h['mean']:>9.3f}")
                if q == "depth"
                else ""
            )
            lines.append(
                f"{name:<13} {q:<9} {r['bias']:>9.4f} {r['rmse']:>9.4f} {r['mean_sd']:>9.4f} "
                f"{r['coverage_68']:>8.3f} {r['coverage_95']:>8.3f} {extra}".rstrip()
            )
            extra_se = (
                f"{f['nees_se']:>8.2f} " + ("".rjust(9) if h is None else f"{h['se']:>9.3f}")
                if q == "depth"
                else ""
            )
            lines.append(
                f"{'':<13} {'(se)':<9} {r['bias_se']:>9.4f} {r['rmse_se']:>9.4f} "
                f"{r['mean_sd_se']:>9.4f} {r['coverage_68_se']:>8.3f} {r['coverage_95_se']:>8.3f} "
                f"{extra_se}".rstrip()
            )
    lines.append(STUDY_LEGEND)
    return "\n".join(lines) + "\n"


# --- the book's texts ----------------------------------------------------------------------


def vec(values, decimals: int = 4) -> str:
    """A vector as the book prints it: ``"(1.2000, 6.0000, 1.2000)"``.

    Rounds first, so that a value that rounds to zero prints as ``0.0000``,
    never ``-0.0000``.

    Parameters
    ----------
    values : array_like, shape (n,)
    decimals : int
        Places after the decimal point, >= 0.
    """
    values = _checks.finite_array(values, "values")
    if values.ndim != 1:
        raise ValueError(f"values must be 1-D, got shape {values.shape}")
    if int(decimals) != decimals or decimals < 0:
        raise ValueError(f"decimals must be a non-negative integer, got {decimals!r}")
    decimals = int(decimals)
    return "(" + ", ".join(f"{v + 0.0:.{decimals}f}" for v in np.round(values, decimals)) + ")"


def comparison(key: str) -> list[dict]:
    """The rows of a figure page's table: the paper's numbers beside ours.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.

    Returns
    -------
    list of dict
        One per entry of :data:`TABLE_ROWS`, with ``id``, ``label``,
        ``quantity``, ``mean``, ``sd``, ``reported_mean``, ``reported_sd``
        (``None`` where the paper prints nothing), ``mean_matches`` and
        ``sd_matches`` (agreement at the paper's printed precision, or ``None``).
    """
    if key not in SCENARIOS:
        raise ValueError(f"key must be one of {tuple(SCENARIOS)}, got {key!r}")
    s = SCENARIOS[key]
    quantity = s.quantity
    rows = scenario_rows(s, names=tuple(dict.fromkeys(row[1] for row in TABLE_ROWS)))
    out = []
    for row_id, filt, reading, support, label in TABLE_ROWS:
        (row,) = [
            r
            for r in rows
            if (r["filter"], r["reading"], r["support"], r["quantity"])
            == (filt, reading, support, quantity)
        ]
        out.append(
            {
                "id": row_id,
                "label": label % QUANTITY_LETTERS[quantity] if "%s" in label else label,
                "quantity": quantity,
                **{
                    k: row[k]
                    for k in (
                        "mean",
                        "sd",
                        "reported_mean",
                        "reported_sd",
                        "mean_matches",
                        "sd_matches",
                    )
                },
            }
        )
    return out


def comparison_texts(key: str, rows: list[dict]) -> dict[str, str]:
    """The numbers of :func:`comparison` as the strings the book shows, keyed for glue.

    Keys are ``f"{key}_{row id}_{field}"`` with fields ``mean``, ``sd`` (ours,
    :data:`DECIMALS` places), ``paper_mean``, ``paper_sd`` (the paper's
    precision, or an em dash where it prints nothing) and ``agrees``.
    """
    texts = {}
    for row in rows:
        name = f"{key}_{row['id']}"
        texts[f"{name}_mean"] = f"{row['mean']:.{DECIMALS}f}"
        texts[f"{name}_sd"] = f"{row['sd']:.{DECIMALS}f}"
        for field in ("mean", "sd"):
            value = row[f"reported_{field}"]
            texts[f"{name}_paper_{field}"] = (
                "—" if value is None else f"{value:.{REPORTED_DECIMALS}f}"
            )
        texts[f"{name}_agrees"] = _agreement(row["mean_matches"], row["sd_matches"])
    return texts


def _agreement(mean_matches, sd_matches) -> str:
    if mean_matches is None:
        return "—"
    return {
        (True, True): "yes",
        (True, False): "mean only",
        (False, True): "SD only",
        (False, False): "no",
    }[(mean_matches, sd_matches)]


def comparison_table(key: str, rows: list[dict]) -> MarkdownTable:
    """A figure page's table of the paper's numbers beside ours, with the numbers in it.

    The book writes this table in the page's text, from the glued
    :func:`comparison_texts`; this is the same table for a notebook, built from
    the same texts. The column ``agrees`` is left out when the paper prints no
    number to agree with.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.
    rows : list of dict
        From :func:`comparison` with the same ``key``.
    """
    if key not in SCENARIOS:
        raise ValueError(f"key must be one of {tuple(SCENARIOS)}, got {key!r}")
    texts = comparison_texts(key, rows)
    fields = ["paper_mean", "mean", "paper_sd", "sd"]
    header = ["density", "paper: mean", "ours: mean", "paper: SD", "ours: SD"]
    if any(row["mean_matches"] is not None for row in rows):
        fields.append("agrees")
        header.append("agrees")
    body = [
        [row["label"], *(texts[f"{key}_{row['id']}_{field}"] for field in fields)] for row in rows
    ]
    return MarkdownTable(header, body)


def rho_label(rho: float) -> str:
    """A noise level as the paper writes it, ``"1/200"`` (``1 / rho`` rounded to an integer)."""
    rho = _checks.positive_scalar(rho, "rho")
    return f"1/{1.0 / rho:.0f}"


def _pm(mean: float, sd: float, decimals: int) -> str:
    return f"{float(mean) + 0.0:.{decimals}f} ± {float(sd):.{decimals}f}"


def _row(rows: list[dict], name: str, quantity: str) -> dict:
    """The row of ``name`` for ``quantity``.

    The row is taken from :func:`depthcore.reproduce.reproduce`'s scenario rows.

    The optimal filter as derived, restricted to the front of the camera; the
    second-order filter with the covariance ``2 rho**2 J^-1``; the others' only row.
    """
    want = {"optimal": ("derived", "front"), "second_order": ("derived", "all")}.get(name)
    found = [
        r
        for r in rows
        if r["filter"] == name
        and r["quantity"] == quantity
        and (want is None or (r["reading"], r["support"]) == want)
    ]
    if len(found) != 1:
        raise ValueError(f"expected one row of {name!r} for {quantity!r}, found {len(found)}")
    return found[0]


def moments_texts(result: dict, decimals: int = 3) -> dict:
    """Texts ``"mean ± sd"`` of every filter in every scenario, for glue.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.reproduce.reproduce`.
    decimals : int

    Returns
    -------
    dict
        ``"bf_<key>_<filter>_<quantity>"``: ``"6.466 ± 0.799"`` for each
        scenario key, filter of :data:`depthcore.filters.FILTERS` and
        quantity; ``"bf_<key>_particle_<quantity>_se"``: the particle filter's
        Monte Carlo standard error (the larger of its mean's and SD's).
    """
    out = {}
    for sc in result["scenarios"]:
        for name in NAMES:
            for q in QUANTITIES:
                r = _row(sc["rows"], name, q)
                out[f"bf_{sc['key']}_{name}_{q}"] = _pm(r["mean"], r["sd"], decimals)
                if name == "particle":
                    out[f"bf_{sc['key']}_{name}_{q}_se"] = f"{r['error']:.{decimals}f}"
    return out


def study_texts(result: dict, prefix: str) -> dict:
    """Texts of every score of :func:`depthcore.study.study`'s result, for glue.

    Returns
    -------
    dict
        ``"<prefix>_<filter>_<quantity>_<score>"`` for the scores of
        :data:`STUDY_DECIMALS`, and ``"<prefix>_<filter>_nees"`` (1 decimal),
        ``"<prefix>_<filter>_hellinger"`` (3 decimals, ``"-"`` when not
        computed); ``"<prefix>_trials"``. Beside each, the same key with
        ``_pm`` appended: ``"value ± standard error"``, the standard error to
        the value's decimals (one more where it would round to zero).
    """
    out = {f"{prefix}_trials": str(result["valid_trials"])}
    for name, f in result["filters"].items():
        for q in QUANTITIES:
            for score, d in STUDY_DECIMALS.items():
                key = f"{prefix}_{name}_{q}_{score}"
                out[key] = f"{f[q][score] + 0.0:.{d}f}"
                out[f"{key}_pm"] = value_se(f[q][score], f[q][f"{score}_se"], d)
        out[f"{prefix}_{name}_nees"] = f"{f['nees']:.1f}"
        out[f"{prefix}_{name}_nees_pm"] = value_se(f["nees"], f["nees_se"], 1)
        h = f["hellinger_depth"]
        out[f"{prefix}_{name}_hellinger"] = "-" if h is None else f"{h['mean']:.3f}"
        out[f"{prefix}_{name}_hellinger_pm"] = "-" if h is None else value_se(h["mean"], h["se"], 3)
    return out


def value_se(value: float, se: float, decimals: int) -> str:
    """``"value ± se"``, both to ``decimals`` places, or more while the SE rounds to zero.

    Up to three more places are used, so a tiny but nonzero SE reads as such
    (``0.900 ± 0.0004``); an SE of exactly 0 is printed as 0.

    Parameters
    ----------
    value, se : float
        A Monte Carlo estimate and its standard error (>= 0).
    decimals : int
        Places of the value, >= 0.

    Returns
    -------
    str
    """
    d_se = decimals
    while se > 0 and round(se, d_se) == 0 and d_se < decimals + 3:
        d_se += 1
    return f"{value + 0.0:.{decimals}f} ± {se:.{d_se}f}"


def sweep_texts(result: dict, x: str, prefix: str, decimals: int = 3) -> dict:
    """Texts of a sweep's rows, for glue.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.noise_sweep` (``x="rho"``) or
        :func:`depthcore.experiments.prior_offset_sweep` (``x="offset"``).
    x : {"rho", "offset"}
    prefix : str
    decimals : int

    Returns
    -------
    dict
        For row ``i``: ``"<prefix>_<i>_x"`` (``"1/200"`` or the offset),
        ``"<prefix>_<i>_<filter>"`` (``"mean ± sd"`` of the depth) and
        ``"<prefix>_<i>_<filter>_h"`` (the Hellinger distance to the optimal
        filter, 3 decimals) for each filter in the result.
    """
    if x not in ("rho", "offset"):
        raise ValueError(f"x must be 'rho' or 'offset', got {x!r}")
    out = {}
    names = [n for n in NAMES if n in result]
    for i, value in enumerate(result[x]):
        out[f"{prefix}_{i}_x"] = rho_label(value) if x == "rho" else f"{float(value) + 0.0:g}"
        for name in names:
            r = result[name]
            out[f"{prefix}_{i}_{name}"] = _pm(r["depth_mean"][i], r["depth_sd"][i], decimals)
            out[f"{prefix}_{i}_{name}_h"] = f"{float(r['hellinger'][i]):.3f}"
    return out


def noise_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`~depthcore.experiments.noise_study`'s rows, for glue.

    Returns
    -------
    dict
        For row ``i``: ``"<prefix>_<i>_x"`` (``"1/200"``), ``"<prefix>_<i>_trials"``,
        and per filter ``"<prefix>_<i>_<filter>_cov68"``, ``"..._cov95"`` (2
        decimals), ``"..._rmse"`` (3 decimals), ``"..._nees"`` (1 decimal),
        each also with ``_pm`` appended: ``"value ± standard error"``
        (:func:`value_se`).
    """
    out = {}
    names = [n for n in NAMES if n in result]
    for i, rho in enumerate(result["rho"]):
        out[f"{prefix}_{i}_x"] = rho_label(rho)
        out[f"{prefix}_{i}_trials"] = str(int(result["valid_trials"][i]))
        for name in names:
            r = result[name]
            row = f"{prefix}_{i}_{name}"
            for key, score, d in SCORE_TEXTS:
                if score in ("bias", "mean_sd"):
                    continue
                out[f"{row}_{key}"] = f"{float(r[score][i]) + 0.0:.{d}f}"
                out[f"{row}_{key}_pm"] = value_se(r[score][i], r[f"{score}_se"][i], d)
    return out


def truth_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`~depthcore.experiments.truth_study`'s rows, for glue.

    Returns
    -------
    dict
        For truth ``i``: ``"<prefix>_<i>_truth"`` (``"(2, 10, 2)"``),
        ``"<prefix>_<i>_trials"``, and per filter ``"<prefix>_<i>_<filter>_<score>"``
        for the depth's ``bias``, ``rmse``, ``mean_sd`` (:data:`STUDY_DECIMALS`),
        ``cov68``, ``cov95`` (2 decimals) and ``nees`` (1 decimal), each also
        with ``_pm`` appended: ``"value ± standard error"`` (:func:`value_se`).
    """
    out = {}
    names = [n for n in NAMES if n in result]
    for i, truth in enumerate(result["truth"]):
        out[f"{prefix}_{i}_truth"] = "(" + ", ".join(f"{float(v):g}" for v in truth) + ")"
        out[f"{prefix}_{i}_trials"] = str(int(result["valid_trials"][i]))
        for name in names:
            r = result[name]
            row = f"{prefix}_{i}_{name}"
            for key, score, d in SCORE_TEXTS:
                out[f"{row}_{key}"] = f"{float(r[score][i]) + 0.0:.{d}f}"
                out[f"{row}_{key}_pm"] = value_se(r[score][i], r[f"{score}_se"][i], d)
    return out


def _frames_text(result: dict) -> str:
    """``"N frames, process noise q; "`` of a prior study beyond three frames, else ``""``."""
    frames, q = result.get("frames", 3), result.get("process_noise", 0.0)
    if frames == 3 and q == 0:
        return ""
    return f"{frames} frames, process noise {q:.6g}; "


def _at_frame(result: dict) -> str:
    """``" at frame N"`` of a prior study beyond the paper's problem, else ``""``."""
    return f" at frame {result['frames']}" if _frames_text(result) else ""


def format_prior_study(result: dict) -> str:
    """A plain-text table of :func:`depthcore.study.prior_study`'s result."""
    alpha = result["false_alarm"]
    lines = [
        f"truths drawn from the fixed prior N({vec(result['prior_mean'], 3)}, "
        f"{result['prior_cov'][0][0]:.6g} I) with the point in front of the camera; "
        f"{_frames_text(result)}rho {result['rho']:.6g}, seed {result['seed']}: "
        f"{result['valid_trials']} trials "
        f"({result['behind_camera_draws']} draws behind the camera redrawn, "
        f"{result['rejected_trials']} without a noise-free solution in front left out)",
        f"optimal filter{_at_frame(result)}: coverage of its central intervals "
        "(binomial SE in brackets)",
    ]
    head = f"{'nominal':>8} {'depth':>16} {'velocity':>16}"
    lines += [head, "-" * len(head)]
    for i, p in enumerate(result["levels"]):
        se = result["coverage_se"][i]
        cells = " ".join(
            f"{result[q]['coverage'][i]:>7.3f} ({se:.3f})".rjust(16) for q in ("depth", "velocity")
        )
        lines.append(f"{p:>8.2f} {cells}")
    lines.append(
        f"uniformity of the PIT values (each test at {alpha / 2:.3g}: "
        f"false-alarm rate {alpha:.3g} per quantity)"
    )
    for q in ("depth", "velocity"):
        r = result[q]
        verdict = "calibrated" if r["calibrated"] else "NOT calibrated"
        lines.append(
            f"{q:<9} KS p {r['ks_pvalue']:.3g}, chi-square p {r['chi2_pvalue']:.3g}: {verdict}"
        )
    lines.append(PRIOR_STUDY_LEGEND)
    return "\n".join(lines) + "\n"


def prior_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`depthcore.study.prior_study`'s result, for glue.

    Returns
    -------
    dict
        ``"<prefix>_trials"``, ``"<prefix>_prior_mean"``, ``"<prefix>_prior_scale"``,
        ``"<prefix>_false_alarm"`` and ``"<prefix>_test_level"`` (percent),
        ``"<prefix>_max_se"`` (largest deviation of a coverage from nominal, in
        binomial standard errors, 1 decimal), and per quantity ``q``:
        ``"<prefix>_<q>_coverage_50"``, ``_90`` and ``_95`` (2 decimals, when
        those levels are reported),
        ``"<prefix>_<q>_ks"``, ``"<prefix>_<q>_chi2"`` (p-values, 2 decimals) and
        ``"<prefix>_<q>_verdict"``.
    """
    levels = list(result["levels"])
    se = np.asarray(result["coverage_se"])
    out = {
        f"{prefix}_trials": str(result["valid_trials"]),
        f"{prefix}_prior_mean": vec(result["prior_mean"], 1),
        f"{prefix}_prior_scale": f"{result['prior_cov'][0][0]:g}",
        f"{prefix}_false_alarm": f"{100 * result['false_alarm']:g} %",
        f"{prefix}_test_level": f"{50 * result['false_alarm']:g} %",
    }
    worst = 0.0
    for q in QUANTITIES:
        r = result[q]
        cov = np.asarray(r["coverage"])
        worst = max(worst, float(np.max(np.abs(cov - np.asarray(levels)) / se)))
        for p in (0.5, 0.9, 0.95):
            if p in levels:
                out[f"{prefix}_{q}_coverage_{round(100 * p)}"] = f"{cov[levels.index(p)]:.2f}"
        out[f"{prefix}_{q}_ks"] = f"{r['ks_pvalue']:.2f}"
        out[f"{prefix}_{q}_chi2"] = f"{r['chi2_pvalue']:.2f}"
        out[f"{prefix}_{q}_verdict"] = "passes" if r["calibrated"] else "fails"
    out[f"{prefix}_max_se"] = f"{worst:.1f}"
    return out


# --- the benchmarks' records -----------------------------------------------------------------


def _sci(x: float, digits: int = 1) -> str:
    """``x`` in scientific notation without a plus sign or leading zeros: ``"1.5e8"``."""
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def bench_origin(record: dict) -> str:
    """When and where a benchmark's record was measured, as the book and the README state it.

    Parameters
    ----------
    record : dict
        From :func:`depthcore.benchmarks.read`.

    Returns
    -------
    str
        E.g. ``"2026-11-25 on 2 cores (AMD EPYC), Python 3.11.7, NumPy 2.4.6, SciPy 1.17.1"``.
    """
    m = record["machine"]
    return (
        f"{record['date'][:10]} on {m['cores']} cores ({m['cpu']}), Python {m['python']}, "
        f"NumPy {m['numpy']}, SciPy {m['scipy']}"
    )


def _optimal_bench_texts(r: dict) -> dict[str, str]:
    m, t = r["results"]["moments"], r["results"]["per_triple"]
    out = {
        "one_d_ms": f"{m['one_d_ms']:.2f}",
        "one_d_error": _sci(m["one_d_error_sd"]),
        "one_d_estimate": _sci(m["one_d_estimate_sd"]),
        "grid_rule": f"{m['grid_panels']} x 8 depth, {m['grid_order']}^2 (x, v) nodes",
        "grid_ms": f"{m['grid_ms']:.0f}",
        "grid_error": _sci(m["grid_error_sd"]),
        "grid_ratio": f"{m['grid_ratio']:,.0f}",
    }
    if "nquad_one_integral_s" in m:
        out.update(
            nquad_s=f"{m['nquad_one_integral_s']:.1f}",
            nquad_error=_sci(m["nquad_relative_error"]),
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
        "estimate": _sci(x["estimate_sd"]),
        "difference": _sci(x["difference_sd"]),
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
        "mean_difference": _sci(x["mean_difference_sd"]),
        "cov_max": _sci(x["covariance_difference_max"]),
        "cov_median": _sci(x["covariance_difference_median"]),
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
        "mean_difference": _sci(x["mean_difference_sd"]),
        "cov_max": _sci(x["covariance_difference_max"]),
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
        "three_difference": _sci(three["difference_sd"]),
        "three_target": f"{x['targets']['three_frames_ratio']:g}",
        "online_trials": f"{online['trials']:,}",
        "online_frames": f"{online['frames']:,}",
        "online_windows": f"{len(online['windows'])}",
        "many_trials": f"{many['trials']:,}",
        "many_frames": f"{many['frames']}",
        "many_s": f"{many['time_s']:.1f}",
        "many_target_s": f"{many['target_s']:g}",
        "many_met": "met" if many["time_s"] < many["target_s"] else "not met",
        "many_worst": _sci(many["worst_error_estimate_sd"]),
        "matched_trials": f"{matched['trials']}",
        "matched_frames": f"{matched['frames']}",
        "matched_replicas": f"{matched['replicas']}",
        "matched_bank_s": f"{matched['bank_time_s']:.3f}",
        "matched_ratio": f"{matched['ratio']:,.0f}",
        "matched_target_ratio": f"{matched['target_ratio']:g}",
        "matched_largest": f"{matched['particles'][-1]:,}",
        "matched_largest_s": f"{matched['time_per_run_s'][-1]:.2f}",
        "matched_largest_error": _sci(matched["error_sd"][-1], 2),
        "matched_target_error": _sci(matched["target_error_sd"], 0),
        "matched_extrapolated_needed": _sci(matched["extrapolated_particles_needed"]),
        "matched_extrapolated_s": _sci(matched["extrapolated_time_s"]),
        "matched_extrapolated_ratio": _sci(matched["extrapolated_ratio"]),
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
        out[f"matched_{i}_error"] = _sci(e, 2)
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


#: The problems of ``bench_range_ekf`` and how the README names them.
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
        Its record, from :func:`depthcore.benchmarks.read`.

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
    """The README's benchmark tables, from the records.

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
            ["depthcore.ekf.run, vectorised", t["ekfpy_depthcore_ms"] + ms, "1"],
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


def bench_readme_blocks(records: dict) -> dict[str, str]:
    """The README's benchmark blocks: each table of :func:`bench_tables` with its notes.

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
        lines = [table._repr_markdown_().rstrip("\n"), ""]
        if key in notes:
            lines += [notes[key], ""]
        lines.append(
            f"Measured {t[prefixes[name] + '_origin']} (`depthcore/benchmark_records/{name}.json`)."
        )
        blocks[key] = "\n".join(lines)
    return blocks


# --- the book's pages as plain notebooks ---------------------------------------------------


def rbpf_texts(result: dict, prefix: str) -> dict:
    """Texts of the Rao-Blackwellised particle filter's convergence table, for glue.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.rbpf_convergence`.
    prefix : str

    Returns
    -------
    dict
        For row ``i`` (one number of particles): ``"<prefix>_<i>_J"``;
        ``"<prefix>_<i>_mean"`` and ``"<prefix>_<i>_sd"``, the clouds'
        average depth mean and SD with their standard errors (``"mean ± se"``,
        4 decimals); ``"<prefix>_<i>_rmse_mean"`` and ``"<prefix>_<i>_rmse_sd"``,
        one cloud's RMS errors of the depth mean and SD (2 significant digits).
        ``"<prefix>_exact_mean"`` and ``"<prefix>_exact_sd"``: the exact bank's
        depth mean and SD (4 decimals).
    """
    out = {
        f"{prefix}_exact_mean": f"{result['exact']['depth_mean']:.4f}",
        f"{prefix}_exact_sd": f"{result['exact']['depth_sd']:.4f}",
    }
    for i, J in enumerate(result["sizes"]):
        out[f"{prefix}_{i}_J"] = f"{int(J):,}"
        for key, moment in (("mean", "depth_mean"), ("sd", "depth_sd")):
            out[f"{prefix}_{i}_{key}"] = (
                f"{result['mean'][moment][i]:.4f} ± {result['se'][moment][i]:.4f}"
            )
            out[f"{prefix}_{i}_rmse_{key}"] = f"{result['rmse'][moment][i]:.2g}"
    return out


class MarkdownTable:
    """A table that Jupyter shows as Markdown (with its math) and as aligned text.

    Parameters
    ----------
    header : sequence of str, shape (n_columns,)
    rows : sequence of sequence of str, shape (n_rows, n_columns)
    """

    def __init__(self, header, rows):
        self.header = [str(cell) for cell in header]
        self.rows = [[str(cell) for cell in row] for row in rows]
        if not self.header:
            raise ValueError("header must name at least one column")
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(
                    f"rows must have {len(self.header)} cells each, got a row of {len(row)}"
                )

    def _repr_markdown_(self) -> str:
        def line(cells):
            return "| " + " | ".join(c.replace("|", r"\|") for c in cells) + " |"

        lines = [line(self.header), line(["---"] * len(self.header))]
        return "\n".join(lines + [line(row) for row in self.rows]) + "\n"

    def __repr__(self) -> str:
        table = [self.header, *self.rows]
        widths = [max(len(row[j]) for row in table) for j in range(len(self.header))]
        lines = [
            "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
            for row in table
        ]
        lines.insert(1, "  ".join("-" * w for w in widths))
        return "\n".join(lines)


#: A role that pastes a glued text into a page's text, ``eval`` (which the book
#: resolves to the text glued under its name, and JupyterLab evaluates in the
#: page's kernel), ``glue:text`` or plain ``glue``; group 1 is the glued name.
GLUE_ROLE = re.compile(r"\{(?:eval|glue(?::text)?)\}`([A-Za-z_][A-Za-z0-9_]*)`")


def page_tables(text: str) -> list[list[str]]:
    """The pipe tables of a MyST page that paste glued texts, each as its lines.

    Lines inside code cells (fenced blocks) are not the page's text and are
    passed over; a table is a run of lines that start with ``|``, stripped.

    Parameters
    ----------
    text : str
        The page's MyST Markdown source.

    Returns
    -------
    list of list of str
        The tables that hold at least one ``glue:text`` role, in page order.
    """
    tables, current, fence = [], [], None
    for line in text.splitlines() + [""]:
        stripped = line.strip()
        marker = re.match(r"^(`{3,}|:{3,})", stripped)
        if fence is None and marker and "{code-cell}" in stripped:
            fence = marker.group(1)
            continue
        if fence is not None:
            if stripped == fence:
                fence = None
            continue
        if stripped.startswith("|"):
            current.append(stripped)
        elif current:
            tables.append(current)
            current = []
    return [t for t in tables if any(GLUE_ROLE.search(line) for line in t)]


def page_text(page) -> str:
    """The text of a book page outside its code cells, from its source or its notebook.

    Parameters
    ----------
    page : str or path
        ``"fig6"``, ``"fig6.md"`` or ``"fig6.ipynb"``: the page's MyST source
        ``fig6.md`` is read if it exists, else the notebook ``fig6.ipynb`` (the
        page as the book offers it for download), whose markdown cells are
        joined.

    Returns
    -------
    str
        The page's text; empty when neither file exists.
    """
    import json

    path = Path(page)
    source, notebook = path.with_suffix(".md"), path.with_suffix(".ipynb")
    if source.is_file():
        return source.read_text(encoding="utf-8")
    if notebook.is_file():
        cells = json.loads(notebook.read_text(encoding="utf-8")).get("cells", [])
        return "\n\n".join(
            "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
            for cell in cells
            if cell.get("cell_type") == "markdown"
        )
    return ""


def paste_table(lines: list[str], texts: dict[str, str]) -> str | None:
    """A page's table with every glued text pasted in, as the book shows it.

    Parameters
    ----------
    lines : list of str
        One table of :func:`page_tables`.
    texts : dict of str to str
        Glued names and their texts, as ``glue:text`` pastes them.

    Returns
    -------
    str or None
        The table's lines joined by newlines; ``None`` while a name it pastes
        has not been glued.
    """
    names = [m.group(1) for line in lines for m in GLUE_ROLE.finditer(line)]
    if any(name not in texts for name in names):
        return None
    return "\n".join(GLUE_ROLE.sub(lambda m: texts[m.group(1)], line) for line in lines)


class PastedTable:
    """A page's table with its glued numbers, shown by Jupyter as Markdown and as text.

    Parameters
    ----------
    text : str
        From :func:`paste_table`.
    """

    def __init__(self, text: str):
        self.text = text

    def _repr_markdown_(self) -> str:
        return self.text + "\n"

    def __repr__(self) -> str:
        return self.text


class GluedText(str):
    """A glued text, bound to its name in the kernel by :class:`GlueLog`.

    Its ``repr`` is the text itself, so Jupyter shows it as the book pastes it
    (``0.25``, not ``'0.25'``) where an ``{eval}`` role of the page names it.
    """

    __slots__ = ()

    def __repr__(self) -> str:
        return str(self)


class GluedOutput:
    """A glued figure (or other display), bound to its name in the kernel by :class:`GlueLog`.

    Displayed, it shows the very output that the book pastes (its media types
    and their metadata, as glued), where an ``{eval}`` role of the page names
    it: the figure of a ``{figure}`` directive whose content is
    ``{eval}`name```.

    Parameters
    ----------
    data : dict
        The glued output's data by media type (``image/png``, ``text/plain``, ...).
    metadata : dict
        Its metadata by media type.
    """

    __slots__ = ("data", "metadata")

    def __init__(self, data: dict, metadata: dict):
        self.data = dict(data)
        self.metadata = dict(metadata)

    def _repr_mimebundle_(self, include=None, exclude=None):
        return self.data, self.metadata

    def __repr__(self) -> str:
        return str(self.data.get("text/plain", "<glued output>"))


class GlueLog:
    """Shows in Jupyter what a book page glues into the book's text.

    A page glues its numbers and figures with ``myst_nb.glue(name, value,
    display=False)``: the book pastes them where its text names them
    (the ``glue:text`` and ``glue:figure`` roles), but a plain notebook shows nothing of
    them. A ``GlueLog`` created in the page's kernel keeps a copy of every such
    record, which passes on unchanged, and :meth:`show` displays those kept
    since its last call: each figure as the very image the book shows, and the
    texts in a :class:`MarkdownTable` of glued name and value, as the book
    pastes them. Given the page's name, :meth:`show` also displays each of the
    page's tables of glued numbers (:func:`page_tables`) whole, with its
    numbers pasted in, once every number in it has been glued. The book leaves
    the cells that create and show it out.

    The tables are read from the page's own file in the kernel's working
    folder (:func:`page_text`): its MyST source (``fig6.md``) where the book's
    pages are, else the notebook that the book offers for download
    (``fig6.ipynb``), which runs alone in any folder. Where neither is found
    (a renamed download), the values are still shown, in the table of glued
    names, and the page's tables are not.

    Every glued text is also bound, as a :class:`GluedText`, to its name in the
    kernel's namespace, where JupyterLab's MyST renderer (jupyterlab-myst)
    evaluates the page's ``{eval}`name``` roles: the prose shows each number
    where the book pastes it, once the cell that glues it has run; every
    other glued output (a figure) as a :class:`GluedOutput`, which the
    ``{eval}`` role of a ``{figure}`` directive shows with its caption. The
    functions of a :class:`depthcore.crossref.BookReferences` (``cite_t``,
    ``cite_p``, ``eq``, ``numref``, ``ref``, ``doc``) are bound too: the
    page's references, written as ``{eval}`` roles, show the book's numbers,
    titles and citations.

    Parameters
    ----------
    page : str or path, optional
        The page's name or source, ``"fig6"`` or ``"fig6.md"`` (relative to the
        kernel's working folder, the page's folder in Jupyter as in the book's
        build).

    Raises
    ------
    RuntimeError
        Outside a Jupyter kernel (ipykernel), where there is nothing to watch.
    ValueError
        From ``glue``, when a text is glued under a name that the page's code
        uses for something else (it would be overwritten).
    """

    #: The prefix of the media types of a record that is not displayed (myst_nb's).
    PREFIX = "application/papermill.record/"

    def __init__(self, page=None):
        from IPython import get_ipython

        shell = get_ipython()
        publisher = getattr(shell, "display_pub", None)
        if not hasattr(publisher, "register_hook"):
            raise RuntimeError("GlueLog runs in a Jupyter kernel (ipykernel) only")
        self._namespace = shell.user_ns
        self._kept: list[tuple[str, dict, dict]] = []
        self._texts: dict[str, str] = {}
        self._tables = [] if page is None else page_tables(page_text(page))
        self._namespace.update(BookReferences().functions())
        publisher.register_hook(self._keep)

    def _keep(self, msg):
        content = msg.get("content", {})
        glued = content.get("metadata", {}).get("scrapbook")
        if msg.get("msg_type") == "display_data" and glued and glued.get("mime_prefix"):
            n = len(glued["mime_prefix"])
            data = {k[n:]: v for k, v in content["data"].items()}
            metadata = {k: v for k, v in content["metadata"].items() if k != "scrapbook"}
            self._kept.append((glued["name"], data, metadata))
            if set(data) == {"text/plain"}:
                self._bind(glued["name"], GluedText(self.pasted_text(data["text/plain"])))
            else:
                self._bind(glued["name"], GluedOutput(data, metadata))
        return msg

    def _bind(self, name: str, value) -> None:
        current = self._namespace.get(name)
        if name in self._namespace and not isinstance(current, (GluedText, GluedOutput)):
            raise ValueError(
                f"name {name!r} is glued but also names a {type(current).__name__} "
                "of the page's code: glue the value under another name"
            )
        self._namespace[name] = value

    @staticmethod
    def pasted_text(text: str) -> str:
        """A record's ``text/plain`` as the ``glue:text`` role pastes it, without quotes."""
        try:
            return str(ast.literal_eval(text))
        except (SyntaxError, ValueError):
            return text

    def show(self) -> None:
        """Display what was glued since the last call: figures, a table of the texts.

        Then the page's tables whose numbers are now all glued, each once.
        """
        from IPython.display import display

        texts = []
        for name, data, metadata in self._kept:
            if set(data) == {"text/plain"}:
                texts.append([name, self.pasted_text(data["text/plain"])])
                self._texts[name] = texts[-1][1]
            else:
                display(data, raw=True, metadata=metadata)
        if texts:
            display(MarkdownTable(["glued name", "value"], texts))
        self._kept.clear()
        pending = []
        for table in self._tables:
            pasted = paste_table(table, self._texts)
            if pasted is None:
                pending.append(table)
            else:
                display(PastedTable(pasted))
        self._tables = pending


# --- more frames ----------------------------------------------------------------------------


def frames_study_texts(result: dict, prefix: str) -> dict:
    """Counts of :func:`~depthcore.experiments.frames_study`'s failed coverage tests, for glue.

    Each filter's coverages of the central 68 % and 95 % intervals at every
    ``N`` are tested by :func:`depthcore.experiments.coverage_test`
    (two-sided, 1 %) against their nominal levels over the filter's trials.

    Returns
    -------
    dict
        ``"<prefix>_tests"`` (tests per filter: two levels at every ``N``) and
        per filter ``"<prefix>_<filter>_fails"`` (the tests it fails, as
        overconfident or as underconfident).
    """
    from .experiments import coverage_test

    out = {f"{prefix}_tests": str(2 * len(result["frames"]))}
    for name, r in result.items():
        if not isinstance(r, dict):
            continue
        verdicts = np.concatenate(
            [
                np.atleast_1d(coverage_test(r[f"coverage_{lv}"], lv / 100, r["trials"])["verdict"])
                for lv in (68, 95)
            ]
        )
        out[f"{prefix}_{name}_fails"] = str(int(np.sum(verdicts != "calibrated")))
    return out


def conjecture_texts(result: dict, wins: dict, prefix: str) -> dict:
    """Counts of the cells of :func:`~depthcore.experiments.conjecture_wins`, for glue.

    Returns
    -------
    dict
        ``"<prefix>_cells"`` (cells per ``N``: noise levels times depths) and,
        for the ``j``-th ``N``: ``"<prefix>_<j>_x"`` (``N``),
        ``"<prefix>_<j>_<score>"`` (cells where the second-order filter wins,
        for ``"hellinger"``, ``"rmse"``, ``"coverage_68"``, ``"coverage_95"``)
        and ``"<prefix>_<j>_cal<level>_<filter>"`` (cells where the filter's
        coverage passes the test) for ``"optimal"``, ``"second_order"``, ``"ekf"``.
    """
    n_rho, n_depth = len(result["rho"]), len(result["depth"])
    out = {f"{prefix}_cells": str(n_rho * n_depth)}
    for j, n in enumerate(result["frames"]):
        out[f"{prefix}_{j}_x"] = str(int(n))
        for score in ("hellinger", "rmse", "coverage_68", "coverage_95"):
            out[f"{prefix}_{j}_{score}"] = str(int(np.sum(wins[score][..., j])))
        for level in (68, 95):
            for name, ok in wins[f"calibrated_{level}"].items():
                out[f"{prefix}_{j}_cal{level}_{name}"] = str(int(np.sum(ok[..., j])))
    return out


#: The depth scores of every filter that :func:`hard_texts` formats.
HARD_SCORES = ("rmse", "mean_sd", "coverage_68", "coverage_95")


def hard_label(cell: dict) -> str:
    """A setting of :func:`depthcore.hardness.hard_cell`: truth, prior covariance, its velocity."""
    x, y, v = (float(a) for a in cell["truth"])
    s = float(cell["prior_cov"][0, 0])
    return f"({x:g}, {y:g}, {v:g}); {s:g} I; v₀ = {float(cell['prior_mean'][2]):g}"


def hard_texts(cells: list, prefix: str) -> dict:
    """Texts of :func:`depthcore.hardness.hard_study`'s cells, for glue.

    Returns
    -------
    dict
        For the ``i``-th cell: ``"<prefix>_<i>_x"`` (:func:`hard_label`),
        ``"<prefix>_<i>_d2"`` (the bearings' second difference over ``rho``),
        ``"<prefix>_<i>_bound"`` (the bound's depth SD), and for each reading
        ``r`` (``"fixed"``, ``"prior"``), filter and score of
        :data:`HARD_SCORES` ``"<prefix>_<i>_<r>_<filter>_<score>"``:
        ``"value ± standard error"`` (:func:`value_se`; two decimals for the
        coverages, three significant figures' worth for the depths).
    """
    out = {}
    for i, c in enumerate(cells):
        out[f"{prefix}_{i}_x"] = hard_label(c)
        out[f"{prefix}_{i}_d2"] = f"{round(c['second_difference'], 1) + 0.0:.1f}"
        out[f"{prefix}_{i}_bound"] = f"{c['bound_sd']:.3g}"
        for reading in ("fixed", "prior"):
            for name, s in c[reading]["filters"].items():
                for score in HARD_SCORES:
                    if score.startswith("coverage"):
                        decimals = 2
                    else:
                        decimals = max(0, 2 - int(np.floor(np.log10(max(abs(s[score]), 1e-3)))))
                    out[f"{prefix}_{i}_{reading}_{name}_{score}"] = value_se(
                        s[score], s[f"{score}_se"], decimals
                    )
    return out
