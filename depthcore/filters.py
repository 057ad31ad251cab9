"""The filters, in one registry: every filter by name, one calling convention, one result shape.

Recommended import: ``from depthcore.filters import FILTERS``.

Each entry of :data:`FILTERS` is a :class:`Filter`. Calling it::

    estimate = FILTERS[name](mu, rho, prior_mean, prior_cov, process_noise=0.0, **options)

runs the filter on one sequence of ``N`` bearings (``mu`` of shape ``(N,)``;
the paper's triple is ``N = 3``) or on a batch (``mu`` of shape ``(B, N)``,
``rho`` a float or shape ``(B,)``, the prior's mean ``(3,)`` or ``(B, 3)`` and
covariance ``(3, 3)``), with process noise ``a_k ~ N(0, q**2)`` on the
velocity if ``process_noise = q > 0`` (the N-frame model of
:mod:`depthcore.bank`; the prior is on the state at frame 1), and returns an
:class:`Estimate`: the depth and velocity means and SDs at frame ``N`` (time 3
for a triple; floats for one sequence, arrays of shape ``(B,)`` for a batch),
their numerical or Monte Carlo errors where the filter has them, the mean and
covariance of the whole state, and the filter's own result (``detail``). The entry also carries the
filter's label and plot style, the table rows it contributes to
:func:`depthcore.reproduce.reproduce` (``variants``), how its estimates
are scored (``family``, whose :class:`Family` in :data:`FAMILY`, the entry's
``scoring``, holds what a study reads of its results: whether it is the exact
reference, a Gaussian, or weighted draws of the depth, and its CDFs and
densities), its smoother if it has one (``smoother``, which :func:`track`
runs over one track), and what it supports: ``any_frames`` (any
``N >= 3`` bearings, up to ``depthcore._checks.MAX_FRAMES``, or only the
paper's three) and ``with_process_noise`` (``q > 0`` or only ``q = 0``); a
call outside them is refused with a :class:`ValueError` naming ``mu`` or
``process_noise``. :mod:`depthcore.reproduce`, :mod:`depthcore.study`,
:mod:`depthcore.experiments`, the command line and :mod:`depthcore.figures`
iterate the entries marked ``default`` (:data:`NAMES`), which are the five of
the paper's problem; the N-frame filters (``iterated``, ``inverse_depth``,
``resample_move``, ``rbpf``) are registered with ``default=False`` and run only when
named (:data:`ALL_NAMES`). Adding a filter means adding an entry here.

The filters: the paper's optimal filter (:mod:`depthcore.optimal`, Eqs.
(6), (13)-(16)), second-order approximation (:mod:`depthcore.second_order`,
Eq. (8)) and EKF (:mod:`depthcore.ekf`, Eqs. (10)-(12)); beyond the paper,
the unscented Kalman filter (:mod:`depthcore.ukf`) and a particle filter
(:mod:`depthcore.particle`); for N frames, the iterated EKF
(:mod:`depthcore.iterated`), the inverse-depth EKF
(:mod:`depthcore.inverse_depth`), the causal bootstrap particle filter with
resample-move (:mod:`depthcore.resample_move`), the Rao-Blackwellised
particle filter (:mod:`depthcore.rbpf`), the range-parametrised EKF
(:mod:`depthcore.range_ekf`), the inverse-depth UKF
(:mod:`depthcore.inverse_depth_ukf`) and the EKF in modified polar coordinates
(:mod:`depthcore.modified_polar`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import (
    _checks,
    bank_mixture,
    bank_posterior,
    bank_track,
    ekf,
    inverse_depth,
    inverse_depth_ukf,
    iterated,
    kalman,
    model,
    modified_polar,
    optimal,
    particle,
    range_ekf,
    rbpf,
    resample_move,
    second_order,
    ukf,
)
from .gaussian import Gaussian, History, paper_prior
from .resampling import weighted_density, weighted_mean_and_cov

QUANTITIES = ("depth", "velocity")
#: The state component of each quantity.
COMPONENT = {"depth": "y", "velocity": "v"}
#: How a filter's estimates are scored, one of ``"exact"`` (the optimal filter, the
#: reference), ``"gaussian"`` (a mean and covariance), ``"particles"``
#: (weighted particles, in ``detail``), ``"rao_blackwellised"`` (weighted
#: particle depths, each with a Gaussian of the lateral state: the
#: :class:`~depthcore.rbpf.RBPF` in ``detail``).
FAMILIES = ("exact", "gaussian", "particles", "rao_blackwellised")
#: Particles of the particle filter unless a caller asks for another number.
PARTICLES = 20_000
#: Particles per replica of the resample-move filter, by default (``resample_move.REPLICAS``
#: replicas: the same 20,000 particles in all as the importance sampler).
RESAMPLE_MOVE_PARTICLES = 5000
#: Particles per replica of the Rao-Blackwellised particle filter, by default.
RBPF_PARTICLES = 1000
#: Independent replicas of the Rao-Blackwellised particle filter, for its standard errors.
RBPF_REPLICAS = 4


@dataclass(frozen=True)
class Estimate:
    """A filter's result: moments of the depth and velocity at frame ``N``, and the state's.

    Frame ``N`` is the last bearing's (time 3 for the paper's triple). Floats
    (or arrays of shape ``()``) for one sequence of bearings, arrays of shape
    ``(B,)`` for a batch.

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
        The filter's own result (:class:`~depthcore.optimal.OptimalMarginals`,
        :class:`~depthcore.gaussian.Gaussian`, :class:`~depthcore.particle.ParticleResult`, ...).
    extras : dict
        Further numbers the filter reports (the optimal filter's probability
        that the point is behind the camera).
    collapsed : bool or ndarray of bool, shape (B,), or None
        For a sampler: whether its particles collapsed (worth fewer than
        :data:`depthcore.resampling.MIN_EFFECTIVE_DRAWS` independent draws of
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


def _exact_cdfs(estimate: Estimate, truths) -> tuple:
    """The exact posterior's marginal CDFs at each problem's true depth and velocity, (B,) each.

    Three frames without process noise give the one-dimensional route's
    :class:`~depthcore.optimal.BatchMarginals` (queries of shape (B,)); more
    frames or process noise the bank's :class:`~depthcore.bank_mixture.Mixture`
    (queries of shape (B, 1)).
    """
    d = estimate.detail
    if isinstance(d, bank_mixture.Mixture):
        return d.depth_cdf(truths[:, 1:2])[:, 0], d.velocity_cdf(truths[:, 2:3])[:, 0]
    return d.depth_cdf(truths[:, 1]), d.velocity_cdf(truths[:, 2])


def exact_depth_range(detail) -> tuple:
    """Where the exact depth marginal lives: ``t`` limits (B,) and the depth offset.

    ``t = log(y - offset)`` with ``offset = N - 1`` for ``N`` frames (2 for the
    paper's three): the quadrature's range for
    :class:`~depthcore.optimal.BatchMarginals`, the nodes with weight for a
    :class:`~depthcore.bank_mixture.Mixture` (the exact filter's ``detail``).
    """
    if isinstance(detail, bank_mixture.Mixture):
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
    true states ``truths`` of shape (B, 3); :meth:`Filter.density` takes one
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
    family : {"exact", "gaussian", "particles", "rao_blackwellised"}
    in_paper : bool
        Whether the paper compares it.
    run : callable
        ``run(mu, rho, prior_mean, prior_cov, **options) -> Estimate``, and
        also ``process_noise=q`` when ``with_process_noise``.
    variants : tuple of (str, str, dict)
        ``(reading, support, options)`` of each row the filter contributes to
        the reproduction tables.
    random : bool
        Whether it draws random numbers: then it takes ``rng`` (a
        ``numpy.random.Generator`` or ``SeedSequence``) and ``n_particles``.
    any_frames : bool
        Whether it takes any ``N >= 3`` bearings per problem; if false, only
        the paper's three.
    with_process_noise : bool
        Whether it takes ``process_noise > 0``; if false, only 0.
    default : bool
        Whether the default outputs (tables, studies, sweeps, figures, the
        command line) include it: :data:`NAMES`.
    smoother : callable or None
        ``smoother(mu, rho, prior_mean, prior_cov, process_noise)`` of one
        track of ``N`` bearings, checked by :func:`track` (which calls it):
        ``(filtered, smoothed, detail)``, the state at every frame given the
        bearings up to it and given all of them, each a
        :class:`~depthcore.bank_mixture.Smoothed` of means (N, 3) and covariances
        (N, 3, 3), and the filter's own result. ``None`` for a filter
        without a smoother.
    """

    name: str
    label: str
    style: dict
    family: str
    in_paper: bool
    run: Callable[..., Estimate]
    variants: tuple
    random: bool = False
    any_frames: bool = False
    with_process_noise: bool = False
    default: bool = True
    smoother: Callable | None = None

    def __call__(self, mu, rho, prior_mean, prior_cov, process_noise=0.0, **options) -> Estimate:
        """Run the filter; see the module docstring for the arguments and their shapes.

        Every number goes through one conversion, :func:`depthcore._checks.as_float`
        (lists and arrays of integers or floats; complex, boolean, object and
        text values are refused by name). ``mu`` is checked by
        :func:`depthcore.model.measurements_batch` (and must have 3 columns
        unless ``any_frames``); for one sequence ``rho`` is a number (a float,
        a 0-d array or a list of one); ``process_noise`` is checked by
        :func:`depthcore._checks.process_noise`, and must be 0 unless
        ``with_process_noise``.
        """
        mu = model.measurements_batch(mu, "mu")
        if mu.shape[-1] != 3 and not self.any_frames:
            raise ValueError(
                f"mu must have shape (3,) or (B, 3): the {self.name} filter takes the "
                f"paper's three frames, got {mu.shape[-1]} bearings per problem"
            )
        rho = _checks.as_float(rho, "rho")
        if mu.ndim == 1:
            rho = _checks.number(rho, "rho")
        prior_mean = _checks.as_float(prior_mean, "prior_mean")
        prior_cov = _checks.as_float(prior_cov, "prior_cov")
        q = _checks.process_noise(process_noise, "process_noise")
        if not self.with_process_noise:
            if q > 0:
                raise ValueError(
                    f"process_noise must be 0 for the {self.name} filter, which supports "
                    f"only the constant-velocity motion, got {q:g}"
                )
            return self.run(mu, rho, prior_mean, prior_cov, **options)
        return self.run(mu, rho, prior_mean, prior_cov, process_noise=q, **options)

    @property
    def frames(self) -> str:
        """``"3"`` (the paper's frames only) or ``"any"`` (``N >= 3``)."""
        return "any" if self.any_frames else "3"

    @property
    def plot_style(self) -> dict:
        """Keyword arguments of ``Axes.plot``: the label and the style."""
        return {"label": self.label, **self.style}

    def density(self, estimate: Estimate, quantity: str, grid) -> np.ndarray:
        """The marginal density of ``quantity`` on ``grid`` (one sequence's estimate).

        The particle filters' is a weighted Gaussian kernel density estimate
        (Silverman's bandwidth); the Rao-Blackwellised filter's velocity
        marginal is its Gaussian mixture, its depth a kernel estimate.
        """
        _quantity(quantity)
        return self.scoring.density(estimate, quantity, np.asarray(grid, dtype=float))

    @property
    def scoring(self) -> Family:
        """The :class:`Family` of its ``family``, which says how its results are scored."""
        return FAMILY[self.family]


def _quantity(quantity: str) -> str:
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    return quantity


def _single(mu) -> bool:
    """Whether ``mu`` is one sequence (shape (N,)) rather than a batch (B, N)."""
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
    process_noise: float = 0.0,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
) -> Estimate:
    """The optimal filter, Eqs. (6), (13)-(16); see :func:`depthcore.optimal.marginals`.

    For a batch with the default reading and support, ``detail`` is the
    :class:`~depthcore.optimal.BatchMarginals` (with the CDFs and densities);
    otherwise the :class:`~depthcore.optimal.Moments`. For more than three
    frames or with process noise it is the bank of Kalman filters over depth
    nodes placed by the same quadrature (:func:`depthcore.bank_posterior.posterior`),
    and ``detail`` its :class:`~depthcore.bank_mixture.Mixture`.
    """
    if np.shape(mu)[-1] != 3 or process_noise > 0:
        if (reading, support) != ("derived", "front"):
            raise ValueError(
                "reading and support other than 'derived' and 'front' are readings of the "
                "paper's three-frame Eqs. (14)-(16); with more frames or process noise "
                f"the optimal filter has neither, got {reading!r} and {support!r}"
            )
        m = bank_posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise, rtol)
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
            {"prob_behind_camera": np.zeros_like(m.depth_mean)},
        )
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


