"""The scores of a Monte Carlo study: running sums over chunks of trials, and their errors.

Recommended import: ``from depthcore.studies import scores``.

A :class:`Tally` keeps one filter's running sums of its scores over the
chunks of trials that :func:`depthcore.studies.monte_carlo.study` streams (its
memory does not grow with the trials): bias and RMSE, coverage, NEES, the
Hellinger distance to the optimal filter and the track loss, each with its
standard error; and, beside the RMSE, what a few far-off trials cannot drive
(:meth:`Tally.robust_scores`, the medians of :mod:`depthcore.studies.medians`).
:func:`scores` tallies one chunk at once.

:func:`coverage_test` and :func:`difference_verdict` test a coverage or a
difference, :func:`detectable_difference` and :func:`detectable_shift` state
their power; the differences of two filters over the same trials are
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

    :meth:`add` each chunk's :class:`~depthcore.studies.trials.Estimates`, then
    read :meth:`scores`; one chunk gives exactly ``numpy.mean``'s means, several
    agree with one to rounding.

    Parameters
    ----------
    truth : array_like, shape (3,)
        True state at time 3 (a chunk's ``Estimates.truth`` replaces it).

    Attributes
    ----------
    n : int
        Trials added.
    error : ndarray, shape (2,)
    squared_error : ndarray, shape (2,)
    sd : ndarray, shape (2,)
        Sums of the depth and velocity errors, their squares, and the SDs.
    spread : dict of ndarray or float
        Sums of squared deviations (:func:`pooled_squares`) of ``"error"``,
        ``"squared_error"``, ``"sd"``, ``"nees"`` and ``"hellinger"`` (absent
        once a chunk has none).
    covered : ndarray of int, shape (2, L)
        Trials covered at each level of :data:`LEVELS` and :data:`CALIBRATION_LEVELS`.
    nees : float
    hellinger : float or None
        ``None`` once a chunk has none.
    lost : int
        Trials whose track is lost (:func:`lost_tracks`).
    absolute : tuple of AbsoluteErrors
        The depth and velocity absolute errors, binned.
    kept : dict
        For ``"divergent"`` (:func:`divergent`) and each threshold of
        :data:`TRACK_LOSS_LEVELS`, over the trials kept: ``{"n",
        "squared_error" (2,), "spread" (2,)}``.
    nees_outside : int
        Trials outside the one-trial :func:`anees_region`.
    refused : int
        Trials the filter refused, counted apart.
    no_maximum : int or None
        Trials where its estimate had no interior maximum, counted apart;
        ``None`` for a filter whose estimates carry no such flag.
    """

    def __init__(self, truth):
        self.truth = checks.finite_array(truth, "truth", (3,))
        self.n = 0
        self.error = np.zeros(2)
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
        self.no_maximum: int | None = None

    def add(self, est: Estimates) -> None:
        """Add the scores of one chunk of trials (an empty chunk adds nothing).

        The trials the filter refused (``est.refused``), and those where its
        estimate has no interior maximum (``est.no_maximum``), are counted apart.
        """
        self.refused += int(est.refused)
        if est.no_maximum is not None:
            self.no_maximum = (self.no_maximum or 0) + int(est.no_maximum)
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
        if self.no_maximum is not None:  # a filter that can have no maximum (batch ML)
            out["no_maximum"] = refused_scores(self.no_maximum, n)
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

    Chan, Golub and LeVeque's pairwise update, ``squares + s_b + (b - total /
    n)**2 n m / (n + m)`` for a chunk of ``m`` values of mean ``b`` and squared
    deviations ``s_b``: no two large numbers are subtracted.

    Parameters
    ----------
    n : int
        Earlier values, >= 0.
    total, squares : float or ndarray, shape (...)
        Their sum (ignored when ``n`` is 0) and sum of squared deviations.
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
    """Each trial's depth and velocity errors and stated SDs, (n, 2), about ``truth`` (3,)."""
    full = est.mean - (truth if est.truth is None else est.truth)
    return full[:, 1:], np.sqrt(est.cov[:, (1, 2), (1, 2)])


def interval_holds(cdf, level) -> np.ndarray:
    """Whether each central ``level`` interval holds the truth: ``|cdf - 1/2| <= level / 2``.

    Parameters
    ----------
    cdf : array_like, shape (...)
        The estimate's CDF at the truth (its PIT value).
    level : float

    Returns
    -------
    ndarray of bool, shape (...)
    """
    return np.abs(np.asarray(cdf, dtype=float) - 0.5) <= level / 2


