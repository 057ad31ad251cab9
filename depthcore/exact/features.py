"""The exact online filter for many features at once, on a fixed number of depth nodes each.

Recommended import: ``from depthcore.exact import features``.

:class:`Features` is :class:`depthcore.exact.online.Online` for ``B`` features (points
seen through bearings, or in 3-D through pairs) updated together, every frame's work
one set of array operations over (B, J): ``J`` depth nodes per feature, the same ``J``
for all and at every frame, so that time and memory per frame do not grow with the
frames. Per feature the nodes lie in ``t = log (y_1 - f)``, ``f`` the feature's floor
(:func:`depthcore.problem.frames.depth_floor`: 0 while it recedes, the largest depth an
approaching camera has travelled towards it), on the grid ``t = c + w sinh(u)`` with
``u`` uniform: nearly uniform in ``t`` within ``w`` of ``c`` (the density's peak and
about twice its SD there), ever coarser in the tails, so that a long tail towards the
camera costs few nodes. They hold what the online filter's nodes hold
(:mod:`depthcore.exact.online_nodes`): the log density ``log N(y_1; m_y, P_yy) + log
p(observations | y_1)`` and the Gaussian of the lateral state given ``y_1``. A frame
predicts every node (textbook 19.2.1), updates it by the observation (19.2.2; a pair
as two scalar updates, exact for noise independent on each coordinate, written out
entry by entry), and mixes the nodes by the trapezoid rule in ``u`` (the weights
``exp(t) dt/du``; the posterior, Eq. (16), integrated over the depth).

The nodes. At the first frame they are placed on the density after the first
observation, computed exactly on two scouting grids: the ``J`` nodes span the ``t``
where its log density lies within 16 of its largest, ``c`` and ``w`` from where it
lies within 2. After every update each feature is checked as the online filter checks
its nodes: the end nodes' log densities lie at least 12 below the largest, no node
holds half the probability, and the depth's and the velocity's means and SDs from
every other node agree with those from all nodes to ``rtol`` of the SD. A feature
that fails is re-placed by the same rule from its current nodes: a 6-point Lagrange
interpolation in ``u`` of each node's log density and Gaussian entries (the log
density extended beyond the end nodes by a quadratic drop of 1 per node spacing
squared, the Gaussian constant). A step towards the point that raises the floor drops
the nodes at or below it (weight 0); if they hold a non-negligible part of the
density, or over half the nodes, the feature is re-placed above the new floor first,
from its density before the frame.

Points in 3-D. Given the depth, the lateral ``(x, v)`` and vertical ``(h, w)`` blocks
see the same geometry; where the prior, conditioned on the depth, makes them one
covariance with none between them (to 1e-9 of it), they stay so, and one 2 x 2
recursion serves both (the vertical block's rows copied from the lateral's), about
half the 4 x 4 recursion's work. Otherwise every entry is updated.

Accuracy. The trapezoid rule converges geometrically here, so that all nodes are far
more accurate than every other node, which the check holds to ``rtol`` (default
``1e-3``); re-placement interpolates smooth functions of ``u``.
``tests/test_features.py`` holds every feature's depth mean and SD, at every frame,
within ``1e-3`` of its SD of :class:`~depthcore.exact.online.Online` at ``rtol =
1e-10`` (plane and 3-D, receding, approaching and mixed steps, uneven, missing
frames, noise per frame, ``q = 0`` and ``q > 0``), and the log predictive within
``1e-3``. A feature that fails its check is re-placed, up to three times in a frame,
each time from the last; one that still fails is not resolved by its nodes, and the
interpolation errors it has taken on would stay with it: ``Features.unresolved`` marks
it and its answers are ``NaN`` from that frame on (start it again on its last answer).
The nodes span the depths where the log density lies within
40 of its largest, and are re-placed once an end comes within 30 of it, so that a
density that moves as bearings arrive stays on them: with ends only 16 below, a
feature on a wide prior whose posterior climbed above the prior's nodes drifted by
0.66 SD with every check passing (a test keeps it). ``J = 128`` (the default) held
every feature of the tests within the tolerance; with 64 such wide priors drift, with 40
some features are withheld, and below 16 the nodes' arithmetic may
overflow (a ``ValueError`` naming the feature). Fuzzed on wide priors (depth SD up to
0.8 of the depth, velocity SD up to 2) with near and approaching points and rho from
1e-4 to 0.1 (some 1,200 features), about 1 % of the features' frames were withheld,
and the answers given lay within 1e-3 of an SD of the full-accuracy filter but for
three features (at most 1.1e-2). The
log predictive of each frame is the ratio of the evidence after and before it; the
filter has no gate (``tail`` is NaN).

Example
-------
::

    from depthcore.exact import features

    f = features.Features(prior_means, prior_covs, rho=0.003, process_noise=1e-3)
    for pairs, steps in camera:            # pairs (B, 2), NaN rows where unseen
        est = f.update(pairs, step=steps)  # steps (B,): each feature's signed step
        print(est.depth_mean, est.depth_sd)
"""

