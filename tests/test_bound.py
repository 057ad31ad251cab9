"""The Cramér-Rao bound on the state at frame N (Tichavský et al. 1998, Eq. (21)),
against batch Fisher informations computed directly, and its limiting cases."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthbook import beyond_bound
from depthcore import SCENARIOS
from depthcore.analysis import bound
from depthcore.problem import model

FIG2 = SCENARIOS["fig2"]
RHO = FIG2.rho
P = 1000.0 * np.eye(3)
# States at frame 1, in front of the camera, with and without lateral motion.
STARTS = [model.G(FIG2.c, -2), np.array([0.5, 3.0, -0.2]), np.array([-2.0, 10.0, 0.0])]


def _track(x1, n):
    return np.stack([model.G(x1, k) for k in range(n)])


def _batch_bound_constant_velocity(s_n, n, rho, prior_cov):
    """The bound on s_N from all N bearings at once: Eqs. (20)-(22) generalised.

    J = sum_k g_k g_k^T / rho^2 + F^{-(N-1)T} P^{-1} F^{-(N-1)}, g_k the gradient of
    bearing k with respect to the state at frame N.
    """
    g = model.residual_gradients(s_n, n)
    J = g.T @ g / rho**2
    if prior_cov is not None:
        f_back = model.G_linear(-(n - 1))  # s_1 = F^{-(N-1)} s_N - const
        J = J + f_back.T @ np.linalg.inv(prior_cov) @ f_back
    return np.linalg.inv(J)


def _bearings_of(theta, n, steps):
    """Bearings of frames 1..N as a function of theta = (s_1, a_k for the steps in ``steps``)."""
    x, y, v = theta[0], theta[1], theta[2]
    a = dict(zip(steps, theta[3:], strict=True))
    out = []
    for k in range(1, n + 1):
        out.append(model.project(np.array([x, y, v])))
        x, y, v = x + v, y + 1.0, v + a.get(k, 0.0)
    return np.array(out)


def _state_n(theta, n, steps):
    """The state at frame N as a function of theta (linear)."""
    x, y, v = theta[0], theta[1], theta[2]
    a = dict(zip(steps, theta[3:], strict=True))
    for k in range(1, n):
        x, y, v = x + v, y + 1.0, v + a.get(k, 0.0)
    return np.array([x, y, v])


def _jacobian(fun, theta, h=1e-6):
    cols = []
    for i in range(len(theta)):
        d = np.zeros_like(theta)
        d[i] = h * max(1.0, abs(theta[i]))
        cols.append((fun(theta + d) - fun(theta - d)) / (2 * d[i]))
    return np.stack(cols, axis=-1)


def _batch_bound_with_accelerations(x1, accelerations, q_steps, rho, prior_cov):
    """The bound on s_N over theta = (s_1, a_1 .. a_{N-1}), by finite differences.

    Bayesian information of the whole trajectory: the bearings' Jacobian, the prior's
    P^{-1} on s_1 and 1 / q_k^2 on each acceleration whose q_k > 0 (the others are 0);
    then the bound on the linear map s_N(theta).
    """
    n = len(q_steps) + 1
    steps = [k + 1 for k in range(n - 1) if q_steps[k] > 0]
    theta = np.concatenate([x1, [accelerations[k - 1] for k in steps]])
    H = _jacobian(lambda t: _bearings_of(t, n, steps), theta)
    J = H.T @ H / rho**2
    prior = np.zeros((len(theta), len(theta)))
    if prior_cov is not None:
        prior[:3, :3] = np.linalg.inv(prior_cov)
    for i, k in enumerate(steps):
        prior[3 + i, 3 + i] = 1.0 / q_steps[k - 1] ** 2
    A = _jacobian(lambda t: _state_n(t, n, steps), theta)
    return A @ np.linalg.inv(J + prior) @ A.T


def _states_with(x1, accelerations):
    n = len(accelerations) + 1
    x, y, v = x1
    out = []
    for k in range(n):
        out.append([x, y, v])
        if k < n - 1:
            x, y, v = x + v, y + 1.0, v + accelerations[k]
    return np.array(out)


@pytest.mark.parametrize("x1", STARTS)
@pytest.mark.parametrize("n", [3, 7, 30])
@pytest.mark.parametrize("prior_cov", [P, np.diag([4.0, 9.0, 1.0]), None])
def test_recursion_without_process_noise_is_the_batch_information(x1, n, prior_cov):
    """Tichavský et al. (1998), Eq. (21) with q = 0 against the sum of the outer products
    of the residual gradients, Eqs. (20)-(22), at every frame k from 3 to N."""
    B = bound.conditional_bound(_track(x1, n), RHO, prior_cov)
    for k in range(3, n + 1):
        s_k = model.G(x1, k - 1)
        assert_allclose(
            B[k - 1], _batch_bound_constant_velocity(s_k, k, RHO, prior_cov), rtol=1e-7, atol=0
        )


def test_the_prior_vanishing_gives_the_bound_of_the_bearings_alone():
    """P = s I with s growing: the bound tends to the bearings' own, with an error O(1 / s)."""
    x1, n = STARTS[0], 10
    alone = bound.conditional_bound(_track(x1, n), RHO)[-1]
    assert_allclose(
        alone, _batch_bound_constant_velocity(model.G(x1, n - 1), n, RHO, None), rtol=1e-7
    )
    gaps = []
    for s in (1e2, 1e4, 1e6):
        B = bound.conditional_bound(_track(x1, n), RHO, s * np.eye(3))[-1]
        assert np.all(np.linalg.eigvalsh(alone - B) > -1e-12 * np.abs(alone).max())  # prior helps
        gaps.append(np.abs(B - alone).max() / np.abs(alone).max())
    assert gaps[2] < 1e-5
    assert_allclose(np.array(gaps[:2]) / np.array(gaps[1:]), 100.0, rtol=0.05)


