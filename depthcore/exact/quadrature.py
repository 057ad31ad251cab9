"""The depth quadrature: the log-depth trapezoid rule with its error estimate.

Recommended import: ``from depthcore.exact import quadrature``.

The marginals of :mod:`depthcore.exact.optimal` (Eqs. (13)-(16)) and
:mod:`depthcore.exact.bank` are integrals over the depth of an integrand (a
:class:`Problem`). Each interval ``(-inf, 0)``, ``(0, 1)``, ``(1, 2)``, ``(2, inf)``
between the poles is sent to the real line (``t = log(y - 2)`` on ``y > 2``) and
integrated by the trapezoid rule about the integrand's mode (:class:`Frame`), halving
the step until the moments agree (:func:`halving_error`). A CDF over such a range is
:func:`depthcore.exact.cdf.gauss_legendre_cdf`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from depthcore.exact import tracks
from depthcore.kalman.second_order import second_order_batch
from depthcore.problem import model
from depthcore.problem.model import noise_free_states

#: Log integrand cut off this far below the maximum (e^-60 ~ 1e-26).
CUTOFF = 60.0
#: The intervals (k, k + 1) are mapped from t in [-_T_MAX, _T_MAX].
_T_MAX = 60.0
_SCAN_STEP = 1.0
#: Starting step in ``u`` (:class:`Frame`).
_U_STEP = 0.5
#: Most nodes of one interval for one problem.
NODE_BUDGET = 4097
#: Widths of the mode within which ``u`` is linear in ``t`` (:class:`Frame`).
_CORE = 4.0
#: Newton steps locating the mode of the depth integrand.
_NEWTON_STEPS = 8
#: Most damped Newton steps from the scan alone (:func:`_newton`).
_SCAN_NEWTON_STEPS = 30


class Problem(NamedTuple):
    """A batch of ``B`` problems: measurements, noise, prior (whitened) and the integrand.

    ``integrand(offsets, problem)``, for offsets ``(y, y - 1, y - 2)`` (B, n, 3),
    returns the log density (B, n), the mean of ``(x, v)`` given the depth (2, B, n)
    and its covariance entries ``(cxx, cxv, cvv)``, each (B, n). With
    ``second_order`` (:mod:`depthcore.exact.optimal`) the nodes on ``y > 2`` start
    from the second-order density of Eq. (24); without it (:mod:`depthcore.exact.bank`,
    depth ``y_1 = offsets[..., 2]``) a scan and Newton steps find the mode.

    Shapes: ``mu`` (B, 3) or (B, N), ``NaN`` at a missing frame; ``rho`` and
    ``process_noise`` (B,); ``mean`` (B, 3); ``R`` and ``cov`` (B, 3, 3), the prior
    ``P^{-1} = R^T R``; ``steps`` (B, N - 1), the depth's change between frames
    (``None``: unit); ``frame_rho`` (B, N) (``None``: ``rho``). ``reading`` is that
    of Eq. (16) (:func:`depthcore.exact.optimal.run`).
    """

    mu: np.ndarray
    rho: np.ndarray
    mean: np.ndarray
    R: np.ndarray
    integrand: Callable
    second_order: bool = False
    reading: str = "derived"
    process_noise: np.ndarray | None = None
    cov: np.ndarray | None = None
    steps: np.ndarray | None = None
    frame_rho: np.ndarray | None = None

    def take(self, idx) -> Problem:
        """The problems at ``idx`` (an index or slice of the batch)."""

        def part(a):
            return None if a is None else a[idx]

        return Problem(
            self.mu[idx],
            self.rho[idx],
            self.mean[idx],
            self.R[idx],
            self.integrand,
            self.second_order,
            self.reading,
            part(self.process_noise),
            part(self.cov),
            part(self.steps),
            part(self.frame_rho),
        )


def _nodes(interval: int, t: np.ndarray):
    """Offsets ``(y, y - 1, y - 2)`` (``t.shape + (3,)``) and ``log |dy/dt|`` at ``t``."""
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


class Frame(NamedTuple):
    """Where one interval's integrand lives, per problem: ``t = t0 + sigma L sinh(u / L)``.

    ``t0`` (B,) is the mode in ``t``, ``sigma`` (B,) its width, ``L = 4``: linear near
    the mode, logarithmic in the tails.
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


def mapped_nodes(interval: int, u: np.ndarray, frame: Frame):
    """Offsets ``(y, y - 1, y - 2)`` and ``log |dy/du|`` at nodes ``u`` of one interval:
    ``interval`` 0, 1, 2 or 3 is ``(-inf, 0)``, ``(0, 1)``, ``(1, 2)`` or ``(2, inf)``;
    ``u`` is (B, n), the results (B, n, 3) and (B, n).
    """
    offsets, log_jac = _nodes(interval, frame.t(u))
    return offsets, log_jac + frame.log_jacobian(u)


