"""From a filter's own result to the registry's :class:`~depthcore.registry.estimates.Estimate`.

Recommended import: ``from depthcore.registry import adapters``.

Each filter has one door, a batched function of its module (``ekf.run``,
``optimal.run``, ``importance.run`` ...), which returns the filter's own result
(a :class:`~depthcore.problem.gaussian.History`, a
:class:`~depthcore.exact.mixture.Mixture`, weighted particles ...). Its entry in
:data:`depthcore.registry.filters.FILTERS` names that door and one of the
functions here, which reads the result as an
:class:`~depthcore.registry.estimates.Estimate`: one per kind of result, not one per
filter. Each takes the result and whether it is of one sequence (``single``: floats)
or of a batch (arrays of shape ``(B,)``).
:func:`gaussian_smoother` and :func:`smooth_optimal` are the smoothers that
:func:`depthcore.registry.tracking.track` runs.
"""

from __future__ import annotations

import numpy as np

from depthcore.exact import mixture, optimal
from depthcore.exact import smoother as bank_track
from depthcore.kalman import ekf, linear
from depthcore.particles.resampling import weighted_mean_and_cov
from depthcore.problem import checks, frames, model
from depthcore.problem.gaussian import Gaussian, History, MeanAndCov
from depthcore.registry.estimates import Estimate


def gaussian(result, single: bool) -> Estimate:
    """The estimate of a Gaussian filter (Eq. (13)): its mean and covariance at frame N.

    Parameters
    ----------
    result : History, Gaussian or object with ``mean`` and ``cov``
        A :class:`~depthcore.problem.gaussian.History` (means (..., N, 3),
        covariances (..., N, 3, 3), or a pair of them), read at its last frame;
        otherwise ``result.mean`` (..., 3) and ``result.cov`` (..., 3, 3). Kept as
        the estimate's ``detail``.
    single : bool
        Whether ``result`` is of one sequence.
    """
    result, mean, cov = _last(result)
    if single:
        g = Gaussian(mean, cov)
        (dm, ds), (vm, vs) = g.marginal("y"), g.marginal("v")
        return Estimate(dm, ds, vm, vs, None, None, g.mean, g.cov, result)
    sd = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    return Estimate(
        mean[..., 1],
        sd[..., 1],
        mean[..., 2],
        sd[..., 2],
        None,
        None,
        mean,
        cov,
        result,
    )


def _last(result):
    """``result`` (a pair of histories read as a History), its mean and covariance at frame N."""
    if isinstance(result, tuple) and not hasattr(result, "mean"):
        if not isinstance(result, History):
            result = History(*result)
        mean, cov = result.means[..., -1, :], result.covs[..., -1, :, :]
    else:
        mean, cov = result.mean, result.cov
    return result, np.asarray(mean, dtype=float), np.asarray(cov, dtype=float)


def spatial(result, single: bool) -> Estimate:
    """The estimate of a filter of a point in 3-D: the state ``(x, y, v, h, w)`` at frame N.

    ``result.mean`` (..., 5) and ``result.cov`` (..., 5, 5) (a
    :class:`~depthcore.exact.spatial.SpatialPosterior`, whose ``error`` gives the
    depth's and velocity's errors, or a :class:`~depthcore.kalman.spatial.SpatialHistory`);
    the velocity is the lateral one, ``v``. ``single`` is not needed: the shapes say it.
    """
    mean, cov = np.asarray(result.mean, dtype=float), np.asarray(result.cov, dtype=float)
    sd = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    error = getattr(result, "error", None)
    return Estimate(
        mean[..., 1],
        sd[..., 1],
        mean[..., 2],
        sd[..., 2],
        None if error is None else error[..., 1],
        None if error is None else error[..., 2],
        mean,
        cov,
        result,
    )


def unscented(result, single: bool) -> Estimate:
    """:func:`gaussian` for the UKF, saying whether its sigma points went behind the camera.

    The registry's UKF runs with ``allow_behind_camera=True``; its estimate's
    ``extras["sigma_points_behind_camera"]`` (a bool for one sequence, an array
    (B,) of them for a batch) is :attr:`depthcore.kalman.ukf.UKFHistory.went_behind`:
    whether at some frame a sigma point lay at a depth ``y <= 0``, where the
    unscented transform averaged ``x / y`` across its pole.
    """
    estimate = gaussian(result, single)
    went = getattr(result, "went_behind", None)
    if went is not None:
        estimate.extras["sigma_points_behind_camera"] = bool(went) if single else np.asarray(went)
    return estimate


