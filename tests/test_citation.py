"""CITATION.cff is complete and valid.

Validated by cffconvert (pinned in requirements-cite.txt, installed by
``make cite-venv`` into ``.venv/cffconvert/`` because it needs jsonschema 3);
without that venv the validation is skipped with a message, and fails under
CI (``CI=true``). The other checks read the file with PyYAML.
"""

from __future__ import annotations

import datetime
import os
import subprocess
from pathlib import Path

import pytest
import yaml

import depthcore

ROOT = Path(__file__).resolve().parent.parent
CFF = ROOT / "CITATION.cff"
CFFCONVERT = ROOT / ".venv" / "cffconvert" / "bin" / "cffconvert"


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


@pytest.fixture(scope="module")
def cff() -> dict:
    return yaml.safe_load(CFF.read_text(encoding="utf-8"))


def test_cffconvert_validates_citation_cff():
    if not CFFCONVERT.exists():
        message = (
            f"{CFFCONVERT.relative_to(ROOT)} not found (run `make cite-venv`): "
            "CITATION.cff not validated"
        )
        if in_ci():
            pytest.fail(message)
        pytest.skip(message)
    run = subprocess.run(
        [str(CFFCONVERT), "--validate", "-i", str(CFF)], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "valid" in run.stdout


def test_citation_cff_describes_this_version_of_the_software(cff):
    assert cff["type"] == "software"
    assert cff["version"] == depthcore.__version__
    released = datetime.date.fromisoformat(str(cff["date-released"]))
    assert released <= datetime.date.today()
    assert cff["license"] == "MIT"
    assert cff["authors"] and cff["title"].startswith("depthcore")


def test_citation_cff_cites_the_paper(cff):
    paper = cff["preferred-citation"]
    assert paper["type"] == "conference-paper"
    assert paper["title"].lower() == "filter based estimates of depth"
    assert paper["authors"][0]["family-names"] == "Maybank"
    assert paper["year"] == 1990
    # the page range and DOI of the BMVA's archive, as the book's bibliography gives them
    assert (paper["start"], paper["end"], paper["doi"]) == ("62.1", "62.6", "10.5244/C.4.62")
    assert paper["publisher"]["name"] == "BMVA Press"
    assert paper in cff["references"]
