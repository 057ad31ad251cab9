"""The tail of a pair under a mixture of bivariate Gaussians: the mass of lower densities.

Recommended import: ``from depthcore.problem import pair_tail``.

A filter of a point in 3-D predicts the next pair ``z = (x / y, h / y)`` by a mixture
``p(z) = sum_j w_j N(z; m_j, S_j)`` (the exact filter: a component per depth node). The
pair's tail, ``T = P_{Z ~ p}(p(Z) <= p(z_obs))``, is ``exp(-d**2 / 2)`` for one Gaussian
(``d`` the Mahalanobis distance, the Gaussian filters' gate,
:mod:`depthcore.kalman.spatial`). :func:`tail` computes it for a mixture, by rays from the
mixture's mean ``c``, whitened by the Cholesky factor ``L`` of its covariance:
``z = c + L r (cos t, sin t)``, ``dz = det(L) r dr dt``. Along a ray, ``f(r) = log p(z) -
log p(z_obs)`` is found on a grid (half an SD or less about each component's centre), its
extrema and then its crossings ``f = 0`` (one between consecutive extrema) refined by the
Illinois rule; over each interval of ``{f <= 0}`` each component's mass has a closed form,
over ``[r, inf)`` ``K exp(-q(r) / 2) s (s + mu sqrt(pi / 2) erfcx((r - mu) / (s sqrt 2)))``
(``q(r) = A r**2 - 2 B r + C`` its Mahalanobis form, ``s = A**-0.5``, ``mu = B / A``). In
the angle, a ray tangent to the level set ``p = p(z_obs)`` changes the number of crossings
and puts a square-root kink in the mass: kinks are found by bisection, and between them
Gauss-Legendre in ``u``, ``t = a + (b - a) (1 - cos(pi u)) / 2``, integrates smoothly
(without kinks, the periodic trapezoid rule). The order doubles until two values agree to
``max(ATOL, RTOL * T)``; the error reported is their difference.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import erfcx, logsumexp, ndtr, roots_legendre

#: The tolerance absolute and relative to the tail, whichever is larger.
ATOL, RTOL = 1e-9, 1e-6
#: The doubling of the angles stops at this many, over all segments of one order.
MAX_ANGLES = 2**13
_NEGLIGIBLE = 40.0  # a component this far below p(z_obs) on a ray places no grid there
_SLIVER = 1e-9  # kinks nearer than this are rounding's (a sector's error: its width**1.5)
_CELLS = 2**22  # grid values per chunk of rays


class PairTail(NamedTuple):
    """The tail ``T`` and the estimate of its error (the last two orders' difference)."""

    tail: float
    error: float


class _Rays:
    """The mixture seen along rays from its mean: crossings and masses."""

    def __init__(self, z, log_w, means, covs):
        keep = log_w > -np.inf
        log_w, means, covs = log_w[keep] - logsumexp(log_w[keep]), means[keep], covs[keep]
        w = np.exp(log_w)
        c = w @ means
        e = means - c
        V = np.einsum("j,jkl->kl", w, covs + e[:, :, None] * e[:, None, :])
        L = np.linalg.cholesky(V)
        P = np.linalg.inv(covs)
        self.log_K = log_w - np.log(2 * np.pi) - 0.5 * np.linalg.slogdet(covs)[1]
        self.G = np.einsum("ki,jkl,lm->jim", L, P, L)
        self.b = np.einsum("ki,jkl,jl->ji", L, P, e)
        self.C = np.einsum("jk,jkl,jl->j", e, P, e)
        self.det_L = L[0, 0] * L[1, 1]
        r = np.asarray(z, float) - means
        q = np.einsum("jk,jkl,jl->j", r, P, r)
        self.log_p0 = float(logsumexp(self.log_K - 0.5 * q))

    def _f(self, A, B, r):
        """``f`` and ``f'`` at ``r`` (..., n) along rays of ``A``, ``B`` (..., J)."""
        A, B = A[..., None, :], B[..., None, :]
        r = r[..., None]
        log_t = self.log_K - 0.5 * (A * r * r - 2 * B * r + self.C)
        top = np.max(log_t, axis=-1, keepdims=True)
        e = np.exp(log_t - top)
        total = np.sum(e, axis=-1)
        lp = np.log(total) + top[..., 0]
        return lp - self.log_p0, np.sum(e * (B - A * r), -1) / total

    def _mass(self, A, B, r):
        """Each ray's mass over ``[r, inf)``, ``det(L)`` included; ``r`` (M,) >= 0."""
        r = r[:, None]
        s = 1 / np.sqrt(A)
        mu = B * s * s
        t = (r - mu) / s
        q = A * r * r - 2 * B * r + self.C
        far = (
            np.exp(self.log_K - 0.5 * q) * s * (s + mu * np.sqrt(np.pi / 2) * erfcx(t / np.sqrt(2)))
        )
        near_q = np.maximum(self.C - B * mu, 0.0)
        near = (
            np.exp(self.log_K - 0.5 * near_q)
            * s
            * (s * np.exp(-0.5 * np.minimum(t, 0) ** 2) + mu * np.sqrt(2 * np.pi) * ndtr(-t))
        )
        return self.det_L * np.sum(np.where(t >= 0, far, near), axis=-1)

    def rays(self, theta):
        """Mass of ``{p <= p(z_obs)}`` along each ray (M,) and its number of crossings (M,)."""
        theta = np.asarray(theta, float)
        step = max(1, _CELLS // (self.C.size * 64))
        if not theta.size:
            return np.empty(0), np.empty(0, int)
        out = [self._rays(theta[k : k + step]) for k in range(0, theta.size, step)]
        return tuple(np.concatenate(v) for v in zip(*out, strict=True))

    def _rays(self, theta):
        u = np.stack([np.cos(theta), np.sin(theta)], -1)
        A = np.einsum("mi,jik,mk->mj", u, self.G, u)
        B = u @ self.b.T
        mu = B / A
        top = np.maximum(mu, 0.0)
        peak = self.log_K - 0.5 * (A * top * top - 2 * B * top + self.C)
        relevant = peak >= self.log_p0 - _NEGLIGIBLE - np.log(self.C.size)
        r_m = np.max(np.where(relevant, top, 0.0), axis=1)
        M = theta.size
        grid = _grid(mu, 1 / np.sqrt(A), relevant, r_m)
        per = max(1, _CELLS // (grid.shape[1] * A.shape[1]))
        parts = [
            self._f(A[k : k + per], B[k : k + per], grid[k : k + per]) for k in range(0, M, per)
        ]
        f, d = (np.concatenate(v) for v in zip(*parts, strict=True))
        # extrema: f' changes sign between grid points
        i, col = np.nonzero((d[:, :-1] > 0) != (d[:, 1:] > 0))
        Ai, Bi = A[i], B[i]
        ext = _root(
            lambda x: self._f(Ai, Bi, x[:, None])[1][:, 0],
            *(grid[i, col], grid[i, col + 1], d[i, col], d[i, col + 1]),
        )
        # the far end: beyond r_m every relevant term decreases, f(r_far) < 0
        a_min = np.min(np.where(relevant, A, np.inf), axis=1)
        a_min = np.where(np.isfinite(a_min), a_min, np.max(A, axis=1))
        r_far = r_m + np.sqrt(2 * np.maximum(f[:, -1] + 1.0, 0.0) / a_min)
        counts = np.bincount(i, minlength=M)
        width = int(np.max(counts, initial=0)) + 2
        crit = np.repeat(r_far[:, None], width, axis=1)
        crit[:, 0] = 0.0
        slot = np.arange(i.size) - np.repeat(np.cumsum(counts) - counts, counts) + 1
        crit[i, slot] = ext
        crit.sort(axis=1)
        fc, _ = self._f(A, B, crit)
        # crossings: one between consecutive critical points of opposite signs
        ri, rc = np.nonzero((fc[:, :-1] <= 0) != (fc[:, 1:] <= 0))
        Ar, Br = A[ri], B[ri]
        cross = _root(
            lambda x: self._f(Ar, Br, x[:, None])[0][:, 0],
            *(crit[ri, rc], crit[ri, rc + 1], fc[ri, rc], fc[ri, rc + 1]),
        )
        inside = fc[:, 0] <= 0  # the ray starts in {p <= p0}
        n_cross = np.bincount(ri, minlength=M)
        order = np.arange(ri.size) - np.repeat(np.cumsum(n_cross) - n_cross, n_cross)
        sign = np.where((order + inside[ri]) % 2 == 0, 1.0, -1.0)
        mass = np.bincount(ri, sign * self._mass(A[ri], B[ri], cross), minlength=M).astype(float)
        mass += np.where(inside, self._mass(A, B, np.zeros(M)), 0.0)
        return mass, n_cross


def _grid(mu, sd, relevant, r_m):
    """Each ray's grid on ``[0, r_m]`` (M, n), padded with ``r_m``: 64 equal cells, and
    about each relevant component's centre ``mu_j`` (within 6 SDs) a lattice of at most
    half its SD ``sd_j`` (a power of 2, shared by the components of one scale)."""
    M = mu.shape[0]
    level = np.floor(np.log2(sd / 2))
    points = mu[..., None] + sd[..., None] * np.linspace(-6.0, 6.0, 25)
    cell = np.floor(points / 2.0 ** level[..., None])
    ok = relevant[..., None] & (points > 0) & (points < r_m[:, None, None])
    ray = np.broadcast_to(np.arange(M)[:, None, None], ok.shape)
    keys = np.unique(np.stack([ray[ok], level[..., None].repeat(25, -1)[ok], cell[ok]]), axis=1)
    ray = np.concatenate([keys[0].astype(int), np.repeat(np.arange(M), 65)])
    r = np.concatenate([keys[2] * 2.0 ** keys[1], (r_m[:, None] * np.linspace(0, 1, 65)).ravel()])
    order = np.lexsort((r, ray))
    ray, r = ray[order], r[order]
    counts = np.bincount(ray, minlength=M)
    grid = np.repeat(r_m[:, None], counts.max() + 1, axis=1)
    grid[ray, np.arange(ray.size) - np.repeat(np.cumsum(counts) - counts, counts)] = r
    return grid


def _root(fun, lo, hi, f_lo, f_hi):
    """Roots of ``fun`` in brackets ``[lo, hi]`` (values of opposite signs) by the Illinois rule."""
    side = np.zeros(lo.shape)
    for _ in range(40):
        if np.all(hi - lo <= 4e-16 * np.maximum(1.0, hi)):
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        x = np.where((x > lo) & (x < hi), x, 0.5 * (lo + hi))
        fx = fun(x)
        keep_hi = (fx > 0) == (f_lo > 0)  # x replaces lo
        f_hi = np.where(keep_hi & (side == 1), 0.5 * f_hi, f_hi)
        f_lo = np.where(~keep_hi & (side == -1), 0.5 * f_lo, f_lo)
        lo, f_lo = np.where(keep_hi, x, lo), np.where(keep_hi, fx, f_lo)
        hi, f_hi = np.where(keep_hi, hi, x), np.where(keep_hi, f_hi, fx)
        side = np.where(keep_hi, 1, -1)
    return 0.5 * (lo + hi) if lo.size else lo


def _breaks(rays, a, b, na):
    """Angles where the crossing count changes, by bisection between ``a`` and ``b``."""
    for _ in range(44):  # 2 pi / 64 / 2**44 < 1e-14
        mid = 0.5 * (a + b)
        _, nm = rays.rays(mid)
        left = nm == na
        a, b = np.where(left, mid, a), np.where(left, b, mid)
        na = np.where(left, nm, na)
    return 0.5 * (a + b)


def _cyclic(rays, theta, n):
    """The kinks between equally spaced angles ``theta`` (around the circle) of counts ``n``."""
    k = np.flatnonzero(n != np.roll(n, -1))
    return _breaks(rays, theta[k], theta[k] + 2 * np.pi / theta.size, n[k])


def tail(z, log_weights, means, covs) -> PairTail:
    """The tail of the pair ``z`` under a Gaussian mixture, ``P(p(Z) <= p(z))`` (module docstring).

    Parameters
    ----------
    z : array_like, shape (2,)
        The observed pair.
    log_weights : array_like, shape (J,)
        Log weights, normalised or not; ``-inf`` for an empty component.
    means : array_like, shape (J, 2)
    covs : array_like, shape (J, 2, 2)
        Symmetric positive definite.

    Returns
    -------
    PairTail
        The tail in [0, 1] and the error estimate, at most ``max(ATOL, RTOL * tail)``
        unless :data:`MAX_ANGLES` angles did not reach it.
    """
    log_w = np.asarray(log_weights, float)
    if not np.any(log_w > -np.inf):
        raise ValueError("log_weights: every component is empty")
    rays = _Rays(z, log_w, np.asarray(means, float), np.asarray(covs, float))
    theta = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    breaks = _clean(_cyclic(rays, theta, rays.rays(theta)[1]))
    for rounds in range(16, -1, -1):  # kinks found at new angles start the segments again
        value, error, extra = _integrate(rays, breaks, rounds > 0)
        if extra is None:
            break
        more = _clean(np.concatenate([breaks, extra]))
        if more.size == breaks.size:  # no new kink but the rounding's: stop looking
            value, error, _ = _integrate(rays, breaks, False)
            break
        breaks = more
    return PairTail(float(np.clip(value, 0.0, 1.0)), float(error))


def _clean(breaks):
    """Kinks in [0, 2 pi), sorted, without pairs nearer than ``_SLIVER``."""
    b = np.sort(np.mod(breaks, 2 * np.pi))
    close = np.diff(b, append=b[:1] + 2 * np.pi) < _SLIVER
    return b[~(close | np.roll(close, 1))]


def _integrate(rays, breaks, check):
    """The angle integral between kinks ``breaks``: value, error, and new kinks or ``None``
    (``check``: whether a crossing count that differs within a segment ends it)."""
    previous = None
    order = 32
    while True:
        if breaks.size == 0:
            theta = np.linspace(0.0, 2 * np.pi, order, endpoint=False)
            g, n = rays.rays(theta)
            value = 2 * np.pi * np.mean(g)
            if check and np.any(n != n[0]):
                return value, np.inf, _cyclic(rays, theta, n)
        else:
            a = breaks
            b = np.append(breaks[1:], breaks[0] + 2 * np.pi)
            x, w = roots_legendre(order)
            s = 0.5 * (x + 1)
            theta = a[:, None] + (b - a)[:, None] * 0.5 * (1 - np.cos(np.pi * s))
            jac = (b - a)[:, None] * 0.25 * np.pi * np.sin(np.pi * s) * w
            g, n = rays.rays(theta.ravel())
            g, n = g.reshape(theta.shape), n.reshape(theta.shape)
            value = float(np.sum(g * jac))
            mid = n[:, order // 2][:, None]
            bad_s, bad_k = np.nonzero(n != mid)
            if check and bad_s.size:
                nb = order // 2
                new = _breaks(rays, theta[bad_s, bad_k], theta[bad_s, nb], n[bad_s, bad_k])
                return value, np.inf, new
        if previous is not None:
            error = abs(value - previous)
            if error <= max(ATOL, RTOL * abs(value)) or order * max(1, breaks.size) >= MAX_ANGLES:
                return value, error, None
        previous = value
        order *= 2
