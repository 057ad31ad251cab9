"""The scores of a Monte Carlo study: running sums over chunks of trials, and their errors.

Recommended import: ``from depthcore.studies import scores``.

A :class:`Tally` keeps, for one filter, the running sums of its scores over
the chunks of trials that :func:`depthcore.studies.monte_carlo.study` streams (so that
memory does not grow with the number of trials): bias and RMSE of the depth
and velocity means, coverage of central intervals at :data:`LEVELS` and
:data:`CALIBRATION_LEVELS`, mean NEES, the Hellinger distance to the optimal
filter, and the fraction of lost tracks (:func:`lost_tracks`,
:func:`track_loss`), each with its standard error (:func:`pooled_squares`,
:func:`mean_se`, :func:`coverage_se`); :func:`detectable_difference` states
the power of a coverage test; :func:`scores` tallies one chunk at once.

Beside the RMSE, what a few far-off trials cannot drive: the median absolute
error with a distribution-free 95 % interval, from a histogram of fixed memory
(:mod:`depthcore.studies.medians`), the count of divergent trials
(:data:`DIVERGENCE`) and the RMSE over the others, the track loss at
each threshold of :data:`TRACK_LOSS_LEVELS` with the RMSE over the tracks
kept, and the ANEES with its chi-square acceptance region (:func:`anees_region`).

:func:`difference_verdict` tests a difference (of two filters' scores, or
of a score and a bound) two-sided with three outcomes and
:func:`detectable_shift` states such a test's power; the differences of two
filters over the same trials and their errors are
:mod:`depthcore.studies.pairs`'.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtri

from depthcore.problem import checks
from depthcore.studies.medians import INTERVAL_LEVEL, AbsoluteErrors
from depthcore.studies.trials import Estimates, Trials

#: Nominal levels of the coverage scores, those of the central 68 % and 95 % intervals.
LEVELS = (0.68, 0.95)


#: Nominal levels of the calibration curve, central intervals from 5 % to 99 %.
CALIBRATION_LEVELS = tuple(np.round(np.concatenate([np.arange(0.05, 0.951, 0.05), [0.99]]), 2))


#: A track is lost when its position error exceeds this fraction of the point's true distance.
TRACK_LOSS = 0.5


#: Confidence of the upper bound on the track-loss probability.
TRACK_LOSS_CONFIDENCE = 0.95


#: The thresholds of :func:`lost_tracks` at which the track loss is also counted.
TRACK_LOSS_LEVELS = (0.1, 0.25, 0.5, 1.0)


#: A trial diverges when its depth error exceeds this multiple of the true depth (or is not
#: finite): an estimate off by more than the whole distance says nothing of it.
DIVERGENCE = 1.0


#: Every nominal level whose coverage is counted: :data:`LEVELS` and :data:`CALIBRATION_LEVELS`.
_COVERAGE_LEVELS = tuple(sorted(set(LEVELS) | set(CALIBRATION_LEVELS)))


class Tally:
    """Running sums of one filter's scores over chunks of trials.

    Holds a fixed number of sums and counts, whatever the number of trials:
    :meth:`add` each chunk's :class:`~depthcore.studies.trials.Estimates`, then read :meth:`scores`.
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
    absolute : tuple of AbsoluteErrors
        The depth and velocity absolute errors, binned
        (:class:`~depthcore.studies.medians.AbsoluteErrors`).
    kept : dict
        Over the trials kept by each rule, ``"divergent"`` (the depth error
        within :data:`DIVERGENCE` times the true depth) and each threshold of
        :data:`TRACK_LOSS_LEVELS`: ``{"n", "squared_error" (2,), "spread" (2,)}``,
        the trials kept, the sums of their squared depth and velocity errors
        and those sums' squared deviations (:func:`pooled_squares`).
    nees_outside : int
        Trials whose NEES lies outside the chi-square(3) region at
        :data:`~depthcore.studies.medians.INTERVAL_LEVEL` (:func:`anees_region` of
        one trial).
    """

    def __init__(self, truth):
        self.truth = checks.finite_array(truth, "truth", (3,))
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
        self.absolute = (AbsoluteErrors(), AbsoluteErrors())
        self.kept = {
            rule: {"n": 0, "squared_error": np.zeros(2), "spread": np.zeros(2)}
            for rule in ("divergent", *TRACK_LOSS_LEVELS)
        }
        self.nees_outside = 0
        self.refused = 0

    def add(self, est: Estimates) -> None:
        """Add the scores of one chunk of trials (an empty chunk adds nothing).

        The trials the filter refused (``est.refused``) are counted apart.
        """
        self.refused += int(est.refused)
        n = len(est.mean)
        if n == 0:
            return
        self._add_robust(est, n)
        full = est.mean - (self.truth if est.truth is None else est.truth)
        nees = np.einsum("ni,ni->n", full, np.linalg.solve(est.cov, full[..., None])[..., 0])
        err, sd = errors_and_sds(est, self.truth)
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

    def _add_robust(self, est: Estimates, n: int) -> None:
        """The robust scores' sums of one chunk: absolute errors, trials kept, NEES outside."""
        err, _ = errors_and_sds(est, self.truth)
        truths = self._truths(est, n)
        for k in range(2):
            self.absolute[k].add(np.abs(err[:, k]))
        keep = {"divergent": ~divergent(est.mean[:, 1], truths[:, 1])}
        for t in TRACK_LOSS_LEVELS:
            keep[t] = ~lost_tracks(est.mean, truths, t)
        for rule, rows in keep.items():
            kept = self.kept[rule]
            squared = err[rows] ** 2
            if len(squared):
                kept["spread"] = pooled_squares(
                    kept["n"], kept["squared_error"], kept["spread"], squared
                )
                kept["squared_error"] = kept["squared_error"] + np.sum(squared, axis=0)
                kept["n"] += len(squared)
        full = est.mean - truths
        nees = np.einsum("ni,ni->n", full, np.linalg.solve(est.cov, full[..., None])[..., 0])
        lo, hi = anees_region(1, 3, INTERVAL_LEVEL)
        self.nees_outside += int(np.count_nonzero(~((nees >= lo) & (nees <= hi))))

    def robust_scores(self) -> dict:
        """The scores beside the RMSE that a few far-off trials cannot drive.

        Returns
        -------
        dict
            ``{"depth": {...}, "velocity": {...}}`` with ``"median_abs_error"``,
            ``"median_abs_error_ci"`` (:meth:`~depthcore.studies.medians.AbsoluteErrors.median`),
            ``"rmse_kept"``, ``"rmse_kept_se"`` (over the trials that did not
            diverge; None when every trial did); ``"divergent"`` (:func:`fraction_of`, with the
            ``"threshold"`` :data:`DIVERGENCE` and the ``"count"``);
            ``"track_loss_levels"``, ``{f"{t:g}": {"lost", "fraction", "se",
            "upper", "rmse_kept", "rmse_kept_se"}}`` for each threshold of
            :data:`TRACK_LOSS_LEVELS` (the depth RMSE over the tracks kept);
            ``"anees"``: ``{"value", "se", "dim", "region", "outside",
            "outside_se"}`` (:func:`anees_region`; ``"outside"`` the fraction of
            trials whose NEES lies outside the one-trial region).
        """
        n = self.n
        out = {}
        for k, q in enumerate(("depth", "velocity")):
            median, ci = self.absolute[k].median(INTERVAL_LEVEL)
            rmse, rmse_se = self._kept_rmse("divergent", k)
            out[q] = {
                "median_abs_error": median,
                "median_abs_error_ci": ci,
                "rmse_kept": rmse,
                "rmse_kept_se": rmse_se,
            }
        count = n - self.kept["divergent"]["n"]
        out["divergent"] = {"threshold": DIVERGENCE, "count": count, **fraction_of(count, n)}
        out["track_loss_levels"] = {}
        for t in TRACK_LOSS_LEVELS:
            lost = n - self.kept[t]["n"]
            rmse, rmse_se = self._kept_rmse(t, 0)
            out["track_loss_levels"][f"{t:g}"] = {
                "lost": lost,
                **fraction_of(lost, n),
                "rmse_kept": rmse,
                "rmse_kept_se": rmse_se,
            }
        outside = fraction_of(self.nees_outside, n)
        out["anees"] = {
            "value": float(self.nees / n),
            "se": mean_se(self.spread["nees"], n),
            "dim": 3,
            "region": list(anees_region(n, 3, INTERVAL_LEVEL)),
            "outside": outside["fraction"],
            "outside_se": outside["se"],
        }
        return out

    def _kept_rmse(self, rule, k: int) -> tuple:
        """The RMSE of quantity ``k`` over the trials ``rule`` keeps and its SE; None when none."""
        kept = self.kept[rule]
        m = kept["n"]
        if m == 0:
            return None, None
        rmse = float(np.sqrt(kept["squared_error"][k] / m))
        se = mean_se(kept["spread"][k], m)
        return rmse, se / (2.0 * rmse) if rmse > 0 else 0.0

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
        out["refused"] = refused_scores(self.refused, n)
        robust = self.robust_scores()
        for q in ("depth", "velocity"):
            out[q].update(robust.pop(q))
        out.update(robust)
        return out


