"""The book's cross-references and citations, resolved in Jupyter as the book resolves them.

A book page writes each reference of its text as an ``{eval}`` role whose
expression names the role the book renders and its target:
``{eval}`cite_t("maybank1990")```, ``{eval}`cite_p("kalman1960,prince2012")```,
``{eval}`eq("eq-7")```, ``{eval}`numref("fig-2")```, ``{eval}`ref("sec-cost")```,
``{eval}`doc("fig5")``` and ``{eval}`prf_ref("thm-1")``` (``"text <target>"`` as in
the roles). The book (``tools/sphinx/depthcore_book.py``) renders each as the role
it names (``{cite:t}``, ``{cite:p}``, ``{eq}``, ``{numref}``, ``{ref}``, ``{doc}``,
sphinx-proof's ``{prf:ref}``),
resolved by Sphinx; in JupyterLab, whose MyST renderer (jupyterlab-myst)
knows one notebook at a time and no bibliography, the expression is
evaluated in the page's kernel, where :class:`depthbook.notebook.GlueLog`
binds the functions of a :class:`BookReferences`. They read the book's
sources as Sphinx does:

* equations and figures are numbered in the order of the table of contents
  (``_toc.yml``) and, within a page, in the order of the text, one counter
  for the whole book each (the book's ``numfig_secnum_depth: 0``): a labelled
  display equation (``$$ ... $$ (label)``, or a ``{math}`` directive with a
  ``:label:``) and a figure with a ``:name:``; theorems (a ``{prf:theorem}``
  with a ``:label:``) likewise, in a count of their own;
* a page is named by its first heading, a section label by the heading that
  follows it;
* a citation is written as sphinxcontrib-bibtex's ``author_year`` style (the
  book's) writes it: the authors' last names (two joined by "and", more
  shortened to the first and "et al."), then the year: "Maybank [1990]" in
  the text and "[Maybank, 1990]" in brackets, several works separated by ", ".

The sources are found from the kernel's working folder, the page's folder:
the nearest folder at or above it that holds ``_toc.yml``. They are read when
a reference is first resolved, so a page run where they are absent (the
notebook downloaded from the book, in a folder of its own) runs as before;
only its references are then not resolved (a :class:`ValueError` that says why).
"""

from __future__ import annotations

import html
import posixpath
import re
from pathlib import Path

#: The book's captions and references of figures (its ``numfig_format``).
FIGURE_FORMAT = "Figure %s"

#: A theorem as sphinx-proof's ``{prf:ref}`` names it.
THEOREM_FORMAT = "Theorem %s"

#: The roles written as ``{eval}`` expressions: function name -> the book's role.
ROLES = {
    "cite_t": "cite:t",
    "cite_p": "cite:p",
    "eq": "eq",
    "numref": "numref",
    "ref": "ref",
    "doc": "doc",
    "prf_ref": "prf:ref",
}

_FENCE = re.compile(r"^(`{3,}|:{3,})\{([^}]+)\}(.*)$")
_DOLLAR_LABEL = re.compile(r"^\$\$\s*\(([^)\s]+)\)\s*$")
_OPTION = re.compile(r"^:([\w-]+):\s*(.*)$")
_TARGET = re.compile(r"^\(([^)\s]+)\)=\s*$")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*$")
_EXPLICIT = re.compile(r"^(.*?)\s*<([^<>]+)>$", re.S)
_FIGURE_DIRECTIVES = ("figure", "glue:figure")


class Resolved(str):
    """A resolved reference: its ``repr`` is its text, as the book shows it."""

    __slots__ = ()

    def __repr__(self) -> str:
        return str(self)


class PageLink(Resolved):
    """A reference to a page: its text, and in HTML a link to the page's source.

    Jupyter shows it as a link to ``href`` (relative to the page's folder),
    which JupyterLab opens as it opens the book's pages.
    """

    def __new__(cls, text: str, href: str):
        link = super().__new__(cls, text)
        link.href = href
        return link

    def _repr_html_(self) -> str:
        return f'<a href="{html.escape(self.href)}">{html.escape(str(self))}</a>'


def find_book(folder=None) -> Path:
    """The book's root: the nearest folder at or above ``folder`` that holds ``_toc.yml``.

    Raises
    ------
    ValueError
        No such folder (the page is not among the book's sources).
    """
    start = Path.cwd() if folder is None else Path(folder)
    for candidate in [start, *start.resolve().parents]:
        if (candidate / "_toc.yml").is_file():
            return candidate
    raise ValueError(
        f"folder {str(start)!r}: no _toc.yml at or above it, so the book's "
        "references cannot be resolved (open the page among the book's sources)"
    )


