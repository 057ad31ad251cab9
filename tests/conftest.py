"""Shared fixtures for the core tests."""

import pytest

from depthcore.scenarios import SCENARIOS


@pytest.fixture(params=list(SCENARIOS))
def scenario(request):
    """Each of the paper's five experiments in turn."""
    return SCENARIOS[request.param]
