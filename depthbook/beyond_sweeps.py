"""The chapter on sweeps: the noise level, the prior mean, the study across noise levels.

Recommended import: ``from depthbook import beyond_sweeps``.

* :func:`noise_sweep` tests the paper's conjecture that the second-order
  approximation beats the EKF "particularly when the noise level is low":
  for each noise level, the Hellinger distance from each filter's depth
  marginal to the optimal one, for one fixed truth and its noise-free
  measurements (deterministic);
* :func:`prior_offset_sweep` generalises Figure 6: the depth of the prior mean
  is moved by an offset and each filter's depth estimate is followed;
  :func:`prior_velocity_sweep` moves the velocity of the prior mean instead,
  and :func:`prior_mean_map` maps the EKF's depth SD over the prior mean's
  depth and velocity, relative to the optimal filter's;
* :func:`noise_study`: the Monte Carlo study (:func:`depthcore.studies.monte_carlo.study`)
  at several noise levels;
* :func:`sweep`, :func:`profile_figure`, :func:`prior_mean_map_figure`,
  :func:`noise_study_figure` draw them, :func:`noise_study_texts` gives the texts the
  chapter glues.
"""

from __future__ import annotations

import numpy as np

from depthbook.formatting import SCORE_TEXTS, rho_label, row_extremes, value_se
from depthbook.style import MIN_FONT, STYLE, WIDTH, legend_below, subplots
from depthcore.problem import checks, model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, paper_prior_means
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry import filters as _filters
from depthcore.registry.filters import FILTERS, NAMES, check_names
from depthcore.studies import monte_carlo
from depthcore.studies import trials as study_trials
from depthcore.studies.monte_carlo import DEPTH_SCORES, gather_scores

# --- sweeps --------------------------------------------------------------------------------


def _compare(mu, rho, pm, pc, names=NAMES) -> dict:
    """Depth means, SDs and Hellinger distances to the optimal filter, for a batch.

    The optimal filter and every Gaussian filter of ``names`` (default
    :data:`depthcore.registry.filters.NAMES`).
    """
    reference = FILTERS["optimal"](mu, rho, pm, pc)
    out = {
        "optimal": {
            "depth_mean": reference.depth_mean,
            "depth_sd": reference.depth_sd,
            "hellinger": np.zeros(len(mu)),
        }
    }
    for name in check_names(names):
        f = FILTERS[name]
        if f.scoring.gaussian:
            est = f(mu, rho, pm, pc)
            out[name] = {
                "depth_mean": est.depth_mean,
                "depth_sd": est.depth_sd,
                "hellinger": study_trials.gaussian_hellinger(reference.detail, est.mean, est.cov),
            }
    return out


def noise_sweep(rhos, truth=None, prior_scale: float = PAPER_PRIOR_SCALE) -> dict:
    """Depth moments and Hellinger distances to the optimal filter against the noise level.

    For each ``rho`` the measurements are the noise-free ones of ``truth``
    (so the noise-free state is the truth), and the prior is the paper's.

    Parameters
    ----------
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    truth : array_like, shape (3,), optional
        State at time 3; default Figure 2's ``c``.

    Returns
    -------
    dict
        ``{"rho": (R,), name: {"depth_mean", "depth_sd", "hellinger"}}`` with
        arrays of shape (R,) for ``"optimal"``, ``"second_order"``, ``"ekf"``, ``"ukf"``.
    """
    truth = SCENARIOS["fig2"].c if truth is None else np.asarray(truth, dtype=float)
    rhos = np.atleast_1d(np.asarray(rhos, dtype=float))
    mu = np.tile([model.project(model.G(truth, k - 2)) for k in range(3)], (len(rhos), 1))
    pm = paper_prior_means(model.noise_free_states(mu))
    return {"rho": rhos, **_compare(mu, rhos, pm, prior_scale * np.eye(3))}


def _noise_free_state(mu, offsets) -> np.ndarray:
    """``c`` of the bearings ``mu`` (Eq. (7)), where each prior depth ``c2 - 2 + offset`` is > 0."""
    c = model.noise_free_states(mu[None])[0]
    if np.any(c[1] - 2 + offsets <= 0):
        raise ValueError("offsets must keep the prior's depth at time 1, c2 - 2 + offset, positive")
    return c


def _prior_means(mu, offsets, velocities):
    """Prior means ``(c1 - 2 c3, c2 - 2 + offset, velocity)``, shape (D, V, 3)."""
    c = _noise_free_state(mu, offsets)
    pm = paper_prior_means(c, offsets[:, None] + np.zeros((1, len(velocities))))
    pm[..., 2] = velocities[None, :]
    return pm


