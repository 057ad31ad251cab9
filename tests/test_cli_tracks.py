"""estimate's tracks: --mu-file (CSV), nan as a missing frame, --per-frame, --gate, --csv."""

import csv
import io
import math
import time

import numpy as np
import pytest

import depthcore
from depthcore.cli import tracks
from depthcore.cli.main import MU_MAX, PIXELS_MAX, STEP_RANGE, main
from depthcore.problem import checks, model
from depthcore.problem.gaussian import paper_prior
from depthcore.registry import track_files, track_runs
from depthcore.registry.filters import FILTERS, PARTICLES
from depthcore.registry.tracking import RHO_RANGE, default_prior
from depthcore.studies.reproduce import PARTICLE_SEED

from helpers import run_cli, strict_json

MU = [-0.3, 0.0, 0.2, 0.33, 0.43]
RHO = 0.005
LIMITS = track_files.Limits(MU_MAX, RHO_RANGE, STEP_RANGE, PIXELS_MAX)


def _file(tmp_path, text, name="track.csv", mode="w"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8", newline="")
    return str(path)


def _csv(columns, rows, end="\n"):
    return end.join([",".join(columns)] + [",".join(str(v) for v in r) for r in rows]) + end


def _refused(argv, capsys, *words):
    status, out, err = run_cli(argv, capsys)
    assert status == 2, (out, err)
    assert out == "" and err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and "Warning" not in err, err
    for w in words:
        assert w in err, err
    return err


def _read(text: bytes, focal=None, cx=None, direction="receding"):
    return track_files.read("t.csv", io.BytesIO(text), LIMITS, focal, cx, tracks.WORDS, direction)


# --- reading a track file -------------------------------------------------------------------


@pytest.mark.parametrize("end", ["\n", "\r\n"], ids=["LF", "CRLF"])
@pytest.mark.parametrize("bom", [b"", b"\xef\xbb\xbf"], ids=["plain", "BOM"])
def test_a_file_of_bearings_gives_what_the_same_bearings_as_arguments_give(
    tmp_path, capsys, end, bom
):
    text = _csv(["mu"], [[m] for m in MU], end).encode()
    path = _file(tmp_path, bom + text)
    assert main(["estimate", "--mu-file", path, "--rho", str(RHO), "--json"]) == 0
    from_file = strict_json(capsys.readouterr().out)
    assert main(["estimate", "--mu", *map(str, MU), "--rho", str(RHO), "--json"]) == 0
    assert from_file == strict_json(capsys.readouterr().out)


def test_standard_input_is_read_for_a_dash(capsys, monkeypatch):
    data = _csv(["frame", "mu"], [[k + 1, m] for k, m in enumerate(MU)]).encode()
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(data)))
    argv = ["estimate", "--mu-file", "-", "--rho", str(RHO), "--per-frame", "--json"]
    assert main(argv) == 0
    rows = strict_json(capsys.readouterr().out)["filters"]["optimal"]
    assert [r["frame"] for r in rows] == [1, 2, 3, 4, 5]
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(b"mu\n0.1\nabc\n")))
    _refused(["estimate", "--mu-file", "-", "--rho", "0.01"], capsys, "<stdin>:3: mu must be")


def test_pixel_columns_are_bearings_by_the_focal_length_and_principal_point(tmp_path):
    focal, cx = 800.0, 320.0
    u = [80.0, 320.0, 480.0, 584.0, 664.0]
    track = _read(_csv(["u"], [[v] for v in u]).encode(), focal, cx)
    np.testing.assert_array_equal(track.mu, model.bearings_from_pixels(u, cx, focal))
    assert track.pixels


