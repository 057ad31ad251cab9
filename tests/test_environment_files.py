"""The pinned environment files describe one and the same environment.

``requirements.txt`` (used by ``make``) and ``environment.yml`` (for conda
readers) must pin exactly the same packages at exactly the same versions, with
Jupyter Book 1 and Python 3.11; the package version is the same in
``pyproject.toml``'s source (``depthcore.__version__``), the installed
metadata and ``CITATION.cff``; and the environment running these tests is the
pinned one.
"""

from __future__ import annotations

import importlib.metadata
import re
from pathlib import Path

import yaml
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent
PIN_RE = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;#]+)$")


def parse_pins(lines: list[str], source: str) -> dict[str, str]:
    """``name==version`` lines -> {canonical name: version}; anything else fails."""
    pins: dict[str, str] = {}
    for line in lines:
        match = PIN_RE.match(line.strip())
        assert match, f"{source}: not an exact pin: {line!r}"
        name = canonicalize_name(match.group(1))
        assert name not in pins, f"{source}: {name} pinned twice"
        pins[name] = match.group(2)
    return pins


def requirements_pins() -> dict[str, str]:
    text = (ROOT / "requirements.txt").read_text(encoding="utf-8")
    lines = [
        line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")
    ]
    return parse_pins(lines, "requirements.txt")


def environment_yml() -> dict:
    return yaml.safe_load((ROOT / "environment.yml").read_text(encoding="utf-8"))


def environment_pip_lines() -> list[str]:
    sections = [dep["pip"] for dep in environment_yml()["dependencies"] if isinstance(dep, dict)]
    assert len(sections) == 1, "environment.yml needs exactly one `- pip:` section"
    return [str(item) for item in sections[0]]


def test_requirements_pin_every_package_exactly():
    pins = requirements_pins()
    for name in (
        "numpy",
        "scipy",
        "matplotlib",
        "jupyter-book",
        "jupytext",
        "nbval",
        "pytest",
        "hypothesis",
        "ipykernel",
        "sympy",
        "selenium",
        "filterpy",
        "pytest-xdist",
        "sphinx-mathjax-offline",
        "sphinx-exercise",
        "sphinx-proof",
        "setuptools",
        "jupyterlab",
    ):
        assert name in pins, f"requirements.txt does not pin {name}"


def test_requirements_pin_jupyter_book_1():
    # Jupyter Book 2 ignores _config.yml and _toc.yml: the book would not be this book.
    assert Version(requirements_pins()["jupyter-book"]).major == 1


def test_environment_yml_pins_the_same_set_as_requirements():
    lines = [line for line in environment_pip_lines() if not line.startswith("-e ")]
    assert parse_pins(lines, "environment.yml") == requirements_pins()


def test_environment_yml_installs_depthcore_its_book_and_python_311():
    deps = environment_yml()["dependencies"]
    assert "python=3.11" in deps
    assert "pip" in deps
    assert {"-e .", "-e depthbook"} <= set(environment_pip_lines())


def test_python_version_file_is_311():
    assert (ROOT / ".python-version").read_text(encoding="utf-8").strip() == "3.11"


def test_pyproject_bounds_admit_the_pins():
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["requires-python"] == ">=3.11"
    pins = requirements_pins()
    for dependency in project["dependencies"]:
        requirement = Requirement(dependency)
        name = canonicalize_name(requirement.name)
        assert name in pins, f"runtime dependency {name} is not pinned"
        assert requirement.specifier.contains(pins[name]), (
            f"{name}=={pins[name]} outside {requirement}"
        )


def test_installed_packages_are_the_pinned_versions():
    wrong = {}
    for name, version in requirements_pins().items():
        try:
            installed = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            installed = None
        if installed != version:
            wrong[name] = (version, installed)
    assert not wrong, f"(pinned, installed) differ; run `make` to rebuild .venv: {wrong}"


def test_version_agrees_in_package_metadata_and_citation():
    import depthcore

    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert (
        depthcore.__version__ == importlib.metadata.version("depthcore") == str(citation["version"])
    )
