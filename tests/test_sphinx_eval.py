"""The book's ``{eval}`name``` role pastes what ``{glue:text}`name``` pastes.

Builds a one-page Sphinx project with myst-nb and the book's extension
(``tools/sphinx/depthcore_book.py``) from a notebook whose outputs hold two
glued records (myst-nb reads them without executing it), strictly (``-W``).
"""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
PREFIX = "application/papermill.record/"


def glued(name: str, text_plain: str) -> dict:
    return nbformat.v4.new_output(
        "display_data",
        data={PREFIX + "text/plain": text_plain},
        metadata={"scrapbook": {"name": name, "mime_prefix": PREFIX}},
    )


def build(tmp_path: Path, text: str) -> str:
    from sphinx.application import Sphinx
    from sphinx.util.docutils import docutils_namespace

    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(ROOT / 'tools' / 'sphinx')!r})\n"
        "extensions = ['myst_nb', 'sphinx.ext.autodoc', 'depthcore_book']\n"
        "nb_execution_mode = 'off'\n"
    )
    code = nbformat.v4.new_code_cell("glue(...)")
    code.outputs = [glued("mean", "'6.4660'"), glued("count", "3")]
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(text), code])
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, src / "index.ipynb")
    with docutils_namespace():  # the roles and nodes registered stay in this build
        app = Sphinx(
            src,
            src,
            tmp_path / "html",
            tmp_path / "doctrees",
            "html",
            warningiserror=True,
            status=None,
            freshenv=True,
        )
        app.build()
    return (tmp_path / "html" / "index.html").read_text(encoding="utf-8")


def test_eval_pastes_the_glued_text_as_glue_text_does(tmp_path):
    html = build(
        tmp_path,
        "# Page\n\nA {eval}`mean` B {glue:text}`mean` C {eval}`count` D {glue:text}`count` E\n",
    )
    body = re.search(r"A (.*) E", html).group(1)
    spans = re.findall(r'<span class="pasted-text">([^<]*)</span>', body)
    assert spans == ["6.4660", "6.4660", "3", "3"]
    assert "{eval}" not in html and "eval" not in body


def test_eval_of_a_name_not_glued_fails_the_strict_build(tmp_path):
    from sphinx.errors import SphinxWarning

    with pytest.raises(SphinxWarning, match="No key 'nope' found in glue data"):
        build(tmp_path, "# Page\n\nA {eval}`nope` E\n")
