"""The registry of filters: one calling convention and one result shape, single and batched."""

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.exact import optimal, posterior
from depthcore.kalman import ekf, inverse_depth, iterated, ukf
from depthcore.particles import depth_hypotheses, importance
from depthcore.problem import checks, model
from depthcore.problem.gaussian import paper_prior_means
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.estimates import FAMILIES, FAMILY, QUANTITIES
from depthcore.registry.filters import (
    ALL_NAMES,
    FILTERS,
    NAMES,
    PAPER_FILTERS,
    check_names,
    get,
    names,
)

FIG2 = SCENARIOS["fig2"]


def _batch(n=4, seed=3):
    mu = model.simulate(FIG2.c, 3, FIG2.rho, 0.0, np.random.default_rng(seed), size=n).mu
    return mu, paper_prior_means(model.noise_free_states(mu)), FIG2.prior.cov


def _options(name, seed=0):
    return {"rng": np.random.default_rng(seed), "n_particles": 500} if FILTERS[name].random else {}


def test_registry_lists_the_five_filters_in_table_order():
    assert NAMES == ("optimal", "second_order", "ekf", "ukf", "particle")
    assert PAPER_FILTERS == ("optimal", "second_order", "ekf")
    assert ALL_NAMES[: len(NAMES) + 4] == NAMES + (
        "iterated",
        "inverse_depth",
        "resample_move",
        "rbpf",
    )
    assert "range_parametrised" in ALL_NAMES
    for name, f in FILTERS.items():
        assert f.name == name and f.family in FAMILIES
        assert f.plot_style["label"] == f.label
        assert f.variants, name


@pytest.mark.parametrize("name", NAMES)
def test_single_triple_gives_floats_and_a_batch_arrays(name):
    f = FILTERS[name]
    one = f(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, **_options(name))
    assert np.ndim(one.depth_mean) == 0 and one.mean.shape == (3,) and one.cov.shape == (3, 3)
    mu, pm, pc = _batch()
    many = f(mu, FIG2.rho, pm, pc, **_options(name))
    for q in QUANTITIES:
        assert np.shape(many.moments(q)["mean"]) == (4,)
        assert np.shape(many.moments(q)["sd"]) == (4,)
    assert many.mean.shape == (4, 3) and many.cov.shape == (4, 3, 3)
    # The depth moments are those of the state's mean and covariance.
    assert_allclose(many.depth_mean, many.mean[:, 1], rtol=1e-12)
    assert_allclose(many.depth_sd, np.sqrt(many.cov[:, 1, 1]), rtol=1e-10)


@pytest.mark.parametrize("name", ["optimal", "second_order", "ekf", "ukf"])
def test_batch_rows_are_the_single_results(name):
    f = FILTERS[name]
    mu, pm, pc = _batch()
    rho = FIG2.rho * np.array([0.5, 1.0, 1.5, 2.0])
    many = f(mu, rho, pm, pc)
    for i in range(len(mu)):
        one = f(mu[i], rho[i], pm[i], pc)
        for q in QUANTITIES:
            assert many.moments(q)["mean"][i] == pytest.approx(one.moments(q)["mean"], rel=1e-8)
            assert many.moments(q)["sd"][i] == pytest.approx(one.moments(q)["sd"], rel=1e-8)


