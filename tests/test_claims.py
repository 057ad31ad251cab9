"""The paper's claims: each decided by its stated test from the numbers, none by construction."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from depthbook.studies import claims, evidence
from depthcore.studies import reproduce

PAGES = {"fig2", "fig3", "fig4", "fig5", "fig6", "appendix", "conclusions"}
UNCHECKABLE = {"abstract-optimal-cost", "fig4-opt-missing", "conjecture"}


@pytest.fixture(scope="module")
def numbers():
    return claims.claim_numbers()


@pytest.fixture(scope="module")
def found(numbers):
    return {c.key: c for c in claims.claims(numbers)}


# --- mutations: numbers changed so that each computed claim's verdict must change ---------------


def _set(path, value):
    """A mutation setting ``numbers[path]`` to ``value(numbers)``, on a deep copy."""

    def mutate(n):
        out = copy.deepcopy(n)
        *head, last = path
        leaf = out
        for k in head:
            leaf = leaf[k]
        leaf[last] = value(n)
        return out

    return mutate


def _together(*mutations):
    """The mutations applied one after another."""

    def mutate(n):
        for m in mutations:
            n = m(n)
        return n

    return mutate


def _printed(key, rid, i, which):
    """Move the derived (or the print's formula's) value across the agreement with the print."""

    def value(n):
        v, printed = n[which][key][rid][i], n["printed"][key][rid][i]
        moved = printed if not claims.agrees(v, printed) else v + 3 * claims.AGREE
        return [moved if j == i else n[which][key][rid][j] for j in (0, 1)]

    return _set((which, key, rid), value)


def _mirror(key):
    """The exact depth marginal's quantiles reflected about its median: the other skew."""
    return _set(
        ("quantiles", key),
        lambda n: [2 * n["quantiles"][key][2] - q for q in n["quantiles"][key][::-1]],
    )


def _marg(key, name, field):
    return ("marginals", key, name, field)


def _dist(key, name):
    return ("marginals", key, "distance", name)


