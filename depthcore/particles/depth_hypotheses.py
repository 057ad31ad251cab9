"""MonoSLAM's depth initialisation: a fixed grid of depth hypotheses, collapsed to a Gaussian.

Recommended import: ``from depthcore.particles import depth_hypotheses``.

MonoSLAM [davison2007]_ (its section "Feature Initialization") starts a new
feature's depth along its ray as 100 particles spread uniformly over 0.5 to
5 m, reweights them by the likelihood of each later image measurement, and,
once the ratio of the depth's standard deviation to its mean falls below 0.3,
replaces them by a Gaussian, from which the feature is filtered by the EKF like
any other. On the N-frame problem of :mod:`depthcore.exact.bank` the scheme reads:

* **Hypotheses** (:func:`grid`). ``J`` depths at frame 1, the midpoints
  ``y_j`` of ``J`` cells that tile ``[m_y / sqrt(r), m_y sqrt(r)]`` about the
  prior's depth mean ``m_y``, ``r`` the span (10: MonoSLAM's 0.5 to 5 m),
  equal in depth (``"depth"``, MonoSLAM's spacing) or in inverse depth
  (``"inverse"``). Hypothesis ``j`` starts with the weight
  ``N(y_j; m_y, P_yy) h_j``, the prior's depth density times the width ``h_j``
  of its cell in depth: a Riemann sum of the prior over the range.
* **Reweighting.** Given the depth the lateral state ``(x_k, v_k)`` is
  linear-Gaussian (textbook 19.2, Eqs. (19.5), (19.7) [prince2012]_), so each
  hypothesis carries its Kalman filter of ``(x_k, v_k)`` from the prior given
  ``y_1 = y_j`` (:func:`depthcore.exact.bank.conditional_prior`,
  :func:`depthcore.exact.bank.filter_bank`, :func:`depthcore.exact.bank.step`), and
  its weight gains the log density of each bearing under that filter,
  ``log p(mu_k | mu_1 .. mu_{k-1}, y_j)``: MonoSLAM's reweighting by the
  measurement's likelihood, with the lateral state Rao-Blackwellised. After
  frame ``k`` the hypotheses are the mixture over depth of the bank's module
  docstring with probabilities ``p_j`` proportional to
  ``h_j N(y_j; m_y, P_yy) p(mu_1 .. mu_k | y_j)``
  (:func:`depthcore.exact.mixture.mixture_of_log_weights`), whose moments of
  ``(x_k, y_k, v_k)`` are the law of total variance's.
* **Collapse.** After each frame (a missing bearing's frame too) the depth's
  ratio ``sd(y_k) / E[y_k]`` under the mixture is compared with the collapse
  ratio ``c`` (0.3); at the first frame ``k`` where it falls below ``c`` the
  mixture is replaced by its moment-matched Gaussian of ``(x_k, y_k, v_k)``, and
  the remaining bearings are filtered by the EKF (:mod:`depthcore.kalman.ekf`,
  Eqs. (10)-(12)) from that Gaussian predicted to frame ``k + 1`` by Eq. (10):
  the recursion of :func:`depthcore.kalman.ekf.run` with that prediction as its
  prior. ``c = 0``: the hypotheses run to frame ``N``.

The hypotheses are the exact filter's bank on other nodes with other weights:
on the exact filter's own nodes and quadrature weights (:func:`filter_nodes`)
and without a collapse they are the exact filter, and on the grid they tend to
it as ``J`` grows wherever its posterior lies inside the range. A frame costs
``O(J)`` per problem; the memory is ``O(J)`` per problem and the bearings kept
by the bank (:attr:`depthcore.exact.bank.Bank.mu`).

References
----------
.. [davison2007] A. J. Davison, I. D. Reid, N. D. Molton and O. Stasse,
   "MonoSLAM: real-time single camera SLAM", IEEE Trans. Pattern Analysis and
   Machine Intelligence 29(6), pp. 1052-1067, 2007.
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.2 (the Kalman filter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

from depthcore.exact import bank as bk
from depthcore.exact.mixture import mixture_of_log_weights
from depthcore.kalman import ekf
from depthcore.problem import checks, signature
from depthcore.problem.gaussian import checked_track, symmetric

#: The hypotheses' spacings, equal cells in depth (MonoSLAM's) or in inverse depth.
SPACINGS = ("depth", "inverse")

#: MonoSLAM's number of depth hypotheses.
N_HYPOTHESES = 100

#: Most hypotheses per problem (the memory grows with them).
MAX_HYPOTHESES = 100_000

#: The ratio of the range's ends, MonoSLAM's 5 m over 0.5 m.
SPAN = 10.0

#: MonoSLAM's collapse ratio, the depth's SD over its mean below which the hypotheses
#: become a Gaussian.
COLLAPSE_RATIO = 0.3


@dataclass(frozen=True)
class Hypotheses:
    """The filter's result after ``N`` frames: batch shape ``(...)``, ``J`` hypotheses.

    Attributes
    ----------
    mean : ndarray, shape (..., 3)
    cov : ndarray, shape (..., 3, 3)
        Of ``(x_N, y_N, v_N)``: the hypotheses' mixture's moments, or the EKF's
        Gaussian after a collapse.
    collapsed_at : ndarray of int, shape (...)
        The frame ``k`` (1 to ``N``) after which the hypotheses collapsed; 0 where
        they never did.
    ratio : ndarray, shape (..., N)
        The depth's SD over its mean under the hypotheses after each frame;
        NaN after a collapse.
    collapsed_mean : ndarray, shape (..., 3)
    collapsed_cov : ndarray, shape (..., 3, 3)
        The moment-matched Gaussian of ``(x_k, y_k, v_k)`` at the collapse, from
        which the EKF goes on; NaN where the hypotheses never collapsed.
    nodes : ndarray, shape (..., J)
        The hypotheses' depths at frame 1.
    log_widths : ndarray, shape (..., J)
        Their log cell widths (quadrature weights).
    probabilities : ndarray, shape (..., J)
    depths : ndarray, shape (..., J)
    lateral_mean : ndarray, shape (..., J, 2)
    lateral_cov : ndarray, shape (..., J, 2, 2)
        The hypotheses at frame ``N``, or at the collapse: their probabilities,
        depths ``y_k`` and Kalman filters of ``(x_k, v_k)``.
    """

    mean: np.ndarray
    cov: np.ndarray
    collapsed_at: np.ndarray
    ratio: np.ndarray
    collapsed_mean: np.ndarray
    collapsed_cov: np.ndarray
    nodes: np.ndarray
    log_widths: np.ndarray
    probabilities: np.ndarray
    depths: np.ndarray
    lateral_mean: np.ndarray
    lateral_cov: np.ndarray

    @property
    def collapsed(self) -> np.ndarray:
        """Whether the hypotheses collapsed to a Gaussian, shape (...)."""
        return self.collapsed_at > 0

    @property
    def n_hypotheses(self) -> int:
        """``J``."""
        return self.nodes.shape[-1]

    def pooled(self):
        """The law at frame ``N`` as weighted depths, each with a Gaussian of ``(x_N, v_N)``.

        The hypotheses where they never collapsed. Where they did, the EKF's
        Gaussian ``N(m, P)`` written on ``J`` depths ``m_y + sqrt(P_yy) z_j``, equally
        weighted, ``z_j`` the standard normal quantiles at ``(j - 1/2) / J`` scaled to
        a mean square of one, each with the Gaussian of ``(x_N, v_N)`` given its depth
        (:func:`depthcore.exact.bank.conditional_prior`): by the law of total
        variance the mixture's mean and covariance are ``m`` and ``P``.

        Returns
        -------
        W : ndarray, shape (..., J)
            Summing to one.
        depths : ndarray, shape (..., J)
        means : ndarray, shape (..., J, 2)
        covs : ndarray, shape (..., J, 2, 2)
        """
        collapsed = self.collapsed
        if not np.any(collapsed):
            return self.probabilities, self.depths, self.lateral_mean, self.lateral_cov
        J = self.n_hypotheses
        z = ndtri((np.arange(J) + 0.5) / J)
        z = z / np.sqrt(np.mean(z * z))
        y = self.mean[..., 1, None] + np.sqrt(self.cov[..., 1, 1])[..., None] * z
        given, _ = bk.conditional_prior(y, self.mean, self.cov)
        c = collapsed[..., None]
        return (
            np.where(c, 1.0 / J, self.probabilities),
            np.where(c, y, self.depths),
            np.where(c[..., None], given.mean, self.lateral_mean),
            np.where(c[..., None, None], given.cov, self.lateral_cov),
        )

    def _aligned(self, value):
        """``value`` and :meth:`pooled`'s weights, depths and velocity means and SDs, aligned
        for queries of shape (...) or (..., G)."""
        value = np.asarray(value, dtype=float)
        W, depths, means, covs = self.pooled()
        m, s = means[..., 1], np.sqrt(covs[..., 1, 1])
        if value.ndim > W.ndim - 1:
            W, depths, m, s = (
                W[..., None, :],
                depths[..., None, :],
                m[..., None, :],
                s[..., None, :],
            )
        return value[..., None], W, depths, m, s

    def _collapsed_gaussian(self, value, k: int):
        """Where the hypotheses collapsed, the Gaussian's marginal of component ``k`` at
        ``value`` (...) or (..., G): the mask, the standardised value and the SD, aligned."""
        value = np.asarray(value, dtype=float)
        c, m, s = self.collapsed, self.mean[..., k], np.sqrt(self.cov[..., k, k])
        if value.ndim > c.ndim:
            c, m, s = c[..., None], m[..., None], s[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(c, (value - m) / np.where(c, s, 1.0), 0.0)
        return c, z, np.where(c, s, 1.0)

    def depth_cdf(self, y) -> np.ndarray:
        """``P(y_N <= y)``, ``y`` (...) or (..., G): the weighted hypotheses' step function,
        or, where they collapsed, the Gaussian's CDF (the answer the EKF carried on)."""
        c, z, _ = self._collapsed_gaussian(y, 1)
        y, W, depths, _, _ = self._aligned(y)
        return np.where(c, ndtr(z), np.sum(W * (depths <= y), axis=-1))

    def velocity_cdf(self, v) -> np.ndarray:
        """``P(v_N <= v)``, ``v`` (...) or (..., G): the hypotheses' mixture of Gaussians, or,
        where they collapsed, the Gaussian's CDF."""
        c, z, _ = self._collapsed_gaussian(v, 2)
        v, W, _, m, s = self._aligned(v)
        return np.where(c, ndtr(z), np.sum(W * ndtr((v - m) / s), axis=-1))

    def velocity_pdf(self, v) -> np.ndarray:
        """The density of ``v_N``; shapes and laws as :meth:`velocity_cdf`."""
        c, zc, sc = self._collapsed_gaussian(v, 2)
        v, W, _, m, s = self._aligned(v)
        z = (v - m) / s
        mixed = np.sum(W * np.exp(-0.5 * z * z) / (np.sqrt(2.0 * np.pi) * s), axis=-1)
        return np.where(c, np.exp(-0.5 * zc * zc) / (np.sqrt(2.0 * np.pi) * sc), mixed)


