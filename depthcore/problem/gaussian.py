"""Gaussian densities on the state, the Gaussian filters' results, and the paper's prior.

Recommended import: ``from depthcore.problem.gaussian import Gaussian, paper_prior``.

* :class:`Gaussian`, with its marginals (Eq. (13)); :func:`gaussian_logpdf`,
  the batched log density every module uses;
* :class:`MeanAndCov` and :class:`History`, the result types of the Gaussian
  filters (:mod:`depthcore.kalman.ekf`, :mod:`depthcore.kalman.ukf`), with each
  update's report (:class:`depthcore.problem.predictive.Updates`);
* :func:`checked_track` and :func:`run_recursion`: the checks and the loop of
  the recursive Gaussian filters, over tracks with gaps, noise per frame and steps;
* :func:`paper_prior` and :func:`paper_prior_means`: the paper's prior rule,
  for one triple and for a batch;
* :func:`student_t`: draws from multivariate Student t laws with their log densities.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from depthcore.problem import checks, frames, model

#: Index of each state component in ``(x, y, v)``.
INDEX = {"x": 0, "y": 1, "v": 2}

#: The paper's prior covariance scale, ``P = 1000 I``.
PAPER_PRIOR_SCALE = 1000.0


def component_mean(index: int, doc: str) -> property:
    """A property: ``self.mean[..., index]``, the mean of one state component."""
    return property(lambda self: self.mean[..., index], doc=doc)


def component_sd(index: int, doc: str) -> property:
    """A property: ``sqrt(self.cov[..., index, index])``, the SD of one state component."""
    return property(lambda self: np.sqrt(self.cov[..., index, index]), doc=doc)


@dataclass(frozen=True)
class Gaussian:
    """A Gaussian density ``N(x, mean, cov)`` on the state ``(x, y, v)``.

    Attributes
    ----------
    mean : ndarray, shape (3,)
    cov : ndarray, shape (3, 3)
        Symmetric positive definite.
    """

    mean: np.ndarray
    cov: np.ndarray

    def __post_init__(self):
        mean = checks.finite_array(self.mean, "mean", (3,)).copy()
        cov = checks.covariance(self.cov, "cov", 3).copy()
        mean.setflags(write=False)
        cov.setflags(write=False)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @classmethod
    def prior(cls, prior_mean, prior_cov, names=("prior_mean", "prior_cov")) -> Gaussian:
        """The prior ``N(prior_mean, prior_cov)``, its refusals naming the two arguments.

        Parameters
        ----------
        prior_mean : array_like, shape (3,)
        prior_cov : array_like, shape (3, 3)
            Symmetric positive definite.
        names : tuple of str
            The arguments' names in the refusals (the command line's are its options').
        """
        try:
            return cls(prior_mean, prior_cov)
        except ValueError as exc:
            raise ValueError(
                str(exc).replace("cov ", f"{names[1]} ", 1).replace("mean ", f"{names[0]} ", 1)
            ) from None

    def marginal(self, component: str) -> tuple[float, float]:
        """Eq. (13): mean and standard deviation of one component (``"x"``, ``"y"``, ``"v"``)."""
        i = INDEX[component]
        return float(self.mean[i]), float(np.sqrt(self.cov[i, i]))

    def marginal_pdf(self, component: str, grid) -> np.ndarray:
        """Eq. (13): the marginal density of one component on ``grid`` (any shape)."""
        m, s = self.marginal(component)
        z = (np.asarray(grid, dtype=float) - m) / s
        return np.exp(-0.5 * z**2) / (np.sqrt(2.0 * np.pi) * s)

    def logpdf(self, x) -> np.ndarray:
        """Log density at states ``x`` of shape ``(..., 3)``; returns shape ``x.shape[:-1]``."""
        return gaussian_logpdf(x, self.mean, self.cov)


def symmetric(cov) -> np.ndarray:
    """The symmetric part ``(C + C^T) / 2`` of a stack of square matrices.

    A covariance computed in floating point is symmetric only to roundoff;
    this makes it exactly so, changing it by no more than that roundoff.

    Parameters
    ----------
    cov : ndarray, shape (..., n, n)

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    return 0.5 * (cov + np.swapaxes(cov, -1, -2))


