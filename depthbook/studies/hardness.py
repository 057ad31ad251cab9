"""Where the problem is hard: every filter and the bound across parallax, prior and depth.

Recommended import: ``from depthbook.studies import hardness``.

Three bearings of a point moving by Eq. (1) say where it is only through the
curvature of their sequence: the noise-free bearings ``b_k = x_k / y_k`` of a
truth ``(x, y, v)`` at time 3 are ``b(t) = v + (x - v y) / (y + t)`` at
``t = -2, -1, 0``, whose second difference (:func:`second_difference`) is

    b_1 - 2 b_2 + b_3 = 2 (x - v y) / (y (y - 1) (y - 2)).

It vanishes when ``x = v y``: the point then moves along its own ray, every
bearing equals ``v``, and every state ``(v y', y', v)`` gives the same bearings,
so the depth is not observable from bearings alone (Nardone and Aidala 1981,
on bearings-only tracking [nardone1981]_). Measured in units of the noise ``rho`` it is the
signal the bearings carry about the depth.

:func:`hard_cell` scores every filter's depth estimate in one setting (a truth,
a prior covariance ``s I`` and a prior velocity) in two ways:

* **at the fixed truth**: bearings drawn afresh around one truth;
* **averaged over the prior** (simulation-based calibration, Talts et al.
  2018 [talts2018b]_): truths drawn from the filter's own prior, each with its bearings.
  A Bayesian posterior is calibrated in this sense, exactly, whatever the
  geometry (:mod:`depthcore.analysis.calibration`); at one fixed truth it need not be,
  and its posterior mean minimises the mean squared error averaged over the
  prior, not at each truth. This is the fair arbiter of the exact posterior.

The prior must not depend on the bearings for the second reading to hold, so
the paper's rule (a prior centred on each trial's own noise-free solution) is
replaced here by that rule applied once, to the truth's noise-free bearings:
the mean ``G^{-2}`` of the truth (Eq. (1)) with the velocity replaced by a
chosen prior velocity (the paper's rule sets it to 0), covariance ``s I``
(:func:`prior_for`). Truths of the second reading are drawn from that prior.

Two filters are compared over the trials both answer (:func:`paired_comparison`,
from the co-moments of their per-trial scores, :func:`paired_scores`): the
ratio of their RMSEs and the difference of their coverages' distances from
nominal, each with its delta-method error, tested by :func:`verdicts` with
three outcomes (significantly better, significantly worse, undecided).

Trials whose first three bearings have no noise-free solution in front of the
camera are left out in both readings, as in :mod:`depthcore.studies.monte_carlo`; a filter
that has no answer for a trial (the EKF's predicted depth behind the camera,
for instance) is scored on the trials it answers, and the number it does not
is reported.

References
----------
.. [nardone1981] S. C. Nardone and V. J. Aidala, "Observability criteria for
   bearings-only target motion analysis", IEEE Trans. Aerospace and
   Electronic Systems AES-17(2), 162-166, 1981.
.. [talts2018b] S. Talts, M. Betancourt, D. Simpson, A. Vehtari and A. Gelman,
   "Validating Bayesian inference algorithms with simulation-based
   calibration", arXiv:1804.06788, 2018.
"""

from __future__ import annotations

import numpy as np

from depthcore.analysis import bound, calibration
from depthcore.exact import mixture
from depthcore.problem import checks, model
from depthcore.problem.gaussian import paper_prior_means
from depthcore.registry.filters import FILTERS, check_names
from depthcore.studies import medians, scores, tasks
from depthcore.studies import pairs as study_pairs
from depthcore.studies import trials as study_trials
from depthcore.studies.scores import LEVELS

#: The filters scored by :func:`hard_cell`: the exact posterior and the Gaussian approximations.
NAMES = ("optimal", "second_order", "ekf", "ukf", "iterated", "inverse_depth")
#: The two readings of :func:`hard_cell`: at the fixed truth, and over truths drawn from the prior.
READINGS = ("fixed", "prior")


def second_difference(truths) -> np.ndarray:
    """The second difference ``b_1 - 2 b_2 + b_3`` of the noise-free bearings of truths at time 3.

    The bearings are ``x_k / y_k`` (Eq. (4) without noise) of the states
    ``G^{k-3}`` of the truth (Eq. (1)), ``k = 1, 2, 3``; in closed form
    ``2 (x - v y) / (y (y - 1) (y - 2))`` (module docstring). Zero means the
    depth is unobservable from the bearings (Nardone and Aidala 1981).

    Parameters
    ----------
    truths : array_like, shape (..., 3)
        States ``(x, y, v)`` at time 3 with depth ``y > 2`` (in front of the
        camera at time 1).

    Returns
    -------
    ndarray, shape (...)
    """
    s = checks.finite_array(truths, "truths")
    if s.ndim < 1 or s.shape[-1] != 3:
        raise ValueError(f"truths must have shape (..., 3), got {s.shape}")
    if not np.all(s[..., 1] > 2):
        raise ValueError("truths must have depth > 2: the point in front of the camera at time 1")
    b = [model.project(model.G(s, k - 3)) for k in (1, 2, 3)]
    return b[0] - 2.0 * b[1] + b[2]


