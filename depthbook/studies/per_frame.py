"""Every filter scored at every frame of one set of tracks: the tracking literature's evaluation.

Recommended import: ``from depthbook.studies import per_frame``.

:func:`per_frame_study` draws each trial's track of ``N`` frames once, runs
every filter on it and scores its estimate of the state at every frame ``k``
from 3 to ``N`` (given the bearings up to ``k``), as the bearings-only
tracking literature evaluates a filter ([ristic2004]_, chapter 6;
[barshalom2001]_, section 5.4):

* the RMSE of the depth and velocity means with its standard error (the
  delta method), the bias and the mean stated SD, beside the Cramér-Rao bound
  at frame ``k`` (:func:`depthcore.analysis.bound.posterior_bound`);
* the NEES, ``(m - x)^T P^{-1} (m - x)`` over the whole state, averaged over
  the ``M`` trials (the ANEES), with its chi-square acceptance region
  (:func:`depthcore.studies.scores.anees_region`: ``M`` times the ANEES of
  a filter whose errors follow its covariances is chi-square with ``3 M``
  degrees of freedom), and the fraction of trials whose own NEES lies
  outside the central 95 % region of the chi-square with 3 degrees of
  freedom;
* track loss at every frame at each threshold of :data:`TRACK_LOSS_LEVELS`
  (the position error over the true distance, as
  :func:`depthcore.studies.scores.lost_tracks`), with its binomial standard
  error and exact (Clopper-Pearson) upper bound, and the RMSE over the tracks
  not lost.

A recursive filter whose result holds its state after each bearing (a
:class:`~depthcore.problem.gaussian.History`: the EKF, the iterated EKF, the
UKF) is run once on the ``N`` bearings and read at every frame; the others
(the exact filter, the second-order fit, the inverse-depth EKF) run on the
first ``k`` bearings for each ``k``.

The trials are drawn and filtered in blocks of :data:`BLOCK`, each from its
own seed (a child of the study's seed by block index), and each block's
scores are summed as one and added in block order; the blocks are grouped
into chunks, tasks of :func:`depthcore.studies.tasks.fold_chunks`. The result
is therefore the same, bit for bit, whatever the chunk size and however many
workers run the chunks, and the memory held is that of one chunk.

References
----------
.. [ristic2004] B. Ristic, S. Arulampalam and N. Gordon, *Beyond the Kalman
   Filter: Particle Filters for Tracking Applications*, Artech House, 2004.
.. [barshalom2001] Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation
   with Applications to Tracking and Navigation*, Wiley, 2001.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from depthcore.analysis import bound
from depthcore.problem import checks
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, History
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS, check_names
from depthcore.studies import scores, tasks
from depthcore.studies.scores import lost_tracks
from depthcore.studies.trials import PARTICLES, simulate

#: Trials drawn and filtered together from one seed, the unit the results are summed in.
BLOCK = 50

#: Trials per chunk (a task of :func:`~depthcore.studies.tasks.fold_chunks`), a multiple of BLOCK.
CHUNK = 200

#: Thresholds of track loss, on the position error over the point's true distance.
TRACK_LOSS_LEVELS = (0.1, 0.25, 0.5, 1.0)

#: Level of the chi-square acceptance regions of the NEES and the ANEES.
NEES_LEVEL = 0.95

#: Dimension of the state whose NEES is scored, ``(x, y, v)``.
STATE_DIM = 3

#: The filters of :func:`per_frame_study` unless named: the deterministic ones of the bound.
NAMES = ("optimal", "second_order", "ekf", "inverse_depth", "iterated", "ukf")


def frame_states(name, mu, rho, prior_mean, prior_cov, frames, process_noise=0.0, **options):
    """A filter's mean and covariance of the state at each frame, given the bearings up to it.

    Parameters
    ----------
    name : str
        A filter of :data:`depthcore.registry.filters.FILTERS`.
    mu : ndarray, shape (B, N)
        Bearings of frames 1 .. N.
    rho, prior_mean, prior_cov, process_noise
        As the registry's filters take them.
    frames : array_like of int, shape (F,)
        Frames ``k``, each from 3 (or 1 for a recursive filter) to ``N``.
    **options
        For the filter (``rng``, ``n_particles``).

    Returns
    -------
    tuple of ndarray
        Means (F, B, 3) and covariances (F, B, 3, 3): those of the filter run
        on ``mu[:, :k]``. A filter whose result is a
        :class:`~depthcore.problem.gaussian.History` of the ``N`` frames
        (its state after each bearing) is run once and read at each ``k``.
    """
    f = FILTERS[name]
    frames = np.asarray(frames, dtype=int)
    noise = {"process_noise": process_noise} if process_noise > 0 else {}
    n = mu.shape[-1]
    est = f(mu, rho, prior_mean, prior_cov, **noise, **options)
    history = est.detail
    if isinstance(history, History) and np.shape(history.means)[-2] == n:
        means = np.moveaxis(np.asarray(history.means)[..., frames - 1, :], -2, 0)
        covs = np.moveaxis(np.asarray(history.covs)[..., frames - 1, :, :], -3, 0)
        return means, covs
    means, covs = [], []
    for k in frames:
        e = est if k == n else f(mu[:, :k], rho, prior_mean, prior_cov, **noise, **options)
        means.append(np.asarray(e.mean, dtype=float))
        covs.append(np.asarray(e.cov, dtype=float))
    return np.stack(means), np.stack(covs)


def trial_values(means, covs, states, levels=TRACK_LOSS_LEVELS) -> dict:
    """Each trial's scores at each frame, from the filter's states and the true ones.

    Parameters
    ----------
    means : ndarray, shape (F, T, 3)
    covs : ndarray, shape (F, T, 3, 3)
    states : ndarray, shape (F, T, 3)
        The true states.
    levels : sequence of float, shape (L,)
        Thresholds of track loss.

    Returns
    -------
    dict
        ``"error"`` and ``"sd"`` (T, F, 2), the depth and velocity errors and
        stated SDs; ``"nees"`` (T, F); ``"lost"`` (T, L, F) of bool
        (:func:`~depthcore.studies.scores.lost_tracks` at each threshold).
        Trials first, the axis the sums run over.
    """
    full = means - states
    with np.errstate(invalid="ignore", over="ignore"):
        nees = np.einsum("fti,fti->ft", full, np.linalg.solve(covs, full[..., None])[..., 0])
    sd = np.sqrt(np.diagonal(covs, axis1=-2, axis2=-1)[..., 1:])
    lost = np.stack([lost_tracks(means, states, t) for t in levels])
    return {
        "error": np.moveaxis(full[..., 1:], 1, 0),
        "sd": np.moveaxis(sd, 1, 0),
        "nees": np.moveaxis(nees, 1, 0),
        "lost": np.moveaxis(lost, 2, 0),
    }


class FrameMoments:
    """Running count, sum and sum of squared deviations of values over blocks of trials, per cell.

    Each block's values (trials first) are added by :meth:`add`, optionally
    only where a mask is true, pooled by Chan, Golub and LeVeque's update
    (:func:`depthcore.studies.scores.pooled_squares`, here with a count per
    cell). Memory is that of one cell array, whatever the number of trials.
    """

    def __init__(self, shape):
        self.n = np.zeros(shape, dtype=np.int64)
        self.total = np.zeros(shape)
        self.squares = np.zeros(shape)

    def add(self, values, mask=None) -> None:
        """Add a block: ``values``, shape ``(m, *shape)``, counted where ``mask`` is true."""
        v = np.asarray(values, dtype=float)
        mask = np.ones(v.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        m = np.count_nonzero(mask, axis=0)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            total_b = np.sum(np.where(mask, v, 0.0), axis=0)
            mean_b = np.where(m > 0, total_b / np.maximum(m, 1), 0.0)
            s_b = np.sum(np.where(mask, (v - mean_b) ** 2, 0.0), axis=0)
            n = self.n
            delta = np.where((n > 0) & (m > 0), mean_b - self.total / np.maximum(n, 1), 0.0)
            self.squares = self.squares + s_b + delta**2 * (n * m / np.maximum(n + m, 1))
        self.total = self.total + total_b
        self.n = self.n + m

    def mean(self) -> np.ndarray:
        """The mean per cell (NaN where nothing was counted)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.n > 0, self.total / np.maximum(self.n, 1), np.nan)

    def se(self) -> np.ndarray:
        """The standard error of the mean per cell, ``sqrt(s**2 / n)`` (0 below two trials)."""
        n = self.n
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 1, np.sqrt(self.squares / np.maximum(n - 1, 1) / n), 0.0)


