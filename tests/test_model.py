"""Eqs. (1), (4), (5), (7), (9), (11), (20)-(22): the motion and measurement model, the misfit."""

import numpy as np
import pytest
from hypothesis import given, settings
from numpy.testing import assert_allclose
from scipy import integrate

from depthcore.problem import model
from depthcore.problem.model import (
    f,
    noise_free_state,
    noise_free_states,
    residual_gradients,
    residuals,
)
from depthcore.problem.scenarios import MU_17, MU_18, SCENARIOS

from helpers import bearings, states

FIG2 = SCENARIOS["fig2"]


def test_eq1_G_forward_and_back_are_inverse():
    x = np.array([0.3, 5.0, -0.7])
    assert_allclose(model.G(model.G(x, 2), -2), x, rtol=0, atol=1e-15)
    assert_allclose(model.G(x, 1), [x[0] + x[2], x[1] + 1, x[2]])


def test_eq9_F_and_e_give_G():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(20, 3))
    assert_allclose(model.G(x), x @ model.F.T + model.e, rtol=0, atol=1e-14)
    for k in (-2, -1, 2):
        assert_allclose(model.G(x, k), x @ model.G_linear(k).T + k * model.e, atol=1e-14)


def test_eq11_observation_vector_is_gradient_of_projection():
    n = np.array([1.3, 4.2, 0.6])
    eps = 1e-6  # central differences: error O(eps^2) ~ 1e-12
    fd = [(model.project(n + eps * e) - model.project(n - eps * e)) / (2 * eps) for e in np.eye(3)]
    assert_allclose(model.observation_vector(n), fd, rtol=1e-8, atol=1e-10)


def test_eq4_likelihood_integrates_to_one_over_mu():
    x = np.array([1.2, 6.0, 1.2])
    total, _ = integrate.quad(
        lambda m: np.exp(model.log_likelihood(m, x, 0.01)), -1, 1, points=[0.2]
    )
    assert total == pytest.approx(1.0, abs=1e-10)


def test_simulate_measurements_statistics_and_repeatability():
    """Eq. (4): bearings x_i / y_i plus noise of SD rho along the motion of Eq. (1)."""
    x1 = np.array([-1.2, 4.0, 1.2])
    mu = model.simulate(x1, 3, 0.01, 0.0, np.random.default_rng(5), size=20000, frame=1).mu
    truth = [-0.3, 0.0, 0.2]
    # standard error of a mean of 20000 draws with sd 0.01 is 7e-5: allow 5 of them
    assert_allclose(mu.mean(axis=0), truth, atol=3.5e-4)
    assert_allclose(mu.std(axis=0), 0.01, rtol=0.03)
    again = model.simulate(x1, 3, 0.01, 0.0, np.random.default_rng(5), size=20000, frame=1).mu
    assert np.array_equal(mu, again)
    # the same track given through its state at time 3 (the default frame)
    at3 = model.simulate(model.G(x1, 2), 3, 0.01, 0.0, np.random.default_rng(5), size=20000)
    assert_allclose(at3.mu, mu, rtol=0, atol=1e-15)


def test_simulate_follows_the_motion_and_is_repeatable():
    """Process noise from frame 1 on (``frame=1``): the bank's model."""
    x1 = np.array([-1.2, 4.0, 1.2])
    a = model.simulate(x1, 12, 0.01, 0.1, np.random.default_rng(1), size=500, frame=1)
    b = model.simulate(x1, 12, 0.01, 0.1, np.random.default_rng(1), size=500, frame=1)
    assert a.states.shape == (500, 12, 3) and a.mu.shape == (500, 12)
    assert np.array_equal(a.mu, b.mu) and np.array_equal(a.states, b.states)
    x, y, v = np.moveaxis(a.states, -1, 0)
    assert_allclose(y, 4.0 + np.arange(12) + 0 * x, rtol=0, atol=0)
    assert_allclose(x[:, 1:], x[:, :-1] + v[:, :-1], rtol=1e-14, atol=1e-14)
    assert_allclose(a.states[:, 0], np.broadcast_to(x1, (500, 3)))
    # accelerations have SD q, bearing errors SD rho (chi-square: 5500 and 6000 draws, 5%)
    assert np.std(np.diff(v, axis=-1)) == pytest.approx(0.1, rel=0.05)
    assert np.std(a.mu - x / y) == pytest.approx(0.01, rel=0.05)
    still = model.simulate(x1, 5, 0.01, 0.0, np.random.default_rng(2), frame=1)
    assert_allclose(still.states, model.trajectory(x1, 5), rtol=1e-15)


