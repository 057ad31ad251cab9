"""Write the book's pasted numbers as ``{eval}`` roles, which JupyterLab renders too.

The pages glue each number of their text (``myst_nb.glue(name, text,
display=False)``) and the text names it. Written ``{glue:text}`name```, the
number shows in the book only; written ``{eval}`name```, it shows in the book
(``tools/sphinx/depthcore_book.py`` pastes the text glued under ``name``,
exactly as ``glue:text`` does) and in JupyterLab, whose MyST renderer
(jupyterlab-myst) evaluates ``name`` in the page's kernel, where
:class:`depthcore.report.GlueLog` binds every glued text to its name.

This script rewrites every ``{glue:text}`name``` of the pages' text,
outside their code cells, to ``{eval}`name```. A role with a format
(``name:.2f``) or another page's name (``page::name``) would not evaluate in
the kernel: the script refuses it, names it and changes nothing.
It is idempotent: run again, it changes nothing.

Usage: ``python tools/myst_roles.py [--check] [book/page.md ...]`` (all
pages of ``book/`` by default); ``--check`` only reports the pages that
would change and exits 1 when there are any.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROLE = re.compile(r"\{glue:text\}`([^`]+)`")
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
FENCE = re.compile(r"^\s*(`{3,}|:{3,})\{code-cell\}")


def convert(text: str, source: str = "page") -> str:
    """``text`` with each pasted number of its prose written as an ``{eval}`` role.

    Raises
    ------
    ValueError
        A role whose content is not a Python name (a format or another page's
        name), with its line.
    """
    out, fence = [], None
    for number, line in enumerate(text.splitlines(keepends=True), start=1):
        marker = FENCE.match(line)
        if fence is None and marker:
            fence = marker.group(1)
        elif fence is not None:
            if line.strip() == fence:
                fence = None
        else:
            for name in ROLE.findall(line):
                if not NAME.fullmatch(name):
                    raise ValueError(
                        f"{source}:{number}: {name!r} is not a Python name, "
                        "so it cannot be evaluated in the kernel: glue it under a name"
                    )
            line = ROLE.sub(r"{eval}`\1`", line)
        out.append(line)
    return "".join(out)


def main(argv: list[str]) -> int:
    check = "--check" in argv
    pages = [Path(a) for a in argv if a != "--check"] or sorted((ROOT / "book").glob("*.md"))
    changed = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        try:
            new = convert(text, page.name)
        except ValueError as error:
            print(f"myst_roles: {error}", file=sys.stderr)
            return 2
        if new != text:
            changed.append(page)
            if not check:
                page.write_text(new, encoding="utf-8")
    verb = "would change" if check else "changed"
    for page in changed:
        print(f"myst_roles: {verb} {page.name}")
    return 1 if check and changed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
