"""The exact posterior at frame ``N``: the filter bank's Gaussians mixed over the depth nodes.

Recommended import: ``from depthcore.exact import mixture``.

Given a :class:`~depthcore.exact.bank.Bank` (one Kalman filter per depth node) and
the nodes' quadrature weights ``w_j``, the posterior of the state at frame
``N`` is the mixture over the nodes of the filters' Gaussians with
probabilities proportional to ``w_j N(y_j; m_y, P_yy) L(y_j)``
(:func:`mixture`, summed in log space). A :class:`Mixture` gives the
mixture's moments, the depth's and the velocity's marginal densities and
CDFs, and the fixed-interval smoothed states (:meth:`Mixture.smoothed`,
textbook 19.2.6), each a :class:`Smoothed`. :class:`Moments` holds the
moments and their error estimates that the optimal filter's quadrature and
the bank report for a batch of problems.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.2 (the Kalman filter and its smoothers).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.special import ndtr

from depthcore.exact.bank import PSI, Bank
from depthcore.exact.cdf import gauss_legendre_cdf
from depthcore.exact.tracks import transitions
from depthcore.kalman import linear
from depthcore.problem import checks, predictive
from depthcore.problem.gaussian import component_mean, component_sd
from depthcore.problem.weights import normalised

#: Nodes whose log probability is this far below the largest are ignored by the CDF.
_CUTOFF = 60.0
_MAX_DOUBLINGS = 12


# --- the mixture over the nodes --------------------------------------------------------


def mixture_moments(W, means, covs, depths):
    """Mean and covariance of ``(x, y, v)`` under a mixture over depth nodes.

    :func:`_stacked_moments` with one set of weights.

    Parameters
    ----------
    W : array_like, shape (..., J)
        Weights >= 0.
    means : ndarray, shape (..., J, 2)
    covs : ndarray, shape (..., J, 2, 2)
        The Gaussians of ``(x, v)`` at each node.
    depths : ndarray, shape (..., J)

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

    Parameters
    ----------
    W : ndarray, shape (..., K, J)
        Weights >= 0; a row with no positive weight gets NaN moments.
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
    # sits on one node, in :func:`~depthcore.exact.posterior.update`) has no moments: NaN, without a
    # warning
    with np.errstate(invalid="ignore", divide="ignore"):
        shift = sums[..., 1:4] / total
        moments = sums[..., 4:] / total - shift[..., _PAIR_FIRST] * shift[..., _PAIR_SECOND]
    mean = centre[..., None, :, 0] + shift
    return mean, moments[..., _SYMMETRIC].reshape(moments.shape[:-1] + (3, 3))


class Moments(NamedTuple):
    """Moments of the optimal depth and velocity marginals for a batch of problems.

    Every field is an array of shape (B,); ``depth_error`` and ``velocity_error`` are
    :func:`depthcore.exact.quadrature.halving_error`'s; ``prob_behind_camera`` is
    ``P(y - 2 <= 0)``; ``mean`` (B, 3) and ``cov`` (B, 3, 3) are of ``(x, y, v)``.
    """

    depth_mean: np.ndarray
    depth_sd: np.ndarray
    velocity_mean: np.ndarray
    velocity_sd: np.ndarray
    depth_error: np.ndarray
    velocity_error: np.ndarray
    prob_behind_camera: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


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

    depth_mean = component_mean(1, "``E[y_k]`` at every frame, shape (..., N).")
    depth_sd = component_sd(1, "The SD of ``y_k`` at every frame, shape (..., N).")
    lateral_mean = component_mean(0, "``E[x_k]`` at every frame, shape (..., N).")
    lateral_sd = component_sd(0, "The SD of ``x_k`` at every frame, shape (..., N).")
    velocity_mean = component_mean(2, "``E[v_k]`` at every frame, shape (..., N).")
    velocity_sd = component_sd(2, "The SD of ``v_k`` at every frame, shape (..., N).")


