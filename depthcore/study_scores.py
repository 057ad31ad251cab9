"""The scores of a Monte Carlo study: running sums over chunks of trials, and their errors.

Recommended import: ``from depthcore import study_scores``.

A :class:`Tally` keeps, for one filter, the running sums of its scores over
the chunks of trials that :func:`depthcore.study.study` streams (so that
memory does not grow with the number of trials): bias and RMSE of the depth
and velocity means, coverage of central intervals at :data:`LEVELS` and
:data:`CALIBRATION_LEVELS`, mean NEES, the Hellinger distance to the optimal
filter, and the fraction of lost tracks (:func:`lost_tracks`,
:func:`track_loss`), each with its standard error (:func:`pooled_squares`,
:func:`mean_se`, :func:`coverage_se`); :func:`detectable_difference` states
the power of a coverage test; :func:`scores` tallies one chunk at once.

Two scores from the same trials are correlated, so their separate errors do
not give the error of their ratio or difference. A :class:`CoMoments` keeps
the running mean and covariance of several filters' per-trial scores
(:func:`trial_scores`, :func:`pooled_comoments`) over the same chunks, and the
delta method gives the errors of a ratio of two means (:func:`mean_ratio_se`),
of two RMSEs (:func:`rmse_ratio_se`), of any ratio of powers of two means
(:func:`ratio_se`), of a paired difference (:func:`paired_difference_se`) and
of how much nearer its level one coverage is than another
(:func:`coverage_gap_difference`); :func:`difference_verdict` tests such a
difference two-sided with three outcomes and :func:`detectable_shift` states
the test's power.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtri
from scipy.stats import beta

from . import _checks
from .study_trials import Estimates, Trials

#: Nominal levels of the coverage scores, those of the central 68 % and 95 % intervals.
LEVELS = (0.68, 0.95)


#: Nominal levels of the calibration curve, central intervals from 5 % to 99 %.
CALIBRATION_LEVELS = tuple(np.round(np.concatenate([np.arange(0.05, 0.951, 0.05), [0.99]]), 2))


#: A track is lost when its position error exceeds this fraction of the point's true distance.
TRACK_LOSS = 0.5


#: Confidence of the upper bound on the track-loss probability.
TRACK_LOSS_CONFIDENCE = 0.95


#: Every nominal level whose coverage is counted: :data:`LEVELS` and :data:`CALIBRATION_LEVELS`.
_COVERAGE_LEVELS = tuple(sorted(set(LEVELS) | set(CALIBRATION_LEVELS)))


class Tally:
    """Running sums of one filter's scores over chunks of trials.

    Holds a fixed number of sums and counts, whatever the number of trials:
    :meth:`add` each chunk's :class:`~depthcore.study_trials.Estimates`, then read :meth:`scores`.
    The
    sums of a chunk are taken with ``numpy.sum`` and added in order, so one
    chunk gives exactly the means ``numpy.mean`` gives over it, and several
    chunks agree with one to rounding.

    Parameters
    ----------
    truth : array_like, shape (3,)
        True state at time 3 (each chunk's ``Estimates.truth``, where given,
        takes its place).

    Attributes
    ----------
    n : int
        Trials added.
    error : ndarray, shape (2,)
        Sums over the trials of the depth and velocity errors.
    squared_error : ndarray, shape (2,)
        Sums of their squares.
    sd : ndarray, shape (2,)
        Sums of the filter's depth and velocity SDs.
    spread : dict of ndarray or float
        For the standard errors: the sums of squared deviations from their
        mean (:func:`pooled_squares`) of the errors (``"error"``), their
        squares (``"squared_error"``), the SDs (``"sd"``), the NEES
        (``"nees"``) and the Hellinger distances (``"hellinger"``, absent once
        a chunk has none).
    covered : ndarray of int, shape (2, L)
        Trials whose central interval holds the true depth and velocity, at
        each of the ``L`` levels of :data:`LEVELS` and :data:`CALIBRATION_LEVELS`.
    nees : float
        Sum of the NEES.
    hellinger : float or None
        Sum of the Hellinger distances; ``None`` once a chunk has none.
    lost : int
        Trials whose track is lost (:func:`lost_tracks`).
    """

    def __init__(self, truth):
        self.truth = _checks.finite_array(truth, "truth", (3,))
        self.n = 0
        self.error = np.zeros(2)  # sums of estimate - truth, depth and velocity
        self.squared_error = np.zeros(2)
        self.sd = np.zeros(2)
        self.covered = np.zeros((2, len(_COVERAGE_LEVELS)), dtype=np.int64)
        self.nees = 0.0
        self.hellinger: float | None = 0.0
        self.spread: dict = {
            "error": np.zeros(2),
            "squared_error": np.zeros(2),
            "sd": np.zeros(2),
            "nees": 0.0,
            "hellinger": 0.0,
        }
        self.lost = 0

    def add(self, est: Estimates) -> None:
        """Add the scores of one chunk of trials (an empty chunk adds nothing)."""
        n = len(est.mean)
        if n == 0:
            return
        full = est.mean - (self.truth if est.truth is None else est.truth)
        nees = np.einsum("ni,ni->n", full, np.linalg.solve(est.cov, full[..., None])[..., 0])
        err, sd = _errors_and_sds(est, self.truth)
        chunk = {"error": err, "squared_error": err**2, "sd": sd, "nees": nees}
        if est.hellinger is not None and self.hellinger is not None:
            chunk["hellinger"] = np.asarray(est.hellinger, dtype=float)
        else:
            self.spread.pop("hellinger", None)
        sums = {
            "error": self.error,
            "squared_error": self.squared_error,
            "sd": self.sd,
            "nees": self.nees,
            "hellinger": self.hellinger,
        }
        for key, values in chunk.items():
            self.spread[key] = pooled_squares(self.n, sums[key], self.spread[key], values)
        for k, cdf in enumerate((est.depth_cdf, est.velocity_cdf)):
            self.error[k] += np.sum(err[:, k])
            self.squared_error[k] += np.sum(err[:, k] ** 2)
            self.sd[k] += np.sum(sd[:, k])
            self.covered[k] += [np.count_nonzero(interval_holds(cdf, p)) for p in _COVERAGE_LEVELS]
        self.nees += np.sum(nees)
        if est.hellinger is None or self.hellinger is None:
            self.hellinger = None
        else:
            self.hellinger += np.sum(est.hellinger)
        self.lost += int(np.count_nonzero(lost_tracks(est.mean, self._truths(est, n))))
        self.n += n

    def _truths(self, est: Estimates, n: int) -> np.ndarray:
        return np.broadcast_to(self.truth if est.truth is None else est.truth, (n, 3))

    def scores(self) -> dict:
        """The scores of :func:`scores` over every trial added, with their standard errors."""
        if self.n == 0:
            raise ValueError("trials: no trial was added to the tally")
        n = self.n
        level = {p: j for j, p in enumerate(_COVERAGE_LEVELS)}
        out = {}
        spread = self.spread
        for k, q in enumerate(("depth", "velocity")):
            rmse = float(np.sqrt(self.squared_error[k] / n))
            mse_se = mean_se(spread["squared_error"][k], n)
            out[q] = {
                "bias": float(self.error[k] / n),
                "bias_se": mean_se(spread["error"][k], n),
                "rmse": rmse,
                # the delta method: d sqrt(m) = dm / (2 sqrt(m))
                "rmse_se": mse_se / (2.0 * rmse) if rmse > 0 else 0.0,
                "mean_sd": float(self.sd[k] / n),
                "mean_sd_se": mean_se(spread["sd"][k], n),
            }
            for p in LEVELS:
                c = float(self.covered[k, level[p]] / n)
                out[q][f"coverage_{round(100 * p)}"] = c
                covered = self.covered[k, level[p]]
                out[q][f"coverage_{round(100 * p)}_se"] = float(proportion_se(covered, n))
        out["nees"] = float(self.nees / n)
        out["nees_se"] = mean_se(spread["nees"], n)
        out["calibration"] = {
            "levels": list(CALIBRATION_LEVELS),
            **{
                q: [float(self.covered[k, level[p]] / n) for p in CALIBRATION_LEVELS]
                for k, q in enumerate(("depth", "velocity"))
            },
        }
        out["hellinger_depth"] = (
            None
            if self.hellinger is None
            else {
                "mean": float(self.hellinger / n),
                "se": mean_se(spread["hellinger"], n),
            }
        )
        out["track_loss"] = track_loss(self.lost, n)
        return out


def pooled_squares(n, total, squares, values):
    """The sum of squared deviations from the mean, with one more chunk of values pooled in.

    Chan, Golub and LeVeque's pairwise update: with ``n`` earlier values of
    sum ``total`` and sum of squared deviations ``squares``, and a chunk of
    ``m`` values of mean ``b`` and sum of squared deviations ``s_b``,
    ``squares + s_b + (b - total / n)**2 n m / (n + m)``. Unlike the sum of
    squares less ``n`` times the squared mean, no two large numbers are
    subtracted, so the result does not depend on the chunks beyond rounding.

    Parameters
    ----------
    n : int
        Earlier values, >= 0.
    total : float or ndarray, shape (...)
        Their sum (ignored when ``n`` is 0).
    squares : float or ndarray, shape (...)
        Their sum of squared deviations from their mean.
    values : ndarray, shape (m, ...)
        The chunk, ``m >= 1``.

    Returns
    -------
    float or ndarray, shape (...)
    """
    m = len(values)
    b = np.mean(values, axis=0)
    s_b = np.sum((values - b) ** 2, axis=0)
    if n == 0:
        return s_b
    return squares + s_b + (b - total / n) ** 2 * (n * m / (n + m))


def _errors_and_sds(est: Estimates, truth) -> tuple:
    """Each trial's depth and velocity errors and stated SDs, both shape (n, 2)."""
    full = est.mean - (truth if est.truth is None else est.truth)
    return full[:, 1:], np.sqrt(est.cov[:, (1, 2), (1, 2)])


