"""Check that the book's displayed outputs have not drifted from the code, with nbval.

Each notebook page ``book/<name>.md`` of ``_toc.yml`` has a reference ``book/_nbval/<name>.ipynb``.
nbval runs the pages (read by jupytext; ``tests/nbval_sanitize.cfg``; this module is its plugin)
``-n`` at a time (pytest-xdist), in their folder or (``--python``) alone, with the downloads only.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import jupytext
import nbformat
from jupyter_cache import get_cache
from jupyter_cache.base import CacheBundleIn
from nbval.plugin import get_sanitize_patterns
from sphinx_external_toc.parsing import parse_toc_yaml

ROOT = Path(__file__).resolve().parent.parent
REF_DIR_NAME, TMP_PREFIX = "_nbval", ".nbval-check-"
SANITIZE = ROOT / "tests" / "nbval_sanitize.cfg"
TIMEOUT = 600  # seconds per cell, as `execute.timeout` in _config.yml
KERNELS, UV = str(ROOT / "tools" / "jupyter"), str(ROOT / ".venv" / "uv" / "bin" / "uv")
VECTOR_ONLY = ("application/pdf", "application/papermill.record/application/pdf")
BOOK_SOURCES, BOOK_DOWNLOADS = ROOT / "_build/html/_sources", ROOT / "_build/html/downloads"
DOWNLOADS = ROOT / "_build" / "extra" / "downloads"  # the same, by `make downloads`
ARCHIVES = ("depthcore.tar.gz", "depthbook.tar.gz")
CACHE, CACHE_KEY = ROOT / "_build" / ".jupyter_cache", "depthcore-key.json"  # and its key
ENVIRONMENT = ("depthcore", "depthbook", "requirements.txt", "CITATION.cff", "tools/jupyter")
AFTER = "If the change is intended, run `make notebooks-update` and commit book/_nbval/."
#: Not compared: stderr (paths), SVG (random ids), figures' glued PNG and dated vector copies.
SKIP_COMPARE = ("stderr", "image/svg+xml", "application/papermill.record/image/png", *VECTOR_ONLY)


def pytest_collectstart(collector):
    """Pytest hook, as nbval's plugin (``-p check_notebooks`` or conftest.py): not compared."""
    if getattr(collector, "skip_compare", None) is not None:
        collector.skip_compare = tuple(collector.skip_compare) + SKIP_COMPARE


def pytest_runtest_makereport(item, call):
    """Pytest hook: append to $DEPTHCORE_NBVAL_OUTPUTS/<notebook>.jsonl what each cell showed."""
    item.output_timeout = 120  # seconds for a cell's last outputs once it ran (nbval: 5)
    if (folder := os.getenv("DEPTHCORE_NBVAL_OUTPUTS")) and (call.excinfo or call.when == "call"):
        outputs = None if call.excinfo else getattr(item, "test_outputs", None)  # None: failed
        with open(Path(folder, f"{item.path.name}.jsonl"), "a", encoding="utf-8") as log:
            log.write(json.dumps(outputs) + "\n")


def toc_files(toc_path: Path = ROOT / "_toc.yml") -> list[str]:
    """The documents of ``_toc.yml`` in order, as Jupyter Book reads them."""
    return list(parse_toc_yaml(toc_path))


def notebook_pages() -> list[Path]:
    """The book pages that jupytext reads as notebooks (a kernelspec), in TOC order."""
    pages = []
    for path in (ROOT / f"{entry}.md" for entry in toc_files()):
        text = path.read_text(encoding="utf-8")
        if text.startswith("---") and "kernelspec" in jupytext.reads(text, "md:myst").metadata:
            pages.append(path)
        elif re.search(r"^(```|~~~)\{code-cell\}", text, flags=re.MULTILINE):
            raise ValueError(f"{shown(path)} has code cells but no kernelspec front matter")
    return pages


