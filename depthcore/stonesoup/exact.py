"""The exact filter as a Stone Soup predictor and updater, on a state that carries the posterior.

Recommended import: ``from depthcore.stonesoup import exact``.

Stone Soup's loop, unchanged, runs the exact filter
(:class:`depthcore.exact.online.Online`, the bank of Kalman filters over depth
nodes, one bearing at a time)::

    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[rho**2]]))
    track = Track([exact.ExactState(prior_mean, prior_cov, timestamp=t0)])
    for detection in detections:
        prediction = predictor.predict(track, timestamp=detection.timestamp)
        track.append(updater.update(SingleHypothesis(prediction, detection)))

The predictor takes a ``Track`` (its last state) or a state, as Stone Soup's
own predictors do, so Stone Soup's hypothesisers, data associators,
initiators and trackers run it (:mod:`depthcore.stonesoup.association` for
the bearing's predictive they ask of the updater).

:class:`ExactState` is a Stone Soup ``stonesoup.types.state.GaussianState``
whose ``state_vector`` and ``covar`` are the exact posterior's mean and
covariance (not a Gaussian's: the posterior is the bank's mixture, skewed in
depth), so Stone Soup's plots and metrics read them; it carries the exact
filter itself (``filter``, the mixture over depth nodes after its last
bearing) and what its last update reported (``estimate``: the depth's and
velocity's means and SDs, the bearing's log predictive density, tail
probability and whether a gate skipped it, :class:`depthcore.problem.predictive.FrameEstimate`).

The states, and why a prediction stays exact and the prior untouched.

* A Gaussian state (an :class:`ExactState` built by the user, any Stone Soup
  ``GaussianState``, such as an initiator's or a mixture reduced to one
  Gaussian by JPDA) is a Gaussian prior: :class:`ExactPredictor` moves it in
  closed form (:func:`moved_gaussian`, exact since the motion is affine), and
  the first bearing starts the exact filter from it.
* An :class:`ExactUpdate` holds the filter after its bearing.
* An :class:`ExactPrediction` holds the filter at the last frame before it
  and the signed depth step from that frame (``step``). Its ``state_vector``
  and ``covar`` are the filter's mean and covariance moved by the step in
  closed form, the moments of an affine map. :class:`ExactUpdater` runs
  the filter through the step with the detection: one update of the exact
  filter per frame, on a copy that shares the filter's arrays (Online's
  update replaces its arrays and never writes into them), so no state is
  ever changed and a state can be predicted and updated any number of times,
  as Stone Soup's data association does. Predicting a prediction (a missed
  detection) first runs its filter through its own frame without a bearing
  (a missing frame), so a prediction holds one step whatever the number of
  frames missed: two steps of ``s / 2`` differ from one of ``s`` when
  ``q > 0`` (the velocity's change at the middle frame moves ``x`` over
  the second half).

Where a step brings the point towards the camera (``s < 0``) the exact filter
gives no weight to depths that would reach it; a prediction's moments are the
affine map's, which differ from the filter's at that frame only by the
posterior probability of such depths.

The process noise ``q`` is the predictor's transition model's; the noise
``rho`` is each detection's model's if it has one (noise per frame), else the
updater's.
"""

from __future__ import annotations

import copy

import numpy as np
from stonesoup.base import Property
from stonesoup.predictor.base import Predictor
from stonesoup.types.prediction import Prediction
from stonesoup.types.state import GaussianState, State
from stonesoup.types.update import Update
from stonesoup.updater.base import Updater

from depthcore.exact import online
from depthcore.problem import checks, frames, predictive
from depthcore.stonesoup.models import DepthStep, velocity_variance

#: The most predictions a predictor keeps, and runs of the filter through a prediction and
#: a detection an updater keeps, for one timestamp (:class:`FrameCache`): a frame's pairs,
#: tracks times detections.
CACHED = 1024
#: A bearing whose predictive tail probability is below this is scored without being
#: incorporated (about 6.1 SDs of a Gaussian): no hypothesiser keeps it.
SCORE_GATE = 1e-9
#: A gate that skips every bearing, the largest double below 1, for a bearing's score alone.
ONLY_SCORE = float(np.nextafter(1.0, 0.0))


