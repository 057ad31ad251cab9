"""The optimal filter p_o and its exact marginals, Eqs. (2)-(6) and (13)-(16).

Recommended import: ``from depthcore.exact import optimal``.

For a fixed depth ``y`` the log posterior (6) is quadratic in ``u = (x, v)``:
each measurement term of ``f`` is linear in ``u`` and so is the prior's
argument ``G^{-2} x = (x - 2v, y - 2, v)``. Writing all six terms (three
measurements, three whitened prior components) as ``g_i . u - z_i``,

    log p_o(x, y, v) = -1/2 sum_i (g_i(y) . u - z_i(y))**2 + const,

so the inner integral over ``u`` is Gaussian (Eqs. (14)-(16)) with precision
``M = sum_i g_i g_i^T`` and

    log p_oy(y) = -1/2 log det M(y) - 1/2 S(y) + const,

where ``S(y) = min_u sum_i (g_i . u - z_i)**2``. The paper's Eq. (16) keeps
only ``-1/2 log det M + l^T M^{-1} l / 8`` and calls the rest a constant
"independent of y"; it is not: ``S = |z|**2 - l^T M^{-1} l / 4`` and ``|z|**2``
contains the prior's depth term ``(y - 2 - m2)**2 / P22``. ``reading="printed"``
drops it as the print does; ``reading="derived"`` (the default) keeps it.

Both ``det M`` and ``S`` are computed as sums of squares by the Cauchy-Binet
formula (``det M = sum_{i<j} (g_i x g_j)**2``, ``S det M = sum_{i<j<k}
det[g z]_{ijk}**2``), so neither suffers cancellation near the poles
``y = 0, 1, 2`` or at small noise.

The depth marginal is integrated by :mod:`depthcore.exact.quadrature`; the velocity
marginal is the mixture over the same nodes of the Gaussians of ``v`` given ``y``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from depthcore.exact import modes, online, posterior, quadrature
from depthcore.exact.cdf import gauss_legendre_cdf
from depthcore.exact.mixture import Moments
from depthcore.kalman.second_order import A2
from depthcore.problem import checks, frames, model, predictive, signature
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import f

READINGS = ("derived", "printed")
#: ``"front"``: depths ``y > 2``, the point in front of the camera at all three
#: frames; ``"all"``: every real ``y`` but the poles, Eq. (6) taken literally.
SUPPORTS = ("front", "all")

#: Target accuracy of each mean and SD, relative to the SD, unless a caller asks for another.
RTOL = 1e-10

#: ``G^{-2} x`` as a function of ``u = (x, v)`` for fixed ``y``: ``L u + (0, y - 2, 0)``.
_L = A2[:, [0, 2]]


def _problem(mu, rho, prior_mean, prior_cov, reading) -> quadrature.Problem:
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    mu = np.atleast_2d(checks.three_frames(mu, "mu"))
    prior_cov = checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.shape != (3, 3):
        raise ValueError(f"prior_cov must have shape (3, 3), got shape {prior_cov.shape}")
    mu, rho, prior_mean, prior_cov = model.batch_problem(mu, rho, prior_mean, prior_cov)
    B = mu.shape[0]
    prior_mean = np.broadcast_to(prior_mean, (B, 3))
    R = np.linalg.inv(np.linalg.cholesky(prior_cov))
    return quadrature.Problem(
        mu, np.full(B, rho), prior_mean, np.broadcast_to(R, (B, 3, 3)), _solve, True, reading
    )


def log_posterior(x, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (6): ``-f(x) / (2 rho**2) + log p(G^{-2} x)``, ``f`` from Eq. (5), unnormalised.

    Parameters
    ----------
    x : array_like, shape (..., 3)
        States at time 3.
    mu : array_like, shape (3,)
    rho : float
    prior : Gaussian
        Density of the state at time 1.

    Returns
    -------
    ndarray, shape x.shape[:-1]
    """
    rho = checks.positive_scalar(rho, "rho")
    mu = model.measurements(mu)
    x = np.asarray(x, dtype=float)
    return -f(x, mu) / (2.0 * rho**2) + prior.logpdf(model.G(x, -2))


