"""Sphinx extension of the book: what a reader can download, and the numbers of the text.

Each page's executed notebook
-----------------------------

The book's pages are MyST Markdown notebooks; myst-nb executes each one into
``_build/jupyter_execute/<page>.ipynb`` (without outputs when they come from
the execution cache: this extension then merges them in from the cache). This
extension copies that notebook, with its outputs, to
``_sources/<page>.ipynb`` in the HTML build and tells
sphinx-book-theme about it, so that the page's download menu offers
``.ipynb`` beside ``.md`` (the theme does so itself only when a launch
service such as Binder is configured).

The numbers of the text: ``{eval}`name```
-----------------------------------------
The pages write each number of their text as ``{eval}`name```, where
``name`` is the name under which the page glues the number's text
(``myst_nb.glue(name, text, display=False)``). In JupyterLab, jupyterlab-myst
evaluates ``name`` in the page's kernel, where ``depthbook.notebook.GlueLog``
binds each glued text to its name. The book executes its pages with myst-nb
(not in myst-nb's ``inline`` mode, the only one in which its own ``eval``
role works): this extension makes ``eval`` paste the text glued under the
name, exactly as myst-nb's ``glue:text`` role does, so the book shows what it
showed with ``glue:text``, and a name that is not glued fails the strict build.

The equations' numbers in JupyterLab
------------------------------------
The book numbers a labelled display equation in one count across its pages
and leaves an unlabelled one unnumbered; jupyterlab-myst numbers every
display of a notebook from 1. ``tools/myst_roles.py`` therefore writes each
unlabelled display as a ``{math}`` directive with ``:enumerated: false``
(this extension accepts the option, and the book renders the display as
before, unnumbered), and opens the first text cell of a page with labelled
equations with its front matter for jupyterlab-myst, a YAML block that sets
where the notebook's count starts (``numbering: equation: start: 17``).
The book does not show that block: this extension drops it.

The downloads folder
--------------------
``make book`` writes into ``_build/extra/downloads/`` (the config value
``depthcore_downloads``) the figures, the source archive, the pinned
requirements, CITATION.cff and the PDF; at the end of an HTML build this
extension copies that folder to ``_build/html/downloads/``, where the pages
link them. A build without it (``jupyter-book build .`` alone) has none.

The list of downloads
---------------------
The directive ``depthcore-downloads`` lists files of that folder, one per
line of its content, ``file: what it is`` (MyST inline markup allowed in the
description). In HTML each description links its file, and only a file that
the folder holds when the book is built: ``make book`` without ``make pdf``
lists the PDF as not built, without a link that would lead nowhere. In the
PDF the list is printed with each file's address, under ``html_baseurl``
when the config sets one, else relative to the HTML book's root. A file that
a build after this one (or beside it) writes, and that is copied into the
downloads when both end, is named in the environment variable
``DEPTHCORE_DOWNLOADS_PENDING`` (space-separated names; in ``make test``
xelatex writes the PDF beside the HTML build) and is linked as shipped.
"""

from __future__ import annotations

import ast
import os
import re
import shutil
from pathlib import Path

import docmath
from docutils import nodes
from docutils.parsers.rst import directives
from sphinx import addnodes
from sphinx.directives import patches
from sphinx.transforms import SphinxTransform
from sphinx.transforms.post_transforms import SphinxPostTransform
from sphinx.util.docutils import SphinxDirective, SphinxRole

CITATION_RE = re.compile(r"^\.\. \[(\w+)\]")


def add_executed_notebook(app, pagename, templatename, context, doctree):
    if app.builder.format != "html" or doctree is None:
        return
    executed = Path(app.outdir).parent / "jupyter_execute" / f"{pagename}.ipynb"
    if not executed.is_file():
        return
    target = Path(app.outdir) / "_sources" / f"{pagename}.ipynb"
    target.parent.mkdir(parents=True, exist_ok=True)
    config = app.env.mystnb_config
    if config.execution_mode == "cache":
        # myst-nb writes the page's notebook without the outputs it took from
        # the cache: merge them in from the cache, as myst-nb did for the page.
        import nbformat
        from jupyter_cache import get_cache

        notebook = nbformat.read(executed, as_version=4)
        _, notebook = get_cache(config.execution_cache_path).merge_match_into_notebook(notebook)
        nbformat.write(notebook, target)
    else:
        shutil.copy2(executed, target)
    context["ipynb_source"] = f"{pagename}.ipynb"


