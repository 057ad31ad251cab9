"""The optimal filter p_o and its exact marginals, Eqs. (2)-(6) and (13)-(16).

Recommended import: ``from depthcore import optimal``.

For a fixed depth ``y`` the log posterior (6) is quadratic in ``u = (x, v)``:
each measurement term of ``f`` is linear in ``u`` and so is the prior's
argument ``G^{-2} x = (x - 2v, y - 2, v)``. Writing all six terms (three
measurements, three whitened prior components) as ``g_i . u - z_i``,

    log p_o(x, y, v) = -1/2 sum_i (g_i(y) . u - z_i(y))**2 + const,

so the inner integral over ``u`` is Gaussian (Eqs. (14)-(16)) with precision
``M = sum_i g_i g_i^T`` and

    log p_oy(y) = -1/2 log det M(y) - 1/2 S(y) + const,

where ``S(y) = min_u sum_i (g_i . u - z_i)**2``. The paper's Eq. (16) keeps
only ``-1/2 log det M + l^T M^{-1} l / 8`` and calls the rest a constant
"independent of y"; it is not: ``S = |z|**2 - l^T M^{-1} l / 4`` and ``|z|**2``
contains the prior's depth term ``(y - 2 - m2)**2 / P22``. ``reading="printed"``
drops it as the print does; ``reading="derived"`` (the default) keeps it.

Both ``det M`` and ``S`` are computed as sums of squares by the Cauchy-Binet
formula (``det M = sum_{i<j} (g_i x g_j)**2``, ``S det M = sum_{i<j<k}
det[g z]_{ijk}**2``), so neither suffers cancellation near the poles
``y = 0, 1, 2`` or at small noise.

The depth marginal is then a one-dimensional integral, done on each of the
intervals ``(-inf, 0)``, ``(0, 1)``, ``(1, 2)``, ``(2, inf)`` by the trapezoid
rule after a change of variable that sends the interval to the real line;
the step is halved until the moments agree to the requested tolerance, and
the last change is reported as the error estimate. The velocity marginal is
the mixture over the same nodes of the Gaussian conditionals of ``v`` given
``y``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import _checks, model
from .gaussian import Gaussian
from .second_order import A2, f, noise_free_states, second_order_batch

READINGS = ("derived", "printed")
#: ``"front"``: depths ``y > 2``, the point in front of the camera at all three
#: frames; ``"all"``: every real ``y`` but the poles, Eq. (6) taken literally.
SUPPORTS = ("front", "all")

#: ``G^{-2} x`` as a function of ``u = (x, v)`` for fixed ``y``: ``L u + (0, y - 2, 0)``.
_L = A2[:, [0, 2]]
#: Nodes whose log integrand is this far below the maximum are cut off (e^-60 ~ 1e-26).
_CUTOFF = 60.0
#: The intervals (k, k + 1) are mapped from t in [-_T_MAX, _T_MAX].
_T_MAX = 60.0
_SCAN_STEP = 1.0
_MAX_HALVINGS = 12
#: Starting step of the quadrature in its standardised variable ``u`` (see :class:`_Frame`).
_U_STEP = 0.5
#: Most nodes of one interval for one problem; beyond it the tolerance is declared out of reach.
_NODE_BUDGET = 4097
#: Widths of the mode within which the quadrature's variable is linear in ``t``
#: (see :class:`_Frame`).
_CORE = 4.0
#: Newton steps locating the mode of the depth integrand.
_NEWTON_STEPS = 8
#: Most damped Newton steps from the scan alone (problems with a solver, :func:`_newton`).
_SCAN_NEWTON_STEPS = 30


class _Problem(NamedTuple):
    """A batch of ``B`` problems: measurements, noise, prior (whitened).

    ``solver``, when given, replaces Eqs. (14)-(16) as the integrand: called as
    ``solver(offsets, problem)`` it returns what :func:`_solve` returns, for
    depths ``y_1 = offsets[..., 2]`` at frame 1 (the quadrature's variable is
    ``t = log(y_1)`` either way). :func:`depthcore.bank.moments` uses it for
    any number of frames; ``q`` (B,) and ``cov`` (B, 3, 3) are then the
    process noise and the prior covariance.
    """

    mu: np.ndarray  # (B, 3), or (B, N) with a solver
    rho: np.ndarray  # (B,)
    mean: np.ndarray  # (B, 3) prior mean
    R: np.ndarray  # (B, 3, 3), P^{-1} = R^T R
    reading: str
    q: np.ndarray | None = None
    cov: np.ndarray | None = None
    solver: Callable | None = None

    def take(self, idx) -> _Problem:
        def part(a):
            return None if a is None else a[idx]

        return _Problem(
            self.mu[idx],
            self.rho[idx],
            self.mean[idx],
            self.R[idx],
            self.reading,
            part(self.q),
            part(self.cov),
            self.solver,
        )


def _problem(mu, rho, prior_mean, prior_cov, reading) -> _Problem:
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    mu = np.atleast_2d(_checks.three_frames(mu, "mu"))
    prior_cov = _checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.shape != (3, 3):
        raise ValueError(f"prior_cov must have shape (3, 3), got shape {prior_cov.shape}")
    mu, rho, prior_mean, prior_cov = model.batch_problem(mu, rho, prior_mean, prior_cov)
    B = mu.shape[0]
    prior_mean = np.broadcast_to(prior_mean, (B, 3))
    R = np.linalg.inv(np.linalg.cholesky(prior_cov))
    return _Problem(mu, np.full(B, rho), prior_mean, np.broadcast_to(R, (B, 3, 3)), reading)


def log_posterior(x, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (6): unnormalised log density of the optimal filter at time 3.

    ``-f(x) / (2 rho**2) + log p(G^{-2} x)``, with ``f`` from Eq. (5).

    Parameters
    ----------
    x : array_like, shape (..., 3)
        States at time 3.
    mu : array_like, shape (3,)
    rho : float
    prior : Gaussian
        Density of the state at time 1.

    Returns
    -------
    ndarray, shape x.shape[:-1]
    """
    rho = _checks.positive_scalar(rho, "rho")
    mu = model.measurements(mu)
    x = np.asarray(x, dtype=float)
    return -f(x, mu) / (2.0 * rho**2) + prior.logpdf(model.G(x, -2))


def _terms(offsets, pb: _Problem):
    """The six linear terms ``g_i . u - z_i`` of Eq. (6) at fixed depths.

    ``offsets`` has shape (B, n, 3): ``(y, y - 1, y - 2)``. Returns ``gx``,
    ``gv`` and ``z``, each of shape (6, B, n): rows 0-2 are the measurement
    terms at times 3, 2, 1 (``((x - k v) / (y - k) - mu_{3-k}) / rho`` for
    ``k = 0, 1, 2``), rows 3-5 the prior's argument ``G^{-2} x - m``
    whitened by ``R``.
    """
    B, n, _ = offsets.shape
    s = np.moveaxis(offsets, -1, 0) * pb.rho[:, None]
    np.reciprocal(s, out=s)
    RL = pb.R @ _L  # (B, 3, 2)
    gx = np.empty((6, B, n))
    gv = np.empty((6, B, n))
    z = np.empty((6, B, n))
    gx[:3] = s
    gv[:3] = -np.array([0.0, 1.0, 2.0])[:, None, None] * s
    gx[3:] = RL[:, :, 0].T[:, :, None]
    gv[3:] = RL[:, :, 1].T[:, :, None]
    z[:3] = (pb.mu[:, ::-1] / pb.rho[:, None]).T[:, :, None]
    # G^{-2} x - m = L u + b with b = (-m1, (y - 2) - m2, -m3), and z = -R b.
    z[3:] = (
        np.einsum("bij,bj->bi", pb.R, pb.mean).T[:, :, None]
        - pb.R[:, :, 1].T[:, :, None] * offsets[None, ..., 2]
    )
    return gx, gv, z


_MEAS_PAIRS = ((0, 1), (0, 2), (1, 2))


