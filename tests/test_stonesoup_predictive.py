"""The exact filter's predictive moments (Online.predictive_moments) and Stone Soup's
measurement prediction of the exact updater: the mean, covariance and cross-covariance of
the exact predictive mixture against a dense grid, Monte Carlo, and the old linearised
summary they replace."""

from __future__ import annotations

import copy
import datetime

import numpy as np
import pytest

pytest.importorskip("stonesoup")

from stonesoup.types.state import GaussianState  # noqa: E402
from stonesoup.updater.kalman import ExtendedKalmanUpdater  # noqa: E402

from depthcore.exact import online  # noqa: E402
from depthcore.problem.scenarios import SCENARIOS  # noqa: E402
from depthcore.stonesoup import exact, models, tracks  # noqa: E402

FIG2 = SCENARIOS["fig2"]
SECOND = datetime.timedelta(seconds=1)
PRIOR_MEAN_3D = np.array([0.5, 8.0, 0.2, 0.1, 0.0])
PRIOR_COV_3D = np.diag([1.0, 4.0, 0.3, 1.0, 0.3])
PAIRS = np.array([[0.11, -0.04], [0.12, -0.03], [0.125, -0.025]])


def fig2_prediction():
    """Figure 2's exact filter after its three bearings, predicted to frame 4."""
    frames = tracks.detections(FIG2.mu, FIG2.rho)
    predictor = exact.ExactPredictor(models.DepthStep(speed=1.0))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[FIG2.rho**2]]))
    start = exact.ExactState(FIG2.prior.mean, FIG2.prior.cov, timestamp=frames[0].timestamp)
    last = tracks.run(predictor, updater, start, frames)[-1]
    return predictor.predict(last, timestamp=last.timestamp + SECOND), updater


def nodes_moved(f, step):
    """The node mixture after the step: weights (J,), the nodes' observed means, covariances,
    states and cross-covariances (the filter moved through a missing frame, on a copy)."""
    g = copy.copy(f)
    g.update(np.full(2, np.nan) if f.model.dim == 5 else np.nan, step=step)
    nodes = g._nodes
    a = nodes.log_p + nodes.log_w
    p = np.exp(a - a.max())
    return (p / p.sum(), *g.model.observed(nodes.lateral, nodes.y + g.travelled, f.rho**2))


def test_the_bearings_moments_equal_a_dense_grid_of_the_exact_predictive():
    # the predictive density at each bearing of a grid, and the state's mean given it, are
    # the exact filter's own update (a copy per bearing): the moments by the trapezoid rule
    prediction, updater = fig2_prediction()
    measured = updater.predict_measurement(prediction)
    f, s = prediction.filter, prediction.step
    mean, sd = float(measured.state_vector[0, 0]), float(np.sqrt(measured.covar[0, 0]))
    grid = mean + sd * np.linspace(-14.0, 14.0, 1401)
    density, states = np.empty(grid.size), np.empty((grid.size, 3))
    for k, mu in enumerate(grid):
        est = copy.copy(f).update(mu, step=s)
        density[k], states[k] = np.exp(est.log_predictive), est.mean
    h = grid[1] - grid[0]
    assert h * density.sum() == pytest.approx(1.0, abs=1e-9)
    m = h * density @ grid
    var = h * density @ (grid - m) ** 2
    cross = h * (density * (grid - m)) @ (states - h * density @ states)
    assert abs(m - mean) <= 1e-8 * sd
    assert var == pytest.approx(float(measured.covar[0, 0]), rel=1e-8)
    np.testing.assert_allclose(cross, np.asarray(measured.cross_covar)[:, 0], rtol=1e-7, atol=0)
    # the old summary, the bearing linearised at the exact predicted moments (Stone Soup's
    # EKF), is another number by far more than the tolerance
    gaussian = GaussianState(prediction.state_vector, prediction.covar)
    bearing = models.TangentBearing(noise_covar=[[FIG2.rho**2]])
    old = ExtendedKalmanUpdater(bearing).predict_measurement(gaussian)
    assert abs(float(old.state_vector[0, 0]) - mean) > 1e5 * 1e-8 * sd
    quiet = updater.predict_measurement(prediction, measurement_noise=False)
    assert float(measured.covar[0, 0] - quiet.covar[0, 0]) == pytest.approx(FIG2.rho**2)


