"""The Kalman filter and its smoothers for a linear-Gaussian model (Prince, section 19.2).

Recommended import: ``from depthcore.kalman import linear``.

The model of [prince2012]_, in its notation: the state ``w_t`` (dimension ``n``)
and the measurement ``x_t`` (dimension ``m``) at times ``t = 1 .. T`` obey

    w_t = mu_p + Psi w_{t-1} + eps_p,   eps_p ~ N(0, Sigma_p)    (textbook Eq. (19.5))
    x_t = mu_m + Phi w_t + eps_m,       eps_m ~ N(0, Sigma_m)    (textbook Eq. (19.7))

with a Gaussian prior ``N(mu_0, Sigma_0)`` on ``w_1``. The filter alternates:

* prediction, textbook 19.2.1 (the Chapman-Kolmogorov integral):
  ``mu_+ = mu_p + Psi mu_{t-1}``, ``Sigma_+ = Sigma_p + Psi Sigma_{t-1} Psi^T``;
* measurement incorporation in the gain form of textbook 19.2.2 (Eq. (19.10)
  by the matrix inversion lemma): ``K = Sigma_+ Phi^T S_t^{-1}``,
  ``mu_t = mu_+ + K (x_t - mu_m - Phi mu_+)``, ``Sigma_t = (I - K Phi) Sigma_+``
  in the Joseph form ``(I - K Phi) Sigma_+ (I - K Phi)^T + K Sigma_m K^T``
  (positive semi-definite in floating point).

The innovation ``x_t - mu_m - Phi mu_+`` is ``N(0, S_t)``, ``S_t = Sigma_m +
Phi Sigma_+ Phi^T``; the log marginal likelihood sums their log densities.

Smoothing, textbook 19.2.6: the fixed-interval (Rauch-Tung-Striebel) smoother
runs, backward,

    C_t = Sigma_t Psi^T Sigma_{+|t+1}^{-1}
    mu_{t|T} = mu_t + C_t (mu_{t+1|T} - mu_{+|t+1})
    Sigma_{t|T} = Sigma_t + C_t (Sigma_{t+1|T} - Sigma_{+|t+1}) C_t^T

over the filter's output; the fixed-lag smoother runs the filter on the state
augmented with its ``tau`` predecessors (:func:`augment`).

Leading axes ``(...)`` of all arrays broadcast: independent filters run side by side.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, section 19.2 (the Kalman filter, 19.2.1-19.2.3;
   smoothing, 19.2.6).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from depthcore.problem import checks
from depthcore.problem.gaussian import MeanAndCov, symmetric

_LOG_2PI = float(np.log(2.0 * np.pi))
#: Relative asymmetry tolerated in a covariance matrix.
_SYMMETRY_TOL = 1e-10
#: Eigenvalues of a positive semi-definite matrix may fall this far (relative) below 0.
_PSD_TOL = 1e-12
#: One half as a NumPy scalar: multiplying an array by it skips converting a Python float.
_HALF = np.float64(0.5)


class Update(NamedTuple):
    """The result of one measurement incorporation (textbook 19.2.2).

    Attributes
    ----------
    mean : ndarray, shape (..., n)
    cov : ndarray, shape (..., n, n)
    log_likelihood : ndarray, shape (...)
        The innovation's log density given the earlier measurements.
    """

    mean: np.ndarray
    cov: np.ndarray
    log_likelihood: np.ndarray


class FilterResult(NamedTuple):
    """The Kalman filter's output over ``T`` measurements.

    Attributes
    ----------
    means : ndarray, shape (..., T, n)
    covs : ndarray, shape (..., T, n, n)
        Entry ``t``: after measurement ``t + 1``.
    predicted_means : ndarray, shape (..., T, n)
    predicted_covs : ndarray, shape (..., T, n, n)
        Entry ``t``: before measurement ``t + 1`` (the prior at ``t = 0``).
    log_likelihoods : ndarray, shape (..., T)
        Log density of each measurement given the earlier ones.
    """

    means: np.ndarray
    covs: np.ndarray
    predicted_means: np.ndarray
    predicted_covs: np.ndarray
    log_likelihoods: np.ndarray

    @property
    def log_likelihood(self) -> np.ndarray:
        """Log marginal likelihood of all measurements, shape (...)."""
        return np.sum(self.log_likelihoods, axis=-1)


def _array(value, name: str, min_ndim: int) -> np.ndarray:
    arr = checks.as_float(value, name)
    if arr.ndim < min_ndim:
        raise ValueError(f"{name} must have at least {min_ndim} dimensions, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(
            f"{name} must be finite, got {int(np.sum(~np.isfinite(arr)))} non-finite entries"
        )
    return arr


def _last(arr: np.ndarray, name: str, shape: tuple) -> np.ndarray:
    if arr.shape[arr.ndim - len(shape) :] != shape:
        raise ValueError(f"{name} must have trailing shape {shape}, got shape {arr.shape}")
    return arr


def _vector(value, name: str, n: int) -> np.ndarray:
    return _last(_array(value, name, 1), name, (n,))


def _matrix(value, name: str, rows: int, cols: int) -> np.ndarray:
    return _last(_array(value, name, 2), name, (rows, cols))


def _covariance(value, name: str, n: int, definite: bool) -> np.ndarray:
    """A symmetric positive definite (or, with ``definite=False``, semi-definite) stack."""
    arr = _matrix(value, name, n, n)
    scale = np.max(np.abs(arr), axis=(-2, -1), keepdims=True)
    if np.any(np.abs(arr - np.swapaxes(arr, -1, -2)) > _SYMMETRY_TOL * scale):
        raise ValueError(f"{name} must be symmetric")
    arr = symmetric(arr)
    if definite:
        try:
            np.linalg.cholesky(arr)
            return arr
        except np.linalg.LinAlgError:
            pass
    low = np.min(np.linalg.eigvalsh(arr))
    if (definite and not low > 0) or low < -_PSD_TOL * np.max(scale):
        kind = "definite" if definite else "semi-definite"
        raise ValueError(f"{name} must be positive {kind}, got smallest eigenvalue {low:.6g}")
    return arr


def _transition(Psi, Sigma_p, mu_p, n: int):
    """Check the prediction's ``Psi``, ``Sigma_p`` and ``mu_p`` (zero by default) against ``n``."""
    Psi = _matrix(Psi, "Psi", n, n)
    Sigma_p = _covariance(Sigma_p, "Sigma_p", n, definite=False)
    return Psi, Sigma_p, np.zeros(n) if mu_p is None else _vector(mu_p, "mu_p", n)


