"""The PDF of the book (``make pdf``) numbers the paper's equations and figures as the paper does.

Reads the text of ``_build/latex/depthcore.pdf`` with poppler's ``pdftotext``
and checks that

* the displayed equations carry the numbers (1), (2), ..., (24), in this order
  and no other (an equation's number is set at the right margin, after a gap);
* the paper's Figures 1-6 (the figures labelled ``fig-1`` ... ``fig-6`` in
  ``book/*.md``) are captioned "Figure N: ..." with the paper's numbers, and
  every other captioned figure of the book has a number above 6;
* no LaTeX or MyST source leaks into the text (``\\mathbf``, ``$``, ``{glue``,
  ``??`` for an unresolved reference);
* the HTML book ships the same PDF.

Without the PDF or pdftotext the checks are skipped with a message, and fail
under CI (``CI=true``).
"""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest
from conftest import HTML_DIR, ROOT

PDF = ROOT / "_build" / "latex" / "depthcore.pdf"
FIGURE_RE = re.compile(
    r"^```\{glue:figure\}\s*\S+\s*\n:name:\s*(\S+)\s*\n(?::\w+:.*\n)*\s*\n(.*?)\n```",
    re.MULTILINE | re.DOTALL,
)
EQNO_RE = re.compile(r"\S.* {6,}\((\d+)\)\s*$", re.MULTILINE)
RAW_RES = (
    re.compile(r"\\[A-Za-z]{2,}"),  # a LaTeX command
    re.compile(r"\$"),  # MyST/LaTeX math delimiters
    re.compile(r"\{(glue|eq|doc|cite|numref|math|ref)[:}]"),  # MyST roles
    re.compile(r"\?\?"),  # an unresolved reference
)


def pdftotext(*args: str) -> str:
    return subprocess.run(
        ["pdftotext", *args, str(PDF), "-"], capture_output=True, text=True, check=True, timeout=120
    ).stdout


@pytest.fixture(scope="module")
def pdf(missing_prerequisite):
    if not PDF.exists():
        missing_prerequisite(
            f"{PDF.relative_to(ROOT)} not found: run `make pdf` (TeX Live's xelatex)"
        )
    if shutil.which("pdftotext") is None:
        missing_prerequisite(
            "pdftotext not found (apt-get install poppler-utils): the PDF is not checked"
        )
    return PDF


@pytest.fixture(scope="module")
def layout_text(pdf) -> str:
    return pdftotext("-layout")


@pytest.fixture(scope="module")
def plain_text(pdf) -> str:
    """The PDF's text with every run of whitespace made one space, and straight apostrophes."""
    return " ".join(pdftotext().split()).replace("\u2019", "'")


def source_figures() -> list[tuple[str, str]]:
    """(label, first words of the caption) of every captioned figure of the book, in TOC order."""
    import check_notebooks

    found = []
    for entry in check_notebooks.toc_files():
        path = ROOT / (entry if entry.endswith(".md") else f"{entry}.md")
        for label, caption in FIGURE_RE.findall(path.read_text(encoding="utf-8")):
            words = re.split(r"[$`{(]", " ".join(caption.split()), maxsplit=1)[0].split()[:4]
            found.append((label, " ".join(words)))
    return found


def captions_in_pdf(plain_text: str) -> list[tuple[str, int]]:
    """(label, number) of every figure caption in the PDF, in the PDF's order.

    A caption is "Figure N: " followed by the first words of one of the
    book's captions; the captions appear in TOC order, each once, so the k-th
    caption found is the k-th figure of the sources.
    """
    figures = source_figures()
    starts = sorted({start for _, start in figures}, key=len, reverse=True)
    pattern = re.compile(r"Figure (\d+): (" + "|".join(map(re.escape, starts)) + ")")
    shown = [(m.group(2), int(m.group(1))) for m in pattern.finditer(plain_text)]
    assert [start for start, _ in shown] == [start for _, start in figures], (
        f"the PDF's figure captions {shown} are not the book's {figures}"
    )
    return [(label, number) for (label, _), (_, number) in zip(figures, shown, strict=True)]


def test_equations_are_numbered_1_to_24_in_order(layout_text):
    numbers = [int(n) for n in EQNO_RE.findall(layout_text)]
    assert numbers == list(range(1, 25)), f"equation numbers in the PDF: {numbers}"


def test_the_papers_figures_carry_the_papers_numbers(plain_text, load_figure_numbers):
    captions = captions_in_pdf(plain_text)
    for label, where in load_figure_numbers.items():
        shown = [number for lab, number in captions if lab == label]
        assert shown == [int(where["number"])], f"{label} is captioned Figure {shown} in the PDF"


def test_no_other_figure_takes_the_papers_numbers(plain_text, load_figure_numbers):
    papers = {int(where["number"]) for where in load_figure_numbers.values()}
    others = [
        number for label, number in captions_in_pdf(plain_text) if label not in load_figure_numbers
    ]
    assert others and min(others) > max(papers), f"the book's own figures are numbered {others}"
    assert len(set(others)) == len(others), f"figure numbers used twice: {others}"


def test_no_raw_latex_or_myst_in_the_text(plain_text):
    for pattern in RAW_RES:
        found = [
            plain_text[max(m.start() - 40, 0) : m.end() + 40] for m in pattern.finditer(plain_text)
        ]
        assert not found, f"{pattern.pattern!r} in the PDF's text: {found[:3]}"


def test_the_html_book_ships_this_pdf(pdf):
    shipped = HTML_DIR / "downloads" / "depthcore.pdf"
    assert shipped.is_file(), (
        f"{shipped.relative_to(ROOT)} not found: run `make pdf` before `make book`"
    )
    assert shipped.read_bytes() == pdf.read_bytes(), (
        "the HTML book ships another PDF than _build/latex's"
    )
