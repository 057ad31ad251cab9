"""The library's track files of pairs (a point in 3-D), their priors, summary and runs."""

import io
import math

import numpy as np
import pytest

from depthcore.problem import model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE
from depthcore.registry import online, track_files, track_runs, tracking
from depthcore.registry.filters import FILTERS

LIMITS = track_files.Limits(10.0, (1e-6, 1.0), (1e-6, 1e3), 1e9)
# a point at (x, y, v, h, w) = (-2, 10, 0.5, 1.5, -0.1) seen at unit steps, receding
FRAMES = np.arange(6.0)
MU = np.stack([(-2.0 + 0.5 * FRAMES), (1.5 - 0.1 * FRAMES)], axis=-1) / (10.0 + FRAMES)[:, None]


def _read(text: str, **kw):
    kw.setdefault("direction", "receding")
    return track_files.read("t.csv", io.BytesIO(text.encode()), LIMITS, **kw)


def _pairs_text(mu, columns="mu,nu"):
    rows = ["" if np.isnan(m) else f"{m!r},{n!r}" for m, n in mu.tolist()]
    return columns + "\n" + "".join((r or ",") + "\n" for r in rows)


# --- reading pairs ------------------------------------------------------------------------


def test_a_mu_nu_file_is_a_track_of_pairs_with_a_missing_row():
    mu = MU.copy()
    mu[2] = np.nan
    track = _read(_pairs_text(mu))
    assert track.mu.shape == (6, 2) and not track.pixels
    np.testing.assert_array_equal(track.mu, mu)
    reading = track_files.open_track("t.csv", io.BytesIO(_pairs_text(mu).encode()), LIMITS)
    assert reading.pairs and [f.nu for f in reading.frames][1] == mu[1, 1]


def test_pixel_columns_and_rows_are_pairs_by_the_focal_length_and_principal_point():
    focal, cx, cy = 800.0, 320.0, 240.0
    u, v = cx + focal * MU[:, 0], cy + focal * MU[:, 1]
    text = "u,v\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(u.tolist(), v.tolist(), strict=True))
    track = _read(text, focal=focal, cx=cx, cy=cy)
    np.testing.assert_array_equal(track.mu[:, 0], model.bearings_from_pixels(u, cx, focal))
    np.testing.assert_array_equal(track.mu[:, 1], model.bearings_from_pixels(v, cy, focal))
    assert track.pixels
    # the row's centre is cy, not cx: read with another cy, the heights move
    other = _read(text, focal=focal, cx=cx, cy=cx)
    assert np.all(other.mu[:, 1] != track.mu[:, 1])


@pytest.mark.parametrize(
    "text, kw, message",
    [
        ("mu,nu\n0.1,\n", {}, "t.csv:2: a pair has one coordinate only"),
        ("mu,nu\n,0.1\n", {}, "t.csv:2: a pair has one coordinate only"),
        ("mu,nu\n0.1,abc\n", {}, "t.csv:2: nu must be a number, got 'abc'"),
        ("mu,nu\n0.1,inf\n", {}, "t.csv:2: nu must be a number"),
        ("mu,nu\n0.1,1e300\n", {}, "t.csv:2: nu must be at most 10 in magnitude"),
        ("u,nu\n1,0.1\n", {"focal": 1.0, "cx": 0.0}, "t.csv:1: a pair's columns are mu and nu"),
        ("mu,v\n0.1,1\n", {}, "t.csv:1: a pair's columns are mu and nu"),
        ("u,v\n1,1\n", {"focal": 1.0, "cx": 0.0}, "t.csv:1: a v column (pixel rows) needs cy"),
        ("u\n1\n", {"focal": 1.0, "cx": 0.0, "cy": 0.0}, "t.csv:1: cy is for a v column"),
        ("u,v\n1,1e12\n", {"focal": 1.0, "cx": 0.0, "cy": 0.0}, "t.csv:2: v gives a bearing"),
    ],
)
def test_malformed_pairs_are_refused_in_one_line_naming_the_line(text, kw, message):
    with pytest.raises(track_files.FileRefusal) as info:
        _read(text, **kw)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"cy": 1.0}, "^cy is for a v column"),
        ({"focal": 1.0, "cx": 0.0, "cy": math.inf}, "^cy must be finite"),
        ({"focal": 1.0, "cx": 0.0, "cy": "a"}, "^cy must be finite"),
    ],
)
def test_a_bad_cy_is_refused_naming_it(kw, message):
    with pytest.raises(ValueError, match=message):
        _read("mu\n0.1\n", **kw)


