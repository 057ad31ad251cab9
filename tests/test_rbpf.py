"""The Rao-Blackwellised particle filter (textbook 19.5.3) against the exact bank of Kalman filters.

Independent routes: the one-dimensional quadrature of Eqs. (14)-(16)
(:func:`depthcore.exact.optimal.moments`) at N = 3, q = 0; the bank of Kalman
filters on a converged log-depth rule (tests/test_bank.py) for N = 10,
q > 0; batch least squares at a fixed depth for the weights; scipy's
truncated normal for the draws from the prior. Tolerances are quantiles of the
distributions the errors have if the filter is right (chi-square, F, Student
t, normal), at false-alarm rates of 1e-4 or below per check.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats
from test_bank import batch_least_squares, converged_mixture, long_track

from depthcore.exact import bank as bk
from depthcore.exact import optimal
from depthcore.particles import rbpf
from depthcore.particles.resampling import weighted_standard_errors
from depthcore.problem.scenarios import RHO_200, SCENARIOS

FALSE_ALARM = 1e-4


def fig2_args():
    s = SCENARIOS["fig2"]
    return dict(mu=s.mu, rho=s.rho, prior_mean=s.prior.mean, prior_cov=s.prior.cov)


def exact_fig2():
    s = SCENARIOS["fig2"]
    return optimal.moments(np.array([s.mu]), s.rho, s.prior.mean, s.prior.cov)


# --- the prior draws and the weights --------------------------------------------------


@pytest.mark.parametrize("m_y, s_y", [(4.47, 31.6), (-50.0, 10.0), (300.0, 2.0)])
def test_prior_depths_are_the_truncated_gaussian(m_y, s_y):
    """Draws from N(m_y, s_y**2) restricted to y > 0 pass a KS test against scipy's truncnorm,
    also five SDs into the tail (m_y = -50, s_y = 10)."""
    cov = np.diag([1.0, s_y**2, 1.0])
    y = rbpf.prior_depths(np.array([0.0, m_y, 0.0]), cov, (20_000,), np.random.default_rng(0))
    assert np.all(y > 0)
    law = stats.truncnorm(-m_y / s_y, np.inf, loc=m_y, scale=s_y)
    assert stats.kstest(y, law.cdf).pvalue > FALSE_ALARM


@pytest.mark.parametrize("q", [0.0, 0.03])
def test_textbook_19_5_2_weights_are_the_marginal_likelihoods_at_each_depth(q):
    """Without resampling the log weights after N frames are log p(mu_1 .. mu_N | y^(j)) up to a
    constant (the particles come from the prior), checked against batch least squares at each
    depth; each particle's Gaussian of (x_N, v_N) is the least-squares one (textbook 19.2.3)."""
    N = 6
    sim, prior = long_track(N, q, seed=2)
    f = rbpf.run(
        sim.mu,
        RHO_200,
        prior.mean,
        prior.cov,
        8,
        np.random.default_rng(1),
        process_noise=q,
        ess_threshold=0,
    )
    assert not f.resampled.any()
    y = f.bank.nodes[0]
    rows = [batch_least_squares(yj, sim.mu, RHO_200, q, prior.mean, prior.cov) for yj in y]
    log_prior = stats.norm(prior.mean[1], np.sqrt(prior.cov[1, 1])).logpdf(y)
    log_like = np.array([r[0] for r in rows]) - log_prior
    expected = log_like - np.max(log_like)
    ours = f.log_weights[0] - np.max(f.log_weights[0])
    assert_allclose(ours, expected, rtol=0, atol=1e-8 * np.max(np.abs(expected)))
    assert_allclose(f.bank.mean[0], [r[1][-1] for r in rows], rtol=1e-8, atol=1e-10)
    assert_allclose(f.bank.cov[0], [r[2][-1] for r in rows], rtol=1e-7, atol=1e-14)


# --- (a) convergence to the exact moments ---------------------------------------------


