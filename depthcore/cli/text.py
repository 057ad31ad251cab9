"""The command line's plain-text tables and their legends.

Recommended import: ``from depthcore.cli import text``.

Nothing here computes: :func:`format_table` formats what
:func:`depthcore.studies.reproduce.reproduce` returns, :func:`format_summary` what
:func:`depthcore.studies.reproduce.summarize` returns, :func:`format_study` and
:func:`format_prior_study` what :func:`depthcore.studies.monte_carlo.study` and
:func:`depthcore.studies.monte_carlo.prior_study` return (the study chapter prints them too).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterator

import numpy as np

from depthcore.cli.priors import RULE as PRIOR_RULE
from depthcore.cli.tracks import FORMAT as TRACK_FORMAT
from depthcore.problem import checks

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

#: The legend of :func:`format_summary`'s columns of a point in 3-D (pairs).
SPACE_LEGEND = """\
        height mean, sd       the same of the height h; vert. vel. mean, sd of its velocity w"""


#: The legend of :func:`format_summary`'s smoothed columns.
SMOOTHED_LEGEND = """\
        frame                 the frame's number in the track (time: its time in seconds,
                              where the track has one); depth mean, depth sd and x mean, x sd:
                              the optimal filter's mean and SD of the depth y and the lateral
                              position x at that frame given all N bearings"""


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


def vec(values, decimals: int = 4) -> str:
    """A vector as the command line and the book print it: ``"(1.2000, 6.0000, 1.2000)"``.

    Rounds first, so that a value that rounds to zero prints as ``0.0000``,
    never ``-0.0000``.

    Parameters
    ----------
    values : array_like, shape (n,)
    decimals : int
        Places after the decimal point, >= 0.
    """
    values = checks.finite_array(values, "values")
    if values.ndim != 1:
        raise ValueError(f"values must be 1-D, got shape {values.shape}")
    if int(decimals) != decimals or decimals < 0:
        raise ValueError(f"decimals must be a non-negative integer, got {decimals!r}")
    decimals = int(decimals)
    return "(" + ", ".join(f"{v + 0.0:.{decimals}f}" for v in np.round(values, decimals)) + ")"


def format_table(result: dict) -> str:
    """A plain-text table of :func:`~depthcore.studies.reproduce.reproduce`'s result."""
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
    """A plain-text rendering of :func:`~depthcore.studies.reproduce.summarize`'s result."""
    c = summary["c"]
    m, cov = summary["prior_mean"], np.asarray(summary["prior_cov"])
    if np.array_equal(cov, cov[0, 0] * np.eye(len(m))):
        cov_text = f"{cov[0, 0]:.4g} I"
    else:
        cov_text = "[" + "; ".join(" ".join(f"{v:.4g}" for v in row) for row in cov) + "]"
    N = summary.get("frames", 3)
    q = summary.get("process_noise", 0.0)
    number = summary.get("frame_numbers", list(range(1, N + 1)))
    undefined = "undefined" + (f": {summary['c_reason']}" if summary.get("c_reason") else "")
    lines = [
        f"noise-free state c = (x, y, v) at frame {number[min(2, N - 1)]} = "
        + (undefined if c is None else f"({c[0]:#.4g}, {c[1]:#.4g}, {c[2]:#.4g})"),
        f"prior at frame {number[0]}: mean {'(x, y, v, h, w)' if len(m) == 5 else '(x, y, v)'}"
        f" = ({', '.join(f'{v:#.4g}' for v in m)}), covariance {cov_text}",
    ]
    if "prior_depth" in summary:
        lines.append(depth_law_text(summary["prior_depth"]))
    if "direction" in summary:
        lines.append(direction_text(summary))
    missing = sum(v is None for v in summary["mu"])
    if N != 3 or q > 0 or missing or "steps" in summary or np.ndim(summary["rho"]):
        lines.append(
            f"{N} frames, process noise q = {q:g}; every filter at frame "
            + _frame_label(summary, N - 1)
        )
    if missing or "steps" in summary or np.ndim(summary["rho"]):
        steps = summary.get("steps")
        lines.append(
            f"{missing} missing frames; "
            + ("unit steps" if steps is None else f"steps {min(steps):.4g} to {max(steps):.4g}")
            + "; "
            + (
                f"rho = {summary['rho']:.4g}"
                if np.ndim(summary["rho"]) == 0
                else f"rho per frame, {min(summary['rho']):.4g} to {max(summary['rho']):.4g}"
            )
        )
    w = max([13, *(len(n) + 1 for n in [*summary["filters"], *summary.get("not_run", {})])])
    space = len(m) == 5  # pairs: a point in 3-D
    columns = _SUMMARY_COLUMNS if space else _SUMMARY_COLUMNS[:2]
    lines.append(
        f"{'filter':<{w}}"
        + "".join(f" {h + ' mean':>{width}} {h + ' sd':>10}" for _, h, width in columns)
    )
    for name in summary["filters"]:
        f = summary["filters"][name]
        lines.append(
            f"{name:<{w}}"
            + "".join(
                f" {f[k]['mean']:>#{width}.4g} {f[k]['sd']:>#10.4g}" for k, _, width in columns
            )
        )
    for name, f in summary["filters"].items():
        if f.get("sigma_points_behind_camera"):
            lines.append(f"{name:<{w}} its sigma points went behind the camera (y <= 0)")
        if "gated" in f:
            times = f.get("gated_times", [None] * len(f["gated"]))
            skipped = ", ".join(map(_label, f["gated"], times)) or "none"
            lines.append(f"{name:<{w}} gate skipped frames: {skipped}")
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
        frames = sm.get("frame", list(range(1, N + 1)))
        times = sm.get("times")
        w = max(5, *(len(str(f)) for f in frames))
        lines.append(
            f"{'frame':>{w}}"
            + (f" {'time':>10}" if times else "")
            + f" {'depth mean':>11} {'depth sd':>10} {'x mean':>10} {'x sd':>10}"
            "   (optimal, smoothed)"
        )
        for k, row in enumerate(
            zip(sm["depth_mean"], sm["depth_sd"], sm["lateral_mean"], sm["lateral_sd"], strict=True)
        ):
            cells = " ".join(f"{v:>#10.4g}" for v in row).replace(" ", "  ", 1)
            time = f" {times[k]:>10.4g}" if times else ""
            lines.append(f"{frames[k]:>{w}}{time} {cells}")
    lines.append(SUMMARY_LEGEND + ("\n" + SPACE_LEGEND if space else ""))
    if "smoothed" in summary:
        lines.append(SMOOTHED_LEGEND)
    return "\n".join(lines) + "\n"


