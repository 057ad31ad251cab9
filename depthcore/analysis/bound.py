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

computed here without inverting ``J_k`` (so also when it is singular, as it
is without a prior), by the Sherman–Morrison identity for the rank-one
``Q_k``: with ``M = F^{-T} J_k F^{-1}``,
``(F J_k^{-1} F^T + Q_k)^{-1} = M - q_k**2 (M u)(M u)^T / (1 + q_k**2 u^T M u)``.
The bound on the covariance of any estimator of ``s_N`` is ``J_N^{-1}``.

Two readings of ``I_k``, both in the recursion above:

* **conditional on the true track** (:func:`conditional_bound`): ``I_k`` at
  the track's true states, the prior's information ``P^{-1}`` added; with
  ``q = 0`` this is the batch information of all ``N`` bearings about
  ``s_N``, ``F^{-(N-1)T} P^{-1} F^{-(N-1)} + sum_k g_k g_k^T / rho**2``, with
  ``g_k`` the residual gradients of Eqs. (20)-(22)
  (:func:`depthcore.problem.model.residual_gradients`), the bound that Ristic,
  Arulampalam & Gordon (2004, ch. 6) [ristic2004]_ set bearings-only trackers against;
* **the posterior bound** (:func:`posterior_bound`, Tichavský et al. 1998):
  ``E[I_k]`` over the law of the track. The expectation is taken over the
  accelerations that act after a known state (the lateral position is then
  Gaussian at a known depth, and ``E[I_k]`` has a closed form,
  :func:`expected_measurement_information`), not over a Gaussian prior on the
  depth: ``I_k`` grows like ``1 / y**2`` and ``E[1 / y**2]`` is infinite for
  any Gaussian depth, whose density is positive at ``y = 0``.

:func:`against_bound` sets estimates' errors and claimed SDs, trial by trial,
against a bound, with Monte Carlo standard errors, and flags a claimed SD
below it.

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
from depthcore.problem.gaussian import symmetric

#: The direction of the process noise in ``(x, y, v)``: only the velocity changes.
U = np.array([0.0, 0.0, 1.0])
U.setflags(write=False)
#: The default critical value of :func:`against_bound`, the standard normal's two-sided 1 % point.
Z = 2.5758293035489004


def measurement_information(states, rho) -> np.ndarray:
    """One bearing's Fisher information about the state it sees, ``h h^T / rho**2``.

    ``h`` is the gradient of the projection ``x / y`` at the state, Eq. (11)
    (:func:`depthcore.problem.model.observation_vector`).

    Parameters
    ----------
    states : array_like, shape (..., 3)
        States ``(x, y, v)`` with ``y != 0``.
    rho : float
        Bearing noise SD, > 0.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    rho = checks.positive_scalar(rho, "rho")
    h = model.observation_vector(checks.finite_array(states, "states"))
    return h[..., :, None] * h[..., None, :] / rho**2


def expected_measurement_information(depth, lateral_mean, lateral_cov, rho) -> np.ndarray:
    """``E[h h^T] / rho**2`` over a Gaussian lateral state at a known depth.

    With ``x ~ N(m, c)`` at depth ``y``, ``h = (1 / y, -x / y**2, 0)`` (Eq. (11))
    has ``E[h h^T] = [[1 / y**2, -m / y**3, 0], [-m / y**3, (m**2 + c) / y**4, 0],
    [0, 0, 0]]``: the expected measurement information of the posterior bound
    (Tichavský et al. 1998, the term ``E[H^T R^{-1} H]`` of ``D22``).

    Parameters
    ----------
    depth : array_like, shape (...)
        Depths ``y > 0``.
    lateral_mean : array_like, shape (..., 2)
        Means of ``(x, v)``.
    lateral_cov : array_like, shape (..., 2, 2)
        Covariances of ``(x, v)``.
    rho : float

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    rho = checks.positive_scalar(rho, "rho")
    y = checks.finite_array(depth, "depth")
    if not np.all(y > 0):
        raise ValueError("depth must be positive: the point must be in front of the camera")
    m = checks.finite_array(lateral_mean, "lateral_mean")[..., 0]
    c = checks.finite_array(lateral_cov, "lateral_cov")[..., 0, 0]
    y, m, c = np.broadcast_arrays(y, m, c)
    out = np.zeros(y.shape + (3, 3))
    out[..., 0, 0] = 1.0 / y**2
    out[..., 0, 1] = out[..., 1, 0] = -m / y**3
    out[..., 1, 1] = (m**2 + c) / y**4
    return out / rho**2


