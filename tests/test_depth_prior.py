"""The exact filter under a prior whose depth law is any proper density (issue: any prior).

The reference is a dense grid written apart from the package: Gauss-Legendre panels
in log depth, many more than the placement uses, cut at the prior's edges and
kinks, and at each depth one joint Gaussian conditioning of the whole track
(initial state and every acceleration at once), not the Kalman recursion.
"""

import math

import numpy as np
import pytest
from scipy import integrate, stats

import depthcore
from depthcore.exact import learning, online, optimal, posterior
from depthcore.problem import depth_prior as dp
from depthcore.problem.gaussian import Gaussian

LATERAL = dp.Lateral.on_ray(0.2, 0.01, 0.3, 1.0)

LAWS = {
    "log_uniform": dp.log_uniform(20 / math.sqrt(10), 20 * math.sqrt(10), LATERAL),
    "range": dp.range_prior(20.0, 6.0, LATERAL, lo=2.0),
    "inverse_depth": dp.inverse_depth(0.05, 0.025, 0.005, 0.5, LATERAL),
    "table": dp.table([5.0, 10.0, 20.0, 40.0, 60.0], [0.0, 1.0, 2.0, 0.5, 0.0], LATERAL),
}


def grid_moments(law, mu, rho, steps, q, panels=2000, order=10, cdf_at=()):
    """Posterior mean and SD of ``y_N``, ``v_N`` and ``x_1`` (given every bearing), and the
    log marginal likelihood of the bearings, (7,)."""
    N = len(mu)
    steps = np.ones(N - 1) if steps is None else np.asarray(steps, float)
    rho = np.broadcast_to(np.asarray(rho, float), (N,))
    elapsed = np.r_[0.0, np.cumsum(steps)]
    lo, hi = law.support
    ey, ey2 = law.depth_moments()
    lo = max(lo, 1e-6, -elapsed.min() + 1e-9)
    hi = hi if np.isfinite(hi) else ey + 40 * math.sqrt(ey2 - ey * ey)
    at = [y - elapsed[-1] for y in cdf_at]  # depths at frame 1 where a CDF is read: cuts
    cuts = np.log(np.clip(np.r_[law.breakpoints, lo, hi, at], lo, hi))
    cuts = np.unique(cuts)
    edges = np.unique(
        np.concatenate(
            [
                np.linspace(a, b, panels // len(cuts) + 2)
                for a, b in zip(cuts[:-1], cuts[1:], strict=True)
            ]
        )
    )
    x, w = np.polynomial.legendre.leggauss(order)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    t = (mid[:, None] + half[:, None] * x).ravel()
    wt = (half[:, None] * w).ravel()
    y = np.exp(t)
    # the track as a linear map of z = (x_1, v_1, a_1 .. a_{N-1})
    G = np.zeros((N, N + 1))  # x_k
    V = np.zeros(N + 1)  # v_N
    G[:, 0] = 1.0
    G[:, 1] = elapsed
    for i in range(N - 1):  # a_i acts on v from frame i + 2 on
        G[i + 2 :, 2 + i] = elapsed[i + 2 :] - elapsed[i + 1]
    V[1] = 1.0
    V[2:] = 1.0
    present = ~np.isnan(mu)
    lat = law.lateral.at(y)
    n = len(y)
    m = np.zeros((n, N + 1))
    S = np.zeros((n, N + 1, N + 1))
    m[:, :2], S[:, :2, :2] = lat.mean, lat.cov
    S[:, 2:, 2:] = np.diag(q * q * np.abs(steps))
    H = (G[None] / (y[:, None] + elapsed)[:, :, None])[:, present]  # (n, M, N + 1)
    Sm = H @ S @ np.swapaxes(H, 1, 2) + np.diag(rho[present] ** 2)
    r = mu[present] - np.einsum("nmk,nk->nm", H, m)
    inv = np.linalg.inv(Sm)
    logl = -0.5 * np.einsum("nm,nmk,nk->n", r, inv, r) - 0.5 * np.linalg.slogdet(2 * np.pi * Sm)[1]
    K = S @ np.swapaxes(H, 1, 2) @ inv
    mz = m + np.einsum("nkm,nm->nk", K, r)
    Sz = S - K @ H @ S
    out = np.stack([logl, mz @ V, np.einsum("k,nkl,l->n", V, Sz, V), mz[:, 0], Sz[:, 0, 0]], 1)
    logp = law.log_pdf(y) + out[:, 0] + np.log(wt) + t
    p = np.exp(logp - logp.max())
    p /= p.sum()
    yN = y + elapsed[-1]
    my = p @ yN
    sy = math.sqrt(p @ (yN - my) ** 2)
    mv = p @ out[:, 1]
    sv = math.sqrt(p @ (out[:, 2] + (out[:, 1] - mv) ** 2))
    mx = p @ out[:, 3]
    log_z = logp.max() + math.log(np.sum(np.exp(logp - logp.max())))
    sx = math.sqrt(p @ (out[:, 4] + (out[:, 3] - mx) ** 2))
    cdfs = [float(np.sum(p[yN < y])) for y in cdf_at]
    return np.array([my, sy, mv, sv, mx, sx, log_z, *cdfs])


def _track(law, N, steps, rho, q, seed):
    rng = np.random.default_rng(seed)
    x1, y1, v = law.draw(1, rng)[0]
    steps = np.ones(N - 1) if steps is None else np.asarray(steps, float)
    e = np.r_[0.0, np.cumsum(steps)]
    vs = v + np.r_[0.0, np.cumsum(q * np.sqrt(np.abs(steps)) * rng.standard_normal(N - 1))]
    xs = x1 + np.r_[0.0, np.cumsum(steps * vs[:-1])]
    return xs / (y1 + e) + rho * rng.standard_normal(N)


CASES = {
    "three frames": (3, None, 0.01, 0.0, []),
    "ten frames, a gap, uneven steps, process noise": (
        10,
        [1.0, 0.5, 2.0, 1.0, 1.0, 0.7, 1.3, 1.0, 1.0],
        0.01,
        0.05,
        [4],
    ),
}


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("form", LAWS)
def test_the_exact_filter_under_each_depth_law_agrees_with_a_dense_grid(form, case):
    law = LAWS[form]
    N, steps, rho, q, gaps = CASES[case]
    mu = _track(law, N, steps, rho, q, seed=len(form) + N)
    mu[gaps] = np.nan
    post = posterior.posterior(mu, rho, None, None, q, steps=steps, law=law)
    ref = grid_moments(law, mu, rho, steps, q)
    got = [post.depth_mean, post.depth_sd, post.velocity_mean, post.velocity_sd]
    assert abs(got[0] - ref[0]) <= 1e-8 * ref[1]
    assert abs(got[1] - ref[1]) <= 1e-8 * ref[1]
    assert abs(got[2] - ref[2]) <= 1e-8 * ref[3]
    assert abs(got[3] - ref[3]) <= 1e-8 * ref[3]
    assert post.depth_error <= 1e-10 * ref[1]


def test_the_grid_sees_a_wrong_law():
    """Negative control: the same track under another law moves the depth by many 1e-8 SDs."""
    mu = _track(LAWS["log_uniform"], 10, None, 0.01, 0.0, seed=3)
    right = grid_moments(LAWS["log_uniform"], mu, 0.01, None, 0.0)
    wrong = posterior.posterior(mu, 0.01, None, None, law=LAWS["range"])
    assert abs(wrong.depth_mean - right[0]) > 1e-3 * right[1]


def test_a_gaussian_law_is_the_gaussian_prior():
    """A range law untruncated above 0 with the joint Gaussian's lateral law is that Gaussian."""
    mean = np.array([4.0, 20.0, 0.3])
    cov = np.array([[4.0, 1.0, 0.1], [1.0, 36.0, 0.0], [0.1, 0.0, 1.0]])
    law = dp.range_prior(20.0, 6.0, dp.Lateral.given_depth(mean, cov))
    mu = _track(law, 8, None, 0.01, 0.0, seed=5)
    a = posterior.posterior(mu, 0.01, None, None, law=law)
    b = posterior.posterior(mu, 0.01, mean, cov)
    assert abs(a.depth_mean - b.depth_mean) <= 1e-8 * b.depth_sd
    assert abs(a.depth_sd - b.depth_sd) <= 1e-8 * b.depth_sd
    assert abs(a.velocity_mean - b.velocity_mean) <= 1e-8 * b.velocity_sd


@pytest.mark.parametrize("form", LAWS)
def test_each_law_is_a_density_with_the_moments_it_states(form):
    law = LAWS[form]
    lo, hi = law.support
    pts = list(law.breakpoints)
    f = lambda k: lambda y: y**k * math.exp(law.log_pdf(y))  # noqa: E731
    hi_q = hi if np.isfinite(hi) else 200.0
    mass, ey, ey2 = (
        integrate.quad(f(k), lo, hi_q, points=pts or None, epsabs=0, epsrel=1e-12, limit=200)[0]
        for k in (0, 1, 2)
    )
    assert mass == pytest.approx(1.0, rel=1e-9)
    assert law.depth_moments() == pytest.approx((ey, ey2), rel=1e-9)
    # the Gaussian filters' stand-in: the draws' mean and covariance
    draws = law.draw(200_000, np.random.default_rng(7))
    mean, cov = law.gaussian()
    se = np.sqrt(np.diag(cov) / len(draws))
    assert np.all(np.abs(draws.mean(0) - mean) <= 5 * se)
    assert np.allclose(np.cov(draws.T), cov, rtol=0.03, atol=1e-3 * np.max(cov))
    # the depths drawn follow the law: a chi-square test over 20 bins of equal mass by quadrature
    assert _chi_square_pvalue(law.draw_depths(4000, np.random.default_rng(8)), law) > 1e-3


def _chi_square_pvalue(sample, law):
    lo, hi = law.support
    hi = hi if np.isfinite(hi) else 200.0
    edges = np.linspace(lo, hi, 21)
    f = lambda y: math.exp(law.log_pdf(y))  # noqa: E731
    pts = list(law.breakpoints)
    prob = np.array(
        [
            integrate.quad(f, a, b, points=[p for p in pts if a < p < b] or None)[0]
            for a, b in zip(edges[:-1], edges[1:], strict=True)
        ]
    )
    seen = np.histogram(sample, edges)[0]
    keep = prob * len(sample) >= 5
    expected = prob[keep] / prob[keep].sum() * seen[keep].sum()
    return stats.chisquare(seen[keep], expected).pvalue


def test_the_draws_fail_the_test_of_another_law():
    sample = LAWS["log_uniform"].draw_depths(4000, np.random.default_rng(8))
    assert _chi_square_pvalue(sample, LAWS["range"]) < 1e-6


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: dp.log_uniform(5.0, 2.0, LATERAL), "hi must exceed lo"),
        (lambda: dp.log_uniform(-1.0, 2.0, LATERAL), "lo"),
        (lambda: dp.inverse_depth(0.05, 0.02, 0.0, 0.5, LATERAL), "lo"),
        (lambda: dp.range_prior(0.0, 1e-300, LATERAL, lo=1.0, hi=2.0), "no mass"),
        (lambda: dp.table([1.0, 1.0], [1.0, 1.0], LATERAL), "increasing"),
        (lambda: dp.table([1.0, 2.0, 3.0], [1.0, 0.0, 1.0], LATERAL), "positive between"),
        (lambda: dp.table([1.0, 2.0], [1.0, 1.0], "ray"), "lateral must be a Lateral"),
        (
            lambda: dp.Lateral([0, 0], [1, 0], np.zeros((2, 2)), np.zeros((2, 2))),
            "positive definite",
        ),
        (
            lambda: posterior.posterior([0.1, 0.2, 0.3], 0.01, [0, 20, 0], None, law=LAWS["range"]),
            "prior_mean must be None",
        ),
    ],
)
def test_a_meaningless_prior_is_refused_in_one_line(build, message):
    with pytest.raises(ValueError, match=message) as err:
        build()
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("form", ["log_uniform", "table"])
def test_the_smoother_under_a_law_agrees_with_the_grid_at_frame_1(form):
    law = LAWS[form]
    N, steps, rho, q, gaps = CASES["ten frames, a gap, uneven steps, process noise"]
    mu = _track(law, N, steps, rho, q, seed=11)
    mu[gaps] = np.nan
    ref = grid_moments(law, mu, rho, steps, q)
    s = posterior.posterior(mu, rho, None, None, q, steps=steps, history=True, law=law).smoothed()
    assert abs(s.mean[0, 0] - ref[4]) <= 1e-8 * ref[5]
    assert abs(math.sqrt(s.cov[0, 0, 0]) - ref[5]) <= 1e-8 * ref[5]