@pytest.mark.parametrize("frame", [1, 3, 5])
def test_simulate_passes_through_the_given_state_at_its_frame(frame):
    """Noise-free motion (Eq. (1)) up to ``frame``, accelerations of SD q after it."""
    state = np.array([1.2, 6.0, 1.2])
    n, q = 10, 10.0
    sim = model.simulate(state, n, 0.005, q, np.random.default_rng(7), size=2000, frame=frame)
    x, y, v = np.moveaxis(sim.states, -1, 0)
    # the given state at its frame in every draw, exactly
    assert np.array_equal(sim.states[:, frame - 1], np.broadcast_to(state, (2000, 3)))
    # before it, the noise-free motion through it
    back = np.stack([model.G(state, k - frame) for k in range(1, frame + 1)])
    assert_allclose(sim.states[:, :frame], np.broadcast_to(back, (2000, frame, 3)), atol=1e-12)
    assert_allclose(y, state[1] + np.arange(1, n + 1) - frame + 0 * x, rtol=0, atol=0)
    assert_allclose(x[:, 1:], x[:, :-1] + v[:, :-1], rtol=1e-13, atol=1e-12)
    # after it, velocity changes of SD q: 2000 (n - frame) draws, chi-square at 5 SE
    dv = np.diff(v[:, frame - 1 :], axis=-1)
    se = np.sqrt(2.0 / (2 * dv.size))
    assert np.std(dv) == pytest.approx(q, rel=5 * se)
    # the bearings' noise has SD rho about the states' projections
    assert np.std(sim.mu - x / y) == pytest.approx(0.005, rel=5 * np.sqrt(1.0 / (2 * x.size)))


def test_simulate_draws_nothing_for_the_motion_without_process_noise():
    rng = np.random.default_rng(3)
    sim = model.simulate([1.2, 6.0, 1.2], 7, 0.005, 0.0, rng, size=4)
    noise = np.random.default_rng(3).standard_normal((4, 7))
    assert_allclose(sim.mu - model.project(sim.states), 0.005 * noise, rtol=0, atol=1e-15)


def test_simulate_batches_states():
    states = np.array([[1.2, 6.0, 1.2], [0.0, 4.0, -0.5]])
    sim = model.simulate(states, 5, 0.01, 0.1, np.random.default_rng(0), size=3)
    assert sim.states.shape == (3, 2, 5, 3) and sim.mu.shape == (3, 2, 5)
    assert_allclose(sim.states[:, :, 2], np.broadcast_to(states, (3, 2, 3)), rtol=0, atol=0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(state=[0.0, -1.0, 0.0]), "state puts the point behind the camera"),
        (dict(state=[0.0, 2.0, 0.0]), "state puts the point behind the camera"),
        (dict(state=[0.0, 2.0, 0.0, 1.0]), r"state must have shape \(..., 3\)"),
        (dict(state=[0.0, np.nan, 0.0]), "state must be finite"),
        (dict(frames=0), "frames must be an integer >= 1"),
        (dict(frames=2.5), "frames must be an integer >= 1"),
        (dict(frame=0), "frame must be an integer >= 1"),
        (dict(rho=0.0), "rho must be"),
        (dict(process_noise=-1.0), "process_noise must be"),
        (dict(size=0), "size must be an integer >= 1"),
        (dict(rng=1), "rng must be a numpy.random.Generator"),
    ],
)
def test_simulate_refuses_bad_input(kwargs, message):
    args = dict(
        state=[0.0, 5.0, 0.5], frames=4, rho=0.01, process_noise=0.0, rng=np.random.default_rng(0)
    )
    with pytest.raises(ValueError, match=message):
        model.simulate(**dict(args, **kwargs))


@pytest.mark.parametrize("rho", [0.0, -1.0, np.nan, np.inf])
def test_log_likelihood_rejects_bad_rho(rho):
    with pytest.raises(ValueError, match="rho must be"):
        model.log_likelihood(0.1, [1.0, 5.0, 0.0], rho)


def test_noise_in_pixels_paper_arithmetic():
    # 512 pixels over 30 degrees: 977.8 pixels per radian.
    assert model.noise_in_pixels(1 / 200) == pytest.approx(4.889, abs=1e-3)  # "about 5 pixels"
    assert model.noise_in_pixels(1 / 500) == pytest.approx(
        1.956, abs=1e-3
    )  # printed "about 1 pixel"
    pinhole = model.noise_in_pixels(1 / 200, small_angle=False)
    assert pinhole == pytest.approx(256 / np.tan(np.deg2rad(15)) * np.tan(1 / 200), rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"rho": 0}, "rho must be positive"),
        ({"rho": 0.01, "fov_deg": 180}, "fov_deg must be below 180"),
        ({"rho": 0.01, "image_size": -5}, "image_size must be positive"),
    ],
)
def test_noise_in_pixels_rejects_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        model.noise_in_pixels(**kwargs)


