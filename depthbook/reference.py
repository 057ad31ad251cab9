"""Independent routes to what the package computes in closed form, for checking it.

Recommended import: ``from depthbook import reference``.

* :func:`grid_moments`, :func:`importance_moments`: the optimal filter's
  moments without Eqs. (14)-(16), from the log posterior (6) itself, by a
  dense three-dimensional Gauss-Legendre grid or by importance sampling;
* :func:`bayes_filter`: the recursion (2) with (3) and (4) run literally, as
  an independent route to the optimal density (6);
* :func:`numerical_gradient`, :func:`numerical_hessian`: central differences,
  to check the observation vector (11) and the Hessian ``J`` of (8);
* :func:`log_gaussian_integral_brute`: the Gaussian integral behind Eq. (16)
  by brute force;
* :func:`trapezoid_depth_moments`: the depth moments by one trapezoid rule of
  a fixed step;
* :func:`track_fixed_lag`: a track's fixed-lag smoothed states by the
  textbook's state augmentation (19.2.6), rerun from frame 1 for every frame;
* :func:`trajectory_laplace_dense`, :func:`iterated_smoother_dense`: the
  trajectory's Gauss-Newton problems with process noise solved densely, over
  the whole trajectory at once.

They are slow by design; :mod:`depthcore.exact.optimal` is the route to use.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from depthcore.exact import bank, optimal
from depthcore.exact.optimal import log_posterior
from depthcore.kalman import linear, second_order
from depthcore.kalman.second_order import bearing_residuals, minimiser, trajectory_map
from depthcore.particles.resampling import weighted_moments, weighted_standard_errors
from depthcore.problem import checks, model
from depthcore.problem.gaussian import Gaussian, student_t, symmetric
from depthcore.problem.weights import normalised

LogDensity = Callable[[np.ndarray], np.ndarray]


class BruteMoments(NamedTuple):
    """Depth and velocity means and SDs of the optimal filter, the number of
    evaluations of Eq. (6), and the mean (3,) and covariance (3, 3) of the state."""

    depth_mean: float
    depth_sd: float
    velocity_mean: float
    velocity_sd: float
    n_evaluations: int
    mean: np.ndarray
    cov: np.ndarray


def _gauss_legendre_panels(lo, hi, panels, order):
    """Nodes and weights of a composite Gauss-Legendre rule on ``[lo, hi]``."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(lo, hi, panels + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    return (mid[:, None] + half[:, None] * x).ravel(), (half[:, None] * w).ravel()


def _uv_box(y, mu, rho, prior):
    """Centre and axes of the Gaussian in ``(x, v)`` at each depth, from Eq. (6) alone.

    The log posterior is exactly quadratic in ``(x, v)`` at fixed ``y``, so one
    Newton step from any point, with a central-difference gradient and
    Hessian, lands on its maximum.
    """
    u0 = np.stack([mu[2] * y, np.zeros_like(y)], -1)
    # a step near the conditional SD keeps rounding small: ~rho (y - 2) close to the pole
    h = rho * np.minimum(y - 2.0, 1.0)[:, None]

    def lp(u):
        return log_posterior(np.stack([u[:, 0], y, u[:, 1]], -1), mu, rho, prior)

    e = np.eye(2)
    grad = np.stack([(lp(u0 + h * e[i]) - lp(u0 - h * e[i])) / (2 * h[:, 0]) for i in range(2)], -1)
    hess = np.empty((y.size, 2, 2))
    for i in range(2):
        for j in range(2):
            hess[:, i, j] = (
                lp(u0 + h * (e[i] + e[j]))
                - lp(u0 + h * (e[i] - e[j]))
                - lp(u0 - h * (e[i] - e[j]))
                + lp(u0 - h * (e[i] + e[j]))
            ) / (4 * h[:, 0] ** 2)
    cov = np.linalg.inv(-hess)
    centre = u0 + np.einsum("nij,nj->ni", cov, grad)
    vals, vecs = np.linalg.eigh(cov)
    return centre, vecs * np.sqrt(vals)[:, None, :]


