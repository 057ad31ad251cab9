"""What a reader of the HTML book can take away.

* every page that runs code offers its executed notebook (``.ipynb`` with
  outputs) in its download menu, at ``_sources/<page>.ipynb``;
* the pages of Figures 2-6 link the figure as PDF, SVG and PNG under
  ``downloads/figures/``, and the files are the formats they claim;
* the intro links the PDF of the book, ``depthcore``'s source archive (an
  sdist of the package's current version with every module and the
  benchmarks' records) and the pinned requirements;
* every link into ``downloads/`` resolves to a file of the built book.
"""

from __future__ import annotations

import json
import re
import tarfile
from pathlib import Path

import pytest
from conftest import ROOT

import depthcore

HREF_RE = re.compile(r'href="([^"#?]*downloads/[^"#?]+)"')
MAGIC = {"pdf": b"%PDF-", "png": b"\x89PNG\r\n\x1a\n"}


def is_format(data: bytes, fmt: str) -> bool:
    """Whether ``data`` is a file of ``fmt`` (pdf, png: its magic number; svg: an ``<svg`` tag)."""
    return data.startswith(MAGIC[fmt]) if fmt in MAGIC else b"<svg" in data[:2000]


def visible_outputs(nb: dict) -> int:
    """Number of outputs of a notebook's code cells that Jupyter displays (not glue records)."""
    count = 0
    for cell in nb["cells"]:
        for output in cell.get("outputs", []) if cell["cell_type"] == "code" else []:
            data = output.get("data", {})
            if output["output_type"] == "stream" or any(
                not mime.startswith("application/papermill.record/") for mime in data
            ):
                count += 1
    return count


def notebook_pages() -> list[str]:
    import check_notebooks

    return [str(p.relative_to(ROOT).with_suffix("")) for p in check_notebooks.notebook_pages()]


@pytest.mark.parametrize("page", notebook_pages())
def test_page_offers_its_executed_notebook(html_dir, html_pages, page):
    html = html_pages[f"{page}.html"]
    assert f"_sources/{page}.ipynb" in html, f"{page}.html offers no .ipynb download"
    nb = json.loads((html_dir / "_sources" / f"{page}.ipynb").read_text(encoding="utf-8"))
    code = [cell for cell in nb["cells"] if cell["cell_type"] == "code"]
    assert code and all(cell.get("execution_count") for cell in code), (
        f"{page}.ipynb is not executed"
    )
    # A page whose reference shows outputs offers a notebook that shows them.
    reference = json.loads(
        (ROOT / "book" / "_nbval" / f"{Path(page).name}.ipynb").read_text(encoding="utf-8")
    )
    # (the book merges a cell's streams into one output, the reference does not: compare presence)
    if visible_outputs(reference):
        assert visible_outputs(nb), (
            f"{page}.ipynb shows no output, the reference {visible_outputs(reference)}"
        )


def test_every_download_link_resolves(html_dir, html_pages):
    links = 0
    for page, html in html_pages.items():
        for href in HREF_RE.findall(html):
            target = (html_dir / page).parent / href
            assert target.resolve().is_file(), f"{page} links {href}, which the build does not ship"
            links += 1
    assert links, "no page links into downloads/"


@pytest.mark.parametrize("number", range(2, 7))
def test_figure_page_links_the_figure_in_three_formats(html_dir, html_pages, number):
    hrefs = set(HREF_RE.findall(html_pages[f"book/fig{number}.html"]))
    for fmt in ("pdf", "svg", "png"):
        href = f"../downloads/figures/figure{number}.{fmt}"
        assert href in hrefs, f"book/fig{number}.html does not link {href}"
        data = (html_dir / "downloads" / "figures" / f"figure{number}.{fmt}").read_bytes()
        assert is_format(data, fmt), f"figure{number}.{fmt} is not a {fmt.upper()} file"


def test_the_downloads_hold_every_figure_the_figures_command_writes_by_default(html_dir):
    # `make downloads` runs `python -m depthbook figures` with its default formats.
    written = sorted(p.name for p in (html_dir / "downloads" / "figures").iterdir())
    assert written == sorted(
        f"figure{n}{x}.{fmt}"
        for n in range(2, 7)
        for x in ("", "-extended")
        for fmt in ("pdf", "png", "svg")
    )
    for name in written:
        data = (html_dir / "downloads" / "figures" / name).read_bytes()
        assert is_format(data, name.rsplit(".", 1)[1]), f"{name} is not the format it names"


def test_intro_links_the_pdf_the_source_archives_and_the_requirements(html_pages):
    hrefs = set(HREF_RE.findall(html_pages["book/intro.html"]))
    for name in (
        "depthcore.pdf",
        "article.pdf",
        "depthcore.tar.gz",
        "depthbook.tar.gz",
        "requirements.txt",
    ):
        assert f"../downloads/{name}" in hrefs, f"the intro does not link downloads/{name}"


def test_source_archive_is_an_sdist_of_this_version(html_dir):
    package = ROOT / "depthcore"
    modules = sorted(p.relative_to(package).as_posix() for p in package.rglob("*.py"))
    with tarfile.open(html_dir / "downloads" / "depthcore.tar.gz") as tar:
        names = tar.getnames()
        top = f"depthcore-{depthcore.__version__}"
        assert f"{top}/pyproject.toml" in names
        missing = [m for m in modules if f"{top}/depthcore/{m}" not in names]
        assert not missing, f"the source archive lacks {missing}"
        info = tar.extractfile(f"{top}/PKG-INFO").read().decode()
    assert f"\nVersion: {depthcore.__version__}\n" in info


def test_the_books_archive_holds_its_code_and_every_record_and_the_packages_none(html_dir):
    # The pages read the records from the book's package, installed from its archive.
    book = ROOT / "depthbook"
    files = sorted(
        p.relative_to(book).as_posix()
        for p in book.rglob("*")
        if p.suffix in (".py", ".json") and "__pycache__" not in p.parts
    )
    assert any(f.startswith("provenance/study_records/") for f in files)
    assert any(f.startswith("provenance/benchmark_records/") for f in files)
    top = f"depthbook-{depthcore.__version__}"
    with tarfile.open(html_dir / "downloads" / "depthbook.tar.gz") as tar:
        names = tar.getnames()
    missing = [f for f in files if f"{top}/{f}" not in names and f"{top}/./{f}" not in names]
    assert not missing, f"the book's archive lacks {missing}"
    with tarfile.open(html_dir / "downloads" / "depthcore.tar.gz") as tar:
        assert not [n for n in tar.getnames() if n.endswith(".json")], "records in the package"


def test_source_archive_installs_the_citation_file(html_dir):
    # The page "Cite this work", downloaded and run alone, reads it from the package.
    top = f"depthcore-{depthcore.__version__}"
    with tarfile.open(html_dir / "downloads" / "depthcore.tar.gz") as tar:
        cff = tar.extractfile(f"{top}/depthcore/CITATION.cff").read()
    assert cff == (ROOT / "CITATION.cff").read_bytes()
    assert not (ROOT / "depthcore" / "CITATION.cff").exists(), "left in the package by make book"
