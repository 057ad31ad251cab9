"""Track files: one track's bearings over frames read from CSV, and its frames' states.

Recommended import: ``from depthcore.registry import track_files``.

:func:`read` reads a track file from a binary stream line by line with the
standard ``csv`` module and refuses a malformed file in one line naming the
file and the line, ``FILE:LINE: ...`` (:class:`FileRefusal`, a
``ValueError``). Its time and memory do not grow with the file: it stops as
soon as the rows pass the filters' limit of frames,
:data:`depthcore.problem.checks.MAX_FRAMES`, and a line may hold at most
:data:`MAX_LINE` characters. :func:`read_path` reads the file at a path.

The format: UTF-8 text (a UTF-8 byte order mark is allowed), lines ending in
LF or CRLF, a header naming the columns (:data:`COLUMNS`), then one row per
frame in time order:

* ``mu``: the bearing (tangent of the angle from the direction of motion); or
* ``u``: the image column in pixels instead of ``mu``, with ``focal`` and
  ``cx``: ``mu = (u - cx) / focal``;
* ``rho`` (optional): the noise SD of each frame's bearing;
* ``step`` (optional): the depth's change since the previous frame (> 0; the
  first row's must be empty);
* ``frame`` (optional): the frame number, strictly increasing integers;
  without a ``step`` column a gap in the numbers is that many missing frames.

An empty field or ``nan`` in ``mu`` (or ``u``) is a missing frame (its
``rho`` may be empty too).

:func:`per_frame` runs a track through filters with a smoother and gives
every frame's filtered and smoothed state, ready for JSON; :func:`learn`
estimates its noise levels by maximum likelihood and :func:`learned_json`
gives the fit as JSON values.
"""

from __future__ import annotations

import csv
import math
import os
import re
from typing import NamedTuple

import numpy as np

from depthcore.problem import checks
from depthcore.registry import filters, tracking

#: The most characters of one line of a track file (a row holds a few numbers).
MAX_LINE = 4096

#: The columns a track file may name, in the order ``estimate --help`` explains them.
COLUMNS = ("mu", "u", "rho", "step", "frame")

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_INTEGER = re.compile(r"^[+-]?\d+$")


class FileRefusal(ValueError):
    """A refusal of a track file as it stands: ``FILE:LINE: why`` or ``FILE: why``."""


#: The names of a track's arrays (:func:`depthcore.registry.tracking.track`'s arguments)
#: and the columns of a track file that give them.
LIBRARY_NAMES = {"mu": "mu", "rho": "rho", "steps": "step"}


class TrackFile(NamedTuple):
    """A track read by :func:`read`.

    Attributes
    ----------
    name : str
        The file as the user named it (``<stdin>`` for ``-``).
    mu : ndarray, shape (N,)
        Bearings, ``NaN`` at a missing frame.
    rho : ndarray, shape (N,), or None
        The ``rho`` column (``NaN`` where empty, only at missing frames); ``None``
        without one.
    steps : ndarray, shape (N - 1,), or None
        The ``step`` column from the second row on; ``None`` without one.
    frames : ndarray of int, shape (N,)
        The frame numbers: the ``frame`` column with the missing frames filled
        in, else ``1 .. N``.
    pixels : bool
        Whether the bearings came from a ``u`` column.
    """

    name: str
    mu: np.ndarray
    rho: np.ndarray | None
    steps: np.ndarray | None
    frames: np.ndarray
    pixels: bool


def _lines(stream, name: str, counter: list):
    """The decoded lines of a binary ``stream``, each at most :data:`MAX_LINE` characters.

    ``counter[0]`` is the number of the line last read (1-based).
    """
    while True:
        raw = stream.readline(4 * MAX_LINE + 2)
        if not raw:
            return
        counter[0] += 1
        if len(raw) > 4 * MAX_LINE and not raw.endswith(b"\n"):
            raise FileRefusal(
                f"{name}:{counter[0]}: a line longer than {MAX_LINE} characters; a row "
                "holds a few numbers"
            )
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
            raise FileRefusal(
                f"{name}:{counter[0]}: a line longer than {MAX_LINE} characters; a row "
                "holds a few numbers"
            )
        yield line