def test_a_held_tracks_frames_are_those_its_file_gives():
    mu = MU.copy()
    mu[3] = np.nan
    text = "frame,mu,nu,rho,step\n" + "".join(
        f"{5 + k},{'' if np.isnan(m) else repr(m)},{'' if np.isnan(n) else repr(n)},"
        f"{'' if np.isnan(m) else 0.01 * (k + 1)},{'' if k == 0 else 0.5 * k}\n"
        for k, (m, n) in enumerate(mu.tolist())
    )
    stream = io.BytesIO(text.encode())
    read = list(track_files.open_track("t.csv", stream, LIMITS, direction="approaching").frames)
    held = list(track_runs.frames_of(_read(text, direction="approaching")))
    assert len(read) == len(held) == 6 and held[2].step == -1.0
    for a, b in zip(read, held, strict=True):
        np.testing.assert_array_equal(a._replace(line=0), b)
    plane = list(track_runs.frames_of(_read("mu\n0.1\n0.2\n")))
    assert [f.mu for f in plane] == [0.1, 0.2] and all(np.isnan(f.nu) for f in plane)
    assert plane[1].step == 1.0


# --- the prior without one given, and the noise-free state ----------------------------------


def test_the_default_prior_of_pairs_is_the_planes_rule_with_the_height_on_the_first_sight():
    prior = track_runs.start_prior(MU)
    plane = tracking.default_prior(MU[:, 0])
    np.testing.assert_array_equal(prior.mean[:3], plane.mean)
    assert prior.mean[3] == MU[0, 1] * plane.mean[1] and prior.mean[4] == 0.0
    np.testing.assert_array_equal(prior.cov, PAPER_PRIOR_SCALE * np.eye(5))
    # frame 1 missing: the height on the first sight's line, at the depth travelled to it
    gap = MU.copy()
    gap[0] = np.nan
    steps = np.array([0.5, 1.0, 1.0, 1.0, 1.0])
    prior = track_runs.start_prior(gap, steps)
    y1 = tracking.default_prior(gap[:, 0], steps).mean[1]
    assert prior.mean[3] == pytest.approx(gap[1, 1] * (y1 + 0.5), rel=1e-15)
    np.testing.assert_array_equal(track_runs.start_prior(MU[:, 0]).mean, plane.mean)


def test_the_range_prior_puts_the_depth_where_it_is_told_and_the_rest_on_the_line_of_sight():
    plane = track_runs.start_prior(MU[:, 0], depth=(30.0, 4.0))
    np.testing.assert_array_equal(plane.mean, [MU[0, 0] * 30.0, 30.0, 0.0])
    np.testing.assert_array_equal(plane.cov, np.diag([1000.0, 16.0, 1000.0]))
    space = track_runs.start_prior(MU, np.full(5, 2.0), (30.0, 4.0))
    np.testing.assert_array_equal(space.mean, [MU[0, 0] * 30, 30, 0, MU[0, 1] * 30, 0])
    np.testing.assert_array_equal(np.diag(space.cov), [1000.0, 16.0, 1000.0, 1000.0, 1000.0])
    for bad in ((0.0, 1.0), (10.0, -1.0), (math.nan, 1.0)):
        with pytest.raises(ValueError, match="^depth must be a mean and an SD"):
            track_runs.start_prior(MU, None, bad)


@pytest.mark.parametrize(
    "mu, steps, why",
    [
        ([0.1, 0.2, 0.3, 0.5], None, "degenerate"),
        ([0.3, 0.1, 0.2, 0.3], None, "behind the camera"),
        ([0.1, np.nan, 0.2, 0.5], None, "frames 1, 2 and 3"),
        ([-0.3, 0.0, 0.2, 0.33], [-1.0, -1.0, -1.0], "a unit step apart, receding"),
    ],
)
def test_the_noise_free_state_says_why_it_is_undefined(mu, steps, why):
    c, reason = track_runs.noise_free(np.array(mu), steps)
    assert c is None and why in reason


def test_the_noise_free_state_is_eq_7_where_defined():
    c, reason = track_runs.noise_free(MU)
    np.testing.assert_array_equal(c, model.noise_free_state(MU[:3, 0]))
    assert reason is None


# --- a point in 3-D at its last frame, and frame by frame -----------------------------------


