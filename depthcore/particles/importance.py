"""Importance sampling of the state, on the paper's problem and on ``N >= 3`` frames.

By default a Student t proposal built from all the bearings: a Monte Carlo
check of the optimal filter, not a causal filter (without process noise).

Recommended import: ``from depthcore.particles import importance``.

With ``proposal="prior"`` and ``ess_threshold > 0`` it is the
sampling-importance-resampling (bootstrap) filter of Prince, section 19.5
[prince2012]_, [gordon1993]_; the motion being deterministic, its particles are
never spread again and its ESS collapses on the paper's broad prior.

``N >= 3`` frames of the constant-velocity model (:mod:`depthcore.exact.bank`
with ``q = 0``; "time 3" is frame ``N``, ``p_s`` the ``N``-frame Gaussian of
:func:`depthcore.kalman.second_order.second_order_batch`). With process noise a
proposal at frame 1 no longer covers the posterior, and the registry refuses it;
the causal filter is :mod:`depthcore.particles.resample_move`.

The state at time 1 is drawn from ``q``, weighted by ``prior / q``, then for
``k = 1 .. N`` moved by ``G`` (Eq. (1)), reweighted by the likelihood of ``mu_k``
(Eq. (4)) and, if ``ess_threshold > 0``, resampled when the ESS falls below
``ess_threshold * N`` (:mod:`depthcore.particles.resampling`). A particle with
depth ``<= 0`` at any frame has weight zero: the target is the optimal posterior
on ``y3 > 2`` (:func:`depthcore.exact.optimal.run`, ``support="front"``).

The proposal (``"second_order"``) is a Student t with ``df`` degrees of freedom
(:data:`DEFAULT_DF`) about the mean of ``p_s`` at time 3, scale ``inflation**2``
(:data:`DEFAULT_INFLATION`) times its covariance, pulled back by ``G^{-2}`` (unit
Jacobian); its heavy tails cover what ``p_s`` misses. As ``q`` anticipates all the
bearings, the intermediate targets match it ([delmoral2006]_): after ``mu_k``

    pi_k(x) ~ prior(x1) prod_{j <= k} L_j(x) prod_{j > k} Lt_j(x),

where ``Lt_j(x) = exp(-(r_j + g_j . (x3 - c))**2 / (2 rho**2))`` is the likelihood
of ``mu_j`` linearised about ``c`` (Eq. (7); the minimiser ``c_N`` for ``N > 3``,
where ``sum_j r_j g_j = 0``), ``g_j`` the gradients of Eqs. (20)-(22): their
product with the prior is ``p_s``. The initial log weight carries ``sum_j log
Lt_j`` and step ``k`` adds ``log L_k - log Lt_k``, so the final weights are
``prior * L_1 L_2 L_3 / q``.

The default ``ess_threshold = 0`` never resamples: duplicates are never
diversified, so resampling cannot help the final estimates (0.5 is the usual rule).
The final particles are an importance sample of ``p_o`` on ``y > 2``; ``q`` has
polynomial tails and ``p_o`` the prior's Gaussian ones, so ``E_q[(p_o / q)**2]`` is
finite and the error falls as ``1 / sqrt(N)``; resampling is an unbiased selection
[douc2005]_. :meth:`ParticleResult.standard_errors` estimates the errors;
:meth:`ParticleResult.collapsed` flags a distinct ESS below
:data:`depthcore.particles.resampling.MIN_EFFECTIVE_DRAWS`, where the registry
reports them as NaN.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.5 (the condensation algorithm).
.. [gordon1993] N. J. Gordon, D. J. Salmond and A. F. M. Smith, "Novel
   approach to nonlinear/non-Gaussian Bayesian state estimation", IEE
   Proceedings F 140(2), 1993 (the bootstrap filter).
.. [delmoral2006] P. Del Moral, A. Doucet and A. Jasra, "Sequential Monte Carlo
   samplers", J. R. Statist. Soc. B 68(3), 2006, section 3 (incremental
   weights between arbitrary intermediate targets).
.. [douc2005] R. Douc, O. Cappe and E. Moulines, "Comparison of resampling
   schemes for particle filtering", ISPA 2005 (multinomial, residual,
   stratified and systematic resampling).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from depthcore.kalman.second_order import minimiser, second_order_batch
from depthcore.particles.resampling import (
    MIN_EFFECTIVE_DRAWS,
    RESAMPLERS,
    check_rng,
    effective_sample_size,
    track_problem,
    weighted_density,
    weighted_moments,
    weighted_standard_errors,
)
from depthcore.problem import checks, frames, model, predictive, signature
from depthcore.problem.gaussian import INDEX, Gaussian, gaussian_logpdf, student_t
from depthcore.problem.weights import normalise

__all__ = [
    "DEFAULT_DF",
    "DEFAULT_INFLATION",
    "PROPOSALS",
    "ParticleBatch",
    "ParticleMoments",
    "ParticleResult",
    "WeightedParticles",
    "run",
]

PROPOSALS = ("second_order", "prior")
#: Default degrees of freedom of the Student t proposal.
DEFAULT_DF = 1.0
#: Default factor on the second-order SDs in the proposal's scale matrix.
DEFAULT_INFLATION = 1.5


# --- results ---------------------------------------------------------------------------


class ParticleMoments(NamedTuple):
    """Weighted means and SDs of the depth ``y`` and velocity ``v`` at time 3.

    Floats for one filter, arrays of shape (B,) for a batch; the field names
    are those of :class:`depthcore.exact.mixture.Moments`.
    """

    depth_mean: np.ndarray
    depth_sd: np.ndarray
    velocity_mean: np.ndarray
    velocity_sd: np.ndarray


def _read_only(a) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


def _freeze(result):
    """Store read-only copies of a result's arrays."""
    for name in ("particles", "log_weights", "ess", "resampled", "ancestors"):
        object.__setattr__(result, name, _read_only(getattr(result, name)))
    if result.updates is not None:
        object.__setattr__(result, "updates", predictive.Updates(*map(_read_only, result.updates)))


