"""Weights of a particle sample: normalising, effective sample size, resampling, moments.

Recommended import: ``from depthcore.particles import resampling``.

Weights are kept as logarithms and normalised by log-sum-exp with the
maximum subtracted. Systematic, multinomial and residual resampling share the
signature ``resampler(W, rng, M=None) -> indices`` and are batched over the
leading axes of ``W`` [douc2005]_.

References
----------
.. [douc2005] R. Douc, O. Cappe and E. Moulines, "Comparison of resampling
   schemes for particle filtering", ISPA 2005 (multinomial, residual,
   stratified and systematic resampling).
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks, frames, model


def check_rng(rng):
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")


def track_problem(mu, rho, prior_mean, prior_cov, steps=None, triples: bool = False):
    """The particle filters' checks of a batch of tracks as they come, and of the prior.

    :func:`depthcore.problem.frames.check`; on regular frames also
    :func:`depthcore.problem.model.batch_inputs` with ``triples``.

    Parameters
    ----------
    mu : array_like, shape (..., N)
        ``NaN`` at a missing frame.
    rho : float or array_like, shape (...) or (..., N)
    prior_mean : array_like, shape (3,) or (..., 3)
    prior_cov : array_like, shape (3, 3) or (..., 3, 3)
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
    triples : bool

    Returns
    -------
    track : depthcore.problem.frames.Frames
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
        Read-only broadcast views.
    """
    if _as_always(mu, rho, steps):  # the paper's frames: the checks as they have always been
        mu, rho, prior_mean, prior_cov = model.batch_inputs(
            mu, rho, prior_mean, prior_cov, triples=triples
        )
        n = mu.shape[-1]
        row = np.broadcast_to(rho, mu.shape[:-1])[..., None]
        track = frames.Frames(
            mu,
            np.ones(mu.shape, dtype=bool),
            np.broadcast_to(row, mu.shape),
            np.broadcast_to(np.ones(max(n - 1, 0)), mu.shape[:-1] + (max(n - 1, 0),)),
        )
        return track, prior_mean, prior_cov
    track = frames.check(mu, rho, steps)
    if track.regular:
        _, _, prior_mean, prior_cov = model.batch_inputs(
            track.mu, track.row_rho, prior_mean, prior_cov, triples=triples
        )
    else:
        filled = np.where(track.present, track.mu, 0.0)
        _, _, prior_mean, prior_cov = model.batch_inputs(
            filled, 1.0, prior_mean, prior_cov, triples=False
        )
    return track, prior_mean, prior_cov


def _as_always(mu, rho, steps) -> bool:
    """No steps, no ``NaN`` bearing and no ``rho`` per frame: the paper's frames."""
    try:
        values = np.asarray(mu, dtype=float)
    except (TypeError, ValueError):
        return True
    per_frame = values.ndim >= 1 and np.ndim(rho) == values.ndim and np.ndim(rho) > 0
    return steps is None and not np.any(np.isnan(values)) and not per_frame


def _weights(W, M) -> tuple[np.ndarray, int]:
    """Check normalised weights ``W`` (..., N) and the number of draws ``M``."""
    W = checks.finite_array(W, "W")
    if W.ndim < 1 or W.shape[-1] < 1:
        raise ValueError(f"W must have shape (..., N) with N >= 1, got shape {W.shape}")
    if np.any(W < 0):
        raise ValueError(f"W must be non-negative, got minimum {float(W.min()):.3g}")
    total = W.sum(axis=-1)
    if np.any(np.abs(total - 1.0) > 1e-9):
        raise ValueError(f"W must sum to 1 along its last axis, got sums {np.unique(total)[:5]}")
    M = W.shape[-1] if M is None else checks.count(M, "M")
    return W / total[..., None], M


