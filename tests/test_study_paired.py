"""Scores of several filters over the same trials: co-moments, delta-method errors, paired tests."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.studies import monte_carlo, pairs, scores

RNG_SEED = 20261125


def correlated(rng, shape, rho):
    """Pairs of standard normals of correlation ``rho``, shape ``shape + (2,)``."""
    z = rng.standard_normal(shape + (2,))
    z[..., 1] = rho * z[..., 0] + np.sqrt(1.0 - rho**2) * z[..., 1]
    return z


def moments(values):
    """Means (..., 2) and sample covariances (..., 2, 2) over the trial axis -2."""
    mean = values.mean(axis=-2)
    d = values - mean[..., None, :]
    cov = np.einsum("...ti,...tj->...ij", d, d) / (values.shape[-2] - 1)
    return mean, cov


# --- the co-moment accumulator (Chan-Golub-LeVeque, matrix form) ---------------------------


def test_pooled_comoments_over_many_chunks_equal_one_chunk_and_numpy_cov():
    rng = np.random.default_rng(RNG_SEED)
    values = rng.standard_normal((1000, 4)) @ rng.standard_normal((4, 4)) + [1e3, -5.0, 0.0, 2.0]
    whole = pairs.CoMoments(["a", "b", "c", "d"])
    whole.add(values)
    chunked = pairs.CoMoments(["a", "b", "c", "d"])
    for part in np.array_split(values, [1, 3, 100, 101, 640]):
        chunked.add(part)
    assert chunked.n == whole.n == 1000
    assert_allclose(chunked.mean, values.mean(axis=0), rtol=1e-13)
    assert_allclose(whole.covariance(), np.cov(values, rowvar=False), rtol=1e-11, atol=1e-12)
    assert_allclose(chunked.covariance(), np.cov(values, rowvar=False), rtol=1e-11, atol=1e-12)


def test_an_empty_chunk_adds_nothing_and_a_covariance_needs_two_trials():
    m = pairs.CoMoments([("ekf", "sd"), ("ekf", "squared_error")])
    m.add(np.zeros((0, 2)))
    assert m.n == 0 and m.summary()["cov"] is None
    m.add([[1.0, 2.0]])
    m.add(np.zeros((0, 2)))
    assert m.n == 1
    with pytest.raises(ValueError, match="trials"):
        m.covariance()
    m.add([[3.0, 2.0]])
    assert_allclose(m.covariance(), [[2.0, 0.0], [0.0, 0.0]])


@pytest.mark.parametrize("shape", [(3,), (2, 3), (2, 1, 2)])
def test_comoments_refuse_values_of_the_wrong_shape(shape):
    m = pairs.CoMoments(["a", "b"])
    with pytest.raises(ValueError, match="values"):
        m.add(np.zeros(shape))


def test_comoments_refuse_repeated_or_no_columns_and_pair_of_names_its_missing_column():
    with pytest.raises(ValueError, match="columns"):
        pairs.CoMoments(["a", "a"])
    with pytest.raises(ValueError, match="columns"):
        pairs.CoMoments([])
    m = pairs.CoMoments([("x", "sd"), ("y", "sd")])
    m.add(np.arange(6.0).reshape(3, 2))
    means, cov, n = pairs.pair_of(m.summary(), ["y", "sd"], ("x", "sd"))
    assert n == 3
    assert_allclose(means, [3.0, 2.0], rtol=1e-15)
    assert_allclose(cov, [[4.0, 4.0], [4.0, 4.0]], rtol=1e-15)
    with pytest.raises(ValueError, match="b: the summary has no column"):
        pairs.pair_of(m.summary(), ("x", "sd"), ("z", "sd"))


# --- the delta-method errors against the spread of replicated studies -------------------------

REPLICATIONS, TRIALS = 4000, 300


def spread_and_se(statistic, se_formula, values):
    """The SD of ``statistic`` over the replications and the median delta-method SE."""
    mean, cov = moments(values)
    return np.std(statistic(mean), ddof=1), np.median(se_formula(mean, cov))


def test_mean_ratio_se_delta_method_matches_the_spread_of_replications_and_needs_the_correlation():
    """The delta method ``a/b sqrt(V_aa/a² + V_bb/b² - 2 V_ab/(ab) / n)`` of a ratio of means.

    Two filters' per-trial scores correlated 0.9 (errors on the same
    bearings); over 4000 replications the SD of the ratio is matched to 6 %
    (the SD's own Monte Carlo error is about 1 %), while the separate SEs
    (``V_ab = 0``) overstate it by a factor of about 2.5.
    """
    rng = np.random.default_rng(RNG_SEED)
    z = correlated(rng, (REPLICATIONS, TRIALS), 0.9)
    values = np.stack([2.0 + 0.5 * z[..., 0], 3.0 + 0.6 * z[..., 1]], axis=-1)

    def ratio(m):
        return m[..., 0] / m[..., 1]

    spread, se = spread_and_se(ratio, lambda m, c: pairs.mean_ratio_se(m, c, TRIALS), values)
    assert abs(se / spread - 1) < 0.06
    independent = lambda m, c: pairs.mean_ratio_se(m, c * np.eye(2), TRIALS)  # noqa: E731
    _, wrong = spread_and_se(ratio, independent, values)
    assert wrong / spread > 2.0


def test_rmse_ratio_se_delta_method_matches_the_spread_of_replications_and_needs_the_correlation():
    """The ratio of RMSEs ``sqrt(a/b)`` of mean squared errors ``a``, ``b``: ratio_se, powers 1/2.

    Errors correlated 0.95 across the two filters; the squared errors then
    correlate about 0.9 and the independent formula overstates the SE by
    more than a factor of 2.
    """
    rng = np.random.default_rng(RNG_SEED + 1)
    z = correlated(rng, (REPLICATIONS, TRIALS), 0.95)
    values = np.stack([(0.2 + 1.0 * z[..., 0]) ** 2, (1.5 * z[..., 1]) ** 2], axis=-1)

    def ratio(m):
        return np.sqrt(m[..., 0] / m[..., 1])

    spread, se = spread_and_se(ratio, lambda m, c: pairs.rmse_ratio_se(m, c, TRIALS), values)
    assert abs(se / spread - 1) < 0.06
    _, wrong = spread_and_se(
        ratio, lambda m, c: pairs.rmse_ratio_se(m, c * np.eye(2), TRIALS), values
    )
    assert wrong / spread > 2.0


def test_rmse_over_mean_sd_ratio_se_matches_the_spread_of_replications():
    """``ratio_se`` with powers (1/2, 1): an RMSE over a mean stated SD, as of one filter."""
    rng = np.random.default_rng(RNG_SEED + 2)
    z = correlated(rng, (REPLICATIONS, TRIALS), 0.7)
    values = np.stack([(2.0 * z[..., 0]) ** 2, np.exp(0.3 * z[..., 1])], axis=-1)

    def ratio(m):
        return np.sqrt(m[..., 0]) / m[..., 1]

    def se(m, c):
        return pairs.ratio_se(m, c, TRIALS, (0.5, 1.0))

    spread, delta = spread_and_se(ratio, se, values)
    assert abs(delta / spread - 1) < 0.06


def test_paired_difference_se_matches_the_spread_of_replications_and_needs_the_correlation():
    """``sqrt((V_aa + V_bb - 2 V_ab) / n)``: a paired difference of means."""
    rng = np.random.default_rng(RNG_SEED + 3)
    z = correlated(rng, (REPLICATIONS, TRIALS), 0.9)
    values = np.stack([z[..., 0], 1.2 * z[..., 1] + 0.1], axis=-1)

    def difference(m):
        return m[..., 0] - m[..., 1]

    def se(m, c):
        return pairs.paired_difference_se(c, TRIALS)

    spread, delta = spread_and_se(difference, se, values)
    assert abs(delta / spread - 1) < 0.06
    _, wrong = spread_and_se(difference, lambda m, c: se(m, c * np.eye(2)), values)
    assert wrong / spread > 2.0


def test_coverage_gap_difference_se_matches_the_spread_of_paired_indicators():
    """``|a - p| - |b - p|`` by the delta method, slopes ``sign(a - p)``, ``-sign(b - p)``.

    One coverage below its level (0.68 against 0.9), one above (0.95): the
    slopes have opposite signs, so a formula that ignored them (a plain
    paired difference of the indicators) understates the SE by about 20 %,
    far outside the 6 % tolerance the delta method meets.
    """
    rng = np.random.default_rng(RNG_SEED + 4)
    z = correlated(rng, (REPLICATIONS, TRIALS), 0.8)
    values = np.stack([np.abs(z[..., 0]) < 0.9945, np.abs(z[..., 1]) < 1.96], axis=-1)
    values = values.astype(float)
    mean, cov = moments(values)
    gap, se = pairs.coverage_gap_difference(mean, cov, TRIALS, 0.9)
    spread = np.std(gap, ddof=1)
    assert abs(np.median(se) / spread - 1) < 0.06
    plain = pairs.paired_difference_se(cov, TRIALS)
    assert np.median(plain) / spread < 1 - 0.15


def test_with_independent_scores_the_ratio_se_is_that_of_the_separate_ses():
    """Limiting case ``V_ab = 0``: ``R sqrt((se_a/a)² + (se_b/b)²)``, an RMSE's se(MSE)/(2 RMSE)."""
    means = np.array([4.0, 9.0])
    cov = np.array([[2.0, 0.0], [0.0, 5.0]])
    n = 50
    se_a, se_b = np.sqrt(np.diag(cov) / n)
    assert_allclose(
        pairs.mean_ratio_se(means, cov, n),
        4 / 9 * np.hypot(se_a / 4, se_b / 9),
        rtol=1e-14,
    )
    rmse_se_a, rmse_se_b = se_a / (2 * 2.0), se_b / (2 * 3.0)  # Tally's delta method per RMSE
    assert_allclose(
        pairs.rmse_ratio_se(means, cov, n),
        2 / 3 * np.hypot(rmse_se_a / 2, rmse_se_b / 3),
        rtol=1e-14,
    )
    assert_allclose(pairs.paired_difference_se(cov, n), np.hypot(se_a, se_b), rtol=1e-14)


def test_identical_filters_have_ratio_one_with_se_zero():
    """Limiting case of two identical scores: every ratio 1 and every paired SE exactly 0."""
    rng = np.random.default_rng(RNG_SEED + 5)
    x = rng.exponential(size=200)
    m = pairs.CoMoments(["a", "b"])
    m.add(np.column_stack([x, x]))
    means, cov, n = pairs.pair_of(m.summary(), "a", "b")
    assert means[0] / means[1] == 1.0
    for se in (
        pairs.mean_ratio_se(means, cov, n),
        pairs.rmse_ratio_se(means, cov, n),
        pairs.paired_difference_se(cov, n),
    ):
        assert se == 0.0
    gap, se = pairs.coverage_gap_difference([0.5, 0.5], [[0.25, 0.25], [0.25, 0.25]], n, 0.68)
    assert gap == 0.0 and se == 0.0


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"means": [1.0, 0.0]}, "means must be positive"),
        ({"means": [1.0, 2.0, 3.0]}, "means must have shape"),
        ({"cov": np.eye(3)}, "cov must have shape"),
        ({"trials": 1}, "trials"),
    ],
)
def test_ratio_se_refuses_bad_input(kwargs, message):
    args = {"means": [1.0, 2.0], "cov": np.eye(2), "trials": 10, **kwargs}
    with pytest.raises(ValueError, match=message):
        pairs.ratio_se(**args)


