"""No number is typed in the book's prose: each is glued from the code, or is
an equation, figure or section number, a year of a citation, or a value quoted
from the paper and listed in :data:`depthcore.problem.scenarios.PROSE_QUOTES`.

The scan strips from every page (``book/*.md``) what is not prose: the front
matter, code cells and other fenced blocks' options, math (``$...$`` and
``$$...$$``), roles (``{glue:text}`...```, ``{eq}`...```, ``{cite:p}`...```
and the like), inline code, labels and anchors (``(sec-x)=``, ``:name:``),
link targets and HTML comments. Every digit left must belong to an allowed
pattern below. The mathematics is read too: a number in it must be structure
(a single digit, an exponent or index), a number of frames, or a value quoted
from the paper and listed in :data:`depthcore.problem.scenarios.MATH_QUOTES`.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from depthcore.analysis import calibration
from depthcore.problem.scenarios import MATH_QUOTES, PROSE_QUOTES
from depthcore.studies import scores

BOOK = Path(__file__).resolve().parent.parent / "book"
PAGES = sorted(BOOK.glob("*.md"))

#: Nominal interval levels defined in code: the study's central intervals
#: (``study_scores.LEVELS``, also written as probabilities, "0.68"), the coverage levels
#: of ``calibration.LEVELS``, and the ends of the calibration curves'
#: ``study_scores.CALIBRATION_LEVELS`` ("from 5 % to 99 %").
_PERCENT = sorted(
    {
        round(100 * float(p))
        for p in (
            *scores.LEVELS,
            *calibration.LEVELS,
            scores.CALIBRATION_LEVELS[0],
            scores.CALIBRATION_LEVELS[-1],
        )
    }
)
NOMINAL = [rf"(?<![\d.]){p}\s*%" for p in _PERCENT] + [
    r"(?<![\d.])" + re.escape(f"{float(p):.2f}") + r"(?!\d)" for p in scores.LEVELS
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
    "time": rf"\b(?:[Tt]imes?|[Ff]rames?)[\s-]+{_LIST}",
    # numbered headings of a page, "## 3. ..."
    "heading": r"^#+\s+\d+\.",
    # the Python version the environment is built with
    "python": r"\bPython\s+3\.\d+",
    # the nominal levels of the intervals scored by depthcore.studies.monte_carlo and
    # depthcore.analysis.calibration, as percentages ("68 %") or probabilities ("0.68")
    "level": "|".join(sorted(NOMINAL, key=len, reverse=True)),
}


def fences(text: str, keep_directives: bool = True) -> str:
    """``text`` without its code cells and fenced blocks, line by line.

    A code cell, a plain fenced block (```` ``` ````, ```` ```text ````, the
    front matter for JupyterLab ```` ```yaml ````) or a display equation
    (```` ```{math} ````, read by :func:`mathematics`) is dropped whole. A
    directive (```` ```{figure} ````) keeps its body, the caption a reader
    sees, without its opening line, its ``:option:`` lines and its closing
    fence (or is dropped whole when ``keep_directives`` is false).
    """
    out, closing, keep = [], None, False
    for line in text.splitlines():
        if closing is not None:
            if re.fullmatch(closing, line):
                closing = None
            elif keep and not re.match(r"^:[\w-]+:", line):
                out.append(line)
            continue
        opening = re.match(r"^(`{3,}|~{3,})\s*(\{[^}]*\})?", line)
        if opening:
            closing = re.escape(opening.group(1)) + r"\s*"
            directive = opening.group(2)
            keep = (
                bool(directive) and directive not in ("{code-cell}", "{math}") and keep_directives
            )
            continue
        out.append(line)
    return "\n".join(out)


def prose(text: str) -> str:
    """The prose of a MyST page: everything that is not code, math, role or label."""
    text = re.sub(r"\A---\n.*?\n---\n", "", text, flags=re.S)  # front matter
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    text = fences(text)  # code cells and fenced blocks; directives keep their body
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
    # The front matter for JupyterLab is no prose either.
    frontmatter = "```yaml\nnumbering:\n  equation:\n    start: 17\n```\n\n"
    assert stray_numbers(frontmatter + page) == ["Some text with 31 units."]


