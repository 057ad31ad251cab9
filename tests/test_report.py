"""The texts the book and the README show: tables, vectors, glued numbers, benchmark tables."""

import re
from pathlib import Path

import numpy as np
import pytest

from depthbook import (
    benchmark_tables,
    beyond_filters,
    beyond_linear,
    beyond_study,
    beyond_sweeps,
    formatting,
    notebook,
    paper,
)
from depthcore import SCENARIOS
from depthcore.exact import optimal
from depthcore.kalman import ekf, iterated
from depthcore.problem.scenarios import REPORTED
from depthcore.registry.filters import FILTERS, NAMES
from depthcore.studies import monte_carlo, reproduce

FIG2 = SCENARIOS["fig2"]


def test_comparison_rows_of_figure_2():
    rows = {r["id"]: r for r in reproduce.comparison("fig2")}
    assert list(rows) == [r[0] for r in reproduce.TABLE_ROWS]
    assert rows["opt"]["reported_mean"] == REPORTED["fig2"]["optimal"]["depth"][0]
    assert rows["so"]["sd"] == pytest.approx(0.6163, abs=1e-4)
    assert rows["so_printed"]["sd"] == pytest.approx(0.4358, abs=1e-4)
    assert rows["so"]["sd_matches"] and not rows["so_printed"]["sd_matches"]
    texts = paper.comparison_texts("fig2", list(rows.values()))
    assert texts["fig2_opt_mean"] == "6.4660"
    assert texts["fig2_opt_paper_mean"] == "6.47"
    assert texts["fig2_so_printed_agrees"] == "mean only"
    assert texts["fig2_ekf_agrees"] == "yes"
    # the paper has no iterated or inverse-depth EKF: no number to agree with
    assert texts["fig2_inv_paper_mean"] == "—" and rows["inv"]["mean_matches"] is None
    assert rows["iter"]["sd"] == pytest.approx(
        FILTERS["iterated"](FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov).depth_sd
    )


def test_comparison_row_of_the_iterated_smoother_is_its_state_at_the_last_frame():
    # Every figure's table ends with the iterated smoother: the MAP of the
    # trajectory at time 3 with its Laplace SD, as a direct call gives it.
    for key, s in SCENARIOS.items():
        rows = {r["id"]: r for r in reproduce.comparison(key)}
        r = iterated.smoother(s.mu, s.rho, s.prior.mean, s.prior.cov)
        i = 1 if s.quantity == "depth" else 2
        row = rows["ismooth"]
        assert row["mean"] == pytest.approx(r.mean[i], abs=1e-12), key
        assert row["sd"] == pytest.approx(np.sqrt(r.cov[i, i]), rel=1e-12), key
        assert row["reported_mean"] is None and row["mean_matches"] is None
        # the mode is the centre of p_s (to 1e-5 of its SD), the Laplace SD p_s's to 1 %
        assert row["mean"] == pytest.approx(rows["so"]["mean"], abs=1e-5 * rows["so"]["sd"]), key
        assert row["sd"] == pytest.approx(rows["so"]["sd"], rel=0.01), key
    assert reproduce.iterated_smoother_moments(FIG2)["velocity"][0] == pytest.approx(
        iterated.smoother(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov).mean[2]
    )


def test_comparison_rows_of_figure_3_and_4():
    rows = {r["id"]: r for r in reproduce.comparison("fig3")}
    texts = paper.comparison_texts("fig3", list(rows.values()))
    assert texts["fig3_opt_agrees"] == "no"
    assert texts["fig3_opt_printed_mean"] == "67.4516"
    assert texts["fig3_opt_printed_agrees"] == "mean only"
    rows4 = reproduce.comparison("fig4")
    assert {r["quantity"] for r in rows4} == {"velocity"}
    texts4 = paper.comparison_texts("fig4", rows4)
    assert texts4["fig4_opt_paper_mean"] == "—" and texts4["fig4_opt_agrees"] == "—"


