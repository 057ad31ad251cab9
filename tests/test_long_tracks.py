"""The online filters take any number of frames, at a cost per frame that does not grow.

Frames 9,001 to 10,000 of a track are compared with frames 1 to 1,000: what the
filter holds (its pickled size, the exact filter's node count), the memory that
a stretch of 1,000 frames leaves allocated and the peak its last frames need
(tracemalloc). A filter that kept its past estimates fails the checks.
"""

import pickle
import sys
import tracemalloc

import numpy as np
import pytest

from depthcore.problem import model
from depthcore.registry import online

FRAMES, STRETCH = 10_000, 1_000
PRIOR_MEAN, PRIOR_COV = [1.0, 5.0, 0.3], np.diag([1.0, 4.0, 0.1])
RHO, Q = 0.01, 1e-3
#: The last frames of a stretch whose peak of memory is measured.
TRACED = 100
#: Memory blocks a stretch may leave allocated (caches), and bytes its peak may differ by.
SLACK_BLOCKS, SLACK = 200, 32_000


def _track():
    """10,000 frames of a receding point, a bearing at every tenth (the others missing)."""
    sim = model.simulate(PRIOR_MEAN, FRAMES, RHO, Q, np.random.default_rng(5), frame=1)
    mu = np.where(np.arange(FRAMES) % 10 == 0, sim.mu, np.nan)
    mu[:3] = sim.mu[:3]
    return mu


def _stretch(f, mu, start: int) -> tuple[int, int]:
    """Frames ``start + 1 .. start + STRETCH`` through ``f``.

    Returns the memory blocks the stretch leaves allocated (Python's own count, which
    costs nothing per frame) and the peak bytes its last ``TRACED`` frames allocate
    (tracemalloc, which slows each allocation).
    """
    blocks = sys.getallocatedblocks()
    for k in range(start, start + STRETCH - TRACED):
        f.update(mu[k])
    tracemalloc.start()
    try:
        for k in range(start + STRETCH - TRACED, start + STRETCH):
            f.update(mu[k])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return sys.getallocatedblocks() - blocks, peak


def _measure(f, mu):
    """Per stretch (first, last): bytes left, peak bytes, pickled size of the filter."""
    first = (*_stretch(f, mu, 0), len(pickle.dumps(f)))
    for k in range(STRETCH, FRAMES - STRETCH):
        f.update(mu[k])
    last = (*_stretch(f, mu, FRAMES - STRETCH), len(pickle.dumps(f)))
    return first, last


class _Hoarding:
    """An online filter that keeps every estimate: what the checks must catch."""

    def __init__(self, inner):
        self.inner, self.seen = inner, []

    def update(self, mu):
        self.seen.append(self.inner.update(mu))
        return self.seen[-1]


def _constant(first, last) -> bool:
    (_, peak_1, held_1), (left_2, peak_2, held_2) = first, last
    return left_2 <= SLACK_BLOCKS and peak_2 <= 1.5 * peak_1 + SLACK and held_2 <= 1.1 * held_1


@pytest.mark.parametrize("name", online.NAMES)
def test_the_last_thousand_of_ten_thousand_frames_cost_what_the_first_did(name):
    mu = _track()
    f = online.start(name, PRIOR_MEAN, PRIOR_COV, rho=RHO, process_noise=Q)
    first, last = _measure(f, mu)
    assert f.frame == FRAMES and f.current.frame == FRAMES
    assert np.isfinite(f.current.depth_mean) and f.current.depth_sd > 0
    assert _constant(first, last), (first, last)
    if name == "optimal":
        from depthcore.exact import quadrature

        assert f.detail.node_count <= quadrature.NODE_BUDGET


def test_a_filter_that_keeps_its_past_fails_the_checks():
    mu = _track()
    hoarding = _Hoarding(online.start("ekf", PRIOR_MEAN, PRIOR_COV, rho=RHO, process_noise=Q))
    first = (*_stretch(hoarding, mu, 0), len(pickle.dumps(hoarding)))
    for k in range(STRETCH, 2 * STRETCH):
        hoarding.update(mu[k])
    last = (*_stretch(hoarding, mu, 2 * STRETCH), len(pickle.dumps(hoarding)))
    assert first[0] > 10 * SLACK_BLOCKS and last[2] > 2 * first[2]
    assert not _constant(first, last)
