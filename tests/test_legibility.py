"""Every figure the book shows is legible at the book's width, on screen and on paper.

For each plotting function of the book's wing (:mod:`depthbook`) that a page
calls, drawn here on small inputs of the same shape: the figure's size in
inches as the book saves it (``bbox_inches="tight"``, as Jupyter and the book
render it), its resolution, and the smallest font of any text it draws
(titles, labels, tick labels, legends, annotations). Each page shows its
figures at the full width of the text (``:width: 100%``), so a text of ``s``
points in a figure ``w`` inches wide is ``s / 72 * W / w`` CSS pixels high at a
content width of ``W`` pixels, and ``s * T / w`` points on a page whose text is
``T`` inches wide.

:data:`CONTENT_WIDTH_PX` is the width at which the sphinx-book-theme layout
shows a figure at a window 1280 CSS pixels wide (its text column, 676 pixels,
less the figure's margins), measured in headless Chromium on a built page; a
wider window, or a narrower one that hides the side bars, shows figures wider
(``tests/book/test_browser.py`` checks it again on the built book).
:data:`TEXT_WIDTH_IN` is the text width of the PDF's A4 pages (Sphinx's LaTeX
default margins of one inch).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.text import Text  # noqa: E402

from depthbook import (
    beyond_atlas,
    beyond_bound,
    beyond_conjecture,
    beyond_filters,
    beyond_frames,
    beyond_hard,
    beyond_linear,
    beyond_particles,
    beyond_stonesoup,
    beyond_study,
    beyond_sweeps,
    beyond_tracks,
    intuition,
    paper,
    style,
)
from depthbook.studies import frames, hardness, per_frame
from depthcore.analysis import bound
from depthcore.exact import posterior, smoother
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry import online
from depthcore.studies import atlas, monte_carlo

#: Width in CSS pixels at which the book shows a figure at a 1280-pixel window.
CONTENT_WIDTH_PX = 660.0
#: Text width in inches of the PDF's A4 pages (8.27 in less two 1-inch margins).
TEXT_WIDTH_IN = 8.27 - 2.0
#: The smallest text on screen, in CSS pixels, and on paper, in points.
MIN_PX = 9.0
MIN_PRINT_PT = 7.0
#: The least resolution of the PNG images (dots per inch).
MIN_DPI = 150
#: The padding matplotlib adds around a tight bounding box (inches).
PAD_IN = 0.1

FIG2 = SCENARIOS["fig2"]


def measure(fig) -> dict:
    """Width (inches, as saved tight), dpi and smallest font (points) of a figure's texts."""
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    width = fig.get_tightbbox(renderer).width + 2 * PAD_IN
    sizes = [
        t.get_fontsize()
        for t in fig.findobj(Text)
        if t.get_visible() and t.get_text().strip() and t.get_window_extent(renderer).width > 0
    ]
    return {"width_in": width, "dpi": fig.dpi, "min_pt": min(sizes)}


def on_screen_px(m: dict) -> float:
    """The smallest text in CSS pixels, the figure shown at the content width."""
    return m["min_pt"] / 72.0 * CONTENT_WIDTH_PX / m["width_in"]


def on_paper_pt(m: dict) -> float:
    """The smallest text in points, the figure printed at the PDF's text width."""
    return m["min_pt"] * TEXT_WIDTH_IN / m["width_in"]


#: The filters of the book's studies of more frames.
FRAMES_NAMES = ("second_order", "ekf", "inverse_depth", "iterated", "ukf", "particle", "rbpf")


def _frames_run():
    return frames.frames_study(
        [3, 5, 10], 12, 5, FRAMES_NAMES, "paper", particle_trials=4, n_particles=100
    )


def _track():
    sim = model.simulate(FIG2.c, 6, FIG2.rho, 0.01, np.random.default_rng(2), frame=3)
    tr = smoother.track(sim.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, 0.01, lag=1)
    return sim, tr


def _bank_depth():
    sim, tr = _track()
    shown = (3, 4, 6)
    densities = {k: posterior.node_density(tr.posteriors[k - 1]) for k in shown}
    return beyond_linear.bank_depth_figure(densities, {k: sim.states[k - 1, 1] for k in shown})


def _smoothing():
    sim, tr = _track()
    return beyond_linear.smoothing_figure(tr, sim.states, first=2)


def _rbpf_convergence():
    sim, _ = _track()
    r = beyond_linear.rbpf_convergence(
        sim.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, [10, 40], 3, seed=1, process_noise=0.01
    )
    return beyond_linear.rbpf_convergence_figure(r)


