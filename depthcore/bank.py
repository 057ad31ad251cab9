"""The exact optimal filter for any number of frames: a bank of Kalman filters over depth.

Recommended import: ``from depthcore import bank``.

The model for ``N`` frames. The state at frame ``k = 1 .. N`` is
``(x_k, y_k, v_k)``; it moves by

    y_{k+1} = y_k + 1,   x_{k+1} = x_k + v_k,   v_{k+1} = v_k + a_k,   a_k ~ N(0, q**2),

(``q = 0`` is the paper's constant velocity, Eq. (1)), the camera sees the
bearings ``mu_k = x_k / y_k + w_k``, ``w_k ~ N(0, rho**2)`` (Eq. (4)), and the
state at frame 1 has the Gaussian prior ``N(m, P)`` (Eq. (13)). With ``N = 3``
and ``q = 0`` this is the paper's problem.

Why a bank of Kalman filters is exact. The depth advances deterministically,
so fixing the depth at frame 1, ``y_1 = y``, fixes it at every frame,
``y_k = y + k - 1``. Given ``y`` the lateral state ``u_k = (x_k, v_k)`` is
linear-Gaussian (Prince, section 19.2, textbook Eqs. (19.5), (19.7)):

* its prior is the prior ``N(m, P)`` conditioned on ``y_1 = y``, a Gaussian in
  ``(x_1, v_1)`` with mean ``m_u + P_uy (y - m_y) / P_yy`` and covariance
  ``P_uu - P_uy P_yu / P_yy``;
* it moves by ``Psi = [[1, 1], [0, 1]]`` with noise ``Sigma_p = diag(0, q**2)``;
* each bearing is a linear observation of it, ``Phi_k = (1 / y_k, 0)``, with
  noise variance ``rho**2``.

So the Kalman filter (:mod:`depthcore.kalman`) gives the exact posterior of
``(x_N, v_N)`` given ``y`` and the marginal likelihood ``L(y) = p(mu_1 .. mu_N | y)``
from its innovations, and

    p(y_1 = y | mu_1 .. mu_N)  proportional to  N(y; m_y, P_yy) L(y).

The exact posterior of the state at frame ``N`` is the mixture over depth of
the Kalman filters' Gaussians weighted by this density. Given depth nodes
``y_j`` and quadrature weights ``w_j`` (``sum_j w_j g(y_j)`` approximates
``integral g(y) dy``), the mixture's probabilities are proportional to
``w_j N(y_j; m_y, P_yy) L(y_j)``, summed in log space. Adding a frame updates
each node's filter and log weight (:func:`step`); the past is not revisited.
The nodes are the depths at frame 1, which do not move as frames are added; the
depth at frame ``N`` is ``y_N = y_1 + N - 1``.

Frame by frame, :func:`track` follows one track: the filtered state at
every frame, the fixed-interval and fixed-lag smoothed states (textbook
19.2.6), and the posterior after each bearing; :func:`node_density` gives the
posterior depth density at a posterior's nodes.

The support is the caller's: the nodes must be positive (the point in front of
the camera at every frame, the "front" support of
:func:`depthcore.optimal.marginals`), and the mixture is exact up to the
quadrature error of the nodes, which the caller controls. At ``N = 3``,
``q = 0`` the unnormalised depth density is that of Eqs. (14)-(16)
(:func:`depthcore.optimal.conditional`) up to a constant factor.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.2 (the Kalman filter and its smoothers).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.special import ndtr

from . import _checks, kalman, model, optimal, quadrature, resampling

#: The lateral state ``(x, v)`` moves by ``x <- x + v``: the transition matrix.
PSI = np.array([[1.0, 1.0], [0.0, 1.0]])
PSI.setflags(write=False)

_LOG_2PI = float(np.log(2.0 * np.pi))
#: Nodes whose log probability is this far below the largest are ignored by the CDF.
_CUTOFF = 60.0
_MAX_DOUBLINGS = 12


class Bank(NamedTuple):
    """The bank of Kalman filters over depth nodes after ``N`` frames.

    Built by :func:`filter_bank`, extended by :func:`step`. The batch shape
    ``(...)`` is that of the trials (empty for one problem); ``J`` is the
    number of nodes.

    Attributes
    ----------
    nodes : ndarray, shape (..., J)
        Depths at frame 1, ``y_1 > 0``.
    mean : ndarray, shape (..., J, 2)
        ``E[(x_N, v_N) | y_1, mu_1 .. mu_N]`` for each node.
    cov : ndarray, shape (..., J, 2, 2)
        ``Cov[(x_N, v_N) | y_1, mu_1 .. mu_N]``.
    log_weight : ndarray, shape (..., J)
        ``log N(y_1; m_y, P_yy) + log p(mu_1 .. mu_N | y_1)``: the unnormalised log
        posterior density of the depth at frame 1.
    mu : ndarray, shape (..., N)
        The bearings so far.
    rho : ndarray, shape (...) or ()
    q : ndarray, shape (...) or ()
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
    history : kalman.FilterResult or None
        With ``history=True``: each node's filter at every frame, arrays of shape
        ``(..., J, N, ...)``.
    """

    nodes: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    log_weight: np.ndarray
    mu: np.ndarray
    rho: np.ndarray
    q: np.ndarray
    prior_mean: np.ndarray
    prior_cov: np.ndarray
    history: kalman.FilterResult | None

    @property
    def n_frames(self) -> int:
        """``N``, the number of bearings seen."""
        return self.mu.shape[-1]


# --- checks ----------------------------------------------------------------------------


def _nodes(nodes) -> np.ndarray:
    nodes = _checks.finite_array(nodes, "nodes")
    if nodes.ndim < 1 or nodes.shape[-1] < 1 or nodes.size == 0:
        raise ValueError(f"nodes must have shape (..., J) with J >= 1, got shape {nodes.shape}")
    if not np.all(nodes > 0):
        raise ValueError(
            f"nodes must be positive (depths at frame 1 in front of the camera), "
            f"got minimum {float(np.min(nodes)):.6g}"
        )
    return nodes


def _prior(prior_mean, prior_cov):
    prior_mean = _checks.finite_array(prior_mean, "prior_mean")
    if prior_mean.ndim < 1 or prior_mean.shape[-1] != 3:
        raise ValueError(f"prior_mean must have shape (..., 3), got shape {prior_mean.shape}")
    prior_cov = _checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.ndim < 2 or prior_cov.shape[-2:] != (3, 3):
        raise ValueError(f"prior_cov must have shape (..., 3, 3), got shape {prior_cov.shape}")
    prior_cov = _checks.covariances(prior_cov, "prior_cov", 3)
    return prior_mean, prior_cov


def _noise(rho, q):
    rho = _checks.finite_array(rho, "rho")
    if not np.all(rho > 0):
        raise ValueError(f"rho must be positive, got minimum {float(np.min(rho)):.6g}")
    q = _checks.finite_array(q, "q")
    if not np.all(q >= 0):
        raise ValueError(f"q must be >= 0, got minimum {float(np.min(q)):.6g}")
    return rho, q


def _bearings(mu) -> np.ndarray:
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim < 1 or mu.shape[-1] < 1:
        raise ValueError(f"mu must have shape (..., N) with N >= 1, got shape {mu.shape}")
    if mu.size == 0:
        raise ValueError(f"mu must hold at least one problem, got an empty batch {mu.shape}")
    return mu


# --- the model given the depth ---------------------------------------------------------


def conditional_prior(nodes, prior_mean, prior_cov):
    """The prior of ``(x_1, v_1)`` given the depth ``y_1``, and the prior depth density.

    Gaussian conditioning of ``N(m, P)`` on ``(x_1, y_1, v_1)``:
    ``E[u | y] = m_u + P_uy (y - m_y) / P_yy``, ``Cov[u | y] = P_uu - P_uy P_yu / P_yy``
    with ``u = (x_1, v_1)``.

    Parameters
    ----------
    nodes : ndarray, shape (..., J)
        Depths at frame 1.
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)

    Returns
    -------
    prior : kalman.MeanAndCov
        Mean (..., J, 2) and covariance (..., 1, 2, 2) of ``(x_1, v_1)`` given ``y_1``.
    log_density : ndarray, shape (..., J)
        ``log N(y_1; m_y, P_yy)``.
    """
    u = slice(0, 3, 2)  # x and v
    m_u, m_y = prior_mean[..., u], prior_mean[..., 1]
    P_yy = prior_cov[..., 1, 1]
    P_uy = prior_cov[..., u, 1]
    slope = P_uy / P_yy[..., None]  # (..., 2)
    d = nodes - m_y[..., None]  # (..., J)
    mean = m_u[..., None, :] + slope[..., None, :] * d[..., None]
    cov = prior_cov[..., u, u] - slope[..., :, None] * P_uy[..., None, :]
    log_density = -0.5 * (_LOG_2PI + np.log(P_yy)[..., None]) - 0.5 * d**2 / P_yy[..., None]
    return kalman.MeanAndCov(mean, cov[..., None, :, :]), log_density


def sigma_p(q) -> np.ndarray:
    """The lateral motion noise ``diag(0, q**2)``: shape ``q.shape + (2, 2)``."""
    q = np.asarray(q, dtype=float)
    out = np.zeros(q.shape + (2, 2))
    out[..., 1, 1] = q**2
    return out


def measurement_matrices(nodes, frames) -> np.ndarray:
    """``Phi_k = (1 / y_k, 0)`` with ``y_k = y_1 + k - 1``, for frames ``k`` (1-based).

    Parameters
    ----------
    nodes : ndarray, shape (..., J)
    frames : array_like of int, shape (K,)

    Returns
    -------
    ndarray, shape (..., J, K, 1, 2)
    """
    depth = nodes[..., None] + (np.asarray(frames, dtype=float) - 1.0)
    Phi = np.zeros(depth.shape + (1, 2))
    Phi[..., 0, 0] = 1.0 / depth
    return Phi


def lateral_filter(nodes, mu, rho, q, prior_mean, prior_cov):
    """The Kalman filter of ``(x, v)`` at each depth node in closed form: log weight, frame ``N``.

    The same filter as :func:`filter_bank` (textbook 19.2.1 prediction, 19.2.2
    update, the log likelihood from the innovations) with its 2 x 2 algebra
    written out, elementwise over the nodes, for the depth quadrature. With
    ``(a, b, c)`` the entries of ``Cov[(x, v)]`` and ``r_k = (rho y_k)**2``
    (the bearing noise in units of ``x``), the update by ``mu_k`` is::

        e = mu_k y_k - x,   x += a e / (a + r_k),   v += b e / (a + r_k),
        a' = a r_k / (a + r_k),   b' = b r_k / (a + r_k),
        det' = det r_k / (a + r_k),   c' = (det' + b'**2) / a',

    the log likelihood gains ``log N(mu_k; x / y_k, (a + r_k) / y_k**2)``,
    and the prediction is ``x += v``, ``a += 2 b + c``, ``b += c``,
    ``c += q**2``, ``det += q**2 a``. Tracking the determinant keeps ``c``
    free of cancellation when the bearings pin ``x`` far more tightly than
    the prior (small noise).

    Parameters
    ----------
    nodes : ndarray, shape (..., J)
        Depths at frame 1, > 0.
    mu : ndarray, shape (..., N)
    rho, q : ndarray, shape (...) or ()
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
        Already checked (see :func:`filter_bank`).

    Returns
    -------
    log_weight : ndarray, shape (..., J)
        ``log N(y_1; m_y, P_yy) + log p(mu_1 .. mu_N | y_1)``, as
        :attr:`Bank.log_weight`.
    mean : ndarray, shape (2, ..., J)
        ``E[x_N | y_1, mu]`` and ``E[v_N | y_1, mu]``, in rows.
    cov : tuple of three ndarrays, shape (..., J)
        ``Var[x_N]``, ``Cov[x_N, v_N]``, ``Var[v_N]`` given ``y_1`` and ``mu``.
    """
    start, log_weight = conditional_prior(nodes, prior_mean, prior_cov)
    rho2 = (np.asarray(rho, dtype=float) ** 2)[..., None]
    q2 = (np.asarray(q, dtype=float) ** 2)[..., None]
    # the covariance does not depend on the bearings: its shape leaves out theirs
    cov_shape = np.broadcast_shapes(start.cov.shape[:-2], nodes.shape, rho2.shape, q2.shape)
    M, C, rows = _lateral_state(
        np.broadcast_shapes(start.mean.shape[:-1], mu.shape[:-1] + (1,)), cov_shape
    )
    M[_X], M[_V] = start.mean[..., 0], start.mean[..., 1]
    c0 = start.cov[..., 0, :, :]
    a, b, c = c0[..., 0, 0, None], c0[..., 0, 1, None], c0[..., 1, 1, None]
    C[_A], C[_B], C[_DET], C[_C] = a, b, a * c - b * b, c
    noise = q2 if np.any(q2) else None  # None: constant velocity, Eq. (1)
    for k in range(mu.shape[-1]):
        if k:
            _predict_lateral(rows, noise)
        y = nodes + k  # y_k = y_1 + k - 1
        log_weight = log_weight + _update_lateral(rows, mu[..., k, None], y, rho2, y * y)
    return (
        log_weight,
        M,
        (rows.a.reshape(cov_shape), rows.b.reshape(cov_shape), rows.c.reshape(cov_shape)),
    )


#: Rows of the lateral state arrays of :func:`lateral_filter`: the means ``(x, v)``, and
#: the covariance entries ``a, b``, the determinant ``det`` and ``c``, in an order that
#: makes the paired updates single operations on slices.
_X, _V = 0, 1
_A, _B, _DET, _C = 0, 1, 2, 3


class _Rows(NamedTuple):
    """Views of the lateral state arrays ``M`` (2, ...) and ``C`` (4, ...), made once.

    The filter updates them in place (``out=``), so the views stay those of the state.
    """

    M: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    b: np.ndarray
    det: np.ndarray
    c: np.ndarray
    ab: np.ndarray
    ab_det: np.ndarray


def _lateral_state(mean_shape, cov_shape):
    """Empty state arrays for :func:`lateral_filter`, ``M`` (2, ...) and ``C`` (4, ...), and rows.

    ``M`` has the shape ``mean_shape`` and ``cov_shape`` broadcast to; ``C``
    has ``cov_shape``, padded with leading ones to that rank, so that
    ``C[_A : _B + 1]`` broadcasts against the means.
    """
    mean_shape = np.broadcast_shapes(mean_shape, cov_shape)
    pad = (1,) * (len(mean_shape) - len(cov_shape))
    M, C = np.empty((2,) + mean_shape), np.empty((4,) + pad + tuple(cov_shape))
    rows = _Rows(M, M[_X], M[_V], C[_A], C[_B], C[_DET], C[_C], C[_A : _B + 1], C[_A : _DET + 1])
    return M, C, rows


def _predict_lateral(s: _Rows, q2) -> None:
    """Textbook 19.2.1 for ``x <- x + v``, ``v <- v + a_k``, in place: see :func:`lateral_filter`.

    ``q2`` is ``q**2``, or ``None`` for no process noise (``q = 0``), where
    ``c`` and ``det`` are left as they are instead of adding zeros to them.
    """
    np.add(s.x, s.v, out=s.x)
    np.add(s.a, 2.0 * s.b, out=s.a)
    np.add(s.a, s.c, out=s.a)  # a + 2 b + c
    np.add(s.b, s.c, out=s.b)
    if q2 is not None:
        np.add(s.c, q2, out=s.c)
        np.add(s.det, q2 * s.a, out=s.det)


def _update_lateral(s: _Rows, mu_k, y, rho2, yy):
    """Textbook 19.2.2 for the bearing ``mu_k`` at depth ``y``, in place; the log likelihood.

    ``yy`` is ``y * y``. The log likelihood ``log N(mu_k; x / y, (a + r) / y**2)``
    is computed as ``-(log 2 pi + log((a + r) / y**2) + e g) / 2`` with
    ``g = e / (a + r)``.
    """
    r = rho2 * yy
    total = s.a + r
    e = mu_k * y - s.x
    g = e / total
    log_likelihood = -0.5 * (_LOG_2PI + np.log(total / yy) + e * g)
    np.add(s.M, s.ab * g, out=s.M)  # x + a g and v + b g
    np.multiply(s.ab_det, r / total, out=s.ab_det)  # a, b and det times r / (a + r)
    np.divide(s.det + s.b * s.b, s.a, out=s.c)
    return log_likelihood


# --- the bank --------------------------------------------------------------------------


def filter_bank(nodes, mu, rho, prior_mean, prior_cov, q=0.0, history: bool = False) -> Bank:
    """Run one Kalman filter (textbook 19.2.3) per depth node over the bearings ``mu_1 .. mu_N``.

    Parameters
    ----------
    nodes : array_like, shape (..., J)
        Depths at frame 1, all > 0. Leading axes broadcast with those of the
        other arguments (one set of nodes per trial, or shared).
    mu : array_like, shape (..., N)
        Bearings at frames 1 .. N, ``N >= 1``.
    rho : float or array_like, shape (...)
        Bearing noise SD, > 0.
    prior_mean : array_like, shape (..., 3)
        Prior mean of ``(x_1, y_1, v_1)``.
    prior_cov : array_like, shape (..., 3, 3)
        Prior covariance, symmetric positive definite.
    q : float or array_like, shape (...)
        SD of the lateral acceleration ``a_k``, >= 0 (0: constant velocity).
    history : bool
        Keep every node's filter at every frame (:meth:`Mixture.smoothed` reuses
        it, and reruns the filters without it).

    Returns
    -------
    Bank
        Finite: nodes so near 0 or so far that the filters' numbers overflow
        the doubles (the model holds ``1 / y`` and ``y**2``) are refused with a
        ValueError naming ``nodes``, never answered with NaN.
    """
    nodes = _nodes(nodes)
    mu = _bearings(mu)
    rho, q = _noise(rho, q)
    prior_mean, prior_cov = _prior(prior_mean, prior_cov)
    _batch(
        nodes=nodes.shape[:-1],
        mu=mu.shape[:-1],
        rho=rho.shape,
        q=q.shape,
        prior_mean=prior_mean.shape[:-1],
        prior_cov=prior_cov.shape[:-2],
    )
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        try:
            bank = _filter_bank(nodes, mu, rho, q, prior_mean, prior_cov, history)
        except ValueError:  # the Kalman filters' own refusal of an overflow
            bank = None
    if bank is None or not all(
        np.all(np.isfinite(a)) for a in (bank.mean, bank.cov, bank.log_weight)
    ):
        raise ValueError(
            f"nodes from {float(np.min(nodes))!r} to {float(np.max(nodes))!r} overflow the "
            "Kalman filters over depth (the model holds 1 / y and y**2) with these mu, rho "
            "and prior; give depths nearer the prior's"
        )
    return bank


def _batch(**shapes) -> tuple:
    """The shape the leading (batch) shapes broadcast to, or a ValueError naming them."""
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        listed = ", ".join(f"{k} {v}" for k, v in shapes.items())
        raise ValueError(f"the leading (batch) shapes do not broadcast: {listed}") from None


def _filter_bank(nodes, mu, rho, q, prior_mean, prior_cov, history) -> Bank:
    if not history:  # the closed form, as the depth quadrature uses
        log_weight, (x, v), (a, b, c) = lateral_filter(nodes, mu, rho, q, prior_mean, prior_cov)
        cov = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
        return Bank(
            nodes=nodes,
            mean=np.stack([x, v], -1),
            cov=cov,
            log_weight=log_weight,
            mu=mu,
            rho=rho,
            q=q,
            prior_mean=prior_mean,
            prior_cov=prior_cov,
            history=None,
        )
    N = mu.shape[-1]
    start, log_prior = conditional_prior(nodes, prior_mean, prior_cov)
    # per node (axis -3 of the Kalman arrays): the prior given its depth, Phi_k = (1 / y_k, 0)
    Phi = measurement_matrices(nodes, np.arange(1, N + 1))
    res = kalman.run(
        mu[..., None, :, None],
        start.mean,
        start.cov,
        PSI,
        sigma_p(q)[..., None, None, :, :],
        Phi,
        (rho**2)[..., None, None, None, None],
    )
    return Bank(
        nodes=nodes,
        mean=res.means[..., -1, :],
        cov=res.covs[..., -1, :, :],
        log_weight=log_prior + res.log_likelihood,
        mu=mu,
        rho=rho,
        q=q,
        prior_mean=prior_mean,
        prior_cov=prior_cov,
        history=res if history else None,
    )


def step(bank: Bank, mu_next) -> Bank:
    """Add frame ``N + 1``: predict (textbook 19.2.1) and update (19.2.2) every node's filter.

    Each node's log weight gains the log density of ``mu_{N+1}`` given the
    earlier bearings and its depth; nothing earlier is recomputed.

    Parameters
    ----------
    bank : Bank
        The bank after ``N`` frames.
    mu_next : float or array_like, shape (...)
        The bearing at frame ``N + 1``, one per trial.

    Returns
    -------
    Bank
        The bank after ``N + 1`` frames (with its history extended if it has one).
    """
    if not isinstance(bank, Bank):
        raise ValueError(f"bank must be a Bank, got {type(bank).__name__}")
    mu_next = _checks.finite_array(mu_next, "mu_next")
    _batch(bank=bank.log_weight.shape[:-1], mu_next=mu_next.shape)
    N = bank.n_frames
    if bank.history is None:  # the closed form of lateral_filter
        rho2 = (np.asarray(bank.rho) ** 2)[..., None]
        q2 = (np.asarray(bank.q) ** 2)[..., None]
        y = bank.nodes + N
        cov_shape = np.broadcast_shapes(bank.cov.shape[:-2], y.shape, rho2.shape, q2.shape)
        M, C, rows = _lateral_state(
            np.broadcast_shapes(bank.mean.shape[:-1], mu_next.shape + (1,)), cov_shape
        )
        M[_X], M[_V] = bank.mean[..., 0], bank.mean[..., 1]
        C[_A], C[_B], C[_C] = bank.cov[..., 0, 0], bank.cov[..., 0, 1], bank.cov[..., 1, 1]
        np.multiply(C[_A], C[_C], out=C[_DET])
        C[_DET] -= C[_B] * C[_B]
        _predict_lateral(rows, q2 if np.any(q2) else None)
        log_likelihood = _update_lateral(rows, mu_next[..., None], y, rho2, y * y)
        mean = np.empty(M.shape[1:] + (2,))
        mean[..., 0], mean[..., 1] = M[_X], M[_V]
        cov = np.empty(cov_shape + (2, 2))
        cov[..., 0, 0], cov[..., 1, 1] = C[_A], C[_C]
        cov[..., 0, 1] = cov[..., 1, 0] = C[_B]
        return bank._replace(
            mean=mean,
            cov=cov,
            mu=_extend(bank.mu, mu_next),
            log_weight=bank.log_weight + log_likelihood,
        )
    pred = kalman.predict(bank.mean, bank.cov, PSI, sigma_p(bank.q)[..., None, :, :])
    Phi = measurement_matrices(bank.nodes, [N + 1])[..., 0, :, :]
    upd = kalman.update(
        pred.mean, pred.cov, mu_next[..., None, None], Phi, (bank.rho**2)[..., None, None, None]
    )
    mu = _extend(bank.mu, mu_next)
    history = bank.history
    if history is not None:
        history = _append(history, pred, upd)
    return bank._replace(
        mean=upd.mean,
        cov=upd.cov,
        mu=mu,
        history=history,
        log_weight=bank.log_weight + upd.log_likelihood,
    )


def _extend(mu, mu_next):
    shape = np.broadcast_shapes(mu.shape[:-1], mu_next.shape)
    return np.concatenate(
        [np.broadcast_to(mu, shape + mu.shape[-1:]), np.broadcast_to(mu_next, shape)[..., None]],
        axis=-1,
    )


def _append(history: kalman.FilterResult, pred, upd) -> kalman.FilterResult:
    new = {
        "means": upd.mean,
        "covs": upd.cov,
        "predicted_means": pred.mean,
        "predicted_covs": pred.cov,
        "log_likelihoods": upd.log_likelihood,
    }
    core = {"means": 1, "predicted_means": 1, "covs": 2, "predicted_covs": 2, "log_likelihoods": 0}
    out = {}
    for k, old in zip(history._fields, history, strict=True):
        c = core[k]
        item = np.expand_dims(new[k], axis=-1 - c)
        batch = np.broadcast_shapes(old.shape[: old.ndim - c - 1], item.shape[: item.ndim - c - 1])
        out[k] = np.concatenate(
            [
                np.broadcast_to(old, batch + old.shape[old.ndim - c - 1 :]),
                np.broadcast_to(item, batch + item.shape[item.ndim - c - 1 :]),
            ],
            axis=-1 - c,
        )
    return kalman.FilterResult(**out)


# --- the mixture over the nodes --------------------------------------------------------


def mixture_moments(W, means, covs, depths):
    """Mean and covariance of ``(x, y, v)`` under a mixture over depth nodes.

    The law of total variance: the weighted covariance of the nodes' means
    plus their weighted covariances (:func:`_stacked_moments` with one set
    of weights); the depth is known exactly given the node.

    Parameters
    ----------
    W : array_like, shape (..., J)
        Weights >= 0 (probabilities once normalised).
    means : ndarray, shape (..., J, 2)
    covs : ndarray, shape (..., J, 2, 2)
        The Gaussians of ``(x, v)`` at each node.
    depths : ndarray, shape (..., J)
        The node depths.

    Returns
    -------
    mean : ndarray, shape (..., 3)
    cov : ndarray, shape (..., 3, 3)
    """
    mean, cov = _stacked_moments(np.asarray(W)[..., None, :], means, covs, depths)
    return mean[..., 0, :], cov[..., 0, :, :]


#: The second moments summed by :func:`_stacked_moments`: pairs of ``(x, y, v)`` ...
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
#: ... with each node's conditional covariance ``Cov[(x, v) | y_j]`` entry added to
#: ``(x, x)``, ``(v, v)`` and ``(x, v)``: (pair, covariance row, covariance column).
_CONDITIONAL = ((0, 0, 0), (2, 1, 1), (4, 0, 1))
_PAIR_FIRST, _PAIR_SECOND = (np.array(ix) for ix in zip(*_PAIRS, strict=True))
#: Where each entry of a 3 x 3 covariance (row-major) sits in :data:`_PAIRS` order.
_SYMMETRIC = np.array([0, 3, 4, 3, 1, 5, 4, 5, 2])


def _stacked_moments(W, means, covs, depths):
    """Mean and covariance of ``(x, y, v)`` under ``K`` weightings of the same node mixture.

    The law of total variance, summed about the node ``c`` of largest weight
    in the first weighting (the sums then carry no multiple of a large
    depth): with ``d_j = m_j - c``, ``m_j = (E[x | y_j], y_j, E[v | y_j])``
    and ``C_j`` the node's covariance of ``(x, v)`` (zero in the depth's row
    and column),

        S = sum_j W_j,   s = sum_j W_j d_j / S,   mean = c + s,
        cov = sum_j W_j (d_j d_j^T + C_j) / S - s s^T.

    The nodes' terms ``(1, d_j, d_j d_j^T + C_j)`` are formed once and summed
    for every weighting by one matrix product.

    Parameters
    ----------
    W : ndarray, shape (..., K, J)
        Weights >= 0 (need not be normalised); a row with no positive weight
        gets NaN moments.
    means : ndarray, shape (..., J, 2)
    covs : ndarray, shape (..., J, 2, 2)
    depths : ndarray, shape (..., J)

    Returns
    -------
    mean : ndarray, shape (..., K, 3)
    cov : ndarray, shape (..., K, 3, 3)
    """
    batch = np.broadcast_shapes(W.shape[:-2], means.shape[:-2], covs.shape[:-3], depths.shape[:-1])
    J = W.shape[-1]
    W = np.broadcast_to(W, batch + W.shape[-2:])
    top = np.argmax(W[..., 0, :], axis=-1)[..., None]  # (..., 1)
    terms = np.empty(batch + (10, J))  # per node: 1, d (3), the second moments (6)
    terms[..., 0, :] = 1.0
    terms[..., 1, :], terms[..., 2, :], terms[..., 3, :] = means[..., 0], depths, means[..., 1]
    d = terms[..., 1:4, :]
    centre = np.take_along_axis(d, top[..., None, :], -1)  # (..., 3, 1)
    d -= centre
    for k, (i, j) in enumerate(_PAIRS):
        np.multiply(d[..., i, :], d[..., j, :], out=terms[..., 4 + k, :])
    for k, i, j in _CONDITIONAL:
        terms[..., 4 + k, :] += covs[..., i, j]
    sums = W @ np.swapaxes(terms, -1, -2)  # (..., K, 10)
    total = sums[..., :1]
    # a weighting with no positive weight (every other node of a posterior that
    # sits on one node, in :func:`update`) has no moments: NaN, without a warning
    with np.errstate(invalid="ignore", divide="ignore"):
        shift = sums[..., 1:4] / total
        moments = sums[..., 4:] / total - shift[..., _PAIR_FIRST] * shift[..., _PAIR_SECOND]
    mean = centre[..., None, :, 0] + shift
    return mean, moments[..., _SYMMETRIC].reshape(moments.shape[:-1] + (3, 3))


class Smoothed(NamedTuple):
    """The state at every frame given all ``N`` bearings (the mixture of the nodes' smoothers).

    Attributes
    ----------
    mean : ndarray, shape (..., N, 3)
        ``E[(x_k, y_k, v_k) | mu_1 .. mu_N]``, row ``k - 1`` for frame ``k``.
    cov : ndarray, shape (..., N, 3, 3)
    """

    mean: np.ndarray
    cov: np.ndarray

    @property
    def depth_mean(self) -> np.ndarray:
        """``E[y_k]`` at every frame, shape (..., N)."""
        return self.mean[..., 1]

    @property
    def depth_sd(self) -> np.ndarray:
        return np.sqrt(self.cov[..., 1, 1])

    @property
    def lateral_mean(self) -> np.ndarray:
        """``E[x_k]`` at every frame, shape (..., N)."""
        return self.mean[..., 0]

    @property
    def lateral_sd(self) -> np.ndarray:
        return np.sqrt(self.cov[..., 0, 0])

    @property
    def velocity_mean(self) -> np.ndarray:
        return self.mean[..., 2]

    @property
    def velocity_sd(self) -> np.ndarray:
        return np.sqrt(self.cov[..., 2, 2])


@dataclass(frozen=True)
class Mixture:
    """The optimal posterior at frame ``N``: the bank's Gaussians mixed over the depth nodes.

    Built by :func:`mixture`. ``(...)`` is the batch shape.

    Attributes
    ----------
    bank : Bank
    log_weights : ndarray, shape (..., J)
        Log quadrature weights of the nodes.
    probabilities : ndarray, shape (..., J)
        ``w_j N(y_j; m_y, P_yy) L(y_j)``, normalised over the nodes.
    log_normaliser : ndarray, shape (...)
        ``log sum_j w_j N(y_j; m_y, P_yy) L(y_j)``: the log density of the bearings
        with the depth integrated over the nodes' support.
    mean : ndarray, shape (..., 3)
        Posterior mean of ``(x_N, y_N, v_N)``.
    cov : ndarray, shape (..., 3, 3)
        Posterior covariance of ``(x_N, y_N, v_N)``.
    depth_error, velocity_error : ndarray, shape (...), or None
        Error estimates of the depth's and the velocity's mean and SD when the
        nodes were placed by :func:`posterior` (and kept by :func:`update`):
        the change of those moments when every other node is dropped (the
        step doubled), floored by roundoff; ``None`` for caller-given nodes.
    rtol : float or None
        The tolerance the nodes were placed for (:func:`posterior`).
    """

    bank: Bank
    log_weights: np.ndarray
    probabilities: np.ndarray
    log_normaliser: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    depth_error: np.ndarray | None = None
    velocity_error: np.ndarray | None = None
    rtol: float | None = None

    @property
    def depth_mean(self) -> np.ndarray:
        """``E[y_N]``, shape (...)."""
        return self.mean[..., 1]

    @property
    def depth_sd(self) -> np.ndarray:
        return np.sqrt(self.cov[..., 1, 1])

    @property
    def velocity_mean(self) -> np.ndarray:
        """``E[v_N]``, shape (...)."""
        return self.mean[..., 2]

    @property
    def velocity_sd(self) -> np.ndarray:
        return np.sqrt(self.cov[..., 2, 2])

    def _query(self, value, name):
        """Queries as (batch..., K) and a function restoring the caller's shape."""
        value = _checks.finite_array(value, name)
        batch = self.log_normaliser.shape
        if batch == ():
            return value.reshape(-1), (lambda out: out.reshape(value.shape))
        if value.ndim < 1:
            raise ValueError(f"{name} must have shape (..., K) for a batch, got a scalar")
        try:
            np.broadcast_shapes(value.shape[:-1], batch)
        except ValueError:
            raise ValueError(
                f"{name} must have shape (..., K) with leading axes broadcasting "
                f"with {batch}, got shape {value.shape}"
            ) from None
        return value, (lambda out: out)

    def depth_log_pdf(self, y) -> np.ndarray:
        """Log posterior density of the depth at frame ``N``, ``y_N``; ``-inf`` at ``y_N <= N - 1``.

        Each query depth gets its own Kalman filter over all ``N`` bearings.

        Parameters
        ----------
        y : array_like
            Any shape for one problem; ``(..., K)`` for a batch.
        """
        y, restore = self._query(y, "y")
        b = self.bank
        y1 = y - (b.n_frames - 1)
        inside = y1 > 0
        log_w = _filter_bank(
            np.where(inside, y1, 1.0), b.mu, b.rho, b.q, b.prior_mean, b.prior_cov, False
        ).log_weight
        return restore(np.where(inside, log_w - self.log_normaliser[..., None], -np.inf))

    def depth_pdf(self, y) -> np.ndarray:
        """Posterior density of the depth at frame ``N`` (see :meth:`depth_log_pdf`)."""
        return np.exp(self.depth_log_pdf(y))

    def depth_cdf(self, y, rtol: float = 1e-10) -> np.ndarray:
        """``P(y_N <= y)``, integrated from the density.

        The mass lies between the smallest and largest nodes whose probability
        is within ``e**-60`` of the largest; the CDF is 0 below and 1 above them.
        In between, the density is integrated from the lower end by composite
        8-point Gauss-Legendre panels in ``t = log(y_1)``, the panels halved
        until the CDF changes by at most ``rtol``
        (:func:`depthcore.quadrature.gauss_legendre_cdf`).

        Parameters
        ----------
        y : array_like
            Depths at frame ``N``: any shape for one problem; ``(..., K)`` for a batch.
        rtol : float
            Absolute tolerance of the CDF, > 0, or its roundoff floor
            ``64 eps (1 + |t|) / sd_t`` where that is larger (``t`` the
            mixture's mean of ``log(y_1)``, ``sd_t`` its SD): at a tiny noise
            level the posterior is so narrow that the depths themselves, as
            floats, cannot resolve it further.
        """
        rtol = _positive_scalar(rtol, "rtol")
        y, restore = self._query(y, "y")
        b = self.bank
        log_p = b.log_weight + self.log_weights - self.log_normaliser[..., None]
        big = log_p > np.max(log_p, axis=-1, keepdims=True) - _CUTOFF
        nodes = np.broadcast_to(b.nodes, big.shape)
        lo = np.log(np.min(np.where(big, nodes, np.inf), axis=-1))[..., None]
        hi = np.log(np.max(np.where(big, nodes, 0.0), axis=-1))[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.log(np.maximum(y - (b.n_frames - 1), 0.0))
        top = np.minimum(t, hi)
        width = np.maximum(top - lo, 0.0)
        # Start with panels of half the SD of log(y_1) under each problem's mixture: as
        # many as the widest range in units of its own SD needs (in a batch of
        # problems, not the widest range over the narrowest SD).
        log_nodes = np.log(nodes)
        centre = np.sum(self.probabilities * log_nodes, axis=-1, keepdims=True)
        sd_t = np.sqrt(np.sum(self.probabilities * (log_nodes - centre) ** 2, axis=-1))
        panels = int(np.clip(np.ceil(np.max(width / (0.5 * sd_t[..., None] + 1e-3))), 4, 4096))
        # Roundoff: a depth is a float, rounded to eps (1 + |t|) in t, which moves the
        # log density by that times its slope, about z / sd_t at z SDs (|z| ~ 1 on
        # average); the CDF, an average of the density's relative errors, cannot
        # settle below 64 eps (1 + |t|) / sd_t (the safety factor of the package's
        # other roundoff floors), which matters only for posteriors narrower than
        # about 1e-5 of the depth in relative terms.
        eps = np.finfo(float).eps
        floor = 64.0 * eps * (1.0 + np.abs(centre)) / np.maximum(sd_t[..., None], eps)
        tol = np.maximum(rtol, floor)

        def density(tt):
            shape = tt.shape
            y1 = np.exp(tt.reshape(shape[:-3] + (-1,)))
            log_w = _filter_bank(y1, b.mu, b.rho, b.q, b.prior_mean, b.prior_cov, False).log_weight
            dens = np.exp(log_w - self.log_normaliser[..., None] + np.log(y1))  # dy = y dt
            return dens.reshape(shape)

        cdf, settled, panels = quadrature.gauss_legendre_cdf(
            density, lo, width, panels, tol, max_levels=_MAX_DOUBLINGS
        )
        if not settled:
            raise ValueError(
                f"y: the depth CDF did not settle to rtol = {rtol:.3g} (or its roundoff "
                f"floor) within {panels} panels"
            )
        cdf = np.where(t >= hi, 1.0, np.where(t <= lo, 0.0, np.clip(cdf, 0.0, 1.0)))
        return restore(cdf)

    @property
    def velocity_gap(self) -> np.ndarray:
        """The resolution of the velocity mixture, shape (...).

        The largest difference between the conditional means ``E[v_N | y_j]``
        of neighbouring nodes (in depth order), in units of the smaller
        conditional SD, over the pairs where either node has probability above
        ``1e-14`` of the largest. :meth:`velocity_pdf` and :meth:`velocity_cdf`
        sum one Gaussian per node; for Gaussians of equal SD spaced ``h`` SDs
        apart the sum ripples with relative amplitude ``2 exp(-2 pi**2 / h**2)``
        (Poisson summation): about ``5e-9`` at ``h = 1`` and ``1e-34`` at
        ``h = 0.5``, but ``0.2`` at ``h = 3``. The moments need no such
        resolution.
        """
        b = self.bank
        order = np.argsort(np.broadcast_to(b.nodes, self.probabilities.shape), axis=-1)
        p = np.take_along_axis(self.probabilities, order, axis=-1)
        m = np.take_along_axis(np.broadcast_to(b.mean[..., 1], p.shape), order, axis=-1)
        sd = np.take_along_axis(np.broadcast_to(np.sqrt(b.cov[..., 1, 1]), p.shape), order, axis=-1)
        big = p > 1e-14 * np.max(p, axis=-1, keepdims=True)
        gap = np.abs(np.diff(m, axis=-1)) / np.minimum(sd[..., 1:], sd[..., :-1])
        return np.max(np.where(big[..., 1:] | big[..., :-1], gap, 0.0), axis=-1, initial=0.0)

    def _velocity_terms(self):
        b = self.bank
        sd = np.sqrt(b.cov[..., 1, 1])
        return self.probabilities[..., None, :], b.mean[..., None, :, 1], sd[..., None, :]

    def velocity_pdf(self, v) -> np.ndarray:
        """Posterior density of ``v_N``: ``sum_j p_j N(v; E[v_N | y_j], Var[v_N | y_j])``.

        The nodes must be close enough that neighbouring conditional means
        differ by less than about a conditional SD (:attr:`velocity_gap`), or
        the sum ripples.

        Parameters
        ----------
        v : array_like
            Any shape for one problem; ``(..., K)`` for a batch.
        """
        v, restore = self._query(v, "v")
        W, m, sd = self._velocity_terms()
        z = (v[..., :, None] - m) / sd
        return restore(np.sum(W * np.exp(-0.5 * z**2) / (np.sqrt(2.0 * np.pi) * sd), axis=-1))

    def velocity_cdf(self, v) -> np.ndarray:
        """``P(v_N <= v)``: the mixture of the nodes' Gaussian CDFs.

        Converged only when the nodes resolve the velocity (:attr:`velocity_gap`
        below about 1), as for :meth:`velocity_pdf`.
        """
        v, restore = self._query(v, "v")
        W, m, sd = self._velocity_terms()
        return restore(np.sum(W * ndtr((v[..., :, None] - m) / sd), axis=-1))

    def smoothed(self) -> Smoothed:
        """Textbook 19.2.6: the state at every frame given all bearings.

        Each node's filter history (the bank's, or from a rerun of the filters
        if the bank kept none) is smoothed by the fixed-interval smoother
        (:func:`depthcore.kalman.fixed_interval_smoother`);
        the smoothed Gaussians of ``(x_k, v_k)`` are mixed with the nodes'
        probabilities, and the depth at frame ``k`` is ``y_1 + k - 1``.
        """
        b = self.bank
        res = b.history
        if res is None:
            res = _filter_bank(b.nodes, b.mu, b.rho, b.q, b.prior_mean, b.prior_cov, True).history
        s = kalman.fixed_interval_smoother(res, PSI)  # (..., J, N, 2), (..., J, N, 2, 2)
        frames = np.arange(b.n_frames)
        mean, cov = mixture_moments(
            self.probabilities[..., None, :],
            np.swapaxes(s.mean, -2, -3),
            np.swapaxes(s.cov, -3, -4),
            b.nodes[..., None, :] + frames[:, None],
        )
        return Smoothed(mean, cov)


def _positive_scalar(value, name: str) -> float:
    arr = _checks.finite_array(value, name)
    if arr.ndim != 0 or not arr > 0:
        raise ValueError(f"{name} must be a positive scalar, got {value!r}")
    return float(arr)


def mixture(bank: Bank, weights) -> Mixture:
    """The optimal posterior at frame ``N`` from the bank and the nodes' quadrature weights.

    Parameters
    ----------
    bank : Bank
    weights : array_like, shape (..., J)
        Quadrature weights of the nodes for integrals over the depth at frame 1
        (``sum_j w_j g(y_j)`` approximates ``integral g(y) dy``), broadcasting
        with ``bank.nodes``: >= 0 (a zero weight pads a batch's node sets to
        one length), at least one positive per problem.

    Returns
    -------
    Mixture
        The probabilities ``p_j`` proportional to ``w_j N(y_j; m_y, P_yy) L(y_j)``
        (in log space, the largest subtracted), the log normaliser, and the
        mixture's mean and covariance of ``(x_N, y_N, v_N)``: with
        ``m_j = (E[x_N | y_j], y_j + N - 1, E[v_N | y_j])``,
        ``mean = sum_j p_j m_j`` and
        ``cov = sum_j p_j (Cov[(x_N, v_N) | y_j] + (m_j - mean)(m_j - mean)^T)``.
    """
    if not isinstance(bank, Bank):
        raise ValueError(f"bank must be a Bank, got {type(bank).__name__}")
    weights = _checks.finite_array(weights, "weights")
    if not (np.all(weights >= 0) and np.all(np.any(weights > 0, axis=-1))):
        raise ValueError(
            "weights must be >= 0 with a positive one per problem, "
            f"got minimum {float(np.min(weights)):.6g}"
        )
    try:
        np.broadcast_shapes(weights.shape, bank.nodes.shape)
    except ValueError:
        raise ValueError(
            f"weights must broadcast with the nodes' shape {bank.nodes.shape}, "
            f"got shape {weights.shape}"
        ) from None
    with np.errstate(divide="ignore"):
        log_weights = np.log(weights)
    return _mixture(bank, log_weights)


def _mixture(bank: Bank, log_weights, halved: bool = False):
    """:func:`mixture` from the checked log quadrature weights (``-inf`` for a zero weight).

    With ``halved``, also the moments on every other node and the ends'
    freedom (:func:`_halving`), from the same pass over the nodes, for
    :func:`_resolution`: returns the Mixture, the halved mean (..., 3) and
    covariance (..., 3, 3), the largest log probability (..., 1) and ``free`` (...).
    """
    a = bank.log_weight + log_weights
    probabilities, log_normaliser = resampling.normalised(a)
    depth_N = bank.nodes + (bank.n_frames - 1)
    if not halved:
        mean, cov = mixture_moments(probabilities, bank.mean, bank.cov, depth_N)
        return Mixture(bank, log_weights, probabilities, log_normaliser, mean, cov)
    top = np.max(a, axis=-1, keepdims=True)
    every_other, free = _halving(a, top)
    W = np.empty(probabilities.shape[:-1] + (2,) + probabilities.shape[-1:])
    W[..., 0, :] = probabilities
    np.multiply(probabilities, every_other, out=W[..., 1, :])  # 0 off every other node
    mean, cov = _stacked_moments(W, bank.mean, bank.cov, depth_N)
    post = Mixture(
        bank, log_weights, probabilities, log_normaliser, mean[..., 0, :], cov[..., 0, :, :]
    )
    return post, mean[..., 1, :], cov[..., 1, :, :], top, free


# --- nodes placed by the depth quadrature ----------------------------------------------

#: Most frames of a problem (the filters' common limit).
MAX_FRAMES = _checks.MAX_FRAMES


def _quadrature_problem(mu, rho, prior_mean, prior_cov, process_noise):
    """The checked inputs as :class:`depthcore.quadrature.Problem`, and the batch shape."""
    mu, rho, prior_mean, prior_cov = model.batch_inputs(
        mu, rho, prior_mean, prior_cov, triples=False
    )
    if mu.shape[-1] > MAX_FRAMES:
        raise ValueError(f"mu: at most {MAX_FRAMES} frames, got {mu.shape[-1]}")
    batch, N = mu.shape[:-1], mu.shape[-1]
    q = _checks.nonnegative_batch(process_noise, "process_noise", batch)
    B = int(np.prod(batch))
    prior_cov = np.ascontiguousarray(np.broadcast_to(prior_cov, batch + (3, 3))).reshape(B, 3, 3)
    pb = quadrature.Problem(
        mu=mu.reshape(B, N),
        rho=np.broadcast_to(rho, batch).reshape(B),
        mean=np.broadcast_to(prior_mean, batch + (3,)).reshape(B, 3),
        R=np.linalg.inv(np.linalg.cholesky(prior_cov)),
        reading="derived",
        q=np.broadcast_to(q, batch).reshape(B),
        cov=prior_cov,
        integrand=_integrand,
    )
    return pb, batch


def _integrand(offsets, pb):
    """The depth quadrature's integrand: :func:`lateral_filter` at ``y_1 = offsets[..., 2]``."""
    return lateral_filter(offsets[..., 2], pb.mu, pb.rho, pb.q, pb.mean, pb.cov)


def _integrate(pb, rtol: float):
    """The quadrature of :mod:`depthcore.quadrature` on ``y_1 > 0``, moments of ``y_N``.

    The quadrature reports the depth as ``y_1 + 2`` (its variable is
    ``t = log(y_1)``, as for the paper's three frames); the depth at frame
    ``N`` is ``y_1 + N - 1``.
    """
    m, err_y, err_v, top, grids = quadrature.integrate(pb, (3,), rtol)
    mean = m.mean.copy()
    mean[:, 1] += pb.mu.shape[1] - 3
    err_y = np.maximum(err_y, 64.0 * np.finfo(float).eps * np.abs(mean[:, 1]))
    return m._replace(mean=mean), err_y, err_v, top, grids


def moments(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, rtol: float = 1e-10, chunk: int = 64
) -> optimal.Moments:
    """The exact posterior moments at frame ``N``, with the depth nodes placed by quadrature.

    The depth at frame 1 is integrated by the quadrature of
    :func:`depthcore.optimal.moments` (nodes about the posterior's own mode
    and width in ``t = log(y_1)``, the step halved until the moments settle,
    a node budget, a roundoff floor on the error estimate), with the
    integrand ``N(y_1; m_y, P_yy) L(y_1)`` and the Gaussian of ``(x_N, v_N)``
    given ``y_1`` from the Kalman filter at each node (:func:`lateral_filter`).

    Parameters
    ----------
    mu : array_like, shape (B, N) or (N,)
        Bearings at frames 1 .. N (any ``N >= 1``; the paper's problem is ``N = 3``).
    rho : float or array_like, shape (B,)
        Bearing noise SD, > 0.
    prior_mean : array_like, shape (3,) or (B, 3)
        Prior mean of ``(x_1, y_1, v_1)``.
    prior_cov : array_like, shape (3, 3) or (B, 3, 3)
        Prior covariance, symmetric positive definite.
    process_noise : float or array_like, shape (B,)
        SD ``q >= 0`` of the velocity's change per frame.
    rtol : float
        Target accuracy of each mean and SD, relative to the SD.
    chunk : int
        Problems integrated together (memory grows with it).

    Returns
    -------
    depthcore.optimal.Moments
        Arrays of shape (B,) (``(1,)`` for one problem), for the state at frame
        ``N``; ``prob_behind_camera`` is 0 (the support is ``y_1 > 0``).

    Raises
    ------
    ValueError
        For invalid inputs, naming the argument, or when the tolerance is out
        of reach within the quadrature's node budget, naming the problem.
    """
    pb, _ = _quadrature_problem(
        np.atleast_2d(mu) if np.ndim(mu) == 1 else mu, rho, prior_mean, prior_cov, process_noise
    )
    rtol = _checks.positive_scalar(rtol, "rtol")
    chunk = _checks.count(chunk, "chunk")
    out, means, covs = [], [], []
    for start in range(0, pb.mu.shape[0], chunk):
        m, err_y, err_v, _, _ = _integrate(pb.take(slice(start, start + chunk)), rtol)
        out.append(np.concatenate([m.key_moments(), [err_y, err_v, m.behind]]))
        means.append(m.mean)
        covs.append(m.cov)
    return optimal.Moments(
        *np.concatenate(out, axis=1), np.concatenate(means), np.concatenate(covs)
    )


def _grid_nodes(grid):
    """Depths at frame 1 (B, J) and log quadrature weights (B, J) of a quadrature grid.

    ``grid = (lo, h, n, frame)`` holds the trapezoid nodes ``u_j = lo + h j``,
    ``j < n``, of each problem in the quadrature's variable ``u``, with
    ``t = log(y_1)`` a function of ``u`` (:class:`depthcore.quadrature.Frame`);
    ``dy_1 = y_1 (dt/du) du``. Rows with fewer nodes are padded with weight 0.
    """
    lo, h, n, frame = grid
    u = quadrature.grid(lo, h, n, 0.0)
    pad = np.isnan(u)
    u = np.where(pad, lo[:, None], u)
    t = frame.t(u)
    log_w = np.log(np.where(h > 0, h, 1.0))[:, None] + t + frame.log_jacobian(u)
    return np.exp(t), np.where(pad, -np.inf, log_w)


def posterior(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, rtol: float = 1e-10, history: bool = False
) -> Mixture:
    """The exact posterior at frame ``N`` as a bank on nodes placed by the depth quadrature.

    The nodes and weights are the last trapezoid level of :func:`moments`'s
    quadrature, so the mixture's moments are those moments (to roundoff) and
    carry their error estimates. :func:`update` adds frames online.

    Parameters
    ----------
    mu : array_like, shape (N,) or (B, N)
    rho, prior_mean, prior_cov, process_noise, rtol
        As for :func:`moments`.
    history : bool
        Keep each node's filter at every frame (for :meth:`Mixture.smoothed`).

    Returns
    -------
    Mixture
        Batch shape ``()`` for ``mu`` of shape ``(N,)``, ``(B,)`` otherwise.
    """
    single = np.ndim(mu) == 1
    pb, _ = _quadrature_problem(
        np.atleast_2d(mu) if single else mu, rho, prior_mean, prior_cov, process_noise
    )
    rtol = _checks.positive_scalar(rtol, "rtol")
    return _place(pb, rtol, history, single)


#: Problems placed together by the quadrature (its memory grows with this times its nodes).
_CHUNK = 64


def _place(pb, rtol, history, single):
    B = pb.mu.shape[0]
    if B > _CHUNK:
        parts = [
            _place(pb.take(slice(i, i + _CHUNK)), rtol, history, False) for i in range(0, B, _CHUNK)
        ]
        return _concatenate(parts)
    _, err_y, err_v, _, grids = _integrate(pb, rtol)
    nodes, log_w = _grid_nodes(grids[3])
    shift = np.max(log_w, axis=1, keepdims=True)
    bank = _filter_bank(nodes, pb.mu, pb.rho, pb.q, pb.mean, pb.cov, history)
    post = mixture(bank, np.exp(log_w - shift))
    post = dataclasses.replace(
        post,
        log_weights=post.log_weights + shift,
        log_normaliser=post.log_normaliser + shift[:, 0],
        depth_error=err_y,
        velocity_error=err_v,
        rtol=rtol,
    )
    return _squeeze(post) if single else post


def _concatenate(parts) -> Mixture:
    """Batches of placed posteriors joined along the batch, their nodes padded to one count.

    A padded node has quadrature weight 0 (log weight ``-inf``) and probability
    0, so each problem's mixture is unchanged: its fields are joined, not
    recomputed.
    """
    J = max(p.log_weights.shape[-1] for p in parts)
    banks = [p.bank for p in parts]

    def join(get, axis, value):
        return np.concatenate([_pad(get(b), J, axis, value) for b in banks])

    bank = Bank(
        nodes=join(lambda b: b.nodes, 1, 1.0),
        mean=join(lambda b: b.mean, 1, 0.0),
        cov=join(lambda b: b.cov, 1, 1.0),
        log_weight=join(lambda b: b.log_weight, 1, 0.0),
        mu=np.concatenate([b.mu for b in banks]),
        rho=np.concatenate([b.rho for b in banks]),
        q=np.concatenate([b.q for b in banks]),
        prior_mean=np.concatenate([b.prior_mean for b in banks]),
        prior_cov=np.concatenate([b.prior_cov for b in banks]),
        history=None
        if banks[0].history is None
        else kalman.FilterResult(
            *(
                np.concatenate([_pad(a, J, 1, 1.0) for a in arrays])
                for arrays in zip(*(b.history for b in banks), strict=True)
            )
        ),
    )

    def rows(get, value=None):
        if value is None:
            return np.concatenate([get(p) for p in parts])
        return np.concatenate([_pad(get(p), J, 1, value) for p in parts])

    return Mixture(
        bank,
        log_weights=rows(lambda p: p.log_weights, -np.inf),
        probabilities=rows(lambda p: p.probabilities, 0.0),
        log_normaliser=rows(lambda p: p.log_normaliser),
        mean=rows(lambda p: p.mean),
        cov=rows(lambda p: p.cov),
        depth_error=rows(lambda p: p.depth_error),
        velocity_error=rows(lambda p: p.velocity_error),
        rtol=parts[0].rtol,
    )


def _each_array(post: Mixture, take) -> Mixture:
    """``post`` with ``take`` applied to every per-problem array (not ``rtol``)."""
    b = post.bank
    history = None if b.history is None else kalman.FilterResult(*(take(a) for a in b.history))
    return Mixture(
        Bank(*(take(a) for a in b[:-1]), history),
        *(
            take(getattr(post, name))
            for name in (
                "log_weights",
                "probabilities",
                "log_normaliser",
                "mean",
                "cov",
                "depth_error",
                "velocity_error",
            )
        ),
        post.rtol,
    )


def _squeeze(post: Mixture) -> Mixture:
    """A batch of one as a single problem (batch shape ``()``)."""
    return _each_array(post, lambda a: a[0])


#: An end node of a placed grid may carry at most this log probability below the largest
#: before :func:`update` re-places the nodes (the quadrature cuts its range at 60).
_END_MARGIN = 40.0


def _halving(log_p, top):
    """Every other node of the placed grid, and whether its ends are free.

    Parameters
    ----------
    log_p : ndarray, shape (..., J)
        The nodes' log probabilities up to a constant, ``-inf`` at padding.
    top : ndarray, shape (..., 1)
        Their largest.

    Returns
    -------
    every_other : ndarray of bool, shape (..., J)
        The nodes with positive weight an even number of places from the first.
    free : ndarray of bool, shape (...)
        The first and last nodes with positive weight carry log probabilities
        more than :data:`_END_MARGIN` below the largest.
    """
    valid = np.isfinite(log_p)
    J = log_p.shape[-1]
    first = np.argmax(valid, axis=-1)
    last = J - 1 - np.argmax(valid[..., ::-1], axis=-1)
    end = np.max(np.take_along_axis(log_p, np.stack([first, last], -1), -1), axis=-1)
    every_other = (np.arange(J) % 2 == (first % 2)[..., None]) & valid
    return every_other, end < top[..., 0] - _END_MARGIN


def _resolution(post: Mixture, halved_mean, halved_cov, top):
    """The error of the moments on the placed nodes and its roundoff floor, each (2, B).

    The nodes of :func:`posterior` are a trapezoid grid in order; dropping
    every other one (doubling the weights of the rest, :func:`_halving`)
    doubles the step, and the change of the depth's and the velocity's mean
    and SD estimates the error, as the quadrature's own halvings do
    (:func:`depthcore.quadrature.halving_error`, floored by roundoff).

    Parameters
    ----------
    post : Mixture
    halved_mean : ndarray, shape (B, 3)
    halved_cov : ndarray, shape (B, 3, 3)
        The mixture's moments on every other node.
    top : ndarray, shape (B, 1)
        The largest log probability of a node, up to the constant of ``post``'s
        log weights.
    """
    eps = np.finfo(float).eps
    floors = []
    for k in (1, 2):
        sd = np.sqrt(post.cov[..., k, k])
        floors.append(
            64.0 * eps * (np.abs(post.mean[..., k]) + sd + (1.0 + np.abs(top[..., 0])) * sd)
        )
    floors = np.stack(floors)
    return quadrature.halving_error(post.mean, post.cov, halved_mean, halved_cov, floors), floors


def _pad(a, J: int, axis: int, value):
    """``a`` padded with ``value`` along ``axis`` (counted from the end of the batch) to ``J``.

    ``a`` itself, not a copy, when it has ``J`` already.
    """
    if a.shape[axis] == J:
        return a
    width = [(0, 0)] * a.ndim
    width[axis] = (0, J - a.shape[axis])
    return np.pad(a, width, constant_values=value)


#: A node holding this much of the probability or more does not resolve the posterior
#: (a step of h carries about h / (2.5 sd) of a Gaussian's mass; the quadrature's
#: tolerances need h well below the SD).
_ONE_NODE = 0.5


def update(post: Mixture, mu_next) -> Mixture:
    """Add frame ``N + 1`` to a posterior from :func:`posterior`, online.

    Every node's Kalman filter and weight is updated (:func:`step`); nothing
    earlier is recomputed while the nodes still resolve the posterior to the
    tolerance they were placed for (:func:`_resolution`: the moments on every
    other node agree with those on all nodes, and the end nodes carry
    negligible probability). As the bearings accumulate, the posterior
    narrows, and a problem whose nodes no longer resolve it has them
    re-placed by the quadrature from all ``N + 1`` bearings (cost ``O(N)``
    for that problem, the others untouched). Since the posterior's width
    shrinks geometrically in the number of re-placements, they are rare and
    the cost per frame stays flat on average.

    Parameters
    ----------
    post : Mixture
        After ``N`` frames, from :func:`posterior` or :func:`update`.
    mu_next : float or array_like, shape (B,)
        The bearing at frame ``N + 1``, one per problem.

    Returns
    -------
    Mixture
        After ``N + 1`` frames, with error estimates.
    """
    if not isinstance(post, Mixture) or post.rtol is None:
        raise ValueError("post must be a Mixture from bank.posterior or bank.update")
    single = post.log_normaliser.ndim == 0
    if single:
        post = _batch_of_one(post)
    mu_next = _checks.finite_array(mu_next, "mu_next")
    if mu_next.ndim > 1 or (mu_next.ndim == 1 and mu_next.shape != post.log_normaliser.shape):
        raise ValueError(
            f"mu_next must be a scalar or have shape {post.log_normaliser.shape}, "
            f"got shape {mu_next.shape}"
        )
    if post.bank.n_frames >= MAX_FRAMES:
        raise ValueError(f"mu_next: at most {MAX_FRAMES} frames")
    new, err, floor, free = _step_rows(post, np.broadcast_to(mu_next, post.log_normaliser.shape))
    rtol = post.rtol
    ok = (
        free
        & (err[0] <= np.maximum(rtol * new.depth_sd, floor[0]))
        & (err[1] <= np.maximum(rtol * new.velocity_sd, floor[1]))
        # a posterior that has narrowed below the nodes' step sits on one node, whose
        # moments every other node reproduces when it is among them: a trapezoid rule
        # that resolves a density puts well under half its mass on any one node
        & (np.max(new.probabilities, axis=-1) < _ONE_NODE)
    )
    new = dataclasses.replace(new, depth_error=err[0], velocity_error=err[1], rtol=rtol)
    if not np.all(ok):
        # step and _mixture made new arrays for the nodes' filters and probabilities
        new = _replace_rows(new, ~ok, own=post.bank.history is None)
    return _squeeze(new) if single else new


#: Node entries (problems times nodes) per block of :func:`_step_rows`.
_BLOCK = 1 << 14


def _row_blocks(rows: int, nodes: int) -> list:
    """Slices of ``rows`` problems in blocks of about :data:`_BLOCK` entries (one row or more)."""
    size = max(1, _BLOCK // max(nodes, 1))
    return [slice(i, i + size) for i in range(0, rows, size)]


def _step_rows(post: Mixture, mu_next):
    """:func:`step`, :func:`_mixture` and :func:`_resolution` for :func:`update`, block by block.

    Each pass is elementwise or a sum over the nodes within a problem, so a
    block of problems at a time gives the same numbers as the whole batch at
    once, while the block's temporaries stay in the processor's cache instead
    of being allocated (and written) at the batch's full size.

    Parameters
    ----------
    post : Mixture
        Batch shape (B,).
    mu_next : ndarray, shape (B,)

    Returns
    -------
    new : Mixture
        After ``N + 1`` frames, without error estimates.
    err, floor : ndarray, shape (2, B)
    free : ndarray of bool, shape (B,)
        As :func:`_halving`.
    """
    B, J = post.log_weights.shape
    # the history grows along the frames, not by blocks: one block
    blocks = _row_blocks(B, J) if post.bank.history is None else [slice(None)]
    parts = []
    for rows in blocks:
        part = post if len(blocks) == 1 else _each_array(post, lambda a, rows=rows: a[rows])
        new, halved_mean, halved_cov, top, free = _mixture(
            step(part.bank, mu_next[rows]), part.log_weights, halved=True
        )
        parts.append((new, *_resolution(new, halved_mean, halved_cov, top), free))
    if len(parts) == 1:
        return parts[0]
    news = [p[0] for p in parts]

    def join(get):
        return np.concatenate([get(n) for n in news])

    bank = post.bank._replace(
        mean=join(lambda n: n.bank.mean),
        cov=join(lambda n: n.bank.cov),
        log_weight=join(lambda n: n.bank.log_weight),
        mu=join(lambda n: n.bank.mu),
    )
    new = Mixture(
        bank,
        post.log_weights,
        join(lambda n: n.probabilities),
        join(lambda n: n.log_normaliser),
        join(lambda n: n.mean),
        join(lambda n: n.cov),
    )
    err, floor = (np.concatenate([p[i] for p in parts], axis=1) for i in (1, 2))
    return new, err, floor, np.concatenate([p[3] for p in parts])


def _replace_rows(post: Mixture, rows, own: bool = False) -> Mixture:
    """``post`` with the problems at ``rows`` (B,) re-placed by the quadrature.

    With ``own``, the arrays of the nodes' means, covariances, log weights and
    probabilities belong to ``post`` alone and are overwritten where they keep
    their shape (saving a copy of each); ``post``'s other arrays are not.
    """
    b = post.bank
    idx = np.flatnonzero(rows)
    pb = quadrature.Problem(
        mu=b.mu[idx],
        rho=np.broadcast_to(b.rho, rows.shape)[idx],
        mean=b.prior_mean[idx],
        R=np.linalg.inv(np.linalg.cholesky(b.prior_cov[idx])),
        reading="derived",
        q=np.broadcast_to(b.q, rows.shape)[idx],
        cov=b.prior_cov[idx],
        integrand=_integrand,
    )
    fresh = _place(pb, post.rtol, b.history is not None, False)
    J = max(post.log_weights.shape[-1], fresh.log_weights.shape[-1])
    fb = fresh.bank

    def merge(old, new, axis, value, owned=False):
        # one copy of the old rows at most: padding makes one, else only an array not owned
        if old.shape[axis] < J:
            out = _pad(old, J, axis, value)
        else:
            out = old if owned else old.copy()
        out[idx] = _pad(new, J, axis, value)
        return out

    bank = b._replace(
        nodes=merge(np.broadcast_to(b.nodes, post.log_weights.shape), fb.nodes, 1, 1.0),
        mean=merge(b.mean, fb.mean, 1, 0.0, own),
        cov=merge(b.cov, fb.cov, 1, 1.0, own),
        log_weight=merge(b.log_weight, fb.log_weight, 1, 0.0, own),
        history=None,
    )
    # the other problems' mixtures are unchanged: their fields are merged, not recomputed
    return dataclasses.replace(
        post,
        bank=bank,
        log_weights=merge(post.log_weights, fresh.log_weights, 1, -np.inf),
        probabilities=merge(post.probabilities, fresh.probabilities, 1, 0.0, own),
        log_normaliser=np.where(rows, _full(fresh.log_normaliser, idx, rows), post.log_normaliser),
        mean=np.where(rows[:, None], _full(fresh.mean, idx, rows), post.mean),
        cov=np.where(rows[:, None, None], _full(fresh.cov, idx, rows), post.cov),
        depth_error=np.where(rows, _full(fresh.depth_error, idx, rows), post.depth_error),
        velocity_error=np.where(rows, _full(fresh.velocity_error, idx, rows), post.velocity_error),
        rtol=post.rtol,
    )


def _full(values, idx, rows):
    """``values`` (len(idx), ...) placed at ``idx`` in zeros of shape ``rows.shape + ...``."""
    out = np.zeros(rows.shape + np.shape(values)[1:])
    out[idx] = values
    return out


def _batch_of_one(post: Mixture) -> Mixture:
    """A single problem as a batch of one."""
    return _each_array(post, lambda a: np.asarray(a)[None])


# --- the posterior frame by frame: node densities, filtered and smoothed series ------------


def node_density(post: Mixture):
    """The posterior density of the depth at frame ``N`` at each of the bank's nodes.

    A node's probability is ``p_j = eta_j N(y_j; m_y, P_yy) L(y_j) / Z`` with its
    quadrature weight ``eta_j`` (``Mixture.log_weights``) and the normaliser
    ``Z`` (``Mixture.log_normaliser``), so ``p_j / eta_j`` is the normalised
    density of the depth at frame 1 at ``y_j``; the depth at frame ``N`` is
    ``y_j + N - 1`` with the same density (a shift).

    Parameters
    ----------
    post : Mixture

    Returns
    -------
    depths : ndarray, shape (..., J)
        ``y_j + N - 1``, the nodes as depths at frame ``N``.
    density : ndarray, shape (..., J)
        ``p(y_N = y_j + N - 1 | mu_1 .. mu_N)``; 0 at padding nodes (weight 0).
    """
    if not isinstance(post, Mixture):
        raise ValueError(f"post must be a Mixture, got {type(post).__name__}")
    b = post.bank
    log_density = b.log_weight - post.log_normaliser[..., None]
    density = np.where(np.isfinite(post.log_weights), np.exp(log_density), 0.0)
    depths = np.broadcast_to(b.nodes, density.shape) + (b.n_frames - 1)
    return depths, density


class Track(NamedTuple):
    """The state at every frame of one track, filtered and smoothed (:func:`track`).

    Each series is a :class:`Smoothed`: means (N, 3) and covariances (N, 3, 3) of
    ``(x_k, y_k, v_k)``, row ``k - 1`` for frame ``k``.

    Attributes
    ----------
    filtered : Smoothed
        Given ``mu_1 .. mu_k`` (the filter at frame ``k``).
    interval : Smoothed
        Given ``mu_1 .. mu_N`` (the fixed-interval smoother).
    lagged : Smoothed
        Given ``mu_1 .. mu_min(k + lag, N)`` (the fixed-lag smoother).
    lag : int
    posteriors : tuple of Mixture
        The posterior after each frame, ``posteriors[k - 1]`` after ``mu_k``.
    """

    filtered: Smoothed
    interval: Smoothed
    lagged: Smoothed
    lag: int
    posteriors: tuple


def track(mu, rho, prior_mean, prior_cov, process_noise=0.0, lag: int = 2, rtol: float = 1e-10):
    """The exact filter and its smoothers (textbook 19.2.6) at every frame of one track.

    The bearings arrive one at a time: the posterior after ``mu_1`` is placed
    by :func:`posterior` and each later bearing is added by :func:`update`
    (online). At frame ``k``:

    * the filtered state is the mixture of the nodes' Kalman filters
      (``Mixture.mean``, ``Mixture.cov`` after ``mu_k``);
    * the fixed-interval smoothed state is :meth:`Mixture.smoothed` of the
      posterior after all ``N`` bearings (each node's Rauch-Tung-Striebel
      smoother, mixed);
    * the fixed-lag smoothed state uses ``mu_1 .. mu_t``, ``t = min(k + lag, N)``:
      on the nodes of the posterior after ``mu_t``, each node's Gaussian of
      ``(x_k, v_k)`` given ``mu_1 .. mu_t`` is the Rauch-Tung-Striebel backward
      recursion (textbook 19.2.6) over the window, run from the node's filtered
      Gaussian at frame ``t`` back to frame ``k``; it equals the textbook's
      fixed-lag smoother in its state-augmentation form (the filter on the
      state augmented with its ``lag`` predecessors,
      :func:`depthcore.kalman.fixed_lag_smoother`). The nodes' Gaussians are
      mixed with that posterior's probabilities, the depth being
      ``y_1 + k - 1`` at each node.

    Cost. The frames whose ``t`` share a set of nodes (:func:`update` keeps
    them until it re-places them) are smoothed together: each node's Kalman
    filter is run once over the bearings, keeping its filtered and predicted
    Gaussians at every frame, and the backward steps are taken for all those
    frames and nodes at once, each frame's chain starting at its own ``t`` and
    stopping at ``k``. The cost is ``O(N)`` per set of nodes (and so per
    re-placement, as in :func:`update`) and ``O(lag)`` per frame (at most
    ``lag`` steps on 2 x 2 covariances); the augmented filter would cost
    ``O(lag**3)`` per frame (its covariance has side ``2 (lag + 1)``).

    Parameters
    ----------
    mu : array_like, shape (N,)
        The bearings of one track, ``N >= 1``.
    rho, prior_mean, prior_cov, process_noise, rtol
        As for :func:`posterior` (one problem).
    lag : int
        The fixed-lag smoother's delay in frames, >= 0 (0: the filter; from
        ``N - 1`` on, the fixed-interval smoother, which is what it then is).

    Returns
    -------
    Track
    """
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim != 1 or mu.size < 1:
        raise ValueError(f"mu must have shape (N,) with N >= 1 (one track), got shape {mu.shape}")
    lag = _checks.nonnegative_count(lag, "lag")
    posts = [posterior(mu[:1], rho, prior_mean, prior_cov, process_noise, rtol)]
    for k in range(1, mu.size):
        posts.append(update(posts[-1], mu[k]))
    filtered = Smoothed(np.stack([p.mean for p in posts]), np.stack([p.cov for p in posts]))
    interval = posts[-1].smoothed()
    # a delay reaching the last bearing from every frame: each frame is read from the
    # posterior after all N bearings, i.e. the fixed-interval smoother
    lagged = interval if lag >= mu.size - 1 else _lagged(posts, lag)
    return Track(filtered, interval, lagged, lag, tuple(posts))


def _lagged(posts, lag: int) -> Smoothed:
    """The fixed-lag smoothed state at every frame of :func:`track` (see there), 0-based.

    Frame ``s + 1`` is read from the posterior after ``mu_{t + 1}``,
    ``t = min(s + lag, N - 1)``. The frames ``t`` are split into runs whose
    posteriors share their nodes; the frames ``s`` read from a run are smoothed
    from that run's nodes' filters: every chain starts at the filtered
    Gaussian at its own ``t`` and takes the backward steps of textbook 19.2.6
    (:func:`depthcore.kalman.smoother_step`, each frame's gain computed once)
    with the others, stopping at its ``s``: at most ``lag`` steps, each over
    all the run's frames and nodes.
    """
    N = len(posts)
    cuts = [
        t for t in range(1, N) if not np.array_equal(posts[t].bank.nodes, posts[t - 1].bank.nodes)
    ]
    means, covs = np.empty((N, 3)), np.empty((N, 3, 3))
    for r, e in zip([0, *cuts], [*cuts, N], strict=True):  # the frames t in [r, e)
        first, last = max(r - lag, 0), (N if e == N else e - lag)  # the frames s read there
        if last <= first:
            continue
        b = posts[e - 1].bank
        h = _filter_bank(b.nodes, b.mu, b.rho, b.q, b.prior_mean, b.prior_cov, True).history
        s = np.arange(first, last)
        t = np.minimum(s + lag, N - 1)
        mean, cov = h.means[:, t, :], h.covs[:, t, :, :]  # (J, frames, ...): at each t
        # the gain at frame k serves every chain through k: one per frame and node
        gain = kalman.smoother_gain(h.covs[:, :-1], h.predicted_covs[:, 1:], PSI)
        for i in range(1, int(np.max(t - s)) + 1):  # w_{k} from w_{k + 1}, k = t - i
            k = np.maximum(t - i, np.minimum(s, t - 1))  # a finished chain: any frame, dropped
            step = kalman.smoother_step(
                gain[:, k],
                h.means[:, k, :],
                h.covs[:, k, :, :],
                h.predicted_means[:, k + 1, :],
                h.predicted_covs[:, k + 1, :, :],
                mean,
                cov,
            )
            going = (t - i >= s)[:, None]
            mean = np.where(going, step.mean, mean)
            cov = np.where(going[..., None], step.cov, cov)
        W = np.stack([posts[k].probabilities for k in t])
        means[first:last], covs[first:last] = mixture_moments(
            W, np.swapaxes(mean, 0, 1), np.swapaxes(cov, 0, 1), b.nodes + s[:, None]
        )
    return Smoothed(means, covs)
