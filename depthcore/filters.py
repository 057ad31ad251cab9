"""The filters, in one registry: every filter by name, one calling convention, one result shape.

Recommended import: ``from depthcore.filters import FILTERS``.

Each entry of :data:`FILTERS` is a :class:`Filter`. Calling it::

    estimate = FILTERS[name](mu, rho, prior_mean, prior_cov, **options)

runs the filter on one triple of measurements (``mu`` of shape ``(3,)``) or on
a batch (``mu`` of shape ``(B, 3)``, ``rho`` a float or shape ``(B,)``, the
prior's mean ``(3,)`` or ``(B, 3)`` and covariance ``(3, 3)``) and returns an
:class:`Estimate`: the depth and velocity means and SDs at time 3 (floats for
one triple, arrays of shape ``(B,)`` for a batch), their numerical or Monte
Carlo errors where the filter has them, the mean and covariance of the whole
state, and the filter's own result (``detail``). The entry also carries the
filter's label and plot style, the table rows it contributes to
:func:`depthcore.reproduce.reproduce` (``variants``), and how its estimates
are scored (``family``). :mod:`depthcore.reproduce`, :mod:`depthcore.study`,
:mod:`depthcore.experiments`, the command line and :mod:`depthcore.figures`
iterate this registry: adding a filter means adding an entry here.

The filters: the paper's optimal filter (:mod:`depthcore.optimal`, Eqs.
(6), (13)-(16)), second-order approximation (:mod:`depthcore.second_order`,
Eq. (8)) and EKF (:mod:`depthcore.ekf`, Eqs. (10)-(12)); beyond the paper,
the unscented Kalman filter (:mod:`depthcore.ukf`) and a particle filter
(:mod:`depthcore.particle`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _checks, ekf, optimal, particle, second_order, ukf
from .gaussian import Gaussian, History
from .resampling import weighted_mean_and_cov

QUANTITIES = ("depth", "velocity")
#: The state component of each quantity.
COMPONENT = {"depth": "y", "velocity": "v"}
#: How a filter's estimates are scored, one of ``"exact"`` (the optimal filter, the
#: reference), ``"gaussian"`` (a mean and covariance), ``"particles"``
#: (weighted particles, in ``detail``).
FAMILIES = ("exact", "gaussian", "particles")
#: Particles of the particle filter unless a caller asks for another number.
PARTICLES = 20_000


@dataclass(frozen=True)
class Estimate:
    """A filter's result: moments of the depth and velocity at time 3, and the state's.

    Floats (or arrays of shape ``()``) for one triple of measurements, arrays
    of shape ``(B,)`` for a batch.

    Attributes
    ----------
    depth_mean, depth_sd, velocity_mean, velocity_sd : float or ndarray, shape (B,)
    depth_error, velocity_error : float or ndarray, shape (B,), or None
        The numerical (optimal filter) or Monte Carlo (particle filter) error of
        the moments; ``None`` for a closed form.
    mean : ndarray, shape (3,) or (B, 3)
        Mean of the state ``(x, y, v)`` at time 3.
    cov : ndarray, shape (3, 3) or (B, 3, 3)
    detail : object
        The filter's own result (:class:`~depthcore.optimal.OptimalMarginals`,
        :class:`~depthcore.gaussian.Gaussian`, :class:`~depthcore.particle.ParticleResult`, ...).
    extras : dict
        Further numbers the filter reports (the optimal filter's probability
        that the point is behind the camera).
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

    def moments(self, quantity: str) -> dict:
        """``{"mean", "sd"}`` of ``"depth"`` or ``"velocity"``.

        Includes ``"error"`` where there is one.
        """
        _quantity(quantity)
        out = {"mean": getattr(self, f"{quantity}_mean"), "sd": getattr(self, f"{quantity}_sd")}
        error = getattr(self, f"{quantity}_error")
        if error is not None:
            out["error"] = error
        return out


