"""Simulation-based calibration of the exact filter over frames, process noise and noise level.

Recommended import: ``from depthbook.studies import calibration_grid``.

:func:`calibration_grid` checks the exact filter as
:func:`depthcore.studies.monte_carlo.prior_study` does (truths drawn from the fixed
prior of Figure 2's truth, the filter's probability integral transforms at frame
``N``) in each setting of numbers of frames ``N``, process noise ``q`` and bearing
noise ``rho`` (:func:`factorial` makes every combination), each on its own stream
spawned from one seed, and keeps the central 68 % and 95 % intervals' coverage, which
the hard chapter tests. :func:`law_calibration` does the same with truths drawn from
each of the tracking literature's laws of the depth and the exact filter under that
law itself. :func:`coverage_verdicts` reads each setting's depth coverages with their
binomial standard errors, the two-sided test of each against its level, and the
uniformity tests of the transforms.
"""

from __future__ import annotations

import itertools

import numpy as np

from depthcore.analysis import bound, calibration
from depthcore.exact import posterior
from depthcore.problem import checks
from depthcore.problem.gaussian import paper_prior_means
from depthcore.problem.scenarios import SCENARIOS
from depthcore.studies import scores, tasks
from depthcore.studies import trials as drawn_trials
from depthcore.studies.monte_carlo import FALSE_ALARM

#: The central intervals whose depth coverage :func:`coverage_verdicts` tests.
TESTED_LEVELS = (0.68, 0.95)


def factorial(frames, process_noises, rhos) -> list[tuple[int, float, float]]:
    """Every combination ``(N, q, rho)`` of the given numbers of frames, process noises and
    bearing noises, in that order (``rho`` varying fastest).

    Parameters
    ----------
    frames : sequence of int
    process_noises : sequence of float
    rhos : sequence of float

    Returns
    -------
    list of tuple
    """
    out = [
        (
            checks.frames(n),
            checks.nonnegative_scalar(q, "process_noises"),
            checks.positive_scalar(r, "rhos"),
        )
        for n, q, r in itertools.product(frames, process_noises, rhos)
    ]
    if not out:
        raise ValueError("frames, process_noises, rhos: each must hold at least one value")
    return out


#: Truths filtered together, one task each.
CHUNK = 256


