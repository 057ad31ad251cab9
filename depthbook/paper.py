"""The paper's chapters: the model, the filters, the marginals, Figures 2-6 and the appendix.

Recommended import: ``from depthbook import paper``.

* :func:`figure` draws the paper's Figures 2-6 from the curves of
  :func:`depthcore.studies.reproduce.curves`, :func:`caption` captions them and
  :func:`save_all` writes them all (the command line's ``figures``);
  :func:`readings_figure` draws the readings of Eq. (16) (the marginals page)
  and :func:`translating_point` the translating point (the model page);
* :func:`comparison_texts` and :func:`comparison_table`: the figure pages'
  reported-versus-reproduced tables, from :func:`depthcore.studies.reproduce.comparison`;
* :func:`ekf_linearisation` and :func:`bearings_depth_sd`: where the EKF
  linearises the three bearings, and the depth SD those linearised bearings
  allow (the filters page and the appendix).

Each filter's label and line style come from :data:`depthbook.style.STYLE`.
The functions return a :class:`matplotlib.figure.Figure` and never show or
save it, except :func:`save_all`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from depthbook.formatting import DECIMALS
from depthbook.notebook import MarkdownTable
from depthbook.style import MIN_FONT, STYLE, subplots
from depthcore.exact import optimal
from depthcore.kalman import ekf
from depthcore.problem import checks, model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.scenarios import REPORTED_DECIMALS, SCENARIOS
from depthcore.registry import filters as _filters
from depthcore.studies import reproduce

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


_SYMBOL = {"depth": "y", "velocity": "v"}


#: Leave the creation date out, so that the same figure gives the same file.
_NO_DATE = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}


def plot_marginals(ax, curves: dict, quantity: str, filters=_filters.PAPER_FILTERS):
    """Draw the marginal densities in ``curves`` on ``ax`` with the shared style."""
    for name in filters:
        ax.plot(curves["grid"], curves[name], linewidth=1.6, **STYLE[name])
    sym = _SYMBOL[quantity]
    ax.set_xlabel(f"{quantity} ${sym}$" + (" at time 3" if quantity == "depth" else ""))
    ax.set_ylabel(f"marginal density of ${sym}$")
    ax.legend(frameon=False)
    return ax


def figure(key: str, n: int = 801, filters=_filters.PAPER_FILTERS, label: bool = False):
    """Figure ``key`` (``"fig2"`` ... ``"fig6"``): the marginal densities the paper plots.

    Parameters
    ----------
    key : str
    n : int
        Grid points.
    filters : sequence of str
        Which filters to draw: the paper's three by default (its Figure 4
        omits the optimal one, which we draw), or
        :data:`depthcore.registry.filters.NAMES` for the extended figure with the
        UKF and the particle filter. For the keys of :data:`PRINTED_OVERLAY`
        the optimal depth marginal of Eq. (16) as printed is drawn first,
        in :data:`PRINTED_STYLE`.
    label : bool
        Name the figure ("Figure 2", "Figure 2, extended") at the top left of
        the axes, for a file read apart from its caption (:func:`save_all`);
        the book's pages leave it out, as their captions say it.

    Returns
    -------
    matplotlib.figure.Figure
    """

    s = SCENARIOS[key]
    lo, hi = GRIDS[key]
    curves = reproduce.curves(s, np.linspace(lo, hi, n), filters=filters)
    fig, ax = subplots(figsize=(6.4, 4.0))
    if key in PRINTED_OVERLAY:
        printed = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading="printed")
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
    if label:
        extended = ", extended" if set(filters) - set(_filters.PAPER_FILTERS) else ""
        ax.set_title(f"Figure {s.figure}{extended}", fontsize=MIN_FONT, loc="left")
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
            fig = figure(key, filters=filters, label=True)
            for fmt in formats:
                path = out / f"figure{s.figure}{suffix}.{fmt}"
                fig.savefig(path, dpi=200, metadata=_NO_DATE.get(fmt))
                paths.append(path)
            plt.close(fig)
            if progress is not None:
                progress(len(paths) // len(formats), 2 * len(SCENARIOS))
    return paths


#: The width of a figure printed in half a column of the replication article (inches), at
#: which its labels print at the book's type size, :data:`depthbook.style.MIN_FONT`.
PRINT_WIDTH = 3.2

#: The depth axes of the printed figures where they differ from :data:`GRIDS`: Figure 3's
#: reaches far enough for the density of Eq. (16) as printed, whose mean is past 60.
PRINT_GRIDS = {"fig3": (2.5, 150.0)}

#: The printed figures that take the full width of the article's text (two half columns),
#: their depth axes logarithmic, so that the long tail of Eq. (16) as printed shows.
PRINT_WIDE = ("fig3",)


def scenario_title(key: str) -> str:
    """A printed figure's title: its scenario, not its number (``"fig6"``: its prior)."""
    s = SCENARIOS[key]
    equation = s.description.split("measurements ")[1].split(",")[0]
    title = f"{s.quantity}: bearings {equation}, ρ = 1/{1 / s.rho:.0f}"
    return title + (f", prior depth +{s.depth_offset:g}" if s.depth_offset else "")


