"""One track filtered and smoothed at every frame, by any filter of the registry with a smoother.

Recommended import: ``import depthcore; depthcore.track(...)``.

:func:`track` takes a point's bearings over ``N`` frames (from a user's own
data: :func:`depthcore.problem.model.bearings_from_pixels`), checks them once, runs a
filter of :data:`depthcore.registry.filters.SMOOTHED` and its fixed-interval smoother,
and returns a :class:`Track`: the depth, the lateral position and the
velocity at every frame with their SDs, filtered and smoothed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from depthcore.exact import spatial as exact_spatial
from depthcore.exact.mixture import Smoothed
from depthcore.kalman import spatial
from depthcore.problem import bearing_pairs, checks, frames, model, predictive
from depthcore.problem.depth_prior import DepthPrior
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, Gaussian, paper_prior
from depthcore.registry.filters import FILTERS, names

#: The noise levels ``rho`` that :func:`track` answers for (and the command line's ``--rho``).
RHO_RANGE = (1e-12, 1e3)

#: The largest process noise that :func:`track` answers for (and the command line's).
PROCESS_NOISE_MAX = 10.0

#: The names a message refusing :func:`track`'s inputs may start with.
_TRACK_ARGUMENTS = ("mu", "rho", "prior", "process_noise", "filter", "steps", "gate")


@dataclass(frozen=True)
class Track:
    """One track's state at every frame, filtered and smoothed (:func:`track`).

    Frame ``k`` is row ``k - 1`` of every array; ``N`` is the number of bearings.
    Depths are in units of the depth's change per frame of the paper's frames
    (the point recedes by 1 from frame to frame, Eq. (1)); the lateral position ``x`` in
    the same units; the velocity ``v`` is ``x``'s change per frame.

    Attributes
    ----------
    filter : str
        The registry's name of the filter.
    filtered : depthcore.exact.mixture.Smoothed
        The state at frame ``k`` given ``mu_1 .. mu_k``: a
        :class:`~depthcore.exact.mixture.Smoothed` of means (N, 3) and covariances
        (N, 3, 3) of ``(x_k, y_k, v_k)`` (of pairs, (N, 5) and (N, 5, 5) of
        ``(x_k, y_k, v_k, h_k, w_k)``), whose ``depth_mean``, ``depth_sd``,
        ``lateral_mean``, ``lateral_sd``, ``velocity_mean`` and
        ``velocity_sd`` have shape (N,).
    smoothed : depthcore.exact.mixture.Smoothed
        The state at frame ``k`` given all ``N`` bearings (the fixed-interval
        smoother, textbook 19.2.6); at frame ``N`` it is the filtered state.
    prior : depthcore.problem.gaussian.Gaussian
        The prior of the state at frame 1 that the filter used (of pairs, one with a
        ``mean`` (5,) and a ``cov`` (5, 5)).
    process_noise : float
    detail : object
        The filter's own result: the exact filter's :class:`~depthcore.exact.smoother.Track`,
        a Gaussian filter's :class:`~depthcore.problem.gaussian.History`; of pairs, a
        :class:`~depthcore.exact.spatial.SpatialTrack` or a
        :class:`~depthcore.kalman.spatial.SpatialHistory`.
    updates : depthcore.problem.predictive.Updates
        Per frame, shape (N,) each: the bearing's log predictive density and
        two-sided tail probability under the filter's prediction before it saw
        it (``NaN`` at a missing frame), and whether the gate skipped it. ``None`` for
        pairs, which have no gate yet.
    """

    filter: str
    filtered: Any
    smoothed: Any
    prior: Gaussian
    process_noise: float
    detail: Any = None
    updates: Any = None

    @property
    def frames(self) -> np.ndarray:
        """The frame numbers ``1 .. N``, shape (N,)."""
        return np.arange(1, self.filtered.mean.shape[0] + 1)


def default_prior(mu, steps=None) -> Gaussian:
    """The paper's prior rule for a track as it comes: from its first three present bearings.

    The paper's rule (:func:`depthcore.problem.gaussian.paper_prior`) takes the
    noise-free state of the first three bearings, Eq. (7), moves it back to
    frame 1 and sets the velocity to 0. A track with gaps or steps uses its
    first three present bearings ``mu_a, mu_b, mu_c`` at their depths
    travelled since frame 1, ``t_a, t_b, t_c``: the state ``(x_1, y_1, v)`` at
    frame 1 through which they pass without noise solves the three linear
    equations ``x_1 + t_k v - mu_k y_1 = mu_k t_k`` (Eq. (1) over the steps),
    and the prior is ``N((x_1, y_1, 0), 1000 I)``. With the first three
    bearings present at unit steps it is the paper's rule itself.

    Parameters
    ----------
    mu : ndarray, shape (N,)
        Checked bearings, ``NaN`` where missing.
    steps : array_like, shape (N - 1,), or None

    Returns
    -------
    Gaussian
        Refused, naming ``prior``, when the three bearings put the point
        behind the camera at frame 1 or are degenerate.
    """
    mu = np.asarray(mu, dtype=float)
    present = np.flatnonzero(~np.isnan(mu))[:3]
    s = np.ones(mu.shape[-1] - 1) if steps is None else np.asarray(steps, dtype=float)
    if np.array_equal(present, [0, 1, 2]) and np.all(s[:2] == 1.0):
        try:
            c = model.noise_free_state(mu[:3])
        except ValueError as exc:
            raise ValueError(
                f"prior is needed: the paper's rule cannot use the first three bearings ({exc})"
            ) from None
        return paper_prior(c)
    t = np.concatenate([[0.0], np.cumsum(s)])[present]
    m = mu[present]
    A = np.stack([np.ones(3), -m, t], axis=-1)  # unknowns (x_1, y_1, v)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        solvable = np.linalg.cond(A) < 1e12
        x1, y1, _ = np.linalg.solve(A, m * t) if solvable else (np.nan,) * 3
    if not solvable or not np.all(y1 + t > 0):  # in front of the camera at those frames
        why = (
            "are degenerate"
            if not solvable
            else f"put the point behind the camera (y_1 = {y1:.6g}, depth travelled "
            f"{', '.join(f'{v:.6g}' for v in t)})"
        )
        raise ValueError(
            f"prior is needed: the first three present bearings (frames "
            f"{', '.join(str(int(i) + 1) for i in present)}) {why}"
        )
    return Gaussian(np.array([x1, y1, 0.0]), PAPER_PRIOR_SCALE * np.eye(3))


def _rho(rho, mu, steps):
    """``rho`` for :func:`track`: a number or one per frame (N,), in :data:`RHO_RANGE`."""
    arr = checks.as_float(rho, "rho")
    if arr.ndim == 0 or arr.shape == (1,):
        value = checks.positive_scalar(rho, "rho")
        used = np.array([value])
    else:
        used = frames.check(mu, arr, steps).rho[~np.isnan(mu)]
        value = arr
    _in_range(used)
    return value


def _in_range(used) -> None:
    """Refuse, naming ``rho``, a noise level of the frames outside :data:`RHO_RANGE`."""
    if not np.all((RHO_RANGE[0] <= used) & (used <= RHO_RANGE[1])):
        bad = float(used[np.argmax(~((RHO_RANGE[0] <= used) & (used <= RHO_RANGE[1])))])
        raise ValueError(f"rho must be from {RHO_RANGE[0]:g} to {RHO_RANGE[1]:g}, got {bad!r}")


def track(
    mu, rho, prior=None, process_noise=0.0, filter: str = "optimal", steps=None, gate=None
) -> Track:
    """Filter and smooth one track: depth, lateral position and velocity at every frame.

    Parameters
    ----------
    mu : array_like, shape (N,) or (N, 2)
        The bearings of frames ``1 .. N``, ``3 <= N <= depthcore.problem.checks.MAX_FRAMES``:
        ``mu_k = x_k / y_k``, the tangent of the angle between the point and the
        camera's direction of motion (from pixel columns,
        :func:`depthcore.problem.model.bearings_from_pixels`); ``NaN`` marks a
        missing frame, which the filter predicts through. Checked by
        :func:`depthcore.problem.model.measurements_batch` (by
        :func:`depthcore.problem.frames.check` with gaps, ``rho`` per frame or
        steps). Pairs ``(x_k / y_k, h_k / y_k)``, a point in 3-D
        (:func:`depthcore.problem.bearing_pairs.check`), go to the 3-D forms of the
        filters: the exact filter at every frame and its smoother
        (:func:`depthcore.exact.spatial.track`), the EKF's and UKF's
        (:func:`depthcore.kalman.spatial.smoother`); their prior is by default the rule of
        :func:`depthcore.registry.track_runs.start_prior`, and a gate reads the online
        filter's tail of each pair (:mod:`depthcore.registry.online`).
    rho : float or array_like, shape (N,)
        The SD of the bearings' noise, in :data:`RHO_RANGE` (in the units of
        ``mu``: a pixel noise of SD ``s`` is ``rho = s / f`` for a focal
        length of ``f`` pixels), one for all frames or one per frame.
    prior : depthcore.problem.gaussian.Gaussian or depthcore.problem.depth_prior.DepthPrior
        The prior of the state ``(x_1, y_1, v_1)`` at frame 1. A
        :class:`~depthcore.problem.depth_prior.DepthPrior` (any law of the depth,
        Gaussian given it) is the exact filter's prior as it is; the Gaussian filters
        take its Gaussian of the same mean and covariance. By default the
        paper's rule applied to the first three present bearings
        (:func:`default_prior`: :func:`depthcore.problem.gaussian.paper_prior`
        of their noise-free state, Eq. (7), when they are frames 1-3 at unit
        steps), refused when those bearings put the point behind the camera
        or are degenerate.
    process_noise : float
        ``q``, the SD of the velocity's change per unit step: 0 (constant
        velocity) or from ``depthcore.problem.checks.MIN_PROCESS_NOISE`` to
        :data:`PROCESS_NOISE_MAX`; over a step ``s`` the velocity's variance
        grows by ``q**2 s``.
    filter : str
        A filter with a smoother, one of :data:`~depthcore.registry.filters.SMOOTHED`:
        ``"optimal"`` (the
        exact filter, a bank of Kalman filters over depth, and its
        smoother), ``"ekf"`` (the extended Kalman filter and smoother),
        ``"ukf"`` (the unscented ones). The others, without a smoother, are
        refused, naming ``filter``.
    steps : array_like, shape (N - 1,), optional
        The depth's signed change from each frame to the next, nonzero: positive
        while the point recedes (the camera moves away), negative while the camera
        approaches it (``None``: ones, the paper's frames). The point must stay in
        front of the camera at every frame.
    gate : float or None
        Skip a bearing whose two-sided tail probability under the filter's
        prediction is below this probability
        (:func:`depthcore.problem.predictive.gate`); the filter and the
        smoother then run as if that frame had no bearing, and
        ``updates.gated`` says which were skipped. ``None``: no gate.

    Returns
    -------
    Track
        ``filtered`` and ``smoothed`` means and SDs of ``x``, ``y`` (the depth)
        and ``v`` at every frame, arrays of shape (N,), and each frame's
        ``updates``.

    Examples
    --------
    >>> import depthcore
    >>> t = depthcore.track([0.1, 0.2, 0.28, 0.35], rho=0.002)
    >>> t.smoothed.depth_mean.shape
    (4,)
    >>> t = depthcore.track([0.1, 0.2, float("nan"), 0.35], rho=0.002, filter="ekf")
    >>> t.smoothed.depth_mean.shape
    (4,)
    >>> t = depthcore.track([[0.1, 0.05], [0.2, 0.04], [0.28, 0.03], [0.35, 0.02]], rho=0.002)
    >>> t.smoothed.mean.shape
    (4, 5)
    """
    if not isinstance(filter, str) or filter not in FILTERS:
        raise ValueError(f"filter must be one of {names(smoothed=True)}, got {filter!r}")
    entry = FILTERS[filter]
    if entry.smoother is None:
        raise ValueError(
            f"filter must be one of {names(smoothed=True)}, the filters with a smoother; "
            f"{filter!r} has none"
        )
    mu_arr = checks.as_float(mu, "mu")
    if mu_arr.ndim == 2 and mu_arr.shape[-1] == 2:
        return _pairs(mu_arr, rho, prior, process_noise, filter, steps, gate)
    rho_arr = checks.as_float(rho, "rho")
    if steps is None and rho_arr.ndim == 0 and not np.any(np.isnan(mu_arr)):
        mu = model.measurements_batch(mu_arr, "mu")
    else:
        checked = frames.check(mu_arr, 1.0, steps)
        mu = checked.mu
        if steps is not None:
            steps = np.array(checked.steps)
    if mu.ndim != 1:
        raise ValueError(f"mu must have shape (N,), one track, got shape {mu.shape}")
    rho = _rho(rho, mu, steps)
    q = checks.process_noise(process_noise, "process_noise")
    if q > PROCESS_NOISE_MAX:
        raise ValueError(f"process_noise must be at most {PROCESS_NOISE_MAX:g}, got {q!r}")
    if prior is None:
        prior = default_prior(mu, steps)
    elif not isinstance(prior, Gaussian | DepthPrior):
        raise ValueError(
            f"prior must be a depthcore.Gaussian or a DepthPrior of the state at frame 1, or "
            f"None, got {type(prior).__name__}"
        )
    gate = predictive.gate(gate)
    more = {} if steps is None else {"steps": steps}
    mean, cov = (prior.mean, prior.cov) if isinstance(prior, Gaussian) else prior.gaussian()
    if isinstance(prior, DepthPrior) and filter == "optimal":
        more["law"] = prior  # the exact filter under the law; the others, its Gaussian
    try:
        report = entry(mu, rho, mean, cov, q, gate=gate, **more).updates
        if gate is not None and np.any(report.gated):
            mu = np.where(report.gated, np.nan, mu)  # a skipped bearing is a missing one
        filtered, smoothed, detail = entry.smoother(mu, rho, mean, cov, q, **more)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise _no_answer(exc, f"the {filter} filter") from None
    for series in (filtered, smoothed):
        variances = np.diagonal(series.cov, axis1=-2, axis2=-1)
        if not (np.all(np.isfinite(series.mean)) and np.all(variances >= 0)):
            raise ValueError(
                f"rho is too small beside the prior for the {filter} filter's "
                f"smoother: its moments are not finite (rho = {rho!r})"
            )
    return Track(filter, filtered, smoothed, prior, q, detail, report)


def _pairs(mu, rho, prior, process_noise, filter: str, steps, gate) -> Track:
    """:func:`track` of pairs ``mu`` (N, 2), a point in 3-D: the exact or a Gaussian 3-D filter.

    ``"optimal"``: :func:`depthcore.exact.spatial.track`, the exact filter at every frame and
    each depth node's Rauch-Tung-Striebel smoother mixed over the nodes; ``"ekf"`` and
    ``"ukf"``: :func:`depthcore.kalman.spatial.smoother`. The prior by default is the
    command line's rule for pairs (:func:`depthcore.registry.track_runs.start_prior`).
    """
    from depthcore.registry import track_runs  # it imports this module

    gate = predictive.gate(gate)
    rho = checks.as_float(rho, "rho")
    rho = checks.positive_scalar(rho, "rho") if rho.shape in ((), (1,)) else rho
    checked = bearing_pairs.check(mu, rho, steps)
    _in_range(checked.rho[checked.present])
    steps = None if steps is None else checked.steps[0]
    q = checks.process_noise(process_noise, "process_noise")
    if q > PROCESS_NOISE_MAX:
        raise ValueError(f"process_noise must be at most {PROCESS_NOISE_MAX:g}, got {q!r}")
    if prior is None:
        prior = track_runs.start_prior(checked.mu[0], steps)
    elif np.shape(getattr(prior, "mean", None)) != (5,):
        raise ValueError(
            "prior must have a mean (5,) and a covariance (5, 5) of (x, y, v, h, w) for pairs, "
            f"or be None, got {type(prior).__name__}"
        )
    report = None
    try:
        if gate is not None:
            report = _gated_pairs(checked, prior, q, filter, gate)
            mu = np.where(report.gated[:, None], np.nan, mu)  # a skipped pair is a missing one
        args = (mu, rho, prior.mean, prior.cov, q, steps)
        if filter == "optimal":
            detail = exact_spatial.track(*args)
            filtered, smoothed = detail.filtered, detail.smoothed
        else:
            detail, s = spatial.smoother(*args, filter=filter)
            filtered, smoothed = Smoothed(detail.means, detail.covs), Smoothed(s.mean, s.cov)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise _no_answer(exc, f"the {filter} filter of pairs") from None
    return Track(filter, filtered, smoothed, prior, q, detail, report)


def _no_answer(exc: Exception, who: str) -> Exception:
    """A filter's failure as :func:`track`'s refusal: a refusal of track()'s own arguments
    as it is, anything else as no answer from ``who``."""
    message = str(exc)
    if isinstance(exc, ValueError) and message.startswith(_TRACK_ARGUMENTS):
        return exc
    return ValueError(
        f"mu, rho and prior have no answer from {who} ({message}); "
        "try another filter, a larger rho or a broader prior"
    )


def _gated_pairs(checked, prior, q: float, filter: str, gate: float) -> predictive.Updates:
    """Each pair's report by the online filter ``filter`` with the gate: arrays (N,)."""
    from depthcore.registry import online  # it imports the registry's filters

    f = online.start(filter, prior.mean, prior.cov, 1.0, q, gate)
    mu, rho = checked.mu[0], checked.rho[0]
    steps = np.concatenate([[1.0], checked.steps[0]])  # the first is not used
    out = np.full((3, len(mu)), np.nan)
    for k in range(len(mu)):
        est = f.update(mu[k], rho=float(rho[k]), step=float(steps[k]))
        out[:, k] = est.log_predictive, est.tail, est.gated
    return predictive.Updates(out[0], out[1], out[2] == 1.0)
