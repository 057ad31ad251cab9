"""The command ``python -m depthcore atlas``: every filter's verdicts over a grid of settings.

Recommended import: ``from depthcore.cli import atlas_command``.

:func:`add` gives the command's parser (made by :mod:`depthcore.cli.main`) its
options and what it runs, :func:`run`: the atlas of
:func:`depthcore.studies.atlas.atlas` at the size asked, in this process, on a
local Dask cluster (``--workers N``) or on a running one (``--scheduler
ADDRESS``), printed or written to ``--out`` as strict JSON.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from depthcore.cli import cluster
from depthcore.cli import text as cli_text
from depthcore.studies import atlas, tasks

#: The command's one-line help.
SUMMARY = "every filter's verdicts over a grid of parallax, prior, noise, depth and frames"


def check_file(out: str) -> Path:
    """The file of ``--out``: refuses an empty path, a folder, a folder that is not there."""
    if not out.strip():
        raise ValueError("--out must be a file, got an empty path")
    path = Path(out)
    if path.is_dir():
        raise ValueError(f"--out must be a file, but {out!r} is a folder")
    if not path.parent.is_dir():
        raise ValueError(f"--out: the folder of {out!r} does not exist")
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ValueError(f"--out: cannot write {out!r}: permission denied")
    return path


def run(args, with_bar, write_error) -> str:
    """The atlas of ``args``; its JSON, or ``""`` once written to ``--out``.

    ``with_bar(desc, unit, run)`` runs ``run(progress)`` under a progress bar;
    ``write_error`` is the exception raised when ``--out`` cannot be written.
    """
    if args.seed < 0:
        raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.workers is not None and args.scheduler is not None:
        raise ValueError("--workers and --scheduler: give one (a local cluster, or a running one)")
    path = None if args.out is None else check_file(args.out)
    workers = None if args.workers is None else cluster.workers(args.workers)
    with tasks.cluster(workers, args.scheduler) as client:
        result = with_bar(
            f"atlas ({args.size})",
            "trial",
            lambda p: atlas.atlas(args.size, args.seed, client=client, progress=p),
        )
    text = cli_text.as_json(result)
    if path is None:
        return text
    try:
        path.write_text(text)
    except OSError as exc:
        raise write_error(f"cannot write --out {args.out!r}: {exc.strerror}") from None
    return ""


def add(parser: argparse.ArgumentParser, with_bar, write_error) -> None:
    """The options of ``atlas`` on its ``parser``, and :func:`run` as what it runs."""
    parser.add_argument(
        "--size",
        choices=tuple(atlas.SIZES),
        default="book",
        help="book (default): the book's grid; full: every axis finer, thousands of trials "
        "per cell, for a cluster",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    same = "the same result, bit for bit (but the measured cost)"
    cluster.add_arguments(parser, "cells", same)
    parser.add_argument(
        "--out", metavar="FILE", help="write the JSON to FILE (default: standard output)"
    )
    parser.set_defaults(run=lambda args: run(args, with_bar, write_error))
