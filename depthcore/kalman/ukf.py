"""The unscented Kalman filter on the paper's problem and its N-frame model (Prince, section 19.4).

Recommended import: ``from depthcore.kalman import ukf``.

The UKF replaces the EKF's linearisation of the projection ``h(x) = x / y``
(Eq. (11)) by the unscented transform: a Gaussian ``N(n, C)`` on the state is
represented by ``2 d + 1`` weighted *sigma points* (``d = 3``), the points are
pushed through ``h`` and the Gaussian of the measurement and its
cross-covariance with the state are read off the transformed points
[julier1997]_, [wan2000]_. It runs in the same order and from the same start
as the paper's EKF (:func:`depthcore.kalman.ekf.run`): the prior is the density of the
state at time 1, so ``mu1`` is incorporated into it directly; then predict and
update twice -- or ``N - 1`` times for ``N`` bearings, with process noise on
the velocity if asked (the model of :mod:`depthcore.exact.bank`).

Sigma points (the scaled set of [wan2000]_, section 2; the points of
[julier1997]_, section 3, are the case ``alpha = 1, beta = 0``). With
``lambda = alpha**2 (d + kappa) - d`` and ``L`` the lower Cholesky factor of
``(d + lambda) C``, whose columns are ``L_j``:

    X_0 = n,   X_j = n + L_j,   X_{d+j} = n - L_j        (j = 1 .. d)
    Wm_0 = lambda / (d + lambda),   Wc_0 = Wm_0 + 1 - alpha**2 + beta,
    Wm_j = Wc_j = 1 / (2 (d + lambda))                  (j = 1 .. 2 d)

These points have mean ``n`` and covariance ``C`` exactly, whatever the
parameters; ``beta`` only changes the centre point's covariance weight, which
multiplies a zero deviation whenever the transformed centre is the
transformed mean (as for any linear map).

Defaults ``alpha = 1, beta = 0, kappa = 0``: Julier and Uhlmann's rule
``kappa = 3 - d`` (which matches the fourth moment of a Gaussian along each
axis) gives ``kappa = 0`` here, and with ``alpha = 1`` the centre point has
weight zero and the six others ``1/6`` each: every weight is non-negative, so
every covariance the transform produces is positive semi-definite. (With
``alpha = 1``, ``beta = 2``, "optimal for Gaussians" in [wan2000]_, would add
``2 (h(n) - z)**2`` to the innovation variance; with ``kappa = 0``, any
``alpha < 1`` makes ``Wm_0`` negative.)

Prediction. The motion ``x -> F x + e`` (Eq. (9)) is linear, and the unscented
transform is exact for linear maps, so the prediction is done in closed form,
``n = F m + e``, ``C = F P F^T`` -- the EKF's Eq. (10), with no approximation;
process noise ``a_k ~ N(0, q**2)`` on the velocity adds ``q**2`` to the
velocity's variance (textbook Eq. (19.10), :func:`depthcore.kalman.ekf.predict`).
Over a step ``s`` of the depth (:mod:`depthcore.problem.frames`) ``F`` and ``e``
are those of the step (``n = G(m, s)``) and the velocity gains ``q**2 |s|``.

Update for the scalar measurement ``mu = h(x) + w``, ``w ~ N(0, rho**2)``,
with sigma points ``X_i`` of the prediction ``N(n, C)`` and ``Z_i = h(X_i)``:

    z = sum_i Wm_i Z_i,   s = rho**2 + sum_i Wc_i (Z_i - z)**2,
    c = sum_i Wc_i (X_i - n) (Z_i - z),   K = c / s,
    m = n + K (mu - z),   P = C - K s K^T = C - c c^T / s.

The point must lie in front of the camera: a sigma point with depth ``y <= 0``
lies across the pole ``y = 0`` of ``h`` from the mean, so the transform would
average values of ``h`` from both sides of the pole, and :func:`update` raises
:class:`ValueError`. With the paper's prior (covariance ``1000 I``, depth SD
31.6) the depth sigma points lie ``sqrt(3) * 31.6 = 54.8`` from a mean depth of
a few units, so the default check rejects every paper scenario; smaller
``alpha`` pulls the points in, and ``allow_behind_camera=True`` runs the
transform across the pole anyway (to show what it does).

Tracks as they come. :func:`run` takes missing bearings (``NaN``: the
prediction is kept, row by row), ``rho`` per frame, steps and a gate; each
frame (:func:`step`) reports the bearing's log density and two-sided tail
probability under the unscented predictive ``N(z, s)`` above
(:func:`bearing_predictive`), and whether a sigma point of the Gaussian it
transformed lay at depth ``y <= 0``: ``UKFHistory.behind`` per frame,
``UKFHistory.went_behind`` for the whole track. With
``allow_behind_camera=True`` the filter runs on across the pole and says where
it did.

Pulling the points in does not rescue the filter on the paper's prior. Under
``N(n, 1000 I)`` the depth has positive density ``p_y(0)`` at ``y = 0``, so
``P(|y| < eps)`` is about ``2 eps p_y(0)`` and ``E[(x / y)**2 ; |y| > eps]``
grows like ``2 p_y(0) E[x**2 | y = 0] / eps``: ``Var[x / y]`` is infinite and
``E[x / y]`` does not exist (:func:`depthbook.beyond_filters.truncated_bearing_moments`).
The moments the transform sets out to match are undefined, so whatever
``alpha``, ``beta`` and ``kappa`` it uses, its answer depends on where its
points happen to fall.

References
----------
.. [julier1997] S. J. Julier and J. K. Uhlmann, "A new extension of the Kalman
   filter to nonlinear systems", Proc. SPIE 3068, 1997, section 3 (the sigma
   points with ``kappa`` and the rule ``kappa = 3 - d``).
.. [wan2000] E. A. Wan and R. van der Merwe, "The unscented Kalman filter for
   nonlinear estimation", IEEE AS-SPCC Symposium, 2000, section 2 (the scaled
   sigma points and weights) and section 3 (the UKF equations).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from depthcore.kalman import ekf
from depthcore.problem import checks, model, predictive, signature
from depthcore.problem.gaussian import History, MeanAndCov, checked_track, symmetric

#: Dimension of the state ``(x, y, v)``.
DIM = 3


@dataclass(frozen=True)
class SigmaPoints:
    """Scaled sigma points of Julier and Uhlmann / Wan and van der Merwe (module docstring).

    Attributes
    ----------
    alpha : float
        Spread of the points about the mean, > 0 (default 1).
    beta : float
        Added to the centre point's covariance weight (default 0).
    kappa : float
        Secondary scaling, with ``dim + kappa > 0`` (default 0, which is ``3 - dim``).
    dim : int
        Dimension of the state (default 3).
    """

    alpha: float = 1.0
    beta: float = 0.0
    kappa: float = 0.0
    dim: int = DIM

    def __post_init__(self):
        alpha = checks.positive_scalar(self.alpha, "alpha")
        beta = float(checks.finite_array(self.beta, "beta"))
        kappa = float(checks.finite_array(self.kappa, "kappa"))
        integral = isinstance(self.dim, (int, np.integer)) and not isinstance(self.dim, bool)
        if not integral or self.dim < 1:
            raise ValueError(f"dim must be a positive integer, got {self.dim!r}")
        if not self.dim + kappa > 0:
            raise ValueError(f"kappa must exceed -dim = {-self.dim}, got {kappa}")
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "beta", beta)
        object.__setattr__(self, "kappa", kappa)
        object.__setattr__(self, "dim", int(self.dim))

    @property
    def lam(self) -> float:
        """``lambda = alpha**2 (dim + kappa) - dim``."""
        return self.alpha**2 * (self.dim + self.kappa) - self.dim

    @property
    def n_points(self) -> int:
        """``2 dim + 1``."""
        return 2 * self.dim + 1

    def weights(self) -> tuple[np.ndarray, np.ndarray]:
        """The mean weights ``Wm`` and covariance weights ``Wc``, each of shape ``(2 dim + 1,)``."""
        scale = self.dim + self.lam
        Wm = np.full(self.n_points, 0.5 / scale)
        Wc = Wm.copy()
        Wm[0] = self.lam / scale
        Wc[0] = Wm[0] + 1.0 - self.alpha**2 + self.beta
        return Wm, Wc

    def points(self, mean, cov) -> np.ndarray:
        """The sigma points of ``N(mean, cov)``, batched.

        Parameters
        ----------
        mean : array_like, shape (..., dim)
        cov : array_like, shape (..., dim, dim)
            Symmetric positive definite.

        Returns
        -------
        ndarray, shape (..., 2 dim + 1, dim)
            Row 0 is ``mean``, rows ``1 .. dim`` are ``mean + L_j`` and rows
            ``dim + 1 .. 2 dim`` are ``mean - L_j``.
        """
        mean = np.asarray(mean, dtype=float)
        cov = np.asarray(cov, dtype=float)
        if mean.shape[-1:] != (self.dim,) or cov.shape[-2:] != (self.dim, self.dim):
            raise ValueError(
                f"mean and cov must have shapes (..., {self.dim}) and (..., {self.dim}, "
                f"{self.dim}), got {mean.shape} and {cov.shape}"
            )
        try:
            L = np.linalg.cholesky((self.dim + self.lam) * cov)
        except np.linalg.LinAlgError:
            raise ValueError("cov must be positive definite to form sigma points") from None
        offsets = np.swapaxes(L, -1, -2)  # row j is the column L_j
        mean, offsets = np.broadcast_arrays(mean[..., None, :], offsets)
        return np.concatenate([mean[..., :1, :], mean + offsets, mean - offsets], axis=-2)


def unscented_transform(points, Wm, Wc, noise_cov=None) -> MeanAndCov:
    """Weighted mean and covariance of transformed sigma points.

    [wan2000]_, section 2: ``z = sum_i Wm_i Z_i``,
    ``S = sum_i Wc_i (Z_i - z)(Z_i - z)^T + noise_cov``.

    Parameters
    ----------
    points : array_like, shape (..., n_points, k)
        The sigma points after the (nonlinear) map, one per row.
    Wm, Wc : array_like, shape (n_points,)
        Mean and covariance weights, from :meth:`SigmaPoints.weights`.
    noise_cov : array_like, shape (..., k, k), optional
        Added to the covariance.

    Returns
    -------
    MeanAndCov
        ``mean`` of shape ``(..., k)``, ``cov`` of shape ``(..., k, k)``.
    """
    points = np.asarray(points, dtype=float)
    Wm = np.asarray(Wm, dtype=float)
    Wc = np.asarray(Wc, dtype=float)
    if points.ndim < 2 or Wm.shape != points.shape[-2:-1] or Wc.shape != Wm.shape:
        raise ValueError(
            f"points must have shape (..., n_points, k) with Wm and Wc of shape (n_points,); "
            f"got {points.shape}, {Wm.shape} and {Wc.shape}"
        )
    mean = np.einsum("i,...ik->...k", Wm, points)
    d = points - mean[..., None, :]
    cov = np.einsum("i,...ij,...ik->...jk", Wc, d, d)
    if noise_cov is not None:
        cov = cov + np.asarray(noise_cov, dtype=float)
    return MeanAndCov(mean, symmetric(cov))


class Innovation(NamedTuple):
    """The unscented moments of a scalar measurement ``mu = h(x) + w`` under ``N(n, C)``.

    Attributes
    ----------
    mean : ndarray, shape (...)
    var : ndarray, shape (...)
        ``z`` and ``s`` of the module docstring: the predictive is ``N(z, s)``.
    cross : ndarray, shape (..., 3)
        ``c``, its cross-covariance with the state.
    """

    mean: np.ndarray
    var: np.ndarray
    cross: np.ndarray


def innovation(
    n, C, rho, h=model.project, sigma_points: SigmaPoints = SigmaPoints(), points=None
) -> Innovation:
    """The unscented transform of ``N(n, C)`` through a scalar ``h``, batched ([wan2000]_, 3).

    Parameters
    ----------
    n, C : array_like, shape (..., 3) and (..., 3, 3)
        Predicted mean and covariance (positive definite).
    rho : float or array_like, shape (...)
        Noise standard deviation, > 0.
    h : callable
        Maps states ``(..., 3)`` to measurements ``(...)``.
    sigma_points : SigmaPoints
    points : ndarray, shape (..., 2 dim + 1, 3), optional
        ``sigma_points.points(n, C)``, when the caller has them already.

    Returns
    -------
    Innovation
    """
    n = np.asarray(n, dtype=float)
    X = sigma_points.points(n, C) if points is None else points  # (..., 7, 3)
    Wm, Wc = sigma_points.weights()
    Z = np.asarray(h(X), dtype=float)[..., None]  # (..., 7, 1)
    noise_var = np.asarray(rho, dtype=float) ** 2
    z, S = unscented_transform(Z, Wm, Wc, noise_var[..., None, None])
    z, s = z[..., 0], S[..., 0, 0]
    c = np.einsum("i,...ij,...i->...j", Wc, X - n[..., None, :], Z[..., 0] - z[..., None])
    return Innovation(z, s, c)


def _gain_update(n, C, mu, moments: Innovation) -> MeanAndCov:
    """``m = n + K (mu - z)``, ``P = C - c c^T / s`` with ``K = c / s`` (module docstring)."""
    z, s, c = moments
    innovation_ = np.asarray(mu, dtype=float) - z
    mean = np.asarray(n, dtype=float) + (innovation_ / s)[..., None] * c
    cov = np.asarray(C, dtype=float) - c[..., :, None] * c[..., None, :] / s[..., None, None]
    return MeanAndCov(mean, symmetric(cov))


def measurement_update(
    n, C, mu, rho: float, h=model.project, sigma_points: SigmaPoints = SigmaPoints()
) -> MeanAndCov:
    """Incorporate one scalar measurement ``mu = h(x) + w`` into ``N(n, C)``, batched.

    [wan2000]_, section 3; the equations are in the module docstring.

    Parameters
    ----------
    n, C, rho, h, sigma_points
        As for :func:`innovation` (``h`` by default ``x / y``).
    mu : float or array_like, shape (...)
        The measurement.

    Returns
    -------
    MeanAndCov
        The updated mean ``(..., 3)`` and covariance ``(..., 3, 3)``.
    """
    return _gain_update(n, C, mu, innovation(n, C, rho, h, sigma_points))


def _depth(X) -> np.ndarray:
    """The depth ``y`` of states (..., 3): a point is in front of the camera where it is > 0."""
    return X[..., 1]


def check_front(depth, rows=None, allow_behind_camera: bool = False) -> None:
    """Refuse sigma points behind the camera (or at the pole ``y = 0``), naming the first.

    Parameters
    ----------
    depth : ndarray, shape (..., 2 dim + 1)
        The sigma points' depths (for :func:`update`, ``y``).
    rows : ndarray of bool, shape (...), optional
        The problems checked (default all).
    allow_behind_camera : bool
        If true only a depth of exactly 0 is refused.
    """
    bad = depth == 0 if allow_behind_camera else ~(depth > 0)
    if rows is not None:
        bad = bad & np.asarray(rows, dtype=bool)[..., None]
    if not np.any(bad):
        return
    where = tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), depth.shape))
    trial = f" of trial {where[:-1]}" if depth.ndim > 1 else ""
    if allow_behind_camera:
        raise ValueError(f"sigma point {where[-1]}{trial} has depth 0, where x/y is undefined")
    raise ValueError(
        f"sigma point {where[-1]}{trial} has depth {depth[where]:.6g} <= 0: it lies behind "
        "the camera, across the pole of x/y at y = 0; use a smaller alpha or a tighter "
        "prior, or pass allow_behind_camera=True"
    )


def update(
    n,
    C,
    mu,
    rho: float,
    sigma_points: SigmaPoints = SigmaPoints(),
    allow_behind_camera: bool = False,
) -> MeanAndCov:
    """Incorporate one image measurement ``mu`` of ``x / y`` into ``N(n, C)``, batched.

    :func:`measurement_update` with ``h = x / y``, after checking that every
    sigma point lies in front of the camera.

    Parameters
    ----------
    n, C, mu, rho, sigma_points
        As for :func:`measurement_update`.
    allow_behind_camera : bool
        If false (default), a sigma point with depth ``<= 0`` raises
        :class:`ValueError`; if true, only a depth of exactly 0 does.

    Returns
    -------
    MeanAndCov
    """
    check_front(_depth(sigma_points.points(n, C)), None, allow_behind_camera)
    return measurement_update(n, C, mu, rho, model.project, sigma_points)


def bearing_predictive(
    n, C, rho, sigma_points: SigmaPoints = SigmaPoints(), allow_behind_camera: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """The UKF's predictive density of a bearing, ``N(z, s)``: :func:`innovation` of ``x / y``.

    The moments :func:`update` uses.

    Parameters
    ----------
    n, C, rho, sigma_points
        As for :func:`innovation`.
    allow_behind_camera : bool
        As for :func:`update` (by default only a sigma point at depth 0 is refused).

    Returns
    -------
    mean, var : ndarray, shape (...)
    """
    X = sigma_points.points(n, C)
    check_front(_depth(X), None, allow_behind_camera)
    moments = innovation(n, C, rho, model.project, sigma_points, points=X)
    return moments.mean, moments.var


class Step(NamedTuple):
    """One frame of the UKF (:func:`step`), batched over problems ``(...)``.

    Attributes
    ----------
    mean : ndarray, shape (..., 3)
        After the frame (the prediction where the bearing is missing or gated).
    cov : ndarray, shape (..., 3, 3)
    log_predictive : ndarray, shape (...)
    tail : ndarray, shape (...)
        The bearing's log density and two-sided tail probability under the
        unscented predictive ``N(z, s)``; NaN where it is missing.
    gated : ndarray of bool, shape (...)
        Where the gate skipped the bearing.
    behind : ndarray of bool, shape (...)
        Where a sigma point the transform used lay at a depth ``<= 0`` (False
        where the bearing is missing: no transform is made there).
    """

    mean: np.ndarray
    cov: np.ndarray
    log_predictive: np.ndarray
    tail: np.ndarray
    gated: np.ndarray
    behind: np.ndarray


def step(
    n,
    C,
    mu,
    rho,
    present=True,
    gate=None,
    sigma_points: SigmaPoints = SigmaPoints(),
    allow_behind_camera: bool = False,
    h=model.project,
    depth=_depth,
) -> Step:
    """One frame's update, masked and gated, batched: report the bearing, then incorporate it.

    Where the bearing is present (``present``, not ``NaN``) its predictive
    ``N(z, s)`` (:func:`innovation`) is reported
    (:func:`depthcore.problem.predictive.gaussian`), a tail below ``gate`` is
    skipped, the others are incorporated as by :func:`measurement_update`.
    A sigma point at ``depth(X) == 0`` is refused; one at ``depth(X) < 0`` is
    flagged in ``behind``, and refused in an update unless ``allow_behind_camera``.

    Parameters
    ----------
    n, C : ndarray, shape (..., 3) and (..., 3, 3)
        Predicted mean and covariance.
    mu, rho : array_like, shape (...)
        The bearing (``NaN`` where missing) and its noise SD.
    present : bool or array_like of bool, shape (...)
    gate : float or None
        Checked by :func:`depthcore.problem.predictive.gate`.
    sigma_points : SigmaPoints
    allow_behind_camera : bool
    h : callable
        The measurement, states (..., 3) to (...); default ``x / y``.
    depth : callable
        States (..., 3) to what must be positive for a point to lie in front
        of the camera; default ``y``.

    Returns
    -------
    Step
    """
    n = np.asarray(n, dtype=float)
    C = np.asarray(C, dtype=float)
    batch = n.shape[:-1]
    mu = np.broadcast_to(np.asarray(mu, dtype=float), batch)
    rho = np.broadcast_to(np.asarray(rho, dtype=float), batch)
    here = np.broadcast_to(present, batch) & ~np.isnan(mu)
    log_p, tail = np.full(batch, np.nan), np.full(batch, np.nan)
    gated, behind = np.zeros(batch, dtype=bool), np.zeros(batch, dtype=bool)
    if not np.any(here):
        return Step(n, C, log_p, tail, gated, behind)
    X = sigma_points.points(n, C)
    d = np.asarray(depth(X), dtype=float)
    check_front(d, here, allow_behind_camera=True)
    if np.all(here):
        moments = innovation(n, C, rho, h, sigma_points, points=X)
    else:
        # rows without a bearing are transformed too (h takes the whole batch) and masked:
        # their sigma points may sit on the pole, where h divides by zero
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            moments = innovation(n, C, rho, h, sigma_points, points=X)
        moments = Innovation(
            np.where(here, moments.mean, 0.0),
            np.where(here, moments.var, 1.0),
            np.where(here[..., None], moments.cross, 0.0),
        )
        mu = np.where(here, mu, 0.0)
    if not np.all(moments.var > 0):
        raise ValueError(
            "sigma_points: their negative weights left the innovation's variance "
            f"{float(np.min(moments.var)):.6g} <= 0"
        )
    lp, tl = predictive.gaussian(mu, moments.mean, moments.var)
    gated = predictive.skipped(tl, here, gate)
    log_p, tail = np.where(here, lp, np.nan), np.where(here, tl, np.nan)
    behind = here & np.any(~(d > 0), axis=-1)
    use = here & ~gated
    if not allow_behind_camera:
        check_front(d, use, allow_behind_camera=False)
    if not np.any(use):
        return Step(n, C, log_p, tail, gated, behind)
    mean, cov = _gain_update(n, C, mu, moments)
    if not np.all(use):
        mean = np.where(use[..., None], mean, n)
        cov = np.where(use[..., None, None], cov, C)
    return Step(mean, cov, log_p, tail, gated, behind)


def rule(sigma_points) -> SigmaPoints:
    """``sigma_points`` checked: a :class:`SigmaPoints`, or ``None`` for the default rule."""
    if sigma_points is None:
        return SigmaPoints()
    if not isinstance(sigma_points, SigmaPoints):
        raise ValueError(f"sigma_points must be a SigmaPoints, got {type(sigma_points).__name__}")
    return sigma_points


class UKFHistory(History):
    """The UKF's estimates after each frame, what each update saw, and where it crossed the pole.

    A :class:`~depthcore.problem.gaussian.History` (it unpacks as ``means, covs
    = history``) with one more per-frame array.

    Attributes
    ----------
    means : ndarray, shape (..., N, 3)
    covs : ndarray, shape (..., N, 3, 3)
    updates : depthcore.problem.predictive.Updates
        Per frame (..., N), as :class:`Step` reports them.
    behind : ndarray of bool, shape (..., N)
        :class:`Step`'s ``behind`` at each frame.
    """

    behind = None

    def __new__(cls, means, covs, updates=None, behind=None):
        self = super().__new__(cls, means, covs, updates)
        if behind is not None:
            self.behind = behind
        return self

    @property
    def went_behind(self) -> np.ndarray:
        """Whether a sigma point lay behind the camera at any frame, shape (...)."""
        return np.any(self.behind, axis=-1)


@signature.documented
def run(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise=0.0,
    sigma_points=None,
    allow_behind_camera=False,
    steps=None,
    gate=None,
) -> UKFHistory:
    """Run the UKF over the measurements, batched like :func:`depthcore.kalman.ekf.run`.

    ``mu1`` updates the prior; each further frame is predicted exactly, Eq.
    (10) (:func:`depthcore.kalman.ekf.predict`), then updated by :func:`step`.

    {parameters}
    sigma_points : SigmaPoints or None
        The sigma-point rule; ``None``: ``SigmaPoints()`` (:func:`rule`).
    allow_behind_camera : bool
        See :func:`update`.

    Returns
    -------
    UKFHistory
        Entry ``i`` after frame ``i + 1``.
    """
    sigma_points = rule(sigma_points)
    track = checked_track(mu, rho, prior_mean, prior_cov, steps)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    g = predictive.gate(gate)
    f = track.frames
    regular = f.regular
    n, C = track.mean, track.cov
    means, covs, reports = [], [], []
    for k in range(1, f.mu.shape[-1] + 1):
        if k > 1:
            n, C = ekf.predict(n, C, q) if regular else ekf.predict(n, C, q, f.steps[..., k - 2])
        rho_k = f.row_rho if regular else f.rho[..., k - 1]
        try:
            out = step(
                n,
                C,
                f.mu[..., k - 1],
                rho_k,
                f.present[..., k - 1],
                g,
                sigma_points,
                allow_behind_camera,
            )
        except ValueError as exc:
            raise ValueError(f"update with measurement {k}: {exc}") from None
        n, C = out.mean, out.cov
        means.append(n)
        covs.append(C)
        reports.append(out[2:])
    return history(means, covs, reports)


def history(means, covs, reports) -> UKFHistory:
    """Per-frame means (..., 3), covariances (..., 3, 3) and :class:`Step` reports as a history.

    ``reports``: each frame's ``(log_p, tail, gated, behind)``; a :class:`UKFHistory` of N frames.
    """
    log_p, tail, gated, behind = (np.stack(r, axis=-1) for r in zip(*reports, strict=True))
    updates = predictive.Updates(log_p, tail, gated)
    return UKFHistory(np.stack(means, axis=-2), np.stack(covs, axis=-3), updates, behind)
