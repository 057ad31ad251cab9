"""The chapter on the bound: the filters' errors at frame ``N`` against the Cramér-Rao bound.

Recommended import: ``from depthbook import beyond_bound``.

:func:`bound_study` runs every named filter over the trials and returns the
errors and claimed SDs that the chapter holds against :mod:`depthcore.analysis.bound`;
:func:`noise_free_depth_rmse` integrates the error of the noise-free solution of Eq. (7),
:func:`value_se_digits` prints a Monte Carlo value to the digits its error allows;
:func:`bound_figure` draws them over the bound; :func:`frame_bound_figure` draws the
RMSE over the bound at every frame, from :func:`depthbook.studies.per_frame.per_frame_study`.
"""

from __future__ import annotations

import numpy as np

from depthbook.style import MIN_FONT, STYLE, WIDTH, legend_below, log_bars, subplots
from depthcore.problem import checks, model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS, check_names
from depthcore.studies import tasks
from depthcore.studies import trials as study_trials

# --- the Cramér-Rao bound --------------------------------------------------------------


def bound_study(
    frames,
    trials: int,
    seed,
    names=("optimal", "second_order", "ekf"),
    prior: str = "paper",
    process_noise: float = 0.0,
    truth=None,
    rho: float = SCENARIOS["fig2"].rho,
    particle_trials: int | None = None,
    n_particles: int = study_trials.PARTICLES,
    client=None,
) -> dict:
    """Every named filter's depth and velocity errors and claimed SDs at frame ``N``, by trial.

    The truth is ``truth`` at time 3 (default Figure 2's ``c``): frames 1 and 2
    are ``G^{-2}`` and ``G^{-1}`` of it (Eq. (1)), and from time 3 on the
    velocity changes by ``a_k ~ N(0, process_noise**2)`` at every step. Each
    trial draws one track of ``max(frames)`` frames and its bearings; every
    filter runs on its first ``N`` bearings for each ``N`` of ``frames`` and is
    scored against the track's state at frame ``N``. The prior is the paper's
    rule (``"paper"``: from each trial's first three bearings) or the same rule
    applied once to ``truth`` (``"fixed"``), covariance 1000 I; trials whose
    first three bearings have no noise-free solution in front of the camera
    are left out, as in :func:`depthcore.studies.trials.simulate`. The filters that
    draw random numbers run on the first ``particle_trials`` valid trials.
    Set the results against :func:`depthcore.analysis.bound.posterior_bound` with
    :func:`depthcore.analysis.bound.against_bound`.

    Parameters
    ----------
    frames : sequence of int, shape (F,)
        Numbers of frames ``N``, each from 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    trials : int
        Trials drawn, >= 2.
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters of :data:`depthcore.registry.filters.FILTERS`; each must support the
        frames and the process noise asked for.
    prior : {"paper", "fixed"}
    process_noise : float
        ``q >= 0``.
    truth : array_like, shape (3,), optional
    rho : float
    particle_trials : int, optional
        Default ``trials``.
    n_particles : int
    client : distributed.Client, optional
        Run the filters as tasks of its cluster (:mod:`depthcore.studies.tasks`):
        each deterministic filter at each ``N`` one task, the random filters,
        which draw from one stream in turn, one task; default in this process.
        The result is the same, bit for bit.

    Returns
    -------
    dict
        ``"frames"`` (F,), ``"truth"``, ``"rho"``, ``"process_noise"``,
        ``"prior"``, ``"prior_cov"`` (3, 3), ``"states"`` (T, F, 3) (the true
        state at each ``N``), and per filter ``{"depth_error", "depth_sd",
        "velocity_error", "velocity_sd"}``, each of shape (F, T_f), ``T_f``
        the trials it ran on.
    """
    frames = [checks.count(n, "frames") for n in checks.nonempty(np.atleast_1d(frames), "frames")]
    if any(not 3 <= n <= checks.MAX_FRAMES for n in frames):
        raise ValueError(f"frames must each be from 3 to {checks.MAX_FRAMES}, got {frames}")
    trials = checks.count(trials, "trials")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    names = check_names(names)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    unable = [n for n in names if q > 0 and not FILTERS[n].with_process_noise]
    unable += [n for n in names if max(frames) > 3 and not FILTERS[n].any_frames]
    if unable:
        raise ValueError(
            f"names: {', '.join(unable)} cannot run on {max(frames)} frames with process "
            f"noise {q:g}; leave them out"
        )
    truth = SCENARIOS["fig2"].c if truth is None else truth
    particle_trials = (
        trials if particle_trials is None else checks.count(particle_trials, "particle_trials")
    )
    noise_rng, particle_rng = (
        np.random.default_rng(s) for s in checks.spawn(checks.seed_sequence(seed), 2)
    )
    drawn = study_trials.simulate(
        truth, rho, trials, noise_rng, prior, PAPER_PRIOR_SCALE, max(frames), q, tracks=True
    )
    mu, pm, pc, states = drawn.mu, drawn.prior_mean, drawn.prior_cov, drawn.tracks
    truth, rho = drawn.truth, drawn.rho
    out = {
        "frames": np.array(frames),
        "truth": truth,
        "rho": rho,
        "process_noise": q,
        "prior": prior,
        "prior_cov": pc,
        "states": states[:, np.array(frames) - 1, :],
        "rejected_trials": drawn.n_rejected,
    }
    # the random filters draw from one stream, one after the other: one task runs them all
    # in order, on the first particle_trials trials; each other filter at each N is a task
    random = tuple(n for n in names if FILTERS[n].random)
    rows = slice(0, particle_trials)
    at = list(enumerate(frames))
    items = [(random, at, mu[rows], rho, pm[rows], pc, states[rows], q, particle_rng, n_particles)]
    items = items[: len(random) > 0] + [
        ((name,), [j_n], mu, rho, pm, pc, states, q, None, n_particles)
        for name in names
        if name not in random
        for j_n in at
    ]
    runs = {name: {} for name in names}

    def fold(k, result):
        for name, by_frame in result.items():
            runs[name].update(by_frame)

    tasks.fold_chunks(_bound_task, items, fold, client=client)
    for name in names:
        by_frame = [runs[name][j] for j in range(len(frames))]
        out[name] = {k: np.array([r[k] for r in by_frame]) for k in BOUND_ERRORS}
    return out


