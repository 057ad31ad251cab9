"""The extended Kalman filter p_e of the paper, Eqs. (10)-(12), for any number of frames.

Recommended import: ``from depthcore.kalman import ekf``.

The paper's filter sees three bearings of a point moving with constant
velocity. The same recursion runs over ``N >= 3`` bearings and, with process
noise ``a_k ~ N(0, q**2)`` on the velocity (``v_{k+1} = v_k + a_k``, the model
of :mod:`depthcore.exact.bank`), adds ``q**2`` to the predicted velocity's variance
(Prince, section 19.3: the prediction ``C = F P F^T + Sigma_p`` of the
Kalman filter, textbook Eq. (19.10), with ``Sigma_p = diag(0, 0, q**2)``).
With ``N = 3`` and ``q = 0`` it is the paper's EKF, Eqs. (10)-(12).

The functions work on batches: a leading shape ``(...)`` on means, covariances
and measurements runs independent filters side by side (one per Monte Carlo
trial, say) with no Python loop over them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.kalman import linear
from depthcore.problem import checks, frames, model, predictive, signature
from depthcore.problem.gaussian import (
    History,
    MeanAndCov,
    checked_track,
    symmetric,
)

#: The EKF's estimates after each measurement: ``means[i]`` is ``m_{i+1}``,
#: ``covs[i]`` is ``P_{i+1}``; ``.posterior`` is ``p_e = N(x, m_3, P_3)``.
EKFHistory = History


def predict(m, P, process_noise: float = 0.0, step=1.0) -> MeanAndCov:
    """Eq. (10) over a step ``s``: ``n = G(m, s)``, ``C = F_s P F_s^T``, plus ``q**2 |s|`` on ``v``.

    With process noise ``q`` (textbook Eq. (19.10), ``Sigma_p = diag(0, 0, q**2 |s|)``,
    :func:`depthcore.problem.frames.velocity_variance`) the velocity's variance
    grows by ``q**2 |s|``; ``F_s`` is :func:`depthcore.problem.frames.transition`.
    ``q = 0`` and ``s = 1`` is Eq. (10).

    Parameters
    ----------
    m : array_like, shape (..., 3)
    P : array_like, shape (..., 3, 3)
    process_noise : float
        ``q >= 0`` (not checked here).
    step : float or array_like, shape (...)
        ``s != 0`` (not checked here), the depth's signed change, per problem.
    """
    m = np.asarray(m, dtype=float)
    P = np.asarray(P, dtype=float)
    s = np.asarray(step, dtype=float)
    # F P F^T with F = I + s E_13: add s times the v row to the x row, then the column.
    C = P.copy()
    if s.ndim == 0 and s == 1.0:
        C[..., 0, :] += P[..., 2, :]
        C[..., :, 0] += C[..., :, 2]
        mean = m @ model.F.T + model.e
    else:
        C[..., 0, :] += s[..., None] * P[..., 2, :]
        C[..., :, 0] += s[..., None] * C[..., :, 2]
        mean = model.G(m, s)
    if process_noise:
        C[..., 2, 2] += frames.velocity_variance(process_noise, s)
    return MeanAndCov(mean, C)


def _gradient(n) -> np.ndarray:
    """Eq. (11) at predicted means ``n`` (..., 3); refuses depths where it is undefined or huge.

    A predicted depth ``n2 <= 0`` puts the point behind the camera; one so small
    that ``n1 / n2**2`` overflows (e.g. ``1e-300``) leaves no finite gradient.
    """
    if not np.all(n[..., 1] > 0):
        raise ValueError(
            "prior_mean leads the EKF to a predicted depth n2 <= 0 "
            f"(min {float(np.min(n[..., 1])):.6g}); the projection x/y is not defined there"
        )
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        h = model.observation_vector(n)
        finite = np.all(np.isfinite(h)) and np.all(np.isfinite(model.project(n)))
    if not finite:
        raise ValueError(
            "prior_mean leads the EKF to a predicted depth n2 so close to the camera "
            f"(min {float(np.min(n[..., 1])):.3g}) that the gradient of x/y, Eq. (11), overflows"
        )
    return h


def update(n, C, mu, rho: float) -> MeanAndCov:
    """Eq. (12): incorporate one measurement ``mu`` into the prediction ``(n, C)``.

    ``P = C - (rho**2 + h^T C h)^{-1} C h h^T C`` and
    ``m = n + (mu - n1/n2) / (rho**2 + h^T C h) C h``, with ``h`` from Eq. (11) at ``n``.
    The covariance is computed in the algebraically equal Joseph form
    ``(I - K h^T) C (I - K h^T)^T + rho**2 K K^T``, ``K = C h / (rho**2 + h^T C h)``.

    Parameters
    ----------
    n : array_like, shape (..., 3)
        Predicted mean; its depth ``n2`` must be positive.
    C : array_like, shape (..., 3, 3)
        Predicted covariance.
    mu : float or array_like, shape (...)
        The measurement.
    rho : float or array_like, shape (...)
        Noise standard deviation, > 0.
    """
    n = np.asarray(n, dtype=float)
    C = np.asarray(C, dtype=float)
    h = _gradient(n)  # Eq. (11)
    r2 = np.asarray(rho, dtype=float) ** 2
    Ch = np.einsum("...ij,...j->...i", C, h)
    s = r2 + np.einsum("...i,...i->...", h, Ch)
    innovation = np.asarray(mu, dtype=float) - model.project(n)
    K = Ch / s[..., None]  # the Kalman gain
    mean = n + innovation[..., None] * K
    # C - C h h^T C / s of Eq. (12), in the Joseph form (I - K h^T) C (I - K h^T)^T + rho^2 K K^T,
    # which equals it algebraically and keeps P symmetric positive definite in floating point.
    cov = linear.joseph(C, K[..., :, None], h[..., None, :], r2[..., None, None])
    return MeanAndCov(mean, cov)


def bearing_predictive(n, C, rho) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's predictive density of a bearing: mean ``n1 / n2``, variance ``h^T C h + rho**2``.

    Eqs. (11)-(12): the innovation's variance ``rho**2 + h^T C h``.

    Parameters
    ----------
    n : array_like, shape (..., 3)
    C : array_like, shape (..., 3, 3)
    rho : float or array_like, shape (...)

    Returns
    -------
    mean, var : ndarray, shape (...)
    """
    n = np.asarray(n, dtype=float)
    return linearised_predictive(n, _gradient(n), C, rho)


