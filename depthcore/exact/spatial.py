"""The exact filter for a point in 3-D: a bank of four-state Kalman filters over depth.

Recommended import: ``from depthcore.exact import spatial``.

The point's state is ``(x, y, v, h, w)``: the paper's ``(x, y, v)`` and its height
``h`` with vertical velocity ``w``, which move as ``x`` and ``v`` do. Over a step
``s`` (the depth's signed change, :mod:`depthcore.problem.frames`)

    y += s,   x += s v,   h += s w,   v += a,   w += b,   a, b ~ N(0, q**2 abs(s)),

and the camera sees the pair ``(mu_k, nu_k) = (x_k / y_k, h_k / y_k)`` plus
independent noise of SD ``rho_k`` on each (Eq. (4) twice). Given the depth at frame
1, ``y_1 = y``, the depths at every frame are known and the lateral-vertical state
``u = (x, v, h, w)`` is linear-Gaussian, as the plane's ``(x, v)`` is in
:mod:`depthcore.exact.bank`: its prior is ``N(m, P)`` conditioned on ``y_1 = y``, it
moves by ``F_s = [[1, s], [0, 1]]`` in each block with noise ``diag(0, q**2 |s|)`` in
each, and the pair observes ``x / y_k`` and ``h / y_k``. One Kalman filter per depth
node (textbook 19.2.1, 19.2.2, the pair as two scalar updates) gives
the exact ``p(mu, nu | y)`` and the Gaussian of ``u_N`` given ``y``, and

    p(y_1 = y | all pairs)  proportional to  N(y; m_y, P_yy) p(mu, nu | y),

integrated over the depth on the nodes of the depth quadrature
(:mod:`depthcore.exact.quadrature`, placed above the floor where the point would
reach the camera, :func:`depthcore.problem.frames.depth_floor`). The prior may
correlate any coordinates; when it does not correlate the blocks, the likelihood is
the product of the plane's for ``mu`` and the same for ``nu``.

A missing frame is a row of two ``NaN``; a pair with one coordinate missing is
refused (:func:`depthcore.problem.bearing_pairs.check`). With the height's prior
narrow at 0, bearings ``nu = 0`` and ``q = 0`` the filter is the plane's
(``tests/test_spatial.py``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.exact import quadrature
from depthcore.exact.mixture import Smoothed
from depthcore.exact.posterior import grid_nodes
from depthcore.kalman import linear
from depthcore.problem import checks, frames
from depthcore.problem.bearing_pairs import Pairs, check

#: The lateral-vertical state ``u = (x, v, h, w)`` in the state ``(x, y, v, h, w)``.
LATERAL = np.array([0, 2, 3, 4])
#: The coordinates of ``u`` the pair observes (``x`` and ``h``).
OBSERVED = (0, 2)
_LOG_2PI = float(np.log(2.0 * np.pi))


def _prior(prior_mean, prior_cov, B: int, batch: tuple):
    m = checks.finite_array(prior_mean, "prior_mean")
    if m.shape[-1:] != (5,) or not checks.broadcasts(m.shape[:-1], batch):
        raise ValueError(
            f"prior_mean must have shape (5,) or (..., 5), (x, y, v, h, w), got {m.shape}"
        )
    P = checks.finite_array(prior_cov, "prior_cov")
    if P.shape[-2:] != (5, 5) or not checks.broadcasts(P.shape[:-2], batch):
        raise ValueError(f"prior_cov must have shape (5, 5) or (..., 5, 5), got {P.shape}")
    P = checks.covariances(P, "prior_cov", 5)
    m = np.broadcast_to(m, batch + (5,)).reshape(B, 5)
    P = np.ascontiguousarray(np.broadcast_to(P, batch + (5, 5))).reshape(B, 5, 5)
    return m, P


def conditional_prior(nodes, prior_mean, prior_cov):
    """The prior of ``u = (x_1, v_1, h_1, w_1)`` given ``y_1`` at each node, and ``log N(y_1)``.

    ``nodes`` (B, J), ``prior_mean`` (B, 5), ``prior_cov`` (B, 5, 5); returns the means
    (B, J, 4), the covariance (B, 1, 4, 4) and the log prior density of the depth (B, J).
    """
    m_u, m_y = prior_mean[:, LATERAL], prior_mean[:, 1]
    P_yy = prior_cov[:, 1, 1]
    P_uy = prior_cov[:, LATERAL, 1]
    slope = P_uy / P_yy[:, None]
    d = nodes - m_y[:, None]
    mean = m_u[:, None, :] + d[..., None] * slope[:, None, :]
    cov = prior_cov[:, LATERAL][:, :, LATERAL] - slope[:, :, None] * P_uy[:, None, :]
    log_density = -0.5 * (_LOG_2PI + np.log(P_yy)[:, None] + d * d / P_yy[:, None])
    return mean, cov[:, None], log_density


def predict_nodes(M, C, s, q2) -> tuple:
    """Textbook 19.2.1 over steps ``s``: both blocks move by ``[[1, s], [0, 1]]``.

    ``M`` (..., 4) and ``C`` (..., 4, 4) of ``u = (x, v, h, w)``, ``s`` broadcasting with
    ``M.shape[:-1]``, ``q2`` the velocities' ``q**2`` (its shape too) or ``None`` for 0.
    """
    F = np.zeros(s.shape + (4, 4))
    F[..., [0, 1, 2, 3], [0, 1, 2, 3]] = 1.0
    F[..., 0, 1] = F[..., 2, 3] = s
    M = np.einsum("...ij,...j->...i", F, M)
    C = F @ C @ np.swapaxes(F, -1, -2)
    if q2 is not None:
        noise = q2 * np.abs(s)
        C = C.copy()
        C[..., 1, 1] += noise
        C[..., 3, 3] += noise
    return M, C


def update_nodes(M, C, bearing, y, rho2, i: int):
    """Textbook 19.2.2 by one coordinate's bearing at depth ``y``; the log density.

    The bearing times the depth observes ``u_i`` with noise variance ``rho**2 y**2``:
    ``S = C_ii + rho**2 y**2``, the gain ``C[:, i] / S``, and the covariance less the
    outer product of its ``i``-th column with itself over ``S`` (symmetric by
    construction).
    """
    r = rho2 * y * y
    S = C[..., i, i] + r
    e = bearing * y - M[..., i]
    column = C[..., :, i]
    C = C - column[..., :, None] * (column / S[..., None])[..., None, :]
    log_density = -0.5 * (_LOG_2PI + np.log(S / (y * y)) + e * e / S)
    return M + column * (e / S)[..., None], C, log_density


def running_floor(elapsed) -> np.ndarray:
    """The depth floor of frames 1 .. k at every ``k``, (B, N), as
    :func:`depthcore.problem.frames.depth_floor` of each prefix of ``elapsed`` (B, N)."""
    return np.maximum.accumulate(np.maximum(-elapsed, 0.0), axis=-1)


def node_filter(nodes, pairs: Pairs, prior_mean, prior_cov, process_noise, history=False):
    """One four-state Kalman filter per depth node over every frame (module docstring).

    Parameters
    ----------
    nodes : ndarray, shape (B, J)
        Depths at frame 1; nodes at or below the floor get log weight ``-inf``.
    pairs : Pairs
    prior_mean : ndarray, shape (B, 5)
    prior_cov : ndarray, shape (B, 5, 5)
    process_noise : ndarray, shape (B,)
    history : bool
        Also return every frame's Gaussians, for the smoother (:func:`track`).

    Returns
    -------
    log_weight : ndarray, shape (B, J)
        ``log N(y_1; m_y, P_yy) + log p(pairs | y_1)``.
    mean : ndarray, shape (B, J, 4)
    cov : ndarray, shape (B, J, 4, 4)
        ``u_N`` given ``y_1`` and the pairs.
    frames : depthcore.kalman.linear.FilterResult
        With ``history``: the filtered and predicted ``u_k`` given ``y_1`` at every frame,
        means (B, J, N, 4) and covariances (B, J, N, 4, 4), and ``log p(pair_k | earlier
        pairs, y_1)`` (B, J, N) (0 at a missing frame and where the point has reached the
        camera by frame ``k``, :func:`running_floor`).
    """
    M, C, log_weight = conditional_prior(nodes, prior_mean, prior_cov)
    C = np.broadcast_to(C, M.shape + (4,)).copy()
    q2 = (process_noise**2)[:, None]
    q2 = q2 if np.any(q2) else None
    elapsed = pairs.elapsed
    floors = running_floor(elapsed)
    kept = []
    for k in range(pairs.mu.shape[1]):
        if k:
            M, C = predict_nodes(M, C, pairs.steps[:, k - 1, None], q2)
        kept.append((M, C))
        gain = 0.0
        reached = nodes <= floors[:, k, None]
        here = pairs.present[:, k, None] & ~reached
        y = np.where(here, nodes + elapsed[:, k, None], 1.0)
        rho2 = (pairs.rho[:, k] ** 2)[:, None]
        for i, coordinate in zip(OBSERVED, (0, 1), strict=True):
            bearing = np.where(here, pairs.mu[:, k, coordinate, None], 0.0)
            M1, C1, log_density = update_nodes(M, C, bearing, y, rho2, i)
            M = np.where(here[..., None], M1, M)
            C = np.where(here[..., None, None], C1, C)
            log_weight = log_weight + np.where(here, log_density, 0.0)
            gain = gain + np.where(here, log_density, 0.0)
        kept[-1] += (M, C, gain)
    C = 0.5 * (C + np.swapaxes(C, -1, -2))
    log_weight = np.where(reached, -np.inf, log_weight)
    if not history:
        return log_weight, M, C
    pm, pc, fm, fc, lp = (np.stack(a, axis=2) for a in zip(*kept, strict=True))
    return log_weight, M, C, linear.FilterResult(fm, fc, pm, pc, lp)


class SpatialPosterior(NamedTuple):
    """The exact posterior of ``(x, y, v, h, w)`` at the last frame, batch shape (...).

    Attributes
    ----------
    mean : ndarray, shape (..., 5)
    cov : ndarray, shape (..., 5, 5)
    error : ndarray, shape (..., 5)
        The quadrature's error estimate of each coordinate's mean and SD (the larger),
        from the moments on every other node.
    nodes : ndarray, shape (..., J)
        Depths at frame 1.
    probabilities : ndarray, shape (..., J)
    node_mean : ndarray, shape (..., J, 4)
    node_cov : ndarray, shape (..., J, 4, 4)
        ``u_N = (x_N, v_N, h_N, w_N)`` given each node.
    travelled : ndarray, shape (...)
        ``y_N - y_1``.
    """

    mean: np.ndarray
    cov: np.ndarray
    error: np.ndarray
    nodes: np.ndarray
    probabilities: np.ndarray
    node_mean: np.ndarray
    node_cov: np.ndarray
    travelled: np.ndarray


def _moments(p, nodes, travelled, M, C):
    """Mean (B, 5) and covariance (B, 5, 5) of the state at frame N under node weights ``p``."""
    B, J = p.shape
    states = np.zeros((B, J, 5))
    states[..., LATERAL] = M
    states[..., 1] = nodes + travelled[:, None]
    covs = np.zeros((B, J, 5, 5))
    covs[..., LATERAL[:, None], LATERAL[None, :]] = C
    mean = np.einsum("bj,bjk->bk", p, states)
    d = states - mean[:, None, :]
    cov = np.einsum("bj,bjkl->bkl", p, covs + d[..., :, None] * d[..., None, :])
    return mean, cov


def _mode_bearings(pairs: Pairs) -> np.ndarray:
    """Per row, the coordinate with the larger parallax (B, N): where the depth scan starts."""
    mu = np.where(pairs.present[..., None], pairs.mu, 0.0)
    second = np.abs(np.diff(mu, n=2, axis=1)).sum(axis=1)  # (B, 2)
    pick = np.argmax(second, axis=1)
    return np.where(pairs.present, mu[np.arange(len(mu)), :, pick], np.nan)


def posterior(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, steps=None, rtol: float = 1e-10
) -> SpatialPosterior:
    """The exact posterior of a point in 3-D at the last frame, to ``rtol`` of each SD.

    Parameters
    ----------
    mu : array_like, shape (N, 2) or (..., N, 2)
        Pairs ``(x / y, h / y)``; ``NaN`` rows at missing frames
        (:func:`depthcore.problem.bearing_pairs.check`).
    rho : float or array_like, shape (...) or (..., N)
    prior_mean : array_like, shape (5,) or (..., 5)
        The prior mean of ``(x_1, y_1, v, h_1, w)``.
    prior_cov : array_like, shape (5, 5) or (..., 5, 5)
    process_noise : float or array_like, shape (...)
        ``q >= 0``, on both velocities.
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
        The depth's signed change between frames.
    rtol : float
        The quadrature's tolerance, relative to each SD.

    Returns
    -------
    SpatialPosterior
    """
    pairs = check(mu, rho, steps)
    B = len(pairs.mu)
    m, P = _prior(prior_mean, prior_cov, B, pairs.batch)
    q = checks.nonnegative_batch(process_noise, "process_noise", pairs.batch).reshape(-1)
    q = np.broadcast_to(q, (B,))
    return _posterior(pairs, m, P, q, checks.positive_scalar(rtol, "rtol"))


def _weighted(a, nodes, travelled, M, C):
    """Node probabilities from log weights ``a`` (B, J), the moments (B, 5), (B, 5, 5) and
    their error (B, 5), the change of each mean and SD on every other node."""
    a = np.where(np.isnan(a), -np.inf, a)
    p = np.exp(a - np.max(a, axis=1, keepdims=True))
    p /= np.sum(p, axis=1, keepdims=True)
    mean, cov = _moments(p, nodes, travelled, M, C)
    half = np.where(np.arange(p.shape[1]) % 2 == 0, p, 0.0)
    half /= np.sum(half, axis=1, keepdims=True)
    half_mean, half_cov = _moments(half, nodes, travelled, M, C)
    sd, half_sd = (np.sqrt(np.diagonal(c, axis1=1, axis2=2)) for c in (cov, half_cov))
    return p, mean, cov, np.maximum(np.abs(half_mean - mean), np.abs(half_sd - sd))


def _placed(pairs: Pairs, m, P, q, rtol: float):
    """The depth quadrature's nodes (B, J) at frame 1 and their log weights (B, J) for
    ``pairs``, placed by :func:`depthcore.exact.quadrature.integrate` to ``rtol``."""
    floor = frames.depth_floor(pairs.elapsed)

    def integrand(offsets, pb):
        log_weight, M, C = node_filter(offsets[..., 2] + floor[:, None], pairs, m, P, q)
        lateral = (C[..., 0, 0], C[..., 0, 1], C[..., 1, 1])
        return log_weight, np.stack([M[..., 0], M[..., 1]]), lateral

    xyv = [0, 1, 2]
    steps_or_none = None if np.all(pairs.steps == 1.0) else pairs.steps
    pb = quadrature.Problem(
        mu=_mode_bearings(pairs),
        rho=np.max(np.where(pairs.present, pairs.rho, 0.0), axis=1),
        mean=m[:, xyv],
        R=np.linalg.inv(np.linalg.cholesky(P[:, xyv][:, :, xyv])),
        integrand=integrand,
        process_noise=q,
        cov=P[:, xyv][:, :, xyv],
        steps=steps_or_none,
    )
    _, _, _, _, grids = quadrature.integrate(pb, (3,), rtol)
    nodes, log_w = grid_nodes(grids[3])
    return nodes + floor[:, None], log_w


def _posterior(pairs: Pairs, m, P, q, rtol: float) -> SpatialPosterior:
    """:func:`posterior` of checked pairs, ``m`` (B, 5), ``P`` (B, 5, 5), ``q`` (B,)."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        nodes, log_w = _placed(pairs, m, P, q, rtol)
        log_weight, M, C = node_filter(nodes, pairs, m, P, q)
        travelled = pairs.elapsed[:, -1]
        p, mean, cov, error = _weighted(log_w + log_weight, nodes, travelled, M, C)
        sd = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov)) and np.all(sd > 0)):
        raise ValueError(
            "mu, rho, prior_mean and prior_cov overflow the exact 3-D filter in double "
            "precision (the model holds 1 / y and y**2); give values nearer the track's scale"
        )
    shape = pairs.batch
    J = nodes.shape[1]
    return SpatialPosterior(
        mean.reshape(shape + (5,)),
        cov.reshape(shape + (5, 5)),
        error.reshape(shape + (5,)),
        nodes.reshape(shape + (J,)),
        p.reshape(shape + (J,)),
        M.reshape(shape + (J, 4)),
        C.reshape(shape + (J, 4, 4)),
        travelled.reshape(shape),
    )


