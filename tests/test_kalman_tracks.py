"""The Kalman-type filters on tracks as they come: gaps, noise per frame, steps, a gate, online."""

from __future__ import annotations

import importlib.util
import pickle
from collections.abc import Callable
from functools import partial

import numpy as np
import pytest

import depthcore
from depthcore.kalman import ekf, iterated, second_order, ukf
from depthcore.kalman import online as kalman_online
from depthcore.problem import checks, frames, predictive
from depthcore.problem.gaussian import History, checked_track, paper_prior, run_recursion
from depthcore.registry import online
from depthcore.registry.filters import FILTERS
from depthcore.registry.tracking import default_prior

pytestmark = pytest.mark.filterwarnings("error")

MU = np.array([0.1, 0.2, 0.27, 0.35, 0.41, 0.46])
PRIOR_MEAN = np.array([0.2, 7.0, 0.0])
PRIOR_COV = 4.0 * np.eye(3)
RHO = 0.01


def run_gaussian_filter(
    update_step: Callable,
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    steps=None,
    gate=None,
    predictive_step: Callable | None = None,
) -> History:
    """The predict-update loop of a Gaussian filter around any update step, batched.

    Initialise ``n = m``, ``C = P`` (the prior is the density of the state at
    time 1), incorporate ``mu1``, then, for each further frame, predict with
    Eq. (10) over its step (exact for the linear motion; :func:`depthcore.kalman.ekf.predict`, with
    the process noise ``q**2 s`` added to the velocity's variance) and
    incorporate its bearing where it is present and not gated
    (:func:`depthcore.problem.gaussian.run_recursion`).

    Parameters
    ----------
    update_step : callable
        ``update_step(n, C, mu_k, rho_k) -> MeanAndCov``, batched; a
        :class:`ValueError` it raises is reraised naming the measurement.
    mu : array_like, shape (..., N)
        Bearings of ``N >= 3`` frames in time order, ``NaN`` where missing,
        checked by :func:`depthcore.problem.gaussian.checked_track` (as are the
        other arguments); the leading shape runs independent filters.
    rho : float or array_like, shape (...) or (..., N)
        Noise standard deviation, > 0, per problem or per frame.
    prior_mean : array_like, shape (3,) or (..., 3)
    prior_cov : array_like, shape (3, 3) or (..., 3, 3)
    process_noise : float
        SD ``q >= 0`` of the velocity's change per unit step (0: the paper's model).
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
        The depth's change between frames (``None``: ones).
    gate : float or None
        :func:`depthcore.problem.predictive.gate`.
    predictive_step : callable, optional
        ``predictive_step(n, C, rho_k) -> (bearing_mean, bearing_var)``: the
        filter's Gaussian predictive density of the bearing (the EKF's is
        :func:`depthcore.kalman.ekf.bearing_predictive`). Without it the result's ``updates`` is
        ``None`` and a ``gate`` is refused.

    Returns
    -------
    History
        ``means`` (..., N, 3) and ``covs`` (..., N, 3, 3) after each frame, and
        ``updates`` (..., N) when ``predictive_step`` is given.
    """
    track = checked_track(mu, rho, prior_mean, prior_cov, steps)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    g = predictive.gate(gate)
    if g is not None and predictive_step is None:
        raise ValueError("gate: this filter reports no predictive density, so it has no gate")
    f = track.frames
    rho_k = f.rho
    regular = f.regular

    def update(n, C, mu_k, k):
        try:
            return update_step(n, C, mu_k, f.row_rho if regular else rho_k[..., k - 1])
        except ValueError as exc:
            raise ValueError(f"update with measurement {k}: {exc}") from None

    def predicted_bearing(n, C, k):
        try:
            return predictive_step(n, C, rho_k[..., k - 1])
        except ValueError as exc:
            raise ValueError(f"update with measurement {k}: {exc}") from None

    def predict_k(m, P, k):
        return ekf.predict(m, P, q) if regular else ekf.predict(m, P, q, f.steps[..., k - 2])

    return run_recursion(
        track.mean,
        track.cov,
        f.mu,
        predict_k,
        update,
        f.present,
        None if predictive_step is None else predicted_bearing,
        g,
    )


