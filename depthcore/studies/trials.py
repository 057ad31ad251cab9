"""The trials of a Monte Carlo study: the bearings drawn afresh, every filter run on them.

Recommended import: ``from depthcore.studies import trials``.

:func:`simulate` draws a study's trials for a true state (the paper's three
bearings, or ``N`` frames with process noise) and builds each trial's prior
(the paper's rule, or fixed), or draws each trial's truth from a prior of
another form (:mod:`depthcore.studies.priors`) centred on that state;
:func:`run_filters` runs the registry's filters on them and keeps what the
scores need of each estimate (:class:`Estimates`): the moments, the marginal
CDFs at the truth, the NEES and the Hellinger distance to the optimal
filter's depth marginal (:func:`hellinger`, :func:`gaussian_hellinger`). The
scores are :mod:`depthcore.studies.scores`'s; the study that streams trials
through both, :mod:`depthcore.studies.monte_carlo`'s.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from depthcore.exact import optimal
from depthcore.problem import checks, model
from depthcore.problem.depth_prior import DepthPrior
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, gaussian_logpdf, paper_prior_means
from depthcore.registry.estimates import exact_depth_range
from depthcore.registry.filters import FILTERS, NAMES, check_names
from depthcore.studies import priors as prior_forms

#: The priors of :func:`simulate`: the paper's rule, fixed, and the forms whose truths are drawn.
PRIORS = ("paper", "fixed", *prior_forms.DRAWN)


#: Particles per trial of the particle filter.
PARTICLES = 2000

#: The row of the exact filter under a drawn form's law itself (``Trials.law``), beside
#: ``"optimal"`` under the law's Gaussian: what the Gaussian stand-in costs.
UNDER_LAW = "optimal_under_law"


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
        ``truth`` (more than three frames, or truths drawn from the prior);
        ``None`` otherwise.
    tracks : ndarray, shape (N, K, 3), or None
        The true state at every frame ``1 .. K`` of each trial, where asked
        for (:func:`simulate`'s ``tracks``); ``None`` otherwise.
    law : depthcore.problem.depth_prior.DepthPrior or None
        The law the truths were drawn from (a drawn form), whose Gaussian is
        ``prior_mean`` and ``prior_cov``; ``None`` otherwise.
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
    law: DepthPrior | None = None

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
    refused : int
        Trials of the batch the filter had no answer for, left out of the
        arrays above (``N`` counts the trials answered).
    answered : ndarray of bool, or None
        Which trials of the batch (one entry each, answered or refused) the
        rows above are; ``None``: all of them.
    no_maximum : int or None
        Trials of the batch answered where the filter's estimate has no
        interior maximum (``extras["at_limit"]``: the batch maximum-likelihood
        estimate at its search limit, :mod:`depthcore.analysis.batch_ml`),
        left out of the arrays above and of ``answered``; ``None`` for a
        filter whose estimates carry no such flag.
    """

    mean: np.ndarray
    cov: np.ndarray
    depth_cdf: np.ndarray
    velocity_cdf: np.ndarray
    hellinger: np.ndarray | None
    truth: np.ndarray | None = None
    refused: int = 0
    answered: np.ndarray | None = None
    no_maximum: int | None = None


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
    prior : {"paper", "fixed", "range", "log_uniform", "inverse_depth"}
        ``"paper"``: mean ``(c1 - 2 c3, c2 - 2, 0)`` from each trial's own
        noise-free solution; ``"fixed"``: the same rule applied once to the
        truth. The other forms (:data:`depthcore.studies.priors.DRAWN`) draw
        each trial's state at frame 1 from the form's law centred on
        ``G^{-2} truth`` (:func:`depthcore.studies.priors.draw`, before the
        bearings, from ``rng``), move it to time 3, where the trial goes on as
        from ``truth``, and give every trial the form's Gaussian
        (:func:`depthcore.studies.priors.gaussian`); ``Trials.states`` holds
        each trial's own truth at its last frame.
    prior_scale : float
        Prior covariance ``prior_scale * I`` (the paper's rule and ``"fixed"``;
        the drawn forms state their own).
    frames : int
        ``N >= 3``: the point is followed on from time 3 to frame ``N``
        (:func:`depthcore.problem.model.simulate` with ``frame=3``). The state at
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
    truth = checks.finite_array(truth, "truth", (3,))
    frames = checks.frames(frames)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    rho = checks.positive_scalar(rho, "rho")
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"trials must be a positive integer, got {n!r}")
    if prior not in PRIORS:
        raise ValueError(f"prior must be one of {PRIORS}, got {prior!r}")
    prior_scale = checks.positive_scalar(prior_scale, "prior_scale")
    if not truth[1] - 2 > 0:
        raise ValueError(
            f"truth puts the point behind the camera: depth at time 1 is {truth[1] - 2:.6g}"
        )
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if prior in prior_forms.DRAWN:
        return _drawn_trials(truth, rho, int(n), rng, prior, frames, q, tracks)
    sim = model.draw_track(truth, frames, rho, q, rng, (int(n),), 3)
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


