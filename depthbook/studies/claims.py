"""Every checkable claim of the paper, each decided by a test stated before its number.

Recommended import: ``from depthbook.studies import claims``.

:func:`claim_numbers` computes every number the claims rest on (plain floats,
lists and dicts, from :mod:`depthbook.studies.evidence`): the paper's printed
means and SDs beside the values of the formulas as derived and of the print's
own formulas, the distances and peaks of each figure's marginals, the exact
depth marginal's quantiles, the noise in pixels, Figure 6's shifts and Theorem
1's agreement. :func:`claims`
states each claim of the paper as a :class:`Claim` (what the paper says, what
is computed, the test) and decides its verdict from those numbers alone, one
small pure function for each kind of claim; the verdicts come from one
vocabulary (:data:`VERDICTS`). :func:`figure_verdicts` summarises the claims of
each item (a figure, Theorem 1, the abstract, the conclusions). The book's
page of claims, its intro, the README and the replication article read them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from depthbook.studies import evidence, verdicts
from depthbook.studies.evidence import FILTER_ROWS, PAPER, PRINT_FORMULAS
from depthcore.problem.scenarios import REPORTED_DECIMALS, SCAN_TEXT, SCENARIOS

__all__ = [
    "AFTER_CORRECTION",
    "AGREE",
    "AS_PRINTED",
    "CLOSER",
    "CONSTANT",
    "FAR",
    "FLATTENED",
    "NOT_CHECKABLE",
    "NOT_REPRODUCED",
    "PASSED",
    "PIXEL_TOL",
    "PRINTED_C",
    "PRINTED_FORMULA",
    "PRINTED_MISS",
    "ROUNDING",
    "SERIOUS",
    "SHARP",
    "SLIGHT",
    "TAIL",
    "THEOREM_BOUND",
    "TOO_STRONG",
    "UNAFFECTED",
    "VERDICTS",
    "Claim",
    "agrees",
    "claim_numbers",
    "claims",
    "figure_verdicts",
]

#: The correct formulas give the paper's number or statement.
AS_PRINTED = "reproduced as printed"
#: The printed number comes only from a printed formula that is wrong; the claim's value
#: shows the correct number beside it.
PRINTED_FORMULA = "reproduced only with the print's own formula, which is wrong"
#: The number or statement holds once an error of the print is corrected.
AFTER_CORRECTION = "reproduced after correcting the print"
#: No reading of the formulas gives the number or statement.
NOT_REPRODUCED = "not reproduced"
#: What the paper gives does not allow a test; the claim's reason says why.
NOT_CHECKABLE = "not checkable from what the paper gives"
#: The vocabulary, worst first, in the order in which :func:`figure_verdicts` lists an item's
#: verdicts.
VERDICTS = (NOT_REPRODUCED, PRINTED_FORMULA, AFTER_CORRECTION, AS_PRINTED, NOT_CHECKABLE)

#: A computed number agrees with a printed one when it rounds to it at the paper's printed
#: decimals: ``|value - printed| <= AGREE``, as ``reproduce.comparison``'s ``*_matches`` decide.
AGREE = 0.5 * 10.0**-REPORTED_DECIMALS
#: Closed forms that hold exactly (Eqs. (7), (19)) hold in double precision to this,
#: relative to the largest component of ``c``: rounding (``1e-16``) with a wide margin.
ROUNDING = 1e-12
#: Theorem 1 holds when ``norm(D - P_3) / norm(P_3)`` and the means' difference (relative to
#: ``|c|``) are below this: the bound book/appendix.md asserts
#: (:data:`depthbook.studies.verdicts.THEOREM_TOL`), a hundred times the rounding of the two
#: formulas (a bound, not a measured residue).
THEOREM_BOUND = verdicts.THEOREM_TOL
#: A printed formula fails when it misses the right covariance by more than this factor, minus 1.
PRINTED_MISS = 0.1
#: Eq. (16)'s dropped factor counts as independent of ``y`` when its log varies by less than
#: this over the central 98 % of the exact depth marginal (its quantiles q01 to q99).
CONSTANT = 1e-6
#: "About n pixels" holds when the noise in pixels is within this share of ``n``.
PIXEL_TOL = 0.25
#: A shift of ``p_sy`` against ``p_oy`` is "slight" below this many SDs of ``p_oy``.
SLIGHT = 1.0
#: The EKF "seriously underestimates" the covariance when its SD is below this share of the
#: exact posterior's.
SERIOUS = 0.5
#: "Greatly flattened": a peak density at most this share of the same filter's in Figure 2.
FLATTENED = 0.5
#: "A sharp peak": a peak density at least this many times those of the flattened densities.
SHARP = 5.0
#: "Only a sharp lower bound": the exact marginal's upper tail, ``q99 - q50``, at least this
#: many times its lower, ``q50 - q01`` (1 for a symmetric density).
TAIL = 3.0
#: "Much closer": the distance between ``p_oy`` and ``p_sy`` at most this share of Figure 2's.
CLOSER = 0.5
#: "Far outperforms": the second-order density's distance to the exact marginal at most this
#: share of the EKF's, on most of the paper's figures.
FAR = 0.5
#: "Straight through": the EKF's depth mean moves by a share of the prior's shift in this range.
PASSED = (0.75, 1.25)
#: "Almost unaffected": a depth mean moves by less than this share of the prior's shift.
UNAFFECTED = 0.05
#: "Too strongly affected by the prior mean": in Figure 6 the EKF's mean moves, beyond the exact
#: posterior's move, by more than this many SDs of the exact posterior.
TOO_STRONG = 1.0
#: The noise-free states ``c`` the paper prints for measurements (17) and (18).
PRINTED_C = {"fig2": (6 / 5, 6.0, 6 / 5), "fig3": (2.0, 10.0, 2.0)}

#: The book's names of the paper's filters.
NAMES = {"optimal": "optimal", "second_order": "second-order", "ekf": "EKF"}
_DISTANCE = "the total variation distance ½∫|p - q| between two marginals"


@dataclass(frozen=True)
class Claim:
    """One checkable claim of the paper, its test and its verdict.

    Attributes
    ----------
    key : str
        Short id, such as ``"fig2-opt-mean"``.
    item : str
        Where the paper makes it: ``"Figure 2"`` ... ``"Theorem 1"``, ``"Abstract"``.
    page : str
        The book's page that shows it: ``"fig2"`` ... ``"fig6"``, ``"appendix"``,
        ``"conclusions"``.
    statement : str
        What the paper says, briefly, with its printed number if any.
    quantity : str
        What is computed, in words.
    criterion : str
        The test, fixed before the number: a tolerance, a threshold, a direction.
    value : str
        The computed numbers as the book prints them.
    verdict : str
        One of :data:`VERDICTS`.
    reason : str
        One line.
    """

    key: str
    item: str
    page: str
    statement: str
    quantity: str
    criterion: str
    value: str
    verdict: str
    reason: str


def agrees(value: float, printed: float) -> bool:
    """Whether ``value`` rounds to ``printed`` at the paper's printed decimals (:data:`AGREE`)."""
    return bool(abs(value - printed) <= AGREE + 1e-12)


