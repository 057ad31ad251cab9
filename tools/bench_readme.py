"""Write the README's benchmark tables from the benchmarks' records.

The README's section "Benchmark" holds, between the marker comments
``<!-- bench:KEY -->`` and ``<!-- /bench:KEY -->``, the blocks of
:func:`depthcore.book.benchmark_tables.bench_blocks`: each a table made from the
records ``depthcore/provenance/benchmark_records/<script>.json``
(:mod:`depthcore.provenance.benchmarks`), with
the date and machine they were measured on. ``make bench`` runs this after
measuring; ``tests/test_benchmark_records.py`` checks that the README equals
what this writes.

Usage: ``python tools/bench_readme.py [--check]`` (``--check``: change
nothing, fail if the README's tables differ from the records).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from depthcore.book import benchmark_tables
from depthcore.provenance import benchmarks

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
BLOCK = re.compile(r"(<!-- bench:(\w+) -->\n)(?:.*?\n)?(<!-- /bench:\2 -->)", re.S)


def records() -> dict:
    """Every benchmark's committed record, by script name."""
    names = sorted(p.stem for p in (ROOT / "benchmarks").glob("bench_*.py"))
    return {name: benchmarks.read(name) for name in names}


def regenerate(text: str, blocks: dict[str, str]) -> str:
    """``text`` with the body between each pair of markers replaced by its block.

    Raises
    ------
    ValueError
        If a marker names no block, or a block has no markers in ``text``.
    """
    found = [m.group(2) for m in BLOCK.finditer(text)]
    unknown = sorted(set(found) - set(blocks))
    missing = sorted(set(blocks) - set(found))
    if unknown or missing:
        raise ValueError(
            f"text must hold the markers of exactly the blocks {sorted(blocks)}: "
            f"unknown {unknown}, missing {missing}"
        )
    return BLOCK.sub(lambda m: m.group(1) + blocks[m.group(2)] + "\n" + m.group(3), text)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="fail if the README is not up to date")
    args = p.parse_args(argv)
    text = README.read_text(encoding="utf-8")
    new = regenerate(text, benchmark_tables.bench_blocks(records()))
    if args.check:
        if new != text:
            print(
                "README.md: the benchmark tables differ from the records: run "
                "`python tools/bench_readme.py`",
                file=sys.stderr,
            )
            return 1
        return 0
    if new != text:
        README.write_text(new, encoding="utf-8")
        print("README.md: benchmark tables rewritten from depthcore/provenance/benchmark_records/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