def _second_order(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, reading: str = "derived"
) -> Estimate:
    """The second-order approximation ``p_s``, Eq. (8); ``detail`` is its Gaussian or ``None``.

    For ``N > 3`` bearings or process noise, its generalisation
    (:func:`depthcore.second_order.second_order_batch`).
    """
    if _single(mu):
        g = second_order.second_order(
            mu, rho, _prior(prior_mean, prior_cov), reading, process_noise
        )
        return _gaussian_estimate(g.mean, g.cov, g)
    mean, cov = second_order.second_order_batch(
        mu, rho, prior_mean, prior_cov, reading, process_noise
    )
    return _gaussian_estimate(mean, cov, None)


def _ekf(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> Estimate:
    """The EKF, Eqs. (10)-(12); ``detail`` is its :class:`~depthcore.gaussian.History`."""
    if _single(mu):
        h = ekf.ekf(mu, rho, _prior(prior_mean, prior_cov), process_noise)
    else:
        h = ekf.run(mu, rho, prior_mean, prior_cov, process_noise)
    return _gaussian_estimate(h.means[..., -1, :], h.covs[..., -1, :, :], h)


def _ukf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = True,
) -> Estimate:
    """The UKF; ``detail`` is its :class:`~depthcore.gaussian.History`.

    By default it runs even where sigma points of the paper's broad prior lie
    behind the camera (``allow_behind_camera``): the comparison is the point.
    """
    if _single(mu):
        h: History = ukf.ukf(
            mu, rho, _prior(prior_mean, prior_cov), sigma_points, allow_behind_camera, process_noise
        )
    else:
        h = ukf.run(
            mu, rho, prior_mean, prior_cov, process_noise, sigma_points, allow_behind_camera
        )
    return _gaussian_estimate(h.means[..., -1, :], h.covs[..., -1, :, :], h)


