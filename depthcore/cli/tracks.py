"""The command line's tracks: ``estimate --mu-file FILE`` and ``--mu``, held whole or streamed.

Recommended import: ``from depthcore.cli import tracks``.

Reading a track file and running it frame by frame are the library's
(:mod:`depthcore.registry.track_files`, :mod:`depthcore.registry.track_runs`);
here are the track's options (:func:`add_arguments`) and their checks in the
user's words (``--focal``, ``--cx``, ``--cy``, ``--mu``, ``--nu``, ``--steps``,
``--direction``, ``--speed``, ``--gate``), standard input for ``-``, the format and the
direction's convention as ``estimate --help`` shows them (:data:`FORMAT`), and
the rows of a long track spooled to temporary files (:func:`spool`), so that
its output is printed whole once every frame is answered, in constant memory.
"""

from __future__ import annotations

import io
import json
import math
import sys
import tempfile

import numpy as np

from depthcore.problem import checks
from depthcore.registry import online, track_files, track_runs

#: The track file's format and the direction's convention, as ``estimate --help`` shows them.
FORMAT = f"""\
The track file of --mu-file (CSV, UTF-8, LF or CRLF line ends; - reads standard
input): a header naming the columns, then one row per frame in time order.
  mu      the bearing (tangent of the angle from the direction of motion); or
  u       the image column in pixels instead of mu, with --focal and --cx:
          mu = (u - cx) / focal (a pixel noise s is rho = s / focal)
  nu      optional, with mu: the vertical bearing h / y, making each frame a
          pair, a point in 3-D (below); or
  v       the image row in pixels, with u and --cy: nu = (v - cy) / focal
  rho     optional: the noise SD of each frame's bearing (in mu's units);
          without it, --rho for every frame
  frame   optional: the frame number, strictly increasing integers; without a
          distance column a gap in the numbers is that many missing frames
and at most one distance column, which gives the steps (without: unit steps):
  step    the depth's change since the previous frame (the first row's empty)
  travel  the distance moved along the line of sight since the first row (0 there)
  time    the time in seconds, strictly increasing: a step is --speed V (the
          depth's change per second) times the time since the previous row
An empty field or nan in mu (or u) is a missing frame: the filter predicts
through it (its rho may be empty too); a pair has both or neither.

The direction. A step is the depth's change: + while the point recedes (the
camera moves away from it), - while it approaches (the camera moves towards
it). Distances (a step, travel or time column, or --steps) need --direction:
receding or approaching (the distances are then positive magnitudes) or signed
(the step or travel column's own signs). Without distances the frames are unit
steps receding, the paper's; every output names the direction it used.

Pairs (a nu or v column, or --nu): the point (x, y, v) and its height h and
vertical velocity w (h measured as the rows grow), the noise rho on each
bearing. The filters that take them are
{", ".join(track_runs.spatial_names())},
on a prior of five coordinates (below); --per-frame streams them through the
online filters; --smooth gives the exact filter's smoother of them; --learn-noise
does not take them yet.

Up to {checks.MAX_FRAMES} frames are held whole, as the summary, --smooth and --learn-noise
need; --per-frame streams a longer file through the online filters ({", ".join(online.NAMES)}):
each frame's filtered state, without the smoothed one."""

#: How the library's refusals of a track file name the options and the format.
WORDS = {
    "focal": "--focal",
    "cx": "--cx",
    "cy": "--cy",
    "format": "see estimate --help",
    "long": "--per-frame streams a longer one through the online filters",
}