def _number(text: str, column: str, where: str) -> float:
    """A field's decimal number; ``NaN`` for an empty field or ``nan``."""
    text = text.strip()
    if text == "" or text.lower() == "nan":
        return math.nan
    if not _NUMBER.match(text):
        raise FileRefusal(f"{where}: {column} must be a number, got {text!r}")
    return float(text)


class Limits(NamedTuple):
    """The ranges :func:`read` checks each field against.

    Attributes
    ----------
    mu : float
        The largest magnitude of a bearing (of ``mu``, or of ``(u - cx) / focal``).
    rho : (float, float)
        The range of a ``rho`` field.
    step : (float, float)
        The range of a ``step`` field.
    pixels : float
        The largest magnitude of ``focal`` and ``cx``.
    """

    mu: float
    rho: tuple
    step: tuple
    pixels: float


#: The most empty lines after the last row (more are refused, so the reading stays short).
MAX_TRAILING_BLANKS = 100


#: How :func:`read`'s refusals name ``focal``, ``cx`` and where the format is described.
WORDS = {"focal": "focal", "cx": "cx", "format": "see depthcore.registry.track_files"}


def read(path: str, stream, limits: Limits, focal=None, cx=None, words=None) -> TrackFile:
    """Read a track file, checking every field where it stands.

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
        How the refusals name ``focal``, ``cx`` and where the format is described
        (the keys of :data:`WORDS`, its values by default).

    Returns
    -------
    TrackFile

    Raises
    ------
    FileRefusal
        ``FILE:LINE: why`` (``FILE: why`` of the whole track).
    ValueError
        Naming ``path``, ``limits``, ``focal``, ``cx`` or ``words`` when it is not of its form.
    """
    if not isinstance(path, str):
        raise ValueError(f"path must be a string, got {type(path).__name__}")
    if not isinstance(limits, Limits):
        raise ValueError(f"limits must be a track_files.Limits, got {type(limits).__name__}")
    _check_pixels(focal, cx, limits.pixels)
    words = {**WORDS, **(words or {})}
    if set(words) != set(WORDS):
        raise ValueError(f"words takes the keys {', '.join(WORDS)}, got {sorted(words)}")
    name = "<stdin>" if path == "-" else path
    counter = [0]
    reader = csv.reader(_lines(stream, name, counter), strict=True)
    rows, columns, blank = [], None, None
    try:
        for row in reader:
            where = f"{name}:{counter[0]}"
            if columns is None:
                columns = _header(row, where, focal is not None, words)
                continue
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
            fields = dict(zip(columns, row, strict=True))
            values = _row(fields, where, limits, focal, cx, first=not rows)
            _in_order(values, rows, columns, where)
            rows.append(values)
    except csv.Error as exc:
        raise FileRefusal(f"{name}:{counter[0]}: not CSV: {exc}") from None
    if columns is None:
        raise FileRefusal(
            f"{name}:1: an empty file; the first line names the columns, of "
            f"{', '.join(COLUMNS)} ({words['format']})"
        )
    if not rows:
        raise FileRefusal(f"{name}:{counter[0] + 1}: no frames after the header")
    return _assemble(name, columns, rows)


def _check_pixels(focal, cx, largest: float) -> None:
    """Refuse ``focal`` and ``cx`` unless both are None or both finite numbers, ``focal > 0``."""
    if (focal is None) != (cx is None):
        raise ValueError(f"{'cx' if cx is None else 'focal'} is needed with the other")
    if focal is None:
        return
    for argument, value in (("focal", focal), ("cx", cx)):
        if not (
            isinstance(value, (int, float, np.integer, np.floating))
            and math.isfinite(value)
            and abs(value) <= largest
        ):
            raise ValueError(
                f"{argument} must be finite and at most {largest:g} in magnitude, got {value!r}"
            )
    if not focal > 0:
        raise ValueError(f"focal must be positive, got {focal!r}")


