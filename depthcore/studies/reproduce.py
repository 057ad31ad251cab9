"""Summaries of every filter, the paper's tables reproduced, and figure curves.

Recommended import: ``from depthcore.studies import reproduce``.

Everything here iterates the default entries of the registry
:data:`depthcore.registry.filters.FILTERS` (:data:`~depthcore.registry.filters.NAMES`);
:func:`comparison` sets each filter's numbers beside the paper's for one
figure (:data:`TABLE_ROWS`). The book's :mod:`depthbook.paper` only draws
what :func:`curves` returns and shows what :func:`comparison` returns, and
:mod:`depthcore.cli.text` formats what :func:`reproduce` and :func:`summarize` return.

The particle filter is the one random filter: every call here that runs it
seeds a fresh ``numpy.random.Generator`` from the ``seed`` argument (default
:data:`PARTICLE_SEED`), so each result is repeatable on its own.
"""

from __future__ import annotations

import numpy as np

from depthcore.exact import posterior
from depthcore.kalman import iterated
from depthcore.problem import checks, depth_prior, frames
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import noise_free_state, noise_free_states_unchecked
from depthcore.problem.scenarios import REPORTED, REPORTED_DECIMALS, SCENARIOS, Scenario
from depthcore.registry.estimates import QUANTITIES, Estimate
from depthcore.registry.filters import FILTERS, NAMES, PAPER_FILTERS, PARTICLES, check_names

#: The default seed of the particle filter wherever this module runs it.
PARTICLE_SEED = 1990

__all__ = [
    "PARTICLE_SEED",
    "QUANTITY_LETTERS",
    "TABLE_ROWS",
    "comparison",
    "curves",
    "filter_moments",
    "iterated_smoother_moments",
    "reproduce",
    "scenario_rows",
    "summarize",
]


def _options(name: str, seed) -> dict:
    """The options a filter needs from this module: a fresh generator for a random one."""
    if FILTERS[name].random:
        return {"rng": np.random.default_rng(checks.seed_sequence(seed)), "n_particles": PARTICLES}
    return {}


def _run(name: str, mu, rho, prior: Gaussian, seed, **options) -> Estimate:
    law = depth_prior.options(name, prior)
    return FILTERS[name](mu, rho, prior.mean, prior.cov, **_options(name, seed), **law, **options)


def _moments(est: Estimate) -> dict:
    """``{"depth": {"mean", "sd"[, "error"]}, "velocity": {...}, **extras}`` with plain floats."""
    out = {q: {k: float(v) for k, v in est.moments(q).items()} for q in QUANTITIES}
    out.update({k: v if isinstance(v, bool) else float(v) for k, v in est.extras.items()})
    return out