def _iterated(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    max_iterations: int = iterated.MAX_ITERATIONS,
) -> Estimate:
    """The iterated EKF (:func:`depthcore.iterated.run`); ``detail`` is its History."""
    if _single(mu):
        _prior(prior_mean, prior_cov)
    means, covs = iterated.run(mu, rho, prior_mean, prior_cov, process_noise, max_iterations)
    _covariance_form(covs[..., -1, :, :], "iterated EKF")
    return _gaussian_estimate(means[..., -1, :], covs[..., -1, :, :], History(means, covs))


def _inverse_depth(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> Estimate:
    """The inverse-depth EKF (:func:`depthcore.inverse_depth.estimate`).

    ``detail`` is its mean and covariance in ``(x, y, v)`` at frame ``N``.
    """
    if _single(mu):
        _prior(prior_mean, prior_cov)
    est = inverse_depth.estimate(mu, rho, prior_mean, prior_cov, process_noise)
    _covariance_form(est.cov, "inverse-depth EKF")
    return _gaussian_estimate(est.mean, est.cov, est)


def _range_parametrised(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    n_components: int = range_ekf.N_COMPONENTS,
    depth_range=None,
) -> Estimate:
    """The range-parametrised EKF (:func:`depthcore.range_ekf.posterior`, Peach 1995).

    ``detail`` is its :class:`~depthcore.range_ekf.GaussianSum`; the estimate's
    mean and covariance are the sum's (law of total variance), so that a study
    scores it, as the other Gaussian filters, by these two moments.
    """
    if _single(mu):
        _prior(prior_mean, prior_cov)
    g = range_ekf.posterior(
        mu, rho, prior_mean, prior_cov, process_noise, n_components, depth_range
    )
    _covariance_form(g.cov, "range-parametrised EKF")
    return _gaussian_estimate(g.mean, g.cov, g)


def _inverse_depth_ukf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = True,
) -> Estimate:
    """The UKF in inverse-depth coordinates (:func:`depthcore.inverse_depth_ukf.estimate`).

    ``detail`` is its mean and covariance in ``(x, y, v)`` at frame ``N``. As
    the UKF's entry, it runs by default even where sigma points lie behind the
    camera (``allow_behind_camera``).
    """
    if _single(mu):
        _prior(prior_mean, prior_cov)
    est = inverse_depth_ukf.estimate(
        mu, rho, prior_mean, prior_cov, process_noise, sigma_points, allow_behind_camera
    )
    _covariance_form(est.cov, "inverse-depth UKF")
    return _gaussian_estimate(est.mean, est.cov, est)


