"""A track's frames as they come: missing bearings, noise per frame, uneven steps.

Recommended import: ``from depthcore.problem import frames``.

The paper's track has a bearing at every frame, one noise level and a unit
step between frames, the point receding from the camera. A real track has gaps
(a missed detection), a noise level per frame (a detector's own uncertainty) and
frames at uneven intervals (a camera moving at varying speed, frames dropped by the
capture).
This module describes such a track and checks it, once, for every filter:

* a missing bearing is ``NaN`` in ``mu``: the filters predict through that
  frame without an update;
* ``rho`` is a number, one per problem (shape ``mu.shape[:-1]``) or one per
  frame (shape ``mu.shape``);
* ``steps``, shape ``(N - 1,)`` (or ``mu.shape[:-1] + (N - 1,)``), is the
  depth's signed change from each frame to the next, ``y_{k+1} = y_k + s_k``:
  positive while the point recedes (the camera moves away from it), negative
  while it approaches (the camera moves towards it), never zero. The point
  moves on a straight line, ``x = x_1 + v (y - y_1)``, so the lateral position
  moves by ``x_{k+1} = x_k + s_k v_k`` for either sign (Eq. (1) with the step
  ``s_k`` in place of 1, :func:`depthcore.problem.model.G` with ``k = s_k``).
  The depth must stay positive at every frame: the filters give no weight to
  depths that would reach the camera (:func:`depth_floor`).

The process noise and the step. With process noise of SD ``q`` the velocity is
a random walk whose variance grows in proportion to the distance moved:
``v_{k+1} = v_k + a_k``, ``a_k ~ N(0, q**2 |s_k|)`` (:func:`velocity_variance`),
the same whichever way the camera moves.
A unit step is the paper's model with the textbook's ``Sigma_p = diag(0, 0,
q**2)`` (textbook Eq. (19.10)); two steps of ``s / 2`` add the same velocity
variance as one step of ``s``, so ``q`` is a rate per unit of depth, not per
frame.

Every filter's door takes ``mu``, ``rho`` and ``steps`` as described here and
checks them with :func:`check`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.problem import checks

#: The fewest bearings a problem must have present (two bearings fit any depth alike).
MIN_PRESENT = 3

#: The range of a noise SD, where its square (a variance) and the square of its
#: inverse (an information) must be normal doubles.
RHO_LIMITS = (1e-150, 1e150)


class Frames(NamedTuple):
    """A batch of tracks' frames, checked by :func:`check`.

    Attributes
    ----------
    mu : ndarray, shape (..., N)
        Bearings, ``NaN`` where a frame has none.
    present : ndarray of bool, shape (..., N)
        Where a bearing is present.
    rho : ndarray, shape (..., N)
        Noise SD per frame (a read-only broadcast view); ``1.0`` at missing frames,
        where it is never used.
    steps : ndarray, shape (..., N - 1)
        The depth's change from each frame to the next (a read-only broadcast view).
    """

    mu: np.ndarray
    present: np.ndarray
    rho: np.ndarray
    steps: np.ndarray

    @property
    def elapsed(self) -> np.ndarray:
        """Depth travelled since frame 1 at each frame, shape (..., N), from 0."""
        zero = np.zeros(self.steps.shape[:-1] + (1,))
        return np.concatenate([zero, np.cumsum(self.steps, axis=-1)], axis=-1)

    @property
    def floor(self) -> np.ndarray:
        """The depth at frame 1 below which the point reaches the camera, shape (...).

        :func:`depth_floor` of :attr:`elapsed`: 0 while the point only recedes.
        """
        return depth_floor(self.elapsed)

    @property
    def regular(self) -> bool:
        """Whether these are the paper's frames (every bearing, unit steps, one ``rho`` per row)."""
        return bool(
            np.all(self.present)
            and np.all(self.steps == 1.0)
            and np.all(self.rho == self.rho[..., :1])
        )

    @property
    def row_rho(self) -> np.ndarray:
        """``rho`` per problem, shape (...), when each row has one (see :attr:`regular`)."""
        return np.array(self.rho[..., 0])