def by_hand(mu, rho, prior_mean, prior_cov, q=0.0, steps=None):
    """The EKF in covariance form, Eqs. (10)-(12), skipping the update where ``mu`` is NaN.

    Returns the means (N, 3), covariances (N, 3, 3) and each present bearing's
    log predictive density ``log N(mu; n1/n2, h^T C h + rho**2)`` (NaN where missing).
    """
    n_frames = len(mu)
    rho = np.broadcast_to(rho, (n_frames,))
    steps = np.ones(n_frames - 1) if steps is None else np.asarray(steps, dtype=float)
    m, P = np.asarray(prior_mean, float), np.asarray(prior_cov, float)
    means, covs, logs = [], [], []
    for k in range(n_frames):
        if k > 0:
            F = frames.transition(steps[k - 1])
            m = F @ m + np.array([0.0, steps[k - 1], 0.0])
            P = F @ P @ F.T + np.diag([0.0, 0.0, q**2 * abs(steps[k - 1])])
        if np.isnan(mu[k]):
            logs.append(np.nan)
        else:
            h = np.array([1.0 / m[1], -m[0] / m[1] ** 2, 0.0])
            s = h @ P @ h + rho[k] ** 2
            r = mu[k] - m[0] / m[1]
            logs.append(-0.5 * (np.log(2 * np.pi * s) + r * r / s))
            K = P @ h / s
            m = m + K * r
            P = P - np.outer(K, K) * s
        means.append(m)
        covs.append(P)
    return np.array(means), np.array(covs), np.array(logs)


# --- History ------------------------------------------------------------------------------


def test_history_unpacks_as_a_pair_and_carries_the_updates():
    h = ekf.run(MU, RHO, PRIOR_MEAN, PRIOR_COV)
    means, covs = h
    assert means.shape == (6, 3) and covs.shape == (6, 3, 3)
    assert isinstance(h.updates, predictive.Updates) and h.updates.tail.shape == (6,)
    assert h.posterior.mean[1] == means[-1, 1]
    again = pickle.loads(pickle.dumps(h))
    np.testing.assert_array_equal(again.updates.tail, h.updates.tail)
    assert History(means, covs).updates is None


# --- the regular case ---------------------------------------------------------------------


@pytest.mark.parametrize("q", [0.0, 0.05])
def test_regular_ekf_equals_the_covariance_form_and_reports_its_predictive(q):
    h = ekf.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, process_noise=q)
    m, P, logs = by_hand(MU, RHO, PRIOR_MEAN, PRIOR_COV, q)
    np.testing.assert_allclose(h.means, m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(h.covs, P, rtol=1e-7, atol=1e-13)
    np.testing.assert_allclose(h.updates.log_predictive, logs, rtol=1e-9)
    assert not np.any(h.updates.gated)


def test_unit_steps_and_per_frame_rho_equal_to_the_row_rho_change_nothing():
    base = ekf.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, process_noise=0.05)
    same = ekf.run(MU, np.full(6, RHO), PRIOR_MEAN, PRIOR_COV, process_noise=0.05, steps=np.ones(5))
    np.testing.assert_allclose(same.means, base.means, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(same.covs, base.covs, rtol=1e-13, atol=1e-18)
    it = iterated.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, process_noise=0.05)
    it_same = iterated.run(MU, np.full(6, RHO), PRIOR_MEAN, PRIOR_COV, 0.05, steps=np.ones(5))
    np.testing.assert_allclose(it_same.means, it.means, rtol=1e-13, atol=1e-15)


# --- gaps ---------------------------------------------------------------------------------