def _modified_polar(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> Estimate:
    """The EKF in modified polar coordinates (:func:`depthcore.modified_polar.estimate`).

    ``detail`` is its mean and covariance in ``(x, y, v)`` at frame ``N``.
    """
    if _single(mu):
        _prior(prior_mean, prior_cov)
    est = modified_polar.estimate(mu, rho, prior_mean, prior_cov, process_noise)
    _covariance_form(est.cov, "modified-polar EKF")
    return _gaussian_estimate(est.mean, est.cov, est)


def _covariance_form(cov, name: str) -> None:
    """Refuse, naming ``rho``, covariances (..., 3, 3) that rounding left not positive definite.

    The filters that carry a covariance (not its square root) lose its small
    eigenvalues to cancellation when the noise is tiny beside the prior.
    """
    cov = np.asarray(cov, dtype=float)
    smallest = np.linalg.eigvalsh(cov)[..., 0]
    if not np.all(smallest > 0):
        raise ValueError(
            f"rho is too small for the {name}, which carries a covariance: rounding "
            f"left its covariance at frame N not positive definite (eigenvalue "
            f"{float(np.min(smallest)):.3g})"
        )


def _resample_move(
    mu,
    rho,
    prior_mean,
    prior_cov,
    rng=None,
    n_particles: int = RESAMPLE_MOVE_PARTICLES,
    replicas: int = resample_move.REPLICAS,
    **options,
) -> Estimate:
    """The causal bootstrap filter with resample-move (:mod:`depthcore.resample_move`).

    ``detail`` is its :class:`~depthcore.resample_move.Replicated`:
    ``replicas`` independent filters of ``n_particles`` each, pooled;
    ``options`` are those of :func:`depthcore.resample_move.run`. The moments
    are the pool's; the errors the larger of those of the mean and of the SD
    from the replicas' spread (Student-t widened), NaN where the replicas
    collapsed (``collapsed``, :meth:`~depthcore.resample_move.Replicated.errors`).
    """
    rng = _rng(rng, "resample-move")
    single = _single(mu)
    if single:
        prior = _prior(prior_mean, prior_cov)
        mu = _checks.finite_array(mu, "mu")
        prior_mean, prior_cov = prior.mean, prior.cov
        rho = _checks.positive_scalar(rho, "rho")
        if mu.ndim != 1:
            raise ValueError(f"mu must have shape (K,), got shape {mu.shape}")
        mu = mu[None]
    r = resample_move.replicated(
        mu, rho, prior_mean, prior_cov, n_particles, rng, replicas, **options
    )
    mean, cov = weighted_mean_and_cov(r.particles, np.exp(r.log_weights))
    m = r.moments()
    errors, collapsed = r.errors()
    depth_error = np.maximum(errors["depth_mean"], errors["depth_sd"])
    velocity_error = np.maximum(errors["velocity_mean"], errors["velocity_sd"])
    if single:
        m = {k: float(v[0]) for k, v in m.items()}
        mean, cov = mean[0], cov[0]
        depth_error, velocity_error = float(depth_error[0]), float(velocity_error[0])
        collapsed = bool(collapsed[0])
    return Estimate(
        m["depth_mean"],
        m["depth_sd"],
        m["velocity_mean"],
        m["velocity_sd"],
        depth_error,
        velocity_error,
        mean,
        cov,
        r,
        collapsed=collapsed,
    )


def _rbpf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    rng=None,
    n_particles: int = RBPF_PARTICLES,
    replicas: int = RBPF_REPLICAS,
    **options,
) -> Estimate:
    """The Rao-Blackwellised particle filter (:mod:`depthcore.rbpf`, textbook 19.5.3).

    ``detail`` is its :class:`~depthcore.rbpf.RBPF`: ``replicas`` independent
    clouds of ``n_particles`` depths, each carrying the Kalman filter of
    ``(x, v)``; ``options`` are those of :func:`depthcore.rbpf.run`. The
    moments are those of the replicas pooled into one mixture
    (:meth:`~depthcore.rbpf.RBPF.state_moments`, the law of total variance
    over the particles' filters); the errors are the larger of the errors of
    the mean and of the SD from the replicas' spread, Student-t widened, NaN
    with one replica or where the replicas collapsed (``collapsed``,
    :meth:`~depthcore.rbpf.RBPF.errors`).
    """
    rng = _rng(rng, "Rao-Blackwellised particle")
    if _single(mu):
        _prior(prior_mean, prior_cov)
    f = rbpf.run(
        mu,
        rho,
        prior_mean,
        prior_cov,
        n_particles,
        rng,
        process_noise=process_noise,
        replicas=replicas,
        **options,
    )
    mean, cov = f.state_moments()
    se, collapsed = f.errors()
    depth_error = np.maximum(se.depth_mean, se.depth_sd)
    velocity_error = np.maximum(se.velocity_mean, se.velocity_sd)
    if _single(mu):
        depth_error, velocity_error = float(depth_error), float(velocity_error)
        collapsed = bool(collapsed)
    e = _gaussian_estimate(mean, cov, f)
    return Estimate(
        e.depth_mean,
        e.depth_sd,
        e.velocity_mean,
        e.velocity_sd,
        depth_error,
        velocity_error,
        e.mean,
        e.cov,
        f,
        collapsed=collapsed,
    )