def prior_for(truth, prior_scale: float, prior_velocity: float = 0.0):
    """The fixed prior of a setting: the paper's rule applied to the truth's noise-free bearings.

    Mean ``G^{-2}`` of the truth (Eq. (1); the paper's ``(c1 - 2 c3, c2 - 2,
    0)``, Eq. (13), with ``c`` the truth) with its velocity set to
    ``prior_velocity``, covariance ``prior_scale * I``.

    Parameters
    ----------
    truth : array_like, shape (3,)
    prior_scale : float
        > 0.
    prior_velocity : float

    Returns
    -------
    tuple of ndarray
        The mean (3,) and the covariance (3, 3).
    """
    truth = checks.finite_array(truth, "truth", (3,))
    scale = checks.positive_scalar(prior_scale, "prior_scale")
    mean = paper_prior_means(truth[None])[0]
    mean[2] = float(checks.finite_array(prior_velocity, "prior_velocity"))
    return mean, scale * np.eye(3)


def depth_scores(errors, sds, pit, true_depth=None) -> dict:
    """Bias, RMSE, mean stated SD and coverage of depth estimates, each with its standard error.

    Beside them, what a few far-off trials cannot drive: the median absolute
    error with its distribution-free interval
    (:func:`depthcore.studies.medians.median_interval`, exact) and, given the
    true depths, the trials that diverged
    (:func:`depthcore.studies.scores.divergent`).

    Parameters
    ----------
    errors : array_like, shape (T,)
        Estimate minus true depth, ``T >= 2`` trials.
    sds : array_like, shape (T,)
        The SDs the estimates state.
    pit : array_like, shape (T,)
        The estimate's CDF at the true depth: the truth lies in the central
        ``p`` interval when ``|pit - 1/2| <= p / 2``.

    Returns
    -------
    dict
        ``"bias"``, ``"rmse"``, ``"mean_sd"`` (the RMSE's error by the delta
        method, :func:`depthcore.analysis.bound.against_bound`), ``"coverage_68"``,
        ``"coverage_95"`` (binomial errors), each with ``"<score>_se"``, and
        ``"trials"``; ``"median_abs_error"``, ``"median_abs_error_ci"`` and,
        given ``true_depth``, ``"divergent"``: ``{"threshold", "count",
        "fraction", "se", "upper"}`` (:func:`depthcore.studies.scores.fraction_of`).
    """
    e = checks.finite_array(errors, "errors")
    pit = checks.finite_array(pit, "pit")
    if pit.shape != e.shape:
        raise ValueError(f"pit must have the shape of errors, {e.shape}, got {pit.shape}")
    a = bound.against_bound(e, sds, 1.0)
    n = len(e)
    out = {
        "bias": float(np.mean(e)),
        "bias_se": float(np.std(e, ddof=1) / np.sqrt(n)),
        "rmse": float(a["rmse"]),
        "rmse_se": float(a["rmse_se"]),
        "mean_sd": float(a["mean_sd"]),
        "mean_sd_se": float(a["mean_sd_se"]),
        "trials": n,
    }
    for p, c in zip(LEVELS, calibration.coverage(pit, LEVELS), strict=True):
        key = f"coverage_{round(100 * p)}"
        out[key] = float(c)
        out[f"{key}_se"] = float(scores.proportion_se(round(c * n), n))
    out["median_abs_error"], out["median_abs_error_ci"] = medians.median_interval(np.abs(e))
    if true_depth is not None:
        y = checks.finite_array(true_depth, "true_depth")
        if y.shape != e.shape:
            raise ValueError(f"true_depth must have the shape of errors, {e.shape}, got {y.shape}")
        count = int(np.count_nonzero(scores.divergent(y + e, y)))
        out["divergent"] = {
            "threshold": scores.DIVERGENCE,
            "count": count,
            **scores.fraction_of(count, n),
        }
    return out


