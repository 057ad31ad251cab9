"""Computations and plots of the book's chapters beyond the paper.

Recommended import: ``from depthcore import book_beyond``.

The book's pages hold no function definitions; what the chapters on the UKF
and the particle filter (``book/beyond_filters.md``), the Monte Carlo study
(``book/beyond_study.md``) and the sweeps (``book/beyond_sweeps.md``) compute
beyond a call into :mod:`depthcore.reproduce`, :mod:`depthcore.study` or
:mod:`depthcore.sweeps` lives here, tested in ``tests/test_book_beyond.py``:

* :func:`first_update`, :func:`correlation`, :func:`first_update_figure`: the
  EKF and the UKF after the first measurement, in the ``(x, y)`` plane;
* :func:`particle_convergence`, :func:`convergence_figure`: the particle
  filter's error against the number of particles, for several settings;
* :func:`noise_study`, :func:`noise_study_figure`: the Monte Carlo study
  repeated at several noise levels;
* :func:`profile_misfit`, :func:`far_misfit`, :func:`profile_figure`: the
  least misfit of the measurements at each depth, and its limit at infinite
  depth, which explain the optimal filter's heavy tail at high noise;
* :func:`moments_texts`, :func:`study_texts`, :func:`sweep_texts`,
  :func:`noise_study_texts`, :func:`rho_label`: the texts the pages glue into
  their tables.

Figures follow :data:`depthcore.figures.STYLE`; like :mod:`depthcore.figures`,
the plotting functions return a figure and never show or save it.
"""

from __future__ import annotations

import numpy as np

from . import _checks, ekf, figures, optimal, particle, reproduce, study, ukf
from .scenarios import Scenario

#: Settings of the particle filter compared by :func:`particle_convergence`:
#: keyword arguments of :func:`depthcore.particle.run`.
SETTINGS = {
    "default": {},
    "resampling": {"ess_threshold": 0.5},
    "bootstrap": {"proposal": "prior"},
}
#: Legend labels and line styles of :data:`SETTINGS`.
SETTING_STYLE = {
    "default": {"label": "t proposal from $p_s$, no resampling (default)",
                "color": "tab:purple", "linestyle": "-", "marker": "o"},
    "resampling": {"label": "same, resampling when ESS < N/2",
                   "color": "tab:orange", "linestyle": "--", "marker": "s"},
    "bootstrap": {"label": "bootstrap: particles from the prior",
                  "color": "0.45", "linestyle": ":", "marker": "^"},
}
#: The moments whose errors :func:`particle_convergence` measures.
MOMENTS = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")
#: Particles per call of :func:`depthcore.particle.run` (bounds the memory, about 200 bytes each).
CHUNK_PARTICLES = 200_000
#: Scores of :func:`depthcore.study.scores` per quantity, with their decimals in the book's tables.
STUDY_DECIMALS = {"bias": 3, "rmse": 3, "mean_sd": 3, "coverage_68": 2, "coverage_95": 2}


# --- the first update of the EKF and the UKF ---------------------------------------------


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
    e = ekf.ekf(scenario.mu, scenario.rho, prior)
    u = ukf.ukf(scenario.mu, scenario.rho, prior, sigma_points, allow_behind_camera=True)
    return {
        "mu1": float(scenario.mu[0]),
        "prior": prior,
        "sigma_points": sigma_points.points(prior.mean, prior.cov),
        "ekf": ekf.MeanAndCov(e.means[0], e.covs[0]),
        "ukf": ekf.MeanAndCov(u.means[0], u.covs[0]),
    }


