"""The numbers behind the print's errors (the claims' verdicts: tests/test_claims.py)."""

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