def _measurement(Phi, Sigma_m, mu_m, n: int):
    """Check the update's ``Phi``, ``Sigma_m`` and ``mu_m`` (zero by default) against ``n``."""
    Phi = _array(Phi, "Phi", 2)
    if Phi.shape[-1] != n:
        raise ValueError(f"Phi must have trailing shape (m, {n}), got shape {Phi.shape}")
    m = Phi.shape[-2]
    Sigma_m = _covariance(Sigma_m, "Sigma_m (the measurement noise covariance)", m, definite=True)
    return Phi, Sigma_m, np.zeros(m) if mu_m is None else _vector(mu_m, "mu_m", m)


def _state(mean, cov) -> tuple[np.ndarray, np.ndarray]:
    """Check a filtered or predicted ``mean`` and ``cov`` (positive semi-definite)."""
    mean = _array(mean, "mean", 1)
    return mean, _covariance(cov, "cov", mean.shape[-1], definite=False)


def _eye(n: int) -> np.ndarray:
    """The identity of size ``n``, read-only and made once per size."""
    if n not in _EYES:
        _EYES[n] = np.eye(n)
        _EYES[n].setflags(write=False)
    return _EYES[n]


_EYES: dict[int, np.ndarray] = {}


def _predict(mean, cov, Psi, Sigma_p, mu_p) -> MeanAndCov:
    mean = mu_p + (Psi @ mean[..., None])[..., 0]
    cov = Sigma_p + Psi @ cov @ Psi.mT
    return MeanAndCov(mean, symmetric(cov))


