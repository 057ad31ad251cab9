"""A Monte Carlo study: which filter's estimate, and which stated uncertainty, to trust.

Recommended import: ``from depthcore.studies import monte_carlo``.

For a true state at time 3 (by default the noise-free state ``c`` of the
paper's Figure 2), each trial draws the bearings afresh: the paper's three,
or ``N`` with ``frames=N`` (up to ``depthcore.problem.checks.MAX_FRAMES``), the point
moving on from time 3 to frame ``N``, with process noise ``q`` on its velocity
if ``process_noise=q``. It builds the prior by the paper's rule from that
trial's first three bearings (``prior="paper"``, as the paper does) or once
from the truth's noise-free bearings (``prior="fixed"``), or, for a prior of
another form (``"range"``, ``"log_uniform"``, ``"inverse_depth"``,
:mod:`depthcore.studies.priors`), draws each trial's truth from that prior
centred on the true state and scores each trial against its own truth; it
runs every filter, and scores its estimate of the state at the last frame:

* bias and RMSE of its depth and velocity means;
* coverage of its central 68 % and 95 % intervals: the truth lies in the
  central ``p`` interval when its marginal CDF at the truth is within
  ``p / 2`` of one half;
* mean NEES, ``(m - x)^T P^{-1} (m - x)`` over the whole state (3 for a
  filter whose covariance matches its error);
* the mean Hellinger distance from its depth marginal to the optimal one,
  when the optimal filter is among the filters run (it is run only when
  asked for; otherwise the distance is not computed and reported as ``None``);
* the fraction of lost tracks, as the bearings-only tracking literature counts
  them beside the RMSE (e.g. [ristic2004]_, chapter 6): a position error beyond
  a fraction of the point's distance, the problem having no natural unit of
  length (:func:`~depthcore.studies.scores.lost_tracks`), with its binomial SE
  and exact upper bound (:func:`~depthcore.studies.scores.track_loss`).

Trials whose measurements have no noise-free solution in front of the camera
(Eq. (7) degenerate or ``c2 <= 2``) cannot run the second-order filter or the
paper's prior rule; they are counted and left out of every score.

:func:`study` streams the trials: it draws and filters them in chunks of at
most :data:`CHUNK` and keeps only running sums (:class:`~depthcore.studies.scores.Tally`), so its
memory does not grow with the number of trials. The chunks are filtered in
this process or, given a ``client``, as tasks of a Dask cluster
(:mod:`depthcore.studies.tasks`), with the same result bit for bit.

References
----------
.. [ristic2004] B. Ristic, S. Arulampalam and N. Gordon, *Beyond the Kalman
   Filter: Particle Filters for Tracking Applications*, Artech House, 2004,
   chapter 6 (bearings-only tracking).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from depthcore.analysis import calibration
from depthcore.problem import checks, model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, paper_prior_means
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS, NAMES, check_names
from depthcore.studies import priors as prior_forms
from depthcore.studies import tasks
from depthcore.studies.pairs import CoMoments, trial_scores
from depthcore.studies.scores import CALIBRATION_LEVELS, Tally, coverage_se
from depthcore.studies.trials import PARTICLES, run_filters, simulate

#: Trials drawn and filtered together by :func:`study`: its memory is that of one chunk.
CHUNK = 100


def filter_chunk(item) -> tuple:
    """One chunk of :func:`study`, its trials' filters run: a task of :mod:`.tasks`.

    Parameters
    ----------
    item : tuple
        ``(trials, names, seed, n_particles)``: the chunk's
        :class:`~depthcore.studies.trials.Trials`, the filters, the seed of its
        random filters' draws (``None`` when none is named) and their particles.

    Returns
    -------
    tuple
        ``(trials, estimates)``: ``estimates`` is
        :func:`~depthcore.studies.trials.run_filters`'s ``{name: Estimates}``,
        ``None`` when the chunk has no valid trial.
    """
    part, names, seed, n_particles = item
    if not len(part.mu):
        return part, None
    rng = None if seed is None else np.random.default_rng(seed)
    return part, run_filters(part, names, rng, n_particles)


def study(
    truth=None,
    rho: float = SCENARIOS["fig2"].rho,
    trials: int = 500,
    seed=0,
    prior: str = "paper",
    prior_scale: float = PAPER_PRIOR_SCALE,
    names=NAMES,
    chunk: int = CHUNK,
    n_particles: int = PARTICLES,
    progress: Callable[[int, int], None] | None = None,
    frames: int = 3,
    process_noise: float = 0.0,
    paired: bool = False,
    client=None,
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
    prior : {"paper", "fixed", "range", "log_uniform", "inverse_depth"}
        How the trials' priors are built (:func:`~depthcore.studies.trials.simulate`):
        for the last three, the truths are drawn from the prior centred on
        ``truth`` and the result's ``"prior_gaussian"`` holds the filters'
        prior (its ``"mean"`` and ``"cov"``).
    prior_scale : float
        The prior covariance ``prior_scale * I`` of the paper's rule and of
        ``"fixed"`` (default the paper's 1000); the drawn forms state their own.
    names : sequence of str
        Filters to score, from :data:`depthcore.registry.filters.FILTERS`; only these
        run. The Hellinger distances need the optimal filter: when
        ``"optimal"`` is not among ``names`` it is not run and every
        filter's ``hellinger_depth`` is ``None``.
    chunk : int
        Trials drawn and filtered together (default :data:`CHUNK`), one task
        of :func:`~depthcore.studies.tasks.fold_chunks`. Memory grows with
        ``chunk`` (and ``n_particles``), not with ``trials``: only running
        sums are kept.
    n_particles : int
        Particles per trial of the particle filter.
    frames : int
        ``N >= 3``: the point, at ``truth`` at time 3, moves on to frame ``N``
        and every filter is scored on its state there (:func:`~depthcore.studies.trials.simulate`).
    process_noise : float
        ``q >= 0``: the velocity's change per frame from time 3 on, drawn in
        every trial, so the true state at frame ``N`` differs from trial to
        trial (the scores are against each trial's own); the state at time 3
        is ``truth`` in every trial. The named filters must support the
        frames and the process noise (:class:`depthcore.registry.filters.Filter`).
    paired : bool
        Also keep, over the same chunks, the running mean and covariance of
        every filter's per-trial depth scores
        (:func:`~depthcore.studies.pairs.trial_scores`, a
        :class:`~depthcore.studies.pairs.CoMoments`), returned as
        ``"paired"`` (:meth:`~depthcore.studies.pairs.CoMoments.summary`,
        columns ``[filter, score]``), from which the errors of ratios and
        differences of two scores over the same trials follow
        (:func:`~depthcore.studies.pairs.pair_of`,
        :func:`~depthcore.studies.pairs.ratio_se`,
        :func:`~depthcore.studies.pairs.paired_difference_se`). Its memory
        grows with the square of the number of filters, not with ``trials``.
    progress : callable, optional
        ``progress(done, total)``, called as each chunk completes, with the
        trials of the chunks completed so far and ``trials``.
    client : distributed.Client, optional
        Filter the chunks as tasks of its cluster (:mod:`depthcore.studies.tasks`);
        default in this process (or on the cluster named by
        ``DEPTHCORE_SCHEDULER``). The result is the same, bit for bit.

    Notes
    -----
    The noise and the random filters draw from the first two children of the
    one seed, whichever filters run: a filter's results do not depend on
    which other filters are named. The noise is drawn from one stream, chunk
    after chunk, so it does not depend on ``chunk``, and the scores of the
    deterministic filters agree across chunk sizes to rounding. The random
    filters of chunk ``k`` draw from the second child's child ``k``
    (:func:`~depthcore.studies.tasks.chunk_seeds`): their draws depend on
    ``chunk``, not on where or in what order the chunks run. The chunks'
    results are added in chunk order, so the result does not depend on the
    number of workers either.
    """
    run = Study(
        truth,
        rho,
        trials,
        seed,
        prior,
        prior_scale,
        names,
        chunk,
        n_particles,
        frames,
        process_noise,
        paired,
    )
    tasks.fold_chunks(
        filter_chunk,
        run.items(),
        run.fold,
        run.sizes,
        run.trials,
        progress=progress,
        client=client,
    )
    return run.result()