@dataclass(frozen=True)
class Filter:
    """One filter of the registry.

    Attributes
    ----------
    name : str
    label : str
        Legend label (LaTeX allowed).
    style : dict
        Matplotlib line properties (colour, line style).
    family : {"exact", "gaussian", "particles"}
    in_paper : bool
        Whether the paper compares it.
    run : callable
        ``run(mu, rho, prior_mean, prior_cov, **options) -> Estimate``.
    variants : tuple of (str, str, dict)
        ``(reading, support, options)`` of each row the filter contributes to
        the reproduction tables.
    random : bool
        Whether it draws random numbers: then it takes ``rng`` (a
        ``numpy.random.Generator`` or ``SeedSequence``) and ``n_particles``.
    """

    name: str
    label: str
    style: dict
    family: str
    in_paper: bool
    run: Callable[..., Estimate]
    variants: tuple
    random: bool = False

    def __call__(self, mu, rho, prior_mean, prior_cov, **options) -> Estimate:
        return self.run(mu, rho, prior_mean, prior_cov, **options)

    @property
    def plot_style(self) -> dict:
        """Keyword arguments of ``Axes.plot``: the label and the style."""
        return {"label": self.label, **self.style}

    def density(self, estimate: Estimate, quantity: str, grid) -> np.ndarray:
        """The marginal density of ``quantity`` on ``grid`` (one triple's estimate).

        The particle filter's is a weighted Gaussian kernel density estimate
        (Silverman's bandwidth).
        """
        _quantity(quantity)
        grid = np.asarray(grid, dtype=float)
        if self.family == "exact":
            d = estimate.detail
            return d.depth_pdf(grid) if quantity == "depth" else d.velocity_pdf(grid)
        if self.family == "particles":
            return estimate.detail.density(COMPONENT[quantity], grid)
        return Gaussian(estimate.mean, estimate.cov).marginal_pdf(COMPONENT[quantity], grid)


def _quantity(quantity: str) -> str:
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    return quantity


def _single(mu) -> bool:
    """Whether ``mu`` is one triple (shape (3,)) rather than a batch (B, 3)."""
    return np.ndim(mu) == 1


def _prior(prior_mean, prior_cov) -> Gaussian:
    try:
        return Gaussian(prior_mean, prior_cov)
    except ValueError as exc:
        raise ValueError(
            str(exc).replace("cov ", "prior_cov ", 1).replace("mean ", "prior_mean ", 1)
        ) from None


def _gaussian_estimate(mean, cov, detail) -> Estimate:
    """An :class:`Estimate` of a Gaussian filter from its mean and covariance (Eq. (13))."""
    mean = np.asarray(mean, dtype=float)
    cov = np.asarray(cov, dtype=float)
    if mean.ndim == 1:
        g = Gaussian(mean, cov)
        (dm, ds), (vm, vs) = g.marginal("y"), g.marginal("v")
        return Estimate(dm, ds, vm, vs, None, None, g.mean, g.cov, detail)
    return Estimate(
        mean[..., 1],
        np.sqrt(cov[..., 1, 1]),
        mean[..., 2],
        np.sqrt(cov[..., 2, 2]),
        None,
        None,
        mean,
        cov,
        detail,
    )


def _optimal(
    mu,
    rho,
    prior_mean,
    prior_cov,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
) -> Estimate:
    """The optimal filter, Eqs. (6), (13)-(16); see :func:`depthcore.optimal.marginals`.

    For a batch with the default reading and support, ``detail`` is the
    :class:`~depthcore.optimal.BatchMarginals` (with the CDFs and densities);
    otherwise the :class:`~depthcore.optimal.Moments`.
    """
    if _single(mu):
        m = optimal.marginals(mu, rho, _prior(prior_mean, prior_cov), reading, support, rtol)
        return Estimate(
            m.depth_mean,
            m.depth_sd,
            m.velocity_mean,
            m.velocity_sd,
            m.depth_error,
            m.velocity_error,
            m.mean,
            m.cov,
            m,
            {"prob_behind_camera": m.prob_behind_camera},
        )
    if (reading, support) == ("derived", "front"):
        detail = optimal.batch_marginals(mu, rho, prior_mean, prior_cov, rtol)
        m = detail.moments
    else:
        m = detail = optimal.moments(mu, rho, prior_mean, prior_cov, reading, support, rtol)
    return Estimate(
        m.depth_mean,
        m.depth_sd,
        m.velocity_mean,
        m.velocity_sd,
        m.depth_error,
        m.velocity_error,
        m.mean,
        m.cov,
        detail,
        {"prob_behind_camera": m.prob_behind_camera},
    )


def _second_order(mu, rho, prior_mean, prior_cov, reading: str = "derived") -> Estimate:
    """The second-order approximation ``p_s``, Eq. (8); ``detail`` is its Gaussian or ``None``."""
    if _single(mu):
        g = second_order.second_order(mu, rho, _prior(prior_mean, prior_cov), reading)
        return _gaussian_estimate(g.mean, g.cov, g)
    mean, cov = second_order.second_order_batch(mu, rho, prior_mean, prior_cov, reading)
    return _gaussian_estimate(mean, cov, None)


def _ekf(mu, rho, prior_mean, prior_cov) -> Estimate:
    """The EKF, Eqs. (10)-(12); ``detail`` is its :class:`~depthcore.gaussian.History`."""
    if _single(mu):
        h = ekf.ekf(mu, rho, _prior(prior_mean, prior_cov))
    else:
        h = ekf.run(mu, rho, prior_mean, prior_cov)
    return _gaussian_estimate(h.means[..., -1, :], h.covs[..., -1, :, :], h)


