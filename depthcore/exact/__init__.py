"""The exact filter: the posterior computed to stated accuracy, with its error estimate.

* :mod:`~depthcore.exact.quadrature`: the log-depth trapezoid rule with its
  error estimate;
* :mod:`~depthcore.exact.modes`: where the quadrature puts its nodes, each
  interval of the depth about its integrand's mode and width;
* :mod:`~depthcore.exact.cdf`: a marginal's CDF by Gauss-Legendre panels;
* :mod:`~depthcore.exact.optimal`: the paper's optimal filter for three
  frames and its exact marginals, Eqs. (6), (13)-(16);
* :mod:`~depthcore.exact.bank`: for any number of frames, a bank of Kalman
  filters over depth (given the depth, the model is linear);
* :mod:`~depthcore.exact.lateral`: the Kalman filter of the lateral state
  given the depth, written out elementwise for every node at once;
* :mod:`~depthcore.exact.tracks`: a track's frames for the bank (steps,
  noise per frame, gaps);
* :mod:`~depthcore.exact.mixture`: the bank's Gaussians mixed over the depth
  nodes, the exact posterior at frame ``N``;
* :mod:`~depthcore.exact.panels`: the depth quadrature under any prior on the
  depth, Gauss-Legendre panels that end at the prior's edges and kinks;
* :mod:`~depthcore.exact.posterior`: the bank with its depth nodes placed by
  the quadrature, the exact N-frame filter;
* :mod:`~depthcore.exact.spatial`: a point in 3-D, ``(x, y, v, h, w)`` seen as
  bearing pairs, by a bank of four-state Kalman filters over depth;
* :mod:`~depthcore.exact.smoother`: one track frame by frame, filtered,
  fixed-lag and fixed-interval smoothed;
* :mod:`~depthcore.exact.online`: the exact filter one bearing at a time, in
  constant time and memory per frame, with each bearing's predictive report
  and a gate;
* :mod:`~depthcore.exact.online_nodes`: what each node of the online filter
  holds, the plane's Gaussian of ``(x, v)`` or the space's of ``(x, v, h, w)``;
* :mod:`~depthcore.exact.features`: the online filter for many features at
  once, a fixed number of nodes each, every frame one set of array operations;
* :mod:`~depthcore.exact.e_step`: EM's expectations under the exact smoothed
  posterior, for learning the noise levels;
* :mod:`~depthcore.exact.learning`: the bearing noise and the process noise
  learned from tracks by maximum likelihood on the depth quadrature, or by EM
  with the nodes' smoothers as its E-step.

Where a new thing goes: another way to compute the exact posterior, or a new
use of the bank (an online form, a likelihood), goes here. It may import
:mod:`depthcore.problem` and :mod:`depthcore.kalman`, nothing above.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
