"""The chapter on the paper's conjecture: the second-order filter against the EKF.

Recommended import: ``from depthbook import beyond_conjecture``.

:func:`conjecture_study` scores both filters against the optimal filter and
the truth over frames, noise levels and depths, with their paired
:func:`comparisons` over the same trials; :func:`conjecture_wins` says where
one beats the other by more than chance (a paired test per cell),
:func:`conjecture_figure` draws it and :func:`conjecture_texts` and
:func:`extreme_text` give the texts the chapter glues.
"""

from __future__ import annotations

import numpy as np

from depthbook.formatting import rho_label, value_se
from depthbook.studies.frames import frames_study
from depthbook.style import WIDTH, log_bars, subplots
from depthcore.problem import checks
from depthcore.registry import filters as _filters
from depthcore.studies import pairs as study_pairs
from depthcore.studies import scores as study_scores
from depthcore.studies.scores import (
    COVERAGE_Z,
    TEST_POWER,
    coverage_test,
    detectable_difference,
    detectable_shift,
)


def conjecture_study(
    frames,
    rhos,
    depths,
    trials: int,
    seed,
    prior: str = "fixed",
    bearing: float = 0.2,
) -> dict:
    """The second-order filter against the EKF, scored against the optimal filter and the truth.

    For every number of frames, noise level and depth,
    :func:`~depthbook.studies.frames.frames_study`
    of the optimal, second-order and EKF filters, the truth at time 3 being
    ``(bearing * y, y, bearing * y)``: Figure 2's ``c = (1.2, 6, 1.2)`` scaled
    to depth ``y`` (its bearings at times 1-3 are nearly those of Eq. (17)).

    Parameters
    ----------
    frames : sequence of int, shape (F,)
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    depths : array_like, shape (D,)
        Depths at time 3, each > 2 (the point in front of the camera at time 1).
    trials : int
        Trials per setting (the same seed in each).
    seed : int or numpy.random.SeedSequence
    prior : {"paper", "fixed"}
    bearing : float
        Bearing at time 3, and lateral velocity per unit of depth.

    Returns
    -------
    dict
        ``"frames"`` (F,), ``"rho"`` (R,), ``"depth"`` (D,), ``"truth"`` (D, 3)
        and per filter (``"optimal"``, ``"second_order"``, ``"ekf"``) the
        scores of :func:`~depthbook.studies.frames.frames_study` as arrays of shape (R, D, F);
        ``"paired"``: the :func:`comparisons` of the second-order filter and
        the EKF over the same trials, each an array (R, D, F).
    """
    rhos = checks.nonempty(np.atleast_1d(checks.positive_array(rhos, "rhos")), "rhos")
    depths = checks.nonempty(np.atleast_1d(checks.positive_array(depths, "depths")), "depths")
    if np.any(depths <= 2):
        raise ValueError("depths must each exceed 2 (the point in front of the camera at time 1)")
    bearing = float(checks.finite_array(bearing, "bearing"))
    truths = np.stack([bearing * depths, depths, bearing * depths], axis=1)
    names = ("optimal", "second_order", "ekf")
    runs = [
        [frames_study(frames, trials, seed, names, prior, truth=t, rho=float(r)) for t in truths]
        for r in rhos
    ]
    out = {"frames": runs[0][0]["frames"], "rho": rhos, "depth": depths, "truth": truths}
    for name in names:
        out[name] = {
            s: np.array([[run[name][s] for run in row] for row in runs]) for s in runs[0][0][name]
        }
    cells = [[[comparisons(p) for p in run["paired"]] for run in row] for row in runs]
    out["paired"] = {
        k: np.array([[[c[k] for c in cell] for cell in row] for row in cells])
        for k in cells[0][0][0]
    }
    return out


