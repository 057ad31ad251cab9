"""The chapter on hard settings: where the filters' coverage fails.

Recommended import: ``from depthcore.book import beyond_hard``.

:func:`hard_figure` draws each filter's coverage over the cells of
:func:`depthcore.studies.hardness.hard_study`; :func:`hard_label` and
:func:`hard_texts`, :func:`score_text` and :func:`extreme_text` give the texts the chapter glues;
:func:`outcome_counts` counts the outcomes of its paired tests.
"""

from __future__ import annotations

import numpy as np

from depthcore.book.style import STYLE, WIDTH, subplots
from depthcore.formatting import value_se


def hard_figure(cells: list, groups: list, level: int = 68):
    """Each filter's coverage at the fixed truth and over the prior, along axes of settings.

    Parameters
    ----------
    cells : list of dict
        From :func:`depthcore.studies.hardness.hard_study`.
    groups : list of (str, list of int, array_like, bool)
        One column each: the x-axis label, the indices of its cells, their
        x values and whether the x-axis is logarithmic.
    level : int
        The central interval's level in percent, 68 or 95.

    Returns
    -------
    matplotlib.figure.Figure
        Two rows (at the fixed truth; truths drawn from the prior), one column
        per group; each filter's coverage with two-standard-error bars, the
        nominal level in grey.
    """
    key = f"coverage_{int(level)}"
    names = list(cells[0]["fixed"]["filters"])
    fig, axes = subplots(2, len(groups), figsize=(WIDTH, 5.4), sharey=True, squeeze=False)
    rows = (("fixed", "at the fixed truth"), ("prior", "truths from the prior"))
    for i, (reading, title) in enumerate(rows):
        for j, (xlabel, indices, xs, log_x) in enumerate(groups):
            ax = axes[i, j]
            xs = np.asarray(xs, dtype=float)
            for k, name in enumerate(names):
                s = [cells[c][reading]["filters"][name] for c in indices]
                # a small offset per filter keeps the error bars apart
                shift = (k - (len(names) - 1) / 2) * 0.012
                x = xs * (1 + shift) if log_x else xs + shift * (np.ptp(xs) or 1.0)
                style = {
                    a: STYLE[name][a] for a in ("color", "marker", "label") if a in STYLE[name]
                }
                ax.errorbar(
                    x,
                    [v[key] for v in s],
                    yerr=[2 * v[f"{key}_se"] for v in s],
                    linewidth=1.2,
                    markersize=3.5,
                    capsize=2,
                    **style,
                )
            ax.axhline(level / 100, color="0.6", linewidth=1)
            if log_x:
                ax.set_xscale("log")
            ax.set_xticks(xs, [f"{v:g}" for v in xs])
            ax.set_xticks([], minor=True)
            ax.set_ylim(-0.03, 1.03)
            if i == 1:
                ax.set_xlabel(xlabel)
            if j == 0:
                ax.set_ylabel(f"{level} % coverage,\n{title}")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, frameon=False)
    return fig


#: The depth scores of every filter that :func:`hard_texts` formats.
HARD_SCORES = ("rmse", "mean_sd", "coverage_68", "coverage_95")


def hard_label(cell: dict) -> str:
    """A setting of :func:`~depthcore.studies.hardness.hard_cell`: truth, prior, velocity."""
    x, y, v = (float(a) for a in cell["truth"])
    s = float(cell["prior_cov"][0, 0])
    return f"({x:g}, {y:g}, {v:g}); {s:g} I; v₀ = {float(cell['prior_mean'][2]):g}"


def hard_texts(cells: list, prefix: str) -> dict:
    """Texts of :func:`depthcore.studies.hardness.hard_study`'s cells, for glue.

    Returns
    -------
    dict
        For the ``i``-th cell: ``"<prefix>_<i>_x"`` (:func:`hard_label`),
        ``"<prefix>_<i>_d2"`` (the bearings' second difference over ``rho``),
        ``"<prefix>_<i>_bound"`` (the bound's depth SD), and for each reading
        ``r`` (``"fixed"``, ``"prior"``), filter and score of
        :data:`HARD_SCORES` ``"<prefix>_<i>_<r>_<filter>_<score>"``:
        ``"value ± standard error"`` (:func:`~depthcore.formatting.value_se`; two decimals for
        the
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
                    out[f"{prefix}_{i}_{reading}_{name}_{score}"] = score_text(s, score)
    return out


def score_text(scores: dict, score: str) -> str:
    """One score of one filter as :func:`hard_texts` shows it: ``"value ± standard error"``.

    Two decimals for a coverage, three significant figures' worth for a depth
    (:func:`~depthcore.formatting.value_se`).
    """
    value = scores[score]
    if score.startswith("coverage"):
        decimals = 2
    else:
        decimals = max(0, 2 - int(np.floor(np.log10(max(abs(value), 1e-3)))))
    return value_se(value, scores[f"{score}_se"], decimals)


def extreme_text(cells: list, reading: str, name: str, score: str, which: str, where=None):
    """The cell where a filter's score is least or greatest, and that score with its SE.

    Parameters
    ----------
    cells : list of dict
        From :func:`depthcore.studies.hardness.hard_study`.
    reading : {"fixed", "prior"}
    name : str
        A filter of the cells.
    score : str
        One of :data:`HARD_SCORES`.
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
        :func:`depthcore.studies.hardness.verdicts`).

    Returns
    -------
    (int, int, int)
        Significantly above (a win), undecided, significantly below.
    """
    v = np.asarray(outcomes)
    if not np.isin(v, (-1, 0, 1)).all():
        raise ValueError("outcomes must each be 1, 0 or -1")
    return tuple(int(np.sum(v == k)) for k in (1, 0, -1))