def process_noise_steps(process_noise, frames: int) -> np.ndarray:
    """The SD ``q_k`` of the velocity's change over each step ``k -> k + 1``, shape (N - 1,).

    ``process_noise`` is a float (the same at every step) or an array of
    shape ``(N - 1,)``, each ``>= 0``.
    """
    q = checks.finite_array(process_noise, "process_noise")
    if np.any(q < 0):
        raise ValueError("process_noise must be >= 0")
    if q.ndim == 0:
        return np.full(frames - 1, float(q))
    if q.shape != (frames - 1,):
        raise ValueError(
            f"process_noise must be a float or have shape ({frames - 1},), one SD per step, "
            f"got shape {q.shape}"
        )
    return q


def information(measurement_info, prior_cov=None, process_noise=0.0) -> np.ndarray:
    """The information about the state at every frame: the recursion of Tichavský et al. (1998).

    ``J_1 = P^{-1} + I_1`` and ``J_{k+1} = (F J_k^{-1} F^T + Q_k)^{-1} + I_{k+1}``,
    Tichavský et al. (1998), Eq. (21) with linear Gaussian motion (module
    docstring), computed by Sherman–Morrison without inverting ``J_k``.

    Parameters
    ----------
    measurement_info : array_like, shape (..., N, 3, 3)
        ``I_k`` of each bearing, conditional (:func:`measurement_information`
        at the true states) or expected
        (:func:`expected_measurement_information`).
    prior_cov : array_like, shape (3, 3), optional
        ``P``, the prior covariance of the state at frame 1 (symmetric positive
        definite); ``None``: no prior, the information of the bearings alone.
    process_noise : float or array_like, shape (N - 1,)
        ``q_k >= 0`` (:func:`process_noise_steps`).

    Returns
    -------
    ndarray, shape (..., N, 3, 3)
        ``J_k`` after the bearing of frame ``k``.
    """
    info = checks.finite_array(measurement_info, "measurement_info")
    if info.ndim < 3 or info.shape[-2:] != (3, 3):
        raise ValueError(f"measurement_info must have shape (..., N, 3, 3), got {info.shape}")
    n = info.shape[-3]
    q2 = process_noise_steps(process_noise, n) ** 2
    if prior_cov is None:
        prior_info = np.zeros((3, 3))
    else:
        prior_info = np.linalg.inv(checks.covariance(prior_cov, "prior_cov", 3))
    f_inv = model.G_linear(-1)
    out = np.empty(info.shape)
    J = prior_info + info[..., 0, :, :]
    out[..., 0, :, :] = J
    for k in range(n - 1):
        M = f_inv.T @ J @ f_inv
        if q2[k] > 0:
            Mu = M @ U
            M = (
                M
                - q2[k]
                * Mu[..., :, None]
                * Mu[..., None, :]
                / (1.0 + q2[k] * (Mu @ U))[..., None, None]
            )
        J = M + info[..., k + 1, :, :]
        J = symmetric(J)
        out[..., k + 1, :, :] = J
    return out


def covariance_bound(information_matrix) -> np.ndarray:
    """The Cramér–Rao bound ``J^{-1}`` of information matrices ``J`` (..., 3, 3).

    Refuses, naming ``information``, a ``J`` that is not positive definite
    (its least eigenvalue at most :data:`SINGULAR` times its largest): the
    bearings (and the prior) then do not determine the state.
    """
    J = checks.finite_array(information_matrix, "information")
    if not np.all(_determined(J)):
        raise ValueError(
            "information is singular: the bearings and the prior do not determine the state "
            "(with no prior, at least three bearings are needed)"
        )
    return _inverse(J)


