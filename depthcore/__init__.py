"""depthcore: the filters of "Filter Based Estimates of Depth", computed exactly.

A point translates in the (x, y) plane and is seen through three noisy image
measurements ``mu_i = x_i / y_i + w_i``. The package computes the three
estimates of its state that the paper compares: the optimal Bayes filter
(:mod:`depthcore.optimal`), the second-order Gaussian approximation
(:mod:`depthcore.second_order`) and the extended Kalman filter
(:mod:`depthcore.ekf`), with their depth and velocity marginals.
"""

from .ekf import ekf
from .gaussian import Gaussian, paper_prior
from .optimal import marginals as optimal_marginals
from .second_order import noise_free_state, second_order

__version__ = "0.1.0"

__all__ = [
    "Gaussian",
    "__version__",
    "ekf",
    "noise_free_state",
    "optimal_marginals",
    "paper_prior",
    "second_order",
]
