"""The batched entry points share one validation path: every bad input is a one-line
ValueError naming the argument, and no RuntimeWarning escapes."""

import numpy as np
import pytest

from depthcore.exact import optimal
from depthcore.kalman import ekf, second_order, ukf
from depthcore.particles import importance
from depthcore.problem import model

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

MU = np.array([-0.3, 0.0, 0.2])
MEAN = np.array([-1.2, 4.0, 0.0])
COV = 1000.0 * np.eye(3)

BAD = {
    "indefinite prior_cov": (
        MU,
        1 / 200,
        MEAN,
        np.diag([1.0, -1.0, 1.0]),
        r"prior_cov must be positive definite",
    ),
    "non-symmetric prior_cov": (
        MU,
        1 / 200,
        MEAN,
        np.array([[1, 0.5, 0], [0, 1, 0], [0, 0, 1.0]]),
        r"prior_cov must be symmetric",
    ),
    "degenerate triple": (
        np.array([[-0.3, 0, 0.2], [0.1, 0.2, 0.3]]),
        1 / 200,
        MEAN,
        COV,
        r"mu\[1\] is degenerate",
    ),
    "triple behind the camera": (
        np.array([[-0.3, 0, 0.2], [0.2, 0, -0.3]]),
        1 / 200,
        MEAN,
        COV,
        r"mu\[1\] puts the point behind the camera",
    ),
    "NaN prior mean": (MU[None], 1 / 200, [np.nan, 4.0, 0.0], COV, r"prior_mean must be finite"),
    "infinite mu": (np.array([[np.inf, 0, 0.2]]), 1 / 200, MEAN, COV, r"mu must be finite"),
    "zero rho": (MU[None], 0.0, MEAN, COV, r"rho must be positive"),
    "NaN rho": (MU[None], np.nan, MEAN, COV, r"rho must be finite"),
    "short prior mean": (MU[None], 1 / 200, [1.0, 2.0], COV, r"prior_mean must have shape"),
    "text mu": ("abc", 1 / 200, MEAN, COV, r"mu must be numeric"),
}


def _batched(mu):
    return np.atleast_2d(np.asarray(mu, dtype=float)) if not isinstance(mu, str) else mu


@pytest.mark.parametrize("case", list(BAD))
def test_ekf_run_refuses_like_the_single_entry_points(case):
    mu, rho, mean, cov, message = BAD[case]
    with pytest.raises(ValueError, match=message) as info:
        ekf.run(mu, rho, mean, cov)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("case", list(BAD))
def test_second_order_batch_refuses_bad_input(case):
    mu, rho, mean, cov, message = BAD[case]
    with pytest.raises(ValueError, match=message):
        second_order.second_order_batch(_batched(mu), rho, mean, cov)


@pytest.mark.parametrize("case", list(BAD))
def test_optimal_moments_refuses_bad_input(case):
    mu, rho, mean, cov, message = BAD[case]
    with pytest.raises(ValueError, match=message):
        optimal.moments(_batched(mu), rho, mean, cov)


@pytest.mark.parametrize("case", [c for c in BAD if c != "text mu"])
def test_particle_run_refuses_bad_input(case):
    mu, rho, mean, cov, message = BAD[case]
    with pytest.raises(ValueError, match=message):
        importance.run(_batched(mu), rho, mean, cov, 100, np.random.default_rng(0))


def test_ukf_run_refuses_a_covariance_that_is_not_positive_definite():
    with pytest.raises(ValueError, match="prior_cov must be positive definite"):
        ukf.run(MU, 1 / 200, MEAN, np.diag([1.0, -1.0, 1.0]))


def test_batched_covariances_name_the_offending_one():
    covs = np.stack([COV, COV, np.diag([1.0, 0.0, 1.0])])
    with pytest.raises(ValueError, match=r"prior_cov\[2\] must be positive definite"):
        ekf.run(np.tile(MU, (3, 1)), 1 / 200, MEAN, covs)


def test_a_two_dimensional_batch_names_the_triple_by_both_indices():
    mu = np.tile(MU, (2, 2, 1))
    mu[1, 0] = [0.2, 0.0, -0.3]
    with pytest.raises(ValueError, match=r"mu\[1, 0\] puts the point behind the camera"):
        ekf.run(mu, 1 / 200, MEAN, COV)


def test_checked_batch_gives_the_same_answer_as_the_single_entry_point():
    means, covs = ekf.run(np.tile(MU, (2, 1)), 1 / 200, MEAN, COV)
    single = ekf.run(MU, 1 / 200, MEAN, COV)
    np.testing.assert_array_equal(means[0], single.means)
    np.testing.assert_array_equal(covs[1], single.covs)


def test_batch_problem_returns_the_symmetrised_covariance_and_keeps_shapes():
    cov = COV.copy()
    cov[0, 1] += 1e-12
    mu, rho, mean, sym = model.batch_problem(MU[None], 0.1, MEAN, cov)
    assert mu.shape == (1, 3) and rho.shape == () and mean.shape == (3,)
    np.testing.assert_array_equal(sym, sym.T)


def test_rho_of_the_wrong_shape_is_refused():
    with pytest.raises(ValueError, match=r"rho must be a scalar or have shape \(2,\)"):
        ekf.run(np.tile(MU, (2, 1)), [0.1, 0.1, 0.1], MEAN, COV)
