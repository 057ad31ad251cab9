"""An atlas of the problem: every filter's verdicts over a grid of settings.

Recommended import: ``from depthcore.studies import atlas``.

A cell of the atlas is one :func:`depthcore.studies.monte_carlo.study`: a
truth, a noise level, a prior and a number of frames, every filter of the
registry that runs there. The truth at time 3 is set by its **parallax**
``p``, the lateral velocity over the depth, and its depth ``y``:
``(p y, y, p y)``, a point that crosses the optical axis at time 2 as the
paper's Figure 2 does (``p = 0.2``, ``y = 6``); at ``p = 0`` it moves along
the axis and its bearings say nothing of its depth. The noise ``rho`` is
counted in pixels of the paper's camera (:data:`PIXEL`, 512 pixels over 30
degrees); the prior's ``form`` (:data:`FORMS`) is the paper's rule (covariance
``s I``, ``s`` the prior scale) or one whose truths are drawn from it, with its
own covariance (:mod:`depthcore.studies.priors`); every filter is scored at
frame ``N`` (``frames``), over the trials it answers, refusals counted apart
(:func:`depthcore.studies.trials.run_filters`).

Each cell says, for each filter, with tests of the cells' own Monte Carlo
error (three outcomes: yes, no, undecided):

* **calibrated**: its central 68 % depth interval's coverage lies within a
  stated tolerance of 0.68 (yes), outside it (no), or the trials cannot tell,
  the false-discovery rate of each claim held over the filter's cells
  (:func:`depthcore.studies.coverage_verdicts.with_calibration`, read over
  all cells once the last is in). Only the cells whose truths are drawn from
  the prior are judged: at the paper's rule the truth is fixed, and a
  coverage at one truth tests no posterior (``None`` there);
* **track lost**: the fraction of trials whose track is lost
  (:func:`~depthcore.studies.scores.lost_tracks`) lies above
  :data:`LOSS_LEVEL` (significantly above: yes; below: no);
* **near the bound**: its depth RMSE over the Cramér-Rao bound's SD
  (:func:`depthcore.analysis.bound.posterior_bound` with the cell's prior
  covariance, the bound of the book's bound chapter) is at most
  :data:`BOUND_TOLERANCE` (within 10 %), tested with its standard error.
  The bound is that of one fixed truth, so the forms whose truths are drawn
  have no bound and no such verdict (``None``).

A filter whose estimate has no interior maximum on a trial (the batch
maximum-likelihood estimate at its search limit) is scored over the others,
the trials at the limit counted apart (``"no_maximum"``).

:func:`atlas` runs all cells' chunks in one stream of tasks
(:func:`depthcore.studies.tasks.fold_chunks`) and folds them in order, each
cell reduced to its summary as its last chunk arrives: memory never holds
trials. Cell ``i``, seeded by the ``i``-th child of the seed, is what ``study``
returns with that seed (:func:`cell_study`); the atlas is the same, bit for
bit, on any number of workers (its ``cost`` aside).

Two sizes, :data:`SIZES`: the book's (``"book"``) and the full one
(``"full"``, every axis finer). Both draw the :data:`TRIALS` a calibration
verdict needs where the truths are drawn from the prior, and
:data:`FIXED_TRIALS` where the truth is fixed and only the error is scored
(:meth:`Grid.trials_of`). The full one's cost a
user can estimate from the book's measured cost per trial
(:func:`estimated_cost`) before running it on a cluster
(``python -m depthcore atlas --size full --scheduler ADDRESS``).
"""

from __future__ import annotations

import itertools
import math
import time
import warnings
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from depthcore.analysis import bound
from depthcore.problem import checks, model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE
from depthcore.registry.filters import ALL_NAMES, FILTERS
from depthcore.studies import coverage_verdicts, monte_carlo, tasks
from depthcore.studies import priors as prior_forms
from depthcore.studies.scores import TEST_Z, difference_verdict, proportion_se
from depthcore.studies.trials import UNDER_LAW, run_filters