def test_textbook_19_5_3_error_falls_like_one_over_root_particles_eqs_14_16():
    """With resampling off (importance sampling of the depth from its prior, each particle
    carrying its exact Kalman filter), on Figure 2 the error of the depth and velocity means from
    Eqs. (14)-(16) is that of the delta-method standard error, and falls like 1 / sqrt(J).

    For R = 16 replicas at each J: sum of (error / SE)**2 lies within the chi-square(R)
    quantiles; the mean squared errors at J = 1000 and J = 16000, scaled by J, agree within
    the F(R, R) quantiles (the errors' ratio would be 16 times bigger were they not falling).
    """
    exact = exact_fig2()
    R = 16
    lo, hi = stats.chi2(R).ppf([FALSE_ALARM, 1 - FALSE_ALARM])
    mse = {}
    for J in (1000, 4000, 16000):
        f = rbpf.run(
            **fig2_args(), n_particles=J, rng=np.random.default_rng(J), replicas=R, ess_threshold=0
        )
        assert not f.resampled.any()
        m = f.replica_moments()
        W = np.exp(f.log_weights)  # (R, J)
        for name, values, truth in (
            ("depth", f.bank.nodes + 2.0, exact.depth_mean[0]),
            ("velocity", f.bank.mean[..., 1], exact.velocity_mean[0]),
        ):
            estimate = getattr(m, f"{name}_mean")
            assert_allclose(estimate, np.sum(W * values, axis=-1), rtol=1e-12)
            se = weighted_standard_errors(values, W)[0]
            z2 = np.sum(((estimate - truth) / se) ** 2)
            assert lo < z2 < hi, (name, J, z2)
            mse[name, J] = np.mean((estimate - truth) ** 2)
    f_lo, f_hi = stats.f(R, R).ppf([FALSE_ALARM, 1 - FALSE_ALARM])
    for name in ("depth", "velocity"):
        ratio = mse[name, 1000] * 1000 / (mse[name, 16000] * 16000)
        assert f_lo < ratio < f_hi, (name, ratio)


# --- (b) N = 10, q = 0.01 against the bank ---------------------------------------------


def test_textbook_19_5_3_n10_moments_agree_with_the_bank_within_standard_errors():
    """N = 10 frames, q = 0.01, with resampling and moves: the replicas' average of the depth and
    velocity means and SDs at frame 10 lies within the Student t(R - 1) quantile times the
    replicas' standard error of the bank's converged mixture (textbook 19.2.3 at every depth)."""
    N, q, R = 10, 0.01, 12
    sim, prior = long_track(N, q, seed=4)
    exact = converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov, q=q)
    f = rbpf.run(
        sim.mu,
        RHO_200,
        prior.mean,
        prior.cov,
        500,
        np.random.default_rng(5),
        process_noise=q,
        replicas=R,
    )
    assert f.resampled.any(axis=-1).all()  # the moves were exercised
    m, se = f.moments(), f.standard_errors()
    bound = stats.t(R - 1).ppf(1 - FALSE_ALARM / 2)
    for name in ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd"):
        error = abs(getattr(m, name) - getattr(exact, name))
        assert error < bound * getattr(se, name), (name, error / getattr(se, name))
    assert f.ess.shape == (R, N) and np.all((f.ess >= 1) & (f.ess <= 500 * (1 + 1e-12)))


# --- (c) the move leaves the posterior invariant ---------------------------------------


def exact_draws(mx, n, rng):
    """Inverse-CDF draws of y_1 from the bank's depth mixture.

    The CDF is the cumulative trapezoid rule, in t = log(y_1), of the mixture's density
    (:meth:`depthcore.exact.mixture.Mixture.depth_pdf`) on 40001 points spanning the depths where
    the
    converged nodes hold their mass; it is inverted by linear interpolation."""
    N = mx.bank.frames
    big = mx.probabilities > 1e-20 * mx.probabilities.max()
    t = np.linspace(np.log(mx.bank.nodes[big].min()), np.log(mx.bank.nodes[big].max()), 40_001)
    dens = mx.depth_pdf(np.exp(t) + N - 1) * np.exp(t)  # dy = y dt
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(t))])
    assert abs(cdf[-1] - 1.0) < 1e-8  # the density is normalised and the grid covers its mass
    return np.exp(np.interp(rng.uniform(0.0, cdf[-1], n), cdf, t))


def moment_z_scores(y, v, mx):
    """z-scores of the sample mean and variance of the depth and of the mean of E[v_N | y]."""
    n = len(y)
    d = y - mx.depth_mean
    var_se = np.sqrt(np.var(d**2) / n)
    return np.array(
        [
            np.mean(d) / (np.std(y) / np.sqrt(n)),
            (np.mean(d**2) - mx.depth_sd**2) / var_se,
            (np.mean(v) - mx.velocity_mean) / (np.std(v) / np.sqrt(n)),
        ]
    )


