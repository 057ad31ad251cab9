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

**Tracks as they come.** Over a step ``s`` of the depth the motion is the
inverse-depth EKF's (``a += s s'``, the noise variance ``E[w**2] q**2 s``), and
the bearing at the depth ``t`` travelled since frame 1 is ``a / (1 + t w)``
(:mod:`depthcore.kalman.inverse_depth`). Each frame's update is
:func:`depthcore.kalman.ukf.step`: a missing bearing (``NaN``) or one the gate
skips is predicted through, the bearing's unscented predictive density is
reported, and so are the frames at which a sigma point lay behind the camera
(``1 + t w <= 0``).

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
from depthcore.kalman.inverse_depth import StateEstimate, travelled
from depthcore.problem import checks, predictive, signature
from depthcore.problem.gaussian import MeanAndCov, checked_track


def bearing(z, k: int, elapsed=None) -> np.ndarray:
    """``h_k(z) = a / (1 + t w)`` at states ``z = (a, w, s)`` of shape (..., 3).

    ``t`` is ``elapsed`` (broadcasting with ``z.shape[:-1]``), the depth
    travelled since frame 1, or ``k - 1``.
    """
    z = np.asarray(z, dtype=float)
    return z[..., 0] / (1.0 + travelled(k, elapsed) * z[..., 1])


def predict(z, S, process_noise: float = 0.0, step=1.0) -> MeanAndCov:
    """A step of motion: the EKF's prediction with the exact variance ``E[w**2] q**2 step``.

    Parameters as for :func:`depthcore.kalman.inverse_depth.predict`.

    Returns
    -------
    MeanAndCov
        Mean (..., 3) and covariance (..., 3, 3) of ``(a_{k+1}, w, s_{k+1})``.
    """
    mean, cov = inverse_depth.predict(z, S, process_noise, step)
    cov = cov.copy()
    cov[..., 2, 2] += np.asarray(S, dtype=float)[..., 1, 1] * process_noise**2 * np.asarray(step)
    return MeanAndCov(mean, cov)