def claim_numbers() -> dict:
    """Every number the claims rest on: :func:`depthbook.studies.evidence.numbers`."""
    return evidence.numbers()


# --- the printed means and SDs of Figures 2 and 3, and Eq. (7) ----------------------------------

_PRINTED_CRITERION = (
    f"agreement at the paper's {REPORTED_DECIMALS} decimals (|value - printed| <= {AGREE:g}); "
    "as printed if the formulas as derived agree (and the print's own formula, where it "
    "has one, too), after correction if only the derived ones do, the print's formula if "
    "only it does, else not reproduced"
)


def _printed_verdict(derived_ok: bool, formula_ok: bool) -> str:
    """The verdict on a printed number from the agreement of the two readings."""
    if derived_ok:
        return AS_PRINTED if formula_ok else AFTER_CORRECTION
    return PRINTED_FORMULA if formula_ok else NOT_REPRODUCED


def _printed_number(n: dict, key: str, rid: str, moment: str) -> Claim:
    """A mean or SD that Figure 2 or 3 prints, for one filter."""
    i = ("mean", "sd").index(moment)
    name, letter = FILTER_ROWS[rid]
    printed, value = n["printed"][key][rid][i], n["derived"][key][rid][i]
    formula = n["print_formula"][key].get(rid, n["derived"][key][rid])[i]
    label = PRINT_FORMULAS.get(rid, ("", "the print's formula"))[1]
    ok, formula_ok = agrees(value, printed), agrees(formula, printed)
    verdict = _printed_verdict(ok, formula_ok)
    symbol = f"E(p_{letter}y)" if moment == "mean" else f"σ_{letter}y"
    scan = SCAN_TEXT.get(key, {}).get(name, {}).get("depth")
    read = f" (the scan reads {scan[i]})" if scan and scan[i] != f"{printed:.2f}" else ""
    shown = f"{value:.2f}" + (
        f" ({label}: {formula:.2f})" if f"{formula:.2f}" != f"{value:.2f}" else ""
    )
    reason = {
        AS_PRINTED: f"the formulas as derived give {value:.2f}",
        AFTER_CORRECTION: f"{label} gives {formula:.2f}, the corrected formula {value:.2f}",
        PRINTED_FORMULA: f"only {label} gives it; the exact density gives {value:.2f}",
        NOT_REPRODUCED: f"no reading gives it: {label} {formula:.2f}, as derived {value:.2f}"
        if rid in PRINT_FORMULAS
        else f"the formulas give {value:.2f}",
    }[verdict]
    if verdict == NOT_REPRODUCED and moment == "sd" and printed == n["printed"][key][rid][0]:
        reason += "; the printed SD repeats the printed mean"
    return Claim(
        f"{key}-{rid}-{moment}",
        f"Figure {SCENARIOS[key].figure}",
        key,
        f"{symbol} = {printed:.2f}{read}",
        f"the {'mean' if i == 0 else 'SD'} of the {NAMES[name]} depth marginal p_{letter}y"
        + (f", and with {label}" if rid in PRINT_FORMULAS else ""),
        _PRINTED_CRITERION,
        shown,
        verdict,
        reason,
    )