def calibration_grid(settings, trials: int, seed, prior_scale: float = 1000.0, client=None):
    """Simulation-based calibration of the exact filter at frame ``N`` in each setting.

    As :func:`depthcore.studies.monte_carlo.prior_study`: truths drawn from the fixed
    prior (the paper's rule applied once to Figure 2's ``c``: mean ``G^{-2} c`` with
    velocity 0, covariance ``prior_scale * I``) with the point in front of the camera,
    followed to frame ``N`` with accelerations ``N(0, q**2)``, their bearings drawn with
    noise ``rho`` (:func:`depthcore.analysis.calibration.draw_from_prior`), and the exact
    filter's depth and velocity CDFs at the truth
    (:func:`depthcore.analysis.calibration.pit_values`); kept here are the coverages
    of the central intervals at :data:`TESTED_LEVELS` and the uniformity tests.

    Parameters
    ----------
    settings : sequence of (int, float, float)
        Numbers of frames ``N`` (3 to ``depthcore.problem.checks.MAX_FRAMES``), process
        noise ``q >= 0`` and bearing noise ``rho > 0`` (:func:`factorial`).
    trials : int
        Truths drawn per setting, >= 2.
    seed : int or numpy.random.SeedSequence
        Setting ``k`` draws from the seed's child ``k``.
    prior_scale : float
        > 0; the paper's 1000 by default.
    client : distributed.Client, optional
        Filter the truths in chunks of :data:`CHUNK` as tasks of its cluster
        (:mod:`depthcore.studies.tasks`); the result is the same, bit for bit.

    Returns
    -------
    list of dict, one per setting
        ``"frames"``, ``"process_noise"``, ``"rho"``, ``"valid_trials"``,
        ``"rejected_trials"``, ``"behind_camera_draws"``, ``"levels"``
        (:data:`TESTED_LEVELS`) and, for ``"depth"`` and ``"velocity"``, the
        ``"coverage"`` at each level with :func:`depthcore.analysis.calibration.uniformity`'s
        tests.
    """
    settings = [tuple(s) for s in settings]
    if not settings:
        raise ValueError("settings must not be empty")
    trials = checks.count(trials, "trials")
    if trials < 2:
        raise ValueError(f"trials must be at least 2, got {trials}")
    scale = checks.positive_scalar(prior_scale, "prior_scale")
    mean = paper_prior_means(np.asarray(SCENARIOS["fig2"].c, dtype=float)[None])[0]
    cov = scale * np.eye(3)
    out = []
    for (n, q, rho), s in zip(
        settings, checks.seed_sequence(seed).spawn(len(settings)), strict=True
    ):
        n, q = checks.frames(n), checks.nonnegative_scalar(q, "settings")
        rho = checks.positive_scalar(rho, "settings")
        draws = calibration.draw_from_prior(
            mean, cov, rho, trials, np.random.default_rng(s), frames=n, process_noise=q
        )
        starts = range(0, len(draws.mu), CHUNK)
        pits = []
        tasks.fold_chunks(
            _pit_chunk,
            (
                (draws.mu[i : i + CHUNK], draws.truth[i : i + CHUNK], rho, mean, cov, q)
                for i in starts
            ),
            lambda k, pit, pits=pits: pits.append(pit),
            client=client,
        )
        result = {
            "frames": n,
            "process_noise": q,
            "rho": rho,
            "valid_trials": len(draws.mu),
            "rejected_trials": draws.n_rejected,
            "behind_camera_draws": draws.n_behind,
            "levels": list(TESTED_LEVELS),
        }
        for j, quantity in enumerate(("depth", "velocity")):
            u = np.concatenate([p[j] for p in pits])
            tests = calibration.uniformity(u)
            tests.pop("counts")
            result[quantity] = {
                "coverage": calibration.coverage(u, TESTED_LEVELS).tolist(),
                **tests,
            }
        out.append(result)
    return out


def law_calibration(forms, frames, trials: int, seed, rho: float, client=None):
    """Simulation-based calibration of the exact filter under each drawn law, at frame ``N``.

    In each setting ``(form, N)`` (every combination, ``N`` varying fastest) the truths
    are drawn from the form's law about Figure 2's truth
    (:func:`depthcore.studies.trials.simulate`, truths kept where the first three
    bearings have a noise-free solution in front of the camera, a selection by the
    bearings alone), followed to frame ``N`` without process noise, and the exact
    filter runs under that law itself (``Trials.law`` of :class:`depthcore.studies.trials.Trials`);
    its depth and velocity CDFs at the truth are kept as :func:`calibration_grid`
    keeps them.

    Parameters
    ----------
    forms : sequence of str
        Of :data:`depthcore.studies.priors.DRAWN`.
    frames : sequence of int
    trials : int
        Truths drawn per setting, >= 2.
    seed : int or numpy.random.SeedSequence
        Setting ``k`` draws from the seed's child ``k``.
    rho : float
        The bearing noise, > 0.
    client : distributed.Client, optional
        As for :func:`calibration_grid`.

    Returns
    -------
    list of dict, one per setting
        ``"form"`` and :func:`calibration_grid`'s keys (``"process_noise"`` 0).
    """
    settings = list(itertools.product(forms, [checks.frames(n) for n in frames]))
    if not settings:
        raise ValueError("forms, frames: each must hold at least one value")
    trials = checks.count(trials, "trials")
    rho = checks.positive_scalar(rho, "rho")
    truth = np.asarray(SCENARIOS["fig2"].c, dtype=float)
    out = []
    for (form, n), s in zip(settings, checks.seed_sequence(seed).spawn(len(settings)), strict=True):
        tr = drawn_trials.simulate(truth, rho, trials, np.random.default_rng(s), form, frames=n)
        pits = []
        tasks.fold_chunks(
            _law_pit_chunk,
            (
                (tr.mu[i : i + CHUNK], tr.truths[i : i + CHUNK], rho, tr.law)
                for i in range(0, len(tr.mu), CHUNK)
            ),
            lambda k, pit, pits=pits: pits.append(pit),
            client=client,
        )
        result = {
            "form": form,
            "frames": n,
            "process_noise": 0.0,
            "rho": rho,
            "valid_trials": len(tr.mu),
            "rejected_trials": tr.n_rejected,
            "levels": list(TESTED_LEVELS),
        }
        for j, quantity in enumerate(("depth", "velocity")):
            u = np.concatenate([p[j] for p in pits])
            tests = calibration.uniformity(u)
            tests.pop("counts")
            result[quantity] = {
                "coverage": calibration.coverage(u, TESTED_LEVELS).tolist(),
                **tests,
            }
        out.append(result)
    return out


