"""``make records`` (tools/records.py): the new records replace the old only once the run ends.

Each test runs the script on a folder of records and a folder of references of its own, with a
command that stands for the pages: it writes records where ``DEPTHCORE_RECORDS_DIR`` says and
rewrites a reference, then ends well, fails, or is interrupted.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from depthbook.provenance import records
from depthbook.studies import frames

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "tools" / "records.py"

#: The command that stands for the pages: one small study recorded, a reference rewritten,
#: then the exit status given (or a wait, to be interrupted).
PAGES = """
import os, sys, time
from pathlib import Path
from depthbook.provenance import records
from depthbook.studies import frames
records.recorded(frames.frames_study, [3, 4], 12, 1, ("optimal", "ekf"))
Path(sys.argv[1], "page.ipynb").write_text("rewritten")
Path(sys.argv[1], "started").write_text("")
if sys.argv[2] == "wait":
    time.sleep(60)
sys.exit(int(sys.argv[2]) if sys.argv[2] != "wait" else 0)
"""


@pytest.fixture
def folders(tmp_path):
    """A folder of one old record, and a folder of references holding one page's."""
    current, references = tmp_path / "study_records", tmp_path / "_nbval"
    current.mkdir()
    references.mkdir()
    (current / "old-0000000000000000.json").write_text('{"old": true}\n')
    (references / "page.ipynb").write_text("committed")
    return current, references


def _pages(references: Path, outcome: str) -> list[str]:
    """The command that stands for the pages (:data:`PAGES`), ending as ``outcome`` says."""
    return [sys.executable, "-c", PAGES, str(references), outcome]


def _start(current: Path, references: Path, command: list[str]) -> subprocess.Popen:
    """tools/records.py on these folders, running ``command`` (``--keep`` first: the option)."""
    keep = command[:1] == ["--keep"]
    return subprocess.Popen(
        [
            sys.executable,
            str(SCRIPT),
            "--records",
            str(current),
            "--references",
            str(references),
            *command[:keep],
            "--",
            *command[keep:],
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={k: v for k, v in os.environ.items() if not k.startswith("DEPTHCORE_RECORDS")},
    )


def _contents(folder: Path) -> dict:
    return {p.name: p.read_text() for p in sorted(folder.iterdir())}


def test_a_run_that_ends_well_replaces_the_records_whole(folders):
    current, references = folders
    process = _start(current, references, _pages(references, "0"))
    _, err = process.communicate(timeout=120)
    assert process.returncode == 0, err
    names = [p.name for p in current.iterdir()]
    assert len(names) == 1 and names[0].startswith("frames_study-"), names
    record = json.loads((current / names[0]).read_text())
    assert record["function"] == "depthbook.studies.frames:frames_study"
    assert (references / "page.ipynb").read_text() == "rewritten"
    assert sorted(p.name for p in current.parent.iterdir()) == ["_nbval", "study_records"]


@pytest.mark.parametrize("outcome", ["1", "interrupt"])
def test_a_failed_or_interrupted_run_leaves_the_records_and_references_as_they_were(
    folders, outcome
):
    current, references = folders
    before, refs = _contents(current), _contents(references)
    if outcome == "interrupt":
        process = _start(current, references, _pages(references, "wait"))
        deadline = time.monotonic() + 120
        while not (references / "started").exists():
            assert time.monotonic() < deadline and process.poll() is None, process.stderr.read()
            time.sleep(0.1)
        process.send_signal(signal.SIGINT)
    else:
        process = _start(current, references, _pages(references, outcome))
    _, err = process.communicate(timeout=120)
    assert process.returncode == (130 if outcome == "interrupt" else 1), err
    assert _contents(current) == before
    assert _contents(references) == refs
    # the partial new set is gone; nothing is left beside the two folders
    assert sorted(p.name for p in current.parent.iterdir()) == ["_nbval", "study_records"]
    assert "Traceback" not in err
    if outcome == "interrupt":
        assert "interrupted (SIGINT): the committed records kept" in err


def test_a_run_that_records_nothing_changes_nothing(folders):
    current, references = folders
    before = _contents(current)
    process = _start(current, references, [sys.executable, "-c", "pass"])
    _, err = process.communicate(timeout=120)
    assert process.returncode == 1 and "wrote no record" in err
    assert _contents(current) == before


def test_the_committed_records_are_read_from_the_folder_named_while_a_run_writes(
    monkeypatch, tmp_path
):
    monkeypatch.setenv(records.DIRECTORY, str(tmp_path))
    monkeypatch.setenv(records.ENVIRONMENT, "write")
    run = records.recorded(frames.frames_study, [3, 4], 12, 1, ("optimal", "ekf"))
    assert run.path.parent == tmp_path and run.path.is_file()
    monkeypatch.setenv(records.ENVIRONMENT, "require")
    assert records.recorded(frames.frames_study, [3, 4], 12, 1, ("optimal", "ekf")).read


def test_make_records_writes_beside_the_committed_records_and_never_deletes_them_first():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = makefile.split("\nrecords:", 1)[1].split("\n\n", 1)[0]
    assert "tools/records.py --" in recipe
    assert "rm " not in recipe


#: A second command that stands for one page: another small study recorded, and nothing else.
ONE_PAGE = """
from depthbook.studies import frames
from depthbook.provenance import records
records.recorded(frames.frames_study, [3, 5], 12, 2, ("optimal",))
"""


def test_a_kept_run_writes_its_records_and_keeps_the_others(tmp_path):
    current, references = tmp_path / "study_records", tmp_path / "_nbval"
    references.mkdir()
    first = _start(current, references, _pages(references, "0"))
    assert first.communicate(timeout=120) and first.returncode == 0
    (old,) = _contents(current)
    for keep, expected in ((["--keep"], 2), ([], 1)):
        command = [*keep, sys.executable, "-c", ONE_PAGE]
        process = _start(current, references, command)
        _, err = process.communicate(timeout=120)
        assert process.returncode == 0, err
        names = sorted(_contents(current))
        assert len(names) == expected and (old in names) == bool(keep), names
    # a kept record that is not of the current code stops the run, and the folder stays
    (current / "frames_study-0000000000000000.json").write_text('{"old": true}\n')
    before = _contents(current)
    process = _start(current, references, ["--keep", sys.executable, "-c", ONE_PAGE])
    _, err = process.communicate(timeout=120)
    assert process.returncode == 1 and "not current after the run" in err
    assert _contents(current) == before


def test_make_atlas_recomputes_the_atlas_alone_keeping_the_other_records():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = makefile.split("\natlas:", 1)[1].split("\n\n", 1)[0]
    assert "tools/records.py --keep --" in recipe and "beyond_atlas" in recipe
    assert "rm " not in recipe
