"""The computing environment of a build, stated once: for the article, the book and the records.

Recommended import: ``from depthbook.provenance import environment``.

:func:`statement` gathers what a reader needs to judge whether a number may
differ on another machine: the date, depthcore's version, Python and the
versions of the packages the numbers and the figures come from, and the
processor with its BLAS (from :func:`depthbook.provenance.benchmarks.machine`,
which every study and benchmark record also stores). :func:`sentence` writes
it as one sentence. The article's build writes that sentence into the
article, and the book's build into its page "Reproducing this book", each
when it runs, so the two state the same environment in the same words.
"""

from __future__ import annotations

import datetime
import functools
import platform
import subprocess
from importlib import metadata

from depthbook.provenance import benchmarks
from depthcore import __version__

#: The packages a statement names, in this order, with the name it gives each; the numbers
#: come from NumPy and SciPy, the figures from Matplotlib, the book from Jupyter Book.
PACKAGES = {
    "numpy": "NumPy",
    "scipy": "SciPy",
    "matplotlib": "Matplotlib",
    "jupyter-book": "Jupyter Book",
    "sphinx": "Sphinx",
}


#: The repository, whose commit names the code of a checkout.
ROOT = benchmarks.ROOT
#: The package's folders of records, which the code writes and its version ignores.
RECORDS = ("depthbook/provenance/study_records", "depthbook/provenance/benchmark_records")


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """depthcore's version and, in a git checkout, the commit of its code.

    Returns
    -------
    str
        ``"0.2.0+g5eaeec6"`` (PEP 440's local version: the commit's first 7
        hexadecimal digits), with ``".dirty"`` appended when the package's
        files (its records apart) differ from that commit; plain ``"0.2.0"``
        outside a checkout (an installed archive), where no commit is known.
    """

    def git(*args):
        return subprocess.run(
            ["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30, check=True
        ).stdout.strip()

    if not (ROOT / ".git").exists():
        return __version__
    try:
        commit = git("rev-parse", "--short=7", "HEAD")
        changes = git(
            "status", "--porcelain", "--", "depthcore", *(f":(exclude){p}" for p in RECORDS)
        )
    except (OSError, subprocess.SubprocessError):
        return __version__
    return f"{__version__}+g{commit}" + (".dirty" if changes else "")


def _version(distribution: str) -> str:
    """The installed version of ``distribution``, or ``"not installed"``."""
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return "not installed"


def statement(date: datetime.date | None = None, packages=None) -> dict:
    """The environment this process runs in.

    Parameters
    ----------
    date : datetime.date, optional
        The date to state; today (UTC) by default.
    packages : dict of str to str, optional
        Distribution name -> the name to print; :data:`PACKAGES` by default.

    Returns
    -------
    dict
        ``date`` (ISO 8601), ``depthcore`` (:func:`code_version`: with the
        commit, in a checkout), ``python``, ``packages`` (printed
        name -> version, in the order given) and ``machine``
        (:func:`depthbook.provenance.benchmarks.machine`: ``cpu``, ``processor``,
        ``cores``, ``system``, ``blas`` and more).
    """
    if date is None:
        date = datetime.datetime.now(datetime.UTC).date()
    if not isinstance(date, datetime.date):
        raise ValueError(f"date must be a datetime.date, got {type(date).__name__}")
    packages = PACKAGES if packages is None else dict(packages)
    return {
        "date": date.isoformat(),
        "depthcore": code_version(),
        "python": platform.python_version(),
        "packages": {label: _version(name) for name, label in packages.items()},
        "machine": benchmarks.machine(),
    }


def sentence(stated: dict) -> str:
    """``stated`` (from :func:`statement`) as one sentence of plain text.

    Examples
    --------
    "Built on 2026-11-28 with depthcore 0.2.0 on Python 3.11.9, NumPy 2.1.3, ...;
    processor Intel Xeon (family 6, model 85), 2 logical CPUs, Linux x86_64, BLAS
    scipy-openblas 0.3.28, Haswell kernels."
    """
    try:
        m = stated["machine"]
        versions = ", ".join(f"{label} {v}" for label, v in stated["packages"].items())
        return (
            f"Built on {stated['date']} with depthcore {stated['depthcore']} on "
            f"Python {stated['python']}, {versions}; processor {m['cpu']} ({m['processor']}), "
            f"{m['cores']} logical CPUs, {m['system']}, BLAS {m['blas']}."
        )
    except (KeyError, TypeError) as err:
        raise ValueError(f"stated must be what environment.statement() returns: {err!r}") from None


def _machine_words(m: dict) -> str:
    """A machine as a record stores it, in words: processor, cores, BLAS and its kernels."""
    return f"{m['cpu']} ({m['processor']}), {m['cores']} logical CPUs, BLAS {m['blas']}"


def origins(kinds: dict) -> list[dict]:
    """Where and when each kind of record was computed, read from the records themselves.

    Parameters
    ----------
    kinds : dict of str to list of dict
        A kind's name (``"study records"``) -> its records, each with the
        fields ``date``, ``machine`` and ``depthcore_version`` that study and
        benchmark records share.

    Returns
    -------
    list of dict
        One per kind and machine, in the order given: ``kind``, ``count``,
        ``dates`` (the first and last, ISO 8601 days), ``machine`` (in
        words), ``versions`` (depthcore's, sorted) and ``software`` (Python,
        NumPy and SciPy as the machine stored them).
    """
    found = []
    for kind, rows in kinds.items():
        groups: dict[str, list[dict]] = {}
        for row in rows:
            try:
                groups.setdefault(_machine_words(row["machine"]), []).append(row)
            except (KeyError, TypeError) as err:
                raise ValueError(f"kinds: a record of {kind} lacks {err}") from None
        for machine, group in groups.items():
            days = sorted(str(r["date"])[:10] for r in group)
            m = group[0]["machine"]
            found.append(
                {
                    "kind": kind,
                    "count": len(group),
                    "dates": (days[0], days[-1]),
                    "machine": machine,
                    "versions": sorted({str(r["depthcore_version"]) for r in group}),
                    "software": f"Python {m['python']}, NumPy {m['numpy']}, SciPy {m['scipy']}",
                }
            )
    return found


def origins_sentence(found: list[dict]) -> str:
    """:func:`origins` as one sentence: which records were computed where, when, by what.

    Examples
    --------
    "The 31 study records were computed on 2026-12-06 on Intel(R) Xeon(R) Processor
    (family 6, model 167), 2 logical CPUs, BLAS scipy-openblas 0.3.31.188.0, SkylakeX
    kernels, with depthcore 0.2.0+g1234567 on Python 3.11.7, NumPy 2.4.6, SciPy 1.17.1;
    the 10 benchmark records on 2026-11-29 on ..."
    """
    if not found:
        raise ValueError("found must name at least one kind of record")
    parts = []
    for i, o in enumerate(found):
        days = " to ".join(dict.fromkeys(o["dates"]))
        verb = (" was computed" if o["count"] == 1 else " were computed") if i == 0 else ""
        kind = o["kind"].removesuffix("s") if o["count"] == 1 else o["kind"]
        parts.append(
            f"{'The' if i == 0 else 'the'} {o['count']} {kind}{verb} on {days} on "
            f"{o['machine']}, with depthcore {' and '.join(o['versions'])} on {o['software']}"
        )
    return "; ".join(parts) + "."


def records_sentence() -> str:
    """:func:`origins_sentence` of the committed study and benchmark records.

    The book's page "Reproducing this book" and the article state it beside
    the environment of their own build (:func:`sentence`), which may differ.
    """
    from depthbook.provenance import records  # records imports this module

    studies = [records.read(path) for path in records.committed()]
    measured = [benchmarks.read(path.stem) for path in sorted(benchmarks.RESULTS.glob("*.json"))]
    return origins_sentence(origins({"study records": studies, "benchmark records": measured}))