def toc_pages(toc: dict) -> list[str]:
    """The pages of a Jupyter Book table of contents (``_toc.yml`` read), in reading order."""
    pages = [toc["root"]]

    def walk(entries):
        for entry in entries or []:
            if "file" in entry:
                pages.append(entry["file"])
            for key in ("sections", "chapters"):
                walk(entry.get(key))
            for part in entry.get("parts", []) or []:
                walk(part.get("chapters"))

    walk(toc.get("chapters"))
    for part in toc.get("parts", []) or []:
        walk(part.get("chapters"))
    return [str(Path(page).with_suffix("")) for page in pages]


def scan_page(text: str) -> dict:
    """What a page's MyST text defines for references, in the order of the text.

    Returns
    -------
    dict
        ``"title"`` (its first heading, or ``None``), ``"equations"`` (labels
        of its numbered equations), ``"figures"`` (names of its named
        figures), ``"theorems"`` (labels of its labelled theorems) and
        ``"sections"`` (``{label: heading}`` of its section labels).
    """
    found = {"title": None, "equations": [], "figures": [], "theorems": [], "sections": {}}
    lines = text.splitlines()
    fence = None  # (marker, directive) of the open directive
    pending_target = None
    for line in lines:
        stripped = line.strip()
        if fence is not None:
            marker, name = fence
            if stripped == marker:
                fence = None
                continue
            option = _OPTION.match(stripped)
            if option and name == "math" and option.group(1) == "label":
                found["equations"].append(option.group(2).strip())
            if option and name in _FIGURE_DIRECTIVES and option.group(1) == "name":
                found["figures"].append(option.group(2).strip())
            if option and name == "prf:theorem" and option.group(1) == "label":
                found["theorems"].append(option.group(2).strip())
            continue
        opening = _FENCE.match(stripped)
        if opening:
            fence = (opening.group(1), opening.group(2).strip())
            continue
        label = _DOLLAR_LABEL.match(stripped)
        if label:
            found["equations"].append(label.group(1))
            continue
        target = _TARGET.match(stripped)
        if target:
            pending_target = target.group(1)
            continue
        heading = _HEADING.match(line)
        if heading:
            if found["title"] is None:
                found["title"] = heading.group(2)
            if pending_target is not None:
                found["sections"][pending_target] = heading.group(2)
        if stripped:
            pending_target = None
    return found


def split_target(text: str) -> tuple[str | None, str]:
    """``(text or None, target)`` of a role's content ``"text <target>"`` or ``"target"``."""
    match = _EXPLICIT.match(text.strip())
    if match:
        return match.group(1), match.group(2).strip()
    return None, text.strip()


def last_names(person) -> str:
    """A pybtex person's last names as the book prints them ("van\xa0der Merwe").

    pybtex's ``last`` name style, as sphinxcontrib-bibtex's citations use it,
    with its ties as no-break spaces, as in the book's HTML.
    """
    import pybtex.plugin
    from pybtex.backends.plaintext import Backend

    class TiedText(Backend):
        symbols = {**Backend.symbols, "nbsp": "\xa0"}

    style = pybtex.plugin.find_plugin("pybtex.style.names", "last")()
    return style.format(person, True).format().render(TiedText())


def cite_authors(entry) -> str:
    """The authors (or editors) of a bibliography entry, as the author-year citation names them."""
    persons = entry.persons.get("author") or entry.persons.get("editor") or []
    names = [last_names(p) for p in persons]
    if not names:
        raise ValueError(f"citation {entry.key!r}: the entry names no author or editor")
    if len(names) == 1:
        return names[0]
    if len(names) == 2:
        return f"{names[0]} and {names[1]}"
    return f"{names[0]} et al."


