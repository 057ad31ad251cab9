"""The conjecture chapter's figure and its reading of far-off trials."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from depthbook import beyond_conjecture  # noqa: E402
from depthcore.analysis import bound  # noqa: E402


@pytest.mark.parametrize("k", [1, 3])
def test_dominant_trials_counts_the_trials_that_carry_the_squared_error(k):
    # k far-off trials among small errors: the RMSE and its delta-method SE, computed by
    # the route the studies use (analysis.bound.against_bound), give k back
    rng = np.random.default_rng(1)
    e = rng.normal(0.0, 1e-3, 200)
    e[:k] = 1e3
    a = bound.against_bound(e, np.ones_like(e), 1.0)
    assert beyond_conjecture.dominant_trials(a["rmse"], a["rmse_se"]) == pytest.approx(k, rel=0.02)
    # errors spread evenly: far more than a few
    even = bound.against_bound(rng.normal(0.0, 1.0, 200), np.ones(200), 1.0)
    assert beyond_conjecture.dominant_trials(even["rmse"], even["rmse_se"]) > 50
    assert beyond_conjecture.dominant_trials(1.0, 0.0) == np.inf


def test_conjecture_figure_draws_every_score_with_its_error_bars():
    result = beyond_conjecture.conjecture_study([3], [1 / 200, 1 / 100], [6.0], 6, 1)
    fig = beyond_conjecture.conjecture_figure(result)
    try:
        assert len(fig.axes) == 3
        for ax in fig.axes:
            # one error bar per filter and depth, its half-widths twice the score's SE
            assert len(ax.containers) == 2
            assert ax.get_title() in ("$N = 3$", "")
        rmse_ax = fig.axes[2]
        bars = rmse_ax.containers[0].lines[2][0].get_segments()
        se = result["second_order"]["rmse_se"][:, 0, 0]
        tops = np.array([seg[1][1] for seg in bars])
        assert tops == pytest.approx(result["second_order"]["rmse"][:, 0, 0] + 2 * se)
    finally:
        plt.close(fig)