def _terms(offsets, pb: quadrature.Problem):
    """The six terms ``g_i . u - z_i`` of Eq. (6) at ``offsets`` (B, n, 3): ``gx, gv, z`` (6, B, n).

    Rows 0-2: ``((x - k v) / (y - k) - mu_{3-k}) / rho``, ``k = 0, 1, 2``; rows 3-5:
    ``R (G^{-2} x - m)``.
    """
    B, n, _ = offsets.shape
    s = np.moveaxis(offsets, -1, 0) * pb.rho[:, None]
    np.reciprocal(s, out=s)
    RL = pb.R @ _L  # (B, 3, 2)
    gx = np.empty((6, B, n))
    gv = np.empty((6, B, n))
    z = np.empty((6, B, n))
    gx[:3] = s
    gv[:3] = -np.array([0.0, 1.0, 2.0])[:, None, None] * s
    gx[3:] = RL[:, :, 0].T[:, :, None]
    gv[3:] = RL[:, :, 1].T[:, :, None]
    z[:3] = (pb.mu[:, ::-1] / pb.rho[:, None]).T[:, :, None]
    # G^{-2} x - m = L u + b with b = (-m1, (y - 2) - m2, -m3), and z = -R b.
    z[3:] = (
        np.einsum("bij,bj->bi", pb.R, pb.mean).T[:, :, None]
        - pb.R[:, :, 1].T[:, :, None] * offsets[None, ..., 2]
    )
    return gx, gv, z


_MEAS_PAIRS = ((0, 1), (0, 2), (1, 2))


def _solve(offsets, pb: quadrature.Problem):
    """The integrand of :class:`~depthcore.exact.quadrature.Problem` for Eq. (6), batched.

    Cauchy-Binet (module docstring) on the rows of :func:`_terms`: measurement row
    ``k`` is ``g = s_k (1, -k)``, ``z = w_k``; prior row ``j`` is ``g = q_j``,
    ``z = zeta_j``. The 2 x 2 minors are ``s_k s_l (k - l)``, ``s_k K_kj`` or ``P_jj'``;
    the mean follows by Cramer's rule.
    """
    rho = pb.rho[:, None]
    s = [1.0 / (offsets[..., k] * rho) for k in range(3)]
    s2 = [sk * sk for sk in s]
    RL = pb.R @ _L
    qx, qv = RL[:, :, 0], RL[:, :, 1]  # (B, 3)
    K = [[(qv[:, j] + k * qx[:, j])[:, None] for j in range(3)] for k in range(3)]
    P = {p: (qx[:, p[0]] * qv[:, p[1]] - qv[:, p[0]] * qx[:, p[1]])[:, None] for p in _MEAS_PAIRS}
    w = [(pb.mu[:, 2 - k] / pb.rho)[:, None] for k in range(3)]
    alpha = np.einsum("bij,bj->bi", pb.R, pb.mean)
    zeta = [alpha[:, j : j + 1] - pb.R[:, j, 1:2] * offsets[..., 2] for j in range(3)]
    qxc = [qx[:, j : j + 1] for j in range(3)]
    qvc = [qv[:, j : j + 1] for j in range(3)]

    det_M = (
        s2[0] * s2[1]
        + 4.0 * s2[0] * s2[2]
        + s2[1] * s2[2]
        + sum(s2[k] * sum(K[k][j] ** 2 for j in range(3)) for k in range(3))
        + sum(P[p] ** 2 for p in _MEAS_PAIRS)
    )
    # The three measurement rows' minor, -w0 s1 s2 + 2 w1 s0 s2 - w2 s0 s1, equals
    # (2 (mu1 - mu2) - d y) s0 s1 s2 = d (c2 - y) s0 s1 s2 with d = mu1 + mu3 - 2 mu2:
    # the factored form keeps its relative accuracy where the terms cancel (near y = c2).
    d = (pb.mu[:, 0] + pb.mu[:, 2] - 2.0 * pb.mu[:, 1])[:, None]
    c2 = model.noise_free_depth_unchecked(pb.mu)[:, None]
    minors3 = (d * (c2 - offsets[..., 0]) * s[0] * s[1] * s[2]) ** 2
    for k, l in _MEAS_PAIRS:
        for j in range(3):
            minors3 = (
                minors3
                + (w[k] * s[l] * K[l][j] - w[l] * s[k] * K[k][j] + (k - l) * zeta[j] * s[k] * s[l])
                ** 2
            )
    for k in range(3):
        for j, jj in _MEAS_PAIRS:
            minors3 = (
                minors3
                + (w[k] * P[(j, jj)] - zeta[j] * s[k] * K[k][jj] + zeta[jj] * s[k] * K[k][j]) ** 2
            )
    minors3 = minors3 + (zeta[0] * P[(1, 2)] - zeta[1] * P[(0, 2)] + zeta[2] * P[(0, 1)]) ** 2
    S = minors3 / det_M

    nx = nv = 0.0
    for k, l in _MEAS_PAIRS:
        D = (k - l) * s[k] * s[l]
        nx = nx + D * (k * w[l] * s[k] - l * w[k] * s[l])
        nv = nv + D * (w[l] * s[k] - w[k] * s[l])
    for k in range(3):
        for j in range(3):
            D = s[k] * K[k][j]
            nx = nx + D * (w[k] * qvc[j] + k * s[k] * zeta[j])
            nv = nv + D * (s[k] * zeta[j] - w[k] * qxc[j])
    for j, jj in _MEAS_PAIRS:
        D = P[(j, jj)]
        nx = nx + D * (zeta[j] * qvc[jj] - qvc[j] * zeta[jj])
        nv = nv + D * (qxc[j] * zeta[jj] - zeta[j] * qxc[jj])
    mean = np.stack([nx / det_M, nv / det_M])
    cxx = (s2[1] + 4.0 * s2[2] + np.sum(qv**2, 1)[:, None]) / det_M
    cvv = (s2[0] + s2[1] + s2[2] + np.sum(qx**2, 1)[:, None]) / det_M
    cxv = (s2[1] + 2.0 * s2[2] - np.sum(qx * qv, 1)[:, None]) / det_M
    log_density = -0.5 * np.log(det_M) - 0.5 * S
    if pb.reading == "printed":
        # Eq. (16) keeps only l^T M^{-1} l / 8 = (|z|^2 - S) / 2 beside the determinant.
        log_density = log_density + 0.5 * (sum(wk**2 for wk in w) + sum(zj**2 for zj in zeta))
    return log_density, mean, (cxx, cxv, cvv)


