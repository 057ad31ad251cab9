"""The particle filter (Prince section 19.5): resampling, weights, collapse, convergence."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats
from scipy.special import logsumexp

from depthcore.exact import bank, mixture, optimal
from depthcore.kalman.second_order import second_order_batch
from depthcore.particles import importance as pf
from depthcore.particles.importance import ParticleResult, run
from depthcore.problem import model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.scenarios import MU_17, SCENARIOS

FIG2 = SCENARIOS["fig2"]


@pytest.fixture(scope="module")
def fig2_optimal():
    return optimal.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, support="front")


def on_fig2(n_particles, rng, **options):
    """The particle filter on Figure 2's triple, with its prior."""
    return run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, n_particles, rng, **options)


def reference(opt):
    return np.array([opt.depth_mean, opt.depth_sd, opt.velocity_mean, opt.velocity_sd])


def replicates(n_particles, n_replicates, seed, scenario=FIG2, **kwargs):
    """``n_replicates`` independent filters on one triple, in one batched call."""
    mu = np.tile(scenario.mu, (n_replicates, 1))
    return run(
        mu,
        scenario.rho,
        scenario.prior.mean,
        scenario.prior.cov,
        n_particles,
        np.random.default_rng(seed),
        **kwargs,
    )


# --- weights ---------------------------------------------------------------------------


def test_result_log_weights_are_normalised_and_ess_matches():
    r = on_fig2(3000, np.random.default_rng(8))
    assert r.particles.shape == (3000, 3) and r.log_weights.shape == (3000,)
    assert_allclose(logsumexp(r.log_weights), 0.0, atol=1e-12)
    assert_allclose(r.ess[-1], 1.0 / np.sum(r.weights**2), rtol=1e-10)
    assert np.all(r.weights[r.particles[:, 1] <= 2.0] == 0.0)  # y1 = y3 - 2 <= 0: weight zero


