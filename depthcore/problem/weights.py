"""Log weights normalised in log space: a particle sample's, a mixture's components'.

Recommended import: ``from depthcore.problem import weights``.

:func:`normalise` and :func:`normalised` normalise unnormalised log weights by
log-sum-exp, shifting by the largest first so that no weight overflows or
underflows; the particle filters (:mod:`depthcore.particles`) and the exact
filter's mixture over depth (:mod:`depthcore.exact.mixture`) both use them.
"""

import numpy as np


def normalise(log_w) -> np.ndarray:
    """Normalise log weights along the last axis: ``log W = log w - logsumexp(log w)``.

    Parameters
    ----------
    log_w : array_like, shape (..., N)
        Unnormalised log weights; ``-inf`` is weight zero.

    Returns
    -------
    ndarray, shape (..., N)
        ``logsumexp`` of each row is 0.
    """
    shifted, _, total = _shifted(log_w)
    return shifted - np.log(total)


def normalised(log_w):
    """Normalised weights and the log of their sum, by log-sum-exp along the last axis.

    ``W = w / sum w`` and ``log sum w = m + log sum exp(log w - m)``,
    ``m = max log w``, with no overflow or underflow of the largest weights.

    Parameters
    ----------
    log_w : array_like, shape (..., N)
        As for :func:`normalise`.

    Returns
    -------
    W : ndarray, shape (..., N)
        The normalised weights, summing to one along the last axis.
    log_normaliser : ndarray, shape (...)
        ``log sum w``.
    """
    shifted, top, total = _shifted(log_w)
    return np.exp(shifted) / total, (top + np.log(total))[..., 0]


def _shifted(log_w):
    """``log w - m``, ``m = max log w`` (..., 1) and ``sum exp(log w - m)`` (..., 1)."""
    log_w = np.asarray(log_w, dtype=float)
    top = np.max(log_w, axis=-1, keepdims=True)
    if not np.all(np.isfinite(top)):
        raise ValueError("log_w has a row with no positive, finite weight")
    # shift first: the weights exp(shifted) then sum to one to rounding, however large
    # |log w| is (top + log(sum) would round to eps |top|, far from one at |top| ~ 1e10)
    shifted = log_w - top
    return shifted, top, np.sum(np.exp(shifted), axis=-1, keepdims=True)