def comparisons(summary: dict) -> dict:
    """The second-order filter against the EKF over the same trials, each with its paired SE.

    Parameters
    ----------
    summary : dict
        The co-moments of the filters' per-trial depth scores,
        ``study(..., paired=True)["paired"]`` with the optimal, second-order
        and EKF filters.

    Returns
    -------
    dict of float
        ``"hellinger_difference"`` (second-order less EKF mean Hellinger
        distance to the optimal filter, :func:`~depthcore.studies.pairs.paired_difference_se`),
        ``"hellinger_ratio"`` (EKF over second-order,
        :func:`~depthcore.studies.pairs.mean_ratio_se`), ``"rmse_ratio"``
        (second-order RMSE over the EKF's) and ``"ekf_rmse_ratio"`` (its
        inverse, :func:`~depthcore.studies.pairs.rmse_ratio_se`),
        ``"coverage_68_gap"`` and ``"coverage_95_gap"`` (how much farther the
        second-order coverage is from its level than the EKF's,
        :func:`~depthcore.studies.pairs.coverage_gap_difference`), each with
        ``"<key>_se"``, and ``"trials"``.
    """
    so, ekf = "second_order", "ekf"
    out = {}
    m, c, n = study_pairs.pair_of(summary, (so, "hellinger"), (ekf, "hellinger"))
    out["hellinger_difference"] = float(m[0] - m[1])
    out["hellinger_difference_se"] = float(study_pairs.paired_difference_se(c, n))
    m, c, n = study_pairs.pair_of(summary, (ekf, "hellinger"), (so, "hellinger"))
    out["hellinger_ratio"] = float(m[0] / m[1])
    out["hellinger_ratio_se"] = float(study_pairs.mean_ratio_se(m, c, n))
    duel = study_pairs.compare(summary, so, ekf, (0.68, 0.95))
    inverse = study_pairs.compare(summary, ekf, so, ())
    out["rmse_ratio"], out["rmse_ratio_se"] = duel.pop("rmse_ratio"), duel.pop("rmse_ratio_se")
    out["ekf_rmse_ratio"] = inverse["rmse_ratio"]
    out["ekf_rmse_ratio_se"] = inverse["rmse_ratio_se"]
    return out | duel


#: The duels of :func:`conjecture_wins`: each score's paired difference (positive where the
#: second-order filter does worse) and its SE, from :func:`comparisons`.
DUELS = {
    "hellinger": "hellinger_difference",
    "coverage_68": "coverage_68_gap",
    "coverage_95": "coverage_95_gap",
}


def conjecture_wins(result: dict, z: float = COVERAGE_Z) -> dict:
    """Where the second-order filter beats the EKF, cell by cell of :func:`conjecture_study`.

    Each duel is a paired two-sided test at critical value ``z``
    (:func:`~depthcore.studies.scores.difference_verdict`) over the trials both
    filters ran on, with three outcomes per cell: ``1`` the second-order filter
    significantly better, ``-1`` the EKF significantly better, ``0`` no
    detectable difference.

    Parameters
    ----------
    result : dict
        From :func:`conjecture_study`; its arrays have shape (R, D, F).
    z : float
        Critical value of the tests and of
        :func:`~depthcore.studies.scores.coverage_test`.

    Returns
    -------
    dict
        Integer arrays of shape (R, D, F): ``"hellinger"`` (the second-order
        depth marginal nearer the optimal one: the paired difference of the
        mean Hellinger distances), ``"rmse"`` (its depth mean's RMSE smaller:
        the logarithm of the ratio of the RMSEs against 0), and for each level
        ``"coverage_68"``, ``"coverage_95"`` (its coverage nearer the level:
        the paired difference of the distances from it); the same with
        ``"_se"`` appended, the SE (R, D, F) each test used (the RMSE
        ratio's relative SE for ``"rmse"``); ``"calibrated_<level>"`` ``{name: (R, D, F)}``,
        the verdicts of :func:`~depthcore.studies.scores.coverage_test`
        for ``"optimal"``, ``"second_order"`` and ``"ekf"``.
    """
    pairs = result["paired"]
    out = {}
    for score, key in DUELS.items():
        out[score] = -study_scores.difference_verdict(pairs[key], pairs[f"{key}_se"], z)
        out[f"{score}_se"] = pairs[f"{key}_se"]
    # the ratio's logarithm against 0: its SE is the ratio's relative SE
    out["rmse_se"] = pairs["rmse_ratio_se"] / pairs["rmse_ratio"]
    out["rmse"] = study_scores.difference_verdict(-np.log(pairs["rmse_ratio"]), out["rmse_se"], z)
    for level in (68, 95):
        tests = {
            name: coverage_test(
                result[name][f"coverage_{level}"], level / 100, result[name]["trials"], z
            )
            for name in ("optimal", "second_order", "ekf")
        }
        out[f"calibrated_{level}"] = {
            name: t["verdict"] == "calibrated" for name, t in tests.items()
        }
    return out