def test_gaussian_proposal_is_the_limit_of_infinite_df():
    r = on_fig2(2000, np.random.default_rng(25), df=np.inf)
    m, S = second_order_batch(np.array([FIG2.mu]), FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    q = stats.multivariate_normal(m[0], pf.DEFAULT_INFLATION**2 * S[0])
    alive = np.isfinite(r.log_weights)
    diff = (
        r.log_weights[alive]
        + q.logpdf(r.particles[alive])
        - optimal.log_posterior(r.particles[alive], FIG2.mu, FIG2.rho, FIG2.prior)
    )
    assert_allclose(diff, diff[0], rtol=0, atol=1e-8)


def test_final_weights_are_posterior_over_proposal():
    # Without resampling the look-ahead terms cancel: log W = log p_o - log q + const,
    # with p_o the optimal posterior (6) and q the t proposal (scipy's density).
    N = 2000
    r = on_fig2(N, np.random.default_rng(9), ess_threshold=0.0)
    m, S = second_order_batch(np.array([FIG2.mu]), FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    q = stats.multivariate_t(m[0], pf.DEFAULT_INFLATION**2 * S[0], df=pf.DEFAULT_DF)
    x = r.particles
    alive = np.isfinite(r.log_weights)
    target = optimal.log_posterior(x[alive], FIG2.mu, FIG2.rho, FIG2.prior) - q.logpdf(x[alive])
    diff = r.log_weights[alive] - target
    assert alive.sum() > 0.9 * N
    assert_allclose(diff, diff[0], rtol=0, atol=1e-8)


# --- repeatability and batching --------------------------------------------------------


@pytest.mark.parametrize("proposal", ["second_order", "prior"])
def test_same_seed_gives_identical_output(proposal):
    kwargs = dict(proposal=proposal, ess_threshold=1.0)  # resampling at every step too
    a = on_fig2(500, np.random.default_rng(10), **kwargs)
    b = on_fig2(500, np.random.default_rng(10), **kwargs)
    c = on_fig2(500, np.random.default_rng(11), **kwargs)
    for name in ("particles", "log_weights", "ess", "resampled", "ancestors"):
        assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.particles, c.particles)


def test_single_is_the_batch_of_one():
    a = on_fig2(400, np.random.default_rng(12))
    b = run(
        np.array([FIG2.mu]),
        FIG2.rho,
        FIG2.prior.mean,
        FIG2.prior.cov,
        400,
        np.random.default_rng(12),
    )
    assert len(b) == 1
    assert_array_equal(a.particles, b.particles[0])
    assert_array_equal(a.log_weights, b.log_weights[0])
    assert_allclose(np.array(b.moments())[:, 0], a.moments(), rtol=1e-15)
    assert_allclose(np.array(b.standard_errors())[:, 0], a.standard_errors(), rtol=1e-15)


def test_batch_of_different_triples():
    rng = np.random.default_rng(13)
    mu = model.simulate(FIG2.c, 3, FIG2.rho, 0.0, rng, size=8).mu
    b = run(mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, 1000, rng)
    assert b.particles.shape == (8, 1000, 3) and b.ess.shape == (8, 3)
    assert_allclose(logsumexp(b.log_weights, axis=-1), 0.0, atol=1e-12)
    m = b.moments()
    for i in (0, 7):
        assert_allclose(b.trial(i).moments(), [f[i] for f in m], rtol=1e-12)


def test_resampling_duplicates_particles_with_their_ancestors():
    r = on_fig2(800, np.random.default_rng(14), ess_threshold=1.0)
    assert_array_equal(r.resampled, [False, True, True])
    assert len(np.unique(r.ancestors)) < 800
    for a in np.unique(r.ancestors)[:20]:
        same = r.particles[r.ancestors == a]
        assert_array_equal(same, np.broadcast_to(same[0], same.shape))
    assert r.distinct_ess() <= r.ess[-1] + 1e-9


def test_result_is_immutable():
    r = on_fig2(100, np.random.default_rng(15))
    with pytest.raises(ValueError):
        r.particles[0, 0] = 1.0
    with pytest.raises(AttributeError):
        r.ess = None


# --- collapse and convergence ----------------------------------------------------------


def test_bootstrap_collapses_on_fig2_while_the_proposal_does_not():
    N = 4000
    boot = on_fig2(N, np.random.default_rng(16), proposal="prior", ess_threshold=0.5)
    assert boot.ess[0] < 0.02 * N  # a bearing alone leaves a thin wedge of the prior
    assert boot.resampled[1]
    assert boot.distinct_ess() < 10  # the copies made by resampling count as one particle
    plain = on_fig2(N, np.random.default_rng(16), proposal="prior", ess_threshold=0.0)
    assert np.all(plain.ess[1:] < 10)  # after two bearings: a handful of particles
    good = on_fig2(N, np.random.default_rng(16))
    assert np.all(good.ess > 0.3 * N) and not good.resampled.any()
    assert good.distinct_ess() == pytest.approx(good.ess[-1], rel=1e-12)


def test_fig2_moments_agree_with_the_optimal_filter_at_N_4000(fig2_optimal):
    b = replicates(4000, 16, seed=17)
    est = np.array(b.moments())  # (4, R)
    ref = reference(fig2_optimal)[:, None]
    # Each replicate within 5 of its own delta-method standard errors ...
    se = np.array(b.standard_errors())
    assert np.all(np.abs(est - ref) < 5 * se)
    # ... and their average within 4 standard errors of the average.
    spread = est.std(axis=1, ddof=1) / np.sqrt(est.shape[1])
    assert np.all(np.abs(est.mean(axis=1) - ref[:, 0]) < 4 * spread)
    # The error is a few percent of the posterior SDs.
    assert np.all(np.abs(est - ref) < 0.1 * ref[[1, 1, 3, 3]])


def root_mean_square_errors(opt, sizes, n_replicates, seed):
    ref = reference(opt)[:, None]
    return np.array(
        [
            np.sqrt(
                np.mean(
                    (np.array(replicates(n, n_replicates, seed + i).moments()) - ref) ** 2, axis=1
                )
            )
            for i, n in enumerate(sizes)
        ]
    )


def test_error_shrinks_with_N(fig2_optimal):
    # 40 times the particles: the RMS error over 16 replicates should fall by
    # about sqrt(40) = 6.3 (between 3.4 and 9 over 20 seeds tried).
    rmse = root_mean_square_errors(fig2_optimal, (500, 20000), 16, seed=18)
    assert np.all(rmse[1] < rmse[0] / 2.5)


@pytest.mark.slow
def test_error_shrinks_like_one_over_root_N(fig2_optimal):
    sizes = (500, 2000, 20000)
    rmse = root_mean_square_errors(fig2_optimal, sizes, 48, seed=19)
    assert np.all(rmse[1:] < rmse[:-1])
    ratio = rmse[0] / rmse[-1]  # sqrt(40) = 6.3 expected
    assert np.all(ratio > 3.5) and np.all(ratio < 12)
    # At N = 20000 the errors are about 1 % of the posterior SDs.
    assert np.all(rmse[-1] < 0.015 * reference(fig2_optimal)[[1, 1, 3, 3]])


@pytest.mark.slow
@pytest.mark.parametrize("key", ["fig5", "fig6"])
def test_other_scenarios_agree_with_the_optimal_filter(key):
    s = SCENARIOS[key]
    opt = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, support="front")
    b = replicates(8000, 8, seed=20, scenario=s)
    est, se = np.array(b.moments()), np.array(b.standard_errors())
    assert np.all(np.abs(est - reference(opt)[:, None]) < 5 * se)


