"""Where the depth quadrature puts its nodes: each interval on the real line, about its mode.

Recommended import: ``from depthcore.exact import modes``.

:func:`depthcore.exact.quadrature.integrate` sends each interval ``(-inf, 0)``,
``(0, 1)``, ``(1, 2)``, ``(2, inf)`` of the paper's depth ``y`` (at frame 3) between
the poles to the real line (:func:`interval_nodes`: ``t = log(y - 2)`` on ``y > 2``)
and lays its trapezoid nodes in ``u``, ``t = t0 + sigma L sinh(u / L)``
(:class:`Frame`), about the integrand's mode ``t0`` and width ``sigma``. This
module finds them (:func:`ranges`): a scan in ``t`` (about the second-order
density of Eq. (24) for the paper's triple, about the noise-free depth of the
first bearings for the bank), then parabolic and Newton steps. A new way to
find an interval's mode goes here; the rule, its error estimate and the moments
stay in :mod:`depthcore.exact.quadrature`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from depthcore.exact import tracks
from depthcore.kalman.second_order import second_order_batch
from depthcore.problem import model
from depthcore.problem.model import noise_free_states

if TYPE_CHECKING:
    from depthcore.exact.quadrature import Problem

#: The intervals (k, k + 1) are mapped from t in [-_T_MAX, _T_MAX].
_T_MAX = 60.0
_SCAN_STEP = 1.0
#: Starting step in ``u`` (:class:`Frame`).
_U_STEP = 0.5
#: Widths of the mode within which ``u`` is linear in ``t`` (:class:`Frame`).
_CORE = 4.0
#: Newton steps locating the mode of the depth integrand.
_NEWTON_STEPS = 8
#: Most damped Newton steps from the scan alone (:func:`_newton`).
_SCAN_NEWTON_STEPS = 30


def interval_nodes(interval: int, t: np.ndarray):
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
    offsets, log_jac = interval_nodes(interval, frame.t(u))
    return offsets, log_jac + frame.log_jacobian(u)


def log_integrand(interval: int, t: np.ndarray, pb: Problem) -> np.ndarray:
    """``log p_oy(y(t)) + log |dy/dt|`` at ``t`` of shape (B, n)."""
    offsets, log_jac = interval_nodes(interval, t)
    return pb.integrand(offsets, pb)[0] + log_jac


def node_values(interval, u, frame, pb):
    """Offsets, ``log`` integrand in ``u`` and the conditional Gaussian at nodes ``u`` (B, n)."""
    offsets, log_jac = mapped_nodes(interval, np.where(np.isnan(u), 0.0, u), frame)
    log_density, mean, cov = pb.integrand(offsets, pb)
    return offsets, log_density + log_jac, mean, cov


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
        sd_t = clip(sd_s / (c[:, 1] - 2.0), _sigma_floor(np.log(c[:, 1] - 2.0)), 1.0)
        t_c = np.log(c[:, 1] - 2.0)
        t_s = np.log(np.where(mean_s[:, 1] > 2.0, mean_s[:, 1] - 2.0, c[:, 1] - 2.0))
        centres = [t_c, t_s]
        if guessed and np.all(np.abs(t_c - t_s) <= sd_t):
            centres = []  # the first level in the second-order frame covers both densely
        t = np.concatenate([t] + [ct[:, None] + sd_t[:, None] * local for ct in centres], 1)
        t = clip(t, lo_t[:, None], hi_t[:, None])
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
    floor = pb.floor
    y = y - floor  # the bank's quadrature depth: above the floor (Problem.floor)
    y = np.where(np.isfinite(y) & (y > 0), y, pb.mean[:, 1] - floor)
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
    k = clip(best, 1, ts.shape[1] - 2)
    t0, sigma, top = _parabola(
        ts[rows, k - 1], ts[rows, k], ts[rows, k + 1], ss[rows, k - 1], ss[rows, k], ss[rows, k + 1]
    )
    coarse = coarse_mask[order[rows, best]]
    if not pb.second_order:
        t0, sigma, top = _newton(interval, pb, ts[rows, best], ss[rows, best], sigma, lo_t, hi_t)
        t0 = clip(t0, lo_t, hi_t)
        return Frame(t0, clip(sigma, _sigma_floor(t0), 1.0)), top
    for _ in range(_NEWTON_STEPS if np.any(coarse) else 0):
        pts = clip(
            t0[:, None] + sigma[:, None] * np.array([-1.0, 0.0, 1.0]), lo_t[:, None], hi_t[:, None]
        )
        phi = log_integrand(interval, pts, pb)
        t1, s1, top1 = _parabola(*pts.T, *phi.T)
        better = coarse & (top1 >= top)
        t0, sigma, top = (
            np.where(better, t1, t0),
            np.where(coarse, s1, sigma),
            np.maximum(top, np.where(coarse, top1, top)),
        )
    t0 = clip(t0, lo_t, hi_t)
    sigma = clip(sigma, _sigma_floor(t0), 1.0)
    return Frame(t0, sigma), top


def _newton(interval: int, pb: Problem, t0, f0, sigma, lo_t, hi_t):
    """Damped Newton steps from ``t0`` (B,): the mode, its width and the log integrand there."""
    floor = _sigma_floor(t0)
    for _ in range(_SCAN_NEWTON_STEPS):
        h = clip(sigma, floor, 1.0)
        pts = t0[:, None] + h[:, None] * np.array([-1.0, 0.0, 1.0])
        phi = log_integrand(interval, clip(pts, lo_t[:, None], hi_t[:, None]), pb)
        with np.errstate(invalid="ignore", over="ignore"):
            d1 = (phi[:, 2] - phi[:, 0]) / (2.0 * h)
            d2 = (phi[:, 2] - 2.0 * phi[:, 1] + phi[:, 0]) / h**2
            concave = np.isfinite(d1) & np.isfinite(d2) & (d2 < 0)
            move = np.where(concave, -d1 / np.where(concave, d2, -1.0), 4.0 * h * np.sign(d1))
            width = np.where(concave, 1.0 / np.sqrt(-np.where(concave, d2, -1.0)), 2.0 * h)
        move = np.where(np.isfinite(move), move, 0.0)
        f1 = np.full_like(f0, -np.inf)
        for _ in range(60):  # halve the move until the log integrand does not decrease
            t1 = clip(t0 + move, lo_t, hi_t)
            worse = ~(f1 >= f0) & (np.abs(move) > 0.01 * h)
            if not np.any(worse):
                break
            f1 = np.where(worse, log_integrand(interval, t1[:, None], pb)[:, 0], f1)
            move = np.where(~(f1 >= f0), 0.5 * move, move)
        up = f1 >= f0
        sigma = clip(width, floor, 1.0)
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
        vertex = np.where(concave, clip(vertex, ta, tc), tb)
        gap = np.maximum(tb - ta, tc - tb)
        width = np.where(concave, clip(1.0 / np.sqrt(-safe), 0.25 * gap, 4.0 * gap), gap)
        value = np.where(
            concave, fb + d1 * (vertex - tb) + 0.5 * curv * (vertex - ta) * (vertex - tb), fb
        )
    return vertex, width, np.maximum(value, fb)


def _unit(n: int) -> np.ndarray:
    """``n`` equally spaced points from 0 to 1."""
    return np.arange(n) / (n - 1)


def clip(a, lo, hi):
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


def ranges(pb: Problem, intervals):
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
            t_scan = clip(
                np.concatenate([t_scan, _local_points(pb)], 1), lo_t[:, None], hi_t[:, None]
            )
            n_coarse = t_scan.shape[1]  # every point may start the Newton steps
        guess = None
        if i == 3 and paper:
            y_s = np.where(mean_s[:, 1] > 2.0, mean_s[:, 1], c[:, 1])
            t0 = clip(np.log(y_s - 2.0), lo_t, hi_t)
            guess = Frame(t0, clip(sd_s / (y_s - 2.0), _sigma_floor(t0), 1.0))
            u = _level0(guess, lo_t, hi_t)
            t_all = np.concatenate([guess.t(u), t_scan], axis=1)
        else:
            t_all = t_scan
        offsets, log_jac = interval_nodes(i, t_all)
        log_density, mean, cov = pb.integrand(offsets, pb)
        log_t = log_density + log_jac
        m = t_all.shape[1] - t_scan.shape[1]
        coarse_mask = np.arange(t_all.shape[1]) - m < n_coarse
        coarse_mask[:m] = False
        if guess is not None:
            # the mode and width from the first level's nodes about its best one
            rows = np.arange(len(c))
            best = np.argmax(log_t, axis=1)
            k = clip(best, 1, m - 2)
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
            values = node_values(i, u, frame, pb)
        scan = (t_all[:, m:], log_t[:, m:])
        found[i] = (frame, u, values, hi_t, scan)
        tops.append(np.maximum(top_i + np.log(frame.sigma), np.max(values[1], axis=1)))
    if paper:
        centre = np.where(np.isfinite(mean_s), mean_s, c)
    else:  # the state at the mode of the depth (in the quadrature's depth, y_1 + 2)
        t0 = found[3][0].t0
        offsets, _ = interval_nodes(3, t0[:, None])
        x_v = pb.integrand(offsets, pb)[1][:, :, 0]
        centre = np.stack([x_v[0], offsets[:, 0, 0], x_v[1]], axis=1)
    return np.max(tops, axis=0), found, centre
