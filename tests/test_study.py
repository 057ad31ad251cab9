"""The Monte Carlo study: simulation, scores, repeatability, bad input."""

import dataclasses
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import integrate, stats

from depthcore.cli.main import main
from depthcore.exact import optimal, posterior
from depthcore.problem import checks, model
from depthcore.problem.scenarios import SCENARIOS
from depthcore.registry.filters import FILTERS, NAMES
from depthcore.studies import monte_carlo
from depthcore.studies import scores as study_scores
from depthcore.studies import trials as study_trials


def test_same_seed_same_result():
    a = monte_carlo.study(trials=40, seed=3, n_particles=300)
    b = monte_carlo.study(trials=40, seed=3, n_particles=300)
    assert a == b
    assert monte_carlo.study(trials=40, seed=4, n_particles=300) != a


def test_particle_filter_tracks_the_optimal_filter():
    # only the two compared run: a filter's scores do not depend on which others run
    # (test_only_the_named_filters_run)
    r = monte_carlo.study(trials=60, seed=5, n_particles=4000, names=("optimal", "particle"))
    o, p = r["filters"]["optimal"], r["filters"]["particle"]
    # averaged over 60 trials, the Monte Carlo error of the means is ~0.01 SD
    assert abs(o["depth"]["bias"] - p["depth"]["bias"]) < 0.05 * o["depth"]["mean_sd"]
    assert p["hellinger_depth"]["mean"] < 0.05


def test_binned_kde_matches_direct_kde():
    rng = np.random.default_rng(0)
    x = rng.normal(5, 1, size=(2, 500))
    W = rng.random((2, 500))
    W /= W.sum(1, keepdims=True)
    bw = np.array([0.3, 0.5])
    y = np.linspace(2, 8, 50)[None].repeat(2, 0)
    direct = np.stack(
        [
            np.exp(-0.5 * ((y[i][:, None] - x[i]) / bw[i]) ** 2)
            @ W[i]
            / (np.sqrt(2 * np.pi) * bw[i])
            for i in range(2)
        ]
    )
    assert_allclose(np.exp(study_trials._binned_kde(x, W, bw)(y)), direct, rtol=1e-3, atol=1e-6)


def test_unknown_filter_is_rejected():
    with pytest.raises(ValueError, match="filters must be among"):
        monte_carlo.study(trials=5, names=("kalman",))


def _assert_same_scores(a, b, rel=1e-12):
    """Two results' scores agree to ``rel``, every key of every filter."""
    assert a.keys() == b.keys()
    for key, x in a.items():
        if isinstance(x, dict):
            _assert_same_scores(x, b[key], rel)
        elif isinstance(x, float):
            assert x == pytest.approx(b[key], rel=rel, abs=1e-300), key
        else:
            assert x == b[key], key


def test_chunk_size_does_not_change_the_deterministic_filters():
    names = ("optimal", "second_order", "ekf", "ukf")
    a = monte_carlo.study(trials=30, seed=2, chunk=7, names=names)
    b = monte_carlo.study(trials=30, seed=2, chunk=30, names=names)
    assert a["filters"] != {}
    _assert_same_scores(a["filters"], b["filters"])


def _direct_scores(truth, est):
    """Scores from every trial's estimates at once, by their definitions."""
    err = est.mean - truth
    out = {}
    for q, i, cdf in (("depth", 1, est.depth_cdf), ("velocity", 2, est.velocity_cdf)):
        out[q] = {
            "bias": np.mean(err[:, i]),
            "rmse": np.sqrt(np.mean(err[:, i] ** 2)),
            "mean_sd": np.mean(np.sqrt(est.cov[:, i, i])),
            "coverage_68": np.mean(np.abs(cdf - 0.5) <= 0.34),
            "coverage_95": np.mean(np.abs(cdf - 0.5) <= 0.475),
        }
    out["nees"] = np.mean([e @ np.linalg.solve(c, e) for e, c in zip(err, est.cov, strict=True)])
    out["hellinger"] = np.mean(est.hellinger)
    return out


