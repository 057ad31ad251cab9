"""Self-calibration of the optimal filter: simulation-based calibration.

Recommended import: ``from depthcore.analysis import calibration``.

A Bayesian posterior is calibrated on average over truths drawn from its own
prior: if ``x ~ p(x)`` and ``mu ~ p(mu | x)``, then ``x`` is a draw from the
posterior ``p(x | mu)``, so the posterior CDF of any scalar function of the
state, evaluated at the truth (its probability integral transform, PIT), is
uniform on [0, 1] [cook2006]_, [talts2018]_. The check draws truths from the
prior on ``y_1 > 0`` (:func:`draw_from_prior`), runs the optimal filter
(:func:`pit_values`) and tests the PIT values at the last frame for uniformity.
Trials whose bearings have no noise-free solution in front (Eq. (7)) are left out:
a selection by the bearings alone, which keeps the PIT uniform. The prior must not
depend on the bearings (the paper's rule does, so its coverage need not be nominal).

References
----------
.. [cook2006] S. R. Cook, A. Gelman and D. B. Rubin, "Validation of software
   for Bayesian models using posterior quantiles", J. Comput. Graph. Statist.
   15(3), 2006.
.. [talts2018] S. Talts, M. Betancourt, D. Simpson, A. Vehtari and A. Gelman,
   "Validating Bayesian inference algorithms with simulation-based
   calibration", arXiv:1804.06788, 2018.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from depthcore.exact import optimal, posterior
from depthcore.problem import checks, model

#: Nominal levels of the central intervals whose coverage is reported.
LEVELS = (0.5, 0.68, 0.8, 0.9, 0.95, 0.99)
#: Equal-probability bins of the chi-square test of the PIT values.
BINS = 10


@dataclass(frozen=True)
class PriorDraws:
    """Truths drawn from the prior and their simulated bearings.

    Attributes
    ----------
    truth : ndarray, shape (n, 3)
        True states at the last frame of the kept trials.
    mu : ndarray, shape (n, N)
    n_behind : int
        Prior draws behind the camera.
    n_rejected : int
        Draws whose bearings had no noise-free solution in front.
    """

    truth: np.ndarray
    mu: np.ndarray
    n_behind: int
    n_rejected: int


def draw_from_prior(
    prior_mean,
    prior_cov,
    rho: float,
    n: int,
    rng: np.random.Generator,
    max_rounds: int = 100,
    frames: int = 3,
    process_noise: float = 0.0,
) -> PriorDraws:
    """Draw ``n`` truths from ``N(m, P)`` with ``y_1 > 0`` and simulate their bearings.

    Tracks by :func:`depthcore.problem.model.simulate` with ``frame=1``; the truth kept
    is the state at frame ``N``.

    Parameters
    ----------
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    rho : float
    n : int
        Truths in front of the camera to draw (fewer may be kept).
    rng : numpy.random.Generator
    max_rounds : int
        Rejection rounds before giving up.
    frames : int
        ``N >= 3``.
    process_noise : float

    Returns
    -------
    PriorDraws
    """
    mean = checks.finite_array(prior_mean, "prior_mean", (3,))
    chol = np.linalg.cholesky(checks.covariance(prior_cov, "prior_cov", 3))
    rho = checks.positive_scalar(rho, "rho")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"trials must be a positive integer, got {n!r}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    frames, q = _frames_and_noise(frames, process_noise)
    kept, behind = [], 0
    for _ in range(max_rounds):
        x1 = mean + rng.standard_normal((n, 3)) @ chol.T
        front = x1[:, 1] > 0
        behind += int(np.sum(~front))
        kept.append(x1[front])
        if sum(len(k) for k in kept) >= n:
            break
    else:
        raise ValueError(
            "prior_mean and prior_cov put almost no mass in front of the camera "
            f"(y_1 > 0): {behind} of {behind + sum(len(k) for k in kept)} draws behind it"
        )
    x1 = np.concatenate(kept)[:n]
    sim = model.draw_track(x1, frames, rho, q, rng, x1.shape[:-1], 1)  # checked above
    mu, last = sim.mu, sim.states[:, -1, :]
    ok = model.valid_measurements(mu[:, :3])  # the noise-free solution, Eq. (7), in front
    return PriorDraws(last[ok], mu[ok], behind, int(np.sum(~ok)))


def _frames_and_noise(frames, process_noise) -> tuple[int, float]:
    """``frames`` (3 to ``MAX_FRAMES``) and ``process_noise`` (>= 0), checked."""
    return checks.frames(frames), checks.nonnegative_scalar(process_noise, "process_noise")


def coverage(pit, levels=LEVELS) -> np.ndarray:
    """Fraction of PIT values inside each central interval: ``|u - 1/2| <= p / 2``.

    ``pit`` (n,), ``levels`` (L,); returns (L,).
    """
    u = np.asarray(pit, dtype=float)
    return np.array([np.mean(np.abs(u - 0.5) <= p / 2) for p in levels])


def uniformity(pit, bins: int = BINS) -> dict:
    """Tests of the PIT values against the uniform distribution on [0, 1].

    The Kolmogorov-Smirnov and the chi-square (``bins`` equal bins) statistics and
    p-values.
    """
    from scipy import stats

    u = np.asarray(pit, dtype=float)
    ks = stats.kstest(u, "uniform")
    counts = np.histogram(u, bins=bins, range=(0.0, 1.0))[0]
    chi2 = stats.chisquare(counts)
    return {
        "ks_statistic": float(ks.statistic),
        "ks_pvalue": float(ks.pvalue),
        "chi2_statistic": float(chi2.statistic),
        "chi2_pvalue": float(chi2.pvalue),
        "counts": counts.tolist(),
    }


@dataclass(frozen=True)
class SelfCalibration:
    """The optimal filter's PIT values over truths drawn from its prior.

    Attributes
    ----------
    draws : PriorDraws
    rho : float
    filter_rho : float
        The noise level simulated and assumed.
    depth_pit : ndarray, shape (n,)
    velocity_pit : ndarray, shape (n,)
    """

    draws: PriorDraws
    rho: float
    filter_rho: float
    depth_pit: np.ndarray
    velocity_pit: np.ndarray

    def summary(self, levels=LEVELS, bins: int = BINS) -> dict:
        """Coverage at ``levels`` and the uniformity tests, per quantity."""
        out = {"trials": int(len(self.depth_pit)), "levels": list(levels)}
        for name, pit in (("depth", self.depth_pit), ("velocity", self.velocity_pit)):
            out[name] = {"coverage": coverage(pit, levels).tolist(), **uniformity(pit, bins)}
        return out


def pit_values(
    mu, truth, rho: float, prior_mean, prior_cov, process_noise: float = 0.0, bank: bool = False
):
    """The optimal filter's posterior CDFs of the depth and velocity at the truth, at frame ``N``.

    :func:`depthcore.exact.optimal.batch_marginals` (Eqs. (13)-(16)) on three frames
    without process noise unless ``bank``; otherwise
    :func:`depthcore.exact.posterior.posterior`.

    Parameters
    ----------
    mu : ndarray, shape (n, N)
    truth : ndarray, shape (n, 3)
    rho : float
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    process_noise : float
    bank : bool

    Returns
    -------
    depth, velocity : ndarray, shape (n,)
        The PIT values.
    """
    if mu.shape[1] == 3 and process_noise == 0 and not bank:
        ref = optimal.batch_marginals(mu, rho, prior_mean, prior_cov)
        return ref.depth_cdf(truth[:, 1]), ref.velocity_cdf(truth[:, 2])
    mx = posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise)
    return mx.depth_cdf(truth[:, 1:2])[:, 0], mx.velocity_cdf(truth[:, 2:3])[:, 0]


def self_calibration(
    prior_mean,
    prior_cov,
    rho: float,
    trials: int,
    rng: np.random.Generator,
    filter_rho: float | None = None,
    chunk: int = 256,
    frames: int = 3,
    process_noise: float = 0.0,
    filter_process_noise: float | None = None,
    progress=None,
) -> SelfCalibration:
    """Simulation-based calibration of the optimal filter, Eqs. (6) and (13)-(16).

    Draws by :func:`draw_from_prior`, the filter of :func:`pit_values`.

    Parameters
    ----------
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    rho : float
    trials : int
    rng : numpy.random.Generator
    filter_rho : float, optional
        ``rho`` by default; another value makes a miscalibrated filter.
    chunk : int
        Trials integrated together.
    frames : int
    process_noise : float
    progress : callable, optional
        ``progress(done, total)`` after each chunk.
    filter_process_noise : float, optional
        ``process_noise`` by default.

    Returns
    -------
    SelfCalibration
    """
    frames, q = _frames_and_noise(frames, process_noise)
    draws = draw_from_prior(prior_mean, prior_cov, rho, trials, rng, frames=frames, process_noise=q)
    filter_rho = rho if filter_rho is None else checks.positive_scalar(filter_rho, "filter_rho")
    filter_q = (
        q
        if filter_process_noise is None
        else checks.nonnegative_scalar(filter_process_noise, "filter_process_noise")
    )
    depth, velocity = [], []
    for start in range(0, len(draws.mu), chunk):
        part = slice(start, start + chunk)
        d, v = pit_values(
            draws.mu[part], draws.truth[part], filter_rho, prior_mean, prior_cov, filter_q, q > 0
        )
        depth.append(d)
        velocity.append(v)
        if progress is not None:
            progress(min(start + chunk, len(draws.mu)), len(draws.mu))
    return SelfCalibration(
        draws, float(rho), float(filter_rho), np.concatenate(depth), np.concatenate(velocity)
    )
