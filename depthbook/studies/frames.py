"""A Monte Carlo study at several numbers of frames: every filter's depth scores at frame ``N``.

Recommended import: ``from depthbook.studies import frames``.

:func:`frames_study` runs :func:`depthcore.studies.monte_carlo.study` at each
number of frames ``N`` (with or without process noise on the velocity) and
gathers each filter's depth scores with their standard errors
(:func:`depthcore.studies.monte_carlo.gather_scores`). The book's chapters on
more frames and on the paper's conjecture read it.
"""

from __future__ import annotations

import numpy as np

from depthcore.problem import checks
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS, check_names
from depthcore.studies import monte_carlo
from depthcore.studies import trials as study_trials
from depthcore.studies.monte_carlo import DEPTH_SCORES, gather_scores


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
    client=None,
) -> dict:
    """:func:`depthcore.studies.monte_carlo.study` at each number of frames, its depth scores
    gathered.

    The point, at ``truth`` at time 3, is followed on to frame ``N`` (with
    velocity changes of SD ``process_noise``) and every filter is scored on its
    state there. The filters that draw random numbers (``Filter.random``) run
    in a second study of ``particle_trials`` trials with ``n_particles``
    particles; the optimal filter, the reference of the Hellinger distances,
    runs in both. Both studies use ``seed``, so their first trials are the same.

    Parameters
    ----------
    frames : sequence of int, shape (F,)
        Numbers of frames ``N``, each from 3 to ``depthcore.problem.checks.MAX_FRAMES``.
    trials : int
        Trials per ``N`` of the deterministic filters.
    seed : int or numpy.random.SeedSequence
        The same at every ``N``.
    names : sequence of str
        Filters, from :data:`depthcore.registry.filters.FILTERS`; ``"optimal"`` is run
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
    client : distributed.Client, optional
        Run every study's chunks as tasks of its cluster
        (:mod:`depthcore.studies.tasks`); default in this process. The result
        is the same, bit for bit.

    Returns
    -------
    dict
        ``"frames"`` (F,), ``"process_noise"``, ``"prior"`` and, per filter
        (the optimal filter first), ``{score: (F,)}`` for
        :data:`~depthcore.studies.monte_carlo.DEPTH_SCORES`
        (of the depth) and ``"nees"``, each with its standard error
        (:func:`~depthcore.studies.monte_carlo.gather_scores`), ``"hellinger"`` (mean Hellinger
        distance of the depth marginal to the optimal one) with ``"hellinger_se"``,
        and ``"trials"`` (valid trials scored); ``"paired"``, a list (F,) of
        the per-trial depth scores' co-moments of the filters that draw no
        random numbers, over their common trials (``study(..., paired=True)``).
    """
    values = list(frames) if np.ndim(frames) else [frames]
    frames = [checks.frames(n) for n in checks.nonempty(values, "frames")]
    names = ("optimal",) + tuple(n for n in check_names(names) if n != "optimal")
    random = tuple(n for n in names if FILTERS[n].random)
    plain = tuple(n for n in names if not FILTERS[n].random)
    particle_trials = trials if particle_trials is None else particle_trials
    groups = [(plain, trials)] + ([(("optimal",) + random, particle_trials)] if random else [])
    rows = {name: [] for name in names}
    paired = []
    same = dict(
        seed=seed, prior=prior, n_particles=n_particles, process_noise=process_noise, client=client
    )
    for n in frames:
        for group, t in groups:
            r = monte_carlo.study(
                truth, rho, trials=t, names=group, frames=n, paired=group is plain, **same
            )
            for name in group[1:] if group is not plain else group:
                rows[name].append((r["filters"][name], r["valid_trials"]))
            if group is plain:
                paired.append(r["paired"])
    out = {"frames": np.array(frames), "process_noise": float(process_noise), "prior": prior}
    for name, runs in rows.items():
        f = [x for x, _ in runs]
        out[name] = gather_scores(f, DEPTH_SCORES)
        out[name]["hellinger"] = np.array([x["hellinger_depth"]["mean"] for x in f])
        out[name]["hellinger_se"] = np.array([x["hellinger_depth"]["se"] for x in f])
        out[name]["trials"] = np.array([v for _, v in runs])
    out["paired"] = paired
    return out