class BookReferences:
    """The book's references and citations, resolved from its sources.

    Each method takes the text of the role it stands for and returns a
    :class:`Resolved` text; an unknown target is a :class:`ValueError` that
    names it.

    Parameters
    ----------
    folder : str or path, optional
        A folder of the book's sources (default: the working folder, the page's
        folder in Jupyter); the book's root is the nearest folder at or above it
        that holds ``_toc.yml``.
    """

    def __init__(self, folder=None):
        self._folder = folder
        self._index = None

    def _load(self) -> dict:
        if self._index is not None:
            return self._index
        import yaml
        from pybtex.database import parse_file

        root = find_book(self._folder)
        config = yaml.safe_load((root / "_config.yml").read_text(encoding="utf-8")) or {}
        toc = yaml.safe_load((root / "_toc.yml").read_text(encoding="utf-8"))
        index = {
            "equations": {},
            "figures": {},
            "theorems": {},
            "sections": {},
            "titles": {},
            "entries": {},
            "page_equations": {},
        }
        for page in toc_pages(toc):
            source = root / f"{page}.md"
            if not source.is_file():
                continue
            found = scan_page(source.read_text(encoding="utf-8"))
            index["titles"][page] = found["title"]
            index["page_equations"][page] = found["equations"]
            index["sections"].update(found["sections"])
            for kind in ("equations", "figures", "theorems"):
                for label in found[kind]:
                    index[kind][label] = str(len(index[kind]) + 1)
        for bib in config.get("bibtex_bibfiles", []):
            index["entries"].update(parse_file(str(root / bib), "bibtex").entries)
        index["page"] = self._page_of(root)
        self._index = index
        return index

    def _page_of(self, root: Path) -> str:
        folder = (Path.cwd() if self._folder is None else Path(self._folder)).resolve()
        relative = folder.relative_to(root.resolve())
        return "" if str(relative) == "." else relative.as_posix()

    def _entries(self, keys: str) -> list:
        entries = self._load()["entries"]
        found = []
        for key in (k.strip() for k in keys.split(",")):
            if key not in entries:
                raise ValueError(f"citation {key!r}: no such entry in the book's bibliography")
            found.append(entries[key])
        return found

    def cite_t(self, keys: str) -> Resolved:
        """``{cite:t}`keys```: "Maybank [1990]", several joined by ", "."""
        return Resolved(
            ", ".join(f"{cite_authors(e)} [{e.fields['year']}]" for e in self._entries(keys))
        )

    def cite_p(self, keys: str) -> Resolved:
        """``{cite:p}`keys```: "[Maybank, 1990]", several joined by ", "."""
        inner = ", ".join(f"{cite_authors(e)}, {e.fields['year']}" for e in self._entries(keys))
        return Resolved(f"[{inner}]")

    def eq(self, label: str) -> Resolved:
        """``{eq}`label```: the equation's number in parentheses, "(7)"."""
        numbers = self._load()["equations"]
        if label.strip() not in numbers:
            raise ValueError(f"equation {label!r}: no numbered equation of the book has this label")
        return Resolved(f"({numbers[label.strip()]})")

    def page_equations(self, page: str) -> list[tuple[str, int]]:
        """``[(label, number), ...]``: a page's numbered equations, in the order of its text.

        ``page`` is named as in ``_toc.yml`` (``"book/fig2"``); a page without
        numbered equations has none (``[]``).

        Raises
        ------
        ValueError
            No page of the book has this name.
        """
        index = self._load()
        if page not in index["page_equations"]:
            raise ValueError(f"page {page!r}: no page of the book has this name")
        return [(label, int(index["equations"][label])) for label in index["page_equations"][page]]

    def numref(self, text: str) -> Resolved:
        """``{numref}`name``` or ``{numref}`text <name>```: "Figure 2" (``%s`` in the text)."""
        explicit, name = split_target(text)
        numbers = self._load()["figures"]
        if name not in numbers:
            raise ValueError(f"figure {name!r}: no numbered figure of the book has this name")
        template = FIGURE_FORMAT if explicit is None else explicit
        return Resolved(template.replace("%s", numbers[name]).replace("{number}", numbers[name]))

    def ref(self, text: str) -> Resolved:
        """``{ref}`label``` or ``{ref}`text <label>```: the section's heading, or the text."""
        explicit, label = split_target(text)
        sections = self._load()["sections"]
        if label not in sections:
            raise ValueError(f"label {label!r}: no section of the book has this label")
        return Resolved(sections[label] if explicit is None else explicit)

    def prf_ref(self, text: str) -> Resolved:
        """``{prf:ref}`label``` or ``{prf:ref}`text <label>```: "Theorem 1", or the text."""
        explicit, label = split_target(text)
        numbers = self._load()["theorems"]
        if label not in numbers:
            raise ValueError(f"theorem {label!r}: no labelled theorem of the book has this label")
        return Resolved(THEOREM_FORMAT % numbers[label] if explicit is None else explicit)

    def doc(self, text: str) -> PageLink:
        """``{doc}`page``` or ``{doc}`text <page>```: the page's title, or the text, as a link."""
        explicit, target = split_target(text)
        index = self._load()
        page = target.lstrip("/") if target.startswith("/") else f"{index['page']}/{target}"
        page = posixpath.normpath(re.sub(r"\.md$", "", page)).lstrip("/")
        if page not in index["titles"]:
            raise ValueError(f"page {target!r}: no page of the book has this name")
        href = posixpath.relpath(f"{page}.md", index["page"] or ".")
        return PageLink(index["titles"][page] if explicit is None else explicit, href)

    def functions(self) -> dict:
        """``{name: function}`` of the roles' expressions (:data:`ROLES`), to bind in a kernel."""
        return {name: getattr(self, name) for name in ROLES}
