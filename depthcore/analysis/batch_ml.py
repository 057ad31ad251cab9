"""The batch maximum-likelihood estimate: the state that best explains every bearing, no prior.

Recommended import: ``from depthcore.analysis import batch_ml``.

The filters are Bayesian: each carries a prior. The baseline that the
bearings-only tracking literature sets beside them [ristic2004]_ uses the
bearings alone: the state ``s_N = (x_N, y_N, v)`` at the last frame ``N``
that maximises the likelihood of all ``N`` bearings under the constant
velocity of Eq. (1) (the paper's model, ``q = 0``), that is, that minimises

    f(s_N) = sum_k ((x_k / y_k - mu_k) / rho_k)**2,
    x_k = x_N - t_k v,   y_k = y_N - t_k,

over the frames ``k`` with a bearing (Eq. (5) weighted by each frame's noise;
``t_k`` the depth travelled from frame ``k`` to frame ``N``,
:mod:`depthcore.problem.frames`: uneven steps, ``rho`` per frame and missing
bearings as the filters take them). With three bearings and three unknowns
the minimum is 0, at the noise-free solution of Eq. (7) where that lies in
front of the camera.

**The search.** At a fixed depth the bearings are linear in ``(x_N, v)``, so
the least misfit over them is a weighted linear least-squares problem
(the profile of :func:`depthcore.problem.model.profile_misfit`). The depth at
frame 1, ``y_1 = y_N - t_1``, is searched on :data:`GRID` points spaced
evenly in ``log((y_1 - f) / r)`` between :data:`DEPTH_LIMITS`, ``f`` the depth at
frame 1 below which the point reaches the camera
(:func:`depthcore.problem.frames.depth_floor`, 0 while it recedes) and ``r`` the
range of depths the track spans (``t_1`` while it recedes); from the best,
Levenberg-Marquardt iterations (Gauss-Newton steps damped by Marquardt's
diagonal, [nocedal2006]_ ch. 10) run on ``(x_N, log y_1, v)``, so the depth
stays positive at every frame, every track of a batch at once, until a step
moves the estimate by less than :data:`STEP_TOLERANCE` of its SD.

**No interior maximum.** Where the likelihood rises all the way to a limit,
or is flat up to it, it has no maximum within the depths searched: the
bearings bend the way no point in front of the camera explains, or not at
all. Noise does that to many tracks of little parallax; at zero parallax,
where the bearings say nothing of the depth, to more than half the tracks
of ten frames. The estimate is then the best state at the limiting depth,
a limit of the search and no estimate of the depth, and ``at_limit`` says
so: a study scores the estimate only where it is false, and counts the
others apart (:func:`depthcore.studies.trials.interior`).

**The covariance** is the inverse of the Fisher information at the estimate,

    J = sum_k g_k g_k^T / rho_k**2,   g_k = (1 / y_k, -x_k / y_k**2, -t_k / y_k),

``g_k`` the gradient of the bearing at frame ``k`` with respect to ``s_N``
(Eqs. (20)-(22) for the paper's triple), the asymptotic covariance of the
maximum-likelihood estimate; at the truth it is the Cramér-Rao bound of
:mod:`depthcore.analysis.bound` without a prior. It is computed from the
singular values of the whitened gradients, their columns scaled to unit
length, so that its condition is that of the gradients, not of ``J``.

References
----------
.. [ristic2004] B. Ristic, S. Arulampalam and N. Gordon, *Beyond the Kalman
   Filter: Particle Filters for Tracking Applications*, Artech House, 2004,
   chapter 6 (bearings-only tracking).
.. [nocedal2006] J. Nocedal and S. J. Wright, *Numerical Optimization*, 2nd
   ed., Springer, 2006, chapter 10 (least-squares problems).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.problem import checks, frames

#: The depth at frame 1 searched, above the floor, as multiples of the range the track spans.
DEPTH_LIMITS = (1e-6, 1e6)

#: Points of the search in log depth before the iterations.
GRID = 121

#: The most Levenberg-Marquardt iterations.
MAX_ITERATIONS = 200

#: A step smaller than this many SDs of the estimate (in the Fisher metric) ends the search.
STEP_TOLERANCE = 1e-10

#: The damping beyond which a track's search stops, as no step lowers its misfit.
MAX_DAMPING = 1e16


class BatchML(NamedTuple):
    """The batch maximum-likelihood estimates of a batch of tracks.

    Attributes
    ----------
    mean : ndarray, shape (..., 3)
        The estimate of the state at the last frame, ``(x_N, y_N, v)``.
    cov : ndarray, shape (..., 3, 3)
        The inverse Fisher information at ``mean``.
    misfit : ndarray, shape (...)
        ``f`` at ``mean``: the sum of squared standardised residuals.
    at_limit : ndarray of bool, shape (...)
        Whether the likelihood has no interior maximum: the depth lies at one
        of :data:`DEPTH_LIMITS`, and ``mean`` is the search's limit, not an
        estimate (the module docstring).
    iterations : int
        The Levenberg-Marquardt iterations run.
    """

    mean: np.ndarray
    cov: np.ndarray
    misfit: np.ndarray
    at_limit: np.ndarray
    iterations: int


class _Tracks(NamedTuple):
    """Flattened checked tracks: weights ``1 / rho`` (0 where missing), bearings (0 where
    missing), ``t`` the depth travelled to frame N, ``elapsed`` from frame 1, ``span`` = t_1,
    ``floor`` (:func:`depthcore.problem.frames.depth_floor`) and ``reach``, the range of
    depths the track spans (``t_1`` while the point recedes)."""

    w: np.ndarray
    mu: np.ndarray
    t: np.ndarray
    elapsed: np.ndarray
    span: np.ndarray
    floor: np.ndarray
    reach: np.ndarray

    def depth1(self, z):
        """The depth at frame 1 at ``z = log((y_1 - floor) / reach)``, (B,)."""
        return self.floor + self.reach * np.exp(z)


def _tracks(f: frames.Frames) -> _Tracks:
    n = f.mu.shape[-1]
    elapsed = f.elapsed.reshape(-1, n)
    span = elapsed[:, -1]
    present = f.present.reshape(-1, n)
    w = np.where(present, 1.0 / f.rho.reshape(-1, n), 0.0)
    # each track's weights scaled by their largest (the estimate does not change)
    w = w / np.max(w, axis=1, keepdims=True)
    mu = np.where(present, f.mu.reshape(-1, n), 0.0)
    floor = frames.depth_floor(elapsed)
    reach = np.max(elapsed, axis=1) - np.min(elapsed, axis=1)
    return _Tracks(w, mu, span[:, None] - elapsed, elapsed, span, floor, reach)


def _profile(tr: _Tracks, depth1: np.ndarray) -> tuple:
    """``(x_N, v, misfit)`` at depths ``depth1`` (B,) at frame 1: weighted least squares."""
    y = depth1[:, None] + tr.elapsed
    a = tr.w / y
    b = -tr.w * tr.t / y
    r = tr.w * tr.mu
    saa, sab, sbb = np.sum(a * a, 1), np.sum(a * b, 1), np.sum(b * b, 1)
    sar, sbr = np.sum(a * r, 1), np.sum(b * r, 1)
    det = saa * sbb - sab * sab
    x = (sbb * sar - sab * sbr) / det
    v = (saa * sbr - sab * sar) / det
    misfit = np.sum((a * x[:, None] + b * v[:, None] - r) ** 2, 1)
    return x, v, misfit


def _residuals(tr: _Tracks, p: np.ndarray):
    """Standardised residuals (B, N) and their Jacobian (B, N, 3) in ``p = (x_N, z, v)``,
    ``z = log((y_1 - floor) / reach)`` (:class:`_Tracks`)."""
    depth1 = tr.depth1(p[:, 1])
    y = depth1[:, None] + tr.elapsed
    x = p[:, :1] - tr.t * p[:, 2:]
    r = tr.w * (x / y - tr.mu)
    jac = np.stack(
        [tr.w / y, -tr.w * x / y**2 * (depth1 - tr.floor)[:, None], -tr.w * tr.t / y],
        axis=-1,
    )
    return r, jac


def _search(tr: _Tracks, limits, scale: np.ndarray) -> tuple:
    """The grid of log depths, then Levenberg-Marquardt: ``(p, at_limit, iterations)``."""
    z_lo, z_hi = np.log(limits[0]), np.log(limits[1])
    grid = np.linspace(z_lo, z_hi, GRID)
    best = np.full(len(tr.span), np.inf)
    p = np.zeros((len(tr.span), 3))
    for z in grid:
        x, v, misfit = _profile(tr, tr.depth1(z))
        better = misfit < best
        best = np.where(better, misfit, best)
        p[better] = np.stack([x, np.full_like(x, z), v], axis=-1)[better]
    damping = np.full(len(p), 1e-3)
    active = np.ones(len(p), dtype=bool)
    r, jac = _residuals(tr, p)
    cost = np.sum(r * r, 1)
    iterations = 0
    while np.any(active) and iterations < MAX_ITERATIONS:
        iterations += 1
        H = np.einsum("bni,bnj->bij", jac, jac)
        g = np.einsum("bni,bn->bi", jac, r)
        d = np.sqrt(np.diagonal(H, axis1=1, axis2=2))
        Hs = H / (d[:, :, None] * d[:, None, :]) + damping[:, None, None] * np.eye(3)
        step = -np.linalg.solve(Hs, (g / d)[..., None])[..., 0] / d
        trial = p + np.where(active[:, None], step, 0.0)
        trial[:, 1] = np.clip(trial[:, 1], z_lo, z_hi)
        r_new, jac_new = _residuals(tr, trial)
        cost_new = np.sum(r_new * r_new, 1)
        accept = active & (cost_new <= cost)
        moved = np.einsum("bi,bij,bj->b", trial - p, H, trial - p)
        p = np.where(accept[:, None], trial, p)
        r = np.where(accept[:, None], r_new, r)
        jac = np.where(accept[:, None, None], jac_new, jac)
        cost = np.where(accept, cost_new, cost)
        damping = np.where(accept, np.maximum(damping / 10.0, 1e-12), damping * 10.0)
        # the step in SDs of the estimate: the weights were scaled by 1 / scale
        done = (accept & (moved <= (STEP_TOLERANCE / scale) ** 2)) | (damping > MAX_DAMPING)
        active &= ~done
    at_limit = (p[:, 1] <= z_lo) | (p[:, 1] >= z_hi)
    if np.any(at_limit):  # the best state at the limiting depth
        edge = _Tracks(*(a[at_limit] for a in tr))
        x, v, _ = _profile(edge, edge.depth1(p[at_limit, 1]))
        p[at_limit, 0], p[at_limit, 2] = x, v
    return p, at_limit, iterations


def _gradients(state: np.ndarray, t: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Whitened gradients ``w_k g_k`` (B, N, 3) of the bearings at ``state`` (B, 3)."""
    y = state[:, 1:2] - t
    x = state[:, :1] - t * state[:, 2:]
    return np.stack([w / y, -w * x / y**2, -w * t / y], axis=-1)