#: The bearing noise of one pixel of the paper's camera, 512 pixels over 30 degrees (radians).
PIXEL = 1.0 / model.noise_in_pixels(1.0)

#: The prior's forms the atlas runs, the paper's rule and then the forms whose truths are drawn.
FORMS = prior_forms.FORMS

#: The axes of the grid, outermost first, in the order of :func:`cells`.
AXES = ("form", "frames", "rho", "prior_scale", "depth", "parallax")

#: The trials per cell the calibration verdict needs at its tolerance, in whole chunks of
#: 100 (:func:`depthcore.studies.coverage_verdicts.trials_needed`), which the full size runs.
TRIALS = 100 * math.ceil(coverage_verdicts.trials_needed() / 100)

#: The trials of a cell whose truth is fixed (the paper's rule), scored for error and not
#: for calibration (:func:`depthcore.studies.coverage_verdicts.fixed_truth`).
FIXED_TRIALS = 2200

#: The fraction of lost tracks above which a filter loses the track.
LOSS_LEVEL = 0.1

#: The RMSE over the bound's SD at most which a filter is near the bound (within 10 %).
BOUND_TOLERANCE = 1.1

#: The filters the book's atlas leaves out, each over 0.1 s per trial at 30 frames; the full
#: size runs them, and the book measures their cost apart (:func:`probe_cost`).
COSTLY = ("resample_move", "rbpf", "range_parametrised")

#: The verdicts of a cell, each True, False or None (undecided, or no answer).
VERDICTS = ("calibrated", "lost", "near_bound")

#: The verdicts each cell draws alone; ``calibrated`` is read over all cells.
CELL_VERDICTS = ("lost", "near_bound")


@dataclass(frozen=True)
class Grid:
    """The axes of an atlas, and its trials.

    Attributes
    ----------
    parallax : tuple of float
        Lateral velocity over depth at time 3, >= 0.
    depth : tuple of float
        Depth at time 3, > 2 (the point in front of the camera at time 1).
    prior_scale : tuple of float
        ``s`` of the prior covariance ``s I``, > 0.
    rho : tuple of float
        Bearing noise (radians), > 0.
    frames : tuple of int
        ``N``, 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    forms : tuple of str
        The prior's forms.
    trials : int
        Trials drawn per cell whose truths are drawn from the prior.
    n_particles : int
        Particles per trial of the filters that draw them.
    chunk : int
        Trials per chunk (a task).
    names : tuple of str
        The filters; those that cannot run at a cell's frames are left out there.
    max_frames : tuple of (str, int)
        Filters run only up to a number of frames, ``(name, N)`` pairs.
    fixed_trials : int, optional
        Trials drawn per cell whose truth is fixed (the paper's rule), where
        no calibration verdict is drawn; ``trials`` when not given.
    """

    parallax: tuple
    depth: tuple
    prior_scale: tuple
    rho: tuple
    frames: tuple
    forms: tuple
    trials: int
    n_particles: int
    chunk: int
    names: tuple = ALL_NAMES
    max_frames: tuple = ()
    fixed_trials: int | None = None

    def trials_of(self, cell: dict) -> int:
        """The trials drawn at ``cell``: ``fixed_trials`` where its truth is fixed."""
        fixed = coverage_verdicts.fixed_truth(cell) and self.fixed_trials is not None
        return self.fixed_trials if fixed else self.trials

    def runs(self, name: str, frames: int) -> bool:
        """Whether filter ``name`` runs on ``frames`` frames in this grid."""
        limit = dict(self.max_frames).get(name)
        able = frames == 3 or FILTERS[name].any_frames
        return able and (limit is None or frames <= limit)

    @property
    def shape(self) -> tuple:
        """The number of values of each axis of :data:`AXES` (the forms whose truths
        are drawn take the prior scale's first value alone, :func:`cells`)."""
        return tuple(len(self.axis(a)) for a in AXES)

    def axis(self, name: str) -> tuple:
        """The values of axis ``name`` of :data:`AXES`."""
        return self.forms if name == "form" else getattr(self, name)


