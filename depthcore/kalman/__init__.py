"""The Gaussian filters: every filter whose state is one Gaussian, one predict-update loop.

* :mod:`~depthcore.kalman.linear`: the Kalman filter and its smoothers for a
  linear-Gaussian model (textbook 19.2);
* :mod:`~depthcore.kalman.second_order`: the paper's second-order
  approximation, Eqs. (8), (24);
* :mod:`~depthcore.kalman.ekf`: the paper's extended Kalman filter, Eqs.
  (10)-(12), and the predict-update recursion the other Gaussian filters share
  (:func:`~depthcore.kalman.ekf.predict`, :func:`~depthcore.problem.gaussian.run_recursion`);
* :mod:`~depthcore.kalman.ukf`: the unscented Kalman filter (textbook 19.4);
* :mod:`~depthcore.kalman.iterated`: the iterated EKF and its smoother;
* :mod:`~depthcore.kalman.online`: the EKF and the UKF one bearing at a time;
* :mod:`~depthcore.kalman.features`: the same for many features at once, batched;
* :mod:`~depthcore.kalman.spatial`: the EKF, the iterated EKF and the UKF for a
  point in 3-D, seen as bearing pairs, and :mod:`~depthcore.kalman.spatial_inverse`,
  the inverse-depth EKF for it;
* :mod:`~depthcore.kalman.inverse_depth`,
  :mod:`~depthcore.kalman.inverse_depth_ukf`,
  :mod:`~depthcore.kalman.modified_polar`,
  :mod:`~depthcore.kalman.range_ekf`: the tracking literature's
  reparametrised filters.

Where a new thing goes: a new Gaussian filter is one module here, with one
batched function in the registry's calling convention, then its entry in
:mod:`depthcore.registry.filters` and its test. It imports from
:mod:`depthcore.problem` only (and from this family).
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