#: The columns of :func:`format_summary`'s table: a moment's key, the column's name and the
#: mean's width; a point in 3-D (pairs) has all four, the plane the first two.
_SUMMARY_COLUMNS = (
    ("depth", "depth", 11),
    ("velocity", "vel.", 10),
    ("height", "height", 11),
    ("vertical_velocity", "vert. vel.", 15),
)


def _label(frame, time=None) -> str:
    """A frame named by its number, and its time where the track has one."""
    return str(frame) if time is None else f"{frame} (t = {time:.6g} s)"


def _frame_label(summary: dict, k: int) -> str:
    """The name of a summary's frame ``k`` (from 0): its number, and its time if it has one."""
    number = summary.get("frame_numbers", [k + 1])[k if "frame_numbers" in summary else 0]
    return _label(number, summary["times"][k] if "times" in summary else None)


def _error(value) -> str:
    """An error estimate in a table: ``n/a`` where there is none or it is not finite."""
    return "n/a" if value is None or not np.isfinite(value) else f"{value:.1e}"


def format_study(result: dict) -> str:
    """A plain-text table of :func:`~depthcore.studies.monte_carlo.study`'s result."""
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
            lines.append(_study_row(f, q, name, q, ""))
            lines.append(_study_row(f, q, "", "(se)", "_se"))
    refused = [
        f"{name} {f['refused']['count']}"
        for name, f in result["filters"].items()
        if f.get("refused", {}).get("count", 0)
    ]
    if refused:
        lines.append(
            f"trials refused, of {result['valid_trials']} (each filter scored over the "
            f"trials it answers): {', '.join(refused)}"
        )
    lines.append(STUDY_LEGEND)
    return "\n".join(lines) + "\n"


#: The columns of :func:`format_study`'s table: each score and its format.
_STUDY_COLUMNS = (
    ("bias", ">9.4f"),
    ("rmse", ">9.4f"),
    ("mean_sd", ">9.4f"),
    ("coverage_68", ">8.3f"),
    ("coverage_95", ">8.3f"),
)


