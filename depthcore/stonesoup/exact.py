"""The exact filter as a Stone Soup predictor and updater, on a state that carries the posterior.

Recommended import: ``from depthcore.stonesoup import exact``.

Stone Soup's loop, unchanged, runs the exact filter
(:class:`depthcore.exact.online.Online`, the bank of Kalman filters over depth
nodes, one bearing at a time)::

    predictor = exact.ExactPredictor(models.DepthStep(process_noise=q, speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[rho**2]]))
    track = Track([exact.ExactState(prior_mean, prior_cov, timestamp=t0)])
    for detection in detections:
        prediction = predictor.predict(track[-1], timestamp=detection.timestamp)
        track.append(updater.update(SingleHypothesis(prediction, detection)))

:class:`ExactState` is a Stone Soup ``stonesoup.types.state.GaussianState``
whose ``state_vector`` and ``covar`` are the exact posterior's mean and
covariance (not a Gaussian's: the posterior is the bank's mixture, skewed in
depth), so Stone Soup's plots and metrics read them; it carries the exact
filter itself (``filter``, the mixture over depth nodes after its last
bearing) and what its last update reported (``estimate``: the depth's and
velocity's means and SDs, the bearing's log predictive density, tail
probability and whether a gate skipped it, :class:`depthcore.problem.predictive.FrameEstimate`).

How a prediction stays exact and the prior untouched. Before the first
bearing the state is the Gaussian prior, and :class:`ExactPredictor` moves it
in closed form (the motion is affine, :class:`~depthcore.stonesoup.models.DepthStep`).
After it, a prediction keeps the filter of its prior and the depth steps
predicted since (``pending``): predicting a prediction (a missed detection)
adds a step, and the update runs the filter through each pending step but the
last without a bearing (a missing frame) and through the last with the
detection. Its ``state_vector`` and ``covar`` are those of a copy of the
filter run through the pending steps. Nothing changes the prior's filter, so
a state can be predicted and updated any number of times, as Stone Soup's
data association does. Two steps of ``s / 2`` differ from one of ``s`` when
``q > 0`` (the velocity's change at the middle frame moves ``x`` over the
second half), and the pending steps keep them apart.

The process noise ``q`` is the predictor's transition model's, read at the
first bearing (from the prediction, which names its transition model); the
noise ``rho`` is each detection's model's if it has one (noise per frame),
else the updater's.
"""

from __future__ import annotations

import copy

import numpy as np
from stonesoup.base import Property
from stonesoup.predictor.base import Predictor
from stonesoup.types.prediction import Prediction
from stonesoup.types.state import GaussianState
from stonesoup.types.update import Update
from stonesoup.updater.base import Updater

from depthcore.exact import online
from depthcore.problem import frames, predictive
from depthcore.stonesoup.models import DepthStep


