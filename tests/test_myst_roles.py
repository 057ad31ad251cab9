"""tools/myst_roles.py: the pages paste their numbers with ``{eval}`` roles."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import myst_roles  # noqa: E402

PAGE = """# A page

Its mean is {glue:text}`a_mean` and {eval}`b_sd`.

```{code-cell} ipython3
print("{glue:text}`kept`")
```

| x | y |
|---|---|
| {glue:text}`a_1` | {glue:text}`a_2` |
"""


def test_convert_rewrites_the_text_and_leaves_code_cells():
    out = myst_roles.convert(PAGE)
    assert "Its mean is {eval}`a_mean` and {eval}`b_sd`." in out
    assert "| {eval}`a_1` | {eval}`a_2` |" in out
    assert 'print("{glue:text}`kept`")' in out
    assert myst_roles.convert(out) == out  # idempotent


@pytest.mark.parametrize("role", ["{glue:text}`a:.2f`", "{glue:text}`fig2::a`"])
def test_convert_refuses_what_the_kernel_cannot_evaluate(role):
    with pytest.raises(ValueError, match=r"page:3: .* is not a Python name"):
        myst_roles.convert(f"# A page\n\n{role}\n")


def test_every_page_pastes_its_numbers_with_eval(capsys):
    assert myst_roles.main(["--check"]) == 0, capsys.readouterr().out


KERNEL_PAGE = """# A page

```{code-cell} ipython3
glued = GlueLog()
```

As {cite:t}`maybank1990` shows {cite:p}`a2001,b2002`, Eq. {eq}`eq-7`, {numref}`fig-2`,
{ref}`below <sec-x>` and {doc}`the introduction <intro>`.

```{glue:figure} fig2_figure
:name: fig-2
:width: 100%

The caption, {eval}`a_mean` and {eq}`eq-17`.
```
"""


def test_convert_writes_references_and_glued_figures_for_the_kernel():
    out = myst_roles.convert(KERNEL_PAGE)
    assert (
        'As {eval}`cite_t("maybank1990")` shows {eval}`cite_p("a2001,b2002")`, '
        'Eq. {eval}`eq("eq-7")`, {eval}`numref("fig-2")`,\n'
        '{eval}`ref("below <sec-x>")` and {eval}`doc("the introduction <intro>")`.'
    ) in out
    assert out.endswith(
        "```{figure}\n:name: fig-2\n:width: 100%\n:enumerated: false\n\n"
        "{eval}`fig2_figure`\n\n"
        'The caption, {eval}`a_mean` and {eval}`eq("eq-17")`.\n```\n'
    )
    assert "glue:figure" not in out and "{cite:" not in out
    assert myst_roles.convert(out) == out  # idempotent


def test_convert_leaves_the_references_of_a_page_without_a_kernel():
    page = KERNEL_PAGE.replace("glued = GlueLog()", "x = 1")
    assert myst_roles.convert(page) == page


DISPLAYS = """# A page

$$
a = 1
$$ (eq-a)

$$
b = 2
$$

* an item,

  $$
  c = 3
  $$
"""


def test_convert_leaves_a_labelled_display_and_unnumbers_the_others_for_jupyterlab():
    out = myst_roles.convert(DISPLAYS)
    assert "$$\na = 1\n$$ (eq-a)\n" in out
    assert "```{math}\n:enumerated: false\nb = 2\n```\n" in out
    assert "  ```{math}\n  :enumerated: false\n  c = 3\n  ```\n" in out
    assert out.count("$$") == 2
    assert myst_roles.convert(out) == out  # idempotent


def test_convert_refuses_a_display_left_open():
    with pytest.raises(ValueError, match=r"page:3: the display equation \(\$\$\) is not closed"):
        myst_roles.convert("# A page\n\n$$\nx = 1\n")


HEADER = "---\njupytext:\n  formats: md:myst\n---\n\n"


def test_lab_numbering_writes_corrects_and_removes_the_front_matter():
    page = HEADER + "# A page\n\nText.\n"
    numbered = myst_roles.lab_numbering(page, 17)
    assert numbered == (
        HEADER + "```yaml\nnumbering:\n  equation:\n    start: 17\n```\n\n# A page\n\nText.\n"
    )
    assert myst_roles.lab_numbering(numbered, 17) == numbered  # idempotent
    assert myst_roles.lab_numbering(numbered, 5) == numbered.replace("17", "5")
    assert myst_roles.lab_numbering(numbered, None) == page


def test_every_page_with_equations_starts_its_count_at_its_first_in_the_book():
    """The front matter of the pages (checked by --check above) holds the book's numbers."""
    import json

    from depthbook.crossref import BookReferences

    paper = json.loads((ROOT / "tests" / "data" / "equation_labels.json").read_text())
    book = BookReferences(ROOT)
    starts = {}
    for page in sorted((ROOT / "book").glob("*.md")):
        found = myst_roles.LAB_FRONTMATTER_FOUND.match(
            myst_roles.HEADER.sub("", page.read_text(encoding="utf-8"))
        )
        equations = book.page_equations(f"book/{page.stem}")
        assert (found is None) == (not equations), f"{page.name}: front matter {found}"
        if found:
            starts[page.stem] = int(found.group(1))
            # The page's equations follow its first, one by one, as in the book and the paper.
            numbers = [number for _, number in equations]
            assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))
            assert [int(paper[label]) for label, _ in equations] == numbers
    assert starts == {
        "model": 1,
        "filters": 5,
        "marginals": 13,
        "fig2": 17,
        "fig3": 18,
        "appendix": 19,
    }
