"""A prior on the state at frame 1 that is any proper law of the depth, Gaussian given it.

Recommended import: ``from depthcore.problem import depth_prior``.

The exact filter conditions on the depth ``y_1`` (:mod:`depthcore.exact.bank`), so
its prior need only say two things: the depth's density ``p(y_1)`` on
``y_1 > 0``, and the Gaussian of the rest ``(x_1, v_1)`` given the depth. A
:class:`DepthPrior` holds both:

* the depth's law, one of :data:`FORMS`: ``"log_uniform"`` over ``[lo, hi]``
  (density ``1 / (y log(hi / lo))``); ``"range"``, a Gaussian ``N(m, s**2)``
  truncated to ``[lo, hi]`` (``hi`` may be infinite); ``"inverse_depth"``, the
  inverse depth ``w = 1 / y_1`` Gaussian ``N(m_w, s_w**2)`` truncated to
  ``[w_lo, w_hi]`` with ``w_lo > 0`` (untruncated it reaches ``w = 0``, a point at
  infinity, and the depth has no mean); ``"table"``, a density tabulated at
  depths and linear between them;
* :class:`Lateral`, the Gaussian of ``(x_1, v_1)`` given ``y_1 = y``: mean
  ``a + b y`` and covariance ``C + D y**2``. A joint Gaussian prior gives
  ``D = 0`` (:meth:`Lateral.given_depth`); a point on the ray of a bearing
  ``x_1 = alpha y_1``, ``alpha ~ N(alpha_0, s**2)``, with a speed
  ``v ~ N(v_0, s_v**2)`` gives ``D = diag(s**2, 0)`` (:meth:`Lateral.on_ray`), the
  initialisation of bearings-only tracking and of monocular SLAM.

Its edges and kinks (:attr:`DepthPrior.breakpoints`) are where the exact filter's
quadrature ends its panels (:mod:`depthcore.exact.panels`). The Gaussian filters
take the Gaussian of the same mean and covariance (:meth:`DepthPrior.gaussian`, also
its :attr:`~DepthPrior.mean` and :attr:`~DepthPrior.cov`, as a Gaussian prior has them).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import log_ndtr, ndtr, ndtri

from depthcore.problem import checks
from depthcore.problem.gaussian import MeanAndCov

#: The depth's laws.
FORMS = ("log_uniform", "range", "inverse_depth", "table")

#: Gauss-Legendre nodes per table segment or for the inverse depth's moments.
_MOMENT_NODES = 200

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def _vector(value, name: str) -> np.ndarray:
    return checks.finite_array(value, name, (2,))


def _psd(value, name: str) -> np.ndarray:
    m = checks.finite_array(value, name, (2, 2))
    if abs(m[0, 1] - m[1, 0]) > 1e-12 * max(1.0, float(np.max(np.abs(m)))):
        raise ValueError(f"{name} must be symmetric, got {m.tolist()}")
    if np.min(np.linalg.eigvalsh(m)) < -1e-12 * max(1.0, float(np.max(np.abs(m)))):
        raise ValueError(f"{name} must be positive semi-definite, got {m.tolist()}")
    return m


@dataclass(frozen=True)
class Lateral:
    """The Gaussian of ``(x_1, v_1)`` given the depth ``y_1 = y``: ``N(a + b y, C + D y**2)``.

    Attributes
    ----------
    intercept : ndarray, shape (2,)
        ``a``.
    slope : ndarray, shape (2,)
        ``b``.
    cov : ndarray, shape (2, 2)
        ``C``, positive semi-definite.
    cov_per_depth2 : ndarray, shape (2, 2)
        ``D``, positive semi-definite, with ``C + D`` positive definite (then
        ``C + D y**2`` is for every ``y > 0``).
    """

    intercept: np.ndarray
    slope: np.ndarray
    cov: np.ndarray
    cov_per_depth2: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "intercept", _vector(self.intercept, "intercept"))
        object.__setattr__(self, "slope", _vector(self.slope, "slope"))
        C, D = _psd(self.cov, "cov"), _psd(self.cov_per_depth2, "cov_per_depth2")
        if np.min(np.linalg.eigvalsh(C + D)) <= 0:
            raise ValueError("cov + cov_per_depth2 must be positive definite")
        object.__setattr__(self, "cov", C)
        object.__setattr__(self, "cov_per_depth2", D)

    @classmethod
    def given_depth(cls, prior_mean, prior_cov) -> Lateral:
        """The conditional of a joint Gaussian ``N(m, P)`` on ``(x_1, y_1, v_1)`` given ``y_1``.

        Mean ``m_u + P_uy (y - m_y) / P_yy``, covariance ``P_uu - P_uy P_yu / P_yy``
        (``u = (x, v)``), as :func:`depthcore.exact.bank.conditional_prior`.
        """
        m = checks.finite_array(prior_mean, "prior_mean", (3,))
        P = checks.covariance(prior_cov, "prior_cov", 3)
        u = [0, 2]
        slope = P[u, 1] / P[1, 1]
        cov = P[np.ix_(u, u)] - np.outer(slope, P[1, u])
        return cls(m[u] - slope * m[1], slope, 0.5 * (cov + cov.T), np.zeros((2, 2)))

    @classmethod
    def on_ray(cls, bearing, bearing_sd, speed, speed_sd) -> Lateral:
        """A point on the ray of a bearing, ``x_1 = alpha y`` with ``alpha ~ N(bearing,
        bearing_sd**2)``, and ``v_1 ~ N(speed, speed_sd**2)``, independent.

        Mean ``(bearing y, speed)``, covariance ``diag(bearing_sd**2 y**2, speed_sd**2)``.
        """
        a = checks.number(bearing, "bearing")
        s = checks.positive_scalar(bearing_sd, "bearing_sd")
        v = checks.number(speed, "speed")
        sv = checks.positive_scalar(speed_sd, "speed_sd")
        return cls(
            np.array([0.0, v]), np.array([a, 0.0]), np.diag([0.0, sv**2]), np.diag([s**2, 0.0])
        )

    def at(self, y) -> MeanAndCov:
        """The Gaussian at depths ``y`` (...): mean (..., 2) and covariance (..., 2, 2)."""
        y = np.asarray(y, dtype=float)[..., None]
        mean = self.intercept + self.slope * y
        cov = self.cov + self.cov_per_depth2 * (y * y)[..., None]
        return MeanAndCov(mean, cov)


@dataclass(frozen=True)
class DepthPrior:
    """A prior on ``(x_1, y_1, v_1)``: the depth's law (:data:`FORMS`) and :class:`Lateral`.

    Build one with :func:`log_uniform`, :func:`range_prior`, :func:`inverse_depth`
    or :func:`table`.

    Attributes
    ----------
    form : str
        One of :data:`FORMS`.
    parameters : tuple of float
        ``(lo, hi)``; ``(m, s, lo, hi)``; ``(m_w, s_w, w_lo, w_hi)``; for a table
        the depths then the densities.
    lateral : Lateral
    """

    form: str
    parameters: tuple
    lateral: Lateral

    @property
    def support(self) -> tuple[float, float]:
        """The depths ``(lo, hi)`` at frame 1 of positive density (``hi`` may be ``inf``)."""
        p = self.parameters
        if self.form == "log_uniform":
            return p[0], p[1]
        if self.form == "range":
            return p[2], p[3]
        if self.form == "inverse_depth":
            return 1.0 / p[3], 1.0 / p[2]
        n = len(p) // 2
        return p[0], p[n - 1]

    @property
    def breakpoints(self) -> np.ndarray:
        """The depths where the density has an edge or a kink, the finite ends and a table's."""
        if self.form == "table":
            return np.array(self.parameters[: len(self.parameters) // 2])
        return np.array([e for e in self.support if np.isfinite(e) and e > 0])

    def log_pdf(self, y) -> np.ndarray:
        """``log p(y_1)`` at depths ``y`` (any shape), ``-inf`` outside the support."""
        y = np.asarray(y, dtype=float)
        lo, hi = self.support
        inside = (y >= lo) & (y <= hi)
        ys = np.where(inside, y, lo if lo > 0 else 1.0)
        p = self.parameters
        with np.errstate(divide="ignore"):
            if self.form == "log_uniform":
                out = -np.log(ys) - math.log(math.log(p[1] / p[0]))
            elif self.form == "range":
                z = (ys - p[0]) / p[1]
                out = -0.5 * z * z - _LOG_SQRT_2PI - math.log(p[1]) - _log_mass(p)
            elif self.form == "inverse_depth":
                z = (1.0 / ys - p[0]) / p[1]
                out = -0.5 * z * z - _LOG_SQRT_2PI - math.log(p[1]) - _log_mass(p) - 2 * np.log(ys)
            else:
                depths, dens = _table(p)
                out = np.log(np.interp(ys, depths, dens) / _table_mass(depths, dens))
        return np.where(inside, out, -np.inf)

    def depth_moments(self) -> tuple[float, float]:
        """``(E[y_1], E[y_1**2])``, in closed form or by Gauss-Legendre quadrature."""
        return self._moments

    @functools.cached_property
    def _moments(self) -> tuple[float, float]:
        p = self.parameters
        if self.form == "log_uniform":
            lo, hi = p
            r = math.log(hi / lo)
            return (hi - lo) / r, (hi * hi - lo * lo) / (2.0 * r)
        if self.form == "range":
            m, s, lo, hi = p
            a, b = (lo - m) / s, (hi - m) / s
            z = math.exp(_log_mass(p))
            pa, pb = _phi(a), _phi(b)
            apa, bpb = (a * pa if np.isfinite(a) else 0.0), (b * pb if np.isfinite(b) else 0.0)
            mean = m + s * (pa - pb) / z
            e2 = m * m + 2 * m * s * (pa - pb) / z + s * s * (1.0 + (apa - bpb) / z)
            return mean, e2
        edges = self.breakpoints
        x, w = _gauss_legendre(_MOMENT_NODES)
        mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
        y = (mid[:, None] + half[:, None] * x).ravel()
        wy = (half[:, None] * w).ravel() * np.exp(self.log_pdf(y))
        return float(wy @ y), float(wy @ (y * y))

    @property
    def mean(self) -> np.ndarray:
        """The mean (3,) of ``(x_1, y_1, v_1)``, :meth:`gaussian`'s."""
        return self.gaussian()[0]

    @property
    def cov(self) -> np.ndarray:
        """The covariance (3, 3) of ``(x_1, y_1, v_1)``, :meth:`gaussian`'s."""
        return self.gaussian()[1]

    def gaussian(self) -> tuple[np.ndarray, np.ndarray]:
        """The mean (3,) and covariance (3, 3) of ``(x_1, y_1, v_1)`` under this prior.

        With ``u = (x_1, v_1)``: ``E u = a + b E y``, ``Cov(u, y) = b Var y`` and
        ``Cov u = C + D E[y**2] + b b^T Var y`` (:class:`Lateral`), exactly: the
        Gaussian filters' stand-in for this prior.
        """
        ey, ey2 = self.depth_moments()
        var = ey2 - ey * ey
        L = self.lateral
        mean_u = L.intercept + L.slope * ey
        cov_u = L.cov + L.cov_per_depth2 * ey2 + np.outer(L.slope, L.slope) * var
        mean = np.array([mean_u[0], ey, mean_u[1]])
        cov = np.empty((3, 3))
        u = [0, 2]
        cov[np.ix_(u, u)] = cov_u
        cov[u, 1] = cov[1, u] = L.slope * var
        cov[1, 1] = var
        return mean, cov

    def draw_depths(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` depths at frame 1 by inversion of the law's CDF (one ``rng.random(n)``)."""
        n = checks.count(n, "n")
        u = checks.generator(rng).random(n)
        p = self.parameters
        if self.form == "log_uniform":
            return p[0] * (p[1] / p[0]) ** u
        if self.form == "range":
            return p[0] + p[1] * _truncated_normal(u, (p[2] - p[0]) / p[1], (p[3] - p[0]) / p[1])
        if self.form == "inverse_depth":
            w = p[0] + p[1] * _truncated_normal(u, (p[2] - p[0]) / p[1], (p[3] - p[0]) / p[1])
            return 1.0 / w
        depths, dens = _table(p)
        return _table_quantile(depths, dens, u)

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` states ``(x_1, y_1, v_1)`` (n, 3): the depths, then ``(x_1, v_1)`` given them."""
        rng = checks.generator(rng)
        y = self.draw_depths(n, rng)
        g = self.lateral.at(y)
        z = rng.standard_normal((len(y), 2))
        L = np.linalg.cholesky(g.cov + 1e-300 * np.eye(2))
        u = g.mean + np.einsum("nij,nj->ni", L, z)
        return np.stack([u[:, 0], y, u[:, 1]], axis=-1)


@functools.lru_cache(maxsize=4)
def _gauss_legendre(n: int):
    return np.polynomial.legendre.leggauss(n)


def _phi(z):
    return math.exp(-0.5 * z * z - _LOG_SQRT_2PI) if np.isfinite(z) else 0.0


def _log_mass(p) -> float:
    """``log P(lo <= Z <= hi)`` of the Gaussian ``N(m, s**2)`` of ``p = (m, s, lo, hi)``."""
    m, s, lo, hi = p
    a, b = (lo - m) / s, (hi - m) / s
    if a > 0:  # both in the upper tail: the mass from the lower tail of -Z
        a, b = -b, -a
    la, lb = float(log_ndtr(a)), float(log_ndtr(b))
    return lb + math.log1p(-math.exp(la - lb))


def _truncated_normal(u, a, b):
    """Quantiles ``u`` of the standard normal truncated to ``[a, b]``, stable in either tail."""
    if a > 0:
        return -_truncated_normal(1.0 - u, -b, -a)
    fa, fb = ndtr(a), ndtr(b)
    return ndtri(fa + u * (fb - fa))


def _table(p):
    n = len(p) // 2
    return np.asarray(p[:n]), np.asarray(p[n:])


def _table_mass(depths, dens) -> float:
    return float(np.sum(0.5 * (dens[1:] + dens[:-1]) * np.diff(depths)))


def _table_quantile(depths, dens, u):
    """The piecewise-linear density's quantiles: its CDF is quadratic on each segment."""
    seg = 0.5 * (dens[1:] + dens[:-1]) * np.diff(depths)
    cdf = np.concatenate([[0.0], np.cumsum(seg)]) / np.sum(seg)
    k = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, len(seg) - 1)
    h = np.diff(depths)[k]
    f0, f1 = dens[k] / np.sum(seg), dens[k + 1] / np.sum(seg)
    target = u - cdf[k]  # = f0 d + (f1 - f0) d**2 / (2 h) for d in [0, h]
    slope = (f1 - f0) / h
    with np.errstate(divide="ignore", invalid="ignore"):
        root = 2.0 * target / (f0 + np.sqrt(np.maximum(f0 * f0 + 2.0 * slope * target, 0.0)))
    return depths[k] + np.clip(np.where(np.isfinite(root), root, 0.0), 0.0, h)


def _lateral(lateral) -> Lateral:
    if not isinstance(lateral, Lateral):
        raise ValueError(f"lateral must be a Lateral, got {type(lateral).__name__}")
    return lateral


def log_uniform(lo, hi, lateral: Lateral) -> DepthPrior:
    """``log y_1`` uniform over ``[log lo, log hi]``, ``0 < lo < hi``."""
    lo, hi = checks.positive_scalar(lo, "lo"), checks.positive_scalar(hi, "hi")
    if not hi > lo:
        raise ValueError(f"hi must exceed lo, got lo = {lo!r}, hi = {hi!r}")
    return DepthPrior("log_uniform", (lo, hi), _lateral(lateral))


def range_prior(mean, sd, lateral: Lateral, lo=0.0, hi=math.inf) -> DepthPrior:
    """A range prior: ``y_1 ~ N(mean, sd**2)`` truncated to ``[lo, hi]``, ``0 <= lo < hi``."""
    m = checks.number(mean, "mean")
    s = checks.positive_scalar(sd, "sd")
    lo = checks.nonnegative_scalar(lo, "lo")
    hi = float(hi)
    if not hi > lo:
        raise ValueError(f"hi must exceed lo, got lo = {lo!r}, hi = {hi!r}")
    if not np.isfinite(_log_mass((m, s, lo, hi))):
        raise ValueError(f"the Gaussian N({m!r}, {s!r}**2) has no mass between lo and hi")
    return DepthPrior("range", (m, s, lo, hi), _lateral(lateral))


def inverse_depth(mean, sd, lo, hi, lateral: Lateral) -> DepthPrior:
    """``w = 1 / y_1 ~ N(mean, sd**2)`` truncated to ``[lo, hi]``, ``0 < lo < hi``.

    The truncation ``lo > 0`` keeps the depth finite: without it the law reaches
    ``w = 0`` and the posterior has no mean.
    """
    m = checks.number(mean, "mean")
    s = checks.positive_scalar(sd, "sd")
    lo, hi = checks.positive_scalar(lo, "lo"), checks.positive_scalar(hi, "hi")
    if not hi > lo:
        raise ValueError(f"hi must exceed lo, got lo = {lo!r}, hi = {hi!r}")
    if not np.isfinite(_log_mass((m, s, lo, hi))):
        raise ValueError(f"the Gaussian N({m!r}, {s!r}**2) has no mass between lo and hi")
    return DepthPrior("inverse_depth", (m, s, lo, hi), _lateral(lateral))


def table(depths, density, lateral: Lateral) -> DepthPrior:
    """A density tabulated at increasing depths > 0, linear between them, zero outside.

    ``density`` (K,) at ``depths`` (K,), ``K >= 2``, positive but at the first and last
    depths (where it may be 0), need not be normalised.
    """
    d = checks.finite_array(depths, "depths")
    f = checks.finite_array(density, "density")
    if d.ndim != 1 or d.size < 2 or f.shape != d.shape:
        raise ValueError(
            f"depths and density must have one shape (K,), K >= 2, got {d.shape} and {f.shape}"
        )
    if not (d[0] > 0 and np.all(np.diff(d) > 0)):
        raise ValueError("depths must be positive and increasing")
    if np.any(f < 0) or not np.all(f[1:-1] > 0) or not _table_mass(d, f) > 0:
        raise ValueError("density must be positive between the first and last depths (0 at them)")
    return DepthPrior("table", tuple(d.tolist()) + tuple(f.tolist()), _lateral(lateral))


def stand_in(law, prior_mean, prior_cov) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussian that stands beside ``law`` (:meth:`DepthPrior.gaussian`), checked against
    a caller's ``prior_mean`` and ``prior_cov``: each ``None`` or the law's own (repeated
    over leading axes or not), else a one-line refusal naming it."""
    if not isinstance(law, DepthPrior):
        raise ValueError(f"law must be a DepthPrior, got {type(law).__name__}")
    mean, cov = law.gaussian()
    for value, own, name in ((prior_mean, mean, "prior_mean"), (prior_cov, cov, "prior_cov")):
        given = None if value is None else checks.as_float(value, name)
        same = given is None or (
            given.shape[given.ndim - own.ndim :] == own.shape
            and np.allclose(given, own, rtol=1e-9, atol=0.0)
        )
        if not same:
            raise ValueError(
                f"{name} must be None with a law, or the law's own moments (law.gaussian())"
            )
    return mean, cov


def options(name: str, prior) -> dict:
    """``{"law": prior}`` for the exact filter ``"optimal"`` when ``prior`` is a
    :class:`DepthPrior`, else ``{}``: the other filters take its Gaussian."""
    return {"law": prior} if name == "optimal" and isinstance(prior, DepthPrior) else {}


def describe(prior) -> dict:
    """A :class:`DepthPrior`'s law for JSON, ``{"form", "parameters"}``; ``{}`` for a Gaussian."""
    if not isinstance(prior, DepthPrior):
        return {}
    values = [float(v) if math.isfinite(v) else None for v in prior.parameters]  # strict JSON
    return {"prior_depth": {"form": prior.form, "parameters": values}}
