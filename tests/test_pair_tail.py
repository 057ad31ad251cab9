"""The tail of a pair under a Gaussian mixture (depthcore.problem.pair_tail): one Gaussian's
exp(-d**2 / 2), an isotropic pair of components against a one-dimensional quadrature, a
banana of components against Monte Carlo, and the ends of the scale."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, optimize
from scipy.special import erfc, logsumexp

from depthcore.problem import pair_tail


def banana(J=40):
    """Components along an arc (as the depth nodes put them), weighted as a Gaussian along it."""
    phi = np.linspace(-1.2, 1.2, J)
    means = np.stack([3 * np.sin(phi), 3 * np.cos(phi)], -1)
    covs = np.broadcast_to(np.diag([0.05, 0.02]), (J, 2, 2)).copy()
    return -0.5 * phi**2 / 0.3, means, covs


def log_density(z, log_w, means, covs):
    r = np.asarray(z)[..., None, :] - means
    q = np.einsum("...jk,jkl,...jl->...j", r, np.linalg.inv(covs), r)
    log_n = -np.log(2 * np.pi) - 0.5 * np.linalg.slogdet(covs)[1] - 0.5 * q
    return logsumexp(log_w - logsumexp(log_w) + log_n, axis=-1)


@pytest.mark.parametrize("z", [[1.5, -0.3], [4.0, 2.0], [1.0, -1.0], [-3.0, 0.5], [9.0, -8.0]])
def test_one_gaussian_gives_exp_minus_half_the_squared_mahalanobis_distance(z):
    m, S = np.array([[1.0, -1.0]]), np.array([[[2.0, 0.5], [0.5, 1.0]]])
    r = np.array(z) - m[0]
    expected = np.exp(-0.5 * r @ np.linalg.solve(S[0], r))
    out = pair_tail.tail(z, [0.0], m, S)
    assert out.tail == pytest.approx(expected, abs=1e-10, rel=1e-10)
    assert out.error <= max(pair_tail.ATOL, pair_tail.RTOL * out.tail)


@pytest.mark.parametrize("z", [[0.0, 0.0], [0.3, 0.8], [1.7, 0.2], [2.5, 1.5], [-0.5, 2.6]])
def test_two_isotropic_components_agree_with_a_quadrature_over_x(z):
    # means on the x-axis, covariances s**2 I: at each x the region p <= p0 is abs(y) >= y*(x),
    # whose mass is closed form, so that T is a one-dimensional integral (scipy's quad)
    a, s, w = np.array([-1.0, 1.2]), 0.8, np.array([0.35, 0.65])
    means, covs = np.stack([a, [0.0, 0.0]], -1), np.broadcast_to(s * s * np.eye(2), (2, 2, 2))
    log_p0 = log_density(z, np.log(w), means, covs)

    def h(x):  # the density at (x, 0)
        return np.sum(w * np.exp(-0.5 * ((x - a) / s) ** 2)) / (2 * np.pi * s * s)

    def mass(x):
        y2 = 2 * s * s * max(0.0, np.log(h(x)) - log_p0)
        return (
            np.sum(w * np.exp(-0.5 * ((x - a) / s) ** 2))
            / (np.sqrt(2 * np.pi) * s)
            * erfc(np.sqrt(y2) / (s * np.sqrt(2)))
        )

    xs = np.linspace(-12, 12, 4801)
    g = np.array([np.log(h(x)) - log_p0 for x in xs])
    kinks = [
        optimize.brentq(lambda x: np.log(h(x)) - log_p0, xs[k], xs[k + 1], xtol=1e-15)
        for k in np.flatnonzero(np.sign(g[:-1]) != np.sign(g[1:]))
    ]
    edges = [-12.0, *kinks, 12.0]
    reference = sum(
        integrate.quad(mass, lo, hi, epsabs=1e-14, epsrel=1e-13, limit=200)[0]
        for lo, hi in zip(edges[:-1], edges[1:], strict=True)
    )
    out = pair_tail.tail(z, np.log(w), means, covs)
    tol = max(pair_tail.ATOL, pair_tail.RTOL * reference)
    assert abs(out.tail - reference) <= tol and out.error <= tol


@pytest.mark.parametrize("z", [[0.0, 2.7], [1.9, 2.0], [2.6, 2.4], [0.0, 2.5], [-2.5, 1.2]])
def test_a_banana_agrees_with_a_million_draws_and_differs_from_one_gaussian(z):
    log_w, means, covs = banana()
    out = pair_tail.tail(z, log_w, means, covs)
    rng = np.random.default_rng(20261206)
    n = 10**6
    w = np.exp(log_w - logsumexp(log_w))
    j = rng.choice(w.size, n, p=w)
    draws = means[j] + np.einsum(
        "nkl,nl->nk", np.linalg.cholesky(covs)[j], rng.standard_normal((n, 2))
    )
    log_p0 = log_density(z, log_w, means, covs)
    hits = np.concatenate(
        [log_density(d, log_w, means, covs) <= log_p0 for d in np.array_split(draws, 20)]
    )
    mc = hits.mean()
    se = np.sqrt(mc * (1 - mc) / n)
    assert abs(out.tail - mc) <= 4 * se
    # one Gaussian of the mixture's moments gives another number, far beyond the tolerance
    mean = w @ means
    e = means - mean
    V = np.einsum("j,jkl->kl", w, covs + e[:, :, None] * e[:, None, :])
    r = np.asarray(z) - mean
    fit = np.exp(-0.5 * r @ np.linalg.solve(V, r))
    assert abs(fit - out.tail) > 10 * max(4 * se, pair_tail.ATOL, pair_tail.RTOL)


def test_the_mode_gives_one_and_far_out_gives_zero():
    log_w, means, covs = banana()
    top = means[np.argmax(log_w)]
    mode = optimize.minimize(lambda z: -log_density(z, log_w, means, covs), top).x
    assert pair_tail.tail(mode, log_w, means, covs).tail == pytest.approx(1.0, abs=1e-6)
    assert pair_tail.tail([30.0, -20.0], log_w, means, covs).tail < 1e-100
    with pytest.raises(ValueError, match="^log_weights: every component is empty$"):
        pair_tail.tail([0.0, 0.0], [-np.inf], means[:1], covs[:1])


# --- the exact filter's gate on pairs ----------------------------------------------------------

PRIOR_MEAN = np.array([0.5, 8.0, 0.2, 0.1, 0.0])
PRIOR_COV = np.diag([1.0, 4.0, 0.3, 1.0, 0.3])
RHO = 0.01


def outlier_track(N=14, seed=1):
    """A point in 3-D seen for N frames, its pairs 5 and ``10 % N`` (0-based) moved 5 SDs
    or more."""
    truth = np.array([0.8, 7.0, 0.1, -0.3, 0.05])
    k = np.arange(N)
    x, y, h = truth[0] + truth[2] * k, truth[1] + k, truth[3] + truth[4] * k
    pairs = np.stack([x / y, h / y], -1)
    pairs = pairs + RHO * np.random.default_rng(seed).standard_normal(pairs.shape)
    pairs[5] += [0.06, -0.05]
    pairs[10 % N] += [-0.05, 0.06]
    return pairs, np.array([x[-1], y[-1], truth[2], h[-1], truth[4]])


def test_the_exact_filter_gates_exactly_the_outlying_pairs_and_beats_no_gate():
    from depthcore.exact.online import Online

    pairs, end = outlier_track()
    runs = {}
    for gate in (None, 1e-3):
        f = Online(PRIOR_MEAN, PRIOR_COV, rho=RHO, gate=gate)
        runs[gate] = [f.update(p) for p in pairs]
    assert [e.frame for e in runs[1e-3] if e.gated] == [6, 11]
    assert not any(e.gated for e in runs[None])
    assert all(e.tail < 1e-6 for e in (runs[1e-3][5], runs[1e-3][10]))
    assert all(np.isnan(e.tail) for e in runs[None])  # without a gate no tail is computed
    errors = {}
    for gate, ests in runs.items():
        d = ests[-1].mean - end
        errors[gate] = (abs(d[1]), d @ np.linalg.solve(ests[-1].cov, d))
    assert errors[1e-3][0] < 0.7 * errors[None][0] and errors[1e-3][1] < 0.5 * errors[None][1]


def test_the_command_line_gates_pairs_of_the_exact_filter_frame_by_frame(tmp_path, capsys):
    from depthcore.registry import online

    from helpers import cli_json

    pairs, _ = outlier_track(N=8)  # the outliers at frames 3 and 6
    path = tmp_path / "pairs.csv"
    path.write_text("mu,nu\n" + "".join(f"{m!r},{n!r}\n" for m, n in pairs.tolist()))
    prior = ["--prior-mean", *map(str, PRIOR_MEAN), "--prior-cov", *map(str, PRIOR_COV.ravel())]
    argv = ["estimate", "--mu-file", str(path), "--rho", str(RHO), *prior, "--per-frame"]
    out = cli_json([*argv, "--filters", "optimal", "--gate", "0.001"], capsys)
    rows = out["filters"]["optimal"]
    assert out["gate"] == 0.001 and [r["frame"] for r in rows if r["gated"]] == [3, 6]
    live = online.start("optimal", PRIOR_MEAN, PRIOR_COV, RHO, 0.0, 0.001)
    for row, pair in zip(rows, pairs, strict=True):
        est = live.update(pair)
        assert row["gated"] == est.gated and row["tail"] == est.tail
        assert row["filtered_depth_mean"] == est.mean[1]
