"""The EKF, the iterated EKF and the UKF for a point in 3-D, seen as bearing pairs.

Recommended import: ``from depthcore.kalman import spatial``.

The state is ``(x, y, v, h, w)`` and the pair ``(mu, nu) = (x / y, h / y)`` plus noise
of SD ``rho`` on each (:mod:`depthcore.problem.bearing_pairs`). The motion is linear
(Eq. (1) in each block over a signed step ``s``: ``x += s v``, ``h += s w``, ``y += s``,
the velocities' variances growing by ``q**2 |s|``), so both filters predict exactly
(textbook 19.2.1). They differ in the update:

* the EKF linearises the pair at the predicted mean (Eqs. (11)-(12) for both
  coordinates: rows ``(1 / y, -x / y**2, 0, 0, 0)`` and ``(0, -h / y**2, 0, 1 / y, 0)``);
* the iterated EKF relinearises at its own iterate, Gauss-Newton on
  ``|x - m|_P**2 + |z - (x / y, h / y)|**2 / rho**2`` as
  :func:`depthcore.kalman.iterated.update` does for one bearing (textbook 19.3,
  Bell and Cathey 1993): the first iterate is the EKF's update, the fixed point
  the mode of the one-step posterior, the covariance the Joseph form at the last
  linearisation;
* the UKF moves ``2 d + 1`` sigma points of the prediction
  (:class:`depthcore.kalman.ukf.SigmaPoints` with ``dim = 5``) through the pair and
  takes their moments.

:func:`run` runs any of them over a track with gaps, noise per frame and signed steps, and
reports each pair's log predictive density. A missing frame (a row of ``NaN``) is
predicted through.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.kalman import linear
from depthcore.kalman.iterated import MAX_ITERATIONS, still_descending
from depthcore.kalman.second_order import damped_step
from depthcore.kalman.ukf import SigmaPoints, unscented_transform
from depthcore.problem import checks
from depthcore.problem.bearing_pairs import check

#: The state's dimension, ``(x, y, v, h, w)``.
DIM = 5
#: The sigma points of the UKF in 3-D, with Julier's ``kappa = 3 - dim``.
SIGMA_POINTS = SigmaPoints(dim=DIM, kappa=3.0 - DIM)
_LOG_2PI = float(np.log(2.0 * np.pi))


class SpatialHistory(NamedTuple):
    """A Gaussian filter's states at every frame of tracks of pairs, batch shape (...).

    Attributes
    ----------
    means : ndarray, shape (..., N, 5)
    covs : ndarray, shape (..., N, 5, 5)
    log_predictive : ndarray, shape (..., N)
        Each pair's log predictive density (``NaN`` at a missing frame).
    """

    means: np.ndarray
    covs: np.ndarray
    log_predictive: np.ndarray

    @property
    def mean(self) -> np.ndarray:
        """The state's mean at the last frame, (..., 5)."""
        return self.means[..., -1, :]

    @property
    def cov(self) -> np.ndarray:
        """The state's covariance at the last frame, (..., 5, 5)."""
        return self.covs[..., -1, :, :]


def predict(m, P, process_noise, step):
    """Textbook 19.2.1 over a signed step: ``F_s m`` and ``F_s P F_s^T`` plus ``q**2 |s|``.

    ``m`` (..., 5), ``P`` (..., 5, 5), ``step`` (...); returns the mean and covariance.
    """
    s = np.asarray(step, dtype=float)
    mean, cov = transition(m, P, s, np.square(np.float64(process_noise)) * np.abs(s))
    mean[..., 1] += s
    return mean, cov


def transition(m, P, step, noise):
    """``F m`` and ``F P F^T``, ``noise`` added to both velocities' variances (textbook 19.2.1).

    ``F`` is the identity with ``step`` (an ndarray, (...)) at (0, 2) and (3, 4): the lateral
    coordinates move by ``step`` times their velocities. ``m`` (..., 5), ``P``
    (..., 5, 5), ``noise`` (...); returns the mean and covariance.
    """
    F = np.broadcast_to(np.eye(DIM), step.shape + (DIM, DIM)).copy()
    F[..., 0, 2] = F[..., 3, 4] = step
    mean = np.einsum("...ij,...j->...i", F, m)
    cov = F @ P @ np.swapaxes(F, -1, -2)
    cov[..., 2, 2] += noise
    cov[..., 4, 4] += noise
    return mean, cov