def _log_integrand(interval: int, t: np.ndarray, pb: Problem) -> np.ndarray:
    """``log p_oy(y(t)) + log |dy/dt|`` at ``t`` of shape (B, n)."""
    offsets, log_jac = _nodes(interval, t)
    return pb.integrand(offsets, pb)[0] + log_jac


#: Index pairs (i, j) of the second moments accumulated, in (x, y, v) order.
_SECOND = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
_FIRST_INDEX, _SECOND_INDEX = (np.array(ix) for ix in zip(*_SECOND, strict=True))
#: Where each entry of a 3 x 3 covariance (row-major) sits in :data:`_SECOND` order.
_SYMMETRIC = np.array([0, 3, 5, 3, 1, 4, 5, 4, 2])


def _node_values(interval, u, frame, pb):
    """Offsets, ``log`` integrand in ``u`` and the conditional Gaussian at nodes ``u`` (B, n)."""
    offsets, log_jac = mapped_nodes(interval, np.where(np.isnan(u), 0.0, u), frame)
    log_density, mean, cov = pb.integrand(offsets, pb)
    return offsets, log_density + log_jac, mean, cov


def _sums(values, skip, shift, centre):
    """Trapezoid sums (11, B): weight, moments of ``(x, y, v) - centre``, weight below 2."""
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


class Totals(NamedTuple):
    """The moments of ``B`` problems: ``mean`` (B, 3) and ``cov`` (B, 3, 3) of ``(x, y, v)``,
    ``behind`` (B,) = P(y < 2), ``Z`` (B,) the normaliser scaled by ``exp(-top)``."""

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