def grid_moments(
    mu,
    rho: float,
    prior: Gaussian,
    y_range=(2.0, None),
    panels: int = 400,
    order: int = 8,
    uv_order: int = 40,
    width: float = 10.0,
) -> BruteMoments:
    """Moments of Eq. (6) by a dense 3-D Gauss-Legendre grid over ``y > 2``.

    Depth nodes: composite Gauss-Legendre in ``t = log(y - 2)``; at each depth,
    a tensor Gauss-Legendre grid of ``uv_order**2`` nodes over ``width``
    standard deviations of the ``(x, v)`` Gaussian found by :func:`_uv_box`.

    Parameters
    ----------
    mu, rho, prior
        As in :func:`depthcore.exact.optimal.log_posterior`.
    y_range : (float, float or None)
        Depth range, at least ``y - 2 >= 0.01`` (in the paper's scenarios the
        mass below is under 1e-100); the upper end defaults to
        ``c2 + 60 sqrt(P22) + 100``.
    panels, order, uv_order, width
        Resolution of the grid.
    """
    mu = model.measurements(mu)
    rho = checks.positive_scalar(rho, "rho")
    lo, hi = y_range
    if hi is None:
        hi = (
            second_order.run(mu, rho, prior.mean, prior.cov).mean[1]
            + 60 * np.sqrt(prior.cov[1, 1])
            + 100
        )
    t, wt = _gauss_legendre_panels(np.log(max(lo - 2, 1e-2)), np.log(hi - 2), panels, order)
    y = 2.0 + np.exp(t)
    wy = wt * np.exp(t)
    centre, axes = _uv_box(y, mu, rho, prior)
    s, ws = _gauss_legendre_panels(-width, width, 1, uv_order)
    S = np.stack(np.meshgrid(s, s, indexing="ij"), -1).reshape(-1, 2)
    W = np.outer(ws, ws).ravel()
    u = centre[:, None, :] + np.einsum("nij,kj->nki", axes, S)  # (ny, k, 2)
    jac = np.abs(np.linalg.det(axes))
    x = np.stack([u[..., 0], np.broadcast_to(y[:, None], u.shape[:2]), u[..., 1]], -1)
    lp = log_posterior(x, mu, rho, prior)
    w = np.exp(lp - lp.max()) * (wy * jac)[:, None] * W[None, :]
    Z = w.sum()
    ey = np.sum(w.sum(1) * y) / Z
    ev = np.sum(w * u[..., 1]) / Z
    sd_y = np.sqrt(np.sum(w.sum(1) * (y - ey) ** 2) / Z)
    sd_v = np.sqrt(np.sum(w * (u[..., 1] - ev) ** 2) / Z)
    mean = np.einsum("nk,nki->i", w, x) / Z
    d = x - mean
    cov = np.einsum("nk,nki,nkj->ij", w, d, d) / Z
    return BruteMoments(float(ey), float(sd_y), float(ev), float(sd_v), int(lp.size), mean, cov)


def importance_moments(
    mu,
    rho: float,
    prior: Gaussian,
    rng: np.random.Generator,
    n: int = 200_000,
    df: float = 3.0,
    inflate: float = 2.0,
):
    """Moments of Eq. (6) over ``y > 2`` by self-normalised importance sampling.

    The proposal is a multivariate Student t with ``df`` degrees of freedom,
    centred at the second-order mean with its covariance scaled by
    ``inflate**2``.

    Returns
    -------
    means : ndarray, shape (2,)
        Depth and velocity means.
    sds : ndarray, shape (2,)
    standard_errors : ndarray, shape (2,)
        Delta-method standard errors of the two means.
    """
    mu = model.measurements(mu)
    ps = second_order.run(mu, rho, prior.mean, prior.cov)
    draws, log_q = student_t(ps.mean[None], inflate**2 * ps.cov[None], df, n, rng)
    x, log_q = draws[0], log_q[0]
    front = x[:, 1] > 2
    log_w = np.full(n, -np.inf)
    log_w[front] = log_posterior(x[front], mu, rho, prior) - log_q[front]
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    vals = x[:, [1, 2]].T  # (2, n): depths and velocities
    means, sds = weighted_moments(vals, w)
    se_means, _ = weighted_standard_errors(vals, w)
    return means, sds, se_means


