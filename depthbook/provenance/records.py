"""The book's heavy studies, computed once and recorded: read back while the pages run.

Recommended import: ``from depthbook.provenance import records``.

A page calls its Monte Carlo study, or a brute-force sum
(:func:`depthbook.reference.grid_moments`), through :func:`recorded`:
``recorded(frames_study, [3, 5], 300, 1)`` returns what ``frames_study([3, 5],
300, 1)`` returns. When the book's records hold a record of that call (the
same function, the same arguments) made by the current code, the result is
read from it, in a fraction of a second; otherwise it is computed there and
then. A reader who changes a page's sizes or seed therefore gets the new
study computed, and an unchanged page shows what the record holds, which is
what the computation returns, bit for bit (floats are written with
``repr``, which reads back exactly).

Each record, ``depthbook/provenance/study_records/<function>-<key>.json``, holds
the function, its arguments, the result, the date, the machine, the seconds
the computation took, depthcore's version with the commit of its code
(:func:`depthbook.provenance.environment.code_version`) and the fingerprints
of what the call runs (:func:`depthbook.provenance.closure.fingerprints`: the
functions and classes its code reaches, the constants they read, the filters
it names, the data files it reads). A change of any of these makes the record
stale (:func:`stale`), and a stale record is never read; a change elsewhere
(a filter the study does not run, a page, a docstring) leaves it valid.

How :func:`recorded` treats records is set by the environment variable
``DEPTHCORE_RECORDS`` (:data:`MODES`): ``read`` (the default) reads a current
record and computes otherwise; ``write`` also writes the record of each
computation (``make records``); ``require`` refuses to compute, so that a
build which must read every study from its record fails on the first that
is missing or stale.

Results are stored by :func:`encode`: dicts, lists, tuples, strings,
numbers, None, NumPy arrays and scalars, and depthcore's dataclasses and
named tuples.

Why not ``joblib.Memory``: it is the right tool for a local cache, but these
records are something else, committed provenance that ships in the source
archive and is read on the reader's machine. ``joblib.Memory`` keys a result
on the cached function's own code only: with joblib 1.6.0, a result stays in
use after a change to a function that the cached one calls (checked: ``f``
calling ``g``, ``g`` changed from ``x + 1`` to ``x + 100``, ``f(1)`` still
returns the stored 2), where a record here is stale as soon as any code the
call reaches changes (:func:`stale`). Its results are pickles,
which a review cannot read in a diff and which depend on the classes'
module paths and the library versions that wrote them; a record is JSON, with
the date, machine, duration and code fingerprint beside the result, and is read
without unpickling anything.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import importlib
import json
import os
import pathlib
import reprlib
import time
from pathlib import Path

import numpy as np

from depthbook.provenance import benchmarks, closure, environment

#: The committed records, kept as package data so that the book's source archive carries them.
RECORDS = Path(__file__).resolve().parent / "study_records"
#: The environment variable that sets how :func:`recorded` treats records.
ENVIRONMENT = "DEPTHCORE_RECORDS"
#: The environment variable naming another folder of records for :func:`recorded` to read
#: and write: ``make records`` writes the new set there, beside the committed one, and
#: puts it in place only once every study has run (``tools/records.py``).
DIRECTORY = "DEPTHCORE_RECORDS_DIR"
#: The values of :data:`ENVIRONMENT`, in this order: read a current record (the default),
#: also write the record of each computation, or require a current record.
MODES = ("read", "write", "require")
#: The fields of every record.
FIELDS = (
    "function",
    "arguments",
    "key",
    "date",
    "seconds",
    "machine",
    "depthcore_version",
    "fingerprint",
    "result",
)
#: The command that computes every record again.
COMMAND = "make records"


# --- the encoding ---------------------------------------------------------------------------


def _class_path(cls) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _ours(path: str) -> bool:
    return path.partition(":")[0].partition(".")[0] in ("depthcore", "depthbook")


def _named(path: str):
    """The object named ``module:qualname``: its module imported, then each attribute read."""
    module, _, qualname = path.partition(":")
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def _depthcore_class(path: str):
    """The class named ``module:qualname``, which must be depthcore's."""
    if not _ours(path):
        raise ValueError(f"a record may hold only depthcore's classes, got {path!r}")
    return _named(path)


