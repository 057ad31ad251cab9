"""The live controls of the figure pages (depthbook.live): bearings, marginals, redraw."""

from __future__ import annotations

import base64

import numpy as np
import pytest

from depthbook import beyond_frames, live
from depthcore import SCENARIOS
from depthcore.problem import checks, model
from depthcore.registry.filters import FILTERS

FIG2 = SCENARIOS["fig2"]


def test_bearings_continue_the_noise_free_track_of_c():
    mu = np.array(FIG2.mu)
    out = live.bearings(mu, 7)
    c = model.noise_free_state(mu)
    # frame k of the point at c at frame 3: (c1 + (k - 3) c3, c2 + k - 3, c3), Eq. (1)
    k = np.arange(4, 8)
    expected = (c[0] + (k - 3) * c[2]) / (c[1] + k - 3)
    np.testing.assert_array_equal(out[:3], mu)
    np.testing.assert_allclose(out[3:], expected, rtol=1e-14)
    np.testing.assert_array_equal(live.bearings(mu, 3), mu)


@pytest.mark.parametrize("frames", [2, 0, checks.MAX_FRAMES + 1, 3.5])
def test_bearings_refuse_a_number_of_frames_out_of_range(frames):
    with pytest.raises(ValueError, match="frames"):
        live.bearings(FIG2.mu, frames)


def test_three_frames_give_the_registry_filters_on_the_page():
    for key in ("fig2", "fig6"):
        s = SCENARIOS[key]
        drawn = live.depth_marginals(s.mu, s.rho, s.prior.mean, s.prior.cov)
        assert drawn["frames"] == 3 and list(drawn["density"]) == list(live.NAMES)
        for name in live.NAMES:
            e = FILTERS[name](s.mu, s.rho, s.prior.mean, s.prior.cov)
            assert drawn["depth_mean"][name] == pytest.approx(float(e.depth_mean), rel=1e-12)
            assert drawn["depth_sd"][name] == pytest.approx(float(e.depth_sd), rel=1e-12)
            # a density on a grid of +-5 SDs of every filter: mass 1 up to the tails
            # (the optimal marginal's long right tail holds about 1e-4 beyond)
            mass = np.trapezoid(drawn["density"][name], drawn["grid"])
            assert 0.999 < mass < 1 + 1e-6, (key, name, mass)


@pytest.mark.parametrize("frames", [5, 12])
def test_more_frames_agree_with_the_frame_marginals_of_the_experiments(frames):
    # beyond_frames.frame_marginals applies the paper's prior rule to the first three
    # bearings, as Figure 2's prior is: the same filters on the same bearings.
    mu = live.bearings(FIG2.mu, frames)
    drawn = live.depth_marginals(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, frames)
    (ref,) = beyond_frames.frame_marginals(mu, FIG2.rho, [frames], names=live.NAMES)
    np.testing.assert_array_equal(drawn["mu"], mu)
    for name in live.NAMES:
        assert drawn["depth_mean"][name] == pytest.approx(ref["depth_mean"][name], rel=1e-10)
        assert drawn["depth_sd"][name] == pytest.approx(ref["depth_sd"][name], rel=1e-10)
    # the depth advances one unit per frame: the estimates sit near c2 + N - 3
    assert drawn["depth_mean"]["optimal"] == pytest.approx(FIG2.c[1] + frames - 3, abs=0.5)


def test_depth_marginals_refuse_random_filters_and_bad_grids():
    args = (FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    with pytest.raises(ValueError, match="names"):
        live.depth_marginals(*args, names=("optimal", "particle"))
    with pytest.raises(ValueError, match="filter must|filters must"):
        live.depth_marginals(*args, names=("kalman",))
    with pytest.raises(ValueError, match="n_points"):
        live.depth_marginals(*args, n_points=0)
    with pytest.raises(ValueError, match="width"):
        live.depth_marginals(*args, width=-1.0)


def test_figure_draws_each_filter_with_its_style():
    fig = live.figure(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov, frames=4, title="t")
    (ax,) = fig.axes
    assert [line.get_label() for line in ax.lines] == [FILTERS[n].label for n in live.NAMES]
    assert ax.get_xlabel() == "depth $y$ at frame 4" and ax.get_title() == "t"


def test_controls_redraw_the_marginals_of_the_sliders_values():
    pytest.importorskip("ipywidgets")
    s = SCENARIOS["fig6"]
    panel = live.controls(s.mu, s.rho, s.prior.mean, s.prior.cov)
    setting = panel.setting()
    np.testing.assert_allclose(setting["prior_mean"], s.prior.mean)
    np.testing.assert_allclose(setting["prior_cov"], s.prior.cov)
    assert setting["rho"] == pytest.approx(s.rho) and setting["frames"] == 3
    before = panel.ax.lines[0].get_ydata().copy()
    (shown,) = panel.output.outputs
    assert shown["output_type"] == "display_data"
    assert base64.b64decode(shown["data"]["image/png"]).startswith(b"\x89PNG")

    panel.sliders["frames"].value = 6
    panel.sliders["mean_y"].value = s.prior.mean[1] + 1.0
    drawn = live.depth_marginals(**panel.setting())
    assert panel.message == "" and panel.ax.get_xlabel() == "depth $y$ at frame 6"
    for line, name in zip(panel.ax.lines, live.NAMES, strict=True):
        np.testing.assert_array_equal(line.get_xdata(), drawn["grid"])
        np.testing.assert_array_equal(line.get_ydata(), drawn["density"][name])
    assert not np.array_equal(panel.ax.lines[0].get_ydata(), before)
    assert len(panel.widget.children) == 4
    (redrawn,) = panel.output.outputs  # the output holds the redrawn figure, not both
    assert redrawn["data"]["image/png"] != shown["data"]["image/png"]


def test_controls_show_a_refusal_instead_of_a_traceback():
    pytest.importorskip("ipywidgets")
    panel = live.controls([0.1, 0.1, 0.1], FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    assert panel.message.startswith("mu is degenerate") and not panel.ax.lines
    assert panel.ax.get_title() == panel.message
