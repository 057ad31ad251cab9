"""The experiments beyond the paper: sweeps, the particle filter's convergence, the first update."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthbook import (
    beyond_filters,
    beyond_linear,
    beyond_particles,
    beyond_study,
    beyond_sweeps,
    paper,
)
from depthcore import SCENARIOS
from depthcore.exact import optimal, posterior
from depthcore.kalman import ekf, second_order, ukf
from depthcore.particles import rbpf, resample_move
from depthcore.problem import checks, gaussian, model
from depthcore.registry import estimates
from depthcore.registry.filters import FILTERS
from depthcore.studies import monte_carlo
from depthcore.studies import trials as study_trials

FIG2 = SCENARIOS["fig2"]


def test_first_update_is_the_filters_first_step():
    u = beyond_filters.first_update(FIG2)
    e = ekf.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    k = ukf.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, allow_behind_camera=True)
    assert_allclose(u["ekf"].mean, e.means[0], rtol=0, atol=0)
    assert_allclose(u["ukf"].cov, k.covs[0], rtol=0, atol=0)
    assert u["mu1"] == FIG2.mu[0]


def test_first_update_sigma_points_reach_behind_the_camera():
    u = beyond_filters.first_update(FIG2)
    X = u["sigma_points"]
    assert X.shape == (7, 3)
    # depth points at the prior depth +- sqrt(3 * 1000): one lies behind the camera
    spread = np.sqrt(3 * 1000.0)
    assert_allclose(sorted(X[:, 1] - FIG2.prior.mean[1])[::6], [-spread, spread], rtol=1e-12)
    assert X[:, 1].min() < 0


def test_first_update_ekf_keeps_the_ray_and_ukf_does_not():
    # The documented behaviour (depthcore/kalman/ukf.py): correlation of x and y after
    # mu1 is -1.00 for the EKF, 0.09 for the UKF.
    u = beyond_filters.first_update(FIG2)
    assert gaussian.correlation(u["ekf"].cov) == pytest.approx(-1.0, abs=1e-4)
    assert abs(gaussian.correlation(u["ukf"].cov)) < 0.2


def test_first_update_rejects_a_non_scenario():
    with pytest.raises(ValueError, match="scenario must be a Scenario"):
        beyond_filters.first_update("fig2")


@pytest.fixture(scope="module")
def convergence():
    return beyond_particles.particle_convergence(FIG2, [300, 600], repeats=4, seed=3)


def test_particle_convergence_shapes(convergence):
    r = convergence
    assert_allclose(r["sizes"], [300, 600])
    assert set(r["rmse"]) == set(beyond_particles.SETTINGS)
    for name in beyond_particles.SETTINGS:
        assert set(r["rmse"][name]) == set(estimates.MOMENTS)
        assert r["rmse"][name]["depth_mean"].shape == (2,)
        assert r["ess"][name].shape == (2, 3)
        # each RMSE carries its delta-method standard error, smaller than itself
        se = r["rmse_se"][name]["depth_mean"]
        assert se.shape == (2,) and np.all((se > 0) & (se < r["rmse"][name]["depth_mean"]))
    m = optimal.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    assert r["exact"]["depth_sd"] == m.depth_sd


def test_particle_convergence_default_is_close_and_bootstrap_collapses(convergence):
    r = convergence
    sd = r["exact"]["depth_sd"]
    # default: the RMS error of the depth mean is about 1.5 sd / sqrt(N)
    # (particle.py), i.e. ~0.07 sd at N = 300; 0.3 sd leaves room for 4 runs.
    assert np.all(r["rmse"]["default"]["depth_mean"] < 0.3 * sd)
    # ESS: about 0.43 N for the default; a few particles after mu2 for the bootstrap
    assert np.all(r["ess"]["default"] > 0.3)
    assert np.all(r["ess"]["bootstrap"][:, 1:] < 0.05)


def test_particle_convergence_streams_are_per_setting_and_repeatable(convergence):
    alone = beyond_particles.particle_convergence(
        FIG2, [300, 600], repeats=4, seed=3, settings={"default": {}}
    )
    for m in estimates.MOMENTS:
        assert_allclose(
            alone["rmse"]["default"][m], convergence["rmse"]["default"][m], rtol=0, atol=0
        )


def test_particle_convergence_chunks_repeats(monkeypatch):
    monkeypatch.setattr(beyond_particles, "CHUNK_PARTICLES", 500)  # one run of N = 300 per call
    r = beyond_particles.particle_convergence(
        FIG2, [300], repeats=3, seed=0, settings={"default": {}}
    )
    assert r["rmse"]["default"]["depth_mean"].shape == (1,)
    assert np.isfinite(r["rmse"]["default"]["depth_mean"]).all()


@pytest.mark.parametrize("bad", [[0], [1.5], [[10, 20]], []])
def test_particle_convergence_rejects_bad_sizes(bad):
    with pytest.raises(ValueError, match="sizes must be positive integers"):
        beyond_particles.particle_convergence(FIG2, bad, repeats=2, seed=0)


def test_particle_convergence_rejects_bad_repeats():
    with pytest.raises(ValueError, match="repeats must be a positive integer"):
        beyond_particles.particle_convergence(FIG2, [100], repeats=0, seed=0)


def test_noise_study_gathers_the_study_at_each_level():
    rhos = [1 / 500, 1 / 200]
    r = beyond_sweeps.noise_study(rhos, trials=30, seed=2, names=("optimal", "ekf"))
    direct = monte_carlo.study(rho=1 / 200, trials=30, seed=2, names=("optimal", "ekf"))
    assert r["valid_trials"][1] == direct["valid_trials"]
    assert r["ekf"]["coverage_68"][1] == direct["filters"]["ekf"]["depth"]["coverage_68"]
    assert r["optimal"]["nees"][1] == direct["filters"]["optimal"]["nees"]
    assert r["ekf"]["hellinger"][1] == direct["filters"]["ekf"]["hellinger_depth"]["mean"]
    assert r["ekf"]["rmse"].shape == (2,)
    assert r["ekf"]["coverage_68_se"][1] == direct["filters"]["ekf"]["depth"]["coverage_68_se"]
    assert r["optimal"]["nees_se"][1] == direct["filters"]["optimal"]["nees_se"]
    fig = beyond_sweeps.noise_study_figure(r)
    _, labels = fig.axes[0].get_legend_handles_labels()
    assert len(labels) == 3  # two filters and the 0.68 line
    plt.close(fig)


def test_noise_sweep_at_the_papers_noise_matches_figure2():
    s = SCENARIOS["fig2"]
    r = beyond_sweeps.noise_sweep([s.rho])
    m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    assert r["optimal"]["depth_mean"][0] == pytest.approx(m.depth_mean, rel=1e-9)
    assert r["ekf"]["depth_sd"][0] == pytest.approx(
        ekf.run(s.mu, s.rho, s.prior.mean, s.prior.cov).posterior.marginal("y")[1]
    )


def test_second_order_approaches_the_optimal_filter_as_noise_falls():
    r = beyond_sweeps.noise_sweep(1 / np.array([50.0, 200.0, 1000.0]))
    h = r["second_order"]["hellinger"]
    assert h[0] > h[1] > h[2]
    # the EKF's distance stays large: its error comes from the prior mean
    assert np.all(r["ekf"]["hellinger"] > 0.5)


def test_prior_offset_sweep_matches_figure6():
    s6 = SCENARIOS["fig6"]
    r = beyond_sweeps.prior_offset_sweep([0.0, 2.0])
    assert r["ekf"]["depth_mean"][1] == pytest.approx(
        ekf.run(s6.mu, s6.rho, s6.prior.mean, s6.prior.cov).posterior.mean[1]
    )
    assert r["second_order"]["depth_mean"][1] == pytest.approx(
        second_order.run(s6.mu, s6.rho, s6.prior.mean, s6.prior.cov).mean[1]
    )
    # the EKF follows the offset, the optimal filter hardly moves
    assert r["ekf"]["depth_mean"][1] - r["ekf"]["depth_mean"][0] > 1.5
    assert abs(np.diff(r["optimal"]["depth_mean"])[0]) < 0.01


def test_prior_offset_sweep_rejects_a_prior_behind_the_camera():
    with pytest.raises(ValueError, match="offsets must keep the prior's depth"):
        beyond_sweeps.prior_offset_sweep([-4.5])


def test_hellinger_is_zero_for_identical_densities_and_bounded():
    s = SCENARIOS["fig2"]
    ref = optimal.batch_marginals(np.array([s.mu]), s.rho, s.prior.mean, s.prior.cov)

    h = study_trials.hellinger(ref, ref.depth_log_pdf, ref.moments.depth_mean, ref.moments.depth_sd)
    assert_allclose(h, 0.0, atol=1e-6)  # H = sqrt(1 - BC): BC to 1e-12


# --- the prior mean's velocity, and where the EKF linearises -----------------------------------


def _prior_with_velocity(v0, offset=0.0):
    mean = gaussian.paper_prior_means(FIG2.c, offset)
    mean[2] = v0
    return gaussian.Gaussian(mean, FIG2.prior.cov)


def test_prior_velocity_sweep_matches_direct_runs():
    v = [-2.0, 0.0, 0.95]
    sw = beyond_sweeps.prior_velocity_sweep(v)
    for i, v0 in enumerate(v):
        prior = _prior_with_velocity(v0)
        direct = ekf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov).posterior.marginal("y")
        assert_allclose([sw["ekf"]["depth_mean"][i], sw["ekf"]["depth_sd"][i]], direct, rtol=1e-9)
    prior = _prior_with_velocity(-2.0)
    opt = optimal.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov)
    assert_allclose(sw["optimal"]["depth_sd"][0], opt.depth_sd, rtol=1e-8)
    # v0 = 0 is the paper's prior: Figure 2's EKF SD 0.16; near v0 = 0.95 the SD is the prior's
    assert abs(sw["ekf"]["depth_sd"][1] - 0.16) < 0.005 and sw["ekf"]["depth_sd"][2] > 25


def test_prior_velocity_sweep_runs_the_named_filters():
    v = [-2.0, 0.0, 0.95]
    sw = beyond_sweeps.prior_velocity_sweep(v, names=("ekf", "inverse_depth"))
    assert set(sw) == {"velocity", "optimal", "ekf", "inverse_depth"}
    for i, v0 in enumerate(v):
        prior = _prior_with_velocity(v0)
        direct = FILTERS["inverse_depth"](FIG2.mu, FIG2.rho, prior.mean, prior.cov)
        assert_allclose(sw["inverse_depth"]["depth_sd"][i], direct.depth_sd, rtol=1e-12)


def test_prior_velocity_sweep_at_c3_is_theorem_1():
    # Theorem 1: with the prior mean G^-2 c (velocity c3) the EKF is p_s.
    sw = beyond_sweeps.prior_velocity_sweep([FIG2.c[2]])
    assert_allclose(sw["ekf"]["depth_sd"], sw["second_order"]["depth_sd"], rtol=1e-8)


def test_prior_mean_map_rows_are_velocity_sweeps_and_change_sign():
    offsets, velocities = [0.0, 2.0], [-3.0, 0.0, 0.95, 3.0]
    m = beyond_sweeps.prior_mean_map(offsets, velocities)
    assert m["log10_sd_ratio"].shape == (2, 4)
    for i, offset in enumerate(offsets):
        sw = beyond_sweeps.prior_velocity_sweep(velocities, depth_offset=offset)
        assert_allclose(m["ekf_depth_sd"][i], sw["ekf"]["depth_sd"], rtol=1e-12)
        assert_allclose(m["optimal_depth_sd"][i], sw["optimal"]["depth_sd"], rtol=1e-8)
    signs = np.sign(m["log10_sd_ratio"][0])
    assert list(signs) == [-1, -1, 1, -1]  # too small, except near the pole at v0 = 0.95
    assert np.all(m["log10_sd_ratio"][1, [0, 1, 3]] < 0)


def test_prior_mean_map_rejects_a_prior_behind_the_camera():
    with pytest.raises(ValueError, match="offsets"):
        beyond_sweeps.prior_mean_map([-4.5], [0.0])


def test_ekf_linearisation_rows_give_eq24_and_the_residual_gradients():
    for v0 in (0.0, 0.95, FIG2.c[2]):
        prior = _prior_with_velocity(v0)
        lin = paper.ekf_linearisation(FIG2.mu, FIG2.rho, prior)
        P3 = ekf.run(FIG2.mu, FIG2.rho, prior.mean, prior.cov).posterior.cov
        F2 = np.array([[1.0, 0.0, -2.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        eq24 = lin["rows"].T @ lin["rows"] / FIG2.rho**2 + F2.T @ np.linalg.solve(prior.cov, F2)
        assert np.abs(eq24 @ P3 - np.eye(3)).max() < 1e-7
        assert_allclose(lin["depth_sd"][-1], np.sqrt(P3[1, 1]), rtol=1e-12)
    # Theorem 1's prior: the rows are the gradients of the residuals at c (Eqs. (20)-(22)).
    from depthcore.problem import model

    assert_allclose(lin["rows"], model.residual_gradients(FIG2.c), rtol=1e-12, atol=1e-15)


def test_bearings_depth_sd_is_the_broad_prior_limit():
    lin = paper.ekf_linearisation(FIG2.mu, FIG2.rho, FIG2.prior)
    R = lin["rows"]
    direct = FIG2.rho * np.sqrt(np.linalg.inv(R.T @ R)[1, 1])
    assert_allclose(lin["bearings_depth_sd"], direct, rtol=1e-8)
    # the prior 1000 I adds little: the EKF's SD is within 0.1 % of the bearings' alone
    assert abs(lin["bearings_depth_sd"] / lin["depth_sd"][-1] - 1) < 1e-3
    # bearings with no depth component leave the depth unresolved
    blind = np.array([[0.25, 0.0, 0.0], [0.2, 0.0, 0.0], [0.17, 0.0, 0.0]])
    assert paper.bearings_depth_sd(blind, 0.01) == np.inf
    with pytest.raises(ValueError, match="rho"):
        paper.bearings_depth_sd(lin["h"], 0.0)


def test_truncated_bearing_moments_against_monte_carlo_and_the_pole():
    mean, cov = FIG2.prior.mean, FIG2.prior.cov
    r = beyond_filters.truncated_bearing_moments(mean, cov, [1.0, 1e-2, 1e-4])
    rng = np.random.default_rng(5)
    xy = rng.multivariate_normal(mean[:2], cov[:2, :2], 1_000_000)
    keep = np.abs(xy[:, 1]) > 1.0
    q = np.where(keep, (xy[:, 0] / np.where(keep, xy[:, 1], 1.0)) ** 2, 0.0)
    assert abs(r["second_moment"][0] - q.mean()) < 5 * q.std() / np.sqrt(q.size)
    assert abs(r["mass"][0] - np.mean(~keep)) < 5 * np.sqrt(r["mass"][0] / q.size)
    # the mass scales like 2 eps p(0) and the moment like 2 p(0) E[x^2 | y = 0] / eps
    p0 = r["density_at_zero"]
    assert_allclose(r["mass"][1:] / r["eps"][1:], 2 * p0, rtol=1e-3)
    assert_allclose(r["second_moment"][2] * 1e-4, 2 * p0 * (mean[0] ** 2 + cov[0, 0]), rtol=1e-3)
    with pytest.raises(ValueError, match="eps"):
        beyond_filters.truncated_bearing_moments(mean, cov, [0.0])


def test_truth_study_gathers_the_study_at_each_truth():
    truths = np.array([FIG2.c, SCENARIOS["fig3"].c])
    r = beyond_study.truth_study(truths, FIG2.rho, trials=30, seed=2, names=("optimal", "ekf"))
    direct = monte_carlo.study(truths[1], FIG2.rho, trials=30, seed=2, names=("optimal", "ekf"))
    assert_allclose(r["truth"], truths)
    assert r["valid_trials"][1] == direct["valid_trials"]
    assert r["ekf"]["coverage_68"][1] == direct["filters"]["ekf"]["depth"]["coverage_68"]
    assert r["optimal"]["bias"][1] == direct["filters"]["optimal"]["depth"]["bias"]
    assert r["optimal"]["nees"][1] == direct["filters"]["optimal"]["nees"]
    assert r["ekf"]["rmse"].shape == (2,)


@pytest.mark.parametrize("bad", [np.zeros(3), np.zeros((2, 2)), np.full((1, 3), np.nan)])
def test_truth_study_rejects_bad_truths(bad):
    with pytest.raises(ValueError, match="truths"):
        beyond_study.truth_study(bad, FIG2.rho, trials=10, seed=0)


def test_resample_move_runs_are_the_filter_run_on_independent_streams():
    r = beyond_particles.resample_move_runs(FIG2, 2000, 3, seed=3, moves=5)
    exact = optimal.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    assert r["exact"]["depth_sd"] == exact.depth_sd
    streams = np.random.SeedSequence(3).spawn(3)
    for i, stream in enumerate(streams):
        rng = np.random.default_rng(stream)
        one = resample_move.run(
            [FIG2.mu], FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, 2000, rng, moves=5
        )
        assert r["runs"]["depth_mean"][i] == one.moments()["depth_mean"][0]
        assert_allclose(r["ess"][i], one.ess[0] / 2000)
    runs = r["runs"]["velocity_sd"]
    assert np.unique(runs).size == 3
    assert_allclose(r["mean"]["velocity_sd"], runs.mean())
    assert_allclose(r["se"]["velocity_sd"], runs.std(ddof=1) / np.sqrt(3))


def test_resample_move_runs_rejects_bad_arguments():
    with pytest.raises(ValueError, match="scenario"):
        beyond_particles.resample_move_runs("fig2", 100, 2, seed=0)
    with pytest.raises(ValueError, match="repeats"):
        beyond_particles.resample_move_runs(FIG2, 100, 1, seed=0)


# --- the Rao-Blackwellised particle filter against the bank ----------------------------


def _rbpf_track():
    s = SCENARIOS["fig2"]
    sim = model.simulate(model.G(s.c, -2), 6, s.rho, 0.01, np.random.default_rng(3), frame=1)
    return sim.mu, s.rho, s.prior.mean, s.prior.cov


def test_rbpf_convergence_measures_each_cloud_from_the_exact_bank():
    mu, rho, pm, pc = _rbpf_track()
    r = beyond_linear.rbpf_convergence(mu, rho, pm, pc, [20, 600], 4, seed=11, process_noise=0.01)
    exact = posterior.posterior(mu, rho, pm, pc, 0.01)
    assert r["frames"] == 6 and r["replicas"] == 4 and list(r["sizes"]) == [20, 600]
    assert r["exact"]["depth_mean"] == pytest.approx(float(exact.depth_mean), rel=1e-14)
    assert r["exact_error"]["depth"] == pytest.approx(float(exact.depth_error), rel=1e-14)
    # the runs are the filter's own clouds, from the seed's child streams
    stream = np.random.default_rng(checks.spawn(11, 2)[1])
    again = rbpf.run(mu, rho, pm, pc, 600, stream, process_noise=0.01, replicas=4).replica_moments()
    assert np.array_equal(r["runs"]["depth_sd"][1], again.depth_sd)
    for m in estimates.MOMENTS:
        runs = r["runs"][m]
        assert runs.shape == (2, 4)
        assert_allclose(r["rmse"][m], np.sqrt(np.mean((runs - r["exact"][m]) ** 2, axis=1)))
        assert_allclose(r["se"][m], np.std(runs, axis=1, ddof=1) / 2.0)
    # 600 particles estimate the depth mean to within a few exact SDs / sqrt(600)
    assert r["rmse"]["depth_mean"][1] < 5 * r["exact"]["depth_sd"] / np.sqrt(600)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(sizes=[1, 10]), "sizes must be integers >= 2"),
        (dict(sizes=[2.5]), "sizes must be positive integers"),
        (dict(replicas=1), "replicas must be an integer >= 2"),
        (dict(mu=np.zeros((2, 3))), r"mu must have shape \(N,\)"),
    ],
)
def test_rbpf_convergence_refuses_bad_input(kwargs, message):
    mu, rho, pm, pc = _rbpf_track()
    args = dict(mu=mu, rho=rho, prior_mean=pm, prior_cov=pc, sizes=[10], replicas=2, seed=1)
    with pytest.raises(ValueError, match=message):
        beyond_linear.rbpf_convergence(**dict(args, **kwargs))