def test_track_gives_the_exact_filter_the_law_and_the_gaussian_filters_its_gaussian():
    law = LAWS["log_uniform"]
    mu = _track(law, 8, None, 0.01, 0.0, seed=12)
    exact = depthcore.track(mu, 0.01, prior=law)
    post = posterior.posterior(mu, 0.01, None, None, law=law)
    assert abs(exact.filtered.depth_mean[-1] - post.depth_mean) <= 1e-8 * post.depth_sd
    stand_in = Gaussian(*law.gaussian())
    under_gaussian = depthcore.track(mu, 0.01, prior=stand_in)
    # the law is not its Gaussian: the exact filter's answer moves by many tolerances
    assert abs(under_gaussian.filtered.depth_mean[-1] - post.depth_mean) > 1e-3 * post.depth_sd
    ekf = depthcore.track(mu, 0.01, prior=law, filter="ekf")
    assert np.array_equal(
        ekf.filtered.depth_mean,
        depthcore.track(mu, 0.01, prior=stand_in, filter="ekf").filtered.depth_mean,
    )


@pytest.mark.parametrize("form", ["log_uniform", "inverse_depth", "table"])
def test_the_online_filter_under_a_law_is_the_batch_posterior_at_every_frame(form):
    """Placed afresh every frame from its interpolated nodes, it keeps the batch's answer."""
    law = LAWS[form]
    mu = _track(law, 30, None, 0.01, 0.0, seed=21)
    mu[7] = np.nan
    f = online.Online(None, None, 0.01, law=law)
    for k in range(30):
        est = f.update(mu[k])
        if k in (0, 2, 9, 29):
            p = posterior.posterior(mu[: k + 1], 0.01, None, None, law=law)
            for got, want, sd in (
                (est.depth_mean, p.depth_mean, p.depth_sd),
                (est.depth_sd, p.depth_sd, p.depth_sd),
                (est.velocity_mean, p.velocity_mean, p.velocity_sd),
            ):
                assert abs(got - want) <= 1e-8 * sd, (k, got, want)


