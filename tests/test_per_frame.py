"""Every filter scored at every frame (depthbook.studies.per_frame), against independent routes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from depthbook.studies import per_frame
from depthcore import SCENARIOS
from depthcore.analysis import bound
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE
from depthcore.registry.filters import FILTERS
from depthcore.studies import monte_carlo, scores, tasks
from depthcore.studies.trials import Trials, simulate

FIG2 = SCENARIOS["fig2"]
NAMES = ("optimal", "second_order", "ekf", "inverse_depth", "ukf")


def _walk(a, b, path=""):
    """Assert two results equal bit for bit (NaN equal to NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for key in a:
            _walk(a[key], b[key], f"{path}/{key}")
    elif isinstance(a, (list, tuple, np.ndarray)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=path, strict=True)
    else:
        assert a == b or (a != a and b != b), path


def test_anees_region_is_the_chi_square_of_m_times_three_degrees_over_m():
    # the quantiles: M * lo and M * hi leave 2.5 % either side of chi2(3 M)
    for m in (1, 10, 2000):
        lo, hi = scores.anees_region(m)
        assert stats.chi2.cdf(m * lo, 3 * m) == pytest.approx(0.025, abs=1e-9)
        assert stats.chi2.sf(m * hi, 3 * m) == pytest.approx(0.025, abs=1e-9)
    # and by simulation: the mean NEES of M Gaussian errors of covariance I lies in it 95 %
    rng = np.random.default_rng(0)
    m, reps = 10, 20_000
    anees = np.mean(np.sum(rng.standard_normal((reps, m, 3)) ** 2, axis=-1), axis=-1)
    lo, hi = scores.anees_region(m)
    inside = np.mean((anees >= lo) & (anees <= hi))
    assert abs(inside - 0.95) < 4 * np.sqrt(0.95 * 0.05 / reps)
    # many trials: the normal approximation 3 +- 1.96 sqrt(6 / M)
    lo, hi = scores.anees_region(20_000)
    half = 1.959964 * np.sqrt(6 / 20_000)
    assert lo == pytest.approx(3 - half, abs=2e-3) and hi == pytest.approx(3 + half, abs=2e-3)
    (lo10, hi10), (lo, hi) = scores.anees_region(10), scores.anees_region(2000)
    assert lo10 < lo < 3 < hi < hi10
    for bad in (0, 2.5, "3"):
        with pytest.raises(ValueError, match="trials"):
            scores.anees_region(bad)
    with pytest.raises(ValueError, match="level"):
        scores.anees_region(10, level=1.0)


@pytest.mark.parametrize("name", ["ekf", "ukf", "iterated", "second_order", "inverse_depth"])
def test_frame_states_equal_the_filter_run_on_the_first_k_bearings(name):
    sim = model_tracks(8, 6, 0.02)
    frames = np.arange(3, 7)
    means, covs = per_frame.frame_states(
        name, sim.mu, sim.rho, sim.prior_mean, sim.prior_cov, frames, 0.02
    )
    assert means.shape == (4, len(sim.mu), 3) and covs.shape == (4, len(sim.mu), 3, 3)
    for i, k in enumerate(frames):
        est = FILTERS[name](sim.mu[:, :k], sim.rho, sim.prior_mean, sim.prior_cov, 0.02)
        np.testing.assert_allclose(means[i], est.mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(covs[i], est.cov, rtol=1e-12, atol=1e-12)


def model_tracks(n, frames, q, seed=4):
    return simulate(
        FIG2.c,
        FIG2.rho,
        n,
        np.random.default_rng(seed),
        "paper",
        frames=frames,
        process_noise=q,
        tracks=True,
    )


@pytest.mark.parametrize("q", [0.0, 0.02])
def test_each_frame_scores_as_the_study_at_that_many_frames_on_the_same_bearings(q):
    n_frames, trials, seed = 7, per_frame.BLOCK, 11
    r = per_frame.per_frame_study(n_frames, trials, seed, NAMES, "paper", q)
    # the one block's trials, drawn as documented: the block's seed is child 0 of child 0
    noise_seed = np.random.SeedSequence(seed).spawn(2)[0].spawn(1)[0]
    part = simulate(
        FIG2.c,
        FIG2.rho,
        trials,
        np.random.default_rng(noise_seed),
        "paper",
        frames=n_frames,
        process_noise=q,
        tracks=True,
    )
    assert r["valid_trials"] == len(part.mu) and r["rejected_trials"] == part.n_rejected
    for i, k in enumerate(range(3, n_frames + 1)):
        at_k = Trials(
            part.truth,
            part.rho,
            part.mu[:, :k],
            part.prior_mean,
            part.prior_cov,
            part.n_rejected,
            q,
            part.tracks[:, k - 1],
        )
        _, estimates = monte_carlo.filter_chunk((at_k, NAMES, None, 10))
        for name in NAMES:
            want = scores.scores(at_k, estimates[name])
            got = r["filters"][name]
            for qty in ("depth", "velocity"):
                for key in ("bias", "bias_se", "rmse", "rmse_se", "mean_sd", "mean_sd_se"):
                    assert got[qty][key][i] == pytest.approx(want[qty][key], rel=1e-9), (
                        name,
                        k,
                        qty,
                        key,
                    )
            assert got["nees"][i] == pytest.approx(want["nees"], rel=1e-9)
            assert got["nees_se"][i] == pytest.approx(want["nees_se"], rel=1e-9)
            half = list(got["track_loss"]["levels"]).index(scores.TRACK_LOSS)
            assert got["track_loss"]["fraction"][half, i] == want["track_loss"]["fraction"]
            assert got["track_loss"]["upper"][half, i] == pytest.approx(
                want["track_loss"]["upper"], rel=1e-9
            )
            # every threshold, and the RMSE over the tracks kept, from the estimates directly
            est = estimates[name]
            truth = part.tracks[:, k - 1]
            err = est.mean - truth
            for j, t in enumerate(got["track_loss"]["levels"]):
                lost = scores.lost_tracks(est.mean, truth, t)
                assert got["track_loss"]["lost"][j, i] == np.count_nonzero(lost)
                kept = err[~lost, 1]
                if kept.size > 1:
                    rmse = np.sqrt(np.mean(kept**2))
                    se = np.std(kept**2, ddof=1) / np.sqrt(kept.size) / (2 * rmse)
                    loss = got["track_loss"]["depth"]
                    assert loss["rmse_kept"][j, i] == pytest.approx(rmse, rel=1e-9)
                    assert loss["rmse_kept_se"][j, i] == pytest.approx(se, rel=1e-7)
            nees = np.einsum("ni,ni->n", err, np.linalg.solve(est.cov, err[..., None])[..., 0])
            lo, hi = stats.chi2.ppf([0.025, 0.975], 3)
            outside = np.mean((nees < lo) | (nees > hi))
            assert got["nees_outside"][i] == pytest.approx(outside, abs=1e-12)
    b = bound.posterior_bound(FIG2.c, 3, n_frames, FIG2.rho, PAPER_PRIOR_SCALE * np.eye(3), q)
    np.testing.assert_allclose(r["bound"]["depth"], np.sqrt(b[2:, 1, 1]), rtol=1e-15)
    assert r["filters"]["ekf"]["anees_region"] == list(scores.anees_region(len(part.mu)))


def test_the_result_is_the_same_bit_for_bit_whatever_the_chunks_and_the_workers():
    args = (6, 3 * per_frame.BLOCK + 7, 2, ("optimal", "ekf", "rbpf"), "paper", 0.02)
    more = {"particle_trials": 60, "n_particles": 50}
    one = per_frame.per_frame_study(*args, chunk=per_frame.BLOCK, **more)
    assert one["filters"]["rbpf"]["trials"] <= 60 < one["filters"]["ekf"]["trials"]
    _walk(one, per_frame.per_frame_study(*args, chunk=4 * per_frame.BLOCK, **more))
    with tasks.cluster(workers=2) as client:
        _walk(one, per_frame.per_frame_study(*args, chunk=per_frame.BLOCK, client=client, **more))


def test_track_loss_falls_as_the_threshold_grows_and_keeps_every_track_beyond_all_errors():
    r = per_frame.per_frame_study(5, 60, 3, ("ekf",), levels=(0.05, 0.5, 1e9))
    loss = r["filters"]["ekf"]["track_loss"]
    assert np.all(np.diff(loss["lost"], axis=0) <= 0) and np.all(loss["lost"][-1] == 0)
    assert loss["upper"].shape == (3, 3) and np.all(loss["upper"] >= loss["fraction"])
    np.testing.assert_allclose(
        loss["depth"]["rmse_kept"][-1], r["filters"]["ekf"]["depth"]["rmse"], rtol=1e-12
    )


def test_refusals_name_the_argument():
    for kwargs, word in (
        ({"chunk": per_frame.BLOCK + 1}, "chunk"),
        ({"frames": 2}, "frames"),
        ({"trials": 1}, "trials"),
        ({"names": ("nope",)}, "filters"),
        ({"names": ("particle",), "process_noise": 0.1}, "names"),
        ({"levels": (0.5, -1.0)}, "levels"),
    ):
        args = {"frames": 5, "trials": 10, "seed": 1, **kwargs}
        with pytest.raises(ValueError, match=word):
            per_frame.per_frame_study(**args)