# --- independent routes to the recursion (2)-(4), Eqs. (8), (11), (16) -------------------------


def bayes_filter(mu, rho: float, prior: Gaussian) -> list[LogDensity]:
    """Eqs. (2)-(4): the filtering densities after each measurement, by the recursion.

    Each step is a prediction and a measurement update. With the deterministic
    motion (3) the Chapman-Kolmogorov integral of the prediction collapses to
    ``p(x_k | I^{k-1}) = p(G^{-1} x_k | I^{k-1}) / |det F|`` with
    ``det F = 1``; the update multiplies by the likelihood (4) (Bayes' rule,
    up to the normalising constant ``c`` of (2)).

    Parameters
    ----------
    mu : array_like, shape (k,)
        Measurements ``mu_1 .. mu_k`` in time order.
    rho : float
        Noise standard deviation, > 0.
    prior : Gaussian
        Density of the state at time 1 before the first measurement.

    Returns
    -------
    list of callables
        Entry ``i`` maps states of shape ``(..., 3)`` at time ``i + 1`` to the
        unnormalised ``log p(x_{i+1} | I^{i+1})``, shape ``(...)``.
    """
    rho = checks.positive_scalar(rho, "rho")
    mu = checks.finite_array(mu, "mu")
    if mu.ndim != 1 or mu.size == 0:
        raise ValueError(f"mu must be a non-empty 1-D array, got shape {mu.shape}")
    log_det_F = float(np.log(abs(np.linalg.det(model.F))))
    densities: list[LogDensity] = []
    predicted: LogDensity = prior.logpdf  # p(x_1 | I^0)
    for k, mu_k in enumerate(mu.tolist()):
        if k:
            predicted = _predicted(densities[-1], log_det_F)
        densities.append(_updated(predicted, mu_k, rho))
    return densities


def _predicted(previous: LogDensity, log_det_F: float) -> LogDensity:
    """Prediction: the integral of (2) with the delta (3), ``p(G^{-1} x) / |det F|``."""

    def log_density(x):
        return previous(model.G(x, -1)) - log_det_F

    return log_density


def _updated(predicted: LogDensity, mu_k: float, rho: float) -> LogDensity:
    """Measurement update: Bayes' rule with the likelihood (4), unnormalised."""

    def log_density(x):
        return model.log_likelihood(mu_k, x, rho) + predicted(x)

    return log_density


def numerical_gradient(fun: Callable, x, step: float = 1e-6) -> np.ndarray:
    """Central-difference gradient of a scalar function of a state.

    Parameters
    ----------
    fun : callable
        Maps an array of shape ``(3,)`` to a float.
    x : array_like, shape (n,)
    step : float
        Difference step, > 0; the error is ``O(step**2)``.

    Returns
    -------
    ndarray, shape (n,)
    """
    x = checks.finite_array(x, "x")
    step = checks.positive_scalar(step, "step")
    eye = np.eye(x.size) * step
    return np.array([(fun(x + d) - fun(x - d)) / (2.0 * step) for d in eye])


def numerical_hessian(fun: Callable, x, step: float = 1e-4) -> np.ndarray:
    """Central-difference Hessian of a scalar function of a state.

    Uses ``(f(x+a+b) - f(x+a-b) - f(x-a+b) + f(x-a-b)) / (4 step**2)`` for the
    steps ``a, b`` along two axes; the error is ``O(step**2)``.

    Returns
    -------
    ndarray, shape (n, n)
        Symmetric.
    """
    x = checks.finite_array(x, "x")
    step = checks.positive_scalar(step, "step")
    eye = np.eye(x.size) * step
    H = np.array(
        [
            [
                (fun(x + a + b) - fun(x + a - b) - fun(x - a + b) + fun(x - a - b))
                / (4.0 * step**2)
                for b in eye
            ]
            for a in eye
        ]
    )
    return symmetric(H)


