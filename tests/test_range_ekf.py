"""The range-parametrised EKF (Peach 1995): its pieces against independent routes, its limit."""

import numpy as np
import pytest
from scipy import stats

from depthcore.exact import posterior
from depthcore.kalman import ekf, range_ekf
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS

FIG2 = SCENARIOS["fig2"]
MU = np.array(FIG2.mu)
PRIOR = FIG2.prior


def ten_frames():
    """Figure 2's point continued to 10 frames, one noisy track."""
    x1 = model.G(np.array(FIG2.c), -2)
    sim = model.simulate(x1, 10, FIG2.rho, 0.0, np.random.default_rng(4), size=1, frame=1)
    return sim.mu[0]


def test_one_component_is_the_ekf_started_at_its_prior():
    for q in (0.0, 0.01):
        start = range_ekf.components(PRIOR.mean, PRIOR.cov, 1, (2.0, 9.0))
        g = range_ekf.posterior(
            MU, FIG2.rho, PRIOR.mean, PRIOR.cov, q, n_components=1, depth_range=(2.0, 9.0)
        )
        h = ekf.run(MU, FIG2.rho, start.mean[0], start.cov[0], q)
        np.testing.assert_allclose(g.mean, h.means[-1], rtol=1e-13)
        np.testing.assert_allclose(g.cov, h.covs[-1], rtol=1e-12, atol=1e-15)
        assert g.weight.tolist() == [1.0]


def test_components_are_the_prior_on_each_interval():
    """Mean 3.5 depth at the centre, SD of the uniform, the prior's regression on the depth."""
    lo, hi = 1.0, 16.0
    start = range_ekf.components(PRIOR.mean, PRIOR.cov, 4, (lo, hi))
    np.testing.assert_allclose(start.edges, [1.0, 2.0, 4.0, 8.0, 16.0])
    np.testing.assert_allclose(start.mean[:, 1], [1.5, 3.0, 6.0, 12.0])
    np.testing.assert_allclose(start.cov[:, 1, 1], np.array([1, 2, 4, 8]) ** 2 / 12.0)
    # prior weights: the normal probability of each interval
    sd = np.sqrt(PRIOR.cov[1, 1])
    cdf = stats.norm.cdf(start.edges, PRIOR.mean[1], sd)
    np.testing.assert_allclose(np.exp(start.log_weight), np.diff(cdf), rtol=1e-12)
    # a correlated prior: the lateral state regresses on the depth
    P = np.array([[4.0, 1.0, 0.5], [1.0, 2.0, -0.4], [0.5, -0.4, 1.0]])
    m = np.array([0.3, 5.0, -0.1])
    c = range_ekf.components(m, P, 3, (1.0, 27.0))
    centre = 0.5 * (c.edges[1:] + c.edges[:-1])
    for i, y in enumerate(centre):
        # conditioning the prior on y exactly, then adding the interval's depth spread
        cond_mean = m + P[:, 1] / P[1, 1] * (y - m[1])
        np.testing.assert_allclose(c.mean[i], cond_mean, rtol=1e-14)
        s2 = (c.edges[i + 1] - c.edges[i]) ** 2 / 12.0
        g = P[:, 1] / P[1, 1]
        expected = P - np.outer(P[:, 1], P[1, :]) / P[1, 1] + s2 * np.outer(g, g)
        np.testing.assert_allclose(c.cov[i], expected, rtol=1e-13, atol=1e-15)


def test_interval_probabilities_in_the_far_tail():
    """Far in either tail the log probabilities stay finite and match scipy's survival function."""
    start = range_ekf.components([0.0, 0.0, 0.0], np.eye(3), 5, (20.0, 30.0))
    sf = stats.norm.logsf(start.edges)
    expected = sf[:-1] + np.log1p(-np.exp(sf[1:] - sf[:-1]))
    np.testing.assert_allclose(start.log_weight, expected, rtol=1e-12)
    low = range_ekf.components([0.0, 60.0, 0.0], np.eye(3), 3, (1.0, 8.0))
    lc = stats.norm.logcdf(low.edges - 60.0)
    expected = lc[1:] + np.log1p(-np.exp(lc[:-1] - lc[1:]))
    np.testing.assert_allclose(low.log_weight, expected, rtol=1e-12)


def test_many_components_start_at_the_truncated_prior():
    """As the intervals shrink the starting sum's depth moments are the truncated normal's."""
    lo, hi = 0.5, 80.0
    start = range_ekf.components(PRIOR.mean, PRIOR.cov, 2000, (lo, hi))
    w = np.exp(start.log_weight - np.max(start.log_weight))
    mean, cov = range_ekf.mixture_moments(w / w.sum(), start.mean, start.cov)
    sd = np.sqrt(PRIOR.cov[1, 1])
    a, b = (lo - PRIOR.mean[1]) / sd, (hi - PRIOR.mean[1]) / sd
    t = stats.truncnorm(a, b, loc=PRIOR.mean[1], scale=sd)
    np.testing.assert_allclose(mean[1], t.mean(), rtol=1e-5)
    np.testing.assert_allclose(np.sqrt(cov[1, 1]), t.std(), rtol=1e-5)