def _solve(offsets, pb: _Problem):
    """Log depth marginal and the Gaussian of ``(x, v)`` given ``y``, batched.

    ``offsets`` has shape (B, n, 3): ``(y, y - 1, y - 2)``. Returns
    ``log_density`` (B, n), ``mean`` (2, B, n) and the covariance entries
    ``(cxx, cxv, cvv)``, each (B, n).

    The six terms of :func:`_terms` have a structure that the Cauchy-Binet
    sums exploit: measurement row ``k`` is ``g = s_k (1, -k)``, ``z = w_k``
    with ``s_k = 1 / ((y - k) rho)`` and ``w_k = mu_{3-k} / rho``; prior row
    ``j`` is ``g = q_j`` (constant), ``z = zeta_j = alpha_j - beta_j (y - 2)``.
    So every 2 x 2 minor of ``g`` is ``s_k s_l (k - l)``, ``s_k K_kj`` with
    ``K_kj = q_jv + k q_jx``, or a constant ``P_jj'``; every 3 x 3 minor of
    ``[g z]`` expands along ``z`` into those. ``det M`` is the sum of the
    squared 2 x 2 minors, ``S det M`` that of the squared 3 x 3 minors, and
    the conditional mean follows by Cramer's rule.
    """
    if pb.solver is not None:
        return pb.solver(offsets, pb)
    rho = pb.rho[:, None]
    s = [1.0 / (offsets[..., k] * rho) for k in range(3)]
    s2 = [sk * sk for sk in s]
    RL = pb.R @ _L
    qx, qv = RL[:, :, 0], RL[:, :, 1]  # (B, 3)
    K = [[(qv[:, j] + k * qx[:, j])[:, None] for j in range(3)] for k in range(3)]
    P = {p: (qx[:, p[0]] * qv[:, p[1]] - qv[:, p[0]] * qx[:, p[1]])[:, None] for p in _MEAS_PAIRS}
    w = [(pb.mu[:, 2 - k] / pb.rho)[:, None] for k in range(3)]
    alpha = np.einsum("bij,bj->bi", pb.R, pb.mean)
    zeta = [alpha[:, j : j + 1] - pb.R[:, j, 1:2] * offsets[..., 2] for j in range(3)]
    qxc = [qx[:, j : j + 1] for j in range(3)]
    qvc = [qv[:, j : j + 1] for j in range(3)]

    det_M = (
        s2[0] * s2[1]
        + 4.0 * s2[0] * s2[2]
        + s2[1] * s2[2]
        + sum(s2[k] * sum(K[k][j] ** 2 for j in range(3)) for k in range(3))
        + sum(P[p] ** 2 for p in _MEAS_PAIRS)
    )
    # The three measurement rows' minor, -w0 s1 s2 + 2 w1 s0 s2 - w2 s0 s1, equals
    # (2 (mu1 - mu2) - d y) s0 s1 s2 = d (c2 - y) s0 s1 s2 with d = mu1 + mu3 - 2 mu2:
    # the factored form keeps its relative accuracy where the terms cancel (near y = c2).
    d = (pb.mu[:, 0] + pb.mu[:, 2] - 2.0 * pb.mu[:, 1])[:, None]
    c2 = model.noise_free_depth_unchecked(pb.mu)[:, None]
    minors3 = (d * (c2 - offsets[..., 0]) * s[0] * s[1] * s[2]) ** 2
    for k, l in _MEAS_PAIRS:
        for j in range(3):
            minors3 = (
                minors3
                + (w[k] * s[l] * K[l][j] - w[l] * s[k] * K[k][j] + (k - l) * zeta[j] * s[k] * s[l])
                ** 2
            )
    for k in range(3):
        for j, jj in _MEAS_PAIRS:
            minors3 = (
                minors3
                + (w[k] * P[(j, jj)] - zeta[j] * s[k] * K[k][jj] + zeta[jj] * s[k] * K[k][j]) ** 2
            )
    minors3 = minors3 + (zeta[0] * P[(1, 2)] - zeta[1] * P[(0, 2)] + zeta[2] * P[(0, 1)]) ** 2
    S = minors3 / det_M

    nx = nv = 0.0
    for k, l in _MEAS_PAIRS:
        D = (k - l) * s[k] * s[l]
        nx = nx + D * (k * w[l] * s[k] - l * w[k] * s[l])
        nv = nv + D * (w[l] * s[k] - w[k] * s[l])
    for k in range(3):
        for j in range(3):
            D = s[k] * K[k][j]
            nx = nx + D * (w[k] * qvc[j] + k * s[k] * zeta[j])
            nv = nv + D * (s[k] * zeta[j] - w[k] * qxc[j])
    for j, jj in _MEAS_PAIRS:
        D = P[(j, jj)]
        nx = nx + D * (zeta[j] * qvc[jj] - qvc[j] * zeta[jj])
        nv = nv + D * (qxc[j] * zeta[jj] - zeta[j] * qxc[jj])
    mean = np.stack([nx / det_M, nv / det_M])
    cxx = (s2[1] + 4.0 * s2[2] + np.sum(qv**2, 1)[:, None]) / det_M
    cvv = (s2[0] + s2[1] + s2[2] + np.sum(qx**2, 1)[:, None]) / det_M
    cxv = (s2[1] + 2.0 * s2[2] - np.sum(qx * qv, 1)[:, None]) / det_M
    log_density = -0.5 * np.log(det_M) - 0.5 * S
    if pb.reading == "printed":
        # Eq. (16) keeps only l^T M^{-1} l / 8 = (|z|^2 - S) / 2 beside the determinant.
        log_density = log_density + 0.5 * (sum(wk**2 for wk in w) + sum(zj**2 for zj in zeta))
    return log_density, mean, (cxx, cxv, cvv)