#: The atlas's sizes, the book's record and the full one for a cluster.
SIZES = {
    "book": Grid(
        parallax=(0.0, 0.1, 0.2, 0.4),
        depth=(6.0,),
        prior_scale=(1000.0, 1.0),
        rho=(PIXEL, PIXEL / 10),
        frames=(3, 10, 30),
        forms=FORMS,
        trials=TRIALS,
        n_particles=200,
        chunk=100,
        names=tuple(n for n in ALL_NAMES if n not in COSTLY),
        fixed_trials=FIXED_TRIALS,
    ),
    "full": Grid(
        parallax=(0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.6),
        depth=(3.0, 4.0, 6.0, 12.0, 24.0),
        prior_scale=(1000.0, 100.0, 10.0, 1.0),
        rho=(PIXEL, PIXEL / math.sqrt(10), PIXEL / 10),
        frames=(3, 10, 30),
        forms=FORMS,
        trials=TRIALS,
        n_particles=500,
        chunk=100,
        fixed_trials=FIXED_TRIALS,
    ),
}


def grid_of(size) -> Grid:
    """The :class:`Grid` of ``size``, a key of :data:`SIZES` or a :class:`Grid`."""
    if isinstance(size, Grid):
        return size
    if isinstance(size, str) and size in SIZES:
        return SIZES[size]
    raise ValueError(f"size must be one of {tuple(SIZES)} or a Grid, got {size!r}")


def truth_of(parallax: float, depth: float) -> np.ndarray:
    """The true state at time 3 of a parallax and a depth: ``(p y, y, p y)``, shape (3,)."""
    p = checks.nonnegative_scalar(parallax, "parallax")
    y = checks.positive_scalar(depth, "depth")
    if not y > 2:
        raise ValueError(f"depth must exceed 2 (in front of the camera at time 1), got {y!r}")
    return np.array([p * y, y, p * y])


def cells(grid: Grid) -> list[dict]:
    """Every cell's setting, ``{axis: value}`` over :data:`AXES`, the last axis fastest.

    A form whose truths are drawn states its own covariance: it runs at the
    prior scale's first value alone, given as ``None``.
    """
    out = []
    first = grid.prior_scale[0]
    for values in itertools.product(*(grid.axis(a) for a in AXES)):
        cell = dict(zip(AXES, values, strict=True))
        if cell["form"] in prior_forms.DRAWN:
            if cell["prior_scale"] != first:
                continue
            cell["prior_scale"] = None
        out.append(cell)
    return out


def names_at(grid: Grid, frames: int) -> tuple:
    """The filters of ``grid`` that run on ``frames`` frames (:meth:`Grid.runs`)."""
    return tuple(n for n in grid.names if grid.runs(n, frames))


def cell_seed(seed, index: int) -> np.random.SeedSequence:
    """Cell ``index``'s seed: child ``index`` of ``seed``, whatever the number of cells."""
    root = checks.seed_sequence(seed)
    return np.random.SeedSequence(
        root.entropy, spawn_key=root.spawn_key + (int(index),), pool_size=root.pool_size
    )


def cell_study(grid: Grid, cell: dict, seed) -> monte_carlo.Study:
    """The :class:`~depthcore.studies.monte_carlo.Study` of one cell (``seed`` its own)."""
    return monte_carlo.Study(
        truth_of(cell["parallax"], cell["depth"]),
        rho=cell["rho"],
        trials=grid.trials_of(cell),
        seed=seed,
        prior=cell["form"],
        prior_scale=PAPER_PRIOR_SCALE if cell["prior_scale"] is None else cell["prior_scale"],
        names=names_at(grid, cell["frames"]),
        chunk=grid.chunk,
        n_particles=grid.n_particles,
        frames=cell["frames"],
    )


