"""Every benchmark has a committed record, complete and measured on the current code.

The book and the README show the numbers of ``depthbook/provenance/benchmark_records/<name>.json``
(:mod:`depthbook.provenance.benchmarks`). These tests never run a benchmark: they read
the records and compare each one's fingerprint with the sources it measured,
so that a change of the measured code names the record to measure again.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import depthcore
from depthbook import benchmark_tables
from depthbook.provenance import benchmarks
from depthcore import __version__

from helpers import OLDER_KERNELS

SCRIPTS = sorted((benchmarks.ROOT / "benchmarks").glob("bench_*.py"))
NAMES = [p.stem for p in SCRIPTS]

#: The tables of each record's results.
TABLES = {
    "bench_bank": {"three_frames", "online", "many_trials", "matched_accuracy", "targets"},
    "bench_ekf_filterpy": {
        "depthcore_ms",
        "filterpy_ms",
        "ratio",
        "ratio_min",
        "ratio_max",
        "mean_difference_sd",
    },
    "bench_frames": {"frames", "filters"},
    "bench_features": {"space", "plane", "target_ms"},
    "bench_import": {"numpy_s", "depthcore_after_numpy_s", "target_s"},
    "bench_kalman": {
        "depthcore_ms",
        "filterpy_ms",
        "ratio",
        "ratio_min",
        "ratio_max",
        "filter_ratio",
        "smoother_ratio",
        "dimensions",
        "target_ratio",
    },
    "bench_long_track": {"frames", "filters"},
    "bench_optimal": {"moments", "per_triple"},
    "bench_range_ekf": {"fig2", "ten_frames"},
    "bench_rbpf": {"exact", "equal_cost", "convergence"},
    "bench_stonesoup": {"per_update", "long_track", "tracker"},
    "bench_trials": {"vectorised_s", "trial_by_trial_s", "ratio", "estimate_sd"},
    "bench_workers": {
        "in_process_s",
        "one_s",
        "two_s",
        "cores_s",
        "speedup_one",
        "speedup_two",
        "speedup_cores",
        "two_over_one",
        "workers",
    },
}


def test_every_script_is_known():
    assert NAMES == sorted(TABLES), "a benchmark script was added or removed: update TABLES"


@pytest.mark.parametrize("name", NAMES)
def test_every_script_has_a_committed_record(name):
    path = benchmarks.RESULTS / f"{name}.json"
    assert path.is_file(), f"{name} has no record: run `make bench BENCH={name}`"


#: What a record says of the machine it was measured on (depthbook.provenance.benchmarks.machine).
MACHINE_FIELDS = ("cores", "cpu", "processor", "system", "python", "numpy", "scipy", "simd", "blas")


def test_the_machine_names_the_blas_kernels_the_processor_runs():
    # OpenBLAS picks its kernels when loaded; OPENBLAS_CORETYPE overrides the choice,
    # and a record names the kernels its numbers were computed with.
    here = benchmarks.machine()
    assert tuple(here) == MACHINE_FIELDS
    built = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
    assert here["blas"].startswith(built["name"])
    if "openblas" not in built["name"] or platform.machine() != "x86_64":
        return
    assert here["blas"].endswith(" kernels")
    code = "from depthbook.provenance import benchmarks; print(benchmarks.machine()['blas'])"
    env = dict(os.environ, **OLDER_KERNELS)
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().endswith(", Nehalem kernels")


@pytest.mark.parametrize("name", NAMES)
def test_every_record_has_its_fields(name):
    r = benchmarks.read(name)
    assert set(benchmarks.FIELDS) <= set(r), f"{name}: fields missing"
    assert r["script"] == f"benchmarks/{name}.py"
    assert r["command"] == benchmarks.command(name)
    assert datetime.datetime.fromisoformat(r["date"]).tzinfo is not None
    assert set(r["machine"]) >= set(MACHINE_FIELDS)
    assert isinstance(r["machine"]["cores"], int) and r["machine"]["cores"] >= 1
    release = r["depthcore_version"].partition("+")[0]  # its commit: tests/test_provenance.py
    assert tuple(map(int, release.split("."))) <= tuple(map(int, __version__.split(".")))
    assert r["units"] == benchmarks.UNITS
    assert f"benchmarks/{name}.py" in r["fingerprint"]
    assert any(p.startswith("depthcore/") for p in r["fingerprint"])
    assert r["sizes"], f"{name}: no sizes"
    assert TABLES[name] <= set(r["results"]), f"{name}: results missing"


@pytest.mark.parametrize("name", NAMES)
def test_every_record_measured_the_current_code(name):
    r = benchmarks.read(name)
    changed = benchmarks.stale(r)
    assert not changed, (
        f"depthbook/provenance/benchmark_records/{name}.json is stale: "
        f"{', '.join(changed)} changed "
        f"since it was recorded on {r['date']}; measure again with `make bench BENCH={name}` "
        f"(`{r['command']}`)"
    )


def test_the_fingerprint_ignores_prose_and_sees_code(tmp_path):
    a, b, c = tmp_path / "a.py", tmp_path / "b.py", tmp_path / "c.py"
    a.write_text('"""Module."""\n\n\ndef f(x):\n    """Twice x."""\n    return 2 * x\n')
    b.write_text('"""Other words."""\n# a comment\ndef f(x):\n    return 2 * x  # twice\n')
    c.write_text('"""Module."""\n\n\ndef f(x):\n    """Twice x."""\n    return 3 * x\n')
    assert benchmarks.fingerprint(a) == benchmarks.fingerprint(b)
    assert benchmarks.fingerprint(a) != benchmarks.fingerprint(c)
    with pytest.raises(ValueError, match="path"):
        benchmarks.fingerprint(tmp_path / "missing.py")


def test_a_changed_source_makes_a_record_stale():
    r = benchmarks.read("bench_optimal")
    assert benchmarks.stale(r) == []
    path = next(p for p in r["fingerprint"] if p.startswith("depthcore/"))
    r["fingerprint"][path] = "0" * 64
    assert benchmarks.stale(r) == [path]


def test_a_quick_run_leaves_the_committed_record(tmp_path, monkeypatch):
    script = tmp_path / "bench_probe.py"
    shutil.copy(benchmarks.ROOT / "benchmarks" / "bench_trials.py", script)
    monkeypatch.setattr(benchmarks, "ROOT", tmp_path)
    monkeypatch.setattr(benchmarks, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(benchmarks, "QUICK_RESULTS", tmp_path / "quick")
    (tmp_path / "depthcore" / "exact").mkdir(parents=True)
    optimal = Path(depthcore.__file__).parent / "exact" / "optimal.py"
    shutil.copy(optimal, tmp_path / "depthcore" / "exact")
    path = benchmarks.write(script, ["exact.optimal"], {"trials": 1}, {"x_s": 1.0}, full=False)
    assert path == tmp_path / "quick" / "bench_probe.json"
    assert not (tmp_path / "results").exists()
    record = json.loads(path.read_text())
    assert record["fingerprint"] == {
        "bench_probe.py": benchmarks.fingerprint(script),
        "depthcore/exact/optimal.py": benchmarks.fingerprint(
            tmp_path / "depthcore" / "exact" / "optimal.py"
        ),
    }
    full = benchmarks.write(script, ["exact.optimal"], {"trials": 1}, {"x_s": 1.0})
    assert full == tmp_path / "results" / "bench_probe.json"
    assert benchmarks.read("bench_probe", tmp_path / "results")["results"] == {"x_s": 1.0}


def test_read_names_an_unknown_benchmark():
    with pytest.raises(ValueError, match="name"):
        benchmarks.read("bench_nothing")


def test_the_readme_shows_the_records():
    """The README's numbers from the benchmarks are those of the records (tools/readme.py)."""
    sys.path.insert(0, str(benchmarks.ROOT / "tools"))
    import readme

    text = readme.README.read_text(encoding="utf-8")
    findings = " ".join(text.split("<!-- readme:findings -->", 1)[1].split("<!--", 1)[0].split())
    texts = readme.cost_texts({name: benchmarks.read(name) for name in NAMES})
    missing = {
        key: value
        for key, value in texts.items()
        if not re.search(rf"(?<![\w.,]){re.escape(value)}(?![\w]|[.,]\d)", findings)
    }
    assert not missing, (
        f"README.md's benchmark numbers differ from depthbook/provenance/benchmark_records/ "
        f"({missing}): run `{readme.COMMAND}`"
    )


