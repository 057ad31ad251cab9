"""The book's ``{eval}`name``` role pastes what ``{glue:text}`name``` pastes.

Builds a one-page Sphinx project with myst-nb and the book's extension
(``tools/sphinx/depthcore_book.py``) from a notebook whose outputs hold two
glued records (myst-nb reads them without executing it), strictly (``-W``).
"""

from __future__ import annotations

import html
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


def build(tmp_path: Path, text: str, conf: str = "") -> str:
    from sphinx.application import Sphinx
    from sphinx.util.docutils import docutils_namespace

    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(ROOT / 'tools' / 'sphinx')!r})\n"
        "extensions = ['myst_nb', 'sphinx.ext.autodoc', 'depthcore_book']\n"
        "nb_execution_mode = 'off'\n" + conf
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


def test_the_front_matter_and_unnumbered_displays_for_jupyterlab_leave_the_book_as_it_was(
    tmp_path,
):
    """A page's front matter for JupyterLab is not shown, and ``:enumerated: false`` is accepted.

    The labelled display keeps the book's number and the ``{math}`` display
    with ``:enumerated: false`` is shown as an unlabelled ``$$`` display is,
    unnumbered (``tools/myst_roles.py`` writes both for jupyterlab-myst), in a
    strict build.
    """
    frontmatter = "```yaml\nnumbering:\n  equation:\n    start: 17\n```\n\n"
    displays = (
        "$$\nx = 1\n$$ (eq-a)\n\n```{math}\n:enumerated: false\ny = 2\n```\n\n$$\nz = 3\n$$\n"
    )
    conf = "myst_enable_extensions = ['dollarmath']\nnumfig = True\n"  # as the book's
    html = build(tmp_path, frontmatter + "# Page\n\n" + displays, conf)
    assert "numbering" not in html and "start: 17" not in html and "highlight-yaml" not in html
    assert re.search(r'id="equation-eq-a">\s*<span class="eqno">\(1\)', html)
    assert html.count('class="eqno"') == 1
    unnumbered = re.findall(r'<div class="math notranslate nohighlight">\s*\\\[\s*(\w) = ', html)
    assert unnumbered == ["y", "z"]


def test_a_yaml_block_that_is_not_front_matter_for_jupyterlab_is_shown(tmp_path):
    html = build(tmp_path, "```yaml\nkept: 1\n```\n\n# Page\n\nText.\n")
    assert "highlight-yaml" in html and "kept" in html


# --- references written as {eval} expressions, and figures of glued images ----------------

PNG = (
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5Erk"
    "Jggg=="
)
BIB = """@article{alpha2001,
  author = {Alpha, Ann},
  title = {One}, journal = {J}, year = {2001},
}
@article{beta2002,
  author = {Beta, Bob and van der Gamma, Carl},
  title = {Two}, journal = {J}, year = {2002},
}
@article{delta2003,
  author = {Delta, Dan and Eps, Eve and Zeta, Zoe},
  title = {Three}, journal = {J}, year = {2003},
}
"""
OTHER = """# The other page

$$
x = 1
$$ (eq-1)

(sec-there)=
## A section there

```{figure} dot.png
:name: fig-there

A figure there.
```
"""
# Each reference twice: as the book's role, then as the {eval} expression.
PAIRS = [
    ("{cite:t}`alpha2001`", '{eval}`cite_t("alpha2001")`'),
    ("{cite:p}`beta2002,delta2003`", '{eval}`cite_p("beta2002,delta2003")`'),
    ("{cite:t}`alpha2001,delta2003`", '{eval}`cite_t("alpha2001,delta2003")`'),
    ("{eq}`eq-1`", '{eval}`eq("eq-1")`'),
    ("{numref}`fig-there`", '{eval}`numref("fig-there")`'),
    ("{numref}`Fig. %s <fig-there>`", '{eval}`numref("Fig. %s <fig-there>")`'),
    ("{ref}`sec-there`", '{eval}`ref("sec-there")`'),
    ("{doc}`other`", '{eval}`doc("other")`'),
    ("{doc}`the other page <other>`", '{eval}`doc("the other page <other>")`'),
]
FIGURES = """
```{glue:figure} image
:name: fig-glue
:alt: a dot
:width: 50%

The glued dot, $x$ and {eval}`mean`.
```

```{figure}
:name: fig-eval
:alt: a dot
:width: 50%
:enumerated: false

{eval}`image`

The glued dot, $x$ and {eval}`mean`.
```
"""