def _moments(totals: np.ndarray, centre: np.ndarray) -> Totals:
    """Mean, covariance, P(y < 2) and normaliser from summed totals (NaN with no weight)."""
    Z = totals[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        m = (totals[1:4] / Z).T  # (B, 3), centred
        second = (totals[4:10] / Z).T - m[:, _FIRST_INDEX] * m[
            :, _SECOND_INDEX
        ]  # (B, 6) in _SECOND order
        behind = totals[10] / Z
    second[:, :3] = np.maximum(second[:, :3], 0.0)
    cov = second[:, _SYMMETRIC].reshape(-1, 3, 3)
    return Totals(centre + m, cov, behind, Z)


def _t_limits(interval: int, pb: Problem, c: np.ndarray, cov_p: np.ndarray):
    """The ``t`` range searched in one interval, (B,) each; far ends 1e4 times the scale."""
    B = len(c)
    if interval in (1, 2):
        return np.full(B, -_T_MAX), np.full(B, _T_MAX)
    scale = np.sqrt(np.trace(cov_p, axis1=-2, axis2=-1))
    far = np.log(1e4 * (scale + np.max(np.abs(pb.mean), axis=1) + np.abs(c[:, 1]) + 10.0))
    return np.full(B, -_T_MAX), far


def _scan_points(interval: int, c, mean_s, sd_s, lo_t, hi_t, guessed: bool = False):
    """Points (B, n) in ``t`` to look for the mode, and ``n_coarse``: a unit-step scan,
    and on ``y > 2`` 25 points across 12 SDs about ``c`` and the second-order mean."""
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


def _local_points(pb: Problem):
    """Scan points (B, 27): Eq. (7)'s depth (or the prior's) offset by ``0, +-1, .., +-1e-12``."""
    if pb.mu.shape[1] >= 3 and (pb.steps is not None or np.any(np.isnan(pb.mu))):
        y = tracks.noise_free_start(pb.mu, pb.steps)
    elif pb.mu.shape[1] >= 3:
        with np.errstate(all="ignore"):
            y = model.noise_free_states_unchecked(pb.mu[:, :3])[:, 1] - 2.0
    else:
        y = np.full(len(pb.mu), np.nan)
    y = np.where(np.isfinite(y) & (y > 0), y, pb.mean[:, 1])
    t = np.log(np.where(y > 0, y, 1.0))
    steps = 10.0 ** -np.arange(13.0)
    return t[:, None] + np.concatenate([[0.0], steps, -steps])


def _frame(interval: int, pb: Problem, t, scan, coarse_mask, lo_t, hi_t):
    """The :class:`Frame` of one interval from ``scan`` at ``t`` (B, n), and the top (B,)."""
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
    if not pb.second_order:
        t0, sigma, top = _newton(interval, pb, ts[rows, best], ss[rows, best], sigma, lo_t, hi_t)
        t0 = _clip(t0, lo_t, hi_t)
        return Frame(t0, _clip(sigma, _sigma_floor(t0), 1.0)), top
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
    return Frame(t0, sigma), top


def _newton(interval: int, pb: Problem, t0, f0, sigma, lo_t, hi_t):
    """Damped Newton steps from ``t0`` (B,): the mode, its width and the log integrand there."""
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
    """Vertex, width and value of the parabola through three points (B,); else ``tb``."""
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


def _level0(frame: Frame, lo_t, hi_t):
    """The first trapezoid level: the whole ``u`` range at step :data:`_U_STEP`, (B, n)."""
    u_lo, u_hi = frame.u(lo_t), frame.u(hi_t)
    n = int(np.ceil(np.max(u_hi - u_lo) / _U_STEP)) + 1
    return u_lo[:, None] + (u_hi - u_lo)[:, None] * _unit(n)


def _ranges(pb: Problem, intervals):
    """Place each interval's nodes about its own mode and width.

    Returns the top (B,), per interval ``(frame, u, values, hi_t, (t, log f))``
    and the centre (B, 3) of the moments.
    """
    paper = pb.second_order
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
            guess = Frame(t0, _clip(sd_s / (y_s - 2.0), _sigma_floor(t0), 1.0))
            u = _level0(guess, lo_t, hi_t)
            t_all = np.concatenate([guess.t(u), t_scan], axis=1)
        else:
            t_all = t_scan
        offsets, log_jac = _nodes(i, t_all)
        log_density, mean, cov = pb.integrand(offsets, pb)
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
                frame = Frame(
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
        x_v = pb.integrand(offsets, pb)[1][:, :, 0]
        centre = np.stack([x_v[0], offsets[:, 0, 0], x_v[1]], axis=1)
    return np.max(tops, axis=0), found, centre


def integrate(pb: Problem, intervals, rtol: float):
    """Integrate the depth marginal of a batch by the trapezoid rule; moments, errors, grids.

    Each problem's step is halved until its means and SDs change by at most ``rtol``
    of the SD (or :func:`_roundoff`'s floor), independently of the other rows.

    Parameters
    ----------
    pb : Problem
    intervals : tuple of int
        See :func:`mapped_nodes`; ``(3,)`` for ``y > 2``.
    rtol : float

    Returns
    -------
    totals : Totals
    depth_error, velocity_error : ndarray, shape (B,)
        Error estimates (:func:`halving_error`).
    top : ndarray, shape (B,)
        The largest log integrand found; the sums are scaled by ``exp(-top)``.
    grids : dict
        ``{interval: (lo, h, n, frame)}``: the last level's nodes ``u = lo + h j``, ``j < n``.

    Raises
    ------
    ValueError
        The integrand does not decay, needs over :data:`NODE_BUDGET` nodes or is too narrow.
    """
    top, found, centre = _ranges(pb, intervals)
    B = len(top)
    grids, totals = {}, {}
    for i, (frame, u, values, hi_t, (t_c, scan_c)) in found.items():
        n0 = u.shape[1]
        u_lo, h0 = u[:, 0], u[:, 1] - u[:, 0]
        keep = values[1] > (top - CUTOFF)[:, None]
        keep_t = scan_c + np.log(frame.sigma)[:, None] > (top - CUTOFF)[:, None]
        if i in (0, 3):
            at_end = keep[:, -1] | np.any(keep_t & (t_c >= hi_t[:, None]), axis=1)
            if np.any(at_end):
                k = int(np.argmax(at_end))
                raise ValueError(
                    f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g}: the depth marginal "
                    f"does not decay by |y| = {np.exp(hi_t[k]):.3g}; "
                    "its moments do not exist in this reading"
                )
        j_lo, j_hi, active = kept_range(keep, (frame.u(t_c) - u_lo[:, None]) / h0[:, None], keep_t)
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
        # no interval left to refine: a posterior narrower than the scan's step
        stuck = ~done & np.all([g[1] == 0 for g in grids.values()], axis=0)
        if np.any(stuck):
            raise _too_narrow(pb, int(np.argmax(stuck)), rtol)
        if (
            max(np.max(np.where(done, 0, growth * (g[2] - 1) + 1)) for g in grids.values())
            > NODE_BUDGET
        ):
            k = int(np.argmin(done))
            raise ValueError(
                f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g} and prior mean "
                f"{pb.mean[k].tolist()}: the optimal marginal's quadrature did not reach "
                f"rtol = {rtol:.3g} within {NODE_BUDGET} nodes per interval"
            )
        levels = [dict() for _ in range(halvings)]
        for i, (lo, h, n, frame) in grids.items():
            hh = np.where(done, 0.0, h)
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
        floor = _roundoff(current, top, centre)
        err = halving_error(current.mean, current.cov, previous.mean, previous.cov, floor)
        ok = (err[0] <= np.maximum(rtol * now[1], floor[0])) & (
            err[1] <= np.maximum(rtol * now[3], floor[1])
        )
        newly = ok & ~done
        if final is None or np.all(newly):
            final = current
        else:
            final = Totals(
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


def kept_range(keep, scan_index, keep_scan):
    """The nodes of the first level that later levels refine: those kept, one more each side.

    Nodes are named by index, scan points by position in steps, so rounding does not
    matter. ``keep`` (B, n) and ``keep_scan`` (B, m) are bool, ``scan_index`` (B, m) the
    scan's positions on the nodes ``0 .. n - 1``. Returns ``j_lo, j_hi`` (B,), floats (0
    where nothing is kept), and ``active`` (B,).
    """
    n = keep.shape[1]
    index = np.arange(n, dtype=float)
    first = np.minimum(
        np.min(np.where(keep, index, np.inf), axis=1),
        np.floor(np.min(np.where(keep_scan, scan_index, np.inf), axis=1)),
    )
    last = np.maximum(
        np.max(np.where(keep, index, -np.inf), axis=1),
        np.ceil(np.max(np.where(keep_scan, scan_index, -np.inf), axis=1)),
    )
    active = np.isfinite(first)
    j_lo = _clip(np.where(active, first - 1, 0), 0, n - 1)
    j_hi = _clip(np.where(active, last + 1, 0), 0, n - 1)
    return j_lo, j_hi, active


def _too_narrow(pb: Problem, k: int, rtol: float) -> ValueError:
    """The refusal of problem ``k``, whose depth marginal no float grid can resolve."""
    return ValueError(
        f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g} and prior mean "
        f"{pb.mean[k].tolist()}: the depth marginal is too narrow to resolve in double "
        f"precision, so its quadrature cannot reach rtol = {rtol:.3g}"
    )


