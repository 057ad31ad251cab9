"""depthcore: the filters of "Filter Based Estimates of Depth", computed exactly.

A point translates in the (x, y) plane and is seen through noisy image
measurements ``mu_i = x_i / y_i + w_i``: the paper's three, or any ``N >= 3``
frames up to ``depthcore.problem.checks.MAX_FRAMES`` (1,000), with or without
process noise on the velocity. The package computes the estimates of its state
that the paper compares (the optimal Bayes filter, the second-order
approximation and the extended Kalman filter) and those of the tracking
literature and the textbook beside them, each against the exact answer.

The package by families, from the bottom up; each subpackage's docstring says
what lives there and where a new thing of its kind goes, and no module imports
from a family above its own:

* :mod:`depthcore.problem`: the paper's model, the Gaussian type and the prior,
  the scenarios of Figures 2-6, the input checks;
* :mod:`depthcore.kalman`: the Gaussian filters, from the linear Kalman filter
  and its smoothers to the second-order filter, the EKF, the UKF and the
  tracking literature's reparametrised EKFs;
* :mod:`depthcore.exact`: the exact filter, by quadrature over depth for three
  frames and as a bank of Kalman filters over depth for any number;
* :mod:`depthcore.particles`: resampling and the particle filters;
* :mod:`depthcore.analysis`: the Cramér-Rao bound, self-calibration and the
  independent routes that check the filters;
* :mod:`depthcore.registry`: every filter under one calling convention
  (:data:`~depthcore.registry.filters.FILTERS`), their results, and
  :func:`~depthcore.registry.tracking.track`;
* :mod:`depthcore.studies`: Monte Carlo studies and the reproduction of the
  paper's tables;
* :mod:`depthcore.cli`: the command line, ``python -m depthcore``;
* :mod:`depthcore.stonesoup`: the paper's problem and the exact filter in Stone
  Soup's types (the ``depthcore[stonesoup]`` extra). Nothing below it imports it.

The package needs NumPy and SciPy alone; the extras add what a part of it uses
(``depthcore[plot]``: matplotlib and tqdm, for the command line's progress
bars and the figures; ``depthcore[stonesoup]``; ``depthcore[dask]``). The
book's code (its chapters, records and verdicts) is a package of its own,
``depthbook``, beside the book's pages in the repository; nothing here imports
it.

The names below are the package's front door; everything else is imported from
its subpackage (``from depthcore.exact import optimal``). Subpackages are
attributes of the package, imported when first used.
"""

import importlib

from depthcore import _paths
from depthcore.problem.gaussian import Gaussian, paper_prior
from depthcore.problem.model import bearings_from_pixels, noise_free_state
from depthcore.problem.scenarios import SCENARIOS

__version__ = "0.3.0"

#: The subpackages, from the bottom of the house up, imported on first access.
SUBPACKAGES = (
    "problem",
    "kalman",
    "exact",
    "particles",
    "analysis",
    "registry",
    "studies",
    "cli",
    "stonesoup",
)


def _modules() -> tuple[str, ...]:
    """Every public module's path, read from the package's folders without importing them.

    :data:`MODULES`, computed when first read: each subpackage, in the order of
    :data:`SUBPACKAGES`, followed by its modules in alphabetical order.
    """
    found = []
    for package in SUBPACKAGES:
        found.append(f"depthcore.{package}")
        found += [f"depthcore.{package}.{m}" for m in _paths.modules_in(f"{__path__[0]}/{package}")]
    return tuple(found)


#: The names a caller reaches through the package itself.
_LAZY = {
    "FILTERS": ("depthcore.registry.filters", "FILTERS"),
    "track": ("depthcore.registry.tracking", "track"),
}

__all__ = [
    "FILTERS",
    "Gaussian",
    "SCENARIOS",
    "__version__",
    "bearings_from_pixels",
    "noise_free_state",
    "paper_prior",
    "track",
]


def __getattr__(name):
    if name == "MODULES":
        # every public module, from the folders (not imported): computed once, when first read
        globals()["MODULES"] = _modules()
        return globals()["MODULES"]
    if name in SUBPACKAGES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _LAZY:
        module, attribute = _LAZY[name]
        return getattr(importlib.import_module(module), attribute)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(SUBPACKAGES) | set(_LAZY) | {"MODULES"})
