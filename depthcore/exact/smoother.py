"""One track frame by frame with the exact filter: filtered, fixed-lag and fixed-interval smoothed.

Recommended import: ``from depthcore.exact import smoother``.

:func:`track` adds the bearings of one track one at a time
(:func:`depthcore.exact.posterior.update`) and returns the filtered state at
every frame, the fixed-interval and fixed-lag smoothed states (textbook
19.2.6, each depth node's Rauch-Tung-Striebel smoother mixed over the nodes)
and the posterior after each bearing.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.2 (the Kalman filter and its smoothers).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.exact.bank import PSI
from depthcore.exact.mixture import Smoothed, mixture_moments
from depthcore.exact.posterior import posterior, update
from depthcore.exact.tracks import transitions
from depthcore.kalman import linear
from depthcore.problem import checks, frames


class Track(NamedTuple):
    """The state at every frame of one track, filtered and smoothed (:func:`track`).

    Each series is a :class:`~depthcore.exact.mixture.Smoothed`: means (N, 3) and covariances (N, 3,
    3) of
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


def track(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    lag: int = 2,
    rtol: float = 1e-10,
    steps=None,
    law=None,
):
    """The exact filter and its smoothers (textbook 19.2.6) at every frame of one track.

    The bearings arrive one at a time: the posterior after ``mu_1`` is placed
    by :func:`~depthcore.exact.posterior.posterior` and each later bearing is added by
    :func:`~depthcore.exact.posterior.update`
    (online). At frame ``k``:

    * the filtered state is the mixture of the nodes' Kalman filters
      (``Mixture.mean``, ``Mixture.cov`` after ``mu_k``);
    * the fixed-interval smoothed state is :meth:`~depthcore.exact.mixture.Mixture.smoothed` of the
      posterior after all ``N`` bearings (each node's Rauch-Tung-Striebel
      smoother, mixed);
    * the fixed-lag smoothed state uses ``mu_1 .. mu_t``, ``t = min(k + lag, N)``:
      on the nodes of the posterior after ``mu_t``, each node's Gaussian of
      ``(x_k, v_k)`` given ``mu_1 .. mu_t`` is the Rauch-Tung-Striebel backward
      recursion (textbook 19.2.6) over the window, run from the node's filtered
      Gaussian at frame ``t`` back to frame ``k``; it equals the textbook's
      fixed-lag smoother in its state-augmentation form (the filter on the
      state augmented with its ``lag`` predecessors,
      :func:`depthcore.kalman.linear.fixed_lag_smoother`). The nodes' Gaussians are
      mixed with that posterior's probabilities, the depth being
      ``y_1 + k - 1`` at each node.

    Cost. The frames whose ``t`` share a set of nodes (:func:`~depthcore.exact.posterior.update`
    keeps
    them until it re-places them) are smoothed together: each node's Kalman
    filter is run once over the bearings, keeping its filtered and predicted
    Gaussians at every frame, and the backward steps are taken for all those
    frames and nodes at once, each frame's chain starting at its own ``t`` and
    stopping at ``k``. The cost is ``O(N)`` per set of nodes (and so per
    re-placement, as in :func:`~depthcore.exact.posterior.update`) and ``O(lag)`` per frame (at most
    ``lag`` steps on 2 x 2 covariances); the augmented filter would cost
    ``O(lag**3)`` per frame (its covariance has side ``2 (lag + 1)``).

    A track as it comes: ``NaN`` bearings are missing frames (the filters
    predict through them), ``rho`` may be given per frame (shape ``(N,)``) and
    ``steps`` are the depth's changes between frames (the motion of
    :mod:`depthcore.problem.frames`); the smoothers run each node's
    Rauch-Tung-Striebel recursion with the transition ``[[1, s_k], [0, 1]]``
    of each step. The first bearing must be present (the nodes are first
    placed on the posterior after it).

    Parameters
    ----------
    mu : array_like, shape (N,)
        The bearings of one track, ``N >= 1``; ``NaN`` at a missing frame.
    rho : float or array_like, shape (N,)
        The noise SD, one or per frame (any value at a missing frame).
    prior_mean, prior_cov, process_noise, rtol
        As for :func:`~depthcore.exact.posterior.posterior` (one problem).
    steps : array_like, shape (N - 1,), or None
        The depth's signed change between frames, nonzero (negative: the camera
        approaches; ``None``: ones).
    lag : int
        The fixed-lag smoother's delay in frames, >= 0 (0: the filter; from
        ``N - 1`` on, the fixed-interval smoother, which is what it then is).
    law : depthcore.problem.depth_prior.DepthPrior, optional
        A prior whose depth law need not be Gaussian, as
        :func:`~depthcore.exact.posterior.posterior` takes it.

    Returns
    -------
    Track
    """
    raw = checks.as_float(mu, "mu")
    if raw.ndim != 1 or raw.size < 1:
        raise ValueError(f"mu must have shape (N,) with N >= 1 (one track), got shape {raw.shape}")
    lag = checks.nonnegative_count(lag, "lag")
    mu = raw
    per_frame, step_list = _frames(mu, rho, steps)
    if np.isnan(mu[0]):
        raise ValueError("mu[0] must be present: the track's first frame needs a bearing")
    present = int(np.sum(~np.isnan(mu)))
    if np.any(np.isinf(mu)) or (present < mu.size and present < frames.MIN_PRESENT):
        raise ValueError(
            f"mu must be finite, or NaN at missing frames with at least {frames.MIN_PRESENT} "
            f"bearings present; got {present} present and {int(np.sum(np.isinf(mu)))} infinite"
        )
    first_rho = rho if per_frame is None else per_frame[0]
    posts = [posterior(mu[:1], first_rho, prior_mean, prior_cov, process_noise, rtol, law=law)]
    for k in range(1, mu.size):
        if per_frame is None and step_list is None and not np.isnan(mu[k]):
            posts.append(update(posts[-1], mu[k]))
        else:
            posts.append(
                update(
                    posts[-1],
                    mu[k],
                    rho=None if per_frame is None else per_frame[k],
                    step=1.0 if step_list is None else step_list[k - 1],
                    gaps=True,
                )
            )
    filtered = Smoothed(np.stack([p.mean for p in posts]), np.stack([p.cov for p in posts]))
    interval = posts[-1].smoothed()
    # a delay reaching the last bearing from every frame: each frame is read from the
    # posterior after all N bearings, i.e. the fixed-interval smoother
    lagged = interval if lag >= mu.size - 1 else _lagged(posts, lag)
    return Track(filtered, interval, lagged, lag, tuple(posts))