def _zero(n: dict, key: str) -> Claim:
    """Eq. (7): the measurements give the printed ``c``, a zero of ``f``."""
    c, printed = np.array(n["c"][key]), np.array(PRINTED_C[key])
    error = float(np.abs(c - printed).max() / np.abs(printed).max())
    holds = error <= ROUNDING and n["f_at_c"][key] <= ROUNDING**2
    mu = "(17)" if key == "fig2" else "(18)"
    return Claim(
        f"{key}-c",
        f"Figure {SCENARIOS[key].figure}",
        key,
        f"measurements {mu} give c = ({', '.join(f'{v:g}' for v in printed)})",
        "c from Eq. (7) and f(c) of Eq. (5)",
        f"c equal to the printed one within {ROUNDING:g} relative, and f(c) <= {ROUNDING**2:g}",
        f"c = ({', '.join(f'{v:.4g}' for v in c)}), f(c) = {n['f_at_c'][key]:.1e}",
        AS_PRINTED if holds else NOT_REPRODUCED,
        "Eq. (7) gives the printed c, a zero of f" if holds else f"c is off by {error:.2g}",
    )


# --- what Figures 2-6 show ----------------------------------------------------------------------


def _shifted_lower(n: dict, key: str, slight: bool) -> Claim:
    """``p_sy`` is shifted toward lower depths than ``p_oy`` (slightly: within :data:`SLIGHT`)."""
    m = n["marginals"][key]
    gap = (m["second_order"]["mean"] - m["optimal"]["mean"]) / m["optimal"]["sd"]
    holds = gap < 0 and (not slight or gap > -SLIGHT)
    bound = f" and above -{SLIGHT:g}" if slight else ""
    return Claim(
        f"{key}-so-lower",
        f"Figure {SCENARIOS[key].figure}",
        key,
        ("p_sy is fairly close to p_oy, shifted slightly" if slight else "p_sy is shifted")
        + " towards the lower values of y",
        "(E p_sy - E p_oy) / σ_oy",
        f"negative{bound}",
        f"{gap:.2f}",
        AS_PRINTED if holds else NOT_REPRODUCED,
        f"p_sy's mean lies {abs(gap):.2f} SDs of p_oy {'below' if gap < 0 else 'above'} p_oy's",
    )


