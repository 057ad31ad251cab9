"""Numbers as the book prints them: vectors, noise levels, values with their errors.

Recommended import: ``from depthbook import formatting``.

``vec`` a vector (the command line's :func:`depthcore.cli.text.vec`),
:func:`rho_label` a noise level, :func:`plus_minus` a mean and an SD,
:func:`value_se` a Monte Carlo value with its standard error, and
:func:`study_texts` every score of one Monte Carlo study, as several chapters
print them.
"""

from __future__ import annotations

import numpy as np

from depthcore.cli.text import vec  # noqa: F401  (the book prints a vector as the command line does)
from depthcore.problem import checks
from depthcore.registry.estimates import QUANTITIES

#: Decimal places of the reproduced means and SDs in the book's tables.
DECIMALS = 4


#: Scores of :func:`depthcore.studies.scores.scores` per quantity, with their decimals in the
#: book's tables.
STUDY_DECIMALS = {"bias": 3, "rmse": 3, "mean_sd": 3, "coverage_68": 2, "coverage_95": 2}


#: (text key, score, decimals) of the rows of several studies' texts.
SCORE_TEXTS = (
    ("bias", "bias", 3),
    ("rmse", "rmse", 3),
    ("mean_sd", "mean_sd", 3),
    ("cov68", "coverage_68", 2),
    ("cov95", "coverage_95", 2),
    ("nees", "nees", 1),
)


# --- the book's texts ----------------------------------------------------------------------


def rho_label(rho: float) -> str:
    """A noise level as the paper writes it, ``"1/200"`` (``1 / rho`` rounded to an integer)."""
    rho = checks.positive_scalar(rho, "rho")
    return f"1/{1.0 / rho:.0f}"


def names(items) -> str:
    """Names as a list in plain prose, each in quotes: ``'"optimal", "ekf" and "ukf"'``.

    A glued text is pasted as plain text, so it holds no Markdown (no backticks).
    """
    texts = [f'"{name}"' for name in items]
    if not texts:
        raise ValueError("names needs at least one name")
    return texts[0] if len(texts) == 1 else ", ".join(texts[:-1]) + " and " + texts[-1]


def sci(x: float, digits: int = 1) -> str:
    """``x`` in scientific notation without a plus sign or leading zeros: ``"1.5e8"``, ``"1e-8"``.

    Parameters
    ----------
    x : float
    digits : int
        Digits after the point of the mantissa (0: ``"1e-8"``).
    """
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def plus_minus(mean: float, sd: float, decimals: int) -> str:
    """A mean and an SD as the book prints them, ``"6.466 ± 0.799"``.

    Parameters
    ----------
    mean, sd : float
        The mean and the standard deviation.
    decimals : int
        Decimal places of both; a mean of ``-0.0`` is printed as ``0.0``.

    Returns
    -------
    str
    """
    return f"{float(mean) + 0.0:.{decimals}f} ± {float(sd):.{decimals}f}"


def study_texts(result: dict, prefix: str) -> dict:
    """Texts of every score of :func:`depthcore.studies.monte_carlo.study`'s result, for glue.

    Returns
    -------
    dict
        ``"<prefix>_<filter>_<quantity>_<score>"`` for the scores of
        :data:`STUDY_DECIMALS`, and ``"<prefix>_<filter>_nees"`` (1 decimal),
        ``"<prefix>_<filter>_hellinger"`` (3 decimals, ``"-"`` when not
        computed); ``"<prefix>_trials"``. Beside each, the same key with
        ``_pm`` appended: ``"value ± standard error"``, the standard error to
        the value's decimals (one more where it would round to zero).
    """
    out = {f"{prefix}_trials": str(result["valid_trials"])}
    for name, f in result["filters"].items():
        for q in QUANTITIES:
            for score, d in STUDY_DECIMALS.items():
                key = f"{prefix}_{name}_{q}_{score}"
                out[key] = f"{f[q][score] + 0.0:.{d}f}"
                out[f"{key}_pm"] = value_se(f[q][score], f[q][f"{score}_se"], d)
        out[f"{prefix}_{name}_nees"] = f"{f['nees']:.1f}"
        out[f"{prefix}_{name}_nees_pm"] = value_se(f["nees"], f["nees_se"], 1)
        h = f["hellinger_depth"]
        out[f"{prefix}_{name}_hellinger"] = "-" if h is None else f"{h['mean']:.3f}"
        out[f"{prefix}_{name}_hellinger_pm"] = "-" if h is None else value_se(h["mean"], h["se"], 3)
    return out


def row_extremes(texts: dict, result: dict, names, prefix: str) -> dict:
    """The ``_pm`` texts of the rows where each score of :data:`SCORE_TEXTS` is least and greatest.

    Parameters
    ----------
    texts : dict
        Row texts ``"<prefix>_<i>_<filter>_<key>_pm"`` of a study with one row per setting.
    result : dict
        That study's result: ``result[filter][score]`` of shape (rows,).
    names : sequence of str
        The filters.
    prefix : str

    Returns
    -------
    dict
        ``"<prefix>_<filter>_<key>_min_pm"`` and ``"..._max_pm"`` for the
        scores other than the bias and the mean SD.
    """
    out = {}
    for name in names:
        for key, score, _ in SCORE_TEXTS:
            if score in ("bias", "mean_sd"):
                continue
            values = np.asarray(result[name][score], dtype=float)
            for which, i in (("min", np.argmin(values)), ("max", np.argmax(values))):
                out[f"{prefix}_{name}_{key}_{which}_pm"] = texts[f"{prefix}_{i}_{name}_{key}_pm"]
    return out


def value_se(value: float, se: float, decimals: int) -> str:
    """``"value ± se"``, both to ``decimals`` places, or more while the SE rounds to zero.

    Up to three more places are used, so a tiny but nonzero SE reads as such
    (``0.900 ± 0.0004``); an SE of exactly 0 is printed as 0.

    Parameters
    ----------
    value, se : float
        A Monte Carlo estimate and its standard error (>= 0).
    decimals : int
        Places of the value, >= 0.

    Returns
    -------
    str
    """
    d_se = decimals
    while se > 0 and round(se, d_se) == 0 and d_se < decimals + 3:
        d_se += 1
    return f"{value + 0.0:.{decimals}f} ± {se:.{d_se}f}"
