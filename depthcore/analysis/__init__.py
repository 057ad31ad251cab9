"""What the filters are measured against: the bound, the batch estimate, self-calibration.

* :mod:`~depthcore.analysis.bound`: the Cramér-Rao bound on the state at
  frame ``N``, conditional on the truth and averaged over the prior;
* :mod:`~depthcore.analysis.bound_space`: the same bound for a point in 3-D
  seen as bearing pairs;
* :mod:`~depthcore.analysis.batch_ml`: the batch maximum-likelihood estimate
  from the bearings alone, the baseline without a prior, with the inverse
  Fisher information as its covariance;
* :mod:`~depthcore.analysis.calibration`: simulation-based calibration of the
  exact filter.

Where a new thing goes: a new yardstick for the filters goes here; an
independent route that only checks one goes to the book's ``depthbook.reference``.
It may import every family of filters, never the registry or the studies, which
use it.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