@pytest.mark.parametrize("N, q", [(3, 0.0), (10, 0.01)])
def test_metropolis_hastings_move_leaves_the_exact_posterior_invariant(N, q):
    """Exact draws from the depth posterior (each with its Kalman filter, textbook 19.2.3), moved
    ten times: the moved depths keep the exact mean and variance, and E[v_N | y] its exact mean,
    within normal quantiles (the chains are independent, so the moved draws are too). Each moved
    particle carries the filter rerun at its new depth. Moving the same draws towards the
    posterior given one bearing fewer shifts them far beyond those quantiles (the check's power).
    """
    sim, prior = long_track(N, q, seed=6)
    mx = converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov, q=q)
    rng = np.random.default_rng(7)
    n = 10_000
    y1 = exact_draws(mx, n, rng)
    start = bk.filter_bank(y1, sim.mu, RHO_200, prior.mean, prior.cov, q)
    z_start = moment_z_scores(y1 + N - 1, start.mean[:, 1], mx)
    bound = stats.norm.ppf(1 - FALSE_ALARM / 2)
    assert np.all(np.abs(z_start) < bound), z_start
    moved, acceptance = rbpf.rejuvenate(start, 2.38 * mx.depth_sd, 10, rng)
    assert 0.2 < acceptance < 0.8
    assert np.mean(moved.nodes != y1) > 0.9
    z = moment_z_scores(moved.nodes + N - 1, moved.mean[:, 1], mx)
    assert np.all(np.abs(z) < bound), z
    fresh = bk.filter_bank(moved.nodes, sim.mu, RHO_200, prior.mean, prior.cov, q)
    assert_allclose(moved.mean, fresh.mean, rtol=1e-12, atol=1e-14)
    assert_allclose(moved.log_weight, fresh.log_weight, rtol=1e-12)
    # the wrong target: one bearing fewer
    fewer = bk.filter_bank(y1, sim.mu[:-1], RHO_200, prior.mean, prior.cov, q)
    wrong, _ = rbpf.rejuvenate(fewer, 2.38 * mx.depth_sd, 10, rng)
    assert abs(moment_z_scores(wrong.nodes + N - 1, start.mean[:, 1], mx)[0]) > 3 * bound


# --- online use, batches, reproducibility ----------------------------------------------


def test_online_steps_equal_one_run():
    """run over 6 frames, then step with the same generator, equals run over 7 frames."""
    sim, prior = long_track(7, 0.02, seed=3)
    args = (RHO_200, prior.mean, prior.cov, 300)
    rng = np.random.default_rng(11)
    online = rbpf.step(
        rbpf.run(sim.mu[:6], *args, rng, process_noise=0.02, replicas=2), sim.mu[6], rng
    )
    whole = rbpf.run(sim.mu, *args, np.random.default_rng(11), process_noise=0.02, replicas=2)
    for a, b in zip(online.bank[:4], whole.bank[:4], strict=True):
        assert_array_equal(a, b)
    assert_array_equal(online.log_weights, whole.log_weights)
    assert_array_equal(online.ess, whole.ess)
    assert online.frames == 7 and online.replicas == 2 and online.n_particles == 300


def test_batch_shapes_and_per_trial_noise():
    """mu of shape (B, N) with per-trial rho and q gives moments of shape (B,), histories
    (B, R, N); a trial's moments agree with the bank within the replicas' t quantile."""
    sim, prior = long_track(5, 0.0, seed=9)
    mu = np.stack([sim.mu, sim.mu + 0.001])
    rho, q = np.array([RHO_200, 2 * RHO_200]), np.array([0.0, 0.02])
    f = rbpf.run(
        mu, rho, prior.mean, prior.cov, 400, np.random.default_rng(2), process_noise=q, replicas=6
    )
    m, se = f.moments(), f.standard_errors()
    assert m.depth_mean.shape == (2,) and se.velocity_sd.shape == (2,)
    assert f.ess.shape == (2, 6, 5) and f.bank.nodes.shape == (2, 6, 400)
    bound = stats.t(5).ppf(1 - FALSE_ALARM / 2)
    for i in range(2):
        exact = converged_mixture(mu[i], rho[i], prior.mean, prior.cov, q=q[i])
        assert abs(m.depth_mean[i] - exact.depth_mean) < bound * se.depth_mean[i]
    single = rbpf.run(sim.mu, RHO_200, prior.mean, prior.cov, 400, np.random.default_rng(2))
    assert single.moments().depth_mean.shape == ()
    assert np.isnan(single.standard_errors().depth_mean)


