"""Importance sampling of the state, on the paper's problem and on ``N >= 3`` frames.

By default a Student t proposal built from all the bearings: a Monte Carlo
check of the optimal filter, not a causal filter (without process noise).

Recommended import: ``from depthcore.particles import importance``.

By default (``proposal="second_order"``, ``ess_threshold=0``) the filter is
importance sampling of the state: the particles are drawn from a multivariate
Student t distribution built on the second-order Gaussian ``p_s`` (Eq. (8)),
weighted by the prior and the three likelihoods (Eq. (4)) over the proposal's
density, and never resampled. With ``proposal="prior"`` and
``ess_threshold > 0`` it is the sampling-importance-resampling (bootstrap)
filter of Prince, section 19.5 [prince2012]_, [gordon1993]_.

N frames. Everything below holds for ``N >= 3`` bearings of the constant-velocity
model (no process noise, the model of :mod:`depthcore.exact.bank` with ``q = 0``),
with "time 3" read as frame ``N`` and ``p_s`` as its ``N``-frame
generalisation (:func:`depthcore.kalman.second_order.second_order_batch`: the
Gaussian at the minimiser ``c_N`` of the misfit of all ``N`` bearings, times
the prior). The filter is importance sampling with a proposal built from all
the bearings, not a causal filter (that is :mod:`depthcore.particles.resample_move`);
with process noise every frame's state is a new unknown and a proposal on the
state at frame 1 alone no longer covers the posterior, so the registry
(:mod:`depthcore.registry.filters`) refuses ``process_noise > 0`` for it.

The steps. The state at time 1 is drawn from a distribution ``q``, weighted by
``prior / q``, and then, for ``k = 1 .. N``: moved deterministically by ``G``
(Eq. (1)), reweighted by the likelihood of ``mu_k`` (Eq. (4)), and, if
``ess_threshold > 0``, resampled when the effective sample size falls below
``ess_threshold * N`` (:mod:`depthcore.particles.resampling`). Weights are kept as
logarithms. A particle whose depth is ``<= 0`` at any frame gets weight zero:
the point is in front of the camera, so the filter targets the optimal
posterior restricted to ``y3 > 2``, as :func:`depthcore.exact.optimal.run`
does with ``support="front"``.

The bootstrap filter. The motion is deterministic: nothing ever spreads the
particles again, so the filter can only reweight (and duplicate) the particles
it drew at time 1. With ``proposal="prior"`` they come from the paper's broad
prior, of which only a thin wedge is compatible with the bearings, so
the effective sample size collapses. (After a resampling step ``ess`` counts
the copies of a particle separately; :meth:`ParticleResult.distinct_ess`
pools them.)

The proposal (``proposal="second_order"``). The particles are drawn where the
posterior is: from a multivariate Student t distribution with ``df`` degrees
of freedom (default :data:`DEFAULT_DF`) centred on the mean of ``p_s`` at time
3, with scale matrix ``inflation**2`` (default :data:`DEFAULT_INFLATION`)
times its covariance, and pulled back to time 1 by ``G^{-2}``. The pull-back
is affine with unit Jacobian (``F^{-2}`` is unit upper triangular), so the
density of the time-1 particles is ``q`` at their image at time 3, and the
initial log weight is ``log prior - log q``. The heavy tails and the inflation
cover the parts of the optimal posterior that ``p_s`` misses (its depth
marginal is skewed and, with a broad prior, heavy-tailed).

Because ``q`` already anticipates all the measurements, the intermediate
targets are chosen to match it ([delmoral2006]_: any sequence of intermediate
distributions may be used as long as the last is the posterior): after
``mu_k`` the particles target

    pi_k(x) ~ prior(x1) prod_{j <= k} L_j(x) prod_{j > k} Lt_j(x),

where ``Lt_j(x) = exp(-(g_j . (x3 - c))**2 / (2 rho**2))`` is the likelihood
of ``mu_j`` linearised about the noise-free state ``c`` (Eq. (7)), ``g_j``
the residual gradients of Eqs. (20)-(22) -- the factors whose product with the
prior is ``p_s`` itself. (With ``N > 3`` frames the linearisation is about the
minimiser ``c_N``, where the residuals ``r_j`` do not vanish:
``Lt_j(x) = exp(-(r_j + g_j . (x_N - c_N))**2 / (2 rho**2))``, whose product
over ``j`` is the ``N``-frame ``p_s``'s likelihood factor up to a constant,
because ``sum_j r_j g_j = 0`` at the minimiser.) So the initial log weight also carries
``sum_j log Lt_j``, and step ``k`` adds ``log L_k - log Lt_k``. After ``mu_3``
every ``Lt`` has been swapped for the exact ``L`` and the weights are
``prior * L_1 L_2 L_3 / q``, the importance weights of the posterior; on the
way, the ESS after each step measures how well the particles fit.

Resampling. The default ``ess_threshold = 0`` never resamples, because the
motion is deterministic: duplicated particles are never diversified again, so
resampling cannot improve the final estimates, and it commits the particles to
the intermediate target of the step at which it fires. ``ess_threshold = 0.5``
is the usual rule.

Convergence. Without resampling the final particles are an importance sample
of the time-3 posterior ``p_o`` restricted to ``y > 2``, with weights
proportional to ``p_o / q``. ``q`` is positive everywhere, so self-normalised
weighted averages converge almost surely to the posterior expectations as
``N`` grows, and since ``q`` has polynomial tails while ``p_o`` inherits the
Gaussian tails of the prior, ``E_q[(p_o / q)**2]`` is finite and the error
falls as ``1 / sqrt(N)`` (delta method for the SDs). With resampling the
limits still hold, each resampling step being an unbiased selection
[douc2005]_. :meth:`ParticleResult.standard_errors` estimates the Monte Carlo
standard errors of the moments. They rest on many distinct particles carrying
the weight: where the distinct ESS (identical particles pooled) falls below
:data:`depthcore.particles.resampling.MIN_EFFECTIVE_DRAWS`, :meth:`ParticleResult.collapsed`
says so, and the registry reports the errors there as NaN, not as the
vanishing spread of a few particles.

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
    """The particle filter's weighted particles at time 3, for one triple.

    Built by :func:`run` (one sequence).

    Attributes
    ----------
    particles : ndarray, shape (N, 3)
        States ``(x, y, v)`` at time 3.
    log_weights : ndarray, shape (N,)
        Normalised: ``logsumexp(log_weights) == 0``; ``-inf`` is weight zero.
    ess : ndarray, shape (N,)
        Effective sample size after each measurement.
    resampled : ndarray of bool, shape (N,)
        Whether the particles were resampled before measurement ``k + 1`` (never before the first).
    ancestors : ndarray of int, shape (N,)
        The time-1 draw each particle descends from; resampling duplicates
        particles, and the motion being deterministic, duplicates stay identical.
    proposal : str
    updates : depthcore.problem.predictive.Updates
        Per frame, arrays of shape (N,): the log predictive density of the
        bearing and its two-sided tail probability under the weighted mixture
        of the particles' ``N(x_k / y_k, rho_k**2)`` (the filtering weights,
        without the look-ahead terms), NaN at a missing frame, and whether the
        gate skipped it.
    """

    def distinct_ess(self) -> float:
        """The ESS with the weights of identical particles (same ancestor) pooled.

        After resampling, ``ess`` counts ``N`` copies of one particle as ``N``;
        this counts them as one.
        """
        return float(_distinct_ess(self.ancestors, self.weights))

    def collapsed(self) -> bool:
        """Whether the weight sits on fewer than ``MIN_EFFECTIVE_DRAWS`` distinct particles.

        Then the weighted spread and :meth:`standard_errors` describe those few
        particles, not the posterior, and cannot be trusted.
        """
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
        """Monte Carlo standard errors of :meth:`moments` (delta method).

        They treat the particles as independent draws, so after resampling
        (``resampled.any()``) they understate the error.
        """
        W = self.weights
        y, v = (weighted_standard_errors(self.particles[:, INDEX[c]], W) for c in "yv")
        return ParticleMoments(float(y[0]), float(y[1]), float(v[0]), float(v[1]))

    def density(
        self, component: str, grid, method: str = "kde", bandwidth: float | None = None
    ) -> np.ndarray:
        """Weighted density estimate of one component's marginal on ``grid``.

        :func:`depthcore.particles.resampling.weighted_density` of the particles' ``component``
        (``"x"``, ``"y"`` or ``"v"``); ``method`` is ``"kde"`` or ``"histogram"``.

        Returns
        -------
        ndarray, shape (G,)
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
        Arrays of shape (B, N), as :class:`ParticleResult`'s.
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

    ``-(r0_k + g_k . (x3 - c))**2 / (2 rho_k**2)`` with ``g_k`` (B, 3) the gradient of
    the residual of ``mu_{k+1}`` at ``c`` (Eq. (8)) and ``r0_k`` (B,) the residual
    there (0 at the paper's noise-free state; ``g_k`` and ``r0_k`` are 0 at a
    missing frame, whose term is 0); ``x3`` (B, n, 3) at the last frame,
    ``rho`` (B, N) per frame, ``k`` (K,) frames from 0: returns shape (B, n, K).
    """
    d = x3 - c[:, None, :]
    r = (d @ np.swapaxes(g[:, k], -1, -2) + r0[:, None, k]) / rho[:, None, k]
    return -0.5 * r**2


#: Floats per array of one block of frames (trials x particles x frames) of the loops over
#: the frames that take several frames at once: about 16 MB.
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

    The minimiser of the misfit ``sum_k ((h_k(x) - mu_k) / rho_k)**2`` over the
    present bearings, ``h_k(x) = (x + b_k v) / (y + b_k)`` the bearing of frame
    ``k`` at the offset ``b_k <= 0`` (depth travelled) from the last frame: the
    track's form of the minimiser ``c_N`` of Eq. (5). It starts from the
    bearings' linear equations ``x + b_k v - mu_k y = mu_k b_k`` (the noise-free
    solution, Eq. (7), in least squares) and takes Gauss-Newton steps, halved
    until the misfit falls with the point in front of the camera at frame 1.
    ``g_k`` is the residual's gradient (Eqs. (20)-(22) at the offsets ``b_k``)
    and ``r0_k`` the residual at ``c``; both 0 at a missing frame.
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

    The prior moved to the last frame (``x_N = F(T) x_1 + (0, T, 0)``, ``T`` the
    depth travelled, :func:`depthcore.problem.frames.transition`) times the
    present bearings' likelihoods linearised about :func:`_track_centre`'s
    ``c``, Eq. (8): information ``(F P F^T)^{-1} + sum_k g_k g_k^T / rho_k**2``.

    Returns
    -------
    mean : ndarray, shape (B, 3)
    cov : ndarray, shape (B, 3, 3)
    look_ahead : tuple
        ``(c, g, r0)`` of :func:`_linearised_log_likelihood`.
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

    The proposal sees only the present bearings: on the paper's frames the
    second-order Gaussian of :func:`depthcore.kalman.second_order.second_order_batch`,
    otherwise :func:`_track_proposal`. The weight is zero where the depth at
    frame 1 is not positive (the front support).
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
    """Refuse a trial none of whose particles (axis 1 of ``log_w``) has a positive weight.

    ``log_w`` (B, N, K) after the frames ``k`` (K,) (``N`` may be 1: the largest of
    each trial's log weights); names the first frame and trial.
    """
    dead = ~np.any(np.isfinite(log_w), axis=1)  # (B, K)
    if np.any(dead):
        j = int(np.argmax(np.any(dead, axis=0)))
        raise RuntimeError(
            f"every particle of trial {int(np.argmax(dead[:, j]))} has zero weight after "
            f"mu_{int(k[j]) + 1} (behind the camera); increase n_particles or use "
            "proposal='second_order'"
        )


def _predictive(mu_k, log_w, states, rho_k, present_k):
    """The bearings' log predictive densities and tails (B, K) under the weighted particles.

    ``log_w`` (B, N, K) the filtering log weights before each frame, ``states``
    (B, N, K, 3) at the frames, ``mu_k``, ``rho_k``, ``present_k`` (B, K): the
    mixture of ``N(x / y, rho_k**2)`` (:func:`depthcore.problem.predictive.mixture`);
    NaN at a missing frame.
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

    Without resampling every particle moves by Eq. (1) alone: its state at
    frame ``k`` is ``x_1`` moved by the depth travelled to frame ``k``, and its
    log weight after ``mu_k`` is the initial one plus, over the present frames
    ``j <= k``, the log likelihood (4) of ``mu_j`` less the look-ahead term of
    frame ``j`` (the terms the initial weight holds, so that at the last frame
    they cancel). These sums are taken a block of frames at a time (one frame
    at a time with a gate, whose decisions depend on the frames before), the
    ESS after each frame from them (it does not depend on the normalisation),
    and the weights normalised once, at the end: the per-frame loop of
    :func:`run`, which normalises and moves the particles at every frame,
    gives the same to rounding. A skipped bearing (gated) swaps its look-ahead
    term for nothing.

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
    # the depth grows with the frames: a particle in front at frame 1 stays in front
    front = not np.all(x1[..., 1] > 0)
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
        log_l = np.where(present[:, None, k], log_l, 0.0)
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
        ``N >= 1`` particles per trial. Memory grows like ``B * N``: about
        ``200 B N`` bytes at the peak.
    rng : numpy.random.Generator
        The only source of randomness.
    proposal : {"second_order", "prior"}
        Where the time-1 particles come from (see the module docstring); the
        second-order proposal is built from the present bearings alone.
    resampler : {"systematic", "multinomial", "residual"}
    ess_threshold : float
        Resample before a move when the ESS is below ``ess_threshold * N``; in
        [0, 1]. Default 0, never (see the module docstring); 0.5 is the usual
        SIR rule.
    df : float
        Degrees of freedom of the t proposal, > 0 (``inf`` for a Gaussian).
    inflation : float
        Factor on the second-order SDs in the proposal's scale matrix, > 0.

    Returns
    -------
    ParticleResult or ParticleBatch
        For one sequence its :class:`ParticleResult`, for a batch the
        :class:`ParticleBatch`.

    Notes
    -----
    A missing bearing (``NaN``) is predicted through: the particles move and
    keep their weights. With a gate, a bearing whose predictive tail under the
    filtering weights falls below it is skipped likewise. The second-order
    proposal is drawn before any bearing is weighed, so with it a gate is
    applied by refitting: the proposal is rebuilt without the bearings skipped
    so far, from the same state of ``rng``, until no further bearing falls
    below the gate; the answer is then the one for those bearings set to
    ``NaN``, draw for draw.
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
        log_w = log_w + np.where(use[:, None], log_l, 0.0)
        if look_ahead is not None:
            log_w = (
                log_w - _linearised_log_likelihood(to_end, *look_ahead, rho, np.array([k]))[..., 0]
            )
        _dead(log_w[..., None], np.array([k]))
        log_w = normalise(log_w)
        ess[:, k] = effective_sample_size(log_w)
    updates = predictive.Updates(log_pred, tail, gated)
    return ParticleBatch(x, log_w, ess, resampled, np.array(ancestors), proposal, updates)
