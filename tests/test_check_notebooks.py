"""The notebook drift check (tools/check_notebooks.py): its choice of pages, its cache key,
what it refuses, and nbval's runs of small notebooks."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import jupytext
import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import check_notebooks  # noqa: E402

PAGES = check_notebooks.notebook_pages()
v4 = nbformat.v4


def test_no_names_select_every_page():
    assert check_notebooks.select_pages(PAGES, []) == PAGES


def test_names_select_those_pages_in_toc_order():
    chosen = check_notebooks.select_pages(PAGES, ["cite", "book/fig6.md", "fig2.md"])
    assert [p.stem for p in chosen] == ["fig2", "fig6", "cite"]


def test_an_unknown_page_is_refused_by_name(capsys):
    with pytest.raises(ValueError, match="not a page of _toc.yml: nosuch"):
        check_notebooks.select_pages(PAGES, ["fig2", "nosuch"])
    assert check_notebooks.main(["check", "nosuch"]) == 1
    assert capsys.readouterr().err.startswith("make notebooks:\n  - not a page of _toc.yml: nosuch")


def test_the_pages_are_the_toc_documents_with_a_kernel():
    names = [page.relative_to(ROOT).with_suffix("").as_posix() for page in PAGES]
    assert names == [entry for entry in check_notebooks.toc_files() if entry in names]
    assert {"intro", "fig2", "fig6", "cite"} <= {p.stem for p in PAGES}
    assert "notation" not in {p.stem for p in PAGES}  # a page without code


def test_only_references_of_pages_outside_the_toc_are_stale():
    assert check_notebooks.stale_references(PAGES) == []
    subset = check_notebooks.select_pages(PAGES, ["fig6"])
    stale = check_notebooks.stale_references(subset)
    assert check_notebooks.reference_path(PAGES[0]) in stale
    assert check_notebooks.reference_path(subset[0]) not in stale


def test_update_of_named_pages_leaves_the_other_references(monkeypatch):
    calls = []
    monkeypatch.setattr(check_notebooks, "update", lambda *args: calls.append(args) or 0)
    assert check_notebooks.main(["update", "fig6"]) == 0
    assert check_notebooks.main(["update"]) == 0
    (pages, _, every), (all_pages, _, all_every) = calls
    assert [p.stem for p in pages] == ["fig6"] and every is None  # no stale reference deleted
    assert all_pages == all_every == PAGES
    assert check_notebooks.main(["update", "nosuch"]) == 1


# --- the execution cache's key -------------------------------------------------------------


def small_project(tmp_path: Path) -> tuple[Path, list[Path]]:
    (tmp_path / "depthcore").mkdir()
    (tmp_path / "depthcore" / "model.py").write_text("X = 1\n")
    (tmp_path / "requirements.txt").write_text("numpy==2.4.6\n")
    (tmp_path / "book").mkdir()
    pages = [tmp_path / "book" / f"{name}.md" for name in ("one", "two")]
    for page in pages:
        page.write_text(f"# {page.stem}\n")
    return tmp_path, pages


def cache_page(cache: Path, page: Path) -> None:
    """Store an executed notebook for ``page`` in a jupyter-cache, as myst-nb does."""
    import nbformat
    from jupyter_cache import get_cache
    from jupyter_cache.base import CacheBundleIn

    nb = nbformat.v4.new_notebook(
        cells=[nbformat.v4.new_code_cell(f"print({page.stem!r})", execution_count=1)]
    )
    nb.metadata.kernelspec = {"name": "python3", "display_name": "Python 3", "language": "python"}
    get_cache(cache).cache_notebook_bundle(
        CacheBundleIn(nb, str(page)), check_validity=False, overwrite=True
    )


def cached_uris(cache: Path) -> list[str]:
    from jupyter_cache import get_cache

    return sorted(Path(r.uri).name for r in get_cache(cache).list_cache_records())


def test_the_cache_is_kept_while_nothing_changes(tmp_path):
    root, pages = small_project(tmp_path)
    cache = root / "_build" / ".jupyter_cache"
    assert check_notebooks.prepare_cache(pages, cache, root) == []
    for page in pages:
        cache_page(cache, page)
    assert check_notebooks.prepare_cache(pages, cache, root) == []
    assert cached_uris(cache) == ["one.md", "two.md"]


def test_a_changed_page_loses_its_cached_outputs_alone(tmp_path):
    root, pages = small_project(tmp_path)
    cache = root / "_build" / ".jupyter_cache"
    check_notebooks.prepare_cache(pages, cache, root)
    for page in pages:
        cache_page(cache, page)
    # Only prose changed (a table of glued numbers, say): the code cells key jupyter-cache.
    pages[1].write_text("# two\n\n| {glue:text}`x` |\n")
    assert check_notebooks.prepare_cache(pages, cache, root) == ["book/two.md"]
    assert cached_uris(cache) == ["one.md"]


@pytest.mark.parametrize(
    "change",
    [
        "depthcore/problem/model.py",
        "depthbook/provenance/benchmark_records/bench_x.json",
        "requirements.txt",
        "tools/jupyter/kernels/python3/launch.py",
    ],
)
def test_a_change_of_the_package_or_its_environment_empties_the_cache(tmp_path, change):
    root, pages = small_project(tmp_path)
    cache = root / "_build" / ".jupyter_cache"
    check_notebooks.prepare_cache(pages, cache, root)
    for page in pages:
        cache_page(cache, page)
    (root / change).parent.mkdir(parents=True, exist_ok=True)
    (root / change).write_text("changed\n")
    assert check_notebooks.prepare_cache(pages, cache, root) == ["all"]
    assert cached_uris(cache) == []
    assert (cache / check_notebooks.CACHE_KEY).is_file()


def test_a_new_reference_loses_the_page_its_cached_outputs(tmp_path):
    # A record executed alone was checked against the reference it was executed beside.
    root, pages = small_project(tmp_path)
    cache = root / "_build" / ".jupyter_cache"
    check_notebooks.prepare_cache(pages, cache, root)
    for page in pages:
        cache_page(cache, page)
    (root / "book" / "_nbval").mkdir()
    (root / "book" / "_nbval" / "one.ipynb").write_text("{}")
    assert check_notebooks.prepare_cache(pages, cache, root) == ["book/one.md"]
    assert cached_uris(cache) == ["two.md"]


def test_bytecode_does_not_change_the_key(tmp_path):
    root, pages = small_project(tmp_path)
    cache = root / "_build" / ".jupyter_cache"
    check_notebooks.prepare_cache(pages, cache, root)
    (root / "depthcore" / "__pycache__").mkdir()
    (root / "depthcore" / "__pycache__" / "model.cpython-311.pyc").write_bytes(b"\0")
    assert check_notebooks.prepare_cache(pages, cache, root) == []
    (root / "depthcore" / "model.py").write_text("X = 2\n")
    assert check_notebooks.prepare_cache(pages, cache, root) == ["all"]


def test_jupytext_reads_each_page_as_myst_nb_does_for_the_cache():
    """The notebooks cached here are found by the build, which looks them up as myst-nb reads."""
    from jupyter_cache import get_cache
    from myst_nb.core.read import read_myst_markdown_notebook

    store = get_cache(Path(tempfile.mkdtemp()))
    for page in PAGES:
        as_the_book = read_myst_markdown_notebook(page.read_text(encoding="utf-8"), path=page)
        assert (
            store.create_hashed_notebook(jupytext.read(page))[1]
            == (store.create_hashed_notebook(as_the_book)[1])
        ), page


def makefile_recipe(target: str) -> str:
    """The Makefile's rule for ``target``: its prerequisites and recipe, to the next blank line."""
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    return makefile.split(f"\n{target}:", 1)[1].split("\n\n", 1)[0]