def value_se_digits(value: float, se: float) -> str:
    """``"value ± se"`` to the decimals of the SE's second significant digit: ``"1.446 ± 0.016"``.

    Parameters
    ----------
    value : float
    se : float
        > 0.

    Returns
    -------
    str
    """
    se = checks.positive_scalar(se, "se")
    decimals = max(0, 1 - int(np.floor(np.log10(se))))
    return f"{float(value) + 0.0:.{decimals}f} ± {se:.{decimals}f}"


#: Where :func:`noise_free_depth_rmse` cuts the denominator of Eq. (7): in its SDs from its mean.
NOISE_FREE_CUT = 6.0


def noise_free_depth_rmse(truth, rho: float, cut: float = NOISE_FREE_CUT) -> dict:
    """The RMS depth error of the noise-free solution ``c`` (Eq. (7)) at time 3, by quadrature.

    With bearings ``mu_k = b_k + w_k`` at times 1 to 3 (``b_k`` noise-free, ``w_k`` i.i.d.
    ``N(0, rho**2)``) and true depth ``y`` at time 3, ``c2 - y = E / D`` with
    ``D = mu1 + mu3 - 2 mu2`` (mean ``D0 = b1 + b3 - 2 b2``, variance ``6 rho**2``) and
    ``E = (2 - y) w1 + (2 y - 2) w2 - y w3``. Given ``D = d``, ``E`` is Gaussian with mean
    ``(1 - y) (d - D0)`` and variance ``2 rho**2`` (for every ``y``), so

        E[(c2 - y)**2 | D = d] = (2 rho**2 + (y - 1)**2 (d - D0)**2) / d**2,

    a one-dimensional integral over ``D``. Its density is positive at ``d = 0``, where
    ``c2`` has a pole, so the mean square error is infinite; what is computed is the mean
    square over ``|D - D0| <= cut * SD(D)``, the pole left out, which is what a Monte Carlo
    of far fewer than ``1 / excluded`` trials estimates. The error is the larger of the
    adaptive quadrature's estimate and its difference from a 400-point Gauss-Legendre rule.

    Parameters
    ----------
    truth : array_like, shape (3,)
        ``(x, y, v)`` at time 3, ``y > 2``, with ``b1 + b3 - 2 b2 != 0``.
    rho : float
        Bearing noise SD, > 0.
    cut : float
        > 0, below ``|D0| / SD(D)``, so that the pole is left out.

    Returns
    -------
    dict of float
        ``"rmse"``, its absolute ``"error"``, ``"excluded"`` (the probability of
        ``|D - D0| > cut * SD(D)``) and ``"delta"`` (the first-order value,
        ``sqrt(2 + 6 (y - 1)**2) rho / |D0|``).
    """
    from scipy import integrate, special

    truth = checks.finite_array(truth, "truth", (3,))
    rho = checks.positive_scalar(rho, "rho")
    cut = checks.positive_scalar(cut, "cut")
    y = float(truth[1])
    if not y > 2:
        raise ValueError(f"truth must have depth > 2, got {y:g}")
    b = [float(np.squeeze(model.project(model.G(truth, k - 3)))) for k in (1, 2, 3)]
    d0, sd = b[0] + b[2] - 2.0 * b[1], np.sqrt(6.0) * rho
    if not cut * sd < abs(d0):
        raise ValueError(
            f"cut must leave out the pole of Eq. (7): below |D0| / SD(D) = {abs(d0) / sd:.3g}, "
            f"got {cut:g}"
        )

    def mean_square(z):  # z = (d - D0) / SD(D), weighted by the normal density
        d = d0 + sd * z
        return np.exp(-0.5 * z**2) / np.sqrt(2 * np.pi) * (2 + 6 * (y - 1) ** 2 * z**2) / d**2

    inside = 1.0 - 2.0 * special.ndtr(-cut)
    value, err = integrate.quad(mean_square, -cut, cut, epsabs=0.0, epsrel=1e-13, limit=200)
    nodes, weights = np.polynomial.legendre.leggauss(400)
    check = cut * float(np.sum(weights * mean_square(cut * nodes)))
    ms = rho**2 * value / inside
    error = rho**2 * max(err, abs(value - check)) / inside
    return {
        "rmse": float(np.sqrt(ms)),
        "error": float(error / (2.0 * np.sqrt(ms))),
        "excluded": float(1.0 - inside),
        "delta": float(np.sqrt(2.0 + 6.0 * (y - 1) ** 2) * rho / abs(d0)),
    }