def _rng(rng, name: str) -> np.random.Generator:
    """``rng`` as a Generator; ``None`` is refused, naming ``rng``."""
    if rng is None:
        raise ValueError(
            f"rng is required to run the {name} filter: pass a "
            "numpy.random.Generator or SeedSequence"
        )
    return _checks.generator(rng)


def _particle(
    mu, rho, prior_mean, prior_cov, rng=None, n_particles: int = PARTICLES, **options
) -> Estimate:
    """The particle filter; ``detail`` is its ParticleResult (one triple) or ParticleBatch.

    ``rng``, a ``numpy.random.Generator`` or a ``SeedSequence`` (or an int
    seed), is required; ``options`` are those of :func:`depthcore.particle.run`.
    The errors are the larger of the delta-method standard errors of the mean
    and of the SD; NaN where the weight sits on fewer than
    ``resampling.MIN_EFFECTIVE_DRAWS`` distinct particles (``collapsed``,
    :meth:`~depthcore.particle.ParticleResult.collapsed`).
    """
    rng = _rng(rng, "particle")
    if _single(mu):
        r = particle.particle_filter(
            mu, rho, _prior(prior_mean, prior_cov), n_particles, rng, **options
        )
        m, se, collapsed = r.moments(), r.standard_errors(), r.collapsed()
        mean, cov = weighted_mean_and_cov(r.particles, r.weights)
        nan = np.nan if collapsed else 0.0
        return Estimate(
            float(m.depth_mean),
            float(m.depth_sd),
            float(m.velocity_mean),
            float(m.velocity_sd),
            float(max(se.depth_mean, se.depth_sd)) + nan,
            float(max(se.velocity_mean, se.velocity_sd)) + nan,
            mean,
            cov,
            r,
            collapsed=collapsed,
        )
    b = particle.run(mu, rho, prior_mean, prior_cov, n_particles, rng, **options)
    m, se, collapsed = b.moments(), b.standard_errors(), b.collapsed()
    mean, cov = weighted_mean_and_cov(b.particles, np.exp(b.log_weights))
    return Estimate(
        m.depth_mean,
        m.depth_sd,
        m.velocity_mean,
        m.velocity_sd,
        np.where(collapsed, np.nan, np.maximum(se.depth_mean, se.depth_sd)),
        np.where(collapsed, np.nan, np.maximum(se.velocity_mean, se.velocity_sd)),
        mean,
        cov,
        b,
        collapsed=collapsed,
    )


