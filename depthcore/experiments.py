"""Experiments beyond the paper: sweeps, the particle filter's convergence, the first update.

Recommended import: ``from depthcore import experiments``.

* :func:`noise_sweep` tests the paper's conjecture that the second-order
  approximation beats the EKF "particularly when the noise level is low":
  for each noise level, the Hellinger distance from each filter's depth
  marginal to the optimal one, for one fixed truth and its noise-free
  measurements (deterministic);
* :func:`prior_offset_sweep` generalises Figure 6: the depth of the prior mean
  is moved by an offset and each filter's depth estimate is followed;
* :func:`prior_velocity_sweep` moves the velocity of the prior mean instead,
  and :func:`prior_mean_map` maps the EKF's depth SD over the prior mean's
  depth and velocity, relative to the optimal filter's;
* :func:`ekf_linearisation` and :func:`bearings_depth_sd`: where the EKF
  linearises the three bearings, and the depth SD those linearised bearings allow;
* :func:`noise_study`: the Monte Carlo study (:func:`depthcore.study.study`)
  at several noise levels;
* :func:`truth_study`: the Monte Carlo study at several true states;
* :func:`particle_convergence`: the importance sampler's error against the
  number of particles, for several settings;
* :func:`resample_move_runs`: the causal particle filter with resample-move
  (:mod:`depthcore.resample_move`) run independently several times on a
  scenario, against the optimal filter;
* :func:`rbpf_convergence`: the Rao-Blackwellised particle filter's moments
  against the number of particles, from the exact bank of Kalman filters;
* :func:`first_update`: the EKF and the UKF after the first measurement;
* :func:`truncated_bearing_moments`: why the unscented transform of the
  paper's prior has nothing to match: the moments of ``x / y`` under a
  Gaussian with positive density at ``y = 0`` do not exist;
* :func:`frames_study`, :func:`frame_marginals` and :func:`conjecture_study`:
  the study and the depth marginals as the frames accumulate (``N`` from 3
  on, with or without process noise), :func:`coverage_test` the binomial test
  of a coverage, and the paper's conjecture over frames, noise levels and depths.

:mod:`depthcore.figures` draws and :mod:`depthcore.report` formats what these return.
"""

from __future__ import annotations

import numpy as np

from . import (
    _checks,
    bank_posterior,
    ekf,
    model,
    optimal,
    particle,
    rbpf,
    resample_move,
    study,
    study_scores,
    study_trials,
    ukf,
)
from .filters import FILTERS, NAMES, check_names
from .gaussian import PAPER_PRIOR_SCALE, Gaussian, MeanAndCov, paper_prior_means
from .scenarios import SCENARIOS, Scenario

#: Settings of the particle filter compared by :func:`particle_convergence`:
#: keyword arguments of :func:`depthcore.particle.run`.
SETTINGS = {
    "default": {},
    "resampling": {"ess_threshold": 0.5},
    "bootstrap": {"proposal": "prior"},
}
#: The moments whose errors :func:`particle_convergence` measures.
MOMENTS = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")
#: Particles per call of :func:`depthcore.particle.run` (bounds the memory, about 200 bytes each).
CHUNK_PARTICLES = 200_000


# --- sweeps --------------------------------------------------------------------------------


def _compare(mu, rho, pm, pc, names=NAMES) -> dict:
    """Depth means, SDs and Hellinger distances to the optimal filter, for a batch.

    The optimal filter and every Gaussian filter of ``names`` (default
    :data:`depthcore.filters.NAMES`).
    """
    reference = FILTERS["optimal"](mu, rho, pm, pc)
    out = {
        "optimal": {
            "depth_mean": reference.depth_mean,
            "depth_sd": reference.depth_sd,
            "hellinger": np.zeros(len(mu)),
        }
    }
    for name in check_names(names):
        f = FILTERS[name]
        if f.scoring.gaussian:
            est = f(mu, rho, pm, pc)
            out[name] = {
                "depth_mean": est.depth_mean,
                "depth_sd": est.depth_sd,
                "hellinger": study_trials.gaussian_hellinger(reference.detail, est.mean, est.cov),
            }
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


def prior_offset_sweep(
    offsets, mu=None, rho: float | None = None, prior_scale: float = PAPER_PRIOR_SCALE
) -> dict:
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


def _prior_means(mu, offsets, velocities):
    """Prior means ``(c1 - 2 c3, c2 - 2 + offset, velocity)``, shape (D, V, 3), and ``c``."""
    c = model.noise_free_states(mu[None])[0]
    if np.any(c[1] - 2 + offsets <= 0):
        raise ValueError("offsets must keep the prior's depth at time 1, c2 - 2 + offset, positive")
    pm = paper_prior_means(c, offsets[:, None] + np.zeros((1, len(velocities))))
    pm[..., 2] = velocities[None, :]
    return pm


def _problem(mu, rho):
    mu = np.asarray(SCENARIOS["fig2"].mu if mu is None else mu, dtype=float)
    return mu, SCENARIOS["fig2"].rho if rho is None else rho


def prior_velocity_sweep(
    velocities,
    mu=None,
    rho: float | None = None,
    depth_offset: float = 0.0,
    prior_scale: float = PAPER_PRIOR_SCALE,
    names=NAMES,
) -> dict:
    """Each filter's depth estimate as the prior mean's velocity moves.

    The prior mean is ``(c1 - 2 c3, c2 - 2 + depth_offset, velocity)``: the
    paper's rule, which sets the velocity to zero, with the velocity varied.
    Every filter, the optimal one included, is given the same prior.

    Parameters
    ----------
    velocities : array_like, shape (R,)
        Velocities of the prior mean.
    mu : array_like, shape (3,), optional
        Default: Eq. (17).
    rho : float, optional
        Default: 1/200.
    depth_offset : float
        Added to the prior mean's depth, as in :func:`prior_offset_sweep`.
    prior_scale : float
    names : sequence of str
        Filters of :data:`depthcore.filters.FILTERS`; the Gaussian ones among
        them run beside the optimal filter (default
        :data:`depthcore.filters.NAMES`).

    Returns
    -------
    dict
        ``{"velocity": (R,), name: {"depth_mean", "depth_sd", "hellinger"}}``.
    """
    mu, rho = _problem(mu, rho)
    velocities = np.atleast_1d(_checks.finite_array(velocities, "velocities"))
    offsets = np.atleast_1d(_checks.finite_array(depth_offset, "depth_offset"))
    pm = _prior_means(mu, offsets, velocities)[0]
    mus = np.tile(mu, (len(velocities), 1))
    return {"velocity": velocities, **_compare(mus, rho, pm, prior_scale * np.eye(3), names)}