from __future__ import annotations

import numpy as np

from depthcore.exact.online_nodes import Plane
from depthcore.problem import checks, predictive

_LOG_2PI = float(np.log(2.0 * np.pi))
#: Placed nodes span the ``t`` where the log density lies within this of its largest ...
_PLACE_MARGIN = 40.0
#: ... and the end nodes must stay this far below the largest.
_END_MARGIN = 30.0
#: Re-placements of a feature within one frame before its answers are withheld.
_ATTEMPTS = 3
#: A node holding this much of the probability or more does not resolve the density.
_ONE_NODE = 0.5
#: The points of the Lagrange interpolation in ``t``, and of each scouting grid.
_STENCIL, _SCOUT = 6, 160
#: The lateral coordinates of the state: ``(x, v)`` or ``(x, v, h, w)``.
_LATERAL = {3: [0, 2], 5: [0, 2, 3, 4]}
#: The rows of a 3-D node's covariance entries (upper triangle of ``Cov[(x, v, h, w)]``).
_ENTRY = {(i, j): 4 + k for k, (i, j) in enumerate(zip(*np.triu_indices(4), strict=True))}


def _predict_space(lat, s, q2) -> None:
    """Textbook 19.2.1 in place over steps ``s``: ``[[1, s], [0, 1]]`` in each block.

    ``lat`` (14, B, J) in :class:`depthcore.exact.online_nodes.Space`'s rows, ``s`` and
    ``q2`` (the velocities' added variance ``q**2 abs(s)``) of shape (B, 1).
    """
    x, v, h, w, c00, c01, c02, c03, c11, c12, c13, c22, c23, c33 = lat
    x += s * v
    h += s * w
    c02 += s * (c12 + c03 + s * c13)
    c00 += s * (2.0 * c01 + s * c11)
    c01 += s * c11
    c03 += s * c13
    c12 += s * c13
    c22 += s * (2.0 * c23 + s * c33)
    c23 += s * c33
    c11 += q2
    c33 += q2


def _update_space(lat, pair, y, rho2) -> np.ndarray:
    """Textbook 19.2.2 in place by the pair, ``mu`` then ``nu``; the log likelihoods (B, J).

    ``pair`` (B, 2), ``y`` the depths (B, J), ``rho2`` (B, 1). The pair times the depth
    observes ``x`` (then ``h``) with noise variance ``rho**2 y**2``: ``S = C_ii + r``,
    the mean moved by ``C[:, i] e / S``, each entry ``C_kl`` less ``C_ki C_li / S``.
    """
    r = rho2 * (y * y)
    total = 0.0
    for i, z in ((0, pair[:, :1]), (2, pair[:, 1:])):
        column = [lat[_ENTRY[min(i, k), max(i, k)]].copy() for k in range(4)]
        S = column[i] + r
        e = z * y - lat[i]
        g = e / S
        total = total - 0.5 * (_LOG_2PI + np.log(S / (y * y)) + e * g)
        gain = [c / S for c in column]
        for k in range(4):
            lat[k] += column[k] * g
        for (k, m), row in _ENTRY.items():
            lat[row] -= column[k] * gain[m]
    return total


