"""The numbers behind the print's errors: the printed means and SDs, Theorem 1, the pixels.

Recommended import: ``from depthbook.studies import verdicts``.

:func:`paper_numbers` computes, from :func:`depthcore.studies.reproduce.comparison`
and the filters, the numbers the book's conclusions, the README and the
replication article state beside the print: how many printed means and SDs the
formulas as derived reproduce, Theorem 1's agreement with either reading of
Eq. (8), Figure 3's mean from Eq. (16) as printed, the noise in pixels of
Figure 5, Figure 6's shifts. The verdicts on the paper's claims are decided in
:mod:`depthbook.studies.claims`.
"""

from __future__ import annotations

import numpy as np

from depthcore.kalman import ekf, second_order
from depthcore.problem import model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.scenarios import SCENARIOS
from depthcore.studies import reproduce

__all__ = ["THEOREM_TOL", "paper_numbers", "relative_misfit"]

#: The bound of Theorem 1's check. With the theorem's prior the second-order filter's
#: covariance ``D`` and the EKF's ``P_3`` differ by less than this relative to ``P_3``, in
#: the Frobenius norm (:func:`relative_misfit`); the rounding of the two formulas leaves
#: about 1e-14, a hundredth of it (book/appendix.md asserts the same bound).
THEOREM_TOL = 1e-12


def relative_misfit(d: np.ndarray, p3: np.ndarray) -> float:
    """``norm(D - P_3) / norm(P_3)``, Frobenius norms: Theorem 1's misfit, shapes (3, 3)."""
    return float(np.linalg.norm(d - p3) / np.linalg.norm(p3))


def _theorem_misfit(reading: str) -> tuple[float, float]:
    """Theorem 1 on Figures 2 and 3: ``D`` against the EKF's ``P_3``.

    Returns the largest :func:`relative_misfit` and the largest mean
    eigenvalue of ``D^-1 P_3`` (the factor by which ``D`` is too small).
    """
    misfit, factor = 0.0, 0.0
    for key in ("fig2", "fig3"):
        s = SCENARIOS[key]
        prior = Gaussian(model.G(s.c, -2), s.prior.cov)  # Theorem 1's prior mean, G^-2 c
        p3 = ekf.run(s.mu, s.rho, prior.mean, prior.cov).posterior.cov
        d = second_order.run(s.mu, s.rho, prior.mean, prior.cov, reading=reading).cov
        misfit = max(misfit, relative_misfit(d, p3))
        factor = max(factor, float(np.trace(np.linalg.solve(d, p3)).real / 3))
    return misfit, factor


def paper_numbers() -> dict:
    """The numbers behind the verdicts and the print's errors (plain floats and ints).

    Returns
    -------
    dict
        ``printed``, ``matched``: the printed depth means and SDs of the paper's
        three filters (Figures 2 and 3) and how many the formulas as derived
        reproduce at the paper's decimals; ``unmatched``: those not reproduced,
        as ``(key, row id, "mean" | "sd")``; ``rows``: each figure's rows of
        :func:`~depthcore.studies.reproduce.comparison` by id; ``theorem``:
        Theorem 1's relative misfit with ``2 rho^2 J^-1``; ``theorem_factor``:
        the factor by which the printed ``rho^2 J^-1`` falls short of the EKF's
        covariance; ``pixels``: Figure 5's noise in
        pixels; ``moments``: :func:`~depthcore.studies.reproduce.filter_moments`
        of each figure; ``prior_shift``, ``shift``: Figure 6's raise of the
        prior's depth and each filter's depth mean's move.
    """
    rows = {key: {r["id"]: r for r in reproduce.comparison(key)} for key in SCENARIOS}
    printed, unmatched = 0, []
    for key in SCENARIOS:
        for rid in ("opt", "so", "ekf"):
            row = rows[key][rid]
            if row["reported_mean"] is not None:
                printed += 2
                unmatched += [(key, rid, m) for m in ("mean", "sd") if not row[f"{m}_matches"]]
    moments = {key: reproduce.filter_moments(s) for key, s in SCENARIOS.items()}
    shift = {name: moments["fig6"][name][0] - moments["fig2"][name][0] for name in moments["fig2"]}
    return {
        "printed": printed,
        "matched": printed - len(unmatched),
        "unmatched": unmatched,
        "rows": rows,
        "theorem": _theorem_misfit("derived")[0],
        "theorem_factor": _theorem_misfit("printed")[1],
        "pixels": float(model.noise_in_pixels(SCENARIOS["fig5"].rho)),
        "moments": moments,
        "prior_shift": float(SCENARIOS["fig6"].prior.mean[1] - SCENARIOS["fig2"].prior.mean[1]),
        "shift": shift,
    }
