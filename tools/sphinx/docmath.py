"""The docstrings' plain-text mathematics, typeset on the book's API pages.

The package's docstrings write formulas as inline literals in plain text, as
``help()`` shows them: ``mu_i = x_i / y_i + w_i``, ``rho**2 J^{-1}``,
``sum_k r_k**2``. On the book's API pages such a literal becomes a ``:math:``
role with its LaTeX (``\\mu_i = x_i / y_i + w_i``); a literal that is code (an
argument's name, a call, a string, a number) stays a literal.

A literal counts as mathematics when every name in it is a single letter, a
Greek letter's name or a known function (``log``, ``exp``, ``sqrt``,
``sum``, ...), each with at most a short subscript (``_k``, ``_oy``,
``_{t+1}``, ``_+``), and it holds an operator, a subscript, a superscript, a
Greek letter or a function: a lone name (``x``, ``mu``) is usually an
argument and stays code.
"""

from __future__ import annotations

import re

GREEK = {
    name: "\\" + name
    for name in (
        "alpha beta gamma delta epsilon zeta eta theta iota kappa lambda mu nu xi pi rho "
        "sigma tau upsilon phi chi psi omega Gamma Delta Theta Lambda Xi Pi Sigma Upsilon "
        "Phi Psi Omega"
    ).split()
}
FUNCTIONS = {
    "log": "\\log",
    "exp": "\\exp",
    "sqrt": "\\sqrt",
    "sum": "\\sum",
    "prod": "\\prod",
    "det": "\\det",
    "tan": "\\tan",
    "arctan": "\\arctan",
    "sin": "\\sin",
    "cos": "\\cos",
    "min": "\\min",
    "max": "\\max",
    "diag": "\\operatorname{diag}",
    "Var": "\\operatorname{Var}",
    "Cov": "\\operatorname{Cov}",
    "inf": "\\infty",
}
LITERAL_RE = re.compile(r"``([^`]+)``")
NAME_RE = re.compile(
    r"(?<![A-Za-z0-9\\])([A-Za-z]+)(\d*)(?:_(\{[^{}]*\}|[A-Za-z0-9]+|[+\-](?![\w(])))?"
)
CODE_RE = re.compile(
    r"[\"'`:;@#$%&\[\]\\]|\.\w|\w\.|\bimport\b|\d[eE][+\-]?\d|^\s*-?[\d.]+\s*$"
    r"|[A-Za-z0-9]_[A-Za-z0-9]+_[A-Za-z0-9]"  # a name of three words (f_at_c): a subscript's twice
)
SIGNAL_RE = re.compile(r"[=+\-*/^~<>|_]|\.\.")


def _name_is_math(base: str, digits: str, sub: str | None) -> bool:
    if not (len(base) == 1 or base in GREEK or base in FUNCTIONS):
        return False
    if sub is None or sub.startswith("{") or sub in "+-":
        return True
    return len(sub) <= 3 and not (digits and len(base) > 1)


def is_math(text: str) -> bool:
    """Whether an inline literal's text reads as a formula rather than code."""
    if CODE_RE.search(text) or text.count("(") != text.count(")"):
        return False
    names = NAME_RE.findall(text)
    if not names or not all(_name_is_math(*name) for name in names):
        return False
    if len(names) == 1 and not SIGNAL_RE.search(text) and names[0][0] not in FUNCTIONS:
        return False
    return bool(SIGNAL_RE.search(text) or any(n[0] in GREEK or n[0] in FUNCTIONS for n in names))


def _closing(text: str, start: int) -> int:
    """Index of the parenthesis closing the one at ``start``, or -1."""
    depth = 0
    for i in range(start, len(text)):
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        if depth == 0:
            return i
    return -1


def _braced(text: str, open_at: int) -> str:
    """``text`` with the parenthesis at ``open_at`` and its partner made braces."""
    close = _closing(text, open_at)
    if close < 0:
        return text
    return text[:open_at] + "{" + text[open_at + 1 : close] + "}" + text[close + 1 :]


def _name(match: re.Match) -> str:
    base, digits, sub = match.group(1), match.group(2), match.group(3)
    out = GREEK.get(base) or FUNCTIONS.get(base) or base
    if out.startswith("\\") and out[-1].isalpha() and not sub and not digits:
        out += " "
    parts = [p for p in (digits, sub.strip("{}") if sub else "") if p]
    if parts:
        inner = ",".join(NAME_RE.sub(_name, p) for p in parts)
        out += "_{" + inner + "}"
    return out


def to_latex(text: str) -> str:
    """The LaTeX of a plain-text formula (``rho**2 J^{-1}`` -> ``\\rho^{2} J^{-1}``)."""
    s = text.replace("**", "^")
    for plain, tex in (
        ("->", r"\to "),
        ("<=", r"\le "),
        (">=", r"\ge "),
        ("!=", r"\ne "),
        ("+-", r"\pm "),
        ("..", r"\ldots "),
        (" . ", r" \cdot "),
        ("~", r"\sim "),
        ("*", r"\,"),
    ):
        s = s.replace(plain, tex)
    s = re.sub(r"\^T\b", r"^{\\top}", s)
    s = re.sub(r"\^(-?[A-Za-z0-9.]+)", r"^{\1}", s)
    while (i := s.find("^(")) >= 0:
        s = _braced(s, i + 1)
    while (i := s.find("sqrt(")) >= 0:
        s = _braced(s, i + 4)
    return NAME_RE.sub(_name, s).strip()


def convert_line(line: str) -> str:
    """``line`` with each mathematical inline literal made a ``:math:`` role."""

    def replace(match: re.Match) -> str:
        text = match.group(1)
        return f":math:`{to_latex(text)}`" if is_math(text) else match.group(0)

    return LITERAL_RE.sub(replace, line)


def typeset_docstring(app, what, name, obj, options, lines) -> None:
    """``autodoc-process-docstring``: the docstring's formulas as ``:math:`` roles."""
    lines[:] = [convert_line(line) for line in lines]
