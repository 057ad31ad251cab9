"""Each figure of the book printed once: in its captioned figure, never also as a cell's output.

A page draws a figure in a code cell and glues it into a ``{figure}`` directive with its
caption. The drawing cell's own output is then a second copy, which the HTML book and the PDF
would print above the captioned one; so every cell whose executed output holds an image is
kept out of the book's output (``remove-output``, or ``remove-cell`` for a gluing cell). The
executed pages are the committed references, ``book/_nbval/``, which ``make notebooks`` checks
against the pages.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

REFERENCES = Path(__file__).resolve().parents[1] / "book" / "_nbval"
PAGES = sorted(REFERENCES.glob("*.ipynb"))
HIDDEN = {"remove-output", "remove-cell"}
IMAGES = ("image/png", "image/svg+xml", "application/pdf")


def shown_images(notebook: dict) -> list[str]:
    """The first line of each code cell whose output holds an image the book would print."""
    out = []
    for cell in notebook["cells"]:
        if cell["cell_type"] != "code":
            continue
        if HIDDEN & set(cell.get("metadata", {}).get("tags", [])):
            continue
        data = [o.get("data", {}) for o in cell.get("outputs", [])]
        if any(kind in d for d in data for kind in IMAGES):
            source = "".join(cell["source"]).strip().splitlines()
            out.append(source[0] if source else "")
    return out


def test_the_references_are_there():
    assert len(PAGES) > 30


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_no_cell_the_book_shows_prints_a_figure(page):
    shown = shown_images(json.loads(page.read_text(encoding="utf-8")))
    assert not shown, f"{page.stem}: cells that print a figure in the book: {shown}"


def test_a_cell_that_prints_a_figure_is_found():
    """The check fails on a cell whose image output the book would print, and passes on it
    once its output is removed."""
    cell = {
        "cell_type": "code",
        "metadata": {"tags": ["hide-input"]},
        "source": ["fig = paper.figure('fig2')\n"],
        "outputs": [{"output_type": "display_data", "data": {"image/png": "iVBOR"}}],
    }
    assert shown_images({"cells": [cell]}) == ["fig = paper.figure('fig2')"]
    cell["metadata"]["tags"].append("remove-output")
    assert shown_images({"cells": [cell]}) == []
