"""Each filter in the registry's calling convention: one function per filter, and the smoothers.

Recommended import: ``from depthcore.registry import adapters``.

``run_<name>(mu, rho, prior_mean, prior_cov, **options)`` runs the filter
``name`` of :mod:`depthcore.registry.filters` and returns an
:class:`~depthcore.registry.estimates.Estimate`; the filters with process noise also
take ``process_noise``. The functions take checked inputs: the registry's
:class:`Filter <depthcore.registry.filters.Filter>`, when called, has converted and
checked ``mu``, ``rho``, the prior and ``process_noise`` (and whether the
filter supports the frames and the process noise given); each function checks
only what is its own (a filter's options, a covariance that rounding left not
positive definite). :func:`smooth_optimal` and :func:`gaussian_smoother` are
the smoothers that :func:`depthcore.registry.tracking.track` runs.
"""

from __future__ import annotations

import numpy as np

from depthcore.exact import mixture, optimal, posterior
from depthcore.exact import smoother as bank_track
from depthcore.kalman import (
    ekf,
    inverse_depth,
    inverse_depth_ukf,
    iterated,
    linear,
    modified_polar,
    range_ekf,
    second_order,
    ukf,
)
from depthcore.particles import importance, rbpf, resample_move
from depthcore.particles.resampling import weighted_mean_and_cov
from depthcore.problem import checks, model
from depthcore.problem.gaussian import Gaussian, History
from depthcore.registry.estimates import Estimate

#: Particles of the particle filter unless a caller asks for another number.
PARTICLES = 20_000

#: Particles per replica of the resample-move filter, by default (``resample_move.REPLICAS``
#: replicas: the same 20,000 particles in all as the importance sampler).
RESAMPLE_MOVE_PARTICLES = 5000

#: Particles per replica of the Rao-Blackwellised particle filter, by default.
RBPF_PARTICLES = 1000

#: Independent replicas of the Rao-Blackwellised particle filter, for its standard errors.
RBPF_REPLICAS = 4


def _single(mu) -> bool:
    """Whether ``mu`` is one sequence (shape (N,)) rather than a batch (B, N)."""
    return np.ndim(mu) == 1


def _prior(prior_mean, prior_cov) -> Gaussian:
    try:
        return Gaussian(prior_mean, prior_cov)
    except ValueError as exc:
        raise ValueError(
            str(exc).replace("cov ", "prior_cov ", 1).replace("mean ", "prior_mean ", 1)
        ) from None


def _gaussian_estimate(mean, cov, detail) -> Estimate:
    """An :class:`~depthcore.registry.estimates.Estimate` of a Gaussian filter from its mean and
    covariance
    (Eq. (13))."""
    mean = np.asarray(mean, dtype=float)
    cov = np.asarray(cov, dtype=float)
    if mean.ndim == 1:
        g = Gaussian(mean, cov)
        (dm, ds), (vm, vs) = g.marginal("y"), g.marginal("v")
        return Estimate(dm, ds, vm, vs, None, None, g.mean, g.cov, detail)
    return Estimate(
        mean[..., 1],
        np.sqrt(cov[..., 1, 1]),
        mean[..., 2],
        np.sqrt(cov[..., 2, 2]),
        None,
        None,
        mean,
        cov,
        detail,
    )


