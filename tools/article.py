"""Write and build the replication article "[Re] Filter based estimates of depth".

The article's text is ``article/article.tex``, written by hand: every number in
it is a macro ``\\val{key}``. This tool writes the files it reads, each from the
computations and records the book uses (no study is computed here; the Monte
Carlo studies are read from their records, the timings from the benchmarks'):

* ``article/numbers.tex``: ``\\defval{key}{text}`` for every number (:func:`numbers`);
* ``article/provenance.tex``: the appendix's table, each number's function,
  arguments, seed and record;
* ``article/references.tex``: the cited entries of ``book/references.bib``;
* ``article/metadata.yaml``: the journal's metadata, from ``CITATION.cff`` and the
  abstract (:func:`metadata`).

``write`` (the default) rewrites them; ``--check`` changes nothing and fails when
any differs from what the code gives now; ``build`` checks them, then typesets
the article with the book's figures 2-6 (vector PDF, from
:func:`depthbook.paper.save_all`) and the environment statement of
:mod:`depthbook.provenance.environment`, written as the build runs, into
``OUT/article.pdf``.

Usage: ``python tools/article.py [--check]``,
``python tools/article.py build --figures DIR --out DIR``.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import readme  # noqa: E402  (the README's numbers: the same computations, shared)

from depthbook import beyond_atlas, formatting, paper, reference  # noqa: E402
from depthbook import claims as claims_chapter  # noqa: E402
from depthbook.provenance import environment, records  # noqa: E402
from depthbook.studies import claims  # noqa: E402
from depthcore import SCENARIOS, Gaussian, __version__  # noqa: E402
from depthcore.exact import optimal  # noqa: E402
from depthcore.kalman import second_order  # noqa: E402
from depthcore.problem import model  # noqa: E402
from depthcore.problem.scenarios import REPORTED_DECIMALS, SCAN_TEXT  # noqa: E402
from depthcore.studies import monte_carlo, reproduce  # noqa: E402

ARTICLE = ROOT / "article"
SOURCE = ARTICLE / "article.tex"
NUMBERS = ARTICLE / "numbers.tex"
PROVENANCE = ARTICLE / "provenance.tex"
REFERENCES = ARTICLE / "references.tex"
ABSTRACT_TEX = ARTICLE / "abstract.tex"
METADATA = ARTICLE / "metadata.yaml"
BIB = ROOT / "book" / "references.bib"
#: What the command line says when a generated file is not what this writes.
COMMAND = "python tools/article.py"
#: The figures the article shows, drawn at the size it prints them
#: (:func:`depthbook.paper.save_print`), as vector PDF.
FIGURES = tuple(f"print-figure{SCENARIOS[key].figure}.pdf" for key in SCENARIOS)
#: The Monte Carlo study of the coverage, as book/beyond_study.md reads it from its record.
STUDY = readme.intro.COVERAGE_STUDY
#: The noise levels of the small-noise limit of Eq. (8) (book/discrepancies.md).
LIMIT_RHO = 1e-5
#: The broad prior's covariance scale of that limit.
LIMIT_PRIOR = 1e8
#: Where the article's code and its book live, as the metadata names them.
CODE_ARCHIVE = "downloads/depthcore.tar.gz"
BOOK_ROUTE = "the book's page discrepancies.html"


@dataclass(frozen=True)
class Number:
    """One number of the article: its text and where it comes from."""

    key: str
    text: str
    source: str
    arguments: str = ""
    seed: str = "none"
    record: str = "computed"


def _sci(x: float, digits: int = 0) -> str:
    """``x`` in LaTeX's scientific notation: ``10^{-8}``, ``1.2\\times 10^{-5}``."""
    mantissa, _, exponent = formatting.sci(x, digits).partition("e")
    return f"10^{{{exponent}}}" if mantissa == "1" else f"{mantissa}\\times 10^{{{exponent}}}"


def plain(text: str) -> str:
    """A number's LaTeX text as plain text: ``10^{-8}`` as ``1e-8``, ``\\%`` as ``%``."""
    text = re.sub(r"^10\^\{(-?\d+)\}$", r"1e\1", text)
    text = re.sub(r"^(.*)\\times 10\^\{(-?\d+)\}$", r"\1e\2", text)
    return text.replace("\\%", "%")