def _law_pit_chunk(item) -> tuple:
    """The exact filter's CDFs under the law at each truth's depth and velocity at frame ``N``:
    a task of :func:`law_calibration`. ``item`` is ``(mu, truths, rho, law)``."""
    mu, truths, rho, law = item
    post = posterior.posterior(mu, rho, None, None, law=law)
    depth = post.depth_cdf(truths[:, 1:2])[:, 0]
    velocity = post.velocity_cdf(truths[:, 2:3])[:, 0]
    return depth, velocity


def _pit_chunk(item) -> tuple:
    """The PIT values of one chunk of truths: a task of :func:`calibration_grid`.

    ``item`` is ``(mu, truth, rho, mean, cov, q)``; returns
    :func:`depthcore.analysis.calibration.pit_values`'s ``(depth, velocity)``.
    """
    mu, truth, rho, mean, cov, q = item
    return calibration.pit_values(mu, truth, rho, mean, cov, q, q > 0)


def coverage_verdicts(result: dict, z: float = bound.Z, false_alarm: float = FALSE_ALARM) -> dict:
    """The depth coverages of one setting of :func:`calibration_grid`, each with its test.

    Parameters
    ----------
    result : dict
        One setting of :func:`calibration_grid`.
    z : float
        Critical value of the two-sided coverage tests (default the 1 % point).
    false_alarm : float
        Rate at which the two uniformity tests together reject calibrated transforms.

    Returns
    -------
    dict
        For each level ``p`` of :data:`TESTED_LEVELS`, ``"coverage_<100 p>"`` and its
        binomial ``"coverage_<100 p>_se"`` (of the coverage found), and
        ``"passes_<100 p>"``: the coverage within ``z`` binomial standard errors of
        ``p`` (the nominal level's, :func:`depthcore.studies.scores.coverage_se`);
        ``"ks_pvalue"``, ``"chi2_pvalue"`` of the depth's transforms and ``"uniform"``
        (both p-values above ``false_alarm / 2``), ``"velocity_uniform"`` likewise,
        and ``"trials"``.
    """
    z = checks.positive_scalar(z, "z")
    false_alarm = checks.probability(false_alarm, "false_alarm")
    n = int(result["valid_trials"])
    depth = result["depth"]
    out = {"trials": n}
    for p, c in zip(result["levels"], depth["coverage"], strict=True):
        key = f"{round(100 * p)}"
        out[f"coverage_{key}"] = float(c)
        out[f"coverage_{key}_se"] = float(scores.proportion_se(round(c * n), n))
        out[f"passes_{key}"] = bool(abs(c - p) <= z * scores.coverage_se(p, n))

    def uniform(r):
        return bool(min(r["ks_pvalue"], r["chi2_pvalue"]) > false_alarm / 2)

    out["ks_pvalue"] = float(depth["ks_pvalue"])
    out["chi2_pvalue"] = float(depth["chi2_pvalue"])
    out["uniform"] = uniform(depth)
    out["velocity_uniform"] = uniform(result["velocity"])
    return out
