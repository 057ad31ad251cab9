"""The Cramér-Rao bound on tracks as they come (gaps, noise per frame, uneven steps), against
independent routes, and every function of the bound fuzzed with odd inputs: an answer with
finite numbers or a one-line refusal naming the argument, never a warning."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from depthcore import SCENARIOS
from depthcore.analysis import bound
from depthcore.problem import model
from depthcore.problem.checks import MAX_FRAMES

FIG2 = SCENARIOS["fig2"]
RHO = FIG2.rho
P = np.diag([4.0, 9.0, 1.0])


def _moving(x1, steps, accelerations=None):
    """States of the motion with a step, by hand: y += s, x += s v, v += a."""
    x, y, v = (float(c) for c in x1)
    a = np.zeros(len(steps)) if accelerations is None else accelerations
    out = [[x, y, v]]
    for s, a_k in zip(steps, a, strict=True):
        x, y, v = x + s * v, y + s, v + a_k
        out.append([x, y, v])
    return np.array(out)


def _back(d):
    """The map from the state at a frame to the state a depth ``d`` earlier (q = 0), by hand."""
    return np.array([[1.0, 0.0, -d], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def _batch_bound(states, rho, present, prior_cov, k):
    """q = 0: the information about s_k of the bearings of frames 1..k, each mapped to frame k,
    plus the prior's: ``sum_j T_j^T h_j h_j^T T_j / rho_j**2 + T_1^T P^{-1} T_1``."""
    x, y = states[:, 0], states[:, 1]
    J = np.zeros((3, 3))
    for j in range(k):
        if present[j]:
            g = np.array([1 / y[j], -x[j] / y[j] ** 2, 0.0]) @ _back(y[k - 1] - y[j])
            J += np.outer(g, g) / rho[j] ** 2
    if prior_cov is not None:
        T = _back(y[k - 1] - y[0])
        J += T.T @ np.linalg.inv(prior_cov) @ T
    return np.linalg.inv(J)


TRACK_STEPS = np.array([0.5, 1.7, 1.0, 0.25, 3.0, 0.8, 1.2])
TRACK_RHO = RHO * np.array([1.0, 2.5, 0.7, 1.0, 4.0, 1.3, 0.9, 2.0])
TRACK_PRESENT = np.array([True, True, False, True, True, False, True, True])


#: A camera that approaches: the same steps towards the point, from 12 units deeper.
APPROACH = (np.array([0.0, 12.0, 0.0]), -TRACK_STEPS)


@pytest.mark.parametrize("prior_cov", [P, None])
@pytest.mark.parametrize(
    ("x1", "steps"),
    [
        (model.G(FIG2.c, -2), TRACK_STEPS),
        (np.array([0.5, 3.0, -0.2]), TRACK_STEPS),
        (np.array([0.5, 3.0, -0.2]) + APPROACH[0], APPROACH[1]),
    ],
    ids=["fig2", "near", "approaching"],
)
def test_gaps_noise_per_frame_and_uneven_steps_are_the_batch_information(x1, steps, prior_cov):
    """q = 0: Eq. (21) with F_k at each step, I_k = 0 at a gap and rho_k per frame, against the
    batch information of the present bearings about s_k, by hand, at every determined frame;
    receding and approaching."""
    states = _moving(x1, steps)
    rho = np.where(TRACK_PRESENT, TRACK_RHO, np.nan)  # NaN at a gap is never read
    B = bound.conditional_bound(states, rho, prior_cov, 0.0, TRACK_PRESENT)
    first = 1 if prior_cov is not None else 4  # the fourth frame has the third bearing
    assert np.all(np.isnan(B[: first - 1]))
    for k in range(first, len(states) + 1):
        expected = _batch_bound(states, TRACK_RHO, TRACK_PRESENT, prior_cov, k)
        assert_allclose(B[k - 1], expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max())


def test_a_batch_of_tracks_with_their_own_steps_is_each_track_alone():
    tracks = np.stack(
        [_moving(model.G(FIG2.c, -2), TRACK_STEPS), _moving([0.5, 3.0, -0.2], TRACK_STEPS[::-1])]
    )
    present = np.stack([TRACK_PRESENT, np.ones(8, bool)])
    B = bound.conditional_bound(tracks, TRACK_RHO, P, 0.01, present)
    for i in range(2):
        alone = bound.conditional_bound(tracks[i], TRACK_RHO, P, 0.01, present[i])
        assert_allclose(B[i], alone, rtol=1e-13, atol=0)