def log_gaussian_integral_brute(M, l, n: int = 801, width: float = 12.0) -> float:
    """``log`` of the integral of ``exp(-1/2 (u^T M u + l^T u))`` over the plane, by brute force.

    A tensor trapezoid rule on an ``n x n`` grid covering ``width`` standard
    deviations either side of the maximum along each principal axis: an
    independent check of the closed form ``2 pi exp(l^T M^{-1} l / 8) / sqrt(det M)``.

    Parameters
    ----------
    M : array_like, shape (2, 2)
        Symmetric positive definite, Eq. (15).
    l : array_like, shape (2,)
    n : int
        Grid points per axis.
    width : float
        Half-width of the grid in standard deviations.

    Returns
    -------
    float
    """
    M = checks.covariance(M, "M", 2)
    l = checks.finite_array(l, "l", (2,))
    vals, vecs = np.linalg.eigh(M)
    axes = vecs / np.sqrt(vals)  # columns: principal axes scaled to one SD
    s = np.linspace(-width, width, n)
    S = np.stack(np.meshgrid(s, s, indexing="ij"), -1)
    # The grid sits on the maximum; where it sits does not change the integral.
    centre = -0.5 * np.linalg.solve(M, l)
    u = centre + S @ axes.T
    exponent = -0.5 * (np.einsum("...i,ij,...j->...", u, M, u) + u @ l)
    top = float(np.max(exponent))
    h = s[1] - s[0]
    w = np.full(n, h)
    w[[0, -1]] *= 0.5
    total = float(np.einsum("i,j,ij->", w, w, np.exp(exponent - top)))
    return top + np.log(total) + float(np.log(abs(np.linalg.det(axes))))


def trapezoid_depth_moments(
    mu, rho: float, prior: Gaussian, step: float, t_range=(-8.0, 8.0), reading: str = "derived"
) -> tuple[float, float, int]:
    """Mean and SD of the optimal depth marginal by one trapezoid rule of a given step.

    The rule is applied in ``t = log(y - 2)`` (support ``y > 2``) on the nodes
    ``t_lo, t_lo + step, ...`` up to ``t_hi``, to the closed form of
    :func:`depthcore.exact.optimal.conditional` times the Jacobian ``dy/dt = e^t``.
    This is the rule :func:`depthcore.exact.optimal.run` refines by halving
    its step; with a fixed step it shows how fast the rule converges.

    Parameters
    ----------
    mu, rho, prior
        As in :func:`depthcore.exact.optimal.log_posterior`.
    step : float
        Node spacing in ``t``, > 0.
    t_range : (float, float)
        First and last node; the default covers ``y - 2`` from 3e-4 to 3e3.
    reading : {"derived", "printed"}

    Returns
    -------
    mean, sd : float
    n_nodes : int
    """
    step = checks.positive_scalar(step, "step")
    t_lo, t_hi = (float(t) for t in checks.finite_array(t_range, "t_range", (2,)))
    if not t_hi > t_lo:
        raise ValueError(f"t_range must be increasing, got {(t_lo, t_hi)}")
    t = np.arange(t_lo, t_hi + step / 2, step)
    y = 2.0 + np.exp(t)
    log_w = optimal.conditional(y, mu, rho, prior, reading)[0] + t
    W, _ = normalised(log_w)
    mean = float(np.sum(W * y))
    return mean, float(np.sqrt(np.sum(W * (y - mean) ** 2))), int(t.size)


