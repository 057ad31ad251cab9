"""The benchmarks' recorded results: written by the scripts, read by the book and the README.

Recommended import: ``from depthbook.provenance import benchmarks``.

Each script ``benchmarks/<name>.py`` measures some of depthcore's modules and,
besides printing its tables, writes a record ``depthbook/provenance/benchmark_records/<name>.json``
(:func:`write`): every number its tables print, the sizes it used, the
machine, the date, depthcore's version and a fingerprint of the code it
measured. The book and the README show the numbers of these records
(:func:`read`), never numbers timed while a page runs.

The fingerprint (:func:`fingerprint`) is the SHA-256 of the parsed source with
its docstrings dropped (comments never reach the parse), so editing prose
leaves a record valid and changing code makes it stale (:func:`stale`), until
the script is run again (:func:`command`).

Keys of the results end with their unit: ``_s`` seconds, ``_ms``
milliseconds, ``_sd`` posterior standard deviations (:data:`UNITS`); a key
without one of these endings is a count or a ratio.
"""

from __future__ import annotations

import ast
import datetime
import functools
import hashlib
import json
import os
import platform
from pathlib import Path

import numpy as np

#: The repository, where the benchmark scripts sit beside the package.
ROOT = Path(__file__).resolve().parents[2]
#: The committed records, one per script, kept as package data so that an installed
#: depthcore (from the source archive or a wheel) reads them as the repository does.
RESULTS = Path(__file__).resolve().parent / "benchmark_records"
#: Where a smaller run (``--quick``) writes its record, outside version control.
QUICK_RESULTS = ROOT / "_build" / "benchmarks"
#: The endings of the results' keys and their units.
UNITS = {"_s": "seconds", "_ms": "milliseconds", "_sd": "posterior standard deviations"}
#: The fields of every record.
FIELDS = (
    "script",
    "command",
    "date",
    "machine",
    "depthcore_version",
    "measures",
    "fingerprint",
    "units",
    "sizes",
    "results",
)


def drop_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with the docstring of the module and of every class and function removed."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if (
                body
                and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)
            ):
                node.body = body[1:]
    return tree


def fingerprint(path) -> str:
    """SHA-256 of a Python source's code: its syntax tree without docstrings or comments.

    Parameters
    ----------
    path : str or path
        A Python source file.

    Returns
    -------
    str
        64 hexadecimal digits; the same for two sources that differ only in
        comments, docstrings, blank lines or line breaks.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path must be an existing Python source, got {str(path)!r}")
    return _source_fingerprint(*_version_of(path))


def _version_of(path: Path) -> tuple[str, int, int]:
    """A source file by its path, modification time and size: the key of the caches below."""
    stat = path.stat()
    return str(path.resolve()), stat.st_mtime_ns, stat.st_size


@functools.lru_cache(maxsize=1024)
def _source_fingerprint(path: str, mtime_ns: int, size: int) -> str:
    """:func:`fingerprint` of one version of a source, computed once per process."""
    tree = drop_docstrings(ast.parse(Path(path).read_text(encoding="utf-8"), filename=path))
    return hashlib.sha256(ast.dump(tree, include_attributes=False).encode()).hexdigest()


def _relative(path: Path) -> str:
    return path.resolve().relative_to(ROOT).as_posix()


def module_path(module: str) -> str:
    """The source of depthcore's module ``module``, relative to the repository.

    Parameters
    ----------
    module : str
        A module's name inside ``depthcore``, dotted for a subpackage's
        (``"exact.optimal"``, ``"exact"`` for its ``__init__``), or a module of
        the book's package by its full name (``"depthbook.reference"``).

    Returns
    -------
    str
        ``depthcore/exact/optimal.py``, ``depthbook/beyond_frames.py``,
        ``depthbook/__init__.py``.

    Raises
    ------
    ValueError
        When no such module exists.
    """
    parts = module.split(".")
    if parts[0] != "depthbook":
        parts = ["depthcore", *parts]
    for path in (
        Path(*parts[:-1], f"{parts[-1]}.py"),
        Path(*parts, "__init__.py"),
    ):
        if (ROOT / path).is_file():
            return path.as_posix()
    raise ValueError(f"modules must name depthcore's modules, got {module!r}")


def _exists(module: str) -> bool:
    try:
        module_path(module)
    except ValueError:
        return False
    return True


def _package_imports(module: str) -> set[str]:
    """The depthcore modules that ``module`` imports: ``from . import x``, ``from .x import y``.

    Relative imports are resolved from the module's own package (``from ..
    import study`` in ``book.beyond_frames`` is ``study``), as are absolute
    ones of ``depthcore``.
    """
    return set(_imports_of(module, *_version_of(ROOT / module_path(module))))


@functools.lru_cache(maxsize=1024)
def _imports_of(module: str, path: str, mtime_ns: int, size: int) -> frozenset[str]:
    """:func:`_package_imports` of one version of a module's source, computed once per process."""
    path = Path(path)
    package = [] if module == "__init__" else module.split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level >= 1:
            if node.level - 1 > len(package):
                continue
            parts = package[: len(package) - (node.level - 1)] + (node.module or "").split(".")
        elif node.module == "depthcore" or (node.module or "").startswith("depthcore."):
            parts = node.module.split(".")[1:]
        elif (node.module or "").startswith("depthbook."):
            parts = node.module.split(".")
        else:
            continue
        parts = [p for p in parts if p]
        if parts:
            found.add(".".join(parts))
        found.update(".".join(parts + [alias.name]) for alias in node.names)
    return frozenset(m for m in found if m and _exists(m))