def quadratic_coefficients(y, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (14): ``log p_o = -1/2 (A x**2 + B x v + C v**2 + D x + E v) + terms in y only``.

    ``y`` is (n,), ``mu, rho, prior`` as in :func:`log_posterior`. Returns (n, 5), columns
    ``A .. E``; ``M = [[A, B/2], [B/2, C]]`` and ``l = (D, E)`` of Eq. (15).
    """
    y = np.atleast_1d(np.asarray(y, dtype=float))
    pb = _problem(model.measurements(mu), rho, prior.mean, prior.cov, "derived")
    gx, gv, z = (a[:, 0] for a in _terms(np.stack([y, y - 1, y - 2], -1)[None], pb))
    A, B, C = np.sum(gx * gx, 0), 2.0 * np.sum(gx * gv, 0), np.sum(gv * gv, 0)
    D, E = -2.0 * np.sum(gx * z, 0), -2.0 * np.sum(gv * z, 0)
    return np.stack([A, B, C, D, E], -1)


def conditional(y, mu, rho: float, prior: Gaussian, reading: str = "derived"):
    """Eqs. (14)-(16): log depth marginal and the Gaussian of ``(x, v)`` given ``y``.

    Parameters
    ----------
    y : array_like, shape (n,)
        Depths at time 3, none at a pole ``0, 1, 2``.
    mu, rho, prior
        As in :func:`log_posterior`.
    reading : {"derived", "printed"}
        See the module docstring.

    Returns
    -------
    log_density : ndarray, shape (n,)
        Unnormalised ``log p_oy(y)``.
    mean : ndarray, shape (n, 2)
    cov : ndarray, shape (n, 2, 2)
        ``E[(x, v) | y]`` and ``Cov[(x, v) | y] = M^{-1}``.
    """
    y = np.atleast_1d(checks.finite_array(y, "y"))
    if np.any(np.isin(y, (0.0, 1.0, 2.0))):
        raise ValueError("y must avoid the poles 0, 1, 2 of Eq. (5)")
    pb = _problem(model.measurements(mu), rho, prior.mean, prior.cov, reading)
    log_density, mean, (cxx, cxv, cvv) = _solve(np.stack([y, y - 1, y - 2], -1)[None], pb)
    cov = np.stack([np.stack([cxx, cxv], -1), np.stack([cxv, cvv], -1)], -2)
    return log_density[0], mean[:, 0].T, cov[0]


@signature.documented
def moments(
    mu,
    rho: float,
    prior_mean,
    prior_cov,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
    chunk: int = 64,
) -> Moments:
    """Eqs. (13)-(16) for a batch of triples (``mu`` of shape (B, 3)): the optimal moments.

    {parameters}
    reading : {"derived", "printed"}
    support : {"front", "all"}
    rtol : float
        See :func:`run`.
    chunk : int
        Problems integrated together (memory grows with it).

    Returns
    -------
    Moments
    """
    pb = _problem(mu, rho, prior_mean, prior_cov, reading)
    if pb.mu.shape[1] != 3:
        raise ValueError(f"mu must have shape (B, 3), got shape {pb.mu.shape}")
    intervals = _intervals(support)
    rtol = checks.positive_scalar(rtol, "rtol")
    out, means, covs = [], [], []
    for start in range(0, pb.mu.shape[0], chunk):
        m, err_y, err_v, _, _ = quadrature.integrate(
            pb.take(slice(start, start + chunk)), intervals, rtol
        )
        out.append(np.concatenate([m.key_moments(), [err_y, err_v, m.behind]]))
        means.append(m.mean)
        covs.append(m.cov)
    return Moments(*np.concatenate(out, axis=1), np.concatenate(means), np.concatenate(covs))


def _intervals(support: str):
    if support not in SUPPORTS:
        raise ValueError(f"support must be one of {SUPPORTS}, got {support!r}")
    return (3,) if support == "front" else (0, 1, 2, 3)


def _fine_velocity_mixture(
    pb: quadrature.Problem, grids: dict, log_normaliser, max_refine: int = 256
):
    """The velocity mixture on nodes close enough for a smooth curve, batched.

    At small noise ``s_v(y)`` is far narrower than the spacing of the means at the
    moment nodes, so each problem's step is halved until neighbouring nodes of weight
    above 1e-14 have means within half an SD. Returns weights, means and SDs (B, n).
    """
    B = len(log_normaliser)
    weights, means, sds = [], [], []
    for i, (lo, h, n, frame) in grids.items():
        rows = [None] * B
        active = np.arange(B)
        u = quadrature.grid(lo, h, n, 0.0)
        w, mean, sd = _velocity_nodes(i, u, frame, pb, log_normaliser)
        factor = 1
        while True:
            valid = ~np.isnan(u)
            big = w > 1e-14 * np.max(w, axis=1, keepdims=True)
            with np.errstate(invalid="ignore"):
                gap = np.abs(np.diff(mean, axis=1)) / np.minimum(sd[:, 1:], sd[:, :-1])
            rough = (big[:, 1:] | big[:, :-1]) & valid[:, 1:] & valid[:, :-1] & (gap > 0.5)
            refine = np.any(rough, axis=1) & (factor < max_refine)
            for k in np.flatnonzero(~refine):
                rows[active[k]] = (w[k] * (h[active[k]] / factor), mean[k], sd[k])
            if not np.any(refine):
                break
            keep = np.flatnonzero(refine)
            active, u, w, mean, sd = active[keep], u[keep], w[keep], mean[keep], sd[keep]
            mid = 0.5 * (u[:, :-1] + u[:, 1:])
            sub = modes.Frame(frame.t0[active], frame.sigma[active])
            new = _velocity_nodes(i, mid, sub, pb.take(active), log_normaliser[active])
            u, w, mean, sd = (
                _interleave(a, b) for a, b in zip((u, w, mean, sd), (mid, *new), strict=True)
            )
            factor *= 2
        width = max(len(r[0]) for r in rows)
        for out, k, fill in ((weights, 0, 0.0), (means, 1, 0.0), (sds, 2, 1.0)):
            out.append(
                np.stack([np.pad(r[k], (0, width - len(r[k])), constant_values=fill) for r in rows])
            )
    w = np.concatenate(weights, axis=1)
    return (
        w / np.sum(w, axis=1, keepdims=True),
        np.concatenate(means, axis=1),
        np.concatenate(sds, axis=1),
    )


def _velocity_nodes(interval: int, u, frame: modes.Frame, pb: quadrature.Problem, log_normaliser):
    """Depth weights, velocity means and SDs at nodes ``u`` (B, n); NaN nodes weigh 0."""
    skip = np.isnan(u)
    offsets, log_jac = modes.mapped_nodes(interval, np.where(skip, 0.0, u), frame)
    log_density, mean, (_, _, cvv) = _solve(offsets, pb)
    w = np.where(skip, 0.0, np.exp(log_density + log_jac - log_normaliser[:, None]))
    return w, np.where(skip, 0.0, mean[1]), np.where(skip, 1.0, np.sqrt(cvv))


def _interleave(a, b):
    """Columns ``a0 b0 a1 b1 ... a_n`` from ``a`` (B, n + 1) and ``b`` (B, n)."""
    out = np.empty((a.shape[0], a.shape[1] + b.shape[1]))
    out[:, 0::2] = a
    out[:, 1::2] = b
    return out


@dataclass(frozen=True)
class OptimalMarginals:
    """The optimal filter's depth and velocity marginals of one triple, Eqs. (13)-(16).

    Attributes
    ----------
    depth_mean, depth_sd, velocity_mean, velocity_sd : float
    depth_error, velocity_error : float
        See :class:`~depthcore.exact.mixture.Moments`.
    prob_behind_camera : float
        Posterior probability that the depth at the first frame is not positive.
    log_normaliser : float
        ``log`` of the integral of :func:`conditional`'s depth marginal.
    n_nodes : int
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
        Posterior mean and covariance of ``(x, y, v)`` at time 3.
    """

    mu: np.ndarray
    rho: float
    prior: Gaussian
    reading: str
    support: str
    depth_mean: float
    depth_sd: float
    velocity_mean: float
    velocity_sd: float
    depth_error: float
    velocity_error: float
    prob_behind_camera: float
    log_normaliser: float
    n_nodes: int
    mean: np.ndarray
    cov: np.ndarray
    _problem: quadrature.Problem
    _grids: dict

    @property
    def updates(self) -> predictive.Updates:
        """The :func:`~depthcore.exact.online.updates` of each bearing, shape (3,) each."""
        return online.updates(self.mu, self.rho, self.prior.mean, self.prior.cov)

    def depth_pdf(self, y) -> np.ndarray:
        """Normalised ``p_oy`` at ``y`` (any shape); zero at the poles and outside the support."""
        y = np.asarray(y, dtype=float)
        flat = y.ravel()
        outside = np.isin(flat, (0.0, 1.0, 2.0))
        if self.support == "front":
            outside |= flat <= 2
        safe = np.where(outside, 3.0, flat)
        log_density, _, _ = conditional(safe, self.mu, self.rho, self.prior, self.reading)
        pdf = np.where(outside, 0.0, np.exp(log_density - self.log_normaliser))
        return pdf.reshape(y.shape)

    def velocity_pdf(self, v) -> np.ndarray:
        """Normalised ``p_ov`` at ``v`` (any shape), on :func:`_fine_velocity_mixture`'s nodes."""
        v = np.asarray(v, dtype=float)
        w, m, sd = (
            a[0]
            for a in _fine_velocity_mixture(
                self._problem, self._grids, np.array([self.log_normaliser])
            )
        )
        keep = w > 1e-17 * np.max(w)
        w, m, sd = w[keep], m[keep], sd[keep]
        flat = v.ravel()
        pdf = np.empty(flat.size)
        for start in range(0, flat.size, 512):  # bounded memory: 512 velocities at a time
            z = (flat[start : start + 512, None] - m) / sd
            pdf[start : start + 512] = (np.exp(-0.5 * z**2) / (np.sqrt(2.0 * np.pi) * sd)) @ w
        return pdf.reshape(v.shape)


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    reading="derived",
    support="front",
    rtol=RTOL,
    steps=None,
    gate=None,
    law=None,
):
    """The optimal filter, Eqs. (6), (13)-(16), of one sequence or a batch: the exact filter's door.

    Three frames without process noise: the quadrature of Eqs. (14)-(16); otherwise (or
    with ``law``) the bank of :func:`depthcore.exact.posterior.posterior`.

    {parameters}
    reading : {"derived", "printed"}
        ``"printed"`` drops the y-dependent factor that Eq. (16) calls constant.
    support : {"front", "all"}
        ``"front"`` (default) conditions on the point being in front of the camera
        at every frame (``y > 2``); ``"all"`` integrates Eq. (6) over every depth,
        behind the camera too, and reports that mass as ``prob_behind_camera``.
        Both readings and supports: the paper's three frames only.
    rtol : float
        Target accuracy of each mean and SD, relative to the SD.
    law : depthcore.problem.depth_prior.DepthPrior, optional
        A prior with any law of the depth in place of the Gaussian.

    Returns
    -------
    OptimalMarginals, BatchMarginals, Moments or Mixture
        One triple: :class:`OptimalMarginals`; a batch of triples: :class:`BatchMarginals`
        (derived, front) or :class:`~depthcore.exact.mixture.Moments`; otherwise the
        :class:`~depthcore.exact.mixture.Mixture`, whose ``updates`` is the gate's report
        (``None`` without a gate: see its :meth:`~depthcore.exact.mixture.Mixture.report`).
    """
    gate = predictive.gate(gate)
    if gate is not None or law is not None:
        _paper_only(reading, support)
        return _gated(mu, rho, prior_mean, prior_cov, process_noise, rtol, steps, gate, law)
    if posterior.irregular(mu, rho, steps):
        track = frames.check(mu, rho, steps)
        if not track.regular:
            _paper_only(reading, support)
            return posterior.posterior(
                mu, rho, prior_mean, prior_cov, process_noise, rtol, steps=steps
            )
        rho = track.row_rho
    mu = model.measurements_batch(mu, "mu")
    if mu.shape[-1] != 3 or process_noise > 0:
        if (reading, support) != ("derived", "front"):
            raise ValueError(
                "reading and support other than 'derived' and 'front' are readings of the "
                "paper's three-frame Eqs. (14)-(16); with more frames or process noise "
                f"the optimal filter has neither, got {reading!r} and {support!r}"
            )
        return posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise, rtol)
    if np.ndim(mu) == 1:
        return _triple(mu, rho, Gaussian.prior(prior_mean, prior_cov), reading, support, rtol)
    if (reading, support) == ("derived", "front"):
        return batch_marginals(mu, rho, prior_mean, prior_cov, rtol)
    return moments(mu, rho, prior_mean, prior_cov, reading, support, rtol)


