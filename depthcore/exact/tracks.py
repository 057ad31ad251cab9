"""The frames of a track for the bank of Kalman filters over depth: steps, noise, gaps.

Recommended import: ``from depthcore.exact import tracks``.

The bank (:mod:`depthcore.exact.bank`) runs the motion of
:mod:`depthcore.problem.frames` given the depth: with the depth travelled
``e_k = y_k - y_1`` (:func:`elapsed`), the lateral state ``(x, v)`` moves by
``[[1, s_k], [0, 1]]`` (:func:`transitions`) with velocity noise ``q**2 |s_k|``
(the step signed: negative while the camera approaches the point),
the bearing at frame ``k`` observes ``(1 / (y_1 + e_k), 0)`` with noise
``rho_k**2``, and a missing frame has no update. This module holds those
pieces, the bank's frame fields, the checks of a track for
:func:`depthcore.exact.bank.filter_bank` and the filters' history on such a
track (:func:`irregular_history`).
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import linear
from depthcore.problem import checks


def frame_fields(mu, rho, steps, frame_rho) -> dict:
    """The bank's ``frame_steps`` and ``frame_noise`` from ``steps`` and ``frame_rho`` or ``None``.

    Broadcast to the bearings' batch: ``(..., N - 1)`` and ``(..., N)``.
    """
    batch, N = mu.shape[:-1], mu.shape[-1]
    s = np.ones(N - 1) if steps is None else np.asarray(steps, dtype=float)
    r = np.asarray(rho, dtype=float)[..., None] if frame_rho is None else frame_rho
    noise_batch = np.broadcast_shapes(batch, np.shape(r)[:-1])
    return {
        "frame_steps": np.broadcast_to(s, np.broadcast_shapes(batch, s.shape[:-1]) + (N - 1,)),
        "frame_noise": np.broadcast_to(r, noise_batch + (N,)),
    }


def elapsed(steps, frames: int) -> np.ndarray:
    """``y_k - y_1`` at frames ``k = 1 .. N``, shape (..., N), from the steps (..., N - 1).

    ``None`` steps are unit steps: ``0, 1, .., N - 1``.
    """
    if steps is None:
        return np.arange(float(frames))
    steps = np.asarray(steps, dtype=float)
    zero = np.zeros(steps.shape[:-1] + (1,))
    return np.concatenate([zero, np.cumsum(steps, axis=-1)], axis=-1)


def check_track(mu, rho, steps, bearings):
    """Bearings with gaps, noise per problem or per frame, steps, checked for ``filter_bank``.

    ``bearings`` checks ``mu`` for the paper's frames. Returns ``mu``, ``rho``
    (``frame_rho`` where given per frame), ``steps`` (``None`` for unit steps)
    and ``frame_rho`` (``None`` for noise per problem).
    """
    arr = checks.as_float(mu, "mu")
    if arr.ndim < 1 or arr.shape[-1] < 1 or arr.size == 0:
        return bearings(mu), rho, None, None
    rho_arr = checks.as_float(rho, "rho")
    per_frame = rho_arr.ndim >= 1 and rho_arr.shape == arr.shape
    if steps is None and not per_frame and not np.any(np.isnan(arr)):
        return bearings(arr), rho, None, None
    if np.any(np.isinf(arr)):
        raise ValueError("mu must be finite or NaN (a missing frame), got infinite entries")
    present = ~np.isnan(arr)
    frame_rho = None
    if per_frame:
        frame_rho = np.where(present, rho_arr, 1.0)
        if not np.all(np.isfinite(frame_rho) & (frame_rho > 0)):
            raise ValueError("rho must be finite and positive at every present frame")
        rho = frame_rho
    if steps is not None:
        steps = checks.finite_array(steps, "steps")
        N = arr.shape[-1]
        if steps.ndim < 1 or steps.shape[-1] != N - 1:
            raise ValueError(
                f"steps must have shape (..., {N - 1}), one per pair of frames, "
                f"got shape {steps.shape}"
            )
        if np.any(steps == 0):
            raise ValueError(
                "steps must be nonzero (the depth's signed change; negative: the camera "
                "approaches), got a zero step"
            )
    return arr, rho, steps, frame_rho


def transitions(steps) -> np.ndarray:
    """``[[1, s_k], [0, 1]]`` per step: shape (..., N - 1, 2, 2) for steps (..., N - 1)."""
    steps = np.asarray(steps, dtype=float)
    out = np.broadcast_to(np.eye(2), steps.shape + (2, 2)).copy()
    out[..., 0, 1] = steps
    return out


def irregular_history(start, nodes, mu, rho, q, steps, frame_rho) -> linear.FilterResult:
    """Each node's Kalman filter at every frame with steps, per-frame noise and gaps.

    :func:`depthcore.kalman.linear.run` with the transition ``[[1, s_k], [0, 1]]``
    and the noise ``diag(0, q**2 |s_k|)`` per step; a missing frame has a zero
    measurement row (no update), whose log density (of a zero bearing with unit
    noise) is replaced by 0.
    """
    N = mu.shape[-1]
    present = ~np.isnan(mu)
    depth = nodes[..., None] + elapsed(steps, N)[..., None, :]  # (..., J, N)
    depth = np.where(depth > 0, depth, 1.0)  # behind the camera: no weight (bank.run_bank)
    Phi = np.zeros(depth.shape + (1, 2))
    Phi[..., 0, 0] = np.where(present[..., None, :], 1.0 / depth, 0.0)
    if frame_rho is None:
        r = np.asarray(rho, dtype=float)[..., None]
    else:
        r = frame_rho
    r2 = np.where(present, r, 1.0) ** 2  # (..., N)
    s = np.ones(N - 1) if steps is None else np.asarray(steps, dtype=float)
    Sigma_p = np.zeros(np.broadcast_shapes(np.shape(q) + (1,), s.shape) + (2, 2))
    Sigma_p[..., 1, 1] = np.asarray(q, dtype=float)[..., None] ** 2 * np.abs(s)
    Psi = transitions(s)
    res = linear.run(
        np.where(present, mu, 0.0)[..., None, :, None],
        start.mean,
        start.cov,
        Psi[..., None, :, :, :],
        Sigma_p[..., None, :, :, :],
        Phi,
        r2[..., None, :, None, None],
    )
    return res._replace(log_likelihoods=np.where(present[..., None, :], res.log_likelihoods, 0.0))


def noise_free_start(mu, steps) -> np.ndarray:
    """The depth at frame 1 (B,) that fits the first three present bearings exactly, or NaN.

    ``mu`` (B, N) with ``NaN`` at missing frames, ``steps`` (B, N - 1) or ``None``.

    With ``e_k`` the depth travelled to frame ``k``, the noise-free bearings
    satisfy ``mu_k (y + e_k) = x + e_k v``: three linear equations in
    ``(x, v, y)``.
    """
    B, N = mu.shape
    e = np.broadcast_to(
        np.arange(float(N))
        if steps is None
        else np.concatenate([np.zeros((B, 1)), np.cumsum(steps, axis=1)], axis=1),
        (B, N),
    )
    present = ~np.isnan(mu)
    order = np.argsort(~present, axis=1, kind="stable")[:, :3]
    m = np.take_along_axis(np.where(present, mu, 0.0), order, 1)
    ek = np.take_along_axis(e, order, 1)
    A = np.stack([-np.ones_like(m), -ek, m], -1)  # (B, 3, 3) in (x, v, y)
    with np.errstate(all="ignore"):
        det = np.linalg.det(A)
        ok = np.abs(det) > 1e-300
        sol = np.linalg.solve(np.where(ok[:, None, None], A, np.eye(3)), (-m * ek)[..., None])
    return np.where(ok, sol[:, 2, 0], np.nan)
