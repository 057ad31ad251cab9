"""``python -m depthcore``: the command line, :mod:`depthcore.cli`."""

import sys

from depthcore.cli.main import main

sys.exit(main())
