"""The online EKF and UKF for many features at once, batched over the features.

Recommended import: ``from depthcore.kalman import features``.

:class:`Features` runs ``B`` independent filters of :mod:`depthcore.kalman.online`
side by side, each frame one call of the batched functions those filters call one
feature at a time: for bearings the EKF's square-root information predict and update
(:func:`depthcore.kalman.ekf.information_predict`,
:func:`depthcore.kalman.ekf.information_update`, Eqs. (10)-(12)) or the UKF's
(:func:`depthcore.kalman.ekf.predict`, :func:`depthcore.kalman.ukf.update`); for
pairs :func:`depthcore.kalman.spatial.predict` and the filter's update of
:data:`depthcore.kalman.spatial.UPDATES`. Row ``b`` of each answer is what
:class:`depthcore.kalman.online.EKF`, :class:`depthcore.kalman.online.UKF` or
:class:`depthcore.kalman.online.Spatial` answers for feature ``b`` alone, to rounding.
There is no gate.
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import ekf, spatial, ukf
from depthcore.kalman.online import unscented_predictive
from depthcore.problem import checks, predictive
from depthcore.problem.gaussian import symmetric


class Features:
    """The EKF or the UKF of ``B`` features at once, one frame per :meth:`update`.

    Parameters
    ----------
    prior_mean : array_like, shape (B, 3) or (B, 5)
        Each feature's prior mean of ``(x_1, y_1, v)`` (a bearing per frame) or of
        ``(x_1, y_1, v, h_1, w)`` (a pair ``(x / y, h / y)`` per frame).
    prior_cov : array_like, shape (B, 3, 3) or (B, 5, 5)
    rho : float, array_like of shape (B,), or None
        The noise SD (> 0) where :meth:`update` is given none.
    process_noise : float
        ``q >= 0``, on every feature's velocities.
    filter : {"ekf", "ukf"}
    sigma_points : depthcore.kalman.ukf.SigmaPoints or None
        The UKF's rule for bearings (``None``: the default); pairs use
        :data:`depthcore.kalman.spatial.SIGMA_POINTS`.
    allow_behind_camera : bool
        As for :func:`depthcore.kalman.ukf.update` (bearings).
    """

    def __init__(
        self,
        prior_mean,
        prior_cov,
        rho=None,
        process_noise=0.0,
        filter="ekf",
        sigma_points=None,
        allow_behind_camera=False,
    ):
        m, P = predictive.batch_prior(prior_mean, prior_cov)
        if filter not in spatial.UPDATES:
            raise ValueError(f"filter must be one of {sorted(spatial.UPDATES)}, got {filter!r}")
        self.filter, self.dim = filter, m.shape[1]
        self.rho = None if rho is None else predictive.per_feature(rho, "rho", len(m))
        self.process_noise = checks.process_noise(process_noise)
        self.sigma_points = ukf.rule(sigma_points)
        self.allow_behind_camera = bool(allow_behind_camera)
        self.frame = 0
        self.current: predictive.FrameEstimates | None = None
        self._mean, self._cov = m.copy(), P.copy()
        if self.dim == 3 and filter == "ekf":
            self._cov = np.linalg.inv(np.linalg.cholesky(P))  # the information's root

    def update(self, mu, rho=None, step=1.0) -> predictive.FrameEstimates:
        """Add the next frame of every feature: predict by ``step``, update by ``mu``.

        ``mu`` (B,) or (B, 2) (NaN, a NaN row: not seen), ``rho`` and ``step`` as
        :meth:`depthcore.exact.features.Features.update` takes them; returns a
        :class:`depthcore.problem.predictive.FrameEstimates` with the tail probabilities.
        """
        B = len(self._mean)
        obs, here, r, s = predictive.batch_inputs(mu, rho, step, self.rho, self.frame, self.dim, B)
        n, C, q = self._mean, self._cov, self.process_noise
        log_p, tail = np.full(B, np.nan), np.full(B, np.nan)
        if self.dim == 3 and self.filter == "ekf":
            if self.frame > 0:
                n, C = ekf.information_predict(n, C, q, s)
            out = ekf.information_update(n, C, obs, r, here, None)
            n, C, log_p, tail = out.mean, out.root, out.log_predictive, out.tail
            R_inv = np.linalg.inv(C)
            cov = symmetric(R_inv @ np.swapaxes(R_inv, -1, -2))
        else:
            if self.frame > 0:
                n, C = (ekf.predict if self.dim == 3 else spatial.predict)(n, C, q, s)
            n, C = n.copy(), C.copy()
            if np.any(here & ~(n[:, 1] > 0)) and self.dim == 5:
                raise ValueError(
                    f"mu: the {self.filter.upper()}'s prediction puts a point at or behind "
                    f"the camera at frame {self.frame + 1}"
                )
            if np.any(here):
                n[here], C[here], log_p[here], tail[here] = self._update(
                    n[here], C[here], obs[here], r[here]
                )
            cov = C
        self._mean, self._cov = n, C
        self.frame += 1
        self.current = predictive.frame_estimates(self.frame, n, cov, log_p, tail)
        return self.current

    def _update(self, n, C, obs, r):
        """The UKF's update of bearings, or either filter's of pairs, on the seen rows."""
        if self.dim == 5:
            return spatial.UPDATES[self.filter](n, C, obs, r)
        z, var = unscented_predictive(n, C, r, self.sigma_points)
        log_p, tail = predictive.gaussian(obs, z, var)
        sp, behind = self.sigma_points, self.allow_behind_camera
        n, C = ukf.update(n, C, obs, r, sigma_points=sp, allow_behind_camera=behind)
        return n, C, log_p, tail
