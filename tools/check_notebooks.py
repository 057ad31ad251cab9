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

# Outputs nbval must not compare: stderr (warnings carry installation paths;
# matplotlib's one-off font-cache message), SVG (random element ids) and glued
# figures (PNG bytes vary across platforms). Images are shown, not quoted.
SKIP_COMPARE = ("stderr", "image/svg+xml", "application/papermill.record/image/png")


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
    for ref in stale_references(pages if every is None else every):
        problems.append(f"{ref.relative_to(ROOT)}: reference notebook of no page in _toc.yml")
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
        cmd = [
            sys.executable,
            "-m",
            "pytest",
            "--nbval",
            "--nbval-current-env",
            "--nbval-sanitize-with",
            str(SANITIZE),
            "--nbval-cell-timeout",
            str(TIMEOUT),
            "-p",
            "check_notebooks",
            "-q",
            "-o",
            "console_output_style=classic",
        ]
        if workers > 1 and len(copies) > 1:
            cmd += ["-n", str(min(workers, len(copies))), "--dist", "loadfile"]
        cmd += [str(c.relative_to(ROOT)) for c in copies]
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            filter(None, [str(Path(__file__).parent), env.get("PYTHONPATH")])
        )
        result = subprocess.run(cmd, cwd=ROOT, env=env)
    finally:
        for copy in copies:
            copy.unlink(missing_ok=True)
    if result.returncode != 0:
        print(
            "make notebooks: outputs differ from the committed references (see above). "
            "If the change is intended, run `make notebooks-update` and commit book/_nbval/.",
            file=sys.stderr,
        )
    return result.returncode


def stable_cell_ids(nb) -> None:
    """Give cells ids derived from their content, so that an unchanged page
    rewrites to an unchanged reference (jupytext draws random ids)."""
    seen: dict[str, int] = {}
    for cell in nb.cells:
        digest = hashlib.sha1(f"{cell.cell_type}\n{cell.source}".encode()).hexdigest()[:8]
        seen[digest] = seen.get(digest, 0) + 1
        cell.id = digest if seen[digest] == 1 else f"{digest}-{seen[digest]}"


def update(pages: list[Path]) -> int:
    import jupytext
    import nbformat
    from nbclient import NotebookClient

    for page in pages:
        nb = jupytext.read(page)
        print(f"executing {page.relative_to(ROOT)}", flush=True)
        NotebookClient(
            nb,
            timeout=TIMEOUT,
            kernel_name="python3",
            record_timing=False,
            resources={"metadata": {"path": str(page.parent)}},
        ).execute()
        stable_cell_ids(nb)
        ref = reference_path(page)
        ref.parent.mkdir(exist_ok=True)
        nbformat.write(nb, ref)
        print(f"  wrote {ref.relative_to(ROOT)}")
    return 0


def stale_references(pages: list[Path]) -> list[Path]:
    """The committed references whose page is not among ``pages`` (all pages of _toc.yml)."""
    known = {reference_path(p) for p in pages}
    return [r for r in sorted(ROOT.glob(f"book/**/{REF_DIR_NAME}/*.ipynb")) if r not in known]


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=["check", "update"])
    parser.add_argument(
        "-n",
        "--workers",
        type=int,
        default=2,
        help="parallel nbval workers for `check` (default 2)",
    )
    parser.add_argument(
        "pages",
        nargs="*",
        help="only these pages (e.g. fig6); `update` then leaves every other reference alone",
    )
    args = parser.parse_args(argv)
    try:
        every = notebook_pages()
        pages = select_pages(every, args.pages)
    except CheckError as err:
        print(f"make notebooks: {err}", file=sys.stderr)
        return 1
    if args.command == "check":
        return check(pages, args.workers, every)
    status = update(pages)
    if not args.pages:
        for ref in stale_references(every):
            ref.unlink()
            print(f"  deleted {ref.relative_to(ROOT)} (its page is not in _toc.yml)")
    return status


if __name__ == "__main__":
    sys.exit(main())
