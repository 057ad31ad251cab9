"""The second-order approximation p_s, Eqs. (8) and (24).

Recommended import: ``from depthcore import second_order``.

The second-order filter replaces ``f`` in the optimal posterior (6) by its
quadratic Taylor expansion about the noise-free state ``c``, where ``f`` and its
gradient vanish. Since ``f = sum_k r_k**2`` with residuals ``r_k`` that vanish
at ``c``, its Hessian there is ``J = 2 sum_k g_k g_k^T`` (``g_k`` the gradient of
``r_k``), and

    exp(-f / (2 rho**2)) ~ exp(-(x - c)^T J (x - c) / (4 rho**2)) = N(x, c, 2 rho**2 J^{-1})

up to a constant. The paper prints ``rho**2 J^{-1}``; ``reading="printed"``
follows the print, ``reading="derived"`` (the default) the expansion.
"""

from __future__ import annotations

import numpy as np

from . import _checks, model
from .gaussian import Gaussian
from .model import f, noise_free_state, noise_free_states, residual_gradients, residuals

__all__ = [
    "A2",
    "READINGS",
    "b2",
    "f",
    "hessian",
    "likelihood_covariance",
    "noise_free_state",
    "noise_free_states",
    "residual_gradients",
    "residuals",
    "second_order",
    "second_order_batch",
    "theorem1_precision",
]

READINGS = ("derived", "printed")


def cho_factor(a):
    """:func:`scipy.linalg.cho_factor`, imported when first needed."""
    from scipy.linalg import cho_factor as factor

    return factor(a)


def cho_solve(factor, b):
    """:func:`scipy.linalg.cho_solve`, imported when first needed."""
    from scipy.linalg import cho_solve as solve

    return solve(factor, b)


#: Linear and constant parts of ``G^{-2}``: ``G^{-2} x = A2 x + b2``.
A2 = model.G_linear(-2)
b2 = np.array([0.0, -2.0, 0.0])


def hessian(mu) -> np.ndarray:
    """Eq. (8): ``J``, the Hessian of ``f`` at the noise-free state ``c``.

    At ``c`` every residual vanishes, so ``J = 2 sum_k g_k g_k^T`` exactly.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    g = residual_gradients(noise_free_state(mu))
    return 2.0 * g.T @ g


def likelihood_covariance(mu, rho: float, reading: str = "derived") -> np.ndarray:
    """Eq. (8): covariance of the Gaussian that replaces ``exp(-f / (2 rho**2))``.

    ``2 rho**2 J^{-1}`` for ``reading="derived"``, ``rho**2 J^{-1}`` for ``"printed"``.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    rho = _checks.positive_scalar(rho, "rho")
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    J = hessian(mu)
    return factor * rho**2 * np.linalg.inv(J)