def _record_name(run) -> str:
    return f"study_records/{run.path.name}"


def _benchmark(name: str) -> str:
    return f"benchmark_records/{name}.json"


def paper_numbers() -> list[Number]:
    """The printed numbers beside ours (Figures 2-6), Theorem 1 and the print's errors."""
    out = []
    comparison = "studies.reproduce.comparison"
    for key in SCENARIOS:
        s = SCENARIOS[key]
        rows = {row["id"]: row for row in reproduce.comparison(key)}
        for rid in ("opt", "opt_printed", "so", "so_printed", "ekf"):
            row = rows[rid]
            name = f"{key}-{rid.replace('_', '-')}"
            for field in ("mean", "sd"):
                out.append(
                    Number(
                        f"{name}-{field}",
                        f"{row[field]:.2f}",
                        comparison,
                        f'"{key}", row "{rid}" ({s.quantity})',
                    )
                )
                if row[f"reported_{field}"] is not None:
                    out.append(
                        Number(
                            f"{name}-paper-{field}",
                            f"{row[f'reported_{field}']:.{REPORTED_DECIMALS}f}",
                            "problem.scenarios.REPORTED",
                            f'"{key}" (the paper\'s text)',
                        )
                    )
    scan_mean, scan_sd = SCAN_TEXT["fig3"]["optimal"]["depth"]
    out.append(Number("fig3-scan-mean", scan_mean, "problem.scenarios.SCAN_TEXT", '"fig3"'))

    p = readme.paper_texts()
    out += [
        Number("matched", p["matched"], "tools/readme.py paper_texts", "Figures 2 and 3"),
        Number("printed", p["printed"], "tools/readme.py paper_texts", "Figures 2 and 3"),
        Number(
            "theorem-tol",
            _sci(readme.THEOREM_TOL),
            "kalman.ekf.run, kalman.second_order.run",
            "Figures 2 and 3 with the prior mean G^-2 c",
        ),
    ]

    found = claims.claims()
    count = claims_chapter.counts(found)
    for verdict, name in (
        ("all", "all"),
        (claims.AS_PRINTED, "as-printed"),
        (claims.AFTER_CORRECTION, "after"),
        (claims.PRINTED_FORMULA, "formula"),
        (claims.NOT_REPRODUCED, "not"),
        (claims.NOT_CHECKABLE, "unchecked"),
    ):
        out.append(Number(f"claims-{name}", f"{count[verdict]}", "studies.claims.claims", ""))
    by_key = {c.key: c for c in found}
    for key in ("fig2", "fig3"):
        for rid in ("opt", "so", "ekf"):
            both = [by_key[f"{key}-{rid}-{moment}"].verdict for moment in ("mean", "sd")]
            short = [claims_chapter.SHORT[v] for v in both]
            text = short[0] if short[0] == short[1] else f"mean {short[0]}; SD {short[1]}"
            out.append(Number(f"row-{key}-{rid}", text, "studies.claims.claims", key))
    pages = {s.figure: key for key, s in SCENARIOS.items()}
    for item in claims.figure_verdicts(found):
        words = item.split()
        if item == "Theorem 1":
            key = "appendix"
        elif words[0] == "Figure" and int(words[1]) in pages:
            key = pages[int(words[1])]
        else:
            continue
        text = claims_chapter.item_summary(found, item)
        out.append(Number(f"verdict-{key}", text, "studies.claims.claims", item))

    fig2, fig3 = SCENARIOS["fig2"], SCENARIOS["fig3"]
    broad = Gaussian(fig2.prior.mean, LIMIT_PRIOR * np.eye(3))
    sd_o = optimal.run(fig2.mu, LIMIT_RHO, broad.mean, broad.cov).depth_sd
    sd_d = second_order.run(fig2.mu, LIMIT_RHO, broad.mean, broad.cov).marginal("y")[1]
    sd_p = second_order.run(fig2.mu, LIMIT_RHO, broad.mean, broad.cov, reading="printed").marginal(
        "y"
    )[1]
    limit_args = f"fig2's bearings, rho = {formatting.sci(LIMIT_RHO, 0)}, prior cov 1e8 I"
    out += [
        Number("limit-rho", _sci(LIMIT_RHO), "tools/article.py LIMIT_RHO"),
        Number(
            "limit-derived",
            f"{sd_o / sd_d:.4f}",
            "exact.optimal.run / second_order.run",
            limit_args,
        ),
        Number(
            "limit-printed",
            f"{sd_o / sd_p:.4f}",
            "exact.optimal.run / second_order.run(reading='printed')",
            limit_args,
        ),
    ]

    with readme._records_required():
        for key, s in (("fig2", fig2), ("fig3", fig3)):
            run = records.recorded(reference.grid_moments, s.mu, s.rho, s.prior)
            exact = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
            assert abs(run.result.depth_mean - exact.depth_mean) < 1e-9
            out.append(
                Number(
                    f"{key}-brute-mean",
                    f"{run.result.depth_mean:.2f}",
                    "analysis.reference.grid_moments",
                    f'SCENARIOS["{key}"]: mu, rho, prior',
                    record=_record_name(run),
                )
            )
            out.append(
                Number(
                    f"{key}-brute-evaluations",
                    f"{run.result.n_evaluations:,}",
                    "analysis.reference.grid_moments",
                    f'SCENARIOS["{key}"]: mu, rho, prior',
                    record=_record_name(run),
                )
            )
    behind = optimal.run(
        fig3.mu, fig3.rho, fig3.prior.mean, fig3.prior.cov, support="all"
    ).prob_behind_camera
    out.append(
        Number(
            "fig3-behind",
            _sci(behind, 1),
            "exact.optimal.run(support='all')",
            '"fig3"',
        )
    )

    for k in (200, 500):
        out.append(
            Number(
                f"px-{k}",
                f"{model.noise_in_pixels(1 / k):.2f}",
                "problem.model.noise_in_pixels",
                f"rho = 1/{k}",
            )
        )
    out.append(
        Number(
            "px-ratio",
            f"{model.noise_in_pixels(1 / 500):.1f}",
            "problem.model.noise_in_pixels",
            "rho = 1/500, against the paper's 1 pixel",
        )
    )

    moments2 = reproduce.filter_moments(fig2)
    moments6 = reproduce.filter_moments(SCENARIOS["fig6"])
    moments5 = reproduce.filter_moments(SCENARIOS["fig5"])
    prior_shift = SCENARIOS["fig6"].prior.mean[1] - fig2.prior.mean[1]
    for name, short in (("optimal", "opt"), ("second_order", "so"), ("ekf", "ekf")):
        shift = moments6[name][0] - moments2[name][0]
        out.append(
            Number(
                f"shift-{short}",
                f"{abs(shift):.2f}" if name == "ekf" else f"{abs(shift):.4f}",
                "studies.reproduce.filter_moments",
                '"fig6" minus "fig2"',
            )
        )
    out.append(Number("prior-shift", f"{prior_shift:.0f}", "problem.scenarios.SCENARIOS", "fig6"))
    out.append(
        Number(
            "ekf-ratio",
            p["ekf_ratio"],
            "studies.reproduce.filter_moments",
            '"fig2": optimal SD / EKF SD',
        )
    )
    for key, m in (("fig2", moments2), ("fig5", moments5)):
        out.append(
            Number(
                f"{key}-so-ratio",
                f"{m['second_order'][1] / m['optimal'][1]:.2f}",
                "studies.reproduce.filter_moments",
                f'"{key}": second-order SD / optimal SD',
            )
        )
    assert moments5["second_order"][1] / moments5["optimal"][1] > (
        moments2["second_order"][1] / moments2["optimal"][1]
    )
    assert abs(moments6["ekf"][0] - moments2["ekf"][0]) > 0.75 * prior_shift
    # the abstract: the EKF's depth SD under a third of the optimal one on every figure of
    # the depth; the second-order SD over 0.7 of it on Figure 2, under a fifth on Figure 3
    moments3 = reproduce.filter_moments(SCENARIOS["fig3"])
    for m in (moments2, moments3, moments5, moments6):
        assert m["ekf"][1] < m["optimal"][1] / 3
    assert moments2["second_order"][1] > 0.7 * moments2["optimal"][1]
    assert moments3["second_order"][1] < 0.2 * moments3["optimal"][1]
    return out