def test_vec_formats_and_never_prints_negative_zero():
    assert formatting.vec([1.2, 6, -1.2]) == "(1.2000, 6.0000, -1.2000)"
    assert formatting.vec([-0.0, -1e-9, 0.25], 2) == "(0.00, 0.00, 0.25)"
    assert formatting.vec(np.array([2.0]), 0) == "(2)"
    with pytest.raises(ValueError, match="1-D"):
        formatting.vec(np.eye(2))
    with pytest.raises(ValueError, match="decimals"):
        formatting.vec([1.0], -1)


def test_rho_label():
    assert formatting.rho_label(1 / 200) == "1/200"
    assert formatting.rho_label(0.001) == "1/1000"
    with pytest.raises(ValueError):
        formatting.rho_label(0.0)


PM = re.compile(r"^-?\d+\.\d{3} ± \d+\.\d{3}$")


def test_moments_texts_cover_every_filter_and_scenario():
    result = reproduce.reproduce()
    texts = beyond_filters.moments_texts(result)
    n = len(SCENARIOS) * len(NAMES) * 2 + len(SCENARIOS) * 2
    assert len(texts) == n
    assert all(PM.match(v) for k, v in texts.items() if not k.endswith("_se"))
    m = optimal.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov)
    assert texts["bf_fig2_optimal_depth"] == f"{m.depth_mean:.3f} ± {m.depth_sd:.3f}"
    ekf_y = ekf.run(FIG2.mu, FIG2.rho, FIG2.prior.mean, FIG2.prior.cov).posterior.marginal("y")
    assert texts["bf_fig2_ekf_depth"] == f"{ekf_y[0]:.3f} ± {ekf_y[1]:.3f}"


def test_moments_texts_reject_ambiguous_rows():
    result = reproduce.reproduce(["fig2"])
    rows = result["scenarios"][0]["rows"]
    rows.append(dict(rows[-1]))  # a second particle row
    with pytest.raises(ValueError, match="expected one row of 'particle'"):
        beyond_filters.moments_texts(result)


def test_study_texts_have_every_score():
    r = monte_carlo.study(trials=20, seed=0, names=("optimal", "ekf"))
    texts = formatting.study_texts(r, "s")
    assert texts["s_trials"] == str(r["valid_trials"])
    assert texts["s_ekf_depth_coverage_68"] == f"{r['filters']['ekf']['depth']['coverage_68']:.2f}"
    assert texts["s_ekf_nees"] == f"{r['filters']['ekf']['nees']:.1f}"
    assert len(texts) == 1 + 2 * 2 * (2 * len(formatting.STUDY_DECIMALS) + 2)
    ekf = r["filters"]["ekf"]
    assert texts["s_ekf_depth_coverage_68_pm"] == (
        f"{ekf['depth']['coverage_68']:.2f} ± {ekf['depth']['coverage_68_se']:.2f}"
    )
    assert texts["s_ekf_hellinger_pm"].startswith(texts["s_ekf_hellinger"] + " ± ")


def test_a_value_and_its_standard_error_are_printed_to_the_values_places():
    assert formatting.value_se(0.9021, 0.0133, 2) == "0.90 ± 0.01"
    # a standard error that would round to zero gets the places that show it
    assert formatting.value_se(0.9021, 0.0004, 2) == "0.90 ± 0.0004"
    assert formatting.value_se(12.5, 0.0, 1) == "12.5 ± 0.0"
    assert formatting.value_se(-0.0, 1e-9, 1) == "0.0 ± 0.0000"  # at most three more places


def test_noise_study_texts():
    r = beyond_sweeps.noise_study([1 / 200], trials=20, seed=0, names=("second_order",))
    texts = beyond_sweeps.noise_study_texts(r, "mc")
    assert texts["mc_0_x"] == "1/200"
    assert texts["mc_0_trials"] == str(r["valid_trials"][0])
    assert texts["mc_0_second_order_cov68"] == f"{r['second_order']['coverage_68'][0]:.2f}"
    assert set(texts) == {"mc_0_x", "mc_0_trials"} | {
        f"mc_0_second_order_{s}{pm}"
        for s in ("cov68", "cov95", "rmse", "nees")
        for pm in ("", "_pm")
    } | {
        f"mc_second_order_{s}_{which}_pm"
        for s in ("cov68", "cov95", "rmse", "nees")
        for which in ("min", "max")
    }
    # over two noise levels the extremes are the rows' texts with their SEs
    r2 = beyond_sweeps.noise_study([1 / 500, 1 / 100], trials=20, seed=0, names=("ekf",))
    t2 = beyond_sweeps.noise_study_texts(r2, "mc")
    cov = r2["ekf"]["coverage_68"]
    assert t2["mc_ekf_cov68_max_pm"] == t2[f"mc_{int(np.argmax(cov))}_ekf_cov68_pm"]
    assert t2["mc_ekf_cov68_min_pm"] == t2[f"mc_{int(np.argmin(cov))}_ekf_cov68_pm"]
    assert " ± " in t2["mc_ekf_nees_min_pm"]
    r = r["second_order"]
    assert texts["mc_0_second_order_rmse_pm"] == formatting.value_se(
        r["rmse"][0], r["rmse_se"][0], 3
    )


