"""Tests of the self-calibration (simulation-based calibration) of the optimal filter."""

import numpy as np
import pytest

from depthcore import calibration, model

PRIOR_MEAN = np.array([-1.2, 4.0, 0.0])
PRIOR_COV = np.diag([1.0, 1.0, 0.25])
RHO = 1 / 200


def test_draws_come_from_the_prior_in_front_of_the_camera():
    """Truths at time 3 are G^2 of prior draws with y_1 > 0, and their bearings are Eq. (4)'s."""
    d = calibration.draw_from_prior(
        PRIOR_MEAN, 4.0 * np.eye(3), RHO, 4000, np.random.default_rng(0)
    )
    x1 = model.G(d.truth, -2)
    assert np.all(x1[:, 1] > 0)
    assert d.n_behind > 0  # the prior's depth SD is 2 about a mean of 4: about 2 % lie behind
    # The depth's mean is that of a normal N(4, 4) truncated at 0 (closed form).
    from scipy.stats import truncnorm

    assert abs(np.mean(x1[:, 1]) - truncnorm.mean(-2.0, np.inf, loc=4.0, scale=2.0)) < 0.1
    residual = d.mu - model.project(np.stack([model.G(x1, k) for k in range(3)], axis=1))
    assert abs(np.std(residual) / RHO - 1.0) < 0.05


def test_coverage_and_uniformity_definitions():
    """Central intervals: |u - 1/2| <= p/2.

    Uniform PITs cover at the nominal rate; KS rejects a spike.
    """
    u = (np.arange(10_000) + 0.5) / 10_000
    np.testing.assert_allclose(calibration.coverage(u, (0.5, 0.9)), [0.5, 0.9], atol=1e-4)
    assert calibration.uniformity(u)["ks_pvalue"] > 0.99
    assert calibration.uniformity(np.full(100, 0.5))["ks_pvalue"] < 1e-10


def test_the_optimal_filter_is_calibrated_over_its_prior():
    """PIT values of the depth and velocity pass KS and chi-square tests.

    The tests are run at a 0.1 % false-alarm rate.
    """
    r = calibration.self_calibration(PRIOR_MEAN, PRIOR_COV, RHO, 120, np.random.default_rng(1))
    s = r.summary()
    assert s["trials"] > 100
    for q in ("depth", "velocity"):
        assert s[q]["ks_pvalue"] > 1e-3 and s[q]["chi2_pvalue"] > 1e-3


def test_a_miscalibrated_filter_is_caught():
    """A filter that assumes half the true noise is overconfident: its intervals cover too rarely.

    With about a hundred trials the velocity's PIT values fail both tests; the
    depth's 90 % intervals cover under 80 % of the truths.
    """
    r = calibration.self_calibration(
        PRIOR_MEAN, PRIOR_COV, RHO, 120, np.random.default_rng(1), filter_rho=RHO / 2
    )
    s = r.summary()
    assert s["velocity"]["ks_pvalue"] < 1e-3 and s["velocity"]["chi2_pvalue"] < 1e-3
    assert s["depth"]["coverage"][s["levels"].index(0.9)] < 0.8


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"prior_mean": [0.0, 1.0]}, "prior_mean"),
        ({"prior_cov": np.zeros((3, 3))}, "prior_cov"),
        ({"rho": -1.0}, "rho"),
        ({"n": 0}, "trials"),
        ({"rng": 5}, "rng"),
        ({"prior_mean": [0.0, -1e6, 0.0]}, "prior_mean"),
    ],
)
def test_bad_input_is_refused(kwargs, name):
    args = {
        "prior_mean": PRIOR_MEAN,
        "prior_cov": PRIOR_COV,
        "rho": RHO,
        "n": 10,
        "rng": np.random.default_rng(0),
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        calibration.draw_from_prior(**args)
