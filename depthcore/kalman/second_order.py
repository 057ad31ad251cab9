"""The second-order approximation p_s, Eqs. (8) and (24).

Recommended import: ``from depthcore.kalman import second_order``.

The second-order filter replaces ``f`` in the optimal posterior (6) by its
quadratic Taylor expansion about the noise-free state ``c``, where ``f`` and its
gradient vanish. Since ``f = sum_k r_k**2`` with residuals ``r_k`` that vanish
at ``c``, its Hessian there is ``J = 2 sum_k g_k g_k^T`` (``g_k`` the gradient of
``r_k``), and

    exp(-f / (2 rho**2)) ~ exp(-(x - c)^T J (x - c) / (4 rho**2)) = N(x, c, 2 rho**2 J^{-1})

up to a constant. The paper prints ``rho**2 J^{-1}``; ``reading="printed"``
follows the print, ``reading="derived"`` (the default) the expansion.

N frames (the model of :mod:`depthcore.exact.bank`). With ``N > 3`` bearings and no
process noise, ``f`` over all ``N`` residuals no longer vanishes anywhere: the
Gaussian is centred on its minimiser ``c_N`` at frame ``N`` (:func:`minimiser`),
where ``J_r^T r = 0`` (``J_r`` the residuals' Jacobian,
:func:`depthcore.problem.model.residual_gradients`), so ``f(c_N + d) ~ f(c_N) +
|J_r d|**2`` and the likelihood is ``N(x, c_N, rho**2 (J_r^T J_r)^{-1})``,
multiplied by the prior as ``p_s`` is, Eq. (8). At ``N = 3``, ``c_N = c``
(``f(c) = 0``, Eq. (7)) and this is ``p_s``.

With process noise ``a_k ~ N(0, q**2)`` on the velocity the unknowns are the
whole trajectory: the state at frame 1 and the accelerations
``a_1 .. a_{N-1}``, on which every state is affine. The Laplace (Gauss-Newton)
approximation of ``p(mu | x_1, a) p(a)`` at its maximiser (the minimiser of
``sum_k r_k**2 / rho**2 + sum_k a_k**2 / q**2``) is multiplied by the prior on
``x_1`` and marginalised to the state at frame ``N``
(:func:`trajectory_laplace`). As ``q -> 0`` the penalty pins the
accelerations at 0 and it tends to the approximation without process noise.
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks, frames, model, signature
from depthcore.problem.gaussian import Gaussian, MeanAndCov, symmetric
from depthcore.problem.model import (
    noise_free_state,
    noise_free_states,
    residual_gradients,
    residuals,
)

__all__ = [
    "A2",
    "CONDITION_LIMIT",
    "MAX_ITERATIONS",
    "READINGS",
    "STEP_TOL",
    "b2",
    "bearing_rows",
    "damped_step",
    "hessian",
    "likelihood_covariance",
    "run",
    "minimiser",
    "paper_frames",
    "second_order_batch",
    "theorem1_precision",
    "trajectory_laplace",
    "trajectory_solve",
    "trajectory_states",
]

READINGS = ("derived", "printed")


def cho_factor(a):
    """:func:`scipy.linalg.cho_factor`, imported when first needed."""
    from scipy.linalg import cho_factor as factor

    return factor(a)


def cho_solve(factor, b):
    """:func:`scipy.linalg.cho_solve`, imported when first needed."""
    from scipy.linalg import cho_solve as solve

    return solve(factor, b)


#: Linear and constant parts of ``G^{-2}``: ``G^{-2} x = A2 x + b2``.
A2 = model.G_linear(-2)
b2 = np.array([0.0, -2.0, 0.0])


def hessian(mu) -> np.ndarray:
    """Eq. (8): ``J``, the Hessian of ``f`` at the noise-free state ``c``.

    At ``c`` every residual vanishes, so ``J = 2 sum_k g_k g_k^T`` exactly.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    g = residual_gradients(noise_free_state(mu))
    return 2.0 * g.T @ g


