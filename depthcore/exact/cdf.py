"""A density's CDF by composite Gauss-Legendre panels, doubled until it settles.

Recommended import: ``from depthcore.exact import cdf``.

The exact filters' marginal CDFs (:mod:`depthcore.exact.optimal`,
:mod:`depthcore.exact.mixture`) integrate a density from the lower end of the
range the depth quadrature (:mod:`depthcore.exact.quadrature`) found by
:func:`gauss_legendre_cdf`.
"""

from __future__ import annotations

import numpy as np

#: Nodes and weights of the 8-point Gauss-Legendre rule on ``[-1, 1]``.
GAUSS_LEGENDRE = np.polynomial.legendre.leggauss(8)


def gauss_legendre_cdf(density, lo, width, panels: int, tol, max_nodes=None, max_levels=None):
    """The integral of a density from ``lo`` over ``width``, by composite Gauss-Legendre panels.

    Each range is cut into ``panels`` equal panels, each integrated by the
    8-point Gauss-Legendre rule (:data:`GAUSS_LEGENDRE`); the panels are
    doubled until no integral changes by more than ``tol``.

    Parameters
    ----------
    density : callable
        ``density(s)`` for nodes ``s`` of shape ``S + (P, 8)`` returns the
        density there, of the same shape.
    lo, width : ndarray, broadcasting to shape S
        Lower ends and lengths of the ranges.
    panels : int
        Panels of the first level.
    tol : float or ndarray, broadcasting to shape S
        Largest change of an integral at the last doubling.
    max_nodes : int, optional
        No level beyond the first with more than this many nodes per range
        (``8 P``) is evaluated.
    max_levels : int, optional
        At most this many levels are evaluated.

    Returns
    -------
    cdf : ndarray, shape S
        The integrals at the last level.
    settled : bool
        Whether they settled to ``tol`` within the limits.
    panels : int
        Panels of the last level evaluated.
    """
    x, w = GAUSS_LEGENDRE
    previous, level = None, 0
    while True:
        edges = lo[..., None] + width[..., None] * np.linspace(0.0, 1.0, panels + 1)
        half = 0.5 * np.diff(edges, axis=-1)[..., None]  # S + (P, 1)
        s = 0.5 * (edges[..., 1:] + edges[..., :-1])[..., None] + half * x
        cdf = np.sum(density(s) * half * w, axis=(-2, -1))
        level += 1
        if previous is not None and np.all(np.abs(cdf - previous) <= tol):
            return cdf, True, panels
        if (max_nodes is not None and 8 * panels > max_nodes) or (
            max_levels is not None and level >= max_levels
        ):
            return cdf, False, panels
        previous, panels = cdf, 2 * panels
