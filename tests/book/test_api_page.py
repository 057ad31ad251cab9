"""The book's API reference documents every public module of depthcore, one page each.

``book/api.md`` lists the modules with the first paragraph of each docstring,
and ``book/api/<name>.md`` renders, through Sphinx autodoc, one module: a
``py:module`` target (``id="module-depthcore.<name>"``) followed by the
module's documented functions and classes. The pages document the modules of
``depthcore.MODULES``, in its order: the package's module map, family by family,
which the page "Using depthcore" (``book/using.md``) generates from the same list.
The docstrings' formulas are typeset (MathJax), and no reST markup is shown raw.
"""

from __future__ import annotations

import re

from conftest import ROOT, toc_pages

import depthcore

RAW_ROLE_RE = re.compile(r":(math|func|class|mod|data|meth|attr):`")
AUTOMODULE_RE = re.compile(r"^\.\. automodule:: (\S+)$", re.MULTILINE)


def api_modules() -> list[str]:
    """The modules the API pages document (their ``automodule`` directives), in TOC order."""
    pages = [p for p in toc_pages() if p.startswith("book/api/")]
    return [
        name
        for page in pages
        for name in AUTOMODULE_RE.findall((ROOT / f"{page}.md").read_text(encoding="utf-8"))
    ]


def page_html(html_dir, page: str) -> str:
    path = html_dir / f"{page}.html"
    assert path.exists(), f"{page}.html is missing from the built book"
    return path.read_text(encoding="utf-8")


def test_module_pages_follow_the_packages_module_map():
    documented = api_modules()
    missing = [name for name in depthcore.MODULES if name not in documented]
    assert not missing, f"the API pages do not document {missing}"
    assert documented == list(depthcore.MODULES), (
        "the API pages are not in depthcore.MODULES' order"
    )


def test_each_module_page_documents_its_module_and_members(html_dir):
    for name in depthcore.MODULES:
        html = page_html(html_dir, f"book/api/{name}")
        assert f'id="module-depthcore.{name}"' in html, f"depthcore.{name} is not documented"
        assert re.search(rf'<dt class="sig[^"]*" id="depthcore\.{name}\.\w+', html), (
            f"depthcore.{name} is documented without any of its members"
        )


def test_the_api_page_lists_every_module_with_its_summary(html_dir):
    html = page_html(html_dir, "book/api")
    for name in depthcore.MODULES:
        assert f'href="api/{name}.html#module-depthcore.{name}"' in html, (
            f"book/api.html does not link depthcore.{name}"
        )


def test_api_pages_render_their_markup_and_mathematics(html_dir):
    typeset = 0
    for page in ["book/api"] + [f"book/api/{name}" for name in depthcore.MODULES]:
        html = page_html(html_dir, page)
        text = re.sub(r"<[^>]+>", "", html)
        raw = sorted(set(RAW_ROLE_RE.findall(text)))
        assert not raw, f"{page}.html shows raw Sphinx roles: {raw}"
        typeset += html.count('<span class="math notranslate nohighlight">')
    assert 'id="depthcore.problem.gaussian.paper_prior"' in page_html(html_dir, "book/api/gaussian")
    # the docstrings' formulas: hundreds of them, typeset
    assert typeset > 300, f"only {typeset} formulas typeset on the API pages"
    assert r"\rho ^{2} J^{-1}" in page_html(html_dir, "book/api/second_order")