def print_figure(key: str, n: int = 1201):
    """Figure ``key`` of the paper's three filters at the size the article prints it.

    :data:`PRINT_WIDTH` wide (twice that for :data:`PRINT_WIDE`), so that its
    type prints at the book's size; titled by its scenario
    (:func:`scenario_title`); the depth axis of :data:`PRINT_GRIDS` where
    given. Returns a matplotlib figure.
    """
    s = SCENARIOS[key]
    lo, hi = PRINT_GRIDS.get(key, GRIDS[key])
    curves = reproduce.curves(s, np.linspace(lo, hi, n), filters=_filters.PAPER_FILTERS)
    width = PRINT_WIDTH * (2 if key in PRINT_WIDE else 1)
    fig, ax = subplots(figsize=(width, 2.5))
    if key in PRINTED_OVERLAY:
        printed = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading="printed")
        ax.plot(curves["grid"], printed.depth_pdf(curves["grid"]), linewidth=1.2, **PRINTED_STYLE)
    plot_marginals(ax, curves, s.quantity)
    if key in YLIM:
        ax.set_ylim(0, YLIM[key])
    if key in PRINT_WIDE:
        ax.set_xscale("log")
        ax.set_xlim(lo, hi)
    ax.set_title(scenario_title(key), fontsize=MIN_FONT, loc="left")
    return fig


def save_print(out_dir) -> list[Path]:
    """Write :func:`print_figure` of Figures 2-6 as ``print-figure<N>.pdf``; returns the paths."""
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for key, s in SCENARIOS.items():
        fig = print_figure(key)
        path = out / f"print-figure{s.figure}.pdf"
        fig.savefig(path, metadata=_NO_DATE["pdf"])
        plt.close(fig)
        paths.append(path)
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
    y_max = checks.positive_scalar(y_max - 2.0, "y_max - 2") + 2.0
    y = np.linspace(2.0, y_max, n)[1:]
    fig, ax = subplots(figsize=(6.4, 3.6))
    styles = {
        "derived": ("black", "-", "from Eq. (6)"),
        "printed": ("tab:orange", "--", "Eq. (16) as printed"),
    }
    for reading, (color, linestyle, label) in styles.items():
        m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading=reading)
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

    if n < 2:
        raise ValueError(f"n: at least 2 frames are needed to show the motion, got {n}")
    x3 = np.asarray(SCENARIOS["fig2"].c if x3 is None else x3, dtype=float)
    if x3.shape != (3,):
        raise ValueError(f"x3: expected a state (x, y, v) of shape (3,), got shape {x3.shape}")
    states = model.trajectory(model.G(x3, -2), n)
    if np.any(states[:, 1] <= 1.0):
        raise ValueError("x3: the point must be beyond the image line (y > 1) at every frame drawn")
    mu = model.project(states)

    fig, ax = subplots(figsize=(6.4, 4.4))
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
    return fig


def comparison_texts(key: str, rows: list[dict]) -> dict[str, str]:
    """The numbers of :func:`~depthcore.studies.reproduce.comparison` as the book shows them, for
    glue.

    Keys are ``f"{key}_{row id}_{field}"`` with fields ``mean``, ``sd`` (ours,
    :data:`~depthbook.formatting.DECIMALS` places), ``paper_mean``, ``paper_sd`` (the paper's
    precision, or an em dash where it prints nothing) and ``agrees``.
    """
    texts = {}
    for row in rows:
        name = f"{key}_{row['id']}"
        texts[f"{name}_mean"] = f"{row['mean']:.{DECIMALS}f}"
        texts[f"{name}_sd"] = f"{row['sd']:.{DECIMALS}f}"
        for field in ("mean", "sd"):
            value = row[f"reported_{field}"]
            texts[f"{name}_paper_{field}"] = (
                "—" if value is None else f"{value:.{REPORTED_DECIMALS}f}"
            )
        texts[f"{name}_agrees"] = _agreement(row["mean_matches"], row["sd_matches"])
    return texts


