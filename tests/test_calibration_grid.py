"""Simulation-based calibration over frames, q and rho: depthbook.studies.calibration_grid.

The settings' combinations, the study's streams (one per setting, the same for the same
seed), its coverages against the transforms it computes, and the verdicts, which must
fail a coverage off its level and transforms that are not uniform.
"""

from __future__ import annotations

import numpy as np
import pytest

from depthbook.studies import calibration_grid
from depthcore.analysis import calibration


def test_factorial_makes_every_combination_in_order():
    s = calibration_grid.factorial([3, 10], [0.0, 0.02], [0.005, 0.0005])
    assert len(s) == 8 and s[0] == (3, 0.0, 0.005) and s[1] == (3, 0.0, 0.0005)
    assert s[-1] == (10, 0.02, 0.0005) and len(set(s)) == 8
    with pytest.raises(ValueError, match="^frames, process_noises, rhos"):
        calibration_grid.factorial([], [0.0], [0.005])
    with pytest.raises(ValueError, match="^rhos must be positive"):
        calibration_grid.factorial([3], [0.0], [0.0])


def test_each_setting_draws_its_own_stream_and_reports_its_coverages():
    settings = [(3, 0.0, 0.005), (10, 0.02, 0.0005), (3, 0.0, 0.005)]
    runs = calibration_grid.calibration_grid(settings, 40, 11)
    again = calibration_grid.calibration_grid(settings[:1], 40, 11)
    assert [(r["frames"], r["process_noise"], r["rho"]) for r in runs] == settings
    assert runs[0] == again[0]  # the same seed, the same first setting: the same study
    assert runs[0]["depth"] != runs[2]["depth"]  # the same setting, its own stream
    for r in runs:
        assert 0 < r["valid_trials"] <= 40 and r["levels"] == list(calibration_grid.TESTED_LEVELS)
        for q in ("depth", "velocity"):
            c = np.asarray(r[q]["coverage"])
            assert c.shape == (2,) and np.all((0 <= c) & (c <= 1)) and c[0] <= c[1]
            assert 0 <= r[q]["ks_pvalue"] <= 1 and 0 <= r[q]["chi2_pvalue"] <= 1
    with pytest.raises(ValueError, match="^settings must not be empty"):
        calibration_grid.calibration_grid([], 40, 11)
    with pytest.raises(ValueError, match="^trials must be at least 2"):
        calibration_grid.calibration_grid(settings, 1, 11)


def _result(pit):
    """A setting's result from given transforms, as calibration_grid builds it."""
    out = {"valid_trials": len(pit), "levels": list(calibration_grid.TESTED_LEVELS)}
    for q in ("depth", "velocity"):
        tests = calibration.uniformity(pit)
        tests.pop("counts")
        out[q] = {"coverage": calibration.coverage(pit, calibration_grid.TESTED_LEVELS).tolist()}
        out[q].update(tests)
    return out


def test_the_verdicts_pass_uniform_transforms_and_fail_those_of_a_filter_too_narrow():
    rng = np.random.default_rng(3)
    ok = calibration_grid.coverage_verdicts(_result(rng.uniform(size=2200)))
    assert ok["passes_68"] and ok["passes_95"] and ok["uniform"] and ok["velocity_uniform"]
    assert ok["trials"] == 2200 and 0 < ok["coverage_68_se"] < 0.011
    # the negative control: a posterior with SDs two thirds of the truth's, its transforms
    # Phi(1.5 z), crowd the ends: the coverages fall below their levels and fail
    from scipy.special import ndtr

    narrow = ndtr(1.5 * rng.standard_normal(2200))
    bad = calibration_grid.coverage_verdicts(_result(narrow))
    assert not bad["passes_68"] and not bad["passes_95"] and not bad["uniform"]
    assert bad["coverage_68"] < 0.68 - 0.1


def test_law_calibration_draws_each_laws_truths_and_runs_the_exact_filter_under_it():
    out = calibration_grid.law_calibration(("log_uniform", "inverse_depth"), (3, 10), 40, 5, 0.005)
    assert [(r["form"], r["frames"]) for r in out] == [
        ("log_uniform", 3),
        ("log_uniform", 10),
        ("inverse_depth", 3),
        ("inverse_depth", 10),
    ]
    again = calibration_grid.law_calibration(("log_uniform",), (3,), 40, 5, 0.005)
    assert again[0] == out[0]  # setting k draws from the seed's child k
    for r in out:
        assert r["valid_trials"] + r["rejected_trials"] == 40
        assert len(r["depth"]["coverage"]) == len(calibration_grid.TESTED_LEVELS)
    with pytest.raises(ValueError, match="forms, frames"):
        calibration_grid.law_calibration((), (3,), 40, 5, 0.005)
