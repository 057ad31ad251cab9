"""The book's pages within their budgets: prose words, shown code, glue out of sight.

``tools/prose.py`` measures a page as its reader meets it: at most 2,500 words of
prose on a page and 33,200 in the book, no shown code line over 88 characters,
and no cell the book shows that glues (gluing is plumbing: the book hides those
cells and a notebook shows them).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import prose  # noqa: E402

PAGES = prose.pages()


def test_the_book_has_pages():
    assert len(PAGES) >= 20


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_each_page_is_within_its_budgets(page):
    assert prose.faults(page) == []


def test_the_book_is_within_its_budget_of_words():
    total = sum(prose.prose_words(p.read_text()) for p in PAGES)
    assert total <= prose.BOOK_WORDS, f"{total} words of prose in the book"


PAGE = """---
jupytext:
  formats: md:myst
---

# A title of four words

Two sentences here. The depth is {eval}`depth` with $\\rho$ small.

$$
x = y + z
$$

```{code-cell} ipython3
import numpy as np

# the mean
m = np.mean([1, 2])
glue("m", f"{m:.1f}", display=False)
fig = draw(m)
glue("fig", fig, display=False)
plt.close(fig)
```

```{code-cell} ipython3
:tags: [remove-cell]

glued.show()
```

```{code-cell} ipython3
:tags: [hide-input]

glue("only", "1", display=False)
```

:::{note}
:class: dropdown
Three more words.
:::
"""


def test_prose_counts_words_outside_code_math_and_options():
    # "A title of four words" 5, "Two sentences here." 3, "The depth is x with x small." 7,
    # "Three more words." 3
    assert prose.prose_words(PAGE) == 18


def test_hide_glue_moves_the_glue_out_of_shown_cells(tmp_path):
    page = tmp_path / "p.md"
    page.write_text(PAGE)
    assert len(prose.faults(page)) == 2  # two shown cells glue
    assert prose.hide_glue(page) == 2
    text = page.read_text()
    assert prose.faults(page) == []
    cells = prose.cells(text)
    shown = [c for c in cells if prose.shown(c[2])]
    assert ["\n".join(c[3]).strip() for c in shown] == [
        "import numpy as np\n\n# the mean\nm = np.mean([1, 2])\nfig = draw(m)"
    ]
    hidden = ["\n".join(c[3]) for c in cells if not prose.shown(c[2])]
    assert 'glue("m"' in hidden[0] and "plt.close(fig)" in hidden[0]
    assert hidden[0].rstrip().endswith("glued.show()")
    assert hidden[1].strip() == 'glue("only", "1", display=False)'
    assert prose.prose_words(text) == prose.prose_words(PAGE)


def test_a_long_shown_line_is_a_fault_named_by_its_line(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("# T\n\n```{code-cell} ipython3\nx = 1\ny = '" + "a" * 90 + "'\n```\n")
    assert prose.faults(page) == ["p.md:5: a shown code line of 96 characters"]


def test_directives_are_read_whole_with_their_options_and_tags():
    text = (
        "````{exercise}\n:label: ex-a\n\n```{code-cell} ipython3\nx = 1\n```\n````\n"
        "```{code-cell} ipython3\n:tags: [hide-input, 'remove-output']\n\nassert x\n```\n"
        "```python\n```{code-cell}\n```\n"
    )
    found = prose.directives(text)
    assert [(d.name, d.first, d.last) for d in found] == [
        ("exercise", 0, 6),
        ("code-cell", 7, 11),
        ("", 12, 14),
    ]
    assert found[0].options == {"label": "ex-a"} and found[0].body[1] == "```{code-cell} ipython3"
    assert prose.tags(found[1].options) == ["hide-input", "remove-output"]
    assert prose.cells(text) == [(7, 11, ["hide-input", "remove-output"], ["", "assert x"])]