def test_the_summary_of_pairs_is_each_filters_own_answer_for_every_coordinate():
    rng = np.random.default_rng(2)
    mu = MU + 0.002 * rng.standard_normal(MU.shape)
    prior = track_runs.Prior(np.array([-2.0, 10.0, 0.0, 1.0, 0.0]), np.diag([4, 25, 1, 4, 1.0]))
    out = track_runs.summarize_pairs(mu, 0.002, prior, 0.0, ["optimal", "ekf"])
    assert out["coordinates"] == ["x", "y", "v", "h", "w"] and out["frames"] == 6
    for name in ("optimal", "ekf"):
        est = FILTERS[name](mu, 0.002, prior.mean, prior.cov)
        f = out["filters"][name]
        for key, i in track_runs.SPACE:
            assert f[key]["mean"] == est.mean[i]
            assert f[key]["sd"] == np.sqrt(est.cov[i, i])
    assert out["filters"]["optimal"]["depth"]["error"] < 1e-8
    assert "not_run" not in out and out["mu"][0] == mu[0].tolist()
    with pytest.raises(ValueError, match="^names: 'second_order' is not a filter of a point"):
        track_runs.summarize_pairs(mu, 0.002, prior, 0.0, ["second_order"])
    half = mu.copy()
    half[2, 1] = np.nan
    with pytest.raises(ValueError, match="one coordinate missing"):
        track_runs.summarize_pairs(half, 0.002, prior, 0.0, ["ekf"])


def test_a_filter_that_cannot_take_the_pairs_is_listed_with_its_reason():
    prior = track_runs.start_prior(MU)  # broad: the UKF's sigma points reach behind the camera
    out = track_runs.summarize_pairs(MU, 0.002, prior, 0.0, ["optimal", "ukf"])
    assert "optimal" in out["filters"]
    assert "ukf" not in out["filters"] and "behind the camera" in out["not_run"]["ukf"]


def test_streamed_pairs_are_each_online_filters_frame_by_frame():
    mu = MU.copy()
    mu[3] = np.nan
    prior = track_runs.Prior(np.array([-2.0, 10.0, 0.0, 1.0, 0.0]), np.diag([4, 25, 1, 4, 1.0]))
    text = _pairs_text(mu, "mu,nu")
    frames = track_files.open_track("t.csv", io.BytesIO(text.encode()), LIMITS).frames
    rows = list(track_runs.streamed(frames, 0.002, prior, 1e-3, ["optimal", "ekf"], None))
    for name in ("optimal", "ekf"):
        live = online.start(name, prior.mean, prior.cov, 0.002, 1e-3)
        for k, pair in enumerate(mu):
            est = live.update(pair)
            row = rows[k][name]
            assert row["bearing"] == (k != 3) and (row["nu"] == pair[1] or k == 3)
            for key, i in track_runs.SPACE:
                assert row[f"filtered_{key}_mean"] == est.mean[i]
                assert row[f"filtered_{key}_sd"] == np.sqrt(est.cov[i, i])


# --- learning -----------------------------------------------------------------------------


def test_learned_json_names_a_columns_scale_the_intervals_and_the_frames_the_gate_skipped():
    from depthcore.exact import learning

    rng = np.random.default_rng(0)
    e = np.arange(30.0)
    mu = (-2.0 + 0.5 * e) / (10.0 + e) + 0.002 * rng.standard_normal(30)
    mu[[13, 21]] += [0.04, -0.04]  # two outliers, 20 SDs off
    prior = tracking.default_prior(mu)
    fit = track_runs.learn(mu, 1.0, prior, 0.0, gate=0.01)
    same = learning.fit(mu, prior.mean, prior.cov, process_noise=0.0, gate=0.01)
    assert (fit.rho, fit.rho_interval) == (same.rho, same.rho_interval)
    frames, times = np.arange(101, 131), 0.04 * e
    out = track_runs.learned_json(fit, True, frames, times)
    assert out["gate_skipped"] == [114, 122]
    assert out["gate_skipped_times"] == times[[13, 21]].tolist()
    assert out["rho_column_scale"] == fit.rho and "rho" not in out
    assert out["estimated"] == ["rho_column_scale"]
    assert out["intervals"] == "profile"
    assert track_runs.learned_json(fit)["gate_skipped"] == [14, 22]
    ungated = track_runs.learned_json(track_runs.learn(mu, 1.0, prior, 0.0))
    assert "gate_skipped" not in ungated and ungated["rho"] > 5 * fit.rho
