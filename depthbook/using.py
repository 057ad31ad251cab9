"""The page "Using depthcore": the package's module map and its tables, from the package.

Recommended import: ``from depthbook import using``.

:func:`module_map` lists the families of ``depthcore.SUBPACKAGES``, each with
the first paragraph of its docstring (:func:`module_summary`) and its modules, and
:func:`filter_table` every filter of the registry, so that the page's tables
follow the package rather than a copy of it; :func:`command_help` is a
command's ``--help`` as the command line prints it, and :func:`limit` prints a
limit of the inputs as the page's table of limits does.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import io
import os
import re

import depthcore
from depthbook.notebook import MarkdownTable
from depthcore.cli import main as cli
from depthcore.cli import text as cli_text
from depthcore.problem import checks
from depthcore.registry import tracking
from depthcore.registry.filters import FILTERS


def family(module: str) -> str:
    """The family of a module: ``depthcore.exact.optimal`` -> ``exact``; a top module's name."""
    parts = module.split(".")
    if len(parts) < 2 or parts[0] != "depthcore":
        raise ValueError(f"module must be one of depthcore's modules, got {module!r}")
    return parts[1]


def module_summary(module: str) -> str:
    """The first paragraph of a module's docstring on one line, its reST markup made Markdown.

    A cross-reference role becomes code with the name it shows (the last part
    of the name when it is abbreviated with a tilde), double backquotes become
    single ones, and a citation is left to the module's own page.
    """
    doc = inspect.getdoc(importlib.import_module(module)) or ""
    text = " ".join(doc.split("\n\n")[0].split())
    text = re.sub(r":\w+:`~[\w.]*?(\w+)`", r"`\1`", text)
    text = re.sub(r":\w+:`([\w.]+)`", r"`\1`", text)
    text = re.sub(r"\s*\[\w+\]_", "", text)
    return text.replace("``", "`")


def module_map() -> MarkdownTable:
    """Every family of ``depthcore.SUBPACKAGES``: its package, what it holds (the first
    paragraph of its docstring, :func:`module_summary`) and its modules, in the order of
    ``depthcore.MODULES``; each module's own summary is the API reference's."""
    rows = []
    for name in depthcore.SUBPACKAGES:
        package = f"depthcore.{name}"
        modules = [m.rpartition(".")[2] for m in depthcore.MODULES if m.startswith(package + ".")]
        listed = ", ".join(f"`{m}`" for m in modules)
        rows.append([f"`{package}`", module_summary(package), listed])
    return MarkdownTable(["family", "what it holds", "its modules"], rows, widths=(22, 43, 35))


def filter_table() -> MarkdownTable:
    """Every filter of the registry: name, label, family, frames, noise, default, smoother."""
    return MarkdownTable(
        ["name", "label", "family", "frames", "process noise", "default", "smoother"],
        [
            [
                f"`{name}`",
                f.label,
                f.family.replace("_", "-"),
                "any $N \\geq 3$" if f.any_frames else "the paper's three",
                "$q \\geq 0$" if f.with_process_noise else "$q = 0$ only",
                "yes" if f.default else "when named",
                "yes" if f.smoother is not None else "",
            ]
            for name, f in FILTERS.items()
        ],
        widths=(25, 21, 13, 12, 11, 9, 9),
    )


