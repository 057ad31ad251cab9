"""Check that the book's displayed outputs have not drifted from the code.

Every book page listed in ``_toc.yml`` is a MyST Markdown notebook
``book/<name>.md``; its executed outputs are committed beside it as the
reference notebook ``book/_nbval/<name>.ipynb``.

``python tools/check_notebooks.py check`` (``make notebooks``)
    For each page, takes the inputs from the ``.md`` and the outputs from the
    committed reference (what ``jupytext --to ipynb --update`` does), and
    fails if

    * a page has no reference, or a reference has no page;
    * the page's code cells differ from the reference's (a code cell was added,
      removed or edited without refreshing the reference), or a reference code
      cell was never executed (nbval would not compare its output);
    * a code cell ends with a trailing ``;`` (nbval runs cells without
      history, so ``;`` does not hide the output there: write ``_ = ...``);

    and then runs every page again in a fresh kernel, with nbval comparing each
    cell's outputs with the reference (``tests/nbval_sanitize.cfg`` removes
    run-to-run noise such as memory addresses). A change to ``depthcore``
    that alters a number the book shows, at the precision it shows, fails.

``python tools/check_notebooks.py update`` (``make notebooks-update``)
    Executes every page in a fresh kernel and rewrites its reference: the
    deliberate update after a reviewed change of the book's outputs. It also
    deletes references whose page left the table of contents.

``check PAGE ...``, ``update PAGE ...`` (``make notebooks PAGES="fig6 cite"``)
    The same for the pages named alone; ``update`` then leaves every other
    reference as it is.

``python tools/check_notebooks.py standalone --python PY`` (``make notebooks-standalone``)
    The drift check of ``make test``, on the notebooks the built book offers
    (``_build/html/_sources/book/<name>.ipynb``, each page's download): each
    runs alone, in an empty folder of its own, with the kernel of ``PY``, a
    Python environment where only the book's ``requirements.txt`` and source
    archive (``_build/html/downloads/``) are installed; nbval compares every
    cell's outputs with the reference, as ``check`` does. A page that needs a
    file of the repository, or a cell that fails, fails the check. Run after
    ``make book``, whose execution of the pages it does not repeat.

``python tools/check_notebooks.py cache`` (before each book build)
    Keys the book's execution cache (``_build/.jupyter_cache``, Jupyter Book's
    ``execute_notebooks: cache``, shared by the HTML and the PDF builds) on
    what a page's outputs depend on beyond its code cells, which alone key
    jupyter-cache's records: the cache is emptied when depthcore (its source
    and data), ``requirements.txt`` or ``CITATION.cff`` changed, and a page's
    record is dropped when the page's text changed (its tables of glued
    numbers are shown by its cells). With ``--execute``, the
    pages it then lacks are executed, two at a time (``-n``), and cached as
    the build would, which would execute them one after the other.

The kernel runs in the page's folder, as it does in the book build. This
module is also loaded by pytest as a plugin (``-p check_notebooks``) to tell
nbval which outputs not to compare.
"""

from __future__ import annotations

import argparse
import difflib
import hashlib
import os
import re
import subprocess
import sys
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
REF_DIR_NAME = "_nbval"
TMP_PREFIX = ".nbval-check-"
SANITIZE = ROOT / "tests" / "nbval_sanitize.cfg"
TIMEOUT = 600  # seconds per cell, as `execute.timeout` in _config.yml
#: Seconds to wait, once a cell has finished, for its last outputs (nbclient's
#: ``iopub_timeout``, 4 s by default, after which it drops them with a mere warning:
#: on a loaded machine a cell that glues hundreds of numbers loses its last ones).
#: Every execution here waits this long and fails, rather than truncate, beyond it.
IOPUB_TIMEOUT = 120
#: Times a page's kernel is started before its failure to start is an error. A kernel binds
#: the ports that jupyter_client chose for it a moment before, and when another process takes
#: one in between (two pages execute at a time) it dies before answering.
KERNEL_STARTS = 3
#: What jupyter_client says of a kernel that died so.
KERNEL_DIED = "Kernel died before replying to kernel_info"


def with_kernel_starts(execute, starts: int = KERNEL_STARTS):
    """``execute()``, called again when its kernel died on starting, up to ``starts`` times."""
    for start in range(1, starts + 1):
        try:
            return execute()
        except RuntimeError as exc:
            if KERNEL_DIED not in str(exc) or start == starts:
                raise


#: The book's kernel, ``kernels/python3``: ipykernel, run by the Python that starts it,
#: without its notice about plain TCP on the loopback interface.
KERNELS = ROOT / "tools" / "jupyter"
#: The uv that installs the book's environment for the pages run alone: the one ``make``
#: puts in ``.venv/uv/`` (``--uv``).
UV = str(ROOT / ".venv" / "uv" / "bin" / "uv")

