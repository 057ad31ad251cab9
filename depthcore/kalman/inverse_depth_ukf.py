"""The unscented Kalman filter in inverse-depth coordinates.

Recommended import: ``from depthcore.kalman import inverse_depth_ukf``.

The coordinates and motion are those of the inverse-depth EKF
(:mod:`depthcore.kalman.inverse_depth`): ``a_k = x_k / y_1``, ``w = 1 / y_1``,
``s_k = v_k / y_1``, moving by ``a_{k+1} = a_k + s_k``, ``s_{k+1} = s_k + w a``
with ``a ~ N(0, q**2)``; the bearing of frame ``k`` is

    mu_k = h_k(a_k, w, s_k) + noise,   h_k = a_k / (1 + (k - 1) w).

Where that EKF linearises ``h_k`` at the predicted mean, this filter carries
the prediction's Gaussian through ``h_k`` by the unscented transform of
:mod:`depthcore.kalman.ukf` [julier1997]_ (its sigma points and
:func:`depthcore.kalman.ukf.measurement_update`, with ``h_k`` in place of ``x / y``).
At frame 1, ``h_1 = a_1`` is linear and the update is the Kalman filter's.

**The prediction** is linear in the state but for the noise ``w a``: its mean
is that of the EKF (:func:`depthcore.kalman.inverse_depth.predict`), and its
covariance takes the exact variance of ``w a`` under the Gaussian,
``E[w**2] q**2 = (w_bar**2 + S_ww) q**2``, where the EKF puts ``w_bar**2 q**2``
(what the unscented transform of the state augmented with ``a`` gives, since
``w a`` is a product of two Gaussian factors and the transform matches
second moments of products exactly).

**The prior** is carried to inverse depth as by the EKF, by linearisation at the
prior mean (:func:`depthcore.kalman.inverse_depth.prior`): the image of the paper's
prior under ``y -> 1 / y`` has no moments (its depth density is positive at
``y = 0``), so no sigma-point rule can match them.

**The estimate** at the last frame ``K`` is the unscented transform of the
Gaussian of ``(a_K, w, s_K)`` through ``(a / w, 1 / w + K - 1, s / w)``; every
sigma point must have a positive inverse depth. Near the small-noise limit
the filter agrees with the inverse-depth EKF (the transform and the
linearisation agree to first order in the spread).

References
----------
.. [julier1997] S. J. Julier and J. K. Uhlmann, "A new extension of the Kalman
   filter to nonlinear systems", Proc. SPIE 3068, 1997.
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import inverse_depth, ukf
from depthcore.problem import checks, model, signature
from depthcore.problem.gaussian import History, MeanAndCov, run_recursion


def bearing(z, k: int) -> np.ndarray:
    """``h_k(z) = a / (1 + (k - 1) w)`` at states ``z = (a, w, s)`` of shape (..., 3)."""
    z = np.asarray(z, dtype=float)
    return z[..., 0] / (1.0 + (k - 1) * z[..., 1])


def predict(z, S, process_noise: float = 0.0) -> MeanAndCov:
    """One frame of motion: the EKF's prediction with the exact variance ``E[w**2] q**2``.

    Parameters as for :func:`depthcore.kalman.inverse_depth.predict`.

    Returns
    -------
    MeanAndCov
        Mean (..., 3) and covariance (..., 3, 3) of ``(a_{k+1}, w, s_{k+1})``.
    """
    mean, cov = inverse_depth.predict(z, S, process_noise)
    cov = cov.copy()
    cov[..., 2, 2] += np.asarray(S, dtype=float)[..., 1, 1] * process_noise**2
    return MeanAndCov(mean, cov)


def update(
    z,
    S,
    mu,
    rho,
    k: int,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = False,
) -> MeanAndCov:
    """The unscented update by the bearing of frame ``k``,
    :func:`depthcore.kalman.ukf.measurement_update`.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Predicted mean of ``(a_k, w, s_k)``.
    S : array_like, shape (..., 3, 3)
    mu : array_like, shape (...)
    rho : float or array_like, shape (...)
    k : int
        The frame, ``>= 1``; every sigma point must have ``1 + (k - 1) w > 0``
        (the point in front of the camera at frame ``k``) unless
        ``allow_behind_camera``.
    sigma_points : depthcore.kalman.ukf.SigmaPoints
    allow_behind_camera : bool
        If true, only a sigma point at the pole ``1 + (k - 1) w = 0`` is refused,
        as :func:`depthcore.kalman.ukf.update` does.
    """

    def h(X):  # the bearing at the sigma points, refused behind the camera
        D = 1.0 + (k - 1) * X[..., 1]
        if np.any(D == 0) or not (allow_behind_camera or np.all(D > 0)):
            raise ValueError(
                f"a sigma point of the inverse-depth UKF lies behind the camera at frame {k} "
                "(1 + (k - 1) w <= 0), where its bearing is not defined"
            )
        return bearing(X, k)

    return ukf.measurement_update(z, S, mu, rho, h, sigma_points)


def to_state(
    z,
    S,
    k: int,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = False,
) -> MeanAndCov:
    """The unscented transform of ``N(z, S)`` through ``(a / w, 1 / w + k - 1, s / w)``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Mean of ``(a_k, w, s_k)``; every sigma point must have ``w > 0``
        (``w != 0`` if ``allow_behind_camera``).
    S : array_like, shape (..., 3, 3)
    k : int
        The frame.
    sigma_points : depthcore.kalman.ukf.SigmaPoints
    allow_behind_camera : bool

    Returns
    -------
    MeanAndCov
        Mean (..., 3) and covariance (..., 3, 3) of ``(x_k, y_k, v_k)``.
    """
    X = sigma_points.points(z, S)
    w = X[..., 1]
    if np.any(w == 0) or not (allow_behind_camera or np.all(w > 0)):
        raise ValueError(
            "a sigma point of the inverse-depth UKF's last estimate has inverse depth "
            f"{float(np.min(np.abs(w) if allow_behind_camera else w)):.3g}: its depth lies "
            "at or beyond infinity"
        )
    Y = np.stack([X[..., 0] / w, 1.0 / w + (k - 1), X[..., 2] / w], axis=-1)
    Wm, Wc = sigma_points.weights()
    return ukf.unscented_transform(Y, Wm, Wc)


@signature.documented
def run(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, sigma_points=None, allow_behind_camera=False
) -> History:
    """The inverse-depth UKF over ``K`` bearings, batched, in its own coordinates.

    {parameters}
    sigma_points : depthcore.kalman.ukf.SigmaPoints or None
        ``None``: the default rule (:func:`depthcore.kalman.ukf.rule`).
    allow_behind_camera : bool
        See :func:`update`.

    Returns
    -------
    means : ndarray, shape (..., K, 3)
        Mean of ``(a_k, w, s_k)`` after bearing ``k``.
    covs : ndarray, shape (..., K, 3, 3)
    """
    sigma_points = ukf.rule(sigma_points)
    mu, rho, m, P = model.batch_inputs(mu, rho, prior_mean, prior_cov, triples=False)
    q = checks.process_noise(process_noise, "process_noise")
    z, S = inverse_depth.prior(m, P)

    def update_k(z, S, mu_k, k):
        try:
            return update(z, S, mu_k, rho, k, sigma_points, allow_behind_camera)
        except ValueError as exc:
            raise _refusal(exc, f"frame {k}") from None

    return run_recursion(z, S, mu, lambda z, S, k: predict(z, S, q), update_k)


def estimate(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, sigma_points=None, allow_behind_camera=False
) -> MeanAndCov:
    """The inverse-depth UKF's estimate of ``(x_K, y_K, v_K)``, batched.

    :func:`run`, then :func:`to_state` at frame ``K``; parameters as for :func:`run`.

    Returns
    -------
    MeanAndCov
        Mean (..., 3) and covariance (..., 3, 3).
    """
    sigma_points = ukf.rule(sigma_points)
    means, covs = run(
        mu, rho, prior_mean, prior_cov, process_noise, sigma_points, allow_behind_camera
    )
    K = means.shape[-2]
    try:
        return to_state(
            means[..., -1, :], covs[..., -1, :, :], K, sigma_points, allow_behind_camera
        )
    except ValueError as exc:
        raise _refusal(exc, "the last frame") from None


def _refusal(exc: ValueError, where: str) -> ValueError:
    """The refusal of a step that failed at ``where``: naming ``rho`` or ``mu``."""
    if "positive definite" in str(exc):
        return ValueError(
            "rho is too small for the inverse-depth UKF, which carries a covariance: "
            f"rounding left its covariance at {where} not positive definite"
        )
    return ValueError(f"mu: {exc}")
