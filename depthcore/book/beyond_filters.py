"""The chapter on the other filters: the first update, the particle filters' convergence.

Recommended import: ``from depthcore.book import beyond_filters``.

* :func:`first_update` and :func:`first_update_figure`: the EKF and the UKF
  after the first measurement; :func:`truncated_bearing_moments`: why the
  unscented transform of the paper's prior has nothing to match, the moments
  of ``x / y`` under a Gaussian with positive density at ``y = 0`` not existing;
* :func:`particle_convergence` and :func:`convergence_figure`: the importance
  sampler's error against the number of particles, for the settings
  :data:`SETTINGS`;
* :func:`resample_move_runs`: the causal particle filter with resample-move
  (:mod:`depthcore.particles.resample_move`) run independently several times on a
  scenario, against the optimal filter;
* :func:`moments_texts`: every filter's moments as the chapter's table glues them.
"""

from __future__ import annotations

import numpy as np

from depthcore.book.style import MIN_FONT, STYLE, WIDTH, legend_below, reference_rate, subplots
from depthcore.exact import optimal
from depthcore.formatting import plus_minus
from depthcore.kalman import ekf, ukf
from depthcore.particles import importance, resample_move
from depthcore.problem import checks
from depthcore.problem.gaussian import MeanAndCov
from depthcore.problem.scenarios import Scenario
from depthcore.registry.estimates import MOMENTS, QUANTITIES
from depthcore.registry.filters import NAMES

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


