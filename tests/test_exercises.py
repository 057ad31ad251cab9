"""The book's exercises, read from the pages' sources: enough of them, each with its solution.

An exercise is a ``{exercise}`` directive with a ``:label:``; its solution is gated,
``{solution-start} LABEL`` with ``:class: dropdown`` up to ``{solution-end}``, and
holds at least one code cell. The solution's code the reader is shown is the lesson:
a code cell in it that is not tagged ``hide-input`` or ``remove-*`` holds no
``assert`` and no ``glue(`` (its checks go in a ``hide-input`` cell after it). A
page's exercises sit under one ``## Exercises`` heading, after its main text: no
other section follows it. The book has at least :data:`AT_LEAST` exercises, at least
:data:`BEYOND_AT_LEAST` of them in the chapters beyond the paper (``beyond_*``), and
their labels are unique.
"""

from __future__ import annotations

import re
import sys
from collections import Counter
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import prose  # noqa: E402

BOOK = prose.BOOK
PAGES = prose.pages()
AT_LEAST, BEYOND_AT_LEAST = 14, 6

_CHECKS = re.compile(r"^\s*assert\b|\bglue\(")


def exercises(text):
    """The labels of the page's exercises, in order."""
    return [d.options.get("label") for d in prose.directives(text) if d.name == "exercise"]


def faults(text):
    """What is wrong with the exercises of one page's source; empty when nothing is."""
    found, labels = [], exercises(text)
    if None in labels:
        found.append("an exercise without a label")
    labels = [label for label in labels if label]
    solutions, open_label, cells = Counter(), None, 0
    for name, argument, options, body, line, _ in prose.directives(text):
        if name == "solution-start":
            if open_label is not None:
                found.append(f"line {line + 1}: solution {argument} opens inside {open_label}")
            solutions[argument] += 1
            open_label, cells = argument, 0
            if options.get("class") != "dropdown":
                found.append(f"solution {argument} is not gated (:class: dropdown)")
        elif name == "solution-end":
            if open_label is None:
                found.append(f"line {line + 1}: a solution ends that never started")
            elif cells == 0:
                found.append(f"solution {open_label} holds no code cell")
            open_label = None
        elif name == "code-cell" and open_label is not None:
            cells += 1
            shown = not any(
                t.startswith("remove-") or t == "hide-input" for t in prose.tags(options)
            )
            if shown and any(_CHECKS.search(code) for code in body):
                found.append(f"line {line + 1}: solution {open_label} shows assert or glue(")
    if open_label is not None:
        found.append(f"solution {open_label} never ends")
    for label in labels:
        if solutions[label] != 1:
            found.append(f"exercise {label} has {solutions[label]} solutions")
    found += [f"solution {label} answers no exercise" for label in solutions if label not in labels]
    found += [f"label {label} used {n} times" for label, n in Counter(labels).items() if n > 1]
    if labels:
        headings = [i for i, s in enumerate(text.splitlines()) if s.startswith("## ")]
        exercises_at = [i for i in headings if text.splitlines()[i].strip() == "## Exercises"]
        first = next(d.first for d in prose.directives(text) if d.name == "exercise")
        if len(exercises_at) != 1:
            found.append(f"{len(exercises_at)} '## Exercises' headings")
        elif exercises_at[0] > first or headings[-1] != exercises_at[0]:
            found.append("the exercises are not under the last heading, '## Exercises'")
    return found


def book_labels():
    return {page.stem: exercises(page.read_text()) for page in PAGES}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_each_pages_exercises_have_one_gated_solution_with_code_that_teaches(page):
    assert faults(page.read_text()) == []


def test_the_book_has_enough_exercises_with_unique_labels():
    labels = book_labels()
    every = [label for page in labels.values() for label in page]
    beyond = [
        label for stem, page in labels.items() if stem.startswith("beyond_") for label in page
    ]
    assert len(every) >= AT_LEAST, every
    assert len(beyond) >= BEYOND_AT_LEAST, beyond
    assert len(set(every)) == len(every), Counter(every).most_common(3)


def test_the_intros_student_route_ends_every_page_after_the_first_with_exercises():
    intro = (BOOK / "intro.md").read_text()
    route = intro[intro.index("*A student's:*") : intro.index("ends with exercises")]
    pages = re.findall(r'doc\("(\w+)"\)', route)
    assert "marginals" in pages and "notation" in pages
    labels = book_labels()
    assert [p for p in pages[1:] if p != "notation" and not labels[p]] == []


GOOD = """# A page

Text.

## Exercises

```{exercise}
:label: ex-a

Compute something.
```

```{solution-start} ex-a
:class: dropdown
```

Why it is so.

```{code-cell} ipython3
answer = 6 * 7
print(answer)
```

```{code-cell} ipython3
:tags: [hide-input]

assert answer == 42
```

```{solution-end}
```
"""

#: Each mutation of GOOD (every occurrence replaced), and words of the fault it must raise.
MUTANTS = {
    "assert shown": (("print(answer)\n", "print(answer)\nassert answer\n"), "shows assert"),
    "glue shown": (("print(answer)\n", "glue('x', answer)\n"), "shows assert or glue"),
    "check cell shown": ((":tags: [hide-input]\n", ""), "shows assert"),
    "no code cell": (("```{code-cell} ipython3", "```{note}"), "no code"),
    "not gated": ((":class: dropdown\n", ""), "not gated"),
    "no solution": (("```{solution-start} ex-a", "```{solution-start} ex-b"), "0 solutions"),
    "no label": ((":label: ex-a\n", ""), "without a label"),
    "never ends": (("```{solution-end}\n```\n", ""), "never ends"),
    "no heading": (("## Exercises\n", ""), "'## Exercises' headings"),
    "heading after": (("## Exercises\n", "## Exercises\n\n## More\n"), "last heading"),
}


def test_a_good_page_has_no_faults():
    assert faults(GOOD) == [] and exercises(GOOD) == ["ex-a"]


@pytest.mark.parametrize("mutant", MUTANTS)
def test_a_mutated_page_is_caught(mutant):
    (old, new), fault = MUTANTS[mutant]
    assert old in GOOD
    found = faults(GOOD.replace(old, new))
    assert any(fault in f for f in found), found


def test_two_solutions_and_a_repeated_label_are_caught():
    solution = GOOD[GOOD.index("```{solution-start}") :]
    twice = GOOD + "\n" + solution
    assert any("2 solutions" in f for f in faults(twice))
    exercise = GOOD[GOOD.index("```{exercise}") : GOOD.index("```{solution-start}")]
    again = GOOD + "\n" + exercise + solution
    assert any("used 2 times" in f for f in faults(again))
