"""The study's track-loss count: the rule, its binomial error, its exact upper bound."""

import numpy as np
import pytest
from scipy import stats

from depthcore.problem.scenarios import SCENARIOS
from depthcore.studies import monte_carlo, scores
from depthcore.studies import trials as study_trials


def test_the_rule_on_hand_made_tracks():
    truth = np.array([[3.0, 4.0, 0.0]] * 5)  # distance 5: the threshold is 2.5
    mean = np.array(
        [
            [3.0, 4.0, 9.0],  # exact position, any velocity: kept
            [3.0 + 1.5, 4.0 + 2.0, 0.0],  # error 2.5, on the threshold: kept
            [3.0 + 1.5, 4.0 + 2.01, 0.0],  # just beyond: lost
            [3.0, -4.0, 0.0],  # behind the camera: lost
            [np.nan, 4.0, 0.0],  # no estimate: lost
        ]
    )
    assert scores.lost_tracks(mean, truth).tolist() == [False, False, True, True, True]
    assert scores.lost_tracks(mean, truth, threshold=10.0).tolist() == [False] * 4 + [True]
    with pytest.raises(ValueError, match="threshold"):
        scores.lost_tracks(mean, truth, threshold=0.0)


@pytest.mark.parametrize(("lost", "n"), [(0, 50), (3, 50), (49, 50), (17, 1000)])
def test_error_and_upper_bound(lost, n):
    r = scores.track_loss(lost, n)
    p = lost / n
    assert r["fraction"] == p and r["se"] == pytest.approx(np.sqrt(p * (1 - p) / n), rel=1e-15)
    # the Clopper-Pearson bound: at p = upper, seeing <= lost losses has probability 5 %
    assert stats.binom.cdf(lost, n, r["upper"]) == pytest.approx(0.05, rel=1e-9)
    if lost == 0:
        assert r["upper"] == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-12)


def test_every_track_lost_and_refusals():
    assert scores.track_loss(10, 10)["upper"] == 1.0
    for lost, n, match in ((-1, 5, "lost"), (6, 5, "lost"), (1.0, 5, "lost"), (0, 0, "trials")):
        with pytest.raises(ValueError, match=match):
            scores.track_loss(lost, n)
    with pytest.raises(ValueError, match="confidence"):
        scores.track_loss(1, 5, confidence=1.0)


def test_the_upper_bound_covers_at_its_confidence():
    """Over 20,000 binomial counts at p = 0.02, n = 200, the bound holds in about 95 %.

    The exact bound is conservative: its coverage is at least 95 % whatever p,
    so the check is one-sided, 5 standard errors below 0.95.
    """
    rng = np.random.default_rng(3)
    counts = rng.binomial(200, 0.02, size=20_000)
    upper = {k: scores.track_loss(int(k), 200)["upper"] for k in np.unique(counts)}
    covered = np.mean([upper[k] >= 0.02 for k in counts])
    assert covered > 0.95 - 5 * np.sqrt(0.95 * 0.05 / 20_000)


def test_the_study_reports_it_and_chunks_agree():
    one = monte_carlo.study(trials=40, seed=2, names=("ekf", "optimal"), chunk=40)
    many = monte_carlo.study(trials=40, seed=2, names=("ekf", "optimal"), chunk=7)
    for name in ("ekf", "optimal"):
        assert one["filters"][name]["track_loss"] == many["filters"][name]["track_loss"]
    # the count is that of the rule on the same trials
    trials = study_trials.simulate(SCENARIOS["fig2"].c, 0.005, 40, np.random.default_rng(0))
    est = study_trials.run_filters(trials, ("ekf",))["ekf"]
    lost = int(np.sum(scores.lost_tracks(est.mean, trials.truths)))
    tally = scores.Tally(trials.truth)
    tally.add(est)
    assert tally.scores()["track_loss"] == scores.track_loss(lost, len(trials.mu))