def _frames(mu, rho, steps):
    """Noise per frame (N,) or ``None`` (one ``rho``), and steps (N - 1,) or ``None``."""
    per_frame = None
    if np.ndim(rho) > 0:
        r = checks.as_float(rho, "rho")
        if r.shape != mu.shape:
            raise ValueError(f"rho must be a number or have shape {mu.shape}, got shape {r.shape}")
        r = np.where(np.isnan(mu), 1.0, r)
        if not np.all(np.isfinite(r) & (r > 0)):
            raise ValueError("rho must be finite and positive at every present frame")
        per_frame = r
    if steps is None:
        return per_frame, None
    s = checks.finite_array(steps, "steps")
    if s.shape != (mu.size - 1,):
        raise ValueError(f"steps must have shape ({mu.size - 1},), got shape {s.shape}")
    if np.any(s == 0):
        raise ValueError("steps must be nonzero (the depth's signed change), got a zero step")
    return per_frame, s


def _lagged(posts, lag: int) -> Smoothed:
    """The fixed-lag smoothed state at every frame of :func:`track` (see there), 0-based.

    Frame ``s + 1`` is read from the posterior after ``mu_{t + 1}``,
    ``t = min(s + lag, N - 1)``. The frames ``t`` are split into runs whose
    posteriors share their nodes; the frames ``s`` read from a run are smoothed
    from that run's nodes' filters: every chain starts at the filtered
    Gaussian at its own ``t`` and takes the backward steps of textbook 19.2.6
    (:func:`depthcore.kalman.linear.smoother_step`, each frame's gain computed once)
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
        h = b.rerun(b.nodes, history=True).history
        Psi = PSI if b.steps is None else transitions(b.steps)[None]  # (1, N - 1, 2, 2)
        s = np.arange(first, last)
        t = np.minimum(s + lag, N - 1)
        mean, cov = h.means[:, t, :], h.covs[:, t, :, :]  # (J, frames, ...): at each t
        # the gain at frame k serves every chain through k: one per frame and node
        gain = linear.smoother_gain(h.covs[:, :-1], h.predicted_covs[:, 1:], Psi)
        for i in range(1, int(np.max(t - s)) + 1):  # w_{k} from w_{k + 1}, k = t - i
            k = np.maximum(t - i, np.minimum(s, t - 1))  # a finished chain: any frame, dropped
            step = linear.smoother_step(
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
            W, np.swapaxes(mean, 0, 1), np.swapaxes(cov, 0, 1), b.nodes + b.elapsed[s][:, None]
        )
    return Smoothed(means, covs)