MUTATIONS = {
    # the low-noise distance above the higher-noise one
    "abstract-low-noise": (
        _set(
            _dist("fig5", "second_order"),
            lambda n: 2 * n["marginals"]["fig2"]["distance"]["second_order"],
        ),
    ),
    # Figure 3's p_s farther from p_o than p_e is
    "intro-closer": (
        _set(
            _dist("fig3", "second_order"), lambda n: 1.5 * n["marginals"]["fig3"]["distance"]["ekf"]
        ),
    ),
    # p_s still the closer everywhere, but far closer only on Figure 5
    "so-far-outperforms": (
        _together(
            *(
                _set(
                    _dist(k, "second_order"),
                    lambda n, k=k: 0.8 * n["marginals"][k]["distance"]["ekf"],
                )
                for k in ("fig2", "fig4", "fig6")
            )
        ),
    ),
    # Eq. (16)'s factor constant after all
    "eq16-constant": (_set(("eq16_spread",), lambda n: {k: 0.0 for k in n["eq16_spread"]}),),
    "fig2-pixels": (_set(("pixels", "fig2"), lambda n: 2 * n["pixels"]["fig2"]),),
    "fig5-pixels": (_set(("pixels", "fig5"), lambda n: 1.1),),
    # c moved off the printed one; f(c) not zero
    "fig2-c": (
        _set(("c", "fig2"), lambda n: [v + 0.1 for v in n["c"]["fig2"]]),
        _set(("f_at_c", "fig2"), lambda n: 1e-6),
    ),
    "fig3-c": (
        _set(("c", "fig3"), lambda n: [v + 0.1 for v in n["c"]["fig3"]]),
        _set(("f_at_c", "fig3"), lambda n: 1e-6),
    ),
    # p_s's mean above p_o's, and (Figure 2) too far below
    "fig2-so-lower": (
        _set(
            _marg("fig2", "second_order", "mean"),
            lambda n: n["marginals"]["fig2"]["optimal"]["mean"] + 0.1,
        ),
        _set(
            _marg("fig2", "second_order", "mean"),
            lambda n: n["marginals"]["fig2"]["optimal"]["mean"] - 2.0,
        ),
    ),
    "fig3-so-lower": (
        _set(
            _marg("fig3", "second_order", "mean"),
            lambda n: n["marginals"]["fig3"]["optimal"]["mean"] + 1.0,
        ),
    ),
    "fig2-opt-skew": (_mirror("fig2"),),
    "fig3-opt-skew": (_mirror("fig3"),),
    # an EKF as wide as the exact posterior
    "fig2-ekf-underestimates": (
        _set(_marg("fig2", "ekf", "sd"), lambda n: n["marginals"]["fig2"]["optimal"]["sd"]),
    ),
    "fig3-ekf-underestimates": (
        _set(_marg("fig3", "ekf", "sd"), lambda n: n["marginals"]["fig3"]["optimal"]["sd"]),
    ),
    "ekf-underestimates": (
        _set(_marg("fig4", "ekf", "sd"), lambda n: 0.6 * n["marginals"]["fig4"]["optimal"]["sd"]),
    ),
    # Figure 3's p_o as peaked as in Figure 2
    "fig3-flattened": (
        _set(_marg("fig3", "optimal", "peak"), lambda n: n["marginals"]["fig2"]["optimal"]["peak"]),
    ),
    "fig3-ekf-sharp": (
        _set(
            _marg("fig3", "ekf", "peak"),
            lambda n: 2 * n["marginals"]["fig3"]["second_order"]["peak"],
        ),
    ),
    # a symmetric exact marginal: its upper tail as long as its lower
    "fig3-lower-bound": (
        _set(
            ("quantiles", "fig3"),
            lambda n: [
                *n["quantiles"]["fig3"][:4],
                2 * n["quantiles"]["fig3"][2] - n["quantiles"]["fig3"][0],
            ],
        ),
    ),
    # Figure 5's marginals farther apart than Figure 2's
    "fig5-closer": (
        _set(
            _dist("fig5", "second_order"),
            lambda n: 1.5 * n["marginals"]["fig2"]["distance"]["second_order"],
        ),
    ),
    "fig5-sharper": (
        _set(
            _marg("fig5", "optimal", "peak"),
            lambda n: 0.5 * n["marginals"]["fig2"]["optimal"]["peak"],
        ),
    ),
    # an EKF that does not move, and one that moves twice the shift
    "fig6-ekf-through": (
        _set(_marg("fig6", "ekf", "mean"), lambda n: n["marginals"]["fig2"]["ekf"]["mean"]),
        _set(
            _marg("fig6", "ekf", "mean"),
            lambda n: n["marginals"]["fig2"]["ekf"]["mean"] + 2 * n["prior_shift"],
        ),
    ),
    "fig6-others-unaffected": (
        _set(
            _marg("fig6", "optimal", "mean"),
            lambda n: n["marginals"]["fig2"]["optimal"]["mean"] + 0.5,
        ),
        _set(
            _marg("fig6", "second_order", "mean"),
            lambda n: n["marginals"]["fig2"]["second_order"]["mean"] - 0.5,
        ),
    ),
    # the exact posterior follows the prior as far as the EKF does
    "ekf-prior-mean": (
        _set(_marg("fig6", "optimal", "mean"), lambda n: n["marginals"]["fig6"]["ekf"]["mean"]),
    ),
    # Theorem 1 failing with 2 rho^2 J^-1; holding with the printed rho^2 J^-1
    "theorem1": (
        _set(("theorem", "fig3", "misfit"), lambda n: 1e-3),
        _set(("theorem",), lambda n: {k: dict(v, factor=1.0) for k, v in n["theorem"].items()}),
    ),
    "theorem1-means": (_set(("theorem", "fig2", "means"), lambda n: 1e-6),),
}
for _key in evidence.PAPER:
    for _rid in evidence.FILTER_ROWS:
        for _i, _moment in enumerate(("mean", "sd")):
            MUTATIONS[f"{_key}-{_rid}-{_moment}"] = (_printed(_key, _rid, _i, "derived"),) + (
                (_printed(_key, _rid, _i, "print_formula"),)
                if _rid in evidence.PRINT_FORMULAS
                else ()
            )

