"""Every sampler's reported Monte Carlo error against its actual error (error_coverage).

Each sampler of the registry runs independently, at its default size, on
Figure 2's problem; its error, estimate minus the optimal filter's exact
moment, must lie within two reported errors in about 95 % of the runs. With 50
runs the test asks for at least 43 (86 %) for every moment: a sampler whose
errors cover 95 % fails it with probability 0.3 % per moment (binomial), one
whose errors cover 80 % passes it with probability 19 % (power 0.81); fewer
runs (the resample-move filter's, and those not collapsed) get the binomial
threshold of the same false alarm rate (at most 1 %). Where a
sampler collapses it must say so and report no error. The full check, 100 runs
on Figure 2 and on a 30-frame track, is :func:`error_coverage` with its
default ``runs=100``.
"""

import numpy as np
import pytest
from scipy import stats

from depthcore.problem import checks
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS

FIG2 = SCENARIOS["fig2"]
#: Independent runs of each sampler: fewer for the slower resample-move filter.
RUNS = {"particle": 50, "rbpf": 50, "resample_move": 30}
#: A false alarm rate per moment: an honest sampler fails with at most this probability.
FALSE_ALARM = 0.01


#: The samplers whose Monte Carlo errors :func:`error_coverage` checks.
SAMPLERS = ("particle", "resample_move", "rbpf")


#: The moments whose errors :func:`error_coverage` checks.
ERROR_MOMENTS = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")


def error_coverage(
    name: str,
    mu,
    rho: float,
    prior_mean,
    prior_cov,
    runs: int = 100,
    seed=0,
    process_noise: float = 0.0,
    **options,
) -> dict:
    """How often a sampler's reported error covers its actual error.

    The sampler ``name`` of the registry runs ``runs`` times, independently,
    on one problem (the runs are the rows of one batch, drawn from one
    generator seeded by ``seed``); each moment's error, estimate minus the
    exact value of the optimal filter (the bank of Kalman filters beyond
    three frames or with process noise), is compared with the error the
    sampler reports for it (``depth_error`` for the depth's moments,
    ``velocity_error`` for the velocity's). An honest error puts about 95 %
    of the runs within two reported errors; a run flagged ``collapsed``
    reports no error (NaN) and is counted apart.

    Parameters
    ----------
    name : str
        One of :data:`SAMPLERS`.
    mu : array_like, shape (K,)
        One sequence of bearings.
    rho, prior_mean, prior_cov, process_noise
        The problem, as for every filter of the registry.
    runs : int
        Independent runs, >= 1.
    seed : int or numpy.random.SeedSequence
    **options
        For the sampler (``n_particles``, ``replicas``, ...); its defaults otherwise.

    Returns
    -------
    dict
        ``"runs"``, ``"collapsed"`` (the number of runs flagged), and for each
        of :data:`ERROR_MOMENTS` ``{"within_two": fraction of the runs not
        collapsed whose error is within two reported errors, "max_z": the
        largest absolute error over the reported error, "se": the binomial standard error of
        the fraction}``; ``"worst_collapsed_z"``: the largest absolute error of a
        collapsed run's depth mean over the exact depth SD (how far off the
        flag was right to be).
    """
    if name not in SAMPLERS:
        raise ValueError(f"name must be one of {SAMPLERS}, got {name!r}")
    runs = checks.count(runs, "runs")
    mu = checks.finite_array(mu, "mu")
    if mu.ndim != 1:
        raise ValueError(f"mu must have shape (K,), got shape {mu.shape}")
    batch = np.tile(mu, (runs, 1))
    noise = {"process_noise": process_noise} if process_noise else {}
    exact = FILTERS["optimal"](mu, rho, prior_mean, prior_cov, **noise)
    rng = np.random.default_rng(checks.seed_sequence(seed))
    est = FILTERS[name](batch, rho, prior_mean, prior_cov, rng=rng, **noise, **options)
    collapsed = np.broadcast_to(np.asarray(est.collapsed, dtype=bool), (runs,))
    out = {"runs": runs, "collapsed": int(np.sum(collapsed))}
    ok = ~collapsed
    for moment in ERROR_MOMENTS:
        quantity = moment.split("_")[0]
        err = np.asarray(getattr(est, moment)) - getattr(exact, moment)
        reported = np.asarray(getattr(est, f"{quantity}_error"))
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(err[ok]) / reported[ok]
        n = int(np.sum(ok))
        frac = float(np.mean(z <= 2.0)) if n else float("nan")
        out[moment] = {
            "within_two": frac,
            "max_z": float(np.max(z)) if n else float("nan"),
            "se": float(np.sqrt(frac * (1 - frac) / n)) if n else float("nan"),
        }
    depth_err = np.abs(np.asarray(est.depth_mean) - exact.depth_mean) / exact.depth_sd
    out["worst_collapsed_z"] = float(np.max(depth_err[collapsed])) if np.any(collapsed) else None
    return out