def test_the_config_uses_the_cache_that_make_keys():
    import yaml

    config = yaml.safe_load((ROOT / "_config.yml").read_text(encoding="utf-8"))
    assert config["execute"]["execute_notebooks"] == "cache"
    # One cache for both builds, the one keyed, though the LaTeX build's output is elsewhere.
    assert check_notebooks.CACHE == ROOT / config["execute"]["cache"]
    assert check_notebooks.CACHE == ROOT / "_build" / ".jupyter_cache"
    for target, builds in (
        ("book", ["book-html"]),
        ("pdf", ["pdf-latex"]),
        ("builds", ["--builder latex", "builds-html"]),
    ):
        text = makefile_recipe(target)
        cached = text.find("tools/check_notebooks.py cache --execute")
        for build in builds:
            assert 0 <= cached < text.index(f" {build}"), (target, build)
    assert "jupyter-book build . --all" in makefile_recipe("book-html")
    latex = "jupyter-book build . --builder latex --path-output $(LATEX_BUILD)"
    assert latex in makefile_recipe("pdf-latex")


def test_make_builds_reads_the_pages_once_for_the_pdf_and_the_book_and_ships_the_pdf():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    builds = makefile_recipe("builds")
    pending = 'DEPTHCORE_DOWNLOADS_PENDING="$(SHIPPED_PDFS)" '
    assert "SHIPPED_PDFS := depthcore.pdf article.pdf" in makefile
    latex = builds.index(pending + "$(VENV)/bin/jupyter-book build . --builder latex --all")
    # The LaTeX build reads every page afresh into the default doctrees (no other output
    # path); the HTML build that follows, beside xelatex, writes from them (no --all).
    assert "--path-output" not in builds[latex:].split("|", 1)[0]
    side_by_side = builds.index(pending + "$(MAKE) -j2")
    assert latex < side_by_side and "builds-html builds-xelatex article" in builds[side_by_side:]
    html = makefile_recipe("builds-html")
    assert "jupyter-book build . " in html and "--all" not in html and "--builder" not in html
    assert "tools/xelatex.sh _build/latex" in makefile_recipe("builds-xelatex")
    after = builds[side_by_side:]
    # the book's PDF and the article, copied in once both are written
    assert "cp $(PDF) $(ARTICLE_PDF) $(DOWNLOADS)/" in after
    assert "cp $(PDF) $(ARTICLE_PDF) _build/html/downloads/" in after
    # make pdf reads every page itself, into doctrees apart from an HTML build's, which
    # a build of the book keeps.
    assert "LATEX_BUILD := _build/pdf" in makefile
    assert "! -name pdf" in makefile.split("define clear-book", 1)[1].split("endef", 1)[0]


