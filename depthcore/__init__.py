"""depthcore: the filters of "Filter Based Estimates of Depth", computed exactly.

A point translates in the (x, y) plane and is seen through three noisy image
measurements ``mu_i = x_i / y_i + w_i``. The package computes the three
estimates of its state that the paper compares: the optimal Bayes filter
(:mod:`depthcore.optimal`), the second-order Gaussian approximation
(:mod:`depthcore.second_order`) and the extended Kalman filter
(:mod:`depthcore.ekf`), with their depth and velocity marginals.

Modules: :mod:`~depthcore.model` (Eqs. (1)-(4), (9), (11)),
:mod:`~depthcore.second_order` (Eqs. (5), (7), (8)), :mod:`~depthcore.ekf`
(Eqs. (10)-(12)), :mod:`~depthcore.optimal` (Eqs. (6), (13)-(16)),
:mod:`~depthcore.scenarios` (Figures 2-6), :mod:`~depthcore.reproduce` and
:mod:`~depthcore.figures`; beyond the paper, the unscented Kalman filter
(:mod:`~depthcore.ukf`), a particle filter (:mod:`~depthcore.particle`), a
Monte Carlo study (:mod:`~depthcore.study`) and sweeps (:mod:`~depthcore.sweeps`).
"""

from . import ekf, model, optimal, particle, reproduce, scenarios, second_order, ukf
from .gaussian import Gaussian, paper_prior
from .optimal import marginals as optimal_marginals
from .scenarios import SCENARIOS
from .second_order import noise_free_state

__version__ = "0.1.0"

__all__ = [
    "Gaussian",
    "SCENARIOS",
    "__version__",
    "ekf",
    "model",
    "noise_free_state",
    "optimal",
    "optimal_marginals",
    "paper_prior",
    "particle",
    "reproduce",
    "scenarios",
    "second_order",
    "ukf",
]