# Outputs nbval must not compare: stderr (warnings carry installation paths;
# matplotlib's one-off font-cache message), SVG (random element ids) and glued
# figures (PNG bytes vary across platforms; the PDF's vector copy carries its date).
# Images are shown, not quoted.
SKIP_COMPARE = (
    "stderr",
    "image/svg+xml",
    "application/pdf",
    "application/papermill.record/image/png",
    "application/papermill.record/application/pdf",
)
#: The figures' vector copies, which only the PDF build reads: a reference keeps the PNG.
VECTOR_ONLY = ("application/pdf", "application/papermill.record/application/pdf")


def pytest_collectstart(collector):
    """Pytest hook: extend nbval's list of output fields it does not compare."""
    if getattr(collector, "skip_compare", None) is not None:
        collector.skip_compare = tuple(collector.skip_compare) + SKIP_COMPARE


class CheckError(Exception):
    """A page or reference notebook is not in a state the check accepts."""


def toc_files(toc_path: Path = ROOT / "_toc.yml") -> list[str]:
    """Return the ``file`` entries of a jupyter-book ``_toc.yml``, in order."""
    import yaml

    toc = yaml.safe_load(toc_path.read_text(encoding="utf-8"))
    found: list[str] = []

    def walk(node):
        if isinstance(node, dict):
            for key in ("root", "file"):
                if isinstance(node.get(key), str):
                    found.append(node[key])
            for value in node.values():
                if isinstance(value, (list, dict)):
                    walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(toc)
    return found


def has_notebook_front_matter(text: str) -> bool:
    """True if a MyST page starts with front matter naming a kernel."""
    match = re.match(r"---\s*\n(.*?)\n---\s*\n", text, flags=re.DOTALL)
    return bool(match) and "kernelspec:" in match.group(1)


def notebook_pages() -> list[Path]:
    """The book pages that are notebooks, from ``_toc.yml``, in TOC order."""
    pages = []
    for entry in toc_files():
        candidates = (
            [ROOT / entry]
            if Path(entry).suffix
            else [ROOT / (entry + ext) for ext in (".md", ".ipynb")]
        )
        path = next((p for p in candidates if p.exists()), None)
        if path is None:
            raise CheckError(f"_toc.yml lists {entry!r}, but no such page exists")
        if path.suffix != ".md":
            raise CheckError(f"{path.relative_to(ROOT)}: book pages must be MyST .md files")
        text = path.read_text(encoding="utf-8")
        if has_notebook_front_matter(text):
            pages.append(path)
        elif re.search(r"^(```|~~~)\{code-cell\}", text, flags=re.MULTILINE):
            raise CheckError(
                f"{path.relative_to(ROOT)} has code cells but no jupytext/kernelspec "
                "front matter, so the book would not execute it"
            )
    return pages


def reference_path(page: Path) -> Path:
    """``book/x.md`` -> ``book/_nbval/x.ipynb``."""
    return page.parent / REF_DIR_NAME / (page.stem + ".ipynb")


def code_sources(nb) -> list[str]:
    return [cell.source for cell in nb.cells if cell.cell_type == "code"]


def structural_problems(page: Path, text_nb, ref_nb) -> list[str]:
    """Why the reference cannot vouch for this page's outputs (empty if it can)."""
    name = page.relative_to(ROOT)
    problems = []
    new, old = code_sources(text_nb), code_sources(ref_nb)
    if new != old:
        changes = []
        matcher = difflib.SequenceMatcher(a=old, b=new, autojunk=False)
        for op, i1, i2, j1, j2 in matcher.get_opcodes():
            if op in ("replace", "insert"):
                changes += [
                    f"code cell {j + 1} is new or edited: {new[j].strip()[:50]!r}"
                    for j in range(j1, j2)
                ]
            elif op == "delete":
                changes += [
                    f"reference code cell {i + 1} was removed: {old[i].strip()[:50]!r}"
                    for i in range(i1, i2)
                ]
        problems.append(
            f"{name}: code cells differ from "
            f"{reference_path(page).relative_to(ROOT)}: " + "; ".join(changes)
        )
    for i, cell in enumerate(c for c in ref_nb.cells if c.cell_type == "code"):
        if cell.get("execution_count") is None:
            problems.append(f"{name}: code cell {i + 1} of the reference was never executed")
    for i, source in enumerate(new):
        last = source.rstrip().splitlines()[-1] if source.strip() else ""
        if last.rstrip().endswith(";") and not last.lstrip().startswith("#"):
            problems.append(
                f"{name}: code cell {i + 1} ends with ';', which does not hide the output "
                "under nbval: assign it instead (`_ = ...`)"
            )
    return problems