def _stacked_bound(states, rho, present, prior_cov, q):
    """q > 0 by brute force: the stacked states z = (s_1 .. s_N) = A xi + c with xi = (s_1,
    w_1 .. w_{N-1}), w_k ~ N(0, q**2 s_k u u^T); the prior covariance A C A^T of z, the
    bearings' Jacobian H (h_k^T / rho_k at frame k, present frames only), and the posterior
    covariance Sigma - Sigma H^T (H Sigma H^T + I)^{-1} H Sigma, whose last block is the bound."""
    n = len(states)
    steps = np.diff(states[:, 1])
    A = np.zeros((3 * n, 3 * n))
    for k in range(n):  # s_k = F_{k-1} .. F_1 s_1 + sum_j F_{k-1} .. F_{j+1} w_j
        for j in range(k + 1):  # block j: s_1 (j = 0) or w_j
            A[3 * k : 3 * k + 3, 3 * j : 3 * j + 3] = _back(-np.sum(steps[j:k]))
    C = np.zeros((3 * n, 3 * n))
    C[:3, :3] = prior_cov
    for j in range(1, n):
        C[3 * j + 2, 3 * j + 2] = q**2 * abs(steps[j - 1])
    Sigma = A @ C @ A.T
    rows = []
    for k in np.flatnonzero(present):
        x, y = states[k, 0], states[k, 1]
        row = np.zeros(3 * n)
        row[3 * k : 3 * k + 2] = [1 / y, -x / y**2]
        rows.append(row / rho[k])
    H = np.array(rows)
    S = H @ Sigma @ H.T + np.eye(len(H))
    post = Sigma - Sigma @ H.T @ np.linalg.solve(S, H @ Sigma)
    return post[-3:, -3:]


@pytest.mark.parametrize("approaching", [False, True])
@pytest.mark.parametrize("q", [0.01, 0.3])
def test_process_noise_over_uneven_steps_is_the_stacked_linear_gaussian_bound(q, approaching):
    """q > 0: the recursion's bound on s_N, with the velocity's variance q**2 |s_k| over each
    step, a gap and rho per frame, against the brute-force marginal of the stacked states;
    receding and approaching."""
    rng = np.random.default_rng(5)
    steps = -TRACK_STEPS if approaching else TRACK_STEPS
    a = q * np.sqrt(TRACK_STEPS) * rng.standard_normal(len(TRACK_STEPS))
    start = model.G(FIG2.c, -2) + (APPROACH[0] if approaching else 0.0)
    states = _moving(start, steps, a)
    B = bound.conditional_bound(states, TRACK_RHO, P, q, TRACK_PRESENT)
    for k in (4, 8):  # the bound at frame k from the frames up to k
        expected = _stacked_bound(states[:k], TRACK_RHO, TRACK_PRESENT[:k], P, q)
        assert_allclose(B[k - 1], expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())


def test_a_missing_bearing_between_unit_steps_is_one_step_of_two_without_process_noise():
    """q = 0: frames 1 .. 6 at unit steps with frame 4 missing give the bound of the five
    frames with a step of 2 in its place; with q > 0 they differ, because the acceleration
    of the first unit step moves x over the second (variance q**2 in x), which one step of 2
    does not."""
    states = _moving(model.G(FIG2.c, -2), np.ones(5))
    present = np.array([True, True, True, False, True, True])
    dropped = np.delete(states, 3, axis=0)
    for q, same in ((0.0, True), (0.05, False)):
        gap = bound.conditional_bound(states, RHO, P, q, present)[-1]
        two = bound.conditional_bound(dropped, RHO, P, q)[-1]
        close = np.allclose(gap, two, rtol=1e-12, atol=1e-12 * np.abs(two).max())
        assert close == same


def test_the_regular_case_is_unchanged_bit_for_bit():
    """Every bearing present, unit steps (read within rounding off depths y_1 + k), one rho:
    the same numbers as the scalar call and as the recursion over model.G_linear."""
    states = np.stack([model.G(np.array([0.3, 10.1, -0.07]), k) for k in range(12)])
    assert np.array_equal(bound.track_steps(states), np.ones(11))
    plain = bound.conditional_bound(states, RHO, P, 0.02)
    again = bound.conditional_bound(states, np.full(12, RHO), P, 0.02, np.ones(12, bool))
    assert np.array_equal(plain, again)
    info = bound.measurement_information(states, RHO)
    J = np.linalg.inv(P) + info[0]
    f = model.G_linear(-1)
    for k in range(11):
        M = f.T @ J @ f
        Mu = M @ bound.U
        M = M - 0.02**2 * Mu[:, None] * Mu[None, :] / (1.0 + 0.02**2 * (Mu @ bound.U))
        J = M + info[k + 1]
        J = 0.5 * (J + J.T)
    assert_allclose(plain[-1], np.linalg.inv(J), rtol=1e-12)