def velocity_variance(process_noise, step) -> np.ndarray:
    """The velocity's variance added over a step: ``q**2 |s|`` (see the module docstring).

    Parameters
    ----------
    process_noise : float
        ``q >= 0``, the SD of the velocity's change over a unit step.
    step : float or array_like
        ``s != 0``, the depth's signed change; the variance grows with the distance moved.

    Returns
    -------
    ndarray, the shape of ``step``
    """
    return float(process_noise) ** 2 * np.abs(np.asarray(step, dtype=float))


def depth_floor(elapsed) -> np.ndarray:
    """The least depth at frame 1 that keeps the point in front of the camera at every frame.

    With ``e_k = y_k - y_1`` the depth travelled to frame ``k`` (``e_1 = 0``), the
    depths ``y_k = y_1 + e_k`` are all positive exactly when ``y_1 > -min_k e_k``:
    the floor is ``max(0, -min_k e_k)``, where the point comes nearest to the
    camera. 0 for a receding point; for one that approaches, the depth travelled
    towards the camera at its nearest.

    Parameters
    ----------
    elapsed : array_like, shape (..., N)

    Returns
    -------
    ndarray, shape (...)
    """
    elapsed = np.asarray(elapsed, dtype=float)
    return np.maximum(-np.min(elapsed, axis=-1), 0.0)


