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
