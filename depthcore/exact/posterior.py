"""The exact filter for ``N`` frames with its depth nodes placed by the quadrature.

Recommended import: ``from depthcore.exact import posterior``.

The filter bank (:mod:`depthcore.exact.bank`) is exact given its depth nodes; here
the nodes are placed by the optimal filter's robust depth quadrature
(:mod:`depthcore.exact.quadrature`, Eqs. (14)-(16) generalised to ``N`` frames and
process noise): :func:`moments` integrates the posterior moments with error
estimates, :func:`posterior` returns the mixture
(:class:`~depthcore.exact.mixture.Mixture`) on the placed nodes, and
:func:`update` adds one bearing online, re-placing the nodes only when the
posterior has moved off them. :func:`node_density` gives the posterior depth
density at a posterior's nodes.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from depthcore.exact import panels, quadrature
from depthcore.exact.bank import Bank, lateral_filter, run_bank, step
from depthcore.exact.mixture import Mixture, Moments, mixture, mixture_of_log_weights
from depthcore.kalman import linear
from depthcore.problem import checks, frames, model, signature
from depthcore.problem.depth_prior import stand_in

# --- nodes placed by the depth quadrature ----------------------------------------------

#: Most frames of a problem (the filters' common limit).
MAX_FRAMES = checks.MAX_FRAMES


def _quadrature_problem(mu, rho, prior_mean, prior_cov, process_noise):
    """The checked inputs as :class:`depthcore.exact.quadrature.Problem`, and the batch shape."""
    mu, rho, prior_mean, prior_cov = model.batch_inputs(
        mu, rho, prior_mean, prior_cov, triples=False
    )
    if mu.shape[-1] > MAX_FRAMES:
        raise ValueError(f"mu: at most {MAX_FRAMES} frames, got {mu.shape[-1]}")
    batch, N = mu.shape[:-1], mu.shape[-1]
    q = checks.nonnegative_batch(process_noise, "process_noise", batch)
    B = int(np.prod(batch))
    rho = np.broadcast_to(rho, batch).reshape(B)
    return _flat_problem(mu.reshape(B, N), rho, prior_mean, prior_cov, q, batch), batch


def _flat_problem(mu, rho, prior_mean, prior_cov, q, batch, steps=None, frame_rho=None):
    """``B`` quadrature problems, ``mu`` (B, N) and ``rho`` (B,), the prior and ``q`` broadcast
    to ``batch`` and flattened."""
    B = mu.shape[0]
    prior_cov = np.ascontiguousarray(np.broadcast_to(prior_cov, batch + (3, 3))).reshape(B, 3, 3)
    return quadrature.Problem(
        mu=mu,
        rho=rho,
        mean=np.broadcast_to(prior_mean, batch + (3,)).reshape(B, 3),
        R=np.linalg.inv(np.linalg.cholesky(prior_cov)),
        reading="derived",
        process_noise=np.broadcast_to(q, batch).reshape(B),
        cov=prior_cov,
        integrand=_integrand,
        steps=steps,
        frame_rho=frame_rho,
    )


def irregular(mu, rho, steps) -> bool:
    """Whether a track is not the paper's frames: gaps, noise per frame or steps given."""
    mu_arr = np.asarray(mu)
    if steps is not None:
        return True
    if mu_arr.dtype.kind == "f" and np.any(np.isnan(mu_arr)):
        return True
    return np.ndim(rho) >= 1 and np.shape(rho) == mu_arr.shape