def summarize(
    mu,
    rho: float,
    prior: Gaussian,
    seed=PARTICLE_SEED,
    process_noise: float = 0.0,
    smooth: bool = False,
    names=NAMES,
    steps=None,
    gate=None,
) -> dict:
    """Moments of the depth and velocity marginals of the named filters at the last frame.

    Parameters
    ----------
    mu : array_like, shape (N,)
        Bearings at frames 1 .. N, ``N >= 3`` (the paper's problem is ``N = 3``);
        ``NaN`` at a missing frame.
    rho : float or array_like, shape (N,)
        One noise SD, or one per frame.
    prior : Gaussian
        Density of the state at frame 1.
    seed : int or numpy.random.SeedSequence
        Seeds the particle filter's generator (default :data:`PARTICLE_SEED`).
    process_noise : float
        SD ``q >= 0`` of the velocity's change per frame (0: the paper's model).
    smooth : bool
        Also the optimal filter's smoothed depth and lateral position at every
        frame (:meth:`depthcore.exact.mixture.Mixture.smoothed`).
    names : sequence of str
        Filters of :data:`depthcore.registry.filters.FILTERS`, run in this order
        (default :data:`depthcore.registry.filters.NAMES`).
    steps : array_like, shape (N - 1,), optional
        The depth's change between frames (``None``: ones).
    gate : float or None
        The outlier gate (:mod:`depthcore.problem.predictive`); each filter with
        one reports the frames it skipped (``"gated"``, numbered from 1).

    Returns
    -------
    dict
        ``{"mu", "rho", "prior_mean", "prior_cov", "c", "frames", "process_noise",
        "filters": {name: moments}}`` with plain floats and lists, ready for
        JSON; ``c`` is the noise-free state of the first three bearings at frame
        3 (``None`` unless they are frames 1-3 at unit steps, in front of the
        camera). Filters that do not support the frames, the process noise, a
        missing bearing, a noise per frame, the steps or the gate are listed
        under ``"not_run"`` with the reason. With three frames and no
        process noise the optimal filter's moments carry ``prob_behind_camera``
        and ``prob_behind_camera_all_depths`` (with every real depth allowed).
        With ``smooth``, ``"smoothed"``: lists over the frames of the depth's
        and the lateral position's mean and SD.
    """
    mu = np.asarray(mu, dtype=float)
    q = float(process_noise)
    track = frames.check(mu, rho, steps)
    first_three = bool(np.all(track.present[:3]) and np.all(track.steps[:2] == 1.0))
    if track.regular and len(mu) == 3:
        c = noise_free_state(mu)
    elif first_three:  # noise may put the first three bearings' solution behind the camera
        c = noise_free_states_unchecked(mu[:3])
        c = c if np.all(np.isfinite(c)) and c[1] > 2 else None
    else:
        c = None
    track_options = {} if steps is None else {"steps": np.asarray(steps, dtype=float)}
    if gate is not None:
        track_options["gate"] = gate
    filters, not_run = {}, {}
    for name in check_names(names):
        f = FILTERS[name]
        if (len(mu) != 3 and not f.any_frames) or (q > 0 and not f.with_process_noise):
            not_run[name] = "supports only " + (
                "the paper's three frames"
                if len(mu) != 3 and not f.any_frames
                else "no process noise"
            )
            continue
        extra = {"process_noise": q} if q > 0 else {}
        try:
            est = _run(name, mu, rho, prior, seed, **extra, **track_options)
        except ValueError as exc:
            if track.regular and not track_options:
                raise
            not_run[name] = str(exc)  # a track this filter does not take: it says why
            continue
        filters[name] = _moments(est)
        if gate is not None:
            filters[name]["gated"] = [int(k) + 1 for k in np.flatnonzero(est.updates.gated)]
    paper_prior = not isinstance(prior, depth_prior.DepthPrior)  # Eq. (6) takes a Gaussian
    if (
        track.regular
        and len(mu) == 3
        and q == 0
        and "optimal" in filters
        and not gate
        and paper_prior
    ):
        filters["optimal"]["prob_behind_camera_all_depths"] = float(
            _run("optimal", mu, rho, prior, seed, support="all").extras["prob_behind_camera"]
        )
    out = {
        "mu": [None if np.isnan(v) else float(v) for v in mu],
        "rho": float(rho) if np.ndim(rho) == 0 else [float(r) for r in rho],
        "prior_mean": prior.mean.tolist(),
        "prior_cov": prior.cov.tolist(),
        **depth_prior.describe(prior),
        "c": None if c is None else c.tolist(),
        "frames": int(len(mu)),
        "process_noise": q,
        "filters": filters,
    }
    if steps is not None:
        out["steps"] = [float(v) for v in np.asarray(steps, dtype=float)]
    if not_run:
        out["not_run"] = not_run
    if smooth:
        kept = mu.copy()
        if gate is not None:  # the bearings the exact filter's gate skips are left out
            skipped = _run("optimal", mu, rho, prior, None, process_noise=q, **track_options)
            kept[skipped.updates.gated] = np.nan
        more = {} if steps is None else {"steps": track_options["steps"]}
        more |= {"law": prior} if not paper_prior else {}
        sm = posterior.posterior(
            kept, rho, prior.mean, prior.cov, q, history=True, **more
        ).smoothed()
        out["smoothed"] = {
            "depth_mean": sm.depth_mean.tolist(),
            "depth_sd": sm.depth_sd.tolist(),
            "lateral_mean": sm.lateral_mean.tolist(),
            "lateral_sd": sm.lateral_sd.tolist(),
        }
    return out


