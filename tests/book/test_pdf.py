"""The PDF of the book (``make pdf``) numbers the paper's equations and figures as the paper does.

Reads the text of ``_build/latex/depthcore.pdf`` with poppler's ``pdftotext``
and checks that

* the displayed equations carry the numbers (1), (2), ..., (24), in this order
  and no other (an equation's number is set at the right margin, after a gap);
* the paper's Figures 1-6 (the figures labelled ``fig-1`` ... ``fig-6`` in
  ``book/*.md``) are captioned "Figure N: ..." with the paper's numbers, and
  every other captioned figure of the book has a number above 6;
* no LaTeX or MyST source leaks into the text (``\\mathbf``, ``$``, ``{glue``,
  ``??`` for an unresolved reference);
* the HTML book ships the same PDF;
* the title page names the paper, the package's version and the build's date;
  the contents are headed "Contents"; the book's parts (``_toc.yml``'s
  captions) each open a page with their heading, in order, and are listed in
  the contents; no page is blank; the figures are vector graphics
  (a handful of raster images at most); no raw Markdown table is printed;
  no line of the code shown is broken (Sphinx marks a broken line with ↪);
  the intro is one chapter, its opening paragraph on the page of its title;
  the list of downloads is printed with their addresses; the API reference is
  a short list of module summaries; the book is within its budget of pages and prints at
  most 500 lines of code and output, no check (``assert``) and no gluing; no
  line overruns the text by over 10 pt and no float its page; every figure's
  smallest text prints at 6.8 pt or more; no link leads to a page the PDF leaves
  out; at least 14 exercises, their solutions gathered in the closing chapter,
  each naming its exercise's chapter; the proof titled; Notation after the model
  and Reproducing the first appendix.

Without the PDF or pdftotext the checks are skipped with a message, and fail
under CI (``CI=true``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys

import pytest
from conftest import HTML_DIR, ROOT

import depthcore

PDF = ROOT / "_build" / "latex" / "depthcore.pdf"
# A glued figure: ```{figure}, its options (:name: first), {eval}`name`, its caption.
FIGURE_RE = re.compile(
    r"^```\{figure\}[ \t]*\n:name:[ \t]*(\S+)[ \t]*\n(?::\w+:[^\n]*\n)*[ \t]*\n"
    r"\{eval\}`\w+`[ \t]*\n[ \t]*\n(.*?)\n```",
    re.MULTILINE | re.DOTALL,
)
# An equation's number: "(12)" at the end of a line, set at the right margin (from the
# column EQNO_COLUMN on, after a gap), whether or not the equation shares its line.
EQNO_RE = re.compile(r"^(.* {6,})\((\d+)\)\s*$", re.MULTILINE)
EQNO_COLUMN = 80
RAW_RES = (
    re.compile(r"\\[A-Za-z]{2,}"),  # a LaTeX command
    re.compile(r"\$"),  # MyST/LaTeX math delimiters
    re.compile(r"\{(glue|eq|doc|cite|numref|math|ref|eval)[:}]"),  # MyST roles
    re.compile(r"\?\?"),  # an unresolved reference
)


def pdftotext(*args: str) -> str:
    return subprocess.run(
        ["pdftotext", *args, str(PDF), "-"], capture_output=True, text=True, check=True, timeout=120
    ).stdout


@pytest.fixture(scope="module")
def pdf(missing_prerequisite):
    if not PDF.exists():
        missing_prerequisite(
            f"{PDF.relative_to(ROOT)} not found: run `make pdf` (TeX Live's xelatex)"
        )
    if shutil.which("pdftotext") is None:
        missing_prerequisite(
            "pdftotext not found (apt-get install poppler-utils): the PDF is not checked"
        )
    return PDF


@pytest.fixture(scope="module")
def layout_text(pdf) -> str:
    return pdftotext("-layout")


@pytest.fixture(scope="module")
def plain_text(pdf) -> str:
    """The PDF's text with every run of whitespace made one space, and straight apostrophes."""
    return " ".join(pdftotext().split()).replace("\u2019", "'")


def source_figures() -> list[tuple[str, str]]:
    """(label, first words of the caption) of every captioned figure of the book, in TOC order."""
    import check_notebooks

    found = []
    for entry in check_notebooks.toc_files():
        path = ROOT / (entry if entry.endswith(".md") else f"{entry}.md")
        for label, caption in FIGURE_RE.findall(path.read_text(encoding="utf-8")):
            words = re.split(r"[$`{(]", " ".join(caption.split()), maxsplit=1)[0].split()[:4]
            found.append((label, " ".join(words)))
    return found


