"""Do a study's standard errors hold? The study replicated on independent seeds.

Recommended import: ``from depthbook.studies import replication``.

A standard error is a claim about the spread of a score over studies that
were never run. :func:`replicate` runs them: the study of
:func:`depthcore.studies.monte_carlo.study` ``R`` times, each on a child of
one ``SeedSequence`` (so the replicates are independent, and each is the study
a reader would get with that seed), each streaming its chunks through
:func:`depthcore.studies.tasks.fold_chunks` (on a Dask cluster when given one).
:func:`spread` sets the errors each replicate states beside the spread of its
scores across the replicates, with the standard error of that spread, and
counts the replicates whose stated interval holds the pooled value.

Where the errors are heavy-tailed the delta method's error of an RMSE is right
on average (its square is unbiased) but short in the typical study: a study
that happens to hold none of the rare large errors states a small RMSE and a
small error together. No error computed from the trials of one study can see
the tails those trials miss; the median absolute error's distribution-free
interval (:func:`depthcore.studies.medians.median_ranks`) does not need them,
and holds at its level whatever the law of the errors, which :func:`spread`
checks across the replicates too.
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks
from depthcore.studies import monte_carlo

#: The depth scores each replicate keeps, with the key of the error it states (or None).
SCORES = {
    "rmse": "rmse_se",
    "coverage_68": "coverage_68_se",
    "median_abs_error": None,
    "rmse_kept": "rmse_kept_se",
}

#: The critical value of the intervals whose holding :func:`spread` counts (two-sided 95 %).
Z95 = 1.959963984540054


def replicate(trials: int, replicates: int, seed, names=("optimal",), **study) -> dict:
    """:func:`~depthcore.studies.monte_carlo.study` on ``replicates`` independent seeds.

    Parameters
    ----------
    trials : int
        Trials of each replicate, >= 2.
    replicates : int
        ``R >= 2``.
    seed : int or numpy.random.SeedSequence
        Replicate ``r`` runs on its child ``r``.
    names : sequence of str
        The filters.
    **study
        The other arguments of :func:`~depthcore.studies.monte_carlo.study`
        (``truth``, ``rho``, ``prior``, ``frames``, ``client``, ...).

    Returns
    -------
    dict
        ``"trials"``, ``"replicates"``, ``"valid"`` (R,), and per filter, for
        each depth score of :data:`SCORES`, ``{score: (R,), error: (R,)}``,
        with ``"median_abs_error_ci"`` (R, 2) and ``"divergent"`` (R,) (counts).
    """
    trials = checks.count(trials, "trials")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    r = checks.count(replicates, "replicates")
    if r < 2:
        raise ValueError(f"replicates must be at least 2, got {r}")
    seeds = checks.spawn(checks.seed_sequence(seed), r)
    runs = [monte_carlo.study(trials=trials, seed=s, names=names, **study) for s in seeds]
    out = {
        "trials": trials,
        "replicates": r,
        "valid": np.array([x["valid_trials"] for x in runs]),
    }
    for name in names:
        depth = [x["filters"][name]["depth"] for x in runs]
        f = {}
        for score, error in SCORES.items():
            f[score] = np.array([d[score] for d in depth], dtype=float)
            if error is not None:
                f[error] = np.array([d[error] for d in depth], dtype=float)
        f["median_abs_error_ci"] = np.array(
            [[np.inf if v is None else v for v in d["median_abs_error_ci"]] for d in depth]
        )
        f["divergent"] = np.array([x["filters"][name]["divergent"]["count"] for x in runs])
        out[name] = f
    return out


def spread(values, errors=None, reference=None, z: float = Z95) -> dict:
    """A score's spread across replicates against the errors the replicates state.

    Parameters
    ----------
    values : array_like, shape (R,)
        The score of each replicate, ``R >= 4``.
    errors : array_like, shape (R,), optional
        The standard error each replicate states.
    reference : float, optional
        The large-sample value the stated intervals should hold; default the
        replicates' mean.
    z : float
        Half-width of the stated intervals, in stated errors.

    Returns
    -------
    dict
        ``"mean"``, ``"actual"`` (the SD across replicates, ``ddof=1``) and
        ``"actual_se"`` (its standard error, from the replicates' fourth
        moment: ``sqrt(Var(s**2)) / (2 s)`` with ``Var(s**2) ~ (m4 - s**4 (R -
        3) / (R - 1)) / R``, exact for normal replicates to ``O(1 / R)`` and
        not assuming normality); with ``errors``, ``"stated"`` (their root mean
        square), ``"stated_median"``, ``"ratio"`` (``actual / stated``) and
        ``"held"``, the fraction of replicates whose interval ``value ± z
        error`` holds ``reference``, with ``"held_se"``.
    """
    v = checks.finite_array(values, "values")
    if v.ndim != 1 or len(v) < 4:
        raise ValueError(f"values must hold at least 4 replicates, got shape {v.shape}")
    r = len(v)
    s = float(np.std(v, ddof=1))
    m4 = float(np.mean((v - v.mean()) ** 4))
    var_s2 = max(m4 - s**4 * (r - 3) / (r - 1), 0.0) / r
    out = {
        "mean": float(v.mean()),
        "actual": s,
        "actual_se": float(np.sqrt(var_s2) / (2 * s)) if s > 0 else 0.0,
    }
    if errors is not None:
        e = checks.finite_array(errors, "errors")
        if e.shape != v.shape:
            raise ValueError(f"errors must have the shape of values, {v.shape}, got {e.shape}")
        ref = out["mean"] if reference is None else float(reference)
        held = np.abs(v - ref) <= checks.positive_scalar(z, "z") * e
        out["stated"] = float(np.sqrt(np.mean(e**2)))
        out["stated_median"] = float(np.median(e))
        out["ratio"] = s / out["stated"] if out["stated"] > 0 else float("inf")
        out["held"] = float(np.mean(held))
        out["held_se"] = float(np.sqrt(out["held"] * (1 - out["held"]) / r))
    return out


def pooled(values, trials) -> dict:
    """A mean score pooled over independent replicates, with the error of their spread.

    Parameters
    ----------
    values : sequence of array_like
        Groups of replicates (one group per size of replicate), each (R_g,),
        ``R_g >= 2``: a mean over the replicate's trials (a mean squared error,
        a coverage).
    trials : sequence of array_like
        The trials behind each value, in the same groups.

    Returns
    -------
    dict
        ``"value"``, the trial-weighted mean over every replicate, and ``"se"``,
        ``sqrt(sum_r n_r**2 s_g**2) / sum_r n_r``, ``s_g`` the SD across the
        replicates of each one's group (batch means, the replicates the
        batches): it does not rest on the trials' variance formula.
    """
    num = var = den = 0.0
    for v, n in zip(values, trials, strict=True):
        v = checks.finite_array(v, "values")
        n = checks.finite_array(n, "trials")
        if v.shape != n.shape or v.ndim != 1 or len(v) < 2:
            raise ValueError("values and trials must be groups of at least 2 replicates alike")
        num += float(np.sum(n * v))
        den += float(np.sum(n))
        var += float(np.sum(n**2)) * float(np.var(v, ddof=1))
    return {"value": num / den, "se": float(np.sqrt(var)) / den}


def referee_cells(frames, blocks, seed, names=("optimal",), **study) -> dict:
    """Independent replicates of the study at each number of frames and block size, compared.

    Parameters
    ----------
    frames : sequence of int
        Numbers of frames ``N`` (the study's ``frames``).
    blocks : sequence of (int, int)
        ``(trials, replicates)`` of each block size.
    seed : int or numpy.random.SeedSequence
        Cell ``(N, block)`` draws from the child ``i`` of the seed, ``i`` its
        place in ``frames x blocks``.
    names : sequence of str
    **study
        As for :func:`replicate`.

    Returns
    -------
    dict
        ``{N: {"blocks": {trials: {"replicates": result, score: spread}},
        "pooled": {name: {"mse", "rmse", "coverage_68", "median_abs_error"}}}}``:
        each block's ``result`` is :func:`replicate`'s and ``spread`` is
        :func:`spread` of each filter's depth score against the pooled value;
        the pooled values are over every replicate of the cell (:func:`pooled`;
        the RMSE's error by the delta method from the pooled MSE's, the median
        absolute error the median of the replicates' with the SD of the largest
        blocks' over their square root).
    """
    frames = [checks.frames(n) for n in np.atleast_1d(frames)]
    blocks = [(checks.count(t, "blocks"), checks.count(r, "blocks")) for t, r in blocks]
    seeds = iter(checks.spawn(checks.seed_sequence(seed), len(frames) * len(blocks)))
    out = {}
    for n_frames in frames:
        runs = {t: replicate(t, r, next(seeds), names, frames=n_frames, **study) for t, r in blocks}
        cell = {"blocks": {}, "pooled": {}}
        for name in names:
            mse = pooled(
                [runs[t][name]["rmse"] ** 2 for t, _ in blocks],
                [runs[t]["valid"] for t, _ in blocks],
            )
            rmse = float(np.sqrt(mse["value"]))
            cov = pooled(
                [runs[t][name]["coverage_68"] for t, _ in blocks],
                [runs[t]["valid"] for t, _ in blocks],
            )
            largest = runs[max(t for t, _ in blocks)][name]["median_abs_error"]
            cell["pooled"][name] = {
                "mse": mse,
                "rmse": {"value": rmse, "se": mse["se"] / (2 * rmse)},
                "coverage_68": cov,
                "median_abs_error": {
                    "value": float(np.median(largest)),
                    "se": float(np.std(largest, ddof=1) / np.sqrt(len(largest))),
                },
            }
        for t, _ in blocks:
            block = {"replicates": runs[t]}
            for name in names:
                f, p = runs[t][name], cell["pooled"][name]
                block[name] = {
                    "rmse": spread(f["rmse"], f["rmse_se"], p["rmse"]["value"]),
                    "coverage_68": spread(
                        f["coverage_68"], f["coverage_68_se"], p["coverage_68"]["value"]
                    ),
                    "median_abs_error": spread(f["median_abs_error"]),
                    "median_held": _held(f["median_abs_error_ci"], p["median_abs_error"]["value"]),
                }
            cell["blocks"][t] = block
        out[n_frames] = cell
    return out


def _held(ci, value: float) -> dict:
    """The fraction of intervals ``ci`` (R, 2) holding ``value``, with its binomial SE."""
    held = (ci[:, 0] <= value) & (value <= ci[:, 1])
    p = float(np.mean(held))
    return {"fraction": p, "se": float(np.sqrt(p * (1 - p) / len(held)))}


def fixed_truth_replicates(
    truth,
    rho: float,
    prior_scale: float,
    prior_velocity: float,
    trials: int,
    replicates: int,
    seed,
    name: str = "optimal",
    client=None,
) -> dict:
    """One filter's depth scores at a fixed truth under a fixed prior, on independent replicates.

    The fixed-truth reading of :func:`depthbook.studies.hardness.hard_cell`
    (its prior :func:`~depthbook.studies.hardness.prior_for`, its scores
    :func:`~depthbook.studies.hardness.score_estimates`), run ``replicates``
    times on the children of ``seed``, each replicate a task of
    :func:`depthcore.studies.tasks.fold_chunks`.

    Returns
    -------
    dict
        ``"bound_sd"``, ``"valid"`` (R,), and ``{score: (R,), score + "_se": (R,)}``
        for ``"rmse"`` and ``"coverage_68"``; ``"pooled"``: the pooled RMSE
        (through the MSE) and 68 % coverage with their errors (:func:`pooled`).
    """
    from depthbook.studies import hardness
    from depthcore.analysis import bound
    from depthcore.studies import tasks

    truth = checks.finite_array(truth, "truth", (3,))
    r = checks.count(replicates, "replicates")
    if r < 2:
        raise ValueError(f"replicates must be at least 2, got {r}")
    pm, pc = hardness.prior_for(truth, prior_scale, prior_velocity)
    seeds = checks.spawn(checks.seed_sequence(seed), r)
    items = ((truth, rho, prior_scale, pm, pc, trials, s, name) for s in seeds)
    rows = []
    tasks.fold_chunks(_fixed_replicate, items, lambda k, x: rows.append(x), client=client)
    out = {
        "bound_sd": float(np.sqrt(bound.posterior_bound(truth, 3, 3, rho, pc)[-1, 1, 1])),
        "valid": np.array([x["trials"] for x in rows]),
    }
    for key in ("rmse", "rmse_se", "coverage_68", "coverage_68_se"):
        out[key] = np.array([x[key] for x in rows], dtype=float)
    mse = pooled([out["rmse"] ** 2], [out["valid"]])
    rmse = float(np.sqrt(mse["value"]))
    out["pooled"] = {
        "rmse": {"value": rmse, "se": mse["se"] / (2 * rmse)},
        "coverage_68": pooled([out["coverage_68"]], [out["valid"]]),
    }
    return out


def _fixed_replicate(item) -> dict:
    """One replicate of :func:`fixed_truth_replicates`: a task of ``fold_chunks``."""
    from depthbook.studies import hardness
    from depthcore.studies import trials as study_trials

    truth, rho, scale, pm, pc, trials, seed, name = item
    drawn = study_trials.simulate(truth, rho, trials, np.random.default_rng(seed), "fixed", scale)
    depth = drawn.truths[:, 1]
    est = hardness.filter_estimates(drawn.mu, rho, pm, pc, depth, (name,))
    return hardness.score_estimates(est, depth)[name]


#: How many combined standard errors a glued number may lie from its long run's value.
AGREEMENT_Z = 3.0


def agreement(value, se, reference, reference_se, z: float = AGREEMENT_Z) -> dict:
    """Whether a number lies within ``z`` combined standard errors of a long run's value.

    Parameters
    ----------
    value, se : float
        The number and its stated standard error (>= 0).
    reference, reference_se : float
        The long run's value and its standard error (>= 0).
    z : float
        > 0.

    Returns
    -------
    dict
        ``"z"``: ``(value - reference) / sqrt(se**2 + reference_se**2)`` and
        ``"agrees"``: ``|z| <= z``.
    """
    se, reference_se = (checks.nonnegative_scalar(v, "se") for v in (se, reference_se))
    combined = float(np.hypot(se, reference_se))
    if combined == 0:
        raise ValueError("se: a number and its reference without errors cannot be compared")
    score = (float(value) - float(reference)) / combined
    return {"z": score, "agrees": bool(abs(score) <= checks.positive_scalar(z, "z"))}