def bound_sd(cell: dict) -> float | None:
    """The Cramér-Rao bound's depth SD at frame ``N`` of a cell; None where it has none.

    A form whose truths are drawn has none: the bound is one fixed truth's.
    """
    if cell["prior_scale"] is None:
        return None
    truth = truth_of(cell["parallax"], cell["depth"])
    cov = cell["prior_scale"] * np.eye(3)
    try:
        b = bound.posterior_bound(truth, 3, cell["frames"], cell["rho"], cov)[-1, 1, 1]
    except ValueError:
        return None
    return float(np.sqrt(b)) if np.isfinite(b) and b > 0 else None


def chunk_task(item) -> tuple:
    """One chunk of a cell, a task of :mod:`.tasks`: its filters run and timed.

    Parameters
    ----------
    item : tuple
        :meth:`~depthcore.studies.monte_carlo.Study.items`' ``(trials, names,
        seed, n_particles)``.

    Returns
    -------
    tuple
        ``(trials, estimates, seconds, failed)``: ``estimates`` as
        :func:`~depthcore.studies.monte_carlo.filter_chunk`'s (``None``
        without a valid trial), ``seconds`` each filter's time, ``failed``
        ``{name: reason}`` of the filters that have no answer for a trial of
        the chunk, which are left out of ``estimates`` (the others then run
        again without them, their draws from the chunk's seed).
    """
    part, names, seed, n_particles = item
    if not len(part.mu):
        return part, None, {}, {}
    failed = {}
    with warnings.catch_warnings():
        # a diverging filter overflows: its non-finite answer is scored, not warned of
        warnings.simplefilter("ignore", RuntimeWarning)
        while names:
            seconds = {}
            rng = None if seed is None else np.random.default_rng(seed)
            try:
                return part, run_filters(part, names, rng, n_particles, seconds), seconds, failed
            except (ValueError, np.linalg.LinAlgError):
                new = _failing(part, names, seed, n_particles)
                if not new:
                    raise
            failed.update(new)
            names = tuple(n for n in names if n not in failed)
    return part, {}, {}, failed


def _failing(part, names, seed, n_particles) -> dict:
    """``{name: reason}`` of the filters that fail on ``part`` when run alone."""
    out = {}
    for name in names:
        rng = None if seed is None else np.random.default_rng(seed)
        try:
            run_filters(part, (name,), rng, n_particles)
        except (ValueError, np.linalg.LinAlgError) as exc:
            out[name] = " ".join(str(exc).split()) or type(exc).__name__
    return out


def _finite(x):
    """``x`` as a float, or None where it is not finite."""
    x = float(x)
    return x if math.isfinite(x) else None


def verdicts(summary: dict) -> dict:
    """A filter's verdicts in a cell that the cell draws alone, from its summary.

    Parameters
    ----------
    summary : dict
        From :func:`filter_summary`: with ``"trials"``, ``"track_loss"``,
        ``"lost"``, ``"bound_ratio"`` and ``"bound_ratio_se"`` (None where
        not finite).

    Returns
    -------
    dict
        ``{verdict: True, False or None}`` for each of :data:`CELL_VERDICTS`:
        None where the test cannot decide, or the score is None.
    """
    n = summary["trials"]
    out = dict.fromkeys(CELL_VERDICTS)
    if n >= 1:
        se = proportion_se(summary["lost"], n)
        v = int(difference_verdict(summary["track_loss"] - LOSS_LEVEL, se, TEST_Z))
        out["lost"] = None if v == 0 else v > 0
    r, r_se = summary["bound_ratio"], summary["bound_ratio_se"]
    if r is not None and r_se is not None:
        v = int(difference_verdict(r - BOUND_TOLERANCE, r_se, TEST_Z))
        out["near_bound"] = None if v == 0 else v < 0
    return out


