"""The page "Using depthcore": its module map and tables come from the package itself."""

import pytest

import depthcore
from depthbook import using
from depthcore.registry.filters import FILTERS


def test_family_names_each_modules_family_and_refuses_another_package():
    assert using.family("depthcore.exact.optimal") == "exact"
    assert using.family("depthcore.cli.text") == "cli"
    for other in ("numpy.linalg", "depthbook.formatting"):
        with pytest.raises(ValueError, match="depthcore's modules"):
            using.family(other)


def test_module_summary_is_the_first_paragraph_with_markdown_for_rest():
    summary = using.module_summary("depthcore.kalman.modified_polar")
    assert summary.startswith("The EKF in modified polar coordinates")
    assert "[aidala1983]_" not in summary and ":mod:" not in summary
    assert "``" not in using.module_summary("depthcore.problem.weights")
    assert using.module_summary("depthcore.registry").endswith("and one result.")


def test_the_module_map_has_a_row_per_family_listing_each_module_once():
    rows = using.module_map().rows
    assert [r[0] for r in rows] == [f"`depthcore.{f}`" for f in depthcore.SUBPACKAGES]
    assert rows[1][1] == using.module_summary("depthcore.kalman")
    listed = [
        f"{r[0].strip('`')}.{m.strip(' `')}" for r in rows for m in r[2].split(",") if m.strip()
    ]
    assert listed == [m for m in depthcore.MODULES if m.count(".") > 1]


def test_the_filter_table_has_a_row_per_registered_filter():
    rows = using.filter_table().rows
    assert [r[0] for r in rows] == [f"`{n}`" for n in FILTERS]
    assert sum(r[5] == "yes" for r in rows) == sum(f.default for f in FILTERS.values())


def test_the_limits_table_reads_each_limit_from_the_module_that_enforces_it():
    from depthcore.cli import main as cli
    from depthcore.problem import checks

    rows = {r[0]: r[1] for r in using.limits_table().rows}
    assert f"3 to {checks.MAX_FRAMES:,} bearings" in rows["`--mu`"]
    assert using.limit(cli.MU_MAX) in rows["`--mu`"]
    assert rows["`study --frames`"] == f"from 3 to {checks.MAX_FRAMES:,}"


def test_command_help_is_the_commands_help_and_refuses_another_name():
    text = using.command_help("estimate", columns=80)
    assert text.startswith("usage: python -m depthcore estimate") and "--mu-file" in text
    assert max(len(line) for line in text.splitlines()) <= 100
    with pytest.raises(ValueError, match="command must be"):
        using.command_help("all")


@pytest.mark.parametrize(
    ("x", "text"), [(1e6, "1e6"), (1e-9, "1e-9"), (0.5, "0.5"), (1e-12, "1e-12"), (1e15, "1e15")]
)
def test_limit_prints_exponents_without_plus_signs_or_zeros(x, text):
    assert using.limit(x) == text
