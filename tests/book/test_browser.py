"""The built book renders in a browser with no network.

Opens the ``file://`` pages of ``_build/html`` in headless Chromium (Debian's
``chromium`` and ``chromium-driver``) with every host name unresolvable, and
checks that

* each page of ``_toc.yml`` loads, fetches nothing over the network, and has
  its mathematics typeset by MathJax (served from the book's own
  ``_static/mathjax``, see ``sphinx-mathjax-offline`` in ``_config.yml``);
* every image of each page is shown, and each page of
  ``tests/data/figure_pages.json`` shows images and at least one table;
* every figure image fills its figure, at least as wide as the width
  ``tests/test_legibility.py`` assumes when it measures the figures' smallest
  text, from an image at least that wide (never enlarged from a smaller one);
* at 1280 px no display equation is cut off, and, narrowed to a phone's width,
  no page is wider than the phone and every table too wide scrolls in its own
  box (a page narrowed is laid out as one loaded on a phone: checked on three
  pages with wide tables).

Without Chromium the browser tests are skipped, except under CI, where a
missing browser is a failure. The check that the HTML asks no CDN for MathJax
needs no browser.
"""

from __future__ import annotations

import contextlib
import json
import re
import shutil
import sys
import tempfile
from pathlib import Path

import pytest
from conftest import ROOT

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_legibility import CONTENT_WIDTH_PX  # noqa: E402

CHROMIUM = next(
    (
        p
        for p in (
            "/usr/bin/chromium",
            shutil.which("chromium") or "",
            shutil.which("chromium-browser") or "",
        )
        if p and Path(p).exists()
    ),
    None,
)
CHROMEDRIVER = next(
    (
        p
        for p in ("/usr/bin/chromedriver", shutil.which("chromedriver") or "")
        if p and Path(p).exists()
    ),
    None,
)
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--window-size=1280,1024",
    # No name resolves: anything fetched from a host would fail.
    "--host-resolver-rules=MAP * ~NOTFOUND",
)
MATHJAX_SRC_RE = re.compile(r'<script[^>]*src="([^"]*mathjax[^"]*)"', re.IGNORECASE)
LOAD_TIMEOUT = 60  # seconds for a page and its typesetting


