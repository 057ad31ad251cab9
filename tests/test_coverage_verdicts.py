"""Coverage verdicts: equivalence tests, Benjamini-Hochberg, and the trials they need."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from depthcore.studies import atlas
from depthcore.studies import coverage_verdicts as cv


def test_the_p_values_are_the_exact_binomial_tails_against_the_band_edges():
    n, t = 1000, 0.03
    for k in (600, 650, 680, 710, 760):
        p_in = cv.equivalence_pvalue(k, n, 0.68, t)
        # TOST: the larger of P(X >= k | 0.65) and P(X <= k | 0.71), by summing the pmf
        upper = sum(binom.pmf(j, n, 0.65) for j in range(k, n + 1))
        lower = sum(binom.pmf(j, n, 0.71) for j in range(0, k + 1))
        assert p_in == pytest.approx(max(upper, lower), rel=1e-9, abs=1e-300)
        p_out = cv.outside_pvalue(k, n, 0.68, t)
        below = sum(binom.pmf(j, n, 0.65) for j in range(0, k + 1))
        above = sum(binom.pmf(j, n, 0.71) for j in range(k, n + 1))
        assert p_out == pytest.approx(min(below, above), rel=1e-9, abs=1e-300)
    # inside the band only the equivalence claim is small, far outside only the other
    assert cv.equivalence_pvalue(680, n, 0.68, t) < 0.05 < cv.outside_pvalue(680, n, 0.68, t)
    assert cv.outside_pvalue(600, n, 0.68, t) < 0.05 < cv.equivalence_pvalue(600, n, 0.68, t)


def test_benjamini_hochberg_on_a_hand_example():
    # m = 6 at 5 %: thresholds 0.0083, 0.0167, 0.025, 0.0333, 0.0417, 0.05; the largest j with
    # p_(j) <= 0.05 j / 6 is j = 4 (0.032 <= 0.0333), so the four smallest are rejected,
    # 0.026 among them though above its own threshold 0.025 (the step-up)
    p = np.array([0.045, 0.001, 0.032, 0.5, 0.026, 0.012])
    assert cv.discoveries(p, 0.05).tolist() == [False, True, True, False, True, True]
    # at 2 % only j = 1 holds: 0.012 > 0.02 * 2 / 6, 0.001 <= 0.02 / 6
    assert cv.discoveries(p, 0.02).tolist() == [False, True, False, False, False, False]
    # a hypothesis not tested (NaN) is neither rejected nor counted in m
    with_gap = cv.discoveries(np.append(p, np.nan), 0.05)
    assert with_gap.tolist() == [False, True, True, False, True, True, False]
    with pytest.raises(ValueError, match="^pvalues"):
        cv.discoveries([0.5, 1.5])


def test_verdicts_are_calibrated_inside_the_band_miscalibrated_outside_undecided_between():
    n = 7500
    coverage = np.array([0.68, 0.60, 0.67, 0.69, 0.75, 0.652])
    k = np.round(coverage * n)
    v = cv.verdicts(k, np.full(6, n), 0.68, 0.028)
    assert v == [True, False, True, True, False, None]
    # at 300 trials the same coverages near the level are undecided: the band is too narrow
    v300 = cv.verdicts(np.round(coverage * 300), np.full(6, 300), 0.68, 0.028)
    assert v300[0] is None and v300[2] is None and v300[3] is None
    assert cv.verdicts([round(0.45 * 300)], [300]) == [False]  # far off, it is found
    # a cell without trials has no verdict and does not count in the families
    assert cv.verdicts([0, 510], [0, 750])[0] is None


def test_the_false_discovery_control_changes_a_verdict():
    # one coverage just inside the band's shrunk edge is calibrated alone (p < 0.05), but
    # among many undecided cells Benjamini-Hochberg no longer lets it through
    n, t = 7500, 0.028
    k = next(k for k in range(4900, 5200) if cv.equivalence_pvalue(k, n, 0.68, t) < 0.04)
    assert cv.verdicts([k], [n], 0.68, t) == [True]
    many = cv.verdicts([k] + [round(0.652 * n)] * 9, [n] * 10, 0.68, t)
    assert many[0] is None


def test_the_trials_needed_give_the_stated_power_exactly():
    t = cv.TOLERANCE
    n = cv.trials_needed(t)
    # the binding demand: the normal approximation's n, checked by exact binomial sums
    for c in (0.68 - cv.NEAR, 0.68 + cv.NEAR):
        assert cv.power(c, n, 0.68, t)["calibrated"] >= cv.DESIGN_POWER - 0.005
    for c in (0.68 - cv.FAR, 0.68 + cv.FAR):
        assert cv.power(c, n, 0.68, t)["miscalibrated"] >= cv.DESIGN_POWER - 0.005
    # and too few trials miss it: at 80 % of n a coverage 0.046 off is found less often
    assert cv.power(0.68 - cv.FAR, int(0.8 * n), 0.68, t)["miscalibrated"] < cv.DESIGN_POWER
    # a tolerance out of balance needs more trials; the chosen one is the balanced one
    best = cv.balanced_tolerance()
    assert abs(best - t) < 0.001
    assert cv.trials_needed(0.02) > n and cv.trials_needed(0.038) > n
    # at each band edge the claims hold their size (the exact tails, at most the level)
    for edge in (0.68 - t, 0.68 + t):
        p = cv.power(edge, n, 0.68, t)
        assert p["calibrated"] <= cv.DESIGN_FALSE_ALARM
        assert p["miscalibrated"] <= cv.DESIGN_FALSE_ALARM + 1e-12
    # both atlases run what the verdicts need where they draw one, in whole chunks; a cell
    # whose truth is fixed (no calibration verdict) runs the 2,200 its error scores need
    assert atlas.TRIALS >= n and atlas.TRIALS - n < 100
    for grid in atlas.SIZES.values():
        assert grid.trials == atlas.TRIALS and grid.fixed_trials == atlas.FIXED_TRIALS == 2200
        assert grid.trials_of({"form": "range"}) == atlas.TRIALS
        assert grid.trials_of({"form": "paper"}) == atlas.FIXED_TRIALS
    with pytest.raises(ValueError, match="^tolerance"):
        cv.trials_needed(0.05)


def test_power_against_a_brute_force_sum_over_every_count():
    n, t, a = 900, 0.04, 0.025
    k = np.arange(n + 1)
    inside = cv.equivalence_pvalue(k, n, 0.68, t) <= a
    outside = cv.outside_pvalue(k, n, 0.68, t) <= a
    for c in (0.6, 0.67, 0.7, 0.74):
        p = cv.power(c, n, 0.68, t, a)
        pmf = binom.pmf(k, n, c)
        assert p["calibrated"] == pytest.approx(pmf[inside].sum(), abs=1e-12)
        assert p["miscalibrated"] == pytest.approx(pmf[outside].sum(), abs=1e-12)


def _cell(form, coverage, trials=7500):
    entry = {"trials": trials, "coverage_68": coverage, "lost": False, "near_bound": None}
    return {"form": form, "prior_scale": None, "filters": {"ekf": entry}}


def test_an_atlas_is_read_over_its_drawn_cells_alone():
    result = {
        "names": ["ekf"],
        "levels": {"calibration_reach": 0.1, "loss_level": 0.1},
        "cells": [
            _cell("paper", 0.68),
            _cell("range", 0.68),
            _cell("log_uniform", 0.5),
            _cell("inverse_depth", 0.66, trials=300),
        ],
    }
    read = cv.with_calibration(result)
    verdicts = [c["filters"]["ekf"]["calibrated"] for c in read["cells"]]
    # the paper's rule has a fixed truth: not judged, however close to 0.68
    assert verdicts == [None, True, False, None]
    levels = read["levels"]
    assert "calibration_reach" not in levels and levels["loss_level"] == 0.1
    assert levels["calibration_tolerance"] == cv.TOLERANCE
    assert levels["false_discovery_rate"] == cv.FALSE_DISCOVERY
    # a verdict read from the coverages replaces one stored, and the input is left as it was
    result["cells"][1]["filters"]["ekf"]["calibrated"] = False
    assert cv.with_calibration(result)["cells"][1]["filters"]["ekf"]["calibrated"] is True
    assert "calibration_tolerance" not in result["levels"]
