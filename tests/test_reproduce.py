"""The reproduction tables and moments of depthcore.reproduce, against each filter."""

import pytest

from depthcore import SCENARIOS, optimal, reproduce
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
