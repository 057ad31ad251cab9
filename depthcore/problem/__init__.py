"""The problem: the model, its Gaussians and prior, its experiments, checks and log weights.

The bottom of the house: the model and the primitives every family shares;
nothing here imports another family.

* :mod:`~depthcore.problem.model`: the motion and the bearings, Eqs. (1)-(5),
  (7), (9), (11), (20)-(22), and the N-frame model with process noise;
* :mod:`~depthcore.problem.gaussian`: Gaussian densities on the state, the
  Gaussian filters' results and the paper's prior (Eq. (13));
* :mod:`~depthcore.problem.scenarios`: Figures 2-6 and the numbers the paper
  reports;
* :mod:`~depthcore.problem.checks`: the checks every public function runs on
  its arguments, each refusal one line naming the argument;
* :mod:`~depthcore.problem.weights`: log weights normalised in log space, for
  the particle filters' samples and the exact filter's mixture alike;
* :mod:`~depthcore.problem.depth_prior`: a prior whose depth law is any proper
  density (log-uniform, range, inverse-depth, tabulated), Gaussian given the depth;
* :mod:`~depthcore.problem.frames`: a track's frames as they come (gaps, noise per
  frame, uneven steps), checked once for every filter;
* :mod:`~depthcore.problem.bearing_pairs`: the same for a point in 3-D, seen as
  pairs ``(x / y, h / y)``;
* :mod:`~depthcore.problem.predictive`: a bearing's predictive density and tail
  probability, and the outlier gate;
* :mod:`~depthcore.problem.pair_tail`: a pair's tail under a Gaussian mixture;
* :mod:`~depthcore.problem.signature`: the filters' one calling convention,
  ``(mu, rho, prior_mean, prior_cov, process_noise)``, documented once.

Where a new thing goes: a new motion or measurement model, or a new way to
describe a track's frames, goes here, beside :mod:`~depthcore.problem.model`;
a new experiment of the paper's kind is an entry of
:data:`~depthcore.problem.scenarios.SCENARIOS`.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
