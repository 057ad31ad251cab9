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

from depthcore.exact.bank import PSI, run_bank
from depthcore.exact.mixture import Smoothed, mixture_moments
from depthcore.exact.posterior import posterior, update
from depthcore.kalman import linear
from depthcore.problem import checks


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


def track(mu, rho, prior_mean, prior_cov, process_noise=0.0, lag: int = 2, rtol: float = 1e-10):
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

    Parameters
    ----------
    mu : array_like, shape (N,)
        The bearings of one track, ``N >= 1``.
    rho, prior_mean, prior_cov, process_noise, rtol
        As for :func:`~depthcore.exact.posterior.posterior` (one problem).
    lag : int
        The fixed-lag smoother's delay in frames, >= 0 (0: the filter; from
        ``N - 1`` on, the fixed-interval smoother, which is what it then is).

    Returns
    -------
    Track
    """
    mu = checks.finite_array(mu, "mu")
    if mu.ndim != 1 or mu.size < 1:
        raise ValueError(f"mu must have shape (N,) with N >= 1 (one track), got shape {mu.shape}")
    lag = checks.nonnegative_count(lag, "lag")
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
        h = run_bank(b.nodes, b.mu, b.rho, b.process_noise, b.prior_mean, b.prior_cov, True).history
        s = np.arange(first, last)
        t = np.minimum(s + lag, N - 1)
        mean, cov = h.means[:, t, :], h.covs[:, t, :, :]  # (J, frames, ...): at each t
        # the gain at frame k serves every chain through k: one per frame and node
        gain = linear.smoother_gain(h.covs[:, :-1], h.predicted_covs[:, 1:], PSI)
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
            W, np.swapaxes(mean, 0, 1), np.swapaxes(cov, 0, 1), b.nodes + s[:, None]
        )
    return Smoothed(means, covs)
