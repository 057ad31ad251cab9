"""The depth quadrature: the log-depth trapezoid rule with its error estimate.

Recommended import: ``from depthcore.exact import quadrature``.

The marginals of :mod:`depthcore.exact.optimal` (Eqs. (13)-(16)) and
:mod:`depthcore.exact.bank` are integrals over the depth of an integrand (a
:class:`Problem`). Each interval ``(-inf, 0)``, ``(0, 1)``, ``(1, 2)``, ``(2, inf)``
between the poles is sent to the real line (``t = log(y - 2)`` on ``y > 2``) and
integrated by the trapezoid rule about the integrand's mode
(:mod:`depthcore.exact.modes`), halving the step until the moments agree
(:func:`halving_error`). A CDF over such a range is
:func:`depthcore.exact.cdf.gauss_legendre_cdf`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from depthcore.exact import modes, tracks
from depthcore.problem.frames import depth_floor

#: Log integrand cut off this far below the maximum (e^-60 ~ 1e-26).
CUTOFF = 60.0
#: Most nodes of one interval for one problem.
NODE_BUDGET = 4097


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

    @property
    def floor(self) -> np.ndarray:
        """The depth at frame 1 below which the point reaches the camera, (B,), 0 receding.

        :func:`depthcore.problem.frames.depth_floor` of the steps. The bank's integrand
        takes the quadrature's depth ``offsets[..., 2]`` as the distance above it, the
        depth where the point comes nearest the camera (:mod:`depthcore.exact.posterior`).
        """
        if self.steps is None:
            return np.zeros(len(self.mu))
        return depth_floor(tracks.elapsed(self.steps, self.mu.shape[1]))

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


#: Index pairs (i, j) of the second moments accumulated, in (x, y, v) order.
_SECOND = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
_FIRST_INDEX, _SECOND_INDEX = (np.array(ix) for ix in zip(*_SECOND, strict=True))
#: Where each entry of a 3 x 3 covariance (row-major) sits in :data:`_SECOND` order.
_SYMMETRIC = np.array([0, 3, 5, 3, 1, 4, 5, 4, 2])


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


def integrate(pb: Problem, intervals, rtol: float):
    """Integrate the depth marginal of a batch by the trapezoid rule; moments, errors, grids.

    Each problem's step is halved until its means and SDs change by at most ``rtol``
    of the SD (or :func:`_roundoff`'s floor), independently of the other rows.

    Parameters
    ----------
    pb : Problem
    intervals : tuple of int
        See :func:`depthcore.exact.modes.mapped_nodes`; ``(3,)`` for ``y > 2``.
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
    top, found, centre = modes.ranges(pb, intervals)
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
            values = modes.node_values(i, u, frame, pb)
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
    j_lo = modes.clip(np.where(active, first - 1, 0), 0, n - 1)
    j_hi = modes.clip(np.where(active, last + 1, 0), 0, n - 1)
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
    """The node values of :func:`modes.node_values` at a slice of the node axis."""
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
