"""The filters, in one registry: every filter by name, one calling convention, one result shape.

Recommended import: ``from depthcore.registry.filters import FILTERS``.

Each entry of :data:`FILTERS` is a :class:`Filter`. Calling it::

    estimate = FILTERS[name](mu, rho, prior_mean, prior_cov, process_noise=0.0,
                             steps=None, gate=None, **options)

runs the filter on one sequence of ``N`` bearings (``mu`` of shape ``(N,)``;
the paper's triple is ``N = 3``) or on a batch (``mu`` of shape ``(B, N)``,
``rho`` a float or shape ``(B,)``, or one per frame, ``(N,)`` or ``(B, N)``;
``NaN`` in ``mu`` marks a missing frame; ``steps`` the depth's change between
frames; ``gate`` an outlier gate, :mod:`depthcore.problem.predictive`), the
prior's mean ``(3,)`` or ``(B, 3)`` and covariance ``(3, 3)``), with process
noise ``a_k ~ N(0, q**2 s_k)`` on the velocity if ``process_noise = q > 0`` (the N-frame model of
:mod:`depthcore.exact.bank`; the prior is on the state at frame 1), and returns an
:class:`~depthcore.registry.estimates.Estimate`: the depth and velocity means and SDs at frame
``N`` (time 3
for a triple; floats for one sequence, arrays of shape ``(B,)`` for a batch),
their numerical or Monte Carlo errors where the filter has them, the mean and
covariance of the whole state, and the filter's own result (``detail``). The entry also carries the
filter's label and plot style, the table rows it contributes to
:func:`depthcore.studies.reproduce.reproduce` (``variants``), how its estimates
are scored (``family``, whose :class:`~depthcore.registry.estimates.Family` in
:data:`~depthcore.registry.estimates.FAMILY`, the entry's
``scoring``, holds what a study reads of its results: whether it is the exact
reference, a Gaussian, or weighted draws of the depth, and its CDFs and
densities), its smoother if it has one (``smoother``, which
:func:`~depthcore.registry.tracking.track`
runs over one track), and what it supports: ``any_frames`` (any
``N >= 3`` bearings, up to ``depthcore.problem.checks.MAX_FRAMES``, or only the
paper's three) and ``with_process_noise`` (``q > 0`` or only ``q = 0``); a
call outside them is refused with a :class:`ValueError` naming ``mu`` or
``process_noise``. :mod:`depthcore.studies.reproduce`, :mod:`depthcore.studies.monte_carlo`,
the command line and the book's chapters (:mod:`depthbook`)
iterate the entries marked ``default`` (:data:`NAMES`), which are the five of
the paper's problem; the N-frame filters (``iterated``, ``inverse_depth``,
``resample_move``, ``rbpf``) are registered with ``default=False`` and run only when
named (:data:`ALL_NAMES`, every filter the studies of all filters run, the atlas's
among them). MonoSLAM's depth hypotheses (``depth_hypotheses``) are registered after
:data:`ALL_NAMES` was fixed, outside it: they run only when named, and the atlas's
record stands without them.

Adding a filter to the package means three things: its module in its family
(:mod:`depthcore.kalman`, :mod:`depthcore.exact`, :mod:`depthcore.particles`),
its entry in :data:`FILTERS` below, and its test; the command line, the
studies and the API reference then list it. A filter of one's own, outside the
package, joins the registry with :func:`register`, and the command line run in
the same process takes it by name.

The filters: the paper's optimal filter (:mod:`depthcore.exact.optimal`, Eqs.
(6), (13)-(16)), second-order approximation (:mod:`depthcore.kalman.second_order`,
Eq. (8)) and EKF (:mod:`depthcore.kalman.ekf`, Eqs. (10)-(12)); beyond the paper,
the unscented Kalman filter (:mod:`depthcore.kalman.ukf`) and a particle filter
(:mod:`depthcore.particles.importance`); for N frames, the iterated EKF
(:mod:`depthcore.kalman.iterated`), the inverse-depth EKF
(:mod:`depthcore.kalman.inverse_depth`), the causal bootstrap particle filter with
resample-move (:mod:`depthcore.particles.resample_move`), the Rao-Blackwellised
particle filter (:mod:`depthcore.particles.rbpf`), the range-parametrised EKF
(:mod:`depthcore.kalman.range_ekf`), the inverse-depth UKF
(:mod:`depthcore.kalman.inverse_depth_ukf`), the EKF in modified polar coordinates
(:mod:`depthcore.kalman.modified_polar`) and MonoSLAM's depth initialisation, a grid of
depth hypotheses that collapses to the EKF (:mod:`depthcore.particles.depth_hypotheses`);
and, as a baseline without a prior, the
batch maximum-likelihood estimate (:mod:`depthcore.analysis.batch_ml`, ``batch_ml``: the
state that maximises the likelihood of all the bearings, with the inverse Fisher
information there as its covariance; ``q = 0`` only), which ignores the prior it is given.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass, field

import numpy as np

from depthcore.analysis import batch_ml
from depthcore.exact import optimal
from depthcore.exact import spatial as exact_spatial
from depthcore.kalman import (
    ekf,
    inverse_depth,
    inverse_depth_ukf,
    iterated,
    modified_polar,
    range_ekf,
    second_order,
    spatial,
    spatial_inverse,
    ukf,
)
from depthcore.particles import depth_hypotheses, importance, rbpf, resample_move
from depthcore.problem import checks, frames, model, predictive
from depthcore.problem.gaussian import Gaussian
from depthcore.registry import adapters
from depthcore.registry.adapters import checked_gaussian, gaussian_smoother
from depthcore.registry.estimates import FAMILY, Estimate, Family, check_quantity


@dataclass(frozen=True)
class Filter:
    """One filter of the registry: ``Filter(name, run, **keywords)``.

    ``name`` and ``run`` are all a Gaussian filter on the paper's three frames
    needs; every other attribute is a keyword with a default.

    Attributes
    ----------
    name : str
    label : str
        Legend label (LaTeX allowed); default the name.
    style : dict
        Matplotlib line properties (colour, line style); default none, the
        plot's next colour.
    family : {"exact", "gaussian", "particles", "rao_blackwellised"}
        Default ``"gaussian"``.
    in_paper : bool
        Whether the paper compares it; default False.
    run : callable
        The filter's door, a batched function of its module:
        ``run(mu, rho, prior_mean, prior_cov, **options)``, and also
        ``process_noise=q`` when ``with_process_noise``, with ``mu`` of shape
        ``(N,)`` or ``(B, N)``; it returns the filter's own result.
    variants : tuple of (str, str, dict)
        ``(reading, support, options)`` of each row the filter contributes to
        the reproduction tables; default one row, ``("-", "all", {})``.
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
        track of ``N`` bearings, checked by :func:`~depthcore.registry.tracking.track` (which calls
        it):
        ``(filtered, smoothed, detail)``, the state at every frame given the
        bearings up to it and given all of them, each a
        :class:`~depthcore.exact.mixture.Smoothed` of means (N, 3) and covariances
        (N, 3, 3), and the filter's own result. ``None`` for a filter
        without a smoother.
    estimate : callable or None
        ``estimate(result, single) -> Estimate``: reads ``run``'s result (of one
        sequence if ``single``), one of :mod:`depthcore.registry.adapters`;
        ``None`` when ``run`` returns an :class:`~depthcore.registry.estimates.Estimate` itself.
    options : dict
        The registry's defaults of ``run``'s options (the number of particles,
        say), which a call's own options override.
    spatial : callable or None
        The filter's door for a point in 3-D, ``spatial(mu, rho, prior_mean,
        prior_cov, process_noise=q, steps=steps)`` with ``mu`` of shape
        ``(..., N, 2)`` (pairs ``(x / y, h / y)``) and a prior on ``(x, y, v, h,
        w)``, returning a result with ``mean`` (..., 5) and ``cov`` (..., 5, 5);
        ``None``: pairs are refused, naming ``mu``.
    """

    name: str
    run: Callable[..., Estimate]
    _: KW_ONLY
    label: str = ""
    style: dict = field(default_factory=dict)
    family: str = "gaussian"
    in_paper: bool = False
    variants: tuple = (("-", "all", {}),)
    random: bool = False
    any_frames: bool = False
    with_process_noise: bool = False
    default: bool = True
    smoother: Callable | None = None
    estimate: Callable | None = None
    options: dict = field(default_factory=dict)
    spatial: Callable | None = None

    def __post_init__(self):
        if not self.label:
            object.__setattr__(self, "label", self.name)

    def __call__(
        self, mu, rho, prior_mean, prior_cov, process_noise=0.0, steps=None, gate=None, **options
    ) -> Estimate:
        """Run the filter; see the module docstring for the arguments and their shapes.

        Every number goes through one conversion, :func:`depthcore.problem.checks.as_float`
        (lists and arrays of integers or floats; complex, boolean, object and
        text values are refused by name). ``mu`` is checked by
        :func:`depthcore.problem.model.measurements_batch` (and must have 3 columns
        unless ``any_frames``), or, with a missing bearing (``NaN``), ``rho``
        per frame or ``steps``, by :func:`depthcore.problem.frames.check`; for one
        sequence ``rho`` is a number (a float, a 0-d array or a list of one) or
        one per frame, shape (N,); ``process_noise`` is checked by
        :func:`depthcore.problem.checks.process_noise`, and must be 0 unless
        ``with_process_noise``. ``steps`` (N - 1,) or (B, N - 1) and ``gate``
        (:func:`depthcore.problem.predictive.gate`) go to the filter's door; a
        door that does not take them refuses steps other than ones, or a gate,
        naming the argument, before it runs.
        """
        mu_arr = checks.as_float(mu, "mu")
        if mu_arr.ndim >= 2 and mu_arr.shape[-1] == 2:  # pairs: a point in 3-D
            return self._pairs(mu_arr, rho, prior_mean, prior_cov, process_noise, steps, gate)
        rho = checks.as_float(rho, "rho")
        per_frame = rho.ndim > 0 and rho.shape == mu_arr.shape
        if steps is None and not per_frame and not np.any(np.isnan(mu_arr)):
            mu = model.measurements_batch(mu_arr, "mu")
        else:
            checked = frames.check(mu_arr, rho, steps)
            mu = checked.mu
            if steps is not None and np.all(checked.steps == 1.0) and "steps" not in self.takes:
                steps = None
        if mu.shape[-1] != 3 and not self.any_frames:
            raise ValueError(
                f"mu must have shape (3,) or (B, 3): the {self.name} filter takes the "
                f"paper's three frames, got {mu.shape[-1]} bearings per problem"
            )
        single = mu.ndim == 1
        if single and not per_frame:
            rho = checks.number(rho, "rho")
        prior_mean = checks.as_float(prior_mean, "prior_mean")
        prior_cov = checks.as_float(prior_cov, "prior_cov")
        if single:
            Gaussian.prior(prior_mean, prior_cov)
        q = checks.process_noise(process_noise, "process_noise")
        gate = predictive.gate(gate)
        options = {**self.options, **options}
        for name, value, refusal in (
            ("steps", steps, f"steps: the {self.name} filter takes only unit steps"),
            ("gate", gate, f"gate: the {self.name} filter has no gate"),
        ):
            if name in self.takes:
                options[name] = value
            elif value is not None:
                raise ValueError(refusal)
        if self.random:
            options["rng"] = adapters.required_rng(options.get("rng"), f"{self.name} filter")
        if self.with_process_noise:
            options["process_noise"] = q
        elif q > 0:
            raise ValueError(
                f"process_noise must be 0 for the {self.name} filter, which supports "
                f"only the constant-velocity motion, got {q:g}"
            )
        result = self.run(mu, rho, prior_mean, prior_cov, **options)
        return result if self.estimate is None else self.estimate(result, single)

    def _pairs(self, mu, rho, prior_mean, prior_cov, process_noise, steps, gate) -> Estimate:
        """:meth:`__call__` for a point in 3-D: the filter's :attr:`spatial` door."""
        if self.spatial is None:
            with_pairs = ", ".join(n for n, f in FILTERS.items() if f.spatial is not None)
            raise ValueError(
                f"mu of shape {mu.shape} holds pairs (x / y, h / y), a point in 3-D, which "
                f"the {self.name} filter does not take ({with_pairs} do)"
            )
        if gate is not None:
            raise ValueError("gate: the filters of a point in 3-D have no gate")
        q = checks.process_noise(process_noise, "process_noise")
        result = self.spatial(mu, rho, prior_mean, prior_cov, process_noise=q, steps=steps)
        variances = np.diagonal(np.asarray(result.cov), axis1=-2, axis2=-1)
        if not np.all(variances >= 0):  # NaN too
            raise ValueError(
                f"mu and rho lead the {self.name} filter of pairs to a variance that is negative "
                "or not a number (a rho tiny beside the prior); try a larger rho"
            )
        return adapters.spatial(result, mu.ndim == 2)

    @property
    def takes(self) -> frozenset:
        """The names of the keyword arguments the filter's door declares."""
        try:
            return frozenset(inspect.signature(self.run).parameters)
        except (TypeError, ValueError):
            return frozenset()

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
        check_quantity(quantity)
        return self.scoring.density(estimate, quantity, np.asarray(grid, dtype=float))

    @property
    def scoring(self) -> Family:
        """The :class:`~depthcore.registry.estimates.Family` of its ``family``, which says how its
        results
        are scored."""
        return FAMILY[self.family]