def _distinct_ess(ancestors, W) -> np.ndarray:
    """``1 / sum_a (sum_{i: ancestor i = a} W_i)**2`` along the last axis."""
    N = W.shape[-1]
    rows = np.arange(W.size // N).reshape(W.shape[:-1] + (1,))
    pooled = np.bincount((ancestors + N * rows).ravel(), weights=W.ravel(), minlength=W.size)
    return 1.0 / np.sum(pooled.reshape(W.shape) ** 2, axis=-1)


@dataclass(frozen=True)
class WeightedParticles:
    """The fields of the particle filter's results, read-only (:class:`ParticleResult` of one
    sequence, :class:`ParticleBatch` of ``B``): particles, log weights, ESS, resampling,
    ancestors and the proposal."""

    particles: np.ndarray
    log_weights: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    ancestors: np.ndarray
    proposal: str
    updates: predictive.Updates | None = None

    def __post_init__(self):
        _freeze(self)


@dataclass(frozen=True)
class ParticleResult(WeightedParticles):
    """The particle filter's weighted particles at time 3, for one sequence (:func:`run`).

    Attributes
    ----------
    particles : ndarray, shape (N, 3)
        States ``(x, y, v)`` at time 3.
    log_weights : ndarray, shape (N,)
        Normalised: ``logsumexp(log_weights) == 0``; ``-inf`` is weight zero.
    ess : ndarray, shape (N,)
        Effective sample size after each measurement.
    resampled : ndarray of bool, shape (N,)
        Whether the particles were resampled before measurement ``k + 1``.
    ancestors : ndarray of int, shape (N,)
        The time-1 draw each particle descends from.
    proposal : str
    updates : depthcore.problem.predictive.Updates
        Per frame (N,), under the particles' ``N(x_k / y_k, rho_k**2)`` with the
        filtering weights; NaN at a missing frame.
    """

    def distinct_ess(self) -> float:
        """The ESS with the weights of identical particles (same ancestor) pooled."""
        return float(_distinct_ess(self.ancestors, self.weights))

    def collapsed(self) -> bool:
        """Whether the weight sits on fewer than ``MIN_EFFECTIVE_DRAWS`` distinct particles."""
        return bool(self.distinct_ess() < MIN_EFFECTIVE_DRAWS)

    @property
    def n_particles(self) -> int:
        """``N``."""
        return self.log_weights.shape[-1]

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights, shape (N,)."""
        return np.exp(self.log_weights)

    def marginal(self, component: str) -> tuple[float, float]:
        """Weighted mean and SD of one component (``"x"``, ``"y"`` or ``"v"``) at time 3."""
        mean, sd = weighted_moments(self.particles[:, _component(component)], self.weights)
        return float(mean), float(sd)

    def moments(self) -> ParticleMoments:
        """Weighted means and SDs of the depth and velocity (floats)."""
        return ParticleMoments(*self.marginal("y"), *self.marginal("v"))

    def standard_errors(self) -> ParticleMoments:
        """Monte Carlo standard errors of :meth:`moments` (delta method; low after resampling)."""
        W = self.weights
        y, v = (weighted_standard_errors(self.particles[:, INDEX[c]], W) for c in "yv")
        return ParticleMoments(float(y[0]), float(y[1]), float(v[0]), float(v[1]))

    def density(
        self, component: str, grid, method: str = "kde", bandwidth: float | None = None
    ) -> np.ndarray:
        """Weighted density estimate of one component's marginal on ``grid``.

        :func:`depthcore.particles.resampling.weighted_density` of ``component``
        (``"x"``, ``"y"`` or ``"v"``); returns shape (G,).
        """
        x = self.particles[:, _component(component)]
        return weighted_density(x, self.weights, grid, method, bandwidth)


def _component(component: str) -> int:
    if component not in INDEX:
        raise ValueError(f"component must be one of {tuple(INDEX)}, got {component!r}")
    return INDEX[component]


@dataclass(frozen=True)
class ParticleBatch(WeightedParticles):
    """The particle filter's results for ``B`` triples at once; built by :func:`run`.

    Attributes
    ----------
    particles : ndarray, shape (B, N, 3)
    log_weights : ndarray, shape (B, N)
        Normalised along the last axis.
    ess : ndarray, shape (B, N)
    resampled : ndarray of bool, shape (B, N)
    ancestors : ndarray of int, shape (B, N)
    proposal : str
    updates : depthcore.problem.predictive.Updates
        (B, N) each.
    """

    def distinct_ess(self) -> np.ndarray:
        """:meth:`ParticleResult.distinct_ess` for each trial, shape (B,)."""
        return _distinct_ess(self.ancestors, np.exp(self.log_weights))

    def collapsed(self) -> np.ndarray:
        """:meth:`ParticleResult.collapsed` for each trial, shape (B,)."""
        return self.distinct_ess() < MIN_EFFECTIVE_DRAWS

    def __len__(self) -> int:
        return self.log_weights.shape[0]

    def trial(self, i: int) -> ParticleResult:
        """The result of trial ``i``."""
        return ParticleResult(
            self.particles[i],
            self.log_weights[i],
            self.ess[i],
            self.resampled[i],
            self.ancestors[i],
            self.proposal,
            None if self.updates is None else predictive.Updates(*(a[i] for a in self.updates)),
        )

    def moments(self) -> ParticleMoments:
        """Weighted means and SDs of the depth and velocity, arrays of shape (B,)."""
        W = np.exp(self.log_weights)
        return ParticleMoments(
            *weighted_moments(self.particles[..., 1], W),
            *weighted_moments(self.particles[..., 2], W),
        )

    def standard_errors(self) -> ParticleMoments:
        """Delta-method standard errors of :meth:`moments`, arrays of shape (B,)."""
        W = np.exp(self.log_weights)
        return ParticleMoments(
            *weighted_standard_errors(self.particles[..., 1], W),
            *weighted_standard_errors(self.particles[..., 2], W),
        )


# --- the filter ------------------------------------------------------------------------


def _degrees_of_freedom(df) -> float:
    """Check ``df``: positive, or ``inf`` for a Gaussian proposal."""
    try:
        if np.ndim(df) == 0 and np.isposinf(float(df)):
            return float("inf")
    except (TypeError, ValueError):
        pass
    return checks.positive_scalar(df, "df")


def _linearised_log_likelihood(x3, c, g, r0, rho, k) -> np.ndarray:
    """``log Lt_k``: the log likelihoods of ``mu_{k+1}`` linearised about ``c``, at states ``x3``.

    ``g`` (B, N, 3), ``r0`` (B, N) (0 at a missing frame), ``x3`` (B, n, 3), ``rho``
    (B, N), ``k`` (K,) frames from 0: returns shape (B, n, K).
    """
    d = x3 - c[:, None, :]
    r = (d @ np.swapaxes(g[:, k], -1, -2) + r0[:, None, k]) / rho[:, None, k]
    return -0.5 * r**2


#: Floats per array of one block of frames (trials x particles x frames): about 16 MB.
_BLOCK_FLOATS = 2**21


def _blocks(n_frames: int, per_frame: int):
    """Consecutive frame indices (arrays) in blocks of at most ``_BLOCK_FLOATS`` floats."""
    size = max(1, min(n_frames, _BLOCK_FLOATS // max(1, per_frame)))
    return [np.arange(k, min(k + size, n_frames)) for k in range(0, n_frames, size)]


#: Gauss-Newton iterations of the proposal's centre on a track that is not the paper's frames.
_CENTRE_ITERATIONS = 50


def _bearings_at(x, back) -> np.ndarray:
    """The bearings ``(x + b v) / (y + b)`` (..., N) of last-frame states ``x`` (..., 3) at
    offsets ``back`` (..., N) from the last frame."""
    return (x[..., None, 0] + back * x[..., None, 2]) / (x[..., None, 1] + back)


def _track_centre(track: frames.Frames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The proposal's centre ``c`` (B, 3) at the last frame, with ``g`` (B, N, 3) and ``r0`` (B, N).

    The minimiser of ``sum_k ((h_k(x) - mu_k) / rho_k)**2``, ``h_k(x) = (x + b_k v) /
    (y + b_k)`` at the offset ``b_k <= 0`` from the last frame (Eq. (5)'s ``c_N``), by
    Gauss-Newton from the least-squares Eq. (7); ``g_k`` is the residual's gradient
    (Eqs. (20)-(22)), ``r0_k`` the residual.
    """
    present, mu = track.present, np.where(track.present, track.mu, 0.0)
    weight = np.where(present, 1.0 / track.rho, 0.0)
    back = track.elapsed - track.elapsed[:, -1:]
    A = np.stack([np.ones_like(mu), -mu, back], axis=-1) * weight[..., None]
    c = np.stack(
        [
            np.linalg.lstsq(a, m * b * w, rcond=None)[0]
            for a, m, b, w in zip(A, mu, back, weight, strict=True)
        ]
    )
    depth_1 = -back[:, 0]  # the last frame's depth less the first's

    def misfit(x):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(present, _bearings_at(x, back) - mu, 0.0) * weight
        return np.where(x[:, 1] > depth_1, np.sum(r**2, axis=-1), np.inf)

    behind = ~(c[:, 1] > depth_1)
    c[behind, 1] = depth_1[behind] + 1.0  # a start in front; Gauss-Newton moves it
    for _ in range(_CENTRE_ITERATIONS):
        g, r = _gradients(c, back, present), np.where(present, _bearings_at(c, back) - mu, 0.0)
        J, res = g * weight[..., None], r * weight
        step = np.stack(
            [np.linalg.lstsq(j, -e, rcond=None)[0] for j, e in zip(J, res, strict=True)]
        )
        now, scale = misfit(c), np.ones(len(c))
        for _ in range(30):
            trial = c + scale[:, None] * step
            better = misfit(trial) < now
            if np.all(better | (scale < 1e-8)):
                break
            scale = np.where(better, scale, scale / 2)
        c = np.where(
            (misfit(c + scale[:, None] * step) < now)[:, None], c + scale[:, None] * step, c
        )
    g = _gradients(c, back, present)
    return c, g, np.where(present, _bearings_at(c, back) - mu, 0.0)


def _gradients(c, back, present) -> np.ndarray:
    """Gradients (B, N, 3) of the bearings ``h_k`` at last-frame states ``c`` (B, 3); 0 where
    a frame is missing."""
    depth = c[:, None, 1] + back
    x = c[:, None, 0] + back * c[:, None, 2]
    g = np.stack([1.0 / depth, -x / depth**2, back / depth], axis=-1)
    return np.where(present[..., None], g, 0.0)


def _track_proposal(track, prior_mean, prior_cov):
    """The Gaussian ``p_s`` at the last frame of a track, its centre and look-ahead terms.

    Eq. (8): information ``(F P F^T)^{-1} + sum_k g_k g_k^T / rho_k**2`` with ``F``
    :func:`depthcore.problem.frames.transition`'s. Returns mean (B, 3), cov (B, 3, 3)
    and ``(c, g, r0)``.
    """
    c, g, r0 = _track_centre(track)
    T = track.elapsed[:, -1]
    F = frames.transition(T)
    moved_mean = model.G(prior_mean, T)
    moved_cov = F @ prior_cov @ np.swapaxes(F, -1, -2)
    prior_info = np.linalg.inv(moved_cov)
    w = np.where(track.present, 1.0 / track.rho**2, 0.0)
    info = prior_info + np.einsum("bk,bki,bkj->bij", w, g, g)
    cov = np.linalg.inv(info)
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    pull = np.einsum("bij,bj->bi", prior_info, moved_mean - c) - np.einsum(
        "bk,bki,bk->bi", w, g, r0
    )
    return c + np.einsum("bij,bj->bi", cov, pull), cov, (c, g, r0)


def _initial(track, prior_mean, prior_cov, N, rng, proposal, df, inflation):
    """Time-1 particles (B, N, 3), their log weights (B, N) and the look-ahead terms.

    The proposal is :func:`_track_proposal`'s, or on the paper's frames
    :func:`depthcore.kalman.second_order.second_order_batch`'s.
    """
    mu = track.mu
    if proposal == "prior":
        L = np.linalg.cholesky(prior_cov)
        x1 = prior_mean[:, None, :] + rng.standard_normal((len(mu), N, 3)) @ L.T
        return x1, np.where(x1[..., 1] > 0, 0.0, -np.inf), None
    n_frames = mu.shape[1]
    rho = track.rho
    if track.regular:
        mean_s, cov_s = second_order_batch(mu, track.row_rho, prior_mean, prior_cov)
        if n_frames == 3:
            c = model.noise_free_states(mu)
            r0 = np.zeros(mu.shape)  # f(c) = 0, Eq. (7)
        else:
            c = minimiser(mu)
            r0 = model.residuals(c, mu)
        g = model.residual_gradients(c, n_frames)  # (B, N, 3): rows g_k, Eqs. (20)-(22)
        look_ahead = (c, g, r0)
    else:
        mean_s, cov_s, look_ahead = _track_proposal(track, prior_mean, prior_cov)
    x3, log_q = student_t(mean_s, inflation**2 * cov_s, df, N, rng)
    log_lt = sum(
        np.sum(_linearised_log_likelihood(x3, *look_ahead, rho, k), axis=-1)
        for k in _blocks(n_frames, x3.shape[0] * N)
    )
    x1 = model.G(x3, -track.elapsed[:, -1:] if not track.regular else 1 - n_frames)
    log_prior = gaussian_logpdf(x1, prior_mean[:, None, :], prior_cov)
    log_w = log_prior - log_q + log_lt
    return x1, np.where(x1[..., 1] > 0, log_w, -np.inf), look_ahead


def _dead(log_w, k) -> None:
    """Refuse a trial none of whose particles has a positive weight, ``log_w`` (B, N, K)."""
    dead = ~np.any(np.isfinite(log_w), axis=1)  # (B, K)
    if np.any(dead):
        j = int(np.argmax(np.any(dead, axis=0)))
        raise ValueError(
            f"n_particles: every particle of trial {int(np.argmax(dead[:, j]))} has zero "
            f"weight after mu_{int(k[j]) + 1} (behind the camera); increase n_particles or use "
            "proposal='second_order'"
        )


def _predictive(mu_k, log_w, states, rho_k, present_k):
    """The bearings' log predictive densities and tails (B, K) under the weighted particles.

    ``log_w`` (B, N, K), ``states`` (B, N, K, 3), ``mu_k``, ``rho_k``, ``present_k``
    (B, K); :func:`depthcore.problem.predictive.mixture`.
    """
    alive = np.isfinite(log_w) & (states[..., 1] > 0)
    safe = np.where(alive[..., None], states, 1.0)
    means = np.swapaxes(model.project(safe), 1, 2)  # (B, K, N)
    weights = np.swapaxes(np.where(alive, log_w, -np.inf), 1, 2)
    var = (rho_k**2)[..., None]
    log_p, tail = predictive.mixture(np.where(present_k, mu_k, 0.0), weights, means, var)
    return np.where(present_k, log_p, np.nan), np.where(present_k, tail, np.nan)


def _without_resampling(x1, log_w, look_ahead, track, gate, skip):
    """The weights after every frame of a run that never resamples, several frames at once.

    Each log weight after ``mu_k`` is the initial one plus, over present frames
    ``j <= k``, ``log L_j - log Lt_j``, summed a block of frames at a time (one with a
    gate) and normalised once: the per-frame loop's result to rounding.

    Returns
    -------
    particles : ndarray, shape (B, N, 3)
        At the last frame.
    log_w : ndarray, shape (B, N)
        Normalised.
    ess : ndarray, shape (B, n_frames)
    updates : depthcore.problem.predictive.Updates
    """
    B, N = log_w.shape
    mu, present, rho, t = track.mu, track.present, track.rho, track.elapsed
    n_frames = mu.shape[1]
    ess = np.empty((B, n_frames))
    log_pred, tail = np.full((B, n_frames), np.nan), np.full((B, n_frames), np.nan)
    gated = np.zeros((B, n_frames), dtype=bool)
    regular = track.regular
    x3 = model.G(x1, n_frames - 1 if regular else t[:, -1:])
    # a particle in front of the camera where the point comes nearest stays in front
    front = not np.all(x1[..., 1] > track.floor.reshape(-1)[:, None])
    filtering = log_w
    if look_ahead is not None:  # the filtering weights: without the look-ahead terms
        filtering = log_w - sum(
            np.sum(_linearised_log_likelihood(x3, *look_ahead, rho, k), axis=-1)
            for k in _blocks(n_frames, B * N)
        )
    blocks = _blocks(n_frames, 4 * B * N) if gate is None else np.arange(n_frames)[:, None]
    for k in blocks:
        states = model.G(x1[:, :, None, :], k if regular else t[:, None, k])  # (B, N, K, 3)
        with np.errstate(invalid="ignore"):
            log_l = model.log_likelihood(
                np.where(present[:, None, k], mu[:, None, k], 0.0), states, rho[:, None, k], front
            )
        behind = front & (states[..., 1] <= 0)  # no weight, with or without a bearing
        log_l = np.where(present[:, None, k], log_l, np.where(behind, -np.inf, 0.0))
        before = filtering[..., None] + np.concatenate(
            [np.zeros((B, N, 1)), np.cumsum(log_l[..., :-1], axis=-1)], axis=-1
        )
        log_pred[:, k], tail[:, k] = _predictive(mu[:, k], before, states, rho[:, k], present[:, k])
        gated[:, k] = predictive.skipped(tail[:, k], present[:, k], gate) | skip[:, k]
        log_l = np.where(gated[:, None, k], 0.0, log_l)
        filtering = filtering + np.sum(log_l, axis=-1)
        increments = log_l
        if look_ahead is not None:
            increments = increments - _linearised_log_likelihood(x3, *look_ahead, rho, k)
        block = log_w[..., None] + np.cumsum(increments, axis=-1)  # (B, N, K)
        top = np.max(block, axis=1, keepdims=True)
        _dead(top, k)  # no particle of positive weight: the largest weight is 0
        w = np.exp(block - top)
        ess[:, k] = np.sum(w, axis=1) ** 2 / np.sum(w**2, axis=1)
        log_w = block[..., -1]
    return x3, normalise(log_w), ess, predictive.Updates(log_pred, tail, gated)


def _resample(x, log_w, ancestors, need, N, rng, resampler):
    """Resample the rows ``need`` of ``x`` (B, N, 3), ``log_w`` and ``ancestors`` (B, N)."""
    if not np.any(need):
        return x, log_w, ancestors
    idx = resampler(np.exp(log_w[need]), rng, N)
    x, log_w, ancestors = x.copy(), log_w.copy(), ancestors.copy()
    x[need] = np.take_along_axis(x[need], idx[..., None], axis=1)
    ancestors[need] = np.take_along_axis(ancestors[need], idx, axis=1)
    log_w[need] = -np.log(N)
    return x, log_w, ancestors


def _one_track(mu, rho, prior_mean, prior_cov, steps):
    """The single sequence's checks, as they have always been made on the paper's frames."""
    if steps is None and np.ndim(rho) == 0 and not np.any(np.isnan(np.asarray(mu, dtype=float))):
        mu = checks.finite_array(mu, "mu")
        if mu.shape == (3,):
            model.measurements(mu)
        Gaussian.prior(prior_mean, prior_cov)
        checks.positive_scalar(rho, "rho")
    track = frames.check(mu, rho, steps)
    Gaussian.prior(prior_mean, prior_cov)
    return track


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    n_particles: int,
    rng: np.random.Generator,
    proposal: str = "second_order",
    resampler: str = "systematic",
    ess_threshold: float = 0.0,
    df: float = DEFAULT_DF,
    inflation: float = DEFAULT_INFLATION,
    steps=None,
    gate=None,
) -> ParticleBatch:
    """The particle filter for one sequence or ``B`` of them at once, vectorised over trials.

    {parameters}
    n_particles : int
        ``N >= 1`` per trial; about ``200 B N`` bytes at the peak.
    rng : numpy.random.Generator
    proposal : {"second_order", "prior"}
        See the module docstring.
    resampler : {"systematic", "multinomial", "residual"}
    ess_threshold : float
        In [0, 1]; see the module docstring.
    df : float
        Degrees of freedom of the t proposal, > 0 (``inf`` for a Gaussian).
    inflation : float
        Factor on the second-order SDs in the proposal's scale matrix, > 0.

    Returns
    -------
    ParticleResult or ParticleBatch

    Notes
    -----
    A missing (``NaN``) or gated bearing is predicted through. With the second-order
    proposal a gate refits it without the bearings skipped, from the same ``rng``
    state, until none more is skipped.
    """
    if np.ndim(mu) == 1:
        _one_track(mu, rho, prior_mean, prior_cov, steps)
        options = (n_particles, rng, proposal, resampler, ess_threshold, df, inflation)
        rho = np.asarray(rho)[None] if np.ndim(rho) == 1 else rho
        steps = None if steps is None else np.asarray(steps)[None]
        mu = np.asarray(mu, dtype=float)[None]
        return run(mu, rho, prior_mean, prior_cov, *options, steps=steps, gate=gate).trial(0)
    prior_cov = checks.covariance(prior_cov, "prior_cov", 3)
    track, prior_mean, _ = track_problem(mu, rho, prior_mean, prior_cov, steps, triples=True)
    if track.mu.ndim != 2:
        raise ValueError(f"mu must have shape (B, N), got shape {track.mu.shape}")
    N = checks.count(n_particles, "n_particles")
    check_rng(rng)
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    if resampler not in RESAMPLERS:
        raise ValueError(f"resampler must be one of {tuple(RESAMPLERS)}, got {resampler!r}")
    threshold = float(checks.finite_array(ess_threshold, "ess_threshold"))
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"ess_threshold must lie in [0, 1], got {threshold}")
    df = _degrees_of_freedom(df)
    inflation = checks.positive_scalar(inflation, "inflation")
    gate = predictive.gate(gate)
    options = (prior_mean, prior_cov, N, proposal, RESAMPLERS[resampler], threshold, df, inflation)
    skip = np.zeros(track.mu.shape, dtype=bool)
    if gate is None or proposal == "prior":
        return _filter(track, skip, gate, rng, *options)
    for _ in range(track.mu.shape[1]):  # refit the proposal without the skipped bearings
        draws = copy.deepcopy(rng)
        result = _filter(track, skip, gate, draws, *options)
        if np.array_equal(result.updates.gated, skip):
            break
        skip = skip | result.updates.gated
    rng.bit_generator.state = draws.bit_generator.state
    return result