def _agreement(mean_matches, sd_matches) -> str:
    if mean_matches is None:
        return "—"
    return {
        (True, True): "yes",
        (True, False): "mean only",
        (False, True): "SD only",
        (False, False): "no",
    }[(mean_matches, sd_matches)]


def comparison_table(key: str, rows: list[dict]) -> MarkdownTable:
    """A figure page's table of the paper's numbers beside ours, with the numbers in it.

    The book writes this table in the page's text, from the glued
    :func:`comparison_texts`; this is the same table for a notebook, built from
    the same texts. The column ``agrees`` is left out when the paper prints no
    number to agree with.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.
    rows : list of dict
        From :func:`~depthcore.studies.reproduce.comparison` with the same ``key``.
    """
    if key not in SCENARIOS:
        raise ValueError(f"key must be one of {tuple(SCENARIOS)}, got {key!r}")
    texts = comparison_texts(key, rows)
    fields = ["paper_mean", "mean", "paper_sd", "sd"]
    header = ["density", "paper: mean", "ours: mean", "paper: SD", "ours: SD"]
    if any(row["mean_matches"] is not None for row in rows):
        fields.append("agrees")
        header.append("agrees")
    body = [
        [row["label"], *(texts[f"{key}_{row['id']}_{field}"] for field in fields)] for row in rows
    ]
    return MarkdownTable(header, body)


# --- where the EKF linearises ------------------------------------------------------------------


def _gradient_rows(h) -> np.ndarray:
    """``h_k^T F^{k-3}`` for the rows ``h_k`` of ``h`` (3, 3): the vectors of Eq. (24), by row."""
    return np.stack([h[k] @ model.G_linear(k - 2) for k in range(3)])


def bearings_depth_sd(h, rho: float) -> float:
    """The depth SD at time 3 that three linearised bearings allow, without a prior.

    The EKF's inverse covariance at time 3 is Eq. (24) with its own observation
    vectors: ``R^T R / rho**2`` plus the prior's term, where the rows of ``R``
    are ``h_k^T F^{k-3}``, the gradients of the linearised bearings with
    respect to the state at time 3. Without the prior's term the covariance is
    ``rho**2 R^{-1} R^{-T}``; this returns the square root of its depth entry,
    which is ``rho`` times the norm of the depth row of ``R^{-1}``. It is
    infinite when ``R`` is singular: then the three bearings leave a direction
    of the state unresolved.

    Parameters
    ----------
    h : array_like, shape (3, 3)
        Observation vectors (Eq. (11)) of the bearings at times 1, 2, 3, one per row.
    rho : float
        Noise standard deviation, > 0.

    Returns
    -------
    float
    """
    h = checks.finite_array(h, "h", (3, 3))
    rho = checks.positive_scalar(rho, "rho")
    R = _gradient_rows(h)
    if np.linalg.matrix_rank(R) < 3:
        return float("inf")
    return float(rho * np.linalg.norm(np.linalg.solve(R.T, np.eye(3)[1])))


def ekf_linearisation(mu, rho: float, prior: Gaussian) -> dict:
    """Where the EKF linearises the bearings (Eq. (11)), and what follows for the depth.

    Parameters
    ----------
    mu, rho, prior
        The bearings (3,), the noise SD and the prior at time 1 (a
        :class:`~depthcore.problem.gaussian.Gaussian`), as the EKF takes them.

    Returns
    -------
    dict
        ``"h"`` (3, 3): the observation vectors of Eq. (11) at the EKF's
        predicted means ``n`` before each measurement (the prior mean, then
        Eq. (10)), one per row; ``"rows"`` (3, 3): ``h_k^T F^{k-3}``, their
        gradients with respect to the state at time 3 (the vectors of
        Eq. (24)); ``"det"``: the determinant of ``rows``; ``"depth_sd"``
        (3,): the EKF's depth SD after each measurement; ``"bearings_depth_sd"``:
        :func:`bearings_depth_sd` of ``h``.
    """
    if not isinstance(prior, Gaussian):
        raise ValueError(f"prior must be a Gaussian, got {type(prior).__name__}")
    history = ekf.run(mu, rho, prior.mean, prior.cov)
    predicted = [prior.mean] + [ekf.predict(history.means[i], history.covs[i])[0] for i in (0, 1)]
    h = model.observation_vector(np.stack(predicted))
    rows = _gradient_rows(h)
    return {
        "h": h,
        "rows": rows,
        "det": float(np.linalg.det(rows)),
        "depth_sd": np.sqrt(history.covs[:, 1, 1]),
        "bearings_depth_sd": bearings_depth_sd(h, rho),
    }