#: Particles of the importance sampler unless a caller asks for another number.
PARTICLES = 20_000

#: Particles per replica of the resample-move filter, by default (``resample_move.REPLICAS``
#: replicas: the same 20,000 particles in all as the importance sampler).
RESAMPLE_MOVE_PARTICLES = 5000

#: Particles per replica of the Rao-Blackwellised particle filter, by default.
RBPF_PARTICLES = 1000

#: Independent replicas of the Rao-Blackwellised particle filter, for its standard errors.
RBPF_REPLICAS = 4

#: Every filter, in the order of the tables and legends.
FILTERS: dict[str, Filter] = {
    f.name: f
    for f in (
        Filter(
            "optimal",
            optimal.run,
            label="optimal $p_o$",
            style={"color": "black", "linestyle": "-"},
            family="exact",
            in_paper=True,
            variants=tuple(
                (r, s, {"reading": r, "support": s})
                for r in optimal.READINGS
                for s in optimal.SUPPORTS
            ),
            any_frames=True,
            with_process_noise=True,
            smoother=adapters.smooth_optimal,
            estimate=adapters.exact,
            spatial=exact_spatial.posterior,
        ),
        Filter(
            "second_order",
            second_order.run,
            label="second order $p_s$",
            style={"color": "tab:blue", "linestyle": "--"},
            in_paper=True,
            variants=tuple((r, "all", {"reading": r}) for r in second_order.READINGS),
            any_frames=True,
            with_process_noise=True,
            estimate=adapters.gaussian,
        ),
        Filter(
            "ekf",
            ekf.run,
            label="EKF $p_e$",
            style={"color": "tab:red", "linestyle": ":"},
            in_paper=True,
            variants=(("printed", "all", {}),),
            any_frames=True,
            with_process_noise=True,
            smoother=gaussian_smoother(ekf.run),
            estimate=adapters.gaussian,
            spatial=functools.partial(spatial.run, filter="ekf"),
        ),
        Filter(
            "ukf",
            ukf.run,
            label="UKF",
            style={"color": "tab:green", "linestyle": "-."},
            any_frames=True,
            with_process_noise=True,
            smoother=gaussian_smoother(ukf.run, allow_behind_camera=True),
            estimate=adapters.unscented,
            options={"allow_behind_camera": True},
            spatial=functools.partial(spatial.run, filter="ukf"),
        ),
        Filter(
            "particle",
            importance.run,
            label="importance sampling, $q$ from $p_s$",
            style={"color": "tab:purple", "linestyle": (0, (5, 1, 1, 1, 1, 1))},
            family="particles",
            variants=(("-", "front", {}),),
            random=True,
            any_frames=True,
            estimate=adapters.particles,
            options={"n_particles": PARTICLES},
        ),
        Filter(
            "iterated",
            iterated.run,
            label="iterated EKF",
            style={"color": "tab:orange", "linestyle": "--"},
            any_frames=True,
            with_process_noise=True,
            default=False,
            estimate=checked_gaussian("iterated EKF"),
            spatial=functools.partial(spatial.run, filter="iterated"),
        ),
        Filter(
            "inverse_depth",
            inverse_depth.estimate,
            label="inverse-depth EKF",
            style={"color": "tab:brown", "linestyle": ":"},
            any_frames=True,
            with_process_noise=True,
            default=False,
            estimate=checked_gaussian("inverse-depth EKF"),
            spatial=spatial_inverse.run,
        ),
        Filter(
            "resample_move",
            resample_move.replicated,
            label="resample-move particle filter",
            style={"color": "tab:pink", "linestyle": "-."},
            family="particles",
            variants=(("-", "front", {}),),
            random=True,
            any_frames=True,
            default=False,
            estimate=adapters.replicas,
            options={"n_particles": RESAMPLE_MOVE_PARTICLES, "replicas": resample_move.REPLICAS},
        ),
        Filter(
            "rbpf",
            rbpf.run,
            label="Rao-Blackwellised particle filter",
            style={"color": "tab:olive", "linestyle": "--"},
            family="rao_blackwellised",
            variants=(("-", "front", {}),),
            random=True,
            any_frames=True,
            with_process_noise=True,
            default=False,
            estimate=adapters.rao_blackwellised,
            options={"n_particles": RBPF_PARTICLES, "replicas": RBPF_REPLICAS},
        ),
        Filter(
            "range_parametrised",
            range_ekf.posterior,
            label="range-parametrised EKF",
            style={"color": "tab:cyan", "linestyle": "-."},
            variants=(("-", "front", {}),),
            any_frames=True,
            with_process_noise=True,
            default=False,
            estimate=checked_gaussian("range-parametrised EKF"),
        ),
        Filter(
            "inverse_depth_ukf",
            inverse_depth_ukf.estimate,
            label="inverse-depth UKF",
            style={"color": "tab:gray", "linestyle": "--"},
            any_frames=True,
            with_process_noise=True,
            default=False,
            estimate=checked_gaussian("inverse-depth UKF"),
            options={"allow_behind_camera": True},
        ),
        Filter(
            "modified_polar",
            modified_polar.estimate,
            label="modified-polar EKF",
            style={"color": "tab:blue", "linestyle": (0, (1, 1))},
            any_frames=True,
            with_process_noise=True,
            default=False,
            estimate=checked_gaussian("modified-polar EKF"),
        ),
        Filter(
            "batch_ml",
            batch_ml.run,
            label="batch maximum likelihood",
            style={"color": "dimgray", "linestyle": (0, (3, 1, 1, 1))},
            variants=(("-", "front", {}),),
            any_frames=True,
            default=False,
            estimate=adapters.maximum_likelihood,
        ),
    )
}


