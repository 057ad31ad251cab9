"""The chapter on hard settings: where the filters' coverage fails.

Recommended import: ``from depthbook import beyond_hard``.

:func:`hard_figure` draws every filter's RMSE and coverage in each cell of
:func:`depthbook.studies.hardness.hard_study`, each cell named by :func:`setting_label`;
:func:`hard_label`, :func:`score_text`, :func:`median_text`, :func:`extreme_text` and
:func:`verdict_texts` give the texts the chapter glues; :func:`outcome_counts` counts
the outcomes of its paired tests; :data:`LONG_RUN` is the long run its exact filter at
Figure 2's truth is set against.
"""

from __future__ import annotations

import numpy as np

from depthbook.formatting import value_se
from depthbook.studies import hardness
from depthbook.style import MIN_FONT, STYLE, WIDTH, log_bars, subplots
from depthcore.studies.medians import INTERVAL_LEVEL

#: The long run of the chapter's setting at Figure 2's truth with the paper's prior
#: covariance (:func:`depthbook.studies.replication.fixed_truth_replicates`): 40 replicates
#: of 500 trials, whose RMSE's error is under a third of a 2,200-trial cell's.
LONG_RUN = {
    "prior_scale": 1000.0,
    "prior_velocity": 0.0,
    "trials": 500,
    "replicates": 40,
    "seed": 34,
}

#: A marker per filter of :data:`depthbook.studies.hardness.NAMES`, so that the
#: filters stay apart in print without colour.
MARKERS = {
    "optimal": "o",
    "second_order": "s",
    "ekf": "v",
    "ukf": "^",
    "iterated": "D",
    "inverse_depth": "P",
}


def setting_label(cell: dict, truth, prior_scale: float, reference: str = "reference") -> str:
    """How one cell of :func:`~depthbook.studies.hardness.hard_study` departs from a reference.

    Parameters
    ----------
    cell : dict
        From :func:`depthbook.studies.hardness.hard_cell`.
    truth : array_like, shape (3,)
        The reference truth ``(x, y, v)`` at time 3.
    prior_scale : float
        The reference prior covariance ``s`` of ``s I``; the reference prior
        velocity is 0.
    reference : str
        The label of a cell that departs in nothing.

    Returns
    -------
    str
        One line per departure, in mathematics: the truth's components that
        differ (its depth alone when the truth is a multiple of the
        reference), ``s`` and ``v_0``; ``reference`` when none does.
    """
    ref = np.asarray(truth, dtype=float)
    t = np.asarray(cell["truth"], dtype=float)
    parts = []
    k = t[1] / ref[1]
    if np.allclose(t, k * ref) and not np.isclose(k, 1.0):
        parts.append(f"$y = {t[1]:g}$")
    else:
        parts += [
            f"${name} = {a:g}$"
            for name, a, b in zip("xyv", t, ref, strict=True)
            if not np.isclose(a, b)
        ]
    s = float(cell["prior_cov"][0, 0])
    if not np.isclose(s, prior_scale):
        parts.append(f"$s = {s:g}$")
    v0 = float(cell["prior_mean"][2])
    if v0 != 0.0:
        parts.append(f"$v_0 = {v0:g}$")
    return "\n".join(parts) or reference


def _ratios(cells: list, reading: str, name: str) -> tuple:
    """A filter's depth RMSE per cell over the reference of ``reading``, with its SE.

    At the fixed truth the reference is the cell's bound SD (exact, so the SE
    is the RMSE's over it); over the prior it is the exact posterior's RMSE over
    the same trials (:func:`~depthbook.studies.hardness.paired_comparison`).
    """
    if reading == "fixed":
        s = [c["fixed"]["filters"][name] for c in cells]
        b = np.array([c["bound_sd"] for c in cells])
        return np.array([v["rmse"] for v in s]) / b, np.array([v["rmse_se"] for v in s]) / b
    if name == "optimal":
        return np.ones(len(cells)), np.zeros(len(cells))
    d = [hardness.paired_comparison(c, "prior", name, "optimal") for c in cells]
    return np.array([v["rmse_ratio"] for v in d]), np.array([v["rmse_ratio_se"] for v in d])


