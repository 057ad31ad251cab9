"""The iterated EKF and the iterated extended Kalman smoother on the paper's problem.

Recommended import: ``from depthcore.kalman import iterated``.

The EKF linearises the projection ``x / y`` at the predicted mean ``n``,
Eq. (11), once. Where the prediction is poor, so is the linearisation. The
textbook (Prince, section 19.3 [prince2012]_) names two remedies:

* **The iterated EKF** relinearises each measurement update at the refined
  estimate: starting from ``x_0 = n``,

      x_{i+1} = n + K_i (mu - h(x_i) - H_i (n - x_i)),
      K_i = C H_i^T / (rho**2 + H_i C H_i^T),

  with ``H_i`` the gradient of Eq. (11) at ``x_i``. This is Gauss-Newton on
  ``|x - n|_C**2 + (mu - h(x))**2 / rho**2``, so its fixed point is the mode
  of the one-step posterior ``N(x; n, C) p(mu | x)`` [bell1993]_; the first
  iterate is the EKF's update, Eq. (12). The covariance is the Joseph form of
  Eq. (12) with the gain and gradient of the last linearisation (at
  convergence, those at the mode).
* **The iterated extended Kalman smoother** makes several passes over all the
  bearings, relinearising every measurement about the previous pass's
  smoothed states. With no process noise the motion is deterministic, so the
  whole trajectory is ``G^{k-1} x_1`` and each pass is one Gauss-Newton step
  on the negative log posterior of ``x_1``::

      |x_1 - m|_P**2 + sum_k (mu_k - h(G^{k-1} x_1))**2 / rho**2,

  whose fixed point is the mode of the optimal posterior, Eq. (6), moved to
  the last frame; its covariance, ``(P^{-1} + sum_k J_k^T J_k / rho**2)^{-1}``
  at the mode, is a Laplace (Gauss-Newton) approximation there. The paper's
  ``p_s`` is the same kind of approximation taken at the noise-free solution
  ``c`` instead of at the mode, with the likelihood's and the prior's
  Gaussians multiplied. With process noise the unknowns are the whole
  trajectory, the accelerations among them with their prior ``N(0, q**2)``
  (:func:`smoother`), and the fixed point is the mode of the trajectory's
  posterior.

Both iterations are damped only where they must be: a step that would put the
point behind the camera (depth ``<= 0`` at some frame), or that would increase
the objective, is halved until it does neither.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.3.
.. [bell1993] B. M. Bell and F. W. Cathey, "The iterated Kalman filter update
   as a Gauss-Newton method", IEEE Trans. Automatic Control 38(2), 1993.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.kalman import linear
from depthcore.kalman.ekf import linearised_predictive, predict
from depthcore.kalman.second_order import (
    bearing_rows,
    damped_step,
    trajectory_solve,
    trajectory_states,
)
from depthcore.problem import checks, model, predictive, signature
from depthcore.problem.gaussian import History, checked_track, run_recursion, symmetric

#: Largest number of Gauss-Newton iterations of one update or smoother.
MAX_ITERATIONS = 100
#: Iterations stop when a step changes the state by less than this, in SDs, or when a step
#: no longer lowers the objective: the iterate is then the mode to within the objective's
#: rounding (about ``sqrt(eps f)`` SDs for an objective ``f`` and the doubles' ``eps``), where
#: steps back and forth by a unit in the last place can still be more than ``STEP_TOL`` SDs.
STEP_TOL = 1e-12


def still_descending(moved, f_new, f) -> np.ndarray:
    """Whether a Gauss-Newton iteration goes on after a step (the rule of :data:`STEP_TOL`).

    Parameters
    ----------
    moved : ndarray, shape (...)
        The step's length, in SDs of the state.
    f_new, f : ndarray, shape (...)
        The objective after the step and before it.

    Returns
    -------
    ndarray of bool, shape (...)
        True where the step moved the state by more than :data:`STEP_TOL` SDs and
        lowered the objective.
    """
    return (moved > STEP_TOL) & (f_new < f)


class IteratedUpdate(NamedTuple):
    """An iterated measurement update: the mean, its covariance and the iterations used."""

    mean: np.ndarray
    cov: np.ndarray
    iterations: np.ndarray


def _objective(x, n, C_chol, mu, r2):
    """``|x - n|_C**2 + (mu - x1/x2)**2 / rho**2``, shape x.shape[:-1].

    ``inf`` behind the camera.
    """
    z = np.linalg.solve(C_chol, (x - n)[..., None])[..., 0]
    front = x[..., 1] > 0
    safe = np.where(front[..., None], x, 1.0)
    r = mu - model.project(safe)
    return np.where(front, np.sum(z**2, axis=-1) + r**2 / r2, np.inf)


def update(n, C, mu, rho, max_iterations: int = MAX_ITERATIONS) -> IteratedUpdate:
    """The iterated EKF's measurement update of the prediction ``(n, C)`` by ``mu``, batched.

    Parameters
    ----------
    n : array_like, shape (..., 3)
        Predicted mean; its depth must be positive.
    C : array_like, shape (..., 3, 3)
        Predicted covariance, symmetric positive definite.
    mu : array_like, shape (...)
    rho : float or array_like, shape (...)
        Noise standard deviation, > 0.
    max_iterations : int
        ``1`` gives the EKF's update, Eq. (12).

    Returns
    -------
    IteratedUpdate
        The mode of ``N(x; n, C) p(mu | x)`` (when the iteration converges),
        the Joseph-form covariance at it, and the iterations each used.
    """
    n = np.asarray(n, dtype=float)
    C = np.asarray(C, dtype=float)
    _check_depth(n)
    mu = np.broadcast_to(np.asarray(mu, dtype=float), n.shape[:-1])
    r2 = np.broadcast_to(np.asarray(rho, dtype=float) ** 2, n.shape[:-1])
    C_chol = np.linalg.cholesky(C)
    x = n.copy()
    f = _objective(x, n, C_chol, mu, r2)
    iterations = np.zeros(n.shape[:-1], dtype=int)
    active = np.ones(n.shape[:-1], dtype=bool)
    linearised_at = x.copy()
    for _ in range(max_iterations):
        if not np.any(active):
            break
        linearised_at = np.where(active[..., None], x, linearised_at)
        h = model.observation_vector(x)  # Eq. (11) at the current iterate
        Ch = np.einsum("...ij,...j->...i", C, h)
        s = r2 + np.einsum("...i,...i->...", h, Ch)
        residual = mu - model.project(x) - np.einsum("...i,...i->...", h, n - x)
        target = n + (residual / s)[..., None] * Ch
        x_new, f_new = damped_step(x, target - x, f, lambda y: _objective(y, n, C_chol, mu, r2))
        iterations = iterations + active
        z = np.linalg.solve(C_chol, (x_new - x)[..., None])[..., 0]
        moved = np.sqrt(np.sum(z**2, axis=-1))
        x = np.where(active[..., None], x_new, x)
        active = active & still_descending(moved, f_new, f)
        f = np.where(active, f_new, f)
    # The gain of the last linearisation (at convergence, the gradient at the mode itself).
    h = model.observation_vector(linearised_at)
    Ch = np.einsum("...ij,...j->...i", C, h)
    K = Ch / (r2 + np.einsum("...i,...i->...", h, Ch))[..., None]
    cov = linear.joseph(C, K[..., :, None], h[..., None, :], r2[..., None, None])
    return IteratedUpdate(x, cov, iterations)


def _check_depth(n) -> None:
    if not np.all(n[..., 1] > 0):
        raise ValueError(
            "prior_mean leads the iterated EKF to a predicted depth n2 <= 0 "
            f"(min {float(np.min(n[..., 1])):.6g}); the projection x/y is not defined there"
        )


def bearing_predictive(n, C, rho) -> tuple[np.ndarray, np.ndarray]:
    """The predictive density of a bearing, linearised at the prediction as the EKF's.

    ``N(n1 / n2, h^T C h + rho**2)`` with ``h`` from Eq. (11) at ``n``: the
    first iterate's linearisation, before the bearing is seen. Parameters and
    returns as for :func:`depthcore.kalman.ekf.bearing_predictive`.
    """
    n = np.asarray(n, dtype=float)
    _check_depth(n)
    return linearised_predictive(n, model.observation_vector(n), C, rho)


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    max_iterations: int = MAX_ITERATIONS,
    steps=None,
    gate=None,
) -> History:
    """The iterated EKF over ``K`` bearings, batched.

    Initialise with the prior, apply the iterated update to ``mu_1``, then
    predict (Eq. (10) over the step, plus the process noise ``q**2 s`` on the
    velocity) and update for each further frame; a missing bearing (``NaN``)
    or one the gate skips is not incorporated, row by row
    (:func:`depthcore.problem.gaussian.run_recursion`). The predictive density
    of each bearing is the EKF's at the prediction (:func:`bearing_predictive`).

    {parameters}
    max_iterations : int

    Returns
    -------
    History
        ``means`` (..., K, 3), ``means[..., k, :]`` the mean after frame
        ``k + 1``; ``covs`` (..., K, 3, 3); ``updates`` (..., K). It unpacks as
        ``means, covs = run(...)``.
    """
    track = checked_track(mu, rho, prior_mean, prior_cov, steps, triples=False)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    g = predictive.gate(gate)
    f = track.frames
    regular = f.regular
    Q = np.diag([0.0, 0.0, q**2])

    def predict_k(m, P, k):
        if regular:
            n, C = predict(m, P)
            return n, C + Q
        return predict(m, P, q, f.steps[..., k - 2])

    def update_k(n, C, mu_k, k):
        try:
            m, P, _ = update(n, C, mu_k, f.rho[..., k - 1], max_iterations)
        except np.linalg.LinAlgError:
            raise ValueError(
                f"mu and rho lead the iterated EKF to a covariance that is not positive "
                f"definite at bearing {k}: a rho tiny beside the prior loses it to "
                "rounding, or the linearisations drift too far apart"
            ) from None
        return m, P

    return run_recursion(
        track.mean,
        track.cov,
        f.mu,
        predict_k,
        update_k,
        f.present,
        lambda n, C, k: bearing_predictive(n, C, f.rho[..., k - 1]),
        g,
    )


def _residuals_and_jacobian(x1, K: int):
    """Bearings of ``G^k x1`` for ``k < K`` and their gradients with respect to ``x1``.

    Returns ``h`` of shape (..., K) and ``J`` of shape (..., K, 3): the chain
    rule through ``G^k``, whose linear part is ``F^k``, of Eq. (11).
    """
    states = np.stack([model.G(x1, k) for k in range(K)], axis=-2)
    grads = model.observation_vector(states)  # (..., K, 3)
    J = grads.copy()
    J[..., 2] = grads[..., 0] * np.arange(K)  # d(x + k v)/dv = k
    return model.project(states), J


class SmootherResult(NamedTuple):
    """The iterated extended Kalman smoother's estimate of the state at the last frame.

    ``mean`` (..., 3) and ``cov`` (..., 3, 3) at frame ``K``; ``iterations``
    and ``converged`` (...) of the Gauss-Newton passes; ``trajectory``
    (..., K, 3), the smoothed states at every frame (the posterior's mode).
    """

    mean: np.ndarray
    cov: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    trajectory: np.ndarray | None = None


def smoother(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    max_iterations: int = MAX_ITERATIONS,
) -> SmootherResult:
    """The iterated extended Kalman smoother (textbook 19.3), batched.

    Gauss-Newton passes over all ``K`` bearings, each relinearising every
    measurement about the current trajectory, starting from the prior mean.
    With no process noise the trajectory is ``G^{k-1} x_1`` (see the module
    docstring). With process noise ``q > 0`` the unknowns are the whole
    trajectory, ``z = (x_1, y_1, v_1, a_1 .. a_{K-1})`` with the accelerations'
    prior ``N(0, q**2)``, and each pass is one Gauss-Newton step on::

        |L^{-1} (x_1 - m)|**2 + sum_k (mu_k - x_k / y_k)**2 / rho**2 + sum_k a_k**2 / q**2

    (``P = L L^T``), the stacked whitened residuals of the prior, the bearings
    and the accelerations; one such step is one linearised Rauch-Tung-Striebel
    smoothing pass about the previous smoothed trajectory [bell1994]_. Its
    fixed point is the mode (MAP) of the trajectory's posterior; the
    covariance at frame ``K`` is the Gauss-Newton (Laplace) one there,
    ``T (M^T M)^{-1} T^T`` with ``M`` the stacked Jacobian and ``T`` the
    linear map from ``z`` to the state at frame ``K``.

    Parameters
    ----------
    mu : array_like, shape (..., K)
        Bearings in time order, ``K >= 1``.
    rho : float or array_like, shape (...)
    prior_mean : array_like, shape (..., 3)
        Prior mean of the state at time 1; its depth must be positive.
    prior_cov : array_like, shape (3, 3)
    process_noise : float
        ``q >= 0``, the SD of the velocity's change per frame.
    max_iterations : int

    Returns
    -------
    SmootherResult
        Mean (..., 3) and covariance (..., 3, 3) of the state at frame ``K``:
        the mode of the posterior and the Gauss-Newton covariance there; the
        smoothed trajectory (..., K, 3).

    References
    ----------
    .. [bell1994] B. M. Bell, "The iterated Kalman smoother as a Gauss-Newton
       method", SIAM J. Optimization 4(3), 1994.
    """
    mu = checks.finite_array(mu, "mu")
    if mu.ndim < 1 or mu.shape[-1] < 1:
        raise ValueError(f"mu must have shape (..., K) with K >= 1, got shape {mu.shape}")
    K = mu.shape[-1]
    batch = mu.shape[:-1]
    rho = np.broadcast_to(checks.positive_array(rho, "rho"), batch)
    m = np.broadcast_to(checks.finite_array(prior_mean, "prior_mean"), batch + (3,))
    if not np.all(m[..., 1] > 0):
        raise ValueError("prior_mean must have a positive depth to start the smoother from it")
    P = checks.covariance(prior_cov, "prior_cov", 3)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    if q > 0:
        return _smoother_with_noise(mu, rho, m, P, q, max_iterations)
    P_chol = np.linalg.cholesky(P)
    P_inv = np.linalg.inv(P)

    def objective(x1):
        z = np.linalg.solve(P_chol, (x1 - m)[..., None])[..., 0]
        front = x1[..., 1] > 0
        h, _ = _residuals_and_jacobian(np.where(front[..., None], x1, 1.0), K)
        r = (mu - h) / rho[..., None]
        return np.where(front, np.sum(z**2, axis=-1) + np.sum(r**2, axis=-1), np.inf)

    x = m.copy()
    f = objective(x)
    iterations = np.zeros(batch, dtype=int)
    active = np.ones(batch, dtype=bool)
    for _ in range(max_iterations):
        if not np.any(active):
            break
        h, J = _residuals_and_jacobian(x, K)
        Jw = J / rho[..., None, None]
        A = P_inv + np.swapaxes(Jw, -1, -2) @ Jw
        g = np.einsum("...ij,...j->...i", P_inv, x - m) - np.einsum(
            "...ki,...k->...i", Jw, (mu - h) / rho[..., None]
        )
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        x_new, f_new = damped_step(x, step, f, objective)
        iterations = iterations + active
        moved = np.sqrt(np.abs(np.einsum("...i,...ij,...j->...", x_new - x, A, x_new - x)))
        x = np.where(active[..., None], x_new, x)
        active = active & still_descending(moved, f_new, f)
        f = np.where(active, f_new, f)
    _, J = _residuals_and_jacobian(x, K)
    Jw = J / rho[..., None, None]
    cov1 = np.linalg.inv(P_inv + np.swapaxes(Jw, -1, -2) @ Jw)
    FK = model.G_linear(K - 1)
    cov = FK @ cov1 @ FK.T
    trajectory = np.stack([model.G(x, k) for k in range(K)], axis=-2)
    return SmootherResult(model.G(x, K - 1), symmetric(cov), iterations, ~active, trajectory)


def _smoother_with_noise(mu, rho, m, P, q, max_iterations) -> SmootherResult:
    """:func:`smoother` for ``q > 0``: Gauss-Newton over the trajectory, problems side by side.

    Each step solves the linearised least-squares problem through the
    trajectory's block-tridiagonal structure
    (:func:`depthcore.kalman.second_order.trajectory_solve`), so its cost grows
    linearly with the frames; :func:`depthbook.reference.iterated_smoother_dense`
    solves the same problems densely.
    """
    K = mu.shape[-1]
    batch = mu.shape[:-1]
    mu = mu.reshape(-1, K)
    B = mu.shape[0]
    rho = np.broadcast_to(rho, batch).reshape(B)
    m = np.broadcast_to(m, batch + (3,)).reshape(B, 3)
    L_inv = np.broadcast_to(np.linalg.inv(np.linalg.cholesky(P)), (B, 3, 3))
    weight = 1.0 / rho

    def objective(z, rows):
        front = z[:, 1] > 0
        safe = np.where(front[:, None], z, 1.0)
        s = trajectory_states(safe)
        prior = np.einsum("bij,bj->bi", L_inv[rows], safe[:, :3] - m[rows])
        bearing = (model.project(s) - mu[rows]) * weight[rows, None]
        value = (
            np.sum(prior**2, axis=-1)
            + np.sum(bearing**2, axis=-1)
            + np.sum((safe[:, 3:] / q) ** 2, axis=-1)
        )
        return np.where(front, value, np.inf)

    z = np.concatenate([m, np.zeros((B, K - 1))], axis=-1)
    f = objective(z, np.arange(B))
    iterations = np.zeros(B, dtype=int)
    converged = np.zeros(B, dtype=bool)
    for _ in range(max_iterations):
        rows = np.flatnonzero(~converged)
        if rows.size == 0:
            break
        za = z[rows]
        s = trajectory_states(za)
        H = bearing_rows(s, weight[rows])
        step, _ = trajectory_solve(
            H,
            -(model.project(s) - mu[rows]) * weight[rows, None],
            -za[:, 3:] / q,
            q,
            L_inv[rows],
            -np.einsum("bij,bj->bi", L_inv[rows], za[:, :3] - m[rows]),
        )
        step = np.where(np.isfinite(step), step, 0.0)
        z_new, f_new = damped_step(za, step, f[rows], lambda y, rows=rows: objective(y, rows))
        iterations[rows] += 1
        dz = z_new - za
        d = trajectory_states(dz, offset=False)
        moved = np.sqrt(
            np.sum(np.einsum("bij,bj->bi", L_inv[rows], dz[:, :3]) ** 2, axis=-1)
            + np.sum(np.einsum("bki,bki->bk", H, d) ** 2, axis=-1)
            + np.sum((dz[:, 3:] / q) ** 2, axis=-1)
        )
        converged[rows] = ~still_descending(moved, f_new, f[rows])
        z[rows], f[rows] = z_new, f_new
    s = trajectory_states(z)
    zero = np.zeros((B, K))
    _, R = trajectory_solve(bearing_rows(s, weight), zero, zero[:, 1:], q, L_inv, np.zeros((B, 3)))
    R_inv = np.linalg.inv(R)
    cov = R_inv @ np.swapaxes(R_inv, -1, -2)
    return SmootherResult(
        s[:, -1].reshape(batch + (3,)),
        symmetric(cov).reshape(batch + (3, 3)),
        iterations.reshape(batch),
        converged.reshape(batch),
        s.reshape(batch + (K, 3)),
    )