def test_streamed_scores_equal_those_of_all_trials_at_once():
    # The study draws the noise from the seed's first child and the particles of
    # chunk k from its second child's child k: redo it without chunks and score
    # every trial at once.
    seed, n = 9, 40
    noise_seed, particle_seed = checks.spawn(seed, 2)
    noise = np.random.default_rng(noise_seed)
    particles = np.random.default_rng(checks.spawn(particle_seed, 1)[0])
    trials = study_trials.simulate(SCENARIOS["fig2"].c, 1 / 200, n, noise)
    est = study_trials.run_filters(trials, NAMES, particles, 300)
    one = monte_carlo.study(trials=n, seed=seed, chunk=n, n_particles=300)
    several = monte_carlo.study(trials=n, seed=seed, chunk=9, n_particles=300)
    for name in NAMES:
        want = _direct_scores(trials.truth, est[name])
        for got, rel in ((one, 1e-15), (several, 1e-12)):
            f = got["filters"][name]
            if name == "particle" and got is several:
                continue  # its draws depend on the chunks
            for q in ("depth", "velocity"):
                for k, v in want[q].items():
                    assert f[q][k] == pytest.approx(v, rel=rel, abs=1e-300), (name, q, k)
            assert f["nees"] == pytest.approx(want["nees"], rel=1e-12)
            assert f["hellinger_depth"]["mean"] == pytest.approx(want["hellinger"], rel=rel)


def test_study_keeps_only_running_sums():
    # Memory of a chunk, not of the trials: the peak allocation of 16 chunks is
    # that of 2 (each trial kept would add 15 numbers per filter).
    import tracemalloc

    def peak(n):
        monte_carlo.study(trials=10, seed=0, chunk=10, names=("ekf",))  # warm the imports
        tracemalloc.start()
        monte_carlo.study(trials=n, seed=0, chunk=50, names=("ekf", "ukf"))
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak

    small, large = peak(100), peak(800)
    assert large < small + 8 * (800 - 100) * 15 * 2 / 2  # half of what keeping them would take


def test_progress_is_reported_after_each_chunk():
    calls = []
    monte_carlo.study(
        trials=25, seed=0, chunk=10, names=("ekf",), progress=lambda *a: calls.append(a)
    )
    assert calls == [(10, 25), (20, 25), (25, 25)]


def test_only_the_named_filters_run(monkeypatch):
    # Without "optimal", neither the optimal filter nor its batched marginals
    # may run, the Hellinger distances are not computed, and every other score
    # is what a run including the optimal filter gives with the same seed.
    names = ("second_order", "ekf", "ukf", "particle")
    full = monte_carlo.study(trials=25, seed=4, chunk=10, n_particles=200)

    def refuse(*args, **kwargs):
        raise AssertionError("the optimal filter ran")

    monkeypatch.setitem(FILTERS, "optimal", dataclasses.replace(FILTERS["optimal"], run=refuse))
    monkeypatch.setattr(optimal, "batch_marginals", refuse)
    monkeypatch.setattr(optimal, "moments", refuse)
    part = monte_carlo.study(trials=25, seed=4, chunk=10, n_particles=200, names=names)
    assert list(part["filters"]) == list(names)
    for name in names:
        got, want = dict(part["filters"][name]), dict(full["filters"][name])
        assert got.pop("hellinger_depth") is None
        assert want.pop("hellinger_depth")["mean"] >= 0
        assert got == want
    with pytest.raises(AssertionError, match="the optimal filter ran"):
        monte_carlo.study(trials=5, seed=4, names=("optimal",))