def gaussian_logpdf(x, mean, cov) -> np.ndarray:
    """Log density of ``N(mean, cov)`` at ``x``.

    Parameters
    ----------
    x : array_like, shape (..., d)
    mean : array_like, broadcastable to ``x``
    cov : array_like, shape (d, d) or (..., d, d)
        Symmetric positive definite: one covariance for every point, or a
        stack whose leading axes broadcast against ``x.shape[:-1]``.

    Returns
    -------
    ndarray, shape x.shape[:-1] (broadcast with ``cov.shape[:-2]``)
    """
    x = np.asarray(x, dtype=float)
    chol = np.linalg.cholesky(np.asarray(cov, dtype=float))
    dim = chol.shape[-1]
    d = x - np.asarray(mean, dtype=float)
    if chol.ndim == 2:
        z = np.linalg.solve(chol, d.reshape(-1, dim).T).T.reshape(d.shape)
        logdet = 2.0 * np.sum(np.log(np.diag(chol)))
    else:
        z = (np.linalg.inv(chol) @ d[..., None])[..., 0]
        logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * np.sum(z**2, axis=-1) - 0.5 * logdet - 0.5 * dim * np.log(2.0 * np.pi)


class MeanAndCov(NamedTuple):
    """A Gaussian: mean of shape ``(..., n)``, covariance of shape ``(..., n, n)``.

    ``n = 3`` for the state ``(x, y, v)``; any ``n`` for the linear-Gaussian
    model of :mod:`depthcore.kalman.linear`.
    """

    mean: np.ndarray
    cov: np.ndarray


class _Pair(NamedTuple):
    means: np.ndarray
    covs: np.ndarray


class History(_Pair):
    """A Gaussian filter's estimates after each measurement, and what each update saw.

    It unpacks as ``means, covs = history``.

    Attributes
    ----------
    means : ndarray, shape (..., K, 3)
        ``means[..., i, :]`` is the mean after measurement ``mu_{i+1}`` (the
        prediction, where that bearing is missing or gated).
    covs : ndarray, shape (..., K, 3, 3)
        ``covs[..., i, :, :]`` is the covariance after measurement ``mu_{i+1}``.
    updates : depthcore.problem.predictive.Updates or None
        Per frame, the bearing's log predictive density and tail probability
        and whether the gate skipped it, each of shape (..., K); ``None`` when
        the filter does not report them.
    """

    updates = None

    def __new__(cls, means, covs, updates=None):
        self = super().__new__(cls, means, covs)
        if updates is not None:
            self.updates = updates
        return self

    @property
    def posterior(self) -> Gaussian:
        """The filter's density of the state at the last time (one triple only)."""
        return Gaussian(self.means[-1], self.covs[-1])


class CheckedTrack(NamedTuple):
    """A batch of tracks and a prior, checked once for a Gaussian filter (:func:`checked_track`).

    Attributes
    ----------
    frames : depthcore.problem.frames.Frames
        The bearings (``NaN`` where missing), which are present, ``rho`` per
        frame (..., N) and the steps (..., N - 1).
    mean : ndarray, shape (..., 3)
        The prior mean, broadcast to the batch (read-only).
    cov : ndarray, shape (..., 3, 3)
        The prior covariance, broadcast to the batch (read-only).
    """

    frames: frames.Frames
    mean: np.ndarray
    cov: np.ndarray


def checked_track(mu, rho, prior_mean, prior_cov, steps=None, triples: bool = True) -> CheckedTrack:
    """Check a Gaussian filter's track and prior: the paper's frames as ever, others as they come.

    Finite bearings with one ``rho`` per problem and no ``steps`` go through
    :func:`depthcore.problem.model.batch_problem` (its refusals, e.g. the
    paper's triple behind the camera); a track with gaps, ``rho`` per frame or
    steps through :func:`depthcore.problem.frames.check`, the prior through
    the same checks.

    Parameters
    ----------
    mu : array_like, shape (..., N)
    rho : float or array_like, shape (...) or (..., N)
    prior_mean : array_like, shape (3,) or (..., 3)
    prior_cov : array_like, shape (3, 3) or (..., 3, 3)
    steps : array_like, shape (N - 1,) or (..., N - 1), or None
    triples : bool
        As for :func:`depthcore.problem.model.batch_problem` (``False``: any
        ``N >= 1`` finite bearings of the paper's frames).

    Returns
    -------
    CheckedTrack
    """
    mu_arr = checks.as_float(mu, "mu")
    rho_arr = checks.as_float(rho, "rho")
    paper = (
        steps is None
        and not np.any(np.isnan(mu_arr))
        and (rho_arr.ndim == 0 or rho_arr.shape != mu_arr.shape)
    )
    if paper:
        mu_arr, rho_arr, prior_mean, prior_cov = model.batch_problem(
            mu_arr, rho_arr, prior_mean, prior_cov, triples
        )
        n = mu_arr.shape[-1]
        checked = frames.Frames(
            mu_arr,
            np.ones(mu_arr.shape, dtype=bool),
            np.broadcast_to(rho_arr[..., None], mu_arr.shape),
            np.broadcast_to(np.ones(n - 1), mu_arr.shape[:-1] + (n - 1,)),
        )
    else:
        checked = frames.check(mu_arr, rho_arr, steps)
        # the prior's checks; the bearings and the noise are checked above
        _, _, prior_mean, prior_cov = model.batch_problem(
            np.zeros(checked.mu.shape[:-1] + (1,)), 1.0, prior_mean, prior_cov, triples=False
        )
    batch = checked.mu.shape[:-1]
    return CheckedTrack(
        checked,
        np.broadcast_to(prior_mean, batch + (3,)),
        np.broadcast_to(prior_cov, batch + (3, 3)),
    )


