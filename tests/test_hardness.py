"""Where the problem is hard (depthbook.studies.hardness): the bearings' second difference
against its closed form, the bound where it vanishes, the scores against direct
computation, and the exact posterior's calibration over its prior (Talts et al. 2018)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.stats import binom

from depthbook import beyond_hard
from depthbook.formatting import value_se
from depthbook.studies import hardness
from depthcore import SCENARIOS
from depthcore.analysis import bound
from depthcore.problem import model
from depthcore.registry.filters import FILTERS
from depthcore.studies import scores

FIG2 = SCENARIOS["fig2"]
RHO = FIG2.rho


def test_second_difference_is_its_closed_form():
    # b(t) = v + (x - v y) / (y + t), t = -2, -1, 0: 2 (x - v y) / (y (y - 1) (y - 2))
    rng = np.random.default_rng(0)
    s = np.column_stack([rng.normal(0, 3, 50), rng.uniform(2.5, 40, 50), rng.normal(0, 2, 50)])
    x, y, v = s.T
    assert_allclose(
        hardness.second_difference(s), 2 * (x - v * y) / (y * (y - 1) * (y - 2)), rtol=1e-9
    )
    # the paper's c and the point with no lateral motion
    assert hardness.second_difference(FIG2.c) / RHO == pytest.approx(-20.0, rel=0.05)
    assert hardness.second_difference([1.2, 6.0, 0.0]) == pytest.approx(2 * 1.2 / 120)


def test_second_difference_vanishes_on_a_ray_and_refuses_points_behind():
    assert hardness.second_difference([1.2, 6.0, 0.2]) == pytest.approx(0.0, abs=1e-15)
    # every state (v y', y', v) gives the same bearings: constant, equal to v
    for depth in (3.0, 6.0, 30.0):
        track = [model.G([0.2 * depth, depth, 0.2], k) for k in (-2, -1, 0)]
        assert_allclose(model.project(np.array(track)), 0.2, rtol=1e-12)
    with pytest.raises(ValueError, match="depth > 2"):
        hardness.second_difference([1.0, 1.5, 0.0])
    with pytest.raises(ValueError, match="shape"):
        hardness.second_difference([1.0, 6.0])


def test_bound_where_the_second_difference_vanishes_is_the_priors():
    # The bearings carry no information along (v, 1, 0): without a prior the bound
    # is refused; with the prior s I the depth variance grows in proportion to s.
    truth = np.array([1.2, 6.0, 0.2])
    with pytest.raises(ValueError, match="singular"):
        bound.posterior_bound(truth, 3, 3, RHO)
    var = [bound.posterior_bound(truth, 3, 3, RHO, s * np.eye(3))[-1, 1, 1] for s in (1e2, 1e4)]
    assert var[1] / var[0] == pytest.approx(100.0, rel=0.01)
    # where it does not vanish the prior's share vanishes as s grows
    no_prior = bound.posterior_bound(FIG2.c, 3, 3, RHO)[-1, 1, 1]
    broad = bound.posterior_bound(FIG2.c, 3, 3, RHO, 1e8 * np.eye(3))[-1, 1, 1]
    assert broad == pytest.approx(no_prior, rel=1e-5)


def test_prior_for_is_the_papers_rule_at_the_truth():
    m, P = hardness.prior_for(FIG2.c, 10.0)
    assert_allclose(m, [FIG2.c[0] - 2 * FIG2.c[2], FIG2.c[1] - 2, 0.0])
    assert_allclose(P, 10.0 * np.eye(3))
    m, _ = hardness.prior_for(FIG2.c, 10.0, prior_velocity=1.2)
    assert_allclose(m, model.G(FIG2.c, -2))
    with pytest.raises(ValueError, match="prior_scale"):
        hardness.prior_for(FIG2.c, 0.0)


def test_depth_scores_against_direct_computation():
    rng = np.random.default_rng(1)
    e, s = rng.normal(0.1, 1.0, 400), rng.uniform(0.5, 1.5, 400)
    pit = rng.uniform(0, 1, 400)
    r = hardness.depth_scores(e, s, pit)
    assert r["rmse"] == pytest.approx(np.sqrt(np.mean(e**2)))
    assert r["bias"] == pytest.approx(np.mean(e))
    assert r["bias_se"] == pytest.approx(np.std(e, ddof=1) / 20)
    assert r["mean_sd"] == pytest.approx(np.mean(s))
    c = np.mean(np.abs(pit - 0.5) <= 0.34)
    assert r["coverage_68"] == pytest.approx(c)
    assert r["coverage_68_se"] == scores.proportion_se(round(c * 400), 400)
    assert r["trials"] == 400
    with pytest.raises(ValueError, match="pit"):
        hardness.depth_scores(e, s, pit[:-1])


def test_depth_estimates_isolate_the_trials_a_filter_cannot_answer():
    # Truths from the broad prior: the EKF has no answer for some of their bearings.
    from depthcore.analysis import calibration

    pm, pc = hardness.prior_for(FIG2.c, 1000.0)
    d = calibration.draw_from_prior(pm, pc, RHO, 40, np.random.default_rng(3))
    m, s, cdf = hardness.depth_estimates("ekf", d.mu, RHO, pm, pc, d.truth[:, 1])
    failed = ~np.isfinite(m)
    assert 0 < failed.sum() < len(m)
    for i in range(len(m)):
        if failed[i]:
            with pytest.raises(ValueError):
                FILTERS["ekf"](d.mu[i : i + 1], RHO, pm, pc)
        else:
            alone = FILTERS["ekf"](d.mu[i : i + 1], RHO, pm, pc)
            assert m[i] == pytest.approx(float(np.ravel(alone.depth_mean)[0]), rel=1e-10)
    with pytest.raises(ValueError, match="not the exact filter"):
        hardness.depth_estimates("particle", d.mu, RHO, pm, pc, d.truth[:, 1])


@pytest.fixture(scope="module")
def cell():
    return hardness.hard_cell(FIG2.c, RHO, 1.0, 0.0, 600, 7, ("optimal", "second_order", "ekf"))


def test_hard_cell_exact_posterior_is_calibrated_over_its_prior(cell):
    # Simulation-based calibration: over truths drawn from the prior the exact
    # posterior's central intervals cover at their nominal rates, within 3 SE.
    s = cell["prior"]["filters"]["optimal"]
    for p in (0.68, 0.95):
        se = scores.coverage_se(p, s["trials"])
        assert abs(s[f"coverage_{round(100 * p)}"] - p) < 3 * se
    assert hardness.verdicts(cell, "prior")["calibrated_68"]["optimal"]


def test_hard_cell_reports_the_bound_and_the_second_difference(cell):
    pc = 1.0 * np.eye(3)
    assert cell["bound_sd"] == pytest.approx(
        np.sqrt(bound.posterior_bound(FIG2.c, 3, 3, RHO, pc)[-1, 1, 1])
    )
    assert cell["second_difference"] == pytest.approx(hardness.second_difference(FIG2.c) / RHO)
    assert cell["fixed"]["valid"] <= 600 and cell["prior"]["valid"] <= 600
    for reading in hardness.READINGS:
        assert set(cell[reading]["filters"]) == {"optimal", "second_order", "ekf"}
        assert cell[reading]["filters"]["optimal"]["failed"] == 0


def constructed_cell(bound_sd):
    """A cell of 400 trials, every filter's depth error a multiple of one shared error ``e``.

    The optimal filter errs by ``e`` and states SD 1 (68 % coverage 0.68); the
    second-order filter by ``2 e`` with SD 2.6 (coverage 0.80), the EKF by
    ``1.5 e`` with SD 0.3 (coverage 0.16): RMSEs 1, 2 and 1.5.
    """
    from scipy.special import ndtr

    rng = np.random.default_rng(11)
    e = rng.standard_normal(400)
    depth = np.full(400, 6.0)
    estimates = {
        name: (depth + k * e, np.full(400, sd), ndtr(-k * e / sd))
        for name, k, sd in (("optimal", 1.0, 1.0), ("second_order", 2.0, 2.6), ("ekf", 1.5, 0.3))
    }
    reading = {
        "filters": hardness.score_estimates(estimates, depth),
        "paired": hardness.paired_scores(estimates, depth),
    }
    return {"fixed": reading, "prior": reading, "bound_sd": bound_sd}


def test_verdicts_read_the_coverages_and_test_the_paired_differences():
    cell = constructed_cell(bound_sd=2.0)
    f = cell["fixed"]["filters"]
    assert f["second_order"]["coverage_68"] == pytest.approx(0.80, abs=0.05)
    assert f["ekf"]["coverage_68"] == pytest.approx(0.16, abs=0.05)
    v = hardness.verdicts(cell, "fixed")
    assert v["calibrated_68"] == {"optimal": True, "second_order": False, "ekf": False}
    assert not v["calibrated_95"]["ekf"]
    # p_s's coverage significantly nearer nominal; its RMSE (2) significantly above the EKF's (1.5)
    assert v["so_nearer_68"] == 1 and v["so_rmse"] == -1
    # a log-ratio of proportional errors is exact: SE 0 but for rounding
    assert v["so_rmse_se"] < 1e-6
    assert v["po_best"] == 1  # RMSE 1 against 2 and 1.5
    assert v["ekf_below"] == 1  # 1.5 +- 0.05 below 2
    assert "ekf_below" not in hardness.verdicts(cell, "prior")
    near = hardness.verdicts(constructed_cell(bound_sd=f["ekf"]["rmse"]), "fixed")
    assert near["ekf_below"] == 0 and near["ekf_below_se"] == f["ekf"]["rmse_se"]
    above = hardness.verdicts(constructed_cell(bound_sd=1.0), "fixed")
    assert above["ekf_below"] == -1
    d = hardness.paired_comparison(cell, "fixed", "ekf", "second_order")
    assert d["rmse_ratio"] == pytest.approx(0.75, rel=1e-12)
    assert d["coverage_68_gap"] == pytest.approx(
        abs(f["ekf"]["coverage_68"] - 0.68) - abs(f["second_order"]["coverage_68"] - 0.68)
    )
    with pytest.raises(ValueError, match="reading"):
        hardness.verdicts(cell, "truth")
    with pytest.raises(ValueError, match="itself"):
        hardness.paired_comparison(cell, "fixed", "ekf", "ekf")


def test_a_pair_is_compared_over_the_trials_both_filters_answer():
    cell = hardness.hard_cell(FIG2.c, RHO, 1000.0, 0.0, 60, 3, ("optimal", "second_order", "ekf"))
    for reading in hardness.READINGS:
        f = cell[reading]["filters"]
        failed = f["ekf"]["failed"]
        pair = cell[reading]["paired"][("second_order", "ekf")]
        assert pair["trials"] == cell[reading]["valid"] - failed
        if failed == 0:
            d = hardness.paired_comparison(cell, reading, "second_order", "ekf")
            assert d["rmse_ratio"] == pytest.approx(
                f["second_order"]["rmse"] / f["ekf"]["rmse"], rel=1e-12
            )


def test_hard_study_texts_and_figure():
    cells = hardness.hard_study(
        [(FIG2.c, 1.0, 0.0), (FIG2.c, 10.0, 0.0)], RHO, 8, 1, ("optimal", "ekf")
    )
    assert beyond_hard.hard_label(cells[0]) == "(1.2, 6, 1.2); 1 I; v₀ = 0"
    # the extremes the prose names: the cell, and its score with its standard error
    cov = [c["prior"]["filters"]["ekf"]["coverage_68"] for c in cells]
    i, text = beyond_hard.extreme_text(cells, "prior", "ekf", "coverage_68", "max")
    ekf = cells[i]["prior"]["filters"]["ekf"]
    assert i == int(np.argmax(cov)) and text == value_se(
        ekf["coverage_68"], ekf["coverage_68_se"], 2
    )
    j, text = beyond_hard.extreme_text(cells, "prior", "ekf", "coverage_68", "max", [False, True])
    assert j == 1 and text == beyond_hard.score_text(
        cells[1]["prior"]["filters"]["ekf"], "coverage_68"
    )
    po = cells[0]["fixed"]["filters"]["optimal"]
    places = max(0, 2 - int(np.floor(np.log10(po["rmse"]))))
    assert beyond_hard.score_text(po, "rmse") == value_se(po["rmse"], po["rmse_se"], places)
    with pytest.raises(ValueError, match="which"):
        beyond_hard.extreme_text(cells, "prior", "ekf", "coverage_68", "median")
    with pytest.raises(ValueError, match="where"):
        beyond_hard.extreme_text(cells, "prior", "ekf", "coverage_68", "min", [False, False])
    # each setting named by its departure from a reference truth and prior
    assert beyond_hard.setting_label(cells[0], FIG2.c, 1.0) == "reference"
    assert beyond_hard.setting_label(cells[0], FIG2.c, 1.0, "c") == "c"
    assert beyond_hard.setting_label(cells[1], FIG2.c, 1.0) == "$s = 10$"
    far = dict(cells[0], truth=4 * np.asarray(FIG2.c))
    assert beyond_hard.setting_label(far, FIG2.c, 1.0) == "$y = 24$"
    slow = dict(cells[0], truth=np.array([1.2, 6.0, 0.0]))
    assert beyond_hard.setting_label(slow, FIG2.c, 10.0) == "$v = 0$\n$s = 1$"
    # the verdicts counted per filter, reading and level: those of hardness.verdicts
    v = beyond_hard.verdict_texts(cells, "h")
    for reading in hardness.READINGS:
        for name in ("optimal", "ekf"):
            expected = sum(hardness.verdicts(c, reading)["calibrated_68"][name] for c in cells)
            assert v[f"h_{name}_{reading}_68"] == str(expected)
    assert len(v) == 2 * 2 * 2
    fig = beyond_hard.hard_figure(cells, ["a", "b"])
    assert len(fig.axes) == 4
    # over the prior the exact posterior's RMSE is its own reference: 1, and the others
    # the paired ratios
    ys = fig.axes[1].lines
    assert any(np.allclose(line.get_ydata(), 1.0) for line in ys)
    with pytest.raises(ValueError, match="labels"):
        beyond_hard.hard_figure(cells, ["a"])
    with pytest.raises(ValueError, match="cells"):
        hardness.hard_study([], RHO, 8, 1)


def test_hard_cell_beyond_three_frames_scores_the_depth_at_frame_n():
    # The exact N-frame filter (the bank) over truths drawn from its prior: calibrated;
    # the bound is the posterior bound at frame N.
    cell = hardness.hard_cell([1.2, 6.0, 0.0], RHO, 10.0, 0.0, 400, 4, ("optimal",), 10)
    assert cell["frames"] == 10
    pc = 10.0 * np.eye(3)
    b = bound.posterior_bound([1.2, 6.0, 0.0], 3, 10, RHO, pc)[-1, 1, 1]
    assert cell["bound_sd"] == pytest.approx(np.sqrt(b))
    s = cell["prior"]["filters"]["optimal"]
    for p in (0.68, 0.95):
        assert abs(s[f"coverage_{round(100 * p)}"] - p) < 3 * scores.coverage_se(p, s["trials"])
    # at the fixed truth the point has moved on to depth 6 + 7 = 13 (Eq. (1))
    e = cell["fixed"]["filters"]["optimal"]
    assert abs(e["bias"]) < 13.0 and e["failed"] == 0
    with pytest.raises(ValueError, match="frames"):
        hardness.hard_cell(FIG2.c, RHO, 1.0, 0.0, 4, 1, ("optimal",), 2)


def test_outcome_counts_count_wins_ties_and_losses():
    assert beyond_hard.outcome_counts([1, 0, -1, 1, 1]) == (3, 1, 1)
    assert beyond_hard.outcome_counts(np.zeros((2, 3), dtype=int)) == (0, 6, 0)
    with pytest.raises(ValueError, match="outcomes"):
        beyond_hard.outcome_counts([1, 2])


def test_median_text_states_the_median_and_its_distribution_free_interval():
    e = np.arange(1.0, 102.0)  # 101 absolute errors, median 51
    s = hardness.depth_scores(e, np.ones(101), np.full(101, 0.5))
    # the order statistics j < k with P(j <= B < k) >= 0.95, B ~ Binomial(101, 1/2)
    j, k = 41, 61
    assert binom.cdf(k - 1, 101, 0.5) - binom.cdf(j - 1, 101, 0.5) >= 0.95
    assert beyond_hard.median_text(s) == f"51.0 (95 % interval {j:.1f} to {k:.1f})"
    unbounded = dict(s, median_abs_error_ci=[2.0, None])
    assert beyond_hard.median_text(unbounded, 2) == "51.00 (95 % interval from 2.00)"
