"""The EKF and the UKF for a point in 3-D (``depthcore.kalman.spatial``), independently checked."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from depthcore.exact import spatial as exact_spatial
from depthcore.kalman import ekf, spatial

from helpers import answer_or_one_line

MU = np.array([0.06, 0.055, np.nan, 0.048, 0.047, 0.04])
NU = np.array([0.02, 0.025, np.nan, 0.03, 0.031, 0.034])
PAIRS = np.stack([MU, NU], axis=-1)
RHO = np.array([0.01, 0.02, np.nan, 0.01, 0.015, 0.01])
STEPS = np.array([1.0, 0.5, 2.0, 1.0, 1.5])
PRIOR_MEAN = np.array([0.5, 8.0, 0.2, 0.1, 0.0])
PRIOR_COV = np.diag([1.0, 4.0, 0.3, 1.0, 0.3])


def by_hand(pairs, rho, m, P, q, steps):
    """The EKF written out frame by frame with explicit matrices (Eqs. (10)-(12), twice)."""
    m, P = np.array(m, float), np.array(P, float)
    for k in range(len(pairs)):
        if k:
            s = steps[k - 1]
            F = np.eye(5)
            F[0, 2] = F[3, 4] = s
            m = F @ m + np.array([0.0, s, 0.0, 0.0, 0.0])
            P = F @ P @ F.T + np.diag([0.0, 0.0, q * q * abs(s), 0.0, q * q * abs(s)])
        if np.isnan(pairs[k, 0]):
            continue
        x, y, h = m[0], m[1], m[3]
        H = np.array([[1 / y, -x / y**2, 0, 0, 0], [0, -h / y**2, 0, 1 / y, 0]])
        S = H @ P @ H.T + rho[k] ** 2 * np.eye(2)
        K = P @ H.T @ np.linalg.inv(S)
        m = m + K @ (pairs[k] - np.array([x / y, h / y]))
        P = (np.eye(5) - K @ H) @ P
    return m, P


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["away", "towards"])
def test_the_3d_ekf_is_the_ekf_written_out(sign):
    m0 = PRIOR_MEAN + [0.0, 10.0 if sign < 0 else 0.0, 0.0, 0.0, 0.0]
    h = spatial.run(PAIRS, RHO, m0, PRIOR_COV, 0.05, steps=sign * STEPS)
    m, P = by_hand(PAIRS, RHO, m0, PRIOR_COV, 0.05, sign * STEPS)
    assert_allclose(h.mean, m, rtol=1e-9)
    assert_allclose(h.cov, P, rtol=1e-7, atol=1e-14)


def test_a_height_known_to_be_zero_gives_the_planes_ekf():
    m0 = np.array([0.5, 8.0, 0.2, 0.0, 0.0])
    P0 = np.diag([1.0, 4.0, 0.3, 1e-24, 1e-24])
    flat = np.stack([MU, np.where(np.isnan(MU), np.nan, 0.0)], axis=-1)
    h = spatial.run(flat, RHO, m0, P0, steps=STEPS)
    plane = ekf.run(MU, RHO, m0[:3], P0[:3, :3], steps=STEPS)
    assert_allclose(h.mean[:3], plane.means[-1], rtol=1e-10)
    assert_allclose(h.cov[:3, :3], plane.covs[-1], rtol=1e-8, atol=1e-16)


def test_the_ukf_is_the_ekf_where_the_pair_is_nearly_linear():
    """A prior a millionth as wide: the pair is linear across the sigma points to 1e-6."""
    P = PRIOR_COV * 1e-12
    a = spatial.run(PAIRS, RHO, PRIOR_MEAN, P, filter="ukf", steps=STEPS)
    b = spatial.run(PAIRS, RHO, PRIOR_MEAN, P, filter="ekf", steps=STEPS)
    assert_allclose(a.mean, b.mean, rtol=1e-9)
    assert_allclose(a.cov, b.cov, rtol=1e-5, atol=1e-9 * np.max(np.diag(b.cov)))


@pytest.mark.parametrize("name", ["ekf", "ukf"])
def test_the_gaussian_filters_end_near_the_exact_answer_on_a_clean_3d_track(name):
    """A 40-frame 3-D track with small noise: within 3 exact SDs of the exact filter."""
    rng = np.random.default_rng(3)
    k = np.arange(40.0)
    x, y, h = 1.0 + 0.3 * k, 12.0 + k, -0.5 + 0.1 * k
    pairs = np.stack([x / y, h / y], axis=-1) + 0.002 * rng.standard_normal((40, 2))
    m0 = np.array([0.0, 10.0, 0.0, 0.0, 0.0])
    P0 = np.diag([4.0, 16.0, 1.0, 4.0, 1.0])
    exact = exact_spatial.posterior(pairs, 0.002, m0, P0)
    g = spatial.run(pairs, 0.002, m0, P0, filter=name)
    sd = np.sqrt(np.diag(exact.cov))
    assert np.all(np.abs(g.mean - exact.mean) < 3 * sd)
    assert abs(exact.mean[1] - y[-1]) < 4 * sd[1]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"filter": "pf"}, "^filter must be one of"),
        ({"prior_mean": PRIOR_MEAN[:3]}, "^prior_mean and prior_cov must have shapes"),
        ({"prior_mean": [0.0, -50.0, 0.0, 0.0, 0.0]}, "^mu: the EKF's prediction puts the point"),
        ({"mu": MU}, r"^mu must have shape \(N, 2\)"),
    ],
)
def test_refusals_name_the_argument_in_one_line(kwargs, message):
    args = {"mu": PAIRS, "rho": RHO, "prior_mean": PRIOR_MEAN, "prior_cov": PRIOR_COV}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message) as info:
        spatial.run(**args)
    assert "\n" not in str(info.value)


def test_the_registry_takes_pairs_in_the_filters_with_a_3d_form():
    """mu of shape (N, 2) selects the 3-D door of optimal, ekf and ukf; the others refuse it."""
    from depthcore.registry.filters import ALL_NAMES, FILTERS

    est = FILTERS["optimal"](PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
    exact = exact_spatial.posterior(PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
    assert est.mean.shape == (5,) and est.depth_mean == exact.mean[1]
    assert est.depth_error == exact.error[1]
    batch = np.stack([PAIRS, PAIRS])
    for name in ("ekf", "ukf"):
        one = FILTERS[name](PAIRS, 0.01, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
        two = FILTERS[name](batch, 0.01, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
        assert_allclose(two.depth_mean, [one.depth_mean] * 2, rtol=1e-12)
    for name in ALL_NAMES:
        if FILTERS[name].spatial is None:
            with pytest.raises(ValueError, match=r"^mu of shape \(6, 2\) holds pairs"):
                FILTERS[name](PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
    with pytest.raises(ValueError, match="^gate: the filters of a point in 3-D have no gate"):
        FILTERS["ekf"](PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS, gate=1e-3)


@pytest.mark.parametrize("name", ["ekf", "ukf", "optimal"])
def test_the_online_filters_take_pairs_when_the_prior_is_in_3d(name):
    """A prior of five coordinates: each update a pair; the EKF and UKF online are their batch
    3-D doors frame by frame, the exact one its batch 3-D filter; the Gaussian filters' gate
    is the pair's exact tail exp(-d**2 / 2)."""
    from depthcore.registry import online

    f = online.start(name, PRIOR_MEAN, PRIOR_COV, rho=0.01)
    for k in range(len(PAIRS)):
        rho = None if np.isnan(RHO[k]) else RHO[k]
        est = f.update(PAIRS[k], rho=rho, step=1.0 if k == 0 else STEPS[k - 1])
    if name == "optimal":
        batch = exact_spatial.posterior(PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS)
        assert_allclose(est.mean, batch.mean, rtol=1e-8)
        return
    batch = spatial.run(PAIRS, RHO, PRIOR_MEAN, PRIOR_COV, steps=STEPS, filter=name)
    assert_allclose(est.mean, batch.mean, rtol=1e-10)
    assert_allclose(est.log_predictive, batch.log_predictive[-1], rtol=1e-10)
    # a pair 4 predictive SDs off along one axis: tail exp(-8); a gate at 1e-3 skips it
    g = online.start(name, PRIOR_MEAN, PRIOR_COV, rho=0.01, gate=1e-3)
    first = g.update(PAIRS[0])
    assert 0.0 < first.tail <= 1.0 and not first.gated
    far = g.update(PAIRS[1] + [0.5, 0.0], step=STEPS[0])
    assert far.gated and far.tail < 1e-3