def add_arguments(parser, given) -> None:
    """The track's options of ``estimate``: ``--mu-file`` in the group ``given``, and the rest."""
    given.add_argument(
        "--mu-file",
        metavar="FILE",
        help="read the bearings from a CSV file instead (- for standard input; its format below)",
    )
    parser.add_argument(
        "--focal", type=float, metavar="F", help="the focal length in pixels, for columns u, v"
    )
    parser.add_argument(
        "--cx", type=float, metavar="C", help="the principal point's column in pixels, for u"
    )
    parser.add_argument(
        "--cy", type=float, metavar="C", help="the principal point's row in pixels, for v"
    )
    parser.add_argument(
        "--nu",
        type=float,
        nargs="+",
        metavar="N",
        help="with --mu: the vertical bearings nu1 nu2 ... (h / y), one per mu (nan where "
        "mu is): a point in 3-D",
    )
    parser.add_argument(
        "--steps",
        type=float,
        nargs="+",
        metavar="S",
        help="with --mu: the depth's change from each frame to the next (N - 1 of them; "
        "default 1 each), with --direction",
    )
    parser.add_argument(
        "--direction",
        choices=track_files.DIRECTIONS,
        help="how the distances are read: receding (the camera moves away from the point: "
        "the depth grows) or approaching (it moves towards the point) with positive "
        "distances, or signed (+ receding, - approaching); needed with distances, receding "
        "without (below)",
    )
    parser.add_argument(
        "--speed",
        type=float,
        metavar="V",
        help="for a file's time column: the depth's change per second, a magnitude",
    )


def read_file(path: str, limits: track_files.Limits, options: dict) -> track_files.Held:
    """:func:`depthcore.registry.track_files.hold` of ``--mu-file`` (``-``: standard input).

    ``options`` holds ``focal``, ``cx``, ``cy``, ``direction`` and ``speed`` as given.

    Returns
    -------
    depthcore.registry.track_files.Held
        The track whole, or past :data:`depthcore.problem.checks.MAX_FRAMES`
        frames its frames row by row (the file open until they are read, or
        until their ``close()``).

    Raises
    ------
    depthcore.registry.track_files.FileRefusal
        A malformed file, ``FILE:LINE: why``.
    ValueError
        Naming ``--mu-file`` (a file that cannot be read), or ``focal``, ``cx``,
        ``cy``, ``speed`` and ``direction`` as the library does (the command line
        names them as its options, :data:`depthcore.cli.refusals.FLAGS`).
    """
    if path == "-":
        stream = getattr(sys.stdin, "buffer", None)
        if stream is None:  # a text stream put in standard input's place
            stream = io.BytesIO(sys.stdin.read().encode())
    else:
        try:
            stream = open(path, "rb")  # noqa: SIM115 - closed once its frames are read
        except OSError as exc:
            raise ValueError(f"--mu-file: cannot read {path!r}: {exc.strerror or exc}") from None
    close = (lambda: None) if path == "-" else stream.close  # standard input is left open
    try:
        pixels = options["focal"], options["cx"]
        args = (limits, *pixels, WORDS, options["direction"], options["speed"], options["cy"])
        held = track_files.hold(track_files.open_track(path, stream, *args))
    except BaseException:
        close()
        raise
    if held.track is not None:
        close()
        return held
    return held._replace(reading=held.reading._replace(frames=_Closing(held.reading.frames, close)))


class _Closing:
    """A long track's frames, row by row; its file closed at the end or by :meth:`close`."""

    def __init__(self, frames, close):
        self.frames, self.close = frames, close

    def __iter__(self):
        return self

    def __next__(self):
        try:
            return next(self.frames)
        except BaseException:
            self.close()
            raise


def labeller(track: track_files.TrackFile):
    """``label(k)``: the name of frame ``k`` (from 1) of ``track``, its number and time."""

    def label(k: int):
        if not 1 <= k <= len(track.frames):
            return k
        time = "" if track.times is None else f" (t = {track.times[k - 1]:.6g} s)"
        return f"{track.frames[k - 1]}{time}"

    return label


