"""Sphinx extension of the book: what a reader can download, and the numbers of the text.

Each page's executed notebook
-----------------------------

The book's pages are MyST Markdown notebooks; myst-nb executes each one into
``_build/jupyter_execute/<page>.ipynb``. This extension copies that notebook,
with its outputs, to ``_sources/<page>.ipynb`` in the HTML build and tells
sphinx-book-theme about it, so that the page's download menu offers
``.ipynb`` beside ``.md`` (the theme does so itself only when a launch
service such as Binder is configured).

The numbers of the text: ``{eval}`name```
-----------------------------------------
The pages write each number of their text as ``{eval}`name```, where
``name`` is the name under which the page glues the number's text
(``myst_nb.glue(name, text, display=False)``). In JupyterLab, jupyterlab-myst
evaluates ``name`` in the page's kernel, where ``depthcore.report.GlueLog``
binds each glued text to its name. The book executes its pages with myst-nb
(not in myst-nb's ``inline`` mode, the only one in which its own ``eval``
role works): this extension makes ``eval`` paste the text glued under the
name, exactly as myst-nb's ``glue:text`` role does, so the book shows what it
showed with ``glue:text``, and a name that is not glued fails the strict build.

The downloads folder
--------------------
``make book`` writes into ``_build/extra/downloads/`` (the config value
``depthcore_downloads``) the figures, the source archive, the pinned
requirements, CITATION.cff and the PDF; at the end of an HTML build this
extension copies that folder to ``_build/html/downloads/``, where the pages
link them. A build without it (``jupyter-book build .`` alone) has none.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

CITATION_RE = re.compile(r"^\.\. \[(\w+)\]")


def add_executed_notebook(app, pagename, templatename, context, doctree):
    if app.builder.format != "html" or doctree is None:
        return
    executed = Path(app.outdir).parent / "jupyter_execute" / f"{pagename}.ipynb"
    if not executed.is_file():
        return
    target = Path(app.outdir) / "_sources" / f"{pagename}.ipynb"
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy2(executed, target)
    context["ipynb_source"] = f"{pagename}.ipynb"


def copy_downloads(app, exception):
    if exception is not None or app.builder.format != "html":
        return
    source = Path(app.confdir) / app.config.depthcore_downloads
    if source.is_dir():
        shutil.copytree(source, Path(app.outdir) / "downloads", dirs_exist_ok=True)


def drop_repeated_citations(app, what, name, obj, options, lines):
    """Keep one definition of each citation of the docstrings (the API page).

    Several modules cite the same work (``.. [prince2012] ...``); on one page
    the repeated definitions would be duplicate targets. The first module's
    definition is kept and the later references (``[prince2012]_``) link to it.
    """
    seen = app.env.temp_data.setdefault("depthcore_citations", set())
    kept, skipping = [], False
    for line in lines:
        match = CITATION_RE.match(line)
        if match:
            skipping = match.group(1) in seen
            seen.add(match.group(1))
        elif skipping and not line.startswith(" "):
            skipping = False
        if not skipping:
            kept.append(line)
    lines[:] = kept


def paste_eval_as_glue(app, config):
    """Make ``{eval}`name``` paste the text glued under ``name`` (myst-nb's ``glue:text``).

    Connected to ``config-inited``, after every extension's ``setup``: it
    replaces the ``eval`` role that myst-nb registers.
    """
    from myst_nb.ext.glue.roles import PasteTextRole

    app.add_role("eval", PasteTextRole(), override=True)


def setup(app):
    app.connect("config-inited", paste_eval_as_glue)
    app.connect("autodoc-process-docstring", drop_repeated_citations)
    app.add_config_value("depthcore_downloads", "_build/extra/downloads", "html")
    # Before sphinx-book-theme builds its header buttons (priority 501).
    app.connect("html-page-context", add_executed_notebook, priority=450)
    app.connect("build-finished", copy_downloads)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
