"""The book's intro: what the replication found, in numbers the other chapters compute.

Recommended import: ``from depthbook import intro``.

The verdicts themselves come from :mod:`depthbook.studies.verdicts`; this module
holds the extensions' headline: the coverage study of book/beyond_study.md
(:data:`COVERAGE_STUDY`), the costs in the benchmarks' records (:func:`cost_texts`)
and the study of the bound that
book/beyond_bound.md runs without process noise (:data:`BOUND_FRAMES`,
:data:`BOUND_STUDY`: the page passes these to its chapter's ``bound_study``
and reads its record) set against the Cramér–Rao bound (:func:`bound_texts`).
The README and the replication article print the same texts.
"""

from __future__ import annotations

import numpy as np

from depthbook import benchmark_tables
from depthbook.formatting import rho_label
from depthcore.analysis import bound
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE
from depthcore.problem.scenarios import SCENARIOS

#: The numbers of frames of the study of the bound that book/beyond_bound.md reads from
#: its record, without process noise.
BOUND_FRAMES = np.array([3, 5, 10, 20, 30])
#: That study's trials, seed, filters, particle trials and particles (its prior rule
#: is the paper's).
BOUND_STUDY = dict(
    trials=150,
    seed=1,
    names=(
        "optimal",
        "second_order",
        "ekf",
        "inverse_depth",
        "iterated",
        "ukf",
        "particle",
        "rbpf",
        "resample_move",
    ),
    particle_trials=30,
    n_particles=100,
)
#: The Monte Carlo study of the coverage that book/beyond_study.md reads from its record
#: (``depthcore.studies.monte_carlo.study`` at Figure 2's point and noise level).
COVERAGE_STUDY = {"trials": 2000, "seed": 1, "prior": "paper", "paired": True}
#: A filter is "on the bound" when its stated depth SD lies within this fraction of it
#: (book/beyond_bound.md).
NEAR = 0.10


def bound_texts(result: dict) -> dict[str, str]:
    """The EKF, the second-order filter and the iterated EKF against the Cramér–Rao bound.

    Parameters
    ----------
    result : dict
        What ``depthbook.beyond_bound.bound_study`` returns for
        :data:`BOUND_FRAMES` and :data:`BOUND_STUDY`, the prior rule ``"paper"``
        and no process noise: per filter, ``depth_error`` and ``depth_sd`` of
        shape ``(len(BOUND_FRAMES), trials)``.

    Returns
    -------
    dict
        ``trials``, ``rho2``, ``n_first``, ``n_second``, ``n_last``, ``ekf_sd3`` (the
        EKF's stated SD over the bound's at the first number of frames),
        ``ekf_rmse`` (the least ratio of its RMSE to the bound from the second on),
        ``z``, ``near``.

    Raises
    ------
    ValueError
        If the study does not bear the headline out: the EKF overconfident at
        every number of frames, its error over 1.5 times the bound from the second,
        the second-order filter and the iterated EKF on the bound.
    """
    fig2 = SCENARIOS["fig2"]
    prior_cov = PAPER_PRIOR_SCALE * np.eye(3)
    b = bound.posterior_bound(fig2.c, 3, int(BOUND_FRAMES[-1]), fig2.rho, prior_cov)
    bound_sd = np.sqrt(b[BOUND_FRAMES - 1, 1, 1])
    a = {
        name: bound.against_bound(result[name]["depth_error"], result[name]["depth_sd"], bound_sd)
        for name in ("ekf", "second_order", "iterated")
    }
    ekf_rmse = a["ekf"]["rmse_ratio"][1:].min()
    on_bound = all(
        not a[name]["overconfident"].any()
        and np.all(np.abs(a[name]["rmse_ratio"] - 1) < bound.Z * a[name]["rmse_ratio_se"])
        and np.all(np.abs(a[name]["sd_ratio"] - 1) < NEAR)
        for name in ("second_order", "iterated")
    )
    if not (a["ekf"]["overconfident"].all() and ekf_rmse > 1.5 and on_bound):
        raise ValueError("the study does not bear out the headline on the bound")
    return {
        "trials": f"{result['ekf']['depth_error'].shape[-1]}",
        "rho2": rho_label(fig2.rho),
        "n_first": f"{BOUND_FRAMES[0]}",
        "n_second": f"{BOUND_FRAMES[1]}",
        "n_last": f"{BOUND_FRAMES[-1]}",
        "ekf_sd3": f"{a['ekf']['sd_ratio'][0]:.2f}",
        "ekf_rmse": f"{ekf_rmse:.1f}",
        "z": f"{bound.Z:.2f}",
        "near": f"{100 * NEAR:g} %",
    }


def cost_texts(bench: dict) -> dict[str, str]:
    """The paper's filters' costs and the bank's against a particle filter, from the records.

    Parameters
    ----------
    bench : dict
        The records of ``bench_optimal`` and ``bench_bank``, by name
        (:func:`depthbook.provenance.benchmarks.read`).

    Returns
    -------
    dict
        The texts of the headline on the cost, by name.
    """
    t = benchmark_tables.bench_texts("bench_optimal", bench["bench_optimal"])
    t |= benchmark_tables.bench_texts("bench_bank", bench["bench_bank"])
    triple = bench["bench_optimal"]["results"]["per_triple"]
    matched = bench["bench_bank"]["results"]["matched_accuracy"]
    if not (float(t["opt_optimal_ekf_min"]) > 1 and matched["ratio"] > 1):
        raise ValueError("the benchmarks' records do not bear out the headline on the cost")
    figures = [SCENARIOS[key].figure for key in triple["keys"]]
    dates = {bench[name]["date"][:10] for name in ("bench_optimal", "bench_bank")}
    return {
        "optimal_ekf_min": t["opt_optimal_ekf_min"],
        "optimal_ekf_max": t["opt_optimal_ekf_max"],
        "figures": "Figures " + ", ".join(str(f) for f in figures[:-1]) + f" and {figures[-1]}",
        "grid_ratio": t["opt_grid_ratio"],
        "bank_trials": t["bank_matched_trials"],
        "bank_frames": t["bank_matched_frames"],
        "bank_particles": t["bank_matched_largest"],
        "bank_ratio": t["bank_matched_ratio"],
        "bank_error": t["bank_matched_largest_error"],
        "date": " and ".join(sorted(dates)),
    }
