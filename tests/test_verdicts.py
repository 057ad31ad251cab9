"""The replication's verdicts: decided from the computations, and as the article states them."""

from __future__ import annotations

import pytest

from depthbook.studies import verdicts


@pytest.fixture(scope="module")
def numbers():
    return verdicts.paper_numbers()


def test_paper_numbers_count_the_printed_means_and_sds(numbers):
    # Figures 2 and 3 print a mean and an SD for each of the three filters.
    assert numbers["printed"] == 12
    assert numbers["matched"] == numbers["printed"] - len(numbers["unmatched"])
    assert numbers["unmatched"] == [("fig3", "opt", "mean"), ("fig3", "opt", "sd")]


def test_eq8_theorem1_holds_with_the_derived_covariance_and_misses_by_two_as_printed(numbers):
    # the printed rho^2 J^-1 is half of 2 rho^2 J^-1, hence half of the EKF's P_3
    assert numbers["theorem"] < verdicts.THEOREM_TOL
    assert numbers["theorem_factor"] == pytest.approx(2.0, rel=1e-3)


def test_verdicts_one_per_figure_and_theorem_in_the_papers_order(numbers):
    found = verdicts.verdicts(numbers)
    assert [v.item for v in found] == [f"Figure {k}" for k in range(2, 7)] + ["Theorem 1"]
    assert {v.verdict for v in found} <= {
        verdicts.REPRODUCED,
        verdicts.CORRECTED,
        verdicts.NOT_REPRODUCED,
    }
    by = {v.item: v.verdict for v in found}
    # as the replication article's table states them
    assert by["Figure 3"] == by["Theorem 1"] == verdicts.CORRECTED
    assert all(by[f"Figure {k}"] == verdicts.REPRODUCED for k in (2, 4, 5, 6))


def test_verdicts_follow_the_numbers_not_a_table(numbers):
    # a Figure 6 whose EKF did not move would not be reproduced
    still = dict(numbers, shift=dict(numbers["shift"], ekf=0.0))
    assert verdicts.verdicts(still)[4].verdict == verdicts.NOT_REPRODUCED
    # Theorem 1 failing with either reading is not reproduced
    broken = dict(numbers, theorem=1.0)
    assert verdicts.verdicts(broken)[5].verdict == verdicts.NOT_REPRODUCED
