"""Trials a filter refuses: counted apart, the filter scored over the trials it answers."""

import numpy as np
import pytest

from depthcore.studies import monte_carlo
from depthcore.studies import trials as study_trials
from depthcore.studies.scores import Tally, refused_scores

NAMES = ("optimal", "ekf", "inverse_depth", "ukf")
RUN = {"trials": 200, "seed": 3, "prior": "inverse_depth"}


@pytest.fixture(scope="module")
def drawn():
    """The inverse-depth prior's trials, on which the EKF refuses some."""
    return study_trials.simulate(
        [1.2, 6.0, 1.2], 0.005, 200, np.random.default_rng(3), "inverse_depth"
    )


def test_answered_rows_isolates_every_failing_row():
    bad = {3, 4, 97, 511}
    calls = []

    def run(rows):
        calls.append(len(rows))
        if bad & set(rows.tolist()):
            raise ValueError("no answer")

    rows = study_trials.answered_rows(run, 600)
    assert rows.tolist() == [r for r in range(600) if r not in bad]
    assert len(calls) <= 2 * len(bad) * (np.log2(600) + 1) + 1  # failures times log n


def test_answered_rows_none_and_all():
    def fail(rows):
        raise np.linalg.LinAlgError("singular")

    assert study_trials.answered_rows(fail, 5).size == 0
    assert study_trials.answered_rows(lambda rows: None, 5).tolist() == [0, 1, 2, 3, 4]


def test_refused_trials_scored_apart(drawn):
    est = study_trials.run_filters(drawn, NAMES)
    ekf = est["ekf"]
    assert ekf.refused > 0 and ekf.answered.sum() == len(drawn.mu) - ekf.refused
    assert len(ekf.mean) == int(ekf.answered.sum())
    # the answered trials alone give the same estimates, bit for bit up to rounding
    alone = study_trials.run_filters(
        study_trials.subset(drawn, np.flatnonzero(ekf.answered)), NAMES
    )
    assert alone["ekf"].refused == 0
    np.testing.assert_allclose(alone["ekf"].mean, ekf.mean, rtol=1e-12)
    np.testing.assert_allclose(alone["ekf"].hellinger, ekf.hellinger, rtol=1e-9, atol=1e-12)
    # a filter that answers every trial is untouched by another's refusals
    assert est["ukf"].refused == 0 and est["ukf"].answered is None
    tally = Tally(drawn.truth)
    tally.add(ekf)
    refused = tally.scores()["refused"]
    assert refused["count"] == ekf.refused
    assert refused["fraction"] == ekf.refused / len(drawn.mu)


def test_study_counts_refused_trials_and_pairs_over_those_answered():
    r = monte_carlo.study(names=NAMES, paired=True, **RUN)
    f = r["filters"]
    assert f["ekf"]["refused"]["count"] > 0
    assert f["optimal"]["refused"]["count"] == 0
    for name in NAMES:
        refused = f[name]["refused"]
        assert refused["fraction"] == refused["count"] / r["valid_trials"]
    # the scores of a filter that refuses nothing do not depend on the others named
    ukf = monte_carlo.study(names=("optimal", "ukf"), **RUN)["filters"]["ukf"]
    assert ukf["depth"]["rmse"] == pytest.approx(f["ukf"]["depth"]["rmse"], rel=1e-12)
    # the pairs are compared over the trials every filter answered
    refused = [f[n]["refused"]["count"] for n in NAMES]
    assert r["valid_trials"] - sum(refused) <= r["paired"]["trials"]
    assert r["paired"]["trials"] <= r["valid_trials"] - max(refused)


def test_refused_scores():
    p = 2 / 104  # the Agresti-Coull centre of 0 of 100
    none = {"count": 0, "fraction": 0.0, "se": pytest.approx(np.sqrt(p * (1 - p) / 104))}
    assert refused_scores(0, 100) == none
    out = refused_scores(10, 90)
    assert out["count"] == 10 and out["fraction"] == 0.1 and 0.02 < out["se"] < 0.04


def test_a_filter_that_answers_nothing_is_refused_in_one_line(monkeypatch):
    from depthcore.registry import filters

    monkeypatch.setitem(filters.FILTERS, "ekf", _Refusing(filters.FILTERS["ekf"]))
    with pytest.raises(ValueError, match=r"^filters: the ekf filter has no answer") as info:
        monte_carlo.study(names=("ekf",), trials=20, seed=1)
    assert "\n" not in str(info.value)


class _Refusing:
    """A registry entry whose filter answers no trial."""

    def __init__(self, entry):
        self._entry = entry

    def __getattr__(self, name):
        return getattr(self._entry, name)

    def __call__(self, *args, **kwargs):
        raise ValueError("mu: no answer")


def test_a_random_filter_refusing_trials_draws_on_from_its_generator():
    """At no parallax the particle filter's proposal is not determined on some tracks."""
    part = study_trials.simulate([0.0, 6.0, 0.0], 0.005, 30, np.random.default_rng(0), frames=5)

    def run():
        return study_trials.run_filters(part, ("particle",), np.random.default_rng(1), 60)

    est = run()["particle"]
    assert 0 < est.refused < len(part.mu) and np.isfinite(est.mean).all()
    again = run()["particle"]
    assert np.array_equal(est.mean, again.mean) and np.array_equal(est.answered, again.answered)


class _Flaky(_Refusing):
    """A random registry entry that, at each call, fails on trials its draws pick anew."""

    def __call__(self, mu, *args, rng, **kwargs):
        if np.any(rng.random(len(mu)) < 0.02):
            raise np.linalg.LinAlgError("Singular matrix")
        return self._entry(mu, *args, rng=rng, **kwargs)


def test_a_random_filter_failing_anew_when_run_again_is_isolated_in_rounds(monkeypatch):
    from depthcore.registry import filters

    monkeypatch.setitem(filters.FILTERS, "particle", _Flaky(filters.FILTERS["particle"]))
    part = study_trials.simulate([1.2, 6.0, 1.2], 0.005, 40, np.random.default_rng(0))
    est = study_trials.run_filters(part, ("particle",), np.random.default_rng(8), 50)["particle"]
    # the first run failed; the trials answered are those the last run answered
    assert est.answered is not None and est.answered.sum() == len(est.mean)
    assert est.refused == len(part.mu) - len(est.mean) < len(part.mu) / 2
    assert np.isfinite(est.mean).all()
