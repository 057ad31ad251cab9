"""The inverse-depth EKF for a point in 3-D, seen as bearing pairs.

Recommended import: ``from depthcore.kalman import spatial_inverse``.

The plane's inverse-depth EKF (:mod:`depthcore.kalman.inverse_depth`) with the height
added. Anchor the state ``(x, y, v, h, w)`` (:mod:`depthcore.kalman.spatial`) at frame 1
and divide by its depth ``y_1``:

    z = (a, u, s, b, c) = (x / y_1, 1 / y_1, v / y_1, h / y_1, w / y_1),

so that with ``t_k`` the depth travelled since frame 1 the pair at frame ``k`` is

    (mu_k, nu_k) = (a_k, b_k) / (1 + t_k u) + noise,

exactly linear at frame 1. Over a step ``s`` of the depth ``a += s s'`` and ``b += s c``,
``u`` is constant, and the scaled velocities ``s'`` and ``c`` gain noise of variance
``u**2 q**2 abs(s)`` each, evaluated at the mean ``u`` (the plane's first-order treatment of
a noise term multiplied by the state): the prediction of textbook 19.2.1 with ``F`` the
identity plus ``s`` at ``(a, s')`` and ``(b, c)``. The update is the EKF's (textbook
19.2.2, Eqs. (11)-(12) for both coordinates), by the Jacobian rows
``(1 / D, -t a / D**2, 0, 0, 0)`` and ``(0, -t b / D**2, 0, 1 / D, 0)``, ``D = 1 + t u``.

**The prior** ``N(m, P)`` of ``(x_1, y_1, v, h_1, w)`` is carried to ``z`` by linearising
the map ``(x, y, v, h, w) -> (x / y, 1 / y, v / y, h / y, w / y)`` at ``m``, as the plane's
:func:`depthcore.kalman.inverse_depth.prior` does (the map's image of the Gaussian has no
moments); ``m_y > 0``.

**The report.** At every frame the filter's Gaussian on ``z`` is carried back to
``(x_k, y_k, v_k, h_k, w_k) = (a, 1, s', b, c) / u + (0, t_k, 0, 0, 0)`` by the same
linearisation at its mean, as :func:`depthcore.kalman.inverse_depth.to_state` does (the delta
method: ``E[1 / u]`` does not exist under a Gaussian on ``u``), which needs a positive mean
inverse depth. With the height's prior narrow at 0, no cross terms and ``nu = 0`` the
filter is the plane's (``tests/test_spatial_filters.py``).
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman.spatial import DIM, SpatialHistory, checked, gain_update, history, transition


def map_jacobian(z) -> np.ndarray:
    """The Jacobian of ``z -> (z_0, 1, z_2, z_3, z_4) / z_1`` at ``z`` (..., 5): (..., 5, 5).

    The map is its own inverse: it carries ``(x, y, v, h, w)`` to ``(a, u, s, b, c)`` and back.
    """
    u = z[..., 1]
    J = np.zeros(z.shape + (DIM,))
    for i in (0, 2, 3, 4):
        J[..., i, i] = 1.0 / u
        J[..., i, 1] = -z[..., i] / u**2
    J[..., 1, 1] = -1.0 / u**2
    return J


def _mapped(z, S):
    """The map of :func:`map_jacobian` at the mean ``z``, and ``J S J^T``."""
    J = map_jacobian(z)
    mean = z / z[..., 1:2]
    mean[..., 1] = 1.0 / z[..., 1]
    cov = J @ S @ np.swapaxes(J, -1, -2)
    return mean, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def prior(mean, cov):
    """The prior of ``(x_1, y_1, v, h_1, w)``, ``m`` (..., 5) and ``P`` (..., 5, 5), in ``z``.

    Mean ``(m_x, 1, m_v, m_h, m_w) / m_y`` and covariance ``J P J^T``, ``J`` the map's
    Jacobian at ``m`` (:func:`map_jacobian`).
    """
    m = np.asarray(mean, dtype=float)
    if not np.all(m[..., 1] > 0):
        raise ValueError(
            "prior_mean must have a positive depth to carry the prior to inverse depth, "
            f"got min {float(np.min(m[..., 1])):.6g}"
        )
    return _mapped(m, np.asarray(cov, dtype=float))


def predict(z, S, process_noise, step):
    """Textbook 19.2.1 in ``z``: ``a += step s'``, ``b += step c``, noise ``(u q)**2 abs(step)``.

    ``z`` (..., 5), ``S`` (..., 5, 5), ``step`` (...); returns the mean and covariance.
    """
    h = np.asarray(step, dtype=float)
    return transition(z, S, h, (z[..., 1] * process_noise) ** 2 * np.abs(h))


def update(z, S, pair, rho, elapsed):
    """The EKF's update (textbook 19.2.2) by the pair of the frame ``elapsed`` from frame 1.

    ``z`` (..., 5), ``S`` (..., 5, 5), ``pair`` (..., 2), ``rho`` and ``elapsed`` (...);
    returns the mean, the covariance, the pair's log predictive density and its tail
    probability (:func:`depthcore.kalman.spatial.gain_update`).
    """
    t = np.asarray(elapsed, dtype=float)
    D = 1.0 + t * z[..., 1]
    H = np.zeros(z.shape[:-1] + (2, DIM))
    H[..., 0, 0] = H[..., 1, 3] = 1.0 / D
    H[..., 0, 1] = -t * z[..., 0] / D**2
    H[..., 1, 1] = -t * z[..., 3] / D**2
    rho2 = np.asarray(rho, dtype=float)[..., None, None] ** 2
    R = H @ S @ np.swapaxes(H, -1, -2) + rho2 * np.eye(2)
    predicted = np.stack([z[..., 0], z[..., 3]], axis=-1) / D[..., None]
    return gain_update(z, S, pair, predicted, R, H @ S, H, rho2)


def run(mu, rho, prior_mean, prior_cov, process_noise=0.0, steps=None) -> SpatialHistory:
    """The inverse-depth EKF over tracks of pairs, batched, reported in ``(x, y, v, h, w)``.

    Parameters
    ----------
    mu : array_like, shape (N, 2) or (..., N, 2)
        Pairs ``(x / y, h / y)``; a row of ``NaN`` at a missing frame, predicted through.
    rho : float or array_like, shape (...) or (..., N)
    prior_mean : array_like, shape (5,) or (..., 5)
        The prior of ``(x_1, y_1, v, h_1, w)``; its depth must be positive.
    prior_cov : array_like, shape (5, 5) or (..., 5, 5)
    process_noise : float
        ``q >= 0`` on both velocities.
    steps : array_like, shape (N - 1,) or (..., N - 1), or None

    Returns
    -------
    SpatialHistory
        Each frame's Gaussian carried to ``(x_k, y_k, v_k, h_k, w_k)`` (module docstring),
        and each pair's log predictive density.

    Raises
    ------
    ValueError
        One line naming the argument; ``mu`` where the depth is not positive at a frame or
        the mean inverse depth is not positive.
    """
    pairs, m, P, q = checked(mu, rho, prior_mean, prior_cov, process_noise, steps)
    B, N = pairs.present.shape
    t = pairs.elapsed
    means, covs = np.empty((B, N, DIM)), np.empty((B, N, DIM, DIM))
    log_p = np.full((B, N), np.nan)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        z, S = prior(m, P)
        for k in range(N):
            if k:
                z, S = predict(z, S, q, pairs.steps[:, k - 1])
            here = pairs.present[:, k]
            if np.any(here & ~(1.0 + t[:, k] * z[:, 1] > 0)):
                raise ValueError(
                    "mu: the inverse-depth EKF's prediction puts the point at or behind the "
                    f"camera at frame {k + 1}"
                )
            if np.any(here):
                r = np.flatnonzero(here)
                z[r], S[r], log_p[r, k], _ = update(
                    z[r], S[r], pairs.mu[r, k], pairs.rho[r, k], t[r, k]
                )
            if not np.all(z[:, 1] > 0):
                raise ValueError(
                    "mu: the inverse-depth EKF's mean inverse depth is not positive at frame "
                    f"{k + 1} (min {float(np.min(z[:, 1])):.6g}): its depth lies beyond infinity"
                )
            means[:, k], covs[:, k] = _mapped(z, S)
            means[:, k, 1] += t[:, k]
    return history(pairs, means, covs, log_p, "inverse-depth EKF")
