"""The median absolute error of a study, streamed: a histogram of fixed size and an interval.

Recommended import: ``from depthcore.studies import medians``.

What a few far-off trials cannot drive, beside a study's RMSE: the median
absolute error and a distribution-free interval for it. :func:`median_ranks`
gives the ranks of the order statistics that bound the interval for any
continuous law, :func:`median_interval` the median and its interval of a
sample held whole, and :class:`AbsoluteErrors` the same from a histogram of
fixed memory whose counts add exactly over chunks of trials, as
:class:`depthcore.studies.scores.Tally` streams them. A new robust summary of
a study's errors goes here; the running sums of the other scores are
:mod:`depthcore.studies.scores`'.
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks

#: Level of the median absolute error's distribution-free interval and of the ANEES's region.
INTERVAL_LEVEL = 0.95


#: Relative width of the bins of :class:`AbsoluteErrors`: the median absolute error and its
#: interval's ends are stated to within this fraction.
MEDIAN_RESOLUTION = 1e-3


#: The absolute errors :class:`AbsoluteErrors` resolves: from the first to the second; smaller
#: ones fall in one bin from 0, larger or non-finite ones in one bin to infinity.
ERROR_RANGE = (1e-8, 1e8)


def median_ranks(trials: int, level: float = INTERVAL_LEVEL) -> tuple:
    """The ranks of the order statistics of a distribution-free interval for a median.

    For ``n`` independent draws of any continuous law, the interval from the
    ``j``-th smallest to the ``(n + 1 - j)``-th holds the median with
    probability ``1 - 2 P(B <= j - 1)``, ``B ~ Binomial(n, 1/2)``; ``j`` is the
    largest rank for which that is at least ``level``.

    Parameters
    ----------
    trials : int
        ``n >= 1``.
    level : float
        In (0, 1).

    Returns
    -------
    tuple of int
        ``(j, k)``, ranks from 1 (``k = n + 1 - j``); ``(0, n + 1)`` when no
        ranks reach ``level`` (too few trials): the interval is then unbounded.
    """
    n = checks.count(trials, "trials")
    level = checks.probability(level, "level")
    from scipy.stats import binom

    cdf = binom.cdf(np.arange(n + 1), n, 0.5)
    j = int(np.count_nonzero(cdf <= (1 - level) / 2))
    return j, n + 1 - j


def median_interval(values, level: float = INTERVAL_LEVEL) -> tuple:
    """The sample median of ``values`` (T,) and its distribution-free interval, exactly.

    Returns ``(median, [lo, hi])``: ``numpy.median`` and the order statistics of
    :func:`median_ranks` (``0.0`` and ``None`` for an end it leaves unbounded).
    """
    v = np.sort(checks.finite_array(values, "values"))
    if v.ndim != 1 or not len(v):
        raise ValueError("values must be a non-empty one-dimensional array")
    j, k = median_ranks(len(v), level)
    lo = float(v[j - 1]) if j >= 1 else 0.0
    hi = float(v[k - 1]) if k <= len(v) else None
    return float(np.median(v)), [lo, hi]


class AbsoluteErrors:
    """A histogram of absolute errors of fixed size: their median and its interval, streamed.

    The bins are geometric, of relative width :data:`MEDIAN_RESOLUTION`, over
    :data:`ERROR_RANGE`, with one bin below it (from 0) and one above (to
    infinity, non-finite errors included): the memory is fixed whatever the
    number of trials, the counts are integers, so chunks add exactly, and each
    order statistic is known to lie in its bin.

    Attributes
    ----------
    counts : ndarray of int
        One count per bin, the bins of the range and the two beyond it.
    n : int
    """

    def __init__(self, resolution: float = MEDIAN_RESOLUTION, error_range=ERROR_RANGE):
        self.resolution = checks.positive_scalar(resolution, "resolution")
        lo, hi = (checks.positive_scalar(v, "error_range") for v in error_range)
        if not hi > lo:
            raise ValueError(f"error_range must be increasing, got {error_range!r}")
        self.bins = int(np.ceil(np.log(hi / lo) / np.log1p(self.resolution)))
        self.lo = lo
        self.counts = np.zeros(self.bins + 2, dtype=np.int64)
        self.n = 0

    def edges(self, b) -> tuple:
        """The lower and upper edges of bins ``b`` (0: below the range; ``B + 1``: above it)."""
        b = np.asarray(b)
        lower = np.where(b == 0, 0.0, self.lo * np.exp((b - 1) * np.log1p(self.resolution)))
        upper = np.where(
            b == self.bins + 1, np.inf, self.lo * np.exp(b * np.log1p(self.resolution))
        )
        return lower, upper

    def index(self, values) -> np.ndarray:
        """The bin of each absolute error (NaN and infinity in the last)."""
        v = np.asarray(values, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            b = np.floor(np.log(v / self.lo) / np.log1p(self.resolution)) + 1
        b = np.where(v < self.lo, 0, b)
        return np.where(np.isfinite(b), np.clip(b, 0, self.bins + 1), self.bins + 1).astype(int)

    def add(self, values) -> None:
        """Count a chunk of absolute errors, shape (m,)."""
        self.counts += np.bincount(self.index(values), minlength=len(self.counts))
        self.n += len(values)

    def order_statistic_bin(self, rank: int) -> int:
        """The bin of the ``rank``-th smallest error (from 1)."""
        return int(np.searchsorted(np.cumsum(self.counts), rank))

    def median(self, level: float = INTERVAL_LEVEL) -> tuple:
        """The median absolute error and its distribution-free ``level`` interval.

        Returns
        -------
        tuple
            ``(median, [lo, hi])``: the median is the mean of the geometric
            centres of the bins of the middle order statistic(s) (within
            :data:`MEDIAN_RESOLUTION` of ``numpy.median``, relative); ``lo`` the
            lower edge of the bin of the ``j``-th smallest error and ``hi`` the
            upper edge of that of the ``(n + 1 - j)``-th (:func:`median_ranks`),
            so the interval holds the exact one. An end that is not finite (the
            errors beyond :data:`ERROR_RANGE`, or too few trials) is ``None``,
            as is the median then.
        """
        if self.n == 0:
            raise ValueError("trials: no trial was added to the tally")
        middle = {(self.n + 1) // 2, self.n // 2 + 1}
        centres = []
        for rank in sorted(middle):
            lower, upper = self.edges(self.order_statistic_bin(rank))
            centres.append(float(np.sqrt(lower * upper)) if lower > 0 else float(upper) / 2)
        median = float(np.mean(centres))
        j, k = median_ranks(self.n, level)
        lo = float(self.edges(self.order_statistic_bin(j))[0]) if j >= 1 else 0.0
        hi = float(self.edges(self.order_statistic_bin(k))[1]) if k <= self.n else np.inf
        return (median if np.isfinite(median) else None), [lo, hi if np.isfinite(hi) else None]
