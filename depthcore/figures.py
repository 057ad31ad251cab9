"""One function per figure of the paper; each draws curves from :mod:`depthcore.reproduce`.

Recommended import: ``from depthcore import figures``.

Nothing here computes a density: :func:`depthcore.reproduce.curves` does. The
functions return a :class:`matplotlib.figure.Figure` and never show or save it,
except :func:`save_all`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import reproduce
from .scenarios import SCENARIOS

#: One vocabulary for every plot: label, colour and line style of each filter.
STYLE = {
    "optimal": {"label": "optimal $p_o$", "color": "black", "linestyle": "-"},
    "second_order": {"label": "second order $p_s$", "color": "tab:blue", "linestyle": "--"},
    "ekf": {"label": "EKF $p_e$", "color": "tab:red", "linestyle": ":"},
    "ukf": {"label": "UKF", "color": "tab:green", "linestyle": "-."},
    "particle": {"label": "particle filter", "color": "tab:purple", "linestyle": (0, (5, 1, 1, 1, 1, 1))},
}

#: Axis ranges comparable with the paper's plots.
GRIDS = {
    "fig2": (2.5, 10.5),
    "fig3": (2.5, 30.0),
    "fig4": (0.4, 2.2),
    "fig5": (4.5, 8.0),
    "fig6": (2.5, 10.5),
}
#: Where the paper truncates the EKF's peak, so do we (upper limit of the density axis).
YLIM = {"fig3": 0.5}
_SYMBOL = {"depth": "y", "velocity": "v"}
#: Leave the creation date out, so that the same figure gives the same file.
_NO_DATE = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}


def plot_marginals(ax, curves: dict, quantity: str, filters=reproduce.PAPER_FILTERS):
    """Draw the marginal densities in ``curves`` on ``ax`` with the shared style."""
    for name in filters:
        ax.plot(curves["grid"], curves[name], linewidth=1.6, **STYLE[name])
    sym = _SYMBOL[quantity]
    ax.set_xlabel(f"{quantity} ${sym}$" + (" at time 3" if quantity == "depth" else ""))
    ax.set_ylabel(f"marginal density of ${sym}$")
    ax.legend(frameon=False)
    return ax


def figure(key: str, n: int = 801, filters=reproduce.PAPER_FILTERS):
    """Figure ``key`` (``"fig2"`` ... ``"fig6"``): the marginal densities the paper plots.

    Parameters
    ----------
    key : str
    n : int
        Grid points.
    filters : sequence of str
        Which filters to draw: the paper's three by default (its Figure 4
        omits the optimal one, which we draw), or
        :data:`depthcore.reproduce.FILTERS` for the extended figure with the
        UKF and the particle filter.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    s = SCENARIOS[key]
    lo, hi = GRIDS[key]
    curves = reproduce.curves(s, np.linspace(lo, hi, n), filters=filters)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), layout="constrained")
    plot_marginals(ax, curves, s.quantity, filters)
    if key in YLIM:
        peak = max(np.max(curves[f]) for f in filters)
        ax.set_ylim(0, YLIM[key])
        if peak > YLIM[key]:
            ax.annotate(f"EKF peak truncated (height {peak:.2f})", xy=(0.98, 0.95),
                        xycoords="axes fraction", ha="right", va="top", fontsize=9)
    extended = "extended " if set(filters) - set(reproduce.PAPER_FILTERS) else ""
    ax.set_title(f"Figure {s.figure} ({extended}reproduction): {caption(key)}", fontsize=9, wrap=True)
    return fig


def caption(key: str) -> str:
    """What figure ``key`` plots and with which parameters."""
    s = SCENARIOS[key]
    mu = ", ".join(f"{m:g}" for m in s.mu)
    prior = s.prior.mean
    return (f"{s.quantity} marginals, mu = ({mu}), rho = 1/{1 / s.rho:.0f}, "
            f"prior mean ({prior[0]:g}, {prior[1]:g}, {prior[2]:g}), covariance 1000 I")