def test_study_command_without_the_optimal_filter_shows_no_hellinger(capsys):
    assert main(["study", "--trials", "5", "--filters", "ekf", "ukf", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [f["hellinger_depth"] for f in data["filters"].values()] == [None, None]
    assert main(["study", "--trials", "5", "--filters", "ekf", "optimal"]) == 0
    table = capsys.readouterr().out
    ekf_depth = next(line for line in table.splitlines() if line.startswith("ekf  "))
    assert ekf_depth.split()[-1] != "-"
    assert main(["study", "--trials", "5", "--filters", "ekf"]) == 0
    table = capsys.readouterr().out
    ekf_depth = next(line for line in table.splitlines() if line.startswith("ekf  "))
    assert ekf_depth.split()[-1] == "-"
    assert "a dash: not computed" in table


def test_scores_follow_their_definitions():
    trials = study_trials.simulate(SCENARIOS["fig2"].c, 1 / 200, 25, np.random.default_rng(0))
    est = study_trials.run_filters(trials, ("optimal", "ekf"))  # no particle filter: no rng needed
    s = study_scores.scores(trials, est["ekf"])
    err = est["ekf"].mean[:, 1] - trials.truth[1]
    assert s["depth"]["bias"] == pytest.approx(np.mean(err))
    assert s["depth"]["rmse"] == pytest.approx(np.sqrt(np.mean(err**2)))
    inside = np.abs(est["ekf"].mean[:, 1] - trials.truth[1]) <= 0.9944578832097535 * np.sqrt(
        est["ekf"].cov[:, 1, 1]
    )  # the 68 % normal quantile
    assert s["depth"]["coverage_68"] == pytest.approx(np.mean(inside))


def test_hellinger_matches_adaptive_quadrature():
    s = SCENARIOS["fig2"]
    trials = study_trials.simulate(s.c, s.rho, 3, np.random.default_rng(5))
    est = study_trials.run_filters(trials, ("optimal", "ekf"))
    ref = optimal.batch_marginals(trials.mu, trials.rho, trials.prior_mean, trials.prior_cov)
    for i in range(3):
        m = optimal.run(trials.mu[i], s.rho, trials.prior_mean[i], trials.prior_cov)
        mean, sd = est["ekf"].mean[i, 1], np.sqrt(est["ekf"].cov[i, 1, 1])

        def q(y, mean=mean, sd=sd):
            return np.exp(-0.5 * ((y - mean) / sd) ** 2) / (np.sqrt(2 * np.pi) * sd)

        bc, _ = integrate.quad(
            lambda y, m=m, q=q: np.sqrt(m.depth_pdf(y) * q(y)), 2, 60, points=[mean], limit=400
        )
        assert est["ekf"].hellinger[i] == pytest.approx(np.sqrt(1 - bc), abs=1e-6)
    assert ref.moments.depth_mean.shape == (3,)


def test_ekf_is_overconfident_and_second_order_is_not():
    r = monte_carlo.study(trials=200, seed=1, names=("ekf", "second_order"))
    ekf, so = r["filters"]["ekf"], r["filters"]["second_order"]
    # 200 trials: the binomial SD of a coverage near 0.68 is 0.033
    assert ekf["depth"]["coverage_68"] < 0.4
    assert abs(so["depth"]["coverage_68"] - 0.68) < 0.12
    assert ekf["nees"] > 10 > so["nees"]


def test_rejected_trials_are_counted():
    # Noise so large that some triples have no solution in front of the camera.
    t = study_trials.simulate(SCENARIOS["fig3"].c, 0.05, 200, np.random.default_rng(0))
    assert t.n_rejected > 0
    assert len(t.mu) + t.n_rejected == 200
    assert study_trials.valid_triples(t.mu).all()


def test_fixed_prior_is_built_from_the_truth():
    c = SCENARIOS["fig2"].c
    t = study_trials.simulate(c, 1 / 200, 5, np.random.default_rng(0), prior="fixed")
    assert_allclose(t.prior_mean, np.tile([c[0] - 2 * c[2], c[1] - 2, 0.0], (5, 1)))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"n": 0}, "trials must be a positive integer"),
        ({"prior": "flat"}, "prior must be one of"),
        ({"rho": -1.0}, "rho must be positive"),
        ({"truth": [0.0, 1.0, 0.0]}, "truth puts the point behind the camera"),
    ],
)
def test_simulate_rejects_bad_input(kwargs, message):
    args = {"truth": SCENARIOS["fig2"].c, "rho": 0.005, "n": 10, "rng": np.random.default_rng(0)}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        study_trials.simulate(**args)


