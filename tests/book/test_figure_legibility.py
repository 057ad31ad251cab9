"""The built book's figures can be read: described, and enlarged with a click.

In ``_build/html``, every image of a figure in a page's text

* has alt text that describes it (words, not a file name);
* is a link to the image file itself, so that a click shows it at full size
  (Sphinx wraps an image given a ``:width:`` in such a link).

That each is shown full width, in a browser, is checked with the page's other
browser checks (``test_browser.py::test_figures_fill_the_text_column``).
"""

from __future__ import annotations

import html as html_lib
import re

FIGURE_RE = re.compile(r"<figure\b[^>]*>(.*?)</figure>", re.DOTALL)
IMG_RE = re.compile(r"<img\b([^>]*)>")
LINKED_IMG_RE = re.compile(r'<a\b[^>]*\bhref="([^"]+)"[^>]*>\s*<img\b([^>]*)>\s*</a>', re.DOTALL)
ATTR_RE = re.compile(r'\b(alt|src)="([^"]*)"')
#: Alt text that describes: at least this many words, and no file name.
MIN_ALT_WORDS = 8


def figure_images(html: str) -> list[str]:
    """The attribute text of every ``<img>`` inside a ``<figure>`` of a page."""
    return [attrs for body in FIGURE_RE.findall(html) for attrs in IMG_RE.findall(body)]


def test_every_figure_image_has_descriptive_alt_text(html_pages):
    bad, seen = [], 0
    for page, html in html_pages.items():
        for attrs in figure_images(html):
            seen += 1
            a = dict(ATTR_RE.findall(attrs))
            alt = html_lib.unescape(a.get("alt", ""))
            path_like = re.search(r"[\\/]|\.(png|svg|jpe?g|pdf)\b", alt)
            if len(alt.split()) < MIN_ALT_WORDS or path_like:
                bad.append((page, a.get("src"), alt[:60]))
    assert seen, "no figure image found in _build/html"
    assert not bad, f"figure images without descriptive alt text: {bad}"


def test_every_figure_image_links_to_its_full_size_file(html_pages, html_dir):
    bad = []
    for page, html in html_pages.items():
        for body in FIGURE_RE.findall(html):
            linked = {img: href for href, img in LINKED_IMG_RE.findall(body)}
            for attrs in IMG_RE.findall(body):
                src = dict(ATTR_RE.findall(attrs)).get("src", "")
                href = linked.get(attrs)
                target = (html_dir / page).parent / (href or "")
                if href is None or href != src or not target.resolve().is_file():
                    bad.append((page, src, href))
    assert not bad, f"figure images not linked to their full-size file: {bad}"
