"""The batch maximum-likelihood estimate: against least squares per track, Eq. (7) and the bound."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from depthcore.analysis import batch_ml, bound
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS
from depthcore.studies import monte_carlo

FIG2 = SCENARIOS["fig2"]
#: Figure 2's noise-free state at time 3.
C = np.asarray(FIG2.c, dtype=float)


def _track(state_n, steps):
    """The states at frames 1 .. N of a track at ``state_n`` at frame N, shape (N, 3)."""
    t = np.concatenate([np.cumsum(np.asarray(steps)[::-1])[::-1], [0.0]])
    x, y, v = state_n
    return np.stack([x - t * v, y - t, np.full_like(t, v)], axis=-1)


def _uneven(seed=0, n=8, tracks=6, rho_scale=0.01):
    """Tracks with uneven steps, noise per frame and a missing bearing each."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.5, 1.5, size=n - 1)
    states = np.stack(
        [
            _track((rng.uniform(-2, 2), rng.uniform(8, 14), rng.uniform(-1, 1)), steps)
            for _ in range(tracks)
        ]
    )
    rho = rho_scale * rng.uniform(0.5, 2.0, size=(tracks, n))
    mu = states[..., 0] / states[..., 1] + rho * rng.standard_normal((tracks, n))
    mu[np.arange(tracks), rng.integers(0, n, tracks)] = np.nan
    return mu, rho, steps, states