def test_every_quote_is_in_some_page_and_has_a_source():
    text = "\n".join(prose(p.read_text(encoding="utf-8")) for p in PAGES)
    for quote, source in PROSE_QUOTES.items():
        assert quote in text, f"{quote!r} is no longer quoted: drop it from PROSE_QUOTES"
        assert source.strip(), f"{quote!r} has no source"


def math_directives(text: str) -> list[str]:
    """The content of every ``{math}`` directive, without its ``:option:`` lines."""
    found = re.findall(r"^[ \t]*(`{3,})\{math\}[^\n]*\n(.*?)^[ \t]*\1[ \t]*$", text, re.S | re.M)
    return [re.sub(r"^[ \t]*:[\w-]+:.*$", "", body, flags=re.M) for _, body in found]


def mathematics(text: str) -> list[str]:
    """The pages' mathematics: every ``$...$``, ``$$...$$`` and ``{math}``, outside code."""
    text = re.sub(r"\A---\n.*?\n---\n", "", text, flags=re.S)
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    directives = math_directives(text)
    text = fences(text)
    display = re.findall(r"\$\$(.*?)\$\$", text, flags=re.S)
    text = re.sub(r"\$\$.*?\$\$", "", text, flags=re.S)
    text = re.sub(r"``.*?``|`[^`]*`", "", text)  # inline code and roles' content
    return directives + display + re.findall(r"(?<!\\)\$([^$]+?)(?<!\\)\$", text, flags=re.S)


def math_numbers(math: str) -> list[str]:
    """The numbers of one piece of mathematics that no allowed use accounts for.

    Structure is not checked: single digits and their fractions (coefficients,
    frame indices, the small integers of the formulas), exponents and indices
    (``^{-2}``, ``_3``), the base of a power of ten and the digits of
    ``\\tfrac12``. A number of frames ``N = 30`` is allowed as ``frames 30``
    is in prose. Values quoted from the paper (:data:`MATH_QUOTES`) are
    removed first; any other number must be glued.
    """
    s = math
    for quote in MATH_QUOTES:
        s = s.replace(quote, " ")
    s = re.sub(r"\\(?:label|tag|text|mathrm|operatorname)\{[^}]*\}", " ", s)
    s = re.sub(r"\\[td]?frac\s*\d\d", " ", s)
    s = re.sub(r"10\s*\^\s*(?:\{[^{}]*\}|-?\d)", " ", s)  # a power of ten
    s = re.sub(r"[_^]\{[^{}]*\}|[_^]\\?\w", " ", s)  # indices and exponents
    s = re.sub(r"\\[A-Za-z]+", " ", s)
    s = re.sub(r"\bN\s*=\s*\d+", " ", s)  # a number of frames
    found = re.findall(r"\d+(?:\.\d+)?(?:/\d+)?", s)
    return [n for n in found if not re.fullmatch(r"\d(?:/\d)?", n)]


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_no_typed_numbers_in_mathematics(page):
    stray = [
        (n, " ".join(m.split())[:60])
        for m in mathematics(page.read_text(encoding="utf-8"))
        for n in math_numbers(m)
    ]
    assert not stray, f"{page.name}: numbers typed in mathematics (glue them): {stray}"


def test_the_mathematics_scan_catches_a_typed_number_and_spares_the_structure():
    page = (
        "A result $\\hat y = 5.70$ and $c = (6/5, 6, 6/5)^\\top$, $G^{-2}\\mathbf{c}$,\n"
        "$\\rho = 1/200$, $10^{-8}$, $\\tfrac12$, $N = 30$, $x_{12}$.\n"
        "$$\nP = 1000\\,I + 42\n$$\n"
        "```{math}\n:enumerated: false\nQ = 77\n```\n"
    )
    found = [n for m in mathematics(page) for n in math_numbers(m)]
    assert sorted(found) == ["42", "5.70", "77"]
    assert stray_numbers(page) == []  # the mathematics is not prose


def test_every_math_quote_is_in_some_page_and_has_a_source():
    text = " ".join(" ".join(mathematics(p.read_text(encoding="utf-8"))) for p in PAGES)
    for quote, source in MATH_QUOTES.items():
        assert quote in text, f"{quote!r} is no longer in the mathematics: drop it from MATH_QUOTES"
        assert source.strip(), f"{quote!r} has no source"
