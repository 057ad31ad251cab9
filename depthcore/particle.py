"""A particle filter (sampling-importance-resampling) on the paper's problem.

Recommended import: ``from depthcore import particle``.

Implements the particle filter of Prince, section 19.5 [prince2012]_ (the
bootstrap filter of [gordon1993]_) for the three measurements and the prior of
the paper, with a proposal that keeps it from collapsing. The state at time 1
is drawn from a distribution ``q``, weighted by ``prior / q``, and then, for
``k = 1, 2, 3``: moved deterministically by ``G`` (Eq. (1)), reweighted by the
likelihood of ``mu_k`` (Eq. (4)), and (optionally, see below) resampled when
the effective sample size falls below ``ess_threshold * N``. Weights are kept
as logarithms and normalised by log-sum-exp with the maximum subtracted. A particle whose depth
is ``<= 0`` at any frame gets weight zero: the point is in front of the camera,
so the filter targets the optimal posterior restricted to ``y3 > 2``, as
:func:`depthcore.optimal.marginals` does with ``support="front"``.

Why the bootstrap filter collapses. The motion is deterministic: nothing ever
spreads the particles again, so the filter can only reweight (and duplicate)
the particles it drew at time 1. With ``proposal="prior"`` they come from the
prior ``N(m, 1000 I)``, whose SD is 31.6 in every component, while three
bearings with noise ``rho = 1/200`` pin it down to about a unit in depth and a
few tenths in position and velocity. On Fig. 2 the ESS after ``mu_1`` is about
0.3 % of ``N`` and after ``mu_2`` one or two particles, for ``N`` from ``1e3``
to ``1e5``: the estimate is whichever particle happens to fit best. (After a
resampling step ``ess`` counts the copies of a particle separately;
:meth:`ParticleResult.distinct_ess` pools them.)

How the proposal avoids it (``proposal="second_order"``, the default). The
particles are drawn where the posterior is: from a multivariate Student t
distribution with ``df`` degrees of freedom centred on the mean of the
second-order Gaussian ``p_s`` (Eq. (8)) of the state at time 3, with scale
matrix ``inflation**2`` times its covariance, and pulled back to time 1 by
``G^{-2}``. The pull-back is affine with unit Jacobian (``F^{-2}`` is unit
upper triangular), so the density of the time-1 particles is ``q`` at their
image at time 3, and the initial log weight is ``log prior - log q``. The heavy
t tails and the inflation cover the parts of the optimal posterior that the
Gaussian ``p_s`` misses (its depth marginal is skewed and, with a broad prior,
heavy-tailed), so the weights ``prior * likelihood / q`` vary little where the
posterior has mass. The defaults ``df = 1`` (Cauchy tails) and ``inflation =
1.5`` were chosen over ``df`` in 1-4 and ``inflation`` in 1.2-3 on Figs. 2, 3,
5 and on 100 noisy triples around Fig. 2's point: they keep the RMS error of
the means and SDs at about 1.5 times the ideal ``sd / sqrt(N)`` (2.5 at worst
among the triples) and 3.5-4.5 times on Fig. 3 (``df = 2, inflation = 1.2``
does a little better on the easy cases and twice as badly on Fig. 3 and the
worst triples). The ESS is then about ``0.43 N`` on
Figs. 2, 4, 5 and 6 and ``0.2 N`` on Fig. 3.

Because ``q`` already anticipates all three measurements, the intermediate
targets are chosen to match it ([delmoral2006]_: any sequence of intermediate
distributions may be used as long as the last is the posterior): after
``mu_k`` the particles target

    pi_k(x) ~ prior(x1) prod_{j <= k} L_j(x) prod_{j > k} Lt_j(x),

where ``Lt_j(x) = exp(-(g_j . (x3 - c))**2 / (2 rho**2))`` is the linearised
likelihood of ``mu_j`` about the noise-free state ``c`` (Eq. (7)) -- the
factors whose product with the prior is ``p_s`` itself. So the initial log
weight also carries ``sum_j log Lt_j``, and step ``k`` adds
``log L_k - log Lt_k``. After ``mu_3`` every ``Lt`` has been swapped for the
exact ``L`` and the weights are ``prior * L_1 L_2 L_3 / q``, the importance
weights of the posterior. On the way each ``pi_k`` stays close to ``q``, so the
ESS after every step measures how well the particles fit: without the
look-ahead, the weights after ``mu_1`` alone would be those of the broad wedge
``prior * L_1`` seen through particles concentrated near ``p_s``, with an ESS
below 1 % of ``N`` even though the final weights are good. With
``proposal="prior"`` there is no look-ahead and the filter is the textbook one.

Resampling. Systematic (default), multinomial and residual resampling share the
signature ``resampler(W, rng, M=None) -> indices``, and the filter resamples
before a move when the ESS is below ``ess_threshold * N``. The usual SIR rule
is ``ess_threshold = 0.5``; the default here is ``0``, never, because the
motion is deterministic: duplicated particles are never diversified again, so
resampling cannot improve the final estimates, and it commits the particles to
the intermediate target of the step at which it fires, whose tails may differ
from the posterior's. The deliberately broad default proposal starts below
``N / 2``, so the rule ``0.5`` fires on every scenario: on Fig. 2 it triples
the RMS error at ``N = 4000`` (4.8 instead of 1.6 times ``sd / sqrt(N)`` for
the depth mean, 6.9 instead of 1.1 for its SD), and on Fig. 3, whose
posterior (depth ``20.7 +- 13.7``) is far from ``p_s`` (``10.0 +- 2.2``), the
depth mean then comes out about 0.5 posterior SDs too low, at ``N = 4000`` and
still at ``N = 50000``, against 0.002 SDs without resampling. With
``ess_threshold = 0`` the filter is importance sampling of the time-1 state
and ``resampler`` is unused.

Why the estimates converge to the optimal filter. Without resampling the final
particles are an importance sample of the time-3 posterior ``p_o`` restricted
to ``y > 2``, with weights proportional to ``p_o / q``. ``q`` is positive
everywhere, so self-normalised weighted averages converge almost surely to the
posterior expectations as ``N`` grows (the strong law of large numbers), and
since ``q`` has polynomial tails while ``p_o`` inherits the Gaussian tails of
the prior, ``E_q[(p_o / q)**2]`` is finite and the error falls as
``1 / sqrt(N)`` (the central limit theorem; delta method for the SDs). With
resampling the limits still hold, each resampling step being an unbiased
selection [douc2005]_, but as Fig. 3 shows ``N`` may have to be huge. The
means and SDs of the depth ``y`` and velocity ``v`` therefore approach the
exact ones of :func:`depthcore.optimal.marginals`, with Monte Carlo standard
errors estimated by :meth:`ParticleResult.standard_errors`.

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

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.special import gammaln, logsumexp

from . import _checks, model
from .gaussian import INDEX, Gaussian
from .second_order import noise_free_states, second_order_batch

PROPOSALS = ("second_order", "prior")
#: Default degrees of freedom of the Student t proposal.
DEFAULT_DF = 1.0
#: Default factor on the second-order SDs in the proposal's scale matrix.
DEFAULT_INFLATION = 1.5


# --- resampling ------------------------------------------------------------------------


def _weights(W, M) -> tuple[np.ndarray, int]:
    """Check normalised weights ``W`` (..., N) and the number of draws ``M``."""
    W = _checks.finite_array(W, "W")
    if W.ndim < 1 or W.shape[-1] < 1:
        raise ValueError(f"W must have shape (..., N) with N >= 1, got shape {W.shape}")
    if np.any(W < 0):
        raise ValueError(f"W must be non-negative, got minimum {float(W.min()):.3g}")
    total = W.sum(axis=-1)
    if np.any(np.abs(total - 1.0) > 1e-9):
        raise ValueError(f"W must sum to 1 along its last axis, got sums {np.unique(total)[:5]}")
    M = W.shape[-1] if M is None else _count(M, "M")
    return W / total[..., None], M


def _count(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def _indices(counts) -> np.ndarray:
    """Indices ``(..., M)`` that repeat particle ``i`` ``counts[..., i]`` times (rows sum to M)."""
    counts = np.asarray(counts)
    *batch, N = counts.shape
    M = int(counts.reshape(-1, N)[0].sum()) if counts.size else 0
    flat = np.repeat(np.tile(np.arange(N), int(np.prod(batch, dtype=int))), counts.ravel())
    return flat.reshape(tuple(batch) + (M,))


def systematic(W, rng: np.random.Generator, M: int | None = None) -> np.ndarray:
    """Systematic resampling, batched over the leading axes of ``W``.

    One uniform ``U`` per row; the points ``(U + j) / M``, ``j = 0 .. M-1``,
    select particle ``i`` when they fall in ``[C_{i-1}, C_i)`` with ``C`` the
    cumulative weights [douc2005]_. Particle ``i`` is drawn ``floor(M W_i)`` or
    ``ceil(M W_i)`` times.

    Parameters
    ----------
    W : array_like, shape (..., N)
        Normalised weights (each row sums to 1).
    rng : numpy.random.Generator
    M : int, optional
        Number of draws; ``N`` by default.

    Returns
    -------
    ndarray of int, shape (..., M)
        Sorted indices into the last axis of ``W``.
    """
    W, M = _weights(W, M)
    _check_rng(rng)
    U = rng.random(W.shape[:-1])
    C = np.cumsum(W, axis=-1)
    C[..., -1] = 1.0
    # Points below C_i: #{j in 0..M-1 : j < M C_i - U} = clip(ceil(M C_i - U), 0, M).
    below = np.clip(np.ceil(M * C - U[..., None]), 0, M).astype(np.int64)
    return _indices(np.diff(below, axis=-1, prepend=0))


def multinomial(W, rng: np.random.Generator, M: int | None = None) -> np.ndarray:
    """Multinomial resampling: ``M`` independent draws from the weights, batched.

    Parameters and returns as :func:`systematic`; particle ``i`` is drawn
    ``M W_i`` times on average.
    """
    W, M = _weights(W, M)
    _check_rng(rng)
    return _indices(rng.multinomial(M, W))


def residual(W, rng: np.random.Generator, M: int | None = None) -> np.ndarray:
    """Residual resampling, batched.

    Particle ``i`` is kept ``floor(M W_i)`` times, and the remaining ``R = M -
    sum_i floor(M W_i)`` draws are multinomial with probabilities proportional
    to the residuals ``M W_i - floor(M W_i)`` [douc2005]_. (filterpy's
    ``residual_resample``, in 1.4.5 and 2.0.0, computes ``weights -
    num_copies``, i.e. ``W_i - floor(N W_i)``, which is negative for every
    copied particle; the residual is ``N W_i - floor(N W_i)``.) Parameters and
    returns as :func:`systematic`; particle ``i`` is drawn at least
    ``floor(M W_i)`` times and ``M W_i`` times on average.
    """
    W, M = _weights(W, M)
    _check_rng(rng)
    floor = np.floor(M * W)
    rest = M * W - floor
    R = M - floor.sum(axis=-1).astype(np.int64)
    total = rest.sum(axis=-1, keepdims=True)
    p = np.where(total > 0, rest / np.where(total > 0, total, 1.0), 1.0 / W.shape[-1])
    return _indices(floor.astype(np.int64) + rng.multinomial(R, p))


RESAMPLERS = {"systematic": systematic, "multinomial": multinomial, "residual": residual}


def normalise(log_w) -> np.ndarray:
    """Normalise log weights along the last axis: ``log W = log w - logsumexp(log w)``.

    Parameters
    ----------
    log_w : array_like, shape (..., N)
        Unnormalised log weights; ``-inf`` is weight zero.

    Returns
    -------
    ndarray, shape (..., N)
        ``logsumexp`` of each row is 0.
    """
    log_w = np.asarray(log_w, dtype=float)
    top = np.max(log_w, axis=-1, keepdims=True)
    if not np.all(np.isfinite(top)):
        raise ValueError("log_w has a row with no positive, finite weight")
    return log_w - (top + np.log(np.sum(np.exp(log_w - top), axis=-1, keepdims=True)))


def effective_sample_size(log_w) -> np.ndarray:
    """Kish's effective sample size ``1 / sum_i W_i**2`` from (unnormalised) log weights.

    Computed as ``exp(2 logsumexp(log w) - logsumexp(2 log w))``.

    Parameters
    ----------
    log_w : array_like, shape (..., N)

    Returns
    -------
    ndarray, shape (...)
        Between 1 and ``N``.
    """
    log_w = np.asarray(log_w, dtype=float)
    return np.exp(2.0 * logsumexp(log_w, axis=-1) - logsumexp(2.0 * log_w, axis=-1))


# --- results ---------------------------------------------------------------------------


class ParticleMoments(NamedTuple):
    """Weighted means and SDs of the depth ``y`` and velocity ``v`` at time 3.

    Floats for one filter, arrays of shape (B,) for a batch; the field names
    are those of :class:`depthcore.optimal.Moments`.
    """

    depth_mean: np.ndarray
    depth_sd: np.ndarray
    velocity_mean: np.ndarray
    velocity_sd: np.ndarray


def _moments(x, W) -> tuple[np.ndarray, np.ndarray]:
    """Weighted means and SDs of ``x`` (..., N) with weights ``W`` (..., N)."""
    mean = np.sum(W * x, axis=-1)
    return mean, np.sqrt(np.sum(W * (x - mean[..., None]) ** 2, axis=-1))


def _standard_errors(x, W) -> tuple[np.ndarray, np.ndarray]:
    """Delta-method standard errors of the weighted mean and SD of ``x`` (..., N).

    For self-normalised weights the mean ``m = sum W x`` has variance about
    ``sum W**2 (x - m)**2``, and the variance ``s2 = sum W (x - m)**2`` about
    ``sum W**2 ((x - m)**2 - s2)**2``; the SD's standard error is that of
    ``s2`` over ``2 s``.
    """
    mean, sd = _moments(x, W)
    d2 = (x - mean[..., None]) ** 2
    se_mean = np.sqrt(np.sum(W**2 * d2, axis=-1))
    se_var = np.sqrt(np.sum(W**2 * (d2 - sd[..., None] ** 2) ** 2, axis=-1))
    # All the weight on one value (a collapsed filter): the SD's error is unknown.
    with np.errstate(divide="ignore", invalid="ignore"):
        return se_mean, np.where(sd > 0, se_var / (2.0 * sd), np.inf)


def _freeze(result):
    """Store read-only copies of a result's arrays."""
    for name in ("particles", "log_weights", "ess", "resampled", "ancestors"):
        a = np.array(getattr(result, name))
        a.setflags(write=False)
        object.__setattr__(result, name, a)


