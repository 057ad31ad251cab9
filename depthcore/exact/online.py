"""The exact filter one bearing at a time, in constant time and memory per frame.

Recommended import: ``from depthcore.exact import online``.

:class:`Online` holds the bank of Kalman filters over depth
(:mod:`depthcore.exact.bank`) on a bounded set of depth nodes, and nothing of
the past bearings: per node ``y_j`` (the depth at frame 1) its quadrature
weight, its log density ``log N(y_j; m_y, P_yy) + log p(mu_1 .. mu_k | y_j)``
and the Gaussian of the lateral state ``(x_k, v_k)`` given ``y_j`` (the
motion of :mod:`depthcore.problem.frames`: ``x <- x + s v``,
``v <- v + a``, ``a ~ N(0, q**2 s)``; the bearing ``mu_k = x_k / y_k + w_k``,
``y_k = y_j + e_k`` with ``e_k`` the depth travelled). Each
:meth:`Online.update` predicts every node's filter by the step (textbook
19.2.1), reports the bearing's predictive density under the mixture of the
nodes (:func:`depthcore.problem.predictive.mixture`: node ``j`` predicts
``N(x_j / y_k, a_j / y_k**2 + rho_k**2)``, ``a_j`` the predicted ``Var[x_k]``,
weighted by the node's probability; a pair of a point in 3-D: the mixture of
bivariate Gaussians of :meth:`depthcore.exact.online_nodes.Space.predictive`, its
tail by :func:`depthcore.problem.pair_tail.tail`, computed only for a gate: ``NaN``
without one), skips it if a gate says so, and
updates each node (textbook 19.2.2).

The nodes. They are placed on the prior by the depth quadrature
(:func:`depthcore.exact.quadrature.integrate`, trapezoid nodes in
``t = log (y_1 - f)`` about the density's mode and width, the step halved until the
moments agree to ``rtol``), ``f`` the floor: the depth at frame 1 below which the
point would have reached the camera by now (0 while it recedes,
:func:`depthcore.problem.frames.depth_floor`). A step towards the point (negative)
that brings it nearer than ever raises the floor: the nodes it brings to the camera
are dropped, and if they held more than a negligible part of the probability the
nodes are first re-placed above the new floor (from the density before the frame,
smooth there), so that the kink the new bearing puts at the floor lies at the end of
the log transform. As bearings accumulate, the posterior narrows; after
each update the nodes are checked as :func:`depthcore.exact.posterior.update`
checks them (the moments on every other node agree with those on all to
``rtol`` of the SD, the end nodes carry negligible probability, no node holds
half of it). Nodes that fail are re-placed by the same quadrature, whose
integrand at a new depth is interpolated from the current nodes: a degree-7
spline in ``t`` of each node's log density and lateral Gaussian (the log
density extended below its end values beyond the nodes). Since the check
fails when the coarser grid of every other node stops resolving the density,
the current nodes still resolve it to far better than ``rtol`` then, and the
spline's error (order ``h**8`` in the node spacing ``h``) is what the
re-placement adds; ``Online.replacements`` counts them. Between
re-placements the filter is the bank on fixed nodes, exact to the
quadrature's error. The node count is bounded by the quadrature's budget
(:data:`depthcore.exact.quadrature.NODE_BUDGET`), so time and memory per frame
are bounded whatever the number of frames. Under a prior with any law of the depth
(``law``) the nodes are Gauss-Legendre panels instead (:mod:`depthcore.exact.panels`),
placed afresh every frame from each half panel's polynomial through its nodes.

Example
-------
A live loop: one bearing per frame as the camera delivers it, a gate at 1e-3
(``NaN`` for a frame without a detection)::

    from depthcore.exact import online

    f = online.Online(prior_mean, prior_cov, rho=0.01, gate=1e-3)
    for mu_k, step_k in camera:            # step_k: the depth moved since the last frame
        est = f.update(mu_k, step=step_k)  # step is ignored at the first frame
        if est.gated:
            print(f"frame {est.frame}: bearing skipped (tail {est.tail:.2g})")
        print(est.depth_mean, est.depth_sd)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.interpolate import make_interp_spline

from depthcore.exact import panels, quadrature
from depthcore.exact.online_nodes import Plane, Space
from depthcore.problem import checks, predictive
from depthcore.problem.depth_prior import stand_in
from depthcore.problem.predictive import FrameEstimate
from depthcore.problem.weights import normalised

#: A node holding this much of the probability or more does not resolve the posterior.
_ONE_NODE = 0.5
#: The end nodes must carry log probabilities this far below the largest.
_END_MARGIN = 40.0
#: The spline's degree in ``t = log y_1`` for a re-placement.
_DEGREE = 7
#: Nodes nearer the floor than this fraction of the depth are dropped (:meth:`Online._place`).
_NEAREST = 1e-12


class _Nodes(NamedTuple):
    """The bank on its nodes: depths at frame 1, log quadrature weights, log densities, lateral."""

    y: np.ndarray  # (J,)
    log_w: np.ndarray  # (J,)
    log_p: np.ndarray  # (J,)
    lateral: np.ndarray  # (K, J): the rows of depthcore.exact.online_nodes' Plane or Space


class Predicted(NamedTuple):
    """The next observation's exact predictive moments (:meth:`Online.predictive_moments`)."""

    mean: np.ndarray  # (d,)
    cov: np.ndarray  # (d, d)
    cross: np.ndarray  # (D, d): Cov[state, observation]