def _indices(counts) -> np.ndarray:
    """Indices ``(..., M)`` that repeat particle ``i`` ``counts[..., i]`` times (rows sum to M)."""
    counts = np.asarray(counts)
    *batch, N = counts.shape
    M = int(counts.reshape(-1, N)[0].sum()) if counts.size else 0
    flat = np.repeat(np.tile(np.arange(N), int(np.prod(batch, dtype=int))), counts.ravel())
    return flat.reshape(tuple(batch) + (M,))


def systematic(W, rng: np.random.Generator, M: int | None = None) -> np.ndarray:
    """Systematic resampling, batched over the leading axes of ``W``.

    One uniform ``U`` per row; the points ``(U + j) / M`` select particle ``i`` in
    ``[C_{i-1}, C_i)`` [douc2005]_: ``floor(M W_i)`` or ``ceil(M W_i)`` times.

    Parameters
    ----------
    W : array_like, shape (..., N)
        Normalised weights.
    rng : numpy.random.Generator
    M : int, optional
        Draws; ``N`` by default.

    Returns
    -------
    ndarray of int, shape (..., M)
        Sorted indices into the last axis of ``W``.
    """
    W, M = _weights(W, M)
    check_rng(rng)
    U = rng.random(W.shape[:-1])
    C = np.cumsum(W, axis=-1)
    C[..., -1] = 1.0
    # Points below C_i: #{j in 0..M-1 : j < M C_i - U} = clip(ceil(M C_i - U), 0, M).
    below = np.clip(np.ceil(M * C - U[..., None]), 0, M).astype(np.int64)
    return _indices(np.diff(below, axis=-1, prepend=0))


def multinomial(W, rng: np.random.Generator, M: int | None = None) -> np.ndarray:
    """Multinomial resampling: ``M`` independent draws from the weights, batched.

    Parameters and returns as :func:`systematic`; particle ``i`` is drawn
    ``M W_i`` times on average.
    """
    W, M = _weights(W, M)
    check_rng(rng)
    return _indices(rng.multinomial(M, W))


def residual(W, rng: np.random.Generator, M: int | None = None) -> np.ndarray:
    """Residual resampling, batched.

    ``floor(M W_i)`` copies, the rest multinomial on the residuals ``M W_i - floor(M
    W_i)`` [douc2005]_ (not filterpy's ``W_i - floor(N W_i)``, negative when copied).
    Parameters and returns as :func:`systematic`.
    """
    W, M = _weights(W, M)
    check_rng(rng)
    floor = np.floor(M * W)
    rest = M * W - floor
    R = M - floor.sum(axis=-1).astype(np.int64)
    total = rest.sum(axis=-1, keepdims=True)
    p = np.where(total > 0, rest / np.where(total > 0, total, 1.0), 1.0 / W.shape[-1])
    return _indices(floor.astype(np.int64) + rng.multinomial(R, p))


#: The resampling schemes by name (systematic is the default of the particle filters).
RESAMPLERS = {"systematic": systematic, "multinomial": multinomial, "residual": residual}