def run_optimal(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    reading: str = "derived",
    support: str = "front",
    rtol: float = 1e-10,
) -> Estimate:
    """The optimal filter, Eqs. (6), (13)-(16); see :func:`depthcore.exact.optimal.marginals`.

    For a batch with the default reading and support, ``detail`` is the
    :class:`~depthcore.exact.optimal.BatchMarginals` (with the CDFs and densities);
    otherwise the :class:`~depthcore.exact.optimal.Moments`. For more than three
    frames or with process noise it is the bank of Kalman filters over depth
    nodes placed by the same quadrature (:func:`depthcore.exact.posterior.posterior`),
    and ``detail`` its :class:`~depthcore.exact.mixture.Mixture`.
    """
    if np.shape(mu)[-1] != 3 or process_noise > 0:
        if (reading, support) != ("derived", "front"):
            raise ValueError(
                "reading and support other than 'derived' and 'front' are readings of the "
                "paper's three-frame Eqs. (14)-(16); with more frames or process noise "
                f"the optimal filter has neither, got {reading!r} and {support!r}"
            )
        m = posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise, rtol)
        return Estimate(
            m.depth_mean,
            m.depth_sd,
            m.velocity_mean,
            m.velocity_sd,
            m.depth_error,
            m.velocity_error,
            m.mean,
            m.cov,
            m,
            {"prob_behind_camera": np.zeros_like(m.depth_mean)},
        )
    if _single(mu):
        m = optimal.marginals(mu, rho, _prior(prior_mean, prior_cov), reading, support, rtol)
        return Estimate(
            m.depth_mean,
            m.depth_sd,
            m.velocity_mean,
            m.velocity_sd,
            m.depth_error,
            m.velocity_error,
            m.mean,
            m.cov,
            m,
            {"prob_behind_camera": m.prob_behind_camera},
        )
    if (reading, support) == ("derived", "front"):
        detail = optimal.batch_marginals(mu, rho, prior_mean, prior_cov, rtol)
        m = detail.moments
    else:
        m = detail = optimal.moments(mu, rho, prior_mean, prior_cov, reading, support, rtol)
    return Estimate(
        m.depth_mean,
        m.depth_sd,
        m.velocity_mean,
        m.velocity_sd,
        m.depth_error,
        m.velocity_error,
        m.mean,
        m.cov,
        detail,
        {"prob_behind_camera": m.prob_behind_camera},
    )


def run_second_order(
    mu, rho, prior_mean, prior_cov, process_noise: float = 0.0, reading: str = "derived"
) -> Estimate:
    """The second-order approximation ``p_s``, Eq. (8); ``detail`` is its Gaussian or ``None``.

    For ``N > 3`` bearings or process noise, its generalisation
    (:func:`depthcore.kalman.second_order.second_order_batch`).
    """
    if _single(mu):
        g = second_order.second_order(
            mu, rho, _prior(prior_mean, prior_cov), reading, process_noise
        )
        return _gaussian_estimate(g.mean, g.cov, g)
    mean, cov = second_order.second_order_batch(
        mu, rho, prior_mean, prior_cov, reading, process_noise
    )
    return _gaussian_estimate(mean, cov, None)


def run_ekf(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> Estimate:
    """The EKF, Eqs. (10)-(12); ``detail`` is its :class:`~depthcore.problem.gaussian.History`."""
    if _single(mu):
        h = ekf.ekf(mu, rho, _prior(prior_mean, prior_cov), process_noise)
    else:
        h = ekf.run(mu, rho, prior_mean, prior_cov, process_noise)
    return _gaussian_estimate(h.means[..., -1, :], h.covs[..., -1, :, :], h)


def run_ukf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = True,
) -> Estimate:
    """The UKF; ``detail`` is its :class:`~depthcore.problem.gaussian.History`.

    By default it runs even where sigma points of the paper's broad prior lie
    behind the camera (``allow_behind_camera``): the comparison is the point.
    """
    if _single(mu):
        h: History = ukf.ukf(
            mu, rho, _prior(prior_mean, prior_cov), sigma_points, allow_behind_camera, process_noise
        )
    else:
        h = ukf.run(
            mu, rho, prior_mean, prior_cov, process_noise, sigma_points, allow_behind_camera
        )
    return _gaussian_estimate(h.means[..., -1, :], h.covs[..., -1, :, :], h)


def run_iterated(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    max_iterations: int = iterated.MAX_ITERATIONS,
) -> Estimate:
    """The iterated EKF (:func:`depthcore.kalman.iterated.run`); ``detail`` is its History."""
    if _single(mu):
        _prior(prior_mean, prior_cov)
    means, covs = iterated.run(mu, rho, prior_mean, prior_cov, process_noise, max_iterations)
    _covariance_form(covs[..., -1, :, :], "iterated EKF")
    return _gaussian_estimate(means[..., -1, :], covs[..., -1, :, :], History(means, covs))


