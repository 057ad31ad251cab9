"""The chapter on related work: MonoSLAM's depth hypotheses measured against the exact filter.

Recommended import: ``from depthbook import related``.

MonoSLAM starts a feature's depth as a fixed set of hypotheses along its ray and
collapses them to a Gaussian once the depth's SD over its mean falls below a
ratio (:mod:`depthcore.particles.depth_hypotheses`). The chapter asks two
questions of it on tracks of :data:`FRAMES` frames whose truths are drawn from
the filters' own prior (:data:`PRIOR`, :func:`depthcore.studies.trials.simulate`),
so that the exact filter's intervals are calibrated by construction. How many
hypotheses does the grid need before its depth mean and SD lie within
:data:`TOLERANCE` exact SDs of the exact filter's, track by track, for each
spacing of :data:`SPACINGS` and number of :data:`COUNTS`, without a collapse
(:func:`agreeing_counts`, :func:`agreement_table`)? And what does the collapse
to a Gaussian at each ratio of :data:`RATIOS` do to the 68 % interval's
coverage of the true depth, at MonoSLAM's :data:`MONOSLAM_COUNT` hypotheses
(:func:`collapse_table`)?

:func:`hypotheses_study` answers both over the same tracks and times each
filter in the same run (seconds per track), so that the cost ratios are
measured side by side; the book reads it from a record.
"""

from __future__ import annotations

import time

import numpy as np

from depthbook import formatting
from depthbook.notebook import MarkdownTable
from depthcore import SCENARIOS
from depthcore.particles import depth_hypotheses
from depthcore.registry.filters import FILTERS
from depthcore.studies import scores, trials

#: The numbers of frames of the tracks.
FRAMES = (3, 10, 30)
#: The numbers of hypotheses tried, ten to a thousand.
COUNTS = (10, 30, 100, 300, 1000)
#: The hypotheses' spacings, equal cells in depth (MonoSLAM's) or in inverse depth.
SPACINGS = depth_hypotheses.SPACINGS
#: The collapse ratios tried, never (0) and then up to above MonoSLAM's 0.3.
RATIOS = (0.0, 0.1, 0.2, 0.3, 0.5)
#: MonoSLAM's number of hypotheses and collapse ratio.
MONOSLAM_COUNT = depth_hypotheses.N_HYPOTHESES
MONOSLAM_RATIO = depth_hypotheses.COLLAPSE_RATIO
#: Trials a number of frames.
TRIALS = 2200
#: The prior's form, from which each trial's truth is drawn (a Gaussian range prior).
PRIOR = "range"
#: The agreement asked of the hypotheses, both moments within this many exact SDs.
TOLERANCE = 0.1
#: The share of trials that must agree, at every number of frames, for a count to agree.
AGREE_SHARE = 0.99
#: The nominal level of the coverage scored.
LEVEL = 0.68
#: Trials filtered together (the memory grows with them times the hypotheses).
CHUNK = 275


def _moments(estimate) -> tuple[np.ndarray, np.ndarray]:
    """The depth's mean and SD of a registry estimate, (B,) each."""
    return np.asarray(estimate.depth_mean, dtype=float), np.asarray(estimate.depth_sd, dtype=float)


def _clocked(function, *args, **kwargs):
    start = time.perf_counter()
    out = function(*args, **kwargs)
    return out, time.perf_counter() - start


def _chunk(part: trials.Trials) -> dict:
    """Every filter of the study on one chunk of trials: the per-trial numbers and seconds."""
    mu, rho, pm, pc = part.mu, part.rho, part.prior_mean, part.prior_cov
    truth = part.truths[:, 1]
    exact, seconds = _clocked(FILTERS["optimal"], mu, rho, pm, pc)
    m0, s0 = _moments(exact)
    # where the exact posterior's depth mean at frame 1 lies outside the hypotheses' range
    m_y = pm[:, 1]
    start = m0 - part.mu.shape[-1] + 1
    span = np.sqrt(depth_hypotheses.SPAN)
    out = {
        "outside": (start < m_y / span) | (start > m_y * span),
        "exact": {
            "covered": scores.interval_holds(
                FILTERS["optimal"].scoring.cdfs(exact, part.truths)[0], LEVEL
            ),
            "seconds": seconds,
            "sd": s0,
        },
        "agreement": {},
        "collapse": {},
    }

    def hypotheses(**options):
        return _clocked(depth_hypotheses.run, mu, rho, pm, pc, **options)

    for spacing in SPACINGS:
        for count in COUNTS:
            h, seconds = hypotheses(n_hypotheses=count, spacing=spacing, collapse_ratio=0.0)
            m, s = h.mean[:, 1], np.sqrt(h.cov[:, 1, 1])
            out["agreement"][spacing, count] = {
                "mean_gap": np.abs(m - m0) / s0,
                "sd_gap": np.abs(s - s0) / s0,
                "seconds": seconds,
            }
    for ratio in RATIOS:
        h, seconds = hypotheses(n_hypotheses=MONOSLAM_COUNT, collapse_ratio=ratio)
        out["collapse"][ratio] = {
            "covered": scores.interval_holds(h.depth_cdf(truth), LEVEL),
            "collapsed_at": h.collapsed_at,
            "mean_gap": np.abs(h.mean[:, 1] - m0) / s0,
            "seconds": seconds,
        }
    return out