def _study_row(f: dict, q: str, name: str, label: str, suffix: str) -> str:
    """One line of :func:`format_study`'s table: a filter's scores of ``q``, or their SEs.

    Parameters
    ----------
    f : dict
        One filter's scores, ``study(...)["filters"][name]``.
    q : {"depth", "velocity"}
    name, label : str
        The line's first two cells.
    suffix : {"", "_se"}
        The scores, or their standard errors; the depth's line adds the NEES
        and the Hellinger distance (``-`` where it was not computed).
    """
    cells = " ".join(format(f[q][score + suffix], spec) for score, spec in _STUDY_COLUMNS)
    extra = ""
    if q == "depth":
        h = f["hellinger_depth"]
        missing = "" if suffix else "-"
        hellinger = (
            missing.rjust(9) if h is None else format(h["se" if suffix else "mean"], ">9.3f")
        )
        extra = f"{f['nees' + suffix]:>8.2f} {hellinger}"
    return f"{name:<13} {label:<9} {cells} {extra}".rstrip()


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
    """A plain-text table of :func:`depthcore.studies.monte_carlo.prior_study`'s result."""
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


#: The legend of :func:`per_frame_text`'s table.
PER_FRAME_LEGEND = """\
legend: frame    the frame's number in the track (time: its time in seconds, where the
                 track has one); bearing: yes, no (a missing frame: the filter predicts
                 through it) or gated (skipped: its predictive tail probability was below
                 the gate)
        mu       the bearing (blank at a missing frame); nu: a pair's vertical bearing
        filtered the state at the frame given the bearings up to it: mean (SD) of the depth
                 y, the lateral position x and the velocity v (with pairs, the height h and
                 its velocity w)
        smoothed the same given every bearing of the track (at the last frame, the filtered)
        tail     the two-sided tail probability of the bearing under the filter's predictive
                 density (small: an outlier)"""


def _cell(value, spec: str) -> str:
    """A number in a table, blank where there is none or it is not finite."""
    return "" if value is None or not np.isfinite(value) else format(value, spec)


def format_learned(result: dict) -> str:
    """The lines of ``--learn-noise``'s estimates, or nothing without them.

    A ``rho`` column's learned factor is named its scale; the intervals are named
    by their kind (the profile likelihood's); with a gate, the frames it skipped.
    """
    fit = result.get("learned")
    if fit is None:
        return ""
    kind = f"{fit['level']:.0%} {fit['intervals']}-likelihood"

    def one(name, symbol):
        value, se, interval = fit[name], fit[f"{name}_se"], fit[f"{name}_interval"]
        if name not in fit["estimated"]:
            return f"{symbol} = {value:.4g} (given)"
        if interval is None:  # the likelihood's curvature gave none
            return f"{symbol} = {value:.4g} (no interval)"
        if se is None:  # at the boundary q = 0: a one-sided interval
            return f"{symbol} = {value:.4g} (at 0; {kind} upper bound {interval[1]:.3g})"
        return (
            f"{symbol} = {value:.4g} ± {se:.2g} ({kind} interval "
            f"{interval[0]:.4g} to {interval[1]:.4g})"
        )

    rho = "rho_column_scale" if "rho_column_scale" in fit else "rho"
    text = f"learned by maximum likelihood: {one(rho, rho.replace('_', ' '))}; "
    text += one("process_noise", "q") + "\n"
    if "gate_skipped" in fit:
        times = fit.get("gate_skipped_times", [None] * len(fit["gate_skipped"]))
        skipped = ", ".join(map(_label, fit["gate_skipped"], times)) or "none"
        text += f"learning's gate skipped frames: {skipped}\n"
    return text


def per_frame_text(head: dict, blocks: dict, output: str) -> Iterator[str]:
    """A per-frame result as text, chunk by chunk: a table, CSV or JSON (``output``).

    ``head`` holds the result's keys but ``"filters"`` (those of
    :func:`depthcore.registry.track_runs.per_frame`'s result, the learned noise
    and the direction of :func:`direction_text`), ``blocks`` each filter's rows,
    each read once, in order: a list, or rows read back one at a time. The JSON
    is :func:`as_json`'s of the whole result; the CSV has a row per filter and
    frame, its columns ``filter`` and the keys of a row (a missing value an
    empty field, booleans ``true`` and ``false``, numbers with every digit).
    """
    return {"table": _table_chunks, "csv": _csv_chunks, "json": _json_chunks}[output](head, blocks)