class Online:
    """The exact filter over depth nodes, one bearing at a time (see the module docstring).

    Parameters
    ----------
    prior_mean, prior_cov, process_noise, gate
        As for :class:`depthcore.kalman.online.EKF`: a prior on ``(x, y, v)`` (the
        paper's point, one bearing per update) or on ``(x, y, v, h, w)`` (a point in
        3-D, :mod:`depthcore.exact.spatial`: a pair ``(x / y, h / y)`` per update,
        its tail the probability of a pair of lower predictive density,
        :func:`depthcore.problem.pair_tail.tail`, reported only with a gate).
    rho : float
        The bearing noise SD, > 0, used where :meth:`update` is given none.
    rtol : float
        The quadrature's tolerance for the nodes (mean and SD relative to the SD).
    law : depthcore.problem.depth_prior.DepthPrior, optional
        For the paper's point, a prior with any law of the depth in place of the Gaussian
        (``prior_mean`` and ``prior_cov`` then ``None`` or its own moments): the nodes
        are Gauss-Legendre panels ending at its edges and kinks
        (:func:`depthcore.exact.panels.place`), placed afresh at every frame from the
        interpolated log likelihood and lateral Gaussian plus the law's exact density, so
        a hard edge needs no margin.
    """

    def __init__(
        self, prior_mean, prior_cov, rho, process_noise=0.0, gate=None, rtol=1e-10, law=None
    ):
        if law is not None:
            prior_mean, prior_cov = stand_in(law, prior_mean, prior_cov)
        self.law = law
        m = checks.finite_array(prior_mean, "prior_mean")
        if m.shape not in ((3,), (5,)):
            raise ValueError(
                f"prior_mean must have shape (3,) or (5,) (a point in 3-D), got shape {m.shape}"
            )
        P = checks.finite_array(prior_cov, "prior_cov")
        if P.shape != m.shape * 2:
            raise ValueError(f"prior_cov must have shape {m.shape * 2}, got shape {P.shape}")
        P = checks.covariances(P, "prior_cov", m.size)
        self.prior_mean, self.prior_cov = m, P
        self.rho = checks.positive_scalar(rho, "rho")
        self.process_noise = checks.nonnegative_scalar(process_noise, "process_noise")
        self.gate = predictive.gate(gate)
        if law is not None and m.size != 3:
            raise ValueError("law: a point in 3-D takes a Gaussian prior (prior_mean (5,))")
        self.model = Plane(m, P, self.rho, law) if m.size == 3 else Space(m, P, self.rho)
        self.rtol = checks.positive_scalar(rtol, "rtol")
        self.frame = 0
        self.travelled = 0.0
        self.floor = 0.0
        self._node_floor = 0.0  # the floor the nodes were placed above
        self.replacements = 0
        self.current: FrameEstimate | None = None
        self._nodes = self._place(self.model.prior, m[1])

    @property
    def node_count(self) -> int:
        """The number of depth nodes now (at most the quadrature's node budget)."""
        return int(self._nodes.y.size)

    # --- placement ---------------------------------------------------------------------

    def _place(self, source, depth_guess) -> _Nodes:
        """Nodes by the depth quadrature for the node values ``source(y_1)`` (log density
        (J,) and rows (K, J)), placed by the ``(x, v)`` block's moments.

        The quadrature's depth is the distance above the floor, ``y_1 - floor``.
        """
        if self.law is not None:
            return self._place_panels(source, depth_guess)
        floor = self.floor
        view = self.model.view

        def above(offsets, pb):
            log_p, lat = source(offsets[0, :, 2] + floor)
            M, cov = view(lat)
            return log_p[None], M[:, None, :], tuple(c[None] for c in cov)

        xyv = [0, 1, 2]
        mean = self.prior_mean[xyv].copy()
        mean[1] = depth_guess - floor
        cov = self.prior_cov[np.ix_(xyv, xyv)]
        pb = quadrature.Problem(
            mu=np.empty((1, 0)),
            rho=np.array([self.rho]),
            mean=mean[None],
            R=np.linalg.inv(np.linalg.cholesky(cov))[None],
            integrand=above,
            process_noise=np.array([self.process_noise]),
            cov=cov[None],
        )
        try:
            _, _, _, _, grids = quadrature.integrate(pb, (3,), self.rtol)
        except ValueError as exc:  # the quadrature names a problem of no bearings: name the frame
            reason = str(exc).split(": ", 1)[-1]
            where = "the prior" if self.frame == 0 else f"frame {self.frame}"
            raise ValueError(
                f"mu: the exact filter's depth nodes cannot be placed at {where} "
                f"(rho = {self.rho:.6g}): {reason}"
            ) from None
        lo, h, n, frame = grids[3]
        u = quadrature.grid(lo, h, n, 0.0)[0]
        u = u[~np.isnan(u)][None]
        t = frame.t(u)
        log_w = (np.log(h) + t + frame.log_jacobian(u))[0]
        y = floor + np.exp(t[0])
        # nodes within rounding of the floor (at the camera) or of each other, or nearer it
        # than _NEAREST of the depth (where the covariances of a track that returns towards
        # an earlier depth lose their digits): no weight
        keep = (y - floor > _NEAREST * (depth_guess - floor)) & np.concatenate(
            [[True], np.diff(y) > 0]
        )
        log_w, y = log_w[keep], y[keep]
        log_p, lateral = source(y)
        return _Nodes(y, log_w, log_p, lateral)

    def _place_panels(self, source, depth_guess) -> _Nodes:
        """Nodes by :func:`depthcore.exact.panels.place` under the law, for ``source``."""

        def values(y, idx):  # one problem: every row of y is one of its panels
            log_p, lat = source(y.ravel())
            return log_p.reshape(y.shape), lat[1].reshape(y.shape), lat[4].reshape(y.shape)

        where = "the prior" if self.frame == 0 else f"frame {self.frame}"
        target = panels.Target(
            values,
            np.array([self.floor]),
            np.array([[depth_guess]]),
            lambda k: f"mu: the exact filter's depth nodes cannot be placed at {where}",
        )
        placed = panels.place(target, self.law, self.rtol)
        keep = np.isfinite(placed.log_weights[0])
        y, log_w = placed.nodes[0][keep], placed.log_weights[0][keep]
        log_p, lateral = source(y)
        return _Nodes(y, log_w, log_p, lateral)

    def _interpolant(self):
        """The node values interpolated from the current nodes (module docstring).

        The splines are in ``log (y_1 - f)``, ``f`` the floor the nodes were placed above.
        Under a law, each half panel's polynomial through its Gauss-Legendre nodes
        (:func:`depthcore.exact.panels.interpolant`) of the log likelihood and the
        lateral rows, plus the law's exact log density.
        """
        nodes = self._nodes
        base = self._node_floor
        t = np.log(nodes.y - base)
        if self.law is not None:
            law, repair = self.law, self.model.repair
            loglik = nodes.log_p - law.log_pdf(nodes.y)
            inner = panels.interpolant(t, np.vstack([loglik, nodes.lateral]))

            def source(y):
                with np.errstate(divide="ignore"):
                    values = inner(np.log(np.maximum(y - base, 0.0)))
                return values[0] + law.log_pdf(y), repair(values[1:])

            return source
        splines = [
            make_interp_spline(t, v, k=min(_DEGREE, len(t) - 1))
            for v in (nodes.log_p, *nodes.lateral)
        ]
        lo, hi = t[0], t[-1]
        h_lo, h_hi = t[1] - t[0], t[-1] - t[-2]

        repair = self.model.repair

        def source(y):
            with np.errstate(divide="ignore"):  # at the floor: log 0, no weight
                tt = np.log(np.maximum(y - base, 0.0))
            values = [s(np.clip(tt, lo, hi)) for s in splines]
            below = (np.minimum(tt - lo, 0.0) / h_lo) ** 2
            above = (np.maximum(tt - hi, 0.0) / h_hi) ** 2
            return values[0] - below - above, repair(np.stack(values[1:]))

        return source

    def _replace_nodes(self) -> None:
        """Re-place the nodes from the current mixture by the quadrature (module docstring)."""
        nodes = self._nodes
        weighted = np.where(nodes.y > self.floor, nodes.log_p + nodes.log_w, -np.inf)
        mode = nodes.y[np.argmax(weighted)]
        self._nodes = self._place(self._interpolant(), mode)
        self._node_floor = self.floor
        self.replacements += 1

    def _raise_floor(self, floor: float) -> None:
        """The point comes nearer than ever: drop the nodes at or below the new floor.

        If they hold more than ``exp(-_END_MARGIN)`` of the largest node's weight the
        nodes are first re-placed above it, from the density before this frame.
        """
        nodes = self._nodes
        cut = nodes.y <= floor
        if np.all(cut):
            raise ValueError(
                f"step: it brings the point to the camera at every depth the filter holds "
                f"(the depth at frame 1 would have to exceed {floor:.6g})"
            )
        a = nodes.log_p + nodes.log_w
        self.floor = floor
        if np.any(cut) and (
            np.max(a[cut]) > np.max(a) - _END_MARGIN or np.sum(~cut) < 8 or self.law is not None
        ):
            self._replace_nodes()
        elif np.any(cut):
            keep = ~cut
            self._nodes = _Nodes(
                nodes.y[keep], nodes.log_w[keep], nodes.log_p[keep], nodes.lateral[:, keep]
            )

    # --- the filter --------------------------------------------------------------------

    def update(self, mu, rho=None, step=1.0) -> FrameEstimate:
        """Add the next frame: predict by ``step``, report the bearing, gate it, update.

        ``mu`` (a bearing, or a pair ``(x / y, h / y)`` for a point in 3-D; ``NaN``: no
        observation), ``rho`` (``None``: the filter's) and ``step`` as
        :func:`depthcore.problem.predictive.frame_inputs` checks them; returns a
        :class:`~depthcore.problem.predictive.FrameEstimate`.
        """
        obs = self.model.observation(mu)
        missing = np.isscalar(obs) and np.isnan(obs)
        _, r, s = predictive.frame_inputs(
            np.nan if missing else 0.0, rho, step, self.rho, self.frame
        )
        if self.frame > 0 and -(self.travelled + s) > self.floor:
            self._raise_floor(-(self.travelled + s))
        nodes = self._nodes
        lat = nodes.lateral.copy()
        travelled = self.travelled + (s if self.frame > 0 else 0.0)
        y = nodes.y + travelled
        log_p = nodes.log_p
        log_pred, tail, gated = np.nan, np.nan, False
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            if self.frame > 0:
                self.model.predict(lat, s, self.process_noise**2 * abs(s))
            if not missing:
                log_pred, tail = self.model.predictive(
                    obs, log_p + nodes.log_w, lat, y, r * r, tail=self.gate is not None
                )
                gated = bool(predictive.skipped(tail, True, self.gate))
                if not gated:
                    log_p = log_p + self.model.update(lat, obs, y, r * r)
        if not (np.all(np.isfinite(lat)) and np.all(log_p < np.inf) and np.any(log_p > -np.inf)):
            raise ValueError(
                f"mu = {mu!r} with rho = {r:.6g} overflows the exact filter's nodes in double "
                f"precision at frame {self.frame + 1}; the filter is left at frame {self.frame}"
            )
        self.travelled = travelled
        self.frame += 1
        self._nodes = nodes._replace(log_p=log_p, lateral=lat)
        if not self._resolved():
            self._replace_nodes()
        mean, cov = self._moments()
        self.current = predictive.frame_estimate(self.frame, mean, cov, log_pred, tail, gated)
        return self.current

    def predictive_moments(self, step=1.0, rho=None) -> Predicted:
        """Mean and covariance of the next observation under the exact predictive, and its
        covariance with the state; the filter is not changed (one prediction of the nodes).

        The predictive is the mixture over the nodes after the step (textbook 19.2.1), node
        ``j`` weighted by its probability ``p_j`` (a node the step brings to the camera by
        none) and predicting ``N(m_j / y_j, S_j)``, ``S_j = C_j / y_j**2 + rho**2 I`` (the
        observed block of its lateral covariance): ``mean = sum_j p_j m_j / y_j``,
        ``cov = sum_j p_j (S_j + d_j d_j^T)``, ``d_j = m_j / y_j - mean``, and
        ``cross = sum_j p_j (Cov_j[state, obs] + (s_j - E[state]) d_j^T)``, ``s_j`` node
        ``j``'s state mean (its depth ``y_j``).

        Parameters
        ----------
        step : float
            The depth's signed change to the next frame, as :meth:`update` takes it (1 at
            the first frame); 0: the observation at the filter's own frame.
        rho : float or None
            The next observation's noise SD (``None``: the filter's).

        Returns
        -------
        Predicted
            ``mean`` (d,), ``cov`` (d, d) and ``cross`` (D, d): ``d`` 1 (a bearing) or 2 (a
            pair), ``D`` the state's 3 or 5 coordinates.
        """
        moved = step == 0 and self.frame > 0
        _, r, s = predictive.frame_inputs(0.0, rho, 1.0 if moved else step, self.rho, self.frame)
        s = 0.0 if moved else s
        nodes = self._nodes
        lat = nodes.lateral.copy()
        y = nodes.y + self.travelled + (s if self.frame > 0 else 0.0)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            if s and self.frame > 0:
                self.model.predict(lat, s, self.process_noise**2 * abs(s))
            p, _ = normalised(np.where(y > 0, nodes.log_p + nodes.log_w, -np.inf))
            keep = p > 0
            means, S, states, cross = self.model.observed(lat[:, keep], y[keep], r * r)
            p = p[keep]
            mean = p @ means
            d = means - mean
            e = states - p @ states
            cov = np.einsum("j,jkl->kl", p, S + d[:, :, None] * d[:, None, :])
            cross = np.einsum("j,jkl->kl", p, cross + e[:, :, None] * d[:, None, :])
        if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(cross))):
            raise ValueError(f"step: the predictive's moments overflow after a step of {s:.6g}")
        return Predicted(mean, 0.5 * (cov + cov.T), cross)

    def _moments(self, every_other: bool = False):
        nodes = self._nodes
        p, _ = normalised(nodes.log_p + nodes.log_w)
        if every_other:
            p = np.where(np.arange(p.size) % 2 == 0, p, 0.0)
        return self.model.moments(p, nodes.lateral, nodes.y + self.travelled)

    def _resolved(self) -> bool:
        """The check of :func:`depthcore.exact.posterior.update` on the current nodes (under
        a law, whose panel nodes it does not apply to, never: they are placed afresh)."""
        if self.law is not None:
            return False
        nodes = self._nodes
        a = nodes.log_p + nodes.log_w
        top = np.max(a)
        p, _ = normalised(a)
        if max(a[0], a[-1]) > top - _END_MARGIN or np.max(p) >= _ONE_NODE:
            return False
        mean, cov = self._moments()
        with np.errstate(invalid="ignore", divide="ignore"):
            half_mean, half_cov = self._moments(every_other=True)
        eps = np.finfo(float).eps
        floor = np.array(
            [64.0 * eps * (abs(mean[k]) + (2.0 + abs(top)) * np.sqrt(cov[k, k])) for k in (1, 2)]
        )
        err = quadrature.halving_error(mean, cov, half_mean, half_cov, floor)
        sd = np.sqrt([cov[1, 1], cov[2, 2]])
        return bool(np.all(err <= np.maximum(self.rtol * sd, floor)))


