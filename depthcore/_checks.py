"""Input checks shared by the public functions.

Every check raises :class:`ValueError` whose message names the offending
argument and says what is wrong with it, so that bad input never turns into a
NaN or a silently wrong answer further down.
"""

from __future__ import annotations

import numpy as np

#: Triples whose second difference ``|mu1 + mu3 - 2 mu2|`` is at or below this
#: value are treated as degenerate: the three bearings are (numerically)
#: collinear in time and no finite depth explains them.
DEGENERACY_TOL = 1e-12


def finite_array(value, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a float array, checking shape and finiteness."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def positive_scalar(value, name: str) -> float:
    """Return ``value`` as a float, checking that it is finite and > 0."""
    arr = finite_array(value, name)
    if arr.ndim != 0:
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    if not arr > 0:
        raise ValueError(f"{name} must be positive, got {float(arr)}")
    return float(arr)


def positive_array(value, name: str) -> np.ndarray:
    """Return ``value`` as a float array (scalar or 1-D), checking every entry is finite and > 0."""
    arr = finite_array(value, name)
    if arr.ndim > 1:
        raise ValueError(f"{name} must be a scalar or 1-D, got shape {arr.shape}")
    if not np.all(arr > 0):
        raise ValueError(f"{name} must be positive, got {arr.tolist()}")
    return arr


def covariance(value, name: str, dim: int) -> np.ndarray:
    """Return ``value`` as a symmetric positive-definite ``(dim, dim)`` array."""
    arr = finite_array(value, name, (dim, dim))
    scale = max(np.max(np.abs(arr)), np.finfo(float).tiny)
    if np.max(np.abs(arr - arr.T)) > 1e-10 * scale:
        raise ValueError(f"{name} must be symmetric, got {arr.tolist()}")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ValueError(
            f"{name} must be positive definite; eigenvalues are "
            f"{np.linalg.eigvalsh(arr).tolist()}"
        ) from None
    return 0.5 * (arr + arr.T)


def measurements(mu, name: str = "mu") -> np.ndarray:
    """Check a triple ``(mu1, mu2, mu3)`` of image measurements.

    The triple must be finite, not degenerate (see :data:`DEGENERACY_TOL`), and
    its noise-free solution, Eq. (7), must lie in front of the camera at all
    three times: depth ``c2 - 2 > 0`` at the first frame.
    """
    arr = finite_array(mu, name, (3,))
    second_difference = arr[0] + arr[2] - 2.0 * arr[1]
    if abs(second_difference) <= DEGENERACY_TOL:
        raise ValueError(
            f"{name} is degenerate: mu1 + mu3 - 2*mu2 = {second_difference:.3g}, "
            "so no finite depth explains the three measurements"
        )
    depth_first = 2.0 * (arr[0] - arr[1]) / second_difference - 2.0
    if not depth_first > 0:
        raise ValueError(
            f"{name} puts the point behind the camera: its noise-free depth at the "
            f"first frame is c2 - 2 = {depth_first:.6g}, which is not positive"
        )
    return arr


def batch_inputs(mu, rho, prior_mean, prior_cov, measurements_axis: bool = True):
    """Check the inputs of a batched filter; return them as float arrays.

    Parameters
    ----------
    mu : array_like, shape (..., K)
        Measurements in time order; the leading shape ``(...)`` is the batch.
    rho : float or array_like, shape (...)
        Noise standard deviation, > 0.
    prior_mean : array_like, broadcastable to (..., 3)
    prior_cov : array_like, broadcastable to (..., 3, 3)
    measurements_axis : bool
        Whether ``mu`` has a last axis of measurements (else ``mu`` is one
        measurement per problem).

    Returns
    -------
    mu : ndarray, shape (..., K)
    rho : ndarray, shape () or (...)
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
        Read-only broadcast views of the priors.
    """
    mu = finite_array(mu, "mu")
    if measurements_axis and (mu.ndim < 1 or mu.shape[-1] < 1):
        raise ValueError(f"mu must have shape (..., n_measurements), got shape {mu.shape}")
    batch = mu.shape[:-1] if measurements_axis else mu.shape
    rho = positive_array(rho, "rho") if np.ndim(rho) <= 1 else finite_array(rho, "rho")
    if rho.ndim and rho.shape != batch:
        raise ValueError(f"rho must be a scalar or have shape {batch}, got shape {rho.shape}")
    if not np.all(rho > 0):
        raise ValueError(f"rho must be positive, got {rho.tolist()}")
    prior_mean = finite_array(prior_mean, "prior_mean")
    prior_cov = finite_array(prior_cov, "prior_cov")
    try:
        prior_mean = np.broadcast_to(prior_mean, batch + (3,))
    except ValueError:
        raise ValueError(
            f"prior_mean must have shape (3,) or {batch + (3,)}, got shape {prior_mean.shape}"
        ) from None
    try:
        prior_cov = np.broadcast_to(prior_cov, batch + (3, 3))
    except ValueError:
        raise ValueError(
            f"prior_cov must have shape (3, 3) or {batch + (3, 3)}, got shape {prior_cov.shape}"
        ) from None
    return mu, rho, prior_mean, prior_cov


def seed_sequence(seed, name: str = "seed") -> np.random.SeedSequence:
    """Return ``seed`` (an int >= 0 or a :class:`numpy.random.SeedSequence`) as a SeedSequence."""
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer or a numpy.random.SeedSequence, "
                         f"got {seed!r}")
    return np.random.SeedSequence(int(seed))


def generator(rng, name: str = "rng") -> np.random.Generator:
    """Return ``rng`` as a Generator: a Generator as is, a SeedSequence or int seeds a new one."""
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(seed_sequence(rng, name))


def spawn(seed, n: int) -> list[np.random.SeedSequence]:
    """The first ``n`` children of ``seed`` (int or SeedSequence), without spawning from it.

    ``SeedSequence.spawn`` counts the children it has given; this does not, so
    the same ``seed`` always gives the same children.
    """
    seed = seed_sequence(seed)
    return [np.random.SeedSequence(seed.entropy, spawn_key=seed.spawn_key + (i,),
                                   pool_size=seed.pool_size) for i in range(n)]


def count(value, name: str) -> int:
    """Return ``value`` as an int, checking that it is an integer >= 1."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)
