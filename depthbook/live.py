"""Live controls for the figure pages: the filters' depth marginals, redrawn as the problem changes.

Recommended import: ``from depthbook import live``.

The pages of Figures 2 and 6 draw the depth marginals of the paper's three
filters for one noise level, one prior and three frames. In Jupyter,
:func:`controls` adds sliders for the noise level ``rho``, the prior's mean
``(x, y, v)`` at frame 1 and its covariance ``diag(s_x**2, s_y**2, s_v**2)``,
and the number of frames ``N``; each change redraws the marginals with
:func:`draw`. The book shows the same drawing at the page's own values,
:func:`figure`.

Frames beyond the page's three bearings are those of the point that the three
bearings put at the noise-free state ``c`` of Eq. (7): ``mu_k`` is the
projection of ``G^(k-3) c`` (Eqs. (1), (2)), with no noise, for ``k = 4 .. N``
(:func:`bearings`). The filters are the registry's
(:data:`depthcore.registry.filters.FILTERS`; for ``N > 3`` the optimal filter is the
bank of Kalman filters over depth of :mod:`depthcore.exact.bank`), run with no
process noise; the prior is on the state at frame 1, and the marginals are
those of the depth at frame ``N``.

``ipywidgets`` is imported by :func:`controls` alone, when it is called: the
other functions need only NumPy and Matplotlib.
"""

from __future__ import annotations

import numpy as np

from depthbook.style import WIDTH
from depthcore.problem import checks, model
from depthcore.registry.filters import FILTERS, check_names

#: The filters drawn by default, the paper's three.
NAMES = ("optimal", "second_order", "ekf")
#: The largest number of frames the frame slider offers.
MAX_SLIDER_FRAMES = 30


def bearings(mu, frames: int) -> np.ndarray:
    """The bearings ``mu`` continued, without noise, to ``frames`` frames.

    Parameters
    ----------
    mu : array_like, shape (3,)
        The bearings of frames 1, 2, 3.
    frames : int
        ``N >= 3``, at most ``depthcore.problem.checks.MAX_FRAMES``.

    Returns
    -------
    ndarray, shape (N,)
        ``mu`` followed by the projections ``x_k / y_k`` of ``G^(k-3) c``,
        ``k = 4 .. N``, where ``c`` is the noise-free state of ``mu`` at frame
        3 (Eq. (7)) and ``G`` the motion (Eq. (1)).
    """
    mu = checks.finite_array(mu, "mu", (3,))
    frames = checks.frames(frames)
    c = model.noise_free_state(mu)
    later = [model.project(model.G(c, k)) for k in range(1, frames - 2)]
    return np.concatenate([mu, np.asarray(later, dtype=float).reshape(-1)])


def depth_marginals(
    mu,
    rho: float,
    prior_mean,
    prior_cov,
    frames: int = 3,
    names=NAMES,
    n_points: int = 801,
    width: float = 5.0,
) -> dict:
    """Each filter's depth marginal at frame ``N``, the bearings ``mu`` continued to ``N`` frames.

    Parameters
    ----------
    mu : array_like, shape (3,)
        The bearings of frames 1, 2, 3 (continued by :func:`bearings`).
    rho : float
        Bearing noise SD (radians), > 0.
    prior_mean : array_like, shape (3,)
        Mean of the prior on the state ``(x, y, v)`` at frame 1.
    prior_cov : array_like, shape (3, 3)
        Its covariance, symmetric positive definite.
    frames : int
        ``N``, from 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    names : sequence of str
        Filters of the registry that take ``N`` frames and no random numbers.
    n_points : int
        Points of the depth grid.
    width : float
        The grid spans every filter's depth mean ± ``width`` of its SDs (cut at 0).

    Returns
    -------
    dict
        ``"frames"`` (N), ``"mu"`` (N,), ``"grid"`` (G,), ``"density"``
        ``{name: (G,)}``, ``"depth_mean"`` and ``"depth_sd"`` ``{name: float}``.
    """
    names = check_names(names)
    random = [name for name in names if FILTERS[name].random]
    if random:
        raise ValueError(f"names must name filters without random numbers, got {random}")
    n_points = checks.count(n_points, "n_points")
    width = checks.positive_scalar(width, "width")
    mu_n = bearings(mu, frames)
    estimates = {name: FILTERS[name](mu_n, rho, prior_mean, prior_cov) for name in names}
    means = {name: float(e.depth_mean) for name, e in estimates.items()}
    sds = {name: float(e.depth_sd) for name, e in estimates.items()}
    lo = max(min(means[n] - width * sds[n] for n in names), 1e-9)
    hi = max(means[n] + width * sds[n] for n in names)
    grid = np.linspace(lo, hi, n_points)
    return {
        "frames": len(mu_n),
        "mu": mu_n,
        "grid": grid,
        "density": {name: FILTERS[name].density(e, "depth", grid) for name, e in estimates.items()},
        "depth_mean": means,
        "depth_sd": sds,
    }