def test_steps_through_information_match_the_states():
    states = _moving([0.5, 3.0, -0.2], TRACK_STEPS)
    info = bound.measurement_information(states, TRACK_RHO)
    J = bound.information(info, P, 0.02, np.diff(states[:, 1]))  # the steps the states carry
    B = bound.conditional_bound(states, TRACK_RHO, P, 0.02)
    assert np.array_equal(bound.covariance_bound(J), B)


def test_scaling_the_track_scales_the_bound():
    """The bearing x / y is scale-free: scaling x, y and the steps by c scales the bound on
    (x, y) by c**2 and leaves that on v; with c = 1e150 and rho / c the information is that of
    the unscaled track, far beyond where squaring the depth overflows."""
    states = _moving([0.5, 3.0, -0.2], TRACK_STEPS)
    base = bound.conditional_bound(states, TRACK_RHO, None, 0.0, TRACK_PRESENT)[-1]
    for c in (1e-150, 1e150, 2.0**500):
        big = states * [c, c, 1.0]
        scaled = bound.conditional_bound(big, TRACK_RHO, None, 0.0, TRACK_PRESENT)[-1]
        d = np.array([c, c, 1.0])
        assert_allclose(scaled / np.outer(d, d), base, rtol=1e-9)
        same = bound.measurement_information(big, TRACK_RHO / c)
        assert_allclose(same, bound.measurement_information(states, TRACK_RHO), rtol=1e-14)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda s: bound.conditional_bound(s + np.eye(8, 3, -7) * 0.1, RHO), "states"),
        (lambda s: bound.conditional_bound(np.concatenate([s[:1], s[:-1]]), RHO), "states"),
        (lambda s: bound.conditional_bound(s, RHO, P, 0.0, [1, 1, 0, 1, 1, 1, 1, 1]), "present"),
        (lambda s: bound.conditional_bound(s, RHO, P, 0.0, np.ones(7, bool)), "present"),
        (lambda s: bound.conditional_bound(s, np.full(7, RHO), P), "rho"),
        (lambda s: bound.conditional_bound(s, np.where(TRACK_PRESENT, np.nan, RHO), P), "rho"),
        (lambda s: bound.conditional_bound(s, RHO, None, 0.0, ~TRACK_PRESENT), "information"),
        (lambda s: bound.information(np.zeros((8, 3, 3)), P, 0.0, [1.0] * 6), "steps"),
        (lambda s: bound.information(np.zeros((8, 3, 3)), P, 0.0, [1.0] * 6 + [0.0]), "steps"),
    ],
)
def test_track_refusals_name_the_argument(call, name):
    states = _moving([0.5, 3.0, -0.2], TRACK_STEPS)
    with pytest.raises(ValueError, match=name):
        call(states)


def test_more_frames_than_the_limit_are_refused():
    n = MAX_FRAMES + 1
    states = _moving([0.0, 1.0, 0.01], np.ones(n - 1))
    with pytest.raises(ValueError, match="states has 1001 frames"):
        bound.conditional_bound(states, RHO, P)
    with pytest.raises(ValueError, match="measurement_info has 1001 frames"):
        bound.information(np.zeros((n, 3, 3)), P)
    with pytest.raises(ValueError, match="frames has 1001 frames"):
        bound.posterior_bound(FIG2.c, 3, n, RHO, P)
    with pytest.raises(ValueError, match="frames has 1001 frames"):
        bound.process_noise_steps(0.1, n)
    assert bound.conditional_bound(states[:MAX_FRAMES], RHO, P).shape == (MAX_FRAMES, 3, 3)


# ---------------------------------------------------------------------------------------------
# Fuzz: odd inputs are answered with finite numbers or refused in one line naming the argument.
# Each case takes every argument good or extreme (depths, noise levels, covariances from 1e-300
# to 1e300) and at most one argument odd (negative, zero, NaN, inf, complex, bool, text, ragged,
# the wrong shape, too many frames).

