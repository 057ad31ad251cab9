"""The chapter on more frames: the study and the depth marginals as the frames accumulate.

Recommended import: ``from depthbook import beyond_frames``.

* :func:`frames_study_figure` draws the study at the last frame ``N``
  (:func:`depthbook.studies.frames.frames_study`) and :func:`frames_study_texts`
  gives its texts, the coverages tested by
  :func:`depthcore.studies.scores.coverage_test`;
* :func:`frame_marginals` and :func:`frame_marginals_figure`: every filter's
  depth marginal at several frames of one track; :func:`track_marginals`
  draws the track and runs them from one seed;
* :func:`nees_frames_figure` and :func:`track_loss_figure`: the ANEES with its
  chi-square region and the track loss at several thresholds, at every frame
  (:func:`depthbook.studies.per_frame.per_frame_study`).
"""

from __future__ import annotations

import numpy as np

from depthbook.style import MIN_FONT, STYLE, WIDTH, legend_below, subplots
from depthcore.problem import checks, model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, paper_prior_means
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry import filters as _filters
from depthcore.registry.filters import FILTERS, check_names
from depthcore.studies import tasks
from depthcore.studies.scores import COVERAGE_Z, coverage_test

# --- more frames ----------------------------------------------------------------------------


def track_marginals(
    seed,
    frames: int,
    panel_frames,
    names,
    scenario: str = "fig2",
    n_points: int = 601,
    client=None,
) -> dict:
    """One track of a scenario's point and each filter's depth marginals along it.

    The track (:func:`depthcore.problem.model.simulate`, no process noise) and the
    random filters (:func:`frame_marginals`) draw from one generator, in that
    order, so that a seed gives the same track and the same panels.

    Parameters
    ----------
    seed : int or numpy.random.SeedSequence
    frames : int
        Frames of the track, >= 3.
    panel_frames : sequence of int, shape (F,)
        Numbers of frames of the panels, each from 3 to ``frames``.
    names : sequence of str
        Filters, as :func:`frame_marginals` takes them.
    scenario : str
        The key of :data:`depthcore.problem.scenarios.SCENARIOS` whose noise-free
        state at time 3 and noise level are taken.
    n_points : int
        Grid points of each density.
    client : distributed.Client, optional
        Run the filters on its cluster (:func:`frame_marginals`); the same result, bit for bit.

    Returns
    -------
    dict
        ``"mu"``, the track's bearings, shape (frames,), and ``"panels"``,
        what :func:`frame_marginals` returns for them.

    Raises
    ------
    ValueError
        For an unknown ``scenario``, and as :func:`depthcore.problem.model.simulate`
        and :func:`frame_marginals` refuse their arguments.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {', '.join(SCENARIOS)}, got {scenario!r}")
    frames = checks.frames(frames)
    s = SCENARIOS[scenario]
    rng = np.random.default_rng(seed)
    track = model.simulate(s.c, frames, s.rho, 0.0, rng)
    panels = frame_marginals(
        track.mu, s.rho, panel_frames, names, rng=rng, n_points=n_points, client=client
    )
    return {"mu": track.mu, "panels": panels}


def frame_marginals(
    mu,
    rho: float,
    frames,
    names=("optimal", "second_order", "ekf"),
    rng=None,
    n_particles: int | None = None,
    n_points: int = 601,
    width: float = 6.0,
    prior_scale: float = PAPER_PRIOR_SCALE,
    client=None,
) -> list[dict]:
    """Each filter's depth marginal after the first ``N`` of one sequence of bearings.

    The prior is the paper's rule applied to the first three bearings (mean
    ``(c1 - 2 c3, c2 - 2, 0)``, covariance ``prior_scale * I``), the same at
    every ``N``; there is no process noise.

    Parameters
    ----------
    mu : array_like, shape (M,)
        Bearings of frames 1 .. M.
    rho : float
    frames : sequence of int, shape (F,)
        Numbers of frames, each from 3 to ``M``.
    names : sequence of str
        Filters; ``"optimal"`` is always run.
    rng : numpy.random.Generator or SeedSequence, optional
        Required when a random filter is named.
    n_particles : int, optional
        Particles of the random filters; default each filter's own.
    n_points : int
        Points of the depth grid.
    width : float
        Each filter's grid joins ``n_points`` points over its depth mean ±
        ``width`` of its SDs and ``n_points`` over the optimal filter's mean ±
        ``width`` optimal SDs (cut at 0), so that both densities are resolved.
    client : distributed.Client, optional
        Run the filters as tasks of its cluster (:mod:`depthcore.studies.tasks`):
        each deterministic filter at each ``N`` one task, the random filters,
        which draw from ``rng`` in turn, one task; default in this process.
        The result is the same, bit for bit.

    Returns
    -------
    list of dict, one per ``N``
        ``"frames"``; ``"grid"`` ``{name: (G,)}``, each filter's grid, and on it
        ``"density"`` ``{name: (G,)}``, the filter's depth density, and
        ``"exact"`` ``{name: (G,)}``, the optimal filter's;
        ``"depth_mean"`` and ``"depth_sd"`` ``{name: float}``.
    """
    mu = checks.finite_array(mu, "mu")
    if mu.ndim != 1 or len(mu) < 3:
        raise ValueError(f"mu must have shape (M,) with M >= 3, got shape {mu.shape}")
    frames = [checks.count(n, "frames") for n in checks.nonempty(np.atleast_1d(frames), "frames")]
    if any(not 3 <= n <= len(mu) for n in frames):
        raise ValueError(f"frames must each be from 3 to {len(mu)}, got {frames}")
    names = ("optimal",) + tuple(n for n in check_names(names) if n != "optimal")
    n_points = checks.count(n_points, "n_points")
    width = checks.positive_scalar(width, "width")
    pm = paper_prior_means(model.noise_free_states(mu[None, :3]))[0]
    pc = checks.positive_scalar(prior_scale, "prior_scale") * np.eye(3)
    random = [name for name in names if FILTERS[name].random]
    if random and rng is None:
        raise ValueError(f"rng is required to run the {random[0]} filter")
    at = list(enumerate(frames))
    # the random filters draw from rng in turn, frame after frame: one task runs them all
    items = [(tuple(random), at, mu, rho, pm, pc, rng, n_particles)][: len(random) > 0]
    items += [
        ((name,), [j_n], mu, rho, pm, pc, None, None)
        for j_n in at
        for name in names
        if name not in random
    ]
    found = [{} for _ in frames]

    def fold(k, result):
        for j, estimates in result.items():
            found[j].update(estimates)

    tasks.fold_chunks(_marginals_task, items, fold, client=client)
    out = []
    for (_, n), by_name in zip(at, found, strict=True):
        estimates = {name: by_name[name] for name in names}
        ref = estimates["optimal"]
        grids = {k: _joint_grid((ref, e), width, n_points) for k, e in estimates.items()}
        out.append(
            {
                "frames": n,
                "grid": grids,
                "density": {
                    k: FILTERS[k].density(e, "depth", grids[k]) for k, e in estimates.items()
                },
                "exact": {k: FILTERS["optimal"].density(ref, "depth", grids[k]) for k in estimates},
                "depth_mean": {k: float(e.depth_mean) for k, e in estimates.items()},
                "depth_sd": {k: float(e.depth_sd) for k, e in estimates.items()},
            }
        )
    return out


def _marginals_task(item) -> dict:
    """Filters ``names`` on the first ``N`` bearings: a task of :func:`frame_marginals`.

    ``item`` is ``(names, frames, mu, rho, pm, pc, rng, n_particles)``, ``frames``
    a list of ``(j, N)``; returns ``{j: {name: estimates}}``, the random filters
    drawing from ``rng`` frame after frame, in the order of ``names``.
    """
    names, frames, mu, rho, pm, pc, rng, n_particles = item
    out = {}
    for j, n in frames:
        out[j] = {}
        for name in names:
            f = FILTERS[name]
            options = {}
            if f.random:
                options["rng"] = rng
                if n_particles is not None:
                    options["n_particles"] = n_particles
            out[j][name] = f(mu[:n], rho, pm, pc, **options)
    return out


def _joint_grid(estimates, width: float, n_points: int) -> np.ndarray:
    """Depths over each estimate's mean ± ``width`` SDs, ``n_points`` each, joined, > 0."""
    parts = []
    for e in estimates:
        m, s = float(e.depth_mean), float(e.depth_sd)
        parts.append(np.linspace(max(m - width * s, 1e-9), m + width * s, n_points))
    return np.unique(np.concatenate(parts))