def test_study_command_json(capsys):
    assert main(["study", "--trials", "30", "--seed", "1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["valid_trials"] == 30
    assert set(data["filters"]) == {"optimal", "second_order", "ekf", "ukf", "particle"}
    for f in data["filters"].values():
        assert set(f) == {
            "depth",
            "velocity",
            "nees",
            "nees_se",
            "hellinger_depth",
            "calibration",
            "track_loss",
            "divergent",
            "track_loss_levels",
            "anees",
            "refused",
        }
        assert len(f["calibration"]["depth"]) == len(f["calibration"]["levels"])
        scores = {"bias", "rmse", "mean_sd", "coverage_68", "coverage_95", "rmse_kept"}
        robust = {"median_abs_error", "median_abs_error_ci"}
        assert set(f["depth"]) == scores | {f"{s}_se" for s in scores} | robust


def test_study_command_rejects_bad_trials(capsys):
    assert main(["study", "--trials", "0"]) == 2
    assert "trials must be a positive integer" in capsys.readouterr().err


def test_a_seed_sequence_and_its_integer_give_the_same_study():
    seq = np.random.SeedSequence(7)
    a = monte_carlo.study(trials=12, seed=7, names=("ekf", "particle"), n_particles=100)
    b = monte_carlo.study(trials=12, seed=seq, names=("ekf", "particle"), n_particles=100)
    c = monte_carlo.study(trials=12, seed=seq, names=("ekf", "particle"), n_particles=100)
    assert a == b == c  # the study spawns its streams without changing the seed
    assert a["seed"] == 7
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        monte_carlo.study(trials=12, seed=-1)


def _estimates_with_cdfs(cdf):
    """Estimates of a fictitious filter whose marginal CDFs at the truth are ``cdf``."""
    n = len(cdf)
    return study_trials.Estimates(
        np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)), cdf, cdf[::-1].copy(), np.zeros(n)
    )


def test_coverage_of_exactly_uniform_cdfs_is_the_nominal_level():
    # A calibrated filter's CDFs at the truth are uniform: on the midpoints of
    # 10,000 equal cells, the central p interval [1/2 - p/2, 1/2 + p/2] holds
    # exactly 10,000 p of them at every level (no midpoint is an end point).
    n = 10_000
    cdf = (np.arange(n) + 0.5) / n
    trials = study_trials.Trials(
        np.zeros(3), 0.01, np.zeros((n, 3)), np.zeros((n, 3)), np.eye(3), 0
    )
    s = study_scores.scores(trials, _estimates_with_cdfs(cdf))
    for q in ("depth", "velocity"):
        assert s[q]["coverage_68"] == 0.68
        assert s[q]["coverage_95"] == 0.95
        assert s["calibration"][q] == pytest.approx(
            list(study_scores.CALIBRATION_LEVELS), abs=1e-12
        )


def test_coverage_counts_a_small_hand_computed_case():
    # Central 68 % interval of the CDF: [0.16, 0.84]; central 95 %: [0.025, 0.975].
    cdf = np.array([0.5, 0.17, 0.83, 0.15, 0.85, 0.03, 0.97, 0.02, 0.98, 0.0])
    trials = study_trials.Trials(
        np.zeros(3), 0.01, np.zeros((10, 3)), np.zeros((10, 3)), np.eye(3), 0
    )
    s = study_scores.scores(trials, _estimates_with_cdfs(cdf))
    assert s["depth"]["coverage_68"] == 3 / 10
    assert s["depth"]["coverage_95"] == 7 / 10
    levels = list(study_scores.CALIBRATION_LEVELS)
    assert s["calibration"]["depth"][levels.index(0.7)] == 5 / 10  # [0.15, 0.85]
    assert s["calibration"]["depth"][levels.index(0.05)] == 1 / 10


@pytest.mark.parametrize("name", ["second_order", "ekf", "ukf"])
def test_gaussian_filters_cdfs_at_the_truth_are_normal_cdfs_of_their_marginals(name):
    # Each Gaussian filter's marginal CDF at the truth, against scipy's normal
    # CDF with the filter's own mean and SD of that component.
    from scipy.stats import norm

    trials = study_trials.simulate(SCENARIOS["fig2"].c, 1 / 200, 20, np.random.default_rng(11))
    est = study_trials.run_filters(trials, ("optimal", name))[name]
    for i, cdf in ((1, est.depth_cdf), (2, est.velocity_cdf)):
        want = norm.cdf(trials.truth[i], loc=est.mean[:, i], scale=np.sqrt(est.cov[:, i, i]))
        assert_allclose(cdf, want, rtol=1e-12, atol=1e-300)
    # and hence the 68 % coverage of the velocity counts |m - v| <= z sd
    z = norm.ppf(0.84)
    inside = np.abs(est.mean[:, 2] - trials.truth[2]) <= z * np.sqrt(est.cov[:, 2, 2])
    assert study_scores.scores(trials, est)["velocity"]["coverage_68"] == pytest.approx(
        np.mean(inside)
    )


