"""Every plot: the paper's figures and the book's other plots, in one style.

Recommended import: ``from depthcore import figures``.

:func:`figure` draws the paper's Figures 2-6 from the curves of
:func:`depthcore.reproduce.curves`; the other functions draw the results of
:mod:`depthcore.optimal`, :mod:`depthcore.study` and :mod:`depthcore.experiments`.
Each filter's label and line style come from the registry
:data:`depthcore.filters.FILTERS` (:data:`STYLE`). The functions return a
:class:`matplotlib.figure.Figure` and never show or save it, except
:func:`save_all`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import _checks, estimates, model, report, reproduce
from . import filters as _filters
from .scenarios import SCENARIOS

#: One vocabulary for every plot, the label, colour and line style of each filter,
#: from the registry :data:`depthcore.filters.FILTERS`.
STYLE = {name: f.plot_style for name, f in _filters.FILTERS.items()}

#: Legend labels and line styles of the importance sampler's settings,
#: :data:`depthcore.experiments.SETTINGS`.
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
#: Axis ranges of the figures, chosen to show the bulk of every density (the
#: scan does not give the paper's axes).
GRIDS = {
    "fig2": (2.5, 10.5),
    "fig3": (2.5, 30.0),
    "fig4": (0.4, 2.2),
    "fig5": (4.5, 8.0),
    "fig6": (2.5, 10.5),
}
#: Where the paper truncates the EKF's peak, so do we (upper limit of the density axis).
YLIM = {"fig3": 0.5}
#: Figures on which the optimal marginal from Eq. (16) as printed (``reading="printed"``)
#: is drawn beside the faithful one: where the two differ visibly.
PRINTED_OVERLAY = ("fig3",)
#: Line style of that curve.
PRINTED_STYLE = {
    "label": "optimal, Eq. (16) as printed",
    "color": "tab:orange",
    "linestyle": (0, (2, 1)),
}
#: The widest figure of the book's plot style, in inches. Every figure is at
#: most ``WIDTH`` inches wide, rendered at ``DPI`` dots per inch (Jupyter and
#: the book draw the PNG at ``fig.dpi``), with no text smaller than ``MIN_FONT``
#: points (tick labels, legends and titles at matplotlib's 10 points unless
#: stated). At the book's content width a figure is shrunk by at most ``WIDTH``
#: inches to that width, so the smallest text stays legible on screen and on an
#: A4 page.
WIDTH = 7.2
#: The dots per inch of every figure's PNG.
DPI = 150
#: The smallest font size of any text of a figure, in points.
MIN_FONT = 9.0
_SYMBOL = {"depth": "y", "velocity": "v"}
#: Leave the creation date out, so that the same figure gives the same file.
_NO_DATE = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}


def _subplots(nrows: int = 1, ncols: int = 1, *, figsize, **kwargs):
    """``plt.subplots`` in the book's style: constrained layout at :data:`DPI`."""
    import matplotlib.pyplot as plt

    if figsize[0] > WIDTH + 1e-9:
        raise ValueError(f"figsize: at most {WIDTH} inches wide, got {figsize[0]}")
    return plt.subplots(nrows, ncols, figsize=figsize, dpi=DPI, layout="constrained", **kwargs)


def plot_marginals(ax, curves: dict, quantity: str, filters=_filters.PAPER_FILTERS):
    """Draw the marginal densities in ``curves`` on ``ax`` with the shared style."""
    for name in filters:
        ax.plot(curves["grid"], curves[name], linewidth=1.6, **STYLE[name])
    sym = _SYMBOL[quantity]
    ax.set_xlabel(f"{quantity} ${sym}$" + (" at time 3" if quantity == "depth" else ""))
    ax.set_ylabel(f"marginal density of ${sym}$")
    ax.legend(frameon=False)
    return ax