def _share(flags) -> dict:
    """A share of trials and its binomial standard error."""
    flags = np.asarray(flags, dtype=bool)
    p = float(np.mean(flags))
    return {"share": p, "se": float(scores.coverage_se(p, flags.size))}


def _mean_se(values) -> dict:
    values = np.asarray(values, dtype=float)
    return {
        "mean": float(np.mean(values)),
        "se": float(np.std(values, ddof=1) / np.sqrt(values.size)),
    }


def _gather(chunks: list[dict], path: tuple) -> np.ndarray:
    def pick(chunk):
        for key in path:
            chunk = chunk[key]
        return np.atleast_1d(chunk)

    return np.concatenate([pick(c) for c in chunks])


def _frames_summary(chunks: list[dict], n_trials: int) -> dict:
    """One number of frames' summary: agreement per spacing and count, coverage per ratio."""
    seconds_exact = sum(c["exact"]["seconds"] for c in chunks)
    outside = _gather(chunks, ("outside",))
    out = {
        "trials": n_trials,
        "outside": _share(outside),
        "exact": {
            "coverage": _share(_gather(chunks, ("exact", "covered"))),
            "sd": _mean_se(_gather(chunks, ("exact", "sd"))),
            "seconds": seconds_exact / n_trials,
        },
        "agreement": {},
        "collapse": {},
    }
    for spacing in SPACINGS:
        rows = {}
        for count in COUNTS:
            key = (spacing, count)
            mean_gap = _gather(chunks, ("agreement", key, "mean_gap"))
            sd_gap = _gather(chunks, ("agreement", key, "sd_gap"))
            seconds = sum(c["agreement"][key]["seconds"] for c in chunks)
            within = (mean_gap <= TOLERANCE) & (sd_gap <= TOLERANCE)
            rows[str(count)] = {
                "within": _share(within),
                "within_inside": _share(within[~outside]),
                "mean_gap": _mean_se(mean_gap),
                "largest_mean_gap": float(np.max(mean_gap)),
                "sd_gap": _mean_se(sd_gap),
                "seconds": seconds / n_trials,
                "cost": seconds / seconds_exact,
            }
        out["agreement"][spacing] = rows
    for ratio in RATIOS:
        at = _gather(chunks, ("collapse", ratio, "collapsed_at"))
        seconds = sum(c["collapse"][ratio]["seconds"] for c in chunks)
        out["collapse"][f"{ratio:g}"] = {
            "coverage": _share(_gather(chunks, ("collapse", ratio, "covered"))),
            "collapsed": _share(at > 0),
            "mean_collapse_frame": float(np.mean(at[at > 0])) if np.any(at > 0) else None,
            "mean_gap": _mean_se(_gather(chunks, ("collapse", ratio, "mean_gap"))),
            "seconds": seconds / n_trials,
            "cost": seconds / seconds_exact,
        }
    return out


