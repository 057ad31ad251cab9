"""Sweeps of the noise level and of the prior's depth (Figure 6 generalised)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore import optimal, sweeps
from depthcore.ekf import ekf
from depthcore.scenarios import SCENARIOS
from depthcore.second_order import second_order


def test_noise_sweep_at_the_papers_noise_matches_figure2():
    s = SCENARIOS["fig2"]
    r = sweeps.noise_sweep([s.rho])
    m = optimal.marginals(s.mu, s.rho, s.prior)
    assert r["optimal"]["depth_mean"][0] == pytest.approx(m.depth_mean, rel=1e-9)
    assert r["ekf"]["depth_sd"][0] == pytest.approx(ekf(s.mu, s.rho, s.prior).posterior.marginal("y")[1])


def test_second_order_approaches_the_optimal_filter_as_noise_falls():
    r = sweeps.noise_sweep(1 / np.array([50.0, 200.0, 1000.0]))
    h = r["second_order"]["hellinger"]
    assert h[0] > h[1] > h[2]
    # the EKF's distance stays large: its error comes from the prior mean
    assert np.all(r["ekf"]["hellinger"] > 0.5)


def test_prior_offset_sweep_matches_figure6():
    s6 = SCENARIOS["fig6"]
    r = sweeps.prior_offset_sweep([0.0, 2.0])
    assert r["ekf"]["depth_mean"][1] == pytest.approx(ekf(s6.mu, s6.rho, s6.prior).posterior.mean[1])
    assert r["second_order"]["depth_mean"][1] == pytest.approx(second_order(s6.mu, s6.rho, s6.prior).mean[1])
    # the EKF follows the offset, the optimal filter hardly moves
    assert r["ekf"]["depth_mean"][1] - r["ekf"]["depth_mean"][0] > 1.5
    assert abs(np.diff(r["optimal"]["depth_mean"])[0]) < 0.01


def test_prior_offset_sweep_rejects_a_prior_behind_the_camera():
    with pytest.raises(ValueError, match="offsets must keep the prior's depth"):
        sweeps.prior_offset_sweep([-4.5])


def test_hellinger_is_zero_for_identical_densities_and_bounded():
    s = SCENARIOS["fig2"]
    ref = optimal.batch_marginals(np.array([s.mu]), s.rho, s.prior.mean, s.prior.cov)
    from depthcore import study
    h = study.hellinger(ref, ref.depth_log_pdf, ref.moments.depth_mean, ref.moments.depth_sd)
    assert_allclose(h, 0.0, atol=1e-6)  # H = sqrt(1 - BC): BC to 1e-12