def refused_scores(refused: int, answered: int) -> dict:
    """Trials refused, apart from the ``answered`` scored: ``{"count", "fraction", "se"}``."""
    total = int(refused) + int(answered)
    se = float(proportion_se(int(refused), total))
    return {"count": int(refused), "fraction": int(refused) / total, "se": se}


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


def errors_and_sds(est: Estimates, truth) -> tuple:
    """Each trial's depth and velocity errors and stated SDs, both shape (n, 2).

    ``truth`` (3,) is the true state, which ``est.truth``, where given, replaces.
    """
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
    threshold = checks.positive_scalar(threshold, "threshold")
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
    n = checks.count(trials, "trials")
    if isinstance(lost, bool) or not isinstance(lost, (int, np.integer)) or not 0 <= lost <= n:
        raise ValueError(f"lost must be an integer from 0 to trials = {n}, got {lost!r}")
    confidence = checks.probability(confidence, "confidence")
    from scipy.stats import beta  # imported here: scipy.stats takes a second to import

    p = lost / n
    upper = 1.0 if lost == n else float(beta.ppf(confidence, lost + 1, n - lost))
    return {
        "fraction": float(p),
        "se": float(np.sqrt(p * (1 - p) / n)),
        "upper": upper,
        "threshold": TRACK_LOSS,
        "confidence": float(confidence),
    }


