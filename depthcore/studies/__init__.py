"""Monte Carlo studies of the filters, and the reproduction of the paper's tables.

* :mod:`~depthcore.studies.trials`: the trials, bearings drawn afresh from a
  ``SeedSequence`` and every filter run on them;
* :mod:`~depthcore.studies.scores`: the scores, as running sums over chunks
  of trials, with their errors, and the tests of a coverage and their power;
* :mod:`~depthcore.studies.medians`: the median absolute error, streamed in a
  histogram of fixed size, with a distribution-free interval;
* :mod:`~depthcore.studies.priors`: the prior's form, an axis of the studies:
  the paper's rule, a range prior, a log-uniform depth, an inverse-depth
  prior, the last three drawing each trial's truth;
* :mod:`~depthcore.studies.pairs`: two filters compared over the same trials;
* :mod:`~depthcore.studies.monte_carlo`: the studies the command line runs
  (which estimate, and which stated uncertainty, to trust);
* :mod:`~depthcore.studies.atlas`: every filter's verdicts over a grid of
  parallax, prior, noise, depth and frames, at the book's size or a cluster's;
* :mod:`~depthcore.studies.coverage_verdicts`: a coverage calibrated within a
  tolerance, outside it, or undecided, at a false-discovery rate, and the trials that takes;
* :mod:`~depthcore.studies.reproduce`: the paper's tables reproduced, and the
  curves of its figures;
* :mod:`~depthcore.studies.tasks`: where the studies' chunks of trials run, in
  this process or as tasks of a Dask cluster, folded in chunk order.

On a cluster: the studies take ``client=`` (a ``distributed.Client``; default
None, this process, with nothing of Dask imported), and with none given run on
the scheduler named by the environment variable ``DEPTHCORE_SCHEDULER`` when it
is set. The results are the same, bit for bit, on any number of workers: each
chunk draws from its own child of the study's seed, by chunk index, and the
chunks are added in chunk order. From the command line,
``python -m depthcore study --workers 4`` starts four local worker processes and
``python -m depthcore study --scheduler tcp://host:8786`` uses a running cluster.

Where a new thing goes: a new study, or a new score, goes here; a study one
the book alone runs goes to the book's own package, ``depthbook``, beside it.
It may import every family below it, through the registry.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