def frames_problem(track: frames.Frames, prior_mean, prior_cov, process_noise):
    """A checked track (:func:`depthcore.problem.frames.check`) as ``B`` quadrature problems.

    Unit steps become ``None`` and equal noise ``rho`` per row. Returns the
    :class:`depthcore.exact.quadrature.Problem` and the track's batch shape.
    """
    mu = track.mu
    if mu.shape[-1] > MAX_FRAMES:
        raise ValueError(f"mu: at most {MAX_FRAMES} frames, got {mu.shape[-1]}")
    batch, N = mu.shape[:-1], mu.shape[-1]
    B = int(np.prod(batch))
    prior_mean = checks.finite_array(prior_mean, "prior_mean")
    if prior_mean.shape[-1:] != (3,) or not checks.broadcasts(prior_mean.shape[:-1], batch):
        raise ValueError(f"prior_mean must have shape (3,) or (..., 3), got {prior_mean.shape}")
    prior_cov = checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.shape[-2:] != (3, 3) or not checks.broadcasts(prior_cov.shape[:-2], batch):
        raise ValueError(f"prior_cov must have shape (3, 3) or (..., 3, 3), got {prior_cov.shape}")
    prior_cov = checks.covariances(prior_cov, "prior_cov", 3)
    q = checks.nonnegative_batch(process_noise, "process_noise", batch)
    rho = np.ascontiguousarray(track.rho).reshape(B, N)
    per_row = np.all(np.where(track.present.reshape(B, N), rho, rho[:, :1]) == rho[:, :1])
    steps = np.ascontiguousarray(track.steps).reshape(B, N - 1)
    pb = _flat_problem(
        np.ascontiguousarray(mu).reshape(B, N),
        rho[:, 0] if per_row else np.max(np.where(np.isnan(mu.reshape(B, N)), 0, rho), 1),
        prior_mean,
        prior_cov,
        q,
        batch,
        steps=None if np.all(steps == 1.0) else steps,
        frame_rho=None if per_row else rho,
    )
    return pb, batch


def _problem_of(mu, rho, prior_mean, prior_cov, process_noise, steps):
    """The quadrature Problem of a track or a batch, the paper's frames or not; and the batch."""
    if irregular(mu, rho, steps):
        return frames_problem(frames.check(mu, rho, steps), prior_mean, prior_cov, process_noise)
    return _quadrature_problem(mu, rho, prior_mean, prior_cov, process_noise)


def _integrand(offsets, pb):
    """The depth quadrature's integrand: :func:`~depthcore.exact.bank.lateral_filter` at ``y_1 =
    offsets[..., 2] + floor``.

    The quadrature's depth is the distance above the floor (:attr:`Problem.floor
    <depthcore.exact.quadrature.Problem.floor>`), the depth where the point comes nearest
    the camera: its log transform then resolves the kink the density has there.
    """
    return lateral_filter(
        offsets[..., 2] + pb.floor[:, None],
        pb.mu,
        pb.rho,
        pb.process_noise,
        pb.mean,
        pb.cov,
        pb.steps,
        pb.frame_rho,
    )


def _integrate(pb, rtol: float):
    """The quadrature of :mod:`depthcore.exact.quadrature` on ``y_1 > 0``, moments of ``y_N``.

    The quadrature reports the depth as ``y_1 - floor + 2``; at frame ``N`` it is
    ``y_1 + N - 1`` (the travelled depth ``e_N`` for steps).
    """
    m, err_y, err_v, top, grids = quadrature.integrate(pb, (3,), rtol)
    mean = m.mean.copy()
    if pb.steps is None:
        mean[:, 1] += pb.mu.shape[1] - 3
    else:
        mean[:, 1] += pb.floor + np.sum(pb.steps, axis=1) - 2.0
    err_y = np.maximum(err_y, 64.0 * np.finfo(float).eps * np.abs(mean[:, 1]))
    return m._replace(mean=mean), err_y, err_v, top, grids


