"""No number is typed in the book's prose: each is glued from the code, or is
an equation, figure or section number, a year of a citation, or a value quoted
from the paper and listed in :data:`depthcore.scenarios.PROSE_QUOTES`.

The scan strips from every page (``book/*.md``) what is not prose: the front
matter, code cells and other fenced blocks' options, math (``$...$`` and
``$$...$$``), roles (``{glue:text}`...```, ``{eq}`...```, ``{cite:p}`...```
and the like), inline code, labels and anchors (``(sec-x)=``, ``:name:``),
link targets and HTML comments. Every digit left must belong to an allowed
pattern below.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from depthcore import calibration, study
from depthcore.scenarios import PROSE_QUOTES

BOOK = Path(__file__).resolve().parent.parent / "book"
PAGES = sorted(BOOK.glob("*.md"))

#: Nominal interval levels defined in code: the study's central intervals
#: (``study.LEVELS``, also written as probabilities, "0.68"), the coverage levels
#: of ``calibration.LEVELS``, and the ends of the calibration curves'
#: ``study.CALIBRATION_LEVELS`` ("from 5 % to 99 %").
_PERCENT = sorted(
    {
        round(100 * float(p))
        for p in (
            *study.LEVELS,
            *calibration.LEVELS,
            study.CALIBRATION_LEVELS[0],
            study.CALIBRATION_LEVELS[-1],
        )
    }
)
NOMINAL = [rf"(?<![\d.]){p}\s*%" for p in _PERCENT] + [
    r"(?<![\d.])" + re.escape(f"{float(p):.2f}") + r"(?!\d)" for p in study.LEVELS
]
#: A number: digits with an optional decimal part.
_NUM = r"\d+(?:\.\d+)?"
#: Lists and ranges of numbers: "2", "2–6", "2, 3, 5 and 6", "2 and 4".
_LIST = rf"{_NUM}(?:\s*(?:–|-|,|and|or|to)\s*{_NUM})*"
#: The allowed uses of digits in prose, each with its reason.
ALLOWED = {
    # the paper's equations, (1) to (24), cited as "Eq. (12)", "Eqs. (13)–(16)",
    # "measurements (17)" or "(19)–(24)"
    "equation": r"\((?:[1-9]|1\d|2[0-4])\)(?:\s*(?:–|-|,|and|to)\s*\((?:[1-9]|1\d|2[0-4])\))*",
    # figure numbers of the paper and the book: "Figure 2", "Figures 2–6", "Fig. 5"
    "figure": rf"\b(?:Figures?|Figs?\.)\s+{_LIST}",
    # sections and chapters of the textbook and the book: "Sect. 19.4", "section 19.5"
    "section": r"\b(?:Sects?\.|[Ss]ections?|[Cc]hapters?|§)\s*\d+(?:\.\d+)*"
    r"(?:\s*(?:–|-|,|and|or|to)\s*\d+(?:\.\d+)*)*",
    # the paper's theorem and its reference list, "Theorem 1", "reference [6]"
    "theorem": rf"\bTheorem\s+{_NUM}",
    "paper reference": r"\[\d+\]",
    # a year beside an author, a conference or in parentheses: "BMVC 1990", "(1990)"
    "year": r"(?:\b[A-Z][A-Za-z&.]*\s+|\()(?:19[5-9]\d|20[0-3]\d)\b",
    # the pages of a bibliographic entry, "pp. 349–354"
    "pages": rf"\bpp\.\s*{_NUM}\s*(?:–|-)\s*{_NUM}",
    # the model's time indices (the paper's frames 1, 2, 3): "time 3", "times 1, 2 and 3",
    # "time-1 state", "at the first frame"
    "time": rf"\b(?:times?|frames?)[\s-]+{_LIST}",
    # numbered headings of a page, "## 3. ..."
    "heading": r"^#+\s+\d+\.",
    # the Python version the environment is built with
    "python": r"\bPython\s+3\.\d+",
    # the nominal levels of the intervals scored by depthcore.study and
    # depthcore.calibration, as percentages ("68 %") or probabilities ("0.68")
    "level": "|".join(sorted(NOMINAL, key=len, reverse=True)),
}


def prose(text: str) -> str:
    """The prose of a MyST page: everything that is not code, math, role or label."""
    text = re.sub(r"\A---\n.*?\n---\n", "", text, flags=re.S)  # front matter
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    # code cells and fenced blocks without a caption: dropped whole
    text = re.sub(r"^(`{3,})\{code-cell\}.*?^\1\s*$", "", text, flags=re.S | re.M)
    text = re.sub(r"^(`{3,})(?!\{).*?^\1\s*$", "", text, flags=re.S | re.M)
    # directives (glue:figure, bibliography, ...): keep their body, drop the
    # opening line with its argument and their ":option:" lines
    text = re.sub(r"^`{3,}\{[^}]*\}.*$", "", text, flags=re.M)
    text = re.sub(r"^:[\w-]+:.*$", "", text, flags=re.M)
    text = re.sub(r"^`{3,}\s*$", "", text, flags=re.M)
    text = re.sub(r"\$\$.*?\$\$(?:\s*\([\w-]+\))?", "", text, flags=re.S)  # display math
    text = re.sub(r"\{[\w:+-]+\}`[^`]*`", "", text)  # roles
    text = re.sub(r"``.*?``|`[^`]*`", "", text)  # inline code
    text = re.sub(r"(?<!\\)\$[^$]+?(?<!\\)\$", "", text, flags=re.S)  # inline math
    text = re.sub(r"^\([\w-]+\)=\s*$", "", text, flags=re.M)  # anchors
    text = re.sub(r"\]\([^)]*\)", "]", text)  # link targets
    text = re.sub(r"<[^>]*>", " ", text)  # HTML tags and their attributes
    return text


def stray_numbers(text: str) -> list[str]:
    """The digits of ``text``'s prose that no allowed pattern or quote accounts for."""
    body = prose(text)
    for quote in PROSE_QUOTES:
        body = body.replace(quote, " ")
    for pattern in ALLOWED.values():
        body = re.sub(pattern, " ", body, flags=re.M)
    return [line.strip() for line in body.splitlines() if re.search(r"\d", line)]


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_no_typed_numbers_in_prose(page):
    stray = stray_numbers(page.read_text(encoding="utf-8"))
    assert not stray, f"{page.name}: numbers typed in prose (glue them): {stray}"


def test_the_scan_catches_a_typed_number_and_spares_the_allowed():
    page = (
        "Some text with 31 units.\n\n"
        "Eqs. (13)–(16) and Figure 2, Sect. 19.4, Theorem 1, BMVC 1990,\n"
        "$\\rho = 1/200$, {glue:text}`x_1`, `model.MU_17`, {eq}`eq-17`.\n"
        "```{code-cell} ipython3\nx = 42\n```\n"
    )
    assert stray_numbers(page) == ["Some text with 31 units."]


def test_every_quote_is_in_some_page_and_has_a_source():
    text = "\n".join(prose(p.read_text(encoding="utf-8")) for p in PAGES)
    for quote, source in PROSE_QUOTES.items():
        assert quote in text, f"{quote!r} is no longer quoted: drop it from PROSE_QUOTES"
        assert source.strip(), f"{quote!r} has no source"