def copy_downloads(app, exception):
    if exception is not None or app.builder.format != "html":
        return
    source = Path(app.confdir) / app.config.depthcore_downloads
    if source.is_dir():
        shutil.copytree(source, Path(app.outdir) / "downloads", dirs_exist_ok=True)


def drop_repeated_citations(app, what, name, obj, options, lines):
    """Keep one definition of each citation of the docstrings (the API pages).

    Several modules cite the same work (``.. [prince2012] ...``); the API
    reference's pages would define it several times, and citations are
    targets of the whole book. The first module whose docstring is read with
    a citation keeps its definition (on that module's page); the others drop
    theirs, and their references (``[prince2012]_``) link to it.
    """
    owners = citation_owners(app.env)
    docname = app.env.docname
    kept, skipping = [], False
    for line in lines:
        match = CITATION_RE.match(line)
        if match:
            _, owner = owners.setdefault(match.group(1), (docname, name))
            skipping = owner != name
        elif skipping and not line.startswith(" "):
            skipping = False
        if not skipping:
            kept.append(line)
    lines[:] = kept


def reference_call(text: str) -> tuple[str, str] | None:
    """``(role, content)`` of an ``{eval}`` expression ``cite_t("maybank1990")``, else ``None``.

    The expression is a call of one of the functions of
    :data:`depthbook.crossref.ROLES` with one string literal, the content of
    the role it stands for; any other expression is ``None`` (a glued name).

    Raises
    ------
    ValueError
        A call of another function, or with other arguments.
    """
    from depthbook.crossref import ROLES

    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except SyntaxError:
        return None
    if not isinstance(tree, ast.Call):
        return None
    name = tree.func.id if isinstance(tree.func, ast.Name) else None
    args = tree.args
    if (
        name not in ROLES
        or tree.keywords
        or len(args) != 1
        or not isinstance(args[0], ast.Constant)
        or not isinstance(args[0].value, str)
    ):
        raise ValueError(
            f"{{eval}}`{text}`: a reference is written as one of "
            f"{', '.join(ROLES)} called with one string, the role's content"
        )
    return ROLES[name], args[0].value


class EvalRole(SphinxRole):
    """``{eval}`name```: the text glued under ``name``; ``{eval}`cite_t("key")```: the citation.

    A glued name is pasted as myst-nb's ``glue:text`` role pastes it. A
    reference written as an expression (:func:`reference_call`) is rendered by
    the role it names, with the same content: ``{eval}`eq("eq-7")``` as
    ``{eq}`eq-7```, resolved and printed (HTML and LaTeX) exactly as that role.
    """

    def run(self):
        from docutils.parsers.rst import roles
        from myst_nb.ext.glue.roles import PasteTextRole

        try:
            call = reference_call(self.text)
        except ValueError as error:
            message = self.inliner.reporter.error(str(error), line=self.lineno)
            problem = self.inliner.problematic(self.rawtext, self.rawtext, message)
            return [problem], [message]
        if call is None:
            return PasteTextRole()(
                self.name, self.rawtext, self.text, self.lineno, self.inliner, self.options, []
            )
        name, content = call
        role, messages = roles.role(name, self.inliner.language, self.lineno, self.inliner.reporter)
        if role is None:
            message = self.inliner.reporter.error(f"unknown role {name!r}", line=self.lineno)
            problem = self.inliner.problematic(self.rawtext, self.rawtext, message)
            return [problem], [*messages, message]
        result, more = role(
            name, f"{{{name}}}`{content}`", content, self.lineno, self.inliner, {}, []
        )
        return result, [*messages, *more]


def paste_eval_as_glue(app, config):
    """Make ``{eval}`` paste glued texts and render references (:class:`EvalRole`).

    Connected to ``config-inited``, after every extension's ``setup``: it
    replaces the ``eval`` role that myst-nb registers.
    """
    app.add_role("eval", EvalRole(), override=True)


