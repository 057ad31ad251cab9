"""A causal particle filter on the paper's problem: bootstrap with resample-move.

Recommended import: ``from depthcore.particles import resample_move``.

The textbook's particle filter (Prince, section 19.5 [prince2012]_; the
bootstrap filter of [gordon1993]_) sees the bearings one at a time and uses
nothing else: the time-1 state is drawn from the prior, and after each bearing
``mu_k`` the particles are reweighted by its likelihood, Eq. (4). The point's
motion, Eq. (1), is deterministic, so a filter that only reweights and
duplicates particles can never place a particle where none was drawn: after
``mu_1`` the prior ``N(m, 1000 I)`` leaves a handful of particles on the thin
wedge of states whose bearing is ``mu_1``, and the estimate after ``mu_3`` is
whichever of them fits best.

The resample-move algorithm of [gilks2001]_ adds what the motion lacks: after
resampling at step ``k`` every particle takes ``moves`` Metropolis steps
(random walk, Gaussian increments with covariance ``(2.38**2 / 3)`` times the
weighted covariance of the particles before resampling [roberts1997]_) that
leave the current filtering distribution invariant,

    pi_k(x_1) ~ N(x_1; m, P) [y_1 > 0] prod_{j <= k} p(mu_j | G^{j-1} x_1),

so duplicated particles spread out again over ``pi_k``, the posterior of the
static ``x_1`` given the first ``k`` bearings (no process noise: the registry
refuses it); the state at frame ``k`` is ``G^{k-1} x_1``. The filter is
causal, and the point is in front of the camera at every frame (``y_1 > 0``,
:func:`depthcore.exact.optimal.run`'s ``support="front"``).

Resampling happens when the ESS falls below ``ess_threshold * N`` (default
``0.5``, the usual rule [kong1994]_), with systematic resampling by default
([douc2005]_ compares the schemes; all share one signature).

Monte Carlo errors. After resampling and moving, the particles are correlated
and one cloud's spread does not measure the error of its estimates.
:func:`replicated` runs ``R`` independent filters on the same bearings (rows of
one batch, drawn from the one generator) and pools them: its moments are the
replicas' average, its errors the Student-t-widened standard error of that
average from their spread, and it flags a collapse
(:func:`depthcore.particles.resampling.replica_errors`): on Figure 2 the ESS after
``mu_3`` falls to a few particles, and with a few hundred particles every
replica settles on a narrow, wrong piece of the posterior (depth means near 40
for an exact 6.5, SDs near 0), which the flag reports and the error (NaN)
does not hide.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.5.
.. [gordon1993] N. J. Gordon, D. J. Salmond and A. F. M. Smith, "Novel
   approach to nonlinear/non-Gaussian Bayesian state estimation", IEE
   Proceedings F 140(2), 1993.
.. [gilks2001] W. R. Gilks and C. Berzuini, "Following a moving target: Monte
   Carlo inference for dynamic Bayesian models", J. R. Statist. Soc. B 63(1),
   2001.
.. [roberts1997] G. O. Roberts, A. Gelman and W. R. Gilks, "Weak convergence
   and optimal scaling of random walk Metropolis algorithms", Ann. Appl.
   Probab. 7(1), 1997.
.. [kong1994] A. Kong, J. S. Liu and W. H. Wong, "Sequential imputations and
   Bayesian missing data problems", J. Am. Statist. Assoc. 89(425), 1994.
.. [douc2005] R. Douc, O. Cappe and E. Moulines, "Comparison of resampling
   schemes for particle filtering", ISPA 2005.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from depthcore.particles.resampling import (
    RESAMPLERS,
    check_rng,
    effective_sample_size,
    metropolis,
    replica_errors,
    state_moments,
    track_problem,
    weighted_density,
    weighted_mean_and_cov,
)
from depthcore.problem import checks, frames, model, predictive, signature
from depthcore.problem.gaussian import INDEX, Gaussian
from depthcore.problem.weights import normalise

#: Random-walk scale for a three-dimensional target [roberts1997]_.
_RW_SCALE = 2.38 / np.sqrt(3.0)
#: Independent replicas of the filter, for its Monte Carlo errors (:func:`replicated`).
REPLICAS = 4


@dataclass(frozen=True)
class ResampleMoveBatch:
    """Weighted particles at the last frame for ``B`` trials.

    Attributes
    ----------
    particles : ndarray, shape (B, N, 3)
        States ``(x, y, v)`` at frame ``K``, the frame of the last bearing.
    log_weights : ndarray, shape (B, N)
        Normalised log weights.
    ess : ndarray, shape (B, K)
        Effective sample size after reweighting by ``mu_k``, before any
        resampling at that step.
    resampled : ndarray of bool, shape (B, K)
        Whether step ``k`` resampled and moved the particles.
    acceptance : ndarray, shape (B, K)
        Mean Metropolis acceptance rate of the moves at step ``k`` (NaN where
        the step did not move).
    updates : depthcore.problem.predictive.Updates or None
        Arrays of shape (B, K): each bearing's log predictive density and
        two-sided tail probability under the weighted mixture of the particles'
        ``N(x_k / y_k, rho_k**2)`` before it was seen (NaN at a missing
        frame), and whether the gate skipped it.
    """

    particles: np.ndarray
    log_weights: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    acceptance: np.ndarray
    updates: predictive.Updates | None = None

    def moments(self) -> dict:
        """Weighted depth and velocity means and SDs at the last frame, each of shape (B,)."""
        return state_moments(self.particles, self.log_weights)

    def density(
        self, component: str, grid, method: str = "kde", bandwidth: float | None = None
    ) -> np.ndarray:
        """Weighted density estimate of one component's marginal on ``grid``, for one trial.

        :func:`depthcore.particles.resampling.weighted_density` of the particles'
        ``component`` (``"x"``, ``"y"`` or ``"v"``) at the last frame; the
        batch must hold one trial (as :func:`run` returns for a batch of one sequence).

        Returns
        -------
        ndarray, shape (G,)
        """
        if component not in INDEX:
            raise ValueError(f"component must be one of {tuple(INDEX)}, got {component!r}")
        if self.particles.shape[0] != 1:
            raise ValueError(
                f"density needs a batch of one trial, got {self.particles.shape[0]} trials"
            )
        x = self.particles[0, :, INDEX[component]]
        return weighted_density(x, np.exp(self.log_weights[0]), grid, method, bandwidth)


@dataclass(frozen=True)
class Replicated:
    """``R`` independent resample-move filters on each of ``B`` sequences of bearings.

    Attributes
    ----------
    runs : ResampleMoveBatch
        The ``B R`` filters as one batch, row ``b R + r`` the ``r``-th replica
        of trial ``b``.
    replicas : int
        ``R``.
    """

    runs: ResampleMoveBatch
    replicas: int

    @property
    def particles(self) -> np.ndarray:
        """The replicas' particles pooled, shape (B, R N, 3)."""
        p = self.runs.particles
        return p.reshape(p.shape[0] // self.replicas, -1, 3)

    @property
    def log_weights(self) -> np.ndarray:
        """Normalised log weights of the pool (each replica's over ``R``), shape (B, R N)."""
        lw = self.runs.log_weights - np.log(self.replicas)
        return lw.reshape(lw.shape[0] // self.replicas, -1)

    @property
    def updates(self) -> predictive.Updates:
        """Per frame, shape (B, K), the pool's log predictive density (the log of the
        replicas' average predictive density, the pooled mixture's), the replicas'
        average tail probability, and whether every replica's gate skipped the bearing
        (each replica gates on its own predictive)."""
        from scipy.special import logsumexp

        u = self.runs.updates
        R = self.replicas
        log_p, tail, gated = (a.reshape(-1, R, a.shape[-1]) for a in u)
        return predictive.Updates(
            logsumexp(log_p, axis=1) - np.log(R), np.mean(tail, axis=1), np.all(gated, axis=1)
        )

    def replica_moments(self) -> dict:
        """Each replica's depth and velocity means and SDs, shape (B, R)."""
        return {k: v.reshape(-1, self.replicas) for k, v in self.runs.moments().items()}

    def moments(self) -> dict:
        """Depth and velocity means and SDs of the pool, shape (B,)."""
        return state_moments(self.particles, self.log_weights)

    def errors(self) -> tuple[dict, np.ndarray]:
        """Monte Carlo errors of :meth:`moments` and the collapse flag, shape (B,).

        :func:`depthcore.particles.resampling.replica_errors` of each moment over the
        replicas (the pool's mean is the replicas' average; its variance their
        average variance plus the spread of their means, at most a tenth of it
        where they have not collapsed). ``collapsed`` is true where either the
        depth or the velocity has collapsed; the errors are NaN there.

        Returns
        -------
        errors : dict
            ``{"depth_mean", "depth_sd", "velocity_mean", "velocity_sd"}``.
        collapsed : ndarray of bool, shape (B,)
        """
        m = self.replica_moments()
        errors, collapsed = {}, np.zeros(m["depth_mean"].shape[0], dtype=bool)
        for name in ("depth", "velocity"):
            sd = m[f"{name}_sd"]
            for moment in ("mean", "sd"):
                e, c = replica_errors(m[f"{name}_{moment}"], sd)
                errors[f"{name}_{moment}"] = e
                collapsed |= c
        errors = {k: np.where(collapsed, np.nan, v) for k, v in errors.items()}
        return errors, collapsed

    def density(
        self, component: str, grid, method: str = "kde", bandwidth: float | None = None
    ) -> np.ndarray:
        """:meth:`ResampleMoveBatch.density` of the pool, for one trial."""
        if self.particles.shape[0] != 1:
            raise ValueError(
                f"density needs a batch of one trial, got {self.particles.shape[0]} trials"
            )
        pool = ResampleMoveBatch(
            self.particles,
            self.log_weights,
            self.runs.ess,
            self.runs.resampled,
            self.runs.acceptance,
        )
        return pool.density(component, grid, method, bandwidth)


def _log_likelihood(mu_k, x1, k, rho) -> np.ndarray:
    """Eq. (4) for bearing ``mu_k`` (B,) of the states ``x1`` (B, N, 3) moved by ``k``.

    ``k`` is the depth travelled since the first frame: a number of unit steps
    (``mu_1`` has ``k = 0``) or one per trial, shape (B, 1). ``rho`` (B,) is the
    bearing's noise SD. A missing bearing (``NaN``) adds nothing (0). States
    at or behind the camera at this frame, ``y_1 + k <= 0``, get ``-inf``
    (a missing bearing too): the point is in front of the camera at every frame.
    """
    xk = model.G(x1, k)
    inside = xk[..., 1] > 0
    xk = np.where(inside[..., None], xk, 1.0)
    present = ~np.isnan(mu_k)
    if np.all(present):
        log_l = model.log_likelihood(mu_k[:, None], xk, rho[:, None])
    else:
        log_l = model.log_likelihood(np.where(present, mu_k, 0.0)[:, None], xk, rho[:, None])
        log_l = np.where(present[:, None], log_l, 0.0)
    return np.where(inside, log_l, -np.inf)


def log_target(x1, mu, rho, prior_mean, prior_chol, elapsed=None) -> np.ndarray:
    """``log pi_k(x_1)`` up to a constant: the prior, the front support and ``k`` likelihoods.

    Parameters
    ----------
    x1 : ndarray, shape (B, N, 3)
        Time-1 states.
    mu : ndarray, shape (B, k)
        The bearings seen so far, ``NaN`` where a frame has none (or its
        bearing was skipped by the gate).
    rho : ndarray, shape (B,) or (B, k)
        Noise SD per trial, or per trial and frame.
    prior_mean : ndarray, shape (B, 3)
    prior_chol : ndarray, shape (3, 3)
        Lower Cholesky factor of the prior covariance.
    elapsed : ndarray, shape (B, k), optional
        Depth travelled from frame 1 to each frame; ``None``: unit steps.

    Returns
    -------
    ndarray, shape (B, N)
    """
    d = (x1 - prior_mean[:, None, :]).reshape(-1, 3).T
    z = np.linalg.solve(prior_chol, d).T.reshape(x1.shape)
    total = -0.5 * np.sum(z**2, axis=-1)
    for k in range(mu.shape[1]):
        rho_k = rho if rho.ndim == 1 else rho[:, k]
        moved = k if elapsed is None else elapsed[:, k, None]
        total = total + _log_likelihood(mu[:, k], x1, moved, rho_k)
    return total


def _predictive(mu_k, log_w, x1, moved, rho_k):
    """Log predictive density and tail (B,) of ``mu_k`` under the weighted particles.

    The mixture of ``N(x / y, rho_k**2)`` over the states ``x1`` (B, N, 3) moved
    by ``moved`` with the normalised ``log_w`` (B, N), particles behind the
    camera left out (:func:`depthcore.problem.predictive.mixture`); NaN where
    ``mu_k`` is.
    """
    inside = x1[..., 1] > 0
    means = model.project(model.G(np.where(inside[..., None], x1, 1.0), moved))
    present = ~np.isnan(mu_k)
    log_p, tail = predictive.mixture(
        np.where(present, mu_k, 0.0), np.where(inside, log_w, -np.inf), means, (rho_k**2)[:, None]
    )
    return np.where(present, log_p, np.nan), np.where(present, tail, np.nan)


def _increment_chol(x1, W, prior_chol) -> np.ndarray:
    """Cholesky factors (B, 3, 3) of the weighted covariance of ``x1`` (B, N, 3) under ``W`` (B, N).

    A collapsed cloud (one distinct particle) has no spread: ``1e-12`` times
    the prior covariance is added so the chain can still move.
    """
    _, cov = weighted_mean_and_cov(x1, W)
    return np.linalg.cholesky(cov + 1e-12 * (prior_chol @ prior_chol.T))


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    n_particles,
    rng,
    moves=20,
    ess_threshold=0.5,
    resampler="systematic",
    steps=None,
    gate=None,
) -> ResampleMoveBatch:
    """The bootstrap filter with resample-move for ``B`` sequences of bearings, vectorised.

    A missing bearing (``NaN``) adds nothing to the weights or to the moves'
    target; the point moves on by the step (``x += s v``, ``y += s``). A
    bearing whose predictive tail probability is below ``gate`` is skipped
    likewise.

    {parameters}
    n_particles : int
        ``N >= 2`` particles per trial; memory grows like ``B * N``.
    rng : numpy.random.Generator
        The only source of randomness.
    moves : int
        Metropolis steps per particle after each resampling, ``>= 0``
        (``0`` is the plain bootstrap filter).
    ess_threshold : float
        Resample and move at step ``k`` when the ESS after ``mu_k`` is below
        ``ess_threshold * N``; in [0, 1].
    resampler : {"systematic", "multinomial", "residual"}

    Returns
    -------
    ResampleMoveBatch
    """
    track, _, _ = track_problem(mu, rho, prior_mean, prior_cov, steps)
    mu, rho, prior_mean, prior_cov = model.batch_problem(
        np.where(track.present, track.mu, 0.0),
        track.rho[..., 0],
        prior_mean,
        prior_cov,
        triples=False,
    )
    mu = track.mu
    if mu.ndim != 2 or mu.shape[0] < 1:
        raise ValueError(f"mu must have shape (B, K) with B, K >= 1, got shape {mu.shape}")
    if prior_cov.shape != (3, 3):
        raise ValueError(f"prior_cov must have shape (3, 3), got shape {prior_cov.shape}")
    B, K = mu.shape
    regular = track.regular
    # on the paper's frames the per-trial rho and unit steps, as the filter has always used
    rho = np.broadcast_to(track.row_rho, (B,)) if regular else np.array(track.rho)
    elapsed = None if regular else track.elapsed
    prior_mean = np.broadcast_to(prior_mean, (B, 3))
    prior_chol = np.linalg.cholesky(prior_cov)
    if (
        isinstance(n_particles, bool)
        or not isinstance(n_particles, (int, np.integer))
        or n_particles < 2
    ):
        raise ValueError(f"n_particles must be an integer >= 2, got {n_particles!r}")
    N = int(n_particles)
    check_rng(rng)
    if isinstance(moves, bool) or not isinstance(moves, (int, np.integer)) or moves < 0:
        raise ValueError(f"moves must be an integer >= 0, got {moves!r}")
    threshold = float(checks.finite_array(ess_threshold, "ess_threshold"))
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"ess_threshold must lie in [0, 1], got {threshold}")
    if resampler not in RESAMPLERS:
        raise ValueError(f"resampler must be one of {tuple(RESAMPLERS)}, got {resampler!r}")
    gate = predictive.gate(gate)

    x1 = prior_mean[:, None, :] + rng.standard_normal((B, N, 3)) @ prior_chol.T
    log_w = np.zeros((B, N))
    ess = np.zeros((B, K))
    resampled = np.zeros((B, K), dtype=bool)
    acceptance = np.full((B, K), np.nan)
    log_pred, tail = np.full((B, K), np.nan), np.full((B, K), np.nan)
    gated = np.zeros((B, K), dtype=bool)
    used = np.array(mu)  # the bearings the weights hold: NaN where missing or gated
    for k in range(K):
        moved = k if regular else elapsed[:, k, None]
        rho_k = rho if regular else rho[:, k]
        log_pred[:, k], tail[:, k] = _predictive(mu[:, k], normalise(log_w), x1, moved, rho_k)
        gated[:, k] = predictive.skipped(tail[:, k], track.present[:, k], gate)
        used[gated[:, k], k] = np.nan
        log_w = log_w + _log_likelihood(used[:, k], x1, moved, rho_k)
        dead = ~np.any(np.isfinite(log_w), axis=-1)
        if np.any(dead):
            raise ValueError(
                f"n_particles is too small: every particle of trial {int(np.argmax(dead))} "
                f"lies behind the camera after mu_{k + 1}"
            )
        log_w = normalise(log_w)
        ess[:, k] = effective_sample_size(log_w)
        need = ess[:, k] < threshold * N
        if not np.any(need):
            continue
        resampled[:, k] = need
        x1, log_w, acceptance[need, k] = _resample_move(
            x1,
            log_w,
            need,
            used[:, : k + 1],
            rho if regular else rho[:, : k + 1],
            prior_mean,
            prior_chol,
            moves,
            rng,
            RESAMPLERS[resampler],
            None if regular else elapsed[:, : k + 1],
        )
    last = model.G(x1, K - 1 if regular else elapsed[:, -1:])
    updates = predictive.Updates(log_pred, tail, gated)
    return ResampleMoveBatch(last, log_w, ess, resampled, acceptance, updates)