def depth_estimates(name: str, mu, rho: float, prior_mean, prior_cov, true_depth):
    """One filter's depth means, SDs and CDFs at the true depths, over a batch of trials.

    Parameters
    ----------
    name : str
        A filter of :data:`depthcore.registry.filters.FILTERS` of the ``"exact"`` or
        ``"gaussian"`` family.
    mu : ndarray, shape (T, N)
        Bearings of frames 1 .. N (the optimal filter beyond three frames is
        the bank of Kalman filters, :func:`depthcore.exact.posterior.posterior`).
    rho : float
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    true_depth : ndarray, shape (T,)
        The true depth at frame ``N``.

    Returns
    -------
    tuple of ndarray, each shape (T,)
        Mean, SD and CDF at the true depth; NaN for a trial the filter has no
        answer for (a batch that fails is halved until such trials are isolated).
    """
    from scipy.special import ndtr

    f = FILTERS[check_names((name,))[0]]
    if f.family not in ("exact", "gaussian"):
        raise ValueError(f"name: {name} is not the exact filter nor a Gaussian one")

    def run(rows):
        est = f(mu[rows], rho, prior_mean, prior_cov)
        m, s = np.asarray(est.depth_mean), np.asarray(est.depth_sd)
        if f.family == "exact" and isinstance(est.detail, mixture.Mixture):  # beyond three frames
            return m, s, est.detail.depth_cdf(true_depth[rows][:, None])[:, 0]
        if f.family == "exact":
            return m, s, est.detail.depth_cdf(true_depth[rows])
        return m, s, ndtr((true_depth[rows] - m) / s)

    out = np.full((3, len(mu)), np.nan)

    def fill(rows):
        # a failing batch is halved until the trials without an answer are isolated
        try:
            out[:, rows] = run(rows)
        except ValueError:
            if len(rows) > 1:
                fill(rows[: len(rows) // 2])
                fill(rows[len(rows) // 2 :])

    fill(np.arange(len(mu)))
    return out[0], out[1], out[2]


def filter_estimates(mu, rho: float, prior_mean, prior_cov, true_depth, names=NAMES) -> dict:
    """:func:`depth_estimates` of each named filter: ``{name: (mean, sd, cdf)}``, each (T,)."""
    return {
        name: depth_estimates(name, mu, rho, prior_mean, prior_cov, true_depth)
        for name in check_names(names)
    }


def _answered(estimate) -> np.ndarray:
    return np.all(np.isfinite(np.asarray(estimate)), axis=0)


def score_estimates(estimates: dict, true_depth) -> dict:
    """:func:`depth_scores` of each filter's :func:`filter_estimates` over the trials it answers.

    Each filter's scores also hold ``"failed"``, the trials it had no answer
    for (left out of its scores); a filter that answers fewer than two is refused.
    """
    out = {}
    for name, (m, s, cdf) in estimates.items():
        ok = _answered((m, s, cdf))
        if np.sum(ok) < 2:
            raise ValueError(
                f"names: the {name} filter answers fewer than two trials; leave it out"
            )
        out[name] = {
            **depth_scores(m[ok] - true_depth[ok], s[ok], cdf[ok], true_depth[ok]),
            "failed": int(np.sum(~ok)),
        }
    return out


#: The per-trial depth scores whose co-moments :func:`paired_scores` keeps.
PAIRED_SCORES = ("squared_error", "sd", "coverage_68", "coverage_95")


def paired_scores(estimates: dict, true_depth) -> dict:
    """The co-moments of every pair of filters' per-trial depth scores, over the trials both answer.

    Parameters
    ----------
    estimates : dict
        :func:`filter_estimates`.
    true_depth : ndarray, shape (T,)

    Returns
    -------
    dict
        ``{(a, b): summary}`` for each pair of filters, ``a`` before ``b`` in
        ``estimates``: :meth:`depthcore.studies.pairs.CoMoments.summary` with
        columns ``[filter, score]`` for each score of :data:`PAIRED_SCORES`
        (the squared error, the stated SD and whether the central 68 % and
        95 % intervals hold the truth, :func:`depthcore.studies.scores.interval_holds`),
        for the paired comparisons of :func:`paired_comparison`.
    """
    names = list(estimates)
    out = {}
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            ok = _answered(estimates[a]) & _answered(estimates[b])
            moments = study_pairs.CoMoments([(f, k) for f in (a, b) for k in PAIRED_SCORES])
            values = []
            for m, sd, cdf in (estimates[a], estimates[b]):
                values += study_pairs.depth_scores(m[ok] - true_depth[ok], sd[ok], cdf[ok]).values()
            moments.add(np.column_stack(values))
            out[(a, b)] = moments.summary()
    return out


def hard_cell(
    truth,
    rho: float,
    prior_scale: float,
    prior_velocity: float,
    trials: int,
    seed,
    names=NAMES,
    frames: int = 3,
) -> dict:
    """Every filter's depth scores in one setting, at the fixed truth and averaged over the prior.

    Parameters
    ----------
    truth : array_like, shape (3,)
        The state at time 3, depth > 2.
    rho : float
        Bearing noise SD, > 0.
    prior_scale, prior_velocity : float
        The prior of :func:`prior_for`.
    trials : int
        Trials drawn in each reading, >= 2.
    seed : int or numpy.random.SeedSequence
        Spawns the two readings' generators.
    names : sequence of str
        Filters of the ``"exact"`` or ``"gaussian"`` family.
    frames : int
        ``N``, from 3 to ``depthcore.problem.checks.MAX_FRAMES``: the point moves on
        from ``truth`` at time 3 to frame ``N`` (Eq. (1), no process noise),
        and the filters are scored on its depth there; the truths drawn from
        the prior are followed from frame 1 to frame ``N``
        (:func:`depthcore.analysis.calibration.draw_from_prior`).

    Returns
    -------
    dict
        ``"truth"``, ``"frames"``, ``"rho"``, ``"prior_mean"``, ``"prior_cov"``,
        ``"second_difference"`` (over ``rho``: the bearings' curvature in
        units of their noise, of the first three frames), ``"bound_sd"`` (the
        depth SD at frame ``N`` of the Cramér–Rao bound at the truth, the
        prior's information included,
        :func:`depthcore.analysis.bound.posterior_bound`), and for each reading of
        :data:`READINGS` ``{"valid": trials kept, "filters": {name: scores},
        "paired": co-moments of each pair of filters' per-trial scores}``
        (:func:`paired_scores`).
    """
    truth = checks.finite_array(truth, "truth", (3,))
    rho = checks.positive_scalar(rho, "rho")
    trials = checks.count(trials, "trials")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    pm, pc = prior_for(truth, prior_scale, prior_velocity)
    fixed_rng, prior_rng = (
        np.random.default_rng(s) for s in checks.spawn(checks.seed_sequence(seed), 2)
    )
    frames = checks.frames(frames)
    b = bound.posterior_bound(truth, 3, frames, rho, pc)
    out = {
        "truth": truth,
        "frames": frames,
        "rho": rho,
        "prior_mean": pm,
        "prior_cov": pc,
        "second_difference": float(second_difference(truth)) / rho,
        "bound_sd": float(np.sqrt(b[-1, 1, 1])),
    }
    drawn = study_trials.simulate(truth, rho, trials, fixed_rng, "fixed", prior_scale, frames)
    draws = calibration.draw_from_prior(pm, pc, rho, trials, prior_rng, frames=frames)
    for reading, mu, depth in (
        ("fixed", drawn.mu, drawn.truths[:, 1]),
        ("prior", draws.mu, draws.truth[:, 1]),
    ):
        estimates = filter_estimates(mu, rho, pm, pc, depth, names)
        out[reading] = {
            "valid": len(mu),
            "filters": score_estimates(estimates, depth),
            "paired": paired_scores(estimates, depth),
        }
    return out


def hard_study(
    cells, rho: float, trials: int, seed, names=NAMES, frames: int = 3, client=None
) -> list[dict]:
    """:func:`hard_cell` for each setting, with independent streams spawned from ``seed``.

    Parameters
    ----------
    cells : sequence of (truth, prior_scale, prior_velocity)
    rho, trials, seed, names, frames
        As for :func:`hard_cell`.
    client : distributed.Client, optional
        Run the cells as tasks of its cluster (:mod:`depthcore.studies.tasks`);
        default in this process. Cell ``k`` draws from the seed's child ``k``
        wherever it runs, so the result is the same, bit for bit.

    Returns
    -------
    list of dict, one per cell
    """
    cells = list(cells)
    if not cells:
        raise ValueError("cells must not be empty")
    seeds = tasks.chunk_seeds(checks.seed_sequence(seed), len(cells))
    items = (
        (t, rho, s, v, trials, sd, names, frames)
        for (t, s, v), sd in zip(cells, seeds, strict=True)
    )
    out = []
    tasks.fold_chunks(_cell, items, lambda k, cell: out.append(cell), client=client)
    return out


def _cell(item) -> dict:
    """:func:`hard_cell` of one cell's arguments: a task of :func:`hard_study`."""
    return hard_cell(*item)


def paired_comparison(cell: dict, reading: str, a: str, b: str) -> dict:
    """Filter ``a`` against filter ``b`` over the trials of one reading both answer.

    Parameters
    ----------
    cell : dict
        From :func:`hard_cell`.
    reading : {"fixed", "prior"}
    a, b : str
        Filters of the cell.

    Returns
    -------
    dict of float
        ``"rmse_ratio"`` (``a``'s depth RMSE over ``b``'s,
        :func:`depthcore.studies.pairs.rmse_ratio_se`), ``"coverage_68_gap"``,
        ``"coverage_95_gap"`` (how much farther ``a``'s coverage lies from its
        level than ``b``'s, :func:`depthcore.studies.pairs.coverage_gap_difference`),
        each with ``"<key>_se"``, and ``"trials"`` (:func:`depthcore.studies.pairs.compare`).
    """
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    if a == b:
        raise ValueError(f"b: a filter is not compared with itself, got {a!r} twice")
    pairs = cell[reading]["paired"]
    return study_pairs.compare(pairs[(a, b)] if (a, b) in pairs else pairs[(b, a)], a, b)


def verdicts(cell: dict, reading: str, z: float = bound.Z) -> dict:
    """Each filter's coverage tests and the paired tests of the conjecture in one cell and reading.

    Parameters
    ----------
    cell : dict
        From :func:`hard_cell`.
    reading : {"fixed", "prior"}
    z : float
        Critical value of the tests (default the two-sided 1 % point).

    Returns
    -------
    dict
        ``"calibrated_68"``, ``"calibrated_95"``: ``{name: bool}``, the
        coverage within ``z`` binomial standard errors of its level (the
        nominal level's error, :func:`depthcore.studies.scores.coverage_se`).
        Where the cell holds the paired co-moments (:func:`paired_scores`),
        the outcomes (``1``, ``0``, ``-1``) of two-sided paired tests
        (:func:`depthcore.studies.scores.difference_verdict`), each with the SE
        it used as ``"<key>_se"``:

        * ``"so_nearer_68"``: ``1`` where the second-order filter's 68 %
          coverage is significantly nearer its level than the EKF's, ``-1``
          where significantly farther, ``0`` where the test detects no
          difference;
        * ``"so_rmse"``: ``1`` where its RMSE is significantly the smaller
          (the logarithm of the ratio of the two RMSEs against 0, with the
          ratio's relative SE), ``-1`` significantly the larger;
        * ``"po_best"`` (with the optimal filter and another): ``1`` where
          the optimal filter's RMSE is significantly smaller than every other
          filter's, ``-1`` where some filter's is significantly smaller than
          it, ``0`` otherwise (five tests, each at the size of ``z``); its SE
          the largest of the log-ratios';
        * ``"ekf_below"`` (with the EKF, at the ``"fixed"`` truth): ``1``
          where the EKF's RMSE lies significantly below the cell's bound SD
          (a one-sample test with the RMSE's SE), ``-1`` significantly above.
    """
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}, got {reading!r}")
    z = checks.positive_scalar(z, "z")
    f = cell[reading]["filters"]
    out = {}
    for p in LEVELS:
        key = f"coverage_{round(100 * p)}"
        out[f"calibrated_{round(100 * p)}"] = {
            name: bool(abs(s[key] - p) <= z * scores.coverage_se(p, s["trials"]))
            for name, s in f.items()
        }
    if "paired" not in cell[reading]:
        return out
    verdict = scores.difference_verdict
    if "second_order" in f and "ekf" in f:
        d = paired_comparison(cell, reading, "second_order", "ekf")
        out["so_nearer_68"] = int(-verdict(d["coverage_68_gap"], d["coverage_68_gap_se"], z))
        out["so_nearer_68_se"] = d["coverage_68_gap_se"]
        out["so_rmse_se"] = d["rmse_ratio_se"] / d["rmse_ratio"]
        out["so_rmse"] = int(verdict(-np.log(d["rmse_ratio"]), out["so_rmse_se"], z))
    others = [name for name in f if name != "optimal"]
    if "optimal" in f and others:
        duels = [paired_comparison(cell, reading, "optimal", name) for name in others]
        ses = [d["rmse_ratio_se"] / d["rmse_ratio"] for d in duels]
        wins = [
            int(verdict(-np.log(d["rmse_ratio"]), se, z)) for d, se in zip(duels, ses, strict=True)
        ]
        out["po_best"] = 1 if min(wins) == 1 else (-1 if min(wins) == -1 else 0)
        out["po_best_se"] = max(ses)
    if "ekf" in f and reading == "fixed":
        ekf = f["ekf"]
        out["ekf_below"] = int(verdict(cell["bound_sd"] - ekf["rmse"], ekf["rmse_se"], z))
        out["ekf_below_se"] = ekf["rmse_se"]
    return out
