"""Tracks as they come for the UKF, the inverse-depth EKF and UKF, the modified-polar EKF and
the range-parametrised EKF: gaps, noise per frame, uneven steps, the gate and the per-frame
predictive report, each against an independent route (the recursion run by hand, or the
track with its missing frame removed and a step of 2)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.kalman import ekf, inverse_depth, inverse_depth_ukf, modified_polar, range_ekf, ukf
from depthcore.problem import model, predictive
from depthcore.problem.gaussian import paper_prior
from depthcore.problem.scenarios import SCENARIOS

FIG2 = SCENARIOS["fig2"]

#: A point at depth 6 moving sideways, seen over six frames; a prior that keeps every sigma
#: point in front of the camera.
TRUTH = np.array([0.4, 6.0, 0.25])
MU = np.array([model.project(model.G(TRUTH, k)) for k in range(6)]) + [
    0.002,
    -0.003,
    0.001,
    0.0025,
    -0.001,
    0.002,
]
RHO = 0.005
MEAN = TRUTH + [0.1, 0.5, -0.05]
COV = np.diag([0.05, 1.0, 0.02])
Q = 0.02


def _estimate(name, mu, rho, q=0.0, **kw):
    """The door's estimate of the state at the last frame, and its per-frame updates."""
    if name == "ukf":
        h = ukf.run(mu, rho, MEAN, COV, q, **kw)
        return h.means[..., -1, :], h.covs[..., -1, :, :], h.updates
    if name == "range_ekf":
        g = range_ekf.posterior(mu, rho, MEAN, COV, q, n_components=16, **kw)
        return g.mean, g.cov, g.updates
    door = {
        "inverse_depth": inverse_depth.estimate,
        "inverse_depth_ukf": inverse_depth_ukf.estimate,
        "modified_polar": modified_polar.estimate,
    }[name]
    e = door(mu, rho, MEAN, COV, q, **kw)
    return e.mean, e.cov, e.updates


DOORS = ["ukf", "inverse_depth", "inverse_depth_ukf", "modified_polar", "range_ekf"]


# --- the paper's frames: unchanged ------------------------------------------------------


@pytest.mark.parametrize("name", DOORS)
def test_unit_steps_and_one_rho_per_frame_are_the_paper_frames_exactly(name):
    a = _estimate(name, MU, RHO, Q)
    b = _estimate(name, MU, np.full(6, RHO), Q, steps=np.ones(5))
    for x, y in zip(a[:2], b[:2], strict=True):
        assert np.array_equal(x, y)
    assert np.all(np.isfinite(a[2].tail)) and not np.any(a[2].gated)


# --- gaps: the recursion by hand, and the frame removed with a step of 2 ----------------


def _by_hand(name, mu, rho, steps, q=0.0):
    """The filter's own predict and update functions, skipping the missing frames."""
    rho = np.broadcast_to(rho, mu.shape)
    t = np.concatenate([[0.0], np.cumsum(steps)])
    if name == "ukf":
        n, C = MEAN, COV
    else:
        n, C = inverse_depth.prior(MEAN, COV)
    for k in range(len(mu)):
        if k:
            if name == "ukf":
                n, C = ekf.predict(n, C, q, steps[k - 1])
            elif name == "inverse_depth":
                n, C = inverse_depth.predict(n, C, q, steps[k - 1])
            elif name == "inverse_depth_ukf":
                n, C = inverse_depth_ukf.predict(n, C, q, steps[k - 1])
            else:
                n, C = modified_polar.predict(n, C, q, steps[k - 1])
        if np.isnan(mu[k]):
            continue
        if name == "ukf":
            n, C = ukf.update(n, C, mu[k], rho[k])
        elif name == "inverse_depth":
            n, C = inverse_depth.update(n, C, mu[k], rho[k], k + 1, elapsed=t[k])
        elif name == "inverse_depth_ukf":
            n, C = inverse_depth_ukf.update(n, C, mu[k], rho[k], k + 1, elapsed=t[k])
        else:
            n, C = modified_polar.update(n, C, mu[k], rho[k])
    if name == "ukf":
        return n, C
    if name == "inverse_depth":
        return inverse_depth.to_state(n, C, len(mu), elapsed=t[-1])
    if name == "inverse_depth_ukf":
        return inverse_depth_ukf.to_state(n, C, len(mu), elapsed=t[-1])
    return inverse_depth.to_state(n, C, 1)


HAND = ["ukf", "inverse_depth", "inverse_depth_ukf", "modified_polar"]