def _drawn_trials(truth, rho, n, rng, form, frames, q, tracks) -> Trials:
    """:func:`simulate` for a prior form whose truths are drawn, on checked inputs."""
    centre = model.G(truth, -2)
    start = prior_forms.draw(form, centre, rho, n, rng)
    sim = model.draw_track(model.G(start, 2), frames, rho, q, rng, (n,), 3)
    keep = valid_triples(sim.mu[:, :3])
    mean, cov = prior_forms.gaussian(form, centre, rho)
    n_kept = int(np.sum(keep))
    return Trials(
        truth,
        rho,
        sim.mu[keep],
        np.tile(mean, (n_kept, 1)),
        cov,
        int(np.sum(~keep)),
        q,
        sim.states[keep, -1, :],
        sim.states[keep] if tracks else None,
        prior_forms.law(form, centre, rho),
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

    The CDFs at the truths are the family's (:attr:`depthcore.registry.estimates.Family.cdfs`).
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
    seconds: dict | None = None,
) -> dict:
    """Run the named filters of :data:`depthcore.registry.filters.FILTERS` over every trial.

    Returns ``{name: Estimates}``. Only the named filters run: the optimal
    filter, the reference of the Hellinger distances, runs only when it is
    among ``names``, and otherwise every ``Estimates.hellinger`` is ``None``.
    ``rng`` drives the random filters (the particle filter; required when one
    is among ``names``). The UKF runs with the default sigma points even where
    some lie behind the camera (the paper's prior is that broad).

    A filter that has no answer for some trials (it refuses them, or a
    covariance turns singular) is scored over the trials it answers: the
    trials it refuses are found by halving the failing batch
    (:func:`answered_rows`) and counted in its ``Estimates.refused``. A
    random filter draws on from ``rng`` as the batches are run again, so its
    draws stay a function of the seed. A filter that answers none, or whose
    particles are too few, is refused with one line naming the filter.

    Given a dict ``seconds``, each filter's wall-clock time over the trials
    (its scores' inputs included) is put there by name.
    """
    names = check_names(names)
    mu, rho, pm, pc = trials.mu, trials.rho, trials.prior_mean, trials.prior_cov
    noise = {"process_noise": trials.process_noise} if trials.process_noise > 0 else {}
    clock = {} if seconds is None else seconds
    start = time.perf_counter()
    reference = FILTERS["optimal"](mu, rho, pm, pc, **noise) if "optimal" in names else None
    if reference is not None:
        clock["optimal"] = time.perf_counter() - start
    ref = None if reference is None else reference.detail
    out = {}
    for name in names:
        start = time.perf_counter()
        f = FILTERS[name]
        if f.scoring.exact:
            out[name] = Estimates(
                reference.mean,
                reference.cov,
                *f.scoring.cdfs(reference, trials.truths),
                np.zeros(len(mu)),
                trials.states,
            )
            clock[name] += time.perf_counter() - start
            continue
        out[name] = _run_one(trials, name, rng, n_particles, noise, ref)
        clock[name] = time.perf_counter() - start
    if trials.law is not None and "optimal" in names:  # the exact filter under the law itself
        start = time.perf_counter()
        out[UNDER_LAW] = _run_one(trials, "optimal", rng, n_particles, noise | {"law": trials.law})
        clock[UNDER_LAW] = time.perf_counter() - start
    return out


#: The failures of a filter on a trial that count the trial as refused by it.
FAILURES = (ValueError, np.linalg.LinAlgError)

#: Most rounds of isolating a filter's refused trials, since a random filter, run again on the
#: trials it answered, draws afresh and may refuse others.
ROUNDS = 5


