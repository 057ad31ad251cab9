"""The command line, ``python -m depthcore``: argument parsing and its plain-text tables.

* :mod:`~depthcore.cli.main`: the parser, the commands and their exit statuses;
* :mod:`~depthcore.cli.parsing`: what the commands share: the parser (each
  option once), their common options, the progress bar and the output;
* :mod:`~depthcore.cli.refusals`: the one-line refusals in the user's words;
* :mod:`~depthcore.cli.priors`: ``estimate``'s prior, ``--prior-mean``,
  ``--prior-cov`` and ``--prior-depth``, on three coordinates or, for pairs, five,
  and the rule it follows without one;
* :mod:`~depthcore.cli.text`: the command line's tables and their legends;
* :mod:`~depthcore.cli.tracks`: ``estimate``'s tracks in the user's words:
  ``--mu-file`` (standard input for ``-``), ``--mu``, ``--nu``, ``--steps``,
  ``--direction``, ``--speed``, ``--focal``, ``--cx``, ``--cy``, ``--gate``, the track
  file's format and the direction's convention as ``estimate --help`` shows
  them, and a long track's rows spooled;
* :mod:`~depthcore.cli.atlas_command`: ``atlas``, every filter's verdicts over
  a grid of settings, in this process or on a Dask cluster;
* :mod:`~depthcore.cli.cluster`: the ``--workers`` and ``--scheduler`` options that
  ``study`` and ``atlas`` share.

Where a new thing goes: a new command is a function and a subparser in
:mod:`~depthcore.cli.main`; what it prints goes in :mod:`~depthcore.cli.text`;
what reads a track or runs it frame by frame is the library's
(:mod:`depthcore.registry.track_files`, :mod:`depthcore.registry.track_runs`);
the command line checks its options and prints.
The command line lists the registry's filters; it holds no filter of its own.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
