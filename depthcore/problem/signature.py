"""The filters' one calling convention, ``(mu, rho, prior_mean, prior_cov, process_noise)``,
documented once.

Recommended import: ``from depthcore.problem import signature``.

Every filter's door (:data:`depthcore.registry.filters.FILTERS` names them) and the
functions built like one take the problem as these five arguments. Their
docstrings write ``{problem}`` (and ``{process_noise}``) in their ``Parameters``
section; :func:`documented` puts :data:`PROBLEM` (and :data:`PROCESS_NOISE`) there.
"""

from __future__ import annotations

import textwrap

#: The problem's four arguments, as a NumPy docstring's ``Parameters`` entries.
PROBLEM = """\
mu : array_like, shape (N,) or (..., N)
    Bearings in time order (the paper's triple for ``N = 3``); a leading shape
    runs independent problems side by side, checked row by row.
rho : float or array_like, shape (...)
    Noise standard deviation, > 0.
prior_mean : array_like, shape (3,) or (..., 3)
    Prior mean of the state ``(x_1, y_1, v_1)`` at frame 1.
prior_cov : array_like, shape (3, 3) or (..., 3, 3)
    Prior covariance, symmetric positive definite."""

#: The process noise, as a NumPy docstring's ``Parameters`` entry.
PROCESS_NOISE = """\
process_noise : float
    SD ``q >= 0`` of the velocity's change per frame, ``v_{k+1} = v_k + a_k``
    with ``a_k ~ N(0, q**2)`` (0: the paper's constant velocity)."""


def documented(function):
    """Fill ``{problem}`` and ``{process_noise}`` in ``function``'s docstring.

    Each placeholder stands alone on a line; the entries take its indentation.

    Parameters
    ----------
    function : callable

    Returns
    -------
    callable
        ``function``, its docstring filled.
    """
    lines = []
    for line in (function.__doc__ or "").splitlines():
        key = line.strip()
        if key in ("{problem}", "{process_noise}"):
            text = PROBLEM if key == "{problem}" else PROCESS_NOISE
            lines.append(textwrap.indent(text, line[: len(line) - len(line.lstrip())]))
        else:
            lines.append(line)
    function.__doc__ = "\n".join(lines)
    return function