@pytest.mark.parametrize("q", [0.0, 0.05])
def test_ekf_with_gaps_equals_the_recursion_skipping_those_updates(q):
    mu = MU.copy()
    mu[[2, 4]] = np.nan
    h = ekf.run(mu, RHO, PRIOR_MEAN, PRIOR_COV, process_noise=q)
    m, P, logs = by_hand(mu, RHO, PRIOR_MEAN, PRIOR_COV, q)
    np.testing.assert_allclose(h.means, m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(h.covs, P, rtol=1e-7, atol=1e-13)
    np.testing.assert_allclose(h.updates.log_predictive, logs, rtol=1e-9)
    assert np.all(np.isnan(h.updates.tail[[2, 4]]))


def test_gaps_in_a_batch_are_masked_row_by_row():
    mu = np.stack([MU, MU, MU])
    mu[0, 1] = np.nan
    mu[2, [3, 5]] = np.nan
    rho = np.array([0.01, 0.02, 0.005])
    for run in (ekf.run, iterated.run):
        batch = run(mu, rho, PRIOR_MEAN, PRIOR_COV, process_noise=0.02)
        for i in range(3):
            one = run(mu[i], rho[i], PRIOR_MEAN, PRIOR_COV, process_noise=0.02)
            np.testing.assert_allclose(batch.means[i], one.means, rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(batch.covs[i], one.covs, rtol=1e-10, atol=1e-16)
            np.testing.assert_array_equal(np.isnan(batch.updates.tail[i]), np.isnan(mu[i]))


def test_iterated_with_one_iteration_is_the_ekf_with_gaps():
    mu = MU.copy()
    mu[3] = np.nan
    it = iterated.run(mu, RHO, PRIOR_MEAN, PRIOR_COV, 0.05, max_iterations=1)
    m, P, logs = by_hand(mu, RHO, PRIOR_MEAN, PRIOR_COV, 0.05)
    np.testing.assert_allclose(it.means, m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(it.covs, P, rtol=1e-7, atol=1e-13)
    np.testing.assert_allclose(it.updates.log_predictive, logs, rtol=1e-9)


def test_ukf_loop_with_gaps_skips_those_updates():
    mu = MU.copy()
    mu[2] = np.nan
    step = partial(ukf.update, allow_behind_camera=True)
    h = run_gaussian_filter(
        step, mu, RHO, PRIOR_MEAN, PRIOR_COV, predictive_step=kalman_online.unscented_predictive
    )
    before = run_gaussian_filter(step, MU[:3], RHO, PRIOR_MEAN, PRIOR_COV)  # frame 2 sees 1-2
    before = History(before.means[:2], before.covs[:2])
    n, C = ekf.predict(*ekf.predict(before.means[-1], before.covs[-1]))
    n, C = step(n, C, mu[3], RHO)
    np.testing.assert_allclose(h.means[3], n, rtol=1e-12)
    np.testing.assert_allclose(h.covs[3], C, rtol=1e-10)
    np.testing.assert_allclose(h.means[2], ekf.predict(h.means[1], h.covs[1]).mean, rtol=1e-14)


# --- noise per frame -----------------------------------------------------------------------


def test_per_frame_rho_equals_the_recursion_with_each_frames_rho():
    rho = np.array([0.01, 0.03, 0.005, 0.02, 0.01, 0.04])
    h = ekf.run(MU, rho, PRIOR_MEAN, PRIOR_COV, process_noise=0.03)
    m, P, logs = by_hand(MU, rho, PRIOR_MEAN, PRIOR_COV, 0.03)
    np.testing.assert_allclose(h.means, m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(h.covs, P, rtol=1e-7, atol=1e-13)
    np.testing.assert_allclose(h.updates.log_predictive, logs, rtol=1e-9)
    it = iterated.run(MU, rho, PRIOR_MEAN, PRIOR_COV, 0.03, max_iterations=1)
    np.testing.assert_allclose(it.means, m, rtol=1e-9, atol=1e-12)


# --- steps ---------------------------------------------------------------------------------


@pytest.mark.parametrize("run", [ekf.run, iterated.run])
def test_two_unit_steps_with_the_middle_bearing_missing_are_one_step_of_two(run):
    mu = np.array([0.1, 0.2, np.nan, 0.35, 0.41])
    gapped = run(mu, RHO, PRIOR_MEAN, PRIOR_COV)
    stepped = run(mu[[0, 1, 3, 4]], RHO, PRIOR_MEAN, PRIOR_COV, steps=[1.0, 2.0, 1.0])
    np.testing.assert_allclose(stepped.means, gapped.means[[0, 1, 3, 4]], rtol=1e-12)
    np.testing.assert_allclose(stepped.covs, gapped.covs[[0, 1, 3, 4]], rtol=1e-9, atol=1e-16)
    np.testing.assert_allclose(
        stepped.updates.log_predictive, gapped.updates.log_predictive[[0, 1, 3, 4]], rtol=1e-12
    )


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["receding", "approaching"])
def test_uneven_steps_equal_the_recursion_with_each_step(sign):
    """Eqs. (10)-(12) over each signed step, the velocity's variance q**2 |s| (textbook 19.10)."""
    steps = sign * np.array([0.5, 1.5, 2.0, 0.25, 1.0])
    prior_mean = PRIOR_MEAN + [0.0, 10.0 if sign < 0 else 0.0, 0.0]  # in front at every frame
    h = ekf.run(MU, RHO, prior_mean, PRIOR_COV, process_noise=0.04, steps=steps)
    m, P, logs = by_hand(MU, RHO, prior_mean, PRIOR_COV, 0.04, steps)
    np.testing.assert_allclose(h.means, m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(h.covs, P, rtol=1e-7, atol=1e-13)
    np.testing.assert_allclose(h.updates.log_predictive, logs, rtol=1e-9)


def test_with_process_noise_two_unit_steps_add_q2_to_x_beyond_one_step_of_two():
    # F D F^T + D against 2 D, D = diag(0, 0, q**2): the acceleration of the first
    # unit step also moves x over the second.
    q = 0.1
    P = np.diag([1.0, 2.0, 3.0])
    m = np.array([0.1, 5.0, 0.2])
    twice = ekf.predict(*ekf.predict(m, P, q), q)
    once = ekf.predict(m, P, q, 2.0)
    np.testing.assert_allclose(twice.mean, once.mean, rtol=1e-15)
    expected = np.array([[q**2, 0, q**2], [0, 0, 0], [q**2, 0, 0]])
    np.testing.assert_allclose(twice.cov - once.cov, expected, atol=1e-14)


# --- the gate ------------------------------------------------------------------------------


@pytest.mark.parametrize("run", [ekf.run, iterated.run])
def test_a_gate_skipping_an_outlier_equals_that_bearing_missing(run):
    mu = MU.copy()
    mu[3] = 2.0  # far out
    gated = run(mu, RHO, PRIOR_MEAN, PRIOR_COV, gate=1e-3)
    mu[3] = np.nan
    missing = run(mu, RHO, PRIOR_MEAN, PRIOR_COV)
    np.testing.assert_allclose(gated.means, missing.means, rtol=1e-14)
    np.testing.assert_allclose(gated.covs, missing.covs, rtol=1e-14)
    assert gated.updates.gated.tolist() == [False, False, False, True, False, False]
    assert gated.updates.tail[3] < 1e-3 and np.isfinite(gated.updates.log_predictive[3])


def test_a_gate_passes_what_it_does_not_skip():
    h = ekf.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, gate=1e-6)
    plain = ekf.run(MU, RHO, PRIOR_MEAN, PRIOR_COV)
    np.testing.assert_array_equal(h.means, plain.means)
    assert not np.any(h.updates.gated)


# --- refusals ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"mu": [0.1, np.nan, 0.2, 0.33]}, r"^mu: the second-order approximation takes no"),
        ({"steps": [1.0, 2.0, 1.0]}, r"^steps: the second-order approximation takes only unit"),
        ({"rho": [0.01, 0.02, 0.01, 0.01]}, r"^rho: the second-order approximation takes one"),
    ],
)
def test_second_order_refuses_what_it_cannot_take_by_name(kwargs, message):
    args = {"mu": [0.1, 0.2, 0.28, 0.35], "rho": RHO, **kwargs}
    with pytest.raises(ValueError, match=message):
        second_order.run(args.pop("mu"), args.pop("rho"), PRIOR_MEAN, PRIOR_COV, **args)


def test_second_order_reads_a_constant_per_frame_rho_as_the_problems():
    mu = [0.1, 0.2, 0.28, 0.35]
    a = second_order.run(mu, np.full(4, RHO), PRIOR_MEAN, PRIOR_COV)
    b = second_order.run(mu, RHO, PRIOR_MEAN, PRIOR_COV)
    np.testing.assert_array_equal(a.mean, b.mean)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"gate": 1.5}, r"^gate must be None or a probability"),
        ({"steps": [1.0, 0.0, 1.0, 1.0, 1.0]}, r"^steps must be nonzero"),
        ({"mu": [0.1, np.nan, np.nan, np.nan, np.nan, 0.5]}, r"^mu has 2 bearings present"),
        ({"rho": np.array([0.01, 0.0, 0.01, 0.01, 0.01, 0.01])}, r"^rho\[1\] must be finite"),
    ],
)
def test_the_ekf_refuses_a_bad_track_in_one_line(kwargs, message):
    args = {"mu": MU, "rho": RHO, **kwargs}
    for run in (ekf.run, iterated.run):
        with pytest.raises(ValueError, match=message) as info:
            run(
                args["mu"],
                args["rho"],
                PRIOR_MEAN,
                PRIOR_COV,
                **{k: v for k, v in args.items() if k in ("gate", "steps")},
            )
        assert "\n" not in str(info.value)