def likelihood_covariance(mu, rho: float, reading: str = "derived") -> np.ndarray:
    """Eq. (8): covariance of the Gaussian that replaces ``exp(-f / (2 rho**2))``.

    ``2 rho**2 J^{-1}`` for ``reading="derived"``, ``rho**2 J^{-1}`` for ``"printed"``.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    rho = checks.positive_scalar(rho, "rho")
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    J = hessian(mu)
    return factor * rho**2 * np.linalg.inv(J)


@signature.documented
def second_order_batch(
    mu, rho: float, prior_mean, prior_cov, reading: str = "derived", process_noise: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (8) for a batch: means ``(B, 3)`` and covariances ``(B, 3, 3)`` at frame ``N``.

    ``p_s`` for triples; for ``N > 3`` or ``q > 0``, see the module docstring.

    {parameters}
    reading : {"derived", "printed"}
    {process_noise}
    """
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    mu, rho, prior_mean, prior_cov = model.batch_problem(mu, rho, prior_mean, prior_cov)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    if mu.ndim != 2:
        raise ValueError(f"mu must have shape (B, N), got shape {mu.shape}")
    B, n_frames = mu.shape
    weight = np.sqrt(2.0 / factor) / np.broadcast_to(rho, (B,))
    if q > 0:
        return trajectory_laplace(mu, weight, prior_mean, prior_cov, q)
    if n_frames == 3:
        c = noise_free_states(mu)
        g = np.stack(
            [model.observation_vector(model.G(c, k - 2)) @ model.G_linear(k - 2) for k in range(3)],
            axis=-2,
        )  # (B, 3, 3), rows in time order
    else:
        c = minimiser(mu)
        g = residual_gradients(c, n_frames)  # (B, N, 3)
    return _square_root_solve(c, g, weight, prior_mean, prior_cov)


#: Gauss-Newton iterations of :func:`minimiser` and :func:`trajectory_laplace`.
MAX_ITERATIONS = 200
#: Gauss-Newton stops when no component moves by more than this, relative to ``1 + |x|``.
STEP_TOL = 1e-11
#: A minimiser whose scaled residual Jacobian has a larger condition number is refused.
CONDITION_LIMIT = 1e12
#: Depths at frame 1 of the coarse profile that starts :func:`minimiser`.
_PROFILE_DEPTHS = np.geomspace(1e-2, 1e5, 60)
_MAX_HALVINGS = 60


def _frames_back(n_frames: int) -> np.ndarray:
    """``k - N + 1`` for ``k = 0 .. N - 1``: each frame's offset from the last."""
    return np.arange(n_frames) - (n_frames - 1.0)


def _misfit(x, mu) -> np.ndarray:
    """``f`` of Eq. (5) over all ``N`` bearings at last-frame states ``x`` (B, M, 3), shape (B, M).

    ``inf`` where the depth at frame 1 is not positive.
    """
    n_frames = mu.shape[-1]
    front = x[..., 1] - (n_frames - 1) > 0
    safe = np.where(front[..., None], x, [0.0, float(n_frames), 0.0])
    back = _frames_back(n_frames)
    bearing = (safe[..., None, 0] + back * safe[..., None, 2]) / (safe[..., None, 1] + back)
    return np.where(front, np.sum((bearing - mu[:, None, :]) ** 2, axis=-1), np.inf)