@pytest.mark.parametrize("name", HAND)
def test_a_gap_is_the_recursion_run_by_hand_without_that_update(name):
    mu = MU.copy()
    mu[[2, 4]] = np.nan
    mean, cov, updates = _estimate(name, mu, RHO, Q)
    m, P = _by_hand(name, mu, RHO, np.ones(5), Q)
    assert_allclose(mean, m, rtol=1e-12, atol=1e-14)
    assert_allclose(cov, P, rtol=1e-10, atol=1e-14)
    assert np.all(np.isnan(updates.tail[[2, 4]]))
    assert np.all(np.isnan(updates.log_predictive[[2, 4]]))
    assert np.all(np.isfinite(updates.tail[[0, 1, 3, 5]])) and not np.any(updates.gated)


@pytest.mark.parametrize("name", DOORS)
def test_a_gap_equals_the_frame_removed_and_a_step_of_two_without_process_noise(name):
    mu = MU.copy()
    mu[3] = np.nan
    mean, cov, updates = _estimate(name, mu, RHO)
    short = np.delete(MU, 3)
    m, P, u = _estimate(name, short, RHO, steps=[1.0, 1.0, 2.0, 1.0])
    assert_allclose(mean, m, rtol=1e-9, atol=1e-12)
    assert_allclose(cov, P, rtol=1e-8, atol=1e-12)
    assert_allclose(np.delete(updates.log_predictive, 3), u.log_predictive, rtol=1e-9)


def test_with_process_noise_two_unit_steps_differ_from_one_step_of_two_by_the_midway_kick():
    # C2 = F (F P F^T + Q) F^T + Q against F_2 P F_2^T + 2 Q: the velocity's change at the
    # missing frame moves x over the second step, adding q**2 (1 0 1; 0 0 0; 1 0 0).
    n, C = ekf.predict(*ekf.predict(MEAN, COV, Q), Q)
    n2, C2 = ekf.predict(MEAN, COV, Q, 2.0)
    assert_allclose(n, n2, rtol=1e-15)
    assert_allclose(C - C2, Q**2 * np.array([[1.0, 0, 1], [0, 0, 0], [1, 0, 0]]), atol=1e-15)
    # ... so a gap at q > 0 is not the frame removed with a step of 2.
    mu = MU.copy()
    mu[3] = np.nan
    gap = ukf.run(mu, RHO, MEAN, COV, Q).means[-1]
    step = ukf.run(np.delete(MU, 3), RHO, MEAN, COV, Q, steps=[1, 1, 2, 1]).means[-1]
    assert not np.allclose(gap, step, rtol=1e-6)


def test_gaps_are_masked_row_by_row_in_a_batch():
    mu = np.stack([MU, MU, MU])
    mu[1, 2] = np.nan
    mu[2, [1, 4]] = np.nan
    for name in DOORS:
        batch = _estimate(name, mu, RHO, Q)
        for b in range(3):
            one = _estimate(name, mu[b], RHO, Q)
            assert_allclose(batch[0][b], one[0], rtol=1e-12, atol=1e-14, err_msg=name)
            assert_allclose(batch[1][b], one[1], rtol=1e-10, atol=1e-14, err_msg=name)
            assert_allclose(batch[2].tail[b], one[2].tail, rtol=1e-10, err_msg=name)


def test_the_range_parametrised_ekf_with_a_gap_is_each_component_by_hand():
    mu = MU.copy()
    mu[2] = np.nan
    g = range_ekf.posterior(mu, RHO, MEAN, COV, Q, n_components=8)
    start = range_ekf.components(MEAN, COV, 8)
    log_w, means = [], []
    for i in range(8):
        m, P, lw = start.mean[i], start.cov[i], start.log_weight[i]
        for k in range(6):
            if k:
                m, P = ekf.predict(m, P, Q)
            if np.isnan(mu[k]):
                continue
            lw += predictive.gaussian(mu[k], *ekf.bearing_predictive(m, P, RHO))[0]
            m, P = ekf.update(m, P, mu[k], RHO)
        log_w.append(lw)
        means.append(m)
    w = np.exp(np.array(log_w) - max(log_w))
    assert_allclose(g.weight, w / w.sum(), rtol=1e-8, atol=1e-300)
    assert_allclose(g.mean, (w / w.sum()) @ np.array(means), rtol=1e-8)
    assert np.isnan(g.updates.tail[2]) and np.all(np.isfinite(np.delete(g.updates.tail, 2)))


# --- rho per frame ----------------------------------------------------------------------