@pytest.mark.parametrize(
    "text, expected",
    [
        ("mu\n0.1\n\n", [0.1]),  # a trailing empty line
        ("mu\n0.1\nnan\n0.3\n", [0.1, math.nan, 0.3]),
        ("mu\n0.1\nNaN\n 0.3 \n", [0.1, math.nan, 0.3]),
        ("frame,mu\n1,0.1\n2,\n3,0.3\n", [0.1, math.nan, 0.3]),
        ("frame,mu\n4,0.1\n7,0.4\n8,0.5\n", [0.1, math.nan, math.nan, 0.4, 0.5]),
        ('"mu"\n"0.1"\n', [0.1]),  # quoted fields
    ],
)
def test_an_empty_field_nan_or_a_gap_in_the_frame_numbers_is_a_missing_frame(text, expected):
    track = _read(text.encode())
    np.testing.assert_array_equal(track.mu, expected)


def test_frame_numbers_are_kept_and_gaps_filled_only_without_a_step_column():
    gaps = _read(b"frame,mu\n4,0.1\n7,0.4\n8,0.5\n")
    assert gaps.frames.tolist() == [4, 5, 6, 7, 8] and gaps.steps is None
    stepped = _read(b"frame,mu,step\n4,0.1,\n7,0.4,3\n8,0.5,1\n")
    assert stepped.frames.tolist() == [4, 7, 8]
    np.testing.assert_array_equal(stepped.mu, [0.1, 0.4, 0.5])
    np.testing.assert_array_equal(stepped.steps, [3.0, 1.0])


def test_a_rho_column_gives_the_noise_of_each_frame_and_may_be_empty_at_a_missing_one():
    track = _read(b"mu,rho\n0.1,0.01\n,\n0.3,0.02\n")
    np.testing.assert_array_equal(track.rho, [0.01, math.nan, 0.02])


def test_a_constant_rho_column_equals_rho_given_once(tmp_path, capsys):
    path = _file(tmp_path, _csv(["mu", "rho"], [[m, RHO] for m in MU]))
    assert main(["estimate", "--mu-file", path, "--per-frame", "--json"]) == 0
    from_file = strict_json(capsys.readouterr().out)
    assert (
        main(["estimate", "--mu", *map(str, MU), "--rho", str(RHO), "--per-frame", "--json"]) == 0
    )
    assert from_file == strict_json(capsys.readouterr().out)


# --- malformed files: one line naming the file and the line ---------------------------------