def track_updates(bank, gate=None, rtol: float = 1e-10) -> predictive.Updates:
    """Each frame's predictive report for the tracks of a bank, by :class:`Online` row by row.

    Parameters
    ----------
    bank : depthcore.exact.bank.Bank
        The tracks (``mu`` with ``NaN`` at missing frames, ``frame_noise``,
        ``frame_steps``), the prior and the process noise, batch shape (...).
    gate : float or None
    rtol : float
        The nodes' tolerance.

    Returns
    -------
    depthcore.problem.predictive.Updates
        Arrays of shape (..., N).
    """
    gate = predictive.gate(gate)
    mu = np.asarray(bank.mu)
    batch = np.broadcast_shapes(
        mu.shape[:-1],
        bank.frame_noise.shape[:-1],
        bank.frame_steps.shape[:-1],
        np.shape(bank.process_noise),
        bank.prior_mean.shape[:-1],
        bank.prior_cov.shape[:-2],
    )
    N = mu.shape[-1]

    def rows(a, core):
        a = np.asarray(a, dtype=float)
        return np.broadcast_to(a, batch + a.shape[a.ndim - core :]).reshape(
            (-1,) + a.shape[a.ndim - core :]
        )

    mus, noise, steps = rows(mu, 1), rows(bank.frame_noise, 1), rows(bank.frame_steps, 1)
    qs, means, covs = rows(bank.process_noise, 0), rows(bank.prior_mean, 1), rows(bank.prior_cov, 2)
    out = np.full((3, len(mus), N), np.nan)
    for i in range(len(mus)):
        f = Online(means[i], covs[i], noise[i, 0], qs[i], gate, rtol, law=bank.law)
        for k in range(N):
            s = f.update(mus[i, k], noise[i, k], 1.0 if k == 0 else steps[i, k - 1])
            out[:, i, k] = s.log_predictive, s.tail, s.gated
    shape = batch + (N,)
    return predictive.Updates(
        out[0].reshape(shape), out[1].reshape(shape), out[2].reshape(shape) == 1.0
    )


