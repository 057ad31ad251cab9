"""estimate's --prior-depth in its forms: a law of the depth the exact filter takes as it is."""

import numpy as np
import pytest

import depthcore
from depthcore.problem import depth_prior as dp
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE

from helpers import cli_json, cli_refused

RHO = 0.005
K = np.arange(12)
MU = (4.0 + 0.3 * K) / (20.0 + K) + RHO * np.random.default_rng(3).standard_normal(12)
LATERAL = dp.Lateral([0.0, 0.0], [MU[0], 0.0], PAPER_PRIOR_SCALE * np.eye(2), np.zeros((2, 2)))
TABLE = "depth,density\n5,0\n10,1\n20,2\n40,0.5\n60,0\n"


def _laws(table_path):
    return {
        ("log-uniform", "6", "60"): dp.log_uniform(6.0, 60.0, LATERAL),
        ("range", "20", "6", "2"): dp.range_prior(20.0, 6.0, LATERAL, 2.0),
        ("inverse-depth", "0.05", "0.025", "0.005", "0.5"): dp.inverse_depth(
            0.05, 0.025, 0.005, 0.5, LATERAL
        ),
        ("table", table_path): dp.table([5, 10, 20, 40, 60], [0, 1, 2, 0.5, 0], LATERAL),
    }


def _argv(*more):
    mu = ["--mu", *(repr(float(v)) for v in MU)]
    return ["estimate", *mu, "--rho", str(RHO), "--filters", "optimal", "ekf", *more]


def test_each_law_reaches_the_exact_filter_and_its_gaussian_the_others(tmp_path, capsys):
    path = tmp_path / "law.csv"
    path.write_text(TABLE, encoding="utf-8")
    for args, law in _laws(str(path)).items():
        out = cli_json(_argv("--prior-depth", *args), capsys)
        assert out["prior_depth"]["form"] == law.form
        assert np.allclose(out["prior_mean"], law.mean) and np.allclose(out["prior_cov"], law.cov)
        exact = depthcore.track(MU, RHO, prior=law).filtered
        got = out["filters"]["optimal"]["depth"]
        assert abs(got["mean"] - exact.depth_mean[-1]) <= 1e-8 * exact.depth_sd[-1], args
        ekf = depthcore.track(MU, RHO, prior=depthcore.Gaussian(law.mean, law.cov), filter="ekf")
        assert out["filters"]["ekf"]["depth"]["mean"] == pytest.approx(
            ekf.filtered.depth_mean[-1], rel=1e-12
        )


def test_a_law_per_frame_and_learning_under_it(capsys):
    law = dp.log_uniform(6.0, 60.0, LATERAL)
    out = cli_json(_argv("--per-frame", "--prior-depth", "log-uniform", "6", "60"), capsys)
    rows = out["filters"]["optimal"]
    t = depthcore.track(MU, RHO, prior=law)
    assert np.allclose([r["smoothed_depth_mean"] for r in rows], t.smoothed.depth_mean, rtol=1e-9)
    learned = cli_json(
        [
            "estimate",
            "--mu",
            *(repr(float(v)) for v in MU),
            "--learn-noise",
            "--process-noise",
            "0",
            "--filters",
            "optimal",
            "--prior-depth",
            "log-uniform",
            "6",
            "60",
        ],
        capsys,
    )
    fit = depthcore.exact.learning.fit(MU, None, None, process_noise=0.0, law=law)
    assert learned["learned"]["rho"] == pytest.approx(fit.rho, rel=1e-6)


@pytest.mark.parametrize(
    "args, words",
    [
        (["log-uniform", "6"], ["log-uniform LO HI", "1 value"]),
        (["foo", "1", "2"], ["law named", "'foo'"]),
        (["log-uniform", "60", "6"], ["hi must exceed lo"]),
        (["inverse-depth", "0.05", "0.02", "0", "0.5"], ["lo must be positive"]),
        (["range", "a", "b"], ["as numbers"]),
        (["log-uniform", "6", "inf"], ["finite"]),
        (["table", "/nonexistent/law.csv"], ["cannot read"]),
        (["table", "a", "b"], ["table FILE"]),
        (["20"], ["MEAN SD"]),
    ],
)
def test_a_meaningless_law_is_refused_in_one_line(args, words, capsys):
    cli_refused(_argv("--prior-depth", *args), capsys, "--prior-depth", *words)


def test_a_law_with_a_prior_mean_or_for_pairs_is_refused(capsys):
    cli_refused(
        _argv("--prior-depth", "log-uniform", "6", "60", "--prior-mean", "0", "20", "0"),
        capsys,
        "--prior-depth",
    )
    pairs = ["--nu", *(repr(0.01 * float(v)) for v in MU)]
    cli_refused(_argv(*pairs, "--prior-depth", "log-uniform", "6", "60"), capsys, "pairs")
