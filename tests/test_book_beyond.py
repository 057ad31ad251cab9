"""The helpers of the chapters beyond the paper: first updates, convergence, texts."""

import re

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from numpy.testing import assert_allclose  # noqa: E402

from depthcore import book_beyond, ekf, figures, optimal, reproduce, study, sweeps, ukf  # noqa: E402
from depthcore.book_beyond import _ellipse  # noqa: E402
from depthcore.scenarios import SCENARIOS  # noqa: E402

FIG2 = SCENARIOS["fig2"]


def test_first_update_is_the_filters_first_step():
    u = book_beyond.first_update(FIG2)
    e = ekf.ekf(FIG2.mu, FIG2.rho, FIG2.prior)
    k = ukf.ukf(FIG2.mu, FIG2.rho, FIG2.prior, allow_behind_camera=True)
    assert_allclose(u["ekf"].mean, e.means[0], rtol=0, atol=0)
    assert_allclose(u["ukf"].cov, k.covs[0], rtol=0, atol=0)
    assert u["mu1"] == FIG2.mu[0]


def test_first_update_sigma_points_reach_behind_the_camera():
    u = book_beyond.first_update(FIG2)
    X = u["sigma_points"]
    assert X.shape == (7, 3)
    # depth points at the prior depth +- sqrt(3 * 1000): one lies behind the camera
    spread = np.sqrt(3 * 1000.0)
    assert_allclose(sorted(X[:, 1] - FIG2.prior.mean[1])[::6], [-spread, spread], rtol=1e-12)
    assert X[:, 1].min() < 0


def test_first_update_ekf_keeps_the_ray_and_ukf_does_not():
    # The documented behaviour (depthcore/ukf.py): correlation of x and y after
    # mu1 is -1.00 for the EKF, 0.09 for the UKF.
    u = book_beyond.first_update(FIG2)
    assert book_beyond.correlation(u["ekf"].cov) == pytest.approx(-1.0, abs=1e-4)
    assert abs(book_beyond.correlation(u["ukf"].cov)) < 0.2


def test_first_update_rejects_a_non_scenario():
    with pytest.raises(ValueError, match="scenario must be a Scenario"):
        book_beyond.first_update("fig2")


def test_correlation_of_a_known_covariance():
    cov = np.array([[4.0, -3.0], [-3.0, 9.0]])
    assert book_beyond.correlation(cov) == pytest.approx(-0.5, rel=1e-15)
    with pytest.raises(ValueError, match="must be square"):
        book_beyond.correlation(np.ones((2, 3)))
    with pytest.raises(ValueError, match="must be positive"):
        book_beyond.correlation(np.diag([1.0, 0.0]))


def test_ellipse_lies_at_two_mahalanobis_units():
    mean, cov = np.array([1.0, -2.0]), np.array([[2.0, 0.6], [0.6, 1.0]])
    pts = _ellipse(mean, cov)
    d = pts - mean
    assert_allclose(np.einsum("ni,ni->n", d, np.linalg.solve(cov, d.T).T), 4.0, rtol=1e-12)


def test_first_update_figure_draws_both_filters():
    fig = book_beyond.first_update_figure(book_beyond.first_update(FIG2))
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    for name in ("ekf", "ukf"):
        assert any(label.startswith(figures.STYLE[name]["label"]) for label in labels)
    plt.close(fig)


@pytest.fixture(scope="module")
def convergence():
    return book_beyond.particle_convergence(FIG2, [300, 600], repeats=4, seed=3)


def test_particle_convergence_shapes(convergence):
    r = convergence
    assert_allclose(r["sizes"], [300, 600])
    assert set(r["rmse"]) == set(book_beyond.SETTINGS)
    for name in book_beyond.SETTINGS:
        assert set(r["rmse"][name]) == set(book_beyond.MOMENTS)
        assert r["rmse"][name]["depth_mean"].shape == (2,)
        assert r["ess"][name].shape == (2, 3)
    m = optimal.marginals(FIG2.mu, FIG2.rho, FIG2.prior)
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
    alone = book_beyond.particle_convergence(FIG2, [300, 600], repeats=4, seed=3,
                                             settings={"default": {}})
    for m in book_beyond.MOMENTS:
        assert_allclose(alone["rmse"]["default"][m], convergence["rmse"]["default"][m], rtol=0, atol=0)