def register(entry: Filter) -> Filter:
    """Add a filter to :data:`FILTERS`, where the command line and the studies find it by name.

    Parameters
    ----------
    entry : Filter
        The new filter. Its name must be a Python identifier not yet taken, its
        family one of :data:`~depthcore.registry.estimates.FAMILY`; its ``run``
        follows the registry's calling convention (the module docstring).

    Returns
    -------
    Filter
        ``entry``, registered.

    Raises
    ------
    ValueError
        Naming ``entry`` when it is not a :class:`Filter`, its name is taken or
        not an identifier, or its family is unknown.

    Notes
    -----
    :data:`NAMES`, :data:`ALL_NAMES`, :data:`PAPER_FILTERS` and :data:`SMOOTHED`
    list the package's own filters, fixed when the module is imported; a
    registered filter is read from :data:`FILTERS` (:func:`names`).
    """
    if not isinstance(entry, Filter):
        raise ValueError(f"entry must be a Filter, got {type(entry).__name__}")
    if not entry.name.isidentifier():
        raise ValueError(f"entry's name must be a Python identifier, got {entry.name!r}")
    if entry.name in FILTERS:
        raise ValueError(f"entry's name {entry.name!r} is taken: a filter of that name exists")
    if entry.family not in FAMILY:
        raise ValueError(f"entry's family must be one of {tuple(FAMILY)}, got {entry.family!r}")
    FILTERS[entry.name] = entry
    return entry