def check(pages: list[Path], workers: int, every: list[Path] | None = None) -> int:
    import jupytext
    import nbformat
    from jupytext.combine import combine_inputs_with_outputs

    problems: list[str] = []
    combined = {}
    for page in pages:
        ref = reference_path(page)
        if not ref.exists():
            problems.append(
                f"{page.relative_to(ROOT)}: no reference notebook {ref.relative_to(ROOT)}"
            )
            continue
        text_nb = jupytext.read(page)
        ref_nb = nbformat.read(ref, as_version=4)
        found = structural_problems(page, text_nb, ref_nb)
        problems += found
        if not found:
            nb = combine_inputs_with_outputs(text_nb, ref_nb)
            assert all(c.execution_count is not None for c in nb.cells if c.cell_type == "code")
            combined[page] = nb
    problems += stale_problems(pages if every is None else every)
    if problems:
        print(
            "make notebooks: the committed reference outputs do not match the book:",
            file=sys.stderr,
        )
        for p in problems:
            print(f"  - {p}", file=sys.stderr)
        print(
            "After reviewing the change, run `make notebooks-update` and commit book/_nbval/.",
            file=sys.stderr,
        )
        return 1
    if not combined:
        print("make notebooks: no notebook pages in _toc.yml", file=sys.stderr)
        return 1

    # The copies sit next to their page, so that the kernel's cwd is the page's folder.
    tag = uuid.uuid4().hex[:8]
    copies = [page.parent / f"{TMP_PREFIX}{page.stem}-{tag}.ipynb" for page in combined]
    try:
        for copy, nb in zip(copies, combined.values(), strict=True):
            nbformat.write(nb, copy)
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            filter(None, [str(Path(__file__).parent), env.get("PYTHONPATH")])
        )
        returncode = run_nbval(copies, workers, sys.executable, ROOT, env, plugin=True)
    finally:
        for copy in copies:
            copy.unlink(missing_ok=True)
    if returncode != 0:
        print(
            "make notebooks: outputs differ from the committed references (see above). "
            "If the change is intended, run `make notebooks-update` and commit book/_nbval/.",
            file=sys.stderr,
        )
    return returncode


def run_nbval(
    notebooks: list[Path],
    workers: int,
    python: str,
    cwd: Path,
    env: dict,
    plugin: bool = False,
    sanitize: Path = SANITIZE,
) -> int:
    """Run nbval on ``notebooks`` with the pytest of ``python``; its return code.

    The kernel is the book's ``python3`` (:data:`KERNELS`, put first on
    ``JUPYTER_PATH`` by :func:`main`), run by ``python``.
    ``plugin``: this module is pytest's plugin (in the repository's
    environment); else ``cwd`` holds a conftest.py (:func:`conftest_text`).
    """
    cmd = [
        python,
        "-m",
        "pytest",
        "--nbval",
        *(["-p", "check_notebooks"] if plugin else ["-p", "no:cacheprovider"]),
        # one argument each: pytest takes a path given apart for a test path, and
        # finds the root of the notebooks' test ids from the paths it is given
        f"--nbval-sanitize-with={sanitize}",
        f"--nbval-cell-timeout={TIMEOUT}",
        f"--rootdir={cwd}",
        "-q",
        "-o",
        "console_output_style=classic",
    ]
    if workers > 1 and len(notebooks) > 1:
        cmd += ["-n", str(min(workers, len(notebooks))), "--dist", "loadfile"]
    cmd += [str(nb.relative_to(cwd)) for nb in notebooks]
    return subprocess.run(cmd, cwd=cwd, env=env).returncode


#: Where the HTML book offers each page's executed notebook (tools/sphinx).
BOOK_SOURCES = ROOT / "_build" / "html" / "_sources"
#: What the HTML book offers to install: the pinned requirements and the two source archives.
BOOK_DOWNLOADS = ROOT / "_build" / "html" / "downloads"
#: The same, as ``make downloads`` writes them, before the book is built.
BOOK_SOURCE_ARCHIVE = ROOT / "_build" / "extra" / "downloads" / "depthcore.tar.gz"
#: The archives a page run alone installs: the package and the book's own package.
ARCHIVES = ("depthcore.tar.gz", "depthbook.tar.gz")
BOOK_REQUIREMENTS = BOOK_SOURCE_ARCHIVE.parent / "requirements.txt"


def shown(path: Path) -> str:
    """``path`` relative to the repository when inside it, as messages name files."""
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def downloaded_notebook(page: Path, sources: Path = BOOK_SOURCES) -> Path:
    """``book/fig6.md`` -> the notebook the built book offers, ``_sources/book/fig6.ipynb``."""
    return sources / page.relative_to(ROOT).with_suffix(".ipynb")


def with_reference_outputs(nb, ref_nb):
    """``nb`` with the outputs of the reference's code cells (same code, checked before)."""
    refs = [c for c in ref_nb.cells if c.cell_type == "code"]
    cells = [c for c in nb.cells if c.cell_type == "code"]
    for cell, ref in zip(cells, refs, strict=True):
        cell.outputs = ref.outputs
        cell.execution_count = ref.execution_count
    return nb


def conftest_text() -> str:
    """A conftest.py for nbval's run outside the repository: :data:`SKIP_COMPARE`."""
    return (
        "def pytest_collectstart(collector):\n"
        '    if getattr(collector, "skip_compare", None) is not None:\n'
        f"        collector.skip_compare = tuple(collector.skip_compare) + {SKIP_COMPARE!r}\n"
    )


