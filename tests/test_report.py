"""The texts of depthcore.report: tables, vectors and glued numbers."""

import re

import numpy as np
import pytest

from depthcore import (
    SCENARIOS,
    ekf,
    experiments,
    optimal,
    report,
    reproduce,
    study,
)
from depthcore.scenarios import REPORTED

FIG2 = SCENARIOS["fig2"]


def test_comparison_rows_of_figure_2():
    rows = {r["id"]: r for r in report.comparison("fig2")}
    assert list(rows) == [r[0] for r in report.TABLE_ROWS]
    assert rows["opt"]["reported_mean"] == REPORTED["fig2"]["optimal"]["depth"][0]
    assert rows["so"]["sd"] == pytest.approx(0.6163, abs=1e-4)
    assert rows["so_printed"]["sd"] == pytest.approx(0.4358, abs=1e-4)
    assert rows["so"]["sd_matches"] and not rows["so_printed"]["sd_matches"]
    texts = report.comparison_texts("fig2", list(rows.values()))
    assert texts["fig2_opt_mean"] == "6.4660"
    assert texts["fig2_opt_paper_mean"] == "6.47"
    assert texts["fig2_so_printed_agrees"] == "mean only"
    assert texts["fig2_ekf_agrees"] == "yes"


def test_comparison_rows_of_figure_3_and_4():
    rows = {r["id"]: r for r in report.comparison("fig3")}
    texts = report.comparison_texts("fig3", list(rows.values()))
    assert texts["fig3_opt_agrees"] == "no"
    assert texts["fig3_opt_printed_mean"] == "67.4516"
    assert texts["fig3_opt_printed_agrees"] == "mean only"
    rows4 = report.comparison("fig4")
    assert {r["quantity"] for r in rows4} == {"velocity"}
    texts4 = report.comparison_texts("fig4", rows4)
    assert texts4["fig4_opt_paper_mean"] == "—" and texts4["fig4_opt_agrees"] == "—"


def test_vec_formats_and_never_prints_negative_zero():
    assert report.vec([1.2, 6, -1.2]) == "(1.2000, 6.0000, -1.2000)"
    assert report.vec([-0.0, -1e-9, 0.25], 2) == "(0.00, 0.00, 0.25)"
    assert report.vec(np.array([2.0]), 0) == "(2)"
    with pytest.raises(ValueError, match="1-D"):
        report.vec(np.eye(2))
    with pytest.raises(ValueError, match="decimals"):
        report.vec([1.0], -1)


def test_rho_label():
    assert report.rho_label(1 / 200) == "1/200"
    assert report.rho_label(0.001) == "1/1000"
    with pytest.raises(ValueError):
        report.rho_label(0.0)


PM = re.compile(r"^-?\d+\.\d{3} ± \d+\.\d{3}$")


def test_moments_texts_cover_every_filter_and_scenario():
    result = reproduce.reproduce()
    texts = report.moments_texts(result)
    n = len(SCENARIOS) * len(reproduce.FILTERS) * 2 + len(SCENARIOS) * 2
    assert len(texts) == n
    assert all(PM.match(v) for k, v in texts.items() if not k.endswith("_se"))
    m = optimal.marginals(FIG2.mu, FIG2.rho, FIG2.prior)
    assert texts["bf_fig2_optimal_depth"] == f"{m.depth_mean:.3f} ± {m.depth_sd:.3f}"
    ekf_y = ekf.ekf(FIG2.mu, FIG2.rho, FIG2.prior).posterior.marginal("y")
    assert texts["bf_fig2_ekf_depth"] == f"{ekf_y[0]:.3f} ± {ekf_y[1]:.3f}"


def test_moments_texts_reject_ambiguous_rows():
    result = reproduce.reproduce(["fig2"])
    rows = result["scenarios"][0]["rows"]
    rows.append(dict(rows[-1]))  # a second particle row
    with pytest.raises(ValueError, match="expected one row of 'particle'"):
        report.moments_texts(result)


def test_study_texts_have_every_score():
    r = study.study(trials=20, seed=0, names=("optimal", "ekf"))
    texts = report.study_texts(r, "s")
    assert texts["s_trials"] == str(r["valid_trials"])
    assert texts["s_ekf_depth_coverage_68"] == f"{r['filters']['ekf']['depth']['coverage_68']:.2f}"
    assert texts["s_ekf_nees"] == f"{r['filters']['ekf']['nees']:.1f}"
    assert len(texts) == 1 + 2 * (2 * len(report.STUDY_DECIMALS) + 2)


def test_sweep_texts_label_the_rows():
    r = experiments.noise_sweep([1 / 1000, 1 / 200])
    texts = report.sweep_texts(r, "rho", "ns")
    assert texts["ns_0_x"] == "1/1000" and texts["ns_1_x"] == "1/200"
    assert texts["ns_1_optimal"] == (
        f"{r['optimal']['depth_mean'][1]:.3f} ± {r['optimal']['depth_sd'][1]:.3f}"
    )
    assert texts["ns_0_ekf_h"] == f"{r['ekf']['hellinger'][0]:.3f}"
    off = report.sweep_texts(experiments.prior_offset_sweep([-1.0, 2.0]), "offset", "po")
    assert off["po_0_x"] == "-1" and off["po_1_x"] == "2"
    with pytest.raises(ValueError, match="x must be"):
        report.sweep_texts(r, "noise", "ns")


def test_noise_study_texts():
    r = experiments.noise_study([1 / 200], trials=20, seed=0, names=("second_order",))
    texts = report.noise_study_texts(r, "mc")
    assert texts["mc_0_x"] == "1/200"
    assert texts["mc_0_trials"] == str(r["valid_trials"][0])
    assert texts["mc_0_second_order_cov68"] == f"{r['second_order']['coverage_68'][0]:.2f}"
    assert set(texts) == {"mc_0_x", "mc_0_trials"} | {
        f"mc_0_second_order_{s}" for s in ("cov68", "cov95", "rmse", "nees")
    }


def test_truth_study_texts():
    r = experiments.truth_study(
        np.array([[2.0, 10.0, 2.0]]), 1 / 200, trials=20, seed=0, names=("second_order",)
    )
    texts = report.truth_study_texts(r, "st")
    assert texts["st_0_truth"] == "(2, 10, 2)"
    assert texts["st_0_trials"] == str(r["valid_trials"][0])
    assert texts["st_0_second_order_bias"] == f"{r['second_order']['bias'][0]:.3f}"
    assert texts["st_0_second_order_cov68"] == f"{r['second_order']['coverage_68'][0]:.2f}"
    assert set(texts) == {"st_0_truth", "st_0_trials"} | {
        f"st_0_second_order_{s}" for s in ("bias", "rmse", "mean_sd", "cov68", "cov95", "nees")
    }