def test_comparison_table_holds_the_glued_texts_of_every_row():
    rows = reproduce.comparison("fig2")
    texts = paper.comparison_texts("fig2", rows)
    table = paper.comparison_table("fig2", rows)
    assert table.header[-1] == "agrees"
    assert [r[0] for r in table.rows][0] == "optimal $p_{oy}$"
    for row, cells in zip(rows, table.rows, strict=True):
        fields = ("paper_mean", "mean", "paper_sd", "sd", "agrees")
        assert cells[1:] == [texts[f"fig2_{row['id']}_{f}"] for f in fields]
    # The paper prints no numbers for Figure 4: no column of agreement, velocity labels.
    table4 = paper.comparison_table("fig4", reproduce.comparison("fig4"))
    assert "agrees" not in table4.header and "EKF $p_{ev}$" in [r[0] for r in table4.rows]
    with pytest.raises(ValueError, match="key"):
        paper.comparison_table("fig7", rows)


def test_markdown_table_renders_as_markdown_and_aligned_text():
    table = notebook.MarkdownTable(["name", "value"], [["a_b", "1|2"], ["c", "3"]])
    assert (
        table._repr_markdown_() == "| name | value |\n| --- | --- |\n| a_b | 1\\|2 |\n| c | 3 |\n"
    )
    assert repr(table).splitlines() == ["name  value", "----  -----", "a_b   1|2", "c     3"]
    with pytest.raises(ValueError, match="rows"):
        notebook.MarkdownTable(["name", "value"], [["a"]])
    with pytest.raises(ValueError, match="header"):
        notebook.MarkdownTable([], [])
    # with widths, a table directive whose columns the PDF wraps
    wide = notebook.MarkdownTable(["name", "value"], [["c", "3"]], widths=(30, 70))
    assert wide.markdown() == (
        "```{table}\n:widths: 30 70\n\n| name | value |\n| --- | --- |\n| c | 3 |\n```\n"
    )
    for widths in ((30,), (0, 70)):
        with pytest.raises(ValueError, match="widths"):
            notebook.MarkdownTable(["name", "value"], [["c", "3"]], widths=widths)


def test_glue_log_pastes_texts_as_glue_text_does_and_needs_a_kernel():
    from myst_nb.core.variables import format_plain_text  # what {glue:text} pastes

    for text in ("'6.4660'", "'—'", "'x|y'", "3", "<Figure size 640x480 with 1 Axes>"):
        assert notebook.GlueLog.pasted_text(text) == format_plain_text(text, "")
    assert notebook.GlueLog.pasted_text("'6.4660'") == "6.4660"
    assert notebook.GlueLog.pasted_text("'—'") == "—"
    assert notebook.GlueLog.pasted_text("<Figure size 640x480 with 1 Axes>") == (
        "<Figure size 640x480 with 1 Axes>"
    )
    with pytest.raises(RuntimeError, match="kernel"):
        notebook.GlueLog()