#: The errors and claimed SDs of each filter that :func:`bound_study` returns.
BOUND_ERRORS = ("depth_error", "depth_sd", "velocity_error", "velocity_sd")


def _bound_task(item) -> dict:
    """Filters ``names`` on the first ``N`` bearings for each ``N``: a task of :func:`bound_study`.

    ``item`` is ``(names, frames, mu, rho, pm, pc, states, q, rng, n_particles)``,
    ``frames`` a list of ``(j, N)``; returns ``{name: {j: {error: (T,)}}}``, each
    error of :data:`BOUND_ERRORS`. The random filters draw from ``rng`` in the
    order of ``names``, then of ``frames``.
    """
    names, frames, mu, rho, pm, pc, states, q, rng, n_particles = item
    noise = {"process_noise": q} if q > 0 else {}
    out = {}
    for name in names:
        f = FILTERS[name]
        options = dict(noise) if f.with_process_noise else {}
        if f.random:
            options.update(rng=rng, n_particles=n_particles)
        out[name] = {}
        for j, n in frames:
            est = f(mu[:, :n], rho, pm, pc, **options)
            true = states[:, n - 1]
            out[name][j] = {
                "depth_error": np.asarray(est.depth_mean) - true[:, 1],
                "depth_sd": np.asarray(est.depth_sd),
                "velocity_error": np.asarray(est.velocity_mean) - true[:, 2],
                "velocity_sd": np.asarray(est.velocity_sd),
            }
    return out


