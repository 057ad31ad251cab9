"""Summaries of the three filters, the paper's tables reproduced, and figure curves.

Recommended import: ``from depthcore import reproduce``.

Everything here is computed from :mod:`depthcore.optimal`,
:mod:`depthcore.second_order` and :mod:`depthcore.ekf`; :mod:`depthcore.figures`
only draws what :func:`curves` returns.
"""

from __future__ import annotations

import numpy as np

from . import optimal, particle, ukf
from .ekf import ekf
from .gaussian import Gaussian
from .scenarios import REPORTED, REPORTED_DECIMALS, SCENARIOS, Scenario
from .second_order import noise_free_state, second_order

#: The paper's three filters.
PAPER_FILTERS = ("optimal", "second_order", "ekf")
#: With the two filters of the textbook chapter: the UKF and a particle filter.
FILTERS = PAPER_FILTERS + ("ukf", "particle")
QUANTITIES = ("depth", "velocity")
#: Particles and seed of the particle filter wherever this module runs it.
PARTICLES = 20_000
PARTICLE_SEED = 1990
_COMPONENT = {"depth": "y", "velocity": "v"}


def gaussian_moments(g: Gaussian) -> dict:
    """Eq. (13): ``{"depth": {"mean", "sd"}, "velocity": {...}}`` of a Gaussian."""
    out = {}
    for q in QUANTITIES:
        mean, sd = g.marginal(_COMPONENT[q])
        out[q] = {"mean": mean, "sd": sd}
    return out


def optimal_moments(m: optimal.OptimalMarginals) -> dict:
    """Depth and velocity moments of the optimal filter with their error estimates."""
    return {
        "depth": {"mean": m.depth_mean, "sd": m.depth_sd, "error": m.depth_error},
        "velocity": {"mean": m.velocity_mean, "sd": m.velocity_sd, "error": m.velocity_error},
        "prob_behind_camera": m.prob_behind_camera,
    }


def ukf_posterior(mu, rho: float, prior: Gaussian) -> Gaussian:
    """The UKF's density at time 3, with the default sigma points.

    With the paper's broad prior some sigma points lie behind the camera at
    the first update; the filter is run all the same (``allow_behind_camera``),
    as the comparison is the point.
    """
    return ukf.ukf(mu, rho, prior, allow_behind_camera=True).posterior


def particle_result(mu, rho: float, prior: Gaussian, n: int = PARTICLES,
                    seed: int = PARTICLE_SEED) -> "particle.ParticleResult":
    """The particle filter with ``n`` particles and a fixed seed (repeatable)."""
    return particle.particle_filter(mu, rho, prior, n, np.random.default_rng(seed))


def particle_moments(r) -> dict:
    """Depth and velocity moments of a particle filter, with Monte Carlo standard errors."""
    m, se = r.moments(), r.standard_errors()
    return {
        "depth": {"mean": float(m.depth_mean), "sd": float(m.depth_sd),
                  "error": float(max(se.depth_mean, se.depth_sd))},
        "velocity": {"mean": float(m.velocity_mean), "sd": float(m.velocity_sd),
                     "error": float(max(se.velocity_mean, se.velocity_sd))},
    }


def summarize(mu, rho: float, prior: Gaussian) -> dict:
    """Moments of the depth and velocity marginals of all three filters.

    Parameters
    ----------
    mu : array_like, shape (3,)
    rho : float
    prior : Gaussian
        Density of the state at time 1.

    Returns
    -------
    dict
        ``{"mu", "rho", "prior_mean", "prior_cov", "c", "filters": {name: moments}}``
        with plain floats and lists, ready for JSON.
    """
    c = noise_free_state(mu)
    filters = {
        "optimal": optimal_moments(optimal.marginals(mu, rho, prior)),
        "second_order": gaussian_moments(second_order(mu, rho, prior)),
        "ekf": gaussian_moments(ekf(mu, rho, prior).posterior),
    }
    filters["optimal"]["prob_behind_camera_all_depths"] = optimal.marginals(
        mu, rho, prior, support="all").prob_behind_camera
    filters["ukf"] = gaussian_moments(ukf_posterior(mu, rho, prior))
    filters["particle"] = particle_moments(particle_result(mu, rho, prior))
    return {
        "mu": [float(v) for v in mu],
        "rho": float(rho),
        "prior_mean": prior.mean.tolist(),
        "prior_cov": prior.cov.tolist(),
        "c": c.tolist(),
        "filters": filters,
    }


def _rows(s: Scenario) -> list[dict]:
    """Every filter and reading for one scenario, as rows of the reproduction table."""
    prior = s.prior
    rows = []
    for reading in optimal.READINGS:
        for support in optimal.SUPPORTS:
            m = optimal_moments(optimal.marginals(s.mu, s.rho, prior, reading, support))
            for q in QUANTITIES:
                rows.append({"filter": "optimal", "reading": reading, "support": support,
                             "quantity": q, **m[q]})
    for reading in ("derived", "printed"):
        m = gaussian_moments(second_order(s.mu, s.rho, prior, reading))
        for q in QUANTITIES:
            rows.append({"filter": "second_order", "reading": reading, "support": "all",
                         "quantity": q, **m[q], "error": 0.0})
    m = gaussian_moments(ekf(s.mu, s.rho, prior).posterior)
    for q in QUANTITIES:
        rows.append({"filter": "ekf", "reading": "printed", "support": "all",
                     "quantity": q, **m[q], "error": 0.0})
    m = gaussian_moments(ukf_posterior(s.mu, s.rho, prior))
    for q in QUANTITIES:
        rows.append({"filter": "ukf", "reading": "-", "support": "all",
                     "quantity": q, **m[q], "error": 0.0})
    m = particle_moments(particle_result(s.mu, s.rho, prior))
    for q in QUANTITIES:
        rows.append({"filter": "particle", "reading": "-", "support": "front",
                     "quantity": q, **m[q]})
    for row in rows:
        reported = REPORTED.get(s.key, {}).get(row["filter"], {}).get(row["quantity"])
        row["reported_mean"], row["reported_sd"] = reported if reported else (None, None)
        row["mean_matches"] = None if reported is None else _agrees(row["mean"], reported[0])
        row["sd_matches"] = None if reported is None else _agrees(row["sd"], reported[1])
    return rows