def run_recursion(
    mean, cov, mu, predict, update, present=None, predictive_step=None, gate=None
) -> History:
    """The predict-update loop of the recursive Gaussian filters, batched, on checked inputs.

    From ``N(mean, cov)``, the Gaussian of the state at frame 1, incorporate
    ``mu_1``; then, for each frame ``k = 2 .. K``, predict the state at frame
    ``k`` and incorporate ``mu_k`` (textbook 19.3). A missing bearing (``NaN``,
    or ``present`` false) or one the gate skips is not incorporated: the state
    after that frame is the prediction (a masked update, row by row). The
    filter's own coordinates, prediction and update are the caller's, as are
    the checks of the inputs and the wording of a refusal.

    Parameters
    ----------
    mean : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    mu : ndarray, shape (..., K)
        Bearings in time order, ``K >= 1``; ``NaN`` where missing.
    predict : callable
        ``predict(mean, cov, k) -> (mean, cov)``: the state at frame ``k`` from
        the state at frame ``k - 1``.
    update : callable
        ``update(mean, cov, mu_k, k) -> (mean, cov)``: incorporate the bearing of
        frame ``k`` (it sees a finite ``mu_k`` in every row: the predicted
        bearing, or 0, where the bearing is not incorporated).
    present : ndarray of bool, shape (..., K), optional
        Where a bearing is present; default where ``mu`` is not ``NaN``.
    predictive_step : callable, optional
        ``predictive_step(mean, cov, k) -> (bearing_mean, bearing_var)``, each
        (...): the Gaussian predictive density of the bearing of frame ``k``
        (:func:`depthcore.problem.predictive.gaussian`). Without it the result's
        ``updates`` is ``None`` and there is no gate.
    gate : float or None
        From :func:`depthcore.problem.predictive.gate`: skip a bearing whose
        tail probability is below it.

    Returns
    -------
    History
        ``means`` (..., K, d) and ``covs`` (..., K, d, d) after each bearing,
        and the per-frame ``updates`` (..., K) when ``predictive_step`` is given.
    """
    # imported here: ``import depthcore`` reads this module and leaves SciPy unloaded
    from depthcore.problem import predictive

    mu = np.asarray(mu, dtype=float)
    present = ~np.isnan(mu) if present is None else np.asarray(present, dtype=bool)
    means, covs, reports = [], [], []
    for k in range(1, mu.shape[-1] + 1):
        if k > 1:
            mean, cov = predict(mean, cov, k)
        here = np.broadcast_to(present[..., k - 1], np.shape(mean)[:-1])
        mu_k = np.where(here, mu[..., k - 1], 0.0)
        use = here
        if predictive_step is not None:
            bearing_mean, bearing_var = predictive_step(mean, cov, k)
            mu_k = np.where(here, mu_k, bearing_mean)
            log_p, tail = predictive.gaussian(mu_k, bearing_mean, bearing_var)
            gated = predictive.skipped(tail, here, gate)
            reports.append((np.where(here, log_p, np.nan), np.where(here, tail, np.nan), gated))
            use = here & ~gated
        if np.all(use):
            mean, cov = update(mean, cov, mu_k, k)
        elif np.any(use):
            new_mean, new_cov = update(mean, cov, mu_k, k)
            mean = np.where(use[..., None], new_mean, mean)
            cov = np.where(use[..., None, None], new_cov, cov)
        means.append(mean)
        covs.append(cov)
    updates = None
    if reports:
        updates = predictive.Updates(*(np.stack(r, axis=-1) for r in zip(*reports, strict=True)))
    return History(np.stack(means, axis=-2), np.stack(covs, axis=-3), updates)


