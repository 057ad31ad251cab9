"""The iterated and inverse-depth EKFs of a point in 3-D, the 3-D smoothers and track() of pairs.

Each 3-D filter is checked against its plane filter where the height drops out, against an
independent computation (a numerical MAP, linear algebra written out, a dense grid with one
joint Gaussian conditioning per node), and through the registry and track().
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import least_squares

from depthcore.exact import spatial as exact_spatial
from depthcore.kalman import ekf, inverse_depth, iterated, spatial, spatial_inverse
from depthcore.registry.adapters import gaussian_smoother
from depthcore.registry.filters import FILTERS
from depthcore.registry.tracking import track

from helpers import answer_or_one_line

RHO = 0.004
PLANE_MEAN = np.array([0.8, 10.0, 0.1])
PLANE_COV = np.array([[2.0, 0.5, 0.05], [0.5, 6.0, 0.0], [0.05, 0.0, 0.3]])
UNEVEN = np.array([1.0, 0.5, 2.0, -0.5, 1.0, 1.5, -1.0])


def _plane_track(steps, seed=0):
    """Bearings of 8 frames of a point (x, y, v) = (1, 11, 0.3) at frame 1, frame 5 missing."""
    s = np.ones(7) if steps is None else steps
    t = np.concatenate([[0.0], np.cumsum(s)])
    mu = (1.0 + 0.3 * t) / (11.0 + t) + RHO * np.random.default_rng(seed).standard_normal(8)
    mu[4] = np.nan
    return mu, t


def _reduced(mu):
    """Pairs with nu = 0 and a prior whose height is narrow at 0 and uncorrelated with the plane."""
    pairs = np.stack([mu, np.where(np.isnan(mu), np.nan, 0.0)], axis=-1)
    m = np.concatenate([PLANE_MEAN, [0.0, 0.0]])
    P = np.zeros((5, 5))
    P[:3, :3] = PLANE_COV
    P[3, 3], P[4, 4] = 1e-12, 0.5
    return pairs, m, P


def _gap(means, covs, plane_means, plane_covs) -> float:
    """The largest difference of the (x, y, v) moments, relative to each SD (the covariances'
    to the product of the SDs), over every frame."""
    sd = np.sqrt(np.diagonal(plane_covs, axis1=-2, axis2=-1))
    scale = np.maximum(np.abs(plane_means), sd)
    mean_gap = np.max(np.abs(means[..., :3] - plane_means) / scale)
    cov_gap = np.max(np.abs(covs[..., :3, :3] - plane_covs) / (sd[..., :, None] * sd[..., None, :]))
    return float(max(mean_gap, cov_gap))


def _plane(name, mu, q, steps, t):
    """The plane filter's (x, y, v) moments at every frame, (N, 3) and (N, 3, 3)."""
    if name == "iterated":
        h = iterated.run(mu, RHO, PLANE_MEAN, PLANE_COV, process_noise=q, steps=steps)
        return h.means, h.covs
    h = inverse_depth.run(mu, RHO, PLANE_MEAN, PLANE_COV, process_noise=q, steps=steps)
    states = [inverse_depth.to_state(h.means[k], h.covs[k], k + 1, t[k]) for k in range(len(mu))]
    return np.array([s.mean for s in states]), np.array([s.cov for s in states])


def _spatial(name, pairs, m, P, q, steps):
    if name == "iterated":
        return spatial.run(pairs, RHO, m, P, q, steps, filter="iterated")
    return spatial_inverse.run(pairs, RHO, m, P, q, steps)