# --- the options -----------------------------------------------------------------------


def _n_hypotheses(value) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, np.integer))
        or not 2 <= value <= MAX_HYPOTHESES
    ):
        raise ValueError(
            f"n_hypotheses must be an integer from 2 to {MAX_HYPOTHESES}, got {value!r}"
        )
    return int(value)


def _spacing(value) -> str:
    if not isinstance(value, str) or value not in SPACINGS:
        raise ValueError(f"spacing must be one of {SPACINGS}, got {value!r}")
    return value


def _span(value) -> float:
    span = checks.number(value, "span")
    if not 1.0 < span < np.inf:
        raise ValueError(
            f"span must be a finite number > 1 (the ratio of the range's ends), got {value!r}"
        )
    return span


def _collapse_ratio(value) -> float:
    ratio = checks.number(value, "collapse_ratio")
    if not 0.0 <= ratio < np.inf:
        raise ValueError(f"collapse_ratio must be a finite number >= 0 (0: never), got {value!r}")
    return ratio


# --- the hypotheses --------------------------------------------------------------------


def grid(prior_mean, n_hypotheses: int = N_HYPOTHESES, spacing="depth", span=SPAN):
    """The depth hypotheses at frame 1 about the prior's depth mean, and their log weights.

    ``J`` cells tile ``[m_y / sqrt(r), m_y sqrt(r)]`` (``r`` the span), equal in
    depth or in inverse depth; hypothesis ``j`` is its cell's midpoint (in depth,
    or in inverse depth) and its log weight the log of the cell's width in
    depth, ``h_j``, so that ``sum_j h_j g(y_j)`` is a Riemann sum of ``integral
    g(y) dy`` over the range (module docstring; MonoSLAM's 0.5 to 5 m is
    ``m_y = 5 / sqrt(10)``, ``r = 10``).

    Parameters
    ----------
    prior_mean : array_like, shape (3,) or (..., 3)
        The prior's mean of ``(x_1, y_1, v_1)``; its depth ``m_y`` must be positive.
    n_hypotheses : int
        ``J``, 2 to :data:`MAX_HYPOTHESES`.
    spacing : {"depth", "inverse"}
    span : float
        The ratio of the range's ends, > 1.

    Returns
    -------
    nodes : ndarray, shape (..., J)
        Increasing depths at frame 1.
    log_widths : ndarray, shape (..., J)
    """
    J = _n_hypotheses(n_hypotheses)
    spacing = _spacing(spacing)
    span = _span(span)
    prior_mean = checks.finite_array(prior_mean, "prior_mean")
    if prior_mean.ndim < 1 or prior_mean.shape[-1] != 3:
        raise ValueError(f"prior_mean must have shape (..., 3), got shape {prior_mean.shape}")
    m_y = prior_mean[..., 1, None]
    if not np.all(m_y > 0):
        raise ValueError(
            "prior_mean's depth m_y must be positive to place the depth hypotheses about it, "
            f"got {float(np.min(m_y)):.6g}"
        )
    lo, hi = m_y / np.sqrt(span), m_y * np.sqrt(span)
    edges = np.arange(J + 1) / J
    middle = (np.arange(J) + 0.5) / J
    if spacing == "depth":
        cuts, nodes = lo + (hi - lo) * edges, lo + (hi - lo) * middle
    else:  # equal cells in 1 / y, from 1 / lo down to 1 / hi
        w_lo, w_hi = 1.0 / lo, 1.0 / hi
        cuts = 1.0 / (w_lo + (w_hi - w_lo) * edges)
        nodes = 1.0 / (w_lo + (w_hi - w_lo) * middle)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        log_widths = np.log(np.diff(cuts, axis=-1))
    if not (np.all(np.isfinite(nodes) & (nodes > 0)) and np.all(np.isfinite(log_widths))):
        raise ValueError(
            f"span {span:g} about prior_mean's depth {float(np.max(m_y)):.6g} gives depths "
            "beyond double precision; give a smaller span or a depth nearer 1"
        )
    return nodes, log_widths


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    n_hypotheses: int = N_HYPOTHESES,
    spacing="depth",
    span=SPAN,
    collapse_ratio=COLLAPSE_RATIO,
    steps=None,
) -> Hypotheses:
    """MonoSLAM's depth hypotheses over the bearings ``mu_1 .. mu_N``, batched: the door.

    The hypotheses of :func:`grid` about the prior's depth mean, filtered by
    :func:`filter_nodes` (module docstring).

    {parameters}
    n_hypotheses : int
        ``J``, 2 to :data:`MAX_HYPOTHESES` (MonoSLAM's 100).
    spacing : {"depth", "inverse"}
        Equal cells in depth (MonoSLAM's) or in inverse depth.
    span : float
        The ratio of the range's ends, > 1 (MonoSLAM's 5 m / 0.5 m = 10).
    collapse_ratio : float
        The depth's SD over its mean below which the hypotheses become a
        Gaussian, >= 0 (MonoSLAM's 0.3; 0: never).

    Returns
    -------
    Hypotheses
        Batch shape ``()`` for ``mu`` of shape ``(N,)``.
    """
    ratio = _collapse_ratio(collapse_ratio)
    q = checks.process_noise(process_noise, "process_noise")
    track = checked_track(mu, rho, prior_mean, prior_cov, steps)
    nodes, log_widths = grid(track.mean, n_hypotheses, spacing, span)
    return _filtered(nodes, log_widths, track, q, ratio)