def divergent(depth, true_depth, threshold: float = DIVERGENCE) -> np.ndarray:
    """Whether each trial diverged: ``|depth - true_depth| > threshold true_depth``, or NaN.

    Parameters
    ----------
    depth, true_depth : array_like, shape (...)
        Estimated and true depths (the true ones > 0).
    threshold : float
        > 0, a multiple of the true depth (default :data:`DIVERGENCE`).

    Returns
    -------
    ndarray of bool, shape (...)
    """
    threshold = checks.positive_scalar(threshold, "threshold")
    depth = np.asarray(depth, dtype=float)
    true_depth = np.asarray(true_depth, dtype=float)
    return ~(np.abs(depth - true_depth) <= threshold * true_depth)


def fraction_of(count: int, trials: int, confidence: float = TRACK_LOSS_CONFIDENCE) -> dict:
    """A fraction of trials, its binomial SE and its exact one-sided upper bound.

    As :func:`track_loss`: ``{"fraction", "se", "upper"}``, ``se`` the
    binomial ``sqrt(p (1 - p) / n)`` and ``upper`` the Clopper-Pearson bound
    at ``confidence`` (useful when ``count`` is 0, where ``se`` is 0).
    """
    t = track_loss(count, trials, confidence)
    return {"fraction": t["fraction"], "se": t["se"], "upper": t["upper"]}


