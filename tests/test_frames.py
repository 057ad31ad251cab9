"""A track's frames (:mod:`depthcore.problem.frames`) and predictive tails
(:mod:`depthcore.problem.predictive`)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import integrate, stats

from depthcore.problem import frames, model, predictive


def test_regular_frames_are_the_papers():
    f = frames.check([0.1, 0.2, 0.31], 0.01)
    assert f.regular and f.present.all()
    np.testing.assert_array_equal(f.elapsed, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(f.rho, [0.01] * 3)


def test_gaps_rho_per_frame_and_steps():
    f = frames.check([0.1, np.nan, 0.3, 0.2, 0.5], [0.1, np.nan, 0.2, 0.1, 0.3], [1, 2, 0.5, 1])
    assert not f.regular
    np.testing.assert_array_equal(f.present, [True, False, True, True, True])
    np.testing.assert_array_equal(f.elapsed, [0.0, 1.0, 3.0, 3.5, 4.5])
    assert f.rho[1] == 1.0  # never used, at the missing frame


def test_batch_rho_per_problem_and_per_frame():
    mu = np.array([[0.1, 0.2, 0.31], [0.1, 0.25, 0.3]])
    np.testing.assert_array_equal(frames.check(mu, [0.1, 0.2]).rho[:, 2], [0.1, 0.2])
    np.testing.assert_array_equal(frames.check(mu, np.full((2, 3), 0.3)).rho, 0.3)


@pytest.mark.parametrize(
    "mu, rho, steps, message",
    [
        ([0.1, np.nan, 0.3], 0.01, None, "mu has 2 bearings present"),
        ([0.1, 0.2, 0.3], 0.01, None, "mu is degenerate"),
        ([0.1, 0.2, 0.4], 0.01, [1, 2], "mu is degenerate"),
        ([0.1, 0.2, 0.31, np.inf], 0.01, None, "mu must be finite or NaN"),
        ([0.1, 0.2], 0.01, None, "mu must have shape"),
        ([0.1, 0.2, 0.31], [1, 2], None, "rho must be a number"),
        ([0.1, 0.2, 0.31], [0.1, -1, 0.1], None, r"rho\[1\] must be finite and positive"),
        ([0.1, 0.2, 0.31], 0.01, [1, 0], "steps must be nonzero"),
        ([0.1, 0.2, 0.31], 0.01, [1, 1, 1], "steps must have shape"),
        ([0.1, 0.2, 0.31], 0.01, [1, np.nan], "steps must be finite"),
        ([0.1, 0.2, 0.31], "0.01", None, "rho must be numeric"),
    ],
)
def test_refusals_name_the_argument(mu, rho, steps, message):
    with pytest.raises(ValueError, match=message):
        frames.check(mu, rho, steps)


def test_degeneracy_agrees_with_the_regular_check():
    rng = np.random.default_rng(1)
    mu = rng.normal(size=(200, 6))
    mu[:50] = np.linspace(0, 1, 6)  # affine in time: degenerate at unit steps
    for row in mu:
        refused = []
        for check in (frames.check, lambda m, r: model.measurements_batch(m)):
            try:
                check(row, 0.1)
                refused.append(False)
            except ValueError:
                refused.append(True)
        assert refused[0] == refused[1]


def test_uneven_steps_of_a_moving_point_are_not_degenerate():
    x1 = np.array([1.0, 5.0, 0.3])
    steps = np.array([0.5, 2.0, 1.0])
    t = np.concatenate([[0.0], np.cumsum(steps)])
    mu = model.project(model.G(x1[None, :], t))
    f = frames.check(mu, 0.01, steps)
    np.testing.assert_allclose(f.elapsed, t)


def test_transition_is_eq9_with_the_step():
    x = np.array([1.0, 5.0, 0.3])
    for s in (1.0, 0.25, 3.0):
        np.testing.assert_allclose(frames.transition(s) @ x + [0, s, 0], model.G(x, s))
    np.testing.assert_array_equal(frames.transition(1.0), model.G_linear(1))


def test_velocity_variance_is_additive_over_steps():
    q = 0.3
    assert frames.velocity_variance(q, 1.0) == pytest.approx(q**2)
    halves = frames.velocity_variance(q, 0.75) + frames.velocity_variance(q, 0.75)
    assert halves == pytest.approx(frames.velocity_variance(q, 1.5))


def test_gaussian_predictive_is_scipys():
    log_d, tail = predictive.gaussian(0.7, 0.2, 0.09)
    assert log_d == pytest.approx(stats.norm.logpdf(0.7, 0.2, 0.3))
    assert tail == pytest.approx(2 * stats.norm.sf(0.5 / 0.3))


def test_mixture_predictive_by_quadrature():
    log_w, means, var = np.log([0.2, 0.5, 0.3]), np.array([-1.0, 0.0, 2.0]), np.array([0.3, 1, 2])
    parts = list(zip(np.exp(log_w), means, np.sqrt(var), strict=True))

    def density(x):
        return sum(w * stats.norm.pdf(x, m, sd) for w, m, sd in parts)

    for mu in (-2.0, 0.4, 3.0):
        log_d, tail = predictive.mixture(mu, log_w, means, var)
        assert np.exp(log_d) == pytest.approx(density(mu), rel=1e-12)
        lower = integrate.quad(density, -np.inf, mu, epsabs=1e-13)[0]
        assert tail == pytest.approx(2 * min(lower, 1 - lower), rel=1e-8)


def test_mixture_of_one_is_the_gaussian():
    a = predictive.mixture(
        np.array([0.3, 5.0]), np.zeros((2, 1)), np.zeros((2, 1)), np.ones((2, 1))
    )
    b = predictive.gaussian(np.array([0.3, 5.0]), 0.0, 1.0)
    np.testing.assert_allclose(a, b, rtol=1e-13)


def test_mixture_with_every_component_empty_predicts_nothing_without_a_warning():
    # a particle cloud wholly behind the camera: every log weight -inf in the first row
    log_w = np.array([[-np.inf, -np.inf], [0.0, -np.inf]])
    means, var = np.array([[0.1, 0.2], [0.1, 0.3]]), np.full((2, 2), 1e-2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log_d, tail = predictive.mixture(np.array([0.1, 0.2]), log_w, means, var)
    assert np.isnan(log_d[0]) and np.isnan(tail[0])
    one = predictive.gaussian(0.2, 0.1, 1e-2)
    assert log_d[1] == pytest.approx(one[0], rel=1e-13) and tail[1] == pytest.approx(one[1])


def test_gate():
    assert predictive.gate(None) is None
    assert predictive.gate(1e-3) == 1e-3
    for bad in (0, 1, -0.1, 2.0):
        with pytest.raises(ValueError, match="gate must be None or a probability"):
            predictive.gate(bad)
    np.testing.assert_array_equal(
        predictive.skipped([1e-4, 1e-2, 1e-5], [True, True, False], 1e-3), [True, False, False]
    )


def test_simulate_with_steps_moves_by_eq1_with_each_step():
    state = np.array([1.0, 5.0, 0.3])
    steps = np.array([0.5, 2.0, 1.0, 1.5])
    sim = model.simulate(state, 5, 1e-3, 0.0, np.random.default_rng(0), frame=3, steps=steps)
    t = np.concatenate([[0.0], np.cumsum(steps)]) - 2.5  # depth travelled since frame 3
    np.testing.assert_allclose(sim.states, model.G(state[None, :], t), rtol=1e-14)


def test_simulate_with_unit_steps_and_rho_per_frame_is_the_regular_draw():
    state = np.array([1.0, 5.0, 0.3])
    for frame in (1, 3):
        a = model.simulate(state, 8, 0.01, 0.2, np.random.default_rng(1), size=3, frame=frame)
        b = model.simulate(
            state, 8, np.full(8, 0.01), 0.2, np.random.default_rng(1), size=3, frame=frame
        )
        np.testing.assert_allclose(b.states, a.states, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(b.mu, a.mu, rtol=1e-14, atol=1e-15)


def test_simulated_velocity_variance_grows_with_the_depth_travelled():
    q, steps, size = 0.3, np.array([0.5, 2.0, 1.5]), 40_000
    sim = model.simulate(
        [0.0, 5.0, 0.0], 4, 0.01, q, np.random.default_rng(2), size=size, frame=1, steps=steps
    )
    v = sim.states[:, -1, 2]
    expected = frames.velocity_variance(q, steps.sum())
    # the sample variance of 40,000 normal draws has relative SE sqrt(2 / 40,000) = 0.7 %
    assert abs(v.var() / expected - 1) < 4 * np.sqrt(2 / size)


def test_simulate_refuses_bad_steps_and_rho():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"steps must have shape \(4,\)"):
        model.simulate([0.0, 5.0, 0.0], 5, 0.01, 0.0, rng, steps=[1, 1])
    with pytest.raises(ValueError, match="steps must be nonzero"):
        model.simulate([0.0, 5.0, 0.0], 3, 0.01, 0.0, rng, steps=[1, 0])
    with pytest.raises(ValueError, match="state and steps bring the point to the camera"):
        model.simulate([0.0, 5.0, 0.0], 3, 0.01, 0.0, rng, frame=1, steps=[-3, -3])
    with pytest.raises(ValueError, match=r"rho must be a number or have shape \(3,\)"):
        model.simulate([0.0, 5.0, 0.0], 3, [0.01, 0.02], 0.0, rng)


def test_extreme_noise_and_steps_are_refused_by_name():
    mu = [0.1, 0.2, 0.31, 0.4]
    with pytest.raises(ValueError, match=r"rho\[0\] must be from 1e-150 to 1e\+150"):
        frames.check(mu, [1e-300, 0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="steps must add up to a depth travelled that changes"):
        frames.check(mu, 0.1, [1e-300, 1e300, 1.0])