def run_inverse_depth(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> Estimate:
    """The inverse-depth EKF (:func:`depthcore.kalman.inverse_depth.estimate`).

    ``detail`` is its mean and covariance in ``(x, y, v)`` at frame ``N``.
    """
    return _moments_estimate(
        mu,
        prior_mean,
        prior_cov,
        "inverse-depth EKF",
        lambda: inverse_depth.estimate(mu, rho, prior_mean, prior_cov, process_noise),
    )


def run_range_parametrised(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    n_components: int = range_ekf.N_COMPONENTS,
    depth_range=None,
) -> Estimate:
    """The range-parametrised EKF (:func:`depthcore.kalman.range_ekf.posterior`, Peach 1995).

    ``detail`` is its :class:`~depthcore.kalman.range_ekf.GaussianSum`; the estimate's
    mean and covariance are the sum's (law of total variance), so that a study
    scores it, as the other Gaussian filters, by these two moments.
    """
    return _moments_estimate(
        mu,
        prior_mean,
        prior_cov,
        "range-parametrised EKF",
        lambda: range_ekf.posterior(
            mu, rho, prior_mean, prior_cov, process_noise, n_components, depth_range
        ),
    )


def run_inverse_depth_ukf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    sigma_points: ukf.SigmaPoints = ukf.SigmaPoints(),
    allow_behind_camera: bool = True,
) -> Estimate:
    """The UKF in inverse-depth coordinates (:func:`depthcore.kalman.inverse_depth_ukf.estimate`).

    ``detail`` is its mean and covariance in ``(x, y, v)`` at frame ``N``. As
    the UKF's entry, it runs by default even where sigma points lie behind the
    camera (``allow_behind_camera``).
    """
    return _moments_estimate(
        mu,
        prior_mean,
        prior_cov,
        "inverse-depth UKF",
        lambda: inverse_depth_ukf.estimate(
            mu, rho, prior_mean, prior_cov, process_noise, sigma_points, allow_behind_camera
        ),
    )


def run_modified_polar(mu, rho, prior_mean, prior_cov, process_noise: float = 0.0) -> Estimate:
    """The EKF in modified polar coordinates (:func:`depthcore.kalman.modified_polar.estimate`).

    ``detail`` is its mean and covariance in ``(x, y, v)`` at frame ``N``.
    """
    return _moments_estimate(
        mu,
        prior_mean,
        prior_cov,
        "modified-polar EKF",
        lambda: modified_polar.estimate(mu, rho, prior_mean, prior_cov, process_noise),
    )


def _moments_estimate(mu, prior_mean, prior_cov, name: str, run) -> Estimate:
    """The :class:`Estimate` of a filter whose ``run()`` returns its mean and covariance.

    ``run()`` returns an object with ``mean`` (..., 3) and ``cov`` (..., 3, 3)
    at frame ``N``, kept as the estimate's ``detail``; the prior is checked
    first for one track, and the covariance after (:func:`_covariance_form`).
    """
    if _single(mu):
        _prior(prior_mean, prior_cov)
    est = run()
    _covariance_form(est.cov, name)
    return _gaussian_estimate(est.mean, est.cov, est)


def _covariance_form(cov, name: str) -> None:
    """Refuse, naming ``rho``, covariances (..., 3, 3) that rounding left not positive definite.

    The filters that carry a covariance (not its square root) lose its small
    eigenvalues to cancellation when the noise is tiny beside the prior.
    """
    cov = np.asarray(cov, dtype=float)
    smallest = np.linalg.eigvalsh(cov)[..., 0]
    if not np.all(smallest > 0):
        raise ValueError(
            f"rho is too small for the {name}, which carries a covariance: rounding "
            f"left its covariance at frame N not positive definite (eigenvalue "
            f"{float(np.min(smallest)):.3g})"
        )