def test_particle_convergence_chunks_repeats(monkeypatch):
    monkeypatch.setattr(book_beyond, "CHUNK_PARTICLES", 500)  # one run of N = 300 per call
    r = book_beyond.particle_convergence(FIG2, [300], repeats=3, seed=0, settings={"default": {}})
    assert r["rmse"]["default"]["depth_mean"].shape == (1,)
    assert np.isfinite(r["rmse"]["default"]["depth_mean"]).all()


@pytest.mark.parametrize("bad", [[0], [1.5], [[10, 20]], []])
def test_particle_convergence_rejects_bad_sizes(bad):
    with pytest.raises(ValueError, match="sizes must be positive integers"):
        book_beyond.particle_convergence(FIG2, bad, repeats=2, seed=0)


def test_particle_convergence_rejects_bad_repeats():
    with pytest.raises(ValueError, match="repeats must be a positive integer"):
        book_beyond.particle_convergence(FIG2, [100], repeats=0, seed=0)


def test_convergence_figure_draws_each_setting_and_the_reference(convergence):
    fig = book_beyond.convergence_figure(convergence)
    assert len(fig.axes) == 2
    assert len(fig.axes[0].get_lines()) == len(book_beyond.SETTINGS) + 1
    assert fig.axes[0].get_xscale() == "log" and fig.axes[0].get_yscale() == "log"
    plt.close(fig)
    with pytest.raises(ValueError, match="quantity must be one of"):
        book_beyond.convergence_figure(convergence, "position")


def test_noise_study_gathers_the_study_at_each_level():
    rhos = [1 / 500, 1 / 200]
    r = book_beyond.noise_study(rhos, trials=30, seed=2, names=("optimal", "ekf"))
    direct = study.study(rho=1 / 200, trials=30, seed=2, names=("optimal", "ekf"))
    assert r["valid_trials"][1] == direct["valid_trials"]
    assert r["ekf"]["coverage_68"][1] == direct["filters"]["ekf"]["depth"]["coverage_68"]
    assert r["optimal"]["nees"][1] == direct["filters"]["optimal"]["nees"]
    assert r["ekf"]["hellinger"][1] == direct["filters"]["ekf"]["hellinger_depth"]["mean"]
    assert r["ekf"]["rmse"].shape == (2,)
    fig = book_beyond.noise_study_figure(r)
    assert len(fig.axes[0].get_lines()) == 3  # two filters and the 0.68 line
    plt.close(fig)


def test_rho_label():
    assert book_beyond.rho_label(1 / 200) == "1/200"
    assert book_beyond.rho_label(0.001) == "1/1000"
    with pytest.raises(ValueError):
        book_beyond.rho_label(0.0)


PM = re.compile(r"^-?\d+\.\d{3} ± \d+\.\d{3}$")


def test_moments_texts_cover_every_filter_and_scenario():
    result = reproduce.reproduce()
    texts = book_beyond.moments_texts(result)
    n = len(SCENARIOS) * len(reproduce.FILTERS) * 2 + len(SCENARIOS) * 2
    assert len(texts) == n
    assert all(PM.match(v) for k, v in texts.items() if not k.endswith("_se"))
    m = optimal.marginals(FIG2.mu, FIG2.rho, FIG2.prior)
    assert texts["bf_fig2_optimal_depth"] == f"{m.depth_mean:.3f} ± {m.depth_sd:.3f}"
    ekf_y = ekf.ekf(FIG2.mu, FIG2.rho, FIG2.prior).posterior.marginal("y")
    assert texts["bf_fig2_ekf_depth"] == f"{ekf_y[0]:.3f} ± {ekf_y[1]:.3f}"


def test_moments_texts_reject_ambiguous_rows():
    result = reproduce.reproduce(["fig2"])
    rows = result["scenarios"][0]["rows"]
    rows.append(dict(rows[-1]))  # a second particle row
    with pytest.raises(ValueError, match="expected one row of 'particle'"):
        book_beyond.moments_texts(result)


