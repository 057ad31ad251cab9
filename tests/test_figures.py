"""Smoke tests of the figures (Agg backend) and the curves behind them."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from depthcore import figures, reproduce  # noqa: E402
from depthcore.scenarios import SCENARIOS  # noqa: E402


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_figure_draws_three_filters(key):
    fig = figures.figure(key, n=101)
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.get_lines()] == [
        figures.STYLE[f]["label"] for f in reproduce.FILTERS]
    assert f"Figure {SCENARIOS[key].figure}" in ax.get_title()
    plt.close(fig)


def test_curves_are_densities_on_a_wide_grid():
    s = SCENARIOS["fig4"]
    grid = np.linspace(-1, 4, 4001)
    c = reproduce.curves(s, grid)
    for name in reproduce.FILTERS:
        assert np.trapezoid(c[name], grid) == pytest.approx(1.0, abs=1e-4)


def test_curves_reject_unknown_quantity():
    with pytest.raises(ValueError, match="quantity must be one of"):
        reproduce.curves(SCENARIOS["fig2"], [1.0], "position")