def figure(key: str, n: int = 801, filters=_filters.PAPER_FILTERS):
    """Figure ``key`` (``"fig2"`` ... ``"fig6"``): the marginal densities the paper plots.

    Parameters
    ----------
    key : str
    n : int
        Grid points.
    filters : sequence of str
        Which filters to draw: the paper's three by default (its Figure 4
        omits the optimal one, which we draw), or
        :data:`depthcore.filters.NAMES` for the extended figure with the
        UKF and the particle filter. For the keys of :data:`PRINTED_OVERLAY`
        the optimal depth marginal of Eq. (16) as printed is drawn first,
        in :data:`PRINTED_STYLE`.

    Returns
    -------
    matplotlib.figure.Figure
    """

    s = SCENARIOS[key]
    lo, hi = GRIDS[key]
    curves = reproduce.curves(s, np.linspace(lo, hi, n), filters=filters)
    fig, ax = _subplots(figsize=(6.4, 4.0))
    if key in PRINTED_OVERLAY:
        printed = _filters.optimal.marginals(s.mu, s.rho, s.prior, reading="printed")
        ax.plot(curves["grid"], printed.depth_pdf(curves["grid"]), linewidth=1.4, **PRINTED_STYLE)
    plot_marginals(ax, curves, s.quantity, filters)
    if key in YLIM:
        peak = max(np.max(curves[f]) for f in filters)
        ax.set_ylim(0, YLIM[key])
        if peak > YLIM[key]:
            ax.annotate(
                f"EKF peak truncated (height {peak:.2f})",
                xy=(0.98, 0.95),
                xycoords="axes fraction",
                ha="right",
                va="top",
                fontsize=MIN_FONT,
            )
    extended = "extended " if set(filters) - set(_filters.PAPER_FILTERS) else ""
    ax.set_title(
        f"Figure {s.figure} ({extended}reproduction): {caption(key)}", fontsize=MIN_FONT, wrap=True
    )
    return fig


def caption(key: str) -> str:
    """What figure ``key`` plots and with which parameters."""
    s = SCENARIOS[key]
    mu = ", ".join(f"{m:g}" for m in s.mu)
    prior = s.prior.mean
    return (
        f"{s.quantity} marginals, mu = ({mu}), rho = 1/{1 / s.rho:.0f}, "
        f"prior mean ({prior[0]:g}, {prior[1]:g}, {prior[2]:g}), covariance 1000 I"
    )