def captions_in_pdf(plain_text: str) -> list[tuple[str, int]]:
    """(label, number) of every figure caption in the PDF, in the PDF's order.

    A caption is "Figure N: " followed by the first words of one of the
    book's captions; the captions appear in TOC order, each once, so the k-th
    caption found is the k-th figure of the sources.
    """
    figures = source_figures()
    starts = sorted({start for _, start in figures}, key=len, reverse=True)
    pattern = re.compile(r"Figure (\d+): (" + "|".join(map(re.escape, starts)) + ")")
    shown = [(m.group(2), int(m.group(1))) for m in pattern.finditer(plain_text)]
    assert [start for start, _ in shown] == [start for _, start in figures], (
        f"the PDF's figure captions {shown} are not the book's {figures}"
    )
    return [(label, number) for (label, _), (_, number) in zip(figures, shown, strict=True)]


def test_equations_are_numbered_1_to_24_in_order(layout_text):
    numbers = [int(n) for lead, n in EQNO_RE.findall(layout_text) if len(lead) >= EQNO_COLUMN]
    assert numbers == list(range(1, 25)), f"equation numbers in the PDF: {numbers}"


def test_the_papers_figures_carry_the_papers_numbers(plain_text, load_figure_numbers):
    captions = captions_in_pdf(plain_text)
    for label, where in load_figure_numbers.items():
        shown = [number for lab, number in captions if lab == label]
        assert shown == [int(where["number"])], f"{label} is captioned Figure {shown} in the PDF"


def test_no_other_figure_takes_the_papers_numbers(plain_text, load_figure_numbers):
    papers = {int(where["number"]) for where in load_figure_numbers.values()}
    others = [
        number for label, number in captions_in_pdf(plain_text) if label not in load_figure_numbers
    ]
    assert others and min(others) > max(papers), f"the book's own figures are numbered {others}"
    assert len(set(others)) == len(others), f"figure numbers used twice: {others}"


def test_no_raw_latex_or_myst_in_the_text(plain_text):
    for pattern in RAW_RES:
        found = [
            plain_text[max(m.start() - 40, 0) : m.end() + 40] for m in pattern.finditer(plain_text)
        ]
        assert not found, f"{pattern.pattern!r} in the PDF's text: {found[:3]}"


def test_the_html_book_ships_this_pdf(pdf):
    shipped = HTML_DIR / "downloads" / "depthcore.pdf"
    assert shipped.is_file(), (
        f"{shipped.relative_to(ROOT)} not found: run `make pdf` before `make book`"
    )
    assert shipped.read_bytes() == pdf.read_bytes(), (
        "the HTML book ships another PDF than _build/latex's"
    )


@pytest.fixture(scope="module")
def pages(pdf) -> list[str]:
    """The PDF's text page by page (pdftotext separates pages by form feeds)."""
    return [" ".join(page.split()) for page in pdftotext("-layout").split("\f")][:-1]


def test_the_title_page_names_the_paper_the_version_and_the_date(pages):
    title = pages[0]
    for words in (
        "Filter Based Estimates of Depth",
        "Maybank",
        "British Machine Vision Conference",
        "1990",
        f"depthcore version {depthcore.__version__}",
    ):
        assert words in title, f"the title page does not name {words!r}: {title!r}"
    assert re.search(r"built \w+ \d{1,2}, \d{4}", title), (
        f"no build date on the title page: {title}"
    )


#: A part's heading in the text, "PART IV The paper's appendix and its print", which the
#: part's first chapter follows ("13 Appendix: ...", or "A Reproducing ...").
PART_HEADING = re.compile(r"PART ([IVXL]+) (.+?) (?=\d+ [A-Z]|[A-Z] [A-Z][a-z])")
#: At most this many raster images in the PDF (heat maps may be raster; curves are not).
MAX_RASTER_IMAGES = 6


def book_parts() -> list[str]:
    """The captions of ``_toc.yml``'s parts, in order."""
    import yaml

    toc = yaml.safe_load((ROOT / "_toc.yml").read_text(encoding="utf-8"))
    return [part["caption"] for part in toc["parts"]]


def test_no_page_is_blank(pages):
    # every page but the parts' openings carries a running head or a chapter's opening
    # (about ten words) and more than a heading or a line spilled from the page before
    blank = [i + 1 for i, page in enumerate(pages) if len(page.split()) < 30]
    assert not blank, f"pages with (almost) no text: {blank}"