# --- the paired test ---------------------------------------------------------------------------


def paired_rmse_verdict(errors_a, errors_b):
    m = pairs.CoMoments(["a", "b"])
    m.add(np.column_stack([errors_a**2, errors_b**2]))
    means, cov, n = pairs.pair_of(m.summary(), "a", "b")
    ratio = np.sqrt(means[0] / means[1])
    se = pairs.rmse_ratio_se(means, cov, n) / ratio  # of the ratio's logarithm
    return scores.difference_verdict(-np.log(ratio), se)


def test_the_paired_test_of_an_rmse_ratio_finds_a_clear_win_a_clear_loss_and_a_tie():
    """The z test of ``log sqrt(a/b)``, SE the ratio's relative delta-method SE: 1, -1 or 0."""
    rng = np.random.default_rng(RNG_SEED + 6)
    e = rng.standard_normal(200)
    noise = 0.05 * rng.standard_normal(200)
    assert paired_rmse_verdict(0.9 * e + noise, e) == 1  # a 10 % smaller error, same trials
    assert paired_rmse_verdict(e, 0.9 * e + noise) == -1
    assert paired_rmse_verdict(e, e) == 0  # identical: ratio 1, SE 0, no difference
    # different draws of one error distribution over few trials: no detectable difference
    assert paired_rmse_verdict(e[:40], rng.permutation(e[:40])) == 0