def test_the_bearings_alone_need_three_frames_and_refuse_fewer():
    track = _track(STARTS[0], 2)
    with pytest.raises(ValueError, match="information is singular"):
        bound.conditional_bound(track, RHO)
    assert np.all(np.isfinite(bound.conditional_bound(track, RHO, P)))


@pytest.mark.parametrize("n", [3, 12])
def test_the_bound_scales_as_rho_squared(n):
    """Without a prior the bound is rho^2 times that of rho = 1 exactly; with one, it
    tends to it as rho -> 0, with a relative gap falling like rho^2."""
    track = _track(STARTS[1], n)
    unit = bound.conditional_bound(track, 1.0)[-1]
    for rho in (1e-1, 1e-3, 1e-5):
        assert_allclose(bound.conditional_bound(track, rho)[-1] / rho**2, unit, rtol=1e-9)
    gaps = [
        np.abs(bound.conditional_bound(track, rho, P)[-1] / rho**2 - unit).max()
        / np.abs(unit).max()
        for rho in (1e-2, 1e-3, 1e-4)
    ]
    assert gaps[-1] < 1e-6
    assert_allclose(np.array(gaps[:2]) / np.array(gaps[1:]), 100.0, rtol=0.05)


def test_one_frame_of_process_noise_against_its_closed_form():
    """Five frames, one acceleration a_3 ~ N(0, q^2) over the step 3 -> 4: the bound on s_5
    from the batch information of theta = (x_1, y_1, v_1, a_3), whose bearing gradients are
    (1 / y_k, -x_k / y_k^2, (k - 1) / y_k, (k - 4)_+ / y_k), against the recursion."""
    x1, q, n = STARTS[0], 0.05, 5
    a3 = 0.03
    states = _states_with(x1, [0.0, 0.0, a3, 0.0])
    x, y = states[:, 0], states[:, 1]
    k = np.arange(1, n + 1)
    H = np.stack([1 / y, -x / y**2, (k - 1) / y, np.maximum(k - 4, 0) / y], axis=1)
    J = H.T @ H / RHO**2
    J[:3, :3] += np.linalg.inv(P)
    J[3, 3] += 1 / q**2
    A = np.array([[1.0, 0, 4, 1], [0, 1, 0, 0], [0, 0, 1, 1]])  # s_5 = A theta + (0, 4, 0)
    expected = A @ np.linalg.inv(J) @ A.T
    B = bound.conditional_bound(states, RHO, P, [0.0, 0.0, q, 0.0])
    assert_allclose(B[-1], expected, rtol=1e-8)


