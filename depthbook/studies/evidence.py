"""The numbers the paper's claims rest on, computed from the filters.

Recommended import: ``from depthbook.studies import evidence``.

:func:`numbers` gathers, as plain floats, lists and dicts, what
:mod:`depthbook.studies.claims` decides its verdicts from: the paper's printed
means and SDs beside the values of the formulas as derived and of the print's
own formulas (:func:`depthcore.studies.reproduce.comparison`); the mean, SD and
peak of each figure's three marginals and the distance (:func:`total_variation`)
of the second-order and EKF marginals to the exact one; the exact depth
marginal's quantiles; the factor Eq. (16) drops; the noise in pixels; Figure 6's
shift of the prior; Theorem 1 and Eq. (19) with the prior mean ``G^-2 c``.
Nothing here decides a verdict.
"""

from __future__ import annotations

import numpy as np

from depthbook.studies import verdicts
from depthcore.exact import optimal
from depthcore.kalman import ekf, second_order
from depthcore.problem import model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.studies import reproduce

__all__ = ["FILTER_ROWS", "PAPER", "PRINT_FORMULAS", "QUANTILES", "numbers", "total_variation"]

#: The probabilities of the exact depth marginal's quantiles that the claims use.
QUANTILES = (0.01, 0.25, 0.5, 0.75, 0.99)
#: The paper's three filters by the row ids of ``reproduce.comparison``, with their symbols.
FILTER_ROWS = {"opt": ("optimal", "o"), "so": ("second_order", "s"), "ekf": ("ekf", "e")}
#: The print's own formulas that the derivation corrects, by filter row, each with the row
#: id of ``reproduce.comparison`` computed with it and the formula's name.
PRINT_FORMULAS = {
    "opt": ("opt_printed", "Eq. (16) as printed"),
    "so": ("so_printed", "Eq. (8)'s ρ²J⁻¹ as printed"),
}
#: The figures that print numbers, and whose measurements (17), (18) Theorem 1 is checked on.
PAPER = ("fig2", "fig3")


def total_variation(grid, p, q) -> float:
    """The total variation distance ``1/2 int |p - q|`` on ``grid``, as ``1 - int min(p, q)``.

    ``grid`` (n,) increasing, ``p`` and ``q`` (n,) normalised densities on it.
    """
    return 1.0 - _integral(grid, np.minimum(p, q))


def _integral(grid, p) -> float:
    """``int p`` on ``grid`` by the trapezoid rule."""
    return float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(grid)))


def _gaussian(x, mean: float, sd: float) -> np.ndarray:
    return np.exp(-0.5 * ((x - mean) / sd) ** 2) / (np.sqrt(2.0 * np.pi) * sd)


def _marginals(key: str) -> dict:
    """A figure's three marginals: mean, SD and peak of each, and the two distances to ``p_o``.

    The depth (Figures 2, 3, 5, 6) or velocity (Figure 4) marginal of the exact filter on a
    grid dense where each density lives (uniform in ``log(y - 2)`` for the depth), and the
    Gaussian marginals of the second-order filter and the EKF on the same grid.
    """
    s = SCENARIOS[key]
    moments = reproduce.filter_moments(s)
    exact = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
    mean, sd = moments["optimal"]
    parts = [np.linspace(m - 12 * v, m + 12 * v, 4001) for m, v in moments.values()]
    if s.quantity == "depth":
        t = np.linspace(np.log(1e-4), np.log(50.0 * (mean + 10.0 * sd)), 20001)
        grid = np.unique(np.concatenate([*parts, 2.0 + np.exp(t)]))
        grid = grid[grid > 2.0]
        p = exact.depth_pdf(grid)
    else:
        grid = np.unique(
            np.concatenate([*parts, np.linspace(mean - 15 * sd, mean + 15 * sd, 8001)])
        )
        p = exact.velocity_pdf(grid)
    mass = _integral(grid, p)
    if abs(mass - 1.0) > 1e-6:
        raise RuntimeError(f"the exact marginal of {key} integrates to {mass:.8f} on the grid")
    out = {"optimal": {"mean": mean, "sd": sd, "peak": float(p.max())}, "distance": {}}
    for name in ("second_order", "ekf"):
        m, v = moments[name]
        out[name] = {"mean": float(m), "sd": float(v), "peak": float(1 / (np.sqrt(2 * np.pi) * v))}
        out["distance"][name] = total_variation(grid, p, _gaussian(grid, m, v))
    out["optimal"] = {k: float(v) for k, v in out["optimal"].items()}
    return out


