"""The book's pages render in JupyterLab as in the book.

Starts JupyterLab (with jupyterlab-myst, pinned in requirements.txt) on
127.0.0.1 over a copy of ``book/`` (with ``_toc.yml`` and ``_config.yml``) in a
temporary folder (so that nothing the session saves reaches the pages), opens
each page of ``PAGES`` as a notebook (jupytext) in headless Chromium, runs all
its cells, runs its text cells once more (as a reader does after "Run All"
for the few numbers that a page's text quotes above the cell that computes
them), and checks in the rendered page that

* every ``{eval}`name``` of its text shows the text that the book pastes there:
  the value glued under ``name`` in the page's reference outputs
  (``book/_nbval/<page>.ipynb``, which ``make notebooks`` checks against a fresh
  run), with no error and no role left as source;
* every reference, written ``{eval}`cite_t("key")```, ``{eval}`eq("eq-7")```,
  ``{eval}`numref("fig-2")```, ``{eval}`doc("fig5")``` (see
  :mod:`depthbook.crossref`), shows what the book shows: an equation of the
  paper its number in the paper (``tests/data/equation_labels.json``), a
  figure of the paper its number there (``tests/data/figure_numbers.json``),
  a citation its author-year text (as sphinxcontrib-bibtex writes it,
  ``tests/test_sphinx_eval.py``), a page its title, as a link;
* every glued figure (``{figure}`` of ``{eval}`name```) shows its image with
  its caption;
* no role or directive is left unknown ("Unknown Directive", "Unknown Role")
  and no citation or cross-reference unresolved, and the mathematics of every
  text cell is typeset (by KaTeX, as jupyterlab-myst does), without errors.

Each page with displayed equations, opened (without running it), numbers them
as the book does: a labelled one by its number in the paper
(``tests/data/equation_labels.json``), however many unlabelled displays
precede it on its page, and an unlabelled one not at all
(``tools/myst_roles.py`` writes the pages so); saved unchanged, it is the
same file.

It needs no built book; without Chromium it is skipped (failed under CI).
"""

from __future__ import annotations

import ast
import os
import re
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import nbformat
import pytest
from test_browser import CHROMEDRIVER, CHROMIUM, CHROMIUM_FLAGS

