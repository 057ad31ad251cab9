"""The notebook drift check's choice of pages (tools/check_notebooks.py), without executing any."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import check_notebooks  # noqa: E402

PAGES = check_notebooks.notebook_pages()


def test_no_names_select_every_page():
    assert check_notebooks.select_pages(PAGES, []) == PAGES


def test_names_select_those_pages_in_toc_order():
    chosen = check_notebooks.select_pages(PAGES, ["cite", "book/fig6.md", "fig2.md"])
    assert [p.stem for p in chosen] == ["fig2", "fig6", "cite"]


def test_an_unknown_page_is_refused_by_name():
    with pytest.raises(check_notebooks.CheckError, match="not a page of _toc.yml: nosuch"):
        check_notebooks.select_pages(PAGES, ["fig2", "nosuch"])


def test_only_references_of_pages_outside_the_toc_are_stale():
    assert check_notebooks.stale_references(PAGES) == []
    subset = check_notebooks.select_pages(PAGES, ["fig6"])
    stale = check_notebooks.stale_references(subset)
    assert check_notebooks.reference_path(PAGES[0]) in stale
    assert check_notebooks.reference_path(subset[0]) not in stale


def test_update_of_named_pages_leaves_the_other_references(monkeypatch):
    executed, deleted = [], []
    monkeypatch.setattr(
        check_notebooks, "update", lambda pages, workers: executed.extend(pages) or 0
    )
    monkeypatch.setattr(Path, "unlink", lambda self, *a, **k: deleted.append(self))
    assert check_notebooks.main(["update", "fig6"]) == 0
    assert [p.stem for p in executed] == ["fig6"] and deleted == []
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


def test_a_reference_keeps_the_png_of_a_figure_and_not_its_vector_copy():
    import nbformat

    nb = nbformat.v4.new_notebook()
    data = {"image/png": "iVBOR", "application/pdf": "JVBER", "text/plain": "<Figure>"}
    glued = {f"application/papermill.record/{k}": v for k, v in data.items()}
    nb.cells = [
        nbformat.v4.new_code_cell("fig", outputs=[nbformat.v4.new_output("display_data", data)]),
        nbformat.v4.new_code_cell("glue", outputs=[nbformat.v4.new_output("display_data", glued)]),
    ]
    check_notebooks.drop_vector_copies(nb)
    assert set(nb.cells[0].outputs[0].data) == {"image/png", "text/plain"}
    assert set(nb.cells[1].outputs[0].data) == {
        "application/papermill.record/image/png",
        "application/papermill.record/text/plain",
    }


def test_bytecode_does_not_change_the_fingerprint(tmp_path):
    root, _ = small_project(tmp_path)
    before = check_notebooks.environment_fingerprint(root)
    (root / "depthcore" / "__pycache__").mkdir()
    (root / "depthcore" / "__pycache__" / "model.cpython-311.pyc").write_bytes(b"\0")
    assert check_notebooks.environment_fingerprint(root) == before
    (root / "depthcore" / "model.py").write_text("X = 2\n")
    assert check_notebooks.environment_fingerprint(root) != before


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


def test_the_pages_the_cache_lacks_are_executed_and_found_by_the_build(tmp_path, monkeypatch):
    from jupyter_cache import get_cache

    monkeypatch.setenv("JUPYTER_PATH", str(check_notebooks.KERNELS))
    good, bad = tmp_path / "good.md", tmp_path / "bad.md"
    good.write_text(
        PAGE_HEAD + "from pathlib import Path\nprint(sorted(Path().glob('*.md')))\n```\n"
    )
    bad.write_text(PAGE_HEAD + "1 / 0\n```\n")
    cache = tmp_path / "cache"
    assert check_notebooks.fill_cache([good, bad], 2, cache) == [good]
    # What myst-nb's cache mode looks up: the page as it reads it.
    store = get_cache(cache)
    record = store.match_cache_notebook(check_notebooks.read_as_the_book(good))
    (cell,) = [c for c in store.get_cache_bundle(record.pk).nb.cells if c.cell_type == "code"]
    # run in the page's folder, as the build runs it
    assert cell.outputs[0]["text"] == "[PosixPath('bad.md'), PosixPath('good.md')]\n"
    assert check_notebooks.fill_cache([good], 2, cache) == []  # nothing left to execute
    with pytest.raises(KeyError):
        store.match_cache_notebook(check_notebooks.read_as_the_book(bad))


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


# --- the downloaded notebooks, run alone ---------------------------------------------------


def test_the_downloaded_notebook_of_a_page():
    page = ROOT / "book" / "fig6.md"
    assert check_notebooks.downloaded_notebook(page) == (
        ROOT / "_build" / "html" / "_sources" / "book" / "fig6.ipynb"
    )


def test_the_reference_outputs_replace_the_downloaded_ones():
    import nbformat

    v4 = nbformat.v4
    nb = v4.new_notebook(
        cells=[v4.new_markdown_cell("text"), v4.new_code_cell("1 + 1", execution_count=3)]
    )
    ref = v4.new_notebook(
        cells=[
            v4.new_code_cell(
                "1 + 1",
                execution_count=1,
                outputs=[v4.new_output("execute_result", {"text/plain": "2"}, execution_count=1)],
            )
        ]
    )
    out = check_notebooks.with_reference_outputs(nb, ref)
    assert out.cells[0].source == "text"
    assert out.cells[1].execution_count == 1
    assert out.cells[1].outputs[0]["data"]["text/plain"] == "2"


def test_the_standalone_conftest_skips_what_the_drift_check_skips():
    namespace: dict = {}
    exec(check_notebooks.conftest_text(), namespace)

    class Collector:
        skip_compare = ("metadata",)

    collector = Collector()
    namespace["pytest_collectstart"](collector)
    assert collector.skip_compare == ("metadata",) + check_notebooks.SKIP_COMPARE


def test_the_environment_is_the_pins_and_depthcore_alone(tmp_path, monkeypatch):
    import subprocess

    requirements = tmp_path / "requirements.txt"
    requirements.write_text("# pins\nNumPy==2.4.6\njupyter_client==8.10.0\nscipy==1.17.1\n")
    listed = "numpy==2.4.6\njupyter-client==8.9.0\npip==24.0\ndepthcore==1.0\nrequests==2.0\n"
    monkeypatch.setattr(
        subprocess, "run", lambda *a, **k: subprocess.CompletedProcess(a, 0, stdout=listed)
    )
    unmet, foreign = check_notebooks.environment_mismatch("python", requirements)
    assert unmet == ["jupyter-client==8.10.0", "scipy==1.17.1"]
    assert foreign == ["requests"]


def test_standalone_refuses_to_run_without_a_built_book(tmp_path, capsys):
    page = check_notebooks.select_pages(PAGES, ["fig6"])
    status = check_notebooks.standalone(
        page, "python", 1, PAGES, sources=tmp_path / "_sources", downloads=tmp_path / "downloads"
    )
    err = capsys.readouterr().err
    assert status == 1
    assert "depthcore.tar.gz not found" in err and "offers no notebook" in err


# --- one execution of each page, alone, for the drift check and the builds ----------------


def output(kind: str, text: str):
    import nbformat

    if kind in ("stdout", "stderr"):
        return nbformat.v4.new_output("stream", name=kind, text=text)
    return nbformat.v4.new_output("execute_result", {"text/plain": text}, execution_count=1)


#: Outputs of a cell against the reference ``0.5``, and whether nbval takes them for it.
CASES = [
    ([output("result", "0.5")], True),
    ([output("result", "np.float64(0.5)")], True),  # NumPy 2's repr, sanitised
    ([output("result", "0.5"), output("stderr", "a warning\n")], True),  # stderr skipped
    ([output("result", "0.51")], False),  # a number the page shows
    ([output("result", "0.5"), output("stdout", "more\n")], False),  # an output more
    ([], False),  # an output less
]


def test_outputs_compare_as_nbval_compares_them(tmp_path):
    """The comparison of the cached outputs gives nbval's verdict, run on the same cells."""
    import os
    import subprocess
    import xml.etree.ElementTree as ET

    import nbformat

    patterns = check_notebooks.sanitize_patterns()
    ref = [output("result", "0.5")]
    assert [check_notebooks.output_difference(new, ref, patterns) is None for new, _ in CASES] == [
        same for _, same in CASES
    ]
    # nbval itself, one cell per case: each shows what the case holds, against the reference.
    v4 = nbformat.v4
    head = (
        "import sys\nfrom IPython.display import display\n\n"
        "class Text:\n    def __init__(self, t):\n        self.t = t\n\n"
        "    def __repr__(self):\n        return self.t\n"
    )
    cells = [v4.new_code_cell(head, execution_count=1)]
    for new, _ in CASES:
        lines = [
            f"print({out.text[:-1]!r}, file=sys.{out.name})"
            if out.output_type == "stream"
            else f"display(Text({out.data['text/plain']!r}))"
            for out in new
        ]
        reference = [v4.new_output("display_data", {"text/plain": "0.5"})]
        cells.append(v4.new_code_cell("\n".join(lines), execution_count=1, outputs=reference))
    nb = v4.new_notebook(cells=cells)
    nb.metadata.kernelspec = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nbformat.write(nb, tmp_path / "cells.ipynb")
    (tmp_path / "conftest.py").write_text(check_notebooks.conftest_text())
    subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--nbval",
         f"--nbval-sanitize-with={check_notebooks.SANITIZE}", "--junitxml=nbval.xml",
         "cells.ipynb"],
        cwd=tmp_path,
        capture_output=True,
        env={**os.environ, "JUPYTER_PATH": str(check_notebooks.KERNELS)},
    )  # fmt: skip
    verdicts = {
        case.get("name"): case.find("failure") is None and case.find("error") is None
        for case in ET.parse(tmp_path / "nbval.xml").getroot().iter("testcase")
    }
    assert [verdicts[f"Cell {i}"] for i in range(1, len(CASES) + 1)] == [s for _, s in CASES]