def mean_se(squares, n: int) -> float:
    """Standard error ``sqrt(s**2 / n)`` of a mean over ``n`` independent trials (0 for one).

    Parameters
    ----------
    squares : float
        Sum of squared deviations from the mean (:func:`pooled_squares`), >= 0.
    n : int

    Returns
    -------
    float
    """
    if n < 2:
        return 0.0
    return float(np.sqrt(float(squares) / (n - 1) / n))


def lost_tracks(mean, truth, threshold: float = TRACK_LOSS) -> np.ndarray:
    """Whether each track is lost: ``|(x_est - x, y_est - y)| > threshold |(x, y)|``, or NaN.

    Parameters
    ----------
    mean, truth : array_like, shape (..., 3)
        Estimated and true states ``(x, y, v)``.
    threshold : float

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
    lost, trials : int
        Tracks lost, ``0 <= lost <= n``, of ``n >= 1``.
    confidence : float
        Of the one-sided upper bound.

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
    """``{"fraction", "se", "upper"}`` of ``count`` of ``trials``, as in :func:`track_loss`."""
    t = track_loss(count, trials, confidence)
    return {"fraction": t["fraction"], "se": t["se"], "upper": t["upper"]}


def anees_region(trials: int, dim: int = 3, level: float = INTERVAL_LEVEL) -> tuple:
    """The two-sided acceptance region of the ANEES of ``trials`` trials of a consistent filter.

    ``M`` times the ANEES of ``M`` trials is chi-square with ``M dim`` degrees
    of freedom (Bar-Shalom, Li and Kirubarajan 2001, section 5.4).

    Parameters
    ----------
    trials, dim : int
        ``M >= 1`` and the state's dimension.
    level : float

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
    level, trials : float or array_like
        Nominal levels ``p`` in (0, 1) and trials ``n >= 1``, broadcast.

    Returns
    -------
    ndarray
    """
    level = np.asarray(level, dtype=float)
    return np.sqrt(level * (1 - level) / trials)


def trials_for_se(se: float, level: float = 0.68, step: int = 100) -> int:
    """The fewest trials, a multiple of ``step``, whose coverage SE at ``level`` is at most ``se``.

    The inverse of :func:`coverage_se`; 2,200 trials bring a 68 % coverage's
    SE to 0.01 (0.00995).

    Parameters
    ----------
    se : float
        The largest standard error, > 0.
    level : float
    step : int

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

    The binomial ``sqrt(p (1 - p) / n)`` at the Agresti-Coull centre ``p = (k +
    2) / (n + 4)``, over ``n + 4`` trials: the plug-in's to ``O(1 / n)``, but
    positive when no trial or every trial is covered (``k = 0`` of 150: 0.009).

    Parameters
    ----------
    covered, trials : int or array_like
        Covered trials ``k`` of ``n >= 1``, broadcast.

    Returns
    -------
    ndarray
    """
    k = np.asarray(covered, dtype=float)
    n = np.asarray(trials, dtype=float)
    centre = (k + 2.0) / (n + 4.0)
    return np.sqrt(centre * (1.0 - centre) / (n + 4.0))


#: The size at which :func:`detectable_difference` states a coverage test's reach.
TEST_FALSE_ALARM = 0.01

#: The power at which :func:`detectable_difference` states a coverage test's reach.
TEST_POWER = 0.8


def detectable_difference(
    level, trials, false_alarm: float = TEST_FALSE_ALARM, power: float = TEST_POWER
):
    """The smallest coverage error that a two-sided binomial test finds with a given power.

    :func:`detectable_shift` of :func:`coverage_se`: ``d = (z_a + z_b) sqrt(p
    (1 - p) / n)``, a true coverage ``p ± d`` failing the test with probability
    ``power``.

    Parameters
    ----------
    level, trials : float or array_like
        As :func:`coverage_se` takes them.
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

    Every score ``s`` has its Monte Carlo SE beside it as ``s_se``
    (:func:`mean_se`, :func:`proportion_se`, the delta method's ``se(MSE) /
    (2 RMSE)`` for the RMSE). ``calibration`` holds the coverage at every level
    of :data:`CALIBRATION_LEVELS`; ``hellinger_depth`` is ``{"mean", "se"}``,
    or ``None`` without the optimal filter.
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
    difference, se : array_like, shape (...)
        An estimate less its null value, and its standard error (>= 0).
    z : float
        Critical value, > 0 (default the 1 % point, :data:`TEST_Z`).

    Returns
    -------
    ndarray of int, shape (...)
        ``1`` where ``difference > z se``, ``-1`` where ``difference < -z se``, else ``0``.
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
    false_alarm, power : float
        The test's size and power.

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

    ``"calibrated"`` within ``z`` standard errors (:func:`coverage_se`) of the
    level, ``"overconfident"`` below (intervals too narrow), ``"underconfident"`` above.

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