def extension_numbers(bench: dict) -> list[Number]:
    """The extensions in numbers: coverage, the Cramér–Rao bound, the cost (from records)."""
    fig2 = SCENARIOS["fig2"]
    with readme._records_required():
        run = records.recorded(monte_carlo.study, fig2.c, fig2.rho, **STUDY)
    texts = formatting.study_texts(run.result, "sp")
    study_args = f"Figure 2's c, rho = 1/200, trials={STUDY['trials']}, prior='paper'"
    seed = f"{STUDY['seed']}"
    out = [
        Number(
            "cov-trials",
            f"{run.result['valid_trials']:,}",
            "studies.monte_carlo.study",
            study_args,
            seed,
            _record_name(run),
        )
    ]
    for name, short in (("ekf", "ekf"), ("second_order", "so"), ("optimal", "opt")):
        out.append(
            Number(
                f"cov-{short}",
                texts[f"sp_{name}_depth_coverage_68_pm"],
                "studies.monte_carlo.study",
                study_args,
                seed,
                _record_name(run),
            )
        )
    b = readme.bound_texts()
    bound_key = records.call_key(
        records.function_name(readme.beyond_bound.bound_study),
        (
            readme.BOUND_FRAMES,
            readme.BOUND_STUDY["trials"],
            readme.BOUND_STUDY["seed"],
            readme.BOUND_STUDY["names"],
            "paper",
            0.0,
        ),
        {
            "particle_trials": readme.BOUND_STUDY["particle_trials"],
            "n_particles": readme.BOUND_STUDY["n_particles"],
        },
    )
    bound_record = f"study_records/bound_study-{bound_key}.json"
    bound_args = f"frames {b['n_first']}-{b['n_last']}, trials={b['trials']}, prior 'paper'"
    bound_seed = f"{readme.BOUND_STUDY['seed']}"
    for key in ("trials", "n_first", "n_second", "n_last", "ekf_sd3", "ekf_rmse", "z", "near"):
        text = b[key].replace("%", r"\%")
        out.append(
            Number(
                f"bound-{key.replace('_', '-')}",
                text,
                "book.beyond_bound.bound_study",
                bound_args,
                bound_seed,
                bound_record,
            )
        )
    out += atlas_numbers()
    c = readme.cost_texts(bench)
    for key, record in (
        ("optimal_ekf_min", "bench_optimal"),
        ("optimal_ekf_max", "bench_optimal"),
        ("grid_ratio", "bench_optimal"),
        ("bank_trials", "bench_bank"),
        ("bank_frames", "bench_bank"),
        ("bank_particles", "bench_bank"),
        ("bank_ratio", "bench_bank"),
        ("bank_error", "bench_bank"),
    ):
        out.append(
            Number(
                f"cost-{key.replace('_', '-')}",
                c[key],
                f"benchmarks/{record}.py",
                "its record's sizes",
                record=_benchmark(record),
            )
        )
    return out


