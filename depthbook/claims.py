"""The chapter of the paper's claims (book/claims.md): its tables and counts.

Recommended import: ``from depthbook import claims``.

The claims and their verdicts are decided in :mod:`depthbook.studies.claims`;
this module lays them out for the chapter, the intro, the README and the
article: the counts of each verdict (:func:`counts`), the table of every claim
(:func:`claims_table`) and the table of each item's verdicts
(:func:`items_table`).
"""

from __future__ import annotations

from depthbook.notebook import MarkdownTable
from depthbook.studies import claims as decided

#: The verdicts' short names, as the tables print them, in the order of
#: :data:`depthbook.studies.claims.VERDICTS`.
SHORT = {
    decided.NOT_REPRODUCED: "not reproduced",
    decided.PRINTED_FORMULA: "only with the print's wrong formula",
    decided.AFTER_CORRECTION: "after correcting the print",
    decided.AS_PRINTED: "as printed",
    decided.NOT_CHECKABLE: "not checkable",
}


def counts(found) -> dict:
    """How many claims have each verdict.

    Parameters
    ----------
    found : list of depthbook.studies.claims.Claim

    Returns
    -------
    dict
        ``{verdict: count}`` over :data:`depthbook.studies.claims.VERDICTS`, in
        that order, and ``"all"``.
    """
    out = {v: sum(c.verdict == v for c in found) for v in decided.VERDICTS}
    out["all"] = len(found)
    return out


def claims_table(found) -> MarkdownTable:
    """Every claim: where the paper makes it, what it says, the test, the number, the verdict."""
    rows = [[c.item, c.statement, c.criterion, c.value, f"**{SHORT[c.verdict]}**"] for c in found]
    header = ["where", "the paper says", "test", "computed", "verdict"]
    return MarkdownTable(header, rows, widths=(12, 32, 32, 12, 12))


def item_summary(found, item: str) -> str:
    """An item's verdicts, worst first, each with its count of claims ("as printed 9; ...")."""
    mine = [c for c in found if c.item == item]
    verdicts = decided.figure_verdicts(mine)[item]
    return "; ".join(f"{SHORT[v]} {sum(c.verdict == v for c in mine)}" for v in verdicts)


def items_table(found, pages: dict) -> MarkdownTable:
    """Each item of the paper and its claims' verdicts, worst first, with their counts.

    ``pages``: ``{item: link}``, the text of the item's cell (a link to its page);
    an item not in it is named as it is.
    """
    rows = []
    for item in decided.figure_verdicts(found):
        mine = sum(c.item == item for c in found)
        rows.append([pages.get(item, item), f"{mine}", item_summary(found, item)])
    return MarkdownTable(["item", "claims", "verdicts"], rows)