@pytest.mark.parametrize("q", [0.0, 0.05])
@pytest.mark.parametrize("steps", [None, UNEVEN], ids=["unit", "uneven"])
@pytest.mark.parametrize("name", ["iterated", "inverse_depth"])
def test_each_3d_filter_is_its_plane_filter_where_the_height_drops_out(name, steps, q):
    """Height narrow at 0, nu = 0, no cross terms: the (x, y, v) moments are the plane's at every
    frame (measured: at most 3e-9 relative for the iterated EKF, whose stopping rule sees its
    own rounding, and 5e-14 for the inverse-depth EKF)."""
    mu, t = _plane_track(steps)
    pairs, m, P = _reduced(mu)
    h = _spatial(name, pairs, m, P, q, steps)
    assert _gap(h.means, h.covs, *_plane(name, mu, q, steps, t)) < 1e-6
    assert np.isnan(h.log_predictive[4]) and np.all(np.isfinite(np.delete(h.log_predictive, 4)))


@pytest.mark.parametrize("name", ["iterated", "inverse_depth"])
def test_the_reduction_check_fails_when_it_should(name):
    """The same comparison with the plane filter fed the wrong bearings (nu's, the heights'
    projections, as mu) or the 3-D filter a height of its own is far beyond the tolerance
    (measured: 0.4 to 1.0)."""
    mu, t = _plane_track(None)
    pairs, m, P = _reduced(mu)
    height = pairs.copy()
    height[:, 1] = np.where(np.isnan(mu), np.nan, 0.02)
    plane = _plane(name, mu, 0.0, None, t)
    for wrong in (height, pairs[:, ::-1]):
        h = _spatial(name, wrong, m, P, 0.0, None)
        assert _gap(h.means, h.covs, *plane) > 1e-3


@pytest.mark.parametrize("filter", ["ekf", "ukf"])
def test_the_3d_gaussian_smoothers_reduce_to_the_planes_ekf_smoother(filter):
    """spatial.smoother is the plane's extended Kalman smoother where the height drops out; its
    last frame is the filter's. (The UKF's 5-point-dimension sigma points differ from the
    plane's, so it is checked only for its last frame.)"""
    mu, _ = _plane_track(UNEVEN)
    pairs, m, P = _reduced(mu)
    h, smoothed = spatial.smoother(pairs, RHO, m, P, 0.05, UNEVEN, filter=filter)
    assert_allclose(smoothed.mean[-1], h.means[-1], rtol=1e-14)
    if filter == "ekf":
        plane = gaussian_smoother(ekf.run)(mu, RHO, PLANE_MEAN, PLANE_COV, 0.05, UNEVEN)[1]
        assert _gap(smoothed.mean, smoothed.cov, plane.mean, plane.cov) < 1e-9


def _ekf_far_case():
    """A prediction well away from the pair, so the linearisation matters."""
    m = np.array([1.0, 10.0, 0.2, -0.5, 0.1])
    A = np.array([[1.0, 0.3, 0.0, 0.2, 0.0], [0.0, 1.5, 0.1, 0.0, 0.0], [0.0, 0.0, 0.4, 0.0, 0.1]])
    P = np.diag([1.0, 9.0, 0.2, 1.0, 0.2]) + A.T @ A
    z = np.array([0.25, -0.2])
    return m, P, z, 0.01