def _agrees(value: float, printed: float) -> bool:
    """Whether ``value`` rounds to ``printed`` at the paper's precision."""
    return bool(abs(value - printed) <= 0.5 * 10.0 ** -REPORTED_DECIMALS + 1e-12)


def reproduce(keys=None) -> dict:
    """The paper's Figures 2-6: every filter's moments beside the reported numbers.

    For the optimal filter both readings of Eq. (16) (``"derived"``,
    ``"printed"``) and both supports (``"front"``, ``"all"``) are given; for the
    second-order filter both readings of Eq. (8). ``mean_matches`` and
    ``sd_matches`` say whether the row's numbers agree with the paper's at its
    printed precision (``None`` where the paper prints nothing).

    Returns
    -------
    dict
        ``{"scenarios": [{"key", "figure", "description", "mu", "rho",
        "prior_mean", "c", "rows": [...]}, ...]}``.
    """
    out = []
    for key in keys or SCENARIOS:
        s = SCENARIOS[key]
        out.append({
            "key": s.key, "figure": s.figure, "description": s.description,
            "mu": list(s.mu), "rho": s.rho, "prior_mean": s.prior.mean.tolist(),
            "c": s.c.tolist(), "rows": _rows(s),
        })
    return {"scenarios": out}


def curves(s: Scenario, grid, quantity: str | None = None, filters=PAPER_FILTERS) -> dict:
    """The marginal densities of the filters on ``grid``, for plotting.

    Parameters
    ----------
    s : Scenario
    grid : array_like, shape (n,)
        Depths or velocities.
    quantity : {"depth", "velocity"}, optional
        Defaults to the one the paper plots for ``s``.
    filters : sequence of str
        Names from :data:`FILTERS`; the particle filter's density is a
        weighted Gaussian kernel density estimate (Silverman's bandwidth).

    Returns
    -------
    dict
        ``{"grid": (n,), name: (n,) for each filter}``.
    """
    quantity = quantity or s.quantity
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    grid = np.asarray(grid, dtype=float)
    prior = s.prior
    unknown = set(filters) - set(FILTERS)
    if unknown:
        raise ValueError(f"filters must be among {FILTERS}, got {sorted(unknown)}")
    comp = _COMPONENT[quantity]
    density = {
        "optimal": lambda: (optimal.marginals(s.mu, s.rho, prior).depth_pdf(grid) if quantity == "depth"
                            else optimal.marginals(s.mu, s.rho, prior).velocity_pdf(grid)),
        "second_order": lambda: second_order(s.mu, s.rho, prior).marginal_pdf(comp, grid),
        "ekf": lambda: ekf(s.mu, s.rho, prior).posterior.marginal_pdf(comp, grid),
        "ukf": lambda: ukf_posterior(s.mu, s.rho, prior).marginal_pdf(comp, grid),
        "particle": lambda: particle_result(s.mu, s.rho, prior).density(comp, grid),
    }
    return {"grid": grid, **{name: density[name]() for name in filters}}


def format_table(result: dict) -> str:
    """A plain-text table of :func:`reproduce`'s result."""
    head = (f"{'fig':>3}  {'filter':<12} {'reading':<8} {'support':<7} {'quantity':<8} "
            f"{'mean':>10} {'sd':>10} {'error':>8}  {'paper mean':>10} {'paper sd':>9}  agrees")
    lines = [head, "-" * len(head)]
    for sc in result["scenarios"]:
        for r in sc["rows"]:
            rep_m = "" if r["reported_mean"] is None else f"{r['reported_mean']:.2f}"
            rep_s = "" if r["reported_sd"] is None else f"{r['reported_sd']:.2f}"
            match = "" if r["mean_matches"] is None else (
                f"mean {'yes' if r['mean_matches'] else 'no'}, sd {'yes' if r['sd_matches'] else 'no'}")
            lines.append(
                f"{sc['figure']:>3}  {r['filter']:<12} {r['reading']:<8} {r['support']:<7} "
                f"{r['quantity']:<8} {r['mean']:>10.4f} {r['sd']:>10.4f} {r['error']:>8.1e}  "
                f"{rep_m:>10} {rep_s:>9}  {match}")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def format_summary(summary: dict) -> str:
    """A plain-text rendering of :func:`summarize`'s result."""
    c = summary["c"]
    lines = [f"noise-free state c = ({c[0]:.6g}, {c[1]:.6g}, {c[2]:.6g})",
             f"{'filter':<13} {'depth mean':>11} {'depth sd':>10} {'vel. mean':>10} {'vel. sd':>10}"]
    for name in FILTERS:
        f = summary["filters"][name]
        lines.append(f"{name:<13} {f['depth']['mean']:>11.6g} {f['depth']['sd']:>10.4g} "
                     f"{f['velocity']['mean']:>10.6g} {f['velocity']['sd']:>10.4g}")
    o = summary["filters"]["optimal"]
    lines.append(f"optimal error estimates: depth {o['depth']['error']:.1e}, "
                 f"velocity {o['velocity']['error']:.1e}; probability behind the camera "
                 f"if depths y <= 2 are allowed: {o['prob_behind_camera_all_depths']:.3g}")
    return "\n".join(lines) + "\n"