def test_the_gaussian_loop_without_a_predictive_refuses_a_gate():
    with pytest.raises(ValueError, match=r"^gate: this filter reports no predictive density"):
        run_gaussian_filter(ekf.update, MU, RHO, PRIOR_MEAN, PRIOR_COV, gate=0.01)


# --- the registry --------------------------------------------------------------------------


def test_the_registry_passes_gaps_rho_per_frame_steps_and_gate_and_reads_the_updates():
    mu = MU.copy()
    mu[2] = np.nan
    rho = np.array([0.01, 0.02, np.nan, 0.01, 0.01, 0.02])
    steps = [1.0, 0.5, 1.5, 1.0, 1.0]
    e = FILTERS["ekf"](mu, rho, PRIOR_MEAN, PRIOR_COV, steps=steps, gate=1e-4)
    h = ekf.run(mu, rho, PRIOR_MEAN, PRIOR_COV, steps=steps, gate=1e-4)
    assert e.depth_mean == h.means[-1, 1]
    assert e.updates.tail.shape == (6,)
    np.testing.assert_array_equal(e.updates.log_predictive, h.updates.log_predictive)
    batch = FILTERS["iterated"](
        np.stack([mu, MU]), np.stack([rho, np.full(6, 0.01)]), PRIOR_MEAN, PRIOR_COV
    )
    assert batch.updates.tail.shape == (2, 6)
    assert np.isnan(batch.updates.tail[0, 2]) and not np.isnan(batch.updates.tail[1, 2])


