"""Track files: one track's bearings over frames read from CSV, row by row or held whole.

Recommended import: ``from depthcore.registry import track_files``.

:func:`open_track` reads a track file's header from a binary stream and then
gives its frames one at a time (:class:`Frame`), each row checked where it
stands with the standard ``csv`` module, so that time and memory do not grow
with the file (a line may hold at most :data:`MAX_LINE` characters).
:func:`read` holds the whole track (:class:`TrackFile`), at most
:data:`depthcore.problem.checks.MAX_FRAMES` frames, the limit of the filters
that need it; :func:`hold` holds it only if it fits. :func:`read_path` reads
the file at a path. A malformed file is refused in one line naming the file
and the line, ``FILE:LINE: ...`` (:class:`FileRefusal`, a ``ValueError``).

The format: UTF-8 text (a UTF-8 byte order mark is allowed), lines ending in
LF or CRLF, a header naming the columns (:data:`COLUMNS`), then one row per
frame in time order:

* ``mu``: the bearing (tangent of the angle from the direction of motion); or
* ``u``: the image column in pixels instead of ``mu``, with ``focal`` and
  ``cx``: ``mu = (u - cx) / focal``;
* ``nu`` with ``mu``, or ``v`` with ``u`` (and ``cy``, the principal point's
  row): the vertical bearing ``h / y``, ``nu = (v - cy) / focal``, which makes
  each frame a pair, a point in 3-D (:mod:`depthcore.problem.bearing_pairs`;
  ``h`` measured the way the rows grow);
* ``rho`` (optional): the noise SD of each frame's bearing;
* ``frame`` (optional): the frame number, strictly increasing integers;
  without a distance column a gap in the numbers is that many missing frames
  (at most :data:`MAX_GAP` in a row);
* at most one distance column (:data:`DISTANCES`), which gives the steps
  (without one, unit steps): ``step``, the depth's change since the previous
  frame (the first row's empty); ``travel``, the distance moved along the
  line of sight since the first row (0 there); or ``time``, in seconds,
  strictly increasing, the step being ``speed`` times the time between rows.

An empty field or ``nan`` in ``mu`` (or ``u``) is a missing frame (its
``rho`` may be empty too); a pair has both coordinates or neither.

The direction. A step is the depth's signed change between frames
(:mod:`depthcore.problem.frames`): positive while the point recedes (the
camera moves away from it), negative while it approaches (the camera moves
towards it), never zero. A file's distances are read in the ``direction``
given (:data:`DIRECTIONS`): ``"receding"`` or ``"approaching"`` take its
step, travel or time amounts as positive magnitudes and give them that sign;
``"signed"`` takes the signs of its step or travel column. A file with a
distance column is refused without a direction, so that a camera moving
towards the scene is never read as one moving away; without one the frames
are unit steps, receding unless ``direction`` says otherwise (the paper's
frames).
"""

from __future__ import annotations

import csv
import itertools
import math
import os
import re
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from depthcore.problem import checks

#: The most characters of one line of a track file (a row holds a few numbers).
MAX_LINE = 4096

#: The columns a track file may name, in the order ``estimate --help`` explains them.
COLUMNS = ("mu", "nu", "u", "v", "rho", "frame", "step", "travel", "time")

#: The columns that give the steps; a file names at most one.
DISTANCES = ("step", "travel", "time")

#: How a file's distances are read, their sign given or their own.
DIRECTIONS = ("receding", "approaching", "signed")

#: The most missing frames in a row that a gap between frame numbers may stand for.
MAX_GAP = checks.MAX_FRAMES

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_INTEGER = re.compile(r"^[+-]?\d+$")


class FileRefusal(ValueError):
    """A refusal of a track file as it stands: ``FILE:LINE: why`` or ``FILE: why``."""


#: The names of a track's arrays (:func:`depthcore.registry.tracking.track`'s arguments)
#: and the columns of a track file that give them.
LIBRARY_NAMES = {"mu": "mu", "rho": "rho", "steps": "step"}