def save_all(out_dir, formats=("pdf", "png", "svg")) -> list[Path]:
    """Write Figures 2-6 into ``out_dir``; returns the paths.

    ``figure<N>.<fmt>`` has the paper's three filters, ``figure<N>-extended.<fmt>``
    adds the UKF and the particle filter.
    """
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for key, s in SCENARIOS.items():
        for suffix, filters in (("", reproduce.PAPER_FILTERS), ("-extended", reproduce.FILTERS)):
            fig = figure(key, filters=filters)
            for fmt in formats:
                path = out / f"figure{s.figure}{suffix}.{fmt}"
                fig.savefig(path, dpi=200, metadata=_NO_DATE.get(fmt))
                paths.append(path)
            plt.close(fig)
    return paths


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
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 4.6), layout="constrained")
    ax.plot([0, 1], [0, 1], color="0.7", linewidth=1, label="calibrated")
    for name, f in result["filters"].items():
        cal = f["calibration"]
        ax.plot(cal["levels"], cal[quantity], marker="o", markersize=3, **STYLE[name])
    ax.set_xlabel("nominal level of the central interval")
    ax.set_ylabel(f"fraction of trials whose true {quantity} it covers")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(frameon=False, fontsize=8)
    ax.set_title(f"{quantity}: {result['valid_trials']} trials, rho = {result['rho']:.4g}, "
                 f"{result['prior']} prior", fontsize=9)
    return fig


def sweep(result: dict, x: str, field: str = "hellinger", log_x: bool = False):
    """One field of each filter against the swept variable.

    Parameters
    ----------
    result : dict
        From :func:`depthcore.sweeps.noise_sweep` (``x="rho"``) or
        :func:`depthcore.sweeps.prior_offset_sweep` (``x="offset"``).
    field : {"hellinger", "depth_mean", "depth_sd"}
    log_x : bool
        Logarithmic horizontal axis.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    labels = {"rho": "noise level rho (radians)", "offset": "offset of the prior's depth"}
    ylabels = {"hellinger": "Hellinger distance of the depth marginal to the optimal one",
               "depth_mean": "depth mean", "depth_sd": "depth SD"}
    fig, ax = plt.subplots(figsize=(6.0, 4.0), layout="constrained")
    for name in reproduce.FILTERS:
        if name in result and not (field == "hellinger" and name == "optimal"):
            ax.plot(result[x], result[name][field], marker="o", markersize=3, **STYLE[name])
    if log_x:
        ax.set_xscale("log")
    ax.set_xlabel(labels[x])
    ax.set_ylabel(ylabels[field], fontsize=9)
    ax.legend(frameon=False, fontsize=8)
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
    import matplotlib.pyplot as plt

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

    fig, ax = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
    reach = float(np.max(states[:, 1])) + 0.8
    wide = max(float(np.max(np.abs(states[:, 0]))), float(np.max(np.abs(mu)))) + 0.8
    ax.plot(states[:, 0], states[:, 1], color="0.55", linewidth=1, linestyle="--", zorder=1)
    ax.annotate("", xy=states[-1, :2] + 0.45 * np.array([states[-1, 2], 1.0]), xytext=states[-1, :2],
                arrowprops={"arrowstyle": "->", "color": "0.3"})
    ax.annotate("velocity $(v, 1)$", xy=states[-1, :2] + 0.45 * np.array([states[-1, 2], 1.0]),
                xytext=(6, 0), textcoords="offset points", fontsize=9, va="center")
    ax.axhline(1.0, color="tab:blue", linewidth=1)
    ax.annotate("image line $y = 1$", xy=(wide, 1.0), xytext=(-2, 4), textcoords="offset points",
                fontsize=9, color="tab:blue", ha="right")
    for i, (state, m) in enumerate(zip(states, mu), start=1):
        ax.plot([0.0, state[0]], [0.0, state[1]], color="tab:red", linewidth=1, zorder=2)
        ax.plot(state[0], state[1], "o", color="black", markersize=5, zorder=3)
        ax.annotate(f"$(x_{i}, y_{i})$", xy=state[:2], xytext=(-8, 6), textcoords="offset points",
                    fontsize=9, ha="right")
        ax.plot(m, 1.0, "|", color="tab:red", markersize=10, markeredgewidth=1.5, zorder=3)
        ax.annotate(f"$\\mu_{i}$", xy=(m, 1.0), xytext=(0, -16), textcoords="offset points",
                    fontsize=9, color="tab:red", ha="center")
    ax.plot(0.0, 0.0, marker="^", color="black", markersize=9)
    ax.annotate("camera", xy=(0.0, 0.0), xytext=(8, -4), textcoords="offset points", fontsize=9)
    ax.set_xlim(-wide, wide)
    ax.set_ylim(-0.4, reach)
    ax.set_xlabel("lateral position $x$")
    ax.set_ylabel("depth $y$")
    ax.set_title(f"Figure 1 (reproduction): a translating point seen at times 1 to {n}", fontsize=9)
    return fig
