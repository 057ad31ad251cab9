"""The book's studies read from their records: the encoding, the modes, and every record current.

The pages call their Monte Carlo studies through ``depthbook.provenance.records.recorded``,
which reads ``depthbook/provenance/study_records/<function>-<key>.json`` when it was made
by the current code. These tests never run a page's study: they check that every
committed record names a function and its arguments, that its key is the key of
that call, and that the code it ran has not changed since (`make records`
computes them again); and, on small calls, that reading a record gives back
what the computation returned, bit for bit.
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from depthbook.provenance import benchmarks, closure, records
from depthbook.studies import frames
from depthcore import SCENARIOS
from depthcore.problem import gaussian
from depthcore.studies import monte_carlo

ROOT = Path(__file__).resolve().parent.parent
COMMITTED = records.committed()


def same(a, b, path="value"):
    """Assert ``a`` and ``b`` are equal in type, dtype, shape and every bit of every float."""
    assert type(a) is type(b), (path, type(a), type(b))
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert a.tobytes() == b.tobytes(), path
    elif isinstance(a, np.generic):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), path
    elif isinstance(a, dict):
        assert list(a) == list(b), path
        for k in a:
            same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), (path, a, b)
    elif isinstance(a, np.random.SeedSequence):
        for name in ("entropy", "spawn_key", "pool_size", "n_children_spawned"):
            assert getattr(a, name) == getattr(b, name), (path, name)
    elif dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    else:
        assert a == b, (path, a, b)


def round_trip(value):
    return records.decode(json.loads(json.dumps(records.encode(value), allow_nan=True)))


# --- the encoding ---------------------------------------------------------------------------

VALUES = {
    "floats": [
        0.1,
        -0.0,
        float("nan"),
        float("inf"),
        -float("inf"),
        5e-324,
        1.7976931348623157e308,
    ],
    "arrays": {
        "f8": np.array([[0.1, np.nan], [-0.0, 1e-300]]),
        "f4": np.array([1 / 3], dtype=np.float32),
        "i8": np.arange(6).reshape(2, 3, 1),
        "bool": np.array([True, False]),
        "str": np.array(["ekf", "optimal"]),
        "empty": np.zeros((0, 3)),
    },
    "scalars": [np.float64(0.1), np.int64(-3), np.bool_(True), np.float32(0.25)],
    "containers": ({"a": (1, [2, "x"])}, {3: "int key", (1, 2): "tuple key", "__x": None}),
    "seed": np.random.SeedSequence(1).spawn(3)[2],
    "spawned": (lambda s: (s.spawn(2), s)[1])(np.random.SeedSequence(5)),
    "scenario": SCENARIOS["fig2"],
    "dataclass": gaussian.MeanAndCov(np.array([1.0, 2.0]), np.eye(2)),
}


@pytest.mark.parametrize("kind", sorted(VALUES))
def test_a_value_reads_back_bit_for_bit(kind):
    same(VALUES[kind], round_trip(VALUES[kind]))


@pytest.mark.parametrize("kind", ["seed", "spawned"])
def test_a_seed_sequence_reads_back_with_its_streams(kind):
    seed = VALUES[kind]
    back = round_trip(seed)
    assert np.array_equal(seed.generate_state(4), back.generate_state(4))
    assert [s.generate_state(2).tolist() for s in seed.spawn(2)] == [
        s.generate_state(2).tolist() for s in back.spawn(2)
    ]


@pytest.mark.parametrize(
    "value, named",
    [
        (object(), "object"),
        (np.array([object()]), "dtype object"),
        (1 + 2j, "complex"),
        ({1, 2}, "set"),
        (np.random.default_rng(0), "Generator"),
    ],
)
def test_what_cannot_be_recorded_is_refused_by_its_type(value, named):
    with pytest.raises(TypeError, match=named):
        records.encode(value)


def test_only_depthcore_classes_are_rebuilt():
    with pytest.raises(ValueError, match="only depthcore's classes"):
        records.decode({"__dataclass__": "os:PathLike", "fields": {}})


def test_a_study_reads_back_bit_for_bit():
    fig2 = SCENARIOS["fig2"]
    result = monte_carlo.study(fig2.c, fig2.rho, trials=30, seed=2, prior="paper", paired=True)
    same(result, round_trip(result))


# --- recorded, in its three modes -----------------------------------------------------------


@pytest.fixture
def record_dir(tmp_path, monkeypatch):
    monkeypatch.setattr(records, "RECORDS", tmp_path)
    monkeypatch.delenv(records.ENVIRONMENT, raising=False)
    monkeypatch.delenv(records.DIRECTORY, raising=False)
    return tmp_path


def small_study(seed=1):
    return records.recorded(frames.frames_study, [3, 4], 12, seed, ("optimal", "ekf"))


def test_read_computes_a_call_without_a_record_and_writes_nothing(record_dir):
    run = small_study()
    assert not run.read and run.date is None and list(record_dir.iterdir()) == []
    same(run.result, frames.frames_study([3, 4], 12, 1, ("optimal", "ekf")))
    assert "no current record" in str(run)


def test_write_records_a_call_and_read_reads_it_back_bit_for_bit(record_dir, monkeypatch):
    monkeypatch.setenv(records.ENVIRONMENT, "write")
    written = small_study()
    assert not written.read and written.path.is_file() and "recorded in" in str(written)
    monkeypatch.setenv(records.ENVIRONMENT, "read")
    read = small_study()
    assert read.read, "a current record must be read, not computed"
    assert read.seconds == round(written.seconds, 1)
    same(written.result, read.result)
    assert read.date == written.date and "read from its record" in str(read)


def test_another_argument_is_another_record(record_dir, monkeypatch):
    monkeypatch.setenv(records.ENVIRONMENT, "write")
    a, b = small_study(1), small_study(2)
    assert a.path != b.path and len(list(record_dir.iterdir())) == 2
    assert not np.array_equal(a.result["ekf"]["rmse"], b.result["ekf"]["rmse"])


def test_require_refuses_a_call_without_a_current_record(record_dir, monkeypatch):
    monkeypatch.setenv(records.ENVIRONMENT, "require")
    with pytest.raises(ValueError, match=r"no current record .* run `make records`"):
        small_study()
    monkeypatch.setenv(records.ENVIRONMENT, "write")
    path = small_study().path
    monkeypatch.setenv(records.ENVIRONMENT, "require")
    assert small_study().read
    # The call is shown in one short line, whatever its arguments hold.
    with pytest.raises(ValueError) as refused:
        records.recorded(frames.frames_study, np.arange(3, 1003), 12, 1)
    assert str(refused.value).startswith(
        "depthbook.studies.frames:frames_study(array([   3, ..., 1001, 1002]), 12, 1) has no "
        "current record"
    )
    assert len(str(refused.value)) < 240
    record = json.loads(path.read_text())
    key = "code depthcore.problem.model:log_likelihood"
    assert key in record["fingerprint"]
    record["fingerprint"][key] = "0" * 64  # as if the likelihood had changed
    path.write_text(json.dumps(record))
    assert records.stale(record) == [key]
    with pytest.raises(ValueError, match="no current record"):
        small_study()


def test_an_unknown_mode_is_refused_by_the_variables_name(record_dir, monkeypatch):
    monkeypatch.setenv(records.ENVIRONMENT, "always")
    with pytest.raises(ValueError, match="DEPTHCORE_RECORDS must be one of read, write, require"):
        small_study()


def test_only_depthcore_functions_are_recorded():
    with pytest.raises(ValueError, match="function must be one of depthcore's"):
        records.recorded(np.mean, [1.0, 2.0])


def test_the_fingerprint_covers_the_code_the_call_runs_and_the_filters_it_names():
    prints = records.code_fingerprint(
        "depthbook.studies.frames:frames_study", ([3, 4], 12, 1, ("optimal", "ekf"))
    )
    for key in (
        "code depthbook.studies.frames:frames_study",
        "code depthcore.exact.bank:run_bank",
        "code depthcore.kalman.ekf:run",
        "code depthcore.problem.model:log_likelihood",
        "filter ekf",
        "filter optimal",
    ):
        assert key in prints, key
    # The Rao-Blackwellised particle filter is neither named nor among the default filters
    # (NAMES) that the code it reaches names: a change to it leaves this study's record valid.
    assert "filter rbpf" not in prints
    assert not any(k.startswith("code depthcore.particles.rbpf:") for k in prints)
    # the study is the book's, and it reaches no chapter's code
    assert not any(k.startswith(("code depthbook.beyond_", "code depthbook.paper")) for k in prints)
    assert all(len(v) == 64 for v in prints.values())
    with_rbpf = records.code_fingerprint(
        "depthbook.studies.frames:frames_study", ([3, 4], 12, 1, ("optimal", "rbpf"))
    )
    assert "filter rbpf" in with_rbpf and "code depthcore.particles.rbpf:run" in with_rbpf


def test_the_fingerprint_of_a_definition_ignores_its_docstring_and_comments():
    sources = (
        'def f(x):\n    """Old words."""\n    return x + 1  # a comment\n',
        'def f(x):\n    """New words, and more of them."""\n\n    return x + 1\n',
        "def f(x):\n    return x + 2\n",
    )
    old, reworded, changed = (closure._read(ast.parse(s).body[0])[0] for s in sources)
    assert old == reworded != changed


def test_a_record_whose_function_is_gone_is_stale_in_everything():
    record = {
        "function": "depthbook.studies.frames:no_such_study",
        "arguments": records.arguments(),
        "fingerprint": {"code depthbook.studies.frames:no_such_study": "0" * 64},
    }
    assert records.stale(record) == ["code depthbook.studies.frames:no_such_study"]


# --- the committed records ------------------------------------------------------------------


def test_every_function_a_page_records_has_records():
    called = set()
    for page in (ROOT / "book").glob("*.md"):
        called |= set(re.findall(r"records\.recorded\(\s*([\w.]+)", page.read_text()))
    assert len(called) >= 8, called
    recorded = {records.read(p)["function"].rpartition(":")[2] for p in COMMITTED}
    named = {c.rpartition(".")[2] for c in called}
    assert named <= recorded, f"no record of {sorted(named - recorded)}: run `make records`"


@pytest.mark.parametrize("path", COMMITTED, ids=[p.stem for p in COMMITTED])
def test_every_record_is_of_the_current_code_and_its_own_call(path):
    record = records.read(path)
    assert set(records.FIELDS) <= set(record), f"{path.name}: fields missing"
    changed = records.stale(record)
    assert not changed, (
        f"{path.name} is stale: {', '.join(changed)} changed since it was recorded on "
        f"{record['date']}; compute it again with `{records.COMMAND}`"
    )
    args = records.decode(record["arguments"]["args"])
    kwargs = records.decode(record["arguments"]["kwargs"])
    assert records.call_key(record["function"], args, kwargs) == record["key"]
    assert path == records.record_path(record["function"], record["key"])
    assert record["seconds"] >= 0 and record["machine"]["cores"] >= 1
    assert set(record["machine"]) == set(benchmarks.machine())
    records.decode(record["result"])


def test_every_page_that_reads_a_record_is_recomputed_by_make_records():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    listed = set(re.search(r"^RECORD_PAGES := (.*)$", makefile, re.M).group(1).split())
    reading = {
        p.stem
        for p in (ROOT / "book").glob("*.md")
        if any(
            call in p.read_text()
            for call in ("records.recorded(", "records.committed(", "records.read(")
        )
    }
    assert reading == listed


def test_the_books_archive_carries_the_records_and_the_packages_does_not():
    book = (ROOT / "depthbook" / "pyproject.toml").read_text(encoding="utf-8")
    assert '"study_records/*.json"' in book and '"benchmark_records/*.json"' in book
    package = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert "records" not in package.split("[tool.setuptools.package-data]")[1].split("[")[0]


def test_an_argument_that_cannot_be_recorded_is_named(record_dir):
    rng = np.random.default_rng(0)
    with pytest.raises(TypeError, match=r"argument 2: cannot record a numpy\.random.*Generator"):
        records.recorded(frames.frames_study, [3], 5, rng)
    with pytest.raises(TypeError, match=r"argument seed: cannot record a .*Generator"):
        records.recorded(frames.frames_study, [3], 5, seed=rng)
    assert list(record_dir.iterdir()) == []


def test_a_result_that_cannot_be_recorded_is_named_when_writing(record_dir, monkeypatch):
    import matplotlib.pyplot as plt

    from depthbook import style

    monkeypatch.setenv(records.ENVIRONMENT, "write")
    with pytest.raises(TypeError, match=r"the result of depthbook\.style:subplots"):
        records.recorded(style.subplots, 1, 1, figsize=(2.0, 2.0))
    plt.close("all")
    assert list(record_dir.iterdir()) == []


def test_a_data_file_a_constant_names_is_fingerprinted_by_its_bytes(tmp_path):
    walk = closure._Walk()
    walk.file(closure.ROOT / "pyproject.toml")
    walk.file(tmp_path / "outside.json")  # not in the repository: not counted
    walk.file("pyproject.toml")  # a plain string is a name, not a path
    digest = hashlib.sha256((closure.ROOT / "pyproject.toml").read_bytes()).hexdigest()
    assert walk.prints == {"file pyproject.toml": digest}


def test_only_depthcore_functions_are_fingerprinted():
    with pytest.raises(ValueError, match="function must be one of depthcore's functions"):
        closure.fingerprints(np.mean)
    with pytest.raises(ValueError, match="function must be one of depthcore's functions"):
        closure.fingerprints(lambda: None)


def test_a_lambda_bound_to_a_name_is_fingerprinted_by_the_statement_that_binds_it(tmp_path):
    def fingerprint(source: str) -> dict:
        path = tmp_path / f"probe{len(source)}.py"
        path.write_text(source, encoding="utf-8")
        spec = importlib.util.spec_from_file_location("depthcore._closure_probe", path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        try:
            spec.loader.exec_module(module)
            return closure.fingerprints(module.study)
        finally:
            del sys.modules[spec.name]

    study = "\n\ndef study(x):\n    return scale(x)\n"
    before = fingerprint("scale = lambda x: 2 * x" + study)
    after = fingerprint("scale = lambda x: 20 * x" + study)
    assert set(before) == {
        "code depthcore._closure_probe:study",
        "constant depthcore._closure_probe:scale",
    }
    assert closure.changed(before, after) == ["constant depthcore._closure_probe:scale"]