@pytest.mark.parametrize("name", HAND)
def test_rho_per_frame_is_the_recursion_by_hand_with_each_frames_rho(name):
    rho = RHO * np.array([1.0, 2.0, 0.5, 1.5, 3.0, 1.0])
    mean, cov, _ = _estimate(name, MU, rho, Q)
    m, P = _by_hand(name, MU, rho, np.ones(5), Q)
    assert_allclose(mean, m, rtol=1e-12, atol=1e-14)
    assert_allclose(cov, P, rtol=1e-10, atol=1e-14)


def test_rho_per_frame_in_the_range_parametrised_ekf_scales_each_frames_likelihood():
    rho = RHO * np.array([1.0, 2.0, 0.5, 1.5, 3.0, 1.0])
    g = range_ekf.posterior(MU, rho, MEAN, COV, n_components=8)
    # frame 1's report is the prior mixture's predictive with frame 1's rho
    start = range_ekf.components(MEAN, COV, 8)
    means, var = range_ekf.component_predictive(start.mean, start.cov, rho[0])
    expected = predictive.mixture(MU[0], start.log_weight, means, var)
    assert_allclose(g.updates.log_predictive[0], expected[0], rtol=1e-13)
    assert_allclose(g.updates.tail[0], expected[1], rtol=1e-12)
    assert not np.allclose(g.mean, range_ekf.posterior(MU, RHO, MEAN, COV, n_components=8).mean)


# --- steps: each filter's own coordinates -----------------------------------------------


def _to_state(z, t):
    """Inverse-depth coordinates anchored at frame 1 back to ``(x, y, v)`` at depth travelled t."""
    return np.array([z[0] / z[1], 1.0 / z[1] + t, z[2] / z[1]])