def test_the_contents_are_headed_contents(pages):
    contents = [i for i, page in enumerate(pages[:4]) if "1 Introduction" in page]
    assert contents, "no table of contents among the first pages"
    head = pages[contents[0]].split("1 Introduction")[0]
    assert head.strip().upper().endswith("CONTENTS"), f"the contents are headed {head!r}"
    for caption in book_parts():
        assert caption.upper() not in head.upper(), f"the contents are headed {head!r}"


def test_each_part_opens_with_its_heading_in_order(layout_text):
    text = " ".join(layout_text.split())
    body = text[text.index("PART I ") :]  # after the contents
    opened = [(m.group(1), m.group(2)) for m in PART_HEADING.finditer(body)]
    numbers = ("I", "II", "III", "IV", "V", "VI", "VII", "VIII", "IX", "X")
    assert [c for _, c in opened] == book_parts(), f"the PDF's parts are {opened}"
    assert [n for n, _ in opened] == list(numbers[: len(opened)])
    contents = text[: text.index("PART I ")]
    for number, caption in zip(numbers, book_parts(), strict=False):
        assert f"{number} {caption}" in contents, f"the contents do not list part {caption!r}"


def test_the_figures_are_vector_graphics(pdf):
    listing = subprocess.run(
        ["pdfimages", "-list", str(pdf)], capture_output=True, text=True, check=True, timeout=120
    ).stdout.splitlines()[2:]
    assert len(listing) <= MAX_RASTER_IMAGES, (
        f"{len(listing)} raster images in the PDF (at most {MAX_RASTER_IMAGES}): "
        f"pages {sorted({int(line.split()[0]) for line in listing})}"
    )


def shown_code_lines() -> list[str]:
    """Every line of code the book shows (cells not removed), its whitespace made one space."""
    sys.path.insert(0, str(ROOT / "tools"))
    import prose

    lines = []
    for page in prose.pages():
        for _, _, tags, code in prose.cells(page.read_text(encoding="utf-8")):
            if prose.shown(tags):
                lines += [" ".join(line.split()) for line in code if line.strip()]
    return lines


def test_no_line_of_code_is_broken(layout_text):
    # Sphinx breaks a verbatim line wider than the page and marks the continuation with a
    # hook arrow (pdftotext: ",→" opening the next line), after a visible space (␣) when
    # it breaks at one. Outputs wider than the page are broken where they must be; a line
    # of the code shown (at most 88 characters) never is.
    code = shown_code_lines()
    lines = layout_text.splitlines()
    broken = []
    for first, then in zip(lines, lines[1:], strict=False):
        if not then.lstrip().startswith((",\u2192", "\u21aa")):
            continue
        head = " ".join(first.replace("\u2423", " ").split())
        if head and any(line.startswith(head[:40]) for line in code):
            broken.append(f"{head} / {then.strip()}")
    assert not broken, f"{len(broken)} broken lines of code in the PDF: {broken[:3]}"


def test_no_raw_markdown_table_is_printed(plain_text):
    found = re.findall(r".{0,40}\|\s*(?:-{3,}|—|:?-+:?)\s*\|.{0,40}", plain_text)
    assert not found, f"a Markdown table printed as text: {found[:3]}"


def test_the_intro_is_one_chapter_that_opens_with_its_first_paragraph(plain_text, pages):
    assert re.search(r"1\.1 What this replication found .*1\.2 Reading routes", plain_text), (
        "the intro's sections are not sections 1.1, 1.2, ... of one chapter"
    )
    opening = [i for i, page in enumerate(pages) if "This book is an executable account" in page]
    assert len(opening) == 1, "the intro's opening paragraph is not on one page"
    page = pages[opening[0]]
    assert "INTRODUCTION" in page.upper() and "What this replication found" in page, (
        "the intro's opening paragraph is not on the page of its chapter's title and first section"
    )


def test_the_downloads_are_printed_with_their_addresses(plain_text):
    for name in (
        "depthcore.pdf",
        "article.pdf",
        "depthcore.tar.gz",
        "depthbook.tar.gz",
        "requirements.txt",
        "CITATION.cff",
    ):
        # the address may break after its folder's slash
        assert re.search(rf"downloads/ ?{re.escape(name)}", plain_text), (
            f"the PDF does not list downloads/{name}"
        )


def test_the_api_reference_is_a_short_list_of_module_summaries(pages, plain_text):
    start = [i for i, page in enumerate(pages) if "API REFERENCE" in page.upper()]
    assert start, "no API reference in the PDF"
    first = start[-1]  # the chapter (the table of contents names it first)
    rest = " ".join(pages[first:])
    for name in depthcore.MODULES:
        assert f"{name}:" in rest, f"the PDF's API reference omits {name}"
    # summaries only: no module's functions are documented in print
    assert "depthcore.problem.gaussian.paper_prior" not in plain_text
    assert "Python Module Index" not in plain_text
    end = [i for i, page in enumerate(pages) if "SOLUTIONS TO THE EXERCISES" in page.upper()]
    assert end and end[-1] > first, "the solutions do not follow the API reference"
    assert end[-1] - first <= 6, f"the API reference fills {end[-1] - first} pages"


