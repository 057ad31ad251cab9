"""The standard error of an RMS error (depthbook.errors.rms_se) against a direct simulation.

Many independent studies of ``R`` runs each are simulated; the SD of their
RMS errors is the standard error that :func:`depthbook.errors.rms_se`
estimates from one study's runs alone. The delta method is first order: with
the page's 20 runs its mean estimate falls short of the simulated SD by about
a tenth for normal errors and a seventh for Student t errors with 8 degrees of
freedom; with 100 runs it is within a tenth for both.
"""

import numpy as np
import pytest

from depthbook.errors import rms_se

#: Simulated studies per case.
STUDIES = 20_000
DRAWS = {
    "normal": lambda rng, shape: rng.normal(0.0, 0.3, shape),
    "biased-normal": lambda rng, shape: rng.normal(0.1, 0.3, shape),
    "student-t-8": lambda rng, shape: 0.3 * rng.standard_t(8, shape),
}


@pytest.mark.parametrize("name", sorted(DRAWS))
@pytest.mark.parametrize(("runs", "low", "high"), [(20, 0.8, 1.0), (100, 0.9, 1.05)])
def test_the_se_matches_the_spread_of_simulated_rms_errors(name, runs, low, high):
    rng = np.random.default_rng(2026)
    errors = DRAWS[name](rng, (STUDIES, runs))
    rms, se = rms_se(errors, axis=1)
    assert rms.shape == se.shape == (STUDIES,)
    assert np.allclose(rms, np.sqrt(np.mean(errors**2, axis=1)))
    assert low < np.mean(se) / np.std(rms, ddof=1) < high


def test_normal_errors_give_about_rms_over_sqrt_2r():
    rng = np.random.default_rng(7)
    rms, se = rms_se(rng.normal(0.0, 2.0, (4000, 200)), axis=-1)
    assert np.median(se / rms) == pytest.approx(1 / np.sqrt(2 * 200), rel=0.05)


def test_axis_zero_errors_and_refusals():
    rms, se = rms_se(np.zeros((5, 3)), axis=0)
    assert np.all(rms == 0) and np.all(se == 0)
    rms, se = rms_se([3.0, -3.0, 3.0])
    assert rms == pytest.approx(3.0) and se == pytest.approx(0.0)
    with pytest.raises(ValueError, match="two runs"):
        rms_se([1.0])
    with pytest.raises(ValueError, match="finite"):
        rms_se([1.0, np.nan])


def test_the_convergence_figure_draws_bars_only_with_standard_errors():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from depthbook.beyond_particles import SETTINGS, convergence_figure

    sizes = np.array([100, 1000])
    moments = ("depth_mean", "depth_sd", "velocity_mean", "velocity_sd")
    result = {
        "sizes": sizes,
        "repeats": 20,
        "exact": dict.fromkeys(moments, 1.0),
        "rmse": {name: dict.fromkeys(moments, np.array([0.1, 0.03])) for name in SETTINGS},
    }
    plain = convergence_figure(result)
    assert not any(
        c.__class__.__name__ == "ErrorbarContainer" for ax in plain.axes for c in ax.containers
    )
    result["rmse_se"] = {name: dict.fromkeys(moments, np.array([0.01, 0.005])) for name in SETTINGS}
    barred = convergence_figure(result)
    bars = [c for c in barred.axes[0].containers if c.__class__.__name__ == "ErrorbarContainer"]
    assert len(bars) == len(SETTINGS)
    plt.close("all")