def test_track_filters_and_smooths_pairs_and_its_gate_skips_an_outlying_pair():
    """track() of pairs: the state (x, y, v, h, w) at every frame (tests/test_spatial_filters.py
    checks the numbers); with a gate, each filter's online tail of each pair decides, a
    skipped pair is a missing one, and without the outlier the gate skips nothing."""
    from depthcore.registry.track_runs import Prior
    from depthcore.registry.tracking import track

    t = track(PAIRS, 0.01, steps=STEPS)
    assert t.filtered.mean.shape == t.smoothed.mean.shape == (len(PAIRS), 5)
    assert t.updates is None
    bad = PAIRS.copy()
    bad[4] += [0.3, -0.3]  # some 20 SDs off
    prior = Prior(PRIOR_MEAN, PRIOR_COV)
    for name in ("optimal", "ekf", "ukf"):
        clean = track(PAIRS, 0.01, prior, steps=STEPS, filter=name, gate=1e-3)
        assert not np.any(clean.updates.gated)
        assert np.all(clean.updates.tail[~np.isnan(MU)] > 1e-3)
        gated = track(bad, 0.01, prior, steps=STEPS, filter=name, gate=1e-3)
        assert gated.updates.gated.tolist() == [False] * 4 + [True, False]
        dropped = PAIRS.copy()
        dropped[4] = np.nan
        without = track(dropped, 0.01, prior, steps=STEPS, filter=name)
        assert_allclose(gated.smoothed.mean, without.smoothed.mean, rtol=1e-12)
        assert_allclose(gated.filtered.cov, without.filtered.cov, rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"prior_mean": [1e300, 1e300, 1e300, 1e300, 1e300]},
        {"process_noise": 1e300},
        {"steps": np.full(5, 1e300)},
        {"mu": PAIRS * 1e300},
    ],
    ids=["prior", "noise", "steps", "pairs"],
)
@pytest.mark.parametrize("door", ["exact", "ekf", "ukf"])
def test_extreme_values_get_an_answer_or_one_line_and_no_warning(kwargs, door):
    args = {"mu": PAIRS, "rho": 0.01, "prior_mean": PRIOR_MEAN, "prior_cov": PRIOR_COV}
    args.update(kwargs)
    run = {
        "exact": exact_spatial.posterior,
        "ekf": spatial.run,
        "ukf": lambda **a: spatial.run(**a, filter="ukf"),
    }[door]
    out = answer_or_one_line(run, **args)
    assert out is None or np.all(np.isfinite(out.mean))