def test_a_seed_gives_reproducible_results():
    a = rbpf.run(**fig2_args(), n_particles=500, rng=np.random.SeedSequence(3), replicas=2)
    b = rbpf.run(**fig2_args(), n_particles=500, rng=np.random.SeedSequence(3), replicas=2)
    c = rbpf.run(**fig2_args(), n_particles=500, rng=np.random.default_rng(3), replicas=2)
    d = rbpf.run(**fig2_args(), n_particles=500, rng=np.random.SeedSequence(4), replicas=2)
    for x in (b, c):
        assert_array_equal(a.bank.nodes, x.bank.nodes)
        assert_array_equal(a.log_weights, x.log_weights)
        assert_array_equal(a.acceptance, x.acceptance)
    assert not np.array_equal(a.bank.nodes, d.bank.nodes)


def test_without_moves_the_depths_degenerate():
    """moves = 0: after resampling at mu_3 (ESS of a few particles) the cloud holds under 2% of
    its particles as distinct depths; with the default moves, over half."""
    kw = dict(**fig2_args(), n_particles=4000)
    still = rbpf.run(**kw, rng=np.random.default_rng(8), moves=0)
    assert still.resampled[0, -1] and np.isnan(still.acceptance[0, -1])
    assert len(np.unique(still.bank.nodes)) < 0.02 * 4000
    moved = rbpf.run(**kw, rng=np.random.default_rng(8))
    assert len(np.unique(moved.bank.nodes)) > 0.5 * 4000


# --- (e) bad input ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(mu=[0.1, np.nan, 0.2]), "mu has 2 bearings present"),
        (dict(mu=np.zeros((2, 0))), "mu must have shape"),
        (dict(rho=0.0), "rho must be positive"),
        (dict(rho=[1.0, 2.0]), "rho must be a scalar or have shape"),
        (dict(prior_mean=[0.0, 1.0]), "prior_mean must have shape"),
        (dict(prior_cov=-np.eye(3)), "prior_cov must be positive definite"),
        (dict(process_noise=-0.1), "process_noise must be >= 0"),
        (dict(process_noise=[0.1, 0.2]), "process_noise must be a scalar or have shape"),
        (dict(n_particles=1), "n_particles must be an integer >= 2"),
        (dict(n_particles=100.0), "n_particles must be an integer >= 2"),
        (dict(replicas=0), "replicas must be an integer >= 1"),
        (dict(moves=-1), "moves must be an integer >= 0"),
        (dict(ess_threshold=1.5), r"ess_threshold must be a number in \[0, 1\]"),
        (dict(ess_threshold=np.nan), "ess_threshold must be finite"),
        (dict(resampler="stratified"), "resampler must be one of"),
        (dict(rng="seed"), "rng must be a non-negative integer or a numpy.random.SeedSequence"),
    ],
)
def test_run_refuses_bad_input_naming_the_argument(change, message):
    kwargs = dict(**fig2_args(), n_particles=10, rng=np.random.default_rng(0))
    kwargs.update(change)
    with pytest.raises(ValueError, match=message):
        rbpf.run(**kwargs)


def test_step_and_rejuvenate_refuse_bad_input():
    f = rbpf.run(**fig2_args(), n_particles=10, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="state must be an RBPF"):
        rbpf.step(f.bank, 0.1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="mu_next must be finite"):
        rbpf.step(f, np.inf, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"mu_next must be a scalar or have shape \(\)"):
        rbpf.step(f, [0.1, 0.2], np.random.default_rng(0))
    with pytest.raises(ValueError, match="bank must be a Bank"):
        rbpf.rejuvenate(f, 1.0, 1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="scale must be positive"):
        rbpf.rejuvenate(f.bank, 0.0, 1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="moves must be an integer >= 0"):
        rbpf.rejuvenate(f.bank, 1.0, 1.5, np.random.default_rng(0))


# --- the registry entry ------------------------------------------------------------------


def _registry(mu, prior, q, seed, n_particles=600, replicas=6):
    from depthcore.registry.filters import FILTERS

    return FILTERS["rbpf"](
        mu,
        RHO_200,
        prior.mean,
        prior.cov,
        process_noise=q,
        rng=np.random.SeedSequence(seed),
        n_particles=n_particles,
        replicas=replicas,
    )