def test_the_moments_equal_monte_carlo_of_the_mixture_for_a_bearing_and_a_pair():
    rng = np.random.default_rng(20261206)
    n = 10**6
    plane = online.Online(FIG2.prior.mean, FIG2.prior.cov, FIG2.rho)
    space = online.Online(PRIOR_MEAN_3D, PRIOR_COV_3D, 0.01)
    for mu in FIG2.mu:
        plane.update(mu)
    for pair in PAIRS:
        space.update(pair)
    for f in (plane, space):
        moments = f.predictive_moments(step=1.5)
        p, means, covs, states, _ = nodes_moved(f, 1.5)
        j = rng.choice(p.size, n, p=p)
        draws = means[j] + np.einsum(
            "nkl,nl->nk", np.linalg.cholesky(covs)[j], rng.standard_normal(means[j].shape)
        )
        se = draws.std(axis=0) / np.sqrt(n)
        assert np.all(np.abs(draws.mean(axis=0) - moments.mean) <= 4 * se)
        centred = draws - draws.mean(axis=0)
        sample = centred.T @ centred / n
        fourth = np.mean((centred[:, :, None] * centred[:, None, :]) ** 2, axis=0)
        se_cov = np.sqrt((fourth - sample**2) / n)
        assert np.all(np.abs(sample - moments.cov) <= 4 * se_cov)
        s = states[j] - states[j].mean(axis=0)  # the node's state mean: Cov[E[state | node], obs]
        within = np.einsum("j,jkl->kl", p, nodes_moved(f, 1.5)[4])
        cross = s.T @ centred / n + within
        se_x = np.sqrt(np.var(s[:, :, None] * centred[:, None, :], axis=0) / n)
        assert np.all(np.abs(cross - moments.cross) <= 4 * se_x + 1e-12)


def test_a_pairs_moments_equal_a_dense_grid_of_the_node_mixture():
    f = online.Online(PRIOR_MEAN_3D, PRIOR_COV_3D, 0.01)
    for pair in PAIRS:
        f.update(pair)
    moments = f.predictive_moments(step=1.0)
    p, means, covs, _, _ = nodes_moved(f, 1.0)
    sd = np.sqrt(np.diag(moments.cov))
    axes = [moments.mean[i] + sd[i] * np.linspace(-14, 14, 561) for i in (0, 1)]
    Z = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    r = Z[..., None, :] - means
    P = np.linalg.inv(covs)
    q = np.einsum("...jk,jkl,...jl->...j", r, P, r)
    dens = np.exp(-0.5 * q) / (2 * np.pi * np.sqrt(np.linalg.det(covs))) @ p
    cell = (axes[0][1] - axes[0][0]) * (axes[1][1] - axes[1][0])
    assert cell * dens.sum() == pytest.approx(1.0, abs=1e-9)
    m = cell * np.einsum("ab,abk->k", dens, Z)
    d = Z - m
    cov = cell * np.einsum("ab,abk,abl->kl", dens, d, d)
    assert np.all(np.abs(m - moments.mean) <= 1e-8 * sd)
    np.testing.assert_allclose(cov, moments.cov, rtol=0, atol=1e-8 * np.outer(sd, sd).max())


def test_a_wide_prior_frame_and_the_filter_left_unchanged():
    # from a Gaussian prediction the first frame's exact predictive is far from the
    # linearised bearing: heavy in the tails where the depth may be small
    prior = GaussianState([0.2, 5.0, 0.1], np.diag([4.0, 4.0, 0.25]))
    updater = exact.ExactUpdater(models.TangentBearing(noise_covar=[[0.01**2]]))
    measured = updater.predict_measurement(prior)
    old = ExtendedKalmanUpdater(updater.measurement_model).predict_measurement(prior)
    assert float(measured.covar[0, 0]) > 2 * float(old.covar[0, 0])
    f = updater.start(prior, 0.01)
    assert float(measured.state_vector[0, 0]) == f.predictive_moments().mean[0]
    g = copy.copy(f)
    g.update(0.05)
    before = (g.frame, g.travelled, g.node_count, g.current, g._nodes)
    g.predictive_moments(step=-2.0)
    assert (g.frame, g.travelled, g.node_count, g.current, g._nodes) == before
    with pytest.raises(ValueError, match="^rho must be"):
        g.predictive_moments(rho=-1.0)
    with pytest.raises(ValueError, match="^step: the first frame"):
        f.predictive_moments(step=2.0)