def test_estimates_are_those_of_each_filters_module():
    p = FIG2.prior
    o = FILTERS["optimal"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    m = optimal.run(FIG2.mu, FIG2.rho, p.mean, p.cov)
    assert (o.depth_mean, o.depth_sd, o.depth_error) == (m.depth_mean, m.depth_sd, m.depth_error)
    assert o.extras["prob_behind_camera"] == m.prob_behind_camera
    e = FILTERS["ekf"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    assert e.depth_error is None and "error" not in e.moments("depth")
    assert (e.depth_mean, e.depth_sd) == ekf.run(
        FIG2.mu, FIG2.rho, p.mean, p.cov
    ).posterior.marginal("y")
    u = FILTERS["ukf"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    h = ukf.run(FIG2.mu, FIG2.rho, p.mean, p.cov, allow_behind_camera=True)
    assert (u.velocity_mean, u.velocity_sd) == h.posterior.marginal("v")
    r = FILTERS["particle"](
        FIG2.mu, FIG2.rho, p.mean, p.cov, rng=np.random.SeedSequence(4), n_particles=800
    )
    direct = importance.run(FIG2.mu, FIG2.rho, p.mean, p.cov, 800, np.random.default_rng(4))
    assert r.depth_mean == direct.moments().depth_mean
    se = direct.standard_errors()
    assert r.depth_error == max(se.depth_mean, se.depth_sd)


def test_particle_filter_needs_an_explicit_random_source():
    p = FIG2.prior
    with pytest.raises(ValueError, match="rng is required"):
        FILTERS["particle"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    with pytest.raises(
        ValueError, match="rng must be a non-negative integer or a numpy.random.SeedSequence"
    ):
        FILTERS["particle"](FIG2.mu, FIG2.rho, p.mean, p.cov, rng="seed")


@pytest.mark.parametrize("name", names())
def test_density_integrates_to_about_one(name):
    f = FILTERS[name]
    est = f(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, **_options(name))
    grid = np.linspace(
        est.velocity_mean - 10 * est.velocity_sd, est.velocity_mean + 10 * est.velocity_sd, 4001
    )
    mass = np.trapezoid(f.density(est, "velocity", grid), grid)
    assert mass == pytest.approx(1.0, abs=0.02)
    with pytest.raises(ValueError, match="quantity must be one of"):
        f.density(est, "position", grid)


def test_every_family_says_what_a_study_reads():
    assert set(FAMILY) == set(FAMILIES)
    assert [n for n, f in FILTERS.items() if f.scoring.exact] == ["optimal"]
    for name, fam in FAMILY.items():
        assert fam.name == name
        # a result is the exact reference, a Gaussian, or weighted draws of the depth
        assert fam.exact + fam.gaussian + (fam.depth_draws is not None) == 1, name


@pytest.mark.parametrize("frames", [3, 5])
@pytest.mark.parametrize("name", names())
def test_a_familys_cdfs_are_its_distribution_at_the_truths(name, frames):
    """The CDFs a study reads, against routes of their own.

    The exact and Gaussian families' CDFs against the trapezoid integral of their
    densities (the Gaussian's against scipy's normal CDF as well); the samplers'
    against the weighted count of their draws below the truth, from
    ``depth_draws`` (depths) and from the particles (velocities).
    """
    from scipy import stats

    f = FILTERS[name]
    if frames != 3 and not f.any_frames:
        return
    rng = np.random.default_rng(5)
    sim = model.simulate(FIG2.c, frames, FIG2.rho, 0.0, rng, size=3)
    pm = paper_prior_means(model.noise_free_states(sim.mu[:, :3]))
    est = f(sim.mu, FIG2.rho, pm, FIG2.prior.cov, **_options(name))
    truths = sim.states[:, -1, :]
    depth_cdf, velocity_cdf = f.scoring.cdfs(est, truths)
    assert depth_cdf.shape == velocity_cdf.shape == (3,)
    assert np.all((0 <= depth_cdf) & (depth_cdf <= 1))
    if f.scoring.gaussian:
        expected = stats.norm.cdf(truths[:, 1], est.depth_mean, est.depth_sd)
        assert_allclose(depth_cdf, expected, rtol=1e-12, atol=1e-15)
    if f.scoring.exact or f.scoring.gaussian:
        for i in range(3):
            one = f(sim.mu[i], FIG2.rho, pm[i], FIG2.prior.cov)
            lo = one.depth_mean - 40 * one.depth_sd  # the exact one lives beyond N - 1
            lo = lo if f.scoring.gaussian else max(lo, frames - 1 + 1e-9)
            grid = np.linspace(lo, truths[i, 1], 20001)
            mass = np.trapezoid(f.density(one, "depth", grid), grid)
            assert mass == pytest.approx(depth_cdf[i], abs=2e-4)
    else:
        depths, W = f.scoring.depth_draws(est)
        assert_allclose(np.sum(W, axis=1), 1.0, rtol=1e-12)
        counted = np.sum(W * (depths <= truths[:, 1:2]), axis=1)
        # a grid of depth hypotheses collapsed to its Gaussian answers with that Gaussian,
        # whose draws are only its quantiles
        gaussian = np.zeros(3, dtype=bool)
        if isinstance(est.detail, depth_hypotheses.Hypotheses):
            gaussian = est.detail.collapsed
        normal = stats.norm.cdf(truths[:, 1], est.depth_mean, est.depth_sd)
        expected = np.where(gaussian, normal, counted)
        assert_allclose(depth_cdf, expected, rtol=1e-10, atol=1e-12)


def test_unknown_names_are_rejected():
    with pytest.raises(ValueError, match="filter must be one of"):
        get("kalman")
    with pytest.raises(ValueError, match="filters must be among"):
        check_names(["ekf", "kalman"])
    assert check_names(["ekf"]) == ("ekf",)


# --- N frames and process noise ---------------------------------------------------------

CASES = [
    (name, n, q)
    for name in names()
    for n in (3, 5)
    for q in (0.0, 0.01)
    if (n == 3 or FILTERS[name].any_frames) and (q == 0 or FILTERS[name].with_process_noise)
]


def _frames(n_frames, size=3, seed=3):
    rng = np.random.default_rng(seed)
    return model.simulate(FIG2.c, n_frames, FIG2.rho, 0.0, rng, size=size).mu


@pytest.mark.parametrize("name", names())
def test_each_filter_runs_what_it_declares_and_refuses_the_rest_by_name(name):
    # What an entry declares (any_frames, with_process_noise) is what a call does:
    # five frames run or are refused naming mu; process noise runs or is refused naming it.
    f, p = FILTERS[name], FIG2.prior
    five = _frames(5, size=1)[0]
    if f.any_frames:
        assert np.isfinite(f(five, FIG2.rho, p.mean, p.cov, **_options(name)).depth_mean)
    else:
        with pytest.raises(ValueError, match=r"^mu must have shape \(3,\)"):
            f(five, FIG2.rho, p.mean, p.cov, **_options(name))
    if f.with_process_noise:
        run = f(FIG2.mu, FIG2.rho, p.mean, p.cov, process_noise=0.01, **_options(name))
        assert np.isfinite(run.depth_mean)
    else:
        with pytest.raises(ValueError, match=r"^process_noise must be 0"):
            f(FIG2.mu, FIG2.rho, p.mean, p.cov, process_noise=0.01, **_options(name))


def test_the_default_filters_are_the_paper_problems_five():
    assert {n: f.default for n, f in FILTERS.items()} == {n: n in NAMES for n in names()}
    assert len(NAMES) == 5 and FILTERS["optimal"].frames == "any"


@pytest.mark.parametrize(("name", "n_frames", "q"), CASES)
def test_every_filter_runs_on_the_frames_and_process_noise_it_supports(name, n_frames, q):
    f = FILTERS[name]
    mu = _frames(n_frames)
    p = FIG2.prior
    many = f(mu, FIG2.rho, p.mean, p.cov, process_noise=q, **_options(name))
    assert many.mean.shape == (3, 3) and many.cov.shape == (3, 3, 3)
    assert np.all(np.isfinite(many.mean)) and np.all(np.isfinite(many.cov))
    for quantity in QUANTITIES:
        assert np.shape(many.moments(quantity)["mean"]) == (3,)
        assert np.all(many.moments(quantity)["sd"] > 0)
    one = f(mu[1], FIG2.rho, p.mean, p.cov, process_noise=q, **_options(name))
    assert one.mean.shape == (3,) and np.ndim(one.depth_mean) == 0
    if not f.random:  # the batch's rows are the single results
        assert_allclose(many.mean[1], one.mean, rtol=1e-8)
        assert_allclose(many.cov[1], one.cov, rtol=1e-7, atol=1e-12)


def test_the_estimate_is_of_the_state_at_frame_n():
    mu = _frames(6, size=1)[0]
    p = FIG2.prior
    h = ekf.run(mu, FIG2.rho, p.mean, p.cov, process_noise=0.01)
    e = FILTERS["ekf"](mu, FIG2.rho, p.mean, p.cov, process_noise=0.01)
    assert np.array_equal(e.mean, h.means[-1]) and np.array_equal(e.cov, h.covs[-1])
    means, _ = iterated.run(mu, FIG2.rho, p.mean, p.cov, 0.01)
    assert np.array_equal(FILTERS["iterated"](mu, FIG2.rho, p.mean, p.cov, 0.01).mean, means[-1])
    d = inverse_depth.estimate(mu, FIG2.rho, p.mean, p.cov, 0.01)
    assert np.array_equal(FILTERS["inverse_depth"](mu, FIG2.rho, p.mean, p.cov, 0.01).mean, d.mean)
    u = FILTERS["ukf"](mu, FIG2.rho, p.mean, p.cov)
    assert np.array_equal(
        u.mean, ukf.run(mu, FIG2.rho, p.mean, p.cov, 0.0, allow_behind_camera=True).means[-1]
    )


@pytest.mark.parametrize("name", names())
def test_the_papers_problem_is_unchanged_by_an_explicit_zero_process_noise(name):
    p = FIG2.prior
    a = FILTERS[name](FIG2.mu, FIG2.rho, p.mean, p.cov, **_options(name))
    b = FILTERS[name](FIG2.mu, FIG2.rho, p.mean, p.cov, process_noise=0.0, **_options(name))
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)


def test_unsupported_frames_and_process_noise_are_refused_naming_the_argument():
    p = FIG2.prior
    mu5 = _frames(5, size=1)[0]
    # the printed reading and the "all" support are readings of the three-frame Eq. (16)
    with pytest.raises(ValueError, match="reading and support other than"):
        FILTERS["optimal"](mu5, FIG2.rho, p.mean, p.cov, reading="printed")
    for name in ("particle", "resample_move"):
        with pytest.raises(ValueError, match="process_noise must be 0"):
            FILTERS[name](FIG2.mu, FIG2.rho, p.mean, p.cov, process_noise=0.01, **_options(name))
    with pytest.raises(ValueError, match="process_noise must be >= 0"):
        FILTERS["ekf"](FIG2.mu, FIG2.rho, p.mean, p.cov, process_noise=-0.01)
    with pytest.raises(ValueError, match=f"more than the {checks.MAX_FRAMES} frames"):
        FILTERS["ekf"](np.zeros(checks.MAX_FRAMES + 1), FIG2.rho, p.mean, p.cov)


def test_the_optimal_entry_is_the_bank_beyond_three_frames_and_the_paper_route_at_three():
    from depthcore.exact import optimal

    p = FIG2.prior
    mu5 = _frames(5, size=2)
    est = FILTERS["optimal"](mu5, FIG2.rho, p.mean, p.cov, process_noise=0.01)
    ref = posterior.moments(mu5, FIG2.rho, p.mean, p.cov, 0.01)
    assert_allclose(est.depth_mean, ref.depth_mean, rtol=1e-12)
    assert_allclose(est.velocity_sd, ref.velocity_sd, rtol=1e-11)
    assert np.all(est.depth_error <= 1e-10 * est.depth_sd)
    # three frames with no process noise: Eqs. (14)-(16), as before
    three = FILTERS["optimal"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    assert three.depth_mean == optimal.run(FIG2.mu, FIG2.rho, p.mean, p.cov).depth_mean


def test_every_filter_follows_a_camera_that_approaches_the_point():
    """60 frames, the camera 0.5 nearer each frame (steps -0.5), the point from depth 50 to 20.5:
    each door answers within 3 exact SDs of the exact filter's depth, but the second-order
    approximation, which takes only unit steps and refuses by name. Read the other way
    (receding), the exact filter's answer is more than 100 SDs away."""
    rng = np.random.default_rng(1)
    steps = np.full(59, -0.5)
    sim = model.simulate(np.array([1.0, 50.0, 0.3]), 60, 0.002, 0.0, rng, frame=1, steps=steps)
    prior = (np.array([0.0, 45.0, 0.0]), np.diag([4.0, 100.0, 1.0]))
    exact = FILTERS["optimal"](sim.mu, 0.002, *prior, steps=steps)
    sd = float(np.sqrt(exact.cov[1, 1]))
    assert abs(exact.mean[1] - sim.states[-1, 1]) < 3 * sd
    for name, entry in FILTERS.items():
        more = {"rng": np.random.default_rng(2)} if entry.random else {}
        if name in ("second_order",):  # the paper's three frames and unit steps only
            with pytest.raises(ValueError, match="^steps: the second-order .* only unit steps"):
                entry(sim.mu, 0.002, *prior, steps=steps, **more)
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            est = entry(sim.mu, 0.002, *prior, steps=steps, **more)
        assert abs(float(np.ravel(est.mean)[1]) - exact.mean[1]) < 3 * sd, name
    wrong = FILTERS["optimal"](sim.mu, 0.002, *prior, steps=-steps)
    assert abs(wrong.mean[1] - exact.mean[1]) > 100 * sd