def _gated(mu, rho, prior_mean, prior_cov, process_noise, rtol, steps, gate, law=None):
    """Bank and report on the bearings :func:`~depthcore.exact.online.track_updates` keeps
    (under ``law`` if given; without a gate, the bank alone)."""
    more = {"steps": steps, "law": law}
    post = posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise, rtol, **more)
    if gate is None:
        return post
    report = online.track_updates(post.bank, gate, rtol)
    if np.any(report.gated):
        b = post.bank
        kept = np.where(report.gated, np.nan, np.asarray(b.mu))
        more["steps"] = b.frame_steps
        post = posterior.posterior(
            kept, b.frame_noise, b.prior_mean, b.prior_cov, process_noise, rtol, **more
        )
    return dataclasses.replace(post, updates=report)


def _paper_only(reading, support) -> None:
    """Refuse a reading or support of Eqs. (14)-(16) for a track that is not the paper's."""
    if (reading, support) != ("derived", "front"):
        raise ValueError(
            "reading and support other than 'derived' and 'front' are readings of the "
            "paper's three-frame Eqs. (14)-(16); a track with gaps, noise per frame or "
            f"steps has neither, got {reading!r} and {support!r}"
        )


def _triple(
    mu,
    rho: float,
    prior: Gaussian,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
) -> OptimalMarginals:
    """Eqs. (13)-(16) for one triple ``mu`` (3,): :func:`run`'s :class:`OptimalMarginals`."""
    mu = model.measurements(mu)
    pb = _problem(mu, rho, prior.mean, prior.cov, reading)
    rtol = checks.positive_scalar(rtol, "rtol")
    m, err_y, err_v, top, grids = quadrature.integrate(pb, _intervals(support), rtol)
    log_z = float(np.log(m.Z[0]) + top[0])
    n_nodes = sum(int(g[2][0]) for g in grids.values())
    return OptimalMarginals(
        mu=mu,
        rho=float(rho),
        prior=prior,
        reading=reading,
        support=support,
        depth_mean=float(m.mean[0, 1]),
        depth_sd=float(np.sqrt(m.cov[0, 1, 1])),
        velocity_mean=float(m.mean[0, 2]),
        velocity_sd=float(np.sqrt(m.cov[0, 2, 2])),
        depth_error=float(err_y[0]),
        velocity_error=float(err_v[0]),
        prob_behind_camera=float(m.behind[0]),
        log_normaliser=log_z,
        n_nodes=int(n_nodes),
        mean=m.mean[0],
        cov=m.cov[0],
        _problem=pb,
        _grids=grids,
    )