def test_an_approaching_camera_under_a_law_online_and_in_batch():
    law = LAWS["range"]
    steps = np.r_[np.ones(4), -np.ones(5)]
    mu = _track(law, 10, steps, 0.01, 0.0, seed=22)
    f = online.Online(None, None, 0.01, law=law)
    for k in range(10):
        est = f.update(mu[k], step=1.0 if k == 0 else steps[k - 1])
    p = posterior.posterior(mu, 0.01, None, None, steps=steps, law=law)
    assert abs(est.depth_mean - p.depth_mean) <= 1e-8 * p.depth_sd
    assert abs(est.depth_sd - p.depth_sd) <= 1e-8 * p.depth_sd


def test_the_gate_under_a_law_skips_the_outlier_and_keeps_the_rest():
    law = LAWS["log_uniform"]
    mu = _track(law, 25, None, 0.01, 0.0, seed=23)
    bad = mu.copy()
    bad[20] += 0.3
    gated = optimal.run(bad, 0.01, None, None, gate=1e-3, law=law)
    assert np.flatnonzero(gated.updates.gated).tolist() == [20]
    without = mu.copy()
    without[20] = np.nan
    ref = posterior.posterior(without, 0.01, None, None, law=law)
    assert abs(gated.depth_mean - ref.depth_mean) <= 1e-8 * ref.depth_sd
    # through track(), the smoother skips it too
    t = depthcore.track(bad, 0.01, prior=law, gate=1e-3)
    assert t.updates.gated[20] and not np.any(np.delete(t.updates.gated, 20))


