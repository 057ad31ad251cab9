"""The library's track files, called directly: reading, every frame's state, learning the noise."""

import io
import json

import numpy as np
import pytest

from depthcore.problem import checks
from depthcore.registry import track_files, track_runs, tracking

LIMITS = track_files.Limits(10.0, (1e-6, 1.0), (1e-6, 1e3), 1e9)
MU = np.array([-0.3, 0.0, 0.2, np.nan, 0.43, 0.5])


def _read(text: str, **kw):
    kw.setdefault("direction", "receding")
    return track_files.read("t.csv", io.BytesIO(text.encode()), LIMITS, **kw)


def test_a_file_with_every_column_is_read_through_csv():
    text = 'frame,mu,rho,step\n3,0.1,0.01,\n4,"0.2",0.02,2\n6,,,1.5\n'
    track = _read(text)
    np.testing.assert_array_equal(track.frames, [3, 4, 6])
    np.testing.assert_array_equal(track.mu, [0.1, 0.2, np.nan])
    np.testing.assert_array_equal(track.rho, [0.01, 0.02, np.nan])
    np.testing.assert_array_equal(track.steps, [2.0, 1.5])
    assert track.name == "t.csv" and not track.pixels


def test_gaps_in_frame_numbers_are_missing_frames_and_pixels_are_bearings():
    track = _read("frame,u\r\n1,420\r\n3,460\r\n", focal=400.0, cx=400.0)
    np.testing.assert_array_equal(track.frames, [1, 2, 3])
    np.testing.assert_array_equal(track.mu, [0.05, np.nan, 0.15])
    assert track.pixels


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "t.csv:1: an empty file"),
        ("mu,x\n0.1,1\n", "t.csv:1: no header or an unknown column 'x'"),
        ("mu\n0.1\nabc\n", "t.csv:3: mu must be a number, got 'abc'"),
        ("mu,rho\n0.1\n", "t.csv:2: 1 fields, but the header names 2 columns"),
        ('mu\n"0.1\n', "t.csv:2: not CSV"),
        ("u\n300\n", "t.csv:1: a u column (pixels) needs focal and cx"),
        ("mu\n", "t.csv:2: no frames after the header"),
        ("frame,mu\n2,0.1\n1,0.2\n", "t.csv:3: frame must increase strictly, got 1 after 2"),
    ],
)
def test_a_malformed_file_is_refused_in_one_line_naming_its_line(text, message):
    with pytest.raises(track_files.FileRefusal) as info:
        _read(text)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


def test_the_refusals_name_the_options_in_the_callers_words():
    words = {"focal": "--focal", "cx": "--cx", "format": "see estimate --help"}
    with pytest.raises(track_files.FileRefusal, match="needs --focal and --cx"):
        _read("u\n300\n", words=words)
    with pytest.raises(track_files.FileRefusal, match=r"\(see estimate --help\)"):
        _read("x\n1\n", words=words)


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"focal": 400.0}, "cx is needed with the other"),
        ({"focal": 0.0, "cx": 1.0}, "focal must be positive"),
        ({"focal": np.inf, "cx": 1.0}, "focal must be finite"),
        ({"focal": 1.0, "cx": "a"}, "cx must be finite"),
        ({"words": {"other": "x"}}, "words takes the keys"),
    ],
)
def test_bad_arguments_are_refused_naming_them(kw, message):
    with pytest.raises(ValueError, match=message):
        _read("mu\n0.1\n", **kw)


def test_bad_path_and_limits_are_refused_naming_them(tmp_path):
    with pytest.raises(ValueError, match="^limits must be"):
        track_files.read("t.csv", io.BytesIO(b"mu\n0.1\n"), (1, 2, 3, 4))
    with pytest.raises(ValueError, match="^path must be"):
        track_files.read(3, io.BytesIO(b"mu\n0.1\n"), LIMITS)
    with pytest.raises(ValueError, match="^path: cannot read"):
        track_files.read_path(tmp_path / "none.csv", LIMITS)
    with pytest.raises(ValueError, match="^path must be a file's path"):
        track_files.read_path(3, LIMITS)
    (tmp_path / "t.csv").write_text("mu\n0.1\n0.2\n")
    np.testing.assert_array_equal(track_files.read_path(tmp_path / "t.csv", LIMITS).mu, [0.1, 0.2])


def test_rows_past_the_filters_limit_stop_the_reading():
    text = "mu\n" + "0.1\n" * (checks.MAX_FRAMES + 5)
    with pytest.raises(track_files.FileRefusal, match=rf":{checks.MAX_FRAMES + 2}: more than"):
        _read(text)


