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
  a filter fed one bearing at a time;
* :mod:`~depthcore.registry.track_files`: a track read from a CSV file
  (:func:`~depthcore.registry.track_files.read`), every frame's state by the
  filters with a smoother (:func:`~depthcore.registry.track_files.per_frame`)
  and its noise levels learned (:func:`~depthcore.registry.track_files.learn`).

Where a new thing goes: a new filter, once its module exists in its family,
gets one entry in :data:`~depthcore.registry.filters.FILTERS`; the command
line, the studies, the API reference and the table of filters of the page
"Using depthcore" follow from the table. A new way to read a track or run
one frame by frame goes in :mod:`~depthcore.registry.track_files`.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
