"""The command line, ``python -m depthcore``: argument parsing and its plain-text tables.

* :mod:`~depthcore.cli.main`: the parser, the commands and the one-line refusals;
* :mod:`~depthcore.cli.text`: the command line's tables and their legends.

Where a new thing goes: a new command is a function and a subparser in
:mod:`~depthcore.cli.main`; what it prints goes in :mod:`~depthcore.cli.text`.
The command line lists the registry's filters; it holds no filter of its own.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
