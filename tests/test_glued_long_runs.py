"""The book's glued Monte Carlo numbers against long runs of the same cells.

Each sampled number, read from the record its page glues it from, must lie
within ``replication.AGREEMENT_Z`` combined standard errors (its own and the
long run's) of the long run's value, read from the long runs' records, which
book/beyond_study.md reads too. The comparison itself is checked to fail on a
number moved by more than that.
"""

import numpy as np
import pytest

from depthbook import beyond_bound, beyond_hard, beyond_study, intro
from depthbook.provenance import records
from depthbook.studies import hardness, replication
from depthcore import SCENARIOS
from depthcore.analysis import bound
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE

FIG2 = SCENARIOS["fig2"]


def committed(function, *args, **kwargs):
    """The result of the committed record of a call, whatever the code's fingerprint."""
    name = records.function_name(function)
    path = records.record_path(name, records.call_key(name, args, kwargs))
    assert path.is_file(), f"no committed record of {name}{args}: run the page that reads it"
    return records.decode(records.read(path)["result"])


def referee():
    return committed(replication.referee_cells, **beyond_study.REFEREE_CELLS)


def hard_long_run():
    return committed(replication.fixed_truth_replicates, FIG2.c, FIG2.rho, **beyond_hard.LONG_RUN)


def bound_page_ratios():
    """The exact filter's RMSE over the bound at each N, as the bound page glues it."""
    s = intro.BOUND_STUDY
    result = committed(
        beyond_bound.bound_study,
        intro.BOUND_FRAMES,
        s["trials"],
        s["seed"],
        s["names"],
        "paper",
        0.0,
        particle_trials=s["particle_trials"],
        n_particles=s["n_particles"],
    )
    b = bound.posterior_bound(
        FIG2.c, 3, int(intro.BOUND_FRAMES[-1]), FIG2.rho, PAPER_PRIOR_SCALE * np.eye(3)
    )
    bound_sd = np.sqrt(b[intro.BOUND_FRAMES - 1, 1, 1])
    o = result["optimal"]
    return bound.against_bound(o["depth_error"], o["depth_sd"], bound_sd), bound_sd


def hard_page_cells():
    """The hard chapter's cell at Figure 2's truth, the paper's prior, in each record."""
    cells = []
    for path in records.committed():
        record = records.read(path)
        if record["function"] != records.function_name(hardness.hard_study):
            continue
        for cell in records.decode(record["result"]):
            scale = float(np.asarray(cell["prior_cov"])[0, 0])
            if (
                np.allclose(cell["truth"], FIG2.c)
                and scale == PAPER_PRIOR_SCALE
                and cell["prior_mean"][2] == 0.0
                and cell["frames"] == 3
            ):
                cells.append(cell["fixed"]["filters"]["optimal"])
    assert cells, "no record of the hard chapter's study holds Figure 2's truth"
    return cells


@pytest.mark.parametrize("n_frames", [3, 30])
def test_the_exact_filters_rmse_over_the_bound(n_frames):
    ratios, bound_sd = bound_page_ratios()
    i = int(np.flatnonzero(intro.BOUND_FRAMES == n_frames)[0])
    long = referee()[n_frames]["pooled"]["optimal"]["rmse"]
    check = replication.agreement(
        ratios["rmse_ratio"][i],
        ratios["rmse_ratio_se"][i],
        long["value"] / bound_sd[i],
        long["se"] / bound_sd[i],
    )
    assert check["agrees"], check


@pytest.mark.parametrize("score", ["rmse", "coverage_68"])
def test_the_hard_chapters_exact_filter_at_figure_2s_truth(score):
    long = hard_long_run()["pooled"][score]
    for glued in hard_page_cells():
        check = replication.agreement(glued[score], glued[f"{score}_se"], long["value"], long["se"])
        assert check["agrees"], (glued["trials"], check)


def test_the_long_runs_are_long():
    """Each long run's error at most a third of the glued number's it is set against."""
    ratios, bound_sd = bound_page_ratios()
    for i, n in enumerate(intro.BOUND_FRAMES):
        if n in beyond_study.REFEREE_CELLS["frames"]:
            long = referee()[int(n)]["pooled"]["optimal"]["rmse"]
            assert long["se"] / bound_sd[i] < ratios["rmse_ratio_se"][i] / 3
    long = hard_long_run()["pooled"]
    for glued in hard_page_cells():
        assert long["rmse"]["se"] < glued["rmse_se"] / 3


@pytest.mark.parametrize("shift", [3.2, -3.2])
def test_the_comparison_fails_a_number_beyond_its_errors(shift):
    """A number moved by 3.2 combined SEs from the long run's fails; one at 2.9 passes."""
    se, long_se = 0.05, 0.02
    combined = np.hypot(se, long_se)
    assert not replication.agreement(1.0 + shift * combined, se, 1.0, long_se)["agrees"]
    assert replication.agreement(1.0 + np.sign(shift) * 2.9 * combined, se, 1.0, long_se)["agrees"]
    ratios, bound_sd = bound_page_ratios()  # and a glued number of the book, perturbed
    long = referee()[30]["pooled"]["optimal"]["rmse"]
    r_se = ratios["rmse_ratio_se"][-1]
    moved = long["value"] / bound_sd[-1] + shift * np.hypot(r_se, long["se"] / bound_sd[-1])
    assert not replication.agreement(
        moved, r_se, long["value"] / bound_sd[-1], long["se"] / bound_sd[-1]
    )["agrees"]


def test_agreement_refusals():
    with pytest.raises(ValueError, match="se"):
        replication.agreement(1.0, 0.0, 1.0, 0.0)
    with pytest.raises(ValueError, match="se"):
        replication.agreement(1.0, -0.1, 1.0, 0.1)