def _problem(mu, rho):
    """The bearings and the noise SD, Figure 2's where not given."""
    mu = np.asarray(SCENARIOS["fig2"].mu if mu is None else mu, dtype=float)
    return mu, SCENARIOS["fig2"].rho if rho is None else rho


def prior_offset_sweep(
    offsets, mu=None, rho: float | None = None, prior_scale: float = PAPER_PRIOR_SCALE
) -> dict:
    """Each filter's depth estimate as the prior mean's depth moves (Figure 6 generalised).

    The prior mean is ``(c1 - 2 c3, c2 - 2 + offset, 0)``.

    Parameters
    ----------
    offsets : array_like, shape (R,)
        Depth offsets; ``c2 - 2 + offset`` must stay positive.
    mu : array_like, shape (3,), optional
        Default: Eq. (17).
    rho : float, optional
        Default: 1/200.

    Returns
    -------
    dict
        ``{"offset": (R,), name: {"depth_mean", "depth_sd", "hellinger"}}``.
    """
    mu, rho = _problem(mu, rho)
    offsets = np.atleast_1d(np.asarray(offsets, dtype=float))
    pm = paper_prior_means(_noise_free_state(mu, offsets), offsets)
    mus = np.tile(mu, (len(offsets), 1))
    return {"offset": offsets, **_compare(mus, rho, pm, prior_scale * np.eye(3))}


def prior_velocity_sweep(
    velocities,
    mu=None,
    rho: float | None = None,
    depth_offset: float = 0.0,
    prior_scale: float = PAPER_PRIOR_SCALE,
    names=NAMES,
) -> dict:
    """Each filter's depth estimate as the prior mean's velocity moves.

    The prior mean is ``(c1 - 2 c3, c2 - 2 + depth_offset, velocity)``: the
    paper's rule, which sets the velocity to zero, with the velocity varied.
    Every filter, the optimal one included, is given the same prior.

    Parameters
    ----------
    velocities : array_like, shape (R,)
        Velocities of the prior mean.
    mu, rho : optional
        The bearings, shape (3,), and the noise SD, as in :func:`prior_offset_sweep`.
    depth_offset : float
        Added to the prior mean's depth, as in :func:`prior_offset_sweep`.
    prior_scale : float
    names : sequence of str
        Filters of :data:`depthcore.registry.filters.FILTERS`; the Gaussian ones among
        them run beside the optimal filter (default
        :data:`depthcore.registry.filters.NAMES`).

    Returns
    -------
    dict
        ``{"velocity": (R,), name: {"depth_mean", "depth_sd", "hellinger"}}``.
    """
    mu, rho = _problem(mu, rho)
    velocities = np.atleast_1d(checks.finite_array(velocities, "velocities"))
    offsets = np.atleast_1d(checks.finite_array(depth_offset, "depth_offset"))
    pm = _prior_means(mu, offsets, velocities)[0]
    mus = np.tile(mu, (len(velocities), 1))
    return {"velocity": velocities, **_compare(mus, rho, pm, prior_scale * np.eye(3), names)}


def prior_mean_map(
    offsets, velocities, mu=None, rho: float | None = None, prior_scale: float = PAPER_PRIOR_SCALE
) -> dict:
    """The EKF's and the optimal filter's depth SDs over the prior mean's depth and velocity.

    The prior mean is ``(c1 - 2 c3, c2 - 2 + offset, velocity)`` on the grid
    of ``offsets`` by ``velocities``; each grid point gives both filters that prior.

    Parameters
    ----------
    offsets : array_like, shape (D,)
        Depth offsets, as in :func:`prior_offset_sweep`.
    velocities : array_like, shape (V,)
        Velocities of the prior mean.
    mu, rho : optional
        The bearings, shape (3,), and the noise SD, as in :func:`prior_offset_sweep`.

    Returns
    -------
    dict
        ``"offset"`` (D,), ``"velocity"`` (V,), and arrays of shape (D, V):
        ``"ekf_depth_sd"``, ``"optimal_depth_sd"`` and ``"log10_sd_ratio"``,
        ``log10(EKF depth SD / optimal depth SD)``.
    """
    mu, rho = _problem(mu, rho)
    offsets = np.atleast_1d(checks.finite_array(offsets, "offsets"))
    velocities = np.atleast_1d(checks.finite_array(velocities, "velocities"))
    pm = _prior_means(mu, offsets, velocities).reshape(-1, 3)
    mus = np.tile(mu, (len(pm), 1))
    cov = prior_scale * np.eye(3)
    shape = (len(offsets), len(velocities))
    e = FILTERS["ekf"](mus, rho, pm, cov).depth_sd.reshape(shape)
    o = FILTERS["optimal"](mus, rho, pm, cov).depth_sd.reshape(shape)
    return {
        "offset": offsets,
        "velocity": velocities,
        "ekf_depth_sd": e,
        "optimal_depth_sd": o,
        "log10_sd_ratio": np.log10(e / o),
    }


