"""Smoke tests of the figures (Agg backend) and the curves behind them."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from numpy.testing import assert_allclose  # noqa: E402

from depthcore import experiments, figures, reproduce  # noqa: E402
from depthcore.scenarios import SCENARIOS  # noqa: E402

FIG2 = SCENARIOS["fig2"]


@pytest.mark.parametrize("key", list(SCENARIOS))
@pytest.mark.parametrize("filters", [reproduce.PAPER_FILTERS, reproduce.FILTERS])
def test_figure_draws_the_filters(key, filters):
    fig = figures.figure(key, n=101, filters=filters)
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.get_lines()] == [
        figures.STYLE[f]["label"] for f in filters
    ]
    assert f"Figure {SCENARIOS[key].figure}" in ax.get_title()
    assert ("extended" in ax.get_title()) == (len(filters) == 5)
    plt.close(fig)


def test_curves_are_densities_on_a_wide_grid():
    s = SCENARIOS["fig4"]
    grid = np.linspace(-1, 4, 4001)
    c = reproduce.curves(s, grid, filters=reproduce.FILTERS)
    for name in reproduce.PAPER_FILTERS:
        assert np.trapezoid(c[name], grid) == pytest.approx(1.0, abs=1e-4)
    assert np.trapezoid(c["particle"], grid) == pytest.approx(1.0, abs=1e-3)  # kernel tails


def test_curves_reject_unknown_quantity_or_filter():
    with pytest.raises(ValueError, match="quantity must be one of"):
        reproduce.curves(SCENARIOS["fig2"], [1.0], "position")
    with pytest.raises(ValueError, match="filters must be among"):
        reproduce.curves(SCENARIOS["fig2"], [1.0], filters=("kalman",))


def test_calibration_and_sweep_figures():
    from depthcore import experiments, study

    r = study.study(trials=20, seed=0, n_particles=200)
    fig = figures.calibration(r)
    assert len(fig.axes[0].get_lines()) == 1 + len(r["filters"])
    plt.close(fig)
    sw = experiments.noise_sweep([1 / 500, 1 / 200])
    fig = figures.sweep(sw, "rho", log_x=True)
    assert len(fig.axes[0].get_lines()) == 3  # the optimal filter is the reference
    plt.close(fig)
    fig = figures.sweep(experiments.prior_offset_sweep([0.0, 2.0]), "offset", "depth_mean")
    assert len(fig.axes[0].get_lines()) == 4
    plt.close(fig)


def test_readings_figure_draws_both_readings():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = figures.readings_figure("fig3", n=101)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels[0].startswith("from Eq. (6) (mean 20.74")
    assert any(label.startswith("Eq. (16) as printed (mean 67.45") for label in labels)
    plt.close(fig)
    with pytest.raises(ValueError, match="y_max"):
        figures.readings_figure("fig3", y_max=1.0)


def test_ellipse_lies_at_two_mahalanobis_units():
    mean, cov = np.array([1.0, -2.0]), np.array([[2.0, 0.6], [0.6, 1.0]])
    pts = figures._ellipse(mean, cov)
    d = pts - mean
    assert_allclose(np.einsum("ni,ni->n", d, np.linalg.solve(cov, d.T).T), 4.0, rtol=1e-12)


def test_first_update_figure_draws_both_filters():
    fig = figures.first_update_figure(experiments.first_update(FIG2))
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    for name in ("ekf", "ukf"):
        assert any(label.startswith(figures.STYLE[name]["label"]) for label in labels)
    plt.close(fig)


@pytest.fixture(scope="module")
def convergence():
    return experiments.particle_convergence(FIG2, [300, 600], repeats=4, seed=3)


def test_convergence_figure_draws_each_setting_and_the_reference(convergence):
    fig = figures.convergence_figure(convergence)
    assert len(fig.axes) == 2
    assert len(fig.axes[0].get_lines()) == len(experiments.SETTINGS) + 1
    assert fig.axes[0].get_xscale() == "log" and fig.axes[0].get_yscale() == "log"
    plt.close(fig)
    with pytest.raises(ValueError, match="quantity must be one of"):
        figures.convergence_figure(convergence, "position")


def test_profile_figure_draws_each_noise_level():
    fig = figures.profile_figure(FIG2.mu, [1 / 200, 1 / 50], np.geomspace(2.5, 100, 50))
    assert [line.get_label() for line in fig.axes[0].get_lines()] == ["rho = 1/200", "rho = 1/50"]
    plt.close(fig)


def test_figure_1_draws_the_bearings_of_figure_2s_measurements():
    # Figure 1 draws the noise-free state c of Figure 2 at times 1-3: each ray
    # runs from the camera at the origin to (x_i, y_i), and crosses the image
    # line y = 1 at the measurement mu_i of Eq. (17), (-3/10, 0, 1/5).
    fig = figures.translating_point()
    ax = fig.axes[0]
    lines = [line.get_xydata() for line in ax.get_lines()]
    rays = [xy for xy in lines if len(xy) == 2 and np.allclose(xy[0], 0.0)]
    assert len(rays) == 3
    ends = np.array([ray[1] for ray in rays])
    assert np.allclose(ends, [[-1.2, 4.0], [0.0, 5.0], [1.2, 6.0]])
    marks = np.array([xy[0] for xy in lines if len(xy) == 1 and xy[0][1] == 1.0])
    assert np.allclose(marks[:, 0], SCENARIOS["fig2"].mu, atol=1e-12)
    assert np.allclose(marks[:, 0], [-0.3, 0.0, 0.2], atol=1e-12)
    assert "Figure 1" in ax.get_title()
    plt.close(fig)


def test_figure_1_rejects_a_point_at_or_behind_the_image_line():
    with pytest.raises(ValueError, match="^x3: the point must be beyond"):
        figures.translating_point([0.0, 2.5, 0.0])
    with pytest.raises(ValueError, match="^x3: expected a state"):
        figures.translating_point([1.0, 6.0])
    with pytest.raises(ValueError, match="^n: at least 2"):
        figures.translating_point(n=1)
