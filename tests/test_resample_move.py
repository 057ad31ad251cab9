"""Tests of the causal bootstrap filter with resample-move (textbook 19.5)."""

import numpy as np
import pytest

from depthcore.exact import optimal
from depthcore.particles import resample_move
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS


def _run(key, n, repeats, seed, **kwargs):
    s = SCENARIOS[key]
    rng = np.random.default_rng(seed)
    return resample_move.run(
        np.tile(s.mu, (repeats, 1)), s.rho, s.prior.mean, s.prior.cov, n, rng, **kwargs
    )


@pytest.mark.parametrize("key", ["fig2", "fig3", "fig6"])
def test_converges_to_the_optimal_marginals_eq_13_16(key):
    """At N = 20000 the depth and velocity moments lie within 0.25 posterior SDs of Eqs. (13)-(16).

    Over ten repeats on these scenarios the RMS error is about 0.05 SD; the
    bound leaves five times that for one run.
    """
    s = SCENARIOS[key]
    exact = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    m = _run(key, 20_000, 2, seed=11).moments()
    for q in ("depth", "velocity"):
        sd = getattr(exact, f"{q}_sd")
        assert np.all(np.abs(m[f"{q}_mean"] - getattr(exact, f"{q}_mean")) < 0.25 * sd)
        assert np.all(np.abs(m[f"{q}_sd"] - sd) < 0.25 * sd)


def test_error_falls_as_particles_grow():
    """The RMS error of the depth mean over repeats falls from N = 1000 to N = 20000 (Fig. 2)."""
    s = SCENARIOS["fig2"]
    exact = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    errors = []
    for n in (1000, 20_000):
        m = _run("fig2", n, 6, seed=3).moments()
        errors.append(np.sqrt(np.mean((m["depth_mean"] - exact.depth_mean) ** 2)) / exact.depth_sd)
    assert errors[1] < 0.2 < errors[0]


def test_without_moves_the_bootstrap_filter_collapses():
    """moves = 0 is the plain bootstrap filter.

    On Fig. 2 its final cloud holds few distinct states.
    """
    b = _run("fig2", 5000, 1, seed=5, moves=0)
    distinct = np.unique(b.particles[0][np.exp(b.log_weights[0]) > 1e-12], axis=0)
    assert len(distinct) < 50
    moved = _run("fig2", 5000, 1, seed=5)
    assert len(np.unique(moved.particles[0], axis=0)) > 2500


def test_is_causal():
    """The filter's steps up to mu_k use only mu_1 .. mu_k.

    Another mu_3 leaves the first two ESS alone.
    """
    s = SCENARIOS["fig2"]
    mu = np.array([s.mu, (s.mu[0], s.mu[1], s.mu[2] + 0.05)])
    a = resample_move.run(mu[:1], s.rho, s.prior.mean, s.prior.cov, 3000, np.random.default_rng(7))
    b = resample_move.run(mu[1:], s.rho, s.prior.mean, s.prior.cov, 3000, np.random.default_rng(7))
    np.testing.assert_array_equal(a.ess[:, :2], b.ess[:, :2])
    assert a.ess[0, 2] != b.ess[0, 2]
    two = resample_move.run(
        mu[:1, :2], s.rho, s.prior.mean, s.prior.cov, 3000, np.random.default_rng(7)
    )
    np.testing.assert_array_equal(two.ess, a.ess[:, :2])


def test_log_target_is_the_log_posterior_eq_6_up_to_a_constant():
    """With all three bearings, log pi_3(x_1) equals Eq. (6) at G^2 x_1 up to one constant."""
    s = SCENARIOS["fig2"]
    rng = np.random.default_rng(0)
    x1 = s.prior.mean + rng.normal(size=(1, 50, 3)) * [1.0, 1.0, 0.3] + [0.0, 2.0, 0.0]
    chol = np.linalg.cholesky(s.prior.cov)
    ours = resample_move.log_target(
        x1, np.array([s.mu]), np.array([s.rho]), s.prior.mean[None], chol
    )[0]
    paper = optimal.log_posterior(model.G(x1[0], 2), s.mu, s.rho, s.prior)
    diff = ours - paper
    np.testing.assert_allclose(diff, diff[0], rtol=0, atol=1e-9 * np.max(np.abs(paper)))