#: A figure's content that names its glued figure: ``{eval}`name```.
EVAL_FIGURE = re.compile(r"\{eval\}`([A-Za-z_][A-Za-z0-9_]*)`")


class Figure(patches.Figure):
    """``{figure}``, also of a glued figure: ``{eval}`name``` as its content's first paragraph.

    With an image's path as its argument it is Sphinx's figure. Without one,
    its content is ``{eval}`name```, a blank line and the caption: the figure
    that the page glues under ``name``, pasted with its caption exactly as
    myst-nb's ``glue:figure`` directive pastes it (and with its options).
    JupyterLab's MyST renderer (jupyterlab-myst) knows ``figure`` but not
    ``glue:figure``, and shows the same figure, evaluated in the page's kernel
    (:class:`depthbook.notebook.GluedOutput`), with the caption. The option
    ``:enumerated: false`` is for JupyterLab, which numbers a notebook's
    figures from 1 (the book numbers them across its pages, and
    ``{eval}`numref("name")``` shows that number in JupyterLab too); the book
    numbers every named figure, whatever it says, and no other (:func:`unnumbered`).
    """

    required_arguments = 0
    optional_arguments = 1
    option_spec = {**patches.Figure.option_spec, "enumerated": directives.unchanged}

    def run(self):
        self.options.pop("enumerated", None)
        named = "name" in self.options  # (Sphinx's figure pops it)
        made = self.figure()
        if not named:
            for figure in made:
                if isinstance(figure, nodes.figure):
                    unnumbered(figure)
        return made

    def figure(self):
        if self.arguments:
            return super().run()
        from myst_nb.ext.glue.directives import PasteFigureDirective

        first = self.content[0].strip() if self.content else ""
        match = EVAL_FIGURE.fullmatch(first)
        if match is None or (len(self.content) > 1 and self.content[1].strip()):
            raise self.error(
                "a figure without an image's path pastes a glued figure: its content "
                "is {eval}`name` alone on its first line, a blank line, then the caption"
            )
        unknown = set(self.options) - set(PasteFigureDirective.option_spec)
        if unknown:
            raise self.error(f"options of a glued figure: not {', '.join(sorted(unknown))}")
        return PasteFigureDirective(
            "glue:figure",
            [match.group(1)],
            self.options,
            self.content[2:],
            self.lineno,
            self.content_offset + 2,
            self.block_text,
            self.state,
            self.state_machine,
        ).run()


def unnumbered(figure) -> None:
    """Make a figure's caption its legend, so that neither build numbers it (in place).

    Sphinx numbers every captioned figure, named or not; the book numbers its
    named figures alone (the paper's Figures 1-6 keep their numbers), and an
    unnamed one (the intuition page's, the live frames of Figures 2 and 6)
    keeps its caption's text, unnumbered, as the legend below it.
    """
    for caption in [c for c in figure.children if isinstance(c, nodes.caption)]:
        caption.replace_self(nodes.legend("", nodes.paragraph("", "", *caption.children)))


class Math(patches.MathDirective):
    """``{math}``, also with the option ``:enumerated: false``, which is for JupyterLab.

    jupyterlab-myst numbers every display of a notebook unless it says
    ``:enumerated: false``; the book numbers a display by its ``:label:``
    alone, whatever it says.
    """

    option_spec = {**patches.MathDirective.option_spec, "enumerated": directives.unchanged}

    def run(self):
        self.options.pop("enumerated", None)
        return super().run()


#: The keys of a page's front matter for jupyterlab-myst (``tools/myst_roles.py``).
LAB_FRONTMATTER_KEYS = {"numbering"}


class DropLabFrontmatter(SphinxTransform):
    """Remove a page's front matter for jupyterlab-myst: a YAML block before its title.

    The block opens the page's first text cell, where jupyterlab-myst reads a
    notebook's front matter (``numbering: ...``, see ``tools/myst_roles.py``);
    a YAML block there with other keys is kept, as text of the page.
    """

    default_priority = 200

    def apply(self, **kwargs):
        for node in list(self.document.children):
            if isinstance(node, nodes.section):
                return
            if not isinstance(node, nodes.literal_block) or node.get("language") != "yaml":
                continue
            import yaml

            try:
                data = yaml.safe_load(node.astext())
            except yaml.YAMLError:
                continue
            if isinstance(data, dict) and data and set(data) <= LAB_FRONTMATTER_KEYS:
                node.parent.remove(node)


