"""The book's API reference documents every public module of depthcore, a page per family.

``book/api.md`` lists every module of ``depthcore.MODULES`` (read from the
package's folders) with the first paragraph of its docstring, and
``book/api/<family>.md`` renders, through Sphinx autodoc, the family's package
and each of its modules: a ``py:module`` target (``id="module-depthcore.<path>"``)
followed by the module's documented functions and classes. Nothing is listed by
hand: the pages follow the package. The docstrings' formulas are typeset
(MathJax), and no reST markup is shown raw.
"""

from __future__ import annotations

import re

from conftest import toc_pages

import depthcore

RAW_ROLE_RE = re.compile(r":(math|func|class|mod|data|meth|attr):`")


def family_of(module: str) -> str:
    """``depthcore.exact.optimal`` -> ``exact``."""
    return module.split(".")[1]


#: The families' pages, in the house's order (that of depthcore.MODULES): the subpackages and
#: the one shared module.
FAMILIES = list(dict.fromkeys(family_of(m) for m in depthcore.MODULES))


def page_html(html_dir, page: str) -> str:
    path = html_dir / f"{page}.html"
    assert path.exists(), f"{page}.html is missing from the built book"
    return path.read_text(encoding="utf-8")


def test_family_pages_follow_the_house():
    pages = [p.removeprefix("book/api/") for p in toc_pages() if p.startswith("book/api/")]
    assert pages == [*FAMILIES, "depthbook"]
    assert FAMILIES == list(depthcore.SUBPACKAGES)


def test_each_module_is_documented_with_its_members_on_its_familys_page(html_dir):
    for name in depthcore.MODULES:
        html = page_html(html_dir, f"book/api/{family_of(name)}")
        assert f'id="module-{name}"' in html, f"{name} is not documented"
        if name.count(".") > 1:
            assert re.search(rf'<dt class="sig[^"]*" id="{re.escape(name)}\.\w+', html), (
                f"{name} is documented without any of its members"
            )


def test_the_api_page_lists_every_module_with_its_summary(html_dir):
    html = page_html(html_dir, "book/api")
    for name in depthcore.MODULES:
        assert f'href="api/{family_of(name)}.html#module-{name}"' in html, (
            f"book/api.html does not link {name}"
        )


def test_api_pages_render_their_markup_and_mathematics(html_dir):
    typeset = 0
    for page in ["book/api"] + [f"book/api/{name}" for name in FAMILIES]:
        html = page_html(html_dir, page)
        text = re.sub(r"<[^>]+>", "", html)
        raw = sorted(set(RAW_ROLE_RE.findall(text)))
        assert not raw, f"{page}.html shows raw Sphinx roles: {raw}"
        typeset += html.count('<span class="math notranslate nohighlight">')
    assert 'id="depthcore.problem.gaussian.paper_prior"' in page_html(html_dir, "book/api/problem")
    # the docstrings' formulas: hundreds of them, typeset
    assert typeset > 300, f"only {typeset} formulas typeset on the API pages"
    assert r"\rho ^{2} J^{-1}" in page_html(html_dir, "book/api/kalman")


def test_the_books_own_package_has_a_page_of_its_own(html_dir):
    html = page_html(html_dir, "book/api/depthbook")
    for name in (
        "depthbook",
        "depthbook.paper",
        "depthbook.reference",
        "depthbook.provenance.records",
        "depthbook.studies.verdicts",
    ):
        assert f'id="module-{name}"' in html, f"{name} is not documented"