def prior_mean_map(
    offsets, velocities, mu=None, rho: float | None = None, prior_scale: float = PAPER_PRIOR_SCALE
) -> dict:
    """The EKF's and the optimal filter's depth SDs over the prior mean's depth and velocity.

    The prior mean is ``(c1 - 2 c3, c2 - 2 + offset, velocity)`` on the grid
    of ``offsets`` by ``velocities``; each grid point gives both filters that prior.

    Parameters
    ----------
    offsets : array_like, shape (D,)
        Depth offsets, as in :func:`prior_offset_sweep`.
    velocities : array_like, shape (V,)
        Velocities of the prior mean.
    mu : array_like, shape (3,), optional
        Default: Eq. (17).
    rho : float, optional
        Default: 1/200.

    Returns
    -------
    dict
        ``"offset"`` (D,), ``"velocity"`` (V,), and arrays of shape (D, V):
        ``"ekf_depth_sd"``, ``"optimal_depth_sd"`` and ``"log10_sd_ratio"``,
        ``log10(EKF depth SD / optimal depth SD)``.
    """
    mu, rho = _problem(mu, rho)
    offsets = np.atleast_1d(_checks.finite_array(offsets, "offsets"))
    velocities = np.atleast_1d(_checks.finite_array(velocities, "velocities"))
    pm = _prior_means(mu, offsets, velocities).reshape(-1, 3)
    mus = np.tile(mu, (len(pm), 1))
    cov = prior_scale * np.eye(3)
    shape = (len(offsets), len(velocities))
    e = FILTERS["ekf"](mus, rho, pm, cov).depth_sd.reshape(shape)
    o = FILTERS["optimal"](mus, rho, pm, cov).depth_sd.reshape(shape)
    return {
        "offset": offsets,
        "velocity": velocities,
        "ekf_depth_sd": e,
        "optimal_depth_sd": o,
        "log10_sd_ratio": np.log10(e / o),
    }


# --- where the EKF linearises ------------------------------------------------------------------


def bearings_depth_sd(h, rho: float) -> float:
    """The depth SD at time 3 that three linearised bearings allow, without a prior.

    The EKF's inverse covariance at time 3 is Eq. (24) with its own observation
    vectors: ``R^T R / rho**2`` plus the prior's term, where the rows of ``R``
    are ``h_k^T F^{k-3}``, the gradients of the linearised bearings with
    respect to the state at time 3. Without the prior's term the covariance is
    ``rho**2 R^{-1} R^{-T}``; this returns the square root of its depth entry,
    which is ``rho`` times the norm of the depth row of ``R^{-1}``. It is
    infinite when ``R`` is singular: then the three bearings leave a direction
    of the state unresolved.

    Parameters
    ----------
    h : array_like, shape (3, 3)
        Observation vectors (Eq. (11)) of the bearings at times 1, 2, 3, one per row.
    rho : float
        Noise standard deviation, > 0.

    Returns
    -------
    float
    """
    h = _checks.finite_array(h, "h", (3, 3))
    rho = _checks.positive_scalar(rho, "rho")
    R = np.stack([h[k] @ model.G_linear(k - 2) for k in range(3)])
    if np.linalg.matrix_rank(R) < 3:
        return float("inf")
    return float(rho * np.linalg.norm(np.linalg.solve(R.T, np.eye(3)[1])))


def ekf_linearisation(mu, rho: float, prior: Gaussian) -> dict:
    """Where the EKF linearises the bearings (Eq. (11)), and what follows for the depth.

    Parameters
    ----------
    mu : array_like, shape (3,)
    rho : float
    prior : Gaussian
        Density of the state at time 1.

    Returns
    -------
    dict
        ``"h"`` (3, 3): the observation vectors of Eq. (11) at the EKF's
        predicted means ``n`` before each measurement (the prior mean, then
        Eq. (10)), one per row; ``"rows"`` (3, 3): ``h_k^T F^{k-3}``, their
        gradients with respect to the state at time 3 (the vectors of
        Eq. (24)); ``"det"``: the determinant of ``rows``; ``"depth_sd"``
        (3,): the EKF's depth SD after each measurement; ``"bearings_depth_sd"``:
        :func:`bearings_depth_sd` of ``h``.
    """
    if not isinstance(prior, Gaussian):
        raise ValueError(f"prior must be a Gaussian, got {type(prior).__name__}")
    history = ekf.ekf(mu, rho, prior)
    predicted = [prior.mean] + [ekf.predict(history.means[i], history.covs[i])[0] for i in (0, 1)]
    h = model.observation_vector(np.stack(predicted))
    rows = np.stack([h[k] @ model.G_linear(k - 2) for k in range(3)])
    return {
        "h": h,
        "rows": rows,
        "det": float(np.linalg.det(rows)),
        "depth_sd": np.sqrt(history.covs[:, 1, 1]),
        "bearings_depth_sd": bearings_depth_sd(h, rho),
    }


# --- the Monte Carlo study at several noise levels --------------------------------------------

#: Depth scores of :func:`noise_study`, from :func:`depthcore.study_scores.scores`.
NOISE_STUDY_SCORES = ("bias", "rmse", "mean_sd", "coverage_68", "coverage_95")