def updates(mu, rho, prior_mean, prior_cov, rtol: float = 1e-10) -> predictive.Updates:
    """Each bearing's predictive report for the paper's frames, by :class:`Online` row by row.

    For the triples of :func:`depthcore.exact.optimal.run`, whose quadrature
    computes the posterior of all three bearings at once: the report of the
    same exact filter fed them one at a time (the model's reading of Eq. (16)
    and the support in front of the camera).

    Parameters
    ----------
    mu : ndarray, shape (..., N)
        Checked bearings.
    rho : ndarray, shape () or (...)
    prior_mean : ndarray, shape (3,) or (..., 3)
    prior_cov : ndarray, shape (3, 3) or (..., 3, 3)
    rtol : float

    Returns
    -------
    depthcore.problem.predictive.Updates
        Arrays of shape (..., N).
    """
    mu = np.asarray(mu, dtype=float)
    batch, N = mu.shape[:-1], mu.shape[-1]
    rho = np.broadcast_to(rho, batch).reshape(-1)
    means = np.broadcast_to(prior_mean, batch + (3,)).reshape(-1, 3)
    covs = np.broadcast_to(prior_cov, batch + (3, 3)).reshape(-1, 3, 3)
    out = np.full((3, len(rho), N), np.nan)
    for i, row in enumerate(mu.reshape(-1, N)):
        f = Online(means[i], covs[i], rho[i], 0.0, None, rtol)
        for k in range(N):
            s = f.update(row[k])
            out[:, i, k] = s.log_predictive, s.tail, s.gated
    shape = batch + (N,)
    return predictive.Updates(
        out[0].reshape(shape), out[1].reshape(shape), out[2].reshape(shape) == 1.0
    )
