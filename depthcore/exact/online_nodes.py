"""What each depth node of the online exact filter holds: the plane's or the space's Gaussian.

Recommended import: ``from depthcore.exact import online_nodes``.

:class:`depthcore.exact.online.Online` keeps, per depth node, the Gaussian of the
lateral state given the depth as the rows of one array ``lat`` of shape (K, J), so
that a re-placement interpolates every row alike. Two layouts:

* :class:`Plane`, the paper's point (a prior on ``(x, y, v)``): the rows ``x, v, a, b,
  c, det`` (``(a, b, c)`` the entries of ``Cov[(x, v)]``, ``det`` its determinant,
  updated as :func:`depthcore.exact.bank.lateral_filter` does);
* :class:`Space`, a point in 3-D (a prior on ``(x, y, v, h, w)``,
  :mod:`depthcore.exact.spatial`): the rows ``x, v, h, w`` and the ten entries of the
  upper triangle of ``Cov[(x, v, h, w)]``.

Each gives the prior's rows at given depths at frame 1, the view the depth quadrature
places its nodes by (the ``(x, v)`` block), the prediction over a signed step (textbook
19.2.1), the update by the frame's observation with its log likelihood (19.2.2), the
observation's predictive density under the mixture of the nodes, and the state's
moments. A new kind of point goes here, as a class with the same methods.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from depthcore.exact import spatial
from depthcore.exact.bank import lateral_filter
from depthcore.exact.mixture import mixture_moments
from depthcore.problem import checks, pair_tail, predictive

_LOG_2PI = float(np.log(2.0 * np.pi))


class Plane:
    """The paper's point: ``(x, v)`` given the depth, one bearing per frame (module docstring)."""

    dim = 3
    rows = 6

    def __init__(self, prior_mean, prior_cov, rho: float, law=None):
        self.prior_mean, self.prior_cov, self.rho, self.law = prior_mean, prior_cov, rho, law

    def prior(self, y):
        """``log N(y; m_y, P_yy)`` (J,) (or the law's log density of the depth) and the rows
        (6, J) of ``(x_1, v_1)`` given ``y_1 = y``."""
        log_p, M, (a, b, c) = lateral_filter(
            y[None], np.empty((1, 0)), self.rho, 0.0, self.prior_mean, self.prior_cov, law=self.law
        )
        a, b, c = (np.broadcast_to(v, log_p.shape)[0] for v in (a, b, c))
        return log_p[0], np.stack([M[0, 0], M[1, 0], a, b, c, a * c - b * b])

    @staticmethod
    def view(lat):
        """``(x, v)`` means (2, J) and covariance entries ``(a, b, c)`` for the quadrature."""
        return lat[:2], (lat[2], lat[3], lat[4])

    @staticmethod
    def repair(lat) -> np.ndarray:
        """Rows made consistent after interpolation: the determinant from ``(a, b, c)``."""
        lat = lat.copy()
        lat[5] = lat[2] * lat[4] - lat[3] ** 2
        return lat

    @staticmethod
    def predict(lat, s: float, q2: float) -> None:
        """Textbook 19.2.1 over a step ``s``, in place; ``Var[x]`` without cancellation.

        As :func:`depthcore.exact.lateral.predict_step`: ``a + s (2 b + s c)`` when
        ``s b >= 0``, else ``(det + (b + s c)**2) / c``.
        """
        x, v, a, b, c, det = lat
        x += s * v
        shear_b = b + s * c
        with np.errstate(divide="ignore", invalid="ignore"):  # only where c > 0 is it used
            stable = (det + shear_b * shear_b) / c
        a[:] = np.where(s * b >= 0, a + s * (2.0 * b + s * c), stable)
        b[:] = shear_b
        if q2:
            c += q2
            det += q2 * a

    @staticmethod
    def update(lat, mu: float, y, rho2: float):
        """Textbook 19.2.2 by the bearing ``mu`` for every node, in place; the log likelihoods."""
        x, v, a, b, c, det = lat
        yy = y * y
        r = rho2 * yy
        total = a + r
        e = mu * y - x
        g = e / total
        log_likelihood = -0.5 * (_LOG_2PI + np.log(total / yy) + e * g)
        x += a * g
        v += b * g
        ratio = r / total
        a *= ratio
        b *= ratio
        det *= ratio
        lat[4] = (det + b * b) / a
        return log_likelihood

    @staticmethod
    def observed(lat, y, rho2: float):
        """Node ``j``'s bearing: mean ``x_j / y_j`` (J, 1), variance ``a_j / y_j**2 + rho**2``
        (J, 1, 1); its state ``(x, y, v)`` (J, 3) and ``Cov[state, bearing]`` (J, 3, 1)."""
        x, v, a, b = lat[:4]
        states = np.stack([x, y, v], -1)
        cross = np.stack([a / y, np.zeros_like(y), b / y], -1)[..., None]
        return (x / y)[:, None], (a / (y * y) + rho2)[:, None, None], states, cross

    @staticmethod
    def predictive(mu: float, log_w, lat, y, rho2: float, tail: bool = True):
        """The bearing's log predictive density and two-sided tail under the nodes (the
        tail always: it costs little)."""
        out = predictive.mixture(mu, log_w, lat[0] / y, lat[2] / (y * y) + rho2)
        return tuple(float(v) for v in out)

    @staticmethod
    def moments(p, lat, depths):
        """Mean (3,) and covariance (3, 3) of ``(x, y, v)`` under node probabilities ``p``."""
        means = np.stack([lat[0], lat[1]], -1)
        covs = np.stack([np.stack([lat[2], lat[3]], -1), np.stack([lat[3], lat[4]], -1)], -2)
        return mixture_moments(p, means, covs, depths)

    @staticmethod
    def observation(mu):
        """One bearing, or ``NaN`` for a frame without one."""
        arr = checks.as_float(mu, "mu")
        if arr.ndim != 0:
            raise ValueError(f"mu must be one bearing (a number), got shape {arr.shape}")
        if np.isinf(arr):
            raise ValueError(f"mu must be finite or NaN (a missing frame), got {float(arr)!r}")
        return float(arr)


