"""How probable a bearing was before it was seen: predictive densities, tails and the gate.

Recommended import: ``from depthcore.problem import predictive``.

Before it incorporates the bearing of frame ``k`` a filter holds a predictive
density of that bearing, ``p(mu_k | mu_1 .. mu_{k-1})``: a Gaussian for the
Kalman-type filters (mean the predicted bearing, variance the innovation's),
a mixture of Gaussians for the exact filter (one per depth node) and for the
particle filters (one per particle). Each update reports two numbers of it:

* the log predictive density at the bearing seen (summed over frames, the log
  marginal likelihood of the track under the filter);
* the two-sided tail probability ``p = 2 min(F(mu_k), 1 - F(mu_k))``, ``F``
  the predictive CDF: the probability, before the bearing was seen, of a
  bearing at least as far out in the predictive's tails. For a Gaussian
  predictive it is the usual two-sided p-value of the innovation.

A gate ``g`` (a probability, e.g. ``1e-3``) skips every bearing whose tail
probability is below ``g``: the filter predicts through that frame as through
a missing one, and records that it did. An online filter takes each frame's
inputs as :func:`frame_inputs` checks them and answers with a
:class:`FrameEstimate` (:func:`frame_estimate`): its state's moments and these reports.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.problem import checks

_LOG_2PI = float(np.log(2.0 * np.pi))


class Updates(NamedTuple):
    """Per frame, what each update saw: shape (..., N) each; NaN / False at a missing frame."""

    log_predictive: np.ndarray
    tail: np.ndarray
    gated: np.ndarray


class FrameEstimate(NamedTuple):
    """An online filter's estimate after a frame, with what its update saw.

    The answer of :meth:`depthcore.registry.online.OnlineFilter.update`, of
    :class:`depthcore.exact.online.Online` and of
    :class:`depthcore.kalman.online.EKF` and :class:`depthcore.kalman.online.UKF`.

    Attributes
    ----------
    frame : int
        Frames seen so far, missing ones included (1 after the first).
    mean : ndarray, shape (3,)
        Mean of the state ``(x_k, y_k, v_k)`` given the bearings so far.
    cov : ndarray, shape (3, 3)
    depth_mean, depth_sd, velocity_mean, velocity_sd : float
    log_predictive : float
        The bearing's log predictive density given the earlier ones; NaN at a
        missing frame.
    tail : float
        Its two-sided tail probability under that predictive; NaN at a missing frame.
    gated : bool
        Whether the gate skipped the bearing.
    """

    frame: int
    mean: np.ndarray
    cov: np.ndarray
    depth_mean: float
    depth_sd: float
    velocity_mean: float
    velocity_sd: float
    log_predictive: float
    tail: float
    gated: bool


class FrameEstimates(NamedTuple):
    """A batched online filter's estimates of ``B`` features after a frame.

    The answer of :class:`depthcore.exact.features.Features` and of
    :class:`depthcore.kalman.features.Features`: :class:`FrameEstimate` row by row,
    without a gate.

    Attributes
    ----------
    frame : int
        Frames seen so far, missing ones included.
    mean : ndarray, shape (B, d)
        Mean of each feature's state, ``(x, y, v)`` (``d = 3``) or ``(x, y, v, h, w)``.
    cov : ndarray, shape (B, d, d)
    depth_mean, depth_sd, velocity_mean, velocity_sd : ndarray, shape (B,)
    log_predictive : ndarray, shape (B,)
        Each observation's log predictive density given the earlier ones; NaN where the
        feature was not seen.
    tail : ndarray, shape (B,)
        Its tail probability where the filter computes one (the Kalman filters), else NaN.
    """

    frame: int
    mean: np.ndarray
    cov: np.ndarray
    depth_mean: np.ndarray
    depth_sd: np.ndarray
    velocity_mean: np.ndarray
    velocity_sd: np.ndarray
    log_predictive: np.ndarray
    tail: np.ndarray


def frame_estimates(frame: int, mean, cov, log_predictive, tail=None) -> FrameEstimates:
    """The :class:`FrameEstimates` of means (B, d) and covariances (B, d, d)."""
    lp = np.asarray(log_predictive, dtype=float)
    tail = np.full(lp.shape, np.nan) if tail is None else np.asarray(tail, dtype=float)
    sd = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    return FrameEstimates(frame, mean, cov, mean[:, 1], sd[:, 1], mean[:, 2], sd[:, 2], lp, tail)


def batch_prior(prior_mean, prior_cov) -> tuple[np.ndarray, np.ndarray]:
    """Priors of ``B`` features, checked: means (B, d) and covariances (B, d, d), d = 3 or 5."""
    m = checks.finite_array(prior_mean, "prior_mean")
    if m.ndim != 2 or m.shape[1] not in (3, 5) or not len(m):
        raise ValueError(f"prior_mean must have shape (B, 3) or (B, 5), got shape {m.shape}")
    P = checks.finite_array(prior_cov, "prior_cov")
    if P.shape != m.shape + m.shape[1:]:
        raise ValueError(f"prior_cov must have shape {m.shape + m.shape[1:]}, got {P.shape}")
    return m, checks.covariances(P, "prior_cov", m.shape[1])


def per_feature(value, name: str, B: int, positive: bool = True) -> np.ndarray:
    """A number or one per feature, (B,): finite and > 0 (``positive``) or nonzero."""
    arr = checks.finite_array(value, name)
    if arr.shape not in ((), (B,)):
        raise ValueError(f"{name} must be a number or have shape ({B},), got shape {arr.shape}")
    bad = ~(arr > 0) if positive else arr == 0
    if np.any(bad):
        what = "positive" if positive else "nonzero (negative: the camera approaches)"
        raise ValueError(f"{name} must be {what}, got {float(np.ravel(arr)[np.argmax(bad)])!r}")
    return np.broadcast_to(arr, (B,)).astype(float)


def batch_inputs(mu, rho, step, default_rho, frame: int, dim: int, B: int):
    """One frame of a batched online filter, checked (as :func:`frame_inputs` checks one).

    Parameters
    ----------
    mu : array_like, shape (B,) or (B, 2)
        Bearings (``dim`` 3) or pairs (``dim`` 5); NaN (a NaN row): not seen this frame.
    rho : float, array_like of shape (B,), or None
        ``None``: ``default_rho``.
    step : float or array_like, shape (B,)
        Signed, nonzero; ignored at the first frame (``frame`` 0).
    default_rho : ndarray, shape (B,), or None
    frame : int
    dim : int
    B : int

    Returns
    -------
    mu : ndarray, shape (B,) or (B, 2)
    present : ndarray of bool, shape (B,)
    rho, step : ndarray, shape (B,)
    """
    arr = checks.as_float(mu, "mu")
    shape = (B,) if dim == 3 else (B, 2)
    if arr.shape != shape:
        raise ValueError(f"mu must have shape {shape}, got shape {arr.shape}")
    if np.any(np.isinf(arr)):
        raise ValueError("mu must be finite or NaN (a feature not seen this frame)")
    nan = np.isnan(arr)
    if dim == 5 and np.any(nan[:, 0] != nan[:, 1]):
        raise ValueError("mu has a pair with one coordinate missing: a frame has both or neither")
    present = ~(nan if dim == 3 else nan[:, 0])
    if rho is None and default_rho is None:
        raise ValueError("rho is needed: give it to start or to this update")
    r = default_rho if rho is None else per_feature(rho, "rho", B)
    s = np.ones(B) if frame == 0 else per_feature(step, "step", B, positive=False)
    return arr, present, r, s


def frame_inputs(mu, rho, step, default_rho, frame: int) -> tuple[float, float, float]:
    """One frame of an online filter, checked: its bearing, noise SD and step.

    Parameters
    ----------
    mu : float
        The bearing; ``NaN`` for a frame without one.
    rho : float or None
        Its noise SD, > 0 (``None``: ``default_rho``).
    step : float
        The depth's signed change since the last frame, nonzero (negative: the
        camera approaches the point); at the first frame it must be left at 1.
    default_rho : float or None
        The filter's own noise SD.
    frame : int
        Frames seen before this one, any number (an online filter holds
        nothing of the frames before).

    Returns
    -------
    mu, rho, step : float
    """
    arr = checks.as_float(mu, "mu")
    if arr.ndim != 0:
        raise ValueError(f"mu must be one bearing (a number), got shape {arr.shape}")
    mu = float(arr)
    if np.isinf(mu):
        raise ValueError(f"mu must be finite or NaN (a missing frame), got {mu!r}")
    if rho is None and default_rho is None:
        raise ValueError("rho is needed: give it to start or to this update")
    r = default_rho if rho is None else checks.positive_scalar(rho, "rho")
    s = checks.number(step, "step")
    if s == 0:
        raise ValueError(
            f"step must be nonzero (the depth's signed change: negative while the "
            f"camera approaches), got {s!r}"
        )
    if frame == 0 and s != 1.0:
        raise ValueError("step: the first frame has no step before it; leave it at 1")
    return mu, r, s


def frame_estimate(frame: int, mean, cov, log_predictive, tail, gated) -> FrameEstimate:
    """The :class:`FrameEstimate` of the state's ``mean`` and ``cov`` after ``frame`` frames."""
    return FrameEstimate(
        frame,
        mean,
        cov,
        float(mean[1]),
        float(np.sqrt(cov[1, 1])),
        float(mean[2]),
        float(np.sqrt(cov[2, 2])),
        float(log_predictive),
        float(tail),
        bool(gated),
    )


