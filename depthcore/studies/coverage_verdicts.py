"""Verdicts on a coverage that its trials can carry: within a tolerance, outside it, or undecided.

Recommended import: ``from depthcore.studies import coverage_verdicts``.

A coverage ``c`` of a nominal level ``L`` (the 68 % interval's) from ``k``
of ``n`` trials is **calibrated** where both one-sided binomial tests, of
``c <= L - t`` and of ``c >= L + t``, reject (two one-sided tests, TOST
[schuirmann1987]_; :func:`equivalence_pvalue`), **miscalibrated** where one
of ``c >= L - t`` or ``c <= L + t`` is rejected (:func:`outside_pvalue`),
and **undecided** otherwise. Each claim's tests over a filter's cells are one
family, whose false-discovery rate Benjamini and Hochberg's procedure
[benjamini1995]_ holds at :data:`FALSE_DISCOVERY` (:func:`verdicts`).

**The tolerance and the trials** are chosen together: a coverage :data:`NEAR`
of ``L`` is to be called calibrated, and one :data:`FAR` off (0.634, a
Gaussian stand-in's for the exact prior) miscalibrated, each with probability
:data:`DESIGN_POWER` (:func:`power`); :func:`trials_needed` gives the trials
for a tolerance, and the tolerance between the two that needs the fewest
(:func:`balanced_tolerance`) is :data:`TOLERANCE`. The procedure rejects the
``j``-th smallest of ``m`` p-values at ``q j / m`` or above, so where a
filter makes a claim in half its cells or more each test is at ``q / 2``
(:data:`DESIGN_FALSE_ALARM`) or looser; in fewer, the power is less.

References
----------
.. [schuirmann1987] D. J. Schuirmann, "A comparison of the two one-sided tests
   procedure and the power approach for assessing the equivalence of average
   bioavailability", *J. Pharmacokinetics and Biopharmaceutics* 15 (1987) 657-680.
.. [benjamini1995] Y. Benjamini and Y. Hochberg, "Controlling the false discovery
   rate: a practical and powerful approach to multiple testing", *J. Royal
   Statistical Society B* 57 (1995) 289-300.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import ndtri
from scipy.stats import binom, false_discovery_control

from depthcore.problem import checks
from depthcore.studies import priors as prior_forms

#: The nominal level of the coverage judged (the central 68 % interval's).
LEVEL = 0.68
#: The false-discovery rate held for each claim, each filter's cells one family.
FALSE_DISCOVERY = 0.05
#: The size of the one-sided tests the trials are designed for, half :data:`FALSE_DISCOVERY`.
DESIGN_FALSE_ALARM = FALSE_DISCOVERY / 2
#: The probability with which :data:`NEAR` and :data:`FAR` are to be decided.
DESIGN_POWER = 0.9
#: A coverage this near the level is to be called calibrated.
NEAR = 0.01
#: A coverage this far off the level is to be called miscalibrated (0.634 = 0.68 - 0.046).
FAR = 0.046
#: The tolerance ``t`` around the level: :func:`balanced_tolerance`, to three decimals.
TOLERANCE = 0.028


def _tails(covered, trials, level, tolerance) -> tuple:
    """``P(X >= k | L - t)``, ``P(X <= k | L + t)``, ``P(X <= k | L - t)``, ``P(X >= k | L + t)``
    of ``X`` binomial over ``n`` trials, ``k`` covered."""
    level = checks.probability(level, "level")
    t = checks.positive_scalar(tolerance, "tolerance")
    if not 0 < level - t < level + t < 1:
        raise ValueError(f"tolerance must keep level +- tolerance within (0, 1), got {t!r}")
    k, n = np.asarray(covered, dtype=float), np.asarray(trials, dtype=float)
    if np.any(n < 1) or np.any(k < 0) or np.any(k > n) or np.any(k != np.round(k)):
        raise ValueError("covered must be whole counts from 0 to trials, trials >= 1")
    lo, hi = level - t, level + t
    return binom.sf(k - 1, n, lo), binom.cdf(k, n, hi), binom.cdf(k, n, lo), binom.sf(k - 1, n, hi)


def equivalence_pvalue(covered, trials, level=LEVEL, tolerance=TOLERANCE) -> np.ndarray:
    """The exact p-value of "the coverage lies within ``level ± tolerance``" (TOST).

    The larger of the binomial one-sided p-values ``P(X >= k | n, L - t)`` and
    ``P(X <= k | n, L + t)``; ``covered`` (``k``) and ``trials`` (``n >= 1``)
    broadcast, and so does the result.
    """
    above_lo, below_hi, _, _ = _tails(covered, trials, level, tolerance)
    return np.maximum(above_lo, below_hi)


def outside_pvalue(covered, trials, level=LEVEL, tolerance=TOLERANCE) -> np.ndarray:
    """The exact p-value of "the coverage lies outside ``level ± tolerance``".

    The smaller of ``P(X <= k | n, L - t)`` and ``P(X >= k | n, L + t)``. At a
    coverage on one edge the other side adds the chance of a count beyond the
    far edge, below 1e-12 at the trials :func:`trials_needed` asks for.
    """
    _, _, below_lo, above_hi = _tails(covered, trials, level, tolerance)
    return np.minimum(below_lo, above_hi)


def discoveries(pvalues, rate: float = FALSE_DISCOVERY) -> np.ndarray:
    """Benjamini and Hochberg's step-up procedure: which hypotheses to reject, (m,) bool.

    With the p-values sorted, ``p_(1) <= ... <= p_(m)``, it rejects the ``j``
    smallest, ``j`` the largest with ``p_(j) <= rate j / m``; under independent
    tests the expected share of false rejections among them is at most
    ``rate`` [benjamini1995]_. ``pvalues`` (m,) in [0, 1], NaN where not
    tested (never rejected, not counted in ``m``).
    """
    p = np.asarray(pvalues, dtype=float)
    rate = checks.probability(rate, "rate")
    if p.ndim != 1 or np.any((p < 0) | (p > 1)):
        raise ValueError("pvalues must be one-dimensional, each in [0, 1] or NaN")
    tested = ~np.isnan(p)
    out = np.zeros(p.shape, dtype=bool)
    if np.any(tested):
        out[tested] = false_discovery_control(p[tested], method="bh") <= rate
    return out


def verdicts(covered, trials, level=LEVEL, tolerance=TOLERANCE, rate=FALSE_DISCOVERY) -> list:
    """One family of cells' verdicts: True (calibrated), False (miscalibrated) or None.

    Each claim's p-values over the cells, each family held to the
    false-discovery ``rate`` (:func:`discoveries`); a cell neither claim is
    discovered in, or without trials, is None. ``covered``, ``trials``: (m,).
    """
    k, n = np.asarray(covered, dtype=float), np.asarray(trials, dtype=float)
    if k.ndim != 1 or k.shape != n.shape:
        raise ValueError("covered and trials must be one-dimensional, of one length")
    p_in, p_out = np.full(k.shape, np.nan), np.full(k.shape, np.nan)
    if np.any(n >= 1):
        p_in[n >= 1] = equivalence_pvalue(k[n >= 1], n[n >= 1], level, tolerance)
        p_out[n >= 1] = outside_pvalue(k[n >= 1], n[n >= 1], level, tolerance)
    inside, outside = discoveries(p_in, rate), discoveries(p_out, rate)
    return [True if a else (False if b else None) for a, b in zip(inside, outside, strict=True)]


def power(coverage, trials: int, level=LEVEL, tolerance=TOLERANCE, false_alarm=None) -> dict:
    """The probabilities that one cell is called calibrated, and miscalibrated.

    Exact binomial sums, at a true ``coverage``, over the counts whose
    one-sided tests reject at ``false_alarm`` (default
    :data:`DESIGN_FALSE_ALARM`): ``{"calibrated": float, "miscalibrated": float}``.
    """
    c = checks.probability(coverage, "coverage")
    n = checks.count(trials, "trials")
    a = checks.probability(
        DESIGN_FALSE_ALARM if false_alarm is None else false_alarm, "false_alarm"
    )
    _tails(0, n, level, tolerance)  # the refusals
    lo, hi = level - tolerance, level + tolerance
    # the counts each test rejects at: X >= k_lo (against lo), X <= k_hi (against hi), ...
    k_lo, above = binom.isf(a, n, lo) + 1, binom.isf(a, n, hi) + 1
    k_hi, below = binom.ppf(a, n, hi), binom.ppf(a, n, lo)
    k_hi -= binom.cdf(k_hi, n, hi) > a
    below -= binom.cdf(below, n, lo) > a
    inside = max(0.0, binom.cdf(k_hi, n, c) - binom.cdf(k_lo - 1, n, c))
    return {
        "calibrated": float(inside),
        "miscalibrated": float(binom.cdf(below, n, c) + binom.sf(above - 1, n, c)),
    }


def trials_needed(
    tolerance=TOLERANCE, level=LEVEL, near=NEAR, far=FAR, false_alarm=None, power=None
):
    """The fewest trials with which a tolerance ``t`` decides ``L ± near`` and ``L ± far``.

    Each is to be called calibrated (``near``) or miscalibrated (``far``) with
    probability ``power`` (default :data:`DESIGN_POWER`) by one-sided tests of
    size ``false_alarm`` (default :data:`DESIGN_FALSE_ALARM`): in the normal
    approximation (score tests, SD ``s(e) = sqrt(e (1 - e))`` at an edge ``e``
    of the band), on each side

        sqrt(n) >= (z_a s(e) + z_b s(L ± near)) / (t - near),
        sqrt(n) >= (z_a s(e) + z_b s(L ± far)) / (far - t),

    ``z_a``, ``z_b`` the normal quantiles of ``1 - false_alarm`` and ``power``
    (the textbook sample size of a one-sided test); ``near < t < far``.
    Returns an int; :func:`power` gives the exact probabilities.
    """
    t, level = checks.positive_scalar(tolerance, "tolerance"), checks.probability(level, "level")
    near, far = checks.nonnegative_scalar(near, "near"), checks.positive_scalar(far, "far")
    if not (near < t < far and 0 < level - far and level + far < 1):
        raise ValueError(f"tolerance must lie between near and far, got {t!r}")
    za = float(ndtri(1.0 - checks.probability(false_alarm or DESIGN_FALSE_ALARM, "false_alarm")))
    zb = float(ndtri(checks.probability(power or DESIGN_POWER, "power")))
    root = 0.0
    for side in (-1.0, 1.0):
        sd = [math.sqrt(c * (1 - c)) for c in level + side * np.array([t, near, far])]
        root = max(
            root, (za * sd[0] + zb * sd[1]) / (t - near), (za * sd[0] + zb * sd[2]) / (far - t)
        )
    return math.ceil(root**2)


def balanced_tolerance(level=LEVEL, near=NEAR, far=FAR, false_alarm=None, power=None) -> float:
    """The tolerance between ``near`` and ``far`` needing the fewest :func:`trials_needed`."""
    span = far - near
    fit = minimize_scalar(
        lambda t: trials_needed(t, level, near, far, false_alarm, power),
        bounds=(near + 1e-6 * span, far - 1e-6 * span),
        method="bounded",
    )
    return float(fit.x)


def fixed_truth(cell: dict) -> bool:
    """Whether an atlas cell's truth is fixed (the paper's rule): a coverage tests no posterior."""
    return cell["form"] not in prior_forms.DRAWN


def with_calibration(result: dict, tolerance=TOLERANCE, rate=FALSE_DISCOVERY) -> dict:
    """An atlas (or its record) with each filter's ``"calibrated"`` read from its coverages.

    Per filter, over the cells whose truths are drawn, :func:`verdicts` of its
    68 % coverages (the trials it answered, each cell's ``"coverage_68"`` and
    ``"trials"``); a cell with a fixed truth (:func:`fixed_truth`) is scored
    for its error alone, its ``"calibrated"`` None, as is a filter's with no
    coverage. A new dict, whatever verdicts ``result`` held (a record made
    before these is read as a new one); ``"levels"`` gets
    ``"calibration_level"``, ``"calibration_tolerance"`` and
    ``"false_discovery_rate"``.
    """
    cells = [
        {**c, "filters": {n: dict(e) for n, e in c["filters"].items()}} for c in result["cells"]
    ]
    for name in [*result["names"], *([result["under_law"]] if "under_law" in result else [])]:
        entries = [c["filters"].get(name) for c in cells if not fixed_truth(c)]
        entries = [e for e in entries if e is not None and e.get("coverage_68") is not None]
        k = [round(e["coverage_68"] * e["trials"]) for e in entries]
        for e, v in zip(
            entries,
            verdicts(k, [e["trials"] for e in entries], LEVEL, tolerance, rate),
            strict=True,
        ):
            e["calibrated"] = v
    for c in cells:
        for e in c["filters"].values():
            if fixed_truth(c) or e.get("coverage_68") is None:
                e["calibrated"] = None
    levels = {k: v for k, v in result.get("levels", {}).items() if k != "calibration_reach"}
    levels.update(
        calibration_level=LEVEL, calibration_tolerance=float(tolerance), false_discovery_rate=rate
    )
    return {**result, "levels": levels, "cells": cells}