@pytest.mark.parametrize(
    "data, words",
    [
        (b"", "t.csv:1: an empty file"),
        (b"\n0.1\n", "t.csv:1: an empty first line"),
        (b"mu\n", "t.csv:2: no frames after the header"),
        (b"0.1\n0.2\n0.3\n", "t.csv:1: no header or an unknown column '0.1'"),
        (b"mu,depth\n0.1,3\n", "t.csv:1: no header or an unknown column 'depth'"),
        (b"mu,mu\n0.1,0.1\n", "t.csv:1: the header names 'mu' more than once"),
        (b"rho\n0.1\n", "t.csv:1: the header must name either a mu column or a u column"),
        (b"mu,u\n0.1,3\n", "t.csv:1: the header must name either"),
        (b"u\n300\n", "t.csv:1: a u column (pixels) needs --focal and --cx"),
        (b"mu,rho\n0.1,0.01\n0.2\n", "t.csv:3: 1 fields, but the header names 2 columns"),
        (b"mu\n0.1\n0.2,0.3\n", "t.csv:3: 2 fields, but the header names 1 columns"),
        (b"mu\n0.1\nabc\n", "t.csv:3: mu must be a number, got 'abc'"),
        (b"mu\n0.1\n1_0\n", "t.csv:3: mu must be a number, got '1_0'"),
        (b"mu\n0.1\ninf\n", "t.csv:3: mu must be a number, got 'inf'"),
        (b"mu\n0.1\n1e7\n", "t.csv:3: mu must be at most 1e+06 in magnitude, got 1e7"),
        (b"mu\n0.1\n\n0.2\n", "t.csv:3: an empty line"),
        (b"mu,rho\n0.1,0\n", "t.csv:2: rho must be from 1e-12 to 1000, got 0"),
        (b"mu,rho\n0.1,x\n", "t.csv:2: rho must be a number, got 'x'"),
        (b"mu,rho\n0.1,0.1\n0.2,\n", "t.csv:3: rho is empty at a frame with a bearing"),
        (b"mu,step\n0.1,1\n", "t.csv:2: the first row's step must be empty"),
        (b"mu,step\n0.1,\n0.2,0\n", "t.csv:3: step must be from 1e-06 to 1000"),
        (b"mu,step\n0.1,\n0.2,\n", "t.csv:3: step must be from 1e-06 to 1000"),
        (b"mu,step\n0.1,\n0.2,-1\n", "t.csv:3: step must be from"),
        (b"frame,mu\n1,0.1\n1,0.2\n", "t.csv:3: frame must increase strictly, got 1 after 1"),
        (b"frame,mu\n2,0.1\n1,0.2\n", "t.csv:3: frame must increase strictly"),
        (b"frame,mu\n1.5,0.1\n", "t.csv:2: frame must be an integer, got '1.5'"),
        (b"frame,mu\n,0.1\n", "t.csv:2: frame must be an integer, got ''"),
        (b"frame,mu\n1,0.1\n5000,0.2\n", "t.csv:3: frame jumps from 1 to 5000, more than 1000"),
        (b"mu\n0.1\n0.\x002\n", "t.csv:3: mu must be a number, got '0.\\x002'"),
        (b"mu\n0.1\n\xff\xfe\x00\x01\n", "t.csv:3: not UTF-8 text"),
        ("mu\n0.1\n".encode("utf-16"), "t.csv:1: not UTF-8 text"),
        (b"mu\n" + b"1" * 5000 + b"\n", "t.csv:2: a line longer than 4096 characters"),
        (b"mu\n" + b"1" * 100_000, "t.csv:2: a line longer than 4096 characters"),
        (b'mu\n"0.1\n0.2\n', "t.csv:3: not CSV"),
        (b"mu\n0.1\n" + b"\n" * 200 + b"0.2\n", "t.csv:"),
    ],
)
def test_a_malformed_file_is_refused_naming_its_line(data, words):
    with pytest.raises(track_files.FileRefusal) as info:
        _read(data)
    message = str(info.value)
    assert "\n" not in message and words in message, message


def test_binary_junk_is_refused_in_one_line(tmp_path, capsys):
    rng = np.random.default_rng(1)
    for k in range(20):
        junk = rng.integers(0, 256, size=int(rng.integers(1, 3000)), dtype=np.uint8).tobytes()
        path = _file(tmp_path, junk, name=f"junk{k}.bin")
        _refused(["estimate", "--mu-file", path, "--rho", "0.01"], capsys, f"junk{k}.bin:")


class _Endless(io.RawIOBase):
    """A stream of ``mu`` then endless rows of bearings; counts the lines read."""

    def __init__(self):
        self.read_lines = 0

    def readline(self, size=-1):
        self.read_lines += 1
        return b"mu\n" if self.read_lines == 1 else b"0.1\n"


def test_a_file_past_the_limit_of_frames_is_refused_without_reading_the_rest():
    stream = _Endless()
    with pytest.raises(track_files.FileRefusal, match=rf"t.csv:{checks.MAX_FRAMES + 2}: more than"):
        track_files.read("t.csv", stream, LIMITS)
    assert stream.read_lines == checks.MAX_FRAMES + 2


def test_a_million_rows_are_refused_at_once(tmp_path, capsys):
    path = _file(tmp_path, "mu\n" + "0.1\n" * 1_000_000)
    start = time.perf_counter()
    _refused(
        ["estimate", "--mu-file", path, "--rho", "0.01"],
        capsys,
        f"{path}:{checks.MAX_FRAMES + 2}: more than {checks.MAX_FRAMES} frames",
    )
    assert time.perf_counter() - start < 2.0


