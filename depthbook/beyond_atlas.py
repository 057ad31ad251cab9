"""The chapter on the atlas: where each filter is calibrated, loses the track, nears the bound.

Recommended import: ``from depthbook import beyond_atlas``.

:func:`read` reads the calibration verdicts from the coverages of a record of
:func:`depthcore.studies.atlas.atlas` (whatever verdicts it stored);
:func:`verdict_counts` counts each filter's verdicts over the cells,
:func:`headline` states its calibration, :func:`count_texts` gives the counts
as the chapter glues them and :func:`cost_rows` the measured cost per trial;
:func:`verdict_map` draws one verdict over every cell: per filter, the
prior settings by the parallaxes, at each number of frames and noise level.
"""

from __future__ import annotations

import numpy as np

from depthbook.notebook import MarkdownTable
from depthbook.provenance import records
from depthbook.style import MIN_FONT, STYLE, WIDTH, subplots
from depthcore.studies import atlas, coverage_verdicts

#: The seed of the book's atlas (cell ``i`` is seeded by its child ``i``).
SEED = 34

#: The trials per number of frames at which the chapter times the filters the atlas leaves out.
PROBE_TRIALS = 50


def runs() -> tuple:
    """The chapter's two records: the atlas's and the cost probe's of the costly filters.

    ``make atlas`` computes them again, the other records kept.

    Returns
    -------
    tuple of depthbook.provenance.records.Recorded
        ``(atlas_run, probe_run)``.
    """
    atlas_run = records.recorded(atlas.atlas, "book", SEED)
    probe_run = records.recorded(
        atlas.probe_cost, atlas.COSTLY, (3, 10, 30), PROBE_TRIALS, 200, SEED
    )
    return atlas_run, probe_run


#: The filters the chapter finds miscalibrated in few cells (its checks assert it).
CALIBRATED_GROUP = ("optimal", "second_order", "modified_polar", "batch_ml", "particle")

#: The filters the chapter finds miscalibrated in most cells (its checks assert it).
MISCALIBRATED_GROUP = ("ekf", "ukf", "inverse_depth", "inverse_depth_ukf")

#: The outcomes of a verdict in a cell, as :func:`verdict_grid` codes them.
OUTCOMES = {True: 1.0, False: 0.0, None: 2.0}

#: Where a filter has no answer in a cell (it failed on a trial, or none was valid).
NO_ANSWER = 3.0

#: The colours of :data:`OUTCOMES` and :data:`NO_ANSWER` (yes dark, no light, undecided grey).
COLOURS = ("#deebf7", "#08519c", "#969696", "#ffffff")


def read(result: dict) -> dict:
    """The atlas ``result`` with its calibration verdicts read from its coverages.

    :func:`depthcore.studies.coverage_verdicts.with_calibration`: every
    filter's ``"calibrated"`` from the coverage and trials of each cell whose
    truths are drawn, at the tolerance and false-discovery rate stated there;
    a record made before those verdicts is read as a new one.
    """
    return coverage_verdicts.with_calibration(result)


def verdict_counts(result: dict, names=None) -> dict:
    """Per filter and verdict, in how many cells it is yes, no, undecided, or not known.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.studies.atlas.atlas` (its record), read by
        :func:`read`.
    names : sequence of str, optional
        Default the atlas's filters.

    Returns
    -------
    dict
        ``{name: {verdict: {"yes", "no", "undecided", "no_answer", "not_run",
        "untested", "cells"}}}``: a cell where the filter failed, or had no
        valid trial, has no answer; one the grid does not run it in
        (:meth:`depthcore.studies.atlas.Grid.runs`) is not run; the nearness to
        the bound is not tested where the cell has no bound, the calibration
        where its truth is fixed; a verdict whose test cannot decide, or whose
        score is not finite, is undecided.
    """
    return _counts(read(result), names)


