"""The command line, ``python -m depthcore``: argument parsing and its plain-text tables.

* :mod:`~depthcore.cli.main`: the parser, the commands and the one-line refusals;
* :mod:`~depthcore.cli.text`: the command line's tables and their legends;
* :mod:`~depthcore.cli.tracks`: ``estimate``'s tracks: bearings from a CSV file
  (``--mu-file``), gaps, noise per frame and steps, every frame's state
  (``--per-frame``);
* :mod:`~depthcore.cli.atlas_command`: ``atlas``, every filter's verdicts over
  a grid of settings, in this process or on a Dask cluster;
* :mod:`~depthcore.cli.cluster`: the ``--workers`` and ``--scheduler`` options that
  ``study`` and ``atlas`` share.

Where a new thing goes: a new command is a function and a subparser in
:mod:`~depthcore.cli.main`; what it prints goes in :mod:`~depthcore.cli.text`;
what reads a track or runs it frame by frame, in :mod:`~depthcore.cli.tracks`.
The command line lists the registry's filters; it holds no filter of its own.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