@pytest.mark.parametrize("form", ["log_uniform", "table"])
def test_the_likelihood_of_the_noise_under_a_law_is_the_grids(form):
    law = LAWS[form]
    N, steps, rho, q, gaps = CASES["ten frames, a gap, uneven steps, process noise"]
    mu = _track(law, N, steps, rho, q, seed=31)
    mu[gaps] = np.nan
    got = learning.log_likelihood(mu, None, None, rho, q, steps=steps, law=law)
    assert abs(got - grid_moments(law, mu, rho, steps, q)[6]) <= 1e-8


def test_learning_rho_under_a_law_finds_the_maximum_of_its_likelihood():
    law = LAWS["log_uniform"]
    mu = np.stack([_track(law, 10, None, 0.01, 0.0, seed=40 + i) for i in range(6)])
    fit = learning.fit(mu, None, None, process_noise=0.0, law=law)
    at = {
        r: learning.log_likelihood(mu, None, None, r, law=law)
        for r in fit.rho * np.r_[0.98, 1, 1.02]
    }
    assert at[fit.rho] > max(v for r, v in at.items() if r != fit.rho)
    assert fit.rho_interval[0] < fit.rho < fit.rho_interval[1]
    stand_in = learning.fit(mu, *law.gaussian(), process_noise=0.0)
    assert abs(stand_in.rho - fit.rho) > 1e-6 * fit.rho  # the law is not its Gaussian