@pytest.mark.parametrize(("frames", "q"), [(3, 0.0), (8, 0.02)])
def test_registry_entry_converges_to_the_bank_within_its_monte_carlo_error(frames, q):
    """Ten independent runs of FILTERS["rbpf"]: a one-sample t test of their moments
    against the bank's (false alarm 1e-4 per check), and their scatter agrees with the
    replicas' standard errors (an F test of the scatter's variance against the mean
    squared standard error, both tails)."""
    sim, prior = long_track(frames, q, seed=5)
    exact = converged_mixture(sim.mu, RHO_200, prior.mean, prior.cov, q=q)
    runs = [_registry(sim.mu, prior, q, seed) for seed in range(10)]
    t_bound = stats.t(9).ppf(1 - FALSE_ALARM / 2)
    for quantity in ("depth", "velocity"):
        for moment in ("mean", "sd"):
            est = np.array([getattr(r, f"{quantity}_{moment}") for r in runs])
            want = getattr(exact, f"{quantity}_{moment}")
            t = (np.mean(est) - want) / (np.std(est, ddof=1) / np.sqrt(len(est)))
            assert abs(t) < t_bound, (quantity, moment, t)
            # the replicas' standard errors measure the scatter of independent runs
            se = np.array(
                [getattr(r.detail.standard_errors(), f"{quantity}_{moment}") for r in runs]
            )
            ratio = np.var(est, ddof=1) / np.mean(se**2)
            f = stats.f(9, 10 * 5)
            assert f.ppf(FALSE_ALARM) < ratio < f.ppf(1 - FALSE_ALARM), (quantity, moment, ratio)
        # the reported error is the larger of the mean's and the SD's, each the standard
        # error widened by the Student t factor for R - 1 degrees of freedom
        r = runs[0]
        se = r.detail.standard_errors()
        factor = stats.t(r.detail.replicas - 1).ppf(0.975) / stats.norm.ppf(0.975)
        want = factor * max(getattr(se, f"{quantity}_mean"), getattr(se, f"{quantity}_sd"))
        assert r.collapsed is False
        assert getattr(r, f"{quantity}_error") == pytest.approx(want, rel=1e-12)


def test_registry_estimate_is_the_pooled_mixture_computed_particle_by_particle():
    """mean and cov by the law of total variance, summed particle by particle in 3 x 3
    matrices; the depth and velocity moments are theirs; the CDFs and the velocity
    density are the mixture's, the density integrating to its CDF."""
    sim, prior = long_track(6, 0.01, seed=2)
    est = _registry(sim.mu, prior, 0.01, seed=1, n_particles=50, replicas=3)
    f = est.detail
    b = f.bank
    second = np.zeros((3, 3))
    first = np.zeros(3)
    W = np.exp(f.log_weights) / f.replicas
    for r in range(f.replicas):
        for j in range(f.n_particles):
            m = np.array([b.mean[r, j, 0], b.nodes[r, j] + 5, b.mean[r, j, 1]])
            c = np.zeros((3, 3))
            c[np.ix_([0, 2], [0, 2])] = b.cov[r, j]
            first += W[r, j] * m
            second += W[r, j] * (c + np.outer(m, m))
    assert_allclose(est.mean, first, rtol=1e-12)
    assert_allclose(est.cov, second - np.outer(first, first), rtol=1e-7, atol=1e-12)
    assert_allclose([est.depth_mean, est.depth_sd], [first[1], np.sqrt(est.cov[1, 1])])
    assert_allclose([est.velocity_mean, est.velocity_sd], [first[2], np.sqrt(est.cov[2, 2])])
    y = first[1]
    assert_allclose(f.depth_cdf(y), np.sum(W * (b.nodes + 5 <= y)), rtol=1e-12)
    v = np.linspace(first[2] - 8 * est.velocity_sd, first[2] + 0.3 * est.velocity_sd, 20001)
    integral = np.trapezoid(f.velocity_pdf(v), v)
    assert_allclose(integral, f.velocity_cdf(v[-1]), atol=1e-6)
    cdf = np.sum(W * stats.norm.cdf(v[-1], b.mean[..., 1], np.sqrt(b.cov[..., 1, 1])))
    assert_allclose(f.velocity_cdf(v[-1]), cdf, rtol=1e-12)
    assert est.depth_error > 0 and est.velocity_error > 0


def test_registry_entry_needs_a_generator_and_refuses_in_one_line():
    from depthcore.registry.filters import FILTERS

    s = SCENARIOS["fig2"]
    with pytest.raises(ValueError, match="rng is required"):
        FILTERS["rbpf"](s.mu, s.rho, s.prior.mean, s.prior.cov)
    with pytest.raises(ValueError, match="n_particles"):
        FILTERS["rbpf"](s.mu, s.rho, s.prior.mean, s.prior.cov, rng=0, n_particles=1)
    with pytest.raises(ValueError, match="replicas"):
        FILTERS["rbpf"](s.mu, s.rho, s.prior.mean, s.prior.cov, rng=0, replicas=0)
