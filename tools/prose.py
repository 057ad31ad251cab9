"""The book's pages measured as a reader meets them: words of prose, code shown, glue hidden.

    python tools/prose.py count            words of prose per page, and the book's total
    python tools/prose.py check            the budgets below; exit 1 naming each fault
    python tools/prose.py hide-glue PAGE…  move the glue of shown cells into hidden cells

A page's prose is its Markdown outside code cells, math blocks and directive
options; a role that pastes a glued value counts as one word, inline math as
one. The budgets: at most ``PAGE_WORDS`` words of prose on a page and
``BOOK_WORDS`` in the book; a code line shown in the book (a cell not tagged
``remove-cell`` or ``remove-input``) at most ``CODE_WIDTH`` characters; a shown
cell glues nothing (gluing is plumbing: the book hides it, a notebook shows it).
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path
from typing import NamedTuple

BOOK = Path(__file__).resolve().parent.parent / "book"
PAGE_WORDS = 2500
# the book's prose; 33,200 since the exercises through the book (fifteen, nine of them
# new, with their solutions: about 1,070 words) and each finding told once, at home, and
# pointed to elsewhere (the conclusions draw lessons instead of repeating numbers, the
# costs and the print's errors told on their own pages: about 430 words fewer)
BOOK_WORDS = 33200
CODE_WIDTH = 88
HIDDEN = ("remove-cell", "remove-input")

_FENCE = re.compile(r"^(`{3,}|~{3,}|:{3,})\s*(\{([^}]*)\})?")
_OPTION = re.compile(r":[\w-]+:")
_ROLE = re.compile(r"\{[A-Za-z:-]+\}`[^`]*`")
_WORD = re.compile(r"[A-Za-z0-9][\w'’.,/-]*")


def pages():
    """The book's pages, ``book/*.md``, in name order."""
    return sorted(BOOK.glob("*.md"))


class Directive(NamedTuple):
    """A fenced block of a MyST page: a directive (``name``) or a plain code block (``""``)."""

    name: str
    argument: str
    options: dict
    body: list
    first: int
    last: int


def directives(text):
    """The fenced blocks of a MyST page in order, each read whole: a block inside
    another's body is part of that body. ``first`` and ``last`` are the lines of the
    opening and closing fences; the options are the ``:key: value`` lines that open it."""
    lines = text.splitlines()
    found, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        first, fence, name = i, m.group(1), m.group(3) or ""
        argument = lines[i][m.end() :].strip()
        i += 1
        options = {}
        while i < len(lines) and _OPTION.match(lines[i]):
            key, _, value = lines[i][1:].partition(":")
            options[key.strip()] = value.strip()
            i += 1
        body_start = i
        while i < len(lines) and lines[i].strip() != fence:
            i += 1
        found.append(Directive(name, argument, options, lines[body_start:i], first, i))
        i += 1
    return found


def tags(options):
    """A code cell's tags, from its ``:tags: [a, b]`` option."""
    listed = options.get("tags", "").strip().removeprefix("[").removesuffix("]")
    return [t.strip().strip("'\"") for t in listed.split(",") if t.strip()]


def cells(text):
    """The code cells of a MyST page: (first line, last line, tags, code lines)."""
    return [
        (d.first, d.last, tags(d.options), d.body)
        for d in directives(text)
        if d.name == "code-cell"
    ]


def prose_words(text):
    """The number of words of prose of a MyST page (see the module's docstring)."""
    text = re.sub(r"\A---\n.*?\n---\n", "", text, flags=re.S)
    kept, fence = [], None
    for line in text.splitlines():
        m = _FENCE.match(line)
        if fence is None and m:
            fence = (m.group(1), m.group(3) or "")
            continue
        if fence is not None and line.strip() == fence[0]:
            fence = None
            continue
        if fence is not None and (
            fence[1] in ("code-cell", "math", "raw", "") or re.match(r"\s*:[\w-]+:", line)
        ):
            continue
        if line.startswith("+++") or re.match(r"^\(.*\)=\s*$", line):
            continue
        kept.append(line)
    prose = "\n".join(kept)
    prose = re.sub(r"\$\$.*?\$\$", " ", prose, flags=re.S)
    prose = re.sub(r"<!--.*?-->", " ", prose, flags=re.S)
    prose = re.sub(r"\$[^$\n]+\$", " x ", prose)
    prose = _ROLE.sub(" x ", prose)
    return len(_WORD.findall(prose))


def shown(tags):
    return not any(t in HIDDEN for t in tags)


def faults(path):
    """The budget faults of one page, each a line naming the page and its line."""
    text = path.read_text()
    out = []
    words = prose_words(text)
    if words > PAGE_WORDS:
        out.append(f"{path.name}: {words} words of prose, over {PAGE_WORDS}")
    for start, end, tags, code in cells(text):
        if not shown(tags):
            continue
        for k, line in enumerate(code):
            n = end - len(code) + k + 1
            if len(line) > CODE_WIDTH:
                out.append(f"{path.name}:{n}: a shown code line of {len(line)} characters")
        if _glues("\n".join(code)):
            out.append(f"{path.name}:{start + 1}: a shown cell glues")
    return out