@dataclass(frozen=True)
class Mixture:
    """The optimal posterior at frame ``N`` (:func:`mixture`), batch shape ``(...)``.

    Attributes
    ----------
    bank : Bank
    log_weights : ndarray, shape (..., J)
        Log quadrature weights of the nodes.
    probabilities : ndarray, shape (..., J)
        ``w_j N(y_j; m_y, P_yy) L(y_j)``, normalised.
    log_normaliser : ndarray, shape (...)
        ``log sum_j w_j N(y_j; m_y, P_yy) L(y_j)``.
    mean : ndarray, shape (..., 3)
    cov : ndarray, shape (..., 3, 3)
        Of ``(x_N, y_N, v_N)``.
    depth_error, velocity_error : ndarray, shape (...), or None
        For nodes placed by :func:`~depthcore.exact.posterior.posterior`; ``None``
        for caller-given nodes.
    rtol : float or None
    updates : depthcore.problem.predictive.Updates or None
        A gated run's report, (..., N); ``None`` without a gate (see :meth:`report`).
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
    updates: predictive.Updates | None = None

    depth_mean = component_mean(1, "``E[y_N]``, shape (...).")
    depth_sd = component_sd(1, "The SD of ``y_N``, shape (...).")
    velocity_mean = component_mean(2, "``E[v_N]``, shape (...).")
    velocity_sd = component_sd(2, "The SD of ``v_N``, shape (...).")

    def report(self) -> predictive.Updates:
        """Each frame's predictive report, arrays (..., N): log density, tail, gated.

        :func:`depthcore.exact.online.track_updates`, computed here on request; NaN at a
        missing frame. From a gated run, its ``updates``.
        """
        if self.updates is not None:
            return self.updates
        from depthcore.exact import online  # the online filter is built on this module

        return online.track_updates(self.bank, rtol=self.rtol or 1e-10)

    def _query(self, value, name):
        """Queries as (batch..., K) and a function restoring the caller's shape."""
        value = checks.finite_array(value, name)
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
        y1 = y - _travelled(b)
        inside = y1 > 0
        log_w = b.rerun(np.where(inside, y1, 1.0)).log_weight
        return restore(np.where(inside, log_w - self.log_normaliser[..., None], -np.inf))

    def depth_pdf(self, y) -> np.ndarray:
        """Posterior density of the depth at frame ``N`` (see :meth:`depth_log_pdf`)."""
        return np.exp(self.depth_log_pdf(y))

    def depth_cdf(self, y, rtol: float = 1e-10) -> np.ndarray:
        """``P(y_N <= y)``, integrated from the density.

        0 and 1 beyond the nodes within ``e**-60`` of the largest (beyond a law's edges,
        :attr:`Bank.law <depthcore.exact.bank.Bank.law>`); between,
        :func:`depthcore.exact.cdf.gauss_legendre_cdf` in ``t = log(y_1)``.

        Parameters
        ----------
        y : array_like
            Any shape for one problem; ``(..., K)`` for a batch.
        rtol : float
            Absolute tolerance, > 0, floored at ``64 eps (1 + |t|) / sd_t``.
        """
        rtol = _positive_scalar(rtol, "rtol")
        y, restore = self._query(y, "y")
        b = self.bank
        log_p = b.log_weight + self.log_weights - self.log_normaliser[..., None]
        big = log_p > np.max(log_p, axis=-1, keepdims=True) - _CUTOFF
        nodes = np.broadcast_to(b.nodes, big.shape)
        lo = np.log(np.min(np.where(big, nodes, np.inf), axis=-1))[..., None]
        hi = np.log(np.max(np.where(big, nodes, 0.0), axis=-1))[..., None]
        if b.law is not None:  # a law's edges bound its mass: the nodes lie inside them
            lo, hi = _law_ends(b, lo, hi, big, np.isfinite(self.log_weights))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.log(np.maximum(y - _travelled(b), 0.0))
        top = np.minimum(t, hi)
        width = np.maximum(top - lo, 0.0)
        # Panels of half the SD of log(y_1) under each problem's own mixture.
        log_nodes = np.log(nodes)
        centre = np.sum(self.probabilities * log_nodes, axis=-1, keepdims=True)
        sd_t = np.sqrt(np.sum(self.probabilities * (log_nodes - centre) ** 2, axis=-1))
        panels = int(np.clip(np.ceil(np.max(width / (0.5 * sd_t[..., None] + 1e-3))), 4, 4096))
        # Roundoff: a depth rounded to eps (1 + |t|) in t moves the log density by
        # about that over sd_t, so the CDF cannot settle below 64 eps (1 + |t|) / sd_t.
        eps = np.finfo(float).eps
        floor = 64.0 * eps * (1.0 + np.abs(centre)) / np.maximum(sd_t[..., None], eps)
        tol = np.maximum(rtol, floor)

        def density(tt):
            shape = tt.shape
            y1 = np.exp(tt.reshape(shape[:-3] + (-1,)))
            log_w = b.rerun(y1).log_weight
            dens = np.exp(log_w - self.log_normaliser[..., None] + np.log(y1))  # dy = y dt
            return dens.reshape(shape)

        cdf, settled, panels = gauss_legendre_cdf(
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

        The largest gap between neighbouring nodes' ``E[v_N | y_j]`` in conditional SDs
        (nodes above ``1e-14`` of the largest). A sum of Gaussians ``h`` SDs apart
        ripples by ``2 exp(-2 pi**2 / h**2)``: ``5e-9`` at ``h = 1``, ``0.2`` at ``h = 3``.
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

        Smooth when :attr:`velocity_gap` is below about 1. ``v``: any shape for one
        problem, ``(..., K)`` for a batch.
        """
        v, restore = self._query(v, "v")
        W, m, sd = self._velocity_terms()
        z = (v[..., :, None] - m) / sd
        return restore(np.sum(W * np.exp(-0.5 * z**2) / (np.sqrt(2.0 * np.pi) * sd), axis=-1))

    def velocity_cdf(self, v) -> np.ndarray:
        """``P(v_N <= v)``: the mixture of the nodes' Gaussian CDFs.

        As :meth:`velocity_pdf`.
        """
        v, restore = self._query(v, "v")
        W, m, sd = self._velocity_terms()
        return restore(np.sum(W * ndtr((v[..., :, None] - m) / sd), axis=-1))

    def smoothed(self) -> Smoothed:
        """Textbook 19.2.6: the state at every frame given all bearings.

        Each node's history is smoothed
        (:func:`depthcore.kalman.linear.fixed_interval_smoother`) and mixed.
        """
        b = self.bank
        res = b.history
        if res is None:
            res = b.rerun(b.nodes, history=True).history
        Psi = PSI if b.steps is None else transitions(b.steps)[..., None, :, :, :]
        s = linear.fixed_interval_smoother(res, Psi)  # (..., J, N, 2), (..., J, N, 2, 2)
        frames = b.elapsed
        mean, cov = mixture_moments(
            self.probabilities[..., None, :],
            np.swapaxes(s.mean, -2, -3),
            np.swapaxes(s.cov, -3, -4),
            b.nodes[..., None, :] + frames[..., :, None],
        )
        return Smoothed(mean, cov)


def _law_ends(bank: Bank, lo, hi, big, valid):
    """``log y_1`` at the ends of the depth CDF's range under the bank's law.

    Where the first (last) node that carries weight, of ``big`` (..., J), is the first
    (last) node of all, of ``valid``, the law's edge there, when finite and above the
    floor: the nodes lie inside the panels that end at it. Elsewhere the nodes' ``lo``
    and ``hi``: what lies beyond them is negligible.
    """
    edge_lo, edge_hi = bank.law.support
    J = big.shape[-1]
    first = np.argmax(big, axis=-1) == np.argmax(valid, axis=-1)
    last = np.argmax(big[..., ::-1], axis=-1) == np.argmax(valid[..., ::-1], axis=-1)
    floor = np.asarray(bank.floor)
    use_lo = (first & (edge_lo > floor))[..., None]
    lo = np.where(use_lo, np.log(max(edge_lo, 1e-300)), lo)
    if np.isfinite(edge_hi):
        hi = np.where(last[..., None] & (J > 0), np.log(edge_hi), hi)
    return lo, hi


def _travelled(bank: Bank):
    """``y_N - y_1``: the number ``N - 1`` for unit steps, else shape (..., 1) against the nodes."""
    if bank.steps is None:
        return bank.frames - 1
    return bank.travelled[..., None]


def _positive_scalar(value, name: str) -> float:
    arr = checks.finite_array(value, name)
    if arr.ndim != 0 or not arr > 0:
        raise ValueError(f"{name} must be a positive scalar, got {value!r}")
    return float(arr)


def mixture(bank: Bank, weights) -> Mixture:
    """The optimal posterior at frame ``N`` from the bank and the nodes' quadrature weights.

    Parameters
    ----------
    bank : Bank
    weights : array_like, shape (..., J)
        Quadrature weights (``sum_j w_j g(y_j)`` approximates ``integral g(y) dy``),
        >= 0 (zero pads), at least one positive per problem.

    Returns
    -------
    Mixture
        ``p_j`` proportional to ``w_j N(y_j; m_y, P_yy) L(y_j)``, with
        ``mean = sum_j p_j m_j`` and
        ``cov = sum_j p_j (Cov[(x_N, v_N) | y_j] + (m_j - mean)(m_j - mean)^T)``.
    """
    if not isinstance(bank, Bank):
        raise ValueError(f"bank must be a Bank, got {type(bank).__name__}")
    weights = checks.finite_array(weights, "weights")
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
    return mixture_of_log_weights(bank, log_weights)


def mixture_of_log_weights(bank: Bank, log_weights, halved: bool = False):
    """:func:`mixture` from the checked log quadrature weights (``-inf`` for a zero weight).

    With ``halved``, also the moments on every other node and the ends'
    freedom (:func:`_halving`), from the same pass over the nodes, for
    ``_resolution``: returns the Mixture, the halved mean (..., 3) and
    covariance (..., 3, 3), the largest log probability (..., 1) and ``free`` (...).
    """
    a = bank.log_weight + log_weights
    probabilities, log_normaliser = normalised(a)
    depth_N = bank.nodes + _travelled(bank)
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


#: An end node of a placed grid may carry at most this log probability below the largest
#: before :func:`~depthcore.exact.posterior.update` re-places the nodes (the quadrature cuts its
#: range at 60).
_END_MARGIN = 40.0


def _halving(log_p, top):
    """Every other node of the placed grid, and whether its ends are free.

    ``log_p`` (..., J) (``-inf`` at padding), ``top`` (..., 1) its largest. Returns
    ``every_other`` (..., J) and ``free`` (...): both end nodes :data:`_END_MARGIN` below.
    """
    valid = np.isfinite(log_p)
    J = log_p.shape[-1]
    first = np.argmax(valid, axis=-1)
    last = J - 1 - np.argmax(valid[..., ::-1], axis=-1)
    end = np.max(np.take_along_axis(log_p, np.stack([first, last], -1), -1), axis=-1)
    every_other = (np.arange(J) % 2 == (first % 2)[..., None]) & valid
    return every_other, end < top[..., 0] - _END_MARGIN