def _track_figure():
    track = beyond_tracks.demo_track(5, frames=12, n_missing=2, outlier=9)
    x1 = track.states[0]
    prior_mean = np.array([x1[0], 1.3 * x1[1], 0.0])
    prior_cov = np.diag([1.0, (0.3 * x1[1]) ** 2, 1.0])
    runs = {
        (name, gated): beyond_tracks.filtered(
            name, track, prior_mean, prior_cov, gate=1e-3 if gated else None
        )
        for name in ("optimal", "ekf")
        for gated in (False, True)
    }
    return beyond_tracks.track_figure(track, runs, 1e-3)


def _offset_figure():
    sim = model.simulate(FIG2.c, 8, FIG2.rho, 0.0, np.random.default_rng(3))
    runs = {}
    for name in ("optimal", "ekf"):
        f = online.start(name, FIG2.prior.mean, FIG2.prior.cov, rho=FIG2.rho)
        est = [f.update(m) for m in sim.mu]
        runs[name] = (np.array([e.mean for e in est]), np.array([e.cov for e in est]))
    return beyond_stonesoup.offset_figure(runs, sim.states[:, 1], [5])


def _frame_marginals():
    sim = model.simulate(FIG2.c, 6, FIG2.rho, 0.0, np.random.default_rng(3))
    names = FRAMES_NAMES[:5] + ("particle", "resample_move", "rbpf")
    m = beyond_frames.frame_marginals(
        sim.mu,
        FIG2.rho,
        [3, 4, 5, 6],
        names,
        rng=np.random.default_rng(4),
        n_particles=200,
        n_points=101,
    )
    return beyond_frames.frame_marginals_figure(m, names)


#: One builder per plotting function the book calls, on small inputs of the book's shape.
def _bound_figure():
    # every filter the page draws, so that the legend is the page's
    ns = np.array([3, 5, 10])
    names = ("optimal", "second_order", "ekf", "inverse_depth", "iterated", "ukf")
    names += ("particle", "rbpf", "resample_move")
    r = beyond_bound.bound_study(ns, 6, 1, names, "paper", particle_trials=4, n_particles=20)
    b = np.sqrt(bound.posterior_bound(FIG2.c, 3, 10, FIG2.rho, 1000.0 * np.eye(3))[ns - 1, 1, 1])
    against = {n: bound.against_bound(r[n]["depth_error"], r[n]["depth_sd"], b) for n in names}
    return beyond_bound.bound_figure(ns, [("$q = 0$", against), ("$q = 0.02$", against)])


def _per_frame_runs():
    names = ("optimal", "second_order", "ekf", "inverse_depth", "iterated", "ukf")
    return [
        (label, per_frame.per_frame_study(8, 50, 1, names, process_noise=q))
        for label, q in (("$q = 0$", 0.0), ("$q = 0.02$", 0.02))
    ]