def test_profile_misfit_vanishes_at_the_noise_free_depth():
    c = FIG2.c
    assert model.profile_misfit(FIG2.mu, [c[1]])[0] == pytest.approx(0.0, abs=1e-25)


def test_profile_misfit_is_the_least_misfit_at_that_depth():
    # Independent route: least squares by numpy's lstsq, then the misfit of the
    # states moved by model.G and projected; rounding only (1e-12 relative).
    from depthcore.problem import model

    mu = np.asarray(FIG2.mu)
    for y3 in (2.5, 6.0, 40.0):
        back = np.array([2.0, 1.0, 0.0])
        A = np.stack([1.0 / (y3 - back), -back / (y3 - back)], axis=-1)
        (x3, v), *_ = np.linalg.lstsq(A, mu, rcond=None)
        f = sum((mu[i] - model.project(model.G([x3, y3, v], i - 2))) ** 2 for i in range(3))
        got = model.profile_misfit(mu, [y3])[0]
        assert got == pytest.approx(f, rel=1e-12, abs=1e-30)
        for dx, dv in ((1e-3, 0.0), (0.0, 1e-3)):  # any other state at this depth fits worse
            g = sum(
                (mu[i] - model.project(model.G([x3 + dx, y3, v + dv], i - 2))) ** 2
                for i in range(3)
            )
            assert g > got


def test_profile_misfit_tends_to_the_far_limit():
    mu = FIG2.mu
    far = model.far_misfit(mu)
    assert far == pytest.approx(0.1**2 / 6, rel=1e-12)  # mu1 - 2 mu2 + mu3 = -0.1
    # the misfit approaches its limit like 1 / y: within 1e-4 relative at y = 1e6
    assert model.profile_misfit(mu, [1e6])[0] == pytest.approx(far, rel=1e-4)
    with pytest.raises(ValueError, match="depths > 2"):
        model.profile_misfit(mu, [2.0])


def test_eq7_eq17_eq18_paper_values():
    assert_allclose(noise_free_state(MU_17), [6 / 5, 6, 6 / 5], rtol=1e-14)
    assert_allclose(noise_free_state(MU_18), [2, 10, 2], rtol=1e-14)


@settings(max_examples=60, deadline=None)
@given(states())
def test_eq7_recovers_the_state_from_noise_free_bearings(c):
    mu = bearings(c)
    assert_allclose(noise_free_state(mu), c, rtol=1e-7, atol=1e-9)
    assert f(noise_free_state(mu), mu) == pytest.approx(0.0, abs=1e-20)


@settings(max_examples=30, deadline=None)
@given(states())
def test_eq7_noise_free_depth_is_the_depth_of_the_noise_free_state(c):
    mu = np.stack([bearings(c), bearings(c)])
    assert_allclose(model.noise_free_depth_unchecked(mu), [c[1], c[1]], rtol=1e-7)
    assert model.noise_free_depth_unchecked(mu[0]) == noise_free_state(mu[0])[1]


def test_eq5_f_is_sum_of_squared_residuals_in_time_order():
    x = np.array([1.0, 5.0, 0.5])
    mu = np.array([-0.3, 0.0, 0.2])
    expected = [
        (x[0] - 2 * x[2]) / (x[1] - 2) - mu[0],
        (x[0] - x[2]) / (x[1] - 1) - mu[1],
        x[0] / x[1] - mu[2],
    ]
    assert_allclose(residuals(x, mu), expected)
    assert f(x, mu) == pytest.approx(np.sum(np.square(expected)))


def test_noise_free_states_names_the_bad_row():
    with pytest.raises(ValueError, match=r"mu\[1\] is degenerate"):
        noise_free_states([MU_17, (0.1, 0.1, 0.1)])
    with pytest.raises(ValueError, match=r"mu\[0\] puts the point behind the camera"):
        noise_free_states([(0.2, 0.0, -0.3), MU_17])


def test_eq20_eq21_eq22_residuals_are_linear_in_the_observation_vectors_near_c():
    mu = MU_17
    c = noise_free_state(mu)
    g = residual_gradients(c)
    rng = np.random.default_rng(2)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    rest = [np.max(np.abs(residuals(c + eps * d, mu) - g @ (eps * d))) for eps in (1e-2, 1e-3)]
    # the remainder is O(|x - c|^2): ten times closer, a hundred times smaller
    assert rest[1] / rest[0] == pytest.approx(1e-2, rel=0.05)
