"""The prior's form as an axis of a study: the paper's rule and three priors of the literature.

Recommended import: ``from depthcore.studies import priors``.

:data:`FORMS` names four ways to give the filters a prior on the state at
frame 1, ``(x_1, y_1, v)``:

* ``"paper"``: the paper's rule, a prior built from each trial's own first
  three bearings, mean ``(c1 - 2 c3, c2 - 2, 0)`` from their noise-free state
  ``c`` (Eq. (7), :func:`depthcore.problem.gaussian.paper_prior_means`) and
  covariance ``1000 I`` (a lateral speed SD of 31.6 depth units per frame).
  The truth is one state for every trial.
* ``"range"``, ``"log_uniform"``, ``"inverse_depth"`` (:data:`DRAWN`): a law of
  the state at frame 1, centred on a given state ``c = (c_x, c_y, c_v)``
  (``c_y > 0``), from which each trial's truth is drawn; the filters get its
  Gaussian, the law itself where that is Gaussian and otherwise the Gaussian
  of the same mean and covariance (:func:`gaussian`), so that a filter's prior
  says what the truths' law says to second order.

The three drawn forms share the lateral part of bearings-only tracking's
initialisation [ristic2004]_ and of monocular SLAM's inverse-depth feature
[civera2008]_: the point lies on a ray whose bearing is known to one bearing's
noise, ``a = x_1 / y_1 ~ N(c_x / c_y, rho**2)``, at a depth ``y_1`` that the
prior knows poorly, and it moves with a lateral speed
``v ~ N(c_v, SPEED_SD**2)`` (:data:`SPEED_SD`); ``a``, ``y_1`` and ``v`` are
independent and ``x_1 = a y_1``. They differ in the depth's law, each truncated to depths in
front of the camera so that its moments exist:

* ``"range"``: a Gaussian range prior, ``y_1 ~ N(c_y, (RANGE_SD c_y)**2)``,
  the range known to :data:`RANGE_SD` of itself, truncated to ``y_1 >=
  RANGE_NEAREST c_y`` (three SDs below the centre, 0.13 % of the mass);
* ``"log_uniform"``: ``log y_1`` uniform over ``log c_y +- log(LOG_UNIFORM_RATIO) / 2``,
  a depth known to a decade: the law under which the geometrically growing
  depth intervals of the range-parametrised filters [peach1995]_ are equally
  probable;
* ``"inverse_depth"``: the inverse depth ``w = 1 / y_1`` Gaussian,
  ``N(1 / c_y, (INVERSE_DEPTH_SD / c_y)**2)``, the SD half the mean so that
  the two-SD region reaches ``w = 0``, a point at infinity, the rule by which
  [civera2008]_ choose their prior's inverse depth and its SD; truncated to
  ``w`` within :data:`INVERSE_DEPTH_LIMITS` times ``1 / c_y`` (depths up to
  ten times the centre's: 3.6 % of the mass lies beyond, nearer infinity).

The numbers are this module's choices, stated here, not measurements: the
literature fixes the forms, and the spreads above are the ones its examples
describe in words (a range known to about a third of itself, a decade of
depth, an inverse depth whose two-SD region reaches infinity). The speed's SD
is the depth's change per frame (the point recedes one depth unit per frame): the point's
direction of motion within 45 degrees of the camera's axis at one SD.

References
----------
.. [ristic2004] B. Ristic, S. Arulampalam and N. Gordon, *Beyond the Kalman
   Filter: Particle Filters for Tracking Applications*, Artech House, 2004,
   chapter 6 (bearings-only tracking).
.. [civera2008] J. Civera, A. J. Davison and J. M. M. Montiel, "Inverse depth
   parametrization for monocular SLAM", IEEE Trans. Robotics 24(5), 2008.
.. [peach1995] N. Peach, "Bearings-only tracking using a set of
   range-parameterised extended Kalman filters", IEE Proceedings - Control
   Theory and Applications 142(1), 73-80, 1995.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr, ndtri

from depthcore.problem import checks, depth_prior

#: The prior's forms, the paper's rule first.
FORMS = ("paper", "range", "log_uniform", "inverse_depth")

#: The forms whose truths are drawn from the prior.
DRAWN = FORMS[1:]

#: The lateral speed's SD in depth units per frame, the speed at which the point recedes.
SPEED_SD = 1.0

#: The range prior's depth SD, as a fraction of its centre.
RANGE_SD = 0.3

#: The range prior's nearest depth, as a fraction of its centre (three SDs below it).
RANGE_NEAREST = 0.1

#: The log-uniform prior's farthest depth over its nearest (a decade).
LOG_UNIFORM_RATIO = 10.0

#: The inverse-depth prior's SD of the inverse depth, as a fraction of its centre.
INVERSE_DEPTH_SD = 0.5

#: The inverse-depth prior's truncation, as multiples of the centre's inverse depth.
INVERSE_DEPTH_LIMITS = (0.1, 10.0)

#: Gauss-Legendre nodes of the inverse-depth prior's depth moments.
QUADRATURE_NODES = 400


def check(form, name: str = "prior") -> str:
    """``form`` if it is one of :data:`FORMS`; otherwise a one-line refusal naming ``name``."""
    if not (isinstance(form, str) and form in FORMS):
        raise ValueError(f"{name} must be one of {FORMS}, got {form!r}")
    return form


def _drawn(form) -> str:
    check(form, "form")
    if form not in DRAWN:
        raise ValueError(
            f"form must be one of {DRAWN}: the paper's rule builds each trial's prior from "
            f"its bearings, and no truth is drawn from it; got {form!r}"
        )
    return form


def _centre(centre) -> np.ndarray:
    c = checks.finite_array(centre, "centre")
    if c.ndim != 1 or c.shape[0] != 3:
        raise ValueError(f"centre must have shape (3,), got shape {c.shape}")
    if not c[1] > 0:
        raise ValueError(f"centre must have a positive depth at frame 1, got {c[1]!r}")
    return c


def _truncated_normal(u, lo, hi):
    """Quantiles ``u`` in [0, 1) of the standard normal truncated to ``[lo, hi]``.

    Inverted through the upper tail's mass, ``z = -ndtri(Q(lo) - u (Q(lo) - Q(hi)))``
    with ``Q(z) = ndtr(-z)``, which stays finite as ``u`` approaches 1 (where
    ``ndtr`` rounds to 1 and its inverse is infinite).
    """
    q_lo, q_hi = ndtr(-lo), ndtr(-hi)
    return -ndtri(q_lo - u * (q_lo - q_hi))


def _inverse_depth_limits() -> tuple[float, float]:
    """The truncation of the standardised inverse depth ``(w - w0) / sd``."""
    lo, hi = INVERSE_DEPTH_LIMITS
    return (lo - 1.0) / INVERSE_DEPTH_SD, (hi - 1.0) / INVERSE_DEPTH_SD


def depth_moments(form: str, depth: float) -> tuple[float, float]:
    """The first two moments of the depth at frame 1 under a drawn form's law.

    Parameters
    ----------
    form : {"range", "log_uniform", "inverse_depth"}
    depth : float
        The centre's depth ``c_y > 0``.

    Returns
    -------
    tuple of float
        ``(E[y_1], E[y_1**2])``. In closed form for the truncated Gaussian
        (``"range"``) and the log-uniform law; for ``"inverse_depth"`` by
        Gauss-Legendre quadrature (:data:`QUADRATURE_NODES`) of ``w**-1`` and
        ``w**-2`` against the truncated Gaussian of ``w``.
    """
    _drawn(form)
    m = checks.positive_scalar(depth, "depth")
    if form == "range":
        s = RANGE_SD * m
        a = (RANGE_NEAREST * m - m) / s
        z = ndtr(-a)  # the mass above the truncation
        phi = np.exp(-0.5 * a * a) / np.sqrt(2.0 * np.pi)
        mean = m + s * phi / z
        var = s * s * (1.0 + a * phi / z - (phi / z) ** 2)
        return float(mean), float(var + mean * mean)
    if form == "log_uniform":
        lo, hi = m / np.sqrt(LOG_UNIFORM_RATIO), m * np.sqrt(LOG_UNIFORM_RATIO)
        log_ratio = np.log(LOG_UNIFORM_RATIO)
        return float((hi - lo) / log_ratio), float((hi * hi - lo * lo) / (2.0 * log_ratio))
    lo, hi = _inverse_depth_limits()
    nodes, weights = np.polynomial.legendre.leggauss(QUADRATURE_NODES)
    z = lo + (hi - lo) * (nodes + 1.0) / 2.0
    density = np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi) / (ndtr(hi) - ndtr(lo))
    w = (1.0 + INVERSE_DEPTH_SD * z) / m
    weights = weights * (hi - lo) / 2.0 * density
    return float(np.sum(weights / w)), float(np.sum(weights / w**2))


def gaussian(form: str, centre, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """The filters' Gaussian prior of a drawn form: the mean and covariance of its law.

    With ``a ~ N(a0, rho**2)``, ``y_1`` and ``v ~ N(c_v, SPEED_SD**2)``
    independent and ``x_1 = a y_1`` (the module docstring), and ``E[y_1]``,
    ``E[y_1**2]`` from :func:`depth_moments`:

        E[x_1] = a0 E[y_1],   Var(x_1) = (a0**2 + rho**2) E[y_1**2] - a0**2 E[y_1]**2,
        Cov(x_1, y_1) = a0 Var(y_1),   E[v] = c_v,   Var(v) = SPEED_SD**2,

    the velocity uncorrelated with the position.

    Parameters
    ----------
    form : {"range", "log_uniform", "inverse_depth"}
    centre : array_like, shape (3,)
        The state ``c`` at frame 1 the law is centred on, ``c_y > 0``.
    rho : float
        The bearing's noise SD, > 0: the SD of the bearing at frame 1.

    Returns
    -------
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
    """
    _drawn(form)
    c = _centre(centre)
    rho = checks.positive_scalar(rho, "rho")
    a0 = c[0] / c[1]
    ey, ey2 = depth_moments(form, c[1])
    var_y = ey2 - ey * ey
    mean = np.array([a0 * ey, ey, c[2]])
    cov = np.zeros((3, 3))
    cov[0, 0] = (a0 * a0 + rho * rho) * ey2 - a0 * a0 * ey * ey
    cov[0, 1] = cov[1, 0] = a0 * var_y
    cov[1, 1] = var_y
    cov[2, 2] = SPEED_SD**2
    return mean, cov


def law(form: str, centre, rho: float) -> depth_prior.DepthPrior:
    """A drawn form's law itself, for the exact filter: the depth's law and, given the depth,
    the ray's Gaussian ``x_1 = a y_1``, ``a ~ N(c_x / c_y, rho**2)``, ``v ~ N(c_v, SPEED_SD**2)``.

    Its :meth:`~depthcore.problem.depth_prior.DepthPrior.gaussian` is :func:`gaussian`'s
    mean and covariance; its draws follow :func:`draw`'s law.

    Parameters
    ----------
    form : {"range", "log_uniform", "inverse_depth"}
    centre : array_like, shape (3,)
    rho : float

    Returns
    -------
    depthcore.problem.depth_prior.DepthPrior
    """
    _drawn(form)
    c = _centre(centre)
    rho = checks.positive_scalar(rho, "rho")
    lateral = depth_prior.Lateral.on_ray(c[0] / c[1], rho, c[2], SPEED_SD)
    m = c[1]
    if form == "range":
        return depth_prior.range_prior(m, RANGE_SD * m, lateral, lo=RANGE_NEAREST * m)
    if form == "log_uniform":
        r = np.sqrt(LOG_UNIFORM_RATIO)
        return depth_prior.log_uniform(m / r, m * r, lateral)
    lo, hi = INVERSE_DEPTH_LIMITS
    return depth_prior.inverse_depth(1.0 / m, INVERSE_DEPTH_SD / m, lo / m, hi / m, lateral)


def draw_depths(form: str, depth: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` depths at frame 1 from a drawn form's law about the depth ``depth``, shape (n,).

    By inversion of the law's CDF at ``n`` uniform draws of ``rng`` (one
    ``rng.random(n)``): a truncated Gaussian's quantile for ``"range"``, ``lo
    (hi / lo)**u`` for ``"log_uniform"``, one over a truncated Gaussian's
    quantile for ``"inverse_depth"``.
    """
    _drawn(form)
    m = checks.positive_scalar(depth, "depth")
    n = checks.count(n, "n")
    rng = checks.generator(rng)
    u = rng.random(n)
    if form == "range":
        lo = (RANGE_NEAREST - 1.0) / RANGE_SD
        return m * (1.0 + RANGE_SD * _truncated_normal(u, lo, np.inf))
    if form == "log_uniform":
        return m * LOG_UNIFORM_RATIO ** (u - 0.5)
    lo, hi = _inverse_depth_limits()
    return m / (1.0 + INVERSE_DEPTH_SD * _truncated_normal(u, lo, hi))


def draw(form: str, centre, rho: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` states at frame 1 drawn from a drawn form's law centred on ``centre``.

    Parameters
    ----------
    form : {"range", "log_uniform", "inverse_depth"}
    centre : array_like, shape (3,)
        The state at frame 1 the law is centred on, its depth positive.
    rho : float
        The bearing's noise SD, > 0 (the SD of the bearing at frame 1).
    n : int
        Draws, >= 1.
    rng : numpy.random.Generator
        Drawn from in this order: the depths (:func:`draw_depths`), then ``n``
        standard normals for the bearings, then ``n`` for the speeds.

    Returns
    -------
    ndarray, shape (n, 3)
        ``(x_1, y_1, v)``, every depth positive.
    """
    _drawn(form)
    c = _centre(centre)
    rho = checks.positive_scalar(rho, "rho")
    rng = checks.generator(rng)
    y = draw_depths(form, c[1], n, rng)
    a = c[0] / c[1] + rho * rng.standard_normal(y.shape)
    v = c[2] + SPEED_SD * rng.standard_normal(y.shape)
    return np.stack([a * y, y, v], axis=-1)
