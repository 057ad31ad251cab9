"""The README's "Use it from Python" example runs, and the book shows the same code.

The book's intro and its page "Using depthcore" run the example as a code
cell, whose output ``make notebooks`` checks against book/_nbval/; here the
README's copy is run and compared with the registry called directly.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import numpy as np
import pytest

from depthcore.exact import optimal
from depthcore.registry import filters

ROOT = Path(__file__).resolve().parents[1]


def readme_example() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Use it from Python\n", 1)[1].split("\n## ", 1)[0]
    return re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)


@pytest.mark.parametrize("page", ["intro", "using"])
def test_readme_example_is_a_code_cell_of_the_book(page):
    text = (ROOT / "book" / f"{page}.md").read_text(encoding="utf-8")
    assert "```{code-cell} ipython3\n" + readme_example() + "```" in text


def test_readme_example_runs_and_prints_each_filters_depth():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(readme_example(), "README.md", "exec"), {})
    lines = out.getvalue().splitlines()
    assert [line.split(":")[0].strip() for line in lines] == ["optimal", "second_order", "ekf"]
    # The optimal filter's depth, read back from the printed line, against the
    # exact marginal computed without the registry.
    mu, rho = np.array([-0.3, 0.0, 0.2]), 0.005
    from depthcore import noise_free_state, paper_prior

    prior = paper_prior(noise_free_state(mu))
    direct = optimal.run(mu, rho, prior.mean, prior.cov)
    mean, sd = map(float, re.findall(r"-?\d+\.\d+", lines[0]))
    assert abs(mean - direct.depth_mean) < 5e-4
    assert abs(sd - direct.depth_sd) < 5e-4
    assert len(filters.NAMES) >= 3