ROOT = Path(__file__).resolve().parents[2]
# fig2: a citation, references to equations and pages, a glued figure;
# beyond_particles: citations of every kind, equations and a figure of other pages,
# glued figures and tables; fig6: an exercise, its solution and a reference to a theorem.
PAGES = ("fig2", "beyond_particles", "fig6")
EVAL_ROLE = re.compile(r"\{eval\}`([A-Za-z_][A-Za-z0-9_]*)`")
REFERENCE = re.compile(r"\{eval\}`((\w+)\(\"([^\"`]*)\"\))`")
# A glued figure: ```{figure}, its options, {eval}`name`, a blank line, its caption.
FIGURE = re.compile(
    r"^(`{3,})\{figure\}[ \t]*\n(?::[\w-]+:[^\n]*\n)*[ \t]*\n\{eval\}`(\w+)`[ \t]*\n"
    r"(?:[ \t]*\n(.*?)\n)?^\1[ \t]*$",
    re.S | re.M,
)
# The pages with labelled equations (model and filters with unlabelled displays
# between them, marginals with unlabelled ones after them) and a page with
# unlabelled displays only.
EQUATION_PAGES = ("model", "filters", "marginals", "fig2", "fig3", "appendix", "beyond_linear")
DISPLAY = re.compile(r"^[ \t]*(?:\$\$[ \t]*$|`{3,}\{math\})", re.M)
START_TIMEOUT = 120  # seconds for JupyterLab to answer
RUN_TIMEOUT = 900  # seconds for a page's cells to run
POLL = 0.25  # seconds between two looks at JupyterLab or at the browser
SCREENSHOTS = os.environ.get("DEPTHCORE_LAB_SCREENSHOTS")  # a folder, to look at the pages


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def lab(missing_prerequisite, tmp_path_factory):
    """(base URL with token, the served folder) of a JupyterLab started for the test."""
    if CHROMIUM is None or CHROMEDRIVER is None:
        missing_prerequisite(
            "Chromium or ChromeDriver not found (apt-get install chromium "
            "chromium-driver): the pages are not checked in JupyterLab"
        )
    home = tmp_path_factory.mktemp("lab")
    # Every cell rendered, not only those scrolled into view.
    tracker = (
        home / "settings" / "@jupyterlab" / "notebook-extension" / "tracker.jupyterlab-settings"
    )
    tracker.parent.mkdir(parents=True)
    tracker.write_text('{"windowingMode": "none"}')
    served = home / "served"
    shutil.copytree(ROOT / "book", served / "book", ignore=shutil.ignore_patterns("_nbval"))
    # read by the pages' references, and by jupytext when JupyterLab saves a page
    for name in ("_toc.yml", "_config.yml", "jupytext.toml"):
        shutil.copy2(ROOT / name, served / name)
    token, port = secrets.token_hex(16), free_port()
    env = dict(
        os.environ,
        JUPYTER_PATH=str(ROOT / "tools" / "jupyter"),
        JUPYTER_PREFER_ENV_PATH="1",
        JUPYTER_CONFIG_DIR=str(home / "config"),
        JUPYTER_RUNTIME_DIR=str(home / "runtime"),
        JUPYTER_DATA_DIR=str(home / "data"),
        JUPYTERLAB_SETTINGS_DIR=str(home / "settings"),
        JUPYTERLAB_WORKSPACES_DIR=str(home / "workspaces"),
    )
    command = [
        sys.executable,
        "-m",
        "jupyterlab",
        "--no-browser",
        "--allow-root",
        "--ServerApp.ip=127.0.0.1",
        f"--ServerApp.port={port}",
        "--ServerApp.port_retries=0",
        f"--IdentityProvider.token={token}",
        f"--ServerApp.root_dir={served}",
        "--LabApp.expose_app_in_browser=True",
    ]
    log = (home / "lab.log").open("w")
    server = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            assert server.poll() is None, f"JupyterLab stopped: {(home / 'lab.log').read_text()}"
            try:
                with urllib.request.urlopen(f"{base}/api/status?token={token}", timeout=5):
                    break
            except OSError:
                assert time.monotonic() < deadline, f"JupyterLab not up in {START_TIMEOUT} s"
                time.sleep(POLL)
        yield base, token, served
    finally:
        server.terminate()
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()


@pytest.fixture(scope="module")
def driver(lab):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="depthcore-chromium-")
    flags = [f for f in CHROMIUM_FLAGS if not f.startswith("--host-resolver-rules")]
    # Only the loopback JupyterLab is reachable: nothing is fetched from a network.
    flags.append("--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1")
    for flag in [*flags, f"--user-data-dir={profile}"]:
        options.add_argument(flag)
    browser = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    browser.set_script_timeout(START_TIMEOUT)
    try:
        yield browser
    finally:
        browser.quit()
        shutil.rmtree(profile, ignore_errors=True)


def glued_texts(page: str) -> dict[str, str]:
    """The texts glued by the page's reference run, as the book pastes them."""
    nb = nbformat.read(ROOT / "book" / "_nbval" / f"{page}.ipynb", as_version=4)
    texts = {}
    for cell in nb.cells:
        for out in cell.get("outputs", []) if cell.cell_type == "code" else []:
            record = out.get("metadata", {}).get("scrapbook")
            if record and record.get("mime_prefix") and len(out["data"]) == 1:
                plain = out["data"].get(record["mime_prefix"] + "text/plain")
                if plain is not None:
                    try:
                        texts[record["name"]] = str(ast.literal_eval(plain))
                    except (SyntaxError, ValueError):
                        texts[record["name"]] = plain
    return texts


# What the scripts below share: sleep(ms), and settled(read, polls), what read() returns
# once it has returned the same (as JSON) at `polls` polls in a row, 250 ms apart.
WAITING = """
const sleep = ms => new Promise(r => setTimeout(r, ms));
const settled = async (read, polls) => {
  let last = null, value;
  for (let stable = 0; stable < polls; ) {
    await sleep(250);
    value = await read();
    const now = JSON.stringify(value);
    stable = now === last ? stable + 1 : 0;
    last = now;
  }
  return value;
};
"""