def frame_marginals_figure(result: list, names=None):
    """Each filter's depth marginal beside the optimal one, one column per number of frames.

    Parameters
    ----------
    result : list of dict
        From :func:`frame_marginals`.
    names : sequence of str, optional
        Filters, one row each; default every filter in ``result`` but the optimal.

    Returns
    -------
    matplotlib.figure.Figure
        One row per filter (its label, wrapped, at the left), one column per
        number of frames (its label at the top). Each panel has its own depth
        and density axes, spanning both densities' means ± :data:`PANEL_SDS`
        of their SDs, so that the filter's density and the optimal one are
        both seen whole however far apart or different in width they are; the
        density axis is logarithmic where their peaks differ by more than a
        factor :data:`LOG_PEAKS`.
    """
    import textwrap

    from matplotlib.ticker import LogLocator, MaxNLocator, NullLocator

    if names is None:
        names = [n for n in result[0]["density"] if n != "optimal"]
    fig, axes = subplots(
        len(names),
        len(result),
        figsize=(WIDTH, 0.82 * len(names) + 0.9),
        squeeze=False,
    )
    exact = {**STYLE["optimal"], "color": "black", "linestyle": "-", "linewidth": 1.0}
    for j, r in enumerate(result):
        for i, name in enumerate(names):
            ax = axes[i, j]
            grid = r["grid"][name]
            ax.fill_between(grid, r["exact"][name], color="0.85", linewidth=0)
            ax.plot(grid, r["exact"][name], **exact)
            ax.plot(grid, r["density"][name], **{**STYLE[name], "linewidth": 1.4})
            ends = [
                (
                    r["depth_mean"][k] - PANEL_SDS * r["depth_sd"][k],
                    r["depth_mean"][k] + PANEL_SDS * r["depth_sd"][k],
                )
                for k in ("optimal", name)
            ]
            ax.set_xlim(
                max(min(e[0] for e in ends), grid[0]), min(max(e[1] for e in ends), grid[-1])
            )
            peaks = sorted((float(np.max(r["exact"][name])), float(np.max(r["density"][name]))))
            if peaks[1] > LOG_PEAKS * peaks[0]:
                ax.set_yscale("log")
                ax.set_ylim(peaks[0] / 30, 3 * peaks[1])
                ax.yaxis.set_major_locator(LogLocator(numticks=3))
                ax.yaxis.set_minor_locator(NullLocator())
            else:
                ax.set_ylim(0, None)
                ax.yaxis.set_major_locator(MaxNLocator(2))
            ax.xaxis.set_major_locator(MaxNLocator(3))
            ax.tick_params(labelsize=MIN_FONT, length=2, pad=1)
            if i == 0:
                ax.set_title(f"$N = {r['frames']}$")
            if j == 0:
                label = textwrap.fill(_filters.FILTERS[name].label, 14)
                ax.set_ylabel(label, fontsize=MIN_FONT, rotation=0, ha="right", va="center")
        axes[-1, j].set_xlabel(f"depth $y$ at frame {r['frames']}", fontsize=MIN_FONT)
    return fig


