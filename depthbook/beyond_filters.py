"""The chapter on the other filters: Figures 2-6 with five filters, the UKF's first update.

Recommended import: ``from depthbook import beyond_filters``.

* :func:`first_update` and :func:`first_update_figure`: the EKF and the UKF
  after the first measurement; :func:`truncated_bearing_moments`: why the
  unscented transform of the paper's prior has nothing to match, the moments
  of ``x / y`` under a Gaussian with positive density at ``y = 0`` not existing;
* :func:`extended_figure`: the paper's Figures 2-6 as one grid of panels, with
  the UKF and importance sampling beside the paper's three filters;
* :func:`moments_texts`: every filter's moments as the chapter's table glues them.
"""

from __future__ import annotations

import numpy as np

from depthbook.formatting import plus_minus, rho_label
from depthbook.style import MIN_FONT, STYLE, WIDTH, legend_below, subplots
from depthcore.kalman import ekf, ukf
from depthcore.problem import checks
from depthcore.problem.gaussian import MeanAndCov
from depthcore.problem.scenarios import SCENARIOS, Scenario
from depthcore.registry.estimates import QUANTITIES
from depthcore.registry.filters import NAMES
from depthcore.studies import reproduce

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
        From :func:`depthbook.beyond_filters.first_update`.
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


# --- Figures 2-6 with five filters -----------------------------------------------------------


def panel_label(key: str, base: str = "fig2") -> str:
    """A panel's label: the paper's figure number and what differs from Figure 2's experiment.

    Parameters
    ----------
    key : str
        A key of :data:`depthcore.problem.scenarios.SCENARIOS`.
    base : str
        The experiment the others are told apart from.

    Returns
    -------
    str
        ``"Figure 5: $\\rho = 1/500$"``: the measurements, the noise and the
        prior's depth offset where they differ from ``base``'s (the marginal
        drawn is the panel's axis label).
    """
    s, b = SCENARIOS[key], SCENARIOS[base]
    parts = []
    if tuple(s.mu) != tuple(b.mu):
        parts.append(r"$\mu_{1:3} = (" + ", ".join(f"{m:g}" for m in s.mu) + ")$")
    if s.rho != b.rho:
        parts.append(rf"$\rho = {rho_label(s.rho)}$")
    if s.depth_offset != b.depth_offset:
        parts.append(f"prior depth ${s.depth_offset:+g}$")
    return f"Figure {s.figure}" + (": " + ", ".join(parts) if parts else "")


def extended_figure(grids: dict, ylim: dict | None = None, n: int = 801, filters=NAMES):
    """The paper's Figures 2-6 redrawn with every filter, one panel each, one legend.

    Parameters
    ----------
    grids : dict
        ``{scenario key: (lo, hi)}``, the range of each panel's axis (the
        figure pages' ranges), one panel per key in a grid of two columns.
    ylim : dict, optional
        ``{scenario key: top}``: where a panel's density axis is cut (as the
        paper cuts the EKF's peak on Figure 3).
    n : int
        Grid points of each density.
    filters : sequence of str
        The filters drawn (default: all of :data:`depthcore.registry.filters.NAMES`).

    Returns
    -------
    matplotlib.figure.Figure
        One panel per key, labelled by :func:`panel_label`, with the marginal
        densities of :func:`depthcore.studies.reproduce.curves`; the legend in
        the grid's empty cell, or below the grid when it has none.
    """
    keys, ylim = list(grids), ylim or {}
    rows = (len(keys) + 1) // 2
    fig, axes = subplots(rows, 2, figsize=(WIDTH, 2.6 * rows + 0.4), squeeze=False)
    axes = axes.ravel()
    for ax, key in zip(axes, keys, strict=False):
        s = SCENARIOS[key]
        curves = reproduce.curves(s, np.linspace(*grids[key], n), filters=filters)
        for name in filters:
            ax.plot(curves["grid"], curves[name], linewidth=1.4, **STYLE[name])
        sym = _SYMBOL[s.quantity]
        ax.set_xlabel(f"{s.quantity} ${sym}$")
        ax.set_ylabel(f"density of ${sym}$")
        if key in ylim:
            ax.set_ylim(0, ylim[key])
        ax.set_title(panel_label(key), fontsize=MIN_FONT)
    spare = axes[len(keys) :]
    for ax in spare:
        ax.axis("off")
    if len(spare):
        handles, labels = axes[0].get_legend_handles_labels()
        spare[0].legend(handles, labels, loc="center", frameon=False, fontsize=MIN_FONT)
    else:
        legend_below(fig, axes[:1], ncol=3)
    return fig


_SYMBOL = {"depth": "y", "velocity": "v"}


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
