"""Two filters compared over the same trials: paired differences and ratios of their scores.

Recommended import: ``from depthcore.studies import pairs``.

Two scores from the same trials are correlated (two filters run on the same
bearings err together), so their separate standard errors
(:mod:`depthcore.studies.scores`) do not give the error of their ratio or
difference. A :class:`CoMoments` keeps the running mean and covariance of
several filters' per-trial scores (:func:`trial_scores`,
:func:`pooled_comoments`) over the chunks of trials that
:func:`depthcore.studies.monte_carlo.study` streams, so that memory does not grow with the
number of trials; :func:`pair_of` picks two of them out. The delta method then
gives the errors of any ratio of powers of two means (:func:`ratio_se`), of
which a ratio of two means (:func:`mean_ratio_se`) and of two RMSEs
(:func:`rmse_ratio_se`) are cases, of a paired difference
(:func:`paired_difference_se`) and of how much nearer its level one coverage
is than another (:func:`coverage_gap_difference`); :func:`compare` gives the
RMSE ratio and the coverage gaps of two filters at once. Such a difference is
tested by :func:`depthcore.studies.scores.difference_verdict`.
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks
from depthcore.studies.scores import LEVELS, errors_and_sds, interval_holds
from depthcore.studies.trials import Estimates

#: The per-trial depth scores whose co-moments :func:`trial_scores` gives, for paired comparisons:
#: the squared error, the stated SD, whether the central 68 % and 95 % intervals hold the truth,
#: and the Hellinger distance to the optimal filter (where computed).
PAIRED_SCORES = ("squared_error", "sd", "coverage_68", "coverage_95", "hellinger")


def pooled_comoments(n: int, mean, comoment, values) -> tuple:
    """The mean and co-moment matrix of vectors, with one more chunk of vectors pooled in.

    The matrix analogue of :func:`depthcore.studies.scores.pooled_squares` (Chan, Golub and
    LeVeque's
    pairwise update): with ``n`` earlier vectors of mean ``a`` and co-moment
    matrix ``C`` (the sum of the outer products of their deviations from
    ``a``), and a chunk of ``m`` vectors of mean ``b`` and co-moment matrix
    ``C_b``, the pooled mean is ``a + (b - a) m / (n + m)`` and the pooled
    co-moment matrix ``C + C_b + (b - a) (b - a)^T n m / (n + m)``.

    Parameters
    ----------
    n : int
        Earlier vectors, >= 0.
    mean : ndarray, shape (K,)
        Their mean (ignored when ``n`` is 0).
    comoment : ndarray, shape (K, K)
        Their co-moment matrix (ignored when ``n`` is 0).
    values : ndarray, shape (m, K)
        The chunk, ``m >= 1``.

    Returns
    -------
    tuple of ndarray
        The pooled mean (K,) and co-moment matrix (K, K).
    """
    m = len(values)
    b = np.mean(values, axis=0)
    d = values - b
    c_b = d.T @ d
    if n == 0:
        return b, c_b
    delta = b - mean
    return mean + delta * (m / (n + m)), comoment + c_b + np.outer(delta, delta) * (n * m / (n + m))


class CoMoments:
    """Running mean and covariance of per-trial score vectors over chunks of trials.

    Holds a mean (K,) and a co-moment matrix (K, K) whatever the number of
    trials (:func:`pooled_comoments`): :meth:`add` each chunk's scores, one
    row per trial, then read ``mean`` and :meth:`covariance`. The
    columns are named (``columns``) so that a pair of them can be picked out
    (:func:`pair_of` of its :meth:`summary`) for the delta-method errors of
    ratios and differences of means over the same trials (:func:`ratio_se`,
    :func:`paired_difference_se`).

    Parameters
    ----------
    columns : sequence of hashable, length K >= 1
        A name per column, e.g. ``("ekf", "squared_error")``.

    Attributes
    ----------
    n : int
        Trials added.
    mean : ndarray, shape (K,)
    comoment : ndarray, shape (K, K)
        Sum of the outer products of the trials' deviations from ``mean``.
    """

    def __init__(self, columns):
        self.columns = [tuple(c) if isinstance(c, (list, tuple)) else c for c in columns]
        if not self.columns:
            raise ValueError("columns must name at least one column")
        if len(set(self.columns)) != len(self.columns):
            raise ValueError(f"columns must be distinct, got {self.columns!r}")
        k = len(self.columns)
        self.n = 0
        self.mean = np.zeros(k)
        self.comoment = np.zeros((k, k))

    def add(self, values) -> None:
        """Pool in a chunk of trials: ``values`` of shape (m, K), one row per trial (m may be 0)."""
        values = np.asarray(values, dtype=float)
        k = len(self.columns)
        if values.ndim != 2 or values.shape[1] != k:
            raise ValueError(f"values must have shape (m, {k}), got shape {values.shape}")
        if len(values) == 0:
            return
        self.mean, self.comoment = pooled_comoments(self.n, self.mean, self.comoment, values)
        self.n += len(values)

    def covariance(self) -> np.ndarray:
        """The sample covariance (K, K) of the trials' vectors, divisor ``n - 1``."""
        if self.n < 2:
            raise ValueError(f"trials: a covariance needs at least two, got {self.n}")
        return self.comoment / (self.n - 1)

    def summary(self) -> dict:
        """JSON-ready: ``{"columns": [...], "trials": n, "mean": (K,), "cov": (K, K) or None}``.

        The covariance is ``None`` before two trials are added; tuple column
        names become lists.
        """
        return {
            "columns": [list(c) if isinstance(c, tuple) else c for c in self.columns],
            "trials": self.n,
            "mean": self.mean.tolist(),
            "cov": self.covariance().tolist() if self.n >= 2 else None,
        }