def test_the_iterated_update_is_the_map_of_prior_times_likelihood():
    """The fixed point is the minimiser of |x - m|_P**2 + |z - g(x)|**2 / rho**2 found by
    scipy's least squares (measured: 2e-8 SDs apart, scipy's own precision: a Newton step from
    its answer is 2e-8 SDs, from the iterate 3e-10); one iteration is the EKF's update, which
    lies 1.1 SDs from the mode here."""
    m, P, z, rho = _ekf_far_case()
    L_inv = np.linalg.inv(np.linalg.cholesky(P))
    mean, cov, log_p, tail = spatial.iterated_update(m, P, z, rho)

    def residuals(x):
        return np.concatenate([L_inv @ (x - m), (z - spatial.measurement(x)) / rho])

    fit = least_squares(residuals, m, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    sd = np.sqrt(np.diag(cov))
    assert np.max(np.abs(fit.x - mean) / sd) < 1e-7
    ekf_mean, ekf_cov, ekf_log_p, ekf_tail = spatial.ekf_update(m, P, z, rho)
    assert np.max(np.abs(ekf_mean - mean) / sd) > 1.0
    once = spatial.iterated_update(m, P, z, rho, max_iterations=1)
    assert_allclose(once[0], ekf_mean, rtol=1e-13, atol=1e-13)
    assert_allclose(once[1], ekf_cov, rtol=1e-10, atol=1e-13)
    assert_allclose([log_p, tail], [ekf_log_p, ekf_tail], rtol=1e-14)
    # the Joseph covariance at the mode is that of the linearisation there
    H = spatial.jacobian(mean)
    info = np.linalg.inv(P) + H.T @ H / rho**2
    assert_allclose(cov, np.linalg.inv(info), rtol=1e-8, atol=1e-14)


def test_the_inverse_depth_3d_filter_is_its_linear_algebra_written_out():
    """Three frames (steps 1.5 and -0.5, q = 0.1) by hand: the prior's map linearised at its mean,
    prediction, the EKF update on the pair, each frame carried back."""
    rho, q, s = 0.01, 0.1, [1.5, -0.5]
    pairs = np.array([[0.1, 0.05], [0.14, 0.03], [0.16, 0.035]])
    m = np.array([1.0, 9.0, 0.3, 0.4, -0.1])
    P = np.diag([1.0, 4.0, 0.1, 1.0, 0.1]) + 0.05

    def jac(z):  # of (z0, 1, z2, z3, z4) / z1, its own inverse
        u = z[1]
        J = np.diag([1 / u, -1 / u**2, 1 / u, 1 / u, 1 / u])
        J[[0, 2, 3, 4], 1] = -z[[0, 2, 3, 4]] / u**2
        return J

    def carry(z):
        return np.array([z[0], 1.0, z[2], z[3], z[4]]) / z[1]

    J = jac(m)
    z, S = carry(m), J @ P @ J.T
    t, expected = 0.0, []
    for k in range(3):
        if k:
            F = np.eye(5)
            F[0, 2] = F[3, 4] = s[k - 1]
            Q = np.diag([0, 0, 1, 0, 1]) * (z[1] * q) ** 2 * abs(s[k - 1])
            z, S, t = F @ z, F @ S @ F.T + Q, t + s[k - 1]
        D = 1 + t * z[1]
        H = np.array([[1 / D, -t * z[0] / D**2, 0, 0, 0], [0, -t * z[3] / D**2, 0, 1 / D, 0]])
        K = S @ H.T @ np.linalg.inv(H @ S @ H.T + rho**2 * np.eye(2))
        z = z + K @ (pairs[k] - np.array([z[0], z[3]]) / D)
        S = (np.eye(5) - K @ H) @ S
        J = jac(z)
        expected.append((carry(z) + [0, t, 0, 0, 0], J @ S @ J.T))
    h = spatial_inverse.run(pairs, rho, m, P, q, s)
    for k, (mean, cov) in enumerate(expected):
        assert_allclose(h.means[k], mean, rtol=1e-10)
        assert_allclose(h.covs[k], cov, rtol=1e-10, atol=1e-12 * np.max(np.abs(cov)))


def _benign_pairs(n=40, seed=3):
    e = np.arange(n, dtype=float)
    state = np.stack([(1.0 + 0.5 * e) / (10.0 + e), (0.3 - 0.2 * e) / (10.0 + e)], axis=-1)
    return state + 0.002 * np.random.default_rng(seed).standard_normal((n, 2))


MEAN_5 = np.array([0.5, 8.0, 0.0, 0.0, 0.0])
COV_5 = np.diag([4.0, 20.0, 1.0, 4.0, 1.0])


def test_the_registry_runs_the_new_3d_doors_near_the_exact_filter_and_refuses_the_rest():
    """FILTERS[name] with mu (N, 2): within 3 exact SDs of the exact filter in every coordinate
    on a benign 40-frame track (measured: at most 0.33 SDs for the iterated EKF, 0.15 for the
    inverse-depth EKF); a filter with no 3-D form refuses in one line naming mu."""
    pairs = _benign_pairs()
    exact = FILTERS["optimal"](pairs, 0.002, MEAN_5, COV_5)
    sd = np.sqrt(np.diag(exact.cov))
    for name in ("iterated", "inverse_depth"):
        est = FILTERS[name](pairs, 0.002, MEAN_5, COV_5, process_noise=0.0)
        assert est.mean.shape == (5,) and np.all(np.abs(est.mean - exact.mean) < 3 * sd), name
        batch = FILTERS[name](np.stack([pairs, pairs]), 0.002, MEAN_5, COV_5)
        assert_allclose(batch.mean, [est.mean] * 2, rtol=1e-12)
    with pytest.raises(ValueError, match=r"^mu of shape \(40, 2\) holds pairs") as info:
        FILTERS["inverse_depth_ukf"](pairs, 0.002, MEAN_5, COV_5)
    assert "\n" not in str(info.value) and "inverse_depth_ukf" in str(info.value)


def _dense_route(pairs, rho, m, P, q, steps, upto, grid):
    """The state at every frame given the pairs of frames 1 .. upto, on a dense uniform grid of
    y_1: per node the lateral states of all frames stacked, their joint Gaussian given y_1
    conditioned on the pairs (times the depths) in one step, and the nodes mixed by the prior
    times the likelihood. Returns means (N, 5) and covariances (N, 5, 5)."""
    N = len(pairs)
    e = np.concatenate([[0.0], np.cumsum(steps)])
    lat = [0, 2, 3, 4]
    slope = P[lat, 1] / P[1, 1]
    M0 = m[lat] + (grid - m[1])[:, None] * slope  # (J, 4)
    C0 = P[np.ix_(lat, lat)] - np.outer(slope, P[1, lat])
    # U = T w, w = (u_1, e_1 .. e_{N-1}), cov(w) = blockdiag(C0, Q_1 ..)
    T = np.zeros((4 * N, 4 * N))
    T[:4, :4] = np.eye(4)
    W = np.zeros((4 * N, 4 * N))
    W[:4, :4] = C0
    for k in range(1, N):
        F = np.eye(4)
        F[0, 1] = F[2, 3] = steps[k - 1]
        T[4 * k : 4 * k + 4] = F @ T[4 * k - 4 : 4 * k]
        T[4 * k : 4 * k + 4, 4 * k : 4 * k + 4] += np.eye(4)
        W[4 * k + 1, 4 * k + 1] = W[4 * k + 3, 4 * k + 3] = q**2 * abs(steps[k - 1])
    mean_U = M0 @ T[:, :4].T  # (J, 4N)
    Sigma = T @ W @ T.T
    seen = [k for k in range(upto) if not np.isnan(pairs[k, 0])]
    rows = [4 * k + i for k in seen for i in (0, 2)]
    y = grid[:, None] + e[seen]  # (J, n) the depths of the seen frames
    z = (pairs[seen] * y[..., None]).reshape(len(grid), -1)
    R = np.repeat((rho * y) ** 2, 2, axis=1)
    S = Sigma[np.ix_(rows, rows)] + R[:, :, None] * np.eye(len(rows))
    r = z - mean_U[:, rows]
    K = np.linalg.solve(S, Sigma[rows][None]).transpose(0, 2, 1)  # (J, 4N, n)
    post_mean = mean_U + np.einsum("jab,jb->ja", K, r)
    log_lik = -0.5 * (
        np.linalg.slogdet(S)[1] + np.einsum("ja,ja->j", r, np.linalg.solve(S, r[..., None])[..., 0])
    ) + 2 * np.sum(np.log(y), axis=1)
    a = -0.5 * (grid - m[1]) ** 2 / P[1, 1] + log_lik
    p = np.exp(a - a.max())
    p /= p.sum()
    means, covs = np.empty((N, 5)), np.empty((N, 5, 5))
    for k in range(N):
        states = np.zeros((len(grid), 5))
        states[:, lat] = post_mean[:, 4 * k : 4 * k + 4]
        states[:, 1] = grid + e[k]
        b = slice(4 * k, 4 * k + 4)
        cov = np.zeros((len(grid), 5, 5))
        cov[:, np.array(lat)[:, None], lat] = Sigma[b, b] - K[:, b] @ Sigma[rows][:, b]
        means[k] = p @ states
        d = states - means[k]
        covs[k] = np.einsum("j,jab->ab", p, cov + d[:, :, None] * d[:, None, :])
    return means, covs


@pytest.mark.parametrize("q", [0.0, 0.1])
def test_the_exact_3d_smoother_is_a_dense_grid_of_joint_gaussian_conditionings(q):
    """Five frames (a gap, uneven signed steps): each frame's filtered and smoothed moments of the
    exact track equal the dense-grid route's to 1e-8 of an SD (measured: 1e-13); the last
    frame's smoothed state is its filtered one."""
    steps = np.array([1.0, 0.5, -0.7, 1.2])
    pairs = np.array([[0.1, 0.05], [0.16, 0.03], [np.nan, np.nan], [0.2, 0.02], [0.25, 0.012]])
    m = np.array([1.0, 6.0, 0.3, 0.4, -0.1])
    P = np.diag([1.0, 4.0, 0.5, 1.0, 0.3])
    P[0, 1] = P[1, 0] = 0.4
    P[2, 4] = P[4, 2] = 0.1
    rho = 0.01
    t = exact_spatial.track(pairs, rho, m, P, q, steps)
    assert_allclose(t.smoothed.mean[-1], t.filtered.mean[-1], rtol=0, atol=0)
    assert_allclose(t.smoothed.cov[-1], t.filtered.cov[-1], rtol=1e-13, atol=1e-15)
    sd = np.sqrt(np.diagonal(t.filtered.cov, axis1=1, axis2=2))
    # from the floor, 0, where the integrand vanishes as y**2 (the pair's Jacobian), so the
    # trapezoid rule's error is of order h**4; above 60 it is below 1e-100 of its top
    grid = np.linspace(0.0, 60.0, 30001)[1:]
    means, covs = _dense_route(pairs, rho, m, P, q, steps, len(pairs), grid)
    smooth_sd = np.sqrt(np.diagonal(t.smoothed.cov, axis1=1, axis2=2))
    assert np.max(np.abs(means - t.smoothed.mean) / smooth_sd) < 1e-8
    dense_sd = np.sqrt(np.diagonal(covs, axis1=1, axis2=2))
    assert np.max(np.abs(dense_sd - smooth_sd) / smooth_sd) < 1e-8
    for k in range(len(pairs)):
        means, covs = _dense_route(pairs, rho, m, P, q, steps, k + 1, grid)
        assert np.max(np.abs(means[k] - t.filtered.mean[k]) / sd[k]) < 1e-8, k
        assert np.max(np.abs(np.sqrt(np.diag(covs[k])) - sd[k]) / sd[k]) < 1e-8, k


def test_track_of_pairs_gives_every_frame_filtered_and_smoothed_by_the_exact_and_gaussian_filters():
    """track() of mu (N, 2): the exact filter's last frame is the 3-D posterior's; the EKF's
    smoothed state is spatial.smoother's; a gate and a prior of the plane are refused by name."""
    pairs = _benign_pairs(12)
    pairs[5] = np.nan
    t = track(pairs, 0.002, process_noise=0.01)
    post = exact_spatial.posterior(pairs, 0.002, t.prior.mean, t.prior.cov, 0.01)
    assert t.filtered.mean.shape == (12, 5) and t.detail.placements >= 1
    sd = np.sqrt(np.diag(post.cov))
    assert np.max(np.abs(t.filtered.mean[-1] - post.mean) / sd) < 1e-8
    assert t.smoothed.depth_sd[0] < t.filtered.depth_sd[0]
    e = track(pairs, 0.002, process_noise=0.01, filter="ekf")
    h, s = spatial.smoother(pairs, 0.002, t.prior.mean, t.prior.cov, 0.01)
    assert_allclose(e.smoothed.mean, s.mean, rtol=1e-14)
    for kwargs, words in (
        ({"gate": 2.0}, "^gate must be"),
        ({"prior": _plane_prior()}, "^prior must have a mean"),
        ({"filter": "iterated"}, "^filter must be one of"),
    ):
        with pytest.raises(ValueError, match=words) as info:
            track(pairs, 0.002, **kwargs)
        assert "\n" not in str(info.value)


def _plane_prior():
    from depthcore.problem.gaussian import Gaussian

    return Gaussian(PLANE_MEAN, PLANE_COV)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"prior_mean": np.full(5, 1e300)},
        {"process_noise": 1e300},
        {"steps": np.full(11, 1e300)},
        {"mu": _benign_pairs(12) * 1e300},
        {"rho": 1e-300},
    ],
    ids=["prior", "noise", "steps", "pairs", "rho"],
)
@pytest.mark.parametrize("door", ["iterated", "inverse_depth", "exact_track", "ekf_smoother"])
def test_extreme_values_get_an_answer_or_one_line_and_no_warning(kwargs, door):
    args = {"mu": _benign_pairs(12), "rho": 0.002, "prior_mean": MEAN_5, "prior_cov": COV_5}
    args.update(kwargs)
    run = {
        "iterated": lambda **a: spatial.run(**a, filter="iterated"),
        "inverse_depth": spatial_inverse.run,
        "exact_track": lambda **a: exact_spatial.track(**a).smoothed,
        "ekf_smoother": lambda **a: spatial.smoother(**a)[1],
    }[door]
    out = answer_or_one_line(run, **args)
    assert out is None or np.all(np.isfinite(out.mean))


