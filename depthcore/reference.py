"""Brute-force routes to the optimal filter's moments, for checking the closed forms.

Recommended import: ``from depthcore import reference``.

Nothing here uses Eqs. (14)-(16): both routes evaluate the log posterior (6)
itself, by a dense three-dimensional Gauss-Legendre grid or by importance
sampling. They are slow by design; :func:`depthcore.optimal.marginals` is the
route to use.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import _checks
from .gaussian import Gaussian
from .optimal import log_posterior
from .second_order import second_order


class BruteMoments(NamedTuple):
    """Depth and velocity means and SDs of the optimal filter, the number of
    evaluations of Eq. (6), and the mean (3,) and covariance (3, 3) of the state."""

    depth_mean: float
    depth_sd: float
    velocity_mean: float
    velocity_sd: float
    n_evaluations: int
    mean: np.ndarray
    cov: np.ndarray


def _gauss_legendre_panels(lo, hi, panels, order):
    """Nodes and weights of a composite Gauss-Legendre rule on ``[lo, hi]``."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(lo, hi, panels + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    return (mid[:, None] + half[:, None] * x).ravel(), (half[:, None] * w).ravel()


def _uv_box(y, mu, rho, prior):
    """Centre and axes of the Gaussian in ``(x, v)`` at each depth, from Eq. (6) alone.

    The log posterior is exactly quadratic in ``(x, v)`` at fixed ``y``, so one
    Newton step from any point, with a central-difference gradient and
    Hessian, lands on its maximum.
    """
    u0 = np.stack([mu[2] * y, np.zeros_like(y)], -1)
    # a step near the conditional SD keeps rounding small: ~rho (y - 2) close to the pole
    h = rho * np.minimum(y - 2.0, 1.0)[:, None]

    def lp(u):
        return log_posterior(np.stack([u[:, 0], y, u[:, 1]], -1), mu, rho, prior)

    e = np.eye(2)
    grad = np.stack([(lp(u0 + h * e[i]) - lp(u0 - h * e[i])) / (2 * h[:, 0]) for i in range(2)], -1)
    hess = np.empty((y.size, 2, 2))
    for i in range(2):
        for j in range(2):
            hess[:, i, j] = (lp(u0 + h * (e[i] + e[j])) - lp(u0 + h * (e[i] - e[j]))
                             - lp(u0 - h * (e[i] - e[j])) + lp(u0 - h * (e[i] + e[j]))) / (4 * h[:, 0] ** 2)
    cov = np.linalg.inv(-hess)
    centre = u0 + np.einsum("nij,nj->ni", cov, grad)
    vals, vecs = np.linalg.eigh(cov)
    return centre, vecs * np.sqrt(vals)[:, None, :]


def grid_moments(mu, rho: float, prior: Gaussian, y_range=(2.0, None), panels: int = 400,
                 order: int = 8, uv_order: int = 40, width: float = 10.0) -> BruteMoments:
    """Moments of Eq. (6) by a dense 3-D Gauss-Legendre grid over ``y > 2``.

    Depth nodes: composite Gauss-Legendre in ``t = log(y - 2)``; at each depth,
    a tensor Gauss-Legendre grid of ``uv_order**2`` nodes over ``width``
    standard deviations of the ``(x, v)`` Gaussian found by :func:`_uv_box`.

    Parameters
    ----------
    mu, rho, prior
        As in :func:`depthcore.optimal.log_posterior`.
    y_range : (float, float or None)
        Depth range, at least ``y - 2 >= 0.01`` (in the paper's scenarios the
        mass below is under 1e-100); the upper end defaults to
        ``c2 + 60 sqrt(P22) + 100``.
    panels, order, uv_order, width
        Resolution of the grid.
    """
    mu = _checks.measurements(mu)
    rho = _checks.positive_scalar(rho, "rho")
    lo, hi = y_range
    if hi is None:
        hi = second_order(mu, rho, prior).mean[1] + 60 * np.sqrt(prior.cov[1, 1]) + 100
    t, wt = _gauss_legendre_panels(np.log(max(lo - 2, 1e-2)), np.log(hi - 2), panels, order)
    y = 2.0 + np.exp(t)
    wy = wt * np.exp(t)
    centre, axes = _uv_box(y, mu, rho, prior)
    s, ws = _gauss_legendre_panels(-width, width, 1, uv_order)
    S = np.stack(np.meshgrid(s, s, indexing="ij"), -1).reshape(-1, 2)
    W = np.outer(ws, ws).ravel()
    u = centre[:, None, :] + np.einsum("nij,kj->nki", axes, S)  # (ny, k, 2)
    jac = np.abs(np.linalg.det(axes))
    x = np.stack([u[..., 0], np.broadcast_to(y[:, None], u.shape[:2]), u[..., 1]], -1)
    lp = log_posterior(x, mu, rho, prior)
    w = np.exp(lp - lp.max()) * (wy * jac)[:, None] * W[None, :]
    Z = w.sum()
    ey = np.sum(w.sum(1) * y) / Z
    ev = np.sum(w * u[..., 1]) / Z
    sd_y = np.sqrt(np.sum(w.sum(1) * (y - ey) ** 2) / Z)
    sd_v = np.sqrt(np.sum(w * (u[..., 1] - ev) ** 2) / Z)
    mean = np.einsum("nk,nki->i", w, x) / Z
    d = x - mean
    cov = np.einsum("nk,nki,nkj->ij", w, d, d) / Z
    return BruteMoments(float(ey), float(sd_y), float(ev), float(sd_v), int(lp.size), mean, cov)


def importance_moments(mu, rho: float, prior: Gaussian, rng: np.random.Generator,
                       n: int = 200_000, df: float = 3.0, inflate: float = 2.0):
    """Moments of Eq. (6) over ``y > 2`` by self-normalised importance sampling.

    The proposal is a multivariate Student t with ``df`` degrees of freedom,
    centred at the second-order mean with its covariance scaled by
    ``inflate**2``.

    Returns
    -------
    means : ndarray, shape (2,)
        Depth and velocity means.
    sds : ndarray, shape (2,)
    standard_errors : ndarray, shape (2,)
        Delta-method standard errors of the two means.
    """
    mu = _checks.measurements(mu)
    ps = second_order(mu, rho, prior)
    L = np.linalg.cholesky(ps.cov) * inflate
    z = rng.standard_normal((n, 3))
    g = rng.chisquare(df, n) / df
    x = ps.mean + (z @ L.T) / np.sqrt(g)[:, None]
    # log density of the t proposal, up to a constant
    q = np.linalg.solve(L, (x - ps.mean).T).T
    log_q = -0.5 * (df + 3) * np.log1p(np.sum(q**2, 1) / df)
    front = x[:, 1] > 2
    log_w = np.full(n, -np.inf)
    log_w[front] = log_posterior(x[front], mu, rho, prior) - log_q[front]
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    vals = x[:, [1, 2]]
    means = w @ vals
    sds = np.sqrt(w @ (vals - means) ** 2)
    se = np.sqrt(np.sum(w[:, None] ** 2 * (vals - means) ** 2, 0))
    return means, sds, se