#: The rows of :func:`_update_space`'s layout: the means, the lateral block (x, v), the
#: vertical block (h, w) and the entries between them.
_X_BLOCK, _H_BLOCK = [4, 5, 8], [11, 12, 13]
_CROSS = [6, 7, 9, 10]
#: How near two blocks of a node's covariance count as one (:func:`_shared`).
_SAME = 1e-9


def _shared(lat) -> bool:
    """Whether every node's lateral and vertical blocks are one covariance with none
    between them, to 1e-9 of it (a prior built so, conditioned on the depth in double
    precision, differs by some 1e-11): then they stay so, and one recursion serves both,
    changing the moments by less than 1e-9 of an SD."""
    x, h, cross = lat[_X_BLOCK], lat[_H_BLOCK], lat[_CROSS]
    scale = np.sqrt(np.abs(lat[4] * lat[8])) + np.abs(lat[5])
    return bool(
        np.all(np.abs(x - h) <= _SAME * np.abs(x)) and np.all(np.abs(cross) <= _SAME * scale)
    )


def _predict_shared(lat, s, q2) -> None:
    """:func:`_predict_space` where :func:`_shared` holds: the lateral block's recursion,
    copied to the vertical block (textbook 19.2.1)."""
    lat[0] += s * lat[1]
    lat[2] += s * lat[3]
    a, b, c = lat[4], lat[5], lat[8]  # views: updated in place
    a += s * (2.0 * b + s * c)
    b += s * c
    c += q2
    lat[_H_BLOCK] = lat[_X_BLOCK]


def _update_shared(lat, pair, y, rho2) -> np.ndarray:
    """:func:`_update_space` where :func:`_shared` holds (textbook 19.2.2): ``mu`` and
    ``nu`` observe independent blocks of one covariance, so one gain serves both."""
    r = rho2 * (y * y)
    a, b, c = lat[4], lat[5], lat[8]  # views: updated in place
    S = a + r
    e_x, e_h = pair[:, :1] * y - lat[0], pair[:, 1:] * y - lat[2]
    log_likelihood = -(_LOG_2PI + np.log(S / (y * y))) - 0.5 * (e_x * e_x + e_h * e_h) / S
    ga, gb = a / S, b / S
    lat[0] += ga * e_x
    lat[1] += gb * e_x
    lat[2] += ga * e_h
    lat[3] += gb * e_h
    c -= b * gb
    b *= r / S
    a *= r / S
    lat[_H_BLOCK] = lat[_X_BLOCK]
    return log_likelihood


def _lagrange(x) -> np.ndarray:
    """The weights (6, ...) of the 6-point Lagrange interpolation at ``x`` (nodes 0..5)."""
    d = [x - k for k in range(_STENCIL)]
    out = []
    for k in range(_STENCIL):
        w = np.ones_like(x)
        for m in range(_STENCIL):
            if m != k:
                w = w * d[m] / (k - m)
        out.append(w)
    return np.stack(out)