def conjecture_figure(result: dict, scores=("hellinger", "coverage_68", "rmse")):
    """The second-order filter (solid) and the EKF (dotted) against ``rho``, per depth and ``N``.

    Parameters
    ----------
    result : dict
        From :func:`depthbook.beyond_conjecture.conjecture_study`.
    scores : sequence of str
        Rows: ``"hellinger"``, ``"coverage_68"``, ``"coverage_95"``, ``"rmse"``, ``"nees"``.

    Returns
    -------
    matplotlib.figure.Figure
        One row per score, one column per number of frames, each score with
        two-standard-error bars (``"<score>_se"``; on a log axis the lower bar
        stops short of zero); the two filters a little apart along ``rho``. The
        legend gives the depths' colours and the filters' line styles once each.
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    labels = {
        "hellinger": "Hellinger distance\nto $p_o$",
        "coverage_68": "coverage of the\ncentral 68 % interval",
        "coverage_95": "coverage of the\ncentral 95 % interval",
        "rmse": "RMSE of the\ndepth mean",
        "nees": "mean NEES",
    }
    nominal = {"coverage_68": 0.68, "coverage_95": 0.95, "nees": 3.0}
    frames = result["frames"]
    fig, axes = subplots(
        len(scores),
        len(frames),
        figsize=(WIDTH, 2.2 * len(scores) + 1.2),
        sharex=True,
        sharey="row",
        squeeze=False,
    )
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, len(result["depth"])))
    # the two filters a little apart along the (logarithmic) noise axis
    styles = (("second_order", "-", 0.95), ("ekf", ":", 1.05))
    rho = np.asarray(result["rho"], dtype=float)
    for j, n in enumerate(frames):
        axes[0, j].set_title(f"$N = {int(n)}$")
        for i, score in enumerate(scores):
            ax = axes[i, j]
            log_y = score in ("rmse", "nees")
            for d, colour in enumerate(colours):
                for name, style, shift in styles:
                    y = result[name][score][:, d, j]
                    se = result[name][f"{score}_se"][:, d, j]
                    ax.errorbar(
                        rho * shift,
                        y,
                        yerr=log_bars(y, se) if log_y else 2 * se,
                        color=colour,
                        linestyle=style,
                        marker="o",
                        markersize=2.5,
                        elinewidth=0.8,
                        capsize=1.5,
                    )
            if score in nominal:
                ax.axhline(nominal[score], color="0.6", linewidth=1)
            if log_y:
                ax.set_yscale("log")
            ax.set_xscale("log")
            ticks = rho[::2]
            ax.set_xticks(ticks, [rho_label(r) for r in ticks])
            ax.set_xticks([], minor=True)
            if j == 0:
                ax.set_ylabel(labels[score])
        axes[-1, j].set_xlabel(r"noise level $\rho$")
    handles = [
        Line2D([], [], color=colour, marker="o", markersize=3, label=f"depth $y = {depth:g}$")
        for depth, colour in zip(result["depth"], colours, strict=True)
    ] + [
        Line2D([], [], color="0.3", linestyle=style, label=_filters.FILTERS[name].label)
        for name, style, _ in styles
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, frameon=False)
    return fig


def dominant_trials(rmse, rmse_se):
    """How many equal far-off trials would give an RMSE its standard error.

    When ``k`` of ``n`` trials carry nearly all the squared error, equally,
    the RMSE is ``e sqrt(k / n)`` and its delta-method standard error
    (:func:`depthcore.analysis.bound.against_bound`) about ``e / (2 sqrt(n))``,
    so ``k`` is about ``(rmse / (2 rmse_se))**2``: near 1 when a single trial
    drives the RMSE, large when the errors are spread evenly.

    Parameters
    ----------
    rmse, rmse_se : array_like, shape (...)
        RMSEs (> 0) and their standard errors.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``(rmse / (2 rmse_se))**2``; infinite where the SE is zero.
    """
    rmse = np.asarray(rmse, dtype=float)
    se = np.asarray(rmse_se, dtype=float)
    with np.errstate(divide="ignore"):
        return (rmse / (2.0 * se)) ** 2


def conjecture_texts(result: dict, wins: dict, prefix: str, z: float = COVERAGE_Z) -> dict:
    """Counts of the cells of :func:`~depthbook.beyond_conjecture.conjecture_wins`, for glue.

    Returns
    -------
    dict
        ``"<prefix>_cells"`` (cells per ``N``: noise levels times depths) and,
        for the ``j``-th ``N``: ``"<prefix>_<j>_x"`` (``N``),
        ``"<prefix>_<j>_<score>"`` (cells where the second-order filter wins
        its paired test, for ``"hellinger"``, ``"rmse"``, ``"coverage_68"``,
        ``"coverage_95"``), ``"<prefix>_<j>_<score>_ties"`` (cells where the
        test detects no difference), ``"<prefix>_<j>_<score>_losses"`` (cells
        where the EKF wins) and ``"<prefix>_<j>_<score>_table"`` (the three
        as ``"wins / ties / losses"``); ``"<prefix>_detect_<score>"``, the
        largest over the cells of the difference the paired test finds with
        power :data:`~depthcore.studies.scores.TEST_POWER`
        (:func:`~depthcore.studies.scores.detectable_shift`): of the mean
        Hellinger distances, of the RMSEs (the factor by which they differ,
        from the shift of their ratio's logarithm), of the coverages'
        distances from their levels (in percentage points);
        and ``"<prefix>_<j>_cal<level>_<filter>"`` (cells where the filter's
        coverage passes the test) for ``"optimal"``, ``"second_order"``, ``"ekf"``.
        The power of those verdicts: ``"<prefix>_test_size"`` (the test's
        false alarm rate at ``z``, in percent), ``"<prefix>_test_trials"``
        (the most trials behind a coverage), ``"<prefix>_test_power"``
        (:data:`~depthcore.studies.scores.TEST_POWER`, in percent) and
        ``"<prefix>_detect_<level>"``, the coverage error that the test finds
        with that power at that many trials
        (:func:`~depthcore.studies.scores.detectable_difference`), in percentage
        points; the same with ``_min`` appended for the fewest trials behind a
        coverage (trials without a noise-free solution in front of the camera are left out).
    """
    from scipy.special import ndtr

    n_rho, n_depth = len(result["rho"]), len(result["depth"])
    out = {f"{prefix}_cells": str(n_rho * n_depth)}
    size = 2.0 * float(ndtr(-abs(z)))
    counts = [result[name]["trials"] for name in ("optimal", "second_order", "ekf")]
    out[f"{prefix}_test_size"] = f"{100 * size:.0f} %"
    out[f"{prefix}_test_power"] = f"{100 * TEST_POWER:.0f} %"
    for suffix, trials in (
        ("", int(max(np.max(c) for c in counts))),
        ("_min", int(min(np.min(c) for c in counts))),
    ):
        out[f"{prefix}_test_trials{suffix}"] = str(trials)
        for level in (68, 95):
            d = float(detectable_difference(level / 100, trials, size, TEST_POWER))
            out[f"{prefix}_detect_{level}{suffix}"] = f"{100 * d:.1f} points"
    for score in ("hellinger", "rmse", "coverage_68", "coverage_95"):
        d = float(np.max(detectable_shift(wins[f"{score}_se"], size, TEST_POWER)))
        if score == "hellinger":
            out[f"{prefix}_detect_{score}"] = f"{d:.3f}"
        elif score == "rmse":  # a shift of the log-ratio, as a factor
            out[f"{prefix}_detect_{score}"] = f"{np.exp(d):.2f}"
        else:
            out[f"{prefix}_detect_{score}"] = f"{100 * d:.1f} points"
    for j, n in enumerate(result["frames"]):
        out[f"{prefix}_{j}_x"] = str(int(n))
        for score in ("hellinger", "rmse", "coverage_68", "coverage_95"):
            w = wins[score][..., j]
            counts = [int(np.sum(w == v)) for v in (1, 0, -1)]
            out[f"{prefix}_{j}_{score}"] = str(counts[0])
            out[f"{prefix}_{j}_{score}_ties"] = str(counts[1])
            out[f"{prefix}_{j}_{score}_losses"] = str(counts[2])
            out[f"{prefix}_{j}_{score}_table"] = " / ".join(str(c) for c in counts)
        for level in (68, 95):
            for name, ok in wins[f"calibrated_{level}"].items():
                out[f"{prefix}_{j}_cal{level}_{name}"] = str(int(np.sum(ok[..., j])))
    return out


def extreme_text(result: dict, key: str, which: str, cells=(...,), decimals: int = 2) -> str:
    """The least or greatest of a paired comparison over some cells, ``"value ± SE"``.

    Parameters
    ----------
    result : dict
        From :func:`conjecture_study`.
    key : str
        A ratio of :func:`comparisons`, e.g. ``"rmse_ratio"``, whose SE is ``"<key>_se"``.
    which : {"min", "max"}
    cells : tuple
        An index into the (R, D, F) arrays: the cells searched (default all).
    decimals : int
        Of :func:`~depthbook.formatting.value_se`.

    Returns
    -------
    str
        The extreme cell's value with its own SE.
    """
    if which not in ("min", "max"):
        raise ValueError(f"which must be 'min' or 'max', got {which!r}")
    values = np.asarray(result["paired"][key])[cells].ravel()
    ses = np.asarray(result["paired"][f"{key}_se"])[cells].ravel()
    i = int(np.argmin(values) if which == "min" else np.argmax(values))
    return value_se(values[i], ses[i], decimals)