def hard_figure(cells: list, labels, level: int = 68):
    """Every filter's depth RMSE and coverage per setting, at the fixed truth and over the prior.

    Parameters
    ----------
    cells : list of dict, length C
        From :func:`depthbook.studies.hardness.hard_study`.
    labels : sequence of str, length C
        The settings' tick labels (:func:`setting_label`).
    level : int
        The central interval's level in percent, 68 or 95.

    Returns
    -------
    matplotlib.figure.Figure
        Four rows sharing the settings as x-axis: the RMSE at the fixed truth
        over the bound's depth SD; the RMSE over the prior over the exact
        posterior's on the same trials; the coverage at the fixed truth; the
        coverage over the prior. Each filter with two-standard-error bars; grey
        lines at 1 and at the nominal level.
    """
    if len(labels) != len(cells):
        raise ValueError(f"labels must name each of the {len(cells)} cells, got {len(labels)}")
    key = f"coverage_{int(level)}"
    names = list(cells[0]["fixed"]["filters"])
    x = np.arange(len(cells), dtype=float)
    fig, axes = subplots(4, 1, figsize=(WIDTH, 7.8), sharex=True)
    rows = (
        ("fixed", "ratio", "RMSE / bound,\nfixed truth"),
        ("prior", "ratio", "RMSE / RMSE of $p_o$,\nover the prior"),
        ("fixed", key, f"{level} % coverage,\nfixed truth"),
        ("prior", key, f"{level} % coverage,\nover the prior"),
    )
    for ax, (reading, score, ylabel) in zip(axes, rows, strict=True):
        for k, name in enumerate(names):
            if score == "ratio":
                y, se = _ratios(cells, reading, name)
                yerr = log_bars(y, se)
            else:
                s = [c[reading]["filters"][name] for c in cells]
                y = np.array([v[score] for v in s])
                yerr = 2 * np.array([v[f"{score}_se"] for v in s])
            # a small offset per filter keeps the error bars apart
            shift = (k - (len(names) - 1) / 2) * 0.13
            ax.errorbar(
                x + shift,
                y,
                yerr=yerr,
                color=STYLE[name]["color"],
                label=STYLE[name]["label"],
                marker=MARKERS.get(name, "o"),
                markersize=3.5,
                linestyle="none",
                elinewidth=1,
                capsize=1.5,
            )
        if score == "ratio":
            ax.set_yscale("log")
            ax.axhline(1.0, color="0.6", linewidth=1, zorder=0)
        else:
            ax.axhline(level / 100, color="0.6", linewidth=1, zorder=0)
            ax.set_ylim(-0.04, 1.04)
        for boundary in x[:-1] + 0.5:
            ax.axvline(boundary, color="0.9", linewidth=0.8, zorder=0)
        ax.set_ylabel(ylabel)
    axes[-1].set_xticks(x, labels)
    axes[-1].set_xlim(-0.5, len(cells) - 0.5)
    axes[-1].set_xlabel("setting")
    handles, texts = axes[0].get_legend_handles_labels()
    fig.legend(handles, texts, loc="outside lower center", ncol=3, frameon=False, fontsize=MIN_FONT)
    return fig


def hard_label(cell: dict) -> str:
    """A setting of :func:`~depthbook.studies.hardness.hard_cell`: truth, prior, velocity."""
    x, y, v = (float(a) for a in cell["truth"])
    s = float(cell["prior_cov"][0, 0])
    return f"({x:g}, {y:g}, {v:g}); {s:g} I; v₀ = {float(cell['prior_mean'][2]):g}"