def run_resample_move(
    mu,
    rho,
    prior_mean,
    prior_cov,
    rng=None,
    n_particles: int = RESAMPLE_MOVE_PARTICLES,
    replicas: int = resample_move.REPLICAS,
    **options,
) -> Estimate:
    """The causal bootstrap filter with resample-move (:mod:`depthcore.particles.resample_move`).

    ``detail`` is its :class:`~depthcore.particles.resample_move.Replicated`:
    ``replicas`` independent filters of ``n_particles`` each, pooled;
    ``options`` are those of :func:`depthcore.particles.resample_move.run`. The moments
    are the pool's; the errors the larger of those of the mean and of the SD
    from the replicas' spread (Student-t widened), NaN where the replicas
    collapsed (``collapsed``, :meth:`~depthcore.particles.resample_move.Replicated.errors`).
    """
    rng = _rng(rng, "resample-move")
    single = _single(mu)
    if single:
        prior = _prior(prior_mean, prior_cov)
        mu = checks.finite_array(mu, "mu")
        prior_mean, prior_cov = prior.mean, prior.cov
        rho = checks.positive_scalar(rho, "rho")
        if mu.ndim != 1:
            raise ValueError(f"mu must have shape (K,), got shape {mu.shape}")
        mu = mu[None]
    r = resample_move.replicated(
        mu, rho, prior_mean, prior_cov, n_particles, rng, replicas, **options
    )
    mean, cov = weighted_mean_and_cov(r.particles, np.exp(r.log_weights))
    m = r.moments()
    errors, collapsed = r.errors()
    depth_error = np.maximum(errors["depth_mean"], errors["depth_sd"])
    velocity_error = np.maximum(errors["velocity_mean"], errors["velocity_sd"])
    if single:
        m = {k: float(v[0]) for k, v in m.items()}
        mean, cov = mean[0], cov[0]
        depth_error, velocity_error = float(depth_error[0]), float(velocity_error[0])
        collapsed = bool(collapsed[0])
    return Estimate(
        m["depth_mean"],
        m["depth_sd"],
        m["velocity_mean"],
        m["velocity_sd"],
        depth_error,
        velocity_error,
        mean,
        cov,
        r,
        collapsed=collapsed,
    )


def run_rbpf(
    mu,
    rho,
    prior_mean,
    prior_cov,
    process_noise: float = 0.0,
    rng=None,
    n_particles: int = RBPF_PARTICLES,
    replicas: int = RBPF_REPLICAS,
    **options,
) -> Estimate:
    """The Rao-Blackwellised particle filter (:mod:`depthcore.particles.rbpf`, textbook 19.5.3).

    ``detail`` is its :class:`~depthcore.particles.rbpf.RBPF`: ``replicas`` independent
    clouds of ``n_particles`` depths, each carrying the Kalman filter of
    ``(x, v)``; ``options`` are those of :func:`depthcore.particles.rbpf.run`. The
    moments are those of the replicas pooled into one mixture
    (:meth:`~depthcore.particles.rbpf.RBPF.state_moments`, the law of total variance
    over the particles' filters); the errors are the larger of the errors of
    the mean and of the SD from the replicas' spread, Student-t widened, NaN
    with one replica or where the replicas collapsed (``collapsed``,
    :meth:`~depthcore.particles.rbpf.RBPF.errors`).
    """
    rng = _rng(rng, "Rao-Blackwellised particle")
    if _single(mu):
        _prior(prior_mean, prior_cov)
    f = rbpf.run(
        mu,
        rho,
        prior_mean,
        prior_cov,
        n_particles,
        rng,
        process_noise=process_noise,
        replicas=replicas,
        **options,
    )
    mean, cov = f.state_moments()
    se, collapsed = f.errors()
    depth_error = np.maximum(se.depth_mean, se.depth_sd)
    velocity_error = np.maximum(se.velocity_mean, se.velocity_sd)
    if _single(mu):
        depth_error, velocity_error = float(depth_error), float(velocity_error)
        collapsed = bool(collapsed)
    e = _gaussian_estimate(mean, cov, f)
    return Estimate(
        e.depth_mean,
        e.depth_sd,
        e.velocity_mean,
        e.velocity_sd,
        depth_error,
        velocity_error,
        e.mean,
        e.cov,
        f,
        collapsed=collapsed,
    )


def _rng(rng, name: str) -> np.random.Generator:
    """``rng`` as a Generator; ``None`` is refused, naming ``rng``."""
    if rng is None:
        raise ValueError(
            f"rng is required to run the {name} filter: pass a "
            "numpy.random.Generator or SeedSequence"
        )
    return checks.generator(rng)