def _span(t, a, margin: float):
    """Per row, the interval of ``t`` (S, K), increasing, where ``a`` > its largest less
    ``margin``: crossings by linear interpolation, beyond an end by a quadratic drop of 1
    per spacing squared; ``a`` may be ``-inf`` on a prefix of each row."""
    bounds = []
    for tt, aa in ((t, a), (-t[:, ::-1], a[:, ::-1])):
        thr = np.max(aa, axis=1) - margin
        rows = np.arange(len(aa))
        i = np.argmax(aa > thr[:, None], axis=1)
        j = np.maximum(i - 1, 0)
        inside, outside = aa[rows, i], aa[rows, j]
        crossed = (i > 0) & np.isfinite(outside)
        spacing = tt[rows, np.minimum(i + 1, tt.shape[1] - 1)] - tt[rows, i]
        beyond = tt[rows, i] - spacing * np.sqrt(np.maximum(inside - thr, 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = (inside - thr) / (inside - outside)
            cross = tt[rows, i] + frac * (tt[rows, j] - tt[rows, i])
        bounds.append(np.where(crossed, cross, beyond))
    return bounds[0], -bounds[1]


class Features:
    """The exact online filter of ``B`` features at once (see the module docstring).

    Parameters
    ----------
    prior_mean : array_like, shape (B, 3) or (B, 5)
        Each feature's prior mean of ``(x_1, y_1, v)``, one bearing per frame, or of
        ``(x_1, y_1, v, h_1, w)``, a pair ``(x / y, h / y)`` per frame.
    prior_cov : array_like, shape (B, 3, 3) or (B, 5, 5)
        Symmetric positive definite.
    rho : float or array_like, shape (B,)
        The noise SD (> 0) on each bearing, where :meth:`update` is given none.
    process_noise : float or array_like, shape (B,)
        ``q >= 0``: each velocity's variance grows by ``q**2 abs(s)`` over a step ``s``.
    nodes : int
        ``J``, the depth nodes per feature, at least 8.
    rtol : float
        The check's tolerance: every other node's moments against all, relative to the SD.
    """

    def __init__(self, prior_mean, prior_cov, rho, process_noise=0.0, nodes=128, rtol=1e-3):
        self.prior_mean, self.prior_cov = predictive.batch_prior(prior_mean, prior_cov)
        B, d = self.prior_mean.shape
        self.dim = d
        self.rho = predictive.per_feature(rho, "rho", B)
        q = checks.nonnegative_batch(process_noise, "process_noise", (B,))
        self.process_noise = np.broadcast_to(q, (B,)).astype(float)
        self.nodes = checks.count(nodes, "nodes")
        if self.nodes < 8:
            raise ValueError(f"nodes must be at least 8, got {self.nodes}")
        self.rtol = checks.positive_scalar(rtol, "rtol")
        self.frame = 0
        self.travelled, self.floor = np.zeros(B), np.zeros(B)
        #: Re-placements of each feature's nodes so far, (B,).
        self.replacements = np.zeros(B, dtype=int)
        #: Whether each feature's nodes have failed their check after a re-placement, (B,):
        #: its answers are NaN from that frame on (start it again on its last answer).
        self.unresolved = np.zeros(B, dtype=bool)
        self.current: predictive.FrameEstimates | None = None
        self._base = np.zeros(B)  # the floor each feature's nodes were placed above
        self._shares = False  # one covariance for both blocks of a point in 3-D (_shared)
        self._y1 = self._log_p = self._log_w = self._lat = self._grid = None

    # --- the nodes' values -------------------------------------------------------------

    def _prior(self, rows, y):
        """``log N(y; m_y, P_yy)`` (S, K) and the lateral rows (R, S, K) given ``y_1 = y``."""
        m, P = self.prior_mean[rows], self.prior_cov[rows]
        L = _LATERAL[self.dim]
        slope = P[:, L, 1] / P[:, 1, 1, None]
        dy = y - m[:, 1, None]
        means = m[:, L, None] + slope[:, :, None] * dy[:, None, :]
        cov = P[:, L][:, :, L] - slope[:, :, None] * P[:, None, L, 1]
        log_p = -0.5 * (_LOG_2PI + np.log(P[:, 1, 1, None]) + dy * dy / P[:, 1, 1, None])
        if self.dim == 3:
            a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
            entries = [a, b, c, a * c - b * b]
        else:
            entries = [cov[:, i, j] for (i, j) in _ENTRY]
        flat = np.stack([np.broadcast_to(e[:, None], y.shape) for e in entries])
        return log_p, np.concatenate([np.moveaxis(means, 1, 0), flat])

    def _observe(self, lat, obs, y, rho2) -> np.ndarray:
        """Update rows ``lat`` (R, S, K) in place by the observations (S,) or (S, 2)."""
        if self.dim == 3:
            return Plane.update(lat, obs[:, None], y, rho2)
        return (_update_shared if self._shares else _update_space)(lat, obs, y, rho2)

    def _first(self, rows, obs, present, rho):
        """The source of the first frame's density, exact: the prior times the first
        observation's likelihood at depths ``y`` (S, K) of the features ``rows``."""

        def source(y):
            log_p, lat = self._prior(rows, y)
            here = present[rows]
            if np.any(here):
                sub = lat[:, here]
                log_p[here] += self._observe(
                    sub, obs[rows][here], y[here], rho[rows][here, None] ** 2
                )
                lat[:, here] = sub
            return log_p, lat

        return source

    # --- placement ---------------------------------------------------------------------

    def _place(self, rows, spans, base, source) -> None:
        """Nodes of ``rows`` above ``base`` on the grid ``t = c + w sinh(u)``, ``u`` uniform,
        from the spans (:func:`_span`) of the density at the margins 16 and 2."""
        (lo, hi), (lo2, hi2) = spans
        c = 0.5 * (lo2 + hi2)
        w = np.maximum(0.5 * (hi2 - lo2), 1e-3 * (hi - lo))
        u0, u1 = np.arcsinh((lo - c) / w), np.arcsinh((hi - c) / w)
        du = (u1 - u0) / (self.nodes - 1)
        u = u0[:, None] + du[:, None] * np.arange(self.nodes)
        t = c[:, None] + w[:, None] * np.sinh(u)
        y1 = base[:, None] + np.exp(t)
        log_p, lat = source(y1)
        self._y1[rows], self._log_p[rows] = y1, log_p
        self._log_w[rows] = t + np.log(w[:, None] * np.cosh(u) * du[:, None])
        self._grid[:, rows] = c, w, u0, du
        self._lat[:, rows] = lat
        self._base[rows] = base

    def _scout(self, rows, source):
        """The span of the exact density of ``rows`` (above the floor 0): two scouting grids."""
        m, sd = self.prior_mean[rows, 1], np.sqrt(self.prior_cov[rows, 1, 1])
        hi = np.log(np.abs(m) + 20.0 * sd)
        lo = np.log(np.maximum(m, sd)) - 25.0
        for _ in range(2):
            t = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, _SCOUT)
            log_p, _ = source(np.exp(t))
            span = _span(t, log_p + t, _PLACE_MARGIN)
            pad = (hi - lo) / (_SCOUT - 1)
            lo, hi = np.maximum(span[0] - pad, lo), np.minimum(span[1] + pad, hi)
        return span, _span(t, log_p + t, 2.0)

    def _re_place(self, rows, floor, old_floor) -> None:
        """Re-place the nodes of ``rows`` above ``floor`` (S,) by interpolation (module
        docstring), from the nodes above ``old_floor`` (S,)."""
        J, y1 = self.nodes, self._y1[rows]
        log_p, lat = self._log_p[rows], self._lat[:, rows]
        above = y1 > floor[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_new = np.log(y1 - floor[:, None])
        t_new, a_new = np.where(above, t_new, -np.inf), np.where(above, log_p + t_new, -np.inf)
        spans = _span(t_new, a_new, _PLACE_MARGIN), _span(t_new, a_new, 2.0)
        first = np.minimum(np.argmax(y1 > old_floor[:, None], axis=1), J - _STENCIL)
        values = np.concatenate([log_p[None], lat])
        (c, w, u0, du), base = self._grid[:, rows], self._base[rows]

        def source(y):
            t = np.log(y - base[:, None])
            u = (np.arcsinh((t - c[:, None]) / w[:, None]) - u0[:, None]) / du[:, None]
            uc = np.clip(u, first[:, None], J - 1)
            i0 = np.clip(np.floor(uc).astype(int) - 2, first[:, None], J - _STENCIL)
            weight = _lagrange(uc - i0)
            flat = values.reshape(len(values), -1)
            at = i0 + (np.arange(len(rows)) * J)[:, None]
            out = sum(weight[k] * flat[:, at + k] for k in range(_STENCIL))
            out[0] -= (u - uc) ** 2
            if self.dim == 3:
                out[6] = out[3] * out[5] - out[4] ** 2
            return out[0], out[1:]

        self._place(rows, spans, floor, source)
        self.replacements[rows] += 1

    # --- the filter --------------------------------------------------------------------

    def update(self, mu, rho=None, step=1.0) -> predictive.FrameEstimates:
        """Add the next frame of every feature: predict by ``step``, update by ``mu``.

        Parameters
        ----------
        mu : array_like, shape (B,) or (B, 2)
            Bearings, or pairs ``(x / y, h / y)``; NaN (a NaN row) where a feature is not
            seen: it is predicted only.
        rho : float, array_like of shape (B,), or None
            The noise SD (``None``: the filter's).
        step : float or array_like, shape (B,)
            Each feature's signed depth change since the last frame, nonzero; ignored at
            the first frame.

        Returns
        -------
        depthcore.problem.predictive.FrameEstimates
            No gate: ``tail`` is NaN.
        """
        obs, present, r, s = predictive.batch_inputs(
            mu, rho, step, self.rho, self.frame, self.dim, len(self.rho)
        )
        B, J = len(r), self.nodes
        from scipy.special import log_ndtr  # scipy loads on first use, not with the package

        m_y, P_yy = self.prior_mean[:, 1], self.prior_cov[:, 1, 1]
        log_before = log_ndtr(m_y / np.sqrt(P_yy))  # the prior's mass in front of the camera
        if self.frame == 0:
            R = 6 if self.dim == 3 else 14
            self._y1, self._log_p, self._log_w = (np.empty((B, J)) for _ in range(3))
            self._grid = np.empty((4, B))
            self._lat = np.empty((R, B, J))
            every = np.arange(B)
            source = self._first(every, obs, present, r)
            self._place(every, self._scout(every, source), np.zeros(B), source)
            if self.dim == 5 and _shared(self._lat):  # exactly so from here on
                self._lat[_CROSS] = 0.0
                self._lat[_H_BLOCK] = self._lat[_X_BLOCK]
                self._shares = True
        else:
            self._advance(s)
            valid = self._y1 > self.floor[:, None]
            a = np.where(valid, self._log_p + self._log_w, -np.inf)
            top = np.max(a, axis=1)
            log_before = top + np.log(np.sum(np.exp(a - top[:, None]), axis=1))
            y = np.where(valid, self._y1 + self.travelled[:, None], 1.0)
            # a feature whose answers are withheld may overflow: the check below sees to it
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                q2 = (self.process_noise**2 * np.abs(s))[:, None]
                if self.dim == 3:
                    Plane.predict(self._lat, s[:, None], 0.0)
                    self._lat[4] += q2
                    self._lat[5] += q2 * self._lat[2]
                else:
                    predict = _predict_shared if self._shares else _predict_space
                    predict(self._lat, s[:, None], q2)
                rho2 = (r * r)[:, None]
                if np.all(present):
                    self._log_p += self._observe(self._lat, obs, y, rho2)
                elif np.any(present):
                    sub = self._lat[:, present]
                    self._log_p[present] += self._observe(
                        sub, obs[present], y[present], rho2[present]
                    )
                    self._lat[:, present] = sub
        self.frame += 1
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            mean, cov, ok, log_z = self._moments(np.arange(B))
        log_pred = np.where(present, log_z - log_before, np.nan)
        bad = np.flatnonzero(~ok & ~self.unresolved)
        for _ in range(_ATTEMPTS):  # each re-placement from the last resolves more finely
            if not bad.size:
                break
            self._re_place(bad, self.floor[bad], self.floor[bad])
            mean[bad], cov[bad], ok_again, _ = self._moments(bad)
            bad = bad[~ok_again]
        self.unresolved[bad] = True
        # a feature its nodes once failed to resolve carries that error on: its answers
        # are withheld from then on, not given wrong
        lost = self.unresolved
        mean[lost], cov[lost], log_pred[lost] = np.nan, np.nan, np.nan
        finite = self.unresolved | (
            np.all(np.isfinite(mean), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
        )
        if not np.all(finite):
            raise ValueError(
                f"mu overflows the exact filter's nodes in double precision at frame "
                f"{self.frame} for feature {int(np.argmin(finite))} (of {int(np.sum(~finite))}); "
                "the batch is left mid-frame: start it again without that feature"
            )
        self.current = predictive.frame_estimates(self.frame, mean, cov, log_pred)
        return self.current

    def _advance(self, s) -> None:
        """The steps ``s`` (B,): travel, raise the floors, re-place where nodes it cuts mattered."""
        travelled = self.travelled + s
        floor = np.maximum(self.floor, -travelled)
        raised = np.flatnonzero(floor > self.floor)
        if raised.size:
            y1, old = self._y1[raised], self.floor[raised]
            valid = y1 > old[:, None]
            a = np.where(valid, self._log_p[raised] + self._log_w[raised], -np.inf)
            cut = valid & (y1 <= floor[raised, None])
            top = np.max(a, axis=1)
            heavy = np.max(np.where(cut, a, -np.inf), axis=1) > top - _END_MARGIN
            few = np.sum(y1 > floor[raised, None], axis=1) < self.nodes // 2
            if np.any(heavy | few):
                rows = raised[heavy | few]
                self._re_place(rows, floor[rows], old[heavy | few])
        self.travelled, self.floor = travelled, floor

    def _moments(self, rows):
        """The state's mean (S, d), covariance (S, d, d), the check (S,) and the log evidence."""
        d, J = self.dim, self.nodes
        y1, lat = self._y1[rows], self._lat[:, rows]
        valid = y1 > self.floor[rows, None]
        a = np.where(valid, self._log_p[rows] + self._log_w[rows], -np.inf)
        top = np.max(a, axis=1)
        w = np.exp(a - top[:, None])
        total = np.sum(w, axis=1)
        p = w / total[:, None]
        log_z = top + np.log(total)
        depth = y1 + self.travelled[rows, None]
        L = _LATERAL[d]
        states = np.empty((d, len(rows), J))
        states[L] = lat[: len(L)]
        states[1] = depth
        mean = np.einsum("kbj,bj->bk", states, p)
        D = states - mean.T[:, :, None]
        cov = np.matmul(np.moveaxis(D * p, 0, 1), np.moveaxis(D, 0, 2))
        entries = np.einsum("rbj,bj->br", lat[len(L) :], p)
        pairs = [(0, 0), (0, 1), (1, 1)] if d == 3 else list(_ENTRY)
        for k, (i, j) in enumerate(pairs):
            cov[:, L[i], L[j]] += entries[:, k]
            if i != j:
                cov[:, L[j], L[i]] += entries[:, k]
        # the check: ends, one node, every other node's moments of depth and velocity
        first = np.argmax(valid, axis=1)
        lowest = a[np.arange(len(rows)), first]
        ok = (np.maximum(lowest, a[:, -1]) < top - _END_MARGIN) & (np.max(p, axis=1) < _ONE_NODE)
        var_v = lat[4] if d == 3 else lat[_ENTRY[1, 1]]
        eps = 64.0 * np.finfo(float).eps
        # every other node may hold no probability at all (a posterior on one node): 0 / 0,
        # whose NaN fails the check and re-places the nodes
        with np.errstate(invalid="ignore", divide="ignore"):
            ph = p[:, ::2] / np.sum(p[:, ::2], axis=1, keepdims=True)
            for k, value, extra in ((1, depth, 0.0), (2, lat[1], var_v)):
                sd = np.sqrt(cov[:, k, k])
                m_h = np.sum(ph * value[:, ::2], axis=1)
                dev = value[:, ::2] - m_h[:, None]
                extra_h = 0.0 if k == 1 else extra[:, ::2]
                sd_h = np.sqrt(np.sum(ph * (extra_h + dev * dev), axis=1))
                err = np.maximum(np.abs(m_h - mean[:, k]), np.abs(sd_h - sd))
                scale = eps * (np.abs(mean[:, k]) + (2.0 + np.abs(top)) * sd)
                ok &= err <= np.maximum(self.rtol * sd, scale)
        return mean, cov, ok, log_z