BUILDERS = {
    "figure": lambda: paper.figure("fig3", n=101),
    "extended_figure": lambda: beyond_filters.extended_figure(paper.GRIDS, paper.YLIM, n=101),
    "translating_point": lambda: paper.translating_point(),
    "bearings_figure": lambda: intuition.bearings_figure(FIG2.mu, [4.0, 6.0, 9.0], 6.0),
    "readings_figure": lambda: paper.readings_figure("fig3", n=201),
    "first_update_figure": lambda: beyond_filters.first_update_figure(
        beyond_filters.first_update(FIG2)
    ),
    "convergence_figure": lambda: beyond_particles.convergence_figure(
        beyond_particles.particle_convergence(FIG2, [100, 200], repeats=2, seed=3)
    ),
    "calibration": lambda: beyond_study.calibration(
        monte_carlo.study(trials=20, seed=0, n_particles=100)
    ),
    "calibration, with notes": lambda: beyond_study.calibration(
        monte_carlo.study(trials=20, seed=0, n_particles=100),
        notes={"optimal": "optimal: a note\nof two lines", "ekf": "EKF: a note"},
    ),
    "truth_study_figure": lambda: beyond_study.truth_study_figure(
        beyond_study.truth_study(
            np.vstack([FIG2.c, [-1.0, 4.0, 1.0]]), FIG2.rho, trials=20, seed=2
        ),
        ["(1.2, 6, 1.2)\nFigure 2", "(-1, 4, 1)\nnear"],
    ),
    "prior_calibration": lambda: beyond_study.prior_calibration(
        monte_carlo.prior_study(trials=40, seed=1)
    ),
    "sweep": lambda: beyond_sweeps.sweep(
        beyond_sweeps.noise_sweep([1 / 500, 1 / 200]), "rho", "hellinger", log_x=True
    ),
    "profile_figure": lambda: beyond_sweeps.profile_figure(
        FIG2.mu, [1 / 200, 1 / 50], np.geomspace(2.5, 100, 50)
    ),
    "noise_study_figure": lambda: beyond_sweeps.noise_study_figure(
        beyond_sweeps.noise_study([1 / 400, 1 / 100], trials=10, seed=1)
    ),
    "prior_mean_map_figure": lambda: beyond_sweeps.prior_mean_map_figure(
        beyond_sweeps.prior_mean_map([0.0, 2.0], [0.0, 1.0]), {"paper": (0.0, 0.0)}
    ),
    "bank_depth_figure": _bank_depth,
    "smoothing_figure": _smoothing,
    "rbpf_convergence_figure": _rbpf_convergence,
    "frame_marginals_figure": _frame_marginals,
    "track_figure": _track_figure,
    "offset_figure": _offset_figure,
    "frames_study_figure": lambda: beyond_frames.frames_study_figure(_frames_run()),
    "hard_figure": lambda: beyond_hard.hard_figure(
        hardness.hard_study(
            [(FIG2.c, s, 0.0) for s in np.geomspace(1.0, 1000.0, 11)], FIG2.rho, 8, 1
        ),
        ["$v = 0$", "$v = 0.2$", "$v = 0.6$", "$\\mathbf{c}$", "$v = 2.4$", "$s = 1$"]
        + ["$s = 10$", "$s = 100$", "$v_0 = 1.2$", "$y = 24$", "$v = 0$\n$s = 1$"],
    ),
    "bound_figure": _bound_figure,
    "frame_bound_figure": lambda: beyond_bound.frame_bound_figure(
        _per_frame_runs(), zoom=(0.9, 2.7)
    ),
    "nees_frames_figure": lambda: beyond_frames.nees_frames_figure(
        _per_frame_runs(), zoom=(1.5, 5.0)
    ),
    "track_loss_figure": lambda: beyond_frames.track_loss_figure(_per_frame_runs()[0][1]),
    "verdict_map": lambda: beyond_atlas.verdict_map(
        atlas.atlas(
            atlas.Grid(
                (0.0, 0.2, 0.4),
                (4.0, 12.0),
                (1.0, 1000.0),
                (atlas.PIXEL, atlas.PIXEL / 10),
                (3, 10, 30),
                ("paper",),
                6,
                20,
                6,
                ("optimal", "ekf", "ukf"),
            ),
            seed=1,
        ),
        "calibrated",
    ),
    "conjecture_figure": lambda: beyond_conjecture.conjecture_figure(
        beyond_conjecture.conjecture_study(
            [3, 10, 30], 1 / np.array([1000, 500, 200, 100, 50]), [4.0, 6.0, 12.0, 24.0], 4, 2
        )
    ),
}


@pytest.fixture(scope="module", params=sorted(BUILDERS))
def drawn(request):
    fig = BUILDERS[request.param]()
    yield request.param, measure(fig)
    plt.close(fig)


def test_every_text_is_legible_at_the_books_width(drawn):
    name, m = drawn
    px = on_screen_px(m)
    assert px >= MIN_PX, f"{name}: smallest text {px:.1f} px at {CONTENT_WIDTH_PX:g} px ({m})"


def test_every_text_is_legible_on_paper(drawn):
    name, m = drawn
    pt = on_paper_pt(m)
    assert pt >= MIN_PRINT_PT, f"{name}: smallest text {pt:.1f} pt on an A4 page ({m})"


def test_every_figure_is_rendered_at_150_dpi_or_more(drawn):
    name, m = drawn
    assert m["dpi"] >= MIN_DPI, name


def test_the_measure_sees_small_text_and_wide_figures():
    # A figure 14 inches wide with 7-point tick labels at 100 dpi, as the book once
    # drew: its width as measured is the width of the PNG that Jupyter saves, and
    # the checks above refuse its text, under 5 px at the content width.
    import io

    from matplotlib.image import imread

    fig, ax = plt.subplots(figsize=(14.0, 4.0), dpi=100, layout="constrained")
    ax.plot([0, 1], [0, 1])
    ax.tick_params(labelsize=7)
    m = measure(fig)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=fig.dpi, bbox_inches="tight")
    plt.close(fig)
    png.seek(0)
    assert imread(png).shape[1] == pytest.approx(m["width_in"] * m["dpi"], abs=2)
    assert m["min_pt"] == 7 and m["dpi"] == 100
    assert on_screen_px(m) < 5.0 and on_paper_pt(m) < MIN_PRINT_PT


def test_figures_refuse_a_width_beyond_the_books():
    with pytest.raises(ValueError, match="figsize: at most"):
        style.subplots(figsize=(style.WIDTH + 1.0, 3.0))