def interval_holds(cdf, level) -> np.ndarray:
    """Whether each central ``level`` interval holds the truth: ``|cdf - 1/2| <= level / 2``.

    Parameters
    ----------
    cdf : array_like, shape (...)
        The estimate's CDF at the truth (its PIT value).
    level : float
        Nominal level, in (0, 1).

    Returns
    -------
    ndarray of bool, shape (...)
    """
    return np.abs(np.asarray(cdf, dtype=float) - 0.5) <= level / 2


def mean_se(squares, n: int) -> float:
    """Standard error ``sqrt(s**2 / n)`` of a mean over ``n`` independent trials.

    ``s**2 = squares / (n - 1)`` is the trials' sample variance, from the sum
    of squared deviations from their mean (:func:`pooled_squares`); 0 for one
    trial (no spread to estimate).

    Parameters
    ----------
    squares : float
        Sum of squared deviations from the mean, >= 0.
    n : int
        Trials, >= 1.

    Returns
    -------
    float
    """
    if n < 2:
        return 0.0
    return float(np.sqrt(float(squares) / (n - 1) / n))


def lost_tracks(mean, truth, threshold: float = TRACK_LOSS) -> np.ndarray:
    """Whether each trial's track is lost: its position error beyond ``threshold`` times the range.

    A track is lost when ``|(x_est - x, y_est - y)| > threshold |(x, y)|`` at the
    last frame (or the estimate is not finite); see the module docstring.

    Parameters
    ----------
    mean : array_like, shape (..., 3)
        Estimated states ``(x, y, v)``.
    truth : array_like, shape (..., 3)
        True states.
    threshold : float
        > 0.

    Returns
    -------
    ndarray of bool, shape (...)
    """
    threshold = _checks.positive_scalar(threshold, "threshold")
    mean = np.asarray(mean, dtype=float)
    truth = np.asarray(truth, dtype=float)
    error = np.hypot(mean[..., 0] - truth[..., 0], mean[..., 1] - truth[..., 1])
    return ~(error <= threshold * np.hypot(truth[..., 0], truth[..., 1]))