def _run_one(trials: Trials, name: str, rng, n_particles: int, noise: dict, ref=None) -> Estimates:
    """One filter's :class:`Estimates` over the trials it answers (``noise``: its options)."""
    f = FILTERS[name]
    options = dict(noise)
    if f.random:
        if rng is None:
            raise ValueError(f"rng is required to run the {name} filter")
        options.update(rng=rng, n_particles=n_particles)

    def run(part: Trials):
        est = f(part.mu, part.rho, part.prior_mean, part.prior_cov, **options)
        # a covariance singular in double precision gives no NEES: no answer a score can read
        np.linalg.solve(est.cov, est.mean[..., None])
        return est

    try:
        est = run(trials)
        return interior(_estimates(trials, est, f.scoring, ref), est)
    except FAILURES as exc:
        if str(exc).startswith("n_particles"):
            raise ValueError(
                f"n_particles: the {name} filter has no answer for a simulated trial "
                f"({exc}); use more particles, or leave {name} out"
            ) from None
        reason = " ".join(str(exc).split()) or type(exc).__name__
    rows = np.arange(len(trials.mu))
    for _ in range(ROUNDS):
        rows = rows[answered_rows(lambda r, rows=rows: run(subset(trials, rows[r])), len(rows))]
        if not len(rows):
            break
        # a random filter draws afresh on the trials it answered, and may refuse others
        try:
            part = subset(trials, rows)
            est = run(part)
            break
        except FAILURES:
            continue
    else:
        rows = rows[:0]
    if not len(rows):
        # the bearings were drawn here, so no bearing is the user's to mend: the blame
        # is the choice of filters
        raise ValueError(
            f"filters: the {name} filter has no answer for a simulated trial ({reason}); "
            f"leave {name} out, or lower the process noise or the noise level"
        )
    if ref is not None:  # the reference over the trials answered, run again on them alone
        ref = FILTERS["optimal"](part.mu, part.rho, part.prior_mean, part.prior_cov, **noise)
        ref = ref.detail
    scored = _estimates(part, est, f.scoring, ref)
    answered = np.zeros(len(trials.mu), dtype=bool)
    answered[rows] = True
    scored = dataclasses.replace(scored, refused=len(trials.mu) - len(rows), answered=answered)
    return interior(scored, est)


def interior(scored: Estimates, estimate) -> Estimates:
    """``scored`` without the trials where ``estimate`` has no interior maximum, counted apart.

    ``scored``: a filter's scores' inputs over the trials it answered;
    ``estimate``: its registry estimate there, whose ``extras["at_limit"]``
    (bool, (n,)) marks a limit of the search, not a maximum of the likelihood.
    Returns ``scored`` where there is no such flag, else its rows with a
    maximum, ``answered`` marking them and ``no_maximum`` counting the others.
    """
    flags = getattr(estimate, "extras", {}).get("at_limit")
    if flags is None:
        return scored
    keep = ~np.asarray(flags, dtype=bool).reshape(-1)
    n_all = scored.refused + len(keep)
    rows = np.arange(n_all) if scored.answered is None else np.flatnonzero(scored.answered)
    answered = np.zeros(n_all, dtype=bool)
    answered[rows[keep]] = True

    def part(a):
        return None if a is None else a[keep]

    return dataclasses.replace(
        scored,
        mean=scored.mean[keep],
        cov=scored.cov[keep],
        depth_cdf=scored.depth_cdf[keep],
        velocity_cdf=scored.velocity_cdf[keep],
        hellinger=part(scored.hellinger),
        truth=part(scored.truth),
        answered=answered,
        no_maximum=int(np.count_nonzero(~keep)),
    )


def answered_rows(run: Callable, n: int) -> np.ndarray:
    """The rows ``0 .. n - 1`` on which ``run(rows)`` does not fail, by halving.

    ``run`` is called on a batch of rows and raises one of :data:`FAILURES`
    when it has no answer for one of them; a failing batch is halved until
    every failing row stands alone. The calls grow as the failing rows times
    ``log2 n``. Returns the answered rows, sorted, shape (m,).
    """
    ok = []

    def fill(rows):
        try:
            run(rows)
        except FAILURES:
            if len(rows) > 1:
                fill(rows[: len(rows) // 2])
                fill(rows[len(rows) // 2 :])
            return
        ok.append(rows)

    fill(np.arange(int(n)))
    return np.concatenate(ok) if ok else np.zeros(0, dtype=int)


def subset(trials: Trials, rows) -> Trials:
    """The trials ``rows`` of ``trials`` (none counted as rejected)."""
    rows = np.asarray(rows, dtype=int)
    return dataclasses.replace(
        trials,
        mu=trials.mu[rows],
        prior_mean=trials.prior_mean[rows],
        n_rejected=0,
        states=None if trials.states is None else trials.states[rows],
        tracks=None if trials.tracks is None else trials.tracks[rows],
    )