def test_log_target_is_minus_infinity_behind_the_camera():
    s = SCENARIOS["fig2"]
    x1 = np.array([[[0.0, -0.5, 0.0], [0.0, 0.0, 0.0], [0.1, 3.0, 0.1]]])
    out = resample_move.log_target(
        x1, np.array([s.mu]), np.array([s.rho]), s.prior.mean[None], np.linalg.cholesky(s.prior.cov)
    )
    assert np.isneginf(out[0, :2]).all() and np.isfinite(out[0, 2])


def test_any_number_of_bearings():
    """One bearing and five bearings run; the result reports the state at the last frame."""
    s = SCENARIOS["fig2"]
    truth = np.array([-1.2, 4.0, 1.2])
    mu5 = model.project(np.stack([model.G(truth, k) for k in range(5)]))
    b = resample_move.run(
        mu5[None], s.rho, s.prior.mean, s.prior.cov, 4000, np.random.default_rng(1)
    )
    assert b.ess.shape == (1, 5)
    m = b.moments()
    assert abs(m["depth_mean"][0] - 8.0) < 1.0
    one = resample_move.run(
        mu5[None, :1], s.rho, s.prior.mean, s.prior.cov, 500, np.random.default_rng(1)
    )
    assert one.particles.shape == (1, 500, 3)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"mu": [[np.nan, 0.0, 0.2]]}, "mu"),
        ({"mu": np.zeros((1, 0))}, "mu"),
        ({"rho": 0.0}, "rho"),
        ({"rho": [0.1, 0.2]}, "rho"),
        ({"prior_mean": [0.0, 1.0]}, "prior_mean"),
        ({"prior_cov": -np.eye(3)}, "prior_cov"),
        ({"n_particles": 1}, "n_particles"),
        ({"n_particles": 2.5}, "n_particles"),
        ({"rng": 3}, "rng"),
        ({"moves": -1}, "moves"),
        ({"ess_threshold": 1.5}, "ess_threshold"),
        ({"resampler": "stratified-ish"}, "resampler"),
    ],
)
def test_bad_input_is_refused_naming_the_argument(kwargs, name):
    s = SCENARIOS["fig2"]
    args = {
        "mu": [s.mu],
        "rho": s.rho,
        "prior_mean": s.prior.mean,
        "prior_cov": s.prior.cov,
        "n_particles": 100,
        "rng": np.random.default_rng(0),
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        resample_move.run(**args)


def test_every_particle_behind_the_camera_is_refused():
    with pytest.raises(ValueError, match="n_particles"):
        resample_move.run(
            [[0.0, 0.1, 0.2]], 0.01, [0.0, -1e6, 0.0], np.eye(3), 10, np.random.default_rng(0)
        )


def test_replicas_are_independent_runs_pooled():
    """replicated: R rows of one batch; the pool's weights are each replica's over R,
    its depth mean the replicas' average, and its errors those of replica_errors."""
    from depthcore.particles.resampling import replica_errors

    s = SCENARIOS["fig3"]
    mu = np.stack([s.mu, np.asarray(s.mu) + 1e-3])
    r = resample_move.replicated(
        mu, s.rho, s.prior.mean, s.prior.cov, 300, np.random.default_rng(2), replicas=3
    )
    alone = resample_move.run(
        np.repeat(mu, 3, axis=0), s.rho, s.prior.mean, s.prior.cov, 300, np.random.default_rng(2)
    )
    np.testing.assert_array_equal(r.runs.particles, alone.particles)
    assert r.particles.shape == (2, 900, 3) and r.log_weights.shape == (2, 900)
    np.testing.assert_allclose(np.exp(r.log_weights).sum(axis=1), 1.0, rtol=1e-12)
    each = r.replica_moments()
    assert each["depth_mean"].shape == (2, 3)
    np.testing.assert_allclose(r.moments()["depth_mean"], each["depth_mean"].mean(axis=1))
    errors, collapsed = r.errors()
    want, c = replica_errors(each["depth_mean"], each["depth_sd"])
    assert np.array_equal(collapsed | c, collapsed)
    np.testing.assert_array_equal(np.isnan(errors["depth_mean"]), collapsed)
    np.testing.assert_allclose(errors["depth_mean"][~collapsed], want[~collapsed])
    with pytest.raises(ValueError, match="replicas must be an integer >= 1"):
        resample_move.replicated(mu, s.rho, s.prior.mean, s.prior.cov, 300, None, replicas=0)
