"""The Kalman filter of the lateral state ``(x, v)`` given the depth, written out elementwise.

Recommended import: ``from depthcore.exact import lateral``.

The bank of Kalman filters over depth (:mod:`depthcore.exact.bank`) runs one
two-state Kalman filter per depth node; for many nodes and problems at once it
holds their means ``M = (x, v)`` and covariances ``C = (a, b, det, c)`` (the
entries of ``Cov[(x, v)]`` and its determinant) in two arrays and updates them
in place, entry by entry (:func:`depthcore.exact.bank.lateral_filter` gives the
recursion): the prediction over a step (textbook 19.2.1, :func:`predict`), the
update by a bearing (19.2.2, :func:`update`, :func:`masked_update` where some
bearings are missing) and the conversions between these arrays and a
:class:`~depthcore.exact.bank.Bank`'s ``mean`` and ``cov``. A new
in-place operation on the nodes' filters goes here; what reads or builds a
bank stays in :mod:`depthcore.exact.bank`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: ``log(2 pi)``.
LOG_2PI = float(np.log(2.0 * np.pi))


def predict(rows, noise, s) -> None:
    """:func:`predict_unit` over a step ``s`` (..., 1), or a unit step for ``None``."""
    if s is None:
        predict_unit(rows, noise)
    else:
        predict_step(rows, None if noise is None else noise * np.abs(s), s)


def masked_update(rows, M, C, mu_k, y, rho2):
    """:func:`update` where ``mu_k`` (..., 1) is present; no change (log 0) elsewhere."""
    present = ~np.isnan(mu_k)
    if np.all(present):
        return update(rows, mu_k, y, rho2, y * y)
    if not np.any(present):
        return 0.0
    M0, C0 = M.copy(), C.copy()
    safe_rho2 = np.where(present, rho2, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):  # the entries not present are dropped
        log_likelihood = update(rows, np.where(present, mu_k, 0.0), y, safe_rho2, y * y)
    np.copyto(M, M0, where=~present)
    np.copyto(C, C0, where=~present)
    return np.where(present, log_likelihood, 0.0)


def predict_step(s: Rows, q2, step) -> None:
    """Textbook 19.2.1 over a step ``s`` (..., 1), in place; ``q2 = q**2 |s|`` or ``None``.

    ``Var[x + s v] = a + s (2 b + s c)`` is a sum of non-negative terms when ``s b >= 0``;
    otherwise (a step back along the motion, ``s < 0`` after steps forward) it is
    computed as ``(det + (b + s c)**2) / c``, the same number without cancellation.
    """
    np.add(s.x, step * s.v, out=s.x)
    shear_b = s.b + step * s.c
    direct = s.a + step * (2.0 * s.b + step * s.c)
    with np.errstate(divide="ignore", invalid="ignore"):  # only where c > 0 is it used
        stable = (s.det + shear_b * shear_b) / s.c
    np.copyto(s.a, np.where(step * s.b >= 0, direct, stable))
    np.copyto(s.b, shear_b)
    if q2 is not None:
        np.add(s.c, q2, out=s.c)
        np.add(s.det, q2 * s.a, out=s.det)


#: Rows of the lateral state arrays ``M`` (``x, v``) and ``C`` (``a, b, det, c``).
X_ROW, V_ROW = 0, 1
A_ROW, B_ROW, DET_ROW, C_ROW = 0, 1, 2, 3


class Rows(NamedTuple):
    """Views of the lateral state arrays ``M`` (2, ...) and ``C`` (4, ...), updated in place."""

    M: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    b: np.ndarray
    det: np.ndarray
    c: np.ndarray
    ab: np.ndarray
    ab_det: np.ndarray


def state(mean_shape, cov_shape):
    """Empty state arrays ``M`` (2, ...) and ``C`` (4, ...) and their :class:`Rows`."""
    mean_shape = np.broadcast_shapes(mean_shape, cov_shape)
    pad = (1,) * (len(mean_shape) - len(cov_shape))
    M, C = np.empty((2,) + mean_shape), np.empty((4,) + pad + tuple(cov_shape))
    rows = Rows(
        M,
        M[X_ROW],
        M[V_ROW],
        C[A_ROW],
        C[B_ROW],
        C[DET_ROW],
        C[C_ROW],
        C[A_ROW : B_ROW + 1],
        C[A_ROW : DET_ROW + 1],
    )
    return M, C, rows


def predict_unit(s: Rows, q2) -> None:
    """Textbook 19.2.1 for a unit step, in place; ``q2`` is ``q**2`` or ``None`` (``q = 0``)."""
    np.add(s.x, s.v, out=s.x)
    np.add(s.a, 2.0 * s.b, out=s.a)
    np.add(s.a, s.c, out=s.a)  # a + 2 b + c
    np.add(s.b, s.c, out=s.b)
    if q2 is not None:
        np.add(s.c, q2, out=s.c)
        np.add(s.det, q2 * s.a, out=s.det)


def update(s: Rows, mu_k, y, rho2, yy):
    """Textbook 19.2.2 for the bearing ``mu_k`` at depth ``y``, in place; the log likelihood.

    ``yy`` is ``y * y``; see :func:`depthcore.exact.bank.lateral_filter`.
    """
    r = rho2 * yy
    total = s.a + r
    e = mu_k * y - s.x
    g = e / total
    log_likelihood = -0.5 * (LOG_2PI + np.log(total / yy) + e * g)
    np.add(s.M, s.ab * g, out=s.M)  # x + a g and v + b g
    # c - b**2 / (a + r) = (det + c r) / (a + r): a sum of non-negative terms, defined
    # where the updated a is 0 (r = 0: a bearing without noise)
    np.divide(s.det + s.c * r, total, out=s.c)
    np.multiply(s.ab_det, r / total, out=s.ab_det)  # a, b and det times r / (a + r)
    return log_likelihood


def loaded_state(bank, mean_shape, cov_shape):
    """:func:`state` holding the bank's means and covariances, with their determinants."""
    M, C, rows = state(mean_shape, cov_shape)
    M[X_ROW], M[V_ROW] = bank.mean[..., 0], bank.mean[..., 1]
    C[A_ROW], C[B_ROW], C[C_ROW] = bank.cov[..., 0, 0], bank.cov[..., 0, 1], bank.cov[..., 1, 1]
    np.multiply(C[A_ROW], C[C_ROW], out=C[DET_ROW])
    C[DET_ROW] -= C[B_ROW] * C[B_ROW]
    return M, C, rows


def pack_mean(M) -> np.ndarray:
    mean = np.empty(M.shape[1:] + (2,))
    mean[..., 0], mean[..., 1] = M[X_ROW], M[V_ROW]
    return mean


def pack_cov(C, cov_shape) -> np.ndarray:
    cov = np.empty(cov_shape + (2, 2))
    cov[..., 0, 0], cov[..., 1, 1] = C[A_ROW].reshape(cov_shape), C[C_ROW].reshape(cov_shape)
    cov[..., 0, 1] = cov[..., 1, 0] = C[B_ROW].reshape(cov_shape)
    return cov
