"""The EKF and the UKF one bearing at a time, in constant time and memory per frame.

Recommended import: ``from depthcore.kalman import online``.

:class:`EKF` and :class:`UKF` hold the filter's Gaussian of the state at the
last frame and nothing of the past bearings. Each ``update(mu, rho, step)``
predicts the state over the step (Eq. (10) with the step ``s``: ``x <- x + s v``,
``y <- y + s``, the velocity's variance grown by ``q**2 |s|``, the step signed,
:mod:`depthcore.problem.frames`), reports the bearing's predictive density and
tail probability (:mod:`depthcore.problem.predictive`), skips it if it is
missing (``NaN``) or the gate says so, and otherwise incorporates it. After
``N`` frames the Gaussian is the batch door's at frame ``N``
(:func:`depthcore.kalman.ekf.run`; for the UKF the same predict-update
loop with :func:`depthcore.kalman.ukf.update` and :func:`unscented_predictive`),
the same arithmetic frame by frame.

Example
-------
>>> import numpy as np
>>> from depthcore.kalman import online
>>> f = online.EKF([0.0, 8.0, 0.0], np.eye(3), rho=0.01)
>>> for mu in (0.1, 0.2, float("nan"), 0.35):
...     step = f.update(mu)
>>> step.frame, bool(np.isnan(step.tail))
(4, False)
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import ekf, spatial, ukf
from depthcore.problem import checks, predictive
from depthcore.problem.gaussian import Gaussian, symmetric
from depthcore.problem.predictive import FrameEstimate


def unscented_predictive(n, C, rho, sigma_points=None) -> tuple[np.ndarray, np.ndarray]:
    """The UKF's predictive density of a bearing: the unscented transform of ``x / y``.

    Mean ``z = sum_i Wm_i Z_i`` and variance ``sum_i Wc_i (Z_i - z)**2 + rho**2``
    of the projected sigma points ``Z_i`` of ``N(n, C)`` (the innovation's
    moments of :func:`depthcore.kalman.ukf.measurement_update`).

    Parameters
    ----------
    n : array_like, shape (..., 3)
    C : array_like, shape (..., 3, 3)
    rho : float or array_like, shape (...)
    sigma_points : depthcore.kalman.ukf.SigmaPoints or None

    Returns
    -------
    mean, var : ndarray, shape (...)
    """
    rule = ukf.rule(sigma_points)
    X = rule.points(n, C)
    depth = X[..., 1]
    if np.any(depth == 0):
        raise ValueError("a sigma point has depth 0, where the bearing x/y is undefined")
    Wm, Wc = rule.weights()
    noise = (np.asarray(rho, dtype=float) ** 2)[..., None, None]
    z, S = ukf.unscented_transform((X[..., 0] / depth)[..., None], Wm, Wc, noise)
    return z[..., 0], S[..., 0, 0]


class _Online:
    """What :class:`EKF` and :class:`UKF` share: the checks, the frame count, the report."""

    def __init__(self, prior_mean, prior_cov, rho=None, process_noise=0.0, gate=None):
        prior = Gaussian.prior(prior_mean, prior_cov)
        self.prior = prior
        self.rho = None if rho is None else checks.positive_scalar(rho, "rho")
        self.process_noise = checks.nonnegative_scalar(process_noise, "process_noise")
        self.gate = predictive.gate(gate)
        self.frame = 0
        self.current: FrameEstimate | None = None

    def _report(self, mean, cov, log_p, tail, gated) -> FrameEstimate:
        self.frame += 1
        self.current = predictive.frame_estimate(self.frame, mean, cov, log_p, tail, gated)
        return self.current


class EKF(_Online):
    """The EKF one bearing at a time, in square-root information form (Eqs. (10)-(12)).

    Each frame is :func:`depthcore.kalman.ekf.information_predict` and
    :func:`depthcore.kalman.ekf.information_update`, as in
    :func:`depthcore.kalman.ekf.run`.

    Parameters
    ----------
    prior_mean : array_like, shape (3,)
        Prior mean of ``(x_1, y_1, v_1)``.
    prior_cov : array_like, shape (3, 3)
        Prior covariance, symmetric positive definite.
    rho : float or None
        The bearing noise SD, > 0, where :meth:`update` is given none.
    process_noise : float
        ``q >= 0``: the velocity's variance grows by ``q**2 s`` over a step ``s``.
    gate : float or None
        Skip a bearing whose two-sided predictive tail probability is below it.
    """

    def __init__(self, prior_mean, prior_cov, rho=None, process_noise=0.0, gate=None):
        super().__init__(prior_mean, prior_cov, rho, process_noise, gate)
        self._mean = self.prior.mean.copy()
        self._root = np.linalg.inv(np.linalg.cholesky(self.prior.cov))

    def update(self, mu, rho=None, step=1.0) -> FrameEstimate:
        """Add the next frame: predict by ``step``, report the bearing, gate it, update.

        ``mu``, ``rho`` (``None``: the filter's) and ``step`` as
        :func:`depthcore.problem.predictive.frame_inputs` checks them; returns a
        :class:`~depthcore.problem.predictive.FrameEstimate`.
        """
        mu, r, s = predictive.frame_inputs(mu, rho, step, self.rho, self.frame)
        n, R = self._mean, self._root
        if self.frame > 0:
            n, R = ekf.information_predict(n, R, self.process_noise, s)
        out = ekf.information_update(n, R, np.array(mu), np.array(r), True, self.gate)
        self._mean, self._root = out.mean, out.root
        R_inv = np.linalg.inv(out.root)
        cov = symmetric(R_inv @ R_inv.T)
        return self._report(out.mean, cov, out.log_predictive, out.tail, out.gated)


class UKF(_Online):
    """The UKF one bearing at a time: exact prediction (Eq. (10)), unscented update.

    Each frame is :func:`depthcore.kalman.ekf.predict` and
    :func:`depthcore.kalman.ukf.update`, as in :func:`depthcore.kalman.ukf.run`;
    the bearing's predictive density is :func:`unscented_predictive`.

    Parameters
    ----------
    prior_mean, prior_cov, rho, process_noise, gate
        As for :class:`EKF`.
    sigma_points : depthcore.kalman.ukf.SigmaPoints or None
        The sigma-point rule (``None``: the default rule).
    allow_behind_camera : bool
        As for :func:`depthcore.kalman.ukf.update`.
    """

    def __init__(
        self,
        prior_mean,
        prior_cov,
        rho=None,
        process_noise=0.0,
        gate=None,
        sigma_points=None,
        allow_behind_camera=False,
    ):
        super().__init__(prior_mean, prior_cov, rho, process_noise, gate)
        self.sigma_points = ukf.rule(sigma_points)
        self.allow_behind_camera = bool(allow_behind_camera)
        self._mean, self._cov = self.prior.mean.copy(), self.prior.cov.copy()

    def update(self, mu, rho=None, step=1.0) -> FrameEstimate:
        """Add the next frame, as :meth:`EKF.update` does."""
        mu, r, s = predictive.frame_inputs(mu, rho, step, self.rho, self.frame)
        n, C = self._mean, self._cov
        if self.frame > 0:
            n, C = ekf.predict(n, C, self.process_noise, s)
        log_p, tail, gated = np.nan, np.nan, False
        if not np.isnan(mu):
            z, var = unscented_predictive(n, C, r, self.sigma_points)
            log_p, tail = predictive.gaussian(mu, z, var)
            gated = bool(predictive.skipped(tail, True, self.gate))
            if not gated:
                n, C = ukf.update(
                    n,
                    C,
                    mu,
                    r,
                    sigma_points=self.sigma_points,
                    allow_behind_camera=self.allow_behind_camera,
                )
        self._mean, self._cov = n, C
        return self._report(n, C, log_p, tail, gated)


class Spatial(_Online):
    """The EKF or the UKF of a point in 3-D, one pair ``(x / y, h / y)`` at a time.

    Each frame is :func:`depthcore.kalman.spatial.predict` and the filter's update
    (:func:`depthcore.kalman.spatial.ekf_update` or ``ukf_update``), as in
    :func:`depthcore.kalman.spatial.run`. A pair's tail probability under the
    Gaussian predictive ``N(z, S)`` is that of a density below the observed pair's,
    ``exp(-d**2 / 2)`` with ``d`` the pair's Mahalanobis distance, exactly.

    Parameters
    ----------
    prior_mean : array_like, shape (5,)
        Prior mean of ``(x_1, y_1, v, h_1, w)``.
    prior_cov : array_like, shape (5, 5)
    rho, process_noise, gate
        As for :class:`EKF`.
    filter : {"ekf", "ukf"}
    """

    def __init__(self, prior_mean, prior_cov, rho=None, process_noise=0.0, gate=None, filter="ekf"):
        m = checks.finite_array(prior_mean, "prior_mean", (5,))
        P = checks.covariance(prior_cov, "prior_cov", 5)
        if filter not in spatial.UPDATES:
            raise ValueError(f"filter must be one of {sorted(spatial.UPDATES)}, got {filter!r}")
        self.rho = None if rho is None else checks.positive_scalar(rho, "rho")
        self.process_noise = checks.nonnegative_scalar(process_noise, "process_noise")
        self.gate = predictive.gate(gate)
        self.frame = 0
        self.current = None
        self.filter = filter
        self._mean, self._cov = m.copy(), P.copy()

    def update(self, mu, rho=None, step=1.0) -> FrameEstimate:
        """Add the next frame: predict by ``step``, report the pair, gate it, update.

        ``mu`` a pair (``NaN``: none this frame); ``rho`` and ``step`` as
        :func:`depthcore.problem.predictive.frame_inputs` checks them.
        """
        pair = checks.as_float(mu, "mu")
        if pair.shape != (2,) or np.isnan(pair[0]) != np.isnan(pair[1]) or np.any(np.isinf(pair)):
            raise ValueError(
                f"mu must be one pair (x / y, h / y), finite or both NaN, got {pair.tolist()}"
            )
        missing = bool(np.isnan(pair[0]))
        placeholder = np.nan if missing else 0.0  # the pair is checked above
        _, r, s = predictive.frame_inputs(placeholder, rho, step, self.rho, self.frame)
        n, C = self._mean, self._cov
        if self.frame > 0:
            n, C = spatial.predict(n, C, self.process_noise, s)
        log_p, tail, gated = np.nan, np.nan, False
        if not missing:
            if not n[1] > 0:
                raise ValueError(
                    f"mu: the {self.filter.upper()}'s prediction puts the point at or behind "
                    f"the camera at frame {self.frame + 1} (depth {n[1]:.6g})"
                )
            new_n, new_C, log_p, tail = spatial.UPDATES[self.filter](n, C, pair, r)
            log_p, tail = float(log_p), float(tail)
            gated = bool(predictive.skipped(tail, True, self.gate))
            if not gated:
                n, C = new_n, new_C
        self._mean, self._cov = n, C
        return self._report(n, C, log_p, tail, gated)