class SpatialTrack(NamedTuple):
    """The exact filter and smoother of one track of pairs at every frame (:func:`track`).

    Attributes
    ----------
    filtered : depthcore.exact.mixture.Smoothed
        The state ``(x_k, y_k, v_k, h_k, w_k)`` given the pairs up to frame ``k``: means
        (N, 5) and covariances (N, 5, 5), row ``k - 1`` for frame ``k``.
    smoothed : depthcore.exact.mixture.Smoothed
        The state at frame ``k`` given all ``N`` pairs; at frame ``N`` the filtered state.
    nodes : ndarray, shape (J,)
        The depths at frame 1 on which the smoother mixes.
    probabilities : ndarray, shape (J,)
        Their posterior probabilities after all ``N`` pairs.
    placements : int
        How many times the filter placed its nodes.
    """

    filtered: Smoothed
    smoothed: Smoothed
    nodes: np.ndarray
    probabilities: np.ndarray
    placements: int


def track(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, steps=None, rtol: float = 1e-10
) -> SpatialTrack:
    """The exact filter and its fixed-interval smoother at every frame of one track of pairs.

    **Filtered.** The state at frame ``k`` given the pairs up to it is the mixture of the
    nodes' Kalman filters (:func:`node_filter`), weighted by the quadrature's weights times
    ``N(y_1; m_y, P_yy) p(pairs_1 .. pairs_k | y_1)``. The nodes are placed for the pairs
    of the first frame (:func:`depthcore.exact.quadrature.integrate`, to ``rtol``) and kept
    while they resolve each later frame's posterior as the plane's online update keeps
    them (:func:`depthcore.exact.posterior.update`): every mean and SD of the depth and the
    velocity changes by at most ``rtol`` of its SD, or by the roundoff floor, on every other
    node, no node holds half the probability, and the nodes at both ends lie
    :data:`depthcore.exact.quadrature.CUTOFF` below the largest in log weight; at the first
    frame they do not, they are placed anew for the pairs up to it.

    **Smoothed.** Given the depth ``y_1`` the model is linear-Gaussian (module docstring), so
    each node's Gaussian of ``u_k`` given all pairs is its Rauch-Tung-Striebel smoother
    (textbook 19.2.3, :func:`depthcore.kalman.linear.fixed_interval_smoother`, the transition
    ``[[1, s], [0, 1]]`` in each block) run back from its filter at frame ``N``; the depth's
    posterior is the filter's at frame ``N``, so the smoothed density of the state at frame
    ``k`` is exactly the mixture over those nodes with those probabilities, the depth
    ``y_1 + t_k`` at each node. At frame ``N`` it is the filtered state.

    Parameters
    ----------
    mu : array_like, shape (N, 2)
        One track's pairs ``(x / y, h / y)``; ``NaN`` rows at missing frames, the first
        present.
    rho : float or array_like, shape (N,)
    prior_mean : array_like, shape (5,)
    prior_cov : array_like, shape (5, 5)
    process_noise : float
    steps : array_like, shape (N - 1,), or None
    rtol : float
        The quadrature's tolerance at every frame, relative to each SD.

    Returns
    -------
    SpatialTrack
    """
    pairs = check(mu, rho, steps)
    if pairs.batch != ():
        raise ValueError(f"mu must have shape (N, 2), one track, got shape {np.shape(mu)}")
    if not pairs.present[0, 0]:
        raise ValueError("mu: the first pair must be present to start the exact filter")
    m, P = _prior(prior_mean, prior_cov, 1, ())
    q = np.array([checks.nonnegative_scalar(process_noise, "process_noise")])
    rtol = checks.positive_scalar(rtol, "rtol")
    N = pairs.mu.shape[1]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        means, covs, nodes, p, history, placements = _filtered(pairs, m, P, q, rtol)
        F = np.broadcast_to(np.eye(4), (N - 1, 4, 4)).copy()
        F[:, 0, 1] = F[:, 2, 3] = pairs.steps[0]
        smooth = linear.fixed_interval_smoother(history, F)
        mean, cov = np.empty((N, 5)), np.empty((N, 5, 5))
        for k in range(N):
            M, C = smooth.mean[:, :, k], smooth.cov[:, :, k]
            mean[k], cov[k] = _moments(p, nodes, pairs.elapsed[:, k], M, C)
    if not all(np.all(np.isfinite(a)) for a in (means, covs, mean, cov)):
        raise ValueError(
            "mu, rho, prior_mean and prior_cov overflow the exact 3-D smoother in double "
            "precision; give values nearer the track's scale"
        )
    return SpatialTrack(Smoothed(means, covs), Smoothed(mean, cov), nodes[0], p[0], placements)