def test_per_frame_equals_the_track_filter_at_every_frame():
    prior = tracking.default_prior(MU)
    out = track_runs.per_frame(MU, 0.01, prior, 1e-4, ["optimal", "ekf"])
    assert out["frames"] == len(MU) and set(out["filters"]) == {"optimal", "ekf"}
    json.dumps(out, allow_nan=True)
    t = tracking.track(MU, 0.01, prior, 1e-4, filter="ekf")
    rows = out["filters"]["ekf"]
    assert [r["bearing"] for r in rows] == list(np.isfinite(MU))
    for key, attribute in track_runs.QUANTITIES:
        np.testing.assert_array_equal(
            [r[f"smoothed_{key}_mean"] for r in rows], getattr(t.smoothed, f"{attribute}_mean")
        )
    assert rows[0]["step"] is None and rows[1]["step"] == 1.0 and rows[3]["rho"] is None


@pytest.mark.parametrize(
    "args, message",
    [
        ({"names": "optimal"}, "^names must be a sequence"),
        ({"names": []}, "^names must be a sequence"),
        ({"names": ["bank"]}, "^names: 'bank' is not a filter with a smoother"),
        ({"frames": [1, 2]}, r"^frames must have shape \(6,\)"),
        ({"mu": [[0.1, 0.2, 0.3]]}, r"^mu must be one track"),
        ({"mu": ["a", "b", "c"]}, "^mu must be an array of numbers"),
    ],
)
def test_per_frame_refuses_bad_arguments_naming_them(args, message):
    call = {"mu": MU, "names": ["optimal"], "frames": None, **args}
    prior = tracking.default_prior(MU)
    with pytest.raises(ValueError, match=message):
        track_runs.per_frame(call["mu"], 0.01, prior, 0.0, call["names"], frames=call["frames"])


def test_learning_the_noise_gives_plain_json():
    rng = np.random.default_rng(1)
    mu = np.array([-0.3, 0.0, 0.2, 0.33, 0.43, 0.5, 0.55, 0.6]) + rng.normal(0, 0.005, 8)
    prior = tracking.default_prior(mu)
    fit = track_runs.learn(mu, 1.0, prior, known_q=0.0)
    out = track_runs.learned_json(fit)
    assert out["rho"] > 0 and out["process_noise"] == 0.0
    assert json.loads(json.dumps(out)) == out
    with pytest.raises(ValueError, match="^prior must be a Gaussian"):
        track_runs.learn(mu, 1.0, None)


# --- distances and their direction ----------------------------------------------------------


def test_a_step_travel_or_time_column_gives_signed_steps_in_the_direction_given():
    steps = np.array([0.5, 1.5, 2.0])
    travel = np.concatenate([[0.0], np.cumsum(steps)])
    texts = {
        "step": "mu,step\n0.1,\n0.2,0.5\n0.3,1.5\n0.35,2\n",
        "travel": "mu,travel\n"
        + "".join(f"{m},{t}\n" for m, t in zip(MU[:4], travel, strict=True)),
        "time": "mu,time\n"
        + "".join(f"{m},{t / 4}\n" for m, t in zip(MU[:4], travel, strict=True)),
    }
    for kind, text in texts.items():
        speed = {"speed": 4.0} if kind == "time" else {}
        for direction, sign in (("receding", 1.0), ("approaching", -1.0)):
            track = _read(text, direction=direction, **speed)
            np.testing.assert_allclose(track.steps, sign * steps, rtol=1e-12)
            assert track.direction == direction
        assert (track.times is not None) == (kind == "time")
    signed = _read("mu,step\n0.1,\n0.2,-0.5\n0.3,1.5\n", direction="signed")
    np.testing.assert_array_equal(signed.steps, [-0.5, 1.5])
    down = _read("mu,travel\n0.1,0\n0.2,-1\n0.3,-3\n", direction="signed")
    np.testing.assert_array_equal(down.steps, [-1.0, -2.0])


def test_without_distances_the_frames_are_unit_steps_receding_unless_said():
    assert _read("mu\n0.1\n0.2\n0.3\n", direction=None).steps is None
    track = _read("frame,mu\n1,0.1\n3,0.3\n", direction="approaching")
    np.testing.assert_array_equal(track.steps, [-1.0, -1.0])
    np.testing.assert_array_equal(track.frames, [1, 2, 3])