class TrackFile(NamedTuple):
    """A track held whole (:func:`read`).

    Attributes
    ----------
    name : str
        The file as the user named it (``<stdin>`` for ``-``).
    mu : ndarray, shape (N,) or (N, 2)
        Bearings, ``NaN`` at a missing frame; pairs ``(mu, nu)`` with a ``nu``
        or ``v`` column.
    rho : ndarray, shape (N,), or None
        The ``rho`` column (``NaN`` where empty, only at missing frames); ``None``
        without one.
    steps : ndarray, shape (N - 1,), or None
        The depth's signed change from each frame to the next; ``None`` for unit
        steps receding (the paper's frames).
    frames : ndarray of int, shape (N,)
        The frame numbers: the ``frame`` column with the missing frames filled
        in, else ``1 .. N``.
    pixels : bool
        Whether the bearings came from a ``u`` column (and ``v``).
    times : ndarray, shape (N,), or None
        The ``time`` column, in seconds; ``None`` without one.
    direction : str
        How the distances were read, one of :data:`DIRECTIONS`.
    """

    name: str
    mu: np.ndarray
    rho: np.ndarray | None
    steps: np.ndarray | None
    frames: np.ndarray
    pixels: bool
    times: np.ndarray | None = None
    direction: str = "receding"


class Frame(NamedTuple):
    """One frame of a track file (:func:`open_track`).

    Attributes
    ----------
    frame : int
        Its number: the ``frame`` column's (missing frames between numbers
        filled in), else 1, 2, ... in the order of the rows.
    time : float
        The ``time`` column's value in seconds; ``NaN`` without one.
    mu : float
        The bearing; ``NaN`` at a missing frame.
    rho : float
        The ``rho`` column's value; ``NaN`` without one or where empty.
    step : float
        The depth's signed change since the previous frame; ``NaN`` at the first.
    line : int
        The line of the file that gave it (for a frame missing between frame
        numbers, the next row's).
    nu : float
        The vertical bearing of a pair (``NaN`` at a missing frame or without one).
    """

    frame: int
    time: float
    mu: float
    rho: float
    step: float
    line: int
    nu: float = math.nan


class Reading(NamedTuple):
    """A track file opened by :func:`open_track`: what its header says, then its frames.

    Attributes
    ----------
    name : str
        The file as the user named it (``<stdin>`` for ``-``).
    columns : tuple of str
        The header's columns.
    direction : str
        How the distances are read, one of :data:`DIRECTIONS`.
    frames : iterator of Frame
        The frames, each read and checked as it is asked for.
    """

    name: str
    columns: tuple
    direction: str
    frames: Iterator[Frame]

    @property
    def pairs(self) -> bool:
        """Whether each frame is a pair ``(mu, nu)``: a ``nu`` or a ``v`` column."""
        return bool({"nu", "v"} & set(self.columns))


class Limits(NamedTuple):
    """The ranges :func:`read` checks each field against.

    Attributes
    ----------
    mu : float
        The largest magnitude of a bearing (of ``mu``, or of ``(u - cx) / focal``).
    rho : (float, float)
        The range of a ``rho`` field.
    step : (float, float)
        The range of a step's magnitude, whichever column gives it.
    pixels : float
        The largest magnitude of ``focal``, ``cx`` and ``cy``.
    """

    mu: float
    rho: tuple
    step: tuple
    pixels: float


#: The most empty lines after the last row (more are refused, so the reading stays short).
MAX_TRAILING_BLANKS = 100


#: How :func:`read`'s refusals name ``focal``, ``cx``, where the format is described and
#: what takes a track longer than the filters that hold it.
WORDS = {
    "focal": "focal",
    "cx": "cx",
    "cy": "cy",
    "format": "see depthcore.registry.track_files",
    "long": "depthcore.registry.track_runs.streamed runs a longer one frame by frame",
}


def _lines(stream, name: str, counter: list):
    """The decoded lines of a binary ``stream``, each at most :data:`MAX_LINE` characters.

    ``counter[0]`` is the number of the line last read (1-based).
    """
    long = f"a line longer than {MAX_LINE} characters; a row holds a few numbers"
    while True:
        raw = stream.readline(4 * MAX_LINE + 2)
        if not raw:
            return
        counter[0] += 1
        if len(raw) > 4 * MAX_LINE and not raw.endswith(b"\n"):
            raise FileRefusal(f"{name}:{counter[0]}: {long}")
        if counter[0] == 1 and raw.startswith(b"\xef\xbb\xbf"):  # UTF-8's byte order mark
            raw = raw[3:]
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise FileRefusal(
                f"{name}:{counter[0]}: not UTF-8 text (a binary file, or text in another "
                "encoding); a track file is CSV text"
            ) from None
        if len(line.rstrip("\r\n")) > MAX_LINE:
            raise FileRefusal(f"{name}:{counter[0]}: {long}")
        yield line


