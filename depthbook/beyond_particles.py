"""The chapter on the Monte Carlo methods: importance sampling's convergence, resample-move.

Recommended import: ``from depthbook import beyond_particles``.

* :func:`particle_convergence` and :func:`convergence_figure`: the importance
  sampler's error against the number of particles, for the settings
  :data:`SETTINGS`;
* :func:`resample_move_runs`: the causal particle filter with resample-move
  (:mod:`depthcore.particles.resample_move`) run independently several times on a
  scenario, against the optimal filter.
"""

from __future__ import annotations

import numpy as np

from depthbook.errors import rms_se
from depthbook.style import MIN_FONT, WIDTH, legend_below, log_bars, reference_rate, subplots
from depthcore.exact import optimal
from depthcore.particles import importance, resample_move
from depthcore.problem import checks
from depthcore.problem.scenarios import Scenario
from depthcore.registry.estimates import MOMENTS, QUANTITIES
from depthcore.studies import tasks

#: Settings of the particle filter compared by :func:`particle_convergence`:
#: keyword arguments of :func:`depthcore.particles.importance.run`.
SETTINGS = {
    "default": {},
    "resampling": {"ess_threshold": 0.5},
    "bootstrap": {"proposal": "prior"},
}


#: Particles per call of :func:`depthcore.particles.importance.run` (bounds the memory, about 200
#: bytes each).
CHUNK_PARTICLES = 200_000


# --- convergence of the particle filter ------------------------------------------------------