def _least_squares(mu, rho, steps, start):
    """scipy's trust-region least squares on (x_N, y_N, v) for one track, from ``start``."""
    present = ~np.isnan(mu)

    def residuals(s):
        track = _track(s, steps)
        return ((track[:, 0] / track[:, 1] - mu) / rho)[present]

    fit = least_squares(residuals, start, x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return fit.x, 2 * fit.cost


def test_it_is_the_least_squares_solution_of_every_track_with_gaps_noise_per_frame_and_steps():
    mu, rho, steps, states = _uneven()
    est = batch_ml.estimate(mu, rho, steps)
    assert not np.any(est.at_limit)
    for i in range(len(mu)):
        s, misfit = _least_squares(mu[i], rho[i], steps, states[i, -1])
        sd = np.sqrt(np.diag(est.cov[i]))
        assert np.all(np.abs(est.mean[i] - s) < 1e-6 * sd), (est.mean[i], s)
        assert est.misfit[i] == pytest.approx(misfit, rel=1e-8)


def test_with_three_bearings_it_is_the_noise_free_solution_of_eq_7():
    mu = model.simulate(C, 3, FIG2.rho, 0.0, np.random.default_rng(2), size=400).mu
    mu = mu[model.valid_measurements(mu)]
    est = batch_ml.estimate(mu, FIG2.rho)
    np.testing.assert_allclose(est.mean, model.noise_free_states(mu), rtol=1e-9)
    assert np.all(est.misfit < 1e-12) and not np.any(est.at_limit)


def test_its_covariance_at_the_truth_is_the_bound_without_a_prior():
    mu, rho, steps, states = _uneven(seed=1)
    present = ~np.isnan(mu)
    crb = bound.conditional_bound(states, rho, present=present)[:, -1]
    P = batch_ml.covariance(states[:, -1], rho, steps, present)
    np.testing.assert_allclose(P, crb, rtol=1e-8, atol=1e-14)
    J = batch_ml.information(states[:, -1], rho, steps, present)
    np.testing.assert_allclose(J @ P, np.broadcast_to(np.eye(3), J.shape), atol=1e-7)


def test_its_covariance_is_the_inverse_fisher_information_by_finite_differences():
    mu, rho, steps, _ = _uneven(seed=2)
    est = batch_ml.estimate(mu, rho, steps)
    for i in range(len(mu)):
        present = ~np.isnan(mu[i])
        grads = []
        for j in range(3):
            h = np.zeros(3)
            h[j] = 1e-6 * max(1.0, abs(est.mean[i, j]))
            up, down = _track(est.mean[i] + h, steps), _track(est.mean[i] - h, steps)
            grads.append((up[:, 0] / up[:, 1] - down[:, 0] / down[:, 1]) / (2 * h[j]))
        g = np.stack(grads, axis=-1)[present] / rho[i, present, None]
        np.testing.assert_allclose(est.cov[i], np.linalg.inv(g.T @ g), rtol=1e-5)


def test_at_many_frames_and_small_noise_its_errors_approach_the_bound():
    trials, frames, rho = 2000, 30, 0.002
    sim = model.simulate(C, frames, rho, 0.0, np.random.default_rng(5), size=trials)
    est = batch_ml.estimate(sim.mu, rho)
    truth = sim.states[:, -1]
    errors = est.mean - truth
    crb = np.sqrt(np.diag(batch_ml.covariance(truth[0], np.full(frames, rho))))
    for k in (1, 2):  # depth and velocity
        sq = errors[:, k] ** 2
        rmse = np.sqrt(sq.mean())
        se = sq.std(ddof=1) / (2 * rmse * np.sqrt(trials))  # the delta method
        assert abs(rmse - crb[k]) < 3 * se + 0.02 * crb[k], (k, rmse, crb[k], se)
    nees = np.einsum("bi,bij,bj->b", errors, np.linalg.inv(est.cov), errors)
    assert abs(nees.mean() - 3) < 3 * nees.std(ddof=1) / np.sqrt(trials) + 0.06


def test_where_the_likelihood_rises_to_infinity_it_stops_at_the_limit_and_says_so():
    mu = np.array([0.0, 0.1, 0.2, 0.31])  # bent the way no point in front explains
    est = batch_ml.estimate(mu, 0.005)
    assert est.at_limit and np.all(np.isfinite(est.mean)) and np.all(np.isfinite(est.cov))
    span = 3.0
    assert est.mean[1] == pytest.approx(span * batch_ml.DEPTH_LIMITS[1] + span, rel=1e-12)
    r = FILTERS["batch_ml"](mu, 0.005, [0.0, 5.0, 0.0], np.eye(3))
    assert r.extras["at_limit"] is True and r.depth_sd > 1e6


def test_the_registry_runs_it_on_a_batch_and_ignores_the_prior():
    mu, rho, steps, _ = _uneven(seed=3)
    direct = batch_ml.estimate(mu, rho, steps)
    a = FILTERS["batch_ml"](mu, rho, [0.0, 5.0, 0.0], np.eye(3), steps=steps)
    b = FILTERS["batch_ml"](mu, rho, [9.0, 50.0, 3.0], 1e4 * np.eye(3), steps=steps)
    assert np.array_equal(a.mean, direct.mean) and np.array_equal(a.cov, direct.cov)
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.extras["misfit"], direct.misfit)


def test_a_study_scores_it():
    out = monte_carlo.study(trials=60, names=("batch_ml", "ekf"), frames=10, seed=1)
    scores = out["filters"]["batch_ml"]
    assert out["valid_trials"] > 50 and 0 < scores["depth"]["rmse"] < 1
    assert np.isfinite(scores["nees"])


def _profile_minimum_at_an_end(mu, rho):
    """Per track: whether the least misfit over a dense grid of depths lies at an end of it.

    An independent check of the flag: the misfit minimised over ``(x_N, v)`` at each depth
    (by numpy's least squares), over 501 depths spanning the limits, log-spaced.
    """
    n = mu.shape[-1]
    t = np.arange(n - 1, -1, -1.0)  # the depth travelled from each frame to frame N
    span = t[0]
    z = np.linspace(np.log(batch_ml.DEPTH_LIMITS[0]), np.log(batch_ml.DEPTH_LIMITS[1]), 501)
    out = []
    for m in mu:
        misfit = []
        for y1 in span * np.exp(z):
            y = y1 + span - t  # the depth at each frame, receding
            A = np.stack([1.0 / y, -t / y], axis=1) / rho
            _, res, *_ = np.linalg.lstsq(A, m / rho, rcond=None)
            misfit.append(res[0] if len(res) else 0.0)
        misfit = np.asarray(misfit)
        best = np.min(misfit)
        # interior: some inner depth beats both ends by more than rounding
        out.append(not best < min(misfit[0], misfit[-1]) - 1e-9 * max(1.0, best))
    return np.asarray(out)