def atlas_numbers() -> list[Number]:
    """The atlas's calibrated cells per group of filters, from its record (book/beyond_atlas.md)."""
    run = readme.atlas_run()
    texts = {
        k: v.replace(" %", r"~\%") for k, v in readme.atlas_texts(run).items() if k != "trials"
    }
    result = run.result
    args = (
        f"size 'book', {len(result['cells'])} cells of {result['trials']:,} trials "
        f"({result.get('fixed_trials', result['trials']):,} at a fixed truth)"
    )
    return [
        Number(
            f"atlas-{key.replace('_', '-')}",
            text,
            "studies.atlas.atlas",
            args,
            f"{beyond_atlas.SEED}",
            _record_name(run),
        )
        for key, text in texts.items()
    ]


def software_numbers() -> list[Number]:
    """The software's authors, version and date (CITATION.cff) and its pins (requirements.txt)."""
    import yaml

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["version"] == __version__, "CITATION.cff and the package disagree"
    lines = (ROOT / "requirements.txt").read_text(encoding="utf-8").splitlines()
    pins = [line for line in lines if "==" in line and not line.lstrip().startswith("#")]
    return [
        Number("authors", ", ".join(a["name"] for a in cff["authors"]), "CITATION.cff", "authors"),
        Number("version", cff["version"], "CITATION.cff", "version"),
        Number("released", str(cff["date-released"]), "CITATION.cff", "date-released"),
        Number("licence", cff["license"], "CITATION.cff", "license"),
        Number("original-doi", cff["preferred-citation"]["doi"], "CITATION.cff", "doi"),
        Number("pins", f"{len(pins)}", "requirements.txt", "lines pinned with =="),
    ]