def _table_chunks(head: dict, blocks: dict) -> Iterator[str]:
    m, q = head["prior_mean"], head["process_noise"]
    yield format_learned(head) + (
        f"{head['frames']} frames; prior at the first frame: mean "
        f"{'(x, y, v, h, w)' if len(m) == 5 else '(x, y, v)'} = "
        f"({', '.join(f'{v:#.4g}' for v in m)}); process noise q = {q:g}"
        + ("" if head["gate"] is None else f"; gate {head['gate']:g}")
        + ("" if "prior_depth" not in head else "\n" + depth_law_text(head["prior_depth"]))
        + f"\n{direction_text(head)}\n"
    )
    if not head["smoothed"]:
        yield f"smoothed: not computed, {head['smoothed_reason']}\n"
    series = ("filtered", "smoothed") if head["smoothed"] else ("filtered",)
    for name, rows in blocks.items():
        for k, r in enumerate(rows):
            if k == 0:
                timed, tail = "time" in r, "tail" in r
                state = _STATE if "nu" in r else _STATE[:3]
                bearings = ("mu", "nu") if "nu" in r else ("mu",)
                top = f"{'frame':>6}" + (f" {'time':>10}" if timed else "")
                top += f" {'bearing':<7}" + "".join(f" {b:>10}" for b in bearings)
                for s in series:
                    top += "  " + " ".join(f"{key + ' ' + s:>19}" for _, key in state)
                yield f"\n{name}:\n{top}" + (f" {'tail':>8}" if tail else "") + "\n"
            flag = "gated" if r.get("gated") else ("yes" if r["bearing"] else "no")
            cells = f"{r['frame']:>6}" + (f" {r['time']:>10.4g}" if timed else "")
            cells += f" {flag:<7}" + "".join(f" {_cell(r[b], '.6g'):>10}" for b in bearings)
            for s in series:
                cells += "  " + " ".join(
                    f"{r[f'{s}_{key}_mean']:>#9.4g} ({r[f'{s}_{key}_sd']:#.3g})".rjust(19)
                    for key, _ in state
                )
            yield cells + (f" {_cell(r.get('tail'), '.3g'):>8}" if tail else "") + "\n"
    yield PER_FRAME_LEGEND + "\n"


#: The quantities of a per-frame table: the key in a row, the column's name (a point in 3-D,
#: pairs, has all five, the plane the first three).
_STATE = (
    ("depth", "depth"),
    ("x", "x"),
    ("velocity", "velocity"),
    ("height", "height"),
    ("vertical_velocity", "vert. vel."),
)


def _csv_chunks(head: dict, blocks: dict) -> Iterator[str]:
    columns = None
    for name, rows in blocks.items():
        for r in rows:
            r = {"filter": name, **r}
            if columns is None:
                columns = list(r)
                yield _csv_line(columns)
            yield _csv_line([_csv_field(r.get(c)) for c in columns])


def _csv_line(fields: list) -> str:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerow(fields)
    return out.getvalue()


def _json_chunks(head: dict, blocks: dict) -> Iterator[str]:
    text = as_json({**head, "filters": {}})  # "filters" last: its rows go between its braces
    yield text[: text.rindex("{}")] + "{"
    for i, (name, rows) in enumerate(blocks.items()):
        yield ("," if i else "") + f"\n    {json.dumps(name)}: ["
        for k, r in enumerate(rows):
            row = json.dumps(strict(r)[0], indent=2, allow_nan=False)
            yield ("," if k else "") + "\n      " + row.replace("\n", "\n      ")
        yield "\n    ]"
    yield "\n  }\n}\n"


#: What each direction of ``--direction`` means, as the outputs say it.
DIRECTIONS = {
    "receding": "the camera moves away from the point",
    "approaching": "the camera moves towards the point",
    "signed": "each step's sign: + receding, - approaching",
}


def direction_text(result: dict) -> str:
    """The line naming the direction a result's steps were read in, and whether it was given."""
    how = "given" if result["direction_given"] else "the default: no distances given"
    return f"direction: {result['direction']} ({DIRECTIONS[result['direction']]}; {how})"


def _csv_field(value) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


# --- the commands' examples -----------------------------------------------------------

