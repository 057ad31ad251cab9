"""The chapter "Why three bearings fix a depth": two bearings fit every depth, the step fixes it.

Recommended import: ``from depthbook import intuition``.

Two bearings ``mu_1``, ``mu_2`` of a point moving by Eq. (1) are met exactly
by a track at every depth: at depth ``y`` at time 3, ``x_1 = mu_1 y_1`` and
``x_2 = mu_2 y_2`` fix the position at two times, and the velocity is their
difference. :func:`two_bearing_tracks` draws that family, one track per depth;
:func:`third_bearing` is the bearing each track predicts at time 3, which
meets the measured ``mu_3`` at one depth only, the ``c_2`` of Eq. (7), in
units of the known step between frames (:func:`depth_for_step`).
:func:`bearings_figure` draws both.
"""

from __future__ import annotations

import numpy as np

from depthbook.style import MIN_FONT, WIDTH, subplots


def two_bearing_tracks(mu, depths, step: float = 1.0) -> np.ndarray:
    """The tracks that meet the first two bearings exactly, one per depth at time 3.

    Parameters
    ----------
    mu : array_like, shape (2,) or (3,)
        The bearings; only ``mu_1`` and ``mu_2`` are used.
    depths : array_like, shape (n,)
        Depths ``y_3`` at time 3, each above ``2 step`` (in front of the camera at time 1).
    step : float
        The depth's change between consecutive frames, > 0 (the paper's 1).

    Returns
    -------
    ndarray, shape (n, 3, 3)
        ``[j, i]`` is the state ``(x, y, v)`` of track ``j`` at time ``i + 1``.
    """
    mu = np.asarray(mu, dtype=float)
    y3 = np.atleast_1d(np.asarray(depths, dtype=float))
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    if y3.ndim != 1 or np.any(y3 <= 2 * step):
        raise ValueError("depths must be a 1-D array of depths above 2 * step")
    y = y3[:, None] - step * np.array([2.0, 1.0, 0.0])  # (n, 3): depth at times 1, 2, 3
    x1, x2 = mu[0] * y[:, 0], mu[1] * y[:, 1]
    v = x2 - x1  # lateral motion per frame
    x = np.stack([x1, x2, x2 + v], axis=-1)
    return np.stack([x, y, np.broadcast_to(v[:, None], y.shape)], axis=-1)


def third_bearing(mu, depths, step: float = 1.0) -> np.ndarray:
    """The bearing ``x_3 / y_3`` that each track of :func:`two_bearing_tracks` predicts.

    Returns
    -------
    ndarray, shape (n,)
    """
    tracks = two_bearing_tracks(mu, depths, step)
    return tracks[:, 2, 0] / tracks[:, 2, 1]


def depth_for_step(mu, step: float = 1.0) -> float:
    """The one depth at time 3 whose two-bearing track meets ``mu_3`` too.

    Setting :func:`third_bearing` equal to ``mu_3`` gives
    ``y_3 = 2 step (mu_1 - mu_2) / (mu_1 + mu_3 - 2 mu_2)``: Eq. (7)'s ``c_2``
    times the step.

    Parameters
    ----------
    mu : array_like, shape (3,)
    step : float

    Returns
    -------
    float
    """
    mu1, mu2, mu3 = np.asarray(mu, dtype=float)
    return float(2.0 * step * (mu1 - mu2) / (mu1 + mu3 - 2.0 * mu2))


def bearings_figure(mu, depths, true_depth: float):
    """Left: tracks meeting two bearings at several depths; right: their third bearing.

    Parameters
    ----------
    mu : array_like, shape (3,)
        The measured bearings, drawn as rays from the camera at the origin.
    depths : array_like, shape (n,)
        Depths at time 3 of the tracks drawn on the left (a few).
    true_depth : float
        The depth whose track meets all three bearings, marked on the right.

    Returns
    -------
    matplotlib.figure.Figure
    """
    mu = np.asarray(mu, dtype=float)
    fig, (left, right) = subplots(1, 2, figsize=(WIDTH, 3.4))
    tracks = two_bearing_tracks(mu, depths)
    top = 1.1 * float(np.max(tracks[:, :, 1]))
    for i, m in enumerate(mu):
        left.plot(
            [0.0, m * top], [0.0, top], color="0.6", linestyle="--" if i == 2 else "-", linewidth=1
        )
        left.annotate(
            f"$\\mu_{i + 1}$", (m * top, top), fontsize=MIN_FONT, ha="center", va="bottom"
        )
    for track, depth in zip(tracks, np.atleast_1d(depths), strict=True):
        left.plot(track[:, 0], track[:, 1], marker="o", markersize=4, label=f"$y_3 = {depth:g}$")
    left.set_xlabel("lateral position $x$", fontsize=MIN_FONT)
    left.set_ylabel("depth $y$", fontsize=MIN_FONT)
    left.set_ylim(0.0, top * 1.12)
    left.legend(frameon=False, fontsize=MIN_FONT, loc="lower right")
    grid = np.linspace(2.5, 4 * true_depth, 400)
    right.plot(grid, third_bearing(mu, grid), color="C0", label="predicted $x_3/y_3$")
    right.axhline(mu[2], color="0.4", linestyle="--", linewidth=1, label="measured $\\mu_3$")
    right.axvline(true_depth, color="0.4", linestyle=":", linewidth=1)
    right.set_xlabel("depth $y_3$ of the two-bearing track", fontsize=MIN_FONT)
    right.set_ylabel("bearing at time 3", fontsize=MIN_FONT)
    right.legend(frameon=False, fontsize=MIN_FONT)
    for ax in (left, right):
        ax.tick_params(labelsize=MIN_FONT)
    return fig