EXTREME = [1e-300, 1e-150, 1e150, 1e300]
ODD = [0.0, -1.0, np.nan, np.inf, -np.inf, 1j, True, "0.1", None, [1.0, [2.0]], [1.0, 2.0]]
REASONS = False  # True: the statistics (--hypothesis-show-statistics) show why cases are refused
FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _answered_or_refused(call, names, nan_frames=False, label=None):
    """Run ``call`` with warnings as errors: finite numbers, or a ValueError naming an argument.

    ``nan_frames``: NaN is allowed at the frames before the last (no bound yet, documented).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            out = call()
        except ValueError as err:
            text = str(err)
            assert "\n" not in text, text
            assert any(name in text for name in names), text
            event(f"{label or names[0]}: refused" + (f" ({text[:60]})" if REASONS else ""))
            return None
    event(f"{label or names[0]}: answered")
    values = out.values() if isinstance(out, dict) else [out]
    for value in values:
        value = np.asarray(value, dtype=float)
        if nan_frames:
            assert np.all(np.isfinite(value[..., -1, :, :])), value
            value = value[~np.isnan(value)]
        assert np.all(np.isfinite(value)), value
    return out


def _arguments(draw, good: dict, odd: dict) -> dict:
    """Every argument from its good values, at most one from its odd ones."""
    out = {name: draw(st.sampled_from(values)) for name, values in good.items()}
    spoiled = draw(st.sampled_from([None, None, *odd]))
    if spoiled is not None:
        out[spoiled] = draw(st.sampled_from(odd[spoiled]))
    return out


def _track(draw, n, scale):
    """A track by the motion with a step, its depths and steps at ``scale``."""
    steps = scale * np.array(
        draw(st.lists(st.sampled_from([0.5, 1.0, 2.0]), min_size=n - 1, max_size=n - 1))
    )
    y1 = scale * draw(st.sampled_from([1.0, 3.0]))
    x1 = y1 * draw(st.sampled_from([0.0, 0.3, -2.0]))
    v = draw(st.sampled_from([0.0, 0.1, -0.4]))
    return _moving([x1, y1, v], steps)


def _odd_tracks(n):
    track = _moving([0.3, 2.0, 0.1], np.ones(max(n - 1, 0)))
    spoiled = [track.copy() for _ in range(6)]
    spoiled[0][-1, 0] = np.nan
    spoiled[1][0, 1] = np.inf
    spoiled[2][0, 1] = 0.0
    spoiled[3][:, 1] *= -1.0
    spoiled[4][-1, 0] += 0.5  # does not move by x + s v
    spoiled[5] = spoiled[5][::-1]  # depths shrinking
    return [
        *spoiled,
        track + 0j,
        track > 0,
        track.astype(str),
        track[:, :2],
        [list(track[0]), list(track[0][:2])],
        _moving([0.3, 2.0, 0.1], np.ones(MAX_FRAMES)),
    ]


COVS = [None, np.diag([4.0, 9.0, 1.0]), *[c * np.eye(3) for c in EXTREME]]
ODD_COVS = [
    1e-320 * np.eye(3),
    -P,
    np.full((3, 3), np.nan),
    np.eye(2),
    [[1.0, 0.0], [0.0]],
    np.ones((3, 3)),
    "P",
]
NOISES = [0.0, 0.01, 0.5, *EXTREME]
ODD_NOISES = [*ODD, 1e-320, [0.1] * 20]


@st.composite
def _conditional_cases(draw):
    n = draw(st.sampled_from([1, 2, 3, 5, 8]))
    scale = draw(st.sampled_from([1.0, *EXTREME]))
    gap = np.arange(n) != n // 2
    good = {
        "states": [_track(draw, n, scale)],
        "rho": [RHO, *EXTREME, np.full(n, RHO), np.where(gap, RHO * 3, np.nan), scale * RHO],
        "prior_cov": COVS,
        "process_noise": NOISES,
        "present": [None, np.ones(n, bool), gap],
    }
    odd = {
        "states": _odd_tracks(n),
        "rho": [*ODD, np.full(n + 1, RHO), np.where(gap, np.nan, RHO)],
        "prior_cov": ODD_COVS,
        "process_noise": ODD_NOISES,
        "present": [np.ones(n, int), np.array(["yes"] * n), np.ones(n + 1, bool), "all", 1.0],
    }
    return _arguments(draw, good, odd)


@FUZZ
@given(case=_conditional_cases(), data=st.data())
def test_conditional_bound_and_its_pieces_answer_or_refuse_by_name(case, data):
    names = ("states", "rho", "prior_cov", "process_noise", "present", "information")
    _answered_or_refused(
        lambda: bound.conditional_bound(**case), names, nan_frames=True, label="conditional_bound"
    )
    states, rho = case["states"], case["rho"]
    info = _answered_or_refused(
        lambda: bound.measurement_information(states, rho), ("states", "rho")
    )
    if info is None or info.ndim < 3:
        return
    n = info.shape[-3]
    steps = data.draw(
        st.sampled_from(
            [
                None,
                np.full(n - 1, 2.0),
                np.full(n - 1, 1e150),
                np.full(n - 1, 1e-150),
                np.zeros(n - 1),
                np.ones(n),
            ]
        )
    )
    J = _answered_or_refused(
        lambda: bound.information(info, case["prior_cov"], case["process_noise"], steps),
        ("measurement_info", "prior_cov", "process_noise", "steps"),
    )
    if J is not None:
        _answered_or_refused(lambda: bound.covariance_bound(J[..., -1, :, :]), ("information",))


@st.composite
def _posterior_cases(draw):
    good = {
        "state": [
            FIG2.c,
            np.array([0.3, 4.0, 0.0]),
            np.array([1e150, 1e150, 0.1]),
            np.array([1e-150, 1e-150, 0.1]),
            np.array([0.3, 1e300, 0.0]),
        ],
        "frame": [1, 3],
        "frames": [3, 8],
        "rho": [RHO, *EXTREME],
        "prior_cov": COVS,
        "process_noise": NOISES,
    }
    odd = {
        "state": [
            [0.3, 1e-300, 0.0],
            [1e300, 5.0, 1e300],
            [0.0, -1.0, 0.0],
            [np.nan, 4.0, 0.0],
            [1.0, 2.0],
            "abc",
            [1j, 2, 3],
        ],
        "frame": [0, 9, 2.5, True, "1"],
        "frames": [0, 1, MAX_FRAMES + 1, 4.0, None],
        "rho": ODD,
        "prior_cov": ODD_COVS,
        "process_noise": [*ODD, 1e-320, [0.1, 0.2]],
    }
    return _arguments(draw, good, odd)


@FUZZ
@given(case=_posterior_cases())
def test_posterior_bound_answers_or_refuses_by_name(case):
    names = ("state", "frame", "frames", "rho", "prior_cov", "process_noise", "information")
    _answered_or_refused(lambda: bound.posterior_bound(**case), names, nan_frames=True)


@st.composite
def _expected_cases(draw):
    good = {
        "depth": [4.0, np.array([1.0, 2.0, 3.0]), *EXTREME],
        "lateral_mean": [
            np.array([0.1, 0.0]),
            np.array([1e150, 1.0]),
            np.array([-1e300, 0.0]),
            np.array([[0.1, 0.0]] * 3),
        ],
        "lateral_cov": [np.diag([v, 1.0]) for v in [0.0, 0.5, *EXTREME]],
        "rho": [RHO, *EXTREME],
    }
    odd = {
        "depth": [*ODD, -np.array([1.0, 2.0, 3.0]), [[1.0], [2.0, 3.0]], np.ones(4)],
        "lateral_mean": [*ODD, [0.1], [np.inf, 0.0], np.zeros((4, 2))],
        "lateral_cov": [*ODD, np.diag([-1.0, 1.0]), np.full((2, 2), np.nan), np.eye(3)],
        "rho": [*ODD, np.ones(4)],
    }
    return _arguments(draw, good, odd)


@FUZZ
@given(case=_expected_cases())
def test_expected_information_answers_or_refuses_by_name(case):
    names = ("depth", "lateral_mean", "lateral_cov", "rho")
    _answered_or_refused(lambda: bound.expected_measurement_information(**case), names)


@st.composite
def _against_cases(draw):
    rng = np.random.default_rng(draw(st.integers(0, 100)))
    e = rng.standard_normal((2, 6))
    s = rng.uniform(0.5, 2.0, (2, 6))
    scales = [1.0, *EXTREME, 1e-320]
    good = {
        "errors": [c * e for c in scales] + [np.zeros((2, 6))],
        "sds": [c * s for c in scales] + [np.zeros((2, 6))],
        "bound_sd": [1.0, *EXTREME, np.array([1.0, 1e-300])],
        "z": [bound.Z, 1.0, *EXTREME],
    }
    bad = e.copy()
    bad[0, 0] = np.nan
    odd = {
        "errors": [*ODD, bad, e[:, :5], e[:, :1], e + 1j, e > 0],
        "sds": [*ODD, -s, s[:, :5], s > 1, np.where(s > 1, np.inf, s)],
        "bound_sd": [*ODD, np.ones(5), np.array([1.0, 0.0])],
        "z": [*ODD, np.array([2.0, 2.0])],
    }
    return _arguments(draw, good, odd)


@FUZZ
@given(case=_against_cases())
def test_against_bound_answers_or_refuses_by_name(case):
    names = ("errors", "sds", "bound_sd", "z")
    _answered_or_refused(lambda: bound.against_bound(**case), names)
