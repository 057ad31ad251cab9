"""The noise levels learned from tracks (textbook 19.1.2): depthcore.exact.learning.

The log-likelihood against independent routes (a dense depth grid with a
Kalman filter written here; brute 3-D quadrature at N = 3), maximum
likelihood against EM with the smoother as its E-step, the standard errors
against the likelihood's curvature, the boundary q = 0, the refusals, and the
coverage of the 95 % intervals of rho and of q over 220 simulated data sets each.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp

from depthcore.exact import learning
from depthcore.problem import model

PRIOR_MEAN = np.array([0.0, 5.0, 0.0])
PRIOR_COV = np.diag([1.0, 1.0, 0.25])


def _tracks(seed, tracks, frames, rho, q, mean=PRIOR_MEAN, cov=PRIOR_COV):
    """Tracks drawn from the model: states at frame 1 from the prior (in front), bearings."""
    rng = np.random.default_rng(seed)
    states = rng.multivariate_normal(mean, cov, size=tracks)
    states[:, 1] = np.abs(states[:, 1]) + 0.5
    return model.simulate(states, frames, rho, q, rng, frame=1).mu


def _grid_log_likelihood(mu, rho, q, mean, cov, steps=None, weights=None, points=40_001):
    """log p(mu | rho, q) of one track: a dense trapezoid over log depth of N(y) L(y) y.

    L(y) by a Kalman filter of (x, v) written out here: the prior conditioned on
    y_1 = y, predictions over a step s: x += s v, v += a (Var a = q**2 s), updates
    by the present mu_k (NaN: none) with Phi = (1 / y_k, 0) and noise
    (rho weights_k)**2, y_k = y + the steps so far.
    """
    steps = np.ones(len(mu) - 1) if steps is None else np.asarray(steps)
    weights = np.ones(len(mu)) if weights is None else np.asarray(weights)
    floor = max(0.0, -float(np.min(np.cumsum(steps))))  # where the point reaches the camera
    lo, hi = np.log(1e-3), np.log(mean[1] + 14.0 * np.sqrt(cov[1, 1]))
    t = np.linspace(lo, hi, points)
    y = floor + np.exp(t)
    u = [0, 2]
    slope = cov[u, 1] / cov[1, 1]
    m = mean[u][None, :] + (y - mean[1])[:, None] * slope[None, :]
    P = cov[np.ix_(u, u)] - np.outer(slope, cov[1, u])
    P = np.broadcast_to(P, (y.size, 2, 2)).copy()
    log_f = stats.norm.logpdf(y, mean[1], np.sqrt(cov[1, 1])) + t  # dy = (y - floor) dt
    yk = y.copy()
    for k, mu_k in enumerate(mu):
        if k:
            F = np.array([[1.0, steps[k - 1]], [0.0, 1.0]])
            m = m @ F.T
            P = F @ P @ F.T
            P[:, 1, 1] += q**2 * abs(steps[k - 1])
            yk = yk + steps[k - 1]
        if np.isnan(mu_k):
            continue
        h = np.stack([1.0 / yk, np.zeros_like(yk)], -1)  # (J, 2)
        S = np.einsum("ji,jik,jk->j", h, P, h) + (rho * weights[k]) ** 2
        e = mu_k - m[:, 0] / yk
        log_f += stats.norm.logpdf(e, 0.0, np.sqrt(S))
        K = np.einsum("jik,jk->ji", P, h) / S[:, None]
        m = m + K * e[:, None]
        P = P - K[:, :, None] * np.einsum("ji,jik->jk", h, P)[:, None, :]
    dt = t[1] - t[0]
    w = np.full(points, dt)
    w[[0, -1]] = dt / 2
    return float(logsumexp(log_f + np.log(w)))


def test_log_likelihood_equals_a_dense_depth_grid():
    """Textbook 19.1.2: log p(mu | rho, q), summed over tracks, to 1e-8."""
    rho, q = 0.02, 0.05
    mu = _tracks(1, 3, 7, rho, q)
    got = learning.log_likelihood(mu, PRIOR_MEAN, PRIOR_COV, rho, q)
    want = sum(_grid_log_likelihood(m, rho, q, PRIOR_MEAN, PRIOR_COV) for m in mu)
    assert got == pytest.approx(want, abs=1e-8)


def test_log_likelihood_with_gaps_steps_and_weights_equals_a_dense_depth_grid():
    """Missing bearings, uneven steps and relative noise per frame, to 1e-8."""
    rho, q = 0.02, 0.05
    mu = _tracks(11, 2, 7, rho, q)
    mu[0, 2] = mu[1, 4] = np.nan
    steps = np.array([1.0, 0.5, 2.0, 1.0, 1.5, 0.75])
    weights = np.array([1.0, 2.0, 1.0, 0.5, 1.0, 1.5, 1.0])
    got = learning.log_likelihood(mu, PRIOR_MEAN, PRIOR_COV, rho, q, steps, weights)
    want = sum(_grid_log_likelihood(m, rho, q, PRIOR_MEAN, PRIOR_COV, steps, weights) for m in mu)
    assert got == pytest.approx(want, abs=1e-8)


def test_learning_on_tracks_of_an_approaching_camera():
    """Negative steps: the log-likelihood equals the dense grid above the floor to 1e-8, and
    ML and EM agree on rho and q (the velocity noise grows with |s|)."""
    rng = np.random.default_rng(5)
    steps = np.full(11, -0.3)
    states = rng.multivariate_normal([0.0, 9.0, 0.0], np.diag([1.0, 1.0, 0.25]), size=4)
    mu = model.simulate(states, 12, 0.01, 0.05, rng, frame=1, steps=steps).mu
    mean, cov = np.array([0.0, 9.0, 0.0]), np.diag([1.0, 1.0, 0.25])
    got = learning.log_likelihood(mu, mean, cov, 0.01, 0.05, steps)
    want = sum(_grid_log_likelihood(m, 0.01, 0.05, mean, cov, steps) for m in mu)
    assert got == pytest.approx(want, abs=1e-8)
    ml = learning.fit(mu, mean, cov, steps=steps)
    em = learning.fit(mu, mean, cov, steps=steps, method="em", tol=1e-9)
    assert ml.converged and em.converged
    assert em.rho == pytest.approx(ml.rho, rel=1e-6)
    assert em.log_likelihood == pytest.approx(ml.log_likelihood, abs=1e-8)


def test_ml_and_em_agree_with_gaps_steps_and_weights():
    mu = _tracks(12, 4, 12, 0.01, 0.05)
    mu[0, 3] = mu[2, 7] = mu[3, 1] = np.nan
    steps = np.tile([1.0, 0.5, 2.0], 4)[:11]
    weights = np.tile([1.0, 2.0], 6)
    kw = {"steps": steps, "weights": weights, "process_noise": 0.05}
    ml = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, **kw)
    em = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, method="em", **kw)
    assert ml.converged and em.converged
    assert em.rho == pytest.approx(ml.rho, rel=1e-7)
    assert em.log_likelihood == pytest.approx(ml.log_likelihood, abs=1e-9)
    # relative weights: doubling every frame's weight halves the estimate of rho
    twice = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, **{**kw, "weights": 2 * weights})
    assert twice.rho == pytest.approx(ml.rho / 2, rel=1e-7)
    assert twice.log_likelihood == pytest.approx(ml.log_likelihood, abs=1e-8)


def test_log_likelihood_equals_brute_3d_quadrature_at_three_frames():
    """At N = 3, q = 0: the triple integral over (x_1, y_1, v_1) of the prior times Eq. (4)."""
    rho = 0.05
    cov = np.array([[0.3, 0.05, 0.02], [0.05, 0.5, 0.0], [0.02, 0.0, 0.1]])
    mu = _tracks(7, 1, 3, rho, 0.0, cov=cov)[0]
    got = learning.log_likelihood(mu, PRIOR_MEAN, cov, rho, 0.0)
    # the integrand is a smooth bump: the trapezoid rule on a box of +-9 prior SDs
    # about the prior mean (the posterior lies well inside it) converges geometrically
    sd = np.sqrt(np.diag(cov))
    x = np.linspace(-9 * sd[0], 9 * sd[0], 181)
    y = PRIOR_MEAN[1] + np.linspace(-9 * sd[1], 9 * sd[1], 91)
    v = np.linspace(-9 * sd[2], 9 * sd[2], 121)
    inverse, log_det = np.linalg.inv(cov), np.linalg.slogdet(cov)[1]
    X, V = np.meshgrid(x, v, indexing="ij")
    slabs = []
    for yy in y:
        d = np.stack(
            [X - PRIOR_MEAN[0], np.full_like(X, yy - PRIOR_MEAN[1]), V - PRIOR_MEAN[2]], -1
        )
        log_f = -0.5 * np.einsum("...i,ij,...j->...", d, inverse, d) - 0.5 * log_det
        log_f -= 1.5 * np.log(2 * np.pi)
        for k in range(3):  # Eq. (4) at frame k + 1: x + k v over y + k
            r = (mu[k] - (X + k * V) / (yy + k)) / rho
            log_f -= 0.5 * r * r + np.log(rho * np.sqrt(2 * np.pi))
        slabs.append(logsumexp(log_f))
    cell = (x[1] - x[0]) * (y[1] - y[0]) * (v[1] - v[0])
    # the box's edges carry e**-40 of the mass: the plain sum is the trapezoid rule
    want = float(logsumexp(slabs) + np.log(cell))
    assert got == pytest.approx(want, abs=1e-8)


def test_ml_and_em_agree_for_rho():
    """The EM fixed point (smoother E-step, closed-form M-step) is the ML estimate."""
    mu = _tracks(2, 5, 12, 0.01, 0.03)
    ml = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.03)
    em = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.03, method="em")
    assert ml.converged and em.converged
    assert em.rho == pytest.approx(ml.rho, rel=1e-7)
    assert em.log_likelihood == pytest.approx(ml.log_likelihood, abs=1e-9)
    assert em.rho_se == pytest.approx(ml.rho_se, rel=1e-5)
    assert ml.estimated == ("rho",) and em.iterations > ml.iterations


def test_ml_and_em_agree_for_rho_and_q():
    """Both noise levels: EM (slow where q is weakly determined) reaches the ML estimate."""
    mu = _tracks(8, 4, 20, 0.005, 0.1)
    ml = learning.fit(mu, PRIOR_MEAN, PRIOR_COV)
    em = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, method="em", tol=1e-9)
    assert ml.converged and em.converged and not ml.at_boundary
    assert em.rho == pytest.approx(ml.rho, rel=1e-6)
    assert em.process_noise == pytest.approx(ml.process_noise, rel=1e-6)
    assert em.log_likelihood == pytest.approx(ml.log_likelihood, abs=1e-9)


def test_standard_errors_are_the_curvature_of_the_log_likelihood():
    """Observed information: -d2 l / d(log rho)**2 by differences of log_likelihood itself."""
    mu = _tracks(4, 4, 10, 0.02, 0.0)
    f = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.0, intervals="wald")
    h = 1e-3

    def ell(r):
        return learning.log_likelihood(mu, PRIOR_MEAN, PRIOR_COV, r, 0.0)

    curv = -(ell(f.rho * np.exp(h)) - 2 * ell(f.rho) + ell(f.rho * np.exp(-h))) / h**2
    assert f.rho_se == pytest.approx(f.rho / np.sqrt(curv), rel=1e-4)
    # the estimate is the maximum: the slope there is zero to the differences' accuracy
    slope = (ell(f.rho * np.exp(h)) - ell(f.rho * np.exp(-h))) / (2 * h)
    assert abs(slope) < 1e-5 * curv
    assert f.log_likelihood == pytest.approx(ell(f.rho), abs=1e-12)
    z = stats.norm.ppf(0.975)
    lo, hi = f.rho_interval
    assert lo == pytest.approx(f.rho * np.exp(-z * f.rho_se / f.rho), rel=1e-12)
    assert hi == pytest.approx(f.rho * np.exp(z * f.rho_se / f.rho), rel=1e-12)


def test_profile_interval_ends_where_the_likelihood_falls_by_half_the_chi2_quantile():
    mu = _tracks(5, 3, 10, 0.02, 0.0)
    f = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.0, intervals="profile")
    drop = stats.chi2.ppf(0.95, 1) / 2
    for end in f.rho_interval:
        ell = learning.log_likelihood(mu, PRIOR_MEAN, PRIOR_COV, end, 0.0)
        assert ell == pytest.approx(f.log_likelihood - drop, abs=1e-6)
    lo, hi = f.rho_interval
    assert lo < f.rho < hi


def test_q_at_the_boundary_is_reported_with_a_one_sided_bound():
    """Data whose likelihood falls from q = 0: q = 0, no SE, (0, upper) at 0.95 one-sided."""
    rho = 0.02
    for seed in range(20):
        mu = _tracks(100 + seed, 3, 8, rho, 0.0)
        f = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, rho=rho)
        if f.at_boundary:
            break
    else:
        pytest.fail("no data set of 20 put q at the boundary")
    assert f.process_noise == 0.0 and f.process_noise_se is None
    assert f.estimated == ("process_noise",) and "boundary" in f.note
    lo, upper = f.process_noise_interval
    assert lo == 0.0 and upper > 0.0
    ell0 = learning.log_likelihood(mu, PRIOR_MEAN, PRIOR_COV, rho, 0.0)
    assert f.log_likelihood == pytest.approx(ell0, abs=1e-12)
    # the bound: where the likelihood has fallen by half chi2's 0.90 quantile (2.706 / 2)
    ell = learning.log_likelihood(mu, PRIOR_MEAN, PRIOR_COV, rho, upper)
    assert ell == pytest.approx(ell0 - stats.chi2.ppf(0.90, 1) / 2, abs=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rho": 0.01, "process_noise": 0.0}, "rho, process_noise: both are given"),
        ({"method": "newton"}, "method must be one of"),
        ({"intervals": "bootstrap"}, "intervals must be"),
        ({"level": 1.0}, "level must be in"),
        ({"rho": -1.0}, "rho must be positive"),
        ({"process_noise": -0.1}, "process_noise must be >= 0"),
    ],
)
def test_refusals_name_the_argument(kwargs, message):
    mu = _tracks(6, 2, 6, 0.01, 0.0)
    with pytest.raises(ValueError, match=message):
        learning.fit(mu, PRIOR_MEAN, PRIOR_COV, **kwargs)


def test_three_bearings_a_track_are_too_few_to_learn_the_noise():
    mu = _tracks(6, 4, 3, 0.01, 0.0)
    with pytest.raises(ValueError, match="process_noise: estimating it needs a track with at"):
        learning.fit(mu, PRIOR_MEAN, PRIOR_COV, rho=0.01)
    with pytest.raises(ValueError, match="rho: estimating it needs"):
        learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.0)


#: The coverage checks' data sets (SE of a 95 % coverage sqrt(0.95 * 0.05 / 220) = 0.0147),
#: tracks per data set and frames per track: short tracks, so that 220 fits take seconds.
COVERAGE_SETS, COVERAGE_TRACKS, COVERAGE_FRAMES = 220, 3, 8
#: The criterion, fixed before the coverages were seen: within 3 binomial SEs of 0.95.
COVERAGE_LEVEL, COVERAGE_Z = 0.95, 3.0


def _covers(share) -> bool:
    se = np.sqrt(COVERAGE_LEVEL * (1 - COVERAGE_LEVEL) / COVERAGE_SETS)
    return abs(share - COVERAGE_LEVEL) <= COVERAGE_Z * se


def _coverage(fits, truth, interval):
    """The share of the fits' 95 % intervals that hold the truth, as given and halved
    (each end moved halfway to the estimate): the halved one is the negative control."""
    whole = halved = 0
    for estimate, (lo, hi) in ((f[0], interval(f[1])) for f in fits):
        whole += lo <= truth <= hi
        halved += (estimate + lo) / 2 <= truth <= (estimate + hi) / 2
    return whole / len(fits), halved / len(fits)


def test_rho_intervals_cover_the_truth_at_their_level():
    """220 data sets drawn at rho = 0.02, q = 0 (q known): the 95 % intervals of rho cover
    the true rho within 3 binomial SEs (3 x 0.0147) of 0.95; halved, they do not."""
    rho, q = 0.02, 0.0
    fits = []
    for s in np.random.SeedSequence(2024).spawn(COVERAGE_SETS):
        mu = _tracks(s, COVERAGE_TRACKS, COVERAGE_FRAMES, rho, q)
        f = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=q, rtol=1e-8)
        fits.append((f.rho, f))
    share, halved = _coverage(fits, rho, lambda f: f.rho_interval)
    assert _covers(share), share
    assert not _covers(halved), halved


def test_q_intervals_cover_the_truth_at_their_level():
    """220 data sets drawn at q = 0.05, rho = 0.02 (rho known): the 95 % profile intervals
    of q, (0, upper) where the estimate sits at q = 0, cover the true q within 3 binomial
    SEs of 0.95; halved, they do not."""
    rho, q = 0.02, 0.05
    fits = []
    for s in np.random.SeedSequence(2025).spawn(COVERAGE_SETS):
        mu = _tracks(s, COVERAGE_TRACKS, COVERAGE_FRAMES, rho, q)
        f = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, rho=rho, rtol=1e-8)
        fits.append((f.process_noise, f))
    share, halved = _coverage(fits, q, lambda f: f.process_noise_interval)
    assert _covers(share), share
    assert not _covers(halved), halved


def test_the_profile_interval_of_q_covers_the_boundary_q_0():
    """Eight fits of three 10-frame tracks drawn at q = 0: the default (profile) interval
    reaches 0 in at least 7 (at the 95 % level); Wald's on the log scale reaches 0 only when
    the estimate sits at the boundary, in fewer."""
    covered = at_boundary = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        states = rng.multivariate_normal(PRIOR_MEAN, PRIOR_COV, size=3)
        states[:, 1] = np.abs(states[:, 1]) + 0.5
        mu = model.simulate(states, 10, 0.01, 0.0, rng, frame=1).mu
        fit = learning.fit(mu, PRIOR_MEAN, PRIOR_COV)
        covered += fit.process_noise_interval[0] == 0.0
        at_boundary += fit.at_boundary
    assert covered >= 7 and at_boundary < covered


def test_the_gate_keeps_outliers_from_inflating_rho():
    """Two mismatched bearings, 20 SDs off, among four 15-frame tracks: without a gate they
    inflate rho by more than half; with a gate at 1e-3 they and only they are skipped, and
    rho is within 3 standard errors of the truth."""
    rho = 0.01
    mu = _tracks(21, 4, 15, rho, 0.0)
    mu[1, 6] += 20 * rho
    mu[3, 11] -= 20 * rho
    plain = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.0)
    gated = learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.0, gate=1e-3)
    assert plain.rho > 1.5 * rho and plain.gated is None
    assert gated.gated[1, 6] and gated.gated[3, 11] and gated.gated.sum() == 2
    assert abs(gated.rho - rho) < 3 * gated.rho_se
    assert "the gate at 0.001 skipped 2 bearings" in gated.note
    with pytest.raises(ValueError, match="^gate"):
        learning.fit(mu, PRIOR_MEAN, PRIOR_COV, process_noise=0.0, gate=2.0)