def _theorem(key: str) -> dict:
    """Theorem 1 and Eq. (19) with the prior mean ``G^-2 c`` (the paper's covariance).

    ``misfit``: ``norm(D - P_3) / norm(P_3)`` and the means' difference over ``max |c|``, ``D`` with
    ``2 rho^2 J^-1``; ``factor``: the mean eigenvalue of ``D^-1 P_3`` with the printed
    ``rho^2 J^-1``; ``means``: ``max |m_k - G^(k-3) c| / max |c|`` of the EKF, Eq. (19).
    """
    s = SCENARIOS[key]
    mean, cov, scale = model.G(s.c, -2), s.prior.cov, float(np.abs(s.c).max())
    history = ekf.run(s.mu, s.rho, mean, cov)
    p3 = history.covs[-1]
    derived = second_order.run(s.mu, s.rho, mean, cov, reading="derived")
    printed = second_order.run(s.mu, s.rho, mean, cov, reading="printed").cov
    expected = np.stack([model.G(s.c, k) for k in (-2, -1, 0)])
    return {
        "misfit": max(
            verdicts.relative_misfit(derived.cov, p3),
            float(np.abs(derived.mean - history.means[-1]).max()) / scale,
        ),
        "factor": float(np.trace(np.linalg.solve(printed, p3)) / 3.0),
        "means": float(np.abs(history.means - expected).max()) / scale,
    }


def _eq16_spread(key: str, quantiles) -> float:
    """The range of ``log`` of the factor Eq. (16) drops, over ``[q01, q99]`` of ``p_oy``."""
    s = SCENARIOS[key]
    y = np.linspace(quantiles[0], quantiles[-1], 201)
    logs = [optimal.conditional(y, s.mu, s.rho, s.prior, r)[0] for r in ("derived", "printed")]
    gap = logs[0] - logs[1]
    return float(gap.max() - gap.min())


def _pair(row: dict, a: str, b: str) -> list[float]:
    return [float(row[a]), float(row[b])]


def numbers() -> dict:
    """Every number the claims rest on, as plain floats, lists and dicts.

    Returns
    -------
    dict
        ``printed``, ``derived``: for ``"fig2"`` and ``"fig3"``, the printed and computed
        ``[mean, sd]`` of each filter by row id (``"opt"``, ``"so"``, ``"ekf"``);
        ``print_formula``: the same with the print's formulas (``"opt"``, ``"so"``);
        ``"c"``, ``"f_at_c"``: Eq. (7)'s ``c`` and ``f(c)`` of Eq. (5); ``marginals``: for
        each figure, ``{"optimal" | "second_order" | "ekf": {"mean", "sd", "peak"},
        "distance": {"second_order", "ekf"}}``, each filter's marginal of the figure's
        quantity (Figure 4: the velocity) and the :func:`total_variation` of the
        second-order and EKF marginals from the exact one; ``quantiles``: the exact
        depth marginal's at :data:`QUANTILES`; ``eq16_spread``: the range of the log of
        the factor Eq. (16) drops, over its q01 to q99; ``pixels``: the noise of Figures
        2 and 5 in pixels; ``prior_shift``: Figure 6's raise of the prior's depth;
        ``theorem``: with the prior mean ``G^-2 c``, ``misfit`` (``norm(D - P_3) / norm(P_3)``
        with ``2 rho^2 J^-1``, and the means' difference over ``max |c|``), ``factor``
        (the mean eigenvalue of ``D^-1 P_3`` with the printed ``rho^2 J^-1``) and
        ``means`` (``max |m_k - G^(k-3) c| / max |c|`` of the EKF, Eq. (19)).
    """
    rows = {key: {r["id"]: r for r in reproduce.comparison(key)} for key in PAPER}
    quantiles = {}
    for key in PAPER:
        s = SCENARIOS[key]
        exact = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov)
        quantiles[key] = optimal.depth_quantiles(exact, QUANTILES).tolist()
    return {
        "printed": {
            k: {rid: _pair(r[rid], "reported_mean", "reported_sd") for rid in FILTER_ROWS}
            for k, r in rows.items()
        },
        "derived": {
            k: {rid: _pair(r[rid], "mean", "sd") for rid in FILTER_ROWS} for k, r in rows.items()
        },
        "print_formula": {
            k: {rid: _pair(r[row], "mean", "sd") for rid, (row, _) in PRINT_FORMULAS.items()}
            for k, r in rows.items()
        },
        "c": {k: SCENARIOS[k].c.tolist() for k in PAPER},
        "f_at_c": {k: float(model.f(SCENARIOS[k].c, SCENARIOS[k].mu)) for k in PAPER},
        "marginals": {key: _marginals(key) for key in SCENARIOS},
        "quantiles": quantiles,
        "eq16_spread": {k: _eq16_spread(k, quantiles[k]) for k in PAPER},
        "pixels": {k: model.noise_in_pixels(SCENARIOS[k].rho) for k in ("fig2", "fig5")},
        "prior_shift": float(SCENARIOS["fig6"].prior.mean[1] - SCENARIOS["fig2"].prior.mean[1]),
        "theorem": {k: _theorem(k) for k in PAPER},
    }