def test_the_largest_track_is_read(tmp_path):
    n = checks.MAX_FRAMES
    text = "mu\n" + "".join(f"{1e-4 * k * k}\n" for k in range(n)) + "\n\n"
    track = _read(text.encode())
    assert track.mu.shape == (n,)


@pytest.mark.parametrize(
    "kind, words",
    [("missing", "No such file or directory"), ("folder", "Is a directory")],
)
def test_a_file_that_is_missing_or_a_folder_is_refused_naming_the_option(
    tmp_path, capsys, kind, words
):
    path = str(tmp_path / "none.csv") if kind == "missing" else str(tmp_path)
    _refused(
        ["estimate", "--mu-file", path, "--rho", "0.01"], capsys, "--mu-file: cannot read", words
    )


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--mu", "0.1", "0.2", "0.35"], ("not allowed with argument",)),
        (["--focal", "800"], ("--cx is needed with the other",)),
        (["--focal", "800", "--cx", "320"], ("--focal and --cx are for a u column",)),
        (["--focal", "0", "--cx", "320"], ("--focal must be positive",)),
        (["--focal", "inf", "--cx", "320"], ("--focal must be finite",)),
        (["--focal", "1", "--cx", "1e10"], ("--cx must be finite and at most 1e+09",)),
    ],
)
def test_the_file_options_are_refused_in_one_line(tmp_path, capsys, argv, words):
    path = _file(tmp_path, _csv(["mu"], [[m] for m in MU]))
    args = ["estimate", "--mu-file", path, *argv]
    if "--rho" not in argv:
        args += ["--rho", "0.01"]
    _refused(args, capsys, *words)


def test_rho_is_needed_once_from_the_file_or_the_option(tmp_path, capsys):
    _refused(["estimate", "--rho", "0.01"], capsys, "one of the arguments --mu --mu-file is")
    plain = _file(tmp_path, _csv(["mu"], [[m] for m in MU]), "plain.csv")
    _refused(["estimate", "--mu-file", plain], capsys, "--rho is needed: no rho column")
    noisy = _file(tmp_path, _csv(["mu", "rho"], [[m, 0.01] for m in MU]), "noisy.csv")
    _refused(["estimate", "--mu-file", noisy, "--rho", "0.01"], capsys, "--rho: not used")
    _refused(["estimate", "--mu", "0.1", "0.2", "0.35"], capsys, "--rho is needed")
    _refused(
        ["estimate", "--mu", "0.1", "0.2", "0.35", "--rho", "1", "--focal", "800"],
        capsys,
        "--focal: not used by --mu",
    )


def test_a_file_without_a_solution_is_refused_naming_the_file(tmp_path, capsys):
    path = _file(tmp_path, _csv(["mu"], [[0.1], [0.2], [0.3], [0.4]]), "line.csv")
    _refused(["estimate", "--mu-file", path, "--rho", "0.01"], capsys, "line.csv: mu is degenerate")


# --- the summary takes tracks as they come ---------------------------------------------


def _seeded(name: str) -> dict:
    """The options the summary gives a random filter: its particles and seed."""
    if not FILTERS[name].random:
        return {}
    return {"rng": np.random.default_rng(PARTICLE_SEED), "n_particles": PARTICLES}