@pytest.mark.parametrize(
    "name, kwargs, message",
    [
        ("second_order", {"gate": 0.01}, "gate: the second_order filter has no gate"),
        (
            "second_order",
            {"steps": [1.0, 2.0]},
            "steps: the second-order approximation takes only unit steps",
        ),
    ],
)
def test_the_registry_refuses_what_a_door_does_not_take_before_running(name, kwargs, message):
    with pytest.raises(ValueError, match=f"^{message}$"):
        FILTERS[name]([0.1, 0.2, 0.28], RHO, PRIOR_MEAN, PRIOR_COV, **kwargs)


def test_the_registry_gives_unit_steps_the_papers_answer():
    a = FILTERS["ukf"]([0.1, 0.2, 0.28], RHO, PRIOR_MEAN, PRIOR_COV, steps=[1.0, 1.0])
    b = FILTERS["ukf"]([0.1, 0.2, 0.28], RHO, PRIOR_MEAN, PRIOR_COV)
    assert a.depth_mean == b.depth_mean


# --- track ---------------------------------------------------------------------------------


def _noise_free(x1, elapsed):
    return (x1[0] + elapsed * x1[2]) / (x1[1] + elapsed)


def test_default_prior_is_the_papers_rule_on_regular_frames():
    mu = np.array([0.1, 0.2, 0.28, 0.35])
    c = depthcore.problem.model.noise_free_state(mu[:3])
    assert default_prior(mu).mean.tolist() == paper_prior(c).mean.tolist()


def test_default_prior_with_gaps_and_steps_passes_through_the_present_bearings():
    x1 = np.array([0.4, 6.0, 0.3])
    steps = np.array([1.0, 0.5, 2.0, 1.0])
    elapsed = np.concatenate([[0.0], np.cumsum(steps)])
    mu = _noise_free(x1, elapsed)
    mu[1] = np.nan
    prior = default_prior(mu, steps)
    np.testing.assert_allclose(prior.mean, [x1[0], x1[1], 0.0], rtol=1e-12)
    np.testing.assert_array_equal(prior.cov, 1000.0 * np.eye(3))
    mu_regular = _noise_free(x1, np.arange(5.0))
    np.testing.assert_allclose(default_prior(mu_regular).mean, [x1[0], x1[1], 0.0], rtol=1e-12)


def test_default_prior_refuses_a_point_behind_the_camera_by_name():
    x1 = np.array([0.4, -10.0, 0.3])  # behind the camera
    mu = _noise_free(x1, np.array([0.0, 1.0, 2.5, 3.5]))
    mu[1] = np.nan
    with pytest.raises(ValueError, match=r"^prior is needed: the first three present bearings"):
        default_prior(mu, [1.0, 1.5, 1.0])