def test_difference_verdict_has_three_outcomes_and_refuses_bad_input():
    """``1`` above ``z se``, ``-1`` below ``-z se``, ``0`` between, at the 1 % point 2.5758."""
    assert scores.TEST_Z == pytest.approx(2.5758293035489004, rel=1e-15)
    v = scores.difference_verdict([3.0, -3.0, 2.5, -2.5, 0.0], 1.0)
    assert v.tolist() == [1, -1, 0, 0, 0]
    with pytest.raises(ValueError, match="se"):
        scores.difference_verdict(1.0, -1.0)
    with pytest.raises(ValueError, match="z"):
        scores.difference_verdict(1.0, 1.0, z=0.0)


def test_detectable_shift_is_found_with_the_stated_power():
    """``(z_a + z_b) se``: a true shift of that size passes the 1 % test in 80 % of replications."""
    assert_allclose(
        scores.detectable_shift(scores.coverage_se(0.68, 150)),
        scores.detectable_difference(0.68, 150),
        rtol=1e-15,
    )
    rng = np.random.default_rng(RNG_SEED + 7)
    se = 0.1
    d = float(scores.detectable_shift(se))
    found = scores.difference_verdict(d + se * rng.standard_normal(20000), se) == 1
    assert abs(found.mean() - scores.TEST_POWER) < 0.01


