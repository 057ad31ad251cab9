"""depthbook: the book's code, beside its pages; ``depthcore`` never imports it.

The mathematics (the model, the filters, their registry, the studies) is
``depthcore``, the installed package, which knows nothing of the book. This
package runs it for the book's pages and shows what it returns. ``make`` puts it
on the path; the book ships it as ``depthbook.tar.gz`` beside
``depthcore.tar.gz`` for a page downloaded and run alone.

Each chapter is one module, its experiment, its figures and the texts its page
glues, in that order:

* :mod:`~depthbook.intro`: the intro's headline of the extensions;
* :mod:`~depthbook.intuition`: why three bearings fix a depth;
* :mod:`~depthbook.paper`: the paper's own chapters, the model, the filters,
  the marginals, Figures 2-6 and the appendix (``python -m depthbook figures``
  writes the figures as files);
* :mod:`~depthbook.using`: the page "Using depthcore";
* ``beyond_<topic>``: the chapters beyond the paper, one each.

What several chapters share has one place each: :mod:`~depthbook.style` the
plots' style, :mod:`~depthbook.notebook` what a page shows when it runs as a
plain notebook, :mod:`~depthbook.crossref` the book's references resolved in
Jupyter, :mod:`~depthbook.live` the figure pages' live controls,
:mod:`~depthbook.benchmark_tables` the benchmarks' tables,
:mod:`~depthbook.formatting` the numbers as the book prints them,
:mod:`~depthbook.errors` the Monte Carlo standard errors of their curves and
:mod:`~depthbook.reference` the independent routes the pages and the tests
check the package against. Two subpackages:

* :mod:`depthbook.studies`: the studies only the book runs (where the problem
  is hard, replication, the verdicts on the paper, the study by frames and per
  frame);
* :mod:`depthbook.provenance`: the records of the heavy studies and of the
  benchmarks, their fingerprints, and the environment of a build.

Where a new thing goes: a new chapter is one module here, ``beyond_<topic>.py``,
and its page ``book/beyond_<topic>.md``; a study only the book runs goes to
:mod:`depthbook.studies`; a chapter module imports no other chapter's.
Every module is an attribute of the package, imported when first read.
"""

import importlib
import pkgutil

#: The package's modules, read from its folder (not imported), each imported on first access.
MODULES = tuple(
    sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
)

__all__ = ["MODULES", *MODULES]


def __getattr__(name):
    if name not in MODULES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return importlib.import_module(f"{__name__}.{name}")


def __dir__():
    return sorted(set(globals()) | set(MODULES))
