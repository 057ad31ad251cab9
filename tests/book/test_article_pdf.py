"""Checks of the built replication article, ``_build/article/article.pdf`` (``make article``,
which ``make builds`` runs beside the book's builds): its length, its figures, that every
number in its text is one the code computed, and that the HTML book ships it.

Reads the PDF's text with poppler's ``pdftotext`` and its page count with ``pdfinfo``.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import article  # noqa: E402

PDF = ROOT / "_build" / "article" / "article.pdf"
HTML_DOWNLOADS = ROOT / "_build" / "html" / "downloads"
#: The pages ReScience C allows a replication article.
PAGES = (4, 12)


@pytest.fixture(scope="module")
def pdf() -> Path:
    if not PDF.is_file():
        pytest.skip(f"no {PDF.relative_to(ROOT)}: run `make article` (or `make builds`)")
    for tool in ("pdftotext", "pdfinfo"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} not found (Debian: poppler-utils)")
    return PDF


@pytest.fixture(scope="module")
def text(pdf) -> str:
    return subprocess.run(
        ["pdftotext", "-layout", str(pdf), "-"], check=True, capture_output=True, text=True
    ).stdout


def test_the_article_has_four_to_twelve_pages(pdf):
    info = subprocess.run(["pdfinfo", str(pdf)], check=True, capture_output=True, text=True)
    pages = int(re.search(r"^Pages:\s+(\d+)", info.stdout, re.M).group(1))
    assert PAGES[0] <= pages <= PAGES[1], f"the article has {pages} pages"


def test_the_article_has_its_title_sections_and_figures(text, pdf):
    assert "[Re] Filter based estimates of depth" in text
    for heading in ("Introduction", "Methods", "Results", "Discussion", "Computing environment"):
        assert heading in text, f"no section {heading}"
    for name in article.FIGURES:
        assert (pdf.parent / name).is_file(), f"{name} is not beside the article"
    assert "Built on " in text, "the article states no environment"


def test_every_decimal_in_the_articles_text_is_a_computed_value(text):
    values = {n.text for n in article.numbers()}
    # the page of the figures is left out: their axes' ticks are the figure code's
    text = "\f".join(page for page in text.split("\f") if "Figures 2–6 reproduced" not in page)
    body = text[: text.index("Where each number comes from")]  # the appendix lists sources
    body = body[body.index("Abstract") :]
    body = body[: body.index("Computing environment")]  # versions and the processor
    decimals = set(re.findall(r"(?<![\w.])\d+\.\d+(?![\w.])", body))
    stray = sorted(d for d in decimals if d not in values and not any(d in v for v in values))
    assert not stray, f"decimals in the article that no computation gives: {stray}"


def test_the_html_book_ships_the_article(pdf):
    shipped = HTML_DOWNLOADS / "article.pdf"
    if not HTML_DOWNLOADS.is_dir():
        pytest.skip("no built HTML book: run `make builds`")
    assert shipped.is_file() and shipped.read_bytes() == pdf.read_bytes()


def test_the_article_has_no_overfull_line(pdf):
    log = pdf.with_suffix(".log")
    assert log.is_file(), f"no {log.name} beside the article"
    overfull = re.findall(
        r"^Overfull \\[hv]box \(([\d.]+)pt too \w+\)", log.read_text(errors="replace"), re.M
    )
    assert not overfull, f"overfull boxes in the article: {overfull} pt"


def test_the_provenance_appendix_takes_at_most_two_pages(pdf):
    pages = subprocess.run(
        ["pdftotext", "-layout", str(pdf), "-"], check=True, capture_output=True, text=True
    ).stdout.split("\f")
    pages = [p for p in pages if p.strip()]
    first = next(i for i, p in enumerate(pages) if "Where each number comes from" in p)
    assert len(pages) - first <= 2, f"the appendix spans {len(pages) - first} pages"