def correlation(cov, i: int = 0, j: int = 1) -> float:
    """The correlation ``cov[i, j] / sqrt(cov[i, i] cov[j, j])`` of components ``i`` and ``j``.

    Parameters
    ----------
    cov : array_like, shape (d, d)
        A covariance with positive ``cov[i, i]`` and ``cov[j, j]``.
    """
    cov = _checks.finite_array(cov, "cov")
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1]:
        raise ValueError(f"cov must be square, got shape {cov.shape}")
    if not (cov[i, i] > 0 and cov[j, j] > 0):
        raise ValueError(f"cov[{i}, {i}] and cov[{j}, {j}] must be positive")
    return float(cov[i, j] / np.sqrt(cov[i, i] * cov[j, j]))


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
        From :func:`first_update`.
    extent : float
        Half-width of the plotted square around the camera.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 7.0), layout="constrained")
    y = np.array([-extent, extent])
    ax.plot(update["mu1"] * y, y, color="0.6", linewidth=1,
            label=r"bearing of $\mu_1$: $x = \mu_1 y$")
    ax.axhline(0.0, color="0.85", linewidth=0.8)
    ax.plot([0], [0], marker="^", color="black", linestyle="none", label="camera")
    prior = update["prior"]
    ax.plot(*_ellipse(prior.mean[:2], prior.cov[:2, :2]).T, color="0.6", linestyle="--",
            linewidth=1, label="prior, 2 SD")
    X = update["sigma_points"]
    ax.plot(X[:, 0], X[:, 1], marker="o", color="tab:green", linestyle="none",
            label="UKF sigma points of the prior")
    for name in ("ekf", "ukf"):
        mean, cov = update[name]
        ax.plot(*_ellipse(mean[:2], cov[:2, :2]).T, color=figures.STYLE[name]["color"],
                linewidth=2, label=f"{figures.STYLE[name]['label']} after $\\mu_1$, 2 SD")
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_box_aspect(1)  # square box and equal limits: equal scales
    ax.set_xlabel("$x$ at time 1")
    ax.set_ylabel("depth $y$ at time 1")
    fig.legend(loc="outside lower center", ncol=2, frameon=False, fontsize=9)
    return fig


# --- convergence of the particle filter ---------------------------------------------------


def _sizes(sizes) -> np.ndarray:
    sizes = np.atleast_1d(np.asarray(sizes))
    if sizes.ndim != 1 or sizes.size < 1 or not np.issubdtype(sizes.dtype, np.integer) \
            or np.any(sizes < 1):
        raise ValueError(f"sizes must be positive integers, got {sizes!r}")
    return sizes.astype(int)


def _run_repeats(scenario: Scenario, n: int, repeats: int, rng, kwargs: dict):
    """Moments (repeats,) per field and the ESS after each measurement (repeats, 3)."""
    s, prior = scenario, scenario.prior
    per_call = max(1, CHUNK_PARTICLES // n)
    moments, ess = [], []
    for start in range(0, repeats, per_call):
        b = min(per_call, repeats - start)
        batch = particle.run(np.tile(s.mu, (b, 1)), s.rho, prior.mean, prior.cov, n, rng, **kwargs)
        moments.append(np.stack(batch.moments(), axis=-1))
        ess.append(batch.ess)
    return np.concatenate(moments), np.concatenate(ess)


def particle_convergence(scenario: Scenario, sizes, repeats: int, seed: int,
                         settings: dict | None = None) -> dict:
    """Root-mean-square errors of the particle filter's moments against ``N``.

    Each setting runs ``repeats`` independent filters on the scenario's
    measurements for each number of particles; the errors are measured from
    the optimal filter's exact moments (:func:`depthcore.optimal.marginals`).

    Parameters
    ----------
    scenario : Scenario
    sizes : array_like of int, shape (S,)
        Numbers of particles ``N``.
    repeats : int
        Independent runs per ``N``, >= 1.
    seed : int
        Seeds a ``SeedSequence``; each setting draws from its own child stream.
    settings : dict, optional
        ``{name: keyword arguments of particle.run}``; default :data:`SETTINGS`.

    Returns
    -------
    dict
        ``"sizes"`` (S,), ``"repeats"``, ``"exact"``: ``{moment: float}`` for
        :data:`MOMENTS`, ``"rmse"``: ``{setting: {moment: (S,)}}`` and
        ``"ess"``: ``{setting: (S, 3)}``, the mean ESS after each measurement
        as a fraction of ``N``.
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    sizes = _sizes(sizes)
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise ValueError(f"repeats must be a positive integer, got {repeats!r}")
    settings = SETTINGS if settings is None else settings
    opt = optimal.marginals(scenario.mu, scenario.rho, scenario.prior)
    exact = np.array([getattr(opt, m) for m in MOMENTS])
    streams = np.random.SeedSequence(seed).spawn(len(settings))
    rmse, ess = {}, {}
    for (name, kwargs), stream in zip(settings.items(), streams):
        rng = np.random.default_rng(stream)
        err, frac = [], []
        for n in sizes:
            m, e = _run_repeats(scenario, int(n), int(repeats), rng, kwargs)
            err.append(np.sqrt(np.mean((m - exact) ** 2, axis=0)))
            frac.append(np.mean(e, axis=0) / n)
        err = np.array(err)
        rmse[name] = {m: err[:, i] for i, m in enumerate(MOMENTS)}
        ess[name] = np.array(frac)
    return {"sizes": sizes, "repeats": int(repeats),
            "exact": {m: float(v) for m, v in zip(MOMENTS, exact)}, "rmse": rmse, "ess": ess}


def convergence_figure(result: dict, quantity: str = "depth"):
    """RMS errors of the mean and the SD of one marginal against ``N``, on log axes.

    The grey line is ``sd / sqrt(N)``, the standard error of the mean of
    ``N`` independent draws from the optimal posterior.

    Parameters
    ----------
    result : dict
        From :func:`particle_convergence`.
    quantity : {"depth", "velocity"}

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    if quantity not in reproduce.QUANTITIES:
        raise ValueError(f"quantity must be one of {reproduce.QUANTITIES}, got {quantity!r}")
    N = result["sizes"]
    ideal = result["exact"][f"{quantity}_sd"] / np.sqrt(N)
    fig, axes = plt.subplots(1, 2, figsize=(9.6, 4.8), layout="constrained", sharey=True)
    for ax, moment, title in zip(axes, ("mean", "sd"), ("mean", "SD")):
        for name, err in result["rmse"].items():
            ax.plot(N, err[f"{quantity}_{moment}"], markersize=4,
                    **SETTING_STYLE.get(name, {"label": name}))
        ax.plot(N, ideal, color="0.7", linewidth=3, alpha=0.6, zorder=0,
                label=r"posterior SD$/\sqrt{N}$")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("number of particles $N$")
        ax.set_title(f"{quantity} {title}: RMS error over {result['repeats']} runs", fontsize=9)
    axes[0].set_ylabel("RMS error from the optimal filter")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, frameon=False, fontsize=9)
    return fig