def measured_modules(modules) -> list[str]:
    """The modules ``modules`` and every depthcore module they import, directly or not.

    A benchmark's numbers depend on all the code its modules run, so its
    record is fingerprinted on this closure: a change anywhere in it makes the
    record stale.

    Parameters
    ----------
    modules : sequence of str
        Names of depthcore's modules, e.g. ``("optimal", "reference")``.

    Returns
    -------
    list of str
        Sorted module names, ``modules`` included.
    """
    seen, todo = set(), list(modules)
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(_package_imports(m) - seen)
    return sorted(seen)


def fingerprints(script, modules) -> dict[str, str]:
    """The fingerprints of a benchmark script and of the depthcore code it measures.

    Parameters
    ----------
    script : str or path
        The script, ``benchmarks/<name>.py``.
    modules : sequence of str
        Names of depthcore's modules, e.g. ``("optimal", "reference")``;
        every module they import is fingerprinted too (:func:`measured_modules`).

    Returns
    -------
    dict of str to str
        Path relative to the repository -> :func:`fingerprint`.
    """
    return {_relative(Path(script)): fingerprint(script)} | module_fingerprints(modules)


def module_fingerprints(modules) -> dict[str, str]:
    """The fingerprints of depthcore's modules ``modules`` and of every module they import.

    Parameters
    ----------
    modules : sequence of str
        Names inside the package (:func:`module_path`), e.g. ``("optimal",)``.

    Returns
    -------
    dict of str to str
        Path relative to the repository (``depthcore/...``) -> :func:`fingerprint`,
        for every module of :func:`measured_modules`.
    """
    paths = (module_path(m) for m in measured_modules(modules))
    return {path: fingerprint(ROOT / path) for path in paths}


def changed_sources(recorded: dict, current: dict) -> list[str]:
    """The sources whose fingerprints differ between two fingerprint maps, sorted.

    A source in one map and not in the other counts as changed (gone, or
    newly imported).
    """
    return [p for p in sorted(set(current) | set(recorded)) if current.get(p) != recorded.get(p)]


def cpuinfo() -> dict[str, str]:
    """The first processor's fields of ``/proc/cpuinfo`` (empty where there is none)."""
    fields: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if not line.strip():
                    break
                key, _, value = line.partition(":")
                fields[key.strip()] = value.strip()
    except OSError:
        pass
    return fields


def _cpu_model(info: dict[str, str]) -> str:
    return info.get("model name") or platform.processor() or platform.machine()


def _processor(info: dict[str, str]) -> str:
    """The processor's family and model, which a model name such as "AMD EPYC" may hide."""
    if "cpu family" in info and "model" in info:
        return f"family {info['cpu family']}, model {info['model']}"
    return platform.machine()


