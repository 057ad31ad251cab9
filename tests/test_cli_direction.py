"""estimate's distances: the direction made explicit, time and travel, the file's frame names,
and tracks past the limit of frames streamed through the online filters."""

import contextlib
import io
import json
import os
import tempfile
import tracemalloc
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import depthcore
from depthcore.cli import tracks
from depthcore.cli.main import main
from depthcore.problem import checks, model
from depthcore.registry import online

from helpers import cli_refused, exit_status, run_cli

RHO = 0.002
PRIOR = ["--prior-mean", "2", "15", "0", "--prior-cov", "100"]
#: A point approached by the camera: depth 20 at the first frame, uneven steps towards it.
STEPS = np.array([0.76, 0.8, 1.31, 0.59, 1.1, 1.23, 0.69, 0.56, 0.77, 1.16, 1.06])
FRAMES = np.arange(100, 112)


def _approaching(outlier=None):
    e = -np.concatenate([[0.0], np.cumsum(STEPS)])
    mu = (3.0 + 0.2 * e) / (20.0 + e) + RHO * np.random.default_rng(2).standard_normal(len(e))
    if outlier is not None:
        mu[outlier] += 0.1
    return mu


def _file(tmp_path, header, columns, name="t.csv"):
    rows = zip(*columns, strict=True)
    text = header + "\n" + "".join(",".join(map(_field, r)) + "\n" for r in rows)
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def _field(v) -> str:
    return "" if v is None else repr(float(v)) if isinstance(v, float | np.floating) else str(v)


def _steps_column():
    return [None, *STEPS.tolist()]


def _json(argv, capsys):
    status, out, err = run_cli([*argv, "--json"], capsys)
    assert status == 0, err
    return json.loads(out, parse_constant=lambda c: pytest.fail(f"not strict JSON: {c}"))


# --- the direction is explicit --------------------------------------------------------------


@pytest.mark.parametrize(
    "header, column, extra",
    [
        ("mu,step", _steps_column(), []),
        ("mu,travel", np.concatenate([[0.0], np.cumsum(STEPS)]).tolist(), []),
        ("mu,time", np.concatenate([[0.0], np.cumsum(STEPS)]).tolist(), ["--speed", "1"]),
    ],
)
def test_distances_in_a_file_are_refused_without_a_direction(
    tmp_path, capsys, header, column, extra
):
    path = _file(tmp_path, header, [_approaching().tolist(), column])
    kind = header.split(",")[1]
    cli_refused(
        ["estimate", "--mu-file", path, "--rho", str(RHO), *extra],
        capsys,
        "--direction is needed",
        f"has a {kind} column",
        "receding",
        "approaching",
    )


def test_steps_as_arguments_are_refused_without_a_direction(capsys):
    mu = _approaching()[:5].tolist()
    argv = ["estimate", "--mu", *map(repr, mu), "--rho", str(RHO), "--steps", "1", "1", "1", "1"]
    cli_refused(argv, capsys, "--direction is needed with --steps")


def test_without_distances_the_output_names_the_receding_default(capsys):
    argv = ["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005"]
    out = _json(argv, capsys)
    assert out["direction"] == "receding" and out["direction_given"] is False
    assert "steps" not in out
    assert exit_status(argv) == 0
    assert "direction: receding" in capsys.readouterr().out
    given = _json([*argv, "--direction", "receding"], capsys)
    assert given["direction_given"] is True and given["filters"] == out["filters"]


