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

__all__ = ["A2", "READINGS", "b2", "f", "hessian", "likelihood_covariance", "noise_free_state",
           "noise_free_states", "residual_gradients", "residuals", "second_order",
           "second_order_batch", "theorem1_precision"]

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


def second_order_batch(mu, rho: float, prior_mean, prior_cov,
                       reading: str = "derived") -> tuple[np.ndarray, np.ndarray]:
    """Eq. (8) for a batch of triples: means ``(B, 3)`` and covariances ``(B, 3, 3)``.

    Parameters
    ----------
    mu : array_like, shape (B, 3)
    rho : float or array_like, shape (B,)
    prior_mean : array_like, shape (3,) or (B, 3)
    prior_cov : array_like, shape (3, 3) or (B, 3, 3)
        Symmetric positive definite (checked by the caller).
    reading : {"derived", "printed"}
    """
    rho = _checks.positive_array(rho, "rho")
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    c = noise_free_states(mu)
    scale = np.broadcast_to(factor * rho**2, (c.shape[0],))[:, None, None]
    g = np.stack([model.observation_vector(model.G(c, k - 2)) @ model.G_linear(k - 2)
                  for k in range(3)], axis=-2)  # (B, 3, 3), rows in time order
    lik_precision = 2.0 * np.swapaxes(g, -1, -2) @ g / scale
    prior_precision = A2.T @ np.linalg.inv(np.asarray(prior_cov, dtype=float)) @ A2
    info = (np.einsum("bij,bj->bi", lik_precision, c)
            + np.einsum("...ij,...j->...i", prior_precision,
                        np.linalg.solve(A2, (np.asarray(prior_mean, float) - b2).T).T))
    cov = np.linalg.inv(lik_precision + prior_precision)
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    return np.einsum("bij,bj->bi", cov, info), cov


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
    lik_precision = np.linalg.inv(likelihood_covariance(mu, rho, reading))
    prior_precision = A2.T @ np.linalg.solve(prior.cov, A2)
    precision = lik_precision + prior_precision
    info = lik_precision @ c + A2.T @ np.linalg.solve(prior.cov, prior.mean - b2)
    factor = cho_factor(precision)
    cov = cho_solve(factor, np.eye(3))
    return Gaussian(cho_solve(factor, info), 0.5 * (cov + cov.T))


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