def _inverse_information(A: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``(A^T A)^{-1} / scale**2`` (B, 3, 3) from the SVD of ``A`` with unit columns."""
    norms = np.sqrt(np.sum(A * A, axis=1))  # (B, 3)
    _, s, vt = np.linalg.svd(A / norms[:, None, :], full_matrices=False)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        root = vt.transpose(0, 2, 1) / s[:, None, :]  # V S^-1
        scaled = root / (norms[:, :, None] * scale[:, None, None])
        return scaled @ scaled.transpose(0, 2, 1)


def _frame_inputs(state, rho, steps, present):
    """Checked inputs of :func:`information`: states (B, 3), ``t`` and weights (B, N), batch."""
    state = checks.finite_array(state, "state")
    rho = checks.as_float(rho, "rho")
    if state.ndim < 1 or state.shape[-1] != 3:
        raise ValueError(f"state must have shape (..., 3), got shape {state.shape}")
    if rho.ndim < 1 or rho.shape[-1] < 3:
        raise ValueError(f"rho must have shape (..., N), one per frame, N >= 3, got {rho.shape}")
    n = rho.shape[-1]
    present = np.ones(n, bool) if present is None else np.asarray(present, dtype=bool)
    if steps is None:
        steps = np.ones(n - 1)
    steps = checks.finite_array(steps, "steps")
    if steps.ndim < 1 or steps.shape[-1] != n - 1 or np.any(steps == 0):
        raise ValueError(
            f"steps must be nonzero (signed; negative: approaching), shape (..., {n - 1}), "
            f"got shape {steps.shape}"
        )
    try:
        batch = np.broadcast_shapes(
            state.shape[:-1], rho.shape[:-1], present.shape[:-1], steps.shape[:-1]
        )
    except ValueError:
        raise ValueError(
            f"state, rho, present and steps must broadcast over the tracks, got {state.shape}, "
            f"{rho.shape}, {present.shape}, {steps.shape}"
        ) from None
    present = np.broadcast_to(present, batch + (n,)).reshape(-1, n)
    rho = np.broadcast_to(rho, batch + (n,)).reshape(-1, n)
    if not np.all((rho > 0) | ~present):
        raise ValueError("rho must be positive at every frame with a bearing")
    steps = np.broadcast_to(steps, batch + (n - 1,)).reshape(-1, n - 1)
    t = np.concatenate([np.cumsum(steps[:, ::-1], axis=1)[:, ::-1], np.zeros((len(steps), 1))], 1)
    s = np.broadcast_to(state, batch + (3,)).reshape(-1, 3)
    if not np.all(s[:, 1] - np.max(t, axis=1) > 0):
        raise ValueError("state must put the point in front of the camera at every frame")
    w = np.where(present, 1.0 / np.where(present, rho, 1.0), 0.0)
    return s, t, w, batch


def information(state, rho, steps=None, present=None) -> np.ndarray:
    """The Fisher information of the bearings about the state at the last frame.

    ``J = sum_k g_k g_k^T / rho_k**2`` over the frames with a bearing (the
    module docstring), with no prior and ``q = 0``.

    Parameters
    ----------
    state : array_like, shape (..., 3)
        The state ``(x_N, y_N, v)`` at the last frame, in front of the camera
        at every frame.
    rho : array_like, shape (..., N)
        The noise SD per frame, > 0 (any value where ``present`` is false).
    steps : array_like, shape (N - 1,) or (..., N - 1), optional
        The depth's change between frames; ``None``: ones.
    present : array_like of bool, shape (N,) or (..., N), optional
        Where a bearing was taken; ``None``: every frame.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    s, t, w, batch = _frame_inputs(state, rho, steps, present)
    A = _gradients(s, t, w)
    return np.einsum("bni,bnj->bij", A, A).reshape(batch + (3, 3))


def covariance(state, rho, steps=None, present=None) -> np.ndarray:
    """The inverse of :func:`information` (same arguments), shape (..., 3, 3).

    At the true state, the Cramér-Rao bound on an unbiased estimate of the
    state at the last frame from the bearings alone; at the estimate, the
    estimate's covariance. Computed from the SVD of the whitened gradients
    (the module docstring), each track's weights scaled by their largest.
    """
    s, t, w, batch = _frame_inputs(state, rho, steps, present)
    scale = np.max(w, axis=1)
    cov = _inverse_information(_gradients(s, t, w / scale[:, None]), scale)
    return cov.reshape(batch + (3, 3))


def estimate(mu, rho, steps=None, process_noise=0.0, depth_limits=DEPTH_LIMITS) -> BatchML:
    """The batch maximum-likelihood estimate of the state at the last frame, batched.

    Parameters
    ----------
    mu : array_like, shape (N,) or (..., N)
        Bearings, ``N >= 3``, ``NaN`` where a frame has none; at least three
        present per track, not affine in the depth travelled
        (:func:`depthcore.problem.frames.check`).
    rho : float or array_like, shape (...) or (..., N)
        The noise SD, per track or per frame.
    steps : array_like, shape (N - 1,) or (..., N - 1), optional
        The depth's change between frames; ``None``: ones.
    process_noise : float
        Must be 0: the likelihood is that of the constant-velocity motion.
    depth_limits : tuple of float
        ``(lo, hi)``, ``0 < lo < hi``: the depth at frame 1 searched, as
        multiples of the range of depths the track spans, above the depth at
        which the point reaches the camera (the module docstring).

    Returns
    -------
    BatchML
        Of the shape of ``mu`` without its last axis.

    Raises
    ------
    ValueError
        One line naming the argument: ``process_noise`` above 0, fewer than
        three bearings present (``mu``), limits out of order
        (``depth_limits``), or a covariance beyond the largest double (``rho``).
    """
    q = checks.process_noise(process_noise, "process_noise")
    if q > 0:
        raise ValueError(
            f"process_noise must be 0: the batch maximum-likelihood estimate assumes a "
            f"constant velocity, got {q:g}"
        )
    limits = checks.finite_array(depth_limits, "depth_limits")
    if limits.shape != (2,) or not 0 < limits[0] < limits[1]:
        raise ValueError(f"depth_limits must be (lo, hi) with 0 < lo < hi, got {limits.tolist()}")
    f = frames.check(mu, rho, steps)
    tr = _tracks(f)
    n = f.mu.shape[-1]
    scale = np.max(np.where(f.present, 1.0 / f.rho, 0.0).reshape(-1, n), axis=1)
    p, at_limit, iterations = _search(tr, limits, scale)
    depth_n = tr.depth1(p[:, 1]) + tr.span
    mean = np.stack([p[:, 0], depth_n, p[:, 2]], axis=-1)
    A = _gradients(mean, tr.t, tr.w)
    cov = _inverse_information(A, scale)
    if not np.all(np.isfinite(cov)):
        raise ValueError(
            "rho: the batch maximum-likelihood estimate's covariance (the inverse Fisher "
            "information) lies beyond the largest double"
        )
    r, _ = _residuals(tr, p)
    with np.errstate(over="ignore"):
        misfit = np.sum(r * r, 1) * scale**2
    batch = f.mu.shape[:-1]
    return BatchML(
        mean.reshape(batch + (3,)),
        cov.reshape(batch + (3, 3)),
        misfit.reshape(batch),
        at_limit.reshape(batch),
        iterations,
    )


def run(mu, rho, prior_mean, prior_cov, steps=None, process_noise=0.0) -> BatchML:
    """:func:`estimate` with the registry's calling convention; the prior is not used.

    ``prior_mean`` and ``prior_cov`` are the registry's common arguments,
    which the maximum-likelihood estimate, using the bearings alone, ignores.
    """
    return estimate(mu, rho, steps=steps, process_noise=process_noise)
