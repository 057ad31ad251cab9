"""A track run frame by frame: every frame's state, held whole or streamed, and its noise learned.

Recommended import: ``from depthcore.registry import track_runs``.

:func:`per_frame` runs a whole track (at most
:data:`depthcore.problem.checks.MAX_FRAMES` frames) through filters with a
smoother and gives every frame's filtered and smoothed state, ready for JSON;
:func:`streamed` runs a track of any length, one frame at a time, through the
online filters (:mod:`depthcore.registry.online`) and gives each frame's
filtered state as it comes, in constant time and memory per frame. Their rows
name each frame by its number in the file (and its time, where the file has
one), and so does :func:`relabel` in a message that counts frames from 1.
:func:`learn` estimates a track's noise levels by maximum likelihood and
:func:`learned_json` gives the fit as JSON values.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator

import numpy as np

from depthcore.registry import filters, online, tracking

#: The quantities of a per-frame row, by the attribute of a series of states.
QUANTITIES = (
    ("depth", "depth"),
    ("x", "lateral"),
    ("velocity", "velocity"),
)


def _named(names, among: tuple, kind: str) -> tuple:
    """``names`` checked: a sequence of filter names, each one of ``among``."""
    if isinstance(names, str) or not len(names):
        raise ValueError(f"names must be a sequence of filter names, got {names!r}")
    for name in names:
        if name not in among:
            raise ValueError(f"names: {name!r} is not {kind}; these are {', '.join(among)}")
    return tuple(names)


def _row(frame: int, time: float, mu: float, rho: float, step) -> dict:
    """The first keys of a frame's row: its number, time, bearing, noise and step."""
    present = not math.isnan(mu)
    row = {"frame": int(frame)} | ({} if math.isnan(time) else {"time": float(time)})
    return row | {"bearing": present, "mu": mu, "rho": rho if present else None, "step": step}


