"""The README is a front door, and its numbers and figure are what the code gives now.

``tools/readme.py`` writes the README's generated blocks (between
``<!-- readme:KEY -->`` and ``<!-- /readme:KEY -->``) from the book's
computations and records, and its figure, ``_static/figure2.svg``, from the
book's figure code; these tests fail when either differs from what the tool
writes, naming the command that writes them again.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import depthcore

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import readme  # noqa: E402

import check_notebooks  # noqa: E402

#: The most lines the README may have: a front door, the rest is in the book.
MAX_LINES = 250


@pytest.fixture(scope="module")
def text() -> str:
    return readme.README.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def blocks() -> dict[str, str]:
    return readme.blocks()


def test_the_readmes_numbers_are_what_the_tool_writes(text, blocks):
    assert readme.regenerate(text, blocks) == text, (
        f"README.md's generated blocks differ from the book's computations and records: "
        f"run `{readme.COMMAND}`"
    )


def test_the_readmes_figure_is_what_the_books_figure_code_draws():
    assert readme.FIGURE.is_file(), f"{readme.FIGURE.name} is missing: run `{readme.COMMAND}`"
    assert readme.figure_svg() == readme.FIGURE.read_bytes(), (
        f"{readme.FIGURE.relative_to(ROOT)} is not what depthbook.paper.figure draws: "
        f"run `{readme.COMMAND}`"
    )
    assert f"]({readme.FIGURE.relative_to(ROOT).as_posix()})" in readme.blocks()["figure"]


def test_the_figure_is_written_without_a_date_and_with_fixed_ids():
    svg = readme.FIGURE.read_text(encoding="utf-8")
    assert "<dc:date>" not in svg
    # matplotlib names the clip paths by a hash salted with svg.hashsalt (random when unset)
    assert re.search(r'<clipPath id="p[0-9a-f]{10}"', svg)
    assert readme.figure_svg() == readme.figure_svg()


def test_regenerate_replaces_between_markers_and_names_a_missing_block():
    text = "a\n<!-- readme:x -->\nold\n<!-- /readme:x -->\nb\n"
    new = readme.regenerate(text, {"x": "new"})
    assert new == "a\n<!-- readme:x -->\nnew\n<!-- /readme:x -->\nb\n"
    empty = "a\n<!-- readme:x -->\n<!-- /readme:x -->\nb\n"
    assert readme.regenerate(empty, {"x": "new"}) == new
    with pytest.raises(ValueError, match="missing"):
        readme.regenerate(text, {"x": "new", "y": "other"})
    with pytest.raises(ValueError, match="unknown"):
        readme.regenerate(text, {})


def test_the_studies_are_read_from_their_records_and_never_computed(monkeypatch):
    from depthbook.provenance import records

    monkeypatch.delenv(records.ENVIRONMENT, raising=False)
    with readme._records_required():
        assert records.mode() == "require"
    assert records.ENVIRONMENT not in os.environ
    monkeypatch.setenv(records.ENVIRONMENT, "write")
    with readme._records_required():
        assert records.mode() == "require"
    assert os.environ[records.ENVIRONMENT] == "write"


def test_the_readme_opens_with_the_two_commands(text):
    first = re.search(r"```(\w*)\n(.*?)```", text, re.S)
    assert first.group(1) == "bash"
    commands = [line.split("#")[0].strip() for line in first.group(2).splitlines()]
    assert commands == ["make book", "make test"]
    assert text.index(first.group(0)) < text.index("\n## ")


def test_the_readme_is_a_front_door(text):
    lines = text.count("\n")
    assert lines <= MAX_LINES, f"README.md has {lines} lines: move the detail into the book"
    pages = set(check_notebooks.toc_files())
    linked = re.findall(r"\]\((book/[\w/]+)\.md\)", text)
    assert {"book/using", "book/reproducing", "book/intro", "book/cite"} <= set(linked)
    assert not set(linked) - pages, f"README.md links pages not in the book: {set(linked) - pages}"
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    for path in re.findall(r"\]\(((?!https?:)[^)#]+)\)", prose):
        assert (ROOT / path).exists(), f"README.md links {path}, which does not exist"


def test_the_families_table_is_every_subpackage_by_its_docstring():
    table = readme.families()
    listed = re.findall(r"^\| `depthcore\.(\w+)` \| (.+) \|$", table, re.M)
    folders = {p.parent.name for p in (ROOT / "depthcore").glob("*/__init__.py")}
    assert [name for name, _ in listed] == list(depthcore.SUBPACKAGES)
    assert {name for name, _ in listed} == folders
    assert dict(listed)["exact"] == depthcore.exact.__doc__.splitlines()[0]


def test_the_layout_names_every_top_level_folder(text):
    layout = text.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    try:
        tracked = subprocess.run(
            ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    folders = {path.split("/", 1)[0] for path in tracked if "/" in path}
    unnamed = sorted(f for f in folders if f"`{f}/`" not in layout)
    assert not unnamed, f"README.md's Layout does not name {unnamed}"
    for extra in ("[plot]", "[stonesoup]", "[dask]"):
        assert f"`{extra}`" in layout


def _readers_targets() -> list[str]:
    """The Makefile's targets with a ``## `` help text, which ``make help`` lists."""
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    return re.findall(r"^([a-z-]+):.*## ", makefile, re.M)


def test_make_help_lists_the_readers_targets_under_distinct_names(text):
    shown = _readers_targets()
    expected = {"book", "pdf", "lab", "test", "core", "figures", "records", "bench", "clean"}
    assert expected <= set(shown)
    assert shown[:2] == ["help", "book"]
    for a in shown:
        for b in shown:
            assert a == b or not b.startswith(a), (
                f"make {a} and make {b}: one name extends the other"
            )
    named = set(re.findall(r"`make ([a-z-]+)", text))
    assert named <= set(shown), f"README.md names targets make help hides: {named - set(shown)}"