def names(default: bool = False, smoothed: bool = False) -> tuple:
    """The registered filters' names, in the registry's order, registered ones included.

    Parameters
    ----------
    default : bool
        Only those of the default outputs (``Filter.default``).
    smoothed : bool
        Only those with a smoother (``Filter.smoother``).
    """
    return tuple(
        n
        for n, f in FILTERS.items()
        if (f.default or not default) and (f.smoother is not None or not smoothed)
    )


#: The paper's three filters.
PAPER_FILTERS = tuple(name for name, f in FILTERS.items() if f.in_paper)

#: The filters of the default outputs (tables, studies, sweeps, figures, the command line):
#: the paper's three, the UKF and the particle filter.
NAMES = names(default=True)

#: The filters of the entries above, the N-frame filters run only when named among them, which
#: the studies of every filter run (the atlas, :mod:`depthcore.studies.atlas`). A filter
#: registered after (below, or by :func:`register`) is read from :data:`FILTERS` (:func:`names`).
ALL_NAMES = names()

#: The filters with a smoother, which :func:`~depthcore.registry.tracking.track` runs.
SMOOTHED = names(smoothed=True)

# --- filters run only when named --------------------------------------------------------
#
# Registered after ALL_NAMES, so that the atlas, which runs every filter of ALL_NAMES, and
# its record stand without them: each runs when named (the command line, a study's names).

FILTERS["depth_hypotheses"] = Filter(
    "depth_hypotheses",
    depth_hypotheses.run,
    label="MonoSLAM's depth hypotheses",
    style={"color": "darkgoldenrod", "linestyle": (0, (3, 1, 1, 1, 1, 1))},
    family="rao_blackwellised",
    variants=(("-", "front", {}),),
    any_frames=True,
    with_process_noise=True,
    default=False,
    estimate=checked_gaussian("MonoSLAM's depth hypotheses"),
)


def get(name: str) -> Filter:
    """The filter called ``name``; a :class:`ValueError` lists the names if there is none."""
    if name not in FILTERS:
        raise ValueError(f"filter must be one of {tuple(FILTERS)}, got {name!r}")
    return FILTERS[name]


def check_names(names) -> tuple:
    """Return ``names`` as a tuple after checking each is in the registry."""
    names = tuple(names)
    unknown = set(names) - set(FILTERS)
    if unknown:
        raise ValueError(f"filters must be among {tuple(FILTERS)}, got {sorted(unknown)}")
    return names
