"""A book page run as a plain notebook in Jupyter shows what the book shows.

The book pastes what a page glues (``myst_nb.glue(..., display=False)``) into
its text: figures (``{glue:figure}``, ``{glue}``) and numbers
(``{eval}``, ``{glue:text}``) in tables and prose. Jupyter displays none of these records,
so each page also displays them in cells that the book leaves out
(:class:`depthbook.notebook.GlueLog`, :func:`depthbook.paper.comparison_table`).

The outputs checked are those of ``book/_nbval/<page>.ipynb``: the page
converted by jupytext and executed as a plain notebook with nbclient (``make
notebooks-update``), which ``make notebooks`` checks against a fresh run of
the page. For each page:

* every glued figure is displayed as the same PNG image that the book shows;
* every name pasted with ``{eval}``, ``{glue:text}`` or ``{glue}`` is displayed on one line
  with its value, as the book pastes it;
* every table of the page that pastes glued numbers is displayed whole, with
  the numbers that the book puts in it (the figure pages' tables of the
  paper's numbers beside ours by :func:`depthbook.paper.comparison_table`,
  the others by :class:`depthbook.notebook.GlueLog` from the page's own text).
"""

from __future__ import annotations

import ast
import functools
import re
import sys
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import check_notebooks  # noqa: E402  (the one reader of _toc.yml)

PREFIX = "application/papermill.record/"
SHOWN = ("text/plain", "text/markdown", "text/html")
FIGURE_DIRECTIVE = re.compile(r"^(?:```|:::)\{glue(?::figure)?\}\s+(\S+)\s*$", re.MULTILINE)
TEXT_ROLE = re.compile(r"\{(?:eval|glue(?::text)?)\}`([A-Za-z_][A-Za-z0-9_]*)`")
# The figure pages' tables of the paper's numbers beside ours.
COMPARISON_HEADER = "| density | paper: mean | ours: mean | paper: SD | ours: SD |"
PAGES = check_notebooks.notebook_pages()


def pasted_text(text_plain: str) -> str:
    """A glued ``text/plain`` as ``{glue:text}`` pastes it (a string without its quotes)."""
    try:
        return str(ast.literal_eval(text_plain))
    except (SyntaxError, ValueError):
        return text_plain


@functools.cache
def executed(page: Path):
    """(glued records by name, displayed outputs) of the page's executed notebook."""
    nb = nbformat.read(check_notebooks.reference_path(page), as_version=4)
    glued, displayed = {}, []
    for cell in nb.cells:
        for out in cell.get("outputs", []) if cell.cell_type == "code" else []:
            if out.output_type not in ("display_data", "execute_result"):
                continue
            record = out.get("metadata", {}).get("scrapbook")
            if record and record.get("mime_prefix"):
                n = len(record["mime_prefix"])
                glued[record["name"]] = {k[n:]: v for k, v in out.data.items()}
            else:
                displayed.append(out.data)
    return glued, displayed


@functools.cache
def markdown(page: Path) -> str:
    """The page's text outside its code cells (which jupytext makes markdown cells)."""
    import jupytext

    nb = jupytext.read(page)
    return "\n\n".join(cell.source for cell in nb.cells if cell.cell_type == "markdown")


def png(data) -> str:
    return re.sub(r"\s", "", data)


def page_tables(text: str) -> list[list[str]]:
    """The pipe tables of a page's markdown, as lists of lines."""
    tables, current = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            current.append(line.strip())
        elif current:
            tables.append(current)
            current = []
    return tables


def fill(line: str, glued: dict) -> str:
    """A line of the page with every glued text pasted in, as the book shows it."""
    return TEXT_ROLE.sub(lambda m: pasted_text(glued[m.group(1)]["text/plain"]), line)


@pytest.fixture(params=PAGES, ids=[p.stem for p in PAGES])
def page(request):
    return request.param


def test_every_glued_figure_is_displayed(page):
    glued, displayed = executed(page)
    text = markdown(page)
    names = FIGURE_DIRECTIVE.findall(text) + [
        name for name in TEXT_ROLE.findall(text) if "image/png" in glued.get(name, {})
    ]
    shown = {png(data["image/png"]) for data in displayed if "image/png" in data}
    for name in names:
        assert name in glued, f"{page.name}: {name!r} is pasted but never glued"
        assert "image/png" in glued[name], f"{page.name}: {name!r} is not a figure"
        is_shown = png(glued[name]["image/png"]) in shown
        assert is_shown, f"{page.name}: figure {name!r} is glued but not displayed in the notebook"