# Opens the page with jupytext's notebook view, runs all cells, waits for the
# kernel, runs the text cells again, and leaves in window.depthcoreResult each
# text cell's source, its rendered text, and what it shows of the inline
# expressions and the math (polled: a call to the browser must not last minutes).
RUN_PAGE = (
    WAITING
    + """
const path = arguments[0];
window.depthcoreResult = null;
const done = result => { window.depthcoreResult = result; };
(async () => {
  const app = window.jupyterapp;
  const panel = await app.commands.execute('docmanager:open',
                                           {path, factory: 'Jupytext Notebook'});
  await panel.context.ready;
  await panel.sessionContext.ready;
  const kernelIdle = async () => {
    while (!panel.sessionContext.session?.kernel ||
           panel.sessionContext.session.kernel.status !== 'idle') await sleep(250);
  };
  await kernelIdle();
  await app.commands.execute('notebook:run-all-cells');
  const running = () => panel.content.widgets.some(
    c => c.model.type === 'code' && c.promptNode && c.promptNode.textContent.includes('*'));
  do { await sleep(250); await kernelIdle(); } while (running());
  const errors = panel.content.widgets
    .filter(c => c.model.type === 'code')
    .flatMap(c => c.model.outputs.toJSON())
    .filter(o => o.output_type === 'error')
    .map(o => o.ename + ': ' + o.evalue);
  // Run the text cells again, one by one: the few numbers quoted above their
  // cell now evaluate.
  for (const [i, c] of panel.content.widgets.entries()) {
    if (c.model.type !== 'markdown') continue;
    panel.content.activeCellIndex = i;
    panel.content.deselectAll();
    await panel.content.scrollToItem(i);
    await app.commands.execute('notebook:run-cell');
    await kernelIdle();
  }
  // Until the text cells show the same for 2 s with the kernel idle: the numbers have landed.
  await settled(async () => {
    await kernelIdle();
    return panel.content.widgets.filter(c => c.model.type === 'markdown')
      .map(c => (c.node.querySelector('.myst') || c.node).textContent);
  }, 8);
  const cells = panel.content.widgets.filter(c => c.model.type === 'markdown').map(c => {
    const node = c.node.querySelector('.myst');  // jupyterlab-myst's rendering
    if (!node) return {source: c.model.sharedModel.getSource(), rendered: false};
    // The text without the math's own text.
    const prose = node.cloneNode(true);
    prose.querySelectorAll('.katex').forEach(e => e.remove());
    return {
      unknown: node.textContent.match(/Unknown (Directive|Role).{0,60}/g) || [],
      links: [...node.querySelectorAll('a[href]')].map(e => e.textContent),
      unresolved: [...node.querySelectorAll('[title$="Not Found"]')].map(
        e => e.title + ': ' + e.textContent),
      figures: [...node.querySelectorAll('figure')].map(f => ({
        images: [...f.querySelectorAll('img')].filter(i => i.naturalWidth > 100).length,
        // jupyterlab-myst puts the image in a caption of its own, before the caption
        caption: [...f.querySelectorAll('figcaption')].map(e => e.textContent).join(' ')
          .replace(/\\s+/g, ' '),
      })),
      source: c.model.sharedModel.getSource(),
      rendered: c.rendered,
      text: prose.textContent,
      codes: [...node.querySelectorAll('code')].map(e => e.textContent),
      errors: [...node.querySelectorAll('[data-mime-type="application/vnd.jupyter.stderr"]')]
        .map(e => e.textContent),
      math: node.querySelectorAll('.katex').length,
      mathErrors: node.querySelectorAll('.katex-error').length,
    };
  });
  done({cells, errors});
})().catch(e => done({failed: String(e)}));
"""
)