def _ukf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = True,
) -> Estimate:
    """The UKF; ``detail`` is its :class:`~depthcore.gaussian.History`.

    By default it runs even where sigma points of the paper's broad prior lie
    behind the camera (``allow_behind_camera``): the comparison is the point.
    """
    if _single(mu):
        h: History = ukf.ukf(
            mu, rho, _prior(prior_mean, prior_cov), sigma_points, allow_behind_camera
        )
    else:
        h = ukf.run(mu, rho, prior_mean, prior_cov, sigma_points, allow_behind_camera)
    return _gaussian_estimate(h.means[..., -1, :], h.covs[..., -1, :, :], h)


def _particle(
    mu, rho, prior_mean, prior_cov, rng=None, n_particles: int = PARTICLES, **options
) -> Estimate:
    """The particle filter; ``detail`` is its ParticleResult (one triple) or ParticleBatch.

    ``rng``, a ``numpy.random.Generator`` or a ``SeedSequence`` (or an int
    seed), is required; ``options`` are those of :func:`depthcore.particle.run`.
    The errors are the larger of the delta-method standard errors of the mean
    and of the SD.
    """
    if rng is None:
        raise ValueError(
            "rng is required to run the particle filter: pass a "
            "numpy.random.Generator or SeedSequence"
        )
    rng = _checks.generator(rng)
    if _single(mu):
        r = particle.particle_filter(
            mu, rho, _prior(prior_mean, prior_cov), n_particles, rng, **options
        )
        m, se = r.moments(), r.standard_errors()
        mean, cov = weighted_mean_and_cov(r.particles, r.weights)
        return Estimate(
            float(m.depth_mean),
            float(m.depth_sd),
            float(m.velocity_mean),
            float(m.velocity_sd),
            float(max(se.depth_mean, se.depth_sd)),
            float(max(se.velocity_mean, se.velocity_sd)),
            mean,
            cov,
            r,
        )
    b = particle.run(mu, rho, prior_mean, prior_cov, n_particles, rng, **options)
    m, se = b.moments(), b.standard_errors()
    mean, cov = weighted_mean_and_cov(b.particles, np.exp(b.log_weights))
    return Estimate(
        m.depth_mean,
        m.depth_sd,
        m.velocity_mean,
        m.velocity_sd,
        np.maximum(se.depth_mean, se.depth_sd),
        np.maximum(se.velocity_mean, se.velocity_sd),
        mean,
        cov,
        b,
    )


#: Every filter, in the order of the tables and legends.
FILTERS: dict[str, Filter] = {
    f.name: f
    for f in (
        Filter(
            "optimal",
            "optimal $p_o$",
            {"color": "black", "linestyle": "-"},
            "exact",
            True,
            _optimal,
            tuple(
                (r, s, {"reading": r, "support": s})
                for r in optimal.READINGS
                for s in optimal.SUPPORTS
            ),
        ),
        Filter(
            "second_order",
            "second order $p_s$",
            {"color": "tab:blue", "linestyle": "--"},
            "gaussian",
            True,
            _second_order,
            tuple((r, "all", {"reading": r}) for r in second_order.READINGS),
        ),
        Filter(
            "ekf",
            "EKF $p_e$",
            {"color": "tab:red", "linestyle": ":"},
            "gaussian",
            True,
            _ekf,
            (("printed", "all", {}),),
        ),
        Filter(
            "ukf",
            "UKF",
            {"color": "tab:green", "linestyle": "-."},
            "gaussian",
            False,
            _ukf,
            (("-", "all", {}),),
        ),
        Filter(
            "particle",
            "importance sampling, $q$ from $p_s$",
            {"color": "tab:purple", "linestyle": (0, (5, 1, 1, 1, 1, 1))},
            "particles",
            False,
            _particle,
            (("-", "front", {}),),
            random=True,
        ),
    )
}

#: The paper's three filters.
PAPER_FILTERS = tuple(name for name, f in FILTERS.items() if f.in_paper)
#: Every filter's name.
NAMES = tuple(FILTERS)


def get(name: str) -> Filter:
    """The filter called ``name``; a :class:`ValueError` lists the names if there is none."""
    if name not in FILTERS:
        raise ValueError(f"filter must be one of {NAMES}, got {name!r}")
    return FILTERS[name]


def check_names(names) -> tuple:
    """Return ``names`` as a tuple after checking each is in the registry."""
    names = tuple(names)
    unknown = set(names) - set(FILTERS)
    if unknown:
        raise ValueError(f"filters must be among {NAMES}, got {sorted(unknown)}")
    return names
