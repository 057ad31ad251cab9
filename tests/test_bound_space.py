"""The Cramér-Rao bound for a point in 3-D (``depthcore.analysis.bound_space``), by brute force.

The route: the states of every frame stacked, ``z = A xi`` with ``xi = (s_1, w_1 ..
w_{N-1})`` (the state at frame 1 and each step's velocity noise), the pairs' Jacobians at
the truth, and the marginal of the last frame's block of the stacked posterior covariance,
``Sigma - Sigma H^T (H Sigma H^T + R)^{-1} H Sigma``: no recursion.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.analysis import bound_space

STEPS = np.array([0.5, 1.7, -1.0, -0.25, 3.0, 0.8, -1.2])
RHO = 0.005 * np.array([1.0, 2.5, 0.7, 1.0, 4.0, 1.3, 0.9, 2.0])
PRESENT = np.array([True, True, False, True, True, False, True, True])
PRIOR_COV = np.diag([4.0, 9.0, 1.0, 4.0, 1.0])


def _track(x1, steps, accelerations):
    out = [np.array(x1, float)]
    for s, (a, b) in zip(steps, accelerations, strict=True):
        x, y, v, h, w = out[-1]
        out.append(np.array([x + s * v, y + s, v + a, h + s * w, w + b]))
    return np.array(out)


def _shift(d):
    F = np.eye(5)
    F[0, 2] = F[3, 4] = d
    return F


def _stacked_bound(states, rho, present, prior_cov, q):
    n = len(states)
    e = np.concatenate([[0.0], np.cumsum(np.diff(states[:, 1]))])
    A = np.zeros((5 * n, 5 * n))
    for k in range(n):
        for j in range(k + 1):
            A[5 * k : 5 * k + 5, 5 * j : 5 * j + 5] = _shift(e[k] - e[j])
    C = np.zeros((5 * n, 5 * n))
    C[:5, :5] = prior_cov
    for j in range(1, n):
        C[5 * j + 2, 5 * j + 2] = C[5 * j + 4, 5 * j + 4] = q**2 * abs(e[j] - e[j - 1])
    Sigma = A @ C @ A.T
    rows = []
    for k in np.flatnonzero(present):
        x, y, h = states[k, 0], states[k, 1], states[k, 3]
        for gradient in ([1 / y, -x / y**2, 0, 0, 0], [0, -h / y**2, 0, 1 / y, 0]):
            row = np.zeros(5 * n)
            row[5 * k : 5 * k + 5] = gradient
            rows.append(row / rho[k])
    H = np.array(rows)
    post = Sigma - Sigma @ H.T @ np.linalg.solve(H @ Sigma @ H.T + np.eye(len(H)), H @ Sigma)
    return post[-5:, -5:]


@pytest.mark.parametrize("q", [0.0, 0.1])
def test_the_recursion_is_the_stacked_bound(q):
    """Gaps, rho per frame, signed steps, q >= 0: the bound at frames 4 and 8 to 1e-8."""
    rng = np.random.default_rng(2)
    acc = q * np.sqrt(np.abs(STEPS))[:, None] * rng.standard_normal((len(STEPS), 2))
    states = _track([0.5, 6.0, -0.2, 1.0, 0.1], STEPS, acc)
    B = bound_space.conditional_bound(states, RHO, PRIOR_COV, q, PRESENT)
    for k in (4, 8):
        expected = _stacked_bound(states[:k], RHO, PRESENT[:k], PRIOR_COV, q)
        assert_allclose(B[k - 1], expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())


def test_without_a_prior_the_bound_waits_for_the_pairs_to_fix_the_state():
    states = _track([0.5, 6.0, -0.2, 1.0, 0.1], STEPS, np.zeros((len(STEPS), 2)))
    B = bound_space.conditional_bound(states, RHO)
    assert np.all(np.isnan(B[0])) and np.all(np.isfinite(B[-1]))


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda s: bound_space.conditional_bound(s[:, :3], RHO), "states"),
        (lambda s: bound_space.conditional_bound(s * [1, -1, 1, 1, 1], RHO), "states"),
        (lambda s: bound_space.conditional_bound(s, -RHO), "rho"),
        (lambda s: bound_space.conditional_bound(s, RHO, np.eye(3)), "prior_cov"),
        (lambda s: bound_space.conditional_bound(s, RHO, None, -1.0), "process_noise"),
    ],
)
def test_refusals_name_the_argument_in_one_line(call, name):
    states = _track([0.5, 6.0, -0.2, 1.0, 0.1], STEPS, np.zeros((len(STEPS), 2)))
    with pytest.raises(ValueError) as info:
        call(states)
    assert str(info.value).startswith(name) and "\n" not in str(info.value)