def draw(ax, marginals: dict) -> None:
    """Draw the densities of :func:`depth_marginals` on the Matplotlib axes ``ax``, afresh."""
    ax.clear()
    for name, density in marginals["density"].items():
        ax.plot(marginals["grid"], density, linewidth=1.6, **FILTERS[name].plot_style)
    ax.set_xlabel(f"depth $y$ at frame {marginals['frames']}")
    ax.set_ylabel("marginal density of $y$")
    ax.set_ylim(bottom=0)
    ax.legend(frameon=False)


def figure(mu, rho: float, prior_mean, prior_cov, frames: int = 3, names=NAMES, title: str = ""):
    """The drawing of :func:`draw` for one setting, as a new figure.

    Parameters are those of :func:`depth_marginals`; ``title`` heads the axes.

    Returns
    -------
    matplotlib.figure.Figure
        Not attached to pyplot: it is shown only where it is displayed.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(WIDTH, 0.5625 * WIDTH), layout="constrained")
    ax = fig.add_subplot()
    draw(ax, depth_marginals(mu, rho, prior_mean, prior_cov, frames, names))
    if title:
        ax.set_title(title, fontsize=9)
    return fig


class Controls:
    """Sliders for ``rho``, the prior's mean and SDs and the frames, and the figure they redraw.

    Made by :func:`controls`; its ``widget`` is what a notebook displays.

    Attributes
    ----------
    mu : ndarray, shape (3,)
    names : tuple of str
    sliders : dict of ipywidgets.Widget
        ``"rho"``, ``"mean_x"``, ``"mean_y"``, ``"mean_v"``, ``"sd_x"``,
        ``"sd_y"``, ``"sd_v"``, ``"frames"``.
    figure : matplotlib.figure.Figure
    message : str
        ``""`` after a redraw, else the one-line refusal of the setting (a
        filter's :class:`ValueError`), shown in place of the densities.
    output : ipywidgets.Output
        Holds the figure as drawn last (:func:`figure_output`).
    widget : ipywidgets.VBox
        The sliders above the figure's output.
    """

    def __init__(self, widgets, mu, rho, prior_mean, prior_cov, frames, names):
        from matplotlib.figure import Figure

        self.mu = checks.finite_array(mu, "mu", (3,))
        self.names = check_names(names)
        mean = checks.finite_array(prior_mean, "prior_mean", (3,))
        sd = np.sqrt(np.diag(checks.finite_array(prior_cov, "prior_cov", (3, 3))))
        log_slider = {"base": 10, "step": 0.05, "continuous_update": False}
        self.sliders = {
            "rho": widgets.FloatLogSlider(
                value=rho, min=-4, max=-1, description=r"$\rho$", readout_format=".2e", **log_slider
            ),
        }
        for axis, m in zip("xyv", mean, strict=True):
            span = max(10.0, 3 * abs(m))
            self.sliders[f"mean_{axis}"] = widgets.FloatSlider(
                value=m,
                min=-span,
                max=span,
                step=span / 200,
                description=f"mean ${axis}$",
                continuous_update=False,
            )
        for axis, s in zip("xyv", sd, strict=True):
            self.sliders[f"sd_{axis}"] = widgets.FloatLogSlider(
                value=s,
                min=-2,
                max=3,
                description=f"SD ${axis}$",
                readout_format=".3g",
                **log_slider,
            )
        self.sliders["frames"] = widgets.IntSlider(
            value=frames,
            min=3,
            max=max(MAX_SLIDER_FRAMES, frames),
            description="frames $N$",
            continuous_update=False,
        )
        self.figure = Figure(figsize=(WIDTH, 0.5625 * WIDTH), layout="constrained")
        self.ax = self.figure.add_subplot()
        self.message = ""
        self.output = widgets.Output()
        for slider in self.sliders.values():
            slider.observe(self.redraw, names="value")
        self.widget = widgets.VBox(
            [
                widgets.HBox([self.sliders["rho"], self.sliders["frames"]]),
                widgets.HBox([self.sliders[f"mean_{axis}"] for axis in "xyv"]),
                widgets.HBox([self.sliders[f"sd_{axis}"] for axis in "xyv"]),
                self.output,
            ]
        )
        self.redraw()

    def setting(self) -> dict:
        """The sliders' values as arguments of :func:`depth_marginals`."""
        v = {key: slider.value for key, slider in self.sliders.items()}
        return {
            "mu": self.mu,
            "rho": float(v["rho"]),
            "prior_mean": np.array([v["mean_x"], v["mean_y"], v["mean_v"]], dtype=float),
            "prior_cov": np.diag([v["sd_x"] ** 2, v["sd_y"] ** 2, v["sd_v"] ** 2]),
            "frames": int(v["frames"]),
            "names": self.names,
        }

    def redraw(self, change=None) -> None:
        """Recompute the marginals for the sliders' values and redraw the figure.

        A setting a filter refuses leaves empty axes with the refusal as their title.
        """
        try:
            draw(self.ax, depth_marginals(**self.setting()))
            self.message = ""
        except ValueError as error:
            self.ax.clear()
            self.message = str(error).splitlines()[0]
            self.ax.set_title(self.message, fontsize=8, wrap=True)
        self.output.outputs = (figure_output(self.figure),)


def figure_output(figure) -> dict:
    """``figure`` as one PNG display output of a notebook (nbformat's ``display_data``).

    The controls put it in their ``ipywidgets.Output`` by setting the
    widget's state, not by displaying into it: the figure then goes wherever
    the widget is shown, and never into the outputs of the cell that made it.

    Parameters
    ----------
    figure : matplotlib.figure.Figure

    Returns
    -------
    dict
        ``{"output_type": "display_data", "data": {"image/png": base64 text,
        "text/plain": ...}, "metadata": {}}``.
    """
    import base64
    import io

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    return {
        "output_type": "display_data",
        "data": {
            "image/png": base64.b64encode(buffer.getvalue()).decode("ascii"),
            "text/plain": repr(figure),
        },
        "metadata": {},
    }


def controls(mu, rho: float, prior_mean, prior_cov, frames: int = 3, names=NAMES) -> Controls:
    """Sliders that redraw the filters' depth marginals, starting from one setting.

    Parameters are those of :func:`depth_marginals` (the covariance's
    off-diagonal terms are dropped: the sliders set the prior's SDs).
    Display ``controls(...).widget`` in Jupyter (``ipywidgets`` installed, as
    ``requirements.txt`` pins it).

    Returns
    -------
    Controls

    Raises
    ------
    ImportError
        Without ``ipywidgets``, saying how to install it.
    """
    try:
        import ipywidgets
    except ImportError as error:  # pragma: no cover - ipywidgets is pinned in requirements.txt
        raise ImportError(
            "the live controls need ipywidgets: pip install -r requirements.txt"
        ) from error
    return Controls(ipywidgets, mu, rho, prior_mean, prior_cov, frames, names)
