"""The command line's track files: ``estimate --mu-file FILE`` and ``--mu``.

Recommended import: ``from depthcore.cli import tracks``.

Reading a track file and running it frame by frame are the library's,
:mod:`depthcore.registry.track_files`; here are the options' checks in the
user's words (``--focal``, ``--cx``, ``--mu``, ``--gate``), standard input for
``-``, and the format as ``estimate --help`` shows it (:data:`FORMAT`).
"""

from __future__ import annotations

import io
import math
import sys

import numpy as np

from depthcore.problem import checks
from depthcore.registry import track_files

#: The track file's format, as ``estimate --help`` shows it.
FORMAT = """\
The track file of --mu-file (CSV, UTF-8, LF or CRLF line ends; - reads standard
input): a header naming the columns, then one row per frame in time order.
  mu     the bearing (tangent of the angle from the direction of motion); or
  u      the image column in pixels instead of mu, with --focal and --cx:
         mu = (u - cx) / focal (a pixel noise s is rho = s / focal)
  rho    optional: the noise SD of each frame's bearing (in mu's units);
         without it, --rho for every frame
  step   optional: the depth's change since the previous frame (> 0; the
         first row's must be empty); without it, 1 between consecutive frames
  frame  optional: the frame number, strictly increasing integers; without a
         step column a gap in the numbers is that many missing frames
An empty field or nan in mu (or u) is a missing frame: the filter predicts
through it (its rho may be empty too)."""

#: How the library's refusals of a track file name the options and the format.
WORDS = {"focal": "--focal", "cx": "--cx", "format": "see estimate --help"}


def read_file(path: str, limits: track_files.Limits, focal=None, cx=None):
    """:func:`depthcore.registry.track_files.read` of ``--mu-file`` (``-``: standard input).

    Returns
    -------
    depthcore.registry.track_files.TrackFile

    Raises
    ------
    depthcore.registry.track_files.FileRefusal
        A malformed file, ``FILE:LINE: why``.
    ValueError
        Naming ``--focal``, ``--cx`` or ``--mu-file`` (a file that cannot be read).
    """
    if (focal is None) != (cx is None):
        raise ValueError(f"{'--cx' if cx is None else '--focal'} is needed with the other")
    if focal is not None:
        for flag, value in (("--focal", focal), ("--cx", cx)):
            if not (math.isfinite(value) and abs(value) <= limits.pixels):
                raise ValueError(
                    f"{flag} must be finite and at most {limits.pixels:g} in magnitude, got "
                    f"{value!r}"
                )
        if not focal > 0:
            raise ValueError(f"--focal must be positive, got {focal!r}")
    if path == "-":
        stream = getattr(sys.stdin, "buffer", None)
        if stream is None:  # a text stream put in standard input's place
            stream = io.BytesIO(sys.stdin.read().encode())
        return track_files.read("-", stream, limits, focal, cx, WORDS)
    try:
        with open(path, "rb") as stream:
            return track_files.read(path, stream, limits, focal, cx, WORDS)
    except OSError as exc:
        raise ValueError(f"--mu-file: cannot read {path!r}: {exc.strerror or exc}") from None


def from_values(values, limit: float) -> track_files.TrackFile:
    """The track of ``estimate --mu``: 3 to ``MAX_FRAMES`` numbers, ``nan`` a missing frame.

    Raises
    ------
    ValueError
        Naming ``--mu``: too few or too many, infinite, or a magnitude above ``limit``.
    """
    mu = np.array(values, dtype=float)
    if not 3 <= len(mu) <= checks.MAX_FRAMES:
        raise ValueError(
            f"--mu takes at least 3 bearings and at most {checks.MAX_FRAMES} (frames 1 .. N), "
            f"got {len(mu)}"
        )
    big = np.abs(mu[~np.isnan(mu)])
    if np.any(big > limit):
        raise ValueError(
            f"--mu must be finite (or nan, a missing frame) and at most {limit:g} in "
            f"magnitude, got {float(mu[np.abs(mu) > limit][0])!r}"
        )
    return track_files.TrackFile("--mu", mu, None, None, np.arange(1, len(mu) + 1), False)


def check_gate(gate: float) -> float:
    """``--gate``: a probability strictly between 0 and 1."""
    if not (math.isfinite(gate) and 0 < gate < 1):
        raise ValueError(f"--gate must be a probability between 0 and 1 (excluded), got {gate!r}")
    return gate
