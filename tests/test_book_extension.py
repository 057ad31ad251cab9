"""The book's Sphinx extension (tools/sphinx): typeset docstring formulas, the list of downloads.

These are the pure helpers of ``tools/sphinx/depthcore_book.py`` and
``tools/sphinx/docmath.py``; the built book is checked in ``tests/book``.
"""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import pytest

import depthbook

SPHINX_DIR = Path(__file__).resolve().parent.parent / "tools" / "sphinx"
sys.path.insert(0, str(SPHINX_DIR))
docmath = importlib.import_module("docmath")
book_ext = importlib.import_module("depthcore_book")


@pytest.mark.parametrize(
    ("text", "latex"),
    [
        ("rho**2 J^{-1}", r"\rho ^{2} J^{-1}"),
        ("f = sum_k r_k**2", r"f = \sum_{k} r_{k}^{2}"),
        ("J = 2 sum_k g_k g_k^T", r"J = 2 \sum_{k} g_{k} g_{k}^{\top}"),
        ("a_k ~ N(0, q**2)", r"a_{k} \sim  N(0, q^{2})"),
        ("mu_1 .. mu_N", r"\mu_{1} \ldots  \mu_{N}"),
        ("c2 + 60 sqrt(P22)", r"c_{2} + 60 \sqrt {P_{22}}"),
        ("q -> 0", r"q \to  0"),
        ("y_N <= N - 1", r"y_{N} \le  N - 1"),
        ("p_oy", "p_{oy}"),
        ("G^(k-3) c", "G^{k-3} c"),
    ],
)
def test_formulas_become_latex(text, latex):
    assert docmath.is_math(text), text
    assert docmath.to_latex(text) == latex


@pytest.mark.parametrize(
    "text",
    [
        "mu",  # an argument's name
        "x",
        'reading="printed"',
        "from depthcore import model",
        "x.shape[:-1]",
        "n_particles",
        "ess_threshold * N",
        "1e-300",
        "depthcore.problem.checks.MAX_FRAMES",
        "focal * tan(rho)",
        "log_ndtr",
        "f_at_c",  # a name of three words, not f with two subscripts
    ],
)
def test_code_stays_code(text):
    assert not docmath.is_math(text), text
    line = f"see ``{text}`` here"
    assert docmath.convert_line(line) == line


def test_a_docstring_line_gets_math_roles_and_keeps_its_code():
    line = 'the Hessian ``J = 2 sum_k g_k g_k^T`` of ``f``, with ``reading="derived"``'
    assert docmath.convert_line(line) == (
        r"the Hessian :math:`J = 2 \sum_{k} g_{k} g_{k}^{\top}` of ``f``, "
        'with ``reading="derived"``'
    )


def test_every_converted_formula_of_the_packages_has_balanced_braces():
    # A formula with an unbalanced brace would not typeset (MathJax shows an error); the API
    # reference documents the package and the book's own.
    found = 0
    root = SPHINX_DIR.parent.parent
    for path in sorted([*(root / "depthcore").rglob("*.py"), *(root / "depthbook").rglob("*.py")]):
        for text in re.findall(r"``([^`\n]+)``", path.read_text(encoding="utf-8")):
            if docmath.is_math(text):
                latex = docmath.to_latex(text)
                assert latex.count("{") == latex.count("}"), (path.name, text, latex)
                found += 1
    assert found > 300, f"only {found} formulas recognised in the docstrings"


def test_module_summaries_are_the_first_paragraph_in_myst():
    summary = book_ext.module_summary(depthbook.live)
    assert summary.startswith("Live controls for the figure pages") and "\n" not in summary
    assert (
        book_ext.rst_to_myst(
            r"on :math:`N \ge 3` frames, :func:`depthcore.problem.model.f` and ``x.shape``"
        )
        == r"on {math}`N \ge 3` frames, {py:func}`depthcore.problem.model.f` and `x.shape`"
    )


def test_download_lines_are_parsed_or_refused():
    assert book_ext.parse_downloads(["depthcore.pdf: the book as a PDF", "", "a.txt: *b*"]) == [
        ("depthcore.pdf", "the book as a PDF"),
        ("a.txt", "*b*"),
    ]
    for bad in ("no colon here", "dir/file.pdf: nested", ": no file", "file.pdf:"):
        with pytest.raises(ValueError, match="file: what it is"):
            book_ext.parse_downloads([bad])


def test_an_unnamed_figure_keeps_its_caption_as_an_unnumbered_legend():
    from docutils import nodes

    figure = nodes.figure("", nodes.image(uri="x.png"), nodes.caption("", "", nodes.Text("A cap")))
    book_ext.unnumbered(figure)
    assert not list(figure.findall(nodes.caption))
    (legend,) = figure.findall(nodes.legend)
    assert legend.astext() == "A cap"
