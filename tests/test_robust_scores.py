"""The scores beside the RMSE: median absolute error, divergent trials, ANEES and its region."""

import numpy as np
import pytest
from scipy import stats

from depthbook.studies import hardness
from depthcore.studies import medians, scores
from depthcore.studies.trials import Estimates

TRUTH = np.array([1.2, 6.0, 1.2])


def heavy_estimates(n, rng, scale=1.0):
    """Estimates with Student-t (3 degrees of freedom) errors and unit covariance."""
    err = scale * rng.standard_t(3, size=(n, 3))
    cov = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    mean = TRUTH + err
    cdf = stats.norm.cdf(-err[:, 1:])
    return Estimates(mean, cov, cdf[:, 0], cdf[:, 1], None)


def split(est, sizes):
    """The chunks of ``est`` of the given sizes, in order."""
    edges = np.cumsum([0, *sizes])
    return [
        Estimates(*(f[a:b] for f in (est.mean, est.cov, est.depth_cdf, est.velocity_cdf)), None)
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    ]


@pytest.mark.parametrize("n", [1, 2, 7, 150, 2001])
def test_median_ranks_are_the_widest_binomial_ones_at_95(n):
    j, k = medians.median_ranks(n)
    assert k == n + 1 - j
    miss = 2 * stats.binom.cdf(j - 1, n, 0.5) if j else 0.0
    assert 1 - miss >= 0.95
    if j:  # one rank further in would fall short of 95 %
        assert 1 - 2 * stats.binom.cdf(j, n, 0.5) < 0.95
    else:
        assert 1 - 2 * stats.binom.cdf(0, n, 0.5) < 0.95


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sizes", [[1000], [1, 999], [100] * 10, [7, 300, 13, 680]])
def test_histogram_median_against_numpy_and_order_statistics(seed, sizes):
    """Cauchy-tailed absolute errors over eight decades, in several chunkings."""
    rng = np.random.default_rng(seed)
    values = np.abs(rng.standard_cauchy(sum(sizes))) * 10.0 ** rng.integers(-3, 4)
    h = medians.AbsoluteErrors()
    edges = np.cumsum([0, *sizes])
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        h.add(values[a:b])
    median, (lo, hi) = h.median()
    r = medians.MEDIAN_RESOLUTION
    assert median == pytest.approx(np.median(values), rel=r)
    v = np.sort(values)
    j, k = medians.median_ranks(len(v))
    eps = 1e-12  # the bins' edges are computed in floating point
    assert lo <= v[j - 1] * (1 + eps) and v[j - 1] <= lo * (1 + r) * (1 + eps)
    assert hi >= v[k - 1] * (1 - eps) and v[k - 1] >= hi / (1 + r) * (1 - eps)
    one = medians.AbsoluteErrors()
    one.add(values)
    assert np.array_equal(one.counts, h.counts)  # any chunking: the same counts


def test_histogram_ends_and_memory():
    h = medians.AbsoluteErrors()
    size = h.counts.nbytes
    h.add(np.array([0.0, 1e-9, np.nan, np.inf, 1e9]))
    assert h.counts[0] == 2 and h.counts[-1] == 3 and h.counts.nbytes == size
    median, ci = h.median()
    assert median is None and ci == [0.0, None]  # five trials: no 95 % interval
    with pytest.raises(ValueError, match="trials"):
        medians.AbsoluteErrors().median()


def test_median_interval_covers_at_its_level():
    """Over 4,000 samples of 40 Cauchy errors the interval holds the true median 1 in >= 95 %."""
    rng = np.random.default_rng(5)
    held = [
        lo <= 1.0 <= hi
        for lo, hi in (
            medians.median_interval(np.abs(rng.standard_cauchy(40)))[1] for _ in range(4000)
        )
    ]
    assert np.mean(held) > 0.95 - 4 * np.sqrt(0.05 * 0.95 / 4000)


def test_tally_robust_scores_against_direct_sums():
    rng = np.random.default_rng(11)
    est = heavy_estimates(3000, rng, scale=2.0)
    tally = scores.Tally(TRUTH)
    for part in split(est, [1000, 1, 1999]):
        tally.add(part)
    out = tally.scores()
    err = est.mean - TRUTH
    depth_err = err[:, 1]
    bad = np.abs(depth_err) > scores.DIVERGENCE * TRUTH[1]
    assert out["divergent"]["count"] == int(bad.sum()) > 0
    assert out["divergent"]["threshold"] == scores.DIVERGENCE
    p = bad.mean()
    assert out["divergent"]["fraction"] == p
    assert out["divergent"]["se"] == pytest.approx(np.sqrt(p * (1 - p) / 3000))
    assert stats.binom.cdf(bad.sum(), 3000, out["divergent"]["upper"]) == pytest.approx(0.05)
    for k, q in enumerate(("depth", "velocity")):
        e = err[~bad, k + 1]
        rmse = np.sqrt(np.mean(e**2))
        assert out[q]["rmse_kept"] == pytest.approx(rmse, rel=1e-12)
        se = np.std(e**2, ddof=1) / np.sqrt(len(e)) / (2 * rmse)
        assert out[q]["rmse_kept_se"] == pytest.approx(se, rel=1e-10)
        median, ci = medians.median_interval(np.abs(err[:, k + 1]))
        assert out[q]["median_abs_error"] == pytest.approx(median, rel=medians.MEDIAN_RESOLUTION)
        assert ci[0] <= out[q]["median_abs_error_ci"][0] * (1 + medians.MEDIAN_RESOLUTION)
    position = np.hypot(err[:, 0], err[:, 1])
    for t in scores.TRACK_LOSS_LEVELS:
        lost = position > t * np.hypot(TRUTH[0], TRUTH[1])
        level = out["track_loss_levels"][f"{t:g}"]
        assert level["lost"] == int(lost.sum()) and level["fraction"] == lost.mean()
        assert level["rmse_kept"] == pytest.approx(np.sqrt(np.mean(depth_err[~lost] ** 2)))
    assert out["track_loss_levels"]["0.5"]["fraction"] == out["track_loss"]["fraction"]
    nees = np.sum(err**2, axis=1)
    a = out["anees"]
    assert a["value"] == out["nees"] and a["se"] == out["nees_se"] and a["dim"] == 3
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3)
    assert a["outside"] == np.mean((nees < lo) | (nees > hi))
    assert a["region"] == list(scores.anees_region(3000))