def pair_of(summary: dict, a, b) -> tuple:
    """The means (2,), covariance (2, 2) and trials of columns ``a`` and ``b`` of a summary.

    Parameters
    ----------
    summary : dict
        :meth:`CoMoments.summary`.
    a, b : hashable or sequence
        Column names, e.g. ``("ekf", "squared_error")``.

    Returns
    -------
    tuple
        ``(means, cov, trials)``, for :func:`ratio_se` and :func:`paired_difference_se`.
    """

    def key(c):
        return tuple(c) if isinstance(c, (list, tuple)) else c

    index = {key(c): i for i, c in enumerate(summary["columns"])}
    for name, c in (("a", a), ("b", b)):
        if key(c) not in index:
            raise ValueError(f"{name}: the summary has no column {c!r}")
    if summary["cov"] is None:
        raise ValueError("summary: fewer than two trials, no covariance")
    j = [index[key(c)] for c in (a, b)]
    cov = np.asarray(summary["cov"], dtype=float)[np.ix_(j, j)]
    return np.asarray(summary["mean"], dtype=float)[j], cov, int(summary["trials"])


def depth_scores(error, sd, cdf) -> dict:
    """Each trial's depth scores from plain arrays: squared error, stated SD, interval indicators.

    Parameters
    ----------
    error : array_like, shape (m,)
        The depth mean less the true depth, per trial.
    sd : array_like, shape (m,)
        The stated depth SD.
    cdf : array_like, shape (m,)
        The filter's depth CDF at the true depth.

    Returns
    -------
    dict of ndarray, each shape (m,)
        ``"squared_error"``, ``"sd"``, and for each level ``p`` of
        :data:`depthcore.studies.scores.LEVELS` ``"coverage_<100 p>"``: 1 when the
        central interval holds the truth (:func:`depthcore.studies.scores.interval_holds`),
        else 0; in the order of :data:`PAIRED_SCORES`.
    """
    out = {"squared_error": np.asarray(error, dtype=float) ** 2, "sd": np.asarray(sd, dtype=float)}
    for p in LEVELS:
        out[f"coverage_{round(100 * p)}"] = interval_holds(cdf, p).astype(float)
    return out