def bound_figure(frames, columns):
    """Every filter's depth RMSE and mean stated SD over the bound, against ``N``.

    Parameters
    ----------
    frames : array_like of int, shape (F,)
        The numbers of frames ``N``.
    columns : sequence of (str, dict)
        One column each: its short label and ``{name: against}``, each
        ``against`` the result of :func:`depthcore.analysis.bound.against_bound`
        over ``frames`` (arrays of shape (F,)).

    Returns
    -------
    matplotlib.figure.Figure
        Two rows (the RMSE over the bound; the mean stated SD over the bound),
        one column per entry of ``columns``, on log axes; every filter with
        two-standard-error bars (the lower bar stopping short of zero), a grey
        line at 1, and a black ring round each stated SD significantly below
        the bound (``"overconfident"``).
    """
    frames = np.asarray(frames, dtype=float)
    fig, axes = subplots(
        2, len(columns), figsize=(WIDTH, 6.4), sharex=True, sharey="row", squeeze=False
    )
    names = list(dict.fromkeys(n for _, against in columns for n in against))
    for j, (title, against) in enumerate(columns):
        axes[0, j].set_title(title)
        for i, key in enumerate(("rmse_ratio", "sd_ratio")):
            ax = axes[i, j]
            for k, name in enumerate(names):
                if name not in against:
                    continue
                a = against[name]
                y, se = np.asarray(a[key]), np.asarray(a[f"{key}_se"])
                # a small offset per filter along the log axis keeps the bars apart
                x = frames * (1 + 0.03 * (k - (len(names) - 1) / 2))
                style = STYLE[name]
                ax.errorbar(
                    x,
                    y,
                    yerr=log_bars(y, se),
                    color=style["color"],
                    linestyle=style["linestyle"],
                    label=style["label"],
                    marker="o",
                    markersize=3,
                    linewidth=1,
                    elinewidth=0.8,
                    capsize=1.5,
                )
                if key == "sd_ratio" and np.any(a["overconfident"]):
                    over = np.asarray(a["overconfident"])
                    ax.plot(
                        x[over],
                        y[over],
                        linestyle="none",
                        marker="o",
                        markersize=8,
                        markerfacecolor="none",
                        markeredgecolor="black",
                        label="stated SD significantly\nbelow the bound",
                    )
            ax.axhline(1.0, color="0.6", linewidth=1, zorder=0)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xticks(frames, [f"{n:g}" for n in frames])
            ax.set_xticks([], minor=True)
        axes[-1, j].set_xlabel("frames $N$")
    axes[0, 0].set_ylabel("RMSE / bound")
    axes[1, 0].set_ylabel("mean stated SD / bound")
    handles, labels = [], []
    for ax in axes.ravel():
        for h, label in zip(*ax.get_legend_handles_labels(), strict=True):
            if label not in labels:
                handles.append(h)
                labels.append(label)
    fig.legend(
        handles, labels, loc="outside lower center", ncol=2, frameon=False, fontsize=MIN_FONT
    )
    return fig


def frame_bound_figure(columns, names=None, zoom=None):
    """Every filter's depth RMSE over the bound at every frame, with Monte Carlo bands.

    Parameters
    ----------
    columns : sequence of (str, dict)
        One column of panels each: its short label and a result of
        :func:`depthbook.studies.per_frame.per_frame_study` (its ``"frames"``
        (K,), its ``"bound"`` and each filter's depth RMSE and its standard
        error, (K,)).
    names : sequence of str, optional
        Filters to draw; default every filter of the first result.
    zoom : (float, float), optional
        The range of a second row of panels, on a linear axis, that shows the
        filters near the bound; default no second row.

    Returns
    -------
    matplotlib.figure.Figure
        One column per entry of ``columns``, sharing a logarithmic axis of the
        RMSE over the bound's depth SD against the frame ``k`` (and, with
        ``zoom``, a linear one below it): a line per filter, shaded two
        standard errors either side (on the logarithmic axis the lower edge
        stopping short of zero), and a grey line at 1, the bound.
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
        b = np.asarray(result["bound"]["depth"])
        for i in range(rows):
            ax = axes[i, j]
            for name in names:
                if name not in result["filters"]:
                    continue
                d = result["filters"][name]["depth"]
                y, se = np.asarray(d["rmse"]) / b, np.asarray(d["rmse_se"]) / b
                style = STYLE[name]
                ax.plot(
                    k,
                    y,
                    color=style["color"],
                    linestyle=style["linestyle"],
                    label=style["label"],
                    linewidth=1.2,
                )
                lo = y - 2 * se if i else np.maximum(y - 2 * se, 0.1 * y)
                ax.fill_between(k, lo, y + 2 * se, color=style["color"], alpha=0.25, linewidth=0)
            ax.axhline(1.0, color="0.6", linewidth=1, zorder=0)
            ax.set_xlim(k[0], k[-1])
        axes[0, j].set_yscale("log")
        axes[0, j].set_title(title)
        axes[-1, j].set_xlabel("frame $k$")
        if zoom is not None:
            axes[1, j].set_ylim(*zoom)
    axes[0, 0].set_ylabel("depth RMSE / bound")
    if zoom is not None:
        axes[1, 0].set_ylabel("depth RMSE / bound\n(near the bound)")
    legend_below(fig, axes.ravel(), ncol=3)
    return fig