# --- nbval's runs of small pages ------------------------------------------------------------

PAGE_HEAD = """---
jupytext:
  text_representation:
    extension: .md
    format_name: myst
kernelspec:
  display_name: Python 3
  language: python
  name: python3
---

# A page

```{code-cell} ipython3
"""


def write_page(folder: Path, name: str, *sources: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    page = folder / f"{name}.md"
    page.write_text(PAGE_HEAD + "\n```\n\n```{code-cell} ipython3\n".join(sources) + "\n```\n")
    return page


def write_reference(page: Path, *texts: str | None, executed: bool = True) -> None:
    """The page's reference, each code cell showing one line ``texts`` (None: nothing)."""
    nb = jupytext.read(page)
    for i, (cell, text) in enumerate(zip(check_notebooks.code_cells(nb), texts, strict=True)):
        cell.execution_count = i + 1 if executed else None
        cell.outputs = [] if text is None else [v4.new_output("stream", name="stdout", text=text)]
    check_notebooks.reference_path(page).parent.mkdir(exist_ok=True)
    nbformat.write(nb, check_notebooks.reference_path(page))


@pytest.fixture
def book(tmp_path, monkeypatch):
    """A repository of its own (``tmp_path``), whose pages run with the book's kernel."""
    monkeypatch.setenv("JUPYTER_PATH", check_notebooks.KERNELS)
    monkeypatch.setattr(check_notebooks, "ROOT", tmp_path)
    return tmp_path / "book"


def test_a_reference_that_cannot_vouch_for_its_page_is_named(book):
    problems: list[str] = []
    cases = {
        "same": (["print(1)", "print(2)"], ["print(1)", "print(2)"]),
        "edited": (["print(1)", "print(3)"], ["print(1)", "print(2)"]),
        "added": (["print(1)", "print(2)"], ["print(1)"]),
        "removed": (["print(1)"], ["print(1)", "print(2)"]),
        "hidden": (["print(1)", "x = 1\ny = 2;"], ["print(1)", "x = 1\ny = 2;"]),
    }
    for name, (now, then) in cases.items():
        page = write_page(book, name, *then)
        write_reference(page, *["1\n"] * len(then))
        write_page(book, name, *now)
    unexecuted = write_page(book, "unexecuted", "print(1)")
    write_reference(unexecuted, "1\n", executed=False)
    write_page(book, "missing", "print(1)")
    nbs = {p.stem: check_notebooks.with_reference(p, problems, jupytext.read(p))
           for p in sorted(book.glob("*.md"))}  # fmt: skip
    assert [stem for stem, nb in nbs.items() if nb is not None] == ["same"]
    assert nbs["same"].cells[1].outputs[0]["text"] == "1\n"  # the reference's outputs
    assert problems == [
        "book/added.md: code cell 2 is new or edited: 'print(2)'",
        "book/edited.md: code cell 2 is new or edited: 'print(3)'",
        "book/hidden.md: code cell 2 ends with ';': assign it (`_ = ...`)",
        "book/missing.md: no reference notebook book/_nbval/missing.ipynb",
        "book/removed.md: reference code cell 2 was removed from the page",
        "book/unexecuted.md: code cell 1 of the reference was never executed",
    ]
    # A downloaded notebook older than its page
    offered = book / "offered.ipynb"
    nbformat.write(
        v4.new_notebook(cells=[v4.new_code_cell("print(0)"), v4.new_code_cell("print(2)")]), offered
    )
    page = book / "same.md"
    assert (
        check_notebooks.with_reference(page, problems, nbformat.read(offered, 4), offered) is None
    )
    assert problems[-1] == "book/offered.ipynb: code cells differ from the page's: run `make book`"


def test_the_pages_the_cache_lacks_run_in_their_folder_and_are_found_by_the_build(book):
    from jupyter_cache import get_cache
    from myst_nb.core.read import read_myst_markdown_notebook

    good = write_page(book, "good", "from pathlib import Path\nprint(sorted(Path().glob('*.md')))")
    bad = write_page(book, "bad", "1 / 0")
    cache = book.parent / "cache"
    assert check_notebooks.fill_cache([good, bad], 2, cache) == ([good], [])
    # What myst-nb's cache mode looks up: the page as it reads it.
    store = get_cache(cache)
    as_the_book = read_myst_markdown_notebook(good.read_text(), path=good)
    record = store.match_cache_notebook(as_the_book)
    assert record.data == {"alone": False}
    (cell,) = check_notebooks.code_cells(store.get_cache_bundle(record.pk).nb)
    assert cell.execution_count == 1
    # run in the page's folder, as the build runs it, and its copies removed
    assert cell.outputs == [
        {
            "output_type": "stream",
            "name": "stdout",
            "text": "[PosixPath('bad.md'), PosixPath('good.md')]\n",
        }
    ]
    assert sorted(p.name for p in book.iterdir()) == ["bad.md", "good.md"]
    with pytest.raises(KeyError):
        store.match_cache_notebook(jupytext.read(bad))


def test_pages_run_alone_off_the_repository_are_cached_once_they_show_their_references(
    book, monkeypatch
):
    from jupyter_cache import get_cache

    monkeypatch.setenv("PYTHONPATH", str(ROOT / "tools"))
    shows = "print(sorted(Path().iterdir()), os.environ.get('PYTHONPATH'), sys.executable)"
    alone = write_page(book, "alone", "import os, sys\nfrom pathlib import Path\n" + shows)
    write_reference(alone, f"[PosixPath('alone.ipynb')] None {sys.executable}\n")
    reads = write_page(book, "reads", "print(len(open('reads.md').read()) > 0)")
    write_reference(reads, "True\n")
    drifted = write_page(book, "drifted", "print(0.51)")
    write_reference(drifted, "0.5\n")
    downloads = book.parent / "downloads"
    downloads.mkdir()
    for name in ("depthcore.tar.gz", "depthbook.tar.gz", "requirements.txt"):
        (downloads / name).write_text("")
    installs, run = [], subprocess.run
    monkeypatch.setattr(subprocess, "run", lambda cmd, *a, **k: installs.append(cmd)
                        if cmd[0] == "uv" else run(cmd, *a, **k))  # fmt: skip
    cache = book.parent / "cache"
    # Executed in the page's folder (as `make book` alone does), the page that reads its file runs.
    assert check_notebooks.fill_cache([reads], 1, cache) == ([reads], [])
    pages = [alone, reads, drifted]
    cached, problems = check_notebooks.fill_cache(
        pages, 2, cache, sys.executable, None, downloads, "uv"
    )
    # ... alone, it fails, and the page whose output differs from its reference is not cached.
    assert cached == [alone] and problems == ["2 fail alone, or differ (above)"]
    into = ["-q", "--python", sys.executable]
    archives = [downloads / "depthcore.tar.gz", downloads / "depthbook.tar.gz"]
    assert installs == [
        ["uv", "pip", "sync", *into, downloads / "requirements.txt"],
        ["uv", "pip", "install", *into, "--reinstall", "--no-deps", "--no-build-isolation"]
        + archives,
    ]
    records = {Path(r.uri).name: r.data for r in get_cache(cache).list_cache_records()}
    assert records == {"alone.md": {"alone": True}, "reads.md": {"alone": False}}


def test_a_built_book_is_needed_to_run_its_notebooks_alone(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(check_notebooks, "BOOK_DOWNLOADS", tmp_path / "downloads")
    monkeypatch.setattr(check_notebooks, "BOOK_SOURCES", tmp_path / "_sources")
    assert check_notebooks.main(["standalone", "--python", "python", "fig6"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("make check-downloads:\n")
    assert "depthcore.tar.gz not found: run `make book` first" in err
    assert "depthbook.tar.gz not found" in err and "requirements.txt not found" in err
    assert f"book/fig6.md: the book offers no notebook {tmp_path}/_sources/book/fig6.ipynb" in err


def test_update_writes_the_outputs_with_ids_of_their_cells_and_no_vector_copies(book):
    figure = {"text/plain": "<Figure>", "image/png": "iVBOR", "application/pdf": "JVBER"}
    page = write_page(book, "fig", "print(1)", f"from IPython.display import publish_display_data\n"
                      f"publish_display_data({figure!r})")  # fmt: skip
    assert check_notebooks.update([page], 1) == 0
    ref = check_notebooks.reference_path(page)
    first = ref.read_bytes()
    nb = nbformat.read(ref, as_version=4)
    one, shows = check_notebooks.code_cells(nb)
    assert (one.execution_count, one.outputs[0]["text"]) == (1, "1\n")
    assert set(shows.outputs[0]["data"]) == {"text/plain", "image/png"}
    assert check_notebooks.update([page], 1) == 0
    assert ref.read_bytes() == first  # an unchanged page, an unchanged reference


#: Outputs of a cell against the reference ``0.5``, and whether nbval takes them for it.
CASES = [
    ([("result", "0.5")], True),
    ([("result", "np.float64(0.5)")], True),  # NumPy 2's repr, sanitised
    ([("result", "0.5"), ("stderr", "a warning")], True),  # stderr skipped
    ([("svg", "<svg id='a1'/>")], True),  # SVG skipped (with the text 0.5)
    ([("result", "0.51")], False),  # a number the page shows
    ([("result", "0.5"), ("stdout", "more")], False),  # an output more
    ([], False),  # an output less
]


def test_nbval_with_this_plugin_compares_what_the_book_shows(tmp_path, monkeypatch):
    monkeypatch.setenv("JUPYTER_PATH", check_notebooks.KERNELS)
    lines = {
        "result": "display(Text({!r}))",
        "svg": "publish_display_data({{'text/plain': '0.5', 'image/svg+xml': {!r}}})",
        "stderr": "print({!r}, file=sys.stderr)",
        "stdout": "print({!r})",
    }
    head = (
        "import sys\nfrom IPython.display import display, publish_display_data\n\n"
        "class Text:\n    def __init__(self, t):\n        self.t = t\n\n"
        "    def __repr__(self):\n        return self.t\n"
    )
    cells = [v4.new_code_cell(head, execution_count=1)]
    for shows, _ in CASES:
        source = "\n".join(lines[kind].format(text) for kind, text in shows)
        reference = [v4.new_output("display_data", {"text/plain": "0.5"})]
        cells.append(v4.new_code_cell(source, execution_count=1, outputs=reference))
    nb = v4.new_notebook(cells=cells)
    nb.metadata.kernelspec = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nbformat.write(nb, tmp_path / "cells.ipynb")
    (tmp_path / "conftest.py").write_bytes(Path(check_notebooks.__file__).read_bytes())
    subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--nbval",
         f"--nbval-sanitize-with={check_notebooks.SANITIZE}", "--junitxml=nbval.xml",
         "cells.ipynb"],
        cwd=tmp_path,
        capture_output=True,
    )  # fmt: skip
    import xml.etree.ElementTree as ET

    verdicts = {
        case.get("name"): case.find("failure") is None and case.find("error") is None
        for case in ET.parse(tmp_path / "nbval.xml").getroot().iter("testcase")
    }
    assert [verdicts[f"Cell {i}"] for i in range(1, len(CASES) + 1)] == [s for _, s in CASES]


def test_make_test_executes_each_page_once_alone_before_the_builds():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = makefile_recipe("test")
    assert "tools/run-stages.sh check-lab $(LAB_BESIDE) $(TEST_STAGES)" in recipe
    steps = makefile.split("\nTEST_STAGES := ", 1)[1].split("\n", 1)[0].split()
    assert steps.index("core-and-setup") < steps.index("notebooks-alone") < steps.index("builds")
    assert steps.index("builds") < steps.index("check-book")
    # check-lab beside the stages from one of them on, waited for at the end.
    assert makefile.split("\nLAB_BESIDE := ", 1)[1].split("\n", 1)[0] in steps
    assert "check-downloads" not in steps + recipe.split()  # a second execution of every page
    alone = makefile_recipe("notebooks-alone")
    assert "cache --execute --python $(ALONE_VENV)/bin/python" in alone


STAGES_MAKEFILE = """\
one:
\t@echo one ran
two:
\t@sleep 0.2; echo two ran
three:
\t@echo three ran
beside:
\t@echo beside ran
broken:
\t@exit 3
"""


def _stages(tmp_path, *args):
    (tmp_path / "Makefile").write_text(STAGES_MAKEFILE, encoding="utf-8")
    return subprocess.run(
        [str(ROOT / "tools" / "run-stages.sh"), *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={**os.environ, "MAKE": "make"},
    )


def test_the_stage_runner_runs_in_order_times_each_and_runs_one_beside(tmp_path):
    out = _stages(tmp_path, "beside", "two", "one", "two", "three")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    ran = [line for line in lines if line.endswith(" ran")]
    # the stages in order; the one beside, started with "two", printed at the end
    assert ran == ["one ran", "two ran", "three ran", "beside ran"]
    assert "make test: beside took" in lines[-2]
    # each stage's whole seconds, which a stage's 0.2 s may carry across a second's boundary
    assert re.fullmatch(
        r"make test: passed \(one \d+ s, two \d+ s, three \d+ s; beside beside from two on\)",
        lines[-1],
    ), lines[-1]


def test_the_stage_runner_stops_at_the_first_failing_stage_and_fails(tmp_path):
    out = _stages(tmp_path, "beside", "one", "one", "broken", "three")
    assert out.returncode == 1
    assert "three ran" not in out.stdout and "beside ran" in out.stdout
    assert out.stderr.strip().endswith("make test: failed")


# --- JupyterLab ----------------------------------------------------------------------------


def kernelspec() -> dict:

    spec = json.loads(
        (ROOT / "tools" / "jupyter" / "kernels" / "python3" / "kernel.json").read_text()
    )
    return {"display_name": spec["display_name"], "language": spec["language"], "name": "python3"}


#: The pages JupyterLab opens as notebooks (the others, without front matter, as Markdown).
NOTEBOOK_PAGES = [
    page
    for page in sorted((ROOT / "book").glob("*.md"))
    if "kernelspec" in jupytext.reads(page.read_text(encoding="utf-8"), "md:myst").metadata
]


def test_the_notebook_pages_are_the_pages_with_code():
    assert {p.stem for p in NOTEBOOK_PAGES} >= {"intro", "fig2", "fig6", "beyond_frames"}


@pytest.mark.parametrize("page", NOTEBOOK_PAGES, ids=lambda p: p.stem)
def test_a_page_saved_unchanged_from_jupyterlab_keeps_its_bytes(page):
    import jupytext
    from jupytext.config import load_jupytext_configuration_file

    config = load_jupytext_configuration_file(str(ROOT / "jupytext.toml"))
    text = page.read_text(encoding="utf-8")
    nb = jupytext.reads(text, fmt="md:myst", config=config)
    # What JupyterLab adds when the page's kernel (the book's, make lab) starts.
    nb.metadata["kernelspec"] = kernelspec()
    nb.metadata["language_info"] = {"name": "python", "version": "3.11.7"}
    assert jupytext.writes(nb, fmt="md:myst", config=config) == text