def test_track_smooths_through_a_gap_as_through_a_step_of_two():
    mu = np.array([0.1, 0.2, np.nan, 0.35, 0.41])
    prior = depthcore.Gaussian(PRIOR_MEAN, PRIOR_COV)
    gapped = depthcore.track(mu, RHO, prior, filter="ekf")
    stepped = depthcore.track(mu[[0, 1, 3, 4]], RHO, prior, filter="ekf", steps=[1.0, 2.0, 1.0])
    keep = [0, 1, 3, 4]
    np.testing.assert_allclose(stepped.smoothed.mean, gapped.smoothed.mean[keep], rtol=1e-10)
    np.testing.assert_allclose(
        stepped.smoothed.cov, gapped.smoothed.cov[keep], rtol=1e-7, atol=1e-14
    )
    np.testing.assert_allclose(gapped.smoothed.mean[-1], gapped.filtered.mean[-1], rtol=1e-14)
    # at the gap the smoothed state lies on the line between its neighbours (q = 0)
    s = gapped.smoothed.mean
    np.testing.assert_allclose(s[2], 0.5 * (s[1] + s[3]), rtol=1e-10)


def test_track_takes_rho_per_frame_and_refuses_one_out_of_range():
    rho = np.array([0.01, 0.02, 0.01, 0.03])
    t = depthcore.track([0.1, 0.2, 0.28, 0.35], rho, filter="ekf")
    h = ekf.run([0.1, 0.2, 0.28, 0.35], rho, t.prior.mean, t.prior.cov)
    np.testing.assert_allclose(t.filtered.mean, h.means, rtol=1e-14)
    with pytest.raises(ValueError, match=r"^rho must be from"):
        depthcore.track([0.1, 0.2, 0.28, 0.35], [0.01, 0.02, 1e4, 0.01], filter="ekf")


# --- online --------------------------------------------------------------------------------

TRACK = np.array([0.1, 0.2, np.nan, 0.35, 2.0, 0.41, 0.46])
TRACK_RHO = np.array([0.01, 0.02, 0.01, 0.01, 0.01, 0.015, 0.01])
TRACK_STEPS = np.array([1.0, 0.5, 1.5, 1.0, 1.0, 2.0])


def _feed(f, mu=TRACK, rho=TRACK_RHO, steps=TRACK_STEPS):
    out = []
    for k in range(len(mu)):
        out.append(f.update(mu[k], rho=rho[k], step=1.0 if k == 0 else steps[k - 1]))
    return out


def test_online_ekf_after_n_frames_equals_the_batch_door():
    f = online.start("ekf", PRIOR_MEAN, PRIOR_COV, process_noise=0.03, gate=1e-3)
    frames_seen = _feed(f)
    h = ekf.run(TRACK, TRACK_RHO, PRIOR_MEAN, PRIOR_COV, 0.03, steps=TRACK_STEPS, gate=1e-3)
    for k, est in enumerate(frames_seen):
        assert est.frame == k + 1
        np.testing.assert_allclose(est.mean, h.means[k], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(est.cov, h.covs[k], rtol=1e-12, atol=1e-16)
        np.testing.assert_allclose(est.log_predictive, h.updates.log_predictive[k], rtol=1e-13)
        assert est.gated == h.updates.gated[k]
    assert frames_seen[4].gated and np.isnan(frames_seen[2].tail)
    assert f.frame == 7 and f.current is frames_seen[-1]
    assert f.current.depth_sd == np.sqrt(h.covs[-1, 1, 1])


def test_online_ukf_after_n_frames_equals_the_batch_loop():
    f = online.start("ukf", PRIOR_MEAN, PRIOR_COV, process_noise=0.03, gate=1e-3)
    frames_seen = _feed(f)
    h = run_gaussian_filter(
        partial(ukf.update, allow_behind_camera=True),
        TRACK,
        TRACK_RHO,
        PRIOR_MEAN,
        PRIOR_COV,
        0.03,
        steps=TRACK_STEPS,
        gate=1e-3,
        predictive_step=kalman_online.unscented_predictive,
    )
    for k, est in enumerate(frames_seen):
        np.testing.assert_allclose(est.mean, h.means[k], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(est.cov, h.covs[k], rtol=1e-12, atol=1e-16)
        assert est.gated == h.updates.gated[k]
    regular = online.start("ukf", PRIOR_MEAN, PRIOR_COV, rho=RHO)
    for mu in MU:
        last = regular.update(mu)
    batch = ukf.run(MU, RHO, PRIOR_MEAN, PRIOR_COV, allow_behind_camera=True)
    np.testing.assert_array_equal(last.mean, batch.means[-1])


def test_online_keeps_constant_memory():
    f = kalman_online.EKF(PRIOR_MEAN, PRIOR_COV, rho=RHO)
    before = set(vars(f))
    for mu in np.tile(MU, 5):
        f.update(mu)
    assert set(vars(f)) == before
    assert all(np.size(v) <= 9 for v in vars(f).values() if isinstance(v, np.ndarray))


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda f: f.update(0.1, rho=0.01, step=2.0),
            r"^step: the first frame has no step before it",
        ),
        (lambda f: f.update(0.1, rho=None), r"^rho is needed"),
        (lambda f: f.update(np.inf, rho=0.01), r"^mu must be finite or NaN"),
        (lambda f: f.update([0.1, 0.2], rho=0.01), r"^mu must be one bearing"),
    ],
)
def test_online_refuses_a_bad_frame_by_name(call, message):
    for name in ("ekf", "ukf"):
        with pytest.raises(ValueError, match=message):
            call(online.start(name, PRIOR_MEAN, PRIOR_COV))