@dataclass(frozen=True)
class BatchMarginals:
    """Optimal marginals of ``B`` problems (``y > 2``) with their CDFs and depth density.

    Attributes
    ----------
    moments : Moments
    log_normaliser : ndarray, shape (B,)
    rtol : float
        The tolerance of the moments and of :meth:`depth_cdf`.
    log_depth_range : tuple of ndarray
        Lower and upper ends (B,) of the range in ``t = log(y - 2)``, and a panel width (B,).
    prior : tuple of ndarray
        Mean (3,) or (B, 3) and covariance (3, 3) or (B, 3, 3), as given.
    """

    moments: Moments
    log_normaliser: np.ndarray
    rtol: float
    _problem: quadrature.Problem
    _grids: dict  # the quadrature's u grids: {interval: (lo, h, n, frame)}
    log_depth_range: tuple
    prior: tuple = None  # (prior_mean, prior_cov) as given

    @property
    def updates(self) -> predictive.Updates:
        """The :func:`~depthcore.exact.online.updates` of each bearing, shape (B, 3) each."""
        mean, cov = self.prior
        return online.updates(self._problem.mu, self._problem.rho, mean, cov)

    def depth_log_pdf(self, y) -> np.ndarray:
        """``log p_oy`` at depths ``y`` of shape (B, m); ``-inf`` at ``y <= 2``."""
        y = np.asarray(y, dtype=float)
        inside = y > 2
        safe = np.where(inside, y, 3.0)
        log_density = _solve(np.stack([safe, safe - 1, safe - 2], -1), self._problem)[0]
        return np.where(inside, log_density - self.log_normaliser[:, None], -np.inf)

    def depth_cdf(self, y) -> np.ndarray:
        """``P(depth <= y)``, ``y`` (B,), by :func:`depthcore.exact.cdf.gauss_legendre_cdf`."""
        y = checks.finite_array(y, "y")
        lo, h, _, frame = self._grids[3]
        step = 2.0 * h
        with np.errstate(divide="ignore"):
            t_up = np.log(np.maximum(y - 2.0, 0.0))
        u_up = frame.u(t_up)
        inside = u_up > lo
        hi = np.where(inside, u_up, lo + 1.0)

        def density(u):
            offsets, log_jac = modes.mapped_nodes(3, u.reshape(len(y), -1), frame)
            log_f = _solve(offsets, self._problem)[0] + log_jac - self.log_normaliser[:, None]
            return np.exp(log_f).reshape(u.shape)

        width = hi - lo
        panels = max(1, int(np.ceil(np.max(width / step))))
        cdf, settled, _ = gauss_legendre_cdf(
            density, lo, width, panels, self.rtol, max_nodes=4 * quadrature.NODE_BUDGET
        )
        if not settled:
            raise ValueError(
                f"y: the depth CDF did not reach rtol = {self.rtol:.3g} "
                f"within {4 * quadrature.NODE_BUDGET} nodes"
            )
        return np.where(inside, np.clip(cdf, 0.0, 1.0), 0.0)

    def velocity_cdf(self, v) -> np.ndarray:
        """``P(velocity <= v)``, ``v`` (B,), on :func:`_fine_velocity_mixture`'s nodes."""
        from scipy.special import ndtr

        v = checks.finite_array(v, "v")
        w, m, sd = _fine_velocity_mixture(self._problem, self._grids, self.log_normaliser)
        return np.sum(w * ndtr((v[:, None] - m) / sd), axis=1)