def _optimal_smoother(mu, rho, prior_mean, prior_cov, process_noise):
    """The exact filter and its fixed-interval smoother: :func:`depthcore.bank_track.track`.

    The bearings are added online (:func:`depthcore.bank_posterior.update`); the smoothed
    state is each depth node's Rauch-Tung-Striebel smoother mixed over the
    nodes (textbook 19.2.6, :meth:`depthcore.bank_mixture.Mixture.smoothed`).
    """
    t = bank_track.track(mu, rho, prior_mean, prior_cov, process_noise, lag=mu.size - 1)
    return t.filtered, t.interval, t


def _gaussian_smoother(name: str):
    """The Gaussian filter ``name`` at every frame and the Rauch-Tung-Striebel smoother over it.

    The motion, Eq. (1) with the process noise on the velocity, is linear
    (``x_{k+1} = F x_k + e``), so every Gaussian filter predicts exactly
    (Eq. (10)): the predicted Gaussian at frame ``k + 1`` is ``F m_k + e``,
    ``F P_k F^T + diag(0, 0, q**2)``, and the backward recursions of textbook
    19.2.6 (:func:`depthcore.kalman.fixed_interval_smoother`) run over the
    filter's own Gaussians: for the EKF this is the extended Kalman smoother
    (textbook 19.3), for the UKF the unscented one.
    """

    def smoother(mu, rho, prior_mean, prior_cov, process_noise):
        h = FILTERS[name](mu, rho, prior_mean, prior_cov, process_noise=process_noise).detail
        means, covs = h.means, h.covs
        predicted = ekf.predict(means[:-1], covs[:-1], process_noise)
        filtered = kalman.FilterResult(
            means,
            covs,
            np.concatenate([prior_mean[None], predicted.mean]),
            np.concatenate([prior_cov[None], predicted.cov]),
            np.zeros(means.shape[0]),
        )
        s = kalman.fixed_interval_smoother(filtered, model.F)
        return bank_mixture.Smoothed(means, covs), bank_mixture.Smoothed(s.mean, s.cov), h

    return smoother


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
            any_frames=True,
            with_process_noise=True,
            smoother=_optimal_smoother,
        ),
        Filter(
            "second_order",
            "second order $p_s$",
            {"color": "tab:blue", "linestyle": "--"},
            "gaussian",
            True,
            _second_order,
            tuple((r, "all", {"reading": r}) for r in second_order.READINGS),
            any_frames=True,
            with_process_noise=True,
        ),
        Filter(
            "ekf",
            "EKF $p_e$",
            {"color": "tab:red", "linestyle": ":"},
            "gaussian",
            True,
            _ekf,
            (("printed", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            smoother=_gaussian_smoother("ekf"),
        ),
        Filter(
            "ukf",
            "UKF",
            {"color": "tab:green", "linestyle": "-."},
            "gaussian",
            False,
            _ukf,
            (("-", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            smoother=_gaussian_smoother("ukf"),
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
            any_frames=True,
        ),
        Filter(
            "iterated",
            "iterated EKF",
            {"color": "tab:orange", "linestyle": "--"},
            "gaussian",
            False,
            _iterated,
            (("-", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            default=False,
        ),
        Filter(
            "inverse_depth",
            "inverse-depth EKF",
            {"color": "tab:brown", "linestyle": ":"},
            "gaussian",
            False,
            _inverse_depth,
            (("-", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            default=False,
        ),
        Filter(
            "resample_move",
            "resample-move particle filter",
            {"color": "tab:pink", "linestyle": "-."},
            "particles",
            False,
            _resample_move,
            (("-", "front", {}),),
            random=True,
            any_frames=True,
            default=False,
        ),
        Filter(
            "rbpf",
            "Rao-Blackwellised particle filter",
            {"color": "tab:olive", "linestyle": "--"},
            "rao_blackwellised",
            False,
            _rbpf,
            (("-", "front", {}),),
            random=True,
            any_frames=True,
            with_process_noise=True,
            default=False,
        ),
        Filter(
            "range_parametrised",
            "range-parametrised EKF",
            {"color": "tab:cyan", "linestyle": "-."},
            "gaussian",
            False,
            _range_parametrised,
            (("-", "front", {}),),
            any_frames=True,
            with_process_noise=True,
            default=False,
        ),
        Filter(
            "inverse_depth_ukf",
            "inverse-depth UKF",
            {"color": "tab:gray", "linestyle": "--"},
            "gaussian",
            False,
            _inverse_depth_ukf,
            (("-", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            default=False,
        ),
        Filter(
            "modified_polar",
            "modified-polar EKF",
            {"color": "tab:blue", "linestyle": (0, (1, 1))},
            "gaussian",
            False,
            _modified_polar,
            (("-", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            default=False,
        ),
    )
}

#: The paper's three filters.
PAPER_FILTERS = tuple(name for name, f in FILTERS.items() if f.in_paper)
#: The filters of the default outputs (tables, studies, sweeps, figures, the command line):
#: the paper's three, the UKF and the particle filter.
NAMES = tuple(name for name, f in FILTERS.items() if f.default)
#: Every registered filter's name, the N-frame filters run only when named among them.
ALL_NAMES = tuple(FILTERS)


def get(name: str) -> Filter:
    """The filter called ``name``; a :class:`ValueError` lists the names if there is none."""
    if name not in FILTERS:
        raise ValueError(f"filter must be one of {ALL_NAMES}, got {name!r}")
    return FILTERS[name]


def check_names(names) -> tuple:
    """Return ``names`` as a tuple after checking each is in the registry."""
    names = tuple(names)
    unknown = set(names) - set(FILTERS)
    if unknown:
        raise ValueError(f"filters must be among {ALL_NAMES}, got {sorted(unknown)}")
    return names


#: The noise levels ``rho`` that :func:`track` answers for (and the command line's ``--rho``).
RHO_RANGE = (1e-12, 1e3)
#: The largest process noise that :func:`track` answers for (and the command line's).
PROCESS_NOISE_MAX = 10.0
#: The names a message refusing :func:`track`'s inputs may start with.
_TRACK_ARGUMENTS = ("mu", "rho", "prior", "process_noise", "filter")

#: The filters with a smoother, which :func:`track` runs.
SMOOTHED = tuple(name for name, f in FILTERS.items() if f.smoother is not None)


@dataclass(frozen=True)
class Track:
    """One track's state at every frame, filtered and smoothed (:func:`track`).

    Frame ``k`` is row ``k - 1`` of every array; ``N`` is the number of bearings.
    Depths are in units of the camera's forward motion per frame (the depth
    grows by 1 from frame to frame, Eq. (1)); the lateral position ``x`` in
    the same units; the velocity ``v`` is ``x``'s change per frame.

    Attributes
    ----------
    filter : str
        The registry's name of the filter.
    filtered : depthcore.bank_mixture.Smoothed
        The state at frame ``k`` given ``mu_1 .. mu_k``: a
        :class:`~depthcore.bank_mixture.Smoothed` of means (N, 3) and covariances
        (N, 3, 3) of ``(x_k, y_k, v_k)``, whose ``depth_mean``, ``depth_sd``,
        ``lateral_mean``, ``lateral_sd``, ``velocity_mean`` and
        ``velocity_sd`` have shape (N,).
    smoothed : depthcore.bank_mixture.Smoothed
        The state at frame ``k`` given all ``N`` bearings (the fixed-interval
        smoother, textbook 19.2.6); at frame ``N`` it is the filtered state.
    prior : depthcore.gaussian.Gaussian
        The prior of the state at frame 1 that the filter used.
    process_noise : float
    detail : object
        The filter's own result: the exact filter's :class:`~depthcore.bank_track.Track`,
        a Gaussian filter's :class:`~depthcore.gaussian.History`.
    """

    filter: str
    filtered: Any
    smoothed: Any
    prior: Gaussian
    process_noise: float
    detail: Any = None

    @property
    def frames(self) -> np.ndarray:
        """The frame numbers ``1 .. N``, shape (N,)."""
        return np.arange(1, self.filtered.mean.shape[0] + 1)


def track(mu, rho, prior=None, process_noise=0.0, filter: str = "optimal") -> Track:
    """Filter and smooth one track: depth, lateral position and velocity at every frame.

    Parameters
    ----------
    mu : array_like, shape (N,)
        The bearings of frames ``1 .. N``, ``3 <= N <= depthcore._checks.MAX_FRAMES``:
        ``mu_k = x_k / y_k``, the tangent of the angle between the point and the
        camera's direction of motion (from pixel columns,
        :func:`depthcore.model.bearings_from_pixels`); checked by
        :func:`depthcore.model.measurements_batch`.
    rho : float
        The SD of the bearings' noise, in :data:`RHO_RANGE` (in the units of
        ``mu``: a pixel noise of SD ``s`` is ``rho = s / f`` for a focal
        length of ``f`` pixels).
    prior : depthcore.gaussian.Gaussian, optional
        The prior of the state ``(x_1, y_1, v_1)`` at frame 1; by default the
        paper's rule applied to the first three bearings
        (:func:`depthcore.gaussian.paper_prior` of their noise-free state,
        Eq. (7)), refused when those bearings put the point behind the camera
        or are degenerate.
    process_noise : float
        ``q``, the SD of the velocity's change per frame: 0 (constant velocity)
        or from ``depthcore._checks.MIN_PROCESS_NOISE`` to :data:`PROCESS_NOISE_MAX`.
    filter : str
        A filter with a smoother, one of :data:`SMOOTHED`: ``"optimal"`` (the
        exact filter, a bank of Kalman filters over depth, and its
        smoother), ``"ekf"`` (the extended Kalman filter and smoother),
        ``"ukf"`` (the unscented ones). The others, without a smoother, are
        refused, naming ``filter``.

    Returns
    -------
    Track
        ``filtered`` and ``smoothed`` means and SDs of ``x``, ``y`` (the depth)
        and ``v`` at every frame, arrays of shape (N,).

    Examples
    --------
    >>> import depthcore
    >>> t = depthcore.track([0.1, 0.2, 0.28, 0.35], rho=0.002)
    >>> t.smoothed.depth_mean.shape
    (4,)
    """
    if not isinstance(filter, str) or filter not in FILTERS:
        raise ValueError(f"filter must be one of {SMOOTHED}, got {filter!r}")
    entry = FILTERS[filter]
    if entry.smoother is None:
        raise ValueError(
            f"filter must be one of {SMOOTHED}, the filters with a smoother; {filter!r} has none"
        )
    mu = model.measurements_batch(mu, "mu")
    if mu.ndim != 1:
        raise ValueError(f"mu must have shape (N,), one track, got shape {mu.shape}")
    rho = _checks.positive_scalar(rho, "rho")
    if not RHO_RANGE[0] <= rho <= RHO_RANGE[1]:
        raise ValueError(f"rho must be from {RHO_RANGE[0]:g} to {RHO_RANGE[1]:g}, got {rho!r}")
    q = _checks.process_noise(process_noise, "process_noise")
    if q > PROCESS_NOISE_MAX:
        raise ValueError(f"process_noise must be at most {PROCESS_NOISE_MAX:g}, got {q!r}")
    if prior is None:
        try:
            c = model.noise_free_state(mu[:3])
        except ValueError as exc:
            raise ValueError(
                f"prior is needed: the paper's rule cannot use the first three bearings ({exc})"
            ) from None
        prior = paper_prior(c)
    elif not isinstance(prior, Gaussian):
        raise ValueError(
            f"prior must be a depthcore.Gaussian of the state at frame 1 or None, "
            f"got {type(prior).__name__}"
        )
    try:
        filtered, smoothed, detail = entry.smoother(mu, rho, prior.mean, prior.cov, q)
    except (ValueError, np.linalg.LinAlgError) as exc:
        message = str(exc)
        if isinstance(exc, ValueError) and message.startswith(_TRACK_ARGUMENTS):
            raise
        raise ValueError(
            f"mu, rho and prior have no answer from the {filter} filter ({message}); "
            "try another filter, a larger rho or a broader prior"
        ) from None
    for series in (filtered, smoothed):
        variances = np.diagonal(series.cov, axis1=-2, axis2=-1)
        if not (np.all(np.isfinite(series.mean)) and np.all(variances >= 0)):
            raise ValueError(
                f"rho is too small beside the prior for the {filter} filter's "
                f"smoother: its moments are not finite (rho = {rho!r})"
            )
    return Track(filter, filtered, smoothed, prior, q, detail)
