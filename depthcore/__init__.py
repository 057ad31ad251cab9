"""depthcore: the filters of "Filter Based Estimates of Depth", computed exactly.

A point translates in the (x, y) plane and is seen through noisy image
measurements ``mu_i = x_i / y_i + w_i``: the paper's three, or any ``N >= 3``
frames up to ``depthcore._checks.MAX_FRAMES`` (1,000), with or without process
noise on the velocity. The package computes the three estimates of its state
that the paper compares: the optimal Bayes filter (:mod:`depthcore.optimal`;
for more frames the bank of Kalman filters over depth, :mod:`depthcore.bank`),
the second-order Gaussian approximation (:mod:`depthcore.second_order`) and
the extended Kalman filter (:mod:`depthcore.ekf`), with their depth and
velocity marginals.

Modules, by concept: :mod:`~depthcore.model` (Eqs. (1)-(5), (7), (9), (11),
(20)-(22)), :mod:`~depthcore.gaussian` (Eq. (13), the paper's prior),
:mod:`~depthcore.scenarios` (Figures 2-6 and the reported numbers),
:mod:`~depthcore.second_order` (Eqs. (8), (24)), :mod:`~depthcore.ekf`
(Eqs. (10)-(12)), :mod:`~depthcore.optimal` (Eqs. (6), (13)-(16)), integrated by
the depth quadrature :mod:`~depthcore.quadrature`; beyond the
paper, the unscented Kalman filter (:mod:`~depthcore.ukf`), importance
sampling from a second-order proposal (:mod:`~depthcore.particle`, with
:mod:`~depthcore.resampling`), the causal bootstrap filter with resample-move
(:mod:`~depthcore.resample_move`), the iterated EKF and smoother
(:mod:`~depthcore.iterated`), the inverse-depth EKF
(:mod:`~depthcore.inverse_depth`) and UKF (:mod:`~depthcore.inverse_depth_ukf`),
the EKF in modified polar coordinates (:mod:`~depthcore.modified_polar`),
the range-parametrised EKF, a Gaussian sum
of EKFs over depth intervals (:mod:`~depthcore.range_ekf`), the textbook's
Kalman filter and smoothers (:mod:`~depthcore.kalman`), the exact filter for
any number of frames as a bank of Kalman filters over depth
(:mod:`~depthcore.bank`), the Rao-Blackwellised
particle filter over depth with a Kalman filter per particle
(:mod:`~depthcore.rbpf`) and the self-calibration check
(:mod:`~depthcore.calibration`). The
registry :mod:`~depthcore.filters` lists every filter,
and :func:`~depthcore.tracking.track` (``depthcore.track``) filters and smooths one
track at every frame;
:mod:`~depthcore.reproduce` and :mod:`~depthcore.study` run them;
:mod:`~depthcore.cli_text` holds the command line's tables;
:mod:`~depthcore.reference` holds independent routes for checking;
:mod:`~depthcore.benchmarks` writes and reads the benchmarks' recorded results
and :mod:`~depthcore.benchmark_tables` renders them. The book's wing,
:mod:`depthcore.book`, holds each chapter's experiments, figures and glued
texts, one module per chapter, with what the chapters share (the plot style,
the number formatting, the notebook helpers and the book's cross-references);
no module outside it imports it but the command line, for the paper's figures,
and :mod:`~depthcore.benchmark_tables`, for its tables.

Every public module is an attribute of the package, imported when first used
(``import depthcore; depthcore.study`` works).
"""

import importlib

from .gaussian import Gaussian, paper_prior
from .model import bearings_from_pixels, noise_free_state
from .scenarios import SCENARIOS

__version__ = "0.1.0"

#: The public modules, imported on first access as attributes of the package.
MODULES = (
    "adapters",
    "bank",
    "bank_mixture",
    "bank_posterior",
    "bank_track",
    "benchmark_tables",
    "benchmarks",
    "book",
    "bound",
    "calibration",
    "cli_text",
    "ekf",
    "estimates",
    "filters",
    "gaussian",
    "hardness",
    "inverse_depth",
    "inverse_depth_ukf",
    "iterated",
    "kalman",
    "live",
    "model",
    "modified_polar",
    "optimal",
    "particle",
    "quadrature",
    "range_ekf",
    "rbpf",
    "reference",
    "reproduce",
    "resample_move",
    "resampling",
    "scenarios",
    "second_order",
    "study",
    "study_pairs",
    "study_scores",
    "study_trials",
    "tracking",
    "ukf",
)

__all__ = [
    "Gaussian",
    "MODULES",
    "SCENARIOS",
    "__version__",
    "bearings_from_pixels",
    "noise_free_state",
    "optimal_marginals",
    "paper_prior",
    "track",
    *MODULES,
]


def __getattr__(name):
    if name in MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name == "optimal_marginals":
        return importlib.import_module(f"{__name__}.optimal").marginals
    if name == "track":
        return importlib.import_module(f"{__name__}.tracking").track
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(MODULES) | {"optimal_marginals", "track"})
