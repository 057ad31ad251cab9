"""The particle filters and what they share: resampling, weighted moments, replicas.

* :mod:`~depthcore.particles.resampling`: the effective sample size, the
  resamplers (one signature), weighted moments;
* :mod:`~depthcore.particles.importance`: importance sampling of the state
  from a second-order (Student t) proposal;
* :mod:`~depthcore.particles.resample_move`: the causal bootstrap filter with
  resample-move;
* :mod:`~depthcore.particles.rbpf`: the Rao-Blackwellised particle filter over
  depth, a Kalman filter per particle (textbook 19.5.3);
* :mod:`~depthcore.particles.depth_hypotheses`: MonoSLAM's depth initialisation,
  its deterministic kin: a fixed grid of depths, each with a Kalman filter,
  reweighted by the bearings and collapsed to a Gaussian that the EKF carries on.

Where a new thing goes: a new particle filter is a module here that takes its
randomness from a ``numpy.random.Generator`` or ``SeedSequence`` argument and
resamples through :mod:`~depthcore.particles.resampling`; then its registry
entry and its test. It may import the families below: the problem, the
Gaussian filters (for a proposal) and the exact filter (for a bank).
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