#: The half-width of each panel of :func:`frame_marginals_figure`, in SDs of either density.
PANEL_SDS = 4.0

#: A panel of :func:`frame_marginals_figure` whose two densities' peaks differ by more than
#: this factor draws the density on a logarithmic axis, where the lower one is seen.
LOG_PEAKS = 20.0


#: The panels of :func:`frames_study_figure`, each (score, label, logarithmic axis, nominal level).
FRAMES_ROWS = (
    ("rmse", "RMSE of the depth mean", True, None),
    ("mean_sd", "mean depth SD", True, None),
    ("hellinger", "Hellinger distance\nto the exact filter", False, None),
    ("nees", "mean NEES", True, 3.0),
    ("coverage_68", "coverage of the\ncentral 68 % interval", False, 0.68),
    ("coverage_95", "coverage of the\ncentral 95 % interval", False, 0.95),
)


#: The factor between neighbouring filters' positions along ``N`` in :func:`frames_study_figure`.
SPREAD = 1.02


def _coverage_bands(ax, frames, level: float, trials) -> None:
    """Shade where a coverage over each number of ``trials`` passes the coverage test."""

    for n in sorted(set(int(t) for t in trials)):
        half = COVERAGE_Z * float(coverage_test(level, level, n)["se"])
        ax.axhspan(level - half, level + half, color="0.5", alpha=0.15, linewidth=0)