def test_optimal_cdfs_at_the_truth_match_quadrature_of_its_marginals():
    s = SCENARIOS["fig2"]
    trials = study_trials.simulate(s.c, s.rho, 2, np.random.default_rng(4))
    est = study_trials.run_filters(trials, ("optimal",))["optimal"]
    for i in range(2):
        m = optimal.run(trials.mu[i], s.rho, trials.prior_mean[i], trials.prior_cov)
        y_cdf, _ = integrate.quad(m.depth_pdf, 2, s.c[1], limit=400)
        v_cdf, _ = integrate.quad(m.velocity_pdf, -np.inf, s.c[2], limit=400)
        assert est.depth_cdf[i] == pytest.approx(y_cdf, abs=1e-6)
        assert est.velocity_cdf[i] == pytest.approx(v_cdf, abs=1e-6)


def test_study_over_more_frames_with_process_noise_scores_each_trials_own_truth():
    from depthcore.kalman import ekf
    from depthcore.problem import checks

    fig2 = SCENARIOS["fig2"]
    truth, rho, q, N = fig2.c, fig2.rho, 0.02, 6
    r = monte_carlo.study(
        truth, rho, 40, seed=4, names=("optimal", "ekf"), frames=N, process_noise=q
    )
    assert r["frames"] == N and r["process_noise"] == q
    # the same trials, drawn from the same stream, filtered directly
    noise_rng = np.random.default_rng(checks.spawn(checks.seed_sequence(4), 2)[0])
    t = study_trials.simulate(truth, rho, 40, noise_rng, "paper", frames=N, process_noise=q)
    assert t.mu.shape == (r["valid_trials"], N) and t.states.shape == (len(t.mu), 3)
    # the truth moves on: depth y_3 + N - 3 at frame N; the velocity changes with q
    assert np.allclose(t.states[:, 1], truth[1] + N - 3)
    assert np.std(t.states[:, 2]) > 0
    exact = posterior.moments(t.mu, rho, t.prior_mean, t.prior_cov, q)
    h = ekf.run(t.mu, rho, t.prior_mean, t.prior_cov, q)
    for name, depth in (("optimal", exact.depth_mean), ("ekf", h.means[:, -1, 1])):
        bias = np.mean(depth - t.states[:, 1])
        assert r["filters"][name]["depth"]["bias"] == pytest.approx(bias, rel=1e-9, abs=1e-12)
    sd = np.sqrt(exact.depth_sd**2)
    z = (t.states[:, 1] - exact.depth_mean) / sd
    assert r["filters"]["optimal"]["depth"]["coverage_95"] == pytest.approx(
        np.mean(np.abs(z) <= 1.959963984540054), abs=1e-12
    )


@pytest.mark.parametrize("q", [0.02, 10.0])
def test_with_process_noise_the_state_at_time_3_is_the_truth_given(q):
    """The velocity changes act between frames 3 .. N: frames 1-3 are the noise-free
    motion through the truth, so the first three bearings are those of three frames."""
    truth, rho, N = np.array([1.2, 6.0, 1.2]), 1 / 200, 10
    rng = np.random.default_rng(8)
    sim = model.simulate(truth, N, rho, q, rng, size=300)
    assert np.array_equal(sim.states[:, 2], np.broadcast_to(truth, (300, 3)))
    # the first three bearings are distributed as the three-frame study's: no rejection
    # beyond those of the measurement noise (none here, the noise-free solution is far)
    t = study_trials.simulate(truth, rho, 300, np.random.default_rng(8), frames=N, process_noise=q)
    three = study_trials.simulate(truth, rho, 300, np.random.default_rng(9))
    assert t.n_rejected == three.n_rejected == 0
    assert np.all(t.states[:, 1] == truth[1] + N - 3)
    # the velocity at frame N spreads with SD q sqrt(N - 3) about the truth's (5 SE)
    assert np.std(t.states[:, 2]) == pytest.approx(q * np.sqrt(N - 3), rel=5 / np.sqrt(600))


