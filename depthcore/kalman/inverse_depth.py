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

**Uneven steps** (:mod:`depthcore.problem.frames`). Over a step ``s_k`` of the
depth, ``y_{k+1} = y_k + s_k``, ``x_{k+1} = x_k + s_k v_k`` and
``v_{k+1} = v_k + a`` with ``a ~ N(0, q**2 s_k)``. Dividing by ``y_1``:

    a_{k+1} = a_k + s_k * s_k',   w constant,   s'_{k+1} = s'_k + w a,

(``s'`` the scaled velocity, ``s_k`` the step), the noise on ``s'`` of variance
``w**2 q**2 s_k`` (:func:`predict` with ``step``); and with ``t_k`` the depth
travelled since frame 1 (``Frames.elapsed`` of :mod:`depthcore.problem.frames`,
``k - 1`` for unit steps), ``y_k = y_1 + t_k`` and the bearing is
``mu_k = a_k / (1 + t_k w)``. A missing bearing (``NaN``) is predicted through.

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
from depthcore.problem import checks, predictive, signature
from depthcore.problem.gaussian import (
    History,
    MeanAndCov,
    checked_track,
    run_recursion,
    symmetric,
)


class StateEstimate(MeanAndCov):
    """A filter's estimate of ``(x_K, y_K, v_K)`` at the last frame, and what each update saw.

    A :class:`~depthcore.problem.gaussian.MeanAndCov` (it unpacks as ``mean, cov
    = estimate``) with the per-frame reports of the run that led to it.

    Attributes
    ----------
    mean : ndarray, shape (..., 3)
    cov : ndarray, shape (..., 3, 3)
    updates : depthcore.problem.predictive.Updates or None
        Per frame (..., K): the bearing's log predictive density, tail
        probability and whether the gate skipped it.
    behind : ndarray of bool, shape (..., K), or None
        For the unscented filters, where a sigma point lay behind the camera
        (:class:`depthcore.kalman.ukf.UKFHistory`).
    """

    updates = None
    behind = None

    def __new__(cls, mean, cov, updates=None, behind=None):
        self = super().__new__(cls, mean, cov)
        if updates is not None:
            self.updates = updates
        if behind is not None:
            self.behind = behind
        return self

    @property
    def went_behind(self) -> np.ndarray:
        """Whether a sigma point lay behind the camera at any frame, shape (...)."""
        if self.behind is None:
            return np.zeros(np.shape(self.mean)[:-1], dtype=bool)
        return np.any(self.behind, axis=-1)


def travelled(k: int, elapsed=None):
    """``t``, the depth travelled since frame 1: ``elapsed``, or ``k - 1`` for unit steps."""
    return k - 1 if elapsed is None else np.asarray(elapsed, dtype=float)


def _jacobian(a, w, s) -> np.ndarray:
    """The Jacobian of ``(a, w, s) -> (a / w, 1 / w, s / w)`` at ``(a, w, s)``, shape (..., 3, 3).

    The map is its own inverse: it carries ``(x, y, v)`` to ``(a, w, s)`` and back.
    """
    J = np.zeros(np.shape(a) + (3, 3))
    J[..., 0, 0] = 1.0 / w
    J[..., 0, 1] = -a / w**2
    J[..., 1, 1] = -1.0 / w**2
    J[..., 2, 1] = -s / w**2
    J[..., 2, 2] = 1.0 / w
    return J


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
    J = _jacobian(x, y, v)
    return MeanAndCov(
        np.stack([x / y, 1.0 / y, v / y], axis=-1), symmetric(J @ P @ np.swapaxes(J, -1, -2))
    )


def predict(z, S, process_noise: float = 0.0, step=1.0) -> MeanAndCov:
    """A step of motion in inverse depth: ``a += step s``; ``s`` gains ``(w q)**2 |step|``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Mean of ``(a_k, w, s_k)``.
    S : array_like, shape (..., 3, 3)
    process_noise : float
        ``q >= 0``.
    step : float or array_like, shape (...)
        The depth's signed change, nonzero (module docstring); 1 is a frame of the paper.
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    h = np.asarray(step, dtype=float)
    # The transition is F = I + step E_13, as in Eq. (10) with the step.
    C = S.copy()
    C[..., 0, :] += h[..., None] * S[..., 2, :]
    C[..., :, 0] += h[..., None] * C[..., :, 2]
    C[..., 2, 2] += (z[..., 1] * process_noise) ** 2 * np.abs(h)
    zero = 0.0 * z[..., 2]
    return MeanAndCov(z + np.stack([h * z[..., 2], zero, zero], axis=-1), C)


def observation_vector(z, k: int, elapsed=None) -> np.ndarray:
    """Gradient of ``a / (1 + t w)`` at ``z = (a, w, s)``, shape (..., 3).

    Frames count from 1; ``t`` is ``elapsed`` (shape (...)), the depth
    travelled since frame 1, or ``k - 1`` (unit steps).
    """
    z = np.asarray(z, dtype=float)
    t = travelled(k, elapsed)
    D = 1.0 + t * z[..., 1]
    return np.stack([1.0 / D, -t * z[..., 0] / D**2, 0.0 * D], axis=-1)


def bearing_predictive(z, S, rho, k: int, elapsed=None) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's predictive density of the bearing of frame ``k``: ``N(a / D, h^T S h + rho**2)``.

    ``D = 1 + t w`` and ``h`` :func:`observation_vector` at the predicted mean
    ``z`` (the innovation's moments of :func:`update`, as Eq. (12)).

    Parameters
    ----------
    z : array_like, shape (..., 3)
    S : array_like, shape (..., 3, 3)
    rho : float or array_like, shape (...)
    k : int
    elapsed : float or array_like, shape (...), optional

    Returns
    -------
    mean, var : ndarray, shape (...)
    """
    z = np.asarray(z, dtype=float)
    h = observation_vector(z, k, elapsed)
    var = np.einsum("...i,...ij,...j->...", h, np.asarray(S, dtype=float), h)
    D = 1.0 + travelled(k, elapsed) * z[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):  # D <= 0 is refused by update
        return z[..., 0] / D, var + np.asarray(rho, dtype=float) ** 2


def update(z, S, mu, rho, k: int, elapsed=None) -> MeanAndCov:
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
    elapsed : float or array_like, shape (...), optional
        The depth travelled since frame 1 (default ``k - 1``).
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    D = 1.0 + travelled(k, elapsed) * z[..., 1]
    if not np.all(D > 0):
        raise ValueError(
            "prior_mean leads the inverse-depth EKF to a predicted depth <= 0 at frame "
            f"{k}; the projection is not defined there"
        )
    r2 = np.asarray(rho, dtype=float) ** 2
    h = observation_vector(z, k, elapsed)
    Sh = np.einsum("...ij,...j->...i", S, h)
    s = r2 + np.einsum("...i,...i->...", h, Sh)
    K = Sh / s[..., None]
    mean = z + (np.asarray(mu, dtype=float) - z[..., 0] / D)[..., None] * K
    return MeanAndCov(mean, linear.joseph(S, K[..., :, None], h[..., None, :], r2[..., None, None]))


def to_state(z, S, k: int, elapsed=None) -> MeanAndCov:
    """The Gaussian of ``(a_k, w, s_k)`` as one of ``(x_k, y_k, v_k)``, linearised at its mean.

    ``x_k = a_k / w``, ``y_k = 1 / w + t``, ``v_k = s_k / w``.

    Parameters
    ----------
    z : array_like, shape (..., 3)
        Mean; its inverse depth ``w`` must be positive.
    S : array_like, shape (..., 3, 3)
    k : int
        The frame, ``>= 1``.
    elapsed : float or array_like, shape (...), optional
        ``t``, the depth travelled since frame 1 (default ``k - 1``).
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    a, w, s = z[..., 0], z[..., 1], z[..., 2]
    if not np.all(w > 0):
        raise ValueError(
            "the inverse-depth EKF's mean inverse depth is not positive "
            f"(min {float(np.min(w)):.6g}): its depth estimate lies at or beyond infinity"
        )
    J = _jacobian(a, w, s)
    mean = np.stack(np.broadcast_arrays(a / w, 1.0 / w + travelled(k, elapsed), s / w), axis=-1)
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
    level = checks.probability(level, "level")
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
def run(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, steps=None, gate=None
) -> History:
    """The inverse-depth EKF over ``K`` bearings, batched, in its own coordinates.

    The prior carried over by :func:`prior`, then :func:`predict` over each
    step and :func:`update` at each bearing; a missing bearing (``NaN``) or one
    the gate skips leaves the prediction, row by row
    (:func:`depthcore.problem.gaussian.run_recursion`).

    {parameters}

    Returns
    -------
    History
        ``means`` (..., K, 3), the mean of ``(a_k, w, s_k)`` after frame ``k``;
        ``covs`` (..., K, 3, 3); ``updates`` (..., K), each bearing's
        predictive report (:func:`bearing_predictive`).

    See Also
    --------
    estimate : the last frame's estimate in ``(x, y, v)``.
    """
    return _run(mu, rho, prior_mean, prior_cov, process_noise, steps, gate)[0]


def _run(mu, rho, prior_mean, prior_cov, process_noise, steps, gate):
    """:func:`run` and the checked frames."""
    track = checked_track(mu, rho, prior_mean, prior_cov, steps, triples=False)
    q = checks.nonnegative_scalar(process_noise, "process_noise")
    g = predictive.gate(gate)
    f, regular = track.frames, track.frames.regular
    z, S = prior(track.mean, track.cov)

    def elapsed(k):
        return None if regular else f.elapsed[..., k - 1]

    def rho_at(k):
        return f.row_rho if regular else f.rho[..., k - 1]

    def predict_k(z, S, k):
        return predict(z, S, q) if regular else predict(z, S, q, f.steps[..., k - 2])

    history = run_recursion(
        z,
        S,
        f.mu,
        predict_k,
        lambda z, S, mu_k, k: update(z, S, mu_k, rho_at(k), k, elapsed(k)),
        f.present,
        lambda z, S, k: bearing_predictive(z, S, rho_at(k), k, elapsed(k)),
        g,
    )
    return history, f


def estimate(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, steps=None, gate=None
) -> StateEstimate:
    """The inverse-depth EKF's estimate of ``(x_K, y_K, v_K)`` at the last frame, batched.

    :func:`run`, then :func:`to_state` at frame ``K`` (at the depth travelled
    to it). Parameters as for :func:`run`.

    Returns
    -------
    StateEstimate
        Mean (..., 3), covariance (..., 3, 3) and the per-frame ``updates`` (..., K).
    """
    history, f = _run(mu, rho, prior_mean, prior_cov, process_noise, steps, gate)
    K = history.means.shape[-2]
    return last_state(history, K, None if f.regular else f.elapsed[..., -1])


def last_state(history: History, k: int, elapsed=None) -> StateEstimate:
    """The last frame of ``history`` carried to ``(x, y, v)`` by :func:`to_state` at frame ``k``.

    Parameters
    ----------
    history : History
        Means (..., K, 3) and covariances (..., K, 3, 3) in inverse-depth
        coordinates anchored at frame ``k`` (the modified-polar EKF's at the
        current frame, ``k = 1``), and their ``updates``.
    k : int
    elapsed : float or array_like, shape (...), optional
        The depth travelled from the anchor to the last frame (default ``k - 1``).

    Returns
    -------
    StateEstimate
        Refused, naming ``mu``, where the bearings left a depth that is not positive.
    """
    try:
        out = to_state(history.means[..., -1, :], history.covs[..., -1, :, :], k, elapsed)
    except ValueError as exc:
        raise ValueError(f"mu: {exc}") from None
    return StateEstimate(
        out.mean, out.cov, getattr(history, "updates", None), getattr(history, "behind", None)
    )