def encode(value):
    """``value`` as JSON's values, tagged so that :func:`decode` rebuilds it exactly.

    Parameters
    ----------
    value : object
        None, bool, int, float, str; list, tuple, dict (any keys it can
        encode); NumPy arrays (not of objects) and scalars; instances of
        depthcore's dataclasses and named tuples, field by field.

    Returns
    -------
    object
        Made of dicts with string keys, lists, strings, numbers, booleans and
        None. Floats stay floats (NaN and infinities as JSON's extensions).

    Raises
    ------
    TypeError
        For any other type, naming it.
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufUS":
            raise TypeError(f"cannot record an array of dtype {value.dtype}")
        return {
            "__array__": value.dtype.str,
            "shape": list(value.shape),
            "data": value.ravel().tolist(),
        }
    if isinstance(value, np.generic):
        return {"__scalar__": value.dtype.str, "value": value.item()}
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, np.random.SeedSequence):
        return {
            "__seed_sequence__": encode(value.entropy),
            "spawn_key": list(value.spawn_key),
            "pool_size": value.pool_size,
            "n_children_spawned": value.n_children_spawned,
        }
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {
            f.name: encode(getattr(value, f.name)) for f in dataclasses.fields(value) if f.init
        }
        return {"__dataclass__": _class_path(type(value)), "fields": fields}
    if isinstance(value, tuple) and hasattr(value, "_fields"):
        return {"__namedtuple__": _class_path(type(value)), "items": [encode(v) for v in value]}
    if isinstance(value, tuple):
        return {"__tuple__": [encode(v) for v in value]}
    if isinstance(value, list):
        return [encode(v) for v in value]
    if isinstance(value, dict):
        if all(isinstance(k, str) and not k.startswith("__") for k in value):
            return {k: encode(v) for k, v in value.items()}
        return {"__items__": [[encode(k), encode(v)] for k, v in value.items()]}
    raise TypeError(f"cannot record a {type(value).__module__}.{type(value).__qualname__}")


def _key(value):
    """A decoded value usable as a dict key (lists become tuples)."""
    return tuple(_key(v) for v in value) if isinstance(value, list) else value


def decode(value):
    """The value that :func:`encode` encoded.

    Parameters
    ----------
    value : object
        What :func:`encode` returned, or the same read back from JSON.

    Returns
    -------
    object
        Equal to the encoded value, arrays with their dtype and shape.
    """
    if isinstance(value, list):
        return [decode(v) for v in value]
    if not isinstance(value, dict):
        return value
    if "__array__" in value:
        dtype = np.dtype(value["__array__"])
        return np.array(value["data"], dtype=dtype).reshape(value["shape"])
    if "__scalar__" in value:
        return np.dtype(value["__scalar__"]).type(value["value"])
    if "__seed_sequence__" in value:
        return np.random.SeedSequence(
            decode(value["__seed_sequence__"]),
            spawn_key=tuple(value["spawn_key"]),
            pool_size=value["pool_size"],
            n_children_spawned=value["n_children_spawned"],
        )
    if "__dataclass__" in value:
        cls = _depthcore_class(value["__dataclass__"])
        return cls(**{k: decode(v) for k, v in value["fields"].items()})
    if "__namedtuple__" in value:
        return _depthcore_class(value["__namedtuple__"])(*(decode(v) for v in value["items"]))
    if "__tuple__" in value:
        return tuple(decode(v) for v in value["__tuple__"])
    if "__items__" in value:
        return {_key(decode(k)): decode(v) for k, v in value["__items__"]}
    return {k: decode(v) for k, v in value.items()}


# --- one call's record ----------------------------------------------------------------------


def function_name(function) -> str:
    """``module:qualname`` of a depthcore function, as records name it."""
    module = getattr(function, "__module__", "") or ""
    if not callable(function) or not _ours(module):
        raise ValueError(f"function must be one of depthcore's functions, got {function!r}")
    return f"{module}:{function.__qualname__}"


def _encode_named(value, what: str):
    """:func:`encode`, its TypeError naming ``what`` was being encoded."""
    try:
        return encode(value)
    except TypeError as err:
        raise TypeError(f"{what}: {err}; a record keeps only values it can write") from None


def arguments(args=(), kwargs=None) -> dict:
    """The encoded arguments of a call, as its record keeps them.

    Raises
    ------
    TypeError
        Naming the argument (by position or by name) that cannot be recorded.
    """
    return {
        "args": [_encode_named(a, f"argument {i}") for i, a in enumerate(args)],
        "kwargs": {k: _encode_named(v, f"argument {k}") for k, v in dict(kwargs or {}).items()},
    }


def call_key(name: str, args=(), kwargs=None) -> str:
    """The first 16 hex digits of the SHA-256 of a call: function name and encoded arguments."""
    return _hash_call(name, arguments(args, kwargs))


def _hash_call(name: str, encoded: dict) -> str:
    text = json.dumps([name, encoded], sort_keys=True, allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def record_path(name: str, key: str, directory=None) -> Path:
    """Where the record of call ``key`` of function ``name`` is kept."""
    function = name.partition(":")[2].replace(".", "_")
    return Path(RECORDS if directory is None else directory) / f"{function}-{key}.json"


def resolve(name: str):
    """The function a record names, ``module:qualname``; a ValueError when there is none."""
    if not _ours(name):
        raise ValueError(f"function must be one of depthcore's functions, got {name!r}")
    try:
        return _named(name)
    except (ImportError, AttributeError):
        raise ValueError(f"function {name!r} is gone from depthcore") from None


def code_fingerprint(name: str, args=(), kwargs=None) -> dict[str, str]:
    """The fingerprints of what one call of a function runs (:mod:`.closure`).

    Parameters
    ----------
    name : str
        ``module:qualname``, from :func:`function_name`.
    args, kwargs
        The call's arguments: the registry's filters they name count.

    Returns
    -------
    dict of str to str
        ``"code module:qualname"``, ``"constant module:NAME"``, ``"filter
        NAME"`` or ``"file path"`` -> fingerprint: the code the call reaches,
        not every module its function's module imports, so that a change
        elsewhere (a filter it does not run, a page, a docstring) leaves its
        record valid.
    """
    return closure.fingerprints(resolve(name), args, kwargs)


def stale(record: dict) -> list[str]:
    """What changed, of the code a record's call runs, since it was made; empty when current.

    Parameters
    ----------
    record : dict
        A record, from :func:`read`.

    Returns
    -------
    list of str
        The fingerprints' keys (:func:`code_fingerprint`) that differ: changed,
        gone, or newly reached.
    """
    try:
        args = decode(record["arguments"]["args"])
        kwargs = decode(record["arguments"]["kwargs"])
        current = code_fingerprint(record["function"], args, kwargs)
    except ValueError:
        return sorted(record["fingerprint"])
    return closure.changed(record["fingerprint"], current)


def read(path) -> dict:
    """The record in file ``path``, with the fields :data:`FIELDS`."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path must be a study record, got {str(path)!r} (no such file)")
    return json.loads(path.read_text(encoding="utf-8"))