def filter_nodes(
    nodes,
    log_widths,
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    collapse_ratio=COLLAPSE_RATIO,
    steps=None,
) -> Hypotheses:
    """The depth hypotheses on given depths at frame 1 and log weights, and their collapse.

    The filter of the module docstring with hypotheses ``nodes`` whose weights
    are ``log_widths`` plus the prior's log depth density: on the exact filter's
    own nodes and log quadrature weights (``log_weights`` of its
    :class:`~depthcore.exact.mixture.Mixture`) and with
    ``collapse_ratio = 0`` it is the exact filter.

    Parameters
    ----------
    nodes : array_like, shape (J,) or (..., J)
        Depths at frame 1, > 0.
    log_widths : array_like, shape (J,) or (..., J)
        Finite, or ``-inf`` for a hypothesis without weight; each problem needs a
        finite one.
    mu, rho, prior_mean, prior_cov, process_noise, collapse_ratio, steps
        As for :func:`run`.

    Returns
    -------
    Hypotheses
    """
    ratio = _collapse_ratio(collapse_ratio)
    q = checks.process_noise(process_noise, "process_noise")
    track = checked_track(mu, rho, prior_mean, prior_cov, steps)
    batch = track.frames.mu.shape[:-1]
    nodes = checks.finite_array(nodes, "nodes")
    if nodes.ndim < 1 or nodes.shape[-1] < 1 or not checks.broadcasts(nodes.shape[:-1], batch):
        raise ValueError(f"nodes must have shape (J,) or {batch + ('J',)}, got {nodes.shape}")
    if not np.all(nodes > 0):
        raise ValueError(f"nodes must be positive depths, got minimum {float(np.min(nodes)):.6g}")
    shape = batch + nodes.shape[-1:]
    log_widths = checks.as_float(log_widths, "log_widths")
    if not checks.broadcasts(log_widths.shape, shape):
        raise ValueError(f"log_widths must broadcast to the shape {shape}, got {log_widths.shape}")
    if np.any(np.isnan(log_widths) | (log_widths == np.inf)):
        raise ValueError("log_widths must be finite or -inf (no weight), got NaN or +inf")
    if not np.all(np.any(np.isfinite(np.broadcast_to(log_widths, shape)), axis=-1)):
        raise ValueError("log_widths must give every problem a hypothesis with weight")
    nodes = np.broadcast_to(nodes, shape)
    return _filtered(nodes, np.broadcast_to(log_widths, shape), track, q, ratio)