def linearised_predictive(n, h, C, rho) -> tuple[np.ndarray, np.ndarray]:
    """A bearing's predictive density ``N(n1 / n2, h^T C h + rho**2)``, linearised by ``h``.

    ``h`` (..., 3) is the projection's gradient at ``n`` (Eq. (11)); ``n``, ``C``,
    ``rho`` and the returns are as for :func:`bearing_predictive`.
    """
    hCh = np.einsum("...i,...ij,...j->...", h, np.asarray(C, dtype=float), h)
    return model.project(n), hCh + np.asarray(rho, dtype=float) ** 2


class InformationStep(NamedTuple):
    """One EKF update in square-root information form (:func:`information_update`).

    ``mean`` (..., 3); ``root`` (..., 3, 3), ``R`` with ``P^{-1} = R^T R``;
    ``log_predictive``, ``tail`` (NaN where the bearing is missing) and
    ``gated`` (...), as in :class:`depthcore.problem.predictive.Updates`.
    """

    mean: np.ndarray
    root: np.ndarray
    log_predictive: np.ndarray
    tail: np.ndarray
    gated: np.ndarray


def information_predict(m, R, process_noise: float = 0.0, step=1.0):
    """Eq. (10) over a step ``s`` in square-root information form, batched.

    ``n = G(m, s)``; the root of ``(F_s P F_s^T)^{-1} = F_s^{-T} P^{-1} F_s^{-1}``
    is ``R F_s^{-1}``, and with process noise the root of
    ``(F_s P F_s^T + diag(0, 0, q**2 s))^{-1}`` comes from a QR factorisation
    (textbook Eq. (19.10); :func:`_predict_information`).

    Parameters
    ----------
    m : ndarray, shape (..., 3)
    R : ndarray, shape (..., 3, 3)
    process_noise : float
        ``q >= 0``, checked.
    step : float or array_like, shape (...)
        ``s != 0`` (signed), checked by the caller.

    Returns
    -------
    n : ndarray, shape (..., 3)
    R : ndarray, shape (..., 3, 3)
    """
    s = np.asarray(step, dtype=float)
    if s.ndim == 0 and s == 1.0:
        n = m @ model.F.T + model.e  # Eq. (10)
        F, F_inverse = model.F, _F_INVERSE
    else:
        n = model.G(m, s)
        F, F_inverse = frames.transition(s), frames.transition(-s)
    if process_noise:
        return n, _predict_information(R, process_noise, F, np.sqrt(np.abs(s)))
    return n, R @ F_inverse