def numbers(bench: dict | None = None) -> list[Number]:
    """Every number of the article, in the order of the appendix's table."""
    bench = readme.bench_records() if bench is None else bench
    found = software_numbers() + paper_numbers() + extension_numbers(bench)
    keys = [n.key for n in found]
    assert len(keys) == len(set(keys)), "a key is used twice"
    return found


# --- the generated files ---------------------------------------------------------------------

_HEADER = "% Written by tools/article.py from the computations; do not edit.\n"


def _tex(text: str) -> str:
    """Plain text for LaTeX, its special characters escaped."""
    if "\\" in text:
        raise ValueError(f"text must hold no backslash, got {text!r}")
    for char in "_#&%{}$":
        text = text.replace(char, f"\\{char}")
    return text.replace("^", r"\^{}").replace("~", r"\~{}")


def numbers_tex(found: list[Number]) -> str:
    """``article/numbers.tex``: one ``\\defval`` per number."""
    lines = [
        rf"\defval{{{n.key}}}{{\ensuremath{{{n.text}}}}}"
        if "^" in n.text
        else rf"\defval{{{n.key}}}{{{n.text}}}"
        for n in found
    ]
    return _HEADER + "\n".join(lines) + "\n"


def _code(text: str) -> str:
    """``text`` in typewriter type, breakable after ``/``, ``.``, ``_``, ``,`` and ``-``."""
    escaped = _tex(text)
    return r"\texttt{" + re.sub(r"(/|\.|\\_|,|-)", r"\1\\allowbreak{}", escaped) + "}"


#: The appendix's table: its columns and their widths (fractions of the text's width).
COLUMNS = (
    ("number", 0.15),
    ("value", 0.08),
    ("function", 0.21),
    ("arguments", 0.2),
    ("seed", 0.04),
    ("record", 0.16),
)


#: The sources whose numbers the appendix leaves out: the software's own metadata (its
#: version, date, licence, pins), read from the files named, not computed.
TRIVIAL_SOURCES = ("CITATION.cff", "requirements.txt")
#: The keys of the verdicts' words (Table 1's), which the appendix names once rather than
#: row by row: each is :func:`depthbook.studies.claims.claims`'s.
VERDICT_KEYS = ("row-", "verdict-")


def provenance_tex(found: list[Number], used: set[str]) -> str:
    """``article/provenance.tex``: the appendix's table, for the numbers the text uses.

    The numbers of :data:`TRIVIAL_SOURCES` and :data:`VERDICT_KEYS` are left
    out; numbers of one function, arguments, seed and record share a row, in
    the order of their first; the seed's column of a number no random draw
    enters holds a dash.
    """
    spec = " ".join(
        rf">{{\raggedright\arraybackslash}}p{{{width}\textwidth}}" for _, width in COLUMNS
    )
    lines = [
        r"\begin{longtable}{@{}" + spec + "@{}}",
        r"\toprule",
        " & ".join(name for name, _ in COLUMNS) + r" \\",
        r"\midrule",
        r"\endhead",
    ]
    groups: dict[tuple, list[Number]] = {}
    for n in found:
        if n.key not in used or n.source in TRIVIAL_SOURCES or n.key.startswith(VERDICT_KEYS):
            continue
        groups.setdefault((n.source, n.arguments, n.seed, n.record), []).append(n)
    for (source, arguments, seed, record), members in groups.items():
        keys = ", ".join(_code(n.key) for n in members)
        values = ", ".join(
            f"${n.text}$" if "^" in n.text else n.text.replace("/", "/\\allowbreak{}")
            for n in members
        )
        seed = "--" if seed == "none" else seed
        lines.append(
            f"{keys} & {values} & {_code(source)} & {_tex(arguments)} & {seed} & "
            f"{_code(record)} \\\\"
        )
    lines += [r"\bottomrule", r"\end{longtable}"]
    return _HEADER + "\n".join(lines) + "\n"


def uncommented(source: str) -> str:
    """LaTeX ``source`` without its comments (``%`` to the end of the line, ``\\%`` kept)."""
    return re.sub(r"(?<!\\)%.*", "", source)


def used_keys(source: str) -> list[str]:
    """The keys of ``\\val{...}`` in the article's text, in order of first use."""
    seen: dict[str, None] = {}
    for key in re.findall(r"\\val\{([^}]*)\}", uncommented(source)):
        seen.setdefault(key, None)
    return list(seen)


def _bib_entries(text: str) -> dict[str, dict[str, str]]:
    """``key -> fields`` of a BibTeX file (the simple form of book/references.bib)."""
    entries = {}
    for kind, key, body in re.findall(r"@(\w+)\{([^,]+),(.*?)\n\}", text, re.S):
        fields = dict(re.findall(r"(\w+)\s*=\s*\{(.*?)\},?\s*$", body, re.M))
        fields["kind"] = kind.lower()
        entries[key.strip()] = fields
    return entries


def _authors(names: str) -> str:
    people = []
    for name in names.split(" and "):
        family, _, given = name.partition(", ")
        initials = " ".join(f"{part[0]}." for part in given.replace(".", ". ").split())
        people.append(f"{initials} {family}".strip())
    return ", ".join(people[:-1]) + (" and " if len(people) > 1 else "") + people[-1]


def references_tex(cited: list[str]) -> str:
    """``article/references.tex``: the entries cited, in order of citation, from the book's bib."""
    entries = _bib_entries(BIB.read_text(encoding="utf-8"))
    missing = [key for key in cited if key not in entries]
    if missing:
        raise ValueError(f"cited but not in {BIB.name}: {missing}")
    items = []
    for key in cited:
        e = entries[key]
        where = e.get("journal") or e.get("booktitle") or e.get("publisher", "")
        parts = [f"{_authors(e['author'])}. {e['title']}. \\emph{{{where}}}"]
        if e.get("series") and e.get("volume"):
            parts.append(f"{e['series']}, vol.~{e['volume']}")
        elif e.get("volume"):
            parts.append(f"{e['volume']}" + (f"({e['number']})" if e.get("number") else ""))
        if e.get("pages"):
            parts.append(f"pp.~{e['pages']}")
        if e.get("address") and e["kind"] != "article":
            parts.append(e["address"])
        parts.append(e["year"])
        doi = f" \\doi{{{e['doi']}}}" if e.get("doi") else ""
        items.append(f"\\bibitem{{{key}}} " + ", ".join(parts) + "." + doi)
    return _HEADER + "\n".join(items) + "\n"


def cited_keys(source: str) -> list[str]:
    seen: dict[str, None] = {}
    for group in re.findall(r"\\cite[tp]?\{([^}]*)\}", uncommented(source)):
        for key in group.split(","):
            seen.setdefault(key.strip(), None)
    return list(seen)


