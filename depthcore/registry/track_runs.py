"""A track run frame by frame: every frame's state, held whole or streamed, and its noise learned.

Recommended import: ``from depthcore.registry import track_runs``.

:func:`per_frame` runs a whole track (at most
:data:`depthcore.problem.checks.MAX_FRAMES` frames) through filters with a
smoother and gives every frame's filtered and smoothed state, ready for JSON;
:func:`streamed` runs a track of any length, one frame at a time, through the
online filters (:mod:`depthcore.registry.online`) and gives each frame's
filtered state as it comes, in constant time and memory per frame, of the
plane's bearings or of pairs (a point in 3-D; :func:`frames_of` gives a held
track's frames). Their rows name each frame by its number in the file (and its
time, where the file has one), and so does :func:`relabel` in a message that
counts frames from 1. :func:`summarize_pairs` gives the moments of a point in
3-D at the last frame by the filters that take pairs. :func:`start_prior` is a
track's prior when none is given (the paper's rule, or a range prior on the
depth), :func:`noise_free` the state ``c`` of Eq. (7) or why there is none.
:func:`learn` estimates a track's noise levels by maximum likelihood and
:func:`learned_json` gives the fit as JSON values.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from depthcore.problem import bearing_pairs, depth_prior, model
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, Gaussian
from depthcore.registry import filters, online, track_files, tracking

#: The quantities of a per-frame row, by the attribute of a series of states.
QUANTITIES = (
    ("depth", "depth"),
    ("x", "lateral"),
    ("velocity", "velocity"),
)

#: The coordinates of a point in 3-D as the outputs name them, by their index in
#: ``(x, y, v, h, w)``; the plane's are the first three.
SPACE = (("depth", 1), ("x", 0), ("velocity", 2), ("height", 3), ("vertical_velocity", 4))


def _named(names, among: tuple, kind: str) -> tuple:
    """``names`` checked: a sequence of filter names, each one of ``among``."""
    if isinstance(names, str) or not len(names):
        raise ValueError(f"names must be a sequence of filter names, got {names!r}")
    for name in names:
        if name not in among:
            raise ValueError(f"names: {name!r} is not {kind}; these are {', '.join(among)}")
    return tuple(names)


def _row(frame: int, time: float, mu: float, rho: float, step, nu=None) -> dict:
    """The first keys of a frame's row: its number, time, bearing (``nu``: a pair's), noise
    and step."""
    present = not math.isnan(mu)
    row = {"frame": int(frame)} | ({} if math.isnan(time) else {"time": float(time)})
    row |= {"bearing": present, "mu": mu} | ({} if nu is None else {"nu": nu})
    return row | {"rho": rho if present else None, "step": step}


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
        **depth_prior.describe(prior),
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
    prior : depthcore.problem.gaussian.Gaussian or Prior
        The state's density at the first frame: of ``(x, y, v, h, w)`` (:class:`Prior`)
        for a point in 3-D, each frame then the pair ``(mu, nu)``.
    process_noise : float
    names : sequence of str
        Online filters, of :data:`depthcore.registry.online.NAMES`.
    gate : float or None
        Skip a bearing whose predictive tail probability is below ``gate``.

    Yields
    ------
    dict
        ``{name: row}`` for each frame: the row of :func:`per_frame` without the
        smoothed state; of a point in 3-D, with ``nu`` and the filtered height and
        vertical velocity (:data:`SPACE`).

    Raises
    ------
    ValueError
        A refusal of the filters, naming the frame by its number in the track.
    """
    names = _named(names, online.NAMES, "an online filter")
    space = SPACE if np.shape(prior.mean) == (5,) else SPACE[:3]
    started = []
    for k, f in enumerate(frames):
        r = f.rho if math.isfinite(f.rho) else (rho or 1.0)  # rho of a missing frame: unused
        step = 1.0 if k == 0 else float(f.step)
        if k == 0:
            mean, cov = prior.mean, prior.cov
            started = [
                online.start(n, mean, cov, r, process_noise, gate, **depth_prior.options(n, prior))
                for n in names
            ]
        rows = {}
        for name, live in zip(names, started, strict=True):
            try:
                est = live.update(f.mu if len(space) == 3 else [f.mu, f.nu], rho=r, step=step)
            except ValueError as exc:
                message = relabel(str(exc), lambda j, k=k, f=f: f.frame if j == k + 1 else j)
                raise ValueError(
                    f"mu: the {name} filter stops at frame {f.frame}: {message}"
                ) from None
            nu = None if len(space) == 3 else float(f.nu)
            row = _row(f.frame, f.time, float(f.mu), r, None if k == 0 else step, nu)
            row |= {"tail": est.tail, "gated": est.gated}
            sd = np.sqrt(np.diag(est.cov))
            for key, i in space:
                row[f"filtered_{key}_mean"] = float(est.mean[i])
                row[f"filtered_{key}_sd"] = float(sd[i])
            rows[name] = row
        yield rows