def _number(text: str, column: str, where: str) -> float:
    """A field's decimal number; ``NaN`` for an empty field or ``nan``."""
    text = text.strip()
    if text == "" or text.lower() == "nan":
        return math.nan
    if not _NUMBER.match(text):
        raise FileRefusal(f"{where}: {column} must be a number, got {text!r}")
    return float(text)


def open_track(
    path: str,
    stream,
    limits: Limits,
    focal=None,
    cx=None,
    words=None,
    direction=None,
    speed=None,
    cy=None,
) -> Reading:
    """Read a track file's header; its frames follow, each checked as it is read.

    Parameters
    ----------
    path : str
        The file as the user named it, for the messages (``-``: standard input).
    stream : binary file object
        The open file, read line by line.
    limits : Limits
        The ranges of the fields.
    focal, cx : float or None
        The focal length (> 0) and the principal point's column in pixels, for a
        ``u`` column (both or neither; finite, at most ``limits.pixels`` in magnitude).
    words : dict, optional
        How the refusals name ``focal``, ``cx``, the format and what takes a
        longer track (the keys of :data:`WORDS`, its values by default).
    direction : str or None
        One of :data:`DIRECTIONS` (module docstring); needed with a distance
        column, ``"receding"`` without one by default.
    speed : float or None
        With a ``time`` column (and only then): the depth's rate of change per
        second, a magnitude (> 0).
    cy : float or None
        The principal point's row in pixels, for a ``v`` column (with ``focal``).

    Returns
    -------
    Reading

    Raises
    ------
    FileRefusal
        ``FILE:LINE: why``, when the header is read or, as they are read, of the rows.
    ValueError
        Naming ``path``, ``limits``, ``focal``, ``cx``, ``cy``, ``words``, ``direction``
        or ``speed`` when it is not of its form or the file needs another.
    """
    if not isinstance(path, str):
        raise ValueError(f"path must be a string, got {type(path).__name__}")
    if not isinstance(limits, Limits):
        raise ValueError(f"limits must be a track_files.Limits, got {type(limits).__name__}")
    _check_pixels(focal, cx, cy, limits.pixels)
    words = {**WORDS, **(words or {})}
    if set(words) != set(WORDS):
        raise ValueError(f"words takes the keys {', '.join(WORDS)}, got {sorted(words)}")
    name = "<stdin>" if path == "-" else path
    counter = [0]
    reader = csv.reader(_lines(stream, name, counter), strict=True)
    try:
        row = next(reader, None)
    except csv.Error as exc:
        raise FileRefusal(f"{name}:{counter[0]}: not CSV: {exc}") from None
    if row is None:
        raise FileRefusal(
            f"{name}:1: an empty file; the first line names the columns, of "
            f"{', '.join(COLUMNS)} ({words['format']})"
        )
    columns = _header(row, f"{name}:1", (focal is not None, cy is not None), words)
    direction = _direction(columns, name, direction, speed)
    rows = _frames(reader, name, counter, columns, (limits, (focal, cx, cy), direction, speed))
    return Reading(name, tuple(columns), direction, rows)


def _direction(columns: list, name: str, direction, speed) -> str:
    """``direction`` checked against the file's distance column; ``speed`` against its time."""
    given = [c for c in DISTANCES if c in columns]
    if len(given) > 1:
        raise FileRefusal(
            f"{name}:1: the header names {given[0]} and {given[1]}; give one of "
            f"{', '.join(DISTANCES)} (each gives the steps)"
        )
    kind = given[0] if given else None
    if direction is not None and direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {', '.join(DIRECTIONS)}, got {direction!r}")
    if kind == "time" and speed is None:
        raise ValueError(
            f"speed is needed: {name} has a time column, and a step is the speed times the "
            "time between rows"
        )
    if kind != "time" and speed is not None:
        raise ValueError(f"speed: not used: {name} has no time column; leave it out")
    if speed is not None and not (
        isinstance(speed, (int, float, np.integer, np.floating))
        and math.isfinite(speed)
        and speed > 0
    ):
        raise ValueError(
            f"speed must be a positive number (the depth's change per second, a magnitude: "
            f"the direction gives its sign), got {speed!r}"
        )
    if direction is None and kind is not None:
        signed = "" if kind == "time" else f", or signed (the {kind} column's own signs)"
        raise ValueError(
            f"direction is needed: {name} has a {kind} column; say receding (the point's "
            f"depth grows: the camera moves away from it), approaching (the camera moves "
            f"towards it){signed}"
        )
    if direction == "signed" and kind in (None, "time"):
        raise ValueError(
            f"direction signed takes the signs of a step or travel column, and {name} has "
            f"{'a time column' if kind else 'no distances'}; say receding or approaching"
        )
    return direction or "receding"