def quadratic_coefficients(y, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (14): the coefficients ``A, B, C, D, E`` of ``p_o`` at fixed depths.

    ``log p_o = -1/2 (A x**2 + B x v + C v**2 + D x + E v) + terms in y only``.

    Parameters
    ----------
    y : array_like, shape (n,)
    mu, rho, prior
        As in :func:`log_posterior`.

    Returns
    -------
    ndarray, shape (n, 5)
        Columns ``A, B, C, D, E``; ``M = [[A, B/2], [B/2, C]]`` and ``l = (D, E)``
        of Eq. (15).
    """
    y = np.atleast_1d(np.asarray(y, dtype=float))
    pb = _problem(model.measurements(mu), rho, prior.mean, prior.cov, "derived")
    gx, gv, z = (a[:, 0] for a in _terms(np.stack([y, y - 1, y - 2], -1)[None], pb))
    A, B, C = np.sum(gx * gx, 0), 2.0 * np.sum(gx * gv, 0), np.sum(gv * gv, 0)
    D, E = -2.0 * np.sum(gx * z, 0), -2.0 * np.sum(gv * z, 0)
    return np.stack([A, B, C, D, E], -1)


def conditional(y, mu, rho: float, prior: Gaussian, reading: str = "derived"):
    """Eqs. (14)-(16): log depth marginal and the Gaussian of ``(x, v)`` given ``y``.

    Parameters
    ----------
    y : array_like, shape (n,)
        Depths at time 3, none at a pole ``0, 1, 2``.
    mu, rho, prior
        As in :func:`log_posterior`.
    reading : {"derived", "printed"}
        See the module docstring.

    Returns
    -------
    log_density : ndarray, shape (n,)
        Unnormalised ``log p_oy(y)`` (the Gaussian integral's ``2 pi`` dropped).
    mean : ndarray, shape (n, 2)
        ``E[(x, v) | y]``.
    cov : ndarray, shape (n, 2, 2)
        ``Cov[(x, v) | y] = M^{-1}``.
    """
    y = np.atleast_1d(_checks.finite_array(y, "y"))
    if np.any(np.isin(y, (0.0, 1.0, 2.0))):
        raise ValueError("y must avoid the poles 0, 1, 2 of Eq. (5)")
    pb = _problem(model.measurements(mu), rho, prior.mean, prior.cov, reading)
    log_density, mean, (cxx, cxv, cvv) = _solve(np.stack([y, y - 1, y - 2], -1)[None], pb)
    cov = np.stack([np.stack([cxx, cxv], -1), np.stack([cxv, cvv], -1)], -2)
    return log_density[0], mean[:, 0].T, cov[0]


def _nodes(interval: int, t: np.ndarray):
    """Map ``t`` (any shape) to depths in one interval between the poles.

    Returns the offsets ``(y, y - 1, y - 2)`` (shape ``t.shape + (3,)``) and
    ``log |dy/dt|``.
    """
    if interval == 0:  # (-inf, 0): y = -exp(t)
        y = -np.exp(t)
        return np.stack([y, y - 1, y - 2], -1), t
    if interval == 3:  # (2, inf): y - 2 = exp(t)
        d = np.exp(t)
        return np.stack([d + 2, d + 1, d], -1), t
    # (k, k + 1): y - k = 1 / (1 + exp(-t)), y - k - 1 = -1 / (1 + exp(t))
    lo, hi = 1.0 / (1.0 + np.exp(-t)), -1.0 / (1.0 + np.exp(t))
    log_jac = -np.logaddexp(0.0, -t) - np.logaddexp(0.0, t)
    if interval == 1:
        return np.stack([lo, hi, hi - 1], -1), log_jac
    return np.stack([lo + 1, lo, hi], -1), log_jac


class _Frame(NamedTuple):
    """Where one interval's integrand lives, per problem: ``t = t0 + sigma L sinh(u / L)``.

    ``t0`` (B,) is the mode of the integrand in ``t`` and ``sigma`` (B,) its
    width there (from the curvature); ``L`` is :data:`_CORE`. Within ``L``
    widths of the mode ``u`` is the standardised variable ``(t - t0) /
    sigma``, where the trapezoid rule converges as fast as on a Gaussian;
    beyond, the node spacing in ``t`` grows in proportion to the distance
    from the mode, so that tails reaching any multiple of the width cost
    only a logarithmic number of nodes.
    """

    t0: np.ndarray
    sigma: np.ndarray

    def t(self, u):
        """``t`` at ``u`` of shape (B, n)."""
        return self.t0[:, None] + (self.sigma * _CORE)[:, None] * np.sinh(u / _CORE)

    def u(self, t):
        """Inverse of :meth:`t` for ``t`` of shape (B,) or (B, n)."""
        t = np.asarray(t)
        if t.ndim == 2:
            return _CORE * np.arcsinh((t - self.t0[:, None]) / (self.sigma * _CORE)[:, None])
        return _CORE * np.arcsinh((t - self.t0) / (self.sigma * _CORE))

    def log_jacobian(self, u):
        """``log |dt/du|`` at ``u`` of shape (B, n)."""
        return np.log(self.sigma)[:, None] + _log_cosh(u / _CORE)


def _log_cosh(u):
    a = np.abs(u)
    return a + np.log1p(np.exp(-2.0 * a)) - np.log(2.0)


def _mapped_nodes(interval: int, u: np.ndarray, frame: _Frame):
    """Offsets ``(y, y - 1, y - 2)`` and ``log |dy/du|`` at nodes ``u`` (B, n)."""
    offsets, log_jac = _nodes(interval, frame.t(u))
    return offsets, log_jac + frame.log_jacobian(u)


def _log_integrand(interval: int, t: np.ndarray, pb: _Problem) -> np.ndarray:
    """``log p_oy(y(t)) + log |dy/dt|`` at ``t`` of shape (B, n)."""
    offsets, log_jac = _nodes(interval, t)
    return _solve(offsets, pb)[0] + log_jac


#: Index pairs (i, j) of the second moments accumulated, in (x, y, v) order.
_SECOND = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
_FIRST_INDEX, _SECOND_INDEX = (np.array(ix) for ix in zip(*_SECOND, strict=True))
#: Where each entry of a 3 x 3 covariance (row-major) sits in :data:`_SECOND` order.
_SYMMETRIC = np.array([0, 3, 5, 3, 1, 4, 5, 4, 2])


def _evaluate(interval, u, frame, pb, shift, centre):
    """Trapezoid sums (without the step) over nodes ``u`` (B, n) of one interval.

    The sums, shape (11, B), are of the weight, of the first moments of
    ``(x, y, v) - centre`` and of the second moments in :data:`_SECOND` order
    (the conditional covariance of ``(x, v)`` given ``y`` included), and of
    the weight below ``y = 2``. Nodes at ``u = nan`` count for nothing.
    """
    return _sums(_node_values(interval, u, frame, pb), np.isnan(u), shift, centre)


def _node_values(interval, u, frame, pb):
    """Offsets, ``log`` integrand in ``u`` and the conditional Gaussian at nodes ``u`` (B, n)."""
    offsets, log_jac = _mapped_nodes(interval, np.where(np.isnan(u), 0.0, u), frame)
    log_density, mean, cov = _solve(offsets, pb)
    return offsets, log_density + log_jac, mean, cov


def _sums(values, skip, shift, centre):
    """The sums of :func:`_evaluate` from :func:`_node_values`, leaving out nodes where ``skip``."""
    offsets, log_f, mean, (cxx, cxv, cvv) = values
    w = np.exp(np.where(skip, -np.inf, log_f - shift[:, None]))
    d = np.stack(
        [mean[0] - centre[:, 0:1], offsets[..., 0] - centre[:, 1:2], mean[1] - centre[:, 2:3]]
    )
    zero = np.zeros_like(cxx)
    conditional = np.stack([cxx, zero, cvv, zero, zero, cxv])  # in _SECOND order
    second = d[_FIRST_INDEX] * d[_SECOND_INDEX] + conditional
    return np.concatenate(
        [
            w.sum(-1)[None],
            np.einsum("kbn,bn->kb", d, w),
            np.einsum("kbn,bn->kb", second, w),
            (w * (offsets[..., 0] < 2)).sum(-1)[None],
        ]
    )


class _Totals(NamedTuple):
    """Posterior mean (B, 3), covariance (B, 3, 3), P(y < 2) (B,), normaliser (B,)."""

    mean: np.ndarray
    cov: np.ndarray
    behind: np.ndarray
    Z: np.ndarray

    def key_moments(self) -> np.ndarray:
        """``(E y, sd y, E v, sd v)``, shape (4, B)."""
        return np.stack(
            [
                self.mean[:, 1],
                np.sqrt(self.cov[:, 1, 1]),
                self.mean[:, 2],
                np.sqrt(self.cov[:, 2, 2]),
            ]
        )


def _moments(totals: np.ndarray, centre: np.ndarray) -> _Totals:
    """Mean, covariance, P(y < 2) and normaliser from summed trapezoid totals.

    A problem whose nodes all carry zero weight (a coarse level that misses a
    posterior narrower than its step) gets NaN moments, without a warning: its
    change between levels is then NaN, which never passes the tolerance, so
    the quadrature refines it or refuses it as too narrow.
    """
    Z = totals[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        m = (totals[1:4] / Z).T  # (B, 3), centred
        second = (totals[4:10] / Z).T - m[:, _FIRST_INDEX] * m[
            :, _SECOND_INDEX
        ]  # (B, 6) in _SECOND order
        behind = totals[10] / Z
    second[:, :3] = np.maximum(second[:, :3], 0.0)
    cov = second[:, _SYMMETRIC].reshape(-1, 3, 3)
    return _Totals(centre + m, cov, behind, Z)


def _t_limits(interval: int, pb: _Problem, c: np.ndarray, cov_p: np.ndarray):
    """The ``t`` range searched in one interval, per problem: two arrays (B,).

    On the unbounded intervals the far end lies 1e4 times beyond the largest
    of the prior's scale, the prior mean and the noise-free depth, where the
    integrand has long decayed (checked by :func:`_ranges`).
    """
    B = len(c)
    if interval in (1, 2):
        return np.full(B, -_T_MAX), np.full(B, _T_MAX)
    scale = np.sqrt(np.trace(cov_p, axis1=-2, axis2=-1))
    far = np.log(1e4 * (scale + np.max(np.abs(pb.mean), axis=1) + np.abs(c[:, 1]) + 10.0))
    return np.full(B, -_T_MAX), far


def _scan_points(interval: int, c, mean_s, sd_s, lo_t, hi_t, guessed: bool = False):
    """Where to look for the mode in ``t``: (B, n) points, the first ``n_coarse`` of them coarse.

    A scan of the whole range at about unit steps and, on ``y > 2``, 25
    points across 12 second-order SDs about the noise-free depth and about
    the second-order mean (left out when ``guessed``, the second-order frame's
    first level being evaluated too, and both lie within an SD of each other;
    and when ``c`` is ``None``, for problems with no noise-free solution).
    Returns the points and ``n_coarse``.
    """
    t = lo_t[:, None] + (hi_t - lo_t)[:, None] * _unit(
        int(np.ceil(np.max(hi_t - lo_t) / _SCAN_STEP)) + 1
    )
    n_coarse = t.shape[1]
    if interval == 3 and c is not None:
        local = np.arange(-12.0, 12.5)
        sd_t = _clip(sd_s / (c[:, 1] - 2.0), _sigma_floor(np.log(c[:, 1] - 2.0)), 1.0)
        t_c = np.log(c[:, 1] - 2.0)
        t_s = np.log(np.where(mean_s[:, 1] > 2.0, mean_s[:, 1] - 2.0, c[:, 1] - 2.0))
        centres = [t_c, t_s]
        if guessed and np.all(np.abs(t_c - t_s) <= sd_t):
            centres = []  # the first level in the second-order frame covers both densely
        t = np.concatenate([t] + [ct[:, None] + sd_t[:, None] * local for ct in centres], 1)
        t = _clip(t, lo_t[:, None], hi_t[:, None])
    return t, n_coarse


def _local_points(pb: _Problem):
    """Scan points (B, 27) about the depth of the first three bearings' noise-free solution.

    For a solver's problems (any number of frames) the depth at frame 3 of
    Eq. (7)'s ``c`` from ``mu_1 .. mu_3`` (in the quadrature's variable
    ``t = log(y_1)``), or the prior mean's depth where that is undefined or
    behind the camera, with offsets ``0, +-1, +-0.1, .., +-1e-12`` in ``t``:
    a start for the Newton steps at every scale of the posterior's width.
    """
    if pb.mu.shape[1] >= 3:
        with np.errstate(all="ignore"):
            y = model.noise_free_states_unchecked(pb.mu[:, :3])[:, 1] - 2.0
    else:
        y = np.full(len(pb.mu), np.nan)
    y = np.where(np.isfinite(y) & (y > 0), y, pb.mean[:, 1])
    t = np.log(np.where(y > 0, y, 1.0))
    steps = 10.0 ** -np.arange(13.0)
    return t[:, None] + np.concatenate([[0.0], steps, -steps])


def _frame(interval: int, pb: _Problem, t, scan, coarse_mask, lo_t, hi_t):
    """Locate the mode of one interval's integrand in ``t`` and its width, per problem.

    From the integrand ``scan`` at points ``t`` (B, n): a parabola through
    the best point and its neighbours gives the mode and the width ``(-d2
    log f / dt2) ** -1/2``; where the best point is one of the coarse ones
    (``coarse_mask``, (n,)), Newton steps on parabolas one width wide refine
    both. Returns the :class:`_Frame` and the largest log integrand seen (B,).
    """
    B = t.shape[0]
    order = np.argsort(t, axis=1, kind="stable")
    ts = np.take_along_axis(t, order, 1)
    ss = np.take_along_axis(scan, order, 1)
    rows = np.arange(B)
    best = np.argmax(ss, axis=1)
    k = _clip(best, 1, ts.shape[1] - 2)
    t0, sigma, top = _parabola(
        ts[rows, k - 1], ts[rows, k], ts[rows, k + 1], ss[rows, k - 1], ss[rows, k], ss[rows, k + 1]
    )
    coarse = coarse_mask[order[rows, best]]
    if pb.solver is not None:
        t0, sigma, top = _newton(interval, pb, ts[rows, best], ss[rows, best], sigma, lo_t, hi_t)
        t0 = _clip(t0, lo_t, hi_t)
        return _Frame(t0, _clip(sigma, _sigma_floor(t0), 1.0)), top
    for _ in range(_NEWTON_STEPS if np.any(coarse) else 0):
        pts = _clip(
            t0[:, None] + sigma[:, None] * np.array([-1.0, 0.0, 1.0]), lo_t[:, None], hi_t[:, None]
        )
        phi = _log_integrand(interval, pts, pb)
        t1, s1, top1 = _parabola(*pts.T, *phi.T)
        better = coarse & (top1 >= top)
        t0, sigma, top = (
            np.where(better, t1, t0),
            np.where(coarse, s1, sigma),
            np.maximum(top, np.where(coarse, top1, top)),
        )
    t0 = _clip(t0, lo_t, hi_t)
    sigma = _clip(sigma, _sigma_floor(t0), 1.0)
    return _Frame(t0, sigma), top


def _newton(interval: int, pb: _Problem, t0, f0, sigma, lo_t, hi_t):
    """Damped Newton steps to the mode of the log integrand in ``t``, from ``t0`` (B,).

    For problems with no second-order guess, whose mode may lie many of its
    own (tiny) widths from the best scan point. Each step takes the first and
    second differences at ``t0 +- sigma``, moves by ``-d1 / d2`` (uphill by
    ``4 sigma`` where the points are not concave), halving the move until the
    log integrand does not decrease, and sets ``sigma`` to the curvature's
    width ``(-d2)**-1/2``. Stops when the moves fall below a hundredth of the
    width and the width settles, or after :data:`_SCAN_NEWTON_STEPS` steps.
    Returns the mode, its width and the log integrand there, each (B,).
    """
    floor = _sigma_floor(t0)
    for _ in range(_SCAN_NEWTON_STEPS):
        h = _clip(sigma, floor, 1.0)
        pts = t0[:, None] + h[:, None] * np.array([-1.0, 0.0, 1.0])
        phi = _log_integrand(interval, _clip(pts, lo_t[:, None], hi_t[:, None]), pb)
        with np.errstate(invalid="ignore", over="ignore"):
            d1 = (phi[:, 2] - phi[:, 0]) / (2.0 * h)
            d2 = (phi[:, 2] - 2.0 * phi[:, 1] + phi[:, 0]) / h**2
            concave = np.isfinite(d1) & np.isfinite(d2) & (d2 < 0)
            move = np.where(concave, -d1 / np.where(concave, d2, -1.0), 4.0 * h * np.sign(d1))
            width = np.where(concave, 1.0 / np.sqrt(-np.where(concave, d2, -1.0)), 2.0 * h)
        move = np.where(np.isfinite(move), move, 0.0)
        f1 = np.full_like(f0, -np.inf)
        for _ in range(60):  # halve the move until the log integrand does not decrease
            t1 = _clip(t0 + move, lo_t, hi_t)
            # (a move below a hundredth of the width is not worth the roundoff it hits)
            worse = ~(f1 >= f0) & (np.abs(move) > 0.01 * h)
            if not np.any(worse):
                break
            f1 = np.where(worse, _log_integrand(interval, t1[:, None], pb)[:, 0], f1)
            move = np.where(~(f1 >= f0), 0.5 * move, move)
        up = f1 >= f0
        sigma = _clip(width, floor, 1.0)
        settled = (np.abs(np.where(up, t1 - t0, 0.0)) <= 0.01 * sigma) & (
            np.abs(sigma - h) <= 0.05 * h
        )
        t0, f0 = np.where(up, t1, t0), np.where(up, f1, f0)
        if np.all(settled):
            break
    return t0, sigma, f0


def _parabola(ta, tb, tc, fa, fb, fc):
    """Vertex, width and value of the parabola through three points (B,) with ``tb`` in the middle.

    Where the points are not concave the middle point is kept and the width
    is the wider gap.
    """
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        d1 = (fb - fa) / (tb - ta)
        d2 = (fc - fb) / (tc - tb)
        curv = 2.0 * (d2 - d1) / (tc - ta)  # second derivative
        concave = np.isfinite(curv) & (curv < 0) & np.isfinite(fa) & np.isfinite(fc)
        safe = np.where(concave, curv, -1.0)
        vertex = 0.5 * (ta + tb) - d1 / safe + 0.5 * (tb - ta)
        vertex = np.where(concave, _clip(vertex, ta, tc), tb)
        gap = np.maximum(tb - ta, tc - tb)
        width = np.where(concave, _clip(1.0 / np.sqrt(-safe), 0.25 * gap, 4.0 * gap), gap)
        value = np.where(
            concave, fb + d1 * (vertex - tb) + 0.5 * curv * (vertex - ta) * (vertex - tb), fb
        )
    return vertex, width, np.maximum(value, fb)


def _unit(n: int) -> np.ndarray:
    """``n`` equally spaced points from 0 to 1."""
    return np.arange(n) / (n - 1)


def _clip(a, lo, hi):
    """``np.clip`` without its overhead on small arrays."""
    return np.minimum(np.maximum(a, lo), hi)


def _sigma_floor(t0):
    """The narrowest width resolved in ``t`` near ``t0``: a thousand roundoffs."""
    return 1e3 * np.finfo(float).eps * np.maximum(1.0, np.abs(t0))


def _level0(frame: _Frame, lo_t, hi_t):
    """The first trapezoid level: the whole ``u`` range at step :data:`_U_STEP`, (B, n)."""
    u_lo, u_hi = frame.u(lo_t), frame.u(hi_t)
    n = int(np.ceil(np.max(u_hi - u_lo) / _U_STEP)) + 1
    return u_lo[:, None] + (u_hi - u_lo)[:, None] * _unit(n)


def _ranges(pb: _Problem, intervals):
    """Place each interval's nodes relative to its own mode and width.

    On ``y > 2`` the second-order density gives a first frame (its mean and
    SD in ``t``), and the first trapezoid level in that frame is evaluated
    together with the scan of :func:`_scan_points`. If the best node is not
    one of the first level's, or the parabola through it and its neighbours
    disagrees with the first frame (mode more than three widths away, width
    off by more than a factor 3), the mode and width are found from all
    nodes (:func:`_frame`) and the first level is evaluated again in that
    frame. Elsewhere the scan comes first.

    Returns the log-integrand maximum found in ``t`` (B,), per interval
    ``(frame, u, values, hi_t, (t, log f))``: the :class:`_Frame`, the first
    level's nodes ``u`` and :func:`_node_values` there, the far end in ``t``
    and the scan; and the second-order mean (B, 3), about which the moments
    are accumulated.
    """
    paper = pb.solver is None
    if paper:
        c = noise_free_states(pb.mu)
        cov_p = np.linalg.inv(np.swapaxes(pb.R, -1, -2) @ pb.R)
        mean_s, cov_s = second_order_batch(pb.mu, pb.rho, pb.mean, cov_p)
        sd_s = np.sqrt(cov_s[:, 1, 1])
    else:  # no second-order density to start from: the scan finds the mode
        c = mean_s = sd_s = None
        cov_p = pb.cov
    found, tops = {}, []
    for i in intervals:
        lo_t, hi_t = _t_limits(i, pb, pb.mean if c is None else c, cov_p)
        t_scan, n_coarse = _scan_points(i, c, mean_s, sd_s, lo_t, hi_t, guessed=i == 3)
        if not paper:
            t_scan = _clip(
                np.concatenate([t_scan, _local_points(pb)], 1), lo_t[:, None], hi_t[:, None]
            )
            n_coarse = t_scan.shape[1]  # every point may start the Newton steps
        guess = None
        if i == 3 and paper:
            y_s = np.where(mean_s[:, 1] > 2.0, mean_s[:, 1], c[:, 1])
            t0 = _clip(np.log(y_s - 2.0), lo_t, hi_t)
            guess = _Frame(t0, _clip(sd_s / (y_s - 2.0), _sigma_floor(t0), 1.0))
            u = _level0(guess, lo_t, hi_t)
            t_all = np.concatenate([guess.t(u), t_scan], axis=1)
        else:
            t_all = t_scan
        offsets, log_jac = _nodes(i, t_all)
        log_density, mean, cov = _solve(offsets, pb)
        log_t = log_density + log_jac
        m = t_all.shape[1] - t_scan.shape[1]
        coarse_mask = np.arange(t_all.shape[1]) - m < n_coarse
        coarse_mask[:m] = False
        if guess is not None:
            # the mode and width from the first level's nodes about its best one
            rows = np.arange(len(c))
            best = np.argmax(log_t, axis=1)
            k = _clip(best, 1, m - 2)
            t0, sigma, top_i = _parabola(
                *(t_all[rows, k + o] for o in (-1, 0, 1)), *(log_t[rows, k + o] for o in (-1, 0, 1))
            )
            good = (
                (best < m)
                & (np.abs(t0 - guess.t0) <= 3.0 * guess.sigma)
                & (sigma <= 3.0 * guess.sigma)
                & (3.0 * sigma >= guess.sigma)
            )
            if not np.all(good):
                frame, top_i = _frame(i, pb, t_all, log_t, coarse_mask, lo_t, hi_t)
            if np.all(good):
                frame = guess
                values = (
                    offsets[:, :m],
                    log_t[:, :m] + guess.log_jacobian(u),
                    mean[:, :, :m],
                    tuple(a[:, :m] for a in cov),
                )
            else:
                frame = _Frame(
                    np.where(good, guess.t0, frame.t0), np.where(good, guess.sigma, frame.sigma)
                )
                guess = None
        else:
            frame, top_i = _frame(i, pb, t_all, log_t, coarse_mask, lo_t, hi_t)
        if guess is None:
            u = _level0(frame, lo_t, hi_t)
            values = _node_values(i, u, frame, pb)
        scan = (t_all[:, m:], log_t[:, m:])
        found[i] = (frame, u, values, hi_t, scan)
        tops.append(np.maximum(top_i + np.log(frame.sigma), np.max(values[1], axis=1)))
    if paper:
        centre = np.where(np.isfinite(mean_s), mean_s, c)
    else:  # the state at the mode of the depth (in the quadrature's depth, y_1 + 2)
        t0 = found[3][0].t0
        offsets, _ = _nodes(3, t0[:, None])
        x_v = _solve(offsets, pb)[1][:, :, 0]
        centre = np.stack([x_v[0], offsets[:, 0, 0], x_v[1]], axis=1)
    return np.max(tops, axis=0), found, centre


def _integrate(pb: _Problem, intervals, rtol: float):
    """Integrate the depth marginal of a batch; returns moments, errors, shift, grids.

    The first level of the trapezoid rule spans each interval's whole ``u``
    range at step :data:`_U_STEP`; the nodes where the integrand is above
    ``e^-60`` of its maximum (and the unit-step scan's) set the range
    ``[lo, hi]`` that later levels refine by halving the step. Each problem's
    step is halved until its means and SDs change by at most ``rtol`` of the
    SD (or by the roundoff floor of :func:`_roundoff`); a problem that has
    converged keeps its result, so it does not depend on the other rows of
    the batch. More than :data:`_NODE_BUDGET` nodes in an interval is a
    ``ValueError`` naming the problem.
    """
    top, found, centre = _ranges(pb, intervals)
    B = len(top)
    grids, totals = {}, {}
    for i, (frame, u, values, hi_t, (t_c, scan_c)) in found.items():
        n0 = u.shape[1]
        u_lo, h0 = u[:, 0], u[:, 1] - u[:, 0]
        keep = values[1] > (top - _CUTOFF)[:, None]
        keep_t = scan_c + np.log(frame.sigma)[:, None] > (top - _CUTOFF)[:, None]
        if i in (0, 3):
            at_end = keep[:, -1] | np.any(keep_t & (t_c >= hi_t[:, None]), axis=1)
            if np.any(at_end):
                k = int(np.argmax(at_end))
                raise ValueError(
                    f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g}: the depth marginal "
                    f"does not decay by |y| = {np.exp(hi_t[k]):.3g}; "
                    "its moments do not exist in this reading"
                )
        u_c = frame.u(t_c)
        first = np.minimum(
            np.min(np.where(keep, u, np.inf), axis=1), np.min(np.where(keep_t, u_c, np.inf), axis=1)
        )
        last = np.maximum(
            np.max(np.where(keep, u, -np.inf), axis=1),
            np.max(np.where(keep_t, u_c, -np.inf), axis=1),
        )
        active = np.isfinite(first)
        j_lo = _clip(np.where(active, np.floor((first - u_lo) / h0) - 1, 0), 0, n0 - 1)
        j_hi = _clip(np.where(active, np.ceil((last - u_lo) / h0) + 1, 0), 0, n0 - 1)
        lo = u_lo + j_lo * h0
        n = (j_hi - j_lo).astype(int) + 1
        h = np.where(active & (n > 1), h0, 0.0)
        grids[i] = (lo, h, n, frame)
        inside = (
            (np.arange(n0) >= j_lo[:, None]) & (np.arange(n0) <= j_hi[:, None]) & active[:, None]
        )
        totals[i] = _sums(values, ~inside, top, centre)
    done = np.zeros(B, dtype=bool)
    final = previous = None
    errors = np.zeros((2, B))
    halvings = 2  # the first pass adds two levels in one evaluation
    while True:
        growth = 2**halvings
        # a problem with no interval left to refine (its scan kept at most one node in
        # each: a posterior narrower than the scan's step) would loop here for ever
        stuck = ~done & np.all([g[1] == 0 for g in grids.values()], axis=0)
        if np.any(stuck):
            raise _too_narrow(pb, int(np.argmax(stuck)), rtol)
        if (
            max(np.max(np.where(done, 0, growth * (g[2] - 1) + 1)) for g in grids.values())
            > _NODE_BUDGET
        ):
            k = int(np.argmin(done))
            raise ValueError(
                f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g} and prior mean "
                f"{pb.mean[k].tolist()}: the optimal marginal's quadrature did not reach "
                f"rtol = {rtol:.3g} within {_NODE_BUDGET} nodes per interval"
            )
        levels = [dict() for _ in range(halvings)]
        for i, (lo, h, n, frame) in grids.items():
            hh = np.where(done, 0.0, h)
            # the new nodes of each level, as fractions of the current step, in one evaluation
            fractions = [
                [(2 * j + 1) / 2 ** (lev + 1) for j in range(2**lev)] for lev in range(halvings)
            ]
            flat = np.concatenate([np.array(f) for f in fractions])
            m = int(np.max(n)) - 1
            j = np.arange(m)
            u = (
                lo[:, None, None] + hh[:, None, None] * (j[None, :] + flat[:, None])[None]
            )  # (B, f, m)
            valid = (j < (np.broadcast_to(n, lo.shape) - 1)[:, None])[:, None, :] & (hh > 0)[
                :, None, None
            ]
            u = np.where(valid, u, np.nan).reshape(len(lo), -1)
            values = _node_values(i, u, frame, pb)
            _check_peak(values[1], np.isnan(u), top, pb, rtol)
            start = 0
            for lev, fr in enumerate(fractions):
                block = slice(start * m, (start + len(fr)) * m)
                totals[i] = totals[i] + _sums(
                    _take(values, block), np.isnan(u[:, block]), top, centre
                )
                start += len(fr)
                levels[lev][i] = (totals[i], np.where(done, h, h / 2 ** (lev + 1)))
            grids[i] = (
                lo,
                np.where(done, h, h / growth),
                np.where(done | (h == 0), n, growth * (n - 1) + 1),
                frame,
            )
        if halvings == 2:
            previous = _moments(sum(tot * step for tot, step in levels[0].values()), centre)
        current = _moments(sum(tot * step for tot, step in levels[-1].values()), centre)
        now = current.key_moments()
        change = np.abs(now - previous.key_moments())
        floor = _roundoff(current, top, centre)
        err = np.maximum(
            np.stack([np.maximum(change[0], change[1]), np.maximum(change[2], change[3])]), floor
        )
        ok = (err[0] <= np.maximum(rtol * now[1], floor[0])) & (
            err[1] <= np.maximum(rtol * now[3], floor[1])
        )
        newly = ok & ~done
        if final is None or np.all(newly):
            final = current
        else:
            final = _Totals(
                *(np.where(_expand(newly, a), a, b) for a, b in zip(current, final, strict=True))
            )
        errors = np.where(newly, err, errors)
        done = done | ok
        if np.all(done):
            break
        previous, halvings = current, 1
    narrow = ~((final.cov[:, 1, 1] > 0) & (final.cov[:, 2, 2] > 0))
    if np.any(narrow):  # all the mass on one node: the width is below the resolution
        raise _too_narrow(pb, int(np.argmax(narrow)), rtol)
    return final, errors[0], errors[1], top, grids


def _too_narrow(pb: _Problem, k: int, rtol: float) -> ValueError:
    """The refusal of problem ``k``, whose depth marginal no float grid can resolve."""
    return ValueError(
        f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g} and prior mean "
        f"{pb.mean[k].tolist()}: the depth marginal is too narrow to resolve in double "
        f"precision, so its quadrature cannot reach rtol = {rtol:.3g}"
    )


def _check_peak(log_f, skip, top, pb: _Problem, rtol: float) -> None:
    """Refuse a problem whose refined nodes rise far above the peak found (a missed mode).

    The sums are scaled by ``exp(-top)``; a node ``e^60`` above it means the
    mode and width that placed the nodes were wrong, and the sums would overflow.
    """
    with np.errstate(invalid="ignore"):
        high = np.any(np.where(skip, False, log_f > (top + _CUTOFF)[:, None]), axis=1)
    if np.any(high):
        k = int(np.argmax(high))
        raise ValueError(
            f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g} and prior mean "
            f"{pb.mean[k].tolist()}: the depth marginal is too narrow to locate in double "
            f"precision, so its quadrature cannot reach rtol = {rtol:.3g}"
        )


def _mapped_log_integrand(interval, u, frame, pb):
    offsets, log_jac = _mapped_nodes(interval, u, frame)
    return _solve(offsets, pb)[0] + log_jac


def _take(values, columns):
    """The node values of :func:`_node_values` at a slice of the node axis."""
    offsets, log_f, mean, cov = values
    return (
        offsets[:, columns],
        log_f[:, columns],
        mean[:, :, columns],
        tuple(c[:, columns] for c in cov),
    )


def _expand(mask, a):
    return mask.reshape(mask.shape + (1,) * (np.ndim(a) - 1))


def _grid(lo, h, n, offset):
    """Nodes ``lo + h (j + offset)``, ``j < n`` (n per problem).

    Padded with NaN, shape (B, max n).
    """
    n = np.broadcast_to(n, lo.shape)
    j = np.arange(int(np.max(n)))
    u = lo[:, None] + h[:, None] * (j + offset)
    return np.where((j < n[:, None]) & (h[:, None] > 0), u, np.nan)


def _roundoff(totals: _Totals, top: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """A floor (2, B) on the error of the depth and velocity moments from roundoff.

    Three sources are counted, each with a safety factor of 64: the depths at
    the nodes are rounded to ``eps |y|``, which moves the moments by up to
    ``eps (|E y| + sd y)`` (likewise for the velocity); the log integrand, a
    difference of terms as large as its maximum ``top``, carries an absolute
    error of about ``eps |top|``, which perturbs the weights and so moves a
    mean or SD by up to ``eps |top|`` times the SD; and the variance, a
    difference of second moments about ``centre``, loses ``eps (E y -
    centre)**2``, which moves the SD by that over the SD.
    """
    eps = np.finfo(float).eps
    noise = 1.0 + np.abs(top)
    sd = np.sqrt(totals.cov[:, [1, 2], [1, 2]].T)
    mean = totals.mean[:, 1:].T
    offset = (mean - centre[:, 1:].T) ** 2 + sd**2
    with np.errstate(divide="ignore", invalid="ignore"):
        cancel = np.where(sd > 0, offset / sd, 0.0)
    return 64.0 * eps * (np.abs(mean) + sd + noise * sd + cancel)


class Moments(NamedTuple):
    """Moments of the optimal depth and velocity marginals for a batch of problems.

    Every field is an array of shape (B,). ``depth_error`` and
    ``velocity_error`` are absolute error estimates of the means and SDs: the
    largest change at the last halving of the quadrature step, an upper bound
    in practice since the trapezoid rule converges geometrically here.
    ``prob_behind_camera`` is the posterior probability that the depth at the
    first frame, ``y - 2``, is not positive (zero for ``support="front"``).
    ``mean`` (B, 3) and ``cov`` (B, 3, 3) are the posterior mean and covariance
    of the whole state ``(x, y, v)`` at time 3.
    """

    depth_mean: np.ndarray
    depth_sd: np.ndarray
    velocity_mean: np.ndarray
    velocity_sd: np.ndarray
    depth_error: np.ndarray
    velocity_error: np.ndarray
    prob_behind_camera: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


def moments(
    mu,
    rho: float,
    prior_mean,
    prior_cov,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
    chunk: int = 64,
) -> Moments:
    """Eqs. (13)-(16) for a batch: the optimal depth and velocity moments.

    Parameters
    ----------
    mu : array_like, shape (B, 3)
        One triple of measurements per row, each checked as in
        :func:`depthcore.model.measurements`.
    rho : float or array_like, shape (B,)
        Noise standard deviation, > 0.
    prior_mean : array_like, shape (3,) or (B, 3)
        Prior mean of the state at time 1.
    prior_cov : array_like, shape (3, 3)
        Prior covariance, symmetric positive definite.
    reading : {"derived", "printed"}
    support : {"front", "all"}
        See :func:`marginals`.
    rtol : float
        Target accuracy of each mean and SD, relative to the SD.
    chunk : int
        Problems integrated together (memory grows with it).

    Returns
    -------
    Moments
    """
    pb = _problem(mu, rho, prior_mean, prior_cov, reading)
    if pb.mu.shape[1] != 3:
        raise ValueError(f"mu must have shape (B, 3), got shape {pb.mu.shape}")
    intervals = _intervals(support)
    rtol = _checks.positive_scalar(rtol, "rtol")
    out, means, covs = [], [], []
    for start in range(0, pb.mu.shape[0], chunk):
        m, err_y, err_v, _, _ = _integrate(pb.take(slice(start, start + chunk)), intervals, rtol)
        out.append(np.concatenate([m.key_moments(), [err_y, err_v, m.behind]]))
        means.append(m.mean)
        covs.append(m.cov)
    return Moments(*np.concatenate(out, axis=1), np.concatenate(means), np.concatenate(covs))


def _intervals(support: str):
    if support not in SUPPORTS:
        raise ValueError(f"support must be one of {SUPPORTS}, got {support!r}")
    return (3,) if support == "front" else (0, 1, 2, 3)


def _fine_velocity_mixture(pb: _Problem, grids: dict, log_normaliser, max_refine: int = 256):
    """The velocity mixture on nodes close enough for a smooth curve, batched.

    Given the depth, the velocity is Gaussian with SD ``s_v(y)``, which at
    small noise is far narrower than the spacing of the conditional means
    ``vbar(y_j)`` at the moment quadrature's nodes: summed there, the mixture
    ``sum_j w_j N(v, vbar_j, s_v_j**2)`` ripples although its moments are
    right. Starting from those nodes, each problem's step in ``t`` is halved
    until its neighbouring nodes with weight above 1e-14 have means within
    half an SD, where the ripple is below 1e-30 of the density. Each problem
    is refined on its own, so its nodes do not depend on the rest of the
    batch, and a halving evaluates only the new midpoints.

    Returns normalised weights, means and SDs, each of shape (B, n) (the
    rows padded with zero weights).
    """
    B = len(log_normaliser)
    weights, means, sds = [], [], []
    for i, (lo, h, n, frame) in grids.items():
        rows = [None] * B
        active = np.arange(B)
        u = _grid(lo, h, n, 0.0)
        w, mean, sd = _velocity_nodes(i, u, frame, pb, log_normaliser)
        factor = 1
        while True:
            valid = ~np.isnan(u)
            big = w > 1e-14 * np.max(w, axis=1, keepdims=True)
            with np.errstate(invalid="ignore"):
                gap = np.abs(np.diff(mean, axis=1)) / np.minimum(sd[:, 1:], sd[:, :-1])
            rough = (big[:, 1:] | big[:, :-1]) & valid[:, 1:] & valid[:, :-1] & (gap > 0.5)
            refine = np.any(rough, axis=1) & (factor < max_refine)
            for k in np.flatnonzero(~refine):
                rows[active[k]] = (w[k] * (h[active[k]] / factor), mean[k], sd[k])
            if not np.any(refine):
                break
            keep = np.flatnonzero(refine)
            active, u, w, mean, sd = active[keep], u[keep], w[keep], mean[keep], sd[keep]
            mid = 0.5 * (u[:, :-1] + u[:, 1:])
            sub = _Frame(frame.t0[active], frame.sigma[active])
            new = _velocity_nodes(i, mid, sub, pb.take(active), log_normaliser[active])
            u, w, mean, sd = (
                _interleave(a, b) for a, b in zip((u, w, mean, sd), (mid, *new), strict=True)
            )
            factor *= 2
        width = max(len(r[0]) for r in rows)
        for out, k, fill in ((weights, 0, 0.0), (means, 1, 0.0), (sds, 2, 1.0)):
            out.append(
                np.stack([np.pad(r[k], (0, width - len(r[k])), constant_values=fill) for r in rows])
            )
    w = np.concatenate(weights, axis=1)
    return (
        w / np.sum(w, axis=1, keepdims=True),
        np.concatenate(means, axis=1),
        np.concatenate(sds, axis=1),
    )


def _velocity_nodes(interval: int, u, frame: _Frame, pb: _Problem, log_normaliser):
    """Depth weights (per unit ``u``), conditional velocity means and SDs at nodes ``u`` (B, n).

    NaN nodes (padding) get weight 0, mean 0 and SD 1.
    """
    skip = np.isnan(u)
    offsets, log_jac = _mapped_nodes(interval, np.where(skip, 0.0, u), frame)
    log_density, mean, (_, _, cvv) = _solve(offsets, pb)
    w = np.where(skip, 0.0, np.exp(log_density + log_jac - log_normaliser[:, None]))
    return w, np.where(skip, 0.0, mean[1]), np.where(skip, 1.0, np.sqrt(cvv))


def _interleave(a, b):
    """Columns ``a0 b0 a1 b1 ... a_n`` from ``a`` (B, n + 1) and ``b`` (B, n)."""
    out = np.empty((a.shape[0], a.shape[1] + b.shape[1]))
    out[:, 0::2] = a
    out[:, 1::2] = b
    return out


@dataclass(frozen=True)
class OptimalMarginals:
    """The optimal filter's depth and velocity marginals, Eqs. (13)-(16).

    Built by :func:`marginals`.

    Attributes
    ----------
    depth_mean, depth_sd, velocity_mean, velocity_sd : float
    depth_error, velocity_error : float
        Absolute error estimates of the means and SDs (see :class:`Moments`).
    prob_behind_camera : float
        Posterior probability that the depth at the first frame is not positive.
    log_normaliser : float
        ``log`` of the integral of the unnormalised depth marginal of :func:`conditional`.
    n_nodes : int
        Number of quadrature nodes used.
    mean : ndarray, shape (3,)
        Posterior mean of ``(x, y, v)`` at time 3.
    cov : ndarray, shape (3, 3)
        Posterior covariance of ``(x, y, v)`` at time 3.
    """

    mu: np.ndarray
    rho: float
    prior: Gaussian
    reading: str
    support: str
    depth_mean: float
    depth_sd: float
    velocity_mean: float
    velocity_sd: float
    depth_error: float
    velocity_error: float
    prob_behind_camera: float
    log_normaliser: float
    n_nodes: int
    mean: np.ndarray
    cov: np.ndarray
    _problem: _Problem
    _grids: dict

    def depth_pdf(self, y) -> np.ndarray:
        """Normalised depth marginal ``p_oy`` at depths ``y`` (any shape).

        Zero at the poles ``y = 0, 1, 2`` and, for ``support="front"``, at ``y <= 2``.
        """
        y = np.asarray(y, dtype=float)
        flat = y.ravel()
        outside = np.isin(flat, (0.0, 1.0, 2.0))
        if self.support == "front":
            outside |= flat <= 2
        safe = np.where(outside, 3.0, flat)
        log_density, _, _ = conditional(safe, self.mu, self.rho, self.prior, self.reading)
        pdf = np.where(outside, 0.0, np.exp(log_density - self.log_normaliser))
        return pdf.reshape(y.shape)

    def velocity_pdf(self, v) -> np.ndarray:
        """Normalised velocity marginal ``p_ov`` at velocities ``v`` (any shape).

        The mixture over depths ``y_j`` of the Gaussian conditionals of ``v``
        given ``y``, weighted by the depth marginal, on nodes fine enough for a
        smooth curve (see :func:`_fine_velocity_mixture`).
        """
        v = np.asarray(v, dtype=float)
        w, m, sd = (
            a[0]
            for a in _fine_velocity_mixture(
                self._problem, self._grids, np.array([self.log_normaliser])
            )
        )
        keep = w > 1e-17 * np.max(w)
        w, m, sd = w[keep], m[keep], sd[keep]
        flat = v.ravel()
        pdf = np.empty(flat.size)
        for start in range(0, flat.size, 512):  # bounded memory: 512 velocities at a time
            z = (flat[start : start + 512, None] - m) / sd
            pdf[start : start + 512] = (np.exp(-0.5 * z**2) / (np.sqrt(2.0 * np.pi) * sd)) @ w
        return pdf.reshape(v.shape)


def marginals(
    mu,
    rho: float,
    prior: Gaussian,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
) -> OptimalMarginals:
    """Eqs. (13)-(16): the optimal depth and velocity marginals and their moments.

    Parameters
    ----------
    mu : array_like, shape (3,)
        Measurements; checked by :func:`depthcore.model.measurements`.
    rho : float
        Noise standard deviation, > 0.
    prior : Gaussian
        Density of the state at time 1.
    reading : {"derived", "printed"}
        ``"printed"`` drops the y-dependent factor that Eq. (16) calls constant.
    support : {"front", "all"}
        ``"front"`` (default) conditions on the point being in front of the
        camera at every frame (``y > 2``), as a camera that sees the point
        implies; ``"all"`` integrates Eq. (6) over every depth, behind the
        camera too, and reports that mass as ``prob_behind_camera``.
    rtol : float
        Target accuracy of each mean and SD, relative to the SD.

    Returns
    -------
    OptimalMarginals
    """
    mu = model.measurements(mu)
    if not isinstance(prior, Gaussian):
        raise ValueError(f"prior must be a Gaussian, got {type(prior).__name__}")
    pb = _problem(mu, rho, prior.mean, prior.cov, reading)
    rtol = _checks.positive_scalar(rtol, "rtol")
    m, err_y, err_v, top, grids = _integrate(pb, _intervals(support), rtol)
    log_z = float(np.log(m.Z[0]) + top[0])
    n_nodes = sum(int(g[2][0]) for g in grids.values())
    return OptimalMarginals(
        mu=mu,
        rho=float(rho),
        prior=prior,
        reading=reading,
        support=support,
        depth_mean=float(m.mean[0, 1]),
        depth_sd=float(np.sqrt(m.cov[0, 1, 1])),
        velocity_mean=float(m.mean[0, 2]),
        velocity_sd=float(np.sqrt(m.cov[0, 2, 2])),
        depth_error=float(err_y[0]),
        velocity_error=float(err_v[0]),
        prob_behind_camera=float(m.behind[0]),
        log_normaliser=log_z,
        n_nodes=int(n_nodes),
        mean=m.mean[0],
        cov=m.cov[0],
        _problem=pb,
        _grids=grids,
    )


@dataclass(frozen=True)
class BatchMarginals:
    """Optimal depth and velocity marginals for a batch of ``B`` problems (``y > 2``).

    Built by :func:`batch_marginals`; used for Monte Carlo studies, where each
    trial needs more than moments: the marginal CDFs at the truth and the
    depth density.

    Attributes
    ----------
    moments : Moments
    log_normaliser : ndarray, shape (B,)
    """

    moments: Moments
    log_normaliser: np.ndarray
    rtol: float
    _problem: _Problem
    _grids: dict  # the quadrature's u grids: {interval: (lo, h, n, frame)}
    # lower and upper ends (B,) of the range in t = log(y - 2) and a panel width in u (B,)
    _start: tuple

    def depth_log_pdf(self, y) -> np.ndarray:
        """``log p_oy`` at depths ``y`` of shape (B, m); ``-inf`` at ``y <= 2``."""
        y = np.asarray(y, dtype=float)
        inside = y > 2
        safe = np.where(inside, y, 3.0)
        log_density = _solve(np.stack([safe, safe - 1, safe - 2], -1), self._problem)[0]
        return np.where(inside, log_density - self.log_normaliser[:, None], -np.inf)

    def depth_cdf(self, y) -> np.ndarray:
        """``P(depth <= y)`` for one depth per problem, ``y`` of shape (B,).

        Integrated afresh from the lower end of the quadrature range up to
        ``y`` by composite 8-point Gauss-Legendre panels in ``t = log(y - 2)``,
        doubling the panels until the mass changes by at most ``rtol``.
        """
        y = _checks.finite_array(y, "y")
        lo, h, _, frame = self._grids[3]
        step = 2.0 * h
        with np.errstate(divide="ignore"):
            t_up = np.log(np.maximum(y - 2.0, 0.0))
        u_up = frame.u(t_up)
        inside = u_up > lo
        hi = np.where(inside, u_up, lo + 1.0)
        x, w = np.polynomial.legendre.leggauss(8)
        panels = max(1, int(np.ceil(np.max((hi - lo) / step))))
        previous = None
        while True:
            edges = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, panels + 1)
            half = 0.5 * np.diff(edges, axis=1)[..., None]
            u = (0.5 * (edges[:, 1:] + edges[:, :-1]))[..., None] + half * x
            offsets, log_jac = _mapped_nodes(3, u.reshape(len(y), -1), frame)
            log_f = _solve(offsets, self._problem)[0] + log_jac - self.log_normaliser[:, None]
            cdf = np.sum(np.exp(log_f) * (half * w).reshape(len(y), -1), axis=1)
            if previous is not None and np.all(np.abs(cdf - previous) <= self.rtol):
                break
            if 8 * panels > 4 * _NODE_BUDGET:
                raise ValueError(
                    f"y: the depth CDF did not reach rtol = {self.rtol:.3g} "
                    f"within {4 * _NODE_BUDGET} nodes"
                )
            previous, panels = cdf, 2 * panels
        return np.where(inside, np.clip(cdf, 0.0, 1.0), 0.0)

    def velocity_cdf(self, v) -> np.ndarray:
        """``P(velocity <= v)`` for one velocity per problem, ``v`` of shape (B,).

        The mixture over depths of the Gaussian CDFs of ``v`` given ``y``, on
        the nodes of :func:`_fine_velocity_mixture`.
        """
        from scipy.special import ndtr

        v = _checks.finite_array(v, "v")
        w, m, sd = _fine_velocity_mixture(self._problem, self._grids, self.log_normaliser)
        return np.sum(w * ndtr((v[:, None] - m) / sd), axis=1)


def batch_marginals(mu, rho, prior_mean, prior_cov, rtol: float = 1e-10) -> BatchMarginals:
    """Eqs. (13)-(16) for a batch, keeping what CDFs and densities need.

    Parameters are as for :func:`moments` (``reading="derived"``,
    ``support="front"``). Memory grows with ``B`` times the number of nodes
    (a few hundred): split very large batches.
    """
    pb = _problem(mu, rho, prior_mean, prior_cov, "derived")
    rtol = _checks.positive_scalar(rtol, "rtol")
    m, err_y, err_v, top, grids = _integrate(pb, (3,), rtol)
    log_z = np.log(m.Z) + top
    moments_ = Moments(*m.key_moments(), err_y, err_v, m.behind, m.mean, m.cov)
    lo, h, n, frame = grids[3]
    t_ends = frame.t(np.stack([lo, lo + (n - 1) * h], 1))
    return BatchMarginals(moments_, log_z, rtol, pb, grids, (t_ends[:, 0], t_ends[:, 1], 2.0 * h))


# --- pieces of the derivation of Eq. (16), and quantiles --------------------------------------


def eq16_printed(coefficients) -> np.ndarray:
    """Eq. (16) as printed: ``log(exp(l^T M^{-1} l / 8) / sqrt(det M))`` from ``A .. E``.

    Parameters
    ----------
    coefficients : array_like, shape (n, 5)
        Columns ``A, B, C, D, E`` of Eq. (14) at ``n`` depths
        (:func:`depthcore.optimal.quadratic_coefficients`).

    Returns
    -------
    ndarray, shape (n,)
        The log of the printed ``p_oy`` without its constant ``c``.
    """
    A, B, C, D, E = np.asarray(coefficients, dtype=float).T
    det_M = A * C - B**2 / 4.0  # Eq. (15): M = [[A, B/2], [B/2, C]]
    # l^T M^{-1} l with M^{-1} = [[C, -B/2], [-B/2, A]] / det M, l = (D, E)
    quad = (C * D**2 - B * D * E + A * E**2) / det_M
    return quad / 8.0 - 0.5 * np.log(det_M)


def prior_exponent(y, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """``K(y)``: the part of the exponent of (6) at depth ``y`` free of ``x`` and ``v``.

    At fixed ``y`` the log posterior (6) is
    ``-1/2 (A x**2 + B x v + C v**2 + D x + E v) - 1/2 K(y)`` up to a constant;
    ``K(y)`` is minus twice its value at ``x = v = 0``. Eq. (14) leaves it out.

    Parameters
    ----------
    y : array_like, shape (n,)
    mu, rho, prior
        As in :func:`depthcore.optimal.log_posterior`.

    Returns
    -------
    ndarray, shape (n,)
        ``K(y)``, up to an additive constant.
    """
    y = np.atleast_1d(_checks.finite_array(y, "y"))
    x = np.stack([np.zeros_like(y), y, np.zeros_like(y)], -1)
    return -2.0 * log_posterior(x, mu, rho, prior)


def depth_quantiles(m: OptimalMarginals, probs, n: int = 20001) -> np.ndarray:
    """Quantiles of the optimal depth marginal ``p_oy`` (support ``y > 2``).

    The cumulative distribution is the trapezoid rule on a grid uniform in
    ``t = log(y - 2)`` from ``y - 2 = 1e-4`` to ``50 * (E y + 10 sd)``,
    inverted by linear interpolation.

    Parameters
    ----------
    m : OptimalMarginals
        From :func:`depthcore.optimal.marginals` with ``support="front"``.
    probs : array_like
        Probabilities in (0, 1).
    n : int
        Grid points.

    Returns
    -------
    ndarray, shape of ``probs``
    """
    if m.support != "front":
        raise ValueError(f"depth_quantiles needs support='front', got {m.support!r}")
    probs = _checks.finite_array(probs, "probs")
    if np.any((probs <= 0) | (probs >= 1)):
        raise ValueError(f"probs must lie in (0, 1), got {probs.tolist()}")
    t = np.linspace(np.log(1e-4), np.log(50.0 * (m.depth_mean + 10.0 * m.depth_sd)), n)
    d = np.exp(t)
    integrand = m.depth_pdf(2.0 + d) * d
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(t))])
    if not abs(cdf[-1] - 1.0) < 1e-6:
        raise RuntimeError(f"the depth marginal integrates to {cdf[-1]:.8f} on the grid, not 1")
    return np.interp(probs, cdf / cdf[-1], 2.0 + d)