def test_the_help_states_the_convention(capsys):
    with pytest.raises(SystemExit):
        main(["estimate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--direction {receding,approaching,signed}" in out
    assert "+ while the point recedes" in out and "- while it approaches" in out
    assert " ".join(tracks.FORMAT.split()) in out


def test_an_approaching_track_reaches_the_library_with_negative_steps(tmp_path, capsys):
    mu = _approaching()
    path = _file(tmp_path, "mu,step", [mu.tolist(), _steps_column()])
    argv = ["estimate", "--mu-file", path, "--rho", str(RHO), *PRIOR, "--filters", "ekf"]
    out = _json([*argv, "--direction", "approaching"], capsys)
    assert out["steps"] == (-STEPS).tolist() and out["direction"] == "approaching"
    prior = depthcore.Gaussian([2.0, 15.0, 0.0], 100.0 * np.eye(3))
    expected = depthcore.FILTERS["ekf"](mu, RHO, prior.mean, prior.cov, steps=-STEPS)
    assert out["filters"]["ekf"]["depth"]["mean"] == float(expected.depth_mean)
    # read the wrong way, the same file is a receding point: another answer
    wrong = _json([*argv, "--direction", "receding"], capsys)
    assert wrong["steps"] == STEPS.tolist()
    assert wrong["filters"]["ekf"]["depth"]["mean"] != out["filters"]["ekf"]["depth"]["mean"]


@pytest.mark.parametrize("name", ["optimal", "ekf", "ukf"])
def test_an_approaching_track_per_frame_is_depthcore_track_with_negative_steps(
    tmp_path, capsys, name
):
    mu = _approaching()
    path = _file(tmp_path, "mu,step", [mu.tolist(), _steps_column()])
    argv = ["estimate", "--mu-file", path, "--rho", str(RHO), *PRIOR, "--per-frame"]
    out = _json([*argv, "--direction", "approaching", "--filters", name], capsys)
    rows = out["filters"][name]
    assert [r["step"] for r in rows] == [None, *(-STEPS).tolist()]
    prior = depthcore.Gaussian([2.0, 15.0, 0.0], 100.0 * np.eye(3))
    t = depthcore.track(mu, RHO, prior, steps=-STEPS, filter=name)
    assert [r["smoothed_depth_mean"] for r in rows] == t.smoothed.depth_mean.tolist()


def test_signed_steps_are_the_columns_own(tmp_path, capsys):
    mu = _approaching()
    signed = _file(tmp_path, "mu,step", [mu.tolist(), [None, *(-STEPS).tolist()]], "signed.csv")
    plain = _file(tmp_path, "mu,step", [mu.tolist(), _steps_column()], "plain.csv")
    common = ["--rho", str(RHO), *PRIOR, "--filters", "ekf"]
    a = _json(["estimate", "--mu-file", signed, "--direction", "signed", *common], capsys)
    b = _json(["estimate", "--mu-file", plain, "--direction", "approaching", *common], capsys)
    assert a["steps"] == b["steps"] and a["filters"] == b["filters"]
    steps = ["--steps", *map(repr, (-STEPS).tolist())]
    c = _json(
        ["estimate", "--mu", *map(repr, mu.tolist()), "--direction", "signed", *steps, *common],
        capsys,
    )
    assert c["filters"] == b["filters"]


@pytest.mark.parametrize(
    "header, column, extra, words",
    [
        ("mu,step", [None, 1.0, -1.0], ["--direction", "receding"], "t.csv:4: step must be from"),
        ("mu,step", [None, 1.0, -1.0], ["--direction", "approaching"], "(a magnitude: the"),
        ("mu,step", [None, 1.0, 0.0], ["--direction", "signed"], "t.csv:4: step must be"),
        ("mu,travel", [0.0, 1.0, 0.5], ["--direction", "approaching"], "t.csv:4: travel must"),
        ("mu,travel", [0.0, 1.0, 1.0], ["--direction", "signed"], "got 1 after 1"),
        ("mu,travel", [2.0, 3.0, 4.0], ["--direction", "receding"], "first row's travel must be 0"),
        ("mu,time", [0.0, 1.0, 1.0], ["--direction", "receding", "--speed", "1"], "increase"),
        ("mu,time", [0.0, 2.0, 1.0], ["--direction", "receding", "--speed", "1"], "got 1 after 2"),
        ("mu,time", [0.0, 1.0, 2.0], ["--direction", "receding", "--speed", "0"], "--speed must"),
        ("mu,time", [0.0, 1.0, 2.0], ["--direction", "receding", "--speed", "-1"], "positive"),
        ("mu,time", [0.0, 1.0, 2.0], ["--direction", "receding", "--speed", "nan"], "--speed"),
        ("mu,time", [0.0, 1.0, 2.0], ["--direction", "receding", "--speed", "1e9"], "a step"),
        ("mu,time", [0.0, 1.0, 2.0], ["--direction", "receding"], "--speed is needed"),
        ("mu,time", [0.0, 1.0, 2.0], ["--direction", "signed", "--speed", "1"], "signed takes"),
        (
            "mu,time",
            [0.0, "x", 2.0],
            ["--direction", "receding", "--speed", "1"],
            "must be a number",
        ),
        ("mu,time", [0.0, "", 2.0], ["--direction", "receding", "--speed", "1"], "at every row"),
        ("mu", [], ["--speed", "1"], "--speed: not used"),
        ("mu", [], ["--direction", "signed"], "--direction signed takes the signs"),
        ("mu,step,time", [None, 1.0, 1.0], ["--direction", "receding"], "give one of"),
    ],
)
def test_distances_against_their_direction_are_refused_in_one_line(
    tmp_path, capsys, header, column, extra, words
):
    mu = [0.1, 0.2, 0.28]
    columns = [mu] + [column] * (header.count(",")) if column else [mu]
    path = _file(tmp_path, header, columns)
    cli_refused(["estimate", "--mu-file", path, "--rho", "0.01", *extra], capsys, words)


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--steps", "1", "1"], "--steps takes one step per pair"),
        (["--steps", "1", "-1", "1", "1", "--direction", "receding"], "--steps must be from"),
        (["--steps", "1", "0", "1", "1", "--direction", "signed"], "in magnitude, nonzero"),
        (["--steps", "1", "nan", "1", "1", "--direction", "receding"], "--steps must be"),
        (["--steps", "1", "1e9", "1", "1", "--direction", "receding"], "--steps must be"),
        (["--direction", "signed"], "--direction signed takes the signs of --steps"),
        (["--speed", "2"], "--speed: not used by --mu"),
    ],
)
def test_steps_as_arguments_are_refused_in_one_line(capsys, extra, words):
    argv = ["estimate", "--mu", "-0.3", "0", "0.2", "0.33", "0.43", "--rho", "0.005", *extra]
    if "--direction" not in extra and "--steps" in extra:
        argv += ["--direction", "receding"]
    cli_refused(argv, capsys, words)


