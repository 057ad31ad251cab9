"""The notebook drift check's choice of pages (tools/check_notebooks.py), without executing any."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import check_notebooks  # noqa: E402

PAGES = check_notebooks.notebook_pages()


def test_no_names_select_every_page():
    assert check_notebooks.select_pages(PAGES, []) == PAGES


def test_names_select_those_pages_in_toc_order():
    chosen = check_notebooks.select_pages(PAGES, ["cite", "book/fig6.md", "fig2.md"])
    assert [p.stem for p in chosen] == ["fig2", "fig6", "cite"]


def test_an_unknown_page_is_refused_by_name():
    with pytest.raises(check_notebooks.CheckError, match="not a page of _toc.yml: nosuch"):
        check_notebooks.select_pages(PAGES, ["fig2", "nosuch"])


def test_only_references_of_pages_outside_the_toc_are_stale():
    assert check_notebooks.stale_references(PAGES) == []
    subset = check_notebooks.select_pages(PAGES, ["fig6"])
    stale = check_notebooks.stale_references(subset)
    assert check_notebooks.reference_path(PAGES[0]) in stale
    assert check_notebooks.reference_path(subset[0]) not in stale


def test_update_of_named_pages_leaves_the_other_references(monkeypatch):
    executed, deleted = [], []
    monkeypatch.setattr(check_notebooks, "update", lambda pages: executed.extend(pages) or 0)
    monkeypatch.setattr(Path, "unlink", lambda self, *a, **k: deleted.append(self))
    assert check_notebooks.main(["update", "fig6"]) == 0
    assert [p.stem for p in executed] == ["fig6"] and deleted == []
    assert check_notebooks.main(["update", "nosuch"]) == 1