def maximum_likelihood(result, single: bool) -> Estimate:
    """:func:`gaussian` for the batch maximum-likelihood estimate (``batch_ml.run``).

    Its mean is the estimate, its covariance the inverse Fisher information
    there; ``extras["at_limit"]`` (a bool, or an array (B,) of them) says
    where the likelihood had no maximum within the depths searched, and
    ``extras["misfit"]`` holds the least sum of squared standardised residuals.
    """
    estimate = gaussian(result, single)
    at_limit, misfit = np.asarray(result.at_limit), np.asarray(result.misfit)
    estimate.extras["at_limit"] = bool(at_limit) if single else at_limit
    estimate.extras["misfit"] = float(misfit) if single else misfit
    return estimate


def checked_gaussian(name: str):
    """:func:`gaussian` for a filter that carries a covariance: refuse one that rounding broke.

    Parameters
    ----------
    name : str
        The filter's name in the refusal.

    Returns
    -------
    callable
        ``(result, single) -> Estimate``, refusing, naming ``rho``, a
        covariance at frame ``N`` that is not positive definite.
    """

    def estimate(result, single: bool) -> Estimate:
        smallest = np.linalg.eigvalsh(_last(result)[2])[..., 0]
        if not np.all(smallest > 0):
            raise ValueError(
                f"rho is too small for the {name}, which carries a covariance: rounding "
                f"left its covariance at frame N not positive definite (eigenvalue "
                f"{float(np.min(smallest)):.3g})"
            )
        return gaussian(result, single)

    return estimate


def exact(result, single: bool) -> Estimate:
    """The estimate of the optimal filter (:func:`depthcore.exact.optimal.run`).

    ``result`` is its :class:`~depthcore.exact.optimal.OptimalMarginals`,
    :class:`~depthcore.exact.optimal.BatchMarginals`,
    :class:`~depthcore.exact.mixture.Moments` or
    :class:`~depthcore.exact.mixture.Mixture`, kept as ``detail``; the
    probability of a depth behind the camera is in ``extra`` (0 for the
    bank, whose depths are in front by construction).
    """
    m = result.moments if isinstance(result, optimal.BatchMarginals) else result
    behind = getattr(m, "prob_behind_camera", None)
    if behind is None:
        behind = np.zeros_like(m.depth_mean)
    return Estimate(
        m.depth_mean,
        m.depth_sd,
        m.velocity_mean,
        m.velocity_sd,
        m.depth_error,
        m.velocity_error,
        m.mean,
        m.cov,
        result,
        {"prob_behind_camera": behind},
    )


def particles(result, single: bool) -> Estimate:
    """The estimate of the importance sampler (:func:`depthcore.particles.importance.run`).

    ``result`` is its ParticleResult (one sequence) or ParticleBatch. The
    errors are the larger of the delta-method standard errors of the mean and
    of the SD; NaN where the weight sits on fewer than
    ``resampling.MIN_EFFECTIVE_DRAWS`` distinct particles (``collapsed``).
    """
    m, se, collapsed = result.moments(), result.standard_errors(), result.collapsed()
    weights = np.exp(result.log_weights)
    mean, cov = weighted_mean_and_cov(result.particles, weights)
    depth_error = np.where(collapsed, np.nan, np.maximum(se.depth_mean, se.depth_sd))
    velocity_error = np.where(collapsed, np.nan, np.maximum(se.velocity_mean, se.velocity_sd))
    moments = (m.depth_mean, m.depth_sd, m.velocity_mean, m.velocity_sd)
    return _replicated_estimate(
        moments, depth_error, velocity_error, mean, cov, result, collapsed, single
    )