def information_update(n, R, mu, rho, present=True, gate=None) -> InformationStep:
    """Eq. (12) in square-root information form, masked and gated, batched.

    The bearing's predictive density ``N(n1 / n2, h^T C h + rho**2)``
    (:func:`bearing_predictive`, ``C = (R^T R)^{-1}``) gives its log density
    and tail probability; where the bearing is missing (``present`` false or
    ``mu`` NaN) or the gate skips it, the prediction is kept.

    Parameters
    ----------
    n : ndarray, shape (..., 3)
        Predicted mean, depth > 0.
    R : ndarray, shape (..., 3, 3)
        Root of the predicted information.
    mu : array_like, shape (...)
    rho : array_like, shape (...)
        > 0.
    present : bool or array_like of bool, shape (...)
    gate : float or None
        Checked by :func:`depthcore.problem.predictive.gate`.

    Returns
    -------
    InformationStep
    """
    batch = n.shape[:-1]
    mu = np.broadcast_to(np.asarray(mu, dtype=float), batch)
    rho = np.broadcast_to(np.asarray(rho, dtype=float), batch)
    here = np.broadcast_to(present, batch) & ~np.isnan(mu)
    h = _gradient(n)  # Eq. (11)
    z = np.linalg.solve(np.swapaxes(R, -1, -2), h[..., None])[..., 0]  # R^{-T} h
    bearing = model.project(n)
    mu_k = np.where(here, mu, bearing)
    log_p, tail = predictive.gaussian(mu_k, bearing, np.sum(z * z, axis=-1) + rho**2)
    gated = predictive.skipped(tail, here, gate)
    use = here & ~gated
    report = (np.where(here, log_p, np.nan), np.where(here, tail, np.nan), gated)
    if not np.any(use):
        return InformationStep(n, R, *report)
    m, R_new = _update_information(n, R, mu_k, rho, h)
    if not np.all(use):
        m = np.where(use[..., None], m, n)
        R_new = np.where(use[..., None, None], R_new, R)
    return InformationStep(m, R_new, *report)