def build_book(tmp_path: Path, text: str, builder: str = "html") -> Path:
    """A two-page project (a notebook with glued records, other.md); its output folder."""
    import base64

    from sphinx.application import Sphinx
    from sphinx.util.docutils import docutils_namespace

    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(ROOT / 'tools' / 'sphinx')!r})\n"
        "extensions = ['myst_nb', 'sphinx.ext.autodoc', 'sphinxcontrib.bibtex', 'depthcore_book']\n"
        "nb_execution_mode = 'off'\n"
        "myst_enable_extensions = ['dollarmath', 'amsmath', 'colon_fence']\n"
        "bibtex_bibfiles = ['refs.bib']\n"
        "bibtex_reference_style = 'author_year'\n"
        "numfig = True\nmath_numfig = True\nnumfig_secnum_depth = 0\n"
        "numfig_format = {'figure': 'Figure %s'}\n"
    )
    (src / "refs.bib").write_text(BIB)
    (src / "dot.png").write_bytes(base64.b64decode(PNG))
    (src / "other.md").write_text(OTHER)
    code = nbformat.v4.new_code_cell("glue(...)")
    image = nbformat.v4.new_output(
        "display_data",
        data={PREFIX + "image/png": PNG, PREFIX + "text/plain": "<Figure>"},
        metadata={"scrapbook": {"name": "image", "mime_prefix": PREFIX}},
    )
    code.outputs = [glued("mean", "'6.4660'"), image]
    toc = "```{toctree}\nother\n```\n\n```{bibliography}\n```\n"
    cells = [nbformat.v4.new_markdown_cell(text + "\n\n" + toc), code]
    nb = nbformat.v4.new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, src / "index.ipynb")
    out = tmp_path / builder
    with docutils_namespace():
        app = Sphinx(
            src,
            src,
            out,
            tmp_path / "doctrees",
            builder,
            warningiserror=True,
            status=None,
            freshenv=True,
        )
        app.build()
    return out


def same(text: str) -> str:
    """Output text without the ids and targets that differ between two references."""
    text = re.sub(r'\s(id|ids|href)="[^"]*"', "", text)
    return re.sub(r"\\(label|hyperref|phantomsection|sphinxcite|sphinxstepscope)\S*", "", text)


@pytest.mark.parametrize("builder", ["html", "latex"])
def test_a_reference_written_as_eval_renders_as_its_role(tmp_path, builder):
    text = "\n\n".join(f"P{i} {role} Q{i} {expr} R{i}" for i, (role, expr) in enumerate(PAIRS))
    out = build_book(tmp_path, "# Page\n\n" + text, builder)
    page = (out / ("index.html" if builder == "html" else "projectnamenotset.tex")).read_text()
    shown = {}
    for i in range(len(PAIRS)):
        role, expr = re.search(rf"P{i} (.*?) Q{i} (.*?) R{i}", page, re.S).groups()
        assert same(role) == same(expr), (PAIRS[i], role, expr)
        shown[i] = role
    if builder == "html":
        plain = {i: re.sub(r"<[^>]+>", "", s) for i, s in shown.items()}
        # What the kernel's functions (depthbook.crossref) give in JupyterLab.
        from depthbook.crossref import BookReferences

        (src := tmp_path / "src" / "_toc.yml").write_text(
            "format: jb-book\nroot: index\nchapters:\n  - file: other\n"
        )
        (tmp_path / "src" / "_config.yml").write_text("bibtex_bibfiles: [refs.bib]\n")
        book = BookReferences(src.parent)
        for i, (role, expr) in enumerate(PAIRS):
            assert html.unescape(plain[i]) == eval(expr[7:-1], book.functions()), (role, plain[i])
        assert plain[0] == "Alpha [2001]"
        assert plain[1] == "[Beta and van\xa0der Gamma, 2002, Delta et al., 2003]"


