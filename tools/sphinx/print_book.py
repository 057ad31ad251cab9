"""What the printed book (the LaTeX builder's PDF) shows differently from the HTML book.

The HTML book keeps every cell's code one click away; the PDF prints only the
code that teaches. A cell is printed whole unless its tags say otherwise:

* ``hide-input``: the code is not the lesson (set-up, a computation behind a
  figure or table, the checks that assert a page's claims). HTML folds it
  away; the PDF prints its tables and figures alone, not the text it printed.
* ``hide-output``: the PDF prints its code alone; ``hide-cell`` or
  ``hide-input`` with ``hide-output``: the PDF prints nothing of it.

The exercises' solutions, folded under their questions in HTML, are gathered
in the PDF into a closing chapter (:data:`SOLUTIONS`), each under its title,
which names and links its exercise. The proofs, which sphinx-proof leaves
untitled, are titled "Proof". The links of the text to the API reference's
pages, which only the HTML book has, lead in the PDF to the module's summary
in its printed list (``book/api``), and links to what that list does not hold
become plain text.
"""

from __future__ import annotations

from docutils import nodes
from sphinx import addnodes
from sphinx.transforms import SphinxTransform
from sphinx.transforms.post_transforms import SphinxPostTransform

#: What each ``hide_mode`` of a myst-nb cell keeps in print: its code, its output.
PRINTED = {
    None: ("cell_code_source", "cell_code_output"),
    "input": ("cell_code_output",),
    "output": ("cell_code_source",),
    "input+output": (),
    "all": (),
}

#: The title of the PDF's chapter of solutions.
SOLUTIONS = "Solutions to the exercises"

#: The page whose list of module summaries the PDF prints (the API reference's front page).
API_PAGE = "book/api"

#: The prefix of the API reference's pages that only the HTML book has.
API_PAGES = "book/api/"


def shows_anything(node: nodes.Element) -> bool:
    """Whether ``node`` holds text that is not blank, an image or raw output."""
    for n in node.findall():
        if isinstance(n, (nodes.image, nodes.raw)):
            return True
        if isinstance(n, nodes.Text) and str(n).strip():
            return True
    return False


def drop_printed_text(output: nodes.Element) -> None:
    """Remove the text a cell printed (its literal blocks) from its output, keeping
    its tables and figures: what a hidden cell prints checks or reports the run."""
    for block in list(output.findall(nodes.literal_block)):
        block.parent.remove(block)


class PrintTheLesson(SphinxPostTransform):
    """In the PDF, keep of each code cell what :data:`PRINTED` says for its ``hide_mode``.

    Runs before myst-nb's transform of hidden cells (priority 199), which makes
    the HTML's toggles.
    """

    default_priority = 197
    formats = ("latex",)

    def run(self, **kwargs):
        for cell in list(self.document.findall(nodes.container)):
            if cell.get("nb_element") != "cell_code":
                continue
            kept = PRINTED.get(cell.get("hide_mode"), PRINTED[None])
            for part in list(cell.children):
                if part.get("nb_element") not in kept:
                    cell.remove(part)
                elif cell.get("hide_mode") == "input":
                    drop_printed_text(part)
            if not shows_anything(cell):
                cell.parent.remove(cell)


def proof_title(admonition: nodes.admonition) -> None:
    """Give a proof's box the title "Proof" and drop the "Proof. " its text opens with.

    sphinx-proof writes a proof as an untitled admonition whose first paragraph
    starts "Proof. "; HTML and LaTeX then draw an empty title bar.
    """
    if admonition.children and isinstance(admonition[0], nodes.title):
        return
    first = admonition.next_node(nodes.paragraph)
    if first is not None and first.children and isinstance(first[0], nodes.Text):
        text = str(first[0])
        if text.startswith("Proof. "):
            first.replace(first[0], nodes.Text(text[len("Proof. ") :]))
    admonition.insert(0, nodes.title("Proof", "Proof"))


class TitleTheProofs(SphinxTransform):
    """Title every proof's box (:func:`proof_title`), in HTML and in the PDF."""

    default_priority = 500

    def apply(self, **kwargs):
        for node in list(self.document.findall(nodes.admonition)):
            if "proof" in node.get("classes", []):
                proof_title(node)