def frames_study_figure(result: dict, names=None):
    """The scores of :func:`~depthbook.studies.frames.frames_study` against ``N``, one panel each.

    Parameters
    ----------
    result : dict
        One ``frames_study`` result.
    names : sequence of str, optional
        Filters to draw; default every filter of ``result``.

    Returns
    -------
    matplotlib.figure.Figure
        Six panels, :data:`FRAMES_ROWS`, three to a row, each score with bars of
        two Monte Carlo standard errors either side (its ``"<score>_se"``), the
        filters' points spread a little along ``N`` so that their bars do not
        overlap. The coverage panels shade
        where a coverage passes :func:`~depthcore.studies.scores.coverage_test`
        (within :data:`~depthcore.studies.scores.COVERAGE_Z` binomial standard errors
        of the nominal level) over each filter's number of trials, one band per
        number of trials: they overlap, darkest in the narrowest, of the most
        trials.
    """
    if names is None:
        names = [k for k, v in result.items() if isinstance(v, dict)]
    names = [n for n in names if n in result]
    fig, axes = subplots(2, 3, figsize=(WIDTH, 5.2), sharex=True)
    frames = np.asarray(result["frames"])
    spread = SPREAD ** (np.arange(len(names)) - (len(names) - 1) / 2)
    for ax, (score, label, log, nominal) in zip(axes.ravel(), FRAMES_ROWS, strict=True):
        for name, factor in zip(names, spread, strict=True):
            if not (score == "hellinger" and name == "optimal"):
                ax.errorbar(
                    frames * factor,
                    result[name][score],
                    yerr=2 * np.asarray(result[name][f"{score}_se"]),
                    marker="o",
                    markersize=3,
                    capsize=1.5,
                    elinewidth=0.8,
                    **STYLE[name],
                )
        if score.startswith("coverage"):
            _coverage_bands(ax, frames, nominal, [result[n]["trials"][0] for n in names])
            ax.set_ylim(-0.02, 1.02)
        if nominal is not None:
            ax.axhline(nominal, color="0.45", linewidth=1)
        if log:
            ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.set_xscale("log")
        ax.set_xticks(frames, [str(int(n)) for n in frames])
        ax.set_xticks([], minor=True)
    for ax in axes[-1]:
        ax.set_xlabel("frames $N$")
    legend_below(fig, axes.ravel(), ncol=3)
    return fig


# --- more frames ----------------------------------------------------------------------------


def frames_study_texts(result: dict, prefix: str) -> dict:
    """Counts of :func:`~depthbook.studies.frames.frames_study`'s failed coverage tests, for glue.

    Each filter's coverages of the central 68 % and 95 % intervals at every
    ``N`` are tested by :func:`~depthcore.studies.scores.coverage_test`
    (two-sided, 1 %) against their nominal levels over the filter's trials.

    Returns
    -------
    dict
        ``"<prefix>_tests"`` (tests per filter: two levels at every ``N``) and
        per filter ``"<prefix>_<filter>_fails"`` (the tests it fails, as
        overconfident or as underconfident).
    """

    out = {f"{prefix}_tests": str(2 * len(result["frames"]))}
    for name, r in result.items():
        if not isinstance(r, dict):
            continue
        verdicts = np.concatenate(
            [
                np.atleast_1d(coverage_test(r[f"coverage_{lv}"], lv / 100, r["trials"])["verdict"])
                for lv in (68, 95)
            ]
        )
        out[f"{prefix}_{name}_fails"] = str(int(np.sum(verdicts != "calibrated")))
    return out


# --- frame by frame --------------------------------------------------------------------------


def _band(ax, k, y, se, name, log: bool = True) -> None:
    """One filter's line with two standard errors shaded either side (short of zero if ``log``)."""
    style = STYLE[name]
    ax.plot(
        k,
        y,
        color=style["color"],
        linestyle=style["linestyle"],
        label=style["label"],
        linewidth=1.2,
    )
    lo = np.maximum(y - 2 * se, 0.1 * y) if log else y - 2 * se
    ax.fill_between(k, lo, y + 2 * se, color=style["color"], alpha=0.25, linewidth=0)


