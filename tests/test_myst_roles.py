"""tools/myst_roles.py: the pages paste their numbers with ``{eval}`` roles."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import myst_roles  # noqa: E402

PAGE = """# A page

Its mean is {glue:text}`a_mean` and {eval}`b_sd`.

```{code-cell} ipython3
print("{glue:text}`kept`")
```

| x | y |
|---|---|
| {glue:text}`a_1` | {glue:text}`a_2` |
"""


def test_convert_rewrites_the_text_and_leaves_code_cells():
    out = myst_roles.convert(PAGE)
    assert "Its mean is {eval}`a_mean` and {eval}`b_sd`." in out
    assert "| {eval}`a_1` | {eval}`a_2` |" in out
    assert 'print("{glue:text}`kept`")' in out
    assert myst_roles.convert(out) == out  # idempotent


@pytest.mark.parametrize("role", ["{glue:text}`a:.2f`", "{glue:text}`fig2::a`"])
def test_convert_refuses_what_the_kernel_cannot_evaluate(role):
    with pytest.raises(ValueError, match=r"page:3: .* is not a Python name"):
        myst_roles.convert(f"# A page\n\n{role}\n")


def test_every_page_pastes_its_numbers_with_eval(capsys):
    assert myst_roles.main(["--check"]) == 0, capsys.readouterr().out