def citation_owners(env) -> dict:
    """``{citation: (page read, object)}``: which docstring defines each citation."""
    if not hasattr(env, "depthcore_citation_owners"):
        env.depthcore_citation_owners = {}
    return env.depthcore_citation_owners


def purge_citation_owners(app, env, docname):
    owners = citation_owners(env)
    for key in [key for key, (page, _) in owners.items() if page == docname]:
        del owners[key]


def merge_citation_owners(app, env, docnames, other):
    for key, owner in citation_owners(other).items():
        citation_owners(env).setdefault(key, owner)


def parse_downloads(lines) -> list[tuple[str, str]]:
    """``(file, description)`` of each non-empty line ``file: description``."""
    items = []
    for line in lines:
        if not line.strip():
            continue
        name, sep, text = line.partition(":")
        if not sep or not name.strip() or "/" in name.strip() or not text.strip():
            raise ValueError(f"a download is written 'file: what it is', got {line!r}")
        items.append((name.strip(), text.strip()))
    return items


#: The environment variable naming the downloads another build is writing.
PENDING = "DEPTHCORE_DOWNLOADS_PENDING"


def pending_downloads() -> set[str]:
    """The names of :data:`PENDING`: downloads copied in once a build beside this one ends."""
    return set(os.environ.get(PENDING, "").split())


class DownloadsDirective(SphinxDirective):
    """The list of downloads: linked in HTML where built, printed with addresses in the PDF."""

    has_content = True

    def run(self):
        try:
            items = parse_downloads(self.content)
        except ValueError as error:
            raise self.error(str(error)) from error
        folder = Path(self.env.app.confdir) / self.config.depthcore_downloads
        up = "../" * self.env.docname.count("/")
        base = (self.config.html_baseurl or "").rstrip("/")
        html, latex = nodes.bullet_list(), nodes.bullet_list()
        for name, text in items:
            described, messages = self.state.inline_text(text, self.lineno)
            shipped = (folder / name).is_file() or name in pending_downloads()
            item = nodes.list_item()
            para = nodes.paragraph()
            if shipped:
                para += nodes.reference("", "", *described, refuri=f"{up}downloads/{name}")
            else:
                para += described
                para += nodes.Text(" (not shipped by this build of the book)")
            item += para
            html += item
            address = f"{base}/downloads/{name}" if base else f"downloads/{name}"
            item = nodes.list_item()
            para = nodes.paragraph()
            para += [node.deepcopy() for node in described]
            para += nodes.Text(": ")
            para += nodes.literal(address, address)
            item += para
            latex += item
        only_html = addnodes.only(expr="html")
        only_html += html
        only_latex = addnodes.only(expr="latex")
        only_latex += latex
        return [only_html, only_latex, *messages]


#: Pages of the HTML book that the PDF leaves out: the API reference's page per
#: family (the PDF prints the summaries of ``book/api`` instead).
HTML_ONLY_PAGES = re.compile(r"^book/api/")
#: Pages whose title the PDF drops, keeping their content: the references, which
#: the LaTeX builder gathers into the book's closing bibliography anyway (the
#: page's own chapter would be left empty).
UNTITLED_IN_PRINT = ("book/bibliography",)

#: The title of the PDF's first chapter, the root page's own text.
INTRODUCTION = "Introduction"


class DropHtmlOnlyPages(SphinxPostTransform):
    """In the PDF's single document, remove :data:`HTML_ONLY_PAGES` and untitle the others.

    Runs before the LaTeX builder gathers the citations, so that the removed
    pages' citations are not printed.
    """

    default_priority = 5
    formats = ("latex",)

    def run(self, **kwargs):
        for node in list(self.document.findall(addnodes.start_of_file)):
            if HTML_ONLY_PAGES.match(node["docname"]):
                node.parent.remove(node)
            elif node["docname"] in UNTITLED_IN_PRINT:
                for section in [c for c in node.children if isinstance(c, nodes.section)]:
                    section.replace_self(
                        [c for c in section.children if not isinstance(c, nodes.title)]
                    )