def _run_repeats(scenario: Scenario, n: int, repeats: int, rng, kwargs: dict):
    """Moments (repeats,) per field and the ESS after each measurement (repeats, 3)."""
    s, prior = scenario, scenario.prior
    per_call = max(1, CHUNK_PARTICLES // n)
    moments, ess = [], []
    for start in range(0, repeats, per_call):
        b = min(per_call, repeats - start)
        batch = importance.run(
            np.tile(s.mu, (b, 1)), s.rho, prior.mean, prior.cov, n, rng, **kwargs
        )
        moments.append(np.stack(batch.moments(), axis=-1))
        ess.append(batch.ess)
    return np.concatenate(moments), np.concatenate(ess)


def _convergence_task(item) -> tuple:
    """One setting of :func:`particle_convergence`, every ``N`` in turn from its own stream.

    ``item`` is ``(scenario, sizes, repeats, kwargs, stream, exact)``; returns the
    RMSE of each moment (S, 4), its standard error (S, 4;
    :func:`~depthbook.errors.rms_se`) and the mean ESS fraction after each
    measurement (S, 3).
    """
    scenario, sizes, repeats, kwargs, stream, exact = item
    rng = np.random.default_rng(stream)
    err, err_se, frac = [], [], []
    for n in sizes:
        m, e = _run_repeats(scenario, int(n), repeats, rng, kwargs)
        rms, se = rms_se(m - exact, axis=0)
        err.append(rms)
        err_se.append(se)
        frac.append(np.mean(e, axis=0) / n)
    return np.array(err), np.array(err_se), np.array(frac)


def particle_convergence(
    scenario: Scenario, sizes, repeats: int, seed, settings: dict | None = None, client=None
) -> dict:
    """Root-mean-square errors of the particle filter's moments against ``N``.

    Each setting runs ``repeats`` independent filters on the scenario's
    measurements for each number of particles; the errors are measured from
    the optimal filter's exact moments (:func:`depthcore.exact.optimal.run`).

    Parameters
    ----------
    scenario : Scenario
    sizes : array_like of int, shape (S,)
        Numbers of particles ``N``.
    repeats : int
        Independent runs per ``N``, >= 1.
    seed : int or numpy.random.SeedSequence
        Each setting draws from its own child stream of this seed.
    settings : dict, optional
        ``{name: keyword arguments of particle.run}``; default :data:`SETTINGS`.
    client : distributed.Client, optional
        Run each setting as a task of its cluster (:mod:`depthcore.studies.tasks`);
        default in this process. The result is the same, bit for bit.

    Returns
    -------
    dict
        ``"sizes"`` (S,), ``"repeats"``, ``"exact"``: ``{moment: float}`` for
        :data:`~depthcore.registry.estimates.MOMENTS`, ``"rmse"``: ``{setting: {moment: (S,)}}``,
        ``"rmse_se"`` its standard errors (:func:`~depthbook.errors.rms_se`), alike, and
        ``"ess"``: ``{setting: (S, 3)}``, the mean ESS after each measurement
        as a fraction of ``N``.
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    sizes = checks.sizes(sizes)
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise ValueError(f"repeats must be a positive integer, got {repeats!r}")
    settings = SETTINGS if settings is None else settings
    opt = optimal.run(scenario.mu, scenario.rho, scenario.prior.mean, scenario.prior.cov)
    exact = np.array([getattr(opt, m) for m in MOMENTS])
    streams = checks.spawn(seed, len(settings))
    items = [
        (scenario, sizes, int(repeats), kwargs, stream, exact)
        for kwargs, stream in zip(settings.values(), streams, strict=True)
    ]
    runs = []
    tasks.fold_chunks(_convergence_task, items, lambda k, r: runs.append(r), client=client)
    rmse, rmse_se, ess = {}, {}, {}
    for name, (err, err_se, frac) in zip(settings, runs, strict=True):
        rmse[name] = {m: err[:, i] for i, m in enumerate(MOMENTS)}
        rmse_se[name] = {m: err_se[:, i] for i, m in enumerate(MOMENTS)}
        ess[name] = frac
    return {
        "sizes": sizes,
        "repeats": int(repeats),
        "exact": {m: float(v) for m, v in zip(MOMENTS, exact, strict=True)},
        "rmse": rmse,
        "rmse_se": rmse_se,
        "ess": ess,
    }


# --- the causal particle filter (resample-move) ----------------------------------------------


def _resample_move_task(item) -> tuple:
    """One run of :func:`resample_move_runs`: ``(moments, ess, resampled)`` of the filter.

    ``item`` is ``(mu, rho, prior_mean, prior_cov, n_particles, stream, moves)``.
    """
    mu, rho, mean, cov, n_particles, stream, moves = item
    b = resample_move.run([mu], rho, mean, cov, n_particles, np.random.default_rng(stream), moves)
    return b.moments(), b.ess, b.resampled


def resample_move_runs(
    scenario: Scenario, n_particles: int, repeats: int, seed, moves: int = 20, client=None
) -> dict:
    """Independent runs of the resample-move particle filter on a scenario.

    The filter of :func:`depthcore.particles.resample_move.run` sees the bearings one at
    a time (bootstrap proposal from the prior, systematic resampling when the
    ESS falls below ``N/2``, then ``moves`` Metropolis steps per particle).
    The ``repeats`` runs draw from independent child streams of ``seed``;
    their spread gives the Monte Carlo standard error of the moments.

    Parameters
    ----------
    scenario : Scenario
    n_particles : int
        Particles per run, >= 2.
    repeats : int
        Independent runs, >= 2.
    seed : int or numpy.random.SeedSequence
    moves : int
        Metropolis steps per particle after each resampling.
    client : distributed.Client, optional
        Run each run as a task of its cluster (:mod:`depthcore.studies.tasks`);
        default in this process. The result is the same, bit for bit.

    Returns
    -------
    dict
        ``"runs"``: ``{moment: (repeats,)}`` for :data:`~depthcore.registry.estimates.MOMENTS`;
        ``"mean"`` and
        ``"se"``: ``{moment: float}``, the mean over the runs and its standard
        error (SD over the runs / sqrt(repeats)); ``"exact"``: ``{moment:
        float}`` of the optimal filter (:func:`depthcore.exact.optimal.run`,
        in front of the camera); ``"ess"`` (repeats, 3): the ESS after each
        bearing as a fraction of ``N``; ``"resampled"`` (repeats, 3).
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 2:
        raise ValueError(f"repeats must be an integer >= 2, got {repeats!r}")
    s, prior = scenario, scenario.prior
    items = (
        (s.mu, s.rho, prior.mean, prior.cov, n_particles, stream, moves)
        for stream in checks.spawn(seed, int(repeats))
    )
    batches = []
    tasks.fold_chunks(_resample_move_task, items, lambda k, b: batches.append(b), client=client)
    runs = {k: np.concatenate([b[0][k] for b in batches]) for k in MOMENTS}
    opt = optimal.run(s.mu, s.rho, prior.mean, prior.cov)
    return {
        "runs": runs,
        "mean": {k: float(np.mean(v)) for k, v in runs.items()},
        "se": {k: float(np.std(v, ddof=1) / np.sqrt(len(v))) for k, v in runs.items()},
        "exact": {k: float(getattr(opt, k)) for k in MOMENTS},
        "ess": np.concatenate([b[1] for b in batches]) / n_particles,
        "resampled": np.concatenate([b[2] for b in batches]),
    }


_SYMBOL = {"depth": "y", "velocity": "v"}


#: Legend labels and line styles of the importance sampler's settings,
#: :data:`depthbook.beyond_particles.SETTINGS`.
SETTING_STYLE = {
    "default": {
        "label": "importance sampling, t proposal from $p_s$ (default)",
        "color": "tab:purple",
        "linestyle": "-",
        "marker": "o",
    },
    "resampling": {
        "label": r"same, resampling (no move) when $\mathrm{ESS} < N/2$",
        "color": "tab:orange",
        "linestyle": "--",
        "marker": "s",
    },
    "bootstrap": {
        "label": "bootstrap: particles from the prior",
        "color": "0.45",
        "linestyle": ":",
        "marker": "^",
    },
}


def convergence_figure(result: dict, quantity: str = "depth"):
    """RMS errors of the mean and the SD of one marginal against ``N``, on log axes.

    The grey line is ``sd / sqrt(N)``, the standard error of the mean of
    ``N`` independent draws from the optimal posterior. Where the result
    holds ``"rmse_se"`` (``{setting: {moment: (S,)}}``, as :func:`~depthbook.errors.rms_se`
    gives it from the runs' errors), each point carries bars of two standard
    errors either side, cut at a tenth of the point on the log axis.

    Parameters
    ----------
    result : dict
        The errors of :func:`depthbook.beyond_particles.particle_convergence` at
        its ``"sizes"`` ``N``, of each setting of ``"rmse"``, over ``"repeats"`` runs,
        and optionally their standard errors ``"rmse_se"``.
    quantity : {"depth", "velocity"}

    Returns
    -------
    matplotlib.figure.Figure
        Two panels, the mean's errors and the SD's, one line per setting.
    """

    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    N = result["sizes"]
    ideal = result["exact"][f"{quantity}_sd"] / np.sqrt(N)
    fig, axes = subplots(1, 2, figsize=(WIDTH, 4.4), sharey=True)
    for ax, moment, label in zip(axes, ("mean", "sd"), ("(a) mean", "(b) SD"), strict=True):
        for name, err in result["rmse"].items():
            y = np.asarray(err[f"{quantity}_{moment}"], dtype=float)
            style = SETTING_STYLE.get(name, {"label": name})
            if "rmse_se" in result:
                se = np.asarray(result["rmse_se"][name][f"{quantity}_{moment}"], dtype=float)
                ax.errorbar(N, y, yerr=log_bars(y, se), markersize=4, capsize=2, **style)
            else:
                ax.plot(N, y, markersize=4, **style)
        reference_rate(ax, N, ideal, r"posterior SD$/\sqrt{N}$")
        ax.set_xlabel("number of particles $N$")
        ax.set_title(f"{label} of {quantity} ${_SYMBOL[quantity]}$", fontsize=MIN_FONT)
    axes[0].set_ylabel("RMS error from the optimal filter")
    legend_below(fig, axes[:1], ncol=2)
    return fig
