"""The RMS depth error of the noise-free solution (Eq. (7)) by quadrature: depthbook.beyond_bound.

Against a Monte Carlo of Eq. (7) itself under the same cut of its denominator, which
also tells the quadrature from its first-order (delta-method) value; the first-order
limit as the noise shrinks; the refusals.
"""

from __future__ import annotations

import numpy as np
import pytest

from depthbook import beyond_bound
from depthcore import SCENARIOS
from depthcore.problem import model


def _monte_carlo(truth, rho, draws, seed, cut=beyond_bound.NOISE_FREE_CUT):
    """The RMS of c2 - y over draws of three noisy bearings, the denominator cut alike."""
    truth = np.asarray(truth, dtype=float)
    b = np.array([model.project(model.G(truth, k - 3)) for k in (1, 2, 3)]).ravel()
    mu = b + rho * np.random.default_rng(seed).standard_normal((draws, 3))
    d = mu[:, 0] + mu[:, 2] - 2 * mu[:, 1]
    keep = np.abs(d - (b[0] + b[2] - 2 * b[1])) <= cut * np.sqrt(6) * rho
    e2 = (model.noise_free_depth_unchecked(mu[keep]) - truth[1]) ** 2
    rmse = np.sqrt(e2.mean())
    return rmse, e2.std(ddof=1) / np.sqrt(e2.size) / (2 * rmse)


@pytest.mark.parametrize(
    ("truth", "rho"), [(SCENARIOS["fig2"].c, 1 / 200), ((1.2, 6.0, 0.6), 1 / 400)]
)
def test_quadrature_equals_a_monte_carlo_of_eq_7_and_not_its_first_order_value(truth, rho):
    r = beyond_bound.noise_free_depth_rmse(truth, rho)
    mc, se = _monte_carlo(truth, rho, 400_000, 5)
    assert r["error"] < 1e-9 * r["rmse"]
    assert abs(mc - r["rmse"]) < 4 * se, (mc, se, r)
    # the check has power: the first-order value lies many SEs away
    assert abs(mc - r["delta"]) > 8 * se, (mc, se, r)


def test_the_first_order_value_is_the_limit_of_small_noise():
    c = SCENARIOS["fig2"].c
    results = [beyond_bound.noise_free_depth_rmse(c, rho) for rho in (1 / 200, 1 / 2000, 1 / 20000)]
    gaps = [abs(r["rmse"] / r["delta"] - 1) for r in results]
    assert gaps[0] > 0.05 and np.all(np.diff(gaps) < 0) and gaps[-1] < 1e-3


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (((1.2, 6.0, 1.2), 1 / 200, 9.0), "^cut must leave out the pole"),
        (((1.2, 6.0, 1.2), 0.0), "^rho must be positive"),
        (((1.2, 1.5, 1.2), 1 / 200), "^truth must have depth > 2"),
        (((1.2, 6.0), 1 / 200), "^truth"),
    ],
)
def test_refusals_name_the_argument(args, message):
    with pytest.raises(ValueError, match=message):
        beyond_bound.noise_free_depth_rmse(*args)


def test_a_value_is_printed_to_the_second_significant_digit_of_its_error():
    assert beyond_bound.value_se_digits(1.44578, 0.015863) == "1.446 ± 0.016"
    assert beyond_bound.value_se_digits(1.00022, 8.6e-5) == "1.000220 ± 0.000086"
    assert beyond_bound.value_se_digits(123.4, 12.0) == "123 ± 12"
    with pytest.raises(ValueError, match="^se must be positive"):
        beyond_bound.value_se_digits(1.0, 0.0)
