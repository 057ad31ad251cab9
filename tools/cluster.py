"""Run a command with a local Dask cluster of every core, named by ``DEPTHCORE_SCHEDULER``.

The studies the command runs (in it, or in the kernels of the pages it
executes) send their chunks of trials to that cluster
(:mod:`depthcore.studies.tasks`), with the same results, bit for bit, as in one
process. ``make records`` runs the book's studies through it.

Usage: ``python tools/cluster.py [--workers N] COMMAND [ARG ...]`` (default
``N``: ``os.cpu_count()``); exits with the command's status.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

from depthcore.studies import tasks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="worker processes of one thread each (default: the cores, %(default)s)",
    )
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the command to run")
    args = parser.parse_args(argv)
    if not args.command:
        parser.error("a command to run is required")
    with tasks.local_cluster(args.workers, host="127.0.0.1") as cluster:
        env = {**os.environ, tasks.SCHEDULER: cluster.scheduler_address}
        print(
            f"a local cluster of {args.workers} workers at {cluster.scheduler_address}",
            flush=True,
        )
        return subprocess.run(args.command, env=env).returncode


if __name__ == "__main__":
    sys.exit(main())