def measurement(states) -> np.ndarray:
    """The pair ``(x / y, h / y)`` of states (..., 5): (..., 2)."""
    return np.stack([states[..., 0] / states[..., 1], states[..., 3] / states[..., 1]], axis=-1)


def jacobian(m) -> np.ndarray:
    """The pair's Jacobian at states ``m`` (..., 5): (..., 2, 5)."""
    x, y, h = m[..., 0], m[..., 1], m[..., 3]
    J = np.zeros(m.shape[:-1] + (2, DIM))
    J[..., 0, 0], J[..., 0, 1] = 1.0 / y, -x / y**2
    J[..., 1, 3], J[..., 1, 1] = 1.0 / y, -h / y**2
    return J


def gain_update(m, P, z, predicted, S, cross, H=None, rho2=None):
    """Textbook 19.2.2: the update from the pair's predicted mean, covariance ``S`` (..., 2, 2)
    and ``Cov[pair, state]`` ``cross`` (..., 2, d), of a state ``(m, P)`` of any dimension d.

    With the linearised measurement ``H`` (..., 2, d) and the noise variance ``rho2``
    (..., 1, 1) the covariance is the Joseph form's (:func:`depthcore.kalman.linear.joseph`),
    positive semi-definite whatever the rounding (a noise tiny beside the prior); else
    ``P - K S K^T``. Returns the mean, the covariance, the pair's log predictive density
    under ``N(pred, S)`` and its tail probability, the probability of a density below the
    observed pair's: ``exp(-d**2 / 2)`` for ``d`` its Mahalanobis distance, exactly.
    """
    K = np.swapaxes(np.linalg.solve(S, cross), -1, -2)  # Cov[state, pair] S^{-1}: (..., 5, 2)
    r = z - predicted
    mean = m + np.einsum("...ij,...j->...i", K, r)
    if H is None:
        cov = P - K @ S @ np.swapaxes(K, -1, -2)
        cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    else:
        cov = linear.joseph(P, K, H, rho2 * np.eye(2))
    sol = np.linalg.solve(S, r[..., None])[..., 0]
    d2 = np.maximum(np.sum(r * sol, axis=-1), 0.0)
    log_p = -0.5 * (2 * _LOG_2PI + np.linalg.slogdet(S)[1] + d2)
    return mean, cov, log_p, np.exp(-0.5 * d2)


def ekf_update(m, P, z, rho):
    """The EKF's update by the pair ``z`` (..., 2), noise SD ``rho`` (...) on each coordinate."""
    J = jacobian(m)
    rho2 = np.asarray(rho, dtype=float)[..., None, None] ** 2
    S = J @ P @ np.swapaxes(J, -1, -2) + rho2 * np.eye(2)
    return gain_update(m, P, z, measurement(m), S, J @ P, J, rho2)


def ukf_update(m, P, z, rho, sigma_points: SigmaPoints = SIGMA_POINTS):
    """The UKF's update by the pair ``z``: the sigma points' moments of the pair."""
    X = sigma_points.points(m, P)
    if np.any(X[..., 1] <= 0):
        raise ValueError("a sigma point lies at or behind the camera, where x / y is undefined")
    Z = measurement(X)
    Wm, Wc = sigma_points.weights()
    rho2 = np.asarray(rho, dtype=float)[..., None, None] ** 2
    moments = unscented_transform(Z, Wm, Wc)
    S = moments.cov + rho2 * np.eye(2)
    cross = np.einsum(
        "i,...ia,...ib->...ab", Wc, Z - moments.mean[..., None, :], X - m[..., None, :]
    )
    return gain_update(m, P, z, moments.mean, S, cross)


def _objective(x, m, P_chol, z, r2):
    """``|x - m|_P**2 + |z - (x / y, h / y)|**2 / rho**2`` (...), ``inf`` behind the camera."""
    d = np.linalg.solve(P_chol, (x - m)[..., None])[..., 0]
    front = x[..., 1] > 0
    r = z - measurement(np.where(front[..., None], x, 1.0))
    return np.where(front, np.sum(d**2, axis=-1) + np.sum(r**2, axis=-1) / r2, np.inf)


