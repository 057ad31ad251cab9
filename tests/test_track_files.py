"""The library's track files, called directly: reading, every frame's state, learning the noise."""

import io
import json

import numpy as np
import pytest

from depthcore.problem import checks
from depthcore.registry import track_files, tracking

LIMITS = track_files.Limits(10.0, (1e-6, 1.0), (1e-6, 1e3), 1e9)
MU = np.array([-0.3, 0.0, 0.2, np.nan, 0.43, 0.5])


def _read(text: str, **kw):
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
    out = track_files.per_frame(MU, 0.01, prior, 1e-4, ["optimal", "ekf"])
    assert out["frames"] == len(MU) and set(out["filters"]) == {"optimal", "ekf"}
    json.dumps(out, allow_nan=True)
    t = tracking.track(MU, 0.01, prior, 1e-4, filter="ekf")
    rows = out["filters"]["ekf"]
    assert [r["bearing"] for r in rows] == list(np.isfinite(MU))
    for key, attribute in track_files.QUANTITIES:
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
        track_files.per_frame(call["mu"], 0.01, prior, 0.0, call["names"], frames=call["frames"])


def test_learning_the_noise_gives_plain_json():
    rng = np.random.default_rng(1)
    mu = np.array([-0.3, 0.0, 0.2, 0.33, 0.43, 0.5, 0.55, 0.6]) + rng.normal(0, 0.005, 8)
    prior = tracking.default_prior(mu)
    fit = track_files.learn(mu, 1.0, prior, known_q=0.0)
    out = track_files.learned_json(fit)
    assert out["rho"] > 0 and out["process_noise"] == 0.0
    assert json.loads(json.dumps(out)) == out
    with pytest.raises(ValueError, match="^prior must be a Gaussian"):
        track_files.learn(mu, 1.0, None)