def _skewed(n: dict, key: str) -> Claim:
    """``p_oy`` is skewed toward higher depths: Bowley's quartile skewness is positive."""
    _, q25, q50, q75, _ = n["quantiles"][key]
    skew = (q75 + q25 - 2.0 * q50) / (q75 - q25)
    return Claim(
        f"{key}-opt-skew",
        f"Figure {SCENARIOS[key].figure}",
        key,
        "p_oy is skewed, with a bias towards the higher values of y",
        "Bowley's skewness (q75 + q25 - 2 q50) / (q75 - q25) of the exact p_oy",
        "positive",
        f"{skew:.3f}",
        AS_PRINTED if skew > 0 else NOT_REPRODUCED,
        f"the upper quartile lies {'farther from' if skew > 0 else 'no farther from'} the median",
    )


def _ekf_ratios(n: dict, keys) -> list[float]:
    return [n["marginals"][k]["ekf"]["sd"] / n["marginals"][k]["optimal"]["sd"] for k in keys]


def _underestimates(n: dict, key: str, item: str, page: str, keys, statement: str) -> Claim:
    """The EKF's SD is below :data:`SERIOUS` of the exact posterior's in each of ``keys``."""
    ratios = _ekf_ratios(n, keys)
    holds = max(ratios) < SERIOUS
    return Claim(
        key,
        item,
        page,
        statement,
        "the EKF's SD over the exact posterior's"
        + (
            ""
            if len(keys) == 1
            else " (Figure 4: velocity), in Figures " + ", ".join(k[3:] for k in keys)
        ),
        f"below {SERIOUS:g} in each",
        ", ".join(f"{r:.2f}" for r in ratios),
        AS_PRINTED if holds else NOT_REPRODUCED,
        f"the EKF's SD is at most {max(ratios):.2f} of the exact one's",
    )


def _pixels(n: dict, key: str, about: int) -> Claim:
    """The noise of a figure in pixels, against the paper's "about n pixels"."""
    px = n["pixels"][key]
    holds = abs(px / about - 1.0) <= PIXEL_TOL
    rho = {"fig2": "1/200", "fig5": "1/500"}[key]
    return Claim(
        f"{key}-pixels",
        "Experiments" if key == "fig2" else "Figure 5",
        key,
        f"ρ = {rho} rad is about {about} pixel{'s' if about > 1 else ''} "
        "(512 × 512 image, 30° field of view)",
        "ρ × 512 / (π/6), the paper's small-angle conversion",
        f"within {PIXEL_TOL:.0%} of {about}",
        f"{px:.2f} px",
        AS_PRINTED if holds else NOT_REPRODUCED,
        f"{px:.2f} pixels is {px / about:.2f} times {about}",
    )


def _peak_change(n: dict, key: str, statement: str) -> Claim:
    """The peaks of ``p_oy`` and ``p_sy`` against Figure 2's: flatter in 3, sharper in 5."""
    flatter = key == "fig3"
    m2, m = n["marginals"]["fig2"], n["marginals"][key]
    ratios = [m[k]["peak"] / m2[k]["peak"] for k in ("optimal", "second_order")]
    holds = max(ratios) <= FLATTENED if flatter else min(ratios) > 1
    return Claim(
        f"{key}-{'flattened' if flatter else 'sharper'}",
        f"Figure {SCENARIOS[key].figure}",
        key,
        statement,
        f"peak density of p_oy and of p_sy in Figure {SCENARIOS[key].figure} over Figure 2's",
        f"each at most {FLATTENED:g}" if flatter else "each above 1",
        ", ".join(f"{r:.2f}" for r in ratios),
        AS_PRINTED if holds else NOT_REPRODUCED,
        f"the peaks are {ratios[0]:.2f} (p_oy) and {ratios[1]:.2f} (p_sy) times Figure 2's",
    )


def _sharp_peak(n: dict) -> Claim:
    m = n["marginals"]["fig3"]
    ratios = [m["ekf"]["peak"] / m[k]["peak"] for k in ("optimal", "second_order")]
    return Claim(
        "fig3-ekf-sharp",
        "Figure 3",
        "fig3",
        "p_ey retains a sharp peak (truncated in the figure)",
        "peak density of p_ey over those of p_oy and p_sy in Figure 3",
        f"each at least {SHARP:g}",
        ", ".join(f"{r:.1f}" for r in ratios),
        AS_PRINTED if min(ratios) >= SHARP else NOT_REPRODUCED,
        f"p_ey's peak is {min(ratios):.1f} times the higher of the flattened peaks",
    )


