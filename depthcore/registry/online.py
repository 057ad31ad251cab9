"""Filters fed one bearing at a time, through one door: :func:`~depthcore.registry.online.start`.

Recommended import: ``from depthcore.registry import online``.

``f = online.start(name, prior_mean, prior_cov, rho=None, process_noise=0.0, gate=None)``
starts the filter ``name`` (one of :data:`NAMES`: ``"optimal"``, the exact
filter, :class:`depthcore.exact.online.Online`; ``"ekf"`` and ``"ukf"``,
:class:`depthcore.kalman.online.EKF` and :class:`depthcore.kalman.online.UKF`)
on the prior of the state at frame 1. Each ``f.update(mu_k, rho=None,
step=1.0)`` predicts the state over ``step`` (not at the first frame),
reports the bearing's predictive density and tail probability, skips it if it
is missing (``NaN``) or gated, incorporates it otherwise, and returns a
:class:`~depthcore.problem.predictive.FrameEstimate`. Time and memory per
frame are constant and the frames are not limited in number (the batch doors
hold a whole track, at most ``depthcore.problem.checks.MAX_FRAMES`` frames);
after ``N`` frames the estimate is the batch door's at frame ``N``
(:data:`depthcore.registry.filters.FILTERS`).

Many features at once: priors of shape (B, d) and (B, d, d) start the batched
filter of the name (:data:`BATCHED`: ``"optimal"``,
:class:`depthcore.exact.features.Features`; ``"ekf"`` and ``"ukf"``,
:class:`depthcore.kalman.features.Features`), whose ``update(mu, rho=None,
step=1.0)`` takes every feature's bearing (B,) or pair (B, 2) of the frame (NaN
where one is not seen), ``rho`` and ``step`` a number or one per feature, and
returns a :class:`~depthcore.problem.predictive.FrameEstimates`; it has no gate.

Example: a live loop, each bearing used as it arrives

>>> import numpy as np
>>> from depthcore.registry import online
>>> f = online.start("ekf", [0.0, 8.0, 0.0], 10.0 * np.eye(3), rho=0.01, gate=1e-4)
>>> for mu in (0.1, 0.2, float("nan"), 0.35, 3.0, 0.41):
...     est = f.update(mu)
...     if est.gated:
...         print(f"frame {est.frame}: bearing skipped (tail {est.tail:.1e})")
frame 5: bearing skipped (tail 0.0e+00)
>>> f.frame, f.current.depth_mean > 0
(6, True)
"""

from __future__ import annotations

import importlib
import inspect

import numpy as np

from depthcore.problem.predictive import FrameEstimate, FrameEstimates

#: The online filters by name, with the module and class of each.
ONLINE = {
    "optimal": ("depthcore.exact.online", "Online"),
    "ekf": ("depthcore.kalman.online", "EKF"),
    "ukf": ("depthcore.kalman.online", "UKF"),
}

#: The batched filters by name, for priors of many features (module docstring).
BATCHED = {
    "optimal": ("depthcore.exact.features", "Features"),
    "ekf": ("depthcore.kalman.features", "Features"),
    "ukf": ("depthcore.kalman.features", "Features"),
}

#: The names :func:`start` takes.
NAMES = tuple(ONLINE)

#: The registry's options of each online filter (those of its batch entry).
DEFAULT_OPTIONS = {"ukf": {"allow_behind_camera": True}}


