"""Monte Carlo standard errors that several chapters' figures share.

Recommended import: ``from depthbook import errors``.

:func:`rms_se` is an RMS error over independent runs with its standard error,
for the error bars of a convergence curve (the importance sampler's and the
Rao-Blackwellised particle filter's).
"""

from __future__ import annotations

import numpy as np


def rms_se(errors, axis: int = -1):
    """The RMS of independent errors and its Monte Carlo standard error.

    Over ``R`` independent runs with errors ``e_r``, the mean square
    ``m = mean(e_r**2)`` has the standard error ``s = SD(e_r**2) / sqrt(R)``,
    and the RMS ``sqrt(m)`` the delta method's ``s / (2 sqrt(m))``: the
    derivative of the square root, ``1 / (2 sqrt(m))``, times ``s``. Like
    every delta-method error it is a first-order one: it needs enough runs
    for ``m`` to lie near its expectation, and it is 0 where every error is 0.

    Parameters
    ----------
    errors : array_like
        The errors of the runs along ``axis`` (at least two runs), finite.
    axis : int
        The axis of the runs.

    Returns
    -------
    rms, se : ndarray
        The RMS error and its standard error, each of the shape of ``errors``
        without ``axis``.
    """
    e = np.asarray(errors, dtype=float)
    if e.ndim == 0 or e.shape[axis] < 2:
        raise ValueError("errors: at least two runs are needed along the axis")
    if not np.all(np.isfinite(e)):
        raise ValueError("errors must be finite")
    squares = e**2
    runs = e.shape[axis]
    mean_square = np.mean(squares, axis=axis)
    square_se = np.std(squares, axis=axis, ddof=1) / np.sqrt(runs)
    rms = np.sqrt(mean_square)
    safe = np.where(rms > 0, rms, 1.0)
    return rms, np.where(rms > 0, square_se / (2.0 * safe), 0.0)