def _lower_bound(n: dict) -> Claim:
    q01, _, q50, _, q99 = n["quantiles"]["fig3"]
    ratio = (q99 - q50) / (q50 - q01)
    return Claim(
        "fig3-lower-bound",
        "Figure 3",
        "fig3",
        "a good estimate of y cannot be obtained; only a sharp lower bound on y",
        "(q99 - q50) / (q50 - q01) of the exact p_oy, its upper tail over its lower",
        f"at least {TAIL:g}",
        f"{ratio:.1f} (q01 {q01:.2f}, q50 {q50:.2f}, q99 {q99:.2f})",
        AS_PRINTED if ratio >= TAIL else NOT_REPRODUCED,
        f"y exceeds {q01:.2f} with probability 0.99; the upper tail is {ratio:.1f} times longer",
    )


def _eq16(n: dict) -> Claim:
    spread = max(n["eq16_spread"].values())
    holds = spread < CONSTANT
    return Claim(
        "eq16-constant",
        "Eq. (16)",
        "fig3",
        "in Eq. (16), c is a normalising constant independent of y",
        "range of log p_oy minus log of Eq. (16) as printed over q01..q99 of p_oy, Figures 2, 3",
        f"below {CONSTANT:g} (constant)",
        ", ".join(f"{v:.3g}" for v in n["eq16_spread"].values()),
        AS_PRINTED if holds else NOT_REPRODUCED,
        "the dropped factor is constant"
        if holds
        else f"the factor the print calls constant varies by e^{spread:.2f} over the marginal",
    )


def _fig4_optimal(n: dict) -> Claim:
    o = n["marginals"]["fig4"]["optimal"]
    return Claim(
        "fig4-opt-missing",
        "Figure 4",
        "fig4",
        "p_ov is not shown because of difficulties in calculating its values",
        "none: the statement is about the paper's own computation",
        "none",
        f"p_ov: mean {o['mean']:.2f}, SD {o['sd']:.2f}",
        NOT_CHECKABLE,
        "the difficulty lay in the paper's computation, which it does not give; "
        "the book computes p_ov with its error estimate",
    )


def _fig5_closer(n: dict) -> Claim:
    d2, d5 = (n["marginals"][k]["distance"]["second_order"] for k in ("fig2", "fig5"))
    return Claim(
        "fig5-closer",
        "Figure 5",
        "fig5",
        "p_oy and p_sy are much closer to each other than in Figure 2",
        f"{_DISTANCE}: p_oy to p_sy in Figure 5 over Figure 2's",
        f"at most {CLOSER:g}",
        f"{d5 / d2:.2f} ({d5:.3f} against {d2:.3f})",
        AS_PRINTED if d5 <= CLOSER * d2 else NOT_REPRODUCED,
        f"the distance falls from {d2:.3f} to {d5:.3f}",
    )


def _shares(n: dict) -> dict:
    """Each filter's depth mean's move, Figure 2 to 6, as a share of the prior's shift."""
    m2, m6 = n["marginals"]["fig2"], n["marginals"]["fig6"]
    return {k: (m6[k]["mean"] - m2[k]["mean"]) / n["prior_shift"] for k in NAMES}


def _through(n: dict) -> Claim:
    share, (lo, hi) = _shares(n)["ekf"], PASSED
    return Claim(
        "fig6-ekf-through",
        "Figure 6",
        "fig6",
        f"the prior's shift of {n['prior_shift']:g} units is transmitted by the EKF straight "
        "through to the estimate of depth",
        "the EKF's depth mean's move, Figure 2 to 6, over the prior's shift",
        f"between {lo:g} and {hi:g}",
        f"{share:.2f}",
        AS_PRINTED if lo <= share <= hi else NOT_REPRODUCED,
        f"the EKF passes on {share:.2f} of the shift"
        + (", a little more than the shift" if 1 < share <= hi else ""),
    )


def _unaffected(n: dict) -> Claim:
    shares = _shares(n)
    moved = [abs(shares[k]) for k in ("optimal", "second_order")]
    return Claim(
        "fig6-others-unaffected",
        "Figure 6",
        "fig6",
        "the optimal and second-order filters are almost unaffected",
        "|move of the depth mean| over the prior's shift, optimal and second-order",
        f"each below {UNAFFECTED:g}",
        ", ".join(f"{v:.4f}" for v in moved),
        AS_PRINTED if max(moved) < UNAFFECTED else NOT_REPRODUCED,
        f"their means move by at most {max(moved):.4f} of the shift",
    )