# The printed book's targets: its length, the code it prints, what fits its pages.
TEX = ROOT / "_build" / "latex" / "depthcore.tex"
LOG = ROOT / "_build" / "latex" / "depthcore.log"
#: At most this many pages in all, appendices included: the printed book's budget, a
#: ceiling that only falls.
MAX_PAGES = 110
#: At most this many lines of code and output printed (the verbatim blocks of the LaTeX).
MAX_PRINTED_LINES = 500
#: The widest overfull line the LaTeX log may report, in points.
MAX_OVERFULL_PT = 10.0
#: At least this many exercises.
MIN_EXERCISES = 14
VERBATIM = re.compile(r"\\begin\{sphinxVerbatim\}[^\n]*\n(.*?)\\end\{sphinxVerbatim\}", re.DOTALL)
OVERFULL = re.compile(r"Overfull \\hbox \((\d+(?:\.\d+)?)pt too wide\)")


@pytest.fixture(scope="module")
def tex(pdf) -> str:
    return TEX.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def latex_log(pdf) -> str:
    return LOG.read_text(encoding="utf-8", errors="replace")


def printed_lines(tex: str) -> list[str]:
    """Every line of code and output the PDF prints (its verbatim blocks)."""
    return [line for block in VERBATIM.findall(tex) for line in block.splitlines()]


def overfull(log: str) -> list[float]:
    """The widths by which the LaTeX log's overfull lines overrun the text, in points."""
    return [float(width) for width in OVERFULL.findall(log)]


def test_the_targets_read_what_they_measure():
    block = (
        "\\begin{sphinxVerbatim}[commandchars=\\\\\\{\\}]\nx = 1\nassert x\n\\end{sphinxVerbatim}\n"
    )
    assert printed_lines("text " + block * 2) == ["x = 1", "assert x"] * 2
    log = "Overfull \\hbox (12.5pt too wide) in paragraph\nOverfull \\hbox (0.3pt too wide)"
    assert overfull(log) == [12.5, 0.3]


def test_the_pdf_has_at_most_its_pages(pages):
    assert len(pages) <= MAX_PAGES, f"the PDF has {len(pages)} pages (at most {MAX_PAGES})"


#: The smallest text a printed figure may have, in points: the book's smallest font
#: (:data:`depthbook.style.MIN_FONT`, 9 pt) at 0.76 of its size.
MIN_PRINTED_FONT = 6.8


def printed_scale(config: str, log: str, width_pt: float, height_pt: float) -> float:
    """The scale at which the PDF prints an image ``width_pt`` by ``height_pt`` points.

    As Sphinx's ``\\sphinxincludegraphics`` does: an image wider than the figures'
    share of the text width (``\\linewidth=F\\linewidth`` in ``config``, the text of
    ``_config.yml``), or taller than its ``\\spx@image@maxheight=H\\textheight``, is
    shrunk to fit both; a smaller one keeps its size. The text's width and height are
    read from the LaTeX ``log`` (geometry's ``textwidth=...pt``, ``textheight=...pt``).
    """
    share = float(re.search(r"\\linewidth=([\d.]+)\\linewidth", config).group(1))
    tall = float(re.search(r"maxheight=([\d.]+)\\textheight", config).group(1))
    text_width = float(re.search(r"textwidth=([\d.]+)pt", log).group(1))
    text_height = float(re.search(r"textheight=([\d.]+)pt", log).group(1))
    return min(1.0, share * text_width / width_pt, tall * text_height / height_pt)


def test_finds_the_scale_at_which_an_image_prints():
    config = "{\\linewidth=0.5\\linewidth ... maxheight=0.5\\textheight}"
    log = "* textwidth=400.0pt\n* textheight=600.0pt\n"
    assert printed_scale(config, log, 400.0, 100.0) == pytest.approx(0.5)  # too wide
    assert printed_scale(config, log, 100.0, 600.0) == pytest.approx(0.5)  # too tall
    assert printed_scale(config, log, 100.0, 100.0) == 1.0