def verdict_texts(cells: list, prefix: str) -> dict:
    """How many settings each filter's coverage passes its test in, per reading and level, for glue.

    Parameters
    ----------
    cells : list of dict
        From :func:`depthbook.studies.hardness.hard_study`.
    prefix : str

    Returns
    -------
    dict
        ``"<prefix>_<filter>_<reading>_<level>"``: the number of cells where
        the filter's central ``level`` % interval passes the coverage test of
        :func:`depthbook.studies.hardness.verdicts`, for each filter, reading
        (``"fixed"``, ``"prior"``) and level (68, 95).
    """
    out = {}
    for reading in hardness.READINGS:
        v = [hardness.verdicts(c, reading) for c in cells]
        for level in (68, 95):
            for name in v[0][f"calibrated_{level}"]:
                n = sum(x[f"calibrated_{level}"][name] for x in v)
                out[f"{prefix}_{name}_{reading}_{level}"] = str(int(n))
    return out


def score_text(scores: dict, score: str) -> str:
    """One score of one filter as the chapter quotes it: ``"value ± standard error"``.

    Two decimals for a coverage, three significant figures' worth for a depth
    (:func:`~depthbook.formatting.value_se`).
    """
    value = scores[score]
    if score.startswith("coverage"):
        decimals = 2
    else:
        decimals = max(0, 2 - int(np.floor(np.log10(max(abs(value), 1e-3)))))
    return value_se(value, scores[f"{score}_se"], decimals)


def median_text(scores: dict, decimals: int = 1) -> str:
    """A filter's median absolute depth error with its distribution-free 95 % interval.

    Parameters
    ----------
    scores : dict
        One filter's scores in one reading of a cell
        (:func:`depthbook.studies.hardness.depth_scores`), with
        ``"median_abs_error"`` and ``"median_abs_error_ci"``.
    decimals : int

    Returns
    -------
    str
        ``"m (95 % interval lo to hi)"``; ``"m (95 % interval from lo)"`` when
        the interval has no upper end.
    """
    m = scores["median_abs_error"]
    lo, hi = scores["median_abs_error_ci"]
    level = f"{100 * INTERVAL_LEVEL:g} %"
    if hi is None:
        return f"{m:.{decimals}f} ({level} interval from {lo:.{decimals}f})"
    return f"{m:.{decimals}f} ({level} interval {lo:.{decimals}f} to {hi:.{decimals}f})"


def extreme_text(cells: list, reading: str, name: str, score: str, which: str, where=None):
    """The cell where a filter's score is least or greatest, and that score with its SE.

    Parameters
    ----------
    cells : list of dict
        From :func:`depthbook.studies.hardness.hard_study`.
    reading : {"fixed", "prior"}
    name : str
        A filter of the cells.
    score : str
        A score of the filter with its ``"<score>_se"``, e.g. ``"rmse"``, ``"coverage_68"``.
    which : {"min", "max"}
    where : array_like of bool, shape (len(cells),), optional
        The cells to search (default all).

    Returns
    -------
    (int, str)
        The cell's index and :func:`score_text` of its score.
    """
    if which not in ("min", "max"):
        raise ValueError(f"which must be 'min' or 'max', got {which!r}")
    values = np.array([c[reading]["filters"][name][score] for c in cells], dtype=float)
    where = np.ones(len(cells), dtype=bool) if where is None else np.asarray(where, dtype=bool)
    if where.shape != values.shape or not where.any():
        raise ValueError("where must be a boolean per cell, true for at least one")
    masked = np.where(where, values, np.inf if which == "min" else -np.inf)
    i = int(np.argmin(masked) if which == "min" else np.argmax(masked))
    return i, score_text(cells[i][reading]["filters"][name], score)


def outcome_counts(outcomes) -> tuple:
    """How many paired tests came out ``1``, ``0`` and ``-1``.

    Parameters
    ----------
    outcomes : array_like of int, shape (...)
        Outcomes of :func:`depthcore.studies.scores.difference_verdict` (or of
        :func:`depthbook.studies.hardness.verdicts`).

    Returns
    -------
    (int, int, int)
        Significantly above (a win), undecided, significantly below.
    """
    v = np.asarray(outcomes)
    if not np.isin(v, (-1, 0, 1)).all():
        raise ValueError("outcomes must each be 1, 0 or -1")
    return tuple(int(np.sum(v == k)) for k in (1, 0, -1))