def gather_scores(filter_results, scores) -> dict:
    """One filter's depth scores over several studies, each with its standard error.

    Parameters
    ----------
    filter_results : sequence of dict, length S
        The filter's entry of :func:`depthcore.study.study`'s ``"filters"``,
        one per study.
    scores : sequence of str
        Depth scores of :func:`depthcore.study_scores.scores`.

    Returns
    -------
    dict
        ``{score: (S,), score + "_se": (S,)}`` for each score, and ``"nees"``,
        ``"nees_se"`` (S,).
    """
    out = {}
    for score in scores:
        out[score] = np.array([x["depth"][score] for x in filter_results])
        out[f"{score}_se"] = np.array([x["depth"][f"{score}_se"] for x in filter_results])
    out["nees"] = np.array([x["nees"] for x in filter_results])
    out["nees_se"] = np.array([x["nees_se"] for x in filter_results])
    return out


def noise_study(
    rhos, trials: int, seed, names=("optimal", "second_order", "ekf", "ukf"), prior: str = "paper"
) -> dict:
    """:func:`depthcore.study.study` at each noise level, its depth scores gathered.

    Parameters
    ----------
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    trials : int
        Trials per noise level (the same seed at every level).
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters, from :data:`depthcore.filters.FILTERS`.
    prior : {"paper", "fixed"}

    Returns
    -------
    dict
        ``"rho"`` (R,), ``"valid_trials"`` (R,) and, per filter,
        ``{score: (R,)}`` for :data:`NOISE_STUDY_SCORES` (of the depth) and
        ``"nees"``, each with its standard error (:func:`gather_scores`), and
        ``"hellinger"`` (the mean Hellinger distance of the depth marginal; NaN
        unless ``"optimal"``, the reference, is among ``names``).
    """
    rhos = np.atleast_1d(_checks.positive_array(rhos, "rhos"))
    runs = [
        study.study(rho=float(r), trials=trials, seed=seed, prior=prior, names=tuple(names))
        for r in rhos
    ]
    out = {"rho": rhos, "valid_trials": np.array([r["valid_trials"] for r in runs])}
    for name in names:
        f = [r["filters"][name] for r in runs]
        out[name] = gather_scores(f, NOISE_STUDY_SCORES)
        out[name]["hellinger"] = np.array(
            [np.nan if x["hellinger_depth"] is None else x["hellinger_depth"]["mean"] for x in f]
        )
    return out


def truth_study(
    truths, rho: float, trials: int, seed, names=("optimal", "second_order", "ekf")
) -> dict:
    """:func:`depthcore.study.study` at each of several true states, with the paper's prior rule.

    Parameters
    ----------
    truths : array_like, shape (T, 3)
        True states ``(x, y, v)`` at time 3.
    rho : float
        Noise standard deviation, > 0.
    trials : int
        Trials per truth (the same seed for every truth).
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters, from :data:`depthcore.filters.FILTERS`.

    Returns
    -------
    dict
        ``"truth"`` (T, 3), ``"valid_trials"`` (T,) and, per filter,
        ``{score: (T,)}`` for :data:`NOISE_STUDY_SCORES` (of the depth) and ``"nees"``,
        each with its standard error (:func:`gather_scores`).
    """
    truths = _checks.finite_array(truths, "truths")
    if truths.ndim != 2 or truths.shape[1] != 3 or truths.shape[0] < 1:
        raise ValueError(f"truths must have shape (T, 3) with T >= 1, got shape {truths.shape}")
    rho = _checks.positive_scalar(rho, "rho")
    runs = [
        study.study(t, rho=rho, trials=trials, seed=seed, prior="paper", names=tuple(names))
        for t in truths
    ]
    out = {"truth": truths, "valid_trials": np.array([r["valid_trials"] for r in runs])}
    for name in names:
        out[name] = gather_scores([r["filters"][name] for r in runs], NOISE_STUDY_SCORES)
    return out


# --- convergence of the particle filter ------------------------------------------------------


def _sizes(sizes) -> np.ndarray:
    sizes = np.atleast_1d(np.asarray(sizes))
    if (
        sizes.ndim != 1
        or sizes.size < 1
        or not np.issubdtype(sizes.dtype, np.integer)
        or np.any(sizes < 1)
    ):
        raise ValueError(f"sizes must be positive integers, got {sizes!r}")
    return sizes.astype(int)


