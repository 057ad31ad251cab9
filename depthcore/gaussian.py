"""A small immutable Gaussian type and the paper's prior, Eq. (13).

Recommended import: ``from depthcore.gaussian import Gaussian, paper_prior``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _checks

#: Index of each state component in ``(x, y, v)``.
INDEX = {"x": 0, "y": 1, "v": 2}

#: The paper's prior covariance scale: ``P = 1000 I``.
PAPER_PRIOR_SCALE = 1000.0


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
        mean = _checks.finite_array(self.mean, "mean", (3,)).copy()
        cov = _checks.covariance(self.cov, "cov", 3).copy()
        mean.setflags(write=False)
        cov.setflags(write=False)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

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
        x = np.asarray(x, dtype=float)
        chol = np.linalg.cholesky(self.cov)
        d = x - self.mean
        z = np.linalg.solve(chol, d.reshape(-1, 3).T).T.reshape(d.shape)
        logdet = 2.0 * np.sum(np.log(np.diag(chol)))
        return -0.5 * np.sum(z**2, axis=-1) - 0.5 * logdet - 1.5 * np.log(2.0 * np.pi)


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
    c = _checks.finite_array(c, "c", (3,))
    depth_offset = float(_checks.finite_array(depth_offset, "depth_offset"))
    scale = _checks.positive_scalar(scale, "scale")
    mean = np.array([c[0] - 2.0 * c[2], c[1] - 2.0 + depth_offset, 0.0])
    return Gaussian(mean, scale * np.eye(3))