def from_values(
    values, limit: float, steps=None, direction=None, step_range=(0, math.inf), nu=None
):
    """The track of ``estimate --mu``: 3 to ``MAX_FRAMES`` numbers, ``nan`` a missing frame.

    ``steps`` (``--steps``, N - 1 numbers) are read in ``direction``
    (``--direction``; needed with them) as a track file's step column is
    (:mod:`depthcore.registry.track_files`), their magnitudes in ``step_range``.
    ``nu`` (``--nu``, N numbers, ``nan`` where ``mu`` is) makes the track pairs
    ``(mu, nu)`` of shape (N, 2).

    Returns
    -------
    depthcore.registry.track_files.TrackFile

    Raises
    ------
    ValueError
        Naming ``--mu`` or ``--nu``: too few or too many, infinite, or a magnitude
        above ``limit``; ``--steps`` or ``--direction``.
    """
    mu = np.array(values, dtype=float)
    if nu is not None:
        nu = np.array(nu, dtype=float)
        if len(nu) != len(mu):
            raise ValueError(f"--nu takes one vertical bearing per --mu ({len(mu)}), got {len(nu)}")
        if np.any(np.isnan(nu) != np.isnan(mu)):
            raise ValueError("--nu must be nan exactly where --mu is: a missing frame has neither")
        if np.any(np.abs(nu[~np.isnan(nu)]) > limit):
            raise ValueError(f"--nu must be finite (or nan) and at most {limit:g} in magnitude")
    if not 3 <= len(mu) <= checks.MAX_FRAMES:
        raise ValueError(
            f"--mu takes at least 3 bearings and at most {checks.MAX_FRAMES} (frames 1 .. N), "
            f"got {len(mu)} (a longer track: --mu-file with --per-frame)"
        )
    big = np.abs(mu[~np.isnan(mu)])
    if np.any(big > limit):
        raise ValueError(
            f"--mu must be finite (or nan, a missing frame) and at most {limit:g} in "
            f"magnitude, got {float(mu[np.abs(mu) > limit][0])!r}"
        )
    signs = {"receding": 1.0, "approaching": -1.0, "signed": 1.0}
    if steps is None:
        if direction == "signed":
            raise ValueError(
                "--direction signed takes the signs of --steps, and none are given; say "
                "receding or approaching"
            )
        s = None if direction in (None, "receding") else -np.ones(len(mu) - 1)
    else:
        s = np.array(steps, dtype=float)
        if direction is None:
            raise ValueError(
                "--direction is needed with --steps: say receding (the camera moves away from "
                "the point), approaching (towards it) or signed (the steps' own signs)"
            )
        if len(s) != len(mu) - 1:
            raise ValueError(
                f"--steps takes one step per pair of consecutive frames, {len(mu) - 1} for "
                f"{len(mu)} bearings, got {len(s)}"
            )
        size = np.abs(s) if direction == "signed" else s
        bad = ~((step_range[0] <= size) & (size <= step_range[1]))
        if np.any(bad):
            raise ValueError(
                f"--steps must be from {step_range[0]:g} to {step_range[1]:g} "
                + ("in magnitude, nonzero" if direction == "signed" else f"({direction}: ")
                + ("" if direction == "signed" else "magnitudes)")
                + f", got {float(s[bad][0])!r}"
            )
        s = signs[direction] * s
    numbers = np.arange(1, len(mu) + 1)
    mu = mu if nu is None else np.stack([mu, nu], axis=-1)
    return track_files.TrackFile("--mu", mu, None, s, numbers, False, None, direction or "receding")


def check_gate(gate: float) -> float:
    """``--gate``: a probability strictly between 0 and 1."""
    if not (math.isfinite(gate) and 0 < gate < 1):
        raise ValueError(f"--gate must be a probability between 0 and 1 (excluded), got {gate!r}")
    return gate


def spool(rows, names) -> tuple[int, dict]:
    """Each filter's rows written to a temporary file as they come, then read back.

    Parameters
    ----------
    rows : iterable of dict
        ``{name: row}`` per frame (:func:`depthcore.registry.track_runs.streamed`).
    names : sequence of str
        The filters, in the order of the output.

    Returns
    -------
    frames : int
        The number of frames.
    blocks : dict
        By filter, its rows read back one at a time (each file removed once read).
    """
    files = {name: tempfile.TemporaryFile("w+", encoding="utf-8") for name in names}
    try:
        frames = 0
        for by_filter in rows:
            frames += 1
            for name, row in by_filter.items():
                files[name].write(json.dumps(row) + "\n")
    except BaseException:
        for f in files.values():
            f.close()
        raise
    return frames, {name: _read_back(f) for name, f in files.items()}


def _read_back(f):
    """The rows of a spooled file, one at a time; the file closed (removed) at the end."""
    try:
        f.seek(0)
        for line in f:
            yield json.loads(line)
    finally:
        f.close()
