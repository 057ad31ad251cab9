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