def particle_convergence(
    scenario: Scenario, sizes, repeats: int, seed, settings: dict | None = None
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

    Returns
    -------
    dict
        ``"sizes"`` (S,), ``"repeats"``, ``"exact"``: ``{moment: float}`` for
        :data:`~depthcore.registry.estimates.MOMENTS`, ``"rmse"``: ``{setting: {moment: (S,)}}`` and
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
    rmse, ess = {}, {}
    for (name, kwargs), stream in zip(settings.items(), streams, strict=True):
        rng = np.random.default_rng(stream)
        err, frac = [], []
        for n in sizes:
            m, e = _run_repeats(scenario, int(n), int(repeats), rng, kwargs)
            err.append(np.sqrt(np.mean((m - exact) ** 2, axis=0)))
            frac.append(np.mean(e, axis=0) / n)
        err = np.array(err)
        rmse[name] = {m: err[:, i] for i, m in enumerate(MOMENTS)}
        ess[name] = np.array(frac)
    return {
        "sizes": sizes,
        "repeats": int(repeats),
        "exact": {m: float(v) for m, v in zip(MOMENTS, exact, strict=True)},
        "rmse": rmse,
        "ess": ess,
    }


# --- the causal particle filter (resample-move) ----------------------------------------------


def resample_move_runs(
    scenario: Scenario, n_particles: int, repeats: int, seed, moves: int = 20
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
    batches = [
        resample_move.run(
            [s.mu],
            s.rho,
            prior.mean,
            prior.cov,
            n_particles,
            np.random.default_rng(stream),
            moves,
        )
        for stream in checks.spawn(seed, int(repeats))
    ]
    runs = {k: np.concatenate([b.moments()[k] for b in batches]) for k in MOMENTS}
    opt = optimal.run(s.mu, s.rho, prior.mean, prior.cov)
    return {
        "runs": runs,
        "mean": {k: float(np.mean(v)) for k, v in runs.items()},
        "se": {k: float(np.std(v, ddof=1) / np.sqrt(len(v))) for k, v in runs.items()},
        "exact": {k: float(getattr(opt, k)) for k in MOMENTS},
        "ess": np.concatenate([b.ess for b in batches]) / n_particles,
        "resampled": np.concatenate([b.resampled for b in batches]),
    }


# --- the first update of the EKF and the UKF -------------------------------------------------


def first_update(scenario: Scenario, sigma_points: ukf.SigmaPoints = ukf.SigmaPoints()) -> dict:
    """The EKF and the UKF after ``mu_1``, and the sigma points of the prior.

    Parameters
    ----------
    scenario : Scenario
    sigma_points : SigmaPoints
        The UKF's rule (default ``alpha = 1, beta = 0, kappa = 0``).

    Returns
    -------
    dict
        ``"mu1"`` (float), ``"prior"`` (Gaussian), ``"sigma_points"`` of
        shape (7, 3), and ``"ekf"``, ``"ukf"``: ``MeanAndCov`` of the state at
        time 1 after ``mu_1``, shapes (3,) and (3, 3). The UKF runs with
        sigma points behind the camera (``allow_behind_camera=True``).
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    prior = scenario.prior
    e = ekf.run(scenario.mu, scenario.rho, prior.mean, prior.cov)
    u = ukf.run(
        scenario.mu,
        scenario.rho,
        prior.mean,
        prior.cov,
        sigma_points=sigma_points,
        allow_behind_camera=True,
    )
    return {
        "mu1": float(scenario.mu[0]),
        "prior": prior,
        "sigma_points": sigma_points.points(prior.mean, prior.cov),
        "ekf": MeanAndCov(e.means[0], e.covs[0]),
        "ukf": MeanAndCov(u.means[0], u.covs[0]),
    }


def truncated_bearing_moments(mean, cov, eps) -> dict:
    """The prior mass near ``y = 0`` and the second moment of ``x / y`` away from it.

    Under a Gaussian on ``(x, y)`` the density of ``y`` is positive at 0, so
    ``P(|y| < eps)`` is about ``2 eps p_y(0)`` and
    ``E[(x / y)**2 ; |y| > eps]`` grows like ``2 p_y(0) E[x**2 | y = 0] / eps``:
    ``E[(x / y)**2]`` is infinite, and ``E[x / y]`` does not exist either
    (``E[|x / y|]`` diverges like ``log(1 / eps)``). These are the moments the
    unscented transform of ``h(x) = x / y`` sets out to match.

    Parameters
    ----------
    mean : array_like, shape (2,) or (3,)
        Mean of ``(x, y)`` (a third component, the velocity, is ignored).
    cov : array_like, shape (2, 2) or (3, 3)
        Covariance; its ``(x, y)`` block is used.
    eps : array_like, shape (E,)
        Half-widths of the excluded band ``|y| < eps``, each > 0.

    Returns
    -------
    dict
        ``"eps"`` (E,), ``"mass"`` (E,): ``P(|y| < eps)``, ``"second_moment"``
        (E,): ``E[(x / y)**2 ; |y| > eps]`` (adaptive quadrature in ``log |y|``
        of ``E[x**2 | y] p(y) / y**2``), and ``"density_at_zero"``: ``p_y(0)``.
    """
    from scipy.integrate import quad
    from scipy.special import ndtr

    mean = checks.finite_array(mean, "mean")
    cov = checks.finite_array(cov, "cov")
    if mean.shape not in ((2,), (3,)) or cov.shape != 2 * mean.shape:
        raise ValueError(
            f"mean and cov must have shapes (d,), (d, d), d = 2 or 3; got {mean.shape}, {cov.shape}"
        )
    eps = np.atleast_1d(checks.positive_array(eps, "eps"))
    mx, my = mean[:2]
    cxx, cxy, cyy = cov[0, 0], cov[0, 1], cov[1, 1]
    if not (cyy > 0 and cxx * cyy - cxy**2 >= 0):
        raise ValueError("cov must be positive semi-definite with cov[1, 1] > 0")
    sy = np.sqrt(cyy)
    slope, residual = cxy / cyy, cxx - cxy**2 / cyy

    def weight(y):  # E[x**2 | y] p(y) / y**2, times |y| for the variable log|y|
        p = np.exp(-0.5 * ((y - my) / sy) ** 2) / (np.sqrt(2.0 * np.pi) * sy)
        return ((mx + slope * (y - my)) ** 2 + residual) * p / np.abs(y)

    top = np.log(abs(my) + 40.0 * sy)
    moments = [
        sum(
            quad(lambda t, sign=sign: weight(sign * np.exp(t)), np.log(e), top, limit=200)[0]
            for sign in (1.0, -1.0)
        )
        for e in eps
    ]
    return {
        "eps": eps,
        "mass": ndtr((eps - my) / sy) - ndtr((-eps - my) / sy),
        "second_moment": np.array(moments),
        "density_at_zero": float(np.exp(-0.5 * (my / sy) ** 2) / (np.sqrt(2.0 * np.pi) * sy)),
    }


#: Legend labels and line styles of the importance sampler's settings,
#: :data:`depthcore.book.beyond_filters.SETTINGS`.
SETTING_STYLE = {
    "default": {
        "label": "importance sampling, t proposal from $p_s$ (default)",
        "color": "tab:purple",
        "linestyle": "-",
        "marker": "o",
    },
    "resampling": {
        "label": "same, resampling (no move) when ESS < N/2",
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


def _ellipse(mean, cov, n_sd: float = 2.0, n: int = 361) -> np.ndarray:
    """Points (n, 2) of the ``n_sd``-SD ellipse of a 2-D Gaussian (a segment if singular)."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    t = np.linspace(0.0, 2.0 * np.pi, n)
    circle = np.stack([np.cos(t), np.sin(t)], axis=-1)
    return mean + n_sd * (circle * np.sqrt(np.clip(vals, 0.0, None))) @ vecs.T


def first_update_figure(update: dict, extent: float = 70.0):
    """The prior's sigma points and the EKF's and UKF's densities after ``mu_1``, in ``(x, y)``.

    Parameters
    ----------
    update : dict
        From :func:`depthcore.book.beyond_filters.first_update`.
    extent : float
        Half-width of the plotted square around the camera.

    Returns
    -------
    matplotlib.figure.Figure
    """

    fig, ax = subplots(figsize=(6.4, 7.0))
    y = np.array([-extent, extent])
    ax.plot(
        update["mu1"] * y, y, color="0.6", linewidth=1, label=r"bearing of $\mu_1$: $x = \mu_1 y$"
    )
    ax.axhline(0.0, color="0.85", linewidth=0.8)
    ax.plot([0], [0], marker="^", color="black", linestyle="none", label="camera")
    prior = update["prior"]
    ax.plot(
        *_ellipse(prior.mean[:2], prior.cov[:2, :2]).T,
        color="0.6",
        linestyle="--",
        linewidth=1,
        label="prior, 2 SD",
    )
    X = update["sigma_points"]
    ax.plot(
        X[:, 0],
        X[:, 1],
        marker="o",
        color="tab:green",
        linestyle="none",
        label="UKF sigma points of the prior",
    )
    for name in ("ekf", "ukf"):
        mean, cov = update[name]
        ax.plot(
            *_ellipse(mean[:2], cov[:2, :2]).T,
            color=STYLE[name]["color"],
            linewidth=2,
            label=f"{STYLE[name]['label']} after $\\mu_1$, 2 SD",
        )
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_box_aspect(1)  # square box and equal limits: equal scales
    ax.set_xlabel("$x$ at time 1")
    ax.set_ylabel("depth $y$ at time 1")
    fig.legend(loc="outside lower center", ncol=2, frameon=False, fontsize=MIN_FONT)
    return fig


def convergence_figure(result: dict, quantity: str = "depth"):
    """RMS errors of the mean and the SD of one marginal against ``N``, on log axes.

    The grey line is ``sd / sqrt(N)``, the standard error of the mean of
    ``N`` independent draws from the optimal posterior.

    Parameters
    ----------
    result : dict
        The errors of :func:`depthcore.book.beyond_filters.particle_convergence` at
        its ``"sizes"`` ``N``, of each setting of ``"rmse"``, over ``"repeats"`` runs.
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
    for ax, moment, title in zip(axes, ("mean", "sd"), ("mean", "SD"), strict=True):
        for name, err in result["rmse"].items():
            ax.plot(
                N,
                err[f"{quantity}_{moment}"],
                markersize=4,
                **SETTING_STYLE.get(name, {"label": name}),
            )
        reference_rate(ax, N, ideal, r"posterior SD$/\sqrt{N}$")
        ax.set_xlabel("number of particles $N$")
        ax.set_title(
            f"{quantity} {title}: RMS error over {result['repeats']} runs", fontsize=MIN_FONT
        )
    axes[0].set_ylabel("RMS error from the optimal filter")
    legend_below(fig, axes[:1], ncol=2)
    return fig


def _row(rows: list[dict], name: str, quantity: str) -> dict:
    """The row of ``name`` for ``quantity``.

    The row is taken from :func:`depthcore.studies.reproduce.reproduce`'s scenario rows.

    The optimal filter as derived, restricted to the front of the camera; the
    second-order filter with the covariance ``2 rho**2 J^-1``; the others' only row.
    """
    want = {"optimal": ("derived", "front"), "second_order": ("derived", "all")}.get(name)
    found = [
        r
        for r in rows
        if r["filter"] == name
        and r["quantity"] == quantity
        and (want is None or (r["reading"], r["support"]) == want)
    ]
    if len(found) != 1:
        raise ValueError(f"expected one row of {name!r} for {quantity!r}, found {len(found)}")
    return found[0]


def moments_texts(result: dict, decimals: int = 3) -> dict:
    """Texts ``"mean ± sd"`` of every filter in every scenario, for glue.

    Parameters
    ----------
    result : dict
        Every scenario's rows of :func:`depthcore.studies.reproduce.reproduce`.
    decimals : int
        Places of the mean, the SD and the standard error.

    Returns
    -------
    dict
        ``"bf_<key>_<filter>_<quantity>"``: ``"6.466 ± 0.799"`` for each
        scenario key, filter of :data:`depthcore.registry.filters.FILTERS` and
        quantity; ``"bf_<key>_particle_<quantity>_se"``: the particle filter's
        Monte Carlo standard error (the larger of its mean's and SD's).
    """
    out = {}
    for sc in result["scenarios"]:
        for name in NAMES:
            for q in QUANTITIES:
                r = _row(sc["rows"], name, q)
                out[f"bf_{sc['key']}_{name}_{q}"] = plus_minus(r["mean"], r["sd"], decimals)
                if name == "particle":
                    out[f"bf_{sc['key']}_{name}_{q}_se"] = f"{r['error']:.{decimals}f}"
    return out
