"""A Monte Carlo study: which filter's estimate, and which stated uncertainty, to trust.

Recommended import: ``from depthcore import study``.

For a true state at time 3 (by default the noise-free state ``c`` of the
paper's Figure 2), each trial draws the bearings afresh: the paper's three,
or ``N`` with ``frames=N`` (up to ``depthcore._checks.MAX_FRAMES``), the point
moving on from time 3 to frame ``N``, with process noise ``q`` on its velocity
if ``process_noise=q``. It builds the prior by the paper's rule from that
trial's first three bearings (``prior="paper"``, as the paper does) or once
from the truth's noise-free bearings (``prior="fixed"``), runs every filter,
and scores its estimate of the state at the last frame:

* bias and RMSE of its depth and velocity means;
* coverage of its central 68 % and 95 % intervals: the truth lies in the
  central ``p`` interval when its marginal CDF at the truth is within
  ``p / 2`` of one half;
* mean NEES, ``(m - x)^T P^{-1} (m - x)`` over the whole state (3 for a
  filter whose covariance matches its error);
* the mean Hellinger distance from its depth marginal to the optimal one,
  when the optimal filter is among the filters run (it is run only when
  asked for; otherwise the distance is not computed and reported as ``None``);
* the fraction of lost tracks, counted beside the RMSE as the bearings-only
  tracking literature does (e.g. [ristic2004]_, chapter 6): a trial's track is
  lost when the error of its estimated position ``(x, y)`` at the last frame
  exceeds :data:`TRACK_LOSS` times the true distance of the point from the
  camera, ``|(x_est - x, y_est - y)| > TRACK_LOSS |(x, y)|`` (a relative
  threshold, the problem having no natural unit of length), or when the
  estimate is not finite. Reported with its binomial standard error
  ``sqrt(p (1 - p) / n)`` and, since that is 0 when no track is lost, the
  exact (Clopper-Pearson) one-sided 95 % upper bound on the loss probability.

Trials whose measurements have no noise-free solution in front of the camera
(Eq. (7) degenerate or ``c2 <= 2``) cannot run the second-order filter or the
paper's prior rule; they are counted and left out of every score.

:func:`study` streams the trials: it draws and filters them in chunks of at
most :data:`CHUNK` and keeps only running sums (:class:`Tally`), so its memory
does not grow with the number of trials.

References
----------
.. [ristic2004] B. Ristic, S. Arulampalam and N. Gordon, *Beyond the Kalman
   Filter: Particle Filters for Tracking Applications*, Artech House, 2004,
   chapter 6 (bearings-only tracking).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import beta

from . import _checks, model, optimal
from .estimates import exact_depth_range
from .filters import FILTERS, NAMES, check_names
from .gaussian import PAPER_PRIOR_SCALE, gaussian_logpdf, paper_prior_means
from .scenarios import SCENARIOS

PRIORS = ("paper", "fixed")
#: Nominal levels of the coverage scores, those of the central 68 % and 95 % intervals.
LEVELS = (0.68, 0.95)
#: Nominal levels of the calibration curve, central intervals from 5 % to 99 %.
CALIBRATION_LEVELS = tuple(np.round(np.concatenate([np.arange(0.05, 0.951, 0.05), [0.99]]), 2))
#: Particles per trial of the particle filter.
PARTICLES = 2000
#: Trials drawn and filtered together by :func:`study`: its memory is that of one chunk.
CHUNK = 100
#: A track is lost when its position error exceeds this fraction of the point's true distance.
TRACK_LOSS = 0.5
#: Confidence of the upper bound on the track-loss probability.
TRACK_LOSS_CONFIDENCE = 0.95


@dataclass(frozen=True)
class Trials:
    """Simulated measurements and the priors built from them.

    Attributes
    ----------
    truth : ndarray, shape (3,)
        True state at time 3.
    rho : float
    mu : ndarray, shape (N, 3)
        Measurements of the valid trials.
    prior_mean : ndarray, shape (N, 3)
    prior_cov : ndarray, shape (3, 3)
    n_rejected : int
        Trials drawn but left out (no noise-free solution in front of the camera).
    process_noise : float
        ``q``, the SD of the velocity's change per frame (0: the paper's model).
    states : ndarray, shape (N, 3), or None
        The true state at the last frame of each trial, where it is not
        ``truth`` (more than three frames); ``None`` otherwise.
    tracks : ndarray, shape (N, K, 3), or None
        The true state at every frame ``1 .. K`` of each trial, where asked
        for (:func:`simulate`'s ``tracks``); ``None`` otherwise.
    """

    truth: np.ndarray
    rho: float
    mu: np.ndarray
    prior_mean: np.ndarray
    prior_cov: np.ndarray
    n_rejected: int
    process_noise: float = 0.0
    states: np.ndarray | None = None
    tracks: np.ndarray | None = None

    @property
    def truths(self) -> np.ndarray:
        """The true state at the last frame of every trial, shape (N, 3)."""
        if self.states is not None:
            return self.states
        return np.broadcast_to(self.truth, (len(self.mu), 3))


@dataclass(frozen=True)
class Estimates:
    """One filter's results over the trials.

    Attributes
    ----------
    mean : ndarray, shape (N, 3)
    cov : ndarray, shape (N, 3, 3)
    depth_cdf, velocity_cdf : ndarray, shape (N,)
        The filter's marginal CDFs at the true depth and velocity.
    hellinger : ndarray, shape (N,), or None
        Hellinger distance from its depth marginal to the optimal one;
        ``None`` when the optimal filter was not run.
    truth : ndarray, shape (N, 3), or None
        The true state of each trial when it is not the tally's one truth.
    """

    mean: np.ndarray
    cov: np.ndarray
    depth_cdf: np.ndarray
    velocity_cdf: np.ndarray
    hellinger: np.ndarray | None
    truth: np.ndarray | None = None


def valid_triples(mu) -> np.ndarray:
    """Rows of ``mu`` (N, 3) with a noise-free solution, Eq. (7), in front of the camera."""
    return model.valid_measurements(mu)


def simulate(
    truth,
    rho: float,
    n: int,
    rng: np.random.Generator,
    prior: str = "paper",
    prior_scale: float = PAPER_PRIOR_SCALE,
    frames: int = 3,
    process_noise: float = 0.0,
    tracks: bool = False,
) -> Trials:
    """Draw ``n`` trials of ``frames`` measurements of ``truth`` and build their priors.

    Parameters
    ----------
    truth : array_like, shape (3,)
        True state at time 3; its depth must be positive at times 1-3.
    rho : float
    n : int
        Number of trials, >= 1.
    rng : numpy.random.Generator
    prior : {"paper", "fixed"}
        ``"paper"``: mean ``(c1 - 2 c3, c2 - 2, 0)`` from each trial's own
        noise-free solution; ``"fixed"``: the same rule applied once to the
        truth.
    prior_scale : float
        Prior covariance ``prior_scale * I``.
    frames : int
        ``N >= 3``: the point is followed on from time 3 to frame ``N``
        (:func:`depthcore.model.simulate` with ``frame=3``). The state at
        time 3 is ``truth`` in every trial: frames 1-3 are the noise-free
        motion through it, as for three frames, and the velocity's changes per
        frame, drawn with SD ``process_noise``, act between frames 3 .. N. The
        prior rule uses the first three measurements, and trials whose first
        three have no noise-free solution in front of the camera are left out,
        as with three frames (a selection by the measurement noise alone).
    process_noise : float
        ``q >= 0``.
    tracks : bool
        Keep every trial's true state at every frame (``Trials.tracks``,
        ``n * frames * 3`` numbers).
    """
    truth = _checks.finite_array(truth, "truth", (3,))
    frames = _checks.count(frames, "frames")
    if not 3 <= frames <= _checks.MAX_FRAMES:
        raise ValueError(f"frames must be from 3 to {_checks.MAX_FRAMES}, got {frames}")
    q = _checks.nonnegative_scalar(process_noise, "process_noise")
    rho = _checks.positive_scalar(rho, "rho")
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"trials must be a positive integer, got {n!r}")
    if prior not in PRIORS:
        raise ValueError(f"prior must be one of {PRIORS}, got {prior!r}")
    prior_scale = _checks.positive_scalar(prior_scale, "prior_scale")
    if not truth[1] - 2 > 0:
        raise ValueError(
            f"truth puts the point behind the camera: depth at time 1 is {truth[1] - 2:.6g}"
        )
    sim = model.simulate(truth, frames, rho, q, rng, size=int(n), frame=3)
    mu = sim.mu
    states = None if frames == 3 else sim.states[:, -1, :]
    keep = valid_triples(mu[:, :3])
    mu = mu[keep]
    if prior == "paper":
        c = model.noise_free_states(mu[:, :3])
    else:
        c = np.broadcast_to(truth, (len(mu), 3))
    mean = paper_prior_means(c)
    return Trials(
        truth,
        rho,
        mu,
        mean,
        prior_scale * np.eye(3),
        int(np.sum(~keep)),
        q,
        None if states is None else states[keep],
        sim.states[keep] if tracks else None,
    )


def gaussian_hellinger(reference: optimal.BatchMarginals, mean, cov) -> np.ndarray:
    """:func:`hellinger` for Gaussian filters: means (N, 3) and covariances (N, 3, 3).

    The filter's depth marginal (Eq. (13)) is the Gaussian with the depth
    component of the mean and covariance; returns shape (N,).
    """

    def log_q(y):
        return gaussian_logpdf(y[..., None], mean[:, None, 1:2], cov[:, None, 1:2, 1:2])

    return hellinger(reference, log_q, mean[:, 1], np.sqrt(cov[:, 1, 1]))


def hellinger(
    reference: optimal.BatchMarginals, log_q: Callable, q_mean, q_sd, n: int = 801
) -> np.ndarray:
    """Hellinger distance from depth densities ``q`` to the optimal ones, per trial.

    ``H^2 = 1 - int sqrt(p_o q) dy`` over ``y > 2`` by the trapezoid rule in
    ``t = log(y - 2)`` on ``n`` points spanning both densities (12 SDs of
    ``q`` and the optimal filter's quadrature range, which reaches its tail).

    Parameters
    ----------
    reference : BatchMarginals
    log_q : callable
        ``log q`` at depths of shape (N, n).
    q_mean, q_sd : ndarray, shape (N,)
        Where ``q`` lives, to place the grid.
    """
    t_lo, t_hi, offset = exact_depth_range(reference)
    with np.errstate(divide="ignore"):
        lo = np.maximum(
            np.minimum(np.log(np.maximum(q_mean - 12 * q_sd - offset, 0.0)), t_lo), t_lo - 10
        )
        hi = np.maximum(np.log(np.maximum(q_mean + 12 * q_sd - offset, 1e-300)), t_hi)
    t = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, n)
    y = offset + np.exp(t)
    log_pq = 0.5 * (reference.depth_log_pdf(y) + log_q(y)) + t
    bc = np.trapezoid(np.exp(log_pq), t, axis=1)
    return np.sqrt(np.clip(1.0 - bc, 0.0, 1.0))


def _estimates(trials: Trials, estimate, family, reference) -> Estimates:
    """Scores' inputs for a filter's batch ``estimate``, read from its family's scoring.

    The CDFs at the truths are the family's (:attr:`depthcore.estimates.Family.cdfs`).
    The Hellinger distance to ``reference`` is in closed form for a Gaussian
    result; for weighted depth draws (the particle filters) it is taken from
    a binned kernel density estimate with Scott's bandwidth for the effective
    sample size. Without ``reference`` there is no Hellinger distance.
    """
    mean, cov = estimate.mean, estimate.cov
    depth_cdf, velocity_cdf = family.cdfs(estimate, trials.truths)
    if reference is None:
        return Estimates(mean, cov, depth_cdf, velocity_cdf, None, trials.states)
    if family.gaussian:
        h = gaussian_hellinger(reference, mean, cov)
    else:
        depths, W = family.depth_draws(estimate)
        sd = np.sqrt(cov[:, 1, 1])
        ess = 1.0 / np.sum(W**2, axis=1)
        bandwidth = 1.06 * sd * ess**-0.2  # Scott's rule with the effective sample size
        h = hellinger(reference, _binned_kde(depths, W, bandwidth), mean[:, 1], sd)
    return Estimates(mean, cov, depth_cdf, velocity_cdf, h, trials.states)


def _binned_kde(samples, W, bandwidth, bins: int = 2048):
    """A weighted Gaussian kernel density estimate per row, by linear binning.

    Returns ``log_q(y)`` for depths ``y`` of shape (B, n): the weights are
    spread linearly onto ``bins`` equal bins spanning each row's samples plus
    six bandwidths, convolved with the kernel, and interpolated.
    """
    B = samples.shape[0]
    lo = np.min(samples, axis=1) - 6 * bandwidth
    hi = np.max(samples, axis=1) + 6 * bandwidth
    step = (hi - lo) / (bins - 1)
    pos = (samples - lo[:, None]) / step[:, None]
    left = np.clip(np.floor(pos).astype(int), 0, bins - 2)
    frac = pos - left
    rows = np.arange(B)[:, None] * bins
    grid_w = (
        np.bincount((rows + left).ravel(), (W * (1 - frac)).ravel(), B * bins)
        + np.bincount((rows + left + 1).ravel(), (W * frac).ravel(), B * bins)
    ).reshape(B, bins)
    k = np.arange(-bins + 1, bins) * step[:, None] / bandwidth[:, None]
    kernel = np.exp(-0.5 * k**2) / (np.sqrt(2 * np.pi) * bandwidth[:, None])
    n_fft = 4 * bins
    dens = np.fft.irfft(np.fft.rfft(grid_w, n_fft) * np.fft.rfft(kernel, n_fft), n_fft)
    dens = np.maximum(dens[:, bins - 1 : 2 * bins - 1], 1e-300)
    centres = lo[:, None] + step[:, None] * np.arange(bins)

    def log_q(y):
        out = np.stack(
            [np.interp(y[i], centres[i], dens[i], left=1e-300, right=1e-300) for i in range(B)]
        )
        return np.log(out)

    return log_q


def run_filters(
    trials: Trials,
    names=NAMES,
    rng: np.random.Generator | None = None,
    n_particles: int = PARTICLES,
) -> dict:
    """Run the named filters of :data:`depthcore.filters.FILTERS` over every trial.

    Returns ``{name: Estimates}``. Only the named filters run: the optimal
    filter, the reference of the Hellinger distances, runs only when it is
    among ``names``, and otherwise every ``Estimates.hellinger`` is ``None``.
    ``rng`` drives the random filters (the particle filter; required when one
    is among ``names``). The UKF runs with the default sigma points even where
    some lie behind the camera (the paper's prior is that broad).
    """
    names = check_names(names)
    mu, rho, pm, pc = trials.mu, trials.rho, trials.prior_mean, trials.prior_cov
    noise = {"process_noise": trials.process_noise} if trials.process_noise > 0 else {}
    reference = FILTERS["optimal"](mu, rho, pm, pc, **noise) if "optimal" in names else None
    ref = None if reference is None else reference.detail
    out = {}
    for name in names:
        f = FILTERS[name]
        if f.scoring.exact:
            out[name] = Estimates(
                reference.mean,
                reference.cov,
                *f.scoring.cdfs(reference, trials.truths),
                np.zeros(len(mu)),
                trials.states,
            )
            continue
        options = dict(noise)
        if f.random:
            if rng is None:
                raise ValueError(f"rng is required to run the {name} filter")
            options.update(rng=rng, n_particles=n_particles)
        try:
            est = f(mu, rho, pm, pc, **options)
        except ValueError as exc:
            # the bearings were drawn here, so no bearing is the user's to mend
            raise ValueError(
                f"filters: the {name} filter has no answer for a simulated trial ({exc}); "
                f"leave {name} out, or lower the process noise or the noise level"
            ) from None
        out[name] = _estimates(trials, est, f.scoring, ref)
    return out


#: Every nominal level whose coverage is counted: :data:`LEVELS` and :data:`CALIBRATION_LEVELS`.
_COVERAGE_LEVELS = tuple(sorted(set(LEVELS) | set(CALIBRATION_LEVELS)))


class Tally:
    """Running sums of one filter's scores over chunks of trials.

    Holds a fixed number of sums and counts, whatever the number of trials:
    :meth:`add` each chunk's :class:`Estimates`, then read :meth:`scores`. The
    sums of a chunk are taken with ``numpy.sum`` and added in order, so one
    chunk gives exactly the means ``numpy.mean`` gives over it, and several
    chunks agree with one to rounding.

    Parameters
    ----------
    truth : array_like, shape (3,)
        True state at time 3 (each chunk's ``Estimates.truth``, where given,
        takes its place).

    Attributes
    ----------
    n : int
        Trials added.
    error : ndarray, shape (2,)
        Sums over the trials of the depth and velocity errors.
    squared_error : ndarray, shape (2,)
        Sums of their squares.
    sd : ndarray, shape (2,)
        Sums of the filter's depth and velocity SDs.
    spread : dict of ndarray or float
        For the standard errors: the sums of squared deviations from their
        mean (:func:`pooled_squares`) of the errors (``"error"``), their
        squares (``"squared_error"``), the SDs (``"sd"``), the NEES
        (``"nees"``) and the Hellinger distances (``"hellinger"``, absent once
        a chunk has none).
    covered : ndarray of int, shape (2, L)
        Trials whose central interval holds the true depth and velocity, at
        each of the ``L`` levels of :data:`LEVELS` and :data:`CALIBRATION_LEVELS`.
    nees : float
        Sum of the NEES.
    hellinger : float or None
        Sum of the Hellinger distances; ``None`` once a chunk has none.
    lost : int
        Trials whose track is lost (:func:`lost_tracks`).
    """

    def __init__(self, truth):
        self.truth = _checks.finite_array(truth, "truth", (3,))
        self.n = 0
        self.error = np.zeros(2)  # sums of estimate - truth, depth and velocity
        self.squared_error = np.zeros(2)
        self.sd = np.zeros(2)
        self.covered = np.zeros((2, len(_COVERAGE_LEVELS)), dtype=np.int64)
        self.nees = 0.0
        self.hellinger: float | None = 0.0
        self.spread: dict = {
            "error": np.zeros(2),
            "squared_error": np.zeros(2),
            "sd": np.zeros(2),
            "nees": 0.0,
            "hellinger": 0.0,
        }
        self.lost = 0

    def add(self, est: Estimates) -> None:
        """Add the scores of one chunk of trials (an empty chunk adds nothing)."""
        n = len(est.mean)
        if n == 0:
            return
        full = est.mean - (self.truth if est.truth is None else est.truth)
        nees = np.einsum("ni,ni->n", full, np.linalg.solve(est.cov, full[..., None])[..., 0])
        err = full[:, 1:]  # depth and velocity
        sd = np.sqrt(est.cov[:, (1, 2), (1, 2)])
        chunk = {"error": err, "squared_error": err**2, "sd": sd, "nees": nees}
        if est.hellinger is not None and self.hellinger is not None:
            chunk["hellinger"] = np.asarray(est.hellinger, dtype=float)
        else:
            self.spread.pop("hellinger", None)
        sums = {
            "error": self.error,
            "squared_error": self.squared_error,
            "sd": self.sd,
            "nees": self.nees,
            "hellinger": self.hellinger,
        }
        for key, values in chunk.items():
            self.spread[key] = pooled_squares(self.n, sums[key], self.spread[key], values)
        for k, cdf in enumerate((est.depth_cdf, est.velocity_cdf)):
            self.error[k] += np.sum(err[:, k])
            self.squared_error[k] += np.sum(err[:, k] ** 2)
            self.sd[k] += np.sum(sd[:, k])
            off = np.abs(cdf - 0.5)
            self.covered[k] += [np.count_nonzero(off <= p / 2) for p in _COVERAGE_LEVELS]
        self.nees += np.sum(nees)
        if est.hellinger is None or self.hellinger is None:
            self.hellinger = None
        else:
            self.hellinger += np.sum(est.hellinger)
        self.lost += int(np.count_nonzero(lost_tracks(est.mean, self._truths(est, n))))
        self.n += n

    def _truths(self, est: Estimates, n: int) -> np.ndarray:
        return np.broadcast_to(self.truth if est.truth is None else est.truth, (n, 3))

    def scores(self) -> dict:
        """The scores of :func:`scores` over every trial added, with their standard errors."""
        if self.n == 0:
            raise ValueError("trials: no trial was added to the tally")
        n = self.n
        level = {p: j for j, p in enumerate(_COVERAGE_LEVELS)}
        out = {}
        spread = self.spread
        for k, q in enumerate(("depth", "velocity")):
            rmse = float(np.sqrt(self.squared_error[k] / n))
            mse_se = mean_se(spread["squared_error"][k], n)
            out[q] = {
                "bias": float(self.error[k] / n),
                "bias_se": mean_se(spread["error"][k], n),
                "rmse": rmse,
                # the delta method: d sqrt(m) = dm / (2 sqrt(m))
                "rmse_se": mse_se / (2.0 * rmse) if rmse > 0 else 0.0,
                "mean_sd": float(self.sd[k] / n),
                "mean_sd_se": mean_se(spread["sd"][k], n),
            }
            for p in LEVELS:
                c = float(self.covered[k, level[p]] / n)
                out[q][f"coverage_{round(100 * p)}"] = c
                out[q][f"coverage_{round(100 * p)}_se"] = float(np.sqrt(c * (1.0 - c) / n))
        out["nees"] = float(self.nees / n)
        out["nees_se"] = mean_se(spread["nees"], n)
        out["calibration"] = {
            "levels": list(CALIBRATION_LEVELS),
            **{
                q: [float(self.covered[k, level[p]] / n) for p in CALIBRATION_LEVELS]
                for k, q in enumerate(("depth", "velocity"))
            },
        }
        out["hellinger_depth"] = (
            None
            if self.hellinger is None
            else {
                "mean": float(self.hellinger / n),
                "se": mean_se(spread["hellinger"], n),
            }
        )
        out["track_loss"] = track_loss(self.lost, n)
        return out


def pooled_squares(n, total, squares, values):
    """The sum of squared deviations from the mean, with one more chunk of values pooled in.

    Chan, Golub and LeVeque's pairwise update: with ``n`` earlier values of
    sum ``total`` and sum of squared deviations ``squares``, and a chunk of
    ``m`` values of mean ``b`` and sum of squared deviations ``s_b``,
    ``squares + s_b + (b - total / n)**2 n m / (n + m)``. Unlike the sum of
    squares less ``n`` times the squared mean, no two large numbers are
    subtracted, so the result does not depend on the chunks beyond rounding.

    Parameters
    ----------
    n : int
        Earlier values, >= 0.
    total : float or ndarray, shape (...)
        Their sum (ignored when ``n`` is 0).
    squares : float or ndarray, shape (...)
        Their sum of squared deviations from their mean.
    values : ndarray, shape (m, ...)
        The chunk, ``m >= 1``.

    Returns
    -------
    float or ndarray, shape (...)
    """
    m = len(values)
    b = np.mean(values, axis=0)
    s_b = np.sum((values - b) ** 2, axis=0)
    if n == 0:
        return s_b
    return squares + s_b + (b - total / n) ** 2 * (n * m / (n + m))


def mean_se(squares, n: int) -> float:
    """Standard error ``sqrt(s**2 / n)`` of a mean over ``n`` independent trials.

    ``s**2 = squares / (n - 1)`` is the trials' sample variance, from the sum
    of squared deviations from their mean (:func:`pooled_squares`); 0 for one
    trial (no spread to estimate).

    Parameters
    ----------
    squares : float
        Sum of squared deviations from the mean, >= 0.
    n : int
        Trials, >= 1.

    Returns
    -------
    float
    """
    if n < 2:
        return 0.0
    return float(np.sqrt(float(squares) / (n - 1) / n))


def lost_tracks(mean, truth, threshold: float = TRACK_LOSS) -> np.ndarray:
    """Whether each trial's track is lost: its position error beyond ``threshold`` times the range.

    A track is lost when ``|(x_est - x, y_est - y)| > threshold |(x, y)|`` at the
    last frame (or the estimate is not finite); see the module docstring.

    Parameters
    ----------
    mean : array_like, shape (..., 3)
        Estimated states ``(x, y, v)``.
    truth : array_like, shape (..., 3)
        True states.
    threshold : float
        > 0.

    Returns
    -------
    ndarray of bool, shape (...)
    """
    threshold = _checks.positive_scalar(threshold, "threshold")
    mean = np.asarray(mean, dtype=float)
    truth = np.asarray(truth, dtype=float)
    error = np.hypot(mean[..., 0] - truth[..., 0], mean[..., 1] - truth[..., 1])
    return ~(error <= threshold * np.hypot(truth[..., 0], truth[..., 1]))


def track_loss(lost: int, trials: int, confidence: float = TRACK_LOSS_CONFIDENCE) -> dict:
    """The fraction of lost tracks, its standard error and an exact upper confidence bound.

    Parameters
    ----------
    lost : int
        Tracks lost, ``0 <= lost <= trials``.
    trials : int
        ``n >= 1``.
    confidence : float
        Of the one-sided upper bound, in (0, 1).

    Returns
    -------
    dict
        ``fraction`` ``p = lost / n``; ``se``, the binomial ``sqrt(p (1 - p) / n)``;
        ``upper`` the Clopper-Pearson bound, the ``confidence`` quantile of
        ``Beta(lost + 1, n - lost)`` (1 when every track is lost);
        ``threshold`` and ``confidence``.
    """
    n = _checks.count(trials, "trials")
    if isinstance(lost, bool) or not isinstance(lost, (int, np.integer)) or not 0 <= lost <= n:
        raise ValueError(f"lost must be an integer from 0 to trials = {n}, got {lost!r}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    p = lost / n
    upper = 1.0 if lost == n else float(beta.ppf(confidence, lost + 1, n - lost))
    return {
        "fraction": float(p),
        "se": float(np.sqrt(p * (1 - p) / n)),
        "upper": upper,
        "threshold": TRACK_LOSS,
        "confidence": float(confidence),
    }


def coverage_se(level, trials) -> np.ndarray:
    """Binomial standard error ``sqrt(p (1 - p) / n)`` of a coverage at level ``p``, ``n`` trials.

    Parameters
    ----------
    level : float or array_like
        Nominal levels ``p`` in (0, 1).
    trials : int or array_like
        Independent trials ``n >= 1``, broadcast against ``level``.

    Returns
    -------
    ndarray
        The standard error of a calibrated filter's coverage.
    """
    level = np.asarray(level, dtype=float)
    return np.sqrt(level * (1 - level) / trials)


#: The size and power at which :func:`detectable_difference` states a coverage test's reach.
TEST_FALSE_ALARM = 0.01
TEST_POWER = 0.8


def detectable_difference(
    level, trials, false_alarm: float = TEST_FALSE_ALARM, power: float = TEST_POWER
):
    """The smallest coverage error that a two-sided binomial test finds with a given power.

    A coverage ``c`` of ``n`` trials is tested against its nominal level
    ``p`` by ``|c - p| > z_a sqrt(p (1 - p) / n)``, ``z_a`` the standard
    normal's upper ``false_alarm / 2`` point. In the normal approximation a
    filter whose true coverage is ``p ± d`` fails the test with probability
    ``power`` (ignoring the far tail) when
    ``d = (z_a + z_b) sqrt(p (1 - p) / n)``, ``z_b`` the standard normal's
    ``power`` quantile.

    Parameters
    ----------
    level : float or array_like
        Nominal levels ``p`` in (0, 1).
    trials : int or array_like
        ``n >= 1``, broadcast against ``level``.
    false_alarm : float
        The test's size, in (0, 1).
    power : float
        In (0, 1).

    Returns
    -------
    ndarray
        ``d``, of the broadcast shape.
    """
    from scipy.special import ndtri

    for value, name in ((false_alarm, "false_alarm"), (power, "power")):
        if not 0.0 < float(value) < 1.0:
            raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
    z = ndtri(1.0 - float(false_alarm) / 2.0) + ndtri(float(power))
    return z * coverage_se(level, trials)


def scores(trials: Trials, est: Estimates) -> dict:
    """Bias, RMSE, coverage, NEES and Hellinger distance of one filter, each with its SE.

    Every score ``s`` has its Monte Carlo standard error beside it as
    ``s_se`` (the Hellinger distance's as ``hellinger_depth["se"]``): the
    sample SD over the trials divided by ``sqrt(n)`` for the means (bias, mean
    SD, NEES, Hellinger distance), ``sqrt(c (1 - c) / n)`` for a coverage
    ``c``, and the delta method's ``se(MSE) / (2 RMSE)`` for the RMSE.

    ``calibration`` holds the coverage of the central intervals at every level
    of :data:`CALIBRATION_LEVELS`: a calibrated filter's curve is the diagonal.
    ``hellinger_depth`` is ``{"mean": ...}``, or ``None`` when the estimates
    have no Hellinger distances (the optimal filter was not run).
    """
    tally = Tally(trials.truth)
    tally.add(est)
    return tally.scores()


def study(
    truth=None,
    rho: float = SCENARIOS["fig2"].rho,
    trials: int = 500,
    seed=0,
    prior: str = "paper",
    names=NAMES,
    chunk: int = CHUNK,
    n_particles: int = PARTICLES,
    progress: Callable[[int, int], None] | None = None,
    frames: int = 3,
    process_noise: float = 0.0,
) -> dict:
    """The whole study; returns a JSON-ready dict.

    Parameters
    ----------
    truth : array_like, shape (3,), optional
        True state at time 3; default the noise-free state of Figure 2.
    rho : float
    trials : int
        Trials drawn, >= 1 (those without a noise-free solution in front of
        the camera are counted and left out).
    seed : int or numpy.random.SeedSequence
        Seeds the ``numpy.random.Generator`` streams that draw the noise and
        the particles (default 0).
    prior : {"paper", "fixed"}
    names : sequence of str
        Filters to score, from :data:`depthcore.filters.FILTERS`; only these
        run. The Hellinger distances need the optimal filter: when
        ``"optimal"`` is not among ``names`` it is not run and every
        filter's ``hellinger_depth`` is ``None``.
    chunk : int
        Trials drawn and filtered together (default :data:`CHUNK`);
        ``progress(done, total)`` is called after each chunk with the trials
        drawn so far and ``trials``. Memory grows with ``chunk`` (and
        ``n_particles``), not with ``trials``: only running sums are kept.
    n_particles : int
        Particles per trial of the particle filter.
    frames : int
        ``N >= 3``: the point, at ``truth`` at time 3, moves on to frame ``N``
        and every filter is scored on its state there (:func:`simulate`).
    process_noise : float
        ``q >= 0``: the velocity's change per frame from time 3 on, drawn in
        every trial, so the true state at frame ``N`` differs from trial to
        trial (the scores are against each trial's own); the state at time 3
        is ``truth`` in every trial. The named filters must support the
        frames and the process noise (:class:`depthcore.filters.Filter`).

    Notes
    -----
    The noise and the particle filter draw from two streams spawned from the
    one seed, whichever filters run: a filter's results do not depend on
    which other filters are named. The noise does not depend on ``chunk``
    either, so the scores of the deterministic filters agree across chunk
    sizes to rounding; the particle filter's draws do depend on ``chunk``.
    """
    truth = SCENARIOS["fig2"].c if truth is None else truth
    names = check_names(names)
    if not (isinstance(trials, (int, np.integer)) and trials >= 1):
        raise ValueError(f"trials must be a positive integer, got {trials!r}")
    chunk = _checks.count(chunk, "chunk")
    q = _checks.nonnegative_scalar(process_noise, "process_noise")
    frames = _checks.count(frames, "frames")
    unable = [
        n
        for n in names
        if (frames != 3 and not FILTERS[n].any_frames)
        or (q > 0 and not FILTERS[n].with_process_noise)
    ]
    if unable:
        raise ValueError(
            f"names: {', '.join(unable)} cannot run on {frames} frames with process "
            f"noise {q:g}; leave them out"
        )
    seed = _checks.seed_sequence(seed)
    noise_rng, particle_rng = (np.random.default_rng(s) for s in _checks.spawn(seed, 2))
    tallies = None
    n_valid = n_rejected = 0
    for start in range(0, int(trials), chunk):
        part = simulate(
            truth,
            rho,
            min(chunk, int(trials) - start),
            noise_rng,
            prior,
            frames=frames,
            process_noise=q,
        )
        if tallies is None:
            tallies = {name: Tally(part.truth) for name in names}
        n_rejected += part.n_rejected
        if len(part.mu):
            n_valid += len(part.mu)
            for name, est in run_filters(part, names, particle_rng, n_particles).items():
                tallies[name].add(est)
        if progress is not None:
            progress(min(start + chunk, int(trials)), int(trials))
    if n_valid == 0:
        raise ValueError(
            f"truth and rho leave no valid trial: all {trials} noisy triples are degenerate "
            "or put the point behind the camera"
        )
    return {
        "truth": [float(v) for v in part.truth],
        "rho": float(rho),
        "prior": prior,
        "seed": seed.entropy,
        "trials": int(trials),
        "valid_trials": n_valid,
        "rejected_trials": n_rejected,
        "particles": int(n_particles) if any(FILTERS[n].random for n in names) else None,
        "frames": int(frames),
        "process_noise": q,
        "filters": {name: tallies[name].scores() for name in names},
    }


#: The ``truth`` that asks for truths drawn from the prior (:func:`prior_study`).
PRIOR_TRUTH = "prior"
#: False-alarm rate of the uniformity tests reported by :func:`prior_study`.
FALSE_ALARM = 0.01


def prior_study(
    rho: float = SCENARIOS["fig2"].rho,
    trials: int = 500,
    seed=0,
    prior_scale: float = PAPER_PRIOR_SCALE,
    false_alarm: float = FALSE_ALARM,
    frames: int = 3,
    process_noise: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Self-calibration of the optimal filter over truths drawn from its fixed prior.

    With ``frames = N > 3`` or ``process_noise = q > 0`` each truth is followed
    from frame 1 to frame ``N`` with accelerations ``N(0, q**2)`` and the
    exact N-frame filter (the bank of Kalman filters over depth) is checked at
    frame ``N``.

    The prior is the study's ``prior="fixed"`` one: the paper's rule applied
    once to Figure 2's noise-free state ``c``, mean ``G^{-2} c = (c1 - 2 c3,
    c2 - 2, 0)`` and covariance ``prior_scale * I``; it does not depend on
    the measurements. Truths are drawn from it with the point in front of the
    camera (:func:`depthcore.calibration.self_calibration`). The coverage of
    the central intervals at every level of :data:`CALIBRATION_LEVELS` is
    reported with its binomial standard error, and the KS and chi-square
    tests of the PIT values with a verdict per quantity: ``calibrated`` is
    false when either test's p-value falls below ``false_alarm / 2``
    (Bonferroni), so a calibrated filter is flagged with probability at most
    ``false_alarm`` per quantity.

    Parameters
    ----------
    rho : float
    trials : int
    seed : int or numpy.random.SeedSequence
    prior_scale : float
    false_alarm : float
        Rate, in (0, 1), at which the tests reject a calibrated filter.
    frames : int
        ``N``, from 3 to ``depthcore._checks.MAX_FRAMES``.
    process_noise : float
        ``q >= 0``.
    progress : callable, optional
        ``progress(done, total)``, called as the trials are filtered.

    Returns
    -------
    dict
        JSON-ready.
    """
    from . import calibration

    prior_scale = _checks.positive_scalar(prior_scale, "prior_scale")
    false_alarm = float(false_alarm)
    if not 0.0 < false_alarm < 1.0:
        raise ValueError(f"false_alarm must lie in (0, 1), got {false_alarm!r}")
    seed = _checks.seed_sequence(seed)
    mean = paper_prior_means(np.asarray(SCENARIOS["fig2"].c, dtype=float)[None])[0]
    cov = prior_scale * np.eye(3)
    r = calibration.self_calibration(
        mean,
        cov,
        rho,
        trials,
        np.random.default_rng(seed),
        frames=frames,
        process_noise=process_noise,
        progress=progress,
    )
    s = r.summary(CALIBRATION_LEVELS)
    n = s["trials"]
    levels = np.asarray(CALIBRATION_LEVELS)
    out = {
        "truth": PRIOR_TRUTH,
        "rho": float(rho),
        "prior": "fixed",
        "prior_mean": [float(v) for v in mean],
        "prior_cov": cov.tolist(),
        "seed": seed.entropy,
        "trials": int(trials),
        "frames": int(frames),
        "process_noise": float(process_noise),
        "valid_trials": n,
        "behind_camera_draws": r.draws.n_behind,
        "rejected_trials": r.draws.n_rejected,
        "false_alarm": false_alarm,
        "levels": s["levels"],
        "coverage_se": coverage_se(levels, max(n, 1)).tolist(),
    }
    for q in ("depth", "velocity"):
        t = s[q]
        t["calibrated"] = bool(min(t["ks_pvalue"], t["chi2_pvalue"]) > false_alarm / 2)
        out[q] = t
    return out


#: The samplers whose Monte Carlo errors :func:`error_coverage` checks.
SAMPLERS = ("particle", "resample_move", "rbpf")
#: The moments whose errors :func:`error_coverage` checks.
ERROR_MOMENTS = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")


def error_coverage(
    name: str,
    mu,
    rho: float,
    prior_mean,
    prior_cov,
    runs: int = 100,
    seed=0,
    process_noise: float = 0.0,
    **options,
) -> dict:
    """How often a sampler's reported error covers its actual error.

    The sampler ``name`` of the registry runs ``runs`` times, independently,
    on one problem (the runs are the rows of one batch, drawn from one
    generator seeded by ``seed``); each moment's error, estimate minus the
    exact value of the optimal filter (the bank of Kalman filters beyond
    three frames or with process noise), is compared with the error the
    sampler reports for it (``depth_error`` for the depth's moments,
    ``velocity_error`` for the velocity's). An honest error puts about 95 %
    of the runs within two reported errors; a run flagged ``collapsed``
    reports no error (NaN) and is counted apart.

    Parameters
    ----------
    name : str
        One of :data:`SAMPLERS`.
    mu : array_like, shape (K,)
        One sequence of bearings.
    rho, prior_mean, prior_cov, process_noise
        The problem, as for every filter of the registry.
    runs : int
        Independent runs, >= 1.
    seed : int or numpy.random.SeedSequence
    **options
        For the sampler (``n_particles``, ``replicas``, ...); its defaults otherwise.

    Returns
    -------
    dict
        ``"runs"``, ``"collapsed"`` (the number of runs flagged), and for each
        of :data:`ERROR_MOMENTS` ``{"within_two": fraction of the runs not
        collapsed whose error is within two reported errors, "max_z": the
        largest absolute error over the reported error, "se": the binomial standard error of
        the fraction}``; ``"worst_collapsed_z"``: the largest absolute error of a
        collapsed run's depth mean over the exact depth SD (how far off the
        flag was right to be).
    """
    if name not in SAMPLERS:
        raise ValueError(f"name must be one of {SAMPLERS}, got {name!r}")
    runs = _checks.count(runs, "runs")
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim != 1:
        raise ValueError(f"mu must have shape (K,), got shape {mu.shape}")
    batch = np.tile(mu, (runs, 1))
    noise = {"process_noise": process_noise} if process_noise else {}
    exact = FILTERS["optimal"](mu, rho, prior_mean, prior_cov, **noise)
    rng = np.random.default_rng(_checks.seed_sequence(seed))
    est = FILTERS[name](batch, rho, prior_mean, prior_cov, rng=rng, **noise, **options)
    collapsed = np.broadcast_to(np.asarray(est.collapsed, dtype=bool), (runs,))
    out = {"runs": runs, "collapsed": int(np.sum(collapsed))}
    ok = ~collapsed
    for moment in ERROR_MOMENTS:
        quantity = moment.split("_")[0]
        err = np.asarray(getattr(est, moment)) - getattr(exact, moment)
        reported = np.asarray(getattr(est, f"{quantity}_error"))
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(err[ok]) / reported[ok]
        n = int(np.sum(ok))
        frac = float(np.mean(z <= 2.0)) if n else float("nan")
        out[moment] = {
            "within_two": frac,
            "max_z": float(np.max(z)) if n else float("nan"),
            "se": float(np.sqrt(frac * (1 - frac) / n)) if n else float("nan"),
        }
    depth_err = np.abs(np.asarray(est.depth_mean) - exact.depth_mean) / exact.depth_sd
    out["worst_collapsed_z"] = float(np.max(depth_err[collapsed])) if np.any(collapsed) else None
    return out
