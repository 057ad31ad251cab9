"""The replication article's numbers are what the code gives now, and none is typed.

``tools/article.py`` writes ``article/numbers.tex`` (every number, ``\\defval``), the
appendix's provenance table, the references, the abstract and ``article/metadata.yaml``
from the book's computations and records; ``article/article.tex`` quotes each number as
``\\val{key}``. These tests fail when a generated file differs from what the tool
writes, when the text types a number instead of quoting it, and when the metadata
leaves out a field the journal asks for or disagrees with ``CITATION.cff``. The
built PDF (its pages, its text's numbers) is checked with the built book
(``tests/book/test_article_pdf.py``).
"""

from __future__ import annotations

import datetime
import re
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from test_prose_numbers import ALLOWED, math_numbers  # noqa: E402

import article  # noqa: E402
from depthbook.provenance import environment  # noqa: E402

SOURCE = article.SOURCE.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def files() -> dict[Path, str]:
    return article.generated()


@pytest.fixture(scope="module")
def found() -> list:
    return article.numbers()


def test_the_generated_files_are_what_the_computations_give(files):
    assert set(files) == {
        article.NUMBERS,
        article.PROVENANCE,
        article.REFERENCES,
        article.ABSTRACT_TEX,
        article.METADATA,
    }
    stale = article.stale(files)
    assert not stale, f"{stale}: not what the code gives now: run `{article.COMMAND}`"


def test_the_check_fails_when_a_generated_number_drifts(files, tmp_path, monkeypatch):
    numbers = tmp_path / "numbers.tex"
    numbers.write_text(files[article.NUMBERS].replace("{6.47}", "{6.48}", 1), encoding="utf-8")
    drifted = dict(files)
    monkeypatch.setattr(article, "ROOT", tmp_path)
    assert article.stale({numbers: drifted[article.NUMBERS]}) == ["numbers.tex"]


def test_every_quoted_number_is_computed_and_has_its_provenance(files, found):
    keys = {n.key for n in found}
    used = article.used_keys(SOURCE)
    assert used, "article.tex quotes no number"
    assert not set(used) - keys
    defined = re.findall(r"\\defval\{([^}]*)\}", files[article.NUMBERS])
    quoted = set(used) | set(article.abstract_keys())
    assert set(defined) == quoted, "numbers.tex defines exactly the numbers the article quotes"
    rows = files[article.PROVENANCE]
    for n in found:
        if n.key in quoted:
            assert n.source and n.record, n.key
            named = n.source in article.TRIVIAL_SOURCES or n.key.startswith(article.VERDICT_KEYS)
            # each quoted number has a row, unless the appendix names its source once
            assert named != (article._code(n.key) in rows), f"{n.key}: its provenance"
    # the appendix says where those it leaves out come from
    for source in (*article.TRIVIAL_SOURCES, "depthbook.studies.claims.claims"):
        assert source.replace("_", r"\_") in SOURCE, source


def test_the_provenance_names_each_study_record_that_exists(found):
    records = {n.record for n in found if n.record != "computed"}
    assert any(r.startswith("study_records/") for r in records)
    for record in records:
        assert (ROOT / "depthbook" / "provenance" / record).is_file(), record
    seeded = [n for n in found if n.seed != "none"]
    assert seeded and all(n.record.startswith("study_records/") for n in seeded)


def test_the_printed_numbers_are_set_beside_ours(found):
    values = {n.key: n.text for n in found}
    # the paper's Figure 3 numbers: the printed optimal mean is Eq. (16) as printed, not Eq. (6)
    assert values["fig3-opt-paper-mean"] == values["fig3-opt-printed-mean"]
    assert values["fig3-opt-paper-mean"] != values["fig3-opt-mean"]
    assert values["fig3-opt-paper-sd"] == values["fig3-opt-paper-mean"]
    # Eq. (8): only 2 rho^2 J^-1 gives the printed SDs of the second-order filter
    for key in ("fig2", "fig3"):
        assert values[f"{key}-so-sd"] == values[f"{key}-so-paper-sd"]
        assert values[f"{key}-so-printed-sd"] != values[f"{key}-so-paper-sd"]


def latex_prose(source: str) -> str:
    """The article's prose: without comments, preamble, math, commands' arguments that are
    names (labels, references, citations, files, values) and environments' options."""
    text = article.uncommented(source)
    text = text[text.index(r"\begin{document}") :]
    text = re.sub(r"\$[^$]*\$|\\\[.*?\\\]", " ", text, flags=re.S)
    text = re.sub(
        r"\\(?:val|label|ref|cite[tp]?|input|includegraphics|code|href|begin|end|doi)"
        r"(?:\[[^\]]*\])?\{[^}]*\}(?:\{[^}]*\})?",
        " ",
        text,
    )
    text = re.sub(r"\\begin\{\w+\}\{[^}]*\}", " ", text)
    text = re.sub(r"\\(?:vspace|hspace)\{[^}]*\}|\\\\\[[^\]]*\]", " ", text)
    text = re.sub(r"\{@\{\}[^\n]*\}", " ", text)  # column specifications
    text = re.sub(r"\d+(?:\.\d+)?\\textwidth", " ", text)
    text = text.replace("~", " ").replace(r"\%", "%").replace("--", "–")
    return text