def frames_of(track: track_files.TrackFile) -> Iterator[track_files.Frame]:
    """The frames of a track held whole, as :func:`streamed` takes them (``line`` 0)."""
    mu = track.mu.reshape(len(track.frames), -1)
    rho = np.full(len(mu), np.nan) if track.rho is None else track.rho
    time = np.full(len(mu), np.nan) if track.times is None else track.times
    step = [math.nan, *(np.ones(len(mu) - 1) if track.steps is None else track.steps)]
    for k, number in enumerate(track.frames):
        nu = mu[k, 1] if mu.shape[1] == 2 else math.nan
        yield track_files.Frame(int(number), time[k], mu[k, 0], rho[k], float(step[k]), 0, nu)


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


# --- a track's prior and a point in 3-D at its last frame -------------------------------


class Prior(NamedTuple):
    """The prior of a point in 3-D: the density of ``(x, y, v, h, w)`` at the first frame.

    Attributes
    ----------
    mean : ndarray, shape (5,)
    cov : ndarray, shape (5, 5)
    """

    mean: np.ndarray
    cov: np.ndarray


def start_prior(mu, steps=None, depth=None):
    """A track's prior at frame 1 when none is given: the paper's rule, or a range prior.

    With ``depth`` ``None``, the paper's rule on the first three present (horizontal)
    bearings, :func:`depthcore.registry.tracking.default_prior`:
    ``N((x_1, y_1, 0), 1000 I)``. With ``depth = (mean, sd)``, a range prior for
    tracks whose first three bearings say little: ``y_1 ~ N(mean, sd**2)``, and the
    lateral terms as the rule makes them, ``x_1 = mu_a (mean + t_a)`` (the point on
    the line of sight of the first bearing present, ``mu_a`` at the depth travelled
    ``t_a``) and ``v = 0``, each of variance 1000, uncorrelated. For pairs the
    height follows the same rule, ``h_1 = nu_a (y_1 + t_a)`` and ``w = 0`` with
    variance 1000: ``N((x_1, y_1, 0, h_1, 0), 1000 I)`` (``y_1``'s variance
    ``sd**2`` with ``depth``).

    Parameters
    ----------
    mu : ndarray, shape (N,) or (N, 2)
        Checked bearings or pairs, ``NaN`` at a missing frame.
    steps : array_like, shape (N - 1,), or None
        The depth's signed change between frames (``None``: unit steps receding).
    depth : (float, float) or None
        The range prior's mean (> 0) and SD (> 0) of the depth at frame 1.

    Returns
    -------
    depthcore.problem.gaussian.Gaussian or Prior
        For bearings, or for pairs; refused, naming ``prior``, where the rule has
        no noise-free solution in front of the camera (:func:`noise_free` says why).
    """
    mu = np.asarray(mu, dtype=float)
    s = np.ones(len(mu) - 1) if steps is None else np.asarray(steps, dtype=float)
    a = int(np.flatnonzero(~np.isnan(mu.reshape(len(mu), -1)[:, 0]))[0])
    t_a = float(np.sum(s[:a]))
    first = mu.reshape(len(mu), -1)[a]
    if depth is None:
        plane = tracking.default_prior(mu if mu.ndim == 1 else mu[:, 0], steps)
        mean, var = plane.mean, np.full(3, PAPER_PRIOR_SCALE)
    else:
        y, sd = (float(v) for v in depth)
        if not (y > 0 and sd > 0 and math.isfinite(y + sd)):
            raise ValueError(f"depth must be a mean and an SD, both > 0, got {y!r} {sd!r}")
        mean = np.array([first[0] * (y + t_a), y, 0.0])
        var = np.array([PAPER_PRIOR_SCALE, sd**2, PAPER_PRIOR_SCALE])
    if mu.ndim == 1:
        return Gaussian(mean, np.diag(var))
    height = [first[1] * (mean[1] + t_a), 0.0]
    return Prior(np.concatenate([mean, height]), np.diag([*var, *[PAPER_PRIOR_SCALE] * 2]))


