"""The command line's refusals in the user's words: one line naming the argument as given.

Recommended import: ``from depthcore.cli import refusals``.

A value out of range is printed exactly as given (:func:`exact`); a refusal
from the library is reworded to name the argument the user gave
(``--prior-cov``, not ``prior_cov``), or the command's inputs when it names
none of them (:func:`users_words`).
"""

from __future__ import annotations

import re

import numpy as np

from depthcore.studies import tasks


def exact(value) -> str:
    """A number as the user gave it: every digit, never rounded to a limit."""
    return repr(float(value))


def check_limits(name: str, values, largest: float) -> None:
    """Refuse a value that is not finite or whose magnitude exceeds ``largest``."""
    v = np.asarray(values, dtype=float)
    bad = ~np.isfinite(v)
    if np.any(bad):
        raise ValueError(f"{name} must be finite, got {exact(v[bad][0])}")
    big = np.abs(v) > largest
    if np.any(big):
        raise ValueError(f"{name} must be at most {largest:g} in magnitude, got {exact(v[big][0])}")


#: The library's names of the command line's arguments.
FLAGS = {
    "mu": "--mu",
    "rho": "--rho",
    "prior_mean": "--prior-mean",
    "prior_cov": "--prior-cov",
    "process_noise": "--process-noise",
    "q": "--process-noise",
    "truth": "--truth",
    "trials": "--trials",
    "seed": "--seed",
    "prior": "--prior",
    "names": "--filters",
    "filters": "--filters",
    "n_particles": "--particles",
    "particles": "--particles",
    "frames": "--frames",
    "steps": "--steps",
    "direction": "--direction",
    "speed": "--speed",
    "focal": "--focal",
    "cx": "--cx",
    "cy": "--cy",
    "out": "--out",
    "workers": "--workers",
    "scheduler": "--scheduler",
    tasks.SCHEDULER: tasks.SCHEDULER,  # the environment's scheduler, named as the user set it
}

#: The arguments a refusal blames when the library names none of them.
INPUTS = {
    "reproduce": "the paper's scenarios",
    "estimate": "--mu, --rho and the prior",
    "study": "--truth, --rho, --frames and --process-noise",
    "atlas": "--size",
}

#: A refusal when a filter's covariance turns out singular.
SINGULAR = {
    "reproduce": "a filter's covariance is singular in double precision",
    "estimate": "--mu, --rho and the prior have no answer: a filter's covariance is singular "
    "in double precision; try a larger --rho or a broader --prior-cov",
    "study": "--particles and --rho have no answer: a filter's covariance is singular (too few "
    "particles carry weight, or the noise is too small to resolve); try more --particles or "
    "a larger --rho",
    "atlas": "a filter's covariance is singular in double precision",
}

_LEADING = re.compile(r"^([A-Za-z_][A-Za-z_0-9]*)(\[[^\]]*\])?(?=[\s:,])")


def users_words(command: str, message: str, words=None) -> str:
    """A refusal naming the argument as the user gave it (``--prior-cov``, not ``prior_cov``).

    ``words`` maps the library's names to the user's where they differ from
    :data:`FLAGS` (a file's columns).
    """
    message = one_line(message)
    if message.startswith("-"):
        return message
    flags = {**FLAGS, **(words or {})}
    m = _LEADING.match(message)
    if m and m.group(1) in flags:
        return flags[m.group(1)] + (m.group(2) or "") + message[m.end() :]
    if m and message[m.end() :].startswith(":"):  # an internal name: drop it
        message = message[m.end() + 1 :].strip()
    return f"{INPUTS[command]} have no answer: {message}"


def one_line(text: str) -> str:
    """``text`` on one line, its runs of white space single spaces."""
    return " ".join(str(text).split())