def _filter(track, skip, gate, rng, prior_mean, prior_cov, N, proposal, resampler, threshold, *t):
    """:func:`run` on checked inputs; ``skip`` (B, N): bearings left out of the proposal and
    the weights (reported as gated, with their predictive)."""
    B, n_frames = track.mu.shape
    fitted = track
    if np.any(skip):
        fitted = frames.Frames(
            np.where(skip, np.nan, track.mu), track.present & ~skip, track.rho, track.steps
        )
    x, log_w, look_ahead = _initial(fitted, prior_mean, prior_cov, N, rng, proposal, *t)
    ancestors = np.broadcast_to(np.arange(N), (B, N))
    resampled = np.zeros((B, n_frames), dtype=bool)
    if threshold == 0.0:  # never resamples: no per-frame normalisation or moves needed
        x, log_w, ess, updates = _without_resampling(x, log_w, look_ahead, track, gate, skip)
        return ParticleBatch(x, log_w, ess, resampled, np.array(ancestors), proposal, updates)
    mu, present, rho, t = track.mu, track.present, track.rho, track.elapsed
    ess = np.zeros((B, n_frames))
    log_pred, tail = np.full((B, n_frames), np.nan), np.full((B, n_frames), np.nan)
    gated = np.zeros((B, n_frames), dtype=bool)
    for k in range(n_frames):
        if k > 0:
            resampled[:, k] = ess[:, k - 1] < threshold * N
            x, log_w, ancestors = _resample(x, log_w, ancestors, resampled[:, k], N, rng, resampler)
            x = model.G(x) if track.regular else model.G(x, track.steps[:, k - 1, None])  # Eq. (1)
        filtering, to_end = log_w, None
        if look_ahead is not None:  # the filtering weights: without the look-ahead terms
            to_end = model.G(x, n_frames - 1 - k if track.regular else t[:, -1:] - t[:, k, None])
            ahead = _linearised_log_likelihood(to_end, *look_ahead, rho, np.arange(k, n_frames))
            filtering = log_w - np.sum(ahead, axis=-1)
        log_pred[:, k], tail[:, k] = (
            a[:, 0]
            for a in _predictive(
                mu[:, k, None],
                filtering[..., None],
                x[:, :, None],
                rho[:, k, None],
                present[:, k, None],
            )
        )
        gated[:, k] = predictive.skipped(tail[:, k], present[:, k], gate) | skip[:, k]
        use = present[:, k] & ~gated[:, k]
        with np.errstate(invalid="ignore"):
            log_l = model.log_likelihood(
                np.where(use, mu[:, k], 0.0)[:, None], x, rho[:, k, None], front=True
            )
        log_w = log_w + np.where(use[:, None], log_l, np.where(x[..., 1] > 0, 0.0, -np.inf))
        if look_ahead is not None:
            log_w = (
                log_w - _linearised_log_likelihood(to_end, *look_ahead, rho, np.array([k]))[..., 0]
            )
        _dead(log_w[..., None], np.array([k]))
        log_w = normalise(log_w)
        ess[:, k] = effective_sample_size(log_w)
    updates = predictive.Updates(log_pred, tail, gated)
    return ParticleBatch(x, log_w, ess, resampled, np.array(ancestors), proposal, updates)