@pytest.mark.parametrize("n", [4, 9])
@pytest.mark.parametrize("first", [1, 3])
def test_recursion_with_process_noise_is_the_batch_over_the_accelerations(n, first):
    """Eq. (21) with q > 0 from step ``first`` on, conditional on a drawn track, against the
    Bayesian information of (s_1, a) by finite differences of the bearings."""
    rng = np.random.default_rng(n + first)
    q = 0.02
    q_steps = np.where(np.arange(1, n) >= first, q, 0.0)
    a = q_steps * rng.standard_normal(n - 1)
    states = _states_with(STARTS[0], a)
    B = bound.conditional_bound(states, RHO, P, q_steps)
    expected = _batch_bound_with_accelerations(STARTS[0], a, q_steps, RHO, P)
    assert_allclose(B[-1], expected, rtol=2e-5, atol=0)
    # and without a prior, where J_1 is singular: the Sherman-Morrison step needs no inverse
    B0 = bound.conditional_bound(states, RHO, None, q_steps)
    assert_allclose(
        B0[-1], _batch_bound_with_accelerations(STARTS[0], a, q_steps, RHO, None), rtol=2e-5
    )


def test_process_noise_widens_the_bound_and_zero_noise_is_constant_velocity():
    states = _track(STARTS[0], 12)
    still = bound.conditional_bound(states, RHO, P)
    assert_allclose(bound.conditional_bound(states, RHO, P, 0.0), still, rtol=0, atol=0)
    noisy = bound.conditional_bound(states, RHO, P, 0.01)
    gap = noisy[-1] - still[-1]
    assert np.linalg.eigvalsh(gap).min() > 0


def test_expected_information_against_monte_carlo_over_the_accelerations():
    """The posterior bound's E[I_k] (Tichavský et al. 1998) in closed form, against its
    Monte Carlo mean over 20,000 tracks drawn with the truth at time 3 and accelerations
    from time 3 on: every entry within 4.5 standard errors."""
    n, q = 20, 0.05
    t = bound.track_moments(FIG2.c, 3, n, q)
    exact = bound.expected_measurement_information(
        t.mean[:, 1], t.mean[:, [0, 2]], t.lateral_cov, RHO
    )
    sim = model.simulate(FIG2.c, n - 2, RHO, q, np.random.default_rng(7), size=20_000, frame=1)
    early = np.broadcast_to(t.mean[:2], (20_000, 2, 3))
    states = np.concatenate([early, sim.states], axis=1)
    draws = bound.measurement_information(states, RHO)
    mc, se = draws.mean(axis=0), draws.std(axis=0, ddof=1) / np.sqrt(len(draws))
    assert_allclose(mc[:, 2, :], 0.0)
    assert_allclose(mc[:, 0, 0], exact[:, 0, 0], rtol=1e-11)  # the depth is exact
    varying = se > 1e-8 * np.abs(exact).max()  # x_k varies from frame 5 on
    assert varying[4:, 1, 1].all() and not varying[:4].any()
    z = np.abs(mc - exact)[varying] / se[varying]
    assert z.max() < 4.5, z.max()
    # the moments of the track: the simulated states' mean and lateral covariance
    assert_allclose(sim.states[:, -1].mean(axis=0), t.mean[-1], atol=5 * q * n / np.sqrt(2e4))
    lat = sim.states[:, -1][:, [0, 2]]
    assert_allclose(np.cov(lat.T), t.lateral_cov[-1], rtol=0.05)


