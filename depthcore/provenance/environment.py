"""The computing environment of a build, stated once: for the article, the book and the records.

Recommended import: ``from depthcore.provenance import environment``.

:func:`statement` gathers what a reader needs to judge whether a number may
differ on another machine: the date, depthcore's version, Python and the
versions of the packages the numbers and the figures come from, and the
processor with its BLAS (from :func:`depthcore.provenance.benchmarks.machine`,
which every study and benchmark record also stores). :func:`sentence` writes
it as one sentence. The article's build writes that sentence into the
article, and the book's build into its page "Reproducing this book", each
when it runs, so the two state the same environment in the same words.
"""

from __future__ import annotations

import datetime
import platform
from importlib import metadata

from depthcore import __version__
from depthcore.provenance import benchmarks

#: The packages a statement names, in this order, with the name it gives each; the numbers
#: come from NumPy and SciPy, the figures from Matplotlib, the book from Jupyter Book.
PACKAGES = {
    "numpy": "NumPy",
    "scipy": "SciPy",
    "matplotlib": "Matplotlib",
    "jupyter-book": "Jupyter Book",
    "sphinx": "Sphinx",
}


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
        ``date`` (ISO 8601), ``depthcore``, ``python``, ``packages`` (printed
        name -> version, in the order given) and ``machine``
        (:func:`depthcore.provenance.benchmarks.machine`: ``cpu``, ``processor``,
        ``cores``, ``system``, ``blas`` and more).
    """
    if date is None:
        date = datetime.datetime.now(datetime.UTC).date()
    if not isinstance(date, datetime.date):
        raise ValueError(f"date must be a datetime.date, got {type(date).__name__}")
    packages = PACKAGES if packages is None else dict(packages)
    return {
        "date": date.isoformat(),
        "depthcore": __version__,
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