# --- the filter ------------------------------------------------------------------------


def _filtered(nodes, log_widths, track, q: float, ratio: float) -> Hypotheses:
    """:func:`filter_nodes` on checked inputs, its batch flattened to ``B`` rows and restored."""
    f = track.frames
    batch, N = f.mu.shape[:-1], f.mu.shape[-1]
    B, J = int(np.prod(batch)), nodes.shape[-1]

    def flat(a, core):
        return np.ascontiguousarray(np.broadcast_to(a, batch + core)).reshape((B,) + core)

    out = _run_rows(
        flat(nodes, (J,)),
        flat(log_widths, (J,)),
        flat(f.mu, (N,)),
        flat(np.where(f.present, f.rho, 1.0), (N,)),
        flat(f.steps, (N - 1,)),
        flat(track.mean, (3,)),
        flat(track.cov, (3, 3)),
        q,
        ratio,
        f.regular,
        batch,
    )
    return Hypotheses(**{k: v.reshape(batch + v.shape[1:]) for k, v in out.items()})


#: The fields of a bank whose first axis is the problem's (all, for the banks built here).
_BANK_ROWS = tuple(f for f in bk.Bank._fields if f not in ("history", "law"))


def _keep(bank: bk.Bank, rows) -> bk.Bank:
    """The bank's problems ``rows`` (a boolean mask of its first axis)."""
    return bank._replace(**{name: getattr(bank, name)[rows] for name in _BANK_ROWS})