# --- the Monte Carlo study at several noise levels -------------------------------------------

#: Depth scores of :func:`noise_study`, from :func:`depthcore.study.scores`.
NOISE_STUDY_SCORES = ("bias", "rmse", "mean_sd", "coverage_68", "coverage_95")


def noise_study(rhos, trials: int, seed: int, names=("optimal", "second_order", "ekf", "ukf"),
                prior: str = "paper") -> dict:
    """:func:`depthcore.study.study` at each noise level, its depth scores gathered.

    Parameters
    ----------
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    trials : int
        Trials per noise level (the same seed at every level).
    seed : int
    names : sequence of str
        Filters, from :data:`depthcore.study.FILTERS`.
    prior : {"paper", "fixed"}

    Returns
    -------
    dict
        ``"rho"`` (R,), ``"valid_trials"`` (R,) and, per filter,
        ``{score: (R,)}`` for :data:`NOISE_STUDY_SCORES` (of the depth), ``"nees"``
        and ``"hellinger"`` (the mean Hellinger distance of the depth marginal).
    """
    rhos = np.atleast_1d(_checks.positive_array(rhos, "rhos"))
    runs = [study.study(rho=float(r), trials=trials, seed=seed, prior=prior, names=tuple(names))
            for r in rhos]
    out = {"rho": rhos, "valid_trials": np.array([r["valid_trials"] for r in runs])}
    for name in names:
        f = [r["filters"][name] for r in runs]
        out[name] = {s: np.array([x["depth"][s] for x in f]) for s in NOISE_STUDY_SCORES}
        out[name]["nees"] = np.array([x["nees"] for x in f])
        out[name]["hellinger"] = np.array([x["hellinger_depth"]["mean"] for x in f])
    return out