class ExactState(GaussianState):
    """The exact posterior in Stone Soup: its mean and covariance, and the filter that holds it.

    Built by the user as the prior: ``ExactState(prior_mean, prior_cov,
    timestamp=t0)`` (the Gaussian of the state at ``t0``); the predictor and
    updater fill the rest (see the module docstring).
    """

    filter: online.Online = Property(
        default=None, doc="The exact filter after its last bearing; ``None`` before the first."
    )
    pending: tuple = Property(
        default=(), doc="The depth steps predicted since the filter's last frame."
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
    """A Gaussian moved by a step ``s``: ``F m + e s``, ``F P F^T + diag(0, 0, q**2 s)``.

    Eqs. (1), (9) with the step ``s`` (:mod:`depthcore.problem.frames`); exact,
    since the motion is affine.

    Returns
    -------
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
    """
    F = frames.transition(step)
    m = F @ np.asarray(mean, dtype=float).reshape(3) + [0.0, step, 0.0]
    P = F @ np.asarray(cov, dtype=float) @ F.T
    P[2, 2] += float(frames.velocity_variance(process_noise, step))
    return m, 0.5 * (P + P.T)


def _run_through(filter_: online.Online, steps) -> online.Online:
    """A copy of the filter run through ``steps`` with no bearing (missing frames)."""
    moved = copy.deepcopy(filter_)
    for s in steps:
        moved.update(np.nan, step=s)
    return moved


class ExactPredictor(Predictor):
    """Stone Soup's predictor for the exact filter: moves an :class:`ExactState` by the depth step.

    ``transition_model`` is a :class:`~depthcore.stonesoup.models.DepthStep`
    (its :meth:`~depthcore.stonesoup.models.DepthStep.step` turns the time
    interval into the depth travelled); there is no control model.
    """

    transition_model: DepthStep = Property(doc="The motion with a depth step.")

    def predict(self, prior, timestamp=None, **kwargs) -> ExactPrediction:
        """The prior predicted to ``timestamp`` (see the module docstring).

        Parameters
        ----------
        prior : ExactState
        timestamp : datetime.datetime or None
            ``None`` (or a prior without one): one step of ``depth_per_step``.

        Returns
        -------
        ExactPrediction
        """
        if not isinstance(prior, ExactState):
            raise ValueError(f"prior must be an ExactState, got {type(prior).__name__}")
        interval = (
            None if timestamp is None or prior.timestamp is None else timestamp - prior.timestamp
        )
        s = self.transition_model.step(interval)
        q = self.transition_model.process_noise
        pending = prior.pending + ((s,) if s > 0 else ())
        if prior.filter is None:
            mean, cov = moved_gaussian(prior.state_vector, prior.covar, s, q)
            pending = ()
        elif pending == prior.pending:
            mean, cov = prior.state_vector, prior.covar
        else:
            moved = _run_through(prior.filter, pending).current
            mean, cov = moved.mean, moved.cov
        return Prediction.from_state(
            prior,
            np.asarray(mean, dtype=float).reshape(3, 1),
            np.asarray(cov, dtype=float),
            timestamp=timestamp,
            filter=prior.filter,
            pending=pending,
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
    ``rtol``: the exact filter's quadrature tolerance.
    """

    measurement_model: object = Property(
        default=None, doc="The bearing's model, used for a detection that carries none."
    )
    gate: float = Property(default=None, doc="A tail probability in (0, 1), or ``None``.")
    rtol: float = Property(default=1e-10, doc="The depth quadrature's tolerance.")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.gate = predictive.gate(self.gate)

    def _rho(self, detection) -> float:
        bearing = self._check_measurement_model(detection.measurement_model)
        covar = np.asarray(bearing.covar(), dtype=float)
        if covar.shape != (1, 1):
            raise ValueError(
                f"measurement_model must see one bearing (noise_covar [[rho**2]]), got a "
                f"covariance of shape {covar.shape}"
            )
        return float(np.sqrt(covar[0, 0]))

    def predict_measurement(self, predicted_state, measurement_model=None, **kwargs):
        """Refused: the exact filter's predictive bearing is a mixture, not a Gaussian.

        Its density at the bearing seen and its tail probability are in the
        update's ``estimate`` (``log_predictive``, ``tail``).
        """
        raise ValueError(
            "predicted_state: the exact filter's predictive bearing is a mixture over depth, "
            "not a Gaussian; its density and tail at a detection are in update().estimate"
        )

    def update(self, hypothesis, **kwargs) -> ExactUpdate:
        """The posterior after the hypothesis's detection (see the module docstring).

        Parameters
        ----------
        hypothesis : stonesoup.types.hypothesis.SingleHypothesis
            Its prediction an :class:`ExactPrediction`, its measurement a
            detection of one bearing.

        Returns
        -------
        ExactUpdate
        """
        prediction, detection = hypothesis.prediction, hypothesis.measurement
        if not isinstance(prediction, ExactState):
            raise ValueError(
                f"hypothesis: its prediction must be an ExactPrediction, got "
                f"{type(prediction).__name__}"
            )
        rho = self._rho(detection)
        mu = float(np.asarray(detection.state_vector, dtype=float).reshape(-1)[0])
        if prediction.filter is None:
            model = getattr(prediction, "transition_model", None)
            q = 0.0 if model is None else model.process_noise
            filter_ = online.Online(
                np.asarray(prediction.state_vector, dtype=float)[:, 0],
                np.asarray(prediction.covar, dtype=float),
                rho,
                process_noise=q,
                gate=self.gate,
                rtol=self.rtol,
            )
            estimate = filter_.update(mu)
        else:
            if not prediction.pending:
                raise ValueError(
                    "hypothesis: its prediction has not moved since the last bearing (a zero "
                    "step); the exact filter takes one bearing per frame"
                )
            filter_ = _run_through(prediction.filter, prediction.pending[:-1])
            estimate = filter_.update(mu, rho=rho, step=prediction.pending[-1])
        return Update.from_state(
            prediction,
            estimate.mean.reshape(3, 1),
            estimate.cov,
            timestamp=detection.timestamp,
            filter=filter_,
            pending=(),
            estimate=estimate,
            hypothesis=hypothesis,
        )
