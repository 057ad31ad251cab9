"""The Rao-Blackwellised particle filter on the N-frame problem (Prince, section 19.5.3).

Recommended import: ``from depthcore.particles import rbpf``.

Rao-Blackwellisation (Prince, section 19.5.3 [prince2012]_, [doucet2000]_) splits
the state of :mod:`depthcore.exact.bank`'s model: given ``y_1 = y`` the lateral state
``u_k = (x_k, v_k)`` is linear-Gaussian (textbook Eqs. (19.5), (19.7)), so each
particle is a depth ``y^(j)`` carrying the Kalman filter of ``u_k`` at that depth
(:func:`depthcore.exact.bank.filter_bank`, :func:`depthcore.exact.bank.step`); the
particles sample only the depth. For ``J`` particles and bearings seen one at a time:

* Frame 1. Depths from ``N(m_y, P_yy)`` on ``y > 0`` (the "front" support),
  exactly (:func:`prior_depths`); each filter starts from
  :func:`depthcore.exact.bank.conditional_prior` and incorporates ``mu_1``
  (textbook 19.2.2).
* Frame ``k``. Each filter predicts (19.2.1) and incorporates ``mu_k``; the log
  weight gains ``log p(mu_k | mu_1 .. mu_{k-1}, y^(j))`` (19.5.2).
* Resampling, when the ESS falls below ``ess_threshold * J`` (default 0.5; 19.5.3)
  (:mod:`depthcore.particles.resampling`), each copy keeping its filter.
* Rejuvenation (:func:`rejuvenate`). The depth is static, so after each
  resampling every particle takes ``moves`` Metropolis-Hastings steps [gilks2001]_,
  a random walk of SD ``2.38`` times the depths' weighted SD [roberts1997]_,
  targeting

      pi_k(y)  proportional to  N(y; m_y, P_yy) [y > f_k] p(mu_1 .. mu_k | y),

  with ``f_k`` the depth at frame 1 below which the point would have reached the
  camera by frame ``k`` (:func:`depthcore.problem.frames.depth_floor`: 0 while it
  recedes; a step towards the point gives the particles it brings to the camera
  no weight).

A frame costs ``O(J)``, a resampling ``O(moves J k)``. On the paper's problem the
third bearing collapses a thousand particles' weights onto two or three and the moves
rebuild the posterior: hence :data:`DEFAULT_MOVES` (``benchmarks/bench_rbpf.py``).

Moved particles are correlated, so the filter runs ``replicas`` independent clouds:
:meth:`RBPF.moments` averages them, :meth:`RBPF.standard_errors` is their SD over
``sqrt(replicas)`` and :meth:`RBPF.errors` widens it by Student t and flags a
collapse (:func:`depthcore.particles.resampling.replica_errors`). The ``1 / J``
bias of self-normalisation is not measured.

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
    """The filter after ``K`` frames: batch ``(...)``, ``R`` replicas of ``J`` particles.

    Attributes
    ----------
    bank : depthcore.exact.bank.Bank
        The particles' filters: ``nodes`` (..., R, J), ``mean`` (..., R, J, 2),
        ``cov`` (..., R, J, 2, 2), ``log_weight`` (..., R, J), ``mu`` (..., R, K).
    log_weights : ndarray, shape (..., R, J)
        Normalised.
    ess : ndarray, shape (..., R, K)
        After reweighting by ``mu_k``, before resampling.
    resampled : ndarray of bool, shape (..., R, K)
    acceptance : ndarray, shape (..., R, K)
        Mean acceptance rate of the moves (NaN without moves).
    settings : Settings
    updates : depthcore.problem.predictive.Updates
        Per frame (..., K), under the pooled particles (:func:`_pooled_report`).
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
        """Depth and velocity means and SDs at frame ``K`` of each replica, shape (..., R)."""
        b = self.bank
        mean, cov = bmix.mixture_moments(
            np.exp(self.log_weights), b.mean, b.cov, b.nodes + self._travelled
        )
        return ParticleMoments(
            mean[..., 1], np.sqrt(cov[..., 1, 1]), mean[..., 2], np.sqrt(cov[..., 2, 2])
        )

    def pooled(self):
        """The replicas pooled into one mixture at frame ``K``.

        Returns weights ``W`` (..., R J) (each replica's over ``R``), depths ``y_K``
        (..., R J), means (..., R J, 2) and covariances (..., R J, 2, 2).
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
        """Mean (..., 3) and covariance (..., 3, 3) of ``(x_K, y_K, v_K)`` under :meth:`pooled`."""
        W, depths, means, covs = self.pooled()
        return bmix.mixture_moments(W, means, covs, depths)

    def depth_cdf(self, y):
        """``P(y_K <= y)`` under :meth:`pooled`, ``y`` (...) or (..., G)."""
        W, depths, _, _ = self.pooled()
        y = np.asarray(y, dtype=float)
        if y.ndim > W.ndim - 1:
            W, depths = W[..., None, :], depths[..., None, :]
        return np.sum(W * (depths <= y[..., None]), axis=-1)

    def _velocity_terms(self, v):
        """``v[..., None]`` and the weights, means and SDs of ``v_K`` under :meth:`pooled`."""
        W, _, means, covs = self.pooled()
        v = np.asarray(v, dtype=float)
        m, s = means[..., 1], np.sqrt(covs[..., 1, 1])
        if v.ndim > W.ndim - 1:
            W, m, s = W[..., None, :], m[..., None, :], s[..., None, :]
        return v[..., None], W, m, s

    def velocity_cdf(self, v):
        """``P(v_K <= v)`` under :meth:`pooled`, ``v`` (...) or (..., G)."""
        v, W, m, s = self._velocity_terms(v)
        return np.sum(W * ndtr((v - m) / s), axis=-1)

    def velocity_pdf(self, v):
        """The density of ``v_K`` under :meth:`pooled`; shapes as :meth:`velocity_cdf`."""
        v, W, m, s = self._velocity_terms(v)
        z = (v - m) / s
        return np.sum(W * np.exp(-0.5 * z**2) / (np.sqrt(2 * np.pi) * s), axis=-1)

    def moments(self) -> ParticleMoments:
        """The replicas' average of :meth:`replica_moments`, shape (...)."""
        return ParticleMoments(*(np.mean(m, axis=-1) for m in self.replica_moments()))

    def standard_errors(self) -> ParticleMoments:
        """Standard errors of :meth:`moments`, shape (...): see the module docstring."""
        R = self.replicas
        if R < 2:
            return ParticleMoments(*(np.full(m.shape[:-1], np.nan) for m in self.replica_moments()))
        return ParticleMoments(
            *(np.std(m, axis=-1, ddof=1) / np.sqrt(R) for m in self.replica_moments())
        )

    def errors(self) -> tuple[ParticleMoments, np.ndarray]:
        """Monte Carlo errors of the moments and the collapse flag, shape (...).

        :func:`depthcore.particles.resampling.replica_errors` of :meth:`replica_moments`.
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

    ``y = m_y - s Phi^{-1}(V)``, ``V`` uniform on ``(0, Phi(m_y / s)]``, in log space.
    ``prior_mean`` (..., 3), ``prior_cov`` (..., 3, 3), ``shape`` ``(...) + (J,)``.
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

    The target is ``pi_K`` (module docstring), ``bank.log_weight`` up to a constant;
    each step reruns the filter at ``y' = y + scale eps`` (textbook 19.2.3) and
    accepts with probability ``min(1, pi_K(y') / pi_K(y))``.

    Parameters
    ----------
    bank : depthcore.exact.bank.Bank
        Nodes (..., J).
    scale : array_like, shape (...) or ()
    moves : int
    rng : numpy.random.Generator

    Returns
    -------
    bank : depthcore.exact.bank.Bank
        Without ``history``.
    acceptance : ndarray, shape (...)
        NaN for ``moves = 0``.
    """
    if not isinstance(bank, bk.Bank):
        raise ValueError(f"bank must be a Bank, got {type(bank).__name__}")
    scale = checks.finite_array(scale, "scale")
    if not np.all(scale > 0):
        raise ValueError(f"scale must be positive, got minimum {float(np.min(scale)):.6g}")
    moves = _moves(moves)
    rng = checks.generator(rng)

    floor = bank.floor[..., None]  # depths at frame 1 that reach the camera have no weight

    def target(proposal):
        inside = proposal > floor
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            rerun = bk.filter_bank(
                np.where(inside, proposal, floor + 1.0),
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
        *(getattr(bank, f)[rows] for f in bk.Bank._fields if f not in ("history", "law")),
        history=None,
        law=bank.law,
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
    """Normalise the new weights, record the ESS and ``report``, resample and move."""
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

    Each particle predicts ``N(x / y, P_xx / y**2 + rho**2)`` after the step ``s``
    (``x + s v``, ``P_xx + 2 s P_xv + s**2 P_vv``), weighted over ``R``. ``log_w``
    (..., R, J), ``mu`` (...), ``depth_ahead`` ``(s, y)`` with ``y`` (..., R, J);
    returns three arrays (...).
    """
    s, y = depth_ahead
    s = np.asarray(s)[..., None, None]
    x = bank.mean[..., 0] + s * bank.mean[..., 1]
    var_x = bank.cov[..., 0, 0] + 2 * s * bank.cov[..., 0, 1] + s * s * bank.cov[..., 1, 1]
    r2 = np.asarray(rho, dtype=float)[..., None, None] ** 2
    shape = log_w.shape[:-2] + (-1,)
    R = log_w.shape[-2]
    reached = y <= 0  # particles the step brings to the camera: no weight
    log_w = np.where(reached, -np.inf, log_w)
    y = np.where(reached, 1.0, y)
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
    """Frame 1: depths from the truncated prior, each filter updated by ``mu_1`` (or NaN)."""
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

    The log weights gain the innovations' log densities (textbook 19.2.2, 19.5.2),
    then particles are resampled and moved where the ESS is low (:func:`rejuvenate`).

    Parameters
    ----------
    state : RBPF
    mu_next : float or array_like, shape (...)
        ``NaN``: no bearing.
    rng : numpy.random.Generator or numpy.random.SeedSequence
    rho : float or array_like, shape (...), or None
        ``None``: the filter's.
    step : float or array_like, shape (...)
        The depth's signed change since frame ``K``, nonzero (negative: the camera
        approaches).
    gate : float or None
        See :mod:`depthcore.problem.predictive`.

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

    The bearings are taken one at a time (:func:`step`); a ``NaN`` is predicted through.

    {parameters}
    n_particles : int
        ``J >= 2`` particles (depths) per replica.
    rng : numpy.random.Generator or numpy.random.SeedSequence
    {process_noise}
    replicas : int
        ``R >= 1`` independent clouds, for :meth:`RBPF.standard_errors`.
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