def image_sizes() -> dict[str, tuple[float, float]]:
    """Width and height in points of each figure's image the LaTeX build holds (its PDFs)."""
    sizes = {}
    for path in sorted(PDF.parent.glob("*.pdf")):
        if path != PDF:
            info = subprocess.run(
                ["pdfinfo", str(path)], capture_output=True, text=True, check=True, timeout=60
            ).stdout
            w, h = re.search(r"Page size:\s+([\d.]+) x ([\d.]+) pts", info).groups()
            sizes[path.name] = (float(w), float(h))
    return sizes


def test_every_figures_smallest_text_prints_legibly(pdf, latex_log):
    from depthbook import style

    config = (ROOT / "_config.yml").read_text(encoding="utf-8")
    sizes = image_sizes()
    assert len(sizes) >= 30, f"only {len(sizes)} images beside the LaTeX"
    small = {
        name: round(style.MIN_FONT * scale, 2)
        for name, (w, h) in sizes.items()
        if style.MIN_FONT * (scale := printed_scale(config, latex_log, w, h)) < MIN_PRINTED_FONT
    }
    assert not small, f"figures whose smallest text prints below {MIN_PRINTED_FONT} pt: {small}"


def test_the_pdf_prints_little_code_and_no_checks(tex):
    lines = printed_lines(tex)
    assert len(lines) <= MAX_PRINTED_LINES, (
        f"{len(lines)} lines of code and output printed (at most {MAX_PRINTED_LINES})"
    )
    checks = [line for line in lines if re.match(r"\s*(assert\b|glue\()", line)]
    assert not checks, f"checks or gluing printed: {checks[:3]}"


def test_every_line_and_float_fits_its_page(latex_log):
    wide = [w for w in overfull(latex_log) if w > MAX_OVERFULL_PT]
    assert not wide, f"{len(wide)} lines overrun the text by over {MAX_OVERFULL_PT} pt: {wide[:5]}"
    assert "Float too large for page" not in latex_log
    assert "There were undefined references" not in latex_log


def test_no_link_leads_to_a_page_the_pdf_leaves_out(tex):
    dangling = re.findall(r"\\hyperref\[\\detokenize\{book/api/[^}]*\}\]", tex)
    assert not dangling, f"{len(dangling)} links to API pages the PDF leaves out: {dangling[:3]}"
    assert "\\detokenize{book/api:module-summary-depthcore.kalman.ekf}" in tex


def test_the_exercises_are_many_and_their_solutions_gathered_at_the_end(plain_text):
    questions = re.findall(r"Exercise (\d+) ", plain_text.split("Solutions to the exercises")[-2])
    assert len(set(questions)) >= MIN_EXERCISES, f"{len(set(questions))} exercises in the PDF"
    before, _, gathered = plain_text.rpartition("Solutions to the exercises")
    assert "Solution to Exercise" not in before, "a solution printed under its question"
    solved = set(re.findall(r"Solution to Exercise (\d+)", gathered))
    unsolved = set(questions) - solved
    assert not unsolved, f"exercises without a printed solution: {unsolved}"


def exercise_chapters(text: str) -> dict[str, str]:
    """The chapter number of each exercise's question: that of the Exercises section before it."""
    found = {}
    for match in re.finditer(r"Exercise (\d+) ", text):
        sections = re.findall(r"\b(\d+)\.\d+ Exercises\b", text[: match.start()])
        if sections:
            found.setdefault(match.group(1), sections[-1])
    return found


def test_finds_the_chapter_of_each_exercise():
    text = "3.4 Exercises Exercise 1 ask 9.1 Other 9.2 Exercises Exercise 2 ask Exercise 3 ask"
    assert exercise_chapters(text) == {"1": "3", "2": "9", "3": "9"}


def test_each_solution_names_the_chapter_of_its_exercise(plain_text):
    before, _, gathered = plain_text.rpartition("Solutions to the exercises")
    named = dict(re.findall(r"Solution to Exercise (\d+) \(chapter (\d+)\)", gathered))
    assert named and named == exercise_chapters(before)


def test_the_proof_is_titled_and_sections_are_numbered_once(plain_text):
    assert "Proof Both densities are Gaussian" in plain_text
    assert "Proof. Both" not in plain_text
    doubled = re.findall(r"\b\d+\.\d+(?:\.\d+)? \d+\. [A-Z][a-z]+", plain_text)
    assert not doubled, f"sections numbered twice: {doubled[:3]}"


def test_notation_follows_the_model_and_reproducing_opens_the_appendices(layout_text):
    body = " ".join(layout_text.split())
    model = re.search(r"(\d+) The model and the optimal filter \d+", body)
    notation = re.search(r"(\d+) Notation \d+", body)
    assert model and notation and int(notation.group(1)) == int(model.group(1)) + 1
    assert re.search(r"VII Appendices[ .]*\d+ A Reproducing this book", body)
