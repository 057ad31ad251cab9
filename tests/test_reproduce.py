"""The reproduction tables and moments of depthcore.studies.reproduce, against each filter."""

import numpy as np
import pytest

from depthcore import SCENARIOS
from depthcore.exact import optimal
from depthcore.kalman import ekf, second_order
from depthcore.studies import reproduce


@pytest.mark.parametrize("key", list(SCENARIOS))
def test_filter_moments_agree_with_each_filter(key):
    s = SCENARIOS[key]
    got = reproduce.filter_moments(s)
    m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    comp = {"depth": "y", "velocity": "v"}[s.quantity]
    opt = (m.depth_mean, m.depth_sd) if s.quantity == "depth" else (m.velocity_mean, m.velocity_sd)
    assert got["optimal"] == pytest.approx(opt, rel=1e-12)
    assert got["second_order"] == pytest.approx(
        second_order.run(s.mu, s.rho, s.prior.mean, s.prior.cov).marginal(comp)
    )
    assert got["ekf"] == pytest.approx(
        ekf.run(s.mu, s.rho, s.prior.mean, s.prior.cov).posterior.marginal(comp)
    )


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
    from depthcore.registry import filters
    from depthcore.studies import reproduce

    def refuse(*args, **kwargs):
        raise AssertionError("the particle filter is not in the figure pages' tables")

    monkeypatch.setitem(
        filters.FILTERS,
        "particle",
        filters.FILTERS["particle"].__class__(
            **{**vars(filters.FILTERS["particle"]), "run": refuse}
        ),
    )
    rows = reproduce.comparison("fig4")
    assert {r["quantity"] for r in rows} == {"velocity"}


def test_agreement_with_the_paper_is_rounding_to_its_printed_precision():
    # The paper prints two decimals: a value agrees when it lies within half a
    # unit of the last printed digit, i.e. when it would be printed the same.
    from depthcore.problem.scenarios import REPORTED_DECIMALS

    assert REPORTED_DECIMALS == 2
    for printed in (20.74, 0.0, -1.23, 5.1):
        for offset, agrees in ((0.0, True), (0.0049, True), (-0.0049, True)):
            assert reproduce._agrees(printed + offset, printed) is agrees
        for offset in (0.0051, -0.0051, 0.01, 0.1):
            assert reproduce._agrees(printed + offset, printed) is False


def test_rows_agree_with_the_paper_exactly_when_they_round_to_its_numbers():
    # An independent route: format each value at the paper's two decimals.
    for row in reproduce.scenario_rows(SCENARIOS["fig2"], names=("optimal", "ekf")):
        for k in ("mean", "sd"):
            printed = row[f"reported_{k}"]
            if printed is None:
                assert row[f"{k}_matches"] is None
                continue
            # values within 1e-9 of a rounding boundary would be ambiguous
            assert abs(abs(row[k] - printed) - 0.005) > 1e-9
            assert row[f"{k}_matches"] is (float(f"{row[k]:.2f}") == printed)