def select_pages(pages: list[Path], names: list[str]) -> list[Path]:
    """The pages named (``fig6``, ``book/fig6.md``), in TOC order; every page without names."""
    wanted = {Path(name).stem for name in names}
    if unknown := sorted(wanted - {p.stem for p in pages}):
        raise ValueError(f"not a page of _toc.yml: {', '.join(unknown)}")
    return [p for p in pages if not names or p.stem in wanted]


def shown(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def reference_path(page: Path) -> Path:
    return page.parent / REF_DIR_NAME / (page.stem + ".ipynb")


def stale_references(pages: list[Path]) -> list[Path]:
    known = {reference_path(p) for p in pages}
    return [r for r in sorted(ROOT.glob(f"book/**/{REF_DIR_NAME}/*.ipynb")) if r not in known]


def sanitize_patterns(path: Path = SANITIZE) -> dict[str, str]:
    return dict(get_sanitize_patterns(path.read_text(encoding="utf-8")))


def code_cells(nb) -> list:
    return [cell for cell in nb.cells if cell.cell_type == "code"]


def with_reference(page: Path, problems: list[str], nb, origin: Path | None = None):
    """``nb`` (the page's) with its reference's outputs; None if the reference cannot vouch."""
    ref, name, found = reference_path(page), shown(page), []
    if not ref.exists():
        return problems.append(f"{name}: no reference notebook {shown(ref)}")
    new, old = code_cells(jupytext.read(page)), code_cells(nbformat.read(ref, as_version=4))
    for i, cell in enumerate(new):
        if i >= len(old) or cell.source != old[i].source:
            found.append(f"{name}: code cell {i + 1} is new or edited: {cell.source[:50]!r}")
            break
        if old[i].get("execution_count") is None:
            found.append(f"{name}: code cell {i + 1} of the reference was never executed")
        if re.search(r"^(?!\s*#).*;\s*\Z", cell.source.rstrip(), flags=re.MULTILINE):
            found.append(f"{name}: code cell {i + 1} ends with ';': assign it (`_ = ...`)")
    if len(old) > len(new) and not found:
        found.append(f"{name}: reference code cell {len(new) + 1} was removed from the page")
    if origin and not found and [c.source for c in new] != [c.source for c in code_cells(nb)]:
        found.append(f"{shown(origin)}: code cells differ from the page's: run `make book`")
    for cell, was in zip(code_cells(nb), old, strict=False):
        cell.outputs, cell.execution_count = was.outputs, was.execution_count
    problems += found
    return None if found else nb


def report(what: str, problems: list[str], after: str = AFTER) -> int:
    if problems:
        print(f"{what}:", *(f"  - {p}" for p in problems), after, sep="\n", file=sys.stderr)
    return int(bool(problems))


def nbval(runs: dict, workers: int, python: str | None = None, compare: bool = True):
    """nbval's return code on ``runs`` ({page: notebook}), and those that passed, as they ran."""
    if not runs:
        return 0, {}
    timeout = 24 * 3600 if os.environ.get("DEPTHCORE_RECORDS") == "write" else TIMEOUT
    cmd = [python or sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
    cmd += ["--nbval" if compare else "--nbval-lax", f"--nbval-cell-timeout={timeout}"]
    cmd += [f"--nbval-sanitize-with={SANITIZE}", f"--numprocesses={min(workers, len(runs))}"]
    path = [str(Path(__file__).parent), os.getenv("PYTHONPATH", "")]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(path))
    if python:  # off the repository, where this plugin is the root's conftest.py
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    with tempfile.TemporaryDirectory(prefix="depthcore-notebooks-") as tmp:
        root = Path(tmp) if python else ROOT
        copies = {p: Path(tmp, p.stem, f"{p.stem}.ipynb") for p in runs}  # alone, as downloaded
        if not python:  # beside the page: the kernel runs in the page's folder
            copies = {p: p.parent / f"{TMP_PREFIX}{p.stem}-{Path(tmp).name}.ipynb" for p in runs}
            cmd += ["-p", "check_notebooks"]
        for page, copy in copies.items():
            copy.parent.mkdir(exist_ok=True)
            nbformat.write(runs[page], copy)
        shutil.copy(__file__, Path(tmp, "conftest.py"))
        env["DEPTHCORE_NBVAL_OUTPUTS"] = tmp
        try:
            cmd += ["--dist=loadfile", f"--rootdir={root}", *map(str, copies.values())]
            status = subprocess.run(cmd, cwd=root, env=env).returncode
        finally:
            for copy in copies.values():
                copy.unlink(missing_ok=True)
        done = {p: Path(tmp, f"{c.name}.jsonl") for p, c in copies.items()}
        done = {p: f.read_text().splitlines() for p, f in done.items() if f.is_file()}
    done = {p: [json.loads(x) for x in lines] for p, lines in done.items() if "null" not in lines}
    for page, outputs in done.items():
        for count, (cell, out) in enumerate(zip(code_cells(runs[page]), outputs, strict=True), 1):
            cell.outputs, cell.execution_count = nbformat.from_dict(out), count
    return status, {page: runs[page] for page in done}


def alone(pages, python, workers, every, downloads, uv=UV, sources=None):
    """Check each page (or the notebook the book offers, ``sources``) alone with ``python``."""
    needed = [downloads / name for name in (*ARCHIVES, "requirements.txt")]
    make = "book" if sources else "downloads"
    problems = [f"{shown(f)} not found: run `make {make}` first" for f in needed if not f.is_file()]
    problems += [f"{shown(r)}: reference of no page in _toc.yml" for r in stale_references(every)]
    runs, python = {}, os.path.abspath(python)
    for page in pages:
        path = sources / page.relative_to(ROOT).with_suffix(".ipynb") if sources else None
        if path and not path.is_file():
            problems.append(f"{shown(page)}: the book offers no notebook {shown(path)}")
            continue
        nb = nbformat.read(path, as_version=4) if path else jupytext.read(page)
        runs[page] = with_reference(page, problems, nb, path)
    if problems:
        return problems, {}
    into, again = ["-q", "--python", python], ["--reinstall", "--no-deps", "--no-build-isolation"]
    subprocess.run([uv, "pip", "sync", *into, needed[-1]], check=True)  # the pins exactly,
    subprocess.run([uv, "pip", "install", *into, *again, *needed[:2]], check=True)  # the archives
    status, executed = nbval(runs, workers, python)
    return [f"{len(runs) - len(executed)} fail alone, or differ (above)"] * bool(status), executed


def digest(*files: Path) -> str:
    return hashlib.sha256(b"".join(f.read_bytes() for f in files if f.is_file())).hexdigest()


def prepare_cache(pages: list[Path], cache: Path = CACHE, root: Path = ROOT) -> list[str]:
    """Drop all if the environment changed, else the records of pages changed; what it dropped."""
    files = [f for n in ENVIRONMENT for f in sorted((root / n).rglob("*")) or [root / n]]
    files = [f for f in files if f.is_file() and "__pycache__" not in f.parts]
    environment = {f.relative_to(root).as_posix(): digest(f) for f in files}
    key = {"environment": hashlib.sha256(json.dumps(environment).encode()).hexdigest()}
    key["pages"] = {p.relative_to(root).as_posix(): digest(p, reference_path(p)) for p in pages}
    path = cache / CACHE_KEY
    old, dropped = json.loads(path.read_text()) if path.is_file() else {}, []
    if old.get("environment") != key["environment"]:
        dropped = ["all"] * cache.exists()
        shutil.rmtree(cache, ignore_errors=True)
    else:
        store = get_cache(cache)
        for record in store.list_cache_records():  # jupyter-cache keys them on code cells alone
            name = os.path.relpath(record.uri, root)
            if name in key["pages"] and key["pages"][name] != old["pages"].get(name):
                store.remove_cache(record.pk)
                dropped.append(name)
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(key, indent=1, sort_keys=True) + "\n")
    return dropped