# Opens the page with jupytext's notebook view and leaves in
# window.depthcoreResult, once every text cell shows its rendering, each
# displayed equation's id and the number shown beside it (null if none); then
# saves the page.
SHOW_EQUATIONS = (
    WAITING
    + """
const path = arguments[0];
window.depthcoreResult = null;
const done = result => { window.depthcoreResult = result; };
(async () => {
  const app = window.jupyterapp;
  const panel = await app.commands.execute('docmanager:open',
                                           {path, factory: 'Jupytext Notebook'});
  await panel.context.ready;
  const text = () => panel.content.widgets.filter(c => c.model.type === 'markdown');
  while (!text().every(c => c.node.querySelector('.myst'))) await sleep(250);
  // the numbers, once they stop changing (1.5 s)
  const equations = await settled(() => text().flatMap(
    c => [...c.node.querySelectorAll('.katex-display')].map(e => {
      const display = e.parentElement.parentElement;  // jupyterlab-myst: its box, with the number
      const number = display.children[1];
      return {id: display.id, number: number ? number.textContent.trim() : null};
    })), 6);
  await panel.context.save();  // saved unchanged, as a reader may
  done({equations});
})().catch(e => done({failed: String(e)}));
"""
)


def open_lab(driver, base, token):
    """Load JupyterLab afresh in the browser and wait until it has started."""
    driver.get(f"{base}/lab?token={token}&reset")
    deadline = time.monotonic() + START_TIMEOUT
    while not driver.execute_script("return !!(window.jupyterapp && window.jupyterapp.started)"):
        assert time.monotonic() < deadline, f"JupyterLab's page not ready in {START_TIMEOUT} s"
        time.sleep(POLL)
    driver.execute_async_script("window.jupyterapp.started.then(arguments[0])")


# Closes every document of a JupyterLab already started, unless one has unsaved
# changes (closing it would ask a question); returns whether it could.
CLOSE_ALL = """
const done = arguments[0];
const app = window.jupyterapp;
if (!app) { done(false); return; }
app.started.then(() => {
  const widgets = [...app.shell.widgets('main')];
  if (widgets.some(w => w.context && w.context.model.dirty)) { done(false); return; }
  app.commands.execute('application:close-all').then(() => done(true), () => done(false));
});
"""


def reuse_lab(driver, base, token):
    """JupyterLab with no document open: the one already loaded, else loaded afresh."""
    if not driver.execute_async_script(CLOSE_ALL):
        open_lab(driver, base, token)


@pytest.mark.parametrize("page", EQUATION_PAGES)
def test_page_numbers_its_equations_as_the_book_in_jupyterlab(lab, driver, page):
    import json

    base, token, served = lab
    reuse_lab(driver, base, token)
    driver.execute_script(SHOW_EQUATIONS, f"book/{page}.md")
    deadline = time.monotonic() + START_TIMEOUT
    while (result := driver.execute_script("return window.depthcoreResult")) is None:
        assert time.monotonic() < deadline, f"{page}: not rendered in {START_TIMEOUT} s"
        time.sleep(POLL)
    assert "failed" not in result, f"{page}: {result.get('failed')}"
    paper = json.loads((ROOT / "tests" / "data" / "equation_labels.json").read_text())
    source = (ROOT / "book" / f"{page}.md").read_text(encoding="utf-8")
    labels = re.findall(r"^\$\$[ \t]*\(([^)\s]+)\)[ \t]*$", source, re.M)
    # A display opens with "$$" alone (closed by "$$ (label)") or a {math} fence.
    displays = len(DISPLAY.findall(source))
    shown = result["equations"]
    numbered = {e["id"]: e["number"] for e in shown if e["number"] is not None}
    assert numbered == {label: f"({paper[label]})" for label in labels}, (
        f"{page}: equations numbered {numbered} in JupyterLab"
    )
    assert len(shown) == displays, f"{page}: {len(shown)} displays shown of {displays}"
    if page == "beyond_linear":
        assert not labels and len(shown) >= 5, f"{page}: {len(shown)} unnumbered displays"
    # Saved unchanged, the page is the same file (jupytext.toml), front matter and all.
    saved = (served / "book" / f"{page}.md").read_text(encoding="utf-8")
    assert saved == source, f"{page}: saving the unchanged page in JupyterLab changed it"