class OnlineFilter:
    """A started online filter (:func:`start`): :meth:`update`, :attr:`frame`, ``current``.

    :attr:`detail` is the family's own filter:
    :class:`depthcore.exact.online.Online`, :class:`depthcore.kalman.online.EKF`
    or :class:`depthcore.kalman.online.UKF` (:class:`depthcore.kalman.online.Spatial`
    in 3-D); for a batch of features :class:`depthcore.exact.features.Features` or
    :class:`depthcore.kalman.features.Features`, whose answers are
    :class:`~depthcore.problem.predictive.FrameEstimates`.
    """

    def __init__(self, name: str, inner, batched: bool = False):
        self.name = name
        self._inner = inner
        self._batched = batched
        self.current: FrameEstimate | FrameEstimates | None = None

    @property
    def detail(self):
        """The family's own online filter (the exact one's node count, say)."""
        return self._inner

    @property
    def frame(self) -> int:
        """Frames seen so far, missing ones included."""
        return int(self._inner.frame)

    @property
    def batched(self) -> bool:
        """Whether the filter holds a batch of features (priors of shape (B, d))."""
        return self._batched

    def update(self, mu, rho=None, step=1.0) -> FrameEstimate | FrameEstimates:
        """Add the next frame's bearing (of every feature, for a batch).

        ``mu``, ``rho`` (``None``: the one given to :func:`start`) and ``step`` as
        :func:`depthcore.problem.predictive.frame_inputs` checks them (as
        :func:`depthcore.problem.predictive.batch_inputs` checks them for a batch);
        returns a :class:`~depthcore.problem.predictive.FrameEstimate`
        (:class:`~depthcore.problem.predictive.FrameEstimates`).
        """
        self.current = self._inner.update(mu, rho=rho, step=step)
        return self.current


def start(
    name: str, prior_mean, prior_cov, rho=None, process_noise=0.0, gate=None, **options
) -> OnlineFilter:
    """Start the online filter ``name`` on the prior of the state at frame 1.

    Parameters
    ----------
    name : str
        One of :data:`NAMES`.
    prior_mean : array_like, shape (3,), (5,), (B, 3) or (B, 5)
        Of ``(x, y, v)``, or of ``(x, y, v, h, w)`` for a point in 3-D: then each
        update takes a pair ``(x / y, h / y)`` (:class:`depthcore.kalman.online.Spatial`
        for the EKF and the UKF). With a
        leading ``B``: ``B`` features at once (module docstring), without a gate.
    prior_cov : array_like, shape (3, 3), (5, 5), (B, 3, 3) or (B, 5, 5)
        Symmetric positive definite.
    rho : float or None
        The bearings' noise SD, > 0, where an update is given none (for a batch, a
        number or one per feature).
    process_noise : float
        ``q >= 0``: the velocity's variance grows by ``q**2 abs(s)`` over a step ``s``.
    gate : float or None
        Skip a bearing whose two-sided predictive tail probability is below it
        (:func:`depthcore.problem.predictive.gate`).
    **options
        The filter's own options (the UKF's ``sigma_points`` and
        ``allow_behind_camera``, the exact filter's ``rtol`` and ``law``, a
        :class:`~depthcore.problem.depth_prior.DepthPrior`, the batched exact filter's
        ``nodes`` and ``rtol``); another is refused in one line naming it.

    Returns
    -------
    OnlineFilter
    """
    if not isinstance(name, str) or name not in ONLINE:
        raise ValueError(f"name must be one of {NAMES}, got {name!r}")
    module, cls = ONLINE[name]
    try:
        factory = getattr(importlib.import_module(module), cls)
    except ImportError:
        raise ValueError(f"name: the online {name} filter is not installed ({module})") from None
    options = {**DEFAULT_OPTIONS.get(name, {}), **options}
    if np.ndim(prior_mean) == 2:  # a batch of features
        if gate is not None:
            raise ValueError(f"gate: the batched {name} filter has no gate; give None")
        module, cls = BATCHED[name]
        factory = getattr(importlib.import_module(module), cls)
        if name != "optimal":
            options = {"filter": name, **options}
            if np.shape(prior_mean)[-1] == 5:
                options.pop("allow_behind_camera", None)
        inner = factory(prior_mean, prior_cov, rho, process_noise, **_known(factory, options))
        return OnlineFilter(name, inner, batched=True)
    if np.shape(prior_mean) == (5,) and name in ("ekf", "ukf"):  # a point in 3-D: pairs
        factory, options = importlib.import_module(module).Spatial, {"filter": name}
    inner = factory(prior_mean, prior_cov, rho, process_noise, gate, **_known(factory, options))
    return OnlineFilter(name, inner)


def _known(factory, options: dict) -> dict:
    """``options`` if ``factory`` takes each of them, else a one-line refusal naming one."""
    takes = inspect.signature(factory).parameters
    for key in options:
        if key not in takes:
            raise ValueError(f"{key}: the {factory.__name__} filter takes no such option")
    return options
