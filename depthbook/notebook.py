"""What a page shows when it runs as a plain notebook in Jupyter.

Recommended import: ``from depthbook.notebook import GlueLog``.

Jupyter displays neither the values nor the figures that a page glues into
the book's text. :class:`GlueLog` glues them and shows them in a notebook;
:class:`MarkdownTable` is a table shown as Markdown; :func:`page_text`,
:func:`page_tables`, :func:`paste_table` and :class:`PastedTable` give a
page's tables of glued numbers, with the numbers pasted in.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from depthbook.crossref import BookReferences


class MarkdownTable:
    """A table that Jupyter shows as Markdown (with its math) and as aligned text.

    Parameters
    ----------
    header : sequence of str, shape (n_columns,)
    rows : sequence of sequence of str, shape (n_rows, n_columns)
    widths : sequence of int, shape (n_columns,), optional
        The columns' relative widths: the Markdown is then a ``{table}`` directive
        with ``:widths:``, whose columns the PDF wraps (without them a long
        table's columns run off the page).
    """

    def __init__(self, header, rows, widths=None):
        self.header = [str(cell) for cell in header]
        self.widths = None if widths is None else [int(w) for w in widths]
        if self.widths is not None and (
            len(self.widths) != len(self.header) or min(self.widths) < 1
        ):
            raise ValueError(f"widths must be {len(self.header)} positive integers")
        self.rows = [[str(cell) for cell in row] for row in rows]
        if not self.header:
            raise ValueError("header must name at least one column")
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(
                    f"rows must have {len(self.header)} cells each, got a row of {len(row)}"
                )

    def markdown(self) -> str:
        """The table as a Markdown table, one line per row, ending in a newline (inside
        a ``{table}`` directive when the table has widths)."""

        def line(cells):
            return "| " + " | ".join(c.replace("|", r"\|") for c in cells) + " |"

        lines = [line(self.header), line(["---"] * len(self.header))]
        table = "\n".join(lines + [line(row) for row in self.rows]) + "\n"
        if self.widths is None:
            return table
        widths = " ".join(map(str, self.widths))
        return f"```{{table}}\n:widths: {widths}\n\n{table}```\n"

    def _repr_markdown_(self) -> str:
        return self.markdown()

    def __repr__(self) -> str:
        """The table as aligned plain text, under a rule line.

        Every column but the last is padded to its longest cell; the last needs
        no padding, and its rule is as wide as its header, so that a long value
        there (an environment naming the processor) leaves the rule unchanged.
        """
        table = [self.header, *self.rows]
        widths = [max(len(row[j]) for row in table) for j in range(len(self.header) - 1)]
        widths.append(len(self.header[-1]))
        lines = [
            "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
            for row in table
        ]
        lines.insert(1, "  ".join("-" * w for w in widths))
        return "\n".join(lines)


#: A role that pastes a glued text into a page's text, ``eval`` (which the book
#: resolves to the text glued under its name, and JupyterLab evaluates in the
#: page's kernel), ``glue:text`` or plain ``glue``; group 1 is the glued name.
GLUE_ROLE = re.compile(r"\{(?:eval|glue(?::text)?)\}`([A-Za-z_][A-Za-z0-9_]*)`")


def page_tables(text: str) -> list[list[str]]:
    """The pipe tables of a MyST page that paste glued texts, each as its lines.

    Lines inside code cells (fenced blocks) are not the page's text and are
    passed over; a table is a run of lines that start with ``|``, stripped.

    Parameters
    ----------
    text : str
        The page's MyST Markdown source.

    Returns
    -------
    list of list of str
        The tables that hold at least one ``glue:text`` role, in page order.
    """
    tables, current, fence = [], [], None
    for line in text.splitlines() + [""]:
        stripped = line.strip()
        marker = re.match(r"^(`{3,}|:{3,})", stripped)
        if fence is None and marker and "{code-cell}" in stripped:
            fence = marker.group(1)
            continue
        if fence is not None:
            if stripped == fence:
                fence = None
            continue
        if stripped.startswith("|"):
            current.append(stripped)
        elif current:
            tables.append(current)
            current = []
    return [t for t in tables if any(GLUE_ROLE.search(line) for line in t)]


def page_text(page) -> str:
    """The text of a book page outside its code cells, from its source or its notebook.

    Parameters
    ----------
    page : str or path
        ``"fig6"``, ``"fig6.md"`` or ``"fig6.ipynb"``: the page's MyST source
        ``fig6.md`` is read if it exists, else the notebook ``fig6.ipynb`` (the
        page as the book offers it for download), whose markdown cells are
        joined.

    Returns
    -------
    str
        The page's text; empty when neither file exists.
    """
    import json

    path = Path(page)
    source, notebook = path.with_suffix(".md"), path.with_suffix(".ipynb")
    if source.is_file():
        return source.read_text(encoding="utf-8")
    if notebook.is_file():
        cells = json.loads(notebook.read_text(encoding="utf-8")).get("cells", [])
        return "\n\n".join(
            "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
            for cell in cells
            if cell.get("cell_type") == "markdown"
        )
    return ""


def paste_table(lines: list[str], texts: dict[str, str]) -> str | None:
    """A page's table with every glued text pasted in, as the book shows it.

    Parameters
    ----------
    lines : list of str
        One table of :func:`page_tables`.
    texts : dict of str to str
        Glued names and their texts, as ``glue:text`` pastes them.

    Returns
    -------
    str or None
        The table's lines joined by newlines; ``None`` while a name it pastes
        has not been glued.
    """
    names = [m.group(1) for line in lines for m in GLUE_ROLE.finditer(line)]
    if any(name not in texts for name in names):
        return None
    return "\n".join(GLUE_ROLE.sub(lambda m: texts[m.group(1)], line) for line in lines)


class PastedTable:
    """A page's table with its glued numbers, shown by Jupyter as Markdown and as text.

    Parameters
    ----------
    text : str
        From :func:`paste_table`.
    """

    def __init__(self, text: str):
        self.text = text

    def _repr_markdown_(self) -> str:
        return self.text + "\n"

    def __repr__(self) -> str:
        return self.text


class GluedText(str):
    """A glued text, bound to its name in the kernel by :class:`GlueLog`.

    Its ``repr`` is the text itself, so Jupyter shows it as the book pastes it
    (``0.25``, not ``'0.25'``) where an ``{eval}`` role of the page names it.
    """

    __slots__ = ()

    def __repr__(self) -> str:
        return str(self)


class GluedOutput:
    """A glued figure (or other display), bound to its name in the kernel by :class:`GlueLog`.

    Displayed, it shows the very output that the book pastes (its media types
    and their metadata, as glued), where an ``{eval}`` role of the page names
    it: the figure of a ``{figure}`` directive whose content is
    ``{eval}`name```.

    Parameters
    ----------
    data : dict
        The glued output's data by media type (``image/png``, ``text/plain``, ...).
    metadata : dict
        Its metadata by media type.
    """

    __slots__ = ("data", "metadata")

    def __init__(self, data: dict, metadata: dict):
        self.data = dict(data)
        self.metadata = dict(metadata)

    def _repr_mimebundle_(self, include=None, exclude=None):
        return self.data, self.metadata

    def __repr__(self) -> str:
        return str(self.data.get("text/plain", "<glued output>"))


class GlueLog:
    """Shows in Jupyter what a book page glues into the book's text.

    A page glues its numbers and figures with ``myst_nb.glue(name, value,
    display=False)``: the book pastes them where its text names them
    (the ``glue:text`` and ``glue:figure`` roles), but a plain notebook shows nothing of
    them. A ``GlueLog`` created in the page's kernel keeps a copy of every such
    record, which passes on unchanged, and :meth:`show` displays those kept
    since its last call: each figure as the very image the book shows, and the
    texts in a :class:`MarkdownTable` of glued name and value, as the book
    pastes them. Given the page's name, :meth:`show` also displays each of the
    page's tables of glued numbers (:func:`page_tables`) whole, with its
    numbers pasted in, once every number in it has been glued. The book leaves
    the cells that create and show it out.

    The tables are read from the page's own file in the kernel's working
    folder (:func:`page_text`): its MyST source (``fig6.md``) where the book's
    pages are, else the notebook that the book offers for download
    (``fig6.ipynb``), which runs alone in any folder. Where neither is found
    (a renamed download), the values are still shown, in the table of glued
    names, and the page's tables are not.

    Every glued text is also bound, as a :class:`GluedText`, to its name in the
    kernel's namespace, where JupyterLab's MyST renderer (jupyterlab-myst)
    evaluates the page's ``{eval}`name``` roles: the prose shows each number
    where the book pastes it, once the cell that glues it has run; every
    other glued output (a figure) as a :class:`GluedOutput`, which the
    ``{eval}`` role of a ``{figure}`` directive shows with its caption. The
    functions of a :class:`depthbook.crossref.BookReferences` (``cite_t``,
    ``cite_p``, ``eq``, ``numref``, ``ref``, ``doc``) are bound too: the
    page's references, written as ``{eval}`` roles, show the book's numbers,
    titles and citations.

    Parameters
    ----------
    page : str or path, optional
        The page's name or source, ``"fig6"`` or ``"fig6.md"`` (relative to the
        kernel's working folder, the page's folder in Jupyter as in the book's
        build).

    Raises
    ------
    RuntimeError
        Outside a Jupyter kernel (ipykernel), where there is nothing to watch.
    ValueError
        From ``glue``, when a text is glued under a name that the page's code
        uses for something else (it would be overwritten).
    """

    #: The prefix of the media types of a record that is not displayed (myst_nb's).
    PREFIX = "application/papermill.record/"

    def __init__(self, page=None):
        from IPython import get_ipython

        shell = get_ipython()
        publisher = getattr(shell, "display_pub", None)
        if not hasattr(publisher, "register_hook"):
            raise RuntimeError("GlueLog runs in a Jupyter kernel (ipykernel) only")
        self._namespace = shell.user_ns
        self._kept: list[tuple[str, dict, dict]] = []
        self._texts: dict[str, str] = {}
        self._tables = [] if page is None else page_tables(page_text(page))
        self._namespace.update(BookReferences().functions())
        publisher.register_hook(self._keep)

    def _keep(self, msg):
        content = msg.get("content", {})
        glued = content.get("metadata", {}).get("scrapbook")
        if msg.get("msg_type") == "display_data" and glued and glued.get("mime_prefix"):
            n = len(glued["mime_prefix"])
            data = {k[n:]: v for k, v in content["data"].items()}
            metadata = {k: v for k, v in content["metadata"].items() if k != "scrapbook"}
            self._kept.append((glued["name"], data, metadata))
            if set(data) == {"text/plain"}:
                self._bind(glued["name"], GluedText(self.pasted_text(data["text/plain"])))
            else:
                self._bind(glued["name"], GluedOutput(data, metadata))
        return msg

    def _bind(self, name: str, value) -> None:
        current = self._namespace.get(name)
        if name in self._namespace and not isinstance(current, (GluedText, GluedOutput)):
            raise ValueError(
                f"name {name!r} is glued but also names a {type(current).__name__} "
                "of the page's code: glue the value under another name"
            )
        self._namespace[name] = value

    @staticmethod
    def pasted_text(text: str) -> str:
        """A record's ``text/plain`` as the ``glue:text`` role pastes it, without quotes."""
        try:
            return str(ast.literal_eval(text))
        except (SyntaxError, ValueError):
            return text

    def show(self) -> None:
        """Display what was glued since the last call: figures, a table of the texts.

        Then the page's tables whose numbers are now all glued, each once.
        """
        from IPython.display import display

        texts = []
        for name, data, metadata in self._kept:
            if set(data) == {"text/plain"}:
                texts.append([name, self.pasted_text(data["text/plain"])])
                self._texts[name] = texts[-1][1]
            else:
                display(data, raw=True, metadata=metadata)
        if texts:
            display(MarkdownTable(["glued name", "value"], texts))
        self._kept.clear()
        pending = []
        for table in self._tables:
            pasted = paste_table(table, self._texts)
            if pasted is None:
                pending.append(table)
            else:
                display(PastedTable(pasted))
        self._tables = pending
