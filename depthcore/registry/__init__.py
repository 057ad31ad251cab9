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
* :mod:`~depthcore.registry.track_files`: a track read from a CSV file, row
  by row (:func:`~depthcore.registry.track_files.open_track`) or whole
  (:func:`~depthcore.registry.track_files.read`);
* :mod:`~depthcore.registry.track_runs`: a track run frame by frame, every
  frame's state held whole (:func:`~depthcore.registry.track_runs.per_frame`)
  or streamed through the online filters
  (:func:`~depthcore.registry.track_runs.streamed`), and its noise levels
  learned (:func:`~depthcore.registry.track_runs.learn`).

Where a new thing goes: a new filter, once its module exists in its family,
gets one entry in :data:`~depthcore.registry.filters.FILTERS`; the command
line, the studies, the API reference and the table of filters of the page
"Using depthcore" follow from the table. A new way to read a track goes in
:mod:`~depthcore.registry.track_files`, to run one frame by frame in
:mod:`~depthcore.registry.track_runs`.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