def test_the_posterior_bound_is_the_batch_with_the_expected_information():
    """The recursion with E[I_k] is the bound of the expected batch information of the
    whole trajectory: Eq. (21) and the batch agree on the same Monte Carlo sample, and
    with q = 0 the posterior bound is the conditional bound of the one known track."""
    n, q = 8, 0.03
    q_steps = np.where(np.arange(1, n) >= 3, q, 0.0)
    rng = np.random.default_rng(3)
    x1 = model.G(FIG2.c, -2)
    steps = [k for k in range(1, n) if q_steps[k - 1] > 0]
    sums_rec = np.zeros((n, 3, 3))
    sum_batch = None
    A = None
    for _ in range(200):
        a = q_steps * rng.standard_normal(n - 1)
        states = _states_with(x1, a)
        sums_rec += bound.measurement_information(states, RHO)
        theta = np.concatenate([x1, a[np.array(steps) - 1]])
        H = _jacobian(lambda t: _bearings_of(t, n, steps), theta)
        sum_batch = H.T @ H if sum_batch is None else sum_batch + H.T @ H
        A = _jacobian(lambda t: _state_n(t, n, steps), theta)
    J = sum_batch / 200 / RHO**2
    J[:3, :3] += np.linalg.inv(P)
    J[3:, 3:] += np.diag(1 / q_steps[np.array(steps) - 1] ** 2)
    batch = A @ np.linalg.inv(J) @ A.T
    rec = bound.covariance_bound(bound.information(sums_rec / 200, P, q_steps))[-1]
    assert_allclose(rec, batch, rtol=2e-5)
    fixed = bound.posterior_bound(FIG2.c, 3, n, RHO, P, 0.0)
    assert_allclose(fixed, bound.conditional_bound(_track(x1, n), RHO, P), rtol=1e-9, atol=1e-12)


def test_the_posterior_bound_lies_below_the_average_conditional_bound():
    """Jensen: the inverse of the expected information is below the expected inverse;
    the gap in the depth exceeds 10 Monte Carlo standard errors of the average."""
    n, q = 25, 0.05
    post = bound.posterior_bound(FIG2.c, 3, n, RHO, P, q)[-1]
    sim = model.simulate(FIG2.c, n - 2, RHO, q, np.random.default_rng(11), size=2000, frame=1)
    t = bound.track_moments(FIG2.c, 3, n, q)
    states = np.concatenate([np.broadcast_to(t.mean[:2], (2000, 2, 3)), sim.states], axis=1)
    cond = bound.conditional_bound(states, RHO, P, t.process_noise)[:, -1]
    depth = cond[:, 1, 1]
    se = depth.std(ddof=1) / np.sqrt(len(depth))
    assert depth.mean() - post[1, 1] > 10 * se


def test_against_bound_scores_and_flags():
    rng = np.random.default_rng(0)
    sigma = 2.0
    e = sigma * rng.standard_normal((2, 3, 4000))
    s = np.broadcast_to(np.array([1.0, 2.0, 3.0])[:, None], (2, 3, 4000))
    r = bound.against_bound(e, s, sigma)
    assert r["rmse"].shape == (2, 3)
    assert np.all(np.abs(r["rmse"] - sigma) < 4 * r["rmse_se"])
    assert_allclose(r["rmse_se"], sigma / np.sqrt(2 * 4000), rtol=0.1)  # Gaussian errors
    assert_allclose(r["sd_ratio"], [[0.5, 1.0, 1.5]] * 2)
    assert r["overconfident"].tolist() == [[True, False, False]] * 2
    # the RMSE's standard error is honest: the spread of 300 independent RMSEs
    many = bound.against_bound(sigma * rng.standard_normal((300, 200)), np.ones((300, 200)), 1.0)
    assert_allclose(many["rmse"].std(ddof=1), many["rmse_se"].mean(), rtol=0.15)


