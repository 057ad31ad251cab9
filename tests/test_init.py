"""The package's namespace: every public module is an attribute, imported when first used."""

import subprocess
import sys

import pytest

import depthcore


def _run(code: str) -> str:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()


def test_import_leaves_scipy_and_the_heavy_modules_unloaded():
    out = _run(
        "import sys, depthcore; "
        "print(sorted(m for m in ('scipy', 'matplotlib', 'depthcore.study', "
        "'depthcore.optimal') if m in sys.modules))"
    )
    assert out == "[]"


def test_every_public_module_is_an_attribute():
    out = _run(
        "import depthcore; print(depthcore.study.__name__, depthcore.optimal_marginals.__name__)"
    )
    assert out == "depthcore.study marginals"
    for name in depthcore.MODULES:
        assert getattr(depthcore, name).__name__ == f"depthcore.{name}"
    assert set(depthcore.MODULES) <= set(dir(depthcore))


def test_an_unknown_attribute_raises_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'walkthrough'"):
        depthcore.walkthrough  # noqa: B018