def test_the_command_line_smooths_pairs_by_the_exact_3d_smoother(tmp_path, capsys):
    """estimate --smooth on a file of pairs: the smoothed depth and lateral position at every
    frame are depthcore.exact.spatial.track's; the table shows them too."""
    from helpers import cli_json, run_cli

    pairs = _benign_pairs(8)
    pairs[3] = np.nan
    path = tmp_path / "pairs.csv"
    rows = [",\n" if np.isnan(m) else f"{m!r},{n!r}\n" for m, n in pairs.tolist()]
    path.write_text("mu,nu\n" + "".join(rows), encoding="utf-8")
    prior = ["--prior-mean", "0.5", "8", "0", "0", "0", "--prior-cov", "4"]
    argv = ["estimate", "--mu-file", str(path), "--rho", "0.002", *prior, "--smooth"]
    out = cli_json(argv, capsys)
    t = exact_spatial.track(pairs, 0.002, MEAN_5, 4.0 * np.eye(5))
    assert_allclose(out["smoothed"]["depth_mean"], t.smoothed.depth_mean, rtol=1e-14)
    assert_allclose(out["smoothed"]["lateral_sd"], t.smoothed.lateral_sd, rtol=1e-14)
    assert out["smoothed"]["frame"] == list(range(1, 9))
    status, text, err = run_cli(argv, capsys)
    assert status == 0 and err == "" and "smoothed" in text


def test_a_noise_tiny_beside_the_prior_gets_an_answer_or_one_line_from_every_3d_door():
    """rho = 1e-9 on four pairs, one far out: the EKF's Joseph-form covariance stays positive
    (P - K S K^T lost it to rounding, a negative variance); the others answer or refuse."""
    from depthcore.registry import track_runs

    pairs = np.array([[0.0027, 1e-300], [0.2875, 0.0], [0.3057, 0.0], [5.0187, -1.0]])
    prior = track_runs.start_prior(pairs, None, (3.0, 2.0))
    answered = []
    for name in track_runs.spatial_names():
        est = answer_or_one_line(
            FILTERS[name], mu=pairs, rho=1e-9, prior_mean=prior.mean, prior_cov=prior.cov
        )
        if est is None:
            continue
        assert np.all(np.diagonal(est.cov) >= 0) and est.depth_sd > 0
        answered.append(name)
    assert "ekf" in answered
