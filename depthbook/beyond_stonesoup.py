"""The chapter on Stone Soup: the exact filter and the EKF on one track, run by that framework.

Recommended import: ``from depthbook import beyond_stonesoup``.

The page runs both filters through Stone Soup's predictors and updaters
(:mod:`depthcore.stonesoup`); this module only draws what they return, so it
takes plain arrays: :func:`offset_figure` draws each filter's depth error
along the track with a band of one SD.
"""

from __future__ import annotations

import numpy as np

from depthbook.style import MIN_FONT, STYLE, WIDTH, subplots


def offset_figure(runs: dict, true_depth, missed, limit: float = 3.0):
    """Each filter's depth mean minus the true depth, frame by frame, with one SD.

    Parameters
    ----------
    runs : dict
        ``{name: (means, covs)}``, ``name`` a filter of the registry (its plot
        style), ``means`` of shape (N, 3) and ``covs`` of shape (N, 3, 3), the
        state ``(x, y, v)`` after each frame.
    true_depth : array_like, shape (N,)
        The true depth ``y`` at each frame.
    missed : sequence of int
        The frames (numbered from 1) without a detection, marked by a line.
    limit : float
        The vertical axis spans ``[-limit, limit]``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    true_depth = np.asarray(true_depth, dtype=float)
    frame = np.arange(1, true_depth.size + 1)
    fig, ax = subplots(figsize=(WIDTH, 3.2))
    for name, (means, covs) in runs.items():
        style = {**STYLE[name]}
        label = style.pop("label")
        offset = np.asarray(means)[:, 1] - true_depth
        sd = np.sqrt(np.asarray(covs)[:, 1, 1])
        ax.fill_between(
            frame, offset - sd, offset + sd, color=style.get("color"), alpha=0.2, linewidth=0
        )
        ax.plot(frame, offset, label=label, **style)
    ax.axhline(0.0, color="grey", linewidth=0.8)
    for k in missed:
        ax.axvline(k, color="grey", linestyle=":", linewidth=1)
    ax.set_ylim(-limit, limit)
    ax.set_xlabel("frame $k$", fontsize=MIN_FONT)
    ax.set_ylabel("depth mean − true depth", fontsize=MIN_FONT)
    ax.tick_params(labelsize=MIN_FONT)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig
