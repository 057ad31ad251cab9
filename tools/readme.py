"""Write the README's generated parts: its numbers and its figure.

The README holds, between the marker comments ``<!-- readme:KEY -->`` and
``<!-- /readme:KEY -->``, the blocks of :func:`blocks`: what the book found,
with every number computed by the functions the book's pages use, or read from
the records they read (the Monte Carlo study of the bound,
:mod:`depthbook.provenance.records`, and the benchmarks,
:mod:`depthbook.provenance.benchmarks`); no study is computed here. Each
sentence's claims are asserted before it is written. The README also shows
``_static/figure2.svg``, the paper's Figure 2 as
:func:`depthbook.paper.figure` draws it (:func:`figure_svg`), written
without a date and with fixed element ids, so that the same code gives the
same bytes. Its table of the package's families is each subpackage's docstring
summary (:func:`families`), read without importing it.

``make bench`` runs this after measuring; ``tests/test_readme.py`` checks
that the README and the figure are what this writes.

Usage: ``python tools/readme.py [--check]`` (``--check``: change nothing,
fail if the README or its figure differs from what the code gives now).
"""

from __future__ import annotations

import argparse
import ast
import io
import os
import re
import sys
from contextlib import contextmanager
from pathlib import Path

import depthcore
from depthbook import beyond_atlas, beyond_bound, intro, paper
from depthbook import claims as claims_chapter
from depthbook.formatting import rho_label, sci
from depthbook.provenance import benchmarks, records
from depthbook.studies import claims, verdicts
from depthcore import SCENARIOS
from depthcore.problem.scenarios import REPORTED_DECIMALS
from depthcore.studies import atlas

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
FIGURE = ROOT / "_static" / "figure2.svg"
BLOCK = re.compile(r"(<!-- readme:(\w+) -->\n)(?:.*?\n)?(<!-- /readme:\2 -->)", re.S)
#: What the command line says when the README is not what this writes.
COMMAND = "python tools/readme.py"
#: Theorem 1's check, as book/appendix.md makes it (:mod:`depthbook.studies.verdicts`).
THEOREM_TOL = verdicts.THEOREM_TOL
#: The study of the bound that book/beyond_bound.md reads (:mod:`depthbook.intro`).
BOUND_FRAMES = intro.BOUND_FRAMES
BOUND_STUDY = intro.BOUND_STUDY
NEAR = intro.NEAR


def bench_records() -> dict:
    """Every benchmark's committed record, by script name."""
    names = sorted(p.stem for p in (ROOT / "benchmarks").glob("bench_*.py"))
    return {name: benchmarks.read(name) for name in names}


def _figures(numbers) -> str:
    """``Figures 2 and 3``, ``Figures 2, 3, 5 and 6``."""
    numbers = [str(n) for n in numbers]
    return "Figures " + ", ".join(numbers[:-1]) + f" and {numbers[-1]}"


@contextmanager
def _records_required():
    """Studies read from their records only, never computed (``DEPTHCORE_RECORDS=require``)."""
    before = os.environ.get(records.ENVIRONMENT)
    os.environ[records.ENVIRONMENT] = "require"
    try:
        yield
    finally:
        if before is None:
            del os.environ[records.ENVIRONMENT]
        else:
            os.environ[records.ENVIRONMENT] = before


def paper_texts() -> dict[str, str]:
    """The claims' verdicts, the reproduction of the paper's numbers, Theorem 1, the print's errors.

    The same computations as book/conclusions.md (the printed numbers
    reproduced), book/appendix.md (Theorem 1) and book/discrepancies.md (Eqs.
    (8) and (16), Figure 3's numbers, the noise in pixels), each cheap.
    """
    n = verdicts.paper_numbers()
    printed, unmatched = n["printed"], n["unmatched"]
    figures = sorted(
        {
            SCENARIOS[key].figure
            for key, rows in n["rows"].items()
            if rows["opt"]["reported_mean"] is not None
        }
    )
    fig3 = n["rows"]["fig3"]
    assert unmatched == [("fig3", "opt", "mean"), ("fig3", "opt", "sd")], unmatched
    assert fig3["opt_printed"]["mean_matches"] and not fig3["opt_printed"]["sd_matches"]
    assert fig3["opt"]["reported_sd"] == fig3["opt"]["reported_mean"]  # the SD repeats the mean
    assert fig3["so"]["sd_matches"] and not fig3["so_printed"]["sd_matches"]
    assert n["theorem"] < THEOREM_TOL

    rho5 = SCENARIOS["fig5"].rho
    pixels = n["pixels"]
    assert pixels > 1.5  # the paper: "about 1 pixel"
    moments = n["moments"]["fig2"]
    ekf_ratio = moments["optimal"][1] / moments["ekf"][1]
    assert ekf_ratio > 4
    count = claims_chapter.counts(claims.claims())
    return {
        "claims": f"{count['all']}",
        "as_printed": f"{count[claims.AS_PRINTED]}",
        "after": f"{count[claims.AFTER_CORRECTION]}",
        "formula": f"{count[claims.PRINTED_FORMULA]}",
        "not": f"{count[claims.NOT_REPRODUCED]}",
        "unchecked": f"{count[claims.NOT_CHECKABLE]}",
        "matched": f"{printed - len(unmatched)}",
        "printed": f"{printed}",
        "printed_figures": _figures(figures),
        "all_figures": f"Figures {min(s.figure for s in SCENARIOS.values())}–"
        f"{max(s.figure for s in SCENARIOS.values())}",
        "decimals": {1: "one decimal", 2: "two decimals"}[REPORTED_DECIMALS],
        "theorem_tol": sci(THEOREM_TOL, 0),
        "fig3_paper_mean": f"{fig3['opt']['reported_mean']:.{REPORTED_DECIMALS}f}",
        "fig3_printed_mean": f"{fig3['opt_printed']['mean']:.2f}",
        "fig3_derived_mean": f"{fig3['opt']['mean']:.2f}",
        "rho5": rho_label(rho5),
        "pixels": f"{pixels:.2f}",
        "ekf_ratio": f"{ekf_ratio:.1f}",
    }


def bound_texts() -> dict[str, str]:
    """The EKF, the second-order filter and the iterated EKF against the Cramér–Rao bound.

    :func:`depthbook.intro.bound_texts` of book/beyond_bound.md's study without
    process noise, read from its record only.
    """
    with _records_required():
        run = records.recorded(
            beyond_bound.bound_study,
            BOUND_FRAMES,
            BOUND_STUDY["trials"],
            BOUND_STUDY["seed"],
            BOUND_STUDY["names"],
            "paper",
            0.0,
            particle_trials=BOUND_STUDY["particle_trials"],
            n_particles=BOUND_STUDY["n_particles"],
        )
    return intro.bound_texts(run.result)


def atlas_run():
    """The book's atlas (book/beyond_atlas.md), read from its record only."""
    with _records_required():
        return records.recorded(atlas.atlas, "book", beyond_atlas.SEED)


def atlas_texts(run=None) -> dict[str, str]:
    """The atlas's cells and calibrated cells per group of filters (book/beyond_atlas.md).

    :func:`depthbook.beyond_atlas.calibration_texts` of ``run`` (default
    :func:`atlas_run`), with ``"cells"``, ``"trials"``, ``"tolerance"``, ``"fdr"``
    (the false-discovery rate) and ``"law"`` (the headline of the exact filter under
    the depth's true law).
    """
    run = atlas_run() if run is None else run
    counts = beyond_atlas.verdict_counts(run.result)
    levels = beyond_atlas.read(run.result)["levels"]
    tolerance = levels["calibration_tolerance"]
    law = beyond_atlas.under_law(run.result)["all"]["law"]
    return {
        "cells": f"{len(run.result['cells'])}",
        "trials": f"{run.result['trials']:,}",
        "tolerance": f"{tolerance:g}",
        "fdr": f"{100 * levels['false_discovery_rate']:g} %",
        "law": beyond_atlas.headline(law, tolerance),
        **beyond_atlas.calibration_texts(counts),
    }


def cost_texts(bench: dict) -> dict[str, str]:
    """The costs of the paper's filters and of the bank (``intro.cost_texts``)."""
    return intro.cost_texts(bench)


def citation() -> str:
    """The paper's and the software's citations, from ``CITATION.cff``."""
    import yaml

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    cited = cff["preferred-citation"]
    (author,) = cited["authors"]
    initials = " ".join(f"{name[0]}." for name in author["given-names"].split())
    released = str(cff["date-released"])
    authors = ", ".join(a["name"] for a in cff["authors"])
    return (
        f"> {author['family-names']}, {initials} ({cited['year']}). "
        f"{cited['title'][0].upper()}{cited['title'][1:]}. *{cited['collection-title']}*, "
        f"{cited['conference']['city']}.\n\n"
        f"> {authors} ({released[:4]}). *{cff['title']}*, version {cff['version']}, "
        f"released {released}."
    )


def families() -> str:
    """The package's families as a Markdown table: each subpackage, in the order of
    ``depthcore.SUBPACKAGES``, and the first line of its docstring (read, not imported)."""
    package = ROOT / "depthcore"
    rows = ["| family | what it holds |", "| --- | --- |"]
    for name in depthcore.SUBPACKAGES:
        source = (package / name / "__init__.py").read_text(encoding="utf-8")
        summary = ast.get_docstring(ast.parse(source)).splitlines()[0]
        rows.append(f"| `depthcore.{name}` | {summary} |")
    return "\n".join(rows)


def blocks(bench: dict | None = None) -> dict[str, str]:
    """The README's generated blocks: ``findings``, ``figure``, ``families``, ``citation``."""
    bench = bench_records() if bench is None else bench
    p, b, c, a = paper_texts(), bound_texts(), cost_texts(bench), atlas_texts()
    findings = [
        f"**Reproduced, claim by claim.** Of the {p['claims']} statements of the paper a "
        f"computation can check, {p['as_printed']} are reproduced as printed, "
        f"{p['after']} once an error of the print is corrected and {p['formula']} only "
        f"with a printed formula that is wrong; {p['not']} are not reproduced and "
        f"{p['unchecked']} cannot be checked ([the claims](book/claims.md)). Computed as "
        f"derived, the paper's three filters reproduce {p['matched']} of the {p['printed']} "
        f"depth means and SDs printed with {p['printed_figures']}, at its {p['decimals']}, "
        f"and Theorem 1 holds on both (the second-order covariance is the EKF's to "
        f"{p['theorem_tol']} relative); the book redraws {p['all_figures']}.",
        "**The paper's errors.** The two numbers not reproduced, the optimal filter's with "
        "Figure 3, are the print's: Eq. (16) drops a factor of the prior (as printed it gives "
        f"the paper's mean, {p['fig3_paper_mean']}, where Eq. (6) gives "
        f"{p['fig3_derived_mean']}) and the SD repeats the mean's digits; Eq. (8)'s "
        "covariance must be 2ρ²J⁻¹, not the printed ρ²J⁻¹; and Figure 5's "
        f'ρ = {p["rho5"]} is {p["pixels"]} pixels, not "about 1 pixel".',
        f"**The EKF, on Figure 2's point.** There its depth SD is {p['ekf_ratio']} times "
        f"smaller than the optimal filter's; over {b['trials']} tracks of Figure 2's point "
        f"(ρ = {b['rho2']}, {b['n_first']} to {b['n_last']} frames, no process noise, the "
        "paper's prior rule) it claims an SD below the Cramér–Rao bound at every number of "
        f"frames ({b['ekf_sd3']} of it at {b['n_first']}) and from {b['n_second']} frames on "
        f"its error is at least {b['ekf_rmse']} times the bound, while on these tracks the "
        f"second-order filter and the iterated EKF sit on it (errors within {b['z']} standard "
        f"errors, stated SDs within {b['near']}).",
        f"**Where each filter holds.** Over an atlas of {a['cells']} settings of parallax, "
        "prior (the paper's rule and three forms of the tracking literature), noise and "
        f"frames, {a['judged']} with truths drawn from the prior at {a['trials']} trials each, "
        "the optimal filter, the second-order filter, the modified-polar EKF, the batch "
        "maximum-likelihood estimate and an importance sampler have 68 % intervals "
        f"calibrated within ±{a['tolerance']} in {a['good_min']} to {a['good_max']} of "
        f"those and miscalibrated in at most {a['good_no_max']}; the EKF, the UKF and the "
        f"inverse-depth filters are miscalibrated in {a['poor_no_min']} to "
        f"{a['poor_no_max']}. Given the depth's true law rather than its Gaussian stand-in, "
        f"the exact filter is {a['law']}.",
        f"**Cost.** In the benchmarks' records (measured {c['date']}) the optimal "
        f"filter costs {c['optimal_ekf_min']} to {c['optimal_ekf_max']} times the EKF per "
        f"triple of bearings ({c['figures']}), where brute-force quadrature of Eq. (6) on a "
        f"three-dimensional grid would cost {c['grid_ratio']} times as much; on "
        f"{c['bank_trials']} tracks of {c['bank_frames']} frames the exact filter, a bank of "
        f"Kalman filters over the depth, runs {c['bank_ratio']} times faster than a causal "
        f"particle filter of {c['bank_particles']} particles, whose depth mean is still "
        f"{c['bank_error']} posterior SDs from the bank's.",
    ]
    s = SCENARIOS["fig2"]
    figure = (
        f"![The paper's Figure 2 reproduced: {paper.caption('fig2')}]"
        f"({FIGURE.relative_to(ROOT).as_posix()})\n\n"
        f'The paper\'s Figure 2, drawn by `depthbook.paper.figure("fig2")`: the '
        f"{s.quantity} marginals of the optimal filter, the second-order approximation and "
        f"the EKF at time 3, for the bearings ({', '.join(f'{m:g}' for m in s.mu)}) at "
        f"ρ = {rho_label(s.rho)}."
    )
    figure = figure.split("\n\n")[0] + "\n\n" + _wrap(figure.split("\n\n")[1])
    listed = "\n".join(_item(text) for text in findings)
    return {
        "findings": listed,
        "figure": figure,
        "families": families(),
        "citation": citation(),
    }


def _wrap(text: str, width: int = 80) -> str:
    """``text`` broken into lines of at most ``width`` characters, at spaces."""
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return "\n".join(lines + [line])


def _item(text: str, width: int = 80) -> str:
    """``text`` as an item of a Markdown list, its lines wrapped at ``width`` and indented."""
    lines = _wrap(text, width - 2).splitlines()
    return "\n".join(["* " + lines[0]] + ["  " + line for line in lines[1:]])


def figure_svg() -> bytes:
    """Figure 2 as :func:`depthbook.paper.figure` draws it, as SVG without a date."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with plt.rc_context({"svg.hashsalt": "depthcore-figure2"}):
        fig = paper.figure("fig2")
        buffer = io.BytesIO()
        fig.savefig(buffer, format="svg", metadata={"Date": None})
        plt.close(fig)
    return buffer.getvalue()


def regenerate(text: str, generated: dict[str, str]) -> str:
    """``text`` with the body between each pair of markers replaced by its block.

    Raises
    ------
    ValueError
        If a marker names no block, or a block has no markers in ``text``.
    """
    found = [m.group(2) for m in BLOCK.finditer(text)]
    unknown = sorted(set(found) - set(generated))
    missing = sorted(set(generated) - set(found))
    if unknown or missing:
        raise ValueError(
            f"text must hold the markers of exactly the blocks {sorted(generated)}: "
            f"unknown {unknown}, missing {missing}"
        )
    return BLOCK.sub(lambda m: m.group(1) + generated[m.group(2)] + "\n" + m.group(3), text)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="fail if the README is not up to date")
    args = p.parse_args(argv)
    text = README.read_text(encoding="utf-8")
    new = regenerate(text, blocks())
    svg = figure_svg()
    old_svg = FIGURE.read_bytes() if FIGURE.is_file() else None
    if args.check:
        stale = [
            str(path.relative_to(ROOT))
            for path, same in ((README, new == text), (FIGURE, svg == old_svg))
            if not same
        ]
        if stale:
            print(
                f"{', '.join(stale)}: not what the code gives now: run `{COMMAND}`", file=sys.stderr
            )
            return 1
        return 0
    if new != text:
        README.write_text(new, encoding="utf-8")
        print("README.md: its generated blocks rewritten")
    if svg != old_svg:
        FIGURE.write_bytes(svg)
        print(f"{FIGURE.relative_to(ROOT)}: written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
