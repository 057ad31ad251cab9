"""Monte Carlo studies of the filters, and the reproduction of the paper's tables.

* :mod:`~depthcore.studies.trials`: the trials, bearings drawn afresh from a
  ``SeedSequence`` and every filter run on them;
* :mod:`~depthcore.studies.scores`: the scores, as running sums over chunks
  of trials, with their errors;
* :mod:`~depthcore.studies.pairs`: two filters compared over the same trials;
* :mod:`~depthcore.studies.monte_carlo`: the studies the command line runs
  (which estimate, and which stated uncertainty, to trust);
* :mod:`~depthcore.studies.frames`: the study at several numbers of frames;
* :mod:`~depthcore.studies.hardness`: where the problem is hard, across
  parallax, prior and depth;
* :mod:`~depthcore.studies.reproduce`: the paper's tables reproduced, and the
  curves of its figures;
* :mod:`~depthcore.studies.verdicts`: what the replication found, one verdict
  per figure and for Theorem 1, decided from those tables.

Where a new thing goes: a new study, or a new score, goes here; a study one
chapter of the book alone runs goes with that chapter in :mod:`depthcore.book`.
It may import every family below it, through the registry.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