class Study:
    """One study's chunks and running sums: :func:`study` in parts, for a runner of many.

    ``Study(...)`` checks the arguments (those of :func:`study`, in its order,
    without ``progress`` and ``client``) and plans the chunks; :meth:`items`
    draws each chunk's trials in order (the inputs of :func:`filter_chunk`);
    :meth:`fold` adds a chunk's result, in chunk order; :meth:`result` is
    :func:`study`'s. A runner that folds several studies' chunks in one stream
    (:mod:`depthcore.studies.atlas`) gets, study by study, what :func:`study`
    returns.

    Attributes
    ----------
    sizes : list of int
        The trials of each chunk, in order.
    trials : int
    n_valid : int
        Trials folded so far that were scored.
    n_rejected : int
        Trials folded so far that were left out.
    """

    def __init__(
        self,
        truth=None,
        rho: float = SCENARIOS["fig2"].rho,
        trials: int = 500,
        seed=0,
        prior: str = "paper",
        prior_scale: float = PAPER_PRIOR_SCALE,
        names=NAMES,
        chunk: int = CHUNK,
        n_particles: int = PARTICLES,
        frames: int = 3,
        process_noise: float = 0.0,
        paired: bool = False,
    ):
        self.truth = SCENARIOS["fig2"].c if truth is None else truth
        names = check_names(names)
        if not (isinstance(trials, (int, np.integer)) and trials >= 1):
            raise ValueError(f"trials must be a positive integer, got {trials!r}")
        chunk = checks.count(chunk, "chunk")
        q = checks.nonnegative_scalar(process_noise, "process_noise")
        frames = checks.frames(frames)
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
        self.prior_scale = checks.positive_scalar(prior_scale, "prior_scale")
        self.seed = checks.seed_sequence(seed)
        noise_seed, particle_seed = checks.spawn(self.seed, 2)
        self._noise_seed = noise_seed
        self.trials, self.names, self.rho, self.prior = int(trials), names, rho, prior
        self.frames, self.q, self.paired, self.n_particles = frames, q, paired, n_particles
        self.sizes = [min(chunk, self.trials - start) for start in range(0, self.trials, chunk)]
        random = any(FILTERS[n].random for n in names)
        n = len(self.sizes)
        self._seeds = tasks.chunk_seeds(particle_seed, n) if random else [None] * n
        self.tallies = self.comoments = self._part = None
        self.n_valid = self.n_rejected = 0

    def items(self):
        """Each chunk's ``(trials, names, seed, n_particles)``, drawn in order, lazily."""
        # the noise is drawn here, chunk after chunk from one stream, as it
        # would be in one chunk: the trials do not depend on the chunks
        noise_rng = np.random.default_rng(self._noise_seed)
        for size, chunk_seed in zip(self.sizes, self._seeds, strict=True):
            part = simulate(
                self.truth,
                self.rho,
                size,
                noise_rng,
                self.prior,
                self.prior_scale,
                frames=self.frames,
                process_noise=self.q,
            )
            yield part, self.names, chunk_seed, self.n_particles

    def fold(self, k: int, result) -> None:
        """Add chunk ``k``'s result (:func:`filter_chunk`'s), ``k = 0, 1, ...`` in order."""
        part, estimates = result
        self._part = part
        if self.tallies is None:
            self.tallies = {name: Tally(part.truth) for name in self.names}
        self.n_rejected += part.n_rejected
        if estimates is None:
            return
        self.n_valid += len(part.mu)
        for name, est in estimates.items():  # a row beside the filters (trials.UNDER_LAW) too
            self.tallies.setdefault(name, Tally(part.truth)).add(est)
        if self.paired:
            per_trial, both = _paired_rows(estimates, part.truth, len(part.mu))
            if self.comoments is None:
                columns = [(n, k) for n in self.names for k in per_trial[n]]
                self.comoments = CoMoments(columns)
            self.comoments.add(
                np.column_stack([per_trial[n][k][both] for n, k in self.comoments.columns])
            )

    def header(self) -> dict:
        """What the study was: every key of :meth:`result` but ``filters`` and ``paired``."""
        return {
            "truth": [float(v) for v in self._part.truth],
            "rho": float(self.rho),
            "prior": self.prior,
            "prior_scale": self.prior_scale,
            "seed": self.seed.entropy,
            "trials": self.trials,
            "valid_trials": self.n_valid,
            "rejected_trials": self.n_rejected,
            "particles": int(self.n_particles)
            if any(FILTERS[n].random for n in self.names)
            else None,
            "frames": int(self.frames),
            "process_noise": self.q,
        }

    def result(self) -> dict:
        """:func:`study`'s result, once every chunk is folded."""
        if self.n_valid == 0:
            raise ValueError(
                f"truth and rho leave no valid trial: all {self.trials} noisy triples are "
                "degenerate or put the point behind the camera"
            )
        silent = [n for n, t in self.tallies.items() if t.n == 0]
        if silent:
            raise ValueError(
                f"filters: the {', '.join(silent)} filter has no answer for any of the "
                f"{self.n_valid} valid trials; leave it out"
            )
        out = {**self.header(), "filters": {n: t.scores() for n, t in self.tallies.items()}}
        if self.prior in prior_forms.DRAWN:
            mean, cov = prior_forms.gaussian(self.prior, model.G(self._part.truth, -2), self.rho)
            out["prior_gaussian"] = {"mean": mean.tolist(), "cov": cov.tolist()}
        if self.paired:
            out["paired"] = self.comoments.summary()
        return out