def _check_peak(log_f, skip, top, pb: Problem, rtol: float) -> None:
    """Refuse a problem whose refined nodes rise ``e^60`` above ``top`` (a missed mode)."""
    with np.errstate(invalid="ignore"):
        high = np.any(np.where(skip, False, log_f > (top + CUTOFF)[:, None]), axis=1)
    if np.any(high):
        k = int(np.argmax(high))
        raise ValueError(
            f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g} and prior mean "
            f"{pb.mean[k].tolist()}: the depth marginal is too narrow to locate in double "
            f"precision, so its quadrature cannot reach rtol = {rtol:.3g}"
        )


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


def grid(lo, h, n, offset):
    """Nodes ``lo + h (j + offset)``, ``j < n`` (``n`` per problem), of a trapezoid level.

    ``lo``, ``h`` and ``n`` are (B,) (``h = 0``: no nodes); ``offset`` is in steps (0.5
    for midpoints). Returns (B, max n), padded with NaN.
    """
    n = np.broadcast_to(n, lo.shape)
    j = np.arange(int(np.max(n)))
    u = lo[:, None] + h[:, None] * (j + offset)
    return np.where((j < n[:, None]) & (h[:, None] > 0), u, np.nan)


def _roundoff(totals: Totals, top: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """A floor (2, B) on the error of the depth and velocity moments from roundoff.

    ``64 eps`` times: ``|E y| + sd y`` (rounded nodes), ``|top| sd y`` (the log
    integrand's error) and ``(E y - centre)**2 / sd y`` (cancellation); likewise for ``v``.
    """
    eps = np.finfo(float).eps
    noise = 1.0 + np.abs(top)
    sd = np.sqrt(totals.cov[:, [1, 2], [1, 2]].T)
    mean = totals.mean[:, 1:].T
    offset = (mean - centre[:, 1:].T) ** 2 + sd**2
    with np.errstate(divide="ignore", invalid="ignore"):
        cancel = np.where(sd > 0, offset / sd, 0.0)
    return 64.0 * eps * (np.abs(mean) + sd + noise * sd + cancel)


def halving_error(mean, cov, halved_mean, halved_cov, floor) -> np.ndarray:
    """The error of the depth's and the velocity's mean and SD from one halving of the step.

    The trapezoid rule converges geometrically here, so the larger change of the
    mean and the SD bounds the finer level's error, at least ``floor``; NaN is infinite.

    ``mean`` (..., 3) and ``cov`` (..., 3, 3) are on the finer nodes, ``halved_*`` on the
    coarser; ``floor`` and the result (2, ...) are the depth's and the velocity's rows.
    """
    changes = []
    for k in (1, 2):
        change = np.maximum(
            np.abs(mean[..., k] - halved_mean[..., k]),
            np.abs(np.sqrt(cov[..., k, k]) - np.sqrt(halved_cov[..., k, k])),
        )
        changes.append(np.where(np.isnan(change), np.inf, change))
    return np.maximum(np.stack(changes), floor)