def trial_scores(est: Estimates, truth) -> dict:
    """Each trial's depth scores of :data:`PAIRED_SCORES`, counted as a Tally counts them.

    Parameters
    ----------
    est : Estimates
        One filter's estimates of a chunk of ``m`` trials.
    truth : array_like, shape (3,)
        The true state (``est.truth``, where given, takes its place).

    Returns
    -------
    dict of ndarray, each shape (m,)
        ``"squared_error"``, ``"sd"``, ``"coverage_68"``, ``"coverage_95"``
        (1 when the interval holds the truth, else 0) and ``"hellinger"``
        (absent when ``est.hellinger`` is ``None``).
    """
    err, sd = errors_and_sds(est, truth)
    out = depth_scores(err[:, 0], sd[:, 0], est.depth_cdf)
    if est.hellinger is not None:
        out["hellinger"] = np.asarray(est.hellinger, dtype=float)
    return out


def _pair_arrays(means, cov, trials) -> tuple:
    means = np.asarray(means, dtype=float)
    cov = np.asarray(cov, dtype=float)
    if means.shape[-1:] != (2,):
        raise ValueError(f"means must have shape (..., 2), got shape {means.shape}")
    if cov.shape[-2:] != (2, 2):
        raise ValueError(f"cov must have shape (..., 2, 2), got shape {cov.shape}")
    n = np.asarray(trials, dtype=float)
    if np.any(~(n >= 2)):
        raise ValueError("trials must each be at least 2")
    return means, cov, n


def ratio_se(means, cov, trials, powers=(1.0, 1.0)) -> np.ndarray:
    """Delta-method SE of ``a**p / b**q``, ``a`` and ``b`` two means over the same trials.

    The ratio's logarithm is ``p log a - q log b``; to first order its variance
    is ``(p**2 V_aa / a**2 + q**2 V_bb / b**2 - 2 p q V_ab / (a b)) / n``,
    ``V`` the per-trial covariance of the two scores, so that the SE is the
    ratio times its square root. The covariance term is what pairing the
    trials brings: two filters run on the same bearings err together, and the
    separate SEs (``V_ab = 0``) overstate the ratio's SE when they do.
    :func:`mean_ratio_se` (``p = q = 1``), :func:`rmse_ratio_se`
    (``p = q = 1/2``) and an RMSE over a mean SD (``p = 1/2``, ``q = 1``) are
    its cases.

    Parameters
    ----------
    means : array_like, shape (..., 2)
        The means ``a`` and ``b``, each > 0.
    cov : array_like, shape (..., 2, 2)
        Sample covariance of the per-trial scores whose means they are
        (:func:`pair_of`).
    trials : int or array_like, shape (...)
        Trials ``n >= 2`` behind the means.
    powers : (float, float)
        ``p`` and ``q``.

    Returns
    -------
    ndarray, shape (...)
        The SE (0 where rounding makes the variance negative, as for two
        identical scores).
    """
    means, cov, n = _pair_arrays(means, cov, trials)
    if np.any(~(means > 0)):
        raise ValueError("means must be positive for a ratio's delta method")
    p, q = (float(v) for v in powers)
    a, b = means[..., 0], means[..., 1]
    rel = (
        p**2 * cov[..., 0, 0] / a**2
        + q**2 * cov[..., 1, 1] / b**2
        - 2.0 * p * q * cov[..., 0, 1] / (a * b)
    ) / n
    return a**p / b**q * np.sqrt(np.maximum(rel, 0.0))


def mean_ratio_se(means, cov, trials) -> np.ndarray:
    """Delta-method SE of a ratio ``a / b`` of two means over the same trials.

    :func:`ratio_se` with ``p = q = 1``: ``means`` (..., 2), ``cov``
    (..., 2, 2) and ``trials`` are its own, and so is the result, of shape (...).
    """
    return ratio_se(means, cov, trials, (1.0, 1.0))


def rmse_ratio_se(means, cov, trials) -> np.ndarray:
    """Delta-method SE of a ratio of two RMSEs over the same trials, ``sqrt(a / b)``.

    ``a`` and ``b`` are the two filters' mean squared errors and ``cov`` the
    covariance of their per-trial squared errors: :func:`ratio_se` with
    ``p = q = 1/2``, its arguments (``means`` (..., 2), ``cov`` (..., 2, 2),
    ``trials``) and its result, of shape (...).
    """
    return ratio_se(means, cov, trials, (0.5, 0.5))