class FrameCache:
    """A function's answers kept for the latest timestamp only: a frame's, dropped at the next.

    A Stone Soup tracker asks, within a frame, for the same prediction and the
    same scores many times (once per detection, once more to update); none is
    asked for again once the tracker has moved on. The answers are kept by
    their arguments' identities (Stone Soup's states and detections are
    compared by identity; numbers by value) while ``timestamp(*args)`` stays the same, at most
    :data:`CACHED` of them; another timestamp starts afresh. So what a long
    track holds per frame does not grow with the frames.

    Parameters
    ----------
    function : callable
    timestamp : callable
        The timestamp of a call's arguments.
    """

    def __init__(self, function, timestamp):
        self.function = function
        self.timestamp = timestamp
        self.time = None
        self.answers: dict = {}

    def __call__(self, *args):
        """``function(*args)``, computed once for the latest timestamp."""
        time = self.timestamp(*args)
        if time != self.time or len(self.answers) >= CACHED:
            self.answers.clear()
            self.time = time
        key = tuple(a if isinstance(a, (int, float)) else id(a) for a in args)
        kept = self.answers.get(key)
        if kept is None or any(
            a is not b and not isinstance(a, (int, float))
            for a, b in zip(args, kept[0], strict=True)
        ):
            kept = (args, self.function(*args))
            self.answers[key] = kept
        return kept[1]


def _pair_time(prediction, detection):
    return detection.timestamp


class ExactState(GaussianState):
    """The exact posterior in Stone Soup: its mean and covariance, and the filter that holds it.

    Built by the user as the prior: ``ExactState(prior_mean, prior_cov,
    timestamp=t0)`` (the Gaussian of the state at ``t0``); the predictor and
    updater fill the rest (see the module docstring).
    """

    filter: online.Online = Property(
        default=None,
        doc="The exact filter at its last frame; ``None`` for a Gaussian (before the first "
        "bearing).",
    )
    step: float = Property(
        default=0.0,
        doc="The depth's signed change from the filter's last frame to this state.",
    )
    estimate: predictive.FrameEstimate = Property(
        default=None, doc="What the filter's last update reported; ``None`` before it."
    )

    @property
    def depth_mean(self) -> float:
        """``E[y]``, the posterior's mean depth."""
        return float(self.state_vector[1, 0])

    @property
    def depth_sd(self) -> float:
        """``SD[y]``."""
        return float(np.sqrt(self.covar[1, 1]))


class ExactPrediction(Prediction, ExactState):
    """An exact state predicted to a timestamp (:class:`ExactPredictor`)."""


class ExactUpdate(Update, ExactState):
    """An exact state updated by a detection (:class:`ExactUpdater`)."""


def moved_gaussian(mean, cov, step: float, process_noise: float):
    """Moments moved by a signed step ``s``: ``F m + e s``, ``F P F^T + diag(0, 0, q**2 |s|)``.

    Eqs. (1), (9) with the step ``s`` (:mod:`depthcore.problem.frames`); exact
    for any distribution's mean and covariance, since the motion is affine.

    Parameters
    ----------
    mean : array_like, shape (3,) or (3, 1)
    cov : array_like, shape (3, 3)
    step : float
        Negative: the point approaches the camera.
    process_noise : float

    Returns
    -------
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
    """
    F = frames.transition(step)
    with np.errstate(over="ignore", invalid="ignore"):
        m = F @ np.asarray(mean, dtype=float).reshape(3) + [0.0, step, 0.0]
        P = F @ np.asarray(cov, dtype=float) @ F.T
        P[2, 2] += velocity_variance(process_noise, step)
    if not (np.all(np.isfinite(m)) and np.all(np.isfinite(P))):
        raise ValueError(
            f"time_interval: a step of {step:.6g} moves the state beyond the floating-point range"
        )
    return m, 0.5 * (P + P.T)


