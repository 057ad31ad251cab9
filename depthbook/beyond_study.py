"""The chapter on the Monte Carlo study: calibration, the truths, the prior study.

Recommended import: ``from depthbook import beyond_study``.

* :func:`truth_study`: the study (:func:`depthcore.studies.monte_carlo.study`) at several
  true states, each filter's scores gathered over the truths by
  :func:`depthcore.studies.monte_carlo.gather_scores`;
* :func:`truth_study_figure`: its depth scores at each truth, with error bars;
* :func:`calibration` and :func:`prior_calibration`: the calibration plots of
  :func:`depthcore.studies.monte_carlo.study` and :func:`depthcore.studies.monte_carlo.prior_study`;
* :func:`truth_study_texts` and :func:`prior_study_texts`: the texts the
  chapter glues (the study's own, :func:`depthbook.formatting.study_texts`).
"""

from __future__ import annotations

import numpy as np

from depthbook.formatting import SCORE_TEXTS, row_extremes, value_se, vec
from depthbook.style import MIN_FONT, STYLE, WIDTH, legend_below, subplots
from depthcore.problem import checks
from depthcore.registry.estimates import QUANTITIES
from depthcore.registry.filters import NAMES
from depthcore.studies import monte_carlo
from depthcore.studies.monte_carlo import DEPTH_SCORES, gather_scores

# --- the Monte Carlo study at several noise levels --------------------------------------------


def truth_study(
    truths, rho: float, trials: int, seed, names=("optimal", "second_order", "ekf")
) -> dict:
    """:func:`depthcore.studies.monte_carlo.study` at each of several true states, with the paper's
    prior rule.

    Parameters
    ----------
    truths : array_like, shape (T, 3)
        True states ``(x, y, v)`` at time 3.
    rho : float
        Noise standard deviation, > 0.
    trials : int
        Trials per truth (the same seed for every truth).
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters, from :data:`depthcore.registry.filters.FILTERS`.

    Returns
    -------
    dict
        ``"truth"`` (T, 3), ``"valid_trials"`` (T,) and, per filter,
        ``{score: (T,)}`` for :data:`~depthcore.studies.monte_carlo.DEPTH_SCORES` (of the depth)
        and ``"nees"``,
        each with its standard error (:func:`~depthcore.studies.monte_carlo.gather_scores`).
    """
    truths = checks.finite_array(truths, "truths")
    if truths.ndim != 2 or truths.shape[1] != 3 or truths.shape[0] < 1:
        raise ValueError(f"truths must have shape (T, 3) with T >= 1, got shape {truths.shape}")
    rho = checks.positive_scalar(rho, "rho")
    runs = [
        monte_carlo.study(t, rho=rho, trials=trials, seed=seed, prior="paper", names=tuple(names))
        for t in truths
    ]
    out = {"truth": truths, "valid_trials": np.array([r["valid_trials"] for r in runs])}
    for name in names:
        out[name] = gather_scores([r["filters"][name] for r in runs], DEPTH_SCORES)
    return out


def calibration(result: dict, quantity: str = "depth", notes: dict | None = None):
    """Coverage of each filter's central intervals against their nominal level.

    Parameters
    ----------
    result : dict
        A study of :func:`depthcore.studies.monte_carlo.study`, whose filters'
        ``"calibration"`` curves are drawn.
    quantity : {"depth", "velocity"}
    notes : dict, optional
        ``{filter: text}``: a note on a filter's curve, with an arrow to its
        point at the level :data:`NOTE_LEVEL`.

    Returns
    -------
    matplotlib.figure.Figure
        The curves over the diagonal, where a calibrated filter's lies, inside a
        grey band of two binomial standard errors ``sqrt(p (1 - p) / n)`` about
        it over the study's ``n`` valid trials: a calibrated filter's curve
        leaves it at a level with probability about 5 %. Each point has bars of
        two binomial standard errors of its own coverage ``c``,
        ``sqrt(c (1 - c) / n)``.
    """

    fig, ax = subplots(figsize=(5.2, 5.0))
    levels = np.linspace(0.0, 1.0, 201)
    se = np.sqrt(levels * (1 - levels) / max(int(result["valid_trials"]), 1))
    ax.fill_between(
        levels,
        levels - 2 * se,
        levels + 2 * se,
        color="0.85",
        linewidth=0,
        label="two binomial SEs",
    )
    ax.plot([0, 1], [0, 1], color="0.6", linewidth=1, label="calibrated")
    n = max(int(result["valid_trials"]), 1)
    for name, f in result["filters"].items():
        cal = f["calibration"]
        covered = np.asarray(cal[quantity], dtype=float)
        ax.errorbar(
            np.asarray(cal["levels"], dtype=float),
            covered,
            yerr=2 * np.sqrt(covered * (1 - covered) / n),
            marker="o",
            markersize=3,
            elinewidth=0.8,
            **STYLE[name],
        )
    for name, text in (notes or {}).items():
        cal = result["filters"][name]["calibration"]
        j = int(np.argmin(np.abs(np.asarray(cal["levels"]) - NOTE_LEVEL)))
        x, y = float(cal["levels"][j]), float(cal[quantity][j])
        below = y < x - 0.05
        ax.annotate(
            text,
            (x, y),
            xytext=(x + 0.02, y - 0.3) if below else (x - 0.55, y + 0.15),
            fontsize=MIN_FONT,
            color=STYLE[name]["color"],
            arrowprops={"arrowstyle": "->", "color": STYLE[name]["color"]},
        )
    ax.set_xlabel("nominal level of the central interval")
    ax.set_ylabel(f"fraction of trials whose true {quantity} it covers")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.03)
    legend_below(fig, [ax], ncol=2)
    return fig