def _glues_node(node):
    for sub in ast.walk(node):
        if isinstance(sub, ast.Call):
            f = sub.func
            if isinstance(f, ast.Name) and f.id == "glue":
                return True
            if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
                if f.value.id == "glued":
                    return True
    return False


def _glues(code):
    try:
        tree = ast.parse(code)
    except SyntaxError:
        return "glue(" in code
    return any(_glues_node(node) for node in tree.body)


def _split(code):
    """A cell's code split into (kept, glue), or None when it cannot be split safely."""
    tree = ast.parse("\n".join(code))
    body = tree.body
    if not body:
        return None
    glue_flags = [_glues_node(node) for node in body]
    # plt.close(fig) after a glued figure belongs with the glue.
    for k, node in enumerate(body):
        if (
            k > 0
            and glue_flags[k - 1]
            and isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Call)
            and ast.unparse(node.value.func) == "plt.close"
        ):
            glue_flags[k] = True
    spans, previous_end = [], 0
    for node in body:
        start = node.lineno - 1
        if getattr(node, "decorator_list", None):
            start = min(d.lineno - 1 for d in node.decorator_list)
        # the blank and comment lines just above a statement belong to it
        if spans:
            start = previous_end
        spans.append((start, node.end_lineno))
        previous_end = node.end_lineno
    head = code[: spans[0][0]]
    kept, glue = list(head), []
    for (a, b), g in zip(spans, glue_flags, strict=True):
        (glue if g else kept).extend(code[a:b])
    return kept, glue


def hide_glue(path):
    """Move the glue out of a page's shown cells; return how many cells changed."""
    lines = path.read_text().splitlines()
    changed = 0
    for start, end, tags, code in reversed(cells("\n".join(lines))):
        if not shown(tags) or not _glues("\n".join(code)):
            continue
        split = _split(code)
        if split is None:
            continue
        kept, glue = split
        while kept and not kept[-1].strip():
            kept.pop()
        while glue and not glue[0].strip():
            glue.pop(0)
        after = end + 1
        nxt = [c for c in cells("\n".join(lines)) if c[0] > end]
        follow = None
        if nxt:
            c = nxt[0]
            between = lines[after : c[0]]
            if all(not x.strip() for x in between) and "remove-cell" in c[2]:
                follow = c
        hidden_header = ["```{code-cell} ipython3", ":tags: [remove-cell]", ""]
        # (the glue joins the next cell when that cell is hidden and only shows it)
        if follow is not None:
            f_start, f_end, f_tags, f_code = follow
            body_start = f_end - len(f_code)
            lead = 0
            while lead < len(f_code) and not f_code[lead].strip():
                lead += 1
            body = f_code[:lead] or [""]
            body += glue + [""] + f_code[lead:]
            new_follow = lines[f_start:body_start] + body + [lines[f_end]]
            lines[f_start : f_end + 1] = new_follow
            extra = []
        else:
            extra = ["", *hidden_header, *glue, "```"]
        if any(x.strip() for x in kept):
            body_start = end - len(code)
            lines[body_start:end] = kept
            shift = len(kept) - len(code)
            insert_at = end + shift + 1
            lines[insert_at:insert_at] = extra
        else:
            # nothing left to show: the whole cell is glue
            block = lines[start : end + 1]
            head = block[0]
            opts = [x for x in block[1:] if x.startswith(":")]
            new_tags = [t for t in tags if t not in ("hide-input", "hide-output", "hide-cell")]
            new_tags = ["remove-cell", *new_tags]
            opts = [x for x in opts if not x.startswith(":tags:")]
            tag_line = ":tags: [" + ", ".join(new_tags) + "]"
            if follow is not None:
                lines[start : end + 2] = []
            else:
                lines[start : end + 1] = [head, tag_line, *opts, "", *glue, "```"]
            changed += 1
            continue
        changed += 1
    path.write_text("\n".join(lines) + "\n")
    return changed


def main(argv):
    if not argv or argv[0] not in ("count", "check", "hide-glue"):
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    if argv[0] == "count":
        total = 0
        for p in pages():
            n = prose_words(p.read_text())
            total += n
            print(f"{n:6d}  {p.stem}")
        print(f"{total:6d}  the book (at most {BOOK_WORDS})")
        return 0
    if argv[0] == "check":
        problems = [f for p in pages() for f in faults(p)]
        total = sum(prose_words(p.read_text()) for p in pages())
        if total > BOOK_WORDS:
            problems.append(f"the book: {total} words of prose, over {BOOK_WORDS}")
        print("\n".join(problems) if problems else "within budget")
        return 1 if problems else 0
    for name in argv[1:]:
        path = BOOK / (name if name.endswith(".md") else name + ".md")
        print(f"{path.name}: {hide_glue(path)} cells")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