def test_every_glued_text_is_displayed_with_its_value(page):
    glued, displayed = executed(page)
    lines = [
        line
        for data in displayed
        for mime in SHOWN
        if mime in data
        for line in data[mime].splitlines()
    ]
    missing = []
    for name in dict.fromkeys(TEXT_ROLE.findall(markdown(page))):
        assert name in glued, f"{page.name}: {name!r} is pasted but never glued"
        if "image/png" in glued[name]:
            continue
        value = pasted_text(glued[name]["text/plain"])
        pattern = re.compile(rf"(^|[\s|`]){re.escape(name)}[\s|`]+{re.escape(value)}\s*\|?\s*$")
        if not any(pattern.search(line) for line in lines):
            missing.append(f"{name} = {value}")
    assert not missing, f"{page.name}: not displayed in the notebook: {', '.join(missing)}"


MARKDOWN = re.compile(r"`|\*\*|\]\(")


def test_a_pasted_text_holds_no_markdown(page):
    # {eval} and {glue:text} paste plain text: a backtick or ** would reach the page as is.
    glued, _ = executed(page)
    raw = [
        f"{name} = {value!r}"
        for name in dict.fromkeys(TEXT_ROLE.findall(markdown(page)))
        if "image/png" not in glued[name]
        and MARKDOWN.search(value := pasted_text(glued[name]["text/plain"]))
    ]
    assert not raw, f"{page.name}: pasted as plain text but written in Markdown: {raw}"


def test_the_tables_of_numbers_are_displayed_whole(page):
    glued, displayed = executed(page)
    shown = [data["text/markdown"] for data in displayed if "text/markdown" in data]
    tables = [t for t in page_tables(markdown(page)) if TEXT_ROLE.search("\n".join(t))]
    whole = [
        t[0]
        for t in tables
        if any("\n".join(fill(line, glued) for line in t) in text for text in shown)
    ]
    missing = [t[0] for t in tables if t[0] not in whole]
    assert not missing, f"{page.name}: tables not displayed whole in the notebook: {missing}"
    if page.stem in ("fig2", "fig3", "fig4", "fig5"):
        assert whole[0].startswith(COMPARISON_HEADER)


def test_a_downloaded_notebook_gives_the_page_its_tables(page, tmp_path, monkeypatch):
    """GlueLog("fig6.md") run where only the page's notebook is (a download) finds its tables."""
    import jupytext

    from depthbook.notebook import page_tables as tables_of
    from depthbook.notebook import page_text

    expected = tables_of(page.read_text(encoding="utf-8"))
    monkeypatch.chdir(tmp_path)
    assert page_text(page.name) == ""  # an empty folder: no tables, and no error
    jupytext.write(jupytext.read(page), tmp_path / f"{page.stem}.ipynb")
    assert tables_of(page_text(page.name)) == expected
    assert tables_of(page_text(page.stem)) == expected
    (tmp_path / page.name).write_text(page.read_text(encoding="utf-8"), encoding="utf-8")
    assert page_text(page.name) == page.read_text(encoding="utf-8")


def test_a_markdown_tables_text_depends_on_its_values_not_on_their_widths():
    """The last column is not padded and its rule is as wide as its header: a long value
    there, such as the environment statement naming the processor (which
    tests/nbval_sanitize.cfg replaces), leaves the rest of the plain text alone."""
    from depthbook.notebook import MarkdownTable

    table = MarkdownTable(["glued name", "value"], [["rep_n", "3"], ["rep_what", "a long value"]])
    assert repr(table).splitlines() == [
        "glued name  value",
        "----------  -----",
        "rep_n       3",
        "rep_what    a long value",
    ]
    patterns = check_notebooks.sanitize_patterns()
    texts = []
    for environment in (
        "Built on 2026-01-31 with depthcore 1.0 on a laptop",
        "Built on 2026-02-01 with depthcore 1.0 on 64 cores (a processor of a long name)",
    ):
        text = repr(MarkdownTable(["glued name", "value"], [["rep_environment", environment]]))
        for regex, replace in patterns.items():
            text = re.sub(regex, replace, text)
        texts.append(text)
    assert texts[0] == texts[1]
    assert texts[0].splitlines()[1] == "---------------  -----"