def test_against_bound_refuses_bad_input_by_name():
    with pytest.raises(ValueError, match="errors and sds"):
        bound.against_bound(np.zeros(5), np.zeros(4), 1.0)
    with pytest.raises(ValueError, match="bound_sd"):
        bound.against_bound(np.zeros(5), np.zeros(5), 0.0)
    with pytest.raises(ValueError, match="sds"):
        bound.against_bound(np.zeros(5), -np.ones(5), 1.0)


def test_refusals_name_the_argument():
    track = _track(STARTS[0], 5)
    with pytest.raises(ValueError, match="process_noise"):
        bound.conditional_bound(track, RHO, P, [0.1, 0.1])
    with pytest.raises(ValueError, match="process_noise"):
        bound.conditional_bound(track, RHO, P, -0.1)
    with pytest.raises(ValueError, match="states"):
        bound.conditional_bound(track - [0, 10, 0], RHO, P)
    with pytest.raises(ValueError, match="rho"):
        bound.conditional_bound(track, 0.0, P)
    with pytest.raises(ValueError, match="prior_cov"):
        bound.conditional_bound(track, RHO, -P)
    with pytest.raises(ValueError, match="frame"):
        bound.posterior_bound(FIG2.c, 6, 5, RHO, P)
    with pytest.raises(ValueError, match="depth"):
        bound.expected_measurement_information([-1.0], [[0.0, 0.0]], np.zeros((1, 2, 2)), RHO)


def test_bound_study_simulates_the_truth_at_time_three():
    """Frames 1-3 are the truth's by G; accelerations act from time 3 on; the filters'
    errors are against the track's own state at frame N."""
    r = beyond_bound.bound_study([3, 6], 30, 2, ("optimal", "ekf"), "fixed", 0.05)
    s = r["states"]
    assert_allclose(s[:, 0], np.broadcast_to(FIG2.c, s[:, 0].shape), rtol=0, atol=0)
    assert_allclose(s[:, 1, 1], FIG2.c[1] + 3)
    assert s[:, 1, 2].std() > 0  # the velocity has changed by frame 6
    assert r["ekf"]["depth_error"].shape == (2, 30 - r["rejected_trials"])
    with pytest.raises(ValueError, match="names: particle"):
        beyond_bound.bound_study([3, 6], 10, 2, ("particle",), "fixed", 0.05)
    again = beyond_bound.bound_study([6], 30, 2, ("ekf",), "fixed", 0.05)
    assert_allclose(again["ekf"]["depth_error"][0], r["ekf"]["depth_error"][1])


def test_bound_figure_draws_each_filter_over_the_bound_and_rings_the_overconfident():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = np.array([3, 6])
    r = beyond_bound.bound_study(frames, 30, 2, ("optimal", "ekf"), "fixed")
    b = np.sqrt(bound.posterior_bound(FIG2.c, 3, 6, RHO, 1000.0 * np.eye(3))[frames - 1, 1, 1])
    against = {
        n: bound.against_bound(r[n]["depth_error"], r[n]["depth_sd"], b)
        for n in r
        if n in ("optimal", "ekf")
    }
    fig = beyond_bound.bound_figure(frames, [("$q = 0$", against), ("again", against)])
    try:
        assert len(fig.axes) == 4
        top, bottom = fig.axes[0], fig.axes[2]
        # one error bar per filter; the ratios plotted are against_bound's
        assert len(top.containers) == 2
        line = top.containers[0].lines[0]
        assert_allclose(line.get_ydata(), against["optimal"]["rmse_ratio"])
        rings = [x for x in bottom.lines if x.get_label().startswith("stated SD")]
        over = sum(int(a["overconfident"].sum()) for a in against.values())
        assert sum(len(x.get_xdata()) for x in rings) == over
    finally:
        plt.close(fig)