def last_state(prior, name: str = "prior") -> GaussianState:
    """A Gaussian state, or a ``Track``'s last one, checked (a one-line refusal otherwise)."""
    if not isinstance(prior, State) and hasattr(prior, "states"):
        if len(prior) == 0:
            raise ValueError(f"{name}: the track has no states")
        prior = prior[-1]
    if not isinstance(prior, GaussianState):
        raise ValueError(
            f"{name} must be a Track or a GaussianState (mean and covariance of (x, y, v)), "
            f"got {type(prior).__name__}"
        )
    mean = np.asarray(prior.state_vector, dtype=float)
    cov = np.asarray(prior.covar, dtype=float)
    if mean.shape != (3, 1) or cov.shape != (3, 3):
        raise ValueError(
            f"{name}: the state must be (x, y, v), got a mean of shape {mean.shape} and a "
            f"covariance of shape {cov.shape}"
        )
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        raise ValueError(f"{name}: the state's mean and covariance must be finite")
    return prior


def filter_at(state: ExactState) -> online.Online | None:
    """The exact filter at a state's own frame: its filter run through its step, if it has one.

    An :class:`ExactUpdate`'s filter as it is; an :class:`ExactPrediction`'s on a
    copy run through its step without a bearing (a missing frame); ``None``
    for a Gaussian. The state's filter is not changed.
    """
    filter_ = getattr(state, "filter", None)
    if filter_ is None or state.step == 0:
        return filter_
    moved = copy.copy(filter_)  # Online.update replaces its arrays, never writes into them
    moved.update(np.nan, step=state.step)
    return moved


class ExactPredictor(Predictor):
    """Stone Soup's predictor for the exact filter: moves a state by the depth step.

    ``transition_model`` is a :class:`~depthcore.stonesoup.models.DepthStep`
    (its :meth:`~depthcore.stonesoup.models.DepthStep.step` turns the time
    interval into the depth's signed change); there is no control model.
    Like Stone Soup's own predictors it keeps its predictions (those to the
    latest timestamp, :class:`FrameCache`), so a hypothesiser that predicts a
    track once per detection predicts it once.
    """

    transition_model: DepthStep = Property(doc="The motion with a depth step.")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if not isinstance(self.transition_model, DepthStep):
            raise ValueError(
                f"transition_model must be a DepthStep, got {type(self.transition_model).__name__}"
            )
        self._cached = FrameCache(self._predict, lambda prior, timestamp: timestamp)

    def predict(self, prior, timestamp=None, **kwargs) -> ExactPrediction:
        """The prior predicted to ``timestamp`` (see the module docstring).

        Parameters
        ----------
        prior : stonesoup.types.track.Track or stonesoup.types.state.GaussianState
            A track (its last state is predicted) or a state: an exact one, or
            any Gaussian of ``(x, y, v)`` (a Gaussian prior).
        timestamp : datetime.datetime or None
            ``None`` (or a prior without one): one step of ``depth_per_step``.
        **kwargs
            Ignored (Stone Soup's hypothesisers may pass the detection).

        Returns
        -------
        ExactPrediction
        """
        return self._cached(last_state(prior), timestamp)

    def _predict(self, prior, timestamp) -> ExactPrediction:
        interval = (
            None if timestamp is None or prior.timestamp is None else timestamp - prior.timestamp
        )
        s = self.transition_model.step(interval)
        q = self.transition_model.process_noise
        filter_ = filter_at(prior) if isinstance(prior, ExactState) else None
        if filter_ is None:
            mean, cov = moved_gaussian(prior.state_vector, prior.covar, s, q)
        else:
            if filter_.process_noise != q:
                raise ValueError(
                    f"prior: its exact filter has process_noise {filter_.process_noise:g}, the "
                    f"transition model {q:g}; start it with ExactUpdater(process_noise={q:g})"
                )
            mean, cov = moved_gaussian(filter_.current.mean, filter_.current.cov, s, q)
        estimate = prior.estimate if isinstance(prior, ExactState) else None
        return ExactPrediction(
            mean.reshape(3, 1),
            cov,
            timestamp=timestamp,
            filter=filter_,
            step=s if filter_ is not None else 0.0,
            estimate=estimate,
            transition_model=self.transition_model,
            prior=prior,
        )