def batch_marginals(mu, rho, prior_mean, prior_cov, rtol: float = 1e-10) -> BatchMarginals:
    """Eqs. (13)-(16) for a batch, as :func:`moments` (derived, front); memory grows with ``B``."""
    pb = _problem(mu, rho, prior_mean, prior_cov, "derived")
    rtol = checks.positive_scalar(rtol, "rtol")
    m, err_y, err_v, top, grids = quadrature.integrate(pb, (3,), rtol)
    log_z = np.log(m.Z) + top
    moments_ = Moments(*m.key_moments(), err_y, err_v, m.behind, m.mean, m.cov)
    lo, h, n, frame = grids[3]
    t_ends = frame.t(np.stack([lo, lo + (n - 1) * h], 1))
    prior = (np.asarray(prior_mean, dtype=float), np.asarray(prior_cov, dtype=float))
    ranges = (t_ends[:, 0], t_ends[:, 1], 2.0 * h)
    return BatchMarginals(moments_, log_z, rtol, pb, grids, ranges, prior)


# --- pieces of the derivation of Eq. (16), and quantiles --------------------------------------


def eq16_printed(coefficients) -> np.ndarray:
    """Eq. (16) as printed: ``log(exp(l^T M^{-1} l / 8) / sqrt(det M))`` from ``A .. E``.

    ``coefficients`` (n, 5) are :func:`quadratic_coefficients`'s; returns (n,), without ``c``.
    """
    A, B, C, D, E = np.asarray(coefficients, dtype=float).T
    det_M = A * C - B**2 / 4.0  # Eq. (15): M = [[A, B/2], [B/2, C]]
    # l^T M^{-1} l with M^{-1} = [[C, -B/2], [-B/2, A]] / det M, l = (D, E)
    quad = (C * D**2 - B * D * E + A * E**2) / det_M
    return quad / 8.0 - 0.5 * np.log(det_M)