def test_study_texts_have_every_score():
    r = study.study(trials=20, seed=0, names=("optimal", "ekf"))
    texts = book_beyond.study_texts(r, "s")
    assert texts["s_trials"] == str(r["valid_trials"])
    assert texts["s_ekf_depth_coverage_68"] == f"{r['filters']['ekf']['depth']['coverage_68']:.2f}"
    assert texts["s_ekf_nees"] == f"{r['filters']['ekf']['nees']:.1f}"
    assert len(texts) == 1 + 2 * (2 * len(book_beyond.STUDY_DECIMALS) + 2)


def test_sweep_texts_label_the_rows():
    r = sweeps.noise_sweep([1 / 1000, 1 / 200])
    texts = book_beyond.sweep_texts(r, "rho", "ns")
    assert texts["ns_0_x"] == "1/1000" and texts["ns_1_x"] == "1/200"
    assert texts["ns_1_optimal"] == (f"{r['optimal']['depth_mean'][1]:.3f} ± "
                                     f"{r['optimal']['depth_sd'][1]:.3f}")
    assert texts["ns_0_ekf_h"] == f"{r['ekf']['hellinger'][0]:.3f}"
    off = book_beyond.sweep_texts(sweeps.prior_offset_sweep([-1.0, 2.0]), "offset", "po")
    assert off["po_0_x"] == "-1" and off["po_1_x"] == "2"
    with pytest.raises(ValueError, match="x must be"):
        book_beyond.sweep_texts(r, "noise", "ns")


def test_profile_misfit_vanishes_at_the_noise_free_depth():
    c = FIG2.c
    assert book_beyond.profile_misfit(FIG2.mu, [c[1]])[0] == pytest.approx(0.0, abs=1e-25)


def test_profile_misfit_is_the_least_misfit_at_that_depth():
    # Independent route: least squares by numpy's lstsq, then the misfit of the
    # states moved by model.G and projected; rounding only (1e-12 relative).
    from depthcore import model

    mu = np.asarray(FIG2.mu)
    for y3 in (2.5, 6.0, 40.0):
        back = np.array([2.0, 1.0, 0.0])
        A = np.stack([1.0 / (y3 - back), -back / (y3 - back)], axis=-1)
        (x3, v), *_ = np.linalg.lstsq(A, mu, rcond=None)
        f = sum((mu[i] - model.project(model.G([x3, y3, v], i - 2))) ** 2 for i in range(3))
        got = book_beyond.profile_misfit(mu, [y3])[0]
        assert got == pytest.approx(f, rel=1e-12, abs=1e-30)
        for dx, dv in ((1e-3, 0.0), (0.0, 1e-3)):  # any other state at this depth fits worse
            g = sum((mu[i] - model.project(model.G([x3 + dx, y3, v + dv], i - 2))) ** 2
                    for i in range(3))
            assert g > got


def test_profile_misfit_tends_to_the_far_limit():
    mu = FIG2.mu
    far = book_beyond.far_misfit(mu)
    assert far == pytest.approx(0.1**2 / 6, rel=1e-12)  # mu1 - 2 mu2 + mu3 = -0.1
    # the misfit approaches its limit like 1 / y: within 1e-4 relative at y = 1e6
    assert book_beyond.profile_misfit(mu, [1e6])[0] == pytest.approx(far, rel=1e-4)
    with pytest.raises(ValueError, match="depths > 2"):
        book_beyond.profile_misfit(mu, [2.0])


def test_profile_figure_draws_each_noise_level():
    fig = book_beyond.profile_figure(FIG2.mu, [1 / 200, 1 / 50], np.geomspace(2.5, 100, 50))
    assert [line.get_label() for line in fig.axes[0].get_lines()] == ["rho = 1/200", "rho = 1/50"]
    plt.close(fig)


def test_noise_study_texts():
    r = book_beyond.noise_study([1 / 200], trials=20, seed=0, names=("second_order",))
    texts = book_beyond.noise_study_texts(r, "mc")
    assert texts["mc_0_x"] == "1/200"
    assert texts["mc_0_trials"] == str(r["valid_trials"][0])
    assert texts["mc_0_second_order_cov68"] == f"{r['second_order']['coverage_68'][0]:.2f}"
    assert set(texts) == {"mc_0_x", "mc_0_trials"} | {
        f"mc_0_second_order_{s}" for s in ("cov68", "cov95", "rmse", "nees")}