def _starts(mu) -> np.ndarray:
    """Candidate last-frame states (B, M, 3) for :func:`minimiser`.

    The noise-free solutions, Eq. (7), of frames 1-3 and ``N-2 .. N`` moved to
    frame ``N``, and at each depth of a coarse grid the least-squares
    ``(x, v)`` (at a fixed depth the bearings are linear in them).
    """
    n_frames = mu.shape[-1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        first = model.G(model.noise_free_states_unchecked(mu[:, :3]), n_frames - 3)
        last = model.noise_free_states_unchecked(mu[:, -3:])
    back = _frames_back(n_frames)
    y_last = _PROFILE_DEPTHS + (n_frames - 1)
    yk = y_last[:, None] + back  # (G, N) depths at each frame
    A = np.stack([1.0 / yk, back / yk], axis=-1)  # bearings = A @ (x_N, v)
    xv = np.einsum("gij,bj->bgi", np.linalg.pinv(A), mu)  # (B, G, 2)
    grid = np.stack([xv[..., 0], np.broadcast_to(y_last, xv.shape[:-1]), xv[..., 1]], axis=-1)
    out = np.concatenate([first[:, None], last[:, None], grid], axis=1)
    return np.where(np.isfinite(out), out, 0.0)


def minimiser(mu) -> np.ndarray:
    """The minimiser over the state at frame ``N`` of ``f = sum_k r_k**2``, batched.

    Gauss-Newton (QR steps, :func:`damped_step`) from the best of :func:`_starts`,
    the point kept in front of the camera at frame 1.

    Parameters
    ----------
    mu : ndarray, shape (B, N)
        Bearings, ``N >= 3``, already checked.

    Returns
    -------
    ndarray, shape (B, 3)
        ``c_N``; for ``N = 3`` the noise-free state ``c`` of Eq. (7) up to rounding.

    A :class:`ValueError` names ``mu[i]`` when no start lies in front of the
    camera, when the iteration does not converge in :data:`MAX_ITERATIONS`
    steps, or when the minimiser is not determined (the residual Jacobian's
    condition number, columns scaled to unit norm, exceeds :data:`CONDITION_LIMIT`).
    """
    mu = np.asarray(mu, dtype=float)
    B, n_frames = mu.shape
    starts = _starts(mu)
    f0 = _misfit(starts, mu)
    x = np.take_along_axis(starts, np.argmin(f0, axis=1)[:, None, None], axis=1)[:, 0]
    f = np.min(f0, axis=1)
    if not np.all(np.isfinite(f)):
        i = int(np.argmax(~np.isfinite(f)))
        raise ValueError(f"mu[{i}]: no start in front of the camera for the misfit's minimiser")
    active = np.ones(B, dtype=bool)
    # A run sent far out, where the gradients overflow, does not converge: refused below.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for _ in range(MAX_ITERATIONS):
            if not np.any(active):
                break
            r = residuals(x, mu)
            J = residual_gradients(x, n_frames)
            step = _lstsq(J, -r)
            x_new, f_new = damped_step(x, step, f, lambda y: _misfit(y[:, None], mu)[:, 0])
            moved = np.max(np.abs(x_new - x) / (1.0 + np.abs(x)), axis=-1)
            x = np.where(active[:, None], x_new, x)
            f = np.where(active, f_new, f)
            active = active & ~(moved <= STEP_TOL)
    active |= ~np.all(np.isfinite(x), axis=-1)
    if np.any(active):
        raise ValueError(
            f"mu[{int(np.argmax(active))}]: Gauss-Newton on the misfit of the bearings did not "
            f"converge in {MAX_ITERATIONS} iterations"
        )
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        J = residual_gradients(x, n_frames)
    _determined(J, "the misfit of the bearings")
    return x


def _lstsq(J, r) -> np.ndarray:
    """Least-squares solutions ``d`` of ``J d = r`` by QR, batched: J (B, M, n), r (B, M)."""
    finite = np.all(np.isfinite(J), axis=(-2, -1)) & np.all(np.isfinite(r), axis=-1)
    J = np.where(finite[:, None, None], J, 0.0)
    r = np.where(finite[:, None], r, 0.0)
    Q, R = np.linalg.qr(J)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        try:
            d = np.linalg.solve(R, np.einsum("bmi,bm->bi", Q, r)[..., None])[..., 0]
        except np.linalg.LinAlgError:
            # an exactly singular R (a run gone where the gradients vanish or
            # overflowed): the pseudo-inverse, whose step such a run cannot use
            d = np.einsum("bim,bm->bi", np.linalg.pinv(J), r)
    return np.where(finite[:, None] & np.isfinite(d), d, 0.0)


def _determined(J, what: str) -> None:
    """Refuse, naming ``mu[i]``, a Jacobian whose columns are (numerically) dependent."""
    finite = np.all(np.isfinite(J), axis=(-2, -1))
    J = np.where(finite[..., None, None], J, 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.linalg.norm(J, axis=-2, keepdims=True)
        scale = np.where((scale > 0) & np.isfinite(scale), scale, 1.0)
        cond = np.where(finite, np.linalg.cond(J / scale), np.inf)
    bad = ~(cond < CONDITION_LIMIT)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ValueError(
            f"mu[{i}] does not determine the minimiser of {what}: the Jacobian's condition "
            f"number is {float(cond[i]):.3g}"
        )


def damped_step(x, step, f, objective):
    """``x + t step`` with ``t`` halved from 1 until the objective does not increase.

    Here and in :mod:`depthcore.kalman.iterated`: ``x`` (..., d) and ``f`` (...)
    the current points and values, ``step`` (..., d), ``objective`` points to
    values. Returns the new points and values (``x``, ``f`` where no halving helps).
    """
    t = np.ones(x.shape[:-1])
    x_new = x + step
    f_new = objective(x_new)
    for _ in range(_MAX_HALVINGS):
        bad = ~(f_new <= f)
        if not np.any(bad):
            break
        t = np.where(bad, 0.5 * t, t)
        trial = x + t[..., None] * step
        x_new = np.where(bad[..., None], trial, x_new)
        f_new = np.where(bad, objective(trial), f_new)
    keep = ~(f_new <= f)
    return np.where(keep[..., None], x, x_new), np.where(keep, f, f_new)


def trajectory_map(frames: int) -> np.ndarray:
    """The map of the accelerations to the lateral positions, Eq. (1) with process noise.

    ``x_k = x_1 + (k - 1) v_1 + sum_i D[k-1, i-1] a_i`` with
    ``D[k-1, i-1] = max(k - 1 - i, 0)``: acceleration ``a_i`` changes ``v_{i+1}`` onwards.

    Parameters
    ----------
    frames : int
        ``N``.

    Returns
    -------
    ndarray, shape (N, N - 1)
    """
    k = np.arange(frames)[:, None]
    i = np.arange(1, frames)[None, :]
    return np.maximum(k - i, 0).astype(float)


def bearing_residuals(z, mu, D):
    """The bearings' residuals ``x_k / y_k - mu_k`` of a trajectory and their Jacobian, Eq. (4).

    Parameters
    ----------
    z : ndarray, shape (N + 2,)
        The trajectory ``(x_1, y_1, v_1, a_1 .. a_{N-1})``.
    mu : ndarray, shape (N,)
        The bearings.
    D : ndarray, shape (N, N - 1)
        :func:`trajectory_map` of ``N``.

    Returns
    -------
    residuals : ndarray, shape (N,)
    jacobian : ndarray, shape (N, N + 2)
        Their derivatives with respect to ``z``.
    """
    n_frames = mu.shape[-1]
    j = np.arange(n_frames, dtype=float)
    x = z[0] + j * z[2] + D @ z[3:]
    y = z[1] + j
    J = np.empty((n_frames, n_frames + 2))
    J[:, 0] = 1.0 / y
    J[:, 1] = -x / y**2
    J[:, 2] = j / y
    J[:, 3:] = D / y[:, None]
    return x / y - mu, J


def trajectory_states(z, offset: bool = True) -> np.ndarray:
    """The states ``(x_k, y_k, v_k)`` of a trajectory ``z = (x_1, y_1, v_1, a_1 .. a_{N-1})``.

    ``v_k = v_1 + sum_{i < k} a_i``, ``x_{k+1} = x_k + v_k``, ``y_k = y_1 + k - 1``
    (Eq. (1) with accelerations). ``offset=False`` leaves out the ``+ k - 1``,
    mapping increments of ``z`` to increments of the states.

    Parameters
    ----------
    z : ndarray, shape (..., N + 2)
    offset : bool

    Returns
    -------
    ndarray, shape (..., N, 3)
    """
    z = np.asarray(z, dtype=float)
    n_frames = z.shape[-1] - 2
    zero = np.zeros(z.shape[:-1] + (1,))
    v = z[..., 2:3] + np.concatenate([zero, np.cumsum(z[..., 3:], axis=-1)], axis=-1)
    x = z[..., 0:1] + np.concatenate([zero, np.cumsum(v[..., :-1], axis=-1)], axis=-1)
    y = np.broadcast_to(z[..., 1:2], v.shape)
    if offset:
        y = y + np.arange(n_frames)
    return np.stack([x, y, v], axis=-1)


def trajectory_solve(H, y, t, process_noise: float, U=None, u=None):
    """Least squares over a trajectory, frame by frame: a square-root information smoother.

    Minimises, over increments ``d_k`` (3,) of the states at frames
    ``k = 1 .. N`` and ``b_k`` of the accelerations, tied by the motion
    ``d_{k+1} = F d_k + (0, 0, b_k)`` (Eq. (1), ``F`` its linear part),

        sum_k (H_k . d_k - y_k)**2 + sum_k (b_k / q - t_k)**2 + norm(U d_1 - u)**2

    (the last term only when ``U`` is given), as the square-root information
    filter does (textbook 19.2, in information form): at each frame one QR of a
    5 x 5 matrix eliminates the acceleration and the previous state, then a back
    substitution recovers every increment, in ``O(N)``.

    Parameters
    ----------
    H : ndarray, shape (B, N, 3)
        The rows of the measurement terms.
    y : ndarray, shape (B, N)
        Their targets.
    t : ndarray, shape (B, N - 1)
        The targets of the acceleration terms.
    process_noise : float
        ``> 0``, the accelerations' scale.
    U : ndarray, shape (B, 3, 3), optional
        Rows on ``d_1`` (a whitened prior); ``None`` for none.
    u : ndarray, shape (B, 3), optional
        Their targets.

    Returns
    -------
    dz : ndarray, shape (B, N + 2)
        ``(d_1, b_1 .. b_{N-1})``; the increments of the states follow from
        :func:`trajectory_states` with ``offset=False``.
    R : ndarray, shape (B, 3, 3)
        Upper triangular: the square-root information of ``d_N`` given every
        term, so that its covariance is ``R^{-1} R^{-T}``. Entries of ``dz``
        that the terms do not determine are not finite.
    """
    B, n_frames = y.shape
    R = np.zeros((B, 3, 3)) if U is None else np.array(U, dtype=float)
    r = np.zeros((B, 3)) if u is None else np.array(u, dtype=float)
    first = np.concatenate(
        [
            np.concatenate([R, r[..., None]], axis=-1),
            np.concatenate([H[:, :1], y[:, :1, None]], -1),
        ],
        axis=1,
    )
    top = np.linalg.qr(first, mode="r")
    R, r = top[:, :3, :3], top[:, :3, 3]
    rows = np.empty((B, max(n_frames - 1, 0), 5))
    A = np.zeros((B, 5, 5))
    for k in range(1, n_frames):
        # R d_{k-1} = r with d_{k-1} = F^{-1} (d_k - (0, 0, b)): the columns of R F^{-1}
        # are R's, with the third less the first; the term in b is R F^{-1} (0, 0, 1).
        A[:, 0, :] = 0.0
        A[:, 0, 0] = 1.0 / process_noise
        A[:, 0, 4] = t[:, k - 1]
        A[:, 1:4, 1:3] = R[..., :2]
        A[:, 1:4, 3] = R[..., 2] - R[..., 0]
        A[:, 1:4, 0] = -A[:, 1:4, 3]
        A[:, 1:4, 4] = r
        A[:, 4, 0] = 0.0
        A[:, 4, 1:4] = H[:, k]
        A[:, 4, 4] = y[:, k]
        top = np.linalg.qr(A, mode="r")
        rows[:, k - 1] = top[:, 0]
        R, r = top[:, 1:4, 1:4], top[:, 1:4, 4]
    dz = np.empty((B, n_frames + 2))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d = _upper_solve(R, r)
        for k in range(n_frames - 1, 0, -1):
            row = rows[:, k - 1]
            b = (row[:, 4] - np.einsum("bi,bi->b", row[:, 1:4], d)) / row[:, 0]
            dz[:, k + 2] = b
            w = d[:, 2] - b  # d_{k-1} = F^{-1} (d_k - (0, 0, b))
            d = np.stack([d[:, 0] - w, d[:, 1], w], axis=-1)
    dz[:, :3] = d
    return dz, R


def _upper_solve(R, r) -> np.ndarray:
    """``R^{-1} r`` for upper triangular ``R`` (B, 3, 3) by back substitution, r (B, 3)."""
    x2 = r[:, 2] / R[:, 2, 2]
    x1 = (r[:, 1] - R[:, 1, 2] * x2) / R[:, 1, 1]
    x0 = (r[:, 0] - R[:, 0, 1] * x1 - R[:, 0, 2] * x2) / R[:, 0, 0]
    return np.stack([x0, x1, x2], axis=-1)


def bearing_rows(states, weight) -> np.ndarray:
    """The rows of the bearings' terms in :func:`trajectory_solve`, shape (B, N, 3).

    ``weight`` (B,) times the gradients ``(1 / y, -x / y**2, 0)`` of ``x / y``,
    Eq. (11), at ``states`` (B, N, 3).
    """
    inv_y = 1.0 / states[..., 1]
    return weight[:, None, None] * np.stack(
        [inv_y, -states[..., 0] * inv_y**2, np.zeros_like(inv_y)], axis=-1
    )


def trajectory_laplace(mu, weight, prior_mean, prior_cov, process_noise: float):
    """The Laplace approximation of the trajectory's likelihood, times the prior, at frame ``N``.

    Gauss-Newton minimises ``|weight r(z)|**2 + |a / q|**2`` over ``z = (x_1,
    y_1, v_1, a_1 .. a_{N-1})`` from :func:`minimiser` (moved to frame 1, ``a =
    0``); at ``z*`` the stacked Jacobian ``M`` gives ``N(z, z*, (M^T M)^{-1})``,
    multiplied by the prior on ``x_1`` and mapped (linearly) to frame ``N``.
    Every least-squares problem is :func:`trajectory_solve`'s, ``O(N)``;
    :func:`depthbook.reference.trajectory_laplace_dense` solves them densely.

    Parameters
    ----------
    mu : ndarray, shape (B, N)
    weight : ndarray, shape (B,)
    prior_mean : ndarray, shape (3,) or (B, 3)
    prior_cov : ndarray, shape (3, 3) or (B, 3, 3)
    process_noise : float
        ``> 0``.

    Returns
    -------
    mean : ndarray, shape (B, 3)
    cov : ndarray, shape (B, 3, 3)
    """
    B, n_frames = mu.shape
    L = np.broadcast_to(np.linalg.cholesky(np.asarray(prior_cov, dtype=float)), (B, 3, 3))
    m = np.broadcast_to(np.asarray(prior_mean, dtype=float), (B, 3))
    z = np.concatenate([model.G(minimiser(mu), 1 - n_frames), np.zeros((B, n_frames - 1))], -1)

    def objective(z, rows):
        s = trajectory_states(z)
        front = z[:, 1] > 0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r = weight[rows, None] * (model.project(s) - mu[rows])
            value = np.sum(r**2, axis=-1) + np.sum((z[:, 3:] / process_noise) ** 2, axis=-1)
        return np.where(front, value, np.inf)

    f = objective(z, np.arange(B))
    active = np.ones(B, dtype=bool)
    for _ in range(MAX_ITERATIONS):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        za = z[rows]
        s = trajectory_states(za)
        r = weight[rows, None] * (model.project(s) - mu[rows])
        step, _ = trajectory_solve(
            bearing_rows(s, weight[rows]), -r, -za[:, 3:] / process_noise, process_noise
        )
        step = np.where(np.isfinite(step), step, 0.0)
        z_new, f_new = damped_step(za, step, f[rows], lambda y, rows=rows: objective(y, rows))
        moved = np.max(np.abs(z_new - za) / (1.0 + np.abs(za)), axis=-1)
        z[rows], f[rows] = z_new, f_new
        active[rows] = moved > STEP_TOL
    if np.any(active):
        raise ValueError(
            f"mu[{int(np.argmax(active))}]: Gauss-Newton on the trajectory's likelihood with "
            f"process_noise {process_noise:g} did not converge in {MAX_ITERATIONS} iterations"
        )
    s = trajectory_states(z)
    L_inv = np.linalg.inv(L)
    gap = np.einsum("bij,bj->bi", L_inv, m - s[:, 0])
    zero = np.zeros((B, n_frames))
    dz, R = trajectory_solve(bearing_rows(s, weight), zero, zero[:, 1:], process_noise, L_inv, gap)
    R_inv = np.linalg.inv(R)
    cov = R_inv @ np.swapaxes(R_inv, -1, -2)
    mean = s[:, -1] + trajectory_states(dz, offset=False)[:, -1]
    return mean, symmetric(cov)


def _square_root_solve(c, g, weight, prior_mean, prior_cov):
    """Eq. (8) in square-root form: the Gaussian ``N(c, S) p(G^{1-N} x)`` by QR, batched.

    With ``S^{-1} = weight**2 g^T g`` (``g`` (B, N, 3) the residual gradients)
    and ``P = L L^T``, the mean ``c + delta`` minimises ``|weight g delta|**2 +
    |L^{-1} (A (c + delta) + b - m)|**2`` (``G^{1-N} x = A x + b``); the QR
    factor ``R`` of its stacked matrix gives ``delta`` and the covariance
    ``R^{-1} R^{-T}`` without squaring the condition. Means (B, 3), covariances (B, 3, 3).
    """
    B, n_frames = g.shape[:2]
    A, b = (A2, b2) if n_frames == 3 else (model.G_linear(1 - n_frames), model.e * (1 - n_frames))
    L = np.broadcast_to(np.linalg.cholesky(np.asarray(prior_cov, dtype=float)), (B, 3, 3))
    gap = np.broadcast_to(np.asarray(prior_mean, dtype=float), (B, 3)) - b - c @ A.T
    whitened = np.linalg.solve(
        L, np.concatenate([np.broadcast_to(A, (B, 3, 3)), gap[..., None]], axis=-1)
    )
    K = np.concatenate([weight[:, None, None] * g, whitened[..., :3]], axis=1)  # (B, N + 3, 3)
    Q, R = np.linalg.qr(K)
    R_inv = np.linalg.inv(R)
    delta = np.einsum("bij,bkj,bk->bi", R_inv, Q[:, n_frames:], whitened[..., 3])
    cov = R_inv @ np.swapaxes(R_inv, -1, -2)
    return c + delta, symmetric(cov)


def paper_frames(mu, rho, steps=None):
    """``mu`` and ``rho`` of a track the second-order approximation takes, or a one-line refusal.

    A missing bearing, uneven steps or a ``rho`` that changes from frame to
    frame is refused; a ``rho`` per frame, the same at every frame, is one.

    Returns
    -------
    mu : array_like
        As given (checked further by the filter).
    rho : float or ndarray, shape (...)
    """
    mu_arr = checks.as_float(mu, "mu")
    rho_arr = checks.as_float(rho, "rho")
    per_frame = rho_arr.ndim > 0 and rho_arr.shape == mu_arr.shape
    if steps is None and not per_frame and not np.any(np.isnan(mu_arr)):
        return mu, rho
    f = frames.check(mu_arr, rho_arr, steps)
    if not np.all(f.present):
        raise ValueError(
            "mu: the second-order approximation takes no missing bearings (NaN); "
            "use the EKF, the UKF or the exact filter"
        )
    if not np.all(f.steps == 1.0):
        raise ValueError("steps: the second-order approximation takes only unit steps")
    if not np.all(f.rho == f.rho[..., :1]):
        raise ValueError(
            "rho: the second-order approximation takes one rho per problem, not one per frame"
        )
    return mu, f.row_rho


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    reading: str = "derived",
    steps=None,
):
    """Eq. (8): the second-order approximation ``p_s`` at frame ``N``, of one sequence or a batch.

    ``p_s(x) = N(x, c, S) p(G^{-2} x)`` with ``S`` from :func:`likelihood_covariance`;
    for ``N > 3`` or process noise, see the module docstring. Only the paper's
    frames (:func:`paper_frames`).

    {parameters}
    reading : {"derived", "printed"}

    Returns
    -------
    Gaussian or MeanAndCov
        For one sequence the Gaussian ``p_s`` (state at frame ``N``); for a batch
        its means (B, 3) and covariances (B, 3, 3).
    """
    mu, rho = paper_frames(mu, rho, steps)
    if np.ndim(mu) != 1:
        return MeanAndCov(
            *second_order_batch(mu, rho, prior_mean, prior_cov, reading, process_noise)
        )
    prior = Gaussian.prior(prior_mean, prior_cov)
    if np.shape(mu)[0] != 3 or process_noise != 0.0:
        rho = checks.positive_scalar(rho, "rho")
        mean, cov = second_order_batch(
            np.asarray(mu)[None], rho, prior.mean, prior.cov, reading, process_noise
        )
        return Gaussian(mean[0], cov[0])
    c = noise_free_state(mu)
    rho = checks.positive_scalar(rho, "rho")
    factor = {"derived": 2.0, "printed": 1.0}[_reading(reading)]
    g = residual_gradients(c)
    mean, cov = _square_root_solve(
        c[None], g[None], np.array([np.sqrt(2.0 / factor) / rho]), prior.mean, prior.cov
    )
    return Gaussian(mean[0], cov[0])


def _reading(reading: str) -> str:
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    return reading


def theorem1_precision(mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (24): ``D^{-1}``, the inverse covariance of ``p_s`` written with EKF vectors.

    ``D^{-1} = (1/rho**2) sum_k (F^{k-3})^T h_k h_k^T F^{k-3} + (F^{-2})^T P^{-1} F^{-2}``,
    with ``h_k`` the observation vector (11) at ``G^{k-3} c``, the EKF's
    predicted mean at time ``k`` when the prior mean is ``G^{-2} c`` (Eq. (19)),
    and ``F^{k-3}`` the linear part of ``G^{k-3}``.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    rho = checks.positive_scalar(rho, "rho")
    g = residual_gradients(noise_free_state(mu))  # rows h_k^T F^{k-3}, Eqs. (20)-(22)
    precision = np.zeros((3, 3))
    for row in g:
        precision += np.outer(row, row) / rho**2
    F2 = model.G_linear(-2)
    return precision + F2.T @ np.linalg.solve(prior.cov, F2)