def _run_rows(nodes, log_widths, mu, rho, steps, mean0, cov0, q, ratio, regular, batch) -> dict:
    """The filter on ``B`` rows: nodes (B, J), bearings and noise (B, N), steps (B, N - 1).

    Returns :class:`Hypotheses`' fields, each with a first axis of ``B``; ``batch`` is the
    caller's batch shape, for the refusals.
    """
    B, J = nodes.shape
    N = mu.shape[1]
    out = {
        "mean": np.empty((B, 3)),
        "cov": np.empty((B, 3, 3)),
        "collapsed_at": np.zeros(B, dtype=int),
        "ratio": np.full((B, N), np.nan),
        "collapsed_mean": np.full((B, 3), np.nan),
        "collapsed_cov": np.full((B, 3, 3), np.nan),
        "nodes": nodes,
        "log_widths": log_widths,
        "probabilities": np.empty((B, J)),
        "depths": np.empty((B, J)),
        "lateral_mean": np.empty((B, J, 2)),
        "lateral_cov": np.empty((B, J, 2, 2)),
    }
    gauss = _Handover(B, q, regular, batch)
    live = np.arange(B)  # the rows whose hypotheses still run
    log_w = log_widths
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        bank = bk.filter_bank(nodes, mu[:, :1], rho[:, 0], mean0, cov0, np.full(B, q))
    for k in range(N):
        if k:
            gauss.frame(k, mu, rho, steps)
            if live.size:
                bank = _step(bank, mu[live, k], rho[live, k], steps[live, k - 1], regular)
        if not live.size:
            continue
        _check_weights(bank.log_weight + log_w, live, k, bank, batch)
        post = mixture_of_log_weights(bank, log_w)
        r = post.depth_sd / post.depth_mean
        out["ratio"][live, k] = r
        done = r < ratio
        last = k == N - 1
        if not (np.any(done) or last):
            continue
        ending = np.ones_like(done) if last else done
        rows = live[ending]
        out["mean"][rows], out["cov"][rows] = post.mean[ending], post.cov[ending]
        out["probabilities"][rows] = post.probabilities[ending]
        travelled = np.asarray(bank.travelled)  # y_k - y_1: one number, or one per row
        depths = bank.nodes + (travelled[:, None] if travelled.ndim else travelled)
        out["depths"][rows] = depths[ending]
        out["lateral_mean"][rows], out["lateral_cov"][rows] = bank.mean[ending], bank.cov[ending]
        gone = live[done]
        out["collapsed_at"][gone] = k + 1
        out["collapsed_mean"][gone], out["collapsed_cov"][gone] = post.mean[done], post.cov[done]
        if not last:
            gauss.start(gone, post.mean[done], post.cov[done], k)
            bank, log_w, live = _keep(bank, ~done), log_w[~done], live[~done]
    mean, cov = gauss.result()
    out["mean"][gauss.rows], out["cov"][gauss.rows] = mean, cov
    if not (np.all(np.isfinite(out["mean"])) and np.all(np.isfinite(out["cov"]))):
        raise ValueError(
            "rho and prior_cov lead the depth hypotheses' filters to overflow; "
            "try a larger rho or a prior nearer the bearings"
        )
    return out


