"""The reproduction tables and moments of depthcore.reproduce, against each filter."""

import numpy as np
import pytest

from depthcore import SCENARIOS, optimal, report, reproduce
from depthcore.ekf import ekf
from depthcore.second_order import second_order


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_filter_moments_agree_with_each_filter(key):
    s = SCENARIOS[key]
    got = reproduce.filter_moments(s)
    m = optimal.marginals(s.mu, s.rho, s.prior)
    comp = {"depth": "y", "velocity": "v"}[s.quantity]
    opt = (m.depth_mean, m.depth_sd) if s.quantity == "depth" else (m.velocity_mean, m.velocity_sd)
    assert got["optimal"] == pytest.approx(opt, rel=1e-12)
    assert got["second_order"] == pytest.approx(second_order(s.mu, s.rho, s.prior).marginal(comp))
    assert got["ekf"] == pytest.approx(ekf(s.mu, s.rho, s.prior).posterior.marginal(comp))


def test_filter_moments_rejects_an_unknown_quantity():
    with pytest.raises(ValueError, match="quantity"):
        reproduce.filter_moments(SCENARIOS["fig2"], "x")


def test_the_particle_filters_seed_is_an_argument():
    s = SCENARIOS["fig5"]
    default = [r for r in reproduce.scenario_rows(s, names=("particle",))]
    same = reproduce.scenario_rows(
        s, names=("particle",), seed=np.random.SeedSequence(reproduce.PARTICLE_SEED)
    )
    other = reproduce.scenario_rows(s, names=("particle",), seed=1)
    assert default == same
    assert default[0]["mean"] != other[0]["mean"]
    assert abs(default[0]["mean"] - other[0]["mean"]) < 5 * default[0]["error"]


def test_comparison_runs_only_the_filters_of_its_table(monkeypatch):
    from depthcore import filters

    def refuse(*args, **kwargs):
        raise AssertionError("the particle filter is not in the figure pages' tables")

    monkeypatch.setitem(
        filters.FILTERS,
        "particle",
        filters.FILTERS["particle"].__class__(
            **{**vars(filters.FILTERS["particle"]), "run": refuse}
        ),
    )
    rows = report.comparison("fig4")
    assert {r["quantity"] for r in rows} == {"velocity"}