def _blas(config: dict) -> str:
    """The BLAS library NumPy runs and, for OpenBLAS, the kernels it picked for this processor.

    OpenBLAS chooses its kernels when loaded (``OPENBLAS_CORETYPE`` overrides the
    choice), and different kernels round differently. The name is asked of the
    library NumPy loaded; where that cannot be done, the build's BLAS and version
    (from ``config``, NumPy's ``show_config(mode="dicts")``).
    """
    import ctypes

    built = config["Build Dependencies"]["blas"]
    name = f"{built.get('name', 'unknown')} {built.get('version', '')}".strip()
    try:
        with open("/proc/self/maps", encoding="utf-8") as f:
            paths = sorted({line.split()[-1] for line in f if "openblas" in line.lower()})
        for path in paths:
            lib = ctypes.CDLL(path)
            for symbol in (
                "scipy_openblas_get_corename64_",
                "scipy_openblas_get_corename",
                "openblas_get_corename64_",
                "openblas_get_corename",
            ):
                get = getattr(lib, symbol, None)
                if get is not None:
                    get.restype = ctypes.c_char_p
                    return f"{name}, {get().decode()} kernels"
    except (OSError, IndexError, AttributeError, UnicodeDecodeError):
        pass
    return name


def machine() -> dict:
    """The machine and software a benchmark runs on.

    Returns
    -------
    dict
        ``cores`` (logical CPUs), ``cpu`` (the model name), ``processor``
        (family and model), ``system``, ``python``, ``numpy``, ``scipy``,
        ``simd`` (NumPy's SIMD extensions found on this processor) and
        ``blas`` (the BLAS library and the kernels it runs): a record's
        numbers may differ in their rounding, and a Monte Carlo study's
        beyond it, between processors that share a model name.
    """
    import scipy

    info, config = cpuinfo(), np.show_config(mode="dicts")
    simd = config.get("SIMD Extensions", {})
    return {
        "cores": os.cpu_count(),
        "cpu": _cpu_model(info),
        "processor": _processor(info),
        "system": f"{platform.system()} {platform.machine()}",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "simd": " ".join(simd.get("baseline", []) + simd.get("found", [])),
        "blas": _blas(config),
    }


def command(name: str) -> str:
    """The command that measures benchmark ``name`` again and rewrites its record."""
    return f"python benchmarks/{name}.py"


def _plain(value):
    """NumPy scalars and arrays as JSON's numbers and lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot record a {type(value).__name__}")


def write(script, modules, sizes: dict, results: dict, full: bool = True) -> Path:
    """Write a benchmark's record; a smaller run's goes outside the committed records.

    Parameters
    ----------
    script : str or path
        The benchmark script, ``benchmarks/<name>.py``.
    modules : sequence of str
        The depthcore modules it measures (fingerprinted with the script).
    sizes : dict
        The sizes it ran with (trials, repeats, particles, ...).
    results : dict
        Every number its tables print, keys ending with their unit (:data:`UNITS`).
    full : bool
        True for the full sizes: the record goes to :data:`RESULTS`
        (committed); False (``--quick``): to :data:`QUICK_RESULTS`.

    Returns
    -------
    Path
        The file written, ``<directory>/<name>.json``.
    """
    from depthbook.provenance.environment import code_version  # it imports this module

    script = Path(script).resolve()
    name = script.stem
    record = {
        "script": _relative(script),
        "command": command(name),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": machine(),
        "depthcore_version": code_version(),
        "measures": list(modules),
        "fingerprint": fingerprints(script, modules),
        "units": UNITS,
        "sizes": sizes,
        "results": results,
    }
    directory = RESULTS if full else QUICK_RESULTS
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.json"
    path.write_text(json.dumps(record, indent=1, default=_plain) + "\n", encoding="utf-8")
    return path


def read(name: str, directory=None) -> dict:
    """The committed record of benchmark ``name`` (e.g. ``"bench_optimal"``).

    Parameters
    ----------
    name : str
    directory : str or path, optional
        Default :data:`RESULTS`.

    Returns
    -------
    dict
        The record, with the fields :data:`FIELDS`.
    """
    path = Path(RESULTS if directory is None else directory) / f"{name}.json"
    if not path.is_file():
        raise ValueError(f"name must be a recorded benchmark, got {name!r} (no {path.name})")
    return json.loads(path.read_text(encoding="utf-8"))


def stale(record: dict) -> list[str]:
    """The measured sources whose code changed since the record was made.

    A source counts as changed when its fingerprint differs from the
    record's, when it is gone, and when it has entered the code the
    benchmark's modules run (:func:`measured_modules`) since.

    Parameters
    ----------
    record : dict
        From :func:`read`.

    Returns
    -------
    list of str
        Paths relative to the repository, empty when the record is current.
    """
    recorded = record["fingerprint"]
    script = ROOT / record["script"]
    if not script.is_file():
        return [record["script"]]
    gone = [m for m in record["measures"] if not _exists(m)]
    if gone:
        return gone
    return changed_sources(recorded, fingerprints(script, record["measures"]))