def second_order_batch(
    mu, rho: float, prior_mean, prior_cov, reading: str = "derived"
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (8) for a batch of triples: means ``(B, 3)`` and covariances ``(B, 3, 3)``.

    Parameters
    ----------
    mu : array_like, shape (B, 3)
    rho : float or array_like, shape (B,)
    prior_mean : array_like, shape (3,) or (B, 3)
    prior_cov : array_like, shape (3, 3) or (B, 3, 3)
        Symmetric positive definite. All four are checked by
        :func:`depthcore._checks.batch_problem`.
    reading : {"derived", "printed"}
    """
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    mu, rho, prior_mean, prior_cov = _checks.batch_problem(mu, rho, prior_mean, prior_cov)
    if mu.ndim != 2:
        raise ValueError(f"mu must have shape (B, 3), got shape {mu.shape}")
    c = noise_free_states(mu)
    g = np.stack(
        [model.observation_vector(model.G(c, k - 2)) @ model.G_linear(k - 2) for k in range(3)],
        axis=-2,
    )  # (B, 3, 3), rows in time order
    return _square_root_solve(
        c, g, np.sqrt(2.0 / factor) / np.broadcast_to(rho, (c.shape[0],)), prior_mean, prior_cov
    )


def _square_root_solve(c, g, weight, prior_mean, prior_cov):
    """Eq. (8) in square-root form: the Gaussian ``N(c, S) p(G^{-2} x)`` by QR, batched.

    With ``S^{-1} = weight**2 g^T g`` (``g`` the residual gradients, ``weight``
    per problem) and ``P = L L^T``, the mean is ``c + delta`` where ``delta``
    minimises ``|weight g delta|**2 + |L^{-1} (A2 (c + delta) + b2 - m)|**2``:
    a least-squares problem whose 6 x 3 matrix ``K`` stacks the whitened
    residual Jacobian on the prior's whitened map. Its QR factor ``R``
    gives ``delta = R^{-1} Q^T r`` and the covariance ``R^{-1} R^{-T}``,
    without forming (and squaring the condition of) the information matrix.

    Parameters
    ----------
    c : ndarray, shape (B, 3)
    g : ndarray, shape (B, 3, 3)
    weight : ndarray, shape (B,)
    prior_mean : array_like, shape (3,) or (B, 3)
    prior_cov : array_like, shape (3, 3) or (B, 3, 3)

    Returns
    -------
    mean : ndarray, shape (B, 3)
    cov : ndarray, shape (B, 3, 3)
    """
    B = c.shape[0]
    L = np.broadcast_to(np.linalg.cholesky(np.asarray(prior_cov, dtype=float)), (B, 3, 3))
    gap = np.broadcast_to(np.asarray(prior_mean, dtype=float), (B, 3)) - b2 - c @ A2.T
    whitened = np.linalg.solve(
        L, np.concatenate([np.broadcast_to(A2, (B, 3, 3)), gap[..., None]], axis=-1)
    )
    K = np.concatenate([weight[:, None, None] * g, whitened[..., :3]], axis=1)  # (B, 6, 3)
    Q, R = np.linalg.qr(K)
    R_inv = np.linalg.inv(R)
    delta = np.einsum("bij,bkj,bk->bi", R_inv, Q[:, 3:], whitened[..., 3])
    cov = R_inv @ np.swapaxes(R_inv, -1, -2)
    return c + delta, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def second_order(mu, rho: float, prior: Gaussian, reading: str = "derived") -> Gaussian:
    """Eq. (8): the second-order approximation ``p_s`` at time 3.

    ``p_s(x) = N(x, c, S) p(G^{-2} x)`` with ``S`` from :func:`likelihood_covariance`;
    the product of two Gaussians is a Gaussian.

    Parameters
    ----------
    mu : array_like, shape (3,)
    rho : float
        Noise standard deviation, > 0.
    prior : Gaussian
        Density of the state at time 1.
    reading : {"derived", "printed"}

    Returns
    -------
    Gaussian
        Mean and covariance of ``p_s`` (state at time 3).
    """
    c = noise_free_state(mu)
    rho = _checks.positive_scalar(rho, "rho")
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    g = residual_gradients(c)
    mean, cov = _square_root_solve(
        c[None], g[None], np.array([np.sqrt(2.0 / factor) / rho]), prior.mean, prior.cov
    )
    return Gaussian(mean[0], cov[0])


def _reading(reading: str) -> str:
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    return reading


def theorem1_precision(mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (24): ``D^{-1}``, the inverse covariance of ``p_s`` written with EKF vectors.

    ``D^{-1} = (1/rho**2) sum_k (F^{k-3})^T h_k h_k^T F^{k-3} + (F^{-2})^T P^{-1} F^{-2}``,
    with ``h_k`` the observation vector (11) at ``G^{k-3} c``, the EKF's
    predicted mean at time ``k`` when the prior mean is ``G^{-2} c`` (Eq. (19)),
    and ``F^{k-3}`` the linear part of ``G^{k-3}``.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    rho = _checks.positive_scalar(rho, "rho")
    g = residual_gradients(noise_free_state(mu))  # rows h_k^T F^{k-3}, Eqs. (20)-(22)
    precision = np.zeros((3, 3))
    for row in g:
        precision += np.outer(row, row) / rho**2
    F2 = model.G_linear(-2)
    return precision + F2.T @ np.linalg.solve(prior.cov, F2)