@pytest.mark.parametrize("form", LAWS)
def test_the_depth_cdf_under_a_law_is_the_grids_up_to_its_edges(form):
    law = LAWS[form]
    mu = _track(law, 6, None, 0.01, 0.0, seed=51)
    post = posterior.posterior(mu, 0.01, None, None, law=law)
    at = post.depth_mean + post.depth_sd * np.array([-1.5, 0.0, 1.0])
    lo, hi = law.support
    at = np.clip(at, lo + 5.0 + 1e-6, (hi if np.isfinite(hi) else 1e9) + 5.0 - 1e-6)
    ref = grid_moments(law, mu, 0.01, None, 0.0, cdf_at=at)[7:]
    assert np.all(np.abs(post.depth_cdf(at) - ref) <= 1e-8)


def test_a_batch_larger_than_one_placement_chunk_keeps_its_law():
    """Past posterior's chunk of problems the joined bank still carries the law."""
    law = LAWS["log_uniform"]
    mu = np.stack([_track(law, 5, None, 0.01, 0.0, seed=60 + i) for i in range(70)])
    batch = posterior.posterior(mu, 0.01, None, None, law=law)
    assert batch.bank.law is law
    for i in (0, 69):
        one = posterior.posterior(mu[i], 0.01, None, None, law=law)
        y = one.depth_mean + one.depth_sd
        assert abs(batch.depth_cdf(np.full((70, 1), y))[i, 0] - one.depth_cdf(y)) <= 1e-9