def transition(step) -> np.ndarray:
    """The linear part of the motion over a step ``s``: ``[[1, 0, s], [0, 1, 0], [0, 0, 1]]``.

    Eq. (9) with the step ``s`` in place of 1 (:func:`depthcore.problem.model.G_linear`).

    Parameters
    ----------
    step : float or array_like, shape (...)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    s = np.asarray(step, dtype=float)
    F = np.broadcast_to(np.eye(3), s.shape + (3, 3)).copy()
    F[..., 0, 2] = s
    return F


def _mu(value) -> np.ndarray:
    mu = checks.frame_rows(checks.as_float(value, "mu"), "mu", "frames")
    if np.any(np.isinf(mu)):
        raise ValueError(
            f"mu must be finite or NaN (a missing frame), got {int(np.sum(np.isinf(mu)))} "
            "infinite entries"
        )
    return mu


def _rho(value, mu: np.ndarray, present: np.ndarray) -> np.ndarray:
    rho = checks.as_float(value, "rho")
    batch = mu.shape[:-1]
    if rho.ndim and rho.shape not in (batch, mu.shape):
        allowed = "a number" + (f", shape {batch}" if batch else "") + f" or shape {mu.shape}"
        raise ValueError(f"rho must be {allowed} (one per frame), got shape {rho.shape}")
    per_frame = rho.shape == mu.shape and rho.ndim > 0
    rho = np.broadcast_to(rho[..., None] if not per_frame else rho, mu.shape)
    used = np.where(present, rho, 1.0)
    bad = ~(np.isfinite(used) & (used > 0))
    if np.any(bad):
        where = np.unravel_index(int(np.argmax(bad)), mu.shape)
        index = "[" + ", ".join(str(int(i)) for i in where) + "]" if per_frame else ""
        raise ValueError(f"rho{index} must be finite and positive, got {float(used[where])!r}")
    extreme = (used < RHO_LIMITS[0]) | (used > RHO_LIMITS[1])
    if np.any(extreme):
        where = np.unravel_index(int(np.argmax(extreme)), mu.shape)
        index = "[" + ", ".join(str(int(i)) for i in where) + "]" if per_frame else ""
        raise ValueError(
            f"rho{index} must be from {RHO_LIMITS[0]:g} to {RHO_LIMITS[1]:g} (its square a "
            f"normal double), got {float(used[where])!r}"
        )
    return used


def _steps(value, mu: np.ndarray) -> np.ndarray:
    n = mu.shape[-1]
    if value is None:
        return np.broadcast_to(np.ones(n - 1), mu.shape[:-1] + (n - 1,))
    steps = checks.finite_array(value, "steps")
    if (
        steps.ndim < 1
        or steps.shape[-1] != n - 1
        or not checks.broadcasts(steps.shape, mu.shape[:-1] + (n - 1,))
    ):
        raise ValueError(
            f"steps must have shape ({n - 1},), one per pair of consecutive frames, "
            f"got shape {steps.shape}"
        )
    if np.any(steps == 0):
        raise ValueError(
            "steps must be nonzero: the depth's signed change between frames, positive "
            "while the point recedes, negative while the camera approaches it; got a zero step"
        )
    return np.broadcast_to(steps, mu.shape[:-1] + (n - 1,))


def degenerate(mu: np.ndarray, present: np.ndarray, elapsed: np.ndarray) -> np.ndarray:
    """Rows whose present bearings are (numerically) affine in the depth travelled, (...).

    ``mu``, ``present`` and ``elapsed`` of shape (..., N), each row with at least
    :data:`MIN_PRESENT` bearings present.

    The second divided differences of consecutive present bearings, scaled so
    that at unit steps they are ``mu_k - 2 mu_{k+1} + mu_{k+2}`` (the check of
    :func:`depthcore.problem.model.measurements_batch`).
    """
    flat_mu = mu.reshape(-1, mu.shape[-1])
    flat_p = present.reshape(flat_mu.shape)
    flat_t = np.broadcast_to(elapsed, mu.shape).reshape(flat_mu.shape)
    out = np.zeros(len(flat_mu), dtype=bool)
    full = np.all(flat_p, axis=1)
    rows = [np.flatnonzero(full)] + [[i] for i in np.flatnonzero(~full)]
    for r in rows:
        m, t = flat_mu[r], flat_t[r]
        if len(r) == 1 and not full[r[0]]:
            m, t = m[:, flat_p[r[0]]], t[:, flat_p[r[0]]]
        slopes = np.diff(m, axis=1) / np.diff(t, axis=1)
        second = np.diff(slopes, axis=1) * (t[:, 2:] - t[:, :-2]) / 2.0
        out[r] = ~np.any(np.abs(second) > checks.DEGENERACY_TOL, axis=1)
    return out.reshape(mu.shape[:-1])


def check(mu, rho, steps=None, parallax: bool = True) -> Frames:
    """Check a batch of tracks: bearings with gaps, noise per frame, steps.

    Parameters
    ----------
    mu : array_like, shape (..., N)
        Bearings in time order, ``N >= 3``; ``NaN`` marks a missing frame.
        Each problem needs at least :data:`MIN_PRESENT` bearings present, not
        all on a line in the depth travelled (no finite depth explains them).
    rho : float or array_like, shape (...) or (..., N)
        Noise SD, > 0, per problem or per frame (any value at a missing frame,
        ``NaN`` included).
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
        The depth's signed change between consecutive frames, nonzero (negative:
        the camera approaches the point); ``None``: all ones.
    parallax : bool
        Refuse rows whose bearings lie on a line in the depth travelled
        (:func:`degenerate`); ``False`` leaves that to the caller (a point in 3-D
        may show its parallax in the other coordinate).

    Returns
    -------
    Frames

    Raises
    ------
    ValueError
        One line naming the argument (and the row of a batch) that is wrong.
    """
    mu = _mu(mu)
    present = ~np.isnan(mu)
    rho = _rho(rho, mu, present)
    steps = _steps(steps, mu)
    batch = mu.shape[:-1]
    counts = present.sum(axis=-1)
    if np.any(counts < MIN_PRESENT):
        i = int(np.argmin(counts.reshape(-1)))
        where = "mu" + (checks.batch_index(i, batch) if batch else "")
        raise ValueError(
            f"{where} has {int(counts.reshape(-1)[i])} bearings present; at least "
            f"{MIN_PRESENT} are needed to fix a depth"
        )
    frames = Frames(mu, present, rho, steps)
    gaps = np.diff(frames.elapsed, axis=-1)
    if not (np.all(np.isfinite(frames.elapsed)) and np.all(gaps != 0)):
        raise ValueError(
            "steps must add up to a depth travelled that changes at every frame in double "
            f"precision; steps from {float(np.min(steps)):.3g} to {float(np.max(steps)):.3g} "
            "lose a step to rounding"
        )
    flat = degenerate(mu, present, frames.elapsed) if parallax else np.zeros(batch, bool)
    if np.any(flat):
        i = int(np.argmax(flat.reshape(-1)))
        where = "mu" + (checks.batch_index(i, batch) if batch else "")
        raise ValueError(
            f"{where} is degenerate: its bearings lie on a line in the depth travelled "
            f"(every second difference at most {checks.DEGENERACY_TOL:g} in magnitude), "
            "so no finite depth explains them"
        )
    return frames
