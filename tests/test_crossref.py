"""depthbook.crossref: the book's references resolved from its sources, as in JupyterLab.

The Sphinx side (each ``{eval}`` reference rendered as the role it names, with
the text that :class:`~depthbook.crossref.BookReferences` gives) is checked in
``tests/test_sphinx_eval.py``; the pages rendered in JupyterLab in
``tests/book/test_lab.py``. Here: every reference of the pages resolves, to the
paper's numbers where the paper numbers, and every page with a kernel writes
its text with constructs that jupyterlab-myst renders.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from depthbook import crossref

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "book").glob("*.md"))
REFERENCE = re.compile(r"\{eval\}`(\w+)\(\"([^\"`]*)\"\)`")
ROLE = re.compile(r"\{([\w:-]+)\}`")
DIRECTIVE = re.compile(r"^\s*(`{3,}|:{3,})\{([\w:-]+)\}", re.M)
CODE_CELL = re.compile(r"^(`{3,})\{code-cell\}.*?^\1\s*$", re.S | re.M)
# What jupyterlab-myst 2.7.0 renders (myst-parser's roles and directives, mystmd's
# exercises, solutions, theorems and proofs, and the cell's {eval} expressions
# evaluated in the kernel).
LAB_ROLES = {"eval", "math", "sub", "sup", "abbr", "kbd", "code"}
LAB_DIRECTIVES = {
    "code-cell",
    "figure",
    "math",
    "note",
    "tip",
    "hint",
    "important",
    "warning",
    "caution",
    "attention",
    "danger",
    "error",
    "seealso",
    "admonition",
    "margin",
    "table",
    "list-table",
    "exercise",
    "solution-start",
    "solution-end",
    "prf:theorem",
    "prf:proof",
}
# Pages with no kernel (no GlueLog, no code cells) and the book's own directives:
# JupyterLab shows these as jupyterlab-myst does, which resolves no reference
# to another page and knows none of Sphinx's own directives.
NOT_FOR_LAB = {
    "api": {"eval-rst", "only", "depthcore-module-summaries"},
    "bibliography": {"bibliography"},
    "notation": {"eq", "doc", "ref"},
    "intro": {"depthcore-downloads"},
}


@pytest.fixture(scope="module")
def book():
    return crossref.BookReferences(ROOT / "book")


def test_the_papers_equations_and_figures_get_the_papers_numbers(book):
    data = ROOT / "tests" / "data"
    for label, number in json.loads((data / "equation_labels.json").read_text()).items():
        assert book.eq(label) == f"({number})"
    for label, figure in json.loads((data / "figure_numbers.json").read_text()).items():
        assert book.numref(label) == f"Figure {figure['number']}"
        assert book.numref(f"Fig. %s <{label}>") == f"Fig. {figure['number']}"


def test_citations_pages_and_sections_resolve_as_the_book_writes_them(book):
    assert book.cite_t("maybank1990") == "Maybank [1990]"
    assert book.cite_p("maybank1990") == "[Maybank, 1990]"
    assert book.cite_t("wan2000") == "Wan and van\xa0der Merwe [2000]"
    assert book.cite_p("cook2006,talts2018") == "[Cook et al., 2006, Talts et al., 2018]"
    assert book.cite_t("tichavsky1998") == "Tichavský et al. [1998]"
    assert book.doc("fig5") == "Figure 5: depth, lower noise"
    assert book.doc("the introduction <intro>") == "the introduction"
    # In Jupyter a link to the page's source, beside the page's own.
    assert book.doc("fig5")._repr_html_() == '<a href="fig5.md">Figure 5: depth, lower noise</a>'
    assert crossref.BookReferences(ROOT / "book" / "api").doc("/book/fig5").href == "../fig5.md"
    assert book.ref("sec-cost") == "What the optimal filter costs"
    assert book.ref("below <sec-resample-move>") == "below"
    # Theorems as sphinx-proof's {prf:ref} names them, numbered in their own count.
    assert book.prf_ref("thm-1") == "Theorem 1"
    assert book.prf_ref("the theorem <thm-1>") == "the theorem"
    with pytest.raises(ValueError, match="theorem 'thm-9': no labelled theorem"):
        book.prf_ref("thm-9")


@pytest.mark.parametrize(
    "call",
    ['cite_t("nobody2000")', 'eq("eq-99")', 'numref("fig-none")', 'doc("nopage")', 'ref("x")'],
)
def test_an_unknown_target_is_refused_by_name(book, call):
    name = re.search(r'"(.*)"', call).group(1)
    with pytest.raises(ValueError, match=re.escape(repr(name))):
        eval(call, book.functions())


def test_outside_the_book_a_reference_says_why_it_is_not_resolved(tmp_path):
    with pytest.raises(ValueError, match="no _toc.yml at or above it"):
        crossref.BookReferences(tmp_path).eq("eq-1")


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_every_reference_of_a_page_resolves(book, page):
    for function, content in REFERENCE.findall(page.read_text(encoding="utf-8")):
        assert function in crossref.ROLES, f"{page.name}: {function}({content!r})"
        getattr(book, function)(content)


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_a_page_uses_only_what_jupyterlab_renders(page):
    text = CODE_CELL.sub("", page.read_text(encoding="utf-8"))
    used = set(ROLE.findall(text)) | {name for _, name in DIRECTIVE.findall(text)}
    unsupported = used - LAB_ROLES - LAB_DIRECTIVES - NOT_FOR_LAB.get(page.stem, set())
    assert not unsupported, (
        f"{page.name}: {sorted(unsupported)} are not rendered in JupyterLab: write references "
        "as {eval} calls (tools/myst_roles.py) and glued figures as {figure} of {eval}`name`"
    )


def test_page_equations_numbers_a_page_s_equations_as_the_book(book):
    assert book.page_equations("book/fig2") == [("eq-17", 17)]
    assert [n for _, n in book.page_equations("book/filters")] == list(range(5, 13))
    assert book.page_equations("book/intro") == []
    with pytest.raises(ValueError, match="page 'book/nowhere': no page of the book"):
        book.page_equations("book/nowhere")


def test_the_toc_order_numbers_a_figure_or_equation_once_each():
    text = "# T\n\n$$\nx\n$$ (eq-a)\n\n```{figure}\n:name: fig-a\n\n{eval}`f`\n\nC.\n```\n"
    text += "\n(sec-a)=\n## S\n\n```{math}\n:label: eq-b\ny\n```\n\n$$\nz\n$$\n"
    text += "\n```{prf:theorem}\n:label: thm-a\n\nP.\n```\n\n```{prf:proof}\nQ.\n```\n"
    assert crossref.scan_page(text) == {
        "title": "T",
        "equations": ["eq-a", "eq-b"],
        "figures": ["fig-a"],
        "theorems": ["thm-a"],
        "sections": {"sec-a": "S"},
    }
    toc = {"root": "a", "parts": [{"chapters": [{"file": "b", "sections": [{"file": "c"}]}]}]}
    assert crossref.toc_pages(toc) == ["a", "b", "c"]


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_no_code_cell_rebinds_a_reference_function(page):
    """The functions that GlueLog binds stay bound: no cell of the page assigns their names."""
    import ast

    for cell in CODE_CELL.finditer(page.read_text(encoding="utf-8")):
        lines = cell.group(0).strip().splitlines()[1:-1]  # without the fences
        code = "\n".join(line for line in lines if not line.startswith(":"))
        bound = {
            node.id
            for node in ast.walk(ast.parse(code.replace("%", "#")))
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store)
        }
        assert not bound & set(crossref.ROLES), f"{page.name}: {bound & set(crossref.ROLES)}"