def test_online_start_refuses_an_unknown_name():
    with pytest.raises(ValueError, match=r"^name must be one of \('optimal', 'ekf', 'ukf'\)"):
        online.start("second_order", PRIOR_MEAN, PRIOR_COV, rho=RHO)


@pytest.mark.skipif(
    importlib.util.find_spec("depthcore.exact.online") is None,
    reason="the online exact filter is not in this tree",
)
def test_online_optimal_after_n_frames_equals_the_batch_door():
    mu = np.array([0.1, 0.2, np.nan, 0.35, 0.41])
    f = online.start("optimal", PRIOR_MEAN, PRIOR_COV, rho=RHO)
    for m in mu:
        last = f.update(m)
    batch = FILTERS["optimal"](mu, RHO, PRIOR_MEAN, PRIOR_COV)
    assert last.frame == 5
    np.testing.assert_allclose(last.depth_mean, batch.depth_mean, rtol=1e-8)
    np.testing.assert_allclose(last.depth_sd, batch.depth_sd, rtol=1e-7)
    np.testing.assert_allclose(last.velocity_mean, batch.velocity_mean, rtol=1e-7, atol=1e-9)


def test_track_passes_the_steps_to_the_exact_smoother():
    mu = np.array([0.1, 0.2, np.nan, 0.35, 0.41])
    gapped = depthcore.track(mu, RHO)
    stepped = depthcore.track(mu[[0, 1, 3, 4]], RHO, gapped.prior, steps=[1.0, 2.0, 1.0])
    keep = [0, 1, 3, 4]
    np.testing.assert_allclose(stepped.smoothed.mean, gapped.smoothed.mean[keep], rtol=1e-8)
    np.testing.assert_allclose(stepped.filtered.mean, gapped.filtered.mean[keep], rtol=1e-8)


def test_the_registrys_ukf_says_when_its_sigma_points_went_behind_the_camera():
    """Figure 2's prior puts sigma points behind the camera; a narrow one at the truth not."""
    from depthcore.problem.scenarios import SCENARIOS

    s = SCENARIOS["fig2"]
    wide = FILTERS["ukf"](s.mu, s.rho, s.prior.mean, s.prior.cov)
    assert wide.extras["sigma_points_behind_camera"] is True
    x1 = np.array([s.c[0] - 2 * s.c[2], s.c[1] - 2, s.c[2]])  # the truth at frame 1
    narrow = FILTERS["ukf"](s.mu, s.rho, x1, 0.01 * np.eye(3))
    assert narrow.extras["sigma_points_behind_camera"] is False
    both = FILTERS["ukf"](np.stack([s.mu, s.mu]), s.rho, np.stack([s.prior.mean, x1]), s.prior.cov)
    assert both.extras["sigma_points_behind_camera"].shape == (2,)