def save_all(out_dir, formats=("pdf", "png", "svg"), progress=None) -> list[Path]:
    """Write Figures 2-6 into ``out_dir``; returns the paths.

    ``figure<N>.<fmt>`` has the paper's three filters, ``figure<N>-extended.<fmt>``
    adds the UKF and the particle filter. ``progress(done, total)``, if given,
    is called after each figure is written.
    """
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for key, s in SCENARIOS.items():
        for suffix, filters in (("", _filters.PAPER_FILTERS), ("-extended", _filters.NAMES)):
            fig = figure(key, filters=filters)
            for fmt in formats:
                path = out / f"figure{s.figure}{suffix}.{fmt}"
                fig.savefig(path, dpi=200, metadata=_NO_DATE.get(fmt))
                paths.append(path)
            plt.close(fig)
            if progress is not None:
                progress(len(paths) // len(formats), 2 * len(SCENARIOS))
    return paths


def readings_figure(key: str, y_max: float = 150.0, n: int = 1201):
    """The optimal depth marginal of a figure under both readings of Eq. (16).

    Draws ``p_oy`` computed from Eq. (6) (``reading="derived"``) and from
    Eq. (16) as printed, which drops the factor ``exp(-K(y) / 2)``
    (``reading="printed"``), each normalised over ``y > 2``, with their means
    marked.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.
    y_max : float
        Upper end of the depth axis (> 2).
    n : int
        Grid points.

    Returns
    -------
    matplotlib.figure.Figure
    """

    s = SCENARIOS[key]
    y_max = _checks.positive_scalar(y_max - 2.0, "y_max - 2") + 2.0
    y = np.linspace(2.0, y_max, n)[1:]
    fig, ax = _subplots(figsize=(6.4, 3.6))
    styles = {
        "derived": ("black", "-", "from Eq. (6)"),
        "printed": ("tab:orange", "--", "Eq. (16) as printed"),
    }
    for reading, (color, linestyle, label) in styles.items():
        m = _filters.optimal.marginals(s.mu, s.rho, s.prior, reading=reading)
        ax.plot(
            y,
            m.depth_pdf(y),
            color=color,
            linestyle=linestyle,
            linewidth=1.6,
            label=f"{label} (mean {m.depth_mean:.2f})",
        )
        ax.axvline(m.depth_mean, color=color, linestyle=":", linewidth=1.0)
    ax.set_xlabel("depth $y$ at time 3")
    ax.set_ylabel("optimal marginal density of $y$")
    ax.set_xlim(0.0, y_max)
    ax.set_ylim(bottom=0.0)
    ax.legend(frameon=False)
    ax.set_title(
        f"Figure {s.figure}'s measurements: the optimal depth marginal, two readings", fontsize=10
    )
    return fig


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
        From :func:`depthcore.experiments.first_update`.
    extent : float
        Half-width of the plotted square around the camera.

    Returns
    -------
    matplotlib.figure.Figure
    """

    fig, ax = _subplots(figsize=(6.4, 7.0))
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
        From :func:`depthcore.experiments.particle_convergence`.
    quantity : {"depth", "velocity"}

    Returns
    -------
    matplotlib.figure.Figure
    """

    if quantity not in estimates.QUANTITIES:
        raise ValueError(f"quantity must be one of {estimates.QUANTITIES}, got {quantity!r}")
    N = result["sizes"]
    ideal = result["exact"][f"{quantity}_sd"] / np.sqrt(N)
    fig, axes = _subplots(1, 2, figsize=(WIDTH, 4.4), sharey=True)
    for ax, moment, title in zip(axes, ("mean", "sd"), ("mean", "SD"), strict=True):
        for name, err in result["rmse"].items():
            ax.plot(
                N,
                err[f"{quantity}_{moment}"],
                markersize=4,
                **SETTING_STYLE.get(name, {"label": name}),
            )
        ax.plot(
            N,
            ideal,
            color="0.7",
            linewidth=3,
            alpha=0.6,
            zorder=0,
            label=r"posterior SD$/\sqrt{N}$",
        )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("number of particles $N$")
        ax.set_title(
            f"{quantity} {title}: RMS error over {result['repeats']} runs", fontsize=MIN_FONT
        )
    axes[0].set_ylabel("RMS error from the optimal filter")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(
        handles, labels, loc="outside lower center", ncol=2, frameon=False, fontsize=MIN_FONT
    )
    return fig


def noise_study_figure(result: dict):
    """Coverage of the central 68 % depth interval, and the depth RMSE, against ``rho``.

    Each point has bars of two Monte Carlo standard errors either side.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.noise_study`.

    Returns
    -------
    matplotlib.figure.Figure
    """

    fig, axes = _subplots(1, 2, figsize=(WIDTH, 4.0))
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
    axes[0].axhline(0.68, color="0.7", linewidth=1, label="calibrated: 0.68")
    axes[0].set_ylim(0, 1.02)
    axes[0].set_ylabel("fraction of trials whose true depth\nthe central 68 % interval covers")
    axes[1].set_yscale("log")
    axes[1].set_ylabel("RMS error of the depth mean")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("noise level rho (radians)")
    axes[0].legend(frameon=False, fontsize=MIN_FONT)
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
    fig, ax = _subplots(figsize=(6.4, 4.0))
    for rho in np.atleast_1d(_checks.positive_array(rhos, "rhos")):
        ax.plot(
            depths,
            np.exp(-f / (2.0 * rho**2)),
            linewidth=1.6,
            label=f"rho = {report.rho_label(rho)}",
        )
    ax.set_xscale("log")
    ax.set_xlabel("depth $y$ at time 3")
    ax.set_ylabel("profile likelihood of the depth\n(relative to its maximum)")
    ax.set_ylim(0, 1.05)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig


def calibration(result: dict, quantity: str = "depth"):
    """Coverage of each filter's central intervals against their nominal level.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.study.study`.
    quantity : {"depth", "velocity"}

    Returns
    -------
    matplotlib.figure.Figure
    """

    fig, ax = _subplots(figsize=(5.2, 4.6))
    ax.plot([0, 1], [0, 1], color="0.7", linewidth=1, label="calibrated")
    for name, f in result["filters"].items():
        cal = f["calibration"]
        ax.plot(cal["levels"], cal[quantity], marker="o", markersize=3, **STYLE[name])
    ax.set_xlabel("nominal level of the central interval")
    ax.set_ylabel(f"fraction of trials whose true {quantity} it covers")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    ax.set_title(
        f"{quantity}: {result['valid_trials']} trials, rho = {result['rho']:.4g}, "
        f"{result['prior']} prior",
        fontsize=MIN_FONT,
    )
    return fig


def sweep(result: dict, x: str, field: str = "hellinger", log_x: bool = False, log_y: bool = False):
    """One field of each filter against the swept variable.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.noise_sweep` (``x="rho"``),
        :func:`depthcore.experiments.prior_offset_sweep` (``x="offset"``) or
        :func:`depthcore.experiments.prior_velocity_sweep` (``x="velocity"``).
    field : {"hellinger", "depth_mean", "depth_sd"}
    log_x, log_y : bool
        Logarithmic horizontal, vertical axis.

    Returns
    -------
    matplotlib.figure.Figure
    """

    labels = {
        "rho": "noise level rho (radians)",
        "offset": "offset of the prior's depth",
        "velocity": "velocity of the prior's mean",
    }
    ylabels = {
        "hellinger": "Hellinger distance of the depth marginal to the optimal one",
        "depth_mean": "depth mean",
        "depth_sd": "depth SD",
    }
    fig, ax = _subplots(figsize=(6.0, 4.0))
    for name in _filters.NAMES:
        if name in result and not (field == "hellinger" and name == "optimal"):
            ax.plot(result[x], result[name][field], marker="o", markersize=3, **STYLE[name])
    if log_x:
        ax.set_xscale("log")
    if log_y:
        ax.set_yscale("log")
    ax.set_xlabel(labels[x])
    ax.set_ylabel(ylabels[field], fontsize=MIN_FONT)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig


def prior_mean_map_figure(result: dict, marks: dict | None = None):
    """``log10(EKF depth SD / optimal depth SD)`` over the prior mean's depth and velocity.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.prior_mean_map`.
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
    fig, ax = _subplots(figsize=(6.4, 4.4))
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
    fig.colorbar(mesh, ax=ax, label="log10(EKF depth SD / optimal depth SD)")
    ax.set_xlabel("velocity of the prior's mean")
    ax.set_ylabel("offset of the prior's depth")
    return fig


def translating_point(x3=None, n: int = 3):
    """Figure 1 of the paper: a translating point and its bearings from the camera.

    Draws the positions of the point at times ``1 .. n`` (moving by Eq. (1)
    with velocity ``(v, 1)``), the ray from the camera at the origin to each of
    them, and where each ray meets the image line ``y = 1``: the noise-free
    measurement ``mu_i = x_i / y_i`` of Eq. (4).

    Parameters
    ----------
    x3 : array_like, shape (3,), optional
        The state ``(x, y, v)`` at time 3; by default the noise-free solution
        ``c`` of Figure 2's measurements (17), ``(6/5, 6, 6/5)``.
    n : int
        Number of frames drawn (at least 2).

    Returns
    -------
    matplotlib.figure.Figure
    """

    from . import model

    if n < 2:
        raise ValueError(f"n: at least 2 frames are needed to show the motion, got {n}")
    x3 = np.asarray(SCENARIOS["fig2"].c if x3 is None else x3, dtype=float)
    if x3.shape != (3,):
        raise ValueError(f"x3: expected a state (x, y, v) of shape (3,), got shape {x3.shape}")
    states = model.trajectory(model.G(x3, -2), n)
    if np.any(states[:, 1] <= 1.0):
        raise ValueError("x3: the point must be beyond the image line (y > 1) at every frame drawn")
    mu = model.project(states)

    fig, ax = _subplots(figsize=(6.4, 4.4))
    reach = float(np.max(states[:, 1])) + 0.8
    wide = max(float(np.max(np.abs(states[:, 0]))), float(np.max(np.abs(mu)))) + 0.8
    ax.plot(states[:, 0], states[:, 1], color="0.55", linewidth=1, linestyle="--", zorder=1)
    ax.annotate(
        "",
        xy=states[-1, :2] + 0.45 * np.array([states[-1, 2], 1.0]),
        xytext=states[-1, :2],
        arrowprops={"arrowstyle": "->", "color": "0.3"},
    )
    ax.annotate(
        "velocity $(v, 1)$",
        xy=states[-1, :2] + 0.45 * np.array([states[-1, 2], 1.0]),
        xytext=(6, 0),
        textcoords="offset points",
        fontsize=MIN_FONT,
        va="center",
    )
    ax.axhline(1.0, color="tab:blue", linewidth=1)
    ax.annotate(
        "image line $y = 1$",
        xy=(wide, 1.0),
        xytext=(-2, 4),
        textcoords="offset points",
        fontsize=MIN_FONT,
        color="tab:blue",
        ha="right",
    )
    for i, (state, m) in enumerate(zip(states, mu, strict=True), start=1):
        ax.plot([0.0, state[0]], [0.0, state[1]], color="tab:red", linewidth=1, zorder=2)
        ax.plot(state[0], state[1], "o", color="black", markersize=5, zorder=3)
        ax.annotate(
            f"$(x_{i}, y_{i})$",
            xy=state[:2],
            xytext=(-8, 6),
            textcoords="offset points",
            fontsize=MIN_FONT,
            ha="right",
        )
        ax.plot(m, 1.0, "|", color="tab:red", markersize=10, markeredgewidth=1.5, zorder=3)
        ax.annotate(
            f"$\\mu_{i}$",
            xy=(m, 1.0),
            xytext=(0, -16),
            textcoords="offset points",
            fontsize=MIN_FONT,
            color="tab:red",
            ha="center",
        )
    ax.plot(0.0, 0.0, marker="^", color="black", markersize=9)
    ax.annotate(
        "camera", xy=(0.0, 0.0), xytext=(8, -4), textcoords="offset points", fontsize=MIN_FONT
    )
    ax.set_xlim(-wide, wide)
    ax.set_ylim(-0.4, reach)
    ax.set_xlabel("lateral position $x$")
    ax.set_ylabel("depth $y$")
    ax.set_title(
        f"Figure 1 (reproduction): a translating point seen at times 1 to {n}", fontsize=MIN_FONT
    )
    return fig


def bank_depth_figure(densities: dict, truth=None):
    """The bank's posterior depth density at its nodes after several frames.

    Parameters
    ----------
    densities : dict
        ``{frame: (depths, density)}``, each from :func:`depthcore.bank_posterior.node_density`
        of the posterior after that frame: the nodes as depths at that frame and
        the density there (arrays of shape (J,)).
    truth : dict, optional
        ``{frame: depth}``, the true depth at each frame, marked on the axis.

    Returns
    -------
    matplotlib.figure.Figure
        The density against the depth at each frame (one curve per frame, the
        nodes as dots), and the same curves against the depth minus the truth,
        on a logarithmic density axis.
    """
    import matplotlib.pyplot as plt

    if not densities:
        raise ValueError("densities must hold at least one frame")
    fig, axes = _subplots(1, 2, figsize=(WIDTH, 4.2))
    colours = plt.cm.viridis(np.linspace(0.0, 0.9, len(densities)))
    for (frame, (depths, density)), colour in zip(densities.items(), colours, strict=True):
        order = np.argsort(depths)
        y, p = np.asarray(depths)[order], np.asarray(density)[order]
        keep = p > 1e-6 * np.max(p)
        label = f"after frame {frame}"
        axes[0].plot(y[keep], p[keep], "-", color=colour, linewidth=1.2, label=label)
        axes[0].plot(y[keep], p[keep], ".", color=colour, markersize=3)
        if truth is not None:
            axes[0].axvline(truth[frame], color=colour, linewidth=0.8, linestyle=":")
            axes[1].semilogy(y[keep] - truth[frame], p[keep], "-", color=colour, linewidth=1.2)
    axes[0].set_xlabel("depth $y_N$ at frame $N$ (dots: the nodes; dotted: the truth)")
    axes[0].set_ylabel("posterior density")
    axes[0].legend(frameon=False, fontsize=MIN_FONT)
    axes[0].set_title("the bank's depth density at its nodes", fontsize=MIN_FONT)
    if truth is not None:
        axes[1].axvline(0.0, color="0.5", linewidth=0.8, linestyle=":")
        axes[1].set_xlabel("depth minus the true depth at frame $N$")
        axes[1].set_ylabel("posterior density (log scale)")
        axes[1].set_title("about the truth, on a log scale", fontsize=MIN_FONT)
    else:
        axes[1].set_visible(False)
    return fig


def smoothing_figure(track, states, first: int = 1):
    """The depth and lateral position at every frame: filtered, fixed-lag and fixed-interval.

    Parameters
    ----------
    track : depthcore.bank_track.Track
        From :func:`depthcore.bank_track.track`.
    states : array_like, shape (N, 3)
        The true states ``(x_k, y_k, v_k)``.
    first : int
        The first frame drawn (the first frames' filtered SDs can dwarf the rest).

    Returns
    -------
    matplotlib.figure.Figure
        Two panels, the depth and the lateral position: each estimate minus the
        truth, with a band of two SDs about it.
    """
    from matplotlib.ticker import MaxNLocator

    states = np.asarray(states, dtype=float)
    N = states.shape[0]
    if not 1 <= first <= N:
        raise ValueError(f"first must be a frame from 1 to {N}, got {first!r}")
    frames = np.arange(first, N + 1)
    rows = slice(first - 1, N)
    series = (
        ("filtered", track.filtered, "tab:blue", "-"),
        (f"fixed-lag smoothed (lag {track.lag})", track.lagged, "tab:orange", "--"),
        ("fixed-interval smoothed", track.interval, "tab:green", "-"),
    )
    fig, axes = _subplots(1, 2, figsize=(WIDTH, 4.2))
    for ax, i, name in zip(axes, (1, 0), ("depth $y_k$", "lateral position $x_k$"), strict=True):
        for label, s, colour, style in series:
            err = s.mean[rows, i] - states[rows, i]
            sd = np.sqrt(s.cov[rows, i, i])
            ax.plot(frames, err, linestyle=style, color=colour, marker=".", label=label)
            ax.fill_between(frames, err - 2 * sd, err + 2 * sd, color=colour, alpha=0.15)
        ax.axhline(0.0, color="black", linewidth=0.8)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("frame $k$")
        ax.set_ylabel(f"estimate minus truth: {name}")
        ax.set_title(f"{name}: mean $\\pm$ 2 SD, minus the truth", fontsize=MIN_FONT)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(
        handles, labels, loc="outside lower center", ncol=3, frameon=False, fontsize=MIN_FONT
    )
    return fig


def rbpf_convergence_figure(result: dict):
    """The Rao-Blackwellised particle filter's depth moments against the number of particles.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.rbpf_convergence`.

    Returns
    -------
    matplotlib.figure.Figure
        Left: the RMS error of one cloud's depth mean and SD from the exact
        bank's, on log axes, beside the exact SD over ``sqrt(J)``. Right: each
        cloud's depth mean, and their average with two standard errors, about
        the exact value.
    """

    J = np.asarray(result["sizes"])
    exact = result["exact"]
    fig, axes = _subplots(1, 2, figsize=(WIDTH, 4.2))
    ax = axes[0]
    ax.plot(J, result["rmse"]["depth_mean"], "o-", color="tab:purple", label="depth mean")
    ax.plot(J, result["rmse"]["depth_sd"], "s--", color="tab:orange", label="depth SD")
    ax.plot(
        J,
        exact["depth_sd"] / np.sqrt(J),
        color="0.7",
        linewidth=3,
        alpha=0.6,
        zorder=0,
        label=r"exact depth SD$/\sqrt{J}$",
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles per cloud $J$")
    ax.set_ylabel("RMS error from the exact bank")
    ax.set_title(f"RMS error over {result['replicas']} independent clouds", fontsize=MIN_FONT)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    ax = axes[1]
    runs = result["runs"]["depth_mean"] - exact["depth_mean"]
    for k, j in enumerate(J):
        ax.plot(np.full(runs.shape[1], j), runs[k], ".", color="0.6", markersize=4)
    ax.errorbar(
        J,
        result["mean"]["depth_mean"] - exact["depth_mean"],
        yerr=2 * result["se"]["depth_mean"],
        fmt="o",
        color="tab:purple",
        capsize=3,
        label="average of the clouds, 2 SE",
    )
    ax.axhline(0.0, color="black", linewidth=0.8, label="exact bank")
    ax.set_xscale("log")
    ax.set_xlabel("particles per cloud $J$")
    ax.set_ylabel(f"depth mean at frame {result['frames']} minus the exact one")
    ax.set_title("each cloud's depth mean (grey dots)", fontsize=MIN_FONT)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig


def prior_calibration(result: dict):
    """The optimal filter's coverage over truths drawn from its prior, with binomial error bars.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.study.prior_study`.

    Returns
    -------
    matplotlib.figure.Figure
        Nominal level against the fraction of trials covered, for the depth and
        the velocity, with bars of two binomial standard errors
        ``sqrt(p (1 - p) / n)`` about the nominal level.
    """

    levels = np.asarray(result["levels"])
    se = np.asarray(result["coverage_se"])
    fig, ax = _subplots(figsize=(5.2, 4.6))
    ax.plot([0, 1], [0, 1], color="0.7", linewidth=1, label="calibrated")
    ax.fill_between(
        levels, levels - 2 * se, levels + 2 * se, color="0.85", label="two binomial SEs"
    )
    for quantity, marker, shift in (("depth", "o", -0.004), ("velocity", "s", 0.004)):
        ax.errorbar(
            levels + shift,
            result[quantity]["coverage"],
            yerr=2 * se,
            marker=marker,
            markersize=3,
            linestyle="none",
            capsize=2,
            label=f"optimal filter, {quantity}",
        )
    ax.set_xlabel("nominal level of the central interval")
    ax.set_ylabel("fraction of trials whose truth it covers")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    ax.set_title(
        f"truths from the prior: {result['valid_trials']} trials, rho = {result['rho']:.4g}",
        fontsize=MIN_FONT,
    )
    return fig


def frame_marginals_figure(result: list, names=None):
    """Each filter's depth marginal beside the optimal one, one column per number of frames.

    Parameters
    ----------
    result : list of dict
        From :func:`depthcore.experiments.frame_marginals`.
    names : sequence of str, optional
        Filters, one row each; default every filter in ``result`` but the optimal.

    Returns
    -------
    matplotlib.figure.Figure
        One row per filter (its label, wrapped, at the left), one column per
        number of frames (its depth axis at the bottom).
    """
    import textwrap

    from matplotlib.ticker import MaxNLocator

    if names is None:
        names = [n for n in result[0]["density"] if n != "optimal"]
    fig, axes = _subplots(
        len(names),
        len(result),
        figsize=(WIDTH, 0.8 * len(names) + 1.1),
        sharex="col",
        squeeze=False,
    )
    exact = {**STYLE["optimal"], "color": "black", "linestyle": "-", "linewidth": 1.0}
    for j, r in enumerate(result):
        for i, name in enumerate(names):
            ax = axes[i, j]
            ax.fill_between(r["grid"], r["density"]["optimal"], color="0.85", linewidth=0)
            ax.plot(r["grid"], r["density"]["optimal"], **exact)
            ax.plot(r["grid"], r["density"][name], **{**STYLE[name], "linewidth": 1.4})
            ax.set_yticks([])
            if i == 0:
                ax.set_title(f"N = {r['frames']}")
            if j == 0:
                label = textwrap.fill(_filters.FILTERS[name].label, 14)
                ax.set_ylabel(label, fontsize=MIN_FONT, rotation=0, ha="right", va="center")
        axes[-1, j].xaxis.set_major_locator(MaxNLocator(3))
        axes[-1, j].tick_params(labelsize=MIN_FONT)
        axes[-1, j].set_xlabel(f"depth at frame {r['frames']}", fontsize=MIN_FONT)
    return fig


#: The panels of :func:`frames_study_figure`, each (score, label, logarithmic axis, nominal level).
FRAMES_ROWS = (
    ("rmse", "RMSE of the depth mean", True, None),
    ("mean_sd", "mean depth SD", True, None),
    ("hellinger", "Hellinger distance\nto the exact filter", False, None),
    ("nees", "mean NEES", True, 3.0),
    ("coverage_68", "coverage of the\ncentral 68 % interval", False, 0.68),
    ("coverage_95", "coverage of the\ncentral 95 % interval", False, 0.95),
)


def _coverage_bands(ax, frames, level: float, trials) -> None:
    """Shade where a coverage over each number of ``trials`` passes the coverage test."""
    from .experiments import COVERAGE_Z, coverage_test

    for n in sorted(set(int(t) for t in trials)):
        half = COVERAGE_Z * float(coverage_test(level, level, n)["se"])
        ax.axhspan(level - half, level + half, color="0.5", alpha=0.15, linewidth=0)


def frames_study_figure(result: dict, names=None, title: str | None = None):
    """The scores of :func:`depthcore.experiments.frames_study` against ``N``, one panel each.

    Parameters
    ----------
    result : dict
        One ``frames_study`` result.
    names : sequence of str, optional
        Filters to draw; default every filter of ``result``.
    title : str, optional
        Drawn above the panels.

    Returns
    -------
    matplotlib.figure.Figure
        Six panels, :data:`FRAMES_ROWS`, two to a row. The coverage panels shade
        where a coverage passes :func:`depthcore.experiments.coverage_test`
        (within :data:`depthcore.experiments.COVERAGE_Z` binomial standard errors
        of the nominal level) over each filter's number of trials, one band per
        number of trials: they overlap, darkest in the narrowest, of the most
        trials.
    """
    if names is None:
        names = [k for k, v in result.items() if isinstance(v, dict)]
    names = [n for n in names if n in result]
    fig, axes = _subplots(3, 2, figsize=(WIDTH, 8.0), sharex=True)
    frames = np.asarray(result["frames"])
    for ax, (score, label, log, nominal) in zip(axes.ravel(), FRAMES_ROWS, strict=True):
        for name in names:
            if not (score == "hellinger" and name == "optimal"):
                ax.plot(frames, result[name][score], marker="o", markersize=3, **STYLE[name])
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
        ax.set_xlabel("frames N")
    if title is not None:
        fig.suptitle(title)
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(
        handles, labels, loc="outside lower center", ncol=3, frameon=False, fontsize=MIN_FONT
    )
    return fig


def conjecture_figure(result: dict, scores=("hellinger", "coverage_68", "rmse")):
    """The second-order filter (solid) and the EKF (dotted) against ``rho``, per depth and ``N``.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.experiments.conjecture_study`.
    scores : sequence of str
        Rows: ``"hellinger"``, ``"coverage_68"``, ``"coverage_95"``, ``"rmse"``, ``"nees"``.

    Returns
    -------
    matplotlib.figure.Figure
        One row per score, one column per number of frames; the legend gives the
        depths' colours and the filters' line styles once each.
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    labels = {
        "hellinger": "Hellinger distance\nto the optimal filter",
        "coverage_68": "coverage of the\ncentral 68 % interval",
        "coverage_95": "coverage of the\ncentral 95 % interval",
        "rmse": "RMSE of the depth mean",
        "nees": "mean NEES",
    }
    nominal = {"coverage_68": 0.68, "coverage_95": 0.95, "nees": 3.0}
    frames = result["frames"]
    fig, axes = _subplots(
        len(scores),
        len(frames),
        figsize=(WIDTH, 2.2 * len(scores) + 1.2),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, len(result["depth"])))
    styles = (("second_order", "-"), ("ekf", ":"))
    for j, n in enumerate(frames):
        axes[0, j].set_title(f"N = {int(n)}")
        for i, score in enumerate(scores):
            ax = axes[i, j]
            for d, colour in enumerate(colours):
                for name, style in styles:
                    ax.plot(
                        result["rho"],
                        result[name][score][:, d, j],
                        color=colour,
                        linestyle=style,
                        marker="o",
                        markersize=2.5,
                    )
            if score in nominal:
                ax.axhline(nominal[score], color="0.6", linewidth=1)
            if score in ("rmse", "nees"):
                ax.set_yscale("log")
            ax.set_xscale("log")
            rho = np.asarray(result["rho"])[::2]
            ax.set_xticks(rho, [report.rho_label(r) for r in rho])
            ax.set_xticks([], minor=True)
            if j == 0:
                ax.set_ylabel(labels[score])
        axes[-1, j].set_xlabel("noise level rho")
    handles = [
        Line2D([], [], color=colour, marker="o", markersize=3, label=f"depth {depth:g}")
        for depth, colour in zip(result["depth"], colours, strict=True)
    ] + [
        Line2D([], [], color="0.3", linestyle=style, label=_filters.FILTERS[name].label)
        for name, style in styles
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, frameon=False)
    return fig


def hard_figure(cells: list, groups: list, level: int = 68):
    """Each filter's coverage at the fixed truth and over the prior, along axes of settings.

    Parameters
    ----------
    cells : list of dict
        From :func:`depthcore.hardness.hard_study`.
    groups : list of (str, list of int, array_like, bool)
        One column each: the x-axis label, the indices of its cells, their
        x values and whether the x-axis is logarithmic.
    level : int
        The central interval's level in percent, 68 or 95.

    Returns
    -------
    matplotlib.figure.Figure
        Two rows (at the fixed truth; truths drawn from the prior), one column
        per group; each filter's coverage with two-standard-error bars, the
        nominal level in grey.
    """
    key = f"coverage_{int(level)}"
    names = list(cells[0]["fixed"]["filters"])
    fig, axes = _subplots(2, len(groups), figsize=(WIDTH, 5.4), sharey=True, squeeze=False)
    rows = (("fixed", "at the fixed truth"), ("prior", "truths from the prior"))
    for i, (reading, title) in enumerate(rows):
        for j, (xlabel, indices, xs, log_x) in enumerate(groups):
            ax = axes[i, j]
            xs = np.asarray(xs, dtype=float)
            for k, name in enumerate(names):
                s = [cells[c][reading]["filters"][name] for c in indices]
                # a small offset per filter keeps the error bars apart
                shift = (k - (len(names) - 1) / 2) * 0.012
                x = xs * (1 + shift) if log_x else xs + shift * (np.ptp(xs) or 1.0)
                style = {
                    a: STYLE[name][a] for a in ("color", "marker", "label") if a in STYLE[name]
                }
                ax.errorbar(
                    x,
                    [v[key] for v in s],
                    yerr=[2 * v[f"{key}_se"] for v in s],
                    linewidth=1.2,
                    markersize=3.5,
                    capsize=2,
                    **style,
                )
            ax.axhline(level / 100, color="0.6", linewidth=1)
            if log_x:
                ax.set_xscale("log")
            ax.set_xticks(xs, [f"{v:g}" for v in xs])
            ax.set_xticks([], minor=True)
            ax.set_ylim(-0.03, 1.03)
            if i == 1:
                ax.set_xlabel(xlabel)
            if j == 0:
                ax.set_ylabel(f"{level} % coverage,\n{title}")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, frameon=False)
    return fig
