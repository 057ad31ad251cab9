"""The package's front door: its names, its subpackages, and the paths 0.3 removed."""

import importlib
import pkgutil
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import depthcore

PACKAGE = Path(depthcore.__file__).parent


def _run(code: str) -> str:
    return subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", code],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


def test_import_leaves_scipy_and_the_heavy_modules_unloaded():
    out = _run(
        "import sys, depthcore; "
        "print(sorted(m for m in ('scipy', 'matplotlib', 'depthcore.studies.monte_carlo', "
        "'depthcore.exact.optimal', 'depthcore.registry.filters', 'depthbook') "
        "if m in sys.modules))"
    )
    assert out == "[]"


def test_the_front_door_names_resolve_without_a_warning():
    out = _run(
        "import depthcore; "
        "print(depthcore.track.__name__, "
        "len(depthcore.FILTERS) > 5, depthcore.exact.optimal.__name__)"
    )
    assert out == "track True depthcore.exact.optimal"


def test_every_module_is_an_attribute_of_its_package_after_import_depthcore():
    out = _run(
        "import functools, depthcore\n"
        "for name in depthcore.MODULES:\n"
        "    got = functools.reduce(getattr, name.split('.')[1:], depthcore)\n"
        "    assert got.__name__ == name, name\n"
        "print(len(depthcore.MODULES))"
    )
    assert int(out) == len(depthcore.MODULES)


def test_a_missing_module_of_a_subpackage_is_an_attribute_error():
    with pytest.raises(AttributeError, match="'depthcore.exact' has no attribute 'nothing'"):
        depthcore.exact.nothing  # noqa: B018
    with pytest.raises(AttributeError, match="has no attribute '_private'"):
        depthcore.studies._private  # noqa: B018


def test_star_import_imports_neither_the_book_nor_every_module():
    out = _run(
        "import sys; from depthcore import *; "
        "print(sorted(n for n in ('Gaussian', 'FILTERS', 'track', 'SCENARIOS') if n in globals()), "
        "'depthbook' in sys.modules, 'depthcore.studies.monte_carlo' in sys.modules)"
    )
    assert out == "['FILTERS', 'Gaussian', 'SCENARIOS', 'track'] False False"


def _modules_on_disk() -> set[str]:
    found = set()
    for sub in depthcore.SUBPACKAGES:
        found.add(f"depthcore.{sub}")
        for m in pkgutil.iter_modules([str(PACKAGE / sub)]):
            if not m.name.startswith("_"):
                found.add(f"depthcore.{sub}.{m.name}")
    return found


def test_modules_lists_every_module_of_the_subpackages_and_each_imports():
    assert set(depthcore.MODULES) == _modules_on_disk()
    for name in depthcore.MODULES:
        assert importlib.import_module(name).__name__ == name


def test_every_subpackage_is_an_attribute_and_in_dir():
    for name in depthcore.SUBPACKAGES:
        assert getattr(depthcore, name).__name__ == f"depthcore.{name}"
    assert set(depthcore.SUBPACKAGES) <= set(dir(depthcore))


def test_every_folder_of_the_package_is_a_listed_subpackage():
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    assert folders == set(depthcore.SUBPACKAGES)


def test_an_unknown_attribute_raises_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'walkthrough'"):
        depthcore.walkthrough  # noqa: B018


# --- what 0.3 removed, as the changelog names it --------------------------------------

CHANGELOG = Path(__file__).resolve().parent.parent / "CHANGELOG.md"


def _removed_rows() -> list[tuple[str, str]]:
    """The changelog's rows of removed module paths: ``(removed, replacement)``."""
    text = CHANGELOG.read_text(encoding="utf-8")
    section = text.split("### Removed", 1)[1].split("Functions that took", 1)[0]
    return re.findall(r"^\| `(depthcore[\w.]*)` \| `(depth(?:core|book)[\w.]*)` \|$", section, re.M)


REMOVED = _removed_rows()


def test_the_changelog_names_every_removed_module_path():
    assert len(REMOVED) == 41, REMOVED


@pytest.mark.parametrize("old, new", REMOVED, ids=[r[0] for r in REMOVED])
def test_a_removed_path_no_longer_imports_and_its_replacement_does(old, new):
    package, _, name = old.rpartition(".")
    with pytest.raises(ImportError):
        exec(f"import {old}", {})
    with pytest.raises(ImportError):
        exec(f"from {package} import {name}", {})
    assert importlib.import_module(new).__name__ == new


@pytest.mark.parametrize(
    "module, removed, door",
    [
        ("depthcore.kalman.ekf", "ekf", "run"),
        ("depthcore.kalman.ukf", "ukf", "run"),
        ("depthcore.kalman.second_order", "second_order", "run"),
        ("depthcore.exact.optimal", "marginals", "run"),
        ("depthcore.particles.importance", "particle_filter", "run"),
        ("depthcore.particles.resample_move", "resample_move", "run"),
        ("depthcore.registry.adapters", "run_ekf", None),
        ("depthcore", "optimal_marginals", None),
        ("depthcore.kalman", "run", None),
    ],
)
def test_a_removed_function_is_gone_and_the_changelog_names_its_replacement(module, removed, door):
    m = importlib.import_module(module)
    with pytest.raises(AttributeError):
        getattr(m, removed)
    assert door is None or callable(getattr(m, door))
    changelog = CHANGELOG.read_text(encoding="utf-8")
    shown = (
        "run_<name>"
        if removed == "run_ekf"
        else "<name>"
        if module == "depthcore.kalman"
        else removed
    )
    assert f"`{module}.{shown}" in changelog


def test_the_new_paths_never_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in depthcore.MODULES:
            importlib.import_module(name)


def test_the_books_package_has_the_packages_version_and_is_not_installed_with_it():
    import tomllib

    root = PACKAGE.parent
    book = tomllib.loads((root / "depthbook" / "pyproject.toml").read_text(encoding="utf-8"))
    assert book["project"]["version"] == depthcore.__version__
    package = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    assert package["project"]["dependencies"] == ["numpy>=1.26", "scipy>=1.11"]
    assert package["tool"]["setuptools"]["packages"]["find"]["include"] == ["depthcore*"]


def _moved_rows() -> list[tuple[str, str]]:
    """The changelog's rows of modules moved out of the package: ``(old, now)``."""
    text = CHANGELOG.read_text(encoding="utf-8")
    section = text.split("### Moved out of the package", 1)[1].split("###", 1)[0]
    return re.findall(r"^\| `(depthcore[\w.]*)` \| `(depthbook[\w.]*)` \|$", section, re.M)


MOVED = _moved_rows()


@pytest.mark.parametrize("old, new", MOVED, ids=[r[0] for r in MOVED])
def test_a_module_moved_to_the_book_leaves_the_package(old, new):
    assert len(MOVED) == 8
    with pytest.raises(ImportError):
        importlib.import_module(old)
    assert importlib.import_module(new).__name__ == new
