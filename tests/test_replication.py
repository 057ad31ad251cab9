"""Replicated studies: the spread across replicates, its error, pooling, and the stated errors."""

import numpy as np
import pytest

from depthbook.studies import replication
from depthcore.studies import monte_carlo


def test_spread_of_normal_replicates_and_its_error():
    """The SD's error from the fourth moment matches the SD's spread over many sets."""
    rng = np.random.default_rng(0)
    sets = rng.normal(2.0, 0.5, size=(4000, 40))
    sds = np.std(sets, axis=1, ddof=1)
    one = replication.spread(sets[0])
    assert one["actual"] == pytest.approx(np.std(sets[0], ddof=1), rel=1e-15)
    stated = np.array([replication.spread(s)["actual_se"] for s in sets[:400]])
    assert np.mean(stated) == pytest.approx(np.std(sds), rel=0.1)


def test_stated_errors_that_hold_and_that_fall_short():
    rng = np.random.default_rng(1)
    values = rng.normal(0.0, 1.0, 5000)
    right = replication.spread(values, np.full(5000, 1.0), reference=0.0)
    assert right["ratio"] == pytest.approx(1.0, abs=0.05)
    assert abs(right["held"] - 0.95) < 4 * right["held_se"]
    short = replication.spread(values, np.full(5000, 0.6), reference=0.0)
    assert short["ratio"] > 1.5 and short["held"] < 0.9
    with pytest.raises(ValueError, match="errors"):
        replication.spread(values, np.ones(3))
    with pytest.raises(ValueError, match="values"):
        replication.spread([1.0, 2.0])


def test_pooled_is_the_trial_weighted_mean_with_the_groups_spread():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([2.0, 2.5])
    na, nb = np.full(3, 10), np.full(2, 100)
    p = replication.pooled([a, b], [na, nb])
    total = 30 + 200
    assert p["value"] == pytest.approx((10 * 6 + 100 * 4.5) / total)
    var = 300 * np.var(a, ddof=1) + 20000 * np.var(b, ddof=1)
    assert p["se"] == pytest.approx(np.sqrt(var) / total)
    with pytest.raises(ValueError, match="replicates"):
        replication.pooled([a[:1]], [na[:1]])


def test_replicates_are_the_studies_of_the_seeds_children():
    r = replication.replicate(20, 3, 5, frames=30)
    seeds = np.random.SeedSequence(5).spawn(3)
    for k, s in enumerate(seeds):
        one = monte_carlo.study(trials=20, seed=s, names=("optimal",), frames=30)
        assert r["optimal"]["rmse"][k] == one["filters"]["optimal"]["depth"]["rmse"]
    assert len(set(r["optimal"]["rmse"])) == 3
    for args, match in (((1, 3, 0), "trials"), ((5, 1, 0), "replicates")):
        with pytest.raises(ValueError, match=match):
            replication.replicate(*args)


def test_referee_cells_pool_every_replicate():
    out = replication.referee_cells([30], [(10, 4), (20, 4)], 2)[30]
    runs = [out["blocks"][t]["replicates"] for t in (10, 20)]
    mse = np.concatenate([r["optimal"]["rmse"] ** 2 * r["valid"] for r in runs])
    n = np.concatenate([r["valid"] for r in runs])
    assert out["pooled"]["optimal"]["mse"]["value"] == pytest.approx(mse.sum() / n.sum())
    assert set(out["blocks"][10]["optimal"]) == {
        "rmse",
        "coverage_68",
        "median_abs_error",
        "median_held",
    }


def test_fixed_truth_replicates_pool_the_hard_cells_scores():
    from depthcore import SCENARIOS

    fig2 = SCENARIOS["fig2"]
    out = replication.fixed_truth_replicates(fig2.c, fig2.rho, 1000.0, 0.0, 30, 3, 4)
    assert out["valid"].shape == (3,) and out["bound_sd"] > 0
    mse = np.sum(out["rmse"] ** 2 * out["valid"]) / out["valid"].sum()
    assert out["pooled"]["rmse"]["value"] == pytest.approx(np.sqrt(mse))