def noise_free(mu, steps=None) -> tuple:
    """``(c, None)``, the noise-free state of Eq. (7) at frame 3 of bearings ``mu`` (N,) or of
    pairs' (N, 2), where the first three frames have them a unit step apart, receding, not
    degenerate and in front of the camera; else ``(None, why)``. ``steps`` (N - 1,) or None."""
    mu = np.asarray(mu, dtype=float)
    mu = mu if mu.ndim == 1 else mu[:, 0]
    s = np.ones(len(mu) - 1) if steps is None else np.asarray(steps, dtype=float)
    if np.any(np.isnan(mu[:3])) or np.any(s[:2] != 1.0):
        return None, "Eq. (7) needs bearings at frames 1, 2 and 3, a unit step apart, receding"
    c = model.noise_free_states_unchecked(mu[:3])
    if not np.all(np.isfinite(c)):
        return None, "the first three bearings are degenerate (mu1 + mu3 - 2 mu2 = 0)"
    if not c[1] > 2:
        return None, (
            "the first three bearings put the point behind the camera (its noise-free depth "
            f"at the first frame is {c[1] - 2:.6g})"
        )
    return c, None


def spatial_names() -> tuple:
    """The registered filters that take pairs, a point in 3-D (``Filter.spatial``)."""
    return tuple(n for n, f in filters.FILTERS.items() if f.spatial is not None)


def summarize_pairs(mu, rho, prior, process_noise: float, names, steps=None) -> dict:
    """The five coordinates of a point in 3-D at the last frame by the filters that take pairs.

    Parameters
    ----------
    mu : ndarray, shape (N, 2)
        Pairs ``(x / y, h / y)``, a row of ``NaN`` at a missing frame.
    rho : float or ndarray, shape (N,)
    prior : Prior
        Of ``(x, y, v, h, w)`` at the first frame.
    process_noise : float
    names : sequence of str
        Filters of :data:`depthcore.registry.filters.FILTERS` with a door for pairs.
    steps : ndarray, shape (N - 1,), or None

    Returns
    -------
    dict
        As :func:`depthcore.studies.reproduce.summarize`'s (``mu`` a list of pairs),
        each filter's ``mean`` and ``sd`` of each coordinate of :data:`SPACE` (and the
        exact filter's ``error`` of the depth and velocity); a filter that cannot
        run is under ``"not_run"`` with its reason.
    """
    bearing_pairs.check(mu, rho, steps)  # the track's refusals before any filter's
    q = float(process_noise)
    out = {"filters": {}, "not_run": {}}
    for name in _named(names, spatial_names(), "a filter of a point in 3-D"):
        try:
            est = filters.FILTERS[name](mu, rho, prior.mean, prior.cov, q, steps=steps)
        except ValueError as exc:
            out["not_run"][name] = str(exc)
            continue
        sd = np.sqrt(np.diag(est.cov))
        moments = {k: {"mean": float(est.mean[i]), "sd": float(sd[i])} for k, i in SPACE}
        for key in ("depth", "velocity"):
            moments[key] = {k: float(v) for k, v in est.moments(key).items()}
        out["filters"][name] = moments
    return {
        "coordinates": ["x", "y", "v", "h", "w"],  # the prior's order
        "mu": [None if np.isnan(m) else [float(m), float(n)] for m, n in mu],
        "rho": float(rho) if np.ndim(rho) == 0 else [float(r) for r in rho],
        "prior_mean": prior.mean.tolist(),
        "prior_cov": prior.cov.tolist(),
        "frames": len(mu),
        "process_noise": q,
        **({} if steps is None else {"steps": [float(v) for v in steps]}),
        **{k: v for k, v in out.items() if v or k == "filters"},
    }