class GatherSolutions(SphinxPostTransform):
    """In the PDF, move every solution into a closing chapter, :data:`SOLUTIONS`.

    Runs after sphinx-exercise has titled the solutions ("Solution to Exercise
    N", priorities 20-22), on the book's single document, whose root section
    holds every page. Each solution's title names its chapter by number.
    """

    default_priority = 30
    formats = ("latex",)

    def run(self, **kwargs):
        from sphinx_exercise.nodes import solution_node

        found = list(self.document.findall(solution_node))
        pages = list(self.document.findall(addnodes.start_of_file))
        if not found or not pages:
            return
        chapter = nodes.section(ids=["depthcore-solutions"], names=[SOLUTIONS.lower()])
        chapter += nodes.title(SOLUTIONS, SOLUTIONS)
        chapter += nodes.paragraph(
            "",
            "Each exercise's solution, in the order of the exercises, with the number of "
            "its chapter; the HTML book folds each under its question.",
        )
        for solution in found:
            solution.parent.remove(solution)
            docname = solution.get("docname")  # the page of the solution's exercise
            title = next(iter(solution.findall(nodes.title)), None)
            if docname and title is not None:
                # "Solution to Exercise N (chapter C)", C the number LaTeX gives its page
                title += nodes.Text(" (chapter ")
                title += nodes.raw("", f"\\ref{{\\detokenize{{{docname}::doc}}}}", format="latex")
                title += nodes.Text(")")
            chapter += solution
        # after the book's last page (the last part's last chapter); the LaTeX builder
        # inlines each page without re-parenting its nodes, so no page is found inside
        # another by walking up from it, and the last in document order is the one
        last = pages[-1]
        last.parent.insert(last.parent.index(last) + 1, chapter)


def compact(node: nodes.Element) -> None:
    """Print ``node`` in two columns of small type (the list of module summaries)."""
    index = node.parent.index(node)
    node.parent.insert(index + 1, nodes.raw("", "\\end{multicols}\n", format="latex"))
    node.parent.insert(index, nodes.raw("", "\\begin{multicols}{2}\\small\n", format="latex"))


def module_of(name: str, modules) -> str | None:
    """The longest of ``modules`` that ``name`` (an object's dotted name) lies in, or None."""
    best = None
    for module in modules:
        if name == module or name.startswith(module + "."):
            if best is None or len(module) > len(best):
                best = module
    return best


def summary_id(module: str) -> str:
    """The id of ``module``'s entry in the printed list of module summaries."""
    return "module-summary-" + module


class LinkToSummaries(SphinxPostTransform):
    """In the PDF, lead the links to the API reference's pages to the printed summaries.

    Each module's entry in :data:`API_PAGE`'s list gets a target
    (:func:`summary_id`), the list printed in two columns (:func:`compact`); a
    link into :data:`API_PAGES` (a module, a function, a class) leads to its
    module's entry; a link to anything else there (the book's own package, which
    the list does not hold) becomes its text.
    Runs after Sphinx has resolved the links (priority 10).
    """

    default_priority = 11
    formats = ("latex",)

    def run(self, **kwargs):
        import depthcore

        modules = depthcore.MODULES
        for page in list(self.document.findall(addnodes.start_of_file)):
            if page["docname"] != API_PAGE:
                continue
            for item in list(page.findall(nodes.list_item)):
                ref = item.next_node(nodes.reference)
                name = ref.astext() if ref is not None else ""
                if name in modules:
                    label = f"{API_PAGE}:{summary_id(name)}"
                    raw = nodes.raw(
                        "", f"\\phantomsection\\label{{\\detokenize{{{label}}}}}", format="latex"
                    )
                    item.insert(0, raw)
            for listing in list(page.findall(nodes.bullet_list)):
                if not isinstance(listing.parent, nodes.list_item):  # the families' lists
                    compact(listing)
        for ref in list(self.document.findall(nodes.reference)):
            uri = ref.get("refuri", "")
            if not uri.startswith("%" + API_PAGES):
                continue
            target = uri.partition("#")[2]
            module = module_of(target.removeprefix("module-"), modules)
            if module is None:
                ref.replace_self(ref.children)
            else:
                ref["refuri"] = f"%{API_PAGE}#{summary_id(module)}"


def setup(app):
    app.add_post_transform(PrintTheLesson)
    app.add_transform(TitleTheProofs)
    app.add_post_transform(GatherSolutions)
    app.add_post_transform(LinkToSummaries)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