#: The abstract: ``{key}`` stands for the article's number ``key``. The article (LaTeX) and
#: the metadata (plain text) both take it from here.
ABSTRACT = (
    "We reproduce S. J. Maybank's comparison of the optimal Bayes filter, a second-order "
    "Gaussian approximation and the extended Kalman filter (EKF) for the depth of a point "
    "seen through three noisy bearings (BMVC 1990), from the paper's equations alone, in a "
    "tested Python package. Each of the paper's {claims-all} checkable statements is decided "
    "by a test stated before its number: {claims-as-printed} hold as printed, {claims-after} "
    "once an error of the print is corrected, {claims-formula} only with a printed formula "
    "that is wrong, {claims-not} not at all, and {claims-unchecked} cannot be checked. Of the "
    "{printed} means and standard deviations (SDs) the paper prints, {matched} are "
    "reproduced at its two decimals; Theorem 1 holds (the two covariances agree within "
    "{theorem-tol}, relative) once Eq. (8)'s covariance is doubled. Figure 3's optimal mean, "
    "{fig3-opt-paper-mean}, comes from Eq. (16) as printed, which drops a factor of the "
    "prior; the exact density has {fig3-opt-mean}, and the printed SD repeats the mean's "
    'digits. The noise of Figure 5 is {px-500} pixels, not "about 1 pixel". The EKF is '
    "overconfident on every figure of the depth: on Figure 2 its depth SD is {ekf-ratio} "
    "times too small, and over {cov-trials} simulated trials its 68 % interval covers the "
    "true depth in a fraction {cov-ekf}, the second-order filter's in {cov-so}. The "
    "second-order filter "
    "stays close to the optimal one on Figure 2 but not on Figure 3, where its depth SD is "
    "{fig3-so-sd} against {fig3-opt-sd}. The paper's numbers are "
    "computed when this article is built; the Monte Carlo studies and timings are read from "
    "records computed on the machine of Section 7, each named in Appendix A."
)


def abstract(values: dict[str, str], latex: bool = False) -> str:
    """:data:`ABSTRACT` with the article's numbers, as LaTeX or as plain text."""
    text = ABSTRACT
    if latex:
        text = text.replace(" %", r"~\%").replace(' "', " ``").replace('"', "''")
        values = {key: f"${v}$" if "^" in v else v for key, v in values.items()}
        text = re.sub(r"Eqs?\. \(", lambda m: m.group(0)[:-2] + "~(", text)
    else:
        values = {key: plain(value) for key, value in values.items()}
    return re.sub(r"\{([a-z0-9-]+)\}", lambda m: values[m.group(1)], text)


def abstract_keys() -> list[str]:
    """The numbers the abstract quotes."""
    return re.findall(r"\{([a-z0-9-]+)\}", ABSTRACT)


#: The fields of ReScience C's metadata template (its ``metadata.yaml``), in its order: each
#: top-level key and, for a list of one-key entries, those keys in order.
TEMPLATE_FIELDS = {
    "title": None,
    "authors": None,
    "affiliations": None,
    "keywords": None,
    "code": ("url", "doi", "swh"),
    "data": ("url", "doi"),
    "replication": ("cite", "bib", "url", "doi"),
    "abstract": None,
    "bibliography": None,
    "type": None,
    "domain": None,
    "language": None,
    "review": ("url",),
    "contributors": None,
    "dates": ("received", "accepted", "published"),
    "article": ("number", "doi", "url"),
    "journal": ("name", "issn", "volume", "issue"),
}


def metadata(values: dict[str, str]) -> str:
    """``article/metadata.yaml``: the journal's metadata, from CITATION.cff and the abstract."""
    import yaml

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    cited = cff["preferred-citation"]
    (author,) = cited["authors"]
    bib = _bib_entries(BIB.read_text(encoding="utf-8"))["maybank1990"]
    assert str(cited["year"]) == bib["year"], "CITATION.cff and the bibliography disagree"
    data = {
        "title": "[Re] Filter based estimates of depth",
        "authors": [{"name": a["name"], "affiliations": "*"} for a in cff["authors"]],
        "affiliations": [],
        "keywords": ", ".join([*cff["keywords"], "rescience c", "python"]),
        "code": [{"url": CODE_ARCHIVE}, {"doi": None}, {"swh": None}],
        "data": [{"url": None}, {"doi": None}],
        "replication": [
            {
                "cite": f"{author['family-names']}, {author['given-names']} ({cited['year']}). "
                f"{cited['title']}. In {bib['editor']} (ed.), {cited['collection-title']}, "
                f"pp. {bib['pages'].replace('--', '–')}. {bib['publisher']}, "
                f"{cited['conference']['city']}. doi:{bib['doi']}",
            },
            {"bib": "maybank1990"},
            {"url": None},
            {"doi": bib["doi"]},
        ],
        "abstract": abstract(values),
        "bibliography": "references.tex (from book/references.bib)",
        "type": "Replication",
        "domain": "Computer vision",
        "language": "Python",
        "review": [{"url": None}],
        "contributors": [],
        "dates": [{"received": None}, {"accepted": None}, {"published": None}],
        "article": [{"number": None}, {"doi": None}, {"url": None}],
        "journal": [
            {"name": "ReScience C"},
            {"issn": "2430-3658"},
            {"volume": None},
            {"issue": None},
        ],
    }
    header = (
        "# The metadata of the replication article, in ReScience C's form; written by\n"
        "# tools/article.py from CITATION.cff and the article's numbers: do not edit.\n"
        "# Its fields are the template's (TEMPLATE_FIELDS); those the journal fills after\n"
        "# acceptance are empty. The original's reference, pages and doi are the book's\n"
        "# bibliography's; its url is left out (no copy at hand to point to).\n"
        f"# The code is depthcore {cff['version']} ({cff['license']} licence, released "
        f"{cff['date-released']}),\n# whose source archive the book ships as {CODE_ARCHIVE}.\n"
    )
    return header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=88)


