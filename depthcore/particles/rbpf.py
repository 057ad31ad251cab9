"""The Rao-Blackwellised particle filter on the N-frame problem (Prince, section 19.5.3).

Recommended import: ``from depthcore.particles import rbpf``.

The textbook's extensions of the particle filter (Prince, section 19.5.3
[prince2012]_) include Rao-Blackwellisation: the state is split into two
parts, the first tracked by particles and the second, conditioned on the
first, by a Kalman filter [doucet2000]_. The model of :mod:`depthcore.exact.bank`
splits this way. Given the depth at frame 1, ``y_1 = y``, the depth at frame
``k`` is ``y + k - 1`` and the lateral state ``u_k = (x_k, v_k)`` is
linear-Gaussian (textbook Eqs. (19.5), (19.7)); so each particle is a depth
``y^(j)`` carrying the Kalman filter of ``u_k`` at that depth
(:func:`depthcore.exact.bank.filter_bank`, :func:`depthcore.exact.bank.step`), and the
lateral part of the posterior is exact given the particles. The particles
sample only the one-dimensional depth.

The steps, for ``J`` particles and bearings ``mu_1, mu_2, ..`` seen one at a time:

* Frame 1. The depths are drawn from the prior's depth marginal
  ``N(m_y, P_yy)`` restricted to ``y > 0`` (the point in front of the camera
  at every frame, the "front" support of :func:`depthcore.exact.optimal.run`).
  The truncation is handled exactly, by inverse-CDF sampling of the truncated
  Gaussian in log space (:func:`prior_depths`); its normaliser
  ``P(y_1 > 0)`` is the same for every particle and cancels when the weights
  are normalised. Each particle's filter starts from the prior of ``(x_1, v_1)``
  given its depth (:func:`depthcore.exact.bank.conditional_prior`) and incorporates
  ``mu_1`` (textbook 19.2.2).
* Frame ``k``. Each filter predicts (textbook 19.2.1) and incorporates ``mu_k``;
  the particle's log weight gains the log density of the innovation,
  ``log p(mu_k | mu_1 .. mu_{k-1}, y^(j))`` (the textbook's measurement
  incorporation, 19.5.2, with the Kalman filter's marginal likelihood in place
  of the likelihood of one state).
* Resampling. When the effective sample size falls below
  ``ess_threshold * J`` (default ``0.5``; textbook 19.5.3 resamples now and
  then rather than at every frame) the particles are resampled, systematically by default
  (:mod:`depthcore.particles.resampling`), each copy keeping its Kalman filter.
* Rejuvenation (:func:`rejuvenate`). The depth is static: resampling only
  duplicates depths and nothing spreads them again, so without a move the
  cloud degenerates to a few distinct depths. After each resampling every
  particle takes ``moves`` Metropolis-Hastings steps on its depth
  [gilks2001]_, a Gaussian random walk with SD ``2.38`` times the weighted SD
  of the depths before resampling (the scale for a one-dimensional target
  [roberts1997]_), targeting the posterior of the depth given all bearings so
  far,

      pi_k(y)  proportional to  N(y; m_y, P_yy) [y > 0] p(mu_1 .. mu_k | y),

  which leaves the filtering distribution invariant. The marginal likelihood
  ``p(mu_1 .. mu_k | y')`` at a proposed depth comes from rerunning that
  particle's Kalman filter over all ``k`` frames (:func:`depthcore.exact.bank.filter_bank`),
  and an accepted move takes the rerun filter with it. Proposals at
  ``y' <= 0`` are rejected without a rerun.

Cost. A frame without resampling costs one Kalman step per particle, ``O(J)``.
A resampling at frame ``k`` costs ``moves`` reruns over ``k`` frames,
``O(moves J k)``; over ``N`` frames, resampling at every frame in the worst
case, ``O(moves J N**2)``. The past bearings are kept for these reruns
(``RBPF.bank.mu``).

On the paper's problem the moves do most of the work. With the broad prior
``N(m, 1000 I)`` the first two bearings leave the depth spread over tens of
units and the third fixes it to within about one: after ``mu_3`` the weights
of a thousand particles collapse onto two or three (ESS near 2), and the
posterior is rebuilt by the moves from those survivors. Hence the default of
:data:`DEFAULT_MOVES` moves, and the error's ``1 / sqrt(J)`` decay only from
about a thousand particles on (``benchmarks/bench_rbpf.py``).

Monte Carlo standard errors. After a resampling and a move, the particles are
correlated and the weighted spread of one cloud does not measure the error of
its estimates. The filter therefore runs ``replicas`` independent clouds
(independent draws from the one generator): :meth:`RBPF.moments` averages
their estimates and :meth:`RBPF.standard_errors` is the SD of the replicas'
estimates over ``sqrt(replicas)``, the standard error of that average (NaN
with one replica). :meth:`RBPF.errors` widens it by the Student t factor for
``replicas - 1`` degrees of freedom, so that the estimate lies within 1.96
errors of the exact value in 95 % of runs, and flags a collapse (replicas that
disagree by more than the posterior's width), where the error is NaN
(:func:`depthcore.particles.resampling.replica_errors`). The self-normalised estimates
also carry a bias of order ``1 / J``, which this does not measure.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.5 (particle filtering; 19.5.3, its
   extensions: occasional resampling, Rao-Blackwellisation).
.. [doucet2000] A. Doucet, N. de Freitas, K. Murphy and S. Russell,
   "Rao-Blackwellised particle filtering for dynamic Bayesian networks",
   UAI 2000.

[gilks2001]_ and [roberts1997]_ are listed with :mod:`depthcore.particles.resample_move`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import log_ndtr, ndtr, ndtri_exp

from depthcore.exact import bank as bk
from depthcore.exact import mixture as bmix
from depthcore.particles.importance import ParticleMoments
from depthcore.particles.resampling import (
    RESAMPLERS,
    effective_sample_size,
    metropolis,
    replica_errors,
    weighted_moments,
)
from depthcore.problem import checks, frames, model, predictive, signature
from depthcore.problem.weights import normalise

#: Metropolis-Hastings steps per particle after each resampling, by default.
DEFAULT_MOVES = 20
#: Random-walk scale for a one-dimensional target [roberts1997]_.
_RW_SCALE = 2.38
#: Floor on the random walk's SD, relative to the prior depth SD (a collapsed cloud).
_SCALE_FLOOR = 1e-6


@dataclass(frozen=True)
class Settings:
    """The filter's tuning, fixed when it starts.

    Attributes
    ----------
    moves : int
        Metropolis-Hastings steps per particle after each resampling.
    ess_threshold : float
        Resample when the ESS is below ``ess_threshold * J``.
    resampler : str
        A key of :data:`depthcore.particles.resampling.RESAMPLERS`.
    """

    moves: int
    ess_threshold: float
    resampler: str


@dataclass(frozen=True)
class RBPF:
    """The Rao-Blackwellised particle filter after ``K`` frames.

    Built by :func:`run`, extended by :func:`step`. ``(...)`` is the batch
    shape of the trials (empty for one sequence), ``R`` the number of
    independent replicas and ``J`` the number of particles in each.

    Attributes
    ----------
    bank : depthcore.exact.bank.Bank
        The particles as a bank of Kalman filters: ``nodes`` (..., R, J) are
        their depths at frame 1, ``mean`` (..., R, J, 2) and ``cov``
        (..., R, J, 2, 2) the Gaussian of ``(x_K, v_K)`` given each depth and
        the bearings, ``log_weight`` (..., R, J) ``log pi_K`` up to a constant,
        ``mu`` (..., R, K) the bearings so far.
    log_weights : ndarray, shape (..., R, J)
        The particles' normalised log weights.
    ess : ndarray, shape (..., R, K)
        Effective sample size after reweighting by ``mu_k``, before any
        resampling at that frame.
    resampled : ndarray of bool, shape (..., R, K)
        Whether frame ``k`` resampled and moved the particles.
    acceptance : ndarray, shape (..., R, K)
        Mean Metropolis-Hastings acceptance rate of the moves at frame ``k``
        (NaN where the frame did not move, or ``moves = 0``).
    settings : Settings
    updates : depthcore.problem.predictive.Updates
        Per frame, shape (..., K) each: the bearing's log predictive density
        and two-sided tail probability under the pooled particles of all
        replicas (each particle's Kalman predictive, weighted by the
        particle's weight over ``R``), and whether the gate skipped it.
    """

    bank: bk.Bank
    log_weights: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    acceptance: np.ndarray
    settings: Settings
    updates: predictive.Updates | None = None

    @property
    def _travelled(self):
        """``y_K - y_1`` with a trailing axis for the particles: ``K - 1`` at unit steps."""
        return np.asarray(self.bank.travelled)[..., None]

    @property
    def frames(self) -> int:
        """``K``, the number of bearings seen."""
        return self.bank.frames

    @property
    def n_particles(self) -> int:
        """``J``, the particles in each replica."""
        return self.log_weights.shape[-1]

    @property
    def replicas(self) -> int:
        """``R``, the independent replicas."""
        return self.log_weights.shape[-2]

    def replica_moments(self) -> ParticleMoments:
        """Depth and velocity means and SDs at frame ``K`` of each replica, shape (..., R).

        The moments of the mixture of the particles' Gaussians
        (:func:`depthcore.exact.mixture.mixture`'s formula with the particles' weights):
        the depth ``y_1 + K - 1`` is exact given a particle, the velocity
        Gaussian given its depth.
        """
        b = self.bank
        mean, cov = bmix.mixture_moments(
            np.exp(self.log_weights), b.mean, b.cov, b.nodes + self._travelled
        )
        return ParticleMoments(
            mean[..., 1], np.sqrt(cov[..., 1, 1]), mean[..., 2], np.sqrt(cov[..., 2, 2])
        )

    def pooled(self):
        """The replicas pooled into one mixture at frame ``K``.

        Returns
        -------
        W : ndarray, shape (..., R J)
            Normalised weights, each replica's over ``R``.
        depths : ndarray, shape (..., R J)
            The particles' depths ``y_K``: ``y_1`` plus the depth travelled
            (``K - 1`` at unit steps).
        means : ndarray, shape (..., R J, 2)
            ``E[(x_K, v_K) | y_1, mu_1 .. mu_K]`` of each particle.
        covs : ndarray, shape (..., R J, 2, 2)
        """
        b = self.bank
        batch = self.log_weights.shape[:-2]
        n = self.replicas * self.n_particles
        W = np.exp(self.log_weights).reshape(batch + (n,)) / self.replicas
        depths = np.broadcast_to(b.nodes, self.log_weights.shape).reshape(batch + (n,))
        means = np.broadcast_to(b.mean, self.log_weights.shape + (2,))
        covs = np.broadcast_to(b.cov, self.log_weights.shape + (2, 2))
        return (
            W,
            depths + self._travelled[..., 0, :]
            if self._travelled.ndim > 1
            else depths + self._travelled,
            means.reshape(batch + (n, 2)),
            covs.reshape(batch + (n, 2, 2)),
        )

    def state_moments(self):
        """Mean (..., 3) and covariance (..., 3, 3) of ``(x_K, y_K, v_K)`` under :meth:`pooled`.

        The law of total variance over the particles' Kalman filters: the
        weighted covariance of their means plus their weighted covariances
        (the depth is exact given a particle).
        """
        W, depths, means, covs = self.pooled()
        return bmix.mixture_moments(W, means, covs, depths)

    def depth_cdf(self, y):
        """``P(y_K <= y)`` under :meth:`pooled`, the particles' weighted step function.

        ``y`` of shape (...) or (..., G); returns the same shape.
        """
        W, depths, _, _ = self.pooled()
        y = np.asarray(y, dtype=float)
        if y.ndim > W.ndim - 1:
            W, depths = W[..., None, :], depths[..., None, :]
        return np.sum(W * (depths <= y[..., None]), axis=-1)

    def velocity_cdf(self, v):
        """``P(v_K <= v)`` under :meth:`pooled`: the Gaussian mixture's CDF.

        ``v`` of shape (...) or (..., G); returns the same shape.
        """
        W, _, means, covs = self.pooled()
        v = np.asarray(v, dtype=float)
        m, s = means[..., 1], np.sqrt(covs[..., 1, 1])
        if v.ndim > W.ndim - 1:
            W, m, s = W[..., None, :], m[..., None, :], s[..., None, :]
        return np.sum(W * ndtr((v[..., None] - m) / s), axis=-1)

    def velocity_pdf(self, v):
        """The density of ``v_K`` under :meth:`pooled`, a Gaussian mixture.

        Shapes as :meth:`velocity_cdf`.
        """
        W, _, means, covs = self.pooled()
        v = np.asarray(v, dtype=float)
        m, s = means[..., 1], np.sqrt(covs[..., 1, 1])
        if v.ndim > W.ndim - 1:
            W, m, s = W[..., None, :], m[..., None, :], s[..., None, :]
        z = (v[..., None] - m) / s
        return np.sum(W * np.exp(-0.5 * z**2) / (np.sqrt(2 * np.pi) * s), axis=-1)

    def moments(self) -> ParticleMoments:
        """The replicas' average of :meth:`replica_moments`, shape (...)."""
        return ParticleMoments(*(np.mean(m, axis=-1) for m in self.replica_moments()))

    def standard_errors(self) -> ParticleMoments:
        """Standard errors of :meth:`moments` from the spread of the independent replicas.

        The SD of the ``R`` replicas' estimates (``ddof = 1``) over ``sqrt(R)``,
        shape (...); NaN with one replica. They do not include the ``O(1 / J)``
        bias of the self-normalised estimates.
        """
        R = self.replicas
        if R < 2:
            return ParticleMoments(*(np.full(m.shape[:-1], np.nan) for m in self.replica_moments()))
        return ParticleMoments(
            *(np.std(m, axis=-1, ddof=1) / np.sqrt(R) for m in self.replica_moments())
        )

    def errors(self) -> tuple[ParticleMoments, np.ndarray]:
        """Monte Carlo errors of the moments and the collapse flag, shape (...).

        :func:`depthcore.particles.resampling.replica_errors` of each of
        :meth:`replica_moments` over the replicas: the standard error of
        :meth:`standard_errors` widened by the Student t factor for ``R - 1``
        degrees of freedom, NaN where the replicas collapsed (each worth fewer
        than ``MIN_EFFECTIVE_DRAWS`` independent draws of the posterior) or
        ``R < 2``. ``collapsed`` is true where the depth or the velocity has.
        """
        m = self.replica_moments()
        out, collapsed = [], np.zeros(m.depth_mean.shape[:-1], dtype=bool)
        for value, sd in (
            (m.depth_mean, m.depth_sd),
            (m.depth_sd, m.depth_sd),
            (m.velocity_mean, m.velocity_sd),
            (m.velocity_sd, m.velocity_sd),
        ):
            e, c = replica_errors(value, sd)
            out.append(e)
            collapsed |= c
        return ParticleMoments(*(np.where(collapsed, np.nan, e) for e in out)), collapsed


# --- the prior of the depth ------------------------------------------------------------


def prior_depths(prior_mean, prior_cov, shape, rng: np.random.Generator) -> np.ndarray:
    """Draws of ``y_1`` from ``N(m_y, P_yy)`` restricted to ``y_1 > 0``, by inverse CDF.

    With ``s = sqrt(P_yy)`` and ``V`` uniform on ``(0, Phi(m_y / s)]``,
    ``y = m_y - s Phi^{-1}(V)`` has the truncated density: ``y > 0`` exactly
    when ``V < Phi(m_y / s)``. ``log V`` and the inverse are computed in log
    space (``log_ndtr``, ``ndtri_exp``), so a prior with almost no mass in
    front of the camera is sampled as accurately as one with almost all.

    Parameters
    ----------
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
    shape : tuple of int
        ``(...) + (J,)``: the draws' shape, the priors' batch shape then the draws.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape ``shape``
        Depths at frame 1, all > 0.
    """
    m = prior_mean[..., 1, None]
    s = np.sqrt(prior_cov[..., 1, 1])[..., None]
    log_v = np.log1p(-rng.random(shape)) + log_ndtr(m / s)  # 1 - U lies in (0, 1]
    y = m - s * ndtri_exp(log_v)
    # > 0 in exact arithmetic; rounding can give 0 at V = Phi(m_y / s)
    return np.maximum(y, np.finfo(float).tiny)


# --- the Metropolis-Hastings move ------------------------------------------------------


def _finite_or_minus_inf(log_weight):
    """A filter that overflowed (a depth within rounding of 0) gets weight zero."""
    return np.where(np.isfinite(log_weight), log_weight, -np.inf)


def rejuvenate(bank: bk.Bank, scale, moves: int, rng: np.random.Generator):
    """Metropolis-Hastings random-walk moves on the particles' depths [gilks2001]_.

    The target of each particle is the posterior of the depth at frame 1 given
    the bank's bearings, ``pi_K(y) ~ N(y; m_y, P_yy) [y > 0] p(mu_1 .. mu_K | y)``,
    whose log is ``bank.log_weight`` up to a constant. Each step proposes
    ``y' = y + scale eps``, ``eps ~ N(0, 1)``, reruns the Kalman filter at
    ``y'`` over all ``K`` bearings (textbook 19.2.3, :func:`depthcore.exact.bank.filter_bank`)
    and accepts with probability ``min(1, pi_K(y') / pi_K(y))``; a proposal
    ``y' <= 0`` is rejected. An accepted particle takes the rerun filter's
    mean, covariance and log weight. Cost: ``moves`` reruns over ``K`` frames
    per particle.

    Parameters
    ----------
    bank : depthcore.exact.bank.Bank
        The particles: nodes (..., J) and their filters after the bank's
        bearings; the other fields broadcast with the batch shape (...).
    scale : array_like, shape (...) or ()
        The random walk's SD, > 0.
    moves : int
        Steps per particle, >= 0.
    rng : numpy.random.Generator

    Returns
    -------
    bank : depthcore.exact.bank.Bank
        The moved particles (``history`` dropped).
    acceptance : ndarray, shape (...)
        Mean acceptance rate over the particles and steps (NaN for ``moves = 0``).
    """
    if not isinstance(bank, bk.Bank):
        raise ValueError(f"bank must be a Bank, got {type(bank).__name__}")
    scale = checks.finite_array(scale, "scale")
    if not np.all(scale > 0):
        raise ValueError(f"scale must be positive, got minimum {float(np.min(scale)):.6g}")
    moves = _moves(moves)
    rng = checks.generator(rng)

    def target(proposal):
        inside = proposal > 0
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            rerun = bk.filter_bank(
                np.where(inside, proposal, 1.0),
                bank.mu,
                bank.rho if bank.frame_rho is None else bank.frame_noise,
                bank.prior_mean,
                bank.prior_cov,
                bank.process_noise,
                steps=bank.steps,
            )
        log_p = np.where(inside, _finite_or_minus_inf(rerun.log_weight), -np.inf)
        return log_p, (rerun.mean, rerun.cov)

    nodes, log_p, (mean, cov), acceptance = metropolis(
        bank.nodes,
        _finite_or_minus_inf(bank.log_weight),
        lambda x, eps: x + np.asarray(scale)[..., None] * eps,
        target,
        moves,
        rng,
        (bank.mean, bank.cov),
    )
    moved = bank._replace(nodes=nodes, mean=mean, cov=cov, log_weight=log_p, history=None)
    return moved, acceptance


# --- the filter ------------------------------------------------------------------------


def _moves(moves) -> int:
    if isinstance(moves, bool) or not isinstance(moves, (int, np.integer)) or moves < 0:
        raise ValueError(f"moves must be an integer >= 0, got {moves!r}")
    return int(moves)


def _settings(moves, ess_threshold, resampler) -> Settings:
    threshold = checks.finite_array(ess_threshold, "ess_threshold")
    if threshold.ndim != 0 or not 0.0 <= threshold <= 1.0:
        raise ValueError(f"ess_threshold must be a number in [0, 1], got {ess_threshold!r}")
    if not isinstance(resampler, str) or resampler not in RESAMPLERS:
        raise ValueError(f"resampler must be one of {tuple(RESAMPLERS)}, got {resampler!r}")
    return Settings(_moves(moves), float(threshold), resampler)


def _rows(bank: bk.Bank, rows) -> bk.Bank:
    """The bank's trials ``rows`` (a boolean mask of its batch shape), history dropped."""
    return bk.Bank(
        *(getattr(bank, f)[rows] for f in bk.Bank._fields if f != "history"), history=None
    )


def _resample_move(bank: bk.Bank, log_w, need, settings: Settings, rng):
    """Resample the trials ``need`` (a mask of the batch shape) and move their particles.

    Returns the bank, the log weights and the acceptance rates of the moved trials.
    """
    sub = _rows(bank, need)
    W = np.exp(log_w[need])
    _, sd = weighted_moments(sub.nodes, W)
    scale = _RW_SCALE * np.maximum(sd, _SCALE_FLOOR * np.sqrt(sub.prior_cov[..., 1, 1]))
    idx = RESAMPLERS[settings.resampler](W, rng)
    sub = sub._replace(
        nodes=np.take_along_axis(sub.nodes, idx, axis=-1),
        mean=np.take_along_axis(sub.mean, idx[..., None], axis=-2),
        cov=np.take_along_axis(sub.cov, idx[..., None, None], axis=-3),
        log_weight=np.take_along_axis(sub.log_weight, idx, axis=-1),
    )
    sub, acceptance = rejuvenate(sub, scale, settings.moves, rng)
    fields = {}
    for name in ("nodes", "mean", "cov", "log_weight"):
        arr = np.array(getattr(bank, name))
        arr[need] = getattr(sub, name)
        fields[name] = arr
    log_w = np.array(log_w)
    log_w[need] = -np.log(log_w.shape[-1])
    return bank._replace(**fields), log_w, acceptance


def _reweighted(state: RBPF, bank: bk.Bank, log_w, rng, report=None) -> RBPF:
    """Normalise the new weights, record the ESS, resample and move where it is low.

    ``report``: the frame's (log predictive, tail, gated), each of the batch
    shape without the replicas, appended to the state's updates.
    """
    if not np.all(np.any(np.isfinite(log_w), axis=-1)):
        raise ValueError(
            f"n_particles is too small: every particle of a replica has weight zero "
            f"after mu_{bank.frames}"
        )
    log_w = normalise(log_w)
    ess = effective_sample_size(log_w)
    settings = state.settings
    need = ess < settings.ess_threshold * log_w.shape[-1]
    acceptance = np.full(ess.shape, np.nan)
    if np.any(need):
        bank, log_w, acceptance[need] = _resample_move(bank, log_w, need, settings, rng)
    updates = state.updates
    if report is not None:
        updates = predictive.Updates(
            *(
                np.concatenate([old, np.asarray(new)[..., None]], axis=-1)
                for old, new in zip(state.updates, report, strict=True)
            )
        )
    return RBPF(
        bank,
        log_w,
        np.concatenate([state.ess, ess[..., None]], axis=-1),
        np.concatenate([state.resampled, need[..., None]], axis=-1),
        np.concatenate([state.acceptance, acceptance[..., None]], axis=-1),
        settings,
        updates,
    )


def _pooled_report(log_w, bank: bk.Bank, mu, rho, depth_ahead, gate):
    """A frame's report under the particles of all replicas pooled, and the gate's verdict.

    Each particle predicts ``mu`` as ``N(x / y, P_xx / y**2 + rho**2)`` from its
    lateral Gaussian moved by the step ahead (``x + s v``, variance
    ``P_xx + 2 s P_xv + s**2 P_vv``) at its depth ``y``; the particles are
    weighted by their normalised weights over ``R``.

    Parameters
    ----------
    log_w : ndarray, shape (..., R, J)
        Normalised log weights before the frame.
    bank : depthcore.exact.bank.Bank
        The particles before the frame (``mean`` (..., R, J, 2)).
    mu : ndarray, shape (...)
    rho : ndarray, shape (...) or ()
    depth_ahead : tuple of ndarray
        The step ``s`` to the frame (shape (...) or ()) and the particles'
        depths ``y`` at it (..., R, J).
    gate : float or None

    Returns
    -------
    log_density, tail, gated : ndarray, shape (...)
    """
    s, y = depth_ahead
    s = np.asarray(s)[..., None, None]
    x = bank.mean[..., 0] + s * bank.mean[..., 1]
    var_x = bank.cov[..., 0, 0] + 2 * s * bank.cov[..., 0, 1] + s * s * bank.cov[..., 1, 1]
    r2 = np.asarray(rho, dtype=float)[..., None, None] ** 2
    shape = log_w.shape[:-2] + (-1,)
    R = log_w.shape[-2]
    with np.errstate(invalid="ignore"):
        log_d, tail = predictive.mixture(
            np.where(np.isnan(mu), 0.0, mu),
            (log_w - np.log(R)).reshape(shape),
            (x / y).reshape(shape),
            (var_x / y**2 + r2).reshape(shape),
        )
    missing = np.isnan(mu)
    log_d, tail = np.where(missing, np.nan, log_d), np.where(missing, np.nan, tail)
    return log_d, tail, predictive.skipped(tail, ~missing, gate)


def _start(mu_1, rho, q, prior_mean, prior_cov, J, R, settings, rng, gate=None) -> RBPF:
    """Frame 1: depths from the truncated prior, each filter updated by ``mu_1``, weights.

    ``mu_1`` may be ``NaN`` (no bearing at frame 1: the particles keep the
    prior's weights); ``rho`` is frame 1's noise.
    """
    batch = mu_1.shape + (R,)
    prior_mean = np.broadcast_to(prior_mean[..., None, :], batch + (3,))
    prior_cov = np.broadcast_to(prior_cov[..., None, :, :], batch + (3, 3))
    nodes = prior_depths(prior_mean, prior_cov, batch + (J,), rng)
    # the prior's predictive of mu_1 at each particle's depth: a bank before any bearing
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        before = bk.filter_bank(
            nodes,
            np.full(batch + (1,), np.nan),
            np.broadcast_to(rho[..., None], batch),
            prior_mean,
            prior_cov,
            np.broadcast_to(q[..., None], batch),
        )
    uniform = np.full(batch + (J,), -np.log(J))
    report = _pooled_report(uniform, before, mu_1, rho, (0.0, nodes), gate)
    mu_1 = np.where(report[2], np.nan, mu_1)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        bank = bk.filter_bank(
            nodes,
            np.broadcast_to(mu_1[..., None, None], batch + (1,)),
            np.broadcast_to(rho[..., None], batch),
            prior_mean,
            prior_cov,
            np.broadcast_to(q[..., None], batch),
        )
    log_prior = bk.conditional_prior(nodes, prior_mean, prior_cov)[1]
    bank = bank._replace(log_weight=_finite_or_minus_inf(bank.log_weight))
    empty = np.zeros(batch + (0,))
    none = np.zeros(mu_1.shape + (0,))
    updates = predictive.Updates(none, none, none.astype(bool))
    state = RBPF(bank, None, empty, empty.astype(bool), empty, settings, updates)
    return _reweighted(state, bank, bank.log_weight - log_prior, rng, report)


def step(state: RBPF, mu_next, rng: np.random.Generator, rho=None, step=1.0, gate=None) -> RBPF:
    """Add frame ``K + 1``: every particle's Kalman filter predicts and incorporates ``mu_{K+1}``.

    The log weights gain the innovations' log densities (textbook 19.2.2,
    19.5.2); then, where the ESS falls below the threshold, the particles are
    resampled and moved (:func:`rejuvenate`). Cost ``O(J)`` per trial and
    replica, plus ``O(moves J (K + 1))`` where it resamples.

    Parameters
    ----------
    state : RBPF
        The filter after ``K`` frames.
    mu_next : float or array_like, shape (...)
        The bearing at frame ``K + 1`` of each trial; ``NaN``: no bearing (the
        filters predict through the frame, the weights stay).
    rng : numpy.random.Generator or numpy.random.SeedSequence
    rho : float or array_like, shape (...), or None
        The frame's noise SD (``None``: the filter's).
    step : float or array_like, shape (...)
        The depth's change since frame ``K``, > 0.
    gate : float or None
        Skip a bearing whose tail probability under the pooled particles'
        predictive is below it (:mod:`depthcore.problem.predictive`).

    Returns
    -------
    RBPF
    """
    if not isinstance(state, RBPF):
        raise ValueError(f"state must be an RBPF, got {type(state).__name__}")
    batch = state.log_weights.shape[:-2]
    mu_next = checks.as_float(mu_next, "mu_next")
    if np.any(np.isinf(mu_next)):
        raise ValueError("mu_next must be finite or NaN (a missing frame)")
    if mu_next.shape not in ((), batch):
        raise ValueError(f"mu_next must be a scalar or have shape {batch}, got {mu_next.shape}")
    rng = checks.generator(rng)
    gate = predictive.gate(gate)
    old = state.bank
    plain = rho is None and np.all(np.asarray(step) == 1.0) and old.steps is None
    plain = plain and old.frame_rho is None and not np.any(np.isnan(mu_next))
    noise = np.asarray(old.frame_noise[..., -1] if rho is None else rho, dtype=float)
    step_b = np.asarray(step, dtype=float)
    step_b = step_b[..., None] if step_b.ndim else step_b  # over the replicas
    depths = old.nodes + (np.asarray(old.travelled) + step_b)[..., None]
    row_noise = noise[..., 0] if noise.ndim > len(batch) else noise  # the same in every replica
    report = _pooled_report(
        state.log_weights, old, np.broadcast_to(mu_next, batch), row_noise, (step, depths), gate
    )
    mu_next = np.where(report[2], np.nan, np.broadcast_to(mu_next, batch))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        if plain and not np.any(report[2]):
            new = bk.step(old, np.broadcast_to(mu_next, batch)[..., None])
        else:
            new = bk.step(
                old,
                np.broadcast_to(mu_next, batch)[..., None],
                rho=None if rho is None else np.asarray(rho, dtype=float)[..., None],
                step=np.asarray(step, dtype=float)[..., None] if np.ndim(step) else step,
                gaps=True,
            )
    new = new._replace(log_weight=_finite_or_minus_inf(new.log_weight))
    with np.errstate(invalid="ignore"):
        increment = np.where(np.isfinite(old.log_weight), new.log_weight - old.log_weight, -np.inf)
    return _reweighted(state, new, state.log_weights + increment, rng, report)


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    n_particles: int,
    rng: np.random.Generator,
    process_noise=0.0,
    replicas: int = 1,
    moves: int = DEFAULT_MOVES,
    ess_threshold: float = 0.5,
    resampler: str = "systematic",
    steps=None,
    gate=None,
) -> RBPF:
    """The Rao-Blackwellised particle filter over bearings ``mu_1 .. mu_K``, batched over trials.

    The bearings are taken one at a time (:func:`step`): the result after
    ``K`` frames is the filter's state, ready for more.

    A missing bearing (``NaN``) is predicted through, ``rho`` may be given per
    frame and ``steps`` between frames; the particles' depths at frame ``k``
    are ``y_1`` plus the depth travelled.

    {parameters}
    n_particles : int
        ``J >= 2`` particles (depths) per replica.
    rng : numpy.random.Generator or numpy.random.SeedSequence
        The only source of randomness.
    {process_noise}
    replicas : int
        ``R >= 1`` independent clouds of ``J`` particles, for standard errors
        (:meth:`RBPF.standard_errors`); the cost grows like ``R J``.
    moves, ess_threshold, resampler
        The resampling schedule, :class:`Settings`: ``moves >= 0``, ``ess_threshold``
        in [0, 1] (0: never resample, importance sampling of the depth from its prior).

    Returns
    -------
    RBPF
    """
    gate = predictive.gate(gate)
    per_frame = np.ndim(rho) > 0 and np.shape(rho) == np.shape(mu)
    arr = checks.as_float(mu, "mu")
    regular = steps is None and not per_frame and not np.any(np.isnan(arr))
    if regular:
        mu, rho, prior_mean, prior_cov = model.batch_inputs(
            mu, rho, prior_mean, prior_cov, triples=False
        )
        rho_frames = np.broadcast_to(np.asarray(rho)[..., None], mu.shape)
        step_frames = np.ones(mu.shape[:-1] + (mu.shape[-1] - 1,))
    else:
        track = frames.check(mu, rho, steps)
        mu, rho_frames, step_frames = track.mu, track.rho, track.steps
        _, _, prior_mean, prior_cov = model.batch_inputs(
            np.where(track.present, mu, 0.0), 1.0, prior_mean, prior_cov, triples=False
        )
        rho = np.array(rho_frames[..., 0])
    batch = mu.shape[:-1]
    process_noise = checks.nonnegative_batch(process_noise, "process_noise", batch)
    if (
        isinstance(n_particles, bool)
        or not isinstance(n_particles, (int, np.integer))
        or n_particles < 2
    ):
        raise ValueError(f"n_particles must be an integer >= 2, got {n_particles!r}")
    R = checks.count(replicas, "replicas")
    settings = _settings(moves, ess_threshold, resampler)
    rng = checks.generator(rng)
    rho, process_noise = np.broadcast_to(rho, batch), np.broadcast_to(process_noise, batch)
    state = _start(
        mu[..., 0],
        rho,
        process_noise,
        prior_mean,
        prior_cov,
        int(n_particles),
        R,
        settings,
        rng,
        gate,
    )
    for k in range(1, mu.shape[-1]):
        if regular and gate is None:
            state = step(state, mu[..., k], rng)
        else:
            state = step(state, mu[..., k], rng, rho_frames[..., k], step_frames[..., k - 1], gate)
    return state