def test_weights_and_moments_against_a_loop_of_single_ekfs():
    """Each component by the Joseph-form EKF and scipy's normal density; the sum reduced by
    second moments about the origin."""
    mu = ten_frames()
    n, rng, q = 24, (1.0, 60.0), 0.01
    g = range_ekf.posterior(mu, FIG2.rho, PRIOR.mean, PRIOR.cov, q, n, rng)
    start = range_ekf.components(PRIOR.mean, PRIOR.cov, n, rng)
    log_w, means, covs = [], [], []
    for i in range(n):
        m, P = start.mean[i], start.cov[i]
        lw = start.log_weight[i]
        for k, mu_k in enumerate(mu):
            if k:
                m, P = ekf.predict(m, P, q)
            h = model.observation_vector(m)
            lw += stats.norm.logpdf(mu_k, m[0] / m[1], np.sqrt(FIG2.rho**2 + h @ P @ h))
            m, P = ekf.update(m, P, mu_k, FIG2.rho)
        log_w.append(lw)
        means.append(m)
        covs.append(P)
    w = np.exp(np.array(log_w) - max(log_w))
    w /= w.sum()
    np.testing.assert_allclose(g.weight, w, rtol=1e-7, atol=1e-300)
    means, covs = np.array(means), np.array(covs)
    mean = w @ means
    second = np.einsum("i,ijk->jk", w, covs + means[:, :, None] * means[:, None, :])
    np.testing.assert_allclose(g.mean, mean, rtol=1e-8)
    np.testing.assert_allclose(g.cov, second - np.outer(mean, mean), rtol=1e-6, atol=1e-10)


def test_batch_equals_one_at_a_time():
    mu = np.stack([MU, MU + [0.01, -0.005, 0.0], MU * 1.1])
    rho = np.array([FIG2.rho, 0.01, FIG2.rho])
    g = range_ekf.posterior(mu, rho, PRIOR.mean, PRIOR.cov, n_components=16)
    for b in range(3):
        one = range_ekf.posterior(mu[b], rho[b], PRIOR.mean, PRIOR.cov, n_components=16)
        np.testing.assert_allclose(g.mean[b], one.mean, rtol=1e-12)
        np.testing.assert_allclose(g.cov[b], one.cov, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize(
    ("mu", "n", "rtol"),
    [(MU, 4096, 1e-3), (ten_frames(), 1024, 1e-3), (ten_frames(), 256, 1e-2)],
    ids=["fig2", "ten_frames_1e-3", "ten_frames_1e-2"],
)
def test_converges_to_the_exact_bank(mu, n, rtol):
    """The bank of Kalman filters is the limit of many narrow components."""
    exact = posterior.posterior(mu, FIG2.rho, PRIOR.mean, PRIOR.cov)
    g = range_ekf.posterior(mu, FIG2.rho, PRIOR.mean, PRIOR.cov, n_components=n)
    assert abs(g.mean[1] / exact.depth_mean - 1) < rtol
    assert abs(np.sqrt(g.cov[1, 1]) / exact.depth_sd - 1) < rtol


def test_few_components_miss_figure_2():
    """The EKFs' linearisation over broad intervals: 64 components are far off on Figure 2."""
    exact = posterior.posterior(MU, FIG2.rho, PRIOR.mean, PRIOR.cov)
    g = range_ekf.posterior(MU, FIG2.rho, PRIOR.mean, PRIOR.cov, n_components=64)
    assert abs(g.mean[1] / exact.depth_mean - 1) > 1.0


def test_the_default_matches_figure_2_to_1e_2():
    exact = posterior.posterior(MU, FIG2.rho, PRIOR.mean, PRIOR.cov)
    g = range_ekf.posterior(MU, FIG2.rho, PRIOR.mean, PRIOR.cov)
    assert g.weight.shape == (range_ekf.N_COMPONENTS,)
    assert abs(g.mean[1] / exact.depth_mean - 1) < 1e-2
    assert abs(np.sqrt(g.cov[1, 1]) / exact.depth_sd - 1) < 1e-2


def test_registry_entry():
    f = FILTERS["range_parametrised"]
    assert f.family == "gaussian" and f.any_frames and f.with_process_noise and not f.default
    est = f(MU, FIG2.rho, PRIOR.mean, PRIOR.cov, n_components=32)
    g = range_ekf.posterior(MU, FIG2.rho, PRIOR.mean, PRIOR.cov, n_components=32)
    assert est.depth_mean == g.mean[1]
    assert est.depth_sd == np.sqrt(g.cov[1, 1])
    assert est.detail.weight.shape == (32,)
    batch = f(np.stack([MU, MU]), FIG2.rho, PRIOR.mean, PRIOR.cov, 0.01)
    assert batch.depth_mean.shape == (2,)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"n_components": 0}, "n_components must be an integer >= 1"),
        ({"n_components": 2.5}, "n_components must be an integer >= 1"),
        ({"n_components": range_ekf.MAX_COMPONENTS + 1}, "n_components must be at most"),
        ({"depth_range": (3.0, 1.0)}, "depth_range must be"),
        ({"depth_range": (0.0, 1.0)}, "depth_range must be"),
        ({"depth_range": (1.0,)}, "depth_range"),
        ({"depth_range": (1.0, np.inf)}, "depth_range"),
    ],
)
def test_refusals_name_the_argument(options, match):
    with pytest.raises(ValueError, match=match):
        FILTERS["range_parametrised"](MU, FIG2.rho, PRIOR.mean, PRIOR.cov, **options)


def test_prior_far_behind_the_camera_is_refused():
    with pytest.raises(ValueError, match="prior_mean"):
        range_ekf.posterior(MU, FIG2.rho, [0.0, -100.0, 0.0], np.eye(3))