def run_particle(
    mu, rho, prior_mean, prior_cov, rng=None, n_particles: int = PARTICLES, **options
) -> Estimate:
    """The particle filter; ``detail`` is its ParticleResult (one triple) or ParticleBatch.

    ``rng``, a ``numpy.random.Generator`` or a ``SeedSequence`` (or an int
    seed), is required; ``options`` are those of :func:`depthcore.particles.importance.run`.
    The errors are the larger of the delta-method standard errors of the mean
    and of the SD; NaN where the weight sits on fewer than
    ``resampling.MIN_EFFECTIVE_DRAWS`` distinct particles (``collapsed``,
    :meth:`~depthcore.particles.importance.ParticleResult.collapsed`).
    """
    rng = _rng(rng, "particle")
    if _single(mu):
        r = importance.particle_filter(
            mu, rho, _prior(prior_mean, prior_cov), n_particles, rng, **options
        )
        m, se, collapsed = r.moments(), r.standard_errors(), r.collapsed()
        mean, cov = weighted_mean_and_cov(r.particles, r.weights)
        nan = np.nan if collapsed else 0.0
        return Estimate(
            float(m.depth_mean),
            float(m.depth_sd),
            float(m.velocity_mean),
            float(m.velocity_sd),
            float(max(se.depth_mean, se.depth_sd)) + nan,
            float(max(se.velocity_mean, se.velocity_sd)) + nan,
            mean,
            cov,
            r,
            collapsed=collapsed,
        )
    b = importance.run(mu, rho, prior_mean, prior_cov, n_particles, rng, **options)
    m, se, collapsed = b.moments(), b.standard_errors(), b.collapsed()
    mean, cov = weighted_mean_and_cov(b.particles, np.exp(b.log_weights))
    return Estimate(
        m.depth_mean,
        m.depth_sd,
        m.velocity_mean,
        m.velocity_sd,
        np.where(collapsed, np.nan, np.maximum(se.depth_mean, se.depth_sd)),
        np.where(collapsed, np.nan, np.maximum(se.velocity_mean, se.velocity_sd)),
        mean,
        cov,
        b,
        collapsed=collapsed,
    )


def smooth_optimal(mu, rho, prior_mean, prior_cov, process_noise):
    """The exact filter and its fixed-interval smoother: :func:`depthcore.exact.smoother.track`.

    The bearings are added online (:func:`depthcore.exact.posterior.update`); the smoothed
    state is each depth node's Rauch-Tung-Striebel smoother mixed over the
    nodes (textbook 19.2.6, :meth:`depthcore.exact.mixture.Mixture.smoothed`).
    """
    t = bank_track.track(mu, rho, prior_mean, prior_cov, process_noise, lag=mu.size - 1)
    return t.filtered, t.interval, t


def gaussian_smoother(run):
    """The Gaussian filter ``run`` at every frame and the Rauch-Tung-Striebel smoother over it.

    ``run`` is one of this module's Gaussian filters (:func:`run_ekf`,
    :func:`run_ukf`), whose ``detail`` is its
    :class:`~depthcore.problem.gaussian.History`; the smoother takes checked inputs, as
    :func:`depthcore.registry.tracking.track` passes them.

    The motion, Eq. (1) with the process noise on the velocity, is linear
    (``x_{k+1} = F x_k + e``), so every Gaussian filter predicts exactly
    (Eq. (10)): the predicted Gaussian at frame ``k + 1`` is ``F m_k + e``,
    ``F P_k F^T + diag(0, 0, q**2)``, and the backward recursions of textbook
    19.2.6 (:func:`depthcore.kalman.linear.fixed_interval_smoother`) run over the
    filter's own Gaussians: for the EKF this is the extended Kalman smoother
    (textbook 19.3), for the UKF the unscented one.
    """

    def smoother(mu, rho, prior_mean, prior_cov, process_noise):
        h = run(mu, rho, prior_mean, prior_cov, process_noise=process_noise).detail
        means, covs = h.means, h.covs
        predicted = ekf.predict(means[:-1], covs[:-1], process_noise)
        filtered = linear.FilterResult(
            means,
            covs,
            np.concatenate([prior_mean[None], predicted.mean]),
            np.concatenate([prior_cov[None], predicted.cov]),
            np.zeros(means.shape[0]),
        )
        s = linear.fixed_interval_smoother(filtered, model.F)
        return mixture.Smoothed(means, covs), mixture.Smoothed(s.mean, s.cov), h

    return smoother
