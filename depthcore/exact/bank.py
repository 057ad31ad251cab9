"""The exact optimal filter for any number of frames: a bank of Kalman filters over depth.

Recommended import: ``from depthcore.exact import bank``.

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

So the Kalman filter (:mod:`depthcore.kalman.linear`) gives the exact posterior of
``(x_N, v_N)`` given ``y`` and the marginal likelihood ``L(y) = p(mu_1 .. mu_N | y)``
from its innovations, and

    p(y_1 = y | mu_1 .. mu_N)  proportional to  N(y; m_y, P_yy) L(y).

The exact posterior at frame ``N`` is the mixture over depth nodes ``y_j`` (depths
at frame 1, fixed as frames are added) with quadrature weights ``w_j`` of the
filters' Gaussians, with probabilities proportional to ``w_j N(y_j; m_y, P_yy)
L(y_j)`` (:mod:`depthcore.exact.mixture`; the nodes, positive, are placed by
:mod:`depthcore.exact.posterior`). A frame more updates each node's filter and
log weight (:func:`step`). At ``N = 3``, ``q = 0`` the depth density is that of
Eqs. (14)-(16) (:func:`depthcore.exact.optimal.conditional`) up to a constant.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.2 (the Kalman filter and its smoothers).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.exact import lateral, tracks
from depthcore.kalman import linear
from depthcore.problem import checks
from depthcore.problem.depth_prior import DepthPrior
from depthcore.problem.frames import depth_floor
from depthcore.problem.gaussian import MeanAndCov

#: The lateral state ``(x, v)`` moves by ``x <- x + v``: the transition matrix.
PSI = np.array([[1.0, 1.0], [0.0, 1.0]])
PSI.setflags(write=False)

_LOG_2PI = float(np.log(2.0 * np.pi))


class Bank(NamedTuple):
    """The bank of Kalman filters over ``J`` depth nodes after ``N`` frames, batch ``(...)``.

    Attributes
    ----------
    nodes : ndarray, shape (..., J)
        Depths at frame 1, ``y_1 > 0``.
    mean : ndarray, shape (..., J, 2)
    cov : ndarray, shape (..., J, 2, 2)
        ``E`` and ``Cov[(x_N, v_N) | y_1, mu_1 .. mu_N]``.
    log_weight : ndarray, shape (..., J)
        ``log p(y_1) + log p(mu_1 .. mu_N | y_1)``, the prior's depth density
        ``N(y_1; m_y, P_yy)`` or :attr:`law`'s.
    mu : ndarray, shape (..., N)
        ``NaN`` at a missing frame.
    rho : ndarray, shape (...) or ()
    process_noise : ndarray, shape (...) or ()
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
    frame_steps : ndarray, shape (..., N - 1)
        The depth's change from each frame to the next.
    frame_noise : ndarray, shape (..., N)
        The bearing noise SD at each frame.
    history : depthcore.kalman.linear.FilterResult or None
        Each node's filter at every frame, ``(..., J, N, ...)``.
    law : depthcore.problem.depth_prior.DepthPrior or None
        A prior whose depth law is not Gaussian, in place of ``prior_mean`` and
        ``prior_cov`` (:func:`conditional_prior`); ``None``: the Gaussian.
    """

    nodes: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    log_weight: np.ndarray
    mu: np.ndarray
    rho: np.ndarray
    process_noise: np.ndarray
    prior_mean: np.ndarray
    prior_cov: np.ndarray
    frame_steps: np.ndarray
    frame_noise: np.ndarray
    history: linear.FilterResult | None
    law: DepthPrior | None = None

    @property
    def steps(self) -> np.ndarray | None:
        """:attr:`frame_steps`, or ``None`` when they are all ones (the paper's frames)."""
        return None if np.all(self.frame_steps == 1.0) else self.frame_steps

    @property
    def frame_rho(self) -> np.ndarray | None:
        """:attr:`frame_noise`, or ``None`` when it is ``rho`` at every frame."""
        rho = np.asarray(self.rho)
        if rho.shape != self.frame_noise.shape and np.all(self.frame_noise == rho[..., None]):
            return None
        return self.frame_noise

    @property
    def frames(self) -> int:
        """``N``, the number of frames seen (missing ones included)."""
        return self.mu.shape[-1]

    @property
    def elapsed(self) -> np.ndarray:
        """The depth travelled since frame 1 at every frame, ``y_k - y_1``, shape (..., N)."""
        return tracks.elapsed(self.steps, self.frames)

    @property
    def floor(self) -> np.ndarray:
        """The depth at frame 1 below which the point has reached the camera, shape (...).

        :func:`depthcore.problem.frames.depth_floor`: 0 while the point only recedes.
        """
        return depth_floor(self.elapsed)

    @property
    def travelled(self) -> np.ndarray:
        """``y_N - y_1``, shape (...)."""
        if self.steps is None:
            return np.asarray(float(self.frames - 1))
        return self.elapsed[..., -1]

    def rerun(self, nodes, history: bool = False) -> Bank:
        """:func:`run_bank` on this bank's bearings, noise, prior and frames at other ``nodes``."""
        return run_bank(
            nodes,
            self.mu,
            self.rho,
            self.process_noise,
            self.prior_mean,
            self.prior_cov,
            history,
            self.steps,
            self.frame_rho,
            self.law,
        )


# --- checks ----------------------------------------------------------------------------


def _nodes(nodes) -> np.ndarray:
    nodes = checks.finite_array(nodes, "nodes")
    if nodes.ndim < 1 or nodes.shape[-1] < 1 or nodes.size == 0:
        raise ValueError(f"nodes must have shape (..., J) with J >= 1, got shape {nodes.shape}")
    if not np.all(nodes > 0):
        raise ValueError(
            f"nodes must be positive (depths at frame 1 in front of the camera), "
            f"got minimum {float(np.min(nodes)):.6g}"
        )
    return nodes


def _prior(prior_mean, prior_cov):
    prior_mean = checks.finite_array(prior_mean, "prior_mean")
    if prior_mean.ndim < 1 or prior_mean.shape[-1] != 3:
        raise ValueError(f"prior_mean must have shape (..., 3), got shape {prior_mean.shape}")
    prior_cov = checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.ndim < 2 or prior_cov.shape[-2:] != (3, 3):
        raise ValueError(f"prior_cov must have shape (..., 3, 3), got shape {prior_cov.shape}")
    prior_cov = checks.covariances(prior_cov, "prior_cov", 3)
    return prior_mean, prior_cov


def _noise(rho, q):
    rho = checks.finite_array(rho, "rho")
    if not np.all(rho > 0):
        raise ValueError(f"rho must be positive, got minimum {float(np.min(rho)):.6g}")
    q = checks.finite_array(q, "process_noise")
    if not np.all(q >= 0):
        raise ValueError(f"process_noise must be >= 0, got minimum {float(np.min(q)):.6g}")
    return rho, q


def _bearings(mu) -> np.ndarray:
    mu = checks.finite_array(mu, "mu")
    if mu.ndim < 1 or mu.shape[-1] < 1:
        raise ValueError(f"mu must have shape (..., N) with N >= 1, got shape {mu.shape}")
    if mu.size == 0:
        raise ValueError(f"mu must hold at least one problem, got an empty batch {mu.shape}")
    return mu


# --- the model given the depth ---------------------------------------------------------


def conditional_prior(nodes, prior_mean, prior_cov, law=None):
    """The prior of ``(x_1, v_1)`` given ``y_1`` (module docstring), and ``log N(y_1; m_y, P_yy)``.

    ``nodes`` (..., J), ``prior_mean`` (..., 3), ``prior_cov`` (..., 3, 3); returns a
    :class:`~depthcore.problem.gaussian.MeanAndCov` (..., J, 2) and (..., 1, 2, 2), and (..., J).
    With ``law`` (:class:`~depthcore.problem.depth_prior.DepthPrior`) its Gaussian given
    the depth, covariance (..., J, 2, 2), and its log density of the depth, in their place.
    """
    if law is not None:
        return law.lateral.at(nodes), law.log_pdf(nodes)
    u = slice(0, 3, 2)  # x and v
    m_u, m_y = prior_mean[..., u], prior_mean[..., 1]
    P_yy = prior_cov[..., 1, 1]
    P_uy = prior_cov[..., u, 1]
    slope = P_uy / P_yy[..., None]  # (..., 2)
    d = nodes - m_y[..., None]  # (..., J)
    mean = m_u[..., None, :] + slope[..., None, :] * d[..., None]
    cov = prior_cov[..., u, u] - slope[..., :, None] * P_uy[..., None, :]
    log_density = -0.5 * (_LOG_2PI + np.log(P_yy)[..., None]) - 0.5 * d**2 / P_yy[..., None]
    return MeanAndCov(mean, cov[..., None, :, :]), log_density


def sigma_p(process_noise) -> np.ndarray:
    """The lateral motion noise ``diag(0, q**2)``: shape ``q.shape + (2, 2)``."""
    process_noise = np.asarray(process_noise, dtype=float)
    out = np.zeros(process_noise.shape + (2, 2))
    out[..., 1, 1] = process_noise**2
    return out


def measurement_matrices(nodes, frames) -> np.ndarray:
    """``Phi_k = (1 / y_k, 0)``, ``y_k = y_1 + k - 1``, at frames ``k`` (K,): (..., J, K, 1, 2)."""
    depth = nodes[..., None] + (np.asarray(frames, dtype=float) - 1.0)
    Phi = np.zeros(depth.shape + (1, 2))
    Phi[..., 0, 0] = 1.0 / depth
    return Phi


def lateral_filter(
    nodes, mu, rho, process_noise, prior_mean, prior_cov, steps=None, frame_rho=None, law=None
):
    """The Kalman filter of ``(x, v)`` at each depth node in closed form: log weight, frame ``N``.

    :func:`filter_bank`'s filter (textbook 19.2.1, 19.2.2) written out elementwise.
    With ``(a, b, c)`` the entries of ``Cov[(x, v)]`` and ``r_k = (rho_k y_k)**2``,
    the update by ``mu_k`` is::

        e = mu_k y_k - x,   x += a e / (a + r_k),   v += b e / (a + r_k),
        a' = a r_k / (a + r_k),   b' = b r_k / (a + r_k),
        det' = det r_k / (a + r_k),   c' = (det + c r_k) / (a + r_k),

    the log likelihood gains ``log N(mu_k; x / y_k, (a + r_k) / y_k**2)``, and the
    prediction over a step ``s`` is ``x += s v``, ``a += s (2 b + s c)``, ``b += s c``,
    ``c += q**2 s``, ``det += q**2 s a`` (the determinant keeps ``c`` free of
    cancellation at small noise). A ``NaN`` bearing has no update.

    The arguments are :func:`run_bank`'s, checked. Returns ``log_weight`` (..., J) as
    :attr:`Bank.log_weight`, ``mean`` (2, ..., J) of ``x_N`` and ``v_N``, and ``cov``,
    three arrays (..., J): ``Var[x_N]``, ``Cov[x_N, v_N]``, ``Var[v_N]``.
    """
    start, log_weight = conditional_prior(nodes, prior_mean, prior_cov, law)
    # with noise per frame, rho is that array and is read frame by frame below
    rho2 = (np.asarray(rho if frame_rho is None else 1.0, dtype=float) ** 2)[..., None]
    q2 = (np.asarray(process_noise, dtype=float) ** 2)[..., None]
    missing = np.isnan(mu)
    gaps = bool(np.any(missing))
    # the covariance depends only on which bearings are present
    per_row = [a.shape[:-1] + (1,) for a in (steps, frame_rho) if a is not None]
    if gaps:
        per_row.append(mu.shape[:-1] + (1,))
    cov_shape = np.broadcast_shapes(
        start.cov.shape[:-2], nodes.shape, rho2.shape, q2.shape, *per_row
    )
    M, C, rows = lateral.state(
        np.broadcast_shapes(start.mean.shape[:-1], mu.shape[:-1] + (1,)), cov_shape
    )
    M[lateral.X_ROW], M[lateral.V_ROW] = start.mean[..., 0], start.mean[..., 1]
    # one covariance for every node (..., 1, 2, 2), or one each (..., J, 2, 2)
    a, b, c = start.cov[..., 0, 0], start.cov[..., 0, 1], start.cov[..., 1, 1]
    C[lateral.A_ROW], C[lateral.B_ROW], C[lateral.DET_ROW], C[lateral.C_ROW] = (
        a,
        b,
        a * c - b * b,
        c,
    )
    noise = q2 if np.any(q2) else None  # None: constant velocity, Eq. (1)
    if steps is None and frame_rho is None and not gaps:  # the paper's frames
        for k in range(mu.shape[-1]):
            if k:
                lateral.predict_unit(rows, noise)
            y = nodes + k  # y_k = y_1 + k - 1
            log_weight = log_weight + lateral.update(rows, mu[..., k, None], y, rho2, y * y)
    else:
        depth = tracks.elapsed(steps, mu.shape[-1])
        for k in range(mu.shape[-1]):
            if k:
                s = None if steps is None else steps[..., k - 1, None]
                lateral.predict(rows, noise, s)
            y = nodes + depth[..., k, None]
            reached = y <= 0  # at or behind the camera: no weight
            if np.any(reached):
                log_weight = np.where(reached, -np.inf, log_weight)
                y = np.where(reached, 1.0, y)
            r2 = rho2 if frame_rho is None else (frame_rho[..., k, None] ** 2)
            log_weight = log_weight + lateral.masked_update(rows, M, C, mu[..., k, None], y, r2)
    return (
        log_weight,
        M,
        (rows.a.reshape(cov_shape), rows.b.reshape(cov_shape), rows.c.reshape(cov_shape)),
    )


# --- the bank --------------------------------------------------------------------------


def filter_bank(
    nodes, mu, rho, prior_mean, prior_cov, process_noise=0.0, history: bool = False, steps=None
) -> Bank:
    """Run one Kalman filter (textbook 19.2.3) per depth node over the bearings ``mu_1 .. mu_N``.

    Parameters
    ----------
    nodes : array_like, shape (..., J)
        Depths at frame 1, > 0; leading axes broadcast with the others'. A node
        that puts the point at or behind the camera at some frame (below
        :attr:`Bank.floor`, for a camera that approaches) has no weight.
    mu : array_like, shape (..., N)
        ``NaN`` at a missing frame.
    rho : float or array_like, shape (...) or (..., N)
        Bearing noise SD, > 0, per problem or per frame.
    prior_mean, prior_cov : array_like, shapes (..., 3) and (..., 3, 3)
    process_noise : float or array_like, shape (...)
        SD of the lateral acceleration ``a_k``, >= 0.
    history : bool
        Keep every node's filter at every frame (for ``Mixture.smoothed``).
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
        The depth's signed change between frames, nonzero (negative: the camera
        approaches; ``None``: unit steps), with ``x_{k+1} = x_k + s_k v_k`` and
        ``a_k ~ N(0, q**2 |s_k|)``.

    Returns
    -------
    Bank
        Finite: nodes whose filters overflow are refused with a ValueError.
    """
    nodes = _nodes(nodes)
    mu, rho, steps, frame_rho = tracks.check_track(mu, rho, steps, _bearings)
    rho, process_noise = _noise(rho, process_noise)
    prior_mean, prior_cov = _prior(prior_mean, prior_cov)
    _batch(
        nodes=nodes.shape[:-1],
        mu=mu.shape[:-1],
        rho=rho.shape if frame_rho is None else rho.shape[:-1],  # per frame: (..., N)
        process_noise=process_noise.shape,
        prior_mean=prior_mean.shape[:-1],
        prior_cov=prior_cov.shape[:-2],
    )
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        try:
            bank = run_bank(
                nodes, mu, rho, process_noise, prior_mean, prior_cov, history, steps, frame_rho
            )
        except ValueError:  # the Kalman filters' own refusal of an overflow
            bank = None
    if bank is not None and np.any(np.all(bank.log_weight == -np.inf, axis=-1)):
        raise ValueError(
            f"nodes: every node is at or behind the floor {float(np.max(bank.floor)):.6g}, "
            "where the point would reach the camera; give depths at frame 1 above it"
        )
    if (
        bank is None
        or not all(np.all(np.isfinite(a)) for a in (bank.mean, bank.cov))
        # no weight only where the point would reach the camera
        or not np.all(np.isfinite(bank.log_weight) | (nodes <= bank.floor[..., None]))
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


def run_bank(
    nodes,
    mu,
    rho,
    process_noise,
    prior_mean,
    prior_cov,
    history,
    steps=None,
    frame_rho=None,
    law=None,
) -> Bank:
    """:func:`filter_bank` on inputs it has checked (``frame_rho`` (..., N) or ``None``), with
    ``law`` (:class:`~depthcore.problem.depth_prior.DepthPrior`) the prior in place of the
    Gaussian's (:func:`conditional_prior`)."""
    q = process_noise
    frames_ = tracks.frame_fields(mu, rho, steps, frame_rho)
    res = None
    if not history:  # the closed form, as the depth quadrature uses
        log_weight, (x, v), (a, b, c) = lateral_filter(
            nodes, mu, rho, q, prior_mean, prior_cov, steps, frame_rho, law
        )
        mean = np.stack([x, v], -1)
        cov = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
    else:
        N = mu.shape[-1]
        start, log_prior = conditional_prior(nodes, prior_mean, prior_cov, law)
        if steps is None and frame_rho is None and not np.any(np.isnan(mu)):
            # per node (axis -3 of the Kalman arrays): the prior given its depth,
            # Phi_k = (1 / y_k, 0)
            Phi = measurement_matrices(nodes, np.arange(1, N + 1))
            res = linear.run(
                mu[..., None, :, None],
                start.mean,
                start.cov,
                PSI,
                sigma_p(q)[..., None, None, :, :],
                Phi,
                (rho**2)[..., None, None, None, None],
            )
        else:
            res = tracks.irregular_history(start, nodes, mu, rho, q, steps, frame_rho)
        mean, cov = res.means[..., -1, :], res.covs[..., -1, :, :]
        log_weight = log_prior + res.log_likelihood
    if steps is not None:  # no weight where the point would reach the camera
        floor = depth_floor(tracks.elapsed(steps, mu.shape[-1]))
        log_weight = np.where(nodes > floor[..., None], log_weight, -np.inf)
    return Bank(
        nodes=nodes,
        mean=mean,
        cov=cov,
        log_weight=log_weight,
        mu=mu,
        rho=rho,
        process_noise=q,
        prior_mean=prior_mean,
        prior_cov=prior_cov,
        history=res,
        law=law,
        **frames_,
    )


def step(bank: Bank, mu_next, rho=None, step=1.0, gaps: bool = False) -> Bank:
    """Add frame ``N + 1``: predict (textbook 19.2.1) and update (19.2.2) every node's filter.

    Each node's log weight gains the log density of ``mu_{N+1}``; nothing earlier is
    recomputed (a bank with a history and irregular frames is rerun).

    Parameters
    ----------
    mu_next : float or array_like, shape (...)
        ``NaN`` (with ``gaps``) for a trial without a bearing.
    rho : float or array_like, shape (...), or None
        ``None``: the bank's (needed with noise per frame).
    step : float or array_like, shape (...)
        The depth's signed change from frame ``N`` to ``N + 1``, nonzero (negative:
        the camera approaches; nodes that the step brings to the camera lose their weight).
    gaps : bool

    Returns
    -------
    Bank
    """
    if not isinstance(bank, Bank):
        raise ValueError(f"bank must be a Bank, got {type(bank).__name__}")
    raw = checks.as_float(mu_next, "mu_next")
    if not gaps and not np.all(np.isfinite(raw)):
        raise ValueError("mu_next must be finite (or NaN for a missing frame, with gaps=True)")
    step_ = checks.finite_array(step, "step")
    if np.any(step_ == 0):
        raise ValueError("step must be nonzero (the depth's signed change), got a zero step")
    plain = (
        rho is None
        and not np.any(np.isnan(raw))
        and np.all(step_ == 1.0)
        and step_.ndim == 0
        and bank.steps is None
        and bank.frame_rho is None
    )
    if plain:
        return _step(bank, mu_next)
    if np.any(np.isinf(raw)):
        raise ValueError("mu_next must be finite or NaN (a missing frame), got infinite entries")
    _batch(bank=bank.log_weight.shape[:-1], mu_next=raw.shape, step=step_.shape)
    N = bank.frames
    if rho is None:
        if bank.frame_rho is not None:
            raise ValueError("rho: this bank has a noise level per frame; give the new frame's")
        rho_next = np.asarray(bank.rho, dtype=float)
    else:
        rho_next = checks.finite_array(rho, "rho")
        if not np.all(rho_next > 0):
            raise ValueError(f"rho must be positive, got minimum {float(np.min(rho_next)):.6g}")
    batch = np.broadcast_shapes(bank.mu.shape[:-1], raw.shape, step_.shape, rho_next.shape)
    mu = np.concatenate(
        [np.broadcast_to(bank.mu, batch + (N,)), np.broadcast_to(raw, batch)[..., None]], -1
    )
    old_steps = np.ones(N - 1) if bank.steps is None else bank.steps
    steps = np.concatenate(
        [np.broadcast_to(old_steps, batch + (N - 1,)), np.broadcast_to(step_, batch)[..., None]],
        -1,
    )
    same_rho = bank.frame_rho is None and (rho is None or np.array_equal(rho_next, bank.rho))
    frame_rho = None
    if not same_rho:
        old = bank.frame_rho
        if old is None:
            old = np.broadcast_to(np.asarray(bank.rho, dtype=float)[..., None], batch + (N,))
        frame_rho = np.concatenate(
            [np.broadcast_to(old, batch + (N,)), np.broadcast_to(rho_next, batch)[..., None]], -1
        )
    steps_or_none = None if np.all(steps == 1.0) else steps
    if bank.history is not None:
        return run_bank(
            bank.nodes,
            mu,
            bank.rho if frame_rho is None else frame_rho,
            bank.process_noise,
            bank.prior_mean,
            bank.prior_cov,
            True,
            steps_or_none,
            frame_rho,
        )
    rho2 = (rho_next**2)[..., None]
    q2 = (np.asarray(bank.process_noise) ** 2)[..., None]
    s = step_[..., None]
    y = bank.nodes + (bank.travelled[..., None] + s)
    reached = y <= 0  # the point at or behind the camera: no weight from here on
    y = np.where(reached, 1.0, y)
    cov_shape = np.broadcast_shapes(bank.cov.shape[:-2], y.shape, rho2.shape, q2.shape)
    if np.any(np.isnan(raw)):
        cov_shape = np.broadcast_shapes(cov_shape, raw.shape + (1,))
    if np.any(reached):  # its own covariance per node: reached nodes are not updated
        cov_shape = np.broadcast_shapes(cov_shape, reached.shape)
    M, C, rows = lateral.loaded_state(
        bank, np.broadcast_shapes(bank.mean.shape[:-1], raw.shape + (1,)), cov_shape
    )
    noise = q2 if np.any(q2) else None
    lateral.predict(rows, noise, None if np.all(step_ == 1.0) and step_.ndim == 0 else s)
    bearing = raw[..., None]
    if np.any(reached):  # no update where the point has reached the camera: no weight there
        bearing = np.where(reached, np.nan, bearing)
    log_likelihood = lateral.masked_update(rows, M, C, bearing, y, rho2)
    log_likelihood = np.where(reached, -np.inf, log_likelihood)
    return bank._replace(
        mean=lateral.pack_mean(M),
        cov=lateral.pack_cov(C, cov_shape),
        mu=mu,
        log_weight=bank.log_weight + log_likelihood,
        rho=bank.rho if frame_rho is None else frame_rho,
        **tracks.frame_fields(mu, bank.rho, steps_or_none, frame_rho),
    )


def _step(bank: Bank, mu_next) -> Bank:
    """:func:`step` on the paper's frames: a unit step, a bearing, the bank's ``rho``."""
    mu_next = checks.finite_array(mu_next, "mu_next")
    _batch(bank=bank.log_weight.shape[:-1], mu_next=mu_next.shape)
    N = bank.frames
    if bank.history is None:  # the closed form of lateral_filter
        rho2 = (np.asarray(bank.rho) ** 2)[..., None]
        q2 = (np.asarray(bank.process_noise) ** 2)[..., None]
        y = bank.nodes + N
        cov_shape = np.broadcast_shapes(bank.cov.shape[:-2], y.shape, rho2.shape, q2.shape)
        M, C, rows = lateral.loaded_state(
            bank, np.broadcast_shapes(bank.mean.shape[:-1], mu_next.shape + (1,)), cov_shape
        )
        lateral.predict_unit(rows, q2 if np.any(q2) else None)
        log_likelihood = lateral.update(rows, mu_next[..., None], y, rho2, y * y)
        return bank._replace(
            mean=lateral.pack_mean(M),
            cov=lateral.pack_cov(C, cov_shape),
            mu=(mu := _extend(bank.mu, mu_next)),
            log_weight=bank.log_weight + log_likelihood,
            **tracks.frame_fields(mu, bank.rho, None, None),
        )
    pred = linear.predict(bank.mean, bank.cov, PSI, sigma_p(bank.process_noise)[..., None, :, :])
    Phi = measurement_matrices(bank.nodes, [N + 1])[..., 0, :, :]
    upd = linear.update(
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
        **tracks.frame_fields(mu, bank.rho, None, None),
    )


def _extend(mu, mu_next):
    shape = np.broadcast_shapes(mu.shape[:-1], mu_next.shape)
    return np.concatenate(
        [np.broadcast_to(mu, shape + mu.shape[-1:]), np.broadcast_to(mu_next, shape)[..., None]],
        axis=-1,
    )


def _append(history: linear.FilterResult, pred, upd) -> linear.FilterResult:
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
    return linear.FilterResult(**out)