def generated(bench: dict | None = None) -> dict[Path, str]:
    """Every generated file's path and the text this writes into it."""
    source = SOURCE.read_text(encoding="utf-8")
    found = numbers(bench)
    defined = {n.key for n in found}
    used = used_keys(source) + [key for key in abstract_keys() if key not in used_keys(source)]
    undefined = [key for key in used if key not in defined]
    if undefined:
        raise ValueError(
            f"article.tex uses numbers that tools/article.py does not compute: {undefined}"
        )
    values = {n.key: n.text for n in found}
    return {
        NUMBERS: numbers_tex([n for n in found if n.key in set(used)]),
        PROVENANCE: provenance_tex(found, set(used)),
        ABSTRACT_TEX: _HEADER + abstract(values, latex=True) + "\n",
        REFERENCES: references_tex(cited_keys(source)),
        METADATA: metadata(values),
    }


def stale(files: dict[Path, str]) -> list[str]:
    """The generated files that differ from ``files``, relative to the repository."""
    return [
        str(path.relative_to(ROOT))
        for path, text in files.items()
        if not path.is_file() or path.read_text(encoding="utf-8") != text
    ]


def _current(files: dict[Path, str]) -> bool:
    """Whether the generated files are ``files``; if not, say which and how to rewrite them."""
    changed = stale(files)
    if changed:
        where = ", ".join(changed)
        print(f"{where}: not what the code gives now: run `{COMMAND}`", file=sys.stderr)
    return not changed


def build(out: Path) -> int:
    """Typeset the article into ``out/article.pdf`` once its generated files are current.

    Its figures are drawn into ``out`` at the size it prints them
    (:func:`depthbook.paper.save_print`).
    """
    files = generated()
    if not _current(files):
        return 1
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for path in (SOURCE, *files):
        shutil.copy(path, out / path.name)
    drawn = {path.name for path in paper.save_print(out)}
    assert drawn == set(FIGURES), drawn
    sentence = environment.records_sentence() + " " + environment.sentence(environment.statement())
    (out / "environment.tex").write_text(_tex(sentence) + "\n", encoding="utf-8")
    done = subprocess.run([str(ROOT / "tools" / "xelatex.sh"), str(out), "article"], check=False)
    return done.returncode


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("action", nargs="?", choices=("write", "build"), default="write")
    p.add_argument("--check", action="store_true", help="fail if a generated file is not current")
    p.add_argument("--out", type=Path, help="build: the folder to typeset the article in")
    args = p.parse_args(argv)
    if args.action == "build":
        if args.out is None:
            p.error("build needs --out DIR")
        return build(args.out)
    files = generated()
    if args.check:
        return 0 if _current(files) else 1
    changed = stale(files)
    for path, text in files.items():
        if str(path.relative_to(ROOT)) in changed:
            path.write_text(text, encoding="utf-8")
            print(f"{path.relative_to(ROOT)}: written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
