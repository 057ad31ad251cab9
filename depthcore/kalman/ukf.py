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

Pulling the points in does not rescue the filter on the paper's prior. Under
``N(n, 1000 I)`` the depth has positive density ``p_y(0)`` at ``y = 0``, so
``P(|y| < eps)`` is about ``2 eps p_y(0)`` and ``E[(x / y)**2 ; |y| > eps]``
grows like ``2 p_y(0) E[x**2 | y = 0] / eps``: ``Var[x / y]`` is infinite and
``E[x / y]`` does not exist (:func:`depthcore.book.beyond_filters.truncated_bearing_moments`).
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
from functools import partial

import numpy as np

from depthcore import _paths
from depthcore.kalman.ekf import run_gaussian_filter
from depthcore.problem import checks, model, signature
from depthcore.problem.gaussian import History, MeanAndCov, symmetric

#: The UKF's estimates after each measurement (the type of :func:`depthcore.kalman.ekf.run`).
UKFHistory = History

#: Dimension of the state ``(x, y, v)``.
DIM = 3


@dataclass(frozen=True)
class SigmaPoints:
    """Scaled sigma points of Julier and Uhlmann / Wan and van der Merwe.

    See the module docstring for the points and weights.

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


def measurement_update(
    n, C, mu, rho: float, h=model.project, sigma_points: SigmaPoints = SigmaPoints()
) -> MeanAndCov:
    """Incorporate one scalar measurement ``mu = h(x) + w`` into ``N(n, C)``, batched.

    The measurement update of [wan2000]_, section 3, for a scalar measurement
    with noise variance ``rho**2``; the equations are in the module docstring.

    Parameters
    ----------
    n : array_like, shape (..., 3)
        Predicted mean.
    C : array_like, shape (..., 3, 3)
        Predicted covariance, symmetric positive definite.
    mu : float or array_like, shape (...)
        The measurement.
    rho : float or array_like, shape (...)
        Noise standard deviation, > 0.
    h : callable
        Maps states of shape ``(..., 3)`` to measurements of shape ``(...)``;
        default the projection ``x / y``.
    sigma_points : SigmaPoints

    Returns
    -------
    MeanAndCov
        The updated mean ``(..., 3)`` and covariance ``(..., 3, 3)``.
    """
    n = np.asarray(n, dtype=float)
    X = sigma_points.points(n, C)  # (..., 7, 3)
    Wm, Wc = sigma_points.weights()
    Z = np.asarray(h(X), dtype=float)[..., None]  # (..., 7, 1)
    noise_var = np.asarray(rho, dtype=float) ** 2
    z, S = unscented_transform(Z, Wm, Wc, noise_var[..., None, None])
    z, s = z[..., 0], S[..., 0, 0]
    c = np.einsum("i,...ij,...i->...j", Wc, X - n[..., None, :], Z[..., 0] - z[..., None])
    innovation = np.asarray(mu, dtype=float) - z
    mean = n + (innovation / s)[..., None] * c
    cov = np.asarray(C, dtype=float) - c[..., :, None] * c[..., None, :] / s[..., None, None]
    return MeanAndCov(mean, symmetric(cov))


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
    depth = sigma_points.points(n, C)[..., 1]
    bad = depth == 0 if allow_behind_camera else ~(depth > 0)
    if np.any(bad):
        where = tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), depth.shape))
        trial = f" of trial {where[:-1]}" if depth.ndim > 1 else ""
        if allow_behind_camera:
            raise ValueError(f"sigma point {where[-1]}{trial} has depth 0, where x/y is undefined")
        raise ValueError(
            f"sigma point {where[-1]}{trial} has depth {depth[where]:.6g} <= 0: it lies behind "
            "the camera, across the pole of x/y at y = 0; use a smaller alpha or a tighter "
            "prior, or pass allow_behind_camera=True"
        )
    return measurement_update(n, C, mu, rho, model.project, sigma_points)


def rule(sigma_points) -> SigmaPoints:
    """``sigma_points`` checked: a :class:`SigmaPoints`, or ``None`` for the default rule."""
    if sigma_points is None:
        return SigmaPoints()
    if not isinstance(sigma_points, SigmaPoints):
        raise ValueError(f"sigma_points must be a SigmaPoints, got {type(sigma_points).__name__}")
    return sigma_points


@signature.documented
def run(
    mu, rho, prior_mean, prior_cov, process_noise=0.0, sigma_points=None, allow_behind_camera=False
) -> History:
    """Run the UKF over the measurements, batched like :func:`depthcore.kalman.ekf.run`.

    Incorporate ``mu1`` into the prior (the density of the state at time 1),
    then predict exactly with Eq. (10) (plus ``q**2`` on the velocity's
    variance) and update, once per further measurement (the loop
    :func:`depthcore.kalman.ekf.run_gaussian_filter`).

    {parameters}
    sigma_points : SigmaPoints or None
        The sigma-point rule; ``None``: ``SigmaPoints()`` (:func:`rule`).
    allow_behind_camera : bool
        See :func:`update`.

    Returns
    -------
    History
        ``means`` (..., N, 3): ``means[..., i, :]`` is the mean after
        measurement ``i + 1``; ``covs`` (..., N, 3, 3).
    """
    sigma_points = rule(sigma_points)
    step = partial(update, sigma_points=sigma_points, allow_behind_camera=allow_behind_camera)
    return run_gaussian_filter(step, mu, rho, prior_mean, prior_cov, process_noise)


#: :func:`depthcore.kalman.ukf.run` with the prior as a Gaussian, ``ukf(mu, rho, prior,
#: sigma_points, allow_behind_camera, process_noise)``; kept until 0.3.
ukf = _paths.kept(
    "depthcore.kalman.ukf.ukf", run, ("sigma_points", "allow_behind_camera", "process_noise")
)