def per_frame(
    mu, rho, prior, process_noise: float, names, steps=None, gate=None, frames=None, times=None
) -> dict:
    """Every frame's filtered and smoothed state by the named filters, ready for JSON.

    Parameters
    ----------
    mu : ndarray, shape (N,)
        Bearings, ``NaN`` at a missing frame.
    rho : float or ndarray, shape (N,)
        The noise SD, one or per frame.
    prior : depthcore.problem.gaussian.Gaussian
        The state's density at the first frame.
    process_noise : float
    names : sequence of str
        Filters with a smoother (:data:`depthcore.registry.filters.SMOOTHED`).
    steps : ndarray, shape (N - 1,), or None
        The depth's signed change between consecutive frames (``None``: unit
        steps receding).
    gate : float or None
        Skip a bearing whose predictive tail probability is below ``gate``.
    frames : ndarray of int, shape (N,), or None
        The frames' numbers (default ``1 .. N``).
    times : ndarray, shape (N,), or None
        The frames' times in seconds, where the track has them.

    Returns
    -------
    dict
        ``{"frames", "prior_mean", "prior_cov", "process_noise", "gate",
        "smoothed", "filters": {name: rows}}``; a row per frame: ``frame``,
        ``time`` (with ``times``), ``bearing`` (whether the frame has one),
        ``mu``, ``rho``, ``step`` (``None`` at the first frame), the filter's
        ``tail`` and ``gated`` where it reports them, then
        ``filtered_depth_mean``, ``filtered_depth_sd``, ``filtered_x_mean``, ...,
        ``smoothed_velocity_sd`` (depth ``y``, lateral position ``x``, velocity ``v``).
    """
    try:
        mu = np.asarray(mu, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("mu must be an array of numbers, shape (N,)") from None
    if mu.ndim != 1:
        raise ValueError(f"mu must be one track, shape (N,), got shape {mu.shape}")
    n = mu.shape[0]
    names = _named(names, filters.names(smoothed=True), "a filter with a smoother")
    for key, value in (("frames", frames), ("times", times)):
        if value is not None and np.shape(value) != (n,):
            raise ValueError(
                f"{key} must have shape ({n},), one per bearing, got {np.shape(value)}"
            )
    if np.ndim(rho):
        rho = np.asarray(rho, dtype=float)
    present = np.isfinite(mu)
    if np.ndim(rho) and np.any(present) and np.all(rho[present] == rho[present][0]):
        rho = float(rho[present][0])  # one noise level: the paper's frames
    frames = np.arange(1, n + 1) if frames is None else np.asarray(frames)
    times = np.full(n, np.nan) if times is None else np.asarray(times, dtype=float)
    rho_k = np.broadcast_to(np.asarray(rho, dtype=float), (n,))
    step_k = [None] + ([1.0] * (n - 1) if steps is None else [float(s) for s in np.asarray(steps)])
    options = {}
    if steps is not None:
        options["steps"] = np.asarray(steps, dtype=float)
    if gate is not None:
        options["gate"] = gate
    out = {
        "frames": int(n),
        "prior_mean": prior.mean.tolist(),
        "prior_cov": prior.cov.tolist(),
        "process_noise": float(process_noise),
        "gate": gate,
        "smoothed": True,
        "filters": {},
    }
    for name in names:
        t = tracking.track(mu, rho, prior, process_noise, filter=name, **options)
        updates = getattr(t, "updates", None)
        rows = []
        for k in range(n):
            row = _row(frames[k], times[k], float(mu[k]), float(rho_k[k]), step_k[k])
            if updates is not None:
                row["tail"] = float(np.asarray(updates.tail)[k])
                row["gated"] = bool(np.asarray(updates.gated)[k])
            for series, states in (("filtered", t.filtered), ("smoothed", t.smoothed)):
                for key, attribute in QUANTITIES:
                    row[f"{series}_{key}_mean"] = float(getattr(states, f"{attribute}_mean")[k])
                    row[f"{series}_{key}_sd"] = float(getattr(states, f"{attribute}_sd")[k])
            rows.append(row)
        out["filters"][name] = rows
    return out


def streamed(frames, rho, prior, process_noise: float, names, gate=None) -> Iterator[dict]:
    """Every frame's filtered state by the named online filters, frame by frame.

    Time and memory per frame are constant, whatever the number of frames.

    Parameters
    ----------
    frames : iterable of depthcore.registry.track_files.Frame
        The track's frames in order (``rho`` ``NaN`` where a frame has none; the
        first frame's ``step`` is not used).
    rho : float or None
        The noise SD of a frame whose ``rho`` is ``NaN``.
    prior : depthcore.problem.gaussian.Gaussian
        The state's density at the first frame.
    process_noise : float
    names : sequence of str
        Online filters, of :data:`depthcore.registry.online.NAMES`.
    gate : float or None
        Skip a bearing whose predictive tail probability is below ``gate``.

    Yields
    ------
    dict
        ``{name: row}`` for each frame: the row of :func:`per_frame` without the
        smoothed state.

    Raises
    ------
    ValueError
        A refusal of the filters, naming the frame by its number in the track.
    """
    names = _named(names, online.NAMES, "an online filter")
    started = []
    for k, f in enumerate(frames):
        r = f.rho if math.isfinite(f.rho) else (rho or 1.0)  # rho of a missing frame: unused
        step = 1.0 if k == 0 else float(f.step)
        if k == 0:
            mean, cov = prior.mean, prior.cov
            started = [online.start(n, mean, cov, r, process_noise, gate) for n in names]
        rows = {}
        for name, live in zip(names, started, strict=True):
            try:
                est = live.update(f.mu, rho=r, step=step)
            except ValueError as exc:
                message = relabel(str(exc), lambda j, k=k, f=f: f.frame if j == k + 1 else j)
                raise ValueError(
                    f"mu: the {name} filter stops at frame {f.frame}: {message}"
                ) from None
            row = _row(f.frame, f.time, float(f.mu), r, None if k == 0 else step)
            row |= {"tail": est.tail, "gated": est.gated}
            sd = np.sqrt(np.diag(est.cov))
            for key, i in (("depth", 1), ("x", 0), ("velocity", 2)):
                row[f"filtered_{key}_mean"] = float(est.mean[i])
                row[f"filtered_{key}_sd"] = float(sd[i])
            rows[name] = row
        yield rows


#: A mention of frames counted from 1 in a message: "frame 4", "frames 1, 2 and 4".
_MENTION = re.compile(r"\b(frames?) (\d+(?:(?:, | and )\d+)*)\b")


def relabel(message: str, label) -> str:
    """``message`` with every frame it counts from 1 named by ``label(k)``, its name in the track.

    Parameters
    ----------
    message : str
    label : callable
        ``label(k)`` for ``k = 1, 2, ...``: the frame's number in the file (or a
        text naming it), ``k`` itself for a frame it does not know.
    """

    def names(m):
        return m.group(1) + " " + re.sub(r"\d+", lambda d: str(label(int(d.group()))), m.group(2))

    return _MENTION.sub(names, message)


# --- learning the noise ---------------------------------------------------------------


def learn(mu, weights, prior, known_q=None, steps=None):
    """A track's noise levels: rho (and q unless given) by maximum likelihood, textbook 19.1.2.

    Parameters
    ----------
    mu : ndarray, shape (N,)
        Bearings, ``NaN`` at a missing frame.
    weights : float or ndarray, shape (N,)
        A file's ``rho`` column: the frames' relative noise levels (a number: none).
    prior : depthcore.problem.gaussian.Gaussian
        The state's density at the first frame.
    known_q : float or None
        The process noise when given, ``None`` to learn it.
    steps : ndarray, shape (N - 1,), or None
        The depth's change between consecutive frames (``None``: unit steps).

    Returns
    -------
    depthcore.exact.learning.Fit

    Raises
    ------
    ValueError
        Naming ``prior`` when it is not a Gaussian, or the argument
        :func:`depthcore.exact.learning.fit` refuses.
    """
    from depthcore.exact import learning

    if not (hasattr(prior, "mean") and hasattr(prior, "cov")):
        raise ValueError(f"prior must be a Gaussian (mean and cov), got {type(prior).__name__}")
    return learning.fit(
        mu,
        prior.mean,
        prior.cov,
        process_noise=known_q,
        steps=steps,
        weights=np.asarray(weights) if np.ndim(weights) else None,
    )


def learned_json(fit) -> dict:
    """A learned fit as plain JSON values (``None`` for a standard error it has not).

    Parameters
    ----------
    fit : depthcore.exact.learning.Fit
        :func:`learn`'s result.

    Returns
    -------
    dict
        ``rho``, ``rho_se``, ``rho_interval``, ``process_noise``,
        ``process_noise_se``, ``process_noise_interval``, ``estimated``,
        ``at_boundary``, ``level``, ``log_likelihood``, ``converged``.
    """

    def number(v):
        return None if v is None else float(v)

    def interval(v):
        return None if v is None else [float(v[0]), float(v[1])]

    return {
        "rho": float(fit.rho),
        "rho_se": number(fit.rho_se),
        "rho_interval": interval(fit.rho_interval),
        "process_noise": float(fit.process_noise),
        "process_noise_se": number(fit.process_noise_se),
        "process_noise_interval": interval(fit.process_noise_interval),
        "estimated": list(fit.estimated),
        "at_boundary": bool(fit.at_boundary),
        "level": float(fit.level),
        "log_likelihood": float(fit.log_likelihood),
        "converged": bool(fit.converged),
    }