def nees_frames_figure(columns, names=None, zoom=None):
    """Every filter's ANEES at every frame, with its chi-square acceptance region.

    Parameters
    ----------
    columns : sequence of (str, dict)
        One column of panels each: its short label and a result of
        :func:`depthbook.studies.per_frame.per_frame_study`.
    names : sequence of str, optional
        Filters to draw; default every filter of the first result.
    zoom : (float, float), optional
        The range of a second row of panels, on a linear axis, that shows the
        filters near the region; default no second row.

    Returns
    -------
    matplotlib.figure.Figure
        One column per entry of ``columns``, on a logarithmic axis against
        the frame ``k`` (and, with ``zoom``, a linear one below it): each
        filter's ANEES (the mean NEES over its trials), shaded two standard
        errors either side, over the grey band of its 95 % acceptance region
        (``"anees_region"``; one band per number of trials) and a grey line
        at 3, the state's dimension.
    """
    if names is None:
        names = list(columns[0][1]["filters"])
    rows = 1 if zoom is None else 2
    fig, axes = subplots(
        rows,
        len(columns),
        figsize=(WIDTH, 3.0 * rows + 0.8),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    for j, (title, result) in enumerate(columns):
        k = np.asarray(result["frames"], dtype=float)
        for i in range(rows):
            ax = axes[i, j]
            regions = set()
            for name in names:
                if name not in result["filters"]:
                    continue
                r = result["filters"][name]
                regions.add(tuple(r["anees_region"]))
                _band(ax, k, np.asarray(r["nees"]), np.asarray(r["nees_se"]), name, log=i == 0)
            for lo, hi in regions:
                ax.axhspan(lo, hi, color="0.5", alpha=0.3, linewidth=0)
            ax.axhline(3.0, color="0.45", linewidth=1, zorder=0)
            ax.set_xlim(k[0], k[-1])
        axes[0, j].set_yscale("log")
        axes[0, j].set_title(title)
        axes[-1, j].set_xlabel("frame $k$")
        if zoom is not None:
            axes[1, j].set_ylim(*zoom)
    axes[0, 0].set_ylabel("ANEES")
    if zoom is not None:
        axes[1, 0].set_ylabel("ANEES\n(near the region)")
    legend_below(fig, axes.ravel(), ncol=3)
    return fig


def track_loss_figure(result: dict, names=None):
    """Track loss at every frame at each threshold, and the depth RMSE over the tracks kept.

    Parameters
    ----------
    result : dict
        A result of :func:`depthbook.studies.per_frame.per_frame_study`.
    names : sequence of str, optional
        Filters to draw; default every filter of ``result``.

    Returns
    -------
    matplotlib.figure.Figure
        One column per threshold of ``result["levels"]``: above, the
        fraction of tracks lost at frame ``k``; below, the depth RMSE over
        the tracks not lost (logarithmic, with the bound's depth SD in
        grey); each filter shaded two standard errors either side.
    """
    if names is None:
        names = list(result["filters"])
    levels = result["levels"]
    fig, axes = subplots(
        2,
        len(levels),
        figsize=(WIDTH, 5.0),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    k = np.asarray(result["frames"], dtype=float)
    for i, t in enumerate(levels):
        for name in names:
            if name not in result["filters"]:
                continue
            loss = result["filters"][name]["track_loss"]
            _band(
                axes[0, i],
                k,
                np.asarray(loss["fraction"][i]),
                np.asarray(loss["se"][i]),
                name,
                log=False,
            )
            kept = loss["depth"]
            _band(
                axes[1, i],
                k,
                np.asarray(kept["rmse_kept"][i]),
                np.asarray(kept["rmse_kept_se"][i]),
                name,
            )
        axes[1, i].plot(
            k,
            result["bound"]["depth"],
            color="0.5",
            linewidth=2.5,
            zorder=0,
            alpha=0.6,
            label="bound (depth SD)",
        )
        axes[1, i].set_yscale("log")
        axes[0, i].set_ylim(-0.02, 1.02)
        axes[0, i].set_title(f"lost at {t:g}\nof the distance", fontsize=MIN_FONT)
    axes[0, 0].set_ylabel("fraction of tracks lost", fontsize=MIN_FONT)
    axes[1, 0].set_ylabel("depth RMSE, tracks kept", fontsize=MIN_FONT)
    for ax in axes[-1]:
        ax.set_xlabel("frame $k$")
        ax.set_xlim(k[0], k[-1])
    legend_below(fig, axes.ravel(), ncol=3)
    return fig