def test_steps_from_a_file_are_refused_with_steps_as_arguments(tmp_path, capsys):
    path = _file(tmp_path, "mu", [[0.1, 0.2, 0.28]])
    argv = ["estimate", "--mu-file", path, "--rho", "0.01", "--steps", "1", "1"]
    cli_refused(argv, capsys, "--steps: not used by --mu-file")


def test_approaching_without_distances_is_unit_steps_towards_the_point(capsys):
    e = -np.arange(5.0)
    mu = [repr(float(m)) for m in (3.0 + 0.2 * e) / (20.0 + e)]
    argv = ["estimate", "--mu", *mu, "--rho", "0.005", *PRIOR, "--filters", "ekf"]
    out = _json([*argv, "--direction", "approaching"], capsys)
    assert out["steps"] == [-1.0] * 4 and out["direction"] == "approaching"
    receding = _json(argv, capsys)
    assert "steps" not in receding and receding["filters"] != out["filters"]


# --- time and travel give the steps ------------------------------------------------------


def test_time_and_speed_and_travel_give_the_steps_a_step_column_gives(tmp_path, capsys):
    mu = _approaching().tolist()
    travel = np.concatenate([[0.0], np.cumsum(STEPS)])
    speed = 2.5
    files = {
        "step": (_file(tmp_path, "mu,step", [mu, _steps_column()], "s.csv"), []),
        "travel": (_file(tmp_path, "mu,travel", [mu, travel.tolist()], "d.csv"), []),
        "time": (
            _file(tmp_path, "mu,time", [mu, (travel / speed).tolist()], "t.csv"),
            ["--speed", str(speed)],
        ),
    }
    common = ["--rho", str(RHO), *PRIOR, "--filters", "ekf", "--direction", "approaching"]
    outs = {
        k: _json(["estimate", "--mu-file", p, *common, *e], capsys) for k, (p, e) in files.items()
    }
    for kind in ("travel", "time"):
        np.testing.assert_allclose(outs[kind]["steps"], -STEPS, rtol=1e-12)
        np.testing.assert_allclose(
            outs[kind]["filters"]["ekf"]["depth"]["mean"],
            outs["step"]["filters"]["ekf"]["depth"]["mean"],
            rtol=1e-9,
        )
    assert outs["time"]["times"] == (travel / speed).tolist()


# --- the file's frame numbers and times name the frames ----------------------------------