def _counts(result: dict, names=None) -> dict:
    names = result["names"] if names is None else names
    keys = ("yes", "no", "undecided", "no_answer", "not_run", "untested", "cells")
    out = {}
    for name in names:
        out[name] = {}
        for verdict in atlas.VERDICTS:
            c = dict.fromkeys(keys, 0)
            for cell in result["cells"]:
                c["cells"] += 1
                c[_outcome(cell, name, verdict)] += 1
            out[name][verdict] = c
    return out


def _outcome(cell: dict, name: str, verdict: str) -> str:
    entry = cell["filters"].get(name)
    if entry is None:
        return "not_run"
    if "failed" in entry:
        return "no_answer"
    if verdict == "near_bound" and "bound_sd" in cell and cell["bound_sd"] is None:
        return "untested"
    if verdict == "calibrated" and coverage_verdicts.fixed_truth(cell):
        return "untested"
    if entry[verdict] is None:
        return "undecided"
    return "yes" if entry[verdict] else "no"


def counts_by_prior(result: dict, name: str, verdict: str) -> dict:
    """One filter's :func:`verdict_counts` for one verdict, per prior setting.

    Returns
    -------
    dict
        ``{(form, prior_scale): {"yes", "no", "undecided", "no_answer", "cells"}}``,
        the settings in cell order.
    """
    out: dict = {}
    for cell in read(result)["cells"]:
        key = (cell["form"], cell["prior_scale"])
        part = {**result, "cells": [cell]}
        c = _counts(part, [name])[name][verdict]
        total = out.setdefault(key, dict.fromkeys(c, 0))
        for k, v in c.items():
            total[k] += v
    return out


def tested(c: dict) -> int:
    """The cells a verdict's counts (:func:`verdict_counts`) decide or leave undecided."""
    return c["yes"] + c["no"] + c["undecided"]


def headline(c: dict, tolerance: float) -> str:
    """A filter's calibration counts as stated: calibrated within ±t in K of M cells, ..."""
    return (
        f"calibrated within ±{tolerance:g} in {c['yes']} of {tested(c)} cells, "
        f"miscalibrated in {c['no']}, undecided in {c['undecided']}"
    )


def calibration_texts(counts: dict) -> dict:
    """The calibration counts of each group, as the chapter and the conclusions glue them.

    Returns
    -------
    dict
        ``"good_min"``, ``"good_max"`` (:data:`CALIBRATED_GROUP`'s fewest and
        most cells called calibrated), ``"ekf"`` (``"none"`` for 0),
        ``"poor_max"`` (the most of :data:`MISCALIBRATED_GROUP` but the EKF),
        ``"good_no_max"`` (:data:`CALIBRATED_GROUP`'s most called
        miscalibrated), ``"poor_no_min"``, ``"poor_no_max"``
        (:data:`MISCALIBRATED_GROUP`'s fewest and most called miscalibrated)
        and ``"judged"`` (the most cells judged).
    """
    yes = {n: counts[n]["calibrated"]["yes"] for n in counts}
    no = {n: counts[n]["calibrated"]["no"] for n in counts}
    return {
        "good_min": f"{min(yes[n] for n in CALIBRATED_GROUP)}",
        "good_max": f"{max(yes[n] for n in CALIBRATED_GROUP)}",
        "ekf": "none" if yes["ekf"] == 0 else f"{yes['ekf']}",
        "poor_max": f"{max(yes[n] for n in MISCALIBRATED_GROUP if n != 'ekf')}",
        "good_no_max": f"{max(no[n] for n in CALIBRATED_GROUP)}",
        "poor_no_min": f"{min(no[n] for n in MISCALIBRATED_GROUP)}",
        "poor_no_max": f"{max(no[n] for n in MISCALIBRATED_GROUP)}",
        "judged": f"{max(tested(counts[n]['calibrated']) for n in counts)}",
    }


def headline_table(counts: dict, names, tolerance: float) -> MarkdownTable:
    """Per filter, its calibration :func:`headline`."""
    rows = [[STYLE[n]["label"], headline(counts[n]["calibrated"], tolerance)] for n in names]
    return MarkdownTable(["filter", "68 % depth intervals"], rows)