def test_the_optimal_filters_record_holds_what_the_book_says_of_it():
    # book/reproducing.md and book/beyond_cost.md: the 1-D route to 1e-8 in milliseconds,
    # over 10,000 times faster than adaptive cubature, over 1,000 times faster than the
    # 3-D Gauss-Legendre grid
    m = benchmarks.read("bench_optimal")["results"]["moments"]
    assert m["one_d_ms"] < 100 and m["one_d_error_sd"] < 1e-8 and m["one_d_estimate_sd"] < 1e-8
    assert m["nquad_ratio"] > 1e4
    assert m["grid_ratio"] > 1e3


def test_the_records_sizes_are_those_the_benchmarks_are_known_by():
    # The EKF over 10,000 trials, the optimal moments over 10,000 Monte Carlo trials, the
    # RBPF's RMS over 10 independent runs, the import's target of at most 0.15 s
    assert benchmarks.read("bench_ekf_filterpy")["sizes"]["trials"] == 10_000
    assert benchmarks.read("bench_trials")["sizes"]["trials"] == 10_000
    assert benchmarks.read("bench_rbpf")["sizes"]["repeats"] == 10
    assert benchmarks.read("bench_import")["results"]["target_s"] == 0.15


def test_a_record_covers_every_module_its_modules_import():
    # the exact posterior imports the bank (which imports the linear Kalman filter) and the
    # mixture, and the model: all are measured with it; the book is not
    closure = benchmarks.measured_modules(["exact.posterior"])
    assert {
        "exact.posterior",
        "exact.bank",
        "exact.mixture",
        "kalman.linear",
        "problem.model",
        "problem.checks",
    } <= set(closure)
    assert "exact.posterior" in benchmarks.measured_modules(["exact.optimal"])
    assert not [m for m in closure if m.startswith(("book", "cli"))]
    prints = benchmarks.fingerprints(
        benchmarks.ROOT / "benchmarks" / "bench_bank.py", ["exact.posterior"]
    )
    assert set(prints) == {"benchmarks/bench_bank.py"} | {
        benchmarks.module_path(m) for m in closure
    }
    # a module that enters the closure later makes the record stale
    r = benchmarks.read("bench_bank")
    del r["fingerprint"]["depthcore/kalman/linear.py"]
    assert benchmarks.stale(r) == ["depthcore/kalman/linear.py"]
    with pytest.raises(ValueError, match="modules"):
        benchmarks.measured_modules(["no_such_module"])