# --- the study keeps the co-moments beside its tallies ------------------------------------------


def test_study_keeps_the_paired_comoments_without_changing_its_scores():
    names = ("optimal", "second_order", "ekf")
    plain = monte_carlo.study(trials=120, seed=4, names=names, chunk=50)
    paired = monte_carlo.study(trials=120, seed=4, names=names, chunk=50, paired=True)
    one = monte_carlo.study(trials=120, seed=4, names=names, chunk=120, paired=True)
    assert "paired" not in plain and paired["filters"] == plain["filters"]
    p = paired["paired"]
    assert p["trials"] == paired["valid_trials"]
    assert_allclose(p["mean"], one["paired"]["mean"], rtol=1e-12)
    assert_allclose(p["cov"], one["paired"]["cov"], rtol=1e-10, atol=1e-15)
    for name in names:
        d = paired["filters"][name]["depth"]
        means, cov, n = pairs.pair_of(p, (name, "squared_error"), (name, "sd"))
        assert_allclose(np.sqrt(means[0]), d["rmse"], rtol=1e-12)
        assert_allclose(means[1], d["mean_sd"], rtol=1e-12)
        assert_allclose(np.sqrt(cov[1, 1] / n), d["mean_sd_se"], rtol=1e-10)
        # the RMSE's own SE is the ratio SE's limit against a constant
        assert_allclose(
            pairs.ratio_se(means, cov * [[1, 0], [0, 0]], n, (0.5, 0.0)),
            d["rmse_se"],
            rtol=1e-10,
        )
        c68 = pairs.pair_of(p, (name, "coverage_68"), (name, "hellinger"))[0][0]
        assert c68 == pytest.approx(d["coverage_68"], abs=1e-12)
        h = pairs.pair_of(p, (name, "hellinger"), (name, "sd"))[0][0]
        assert h == pytest.approx(paired["filters"][name]["hellinger_depth"]["mean"], rel=1e-12)


def test_compare_gives_the_rmse_ratio_and_coverage_gaps_of_two_filters_of_a_study():
    names = ("optimal", "second_order", "ekf")
    r = monte_carlo.study(trials=150, seed=6, names=names, paired=True)
    p, f = r["paired"], r["filters"]
    duel, back = (
        pairs.compare(p, "second_order", "ekf"),
        pairs.compare(p, "ekf", "second_order"),
    )
    rmse = {n: f[n]["depth"]["rmse"] for n in names}
    assert duel["rmse_ratio"] == pytest.approx(rmse["second_order"] / rmse["ekf"], rel=1e-12)
    assert duel["rmse_ratio"] * back["rmse_ratio"] == pytest.approx(1.0, rel=1e-12)
    # the SE of a ratio's inverse is the SE over the ratio squared (delta method)
    assert back["rmse_ratio_se"] == pytest.approx(
        duel["rmse_ratio_se"] / duel["rmse_ratio"] ** 2, rel=1e-9
    )
    for level in (68, 95):
        gap = [
            abs(f[n]["depth"][f"coverage_{level}"] - level / 100) for n in ("second_order", "ekf")
        ]
        assert duel[f"coverage_{level}_gap"] == pytest.approx(gap[0] - gap[1], abs=1e-12)
        assert back[f"coverage_{level}_gap"] == pytest.approx(gap[1] - gap[0], abs=1e-12)
        assert duel[f"coverage_{level}_gap_se"] == back[f"coverage_{level}_gap_se"] >= 0
    assert duel["trials"] == r["valid_trials"]
    assert set(pairs.compare(p, "ekf", "optimal", ())) == {
        "rmse_ratio",
        "rmse_ratio_se",
        "trials",
    }


def test_the_paired_study_keeps_only_running_co_moments():
    """Memory of a chunk, not of the trials: doubling the chunks (32 to 64) leaves the peak."""
    import tracemalloc

    def peak(n):
        monte_carlo.study(
            trials=10, seed=0, chunk=10, names=("ekf",), paired=True
        )  # warm the imports
        tracemalloc.start()
        monte_carlo.study(trials=n, seed=0, chunk=50, names=("ekf", "ukf"), paired=True)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak

    # Past the first chunks (whose one-off allocations vary between machines by tens of kB),
    # keeping each trial's 4 paired scores per filter would add 8 bytes each: 102 kB here,
    # against some 16 kB of allocator and cache growth measured between these two runs.
    small, large = peak(1600), peak(3200)
    assert large < small + 8 * (3200 - 1600) * 4 * 2 / 2