def no_maximum(result: dict, name: str = "batch_ml") -> dict:
    """The trials where a filter's estimate had no interior maximum, over an atlas's cells.

    Returns
    -------
    dict
        ``"counted"`` (whether the record counts them, per cell, as
        :func:`depthcore.studies.atlas.filter_summary`'s ``"no_maximum"``),
        ``"trials"`` (their sum), ``"answered"`` (the trials with a maximum
        scored, summed over the same cells) and ``"cells"`` (the cells with
        one or more).
    """
    entries = [c["filters"][name] for c in result["cells"] if name in c["filters"]]
    entries = [e for e in entries if "failed" not in e]
    counted = bool(entries) and all("no_maximum" in e for e in entries)
    return {
        "counted": counted,
        "trials": sum(e.get("no_maximum", 0) for e in entries),
        "answered": sum(e["trials"] for e in entries),
        "cells": sum(e.get("no_maximum", 0) > 0 for e in entries),
    }


def count_texts(counts: dict, prefix: str) -> dict:
    """The counts as glued: ``{prefix}_{name}_{verdict}`` is "yes (undecided)"."""
    return {
        f"{prefix}_{name}_{verdict}": f"{c['yes']} ({c['undecided']})"
        for name, by in counts.items()
        for verdict, c in by.items()
    }


#: Where a verdict is not tested in a cell (no bound for the forms whose truths are drawn).
UNTESTED = 4.0

#: Where a filter does not run in a cell (the grid's most frames for it).
NOT_RUN = 5.0

#: The code of each outcome of a verdict in :func:`verdict_grid`'s matrix.
CODES = {
    "yes": OUTCOMES[True],
    "no": OUTCOMES[False],
    "undecided": OUTCOMES[None],
    "no_answer": NO_ANSWER,
    "untested": UNTESTED,
    "not_run": NOT_RUN,
}


def prior_label(form: str, scale) -> str:
    """A prior setting as the map names it: the paper's rule with its scale, or the form."""
    return {
        "paper": f"paper, $s = {scale:g}$" if scale is not None else "paper",
        "range": "range",
        "log_uniform": "log-uniform",
        "inverse_depth": "inverse depth",
    }.get(form, form)


def _row_key(cell: dict) -> tuple:
    return (cell["form"], cell["prior_scale"], cell["depth"])


def _column_key(cell: dict) -> tuple:
    return (cell["frames"], cell["rho"])


def _keys(cells, key) -> list:
    out = []
    for c in cells:
        if key(c) not in out:
            out.append(key(c))
    return out


def verdict_grid(result: dict, verdict: str, names) -> tuple:
    """One verdict as a matrix of tiles, with the settings of its rows and columns.

    Rows: per filter, a block of the prior settings and depths (in cell
    order, the prior's form and scale, then the depth), then a gap; columns:
    per number of frames and noise level, the parallaxes (increasing to the
    right), then a gap.

    Returns
    -------
    tuple
        ``(matrix, rows, columns)``: ``matrix`` of shape
        ``(F (R + 1) - 1, C (P + 1) - 1)`` coded by :data:`OUTCOMES`,
        :data:`NO_ANSWER` and :data:`UNTESTED`, NaN in the gaps; ``rows`` the
        ``R`` settings ``(form, prior_scale, depth)`` of a filter's block,
        ``columns`` the ``C`` settings ``(frames, rho)``.
    """
    cells = read(result)["cells"]
    rows, columns = _keys(cells, _row_key), _keys(cells, _column_key)
    parallax = list(result["axes"]["parallax"])
    n_row, n_par = len(rows), len(parallax)
    m = np.full((len(names) * (n_row + 1) - 1, len(columns) * (n_par + 1) - 1), np.nan)
    for cell in cells:
        r, c = rows.index(_row_key(cell)), columns.index(_column_key(cell))
        col = c * (n_par + 1) + parallax.index(cell["parallax"])
        for f, name in enumerate(names):
            outcome = _outcome(cell, name, verdict)
            m[f * (n_row + 1) + r, col] = CODES[outcome]
    return m, rows, columns


