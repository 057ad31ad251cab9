"""How the package's modules are reached: as attributes of their package, and by old paths.

A subpackage's modules are attributes of it, imported when first read
(``import depthcore; depthcore.exact.optimal``): each subpackage's
``__getattr__`` calls :func:`submodule`.

The modules that moved in depthcore 0.2 are still importable by their old
paths until 0.3. Importing a module by its old path (``import depthcore.optimal``, ``from
depthcore import optimal``, ``from depthcore.book import records``) returns the
module at its new path and warns once, with a :class:`DeprecationWarning`
naming that path. The linear Kalman filter's module ``depthcore.kalman`` is now
:mod:`depthcore.kalman.linear`: its names read through the subpackage
:mod:`depthcore.kalman` warn the same way (:func:`moved_attribute`).
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys
import warnings
from pathlib import Path

#: The release in which the old paths stop working.
REMOVED_IN = "0.3"

#: Old module path -> new module path.
MOVED = {
    "depthcore._checks": "depthcore.problem.checks",
    "depthcore.model": "depthcore.problem.model",
    "depthcore.gaussian": "depthcore.problem.gaussian",
    "depthcore.scenarios": "depthcore.problem.scenarios",
    "depthcore.second_order": "depthcore.kalman.second_order",
    "depthcore.ekf": "depthcore.kalman.ekf",
    "depthcore.ukf": "depthcore.kalman.ukf",
    "depthcore.iterated": "depthcore.kalman.iterated",
    "depthcore.inverse_depth": "depthcore.kalman.inverse_depth",
    "depthcore.inverse_depth_ukf": "depthcore.kalman.inverse_depth_ukf",
    "depthcore.modified_polar": "depthcore.kalman.modified_polar",
    "depthcore.range_ekf": "depthcore.kalman.range_ekf",
    "depthcore.quadrature": "depthcore.exact.quadrature",
    "depthcore.optimal": "depthcore.exact.optimal",
    "depthcore.bank": "depthcore.exact.bank",
    "depthcore.bank_mixture": "depthcore.exact.mixture",
    "depthcore.bank_posterior": "depthcore.exact.posterior",
    "depthcore.bank_track": "depthcore.exact.smoother",
    "depthcore.resampling": "depthcore.particles.resampling",
    "depthcore.particle": "depthcore.particles.importance",
    "depthcore.resample_move": "depthcore.particles.resample_move",
    "depthcore.rbpf": "depthcore.particles.rbpf",
    "depthcore.estimates": "depthcore.registry.estimates",
    "depthcore.adapters": "depthcore.registry.adapters",
    "depthcore.filters": "depthcore.registry.filters",
    "depthcore.tracking": "depthcore.registry.tracking",
    "depthcore.bound": "depthcore.analysis.bound",
    "depthcore.calibration": "depthcore.analysis.calibration",
    "depthcore.reference": "depthcore.analysis.reference",
    "depthcore.study_trials": "depthcore.studies.trials",
    "depthcore.study_scores": "depthcore.studies.scores",
    "depthcore.study_pairs": "depthcore.studies.pairs",
    "depthcore.study": "depthcore.studies.monte_carlo",
    "depthcore.hardness": "depthcore.studies.hardness",
    "depthcore.reproduce": "depthcore.studies.reproduce",
    "depthcore.cli_text": "depthcore.cli.text",
    "depthcore.benchmarks": "depthcore.provenance.benchmarks",
    "depthcore.benchmark_tables": "depthcore.book.benchmark_tables",
    "depthcore.book.records": "depthcore.provenance.records",
    "depthcore.book.formatting": "depthcore.formatting",
    "depthcore.live": "depthcore.book.live",
}


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


def message(old: str, new: str) -> str:
    """The warning's text: ``old`` has moved to ``new``."""
    return f"{old} has moved to {new}; the old path stops working in depthcore {REMOVED_IN}"


def kept(old: str, door, positional: tuple = (), one_row: bool = False):
    """A 0.1 function that took the prior as a Gaussian, kept until :data:`REMOVED_IN`.

    ``old(mu, rho, prior, *args, **options)`` warns, naming ``door``, and returns
    ``door(mu, rho, prior.mean, prior.cov, **options)`` with ``args`` named by
    ``positional`` (the old function's order).

    Parameters
    ----------
    old : str
        The kept function's full name, e.g. ``"depthcore.kalman.ekf.ekf"``.
    door : callable
        The filter's door that replaces it.
    positional : tuple of str
        The names of the old function's arguments after ``prior``, in order.
    one_row : bool
        Whether ``door`` is called with ``mu`` as a batch of one row (the old
        function returned the door's batch of one).
    """
    new = f"{door.__module__}.{door.__name__}(mu, rho, prior.mean, prior.cov, ...)"

    def function(mu, rho, prior, *args, **options):
        warnings.warn(
            f"{old} is replaced by {new}; it stops working in depthcore {REMOVED_IN}",
            DeprecationWarning,
            stacklevel=2,
        )
        if not (hasattr(prior, "mean") and hasattr(prior, "cov")):
            raise ValueError(f"prior must be a Gaussian, got {type(prior).__name__}")
        if len(args) > len(positional):
            raise TypeError(f"{old} takes at most {3 + len(positional)} positional arguments")
        options.update(zip(positional, args, strict=False))
        if one_row:
            mu = [mu]
        return door(mu, rho, prior.mean, prior.cov, **options)

    function.__name__ = function.__qualname__ = old.rsplit(".", 1)[1]
    function.__module__ = old.rsplit(".", 1)[0]
    function.__doc__ = (
        f":func:`{door.__module__}.{door.__name__}` with the prior as a Gaussian "
        f"``prior`` (its ``mean`` and ``cov``); kept until {REMOVED_IN}."
    )
    return function


def moved_module(old: str):
    """The module now at ``MOVED[old]``, with a :class:`DeprecationWarning` naming it.

    Parameters
    ----------
    old : str
        A key of :data:`MOVED`, e.g. ``"depthcore.optimal"``.
    """
    new = MOVED[old]
    warnings.warn(message(old, new), DeprecationWarning, stacklevel=3)
    return importlib.import_module(new)


def moved_attribute(package: str, module: str, name: str):
    """Attribute ``name`` of ``package``, now in its submodule ``module``, with a warning.

    Parameters
    ----------
    package : str
        The package read, e.g. ``"depthcore.kalman"``.
    module : str
        The module that now holds the name, e.g. ``"depthcore.kalman.linear"``.
    name : str
        The attribute.

    Raises
    ------
    AttributeError
        When ``module`` has no such name either.
    """
    target = importlib.import_module(module)
    if not hasattr(target, name):
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    warnings.warn(
        message(f"{package}.{name}", f"{module}.{name}"), DeprecationWarning, stacklevel=3
    )
    return getattr(target, name)


class _Alias:
    """Loads an old path as the module at its new path."""

    def __init__(self, old: str):
        self.old = old

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        # The import returns what sys.modules holds under the old path once this has run:
        # the module at its new path, whose own __spec__ stays untouched.
        sys.modules[self.old] = moved_module(self.old)


class MovedFinder:
    """Finds the old paths of :data:`MOVED` for ``import depthcore.optimal`` and its kind."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias(fullname))


def install() -> None:
    """Put :class:`MovedFinder` on :data:`sys.meta_path`, once."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(MovedFinder())
