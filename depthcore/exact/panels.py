"""The depth quadrature under any prior on the depth: Gauss-Legendre panels that end at its edges.

Recommended import: ``from depthcore.exact import panels``.

Under a :class:`~depthcore.problem.depth_prior.DepthPrior` the integrand over the
depth at frame 1, ``f(y) = p(y) L(y)`` (:func:`depthcore.exact.bank.lateral_filter`
with the law), may jump at the prior's edges and bend at its kinks, so the
trapezoid rule of :mod:`depthcore.exact.quadrature`, exact for smooth integrands on
the line, would converge slowly. Here the depth above the floor is written
``y - floor = e^t`` and ``t`` is cut into panels at every edge and kink
(:attr:`~depthcore.problem.depth_prior.DepthPrior.breakpoints`), about the
integrand's mode (found by a scan and Newton steps) and evenly elsewhere. Each
panel's 8-point Gauss-Legendre rule is compared with the rule on its two halves;
panels whose change moves the depth's or the velocity's mean or SD by more than
their share of ``rtol`` SDs are halved, until the changes summed over the panels
are within ``rtol`` of each SD (or of the moments' own rounding, as
:func:`depthcore.exact.quadrature.integrate` allows). The nodes returned are the
halves' (:func:`place`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from depthcore.exact import tracks
from depthcore.exact.bank import lateral_filter
from depthcore.exact.quadrature import CUTOFF, Problem
from depthcore.problem.depth_prior import DepthPrior

#: Gauss-Legendre nodes per panel (and per half panel).
ORDER = 8
_X, _W = np.polynomial.legendre.leggauss(ORDER)
#: Points of the first scan across the prior's range, in ``t``.
SCAN = 257
#: Most panels for one problem before it is refused.
PANEL_BUDGET = 4096
#: Most rounds of halving.
ROUNDS = 40
#: The widest first panel, as a fraction of the range in ``t``.
_SPREAD = 1.0 / 32.0
#: Cuts about the mode, in its widths.
_ABOUT_MODE = np.array([0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
#: How far below the floor's neighbourhood the lower end may go: ``y - floor = e^-60`` y.
_T_FLOOR = 60.0


class Placed(NamedTuple):
    """Nodes of ``B`` problems and their errors.

    Attributes
    ----------
    nodes : ndarray, shape (B, J)
        Depths at frame 1; padding repeats a node.
    log_weights : ndarray, shape (B, J)
        Log quadrature weights in ``y`` (``-inf`` at padding).
    depth_error, velocity_error : ndarray, shape (B,)
        The larger change of the mean and the SD of ``y`` (of ``v_N``) under one
        halving of every panel, summed over the panels.
    """

    nodes: np.ndarray
    log_weights: np.ndarray
    depth_error: np.ndarray
    velocity_error: np.ndarray


class Target(NamedTuple):
    """What the panels integrate for ``B`` problems.

    Attributes
    ----------
    values : callable
        ``values(y, idx)``, depths at frame 1 ``y`` (P, n) of the problems ``idx`` (P,):
        ``log f(y)`` (the prior's log density plus the log likelihood), ``E[v_N | y]`` and
        ``Var[v_N | y]``, each (P, n).
    floor : ndarray, shape (B,)
        The depth at frame 1 below which the point would reach the camera.
    seeds : ndarray, shape (B, S)
        Depths at frame 1 the scan for the mode also tries (``NaN``: none).
    name : callable
        ``name(k)``, problem ``k`` in a refusal.
    """

    values: Callable
    floor: np.ndarray
    seeds: np.ndarray
    name: Callable


def of_problems(pb: Problem, law: DepthPrior) -> Target:
    """The :class:`Target` of the bank's problems ``pb`` under ``law``
    (:func:`~depthcore.exact.bank.lateral_filter` at each depth, its ``prior_mean`` and
    ``prior_cov`` unread); the scan also tries the depth the first three bearings fit."""

    def values(y, idx):
        log_w, (_, v), (_, _, c) = lateral_filter(
            y,
            pb.mu[idx],
            pb.rho[idx],
            pb.process_noise[idx],
            pb.mean[idx],
            pb.cov[idx],
            None if pb.steps is None else pb.steps[idx],
            None if pb.frame_rho is None else pb.frame_rho[idx],
            law,
        )
        return log_w, v, c

    seeds = np.full((pb.mu.shape[0], 1), np.nan)
    if pb.mu.shape[1] >= 3:  # the depth the first three present bearings fit exactly
        with np.errstate(all="ignore"):
            seeds[:, 0] = tracks.noise_free_start(pb.mu, pb.steps)

    def name(k):
        return f"mu[{k}] = {pb.mu[k].tolist()} with rho = {pb.rho[k]:.6g}"

    return Target(values, pb.floor, seeds, name)


def _log_f(t, idx, target: Target):
    """``log f`` in ``t`` (with ``dy = e^t dt``), ``E[v_N | y]`` and ``Var[v_N | y]`` at ``t``
    (P, n) of the problems ``idx`` (P,)."""
    y = target.floor[idx][:, None] + np.exp(t)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        log_w, v, c = target.values(y, idx)
    log_w = np.where(np.isnan(log_w), -np.inf, log_w)
    return y, log_w + t, np.broadcast_to(v, y.shape), np.broadcast_to(c, y.shape)


def _ends(target: Target, law: DepthPrior):
    """The range ``(t_lo, t_hi)`` (B,) of ``t`` and whether each end is the prior's edge."""
    lo, hi = law.support
    floor = target.floor
    ey, ey2 = law.depth_moments()
    scale = ey + np.sqrt(max(ey2 - ey * ey, 0.0))
    lo_edge = lo > floor
    t_lo = np.where(lo_edge, np.log(np.where(lo_edge, lo - floor, 1.0)), 0.0)
    t_lo = np.where(lo_edge, t_lo, np.log(scale + np.abs(floor)) - _T_FLOOR)
    far = hi if np.isfinite(hi) else ey + 40.0 * np.sqrt(max(ey2 - ey * ey, 0.0)) + scale
    t_hi = np.log(np.maximum(far - floor, np.exp(t_lo) * 2.0))
    return t_lo, t_hi, lo_edge, np.full(len(floor), np.isfinite(hi))


def _mode(target: Target, law, t_lo, t_hi):
    """The scan's and Newton's mode ``t*`` (B,), its width (B,) and ``log f`` there (B,)."""
    B = len(t_lo)
    rows = np.arange(B)
    t = t_lo[:, None] + (t_hi - t_lo)[:, None] * np.linspace(0.0, 1.0, SCAN)
    ey, _ = law.depth_moments()
    seeds = np.concatenate([target.seeds, np.full((B, 1), ey)], 1) - target.floor[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        extra = np.log(np.where(np.isfinite(seeds) & (seeds > 0), seeds, np.exp(t_lo)[:, None]))
    t = np.clip(np.concatenate([t, extra], 1), t_lo[:, None], t_hi[:, None])
    f = _log_f(t, rows, target)[1]
    k = np.argmax(f, axis=1)
    t0, f0 = t[rows, k], f[rows, k]
    h = np.full(B, (t_hi - t_lo) / (SCAN - 1))
    for _ in range(30):  # damped Newton on finite differences
        pts = np.clip(
            t0[:, None] + h[:, None] * np.array([-1.0, 0.0, 1.0]), t_lo[:, None], t_hi[:, None]
        )
        phi = _log_f(pts, rows, target)[1]
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            d1 = (phi[:, 2] - phi[:, 0]) / (2.0 * h)
            d2 = (phi[:, 2] - 2.0 * phi[:, 1] + phi[:, 0]) / h**2
            concave = np.isfinite(d1) & np.isfinite(d2) & (d2 < 0)
            move = np.where(concave, -d1 / np.where(concave, d2, -1.0), 2.0 * h * np.sign(d1))
            width = np.where(concave, 1.0 / np.sqrt(-np.where(concave, d2, -1.0)), h)
        move = np.where(np.isfinite(move), move, 0.0)
        t1 = np.clip(t0 + move, t_lo, t_hi)
        f1 = _log_f(t1[:, None], rows, target)[1][:, 0]
        up = f1 > f0
        t0, f0 = np.where(up, t1, t0), np.where(up, f1, f0)
        floor_h = 1e3 * np.finfo(float).eps * np.maximum(1.0, np.abs(t0))
        settled = ~up & (np.abs(width - h) <= 0.05 * h)
        h = np.clip(np.where(up | settled, width, 0.5 * h), floor_h, t_hi - t_lo)
        if np.all(settled | (~up & (h <= floor_h))):
            break
    return t0, h, np.maximum(f0, np.max(f, axis=1))


def _first_panels(target: Target, law, t_lo, t_hi, t0, width):
    """The first panels' ends, as flat arrays ``idx``, ``a``, ``b``."""
    idx, a, b = [], [], []
    bps = law.breakpoints
    for i in range(len(t_lo)):
        cuts = [np.linspace(t_lo[i], t_hi[i], int(np.ceil(1.0 / _SPREAD)) + 1)]
        inside = bps[bps > target.floor[i]] - target.floor[i]
        cuts.append(np.log(inside))
        cuts.append(t0[i] + width[i] * np.concatenate([-_ABOUT_MODE, _ABOUT_MODE]))
        c = np.unique(np.clip(np.concatenate(cuts), t_lo[i], t_hi[i]))
        c = c[np.concatenate([[True], np.diff(c) > 1e-12 * np.maximum(1.0, np.abs(c[1:]))])]
        idx.append(np.full(len(c) - 1, i))
        a.append(c[:-1])
        b.append(c[1:])
    return np.concatenate(idx), np.concatenate(a), np.concatenate(b)


def _sums(t_a, t_b, idx, target, shift, centre):
    """Each panel's Gauss-Legendre sums (5, P) of ``1``, ``d``, ``d**2``, ``u``, ``u**2 +
    Var[v | y]`` (``d``, ``u`` the depth and ``E[v | y]`` less the problem's ``centre`` (2, B),
    against cancellation), scaled by ``e^-shift[idx]``; its nodes' depths (P, n) and log
    weights in ``y`` (P, n), and the largest ``log f`` (P,)."""
    half = 0.5 * (t_b - t_a)
    t = (0.5 * (t_a + t_b))[:, None] + half[:, None] * _X
    y, log_f, v, c = _log_f(t, idx, target)
    log_q = np.log(half)[:, None] + np.log(_W) + log_f  # the panel's terms, in t
    e = np.exp(log_q - shift[idx][:, None])
    d, u = y - centre[0, idx][:, None], v - centre[1, idx][:, None]
    sums = np.stack(
        [e.sum(1), (e * d).sum(1), (e * d * d).sum(1), (e * u).sum(1), (e * (u * u + c)).sum(1)]
    )
    log_wy = np.log(half)[:, None] + np.log(_W) + t  # dy = e^t dt
    return sums, y, log_wy, np.max(log_f, axis=1)


def _halves(t_a, t_b, idx, target, shift, centre):
    m = 0.5 * (t_a + t_b)
    left = _sums(t_a, m, idx, target, shift, centre)
    right = _sums(m, t_b, idx, target, shift, centre)
    return left, right


def _moments(totals):
    """Mean (less the centre) and SD of ``y`` and ``v`` (B,) each, from summed totals (5, B)."""
    Z = totals[0]
    my, mv = totals[1] / Z, totals[3] / Z
    vy = np.maximum(totals[2] / Z - my * my, 0.0)
    vv = np.maximum(totals[4] / Z - mv * mv, 0.0)
    return Z, my, np.sqrt(vy), mv, np.sqrt(vv)


def _errors(diff, idx, totals):
    """Each panel's change (P,) of the depth's and velocity's mean and SD, in those units."""
    Z, my, sy, mv, sv = (m[idx] for m in _moments(totals))
    dmy = (diff[1] - my * diff[0]) / Z
    dvy = (diff[2] - (sy * sy + my * my) * diff[0]) / Z - 2.0 * my * dmy
    dmv = (diff[3] - mv * diff[0]) / Z
    dvv = (diff[4] - (sv * sv + mv * mv) * diff[0]) / Z - 2.0 * mv * dmv
    with np.errstate(divide="ignore", invalid="ignore"):
        ey = np.maximum(np.abs(dmy), np.abs(dvy) / (2.0 * sy))
        ev = np.maximum(np.abs(dmv), np.abs(dvv) / (2.0 * sv))
    return np.where(np.isfinite(ey), ey, np.inf), np.where(np.isfinite(ev), ev, np.inf)


def _rounding(mean, sd, offset, top):
    """The rounding of a mean and SD in units of ``eps``, as the trapezoid quadrature's:
    the mean's size, the log integrand's (``top``) and the centre's offset."""
    return np.abs(mean) + sd * (1.0 + np.abs(top)) + np.where(sd > 0, offset**2 / sd, 0.0)


def _refuse(target: Target, k: int, why: str) -> ValueError:
    return ValueError(f"{target.name(k)}: {why}")


def place(target: Target, law: DepthPrior, rtol: float) -> Placed:
    """Nodes and log weights in ``y_1`` for ``B`` problems under the prior ``law``.

    Parameters
    ----------
    target : Target
        What to integrate (:func:`of_problems` for the bank's problems).
    law : depthcore.problem.depth_prior.DepthPrior
    rtol : float
        The changes of the means and SDs of the depth and the velocity, summed over
        the panels, within ``rtol`` of each SD.

    Returns
    -------
    Placed

    Raises
    ------
    ValueError
        Where the integrand does not decay at an open end, or the panels exceed
        :data:`PANEL_BUDGET` or :data:`ROUNDS` before ``rtol``.
    """
    B = len(target.floor)
    t_lo, t_hi, lo_edge, hi_edge = _ends(target, law)
    t0, width, top = _mode(target, law, t_lo, t_hi)
    rows = np.arange(B)
    for end, edge, step in ((t_hi, hi_edge, 2.0), (t_lo, lo_edge, -5.0)):
        for _ in range(12):  # an open end moves out until the integrand is negligible there
            f_end = _log_f(end[:, None], rows, target)[1][:, 0]
            open_ = ~edge & (f_end > top - CUTOFF)
            if not np.any(open_):
                break
            end[open_] += step
        else:
            k = int(np.argmax(open_))
            raise _refuse(
                target, k, "the posterior of the depth does not decay at the prior's open end"
            )
    idx, a, b = _first_panels(target, law, t_lo, t_hi, t0, width)
    rows = np.arange(B)
    centre = np.stack([target.floor + np.exp(t0), _log_f(t0[:, None], rows, target)[2][:, 0]])
    centre[1] = np.where(np.isfinite(centre[1]), centre[1], 0.0)
    coarse = _sums(a, b, idx, target, top, centre)[0]
    for _ in range(ROUNDS):
        (left, yl, wl, fl), (right, yr, wr, fr) = _halves(a, b, idx, target, top, centre)
        high = np.full(B, -np.inf)
        np.maximum.at(high, idx, np.maximum(fl, fr))
        fine = left + right
        totals = np.zeros((5, B))
        np.add.at(totals.T, idx, fine.T)
        ey, ev = _errors(fine - coarse, idx, totals)
        err_y, err_v = np.zeros(B), np.zeros(B)
        np.add.at(err_y, idx, ey)
        np.add.at(err_v, idx, ev)
        _, my, sy, mv, sv = _moments(totals)
        # the roundoff floor, as the trapezoid quadrature's: the moments' own rounding
        eps = 64.0 * np.finfo(float).eps
        with np.errstate(divide="ignore", invalid="ignore"):
            tol_y = np.maximum(rtol * sy, eps * _rounding(centre[0] + my, sy, my, top))
            tol_v = np.maximum(rtol * sv, eps * _rounding(centre[1] + mv, sv, mv, top))
        count = np.bincount(idx, minlength=B)
        lagging = ~((err_y <= tol_y) & (err_v <= tol_v))
        if np.any(high > top + CUTOFF):
            k = int(np.argmax(high > top + CUTOFF))
            raise _refuse(
                target, k, "the depth's posterior is narrower than its quadrature can place"
            )
        if not np.any(lagging):
            break
        share = np.maximum(ey / tol_y[idx], ev / tol_v[idx])
        split = lagging[idx] & (share * count[idx] >= 1.0)
        if np.any(count + np.bincount(idx[split], minlength=B) > PANEL_BUDGET):
            k = int(np.argmax(count + np.bincount(idx[split], minlength=B) > PANEL_BUDGET))
            raise _refuse(target, k, f"the depth quadrature needs over {PANEL_BUDGET} panels")
        m = 0.5 * (a + b)
        keep = ~split
        idx = np.concatenate([idx[keep], idx[split], idx[split]])
        coarse = np.concatenate([fine[:, keep], left[:, split], right[:, split]], axis=1)
        a, b = (
            np.concatenate([a[keep], a[split], m[split]]),
            np.concatenate([b[keep], m[split], b[split]]),
        )
    else:
        k = int(np.argmax(lagging))
        raise _refuse(target, k, f"the depth quadrature did not reach rtol = {rtol:.3g}")
    y = np.concatenate([yl, yr], axis=1)
    log_w = np.concatenate([wl, wr], axis=1)
    order = np.argsort(idx, kind="stable")
    idx, y, log_w = idx[order], y[order], log_w[order]
    J = int(np.max(count)) * 2 * ORDER
    nodes = np.empty((B, J))
    weights = np.full((B, J), -np.inf)
    start = np.r_[0, np.cumsum(count)[:-1]]
    for i in range(B):
        yi = y[start[i] : start[i] + count[i]].ravel()
        order = np.argsort(yi, kind="stable")  # increasing depths
        nodes[i, : yi.size], nodes[i, yi.size :] = yi[order], yi[order[0]]
        weights[i, : yi.size] = log_w[start[i] : start[i] + count[i]].ravel()[order]
    return Placed(nodes, weights, err_y, err_v)


#: Barycentric weights of the Gauss-Legendre nodes on [-1, 1].
_BARY = 1.0 / np.array([np.prod([a - b for b in _X if b != a]) for a in _X])


def interpolant(t, values) -> Callable:
    """The polynomials through each half panel's nodes, for values at placed nodes.

    ``t`` (J,) are :func:`place`'s nodes (one problem, increasing, in ``t``), ``J`` a
    multiple of :data:`ORDER`: each run of ``ORDER`` is one half panel's Gauss-Legendre
    nodes, from which its ends are recovered. ``values`` (K, J). Returns a function of
    ``t`` (n,) giving (K, n): at each point the degree ``ORDER - 1`` polynomial of the
    half panel holding it (barycentric form), the end ones continued beyond the nodes.
    """
    groups = t.reshape(-1, ORDER)
    half = (groups[:, -1] - groups[:, 0]) / (_X[-1] - _X[0])
    mid = groups[:, 0] - half * _X[0]
    starts = mid - half
    per_group = values.reshape(values.shape[0], -1, ORDER)

    def evaluate(tt):
        g = np.clip(np.searchsorted(starts, tt, side="right") - 1, 0, len(starts) - 1)
        d = (tt - mid[g])[:, None] / half[g][:, None] - _X
        hit = d == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(hit, 0.0, _BARY / d)
        c = np.where(np.any(hit, axis=1)[:, None], hit.astype(float), c)
        v = per_group[:, g, :]  # (K, n, ORDER)
        return np.einsum("kno,no->kn", v, c) / c.sum(1)

    return evaluate
