"""The Cramér-Rao bound for a point in 3-D seen as bearing pairs.

Recommended import: ``from depthcore.analysis import bound_space``.

The state ``(x, y, v, h, w)`` moves linearly (:mod:`depthcore.exact.spatial`): over a
signed step ``s`` the transition is ``F_s`` (``x += s v``, ``h += s w``, ``y += s``)
and both velocities gain variance ``q**2 |s|``. The pair ``(x / y, h / y)`` with noise
of SD ``rho_k`` on each gives the measurement information

    I_k = (g_k g_k^T + f_k f_k^T) / rho_k**2,
    g_k = (1 / y, -x / y**2, 0, 0, 0),   f_k = (0, -h / y**2, 0, 1 / y, 0),

at the true state of frame ``k`` (zero at a missing frame), and the recursion of
Tichavský et al. (1998) for linear Gaussian motion, as :mod:`depthcore.analysis.bound`
runs it for the plane,

    J_1 = P^{-1} + I_1,   J_{k+1} = (F_k J_k^{-1} F_k^T + Q_k)^{-1} + I_{k+1},

the noise entering by one Sherman-Morrison step per velocity (``Q_k`` is ``q**2 |s_k|``
on ``v`` and on ``w``), gives the bound ``J_k^{-1}`` on the error of any unbiased
estimate of the state at frame ``k`` from the pairs up to it and the prior.
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks

#: The velocities' positions in ``(x, y, v, h, w)``.
VELOCITIES = (2, 4)


def _states(states) -> np.ndarray:
    states = checks.finite_array(states, "states")
    if states.ndim < 2 or states.shape[-1] != 5 or states.shape[-2] < 1:
        raise ValueError(
            f"states must have shape (N, 5) or (..., N, 5), (x, y, v, h, w), got {states.shape}"
        )
    if not np.all(states[..., 1] > 0):
        raise ValueError("states must put the point in front of the camera at every frame")
    return states


def measurement_information(states, rho, present=None) -> np.ndarray:
    """``I_k`` of each frame's pair (module docstring), (..., N, 5, 5).

    Parameters
    ----------
    states : array_like, shape (..., N, 5)
        The true states, depth > 0.
    rho : float or array_like, shape (..., N)
        The noise SD on each coordinate, > 0.
    present : array_like of bool, shape (..., N), optional
        Where a pair is seen (default: every frame).
    """
    states = _states(states)
    rho = checks.finite_array(rho, "rho")
    if not np.all(rho > 0):
        raise ValueError(f"rho must be positive, got minimum {float(np.min(rho)):.6g}")
    x, y, h = states[..., 0], states[..., 1], states[..., 3]
    g = np.zeros(states.shape)
    f = np.zeros(states.shape)
    g[..., 0], g[..., 1] = 1.0 / y, -x / y**2
    f[..., 3], f[..., 1] = 1.0 / y, -h / y**2
    info = (g[..., :, None] * g[..., None, :] + f[..., :, None] * f[..., None, :]) / (
        np.asarray(rho, dtype=float)[..., None, None] ** 2
    )
    if present is not None:
        info = np.where(np.asarray(present, dtype=bool)[..., None, None], info, 0.0)
    return info


def _transition_inverse(s) -> np.ndarray:
    """``F_s^{-1} = F_{-s}`` of the lateral and vertical motion, (..., 5, 5)."""
    F = np.broadcast_to(np.eye(5), np.shape(s) + (5, 5)).copy()
    F[..., 0, 2] = F[..., 3, 4] = -np.asarray(s, dtype=float)
    return F


def _noise(M, variance, index: int) -> np.ndarray:
    """``(M^{-1} + variance e_i e_i^T)^{-1}`` by Sherman-Morrison."""
    column = M[..., :, index]
    denominator = 1.0 + variance * M[..., index, index]
    return (
        M
        - variance[..., None, None]
        * column[..., :, None]
        * column[..., None, :]
        / (denominator[..., None, None])
    )


def conditional_bound(states, rho, prior_cov=None, process_noise=0.0, present=None):
    """The bound ``J_k^{-1}`` (..., N, 5, 5) at every frame, on the states' own steps.

    Parameters
    ----------
    states : array_like, shape (..., N, 5)
        A true track: the steps are its depths' changes, and ``x``, ``h`` must move by
        ``s v`` and ``s w`` (with ``q = 0``, or the track drawn with its accelerations).
    rho : float or array_like, shape (..., N)
    prior_cov : array_like, shape (5, 5), optional
        The prior's covariance of the state at frame 1; ``None``: the pairs alone (the
        bound is infinite, ``NaN`` here, until they fix the state).
    process_noise : float
        ``q >= 0`` on both velocities, per unit of depth moved.
    present : array_like of bool, shape (..., N), optional

    Returns
    -------
    ndarray, shape (..., N, 5, 5)
    """
    states = _states(states)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        info = measurement_information(states, rho, present)
    if not np.all(np.isfinite(info)):
        raise ValueError("states and rho: the information exceeds the largest double")
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    steps = np.diff(states[..., 1], axis=-1)
    if np.any(steps == 0):
        raise ValueError("states must have depths that change from frame to frame")
    if prior_cov is None:
        J = np.zeros(info.shape[:-3] + (5, 5))
    else:
        P = checks.covariance(prior_cov, "prior_cov", 5)
        J = np.broadcast_to(np.linalg.inv(P), info.shape[:-3] + (5, 5))
    with np.errstate(over="ignore", invalid="ignore"):
        out = _recursion(info, J, q, steps)
    if np.any(np.isinf(out)):
        raise ValueError("states and rho: the bound exceeds the largest double")
    return out


def _recursion(info, J, q, steps):
    """The recursion of :func:`conditional_bound` on checked inputs, (..., N, 5, 5)."""
    n = info.shape[-3]
    out = np.full(info.shape, np.nan)
    for k in range(n):
        if k:
            F_inv = _transition_inverse(steps[..., k - 1])
            J = np.swapaxes(F_inv, -1, -2) @ J @ F_inv
            if q > 0:
                variance = q**2 * np.abs(steps[..., k - 1])
                for index in VELOCITIES:
                    J = _noise(J, variance, index)
        J = J + info[..., k, :, :]
        J = 0.5 * (J + np.swapaxes(J, -1, -2))
        with np.errstate(invalid="ignore"):
            full = np.linalg.matrix_rank(J) == 5
        if np.any(full):
            out[..., k, :, :] = np.where(
                full[..., None, None],
                np.linalg.inv(np.where(full[..., None, None], J, np.eye(5))),
                np.nan,
            )
    return out