def track_loss(lost: int, trials: int, confidence: float = TRACK_LOSS_CONFIDENCE) -> dict:
    """The fraction of lost tracks, its standard error and an exact upper confidence bound.

    Parameters
    ----------
    lost : int
        Tracks lost, ``0 <= lost <= trials``.
    trials : int
        ``n >= 1``.
    confidence : float
        Of the one-sided upper bound, in (0, 1).

    Returns
    -------
    dict
        ``fraction`` ``p = lost / n``; ``se``, the binomial ``sqrt(p (1 - p) / n)``;
        ``upper`` the Clopper-Pearson bound, the ``confidence`` quantile of
        ``Beta(lost + 1, n - lost)`` (1 when every track is lost);
        ``threshold`` and ``confidence``.
    """
    n = _checks.count(trials, "trials")
    if isinstance(lost, bool) or not isinstance(lost, (int, np.integer)) or not 0 <= lost <= n:
        raise ValueError(f"lost must be an integer from 0 to trials = {n}, got {lost!r}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    p = lost / n
    upper = 1.0 if lost == n else float(beta.ppf(confidence, lost + 1, n - lost))
    return {
        "fraction": float(p),
        "se": float(np.sqrt(p * (1 - p) / n)),
        "upper": upper,
        "threshold": TRACK_LOSS,
        "confidence": float(confidence),
    }


def coverage_se(level, trials) -> np.ndarray:
    """Binomial standard error ``sqrt(p (1 - p) / n)`` of a coverage at level ``p``, ``n`` trials.

    Parameters
    ----------
    level : float or array_like
        Nominal levels ``p`` in (0, 1).
    trials : int or array_like
        Independent trials ``n >= 1``, broadcast against ``level``.

    Returns
    -------
    ndarray
        The standard error of a calibrated filter's coverage.
    """
    level = np.asarray(level, dtype=float)
    return np.sqrt(level * (1 - level) / trials)


def proportion_se(covered, trials) -> np.ndarray:
    """Standard error of a coverage estimated from ``covered`` of ``trials`` trials.

    The binomial ``sqrt(p (1 - p) / n)`` at the Agresti-Coull centre
    ``p = (k + 2) / (n + 4)``, over ``n + 4`` trials: it agrees with the
    plug-in ``sqrt(c (1 - c) / n)`` (``c = k / n``) to a relative ``O(1 / n)``
    inside the range, but stays positive when no trial or every trial is
    covered, where the plug-in says 0 and a reader would take the coverage
    for exact (``k = 0`` of 150: 0.009, about a third of the rule of three's
    95 % bound ``3 / n``).

    Parameters
    ----------
    covered : int or array_like
        Covered trials ``k``, from 0 to ``n``.
    trials : int or array_like
        Trials ``n >= 1``, broadcast against ``covered``.

    Returns
    -------
    ndarray
    """
    k = np.asarray(covered, dtype=float)
    n = np.asarray(trials, dtype=float)
    centre = (k + 2.0) / (n + 4.0)
    return np.sqrt(centre * (1.0 - centre) / (n + 4.0))


#: The size and power at which :func:`detectable_difference` states a coverage test's reach.
TEST_FALSE_ALARM = 0.01


#: The power at which :func:`detectable_difference` states a coverage test's reach.
TEST_POWER = 0.8


def detectable_difference(
    level, trials, false_alarm: float = TEST_FALSE_ALARM, power: float = TEST_POWER
):
    """The smallest coverage error that a two-sided binomial test finds with a given power.

    A coverage ``c`` of ``n`` trials is tested against its nominal level
    ``p`` by ``|c - p| > z_a sqrt(p (1 - p) / n)``, ``z_a`` the standard
    normal's upper ``false_alarm / 2`` point. In the normal approximation a
    filter whose true coverage is ``p ± d`` fails the test with probability
    ``power`` (ignoring the far tail) when
    ``d = (z_a + z_b) sqrt(p (1 - p) / n)``, ``z_b`` the standard normal's
    ``power`` quantile.

    Parameters
    ----------
    level : float or array_like
        Nominal levels ``p`` in (0, 1).
    trials : int or array_like
        ``n >= 1``, broadcast against ``level``.
    false_alarm : float
        The test's size, in (0, 1).
    power : float
        In (0, 1).

    Returns
    -------
    ndarray
        ``d``, of the broadcast shape.
    """
    return detectable_shift(coverage_se(level, trials), false_alarm, power)


def scores(trials: Trials, est: Estimates) -> dict:
    """Bias, RMSE, coverage, NEES and Hellinger distance of one filter, each with its SE.

    Every score ``s`` has its Monte Carlo standard error beside it as
    ``s_se`` (the Hellinger distance's as ``hellinger_depth["se"]``): the
    sample SD over the trials divided by ``sqrt(n)`` for the means (bias, mean
    SD, NEES, Hellinger distance), ``sqrt(c (1 - c) / n)`` for a coverage
    ``c``, and the delta method's ``se(MSE) / (2 RMSE)`` for the RMSE.

    ``calibration`` holds the coverage of the central intervals at every level
    of :data:`CALIBRATION_LEVELS`: a calibrated filter's curve is the diagonal.
    ``hellinger_depth`` is ``{"mean": ...}``, or ``None`` when the estimates
    have no Hellinger distances (the optimal filter was not run).
    """
    tally = Tally(trials.truth)
    tally.add(est)
    return tally.scores()


# --- scores of several filters over the same trials -------------------------------------------

#: The per-trial depth scores whose co-moments :func:`trial_scores` gives, for paired comparisons:
#: the squared error, the stated SD, whether the central 68 % and 95 % intervals hold the truth,
#: and the Hellinger distance to the optimal filter (where computed).
PAIRED_SCORES = ("squared_error", "sd", "coverage_68", "coverage_95", "hellinger")


def pooled_comoments(n: int, mean, comoment, values) -> tuple:
    """The mean and co-moment matrix of vectors, with one more chunk of vectors pooled in.

    The matrix analogue of :func:`pooled_squares` (Chan, Golub and LeVeque's
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


def trial_scores(est: Estimates, truth) -> dict:
    """Each trial's depth scores of :data:`PAIRED_SCORES`, as :class:`Tally` counts them.

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
    err, sd = _errors_and_sds(est, truth)
    out = {"squared_error": err[:, 0] ** 2, "sd": sd[:, 0]}
    for p in LEVELS:
        out[f"coverage_{round(100 * p)}"] = interval_holds(est.depth_cdf, p).astype(float)
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
    """Delta-method SE of a ratio ``a / b`` of two means over the same trials (:func:`ratio_se`).

    Parameters
    ----------
    means : array_like, shape (..., 2)
    cov : array_like, shape (..., 2, 2)
    trials : int or array_like, shape (...)

    Returns
    -------
    ndarray, shape (...)
    """
    return ratio_se(means, cov, trials, (1.0, 1.0))


def rmse_ratio_se(means, cov, trials) -> np.ndarray:
    """Delta-method SE of a ratio of two RMSEs over the same trials, ``sqrt(a / b)``.

    ``a`` and ``b`` are the two filters' mean squared errors and ``cov`` the
    covariance of their per-trial squared errors (:func:`ratio_se` with
    ``p = q = 1/2``).

    Parameters
    ----------
    means : array_like, shape (..., 2)
    cov : array_like, shape (..., 2, 2)
    trials : int or array_like, shape (...)

    Returns
    -------
    ndarray, shape (...)
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
    level = float(level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    off = means - level
    gap = np.abs(off[..., 0]) - np.abs(off[..., 1])
    return gap, paired_difference_se(cov, n, (np.sign(off[..., 0]), np.sign(off[..., 1])))


#: The critical value of :func:`difference_verdict`: the two-sided point of
#: :data:`TEST_FALSE_ALARM` (2.5758 for 1 %).
TEST_Z = float(ndtri(1.0 - TEST_FALSE_ALARM / 2.0))


def difference_verdict(difference, se, z: float = TEST_Z) -> np.ndarray:
    """A two-sided z test of a difference against 0, with three outcomes.

    Parameters
    ----------
    difference : array_like, shape (...)
        An estimate less its null value (a paired difference of two filters'
        scores, or a score less a bound).
    se : array_like, shape (...)
        Its standard error, >= 0.
    z : float
        Critical value, > 0 (default the 1 % point, :data:`TEST_Z`).

    Returns
    -------
    ndarray of int, shape (...)
        ``1`` where ``difference > z se`` (significantly above), ``-1`` where
        ``difference < -z se`` (significantly below), ``0`` where the test
        detects no difference.
    """
    d = np.asarray(difference, dtype=float)
    se = np.asarray(se, dtype=float)
    if np.any(se < 0) or np.any(~np.isfinite(se)):
        raise ValueError("se must be finite and >= 0")
    z = float(z)
    if not z > 0:
        raise ValueError(f"z must be positive, got {z!r}")
    return np.where(d > z * se, 1, np.where(d < -z * se, -1, 0))


def detectable_shift(se, false_alarm: float = TEST_FALSE_ALARM, power: float = TEST_POWER):
    """The smallest true difference a two-sided z test finds with a given power.

    ``(z_a + z_b) se``, ``z_a`` the standard normal's upper ``false_alarm / 2``
    point and ``z_b`` its ``power`` quantile (normal approximation, ignoring
    the far tail).

    Parameters
    ----------
    se : float or array_like
        The standard error of the difference tested.
    false_alarm : float
        The test's size, in (0, 1).
    power : float
        In (0, 1).

    Returns
    -------
    ndarray
        Of the shape of ``se``.
    """
    for value, name in ((false_alarm, "false_alarm"), (power, "power")):
        if not 0.0 < float(value) < 1.0:
            raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
    z = ndtri(1.0 - float(false_alarm) / 2.0) + ndtri(float(power))
    return z * np.asarray(se, dtype=float)
