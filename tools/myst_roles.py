"""Write the book's pasted numbers as ``{eval}`` roles, which JupyterLab renders too.

The pages glue each number of their text (``myst_nb.glue(name, text,
display=False)``) and the text names it. Written ``{glue:text}`name```, the
number shows in the book only; written ``{eval}`name```, it shows in the book
(``tools/sphinx/depthcore_book.py`` pastes the text glued under ``name``,
exactly as ``glue:text`` does) and in JupyterLab, whose MyST renderer
(jupyterlab-myst) evaluates ``name`` in the page's kernel, where
:class:`depthcore.book.notebook.GlueLog` binds every glued text to its name.

The references and glued figures of a page that runs a ``GlueLog`` are
written for JupyterLab too, which knows one notebook at a time, no
bibliography and no ``glue:figure``: each reference as an ``{eval}`` call of
the function of :mod:`depthcore.book.crossref` that resolves it in the kernel as
the book does (``{cite:t}`maybank1990``` as ``{eval}`cite_t("maybank1990")```,
likewise ``cite:p``, ``eq``, ``numref``, ``ref`` and ``doc``), which the book
renders as the role it names; each ``{glue:figure}`` as a ``{figure}``
whose content is ``{eval}`name``` and the caption, which the book renders as
``glue:figure`` and JupyterLab as the glued figure with its caption (with
``:enumerated: false``: JupyterLab numbers a notebook's figures from 1, the
book across its pages).

This script rewrites every ``{glue:text}`name``` of the pages' text,
outside their code cells, to ``{eval}`name```, and the references and glued
figures as above. A role with a format
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
sys.path.insert(0, str(ROOT))
from depthcore.book.crossref import ROLES  # noqa: E402

ROLE = re.compile(r"\{glue:text\}`([^`]+)`")
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
FENCE = re.compile(r"^\s*(`{3,}|:{3,})\{code-cell\}")


#: The references of the text, each written as an ``{eval}`` call of the
#: function of ``depthcore.book.crossref`` that JupyterLab evaluates: role -> function.
REFERENCE_ROLES = {role: function for function, role in ROLES.items()}
REFERENCE = re.compile(r"\{(" + "|".join(map(re.escape, REFERENCE_ROLES)) + r")\}`([^`]+)`")
KERNEL = re.compile(r"^\w+ = GlueLog\(", re.M)
GLUE_FIGURE = re.compile(r"^(\s*)(`{3,}|:{3,})\{glue:figure\}\s+(\S+)\s*$")


def reference(match: re.Match, where: str) -> str:
    """``{eval}`cite_t("key")``` for the role ``{cite:t}`key```."""
    role, content = match.groups()
    if '"' in content or "\\" in content:
        raise ValueError(f"{where}: {match.group(0)!r}: a quote or backslash in a reference")
    return f'{{eval}}`{REFERENCE_ROLES[role]}("{content}")`'


def glue_figure(lines: list[str], start: int, where: str) -> tuple[list[str], int]:
    """A ``{glue:figure}`` directive at ``lines[start]`` as a ``{figure}`` of ``{eval}`name```.

    Returns the new lines and the index of the line after the directive.
    """
    indent, fence, name = GLUE_FIGURE.match(lines[start]).groups()
    options, i = [], start + 1
    while i < len(lines) and re.match(r"^\s*:[\w-]+:", lines[i]):
        options.append(lines[i])
        i += 1
    if not any(re.match(r"^\s*:enumerated:", o) for o in options):
        options.append(f"{indent}:enumerated: false\n")
    while i < len(lines) and not lines[i].strip():
        i += 1
    end = next((j for j in range(i, len(lines)) if lines[j].strip() == fence), None)
    if end is None:
        raise ValueError(f"{where}: the glued figure {name!r} is not closed")
    head = [f"{indent}{fence}{{figure}}\n", *options, "\n", f"{indent}{{eval}}`{name}`\n"]
    caption = lines[i:end]
    return [*head, *(["\n", *caption] if caption else []), lines[end]], end + 1


def convert(text: str, source: str = "page") -> str:
    """``text`` with each pasted number of its prose written as an ``{eval}`` role.

    Raises
    ------
    ValueError
        A role whose content is not a Python name (a format or another page's
        name), with its line.
    """
    lines = text.splitlines(keepends=True)
    out, fence, index = [], None, 0
    # References and glued figures evaluate where a GlueLog binds their functions.
    kernel = KERNEL.search(text) is not None
    while index < len(lines):
        line, where = lines[index], f"{source}:{index + 1}"
        marker = FENCE.match(line)
        if fence is None and marker:
            fence = marker.group(1)
        elif fence is not None:
            if line.strip() == fence:
                fence = None
        elif kernel and GLUE_FIGURE.match(line):
            figure, index = glue_figure(lines, index, where)
            out += [convert_line(text, where, kernel) for text in figure]  # the caption's roles
            continue
        else:
            line = convert_line(line, where, kernel)
        out.append(line)
        index += 1
    return "".join(out)


def convert_line(line: str, where: str, kernel: bool) -> str:
    """A line of text with its roles converted (references too on a page with a kernel)."""
    for name in ROLE.findall(line):
        if not NAME.fullmatch(name):
            raise ValueError(
                f"{where}: {name!r} is not a Python name, "
                "so it cannot be evaluated in the kernel: glue it under a name"
            )
    line = ROLE.sub(r"{eval}`\1`", line)
    if kernel:
        line = REFERENCE.sub(lambda m: reference(m, where), line)
    return line


def main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="tools/myst_roles.py",
        description="Write the pages' pasted numbers, references and glued figures as the "
        "{eval} forms that the book and JupyterLab both render (idempotent).",
    )
    parser.add_argument(
        "--check", action="store_true", help="change nothing; exit 1 if a page would change"
    )
    parser.add_argument("pages", nargs="*", type=Path, help="pages (default: book/*.md)")
    args = parser.parse_args(argv)
    check = args.check
    pages = args.pages or sorted((ROOT / "book").glob("*.md"))
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