def test_tally_keeps_nothing_that_grows():
    rng = np.random.default_rng(1)
    tally = scores.Tally(TRUTH)
    tally.add(heavy_estimates(10, rng))
    sizes = [h.counts.nbytes for h in tally.absolute]
    tally.add(heavy_estimates(5000, rng))
    assert [h.counts.nbytes for h in tally.absolute] == sizes


def test_divergent_rule():
    depth = np.array([6.0, 12.0, 12.01, -0.1, np.nan])
    assert scores.divergent(depth, np.full(5, 6.0)).tolist() == [False, False, True, True, True]
    with pytest.raises(ValueError, match="threshold"):
        scores.divergent(depth, depth, threshold=-1.0)


@pytest.mark.parametrize(("m", "dim"), [(1, 3), (50, 3), (2000, 3), (10, 1)])
def test_anees_region_is_the_scaled_chi_square_interval(m, dim):
    lo, hi = scores.anees_region(m, dim)
    assert stats.chi2.cdf(m * lo, m * dim) == pytest.approx(0.025, rel=1e-9)
    assert stats.chi2.cdf(m * hi, m * dim) == pytest.approx(0.975, rel=1e-9)
    assert lo < dim < hi


def test_anees_region_holds_consistent_gaussian_errors_at_its_rate():
    """Errors drawn from the stated covariance: ANEES inside the region in about 95 % of studies."""
    rng = np.random.default_rng(7)
    m, studies = 100, 2000
    a = rng.standard_normal((3, 3))
    cov = a @ a.T + 3 * np.eye(3)
    err = rng.multivariate_normal(np.zeros(3), cov, size=(studies, m))
    nees = np.einsum("smi,ij,smj->sm", err, np.linalg.inv(cov), err)
    lo, hi = scores.anees_region(m)
    inside = np.mean((nees.mean(axis=1) >= lo) & (nees.mean(axis=1) <= hi))
    assert abs(inside - 0.95) < 4 * np.sqrt(0.95 * 0.05 / studies)
    # one trial's region: the tally's "outside", about 5 % of consistent trials
    est = Estimates(
        TRUTH + err[0], np.broadcast_to(cov, (m, 3, 3)), np.full(m, 0.5), np.full(m, 0.5), None
    )
    big = Estimates(
        TRUTH + err.reshape(-1, 3),
        np.broadcast_to(cov, (m * studies, 3, 3)),
        np.full(m * studies, 0.5),
        np.full(m * studies, 0.5),
        None,
    )
    tally = scores.Tally(TRUTH)
    tally.add(est)
    tally.add(big)
    out = tally.scores()["anees"]
    assert abs(out["outside"] - 0.05) < 4 * out["outside_se"]


def test_anees_region_refusals():
    for args, match in (((0,), "trials"), ((5, 0), "dim"), ((5, 3, 1.0), "level")):
        with pytest.raises(ValueError, match=match):
            scores.anees_region(*args)


def test_hard_scores_add_median_and_divergent_keeping_their_keys():
    rng = np.random.default_rng(2)
    y = np.full(500, 6.0)
    e = 3.0 * rng.standard_t(2, size=500)
    sd = np.full(500, 3.0)
    pit = stats.norm.cdf(-e / sd)
    plain = hardness.depth_scores(e, sd, pit)
    full = hardness.depth_scores(e, sd, pit, y)
    assert {k: full[k] for k in plain} == plain and "divergent" not in plain
    assert plain["median_abs_error"] == np.median(np.abs(e))
    assert full["divergent"]["count"] == int(np.sum(np.abs(e) > scores.DIVERGENCE * 6.0))
    with pytest.raises(ValueError, match="true_depth"):
        hardness.depth_scores(e, sd, pit, y[:3])


def test_every_trial_divergent_leaves_no_rmse_kept_and_strict_json():
    import json

    rng = np.random.default_rng(4)
    est = heavy_estimates(20, rng)
    far = Estimates(est.mean + [0.0, 100.0, 0.0], est.cov, est.depth_cdf, est.velocity_cdf, None)
    tally = scores.Tally(TRUTH)
    tally.add(far)
    out = tally.scores()
    assert out["divergent"]["count"] == 20 and out["depth"]["rmse_kept"] is None
    assert out["track_loss_levels"]["0.1"]["rmse_kept"] is None
    json.dumps(out, allow_nan=False)