def fill_cache(pages, workers, cache=CACHE, python=None, every=None, downloads=DOWNLOADS, uv=UV):
    """Cache the pages it lacks (with ``python``: lacks from a run alone, then checked)."""
    store, records = get_cache(cache), get_cache(cache).list_cache_records()
    was = {Path(r.uri).resolve(): bool((r.data or {}).get("alone")) for r in records}
    missing = [p for p in pages if was.get(p.resolve()) is None or python and not was[p.resolve()]]
    if python:
        problems, executed = alone(missing, python, workers, every or pages, downloads, uv)
    else:
        runs = {p: jupytext.read(p) for p in missing}
        problems, executed = [], nbval(runs, workers, compare=False)[1]
    for page, nb in executed.items():
        bundle = CacheBundleIn(nb, str(page), data={"alone": python is not None})
        store.cache_notebook_bundle(bundle, check_validity=False, overwrite=True)
    return list(executed), problems


def update(pages: list[Path], workers: int, every: list[Path] | None = None) -> int:
    """Rewrite the references of ``pages``; delete the stale ones of ``every``."""
    status, executed = nbval({page: jupytext.read(page) for page in pages}, workers, compare=False)
    for page, nb in executed.items():
        seen: dict[str, int] = {}
        for cell in nb.cells:  # ids from the content: an unchanged page, an unchanged reference
            cid = hashlib.sha1(f"{cell.cell_type}\n{cell.source}".encode()).hexdigest()[:8]
            seen[cid] = seen.get(cid, 0) + 1
            cell.id = cid if seen[cid] == 1 else f"{cid}-{seen[cid]}"
            for output in cell.get("outputs", []):  # a figure's PNG, not its vector copy
                for mime in VECTOR_ONLY:
                    output.get("data", {}).pop(mime, None)
        reference_path(page).parent.mkdir(exist_ok=True)
        nbformat.write(nb, reference_path(page))
        print(f"  wrote {shown(reference_path(page))}", flush=True)
    for ref in stale_references(every) if every else []:
        ref.unlink()
        print(f"  deleted {shown(ref)} (its page is not in _toc.yml)")
    return int(bool(status))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=["check", "update", "standalone", "cache"])
    parser.add_argument("--python", help="the Python of the environment of pages run alone")
    parser.add_argument("--uv", default=UV, help="the uv that installs it (default: %(default)s)")
    parser.add_argument("-n", "--workers", type=int, default=2, help="pages at a time (default 2)")
    parser.add_argument("--execute", action="store_true", help="`cache`: execute what it lacks")
    parser.add_argument("pages", nargs="*", help="only these pages (e.g. fig6)")
    args = parser.parse_intermixed_args(argv)
    os.environ["JUPYTER_PATH"] = os.pathsep.join(filter(None, [KERNELS, os.getenv("JUPYTER_PATH")]))
    try:
        pages = select_pages(every := notebook_pages(), args.pages)
    except ValueError as err:
        return report("make notebooks", [str(err)], "")
    if args.command == "update":
        return update(pages, args.workers, None if args.pages else every)
    if args.command == "check":
        problems: list[str] = []
        runs = {page: with_reference(page, problems, jupytext.read(page)) for page in pages}
        problems += [f"{shown(r)}: reference of no page" for r in stale_references(every)]
        if report("make notebooks: the committed references do not match the book", problems):
            return 1
        failed = ["outputs differ from the references (above)"] * bool(nbval(runs, args.workers)[0])
        return report("make notebooks", failed)
    if args.command == "standalone":
        python = args.python or str(ROOT / ".venv" / "standalone" / "bin" / "python")
        run = (pages, python, args.workers, every, BOOK_DOWNLOADS, args.uv, BOOK_SOURCES)
        return report("make check-downloads", alone(*run)[0])
    if dropped := prepare_cache(every):
        print(f"execution cache: dropped {', '.join(dropped)} (changed since executed)")
    if not args.execute:
        return 0
    problems = fill_cache(every, args.workers, python=args.python, uv=args.uv)[1]
    if args.python and not report("make notebooks-alone", problems):
        print(f"make notebooks-alone: {len(every)} pages executed alone show their references")
    return int(bool(problems))


if __name__ == "__main__":
    sys.exit(main())