def update(
    z,
    S,
    mu,
    rho,
    k: int,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = False,
    elapsed=None,
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
    elapsed : float or array_like, shape (...), optional
        The depth ``t`` travelled since frame 1 (default ``k - 1``); the
        condition is then ``1 + t w > 0``.
    """
    t = _points_axis(travelled(k, elapsed))

    def h(X):  # the bearing at the sigma points, refused behind the camera
        D = 1.0 + t * X[..., 1]
        if np.any(D == 0) or not (allow_behind_camera or np.all(D > 0)):
            raise ValueError(
                f"a sigma point of the inverse-depth UKF lies behind the camera at frame {k} "
                "(1 + (k - 1) w <= 0), where its bearing is not defined"
            )
        return X[..., 0] / D

    return ukf.measurement_update(z, S, mu, rho, h, sigma_points)


def _points_axis(t):
    """The depth travelled, per problem (...), broadcast over the sigma points' axis."""
    return t if np.ndim(t) == 0 else np.asarray(t)[..., None]


def to_state(
    z,
    S,
    k: int,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = False,
    elapsed=None,
) -> MeanAndCov:
    """The unscented transform of ``N(z, S)`` through ``(a / w, 1 / w + t, s / w)``.

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
    elapsed : float or array_like, shape (...), optional
        ``t``, the depth travelled since frame 1 (default ``k - 1``).

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
    t = _points_axis(travelled(k, elapsed))
    Y = np.stack(np.broadcast_arrays(X[..., 0] / w, 1.0 / w + t, X[..., 2] / w), axis=-1)
    Wm, Wc = sigma_points.weights()
    return ukf.unscented_transform(Y, Wm, Wc)


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    sigma_points=None,
    allow_behind_camera=False,
    steps=None,
    gate=None,
) -> ukf.UKFHistory:
    """The inverse-depth UKF over ``K`` bearings, batched, in its own coordinates.

    {parameters}
    sigma_points : depthcore.kalman.ukf.SigmaPoints or None
        ``None``: the default rule (:func:`depthcore.kalman.ukf.rule`).
    allow_behind_camera : bool
        See :func:`update`.

    Returns
    -------
    depthcore.kalman.ukf.UKFHistory
        ``means`` (..., K, 3), the mean of ``(a_k, w, s_k)`` after frame ``k``;
        ``covs`` (..., K, 3, 3); ``updates`` (..., K), each bearing's unscented
        predictive report; ``behind`` (..., K), where a sigma point had
        ``1 + t w <= 0``.
    """
    return _run(
        mu,
        rho,
        prior_mean,
        prior_cov,
        process_noise,
        sigma_points,
        allow_behind_camera,
        steps,
        gate,
    )[0]


def _run(mu, rho, prior_mean, prior_cov, q, sigma_points, allow_behind_camera, steps, gate):
    """:func:`run` and the checked frames."""
    sigma_points = ukf.rule(sigma_points)
    track = checked_track(mu, rho, prior_mean, prior_cov, steps, triples=False)
    q = checks.process_noise(q, "process_noise")
    g = predictive.gate(gate)
    f, regular = track.frames, track.frames.regular
    z, S = inverse_depth.prior(track.mean, track.cov)
    means, covs, reports = [], [], []
    for k in range(1, f.mu.shape[-1] + 1):
        if k > 1:
            z, S = predict(z, S, q) if regular else predict(z, S, q, f.steps[..., k - 2])
        t = _points_axis(travelled(k, None if regular else f.elapsed[..., k - 1]))

        def h(X, t=t):
            return X[..., 0] / (1.0 + t * X[..., 1])

        def depth(X, t=t):
            return 1.0 + t * X[..., 1]

        rho_k = f.row_rho if regular else f.rho[..., k - 1]
        try:
            out = ukf.step(
                z,
                S,
                f.mu[..., k - 1],
                rho_k,
                f.present[..., k - 1],
                g,
                sigma_points,
                True,
                h,
                depth,
            )
        except ValueError as exc:
            raise _refusal(exc, f"frame {k}") from None
        if not allow_behind_camera and np.any(out.behind & ~out.gated):
            raise ValueError(
                f"mu: a sigma point of the inverse-depth UKF lies behind the camera at frame {k} "
                "(1 + t w <= 0, t the depth travelled), where its bearing is not defined"
            )
        z, S = out.mean, out.cov
        means.append(z)
        covs.append(S)
        reports.append(out[2:])
    return ukf.history(means, covs, reports), f


def estimate(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    sigma_points=None,
    allow_behind_camera=False,
    steps=None,
    gate=None,
) -> StateEstimate:
    """The inverse-depth UKF's estimate of ``(x_K, y_K, v_K)``, batched.

    :func:`run`, then :func:`to_state` at frame ``K`` (at the depth travelled
    to it); parameters as for :func:`run`.

    Returns
    -------
    depthcore.kalman.inverse_depth.StateEstimate
        Mean (..., 3), covariance (..., 3, 3), the per-frame ``updates`` and
        ``behind`` (..., K).
    """
    sigma_points = ukf.rule(sigma_points)
    history, f = _run(
        mu,
        rho,
        prior_mean,
        prior_cov,
        process_noise,
        sigma_points,
        allow_behind_camera,
        steps,
        gate,
    )
    K = history.means.shape[-2]
    try:
        out = to_state(
            history.means[..., -1, :],
            history.covs[..., -1, :, :],
            K,
            sigma_points,
            allow_behind_camera,
            None if f.regular else f.elapsed[..., -1],
        )
    except ValueError as exc:
        raise _refusal(exc, "the last frame") from None
    return StateEstimate(out.mean, out.cov, history.updates, history.behind)


def _refusal(exc: ValueError, where: str) -> ValueError:
    """The refusal of a step that failed at ``where``: naming ``rho`` or ``mu``."""
    if "positive definite" in str(exc):
        return ValueError(
            "rho is too small for the inverse-depth UKF, which carries a covariance: "
            f"rounding left its covariance at {where} not positive definite"
        )
    return ValueError(f"mu: {exc}")