# --- learning the noise ---------------------------------------------------------------

#: The intervals of the learned noise levels, the profile likelihood's
#: (:func:`depthcore.exact.learning.fit`).
INTERVALS = "profile"


def learn(mu, weights, prior, known_q=None, steps=None, gate=None):
    """A track's noise levels: rho (and q unless given) by maximum likelihood, textbook 19.1.2.

    The intervals are :data:`INTERVALS`'s, the profile likelihood's, which reach ``q = 0``.

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
    gate : float or None
        Leave out the bearings whose tail probability at the estimate is below it
        (``Fit.gated``), so that outliers do not inflate ``rho``.

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
        **depth_prior.options("optimal", prior),
        process_noise=known_q,
        steps=steps,
        weights=np.asarray(weights) if np.ndim(weights) else None,
        gate=gate,
        intervals=INTERVALS,
    )


def learned_json(fit, column: bool = False, frames=None, times=None) -> dict:
    """A learned fit as plain JSON values (``None`` for a standard error it has not).

    Parameters
    ----------
    fit : depthcore.exact.learning.Fit
        :func:`learn`'s result.
    column : bool
        Whether ``rho`` is a factor of a ``rho`` column, the frames' relative noise
        levels: then named ``rho_column_scale``.
    frames, times : ndarray, shape (N,), or None
        The frames' numbers (default ``1 .. N``) and times, naming those the gate skipped.

    Returns
    -------
    dict
        ``rho`` (or ``rho_column_scale``), ``rho_se``, ``rho_interval``,
        ``process_noise``, ``process_noise_se``, ``process_noise_interval``,
        ``estimated``, ``at_boundary``, ``level``, ``intervals`` (``"profile"``: the
        profile likelihood's), ``log_likelihood``, ``converged``; with a gate,
        ``gate_skipped`` (the frames' numbers) and ``gate_skipped_times`` (with ``times``).
    """

    def number(v):
        return None if v is None else float(v)

    def interval(v):
        return None if v is None else [float(v[0]), float(v[1])]

    rho = "rho_column_scale" if column else "rho"
    out = {
        rho: float(fit.rho),
        f"{rho}_se": number(fit.rho_se),
        f"{rho}_interval": interval(fit.rho_interval),
        "process_noise": float(fit.process_noise),
        "process_noise_se": number(fit.process_noise_se),
        "process_noise_interval": interval(fit.process_noise_interval),
        "estimated": [rho if n == "rho" else n for n in fit.estimated],
        "at_boundary": bool(fit.at_boundary),
        "level": float(fit.level),
        "intervals": INTERVALS,
        "log_likelihood": float(fit.log_likelihood),
        "converged": bool(fit.converged),
    }
    if fit.gated is not None:
        k = np.flatnonzero(np.asarray(fit.gated).reshape(-1))
        frames = np.arange(1, np.size(fit.gated) + 1) if frames is None else np.asarray(frames)
        out["gate_skipped"] = frames[k].tolist()
        if times is not None:
            out["gate_skipped_times"] = np.asarray(times)[k].tolist()
    return out