CASES = [(key, i) for key, mutations in MUTATIONS.items() for i in range(len(mutations))]


# --- the claims -----------------------------------------------------------------------------------


def test_claims_are_many_with_unique_keys_a_verdict_of_the_vocabulary_and_a_stated_test(numbers):
    found = claims.claims(numbers)
    assert len(found) >= 15
    assert len({c.key for c in found}) == len(found)
    for c in found:
        assert c.verdict in claims.VERDICTS
        assert c.page in PAGES
        assert all(s.strip() for s in (c.item, c.statement, c.quantity, c.criterion, c.value))
        assert c.reason.strip() and "\n" not in c.reason


def test_claim_numbers_are_plain_python_values(numbers):
    def walk(v):
        if isinstance(v, dict):
            return all(isinstance(k, str) and walk(x) for k, x in v.items())
        if isinstance(v, list):
            return all(walk(x) for x in v)
        return type(v) in (float, int, bool)

    assert walk(numbers)


def test_the_known_verdicts(found):
    printed = {
        f"{k}-{r}-{m}" for k in evidence.PAPER for r in evidence.FILTER_ROWS for m in ("mean", "sd")
    }
    expected = {key: claims.AS_PRINTED for key in printed}
    expected |= {
        # Figure 3's optimal mean comes only from Eq. (16) as printed; its SD from no reading
        "fig3-opt-mean": claims.PRINTED_FORMULA,
        "fig3-opt-sd": claims.NOT_REPRODUCED,
        # the second-order SDs need 2 rho^2 J^-1
        "fig2-so-sd": claims.AFTER_CORRECTION,
        "fig3-so-sd": claims.AFTER_CORRECTION,
        "theorem1": claims.AFTER_CORRECTION,
        "eq16-constant": claims.NOT_REPRODUCED,
        "fig5-pixels": claims.NOT_REPRODUCED,
        "fig2-pixels": claims.AS_PRINTED,
        "fig6-ekf-through": claims.AS_PRINTED,
        "fig3-lower-bound": claims.AS_PRINTED,
        **{key: claims.NOT_CHECKABLE for key in UNCHECKABLE},
    }
    assert {key: found[key].verdict for key in expected} == expected
    # every claim not named above holds as printed
    assert {c.verdict for key, c in found.items() if key not in expected} == {claims.AS_PRINTED}


def test_the_numbers_behind_the_known_verdicts(numbers):
    # Figure 3: the exact density against Eq. (16) as printed; Figure 5: 512 px over 30 degrees
    assert numbers["derived"]["fig3"]["opt"] == pytest.approx([20.74, 13.71], abs=0.005)
    assert numbers["print_formula"]["fig3"]["opt"][0] == pytest.approx(67.45, abs=0.005)
    assert numbers["pixels"]["fig5"] == pytest.approx(512 / (np.pi / 6) / 500, rel=1e-12)
    # Theorem 1's printed covariance is half the EKF's, near enough
    for t in numbers["theorem"].values():
        assert t["misfit"] < claims.THEOREM_BOUND
        assert t["factor"] == pytest.approx(2.0, rel=2e-3)
    # the EKF passes on a little more than the shift: "straight through" by PASSED
    m = numbers["marginals"]
    share = (m["fig6"]["ekf"]["mean"] - m["fig2"]["ekf"]["mean"]) / numbers["prior_shift"]
    assert 1.0 < share <= claims.PASSED[1]


def test_agreement_with_the_print_is_the_packages_rule(numbers):
    for key in evidence.PAPER:
        for row in reproduce.comparison(key):
            if row["reported_mean"] is None:
                continue
            for moment in ("mean", "sd"):
                assert (
                    claims.agrees(row[moment], row[f"reported_{moment}"])
                    == row[f"{moment}_matches"]
                )


