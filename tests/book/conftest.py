"""Shared fixtures for the checks of the built book (``_build/html``).

These tests read the HTML that ``make book`` wrote; ``make test`` runs them
after a clean build. The core test run (``pytest tests``) does not collect
this folder (``norecursedirs`` in pyproject.toml).

Parametrised arguments, filled in by ``pytest_generate_tests``:

* ``equation_label``: each equation label ``eq-N`` written in ``book/**/*.md``;
* ``toc_page``: each page of ``_toc.yml``, as ``book/<name>`` (only those of
  its class's ``pages``, a slice, when it has one: ``test_browser.py``);
* ``phone_page``: each page of its module's ``PHONE_PAGES`` (sliced in the same way).
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import check_notebooks  # noqa: E402  (the one reader of _toc.yml)

HTML_DIR = ROOT / "_build" / "html"
DATA_DIR = ROOT / "tests" / "data"


SOURCE_LABEL_RES = (
    re.compile(r"^\((eq-[^)\s]+)\)=\s*$", re.MULTILINE),  # (eq-N)= target
    re.compile(r"^:label:\s*(eq-\S+)\s*$", re.MULTILINE),  # {math} :label: eq-N
    re.compile(r"^\$\$\s*\((eq-[^)\s]+)\)\s*$", re.MULTILINE),  # $$ ... $$ (eq-N)
)


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def toc_pages() -> list[str]:
    """Source pages of the book in TOC order, as ``book/<name>`` (no suffix)."""
    return [str(Path(entry).with_suffix("")) for entry in check_notebooks.toc_files()]


def load_json(name: str):
    return json.loads((DATA_DIR / name).read_text(encoding="utf-8"))


def source_labels() -> list[tuple[str, str]]:
    """(label, page) for every equation label written in ``book/**/*.md``."""
    found = []
    for path in sorted((ROOT / "book").rglob("*.md")):
        if any(part.startswith((".", "_")) for part in path.relative_to(ROOT / "book").parts):
            continue
        text = path.read_text(encoding="utf-8")
        for pattern in SOURCE_LABEL_RES:
            found += [
                (m.group(1), path.relative_to(ROOT).as_posix()) for m in pattern.finditer(text)
            ]
    return found


def figure_pages() -> list[str]:
    """Pages of tests/data/figure_pages.json, normalised to ``book/<name>``."""
    return [str(Path(page).with_suffix("")) for page in load_json("figure_pages.json")]


def pytest_generate_tests(metafunc):
    if "equation_label" in metafunc.fixturenames:
        labels = sorted({label for label, _ in source_labels()}, key=lambda s: (len(s), s))
        metafunc.parametrize("equation_label", labels)
    if "toc_page" in metafunc.fixturenames:
        # Class scope: pytest runs a class's checks of one page one after the other, so
        # that a check may read the page the previous one loaded (test_browser); a class
        # with ``pages`` (a slice of the table of contents) checks only those.
        pages = toc_pages()[getattr(metafunc.cls, "pages", slice(None))]
        metafunc.parametrize("toc_page", pages, scope="class")
    if "phone_page" in metafunc.fixturenames:
        # test_browser.py's PHONE_PAGES, as its class's ``pages`` slices the table of contents.
        pages = metafunc.module.PHONE_PAGES[getattr(metafunc.cls, "pages", slice(None))]
        metafunc.parametrize("phone_page", pages)


@pytest.fixture(scope="session")
def figure_page_names() -> set[str]:
    """The pages of tests/data/figure_pages.json, as ``book/<name>``."""
    return set(figure_pages())


@pytest.fixture(scope="session")
def equation_sources() -> list[tuple[str, str]]:
    return source_labels()


@pytest.fixture(scope="session")
def expected_equation_numbers() -> dict[str, str]:
    """tests/data/equation_labels.json: label -> the paper's equation number."""
    return load_json("equation_labels.json")


def skip_or_fail(message: str) -> None:
    """Skip a check whose prerequisite is missing; under CI, fail it instead."""
    if in_ci():
        pytest.fail(message)
    pytest.skip(message)


@pytest.fixture(scope="session")
def missing_prerequisite():
    """``missing_prerequisite(message)``: skip, or fail under CI (``CI=true``)."""
    return skip_or_fail


@pytest.fixture(scope="session")
def html_dir() -> Path:
    """``_build/html``; skipped (failed under CI) when the book is not built."""
    if not (HTML_DIR / "index.html").exists():
        skip_or_fail(f"{HTML_DIR.relative_to(ROOT)} not found: run `make book` first")
    return HTML_DIR


@pytest.fixture(scope="session")
def html_pages(html_dir: Path) -> dict[str, str]:
    """Text of every built page, keyed by its path relative to ``_build/html``."""
    pages = {}
    for path in sorted(html_dir.rglob("*.html")):
        rel = path.relative_to(html_dir).as_posix()
        if rel.startswith(("_static/", "_sources/", "_images/")):
            continue
        pages[rel] = path.read_text(encoding="utf-8")
    return pages


@pytest.fixture(scope="session")
def load_figure_numbers() -> dict[str, dict[str, str]]:
    """tests/data/figure_numbers.json: label of each of the paper's figures -> number, page."""
    return load_json("figure_numbers.json")
