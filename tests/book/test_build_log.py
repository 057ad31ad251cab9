"""The log of ``make book`` (``_build/book.log``) carries no warnings.

Sphinx's own warnings already fail the strict build (``-W``); this check
covers what reaches the log from elsewhere: the kernels that execute the pages
(``[IPKernelApp] WARNING | ...``) and Python warnings (``...Warning: ...``).
"""

from __future__ import annotations

import re

import pytest
from conftest import ROOT

LOG = ROOT / "_build" / "book.log"
WARNING_RES = (
    re.compile(r"\[\w*(Kernel|App)\w*\]\s*(WARNING|ERROR|CRITICAL)"),  # a kernel's own log
    re.compile(r"\b[A-Z]\w*Warning: "),  # Python warnings
    re.compile(r"(^|: )WARNING: "),  # Sphinx
)


@pytest.fixture(scope="module")
def build_log(html_dir, missing_prerequisite) -> list[str]:
    if not LOG.exists():
        missing_prerequisite(f"{LOG.relative_to(ROOT)} not found: build the book with `make book`")
    text = LOG.read_text(encoding="utf-8", errors="replace")
    return re.sub(r"\x1b\[[0-9;]*m", "", text).splitlines()


def test_build_log_has_no_warnings(build_log):
    assert any("build succeeded" in line for line in build_log), (
        "the log is not of a finished build"
    )
    found = [line for line in build_log if any(r.search(line) for r in WARNING_RES)]
    assert not found, f"{len(found)} warning lines in {LOG.relative_to(ROOT)}, e.g. {found[:3]}"