#: An information matrix whose least eigenvalue is at most this fraction of its largest is singular.
SINGULAR = 1e-13


def _determined(J) -> np.ndarray:
    """Whether each information matrix (..., 3, 3) is positive definite beyond rounding."""
    w = np.linalg.eigvalsh(J)
    return w[..., 0] > SINGULAR * np.abs(w[..., -1])


def _inverse(J) -> np.ndarray:
    """Inverse of symmetric positive definite matrices (..., 3, 3), by Cholesky."""
    L_inv = np.linalg.inv(np.linalg.cholesky(J))
    return np.swapaxes(L_inv, -1, -2) @ L_inv


def _frame_bounds(J) -> np.ndarray:
    """:func:`covariance_bound` at every frame of ``J`` (..., N, 3, 3).

    The last frame must be determined; earlier frames that are not (fewer
    than three bearings and no prior) get NaN.
    """
    ok = _determined(J)
    covariance_bound(J[..., -1, :, :])
    out = np.full(J.shape, np.nan)
    out[ok] = _inverse(J[ok])
    return out


def conditional_bound(states, rho, prior_cov=None, process_noise=0.0) -> np.ndarray:
    """The bound on the state at every frame, conditional on the true track.

    :func:`information` with ``I_k`` at the true states (Tichavský et al.
    1998, Eq. (21); the bound along the true trajectory of Ristic et al. 2004,
    ch. 6), inverted by :func:`covariance_bound`.

    Parameters
    ----------
    states : array_like, shape (..., N, 3)
        The true track, frames 1 .. N.
    rho : float
    prior_cov : array_like, shape (3, 3), optional
        The prior covariance of the state at frame 1; ``None``: none.
    process_noise : float or array_like, shape (N - 1,)

    Returns
    -------
    ndarray, shape (..., N, 3, 3)
        The bound on the covariance of the state at each frame ``k``, from
        the bearings of frames 1 .. k (NaN at frames that the bearings so far
        do not determine, without a prior; refused at frame ``N``).
    """
    states = checks.finite_array(states, "states")
    if states.ndim < 2 or states.shape[-1] != 3:
        raise ValueError(f"states must have shape (..., N, 3), got {states.shape}")
    if not np.all(states[..., 1] > 0):
        raise ValueError("states must have positive depths: the point in front of the camera")
    J = information(measurement_information(states, rho), prior_cov, process_noise)
    return _frame_bounds(J)


class TrackMoments(NamedTuple):
    """The law of a track whose state at one frame is known, frames 1 .. N.

    Attributes
    ----------
    mean : ndarray, shape (N, 3)
        Mean state at each frame (its depth is exact).
    lateral_cov : ndarray, shape (N, 2, 2)
        Covariance of ``(x_k, v_k)``.
    process_noise : ndarray, shape (N - 1,)
        ``q_k`` of each step: 0 before the known frame.
    """

    mean: np.ndarray
    lateral_cov: np.ndarray
    process_noise: np.ndarray