def filter_summary(scores: dict, limit: float | None) -> dict:
    """What a cell keeps of one filter's :meth:`~depthcore.studies.scores.Tally.scores`.

    The depth's RMSE, median absolute error (where the scores have it),
    coverage and the fraction of lost tracks, each with its SE, the RMSE over
    ``limit`` (the bound's SD, None without one), the divergent trials'
    fraction (where the scores count them), the trials it refused and those
    where its estimate has no interior maximum (``"no_maximum"``, where the
    filter can have none; both counted apart: ``"trials"`` are those scored),
    and the :func:`verdicts`.
    """
    d = scores["depth"]
    n = int(scores["trials"])
    loss = scores["track_loss"]
    out = {
        "trials": n,
        "rmse": _finite(d["rmse"]),
        "rmse_se": _finite(d["rmse_se"]),
        "coverage_68": _finite(d["coverage_68"]),
        "coverage_68_se": _finite(d["coverage_68_se"]),
        "track_loss": float(loss["fraction"]),
        "track_loss_se": float(loss["se"]),
        "lost": int(round(loss["fraction"] * n)),
        "nees": _finite(scores["nees"]),
        "bound_ratio": None,
        "bound_ratio_se": None,
    }
    if "median_abs_error" in d:
        out["median_abs_error"] = _finite(d["median_abs_error"])
    if "refused" in scores:
        out["refused"] = int(scores["refused"]["count"])
    if "no_maximum" in scores:
        out["no_maximum"] = int(scores["no_maximum"]["count"])
    if "divergent" in scores:
        out["divergent"] = float(scores["divergent"]["fraction"])
        out["divergent_se"] = float(scores["divergent"]["se"])
    if limit is not None and out["rmse"] is not None and out["rmse_se"] is not None:
        out["bound_ratio"] = _finite(out["rmse"] / limit)
        out["bound_ratio_se"] = _finite(out["rmse_se"] / limit)
    return {**out, **verdicts(out)}


class _Cell:
    """A cell being folded: its study, the chunks still to come and its failures."""

    def __init__(self, index: int, setting: dict, run: monte_carlo.Study):
        self.index, self.setting, self.run = index, setting, run
        self.left = len(run.sizes)
        self.failed: dict = {}

    def fold(self, result) -> None:
        part, estimates, _, failed = result
        self.failed.update(failed)
        if estimates is not None:
            estimates = {n: e for n, e in estimates.items() if n not in self.failed}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            self.run.fold(len(self.run.sizes) - self.left, (part, estimates))
        self.left -= 1

    def summary(self) -> dict:
        run = self.run
        b = bound_sd(self.setting)
        out = {**self.setting, "truth": [float(v) for v in run.truth], "bound_sd": b}
        out.update(valid_trials=run.n_valid, rejected_trials=run.n_rejected, filters={})
        if run.n_valid == 0:
            return out
        for name in [*run.names, *([UNDER_LAW] if UNDER_LAW in run.tallies else [])]:
            if name in self.failed:
                out["filters"][name] = {"failed": self.failed[name], **dict.fromkeys(VERDICTS)}
                continue
            tally = run.tallies[name]
            if tally.n == 0:
                reason = "no answer for any trial"
                out["filters"][name] = {"failed": reason, **dict.fromkeys(VERDICTS)}
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                scores = tally.scores()
            out["filters"][name] = filter_summary({**scores, "trials": tally.n}, b)
        return out