@pytest.mark.parametrize("page", PAGES)
def test_page_renders_its_numbers_and_math_in_jupyterlab(lab, driver, page):
    base, token, served = lab
    reuse_lab(driver, base, token)
    driver.execute_script(RUN_PAGE, f"book/{page}.md")
    deadline = time.monotonic() + RUN_TIMEOUT
    while (result := driver.execute_script("return window.depthcoreResult")) is None:
        assert time.monotonic() < deadline, f"{page}: not run in JupyterLab in {RUN_TIMEOUT} s"
        time.sleep(POLL)
    if SCREENSHOTS:
        driver.save_screenshot(str(Path(SCREENSHOTS) / f"lab-{page}.png"))
    assert "failed" not in result, f"{page}: {result.get('failed')}"
    assert not result["errors"], f"{page}: cells failed in JupyterLab: {result['errors']}"

    texts = glued_texts(page)
    expected = expected_references()
    cells = result["cells"]
    assert cells and all(c["rendered"] for c in cells), f"{page}: a text cell is not rendered"
    shown, missing, references, figures = 0, [], 0, 0
    for cell in cells:
        source = cell["source"]
        assert not cell["errors"], f"{page}: expressions failed: {cell['errors']}"
        assert "{eval}" not in cell["text"] and "{glue" not in cell["text"], (
            f"{page}: a role is shown as source: {cell['text'][:200]!r}"
        )
        assert not cell["unknown"], f"{page}: not rendered: {cell['unknown']}"
        assert not cell["unresolved"], f"{page}: unresolved: {cell['unresolved']}"
        glued_figures = FIGURE.findall(source)
        for name in EVAL_ROLE.findall(source):
            if any(name == figure for _, figure, _ in glued_figures):
                continue
            assert name in texts, f"{page}: {name!r} is evaluated but never glued"
            assert name not in cell["codes"], f"{page}: {{eval}}`{name}` is not evaluated"
            if texts[name] in cell["text"]:
                shown += 1
            else:
                missing.append(f"{name} = {texts[name]}")
        for call, function, content in REFERENCE.findall(source):
            text = expected(function, content)
            assert text in cell["text"], f"{page}: {call} does not show {text!r}"
            if function == "doc":  # a link to the page, as in the book
                assert text in cell["links"], f"{page}: {call} is not a link"
            references += 1
        assert len(cell["figures"]) == len(glued_figures), (
            f"{page}: {len(glued_figures)} glued figures, {len(cell['figures'])} shown"
        )
        for (_, name, caption), figure in zip(glued_figures, cell["figures"], strict=True):
            assert figure["images"] == 1, f"{page}: figure {name!r} shows no image"
            words = " ".join(re.split(r"[${]", caption, maxsplit=1)[0].split())
            # (typographic apostrophes, as the book's too)
            assert words in figure["caption"].replace("\u2019", "'"), (
                f"{page}: figure {name!r} without its caption {words!r}: {figure['caption']!r}"
            )
            figures += 1
        if "$" in source:
            assert cell["math"] > 0, f"{page}: math not typeset in {source[:80]!r}"
        assert cell["mathErrors"] == 0, f"{page}: MathJax errors in {source[:80]!r}"
    assert not missing, f"{page}: numbers not shown: {missing}"
    assert shown >= 10, f"{page}: only {shown} numbers shown in the text"
    assert references >= 5, f"{page}: only {references} references shown"
    assert figures >= 1, f"{page}: no glued figure shown"


def expected_references():
    """``expected(function, content)``: the text that the book shows for a reference.

    The paper's equations and figures by the tables of tests/data (their
    numbers in the paper, which the built book is checked to show); the
    rest as :mod:`depthbook.crossref` resolves them, which
    ``tests/test_sphinx_eval.py`` checks against Sphinx's own rendering.
    """
    import json

    from depthbook.crossref import BookReferences, split_target

    data = ROOT / "tests" / "data"
    equations = json.loads((data / "equation_labels.json").read_text())
    figures = {
        label: f["number"]
        for label, f in json.loads((data / "figure_numbers.json").read_text()).items()
    }
    book = BookReferences(ROOT / "book")

    def expected(function, content):
        if function == "eq" and content in equations:
            return f"({equations[content]})"
        if function == "numref" and split_target(content)[1] in figures:
            explicit, label = split_target(content)
            return (explicit or "Figure %s").replace("%s", str(figures[label]))
        return getattr(book, function)(content)

    return expected
