"""The built book shows the paper's equations with the paper's numbers.

Every equation label ``eq-N`` in the book's sources (``book/**/*.md``) must be
one of the paper's equations listed in ``tests/data/equation_labels.json``
(``eq-1`` ... ``eq-24``) and render in ``_build/html`` with its number there;
no other equation of the book may carry a number. Labels of the paper's
equations that no page writes yet are simply not checked.

Two ways of numbering are recognised in the HTML:

* Sphinx numbering of a labelled equation (``$$ ... $$ (eq-N)`` or a
  ``{math}`` directive with ``:label: eq-N``):
  ``<div ... id="equation-eq-N"><span class="eqno">(N)``;
* a MathJax ``\\tag{N}`` inside a starred environment after a ``(eq-N)=``
  target: ``<div class="math ..." id="eq-N">\\[ ... \\tag{N} ... \\]</div>``.
"""

from __future__ import annotations

import re
from collections import Counter

EQNO_RE = re.compile(r'id="equation-([^"]+)">\s*<span class="eqno">\(([^)<]+)\)')
MATH_DIV_RE = re.compile(r'<div class="math[^"]*"(?: id="([^"]*)")?>(.*?)</div>', re.DOTALL)
TAG_RE = re.compile(r"\\tag\*?\{([^}]*)\}")


def rendered_numbers(pages: dict[str, str]) -> list[tuple[str | None, str, str]]:
    """(label or None, number, page) for every numbered equation in the HTML."""
    found = []
    for page, html in pages.items():
        found += [(label, number, page) for label, number in EQNO_RE.findall(html)]
        for div_id, body in MATH_DIV_RE.findall(html):
            label = div_id.removeprefix("equation-") or None
            found += [(label, number, page) for number in TAG_RE.findall(body)]
    return found


def test_equation_labels_json_lists_the_papers_24_equations(expected_equation_numbers):
    assert expected_equation_numbers == {f"eq-{n}": str(n) for n in range(1, 25)}


def test_source_labels_are_the_papers_and_unique(equation_sources, expected_equation_numbers):
    assert equation_sources, "no equation label eq-N in book/*.md"
    unknown = [
        (label, page) for label, page in equation_sources if label not in expected_equation_numbers
    ]
    assert not unknown, f"labels that are not the paper's equations eq-1 ... eq-24: {unknown}"
    twice = [label for label, n in Counter(label for label, _ in equation_sources).items() if n > 1]
    assert not twice, f"labels defined more than once: {twice}"


def test_labelled_equation_renders_with_the_papers_number(
    equation_label, html_pages, expected_equation_numbers
):
    rendered = [
        (number, page)
        for label, number, page in rendered_numbers(html_pages)
        if label == equation_label
    ]
    expected = expected_equation_numbers.get(equation_label)
    assert rendered, f"{equation_label} is not rendered with a number in _build/html"
    assert [number for number, _ in rendered] == [expected], (
        f"{equation_label} renders as {rendered}, expected ({expected})"
    )


def test_no_other_numbered_equations(html_pages, equation_sources, expected_equation_numbers):
    labels = {label for label, _ in equation_sources}
    rendered = rendered_numbers(html_pages)
    assert rendered, "no numbered equation found in _build/html"
    stray = [
        (label, number, page)
        for label, number, page in rendered
        if label not in labels or expected_equation_numbers.get(label) != number
    ]
    assert not stray, f"numbered equations that are not the paper's, or misnumbered: {stray}"
    twice = [n for n, count in Counter(number for _, number, _ in rendered).items() if count > 1]
    assert not twice, f"equation numbers shown more than once: {twice}"