class FrameTally:
    """Running sums of one filter's scores at every frame, over blocks of trials.

    Parameters
    ----------
    frames : int
        ``F``, the frames scored.
    levels : sequence of float, shape (L,)
        Thresholds of track loss.
    """

    def __init__(self, frames: int, levels=TRACK_LOSS_LEVELS):
        self.levels = tuple(float(t) for t in levels)
        L = len(self.levels)
        self.n = 0
        self.error = FrameMoments((frames, 2))
        self.squared = FrameMoments((frames, 2))
        self.sd = FrameMoments((frames, 2))
        self.nees = FrameMoments(frames)
        self.outside = np.zeros(frames, dtype=np.int64)
        self.lost = np.zeros((L, frames), dtype=np.int64)
        self.kept = FrameMoments((L, frames, 2))

    def add(self, values: dict, region) -> None:
        """Add one block's :func:`trial_values`; ``region`` the NEES's per-trial (lo, hi)."""
        err = values["error"]
        if len(err) == 0:
            return
        self.n += len(err)
        self.error.add(err)
        self.squared.add(err**2)
        self.sd.add(values["sd"])
        self.nees.add(values["nees"])
        nees = values["nees"]
        self.outside += np.count_nonzero(~((nees >= region[0]) & (nees <= region[1])), axis=0)
        lost = values["lost"]
        self.lost += np.count_nonzero(lost, axis=0)
        kept = np.broadcast_to(~lost[..., None], lost.shape + (2,))
        self.kept.add(np.broadcast_to(err[:, None] ** 2, kept.shape), kept)

    def scores(self, confidence: float = 0.95) -> dict:
        """The scores at every frame, each with its standard error; arrays of shape (F,) or (L, F).

        Returns
        -------
        dict
            ``"trials"``; ``"depth"`` and ``"velocity"``, each ``{"bias",
            "bias_se", "rmse", "rmse_se", "mean_sd", "mean_sd_se"}`` (F,);
            ``"nees"``, ``"nees_se"`` (F,) (the ANEES over the trials and its
            standard error); ``"nees_outside"``, ``"nees_outside_se"`` (F,):
            the fraction of trials whose NEES lies outside its per-trial
            region; ``"track_loss"``: ``{"levels", "lost", "fraction", "se",
            "upper"}`` (L, F), the upper bound the Clopper-Pearson one at
            ``confidence``, and per quantity ``{"rmse_kept", "rmse_kept_se"}``
            (L, F), the RMSE over the trials not lost (NaN where every one is).
        """
        from scipy.stats import beta  # imported here: scipy.stats takes a second to import

        if self.n == 0:
            raise ValueError("trials: no trial was added to the tally")
        n = self.n
        out: dict = {"trials": n}
        bias, bias_se = self.error.mean(), self.error.se()
        mse, mse_se = self.squared.mean(), self.squared.se()
        rmse, rmse_se = _rmse(mse, mse_se)
        mean_sd, mean_sd_se = self.sd.mean(), self.sd.se()
        kept_rmse, kept_se = _rmse(self.kept.mean(), self.kept.se())
        for k, q in enumerate(("depth", "velocity")):
            out[q] = {
                "bias": bias[:, k],
                "bias_se": bias_se[:, k],
                "rmse": rmse[:, k],
                "rmse_se": rmse_se[:, k],
                "mean_sd": mean_sd[:, k],
                "mean_sd_se": mean_sd_se[:, k],
            }
        out["nees"], out["nees_se"] = self.nees.mean(), self.nees.se()
        p = self.outside / n
        out["nees_outside"], out["nees_outside_se"] = p, np.sqrt(p * (1 - p) / n)
        p = self.lost / n
        with np.errstate(invalid="ignore"):
            upper = np.where(
                self.lost == n,
                1.0,
                beta.ppf(confidence, self.lost + 1, np.maximum(n - self.lost, 1)),
            )
        out["track_loss"] = {
            "levels": list(self.levels),
            "lost": self.lost.copy(),
            "fraction": p,
            "se": np.sqrt(p * (1 - p) / n),
            "upper": upper,
            "confidence": float(confidence),
            "depth": {"rmse_kept": kept_rmse[..., 0], "rmse_kept_se": kept_se[..., 0]},
            "velocity": {"rmse_kept": kept_rmse[..., 1], "rmse_kept_se": kept_se[..., 1]},
        }
        return out