class ExactUpdater(Updater):
    """Stone Soup's updater for the exact filter: adds a detection's bearing to the posterior.

    ``measurement_model`` is a :class:`~depthcore.stonesoup.models.TangentBearing`
    (a detection's own model, if it has one, wins: its ``rho`` is that frame's).
    ``gate``: skip a bearing whose two-sided predictive tail probability is
    below it (:mod:`depthcore.problem.predictive`); the update then equals the
    prediction moved through a missing frame, and ``estimate.gated`` says so.
    ``rtol``: the exact filter's quadrature tolerance. ``process_noise``: the
    ``q`` of a filter started from a prediction that names no transition
    model (an initiator's prior state); a prediction of
    :class:`ExactPredictor` names its own.

    :meth:`predict_measurement` gives the bearing's exact predictive
    (:mod:`depthcore.stonesoup.association`).
    """

    measurement_model: object = Property(
        default=None, doc="The bearing's model, used for a detection that carries none."
    )
    gate: float = Property(default=None, doc="A tail probability in (0, 1), or ``None``.")
    rtol: float = Property(default=1e-10, doc="The depth quadrature's tolerance.")
    process_noise: float = Property(
        default=0.0, doc="``q`` where the prediction names no transition model."
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.gate = predictive.gate(self.gate)
        self.rtol = checks.positive_scalar(self.rtol, "rtol")
        self.process_noise = checks.nonnegative_scalar(self.process_noise, "process_noise")
        self._runs = FrameCache(self._run, _pair_time)
        self._scores = FrameCache(self._score, _pair_time)
        self._started = FrameCache(self._start, lambda prediction, rho: prediction.timestamp)

    def rho(self, measurement_model=None) -> float:
        """The bearing's noise SD under ``measurement_model`` (``None``: the updater's)."""
        bearing = self._check_measurement_model(measurement_model)
        covar = np.asarray(bearing.covar(), dtype=float)
        if covar.shape != (1, 1):
            raise ValueError(
                f"measurement_model must see one bearing (noise_covar [[rho**2]]), got a "
                f"covariance of shape {covar.shape}"
            )
        return float(np.sqrt(covar[0, 0]))

    def predict_measurement(
        self, predicted_state, measurement_model=None, measurement_noise=True, **kwargs
    ):
        """The bearing's predictive, as Stone Soup's Gaussian measurement prediction.

        :func:`depthcore.stonesoup.association.predict_bearing`: the exact
        predictive's mean, variance and covariance with the state, for Stone Soup's
        Gaussian association, with its density and tail at a detection on request.
        """
        from depthcore.stonesoup import association  # it builds on this module

        return association.predict_bearing(
            self, predicted_state, measurement_model, measurement_noise
        )

    def start(self, prediction: GaussianState, rho: float) -> online.Online:
        """The exact filter started on a Gaussian prediction, before its first bearing.

        Kept for the prediction (:class:`FrameCache`): every detection scored
        against it starts from the same nodes.
        """
        return self._started(prediction, rho)

    def _start(self, prediction, rho):
        model = getattr(prediction, "transition_model", None)
        q = self.process_noise if model is None else model.process_noise
        return online.Online(
            np.asarray(prediction.state_vector, dtype=float)[:, 0],
            np.asarray(prediction.covar, dtype=float),
            rho,
            process_noise=q,
            gate=self.gate,
            rtol=self.rtol,
        )

    def predictive_at(self, prediction, detection) -> predictive.FrameEstimate:
        """The exact predictive's report at a detection: how a hypothesiser scores the pair.

        Its ``log_predictive`` and ``tail`` are the log density and two-sided
        tail probability of the detection's bearing under the exact predictive
        (the mixture over depth nodes, :mod:`depthcore.problem.predictive`). A
        bearing with a tail probability of at least :data:`SCORE_GATE` is
        incorporated on the way, and :meth:`update` uses that run; one further
        out is only scored (the filter is not asked to move that far).

        Parameters
        ----------
        prediction : stonesoup.types.state.GaussianState or Track
        detection : stonesoup.types.detection.Detection

        Returns
        -------
        depthcore.problem.predictive.FrameEstimate
        """
        return self._scores(*self._pair(prediction, detection))[1]

    def filter_through(self, prediction, detection):
        """The exact filter run through a prediction's step with a detection's bearing.

        The updater keeps the runs of the latest timestamp (:class:`FrameCache`),
        and a run made while scoring the pair (:meth:`predictive_at`) is this one.

        Parameters
        ----------
        prediction : stonesoup.types.state.GaussianState or Track
            An :class:`ExactPrediction`, or any Gaussian (a Gaussian prior at the
            detection's frame).
        detection : stonesoup.types.detection.Detection
            One finite bearing.

        Returns
        -------
        filter : depthcore.exact.online.Online
            A new filter; the prediction's is not changed.
        estimate : depthcore.problem.predictive.FrameEstimate
            Its update's report: the bearing's log predictive density and tail
            probability, the posterior's moments.
        """
        return self._runs(*self._pair(prediction, detection))

    def _pair(self, prediction, detection):
        prediction = last_state(prediction, "hypothesis: its prediction")
        if not detection:
            raise ValueError(
                "hypothesis: a missed detection has no bearing; its track keeps the prediction"
            )
        bearing_of(detection)
        if getattr(prediction, "filter", None) is not None and prediction.step == 0:
            raise ValueError(
                "hypothesis: its prediction has not moved since the last bearing (a zero "
                "step); the exact filter takes one bearing per frame"
            )
        return prediction, detection

    def _moved(self, prediction, detection, gate):
        """A new filter through the pair, its gate ``gate`` for this bearing."""
        mu = bearing_of(detection)
        rho = self.rho(detection.measurement_model)
        base = getattr(prediction, "filter", None)
        fresh = base is None
        moved = copy.copy(self.start(prediction, rho) if fresh else base)
        # Online.update replaces its arrays and never writes into them: the copy shares them
        moved.gate = gate
        try:
            estimate = (
                moved.update(mu) if fresh else moved.update(mu, rho=rho, step=prediction.step)
            )
        finally:
            moved.gate = self.gate
        return moved, estimate

    def _score(self, prediction, detection):
        gate = SCORE_GATE if self.gate is None else max(self.gate, SCORE_GATE)
        try:
            moved, estimate = self._moved(prediction, detection, gate)
        except ValueError:  # the filter cannot take this bearing: its score alone
            return None, self._moved(prediction, detection, ONLY_SCORE)[1]
        own = self.gate is not None and estimate.tail < self.gate
        return (moved if own or not estimate.gated else None), estimate

    def _run(self, prediction, detection):
        moved, estimate = self._scores(prediction, detection)
        if moved is not None:
            return moved, estimate
        return self._moved(prediction, detection, self.gate)

    def update(self, hypothesis, **kwargs) -> ExactUpdate:
        """The posterior after the hypothesis's detection (see the module docstring).

        Parameters
        ----------
        hypothesis : stonesoup.types.hypothesis.SingleHypothesis
            Its prediction an :class:`ExactPrediction` (or a Gaussian prior),
            its measurement a detection of one bearing. A run of the filter
            through the pair that a hypothesiser made is used as it is
            (:meth:`filter_through`).

        Returns
        -------
        ExactUpdate
        """
        prediction, detection = hypothesis.prediction, hypothesis.measurement
        filter_, estimate = self.filter_through(prediction, detection)
        mean, t = estimate.mean.reshape(3, 1), detection.timestamp
        return exact_update(hypothesis, prediction, mean, estimate.cov, t, filter_, estimate)


def exact_update(hypothesis, prediction, mean, covar, timestamp, filter_=None, estimate=None):
    """``prediction`` updated by ``hypothesis`` to ``N(mean, covar)`` at ``timestamp``.

    ``mean`` (3, 1), ``covar`` (3, 3); the :class:`ExactUpdate` stands at the
    filter's last frame (``step`` 0), ``filter_`` and ``estimate`` as
    :class:`ExactState` holds them (``None``: a Gaussian without a filter).
    """
    return Update.from_state(
        prediction,
        mean,
        covar,
        timestamp=timestamp,
        filter=filter_,
        step=0.0,
        estimate=estimate,
        hypothesis=hypothesis,
        target_type=ExactUpdate,
    )


def bearing_of(detection) -> float:
    """A detection's bearing, one finite number (a one-line refusal otherwise)."""
    values = getattr(detection, "state_vector", None)
    if values is None:
        raise ValueError(
            f"measurement must be a Stone Soup detection, got {type(detection).__name__}"
        )
    values = np.asarray(values, dtype=float).reshape(-1)
    if values.size != 1:
        raise ValueError(f"measurement must be one bearing, got {values.size} values")
    if not np.isfinite(values[0]):
        raise ValueError(
            f"measurement: a detection's bearing must be finite, got {values[0]!r} (a frame "
            "without a bearing has no detection)"
        )
    return float(values[0])