def limits_table() -> MarkdownTable:
    """What the library and the command line refuse: every input and its boundary.

    The limits are read from the modules that enforce them
    (:mod:`depthcore.problem.checks`, :mod:`depthcore.registry.tracking` and the
    command line's parser), so that the page's table follows them.
    """
    return MarkdownTable(
        ["input", "boundary"],
        [
            [
                "a degenerate triple",
                f"$\\lvert\\mu_1 + \\mu_3 - 2\\mu_2\\rvert \\leq$ "
                f"{limit(checks.DEGENERACY_TOL)}: no finite depth explains the bearings "
                "(with more bearings: every second difference)",
            ],
            [
                "a solution behind the camera",
                "the noise-free depth at the first frame, $c_2 - 2$, must be positive",
            ],
            [
                "a non-finite value",
                "an infinity in $\\mu$ (NaN there is a missing frame), a NaN or "
                "infinity in $\\rho$ at a frame with a bearing, in the prior mean or covariance",
            ],
            ["too few bearings", "fewer than 3 present: two bearings fit any depth alike"],
            [
                "a prior covariance",
                "symmetric (to a relative tolerance) and positive definite (Cholesky)",
            ],
            [
                "a prior mean the EKF cannot use",
                "a predicted depth $n_2 \\leq 0$, where the projection $x/y$ is undefined",
            ],
            [
                "$\\rho$",
                f"from {limit(tracking.RHO_RANGE[0])} to {limit(tracking.RHO_RANGE[1])}",
            ],
            [
                "`--mu`",
                f"3 to {checks.MAX_FRAMES:,} bearings, magnitudes up to {limit(cli.MU_MAX)}",
            ],
            [
                "`--prior-mean`",
                f"magnitudes up to {limit(cli.PRIOR_MEAN_MAX)} (beyond it the "
                "particle filter's weights collapse onto one particle)",
            ],
            [
                "`--prior-cov`",
                f"entries up to {limit(cli.PRIOR_COV_RANGE[1])} in magnitude, eigenvalues "
                f"at least {limit(cli.PRIOR_COV_RANGE[0])}",
            ],
            [
                "`--process-noise`",
                f"0, or from {cli.PROCESS_NOISE_MIN!r} (the smallest normal double: "
                "the inverse of a smaller noise overflows) to "
                f"{limit(tracking.PROCESS_NOISE_MAX)}",
            ],
            ["`study --frames`", f"from 3 to {checks.MAX_FRAMES:,}"],
            [
                "`study --trials`",
                f"from 1 to {cli.MAX_TRIALS:,} (a limit on run time: trials run in "
                "chunks and only running sums are kept)",
            ],
            [
                "`study --particles`",
                f"from {cli.MIN_PARTICLES} to {cli.MAX_PARTICLES:,}; the study "
                f"holds at most {cli.PARTICLES_IN_FLIGHT:,} particles in memory at once",
            ],
            [
                "`--filters`",
                "names of the registry, each at most once; one that cannot run on the "
                "frames or the process noise given is listed by `estimate` as not run "
                "and refused by `study`",
            ],
            [
                "a flag given twice, or one the mode ignores",
                "refused; abbreviations of flags are not accepted",
            ],
            [
                "numbers in the library",
                "one conversion, `depthcore.problem.checks.as_float`: complex, "
                "boolean, object and text values are refused by name, as is an empty batch",
            ],
            [
                "overflow",
                "a run whose numbers overflow the doubles (depth nodes or covariances near "
                "the largest double) is refused by name, never answered with NaN",
            ],
        ],
    )


def limit(x: float) -> str:
    """A limit as the page's table prints it: ``1e6`` rather than ``1e+06``, ``1e-9``."""
    return re.sub(r"e\+?0*(\d)", r"e\1", f"{x:g}").replace("e-0", "e-")


def command_help(command: str, columns: int = 100) -> str:
    """The ``--help`` of one command of ``python -m depthcore``, as the parser prints it.

    Parameters
    ----------
    command : str
        One of the commands: ``reproduce``, ``estimate``, ``study``, ``figures``.
    columns : int
        The width the help is wrapped to (argparse reads it from ``COLUMNS``).

    Returns
    -------
    str
        The help text, ending with the command's examples.

    Raises
    ------
    ValueError
        If ``command`` is not one of the commands.
    """
    if command not in cli_text.EXAMPLES or command == "all":
        raise ValueError(f"command must be one of python -m depthcore's commands, got {command!r}")
    out = io.StringIO()
    before = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(columns)
    try:
        with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
            cli.build_parser().parse_args([command, "--help"])
    finally:
        if before is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = before
    return out.getvalue()