def _frames(reader, name: str, counter: list, columns: list, how: tuple) -> Iterator[Frame]:
    """The frames of the rows after the header (:func:`open_track`), missing ones filled in."""
    limits, pixels, direction, speed = how
    sign = -1.0 if direction == "approaching" else 1.0
    distance = next((c for c in DISTANCES if c in columns), None)
    previous, blank = None, None
    try:
        for row in reader:
            where = f"{name}:{counter[0]}"
            if not row:  # an empty line: allowed at the end only
                blank = blank or counter[0]
                if counter[0] - blank >= MAX_TRAILING_BLANKS:
                    raise FileRefusal(f"{where}: more than {MAX_TRAILING_BLANKS} empty lines")
                continue
            if blank is not None:
                raise FileRefusal(f"{name}:{blank}: an empty line; give one row per frame")
            if len(row) != len(columns):
                raise FileRefusal(
                    f"{where}: {len(row)} fields, but the header names {len(columns)} columns"
                )
            values = _row(dict(zip(columns, row, strict=True)), where, limits, pixels)
            number = values.get("frame", 1 if previous is None else previous["frame"] + 1)
            values["frame"] = number
            step = math.nan
            if previous is not None:
                if number <= previous["frame"]:
                    raise FileRefusal(
                        f"{where}: frame must increase strictly, got {number} after "
                        f"{previous['frame']}"
                    )
                if distance is None:
                    step = sign
                    yield from _gap(previous["frame"], number, sign, where, counter[0])
                else:
                    step = _step(distance, values, previous, where, limits, direction, speed)
            elif distance is not None:
                _first(distance, values, where)
            previous = values
            time = values.get("time", math.nan)
            rho, nu = values.get("rho", math.nan), values.get("nu", math.nan)
            yield Frame(number, time, values["mu"], rho, step, counter[0], nu)
    except csv.Error as exc:
        raise FileRefusal(f"{name}:{counter[0]}: not CSV: {exc}") from None
    if previous is None:
        raise FileRefusal(f"{name}:{counter[0] + 1}: no frames after the header")


def _gap(last: int, number: int, sign: float, where: str, line: int) -> Iterator[Frame]:
    """The missing frames between frame numbers ``last`` and ``number``, unit steps apart."""
    if number - last - 1 > MAX_GAP:
        raise FileRefusal(
            f"{where}: frame jumps from {last} to {number}, more than {MAX_GAP} missing "
            "frames in a row; a step, travel or time column spans a gap in one step"
        )
    for k in range(last + 1, number):
        yield Frame(k, math.nan, math.nan, math.nan, sign, line)


def _first(distance: str, values: dict, where: str) -> None:
    """Refuse a first row whose step is not empty or whose travel is not 0."""
    value = values[distance]
    if distance == "step" and not math.isnan(value):
        raise FileRefusal(
            f"{where}: the first row's step must be empty (step is the depth's change since "
            f"the previous frame), got {value:g}"
        )
    if distance == "travel" and value != 0:
        raise FileRefusal(
            f"{where}: the first row's travel must be 0 (travel is the distance moved since "
            f"the first row), got {value:g}"
        )


def _step(distance: str, values, previous, where: str, limits, direction: str, speed) -> float:
    """The depth's signed change since the previous row, from the file's distance column."""
    lo, hi = limits.step
    value = values[distance]
    signed = direction == "signed"
    amount = value if distance == "step" else value - previous[distance]
    if distance == "time":
        if not amount > 0:
            raise FileRefusal(
                f"{where}: time must increase strictly, got {value:g} after {previous['time']:g}"
            )
        amount *= speed
        if not lo <= amount <= hi:
            raise FileRefusal(
                f"{where}: time gives a step of {amount:.6g} (speed times the "
                f"{value - previous['time']:g} s since the previous row); a step must be "
                f"from {lo:g} to {hi:g}"
            )
    elif not lo <= (abs(amount) if signed else amount) <= hi:  # an empty step (NaN) too
        size = (
            "in magnitude (its sign the direction: + receding, - approaching)"
            if signed
            else f"(a magnitude: the direction, {direction}, gives the sign)"
        )
        if distance == "step":
            got = "an empty field" if math.isnan(value) else f"{value:g}"
            raise FileRefusal(
                f"{where}: step must be from {lo:g} to {hi:g} {size}, the depth's change since "
                f"the previous frame; got {got}"
            )
        raise FileRefusal(
            f"{where}: travel must change by {lo:g} to {hi:g} {size} from row to row, the "
            f"distance moved since the first row; got {value:g} after {previous['travel']:g}"
        )
    return -amount if direction == "approaching" else amount