@pytest.mark.parametrize("builder", ["html", "latex"])
def test_a_figure_of_an_eval_pastes_the_glued_figure_as_glue_figure_does(tmp_path, builder):
    out = build_book(
        tmp_path, "# Page\n\nSee {numref}`fig-glue` and {numref}`fig-eval`.\n" + FIGURES, builder
    )
    page = (out / ("index.html" if builder == "html" else "projectnamenotset.tex")).read_text()
    if builder == "html":
        figures = re.findall(r"<figure.*?</figure>", page, re.S)
        assert "See Figure 1 and Figure 2" in re.sub(r"<[^>]+>", "", page)
    else:
        figures = re.findall(r"\\begin\{figure\}.*?\\end\{figure\}", page, re.S)
    # The two of the page (the PDF goes on with the other page's figure, from its path).
    assert len(figures) == 2 + (builder == "latex")
    assert builder == "html" or "{{dot}.png}" in figures[2]
    one, two = (same(f).replace("glue", "X").replace("eval", "X") for f in figures[:2])
    assert one.replace("Figure 1", "Figure N") == two.replace("Figure 2", "Figure N")
    assert "6.4660" in figures[1] and (
        "<img" in figures[1] or "sphinxincludegraphics" in figures[1]
    )


@pytest.mark.parametrize("builder", ["html", "latex"])
def test_a_figure_without_a_name_is_not_numbered_and_keeps_its_caption(tmp_path, builder):
    unnamed = FIGURES.split("```{figure}")[1].replace(":name: fig-eval\n", "")
    text = "# Page\n\nSee {numref}`fig-glue`.\n" + FIGURES.split("```{figure}")[0]
    out = build_book(tmp_path, text + "```{figure}" + unnamed, builder)
    page = (out / ("index.html" if builder == "html" else "projectnamenotset.tex")).read_text()
    if builder == "html":
        plain = re.sub(r"<[^>]+>", "", page)
        assert "See Figure 1" in plain and "Figure 2" not in plain
        assert plain.count("The glued dot") == 2
    else:
        assert page.count("\\caption{") == 2  # the named one and the other page's
        assert "sphinxlegend" in page and "The glued dot" in page.split("sphinxlegend")[1]


def test_a_figure_without_a_glued_name_fails_the_strict_build(tmp_path):
    with pytest.raises(Exception, match="glued figure"):
        build_book(tmp_path, "# Page\n\n```{figure}\n:name: fig-x\n\nNo image.\n```\n")


def test_an_eval_call_of_another_function_fails_the_strict_build(tmp_path):
    with pytest.raises(Exception, match="a reference is written as one of"):
        build_book(tmp_path, '# Page\n\nA {eval}`cite("alpha2001")` B\n')


def test_the_downloads_link_what_the_folder_holds_and_what_is_pending(tmp_path, monkeypatch):
    folder = tmp_path / "downloads"
    folder.mkdir()
    (folder / "requirements.txt").write_text("numpy\n")
    listing = (
        "# Page\n\n```{depthcore-downloads}\nrequirements.txt: the pins\n"
        "depthcore.pdf: the book\nnotes.txt: the notes\n```\n"
    )
    conf = f"depthcore_downloads = {str(folder)!r}\n"
    monkeypatch.delenv("DEPTHCORE_DOWNLOADS_PENDING", raising=False)
    (tmp_path / "alone").mkdir()
    page = build(tmp_path / "alone", listing, conf)
    assert '<a class="reference external" href="downloads/requirements.txt">the pins</a>' in page
    assert "the book (not shipped by this build of the book)" in page
    assert "the notes (not shipped by this build of the book)" in page
    # make test: the PDF is written beside the HTML build and copied in when both end.
    monkeypatch.setenv("DEPTHCORE_DOWNLOADS_PENDING", "depthcore.pdf")
    (tmp_path / "beside").mkdir()
    page = build(tmp_path / "beside", listing, conf)
    assert '<a class="reference external" href="downloads/depthcore.pdf">the book</a>' in page
    assert "the notes (not shipped by this build of the book)" in page
    assert "the book (not shipped" not in page
