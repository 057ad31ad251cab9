"""Smoke tests of the figures (Agg backend) and the curves behind them."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from numpy.testing import assert_allclose  # noqa: E402

from depthbook import (
    beyond_filters,
    beyond_linear,
    beyond_particles,
    beyond_study,
    beyond_sweeps,
    errors,
    paper,
    style,
)
from depthcore.exact import posterior, smoother
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import NAMES, PAPER_FILTERS
from depthcore.studies import reproduce

FIG2 = SCENARIOS["fig2"]


@pytest.mark.parametrize("key", list(SCENARIOS))
@pytest.mark.parametrize("filters", [PAPER_FILTERS, NAMES])
def test_figure_draws_the_filters(key, filters):
    fig = paper.figure(key, n=101, filters=filters)
    ax = fig.axes[0]
    overlay = [paper.PRINTED_STYLE["label"]] if key in paper.PRINTED_OVERLAY else []
    assert [line.get_label() for line in ax.get_lines()] == overlay + [
        style.STYLE[f]["label"] for f in filters
    ]
    # the page's caption says what the figure shows: no title in the plot
    assert ax.get_title() == "" and fig.get_suptitle() == ""
    plt.close(fig)
    # a file read apart from its caption names the figure, and no more
    fig = paper.figure(key, n=101, filters=filters, label=True)
    extended = ", extended" if len(filters) == 5 else ""
    assert fig.axes[0].get_title(loc="left") == f"Figure {SCENARIOS[key].figure}{extended}"
    plt.close(fig)


def test_figure_3_overlays_the_printed_reading_of_eq16():
    # The curve the paper's Eq. (16) gives as printed, drawn beside the faithful one.
    from depthbook import paper, style
    from depthcore.exact import optimal

    s = SCENARIOS["fig3"]
    fig = paper.figure("fig3", n=101)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    x, y = lines[paper.PRINTED_STYLE["label"]].get_data()
    printed = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading="printed")
    assert_allclose(y, printed.depth_pdf(x), rtol=1e-12)
    assert_allclose(x, np.linspace(*paper.GRIDS["fig3"], 101))
    # it differs from the faithful optimal curve drawn beside it
    _, faithful = lines[style.STYLE["optimal"]["label"]].get_data()
    assert np.max(np.abs(y - faithful)) > 0.01
    plt.close(fig)


def test_prior_velocity_sweep_and_map_figures_draw_the_data():
    sw = beyond_sweeps.prior_velocity_sweep([0.0, 0.95, 2.0])
    fig = beyond_sweeps.sweep(sw, "velocity", "depth_sd", log_y=True)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log" and len(ax.get_lines()) == 4
    ekf_line = [ln for ln in ax.get_lines() if ln.get_label() == style.STYLE["ekf"]["label"]][0]
    assert_allclose(ekf_line.get_ydata(), sw["ekf"]["depth_sd"])
    plt.close(fig)
    m = beyond_sweeps.prior_mean_map([0.0, 1.0, 2.0], [-1.0, 0.0, 0.95, 2.0])
    fig = beyond_sweeps.prior_mean_map_figure(m, {"paper": (0.0, 0.0)})
    mesh = fig.axes[0].collections[0]
    assert_allclose(np.asarray(mesh.get_array()).reshape(3, 4), m["log10_sd_ratio"])
    assert [t.get_text() for t in fig.axes[0].texts] == ["paper"]
    plt.close(fig)


def test_curves_are_densities_on_a_wide_grid():
    s = SCENARIOS["fig4"]
    grid = np.linspace(-1, 4, 1001)  # a finer grid changes no integral by 1e-7
    c = reproduce.curves(s, grid, filters=NAMES)
    for name in PAPER_FILTERS:
        assert np.trapezoid(c[name], grid) == pytest.approx(1.0, abs=1e-4)
    assert np.trapezoid(c["particle"], grid) == pytest.approx(1.0, abs=1e-3)  # kernel tails


def test_curves_reject_unknown_quantity_or_filter():
    with pytest.raises(ValueError, match="quantity must be one of"):
        reproduce.curves(SCENARIOS["fig2"], [1.0], "position")
    with pytest.raises(ValueError, match="filters must be among"):
        reproduce.curves(SCENARIOS["fig2"], [1.0], filters=("kalman",))


def test_calibration_and_sweep_figures():
    from depthbook import beyond_sweeps
    from depthcore.studies import monte_carlo

    r = monte_carlo.study(trials=20, seed=0, n_particles=200)
    fig = beyond_study.calibration(r)
    assert len(fig.axes[0].get_lines()) == 1 + len(r["filters"])
    plt.close(fig)
    sw = beyond_sweeps.noise_sweep([1 / 500, 1 / 200])
    fig = beyond_sweeps.sweep(sw, "rho", log_x=True)
    assert len(fig.axes[0].get_lines()) == 3  # the optimal filter is the reference
    plt.close(fig)
    fig = beyond_sweeps.sweep(beyond_sweeps.prior_offset_sweep([0.0, 2.0]), "offset", "depth_mean")
    assert len(fig.axes[0].get_lines()) == 4
    plt.close(fig)


def test_readings_figure_draws_both_readings():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = paper.readings_figure("fig3", n=101)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels[0].startswith("from Eq. (6) (mean 20.74")
    assert any(label.startswith("Eq. (16) as printed (mean 67.45") for label in labels)
    plt.close(fig)
    with pytest.raises(ValueError, match="y_max"):
        paper.readings_figure("fig3", y_max=1.0)


def test_ellipse_lies_at_two_mahalanobis_units():
    mean, cov = np.array([1.0, -2.0]), np.array([[2.0, 0.6], [0.6, 1.0]])
    pts = beyond_filters._ellipse(mean, cov)
    d = pts - mean
    assert_allclose(np.einsum("ni,ni->n", d, np.linalg.solve(cov, d.T).T), 4.0, rtol=1e-12)


def test_first_update_figure_draws_both_filters():
    fig = beyond_filters.first_update_figure(beyond_filters.first_update(FIG2))
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    for name in ("ekf", "ukf"):
        assert any(label.startswith(style.STYLE[name]["label"]) for label in labels)
    plt.close(fig)


def test_extended_figure_draws_every_filter_in_a_panel_per_experiment():
    from depthcore.registry.filters import NAMES
    from depthcore.studies import reproduce

    grids = {"fig2": (2.5, 10.5), "fig5": (4.5, 8.0), "fig4": (0.4, 2.2)}
    fig = beyond_filters.extended_figure(grids, {"fig5": 0.5}, n=41)
    panels = fig.axes[: len(grids)]
    assert [ax.get_title() for ax in panels] == [
        "Figure 2",
        r"Figure 5: $\rho = 1/500$",
        "Figure 4",
    ]
    for ax, key in zip(panels, grids, strict=True):
        curves = reproduce.curves(SCENARIOS[key], np.linspace(*grids[key], 41), filters=NAMES)
        lines = ax.get_lines()
        assert [line.get_label() for line in lines] == [style.STYLE[n]["label"] for n in NAMES]
        for line, name in zip(lines, NAMES, strict=True):
            assert_allclose(line.get_ydata(), curves[name], rtol=1e-12)
    assert panels[1].get_ylim() == (0.0, 0.5)
    assert panels[2].get_xlabel() == "velocity $v$"
    # the fourth cell of the grid holds the one legend, naming every filter
    spare = fig.axes[len(grids)]
    assert [t.get_text() for t in spare.get_legend().get_texts()] == [
        style.STYLE[n]["label"] for n in NAMES
    ]
    plt.close(fig)


def test_panel_label_names_what_differs_from_figure_2():
    assert beyond_filters.panel_label("fig2") == "Figure 2"
    assert beyond_filters.panel_label("fig3") == r"Figure 3: $\mu_{1:3} = (-0.25, 0, 0.2)$"
    assert beyond_filters.panel_label("fig6") == "Figure 6: prior depth $+2$"


@pytest.fixture(scope="module")
def convergence():
    return beyond_particles.particle_convergence(FIG2, [300, 600], repeats=4, seed=3)


def drawn_curves(ax):
    """The data line of each error-bar series of ``ax``, then its lines drawn alone."""
    bars = [c for c in ax.containers if c.__class__.__name__ == "ErrorbarContainer"]
    in_bars = {id(line) for c in bars for line in c.get_children()}
    return [c.lines[0] for c in bars], [x for x in ax.get_lines() if id(x) not in in_bars]


def test_convergence_figure_draws_each_setting_and_the_reference(convergence):
    fig = beyond_particles.convergence_figure(convergence)
    assert len(fig.axes) == 2
    series, alone = drawn_curves(fig.axes[0])
    assert len(series) == len(beyond_particles.SETTINGS) and len(alone) == 1
    assert fig.axes[0].get_xscale() == "log" and fig.axes[0].get_yscale() == "log"
    plt.close(fig)
    with pytest.raises(ValueError, match="quantity must be one of"):
        beyond_particles.convergence_figure(convergence, "position")


def test_profile_figure_draws_each_noise_level():
    fig = beyond_sweeps.profile_figure(FIG2.mu, [1 / 200, 1 / 50], np.geomspace(2.5, 100, 50))
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels == [r"$\rho = 1/200$", r"$\rho = 1/50$"]
    plt.close(fig)


def test_figure_1_draws_the_bearings_of_figure_2s_measurements():
    # Figure 1 draws the noise-free state c of Figure 2 at times 1-3: each ray
    # runs from the camera at the origin to (x_i, y_i), and crosses the image
    # line y = 1 at the measurement mu_i of Eq. (17), (-3/10, 0, 1/5).
    fig = paper.translating_point()
    ax = fig.axes[0]
    lines = [line.get_xydata() for line in ax.get_lines()]
    rays = [xy for xy in lines if len(xy) == 2 and np.allclose(xy[0], 0.0)]
    assert len(rays) == 3
    ends = np.array([ray[1] for ray in rays])
    assert np.allclose(ends, [[-1.2, 4.0], [0.0, 5.0], [1.2, 6.0]])
    marks = np.array([xy[0] for xy in lines if len(xy) == 1 and xy[0][1] == 1.0])
    assert np.allclose(marks[:, 0], SCENARIOS["fig2"].mu, atol=1e-12)
    assert np.allclose(marks[:, 0], [-0.3, 0.0, 0.2], atol=1e-12)
    assert ax.get_title() == ""
    plt.close(fig)


def test_figure_1_rejects_a_point_at_or_behind_the_image_line():
    with pytest.raises(ValueError, match="^x3: the point must be beyond"):
        paper.translating_point([0.0, 2.5, 0.0])
    with pytest.raises(ValueError, match="^x3: expected a state"):
        paper.translating_point([1.0, 6.0])
    with pytest.raises(ValueError, match="^n: at least 2"):
        paper.translating_point(n=1)


def _lines(ax):
    """``{label: (x, y)}`` of the lines drawn on ``ax``."""
    return {line.get_label(): (line.get_xdata(), line.get_ydata()) for line in ax.get_lines()}


def _normal_pdf(x, mean, sd):
    return np.exp(-0.5 * ((x - mean) / sd) ** 2) / (np.sqrt(2 * np.pi) * sd)


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_figure_draws_the_densities_of_each_filter(key):
    # The drawn curves, against the filters' own marginals computed here:
    # the optimal filter's quadrature density and the Gaussian ones of Eq. (13).
    from depthbook import paper, style
    from depthcore.exact import optimal
    from depthcore.kalman import ekf, second_order

    s = SCENARIOS[key]
    fig = paper.figure(key, n=201)
    lines = _lines(fig.axes[0])
    grid = np.linspace(*paper.GRIDS[key], 201)
    comp = {"depth": "y", "velocity": "v"}[s.quantity]
    m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    pdf = m.depth_pdf if s.quantity == "depth" else m.velocity_pdf
    want = {
        "optimal": pdf(grid),
        "second_order": _normal_pdf(
            grid, *second_order.run(s.mu, s.rho, s.prior.mean, s.prior.cov).marginal(comp)
        ),
        "ekf": _normal_pdf(
            grid, *ekf.run(s.mu, s.rho, s.prior.mean, s.prior.cov).posterior.marginal(comp)
        ),
    }
    for name, y in want.items():
        x_drawn, y_drawn = lines[style.STYLE[name]["label"]]
        assert_allclose(x_drawn, grid, rtol=1e-15)
        assert_allclose(y_drawn, y, rtol=1e-9, atol=1e-12 * np.max(y))
    plt.close(fig)


def test_extended_figure_draws_the_curves_of_every_filter():
    from depthcore.kalman import ukf

    s = FIG2
    fig = paper.figure("fig2", n=101, filters=NAMES)
    lines = _lines(fig.axes[0])
    grid = np.linspace(*paper.GRIDS["fig2"], 101)
    c = reproduce.curves(s, grid, filters=NAMES)
    for name in NAMES:
        assert_allclose(lines[style.STYLE[name]["label"]][1], c[name], rtol=1e-12, atol=0)
    u = ukf.run(
        s.mu, s.rho, s.prior.mean, s.prior.cov, allow_behind_camera=True
    ).posterior.marginal("y")
    u = _normal_pdf(grid, *u)
    assert_allclose(lines[style.STYLE["ukf"]["label"]][1], u, rtol=1e-9)
    # the particle filter's kernel estimate integrates to one and sits on the optimal curve
    p, o = lines[style.STYLE["particle"]["label"]][1], lines[style.STYLE["optimal"]["label"]][1]
    assert np.max(np.abs(p - o)) < 0.1 * np.max(o)
    plt.close(fig)


def test_readings_figure_draws_both_densities_and_their_means():
    from depthbook import paper
    from depthcore.exact import optimal

    s = SCENARIOS["fig3"]
    fig = paper.readings_figure("fig3", y_max=60.0, n=301)
    ax = fig.axes[0]
    y = np.linspace(2.0, 60.0, 301)[1:]
    drawn = [line for line in ax.get_lines() if len(line.get_xdata()) == len(y)]
    means = [line.get_xdata()[0] for line in ax.get_lines() if len(line.get_xdata()) == 2]
    assert len(drawn) == 2
    for line, mean, reading in zip(drawn, means, ("derived", "printed"), strict=True):
        m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading=reading)
        assert_allclose(line.get_xdata(), y, rtol=1e-15)
        assert_allclose(line.get_ydata(), m.depth_pdf(y), rtol=1e-12)
        assert mean == pytest.approx(m.depth_mean, rel=1e-12)
    # both are normalised over y > 2: below y_max they hold most of the mass, not more
    for line in drawn:
        assert 0.5 < np.trapezoid(line.get_ydata(), y) < 1.0
    plt.close(fig)


def test_first_update_figure_draws_the_ellipses_and_sigma_points():
    u = beyond_filters.first_update(FIG2)
    fig = beyond_filters.first_update_figure(u, extent=50.0)
    lines = _lines(fig.axes[0])
    x, y = lines[r"bearing of $\mu_1$: $x = \mu_1 y$"]
    assert_allclose(x, u["mu1"] * np.asarray(y), rtol=1e-15)
    assert_allclose(np.asarray(y), [-50.0, 50.0])
    X = u["sigma_points"]
    sx, sy = lines["UKF sigma points of the prior"]
    assert_allclose(np.column_stack([sx, sy]), X[:, :2], rtol=1e-15)
    for label, (mean, cov) in (
        ("prior, 2 SD", (u["prior"].mean, u["prior"].cov)),
        (f"{style.STYLE['ekf']['label']} after $\\mu_1$, 2 SD", u["ekf"]),
        (f"{style.STYLE['ukf']['label']} after $\\mu_1$, 2 SD", u["ukf"]),
    ):
        pts = np.column_stack(lines[label]) - mean[:2]
        c = cov[:2, :2]
        # every drawn point at Mahalanobis distance 2, and the whole ellipse drawn
        r2 = np.einsum("ni,ni->n", pts, np.linalg.solve(c, pts.T).T)
        assert_allclose(r2, 4.0, rtol=1e-9)
        assert np.ptp(pts[:, 0]) == pytest.approx(4 * np.sqrt(c[0, 0]), rel=1e-3)
        assert np.ptp(pts[:, 1]) == pytest.approx(4 * np.sqrt(c[1, 1]), rel=1e-3)
    plt.close(fig)


def test_convergence_figure_draws_the_errors_and_the_ideal_line(convergence):
    for quantity in ("depth", "velocity"):
        fig = beyond_particles.convergence_figure(convergence, quantity)
        N = np.asarray(convergence["sizes"])
        for ax, moment in zip(fig.axes, ("mean", "sd"), strict=True):
            series, (ideal_line,) = drawn_curves(ax)
            for line, err in zip(series, convergence["rmse"].values(), strict=True):
                assert_allclose(line.get_xdata(), N)
                assert_allclose(line.get_ydata(), err[f"{quantity}_{moment}"], rtol=1e-15)
            ideal = convergence["exact"][f"{quantity}_sd"] / np.sqrt(N)
            assert_allclose(ideal_line.get_ydata(), ideal, rtol=1e-15)
        plt.close(fig)


def test_profile_figure_draws_the_profile_likelihood():
    # exp(-f_min(y) / (2 rho^2)) against a direct minimisation of Eq. (5) over (x3, v).
    from scipy.optimize import minimize

    depths = np.array([3.0, 4.0, 5.0, 8.0, 20.0])
    rhos = [1 / 200, 1 / 50]
    fig = beyond_sweeps.profile_figure(FIG2.mu, rhos, depths)
    mu = np.asarray(FIG2.mu)
    back = np.array([2.0, 1.0, 0.0])
    for line, rho in zip(fig.axes[0].get_lines(), rhos, strict=True):
        assert_allclose(line.get_xdata(), depths)
        for y3, drawn in zip(depths, line.get_ydata(), strict=True):

            def f(p, y3=y3):
                return np.sum((mu - (p[0] - back * p[1]) / (y3 - back)) ** 2)

            best = minimize(
                f, [0.0, 0.0], method="Nelder-Mead", options={"xatol": 1e-12, "fatol": 1e-16}
            )
            assert drawn == pytest.approx(np.exp(-best.fun / (2 * rho**2)), rel=1e-6, abs=1e-12)
    plt.close(fig)


def test_calibration_and_sweep_figures_draw_their_results():
    from depthbook import beyond_sweeps, style
    from depthcore.studies import monte_carlo

    r = monte_carlo.study(trials=20, seed=0, names=("optimal", "ekf"))
    for quantity in ("depth", "velocity"):
        fig = beyond_study.calibration(r, quantity)
        lines = fig.axes[0].get_lines()
        assert_allclose(lines[0].get_xydata(), [[0, 0], [1, 1]])
        for line, f in zip(lines[1:], r["filters"].values(), strict=True):
            assert_allclose(line.get_xdata(), f["calibration"]["levels"])
            assert_allclose(line.get_ydata(), f["calibration"][quantity])
        plt.close(fig)
    sw = beyond_sweeps.prior_offset_sweep([0.0, 1.0, 2.0])
    for field in ("hellinger", "depth_mean", "depth_sd"):
        fig = beyond_sweeps.sweep(sw, "offset", field)
        drawn = {line.get_label(): line for line in fig.axes[0].get_lines()}
        names = [n for n in NAMES if n in sw]
        if field == "hellinger":
            names.remove("optimal")
        assert len(drawn) == len(names)
        for name in names:
            line = drawn[style.STYLE[name]["label"]]
            assert_allclose(line.get_xdata(), sw["offset"])
            assert_allclose(line.get_ydata(), sw[name][field])
        plt.close(fig)


def test_noise_study_figure_draws_coverage_and_rmse():
    r = beyond_sweeps.noise_study([1 / 400, 1 / 100], trials=20, seed=1, names=("optimal", "ekf"))
    fig = beyond_sweeps.noise_study_figure(r)
    for ax, field in zip(fig.axes, ("coverage_68", "rmse"), strict=True):
        drawn = {bar.get_label(): bar for bar in ax.containers}
        for name in ("optimal", "ekf"):
            bar = drawn[style.STYLE[name]["label"]]
            line, _, (segments,) = bar.lines
            assert_allclose(line.get_xdata(), r["rho"])
            assert_allclose(line.get_ydata(), r[name][field])
            # each point's bar spans two standard errors either side
            ends = np.array(segments.get_segments())[:, :, 1]
            assert_allclose(ends[:, 0], r[name][field] - 2 * r[name][f"{field}_se"])
            assert_allclose(ends[:, 1], r[name][field] + 2 * r[name][f"{field}_se"])
    plt.close(fig)


# --- the bank of Kalman filters, its smoothers, and the RBPF ----------------------------


@pytest.fixture(scope="module")
def fig2_track():
    from depthcore.problem import model

    sim = model.simulate(model.G(FIG2.c, -2), 6, FIG2.rho, 0.01, np.random.default_rng(2), frame=1)
    tr = smoother.track(sim.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, 0.01, lag=1)
    return sim, tr


def test_bank_depth_figure_draws_one_curve_per_frame(fig2_track):
    from depthbook import beyond_linear

    sim, tr = fig2_track
    frames = [3, 4, 6]
    d = {k: posterior.node_density(tr.posteriors[k - 1]) for k in frames}
    fig = beyond_linear.bank_depth_figure(d, {k: sim.states[k - 1, 1] for k in frames})
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert [lab for lab in labels if lab.startswith("after")] == [
        f"after frame {k}" for k in frames
    ]
    assert len(fig.axes[1].get_lines()) == len(frames) + 1  # a curve per frame and the zero
    plt.close(fig)
    with pytest.raises(ValueError, match="densities must hold at least one frame"):
        beyond_linear.bank_depth_figure({})


def test_smoothing_figure_draws_the_three_estimates_minus_the_truth(fig2_track):
    sim, tr = fig2_track
    fig = beyond_linear.smoothing_figure(tr, sim.states, first=2)
    for ax, i in zip(fig.axes, (1, 0), strict=True):
        lines = ax.get_lines()[:3]
        assert [line.get_label() for line in lines][0] == "filtered"
        assert_allclose(lines[2].get_ydata(), tr.interval.mean[1:, i] - sim.states[1:, i])
    plt.close(fig)
    with pytest.raises(ValueError, match="first must be a frame from 1 to 6"):
        beyond_linear.smoothing_figure(tr, sim.states, first=7)


def test_rbpf_convergence_figure_draws_the_errors(fig2_track):
    sim, _ = fig2_track
    r = beyond_linear.rbpf_convergence(
        sim.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, [10, 40], 3, seed=1, process_noise=0.01
    )
    fig = beyond_linear.rbpf_convergence_figure(r)
    first = fig.axes[0].get_lines()[0]
    assert_allclose(first.get_ydata(), r["rmse"]["depth_mean"])
    assert_allclose(first.get_xdata(), [10, 40])
    # each RMS error with bars of two standard errors over the clouds, from their runs
    bars = [c for c in fig.axes[0].containers if c.__class__.__name__ == "ErrorbarContainer"]
    for container, moment in zip(bars, ("depth_mean", "depth_sd"), strict=True):
        y, low, high = _bars(container)
        _, se = errors.rms_se(r["runs"][moment] - r["exact"][moment], axis=1)
        assert_allclose(y, r["rmse"][moment])
        assert_allclose(high - y, 2 * se)
        assert_allclose(y - low, np.minimum(2 * se, 0.9 * y))
    plt.close(fig)


def _bars(container):
    """The data line's values and the lower and upper ends of an errorbar container's bars."""
    line, _, (segments,) = container.lines
    ends = np.array(segments.get_segments())[:, :, 1]
    return np.asarray(line.get_ydata(), float), ends[:, 0], ends[:, 1]


def test_truth_study_figure_draws_each_score_with_two_standard_errors():
    truths = np.vstack([FIG2.c, [-1.0, 4.0, 1.0]])
    r = beyond_study.truth_study(truths, FIG2.rho, trials=20, seed=2, names=("optimal", "ekf"))
    fig = beyond_study.truth_study_figure(r, ["a", "b"])
    fig.canvas.draw()
    for ax, (score, *_) in zip(fig.axes, beyond_study.TRUTH_PANELS, strict=True):
        drawn = {c.get_label(): c for c in ax.containers}
        for name in ("optimal", "ekf"):
            y, lo, hi = _bars(drawn[style.STYLE[name]["label"]])
            assert_allclose(y, r[name][score])
            assert_allclose(lo, r[name][score] - 2 * r[name][f"{score}_se"])
            assert_allclose(hi, r[name][score] + 2 * r[name][f"{score}_se"])
    for ax in fig.axes[2:]:  # the truths' labels under the lower panels
        assert [t.get_text() for t in ax.get_xticklabels()] == ["a", "b"]
    plt.close(fig)


def test_calibration_notes_point_at_the_curve():
    from depthcore.studies import monte_carlo

    r = monte_carlo.study(trials=20, seed=0, names=("optimal", "ekf"))
    fig = beyond_study.calibration(r, notes={"ekf": "a note"})
    (note,) = fig.axes[0].texts
    cal = r["filters"]["ekf"]["calibration"]
    j = int(np.argmin(np.abs(np.asarray(cal["levels"]) - beyond_study.NOTE_LEVEL)))
    assert note.get_text() == "a note"
    assert_allclose(note.xy, (cal["levels"][j], cal["depth"][j]))
    plt.close(fig)


def test_frames_study_figure_draws_each_score_with_two_standard_errors():
    from depthbook import beyond_frames
    from depthbook.studies import frames

    r = frames.frames_study([3, 5], 10, 1, ("optimal", "ekf"))
    fig = beyond_frames.frames_study_figure(r)
    for ax, (score, *_) in zip(fig.axes, beyond_frames.FRAMES_ROWS, strict=True):
        drawn = {c.get_label(): c for c in ax.containers}
        names = ["ekf"] if score == "hellinger" else ["optimal", "ekf"]
        assert len(drawn) == len(names)
        for name in names:
            y, lo, hi = _bars(drawn[style.STYLE[name]["label"]])
            assert_allclose(y, r[name][score])
            assert_allclose(hi - lo, 4 * r[name][f"{score}_se"], atol=1e-12)
    plt.close(fig)


def test_frame_marginals_grids_hold_each_filter_and_the_exact_marginal():
    # Each filter's grid spans its own mean +- 6 SDs and the exact one's, and on it
    # both densities hold nearly all their mass, however far apart they are.
    from depthbook import beyond_frames
    from depthcore.problem import model

    sim = model.simulate(FIG2.c, 10, FIG2.rho, 0.0, np.random.default_rng(3))
    (p,) = beyond_frames.frame_marginals(sim.mu, FIG2.rho, [10], ("ekf", "ukf"), n_points=401)
    for name in ("optimal", "ekf", "ukf"):
        grid = p["grid"][name]
        assert np.all(np.diff(grid) > 0)
        for k in ("optimal", name):
            m, s = p["depth_mean"][k], p["depth_sd"][k]
            assert grid[0] <= max(m - 6 * s, 1e-9) + 1e-9 and grid[-1] >= m + 6 * s - 1e-9
        assert 0.99 < np.trapezoid(p["exact"][name], grid) < 1.01
        if name != "ukf":  # the UKF's grid is cut at depth 0, within its SD of the mean
            assert 0.99 < np.trapezoid(p["density"][name], grid) < 1.01
    fig = beyond_frames.frame_marginals_figure([p], ["ekf", "ukf"])
    plt.close(fig)


def _per_frame_run():
    from depthbook.studies import per_frame

    return per_frame.per_frame_study(6, 50, 1, ("optimal", "ekf"), process_noise=0.02)


def _band_widths(ax, x):
    """The height of each band ``fill_between`` drew at each ``x``, in order."""
    out = []
    for poly in ax.collections:
        v = poly.get_paths()[0].vertices
        out.append(np.array([np.ptp(v[np.isclose(v[:, 0], xi), 1]) for xi in x]))
    return out


def test_frame_bound_figure_draws_the_rmse_over_the_bound_with_two_standard_errors():
    from depthbook import beyond_bound

    r = _per_frame_run()
    fig = beyond_bound.frame_bound_figure([("a", r)], zoom=(0.5, 5.0))
    b = r["bound"]["depth"]
    zoomed = fig.axes[1]
    lines = {line.get_label(): line for line in zoomed.get_lines()}
    widths = _band_widths(zoomed, r["frames"])
    for name, width in zip(("optimal", "ekf"), widths, strict=True):
        d = r["filters"][name]["depth"]
        assert_allclose(lines[style.STYLE[name]["label"]].get_ydata(), d["rmse"] / b)
        assert_allclose(width, 4 * d["rmse_se"] / b, rtol=1e-9)
    assert zoomed.get_ylim() == (0.5, 5.0)
    plt.close(fig)


def test_nees_frames_figure_shades_the_anees_region_of_each_filter():
    from depthbook import beyond_frames

    r = _per_frame_run()
    fig = beyond_frames.nees_frames_figure([("a", r)])
    (ax,) = fig.axes
    lines = {line.get_label(): line for line in ax.get_lines()}
    for name in ("optimal", "ekf"):
        assert_allclose(lines[style.STYLE[name]["label"]].get_ydata(), r["filters"][name]["nees"])
    lo, hi = r["filters"]["ekf"]["anees_region"]
    spans = [p for p in ax.patches if p.get_height() > 0]
    assert any(
        np.isclose(p.get_y(), lo) and np.isclose(p.get_y() + p.get_height(), hi) for p in spans
    )
    plt.close(fig)


def test_track_loss_figure_draws_each_threshold_and_the_rmse_over_the_tracks_kept():
    from depthbook import beyond_frames

    r = _per_frame_run()
    fig = beyond_frames.track_loss_figure(r)
    axes = np.reshape(fig.axes, (2, len(r["levels"])))
    for i in range(len(r["levels"])):
        lines = {line.get_label(): line for line in axes[0, i].get_lines()}
        kept = {line.get_label(): line for line in axes[1, i].get_lines()}
        for name in ("optimal", "ekf"):
            loss = r["filters"][name]["track_loss"]
            label = style.STYLE[name]["label"]
            assert_allclose(lines[label].get_ydata(), loss["fraction"][i])
            assert_allclose(kept[label].get_ydata(), loss["depth"]["rmse_kept"][i])
    plt.close(fig)


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_the_articles_figures_print_at_their_size_titled_by_their_scenario(key):
    fig = paper.print_figure(key, n=101)
    ax = fig.axes[0]
    wide = key in paper.PRINT_WIDE
    assert fig.get_size_inches()[0] == pytest.approx(paper.PRINT_WIDTH * (2 if wide else 1))
    # every text prints at 7 pt or more: drawn at the size the article prints it
    texts = [t for t in ax.get_children() if isinstance(t, matplotlib.text.Text)]
    texts += [ax.xaxis.label, ax.yaxis.label, *ax.get_legend().get_texts()]
    texts += ax.get_xticklabels() + ax.get_yticklabels()
    assert min(t.get_fontsize() for t in texts if t.get_text()) >= 7
    title = ax.get_title(loc="left")
    assert "Figure" not in title and f"1/{1 / SCENARIOS[key].rho:.0f}" in title
    assert title.startswith(SCENARIOS[key].quantity)
    if wide:  # Figure 3 reaches far enough to show Eq. (16) as printed, mean past 60
        assert ax.get_xscale() == "log" and ax.get_xlim()[1] >= 150
    plt.close(fig)


def test_the_articles_figures_are_written_as_it_names_them(tmp_path):
    paths = paper.save_print(tmp_path)
    assert [p.name for p in paths] == [f"print-figure{s.figure}.pdf" for s in SCENARIOS.values()]
    assert all(p.read_bytes().startswith(b"%PDF") for p in paths)


def test_log_bars_are_two_standard_errors_the_lower_short_of_zero():
    from depthbook.style import log_bars

    bars = log_bars([1.0, 0.1], [0.01, 0.2])
    assert_allclose(bars, [[0.02, 0.09], [0.02, 0.4]], rtol=1e-15)