def _noise_label(rho: float) -> str:
    return f"{rho / atlas.PIXEL:.2g} px"


#: The height of a row of tiles in :func:`verdict_map`, in inches: its label's
#: :data:`~depthbook.style.MIN_FONT` points and a little space.
MAP_ROW = 0.15


def verdict_map(result: dict, verdict: str, names=None):
    """One verdict in every cell: a block of tiles per filter, per frames and noise.

    The filters' blocks stand in two columns, the first half of ``names`` at the
    left; each block is headed by its filter, and within it the prior settings
    (and depths) run down, labelled at the left for both columns, the
    parallaxes (increasing) to the right. A tile is dark where the verdict
    holds, light where it does not, grey where the test cannot decide, white
    with a cross where the filter has no answer, white with a dot where the
    verdict is not tested (no bound, or a fixed truth for the calibration),
    pale grey where the grid does not run the filter.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    names = list(result["names"] if names is None else names)
    half = (len(names) + 1) // 2
    columns_of_blocks = [names[:half], names[half:]] if len(names) > 1 else [names]
    grids = [verdict_grid(result, verdict, block) for block in columns_of_blocks]
    m, rows, columns = grids[0]
    n_row, n_par = len(rows), len(result["axes"]["parallax"])
    height = 1.3 + (m.shape[0] + 1.5) * MAP_ROW
    fig, axes = subplots(1, len(grids), figsize=(WIDTH, height), squeeze=False)
    colours = ListedColormap([*COLOURS, "#ffffff", "#f0f0f0"])
    bounds = [-0.5, 0.5, 1.5, 2.5, 3.5, 4.5, 5.5]
    depths = {d for _, _, d in rows}
    labels = [
        prior_label(form, scale) + (f", $y = {d:g}$" if len(depths) > 1 else "")
        for form, scale, d in rows
    ]
    for ax, block, (grid, _, _) in zip(axes[0], columns_of_blocks, grids, strict=True):
        ax.pcolormesh(  # tiles as vector rectangles; the gaps between blocks left blank
            np.arange(grid.shape[1] + 1) - 0.5,
            np.arange(grid.shape[0] + 1) - 0.5,
            np.ma.masked_invalid(grid),
            cmap=colours,
            norm=BoundaryNorm(bounds, 6),
        )
        for code, marker, size in ((NO_ANSWER, "x", 8), (UNTESTED, ".", 3)):
            r, c = np.nonzero(grid == code)
            ax.scatter(c, r, marker=marker, s=size, color="0.3", linewidths=0.6)
        for f, name in enumerate(block):  # each block headed by its filter, in the gap above
            ax.text(
                -0.5,
                f * (n_row + 1) - 1,
                STYLE[name]["label"],
                fontsize=MIN_FONT,
                fontweight="bold",
                va="center",
            )
        ax.set_ylim(m.shape[0] - 0.5, -1.5)
        ax.set_xlim(-0.5, grid.shape[1] - 0.5)
        ax.set_xticks([c * (n_par + 1) + (n_par - 1) / 2 for c in range(len(columns))])
        ax.set_xticklabels(
            [f"N = {frames}\n{_noise_label(rho)}" for frames, rho in columns], fontsize=MIN_FONT
        )
        ax.set_yticks([f * (n_row + 1) + r for f in range(half) for r in range(n_row)])
        ax.set_yticklabels(labels * half if ax is axes[0, 0] else [], fontsize=MIN_FONT)
        ax.tick_params(length=0)
        for spine in ax.spines.values():
            spine.set_visible(False)
    handles = [
        Patch(facecolor=COLOURS[1], label="yes"),
        Patch(facecolor=COLOURS[0], edgecolor="0.6", label="no"),
        Patch(facecolor=COLOURS[2], label="undecided"),
        Line2D([], [], marker="x", linestyle="", color="0.3", label="no answer"),
        Line2D([], [], marker=".", linestyle="", color="0.3", label="not tested"),
        Patch(facecolor="#f0f0f0", label="not run"),
    ]
    fig.legend(
        handles=handles, loc="outside lower center", ncol=6, frameon=False, fontsize=MIN_FONT
    )
    return fig


#: The headings of :func:`summary_table`'s columns, by verdict.
VERDICT_HEADINGS = {
    "calibrated": "calibrated",
    "lost": "track lost",
    "near_bound": "near the bound",
}


def count_cell(c: dict) -> str:
    """One filter's counts of one verdict as a table shows them: yes / no / undecided."""
    text = f"{c['yes']} / {c['no']} / {c['undecided']}"
    notes = [
        f"{c[key]} {words}"
        for key, words in (
            ("not_run", "not run"),
            ("no_answer", "without answer"),
            ("untested", "not tested"),
        )
        if c[key]
    ]
    return text + (f" ({', '.join(notes)})" if notes else "")


