"""``python -m depthbook figures``: the paper's Figures 2-6 as files, for the book's downloads.

Writes ``figure<N>.<fmt>`` (the paper's three filters) and
``figure<N>-extended.<fmt>`` (with the UKF and the particle filter) through
:func:`depthbook.paper.save_all`. A refusal is one line on standard error,
exit status 2; a folder that cannot be written, exit status 1.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

#: The formats ``--format`` accepts, all written when it is not given.
FORMATS = ("pdf", "png", "svg")


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def parser() -> argparse.ArgumentParser:
    """The arguments of ``python -m depthbook``."""
    p = _Parser(prog="python -m depthbook", description="the book's tools")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    f = sub.add_parser("figures", help="write Figures 2-6 as PDF, PNG and SVG")
    f.add_argument("--out", default="figures", help="output folder (default: figures)")
    f.add_argument(
        "--format",
        dest="formats",
        nargs="+",
        choices=FORMATS,
        metavar="FORMAT",
        help="write these formats only, of pdf, png and svg (default: all three)",
    )
    return p


def folder(out: str) -> Path:
    """The folder ``--out``, made if missing; a ValueError naming ``--out`` when it cannot be."""
    if not out.strip():
        raise ValueError("--out must be a folder, got an empty path")
    path = Path(out)
    for p in (path, *path.parents):
        if p.exists() and not p.is_dir():
            raise ValueError(f"--out must be a folder, but {str(p)!r} is a file")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--out: cannot make the folder {out!r}: {exc.strerror}") from None
    if not os.access(path, os.W_OK):
        raise ValueError(f"--out: cannot write into the folder {out!r}: permission denied")
    return path


def main(argv=None) -> int:
    """Run ``python -m depthbook``; returns the exit status."""
    p = parser()
    args = p.parse_args(argv)
    formats = tuple(args.formats or FORMATS)
    repeated = sorted({f for f in formats if formats.count(f) > 1})
    if repeated:
        p.error(f"--format names {', '.join(repeated)} more than once")
    try:
        out = folder(args.out)
    except ValueError as exc:
        p.error(str(exc))
    import matplotlib

    matplotlib.use("Agg")
    from depthbook import paper

    try:
        paths = paper.save_all(out, formats)
    except OSError as exc:
        where = exc.filename or args.out
        print(f"{p.prog}: --out: cannot write {str(where)!r}: {exc.strerror}", file=sys.stderr)
        return 1
    print("\n".join(str(path) for path in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