def read(
    path: str,
    stream,
    limits: Limits,
    focal=None,
    cx=None,
    words=None,
    direction=None,
    speed=None,
    cy=None,
) -> TrackFile:
    """Read a whole track file, checking every field where it stands.

    The arguments are :func:`open_track`'s. A file of more than
    :data:`depthcore.problem.checks.MAX_FRAMES` frames is refused at the line
    that passes the limit, the rest unread.

    Returns
    -------
    TrackFile

    Raises
    ------
    FileRefusal, ValueError
        As :func:`open_track`'s.
    """
    reading = open_track(path, stream, limits, focal, cx, words, direction, speed, cy)
    held = hold(reading)
    if held.track is None:
        words = {**WORDS, **(words or {})}
        raise FileRefusal(
            f"{reading.name}:{held.first[-1].line}: more than {checks.MAX_FRAMES} frames, "
            f"the most the filters that hold a whole track take ({words['long']})"
        )
    return held.track


class Held(NamedTuple):
    """A track held whole if it fits (:func:`hold`).

    Attributes
    ----------
    track : TrackFile or None
        The whole track, or ``None`` past the limit.
    reading : Reading
        The track's reading; past the limit its ``frames`` are every frame,
        row by row, from the first (those of ``first`` read already).
    first : list of Frame or None
        Past the limit, its first ``limit + 1`` frames.
    """

    track: TrackFile | None
    reading: Reading
    first: list | None


def hold(reading: Reading, limit: int = checks.MAX_FRAMES) -> Held:
    """The track of ``reading`` whole if it has at most ``limit`` frames, else row by row.

    At most ``limit + 1`` frames are read before the answer.
    """
    first = list(itertools.islice(reading.frames, limit + 1))
    if len(first) <= limit:
        return Held(assemble(reading, first), reading, None)
    return Held(None, reading._replace(frames=itertools.chain(first, reading.frames)), first)


def assemble(reading: Reading, frames: list) -> TrackFile:
    """The :class:`TrackFile` of a list of ``reading``'s frames."""
    time, mu, rho, step = np.array([f[1:5] for f in frames], dtype=float).reshape(-1, 4).T
    if reading.pairs:
        mu = np.stack([mu, np.array([f.nu for f in frames], dtype=float)], axis=-1)
    steps = step[1:]
    if not set(DISTANCES) & set(reading.columns) and reading.direction == "receding":
        steps = None  # unit steps receding: the paper's frames
    return TrackFile(
        reading.name,
        mu,
        rho if "rho" in reading.columns else None,
        steps,
        np.array([f.frame for f in frames], dtype=int),
        "u" in reading.columns,
        time if "time" in reading.columns else None,
        reading.direction,
    )


def _check_pixels(focal, cx, cy, largest: float) -> None:
    """Refuse ``focal`` and ``cx`` unless both are None or both finite numbers, ``focal > 0``;
    ``cy`` unless None or, with them, finite."""
    if (focal is None) != (cx is None):
        raise ValueError(f"{'cx' if cx is None else 'focal'} is needed with the other")
    if cy is not None and focal is None:
        raise ValueError("cy is for a v column (pixel rows), with focal and cx; give them too")
    if focal is None:
        return
    for argument, value in (("focal", focal), ("cx", cx), ("cy", cy)):
        if value is not None and not (
            isinstance(value, (int, float, np.integer, np.floating))
            and math.isfinite(value)
            and abs(value) <= largest
        ):
            raise ValueError(
                f"{argument} must be finite and at most {largest:g} in magnitude, got {value!r}"
            )
    if not focal > 0:
        raise ValueError(f"focal must be positive, got {focal!r}")


