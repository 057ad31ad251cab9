"""Bad input gets a ValueError that names the argument and the problem."""

import re

import numpy as np
import pytest

from depthbook.studies import frames
from depthcore import paper_prior
from depthcore.exact import optimal
from depthcore.kalman import ekf, second_order
from depthcore.problem import checks, model
from depthcore.problem.gaussian import Gaussian
from depthcore.problem.model import noise_free_state
from depthcore.problem.scenarios import MU_17

PRIOR = paper_prior(noise_free_state(MU_17))
FILTERS = [
    lambda mu, rho, prior: optimal.run(mu, rho, prior.mean, prior.cov),
    lambda mu, rho, prior: second_order.run(mu, rho, prior.mean, prior.cov),
    lambda mu, rho, prior: ekf.run(mu, rho, prior.mean, prior.cov),
]


@pytest.mark.parametrize("run", FILTERS)
@pytest.mark.parametrize(
    "mu, message",
    [
        ((0.1, 0.1, 0.1), "mu is degenerate"),
        ((-0.1, 0.0, 0.1), "mu is degenerate"),
        ((np.nan, 0.0, 0.2), "mu has 2 bearings present"),  # NaN: a missing frame
        ((-0.3, np.inf, 0.2), "mu must be finite"),
        ((0.2, 0.0, -0.3), "mu puts the point behind the camera"),
        ((-0.3, 0.0), r"mu must have shape (\(3,\)|\(\.\.\., N\) with N >= 3)"),
        (("a", 0.0, 0.2), "mu must be numeric"),
    ],
)
def test_bad_measurements(run, mu, message):
    with pytest.raises(ValueError, match=message):
        run(mu, 0.005, PRIOR)


@pytest.mark.parametrize("run", FILTERS)
@pytest.mark.parametrize(
    "rho, message",
    [
        (0.0, "rho must be positive"),
        (-0.005, "rho must be positive"),
        (np.nan, "rho must be finite"),
        (np.inf, "rho must be finite"),
    ],
)
def test_bad_noise_level(run, rho, message):
    with pytest.raises(ValueError, match=message):
        run(MU_17, rho, PRIOR)


@pytest.mark.parametrize(
    "cov, message",
    [
        (np.diag([1.0, -1.0, 1.0]), "cov must be positive definite"),
        (np.zeros((3, 3)), "cov must be positive definite"),
        (np.array([[1.0, 2.0, 0], [0, 1, 0], [0, 0, 1]]), "cov must be symmetric"),
        (np.eye(2), r"cov must have shape \(3, 3\)"),
        (np.full((3, 3), np.nan), "cov must be finite"),
    ],
)
def test_bad_prior_covariance(cov, message):
    with pytest.raises(ValueError, match=message):
        Gaussian([0.0, 4.0, 0.0], cov)


def test_bad_prior_mean():
    with pytest.raises(ValueError, match="mean must be finite"):
        Gaussian([0.0, np.nan, 0.0], np.eye(3))


def test_degeneracy_boundary():
    # |mu1 + mu3 - 2 mu2| <= 1e-12 is degenerate; just above it is accepted.
    tol = checks.DEGENERACY_TOL
    with pytest.raises(ValueError, match="degenerate"):
        model.measurements([0.0, -tol / 2, 0.0])
    mu = model.measurements([4 * tol, 0.0, -2 * tol])  # second difference 2e-12, c2 = 4
    assert noise_free_state(mu)[1] == pytest.approx(4.0)


def test_behind_camera_boundary():
    # c2 = 2 exactly (depth 0 at the first frame) is rejected; c2 slightly above 2 is not.
    with pytest.raises(ValueError, match="behind the camera"):
        model.measurements([0.3, 0.0, 0.0])  # mu = (a, 0, b) gives c2 = 2 a / (a + b) = 2
    # c2 = 2 + 1e-9 needs b = -a * 1e-9 / (2 + 1e-9)
    a = 0.3
    b = -a * 1e-9 / (2 + 1e-9)
    assert noise_free_state([a, 0.0, b])[1] == pytest.approx(2 + 1e-9, abs=1e-12)


def test_valid_measurements_is_what_measurements_accepts():
    tol = checks.DEGENERACY_TOL
    rng = np.random.default_rng(0)
    mu = np.concatenate(
        [
            rng.normal(0.0, 0.3, (200, 3)),
            [[0.0, -tol / 2, 0.0], [4 * tol, 0.0, -2 * tol], [0.3, 0.0, 0.0]],
            [[np.nan, 0.0, 0.2], [-0.3, np.inf, 0.2], list(MU_17)],
        ]
    )

    def accepted(row):
        try:
            model.measurements(row)
        except ValueError:
            return False
        return True

    want = [accepted(row) for row in mu]
    assert 0 < sum(want) < len(want)
    assert model.valid_measurements(mu).tolist() == want
    assert (
        model.valid_measurements(mu.reshape(2, -1, 3)).tolist()
        == np.reshape(want, (2, -1)).tolist()
    )