def _paired_rows(estimates: dict, truth, m: int) -> tuple:
    """Each filter's per-trial scores over a chunk's ``m`` trials, and the trials all answer.

    Returns ``({name: {score: (m,)}}, both)``: a trial a filter refused is
    NaN in its scores, and ``both`` (bool, shape (m,)) marks the trials
    every filter answered, over which the pairs are compared.
    """
    both = np.ones(m, dtype=bool)
    out = {}
    for name, est in estimates.items():
        rows = np.ones(m, dtype=bool) if est.answered is None else est.answered
        both &= rows
        out[name] = {}
        for key, values in trial_scores(est, truth).items():
            full = np.full(m, np.nan)
            full[rows] = values
            out[name][key] = full
    return out, both


#: The ``truth`` that asks for truths drawn from the prior (:func:`prior_study`).
PRIOR_TRUTH = "prior"


#: False-alarm rate of the uniformity tests reported by :func:`prior_study`.
FALSE_ALARM = 0.01

#: Truths filtered together by :func:`prior_study`, one task each.
PRIOR_CHUNK = 256


def _pit_chunk(item) -> tuple:
    """The PIT values of one chunk of truths: a task of :func:`prior_study`.

    ``item`` is ``(mu, truth, rho, mean, cov, q)``; returns
    :func:`depthcore.analysis.calibration.pit_values`'s ``(depth, velocity)``.
    """
    mu, truth, rho, mean, cov, q = item
    return calibration.pit_values(mu, truth, rho, mean, cov, q, q > 0)


