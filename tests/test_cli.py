"""The command line: python -m depthcore reproduce | estimate | study | atlas."""

import json
import subprocess
import sys
import time

import pytest

from depthcore.cli import cluster as cluster_options
from depthcore.cli.main import build_parser, main
from depthcore.exact import posterior
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS
from depthcore.studies import monte_carlo, reproduce, tasks
from depthcore.studies import trials as study_trials

from helpers import exit_status

FIG2 = SCENARIOS["fig2"]


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "depthcore", *args], capture_output=True, text=True
    )


def refusal(args, capsys):
    """(exit status, standard output, standard error) of ``main(args)`` in this process."""
    status = exit_status(args)
    out, err = capsys.readouterr()
    return status, out, err


def test_reproduce_json_has_every_scenario_filter_and_reading(capsys):
    assert main(["reproduce", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    keys = [s["key"] for s in data["scenarios"]]
    assert keys == ["fig2", "fig3", "fig4", "fig5", "fig6"]
    for s in data["scenarios"]:
        combos = {(r["filter"], r["reading"], r["support"], r["quantity"]) for r in s["rows"]}
        assert ("optimal", "derived", "front", "velocity") in combos
        assert ("second_order", "printed", "all", "depth") in combos
        assert ("ekf", "printed", "all", "depth") in combos
        assert ("ukf", "-", "all", "velocity") in combos
        assert ("particle", "-", "front", "depth") in combos
        assert len(combos) == len(s["rows"]) == 18


def test_reproduce_table_prints_paper_numbers(capsys):
    assert main(["reproduce"]) == 0
    out = capsys.readouterr().out
    assert "6.47" in out and "67.45" in out and "mean yes, sd yes" in out


def test_estimate_matches_the_library(capsys):
    assert main(["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["c"] == pytest.approx([1.2, 6.0, 1.2])
    assert data["prior_mean"] == pytest.approx([-1.2, 4.0, 0.0])
    assert data["filters"]["optimal"]["depth"]["mean"] == pytest.approx(6.4659786, abs=1e-6)
    assert data["filters"]["ekf"]["depth"]["sd"] == pytest.approx(0.16, abs=5e-4)


@pytest.mark.parametrize("names", [("iterated", "inverse_depth"), ("modified_polar", "ekf")])
def test_estimate_runs_the_named_filters_of_the_registry(capsys, names):
    mu, rho = ["-0.3", "0", "0.2"], 0.005
    assert main(["estimate", "--mu", *mu, "--rho", str(rho), "--filters", *names, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert list(data["filters"]) == list(names)
    prior = FIG2.prior
    for name in names:
        est = FILTERS[name]([-0.3, 0.0, 0.2], rho, prior.mean, prior.cov)
        assert data["filters"][name]["depth"]["mean"] == pytest.approx(est.depth_mean)
        assert data["filters"][name]["depth"]["sd"] == pytest.approx(est.depth_sd)
    assert main(["estimate", "--mu", *mu, "--rho", str(rho), "--filters", *names]) == 0
    table = capsys.readouterr().out
    assert all(f"\n{name} " in table for name in names) and "\noptimal " not in table


def test_estimate_refuses_a_filter_named_twice_or_unknown():
    twice = run("estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005", "--filters", "ekf", "ekf")
    assert twice.returncode == 2 and "named more than once" in twice.stderr
    assert "Traceback" not in twice.stderr
    unknown = run("estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005", "--filters", "kf")
    assert unknown.returncode == 2 and "invalid choice" in unknown.stderr


def test_estimate_accepts_prior_options(capsys):
    args = [
        "estimate",
        "--mu",
        "-0.3",
        "0",
        "0.2",
        "--rho",
        "0.005",
        "--prior-mean",
        "-1.2",
        "6",
        "0",
        "--prior-cov",
        "500",
        "--json",
    ]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["prior_cov"][0][0] == 500 and data["prior_mean"][1] == 6
    full = ["--prior-cov"] + "4 0 0 0 4 0 0 0 4".split()
    assert main(args[:-3] + full + ["--json"]) == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["--mu", "0.1", "0.1", "0.1", "--rho", "0.01"], "--mu is degenerate"),
        (["--mu", "-0.3", "0", "0.2", "--rho", "0"], "--rho must be from 1e-12 to 1000, got 0.0"),
        (["--mu", "-0.3", "0", "0.2", "--rho", "-1"], "--rho must be from 1e-12 to 1000, got -1.0"),
        (["--mu", "-0.3", "0", "0.2", "--rho", "nan"], "--rho must be from 1e-12 to 1000, got nan"),
        (["--mu", "-0.3", "0", "0.2", "--rho", "1000.0001"], "got 1000.0001"),
        (["--mu", "-0.3", "nan", "0.2", "--rho", "0.01"], "--mu has 2 bearings present"),
        (["--mu", "-0.3", "inf", "0.2", "--rho", "0.01"], "--mu must be finite (or nan"),
        (["--mu", "0.2", "0", "-0.3", "--rho", "0.01"], "behind the camera"),
        (
            ["--mu", "-0.3", "0", "0.2", "--rho", "0.01", "--prior-cov", "-5"],
            "--prior-cov must be positive definite",
        ),
        (
            ["--mu", "-0.3", "0", "0.2", "--rho", "0.01", "--prior-cov", "1", "2"],
            "--prior-cov takes 1 value",
        ),
        (
            ["--mu", "-0.3", "0", "0.2", "--rho", "0.01", "--prior-cov"]
            + "1 0 0 0 -1 0 0 0 1".split(),
            "--prior-cov must be positive definite",
        ),
        (
            ["--mu", "-0.3", "0", "0.2", "--rho", "0.01", "--prior-mean", "0", "inf", "0"],
            "--prior-mean must be finite",
        ),
        (
            ["--mu", "-0.3", "0", "0.2", "--rho", "0.01", "--prior-mean", "0", "-4", "0"],
            "predicted depth",
        ),
        (["--mu", "-0.3", "0", "--rho", "0.01"], "--mu takes at least 3 bearings"),
        (["--mu", "-0.3", "0", "0.2", "--rho", "abc"], "invalid float value"),
    ],
)
def test_estimate_rejects_bad_input_with_one_line(args, message, capsys):
    status, out, err = refusal(["estimate", *args], capsys)
    assert status == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--mu", "0.1", "0.1", "0.1", "--rho", "0.01"], "--mu is degenerate"),
        (["--mu", "-0.3", "0", "0.2", "--rho", "abc"], "invalid float value"),
    ],
)
def test_a_refusal_ends_the_process_with_one_line_and_status_2(args, message):
    # (the refusals above run in this process: here the interpreter's own exit, warnings and all)
    result = run("estimate", *args)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]