def iterated_update(m, P, z, rho, max_iterations: int = MAX_ITERATIONS):
    """The iterated EKF's update by the pair ``z`` (module docstring), from ``x_0 = m``.

    ``x_{i+1} = m + K_i (z - g(x_i) - H_i (m - x_i))``, ``K_i = P H_i^T (H_i P H_i^T +
    rho**2 I)^{-1}`` with ``g`` the pair and ``H_i`` its Jacobian at ``x_i``, each step
    halved where it would leave the camera's front or raise the objective
    (:func:`depthcore.kalman.second_order.damped_step`), stopped by
    :func:`depthcore.kalman.iterated.still_descending`. ``m`` (..., 5), ``P`` (..., 5, 5),
    ``z`` (..., 2), ``rho`` (...). Returns the mean, the Joseph-form covariance at the last
    linearisation, and the log predictive density and tail probability of the EKF's
    linearisation at ``m`` (as :func:`depthcore.kalman.iterated.bearing_predictive`).
    """
    r2 = np.asarray(rho, dtype=float) ** 2
    eye = np.eye(2)

    def gain(x):
        H = jacobian(x)
        S = H @ P @ np.swapaxes(H, -1, -2) + r2[..., None, None] * eye
        return H, S, np.swapaxes(np.linalg.solve(S, H @ P), -1, -2)

    H, S, _ = gain(m)
    _, _, log_p, tail = gain_update(m, P, z, measurement(m), S, H @ P)
    P_chol = np.linalg.cholesky(P)
    x, at = m.copy(), m.copy()
    f = _objective(x, m, P_chol, z, r2)
    active = np.ones(m.shape[:-1], dtype=bool)
    for _ in range(max_iterations):
        if not np.any(active):
            break
        at = np.where(active[..., None], x, at)
        H, _, K = gain(x)
        residual = z - measurement(x) - np.einsum("...ij,...j->...i", H, m - x)
        step = m + np.einsum("...ij,...j->...i", K, residual) - x
        x_new, f_new = damped_step(x, step, f, lambda y: _objective(y, m, P_chol, z, r2))
        d = np.linalg.solve(P_chol, (x_new - x)[..., None])[..., 0]
        x = np.where(active[..., None], x_new, x)
        active = active & still_descending(np.sqrt(np.sum(d**2, axis=-1)), f_new, f)
        f = np.where(active, f_new, f)
    H, _, K = gain(at)
    cov = linear.joseph(P, K, H, r2[..., None, None] * eye)
    return x, cov, log_p, tail


#: The updates by name.
UPDATES = {"ekf": ekf_update, "iterated": iterated_update, "ukf": ukf_update}
_LABELS = {"ekf": "EKF", "iterated": "iterated EKF", "ukf": "UKF"}


def run(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, steps=None, filter: str = "ekf"
) -> SpatialHistory:
    """The EKF, the iterated EKF or the UKF over tracks of pairs, batched.

    Parameters
    ----------
    mu : array_like, shape (N, 2) or (..., N, 2)
        Pairs ``(x / y, h / y)``; a row of ``NaN`` at a missing frame.
    rho : float or array_like, shape (...) or (..., N)
    prior_mean : array_like, shape (5,) or (..., 5)
        The prior of ``(x_1, y_1, v, h_1, w)`` at frame 1.
    prior_cov : array_like, shape (5, 5) or (..., 5, 5)
    process_noise : float
        ``q >= 0`` on both velocities.
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
        The depth's signed change between frames.
    filter : {"ekf", "iterated", "ukf"}

    Returns
    -------
    SpatialHistory

    Raises
    ------
    ValueError
        One line naming the argument; ``mu`` where a prediction puts the point at or
        behind the camera.
    """
    if filter not in UPDATES:
        raise ValueError(f"filter must be one of {sorted(UPDATES)}, got {filter!r}")
    pairs, m, P, q = checked(mu, rho, prior_mean, prior_cov, process_noise, steps)
    label = _LABELS[filter]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        try:
            means, covs, log_p = _loop(pairs, m, P, q, UPDATES[filter], label)
        except np.linalg.LinAlgError:
            raise ValueError(
                f"mu and rho lead the {label} to a covariance that is not positive definite: "
                "a rho tiny beside the prior loses it to rounding"
            ) from None
    return history(pairs, means, covs, log_p, label)


