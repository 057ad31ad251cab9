"""The range-parametrised EKF: a Gaussian sum of EKFs over depth intervals [peach1995]_.

Recommended import: ``from depthcore.kalman import range_ekf``.

Bearings-only tracking met the EKF's failure on a broad range prior by
splitting the range into intervals whose widths grow in geometric progression,
starting one EKF on each, and weighting the EKFs by how well each predicts the
bearings [peach1995]_. On the paper's problem the range is the depth at frame 1.
The depth interval ``[lo, hi]`` (``0 < lo < hi``) is cut at

    e_i = lo * r**i,   i = 0 .. n,   r = (hi / lo)**(1 / n),

so that every interval is the same multiple of its position: each EKF sees a
depth SD that is the same fraction of its depth, the condition under which
[peach1995]_ chooses the ratio.

**The components.** Component ``i`` stands for the prior ``N(m, P)`` of
``(x_1, y_1, v)`` restricted to its interval. Its depth has the interval's
centre ``c_i = (e_{i-1} + e_i) / 2`` as mean and the SD ``s_i = (e_i - e_{i-1}) /
sqrt(12)`` of the uniform density on the interval; the lateral state follows
the prior's regression on the depth, ``g = P[:, y] / P_yy``:

    mean_i = m + g (c_i - m_y),     cov_i = P - P[:, y] P[y, :] / P_yy + s_i**2 g g^T,

and its prior weight is the prior's probability of the interval,
``Phi((e_i - m_y) / sqrt(P_yy)) - Phi((e_{i-1} - m_y) / sqrt(P_yy))``
(:func:`components`). Prior probability outside ``[lo, hi]`` is left out.

**The recursion.** Each component runs the EKF of :mod:`depthcore.kalman.ekf`
(Eqs. (10)-(12), with the process noise of its prediction), and its weight is
multiplied at each frame by its EKF's predictive likelihood of the bearing,
``N(mu_k; n1 / n2, rho**2 + h^T C h)`` with ``(n, C)`` the EKF's prediction and
``h`` Eq. (11) at ``n`` (:func:`component_predictive`); weights are kept in
log space and normalised at the end (:func:`posterior`).

**Tracks as they come** (:mod:`depthcore.problem.frames`). Each component's
EKF predicts over the step ``s_k`` (Eq. (10) with the step, the velocity's
variance grown by ``q**2 s_k``) and reads ``rho`` per frame; a missing bearing
(``NaN``) is predicted through and leaves the weights alone. Before each bearing
the mixture's predictive density is the Gaussian sum of the components'
predictive densities with the weights so far,
``sum_i w_i N(mu_k; n1 / n2, s_k)`` (:func:`depthcore.problem.predictive.mixture`):
its log density and two-sided tail probability are reported per frame, and a
gate skips a bearing whose tail is below it, in every component at once (as a
missing bearing).

**Relation to the exact filter.** The bank of Kalman filters of
:mod:`depthcore.exact.bank` is the limit of this mixture as the intervals shrink:
with a depth SD ``s_i -> 0`` the EKF's linearisation in the depth is exact, the
EKF of component ``i`` becomes the Kalman filter of the lateral state given
``y_1 = c_i``, its predictive likelihood the marginal likelihood ``L(c_i)``, and
the prior weights the midpoint rule's ``N(c_i; m_y, P_yy) (e_i - e_{i-1})``. With
few components the EKFs' linearisations over broad intervals make it an
approximation; how many it needs to match the bank is measured, not assumed.

References
----------
.. [peach1995] N. Peach, "Bearings-only tracking using a set of
   range-parameterised extended Kalman filters", IEE Proceedings - Control
   Theory and Applications 142(1), 73-80, 1995.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import log_ndtr

from depthcore.kalman import ekf
from depthcore.problem import checks, model, predictive, signature
from depthcore.problem.gaussian import checked_track, symmetric

#: Components by default, enough for Figure 2's depth mean and SD to agree with the
#: exact filter's to 1e-2 relative (far fewer leave the EKFs' linearisation over broad
#: depth intervals in charge, and the sum far off).
N_COMPONENTS = 1024
#: The most components a call may ask for (bounds the memory per problem).
MAX_COMPONENTS = 4096
#: The default interval's top is the prior's depth mean plus this many prior depth SDs.
DEPTH_SPAN = 10.0
#: The default interval's bottom, as a fraction of its top.
NEAREST = 1e-3

_LOG_2PI = float(np.log(2.0 * np.pi))


class Components(NamedTuple):
    """The Gaussian sum that starts the filter, batched over problems ``(...)``.

    Attributes
    ----------
    log_weight : ndarray, shape (..., n)
        Log prior probability of each component's depth interval.
    mean : ndarray, shape (..., n, 3)
    cov : ndarray, shape (..., n, 3, 3)
    edges : ndarray, shape (..., n + 1)
        The interval's cuts ``e_0 = lo < ... < e_n = hi`` (depths at frame 1).
    """

    log_weight: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    edges: np.ndarray


class GaussianSum(NamedTuple):
    """The filter's posterior at frame ``N``: a Gaussian sum and its moments.

    Attributes
    ----------
    weight : ndarray, shape (..., n)
        Normalised component probabilities.
    means : ndarray, shape (..., n, 3)
        Each component's EKF mean of ``(x_N, y_N, v_N)``.
    covs : ndarray, shape (..., n, 3, 3)
    mean : ndarray, shape (..., 3)
        The mixture's mean.
    cov : ndarray, shape (..., 3, 3)
        The mixture's covariance (law of total variance).
    edges : ndarray, shape (..., n + 1)
    log_evidence : ndarray, shape (...)
        Log of the sum of prior weight times predictive likelihood: the
        mixture's approximation of ``log p(mu_1 .. mu_N)`` restricted to the
        interval (over the bearings incorporated).
    updates : depthcore.problem.predictive.Updates or None
        Per frame (..., N): the bearing's log density and tail probability
        under the mixture's predictive density, and whether the gate skipped it.
    """

    weight: np.ndarray
    means: np.ndarray
    covs: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    edges: np.ndarray
    log_evidence: np.ndarray
    updates: predictive.Updates | None = None


def _log_interval_probability(a, b, mean, sd):
    """``log(Phi((b - mean) / sd) - Phi((a - mean) / sd))`` without cancellation in the tails."""
    za, zb = (a - mean) / sd, (b - mean) / sd
    # Above the mean use the upper tail, Phi(zb) - Phi(za) = Phi(-za) - Phi(-zb).
    upper = za > 0
    lo = np.where(upper, -zb, za)
    hi = np.where(upper, -za, zb)
    log_hi, log_lo = log_ndtr(hi), log_ndtr(lo)
    with np.errstate(divide="ignore"):
        return log_hi + np.log1p(-np.exp(log_lo - log_hi))


def default_depth_range(prior_mean, prior_cov, floor=0.0) -> tuple[np.ndarray, np.ndarray]:
    """The default ``[lo, hi]``: ``hi = m_y + DEPTH_SPAN sqrt(P_yy)``, ``lo`` just above the floor.

    ``lo = floor + NEAREST (hi - floor)``: the depths at frame 1 that keep the point in
    front of the camera at every frame are those above the floor
    (:func:`depthcore.problem.frames.depth_floor`, 0 for a receding point).

    Parameters
    ----------
    prior_mean : array_like, shape (..., 3)
    prior_cov : array_like, shape (..., 3, 3)
    floor : float or array_like, shape (...)

    Returns
    -------
    lo, hi : ndarray, shape (...)
    """
    m = np.asarray(prior_mean, dtype=float)
    P = np.asarray(prior_cov, dtype=float)
    hi = m[..., 1] + DEPTH_SPAN * np.sqrt(P[..., 1, 1])
    if not np.all(hi > floor):
        raise ValueError(
            f"prior_mean puts the prior's depth so far behind the camera that m_y + "
            f"{DEPTH_SPAN:g} prior SDs does not keep the point in front at every frame; "
            "pass depth_range"
        )
    return floor + NEAREST * (hi - floor), hi


def components(prior_mean, prior_cov, n_components: int, depth_range=None, floor=0.0) -> Components:
    """Cut the depth interval in geometric progression and start one Gaussian on each piece.

    The progression is in the depth above the floor, ``y_1 - floor``, where the
    point comes nearest the camera (0 while it recedes).

    Parameters
    ----------
    prior_mean : array_like, shape (..., 3)
        ``m``, the prior mean of ``(x_1, y_1, v)``.
    prior_cov : array_like, shape (..., 3, 3)
        ``P``, symmetric positive definite.
    n_components : int
        ``n``, from 1 to :data:`MAX_COMPONENTS`.
    depth_range : (float, float), optional
        ``(lo, hi)`` with ``floor < lo < hi``; by default :func:`default_depth_range`.
    floor : float or array_like, shape (...)
        The depth at frame 1 below which the point reaches the camera, >= 0.

    Returns
    -------
    Components
        Log prior weights (..., n), means (..., n, 3), covariances (..., n, 3, 3)
        and the cuts (..., n + 1), as in the module docstring.
    """
    n = checks.count(n_components, "n_components")
    if n > MAX_COMPONENTS:
        raise ValueError(f"n_components must be at most {MAX_COMPONENTS}, got {n}")
    m = np.asarray(prior_mean, dtype=float)
    P = np.asarray(prior_cov, dtype=float)
    batch = np.broadcast_shapes(m.shape[:-1], P.shape[:-2])
    m = np.broadcast_to(m, batch + (3,))
    P = np.broadcast_to(P, batch + (3, 3))
    floor = np.broadcast_to(np.asarray(floor, dtype=float), batch)
    if depth_range is None:
        lo, hi = default_depth_range(m, P, floor)
    else:
        rng = checks.finite_array(depth_range, "depth_range", (2,))
        least = float(np.max(floor))
        if not least < rng[0] < rng[1]:
            raise ValueError(
                f"depth_range must be (lo, hi) with {least:g} < lo < hi (above the depth at "
                f"which the point reaches the camera), got {tuple(rng.tolist())}"
            )
        lo, hi = np.broadcast_to(rng[0], batch), np.broadcast_to(rng[1], batch)
    steps = np.arange(n + 1) / n
    edges = (
        floor[..., None]
        + (lo - floor)[..., None] * ((hi - floor) / (lo - floor))[..., None] ** steps
    )
    edges[..., -1] = hi
    centre = 0.5 * (edges[..., 1:] + edges[..., :-1])
    s2 = (edges[..., 1:] - edges[..., :-1]) ** 2 / 12.0
    pyy = P[..., 1, 1]
    g = P[..., :, 1] / pyy[..., None]  # the regression of the state on the depth; g_y = 1
    base = P - P[..., :, 1, None] * P[..., None, 1, :] / pyy[..., None, None]
    gg = g[..., :, None] * g[..., None, :]
    mean = m[..., None, :] + (centre - m[..., 1, None])[..., None] * g[..., None, :]
    cov = base[..., None, :, :] + s2[..., None, None] * gg[..., None, :, :]
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    log_w = _log_interval_probability(
        edges[..., :-1], edges[..., 1:], m[..., 1, None], np.sqrt(pyy)[..., None]
    )
    return Components(log_w, mean, cov, edges)


def mixture_moments(weight, means, covs) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a Gaussian sum (law of total variance).

    Parameters
    ----------
    weight : array_like, shape (..., n)
        Probabilities summing to 1.
    means : array_like, shape (..., n, d)
    covs : array_like, shape (..., n, d, d)

    Returns
    -------
    mean : ndarray, shape (..., d)
        ``sum_i w_i m_i``.
    cov : ndarray, shape (..., d, d)
        ``sum_i w_i (P_i + (m_i - mean)(m_i - mean)^T)``.
    """
    w = np.asarray(weight, dtype=float)
    means = np.asarray(means, dtype=float)
    covs = np.asarray(covs, dtype=float)
    mean = np.einsum("...i,...ij->...j", w, means)
    d = means - mean[..., None, :]
    cov = np.einsum("...i,...ijk->...jk", w, covs) + np.einsum("...i,...ij,...ik->...jk", w, d, d)
    return mean, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def component_predictive(n, C, rho) -> tuple[np.ndarray, np.ndarray]:
    """Each EKF's predictive density of a bearing: ``N(n1 / n2, rho**2 + h^T C h)``, Eq. (12).

    Parameters
    ----------
    n : ndarray, shape (..., 3)
        The EKF's prediction (Eq. (10)).
    C : ndarray, shape (..., 3, 3)
    rho : float or array_like, broadcasting with (...)

    Returns
    -------
    mean, var : ndarray, shape (...)
    """
    return ekf.linearised_predictive(n, model.observation_vector(n), C, rho)