def scenario_rows(s: Scenario, names=NAMES, seed=PARTICLE_SEED) -> list[dict]:
    """Every variant of the named filters for one scenario, as rows of the reproduction table.

    Each row: ``filter``, ``reading``, ``support``, ``quantity``, ``mean``,
    ``sd``, ``error`` (0 for a closed form), ``reported_mean``,
    ``reported_sd`` (``None`` where the paper prints nothing), ``mean_matches``
    and ``sd_matches`` (agreement at the paper's printed precision, or ``None``).
    """
    prior = s.prior
    rows = []
    for name in check_names(names):
        for reading, support, options in FILTERS[name].variants:
            est = _run(name, s.mu, s.rho, prior, seed, **options)
            for q in QUANTITIES:
                m = est.moments(q)
                rows.append(
                    {
                        "filter": name,
                        "reading": reading,
                        "support": support,
                        "quantity": q,
                        "mean": float(m["mean"]),
                        "sd": float(m["sd"]),
                        "error": float(m.get("error", 0.0)),
                    }
                )
    for row in rows:
        reported = REPORTED.get(s.key, {}).get(row["filter"], {}).get(row["quantity"])
        row["reported_mean"], row["reported_sd"] = reported if reported else (None, None)
        row["mean_matches"] = None if reported is None else _agrees(row["mean"], reported[0])
        row["sd_matches"] = None if reported is None else _agrees(row["sd"], reported[1])
    return rows


def _agrees(value: float, printed: float) -> bool:
    """Whether ``value`` rounds to ``printed`` at the paper's precision."""
    return bool(abs(value - printed) <= 0.5 * 10.0**-REPORTED_DECIMALS + 1e-12)


def reproduce(keys=None, seed=PARTICLE_SEED, progress=None) -> dict:
    """The paper's Figures 2-6: every filter's moments beside the reported numbers.

    For the optimal filter both readings of Eq. (16) (``"derived"``,
    ``"printed"``) and both supports (``"front"``, ``"all"``) are given; for the
    second-order filter both readings of Eq. (8). ``mean_matches`` and
    ``sd_matches`` say whether the row's numbers agree with the paper's at its
    printed precision (``None`` where the paper prints nothing).

    Parameters
    ----------
    keys : sequence of str, optional
        Scenario keys; default all of :data:`depthcore.problem.scenarios.SCENARIOS`.
    seed : int or numpy.random.SeedSequence
        Seeds the particle filter's generator afresh for each scenario
        (default :data:`PARTICLE_SEED`).
    progress : callable, optional
        ``progress(done, total)``, called after each scenario.

    Returns
    -------
    dict
        ``{"scenarios": [{"key", "figure", "description", "mu", "rho",
        "prior_mean", "c", "rows": [...]}, ...]}``.
    """
    out = []
    keys = list(keys or SCENARIOS)
    for key in keys:
        s = SCENARIOS[key]
        out.append(
            {
                "key": s.key,
                "figure": s.figure,
                "description": s.description,
                "mu": list(s.mu),
                "rho": s.rho,
                "prior_mean": s.prior.mean.tolist(),
                "c": s.c.tolist(),
                "rows": scenario_rows(s, seed=seed),
            }
        )
        if progress is not None:
            progress(len(out), len(keys))
    return {"scenarios": out}


