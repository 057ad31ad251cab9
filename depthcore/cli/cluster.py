"""The options ``study`` and ``atlas`` share to run on a Dask cluster: ``--workers N``.

Recommended import: ``from depthcore.cli import cluster``.

The command line reads ``--workers`` as text and refuses, in one line naming it,
anything but a whole number in plain digits within the cap; what a cluster is and
how one is reached (``--scheduler``) is :mod:`depthcore.studies.tasks`'s.
"""

from __future__ import annotations

from depthcore.studies import tasks


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