def test_page_tables_finds_the_tables_that_paste_glued_texts():
    page = """Text with {glue:text}`a` but no table.

| x | y |
|---|---:|
| {glue:text}`a` | {glue}`b` |

| plain | table |
|---|---|
| 1 | 2 |

```{code-cell} ipython3
:tags: [remove-cell]

print("| {glue:text}`c` |")
```

| z |
|---|
| {glue:text}`c` |"""
    tables = notebook.page_tables(page)
    assert tables == [
        ["| x | y |", "|---|---:|", "| {glue:text}`a` | {glue}`b` |"],
        ["| z |", "|---|", "| {glue:text}`c` |"],
    ]
    assert notebook.paste_table(tables[0], {"a": "1.5"}) is None  # b not glued yet
    pasted = notebook.paste_table(tables[0], {"a": "1.5", "b": "—"})
    assert pasted == "| x | y |\n|---|---:|\n| 1.5 | — |"
    shown = notebook.PastedTable(pasted)
    assert repr(shown) == pasted and shown._repr_markdown_() == pasted + "\n"


def test_every_glued_table_of_a_book_page_is_found():
    # The moments tables of beyond_filters: a row per filter, a column per figure.
    text = (Path(__file__).resolve().parents[1] / "book" / "beyond_filters.md").read_text()
    tables = notebook.page_tables(text)
    moments = [t for t in tables if t[0].startswith("| filter | Fig. 2 |")]
    assert len(moments) == 2
    names = notebook.GLUE_ROLE.findall("\n".join(moments[1]))
    assert "bf_fig2_second_order_velocity" in names and "bf_fig6_particle_velocity_se" in names
    result = reproduce.reproduce(["fig2"])
    texts = beyond_filters.moments_texts(result)
    assert "bf_fig2_second_order_velocity" in texts


def test_truth_study_texts():
    r = beyond_study.truth_study(
        np.array([[2.0, 10.0, 2.0]]), 1 / 200, trials=20, seed=0, names=("second_order",)
    )
    texts = beyond_study.truth_study_texts(r, "st")
    assert texts["st_0_truth"] == "(2, 10, 2)"
    assert texts["st_0_trials"] == str(r["valid_trials"][0])
    assert texts["st_0_second_order_bias"] == f"{r['second_order']['bias'][0]:.3f}"
    assert texts["st_0_second_order_cov68"] == f"{r['second_order']['coverage_68'][0]:.2f}"
    assert set(texts) == {"st_0_truth", "st_0_trials"} | {
        f"st_0_second_order_{s}{pm}"
        for s in ("bias", "rmse", "mean_sd", "cov68", "cov95", "nees")
        for pm in ("", "_pm")
    } | {
        f"st_second_order_{s}_{which}_pm"
        for s in ("rmse", "cov68", "cov95", "nees")
        for which in ("min", "max")
    }
    # one truth: its row is both extremes, with its standard error
    assert texts["st_second_order_cov68_min_pm"] == texts["st_0_second_order_cov68_pm"]
    assert " ± " in texts["st_second_order_cov68_max_pm"]


def test_rbpf_texts_format_each_row_of_the_convergence_table():
    result = {
        "sizes": np.array([30, 3000]),
        "exact": {"depth_mean": 23.03228, "depth_sd": 0.137451},
        "mean": {"depth_mean": np.array([23.04, 23.0321]), "depth_sd": np.array([0.12, 0.1374])},
        "se": {"depth_mean": np.array([0.0036, 0.00066]), "depth_sd": np.array([0.004, 0.0005])},
        "rmse": {"depth_mean": np.array([0.0181, 0.00257]), "depth_sd": np.array([0.0188, 0.0021])},
    }
    t = beyond_linear.rbpf_texts(result, "rb")
    assert t["rb_exact_mean"] == "23.0323" and t["rb_exact_sd"] == "0.1375"
    assert t["rb_1_J"] == "3,000" and t["rb_0_J"] == "30"
    assert t["rb_0_mean"] == "23.0400 ± 0.0036"
    assert t["rb_1_sd"] == "0.1374 ± 0.0005"
    assert t["rb_0_rmse_mean"] == "0.018" and t["rb_1_rmse_sd"] == "0.0021"