def hypotheses_study(
    frames=FRAMES, n_trials: int = TRIALS, seed: int = 1, prior: str = PRIOR
) -> dict:
    """The hypotheses against the exact filter over ``n_trials`` tracks at each number of frames.

    Parameters
    ----------
    frames : sequence of int
        Numbers of frames ``N >= 3``.
    n_trials : int
        Tracks drawn at each ``N``, in chunks of :data:`CHUNK`.
    seed : int
        Seeds a ``numpy.random.SeedSequence``, one child per ``N``.
    prior : str
        The prior's form (:func:`depthcore.studies.trials.simulate`), centred on
        Figure 2's state; each trial's truth is drawn from it.

    Returns
    -------
    dict
        ``{"frames": {str(N): summary}, "rejected": int, ...}``; a summary holds
        the exact filter's coverage (share and SE), mean SD and seconds per
        track, and per spacing and count the share of trials within
        :data:`TOLERANCE` (``"within"``), the mean and largest gap of the mean
        in exact SDs, the seconds per track and the cost over the exact
        filter's; per collapse ratio the coverage, the share of trials
        collapsed and the mean frame of the collapse.
    """
    fig2 = SCENARIOS["fig2"]
    children = np.random.SeedSequence(seed).spawn(len(frames))
    out, rejected = {}, 0
    for n, child in zip(frames, children, strict=True):
        rng = np.random.default_rng(child)
        chunks, drawn = [], 0
        for start in range(0, n_trials, CHUNK):
            size = min(CHUNK, n_trials - start)
            part = trials.simulate(fig2.c, fig2.rho, size, rng, prior, frames=int(n))
            rejected += part.n_rejected
            drawn += len(part.mu)
            chunks.append(_chunk(part))
        out[str(n)] = _frames_summary(chunks, drawn)
    return {
        "frames": out,
        "rejected": rejected,
        "prior": prior,
        "rho": fig2.rho,
        "truth": [float(v) for v in fig2.c],
        "counts": list(COUNTS),
        "ratios": list(RATIOS),
        "tolerance": TOLERANCE,
        "level": LEVEL,
    }


def agreeing_counts(result: dict, spacing: str, share: float = AGREE_SHARE) -> dict:
    """Per number of frames, the fewest hypotheses of :data:`COUNTS` that agree, as do all more.

    A count agrees at ``N`` when, among the tracks whose exact posterior mean
    lies inside the hypotheses' range, the share whose two moments lie within
    :data:`TOLERANCE` of the exact SD is at least ``share``.

    Returns
    -------
    dict
        ``{N: count}`` (``N`` as in ``result``), ``None`` where the largest count
        does not agree.
    """
    out = {}
    for n, f in result["frames"].items():
        found = None
        for count in reversed(result["counts"]):
            if f["agreement"][spacing][str(count)]["within_inside"]["share"] < share:
                break
            found = count
        out[n] = found
    return out


def _span_text(values) -> str:
    """``"a to b"`` of the values at one decimal, one value when they agree, ``"never"``."""
    if not values:
        return "never"
    lo, hi = f"{min(values):.1f}", f"{max(values):.1f}"
    return lo if lo == hi else f"{lo} to {hi}"


def _value_se(entry: dict, decimals: int = 3) -> str:
    return formatting.value_se(entry["share"], entry["se"], decimals)


def agreement_table(result: dict) -> MarkdownTable:
    """The agreement of :func:`hypotheses_study`: per spacing and count, each N's shares, cost."""
    frames = result["frames"]
    header = ["spacing", "$J$", *(f"$N = {n}$" for n in frames), "time over exact"]
    rows = []
    for spacing in SPACINGS:
        for count in result["counts"]:
            cells = [f["agreement"][spacing][str(count)] for f in frames.values()]
            costs = [c["cost"] for c in cells]
            rows.append(
                [
                    spacing,
                    f"{count:,}",
                    *(
                        f"{_value_se(c['within'])} ({c['within_inside']['share']:.3f})"
                        for c in cells
                    ),
                    f"{min(costs):.2f} to {max(costs):.2f}",
                ]
            )
    return MarkdownTable(header, rows)


def collapse_table(result: dict) -> MarkdownTable:
    """:func:`hypotheses_study`'s coverage per collapse ratio, and the exact filter's, per ``N``."""
    frames = result["frames"]
    header = ["collapse ratio", *(f"$N = {n}$" for n in frames), "mean frame of collapse"]
    rows = [["exact filter", *(_value_se(f["exact"]["coverage"]) for f in frames.values()), "-"]]
    for ratio in result["ratios"]:
        cells = [f["collapse"][f"{ratio:g}"] for f in frames.values()]
        at = [c["mean_collapse_frame"] for c in cells if c["mean_collapse_frame"] is not None]
        rows.append(
            [
                f"{ratio:g}",
                *(_value_se(c["coverage"]) for c in cells),
                _span_text(at),
            ]
        )
    return MarkdownTable(header, rows)
