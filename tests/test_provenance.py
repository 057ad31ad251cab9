"""Where the records were computed, and by which code: stated from the records, never assumed."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

import depthcore
from depthbook.provenance import benchmarks, environment, records

ROOT = Path(__file__).resolve().parent.parent
#: A record's version: the package's, and in a checkout the commit of the code that computed it.
VERSION = re.compile(r"^(?P<release>\d+\.\d+\.\d+)(?:\+g(?P<commit>[0-9a-f]{7,40}))?$")
STUDIES = [records.read(p) for p in records.committed()]
MEASURED = [benchmarks.read(p.stem) for p in sorted(benchmarks.RESULTS.glob("*.json"))]


def _release_at(commit: str) -> str | None:
    """depthcore's version in the code of ``commit``; None outside a git checkout.

    Raises
    ------
    AssertionError
        When the checkout has no such commit.
    """
    if not (ROOT / ".git").exists() or shutil.which("git") is None:
        return None
    out = subprocess.run(
        ["git", "show", f"{commit}:depthcore/__init__.py"], cwd=ROOT, capture_output=True, text=True
    )
    assert out.returncode == 0, f"no commit {commit} in this checkout"
    return re.search(r'^__version__ = "([^"]+)"$', out.stdout, re.M).group(1)


def _release(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in version.split("."))


@pytest.mark.parametrize(
    "kind, rows", [("study", STUDIES), ("benchmark", MEASURED)], ids=["study", "benchmark"]
)
def test_every_record_names_the_release_and_the_commit_that_computed_it(kind, rows):
    for record in rows:
        version = str(record["depthcore_version"])
        match = VERSION.match(version)
        assert match, f"{kind} record {record.get('key')}: version {version!r}, not clean"
        assert match["commit"], f"{kind} record {record.get('key')}: no commit in {version!r}"
        # the release it names is the code's at that commit, and no later than this one's
        assert _release_at(match["commit"]) in (match["release"], None), version
        assert _release(match["release"]) <= _release(depthcore.__version__)


def test_the_code_version_is_the_release_with_the_checkouts_commit():
    version = environment.code_version()
    assert version.startswith(depthcore.__version__)
    if (ROOT / ".git").exists() and shutil.which("git"):
        assert re.fullmatch(r"\d+\.\d+\.\d+\+g[0-9a-f]{7}(\.dirty)?", version), version


def _record(cpu: str, date: str, version: str) -> dict:
    machine = dict(benchmarks.machine(), cpu=cpu, processor="family 1, model 2")
    return {"machine": machine, "date": f"{date}T10:00:00+00:00", "depthcore_version": version}


def test_the_origins_name_each_machine_its_dates_and_versions():
    found = environment.origins(
        {
            "study records": [
                _record("Chip A", "2026-12-02", "0.2.0+gaaaaaaa"),
                _record("Chip A", "2026-12-01", "0.2.0+gaaaaaaa"),
            ],
            "benchmark records": [_record("Chip B", "2026-11-29", "0.2.0+gbbbbbbb")],
        }
    )
    assert [(o["kind"], o["count"], o["dates"]) for o in found] == [
        ("study records", 2, ("2026-12-01", "2026-12-02")),
        ("benchmark records", 1, ("2026-11-29", "2026-11-29")),
    ]
    text = environment.origins_sentence(found)
    assert text.startswith(
        "The 2 study records were computed on 2026-12-01 to 2026-12-02 on Chip A"
    )
    assert "; the 1 benchmark record on 2026-11-29 on Chip B" in text
    assert "0.2.0+gaaaaaaa" in text and "0.2.0+gbbbbbbb" in text
    with pytest.raises(ValueError, match="lacks"):
        environment.origins({"study records": [{"date": "2026-12-01"}]})


def test_the_records_sentence_is_read_from_the_committed_records():
    import re

    text = environment.records_sentence()
    # one clause per kind and machine, their counts adding up to the committed records
    studies = [int(n) for n in re.findall(r"(\d+) study records?\b", text)]
    measured = [int(n) for n in re.findall(r"(\d+) benchmark records?\b", text)]
    assert text.startswith("The ") and sum(studies) == len(STUDIES)
    assert sum(measured) == len(MEASURED)
    assert "the 1 study records" not in text and "the 1 benchmark records" not in text
    for record in STUDIES + MEASURED:
        assert record["machine"]["cpu"] in text and str(record["depthcore_version"]) in text
