"""The inverse-depth EKF: an EKF in coordinates where the bearings are nearly linear.

Recommended import: ``from depthcore.kalman import inverse_depth``.

Monocular SLAM replaced the EKF on Euclidean coordinates by an EKF on a
point's inverse depth [civera2008]_. On the paper's problem, anchor the
coordinates at the first frame and divide by its depth ``y_1``:

    a_k = x_k / y_1,    w = 1 / y_1,    s_k = v_k / y_1,

so that ``y_k = y_1 + k - 1`` gives the bearing at frame ``k``

    mu_k = x_k / y_k = a_k / (1 + (k - 1) w) + noise,

exactly linear at ``k = 1`` (``mu_1 = a_1``) and nearly linear for a distant
point (small ``w``) at every frame. The motion of Eq. (1) with lateral process
noise (``x_{k+1} = x_k + v_k``, ``v_{k+1} = v_k + a``, ``a ~ N(0, q**2)``)
becomes ``a_{k+1} = a_k + s_k``, ``w`` constant, ``s_{k+1} = s_k + w a``: linear
in the state, with process noise of variance ``w**2 q**2`` on ``s``, which the
filter evaluates at its mean ``w`` (the EKF's first-order treatment of a noise
term multiplied by the state). With no process noise (the paper's model)
``(a_1, w, s)`` is constant, ``s`` stays ``v / y_1`` and ``a_k = a_1 + (k - 1) s``.

**The prior.** The paper's prior is a Gaussian ``N(m, P)`` on ``(x_1, y_1, v)``.
Its image under ``(x, y, v) -> (x / y, 1 / y, v / y)`` has no moments (the
depth's density is positive at ``y = 0``), so, as an EKF carries a Gaussian
through any nonlinearity, the map is linearised at ``m``: mean
``(m_x / m_y, 1 / m_y, m_v / m_y)`` and covariance ``J P J^T`` with ``J`` the
map's Jacobian at ``m`` (:func:`prior`). This needs ``m_y > 0``.

**The estimate.** The filter's Gaussian on ``(a_K, w, s_K)`` is reported in the
paper's coordinates at the last frame, ``x_K = a_K / w``, ``y_K = 1 / w + K - 1``,
``v_K = s_K / w``, by the same linearisation at its mean (:func:`to_state`),
which needs a positive mean inverse depth. That is the delta method: the
depth's moments under the filter's Gaussian on ``w`` do not exist
(``E[1 / w]`` diverges, as the Gaussian's density is positive at ``w = 0``),
so the mean and SD it reports are those of the linearised map. What carries
over exactly are the Gaussian's quantiles: ``y = 1 / w + K - 1`` decreases
with ``w > 0``, so the median and a central interval of ``w`` map to a
median and an interval of the depth with the same probability
(:func:`depth_interval`).

References
----------
.. [civera2008] J. Civera, A. J. Davison and J. M. M. Montiel, "Inverse depth
   parametrization for monocular SLAM", IEEE Trans. Robotics 24(5), 2008.
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import linear
from depthcore.problem import checks, model, signature
from depthcore.problem.gaussian import History, MeanAndCov, run_recursion, symmetric


def prior(mean, cov) -> MeanAndCov:
    """The prior ``N(m, P)`` of ``(x_1, y_1, v)`` carried to ``(a_1, w, s_1)``.

    The prior is carried over by linearisation at ``m``.

    Parameters
    ----------
    mean : array_like, shape (..., 3)
        ``m``; its depth must be positive.
    cov : array_like, shape (..., 3, 3)

    Returns
    -------
    MeanAndCov
        Mean ``(m_x / m_y, 1 / m_y, m_v / m_y)`` and covariance ``J P J^T``.
    """
    m = np.asarray(mean, dtype=float)
    P = np.asarray(cov, dtype=float)
    if not np.all(m[..., 1] > 0):
        raise ValueError(
            "prior_mean must have a positive depth to carry the prior to inverse depth, "
            f"got min {float(np.min(m[..., 1])):.6g}"
        )
    x, y, v = m[..., 0], m[..., 1], m[..., 2]
    J = np.zeros(m.shape + (3,))
    J[..., 0, 0] = 1.0 / y
    J[..., 0, 1] = -x / y**2
    J[..., 1, 1] = -1.0 / y**2
    J[..., 2, 1] = -v / y**2
    J[..., 2, 2] = 1.0 / y
    return MeanAndCov(
        np.stack([x / y, 1.0 / y, v / y], axis=-1), symmetric(J @ P @ np.swapaxes(J, -1, -2))
    )


def predict(z, S, process_noise: float = 0.0) -> MeanAndCov:
    """One frame of motion in inverse-depth coordinates: ``a += s``; ``s`` gains ``w**2 q**2``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Mean of ``(a_k, w, s_k)``.
    S : array_like, shape (..., 3, 3)
    process_noise : float
        ``q >= 0``.
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    # The transition is F = I + E_13, as in Eq. (10).
    C = S.copy()
    C[..., 0, :] += S[..., 2, :]
    C[..., :, 0] += C[..., :, 2]
    C[..., 2, 2] += (z[..., 1] * process_noise) ** 2
    return MeanAndCov(z + np.stack([z[..., 2], 0.0 * z[..., 2], 0.0 * z[..., 2]], axis=-1), C)


