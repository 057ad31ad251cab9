"""Every filter under one name, one calling convention and one result.

* :mod:`~depthcore.registry.estimates`: a filter's result,
  :class:`~depthcore.registry.estimates.Estimate`, and how each family of
  filters is scored;
* :mod:`~depthcore.registry.adapters`: each filter in the calling convention
  ``(mu, rho, prior_mean, prior_cov, process_noise, **options)``, and the
  smoothers;
* :mod:`~depthcore.registry.filters`: the table
  :data:`~depthcore.registry.filters.FILTERS`, by name;
* :mod:`~depthcore.registry.tracking`: :func:`~depthcore.registry.tracking.track`,
  one track filtered and smoothed at every frame;
* :mod:`~depthcore.registry.online`: :func:`~depthcore.registry.online.start`,
  a filter fed one bearing at a time.

Where a new thing goes: a new filter, once its module exists in its family,
gets one entry in :data:`~depthcore.registry.filters.FILTERS`; the command
line, the studies, the API reference and the table of filters of the page
"Using depthcore" follow from the table.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