@pytest.mark.parametrize(
    "text, kw, message",
    [
        ("mu,step\n0.1,\n0.2,1\n", {"direction": None}, "^direction is needed: t.csv has a step"),
        ("mu,time\n0.1,0\n", {"direction": None, "speed": 1.0}, "^direction is needed"),
        ("mu\n0.1\n", {"direction": "forward"}, "^direction must be one of"),
        ("mu\n0.1\n", {"direction": "signed"}, "^direction signed takes the signs"),
        ("mu,time\n0.1,0\n", {"direction": "signed", "speed": 1.0}, "a time column"),
        ("mu,time\n0.1,0\n", {}, "^speed is needed"),
        ("mu\n0.1\n", {"speed": 1.0}, "^speed: not used"),
        ("mu,time\n0.1,0\n", {"speed": -1.0}, "^speed must be a positive number"),
        ("mu,time\n0.1,0\n", {"speed": np.inf}, "^speed must be"),
        ("mu,step,travel\n0.1,,0\n", {}, "t.csv:1: the header names step and travel"),
        ("mu,step\n0.1,\n0.2,-1\n", {}, "t.csv:3: step must be from 1e-06 to 1000 .a magnitude"),
        ("mu,step\n0.1,\n0.2,0\n", {"direction": "signed"}, "t.csv:3: step must be from"),
        ("mu,step\n0.1,\n0.2,\n", {}, "got an empty field"),
        ("mu,travel\n0.1,1\n", {}, "t.csv:2: the first row's travel must be 0"),
        ("mu,travel\n0.1,0\n0.2,-1\n", {}, "t.csv:3: travel must change by 1e-06 to 1000"),
        ("mu,travel\n0.1,0\n0.2,\n", {}, "t.csv:3: travel must be a number at every row"),
        ("mu,time\n0.1,0\n0.2,0\n", {"speed": 1.0}, "t.csv:3: time must increase strictly"),
        ("mu,time\n0.1,0\n0.2,1e9\n", {"speed": 1.0}, "t.csv:3: time gives a step of 1e"),
        ("frame,mu\n1,0.1\n1003,0.2\n", {}, "t.csv:3: frame jumps from 1 to 1003, more than 1000"),
    ],
)
def test_distances_against_their_direction_are_refused_naming_the_argument_or_line(
    text, kw, message
):
    with pytest.raises(ValueError, match=message) as info:
        _read(text, **kw)
    assert "\n" not in str(info.value)


class _Rows:
    """A header, then endless rows of a track (a bearing and a step); counts the lines read."""

    def __init__(self):
        self.lines = 0

    def readline(self, size=-1):
        self.lines += 1
        if self.lines == 1:
            return b"frame,mu,step\n"
        return f"{self.lines},0.1,{'' if self.lines == 2 else 1}\n".encode()


def test_a_file_is_read_row_by_row_as_its_frames_are_asked_for():
    stream = _Rows()
    reading = track_files.open_track("t.csv", stream, LIMITS, direction="approaching")
    assert stream.lines == 1 and reading.direction == "approaching"
    frames = [next(reading.frames) for _ in range(5000)]
    assert stream.lines == 5001
    assert frames[0].step != frames[0].step and {f.step for f in frames[1:]} == {-1.0}
    assert [f.frame for f in frames[:3]] == [2, 3, 4] and frames[2].line == 4
    held = track_files.hold(track_files.open_track("t.csv", _Rows(), LIMITS, direction="signed"))
    assert held.track is None and len(held.first) == checks.MAX_FRAMES + 1
    assert [next(held.reading.frames).frame for _ in range(3)] == [2, 3, 4]


def test_streamed_rows_are_each_online_filters_frame_by_frame():
    from depthcore.registry import online

    prior = tracking.default_prior(MU)
    text = "frame,mu,rho\n" + "".join(
        f"{10 + k},{'' if np.isnan(m) else m},{'' if np.isnan(m) else 0.01 * (k + 1)}\n"
        for k, m in enumerate(MU)
    )
    reading = track_files.open_track("t.csv", io.BytesIO(text.encode()), LIMITS)
    rows = list(track_runs.streamed(reading.frames, None, prior, 1e-3, ["optimal", "ekf"], 0.5))
    assert len(rows) == len(MU) and list(rows[0]) == ["optimal", "ekf"]
    for name in ("optimal", "ekf"):
        live = online.start(name, prior.mean, prior.cov, 0.01, 1e-3, 0.5)
        for k, m in enumerate(MU):
            r = 0.01 * (k + 1) if np.isfinite(m) else 0.01
            est = live.update(m, rho=r, step=1.0)
            row = rows[k][name]
            assert row["frame"] == 10 + k and row["bearing"] == bool(np.isfinite(m))
            assert row["filtered_depth_mean"] == est.depth_mean and row["gated"] == est.gated
            assert row["step"] == (None if k == 0 else 1.0) and "smoothed_depth_mean" not in row
    with pytest.raises(ValueError, match="^names: 'iterated' is not an online filter"):
        next(track_runs.streamed(iter([]), 0.01, prior, 0.0, ["iterated"]))


def test_relabel_names_the_frames_a_message_counts_from_one():
    def label(k):
        return 100 + k if k <= 5 else k

    message = "the first three present bearings (frames 1, 2 and 4) put it behind; frame 5"
    assert track_runs.relabel(message, label) == (
        "the first three present bearings (frames 101, 102 and 104) put it behind; frame 105"
    )
    assert track_runs.relabel("at most 1000 frames", label) == "at most 1000 frames"