def predict(mean, cov, Psi, Sigma_p, mu_p=None) -> MeanAndCov:
    """Textbook 19.2.1: predict ``mu_+ = mu_p + Psi mu``, ``Sigma_+ = Sigma_p + Psi Sigma Psi^T``.

    Parameters
    ----------
    mean, cov : array_like, shape (..., n) and (..., n, n)
        Filtered mean and covariance (positive semi-definite) at time ``t - 1``.
    Psi, Sigma_p : array_like, shape (..., n, n)
        Transition matrix and noise covariance (positive semi-definite).
    mu_p : array_like, shape (..., n), optional
        Mean change of the state; zero by default.

    Returns
    -------
    MeanAndCov
        Leading axes broadcast.
    """
    mean, cov = _state(mean, cov)
    Psi, Sigma_p, mu_p = _transition(Psi, Sigma_p, mu_p, mean.shape[-1])
    return _predict(mean, cov, Psi, Sigma_p, mu_p)


def joseph(cov, gain, Phi, Sigma_m) -> np.ndarray:
    """Textbook 19.2.2: the updated covariance in the Joseph form (module docstring), symmetrised.

    The EKF's Eq. (12) is the case ``Phi = h^T``, ``Sigma_m = rho**2``.

    Parameters
    ----------
    cov : ndarray, shape (..., n, n)
        The predicted covariance ``Sigma_+``.
    gain : ndarray, shape (..., n, m)
        The gain ``K``.
    Phi : ndarray, shape (..., m, n)
        The measurement matrix (the linearised measurement).
    Sigma_m : ndarray, shape (..., m, m)
        The measurement noise covariance.

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    A = _eye(cov.shape[-1]) - gain @ Phi
    return symmetric(A @ cov @ A.mT + gain @ Sigma_m @ gain.mT)


def _gain(PHt, S) -> np.ndarray:
    """Textbook 19.2.2: the gain ``K = Sigma_+ Phi^T S^{-1}`` (..., n, m) from ``Sigma_+ Phi^T``."""
    if S.shape[-1] == 1:
        return PHt / S
    return np.linalg.solve(S, PHt.mT).mT


def _innovation_log_density(r, S) -> np.ndarray:
    """``log N(r; 0, S)`` (...) of innovations ``r`` (..., m) with covariances ``S`` (..., m, m)."""
    if S.shape[-1] == 1:  # a scalar measurement: divide instead of factorising
        s = S[..., 0, 0]
        log_det = np.log(s)
        quad = r[..., 0] ** 2 / s
    else:
        chol = np.linalg.cholesky(S)
        log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
        z = np.linalg.solve(chol, r[..., None])[..., 0]
        quad = np.sum(z**2, axis=-1)
    return -0.5 * (S.shape[-1] * _LOG_2PI + log_det + quad)


def _update(mean, cov, x, Phi, Sigma_m, mu_m) -> Update:
    PHt = cov @ Phi.mT
    K, S = _gain_and_innovation_cov(PHt, Sigma_m + Phi @ PHt)
    r = x - mu_m - (Phi @ mean[..., None])[..., 0]  # the innovation (..., m)
    new_mean = mean + (K @ r[..., None])[..., 0]
    return Update(new_mean, joseph(cov, K, Phi, Sigma_m), _innovation_log_density(r, S))


def update(mean, cov, x, Phi, Sigma_m, mu_m=None) -> Update:
    """Textbook 19.2.2: incorporate the measurement ``x`` in the gain form (module docstring).

    Parameters
    ----------
    mean, cov : array_like, shape (..., n) and (..., n, n)
        Predicted mean ``mu_+`` and covariance ``Sigma_+`` (positive semi-definite).
    x : array_like, shape (..., m)
        The measurement (``m = 1`` for a scalar one).
    Phi, Sigma_m : array_like, shape (..., m, n) and (..., m, m)
        Measurement matrix and noise covariance (positive definite).
    mu_m : array_like, shape (..., m), optional
        Measurement offset; zero by default.

    Returns
    -------
    Update
        Leading axes broadcast.
    """
    mean, cov = _state(mean, cov)
    Phi, Sigma_m, mu_m = _measurement(Phi, Sigma_m, mu_m, mean.shape[-1])
    x = _vector(x, "x", Phi.shape[-2])
    return _update(mean, cov, x, Phi, Sigma_m, mu_m)


def _at(arr: np.ndarray, t: int, core: int) -> np.ndarray:
    """Step ``t`` of a model array: itself if it has only its ``core`` axes, else its time slice."""
    if arr.ndim == core:
        return arr
    return arr[(..., min(t, arr.shape[-core - 1] - 1)) + (slice(None),) * core]


def _time_axis(arr: np.ndarray, name: str, core: int, steps: int) -> None:
    if arr.ndim > core and arr.shape[-core - 1] not in (1, steps):
        raise ValueError(
            f"{name} must have {steps} (or 1) entries on its time axis "
            f"{-core - 1}, got shape {arr.shape}"
        )


def _batch_shape(x, mean, cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m) -> tuple:
    """The leading axes that every step's output broadcasts to (the model's time axes dropped)."""
    shapes = [x.shape[:-2], mean.shape[:-1], cov.shape[:-2]]
    for arr, core in ((Psi, 2), (Sigma_p, 2), (Phi, 2), (Sigma_m, 2), (mu_p, 1), (mu_m, 1)):
        if arr.ndim > core:
            shapes.append(arr.shape[: arr.ndim - core - 1])
    return np.broadcast_shapes(*shapes)


def _steps(arr: np.ndarray, core: int, steps: int) -> list:
    """The model array ``arr`` at each of ``steps`` steps: itself, or its time slices (views)."""
    if arr.ndim == core:
        return [arr] * steps
    return [_at(arr, t, core) for t in range(steps)]


def _time_first(arr: np.ndarray, core: int) -> np.ndarray:
    """A view of ``arr`` (..., T, *core) with its time axis first, for cheap per-step indexing."""
    return np.moveaxis(arr, -core - 1, 0)


def _symmetric_matrix(A: np.ndarray) -> np.ndarray:
    """``(A + A^T) / 2`` of one matrix (n, n): :func:`symmetric`'s numbers, faster."""
    return (A + A.T.copy()) * _HALF