def _filtered(pairs: Pairs, m, P, q, rtol: float):
    """:func:`track`'s filter: the moments at every frame, (N, 5) and (N, 5, 5), the last
    nodes (1, J), their probabilities (1, J) at frame N, their filters' history and the
    number of placements."""
    N = pairs.mu.shape[1]
    floors = running_floor(pairs.elapsed)
    means, covs = np.empty((N, 5)), np.empty((N, 5, 5))
    eps = np.finfo(float).eps
    k, placements = 0, 0
    while k < N:
        cut = (pairs.mu[:, : k + 1], pairs.present[:, : k + 1], pairs.rho[:, : k + 1])
        nodes, log_w = _placed(Pairs(*cut, pairs.steps[:, :k], ()), m, P, q, rtol)
        placements += 1
        *_, history = node_filter(nodes, pairs, m, P, q, history=True)
        log_prior = conditional_prior(nodes, m, P)[2]
        a = (log_w + log_prior)[..., None] + np.cumsum(history.log_likelihoods, axis=-1)
        a = np.where(nodes[..., None] <= floors[:, None, :], -np.inf, a)
        start = k
        while k < N:
            M, C = history.means[:, :, k], history.covs[:, :, k]
            p, mean, cov, error = _weighted(a[..., k], nodes, pairs.elapsed[:, k], M, C)
            sd = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
            top = np.log(np.max(p))
            floor = 64.0 * eps * (np.abs(mean) + (2.0 + abs(top)) * sd)
            resolved = (
                np.all(error[0, 1:3] <= np.maximum(rtol * sd[0, 1:3], floor[0, 1:3]))
                and np.max(p) < 0.5
                and max(a[0, 0, k], a[0, -1, k]) < np.max(a[..., k]) - quadrature.CUTOFF
            )
            if k > start and not resolved:
                break
            means[k], covs[k] = mean[0], cov[0]
            k += 1
    return means, covs, nodes, p, history, placements