def test_a_track_without_parallax_is_flagged_and_one_with_a_clear_maximum_is_not():
    rng = np.random.default_rng(7)
    rho = 0.002
    # zero parallax: the point moves along the optical axis, the bearings are noise alone
    flat = model.simulate(np.array([0.0, 6.0, 0.0]), 10, rho, 0.0, rng, size=40).mu
    clear = model.simulate(np.array([3.0, 6.0, 3.0]), 10, rho, 0.0, rng, size=40).mu
    flat_est, clear_est = batch_ml.estimate(flat, rho), batch_ml.estimate(clear, rho)
    assert not np.any(clear_est.at_limit)
    # about half the tracks without parallax have no interior maximum, and the flag is
    # exactly where a dense search over the depth finds its least misfit at an end
    assert 0.25 < np.mean(flat_est.at_limit) < 0.9
    np.testing.assert_array_equal(flat_est.at_limit, _profile_minimum_at_an_end(flat, rho))
    assert not np.any(_profile_minimum_at_an_end(clear, rho))


def test_a_study_scores_it_only_where_it_has_a_maximum_and_counts_the_others_apart():
    run = monte_carlo.Study(
        np.array([0.0, 6.0, 0.0]),
        rho=0.002,
        trials=300,
        seed=2,
        names=("batch_ml", "ekf"),
        chunk=100,
        frames=10,
    )
    flagged = 0
    for k, item in enumerate(run.items()):
        part = item[0]
        flagged += int(np.sum(batch_ml.estimate(part.mu, part.rho).at_limit))
        run.fold(k, (part, monte_carlo.filter_chunk(item)[1]))
    out = run.result()
    ml, ekf = out["filters"]["batch_ml"], out["filters"]["ekf"]
    assert flagged > 0 and ml["no_maximum"]["count"] == flagged
    assert run.tallies["batch_ml"].n == out["valid_trials"] - flagged and "no_maximum" not in ekf
    assert run.tallies["ekf"].n + ekf["refused"]["count"] == out["valid_trials"]
    assert ml["no_maximum"]["fraction"] == flagged / out["valid_trials"]


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (
            lambda: batch_ml.estimate([-0.3, 0.0, 0.2, 0.3], 0.005, process_noise=0.01),
            "process_noise",
        ),
        (
            lambda: FILTERS["batch_ml"]([-0.3, 0.0, 0.2, 0.3], 0.005, [0, 5, 0], np.eye(3), 0.01),
            "process_noise",
        ),
        (lambda: batch_ml.estimate([-0.3, np.nan, 0.2, np.nan], 0.005), "mu"),
        (lambda: batch_ml.estimate([-0.3, 0.0], 0.005), "mu"),
        (
            lambda: batch_ml.estimate([-0.3, 0.0, 0.2], 0.005, depth_limits=(1.0, 0.5)),
            "depth_limits",
        ),
        (lambda: batch_ml.estimate([-0.3, 0.0, 0.2], -1.0), "rho"),
        (lambda: batch_ml.covariance([1.0, 1.0, 0.0], np.full(4, 0.01)), "state"),
        (
            lambda: batch_ml.information([1.0, 9.0, 0.0], np.full(4, 0.01), [1.0, 0.0, 1.0]),
            "steps",
        ),
    ],
)
def test_refusals_name_the_argument_in_one_line(call, name):
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert message.startswith(name) and "\n" not in message, message
