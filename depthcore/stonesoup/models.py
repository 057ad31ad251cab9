"""The paper's motion and bearing as Stone Soup models: the depth step and the tangent bearing.

Recommended import: ``from depthcore.stonesoup import models``.

Stone Soup (``stonesoup``) describes a tracking problem by a transition model
(how a state moves between timestamps) and a measurement model (what a sensor
sees of it). This module writes the paper's two:

* :class:`DepthStep`, the motion with a step ``s`` (Eq. (1) with ``s`` in
  place of 1, :func:`depthcore.problem.model.G`): ``y <- y + s``,
  ``x <- x + s v``, ``v <- v + a``, ``a ~ N(0, q**2 |s|)``
  (:func:`depthcore.problem.frames.velocity_variance`). The step ``s`` is the
  depth's signed change over Stone Soup's ``time_interval``: the interval in
  seconds times a speed (depth per second), or a fixed depth per prediction.
  Positive: the point recedes (the camera moves away from it); negative: it
  approaches (the camera moves towards it). The point moves on a straight
  line, so ``x <- x + s v`` holds for either sign, and the velocity's noise
  grows with the distance moved, ``|s|``, never with ``s`` itself; a negative
  ``time_interval`` (a prediction back in time) moves it the other way.
* :class:`TangentBearing`, the bearing ``mu = x / y + w``, ``w ~ N(0, rho**2)``
  (Eq. (4)), with its gradient ``(1 / y, -x / y**2, 0)`` (Eq. (11)); a state
  behind the camera (``y <= 0``) has likelihood 0 (the support of the exact
  filter, :func:`depthcore.exact.optimal.run`).

The motion is affine, ``F(s) x + e s`` with ``e = (0, 1, 0)`` (Eq. (9)):
Stone Soup's ``stonesoup.predictor.kalman.KalmanPredictor`` predicts the
mean as ``F x`` alone and would drop the depth's ``+ s``, so
:class:`DepthStep` is not a Stone Soup ``LinearModel``: the
``stonesoup.predictor.kalman.ExtendedKalmanPredictor`` (which moves the
mean by :meth:`DepthStep.function` and the covariance by
:meth:`DepthStep.jacobian`) and the
``stonesoup.predictor.kalman.UnscentedKalmanPredictor`` predict it
exactly, and the particle predictor moves each particle by it.
"""

from __future__ import annotations

import datetime

import numpy as np
from stonesoup.base import Property
from stonesoup.models.base import GaussianModel
from stonesoup.models.measurement.base import MeasurementModel
from stonesoup.models.transition.base import TransitionModel
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.numeric import Probability

from depthcore.problem import checks, frames, model

_LOG_2PI = float(np.log(2.0 * np.pi))