def noise_study_figure(result: dict):
    """Coverage of the central 68 % depth interval, and the depth RMSE, against ``rho``.

    Parameters
    ----------
    result : dict
        From :func:`noise_study`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.6, 4.0), layout="constrained")
    names = [n for n in reproduce.FILTERS if n in result]
    for name in names:
        axes[0].plot(result["rho"], result[name]["coverage_68"], marker="o", markersize=3,
                     **figures.STYLE[name])
        axes[1].plot(result["rho"], result[name]["rmse"], marker="o", markersize=3,
                     **figures.STYLE[name])
    axes[0].axhline(0.68, color="0.7", linewidth=1, label="calibrated: 0.68")
    axes[0].set_ylim(0, 1.02)
    axes[0].set_ylabel("fraction of trials whose true depth\nthe central 68 % interval covers")
    axes[1].set_yscale("log")
    axes[1].set_ylabel("RMS error of the depth mean")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("noise level rho (radians)")
    axes[0].legend(frameon=False, fontsize=8)
    return fig


# --- the misfit profile along the depth ---------------------------------------------------------


def profile_misfit(mu, depths) -> np.ndarray:
    """The least misfit ``f`` (Eq. (5)) of the measurements over states with a given depth.

    At a fixed depth ``y3`` at time 3 the bearings
    ``(x3 - (3 - i) v) / (y3 - 3 + i)`` are linear in ``(x3, v)``, so
    ``min_{x3, v} sum_i (mu_i - x_i / y_i)**2`` is a linear least-squares
    problem, solved here for each depth. ``exp(-f / (2 rho**2))`` at the
    minimum is the profile likelihood of the depth, relative to its value at
    the noise-free solution (where the misfit is 0).

    Parameters
    ----------
    mu : array_like, shape (3,)
    depths : array_like, shape (n,)
        Depths ``y3 > 2`` at time 3 (the point in front of the camera at times 1-3).

    Returns
    -------
    ndarray, shape (n,)
    """
    mu = _checks.measurements(mu)
    y3 = np.atleast_1d(_checks.finite_array(depths, "depths"))
    if y3.ndim != 1 or np.any(y3 <= 2.0):
        raise ValueError("depths must be a 1-D array of depths > 2 at time 3")
    back = np.array([2.0, 1.0, 0.0])  # 3 - i for i = 1, 2, 3
    yi = y3[:, None] - back  # (n, 3): depth at times 1..3
    A = np.stack([1.0 / yi, -back / yi], axis=-1)  # (n, 3, 2): bearings = A @ (x3, v)
    AtA = np.einsum("nij,nik->njk", A, A)
    Atb = np.einsum("nij,i->nj", A, mu)
    xv = np.linalg.solve(AtA, Atb[..., None])[..., 0]
    r = mu - np.einsum("nij,nj->ni", A, xv)
    return np.sum(r**2, axis=-1)


def far_misfit(mu) -> float:
    """The limit of :func:`profile_misfit` at infinite depth, ``(mu1 - 2 mu2 + mu3)**2 / 6``.

    Far away the bearings of a point moving with constant velocity change
    linearly in time, ``a + b (i - 1)``, and the least misfit of three
    measurements by such a line is their component along ``(1, -2, 1) / sqrt(6)``.
    """
    mu = _checks.measurements(mu)
    return float((mu[0] - 2.0 * mu[1] + mu[2]) ** 2 / 6.0)


def profile_figure(mu, rhos, depths):
    """The profile likelihood ``exp(-f_min(y) / (2 rho**2))`` of the depth, for several ``rho``.

    Parameters
    ----------
    mu : array_like, shape (3,)
    rhos : array_like, shape (R,)
    depths : array_like, shape (n,)
        Depths > 2 at time 3; plotted on a logarithmic axis.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    f = profile_misfit(mu, depths)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), layout="constrained")
    for rho in np.atleast_1d(_checks.positive_array(rhos, "rhos")):
        ax.plot(depths, np.exp(-f / (2.0 * rho**2)), linewidth=1.6, label=f"rho = {rho_label(rho)}")
    ax.set_xscale("log")
    ax.set_xlabel("depth $y$ at time 3")
    ax.set_ylabel("profile likelihood of the depth\n(relative to its maximum)")
    ax.set_ylim(0, 1.05)
    ax.legend(frameon=False, fontsize=8)
    return fig


# --- texts for the pages' tables ---------------------------------------------------------------


def rho_label(rho: float) -> str:
    """A noise level as the paper writes it, ``"1/200"`` (``1 / rho`` rounded to an integer)."""
    rho = _checks.positive_scalar(rho, "rho")
    return f"1/{1.0 / rho:.0f}"


def _pm(mean: float, sd: float, decimals: int) -> str:
    return f"{float(mean) + 0.0:.{decimals}f} ± {float(sd):.{decimals}f}"


def _row(rows: list[dict], name: str, quantity: str) -> dict:
    """The row of ``name`` for ``quantity`` in :func:`reproduce.reproduce`'s scenario rows.

    The optimal filter as derived, restricted to the front of the camera; the
    second-order filter with the covariance ``2 rho**2 J^-1``; the others' only row.
    """
    want = {"optimal": ("derived", "front"), "second_order": ("derived", "all")}.get(name)
    found = [r for r in rows if r["filter"] == name and r["quantity"] == quantity
             and (want is None or (r["reading"], r["support"]) == want)]
    if len(found) != 1:
        raise ValueError(f"expected one row of {name!r} for {quantity!r}, found {len(found)}")
    return found[0]