def atlas(
    size="book",
    seed=0,
    client=None,
    progress: Callable[[int, int], None] | None = None,
    on_cell: Callable[[dict], None] | None = None,
) -> dict:
    """Every cell of a grid, each filter's scores and verdicts; returns a JSON-ready dict.

    Parameters
    ----------
    size : str or Grid
        A key of :data:`SIZES` (``"book"`` or ``"full"``), or a :class:`Grid`.
    seed : int or numpy.random.SeedSequence
        Cell ``i`` is seeded by its child ``i`` (:func:`cell_seed`).
    client : distributed.Client, optional
        Run the chunks on its cluster (:func:`depthcore.studies.tasks.fold_chunks`).
    progress : callable, optional
        ``progress(done, total)`` in trials, over every cell.
    on_cell : callable, optional
        ``on_cell(summary)`` as each cell is summarised, in cell order (its
        filters without ``"calibrated"``, read once every cell is in).

    Returns
    -------
    dict
        ``"axes"`` (each axis's values), ``"shape"``, ``"seed"``, ``"trials"``,
        ``"particles"``, ``"chunk"``, ``"names"``, ``"levels"`` (the verdicts'
        thresholds), ``"cells"`` (each cell's summary, in :func:`cells`
        order: its setting, truth, ``bound_sd``, valid and rejected trials,
        and per filter the summary of :func:`filter_summary` with its
        ``"calibrated"``) and ``"cost"`` (the measured time, :func:`cost_of`;
        it alone differs from run to run); the calibration's level, tolerance
        and false-discovery rate in ``"levels"``
        (:func:`~depthcore.studies.coverage_verdicts.with_calibration`).
    """
    grid = grid_of(size)
    root = checks.seed_sequence(seed)
    settings = cells(grid)
    for s in settings:  # every refusal before the first chunk runs
        truth_of(s["parallax"], s["depth"])
    open_cells: deque = deque()
    summaries = []
    clock: dict = {}

    def items():
        for i, setting in enumerate(settings):
            cell = _Cell(i, setting, cell_study(grid, setting, cell_seed(root, i)))
            open_cells.append(cell)
            yield from cell.run.items()

    def fold(k, result):
        cell = open_cells[0]
        cell.fold(result)
        part, _, seconds, _ = result
        for name, s in seconds.items():
            key = (name, cell.setting["frames"])
            total = clock.setdefault(key, [0.0, 0])
            total[0] += s
            total[1] += len(part.mu)
        if cell.left == 0:
            summary = open_cells.popleft().summary()
            summaries.append(summary)
            if on_cell is not None:
                on_cell(summary)

    sizes = (s for setting in settings for s in _chunk_sizes(grid, grid.trials_of(setting)))
    total = sum(grid.trials_of(s) for s in settings)
    start = time.perf_counter()
    tasks.fold_chunks(chunk_task, items(), fold, sizes, total, progress, client)
    wall = time.perf_counter() - start
    out = {
        "axes": {a: list(grid.axis(a)) for a in AXES},
        "shape": list(grid.shape),
        "seed": root.entropy,
        "trials": grid.trials,
        "fixed_trials": grid.trials if grid.fixed_trials is None else grid.fixed_trials,
        "particles": grid.n_particles,
        "chunk": grid.chunk,
        "names": list(grid.names),
        "under_law": UNDER_LAW,
        "max_frames": dict(grid.max_frames),
        "levels": {
            "loss_level": LOSS_LEVEL,
            "bound_tolerance": BOUND_TOLERANCE,
            "z": TEST_Z,
        },
        "cells": summaries,
        "cost": cost_of(clock, grid, wall),
    }
    return coverage_verdicts.with_calibration(out)


def _chunk_sizes(grid: Grid, trials: int) -> list[int]:
    return [min(grid.chunk, trials - s) for s in range(0, trials, grid.chunk)]


def cost_of(clock: dict, grid: Grid, wall: float) -> dict:
    """The measured cost: seconds per trial of each filter at each number of frames.

    Parameters
    ----------
    clock : dict
        ``{(name, frames): [seconds, trials]}`` summed over the chunks.
    grid : Grid
    wall : float
        The atlas's wall-clock seconds.

    Returns
    -------
    dict
        ``"seconds_per_trial"``: ``{name: {str(frames): seconds}}``, the
        random filters' at ``"particles"`` particles; ``"filter_seconds"``,
        the sum over every chunk; ``"wall_seconds"``.
    """
    per = {}
    for (name, frames), (seconds, trials) in sorted(clock.items()):
        if trials:
            per.setdefault(name, {})[str(frames)] = seconds / trials
    return {
        "seconds_per_trial": per,
        "particles": grid.n_particles,
        "filter_seconds": float(sum(s for s, _ in clock.values())),
        "wall_seconds": float(wall),
    }