def test_every_output_names_frames_by_the_files_numbers_and_times(tmp_path, capsys):
    mu = _approaching(outlier=6)
    times = np.concatenate([[0.0], np.cumsum(STEPS)]) / 2.0
    path = _file(tmp_path, "frame,time,mu", [FRAMES.tolist(), times.tolist(), mu.tolist()])
    argv = ["estimate", "--mu-file", path, "--rho", str(RHO), *PRIOR, "--gate", "1e-3"]
    argv += ["--direction", "approaching", "--speed", "2", "--filters", "optimal", "ekf"]
    out = _json(argv, capsys)
    assert out["frame_numbers"] == FRAMES.tolist() and out["times"] == times.tolist()
    for name in ("optimal", "ekf"):
        assert out["filters"][name]["gated"] == [106]
        assert out["filters"][name]["gated_times"] == [times[6]]
    assert exit_status(argv) == 0
    table = capsys.readouterr().out
    assert f"gate skipped frames: 106 (t = {times[6]:.6g} s)" in table
    assert "every filter at frame 111" in table and "prior at frame 100" in table
    smooth = _json([*argv[:-3], "--smooth"], capsys)["smoothed"]
    assert smooth["frame"] == FRAMES.tolist() and smooth["times"] == times.tolist()
    rows = _json([*argv[:-3], "--per-frame"], capsys)["filters"]["optimal"]
    assert [r["frame"] for r in rows] == FRAMES.tolist()
    assert [r["time"] for r in rows] == times.tolist()
    assert [r["gated"] for r in rows] == [k == 6 for k in range(len(mu))]


def test_a_refusal_names_frames_by_the_files_numbers(tmp_path, capsys):
    # the first three present bearings put the point behind the camera: the paper's rule
    # refuses, naming them as the file numbers them
    mu = [0.1, None, 0.3, 0.2, 0.25]
    path = _file(tmp_path, "frame,mu", [[7, 8, 9, 10, 11], mu])
    err = cli_refused(["estimate", "--mu-file", path, "--rho", "0.01"], capsys, "frames 7, 9, 10")
    assert "frames 1," not in err


# --- tracks past the limit: streamed through the online filters --------------------------


def _long(tmp_path, n, name="long.csv", bad_line=None, every=1):
    """A file of ``n`` frames of a receding point, a bearing at every ``every``-th."""
    sim = model.simulate([1.0, 5.0, 0.3], n, 0.01, 1e-3, np.random.default_rng(1), frame=1)
    mu = np.where(np.arange(n) % every == 0, sim.mu, np.nan)
    mu[:3] = sim.mu[:3]
    rows = [f"{k + 1},{'' if np.isnan(m) else repr(float(m))}\n" for k, m in enumerate(mu)]
    if bad_line is not None:
        rows[bad_line - 2] = f"{bad_line - 1},abc\n"
    path = tmp_path / name
    path.write_text("frame,mu\n" + "".join(rows), encoding="utf-8")
    return str(path), mu


def test_a_long_file_is_refused_but_with_per_frame_naming_the_line_and_the_way(tmp_path, capsys):
    path, _ = _long(tmp_path, checks.MAX_FRAMES + 5)
    where = f"{path}:{checks.MAX_FRAMES + 2}: more than {checks.MAX_FRAMES} frames"
    base = ["estimate", "--mu-file", path, "--rho", "0.01"]
    cli_refused(base, capsys, where, "--per-frame streams")
    cli_refused([*base, "--per-frame", "--learn-noise"], capsys, where, "--learn-noise holds")
    cli_refused([*base, "--rho", "0.01"][:-2] + ["--per-frame", "--smooth"], capsys, "--smooth")


@pytest.mark.parametrize("output", ["json", "csv", "table"])
def test_a_long_file_streams_each_frames_filtered_state_through_the_online_filters(
    tmp_path, capsys, output
):
    n = checks.MAX_FRAMES + 200
    path, mu = _long(tmp_path, n)
    argv = ["estimate", "--mu-file", path, "--rho", "0.01", "--per-frame", "--filters", "ukf"]
    argv += ["--prior-mean", "1", "5", "0", "--gate", "1e-4"]
    argv += {"json": ["--json"], "csv": ["--csv"], "table": []}[output]
    status, out, err = run_cli(argv, capsys)
    assert status == 0 and err == "", err
    live = online.start("ukf", [1.0, 5.0, 0.0], 1000.0 * np.eye(3), rho=0.01, gate=1e-4)
    states = [live.update(m) for m in mu]
    if output == "table":
        assert f"{n} frames;" in out and "smoothed: not computed" in out
        rows = [r.split() for r in out.splitlines() if r.split()[:2] in ([str(n), "yes"],)]
        assert len(rows) == 1 and float(rows[0][3]) == float(f"{states[-1].depth_mean:#.4g}")
        return
    if output == "csv":
        rows = [line.split(",") for line in out.splitlines()]
        assert len(rows) == n + 1 and "smoothed_depth_mean" not in rows[0]
        column = rows[0].index("filtered_depth_mean")
        got = [float(r[column]) for r in rows[1:]]
    else:
        data = json.loads(out)
        assert data["frames"] == n and data["smoothed"] is False
        rows = data["filters"]["ukf"]
        assert [r["frame"] for r in rows] == list(range(1, n + 1))
        got = [r["filtered_depth_mean"] for r in rows]
    assert got == [s.depth_mean for s in states]