@pytest.mark.parametrize(
    "header, rows",
    [
        (["mu"], [[-0.3], [0.0], ["nan"], [0.2], [0.33]]),
        (["mu", "rho"], [[m, 0.01 * (k + 1)] for k, m in enumerate(MU)]),
        (["mu", "step"], [[-0.3, ""], [0, 1], [0.2, 2], [0.3, 0.5]]),
    ],
)
def test_without_per_frame_a_track_as_it_comes_is_each_filters_last_frame(
    tmp_path, capsys, header, rows
):
    path = _file(tmp_path, _csv(header, rows))
    track = _read(_csv(header, rows).encode())
    rho = track.rho if "rho" in header else 0.01
    argv = ["estimate", "--mu-file", path, "--json", "--direction", "receding"] + (
        [] if "rho" in header else ["--rho", "0.01"]
    )
    assert main(argv) == 0
    out = strict_json(capsys.readouterr().out)
    steps = None if track.steps is None else track.steps
    prior = default_prior(track.mu, steps)
    assert out["prior_mean"] == prior.mean.tolist()
    more = {} if steps is None else {"steps": steps}
    for name, got in out["filters"].items():
        expected = FILTERS[name](track.mu, rho, prior.mean, prior.cov, **more, **_seeded(name))
        assert got["depth"]["mean"] == float(expected.depth_mean)
    for name, reason in out.get("not_run", {}).items():
        assert reason.splitlines() == [reason] and name in FILTERS


def test_unit_steps_in_a_file_are_the_papers_frames(tmp_path, capsys):
    path = _file(tmp_path, _csv(["mu", "step"], [[MU[0], ""]] + [[m, 1] for m in MU[1:]]))
    argv = ["estimate", "--mu-file", path, "--rho", str(RHO), "--json", "--direction", "receding"]
    assert main(argv) == 0
    from_file = strict_json(capsys.readouterr().out)
    assert main(["estimate", "--mu", *map(str, MU), "--rho", str(RHO), "--json"]) == 0
    from_values = strict_json(capsys.readouterr().out)
    assert from_file.pop("direction_given") and not from_values.pop("direction_given")
    assert from_file == from_values


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--csv"], "--csv: not used by estimate without --per-frame"),
        (["--per-frame", "--csv", "--json"], "--csv: print JSON (--json) or CSV (--csv)"),
        (["--per-frame", "--smooth"], "--smooth: not used by --per-frame"),
        (["--per-frame", "--filters", "particle"], "--filters: particle has no smoother"),
        (["--per-frame", "--filters", "ekf", "ekf"], "--filters names ekf more than once"),
        (["--per-frame", "--gate", "0"], "--gate must be a probability"),
        (["--per-frame", "--gate", "1"], "--gate must be a probability"),
        (["--per-frame", "--gate", "nan"], "--gate must be a probability"),
    ],
)
def test_the_per_frame_options_are_refused_in_one_line(capsys, extra, words):
    _refused(["estimate", "--mu", *map(str, MU), "--rho", str(RHO), *extra], capsys, words)


def test_the_papers_prior_takes_the_first_three_bearings_present(capsys):
    mu = [-0.3, float("nan"), 0.0, 0.1, 0.16]
    argv = ["estimate", "--mu", *map(str, mu), "--rho", "0.01", "--per-frame", "--json"]
    assert main(argv) == 0
    out = strict_json(capsys.readouterr().out)
    assert out["prior_mean"] == default_prior(np.array(mu)).mean.tolist()


# --- every frame's state ------------------------------------------------------------------


@pytest.mark.parametrize("name", ["optimal", "ekf", "ukf"])
def test_per_frame_json_is_the_librarys_track(capsys, name):
    argv = ["estimate", "--mu", *map(str, MU), "--rho", str(RHO), "--per-frame", "--json"]
    assert main([*argv, "--filters", name]) == 0
    data = strict_json(capsys.readouterr().out)
    t = depthcore.track(MU, RHO, filter=name)
    assert data["prior_mean"] == t.prior.mean.tolist()
    rows = data["filters"][name]
    assert [r["frame"] for r in rows] == [1, 2, 3, 4, 5]
    assert all(r["bearing"] for r in rows) and rows[0]["step"] is None
    for series, states in (("filtered", t.filtered), ("smoothed", t.smoothed)):
        for key, attribute in track_runs.QUANTITIES:
            for suffix in ("mean", "sd"):
                got = [r[f"{series}_{key}_{suffix}"] for r in rows]
                assert got == getattr(states, f"{attribute}_{suffix}").tolist()