def _run_repeats(scenario: Scenario, n: int, repeats: int, rng, kwargs: dict):
    """Moments (repeats,) per field and the ESS after each measurement (repeats, 3)."""
    s, prior = scenario, scenario.prior
    per_call = max(1, CHUNK_PARTICLES // n)
    moments, ess = [], []
    for start in range(0, repeats, per_call):
        b = min(per_call, repeats - start)
        batch = particle.run(np.tile(s.mu, (b, 1)), s.rho, prior.mean, prior.cov, n, rng, **kwargs)
        moments.append(np.stack(batch.moments(), axis=-1))
        ess.append(batch.ess)
    return np.concatenate(moments), np.concatenate(ess)


def particle_convergence(
    scenario: Scenario, sizes, repeats: int, seed, settings: dict | None = None
) -> dict:
    """Root-mean-square errors of the particle filter's moments against ``N``.

    Each setting runs ``repeats`` independent filters on the scenario's
    measurements for each number of particles; the errors are measured from
    the optimal filter's exact moments (:func:`depthcore.optimal.marginals`).

    Parameters
    ----------
    scenario : Scenario
    sizes : array_like of int, shape (S,)
        Numbers of particles ``N``.
    repeats : int
        Independent runs per ``N``, >= 1.
    seed : int or numpy.random.SeedSequence
        Each setting draws from its own child stream of this seed.
    settings : dict, optional
        ``{name: keyword arguments of particle.run}``; default :data:`SETTINGS`.

    Returns
    -------
    dict
        ``"sizes"`` (S,), ``"repeats"``, ``"exact"``: ``{moment: float}`` for
        :data:`MOMENTS`, ``"rmse"``: ``{setting: {moment: (S,)}}`` and
        ``"ess"``: ``{setting: (S, 3)}``, the mean ESS after each measurement
        as a fraction of ``N``.
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    sizes = _sizes(sizes)
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise ValueError(f"repeats must be a positive integer, got {repeats!r}")
    settings = SETTINGS if settings is None else settings
    opt = optimal.marginals(scenario.mu, scenario.rho, scenario.prior)
    exact = np.array([getattr(opt, m) for m in MOMENTS])
    streams = _checks.spawn(seed, len(settings))
    rmse, ess = {}, {}
    for (name, kwargs), stream in zip(settings.items(), streams, strict=True):
        rng = np.random.default_rng(stream)
        err, frac = [], []
        for n in sizes:
            m, e = _run_repeats(scenario, int(n), int(repeats), rng, kwargs)
            err.append(np.sqrt(np.mean((m - exact) ** 2, axis=0)))
            frac.append(np.mean(e, axis=0) / n)
        err = np.array(err)
        rmse[name] = {m: err[:, i] for i, m in enumerate(MOMENTS)}
        ess[name] = np.array(frac)
    return {
        "sizes": sizes,
        "repeats": int(repeats),
        "exact": {m: float(v) for m, v in zip(MOMENTS, exact, strict=True)},
        "rmse": rmse,
        "ess": ess,
    }


# --- the causal particle filter (resample-move) ----------------------------------------------


def resample_move_runs(
    scenario: Scenario, n_particles: int, repeats: int, seed, moves: int = 20
) -> dict:
    """Independent runs of the resample-move particle filter on a scenario.

    The filter of :func:`depthcore.resample_move.run` sees the bearings one at
    a time (bootstrap proposal from the prior, systematic resampling when the
    ESS falls below ``N/2``, then ``moves`` Metropolis steps per particle).
    The ``repeats`` runs draw from independent child streams of ``seed``;
    their spread gives the Monte Carlo standard error of the moments.

    Parameters
    ----------
    scenario : Scenario
    n_particles : int
        Particles per run, >= 2.
    repeats : int
        Independent runs, >= 2.
    seed : int or numpy.random.SeedSequence
    moves : int
        Metropolis steps per particle after each resampling.

    Returns
    -------
    dict
        ``"runs"``: ``{moment: (repeats,)}`` for :data:`MOMENTS`; ``"mean"`` and
        ``"se"``: ``{moment: float}``, the mean over the runs and its standard
        error (SD over the runs / sqrt(repeats)); ``"exact"``: ``{moment:
        float}`` of the optimal filter (:func:`depthcore.optimal.marginals`,
        in front of the camera); ``"ess"`` (repeats, 3): the ESS after each
        bearing as a fraction of ``N``; ``"resampled"`` (repeats, 3).
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 2:
        raise ValueError(f"repeats must be an integer >= 2, got {repeats!r}")
    s, prior = scenario, scenario.prior
    batches = [
        resample_move.resample_move(
            s.mu, s.rho, prior, n_particles, np.random.default_rng(stream), moves
        )
        for stream in _checks.spawn(seed, int(repeats))
    ]
    runs = {k: np.concatenate([b.moments()[k] for b in batches]) for k in MOMENTS}
    opt = optimal.marginals(s.mu, s.rho, prior)
    return {
        "runs": runs,
        "mean": {k: float(np.mean(v)) for k, v in runs.items()},
        "se": {k: float(np.std(v, ddof=1) / np.sqrt(len(v))) for k, v in runs.items()},
        "exact": {k: float(getattr(opt, k)) for k in MOMENTS},
        "ess": np.concatenate([b.ess for b in batches]) / n_particles,
        "resampled": np.concatenate([b.resampled for b in batches]),
    }


# --- the Rao-Blackwellised particle filter against the exact bank ----------------------------


def rbpf_convergence(
    mu,
    rho,
    prior_mean,
    prior_cov,
    sizes,
    replicas: int,
    seed,
    process_noise=0.0,
    moves: int = rbpf.DEFAULT_MOVES,
) -> dict:
    """The Rao-Blackwellised particle filter's moments at the last frame against ``J``.

    For each number of particles ``J`` the filter (:func:`depthcore.rbpf.run`)
    runs ``replicas`` independent clouds over the bearings, from its own child
    stream of ``seed``; each cloud's moments at frame ``N`` are compared with
    the exact posterior of the bank of Kalman filters (:func:`depthcore.bank_posterior.posterior`).

    Parameters
    ----------
    mu : array_like, shape (N,)
        The bearings of one track.
    rho, prior_mean, prior_cov, process_noise
        As for :func:`depthcore.bank_posterior.posterior`.
    sizes : array_like of int, shape (S,)
        Particles per cloud, each >= 2.
    replicas : int
        Independent clouds per size, >= 2.
    seed : int or numpy.random.SeedSequence
    moves : int
        Metropolis-Hastings steps per particle after each resampling.

    Returns
    -------
    dict
        ``"sizes"`` (S,), ``"replicas"``, ``"frames"`` (``N``); ``"exact"``:
        ``{moment: float}`` for :data:`MOMENTS` and ``"exact_error"``: the
        bank's error estimates of the depth's and the velocity's moments
        (``{"depth": float, "velocity": float}``); ``"runs"``: ``{moment: (S,
        replicas)}``, each cloud's estimate; ``"mean"``, ``"se"`` and
        ``"rmse"``: ``{moment: (S,)}``, the mean over the clouds, its standard
        error (SD over the clouds / sqrt(replicas)), and the root-mean-square
        error of one cloud from the exact value.
    """
    sizes = _sizes(sizes)
    if np.any(sizes < 2):
        raise ValueError(f"sizes must be integers >= 2, got {sizes!r}")
    if isinstance(replicas, bool) or not isinstance(replicas, (int, np.integer)) or replicas < 2:
        raise ValueError(f"replicas must be an integer >= 2, got {replicas!r}")
    post = bank_posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise)
    if np.ndim(post.log_normaliser) != 0:
        raise ValueError(f"mu must have shape (N,) (one track), got shape {np.shape(mu)}")
    exact = {m: float(getattr(post, m)) for m in MOMENTS}
    runs = {m: [] for m in MOMENTS}
    for J, stream in zip(sizes, _checks.spawn(seed, len(sizes)), strict=True):
        state = rbpf.run(
            mu,
            rho,
            prior_mean,
            prior_cov,
            int(J),
            np.random.default_rng(stream),
            process_noise=process_noise,
            replicas=int(replicas),
            moves=moves,
        )
        per_cloud = state.replica_moments()
        for m in MOMENTS:
            runs[m].append(getattr(per_cloud, m))
    runs = {m: np.array(v) for m, v in runs.items()}
    return {
        "sizes": sizes,
        "replicas": int(replicas),
        "frames": int(post.bank.frames),
        "exact": exact,
        "exact_error": {
            "depth": float(post.depth_error),
            "velocity": float(post.velocity_error),
        },
        "runs": runs,
        "mean": {m: np.mean(v, axis=1) for m, v in runs.items()},
        "se": {m: np.std(v, axis=1, ddof=1) / np.sqrt(replicas) for m, v in runs.items()},
        "rmse": {m: np.sqrt(np.mean((v - exact[m]) ** 2, axis=1)) for m, v in runs.items()},
    }