def anees_region(trials: int, dim: int = 3, level: float = INTERVAL_LEVEL) -> tuple:
    """The two-sided acceptance region of the ANEES of ``trials`` trials of a consistent filter.

    For a filter whose errors follow its covariance, each trial's NEES is
    chi-square with ``dim`` degrees of freedom, so ``M`` times the average of
    ``M`` independent trials' NEES (the ANEES) is chi-square with ``M dim``
    (Bar-Shalom, Li and Kirubarajan 2001, section 5.4). The region holds the
    ANEES with probability ``level``.

    Parameters
    ----------
    trials : int
        ``M >= 1``.
    dim : int
        The state's dimension, >= 1.
    level : float
        In (0, 1).

    Returns
    -------
    tuple of float
        ``(lo, hi)``: the chi-square(``M dim``) quantiles at ``(1 - level) / 2``
        and ``(1 + level) / 2``, over ``M``.
    """
    m = checks.count(trials, "trials")
    dim = checks.count(dim, "dim")
    level = checks.probability(level, "level")
    from scipy.stats import chi2

    lo, hi = chi2.ppf([(1 - level) / 2, (1 + level) / 2], m * dim)
    return float(lo / m), float(hi / m)


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


def trials_for_se(se: float, level: float = 0.68, step: int = 100) -> int:
    """The fewest trials, a multiple of ``step``, whose coverage SE at ``level`` is at most ``se``.

    The inverse of :func:`coverage_se`: ``n = step * ceil(p (1 - p) / (se^2 step))``
    for ``p = level``; 2,200 trials bring a 68 % coverage's SE to 0.01
    (0.00995), which is what a verdict of :func:`coverage_test` between a
    calibrated filter and one a few points off needs.

    Parameters
    ----------
    se : float
        The largest standard error, > 0.
    level : float
        Nominal level ``p``, in (0, 1).
    step : int
        Trials are counted in multiples of it, >= 1.

    Returns
    -------
    int
    """
    se, step = checks.positive_scalar(se, "se"), checks.count(step, "step")
    level = checks.probability(level, "level")
    n = step * max(1, int(np.ceil(level * (1.0 - level) / se**2 / step)))
    while coverage_se(level, n) > se:  # the rounding of the quotient, at most once
        n += step
    while n > step and coverage_se(level, n - step) <= se:
        n -= step
    return n


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
    false_alarm, power : float
        The test's size and power, as :func:`detectable_shift` takes them.

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
    false_alarm = checks.probability(false_alarm, "false_alarm")
    power = checks.probability(power, "power")
    z = ndtri(1.0 - false_alarm / 2.0) + ndtri(power)
    return z * np.asarray(se, dtype=float)


#: The default critical value of :func:`coverage_test`, the standard normal's two-sided 1 % point.
COVERAGE_Z = TEST_Z


def coverage_test(coverage, level: float, trials, z: float = COVERAGE_Z) -> dict:
    """The binomial test of a coverage against its nominal level, normal approximation.

    A filter whose central ``level`` interval holds the truth with probability
    ``level`` covers it in a fraction of ``n`` independent trials with standard
    error ``sqrt(level (1 - level) / n)``. The coverage is called
    ``"calibrated"`` when it lies within ``z`` standard errors of the level
    (a two-sided test at 1 % for the default ``z``), ``"overconfident"`` when
    below (intervals too narrow), ``"underconfident"`` when above.

    Parameters
    ----------
    coverage : array_like, shape (...)
        Fractions of trials covered, in [0, 1].
    level : float
        Nominal level, in (0, 1).
    trials : array_like of int, shape (...)
        Trials behind each coverage, >= 1.
    z : float
        Critical value, > 0.

    Returns
    -------
    dict
        ``"se"``, ``"z"`` (the standardised deviation) and ``"verdict"``
        (array of str), each of the broadcast shape.
    """
    coverage = checks.finite_array(coverage, "coverage")
    if np.any((coverage < 0) | (coverage > 1)):
        raise ValueError("coverage must lie in [0, 1]")
    level = checks.probability(level, "level")
    trials = checks.finite_array(trials, "trials")
    if np.any(trials < 1):
        raise ValueError("trials must each be at least 1")
    z = checks.positive_scalar(z, "z")
    se = coverage_se(level, trials)
    score = (coverage - level) / se
    verdict = np.where(
        np.abs(score) <= z, "calibrated", np.where(score < 0, "overconfident", "underconfident")
    )
    return {"se": se, "z": score, "verdict": verdict}