def track_fixed_lag(track) -> tuple[np.ndarray, np.ndarray]:
    """The fixed-lag smoothed states of a track by state augmentation, textbook 19.2.6.

    An independent route to ``track.lagged`` (:func:`depthcore.exact.smoother.track`,
    which runs the backward recursions over each window): frame ``s + 1`` is
    read from the posterior after ``mu_{t + 1}``, ``t = min(s + lag, N - 1)``;
    every node's filter on the state augmented with its ``t - s``
    predecessors (:func:`depthcore.kalman.linear.fixed_lag_smoother`) runs over
    ``mu_1 .. mu_{t + 1}`` from the prior given its depth, and the nodes'
    Gaussians are mixed with that posterior's probabilities by the law of
    total variance. Its cost grows like ``N^2``.

    Parameters
    ----------
    track : depthcore.exact.smoother.Track

    Returns
    -------
    mean : ndarray, shape (N, 3)
    cov : ndarray, shape (N, 3, 3)
        Of ``(x, y, v)`` at every frame.
    """
    N = len(track.posteriors)
    means, covs = [], []
    for s in range(N):
        t = min(s + track.lag, N - 1)
        post = track.posteriors[t]
        b = post.bank
        start, _ = bank.conditional_prior(b.nodes, b.prior_mean, b.prior_cov)
        sm = linear.fixed_lag_smoother(
            b.mu[:, None],
            start.mean,
            start.cov[0],  # shared by the nodes
            bank.PSI,
            bank.sigma_p(b.process_noise),
            bank.measurement_matrices(b.nodes, np.arange(1, t + 2)),
            np.reshape(b.rho**2, (1, 1)),
            lag=t - s,
        )
        x, v = sm.mean[:, s, 0], sm.mean[:, s, 1]
        m = np.stack([x, b.nodes + s, v], axis=-1)  # (J, 3)
        C = np.zeros((m.shape[0], 3, 3))  # the depth is exact given the node
        C[:, [[0], [2]], [0, 2]] = sm.cov[:, s]  # rows and columns x and v
        p = post.probabilities
        mean = p @ m
        d = m - mean
        means.append(mean)
        covs.append(np.einsum("j,jab->ab", p, C + d[:, :, None] * d[:, None, :]))
    return np.array(means), np.array(covs)


def _dense_final_state_map(n_frames: int):
    """``T`` (3, N + 2) and ``offset`` (3,): the state at frame ``N`` is ``T z + offset``."""
    T = np.zeros((3, n_frames + 2))
    T[0, 0], T[0, 2], T[0, 3:] = 1.0, n_frames - 1.0, n_frames - 2.0 - np.arange(n_frames - 1)
    T[1, 1] = 1.0
    T[2, 2], T[2, 3:] = 1.0, 1.0
    return T, np.array([0.0, n_frames - 1.0, 0.0])


def _dense_gauss_newton(z, stacked, objective, max_iterations, step_tol, moved):
    """Gauss-Newton with the step halved until the objective does not increase.

    ``stacked(z)`` gives the residuals and their dense Jacobian, each step a
    least-squares solve of the whole problem by :func:`numpy.linalg.lstsq`;
    ``moved(z_new, z, M)`` the size of a step. Returns the last ``z``, the
    iterations and whether it converged.
    """
    f = objective(z)
    for i in range(max_iterations):
        r, M = stacked(z)
        step = np.linalg.lstsq(M, -r, rcond=None)[0]
        t, z_new = 1.0, z + step
        f_new = objective(z_new)
        for _ in range(60):
            if f_new <= f:
                break
            t *= 0.5
            z_new = z + t * step
            f_new = objective(z_new)
        if not f_new <= f:
            z_new, f_new = z, f
        size = moved(z_new, z, M)
        z, f = z_new, f_new
        if not size > step_tol:
            return z, i + 1, True
    return z, max_iterations, False