def gate(value, name: str = "gate"):
    """A gate: ``None`` (no gate) or a probability strictly between 0 and 1."""
    if value is None:
        return None
    g = checks.number(value, name)
    if not 0.0 < g < 1.0:
        raise ValueError(f"{name} must be None or a probability in (0, 1), got {g!r}")
    return g


def _two_sided(log_lower, log_upper) -> np.ndarray:
    """``2 min(F, 1 - F)`` from ``log F`` and ``log(1 - F)``, at most 1."""
    return np.minimum(1.0, 2.0 * np.exp(np.minimum(log_lower, log_upper)))


def gaussian(mu, mean, var):
    """Log density and two-sided tail probability of ``mu`` under ``N(mean, var)``.

    Parameters
    ----------
    mu, mean, var : array_like, broadcasting to a shape (...)
        The bearing, the predicted bearing and the innovation's variance (> 0).

    Returns
    -------
    log_density, tail : ndarray, shape (...)
    """
    from scipy.special import log_ndtr  # scipy loads on first use, not with the package

    mu, mean, var = (np.asarray(a, dtype=float) for a in (mu, mean, var))
    z = (mu - mean) / np.sqrt(var)
    log_density = -0.5 * (_LOG_2PI + np.log(var) + z * z)
    return log_density, _two_sided(log_ndtr(z), log_ndtr(-z))


