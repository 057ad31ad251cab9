"""The filters' one calling convention, ``(mu, rho, prior_mean, prior_cov, process_noise)``,
documented once.

Recommended import: ``from depthcore.problem import signature``.

Every filter's door (:data:`depthcore.registry.filters.FILTERS` names them) and the
functions built like one take the problem as these five arguments. Their
docstrings write ``{parameters}`` where their ``Parameters`` section starts;
:func:`documented` puts the section's heading and :data:`PROBLEM` there, and
:data:`PROCESS_NOISE`, :data:`STEPS` and :data:`GATE` when the function takes
``process_noise``, ``steps`` or ``gate``; the function's own parameters follow.
"""

from __future__ import annotations

import inspect
import textwrap

#: The problem's four arguments, as a NumPy docstring's ``Parameters`` entries.
PROBLEM = """\
mu : array_like, shape (N,) or (..., N)
    Bearings in time order (the paper's triple for ``N = 3``); ``NaN`` marks a
    missing frame, which the filter predicts through without an update. A
    leading shape runs independent problems side by side, checked row by row
    (:func:`depthcore.problem.frames.check`).
rho : float or array_like, shape (...) or (..., N)
    Noise standard deviation, > 0: one for all frames, one per problem, or one
    per frame.
prior_mean : array_like, shape (3,) or (..., 3)
    Prior mean of the state ``(x_1, y_1, v_1)`` at frame 1.
prior_cov : array_like, shape (3, 3) or (..., 3, 3)
    Prior covariance, symmetric positive definite."""

#: The process noise, as a NumPy docstring's ``Parameters`` entry.
PROCESS_NOISE = """\
process_noise : float
    SD ``q >= 0`` of the velocity's change per frame, ``v_{k+1} = v_k + a_k``
    with ``a_k ~ N(0, q**2 |s_k|)`` over a step ``s_k`` (0: the paper's constant
    velocity; :mod:`depthcore.problem.frames`)."""

#: The steps between frames, as a NumPy docstring's ``Parameters`` entry.
STEPS = """\
steps : array_like, shape (N - 1,) or (..., N - 1), optional
    The depth's signed change from each frame to the next, nonzero: positive
    while the point recedes, negative while the camera approaches it (``None``:
    all ones, the paper's frames); the lateral position moves by ``v * steps[k]``
    either way, and the point stays in front of the camera at every frame."""

#: The outlier gate, as a NumPy docstring's ``Parameters`` entry.
GATE = """\
gate : float or None, optional
    Skip a bearing whose two-sided predictive tail probability is below this
    probability (:mod:`depthcore.problem.predictive`), recorded in the result;
    ``None``: no gate."""


def documented(function):
    """Fill ``{parameters}`` in ``function``'s docstring: the heading and the problem's entries.

    The placeholder stands alone on a line; the section takes its indentation.

    Parameters
    ----------
    function : callable

    Returns
    -------
    callable
        ``function``, its docstring filled.
    """
    entries = [PROBLEM]
    parameters = inspect.signature(function).parameters
    for name, entry in (("process_noise", PROCESS_NOISE), ("steps", STEPS), ("gate", GATE)):
        if name in parameters:
            entries.append(entry)
    section = "\n".join(["Parameters", "----------", *entries])
    lines = []
    for line in (function.__doc__ or "").splitlines():
        if line.strip() == "{parameters}":
            line = textwrap.indent(section, line[: len(line) - len(line.lstrip())])
        lines.append(line)
    function.__doc__ = "\n".join(lines)
    return function