def stray_numbers(source: str) -> list[str]:
    body = latex_prose(source)
    for pattern in ALLOWED.values():
        body = re.sub(pattern, " ", body, flags=re.M)
    for quote in ('"about 1 pixel"', "``about 1 pixel''", "``about 5 pixels''"):
        body = body.replace(quote, " ")
    return [line.strip() for line in body.splitlines() if re.search(r"\d", line)]


def test_no_number_is_typed_in_the_articles_prose():
    stray = stray_numbers(SOURCE)
    assert not stray, f"article.tex: numbers typed in prose (quote them with \\val): {stray}"


def test_no_number_is_typed_in_the_articles_mathematics():
    text = article.uncommented(SOURCE)
    text = text[text.index(r"\begin{document}") :]
    maths = re.findall(r"\$([^$]*)\$", text)
    assert maths
    stray = [(n, m) for m in maths for n in math_numbers(re.sub(r"\\val\{[^}]*\}", " ", m))]
    assert not stray, f"article.tex: numbers typed in mathematics: {stray}"


def test_the_prose_scan_catches_a_typed_number():
    page = (
        "\\begin{document}\nThe EKF's SD is \\val{ekf-ratio} times too small;\n"
        "Figure 2, Eq.~(16), Theorem 1, BMVC 1990, $\\rho = 1/200$, 68~\\% interval.\n"
    )
    assert stray_numbers(page) == []
    typed = page.replace("\\val{ekf-ratio}", "5.0")
    assert len(stray_numbers(typed)) == 1 and "5.0" in stray_numbers(typed)[0]


def test_the_abstract_is_the_same_in_the_article_and_the_metadata(files):
    values = {n.key: n.text for n in article.numbers()}
    meta = yaml.safe_load(files[article.METADATA])
    assert meta["abstract"] == article.abstract(values)
    assert article.abstract(values, latex=True) in files[article.ABSTRACT_TEX]
    assert r"\input{abstract}" in SOURCE
    assert "{" not in meta["abstract"], "a number of the abstract is left unfilled"


def test_the_metadata_has_the_journals_fields_and_agrees_with_citation_cff():
    meta = yaml.safe_load(article.METADATA.read_text(encoding="utf-8"))
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    # the template's fields, in its order, and no other; its lists of one-key entries too
    assert list(meta) == list(article.TEMPLATE_FIELDS)
    for field, keys in article.TEMPLATE_FIELDS.items():
        if keys is not None:
            assert [k for item in meta[field] for k in item] == list(keys), field
    for field in ("title", "authors", "keywords", "code", "replication", "abstract", "type"):
        assert meta.get(field), f"metadata.yaml has no {field}"
    assert meta["title"] == "[Re] Filter based estimates of depth"
    assert meta["type"] == "Replication"
    assert [a["name"] for a in meta["authors"]] == [a["name"] for a in cff["authors"]]
    assert all(a["affiliations"] == "*" for a in meta["authors"])  # the contact
    code = {k: v for item in meta["code"] for k, v in item.items()}
    assert code["url"] == article.CODE_ARCHIVE and code["doi"] is None  # no invented DOI
    assert f"depthcore {cff['version']} ({cff['license']} licence" in (
        article.METADATA.read_text(encoding="utf-8")
    )
    replication = {k: v for item in meta["replication"] for k, v in item.items()}
    assert replication["bib"] == "maybank1990" and replication["doi"] == "10.5244/C.4.62"
    assert "pp. 62.1–62.6" in replication["cite"] and replication["doi"] in replication["cite"]
    assert (
        "Maybank" in replication["cite"]
        and str(cff["preferred-citation"]["year"]) in (replication["cite"])
    )
    journal = {k: v for item in meta["journal"] for k, v in item.items()}
    assert journal["name"] == "ReScience C"
    for keyword in cff["keywords"]:
        assert keyword in meta["keywords"]


def test_citation_cff_and_the_cite_page_point_to_the_article():
    cff = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    assert "[Re] Filter based estimates of depth" in cff
    cite = (ROOT / "book" / "cite.md").read_text(encoding="utf-8")
    assert "downloads/article.pdf" in cite
    intro = (ROOT / "book" / "intro.md").read_text(encoding="utf-8")
    assert "\narticle.pdf: " in intro and 'href="../downloads/article.pdf"' in intro


def test_the_references_come_from_the_books_bibliography(files):
    cited = article.cited_keys(SOURCE)
    assert "maybank1990" in cited
    for key in cited:
        assert f"\\bibitem{{{key}}}" in files[article.REFERENCES]
    with pytest.raises(ValueError, match="nowhere"):
        article.references_tex(["nowhere"])


def test_the_environment_statement_names_the_versions_and_the_processor():
    stated = environment.statement(datetime.date(2026, 1, 2))
    text = environment.sentence(stated)
    assert text.startswith("Built on 2026-01-02 with depthcore ")
    for label, version in stated["packages"].items():
        assert f"{label} {version}" in text
    assert stated["machine"]["cpu"] in text and f"Python {stated['python']}" in text
    with pytest.raises(ValueError, match="date"):
        environment.statement("2026-01-02")
    with pytest.raises(ValueError, match="statement"):
        environment.sentence({"date": "2026-01-02"})