# --- the first update of the EKF and the UKF -------------------------------------------------


def first_update(scenario: Scenario, sigma_points: ukf.SigmaPoints = ukf.SigmaPoints()) -> dict:
    """The EKF and the UKF after ``mu_1``, and the sigma points of the prior.

    Parameters
    ----------
    scenario : Scenario
    sigma_points : SigmaPoints
        The UKF's rule (default ``alpha = 1, beta = 0, kappa = 0``).

    Returns
    -------
    dict
        ``"mu1"`` (float), ``"prior"`` (Gaussian), ``"sigma_points"`` of
        shape (7, 3), and ``"ekf"``, ``"ukf"``: ``MeanAndCov`` of the state at
        time 1 after ``mu_1``, shapes (3,) and (3, 3). The UKF runs with
        sigma points behind the camera (``allow_behind_camera=True``).
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    prior = scenario.prior
    e = ekf.ekf(scenario.mu, scenario.rho, prior)
    u = ukf.ukf(scenario.mu, scenario.rho, prior, sigma_points, allow_behind_camera=True)
    return {
        "mu1": float(scenario.mu[0]),
        "prior": prior,
        "sigma_points": sigma_points.points(prior.mean, prior.cov),
        "ekf": MeanAndCov(e.means[0], e.covs[0]),
        "ukf": MeanAndCov(u.means[0], u.covs[0]),
    }


def truncated_bearing_moments(mean, cov, eps) -> dict:
    """The prior mass near ``y = 0`` and the second moment of ``x / y`` away from it.

    Under a Gaussian on ``(x, y)`` the density of ``y`` is positive at 0, so
    ``P(|y| < eps)`` is about ``2 eps p_y(0)`` and
    ``E[(x / y)**2 ; |y| > eps]`` grows like ``2 p_y(0) E[x**2 | y = 0] / eps``:
    ``E[(x / y)**2]`` is infinite, and ``E[x / y]`` does not exist either
    (``E[|x / y|]`` diverges like ``log(1 / eps)``). These are the moments the
    unscented transform of ``h(x) = x / y`` sets out to match.

    Parameters
    ----------
    mean : array_like, shape (2,) or (3,)
        Mean of ``(x, y)`` (a third component, the velocity, is ignored).
    cov : array_like, shape (2, 2) or (3, 3)
        Covariance; its ``(x, y)`` block is used.
    eps : array_like, shape (E,)
        Half-widths of the excluded band ``|y| < eps``, each > 0.

    Returns
    -------
    dict
        ``"eps"`` (E,), ``"mass"`` (E,): ``P(|y| < eps)``, ``"second_moment"``
        (E,): ``E[(x / y)**2 ; |y| > eps]`` (adaptive quadrature in ``log |y|``
        of ``E[x**2 | y] p(y) / y**2``), and ``"density_at_zero"``: ``p_y(0)``.
    """
    from scipy.integrate import quad
    from scipy.special import ndtr

    mean = _checks.finite_array(mean, "mean")
    cov = _checks.finite_array(cov, "cov")
    if mean.shape not in ((2,), (3,)) or cov.shape != 2 * mean.shape:
        raise ValueError(
            f"mean and cov must have shapes (d,), (d, d), d = 2 or 3; got {mean.shape}, {cov.shape}"
        )
    eps = np.atleast_1d(_checks.positive_array(eps, "eps"))
    mx, my = mean[:2]
    cxx, cxy, cyy = cov[0, 0], cov[0, 1], cov[1, 1]
    if not (cyy > 0 and cxx * cyy - cxy**2 >= 0):
        raise ValueError("cov must be positive semi-definite with cov[1, 1] > 0")
    sy = np.sqrt(cyy)
    slope, residual = cxy / cyy, cxx - cxy**2 / cyy

    def weight(y):  # E[x**2 | y] p(y) / y**2, times |y| for the variable log|y|
        p = np.exp(-0.5 * ((y - my) / sy) ** 2) / (np.sqrt(2.0 * np.pi) * sy)
        return ((mx + slope * (y - my)) ** 2 + residual) * p / np.abs(y)

    top = np.log(abs(my) + 40.0 * sy)
    moments = [
        sum(
            quad(lambda t, sign=sign: weight(sign * np.exp(t)), np.log(e), top, limit=200)[0]
            for sign in (1.0, -1.0)
        )
        for e in eps
    ]
    return {
        "eps": eps,
        "mass": ndtr((eps - my) / sy) - ndtr((-eps - my) / sy),
        "second_moment": np.array(moments),
        "density_at_zero": float(np.exp(-0.5 * (my / sy) ** 2) / (np.sqrt(2.0 * np.pi) * sy)),
    }


# --- more frames ----------------------------------------------------------------------------

#: Depth scores gathered per filter by :func:`frames_study`, from :func:`depthcore.study.study`.
FRAMES_SCORES = ("bias", "rmse", "mean_sd", "coverage_68", "coverage_95")
#: The default critical value of :func:`coverage_test`, the standard normal's two-sided 1 % point.
COVERAGE_Z = 2.5758293035489004


def frames_study(
    frames,
    trials: int,
    seed,
    names=("optimal", "second_order", "ekf"),
    prior: str = "paper",
    process_noise: float = 0.0,
    truth=None,
    rho: float = SCENARIOS["fig2"].rho,
    particle_trials: int | None = None,
    n_particles: int = study_trials.PARTICLES,
) -> dict:
    """:func:`depthcore.study.study` at each number of frames, its depth scores gathered.

    The point, at ``truth`` at time 3, is followed on to frame ``N`` (with
    velocity changes of SD ``process_noise``) and every filter is scored on its
    state there. The filters that draw random numbers (``Filter.random``) run
    in a second study of ``particle_trials`` trials with ``n_particles``
    particles; the optimal filter, the reference of the Hellinger distances,
    runs in both. Both studies use ``seed``, so their first trials are the same.

    Parameters
    ----------
    frames : sequence of int, shape (F,)
        Numbers of frames ``N``, each from 3 to ``depthcore._checks.MAX_FRAMES``.
    trials : int
        Trials per ``N`` of the deterministic filters.
    seed : int or numpy.random.SeedSequence
        The same at every ``N``.
    names : sequence of str
        Filters, from :data:`depthcore.filters.FILTERS`; ``"optimal"`` is run
        whether named or not.
    prior : {"paper", "fixed"}
    process_noise : float
        ``q >= 0``.
    truth : array_like, shape (3,), optional
        State at time 3; default Figure 2's ``c``.
    rho : float
    particle_trials : int, optional
        Trials per ``N`` of the random filters; default ``trials``.
    n_particles : int

    Returns
    -------
    dict
        ``"frames"`` (F,), ``"process_noise"``, ``"prior"`` and, per filter
        (the optimal filter first), ``{score: (F,)}`` for :data:`FRAMES_SCORES`
        (of the depth) and ``"nees"``, each with its standard error
        (:func:`gather_scores`), ``"hellinger"`` (mean Hellinger distance of
        the depth marginal to the optimal one) and ``"trials"`` (valid trials
        scored).
    """
    frames = [_checks.count(n, "frames") for n in _checks.nonempty(np.atleast_1d(frames), "frames")]
    names = ("optimal",) + tuple(n for n in check_names(names) if n != "optimal")
    random = tuple(n for n in names if FILTERS[n].random)
    plain = tuple(n for n in names if not FILTERS[n].random)
    particle_trials = trials if particle_trials is None else particle_trials
    groups = [(plain, trials)] + ([(("optimal",) + random, particle_trials)] if random else [])
    rows = {name: [] for name in names}
    for n in frames:
        for group, t in groups:
            r = study.study(
                truth,
                rho,
                trials=t,
                seed=seed,
                prior=prior,
                names=group,
                n_particles=n_particles,
                frames=n,
                process_noise=process_noise,
            )
            for name in group[1:] if group is not plain else group:
                rows[name].append((r["filters"][name], r["valid_trials"]))
    out = {"frames": np.array(frames), "process_noise": float(process_noise), "prior": prior}
    for name, runs in rows.items():
        f = [x for x, _ in runs]
        out[name] = gather_scores(f, FRAMES_SCORES)
        out[name]["hellinger"] = np.array([x["hellinger_depth"]["mean"] for x in f])
        out[name]["trials"] = np.array([v for _, v in runs])
    return out


def coverage_test(coverage, level: float, trials, z: float = COVERAGE_Z) -> dict:
    """The binomial test of a coverage against its nominal level, normal approximation.

    A filter whose central ``level`` interval holds the truth with probability
    ``level`` covers it in a fraction of ``n`` independent trials with standard
    error ``sqrt(level (1 - level) / n)``. The coverage is called
    ``"calibrated"`` when it lies within ``z`` standard errors of the level
    (a two-sided test at 1 % for the default ``z``), ``"overconfident"`` when
    below (intervals too narrow), ``"underconfident"`` when above.

    Parameters
    ----------
    coverage : array_like, shape (...)
        Fractions of trials covered, in [0, 1].
    level : float
        Nominal level, in (0, 1).
    trials : array_like of int, shape (...)
        Trials behind each coverage, >= 1.
    z : float
        Critical value, > 0.

    Returns
    -------
    dict
        ``"se"``, ``"z"`` (the standardised deviation) and ``"verdict"``
        (array of str), each of the broadcast shape.
    """
    coverage = _checks.finite_array(coverage, "coverage")
    if np.any((coverage < 0) | (coverage > 1)):
        raise ValueError("coverage must lie in [0, 1]")
    level = float(level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    trials = _checks.finite_array(trials, "trials")
    if np.any(trials < 1):
        raise ValueError("trials must each be at least 1")
    z = _checks.positive_scalar(z, "z")
    se = study_scores.coverage_se(level, trials)
    score = (coverage - level) / se
    verdict = np.where(
        np.abs(score) <= z, "calibrated", np.where(score < 0, "overconfident", "underconfident")
    )
    return {"se": se, "z": score, "verdict": verdict}


def frame_marginals(
    mu,
    rho: float,
    frames,
    names=("optimal", "second_order", "ekf"),
    rng=None,
    n_particles: int | None = None,
    n_points: int = 601,
    width: float = 6.0,
    prior_scale: float = PAPER_PRIOR_SCALE,
) -> list[dict]:
    """Each filter's depth marginal after the first ``N`` of one sequence of bearings.

    The prior is the paper's rule applied to the first three bearings (mean
    ``(c1 - 2 c3, c2 - 2, 0)``, covariance ``prior_scale * I``), the same at
    every ``N``; there is no process noise.

    Parameters
    ----------
    mu : array_like, shape (M,)
        Bearings of frames 1 .. M.
    rho : float
    frames : sequence of int, shape (F,)
        Numbers of frames, each from 3 to ``M``.
    names : sequence of str
        Filters; ``"optimal"`` is always run.
    rng : numpy.random.Generator or SeedSequence, optional
        Required when a random filter is named.
    n_particles : int, optional
        Particles of the random filters; default each filter's own.
    n_points : int
        Points of the depth grid.
    width : float
        The grid spans the optimal depth mean ± ``width`` optimal SDs (cut at 0).

    Returns
    -------
    list of dict, one per ``N``
        ``"frames"``, ``"grid"`` (G,), ``"density"`` ``{name: (G,)}``,
        ``"depth_mean"`` and ``"depth_sd"`` ``{name: float}``.
    """
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim != 1 or len(mu) < 3:
        raise ValueError(f"mu must have shape (M,) with M >= 3, got shape {mu.shape}")
    frames = [_checks.count(n, "frames") for n in _checks.nonempty(np.atleast_1d(frames), "frames")]
    if any(not 3 <= n <= len(mu) for n in frames):
        raise ValueError(f"frames must each be from 3 to {len(mu)}, got {frames}")
    names = ("optimal",) + tuple(n for n in check_names(names) if n != "optimal")
    n_points = _checks.count(n_points, "n_points")
    width = _checks.positive_scalar(width, "width")
    pm = paper_prior_means(model.noise_free_states(mu[None, :3]))[0]
    pc = _checks.positive_scalar(prior_scale, "prior_scale") * np.eye(3)
    out = []
    for n in frames:
        estimates = {}
        for name in names:
            f = FILTERS[name]
            options = {}
            if f.random:
                if rng is None:
                    raise ValueError(f"rng is required to run the {name} filter")
                options["rng"] = rng
                if n_particles is not None:
                    options["n_particles"] = n_particles
            estimates[name] = f(mu[:n], rho, pm, pc, **options)
        ref = estimates["optimal"]
        lo = max(float(ref.depth_mean) - width * float(ref.depth_sd), 1e-9)
        grid = np.linspace(lo, float(ref.depth_mean) + width * float(ref.depth_sd), n_points)
        out.append(
            {
                "frames": n,
                "grid": grid,
                "density": {k: FILTERS[k].density(e, "depth", grid) for k, e in estimates.items()},
                "depth_mean": {k: float(e.depth_mean) for k, e in estimates.items()},
                "depth_sd": {k: float(e.depth_sd) for k, e in estimates.items()},
            }
        )
    return out


def conjecture_study(
    frames,
    rhos,
    depths,
    trials: int,
    seed,
    prior: str = "fixed",
    bearing: float = 0.2,
) -> dict:
    """The second-order filter against the EKF, scored against the optimal filter and the truth.

    For every number of frames, noise level and depth, :func:`frames_study`
    of the optimal, second-order and EKF filters, the truth at time 3 being
    ``(bearing * y, y, bearing * y)``: Figure 2's ``c = (1.2, 6, 1.2)`` scaled
    to depth ``y`` (its bearings at times 1-3 are nearly those of Eq. (17)).

    Parameters
    ----------
    frames : sequence of int, shape (F,)
    rhos : array_like, shape (R,)
        Noise levels, each > 0.
    depths : array_like, shape (D,)
        Depths at time 3, each > 2 (the point in front of the camera at time 1).
    trials : int
        Trials per setting (the same seed in each).
    seed : int or numpy.random.SeedSequence
    prior : {"paper", "fixed"}
    bearing : float
        Bearing at time 3, and lateral velocity per unit of depth.

    Returns
    -------
    dict
        ``"frames"`` (F,), ``"rho"`` (R,), ``"depth"`` (D,), ``"truth"`` (D, 3)
        and per filter (``"optimal"``, ``"second_order"``, ``"ekf"``) the
        scores of :func:`frames_study` as arrays of shape (R, D, F).
    """
    rhos = _checks.nonempty(np.atleast_1d(_checks.positive_array(rhos, "rhos")), "rhos")
    depths = _checks.nonempty(np.atleast_1d(_checks.positive_array(depths, "depths")), "depths")
    if np.any(depths <= 2):
        raise ValueError("depths must each exceed 2 (the point in front of the camera at time 1)")
    bearing = float(_checks.finite_array(bearing, "bearing"))
    truths = np.stack([bearing * depths, depths, bearing * depths], axis=1)
    names = ("optimal", "second_order", "ekf")
    runs = [
        [frames_study(frames, trials, seed, names, prior, truth=t, rho=float(r)) for t in truths]
        for r in rhos
    ]
    out = {"frames": runs[0][0]["frames"], "rho": rhos, "depth": depths, "truth": truths}
    for name in names:
        out[name] = {
            s: np.array([[run[name][s] for run in row] for row in runs]) for s in runs[0][0][name]
        }
    return out


def conjecture_wins(result: dict, z: float = COVERAGE_Z) -> dict:
    """Where the second-order filter beats the EKF, cell by cell of :func:`conjecture_study`.

    Parameters
    ----------
    result : dict
        From :func:`conjecture_study`; its arrays have shape (R, D, F).
    z : float
        Critical value of :func:`coverage_test`.

    Returns
    -------
    dict
        Boolean arrays of shape (R, D, F): ``"hellinger"`` (the second-order
        depth marginal is nearer the optimal one), ``"rmse"`` (its depth mean
        has the smaller RMSE), and for each level ``"coverage_68"``,
        ``"coverage_95"`` (its coverage lies fewer standard errors from the
        level); ``"calibrated_<level>"`` ``{name: (R, D, F)}``, the verdicts of
        :func:`coverage_test` for ``"optimal"``, ``"second_order"`` and ``"ekf"``.
    """
    so, ekf = result["second_order"], result["ekf"]
    out = {"hellinger": so["hellinger"] < ekf["hellinger"], "rmse": so["rmse"] < ekf["rmse"]}
    for level in (68, 95):
        tests = {
            name: coverage_test(
                result[name][f"coverage_{level}"], level / 100, result[name]["trials"], z
            )
            for name in ("optimal", "second_order", "ekf")
        }
        out[f"coverage_{level}"] = np.abs(tests["second_order"]["z"]) < np.abs(tests["ekf"]["z"])
        out[f"calibrated_{level}"] = {
            name: t["verdict"] == "calibrated" for name, t in tests.items()
        }
    return out


# --- the Cramér-Rao bound --------------------------------------------------------------


def bound_study(
    frames,
    trials: int,
    seed,
    names=("optimal", "second_order", "ekf"),
    prior: str = "paper",
    process_noise: float = 0.0,
    truth=None,
    rho: float = SCENARIOS["fig2"].rho,
    particle_trials: int | None = None,
    n_particles: int = study_trials.PARTICLES,
) -> dict:
    """Every named filter's depth and velocity errors and claimed SDs at frame ``N``, by trial.

    The truth is ``truth`` at time 3 (default Figure 2's ``c``): frames 1 and 2
    are ``G^{-2}`` and ``G^{-1}`` of it (Eq. (1)), and from time 3 on the
    velocity changes by ``a_k ~ N(0, process_noise**2)`` at every step. Each
    trial draws one track of ``max(frames)`` frames and its bearings; every
    filter runs on its first ``N`` bearings for each ``N`` of ``frames`` and is
    scored against the track's state at frame ``N``. The prior is the paper's
    rule (``"paper"``: from each trial's first three bearings) or the same rule
    applied once to ``truth`` (``"fixed"``), covariance 1000 I; trials whose
    first three bearings have no noise-free solution in front of the camera
    are left out, as in :func:`depthcore.study_trials.simulate`. The filters that
    draw random numbers run on the first ``particle_trials`` valid trials.
    Set the results against :func:`depthcore.bound.posterior_bound` with
    :func:`depthcore.bound.against_bound`.

    Parameters
    ----------
    frames : sequence of int, shape (F,)
        Numbers of frames ``N``, each from 3 to ``depthcore._checks.MAX_FRAMES``.
    trials : int
        Trials drawn, >= 2.
    seed : int or numpy.random.SeedSequence
    names : sequence of str
        Filters of :data:`depthcore.filters.FILTERS`; each must support the
        frames and the process noise asked for.
    prior : {"paper", "fixed"}
    process_noise : float
        ``q >= 0``.
    truth : array_like, shape (3,), optional
    rho : float
    particle_trials : int, optional
        Default ``trials``.
    n_particles : int

    Returns
    -------
    dict
        ``"frames"`` (F,), ``"truth"``, ``"rho"``, ``"process_noise"``,
        ``"prior"``, ``"prior_cov"`` (3, 3), ``"states"`` (T, F, 3) (the true
        state at each ``N``), and per filter ``{"depth_error", "depth_sd",
        "velocity_error", "velocity_sd"}``, each of shape (F, T_f), ``T_f``
        the trials it ran on.
    """
    frames = [_checks.count(n, "frames") for n in _checks.nonempty(np.atleast_1d(frames), "frames")]
    if any(not 3 <= n <= _checks.MAX_FRAMES for n in frames):
        raise ValueError(f"frames must each be from 3 to {_checks.MAX_FRAMES}, got {frames}")
    trials = _checks.count(trials, "trials")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    names = check_names(names)
    q = _checks.nonnegative_scalar(process_noise, "process_noise")
    unable = [n for n in names if q > 0 and not FILTERS[n].with_process_noise]
    unable += [n for n in names if max(frames) > 3 and not FILTERS[n].any_frames]
    if unable:
        raise ValueError(
            f"names: {', '.join(unable)} cannot run on {max(frames)} frames with process "
            f"noise {q:g}; leave them out"
        )
    truth = SCENARIOS["fig2"].c if truth is None else truth
    particle_trials = (
        trials if particle_trials is None else _checks.count(particle_trials, "particle_trials")
    )
    noise_rng, particle_rng = (
        np.random.default_rng(s) for s in _checks.spawn(_checks.seed_sequence(seed), 2)
    )
    drawn = study_trials.simulate(
        truth, rho, trials, noise_rng, prior, PAPER_PRIOR_SCALE, max(frames), q, tracks=True
    )
    mu, pm, pc, states = drawn.mu, drawn.prior_mean, drawn.prior_cov, drawn.tracks
    truth, rho = drawn.truth, drawn.rho
    noise = {"process_noise": q} if q > 0 else {}
    out = {
        "frames": np.array(frames),
        "truth": truth,
        "rho": rho,
        "process_noise": q,
        "prior": prior,
        "prior_cov": pc,
        "states": states[:, np.array(frames) - 1, :],
        "rejected_trials": drawn.n_rejected,
    }
    for name in names:
        f = FILTERS[name]
        rows = slice(None) if not f.random else slice(0, particle_trials)
        options = dict(noise) if f.with_process_noise else {}
        if f.random:
            options.update(rng=particle_rng, n_particles=n_particles)
        r = {k: [] for k in ("depth_error", "depth_sd", "velocity_error", "velocity_sd")}
        for n in frames:
            est = f(mu[rows, :n], rho, pm[rows], pc, **options)
            true = states[rows, n - 1]
            r["depth_error"].append(np.asarray(est.depth_mean) - true[:, 1])
            r["depth_sd"].append(np.asarray(est.depth_sd))
            r["velocity_error"].append(np.asarray(est.velocity_mean) - true[:, 2])
            r["velocity_sd"].append(np.asarray(est.velocity_sd))
        out[name] = {k: np.array(v) for k, v in r.items()}
    return out
