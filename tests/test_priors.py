"""The prior's forms: their laws, their Gaussians, and the studies that draw truths from them."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, stats

from depthcore.cli.main import main
from depthcore.problem import checks, model
from depthcore.registry.filters import FILTERS
from depthcore.studies import monte_carlo, priors, trials

#: A state at frame 1: Figure 2's truth moved back two frames.
CENTRE = np.array([-1.2, 4.0, 1.2])
RHO = 0.005


def _draws(form, n=100_000, seed=3):
    return priors.draw(form, CENTRE, RHO, n, np.random.default_rng(seed))


@pytest.mark.parametrize("form", priors.DRAWN)
def test_drawn_truths_have_the_mean_and_covariance_of_the_stated_gaussian(form):
    s = _draws(form)
    mean, cov = priors.gaussian(form, CENTRE, RHO)
    n = len(s)
    se_mean = s.std(axis=0, ddof=1) / np.sqrt(n)
    assert np.all(np.abs(s.mean(axis=0) - mean) < 4 * se_mean), (s.mean(axis=0), mean)
    d = s - s.mean(axis=0)
    for i in range(3):
        for j in range(i, 3):
            products = d[:, i] * d[:, j]
            se = products.std(ddof=1) / np.sqrt(n)
            assert abs(products.mean() - cov[i, j]) < 4 * se + 1e-12, (i, j)


@pytest.mark.parametrize("form", priors.DRAWN)
def test_every_drawn_depth_is_in_front_of_the_camera_and_within_its_limits(form):
    y = _draws(form, 200_000)[:, 1]
    assert np.all(np.isfinite(y)) and np.all(y > 0)
    if form == "range":
        assert y.min() >= priors.RANGE_NEAREST * CENTRE[1] * (1 - 1e-12)
    if form == "inverse_depth":
        lo, hi = priors.INVERSE_DEPTH_LIMITS
        assert np.all((1 / y >= lo / CENTRE[1] * (1 - 1e-12)) & (1 / y <= hi / CENTRE[1]))


def test_the_log_uniform_depths_pass_a_ks_test_of_their_law_and_the_range_ones_fail_it():
    half = np.log(priors.LOG_UNIFORM_RATIO) / 2
    law = stats.uniform(np.log(CENTRE[1]) - half, 2 * half)
    assert stats.kstest(np.log(_draws("log_uniform")[:, 1]), law.cdf).pvalue > 0.01
    assert stats.kstest(np.log(_draws("range")[:, 1]), law.cdf).pvalue < 1e-6


def test_the_inverse_depth_is_a_truncated_gaussian_by_a_ks_test():
    w = 1 / _draws("inverse_depth")[:, 1]
    w0 = 1 / CENTRE[1]
    lo, hi = priors.INVERSE_DEPTH_LIMITS
    sd = priors.INVERSE_DEPTH_SD * w0
    law = stats.truncnorm((lo * w0 - w0) / sd, (hi * w0 - w0) / sd, loc=w0, scale=sd)
    assert stats.kstest(w, law.cdf).pvalue > 0.01


def test_the_depth_moments_match_scipy_and_quadrature():
    m = CENTRE[1]
    s = priors.RANGE_SD * m
    tn = stats.truncnorm((priors.RANGE_NEAREST * m - m) / s, np.inf, loc=m, scale=s)
    assert priors.depth_moments("range", m) == pytest.approx((tn.mean(), tn.moment(2)), rel=1e-12)
    lo, hi = m / np.sqrt(priors.LOG_UNIFORM_RATIO), m * np.sqrt(priors.LOG_UNIFORM_RATIO)

    def log_uniform(k):
        return integrate.quad(lambda y: y**k / (y * np.log(hi / lo)), lo, hi, epsabs=0)[0]

    assert priors.depth_moments("log_uniform", m) == pytest.approx(
        (log_uniform(1), log_uniform(2)), rel=1e-10
    )
    w0 = 1 / m
    sd = priors.INVERSE_DEPTH_SD * w0
    a, b = [(lim * w0 - w0) / sd for lim in priors.INVERSE_DEPTH_LIMITS]
    law = stats.truncnorm(a, b, loc=w0, scale=sd)

    def inverse(k):
        lo, hi = law.support()
        return integrate.quad(lambda w: w**-k * law.pdf(w), lo, hi, points=[w0], epsabs=0)[0]

    assert priors.depth_moments("inverse_depth", m) == pytest.approx(
        (inverse(1), inverse(2)), rel=1e-9
    )


def test_the_gaussians_are_positive_definite_and_centred_on_the_bearing_and_speed():
    for form in priors.DRAWN:
        mean, cov = priors.gaussian(form, CENTRE, RHO)
        assert np.allclose(cov, cov.T) and np.linalg.eigvalsh(cov)[0] > 0
        assert mean[0] / mean[1] == pytest.approx(CENTRE[0] / CENTRE[1], rel=1e-12)
        assert mean[2] == CENTRE[2] and cov[2, 2] == priors.SPEED_SD**2


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: priors.gaussian("paper", CENTRE, RHO), "form"),
        (lambda: priors.draw("flat", CENTRE, RHO, 5, np.random.default_rng(0)), "form"),
        (lambda: priors.gaussian("range", [1.0, -4.0, 0.0], RHO), "centre"),
        (lambda: priors.gaussian("range", [1.0, 4.0], RHO), "centre"),
        (lambda: priors.gaussian("range", CENTRE, 0.0), "rho"),
        (lambda: priors.draw("range", CENTRE, RHO, 0, np.random.default_rng(0)), "n"),
        (lambda: priors.check("flat"), "prior"),
        (
            lambda: trials.simulate(model.G(CENTRE, 2), RHO, 5, np.random.default_rng(0), "x"),
            "prior",
        ),
    ],
)
def test_refusals_name_the_argument_in_one_line(call, name):
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert message.startswith(name) and "\n" not in message, message


def test_simulate_draws_each_trials_truth_from_the_prior_before_its_bearings():
    truth = model.G(CENTRE, 2)
    t = trials.simulate(truth, RHO, 400, np.random.default_rng(7), "log_uniform")
    start = priors.draw("log_uniform", CENTRE, RHO, 400, np.random.default_rng(7))
    n_kept = len(t.mu)
    assert n_kept + t.n_rejected == 400 and t.n_rejected > 0
    kept = model.valid_measurements(t.mu[:, :3])
    assert np.all(kept)
    # the kept truths are draws from the prior, in order, moved on to time 3
    back = model.G(t.states, -2)
    match = np.abs(back[:, None, 1] - start[None, :, 1]).argmin(axis=1)
    assert np.all(np.diff(match) > 0)
    assert np.allclose(back, start[match], rtol=1e-13, atol=1e-13)
    assert np.array_equal(t.truths, t.states)
    mean, cov = priors.gaussian("log_uniform", CENTRE, RHO)
    assert np.array_equal(t.prior_mean, np.tile(mean, (n_kept, 1)))
    assert np.array_equal(t.prior_cov, cov)
    # the bearings are those of each trial's own truth
    resid = t.mu - model.project(model.G(t.states[:, None, :], np.arange(3) - 2.0))
    assert np.abs(resid).max() < 6 * RHO


def test_simulate_with_frames_and_process_noise_follows_each_drawn_truth():
    truth = model.G(CENTRE, 2)
    t = trials.simulate(
        truth, RHO, 50, np.random.default_rng(1), "range", frames=6, process_noise=0.01, tracks=True
    )
    assert t.tracks.shape == (len(t.mu), 6, 3)
    assert np.array_equal(t.states, t.tracks[:, -1, :])
    assert np.allclose(t.tracks[:, 0, 1] + 5, t.states[:, 1])


def test_a_study_scores_each_trial_against_its_own_truth():
    truth = model.G(CENTRE, 2)
    out = monte_carlo.study(truth, RHO, trials=150, seed=4, prior="range", names=("ekf",))
    noise_seed, _ = checks.spawn(4, 2)
    rng = np.random.default_rng(noise_seed)
    parts = [
        trials.simulate(truth, RHO, 100, rng, "range"),
        trials.simulate(truth, RHO, 50, rng, "range"),
    ]
    errors = []
    for p in parts:
        est = FILTERS["ekf"](p.mu, RHO, p.prior_mean, p.prior_cov)
        errors.append(est.depth_mean - p.states[:, 1])
    errors = np.concatenate(errors)
    assert out["valid_trials"] == len(errors)
    assert out["filters"]["ekf"]["depth"]["rmse"] == pytest.approx(
        np.sqrt(np.mean(errors**2)), rel=1e-12
    )
    mean, cov = priors.gaussian("range", CENTRE, RHO)
    assert out["prior_gaussian"] == {"mean": mean.tolist(), "cov": cov.tolist()}


def test_the_paper_rule_draws_no_truths():
    truth = model.G(CENTRE, 2)
    t = trials.simulate(truth, RHO, 20, np.random.default_rng(0), "paper")
    assert t.states is None and np.array_equal(t.truths[0], truth)
    assert "prior_gaussian" not in monte_carlo.study(truth, RHO, trials=5, names=("ekf",))


def test_the_command_line_takes_the_forms(capsys):
    argv = ["study", "--trials", "20", "--filters", "ekf", "--prior", "range", "--json"]
    assert main(argv) == 0
    assert '"prior": "range"' in capsys.readouterr().out
    assert main(["study", "--truth", "prior", "--prior", "range", "--trials", "5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--prior" in err, err


@pytest.mark.parametrize("form", priors.DRAWN)
def test_each_drawn_forms_law_has_the_filters_gaussian_and_the_draws_depths(form):
    centre, rho = np.array([4.0, 20.0, 0.5]), 0.01
    law = priors.law(form, centre, rho)
    mean, cov = priors.gaussian(form, centre, rho)
    own_mean, own_cov = law.gaussian()
    assert np.allclose(own_mean, mean, rtol=1e-9, atol=1e-12)
    assert np.allclose(own_cov, cov, rtol=1e-8, atol=1e-12)
    # the same uniforms give the same depths: the law's quantiles are the study's
    a = law.draw_depths(1000, np.random.default_rng(4))
    b = priors.draw_depths(form, centre[1], 1000, np.random.default_rng(4))
    assert np.allclose(a, b, rtol=1e-12)
    assert not np.allclose(
        priors.law("log_uniform" if form != "log_uniform" else "range", centre, rho).gaussian()[1],
        cov,
    )