def noise_study(
    rhos, trials: int, seed, names=("optimal", "second_order", "ekf", "ukf"), prior: str = "paper"
) -> dict:
    """:func:`depthcore.studies.monte_carlo.study` at each noise level, its depth scores gathered.

    Parameters
    ----------
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    trials : int
        Trials per noise level (the same seed at every level).
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters, from :data:`depthcore.registry.filters.FILTERS`.
    prior : {"paper", "fixed"}

    Returns
    -------
    dict
        ``"rho"`` (R,), ``"valid_trials"`` (R,) and, per filter,
        ``{score: (R,)}`` for :data:`~depthcore.studies.monte_carlo.DEPTH_SCORES` (of the
        depth) and
        ``"nees"``, each with its standard error
        (:func:`~depthcore.studies.monte_carlo.gather_scores`), and
        ``"hellinger"`` (the mean Hellinger distance of the depth marginal; NaN
        unless ``"optimal"``, the reference, is among ``names``).
    """
    rhos = np.atleast_1d(checks.positive_array(rhos, "rhos"))
    runs = [
        monte_carlo.study(rho=float(r), trials=trials, seed=seed, prior=prior, names=tuple(names))
        for r in rhos
    ]
    out = {"rho": rhos, "valid_trials": np.array([r["valid_trials"] for r in runs])}
    for name in names:
        f = [r["filters"][name] for r in runs]
        out[name] = gather_scores(f, DEPTH_SCORES)
        out[name]["hellinger"] = np.array(
            [np.nan if x["hellinger_depth"] is None else x["hellinger_depth"]["mean"] for x in f]
        )
    return out


def noise_study_figure(result: dict):
    """Coverage of the central 68 % depth interval, and the depth RMSE, against ``rho``.

    Each point has bars of two Monte Carlo standard errors either side.

    Parameters
    ----------
    result : dict
        The scores of :func:`depthbook.beyond_sweeps.noise_study` at each ``"rho"``.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels: the coverage beside its nominal 0.68, and the RMSE.
    """

    fig, axes = subplots(1, 2, figsize=(WIDTH, 4.4))
    names = [n for n in _filters.NAMES if n in result]
    for name in names:
        r = result[name]
        for ax, score in zip(axes, ("coverage_68", "rmse"), strict=True):
            # bars: two Monte Carlo standard errors either side
            ax.errorbar(
                result["rho"],
                r[score],
                yerr=2 * r[f"{score}_se"],
                marker="o",
                markersize=3,
                capsize=2,
                **STYLE[name],
            )
    axes[0].axhline(0.68, color="0.7", linewidth=1, label="calibrated")
    axes[0].set_ylim(0, 1.02)
    axes[0].set_ylabel("fraction of trials whose true depth\nthe central 68 % interval covers")
    axes[1].set_yscale("log")
    axes[1].set_ylabel("RMS error of the depth mean")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel(r"noise level $\rho$ (radians)")
    legend_below(fig, axes, ncol=5)
    return fig


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

    f = model.profile_misfit(mu, depths)
    fig, ax = subplots(figsize=(6.4, 4.0))
    for rho in np.atleast_1d(checks.positive_array(rhos, "rhos")):
        ax.plot(
            depths,
            np.exp(-f / (2.0 * rho**2)),
            linewidth=1.6,
            label=rf"$\rho = {rho_label(rho)}$",
        )
    ax.set_xscale("log")
    ax.set_xlabel("depth $y$ at time 3")
    ax.set_ylabel("profile likelihood of the depth\n(relative to its maximum)")
    ax.set_ylim(0, 1.05)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig


def sweep(result: dict, x: str, field: str = "hellinger", log_x: bool = False, log_y: bool = False):
    """One field of each filter against the swept variable.

    Parameters
    ----------
    result : dict
        From :func:`depthbook.beyond_sweeps.noise_sweep` (``x="rho"``),
        :func:`depthbook.beyond_sweeps.prior_offset_sweep` (``x="offset"``) or
        :func:`depthbook.beyond_sweeps.prior_velocity_sweep` (``x="velocity"``).
    field : {"hellinger", "depth_mean", "depth_sd"}
    log_x, log_y : bool
        Logarithmic horizontal, vertical axis.

    Returns
    -------
    matplotlib.figure.Figure
    """

    labels = {
        "rho": r"noise level $\rho$ (radians)",
        "offset": r"offset $\Delta$ of the prior's depth",
        "velocity": r"velocity $v_0$ of the prior mean",
    }
    ylabels = {
        "hellinger": "Hellinger distance of the\ndepth marginal to the optimal one",
        "depth_mean": "depth mean at time 3",
        "depth_sd": "depth SD at time 3",
    }
    fig, ax = subplots(figsize=(6.0, 4.4))
    for name in FILTERS:
        if name in result and not (field == "hellinger" and name == "optimal"):
            ax.plot(result[x], result[name][field], marker="o", markersize=3, **STYLE[name])
    if log_x:
        ax.set_xscale("log")
    if log_y:
        ax.set_yscale("log")
    ax.set_xlabel(labels[x])
    ax.set_ylabel(ylabels[field])
    legend_below(fig, [ax], ncol=3)
    return fig


def prior_mean_map_figure(result: dict, marks: dict | None = None):
    """``log10(EKF depth SD / optimal depth SD)`` over the prior mean's depth and velocity.

    Parameters
    ----------
    result : dict
        From :func:`depthbook.beyond_sweeps.prior_mean_map`.
    marks : dict, optional
        ``{label: (offset, velocity)}``: prior means to mark on the map.

    Returns
    -------
    matplotlib.figure.Figure
        A diverging colour map centred on 0 (equal SDs), with the contour 0 drawn.
    """
    from matplotlib.colors import TwoSlopeNorm

    r = result["log10_sd_ratio"]
    limit = float(np.max(np.abs(r)))
    fig, ax = subplots(figsize=(6.4, 4.4))
    mesh = ax.pcolormesh(
        result["velocity"],
        result["offset"],
        r,
        cmap="RdBu_r",
        norm=TwoSlopeNorm(0.0, -limit, limit),
        shading="nearest",
    )
    ax.contour(result["velocity"], result["offset"], r, levels=[0.0], colors="black")
    for label, (offset, velocity) in (marks or {}).items():
        ax.plot(velocity, offset, marker="o", color="black", linestyle="none")
        ax.annotate(label, (velocity, offset), xytext=(5, 5), textcoords="offset points")
    fig.colorbar(mesh, ax=ax, label=r"$\log_{10}$(EKF depth SD / optimal depth SD)")
    ax.set_xlabel(r"velocity $v_0$ of the prior mean")
    ax.set_ylabel(r"offset $\Delta$ of the prior's depth")
    return fig


def noise_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`~depthbook.beyond_sweeps.noise_study`'s rows, for glue.

    Returns
    -------
    dict
        For row ``i``: ``"<prefix>_<i>_x"`` (``"1/200"``), ``"<prefix>_<i>_trials"``,
        and per filter ``"<prefix>_<i>_<filter>_cov68"``, ``"..._cov95"`` (2
        decimals), ``"..._rmse"`` (3 decimals), ``"..._nees"`` (1 decimal),
        each also with ``_pm`` appended: ``"value ± standard error"``
        (:func:`~depthbook.formatting.value_se`). Per filter and score,
        ``"<prefix>_<filter>_<key>_min_pm"`` and ``"..._max_pm"``: the ``_pm``
        text of the row where the score is least, and greatest.
    """
    out = {}
    names = [n for n in NAMES if n in result]
    for i, rho in enumerate(result["rho"]):
        out[f"{prefix}_{i}_x"] = rho_label(rho)
        out[f"{prefix}_{i}_trials"] = str(int(result["valid_trials"][i]))
        for name in names:
            r = result[name]
            row = f"{prefix}_{i}_{name}"
            for key, score, d in SCORE_TEXTS:
                if score in ("bias", "mean_sd"):
                    continue
                out[f"{row}_{key}"] = f"{float(r[score][i]) + 0.0:.{d}f}"
                out[f"{row}_{key}_pm"] = value_se(r[score][i], r[f"{score}_se"][i], d)
    out.update(row_extremes(out, result, names, prefix))
    return out