def moments_texts(result: dict, decimals: int = 3) -> dict:
    """Texts ``"mean ± sd"`` of every filter in every scenario, for glue.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.reproduce.reproduce`.
    decimals : int

    Returns
    -------
    dict
        ``"bf_<key>_<filter>_<quantity>"``: ``"6.466 ± 0.799"`` for each
        scenario key, filter of :data:`depthcore.reproduce.FILTERS` and
        quantity; ``"bf_<key>_particle_<quantity>_se"``: the particle filter's
        Monte Carlo standard error (the larger of its mean's and SD's).
    """
    out = {}
    for sc in result["scenarios"]:
        for name in reproduce.FILTERS:
            for q in reproduce.QUANTITIES:
                r = _row(sc["rows"], name, q)
                out[f"bf_{sc['key']}_{name}_{q}"] = _pm(r["mean"], r["sd"], decimals)
                if name == "particle":
                    out[f"bf_{sc['key']}_{name}_{q}_se"] = f"{r['error']:.{decimals}f}"
    return out


def study_texts(result: dict, prefix: str) -> dict:
    """Texts of every score of :func:`depthcore.study.study`'s result, for glue.

    Returns
    -------
    dict
        ``"<prefix>_<filter>_<quantity>_<score>"`` for the scores of
        :data:`STUDY_DECIMALS`, and ``"<prefix>_<filter>_nees"`` (1 decimal),
        ``"<prefix>_<filter>_hellinger"`` (3 decimals); ``"<prefix>_trials"``.
    """
    out = {f"{prefix}_trials": str(result["valid_trials"])}
    for name, f in result["filters"].items():
        for q in reproduce.QUANTITIES:
            for score, d in STUDY_DECIMALS.items():
                out[f"{prefix}_{name}_{q}_{score}"] = f"{f[q][score] + 0.0:.{d}f}"
        out[f"{prefix}_{name}_nees"] = f"{f['nees']:.1f}"
        out[f"{prefix}_{name}_hellinger"] = f"{f['hellinger_depth']['mean']:.3f}"
    return out


def sweep_texts(result: dict, x: str, prefix: str, decimals: int = 3) -> dict:
    """Texts of a sweep's rows, for glue.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.sweeps.noise_sweep` (``x="rho"``) or
        :func:`depthcore.sweeps.prior_offset_sweep` (``x="offset"``).
    x : {"rho", "offset"}
    prefix : str
    decimals : int

    Returns
    -------
    dict
        For row ``i``: ``"<prefix>_<i>_x"`` (``"1/200"`` or the offset),
        ``"<prefix>_<i>_<filter>"`` (``"mean ± sd"`` of the depth) and
        ``"<prefix>_<i>_<filter>_h"`` (the Hellinger distance to the optimal
        filter, 3 decimals) for each filter in the result.
    """
    if x not in ("rho", "offset"):
        raise ValueError(f"x must be 'rho' or 'offset', got {x!r}")
    out = {}
    names = [n for n in reproduce.FILTERS if n in result]
    for i, value in enumerate(result[x]):
        out[f"{prefix}_{i}_x"] = rho_label(value) if x == "rho" else f"{float(value) + 0.0:g}"
        for name in names:
            r = result[name]
            out[f"{prefix}_{i}_{name}"] = _pm(r["depth_mean"][i], r["depth_sd"][i], decimals)
            out[f"{prefix}_{i}_{name}_h"] = f"{float(r['hellinger'][i]):.3f}"
    return out


def noise_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`noise_study`'s rows, for glue.

    Returns
    -------
    dict
        For row ``i``: ``"<prefix>_<i>_x"`` (``"1/200"``), ``"<prefix>_<i>_trials"``,
        and per filter ``"<prefix>_<i>_<filter>_cov68"``, ``"..._cov95"`` (2
        decimals), ``"..._rmse"`` (3 decimals), ``"..._nees"`` (1 decimal).
    """
    out = {}
    names = [n for n in reproduce.FILTERS if n in result]
    for i, rho in enumerate(result["rho"]):
        out[f"{prefix}_{i}_x"] = rho_label(rho)
        out[f"{prefix}_{i}_trials"] = str(int(result["valid_trials"][i]))
        for name in names:
            r = result[name]
            out[f"{prefix}_{i}_{name}_cov68"] = f"{r['coverage_68'][i]:.2f}"
            out[f"{prefix}_{i}_{name}_cov95"] = f"{r['coverage_95'][i]:.2f}"
            out[f"{prefix}_{i}_{name}_rmse"] = f"{r['rmse'][i]:.3f}"
            out[f"{prefix}_{i}_{name}_nees"] = f"{r['nees'][i]:.1f}"
    return out