def summary_table(counts: dict, names) -> MarkdownTable:
    """Per filter, in how many cells each verdict is yes, no and undecided."""
    header = ["filter", *(f"{h}: yes / no / undecided" for h in VERDICT_HEADINGS.values())]
    rows = [
        [STYLE[name]["label"], *(count_cell(counts[name][v]) for v in VERDICT_HEADINGS)]
        for name in names
    ]
    return MarkdownTable(header, rows)


def cost_table(cost: dict, names) -> MarkdownTable:
    """The measured milliseconds per trial of each filter at each number of frames."""
    rows = cost_rows(cost, names)
    frames = sorted({f for r in rows for f in r["frames"]}, key=int)
    header = ["filter", *(f"N = {f}" for f in frames)]
    body = [
        [
            STYLE[r["name"]]["label"],
            *(f"{r['frames'][f]:.2g}" if f in r["frames"] else "–" for f in frames),
        ]
        for r in rows
    ]
    return MarkdownTable(header, body)


def cost_rows(cost: dict, names) -> list[dict]:
    """The measured milliseconds per trial of each filter at each number of frames.

    Returns
    -------
    list of dict
        ``{"name", "frames": {str(N): milliseconds}}`` per name of ``names``.
    """
    per = cost["seconds_per_trial"]
    return [
        {"name": n, "frames": {f: 1e3 * s for f, s in sorted(per[n].items(), key=_frames)}}
        for n in names
    ]


def _frames(item) -> int:
    return int(item[0])


def under_law(result: dict) -> dict:
    """The exact filter under each drawn form's law and under its Gaussian, pooled over cells.

    Per form (and ``"all"``), for ``"law"`` (the record's ``"under_law"`` row) and
    ``"gaussian"`` (``"optimal"``): the 68 % coverage pooled over the drawn cells'
    trials with its binomial SE, the mean of the cells' depth RMSE, and the
    calibration counts (:func:`depthcore.studies.coverage_verdicts.with_calibration`).
    Empty for a record without the row.
    """
    if "under_law" not in result:
        return {}
    result = read(result)
    drawn = [c for c in result["cells"] if not coverage_verdicts.fixed_truth(c)]
    out = {}
    for form in [*sorted({c["form"] for c in drawn}), "all"]:
        cells = [c for c in drawn if form in ("all", c["form"])]
        out[form] = {}
        for key, name in (("law", result["under_law"]), ("gaussian", "optimal")):
            rows = [c["filters"][name] for c in cells if name in c["filters"]]
            rows = [r for r in rows if r.get("coverage_68") is not None]
            n = sum(r["trials"] for r in rows)
            p = sum(r["coverage_68"] * r["trials"] for r in rows) / n
            verdicts = [r["calibrated"] for r in rows]
            out[form][key] = {
                "coverage": p,
                "coverage_se": float(np.sqrt(p * (1.0 - p) / n)),
                "rmse": float(np.mean([r["rmse"] for r in rows])),
                "cells": len(rows),
                "yes": verdicts.count(True),
                "no": verdicts.count(False),
                "undecided": verdicts.count(None),
            }
    return out