def test_a_malformed_row_deep_in_a_long_file_prints_nothing_but_its_refusal(tmp_path, capsys):
    path, _ = _long(tmp_path, checks.MAX_FRAMES + 300, bad_line=checks.MAX_FRAMES + 250)
    argv = ["estimate", "--mu-file", path, "--rho", "0.01", "--per-frame", "--filters", "ukf"]
    cli_refused(argv, capsys, f"{path}:{checks.MAX_FRAMES + 250}: mu must be a number")


class _Discard(io.TextIOBase):
    """A standard output that keeps nothing of what is written to it."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        return len(text)


def _peak(argv, sink) -> int:
    """The peak of memory allocated while ``argv`` runs, its output written to ``sink``."""
    tracemalloc.start()
    try:
        with pytest.MonkeyPatch.context() as m:
            m.setattr("sys.stdout", sink)
            assert exit_status(argv) == 0
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_streaming_a_long_file_takes_memory_that_does_not_grow_with_it(tmp_path):
    argv = ["estimate", "--rho", "0.01", "--per-frame", "--filters", "ukf", "--json"]
    argv += ["--prior-mean", "1", "5", "0", "--mu-file"]
    short, _ = _long(tmp_path, 1_100, name="short.csv", every=10)
    long, _ = _long(tmp_path, 2_600, name="long.csv", every=10)
    _peak([*argv, short], _Discard())  # the modules a first run imports
    peaks = [_peak([*argv, path], _Discard()) for path in (short, long)]
    assert peaks[1] < 1.2 * peaks[0] + 100_000, peaks
    # the measure sees memory that grows with the file: output held whole grows by a
    # kilobyte per frame
    held = _peak([*argv, long], io.StringIO())
    assert held > peaks[0] + 1_000_000, (peaks, held)


# --- odd distances, directions and speeds: an answer or one line ---------------------------

_DISTANCE = st.one_of(
    st.floats(-3.0, 3.0).map(repr),
    st.sampled_from(["", "0", "-0", "nan", "inf", "1e308", "-1e308", "1e-320", "x", "1_0"]),
)


@st.composite
def _distance_files(draw):
    """A track's bearings with a frame, step, travel or time column of odd values."""
    n = draw(st.integers(0, 8))
    column = draw(st.sampled_from(["step", "travel", "time", "frame"]))
    e = np.cumsum(np.concatenate([[0.0], np.full(max(n - 1, 0), 0.7)]))
    mu = (1.0 + 0.3 * e) / (6.0 + e)
    rows = [
        f"{m!r},{draw(_DISTANCE) if column != 'frame' else draw(st.integers(-2, 9))}" for m in mu
    ]
    return f"mu,{column}\n" + "".join(r + "\n" for r in rows)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    text=_distance_files(),
    direction=st.sampled_from([None, "receding", "approaching", "signed"]),
    speed=st.sampled_from([None, "1", "0", "-2", "nan", "1e308", "1e-300"]),
    per_frame=st.booleans(),
    output=st.sampled_from(["json", "csv", "table"]),
)
def test_odd_distances_directions_and_speeds_are_answered_or_refused_in_one_line(
    text, direction, speed, per_frame, output
):
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "t.csv")
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        argv = ["estimate", "--mu-file", path, "--rho", "0.01", "--filters", "ekf"]
        argv += [] if direction is None else ["--direction", direction]
        argv += [] if speed is None else ["--speed", speed]
        argv += ["--per-frame"] if per_frame else []
        argv += {"json": ["--json"], "csv": ["--csv"] if per_frame else [], "table": []}[output]
        out, err = io.StringIO(), io.StringIO()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                status = exit_status(argv)
    out, err = out.getvalue(), err.getvalue()
    if status == 0:
        assert err == "" and out, err
        if "--json" in argv:
            json.loads(out, parse_constant=lambda c: pytest.fail(f"not strict JSON: {c}"))
    else:
        assert status == 2 and out == "" and err.count("\n") == 1, (status, out, err)
        assert "Traceback" not in err and "Warning" not in err, err