@signature.documented
def moments(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    rtol: float = 1e-10,
    chunk: int = 64,
    steps=None,
) -> Moments:
    """The exact posterior moments at frame ``N``, with the depth nodes placed by quadrature.

    :mod:`depthcore.exact.quadrature` of ``N(y_1; m_y, P_yy) L(y_1)`` in ``t = log(y_1)``,
    with :func:`~depthcore.exact.bank.lateral_filter` at each node.

    {parameters}
    rtol, chunk
        As for :func:`depthcore.exact.optimal.moments`.

    Returns
    -------
    depthcore.exact.mixture.Moments
        Arrays of shape (B,) (``(1,)`` for one problem) at frame ``N``.

    Raises
    ------
    ValueError
        For invalid inputs or a tolerance out of reach.
    """
    mu2 = np.atleast_2d(mu) if np.ndim(mu) == 1 else mu
    rho2 = np.atleast_2d(rho) if np.ndim(mu) == 1 and np.shape(rho) == np.shape(mu) else rho
    pb, _ = _problem_of(mu2, rho2, prior_mean, prior_cov, process_noise, steps)
    rtol = checks.positive_scalar(rtol, "rtol")
    chunk = checks.count(chunk, "chunk")
    out, means, covs = [], [], []
    for start in range(0, pb.mu.shape[0], chunk):
        m, err_y, err_v, _, _ = _integrate(pb.take(slice(start, start + chunk)), rtol)
        out.append(np.concatenate([m.key_moments(), [err_y, err_v, m.behind]]))
        means.append(m.mean)
        covs.append(m.cov)
    return Moments(*np.concatenate(out, axis=1), np.concatenate(means), np.concatenate(covs))


