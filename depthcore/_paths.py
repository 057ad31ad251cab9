"""How the package's modules are reached: as attributes of their package, imported when read.

A subpackage's modules are attributes of it, imported when first read
(``import depthcore; depthcore.exact.optimal``): each subpackage's
``__getattr__`` calls :func:`submodule`.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path


def modules_in(folder) -> tuple[str, ...]:
    """The public modules of a package's folder, by name, sorted; subpackages left out.

    Read from the folder, nothing imported: :data:`depthcore.MODULES`, the
    book's ``MODULES`` and :func:`submodule` all list modules this way.
    """
    import pkgutil

    found = pkgutil.iter_modules([str(folder)])
    return tuple(sorted(m.name for m in found if not m.ispkg and not m.name.startswith("_")))


def submodule(package: str, name: str):
    """The module ``name`` of ``package`` (a folder of the package), imported when first read.

    Parameters
    ----------
    package : str
        The subpackage, e.g. ``"depthcore.exact"``.
    name : str
        The attribute read, e.g. ``"optimal"``.

    Raises
    ------
    AttributeError
        When ``package`` has no public module ``name``.
    """
    if name not in modules_in(Path(sys.modules[package].__file__).parent):
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return importlib.import_module(f"{package}.{name}")
