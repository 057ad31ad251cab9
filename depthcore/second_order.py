"""The noise-free state and the second-order approximation p_s, Eqs. (5), (7), (8).

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

READINGS = ("derived", "printed")

#: Linear and constant parts of ``G^{-2}``: ``G^{-2} x = A2 x + b2``.
A2 = model.G_linear(-2)
b2 = np.array([0.0, -2.0, 0.0])


def noise_free_state(mu) -> np.ndarray:
    """Eq. (7): the state ``c`` at time 3 with ``f(c) = 0``.

    Parameters
    ----------
    mu : array_like, shape (3,)
        Measurements ``(mu1, mu2, mu3)``; checked by :func:`depthcore._checks.measurements`.

    Returns
    -------
    ndarray, shape (3,)
        ``c = (c1, c2, c3)``: position ``(c1, c2)``, velocity ``(c3, 1)``.
    """
    mu1, mu2, mu3 = _checks.measurements(mu)
    d = mu3 + mu1 - 2.0 * mu2
    return np.array([
        2.0 * mu3 * (mu1 - mu2) / d,
        2.0 * (mu1 - mu2) / d,
        (2.0 * mu1 * mu3 - mu2 * mu3 - mu1 * mu2) / d,
    ])


def residuals(x, mu) -> np.ndarray:
    """The three terms of Eq. (5) before squaring, in time order.

    Parameters
    ----------
    x : array_like, shape (..., 3)
        States at time 3.
    mu : array_like, shape (3,)

    Returns
    -------
    ndarray, shape (..., 3)
        ``((x - 2v)/(y - 2) - mu1, (x - v)/(y - 1) - mu2, x/y - mu3)``.
    """
    x = np.asarray(x, dtype=float)
    mu = np.asarray(mu, dtype=float)
    return np.stack([model.project(model.G(x, k - 2)) - mu[k] for k in range(3)], axis=-1)


def f(x, mu) -> np.ndarray:
    """Eq. (5): the sum of squared residuals, shape ``x.shape[:-1]``."""
    return np.sum(residuals(x, mu) ** 2, axis=-1)


def residual_gradients(x) -> np.ndarray:
    """Gradients of the three residuals at a state ``x`` (shape (3,)), rows in time order.

    Row ``k`` is ``h(G^{k-2} x) F^{k-2}``: the observation vector (11) at the
    state of time ``k + 1``, pulled back to time 3; these are the vectors of
    Eqs. (20)-(22).

    Returns
    -------
    ndarray, shape (3, 3)
    """
    x = np.asarray(x, dtype=float)
    return np.stack([model.observation_vector(model.G(x, k - 2)) @ model.G_linear(k - 2)
                     for k in range(3)])


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


def noise_free_states(mu) -> np.ndarray:
    """Eq. (7) for a batch of triples ``mu`` of shape ``(B, 3)``; returns ``(B, 3)``.

    Each row is checked as in :func:`noise_free_state`.
    """
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim != 2 or mu.shape[1] != 3:
        raise ValueError(f"mu must have shape (B, 3), got shape {mu.shape}")
    mu1, mu2, mu3 = mu.T
    d = mu3 + mu1 - 2.0 * mu2
    bad = np.abs(d) <= _checks.DEGENERACY_TOL
    if np.any(bad):
        _checks.measurements(mu[np.argmax(bad)], f"mu[{int(np.argmax(bad))}]")
    c = np.stack([2.0 * mu3 * (mu1 - mu2) / d, 2.0 * (mu1 - mu2) / d,
                  (2.0 * mu1 * mu3 - mu2 * mu3 - mu1 * mu2) / d], axis=-1)
    behind = ~(c[:, 1] > 2.0)
    if np.any(behind):
        i = int(np.argmax(behind))
        _checks.measurements(mu[i], f"mu[{i}]")
    return c


def second_order_batch(mu, rho: float, prior_mean, prior_cov,
                       reading: str = "derived") -> tuple[np.ndarray, np.ndarray]:
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
    g = np.stack([model.observation_vector(model.G(c, k - 2)) @ model.G_linear(k - 2)
                  for k in range(3)], axis=-2)  # (B, 3, 3), rows in time order
    return _square_root_solve(c, g, np.sqrt(2.0 / factor) / np.broadcast_to(rho, (c.shape[0],)),
                              prior_mean, prior_cov)


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
    whitened = np.linalg.solve(L, np.concatenate([np.broadcast_to(A2, (B, 3, 3)), gap[..., None]], axis=-1))
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
    mean, cov = _square_root_solve(c[None], g[None], np.array([np.sqrt(2.0 / factor) / rho]),
                                   prior.mean, prior.cov)
    return Gaussian(mean[0], cov[0])


def _reading(reading: str) -> str:
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    return reading