#: The upper triangle of a 4 x 4 covariance, row by row: the rows 4 .. 13 of :class:`Space`.
_UPPER = np.triu_indices(4)


class Space:
    """A point in 3-D: ``(x, v, h, w)`` given the depth, a pair per frame (module docstring)."""

    dim = 5
    rows = 14

    def __init__(self, prior_mean, prior_cov, rho: float):
        self.prior_mean, self.prior_cov, self.rho = prior_mean[None], prior_cov[None], rho

    @staticmethod
    def pack(M, C) -> np.ndarray:
        """Rows (14, J) from means (J, 4) and covariances (J, 4, 4)."""
        return np.concatenate([M.T, C[:, _UPPER[0], _UPPER[1]].T])

    @staticmethod
    def unpack(lat):
        """Means (J, 4) and covariances (J, 4, 4) from the rows (14, J)."""
        M = lat[:4].T.copy()
        C = np.empty((lat.shape[1], 4, 4))
        C[:, _UPPER[0], _UPPER[1]] = lat[4:].T
        C[:, _UPPER[1], _UPPER[0]] = lat[4:].T
        return M, C

    def prior(self, y):
        """``log N(y; m_y, P_yy)`` (J,) and the rows (14, J) of ``u_1`` given ``y_1 = y``."""
        M, C, log_p = spatial.conditional_prior(y[None], self.prior_mean, self.prior_cov)
        C = np.broadcast_to(C, M.shape + (4,))
        return log_p[0], self.pack(M[0], C[0])

    @staticmethod
    def view(lat):
        """``(x, v)`` means (2, J) and covariance entries for the quadrature (rows 4, 5, 8)."""
        return lat[:2], (lat[4], lat[5], lat[8])

    @staticmethod
    def repair(lat) -> np.ndarray:
        """Rows after interpolation: kept as they are (each an entry of the Gaussian)."""
        return lat

    def predict(self, lat, s: float, q2: float) -> None:
        """Textbook 19.2.1 over a step ``s`` for every node, in place."""
        M, C = self.unpack(lat)
        M, C = spatial.predict_nodes(M, C, np.full(len(M), float(s)), q2 / abs(s) if q2 else None)
        lat[:] = self.pack(M, C)

    def update(self, lat, pair, y, rho2: float):
        """Textbook 19.2.2 by the pair, one coordinate after the other; the log likelihoods."""
        M, C = self.unpack(lat)
        total = 0.0
        for i, coordinate in zip(spatial.OBSERVED, (0, 1), strict=True):
            M, C, log_density = spatial.update_nodes(M, C, pair[coordinate], y, rho2, i)
            total = total + log_density
        lat[:] = self.pack(M, 0.5 * (C + np.swapaxes(C, -1, -2)))
        return total

    @staticmethod
    def observed(lat, y, rho2: float):
        """Node ``j``'s pair: mean ``(x_j, h_j) / y_j`` (J, 2), covariance
        ``C_j[[x, h]] / y_j**2 + rho**2 I`` (J, 2, 2); its state ``(x, y, v, h, w)``
        (J, 5) and ``Cov[state, pair]`` (J, 5, 2) (none with ``y``, known given the node)."""
        M, C = Space.unpack(lat)
        ij = list(spatial.OBSERVED)
        states = np.insert(M, 1, y, axis=1)
        cross = np.insert(C[:, :, ij] / y[:, None, None], 1, 0.0, axis=1)
        S = C[:, ij][:, :, ij] / (y * y)[:, None, None] + rho2 * np.eye(2)
        return M[:, ij] / y[:, None], S, states, cross

    def predictive(self, pair, log_w, lat, y, rho2: float, tail: bool = True):
        """The pair's log predictive density under the nodes (a mixture of bivariate
        Gaussians) and, with ``tail``, its tail, the probability of a pair of lower
        predictive density (:func:`depthcore.problem.pair_tail.tail`, to 1e-9 or 1e-6 of
        it; some hundred times the cost of the rest of a frame); else ``NaN``."""
        mean, S, _, _ = self.observed(lat, y, rho2)
        r = np.asarray(pair) - mean
        sol = np.linalg.solve(S, r[..., None])[..., 0]
        log_n = -0.5 * (2 * _LOG_2PI + np.linalg.slogdet(S)[1] + np.sum(r * sol, axis=-1))
        log_w = log_w - logsumexp(log_w)
        p_tail = pair_tail.tail(pair, log_w, mean, S).tail if tail else np.nan
        return float(logsumexp(log_w + log_n)), p_tail

    def moments(self, p, lat, depths):
        """Mean (5,) and covariance (5, 5) of ``(x, y, v, h, w)`` under node probabilities."""
        M, C = self.unpack(lat)
        states = np.zeros((len(p), 5))
        states[:, spatial.LATERAL] = M
        states[:, 1] = depths
        covs = np.zeros((len(p), 5, 5))
        covs[:, spatial.LATERAL[:, None], spatial.LATERAL[None, :]] = C
        mean = p @ states
        d = states - mean
        return mean, np.einsum("j,jkl->kl", p, covs + d[:, :, None] * d[:, None, :])

    @staticmethod
    def observation(mu):
        """A pair ``(mu, nu)``, or ``NaN`` for a frame without one."""
        arr = checks.as_float(mu, "mu")
        if arr.shape != (2,):
            raise ValueError(f"mu must be one pair (x / y, h / y), got shape {arr.shape}")
        if np.isnan(arr[0]) != np.isnan(arr[1]):
            raise ValueError("mu has one coordinate missing: a frame has both or neither")
        if np.any(np.isinf(arr)):
            raise ValueError(f"mu must be finite or NaN (a missing frame), got {arr.tolist()}")
        return np.nan if np.isnan(arr[0]) else arr