def test_pages_executed_alone_run_beside_their_notebook_alone_off_the_repository(
    tmp_path, monkeypatch
):
    from jupyter_cache import get_cache

    monkeypatch.setenv("JUPYTER_PATH", str(check_notebooks.KERNELS))
    monkeypatch.setenv("PYTHONPATH", str(ROOT / "tools"))
    alone = tmp_path / "alone.md"
    alone.write_text(
        PAGE_HEAD
        + "import os, sys\nfrom pathlib import Path\n"
        + "print(sorted(Path().iterdir()), os.environ.get('PYTHONPATH'), sys.executable)\n```\n"
    )
    reads = tmp_path / "reads.md"
    reads.write_text(PAGE_HEAD + "open('reads.md').read()\n```\n")
    cache = tmp_path / "cache"
    # Executed beside the page (as `make book` alone does), the page that reads its file runs.
    assert check_notebooks.fill_cache([reads], 1, cache) == [reads]
    store = get_cache(cache)
    assert check_notebooks.executed_alone(store, reads) is False
    done = check_notebooks.fill_cache([alone, reads], 2, cache, python=sys.executable)
    # ... alone, it fails, and its record from the page's folder is not taken for one alone.
    assert done == [alone]
    assert check_notebooks.executed_alone(store, alone) is True
    assert check_notebooks.executed_alone(store, reads) is False
    record = store.match_cache_notebook(check_notebooks.read_as_the_book(alone))
    (cell,) = [c for c in store.get_cache_bundle(record.pk).nb.cells if c.cell_type == "code"]
    # the folder holds the page's notebook alone, as a reader's download folder
    assert cell.outputs[0]["text"] == f"[PosixPath('alone.ipynb')] None {sys.executable}\n"
    # Nothing left to execute alone: a record executed alone is kept.
    assert check_notebooks.fill_cache([alone], 2, cache, python=sys.executable) == []