def environment_mismatch(
    python: str, requirements: Path, uv: str = UV
) -> tuple[list[str], list[str]]:
    """How the packages installed for ``python`` differ from the pins of ``requirements``.

    The installed distributions as ``uv pip list`` (``uv``) lists them.

    Returns
    -------
    unmet : list of str
        The pins (``name==version``) not installed at their version.
    foreign : list of str
        Installed distributions that are neither pinned nor depthcore, depthbook or pip.
    """
    listed = subprocess.run(
        [uv, "pip", "list", "--quiet", "--python", python, "--format", "freeze"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout

    def pins(lines) -> dict[str, str]:
        out = {}
        for line in lines:
            if "==" in line and not line.lstrip().startswith("#"):
                name, version = line.split("#")[0].strip().split("==", 1)
                out[re.sub(r"[-_.]+", "-", name).lower()] = version.strip()
        return out

    pinned = pins(requirements.read_text(encoding="utf-8").splitlines())
    installed = pins(listed.splitlines())
    unmet = [f"{n}=={v}" for n, v in sorted(pinned.items()) if installed.get(n) != v]
    foreign = sorted(set(installed) - set(pinned) - {"depthcore", "depthbook", "pip"})
    return unmet, foreign


def install_book_environment(
    python: str, downloads: Path = BOOK_DOWNLOADS, uv: str = UV
) -> str | None:
    """Install into ``python``'s environment the book's requirements and source archive.

    The environment a reader makes from the downloads: ``requirements.txt``
    (installed only when a pin is unmet) and the archives :data:`ARCHIVES` (always
    reinstalled, as they change with the tree), installed by ``uv``
    (``uv pip install``, as ``pip install`` would, in a second rather than five).

    Returns
    -------
    str or None
        Why the environment is not the book's (a pin unmet, a package not
        pinned), or None when it is.
    """
    requirements = downloads / "requirements.txt"
    install = [uv, "pip", "install", "--quiet", "--python", python]
    if environment_mismatch(python, requirements, uv)[0]:
        subprocess.run(install + ["-r", str(requirements)], check=True)
    subprocess.run(
        install
        + ["--no-build-isolation", "--reinstall", "--no-deps"]
        + [str(downloads / a) for a in ARCHIVES],
        check=True,
    )
    unmet, foreign = environment_mismatch(python, requirements, uv)
    if not (unmet or foreign):
        return None
    return f"{python} is not the book's environment: " + "; ".join(
        ([f"not installed: {', '.join(unmet)}"] if unmet else [])
        + ([f"not pinned: {', '.join(foreign)}"] if foreign else [])
    )


def standalone(
    pages: list[Path],
    python: str,
    workers: int,
    every: list[Path] | None = None,
    sources: Path = BOOK_SOURCES,
    downloads: Path = BOOK_DOWNLOADS,
    uv: str = UV,
) -> int:
    """Run each page's downloaded notebook alone with ``python`` and compare its outputs."""
    import tempfile

    # The notebooks run in a temporary folder: a relative path to the interpreter
    # (the Makefile's .venv/standalone/bin/python) is made absolute, not resolved,
    # which would leave the venv for the interpreter it links to.
    python = os.path.abspath(python)

    import jupytext
    import nbformat

    problems: list[str] = []
    for needed in [downloads / a for a in ARCHIVES] + [downloads / "requirements.txt"]:
        if not needed.is_file():
            problems.append(f"{shown(needed)} not found: run `make book` first")
    runs = {}
    for page in pages:
        ref, offered = reference_path(page), downloaded_notebook(page, sources)
        if not ref.exists():
            problems.append(
                f"{page.relative_to(ROOT)}: no reference notebook {ref.relative_to(ROOT)}"
            )
            continue
        if not offered.exists():
            problems.append(
                f"{page.relative_to(ROOT)}: the book offers no notebook "
                f"{shown(offered)}: run `make book` first"
            )
            continue
        ref_nb = nbformat.read(ref, as_version=4)
        nb = nbformat.read(offered, as_version=4)
        found = structural_problems(page, jupytext.read(page), ref_nb)
        if not found and code_sources(nb) != code_sources(ref_nb):
            found.append(
                f"{shown(offered)}: code cells differ from the page's: "
                "the book is older than the page, run `make book`"
            )
        problems += found
        if not found:
            runs[page] = with_reference_outputs(nb, ref_nb)
    problems += stale_problems(pages if every is None else every)
    if problems:
        print("make notebooks-standalone: cannot check the downloaded notebooks:", file=sys.stderr)
        for p in problems:
            print(f"  - {p}", file=sys.stderr)
        return 1

    mismatch = install_book_environment(python, downloads, uv)
    if mismatch is not None:
        print(f"make notebooks-standalone: {mismatch}", file=sys.stderr)
        return 1

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    with tempfile.TemporaryDirectory(prefix="depthcore-notebooks-") as tmp:
        root = Path(tmp)
        (root / "conftest.py").write_text(conftest_text(), encoding="utf-8")
        sanitize = root / SANITIZE.name
        sanitize.write_bytes(SANITIZE.read_bytes())
        copies = []
        for page, nb in runs.items():
            folder = root / page.stem
            folder.mkdir()
            copies.append(folder / f"{page.stem}.ipynb")
            nbformat.write(nb, copies[-1])
        print(
            f"running {len(copies)} downloaded notebooks, each alone in an empty folder of "
            f"{root}, with {python}",
            flush=True,
        )
        status = run_nbval(copies, workers, python, root, env, sanitize=sanitize.relative_to(root))
    if status != 0:
        print(
            "make notebooks-standalone: a downloaded notebook fails alone, or its outputs "
            "differ from the committed references (see above). If the change is intended, "
            "run `make notebooks-update` and commit book/_nbval/.",
            file=sys.stderr,
        )
    return status


def execution_cache(config_path: Path = ROOT / "_config.yml") -> Path:
    """Jupyter Book's execution cache, ``execute.cache`` of ``_config.yml``, under :data:`ROOT`."""
    import yaml

    config = yaml.safe_load(config_path.read_text(encoding="utf-8"))
    return ROOT / config["execute"]["cache"]


#: The execution cache that the HTML and the PDF builds share (``_build/.jupyter_cache``).
CACHE = execution_cache()
#: What every page's outputs may depend on besides its own text.
ENVIRONMENT = ("depthcore", "depthbook", "requirements.txt", "CITATION.cff", "tools/jupyter")
#: The key of the cache's contents, beside them.
CACHE_KEY = "depthcore-key.json"


def environment_fingerprint(root: Path = ROOT, inputs=ENVIRONMENT) -> str:
    """SHA-256 of the files of :data:`ENVIRONMENT` (paths and bytes, no bytecode)."""
    digest = hashlib.sha256()
    for name in inputs:
        path = root / name
        files = sorted(path.rglob("*")) if path.is_dir() else [path]
        for f in files:
            if not f.is_file() or "__pycache__" in f.parts or f.suffix == ".pyc":
                continue
            digest.update(f.relative_to(root).as_posix().encode() + b"\0")
            digest.update(hashlib.sha256(f.read_bytes()).digest())
    return digest.hexdigest()


def page_fingerprints(pages: list[Path], root: Path = ROOT) -> dict[str, str]:
    """SHA-256 of each page's text, by its path relative to ``root``."""
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in pages
    }


def prepare_cache(pages: list[Path], cache: Path = CACHE, root: Path = ROOT) -> list[str]:
    """Drop what the execution cache holds that is older than depthcore or a page's text.

    Returns
    -------
    list of str
        What was dropped: ``"all"``, or the pages whose records were dropped.
    """
    import json
    import shutil

    key = {"environment": environment_fingerprint(root), "pages": page_fingerprints(pages, root)}
    key_path = cache / CACHE_KEY
    old = json.loads(key_path.read_text(encoding="utf-8")) if key_path.is_file() else None
    dropped: list[str] = []
    if old is None or old.get("environment") != key["environment"]:
        if cache.exists():
            shutil.rmtree(cache)
            dropped.append("all")
    else:
        changed = {
            str((root / name).resolve())
            for name, digest in key["pages"].items()
            if old.get("pages", {}).get(name) != digest
        }
        if changed:
            from jupyter_cache import get_cache

            store = get_cache(cache)
            for record in store.list_cache_records():
                if str(Path(record.uri).resolve()) in changed:
                    store.remove_cache(record.pk)
                    dropped.append(Path(record.uri).resolve().relative_to(root).as_posix())
    cache.mkdir(parents=True, exist_ok=True)
    key_path.write_text(json.dumps(key, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return dropped


def read_as_the_book(page: Path):
    """The page as myst-nb reads it in the book's build (its cache key is this notebook's)."""
    from myst_nb.core.read import read_myst_markdown_notebook

    return read_myst_markdown_notebook(
        page.read_text(encoding="utf-8"), add_source_map=True, path=page
    )


def execute_for_cache(page: Path, alone: bool = False):
    """Execute ``page`` as myst-nb's cache mode does: (page, notebook, seconds, error text).

    ``alone``: in a folder of its own (made and removed here) that holds only
    the page's notebook, ``<page>.ipynb`` as the book offers it for download,
    rather than in the page's folder: as a reader runs the downloaded notebook.
    """
    import tempfile

    import nbformat
    from jupyter_cache.executors.utils import single_nb_execution

    with tempfile.TemporaryDirectory(prefix=f"depthcore-{page.stem}-") as folder:
        cwd = folder if alone else str(page.parent)

        def execute():
            nb = read_as_the_book(page)
            if alone:
                nbformat.write(nb, Path(folder) / f"{page.stem}.ipynb")
            result = single_nb_execution(
                nb,
                cwd=cwd,
                timeout=TIMEOUT,
                allow_errors=False,
                iopub_timeout=IOPUB_TIMEOUT,
                raise_on_iopub_timeout=True,
            )
            return nb, result

        nb, result = with_kernel_starts(execute)
    return page, nb, result.time, None if result.err is None else result.exc_string


def book_kernel(python: str, folder: Path) -> Path:
    """Write into ``folder`` the book's kernel run by ``python``; the folder for ``JUPYTER_PATH``.

    The kernel of :data:`KERNELS` names ``python``, which jupyter_client
    replaces by the Python that starts it; this copy names ``python`` itself,
    so that the kernel runs in that environment whoever starts it.
    """
    import json

    spec = KERNELS / "kernels" / "python3"
    target = folder / "kernels" / "python3"
    target.mkdir(parents=True, exist_ok=True)
    kernel = json.loads((spec / "kernel.json").read_text(encoding="utf-8"))
    kernel["argv"] = [os.path.abspath(python), *kernel["argv"][1:]]
    (target / "kernel.json").write_text(json.dumps(kernel, indent=1) + "\n", encoding="utf-8")
    (target / "launch.py").write_bytes((spec / "launch.py").read_bytes())
    return folder


def isolate(jupyter_path: str) -> None:
    """Start kernels from ``jupyter_path`` only, without the repository on their path.

    Run in each worker before it executes a page alone.
    """
    os.environ["JUPYTER_PATH"] = jupyter_path
    for name in ("PYTHONPATH", "VIRTUAL_ENV"):
        os.environ.pop(name, None)


#: The mark of a cache record executed alone (``data`` of the record).
ALONE = "alone"


def executed_alone(store, page: Path) -> bool | None:
    """Whether ``page``'s cached record was executed alone; None when it has none."""
    try:
        record = store.match_cache_notebook(read_as_the_book(page))
    except KeyError:
        return None
    return bool((record.data or {}).get(ALONE))


def fill_cache(
    pages: list[Path], workers: int, cache: Path = CACHE, python: str | None = None
) -> list[Path]:
    """Execute the pages the cache lacks, ``workers`` at a time, and cache their outputs.

    The book's build executes its pages one after the other; run first, this
    spreads them over the cores, and the build then finds every page cached.
    A page that fails is left out of the cache: the build runs it again and
    reports its error.

    ``python``: execute each page alone, as a reader runs its download: in a
    folder holding only its notebook, with the kernel of ``python`` (an environment holding only
    the book's requirements and source archive, see
    :func:`install_book_environment`), and the repository off the path. The
    pages then executed are those the cache lacks or holds from an execution
    that was not alone; their records are marked :data:`ALONE`.

    Returns
    -------
    list of Path
        The pages executed and cached.
    """
    import tempfile
    from concurrent.futures import ProcessPoolExecutor
    from functools import partial

    from jupyter_cache import get_cache
    from jupyter_cache.base import CacheBundleIn

    store = get_cache(cache)
    missing = [
        page
        for page in pages
        if executed_alone(store, page) in ((None, False) if python is not None else (None,))
    ]
    done = []
    if not missing:
        return done
    how = (
        "" if python is None else f", each alone in a folder with its notebook only, with {python}"
    )
    print(f"execution cache: executing {len(missing)} pages, {workers} at a time{how}", flush=True)
    with tempfile.TemporaryDirectory(prefix="depthcore-kernels-") as kernels:
        pool = ProcessPoolExecutor(
            max_workers=max(1, min(workers, len(missing))),
            **(
                {}
                if python is None
                else {
                    "initializer": isolate,
                    "initargs": (str(book_kernel(python, Path(kernels))),),
                }
            ),
        )
        with pool:
            run = partial(execute_for_cache, alone=python is not None)
            for page, nb, seconds, error in pool.map(run, missing):
                name = page.relative_to(ROOT) if page.is_relative_to(ROOT) else page
                if error is not None:
                    print(f"  {name}: failed, left to the build to report", flush=True)
                    if python is not None:
                        print(error, flush=True)
                    continue
                data = {"execution_seconds": seconds, ALONE: python is not None}
                store.cache_notebook_bundle(
                    CacheBundleIn(nb, str(page), data=data),
                    check_validity=False,
                    overwrite=True,
                )
                print(f"  {name}: executed in {seconds:.1f} s", flush=True)
                done.append(page)
    return done


def sanitize_patterns(path: Path = SANITIZE) -> dict[str, str]:
    """The regex replacements of nbval's sanitize file ``path``."""
    from nbval.plugin import get_sanitize_patterns

    return dict(get_sanitize_patterns(path.read_text(encoding="utf-8")))


#: What nbval leaves out of a comparison by default (``IPyNbFile.skip_compare``,
#: without --nbdime), and then :data:`SKIP_COMPARE`.
NBVAL_SKIP = (
    "metadata",
    "traceback",
    "prompt_number",
    "output_type",
    "name",
    "execution_count",
    "application/vnd.jupyter.widget-view+json",
    "image/png",
    "image/jpeg",
)


def output_difference(test: list, ref: list, patterns: dict[str, str]) -> str | None:
    """Compare one cell's outputs as nbval does; the first difference, or None.

    nbval's rule (``IPyNbCell.compare_outputs``): streams coalesced, then every
    output's fields and MIME types outside :data:`NBVAL_SKIP` and
    :data:`SKIP_COMPARE`, sanitised, compared in order within each field
    (the order across fields is free).
    """
    from collections import defaultdict

    from nbval.plugin import coalesce_streams, transform_streams_for_comparison

    skip = NBVAL_SKIP + SKIP_COMPARE

    def clean(value):
        if not isinstance(value, str):
            return value
        for regex, replace in patterns.items():
            value = re.sub(regex, replace, value)
        return value

    def flat(outputs) -> dict[str, list]:
        out = defaultdict(list)
        for output in transform_streams_for_comparison(coalesce_streams(list(outputs))):
            for key, value in output.items():
                if key in skip:
                    continue
                if key == "data":
                    for mime, content in value.items():
                        if mime not in skip:
                            out[mime].append(clean(content))
                else:
                    out[key].append(clean(value))
        return out

    new, old = flat(test), flat(ref)
    if set(old) - set(new):
        return f"missing output fields {sorted(set(old) - set(new))}"
    if set(new) - set(old):
        return f"unexpected output fields {sorted(set(new) - set(old))}"
    for key, values in old.items():
        if len(values) != len(new[key]):
            return f"{len(new[key])} outputs of {key!r}, the reference has {len(values)}"
        for was, now in zip(values, new[key], strict=True):
            if was != now:
                return f"{key!r} differs: reference {str(was)[:200]!r}, now {str(now)[:200]!r}"
    return None


def cached_drift(pages: list[Path], cache: Path = CACHE) -> list[str]:
    """How the cached outputs of ``pages`` differ from their references (empty if they do not).

    The drift check of :func:`check` on the execution the book builds from,
    without executing again: each page's code cells against its reference's
    (:func:`structural_problems`), then each cell's outputs as nbval compares
    them (:func:`output_difference`).
    """
    import jupytext
    import nbformat
    from jupyter_cache import get_cache

    store = get_cache(cache)
    patterns = sanitize_patterns()
    problems: list[str] = []
    for page in pages:
        name, ref = shown(page), reference_path(page)
        if not ref.exists():
            problems.append(f"{name}: no reference notebook {ref.relative_to(ROOT)}")
            continue
        ref_nb = nbformat.read(ref, as_version=4)
        found = structural_problems(page, jupytext.read(page), ref_nb)
        problems += found
        if found:
            continue
        try:
            record = store.match_cache_notebook(read_as_the_book(page))
        except KeyError:
            problems.append(f"{name}: not executed (it failed, see above)")
            continue
        nb = store.get_cache_bundle(record.pk).nb
        cells = [c for c in nb.cells if c.cell_type == "code"]
        refs = [c for c in ref_nb.cells if c.cell_type == "code"]
        for i, (cell, was) in enumerate(zip(cells, refs, strict=True)):
            difference = output_difference(cell.outputs, was.outputs, patterns)
            if difference is not None:
                problems.append(f"{name}: code cell {i + 1}: {difference}")
    return problems


def stable_cell_ids(nb) -> None:
    """Give cells ids derived from their content, so that an unchanged page
    rewrites to an unchanged reference (jupytext draws random ids)."""
    seen: dict[str, int] = {}
    for cell in nb.cells:
        digest = hashlib.sha1(f"{cell.cell_type}\n{cell.source}".encode()).hexdigest()[:8]
        seen[digest] = seen.get(digest, 0) + 1
        cell.id = digest if seen[digest] == 1 else f"{digest}-{seen[digest]}"


def drop_vector_copies(nb) -> None:
    """Remove the figures' PDF copies (:data:`VECTOR_ONLY`) from a notebook's outputs, in place."""
    for cell in nb.cells:
        for output in cell.get("outputs", []):
            for mime in VECTOR_ONLY:
                output.get("data", {}).pop(mime, None)


def update_page(page: Path) -> Path:
    """Execute ``page`` in a fresh kernel and write its outputs as its reference; return that."""
    import jupytext
    import nbformat
    from nbclient import NotebookClient

    def execute():
        nb = jupytext.read(page)
        NotebookClient(
            nb,
            # a cell that computes its study's record (make records) takes what the study takes
            timeout=None if os.environ.get("DEPTHCORE_RECORDS") == "write" else TIMEOUT,
            iopub_timeout=IOPUB_TIMEOUT,
            raise_on_iopub_timeout=True,
            kernel_name="python3",
            record_timing=False,
            resources={"metadata": {"path": str(page.parent)}},
        ).execute()
        return nb

    nb = with_kernel_starts(execute)
    stable_cell_ids(nb)
    drop_vector_copies(nb)
    ref = reference_path(page)
    ref.parent.mkdir(exist_ok=True)
    nbformat.write(nb, ref)
    return ref


def update(pages: list[Path], workers: int = 1) -> int:
    """Rewrite the references of ``pages``, executing ``workers`` of them at a time."""
    from concurrent.futures import ProcessPoolExecutor

    print(f"executing {len(pages)} pages, {workers} at a time", flush=True)
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        for ref in pool.map(update_page, pages):
            print(f"  wrote {ref.relative_to(ROOT)}", flush=True)
    return 0


def stale_references(pages: list[Path]) -> list[Path]:
    """The committed references whose page is not among ``pages`` (all pages of _toc.yml)."""
    known = {reference_path(p) for p in pages}
    return [r for r in sorted(ROOT.glob(f"book/**/{REF_DIR_NAME}/*.ipynb")) if r not in known]


def stale_problems(pages: list[Path]) -> list[str]:
    """A message for each reference of :func:`stale_references`, as the checks report them."""
    return [
        f"{ref.relative_to(ROOT)}: reference notebook of no page in _toc.yml"
        for ref in stale_references(pages)
    ]


def select_pages(pages: list[Path], names: list[str]) -> list[Path]:
    """The pages named (``fig6``, ``book/fig6.md`` or ``fig6.md``), in table-of-contents order.

    No names: every page. A name that is no page of ``_toc.yml`` raises :class:`CheckError`.
    """
    if not names:
        return pages
    by_stem = {p.stem: p for p in pages}
    wanted = {Path(name).stem for name in names}
    unknown = sorted(wanted - set(by_stem))
    if unknown:
        raise CheckError(f"not a page of _toc.yml: {', '.join(unknown)}")
    return [p for p in pages if p.stem in wanted]


def execute_alone(pages: list[Path], python: str, workers: int, uv: str = UV) -> int:
    """``cache --execute --python PY``: the one execution of each page in ``make test``.

    Installs the book's requirements and source archive into ``python``'s
    environment, executes alone every page the cache lacks (:func:`fill_cache`),
    and compares every page's cached outputs with its reference
    (:func:`cached_drift`). The PDF and the HTML builds then take every page
    from the cache.
    """
    problems = [
        f"{shown(needed)} not found: run `make downloads` first"
        for needed in (BOOK_SOURCE_ARCHIVE, BOOK_REQUIREMENTS)
        if not needed.is_file()
    ]
    mismatch = (
        None if problems else install_book_environment(python, BOOK_SOURCE_ARCHIVE.parent, uv)
    )
    if problems or mismatch is not None:
        for problem in problems or [mismatch]:
            print(f"make notebooks-alone: {problem}", file=sys.stderr)
        return 1
    fill_cache(pages, workers, python=python)
    problems = cached_drift(pages) + stale_problems(pages)
    if problems:
        print(
            "make notebooks-alone: the pages, executed alone, do not show what book/_nbval/ holds:",
            file=sys.stderr,
        )
        for p in problems:
            print(f"  - {p}", file=sys.stderr)
        print(
            "If the change is intended, run `make notebooks-update` and commit book/_nbval/.",
            file=sys.stderr,
        )
        return 1
    print(f"make notebooks-alone: {len(pages)} pages executed alone show their references")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=["check", "update", "standalone", "cache"])
    parser.add_argument(
        "--python",
        default=None,
        help="`standalone`, `cache --execute`: the Python of the environment that runs the "
        "notebooks alone (the book's requirements and source archive are installed into it)",
    )
    parser.add_argument(
        "--uv",
        default=UV,
        help="`standalone`, `cache --execute`: the uv that installs them (default: %(default)s)",
    )
    parser.add_argument(
        "-n",
        "--workers",
        type=int,
        default=2,
        help="pages executed at a time by `check`, `update`, `standalone` and `cache` (default 2)",
    )
    parser.add_argument(
        "--execute",
        action="store_true",
        help="`cache`: then execute the pages it lacks, --workers at a time",
    )
    parser.add_argument(
        "pages",
        nargs="*",
        help="only these pages (e.g. fig6); `update` then leaves every other reference alone",
    )
    args = parser.parse_args(argv)
    # Every kernel this module starts is the book's, also when run outside make.
    os.environ["JUPYTER_PATH"] = os.pathsep.join(
        dict.fromkeys(
            filter(None, [str(KERNELS), *os.environ.get("JUPYTER_PATH", "").split(os.pathsep)])
        )
    )
    try:
        every = notebook_pages()
        pages = select_pages(every, args.pages)
    except CheckError as err:
        print(f"make notebooks: {err}", file=sys.stderr)
        return 1
    if args.command == "check":
        return check(pages, args.workers, every)
    if args.command == "standalone":
        if args.python is None:
            print("make notebooks-standalone: --python is required", file=sys.stderr)
            return 1
        return standalone(pages, args.python, args.workers, every, uv=args.uv)
    if args.command == "cache":
        dropped = prepare_cache(every)
        if dropped:
            print(f"execution cache: dropped {', '.join(dropped)} (changed since executed)")
        if not args.execute:
            return 0
        if args.python is None:
            fill_cache(every, args.workers)
            return 0
        return execute_alone(every, args.python, args.workers, args.uv)
    status = update(pages, args.workers)
    if not args.pages:
        for ref in stale_references(every):
            ref.unlink()
            print(f"  deleted {ref.relative_to(ROOT)} (its page is not in _toc.yml)")
    return status


if __name__ == "__main__":
    sys.exit(main())
