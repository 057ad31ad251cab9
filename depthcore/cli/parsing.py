"""The command line's parser and what its commands share.

Recommended import: ``from depthcore.cli import parsing``.

:class:`Parser` takes negative numbers as values and each option once, and
refuses in one line; :func:`command` makes a command's parser with its help
and examples, and :func:`add_json`, :func:`add_filters` and
:func:`add_process_noise` give it the options the commands share;
:func:`refuse_ignored` and :func:`named_once` refuse options given in vain or
a name given twice; :func:`with_bar` shows a progress bar on a terminal; and
:func:`write` writes the output, raising :class:`WriteError` when it cannot.
"""

from __future__ import annotations

import argparse
import os
import re
import sys

from depthcore.cli import refusals
from depthcore.cli import text as cli_text
from depthcore.registry.filters import names

# A negative number in any notation (-1, -.5, -1e-1, -1E+3, -inf, -nan) is a value.
_NEGATIVE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.I)


class _Once:
    """Mixed into every option's action: refuses a second use; records in ``namespace._given``."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = namespace.__dict__.setdefault("_given", set())
        if self.dest in given:
            raise argparse.ArgumentError(self, "given more than once; give it once")
        given.add(self.dest)
        super().__call__(parser, namespace, values, option_string)


class Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE
        self._has_negative_number_optionals = []

    def _add_action(self, action):
        if action.option_strings and not isinstance(
            action, (_Once, argparse._HelpAction, argparse._VersionAction)
        ):
            action.__class__ = type(f"Once{type(action).__name__}", (_Once, type(action)), {})
        return super()._add_action(action)

    def error(self, message):
        """Exit with status 2, ``message`` in one line after the program's name."""
        self.exit(2, f"{self.prog}: error: {refusals.one_line(message)}\n")

    def _print_message(self, message, file=None):
        # argparse drops a failed write of --help or --version silently; report it
        if message and (file is None or file is sys.stdout):
            write(message)
        else:
            super()._print_message(message, file)


def _bar(total: int, desc: str, unit: str):
    """A progress bar on stderr when it is a terminal and tqdm is installed, else ``None``."""
    if not sys.stderr.isatty():
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # the extra depthcore[plot] is not installed: no bar
        return None

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr)


def _progress(bar):
    """``progress(done, total)`` moving ``bar`` (or doing nothing without one)."""

    def progress(done, total):
        if bar is not None:
            bar.total = total
            bar.update(done - bar.n)

    return progress


def with_bar(desc: str, unit: str, run):
    """``run(progress)`` with a progress bar named ``desc`` on stderr."""
    bar = _bar(None, desc, unit)
    try:
        return run(_progress(bar))
    finally:
        if bar is not None:
            bar.close()


def named_once(values, option: str) -> tuple:
    """``values`` as a tuple; a ``ValueError`` naming those the option ``option`` repeats."""
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise ValueError(f"{option} names {', '.join(repeated)} more than once")
    return tuple(values)


def refuse_ignored(args, mode: str, flags: dict) -> None:
    """Refuse the flags of ``flags`` (dest: flag) that the user gave but ``mode`` ignores."""
    given = [flag for dest, flag in flags.items() if dest in getattr(args, "_given", ())]
    if given:
        raise ValueError(
            f"{' and '.join(given)}: not used by {mode}; "
            f"leave {'them' if len(given) > 1 else 'it'} out"
        )


class WriteError(Exception):
    """The output could not be written: one line, exit status 1."""


def write(text: str) -> None:
    """Write ``text`` to standard output, raising :class:`WriteError` if it cannot."""
    stream = sys.stdout
    if stream is None:
        raise WriteError("cannot write the output: standard output is closed")
    try:
        stream.write(text)
        stream.flush()
    except (OSError, ValueError) as exc:
        # nothing more may reach the broken stream, not even at exit
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, stream.fileno())
        except (OSError, ValueError):
            pass
        reason = getattr(exc, "strerror", None) or str(exc)
        raise WriteError(f"cannot write the output to standard output: {reason}") from None


def command(sub, common, name: str, summary: str) -> argparse.ArgumentParser:
    """The parser of command ``name``: ``summary`` its help and, as a sentence, its description.

    ``name`` is a key of ``cli_text.EXAMPLES`` (the epilog); ``summary`` one
    line, lower case, without a full stop.
    """
    return sub.add_parser(
        name,
        parents=[common],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=cli_text.EXAMPLES[name],
        help=summary,
        description=f"{summary[0].upper()}{summary[1:]}.",
    )


def add_json(parser: argparse.ArgumentParser, run) -> None:
    """The last option of a command that prints a table, ``--json``, and what the command runs."""
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.set_defaults(run=run)


def add_filters(parser: argparse.ArgumentParser, what: str, note: str = "") -> None:
    """``--filters`` (the registry's defaults): ``what`` begins the help, ``note`` ends it."""
    every, defaults = names(), names(default=True)
    parser.add_argument(
        "--filters",
        nargs="+",
        default=list(defaults),
        choices=every,
        metavar="NAME",
        help=f"{what} (default: {' '.join(defaults)}; also "
        f"{' '.join(n for n in every if n not in defaults)}){note}",
    )


def add_process_noise(parser: argparse.ArgumentParser, default: str, note: str = "") -> None:
    """``--process-noise``, 0 by default: ``default`` says what 0 means, ``note`` ends its help."""
    parser.add_argument(
        "--process-noise",
        type=float,
        default=0.0,
        metavar="Q",
        help=f"SD of the velocity's change per frame (default 0{default}){note}",
    )