def _rmse(mse, mse_se) -> tuple:
    """The RMSE and its standard error by the delta method, ``se(MSE) / (2 RMSE)``."""
    rmse = np.sqrt(mse)
    with np.errstate(invalid="ignore", divide="ignore"):
        se = np.where(rmse > 0, mse_se / (2.0 * rmse), 0.0)
    return rmse, se


def block_chunk(item) -> list:
    """One chunk of :func:`per_frame_study`: its blocks drawn and filtered, a task of :mod:`.tasks`.

    Parameters
    ----------
    item : tuple
        ``(blocks, settings)``: ``blocks`` a list of ``(noise_seed,
        particle_seed, size, particle_rows)``, one per block, and
        ``settings`` the study's ``{"truth", "rho", "prior", "frames",
        "process_noise", "names", "n_particles", "levels"}``.

    Returns
    -------
    list of dict, one per block
        ``"truth"``, ``"rejected"``, ``"valid"`` and ``"values"``
        ``{name: trial_values}`` (``None`` for a block with no valid trial).
    """
    blocks, s = item
    n_frames = s["frames"]
    scored = np.arange(3, n_frames + 1)
    out = []
    for noise_seed, particle_seed, size, particle_rows in blocks:
        part = simulate(
            s["truth"],
            s["rho"],
            size,
            np.random.default_rng(noise_seed),
            s["prior"],
            PAPER_PRIOR_SCALE,
            n_frames,
            s["process_noise"],
            tracks=True,
        )
        result = {"truth": part.truth, "rejected": part.n_rejected, "valid": len(part.mu)}
        if not len(part.mu):
            result["values"] = None
            out.append(result)
            continue
        rng = np.random.default_rng(particle_seed)
        states = np.moveaxis(part.tracks[:, scored - 1, :], 1, 0)
        values = {}
        for name in s["names"]:
            f = FILTERS[name]
            rows = slice(None)
            options = {}
            if f.random:
                rows = slice(0, max(particle_rows, 0))
                options = {"rng": rng, "n_particles": s["n_particles"]}
            mu = part.mu[rows]
            if not len(mu):
                continue
            means, covs = frame_states(
                name,
                mu,
                part.rho,
                part.prior_mean[rows],
                part.prior_cov,
                scored,
                s["process_noise"],
                **options,
            )
            values[name] = trial_values(means, covs, states[:, rows], s["levels"])
        result["values"] = values
        out.append(result)
    return out