def test_the_uncheckable_claims_are_the_stated_ones_with_a_reason(found):
    uncheckable = {key for key, c in found.items() if c.verdict == claims.NOT_CHECKABLE}
    assert uncheckable == UNCHECKABLE
    assert "chapter on the conjecture" in found["conjecture"].reason


def test_every_computed_claim_has_a_mutation(found):
    computed = {key for key, c in found.items() if c.verdict != claims.NOT_CHECKABLE}
    assert set(MUTATIONS) == computed


@pytest.mark.parametrize(("key", "index"), CASES, ids=[f"{k}-{i}" for k, i in CASES])
def test_no_verdict_holds_by_construction(numbers, found, key, index):
    mutated = MUTATIONS[key][index](numbers)
    after = {c.key: c.verdict for c in claims.claims(mutated)}
    assert after[key] != found[key].verdict
    # the mutation worked on a copy
    assert {c.key: c.verdict for c in claims.claims(numbers)}[key] == found[key].verdict


def test_uncheckable_claims_stay_so_whatever_the_numbers(numbers):
    for mutations in MUTATIONS.values():
        after = {c.key: c.verdict for c in claims.claims(mutations[0](numbers))}
        assert all(after[key] == claims.NOT_CHECKABLE for key in UNCHECKABLE)


# --- the items' summaries -------------------------------------------------------------------------


def _claim(item, verdict):
    return claims.Claim("k", item, "fig2", "s", "q", "c", "v", verdict, "r")


def test_figure_verdicts_list_each_items_verdicts_worst_first():
    found = [
        _claim("Figure 2", claims.AS_PRINTED),
        _claim("Figure 4", claims.NOT_CHECKABLE),
        _claim("Figure 2", claims.NOT_REPRODUCED),
        _claim("Figure 2", claims.AS_PRINTED),
        _claim("Conclusions", claims.NOT_CHECKABLE),
        _claim("Conclusions", claims.AFTER_CORRECTION),
    ]
    assert claims.figure_verdicts(found) == {
        "Figure 2": (claims.NOT_REPRODUCED, claims.AS_PRINTED),
        "Figure 4": (claims.NOT_CHECKABLE,),
        "Conclusions": (claims.AFTER_CORRECTION, claims.NOT_CHECKABLE),
    }


def test_figure_verdicts_of_the_paper(found):
    summary = claims.figure_verdicts(list(found.values()))
    assert set(summary) == {c.item for c in found.values()}
    for item, verdicts in summary.items():
        assert set(verdicts) == {c.verdict for c in found.values() if c.item == item}
    assert summary["Figure 3"][:2] == (claims.NOT_REPRODUCED, claims.PRINTED_FORMULA)
    assert summary["Theorem 1"][0] == claims.AFTER_CORRECTION
    assert summary["Figure 4"] == (claims.NOT_CHECKABLE,)


def test_the_chapter_counts_and_lays_out_the_claims(found):
    from depthbook import claims as chapter

    found = list(found.values())
    n = chapter.counts(found)
    assert list(n)[:-1] == list(claims.VERDICTS) and n["all"] == len(found)
    assert sum(n[v] for v in claims.VERDICTS) == n["all"]
    table = chapter.claims_table(found)
    assert len(table.rows) == len(found) and table.rows[0][0] == found[0].item
    assert all(row[-1].strip("*") in chapter.SHORT.values() for row in table.rows)
    items = chapter.items_table(found, {"Figure 2": "[Figure 2](fig2.md)"})
    by_item = {row[0]: row for row in items.rows}
    assert "[Figure 2](fig2.md)" in by_item and "Figure 3" in by_item
    # Figure 3's verdicts, worst first, each with its count; the counts add to its claims
    row = by_item["Figure 3"]
    said = row[2].split("; ")
    assert said[0].startswith(chapter.SHORT[claims.NOT_REPRODUCED])
    assert sum(int(part.rsplit(" ", 1)[1]) for part in said) == int(row[1])
