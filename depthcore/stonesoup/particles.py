"""Stone Soup's particle filter on the paper's problem: a start from one bearing, and resampling.

Recommended import: ``from depthcore.stonesoup import particles``.

Stone Soup's ``ParticlePredictor`` and ``ParticleUpdater`` run on
:class:`~depthcore.stonesoup.models.DepthStep` and
:class:`~depthcore.stonesoup.models.TangentBearing` as they are. What a
multi-target tracker adds, here with numpy Generators (Stone Soup's own
resamplers and particle initiators draw from numpy's global state):

* :class:`BearingParticleInitiator`, a track per detection, its particles
  drawn by importance sampling from the posterior after that one bearing: the
  depth and velocity from the prior, the lateral position from the bearing,
  ``x = y (mu + rho e)``, ``e ~ N(0, 1)``, weighted by
  ``p(x | y, v) y`` (the prior's conditional density of ``x`` over the
  proposal's, the bearing's likelihood cancelling but for its Jacobian ``y``);
  a depth at or behind the camera gets weight 0;
* :class:`SystematicResampler`, systematic resampling
  (:func:`depthcore.particles.resampling.systematic`) when the effective sample
  size falls below a fraction of the particles.

Each draws from a Generator seeded by its seed and by what it is given (the
detection, the particles), not from one stream: a Stone Soup tracker keeps
its tracks in a set and visits them in an order that changes from run to
run, and the draws then do not depend on it.
"""

from __future__ import annotations

import hashlib

import numpy as np
from stonesoup.base import Property
from stonesoup.initiator.base import ParticleInitiator
from stonesoup.resampler.base import Resampler
from stonesoup.types.array import StateVectors
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState, ParticleState
from stonesoup.types.track import Track
from stonesoup.types.update import ParticleStateUpdate

from depthcore.particles import resampling
from depthcore.problem import checks
from depthcore.stonesoup.exact import bearing_of

_LOG_2PI = float(np.log(2.0 * np.pi))


def keyed_generator(seed: int, *arrays) -> np.random.Generator:
    """A Generator seeded by ``seed`` and the bytes of ``arrays`` (the same for the same inputs).

    Parameters
    ----------
    seed : int
        >= 0.
    *arrays : array_like
        Converted to float64; their bytes, hashed (BLAKE2b), join the seed.

    Returns
    -------
    numpy.random.Generator
    """
    digest = hashlib.blake2b(digest_size=16)
    for a in arrays:
        digest.update(np.ascontiguousarray(a, dtype=float).tobytes())
    key = np.frombuffer(digest.digest(), dtype=np.uint32).tolist()
    return np.random.default_rng(np.random.SeedSequence([int(seed), *key]))


def _seed(value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"seed must be a non-negative integer, got {value!r}")
    return int(value)