def observation_vector(z, k: int) -> np.ndarray:
    """Gradient of ``a / (1 + (k - 1) w)`` at ``z = (a, w, s)``, shape (..., 3).

    Frames count from 1.
    """
    z = np.asarray(z, dtype=float)
    D = 1.0 + (k - 1) * z[..., 1]
    return np.stack([1.0 / D, -(k - 1) * z[..., 0] / D**2, 0.0 * D], axis=-1)


def update(z, S, mu, rho, k: int) -> MeanAndCov:
    """The EKF update (gain form, Joseph covariance, as Eq. (12)) by the bearing of frame ``k``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Predicted mean of ``(a_k, w, s_k)``; ``1 + (k - 1) w`` must be positive.
    S : array_like, shape (..., 3, 3)
    mu : array_like, shape (...)
    rho : float or array_like, shape (...)
    k : int
        The frame, ``>= 1``.
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    D = 1.0 + (k - 1) * z[..., 1]
    if not np.all(D > 0):
        raise ValueError(
            "prior_mean leads the inverse-depth EKF to a predicted depth <= 0 at frame "
            f"{k}; the projection is not defined there"
        )
    r2 = np.asarray(rho, dtype=float) ** 2
    h = observation_vector(z, k)
    Sh = np.einsum("...ij,...j->...i", S, h)
    s = r2 + np.einsum("...i,...i->...", h, Sh)
    K = Sh / s[..., None]
    mean = z + (np.asarray(mu, dtype=float) - z[..., 0] / D)[..., None] * K
    return MeanAndCov(mean, linear.joseph(S, K[..., :, None], h[..., None, :], r2[..., None, None]))


def to_state(z, S, k: int) -> MeanAndCov:
    """The Gaussian of ``(a_k, w, s_k)`` as one of ``(x_k, y_k, v_k)``, linearised at its mean.

    ``x_k = a_k / w``, ``y_k = 1 / w + k - 1``, ``v_k = s_k / w``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Mean; its inverse depth ``w`` must be positive.
    S : array_like, shape (..., 3, 3)
    k : int
        The frame, ``>= 1``.
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    a, w, s = z[..., 0], z[..., 1], z[..., 2]
    if not np.all(w > 0):
        raise ValueError(
            "the inverse-depth EKF's mean inverse depth is not positive "
            f"(min {float(np.min(w)):.6g}): its depth estimate lies at or beyond infinity"
        )
    J = np.zeros(z.shape + (3,))
    J[..., 0, 0] = 1.0 / w
    J[..., 0, 1] = -a / w**2
    J[..., 1, 1] = -1.0 / w**2
    J[..., 2, 1] = -s / w**2
    J[..., 2, 2] = 1.0 / w
    mean = np.stack([a / w, 1.0 / w + (k - 1), s / w], axis=-1)
    return MeanAndCov(mean, symmetric(J @ S @ np.swapaxes(J, -1, -2)))