def curves(
    s: Scenario, grid, quantity: str | None = None, filters=PAPER_FILTERS, seed=PARTICLE_SEED
) -> dict:
    """The marginal densities of the filters on ``grid``, for plotting.

    Parameters
    ----------
    s : Scenario
    grid : array_like, shape (n,)
        Depths or velocities.
    quantity : {"depth", "velocity"}, optional
        Defaults to the one the paper plots for ``s``.
    filters : sequence of str
        Names from :data:`depthcore.registry.filters.FILTERS`; the particle filter's
        density is a weighted Gaussian kernel density estimate (Silverman's bandwidth).
    seed : int or numpy.random.SeedSequence
        Seeds the particle filter (default :data:`PARTICLE_SEED`).

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
    names = check_names(filters)
    return {
        "grid": grid,
        **{
            name: FILTERS[name].density(_run(name, s.mu, s.rho, prior, seed), quantity, grid)
            for name in names
        },
    }


def filter_moments(s: Scenario, quantity: str | None = None, names=PAPER_FILTERS) -> dict:
    """Mean and SD of each filter's marginal for a scenario (each filter's default reading).

    Parameters
    ----------
    s : Scenario
    quantity : {"depth", "velocity"}, optional
        Defaults to the one the paper plots for ``s``.
    names : sequence of str
        Filters without randomness; default the paper's three.

    Returns
    -------
    dict
        ``{name: (mean, sd)}``.
    """
    quantity = quantity or s.quantity
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be 'depth' or 'velocity', got {quantity!r}")
    prior = s.prior
    out = {}
    for name in check_names(names):
        m = FILTERS[name](s.mu, s.rho, prior.mean, prior.cov).moments(quantity)
        out[name] = (m["mean"], m["sd"])
    return out


#: Rows of the figure pages' tables, as (row id, filter, reading, support, label).
#: The optimal filter with Eq. (16) as derived and as printed; the second-order
#: filter with the covariance ``2 rho**2 J^{-1}`` of the expansion (8) and with
#: the printed ``rho**2 J^{-1}``; the EKF; the iterated EKF; the inverse-depth
#: EKF; and the iterated extended Kalman smoother's state at the last frame
#: (reading ``"smoother"``, :func:`iterated_smoother_moments`). A label's ``%s`` is the quantity's
#: letter, ``y`` or ``v``, as in the paper's marginals ``p_oy`` and ``p_ov``.
TABLE_ROWS = (
    ("opt", "optimal", "derived", "front", "optimal $p_{o%s}$"),
    ("opt_printed", "optimal", "printed", "front", "optimal, Eq. (16) as printed"),
    ("so", "second_order", "derived", "all", r"second order $p_{s%s}$, $2\rho^2 J^{-1}$"),
    ("so_printed", "second_order", "printed", "all", r"second order, $\rho^2 J^{-1}$ as printed"),
    ("ekf", "ekf", "printed", "all", "EKF $p_{e%s}$"),
    ("iter", "iterated", "-", "all", "iterated EKF"),
    ("inv", "inverse_depth", "-", "all", "inverse-depth EKF, delta method"),
    ("ismooth", "iterated", "smoother", "all", "iterated smoother at time 3 (MAP, Laplace SD)"),
)


def iterated_smoother_moments(s: Scenario) -> dict:
    """Depth and velocity of the iterated extended Kalman smoother at the scenario's last frame.

    :func:`depthcore.kalman.iterated.smoother` over all the scenario's bearings: its
    state at the last frame is the mode (MAP) of the trajectory's posterior,
    with the Gauss-Newton (Laplace) covariance there.

    Parameters
    ----------
    s : Scenario

    Returns
    -------
    dict
        ``{"depth": (mean, sd), "velocity": (mean, sd)}`` as plain floats.

    Raises
    ------
    ValueError
        If the Gauss-Newton passes do not converge.
    """
    r = iterated.smoother(s.mu, s.rho, s.prior.mean, s.prior.cov)
    if not bool(r.converged):
        raise ValueError(f"the iterated smoother does not converge for scenario {s.key!r}")
    index = {"depth": 1, "velocity": 2}
    return {q: (float(r.mean[i]), float(np.sqrt(r.cov[i, i]))) for q, i in index.items()}


def _smoother_rows(s: Scenario) -> list[dict]:
    """The iterated smoother's rows in the form of :func:`scenario_rows` (the paper has none)."""
    return [
        {
            "filter": "iterated",
            "reading": "smoother",
            "support": "all",
            "quantity": q,
            "mean": mean,
            "sd": sd,
            "error": 0.0,
            "reported_mean": None,
            "reported_sd": None,
            "mean_matches": None,
            "sd_matches": None,
        }
        for q, (mean, sd) in iterated_smoother_moments(s).items()
    ]


#: The letter of each quantity in the paper's names of the marginals.
QUANTITY_LETTERS = {"depth": "y", "velocity": "v"}


def comparison(key: str) -> list[dict]:
    """The rows of a figure page's table: the paper's numbers beside ours.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.

    Returns
    -------
    list of dict
        One per entry of :data:`TABLE_ROWS`, with ``id``, ``label``,
        ``quantity``, ``mean``, ``sd``, ``reported_mean``, ``reported_sd``
        (``None`` where the paper prints nothing), ``mean_matches`` and
        ``sd_matches`` (agreement at the paper's printed precision, or ``None``).
    """
    if key not in SCENARIOS:
        raise ValueError(f"key must be one of {tuple(SCENARIOS)}, got {key!r}")
    s = SCENARIOS[key]
    quantity = s.quantity
    rows = scenario_rows(s, names=tuple(dict.fromkeys(row[1] for row in TABLE_ROWS)))
    rows += _smoother_rows(s)
    out = []
    for row_id, filt, reading, support, label in TABLE_ROWS:
        (row,) = [
            r
            for r in rows
            if (r["filter"], r["reading"], r["support"], r["quantity"])
            == (filt, reading, support, quantity)
        ]
        out.append(
            {
                "id": row_id,
                "label": label % QUANTITY_LETTERS[quantity] if "%s" in label else label,
                "quantity": quantity,
                **{
                    k: row[k]
                    for k in (
                        "mean",
                        "sd",
                        "reported_mean",
                        "reported_sd",
                        "mean_matches",
                        "sd_matches",
                    )
                },
            }
        )
    return out