@pytest.fixture(scope="module")
def browser(missing_prerequisite):
    if CHROMIUM is None or CHROMEDRIVER is None:
        missing_prerequisite(
            "Chromium or ChromeDriver not found (apt-get install chromium "
            "chromium-driver): browser checks of the built book not run"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    options.set_capability("goog:loggingPrefs", {"performance": "ALL"})
    profile = tempfile.mkdtemp(prefix="depthcore-chromium-")
    for flag in CHROMIUM_FLAGS + (f"--user-data-dir={profile}",):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(LOAD_TIMEOUT)
    driver.set_script_timeout(LOAD_TIMEOUT)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def open_page(driver, html_dir: Path, page: str, reuse: bool = False) -> None:
    """Load ``page`` in ``driver``; with ``reuse``, keep it when it is the page already shown."""
    path = html_dir / f"{page}.html"
    assert path.exists(), f"{path} not built"
    if reuse and driver.current_url == path.as_uri():
        return
    driver.get_log("performance")  # drop the previous page's events
    driver.get(path.as_uri())


def network_requests(driver) -> list[str]:
    """Network URLs the page requested (from Chrome's network log)."""
    urls = []
    for entry in driver.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    return [url for url in urls if url.split(":", 1)[0] in ("http", "https", "ws", "wss", "ftp")]


def wait_for_mathjax(driver) -> dict:
    """Wait for MathJax's first typesetting; return counts of math and of its output."""
    return driver.execute_async_script(
        """
        const done = arguments[arguments.length - 1];
        const counts = () => done({
            loaded: typeof window.MathJax === 'object' && !!MathJax.startup,
            math: document.querySelectorAll('.math').length,
            typeset: document.querySelectorAll('mjx-container').length,
            errors: document.querySelectorAll('mjx-merror').length,
        });
        if (!document.querySelector('.math')) { counts(); return; }
        const t0 = Date.now();
        (function poll() {
            if (window.MathJax && MathJax.startup && MathJax.startup.promise) {
                MathJax.startup.promise.then(counts, counts);
            } else if (Date.now() - t0 > 30000) {
                counts();
            } else {
                setTimeout(poll, 100);
            }
        })();
        """
    )


def test_mathjax_is_served_from_the_book(html_pages, html_dir):
    with_math = [page for page, html in html_pages.items() if 'class="math' in html]
    assert with_math, "no page of the built book has math"
    for page, html in html_pages.items():
        sources = MATHJAX_SRC_RE.findall(html)
        if page in with_math:
            assert sources, f"{page} has math but loads no MathJax"
        for src in sources:
            assert not re.match(r"(https?:)?//", src), f"{page} loads MathJax from {src}"
            # Sphinx may append a cache-busting "?v=<checksum>" to the path
            target = (html_dir / page).parent / src.split("?", 1)[0].split("#", 1)[0]
            assert target.resolve().is_file(), f"{src} (from {page}) is not in the built book"


PHONE = (390, 844)  # a phone's window, in CSS pixels
# What a narrow window shows of each page: its width, and each table too wide for its box
# that neither it nor its parent scrolls (or that is wider than the window).
PHONE_LAYOUT = """
const done = arguments[arguments.length - 1];
requestAnimationFrame(() => requestAnimationFrame(() => {  // the layout after a resize
  const scrolls = el => ['auto', 'scroll'].includes(getComputedStyle(el).overflowX);
  const tables = Array.from(document.querySelectorAll('article table'));
  const wide = tables
    .filter(t => t.scrollWidth > t.clientWidth + 1
                 || t.getBoundingClientRect().right > window.innerWidth)
    .filter(t => !(scrolls(t) || scrolls(t.parentElement))
                 || t.clientWidth > window.innerWidth)
    .map(t => t.textContent.trim().slice(0, 40));
  done({
    page: document.documentElement.scrollWidth, window: window.innerWidth, wide: wide,
    boxes: tables.map(t => [
      t.clientWidth, t.scrollWidth, Math.round(t.getBoundingClientRect().right)]),
  });
}));
"""


@contextlib.contextmanager
def phone_window(driver):
    """The browser's window at a phone's size (``PHONE``), then restored."""
    size = driver.get_window_size()
    driver.set_window_size(*PHONE)
    try:
        yield
    finally:
        driver.set_window_size(size["width"], size["height"])


def narrowed_to_a_phone(driver) -> dict:
    """The phone's layout of the page shown (``PHONE_LAYOUT``), the window then restored."""
    with phone_window(driver):
        return driver.execute_async_script(PHONE_LAYOUT)


#: Pages with tables wider than a phone, and their mathematics.
PHONE_PAGES = ("book/fig2", "book/beyond_filters", "book/beyond_particles", "book/beyond_hard")


class PageChecks:
    """The browser's checks of one page, one after the other in one browser.

    The first loads the page at 1280 px (``CHROMIUM_FLAGS``); the others read
    the page it loaded (``open_page(..., reuse=True)``), the last narrowed to
    a phone's width. ``TestPagesA`` and ``TestPagesB`` run them on every other
    page of ``_toc.yml`` each (``pages``, read by ``conftest.py``), and the
    comparison of a narrowed page with one loaded on a phone on every other
    page of :data:`PHONE_PAGES`, so that ``pytest -n 2 --dist loadscope``
    runs the two halves side by side, each in a browser of its own.
    """

    def test_page_typesets_its_math_offline(self, browser, html_dir, toc_page):
        open_page(browser, html_dir, toc_page)
        counts = wait_for_mathjax(browser)
        if counts["math"]:
            assert counts["loaded"], f"MathJax did not load on {toc_page}.html"
            assert counts["typeset"] >= counts["math"], (
                f"{toc_page}.html: {counts['typeset']} MathJax outputs "
                f"for {counts['math']} math elements"
            )
            assert counts["errors"] == 0, f"{toc_page}.html: {counts['errors']} MathJax errors"
        assert network_requests(browser) == []

    def test_page_shows_its_images_and_a_figure_page_a_table(
        self, browser, html_dir, toc_page, figure_page_names
    ):
        # The page test_page_typesets_its_math_offline loaded (and checked for network requests).
        open_page(browser, html_dir, toc_page, reuse=True)
        wait_for_mathjax(browser)
        images = browser.execute_script(
            "return Array.from(document.querySelectorAll('main img, article img'))"
            ".map(img => [img.getAttribute('src').slice(0, 80), img.complete, img.naturalWidth]);"
        )
        broken = [src for src, complete, width in images if not complete or width == 0]
        assert not broken, f"{toc_page}.html: images not shown: {broken}"
        if toc_page in figure_page_names:
            assert images, f"{toc_page}.html has no image"
            tables = browser.execute_script(
                "return document.querySelectorAll('main table, article table').length;"
            )
            source = (ROOT / f"{toc_page}.md").read_text(encoding="utf-8")
            if re.search(r"^\| *-{3,}", source, re.MULTILINE):  # the page has a pipe table
                assert tables >= 1, f"{toc_page}.html has no table"

    def test_figures_fill_the_text_column(self, browser, html_dir, toc_page, figure_page_names):
        # Every figure image fills its figure, at least as wide as the width
        # tests/test_legibility.py assumes when it measures the figures' smallest text, from an
        # image at least that wide (never enlarged from a smaller one).
        open_page(browser, html_dir, toc_page, reuse=True)
        wait_for_mathjax(browser)
        images = browser.execute_script(
            """
            return Array.from(document.querySelectorAll('article figure img')).map(img => {
                const figure = img.closest('figure');
                const style = getComputedStyle(figure);
                return {
                    src: img.getAttribute('src').slice(-20),
                    width: img.getBoundingClientRect().width,
                    figure: figure.clientWidth - parseFloat(style.paddingLeft)
                            - parseFloat(style.paddingRight),
                    natural: img.naturalWidth,
                };
            });
            """
        )
        if toc_page in figure_page_names:
            assert images, f"{toc_page}.html shows no figure"
        for image in images:
            assert image["width"] == pytest.approx(image["figure"], abs=1.5), (toc_page, image)
            assert image["width"] >= CONTENT_WIDTH_PX - 1, (
                f"{toc_page}.html: a figure shown {image['width']:.0f} px wide, narrower than "
                f"the {CONTENT_WIDTH_PX:g} px the legibility test assumes: {image}"
            )
            assert image["natural"] >= image["width"], (toc_page, image)

    def test_equations_fit_or_scroll_in_their_own_box(self, browser, html_dir, toc_page):
        # At 1280 px (CHROMIUM_FLAGS), a display equation wider than the text
        # column scrolls inside its own box, so that none is cut off. The page
        # test_page_typesets_its_math_offline loaded at that width is read again.
        open_page(browser, html_dir, toc_page, reuse=True)
        wait_for_mathjax(browser)
        cut = browser.execute_script(
            """
            const scrolls = el => ['auto', 'scroll'].includes(getComputedStyle(el).overflowX);
            const selector = 'article div.math mjx-container[display="true"]';
            return Array.from(document.querySelectorAll(selector))
              .filter(c => c.scrollWidth > c.clientWidth + 1
                           && !scrolls(c) && !scrolls(c.parentElement))
              .map(c => c.parentElement.id || c.textContent.slice(0, 40));
            """
        )
        assert not cut, f"{toc_page}.html: equations cut off at 1280 px: {cut}"

    def test_tables_scroll_inside_themselves_on_a_phone(self, browser, html_dir, toc_page):
        # The page that test_page_typesets_its_math_offline loaded and typeset, narrowed to a
        # phone's width (laid out as loaded there: test_a_page_narrowed_to_a_phone_...).
        open_page(browser, html_dir, toc_page, reuse=True)
        wait_for_mathjax(browser)
        widths = narrowed_to_a_phone(browser)
        assert widths["page"] <= widths["window"], (
            f"{toc_page}.html is wider than a phone's screen: {widths}"
        )
        assert not widths["wide"], (
            f"{toc_page}.html: tables that run off a phone's screen: {widths['wide']}"
        )

    def test_a_page_narrowed_to_a_phone_is_laid_out_as_one_loaded_there(
        self, browser, html_dir, phone_page
    ):
        # Media queries apply to the narrowed window as to a page loaded in it, and MathJax 3
        # breaks no line by the width: the phone check of every page narrows the page loaded.
        open_page(browser, html_dir, phone_page)
        wait_for_mathjax(browser)
        narrowed = narrowed_to_a_phone(browser)
        with phone_window(browser):
            open_page(browser, html_dir, phone_page)
            wait_for_mathjax(browser)
            loaded = browser.execute_async_script(PHONE_LAYOUT)
        assert narrowed["boxes"], f"{phone_page}.html: no table"
        assert narrowed == loaded, (
            f"{phone_page}.html narrowed to a phone: {narrowed}; loaded on one: {loaded}"
        )


class TestPagesA(PageChecks):
    pages = slice(0, None, 2)


class TestPagesB(PageChecks):
    pages = slice(1, None, 2)