@pytest.mark.parametrize("command", ["reproduce", "estimate", "study", "atlas"])
def test_every_help_is_plain_text_with_examples(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = capsys.readouterr().out
    assert f"python -m depthcore {command}" in out.split("examples:")[1]
    assert "``" not in out and ":func:" not in out


def test_estimate_shows_its_prior_and_labels_c(capsys):
    assert main(["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005"]) == 0
    out = capsys.readouterr().out
    assert "c = (x, y, v) at frame 3 = (1.200, 6.000, 1.200)" in out
    assert "prior at frame 1: mean (x, y, v) = (-1.200, 4.000, 0.000), covariance 1000 I" in out


def test_reproduce_counts_the_matched_numbers(capsys):
    assert main(["reproduce"]) == 0
    out = capsys.readouterr().out
    rows = [r for sc in reproduce.reproduce()["scenarios"] for r in sc["rows"]]
    compared = [r for r in rows if r["mean_matches"] is not None]
    matched = sum(r["mean_matches"] + r["sd_matches"] for r in compared)
    assert f"{matched} of the paper's {2 * len(compared)} printed means and SDs" in out
    assert "reading  derived" in out and "support  front" in out


def test_debug_shows_the_traceback_of_an_unexpected_failure(capsys, monkeypatch):
    def boom(*args, **kwargs):
        raise OverflowError("boom")

    monkeypatch.setattr(reproduce, "summarize", boom)
    argv = ["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rerun with --debug" in err
    assert main([*argv, "--debug"]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_study_shows_a_progress_bar_on_a_terminal_only():
    import fcntl
    import os
    import pty
    import struct
    import termios

    argv = [sys.executable, "-m", "depthcore", "study", "--trials", "30", "--filters", "ekf"]
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    done = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=slave, timeout=120)
    os.close(slave)
    shown = b""
    try:
        while chunk := os.read(master, 4096):
            shown += chunk
    except OSError:  # the terminal closed
        pass
    os.close(master)
    assert done.returncode == 0 and b"30/30" in shown
    quiet = subprocess.run(argv, capture_output=True, timeout=120)
    assert quiet.returncode == 0 and quiet.stderr == b""


def test_study_particles_default_is_the_studys():
    assert build_parser().parse_args(["study"]).particles == study_trials.PARTICLES


def test_estimate_takes_more_frames_process_noise_and_smoothing(capsys):
    import numpy as np

    mu = ["-0.3", "0", "0.2", "0.33", "0.43"]
    argv = ["estimate", "--mu", *mu, "--rho", "0.005", "--process-noise", "0.01"]
    assert main([*argv, "--smooth", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["frames"] == 5 and data["process_noise"] == 0.01
    assert set(data["filters"]) == {"optimal", "second_order", "ekf", "ukf"}
    assert data["not_run"] == {"particle": "supports only no process noise"}
    # the default prior is the paper's rule on the first three bearings
    mean = np.array([-1.2, 4.0, 0.0])
    m = posterior.moments([float(v) for v in mu], 0.005, mean, 1000 * np.eye(3), 0.01)
    assert data["filters"]["optimal"]["depth"]["mean"] == pytest.approx(m.depth_mean[0], 1e-12)
    sm = data["smoothed"]
    assert len(sm["depth_mean"]) == 5
    assert sm["depth_mean"][-1] == pytest.approx(m.depth_mean[0], rel=1e-10)
    assert np.allclose(np.diff(sm["depth_mean"]), 1.0)
    assert main([*argv, "--smooth"]) == 0
    out = capsys.readouterr().out
    assert "5 frames, process noise q = 0.01" in out and "(optimal, smoothed)" in out
    assert "particle      not run" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005", "--process-noise", "-1"],
            "--process-noise must be 0 or from",
        ),
        (
            ["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005", "--process-noise", "1e3"],
            "--process-noise must be 0 or from",
        ),
        (
            ["estimate", "--mu", "0.3", "0", "0.2", "0.1", "--rho", "0.005"],
            "--prior-mean or --prior-depth MEAN SD is needed",
        ),
        (["study", "--frames", "2"], "--frames must be an integer from 3 to 1000, got 2"),
        (
            ["study", "--frames", "5", "--process-noise", "0.01", "--filters", "particle"],
            "--filters: particle cannot run",
        ),
        (["study", "--truth", "prior", "--prior", "paper", "--frames", "5"], "needs a fixed prior"),
        (
            ["study", "--truth", "prior", "--frames", "5", "--process-noise", "-1"],
            "--process-noise",
        ),
    ],
)
def test_more_frames_refusals_are_one_line(args, message, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_study_runs_more_frames_with_process_noise(capsys):
    argv = ["study", "--frames", "6", "--process-noise", "0.01", "--trials", "30", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["frames"] == 6 and "particle" not in data["filters"]
    assert data["filters"]["optimal"]["hellinger_depth"]["mean"] == 0.0


def test_study_of_more_frames_answers_at_the_smallest_noise(capsys):
    # rho = 1e-12: the exact filter's depth CDF at the truth settles at its roundoff
    # floor (the depths, as floats, resolve the posterior to about 1e-6 of its SD)
    argv = ["study", "--frames", "4", "--rho", "1e-12", "--trials", "20", "--json"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    data = json.loads(captured.out)
    scores = data["filters"]["optimal"]["depth"]
    assert 0.0 <= scores["coverage_68"] <= scores["coverage_95"] <= 1.0


def test_the_long_commands_report_their_progress():
    calls = []
    reproduce.reproduce(keys=["fig2"], progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 1)]
    calls.clear()
    monte_carlo.prior_study(trials=5, progress=lambda done, total: calls.append((done, total)))
    assert calls and calls[-1] == (5, 5)


def test_every_table_has_a_legend_of_its_columns(capsys):
    assert main(["estimate", "--mu", "-0.3", "0", "0.2", "0.33", "--rho", "0.005", "--smooth"]) == 0
    out = capsys.readouterr().out
    assert "legend: depth mean, depth sd" in out and "vel. mean, vel. sd" in out
    assert "frame                 the frame's number in the track" in out
    assert main(["study", "--truth", "prior", "--trials", "3"]) == 0
    out = capsys.readouterr().out
    assert "legend: nominal" in out and "KS p, chi-square p" in out


@pytest.mark.parametrize("argv", [["--help"], ["estimate", "--help"]])
def test_help_speaks_of_n_frames_not_three_measurements(argv, capsys):
    import depthcore

    with pytest.raises(SystemExit):
        main(argv)
    out = capsys.readouterr().out
    assert "three measurements" not in out and "any three" not in out
    assert "N >= 3 bearings (up to 1000 frames, or any number streamed)" in " ".join(out.split())
    assert "three noisy image" not in depthcore.__doc__


# --- study --workers: a whole number from 1 to tasks.MAX_WORKERS, or one line -------------

#: Values of ``study --workers`` refused, by class: out of range (10000 must not start ten
#: thousand processes), not a whole number in decimal digits, or no value at all.
_BAD_WORKERS = {
    "out of range": ["0", "-1", "65", "10000", "99999999999999999999"],
    "not whole": ["1.5", "abc", "", "1e3", "0x10", "1_0", "\u0662", "2 2", "64x"],
}


@pytest.mark.parametrize("command", [["study", "--trials", "3"], ["atlas"]], ids=["study", "atlas"])
@pytest.mark.parametrize("value", [v for values in _BAD_WORKERS.values() for v in values], ids=repr)
def test_study_refuses_workers_out_of_range_or_not_whole_in_one_line(
    command, value, capsys, recwarn
):
    # refused before any cluster starts, in this process: within a second (30 s: a guard)
    start = time.monotonic()
    status, out, err = refusal([*command, "--workers", value], capsys)
    assert status == 2 and out == ""
    assert err == (
        f"python -m depthcore {command[0]}: error: --workers must be a whole number from 1 to "
        f"{tasks.MAX_WORKERS}, got {value!r}\n"
    )
    assert "Traceback" not in err and "Warning" not in err and not recwarn.list
    assert time.monotonic() - start < 30


def test_study_refuses_workers_given_no_value_in_one_line(capsys):
    status, out, err = refusal(["study", "--workers", "-x"], capsys)
    assert status == 2 and out == "" and err.count("\n") == 1
    assert "argument --workers: expected one argument" in err


@pytest.mark.parametrize("value, workers", [("2", 2), (" 2", 2), ("+2 ", 2), ("064", 64)])
def test_study_reads_workers_as_a_whole_number_blanks_around_it_dropped(value, workers):
    assert cluster_options.workers(value) == workers


def test_study_help_states_the_cap_on_workers_and_the_wait_for_a_scheduler(capsys):
    with pytest.raises(SystemExit):
        main(["study", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert f"a whole number from 1 to {tasks.MAX_WORKERS} whatever the cores" in out
    wait = f"{tasks.CONNECT_TIMEOUT:g} s"
    assert f"refused unless it answers within {wait} and has a worker within {wait} more" in out
