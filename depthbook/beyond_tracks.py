"""The chapter on real tracks: one track with gaps, uneven steps, noise per frame and an outlier.

Recommended import: ``from depthbook import beyond_tracks``.

* :func:`demo_track` draws the chapter's track from one seed: Figure 2's point
  seen by a camera moving at varying speed, some frames without a detection,
  a noise level per frame, and one mismatched bearing;
* :func:`filtered` runs a filter of the registry over every prefix of it, with
  or without a gate, and :func:`track_figure` draws the filtered depths and
  each bearing's tail probability;
* :func:`approach` runs the exact filter on tracks of a camera that approaches
  the point, reading the steps the right way and the wrong way.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthbook.style import MIN_FONT, STYLE, WIDTH, legend_below, subplots
from depthcore.exact import posterior
from depthcore.problem import checks, model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry import online


class DemoTrack(NamedTuple):
    """The chapter's track (:func:`demo_track`).

    Attributes
    ----------
    mu : ndarray, shape (N,)
        Bearings, ``NaN`` at the missing frames, the outlier included.
    clean : ndarray, shape (N,)
        The same bearings with the outlier's true value.
    rho : ndarray, shape (N,)
        Noise SD per frame.
    steps : ndarray, shape (N - 1,)
    states : ndarray, shape (N, 3)
        The true states ``(x, y, v)``.
    missing : ndarray of int
        The missing frames (numbered from 1).
    outlier : int
        The frame of the mismatched bearing (numbered from 1).
    offset : float
        The outlier's offset, in units of its frame's ``rho``.
    """

    mu: np.ndarray
    clean: np.ndarray
    rho: np.ndarray
    steps: np.ndarray
    states: np.ndarray
    missing: np.ndarray
    outlier: int
    offset: float


def demo_track(
    seed,
    frames: int = 40,
    n_missing: int = 6,
    outlier: int = 30,
    offset: float = 15.0,
    step_range=(0.5, 1.5),
    rho_range=(0.5, 2.0),
) -> DemoTrack:
    """Figure 2's point on a real track, drawn from one seed.

    The point passes through Figure 2's noise-free state at time 3 with
    constant velocity. Between frames the point recedes from the camera by a step drawn
    uniformly from ``step_range``; each frame's noise SD is Figure 2's
    ``rho = 1/200`` times a factor drawn log-uniformly from ``rho_range``;
    ``n_missing`` frames after the third are drawn without a detection; and
    the bearing of frame ``outlier`` is moved by ``offset`` of its SDs (a
    mismatched feature).

    Parameters
    ----------
    seed : int or numpy.random.SeedSequence
    frames : int
    n_missing : int
    outlier : int
        From 4 to ``frames``; never a missing frame.
    offset : float
    step_range, rho_range : tuple of float
        ``(low, high)``, ``0 < low <= high``.

    Returns
    -------
    DemoTrack
    """
    rng = checks.generator(seed, "seed")
    frames = checks.frames(frames)
    fig2 = SCENARIOS["fig2"]
    steps = rng.uniform(*step_range, size=frames - 1)
    factor = np.exp(rng.uniform(*np.log(rho_range), size=frames))
    rho = fig2.rho * factor
    candidates = np.setdiff1d(np.arange(4, frames + 1), [outlier])
    missing = np.sort(rng.choice(candidates, size=n_missing, replace=False))
    sim = model.simulate(fig2.c, frames, rho, 0.0, rng, steps=steps)
    clean = sim.mu.copy()
    clean[missing - 1] = np.nan
    mu = clean.copy()
    mu[outlier - 1] += offset * rho[outlier - 1]
    return DemoTrack(mu, clean, rho, steps, sim.states, missing, outlier, offset)


def filtered(name: str, track: DemoTrack, prior_mean, prior_cov, gate=None, mu=None) -> list:
    """A filter run one frame at a time over the track (the online door), every frame's state.

    Parameters
    ----------
    name : str
        A filter of :func:`depthcore.registry.online.start`.
    track : DemoTrack
    prior_mean : array_like, shape (3,)
    prior_cov : array_like, shape (3, 3)
    gate : float or None
    mu : array_like, shape (N,), optional
        Bearings in place of the track's (its clean ones, say).

    Returns
    -------
    list of depthcore.problem.predictive.FrameEstimate
        One per frame.
    """
    mu = track.mu if mu is None else mu
    f = online.start(name, prior_mean, prior_cov, rho=track.rho[0], gate=gate)
    steps = np.concatenate([[1.0], track.steps])
    return [f.update(m, rho=r, step=s) for m, r, s in zip(mu, track.rho, steps, strict=True)]


def track_figure(track: DemoTrack, runs: dict, gate: float):
    """Filtered depth errors along the track and each bearing's predictive tail probability.

    Parameters
    ----------
    track : DemoTrack
    runs : dict
        ``{(name, gated): list of FrameEstimate}`` from :func:`filtered`, for
        each filter with ``gated`` false and true.
    gate : float
        The gate of the gated runs, drawn as a line.

    Returns
    -------
    matplotlib.figure.Figure
        Above, each run's filtered depth minus the truth (a symmetric log scale,
        linear within 0.1), the ungated runs with a band of one SD; below, the
        tail probability of each bearing before the ungated runs saw it, and
        circled, the bearings a gated run skipped, at their tail probability
        under that run's prediction.
    """
    fig, (top, bottom) = subplots(2, 1, figsize=(WIDTH, 5.6), sharex=True)
    k = np.arange(1, len(track.mu) + 1)
    truth = track.states[:, 1]
    for (name, gated), states in runs.items():
        style = {**STYLE[name]}
        label = style.pop("label") + (", gated" if gated else "")
        style["linestyle"] = "--" if gated else "-"
        error = np.array([s.depth_mean for s in states]) - truth
        top.plot(k, error, label=label, **style)
        if gated:
            skipped = np.array([s.gated for s in states])
            tail = np.array([s.tail for s in states])
            bottom.plot(
                k[skipped],
                np.maximum(tail[skipped], 1e-300),
                linestyle="none",
                marker="o",
                markersize=8,
                markerfacecolor="none",
                color=style.get("color"),
                label=f"skipped, {label}",
            )
        else:
            sd = np.array([s.depth_sd for s in states])
            top.fill_between(k, error - sd, error + sd, alpha=0.15, color=style.get("color"))
            tail = np.array([s.tail for s in states])
            bottom.plot(k, np.maximum(tail, 1e-300), marker=".", label=label, **style)
    top.set_yscale("symlog", linthresh=0.1)
    top.axhline(0.0, color="black", linewidth=0.8)
    bottom.set_yscale("log")
    bottom.axhline(gate, color="0.3", linewidth=1, linestyle=":", label=f"gate {gate:g}")
    for ax in (top, bottom):
        ax.axvline(track.outlier, color="0.6", linewidth=5, alpha=0.35, zorder=0)
        for m in track.missing:
            ax.axvline(m, color="0.8", linewidth=0.8, linestyle="-.", zorder=0)
        ax.tick_params(labelsize=MIN_FONT)
    top.set_ylabel("filtered depth − truth", fontsize=MIN_FONT)
    bottom.set_ylabel("tail probability", fontsize=MIN_FONT)
    bottom.set_xlabel("frame $k$", fontsize=MIN_FONT)
    legend_below(fig, [top, bottom], ncol=3)
    return fig


class Approach(NamedTuple):
    """Tracks of a camera that approaches the point, and the exact filter read both ways.

    Attributes
    ----------
    steps : ndarray, shape (N - 1,)
        The depth's signed change between frames (negative: approaching).
    truth : ndarray, shape (B, 3)
        The state at the last frame of each track.
    right : depthcore.exact.mixture.Moments
        The exact filter's moments at the last frame with the steps as they are.
    wrong : depthcore.exact.mixture.Moments
        The same with the steps' signs flipped: the camera read as receding.
    """

    steps: np.ndarray
    truth: np.ndarray
    right: object
    wrong: object

    def z(self, which: str) -> np.ndarray:
        """The depth's error at the last frame in the filter's SDs, (B,), for ``"right"``
        or ``"wrong"``."""
        m = getattr(self, which)
        return (m.mean[:, 1] - self.truth[:, 1]) / np.sqrt(m.cov[:, 1, 1])


def approach(
    seed: int, draws: int, frames: int, step: float, rho: float, prior_mean, prior_cov
) -> Approach:
    """``draws`` tracks of ``frames`` frames, each step ``step`` (< 0), the truth from the prior.

    The states at frame 1 are drawn from ``N(prior_mean, prior_cov)`` restricted to
    depths that keep the point in front of the camera at every frame (the exact
    filter's own support), the bearings by :func:`depthcore.problem.model.simulate`
    with noise SD ``rho``; both readings run through
    :func:`depthcore.exact.posterior.moments`.
    """
    rng = np.random.default_rng(seed)
    steps = np.full(frames - 1, float(step))
    floor = -float(np.min(np.concatenate([[0.0], np.cumsum(steps)])))
    mean, cov = np.asarray(prior_mean, dtype=float), np.asarray(prior_cov, dtype=float)
    states = np.empty((0, 3))
    while len(states) < draws:
        drawn = rng.multivariate_normal(mean, cov, size=2 * draws)
        states = np.concatenate([states, drawn[drawn[:, 1] > floor]])
    states = states[:draws]
    sims = [model.simulate(x, frames, rho, 0.0, rng, frame=1, steps=steps) for x in states]
    mu = np.array([s.mu for s in sims])
    right = posterior.moments(mu, rho, mean, cov, steps=steps)
    wrong = posterior.moments(mu, rho, mean, cov, steps=-steps)
    return Approach(steps, np.array([s.states[-1] for s in sims]), right, wrong)


#: The filters with a door for a point in 3-D that the chapter runs.
SPACE_FILTERS = ("optimal", "ekf", "ukf", "iterated", "inverse_depth")


def space_tracks(seed: int, draws: int, frames: int, step: float, pixel_sd, focal, prior):
    """Points in 3-D that the camera approaches, seen in pixels: truths and bearing pairs.

    Each state at frame 1 is drawn from ``prior`` (a mean (5,) and covariance (5, 5) of
    ``(x, y, v, h, w)``) restricted to points in front of the camera at every frame;
    the point moves on its line by ``step`` (< 0: approaching) per frame; each frame's
    column and row carry noise of SD ``pixel_sd`` about the principal point ``(0, 0)``,
    and :func:`depthcore.problem.model.bearings_from_pixels` turns each into a bearing
    (``rho = pixel_sd / focal``). Returns the states (draws, N, 5) and pairs (draws, N, 2).
    """
    rng = np.random.default_rng(seed)
    mean, cov = (np.asarray(a, dtype=float) for a in prior)
    e = step * np.arange(frames)
    x1 = np.empty((0, 5))
    while len(x1) < draws:
        drawn = rng.multivariate_normal(mean, cov, size=2 * draws)
        x1 = np.concatenate([x1, drawn[drawn[:, 1] + e.min() > 0]])
    x1 = x1[:draws]
    ones = np.ones(frames)
    states = np.stack(
        [
            x1[:, 0, None] + e * x1[:, 2, None],
            x1[:, 1, None] + e,
            x1[:, 2, None] * ones,
            x1[:, 3, None] + e * x1[:, 4, None],
            x1[:, 4, None] * ones,
        ],
        axis=-1,
    )
    exact = focal * states[..., [0, 3]] / states[..., 1:2]
    pixels = exact + pixel_sd * rng.standard_normal(exact.shape)
    pairs = np.stack(
        [model.bearings_from_pixels(p, 0.0, focal) for p in pixels.reshape(-1, 2).T], axis=-1
    )
    return states, pairs.reshape(pixels.shape)


def space_study(seed: int, draws: int, frames: int, step: float, pixel_sd, focal, prior):
    """Each 3-D filter's depth error at the last frame, in its own SDs, over the tracks of
    :func:`space_tracks`.

    The exact filter runs on the batch; the Gaussian filters track by track, ``NaN``
    where one refuses a track (its prediction lost the point). Returns ``{name: ndarray
    (draws,)}`` and the tracks' last depths (draws,).
    """
    from depthcore.registry.filters import FILTERS

    states, pairs = space_tracks(seed, draws, frames, step, pixel_sd, focal, prior)
    depth = states[:, -1, 1]
    steps = np.full(frames - 1, float(step))
    rho = pixel_sd / focal
    exact = FILTERS["optimal"](pairs, rho, *prior, steps=steps)
    z = {"optimal": (exact.depth_mean - depth) / exact.depth_sd}
    for name in SPACE_FILTERS[1:]:
        z[name] = np.full(draws, np.nan)
        for i in range(draws):
            try:
                est = FILTERS[name](pairs[i], rho, *prior, steps=steps)
            except ValueError:
                continue
            z[name][i] = (est.depth_mean - depth[i]) / est.depth_sd
    return z, depth