def _distinct_ess(ancestors, W) -> np.ndarray:
    """``1 / sum_a (sum_{i: ancestor i = a} W_i)**2`` along the last axis."""
    N = W.shape[-1]
    rows = np.arange(W.size // N).reshape(W.shape[:-1] + (1,))
    pooled = np.bincount((ancestors + N * rows).ravel(), weights=W.ravel(), minlength=W.size)
    return 1.0 / np.sum(pooled.reshape(W.shape) ** 2, axis=-1)


@dataclass(frozen=True)
class ParticleResult:
    """The particle filter's weighted particles at time 3, for one triple.

    Built by :func:`particle_filter`.

    Attributes
    ----------
    particles : ndarray, shape (N, 3)
        States ``(x, y, v)`` at time 3.
    log_weights : ndarray, shape (N,)
        Normalised: ``logsumexp(log_weights) == 0``; ``-inf`` is weight zero.
    ess : ndarray, shape (3,)
        Effective sample size after each measurement.
    resampled : ndarray of bool, shape (3,)
        Whether the particles were resampled before measurement ``k + 1`` (never before the first).
    ancestors : ndarray of int, shape (N,)
        The time-1 draw each particle descends from; resampling duplicates
        particles, and the motion being deterministic, duplicates stay identical.
    proposal : str
    """

    particles: np.ndarray
    log_weights: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    ancestors: np.ndarray
    proposal: str

    def __post_init__(self):
        _freeze(self)

    def distinct_ess(self) -> float:
        """The ESS with the weights of identical particles (same ancestor) pooled.

        After resampling, ``ess`` counts ``N`` copies of one particle as ``N``;
        this counts them as one.
        """
        return float(_distinct_ess(self.ancestors, self.weights))

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
        mean, sd = _moments(self.particles[:, _component(component)], self.weights)
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
        y, v = (_standard_errors(self.particles[:, INDEX[c]], W) for c in "yv")
        return ParticleMoments(float(y[0]), float(y[1]), float(v[0]), float(v[1]))

    def density(self, component: str, grid, method: str = "kde",
                bandwidth: float | None = None) -> np.ndarray:
        """Weighted density estimate of one component's marginal on ``grid``.

        Parameters
        ----------
        component : {"x", "y", "v"}
        grid : array_like, shape (G,)
            Increasing points. For ``method="histogram"`` they must be evenly
            spaced: they are the centres of the bins.
        method : {"kde", "histogram"}
            ``"kde"``: a weighted Gaussian kernel density estimate;
            ``"histogram"``: the weight in each bin over its width (weight
            outside the bins is dropped).
        bandwidth : float, optional
            The kernel SD for ``"kde"``; default Silverman's rule
            ``0.9 min(sd, IQR / 1.34) ESS**(-1/5)`` with weighted quantiles.

        Returns
        -------
        ndarray, shape (G,)
        """
        x = self.particles[:, _component(component)]
        W = self.weights
        grid = _checks.finite_array(grid, "grid")
        if grid.ndim != 1 or grid.size < 2 or not np.all(np.diff(grid) > 0):
            raise ValueError(
                f"grid must be increasing with at least 2 points, got shape {grid.shape}")
        if method == "histogram":
            step = np.diff(grid)
            if not np.allclose(step, step[0], rtol=1e-9, atol=0):
                raise ValueError("grid must be evenly spaced for method='histogram'")
            edges = np.concatenate([grid - step[0] / 2, grid[-1:] + step[0] / 2])
            return np.histogram(x, bins=edges, weights=W)[0] / step[0]
        if method != "kde":
            raise ValueError(f"method must be 'kde' or 'histogram', got {method!r}")
        if bandwidth is None:
            h = _silverman(x, W)
        else:
            h = _checks.positive_scalar(bandwidth, "bandwidth")
        keep = W > 0
        z = (grid[:, None] - x[keep]) / h
        return np.exp(-0.5 * z**2) @ W[keep] / (np.sqrt(2.0 * np.pi) * h)


def _silverman(x, W) -> float:
    """Silverman's bandwidth ``0.9 min(sd, IQR / 1.34) n**(-1/5)`` with weights (n the ESS)."""
    order = np.argsort(x)
    cdf = np.cumsum(W[order])
    q1, q3 = np.interp([0.25, 0.75], cdf - W[order] / 2, x[order])
    sd = float(_moments(x, W)[1])
    spread = min(sd, (q3 - q1) / 1.34) if q3 > q1 else sd
    if not spread > 0:
        raise ValueError("the particles have a single distinct value: pass bandwidth")
    return 0.9 * spread * (1.0 / np.sum(W**2)) ** -0.2


def _component(component: str) -> int:
    if component not in INDEX:
        raise ValueError(f"component must be one of {tuple(INDEX)}, got {component!r}")
    return INDEX[component]


@dataclass(frozen=True)
class ParticleBatch:
    """The particle filter's results for ``B`` triples at once; built by :func:`run`.

    Attributes
    ----------
    particles : ndarray, shape (B, N, 3)
    log_weights : ndarray, shape (B, N)
        Normalised along the last axis.
    ess : ndarray, shape (B, 3)
    resampled : ndarray of bool, shape (B, 3)
    ancestors : ndarray of int, shape (B, N)
    proposal : str
    """

    particles: np.ndarray
    log_weights: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    ancestors: np.ndarray
    proposal: str

    def __post_init__(self):
        _freeze(self)

    def distinct_ess(self) -> np.ndarray:
        """:meth:`ParticleResult.distinct_ess` for each trial, shape (B,)."""
        return _distinct_ess(self.ancestors, np.exp(self.log_weights))

    def __len__(self) -> int:
        return self.log_weights.shape[0]

    def trial(self, i: int) -> ParticleResult:
        """The result of trial ``i``."""
        return ParticleResult(self.particles[i], self.log_weights[i], self.ess[i],
                              self.resampled[i], self.ancestors[i], self.proposal)

    def moments(self) -> ParticleMoments:
        """Weighted means and SDs of the depth and velocity, arrays of shape (B,)."""
        W = np.exp(self.log_weights)
        return ParticleMoments(*_moments(self.particles[..., 1], W),
                               *_moments(self.particles[..., 2], W))

    def standard_errors(self) -> ParticleMoments:
        """Delta-method standard errors of :meth:`moments`, arrays of shape (B,)."""
        W = np.exp(self.log_weights)
        return ParticleMoments(*_standard_errors(self.particles[..., 1], W),
                               *_standard_errors(self.particles[..., 2], W))


# --- the filter ------------------------------------------------------------------------


def _check_rng(rng):
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")


def _degrees_of_freedom(df) -> float:
    """Check ``df``: positive, or ``inf`` for a Gaussian proposal."""
    try:
        if np.ndim(df) == 0 and np.isposinf(float(df)):
            return float("inf")
    except (TypeError, ValueError):
        pass
    return _checks.positive_scalar(df, "df")


def _student_t(mean, cov, df: float, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``n`` points per row from multivariate t laws; return them and their log densities.

    ``mean`` (B, 3), ``cov`` (B, 3, 3) the scale matrices; ``df = inf`` is the
    Gaussian. Returns ``x`` (B, n, 3) and ``log q`` (B, n).
    """
    L = np.linalg.cholesky(cov)
    z = rng.standard_normal(mean.shape[:1] + (n, 3))
    log_det = np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)[:, None]
    delta = np.sum(z**2, axis=-1)
    if np.isinf(df):
        scale = np.ones(delta.shape)
        log_q = -0.5 * delta - 1.5 * np.log(2.0 * np.pi) - log_det
    else:
        scale = np.sqrt(df / rng.chisquare(df, delta.shape))
        delta = delta * scale**2  # the Mahalanobis distance of the t draw
        log_q = (gammaln((df + 3.0) / 2.0) - gammaln(df / 2.0) - 1.5 * np.log(df * np.pi)
                 - log_det - 0.5 * (df + 3.0) * np.log1p(delta / df))
    x = mean[:, None, :] + scale[..., None] * np.einsum("bij,bnj->bni", L, z)
    return x, log_q


def _gaussian_logpdf(x, mean, cov) -> np.ndarray:
    """Log density of ``N(mean, cov)`` (mean (B, 3), one cov (3, 3)) at ``x`` (B, n, 3)."""
    L = np.linalg.cholesky(cov)
    d = (x - mean[:, None, :]).reshape(-1, 3)
    z = np.linalg.solve(L, d.T).T.reshape(x.shape)
    return (-0.5 * np.sum(z**2, axis=-1) - np.sum(np.log(np.diag(L)))
            - 1.5 * np.log(2.0 * np.pi))


def _log_likelihood(mu, x, rho) -> np.ndarray:
    """Eq. (4) for ``mu`` (B,), states ``x`` (B, n, 3), ``rho`` (B,); ``-inf`` where ``y <= 0``."""
    front = x[..., 1] > 0
    h = np.where(front, x[..., 0], 0.0) / np.where(front, x[..., 1], 1.0)
    r = (h - mu[:, None]) / rho[:, None]
    log_l = -0.5 * r**2 - np.log(rho)[:, None] - 0.5 * np.log(2.0 * np.pi)
    return np.where(front, log_l, -np.inf)


def _linearised_log_likelihood(x3, c, g, rho, k: int) -> np.ndarray:
    """``log Lt_k``: the log likelihood of ``mu_{k+1}`` linearised about ``c``, at states ``x3``.

    ``-(g_k . (x3 - c))**2 / (2 rho**2)`` with ``g_k`` (B, 3) the gradient of
    the residual of ``mu_{k+1}`` at ``c`` (Eq. (8)); ``x3`` (B, n, 3) at time 3.
    """
    r = np.einsum("bnj,bj->bn", x3 - c[:, None, :], g[:, k]) / rho[:, None]
    return -0.5 * r**2


def _initial(mu, rho, prior_mean, prior_cov, N, rng, proposal, df, inflation):
    """Time-1 particles (B, N, 3), their log weights (B, N) and the look-ahead terms."""
    if proposal == "prior":
        L = np.linalg.cholesky(prior_cov)
        x1 = prior_mean[:, None, :] + rng.standard_normal((len(mu), N, 3)) @ L.T
        return x1, np.zeros(x1.shape[:2]), None
    mean_s, cov_s = second_order_batch(mu, rho, prior_mean, prior_cov)
    x3, log_q = _student_t(mean_s, inflation**2 * cov_s, df, N, rng)
    c = noise_free_states(mu)
    g = np.stack([model.observation_vector(model.G(c, k - 2)) @ model.G_linear(k - 2)
                  for k in range(3)], axis=-2)  # (B, 3, 3): rows g_k
    look_ahead = (c, g)
    log_lt = sum(_linearised_log_likelihood(x3, c, g, rho, k) for k in range(3))
    x1 = model.G(x3, -2)
    return x1, _gaussian_logpdf(x1, prior_mean, prior_cov) - log_q + log_lt, look_ahead


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


def run(mu, rho, prior_mean, prior_cov, n_particles: int, rng: np.random.Generator,
        proposal: str = "second_order", resampler: str = "systematic",
        ess_threshold: float = 0.0, df: float = DEFAULT_DF,
        inflation: float = DEFAULT_INFLATION) -> ParticleBatch:
    """The particle filter for ``B`` triples of measurements at once, vectorised over trials.

    Parameters
    ----------
    mu : array_like, shape (B, 3)
        One triple per row, each checked as in :func:`depthcore._checks.measurements`.
    rho : float or array_like, shape (B,)
        Noise standard deviation, > 0.
    prior_mean : array_like, shape (3,) or (B, 3)
        Prior mean of the state at time 1.
    prior_cov : array_like, shape (3, 3)
        Prior covariance, symmetric positive definite.
    n_particles : int
        ``N >= 1`` particles per trial. Memory grows like ``B * N``: about
        ``200 B N`` bytes at the peak.
    rng : numpy.random.Generator
        The only source of randomness.
    proposal : {"second_order", "prior"}
        Where the time-1 particles come from (see the module docstring).
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
    ParticleBatch
    """
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim != 2 or mu.shape[1] != 3:
        raise ValueError(f"mu must have shape (B, 3), got shape {mu.shape}")
    B = mu.shape[0]
    rho = _checks.positive_array(rho, "rho")
    if rho.ndim and rho.shape != (B,):
        raise ValueError(f"rho must be a scalar or have shape ({B},), got shape {rho.shape}")
    rho = np.broadcast_to(rho, (B,))
    prior_mean = _checks.finite_array(prior_mean, "prior_mean")
    if prior_mean.shape not in ((3,), (B, 3)):
        raise ValueError(f"prior_mean must have shape (3,) or ({B}, 3), got {prior_mean.shape}")
    prior_cov = _checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.shape != (3, 3):
        raise ValueError(f"prior_cov must have shape (3, 3), got shape {prior_cov.shape}")
    mu, rho, prior_mean, prior_cov = _checks.batch_problem(mu, rho, prior_mean, prior_cov)
    rho = np.broadcast_to(rho, (B,))
    prior_mean = np.broadcast_to(prior_mean, (B, 3))
    N = _count(n_particles, "n_particles")
    _check_rng(rng)
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    if resampler not in RESAMPLERS:
        raise ValueError(f"resampler must be one of {tuple(RESAMPLERS)}, got {resampler!r}")
    threshold = float(_checks.finite_array(ess_threshold, "ess_threshold"))
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"ess_threshold must lie in [0, 1], got {threshold}")
    df = _degrees_of_freedom(df)
    inflation = _checks.positive_scalar(inflation, "inflation")

    x, log_w, look_ahead = _initial(mu, rho, prior_mean, prior_cov, N, rng, proposal, df, inflation)
    ess = np.zeros((B, 3))
    resampled = np.zeros((B, 3), dtype=bool)
    ancestors = np.broadcast_to(np.arange(N), (B, N))
    for k in range(3):
        if k > 0:
            resampled[:, k] = ess[:, k - 1] < threshold * N
            x, log_w, ancestors = _resample(x, log_w, ancestors, resampled[:, k], N, rng,
                                            RESAMPLERS[resampler])
            x = model.G(x)  # Eq. (1): the deterministic motion
        log_w = log_w + _log_likelihood(mu[:, k], x, rho)
        if look_ahead is not None:
            log_w = log_w - _linearised_log_likelihood(model.G(x, 2 - k), *look_ahead, rho, k)
        dead = ~np.any(np.isfinite(log_w), axis=-1)
        if np.any(dead):
            raise RuntimeError(
                f"every particle of trial {int(np.argmax(dead))} has zero weight after mu_{k + 1} "
                "(behind the camera); increase n_particles or use proposal='second_order'"
            )
        log_w = normalise(log_w)
        ess[:, k] = effective_sample_size(log_w)
    return ParticleBatch(x, log_w, ess, resampled, np.array(ancestors), proposal)


def particle_filter(mu, rho: float, prior: Gaussian, n_particles: int, rng: np.random.Generator,
                    proposal: str = "second_order", resampler: str = "systematic",
                    ess_threshold: float = 0.0, df: float = DEFAULT_DF,
                    inflation: float = DEFAULT_INFLATION) -> ParticleResult:
    """The particle filter for one triple of measurements.

    Parameters
    ----------
    mu : array_like, shape (3,)
        Checked by :func:`depthcore._checks.measurements`.
    rho : float
        Noise standard deviation, > 0.
    prior : Gaussian
        Density of the state at time 1.
    n_particles : int
        ``N >= 1``.
    rng : numpy.random.Generator
    proposal, resampler, ess_threshold, df, inflation
        As for :func:`run`.

    Returns
    -------
    ParticleResult
        Weighted particles at time 3, the ESS after each measurement; moments
        and densities of the depth and velocity.
    """
    mu = _checks.measurements(mu)
    rho = _checks.positive_scalar(rho, "rho")
    if not isinstance(prior, Gaussian):
        raise ValueError(f"prior must be a Gaussian, got {type(prior).__name__}")
    batch = run(mu[None], rho, prior.mean, prior.cov, n_particles, rng, proposal, resampler,
                ess_threshold, df, inflation)
    return batch.trial(0)
