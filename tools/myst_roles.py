"""Write the book's pasted numbers as ``{eval}`` roles, which JupyterLab renders too.

The pages glue each number of their text (``myst_nb.glue(name, text,
display=False)``) and the text names it. Written ``{glue:text}`name```, the
number shows in the book only; written ``{eval}`name```, it shows in the book
(``tools/sphinx/depthcore_book.py`` pastes the text glued under ``name``,
exactly as ``glue:text`` does) and in JupyterLab, whose MyST renderer
(jupyterlab-myst) evaluates ``name`` in the page's kernel, where
:class:`depthbook.notebook.GlueLog` binds every glued text to its name.

The references and glued figures of a page that runs a ``GlueLog`` are
written for JupyterLab too, which knows one notebook at a time, no
bibliography and no ``glue:figure``: each reference as an ``{eval}`` call of
the function of :mod:`depthbook.crossref` that resolves it in the kernel as
the book does (``{cite:t}`maybank1990``` as ``{eval}`cite_t("maybank1990")```,
likewise ``cite:p``, ``eq``, ``numref``, ``ref`` and ``doc``), which the book
renders as the role it names; each ``{glue:figure}`` as a ``{figure}``
whose content is ``{eval}`name``` and the caption, which the book renders as
``glue:figure`` and JupyterLab as the glued figure with its caption (with
``:enumerated: false``: JupyterLab numbers a notebook's figures from 1, the
book across its pages).

The displayed equations are numbered for JupyterLab as in the book. The
book numbers a labelled display (``$$ ... $$ (eq-17)``) in one count across
its pages and leaves an unlabelled one unnumbered; jupyterlab-myst numbers
every display of a notebook from 1, unless the display says
``:enumerated: false`` (a ``{math}`` directive, which the book renders as it
renders ``$$ ... $$``: ``tools/sphinx/depthcore_book.py`` accepts the
option), and starts its count where the notebook's front matter says. So
each unlabelled display is written as a ``{math}`` directive with
``:enumerated: false``, and a page with labelled equations opens its first
text cell with its front matter, a YAML block::

    ```yaml
    numbering:
      equation:
        start: 17
    ```

whose number is that of the page's first labelled equation in the book
(:meth:`depthbook.crossref.BookReferences.page_equations`, which numbers
them as the book does); the page's others follow it, as in the book. The
book does not show this block (``tools/sphinx/depthcore_book.py`` drops it).

This script rewrites every ``{glue:text}`name``` of the pages' text,
outside their code cells, to ``{eval}`name```, and the references and glued
figures as above, the unlabelled displays as above, and writes (or
corrects, or removes) each page's front matter of equation numbers. A role with a format
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
from depthbook.crossref import ROLES, BookReferences

ROLE = re.compile(r"\{glue:text\}`([^`]+)`")
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
FENCE = re.compile(r"^\s*(`{3,}|:{3,})\{code-cell\}")


#: The references of the text, each written as an ``{eval}`` call of the
#: function of ``depthbook.crossref`` that JupyterLab evaluates: role -> function.
REFERENCE_ROLES = {role: function for function, role in ROLES.items()}
REFERENCE = re.compile(r"\{(" + "|".join(map(re.escape, REFERENCE_ROLES)) + r")\}`([^`]+)`")
KERNEL = re.compile(r"^\w+ = GlueLog\(", re.M)
GLUE_FIGURE = re.compile(r"^(\s*)(`{3,}|:{3,})\{glue:figure\}\s+(\S+)\s*$")
DISPLAY_OPEN = re.compile(r"^([ \t]*)\$\$\s*$")
DISPLAY_CLOSE = re.compile(r"^[ \t]*\$\$\s*(?:\(([^)\s]+)\))?\s*$")
#: A page's front matter for JupyterLab: where its count of equations starts.
LAB_FRONTMATTER = "```yaml\nnumbering:\n  equation:\n    start: {start}\n```\n"
LAB_FRONTMATTER_FOUND = re.compile(
    r"\A```yaml\nnumbering:\n  equation:\n    start: (\d+)\n```\n(?:[ \t]*\n)*"
)
HEADER = re.compile(r"\A---\n.*?^---\n(?:[ \t]*\n)*", re.S | re.M)


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


def display_math(lines: list[str], start: int, where: str) -> tuple[list[str], int]:
    """A display ``$$ ... $$`` at ``lines[start]``, if unlabelled as ``{math}``, not enumerated.

    A labelled display (``$$ (label)`` closing it) is kept as it is. Returns
    the new lines and the index of the line after the display.
    """
    indent = DISPLAY_OPEN.match(lines[start]).group(1)
    end = next((j for j in range(start + 1, len(lines)) if DISPLAY_CLOSE.match(lines[j])), None)
    if end is None:
        raise ValueError(f"{where}: the display equation ($$) is not closed")
    if DISPLAY_CLOSE.match(lines[end]).group(1) is not None:
        return lines[start : end + 1], end + 1
    body = lines[start + 1 : end]
    return [
        f"{indent}```{{math}}\n",
        f"{indent}:enumerated: false\n",
        *body,
        f"{indent}```\n",
    ], end + 1


def lab_numbering(text: str, start: int | None) -> str:
    """``text`` whose first text cell opens with the front matter ``start`` (none if ``None``).

    The front matter follows the page's jupytext header, before its title,
    separated from both by a blank line.
    """
    header = HEADER.match(text)
    head = "" if header is None else text[: header.end()]
    body = text[len(head) :]
    found = LAB_FRONTMATTER_FOUND.match(body)
    if found is not None:
        body = body[found.end() :]
    if start is not None:
        body = LAB_FRONTMATTER.format(start=start) + "\n" + body
    return head + body


def page_numbering(book: BookReferences, page: str) -> int | None:
    """Where a page's count of equations starts in JupyterLab: its first one's number in the book.

    ``None`` for a page without labelled equations.
    """
    equations = book.page_equations(page)
    return equations[0][1] if equations else None


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
        elif DISPLAY_OPEN.match(line):
            display, index = display_math(lines, index, where)
            out += display
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
    book = BookReferences(ROOT)
    changed = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        try:
            new = convert(text, page.name)
            name = page.resolve().relative_to(ROOT).with_suffix("").as_posix()
            new = lab_numbering(new, page_numbering(book, name))
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