def test_spawn_gives_the_children_of_a_fresh_seed_sequence():
    fresh = [np.random.default_rng(s).random() for s in np.random.SeedSequence(5).spawn(3)]
    seq = np.random.SeedSequence(5)
    for _ in range(2):
        assert [np.random.default_rng(s).random() for s in checks.spawn(seq, 3)] == fresh
    assert seq.n_children_spawned == 0


@pytest.mark.parametrize("seed", [-1, 1.5, True, "1"])
def test_seed_sequence_rejects_what_is_not_a_seed(seed):
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        checks.seed_sequence(seed)


def test_batch_inputs_broadcast_the_prior_and_check_shapes():
    mu, rho, pm, pc = model.batch_inputs(
        np.zeros((4, 3)), 0.1, np.ones(3), np.eye(3), triples=False
    )
    assert pm.shape == (4, 3) and pc.shape == (4, 3, 3) and rho.shape == ()
    with pytest.raises(ValueError, match=r"rho must be a scalar or have shape \(4,\)"):
        model.batch_inputs(np.zeros((4, 3)), [0.1, 0.2], np.ones(3), np.eye(3), triples=False)
    with pytest.raises(ValueError, match=r"prior_mean must have shape \(3,\) or \(4, 3\)"):
        model.batch_inputs(np.zeros((4, 3)), 0.1, np.ones((2, 3)), np.eye(3), triples=False)
    with pytest.raises(ValueError, match="rho must be positive"):
        model.batch_inputs(
            np.zeros((2, 2, 3)), [[0.1, -0.2]] * 2, np.ones(3), np.eye(3), triples=False
        )


@pytest.mark.parametrize(
    ("value", "kind"),
    [
        (1 + 2j, "complex"),
        (np.array([1.0, 2.0], dtype=complex), "complex"),
        (True, "boolean"),
        ("0.1", "text"),
        (b"0.1", "bytes"),
        ([None, 1.0], "object"),
        (np.array([1.0, 2.0], dtype=object), "object"),
        (np.datetime64("2020-01-01"), "datetime"),
    ],
)
def test_as_float_refuses_what_is_not_a_real_number_by_name(value, kind):
    with pytest.raises(ValueError, match=rf"^rho must be numeric .*got {kind} values"):
        checks.as_float(value, "rho")


def test_as_float_refuses_ragged_lists_and_takes_integers_lists_and_0d_arrays():
    with pytest.raises(ValueError, match="^mu must be numeric, got a ragged"):
        checks.as_float([[1, 2], [3]], "mu")
    assert checks.as_float([1, 2], "mu").dtype == float
    assert checks.as_float(np.array(3), "mu").shape == ()
    assert checks.number([0.5], "rho") == checks.number(np.array(0.5), "rho") == 0.5
    with pytest.raises(ValueError, match=r"rho must be a number, got shape \(2,\)"):
        checks.number([0.5, 0.6], "rho")


def test_process_noise_is_zero_or_a_normal_double():
    tiny = np.finfo(float).tiny
    assert checks.process_noise(0.0) == 0.0 and checks.process_noise(tiny) == tiny
    for q in (1e-320, 5e-324, tiny / 2):
        with pytest.raises(ValueError, match="process_noise must be 0 or at least"):
            checks.process_noise(q)


@pytest.mark.parametrize("value", [3, 10, checks.MAX_FRAMES, np.int64(4), np.uint16(7)])
def test_frames_takes_integers_from_3_to_the_most_frames(value):
    assert checks.frames(value) == int(value)
    assert type(checks.frames(value)) is int


@pytest.mark.parametrize(
    "value, shown",
    [
        (0, "0"),
        (2, "2"),
        (-5, "-5"),
        (checks.MAX_FRAMES + 1, str(checks.MAX_FRAMES + 1)),
        (2.5, "2.5"),
        (np.float64(3.0), "3.0"),
        (np.int64(2), "2"),
        (True, "True"),
        ("3", "'3'"),
        (None, "None"),
    ],
)
def test_frames_refuses_what_is_not_a_number_of_frames_and_shows_it(value, shown):
    message = f"N must be an integer from 3 to {checks.MAX_FRAMES}, got {shown}"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        checks.frames(value, "N")


def test_a_list_of_frames_names_the_value_refused():

    with pytest.raises(ValueError, match=r"got 2\.5$"):
        frames.frames_study([3, 2.5], 10, 1)
    with pytest.raises(ValueError, match=r"from 3 to 1000, got 0$"):
        frames.frames_study(0, 10, 1)


@pytest.mark.parametrize(
    "value", [float("nan"), float("inf"), -float("inf"), 0, 0.0, 1, 1.0, -0.5, True, False, "0.5"]
)
def test_probability_refuses_what_is_not_strictly_between_0_and_1(value):
    message = f"level must lie in (0, 1), got {value!r}"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        checks.probability(value, "level")


@pytest.mark.parametrize("value", [0.95, 1e-300, np.float32(0.5), np.array(0.25), 1 - 1e-16])
def test_probability_returns_a_level_in_the_open_interval_as_a_float(value):
    p = checks.probability(value, "level")
    assert type(p) is float and p == float(value)