def per_frame_study(
    frames: int,
    trials: int,
    seed,
    names=NAMES,
    prior: str = "paper",
    process_noise: float = 0.0,
    truth=None,
    rho: float = SCENARIOS["fig2"].rho,
    particle_trials: int | None = None,
    n_particles: int = PARTICLES,
    chunk: int = CHUNK,
    levels=TRACK_LOSS_LEVELS,
    progress: Callable[[int, int], None] | None = None,
    client=None,
) -> dict:
    """Every named filter scored at every frame ``k = 3 .. N`` of tracks of ``N`` frames.

    The truth is ``truth`` at time 3 (default Figure 2's ``c``), followed on
    to frame ``N`` with velocity changes of SD ``process_noise`` from time 3
    on, as in :func:`depthcore.studies.trials.simulate` (whose trials without a
    noise-free solution in front of the camera are left out). Each trial's
    track and bearings are drawn once; every filter runs on them
    (:func:`frame_states`) and is scored at each frame ``k`` against the
    track's state there (:class:`FrameTally`). See the module docstring for
    the scores and how the result is independent of ``chunk`` and ``client``.

    Parameters
    ----------
    frames : int
        ``N``, from 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    trials : int
        Trials drawn, >= 2.
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters of :data:`depthcore.registry.filters.FILTERS`, each able to
        run on ``N`` frames with the process noise asked for.
    prior : {"paper", "fixed"}
        As :func:`depthcore.studies.trials.simulate` takes it, covariance 1000 I.
    process_noise : float
        ``q >= 0``.
    truth : array_like, shape (3,), optional
    rho : float
    particle_trials : int, optional
        The filters that draw random numbers run on at most this many valid
        trials (default ``trials``): in block ``b``, on its first
        ``particle_trials - b BLOCK`` valid ones.
    n_particles : int
    chunk : int
        Trials per task, a multiple of :data:`BLOCK`: the memory held is of
        one chunk, the result the same whatever ``chunk``.
    levels : sequence of float
        Thresholds of track loss, each > 0 (default :data:`TRACK_LOSS_LEVELS`).
    progress : callable, optional
        ``progress(done, total)`` as each chunk completes, in trials.
    client : distributed.Client, optional
        Run the chunks on its cluster (:func:`depthcore.studies.tasks.fold_chunks`).

    Returns
    -------
    dict
        ``"frames"`` (K,), the frames ``3 .. N``; ``"truth"``, ``"rho"``,
        ``"prior"``, ``"process_noise"``, ``"seed"``, ``"trials"``,
        ``"valid_trials"``, ``"rejected_trials"``, ``"particle_trials"``,
        ``"levels"``; ``"nees_region"``, the per-trial central
        :data:`NEES_LEVEL` region of the chi-square with 3 degrees of freedom;
        ``"bound"``: ``{"depth", "velocity"}`` (K,), the SDs of
        :func:`depthcore.analysis.bound.posterior_bound` at each frame (for
        the truth's law, the prior covariance and ``process_noise``); and
        ``"filters"``: per filter :meth:`FrameTally.scores` (arrays over the
        K frames) and ``"anees_region"``, the
        :func:`depthcore.studies.scores.anees_region` of its trials.
    """
    n_frames = checks.frames(frames)
    trials = checks.count(trials, "trials")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    names = check_names(names)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    unable = [
        n
        for n in names
        if (n_frames > 3 and not FILTERS[n].any_frames)
        or (q > 0 and not FILTERS[n].with_process_noise)
    ]
    if unable:
        raise ValueError(
            f"names: {', '.join(unable)} cannot run on {n_frames} frames with process "
            f"noise {q:g}; leave them out"
        )
    chunk = checks.count(chunk, "chunk")
    if chunk % BLOCK:
        raise ValueError(f"chunk must be a multiple of {BLOCK} trials, got {chunk}")
    particle_trials = (
        trials if particle_trials is None else checks.count(particle_trials, "particle_trials")
    )
    levels = tuple(checks.positive_scalar(t, "levels") for t in levels)
    truth = checks.finite_array(SCENARIOS["fig2"].c if truth is None else truth, "truth", (3,))
    rho = checks.positive_scalar(rho, "rho")
    seed = checks.seed_sequence(seed)
    noise_seed, particle_seed = checks.spawn(seed, 2)
    n_blocks = -(-trials // BLOCK)
    sizes = [min(BLOCK, trials - b * BLOCK) for b in range(n_blocks)]
    blocks = list(
        zip(
            tasks.chunk_seeds(noise_seed, n_blocks),
            tasks.chunk_seeds(particle_seed, n_blocks),
            sizes,
            [particle_trials - b * BLOCK for b in range(n_blocks)],
            strict=True,
        )
    )
    settings = {
        "truth": truth,
        "rho": rho,
        "prior": prior,
        "frames": n_frames,
        "process_noise": q,
        "names": names,
        "n_particles": n_particles,
        "levels": levels,
    }
    per_chunk = chunk // BLOCK
    groups = [blocks[i : i + per_chunk] for i in range(0, n_blocks, per_chunk)]
    region = _nees_region()
    tallies = {name: FrameTally(n_frames - 2, levels) for name in names}
    counts = {"valid": 0, "rejected": 0}

    def fold(k, result):
        for block in result:
            counts["valid"] += block["valid"]
            counts["rejected"] += block["rejected"]
            for name, values in (block["values"] or {}).items():
                tallies[name].add(values, region)

    tasks.fold_chunks(
        block_chunk,
        ((g, settings) for g in groups),
        fold,
        [sum(b[2] for b in g) for g in groups],
        trials,
        progress=progress,
        client=client,
    )
    if counts["valid"] == 0:
        raise ValueError(
            f"truth and rho leave no valid trial: all {trials} noisy triples are degenerate "
            "or put the point behind the camera"
        )
    cov = PAPER_PRIOR_SCALE * np.eye(3)
    b = bound.posterior_bound(truth, 3, n_frames, rho, cov, q)[2:]
    out = {
        "frames": np.arange(3, n_frames + 1),
        "truth": [float(v) for v in truth],
        "rho": rho,
        "prior": prior,
        "process_noise": q,
        "seed": seed.entropy,
        "trials": trials,
        "valid_trials": counts["valid"],
        "rejected_trials": counts["rejected"],
        "particle_trials": min(particle_trials, trials),
        "levels": list(levels),
        "nees_region": list(region),
        "bound": {"depth": np.sqrt(b[:, 1, 1]), "velocity": np.sqrt(b[:, 2, 2])},
        "filters": {},
    }
    for name, tally in tallies.items():
        if tally.n == 0:
            continue
        s = tally.scores()
        s["anees_region"] = list(scores.anees_region(tally.n, STATE_DIM, NEES_LEVEL))
        out["filters"][name] = s
    return out


def _nees_region(level: float = NEES_LEVEL) -> tuple:
    """The central ``level`` region of one trial's NEES, a chi-square with 3 degrees of freedom."""
    from scipy.stats import chi2

    a = 1.0 - level
    return float(chi2.ppf(a / 2, STATE_DIM)), float(chi2.ppf(1 - a / 2, STATE_DIM))