def under_law_table(rows: dict) -> MarkdownTable:
    """Per drawn form, the exact filter's pooled coverage and mean RMSE, law and Gaussian."""
    body = []
    for form, r in rows.items():
        label = "all drawn" if form == "all" else prior_label(form, None)
        body.append(
            [label]
            + [f"{r[k]['coverage']:.3f} ± {r[k]['coverage_se']:.3f}" for k in ("law", "gaussian")]
            + [f"{r[k]['rmse']:.3g}" for k in ("law", "gaussian")]
        )
    header = ["prior", "coverage, law", "coverage, Gaussian", "RMSE, law", "RMSE, Gaussian"]
    return MarkdownTable(header, body)


def undecided(result: dict, names=None, tolerance: float | None = None) -> dict:
    """Per filter, the drawn cells its calibration leaves undecided, and why.

    A coverage is undecided where its binomial interval reaches across an edge
    of the band ``0.68 ± t``: its distance to the nearer edge, in standard
    errors, says how near it lies; a cell where the filter answered fewer of
    its trials (refusals) has a wider interval.

    Parameters
    ----------
    result : dict
        An atlas record's result, read by :func:`read`.
    names : sequence of str, optional
        Default the atlas's filters and its row under the law.
    tolerance : float, optional
        ``t``; default :data:`depthcore.studies.coverage_verdicts.TOLERANCE`.

    Returns
    -------
    dict
        ``{name: {"cells", "coverages" (list), "ses" (list), "trials" (list),
        "edge_se" (the largest distance to the nearer edge, in SEs; None
        without a cell)}}``.
    """
    result = read(result)
    t = coverage_verdicts.TOLERANCE if tolerance is None else tolerance
    if names is None:
        names = [*result["names"], *([result["under_law"]] if "under_law" in result else [])]
    edges = (coverage_verdicts.LEVEL - t, coverage_verdicts.LEVEL + t)
    out = {}
    for name in names:
        rows = [
            c["filters"][name]
            for c in result["cells"]
            if not coverage_verdicts.fixed_truth(c)
            and name in c["filters"]
            and "failed" not in c["filters"][name]
            and c["filters"][name]["calibrated"] is None
        ]
        distance = [
            min(abs(r["coverage_68"] - e) for e in edges) / r["coverage_68_se"] for r in rows
        ]
        out[name] = {
            "cells": len(rows),
            "coverages": [r["coverage_68"] for r in rows],
            "ses": [r["coverage_68_se"] for r in rows],
            "trials": [r["trials"] for r in rows],
            "edge_se": max(distance) if distance else None,
        }
    return out


def undecided_table(rows: dict, trials: int) -> MarkdownTable:
    """Per filter with an undecided cell (:func:`undecided`): their coverages and why.

    ``trials``: the trials each drawn cell ran; a cell where the filter
    answered fewer than nine in ten of them is counted apart.
    """
    body = []
    for name, r in rows.items():
        if not r["cells"]:
            continue
        label = "exact, under the law" if name not in STYLE else STYLE[name]["label"]
        few = sum(n < 0.9 * trials for n in r["trials"])
        body.append(
            [
                label,
                f"{r['cells']}",
                f"{min(r['coverages']):.3f} to {max(r['coverages']):.3f}",
                f"{max(r['ses']):.4f}",
                f"{r['edge_se']:.1f}",
                f"{few}",
            ]
        )
    header = [
        "filter",
        "undecided cells",
        "their coverages",
        "largest SE",
        "farthest from an edge (SEs)",
        "answering < 90 %",
    ]
    return MarkdownTable(header, body)
