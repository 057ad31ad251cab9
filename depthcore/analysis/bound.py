"""What any estimator can achieve: the Cramér–Rao bound on the state at frame ``N``.

Recommended import: ``from depthcore.analysis import bound``.

The model is that of :mod:`depthcore.exact.bank`: the state ``s_k = (x_k, y_k, v_k)``
at frame ``k = 1 .. N`` moves by ``s_{k+1} = F s_k + e + (0, 0, a_k)`` (Eqs.
(1), (9), with ``a_k ~ N(0, q_k**2)`` the change of the lateral velocity over
step ``k``), the camera sees ``mu_k = x_k / y_k + w_k``, ``w_k ~ N(0, rho**2)``
(Eq. (4)), and the state at frame 1 has the prior ``N(m, P)`` (Eq. (13)).

One bearing's Fisher information about the state it sees is
``I_k = h_k h_k^T / rho**2``, with ``h_k`` the gradient of the projection at
``s_k`` (Eq. (11)). The information about the state at frame ``k``, the
prior's included, follows the recursion of Tichavský, Muravchik & Nehorai
(1998, Eq. (21)) [tichavsky1998]_, ``J_{k+1} = D22 - D21 (J_k + D11)^{-1} D12``, which for
this linear motion with Gaussian noise of covariance ``Q_k = q_k**2 u u^T``
(``u = (0, 0, 1)``: only the velocity is disturbed) is

    J_1 = P^{-1} + I_1,    J_{k+1} = (F J_k^{-1} F^T + Q_k)^{-1} + I_{k+1},

computed without inverting ``J_k`` by Sherman–Morrison (:func:`_velocity_noise`).
The bound on the covariance of any estimator of ``s_N`` is ``J_N^{-1}``.

* **conditional on the true track** (:func:`conditional_bound`): ``I_k`` at the
  true states; with ``q = 0`` the batch information
  ``F^{-(N-1)T} P^{-1} F^{-(N-1)} + sum_k g_k g_k^T / rho**2`` (Eqs. (20)-(22)), the
  bound of Ristic, Arulampalam & Gordon (2004, ch. 6) [ristic2004]_;
* **the posterior bound** (:func:`posterior_bound`): ``E[I_k]`` over the
  accelerations after a known state (a Gaussian depth would make ``E[1 / y**2]``
  infinite).

:func:`against_bound` sets estimates' errors and claimed SDs against a bound.
With steps ``s_k`` (:mod:`depthcore.problem.frames`) ``F`` becomes ``F_k`` and
``Q_k = q_k**2 s_k u u^T``; a missing bearing has ``I_k = 0``. Information is
computed on mantissas and exponents apart, so extreme scales cost nothing; a
result beyond the largest double is a one-line :class:`ValueError`.

References
----------
.. [tichavsky1998] P. Tichavský, C. H. Muravchik and A. Nehorai, "Posterior
   Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans.
   Signal Processing 46(5), 1386-1396, 1998.
.. [ristic2004] B. Ristic, S. Arulampalam and N. Gordon, *Beyond the Kalman
   Filter: Particle Filters for Tracking Applications*, Artech House, 2004,
   ch. 6 (bearings-only tracking).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.problem import checks, model
from depthcore.problem.frames import transition, velocity_variance
from depthcore.problem.gaussian import symmetric

#: The direction of the process noise in ``(x, y, v)``: only the velocity changes.
U = np.array([0.0, 0.0, 1.0])
U.setflags(write=False)
#: The default critical value of :func:`against_bound`, the standard normal's two-sided 1 % point.
Z = 2.5758293035489004


#: Process noise variances above this take the Sherman-Morrison step's limiting form.
_LARGE_VARIANCE = 1e100

#: Matrices within ``2**±_SCALE_FREE`` are inverted as they are; others scaled first.
_SCALE_FREE = 256


def _rho(value, shape: tuple[int, ...], present=None) -> np.ndarray:
    """``rho`` broadcast to ``shape`` (..., N): finite and > 0 where a bearing is present."""
    rho = checks.as_float(value, "rho")
    if not checks.broadcasts(rho.shape, shape):
        raise ValueError(
            f"rho must be a number or broadcast to {shape} (one per frame), got shape {rho.shape}"
        )
    rho = np.broadcast_to(rho, shape)
    used = rho if present is None else np.where(present, rho, 1.0)
    bad = ~(np.isfinite(used) & (used > 0))
    if np.any(bad):
        worst = float(used[np.unravel_index(np.argmax(bad), shape)])
        raise ValueError(f"rho must be finite and positive, got {worst!r}")
    return used


def _states(value, name: str = "states") -> np.ndarray:
    """States ``(..., N, 3)``, finite, ``N`` at most :data:`checks.MAX_FRAMES`."""
    states = checks.finite_array(value, name)
    if states.ndim < 2 or states.shape[-1] != 3 or states.shape[-2] < 1:
        raise ValueError(f"{name} must have shape (..., N, 3), got {states.shape}")
    _frames_limit(states.shape[-2], name)
    return states


def _frames_limit(n: int, name: str) -> None:
    if n > checks.MAX_FRAMES:
        raise ValueError(
            f"{name} has {n} frames, more than the {checks.MAX_FRAMES} the bound accepts"
        )


def _information_block(x, y, rho, c=None):
    """The nonzero 2 x 2 block of ``h h^T / rho**2`` (``c`` None) or ``E[h h^T] / rho**2``.

    On ``frexp`` mantissas with exponents apart (bit for bit the plain result in
    range, ``inf`` beyond). Returns the entries (0, 0), (0, 1) and (1, 1).
    """
    my, ey = np.frexp(y)
    mx, ex = np.frexp(x)
    mr, er = np.frexp(rho)
    r2 = mr**2
    with np.errstate(over="ignore", under="ignore"):
        if c is None:
            am, ae = 1.0 / my, -ey
            bm, be = -mx / my**2, ex - 2 * ey
            i00 = np.ldexp(am * am / r2, 2 * ae - 2 * er)
            i01 = np.ldexp(am * bm / r2, ae + be - 2 * er)
            i11 = np.ldexp(bm * bm / r2, 2 * be - 2 * er)
        else:
            mc, ec = np.frexp(c)
            top = np.maximum(2 * ex, ec)
            total = np.ldexp(mx**2, 2 * ex - top) + np.ldexp(mc, ec - top)
            i00 = np.ldexp(1.0 / my**2 / r2, -2 * ey - 2 * er)
            i01 = np.ldexp(-mx / my**3 / r2, ex - 3 * ey - 2 * er)
            i11 = np.ldexp(total / my**4 / r2, top - 4 * ey - 2 * er)
    return i00, i01, i11


def _assemble(block, shape, names: str) -> np.ndarray:
    i00, i01, i11 = np.broadcast_arrays(*block)
    if not (np.all(np.isfinite(i00)) and np.all(np.isfinite(i01)) and np.all(np.isfinite(i11))):
        raise ValueError(
            f"{names}: the information exceeds the largest double (a depth too small for the "
            "noise level)"
        )
    out = np.zeros(shape + (3, 3))
    out[..., 0, 0] = i00
    out[..., 0, 1] = out[..., 1, 0] = i01
    out[..., 1, 1] = i11
    return out


def measurement_information(states, rho) -> np.ndarray:
    """One bearing's Fisher information about the state it sees, ``h h^T / rho**2``.

    ``h`` is Eq. (11)'s gradient (:func:`depthcore.problem.model.observation_vector`).
    ``states`` (..., 3) with ``y != 0``, ``rho`` broadcastable to (...); returns
    (..., 3, 3).
    """
    states = checks.finite_array(states, "states")
    if states.ndim < 1 or states.shape[-1] != 3:
        raise ValueError(f"states must have shape (..., 3), got {states.shape}")
    if np.any(states[..., 1] == 0):
        raise ValueError("states must have nonzero depths y: the projection x / y is undefined")
    rho = _rho(rho, states.shape[:-1])
    block = _information_block(states[..., 0], states[..., 1], rho)
    return _assemble(block, states.shape[:-1], "states and rho")


def expected_measurement_information(depth, lateral_mean, lateral_cov, rho) -> np.ndarray:
    """``E[h h^T] / rho**2`` over a Gaussian lateral state at a known depth.

    With ``x ~ N(m, c)``, ``E[h h^T] = [[1 / y**2, -m / y**3], [-m / y**3, (m**2 + c) /
    y**4]]`` (Tichavský et al. 1998, ``E[H^T R^{-1} H]`` of ``D22``). ``depth`` (...),
    ``lateral_mean`` (..., 2), ``lateral_cov`` (..., 2, 2) of ``(x, v)``; returns (..., 3, 3).
    """
    y = checks.finite_array(depth, "depth")
    if not np.all(y > 0):
        raise ValueError("depth must be positive: the point must be in front of the camera")
    mean = checks.finite_array(lateral_mean, "lateral_mean")
    if mean.ndim < 1 or mean.shape[-1] != 2:
        raise ValueError(f"lateral_mean must have shape (..., 2), got {mean.shape}")
    cov = checks.finite_array(lateral_cov, "lateral_cov")
    if cov.ndim < 2 or cov.shape[-2:] != (2, 2):
        raise ValueError(f"lateral_cov must have shape (..., 2, 2), got {cov.shape}")
    m, c = mean[..., 0], cov[..., 0, 0]
    if np.any(c < 0):
        raise ValueError("lateral_cov must have a nonnegative variance of x")
    try:
        shape = np.broadcast_shapes(y.shape, m.shape, c.shape)
    except ValueError:
        raise ValueError(
            f"depth, lateral_mean and lateral_cov must broadcast, got shapes {y.shape}, "
            f"{mean.shape} and {cov.shape}"
        ) from None
    rho = _rho(rho, shape)
    block = _information_block(m, y, rho, c)
    return _assemble(block, shape, "depth, lateral_mean and rho")


def process_noise_steps(process_noise, frames: int) -> np.ndarray:
    """The SD ``q_k`` of the velocity's change over each step ``k -> k + 1``, shape (N - 1,).

    ``process_noise``: a float or (N - 1,), ``>= 0``; ``frames`` is ``N``.
    """
    n = checks.count(frames, "frames")
    _frames_limit(n, "frames")
    q = checks.finite_array(process_noise, "process_noise")
    if np.any(q < 0):
        raise ValueError("process_noise must be >= 0")
    if q.ndim == 0:
        return np.full(n - 1, float(q))
    if q.shape != (n - 1,):
        raise ValueError(
            f"process_noise must be a float or have shape ({n - 1},), one SD per step, "
            f"got shape {q.shape}"
        )
    return q


def _steps(value, n: int, batch: tuple[int, ...]):
    """Steps ``(N - 1,)`` or ``(..., N - 1)``, finite and nonzero (signed); None stays None."""
    if value is None:
        return None
    steps = checks.finite_array(value, "steps")
    if (
        steps.ndim < 1
        or steps.shape[-1] != n - 1
        or not checks.broadcasts(steps.shape, batch + (n - 1,))
    ):
        raise ValueError(
            f"steps must have shape ({n - 1},) or broadcast to {batch + (n - 1,)}, "
            f"got shape {steps.shape}"
        )
    if np.any(steps == 0):
        raise ValueError("steps must be nonzero (the depth's signed change; negative: approaching)")
    return steps


def information(measurement_info, prior_cov=None, process_noise=0.0, steps=None) -> np.ndarray:
    """The information about the state at every frame: the recursion of Tichavský et al. (1998).

    Eq. (21) with linear Gaussian motion (module docstring).

    Parameters
    ----------
    measurement_info : array_like, shape (..., N, 3, 3)
        ``I_k`` of each bearing (zero at a missing one).
    prior_cov : array_like, shape (3, 3), optional
        ``P``; ``None``: the bearings alone.
    process_noise : float or array_like, shape (N - 1,)
        ``q_k >= 0``, per unit step.
    steps : array_like, shape (N - 1,) or (..., N - 1), optional
        ``s_k > 0``; ``None``: all ones.

    Returns
    -------
    ndarray, shape (..., N, 3, 3)
        ``J_k`` after the bearing of frame ``k``.
    """
    info = checks.finite_array(measurement_info, "measurement_info")
    if info.ndim < 3 or info.shape[-2:] != (3, 3) or info.shape[-3] < 1:
        raise ValueError(f"measurement_info must have shape (..., N, 3, 3), got {info.shape}")
    n = info.shape[-3]
    _frames_limit(n, "measurement_info")
    q = process_noise_steps(process_noise, n)
    steps = _steps(steps, n, info.shape[:-3])
    J = _recursion(info, _prior_information(prior_cov), q, steps)
    if not np.all(np.isfinite(J)):
        raise ValueError("measurement_info: the information exceeds the largest double")
    return J


def _prior_information(prior_cov) -> np.ndarray:
    """``P^{-1}``, or zero without a prior."""
    if prior_cov is None:
        return np.zeros((3, 3))
    P = checks.covariance(prior_cov, "prior_cov", 3)
    with np.errstate(over="ignore", invalid="ignore"):
        out = _scaled_inverse(P, np.linalg.inv)
    if not np.all(np.isfinite(out)):
        raise ValueError("prior_cov: its inverse exceeds the largest double")
    return out


def _recursion(info, prior_info, q, steps) -> np.ndarray:
    """Eq. (21) of Tichavský et al. (1998) over ``I_k`` (..., N, 3, 3); ``inf`` on overflow."""
    n = info.shape[-3]
    if steps is not None and np.all(steps == 1.0):
        steps = None
    if steps is None:
        f_inv = [model.G_linear(-1)] * (n - 1)
        with np.errstate(over="ignore"):
            var = q**2
    else:
        if steps.ndim > 1 and np.all(steps == steps.reshape(-1, n - 1)[0]):
            steps = steps.reshape(-1, n - 1)[0]
        f_inv = [transition(-steps[..., k]) for k in range(n - 1)]
        with np.errstate(over="ignore"):
            var = velocity_variance(1.0, steps) * q**2
    out = np.empty(info.shape)
    J = prior_info + info[..., 0, :, :]
    out[..., 0, :, :] = J
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(n - 1):
            F = f_inv[k]
            M = np.swapaxes(F, -1, -2) @ J @ F
            v = var[..., k]
            if np.any(v > 0):
                M = _velocity_noise(M, v)
            J = M + info[..., k + 1, :, :]
            J = symmetric(J)
            out[..., k + 1, :, :] = J
    return np.where(np.isnan(out), np.inf, out)


def _velocity_noise(M, v) -> np.ndarray:
    """``(M^{-1} + v u u^T)^{-1}`` by Sherman–Morrison: ``M - v (Mu)(Mu)^T / (1 + v u^T M u)``.

    Above :data:`_LARGE_VARIANCE` as ``M - (Mu)(Mu)^T / (1 / v + u^T M u)``.
    """
    Mu = M @ U
    w = (Mu @ U)[..., None, None]
    outer = Mu[..., :, None] * Mu[..., None, :]
    if np.ndim(v) == 0:
        if v <= _LARGE_VARIANCE:
            return (
                M - v * Mu[..., :, None] * Mu[..., None, :] / (1.0 + v * (Mu @ U))[..., None, None]
            )
        denominator = 1.0 / v + w
        return M - outer / np.where(denominator > 0, denominator, 1.0)
    vv = np.asarray(v)[..., None, None]
    small = M - vv * Mu[..., :, None] * Mu[..., None, :] / (1.0 + vv * w)
    denominator = 1.0 / vv + w
    large = M - outer / np.where(denominator > 0, denominator, 1.0)
    return np.where(vv > _LARGE_VARIANCE, large, small)


def covariance_bound(information_matrix) -> np.ndarray:
    """The Cramér–Rao bound ``J^{-1}`` of information matrices ``J`` (..., 3, 3).

    Refuses a ``J`` not positive definite (:data:`SINGULAR`) or whose inverse overflows.
    """
    J = checks.finite_array(information_matrix, "information")
    if J.ndim < 2 or J.shape[-2:] != (3, 3):
        raise ValueError(f"information must have shape (..., 3, 3), got {J.shape}")
    if not np.all(_determined(J)):
        raise ValueError(
            "information is singular: the bearings and the prior do not determine the state "
            "(with no prior, at least three bearings are needed)"
        )
    return _checked_inverse(J)


#: An information matrix whose least eigenvalue is at most this fraction of its largest is singular.
SINGULAR = 1e-13


def _scale(A) -> np.ndarray:
    """Per matrix (..., 3, 3), exponents ``d`` (..., 3) equilibrating it: ``2**(d_i + d_j) A_ij``.

    Zero unless the diagonal leaves ``2**±_SCALE_FREE``; then ``d_i = -floor(e_i / 2)``
    with ``A_ii = m 2**e_i`` (exact).
    """
    e = np.frexp(np.abs(np.diagonal(A, axis1=-2, axis2=-1)))[1]
    wide = (np.max(np.abs(e), axis=-1) > _SCALE_FREE) | (
        np.max(e, axis=-1) - np.min(e, axis=-1) > _SCALE_FREE
    )
    return np.where(wide[..., None], -(e // 2), 0)


def _scaled(A, d) -> np.ndarray:
    """``2**(d_i + d_j) A_ij``."""
    return np.ldexp(A, d[..., :, None] + d[..., None, :])


def _scaled_inverse(A, invert) -> np.ndarray:
    """``A^{-1}`` as ``D (D A D)^{-1} D``, ``D`` a diagonal of powers of two (:func:`_scale`)."""
    d = _scale(A)
    return _scaled(invert(_scaled(A, d)), d)


def _determined(J) -> np.ndarray:
    """Whether each information matrix (..., 3, 3) is positive definite, after :func:`_scale`."""
    w = np.linalg.eigvalsh(_scaled(J, _scale(J)))
    return w[..., 0] > SINGULAR * np.abs(w[..., -1])


def _inverse(J) -> np.ndarray:
    """Inverse of symmetric positive definite matrices (..., 3, 3), by Cholesky."""
    L_inv = np.linalg.inv(np.linalg.cholesky(J))
    return np.swapaxes(L_inv, -1, -2) @ L_inv


def _checked_inverse(J) -> np.ndarray:
    """:func:`_inverse` of scaled ``J``, refused (naming ``information``) beyond the doubles."""
    with np.errstate(over="ignore", invalid="ignore"):
        out = _scaled_inverse(J, _inverse)
    if not np.all(np.isfinite(out)):
        raise ValueError(
            "information: its inverse, the bound, exceeds the largest double (the bearings "
            "carry almost no information)"
        )
    return out


def _frame_bounds(J) -> np.ndarray:
    """:func:`covariance_bound` at every frame of ``J`` (..., N, 3, 3), NaN if undetermined."""
    ok = _determined(J)
    covariance_bound(J[..., -1, :, :])
    out = np.full(J.shape, np.nan)
    out[ok] = _checked_inverse(J[ok])
    return out


def _present(value, shape: tuple[int, ...]) -> np.ndarray:
    """``present`` as booleans broadcast to ``shape`` (..., N); None: every frame."""
    if value is None:
        return np.ones(shape, dtype=bool)
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        raise ValueError("present must be booleans, got a ragged or mixed value") from None
    if arr.dtype.kind != "b":
        raise ValueError(f"present must be booleans (True where a bearing is), got {arr.dtype}")
    if not checks.broadcasts(arr.shape, shape):
        raise ValueError(f"present must broadcast to {shape}, got shape {arr.shape}")
    return np.broadcast_to(arr, shape)


#: A step within this many units in the last place of the depths of 1 is the unit step.
_STEP_ULPS = 4.0
#: ``x_{k+1} = x_k + s_k v_k`` must hold within this many units in the last place of its terms.
_MOTION_ULPS = 64.0


def track_steps(states) -> np.ndarray:
    """The steps ``s_k = y_{k+1} - y_k`` of a true track, checked against its lateral motion.

    Within ``_STEP_ULPS`` of 1 a step is 1; ``x_{k+1} = x_k + s_k v_k`` must hold
    within ``_MOTION_ULPS``. ``states`` (..., N, 3); returns (..., N - 1).
    """
    states = _states(states)
    x, y, v = states[..., 0], states[..., 1], states[..., 2]
    eps = np.finfo(float).eps
    with np.errstate(over="ignore", invalid="ignore"):
        s = np.diff(y, axis=-1)
        depth = np.maximum(np.abs(y[..., 1:]), np.abs(y[..., :-1]))
        s = np.where(np.abs(s - 1.0) <= _STEP_ULPS * eps * np.maximum(depth, 1.0), 1.0, s)
        if np.any(s == 0) or not np.all(np.isfinite(s)):
            raise ValueError(
                "states must have depths that change from frame to frame (steps nonzero: "
                "positive receding, negative approaching)"
            )
        moved = s * v[..., :-1]
        error = np.abs(x[..., 1:] - x[..., :-1] - moved)
        scale = np.abs(x[..., 1:]) + np.abs(x[..., :-1]) + 2 * depth * np.abs(v[..., :-1])
        ok = error <= _MOTION_ULPS * eps * scale
    if not np.all(ok):
        raise ValueError(
            "states must move by x_{k+1} = x_k + s_k v_k with the step s_k = y_{k+1} - y_k"
        )
    return s


def conditional_bound(states, rho, prior_cov=None, process_noise=0.0, present=None) -> np.ndarray:
    """The bound on the state at every frame, conditional on the true track.

    :func:`information` with ``I_k`` at the true states (Eq. (21); Ristic et al. 2004,
    ch. 6), steps from :func:`track_steps`, inverted by :func:`covariance_bound`.

    Parameters
    ----------
    states : array_like, shape (..., N, 3)
        The true track, frames 1 .. N.
    rho : float or array_like, broadcastable to shape (..., N)
        Per frame (any value at a missing frame).
    prior_cov : array_like, shape (3, 3), optional
    process_noise : float or array_like, shape (N - 1,)
        ``q_k >= 0``, per unit step.
    present : array_like of bool, broadcastable to shape (..., N), optional
        Where a bearing was taken; ``None``: at every frame.

    Returns
    -------
    ndarray, shape (..., N, 3, 3)
        The bound at each frame from the bearings so far; NaN where undetermined.
    """
    states = _states(states)
    if not np.all(states[..., 1] > 0):
        raise ValueError("states must have positive depths: the point in front of the camera")
    steps = track_steps(states)
    shape = states.shape[:-1]
    present = _present(present, shape)
    rho = _rho(rho, shape, present)
    info = measurement_information(states, rho)
    info = np.where(present[..., None, None], info, 0.0)
    q = process_noise_steps(process_noise, shape[-1])
    with np.errstate(over="ignore"):
        J = _recursion(info, _prior_information(prior_cov), q, steps)
    if not np.all(np.isfinite(J)):
        raise ValueError("states and rho: the information exceeds the largest double")
    return _frame_bounds(J)


class TrackMoments(NamedTuple):
    """The law of a track whose state at one frame is known, frames 1 .. N.

    ``mean`` (N, 3) (the depth exact), ``lateral_cov`` (N, 2, 2) of ``(x_k, v_k)``,
    ``process_noise`` (N - 1,), 0 before the known frame.
    """

    mean: np.ndarray
    lateral_cov: np.ndarray
    process_noise: np.ndarray


def track_moments(state, frame: int, frames: int, process_noise: float) -> TrackMoments:
    """The law of the track when the state at ``frame`` is known and accelerations act after it.

    Before ``frame`` by ``G`` (Eq. (1)); after, ``(x_k, v_k)`` has mean ``Psi**(k - frame)
    (x, v)`` and ``C_{k+1} = Psi C_k Psi^T + diag(0, q**2)``, ``C_frame = 0``. ``state``
    (3,), ``1 <= frame <= frames``, ``process_noise`` ``q >= 0``.
    """
    state = checks.finite_array(state, "state", (3,))
    n = checks.count(frames, "frames")
    _frames_limit(n, "frames")
    frame = checks.count(frame, "frame")
    if not 1 <= frame <= n:
        raise ValueError(f"frame must be from 1 to frames = {n}, got {frame}")
    q = checks.process_noise(process_noise)
    if not state[1] - (frame - 1) > 0:
        raise ValueError("state puts the point behind the camera at frame 1")
    with np.errstate(over="ignore", invalid="ignore"):
        mean = np.stack([model.G(state, k - frame) for k in range(1, n + 1)])
        psi = np.array([[1.0, 1.0], [0.0, 1.0]])
        cov = np.zeros((n, 2, 2))
        for k in range(frame, n):
            cov[k] = psi @ cov[k - 1] @ psi.T + np.diag([0.0, np.float64(q) ** 2])
    if not np.all(np.isfinite(mean)):
        raise ValueError("state: the track it starts leaves the range of doubles")
    if not np.all(np.isfinite(cov)):
        raise ValueError("process_noise: the track's lateral variance exceeds the largest double")
    steps = np.where(np.arange(1, n) >= frame, q, 0.0)
    return TrackMoments(mean, cov, steps)


def posterior_bound(state, frame: int, frames: int, rho, prior_cov=None, process_noise=0.0):
    """The posterior bound on the state at every frame, over the accelerations after ``frame``.

    Tichavský et al. (1998), Eq. (21) with ``E[I_k]`` over :func:`track_moments`;
    ``state`` (3,) at ``frame``; returns (N, 3, 3) as :func:`conditional_bound`.
    """
    t = track_moments(state, frame, frames, process_noise)
    rho = checks.positive_scalar(rho, "rho")
    block = _information_block(t.mean[:, 0], t.mean[:, 1], rho, t.lateral_cov[:, 0, 0])
    info = _assemble(block, (len(t.mean),), "state and rho")  # Eq. (11), E[I_k] as below
    J = _recursion(info, _prior_information(prior_cov), t.process_noise, None)
    if not np.all(np.isfinite(J)):
        raise ValueError("state and rho: the information exceeds the largest double")
    return _frame_bounds(J)


def against_bound(errors, sds, bound_sd, z: float = Z) -> dict:
    """Estimates' errors and claimed SDs over trials, set against a bound's SD.

    The RMSE's standard error is ``sd(e**2) / (2 sqrt(T) RMSE)``, the mean claimed SD's
    ``sd(s) / sqrt(T)``. ``"overconfident"`` flags a mean claimed SD more than ``z``
    standard errors below the bound (a claim, not the errors).

    Parameters
    ----------
    errors : array_like, shape (..., T)
        Estimate minus truth, ``T >= 2``.
    sds : array_like, shape (..., T)
    bound_sd : array_like, broadcastable to shape (...)
    z : float

    Returns
    -------
    dict
        Arrays of shape (...): ``"rmse"``, ``"rmse_se"``, ``"mean_sd"``,
        ``"mean_sd_se"``, ``"rmse_ratio"`` and ``"sd_ratio"`` (over the
        bound), ``"rmse_ratio_se"``, ``"sd_ratio_se"``, ``"overconfident"``
        (bool) and ``"trials"``.
    """
    e = checks.finite_array(errors, "errors")
    s = checks.finite_array(sds, "sds")
    if e.ndim < 1 or e.shape != s.shape or e.shape[-1] < 2:
        raise ValueError(
            f"errors and sds must have the same shape (..., T) with T >= 2, got {e.shape} "
            f"and {s.shape}"
        )
    if np.any(s < 0):
        raise ValueError("sds must be >= 0")
    b = checks.finite_array(bound_sd, "bound_sd")
    if np.any(b <= 0):
        raise ValueError("bound_sd must be positive")
    z = checks.positive_scalar(z, "z")
    try:
        np.broadcast_shapes(b.shape, e.shape[:-1])
    except ValueError:
        raise ValueError(
            f"bound_sd must broadcast to {e.shape[:-1]}, got shape {b.shape}"
        ) from None
    t = e.shape[-1]
    # Each row scaled by an even power of two (exact), so that squares neither
    # overflow nor underflow; the scale is taken out again at the end.
    ke = _row_scale(e)
    ks = _row_scale(s)
    e = np.ldexp(e, -ke[..., None])
    s = np.ldexp(s, -ks[..., None])
    mse = np.mean(e**2, axis=-1)
    rmse = np.sqrt(mse)
    with np.errstate(divide="ignore", invalid="ignore"):
        rmse_se = np.where(rmse > 0, np.std(e**2, axis=-1, ddof=1) / (2 * np.sqrt(t) * rmse), 0.0)
    mean_sd = np.mean(s, axis=-1)
    mean_sd_se = np.std(s, axis=-1, ddof=1) / np.sqrt(t)
    with np.errstate(over="ignore", under="ignore"):
        out = {
            "rmse": np.ldexp(rmse, ke),
            "rmse_se": np.ldexp(rmse_se, ke),
            "mean_sd": np.ldexp(mean_sd, ks),
            "mean_sd_se": np.ldexp(mean_sd_se, ks),
            "rmse_ratio": _ratio(rmse, ke, b),
            "rmse_ratio_se": _ratio(rmse_se, ke, b),
            "sd_ratio": _ratio(mean_sd, ks, b),
            "sd_ratio_se": _ratio(mean_sd_se, ks, b),
        }
        z_se = np.ldexp(z * mean_sd_se, ks)  # may be inf: then not overconfident, rightly
        out["overconfident"] = out["mean_sd"] + z_se < b
    if not all(np.all(np.isfinite(out[key])) for key in out if key != "overconfident"):
        raise ValueError(
            "bound_sd: the errors or sds over it exceed the largest double (a bound_sd too small)"
        )
    out["trials"] = np.full(np.shape(out["rmse"]), t)
    return out


def _row_scale(a) -> np.ndarray:
    """Per row of ``a`` (..., T), an even exponent ``k`` with ``2**-k max|a|`` near 1."""
    e = np.frexp(np.max(np.abs(a), axis=-1))[1]
    return 2 * (e // 2)


def _ratio(mantissa, exponent, b) -> np.ndarray:
    """``mantissa * 2**exponent / b`` without overflow in between (``inf`` if it overflows)."""
    mb, eb = np.frexp(b)
    return np.ldexp(mantissa / mb, exponent - eb)