def test_the_bank_records_a_measured_ratio_and_labels_its_extrapolation():
    # the ratio against the particle filter is its measured time over the bank's; the
    # extrapolation to the bank's accuracy sits beside it under its own name
    m = benchmarks.read("bench_bank")["results"]["matched_accuracy"]
    assert m["ratio"] == pytest.approx(m["time_per_run_s"][-1] / m["bank_time_s"])
    assert {"extrapolated_ratio", "extrapolated_particles_needed"} <= set(m)
    row = benchmark_tables.bench_tables({n: benchmarks.read(n) for n in NAMES})["bank"]
    text = row._repr_markdown_()
    assert "measured" in text and "Extrapolated" in text and "not measured" in text


def test_the_kalman_and_frames_records_are_what_the_book_says_of_them():
    # 1,000 steps, agreeing with filterpy; "linear growth": a cost per frame at the
    # largest N no more than twice that at the smallest
    k = benchmarks.read("bench_kalman")
    assert k["sizes"]["steps"] == 1000 and k["results"]["mean_difference_sd"] < 1e-9
    # the plane's models: state dimensions 2, 4, 6, measured in 2-D, filter and smoother timed
    dims = k["results"]["dimensions"]
    assert [row["state_dimension"] for row in dims] == [2, 4, 6]
    for row in dims:
        assert row["measurement_dimension"] == 2 and row["mean_difference_sd"] < 1e-9
        assert {"filter_ratio", "smoother_ratio", "ratio"} <= set(row)
    frames = benchmarks.read("bench_frames")["results"]
    assert frames["frames"] == [30, 100, 300, 1000]
    for row in frames["filters"]:
        assert len(row["ms_per_trial"]) == len(frames["frames"])
        if row["filter"] in ("second_order", "iterated", "iterated smoother", "ekf", "ukf"):
            assert row["growth"] < 2, row["filter"]
