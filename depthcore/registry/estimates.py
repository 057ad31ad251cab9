"""A filter's result and how a study scores it: the :class:`~depthcore.registry.estimates.Estimate`
and the filters' families.

Recommended import: ``from depthcore.registry import estimates``.

Every filter of the registry (:mod:`depthcore.registry.filters`) returns an
:class:`Estimate`: the depth's and the velocity's mean and SD at the last
frame, their numerical or Monte Carlo errors, the state's mean and
covariance, and the filter's own result. How a study reads it depends on the
filter's family (:data:`FAMILIES`): the exact reference, a Gaussian, weighted
particles or Rao-Blackwellised particles, each a :class:`Family` in
:data:`FAMILY` with its CDFs, densities and depth draws.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from depthcore.exact import mixture
from depthcore.particles.resampling import weighted_density
from depthcore.problem import predictive
from depthcore.problem.gaussian import Gaussian

QUANTITIES = ("depth", "velocity")

#: The moments every :class:`Estimate` reports, by attribute.
MOMENTS = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")

#: The state component of each quantity.
COMPONENT = {"depth": "y", "velocity": "v"}

#: How a filter's estimates are scored, one of ``"exact"`` (the optimal filter, the
#: reference), ``"gaussian"`` (a mean and covariance), ``"particles"``
#: (weighted particles, in ``detail``), ``"rao_blackwellised"`` (weighted
#: particle depths, each with a Gaussian of the lateral state: the
#: :class:`~depthcore.particles.rbpf.RBPF` in ``detail``).
FAMILIES = ("exact", "gaussian", "particles", "rao_blackwellised")


@dataclass(frozen=True)
class Estimate:
    """A filter's result: moments of the depth and velocity at frame ``N``, and the state's.

    Frame ``N`` is the last bearing's (time 3 for the paper's triple). Floats
    (or arrays of shape ``()``) for one sequence of bearings, arrays of shape
    ``(B,)`` for a batch.

    The per-frame report, :attr:`updates`, is read from ``detail`` when first
    asked for (the exact filter computes it then).

    Attributes
    ----------
    depth_mean, depth_sd, velocity_mean, velocity_sd : float or ndarray, shape (B,)
    depth_error, velocity_error : float or ndarray, shape (B,), or None
        The numerical (optimal filter) or Monte Carlo (particle filter) error of
        the moments; ``None`` for a closed form.
    mean : ndarray, shape (3,) or (B, 3)
        Mean of the state ``(x, y, v)`` at frame ``N``.
    cov : ndarray, shape (3, 3) or (B, 3, 3)
    detail : object
        The filter's own result (:class:`~depthcore.exact.optimal.OptimalMarginals`,
        :class:`~depthcore.problem.gaussian.Gaussian`,
        :class:`~depthcore.particles.importance.ParticleResult`, ...).
    extras : dict
        Further numbers the filter reports (the optimal filter's probability
        that the point is behind the camera).
    collapsed : bool or ndarray of bool, shape (B,), or None
        For a sampler: whether its particles collapsed (worth fewer than
        :data:`depthcore.particles.resampling.MIN_EFFECTIVE_DRAWS` independent draws of
        the posterior), so that neither its spread nor its error can be
        trusted; its errors are then NaN. ``None`` for the other filters.
    """

    depth_mean: Any
    depth_sd: Any
    velocity_mean: Any
    velocity_sd: Any
    depth_error: Any
    velocity_error: Any
    mean: np.ndarray
    cov: np.ndarray
    detail: Any = None
    extras: dict = field(default_factory=dict)
    collapsed: Any = None

    @functools.cached_property
    def updates(self):
        """Per frame, each bearing's log predictive density, tail and whether the gate skipped it.

        ``detail.updates`` (:class:`depthcore.problem.predictive.Updates`) with
        arrays of shape (N,) for one sequence (a leading axis of one, as a
        replicated filter's, dropped) and (B, N) for a batch; ``None`` for a
        filter that does not report them.
        """
        return read_updates(self.detail, np.ndim(self.mean) == 1)

    def moments(self, quantity: str) -> dict:
        """``{"mean", "sd"}`` of ``"depth"`` or ``"velocity"``.

        Includes ``"error"`` where there is one.
        """
        check_quantity(quantity)
        out = {"mean": getattr(self, f"{quantity}_mean"), "sd": getattr(self, f"{quantity}_sd")}
        error = getattr(self, f"{quantity}_error")
        if error is not None:
            out["error"] = error
        return out


def read_updates(result, single: bool):
    """``result.updates`` as :class:`depthcore.problem.predictive.Updates`, or ``None``.

    A result that computes its report only on demand (the exact filter's
    :meth:`depthcore.exact.mixture.Mixture.report`) is asked for it here.

    Parameters
    ----------
    result : object
        A filter's own result.
    single : bool
        Whether it is of one sequence: then each array has shape (N,).
    """
    report = getattr(result, "report", None)
    found = report() if callable(report) else getattr(result, "updates", None)
    if found is None:
        return None
    found = predictive.Updates(*(np.asarray(a) for a in found))
    if single and found.tail.ndim == 2 and found.tail.shape[0] == 1:
        found = predictive.Updates(*(a[0] for a in found))
    return found


def check_quantity(quantity: str) -> str:
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    return quantity


def _exact_cdfs(estimate: Estimate, truths) -> tuple:
    """The exact posterior's marginal CDFs at each problem's true depth and velocity, (B,) each.

    Three frames without process noise give the one-dimensional route's
    :class:`~depthcore.exact.optimal.BatchMarginals` (queries of shape (B,)); more
    frames or process noise the bank's :class:`~depthcore.exact.mixture.Mixture`
    (queries of shape (B, 1)).
    """
    d = estimate.detail
    if isinstance(d, mixture.Mixture):
        return d.depth_cdf(truths[:, 1:2])[:, 0], d.velocity_cdf(truths[:, 2:3])[:, 0]
    return d.depth_cdf(truths[:, 1]), d.velocity_cdf(truths[:, 2])


def exact_depth_range(detail) -> tuple:
    """Where the exact depth marginal lives: ``t`` limits (B,) and the depth offset.

    ``t = log(y - offset)`` with ``offset = N - 1`` for ``N`` frames (2 for the
    paper's three): the quadrature's range for
    :class:`~depthcore.exact.optimal.BatchMarginals`, the nodes with weight for a
    :class:`~depthcore.exact.mixture.Mixture` (the exact filter's ``detail``).
    """
    if isinstance(detail, mixture.Mixture):
        p = detail.probabilities
        log_y1 = np.log(np.broadcast_to(detail.bank.nodes, p.shape))
        used = p > 1e-300
        t_lo = np.min(np.where(used, log_y1, np.inf), axis=-1)
        t_hi = np.max(np.where(used, log_y1, -np.inf), axis=-1)
        return t_lo, t_hi, detail.bank.frames - 1.0
    t_lo, t_hi, _ = detail.log_depth_range
    return t_lo, t_hi, 2.0


def _exact_density(estimate: Estimate, quantity: str, grid) -> np.ndarray:
    d = estimate.detail
    return d.depth_pdf(grid) if quantity == "depth" else d.velocity_pdf(grid)


def _gaussian_cdfs(estimate: Estimate, truths) -> tuple:
    """Eq. (13)'s Gaussian marginal CDFs at the true depth and velocity, (B,) each."""
    from scipy.special import ndtr

    mean, cov = estimate.mean, estimate.cov
    return (
        ndtr((truths[:, 1] - mean[:, 1]) / np.sqrt(cov[:, 1, 1])),
        ndtr((truths[:, 2] - mean[:, 2]) / np.sqrt(cov[:, 2, 2])),
    )


def _gaussian_density(estimate: Estimate, quantity: str, grid) -> np.ndarray:
    return Gaussian(estimate.mean, estimate.cov).marginal_pdf(COMPONENT[quantity], grid)


def _particle_cdfs(estimate: Estimate, truths) -> tuple:
    """The weighted particles' step-function CDFs at the true depth and velocity, (B,) each."""
    batch = estimate.detail
    W = np.exp(batch.log_weights)
    x = batch.particles
    return (
        np.sum(W * (x[..., 1] <= truths[:, 1, None]), axis=1),
        np.sum(W * (x[..., 2] <= truths[:, 2, None]), axis=1),
    )


def _particle_depths(estimate: Estimate) -> tuple:
    """The particles' depths (B, M) and normalised weights (B, M)."""
    batch = estimate.detail
    return batch.particles[..., 1], np.exp(batch.log_weights)


def _particle_density(estimate: Estimate, quantity: str, grid) -> np.ndarray:
    return estimate.detail.density(COMPONENT[quantity], grid)


def _rao_blackwellised_cdfs(estimate: Estimate, truths) -> tuple:
    """The particles' depth CDF (a step function) and the Gaussian mixture's velocity CDF."""
    f = estimate.detail
    return f.depth_cdf(truths[:, 1]), f.velocity_cdf(truths[:, 2])


def _rao_blackwellised_depths(estimate: Estimate) -> tuple:
    """The pooled particles' depths (B, M) and normalised weights (B, M)."""
    W, depths, _, _ = estimate.detail.pooled()
    return depths, W


def _rao_blackwellised_density(estimate: Estimate, quantity: str, grid) -> np.ndarray:
    if quantity == "velocity":
        return estimate.detail.velocity_pdf(grid)
    depths, W = _rao_blackwellised_depths(estimate)
    return weighted_density(depths, W, grid)


@dataclass(frozen=True)
class Family:
    """What scoring a filter's result needs: one entry of :data:`FAMILY` per kind of result.

    The functions take a batch's :class:`Estimate` (``B`` problems) and the
    true states ``truths`` of shape (B, 3); :meth:`~depthcore.registry.filters.Filter.density`
    takes one
    problem's.

    Attributes
    ----------
    name : {"exact", "gaussian", "particles", "rao_blackwellised"}
    exact : bool
        The exact posterior: the reference of every Hellinger distance (its
        distance to itself is 0).
    gaussian : bool
        The result is the Gaussian with the estimate's mean and covariance,
        whose depth density has a closed form.
    cdfs : callable
        ``cdfs(estimate, truths) -> (depth_cdf, velocity_cdf)``, each (B,): the
        filter's marginal CDFs at the true depth and velocity.
    depth_draws : callable or None
        ``depth_draws(estimate) -> (depths, weights)``, each (B, M): weighted
        draws of the depth, from which a kernel estimate gives its density;
        ``None`` where the density is given (exact or Gaussian).
    density : callable
        ``density(estimate, quantity, grid)``: the marginal density of
        ``"depth"`` or ``"velocity"`` on ``grid`` (one problem).
    """

    name: str
    exact: bool
    gaussian: bool
    cdfs: Callable
    depth_draws: Callable | None
    density: Callable


#: How each family of results is scored, as a :class:`Family` by name (one per :data:`FAMILIES`).
FAMILY: dict[str, Family] = {
    "exact": Family("exact", True, False, _exact_cdfs, None, _exact_density),
    "gaussian": Family("gaussian", False, True, _gaussian_cdfs, None, _gaussian_density),
    "particles": Family(
        "particles", False, False, _particle_cdfs, _particle_depths, _particle_density
    ),
    "rao_blackwellised": Family(
        "rao_blackwellised",
        False,
        False,
        _rao_blackwellised_cdfs,
        _rao_blackwellised_depths,
        _rao_blackwellised_density,
    ),
}
