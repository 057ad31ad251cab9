"""The book's API reference documents every public module of depthcore.

``book/api.md`` renders, through Sphinx autodoc, one section per module of
``depthcore.MODULES``; each section is a ``py:module`` target
(``id="module-depthcore.<name>"``) followed by that module's documented
functions and classes. The page's mathematics (``.. math::`` and ``:math:``
in the docstrings) is rendered, not shown as raw markup.
"""

from __future__ import annotations

import re

import depthcore

RAW_ROLE_RE = re.compile(r":(math|func|class|mod|data|meth|attr):`")


def api_html(html_dir) -> str:
    path = html_dir / "book" / "api.html"
    assert path.exists(), "book/api.html is missing from the built book"
    return path.read_text(encoding="utf-8")


def test_api_page_documents_every_public_module(html_dir):
    html = api_html(html_dir)
    for name in depthcore.MODULES:
        assert f'id="module-depthcore.{name}"' in html, f"depthcore.{name} is not documented"
        # At least one documented member of the module (a function, class or data).
        assert re.search(rf'<dt class="sig[^"]*" id="depthcore\.{name}\.\w+', html), (
            f"depthcore.{name} is documented without any of its members"
        )


def test_api_page_renders_its_markup(html_dir):
    html = api_html(html_dir)
    text = re.sub(r"<[^>]+>", "", html)
    raw = sorted(set(RAW_ROLE_RE.findall(text)))
    assert not raw, f"book/api.html shows raw Sphinx roles: {raw}"
    assert 'id="depthcore.gaussian.paper_prior"' in html
