"""The EKF in modified polar coordinates [aidala1983]_, carried over to the paper's camera.

Recommended import: ``from depthcore.kalman import modified_polar``.

**The coordinates.** Bearings-only tracking in the plane writes the relative
state as bearing ``beta``, bearing rate, range rate over range and inverse range
[aidala1983]_: the bearing is then a state component (the measurement is
linear), and the inverse range, the one component the bearings cannot
observe without an observer manoeuvre, is kept apart from the others. On the
paper's problem the bearing is the image coordinate ``mu = x / y``, the range
along the line of sight is replaced by the depth ``y`` (the camera looks and
moves along ``y``), and the depth's rate is known: ``y`` grows by one unit per
frame. So at frame ``k``

* the bearing is ``mu_k = x_k / y_k``;
* the range rate over range is ``(dy/dt) / y_k = 1 / y_k``, the inverse depth
  ``omega_k``: the two coordinates of [aidala1983]_ coincide;
* the bearing rate is ``d(x / y)/dt = (v y - x dy/dt) / y**2 = nu_k - mu_k omega_k``
  with ``nu_k = v_k / y_k``, a function of ``(mu_k, omega_k, nu_k)``.

The state is therefore the three numbers ``u_k = (mu_k, omega_k, nu_k) = (x_k,
1, v_k) / y_k``, carrying the bearing rate through ``nu_k`` (the lateral
velocity over depth) rather than as its own coordinate. With ``D = 1 +
omega_k`` (so that ``y_{k+1} / y_k = D``), the motion ``x += v``, ``y += 1``,
``v += a`` with ``a ~ N(0, q**2)`` becomes

    mu_{k+1} = (mu_k + nu_k) / D,   omega_{k+1} = omega_k / D,
    nu_{k+1} = (nu_k + omega_k a) / D,

nonlinear (:func:`transition`, Jacobian :func:`transition_jacobian`), and the
bearing ``mu_k + noise`` is linear. The EKF linearises the motion at the
filtered mean (with the noise ``omega_k a / D`` evaluated at it, variance
``(omega q / D)**2``, as the inverse-depth EKF does) and updates by the exact
Kalman update (:func:`depthcore.kalman.linear.update`, textbook 19.2.2).

**Relation to the inverse-depth EKF** (:mod:`depthcore.kalman.inverse_depth`). Its
state ``z_k = (a_k, w, s_k) = (x_k, 1, v_k) / y_1`` is anchored at frame 1;
``u_k`` is the same construction anchored at frame ``k``, and
``u_k = phi_k(z_k) = z_k / (1 + (k - 1) w)``, a projective map with
``phi_1`` the identity. The prior is the same (:func:`depthcore.kalman.inverse_depth.prior`),
so the two filters agree at frame 1. Thereafter each filter puts the
nonlinearity in a different place (the inverse-depth EKF in the bearing, this
one in the motion), and the chain rule makes them agree exactly up to one
point: from Gaussians that correspond through ``phi_{k-1}`` (mean mapped,
covariance by its Jacobian), the predictions at frame ``k`` correspond through
``phi_k``, and so do the updated covariances, while the updated means differ
by the second-order remainder of ``phi_k`` over the update's step:
``u_k = phi_k(z_bar) + J (z_k - z_bar)`` where the inverse-depth EKF's mean maps
to ``phi_k(z_k)`` (``z_bar`` the predicted mean, ``J`` the Jacobian of
``phi_k`` there): the modified-polar Gaussian is the inverse-depth one carried
by the tangent of ``phi_k`` at the predicted mean, not at the updated one. The
remainder vanishes when the update leaves the inverse depth unchanged
(``phi_k`` is linear in ``(a, s)`` at fixed ``w``), so the filters coincide
when the depth is known. Otherwise the next step linearises each filter at a
different point, and the tangents there differ at first order in the update's
step, weighted by the inverse depth's spread. That is no small remainder when
the prior is broad: on Figure 2's bearings with the paper's prior the inverse
depth is still almost unknown after the second bearing (its SD above one), and
the two filters' depth SDs at time 3 differ more than twofold.

**Uneven steps** (:mod:`depthcore.problem.frames`). Over a step ``s`` of the
depth (``y_{k+1} = y_k + s``, ``x_{k+1} = x_k + s v_k``, ``v_{k+1} = v_k + a``
with ``a ~ N(0, q**2 s)``) the same division by the new depth gives, with
``D = 1 + s omega_k`` (so that ``y_{k+1} / y_k = D``),

    mu_{k+1} = (mu_k + s nu_k) / D,   omega_{k+1} = omega_k / D,
    nu_{k+1} = (nu_k + omega_k a) / D,

the noise on ``nu`` of variance ``(omega q / D)**2 s``: :func:`transition`,
:func:`transition_jacobian` and :func:`predict` with ``step``; ``s = 1`` is the
motion above. A missing bearing (``NaN``) is predicted through.

The estimate at the last frame ``K`` is ``(x_K, y_K, v_K) = (mu_K, 1, nu_K) /
omega_K``, linearised at the mean (:func:`depthcore.kalman.inverse_depth.to_state` at
frame 1, the anchor being the current frame).

References
----------
.. [aidala1983] V. J. Aidala and S. E. Hammel, "Utilization of modified polar
   coordinates for bearings-only tracking", IEEE Transactions on Automatic
   Control 28(3), 283-294, 1983.
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import inverse_depth, linear
from depthcore.problem import checks, predictive, signature
from depthcore.problem.gaussian import History, MeanAndCov, checked_track, run_recursion

#: The measurement matrix (the bearing is the first coordinate).
H = np.array([[1.0, 0.0, 0.0]])
H.setflags(write=False)


def _ratio(u, step=1.0) -> np.ndarray:
    """``D = 1 + s omega`` at states (..., 3); refuses a point that would pass behind the camera."""
    s = np.asarray(step, dtype=float)
    D = 1.0 + s * u[..., 1]
    if not np.all(D > 0):
        raise ValueError(
            "the modified-polar EKF's mean inverse depth is <= -1 / step "
            f"(min {float(np.min(u[..., 1])):.6g}): the next depth y + step would not be "
            "positive"
        )
    return D


def transition(u, step=1.0) -> np.ndarray:
    """A step of motion without noise, ``(mu + s nu, omega, nu) / (1 + s omega)``.

    Parameters
    ----------
    u : array_like, shape (..., 3)
        ``(mu_k, omega_k, nu_k)``.
    step : float or array_like, shape (...)
        ``s != 0``, the depth's signed change (1: a frame of the paper).

    Returns
    -------
    ndarray, shape (..., 3)
        ``(mu_{k+1}, omega_{k+1}, nu_{k+1})``.
    """
    u = np.asarray(u, dtype=float)
    s = np.asarray(step, dtype=float)
    D = 1.0 + s * u[..., 1]
    moved = np.broadcast_arrays(u[..., 0] + s * u[..., 2], u[..., 1], u[..., 2])
    return np.stack(moved, axis=-1) / D[..., None]


def transition_jacobian(u, step=1.0) -> np.ndarray:
    """The Jacobian of :func:`transition` at ``u`` (..., 3), shape (..., 3, 3)."""
    u = np.asarray(u, dtype=float)
    s = np.asarray(step, dtype=float)
    mu, omega, nu = u[..., 0], u[..., 1], u[..., 2]
    D = 1.0 + s * omega
    J = np.zeros(D.shape + (3, 3))
    J[..., 0, 0] = 1.0 / D
    J[..., 0, 1] = -s * (mu + s * nu) / D**2
    J[..., 0, 2] = s / D
    J[..., 1, 1] = 1.0 / D**2
    J[..., 2, 1] = -s * nu / D**2
    J[..., 2, 2] = 1.0 / D
    return J


def predict(u, U, process_noise: float = 0.0, step=1.0) -> MeanAndCov:
    """The EKF's prediction over a step: the motion at the mean, the covariance by its Jacobian.

    Parameters
    ----------
    u : array_like, shape (..., 3)
        Filtered mean of ``(mu_k, omega_k, nu_k)``; ``1 + s omega > 0``.
    U : array_like, shape (..., 3, 3)
    process_noise : float
        ``q >= 0``; adds ``(omega q / D)**2 s`` to ``nu``'s variance.
    step : float or array_like, shape (...)
        ``s != 0``, signed (default 1, the paper's frame).

    Returns
    -------
    MeanAndCov
        Predicted mean (..., 3) and covariance (..., 3, 3) at the next frame.
    """
    u = np.asarray(u, dtype=float)
    U = np.asarray(U, dtype=float)
    s = np.asarray(step, dtype=float)
    D = _ratio(u, s)
    J = transition_jacobian(u, s)
    cov = J @ U @ np.swapaxes(J, -1, -2)
    cov[..., 2, 2] += (u[..., 1] * process_noise / D) ** 2 * np.abs(s)
    return MeanAndCov(transition(u, s), 0.5 * (cov + np.swapaxes(cov, -1, -2)))


def bearing_predictive(u, U, rho) -> tuple[np.ndarray, np.ndarray]:
    """The predictive density of the bearing, ``N(u_0, U_00 + rho**2)`` (textbook 19.2.2).

    Parameters
    ----------
    u : array_like, shape (..., 3)
        Predicted mean.
    U : array_like, shape (..., 3, 3)
    rho : float or array_like, shape (...)

    Returns
    -------
    mean, var : ndarray, shape (...)
    """
    u = np.asarray(u, dtype=float)
    return u[..., 0], np.asarray(U, dtype=float)[..., 0, 0] + np.asarray(rho, dtype=float) ** 2


def update(u, U, mu, rho) -> MeanAndCov:
    """The Kalman update by the bearing, ``mu = u_0 + noise`` (textbook 19.2.2).

    Parameters
    ----------
    u : array_like, shape (..., 3)
    U : array_like, shape (..., 3, 3)
    mu : array_like, shape (...)
    rho : float or array_like, shape (...)
    """
    r2 = np.asarray(rho, dtype=float) ** 2
    out = linear.update(u, U, np.asarray(mu, dtype=float)[..., None], H, r2[..., None, None])
    return MeanAndCov(out.mean, out.cov)


def anchor_map(z, k: int) -> np.ndarray:
    """``phi_k``: the inverse-depth state ``(a_k, w, s_k)`` as ``(mu_k, omega_k, nu_k)``.

    ``phi_k(z) = z / (1 + (k - 1) w)``, shape (..., 3).
    """
    z = np.asarray(z, dtype=float)
    return z / (1.0 + (k - 1) * z[..., 1:2])


def anchor_jacobian(z, k: int) -> np.ndarray:
    """The Jacobian of :func:`anchor_map` at ``z`` (..., 3), shape (..., 3, 3)."""
    z = np.asarray(z, dtype=float)
    D = 1.0 + (k - 1) * z[..., 1]
    J = np.eye(3) / D[..., None, None]
    J[..., :, 1] -= (k - 1) * z / D[..., None] ** 2
    return J


@signature.documented
def run(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, steps=None, gate=None
) -> History:
    """The modified-polar EKF over ``K`` bearings, batched, in its own coordinates.

    As :func:`depthcore.kalman.inverse_depth.run` (the same arguments, a
    :class:`~depthcore.problem.gaussian.History` of ``K`` frames with its
    ``updates``), with the means and covariances of ``(mu_k, omega_k, nu_k)``:
    :func:`predict` over each step, :func:`update` at each bearing, a missing
    or gated bearing predicted through (the predictive density
    :func:`bearing_predictive`).

    {parameters}
    """
    track = checked_track(mu, rho, prior_mean, prior_cov, steps, triples=False)
    q = checks.process_noise(process_noise, "process_noise")
    g = predictive.gate(gate)
    f, regular = track.frames, track.frames.regular
    u, U = inverse_depth.prior(track.mean, track.cov)  # at frame 1 the two coordinates coincide

    def rho_at(k):
        return f.row_rho if regular else f.rho[..., k - 1]

    def predict_k(u, U, k):
        try:
            return predict(u, U, q) if regular else predict(u, U, q, f.steps[..., k - 2])
        except ValueError as exc:
            raise ValueError(f"mu: {exc}") from None

    return run_recursion(
        u,
        U,
        f.mu,
        predict_k,
        lambda u, U, mu_k, k: update(u, U, mu_k, rho_at(k)),
        f.present,
        lambda u, U, k: bearing_predictive(u, U, rho_at(k)),
        g,
    )


def estimate(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, steps=None, gate=None
) -> inverse_depth.StateEstimate:
    """The modified-polar EKF's estimate of ``(x_K, y_K, v_K)``, batched.

    :func:`run`, then ``(mu_K, 1, nu_K) / omega_K`` linearised at the mean.
    Parameters as for :func:`run`.

    Returns
    -------
    depthcore.kalman.inverse_depth.StateEstimate
        Mean (..., 3), covariance (..., 3, 3) and the per-frame ``updates`` (..., K).
    """
    history = run(mu, rho, prior_mean, prior_cov, process_noise, steps, gate)
    return inverse_depth.last_state(history, 1)
