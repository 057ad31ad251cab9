"""The built book numbers the paper's Figures 1-6 as the paper does.

``tests/data/figure_numbers.json`` lists the paper's figures: the label
(``:name: fig-N``) of each, the number it must carry and the page that shows
it. In ``_build/html`` each must render as ``Figure N`` on that page; no other
figure of the book may carry one of the numbers 1-6 (the book's own figures
come after them, or carry no number at all), and no caption repeats its own
number ("Figure 2 Figure 2 ...").

A numbered figure renders as::

    <figure ... id="fig-2"> ... <figcaption><p><span class="caption-number">Figure 2 </span>
"""

from __future__ import annotations

import re
from collections import Counter

FIGURE_RE = re.compile(r'<figure[^>]*\bid="([^"]+)"[^>]*>(.*?)</figure>', re.DOTALL)
CAPTION_RE = re.compile(
    r'<span class="caption-number">\s*(\S+)\s+([^<\s]+)\s*</span>\s*'
    r'<span class="caption-text">(.*?)</span>',
    re.DOTALL,
)


def numbered_figures(pages: dict[str, str]) -> list[tuple[str, str, str, str, str]]:
    """(label, word, number, caption text, page) of every numbered figure in the HTML."""
    found = []
    for page, html in pages.items():
        for label, body in FIGURE_RE.findall(html):
            for word, number, text in CAPTION_RE.findall(body):
                found.append((label, word, number, re.sub(r"<[^>]+>", "", text), page))
    return found


def test_the_papers_figures_carry_the_papers_numbers(html_pages, load_figure_numbers):
    found = numbered_figures(html_pages)
    for label, where in load_figure_numbers.items():
        rendered = [(word, number, page) for lab, word, number, _, page in found if lab == label]
        assert rendered == [("Figure", where["number"], where["page"])], (
            f"{label} renders as {rendered}, expected Figure {where['number']} on {where['page']}"
        )


def test_no_other_figure_takes_the_papers_numbers(html_pages, load_figure_numbers):
    found = numbered_figures(html_pages)
    assert found, "no numbered figure found in _build/html"
    papers = {where["number"] for where in load_figure_numbers.values()}
    stray = [
        (label, number, page)
        for label, _, number, _, page in found
        if number in papers and label not in load_figure_numbers
    ]
    assert not stray, f"figures that take one of the paper's numbers: {stray}"
    twice = [n for n, count in Counter(number for _, _, number, _, _ in found).items() if count > 1]
    assert not twice, f"figure numbers shown more than once: {twice}"


def test_no_caption_repeats_its_number(html_pages):
    doubled = [
        (label, number, page)
        for label, word, number, text, page in numbered_figures(html_pages)
        if re.match(rf"\s*(Figure|Fig\.)\s*{re.escape(number)}\b", text)
    ]
    assert not doubled, f"captions that repeat their own number: {doubled}"
