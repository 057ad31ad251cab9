"""The options ``study`` and ``atlas`` share to run on Dask: ``--workers``, ``--scheduler``.

Recommended import: ``from depthcore.cli import cluster``.

The command line reads ``--workers`` as text and refuses, in one line naming it,
anything but a whole number in plain digits within the cap; what a cluster is and
how one is reached (``--scheduler``) is :mod:`depthcore.studies.tasks`'s.
"""

from __future__ import annotations

import argparse

from depthcore.studies import tasks


def add_arguments(parser: argparse.ArgumentParser, what: str, same: str) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` on ``parser``, which run its ``what``.

    ``same`` says what the result is on a cluster ("the same result, bit for bit").
    """
    parser.add_argument(
        "--workers",
        metavar="N",
        help=f"run the {what} on a local Dask cluster of N processes, a whole number from 1 to "
        f"{tasks.MAX_WORKERS} whatever the cores (default: in this process); {same}",
    )
    wait = f"{tasks.CONNECT_TIMEOUT:g} s"
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"run the {what} on the Dask cluster whose scheduler is at ADDRESS "
        f"(tcp://host:8786, workers with this depthcore), refused unless it answers within "
        f"{wait} and has a worker within {wait} more; {same}",
    )


def workers(text: str) -> int:
    """``--workers`` as given: a whole number, 1 to :data:`~depthcore.studies.tasks.MAX_WORKERS`.

    Blanks around it are dropped; ``1_0``, ``2.0`` or digits of other scripts are refused.

    Raises
    ------
    ValueError
        Naming ``--workers`` and the text as given.
    """
    digits = text.strip().removeprefix("+")
    if not (digits.isascii() and digits.isdigit() and 1 <= int(digits) <= tasks.MAX_WORKERS):
        raise ValueError(
            f"--workers must be a whole number from 1 to {tasks.MAX_WORKERS}, got {text!r}"
        )
    return int(digits)