def test_the_cached_outputs_are_compared_with_the_references(tmp_path, monkeypatch):
    import nbformat

    monkeypatch.setenv("JUPYTER_PATH", str(check_notebooks.KERNELS))
    monkeypatch.setattr(check_notebooks, "ROOT", tmp_path)
    pages = []
    for name, shows, reference in (("same", "0.5", "0.5"), ("drifted", "0.51", "0.5")):
        page = tmp_path / f"{name}.md"
        page.write_text(PAGE_HEAD + f"print({shows})\n```\n")
        ref = check_notebooks.reference_path(page)
        ref.parent.mkdir(exist_ok=True)
        nb = nbformat.v4.new_notebook(
            cells=[
                nbformat.v4.new_markdown_cell("# A page"),
                nbformat.v4.new_code_cell(
                    f"print({shows})",
                    execution_count=1,
                    outputs=[
                        nbformat.v4.new_output("stream", name="stdout", text=reference + "\n")
                    ],
                ),
            ]
        )
        nbformat.write(nb, ref)
        pages.append(page)
    cache = tmp_path / "cache"
    missing = tmp_path / "missing.md"
    missing.write_text(PAGE_HEAD + "print(1)\n```\n")
    assert check_notebooks.fill_cache(pages, 2, cache, python=sys.executable) == pages
    problems = check_notebooks.cached_drift([*pages, missing], cache)
    assert len(problems) == 2, problems
    assert problems[0].startswith("drifted.md: code cell 1: 'stdout' differs")
    assert problems[1].startswith("missing.md: no reference notebook")


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
    import json

    spec = json.loads(
        (ROOT / "tools" / "jupyter" / "kernels" / "python3" / "kernel.json").read_text()
    )
    return {"display_name": spec["display_name"], "language": spec["language"], "name": "python3"}


#: The pages JupyterLab opens as notebooks (the others, without front matter, as Markdown).
NOTEBOOK_PAGES = [
    page
    for page in sorted((ROOT / "book").glob("*.md"))
    if check_notebooks.has_notebook_front_matter(page.read_text(encoding="utf-8"))
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


def test_a_kernel_that_dies_on_starting_is_started_again_then_named():
    # jupyter_client's message for a kernel that could not bind its ports: started again,
    # up to KERNEL_STARTS times; any other error, or the last such death, is raised.
    calls = []

    def dies_once():
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError(check_notebooks.KERNEL_DIED)
        return "ran"

    assert check_notebooks.with_kernel_starts(dies_once) == "ran" and len(calls) == 2

    def always_dies():
        calls.append(1)
        raise RuntimeError(check_notebooks.KERNEL_DIED)

    calls.clear()
    with pytest.raises(RuntimeError, match=check_notebooks.KERNEL_DIED):
        check_notebooks.with_kernel_starts(always_dies)
    assert len(calls) == check_notebooks.KERNEL_STARTS

    def other_error():
        calls.append(1)
        raise RuntimeError("Kernel didn't respond in 60 seconds")

    calls.clear()
    with pytest.raises(RuntimeError, match="didn't respond"):
        check_notebooks.with_kernel_starts(other_error)
    assert len(calls) == 1