def replicas(result, single: bool) -> Estimate:
    """The estimate of the resample-move filter's replicas (``resample_move.replicated``).

    The moments are the pool's; the errors the larger of those of the mean and
    of the SD from the replicas' spread (Student-t widened), NaN where the
    replicas collapsed (``collapsed``,
    :meth:`~depthcore.particles.resample_move.Replicated.errors`).
    """
    mean, cov = weighted_mean_and_cov(result.particles, np.exp(result.log_weights))
    m = result.moments()
    errors, collapsed = result.errors()
    moments = tuple(m[k] for k in ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd"))
    depth_error = np.maximum(errors["depth_mean"], errors["depth_sd"])
    velocity_error = np.maximum(errors["velocity_mean"], errors["velocity_sd"])
    if single:
        mean, cov = mean[0], cov[0]
        moments = tuple(v[0] for v in moments)
        depth_error, velocity_error, collapsed = depth_error[0], velocity_error[0], collapsed[0]
    return _replicated_estimate(
        moments, depth_error, velocity_error, mean, cov, result, collapsed, single
    )


def rao_blackwellised(result, single: bool) -> Estimate:
    """The estimate of the Rao-Blackwellised particle filter (``rbpf.run``).

    The moments are those of the replicas pooled into one mixture
    (:meth:`~depthcore.particles.rbpf.RBPF.state_moments`, the law of total
    variance over the particles' filters); the errors the larger of those of
    the mean and of the SD from the replicas' spread, Student-t widened, NaN
    with one replica or where the replicas collapsed.
    """
    mean, cov = result.state_moments()
    se, collapsed = result.errors()
    e = gaussian(MeanAndCov(mean, cov), single)
    moments = (e.depth_mean, e.depth_sd, e.velocity_mean, e.velocity_sd)
    depth_error = np.maximum(se.depth_mean, se.depth_sd)
    velocity_error = np.maximum(se.velocity_mean, se.velocity_sd)
    return _replicated_estimate(
        moments, depth_error, velocity_error, e.mean, e.cov, result, collapsed, single
    )


def _replicated_estimate(
    moments, depth_error, velocity_error, mean, cov, detail, collapsed, single
):
    """An estimate with Monte Carlo errors; floats and a bool for one sequence."""
    if single:
        moments = tuple(float(v) for v in moments)
        depth_error, velocity_error = float(depth_error), float(velocity_error)
        collapsed = bool(collapsed)
    return Estimate(
        *moments,
        depth_error,
        velocity_error,
        mean,
        cov,
        detail,
        collapsed=collapsed,
    )


def smooth_optimal(mu, rho, prior_mean, prior_cov, process_noise, steps=None, law=None):
    """The exact filter and its fixed-interval smoother: :func:`depthcore.exact.smoother.track`.

    The bearings are added online (:func:`depthcore.exact.posterior.update`); the smoothed
    state is each depth node's Rauch-Tung-Striebel smoother mixed over the
    nodes (textbook 19.2.6, :meth:`depthcore.exact.mixture.Mixture.smoothed`).
    ``steps`` (N - 1,), or ``None`` for unit steps, and ``law`` (a
    :class:`~depthcore.problem.depth_prior.DepthPrior`, or ``None``) are passed on by keyword.
    """
    more = {} if steps is None else {"steps": steps}
    t = bank_track.track(
        mu, rho, prior_mean, prior_cov, process_noise, lag=np.shape(mu)[-1] - 1, law=law, **more
    )
    return t.filtered, t.interval, t


def gaussian_smoother(run, **options):
    """The Gaussian filter ``run`` at every frame and the Rauch-Tung-Striebel smoother over it.

    ``run`` is the door of a Gaussian filter whose result is a
    :class:`~depthcore.problem.gaussian.History` (:func:`depthcore.kalman.ekf.run`,
    :func:`depthcore.kalman.ukf.run`), called with ``options``; the smoother
    takes checked inputs, as :func:`depthcore.registry.tracking.track` passes them
    (``mu`` (N,) with ``NaN`` where missing, ``rho`` a number or (N,), and
    ``steps`` (N - 1,) or ``None``, passed to ``run`` only when given).

    The motion, Eq. (1) over the step ``s_k`` with the process noise on the
    velocity, is linear (``x_{k+1} = F_k x_k + s_k e``), so every Gaussian
    filter predicts exactly (Eq. (10)): the predicted Gaussian at frame
    ``k + 1`` is ``F_k m_k + s_k e``, ``F_k P_k F_k^T + diag(0, 0, q**2 s_k)``,
    and the backward recursions of textbook 19.2.6
    (:func:`depthcore.kalman.linear.fixed_interval_smoother`, with ``Psi = F_k``
    per step) run over the filter's own Gaussians: for the EKF this is the
    extended Kalman smoother (textbook 19.3), for the UKF the unscented one. At
    a missing frame the filter's Gaussian is its prediction, and the
    smoother's recursions run through it unchanged.
    """

    def smoother(mu, rho, prior_mean, prior_cov, process_noise, steps=None):
        more = {} if steps is None else {"steps": steps}
        h = run(mu, rho, prior_mean, prior_cov, process_noise=process_noise, **options, **more)
        means, covs = h.means, h.covs
        if steps is None:
            predicted = ekf.predict(means[:-1], covs[:-1], process_noise)
            Psi = model.F
        else:
            s = np.asarray(steps, dtype=float)
            predicted = ekf.predict(means[:-1], covs[:-1], process_noise, s)
            Psi = frames.transition(s)
        filtered = linear.FilterResult(
            means,
            covs,
            np.concatenate([prior_mean[None], predicted.mean]),
            np.concatenate([prior_cov[None], predicted.cov]),
            np.zeros(means.shape[0]),
        )
        smoothed = linear.fixed_interval_smoother(filtered, Psi)
        return mixture.Smoothed(means, covs), mixture.Smoothed(smoothed.mean, smoothed.cov), h

    return smoother


def required_rng(rng, name: str) -> np.random.Generator:
    """``rng`` as a Generator; ``None`` is refused, naming ``rng`` and the filter ``name``."""
    if rng is None:
        raise ValueError(
            f"rng is required to run the {name}: pass a numpy.random.Generator or SeedSequence"
        )
    return checks.generator(rng)
