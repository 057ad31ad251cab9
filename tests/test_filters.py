"""The registry of filters: one calling convention and one result shape, single and batched."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore import ekf, model, optimal, particle, ukf
from depthcore.filters import FILTERS, NAMES, PAPER_FILTERS, QUANTITIES, check_names, get
from depthcore.gaussian import paper_prior_means
from depthcore.scenarios import SCENARIOS

FIG2 = SCENARIOS["fig2"]


def _batch(n=4, seed=3):
    mu = model.simulate_measurements(
        model.G(FIG2.c, -2), FIG2.rho, np.random.default_rng(seed), size=n
    )
    return mu, paper_prior_means(model.noise_free_states(mu)), FIG2.prior.cov


def _options(name, seed=0):
    return {"rng": np.random.default_rng(seed), "n_particles": 500} if FILTERS[name].random else {}


def test_registry_lists_the_five_filters_in_table_order():
    assert NAMES == ("optimal", "second_order", "ekf", "ukf", "particle")
    assert PAPER_FILTERS == ("optimal", "second_order", "ekf")
    for name, f in FILTERS.items():
        assert f.name == name and f.family in ("exact", "gaussian", "particles")
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
    m = optimal.marginals(FIG2.mu, FIG2.rho, p)
    assert (o.depth_mean, o.depth_sd, o.depth_error) == (m.depth_mean, m.depth_sd, m.depth_error)
    assert o.extras["prob_behind_camera"] == m.prob_behind_camera
    e = FILTERS["ekf"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    assert e.depth_error is None and "error" not in e.moments("depth")
    assert (e.depth_mean, e.depth_sd) == ekf.ekf(FIG2.mu, FIG2.rho, p).posterior.marginal("y")
    u = FILTERS["ukf"](FIG2.mu, FIG2.rho, p.mean, p.cov)
    h = ukf.ukf(FIG2.mu, FIG2.rho, p, allow_behind_camera=True)
    assert (u.velocity_mean, u.velocity_sd) == h.posterior.marginal("v")
    r = FILTERS["particle"](
        FIG2.mu, FIG2.rho, p.mean, p.cov, rng=np.random.SeedSequence(4), n_particles=800
    )
    direct = particle.particle_filter(FIG2.mu, FIG2.rho, p, 800, np.random.default_rng(4))
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


@pytest.mark.parametrize("name", NAMES)
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


def test_unknown_names_are_rejected():
    with pytest.raises(ValueError, match="filter must be one of"):
        get("kalman")
    with pytest.raises(ValueError, match="filters must be among"):
        check_names(["ekf", "kalman"])
    assert check_names(["ekf"]) == ("ekf",)
