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

from collections.abc import Callable

import numpy as np

from depthcore import _paths
from depthcore.kalman import linear
from depthcore.problem import checks, model, signature
from depthcore.problem.gaussian import History, MeanAndCov, run_recursion, symmetric

#: The EKF's estimates after each measurement: ``means[i]`` is ``m_{i+1}``,
#: ``covs[i]`` is ``P_{i+1}``; ``.posterior`` is ``p_e = N(x, m_3, P_3)``.
EKFHistory = History


def predict(m, P, process_noise: float = 0.0) -> MeanAndCov:
    """Eq. (10): ``n = F m + e``, ``C = F P F^T``, plus ``q**2`` on the velocity's variance.

    With process noise ``q`` (textbook Eq. (19.10), ``Sigma_p = diag(0, 0, q**2)``)
    the velocity's variance grows by ``q**2``; ``q = 0`` is Eq. (10).

    Parameters
    ----------
    m : array_like, shape (..., 3)
    P : array_like, shape (..., 3, 3)
    process_noise : float
        ``q >= 0`` (not checked here).
    """
    m = np.asarray(m, dtype=float)
    P = np.asarray(P, dtype=float)
    # F P F^T with F = I + E_13: add the v row to the x row, then the v column to the x column.
    C = P.copy()
    C[..., 0, :] += P[..., 2, :]
    C[..., :, 0] += C[..., :, 2]
    if process_noise:
        C[..., 2, 2] += process_noise**2
    return MeanAndCov(m @ model.F.T + model.e, C)


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


def run_gaussian_filter(
    update_step: Callable, mu, rho, prior_mean, prior_cov, process_noise: float = 0.0
) -> History:
    """The run loop shared by the Gaussian filters (EKF, UKF), batched.

    Initialise ``n = m``, ``C = P`` (the prior is the density of the state at
    time 1), incorporate ``mu1``, then, for each further measurement, predict
    with Eq. (10) (exact for the linear motion; :func:`predict`, with the
    process noise ``q**2`` added to the velocity's variance) and incorporate it.

    Parameters
    ----------
    update_step : callable
        ``update_step(n, C, mu_k, rho) -> MeanAndCov``, batched; a
        :class:`ValueError` it raises is reraised naming the measurement.
    mu : array_like, shape (..., N)
        Bearings of ``N >= 3`` frames in time order, checked by
        :func:`depthcore.problem.model.batch_inputs` (as are the other arguments);
        the leading shape runs independent filters.
    rho : float or array_like, shape (...)
        Noise standard deviation, > 0.
    prior_mean : array_like, shape (3,) or (..., 3)
    prior_cov : array_like, shape (3, 3) or (..., 3, 3)
    process_noise : float
        SD ``q >= 0`` of the velocity's change per frame (0: the paper's model).

    Returns
    -------
    History
        ``means`` (..., N, 3) and ``covs`` (..., N, 3, 3) after each measurement.
    """
    mu, rho, n, C = model.batch_inputs(mu, rho, prior_mean, prior_cov)
    q = checks.nonnegative_scalar(process_noise, "process_noise")

    def update(n, C, mu_k, k):
        try:
            return update_step(n, C, mu_k, rho)
        except ValueError as exc:
            raise ValueError(f"update with measurement {k}: {exc}") from None

    return run_recursion(n, C, mu, lambda m, P, k: predict(m, P, q), update)


@signature.documented
def run(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> History:
    """Run the EKF over the measurements, batched: Eq. (12), then (10) and (12) per measurement.

    Initialise ``n = m``, ``C = P`` (the prior, on the state at frame 1),
    incorporate ``mu1`` with (12), then predict (10) and update (12) for each
    further measurement; the last mean and covariance are those of the state
    at frame ``N``. The information is carried as a square root
    (:func:`_update_information`), which equals :func:`predict` and
    :func:`update` algebraically and keeps the small variances accurate at
    small noise. With process noise the prediction ``C = F P F^T + Sigma_p``
    (textbook Eq. (19.10)) is formed as a square root too
    (:func:`_predict_information`).

    {parameters}

    Returns
    -------
    History
        ``means`` (..., N, 3): ``means[..., i, :]`` is the mean after
        measurement ``i + 1``; ``covs`` (..., N, 3, 3). It unpacks as
        ``means, covs = run(...)``.
    """
    mu, rho, prior_mean, prior_cov = model.batch_problem(mu, rho, prior_mean, prior_cov)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    batch = mu.shape[:-1]
    n = np.broadcast_to(prior_mean, batch + (3,))
    # square root of the information: R^T R = P^{-1}, with P = L L^T
    R = np.broadcast_to(np.linalg.inv(np.linalg.cholesky(prior_cov)), batch + (3, 3))
    rho = np.broadcast_to(rho, batch)
    means, roots = [], []
    for i in range(mu.shape[-1]):
        if i > 0:
            n = means[-1] @ model.F.T + model.e  # Eq. (10)
            if q:
                R = _predict_information(roots[-1], q)
            else:
                R = roots[-1] @ _F_INVERSE  # (F P F^T)^{-1} = F^{-T} P^{-1} F^{-1}
        m, R_new = _update_information(n, R, mu[..., i], rho)
        means.append(m)
        roots.append(R_new)
    R_inv = np.linalg.inv(np.stack(roots, axis=-3))
    covs = R_inv @ np.swapaxes(R_inv, -1, -2)
    return History(np.stack(means, axis=-2), symmetric(covs))


#: Linear part of ``G^{-1}``, the inverse of ``F`` of Eq. (9).
_F_INVERSE = model.G_linear(-1)


def _predict_information(R, q: float) -> np.ndarray:
    """The root of the predicted information with process noise, batched.

    With ``P^{-1} = R^T R`` the covariance is ``P = S S^T``, ``S = R^{-1}``; the
    prediction ``C = F P F^T + diag(0, 0, q**2)`` (textbook Eq. (19.10)) is
    ``M^T M`` for ``M`` the rows of ``(F S)^T`` stacked on ``(0, 0, q)``, so the
    QR factorisation ``M = Q U`` gives ``C = U^T U`` and the new root
    ``U^{-T}`` (``C^{-1} = U^{-1} U^{-T}``), with no subtraction.
    """
    S = np.linalg.inv(R)
    noise = np.broadcast_to(np.array([[0.0, 0.0, q]]), R.shape[:-2] + (1, 3))
    M = np.concatenate([np.swapaxes(model.F @ S, -1, -2), noise], axis=-2)  # (..., 4, 3)
    U = np.linalg.qr(M, mode="r")
    return np.swapaxes(np.linalg.inv(U), -1, -2)


def _update_information(n, R, mu, rho):
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
    h = _gradient(n)  # Eq. (11)
    innovation = np.asarray(mu, dtype=float) - model.project(n)
    stacked = np.concatenate([R, (h / rho[..., None])[..., None, :]], axis=-2)  # (..., 4, 3)
    Q, R_new = np.linalg.qr(stacked)
    delta = np.linalg.solve(R_new, (Q[..., 3, :] * (innovation / rho)[..., None])[..., None])[
        ..., 0
    ]
    return n + delta, R_new


#: :func:`depthcore.kalman.ekf.run` with the prior as a Gaussian, ``ekf(mu, rho, prior,
#: process_noise)``; until 0.3.
ekf = _paths.kept("depthcore.kalman.ekf.ekf", run, ("process_noise",))