def _gain_and_innovation_cov(PHt, S) -> tuple[np.ndarray, np.ndarray]:
    """The gain (:func:`_gain`) and ``S``'s symmetric part, from ``PHt`` and ``S`` as computed."""
    if S.shape[-1] > 1:
        S = symmetric(S)
    return _gain(PHt, S), S


def _matrix_gain_and_innovation_cov(PHt, S) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_gain_and_innovation_cov` for one filter, ``PHt`` (n, m) and ``S`` (m, m).

    For ``m = 2`` the symmetric part ``[[a, b], [b, c]]`` of ``S`` is inverted
    from its Cholesky factor ``L`` in closed form, LAPACK's ``potrf`` arithmetic:
    ``l11 = sqrt(a)``, ``l21 = b / l11``, ``l22 = sqrt(c - l21^2)``, ``S^{-1} =
    L^{-T} L^{-1}``. A failed factorisation is left to LAPACK's solver.
    """
    m = S.shape[-1]
    if m == 1:
        return PHt / S, S
    if m == 2:
        (a, b01), (b10, c) = S.tolist()
        b = (b01 + b10) * 0.5
        S = np.array([[a, b], [b, c]])
        if a > 0.0:
            l11 = math.sqrt(a)
            l21 = b / l11
            d = c - l21 * l21
            if d > 0.0 and math.isfinite(d):
                i11, i22 = 1.0 / l11, 1.0 / math.sqrt(d)
                i21 = -l21 * i11 * i22
                off = i21 * i22
                inverse = np.array([[i11 * i11 + i21 * i21, off], [off, i22 * i22]])
                return PHt.dot(inverse), S
        return np.linalg.solve(S, PHt.T).T, S
    S = _symmetric_matrix(S)
    return np.linalg.solve(S, PHt.T).T, S


def _run(x, mean, cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m) -> FilterResult:
    """The filter's loop over checked inputs (:func:`run`): :func:`predict` and :func:`update`.

    Only what depends on the previous step is done per step; means are
    columns ``(..., n, 1)``, and the log densities come after the loop. A
    single filter uses ``ndarray.dot`` and :func:`_matrix_gain_and_innovation_cov`.
    """
    T, n, m = x.shape[-2], mean.shape[-1], x.shape[-1]
    batch = _batch_shape(x, mean, cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m)
    if batch:
        mm, sym, gain = np.matmul, symmetric, _gain_and_innovation_cov
    else:
        mm, sym, gain = np.ndarray.dot, _symmetric_matrix, _matrix_gain_and_innovation_cov
    means, pmeans = np.empty(batch + (T, n, 1)), np.empty(batch + (T, n, 1))
    covs, pcovs = np.empty(batch + (T, n, n)), np.empty(batch + (T, n, n))
    innovations, innovation_covs = np.empty(batch + (T, m, 1)), np.empty(batch + (T, m, m))
    means_t, pmeans_t, covs_t, pcovs_t, r_t, S_t = (
        _time_first(a, 2) for a in (means, pmeans, covs, pcovs, innovations, innovation_covs)
    )
    Psis, Sigma_ps = _steps(Psi, 2, T - 1), _steps(Sigma_p, 2, T - 1)
    Psi_Ts = [P.mT for P in Psis] if Psi.ndim > 2 else [Psi.mT] * (T - 1)
    offsets = np.any(mu_p != 0.0)  # a zero offset is skipped: adding it changes nothing
    mu_ps = _steps(mu_p[..., None], 2, T - 1)
    Phis, Sigma_ms = _steps(Phi, 2, T), _steps(Sigma_m, 2, T)
    Phi_Ts = [P.mT for P in Phis] if Phi.ndim > 2 else [Phi.mT] * T
    xs = _time_first((x - mu_m)[..., None], 2)  # x_t - mu_m, (T, ..., m, 1)
    eye = _eye(n)
    mean = mean[..., None]
    for t in range(T):
        if t > 0:  # textbook 19.2.1
            Psi_t = Psis[t - 1]
            mean = mm(Psi_t, mean)
            if offsets:
                mean = mu_ps[t - 1] + mean
            cov = sym(Sigma_ps[t - 1] + mm(mm(Psi_t, cov), Psi_Ts[t - 1]))
        pmeans_t[t] = mean
        pcovs_t[t] = cov
        Phi_t, Sigma_m_t = Phis[t], Sigma_ms[t]
        PHt = mm(cov, Phi_Ts[t])
        K, S = gain(PHt, Sigma_m_t + mm(Phi_t, PHt))
        r = xs[t] - mm(Phi_t, mean)
        mean = mean + mm(K, r)
        A = eye - mm(K, Phi_t)
        cov = sym(mm(mm(A, cov), A.mT) + mm(mm(K, Sigma_m_t), K.mT))
        means_t[t] = mean
        covs_t[t] = cov
        r_t[t] = r
        S_t[t] = S
    return FilterResult(
        means[..., 0],
        covs,
        pmeans[..., 0],
        pcovs,
        _innovation_log_density(innovations[..., 0], innovation_covs),
    )


def _sequence(x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m):
    """Check the inputs of a run over a sequence; return them as arrays."""
    prior_mean = _array(prior_mean, "prior_mean", 1)
    n = prior_mean.shape[-1]
    prior_cov = _covariance(prior_cov, "prior_cov", n, definite=True)
    Psi, Sigma_p, mu_p = _transition(Psi, Sigma_p, mu_p, n)
    Phi, Sigma_m, mu_m = _measurement(Phi, Sigma_m, mu_m, n)
    x = _array(x, "x", 2)
    T, m = x.shape[-2:]
    if m != Phi.shape[-2]:
        raise ValueError(f"x must have trailing shape (T, {Phi.shape[-2]}), got shape {x.shape}")
    for arr, name, core, steps in (
        (Psi, "Psi", 2, T - 1),
        (Sigma_p, "Sigma_p", 2, T - 1),
        (mu_p, "mu_p", 1, T - 1),
        (Phi, "Phi", 2, T),
        (Sigma_m, "Sigma_m", 2, T),
        (mu_m, "mu_m", 1, T),
    ):
        _time_axis(arr, name, core, steps)
    return x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m


def run(x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p=None, mu_m=None) -> FilterResult:
    """Textbook 19.2.3: the Kalman filter over ``T`` measurements, with the log marginal likelihood.

    ``x_1`` updates the prior (19.2.2); each later one follows a prediction (19.2.1).

    Parameters
    ----------
    x : array_like, shape (..., T, m)
        Measurements in time order.
    prior_mean : array_like, shape (..., n)
    prior_cov : array_like, shape (..., n, n)
        Symmetric positive definite.
    Psi, Sigma_p : array_like, shape (n, n) or (..., T - 1, n, n)
        Transition matrix and noise covariance (positive semi-definite). A
        two-dimensional array applies at every step; otherwise axis ``-3`` is
        time (length ``T - 1``, or 1 to broadcast), entry ``t`` taking the state
        from time ``t + 1`` to ``t + 2``.
    Phi : array_like, shape (m, n) or (..., T, m, n)
        Measurement matrix, constant or with time on axis ``-3``.
    Sigma_m : array_like, shape (m, m) or (..., T, m, m)
        Measurement noise covariance, positive definite.
    mu_p : array_like, shape (n,) or (..., T - 1, n), optional
    mu_m : array_like, shape (m,) or (..., T, m), optional
        Offsets, zero by default; time on axis ``-2`` when not one-dimensional.

    Returns
    -------
    FilterResult
        A run whose numbers overflow the doubles (scales near 1e154 and beyond)
        or whose innovation covariance is singular or indefinite to working
        precision is refused with a ValueError, never returned with NaN.
    """
    args = _sequence(x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        try:
            res = _run(*args)
        except np.linalg.LinAlgError:  # the solve or the Cholesky factor of S failed
            raise ValueError(
                "Sigma_m (the measurement noise covariance) is too small beside prior_cov, "
                "Psi and Sigma_p: the innovation covariance Sigma_m + Phi Sigma_+ Phi^T is "
                "not positive definite to working precision; rescale the state or the "
                "measurements"
            ) from None
    if not all(np.all(np.isfinite(a)) for a in res):
        raise ValueError(
            "x, prior_cov, Psi, Sigma_p and Sigma_m are too large together: the filter's "
            "covariances or likelihoods overflowed the doubles; rescale the state or "
            "the measurements"
        )
    return res


def _solve_or_pinv(A, B):
    """``A^{-1} B`` for symmetric positive semi-definite ``A`` (..., n, n), matrix by matrix.

    A matrix singular to working precision (2-norm condition number, from the
    eigenvalues, above ``1 / eps``) takes its pseudo-inverse, each matrix alone.
    """
    lam = np.abs(np.linalg.eigvalsh(A))
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero eigenvalue: singular
        cond = np.max(lam, axis=-1) / np.min(lam, axis=-1)
    singular = ~(cond < 1.0 / np.finfo(float).eps)
    if not np.any(singular):
        return np.linalg.solve(A, B)
    eye = np.broadcast_to(np.eye(A.shape[-1]), A.shape)
    safe = np.where(singular[..., None, None], eye, A)
    return np.where(
        singular[..., None, None], np.linalg.pinv(A, hermitian=True) @ B, np.linalg.solve(safe, B)
    )


def fixed_interval_smoother(filtered: FilterResult, Psi) -> MeanAndCov:
    """Textbook 19.2.6: the fixed-interval (Rauch-Tung-Striebel) smoother (module docstring).

    Where a predicted covariance ``Sigma_{+|t+1}`` is singular, its
    pseudo-inverse takes the place of the inverse: ``w_{t+1} - mu_{+|t+1}``
    lies in its range, where every generalised inverse gives the same answer.

    Parameters
    ----------
    filtered : FilterResult
        The output of :func:`run` over ``T`` measurements.
    Psi : array_like, shape (n, n) or (..., T - 1, n, n)
        The transition matrices the filter used.

    Returns
    -------
    MeanAndCov
        Means (..., T, n) and covariances (..., T, n, n) of the state at every
        time given all ``T`` measurements.
    """
    if not isinstance(filtered, FilterResult):
        raise ValueError(f"filtered must be a FilterResult, got {type(filtered).__name__}")
    T, n = filtered.means.shape[-2:]
    Psi = _matrix(Psi, "Psi", n, n)
    _time_axis(Psi, "Psi", 2, T - 1)
    gains = smoother_gain(
        filtered.covs[..., :-1, :, :], filtered.predicted_covs[..., 1:, :, :], Psi
    )
    batch = np.broadcast_shapes(filtered.means.shape[:-2], gains.shape[:-3])
    means, covs = np.empty(batch + (T, n, 1)), np.empty(batch + (T, n, n))
    means_t, covs_t = _time_first(means, 2), _time_first(covs, 2)
    C_t = _time_first(gains, 2)
    m_t = _time_first(filtered.means[..., None], 2)
    P_t = _time_first(filtered.covs, 2)
    pm_t = _time_first(filtered.predicted_means[..., None], 2)
    pP_t = _time_first(filtered.predicted_covs, 2)
    mm, sym = (np.matmul, symmetric) if batch else (np.ndarray.dot, _symmetric_matrix)
    mean, cov = m_t[T - 1], P_t[T - 1]
    means_t[T - 1], covs_t[T - 1] = mean, cov
    # the arithmetic of smoother_step, without its per-call slicing
    for t in range(T - 2, -1, -1):
        C = C_t[t]
        mean = m_t[t] + mm(C, mean - pm_t[t + 1])
        cov = sym(P_t[t] + mm(mm(C, cov - pP_t[t + 1]), C.mT))
        means_t[t], covs_t[t] = mean, cov
    return MeanAndCov(means[..., 0], covs)


def smoother_gain(cov, predicted_cov, Psi) -> np.ndarray:
    """Textbook 19.2.6: the Rauch-Tung-Striebel gain ``C_t = Sigma_t Psi^T Sigma_{+|t+1}^{-1}``.

    It depends on the filter alone; a singular ``Sigma_{+|t+1}`` is handled as
    in :func:`fixed_interval_smoother`.

    Parameters
    ----------
    cov : ndarray, shape (..., n, n)
        The filtered covariance ``Sigma_t``.
    predicted_cov : ndarray, shape (..., n, n)
        The prediction ``Sigma_{+|t+1}`` made from it.
    Psi : ndarray, shape (..., n, n)
        The transition from ``t`` to ``t + 1``.

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    return np.swapaxes(_solve_or_pinv(predicted_cov, Psi @ cov), -1, -2)


def smoother_step(
    gain, mean, cov, predicted_mean, predicted_cov, next_mean, next_cov
) -> MeanAndCov:
    """Textbook 19.2.6: one backward step of the Rauch-Tung-Striebel smoother (module docstring).

    From the filtered ``(mu_t, Sigma_t)``, its prediction, its gain
    (:func:`smoother_gain`) and the smoothed ``(mu_{t+1|T}, Sigma_{t+1|T})``.

    Parameters
    ----------
    gain, cov, predicted_cov, next_cov : ndarray, shape (..., n, n)
    mean, predicted_mean, next_mean : ndarray, shape (..., n)

    Returns
    -------
    MeanAndCov
        The smoothed mean (..., n) and covariance (..., n, n) of ``w_t``.
    """
    C = gain
    smoothed_mean = mean + (C @ (next_mean - predicted_mean)[..., None])[..., 0]
    smoothed_cov = cov + C @ (next_cov - predicted_cov) @ C.mT
    return MeanAndCov(smoothed_mean, symmetric(smoothed_cov))


def augment(Psi, Sigma_p, Phi, lag: int, mu_p=None):
    """Textbook 19.2.6: the fixed-lag smoother's augmented temporal and measurement models.

    The state ``(w_t, w_{t-1}, .., w_{t-lag})`` moves by ``Psi_a = [[Psi, 0, ..],
    [I, 0, ..], [0, I, ..], ..]``, noise and offset on the first block alone,
    and is measured by ``Phi_a = [Phi, 0, .., 0]``.

    Parameters
    ----------
    Psi, Sigma_p : array_like, shape (..., n, n)
    Phi : array_like, shape (..., m, n)
    lag : int
        Number of delayed copies ``tau >= 0``.
    mu_p : array_like, shape (..., n), optional

    Returns
    -------
    Psi_a, Sigma_pa : ndarray, shape (..., n (lag + 1), n (lag + 1))
    Phi_a : ndarray, shape (..., m, n (lag + 1))
    mu_pa : ndarray, shape (..., n (lag + 1))
    """
    lag = checks.nonnegative_count(lag, "lag")
    Psi, Sigma_p, Phi = (np.asarray(a, dtype=float) for a in (Psi, Sigma_p, Phi))
    n = Psi.shape[-1]
    mu_p = np.zeros(n) if mu_p is None else np.asarray(mu_p, dtype=float)
    N = n * (lag + 1)
    Psi_a = np.zeros(Psi.shape[:-2] + (N, N))
    Psi_a[..., :n, :n] = Psi
    for j in range(lag):
        Psi_a[..., n * (j + 1) : n * (j + 2), n * j : n * (j + 1)] = np.eye(n)
    Sigma_pa = np.zeros(Sigma_p.shape[:-2] + (N, N))
    Sigma_pa[..., :n, :n] = Sigma_p
    Phi_a = np.zeros(Phi.shape[:-1] + (N,))
    Phi_a[..., :n] = Phi
    mu_pa = np.zeros(mu_p.shape[:-1] + (N,))
    mu_pa[..., :n] = mu_p
    return Psi_a, Sigma_pa, Phi_a, mu_pa


def fixed_lag_smoother(
    x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, lag: int, mu_p=None, mu_m=None
) -> MeanAndCov:
    """Textbook 19.2.6: the fixed-lag smoother, by running the filter on the augmented state.

    The prior of ``w_1`` fills every block (:func:`augment`); ``w_s`` is read
    off at time ``min(s + lag, T)``. ``lag = 0`` is the filter itself.

    Parameters
    ----------
    x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m
        As for :func:`run`.
    lag : int
        The delay ``tau >= 0``, in time steps.

    Returns
    -------
    MeanAndCov
        Means (..., T, n) and covariances (..., T, n, n): entry ``s`` is the
        state at time ``s + 1`` given the measurements up to time
        ``min(s + 1 + lag, T)``.
    """
    x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m = _sequence(
        x, prior_mean, prior_cov, Psi, Sigma_p, Phi, Sigma_m, mu_p, mu_m
    )
    T, n = x.shape[-2], prior_mean.shape[-1]
    lag = min(checks.nonnegative_count(lag, "lag"), T - 1)
    Psi_a, Sigma_pa, Phi_a, mu_pa = augment(Psi, Sigma_p, Phi, lag, mu_p)
    res = _run(
        x,
        np.tile(prior_mean, lag + 1),
        np.tile(prior_cov, (lag + 1, lag + 1)),
        Psi_a,
        Sigma_pa,
        Phi_a,
        Sigma_m,
        mu_pa,
        mu_m,
    )
    means, covs = [], []
    for s in range(T):
        t = min(s + lag, T - 1)  # read at time t, block t - s
        block = slice(n * (t - s), n * (t - s + 1))
        means.append(res.means[..., t, block])
        covs.append(res.covs[..., t, block, block])
    return MeanAndCov(np.stack(means, axis=-2), np.stack(covs, axis=-3))