@signature.documented
def posterior(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    n_components: int = N_COMPONENTS,
    depth_range=None,
    steps=None,
    gate=None,
) -> GaussianSum:
    """The range-parametrised EKF [peach1995]_ over ``N`` bearings, batched.

    Each component runs the EKF of :func:`depthcore.kalman.ekf.run` (its
    square-root information steps :func:`depthcore.kalman.ekf.information_predict`
    and :func:`depthcore.kalman.ekf.information_update`), its weight multiplied
    by its predictive likelihood of each bearing incorporated
    (:func:`component_predictive`' density); a missing or gated bearing
    is predicted through (module docstring).

    {parameters}
    n_components : int
        EKFs in the sum, 1 to :data:`MAX_COMPONENTS`.
    depth_range : (float, float), optional
        ``(lo, hi)``, the depths at frame 1 the components cover
        (:func:`components`).

    Returns
    -------
    GaussianSum
        The components at frame ``N``, their normalised weights, the
        mixture's mean (..., 3) and covariance (..., 3, 3), and the per-frame
        ``updates`` (..., N).
    """
    track = checked_track(mu, rho, prior_mean, prior_cov, steps)
    q = checks.process_noise(process_noise, "process_noise")
    g = predictive.gate(gate)
    f, regular = track.frames, track.frames.regular
    start = components(track.mean, track.cov, n_components, depth_range, track.frames.floor)
    batch, n_frames = f.mu.shape[:-1], f.mu.shape[-1]
    shape = batch + (start.log_weight.shape[-1],)
    try:
        cov0 = checks.covariances(start.cov, "prior_cov", 3)
    except ValueError as exc:
        raise ValueError(f"mu: a component's EKF has no answer ({exc})") from None
    if not np.all(np.isfinite(np.max(start.log_weight, axis=-1))):
        raise ValueError(
            "depth_range holds no prior probability, or no component explains the bearings"
        )
    m = np.broadcast_to(start.mean, shape + (3,))
    C = np.broadcast_to(cov0, shape + (3, 3))
    R = np.linalg.inv(np.linalg.cholesky(C))
    log_w = start.log_weight
    means, roots, log_liks, reports = [], [], [], []
    for i in range(n_frames):
        rho_i = (f.row_rho if regular else f.rho[..., i])[..., None]
        if i > 0:
            step = 1.0 if regular else f.steps[..., i - 1, None]
            m, R = ekf.information_predict(means[-1], roots[-1], q, step)
            R_inv = np.linalg.inv(roots[-1])
            previous = symmetric(R_inv @ np.swapaxes(R_inv, -1, -2))
            C = (
                ekf.predict(means[-1], previous, q)
                if regular
                else ekf.predict(means[-1], previous, q, step)
            ).cov
        here = f.present[..., i]
        mu_i = np.where(here, f.mu[..., i], 0.0)
        bearing, var = component_predictive(m, C, rho_i)
        log_p, tail = predictive.mixture(mu_i, log_w, bearing, var)
        gated = predictive.skipped(tail, here, g)
        use = here & ~gated
        reports.append((np.where(here, log_p, np.nan), np.where(here, tail, np.nan), gated))
        r = mu_i[..., None] - bearing
        log_lik = np.where(use[..., None], -0.5 * (_LOG_2PI + np.log(var) + r**2 / var), 0.0)
        log_w = log_w + log_lik
        log_liks.append(log_lik)
        out = ekf.information_update(m, R, mu_i[..., None], rho_i, use[..., None])
        means.append(out.mean)
        roots.append(out.root)
    log_w = start.log_weight + np.sum(np.stack(log_liks, axis=-1), axis=-1)
    top = np.max(log_w, axis=-1, keepdims=True)
    if not np.all(np.isfinite(top)):
        raise ValueError(
            "depth_range holds no prior probability, or no component explains the bearings"
        )
    w = np.exp(log_w - top)
    total = np.sum(w, axis=-1, keepdims=True)
    w = w / total
    last_m = means[-1]
    R_inv = np.linalg.inv(roots[-1])
    last_c = symmetric(R_inv @ np.swapaxes(R_inv, -1, -2))
    mean, cov = mixture_moments(w, last_m, last_c)
    updates = predictive.Updates(*(np.stack(x, axis=-1) for x in zip(*reports, strict=True)))
    return GaussianSum(
        w, last_m, last_c, mean, cov, start.edges, (top + np.log(total))[..., 0], updates
    )