# --- Theorem 1, the abstract and the conclusions ------------------------------------------------


def _theorem1(n: dict) -> Claim:
    t = n["theorem"].values()
    holds = max(v["misfit"] for v in t) < THEOREM_BOUND
    factors = [v["factor"] for v in t]
    printed_holds = max(abs(f - 1.0) for f in factors) <= PRINTED_MISS
    verdict = (AS_PRINTED if printed_holds else AFTER_CORRECTION) if holds else NOT_REPRODUCED
    return Claim(
        "theorem1",
        "Theorem 1",
        "appendix",
        "if m = G⁻²c then p_s = p_e",
        "p_s against p_e with m = G⁻²c, Figures 2 and 3: max |P_3⁻¹D - I| and the means, "
        "with 2ρ²J⁻¹ and with the printed ρ²J⁻¹ of Eq. (8)",
        f"below {THEOREM_BOUND:g} relative; the printed covariance within {PRINTED_MISS:.0%}",
        f"{'below' if holds else 'above'} {THEOREM_BOUND:g} with 2ρ²J⁻¹; "
        f"ρ²J⁻¹ is {max(factors):.2f} times too small",
        verdict,
        f"p_s = p_e {'holds' if holds else 'fails'} with 2ρ²J⁻¹; the printed ρ²J⁻¹ "
        f"{'also holds' if printed_holds else f'misses by a factor {max(factors):.2f}'}",
    )


def _eq19(n: dict) -> Claim:
    worst = max(v["means"] for v in n["theorem"].values())
    return Claim(
        "theorem1-means",
        "Theorem 1",
        "appendix",
        "Eq. (19): with m = G⁻²c the EKF's means are G⁻²c, G⁻¹c, c",
        "max |m_k - G^(k-3) c| / max |c| of the EKF, Figures 2 and 3",
        f"at most {ROUNDING:g}",
        f"{worst:.1e}",
        AS_PRINTED if worst <= ROUNDING else NOT_REPRODUCED,
        "every innovation is zero" if worst <= ROUNDING else "the means leave G^(k-3) c",
    )


def _against_ekf(n: dict, far: bool) -> Claim:
    """``p_s`` against ``p_e`` by their distances to ``p_o``: closer on all figures, far on most."""
    ratios = [m["distance"]["second_order"] / m["distance"]["ekf"] for m in n["marginals"].values()]
    many = sum(r <= FAR for r in ratios)
    holds = max(ratios) < 1 and (not far or many > len(ratios) / 2)
    return Claim(
        "so-far-outperforms" if far else "intro-closer",
        "Conclusions" if far else "Introduction",
        "conclusions",
        "the approximation in general far outperforms the extended Kalman filter"
        if far
        else "our main result: the second order approximation is closer to the optimal filter "
        "than the EKF",
        f"{_DISTANCE}: p_s's to p_o over p_e's to p_o, Figures 2-6 (Figure 4: velocity)",
        "below 1 on each figure" + (f", at most {FAR:g} on most ('in general')" if far else ""),
        ", ".join(f"{r:.2f}" for r in ratios),
        AS_PRINTED if holds else NOT_REPRODUCED,
        f"below 1 on {sum(r < 1 for r in ratios)} and at most {FAR:g} on {many} of "
        f"{len(ratios)} figures",
    )


def _too_strongly(n: dict) -> Claim:
    shares, m2 = _shares(n), n["marginals"]["fig2"]["optimal"]
    excess = (shares["ekf"] - shares["optimal"]) * n["prior_shift"] / m2["sd"]
    return Claim(
        "ekf-prior-mean",
        "Conclusions",
        "conclusions",
        "the EKF is too strongly affected by the prior mean",
        "Figure 6: the EKF's depth mean's move beyond the exact posterior's, in SDs of p_oy",
        f"above {TOO_STRONG:g}",
        f"{excess:.2f}",
        AS_PRINTED if excess > TOO_STRONG else NOT_REPRODUCED,
        f"a prior {n['prior_shift']:g} units deeper moves the EKF {excess:.2f} exact SDs off",
    )