def test_study_with_large_process_noise_keeps_its_trials():
    r = monte_carlo.study(
        [1.2, 6.0, 1.2], 1 / 200, 20, seed=1, names=("ekf",), frames=10, process_noise=10.0
    )
    assert r["valid_trials"] == 20 and r["rejected_trials"] == 0


def test_a_filter_without_answer_for_some_simulated_trials_is_scored_over_the_others(capsys):
    """At q = 10 the velocity swings by 10 a frame: the second-order filter's start (the
    least misfit without process noise) is not determined on some trials. Those trials are
    counted apart, the filter scored over the others, and the table says how many."""
    args = ([1.2, 6.0, 1.2], 1 / 200, 12)
    kwargs = {"frames": 5, "process_noise": 10.0}
    r = monte_carlo.study(*args, names=("second_order", "optimal"), **kwargs)
    refused = r["filters"]["second_order"]["refused"]["count"]
    assert 0 < refused < r["valid_trials"] and r["filters"]["optimal"]["refused"]["count"] == 0
    alone = monte_carlo.study(*args, names=("optimal",), **kwargs)["filters"]["optimal"]
    assert alone["depth"]["rmse"] == r["filters"]["optimal"]["depth"]["rmse"]
    command = ["study", "--frames", "5", "--process-noise", "10", "--trials", "12"]
    command += ["--filters", "second_order", "optimal"]
    assert main([*command, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert main(command) == 0
    out = capsys.readouterr().out
    counts = [(n, f["refused"]["count"]) for n, f in data["filters"].items()]
    listed = ", ".join(f"{n} {c}" for n, c in counts if c)
    n = data["valid_trials"]
    line = f"trials refused, of {n} (each filter scored over the trials it answers): {listed}"
    assert "second_order" in listed and line in out.splitlines()


def test_study_refuses_filters_that_cannot_run_on_the_frames_or_process_noise():
    with pytest.raises(ValueError, match="names: particle cannot run"):
        monte_carlo.study(trials=5, names=("ekf", "particle"), frames=5, process_noise=0.01)
    with pytest.raises(ValueError, match="frames must be an integer from 3"):
        monte_carlo.study(trials=5, names=("ekf",), frames=2)


def test_rao_blackwellised_filter_is_scored_by_its_mixture_and_tracks_the_optimal_filter():
    """The RBPF's scores use its mixture: its mean and covariance, the particles' step
    function as the depth's CDF, the Gaussian mixture's as the velocity's; they lie near
    the optimal filter's (within its Monte Carlo error), and so does its depth density."""
    trials = study_trials.simulate(
        SCENARIOS["fig2"].c, rho=0.005, n=6, rng=np.random.default_rng(1)
    )
    out = study_trials.run_filters(
        trials, ("optimal", "rbpf"), rng=np.random.default_rng(2), n_particles=1000
    )
    o, r = out["optimal"], out["rbpf"]
    again = FILTERS["rbpf"](
        trials.mu,
        trials.rho,
        trials.prior_mean,
        trials.prior_cov,
        rng=np.random.default_rng(2),
        n_particles=1000,
    )
    t = trials.truths
    assert_allclose(r.velocity_cdf, again.detail.velocity_cdf(t[:, 2]), rtol=1e-12)
    W, depths, _, _ = again.detail.pooled()
    assert_allclose(r.depth_cdf, np.sum(W * (depths <= t[:, 1:2]), axis=1), rtol=1e-12)
    assert np.array_equal(r.mean, again.mean) and np.array_equal(r.cov, again.cov)
    # within a few of its own Monte Carlo errors where it has not collapsed (a replica
    # worth fewer than ten draws of the posterior: no error, NaN), and most have not
    ok = ~again.collapsed
    assert np.array_equal(np.isnan(again.depth_error), again.collapsed) and ok.sum() >= 4
    z = (again.depth_mean - o.mean[:, 1]) / again.depth_error
    assert np.all(np.abs(z[ok]) < 6), z
    assert_allclose(r.depth_cdf, o.depth_cdf, atol=0.1)
    assert_allclose(r.velocity_cdf, o.velocity_cdf, atol=0.1)
    assert np.all(r.hellinger < 0.2) and np.median(r.hellinger) < 0.1


def test_study_command_scores_the_rao_blackwellised_filter(capsys):
    argv = ["study", "--trials", "5", "--particles", "300", "--json"]
    assert main([*argv, "--filters", "optimal", "rbpf"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert list(data["filters"]) == ["optimal", "rbpf"]
    assert 0 <= data["filters"]["rbpf"]["hellinger_depth"]["mean"] < 0.2
    more = ["--frames", "5", "--process-noise", "0.01"]
    assert main([*argv, *more, "--filters", "optimal", "rbpf"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 5
    # a filter that cannot take the process noise is refused in one line
    assert main([*argv, *more, "--filters", "resample_move"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "resample_move cannot run" in err[0]


def test_coverage_se_is_the_binomial_standard_error():
    # a coverage of n Bernoulli(p) trials: its SD by simulation matches sqrt(p (1 - p) / n)
    rng = np.random.default_rng(11)
    p, n = 0.68, 400
    sim = rng.binomial(n, p, size=20_000) / n
    assert study_scores.coverage_se(p, n) == pytest.approx(np.std(sim), rel=0.03)
    assert_allclose(study_scores.coverage_se([0.68, 0.95], 100), np.sqrt([0.2176, 0.0475]) / 10)


def test_standard_errors_follow_their_definitions():
    trials = study_trials.simulate(SCENARIOS["fig2"].c, 1 / 200, 60, np.random.default_rng(3))
    est = study_trials.run_filters(trials, ("optimal", "ekf"))
    s = study_scores.scores(trials, est["ekf"])
    n = len(trials.mu)
    for i, q in ((1, "depth"), (2, "velocity")):
        err = est["ekf"].mean[:, i] - trials.truth[i]
        sd = np.sqrt(est["ekf"].cov[:, i, i])
        rmse = np.sqrt(np.mean(err**2))
        assert s[q]["bias_se"] == pytest.approx(np.std(err, ddof=1) / np.sqrt(n), rel=1e-9)
        assert s[q]["mean_sd_se"] == pytest.approx(np.std(sd, ddof=1) / np.sqrt(n), rel=1e-6)
        # the delta method for the square root of the mean squared error
        assert s[q]["rmse_se"] == pytest.approx(
            np.std(err**2, ddof=1) / np.sqrt(n) / (2 * rmse), rel=1e-9
        )
        for level in (68, 95):
            c = s[q][f"coverage_{level}"]
            k = round(c * n)
            assert s[q][f"coverage_{level}_se"] == study_scores.proportion_se(k, n)
            # inside the range, the plug-in binomial error to a relative O(1 / n)
            if 0 < k < n:
                plug_in = np.sqrt(c * (1 - c) / n)
                assert s[q][f"coverage_{level}_se"] == pytest.approx(
                    plug_in, rel=10 / n / min(c, 1 - c)
                )
    t = trials.truth
    err = est["ekf"].mean - t
    nees = np.einsum("ni,ni->n", err, np.linalg.solve(est["ekf"].cov, err[..., None])[..., 0])
    assert s["nees_se"] == pytest.approx(np.std(nees, ddof=1) / np.sqrt(n), rel=1e-9)
    h = est["ekf"].hellinger
    assert s["hellinger_depth"]["se"] == pytest.approx(np.std(h, ddof=1) / np.sqrt(n), rel=1e-9)


def test_standard_errors_match_the_spread_of_replicated_studies():
    # 40 independent studies of 150 trials: the SD of each score over the
    # studies estimates its standard error to about 1/sqrt(2 * 39) = 11 %, and
    # the mean of the reported SEs must agree with it to 3.5 times that.
    runs = [
        monte_carlo.study(trials=150, seed=s, names=("ekf",), prior="fixed")["filters"]["ekf"]
        for s in range(40)
    ]
    for q in ("depth", "velocity"):
        for score in ("bias", "rmse", "mean_sd", "coverage_68", "coverage_95"):
            spread = np.std([r[q][score] for r in runs], ddof=1)
            reported = np.mean([r[q][f"{score}_se"] for r in runs])
            assert reported == pytest.approx(spread, rel=0.4), (q, score, reported, spread)
    spread = np.std([r["nees"] for r in runs], ddof=1)
    assert np.mean([r["nees_se"] for r in runs]) == pytest.approx(spread, rel=0.4)


def test_pooled_squares_do_not_depend_on_the_chunks():
    # values with a large mean and a small spread, where the sum of squares
    # less n times the squared mean would lose most digits
    x = 1e4 + np.random.default_rng(1).normal(0.0, 1e-3, 1000)
    want = np.sum((x - np.mean(x)) ** 2)
    squares, total, n = 0.0, 0.0, 0
    for chunk in np.array_split(x, 7):
        squares = study_scores.pooled_squares(n, total, squares, chunk)
        total, n = total + np.sum(chunk), n + len(chunk)
    assert squares == pytest.approx(want, rel=1e-6)
    assert study_scores.mean_se(squares, n) == pytest.approx(
        np.std(x, ddof=1) / np.sqrt(n), rel=1e-6
    )
    assert study_scores.mean_se(0.0, 1) == 0.0  # one trial: no spread to estimate


def test_a_coverage_error_is_the_binomial_one_and_never_zero():
    # against the exact SD of k / n at the true p: within 10 % wherever n p (1 - p) >= 5
    for n in (50, 150, 300, 2000):
        for p in (0.05, 0.2, 0.5, 0.68, 0.95):
            if n * p * (1 - p) < 5:
                continue
            k = np.arange(n + 1)
            pmf = stats.binom.pmf(k, n, p)
            expected = np.sum(pmf * study_scores.proportion_se(k, n))
            assert expected == pytest.approx(np.sqrt(p * (1 - p) / n), rel=0.1), (n, p)
    # no trial or every trial covered: positive, below the rule of three's 95 % bound 3 / n
    for n in (20, 150, 1000):
        for k in (0, n):
            se = float(study_scores.proportion_se(k, n))
            assert 0 < se < 3 / n
    assert study_scores.proportion_se(0, 150) == pytest.approx(study_scores.proportion_se(150, 150))


def test_the_detectable_difference_is_found_with_the_stated_power():
    # Simulate the test: a coverage whose true value is 0.68 - d, over n trials,
    # fails the 1 % test against 0.68 in about 80 % of repetitions.
    n = 2000
    d = float(study_scores.detectable_difference(0.68, n))
    assert d == pytest.approx((2.5758293035489 + 0.8416212335729) * np.sqrt(0.68 * 0.32 / n))
    counts = np.random.default_rng(0).binomial(n, 0.68 - d, size=20000) / n
    fails = np.abs(counts - 0.68) > 2.5758293035489 * study_scores.coverage_se(0.68, n)
    assert np.mean(fails) == pytest.approx(0.8, abs=0.02)  # binomial SE of 20,000 tests: 0.003
    with pytest.raises(ValueError, match="power must lie in"):
        study_scores.detectable_difference(0.68, n, power=1.0)


@pytest.mark.parametrize(
    "se, level, step",
    [(0.01, 0.68, 100), (0.005, 0.95, 100), (0.02, 0.5, 1), (0.0033, 0.68, 50), (0.3, 0.68, 100)],
)
def test_trials_for_se_is_the_fewest_multiple_that_reaches_the_se(se, level, step):
    # The binomial SE sqrt(p (1 - p) / n) at the returned n is at most se, one step fewer is not.
    n = study_scores.trials_for_se(se, level, step)
    assert n % step == 0 and n >= step
    assert np.sqrt(level * (1 - level) / n) <= se
    if n > step:
        assert np.sqrt(level * (1 - level) / (n - step)) > se


def test_trials_for_se_gives_the_books_2200_and_refuses_in_one_line():
    assert study_scores.trials_for_se(0.01) == 2200
    assert study_scores.coverage_se(0.68, 2200) < 0.01 < study_scores.coverage_se(0.68, 2100)
    for kwargs, name in (
        ({"se": 0.0}, "se"),
        ({"se": float("nan")}, "se"),
        ({"se": 0.01, "level": 1.0}, "level"),
        ({"se": 0.01, "step": 0}, "step"),
        ({"se": 0.01, "step": 2.5}, "step"),
    ):
        with pytest.raises(ValueError, match=f"^{name} must"):
            study_scores.trials_for_se(**kwargs)