@pytest.mark.slow
def test_fig3_converges_without_resampling_but_not_with_it():
    # Fig. 3's posterior (depth 20.7 +- 13.7) is far from the second-order
    # Gaussian (10.0 +- 2.2): the hard case for the proposal.
    s = SCENARIOS["fig3"]
    ref = reference(optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, support="front"))[:, None]
    b = replicates(50000, 8, seed=24, scenario=s)
    est, se = np.array(b.moments()), np.array(b.standard_errors())
    assert np.all(np.abs(est - ref) < 5 * se)
    assert np.all(np.abs(est - ref) < 0.1 * ref[[1, 1, 3, 3]])
    # Resampling against the intermediate targets loses the far depth tail for good.
    b = replicates(50000, 8, seed=24, scenario=s, ess_threshold=0.5)
    assert np.all(b.resampled[:, 1:])
    assert np.all(np.array(b.moments()) - ref < -0.2 * ref[[1, 1, 3, 3]])


# --- densities -------------------------------------------------------------------------


def test_depth_density_approaches_the_optimal_marginal(fig2_optimal):
    r = on_fig2(20000, np.random.default_rng(21))
    grid = np.linspace(2.5, 14.0, 231)
    exact = fig2_optimal.depth_pdf(grid)
    step = grid[1] - grid[0]
    for method in ("kde", "histogram"):
        p = r.density("y", grid, method=method)
        assert p.shape == grid.shape and np.all(p >= 0)
        assert np.sum(p) * step == pytest.approx(1.0, abs=0.02)  # the grid holds ~all the mass
        assert np.sum(np.abs(p - exact)) * step < 0.1  # L1 distance
    v = np.linspace(0.0, 3.0, 151)
    l1 = np.sum(np.abs(r.density("v", v) - fig2_optimal.velocity_pdf(v))) * (v[1] - v[0])
    assert l1 < 0.1


def test_density_bandwidth_and_grid_checks():
    r = on_fig2(500, np.random.default_rng(22))
    narrow = r.density("y", np.linspace(0, 20, 50), bandwidth=0.05)
    wide = r.density("y", np.linspace(0, 20, 50), bandwidth=2.0)
    assert narrow.max() > wide.max()
    with pytest.raises(ValueError, match="evenly spaced"):
        r.density("y", [1.0, 2.0, 4.0], method="histogram")
    with pytest.raises(ValueError, match="grid must be increasing"):
        r.density("y", [3.0, 2.0])
    with pytest.raises(ValueError, match="bandwidth must be positive"):
        r.density("y", [1.0, 2.0], bandwidth=0.0)
    with pytest.raises(ValueError, match="method must be"):
        r.density("y", [1.0, 2.0], method="spline")
    with pytest.raises(ValueError, match="component must be one of"):
        r.marginal("depth")


