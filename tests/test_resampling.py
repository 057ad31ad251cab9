"""Weights of a particle sample: normalising, ESS, resamplers, moments.

:mod:`depthcore.particles.resampling` and :mod:`depthcore.problem.weights`.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.special import logsumexp

from depthcore.particles.resampling import (
    RESAMPLERS,
    effective_sample_size,
    residual,
    systematic,
    weighted_standard_errors,
)
from depthcore.problem.weights import normalise


def random_weights(rng, shape):
    w = rng.gamma(0.3, size=shape)  # uneven: many small, a few large
    return w / w.sum(axis=-1, keepdims=True)


# --- resampling ------------------------------------------------------------------------


@pytest.mark.parametrize("M", [None, 7, 50, 1000])
def test_systematic_counts_are_floor_or_ceil_of_M_W(M):
    rng = np.random.default_rng(1)
    W = random_weights(rng, (200, 50))
    idx = systematic(W, rng, M)
    M = 50 if M is None else M
    assert idx.shape == (200, M)
    counts = np.stack([np.bincount(row, minlength=50) for row in idx])
    assert np.all(counts >= np.floor(M * W) - 1e-9) and np.all(counts <= np.ceil(M * W) + 1e-9)


@pytest.mark.parametrize("name", sorted(RESAMPLERS))
def test_resampling_counts_have_expectation_M_W(name):
    # Over R independent draws the mean count of particle i is M W_i; the
    # multinomial SD sqrt(M W (1 - W) / R) bounds that of all three schemes.
    rng = np.random.default_rng(2)
    W = random_weights(rng, (1, 30))[0]
    R, M = 4000, 30
    idx = RESAMPLERS[name](np.broadcast_to(W, (R, 30)), rng, M)
    mean = np.mean([np.bincount(row, minlength=30) for row in idx], axis=0)
    se = np.sqrt(M * W * (1 - W) / R)
    assert np.all(np.abs(mean - M * W) <= 5 * se + 1e-12)


@pytest.mark.parametrize("name", sorted(RESAMPLERS))
def test_resampling_returns_sorted_valid_indices(name):
    rng = np.random.default_rng(3)
    W = random_weights(rng, (5, 40))
    W[:, ::3] = 0.0
    W /= W.sum(axis=-1, keepdims=True)
    idx = RESAMPLERS[name](W, rng)
    assert idx.shape == (5, 40) and idx.dtype.kind == "i"
    assert np.all(np.diff(idx, axis=-1) >= 0)
    assert np.all(np.take_along_axis(W, idx, axis=-1) > 0)  # weight-zero particles never drawn


def test_residual_keeps_the_integer_part():
    rng = np.random.default_rng(4)
    W = random_weights(rng, (100, 20))
    counts = np.stack([np.bincount(row, minlength=20) for row in residual(W, rng, 20)])
    assert np.all(counts >= np.floor(20 * W))
    # filterpy 1.4.5 draws the rest with weights W - floor(N W) (negative here); the
    # residuals N W - floor(N W) are what is left after the deterministic copies.
    W = np.array([0.55, 0.3, 0.15])
    counts = np.bincount(residual(np.broadcast_to(W, (20000, 3)), rng, 3).ravel(), minlength=3)
    assert_allclose(counts / 20000, 3 * W, atol=0.02)


def test_resampling_is_deterministic_for_degenerate_weights():
    rng = np.random.default_rng(5)
    W = np.zeros((3, 6))
    W[:, 2] = 1.0
    for resampler in RESAMPLERS.values():
        assert_array_equal(resampler(W, rng), 2)


@pytest.mark.parametrize(
    "W, M, message",
    [
        ([0.5, 0.6], None, "W must sum to 1"),
        ([1.5, -0.5], None, "W must be non-negative"),
        ([0.5, np.nan], None, "W must be finite"),
        ([0.5, 0.5], 0, "M must be an integer >= 1"),
        (np.zeros((2, 0)), None, r"W must have shape \(\.\.\., N\)"),
    ],
)
def test_resamplers_reject_bad_weights(W, M, message):
    for resampler in RESAMPLERS.values():
        with pytest.raises(ValueError, match=message):
            resampler(W, np.random.default_rng(0), M)
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        systematic([0.5, 0.5], None)


def test_standard_errors_of_a_collapsed_filter_are_infinite_not_nan():
    x = np.array([[1.0, 2.0, 3.0]])
    W = np.array([[0.0, 1.0, 0.0]])
    with np.errstate(all="raise"):
        se_mean, se_sd = weighted_standard_errors(x, W)
    assert se_mean[0] == 0 and np.isinf(se_sd[0])


def test_normalise_gives_log_weights_summing_to_one():
    rng = np.random.default_rng(6)
    log_w = 1e3 * rng.normal(size=(4, 100)) - 5e4  # exp() of these underflows
    log_w[:, :10] = -np.inf
    lw = normalise(log_w)
    assert_allclose(logsumexp(lw, axis=-1), 0.0, atol=1e-12)
    assert np.all(np.isneginf(lw[:, :10]))
    assert_allclose(np.exp(lw).sum(axis=-1), 1.0, rtol=1e-12)


def test_ess_formula():
    rng = np.random.default_rng(7)
    log_w = rng.normal(scale=2.0, size=(3, 50))
    log_w[:, 0] = -np.inf
    W = np.exp(normalise(log_w))
    assert_allclose(effective_sample_size(log_w), 1.0 / np.sum(W**2, axis=-1), rtol=1e-12)
    # Shift invariance, up to the rounding of log_w + 1e3 (1e3 * 2**-52 ~ 2e-13).
    assert_allclose(effective_sample_size(log_w + 1e3), effective_sample_size(log_w), rtol=1e-11)
    assert_allclose(effective_sample_size(np.zeros(17)), 17.0, rtol=1e-14)
    one = np.full(9, -np.inf)
    one[4] = 3.0
    assert_allclose(effective_sample_size(one), 1.0, rtol=1e-14)


def test_weighted_standard_errors_of_a_hand_computed_case():
    # x = 0, 1, 2, 3 with equal weights: mean 3/2, variance 5/4;
    # se(mean)^2 = sum W^2 (x - m)^2 = (9/4 + 1/4 + 1/4 + 9/4) / 16 = 5/16;
    # se(var)^2 = sum W^2 ((x - m)^2 - 5/4)^2 = 4 * 1 / 16; se(sd) = se(var) / (2 sd).
    from depthcore.particles.resampling import weighted_standard_errors

    se_mean, se_sd = weighted_standard_errors(np.arange(4.0), np.full(4, 0.25))
    assert se_mean == pytest.approx(np.sqrt(5 / 16), rel=1e-14)
    assert se_sd == pytest.approx(0.5 / (2 * np.sqrt(5 / 4)), rel=1e-14)


def test_weighted_standard_errors_match_the_spread_over_repeated_runs():
    # Self-normalised importance sampling of N(0, 1) from N(0, 1.5^2): the SD
    # over 4,000 independent runs of the weighted mean and SD is the standard
    # error the delta method should predict (relative MC error ~ 1/sqrt(8000)).
    from depthcore.particles.resampling import weighted_moments, weighted_standard_errors

    rng = np.random.default_rng(2024)
    x = rng.normal(0.0, 1.5, size=(4000, 500))
    log_w = -0.5 * x**2 + 0.5 * (x / 1.5) ** 2
    W = np.exp(normalise(log_w))
    mean, sd = weighted_moments(x, W)
    se_mean, se_sd = weighted_standard_errors(x, W)
    assert np.mean(se_mean) == pytest.approx(np.std(mean), rel=0.05)
    assert np.mean(se_sd) == pytest.approx(np.std(sd), rel=0.05)


def test_particle_standard_errors_are_those_of_their_weighted_particles():
    from depthcore.particles import importance
    from depthcore.particles.resampling import weighted_standard_errors
    from depthcore.problem.scenarios import SCENARIOS

    s = SCENARIOS["fig2"]
    r = importance.run(
        [s.mu, s.mu], s.rho, s.prior.mean, s.prior.cov, 500, np.random.default_rng(3)
    )
    se = r.standard_errors()
    W = np.exp(r.log_weights)
    for comp, i in (("depth", 1), ("velocity", 2)):
        want = weighted_standard_errors(r.particles[..., i], W)
        assert_allclose(getattr(se, f"{comp}_mean"), want[0], rtol=1e-12)
        assert_allclose(getattr(se, f"{comp}_sd"), want[1], rtol=1e-12)


def test_normalise_sums_to_one_when_the_log_weights_are_huge():
    # log weights near -1e10 (a particle filter's far particles after many frames):
    # the weights must still sum to one to rounding, as the resamplers require
    rng = np.random.default_rng(8)
    log_w = -1e10 + rng.normal(scale=5.0, size=(50, 200))
    W = np.exp(normalise(log_w))
    assert_allclose(W.sum(axis=-1), 1.0, rtol=0, atol=1e-13)
    systematic(W, np.random.default_rng(9))  # accepted: rows sum to one within 1e-9
