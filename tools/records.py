"""Compute every study record again without ever leaving the book without records.

``make records`` runs the pages that read records through this script:

    python tools/records.py -- COMMAND [ARG ...]

COMMAND (the pages executed with ``DEPTHCORE_RECORDS=write``) writes its new
records into a folder beside the committed ones, ``study_records.new/``
(``DEPTHCORE_RECORDS_DIR``). Only once it has ended well, and every new record
is of the current code, does that folder replace the committed one. When it
fails, or is interrupted (Ctrl-C, SIGTERM), the committed records, and the
pages' references that COMMAND rewrites, are left as they were, so that the
book still builds from them; the partial new set is removed.

With ``--keep`` the new folder starts as a copy of the committed one, so
that COMMAND may compute a few records again (``make atlas``, the atlas's
alone) and the others stay; each must still be of the current code.

Exits with COMMAND's status (130 when interrupted).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

from depthbook.provenance import records

ROOT = Path(__file__).resolve().parent.parent
#: The pages' references, which the first pass of ``make records`` rewrites.
REFERENCES = ROOT / "book" / "_nbval"


class Interrupted(Exception):
    """SIGINT or SIGTERM reached this process."""


def _interrupt(signum, frame):
    raise Interrupted(signal.Signals(signum).name)


def incomplete(folder: Path) -> list[str]:
    """The records in ``folder`` that are stale or unreadable, by file name."""
    bad = []
    for path in records.committed(folder):
        try:
            if records.stale(records.read(path)):
                bad.append(path.name)
        except (ValueError, KeyError):
            bad.append(path.name)
    return bad


def swap(new: Path, current: Path) -> None:
    """Put folder ``new`` where ``current`` is: two renames, the old set removed last."""
    old = current.with_name(current.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if current.exists():
        current.rename(old)
    new.rename(current)
    shutil.rmtree(old, ignore_errors=True)


def run(command: list[str], current: Path, references: Path, keep: bool = False) -> int:
    """Run ``command`` writing records beside ``current``; swap them in only if it ends well.

    ``keep``: the new folder starts as a copy of ``current``, whose records
    ``command`` does not write again stay.
    """
    new = current.with_name(current.name + ".new")
    kept = references.with_name(references.name + ".kept")
    for folder in (new, kept):
        shutil.rmtree(folder, ignore_errors=True)
    if keep and current.is_dir():
        shutil.copytree(current, new)
    else:
        new.mkdir(parents=True)
    if references.is_dir():
        shutil.copytree(references, kept)
    env = {**os.environ, records.ENVIRONMENT: "write", records.DIRECTORY: str(new)}
    status = 130
    handlers = {s: signal.signal(s, _interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        process = subprocess.Popen(command, env=env)
        try:
            status = process.wait()
        except Interrupted:
            process.terminate()
            process.wait()
            raise
        if status == 0 and (bad := incomplete(new)):
            print(f"records: not current after the run: {', '.join(bad)}", file=sys.stderr)
            status = 1
        if status == 0 and not records.committed(new):
            print("records: the command wrote no record", file=sys.stderr)
            status = 1
        if status == 0:
            swap(new, current)
    except Interrupted as signal_name:
        print(f"records: interrupted ({signal_name}): the committed records kept", file=sys.stderr)
        status = 130
    finally:
        for s, handler in handlers.items():
            signal.signal(s, handler)
        if status != 0 and kept.is_dir():
            shutil.rmtree(references, ignore_errors=True)
            shutil.copytree(kept, references)
        shutil.rmtree(kept, ignore_errors=True)
        shutil.rmtree(new, ignore_errors=True)
    return status


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--records", type=Path, default=records.RECORDS, help=argparse.SUPPRESS)
    parser.add_argument("--references", type=Path, default=REFERENCES, help=argparse.SUPPRESS)
    parser.add_argument(
        "--keep", action="store_true", help="keep the records the command does not write again"
    )
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- COMMAND [ARG ...]")
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("a command to run is required, after --")
    return run(command, args.records, args.references, args.keep)


if __name__ == "__main__":
    sys.exit(main())