def _low_noise(n: dict) -> Claim:
    d2, d5 = (n["marginals"][k]["distance"]["second_order"] for k in ("fig2", "fig5"))
    return Claim(
        "abstract-low-noise",
        "Abstract",
        "conclusions",
        "the second order approximation is close to the optimal filter, especially if the "
        "noise level is low",
        f"{_DISTANCE}: p_s to p_o at ρ = 1/500 (Figure 5) against ρ = 1/200 (Figure 2)",
        "smaller at the lower noise",
        f"{d5:.3f} against {d2:.3f}",
        AS_PRINTED if d5 < d2 else NOT_REPRODUCED,
        f"the distance {'falls' if d5 < d2 else 'does not fall'} as the noise falls",
    )


def _not_checkable(key: str, item: str, statement: str, reason: str) -> Claim:
    return Claim(key, item, "conclusions", statement, "none", "none", "-", NOT_CHECKABLE, reason)


def claims(numbers: dict | None = None) -> list[Claim]:
    """Every checkable claim of the paper, each with its test and verdict, in the paper's order.

    Parameters
    ----------
    numbers : dict, optional
        What :func:`claim_numbers` returns (computed when not given).

    Returns
    -------
    list of Claim
    """
    n = claim_numbers() if numbers is None else numbers
    printed = [
        _printed_number(n, key, rid, moment)
        for key in PAPER
        for rid in FILTER_ROWS
        for moment in ("mean", "sd")
    ]
    return [
        _low_noise(n),
        _not_checkable(
            "abstract-optimal-cost",
            "Abstract",
            "the optimal filter requires an excessive amount of computation; the second order "
            "approximation far less",
            "a statement about the paper's 1990 computation, which it does not time; the book "
            "measures the filters' costs in its benchmarks",
        ),
        _against_ekf(n, far=False),
        _eq16(n),
        _pixels(n, "fig2", 5),
        _zero(n, "fig2"),
        *printed[:6],
        _shifted_lower(n, "fig2", slight=True),
        _skewed(n, "fig2"),
        _underestimates(
            n,
            "fig2-ekf-underestimates",
            "Figure 2",
            "fig2",
            ("fig2",),
            "p_ey is sharply peaked, but severely underestimates the covariance",
        ),
        _zero(n, "fig3"),
        *printed[6:],
        _peak_change(n, "fig3", "p_oy and p_sy are greatly flattened compared with Figure 2"),
        _sharp_peak(n),
        _shifted_lower(n, "fig3", slight=False),
        _skewed(n, "fig3"),
        _lower_bound(n),
        _underestimates(
            n,
            "fig3-ekf-underestimates",
            "Figure 3",
            "fig3",
            ("fig3",),
            "the sharp peak of p_ey shows that the EKF seriously underestimates the covariance",
        ),
        _fig4_optimal(n),
        _fig5_closer(n),
        _peak_change(n, "fig5", "p_oy and p_sy are more sharply peaked about their means"),
        _pixels(n, "fig5", 1),
        _through(n),
        _unaffected(n),
        _against_ekf(n, far=True),
        _too_strongly(n),
        _underestimates(
            n,
            "ekf-underestimates",
            "Conclusions",
            "conclusions",
            tuple(n["marginals"]),
            "the EKF seriously underestimates covariances; its covariance estimates are far "
            "too optimistic, as illustrated in Figures 2-6",
        ),
        _not_checkable(
            "conjecture",
            "Conclusions",
            "conjecture: approximations of this kind are preferable to the EKF in a wide range "
            "of applications, particularly when the noise level is low",
            "a conjecture over applications the paper does not specify; the book tests it on "
            "ranges of noise, depth and prior in its chapter on the conjecture",
        ),
        _theorem1(n),
        _eq19(n),
    ]


def figure_verdicts(found: list[Claim]) -> dict[str, tuple[str, ...]]:
    """Each item's verdicts: the distinct verdicts of its claims, worst first.

    An item (a figure, Theorem 1, the abstract ...) has no verdict of its own: it is
    summarised by the set of its claims' verdicts, ordered as :data:`VERDICTS` (so the
    first is the item's worst; :data:`NOT_CHECKABLE` comes first only when no claim of
    the item could be checked).

    Parameters
    ----------
    found : list of Claim
        As :func:`claims` returns them.

    Returns
    -------
    dict
        ``{item: verdicts}``, items in the order of their first claim.
    """
    items: dict[str, set] = {}
    for claim in found:
        items.setdefault(claim.item, set()).add(claim.verdict)
    return {item: tuple(v for v in VERDICTS if v in seen) for item, seen in items.items()}