def metropolis(x, log_p, propose, target, moves: int, rng: np.random.Generator, carried=()):
    """Random-walk Metropolis-Hastings moves of every particle, batched.

    Each step proposes ``propose(x, eps)``, ``eps ~ N(0, I)``, and accepts with
    probability ``min(1, exp(target - log_p))``.

    Parameters
    ----------
    x : ndarray, shape (..., J) or (..., J, D)
    log_p : ndarray, shape (..., J)
        ``-inf`` outside the support.
    propose : callable
        ``propose(x, eps) -> proposal``.
    target : callable
        ``target(proposal) -> (log_p, carried)``, the arrays (..., J, ...) an
        accepted proposal brings.
    moves : int
    rng : numpy.random.Generator
    carried : tuple of ndarray

    Returns
    -------
    x, log_p, carried
    acceptance : ndarray, shape (...)
        NaN for ``moves = 0``.
    """
    accepted = np.zeros(log_p.shape[:-1])
    for _ in range(moves):
        proposal = propose(x, rng.standard_normal(x.shape))
        candidate, brought = target(proposal)
        with np.errstate(invalid="ignore"):
            ok = np.log(rng.random(log_p.shape)) < candidate - log_p
        x = _where(ok, proposal, x)
        carried = tuple(_where(ok, b, c) for b, c in zip(brought, carried, strict=True))
        log_p = np.where(ok, candidate, log_p)
        accepted += ok.mean(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return x, log_p, carried, accepted / moves if moves else np.full(accepted.shape, np.nan)


def _where(ok, new, old):
    """``new`` where ``ok`` (..., J), else ``old``; trailing axes of the arrays broadcast."""
    new = np.asarray(new)
    return np.where(ok.reshape(ok.shape + (1,) * (new.ndim - ok.ndim)), new, old)


def effective_sample_size(log_w) -> np.ndarray:
    """Kish's effective sample size ``1 / sum_i W_i**2`` from (unnormalised) log weights.

    ``log_w`` (..., N); returns (...), between 1 and ``N``.
    """
    from scipy.special import logsumexp

    log_w = np.asarray(log_w, dtype=float)
    return np.exp(2.0 * logsumexp(log_w, axis=-1) - logsumexp(2.0 * log_w, axis=-1))


def weighted_moments(x, W) -> tuple[np.ndarray, np.ndarray]:
    """Weighted means and SDs of ``x`` (..., N) with weights ``W`` (..., N)."""
    mean = np.sum(W * x, axis=-1)
    return mean, np.sqrt(np.sum(W * (x - mean[..., None]) ** 2, axis=-1))


def state_moments(particles, log_weights) -> dict:
    """Weighted depth and velocity means and SDs of particles of the state ``(x, y, v)``.

    ``particles`` (..., N, 3), normalised ``log_weights`` (..., N); returns a dict of
    ``depth_mean``, ``depth_sd``, ``velocity_mean``, ``velocity_sd``, each (...).
    """
    W = np.exp(log_weights)
    out = {}
    for name, i in (("depth", 1), ("velocity", 2)):
        out[f"{name}_mean"], out[f"{name}_sd"] = weighted_moments(particles[..., i], W)
    return out


def weighted_standard_errors(x, W) -> tuple[np.ndarray, np.ndarray]:
    """Delta-method standard errors of the weighted mean and SD of ``x`` (..., N).

    For self-normalised weights the mean ``m = sum W x`` has variance about
    ``sum W**2 (x - m)**2``, and the variance ``s2 = sum W (x - m)**2`` about
    ``sum W**2 ((x - m)**2 - s2)**2``; the SD's standard error is that of
    ``s2`` over ``2 s``.
    """
    mean, sd = weighted_moments(x, W)
    d2 = (x - mean[..., None]) ** 2
    se_mean = np.sqrt(np.sum(W**2 * d2, axis=-1))
    se_var = np.sqrt(np.sum(W**2 * (d2 - sd[..., None] ** 2) ** 2, axis=-1))
    # All the weight on one value (a collapsed filter): the SD's error is unknown.
    with np.errstate(divide="ignore", invalid="ignore"):
        return se_mean, np.where(sd > 0, se_var / (2.0 * sd), np.inf)


#: A cloud worth fewer independent draws of the posterior than this has collapsed.
MIN_EFFECTIVE_DRAWS = 10.0


def replica_errors(estimates, within_sd, axis: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """Monte Carlo error of the average of ``R`` independent replicas' estimates, and collapse.

    The error is ``s / sqrt(R)`` (``s`` the replicas' SD, ``ddof = 1``) widened by
    ``t_{R-1}(0.975) / z(0.975)``, so the estimate lies within 1.96 errors of the exact
    value in 95 % of runs. A replica is worth ``n_eff = within_sd**2 / s**2`` draws;
    below :data:`MIN_EFFECTIVE_DRAWS` (or with no spread) the replicas have collapsed
    and the error is NaN.

    Parameters
    ----------
    estimates : array_like, shape (..., R, ...)
        Replicas along ``axis``.
    within_sd : array_like, same shape
        Each replica's own posterior SD.
    axis : int

    Returns
    -------
    error : ndarray
        The estimates' shape without ``axis``; NaN where collapsed or ``R < 2``.
    collapsed : ndarray of bool
        Same shape; false with ``R < 2`` (no spread to judge by).
    """
    from scipy import stats

    estimates = np.asarray(estimates, dtype=float)
    within = np.mean(np.asarray(within_sd, dtype=float) ** 2, axis=axis)
    R = estimates.shape[axis]
    if R < 2:
        shape = within.shape
        return np.full(shape, np.nan), np.zeros(shape, dtype=bool)
    spread = np.var(estimates, axis=axis, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        collapsed = ~(within >= MIN_EFFECTIVE_DRAWS * spread) | ~(within > 0)
    factor = stats.t.ppf(0.975, R - 1) / stats.norm.ppf(0.975)
    error = factor * np.sqrt(spread / R)
    return np.where(collapsed, np.nan, error), collapsed


def weighted_mean_and_cov(x, W) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (..., d) and covariance (..., d, d) of points ``x`` (..., N, d).

    ``W`` (..., N) are normalised weights.
    """
    mean = np.einsum("...n,...ni->...i", W, x)
    d = x - mean[..., None, :]
    return mean, np.einsum("...n,...ni,...nj->...ij", W, d, d)


def weighted_density(x, W, grid, method: str = "kde", bandwidth: float | None = None) -> np.ndarray:
    """Weighted density estimate of the sample ``x`` with weights ``W`` on ``grid``.

    Parameters
    ----------
    x, W : ndarray, shape (N,)
    grid : array_like, shape (G,)
        Increasing; evenly spaced bin centres for ``"histogram"``.
    method : {"kde", "histogram"}
    bandwidth : float, optional
        The kernel SD; default Silverman's ``0.9 min(sd, IQR / 1.34) ESS**(-1/5)``.

    Returns
    -------
    ndarray, shape (G,)
    """
    grid = checks.finite_array(grid, "grid")
    if grid.ndim != 1 or grid.size < 2 or not np.all(np.diff(grid) > 0):
        raise ValueError(f"grid must be increasing with at least 2 points, got shape {grid.shape}")
    if method == "histogram":
        step = np.diff(grid)
        if not np.allclose(step, step[0], rtol=1e-9, atol=0):
            raise ValueError("grid must be evenly spaced for method='histogram'")
        edges = np.concatenate([grid - step[0] / 2, grid[-1:] + step[0] / 2])
        return np.histogram(x, bins=edges, weights=W)[0] / step[0]
    if method != "kde":
        raise ValueError(f"method must be 'kde' or 'histogram', got {method!r}")
    if bandwidth is None:
        h = _silverman(x, W)
    else:
        h = checks.positive_scalar(bandwidth, "bandwidth")
    keep = W > 0
    z = (grid[:, None] - x[keep]) / h
    return np.exp(-0.5 * z**2) @ W[keep] / (np.sqrt(2.0 * np.pi) * h)


def _silverman(x, W) -> float:
    """Silverman's bandwidth ``0.9 min(sd, IQR / 1.34) n**(-1/5)`` with weights (n the ESS)."""
    order = np.argsort(x)
    cdf = np.cumsum(W[order])
    q1, q3 = np.interp([0.25, 0.75], cdf - W[order] / 2, x[order])
    sd = float(weighted_moments(x, W)[1])
    spread = min(sd, (q3 - q1) / 1.34) if q3 > q1 else sd
    if not spread > 0:
        raise ValueError("the particles have a single distinct value: pass bandwidth")
    return 0.9 * spread * (1.0 / np.sum(W**2)) ** -0.2