def paper_prior(c, depth_offset: float = 0.0, scale: float = PAPER_PRIOR_SCALE) -> Gaussian:
    """The paper's prior for the state at time 1, built from the noise-free state ``c``.

    Mean ``(c1 - 2 c3, c2 - 2 + depth_offset, 0)``: the position of ``G^{-2} c`` with
    the velocity set to zero; covariance ``scale * I``. Figure 6 uses
    ``depth_offset = 2``.

    Parameters
    ----------
    c : array_like, shape (3,)
        Noise-free state at time 3, Eq. (7).
    depth_offset : float
        Added to the depth component of the mean.
    scale : float
        Prior variance of each component, > 0.
    """
    c = checks.finite_array(c, "c", (3,))
    depth_offset = float(checks.finite_array(depth_offset, "depth_offset"))
    scale = checks.positive_scalar(scale, "scale")
    return Gaussian(paper_prior_means(c, depth_offset), scale * np.eye(3))


def paper_prior_means(c, depth_offset=0.0) -> np.ndarray:
    """The paper's prior mean ``(c1 - 2 c3, c2 - 2 + depth_offset, 0)``, batched.

    The position of ``G^{-2} c`` (Eq. (1)) with the velocity set to zero.

    Parameters
    ----------
    c : array_like, shape (..., 3)
        Noise-free states at time 3, Eq. (7).
    depth_offset : float or array_like, broadcastable to ``c.shape[:-1]``

    Returns
    -------
    ndarray, shape (..., 3)
    """
    c = np.asarray(c, dtype=float)
    depth = c[..., 1] - 2.0 + np.asarray(depth_offset, dtype=float)
    x = np.broadcast_to(c[..., 0] - 2.0 * c[..., 2], depth.shape)
    return np.stack([x, depth, np.zeros(depth.shape)], axis=-1)


def correlation(cov, i: int = 0, j: int = 1) -> float:
    """The correlation ``cov[i, j] / sqrt(cov[i, i] cov[j, j])`` of components ``i`` and ``j``.

    Parameters
    ----------
    cov : array_like, shape (d, d)
        A covariance with positive ``cov[i, i]`` and ``cov[j, j]``.
    """
    cov = checks.finite_array(cov, "cov")
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1]:
        raise ValueError(f"cov must be square, got shape {cov.shape}")
    if not (cov[i, i] > 0 and cov[j, j] > 0):
        raise ValueError(f"cov[{i}, {i}] and cov[{j}, {j}] must be positive")
    return float(cov[i, j] / np.sqrt(cov[i, i] * cov[j, j]))


def student_t(mean, scale, df: float, n: int, rng: np.random.Generator):
    """Draw ``n`` points per row from multivariate Student t laws, with their log densities.

    ``x = mean + sqrt(df / g) L z`` with ``z`` standard normal, ``g ~ chi2(df)``
    and ``L`` the lower Cholesky factor of ``scale``; ``df = inf`` is the
    Gaussian ``N(mean, scale)``.

    Parameters
    ----------
    mean : array_like, shape (B, d)
    scale : array_like, shape (B, d, d)
        Scale matrices, symmetric positive definite.
    df : float
        Degrees of freedom, > 0, or ``inf``.
    n : int
        Draws per row.
    rng : numpy.random.Generator

    Returns
    -------
    x : ndarray, shape (B, n, d)
    log_q : ndarray, shape (B, n)
        The normalised log density of each draw.
    """
    from scipy.special import gammaln

    mean = np.asarray(mean, dtype=float)
    L = np.linalg.cholesky(np.asarray(scale, dtype=float))
    dim = mean.shape[-1]
    z = rng.standard_normal(mean.shape[:1] + (n, dim))
    log_det = np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)[:, None]
    delta = np.sum(z**2, axis=-1)
    if np.isinf(df):
        factor = np.ones(delta.shape)
        log_q = -0.5 * delta - 0.5 * dim * np.log(2.0 * np.pi) - log_det
    else:
        factor = np.sqrt(df / rng.chisquare(df, delta.shape))
        delta = delta * factor**2  # the Mahalanobis distance of the t draw
        log_q = (
            gammaln((df + dim) / 2.0)
            - gammaln(df / 2.0)
            - 0.5 * dim * np.log(df * np.pi)
            - log_det
            - 0.5 * (df + dim) * np.log1p(delta / df)
        )
    x = mean[:, None, :] + factor[..., None] * np.einsum("bij,bnj->bni", L, z)
    return x, log_q