def vectors(values) -> StateVector | StateVectors:
    """Stone Soup's vectors of ``values`` (shape (d, n)): a StateVector when ``n == 1``."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    return values.view(StateVector) if values.shape[1] == 1 else values.view(StateVectors)


def states_of(state) -> np.ndarray:
    """The state vectors of a Stone Soup state (or an array), shape (3, n), as floats."""
    values = np.asarray(getattr(state, "state_vector", state), dtype=float)
    values = values.reshape(3, -1) if values.ndim == 1 else values
    if values.shape[0] != 3:
        raise ValueError(f"state must have 3 rows (x, y, v), got shape {values.shape}")
    return values


#: The largest process noise ``q`` whose square is a finite double.
MAX_PROCESS_NOISE = 1e150


def velocity_variance(process_noise: float, step: float) -> float:
    """``q**2 |s|``: the velocity's variance added over a signed step ``s`` (Eq. (1) with noise).

    :func:`depthcore.problem.frames.velocity_variance` of the distance moved,
    ``|s|``: the same whichever way the camera moves. Refused where it
    overflows.
    """
    with np.errstate(over="ignore"):
        var = float(frames.velocity_variance(process_noise, abs(float(step))))
    if not np.isfinite(var):
        raise ValueError(
            f"time_interval: the velocity's variance q**2 |s| over a step of {step:.6g} with "
            f"q = {process_noise:.6g} overflows"
        )
    return var


def _nonzero(value, name: str) -> float:
    """A finite, nonzero number (a signed step or speed)."""
    x = checks.number(value, name)
    if x == 0:
        raise ValueError(
            f"{name} must be nonzero: positive while the point recedes, negative while the "
            "camera approaches it"
        )
    return x


def _draw(random_state, scale, size) -> np.ndarray:
    """Normal draws of SD ``scale`` from a numpy Generator (or RandomState), shape ``size``."""
    if random_state is None:
        random_state = np.random.default_rng()
    return random_state.normal(0.0, 1.0, size) * scale


class DepthStep(TransitionModel, GaussianModel):
    """The motion with a depth step ``s``: ``(x + s v, y + s, v + a)``, ``a ~ N(0, q**2 |s|)``.

    Eq. (1) with the step ``s`` in place of 1 and process noise on the
    velocity (:mod:`depthcore.problem.frames`). The step over a prediction is
    :meth:`step`: ``speed`` times Stone Soup's ``time_interval`` in seconds
    when a speed is given; otherwise ``depth_per_step`` for every prediction
    over a positive (or unknown, ``None``) interval, minus it over a negative
    one, and 0 over a zero one (so the prior at the first detection's
    timestamp does not move). The step is signed: a negative ``speed`` or
    ``depth_per_step`` is a camera that approaches the point, and the
    velocity's noise grows with ``|s|`` either way.

    The seed (Stone Soup's ``seed`` property) starts a numpy Generator for
    :meth:`rvs`; pass ``random_state=`` (a Generator) to draw from your own.
    """

    process_noise: float = Property(
        default=0.0, doc="``q >= 0``: the SD of the velocity's change over a unit of depth."
    )
    speed: float = Property(
        default=None,
        doc="The depth's signed change per second of ``time_interval`` (negative: the "
        "camera approaches); ``None``: ``depth_per_step``.",
    )
    depth_per_step: float = Property(
        default=1.0,
        doc="The signed step ``s`` of each prediction when ``speed`` is ``None``.",
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.process_noise = checks.nonnegative_scalar(self.process_noise, "process_noise")
        if self.process_noise > MAX_PROCESS_NOISE:
            raise ValueError(
                f"process_noise must be at most {MAX_PROCESS_NOISE:g} (its square a finite "
                f"double), got {self.process_noise:g}"
            )
        if self.speed is not None:
            self.speed = _nonzero(self.speed, "speed")
        self.depth_per_step = _nonzero(self.depth_per_step, "depth_per_step")
        self.random_state = np.random.default_rng(self.seed) if self.seed is not None else None

    @property
    def ndim_state(self) -> int:
        """3: the state ``(x, y, v)``."""
        return 3

    def step(self, time_interval=None) -> float:
        """The depth's signed change over ``time_interval`` (see the class docstring).

        Parameters
        ----------
        time_interval : datetime.timedelta or None

        Returns
        -------
        float
            Finite; negative where the point approaches the camera.
        """
        if time_interval is None:
            if self.speed is not None:
                raise ValueError(
                    "time_interval: a speed needs timestamps on the states and detections"
                )
            return self.depth_per_step
        if not isinstance(time_interval, datetime.timedelta):
            raise ValueError(
                f"time_interval must be a datetime.timedelta or None, got "
                f"{type(time_interval).__name__}"
            )
        seconds = time_interval.total_seconds()
        if self.speed is None:
            return float(np.sign(seconds)) * self.depth_per_step
        s = self.speed * seconds
        if not np.isfinite(s):
            raise ValueError(
                f"time_interval: {seconds:g} s at speed {self.speed:g} is a step beyond the "
                "floating-point range"
            )
        return s

    def matrix(self, time_interval=None, **kwargs) -> np.ndarray:
        """The linear part ``F(s) = [[1, 0, s], [0, 1, 0], [0, 0, 1]]`` (Eq. (9)), shape (3, 3)."""
        return frames.transition(self.step(time_interval))

    def offset(self, time_interval=None, **kwargs) -> StateVector:
        """The constant part ``e s = (0, s, 0)`` (Eq. (9)), shape (3, 1)."""
        return StateVector([0.0, self.step(time_interval), 0.0])

    def jacobian(self, state, time_interval=None, **kwargs) -> np.ndarray:
        """The motion's gradient, ``F(s)`` at every state, shape (3, 3)."""
        return self.matrix(time_interval)

    def function(self, state, noise=False, time_interval=None, **kwargs):
        """Move states by the step: ``F(s) x + e s`` plus the velocity noise (Eq. (1)).

        Parameters
        ----------
        state : State or array_like, state vectors of shape (3, n)
        noise : bool or array_like, shape (3, n)
            ``True`` adds a draw of :meth:`rvs`; an array is added as it is.
        time_interval : datetime.timedelta or None

        Returns
        -------
        StateVector (n = 1) or StateVectors, shape (3, n)
        """
        x = states_of(state)
        s = self.step(time_interval)
        moved = np.stack([x[0] + s * x[2], x[1] + s, x[2]])
        if isinstance(noise, bool) or noise is None:
            noise = self.rvs(x.shape[1], time_interval=time_interval, **kwargs) if noise else 0.0
        return vectors(moved + np.asarray(noise, dtype=float))

    def covar(self, time_interval=None, **kwargs) -> CovarianceMatrix:
        """The motion's noise covariance ``diag(0, 0, q**2 |s|)``, shape (3, 3)."""
        return CovarianceMatrix(np.diag([0.0, 0.0, self.velocity_variance(time_interval)]))

    def velocity_variance(self, time_interval=None) -> float:
        """``q**2 |s|``, the velocity's variance added over ``time_interval`` (never negative)."""
        return velocity_variance(self.process_noise, self.step(time_interval))

    def rvs(self, num_samples=1, random_state=None, time_interval=None, **kwargs):
        """Draws of the motion's noise: zeros in ``x`` and ``y``, ``N(0, q**2 |s|)`` in ``v``.

        Returns
        -------
        StateVector (``num_samples == 1``) or StateVectors, shape (3, num_samples)
        """
        rng = random_state if random_state is not None else self.random_state
        sd = float(np.sqrt(self.velocity_variance(time_interval)))
        noise = np.zeros((3, int(num_samples)))
        noise[2] = _draw(rng, sd, int(num_samples))
        return vectors(noise)

    def logpdf(self, state1, state2, time_interval=None, **kwargs):
        """Log density of ``state1`` after a step from ``state2``, log space.

        Only the velocity is random: ``x`` and ``y`` move deterministically, so
        the density is that of the velocity, ``N(v1; v2, q**2 |s|)``, where
        ``state1``'s ``x`` and ``y`` are the move's (to a relative 1e-12, the
        rounding of :meth:`function`), and ``-inf`` elsewhere. With ``q = 0``
        or ``s = 0`` the motion is deterministic and has no density: refused.

        Returns
        -------
        float (one pair) or ndarray, shape (n,)
        """
        var = self.velocity_variance(time_interval)
        if var == 0:
            raise ValueError(
                "process_noise: with q = 0 (or a zero step) the motion is deterministic and "
                "has no density"
            )
        after = states_of(state1)
        moved = states_of(self.function(state2, time_interval=time_interval))
        on_path = np.all(np.isclose(after[:2], moved[:2], rtol=1e-12, atol=1e-12), axis=0)
        dv = after[2] - moved[2]
        log_p = np.where(on_path, -0.5 * (_LOG_2PI + np.log(var) + dv * dv / var), -np.inf)
        return float(log_p[0]) if log_p.size == 1 else log_p

    def pdf(self, state1, state2, time_interval=None, **kwargs):
        """:meth:`logpdf` as a Stone Soup ``stonesoup.types.numeric.Probability``."""
        return Probability.from_log_ufunc(self.logpdf(state1, state2, time_interval=time_interval))


class TangentBearing(MeasurementModel, GaussianModel):
    """The bearing ``mu = x / y + w``, ``w ~ N(0, rho**2)`` (Eq. (4)), seen in front of the camera.

    ``noise_covar`` is ``[[rho**2]]`` (Stone Soup's convention; :attr:`rho` is
    its root). A detection may carry its own model, and so its own ``rho``
    (noise per frame). The likelihood is 0 for a state with depth ``y <= 0``
    (:func:`depthcore.problem.model.log_likelihood` with ``front=True``).
    This is the tangent of the bearing, not Stone Soup's angle models
    (``Cartesian2DToBearing``, ``atan2``).

    The seed (Stone Soup's ``seed`` property) starts a numpy Generator for
    :meth:`rvs`. With ``common_draws`` every call without a ``random_state``
    starts from the seed again, so that every caller gets the same draws
    (common random numbers): a particle filter's predicted bearings then do
    not depend on the order in which a Stone Soup tracker, whose tracks are a
    set, visits the tracks that score a detection.
    """

    ndim_state: int = Property(default=3, doc="3: the state ``(x, y, v)``.")
    common_draws: bool = Property(
        default=False, doc="Whether each call of :meth:`rvs` starts from the seed."
    )
    mapping: tuple = Property(default=(0, 1), doc="The state's ``x`` and ``y`` are seen.")
    noise_covar: CovarianceMatrix = Property(doc="``[[rho**2]]``, the bearing's noise variance.")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        covar = checks.finite_array(self.noise_covar, "noise_covar")
        if covar.size != 1 or not covar.reshape(-1)[0] > 0:
            raise ValueError(f"noise_covar must be [[rho**2]] with rho > 0, got {covar.tolist()!r}")
        if self.ndim_state != 3 or tuple(self.mapping) != (0, 1):
            raise ValueError("ndim_state and mapping must be 3 and (0, 1): the state (x, y, v)")
        self.noise_covar = CovarianceMatrix(covar.reshape(1, 1))
        if self.common_draws and self.seed is None:
            raise ValueError("common_draws: a seed is needed to start every call from")
        self.random_state = np.random.default_rng(self.seed) if self.seed is not None else None

    @property
    def ndim_meas(self) -> int:
        """1: one bearing."""
        return 1

    @property
    def rho(self) -> float:
        """The bearing's noise SD, ``sqrt(noise_covar)``."""
        return float(np.sqrt(self.noise_covar[0, 0]))

    def covar(self, **kwargs) -> CovarianceMatrix:
        """``[[rho**2]]``, shape (1, 1)."""
        return self.noise_covar

    def function(self, state, noise=False, **kwargs):
        """The bearing ``x / y`` of states (shape (3, n)), plus noise; shape (1, n).

        ``noise=True`` adds a draw of :meth:`rvs`; an array (1, n) is added as it is.
        """
        x = states_of(state)
        bearing = model.project(x.T)[None, :]
        if isinstance(noise, bool) or noise is None:
            noise = self.rvs(x.shape[1], **kwargs) if noise else 0.0
        return vectors(bearing + np.asarray(noise, dtype=float))

    def jacobian(self, state, **kwargs) -> np.ndarray:
        """Eq. (11): ``h = (1 / y, -x / y**2, 0)`` at the state, shape (1, 3)."""
        return model.observation_vector(states_of(state)[:, 0])[None, :]

    def rvs(self, num_samples=1, random_state=None, **kwargs):
        """Draws of the bearing's noise ``N(0, rho**2)``, shape (1, num_samples)."""
        rng = random_state if random_state is not None else self.random_state
        if random_state is None and self.common_draws:
            rng = np.random.default_rng(self.seed)
        return vectors(_draw(rng, self.rho, (1, int(num_samples))))

    def logpdf(self, state1, state2, **kwargs):
        """Eq. (4): the log likelihood of the bearing ``state1`` at states ``state2`` (front only).

        Returns
        -------
        float (one state) or ndarray, shape (n,)
        """
        mu = float(np.asarray(getattr(state1, "state_vector", state1), dtype=float).reshape(-1)[0])
        log_l = model.log_likelihood(mu, states_of(state2).T, self.rho, front=True)
        return float(log_l[0]) if log_l.size == 1 else log_l

    def pdf(self, state1, state2, **kwargs):
        """:meth:`logpdf` as a Stone Soup ``stonesoup.types.numeric.Probability``."""
        return Probability.from_log_ufunc(self.logpdf(state1, state2))