def read_path(path, limits: Limits, focal=None, cx=None) -> TrackFile:
    """:func:`read` of the file at ``path`` (a str or os.PathLike).

    ``limits``, ``focal`` and ``cx``, the :class:`TrackFile` and the
    :class:`FileRefusal` of a malformed file are :func:`read`'s; a ``ValueError``
    names ``path`` when the file cannot be opened or read.
    """
    try:
        text = os.fspath(path)
    except TypeError:
        raise ValueError(f"path must be a file's path, got {type(path).__name__}") from None
    try:
        with open(text, "rb") as stream:
            return read(str(text), stream, limits, focal, cx)
    except OSError as exc:
        raise ValueError(f"path: cannot read {text!r}: {exc.strerror or exc}") from None


def _header(row: list, where: str, pixels: bool, words: dict) -> list:
    """The header's column names, checked."""
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
    if "u" in names and not pixels:
        raise FileRefusal(f"{where}: a u column (pixels) needs {words['focal']} and {words['cx']}")
    if "mu" in names and pixels:
        raise FileRefusal(
            f"{where}: {words['focal']} and {words['cx']} are for a u column; this file has mu"
        )
    return names


def _row(fields: dict, where: str, limits: Limits, focal, cx, first: bool) -> dict:
    """One row's numbers, checked: ``mu`` (from ``u``), ``rho``, ``step``, ``frame``."""
    out = {}
    for column, raw in fields.items():
        text = raw.strip()
        if column == "frame":
            if not _INTEGER.match(text) or len(text) > 18:
                raise FileRefusal(f"{where}: frame must be an integer, got {text!r}")
            out["frame"] = int(text)
            continue
        value = _number(text, column, where)
        if column == "u" and not math.isnan(value):
            value = (value - cx) / focal
            column = "mu"
            if not abs(value) <= limits.mu:
                raise FileRefusal(
                    f"{where}: u gives a bearing (u - cx) / focal of magnitude more than "
                    f"{limits.mu:g}, got u = {text}"
                )
        elif column == "u":
            column = "mu"
        elif column == "mu" and not abs(value) <= limits.mu and not math.isnan(value):
            raise FileRefusal(f"{where}: mu must be at most {limits.mu:g} in magnitude, got {text}")
        elif column == "rho" and not math.isnan(value):
            lo, hi = limits.rho
            if not lo <= value <= hi:
                raise FileRefusal(f"{where}: rho must be from {lo:g} to {hi:g}, got {text}")
        elif column == "step":
            lo, hi = limits.step
            if first and text:
                raise FileRefusal(
                    f"{where}: the first row's step must be empty (step is the depth's "
                    f"change since the previous frame), got {text}"
                )
            if not first and not lo <= value <= hi:  # an empty field (NaN) too
                raise FileRefusal(
                    f"{where}: step must be from {lo:g} to {hi:g} (the depth's change since "
                    f"the previous frame), got {text or 'an empty field'}"
                )
        out[column] = value
    if "rho" in out and math.isnan(out["rho"]) and not math.isnan(out["mu"]):
        raise FileRefusal(f"{where}: rho is empty at a frame with a bearing")
    return out


def _in_order(values: dict, rows: list, columns: list, where: str) -> None:
    """Refuse a frame number out of order, or the frames passing the filters' limit."""
    frames = len(rows) + 1
    if "frame" in values and rows:
        if values["frame"] <= rows[-1]["frame"]:
            raise FileRefusal(
                f"{where}: frame must increase strictly, got {values['frame']} after "
                f"{rows[-1]['frame']}"
            )
        if "step" not in columns:  # the gaps are missing frames
            frames = values["frame"] - rows[0]["frame"] + 1
    if frames > checks.MAX_FRAMES:
        raise FileRefusal(
            f"{where}: more than {checks.MAX_FRAMES} frames (the filters' limit)"
            + (
                " counting the missing frames between the frame numbers"
                if len(rows) + 1 < frames
                else ""
            )
        )