def estimated_cost(cost: dict, size="full") -> dict:
    """The filters' time of a grid, from a measured cost per trial (:func:`cost_of`).

    Each cell costs its trials times the sum, over the filters it runs, of
    their seconds per trial at its frames; a filter that draws particles
    costs in proportion to them (from the measurement's ``"particles"``).
    Frames not measured are interpolated linearly in the number of frames.

    Returns
    -------
    dict
        ``"core_hours"``, ``"cells"``, ``"seconds_per_cell"`` (their mean).
    """
    grid = grid_of(size)
    per = cost["seconds_per_trial"]
    total = 0.0
    settings = cells(grid)
    for s in settings:
        for name in names_at(grid, s["frames"]):
            if name not in per:
                raise ValueError(f"cost: no measured cost of the filter {name}")
            measured = sorted((int(f), t) for f, t in per[name].items())
            f, t = zip(*measured, strict=True)
            seconds = float(np.interp(s["frames"], f, t))
            if FILTERS[name].random:
                seconds *= grid.n_particles / cost["particles"]
            total += grid.trials_of(s) * seconds
    return {
        "core_hours": total / 3600.0,
        "cells": len(settings),
        "seconds_per_cell": total / len(settings),
    }


#: The setting at which :func:`probe_cost` times filters, Figure 2's point at one pixel of noise.
PROBE = {"form": "paper", "rho": PIXEL, "prior_scale": 1000.0, "depth": 6.0, "parallax": 0.2}


def probe_cost(names, frames=(3, 10, 30), trials: int = 50, n_particles: int = 200, seed=0):
    """Seconds per trial of filters at :data:`PROBE`, at each number of frames.

    The cost of filters an atlas does not run (the book's leaves out
    :data:`COSTLY`), measured as :func:`atlas` measures its own: each
    filter's time in :func:`chunk_task`, over ``trials`` trials per number of
    frames.

    Returns
    -------
    dict
        As :func:`cost_of`: ``"seconds_per_trial"`` ``{name: {str(frames):
        seconds}}``, ``"particles"``, ``"filter_seconds"``, ``"wall_seconds"``.
    """
    names = tuple(names)
    frames = tuple(checks.frames(f) for f in frames)
    grid = Grid(
        (PROBE["parallax"],),
        (PROBE["depth"],),
        (PROBE["prior_scale"],),
        (PROBE["rho"],),
        frames,
        ("paper",),
        checks.count(trials, "trials"),
        checks.count(n_particles, "n_particles"),
        trials,
        names,
    )
    clock: dict = {}
    start = time.perf_counter()
    for i, f in enumerate(frames):
        run = cell_study(grid, {**PROBE, "frames": f}, cell_seed(seed, i))

        def fold(k, result, f=f):
            part, _, seconds, _ = result
            for name, s in seconds.items():
                total = clock.setdefault((name, f), [0.0, 0])
                total[0] += s
                total[1] += len(part.mu)

        tasks.fold_chunks(chunk_task, run.items(), fold)
    return cost_of(clock, grid, time.perf_counter() - start)


def merged_cost(*costs) -> dict:
    """Costs of :func:`cost_of` or :func:`probe_cost` at the same particles, as one.

    A filter's seconds per trial at a number of frames are the first cost's
    that has them.
    """
    if len({c["particles"] for c in costs}) != 1:
        raise ValueError("costs: measured at different numbers of particles")
    per: dict = {}
    for c in costs:
        for name, by_frames in c["seconds_per_trial"].items():
            mine = per.setdefault(name, {})
            for frames, seconds in by_frames.items():
                mine.setdefault(frames, seconds)
    return {
        "seconds_per_trial": per,
        "particles": costs[0]["particles"],
        "filter_seconds": float(sum(c["filter_seconds"] for c in costs)),
        "wall_seconds": float(sum(c["wall_seconds"] for c in costs)),
    }