@signature.documented
def run(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, steps=None, gate=None
) -> History:
    """Run the EKF over the measurements, batched: Eq. (12), then (10) and (12) per measurement.

    Initialise ``n = m``, ``C = P`` (the prior, on the state at frame 1),
    incorporate ``mu1`` with (12), then predict (10) over each step and update
    (12) for each further frame; a missing bearing (``NaN``) or one the gate
    skips is not incorporated, row by row. The last mean and covariance are
    those of the state at frame ``N``. The information is carried as a square
    root (:func:`information_update`), which equals :func:`predict` and
    :func:`update` algebraically and keeps the small variances accurate at
    small noise. With process noise the prediction ``C = F P F^T + Sigma_p``
    (textbook Eq. (19.10)) is formed as a square root too
    (:func:`information_predict`).

    {parameters}

    Returns
    -------
    History
        ``means`` (..., N, 3): ``means[..., i, :]`` is the mean after
        frame ``i + 1``; ``covs`` (..., N, 3, 3); ``updates`` (..., N), each
        bearing's log predictive density, tail probability and whether the
        gate skipped it. It unpacks as ``means, covs = run(...)``.
    """
    track = checked_track(mu, rho, prior_mean, prior_cov, steps)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    g = predictive.gate(gate)
    f = track.frames
    regular = f.regular
    n = track.mean
    # square root of the information: R^T R = P^{-1}, with P = L L^T
    R = np.linalg.inv(np.linalg.cholesky(track.cov))
    means, roots, reports = [], [], []
    for i in range(f.mu.shape[-1]):
        if i > 0:
            n, R = information_predict(
                means[-1], roots[-1], q, 1.0 if regular else f.steps[..., i - 1]
            )
        step = information_update(n, R, f.mu[..., i], f.rho[..., i], f.present[..., i], g)
        means.append(step.mean)
        roots.append(step.root)
        reports.append(step[2:])
    R_inv = np.linalg.inv(np.stack(roots, axis=-3))
    covs = R_inv @ np.swapaxes(R_inv, -1, -2)
    updates = predictive.Updates(*(np.stack(r, axis=-1) for r in zip(*reports, strict=True)))
    return History(np.stack(means, axis=-2), symmetric(covs), updates)


#: Linear part of ``G^{-1}``, the inverse of ``F`` of Eq. (9).
_F_INVERSE = model.G_linear(-1)


def _predict_information(R, q: float, F=model.F, root_step=1.0) -> np.ndarray:
    """The root of the predicted information with process noise, batched.

    With ``P^{-1} = R^T R`` the covariance is ``P = S S^T``, ``S = R^{-1}``; the
    prediction ``C = F P F^T + diag(0, 0, q**2 |s|)`` (textbook Eq. (19.10)) is
    ``M^T M`` for ``M`` the rows of ``(F S)^T`` stacked on ``(0, 0, q sqrt(|s|))``,
    so the QR factorisation ``M = Q U`` gives ``C = U^T U`` and the new root
    ``U^{-T}`` (``C^{-1} = U^{-1} U^{-T}``), with no subtraction.
    """
    S = np.linalg.inv(R)
    noise = np.zeros(R.shape[:-2] + (1, 3))
    noise[..., 0, 2] = q * np.asarray(root_step, dtype=float)
    M = np.concatenate([np.swapaxes(F @ S, -1, -2), noise], axis=-2)  # (..., 4, 3)
    U = np.linalg.qr(M, mode="r")
    return np.swapaxes(np.linalg.inv(U), -1, -2)


def _update_information(n, R, mu, rho, h):
    """Eq. (12) in square-root information form, batched: returns the mean and the new root.

    With the prediction's information ``C^{-1} = R^T R`` and the linearised
    measurement ``h . (x - n) = mu - n1 / n2`` of Eqs. (11)-(12), the update
    minimises ``|R delta|**2 + (h . delta - (mu - n1/n2))**2 / rho**2`` over
    ``delta = x - n``: the QR factorisation of ``R`` stacked on ``h^T / rho``
    gives the new root ``R'`` (``P^{-1} = R'^T R'``, so ``P`` is Eq. (12)'s
    ``C - C h h^T C / (rho**2 + h^T C h)``) and ``delta``, the mean's step
    ``C h (mu - n1/n2) / (rho**2 + h^T C h)``. No covariance is formed by a
    subtraction, so its small eigenvalues keep their relative accuracy at
    small noise.
    """
    innovation = np.asarray(mu, dtype=float) - model.project(n)
    stacked = np.concatenate([R, (h / rho[..., None])[..., None, :]], axis=-2)  # (..., 4, 3)
    Q, R_new = np.linalg.qr(stacked)
    delta = np.linalg.solve(R_new, (Q[..., 3, :] * (innovation / rho)[..., None])[..., None])[
        ..., 0
    ]
    return n + delta, R_new
