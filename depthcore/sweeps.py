"""Sweeps beyond the paper's five cases: the noise level and the prior's depth.

Recommended import: ``from depthcore import sweeps``.

* :func:`noise_sweep` tests the paper's conjecture that the second-order
  approximation beats the EKF "particularly when the noise level is low":
  for each noise level, the Hellinger distance from each filter's depth
  marginal to the optimal one, for one fixed truth and its noise-free
  measurements (deterministic). For Monte Carlo scores at each noise level,
  run :func:`depthcore.study.study` with that ``rho``.
* :func:`prior_offset_sweep` generalises Figure 6: the depth of the prior mean
  is moved by an offset and each filter's depth estimate is followed.
"""

from __future__ import annotations

import numpy as np

from . import model, study
from .filters import FILTERS
from .gaussian import PAPER_PRIOR_SCALE, paper_prior_means
from .scenarios import SCENARIOS


def _compare(mu, rho, pm, pc) -> dict:
    """Depth means, SDs and Hellinger distances to the optimal filter, for a batch.

    The optimal filter and every Gaussian filter of :data:`depthcore.filters.FILTERS`.
    """
    reference = FILTERS["optimal"](mu, rho, pm, pc)
    out = {"optimal": {"depth_mean": reference.depth_mean, "depth_sd": reference.depth_sd,
                       "hellinger": np.zeros(len(mu))}}
    for name, f in FILTERS.items():
        if f.family == "gaussian":
            est = f(mu, rho, pm, pc)
            out[name] = {"depth_mean": est.depth_mean, "depth_sd": est.depth_sd,
                         "hellinger": study.gaussian_hellinger(reference.detail, est.mean, est.cov)}
    return out


def noise_sweep(rhos, truth=None, prior_scale: float = PAPER_PRIOR_SCALE) -> dict:
    """Depth moments and Hellinger distances to the optimal filter against the noise level.

    For each ``rho`` the measurements are the noise-free ones of ``truth``
    (so the noise-free state is the truth), and the prior is the paper's.

    Parameters
    ----------
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    truth : array_like, shape (3,), optional
        State at time 3; default Figure 2's ``c``.

    Returns
    -------
    dict
        ``{"rho": (R,), name: {"depth_mean", "depth_sd", "hellinger"}}`` with
        arrays of shape (R,) for ``"optimal"``, ``"second_order"``, ``"ekf"``, ``"ukf"``.
    """
    truth = SCENARIOS["fig2"].c if truth is None else np.asarray(truth, dtype=float)
    rhos = np.atleast_1d(np.asarray(rhos, dtype=float))
    mu = np.tile([model.project(model.G(truth, k - 2)) for k in range(3)], (len(rhos), 1))
    pm = paper_prior_means(model.noise_free_states(mu))
    return {"rho": rhos, **_compare(mu, rhos, pm, prior_scale * np.eye(3))}


def prior_offset_sweep(offsets, mu=None, rho: float | None = None,
                       prior_scale: float = PAPER_PRIOR_SCALE) -> dict:
    """Each filter's depth estimate as the prior mean's depth moves (Figure 6 generalised).

    The prior mean is ``(c1 - 2 c3, c2 - 2 + offset, 0)``.

    Parameters
    ----------
    offsets : array_like, shape (R,)
        Depth offsets; ``c2 - 2 + offset`` must stay positive.
    mu : array_like, shape (3,), optional
        Default: Eq. (17).
    rho : float, optional
        Default: 1/200.

    Returns
    -------
    dict
        ``{"offset": (R,), name: {"depth_mean", "depth_sd", "hellinger"}}``.
    """
    mu = np.asarray(SCENARIOS["fig2"].mu if mu is None else mu, dtype=float)
    rho = SCENARIOS["fig2"].rho if rho is None else rho
    offsets = np.atleast_1d(np.asarray(offsets, dtype=float))
    c = model.noise_free_states(mu[None])[0]
    if np.any(c[1] - 2 + offsets <= 0):
        raise ValueError("offsets must keep the prior's depth at time 1, c2 - 2 + offset, positive")
    pm = paper_prior_means(c, offsets)
    mus = np.tile(mu, (len(offsets), 1))
    return {"offset": offsets, **_compare(mus, rho, pm, prior_scale * np.eye(3))}