def trajectory_laplace_dense(mu, rho: float, prior_mean, prior_cov, process_noise: float):
    """:func:`depthcore.kalman.second_order.trajectory_laplace` for one sequence, densely.

    Gauss-Newton on ``|r(z) / rho|**2 + |a / q|**2`` over the whole trajectory
    ``z = (x_1, y_1, v_1, a_1 .. a_{N-1})``, each step a least-squares solve of
    the full ``(2 N - 1) x (N + 2)`` Jacobian, from ``start`` (the state at frame
    1 given by the minimiser without process noise, ``a = 0``); then the
    Laplace Gaussian times the prior by a QR factorisation of the stacked
    ``(2 N + 2) x (N + 2)`` system, mapped to frame ``N``. Its cost grows like
    ``N**3``: the independent route that the block-tridiagonal solver is
    checked against.

    Parameters
    ----------
    mu : array_like, shape (N,)
    rho : float
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    process_noise : float

    Returns
    -------
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
    """
    mu = np.asarray(mu, dtype=float)
    n_frames = mu.shape[-1]
    penalty = np.zeros((n_frames - 1, n_frames + 2))
    penalty[:, 3:] = np.eye(n_frames - 1) / process_noise

    def stacked(z):
        r, J = bearing_residuals(z, mu, trajectory_map(mu.shape[-1]))
        return np.concatenate([r / rho, z[3:] / process_noise]), np.concatenate([J / rho, penalty])

    def objective(z):
        return float(np.sum(stacked(z)[0] ** 2)) if z[1] > 0 else np.inf

    start = model.G(minimiser(mu[None])[0], 1 - n_frames)
    z, _, converged = _dense_gauss_newton(
        np.concatenate([start, np.zeros(n_frames - 1)]),
        stacked,
        objective,
        200,
        1e-11,
        lambda new, old, M: np.max(np.abs(new - old) / (1.0 + np.abs(old))),
    )
    if not converged:
        raise ValueError("the dense Gauss-Newton did not converge")
    _, M = stacked(z)
    prior_rows = np.zeros((3, n_frames + 2))
    prior_rows[:, :3] = np.linalg.inv(np.linalg.cholesky(prior_cov))
    K = np.concatenate([M, prior_rows])
    rhs = np.concatenate([M @ z, prior_rows[:, :3] @ np.asarray(prior_mean, dtype=float)])
    Q, R = np.linalg.qr(K)
    R_inv = np.linalg.inv(R)
    T, offset = _dense_final_state_map(n_frames)
    cov = T @ R_inv @ R_inv.T @ T.T
    return T @ (R_inv @ (Q.T @ rhs)) + offset, symmetric(cov)


def iterated_smoother_dense(mu, rho: float, prior_mean, prior_cov, process_noise: float):
    """:func:`depthcore.kalman.iterated.smoother` with process noise for one sequence, densely.

    Gauss-Newton on the stacked whitened residuals of the prior, the bearings
    and the accelerations over ``z = (x_1, y_1, v_1, a_1 .. a_{K-1})`` from
    ``(m, 0)``, each step a least-squares solve of the full Jacobian, stopped
    when ``|M step| <= 1e-12``; the covariance at frame ``K`` is
    ``T (M^T M)^{-1} T^T`` from a QR factorisation of ``M``. Its cost grows like
    ``K**3``.

    Returns
    -------
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
    iterations : int
    """
    mu = np.asarray(mu, dtype=float)
    m = np.asarray(prior_mean, dtype=float)
    K = mu.shape[-1]
    L_inv = np.linalg.inv(np.linalg.cholesky(prior_cov))

    def stacked(z):
        bearing, J = bearing_residuals(z, mu, trajectory_map(mu.shape[-1]))
        M = np.zeros((2 * K + 2, K + 2))
        M[:3, :3] = L_inv
        M[3 : K + 3] = J / rho
        M[K + 3 :, 3:] = np.eye(K - 1) / process_noise
        return np.concatenate([L_inv @ (z[:3] - m), bearing / rho, z[3:] / process_noise]), M

    def objective(z):
        return float(np.sum(stacked(z)[0] ** 2)) if z[1] > 0 else np.inf

    z, iterations, _ = _dense_gauss_newton(
        np.concatenate([m, np.zeros(K - 1)]),
        stacked,
        objective,
        100,
        1e-12,
        lambda new, old, M: np.linalg.norm(M @ (new - old)),
    )
    _, M = stacked(z)
    R_inv = np.linalg.inv(np.linalg.qr(M, mode="r"))
    T, offset = _dense_final_state_map(K)
    cov = T @ R_inv @ R_inv.T @ T.T
    return T @ z + offset, symmetric(cov), iterations
