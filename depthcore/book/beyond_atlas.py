"""The chapter on the atlas: where each filter is calibrated, loses the track, nears the bound.

Recommended import: ``from depthcore.book import beyond_atlas``.

:func:`verdict_counts` counts each filter's verdicts over the cells of
:func:`depthcore.studies.atlas.atlas`, :func:`count_texts` gives them as the
chapter glues them and :func:`cost_rows` the measured cost per trial;
:func:`verdict_map` draws one verdict over every cell, small multiples of
parallax by depth.
"""

from __future__ import annotations

import numpy as np

from depthcore.book.style import MIN_FONT, STYLE, WIDTH, subplots
from depthcore.studies import atlas

#: The outcomes of a verdict in a cell, as :func:`verdict_grid` codes them.
OUTCOMES = {True: 1.0, False: 0.0, None: 2.0}

#: Where a filter has no answer in a cell (it failed on a trial, or none was valid).
NO_ANSWER = 3.0

#: The colours of :data:`OUTCOMES` and :data:`NO_ANSWER`: yes dark, no light, undecided grey.
COLOURS = ("#deebf7", "#08519c", "#969696", "#ffffff")


def _undecided(entry: dict, verdict: str) -> bool:
    return entry.get(verdict) is None and "failed" not in entry


def verdict_counts(result: dict, names=None) -> dict:
    """Per filter and verdict, in how many cells it is yes, no, undecided, or has no answer.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.studies.atlas.atlas`.
    names : sequence of str, optional
        Default the atlas's filters.

    Returns
    -------
    dict
        ``{name: {verdict: {"yes", "no", "undecided", "no_answer", "cells"}}}``:
        a cell where the filter failed, or had no valid trial, has no answer;
        one where its score is not finite is undecided.
    """
    names = result["names"] if names is None else names
    out = {}
    for name in names:
        out[name] = {}
        for verdict in atlas.VERDICTS:
            c = dict.fromkeys(("yes", "no", "undecided", "no_answer", "cells"), 0)
            for cell in result["cells"]:
                entry = cell["filters"].get(name)
                c["cells"] += 1
                if entry is None or "failed" in entry:
                    c["no_answer"] += 1
                elif entry[verdict] is None:
                    c["undecided"] += 1
                else:
                    c["yes" if entry[verdict] else "no"] += 1
            out[name][verdict] = c
    return out


def count_texts(counts: dict, prefix: str) -> dict:
    """The counts as glued: ``{prefix}_{name}_{verdict}`` is "yes (undecided)"."""
    return {
        f"{prefix}_{name}_{verdict}": f"{c['yes']} ({c['undecided']})"
        for name, by in counts.items()
        for verdict, c in by.items()
    }


def verdict_grid(result: dict, verdict: str, names) -> tuple:
    """One verdict as a matrix of tiles, with the settings of its columns.

    Rows: per filter, the depths (increasing downwards), then a gap; columns:
    per setting of frames, noise and prior (in :data:`depthcore.studies.atlas.AXES`
    order), the parallaxes (increasing to the right), then a gap.

    Returns
    -------
    tuple
        ``(matrix, settings)``: ``matrix`` of shape
        ``(F (D + 1) - 1, S (P + 1) - 1)`` coded by :data:`OUTCOMES` and
        :data:`NO_ANSWER`, NaN in the gaps; ``settings`` the ``S`` column
        groups' ``(form, frames, rho, prior_scale)``.
    """
    axes = result["axes"]
    shape = [len(axes[a]) for a in atlas.AXES]
    *outer, n_depth, n_par = shape
    n_set = int(np.prod(outer))
    m = np.full((len(names) * (n_depth + 1) - 1, n_set * (n_par + 1) - 1), np.nan)
    for i, cell in enumerate(result["cells"]):
        s, rest = divmod(i, n_depth * n_par)
        d, p = divmod(rest, n_par)
        for f, name in enumerate(names):
            entry = cell["filters"].get(name)
            if entry is None or "failed" in entry:
                value = NO_ANSWER
            else:
                value = OUTCOMES[entry[verdict]]
            m[f * (n_depth + 1) + d, s * (n_par + 1) + p] = value
    settings = [
        tuple(cell[a] for a in atlas.AXES[:4]) for cell in result["cells"][:: n_depth * n_par]
    ]
    return m, settings


def _noise_label(rho: float) -> str:
    return f"{rho / atlas.PIXEL:.2g} px"


def verdict_map(result: dict, verdict: str, names=None):
    """One verdict in every cell: for each filter (rows) and setting (columns), a tile.

    Each tile holds the parallaxes (increasing to the right) by the depths
    (increasing downwards); a cell is dark where the verdict holds, light
    where it does not, grey where the test cannot decide, white with a cross
    where the filter has no answer. The columns are grouped by frames (top),
    then noise in pixels and prior scale.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap

    names = result["names"] if names is None else names
    m, settings = verdict_grid(result, verdict, names)
    axes = result["axes"]
    n_depth, n_par = len(axes["depth"]), len(axes["parallax"])
    height = 1.2 + m.shape[0] / m.shape[1] * WIDTH * 0.8
    fig, ax = subplots(figsize=(WIDTH, height))
    cmap = ListedColormap(COLOURS)
    ax.imshow(m, cmap=cmap, norm=BoundaryNorm([-0.5, 0.5, 1.5, 2.5, 3.5], 4), aspect="equal")
    rows, cols = np.nonzero(m == NO_ANSWER)
    ax.scatter(cols, rows, marker="x", s=6, color="0.3", linewidths=0.6)
    ax.set_yticks([f * (n_depth + 1) + (n_depth - 1) / 2 for f in range(len(names))])
    ax.set_yticklabels([STYLE[n]["label"] for n in names], fontsize=MIN_FONT)
    ax.set_xticks([s * (n_par + 1) + (n_par - 1) / 2 for s in range(len(settings))])
    ax.set_xticklabels(
        [f"{_noise_label(rho)}\n$s = {scale:g}$" for _, _, rho, scale in settings],
        fontsize=MIN_FONT,
    )
    top = ax.secondary_xaxis("top")
    frames = [f for _, f, _, _ in settings]
    starts = [s for s in range(len(settings)) if s == 0 or frames[s] != frames[s - 1]]
    ends = starts[1:] + [len(settings)]
    top.set_xticks([((a + b) * (n_par + 1) - 2) / 2 for a, b in zip(starts, ends, strict=True)])
    top.set_xticklabels([f"N = {frames[a]}" for a in starts], fontsize=MIN_FONT)
    top.tick_params(length=0)
    for a in starts[1:]:
        ax.axvline(a * (n_par + 1) - 1, color="0.2", linewidth=1.0)
    ax.tick_params(length=0)
    for spine in ax.spines.values():
        spine.set_visible(False)
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Patch(facecolor=COLOURS[1], label="yes"),
        Patch(facecolor=COLOURS[0], edgecolor="0.6", label="no"),
        Patch(facecolor=COLOURS[2], label="undecided"),
        Line2D([], [], marker="x", linestyle="", color="0.3", label="no answer"),
    ]
    fig.legend(
        handles=handles, loc="outside lower center", ncol=4, frameon=False, fontsize=MIN_FONT
    )
    return fig


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