#: The nominal level at which :func:`calibration` points a note at a filter's curve.
NOTE_LEVEL = 0.6


def prior_calibration(result: dict):
    """The optimal filter's coverage over truths drawn from its prior, with binomial error bars.

    Parameters
    ----------
    result : dict
        :func:`depthcore.studies.monte_carlo.prior_study`'s result: its ``"levels"``,
        ``"coverage_se"`` and the depth's and velocity's ``"coverage"`` are drawn.

    Returns
    -------
    matplotlib.figure.Figure
        Nominal level against the fraction of trials covered, for the depth and
        the velocity, with bars of two binomial standard errors
        ``sqrt(p (1 - p) / n)`` about the nominal level.
    """

    levels = np.asarray(result["levels"])
    se = np.asarray(result["coverage_se"])
    fig, ax = subplots(figsize=(5.2, 4.6))
    ax.plot([0, 1], [0, 1], color="0.7", linewidth=1, label="calibrated")
    ax.fill_between(
        levels, levels - 2 * se, levels + 2 * se, color="0.85", label="two binomial SEs"
    )
    for quantity, marker, shift in (("depth", "o", -0.004), ("velocity", "s", 0.004)):
        ax.errorbar(
            levels + shift,
            result[quantity]["coverage"],
            yerr=2 * se,
            marker=marker,
            markersize=3,
            linestyle="none",
            capsize=2,
            label=f"optimal filter, {quantity}",
        )
    ax.set_xlabel("nominal level of the central interval")
    ax.set_ylabel("fraction of trials whose truth it covers")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig


#: The panels of :func:`truth_study_figure`: (score, axis label, logarithmic axis, reference).
TRUTH_PANELS = (
    ("bias", "bias of the depth mean", False, 0.0),
    ("rmse", "RMSE of the depth mean", True, None),
    ("coverage_68", "coverage of the central\n68 % depth interval", False, 0.68),
    ("nees", "mean NEES", True, 3.0),
)


def truth_study_figure(result: dict, labels=None):
    """:func:`truth_study`'s depth scores at each truth, with two-standard-error bars.

    Parameters
    ----------
    result : dict
        From :func:`truth_study`.
    labels : sequence of str, shape (T,), optional
        The truths' names on the horizontal axis; default their states.

    Returns
    -------
    matplotlib.figure.Figure
        Four panels, :data:`TRUTH_PANELS`, one point per filter and truth with
        bars of two Monte Carlo standard errors either side, and a grey line at
        the value of an unbiased or calibrated filter.
    """

    truths = np.asarray(result["truth"])
    if labels is None:
        labels = ["(" + ", ".join(f"{v:g}" for v in t) + ")" for t in truths]
    names = [n for n in NAMES if n in result]
    x = np.arange(len(truths), dtype=float)
    fig, axes = subplots(2, 2, figsize=(WIDTH, 5.6), sharex=True)
    for ax, (score, label, log, reference) in zip(axes.ravel(), TRUTH_PANELS, strict=True):
        for k, name in enumerate(names):
            r = result[name]
            ax.errorbar(
                x + 0.08 * (k - (len(names) - 1) / 2),
                r[score],
                yerr=2 * np.asarray(r[f"{score}_se"]),
                marker="o",
                markersize=4,
                capsize=2,
                linestyle="none",
                color=STYLE[name]["color"],
                label=STYLE[name]["label"],
            )
        if reference is not None:
            ax.axhline(reference, color="0.6", linewidth=1, zorder=0)
        if log:
            ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.set_xticks(x, labels)
        ax.set_xlim(x[0] - 0.4, x[-1] + 0.4)
    for ax in axes[-1]:
        ax.set_xlabel("true state $(x, y, v)$ at time 3")
    legend_below(fig, axes.ravel(), ncol=len(names))
    return fig