def paired_difference_se(cov, trials, signs=(1.0, 1.0)) -> np.ndarray:
    """SE of a paired difference of two means, ``s a - t b``, over the same trials.

    ``sqrt((s**2 V_aa + t**2 V_bb - 2 s t V_ab) / n)``, ``V`` the per-trial
    covariance of the two scores. The signs ``s``, ``t`` give the delta method
    of a difference of functions of the means whose slopes they are, as
    :func:`coverage_gap_difference` needs.

    Parameters
    ----------
    cov : array_like, shape (..., 2, 2)
    trials : int or array_like, shape (...)
        ``n >= 2``.
    signs : (float or array_like, float or array_like)
        ``s`` and ``t``, broadcast against shape (...).

    Returns
    -------
    ndarray, shape (...)
    """
    _, cov, n = _pair_arrays(np.zeros(2), cov, trials)
    s, t = (np.asarray(v, dtype=float) for v in signs)
    var = s**2 * cov[..., 0, 0] + t**2 * cov[..., 1, 1] - 2.0 * s * t * cov[..., 0, 1]
    return np.sqrt(np.maximum(var, 0.0) / n)


def coverage_gap_difference(means, cov, trials, level) -> tuple:
    """How much nearer its nominal level one coverage is than another, over the same trials.

    ``|a - level| - |b - level|`` for the coverages ``a`` and ``b`` (means of
    the per-trial 0/1 indicators of :func:`trial_scores`), negative when
    ``a`` is the nearer; its SE by the delta method is
    :func:`paired_difference_se` with the slopes ``sign(a - level)`` and
    ``sign(b - level)`` (a coverage exactly at the level contributes no slope).

    Parameters
    ----------
    means : array_like, shape (..., 2)
        The coverages ``a`` and ``b``.
    cov : array_like, shape (..., 2, 2)
        Covariance of the paired indicators.
    trials : int or array_like, shape (...)
    level : float
        In (0, 1).

    Returns
    -------
    tuple of ndarray, shape (...)
        The difference and its SE.
    """
    means, cov, n = _pair_arrays(means, cov, trials)
    level = checks.probability(level, "level")
    off = means - level
    gap = np.abs(off[..., 0]) - np.abs(off[..., 1])
    return gap, paired_difference_se(cov, n, (np.sign(off[..., 0]), np.sign(off[..., 1])))


def compare(summary: dict, a: str, b: str, levels=LEVELS) -> dict:
    """Filter ``a`` against filter ``b`` over the same trials: RMSE ratio and coverage gaps.

    Parameters
    ----------
    summary : dict
        The co-moments of the filters' per-trial depth scores (``"names"``,
        ``"scores"``, ``"mean"``, ``"cov"``, ``"trials"``), as
        ``study(..., paired=True)["paired"]`` gives them; it must hold ``a``
        and ``b`` with the scores ``"squared_error"`` and ``"coverage_<100 p>"``.
    a, b : str
        Two filters of the summary.
    levels : sequence of float
        The coverages' nominal levels, each in (0, 1); default
        :data:`depthcore.studies.scores.LEVELS`.

    Returns
    -------
    dict of float
        ``"rmse_ratio"`` (``a``'s depth RMSE over ``b``'s, :func:`rmse_ratio_se`)
        and, for each level ``p``, ``"coverage_<100 p>_gap"`` (how much farther
        ``a``'s coverage lies from ``p`` than ``b``'s,
        :func:`coverage_gap_difference`), each with ``"<key>_se"``; and ``"trials"``.
    """
    m, c, n = pair_of(summary, (a, "squared_error"), (b, "squared_error"))
    out = {
        "rmse_ratio": float(np.sqrt(m[0] / m[1])),
        "rmse_ratio_se": float(rmse_ratio_se(m, c, n)),
    }
    for p in levels:
        key = f"coverage_{round(100 * p)}"
        m, c, n = pair_of(summary, (a, key), (b, key))
        gap, se = coverage_gap_difference(m, c, n, p)
        out[f"{key}_gap"], out[f"{key}_gap_se"] = float(gap), float(se)
    out["trials"] = n
    return out