def depth_interval(z, S, k: int, level: float = 0.68) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The depth's median and central interval under the filter's Gaussian on ``w``, exactly.

    The depth at frame ``k`` is ``y_k = 1 / w + k - 1``, decreasing in
    ``w > 0``: the Gaussian's median ``m_w`` and central interval
    ``[w_lo, w_hi]`` (probability ``level``) map to the median
    ``1 / m_w + k - 1`` and the interval ``[1 / w_hi + k - 1, 1 / w_lo + k - 1]``
    of the depth, with the same probabilities, the exact transformation of the
    filter's own distribution that :func:`to_state`'s delta method
    approximates. Where ``w_lo <= 0`` the interval reaches beyond infinity:
    its upper end is ``inf``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Mean of ``(a_k, w, s_k)``; its inverse depth must be positive.
    S : array_like, shape (..., 3, 3)
    k : int
        The frame, ``>= 1``.
    level : float
        In (0, 1).

    Returns
    -------
    median, low, high : ndarray, shape (...)
    """
    from scipy.special import ndtri

    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    level = float(level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    w, sd = z[..., 1], np.sqrt(S[..., 1, 1])
    if not np.all(w > 0):
        raise ValueError(
            "the inverse-depth EKF's mean inverse depth is not positive "
            f"(min {float(np.min(w)):.6g}): its depth's median lies at or beyond infinity"
        )
    half = ndtri(0.5 + level / 2.0) * sd
    low_w, high_w = w - half, w + half
    with np.errstate(divide="ignore"):
        high = np.where(low_w > 0, 1.0 / np.where(low_w > 0, low_w, 1.0) + (k - 1), np.inf)
    return 1.0 / w + (k - 1), 1.0 / high_w + (k - 1), high


@signature.documented
def run(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> History:
    """The inverse-depth EKF over ``K`` bearings, batched, in its own coordinates.

    {parameters}

    Returns
    -------
    means : ndarray, shape (..., K, 3)
        The mean of ``(a_k, w, s_k)`` after bearing ``k``.
    covs : ndarray, shape (..., K, 3, 3)

    See Also
    --------
    estimate : the last frame's estimate in ``(x, y, v)``.
    """
    mu, rho, m, P = model.batch_inputs(mu, rho, prior_mean, prior_cov, triples=False)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    z, S = prior(m, P)
    return run_recursion(
        z, S, mu, lambda z, S, k: predict(z, S, q), lambda z, S, mu_k, k: update(z, S, mu_k, rho, k)
    )


def estimate(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> MeanAndCov:
    """The inverse-depth EKF's estimate of ``(x_K, y_K, v_K)`` at the last frame, batched.

    :func:`run`, then :func:`to_state` at frame ``K``. Parameters as for :func:`run`.

    Returns
    -------
    MeanAndCov
        Mean (..., 3) and covariance (..., 3, 3).
    """
    history = run(mu, rho, prior_mean, prior_cov, process_noise)
    return last_state(history, history.means.shape[-2])


def last_state(history: History, k: int) -> MeanAndCov:
    """The last frame of ``history`` carried to ``(x, y, v)`` by :func:`to_state` at frame ``k``.

    Parameters
    ----------
    history : History
        Means (..., K, 3) and covariances (..., K, 3, 3) in inverse-depth
        coordinates anchored at frame ``k`` (the modified-polar EKF's at the
        current frame, ``k = 1``).
    k : int

    Returns
    -------
    MeanAndCov
        Refused, naming ``mu``, where the bearings left a depth that is not positive.
    """
    try:
        return to_state(history.means[..., -1, :], history.covs[..., -1, :, :], k)
    except ValueError as exc:
        raise ValueError(f"mu: {exc}") from None