def prior_study(
    rho: float = SCENARIOS["fig2"].rho,
    trials: int = 500,
    seed=0,
    prior_scale: float = PAPER_PRIOR_SCALE,
    false_alarm: float = FALSE_ALARM,
    frames: int = 3,
    process_noise: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
    client=None,
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
    camera (:func:`depthcore.analysis.calibration.self_calibration`). The coverage of
    the central intervals at every level of :data:`~depthcore.studies.scores.CALIBRATION_LEVELS` is
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
        ``N``, from 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    process_noise : float
        ``q >= 0``.
    progress : callable, optional
        ``progress(done, total)``, called as the trials are filtered.
    client : distributed.Client, optional
        Filter the truths, drawn here, in chunks of :data:`PRIOR_CHUNK` as tasks
        of its cluster (:mod:`depthcore.studies.tasks`); default in this process.
        The result is the same, bit for bit.

    Returns
    -------
    dict
        JSON-ready.
    """
    prior_scale = checks.positive_scalar(prior_scale, "prior_scale")
    false_alarm = checks.probability(false_alarm, "false_alarm")
    seed = checks.seed_sequence(seed)
    mean = paper_prior_means(np.asarray(SCENARIOS["fig2"].c, dtype=float)[None])[0]
    cov = prior_scale * np.eye(3)
    frames = checks.frames(frames)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    draws = calibration.draw_from_prior(
        mean, cov, rho, trials, np.random.default_rng(seed), frames=frames, process_noise=q
    )
    starts = range(0, len(draws.mu), PRIOR_CHUNK)
    pits = []
    tasks.fold_chunks(
        _pit_chunk,
        (
            (draws.mu[i : i + PRIOR_CHUNK], draws.truth[i : i + PRIOR_CHUNK], rho, mean, cov, q)
            for i in starts
        ),
        lambda k, pit: pits.append(pit),
        sizes=[len(draws.mu[i : i + PRIOR_CHUNK]) for i in starts],
        total=len(draws.mu),
        progress=progress,
        client=client,
    )
    depth, velocity = (np.concatenate([p[j] for p in pits]) for j in (0, 1))
    r = calibration.SelfCalibration(draws, float(rho), float(rho), depth, velocity)
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


#: The depth scores :func:`gather_scores` gathers for the book's studies over several settings.
DEPTH_SCORES = ("bias", "rmse", "mean_sd", "coverage_68", "coverage_95")


def gather_scores(filter_results, scores) -> dict:
    """One filter's depth scores over several studies, each with its standard error.

    Parameters
    ----------
    filter_results : sequence of dict, length S
        The filter's entry of :func:`depthcore.studies.monte_carlo.study`'s ``"filters"``,
        one per study.
    scores : sequence of str
        Depth scores of :func:`depthcore.studies.scores.scores`.

    Returns
    -------
    dict
        ``{score: (S,), score + "_se": (S,)}`` for each score, and ``"nees"``,
        ``"nees_se"`` (S,).
    """
    out = {}
    for score in scores:
        out[score] = np.array([x["depth"][score] for x in filter_results])
        out[f"{score}_se"] = np.array([x["depth"][f"{score}_se"] for x in filter_results])
    out["nees"] = np.array([x["nees"] for x in filter_results])
    out["nees_se"] = np.array([x["nees_se"] for x in filter_results])
    return out