def _resample_move(
    x1, log_w, need, mu, rho, prior_mean, prior_chol, moves, rng, resampler, elapsed=None
):
    """Resample the trials ``need`` (B,) and move their particles.

    Returns ``x1, log_w, acceptance``.
    """
    W = np.exp(log_w[need])
    sub = x1[need]
    chol = _increment_chol(sub, W, prior_chol)
    idx = resampler(W, rng)
    sub = np.take_along_axis(sub, idx[..., None], axis=1)
    args = (mu[need], rho[need], prior_mean[need], prior_chol)
    args = args if elapsed is None else args + (elapsed[need],)
    sub, _, _, acceptance = metropolis(
        sub,
        log_target(sub, *args),
        lambda x, eps: x + _RW_SCALE * np.einsum("bij,bnj->bni", chol, eps),
        lambda proposal: (log_target(proposal, *args), ()),
        moves,
        rng,
    )
    x1, log_w = x1.copy(), log_w.copy()
    x1[need] = sub
    log_w[need] = -np.log(x1.shape[1])
    return x1, log_w, acceptance


def replicated(
    mu,
    rho,
    prior_mean,
    prior_cov,
    n_particles,
    rng,
    replicas=REPLICAS,
    steps=None,
    gate=None,
    **options,
) -> Replicated:
    """``replicas`` independent runs of :func:`run` on each sequence of bearings.

    The filter's door: parameters are as for :func:`run`, with ``mu`` of shape
    (K,) (one sequence, a batch of one) or (B, K), ``prior_mean`` (3,) or
    (B, 3), ``rho`` a number or of shape (B,), (K,) or (B, K) (one per frame),
    ``steps`` (K - 1,) or (B, K - 1), ``n_particles`` per replica and
    ``options`` those of :func:`run`; the replicas are rows of one batch, drawn
    from ``rng``.

    Returns
    -------
    Replicated
    """
    R = checks.count(replicas, "replicas")
    mu = np.asarray(mu)
    if mu.ndim == 1:
        Gaussian.prior(prior_mean, prior_cov)
        track = frames.check(mu, rho, steps)
        if track.regular:
            checks.finite_array(mu, "mu")
        if np.ndim(rho) == 0:
            rho = checks.positive_scalar(rho, "rho")
        else:
            rho = np.asarray(rho)[None]
        mu = track.mu[None]
        steps = None if steps is None else np.asarray(steps, dtype=float)[None]
    if mu.ndim != 2:
        raise ValueError(f"mu must have shape (K,) or (B, K), got shape {mu.shape}")
    rho = np.asarray(rho)
    prior_mean = np.asarray(prior_mean)
    rho = np.repeat(rho, R, axis=0) if rho.ndim == 2 or rho.shape == mu.shape[:1] else rho
    prior_mean = np.repeat(prior_mean, R, axis=0) if prior_mean.ndim == 2 else prior_mean
    if steps is not None and np.ndim(steps) == 2:
        steps = np.repeat(np.asarray(steps), R, axis=0)
    runs = run(
        np.repeat(mu, R, axis=0),
        rho,
        prior_mean,
        prior_cov,
        n_particles,
        rng,
        steps=steps,
        gate=gate,
        **options,
    )
    return Replicated(runs, R)
