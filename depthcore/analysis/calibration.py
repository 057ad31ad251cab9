"""Self-calibration of the optimal filter: simulation-based calibration.

Recommended import: ``from depthcore.analysis import calibration``.

A Bayesian posterior is calibrated on average over truths drawn from its own
prior: if ``x ~ p(x)`` and ``mu ~ p(mu | x)``, then ``x`` is a draw from the
posterior ``p(x | mu)``, so the posterior CDF of any scalar function of the
state, evaluated at the truth (its probability integral transform, PIT), is
uniform on [0, 1] [cook2006]_, [talts2018]_. Every central interval then
covers the truth at exactly its nominal rate. The check below draws truths
from the filter's prior ``N(m, P)`` restricted to the front support (the point
in front of the camera at every frame: depth ``y_1 > 0`` at the first frame),
simulates its bearings (the paper's three, or ``N`` frames with process noise
``q``, :func:`draw_from_prior`), runs the optimal filter
(:func:`depthcore.exact.optimal.batch_marginals`, or the bank of
:mod:`depthcore.exact.bank` beyond three frames) and tests the PIT values of the
depth and velocity at the last frame for uniformity.

Trials whose bearings have no noise-free solution in front of the camera
(Eq. (7) degenerate or ``c2 <= 2``) are left out, as in the Monte Carlo study.
That selection depends on the bearings alone, and for every kept ``mu`` the
truth is still a draw from ``p(x | mu)``: the PIT values of the kept trials
stay uniform.

The prior must not depend on the bearings: the paper's rule, which centres
the prior on each trial's own noise-free solution, is not a prior in this
sense, and the fixed-truth study's coverage need not be nominal.

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
        True states at time 3 of the kept trials.
    mu : ndarray, shape (n, 3)
        Their bearings.
    n_behind : int
        Prior draws rejected because the point was behind the camera.
    n_rejected : int
        Kept draws whose bearings had no noise-free solution in front of the camera.
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

    With ``frames = N > 3`` or ``process_noise = q > 0`` each truth is
    followed from frame 1 to frame ``N`` with accelerations ``a_k ~ N(0, q**2)``
    from frame 1 on (:func:`depthcore.problem.model.simulate` with ``frame=1``: the
    filter's own model, whose prior is on the state at frame 1, as drawing
    truths from the prior needs), and the truth kept is the state at
    frame ``N``; the trials kept are those whose first three bearings have a
    noise-free solution in front of the camera, a selection by the bearings
    alone.

    Parameters
    ----------
    prior_mean : array_like, shape (3,)
        Prior mean of the state at time 1.
    prior_cov : array_like, shape (3, 3)
    rho : float
        Noise standard deviation of the bearings, > 0.
    n : int
        Truths in front of the camera to draw, >= 1 (fewer trials are kept
        when some bearings have no noise-free solution in front).
    rng : numpy.random.Generator
    max_rounds : int
        Rejection rounds before giving up (a prior with almost no mass in front
        of the camera is refused).
    frames : int
        ``N``, from 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    process_noise : float
        ``q >= 0``.

    Returns
    -------
    PriorDraws
        ``truth`` is the state at frame ``N`` (time 3 for the paper's problem),
        ``mu`` the ``N`` bearings of each kept trial.
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

    Parameters
    ----------
    pit : array_like, shape (n,)
    levels : sequence of float, shape (L,)

    Returns
    -------
    ndarray, shape (L,)
    """
    u = np.asarray(pit, dtype=float)
    return np.array([np.mean(np.abs(u - 0.5) <= p / 2) for p in levels])


def uniformity(pit, bins: int = BINS) -> dict:
    """Tests of the PIT values against the uniform distribution on [0, 1].

    Returns the Kolmogorov-Smirnov statistic and p-value, and the chi-square
    statistic and p-value of ``bins`` equal bins (``bins - 1`` degrees of
    freedom). Under uniformity each p-value is itself uniform: at a
    false-alarm rate ``alpha`` a test rejects a calibrated filter with
    probability ``alpha``.
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
        The noise level the bearings were simulated with.
    filter_rho : float
        The noise level the filter assumed.
    depth_pit, velocity_pit : ndarray, shape (n,)
        Posterior CDFs of the depth and velocity at time 3, at the truth.
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

    For the paper's three frames with no process noise the filter is
    :func:`depthcore.exact.optimal.batch_marginals`, Eqs. (13)-(16), unless
    ``bank``; otherwise the exact N-frame filter, the bank of Kalman filters
    over depth (:func:`depthcore.exact.posterior.posterior`).

    Parameters
    ----------
    mu : ndarray, shape (n, N)
        Bearings of each trial, ``N >= 3``.
    truth : ndarray, shape (n, 3)
        The true state at frame ``N``.
    rho : float
        Noise level the filter assumes.
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    process_noise : float
        ``q >= 0`` the filter assumes.
    bank : bool
        Run the bank of Kalman filters on three frames without process noise too.

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

    For the paper's three frames with no process noise the filter is
    :func:`depthcore.exact.optimal.batch_marginals`; for ``frames = N > 3`` or
    ``process_noise > 0`` it is the exact N-frame filter, the bank of Kalman
    filters over depth (:func:`depthcore.exact.posterior.posterior`), and the PIT values
    are those of the depth and velocity at frame ``N``.

    Parameters
    ----------
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
        The filter's prior of the state at time 1, from which the truths are drawn.
    rho : float
        Noise level of the simulated bearings.
    trials : int
        Truths to draw (see :func:`draw_from_prior`).
    rng : numpy.random.Generator
    filter_rho : float, optional
        Noise level the filter assumes; ``rho`` by default. Another value makes
        a miscalibrated filter, to show the check's power.
    chunk : int
        Trials integrated together (memory grows with it).
    frames : int
        ``N``, the bearings of each trial (see :func:`draw_from_prior`).
    process_noise : float
        ``q >= 0`` of the simulated tracks.
    progress : callable, optional
        ``progress(done, total)``, called after each chunk with the truths
        filtered so far and their number.
    filter_process_noise : float, optional
        Process noise the filter assumes; ``process_noise`` by default. Another
        value makes a miscalibrated filter.

    Returns
    -------
    SelfCalibration
        The PIT values are at frame ``N``.
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
