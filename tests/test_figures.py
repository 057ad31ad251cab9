"""Smoke tests of the figures (Agg backend) and the curves behind them."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from depthcore import figures, reproduce  # noqa: E402
from depthcore.scenarios import SCENARIOS  # noqa: E402


@pytest.mark.parametrize("key", list(SCENARIOS))
@pytest.mark.parametrize("filters", [reproduce.PAPER_FILTERS, reproduce.FILTERS])
def test_figure_draws_the_filters(key, filters):
    fig = figures.figure(key, n=101, filters=filters)
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.get_lines()] == [figures.STYLE[f]["label"] for f in filters]
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
    from depthcore import study, sweeps

    r = study.study(trials=20, seed=0, n_particles=200)
    fig = figures.calibration(r)
    assert len(fig.axes[0].get_lines()) == 1 + len(r["filters"])
    plt.close(fig)
    sw = sweeps.noise_sweep([1 / 500, 1 / 200])
    fig = figures.sweep(sw, "rho", log_x=True)
    assert len(fig.axes[0].get_lines()) == 3  # the optimal filter is the reference
    plt.close(fig)
    fig = figures.sweep(sweeps.prior_offset_sweep([0.0, 2.0]), "offset", "depth_mean")
    assert len(fig.axes[0].get_lines()) == 4
    plt.close(fig)