class BearingParticleInitiator(ParticleInitiator):
    """A track per detection, its particles the posterior after that one bearing.

    See the module docstring. ``prior_state`` is the Gaussian of ``(x, y, v)``
    before the bearing; ``measurement_model`` the bearing's model where a
    detection carries none.
    """

    prior_state: GaussianState = Property(doc="The Gaussian prior of (x, y, v).")
    number_particles: int = Property(default=1000, doc="Particles per track.")
    measurement_model: object = Property(
        default=None, doc="The bearing's model, for a detection that carries none."
    )
    seed: int = Property(default=0, doc="Joins each detection in seeding its draws.")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.number_particles = checks.count(self.number_particles, "number_particles")
        self.seed = _seed(self.seed)
        mean = checks.finite_array(
            np.asarray(self.prior_state.state_vector, float).reshape(-1), "prior_state"
        )
        cov = checks.covariances(np.asarray(self.prior_state.covar, dtype=float), "prior_state", 3)
        if mean.shape != (3,):
            raise ValueError(f"prior_state must be (x, y, v), got a mean of shape {mean.shape}")
        self._prior = (mean, cov)

    def particles(self, detection) -> ParticleState:
        """The weighted particles after the detection's bearing alone (see the module docstring).

        Returns
        -------
        stonesoup.types.state.ParticleState
            ``number_particles`` states ``(x, y, v)`` and their log weights,
            normalised; the detection's timestamp.
        """
        mu = bearing_of(detection)
        model = detection.measurement_model or self.measurement_model
        if model is None:
            raise ValueError("measurement_model: the detection carries none and none is given")
        rho = float(np.sqrt(np.asarray(model.covar(), dtype=float).reshape(-1)[0]))
        m, P = self._prior
        rng = keyed_generator(self.seed, [mu, rho], [_seconds(detection.timestamp)])
        n = self.number_particles
        yv = rng.multivariate_normal(m[1:], P[1:, 1:], n)
        y, v = yv[:, 0], yv[:, 1]
        x = y * (mu + rho * rng.standard_normal(n))
        # p(x | y, v) under the prior: Gaussian conditioning on (y, v)
        gain = np.linalg.solve(P[1:, 1:], P[1:, 0])
        cond_mean = m[0] + (yv - m[1:]) @ gain
        cond_var = P[0, 0] - P[0, 1:] @ gain
        log_w = np.full(n, -np.inf)
        front = y > 0
        z2 = (x[front] - cond_mean[front]) ** 2 / cond_var
        log_w[front] = -0.5 * (_LOG_2PI + np.log(cond_var) + z2) + np.log(y[front])
        if not np.any(front):
            raise ValueError(
                "prior_state: none of its depths is in front of the camera; its depth's mean "
                "must be positive"
            )
        log_w -= np.logaddexp.reduce(log_w[front])
        return ParticleState(
            StateVectors(np.stack([x, y, v])), log_weight=log_w, timestamp=detection.timestamp
        )

    def initiate(self, detections, timestamp, **kwargs):
        """One track per detection, its first state the particles after its bearing.

        Returns
        -------
        set of stonesoup.types.track.Track
        """
        tracks = set()
        for detection in detections:
            state = self.particles(detection)
            tracks.add(
                Track(
                    [
                        ParticleStateUpdate(
                            state.state_vector,
                            log_weight=state.log_weight,
                            hypothesis=SingleHypothesis(None, detection),
                            timestamp=detection.timestamp,
                        )
                    ]
                )
            )
        return tracks


def _seconds(timestamp) -> float:
    """A timestamp as seconds since the epoch (0 for none), to key a detection's draws."""
    return 0.0 if timestamp is None else timestamp.timestamp()


class SystematicResampler(Resampler):
    """Systematic resampling when the effective sample size falls below ``threshold`` of N.

    The uniform offset is drawn from a Generator keyed on ``seed`` and the
    particles (:func:`keyed_generator`). ``threshold = 1`` resamples at every
    update.
    """

    seed: int = Property(default=0, doc="Joins the particles in seeding each resampling.")
    threshold: float = Property(default=0.5, doc="The fraction of N below which to resample.")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.seed = _seed(self.seed)
        self.threshold = checks.number(self.threshold, "threshold")
        if not 0.0 < self.threshold <= 1.0:
            raise ValueError(f"threshold must lie in (0, 1], got {self.threshold!r}")

    def resample(self, particles, nparts=None):
        """The particles resampled (equal weights), or as they are above the threshold.

        Parameters
        ----------
        particles : stonesoup.types.state.ParticleState
        nparts : int or None
            Particles after resampling (``None``: as many).

        Returns
        -------
        stonesoup.types.state.ParticleState
        """
        if not isinstance(particles, ParticleState):
            raise ValueError(
                f"particles must be a Stone Soup ParticleState, got {type(particles).__name__}"
            )
        log_w = np.asarray(particles.log_weight, dtype=float)
        n = log_w.size if nparts is None else checks.count(nparts, "nparts")
        ess = float(resampling.effective_sample_size(log_w))
        if nparts is None and ess >= self.threshold * log_w.size:
            return particles
        W = np.exp(log_w - np.logaddexp.reduce(log_w))
        rng = keyed_generator(self.seed, np.asarray(particles.state_vector), log_w)
        index = resampling.systematic(W / W.sum(), rng, n)
        out = particles[index]
        out.log_weight = np.full(n, -np.log(n))
        return out