#: The heading of the PDF's table of contents. The LaTeX builder would take the
#: caption of the root page's first toctree, the book's first part ("The idea").
CONTENTS = "Contents"


def book_parts(env) -> dict[str, str]:
    """The first page of each of the book's parts, and the part's caption.

    The parts are the captioned toctrees of the root page (``_toc.yml``'s
    ``parts``), in order.
    """
    first = {}
    for toctree in env.get_doctree(env.config.root_doc).findall(addnodes.toctree):
        caption = toctree.get("caption")
        entries = [name for _, name in toctree["entries"] if name not in ("self", None)]
        if caption and entries:
            first[entries[0]] = caption
    return first


#: The caption of the book's last part, whose chapters the PDF letters as appendices.
APPENDICES = "Appendices"


class PrintParts(SphinxPostTransform):
    """In the PDF, open each of the book's parts with ``\\part{caption}``.

    The HTML book shows its parts as the captions of the sidebar's sections; the
    LaTeX builder drops toctree captions. Each part's first page (its
    ``start_of_file`` node in the PDF's single document) is preceded by a raw
    LaTeX ``\\part``, so that the printed book and its contents show the parts;
    the part :data:`APPENDICES` is preceded by ``\\appendix`` as well.
    """

    default_priority = 6
    formats = ("latex",)

    def run(self, **kwargs):
        first = book_parts(self.env)
        for node in list(self.document.findall(addnodes.start_of_file)):
            caption = first.get(node["docname"])
            if caption is None:
                continue
            opening = "\\appendix\n" if caption == APPENDICES else ""
            raw = nodes.raw("", f"{opening}\\part{{{caption}}}\n", format="latex")
            node.parent.insert(node.parent.index(node), raw)


def contents_heading(app):
    """Head the PDF's table of contents :data:`CONTENTS` (see there)."""
    if app.builder.format == "latex":
        app.builder.get_contentsname = lambda indexfile: CONTENTS


def root_page_as_one_chapter(app, doctree, docname):
    """In the PDF, make the root page's own text one chapter, :data:`INTRODUCTION`.

    The LaTeX builder takes the root page's title for the book's and makes each
    of its sections a chapter, like the chapters of the other pages it includes
    after them; its opening paragraphs would stand alone before the first.
    Here they and its sections become one chapter, the sections its sections.
    """
    if app.builder.format != "latex" or docname != app.config.root_doc:
        return
    root = doctree.next_node(nodes.section)
    if root is None or not root.children or not isinstance(root[0], nodes.title):
        return
    own = []
    for child in root.children[1:]:
        if isinstance(child, addnodes.start_of_file) or child.next_node(addnodes.start_of_file):
            break
        own.append(child)
    if not own:
        return
    chapter = nodes.section(ids=["depthcore-introduction"], names=[INTRODUCTION.lower()])
    chapter += nodes.title(INTRODUCTION, INTRODUCTION)
    for child in own:
        root.remove(child)
        chapter += child
    root.insert(1, chapter)


def module_summary(module) -> str:
    """The first paragraph of a module's docstring, on one line."""
    doc = (module.__doc__ or "").strip()
    return " ".join(doc.split("\n\n", 1)[0].split())


RST_ROLE_RE = re.compile(r":(?:py:)?(\w+):`([^`]+)`")
RST_LITERAL_RE = re.compile(r"``([^`]+)``")


def rst_to_myst(text: str) -> str:
    """A docstring line's reST inline markup (roles, literals) in MyST, for a MyST page."""
    text = RST_ROLE_RE.sub(
        lambda m: f"{{{'math' if m[1] == 'math' else 'py:' + m[1]}}}`{m[2]}`", text
    )
    return RST_LITERAL_RE.sub(r"`\1`", text)