#: The epilog of each command's help (``"all"``: the main help's).
EXAMPLES = {
    "reproduce": """\
examples:
  python -m depthcore reproduce          the table of Figures 2-6 beside the paper
  python -m depthcore reproduce --json   the same as JSON""",
    "estimate": f"""\
examples:
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005
  python -m depthcore estimate --mu -1e-1 0 0.2 --rho 0.01 --prior-cov 100
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005 --prior-mean -1 4 0 --json
  python -m depthcore estimate --mu -0.3 0 0.2 0.33 0.43 --rho 0.005 --process-noise 0.01 --smooth
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005 --filters optimal iterated inverse_depth
  python -m depthcore estimate --mu -0.3 0 nan 0.33 0.43 --rho 0.005 --prior-mean -1 4 0 --per-frame
  python -m depthcore estimate --mu-file track.csv --per-frame --csv
  python -m depthcore estimate --mu-file pixels.csv --focal 800 --cx 320 --rho 0.002 --per-frame
  python -m depthcore estimate --mu-file drive.csv --direction approaching --speed 8 --per-frame
  python -m depthcore estimate --mu-file points.csv --focal 800 --cx 320 --cy 240 --rho 0.002
  python -m depthcore estimate --mu-file track.csv --learn-noise --gate 0.001 --prior-depth 20 5

The noise-free state c is (x, y, v) at frame 3 (from the first three bearings);
the prior is at frame 1; every filter reports the state at the last frame N.

{TRACK_FORMAT}

{PRIOR_RULE}""",
    "study": f"""\
examples:
  python -m depthcore study --trials 500 --seed 1
  python -m depthcore study --filters ekf ukf --rho 0.01 --json
  python -m depthcore study --frames 10 --process-noise 0.01 --trials 200
  python -m depthcore study --trials 20000 --workers 4
  python -m depthcore study --trials 20000 --scheduler tcp://host:8786

{STUDY_LEGEND}""",
    "atlas": """\
examples:
  python -m depthcore atlas --size book --workers 2 --out atlas.json
  python -m depthcore atlas --size full --scheduler tcp://host:8786 --out atlas.json

Each cell is a study; the JSON holds every cell's scores and verdicts (calibrated,
track lost, within 10 % of the bound: true, false or null when undecided) and the
measured seconds per trial of each filter at each number of frames.""",
}
EXAMPLES["all"] = """\
examples:
  python -m depthcore reproduce
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005
  python -m depthcore study --trials 500 --seed 1

`python -m depthcore COMMAND --help` shows each command's options and examples."""


# --- strict JSON -----------------------------------------------------------------------

#: Why a number of the output is not finite, by its key.
REASONS = {
    "error": "the Monte Carlo error cannot be estimated from this run: the weights "
    "collapsed onto too few particles (or too few replicas)",
}


def strict(value, key: str = ""):
    """``value`` with every non-finite float made ``None``; returns (value, reason or None)."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            v, reason = strict(v, k)
            out[k] = v
            if reason is not None and f"{k}_reason" not in value:
                out[f"{k}_reason"] = reason
        return out, None
    if isinstance(value, (list, tuple)):
        items = [strict(v, key) for v in value]
        reasons = [r for _, r in items if r is not None]
        return [v for v, _ in items], (reasons[0] if reasons else None)
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return None, REASONS.get(
            key, f"not a finite number ({float(value)}): cannot be estimated from this run"
        )
    if isinstance(value, np.generic):
        return value.item(), None
    return value, None


def as_json(result) -> str:
    """``result`` as strict JSON: no NaN or Infinity (see :func:`strict`)."""
    return json.dumps(strict(result)[0], indent=2, allow_nan=False) + "\n"


def depth_law_text(law: dict) -> str:
    """The line naming ``--prior-depth``'s law, which the exact filter takes as it is."""
    p = ["inf" if v is None else f"{v:g}" for v in law["parameters"]]
    what = {
        "log_uniform": lambda: f"log-uniform from {p[0]} to {p[1]}",
        "range": lambda: f"Gaussian N({p[0]}, {p[1]}**2) truncated to {p[2]} .. {p[3]}",
        "inverse_depth": lambda: f"1/depth ~ N({p[0]}, {p[1]}**2) truncated to {p[2]} .. {p[3]}",
        "table": lambda: f"tabulated at {len(p) // 2} depths from {p[0]} to {p[len(p) // 2 - 1]}",
    }[law["form"]]()
    return (
        f"prior on the depth at the first frame: {what} (the optimal filter's; the other "
        "filters take the mean and covariance above)"
    )