def _step(bank: bk.Bank, mu_k, rho_k, step_k, regular: bool) -> bk.Bank:
    """:func:`depthcore.exact.bank.step` by one frame: the paper's frames, or as they come."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        if regular:
            return bk.step(bank, mu_k)
        return bk.step(bank, mu_k, rho=rho_k, step=step_k, gaps=True)


def _where(i: int, batch: tuple) -> str:
    """The position of flat row ``i`` in the batch, or nothing for one problem."""
    return checks.batch_index(i, batch) if batch else ""


def _check_weights(log_p, live, k: int, bank: bk.Bank, batch: tuple) -> None:
    """Refuse, in one line, a problem whose hypotheses all lost their weight after frame ``k``.

    ``log_p`` (B, J): the hypotheses' log weights, ``-inf`` where the point reached the camera.
    """
    bad = ~np.any(np.isfinite(log_p), axis=-1)
    if np.any(bad):
        i = int(np.argmax(bad))
        where = _where(int(live[i]), batch)
        lo, hi = float(np.min(bank.nodes[i])), float(np.max(bank.nodes[i]))
        raise ValueError(
            f"mu{where}: every depth hypothesis has weight zero after frame {k + 1} (the "
            f"bearings, steps and prior rule out the depths {lo:.3g} to {hi:.3g} at frame 1); "
            "give a wider span or more hypotheses"
        )


class _Handover:
    """The EKF's rows: each takes over from the hypotheses' Gaussian after its collapse.

    A row that collapsed at frame ``k`` is predicted to frame ``k + 1`` by Eq. (10)
    in covariance form (:func:`depthcore.kalman.ekf.predict`), then carried as
    :func:`depthcore.kalman.ekf.run` carries its prior: the root ``R`` of the
    information, ``R^T R = P^{-1}``, updated by Eq. (12)
    (:func:`depthcore.kalman.ekf.information_update`) and predicted by Eq. (10)
    (:func:`depthcore.kalman.ekf.information_predict`).
    """

    def __init__(self, B: int, q: float, regular: bool, batch: tuple):
        self.q, self.regular, self.batch = q, regular, batch
        self.mean = np.zeros((B, 3))
        self.cov = np.zeros((B, 3, 3))
        self.root = np.zeros((B, 3, 3))
        self.fresh = np.zeros(B, dtype=bool)  # collapsed at the frame before: covariance form
        self.rows = np.zeros(0, dtype=int)
        self.since = np.zeros(B, dtype=int)

    def start(self, rows, mean, cov, k: int) -> None:
        """Rows ``rows`` collapsed after frame ``k + 1`` to ``N(mean, cov)``."""
        self.mean[rows], self.cov[rows] = mean, cov
        self.fresh[rows] = True
        self.since[rows] = k + 1
        self.rows = np.sort(np.concatenate([self.rows, rows]))

    def frame(self, k: int, mu, rho, steps) -> None:
        """Predict the rows to frame ``k + 1`` (0-based ``k``) and update them by ``mu_{k+1}``."""
        rows = self.rows
        if not rows.size:
            return
        s = 1.0 if self.regular else steps[rows, k - 1]
        fresh = self.fresh[rows]
        n = np.empty((rows.size, 3))
        R = np.empty((rows.size, 3, 3))
        if np.any(fresh):
            new = rows[fresh]
            pred = ekf.predict(self.mean[new], self.cov[new], self.q, _part(s, fresh))
            try:
                R[fresh] = np.linalg.inv(np.linalg.cholesky(pred.cov))
            except np.linalg.LinAlgError:
                raise ValueError(self._singular(new, pred.cov)) from None
            n[fresh] = pred.mean
            self.fresh[new] = False
        if not np.all(fresh):
            old = rows[~fresh]
            n[~fresh], R[~fresh] = ekf.information_predict(
                self.mean[old], self.root[old], self.q, _part(s, ~fresh)
            )
        if not np.all(n[:, 1] > 0):
            i = int(rows[np.argmin(n[:, 1])])
            raise ValueError(
                f"mu{_where(i, self.batch)}: after the depth hypotheses "
                f"collapsed at frame {self.since[i]}, the EKF predicts a depth <= 0 at frame "
                f"{k + 1}, where the bearing x / y has no linearisation; the bearings (or "
                "steps) leave the Gaussian no depth in front of the camera"
            )
        st = ekf.information_update(n, R, mu[rows, k], rho[rows, k], ~np.isnan(mu[rows, k]))
        self.mean[rows], self.root[rows] = st.mean, st.root

    def _singular(self, rows, cov) -> str:
        sd = float(np.min(np.sqrt(np.maximum(cov[:, 1, 1], 0.0))))
        return (
            f"n_hypotheses: the hypotheses collapsed at frame {int(self.since[rows[0]])} onto "
            f"depths too few for a Gaussian with a positive definite covariance (depth SD "
            f"{sd:.3g}): rho and prior_cov pin the depth within the hypotheses' spacing; give "
            "more hypotheses or a smaller span"
        )

    def result(self):
        """The means (R, 3) and covariances (R, 3, 3) at frame ``N`` of the rows started.

        Every row started before the last frame, so the EKF updated it at least once.
        """
        rows = self.rows
        if not rows.size:
            return np.zeros((0, 3)), np.zeros((0, 3, 3))
        R_inv = np.linalg.inv(self.root[rows])
        return self.mean[rows], symmetric(R_inv @ np.swapaxes(R_inv, -1, -2))


def _part(s, mask):
    """A step per row (an array) restricted to ``mask``, or the scalar step."""
    return s[mask] if np.ndim(s) else s