def prior_exponent(y, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """``K(y)``: the part of the exponent of (6) at depth ``y`` free of ``x`` and ``v``.

    (6) is ``-1/2 (A x**2 + B x v + C v**2 + D x + E v) - 1/2 K(y)`` + const; Eq. (14)
    leaves ``K`` out. ``y`` (n,), the rest as in :func:`log_posterior`; returns (n,).
    """
    y = np.atleast_1d(checks.finite_array(y, "y"))
    x = np.stack([np.zeros_like(y), y, np.zeros_like(y)], -1)
    return -2.0 * log_posterior(x, mu, rho, prior)


def depth_quantiles(m: OptimalMarginals, probs, n: int = 20001) -> np.ndarray:
    """Quantiles of the optimal depth marginal ``p_oy`` (support ``y > 2``).

    The trapezoid CDF on ``n`` points uniform in ``t = log(y - 2)`` from ``1e-4`` to
    ``50 (E y + 10 sd)``, inverted linearly at ``probs`` in (0, 1) (same shape out).
    """
    if m.support != "front":
        raise ValueError(f"depth_quantiles needs support='front', got {m.support!r}")
    probs = checks.finite_array(probs, "probs")
    if np.any((probs <= 0) | (probs >= 1)):
        raise ValueError(f"probs must lie in (0, 1), got {probs.tolist()}")
    t = np.linspace(np.log(1e-4), np.log(50.0 * (m.depth_mean + 10.0 * m.depth_sd)), n)
    d = np.exp(t)
    integrand = m.depth_pdf(2.0 + d) * d
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(t))])
    if not abs(cdf[-1] - 1.0) < 1e-6:
        raise RuntimeError(f"the depth marginal integrates to {cdf[-1]:.8f} on the grid, not 1")
    return np.interp(probs, cdf / cdf[-1], 2.0 + d)
