"""The E-step of learning the noise levels: expected squared residuals under the exact posterior.

Recommended import: ``from depthcore.exact import e_step``.

EM (:func:`depthcore.exact.learning.fit` with ``method="em"``) needs, for each track,
the expected squared bearing residuals and velocity changes under the exact smoothed
posterior: each depth node's Kalman filter smoothed (:func:`smooth`, textbook 19.2.6,
with the cross covariances of consecutive frames) and mixed over the nodes
(:func:`expectations`). Another expectation an M-step needs goes here.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from depthcore.exact.bank import PSI
from depthcore.exact.tracks import transitions
from depthcore.kalman import linear
from depthcore.problem.gaussian import MeanAndCov


def expectations(bank, log_weights, tracks):
    """The E-step: the expected squared residuals under the exact smoothed posterior.

    Each node's filter is smoothed (:func:`smooth`, textbook 19.2.6); given the node,
    ``E[(mu_k - x_k / y_k)**2] = (mu_k - E[x_k] / y_k)**2 + Var[x_k] / y_k**2`` and
    ``E[(v_{k+1} - v_k)**2] = (E[v_{k+1}] - E[v_k])**2 + Var[v_k] + Var[v_{k+1}]
    - 2 Cov[v_k, v_{k+1}]``, mixed over the nodes with the posterior's probabilities.

    Parameters
    ----------
    bank : depthcore.exact.bank.Bank
        ``B`` tracks on nodes (B, J), with their history.
    log_weights : ndarray, shape (B, J)
        The nodes' log quadrature weights (``-inf`` at padding).
    tracks : depthcore.exact.learning's checked tracks
        Their ``mu``, ``present``, ``weights``, ``steps``, ``elapsed`` and ``unit_steps``.

    Returns
    -------
    measurement : ndarray, shape (B, N)
        ``E[(mu_k - x_k / y_k)**2] / w_k**2`` (0 at a missing frame).
    motion : ndarray, shape (B, N - 1)
        ``E[(v_{k+1} - v_k)**2] / |s_k|``.
    """
    b = bank
    steps = tracks.unit_steps
    smoothed, cross = smooth(b.history, PSI if steps is None else transitions(steps)[:, None])
    depth = b.nodes[..., None] + tracks.elapsed[:, None, :]  # (B, J, N)
    mx, vx = smoothed.mean[..., 0], smoothed.cov[..., 0, 0]
    mu = np.where(tracks.present, tracks.mu, 0.0)[:, None, :]
    meas = (mu - mx / depth) ** 2 + vx / depth**2
    mv, vv = smoothed.mean[..., 1], smoothed.cov[..., 1, 1]
    motion = (mv[..., 1:] - mv[..., :-1]) ** 2 + vv[..., 1:] + vv[..., :-1] - 2.0 * cross[..., 1, 1]
    log_p = log_weights + b.log_weight
    p = np.exp(log_p - logsumexp(log_p, axis=-1, keepdims=True))[..., None]  # (B, J, 1)
    meas = np.sum(np.where(p > 0, p * meas, 0.0), axis=1)
    motion = np.sum(np.where(p > 0, p * motion, 0.0), axis=1)
    meas = np.where(tracks.present, meas / tracks.weights**2, 0.0)
    return meas, motion / np.abs(tracks.steps)


def smooth(res: linear.FilterResult, Psi):
    """Textbook 19.2.6 on each node's filter, with ``Cov[w_k, w_{k+1} | mu] = C_k Sigma_{k+1|N}``.

    Returns the smoothed ``MeanAndCov`` (..., N, 2), (..., N, 2, 2) and the cross
    covariances (..., N - 1, 2, 2).
    """
    cov, predicted = res.covs[..., :-1, :, :], res.predicted_covs[..., 1:, :, :]
    try:  # C_k^T = Sigma_{+|k+1}^{-1} Psi Sigma_k, the predictions positive definite
        gains = np.swapaxes(np.linalg.solve(predicted, Psi @ cov), -1, -2)
    except np.linalg.LinAlgError:  # a singular prediction: the pseudo-inverse's gain
        gains = linear.smoother_gain(cov, predicted, Psi)
    means, covs = np.empty_like(res.means), np.empty_like(res.covs)
    means[..., -1, :], covs[..., -1, :, :] = res.means[..., -1, :], res.covs[..., -1, :, :]
    for t in range(res.means.shape[-2] - 2, -1, -1):
        means[..., t, :], covs[..., t, :, :] = linear.smoother_step(
            gains[..., t, :, :],
            res.means[..., t, :],
            res.covs[..., t, :, :],
            res.predicted_means[..., t + 1, :],
            res.predicted_covs[..., t + 1, :, :],
            means[..., t + 1, :],
            covs[..., t + 1, :, :],
        )
    return MeanAndCov(means, covs), gains @ covs[..., 1:, :, :]