def read_path(
    path, limits: Limits, focal=None, cx=None, direction=None, speed=None, cy=None
) -> TrackFile:
    """:func:`read` of the file at ``path`` (a str or os.PathLike).

    ``limits``, ``focal``, ``cx``, ``direction``, ``speed`` and ``cy``, the
    :class:`TrackFile` and the :class:`FileRefusal` of a malformed file are
    :func:`read`'s; a ``ValueError`` names ``path`` when the file cannot be
    opened or read.
    """
    try:
        text = os.fspath(path)
    except TypeError:
        raise ValueError(f"path must be a file's path, got {type(path).__name__}") from None
    try:
        with open(text, "rb") as stream:
            return read(str(text), stream, limits, focal, cx, None, direction, speed, cy)
    except OSError as exc:
        raise ValueError(f"path: cannot read {text!r}: {exc.strerror or exc}") from None


def _header(row: list, where: str, pixels: tuple, words: dict) -> list:
    """The header's column names, checked; ``pixels``: whether focal and cx, and cy, are given."""
    names = [c.strip() for c in row]
    if not any(names):
        raise FileRefusal(
            f"{where}: an empty first line; the first line names the columns, of "
            f"{', '.join(COLUMNS)} ({words['format']})"
        )
    unknown = [c for c in names if c not in COLUMNS]
    if unknown:
        raise FileRefusal(
            f"{where}: no header or an unknown column {unknown[0]!r}; the first line names the "
            f"columns, of {', '.join(COLUMNS)} ({words['format']})"
        )
    repeated = sorted({c for c in names if names.count(c) > 1})
    if repeated:
        raise FileRefusal(f"{where}: the header names {repeated[0]!r} more than once")
    if ("mu" in names) == ("u" in names):
        raise FileRefusal(
            f"{where}: the header must name either a mu column or a u column (pixels)"
        )
    if "u" in names and not pixels[0]:
        raise FileRefusal(f"{where}: a u column (pixels) needs {words['focal']} and {words['cx']}")
    if "mu" in names and pixels[0]:
        raise FileRefusal(
            f"{where}: {words['focal']} and {words['cx']} are for a u column; this file has mu"
        )
    if ("nu" in names and "u" in names) or ("v" in names and "mu" in names):
        raise FileRefusal(f"{where}: a pair's columns are mu and nu, or u and v (pixels)")
    if ("v" in names) != pixels[1]:
        raise FileRefusal(
            f"{where}: a v column (pixel rows) needs {words['cy']}"
            if "v" in names
            else f"{where}: {words['cy']} is for a v column (pixel rows); this file has none"
        )
    return names


def _row(fields: dict, where: str, limits: Limits, pixels: tuple) -> dict:
    """One row's numbers, checked: ``mu`` (from ``u``), ``nu`` (from ``v``), ``rho``, ``frame``,
    a distance; ``pixels`` is ``(focal, cx, cy)``."""
    focal, cx, cy = pixels
    out = {}
    for column, raw in fields.items():
        text = raw.strip()
        if column == "frame":
            if not _INTEGER.match(text) or len(text) > 18:
                raise FileRefusal(f"{where}: frame must be an integer, got {text!r}")
            out["frame"] = int(text)
            continue
        value = _number(text, column, where)
        if column in ("u", "v") and not math.isnan(value):
            centre, axis = (cx, "cx") if column == "u" else (cy, "cy")
            value = (value - centre) / focal
            if not abs(value) <= limits.mu:
                raise FileRefusal(
                    f"{where}: {column} gives a bearing ({column} - {axis}) / focal of magnitude "
                    f"more than {limits.mu:g}, got {column} = {text}"
                )
        elif column in ("mu", "nu") and not abs(value) <= limits.mu and not math.isnan(value):
            raise FileRefusal(
                f"{where}: {column} must be at most {limits.mu:g} in magnitude, got {text}"
            )
        elif column == "rho" and not math.isnan(value):
            lo, hi = limits.rho
            if not lo <= value <= hi:
                raise FileRefusal(f"{where}: rho must be from {lo:g} to {hi:g}, got {text}")
        elif column in ("travel", "time") and math.isnan(value):
            raise FileRefusal(f"{where}: {column} must be a number at every row, got {text!r}")
        out[{"u": "mu", "v": "nu"}.get(column, column)] = value
    if "nu" in out and math.isnan(out["mu"]) != math.isnan(out["nu"]):
        raise FileRefusal(
            f"{where}: a pair has one coordinate only; give both (a frame with a bearing) or "
            "neither (a missing frame)"
        )
    if "rho" in out and math.isnan(out["rho"]) and not math.isnan(out["mu"]):
        raise FileRefusal(f"{where}: rho is empty at a frame with a bearing")
    return out