def track_moments(state, frame: int, frames: int, process_noise: float) -> TrackMoments:
    """The law of the track when the state at ``frame`` is known and accelerations act after it.

    Before ``frame`` the point moves by ``G`` (Eq. (1)), exactly; from
    ``frame`` on, ``v_{k+1} = v_k + a_k`` with ``a_k ~ N(0, q**2)`` and
    ``x_{k+1} = x_k + v_k``, so ``(x_k, v_k)`` is Gaussian with mean
    ``Psi**(k - frame) (x, v)`` and covariance
    ``C_{k+1} = Psi C_k Psi^T + diag(0, q**2)``, ``C_frame = 0``.

    Parameters
    ----------
    state : array_like, shape (3,)
        The state at ``frame``, with positive depth at frame 1.
    frame : int
        From 1 to ``frames``.
    frames : int
        ``N >= 1``.
    process_noise : float
        ``q >= 0``.
    """
    state = checks.finite_array(state, "state", (3,))
    n = checks.count(frames, "frames")
    frame = checks.count(frame, "frame")
    if not 1 <= frame <= n:
        raise ValueError(f"frame must be from 1 to frames = {n}, got {frame}")
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    if not state[1] - (frame - 1) > 0:
        raise ValueError("state puts the point behind the camera at frame 1")
    mean = np.stack([model.G(state, k - frame) for k in range(1, n + 1)])
    psi = np.array([[1.0, 1.0], [0.0, 1.0]])
    cov = np.zeros((n, 2, 2))
    for k in range(frame, n):
        cov[k] = psi @ cov[k - 1] @ psi.T + np.diag([0.0, q**2])
    steps = np.where(np.arange(1, n) >= frame, q, 0.0)
    return TrackMoments(mean, cov, steps)


def posterior_bound(state, frame: int, frames: int, rho, prior_cov=None, process_noise=0.0):
    """The posterior bound on the state at every frame, over the accelerations after ``frame``.

    Tichavský et al. (1998), Eq. (21) (:func:`information`) with the expected
    measurement information ``E[I_k]`` (:func:`expected_measurement_information`)
    over the law of the track given the state at ``frame``
    (:func:`track_moments`), and ``q_k = 0`` before it. With
    ``process_noise = 0`` the track is known and this is
    :func:`conditional_bound` of it.

    Parameters
    ----------
    state : array_like, shape (3,)
        The true state at ``frame``.
    frame : int
    frames : int
    rho : float
    prior_cov : array_like, shape (3, 3), optional
    process_noise : float

    Returns
    -------
    ndarray, shape (N, 3, 3)
        As :func:`conditional_bound`.
    """
    t = track_moments(state, frame, frames, process_noise)
    lateral = t.mean[:, [0, 2]]
    info = expected_measurement_information(t.mean[:, 1], lateral, t.lateral_cov, rho)
    return _frame_bounds(information(info, prior_cov, t.process_noise))


def against_bound(errors, sds, bound_sd, z: float = Z) -> dict:
    """Estimates' errors and claimed SDs over trials, set against a bound's SD.

    The RMSE ``sqrt(mean(e**2))`` has the standard error
    ``sd(e**2) / (2 sqrt(T) RMSE)`` (the delta method), the mean claimed SD
    ``sd(s) / sqrt(T)``. A filter is flagged *overconfident* where its mean
    claimed SD lies more than ``z`` standard errors below the bound: it claims
    an uncertainty that no estimator achieves.

    Parameters
    ----------
    errors : array_like, shape (..., T)
        Estimate minus truth in each of ``T >= 2`` trials.
    sds : array_like, shape (..., T)
        The SD each estimate claims.
    bound_sd : array_like, broadcastable to shape (...)
        The bound's SD (the square root of a diagonal entry of a
        :func:`covariance_bound`), > 0.
    z : float
        Critical value, > 0 (default the two-sided 1 % point).

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
    t = e.shape[-1]
    mse = np.mean(e**2, axis=-1)
    rmse = np.sqrt(mse)
    with np.errstate(divide="ignore", invalid="ignore"):
        rmse_se = np.where(rmse > 0, np.std(e**2, axis=-1, ddof=1) / (2 * np.sqrt(t) * rmse), 0.0)
    mean_sd = np.mean(s, axis=-1)
    mean_sd_se = np.std(s, axis=-1, ddof=1) / np.sqrt(t)
    return {
        "rmse": rmse,
        "rmse_se": rmse_se,
        "mean_sd": mean_sd,
        "mean_sd_se": mean_sd_se,
        "rmse_ratio": rmse / b,
        "rmse_ratio_se": rmse_se / b,
        "sd_ratio": mean_sd / b,
        "sd_ratio_se": mean_sd_se / b,
        "overconfident": mean_sd + z * mean_sd_se < b,
        "trials": np.full(np.shape(rmse), t),
    }