def mixture(mu, log_weights, means, var):
    """Log density and two-sided tail probability of ``mu`` under a mixture of Gaussians.

    Parameters
    ----------
    mu : array_like, shape (...)
        The bearing.
    log_weights : array_like, shape (..., J)
        Log weights of the components, normalised or not (they are normalised
        here, in log space); ``-inf`` for an empty component.
    means, var : array_like, shape (..., J)
        The components' means and variances (> 0).

    Returns
    -------
    log_density, tail : ndarray, shape (...)
        NaN where every component is empty (every log weight ``-inf``, as for a
        particle cloud wholly behind the camera): such a mixture predicts nothing.
    """
    from scipy.special import log_ndtr, logsumexp

    mu = np.asarray(mu, dtype=float)[..., None]
    log_w = np.asarray(log_weights, dtype=float)
    total = logsumexp(log_w, axis=-1, keepdims=True)
    empty = np.isneginf(total[..., 0])
    log_w = log_w - np.where(empty[..., None], 0.0, total)  # an empty row stays -inf
    means, var = np.asarray(means, dtype=float), np.asarray(var, dtype=float)
    z = (mu - means) / np.sqrt(var)
    log_density = logsumexp(log_w - 0.5 * (_LOG_2PI + np.log(var) + z * z), axis=-1)
    log_lower = logsumexp(log_w + log_ndtr(z), axis=-1)
    log_upper = logsumexp(log_w + log_ndtr(-z), axis=-1)
    tail = _two_sided(log_lower, log_upper)
    return np.where(empty, np.nan, log_density), np.where(empty, np.nan, tail)


def skipped(tail, present, gate_value) -> np.ndarray:
    """Which present bearings a gate skips: tail probability below the gate.

    Parameters
    ----------
    tail : ndarray, shape (...)
    present : ndarray of bool, shape (...)
    gate_value : float or None
        From :func:`gate`.

    Returns
    -------
    ndarray of bool, shape (...)
    """
    if gate_value is None:
        return np.zeros(np.shape(present), dtype=bool)
    return np.asarray(present) & (np.asarray(tail) < gate_value)