# --- bad input -------------------------------------------------------------------------


@pytest.mark.parametrize("n", [0, -5, 2.5, True, "100"])
def test_rejects_bad_n_particles(n):
    with pytest.raises(ValueError, match="n_particles must be an integer >= 1"):
        run(MU_17, 0.005, FIG2.prior.mean, FIG2.prior.cov, n, np.random.default_rng(0))


@pytest.mark.parametrize(
    "mu, message",
    [
        ((0.1, 0.1, 0.1), "mu is degenerate"),
        ((-0.1, 0.0, 0.1), "mu is degenerate"),
        # a NaN bearing is a missing frame: a triple with one has two bearings
        ((np.nan, 0.0, 0.2), "mu has 2 bearings present"),
        ((0.2, 0.0, -0.3), "mu puts the point behind the camera"),
        ((-0.3, 0.0), r"mu must have shape (\(3,\)|\(\.\.\., N\) with N >= 3)"),
    ],
)
def test_rejects_bad_measurements(mu, message):
    with pytest.raises(ValueError, match=message):
        run(mu, 0.005, FIG2.prior.mean, FIG2.prior.cov, 100, np.random.default_rng(0))


@pytest.mark.parametrize(
    "rho, message",
    [(0.0, "rho must be positive"), (-1.0, "rho must be positive"), (np.inf, "rho must be finite")],
)
def test_rejects_bad_rho(rho, message):
    with pytest.raises(ValueError, match=message):
        run(MU_17, rho, FIG2.prior.mean, FIG2.prior.cov, 100, np.random.default_rng(0))
    with pytest.raises(ValueError, match=message):
        run(np.array([MU_17]), rho, FIG2.prior.mean, FIG2.prior.cov, 100, np.random.default_rng(0))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"proposal": "gaussian"}, "proposal must be one of"),
        ({"resampler": "stratified"}, "resampler must be one of"),
        ({"ess_threshold": 1.5}, r"ess_threshold must lie in \[0, 1\]"),
        ({"ess_threshold": -0.1}, r"ess_threshold must lie in \[0, 1\]"),
        ({"df": 0.0}, "df must be positive"),
        ({"df": "many"}, "df must be numeric"),
        ({"inflation": -1.0}, "inflation must be positive"),
    ],
)
def test_rejects_bad_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        run(MU_17, 0.005, FIG2.prior.mean, FIG2.prior.cov, 100, np.random.default_rng(0), **kwargs)


def test_rejects_a_bad_rng_or_prior():
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        run(MU_17, 0.005, FIG2.prior.mean, FIG2.prior.cov, 100, 42)
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        run(MU_17, 0.005, FIG2.prior.mean, FIG2.prior.cov, 100, np.random.RandomState(0))


def test_run_rejects_bad_shapes():
    rng = np.random.default_rng(0)
    p = FIG2.prior
    one = run(np.array(MU_17), 0.005, p.mean, p.cov, 10, np.random.default_rng(1))
    batch = run(np.array([MU_17]), 0.005, p.mean, p.cov, 10, np.random.default_rng(1))
    assert isinstance(one, ParticleResult) and np.array_equal(one.particles, batch.particles[0])
    with pytest.raises(ValueError, match=r"mu must have shape"):
        run(np.array([[MU_17]]), 0.005, p.mean, p.cov, 10, rng)
    with pytest.raises(ValueError, match=r"rho must be a scalar or have shape \(2,\)"):
        run(np.array([MU_17, MU_17]), [0.005] * 3, p.mean, p.cov, 10, rng)
    with pytest.raises(ValueError, match=r"prior_mean must have shape \(3,\) or \(2, 3\)"):
        run(np.array([MU_17, MU_17]), 0.005, np.zeros((3, 3)), p.cov, 10, rng)
    with pytest.raises(ValueError, match="prior_cov must be positive definite"):
        run(np.array([MU_17]), 0.005, p.mean, -np.eye(3), 10, rng)
    with pytest.raises(ValueError, match=r"mu\[1\] is degenerate"):
        run(np.array([MU_17, (0.1, 0.1, 0.1)]), 0.005, p.mean, p.cov, 10, rng)