def grid_nodes(grid):
    """Depths at frame 1 (B, J) and log quadrature weights (B, J) of a quadrature grid.

    ``grid = (lo, h, n, frame)`` as :func:`depthcore.exact.quadrature.integrate`'s;
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
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    rtol: float = 1e-10,
    history: bool = False,
    steps=None,
    law=None,
) -> Mixture:
    """The exact posterior at frame ``N`` as a bank on nodes placed by the depth quadrature.

    The nodes are the last level of :func:`moments`'s quadrature, so the mixture's
    moments are those and carry their error estimates.

    Parameters
    ----------
    mu : array_like, shape (N,) or (B, N)
    rho, prior_mean, prior_cov, process_noise, rtol
        As for :func:`moments`.
    history : bool
        Keep each node's filter at every frame (for
        :meth:`~depthcore.exact.mixture.Mixture.smoothed`).
    steps : array_like, shape (N - 1,) or (B, N - 1), or None
        With steps, ``NaN`` bearings or ``rho`` per frame the track is checked by
        :func:`depthcore.problem.frames.check`.
    law : depthcore.problem.depth_prior.DepthPrior, optional
        A prior whose depth law need not be Gaussian, in place of ``prior_mean`` and
        ``prior_cov`` (``None`` both, or its own :meth:`gaussian
        <depthcore.problem.depth_prior.DepthPrior.gaussian>`); its nodes are placed by
        :func:`depthcore.exact.panels.place`.

    Returns
    -------
    Mixture
        Batch shape ``()`` for ``mu`` of shape ``(N,)``, ``(B,)`` otherwise.
    """
    single = np.ndim(mu) == 1
    mu2 = np.atleast_2d(mu) if single else mu
    rho2 = np.atleast_2d(rho) if single and np.shape(rho) == np.shape(mu) else rho
    if law is not None:
        prior_mean, prior_cov = stand_in(law, prior_mean, prior_cov)
    pb, _ = _problem_of(mu2, rho2, prior_mean, prior_cov, process_noise, steps)
    rtol = checks.positive_scalar(rtol, "rtol")
    return _place(pb, rtol, history, single, law)


#: Problems placed together by the quadrature (its memory grows with this times its nodes).
_CHUNK = 64


def _place(pb, rtol, history, single, law=None):
    B = pb.mu.shape[0]
    if B > _CHUNK:
        parts = [
            _place(pb.take(slice(i, i + _CHUNK)), rtol, history, False, law)
            for i in range(0, B, _CHUNK)
        ]
        return _concatenate(parts)
    if law is not None:
        return _place_law(pb, rtol, history, single, law)
    _, err_y, err_v, _, grids = _integrate(pb, rtol)
    nodes, log_w = grid_nodes(grids[3])
    nodes = nodes + pb.floor[:, None]
    shift = np.max(log_w, axis=1, keepdims=True)
    rho = pb.rho if pb.frame_rho is None else pb.frame_rho
    bank = run_bank(
        nodes, pb.mu, rho, pb.process_noise, pb.mean, pb.cov, history, pb.steps, pb.frame_rho
    )
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


def _place_law(pb, rtol, history, single, law):
    """:func:`_place` under a prior ``law``, its nodes from :func:`panels.place`."""
    placed = panels.place(panels.of_problems(pb, law), law, rtol)
    shift = np.max(placed.log_weights, axis=1, keepdims=True)
    rho = pb.rho if pb.frame_rho is None else pb.frame_rho
    bank = run_bank(
        placed.nodes,
        pb.mu,
        rho,
        pb.process_noise,
        pb.mean,
        pb.cov,
        history,
        pb.steps,
        pb.frame_rho,
        law,
    )
    post = mixture(bank, np.exp(placed.log_weights - shift))
    post = dataclasses.replace(
        post,
        log_weights=post.log_weights + shift,
        log_normaliser=post.log_normaliser + shift[:, 0],
        depth_error=placed.depth_error,
        velocity_error=placed.velocity_error,
        rtol=rtol,
    )
    return _squeeze(post) if single else post


def _concatenate(parts) -> Mixture:
    """Batches of placed posteriors joined along the batch, their nodes padded to one count.

    A padded node has weight 0, so the fields are joined, not recomputed.
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
        process_noise=np.concatenate([b.process_noise for b in banks]),
        prior_mean=np.concatenate([b.prior_mean for b in banks]),
        prior_cov=np.concatenate([b.prior_cov for b in banks]),
        frame_steps=np.concatenate([b.frame_steps for b in banks]),
        frame_noise=np.concatenate([b.frame_noise for b in banks]),
        law=banks[0].law,  # one law for the batch
        history=None
        if banks[0].history is None
        else linear.FilterResult(
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
    history = None if b.history is None else linear.FilterResult(*(take(a) for a in b.history))
    return Mixture(
        Bank(*(take(a) for a in b[:-2]), history, b.law),
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


def _resolution(post: Mixture, halved_mean, halved_cov, top):
    """The error of the moments on the placed nodes and its roundoff floor, each (2, B).

    The moments on every other node (``halved_mean`` (B, 3), ``halved_cov`` (B, 3, 3))
    against all, as :func:`depthcore.exact.quadrature.halving_error`; ``top`` (B, 1) is
    the largest log probability of a node.
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
    """``a`` padded with ``value`` along ``axis`` (from the batch's end) to ``J``, or ``a``."""
    if a.shape[axis] == J:
        return a
    width = [(0, 0)] * a.ndim
    width[axis] = (0, J - a.shape[axis])
    return np.pad(a, width, constant_values=value)


#: A node holding this much of the probability or more does not resolve the posterior.
_ONE_NODE = 0.5


def update(post: Mixture, mu_next, rho=None, step=1.0, gaps: bool = False) -> Mixture:
    """Add frame ``N + 1`` to a posterior from :func:`posterior`, online.

    Every node's filter and weight is updated (:func:`~depthcore.exact.bank.step`);
    a problem whose nodes no longer resolve the posterior (:func:`_resolution`) has
    them re-placed from all ``N + 1`` bearings, rarely, so the cost per frame stays flat.
    Under a prior's law (:attr:`Bank.law <depthcore.exact.bank.Bank.law>`), whose panel
    nodes the halving check does not apply to, every frame re-places them, at a cost
    that grows with ``N``.

    Parameters
    ----------
    post : Mixture
        From :func:`posterior` or :func:`update`.
    mu_next : float or array_like, shape (B,)
    rho, step, gaps
        As for :func:`depthcore.exact.bank.step`.

    Returns
    -------
    Mixture
        After ``N + 1`` frames, with error estimates.
    """
    if not isinstance(post, Mixture) or post.rtol is None:
        raise ValueError(
            "post must be a Mixture from bank_posterior.posterior or bank_posterior.update"
        )
    single = post.log_normaliser.ndim == 0
    if single:
        post = _batch_of_one(post)
    mu_next = checks.as_float(mu_next, "mu_next")
    if not np.all(np.isfinite(mu_next) | (gaps & np.isnan(mu_next))):
        raise ValueError("mu_next must be finite (or NaN for a missing frame, with gaps=True)")
    if mu_next.ndim > 1 or (mu_next.ndim == 1 and mu_next.shape != post.log_normaliser.shape):
        raise ValueError(
            f"mu_next must be a scalar or have shape {post.log_normaliser.shape}, "
            f"got shape {mu_next.shape}"
        )
    if post.bank.frames >= MAX_FRAMES:
        raise ValueError(f"mu_next: at most {MAX_FRAMES} frames")
    frame = {"rho": rho, "step": step, "gaps": gaps}
    new, err, floor, free = _step_rows(
        post, np.broadcast_to(mu_next, post.log_normaliser.shape), frame
    )
    rtol = post.rtol
    ok = (
        free
        & (err[0] <= np.maximum(rtol * new.depth_sd, floor[0]))
        & (err[1] <= np.maximum(rtol * new.velocity_sd, floor[1]))
        # a posterior narrower than the step sits on one node
        & (np.max(new.probabilities, axis=-1) < _ONE_NODE)
    )
    new = dataclasses.replace(new, depth_error=err[0], velocity_error=err[1], rtol=rtol)
    if post.bank.law is not None:
        # panel nodes have no every-other-node check: under a law they are placed afresh
        ok = np.zeros_like(ok)
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


def _step_rows(post: Mixture, mu_next, frame=None):
    """:func:`~depthcore.exact.bank.step`, the mixture and :func:`_resolution`, block by block.

    The same numbers as the whole batch, with the temporaries in cache. ``post`` (B,),
    ``mu_next`` (B,), ``frame`` :func:`update`'s ``rho, step, gaps`` or ``None``.
    Returns the mixture (no error estimates), ``err, floor`` (2, B) and ``free`` (B,).
    """
    B, J = post.log_weights.shape
    # the history grows along the frames, not by blocks: one block
    blocks = _row_blocks(B, J) if post.bank.history is None else [slice(None)]
    parts = []
    for rows in blocks:
        part = post if len(blocks) == 1 else _each_array(post, lambda a, rows=rows: a[rows])
        new, halved_mean, halved_cov, top, free = mixture_of_log_weights(
            step(part.bank, mu_next[rows], **_frame_rows(frame, rows)),
            part.log_weights,
            halved=True,
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


def _frame_rows(frame, rows) -> dict:
    """:func:`~depthcore.exact.bank.step`'s frame keywords for the problems ``rows``."""
    if frame is None:
        return {}
    return {k: v[rows] if np.ndim(v) == 1 else v for k, v in frame.items()}


def _replace_rows(post: Mixture, rows, own: bool = False) -> Mixture:
    """``post`` with the problems at ``rows`` (B,) re-placed by the quadrature.

    With ``own``, ``post``'s node arrays are overwritten where they keep their shape.
    """
    b = post.bank
    idx = np.flatnonzero(rows)
    fr = b.frame_rho
    pb = quadrature.Problem(
        mu=b.mu[idx],
        rho=np.broadcast_to(b.rho, rows.shape)[idx] if fr is None else np.max(fr[idx], axis=1),
        mean=b.prior_mean[idx],
        R=np.linalg.inv(np.linalg.cholesky(b.prior_cov[idx])),
        reading="derived",
        process_noise=np.broadcast_to(b.process_noise, rows.shape)[idx],
        cov=b.prior_cov[idx],
        integrand=_integrand,
        steps=None if b.steps is None else b.steps[idx],
        frame_rho=None if fr is None else fr[idx],
    )
    fresh = _place(pb, post.rtol, b.history is not None, False, b.law)
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

    ``p_j / eta_j`` with ``p_j`` the node's probability and ``eta_j`` its quadrature
    weight. Returns ``depths`` ``y_j + N - 1`` and the ``density`` there, (..., J) each
    (0 at padding).
    """
    if not isinstance(post, Mixture):
        raise ValueError(f"post must be a Mixture, got {type(post).__name__}")
    b = post.bank
    log_density = b.log_weight - post.log_normaliser[..., None]
    density = np.where(np.isfinite(post.log_weights), np.exp(log_density), 0.0)
    travelled = b.frames - 1 if b.steps is None else b.travelled[..., None]
    depths = np.broadcast_to(b.nodes, density.shape) + travelled
    return depths, density