def test_bench_texts_format_the_records_numbers():
    from depthbook.provenance import benchmarks

    r = benchmarks.read("bench_optimal")
    t = benchmark_tables.bench_texts("bench_optimal", r)
    triple = r["results"]["per_triple"]
    i = triple["keys"].index("fig3")
    assert t["opt_fig3_figure"] == "Figure 3"
    assert t["opt_fig3_optimal_ekf"] == f"{triple['optimal_ms'][i] / triple['ekf_ms'][i]:.1f}"
    assert t["opt_nodes_max"] == str(max(triple["nodes"]))
    assert t["opt_origin"] == benchmark_tables.bench_origin(r)
    assert r["date"][:10] in t["opt_origin"] and r["machine"]["cpu"] in t["opt_origin"]
    machine = benchmark_tables.bench_machine(r)
    assert t["opt_origin"] == f"{r['date'][:10]} on {machine}"
    assert machine.startswith(f"{r['machine']['cores']} cores (") and r["date"][:4] not in machine
    assert formatting.sci(1.5e8) == "1.5e8" and formatting.sci(0.0287, 2) == "2.87e-2"
    assert formatting.sci(1e-8, 0) == "1e-8"
    with pytest.raises(ValueError, match="name"):
        benchmark_tables.bench_texts("bench_nothing", r)


def test_bench_blocks_hold_every_table_and_its_origin():
    from depthbook.provenance import benchmarks

    names = ["bench_bank", "bench_ekf_filterpy", "bench_import", "bench_kalman"]
    names += ["bench_optimal", "bench_rbpf", "bench_trials", "bench_frames", "bench_range_ekf"]
    records = {n: benchmarks.read(n) for n in names}
    blocks = benchmark_tables.bench_blocks(records)
    assert set(blocks) == set(benchmark_tables.bench_tables(records))
    for key, block in blocks.items():
        assert block.startswith("| ") and "Measured " in block, key
    bank = records["bench_bank"]["results"]["many_trials"]
    verdict = "met" if bank["time_s"] < bank["target_s"] else "not met"
    assert f"({verdict})" in blocks["bank"]
    # the range EKF's rows: the components the record found, its times and their ratio
    rows = records["bench_range_ekf"]["results"]["fig2"]["1e-03"]
    assert f"| {rows['components']:,} | {rows['range_ekf_ms']:.1f} ms |" in blocks["range_ekf"]


def test_glue_log_binds_each_glued_text_to_its_name(monkeypatch):
    import IPython

    class Publisher:
        def register_hook(self, hook):
            self.hook = hook

    class Shell:
        display_pub = Publisher()
        user_ns = {"rho": 0.005}

    monkeypatch.setattr(IPython, "get_ipython", Shell)
    notebook.GlueLog()
    prefix = notebook.GlueLog.PREFIX

    def glue(name, data):
        record = {"name": name, "mime_prefix": prefix}
        msg = {
            "msg_type": "display_data",
            "content": {
                "data": {prefix + k: v for k, v in data.items()},
                "metadata": {"scrapbook": record},
            },
        }
        assert Shell.display_pub.hook(msg) is msg

    glue("fig2_mean", {"text/plain": "'6.4660'"})
    glue("fig2_count", {"text/plain": "3"})
    glue("fig2_figure", {"text/plain": "<Figure>", "image/png": "iVBOR"})
    bound = Shell.user_ns["fig2_mean"]
    assert isinstance(bound, notebook.GluedText) and bound == "6.4660"
    assert repr(bound) == "6.4660" and repr(Shell.user_ns["fig2_count"]) == "3"
    figure = Shell.user_ns["fig2_figure"]  # shown by {eval} as the very output glued
    assert isinstance(figure, notebook.GluedOutput)
    assert figure._repr_mimebundle_() == ({"text/plain": "<Figure>", "image/png": "iVBOR"}, {})
    # The references of the page's text, resolved as the book resolves them.
    assert {"cite_t", "cite_p", "eq", "numref", "ref", "doc"} <= set(Shell.user_ns)
    glue("fig2_mean", {"text/plain": "'6.47'"})  # glued again: bound again
    assert Shell.user_ns["fig2_mean"] == "6.47"
    with pytest.raises(ValueError, match="'rho' is glued but also names a float"):
        glue("rho", {"text/plain": "'1/200'"})
    assert Shell.user_ns["rho"] == 0.005


def test_page_tables_reads_eval_roles_as_glue_text():
    tables = notebook.page_tables("| a | b |\n|---|---|\n| {eval}`x` | {glue:text}`y` |\n")
    assert notebook.paste_table(tables[0], {"x": "1", "y": "2"}).endswith("| 1 | 2 |")
