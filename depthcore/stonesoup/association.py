"""The exact filter's predictive bearing in Stone Soup's data association: distance, PDA, JPDA.

Recommended import: ``from depthcore.stonesoup import association``.

Stone Soup's hypothesisers ask the updater for a measurement prediction
(``predict_measurement``) and score each detection against it: the
``DistanceHypothesiser`` by a ``Measure`` (Mahalanobis by default), the
``PDAHypothesiser`` (and so JPDA) by the Gaussian density of the detection
under the prediction's mean and covariance. The exact filter's predictive
bearing is not a Gaussian: given the depth ``y_j`` of node ``j`` it is
``N(x_j / y_j, a_j / y_j**2 + rho**2)``, and over the nodes a mixture
(:mod:`depthcore.exact.online`), skewed, with heavy tails where the depth may
be small. Here:

* :func:`predict_bearing` (the exact updater's ``predict_measurement``) gives
  an :class:`ExactMeasurementPrediction`: a Stone Soup Gaussian measurement
  prediction whose mean, covariance and cross-covariance are the exact
  predictive's moments (the mixture over the depth nodes,
  :meth:`depthcore.exact.online.Online.predictive_moments`), for Stone Soup's
  Gaussian measures; and whose :meth:`~ExactMeasurementPrediction.log_predictive` and
  :meth:`~ExactMeasurementPrediction.tail` are the exact predictive's log
  density and two-sided tail probability at a detection
  (:mod:`depthcore.problem.predictive`).
* :class:`ExactMahalanobis`, a measure for Stone Soup's
  ``DistanceHypothesiser``: the normal quantile of the exact two-sided tail
  probability, ``d = Phi^-1(1 - p / 2)``, which is the Mahalanobis distance
  when the predictive is Gaussian; a gate ``missed_distance = d`` keeps a
  detection with the exact probability ``2 Phi(d) - 1``.
* :class:`ExactPDAHypothesiser`, Stone Soup's ``PDAHypothesiser`` with the
  exact density in the association probabilities,
  ``beta_i ∝ P_D p(z_i) / lambda`` (missed: ``1 - P_D P_G``), and the gate
  on the exact tail: a detection is inside when its tail probability is at
  least ``1 - P_G``, a region that holds the true detection with probability
  ``P_G`` exactly. Stone Soup's ``JPDA`` takes it as its hypothesiser.
* :class:`ExactPDAUpdater`: each detection's hypothesis updated by the exact
  filter and the hypotheses merged as Gaussians.

Where the answer stops being exact. Each hypothesis's update is exact, and
the merged mean and covariance are the exact moments of the PDA posterior, the
mixture of the hypotheses' exact posteriors with their association
probabilities. But the merged state is a Gaussian of those moments: the exact
filter starts again from it at the next frame, and the mixture's shape (the
skew in depth, the spread between hypotheses) is lost there. A frame whose
association is certain (one hypothesis with all the weight) keeps its exact
state. Stone Soup's ``JPDA`` with its ``MultiTargetMixtureTracker`` merges
the same way, and the exact predictor starts from its merged Gaussian. A
single-hypothesis association (the distance hypothesiser with a global
nearest neighbour) keeps the exact filter exact given its associations.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtri
from stonesoup.base import Property
from stonesoup.functions import gm_reduce_single
from stonesoup.hypothesiser.probability import PDAHypothesiser
from stonesoup.measures import Mahalanobis, Measure
from stonesoup.types.array import CovarianceMatrix, StateVectors
from stonesoup.types.detection import MissedDetection
from stonesoup.types.hypothesis import SingleProbabilityHypothesis
from stonesoup.types.multihypothesis import MultipleHypothesis
from stonesoup.types.numeric import Probability
from stonesoup.types.prediction import MeasurementPrediction
from stonesoup.types.state import GaussianState

from depthcore.problem import model
from depthcore.stonesoup.exact import ExactUpdater, exact_update, last_state


class ExactBearing(GaussianState):
    """The bearing predicted by the exact filter: its moments, and the filter's prediction.

    The state type of :class:`ExactMeasurementPrediction` (Stone Soup makes a
    measurement prediction of a state type).
    """

    prediction: GaussianState = Property(default=None, doc="The predicted state.")
    updater: ExactUpdater = Property(default=None, doc="The exact updater that predicted it.")


class ExactMeasurementPrediction(MeasurementPrediction, ExactBearing):
    """The exact filter's predictive bearing: its moments, and the exact density on request.

    ``state_vector``, ``covar`` and ``cross_covar`` are the exact predictive's
    mean, variance and covariance with the state (:func:`predict_bearing`);
    :meth:`log_predictive` and :meth:`tail` are its density and tail at a detection.
    """

    cross_covar: CovarianceMatrix = Property(
        default=None, doc="The state-bearing cross-covariance, shape (3, 1)."
    )

    def log_predictive(self, detection) -> float:
        """The exact predictive's log density at the detection's bearing (Eq. (16)'s integrand).

        The log of ``p(mu_k | mu_1 .. mu_{k-1})``, the mixture over the depth
        nodes (:meth:`depthcore.stonesoup.exact.ExactUpdater.predictive_at`,
        whose run an update with this detection reuses).
        """
        return self.updater.predictive_at(self.prediction, detection).log_predictive

    def tail(self, detection) -> float:
        """The exact predictive's two-sided tail probability at the detection's bearing."""
        return self.updater.predictive_at(self.prediction, detection).tail


def predict_bearing(updater, predicted_state, measurement_model=None, measurement_noise=True):
    """The exact updater's measurement prediction (see the module docstring).

    Its mean, covariance and cross-covariance are the exact predictive's
    (:meth:`depthcore.exact.online.Online.predictive_moments`: the moments of the
    mixture over the depth nodes, with the state's covariance with the bearing), of the
    prediction's filter moved by its step, or of the filter started on a Gaussian
    prediction (:meth:`depthcore.stonesoup.exact.ExactUpdater.start`).

    Parameters
    ----------
    updater : depthcore.stonesoup.exact.ExactUpdater
    predicted_state : stonesoup.types.state.GaussianState or Track
        An exact prediction, or any Gaussian (a Gaussian prior).
    measurement_model : depthcore.stonesoup.models.TangentBearing or None
        ``None``: the updater's.
    measurement_noise : bool
        Whether the covariance includes the bearing's noise ``rho**2``.

    Returns
    -------
    ExactMeasurementPrediction
    """
    state = last_state(predicted_state, "predicted_state")
    rho = updater.rho(measurement_model)
    m = np.asarray(state.state_vector, dtype=float)[:, 0]
    if not m[1] > 0:
        raise ValueError(
            f"predicted_state: its mean depth must be positive (in front of the camera), got "
            f"{m[1]:.6g}"
        )
    overflow = (
        "predicted_state: its bearing's mean or variance overflows (a state of depth "
        f"{m[1]:.6g} and lateral position {m[0]:.6g})"
    )
    with np.errstate(over="ignore", divide="ignore", invalid="ignore", under="ignore"):
        if not (np.isfinite(m[0] / m[1]) and np.all(np.isfinite(model.observation_vector(m)))):
            raise ValueError(overflow)
    base = getattr(state, "filter", None)
    try:
        if base is None:
            moments = updater.start(state, rho).predictive_moments(rho=rho)
        else:
            moments = base.predictive_moments(step=state.step, rho=rho)
    except ValueError:
        raise ValueError(overflow) from None
    covar = moments.cov - (0.0 if measurement_noise else rho * rho)
    return ExactMeasurementPrediction(
        moments.mean[:, None],
        covar,
        timestamp=state.timestamp,
        cross_covar=moments.cross,
        prediction=state,
        updater=updater,
    )


class ExactMahalanobis(Measure):
    """The normal quantile of the exact predictive's two-sided tail: Mahalanobis when Gaussian.

    ``d = Phi^-1(1 - p / 2)``, ``p`` the two-sided tail probability of the
    detection under an :class:`ExactMeasurementPrediction` (infinite where
    ``p`` underflows to 0); for any other measurement prediction, Stone
    Soup's ``Mahalanobis``.
    """

    def __call__(self, state1, state2):
        """The distance of the detection ``state2`` from the measurement prediction ``state1``."""
        if isinstance(state1, ExactMeasurementPrediction):
            return float(ndtri(1.0 - 0.5 * state1.tail(state2)))
        return Mahalanobis()(state1, state2)


class ExactPDAHypothesiser(PDAHypothesiser):
    """Stone Soup's PDA hypothesiser with the exact predictive density and gate.

    ``updater`` must be an :class:`~depthcore.stonesoup.exact.ExactUpdater`
    and ``clutter_spatial_density`` (``lambda``, false detections per unit of
    bearing) given: Stone Soup's estimate of it from the gate's volume is a
    Gaussian's. See the module docstring.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if not isinstance(self.updater, ExactUpdater):
            raise ValueError(f"updater must be an ExactUpdater, got {type(self.updater).__name__}")
        if self.clutter_spatial_density is None or not self.clutter_spatial_density > 0:
            raise ValueError(
                "clutter_spatial_density must be given, > 0 (false detections per unit of "
                f"bearing), got {self.clutter_spatial_density!r}"
            )

    def hypothesise(self, track, detections, timestamp, **kwargs):
        """A missed-detection hypothesis and one per gated detection, with their probabilities.

        Parameters
        ----------
        track : stonesoup.types.track.Track
        detections : set of stonesoup.types.detection.Detection
        timestamp : datetime.datetime

        Returns
        -------
        stonesoup.types.multihypothesis.MultipleHypothesis
        """
        prob_detect, prob_gate = float(self.prob_detect), float(self.prob_gate)
        prediction = self.predictor.predict(track, timestamp=timestamp)
        hypotheses = [
            SingleProbabilityHypothesis(
                prediction,
                MissedDetection(timestamp=timestamp),
                Probability(1.0 - prob_detect * prob_gate),
            )
        ]
        for detection in detections:
            predicted = self.predictor.predict(track, timestamp=detection.timestamp)
            measured = self.updater.predict_measurement(predicted, detection.measurement_model)
            if measured.tail(detection) < 1.0 - prob_gate and not self.include_all:
                continue
            log_p = measured.log_predictive(detection)
            probability = Probability(
                log_p + np.log(prob_detect / self.clutter_spatial_density), log_value=True
            )
            hypotheses.append(
                SingleProbabilityHypothesis(predicted, detection, probability, measured)
            )
        return MultipleHypothesis(hypotheses, normalise=self.normalise)


class ExactPDAUpdater(ExactUpdater):
    """The exact updater for PDA's hypotheses: each updated exactly, merged as Gaussians.

    ``update`` takes a Stone Soup ``MultipleHypothesis`` (of
    :class:`ExactPDAHypothesiser`, ``PDA`` or ``JPDA``); a single hypothesis
    as :class:`~depthcore.stonesoup.exact.ExactUpdater` does. Where the answer
    stops being exact: see the module docstring.
    """

    def update(self, hypothesis, **kwargs):
        """The merged posterior of the hypotheses (see the module docstring).

        Returns
        -------
        ExactUpdate or ExactPrediction
            The one hypothesis's exact state when it has all the weight (the
            prediction when that is the missed detection); otherwise an
            :class:`~depthcore.stonesoup.exact.ExactUpdate` without a filter,
            the Gaussian of the merged moments.
        """
        if not isinstance(hypothesis, MultipleHypothesis):
            return super().update(hypothesis, **kwargs)
        hypotheses = list(hypothesis)
        if not hypotheses:
            raise ValueError("hypothesis: no hypotheses to merge")
        weights = np.array([float(h.probability) for h in hypotheses])
        if not (np.all(np.isfinite(weights)) and np.all(weights >= 0) and weights.sum() > 0):
            raise ValueError("hypothesis: the probabilities must be finite, >= 0, not all 0")
        states = [ExactUpdater.update(self, h) if h else h.prediction for h in hypotheses]
        if np.count_nonzero(weights) == 1:
            return states[int(np.flatnonzero(weights)[0])]
        means = StateVectors([s.state_vector for s in states])
        covars = np.stack([np.asarray(s.covar, dtype=float) for s in states], axis=2)
        mean, covar = gm_reduce_single(means, covars, weights / weights.sum())
        present = next((h.measurement for h in hypotheses if h), hypotheses[0].measurement)
        return exact_update(hypothesis, hypotheses[0].prediction, mean, covar, present.timestamp)