def least_within_two(n: int) -> int:
    """The least count of ``n`` runs within two errors: P(X < it) <= 1 % at 95 %."""
    return int(stats.binom.ppf(FALSE_ALARM, n, 0.95))


def test_the_threshold_has_the_stated_false_alarm_rate_and_power():
    least = least_within_two(50)
    assert least == 43
    assert stats.binom.cdf(least - 1, 50, 0.95) <= FALSE_ALARM
    assert stats.binom.cdf(least - 1, 50, 0.80) > 0.8  # power against 80 % coverage


@pytest.mark.parametrize("name", SAMPLERS)
def test_reported_errors_cover_the_actual_errors_on_figure_2(name):
    runs = RUNS[name]
    r = error_coverage(name, FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, runs, 5)
    if name != "resample_move":
        assert r["collapsed"] == 0
    # the resample-move filter's 5,000 particles per replica collapse in about half the
    # runs on Figure 2 (its ESS falls to a few particles at mu_3): those say so
    n = runs - r["collapsed"]
    assert n >= 8, r
    for moment in ERROR_MOMENTS:
        assert r[moment]["within_two"] * n >= least_within_two(n), (moment, r[moment])
        # and they are errors, not bounds too wide to be wrong: some run comes near two
        assert r[moment]["max_z"] > 1.0, (moment, r[moment])


def test_resample_move_with_few_particles_says_it_collapsed():
    """200 particles per replica on Figure 2: every replica settles on a narrow, wrong
    piece of the posterior (depth means near 40 for an exact 6.5, SDs near 0)."""
    r = error_coverage(
        "resample_move",
        FIG2.mu,
        FIG2.rho,
        FIG2.prior.mean,
        FIG2.prior.cov,
        10,
        1,
        n_particles=200,
    )
    assert r["collapsed"] == 10
    assert r["worst_collapsed_z"] > 5
    est = FILTERS["resample_move"](
        FIG2.mu,
        FIG2.rho,
        FIG2.prior.mean,
        FIG2.prior.cov,
        rng=np.random.default_rng(0),
        n_particles=200,
    )
    assert est.collapsed is True
    assert np.isnan(est.depth_error) and np.isnan(est.velocity_error)


def test_importance_sampling_from_the_prior_says_it_collapsed():
    est = FILTERS["particle"](
        FIG2.mu,
        FIG2.rho,
        FIG2.prior.mean,
        FIG2.prior.cov,
        rng=np.random.default_rng(0),
        n_particles=500,
        proposal="prior",
    )
    assert est.collapsed is True and np.isnan(est.depth_error)


def test_deterministic_filters_have_no_collapse_flag():
    est = FILTERS["ekf"](FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    assert est.collapsed is None


def test_replica_errors_cover_95_percent_with_four_normal_replicas():
    """The Student t factor: 20,000 averages of four N(0, 1) replicas lie within 1.96
    errors of 0 in 95 % of cases (binomial SE 0.15 %; +/- 2 SD without it gives 86 %)."""
    from depthcore.particles.resampling import replica_errors

    x = np.random.default_rng(3).standard_normal((20_000, 4))
    error, collapsed = replica_errors(x, np.full(x.shape, 100.0))
    assert not collapsed.any()
    inside = np.abs(x.mean(axis=1)) <= 1.96 * error
    assert np.mean(inside) == pytest.approx(0.95, abs=4 * 0.0015)
    plain = np.abs(x.mean(axis=1)) <= 2 * x.std(axis=1, ddof=1) / 2
    assert np.mean(plain) == pytest.approx(stats.t.cdf(2, 3) * 2 - 1, abs=4 * 0.0025)


def test_replicas_that_disagree_by_more_than_their_width_have_collapsed():
    from depthcore.particles.resampling import MIN_EFFECTIVE_DRAWS, replica_errors

    est = np.array([[0.0, 1.0, 2.0, 3.0]])  # variance 5/3 between the replicas
    wide = np.sqrt(MIN_EFFECTIVE_DRAWS * 5 / 3) * 1.01
    e, c = replica_errors(est, np.full(est.shape, wide))
    assert not c[0] and np.isfinite(e[0])
    e, c = replica_errors(est, np.full(est.shape, wide / 1.02))
    assert c[0] and np.isnan(e[0])
    # no spread at all within the replicas is a collapse too; one replica judges nothing
    e, c = replica_errors(np.zeros((1, 4)), np.zeros((1, 4)))
    assert c[0] and np.isnan(e[0])
    e, c = replica_errors(np.zeros((1, 1)), np.ones((1, 1)))
    assert not c[0] and np.isnan(e[0])
