"""Eqs. (8), (23), (24): the second-order approximation p_s."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthbook import reference
from depthcore import paper_prior
from depthcore.exact import optimal
from depthcore.kalman import ekf, second_order
from depthcore.kalman.second_order import (
    hessian,
    likelihood_covariance,
    minimiser,
    second_order_batch,
    theorem1_precision,
    trajectory_solve,
    trajectory_states,
)
from depthcore.problem import model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import f, noise_free_state
from depthcore.problem.scenarios import MU_17, MU_18

from helpers import bearings


@pytest.mark.parametrize("mu", [MU_17, MU_18, tuple(bearings(np.array([1.0, 8.0, -0.5])))])
def test_eq8_hessian_matches_finite_differences(mu):
    c = noise_free_state(mu)
    h = 1e-4 * c[1]  # central second differences: truncation O(h^2) relative
    E = np.eye(3) * h
    fd = np.array(
        [
            [
                (
                    f(c + E[i] + E[j], mu)
                    - f(c + E[i] - E[j], mu)
                    - f(c - E[i] + E[j], mu)
                    + f(c - E[i] - E[j], mu)
                )
                / (4 * h * h)
                for j in range(3)
            ]
            for i in range(3)
        ]
    )
    assert_allclose(hessian(mu), fd, rtol=1e-5, atol=1e-7 * np.abs(fd).max())


def test_eq8_derived_covariance_is_the_small_noise_limit_of_the_optimal_filter():
    # With a prior too broad to matter and small noise, the optimal filter's
    # depth SD approaches that of N(c, 2 rho^2 J^{-1}), not of N(c, rho^2 J^{-1}).
    mu = MU_17
    c = noise_free_state(mu)
    prior = Gaussian(paper_prior(c).mean, 1e8 * np.eye(3))
    rho = 1e-5
    exact = optimal.run(mu, rho, prior.mean, prior.cov)
    derived = np.sqrt(likelihood_covariance(mu, rho, "derived")[1, 1])
    printed = np.sqrt(likelihood_covariance(mu, rho, "printed")[1, 1])
    assert exact.depth_sd == pytest.approx(derived, rel=1e-3)  # O(rho) skew corrections
    assert exact.depth_sd / printed == pytest.approx(np.sqrt(2), rel=1e-3)


def test_eq8_second_order_is_the_product_of_its_two_gaussians():
    mu, rho = MU_17, 1 / 200
    c = noise_free_state(mu)
    prior = paper_prior(c)
    ps = second_order.run(mu, rho, prior.mean, prior.cov)
    lik = Gaussian(c, likelihood_covariance(mu, rho))
    rng = np.random.default_rng(3)
    x = ps.mean + rng.normal(scale=0.3, size=(50, 3))
    from depthcore.problem import model

    diff = ps.logpdf(x) - lik.logpdf(x) - prior.logpdf(model.G(x, -2))
    assert np.ptp(diff) < 1e-9  # a constant: the log normaliser


def test_second_order_batch_matches_single():
    mus = np.array([MU_17, MU_18])
    means = np.array([paper_prior(noise_free_state(m)).mean for m in mus])
    m, P = second_order_batch(mus, 1 / 200, means, 1000 * np.eye(3))
    for i, mu in enumerate(mus):
        prior = paper_prior(noise_free_state(mu))
        g = second_order.run(mu, 1 / 200, prior.mean, prior.cov)
        # inverse versus Cholesky solve of a precision with condition number ~1e5
        assert_allclose(m[i], g.mean, rtol=1e-10)
        assert_allclose(P[i], g.cov, rtol=1e-9)


def test_reading_must_be_known():
    with pytest.raises(ValueError, match="reading must be one of"):
        likelihood_covariance(MU_17, 0.01, "halved")


def test_eq23_second_order_density_is_the_linearised_posterior():
    from depthcore.problem import model
    from depthcore.problem.model import residual_gradients

    mu, rho = MU_17, 1 / 200
    c = noise_free_state(mu)
    prior = paper_prior(c)
    g = residual_gradients(c)
    ps = second_order.run(mu, rho, prior.mean, prior.cov)
    x = ps.mean + np.random.default_rng(3).normal(scale=0.2, size=(40, 3))
    eq23 = -np.sum(((x - c) @ g.T) ** 2, axis=1) / (2 * rho**2) + prior.logpdf(model.G(x, -2))
    assert np.ptp(ps.logpdf(x) - eq23) < 1e-8


@pytest.mark.parametrize("mu", [MU_17, MU_18])
def test_theorem1_precision_is_the_inverse_of_the_ekf_and_second_order_covariances(mu):
    c = noise_free_state(mu)
    prior = Gaussian(model.G(c, -2), 1000.0 * np.eye(3))
    rho = 1 / 200
    D_inv = theorem1_precision(mu, rho, prior)
    P3 = ekf.run(mu, rho, prior.mean, prior.cov).posterior.cov
    D = second_order.run(mu, rho, prior.mean, prior.cov).cov
    # inverses of matrices with condition number ~1e6: 1e-8 relative
    assert_allclose(D_inv @ P3, np.eye(3), atol=1e-8)
    assert_allclose(D_inv @ D, np.eye(3), atol=1e-8)


# --- N frames, Eq. (8) generalised ------------------------------------------------------

X1 = np.array([-1.0, 6.0, 0.4])  # state at frame 1
PRIOR_COV = np.diag([4.0, 25.0, 0.25])


def _problem(n_frames, rho=2e-3, size=3, seed=0):
    rng = np.random.default_rng(seed + n_frames)
    return model.simulate(X1, n_frames, rho, 0.0, rng, size=size, frame=1).mu


def test_n3_minimiser_is_the_noise_free_state_and_the_gaussian_is_p_s():
    mu = _problem(3, size=4)
    c = model.noise_free_states(mu)
    assert_allclose(minimiser(mu), c, rtol=1e-12)
    prior_mean = X1 + [0.5, -1.0, 0.1]
    mean, cov = second_order_batch(mu, 2e-3, prior_mean, PRIOR_COV)
    # The N-frame construction at N = 3: the minimiser's Gaussian N(c, rho^2 (g^T g)^{-1})
    # times the prior, written out with the information matrix.
    for i in range(len(mu)):
        g = model.residual_gradients(minimiser(mu[i : i + 1])[0], 3)
        A = model.G_linear(-2)
        info = g.T @ g / 2e-3**2 + A.T @ np.linalg.solve(PRIOR_COV, A)
        rhs = g.T @ g @ c[i] / 2e-3**2 + A.T @ np.linalg.solve(
            PRIOR_COV, prior_mean - np.array([0.0, -2.0, 0.0])
        )
        assert_allclose(mean[i], np.linalg.solve(info, rhs), rtol=1e-10)
        assert_allclose(cov[i], np.linalg.inv(info), rtol=1e-8)
        ps = second_order.run(mu[i], 2e-3, prior_mean, PRIOR_COV)
        assert np.array_equal(ps.mean, mean[i]) and np.array_equal(ps.cov, cov[i])


@pytest.mark.parametrize("n_frames", [4, 7, 12])
def test_n_frame_minimiser_matches_scipy_least_squares(n_frames):
    from scipy.optimize import least_squares

    mu = _problem(n_frames)
    ours = minimiser(mu)
    for i in range(len(mu)):
        # an independent solver from an independent start: the truth moved to frame N
        fit = least_squares(
            lambda x, i=i: model.residuals(x, mu[i]),
            model.G(X1, n_frames - 1) + [0.05, 0.5, -0.02],
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
        )
        assert_allclose(ours[i], fit.x, rtol=1e-8)
        assert model.f(ours[i], mu[i]) <= model.f(fit.x, mu[i]) * (1 + 1e-10)


@pytest.mark.parametrize("n_frames", [4, 9])
def test_n_frame_covariance_is_twice_rho_squared_over_the_misfit_hessian(n_frames):
    # With the prior made negligible the Gaussian is the likelihood's:
    # covariance 2 rho^2 H^{-1}, H the Hessian of f at the minimiser. H from central
    # finite differences of f includes sum_k r_k grad^2 r_k, which the Gauss-Newton
    # Hessian 2 J^T J drops: a relative O(rho) term, so the noise is small here.
    rho = 1e-6
    mu = _problem(n_frames, rho=rho, size=1)
    c = minimiser(mu)[0]
    mean, cov = second_order_batch(mu, rho, X1, 1e12 * np.eye(3))
    h = 1e-4
    E = np.eye(3) * h * np.maximum(1.0, np.abs(c))
    H = np.array(
        [
            [
                (
                    model.f(c + E[a] + E[b], mu[0])
                    - model.f(c + E[a] - E[b], mu[0])
                    - model.f(c - E[a] + E[b], mu[0])
                    + model.f(c - E[a] - E[b], mu[0])
                )
                / (4 * E[a, a] * E[b, b])
                for b in range(3)
            ]
            for a in range(3)
        ]
    )
    assert_allclose(mean[0], c, rtol=1e-7)
    assert_allclose(cov[0], 2 * rho**2 * np.linalg.inv(H), rtol=1e-3)


def dense_trajectory_laplace(mu, rho, prior_mean, prior_cov, q):
    """An independent dense Gauss-Newton over ``(x_1, y_1, v_1, a_1 .. a_{N-1})``.

    The states are built by stepping the motion frame by frame; the Jacobian by
    central differences; the Laplace Gaussian times the prior in information
    form; the marginal at frame N by pushing sigma-free linear maps.
    """
    n = len(mu)

    def states(z):
        x, y, v = z[:3]
        out = []
        for k in range(n):
            out.append((x, y, v))
            if k < n - 1:
                x, y, v = x + v, y + 1.0, v + z[3 + k]
        return np.array(out)

    def stacked(z):
        s = states(z)
        return np.concatenate([(s[:, 0] / s[:, 1] - mu) / rho, z[3:] / q])

    def jac(z):
        eps = 1e-7 * np.maximum(1.0, np.abs(z))
        return np.stack(
            [(stacked(z + e) - stacked(z - e)) / (2 * e.sum()) for e in np.diag(eps)], axis=1
        )

    z = np.concatenate([X1, np.zeros(n - 1)])
    for _ in range(50):
        J = jac(z)
        z = z - np.linalg.lstsq(J, stacked(z), rcond=None)[0]
    J = jac(z)
    E = np.zeros((3, n + 2))
    E[:, :3] = np.eye(3)
    P_inv = np.linalg.inv(prior_cov)
    info = J.T @ J + E.T @ P_inv @ E
    post_cov = np.linalg.inv(info)
    post = post_cov @ (J.T @ J @ z + E.T @ P_inv @ prior_mean)
    # the state at frame N is linear in z: its map by differences of the motion
    base = states(np.zeros(n + 2))[-1]
    T = np.stack([states(e)[-1] - base for e in np.eye(n + 2)], axis=1)
    v_last = post[2] + post[3:].sum()
    mean = T @ post + base
    mean[2] = v_last
    T[2] = np.r_[0.0, 0.0, 1.0, np.ones(n - 1)]
    return mean, T @ post_cov @ T.T


@pytest.mark.parametrize("n_frames", [3, 5, 8])
def test_trajectory_laplace_matches_a_dense_gauss_newton(n_frames):
    rho, q = 2e-3, 0.02
    mu = _problem(n_frames, rho=rho, size=2)
    prior_mean = X1 + [0.3, -0.8, 0.05]
    mean, cov = second_order_batch(mu, rho, prior_mean, PRIOR_COV, process_noise=q)
    for i in range(len(mu)):
        m, c = dense_trajectory_laplace(mu[i], rho, prior_mean, PRIOR_COV, q)
        assert_allclose(mean[i], m, rtol=1e-7)
        assert_allclose(cov[i], c, rtol=1e-5, atol=1e-12)


@pytest.mark.parametrize("n_frames", [3, 6])
def test_trajectory_laplace_tends_to_the_approximation_without_process_noise(n_frames):
    mu = _problem(n_frames)
    still = second_order_batch(mu, 2e-3, X1, PRIOR_COV)
    barely = second_order_batch(mu, 2e-3, X1, PRIOR_COV, process_noise=1e-9)
    # Both minimisers are Gauss-Newton iterations stopped by a line search that can no
    # longer decrease the misfit in floating point: they agree to about 1e-9 relative.
    assert_allclose(barely[0], still[0], rtol=1e-8)
    assert_allclose(barely[1], still[1], rtol=1e-6)


def test_single_sequence_is_the_batch_row():
    mu = _problem(6, size=1)
    g = second_order.run(mu[0], 2e-3, X1, PRIOR_COV, process_noise=0.01)
    mean, cov = second_order_batch(mu, 2e-3, X1, PRIOR_COV, process_noise=0.01)
    assert np.array_equal(g.mean, mean[0]) and np.array_equal(g.cov, cov[0])


def test_a_misfit_without_a_determined_minimiser_is_refused():
    # constant bearings but the last: far-away points at every depth fit nearly as well
    mu = np.array([[0.1, 0.1, 0.1, 0.1, 0.1 + 1e-10]])
    with pytest.raises(ValueError, match=r"mu\[0\]"):
        second_order_batch(mu, 1e-3, X1, PRIOR_COV)


def _random_trajectory_problem(n_frames, B, seed, prior=True):
    rng = np.random.default_rng(seed)
    H = rng.standard_normal((B, n_frames, 3))
    y = rng.standard_normal((B, n_frames))
    t = rng.standard_normal((B, n_frames - 1))
    U = np.triu(rng.standard_normal((B, 3, 3))) + 3 * np.eye(3) if prior else None
    u = rng.standard_normal((B, 3)) if prior else None
    return H, y, t, U, u


@pytest.mark.parametrize(
    ("n_frames", "prior"),
    # without a prior, fewer than three measurement rows leave the states undetermined
    [(n, True) for n in (1, 2, 3, 7, 25)] + [(n, False) for n in (3, 7, 25)],
)
def test_trajectory_solve_is_the_dense_least_squares_solution(n_frames, prior):
    """The block-tridiagonal (square-root information) route against a dense lstsq of the
    whole stacked system over z = (d_1, b_1 .. b_{N-1}), written from the motion frame by frame."""
    q = 0.3
    H, y, t, U, u = _random_trajectory_problem(n_frames, 3, seed=n_frames, prior=prior)
    dz, R = trajectory_solve(H, y, t, q, U, u)
    for i in range(3):
        dim = n_frames + 2
        maps = []  # d_k as a linear map of z, stepping d_{k+1} = F d_k + (0, 0, b_k)
        Mk = np.zeros((3, dim))
        Mk[:, :3] = np.eye(3)
        for k in range(n_frames):
            maps.append(Mk.copy())
            Mk = model.G_linear(1) @ Mk
            if k < n_frames - 1:
                Mk[2, 3 + k] += 1.0
        rows = [H[i, k] @ maps[k] for k in range(n_frames)]
        rhs = list(y[i])
        for k in range(n_frames - 1):
            e = np.zeros(dim)
            e[3 + k] = 1.0 / q
            rows.append(e)
            rhs.append(t[i, k])
        if prior:
            rows.extend(U[i] @ maps[0])
            rhs.extend(u[i])
        A = np.array(rows)
        z = np.linalg.lstsq(A, np.array(rhs), rcond=None)[0]
        assert_allclose(dz[i], z, rtol=1e-10, atol=1e-10)
        assert_allclose(trajectory_states(dz[i], offset=False), [m @ z for m in maps], atol=1e-10)
        # R^{-1} R^{-T} is the covariance of d_N: the last state's block of (A^T A)^{-1}
        cov = maps[-1] @ np.linalg.inv(A.T @ A) @ maps[-1].T
        R_inv = np.linalg.inv(R[i])
        assert_allclose(R_inv @ R_inv.T, cov, rtol=1e-9, atol=1e-12)


def test_trajectory_states_follow_the_motion_frame_by_frame():
    z = np.array([0.3, 4.0, -0.2, 0.05, -0.1, 0.02])
    x, y, v = z[:3]
    for k, state in enumerate(trajectory_states(z)):
        assert_allclose(state, [x, y, v], rtol=1e-14)
        if k < 3:
            x, y, v = x + v, y + 1.0, v + z[3 + k]


@pytest.mark.parametrize("n_frames", [3, 5, 12, 30])
def test_trajectory_laplace_equals_the_dense_route(n_frames):
    """The linear-cost route against :func:`depthbook.reference.trajectory_laplace_dense`,
    the same Gauss-Newton with every step a dense solve, to the resolution of their line
    searches (which stop where the objective no longer decreases in floating point)."""
    rho, q = 2e-3, 0.02
    mu = _problem(n_frames, rho=rho, size=3)
    prior_mean = X1 + [0.3, -0.8, 0.05]
    mean, cov = second_order_batch(mu, rho, prior_mean, PRIOR_COV, process_noise=q)
    for i in range(len(mu)):
        m, c = reference.trajectory_laplace_dense(mu[i], rho, prior_mean, PRIOR_COV, q)
        sd = np.sqrt(np.diag(c))
        assert np.max(np.abs(mean[i] - m) / sd) < 1e-6
        assert np.max(np.abs(cov[i] - c) / np.outer(sd, sd)) < 1e-6