def checked(mu, rho, prior_mean, prior_cov, process_noise, steps):
    """:func:`run`'s inputs checked: the pairs, the prior's means (B, 5) and covariances
    (B, 5, 5) for their ``B`` rows, and ``q``; refusals name the argument."""
    pairs = check(mu, rho, steps)
    B = len(pairs.mu)
    m = checks.finite_array(prior_mean, "prior_mean")
    P = checks.finite_array(prior_cov, "prior_cov")
    if m.shape[-1:] != (DIM,) or P.shape[-2:] != (DIM, DIM):
        raise ValueError(
            f"prior_mean and prior_cov must have shapes (5,) and (5, 5), (x, y, v, h, w), "
            f"got {m.shape} and {P.shape}"
        )
    P = checks.covariances(P, "prior_cov", DIM)
    m = np.broadcast_to(m, pairs.batch + (DIM,)).reshape(B, DIM).copy()
    P = np.broadcast_to(P, pairs.batch + (DIM, DIM)).reshape(B, DIM, DIM).copy()
    return pairs, m, P, checks.process_noise(process_noise, "process_noise")


def history(pairs, means, covs, log_p, label: str) -> SpatialHistory:
    """Rows (B, N, ...) of a filter named ``label`` as a :class:`SpatialHistory` of the pairs'
    batch shape; refused, naming the arguments, where they overflowed."""
    if not (np.all(np.isfinite(means)) and np.all(np.isfinite(covs))):
        raise ValueError(
            f"mu, rho, prior_mean and prior_cov overflow the {label} in double "
            "precision; give values nearer the track's scale"
        )
    shape, N = pairs.batch, pairs.mu.shape[1]
    return SpatialHistory(
        means.reshape(shape + (N, DIM)),
        covs.reshape(shape + (N, DIM, DIM)),
        log_p.reshape(shape + (N,)),
    )


def _loop(pairs, m, P, q, update, label):
    """:func:`run`'s predict-update loop on checked inputs: means, covariances, log densities."""
    B, N = pairs.present.shape
    means, covs = np.empty((B, N, DIM)), np.empty((B, N, DIM, DIM))
    log_p = np.full((B, N), np.nan)
    for k in range(N):
        if k:
            m, P = predict(m, P, q, pairs.steps[:, k - 1])
        here = pairs.present[:, k]
        if np.any(here & ~(m[:, 1] > 0)):
            raise ValueError(
                f"mu: the {label}'s prediction puts the point at or behind the camera "
                f"at frame {k + 1} (depth {float(np.min(m[here, 1])):.6g})"
            )
        if np.any(here):
            rows = np.flatnonzero(here)
            new_m, new_P, lp, _ = update(m[rows], P[rows], pairs.mu[rows, k], pairs.rho[rows, k])
            m[rows], P[rows], log_p[rows, k] = new_m, new_P, lp
        means[:, k], covs[:, k] = m, P
    return means, covs, log_p


def smoother(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, steps=None, filter: str = "ekf"
) -> tuple:
    """:func:`run` and the Rauch-Tung-Striebel smoother over its Gaussians (textbook 19.2.3).

    The motion is linear (:func:`predict`), so the backward recursions run over the
    filter's own Gaussians with ``F_s`` per step
    (:func:`depthcore.kalman.linear.fixed_interval_smoother`): for the EKF the extended
    Kalman smoother, for the UKF the unscented one, as the plane's
    (:func:`depthcore.registry.adapters.gaussian_smoother`). Parameters as for :func:`run`.

    Returns
    -------
    history : SpatialHistory
        The filter's, means (..., N, 5) and covariances (..., N, 5, 5).
    smoothed : depthcore.problem.gaussian.MeanAndCov
        The state at every frame given all pairs, the same shapes; at frame ``N`` the
        filter's.
    """
    h = run(mu, rho, prior_mean, prior_cov, process_noise, steps, filter)
    s = np.ascontiguousarray(check(mu, rho, steps).steps).reshape(h.means.shape[:-2] + (-1,))
    q = checks.process_noise(process_noise, "process_noise")
    pm, pc = predict(h.means[..., :-1, :], h.covs[..., :-1, :, :], q, s)
    # entry 0, the prior, is not used by the backward recursions: the filter's first stands in
    pm = np.concatenate([h.means[..., :1, :], pm], axis=-2)
    pc = np.concatenate([h.covs[..., :1, :, :], pc], axis=-3)
    F = np.broadcast_to(np.eye(DIM), s.shape + (DIM, DIM)).copy()
    F[..., 0, 2] = F[..., 3, 4] = s
    filtered = linear.FilterResult(h.means, h.covs, pm, pc, h.log_predictive)
    return h, linear.fixed_interval_smoother(filtered, F)