def test_prior_proposal_with_one_particle_can_lose_every_particle():
    # Half the prior's mass is behind the camera; a lone particle there has weight zero.
    prior = Gaussian(FIG2.prior.mean - [0.0, 60.0, 0.0], FIG2.prior.cov)
    with pytest.raises(ValueError, match="^n_particles: every particle of trial 0 has zero weight"):
        run(FIG2.mu, FIG2.rho, prior.mean, prior.cov, 1, np.random.default_rng(0), proposal="prior")


# --- N frames ---------------------------------------------------------------------------


def test_n_frame_importance_sampling_matches_the_bank_of_kalman_filters():
    # The exact N-frame posterior (a bank of Kalman filters over the depth at frame 1,
    # depthcore.exact.bank) against the importance sample with the N-frame p_s proposal.
    x1 = np.array([-1.0, 5.0, 0.3])
    rho = 0.01
    mu = model.simulate(x1, 6, rho, 0.0, np.random.default_rng(21), frame=1).mu
    prior = Gaussian(x1 + [0.5, 1.0, -0.1], np.diag([4.0, 9.0, 0.25]))
    mean_s, cov_s = second_order_batch(mu[None], rho, prior.mean, prior.cov)
    sd_y1 = np.sqrt(cov_s[0, 1, 1])
    y1 = np.linspace(max(1e-3, mean_s[0, 1] - 5 - 15 * sd_y1), mean_s[0, 1] - 5 + 15 * sd_y1, 4001)
    w = np.full(y1.shape, y1[1] - y1[0])
    w[[0, -1]] /= 2
    exact = mixture.mixture(bank.filter_bank(y1, mu, rho, prior.mean, prior.cov), w)
    r = run(mu, rho, prior.mean, prior.cov, 40_000, np.random.default_rng(22))
    assert r.particles.shape == (40_000, 3) and r.ess.shape == (6,)
    m, se = r.moments(), r.standard_errors()
    for got, err, want in (
        (m.depth_mean, se.depth_mean, exact.depth_mean),
        (m.depth_sd, se.depth_sd, exact.depth_sd),
        (m.velocity_mean, se.velocity_mean, exact.velocity_mean),
        (m.velocity_sd, se.velocity_sd, exact.velocity_sd),
    ):
        assert abs(got - want) < 5 * err, (got, want, err)


@pytest.mark.parametrize("proposal", ["second_order", "prior"])
@pytest.mark.parametrize("n_frames", [3, 8])
def test_a_run_without_resampling_is_the_frame_by_frame_loop(proposal, n_frames, monkeypatch):
    """``ess_threshold = 0`` takes several frames at once and normalises once; the per-frame
    loop (forced here by a threshold so small that it never fires) gives the same particles,
    weights and ESS after every frame to rounding, from the same draws."""
    rng = np.random.default_rng(11)
    x1 = np.array([-1.2, 4.0, 0.3])
    mu = model.simulate(x1, n_frames, 5e-3, 0.0, rng, size=3, frame=1).mu
    args = (mu, 5e-3, x1 + [0.1, -0.3, 0.0], 0.5 * np.eye(3), 500)
    fast = run(*args, np.random.default_rng(2), proposal=proposal)
    slow = run(*args, np.random.default_rng(2), proposal=proposal, ess_threshold=1e-300)
    assert not slow.resampled.any()
    assert_allclose(fast.particles, slow.particles, rtol=1e-12, atol=1e-12)
    assert_allclose(np.exp(fast.log_weights), np.exp(slow.log_weights), rtol=1e-9, atol=1e-15)
    assert_allclose(fast.ess, slow.ess, rtol=1e-9)
    # blocks of one frame each give the same as one block of all of them
    monkeypatch.setattr(pf, "_BLOCK_FLOATS", 1)
    tiny = run(*args, np.random.default_rng(2), proposal=proposal)
    assert_allclose(tiny.ess, fast.ess, rtol=1e-12)
    assert_allclose(tiny.log_weights, fast.log_weights, rtol=1e-12, atol=1e-12)