def committed(directory=None) -> list[Path]:
    """The record files in ``directory`` (default :data:`RECORDS`), sorted."""
    return sorted(Path(RECORDS if directory is None else directory).glob("*.json"))


def write(name: str, args, kwargs, result, seconds: float, directory=None) -> dict:
    """Write the record of one call of function ``name`` to :func:`record_path`; return it."""
    encoded = arguments(args, kwargs)
    key = _hash_call(name, encoded)
    record = {
        "function": name,
        "arguments": encoded,
        "key": key,
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "seconds": round(float(seconds), 1),
        "machine": benchmarks.machine(),
        "depthcore_version": environment.code_version(),
        "fingerprint": code_fingerprint(name, args, kwargs),
        "result": _encode_named(result, f"the result of {name}"),
    }
    path = record_path(name, key, directory)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=None, allow_nan=True) + "\n", encoding="utf-8")
    return record


def directory() -> Path:
    """Where :func:`recorded` reads and writes: ``DEPTHCORE_RECORDS_DIR``, else :data:`RECORDS`."""
    value = os.environ.get(DIRECTORY, "").strip()
    return Path(value) if value else RECORDS


def mode() -> str:
    """How :func:`recorded` treats records now: ``DEPTHCORE_RECORDS``'s value (:data:`MODES`)."""
    value = os.environ.get(ENVIRONMENT, "").strip() or "read"
    if value not in MODES:
        raise ValueError(f"{ENVIRONMENT} must be one of {', '.join(MODES)}, got {value!r}")
    return value


@dataclasses.dataclass(frozen=True)
class Recorded:
    """What :func:`recorded` returns: the result and where it came from.

    Attributes
    ----------
    result : object
        What the function returns.
    path : pathlib.Path
        The record's file (read, written, or that would be written).
    date : str or None
        When the record was made; None when computed now and not written.
    seconds : float
        How long the computation took (when the record was made, if read).
    read : bool
        True when the result was read from the record.
    """

    result: object
    path: pathlib.Path
    date: str | None
    seconds: float
    read: bool

    def __str__(self) -> str:
        where = f"depthbook/provenance/study_records/{self.path.name}"
        if self.read:
            computed = f"computed on {self.date[:10]} in {self.seconds:.0f} s"
            return f"read from its record {where}, {computed}"
        if self.date is not None:
            return f"computed now in {self.seconds:.0f} s and recorded in {where}"
        return f"computed now in {self.seconds:.0f} s (no current record of this call)"


def recorded(function, /, *args, **kwargs) -> Recorded:
    """``function(*args, **kwargs)``, read from its record when one is current.

    Parameters
    ----------
    function : callable
        One of depthcore's functions; it must be deterministic given its
        arguments (a study with its seed), and its result encodable
        (:func:`encode`).
    *args, **kwargs
        Its arguments, encodable.

    Returns
    -------
    Recorded
        The result, and whether it was read or computed.

    Raises
    ------
    ValueError
        When ``DEPTHCORE_RECORDS`` is ``require`` and no current record of
        this call exists, naming the record and :data:`COMMAND`.
    """
    name = function_name(function)
    key = call_key(name, args, kwargs)
    folder = directory()
    path = record_path(name, key, folder)
    how = mode()
    if path.is_file():
        record = read(path)
        if not stale(record) and record["function"] == name:
            return Recorded(decode(record["result"]), path, record["date"], record["seconds"], True)
    if how == "require":
        raise ValueError(
            f"{name}{reprlib.repr(tuple(args))} has no current record ({path.name}): "
            f"run `{COMMAND}` (or unset {ENVIRONMENT} to compute it)"
        )
    start = time.perf_counter()
    result = function(*args, **kwargs)
    seconds = time.perf_counter() - start
    if how == "write":
        record = write(name, args, kwargs, result, seconds, folder)
        return Recorded(decode(record["result"]), path, record["date"], seconds, False)
    return Recorded(result, path, None, seconds, False)