def _assemble(name: str, columns: list, rows: list) -> TrackFile:
    """The track of the rows, the missing frames between frame numbers filled in."""
    if "frame" in columns and "step" not in columns:
        first = rows[0]["frame"]
        n = rows[-1]["frame"] - first + 1
        index = [r["frame"] - first for r in rows]
        frames = np.arange(first, first + n)
    else:
        n = len(rows)
        index = list(range(n))
        frames = np.array([r["frame"] for r in rows]) if "frame" in columns else np.arange(1, n + 1)
    mu = np.full(n, np.nan)
    mu[index] = [r["mu"] for r in rows]
    rho = None
    if "rho" in columns:
        rho = np.full(n, np.nan)
        rho[index] = [r["rho"] for r in rows]
    steps = np.array([r["step"] for r in rows[1:]]) if "step" in columns else None
    return TrackFile(name, mu, rho, steps, frames, "u" in columns)


# --- every frame's state ------------------------------------------------------------------

#: The quantities of a per-frame row, by the attribute of a series of states.
QUANTITIES = (
    ("depth", "depth"),
    ("x", "lateral"),
    ("velocity", "velocity"),
)


def per_frame(
    mu, rho, prior, process_noise: float, names, steps=None, gate=None, frames=None
) -> dict:
    """Every frame's filtered and smoothed state by the named filters, ready for JSON.

    Parameters
    ----------
    mu : ndarray, shape (N,)
        Bearings, ``NaN`` at a missing frame.
    rho : float or ndarray, shape (N,)
        The noise SD, one or per frame.
    prior : depthcore.problem.gaussian.Gaussian
        The state's density at the first frame.
    process_noise : float
    names : sequence of str
        Filters with a smoother (:data:`depthcore.registry.filters.SMOOTHED`).
    steps : ndarray, shape (N - 1,), or None
        The depth's change between consecutive frames (``None``: unit steps).
    gate : float or None
        Skip a bearing whose predictive tail probability is below ``gate``.
    frames : ndarray of int, shape (N,), or None
        The frames' numbers (default ``1 .. N``).

    Returns
    -------
    dict
        ``{"frames", "prior_mean", "prior_cov", "process_noise", "gate", "filters":
        {name: rows}}``; a row per frame: ``frame``, ``bearing`` (whether the frame
        has one), ``mu``, ``rho``, ``step`` (``None`` at the first frame), the
        filter's ``tail`` and ``gated`` where it reports them, then
        ``filtered_depth_mean``, ``filtered_depth_sd``, ``filtered_x_mean``, ...,
        ``smoothed_velocity_sd`` (depth ``y``, lateral position ``x``, velocity ``v``).
    """
    try:
        mu = np.asarray(mu, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("mu must be an array of numbers, shape (N,)") from None
    if mu.ndim != 1:
        raise ValueError(f"mu must be one track, shape (N,), got shape {mu.shape}")
    n = mu.shape[0]
    if isinstance(names, str) or not len(names):
        raise ValueError(f"names must be a sequence of filter names, got {names!r}")
    smoothed = filters.names(smoothed=True)
    for name in names:
        if name not in smoothed:
            raise ValueError(
                f"names: {name!r} is not a filter with a smoother; these are {', '.join(smoothed)}"
            )
    if frames is not None and np.shape(frames) != (n,):
        raise ValueError(f"frames must have shape ({n},), one per bearing, got {np.shape(frames)}")
    if np.ndim(rho):
        rho = np.asarray(rho, dtype=float)
    present = np.isfinite(mu)
    if np.ndim(rho) and np.any(present) and np.all(rho[present] == rho[present][0]):
        rho = float(rho[present][0])  # one noise level: the paper's frames
    frames = np.arange(1, n + 1) if frames is None else np.asarray(frames)
    rho_k = np.broadcast_to(np.asarray(rho, dtype=float), (n,))
    step_k = [None] + ([1.0] * (n - 1) if steps is None else [float(s) for s in np.asarray(steps)])
    options = {}
    if steps is not None:
        options["steps"] = np.asarray(steps, dtype=float)
    if gate is not None:
        options["gate"] = gate
    out = {
        "frames": int(n),
        "prior_mean": prior.mean.tolist(),
        "prior_cov": prior.cov.tolist(),
        "process_noise": float(process_noise),
        "gate": gate,
        "filters": {},
    }
    for name in names:
        t = tracking.track(mu, rho, prior, process_noise, filter=name, **options)
        updates = getattr(t, "updates", None)
        rows = []
        for k in range(n):
            present = bool(np.isfinite(mu[k]))
            row = {
                "frame": int(frames[k]),
                "bearing": present,
                "mu": float(mu[k]),
                "rho": float(rho_k[k]) if present else None,
                "step": step_k[k],
            }
            if updates is not None:
                row["tail"] = float(np.asarray(updates.tail)[k])
                row["gated"] = bool(np.asarray(updates.gated)[k])
            for series, states in (("filtered", t.filtered), ("smoothed", t.smoothed)):
                for key, attribute in QUANTITIES:
                    row[f"{series}_{key}_mean"] = float(getattr(states, f"{attribute}_mean")[k])
                    row[f"{series}_{key}_sd"] = float(getattr(states, f"{attribute}_sd")[k])
            rows.append(row)
        out["filters"][name] = rows
    return out


# --- learning the noise ---------------------------------------------------------------


def learn(mu, weights, prior, known_q=None, steps=None):
    """A track's noise levels: rho (and q unless given) by maximum likelihood, textbook 19.1.2.

    Parameters
    ----------
    mu : ndarray, shape (N,)
        Bearings, ``NaN`` at a missing frame.
    weights : float or ndarray, shape (N,)
        A file's ``rho`` column: the frames' relative noise levels (a number: none).
    prior : depthcore.problem.gaussian.Gaussian
        The state's density at the first frame.
    known_q : float or None
        The process noise when given, ``None`` to learn it.
    steps : ndarray, shape (N - 1,), or None
        The depth's change between consecutive frames (``None``: unit steps).

    Returns
    -------
    depthcore.exact.learning.Fit

    Raises
    ------
    ValueError
        Naming ``prior`` when it is not a Gaussian, or the argument
        :func:`depthcore.exact.learning.fit` refuses.
    """
    from depthcore.exact import learning

    if not (hasattr(prior, "mean") and hasattr(prior, "cov")):
        raise ValueError(f"prior must be a Gaussian (mean and cov), got {type(prior).__name__}")
    return learning.fit(
        mu,
        prior.mean,
        prior.cov,
        process_noise=known_q,
        steps=steps,
        weights=np.asarray(weights) if np.ndim(weights) else None,
    )


def learned_json(fit) -> dict:
    """A learned fit as plain JSON values (``None`` for a standard error it has not).

    Parameters
    ----------
    fit : depthcore.exact.learning.Fit
        :func:`learn`'s result.

    Returns
    -------
    dict
        ``rho``, ``rho_se``, ``rho_interval``, ``process_noise``,
        ``process_noise_se``, ``process_noise_interval``, ``estimated``,
        ``at_boundary``, ``level``, ``log_likelihood``, ``converged``.
    """

    def number(v):
        return None if v is None else float(v)

    def interval(v):
        return None if v is None else [float(v[0]), float(v[1])]

    return {
        "rho": float(fit.rho),
        "rho_se": number(fit.rho_se),
        "rho_interval": interval(fit.rho_interval),
        "process_noise": float(fit.process_noise),
        "process_noise_se": number(fit.process_noise_se),
        "process_noise_interval": interval(fit.process_noise_interval),
        "estimated": list(fit.estimated),
        "at_boundary": bool(fit.at_boundary),
        "level": float(fit.level),
        "log_likelihood": float(fit.log_likelihood),
        "converged": bool(fit.converged),
    }