class ModuleSummaries(SphinxDirective):
    """Every module of the package (``depthcore.MODULES``), each with its summary.

    A list per family, in the order of ``depthcore.SUBPACKAGES``: the family's
    package, then its modules, each linking its documentation (in HTML) and
    giving the first paragraph of its docstring, its formulas typeset
    (:mod:`docmath`). Nothing is typed: a module added to a family's folder is
    listed here at the next build.
    """

    has_content = False

    def run(self):
        import importlib

        from docutils.statemachine import StringList

        import depthcore

        lines = []
        for name in depthcore.MODULES:
            module = importlib.import_module(name)
            summary = rst_to_myst(docmath.convert_line(module_summary(module)))
            indent = "  " if name.count(".") > 1 else ""
            lines.append(f"{indent}* {{py:mod}}`{name}`: {summary}")
        container = nodes.container(classes=["module-summaries"])
        self.state.nested_parse(StringList(lines, source=self.get_source_info()[0]), 0, container)
        return container.children


def book_modules() -> list[str]:
    """``depthbook``, the book's own package, and its modules and subpackages, by folder."""
    import pkgutil

    import depthbook

    found = ["depthbook"]
    for m in pkgutil.walk_packages(depthbook.__path__, "depthbook."):
        if not any(part.startswith("_") for part in m.name.split(".")):
            found.append(m.name)
    return found


def family_modules(package: str) -> list[str]:
    """The modules a family's API page documents: the package, then its modules.

    Parameters
    ----------
    package : str
        ``depthcore.<family>`` (one of ``depthcore.SUBPACKAGES``), or ``depthbook``,
        the book's own package.

    Returns
    -------
    list of str
        ``package`` and, for a family, the names in ``depthcore.MODULES`` below it;
        for ``depthbook``, :func:`book_modules`.
    """
    import depthcore

    if package == "depthbook":
        return book_modules()
    if package not in depthcore.MODULES:
        raise ValueError(f"package must be one of depthcore.MODULES, got {package!r}")
    return [package] + [m for m in depthcore.MODULES if m.startswith(f"{package}.")]


class PackageReference(SphinxDirective):
    """The API reference of one family's modules, each a section of the page.

    Each module is a section titled by its name, rendered by autodoc
    (``automodule`` with its members); the list comes from the package's folder
    (:func:`family_modules`), so a new module needs no page of its own. The
    page itself shows the family's own docstring above (the sections are
    attached to the page as they are parsed, so that text comes first there);
    a package without modules is rendered whole, members included.
    """

    required_arguments = 1

    def run(self):
        from docutils.statemachine import StringList

        names = family_modules(self.arguments[0])
        lines = []
        if len(names) == 1:
            lines += ["```{eval-rst}", f".. automodule:: {names[0]}", "   :members:", "```", ""]
        for name in names[1:]:
            lines += [f"## `{name}`", "", "```{eval-rst}", f".. automodule:: {name}"]
            lines += ["   :members:", "```", ""]
        node = nodes.section()
        node.document = self.state.document
        source = self.get_source_info()[0]
        self.state.nested_parse(StringList(lines, source), 0, node, match_titles=True)
        return node.children


def set_release(app, config):
    """The book's release is the package's version (the PDF's title page shows it)."""
    import depthcore

    if not config.release:
        config.release = config.version = depthcore.__version__


def setup(app):
    app.connect("config-inited", paste_eval_as_glue)
    app.connect("config-inited", set_release)
    app.connect("autodoc-process-docstring", drop_repeated_citations)
    app.connect("env-purge-doc", purge_citation_owners)
    app.connect("env-merge-info", merge_citation_owners)
    app.connect("autodoc-process-docstring", docmath.typeset_docstring)
    app.add_directive("depthcore-module-summaries", ModuleSummaries)
    app.add_directive("depthcore-package", PackageReference)
    app.add_directive("figure", Figure, override=True)
    app.add_directive("math", Math, override=True)
    app.add_transform(DropLabFrontmatter)
    app.add_post_transform(DropHtmlOnlyPages)
    app.add_post_transform(PrintParts)
    app.connect("builder-inited", contents_heading)
    app.connect("doctree-resolved", root_page_as_one_chapter)
    app.add_config_value("depthcore_downloads", "_build/extra/downloads", "env")
    app.add_directive("depthcore-downloads", DownloadsDirective)
    # Before sphinx-book-theme builds its header buttons (priority 501).
    app.connect("html-page-context", add_executed_notebook, priority=450)
    app.connect("build-finished", copy_downloads)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