def test_per_frame_csv_holds_the_json_numbers_in_full(capsys):
    argv = ["estimate", "--mu", *map(str, MU), "--rho", str(RHO), "--per-frame"]
    assert main([*argv, "--filters", "optimal", "ekf", "--json"]) == 0
    data = strict_json(capsys.readouterr().out)
    assert main([*argv, "--filters", "optimal", "ekf", "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == 2 * len(MU)
    flat = [dict(filter=n, **r) for n, rs in data["filters"].items() for r in rs]
    for text, row in zip(rows, flat, strict=True):
        assert list(text) == list(row)
        assert text["filter"] == row["filter"] and int(text["frame"]) == row["frame"]
        assert text["bearing"] == "true"
        assert text["step"] == ("" if row["step"] is None else repr(row["step"]))
        assert float(text["smoothed_depth_sd"]) == row["smoothed_depth_sd"]


def test_the_per_frame_table_shows_every_frame_and_its_legend(capsys):
    argv = ["estimate", "--mu", *map(str, MU), "--rho", str(RHO), "--per-frame"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "optimal:" in out and "depth filtered" in out and "velocity smoothed" in out
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if "depth filtered" in line)
    assert [line.split()[0] for line in lines[head + 1 : head + 6]] == ["1", "2", "3", "4", "5"]
    assert "legend:" in out and "tail" in out
    t = depthcore.track(MU, RHO)
    assert f"{t.smoothed.depth_mean[0]:#.4g}" in lines[head + 1]


def test_the_help_describes_the_file_format(capsys):
    with pytest.raises(SystemExit):
        main(["estimate", "--help"])
    out = capsys.readouterr().out
    for word in ("--mu-file", "--per-frame", "--gate", "--csv", "--focal", "--cx", "step"):
        assert word in out
    assert tracks.FORMAT.splitlines()[0] in out


def test_the_prior_of_a_file_is_the_papers_rule_on_its_first_three_bearings(tmp_path, capsys):
    path = _file(tmp_path, _csv(["mu"], [[m] for m in MU]))
    assert main(["estimate", "--mu-file", path, "--rho", str(RHO), "--per-frame", "--json"]) == 0
    data = strict_json(capsys.readouterr().out)
    assert data["prior_mean"] == paper_prior(model.noise_free_state(MU[:3])).mean.tolist()


# --- gaps, noise per frame, steps and a gate reach depthcore.track ------------------------

PRIOR_MEAN = [-1.0, 4.0, 0.0]


def _library(mu, rho, **options):
    """``depthcore.track``'s answer, or None where it refuses the inputs."""
    prior = depthcore.Gaussian.prior(PRIOR_MEAN, 1000.0 * np.eye(3))
    try:
        return depthcore.track(mu, rho, prior, **options)
    except (TypeError, ValueError):  # TypeError: a keyword this version does not take
        return None


TRACK_CASES = {
    "gap as nan": ("mu\n-0.3\n0\n0.2\nnan\n0.43\n", {}, 0.005),
    "gap in the frame numbers": ("frame,mu\n1,-0.3\n2,0\n3,0.2\n5,0.43\n", {}, 0.005),
    "noise per frame": (
        "mu,rho\n-0.3,0.005\n0,0.01\n0.2,0.005\n0.33,0.02\n0.43,0.005\n",
        {},
        None,
    ),
    "steps": (
        "mu,step\n-0.3,\n0,1\n0.2,1\n0.3,0.5\n0.43,2\n",
        {"steps": [1, 1, 0.5, 2]},
        0.005,
    ),
    "gate": ("mu\n-0.3\n0\n0.2\n0.9\n0.43\n", {"gate": 0.01}, 0.005),
}


@pytest.mark.parametrize(
    "case, name",
    [(c, n) for c in TRACK_CASES for n in ("optimal", "ekf")],
)
def test_a_track_with_gaps_noise_or_steps_is_depthcore_track_or_its_refusal(
    tmp_path, capsys, case, name
):
    text, options, rho = TRACK_CASES[case]
    path = _file(tmp_path, text)
    track = _read(text.encode())
    argv = ["estimate", "--mu-file", path, "--per-frame", "--json", "--filters", name]
    argv += ["--prior-mean", *map(str, PRIOR_MEAN)] + ([] if rho is None else ["--rho", str(rho)])
    argv += ["--gate", str(options["gate"])] if "gate" in options else []
    argv += ["--direction", "receding"] if "step" in text else []
    expected = _library(track.mu, track.rho if rho is None else rho, filter=name, **options)
    status, out, err = run_cli(argv, capsys)
    if expected is None:
        assert status == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        return
    assert status == 0, err
    rows = strict_json(out)["filters"][name]
    assert [r["bearing"] for r in rows] == np.isfinite(track.mu).tolist()
    assert [r["mu"] for r in rows] == [None if np.isnan(m) else m for m in track.mu]
    for key, attribute in track_runs.QUANTITIES:
        got = [r[f"smoothed_{key}_mean"] for r in rows]
        assert got == getattr(expected.smoothed, f"{attribute}_mean").tolist()
    updates = getattr(expected, "updates", None)
    if updates is not None:
        assert [r["gated"] for r in rows] == np.asarray(updates.gated).tolist()


# --- learning the noise --------------------------------------------------------------------


def _learn_track():
    sim = model.simulate([1.0, 5.0, 0.3], 30, 0.005, 0.02, np.random.default_rng(3), frame=1)
    return sim.mu


def test_learn_noise_is_the_maximum_likelihood_fit_and_runs_the_filters_with_it(capsys):
    from depthcore.exact import learning

    mu = _learn_track()
    argv = ["estimate", "--mu", *map(repr, mu.tolist()), "--learn-noise", "--json"]
    argv += [
        "--prior-mean",
        "1",
        "5",
        "0",
        "--prior-cov",
        "1",
        "0",
        "0",
        "0",
        "4",
        "0",
        "0",
        "0",
        "1",
    ]
    assert main(argv) == 0
    out = strict_json(capsys.readouterr().out)
    prior_cov = np.diag([1.0, 4.0, 1.0])
    fit = learning.fit(mu, [1.0, 5.0, 0.0], prior_cov)
    assert out["learned"]["rho"] == fit.rho and out["learned"]["rho_se"] == fit.rho_se
    assert out["learned"]["process_noise"] == fit.process_noise
    assert out["rho"] == fit.rho and out["process_noise"] == fit.process_noise
    ekf = FILTERS["ekf"](mu, fit.rho, [1.0, 5.0, 0.0], prior_cov, fit.process_noise)
    assert out["filters"]["ekf"]["depth"]["mean"] == float(ekf.depth_mean)


def test_learn_noise_with_a_given_process_noise_learns_rho_only(capsys):
    mu = _learn_track()
    argv = ["estimate", "--mu", *map(repr, mu.tolist()), "--learn-noise", "--per-frame"]
    argv += ["--prior-mean", "1", "5", "0", "--process-noise", "0", "--json"]
    assert main(argv) == 0
    learned = strict_json(capsys.readouterr().out)["learned"]
    assert learned["estimated"] == ["rho"] and learned["process_noise"] == 0.0
    assert learned["process_noise_se"] is None and learned["rho_se"] > 0


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--rho", "0.01"], "--rho: not used with --learn-noise"),
        (["--per-frame", "--csv"], "--csv: the learned noise levels have no CSV"),
    ],
)
def test_learn_noise_refusals(capsys, extra, words):
    argv = ["estimate", "--mu", *map(repr, _learn_track().tolist()), "--learn-noise"]
    _refused(argv + ["--prior-mean", "1", "5", "0", *extra], capsys, words)


def test_learn_noise_needs_four_bearings(capsys):
    _refused(["estimate", "--mu", "0.1", "0.2", "0.28", "--learn-noise"], capsys, "at least 4")