def truth_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`~depthbook.beyond_study.truth_study`'s rows, for glue.

    Returns
    -------
    dict
        For truth ``i``: ``"<prefix>_<i>_truth"`` (``"(2, 10, 2)"``),
        ``"<prefix>_<i>_trials"``, and per filter ``"<prefix>_<i>_<filter>_<score>"``
        for the depth's ``bias``, ``rmse``, ``mean_sd``
        (:data:`~depthbook.formatting.STUDY_DECIMALS`),
        ``cov68``, ``cov95`` (2 decimals) and ``nees`` (1 decimal), each also
        with ``_pm`` appended: ``"value ± standard error"``
        (:func:`~depthbook.formatting.value_se`); the least and greatest
        of each score over the truths, ``"<prefix>_<filter>_<key>_min_pm"``
        and ``"..._max_pm"`` (:func:`~depthbook.formatting.row_extremes`).
    """
    out = {}
    names = [n for n in NAMES if n in result]
    for i, truth in enumerate(result["truth"]):
        out[f"{prefix}_{i}_truth"] = "(" + ", ".join(f"{float(v):g}" for v in truth) + ")"
        out[f"{prefix}_{i}_trials"] = str(int(result["valid_trials"][i]))
        for name in names:
            r = result[name]
            row = f"{prefix}_{i}_{name}"
            for key, score, d in SCORE_TEXTS:
                out[f"{row}_{key}"] = f"{float(r[score][i]) + 0.0:.{d}f}"
                out[f"{row}_{key}_pm"] = value_se(r[score][i], r[f"{score}_se"][i], d)
    out.update(row_extremes(out, result, names, prefix))
    return out


def prior_study_texts(result: dict, prefix: str) -> dict:
    """Texts of :func:`depthcore.studies.monte_carlo.prior_study`'s result, for glue.

    Returns
    -------
    dict
        ``"<prefix>_trials"``, ``"<prefix>_prior_mean"``, ``"<prefix>_prior_scale"``,
        ``"<prefix>_false_alarm"`` and ``"<prefix>_test_level"`` (percent),
        ``"<prefix>_max_se"`` (largest deviation of a coverage from nominal, in
        binomial standard errors, 1 decimal), and per quantity ``q``:
        ``"<prefix>_<q>_coverage_50"``, ``_90`` and ``_95`` (2 decimals, when
        those levels are reported; with ``_pm`` appended, ``"value ± standard
        error"``, the binomial SE of a calibrated filter's coverage at that level),
        ``"<prefix>_<q>_ks"``, ``"<prefix>_<q>_chi2"`` (p-values, 2 decimals) and
        ``"<prefix>_<q>_verdict"``.
    """
    levels = list(result["levels"])
    se = np.asarray(result["coverage_se"])
    out = {
        f"{prefix}_trials": str(result["valid_trials"]),
        f"{prefix}_prior_mean": vec(result["prior_mean"], 1),
        f"{prefix}_prior_scale": f"{result['prior_cov'][0][0]:g}",
        f"{prefix}_false_alarm": f"{100 * result['false_alarm']:g} %",
        f"{prefix}_test_level": f"{50 * result['false_alarm']:g} %",
    }
    worst = 0.0
    for q in QUANTITIES:
        r = result[q]
        cov = np.asarray(r["coverage"])
        worst = max(worst, float(np.max(np.abs(cov - np.asarray(levels)) / se)))
        for p in (0.5, 0.9, 0.95):
            if p in levels:
                j = levels.index(p)
                out[f"{prefix}_{q}_coverage_{round(100 * p)}"] = f"{cov[j]:.2f}"
                out[f"{prefix}_{q}_coverage_{round(100 * p)}_pm"] = value_se(cov[j], se[j], 2)
        out[f"{prefix}_{q}_ks"] = f"{r['ks_pvalue']:.2f}"
        out[f"{prefix}_{q}_chi2"] = f"{r['chi2_pvalue']:.2f}"
        out[f"{prefix}_{q}_verdict"] = "passes" if r["calibrated"] else "fails"
    out[f"{prefix}_max_se"] = f"{worst:.1f}"
    return out


# --- do the errors hold? independent replicates and long runs -----------------------------------

#: The cells replicated (:func:`depthbook.studies.replication.referee_cells`): Figure 2's truth,
#: the exact filter, the paper's prior rule, three and thirty frames, blocks of 150 trials
#: (60 replicates) and of 2,000 (10), pooled into long runs of 29,000 trials.
REFEREE_CELLS = {"frames": (3, 30), "blocks": ((150, 60), (2000, 10)), "seed": 34}
