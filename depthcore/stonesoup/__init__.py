"""The paper's problem in Stone Soup's own types, for Stone Soup's tracking loops.

* :mod:`~depthcore.stonesoup.models`: the motion with a depth step and the
  tangent bearing as Stone Soup transition and measurement models, for Stone
  Soup's own Kalman and particle filters;
* :mod:`~depthcore.stonesoup.exact`: the exact filter as a Stone Soup predictor
  and updater, on a state that carries the exact posterior and shows its mean
  and covariance;
* :mod:`~depthcore.stonesoup.association`: the exact filter's predictive
  bearing for Stone Soup's data association (distance, PDA, JPDA);
* :mod:`~depthcore.stonesoup.particles`: a start from one bearing and
  resampling for Stone Soup's particle filter in a multi-target tracker;
* :mod:`~depthcore.stonesoup.tracks`: a depthcore track as Stone Soup
  detections (a missed frame without one), a scene of several points with
  clutter as a multi-target tracker reads it, and Stone Soup's tracking loop.

Where a new thing goes: another Stone Soup model of the paper's problem goes in
:mod:`~depthcore.stonesoup.models`; another of depthcore's filters as a
Stone Soup predictor and updater, in a module of its own beside
:mod:`~depthcore.stonesoup.exact`; how a filter's predictive scores
detections, in :mod:`~depthcore.stonesoup.association`; what Stone Soup's
own particle filter needs, in :mod:`~depthcore.stonesoup.particles`; a new
way in from depthcore's arrays, in :mod:`~depthcore.stonesoup.tracks`. This
subpackage needs Stone Soup (the ``depthcore[stonesoup]`` extra); it may
import :mod:`depthcore.problem`, :mod:`depthcore.kalman`,
:mod:`depthcore.exact`, :mod:`depthcore.particles` and
:mod:`depthcore.registry`, and nothing in the rest of the package imports it.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
