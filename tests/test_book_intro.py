"""The intro's headline of the extensions: texts only where the study bears them out."""

from __future__ import annotations

import numpy as np
import pytest

from depthbook import intro
from depthcore import SCENARIOS
from depthcore.analysis import bound
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE

TRIALS = 400


def _bound_sd():
    fig2 = SCENARIOS["fig2"]
    b = bound.posterior_bound(
        fig2.c, 3, int(intro.BOUND_FRAMES[-1]), fig2.rho, PAPER_PRIOR_SCALE * np.eye(3)
    )
    return np.sqrt(b[intro.BOUND_FRAMES - 1, 1, 1])


def _study(ekf_sd_scale: float, ekf_error_scale: float) -> dict:
    """A synthetic study: filters on the bound, and an EKF scaled from it."""
    rng = np.random.default_rng(0)
    sd = _bound_sd()[:, None] * np.ones((1, TRIALS))
    # errors drawn at the bound's SD, rescaled so their RMS is the bound exactly
    z = rng.standard_normal(sd.shape)
    z /= np.sqrt(np.mean(z**2, axis=-1, keepdims=True))
    # stated SDs a little above the bound (exactly on it, rounding may put them below)
    on = {"depth_error": sd * z, "depth_sd": 1.02 * sd}
    ekf = {"depth_error": ekf_error_scale * sd * z, "depth_sd": ekf_sd_scale * sd}
    return {"second_order": on, "iterated": on, "ekf": ekf}


def test_bound_texts_state_the_ekf_overconfident_and_off_and_the_others_on_the_bound():
    texts = intro.bound_texts(_study(ekf_sd_scale=0.25, ekf_error_scale=2.5))
    assert texts["trials"] == f"{TRIALS}"
    assert texts["ekf_sd3"] == "0.25" and texts["ekf_rmse"] == "2.5"
    assert texts["n_first"] == f"{intro.BOUND_FRAMES[0]}"


@pytest.mark.parametrize("sd_scale, error_scale", [(1.0, 2.5), (0.25, 1.0)])
def test_bound_texts_refuse_a_study_that_does_not_bear_them_out(sd_scale, error_scale):
    # an honest EKF, or one on the bound, is not the headline's
    with pytest.raises(ValueError, match="does not bear out"):
        intro.bound_texts(_study(sd_scale, error_scale))
