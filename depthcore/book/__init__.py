"""The book's wing: each chapter's experiments, figures and glued texts, one module per chapter.

The mathematics (the model, the quadrature, the filters and their registry,
the studies) knows nothing of the book; the modules here run it for the book's
pages and show what it returns. A chapter's module holds its experiment, its
figures and the texts its page glues, in that order:

* :mod:`~depthcore.book.intro`: the intro's headline of the extensions;
* :mod:`~depthcore.book.intuition`: the first chapter, why three bearings
  fix a depth (two fit every depth, the known step fixes the scale);
* :mod:`~depthcore.book.paper`: the paper's own chapters, the model, the
  filters, the marginals, Figures 2-6 and the appendix;
* :mod:`~depthcore.book.using`: the page "Using depthcore", its module map and
  tables read from the package;
* :mod:`~depthcore.book.beyond_filters`, :mod:`~depthcore.book.beyond_particles`,
  :mod:`~depthcore.book.beyond_study`,
  :mod:`~depthcore.book.beyond_sweeps`, :mod:`~depthcore.book.beyond_linear`,
  :mod:`~depthcore.book.beyond_frames`, :mod:`~depthcore.book.beyond_bound`,
  :mod:`~depthcore.book.beyond_hard`, :mod:`~depthcore.book.beyond_conjecture`,
  :mod:`~depthcore.book.beyond_atlas`,
  :mod:`~depthcore.book.beyond_tracks`, :mod:`~depthcore.book.beyond_stonesoup`:
  the chapters beyond the paper, one each, in the book's order.

What several chapters share has one place each: :mod:`~depthcore.book.style`
the plots' style, :mod:`~depthcore.book.notebook` what a page shows when it
runs as a plain notebook, :mod:`~depthcore.book.crossref` the book's
references resolved in Jupyter, :mod:`~depthcore.book.live` the live controls
of the figure pages and :mod:`~depthcore.book.benchmark_tables` the
benchmarks' tables. What they share with the rest of the package lives below
it: the numbers as the book prints them (:mod:`depthcore.formatting`), the
records of the chapters' Monte Carlo studies, which their pages read rather
than compute (:mod:`depthcore.provenance.records`), the studies two chapters
run (:mod:`depthcore.studies`).

Where a new thing goes: a new chapter's experiment, figures and texts are one
module here, ``beyond_<topic>.py``, and its page ``book/beyond_<topic>.md``.
A chapter module imports no other chapter's: what two chapters need moves down
into the package. Nothing outside this wing imports it.

Every module is an attribute of the package, imported when first used
(``import depthcore; depthcore.book.paper`` works).
"""

from pathlib import Path

from depthcore import _paths

#: The wing's modules, read from its folder (not imported), each imported on first access.
MODULES = _paths.modules_in(Path(__file__).parent)

__all__ = ["MODULES", *MODULES]


def __getattr__(name):
    return _paths.submodule(__name__, name)


def __dir__():
    return sorted(set(globals()) | set(MODULES))
