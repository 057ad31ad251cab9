"""A point in 3-D seen as bearing pairs: the tracks' frames checked once for every filter.

Recommended import: ``from depthcore.problem import bearing_pairs``.

A point with state ``(x, y, v, h, w)`` (the paper's ``(x, y, v)``, its height ``h``
and vertical velocity ``w``) is seen at frame ``k`` as the pair ``(mu_k, nu_k) =
(x_k / y_k, h_k / y_k)`` plus noise of SD ``rho_k`` on each. A track is ``mu`` of
shape ``(N, 2)`` (or ``(..., N, 2)``) with a row of ``NaN`` at a missing frame, a
noise level per track or per frame, and signed steps, as
:mod:`depthcore.problem.frames` describes them for the plane. :func:`check` checks
it once for the 3-D filters (:mod:`depthcore.exact.spatial`,
:mod:`depthcore.kalman.spatial`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.problem import checks, frames


class Pairs(NamedTuple):
    """Checked tracks of bearing pairs (:func:`check`), flattened to ``B`` rows.

    Attributes
    ----------
    mu : ndarray, shape (B, N, 2)
        ``NaN`` rows at missing frames.
    present : ndarray of bool, shape (B, N)
    rho : ndarray, shape (B, N)
        Noise SD per frame, on each coordinate (1 at missing frames).
    steps : ndarray, shape (B, N - 1)
    batch : tuple of int
        The leading shape the rows came from.
    """

    mu: np.ndarray
    present: np.ndarray
    rho: np.ndarray
    steps: np.ndarray
    batch: tuple

    @property
    def elapsed(self) -> np.ndarray:
        """Depth travelled since frame 1 at each frame, (B, N)."""
        zero = np.zeros((len(self.steps), 1))
        return np.concatenate([zero, np.cumsum(self.steps, axis=1)], axis=1)


def check(mu, rho, steps=None) -> Pairs:
    """Check tracks of pairs ``(mu_k, nu_k)``: gaps, noise per frame, signed steps.

    Parameters
    ----------
    mu : array_like, shape (N, 2) or (..., N, 2)
        ``(x / y, h / y)`` per frame; a row of ``NaN`` is a missing frame. At least
        :data:`depthcore.problem.frames.MIN_PRESENT` pairs present, and in one of
        the two coordinates not all on a line in the depth travelled.
    rho : float or array_like, shape (...) or (..., N)
        Noise SD on each coordinate, per track or per frame.
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
        As for :func:`depthcore.problem.frames.check`.

    Returns
    -------
    Pairs

    Raises
    ------
    ValueError
        One line naming the argument.
    """
    arr = checks.as_float(mu, "mu")
    if arr.ndim < 2 or arr.shape[-1] != 2:
        raise ValueError(
            f"mu must have shape (N, 2) or (..., N, 2), a pair (x / y, h / y) per frame, "
            f"got shape {arr.shape}"
        )
    half = np.isnan(arr[..., 0]) != np.isnan(arr[..., 1])
    if np.any(half):
        k = np.unravel_index(int(np.argmax(half)), half.shape)
        raise ValueError(
            f"mu{list(map(int, k))} has one coordinate missing: a frame has both or neither"
        )
    across = frames.check(arr[..., 0], rho, steps, parallax=False)
    up = np.where(across.present, arr[..., 1], np.nan)
    if np.any(np.isinf(up)):
        raise ValueError("mu must be finite or NaN (a missing frame), got infinite entries")
    flat = frames.degenerate(across.mu, across.present, across.elapsed) & frames.degenerate(
        np.where(across.present, up, 0.0), across.present, across.elapsed
    )
    if np.any(flat):
        raise ValueError(
            "mu is degenerate: both coordinates lie on lines in the depth travelled, "
            "so no finite depth explains them"
        )
    batch, n = across.mu.shape[:-1], across.mu.shape[-1]
    B = int(np.prod(batch))
    return Pairs(
        np.stack([across.mu, up], axis=-1).reshape(B, n, 2),
        across.present.reshape(B, n),
        np.ascontiguousarray(across.rho).reshape(B, n),
        np.ascontiguousarray(across.steps).reshape(B, n - 1),
        batch,
    )