@pytest.mark.parametrize("step", [0.5, 1.0, 2.7])
def test_the_inverse_depth_motion_over_a_step_is_g_re_expressed(step):
    z = np.array([0.07, 0.15, 0.04])  # y_1 = 6.67
    t = 1.3  # depth already travelled since frame 1
    x = _to_state(z, t)
    moved = model.G(x, step)
    w = 1.0 / (moved[1] - t - step)  # the anchor's inverse depth, unchanged
    expected = np.array([moved[0] * w, w, moved[2] * w])
    mean, cov = inverse_depth.predict(z, np.eye(3), 0.0, step)
    assert_allclose(mean, expected, rtol=1e-14)
    F = np.array([[1.0, 0.0, step], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert_allclose(cov, F @ F.T, rtol=1e-15)
    # the velocity noise a ~ N(0, q**2 s) enters s' = v / y_1 as w a
    noisy = inverse_depth.predict(z, np.zeros((3, 3)), 0.1, step).cov
    assert_allclose(noisy[2, 2], (z[1] * 0.1) ** 2 * step, rtol=1e-14)
    ukf_noisy = inverse_depth_ukf.predict(z, np.diag([0.0, 0.01, 0.0]), 0.1, step).cov
    assert_allclose(ukf_noisy[2, 2], (z[1] ** 2 + 0.01) * 0.1**2 * step, rtol=1e-14)
    # the bearing at the depth travelled is the state's x / y
    assert_allclose(
        inverse_depth_ukf.bearing(mean, 0, elapsed=t + step), model.project(moved), rtol=1e-14
    )


@pytest.mark.parametrize("step", [0.5, 1.0, 2.7])
def test_the_modified_polar_motion_over_a_step_is_g_re_expressed(step):
    x = np.array([0.8, 5.0, -0.3])
    u = np.array([x[0], 1.0, x[2]]) / x[1]
    moved = model.G(x, step)
    expected = np.array([moved[0], 1.0, moved[2]]) / moved[1]
    assert_allclose(modified_polar.transition(u, step), expected, rtol=1e-14)
    # the Jacobian against central differences
    eps = 1e-6
    numeric = np.stack(
        [
            (
                modified_polar.transition(u + eps * e, step)
                - modified_polar.transition(u - eps * e, step)
            )
            / (2 * eps)
            for e in np.eye(3)
        ],
        axis=-1,
    )
    assert_allclose(modified_polar.transition_jacobian(u, step), numeric, rtol=1e-8, atol=1e-10)
    # the velocity noise a ~ N(0, q**2 s) enters nu = v / y as omega a / D
    noisy = modified_polar.predict(u, np.zeros((3, 3)), 0.1, step).cov
    D = 1.0 + step * u[1]
    assert_allclose(noisy[2, 2], (u[1] * 0.1 / D) ** 2 * step, rtol=1e-14)


@pytest.mark.parametrize("name", HAND)
def test_uneven_steps_are_the_recursion_by_hand(name):
    steps = np.array([0.5, 1.5, 2.0, 0.7, 1.2])
    rho = RHO * np.array([1.0, 2.0, 0.5, 1.5, 3.0, 1.0])
    mu = np.array([model.project(model.G(TRUTH, t)) for t in np.r_[0, np.cumsum(steps)]])
    mu[2] = np.nan
    mean, cov, _ = _estimate(name, mu, rho, Q, steps=steps)
    m, P = _by_hand(name, mu, rho, steps, Q)
    assert_allclose(mean, m, rtol=1e-12, atol=1e-14)
    assert_allclose(cov, P, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("name", DOORS)
def test_with_uneven_steps_the_filters_find_the_point(name):
    steps = np.array([0.5, 1.5, 2.0, 0.7, 1.2])
    t = np.r_[0, np.cumsum(steps)]
    mu = np.array([model.project(model.G(TRUTH, s)) for s in t])
    mean, cov, _ = _estimate(name, mu, 1e-4, steps=steps)
    truth = model.G(TRUTH, t[-1])
    assert abs(mean[1] - truth[1]) < 0.02 * truth[1]
    assert abs(mean[2] - truth[2]) < 0.02 * abs(truth[2])


# --- the per-frame report and the gate --------------------------------------------------


def test_the_ukf_reports_the_unscented_predictive_density():
    h = ukf.run(MU, RHO, MEAN, COV, Q)
    n, C = MEAN, COV
    for k in range(6):
        if k:
            n, C = ekf.predict(h.means[k - 1], h.covs[k - 1], Q)
        z, s = ukf.bearing_predictive(n, C, RHO)
        # the unscented moments by hand: six points n +- sqrt(3) L_j, weight 1/6 each
        L = np.linalg.cholesky(3.0 * C)
        Z = np.array([model.project(n + sign * L[:, j]) for j in range(3) for sign in (1, -1)])
        assert_allclose(z, Z.mean(), rtol=1e-13)
        assert_allclose(s, RHO**2 + np.mean((Z - Z.mean()) ** 2), rtol=1e-10)
        log_p, tail = predictive.gaussian(MU[k], z, s)
        assert_allclose(h.updates.log_predictive[k], log_p, rtol=1e-13)
        assert_allclose(h.updates.tail[k], tail, rtol=1e-12)


@pytest.mark.parametrize("name", HAND)
def test_the_gaussian_filters_report_their_own_predictive(name):
    """EKF-type: the linearised innovation's moments; modified polar: the bearing coordinate."""
    mean, cov, updates = _estimate(name, MU, RHO)
    history = {
        "ukf": ukf.run,
        "inverse_depth": inverse_depth.run,
        "inverse_depth_ukf": inverse_depth_ukf.run,
        "modified_polar": modified_polar.run,
    }[name](MU, RHO, MEAN, COV)
    assert_allclose(updates.tail, history.updates.tail, rtol=1e-14)
    if name == "inverse_depth":
        z, S = inverse_depth.predict(history.means[2], history.covs[2])
        m, v = inverse_depth.bearing_predictive(z, S, RHO, 4)
        h = inverse_depth.observation_vector(z, 4)
        assert_allclose(m, z[0] / (1 + 3 * z[1]), rtol=1e-15)
        assert_allclose(v, h @ S @ h + RHO**2, rtol=1e-14)
        assert_allclose(updates.log_predictive[3], predictive.gaussian(MU[3], m, v)[0], rtol=1e-13)
    if name == "modified_polar":
        u, U = modified_polar.predict(history.means[2], history.covs[2])
        lp = predictive.gaussian(MU[3], u[0], U[0, 0] + RHO**2)[0]
        assert_allclose(updates.log_predictive[3], lp, rtol=1e-13)


@pytest.mark.parametrize("name", DOORS)
def test_a_gate_skips_an_outlier_as_a_missing_bearing(name):
    mu = MU.copy()
    mu[3] += 0.2  # forty noise SDs
    mean, cov, updates = _estimate(name, mu, RHO, Q, gate=1e-4)
    assert updates.gated.tolist() == [False, False, False, True, False, False]
    assert updates.tail[3] < 1e-4 and np.all(updates.tail[[0, 1, 2, 4, 5]] >= 1e-4)
    missing = mu.copy()
    missing[3] = np.nan
    m, P, u = _estimate(name, missing, RHO, Q)
    assert_allclose(mean, m, rtol=1e-13, atol=1e-15)
    assert_allclose(cov, P, rtol=1e-13, atol=1e-15)
    assert np.isnan(u.tail[3])
    assert_allclose(np.delete(updates.tail, 3), np.delete(u.tail, 3), rtol=1e-13)
    # without the gate the outlier is incorporated
    assert not np.allclose(_estimate(name, mu, RHO, Q)[0], m, rtol=1e-3)


# --- the UKF's sigma points behind the camera -------------------------------------------


def test_on_figure_2_the_ukfs_sigma_points_lie_behind_the_camera_at_every_frame():
    prior = paper_prior(model.noise_free_state(FIG2.mu))
    assert np.array_equal(prior.mean, FIG2.prior.mean) and np.array_equal(prior.cov, FIG2.prior.cov)
    h = ukf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov, allow_behind_camera=True)
    assert h.behind.tolist() == [True, True, True] and bool(h.went_behind)
    # depth SD sqrt(1000) = 31.6: the point mean - sqrt(3) * 31.6 e_y lies at 4 - 54.8
    X = ukf.SigmaPoints().points(prior.mean, prior.cov)
    assert_allclose(X[5, 1], 4.0 - np.sqrt(3000.0), rtol=1e-14)
    # the inverse-depth UKF's frame 1 is linear (1 + 0 w > 0); frames 2 and 3 are not
    e = inverse_depth_ukf.estimate(
        FIG2.mu, FIG2.rho, prior.mean, prior.cov, allow_behind_camera=True
    )
    assert e.behind.tolist() == [False, True, True] and bool(e.went_behind)
    with pytest.raises(ValueError, match="^update with measurement 1: sigma point 5 has depth"):
        ukf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov)


def test_a_well_posed_track_keeps_every_sigma_point_in_front():
    h = ukf.run(MU, RHO, MEAN, COV, Q)
    assert not np.any(h.behind) and not h.went_behind
    assert h.behind.shape == (6,)
    e = inverse_depth_ukf.estimate(MU, RHO, MEAN, COV, Q)
    assert not np.any(e.behind) and not e.went_behind
    batch = ukf.run(
        np.stack([MU, MU]),
        RHO,
        np.stack([MEAN, FIG2.prior.mean]),
        np.stack([COV, FIG2.prior.cov]),
        allow_behind_camera=True,
    )
    assert batch.behind.shape == (2, 6) and batch.went_behind.tolist() == [False, True]


def test_a_gated_bearing_is_flagged_behind_but_not_refused():
    # Only a transform that enters an update is refused without allow_behind_camera.
    n, C = FIG2.prior.mean, FIG2.prior.cov
    out = ukf.step(n, C, 50.0, 0.005, True, 0.9)
    assert bool(out.gated) and bool(out.behind)
    assert np.array_equal(out.mean, n) and np.array_equal(out.cov, C)
    with pytest.raises(ValueError, match="sigma point 5 has depth"):
        ukf.step(n, C, FIG2.mu[0], 0.005, True, None)


def test_the_ukf_step_functions_keep_their_signatures():
    # ukf.update and ukf.measurement_update are the step's update, bit for bit
    n, C = ekf.predict(MEAN, COV, Q)
    a = ukf.update(n, C, MU[1], RHO)
    b = ukf.step(n, C, MU[1], RHO)
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)
    c = ukf.measurement_update(n, C, MU[1], RHO)
    assert np.array_equal(a.mean, c.mean)


# --- refusals ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", DOORS)
@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"steps": [1.0, 1.0]}, r"^steps must have shape \(5,\)"),
        ({"steps": [1.0, 0.0, 1.0, 1.0, 1.0]}, "^steps must be nonzero"),
        ({"gate": 1.5}, r"^gate must be None or a probability in \(0, 1\)"),
        ({"gate": 0.0}, r"^gate must be None or a probability"),
    ],
)
def test_refusals_name_the_argument_in_one_line(name, kwargs, message):
    with pytest.raises(ValueError, match=message) as info:
        _estimate(name, MU, RHO, **kwargs)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("name", DOORS)
def test_too_few_bearings_and_bad_rho_per_frame_are_refused(name):
    mu = MU.copy()
    mu[1:5] = np.nan
    with pytest.raises(ValueError, match="^mu has 2 bearings present"):
        _estimate(name, mu, RHO)
    rho = np.full(6, RHO)
    rho[2] = -1.0
    with pytest.raises(ValueError, match=r"^rho\[2\] must be finite and positive"):
        _estimate(name, MU, rho)
