"""Adding a filter: its module, its registry entry and its test; everything else follows.

Two ways are checked, each in a fresh interpreter so that the package's own
registry is untouched: a filter of one's own, outside the package, joined to
the registry with :func:`depthcore.registry.filters.register`; and a filter
added to the package itself (a module in a family's folder and an entry in
:data:`~depthcore.registry.filters.FILTERS`), in a copy of the package. In
both, the registry, the command line and (for the package) the module list
that the API reference is built from pick the new filter up.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from depthcore.registry.filters import FILTERS, Filter, names, register

ROOT = Path(__file__).resolve().parent.parent

#: A toy Gaussian filter: the EKF with its bearings' noise doubled (the name says what it is).
TOY_MODULE = '''
"""A toy filter for the tests: the EKF, Eqs. (10)-(12), with the bearings' noise doubled."""

from depthcore.kalman import ekf
from depthcore.registry.estimates import Estimate


def run(mu, rho, prior_mean, prior_cov, process_noise=0.0):
    """The EKF on bearings of noise SD ``2 rho``; the registry's calling convention."""
    h = ekf.run(mu, 2 * rho, prior_mean, prior_cov, process_noise)
    mean, cov = h.means[..., -1, :], h.covs[..., -1, :, :]
    return Estimate(
        mean[..., 1], cov[..., 1, 1] ** 0.5, mean[..., 2], cov[..., 2, 2] ** 0.5,
        None, None, mean, cov, h,
    )
'''

TOY_ENTRY = """
Filter("toy", {run}, any_frames=True, with_process_noise=True, default=False)
"""

#: What each interpreter checks once the toy filter is in: the registry runs it and agrees
#: with the EKF at twice the noise; the command line lists it and runs it by name.
CHECKS = """
import contextlib, io, json
import numpy as np
from depthcore import SCENARIOS
from depthcore.cli.main import main
from depthcore.kalman import ekf
from depthcore.registry.filters import FILTERS, names

s = SCENARIOS["fig2"]
est = FILTERS["toy"](s.mu, s.rho, s.prior.mean, s.prior.cov)
h = ekf.run(s.mu, 2 * s.rho, s.prior.mean, s.prior.cov, 0.0)
assert np.isclose(est.depth_mean, h.means[-1, 1], rtol=0, atol=0)
out = io.StringIO()
with contextlib.redirect_stdout(out):
    status = main(["estimate", "--mu", *map(str, s.mu), "--rho", str(s.rho),
                   "--filters", "ekf", "toy", "--json"])
assert status == 0, status
rows = json.loads(out.getvalue())
help_text = io.StringIO()
with contextlib.redirect_stdout(help_text), contextlib.suppress(SystemExit):
    main(["study", "--help"])
from depthcore.studies import monte_carlo
studied = monte_carlo.study(trials=20, seed=1, names=("ekf", "toy"))
print(json.dumps({"names": names(), "in_help": "toy" in help_text.getvalue(),
                  "cli": rows, "depth": float(est.depth_mean),
                  "studied": sorted(studied["filters"])}))
"""


def _run(code: str, cwd: Path, **env) -> dict:
    """The JSON that ``code`` prints last, run in a fresh interpreter in folder ``cwd``."""
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        cwd=cwd,
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.splitlines()[-1])


def _cli_depth(rows: dict, name: str) -> float:
    """The depth mean the command line's JSON reports for filter ``name``."""
    assert name in rows["filters"], f"{name} missing from the command line's output"
    return float(rows["filters"][name]["depth"]["mean"])


def test_a_filter_of_ones_own_joins_the_registry_and_the_command_line(tmp_path):
    (tmp_path / "toy_filter.py").write_text(TOY_MODULE, encoding="utf-8")
    register_it = (
        f"import sys; sys.path.insert(0, {str(tmp_path)!r})\n"
        "import toy_filter\n"
        "from depthcore.registry.filters import Filter, register\n"
        "register(" + TOY_ENTRY.format(run="toy_filter.run") + ")\n"
    )
    got = _run(register_it + textwrap.dedent(CHECKS), tmp_path)
    assert got["names"][-1] == "toy" and got["in_help"] and got["studied"] == ["ekf", "toy"]
    assert _cli_depth(got["cli"], "toy") == pytest.approx(got["depth"], rel=1e-12)
    assert _cli_depth(got["cli"], "toy") != pytest.approx(_cli_depth(got["cli"], "ekf"))


def test_a_filter_added_to_the_package_is_listed_everywhere(tmp_path):
    package = tmp_path / "depthcore"
    shutil.copytree(
        ROOT / "depthcore", package, ignore=shutil.ignore_patterns("__pycache__", "*_records")
    )
    (package / "kalman" / "toy.py").write_text(TOY_MODULE, encoding="utf-8")
    registry = package / "registry" / "filters.py"
    registry.write_text(
        registry.read_text(encoding="utf-8")
        + "\n\nfrom depthcore.kalman import toy  # noqa: E402\n\n"
        + "FILTERS['toy'] = "
        + TOY_ENTRY.format(run="toy.run").strip()
        + "\n",
        encoding="utf-8",
    )
    listing = (
        f"import sys; sys.path.insert(0, {str(ROOT / 'tools' / 'sphinx')!r})\n"
        "import depthcore_book\n"
        "import depthcore\n"
        f"assert depthcore.__file__.startswith({str(tmp_path)!r}), depthcore.__file__\n"
        "assert 'depthcore.kalman.toy' in depthcore.MODULES\n"
        "assert 'depthcore.kalman.toy' in depthcore_book.family_modules('depthcore.kalman')\n"
    )
    got = _run(listing + textwrap.dedent(CHECKS), tmp_path, PYTHONPATH=str(tmp_path))
    assert "toy" in got["names"] and got["in_help"] and got["studied"] == ["ekf", "toy"]
    assert _cli_depth(got["cli"], "toy") == pytest.approx(got["depth"], rel=1e-12)


def test_register_refuses_what_is_not_a_new_filter():
    ekf = FILTERS["ekf"]
    with pytest.raises(ValueError, match="entry must be a Filter"):
        register("ekf")
    with pytest.raises(ValueError, match="'ekf' is taken"):
        register(ekf)
    renamed = Filter(**{**ekf.__dict__, "name": "not a name"})
    with pytest.raises(ValueError, match="must be a Python identifier"):
        register(renamed)
    unknown = Filter(**{**ekf.__dict__, "name": "x", "family": "kalman"})
    with pytest.raises(ValueError, match="family must be one of"):
        register(unknown)
    assert "x" not in names()


#: The fingerprints of what each committed study record's call runs, as a copy of the package
#: sees them (:func:`depthbook.provenance.records.code_fingerprint`).
FINGERPRINTS = """
import json
from depthbook.provenance import records
prints = {}
for path in records.committed():
    r = records.read(path)
    args = records.decode(r["arguments"]["args"])
    kwargs = records.decode(r["arguments"]["kwargs"])
    prints[path.stem] = records.code_fingerprint(r["function"], args, kwargs)
print(json.dumps(prints))
"""


def _changed_in_a_copy(tmp_path, edit) -> dict:
    """Each record's fingerprints that ``edit`` changes: this package against an edited copy."""
    before = _run(FINGERPRINTS, ROOT)
    package = tmp_path / "depthcore"
    for name in ("depthcore", "depthbook"):
        shutil.copytree(ROOT / name, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__"))
    edit(package)
    after = _run(FINGERPRINTS, tmp_path, PYTHONPATH=str(tmp_path))
    assert before.keys() == after.keys() and len(before) >= 20
    changed = {
        name: sorted(
            k
            for k in before[name].keys() | after[name].keys()
            if before[name].get(k) != after[name].get(k)
        )
        for name in before
    }
    return {name: keys for name, keys in changed.items() if keys}


def _add_toy_to_the_registry(package: Path) -> None:
    """The toy filter added as the package's own: a module, and an entry among FILTERS'."""
    (package / "kalman" / "toy.py").write_text(TOY_MODULE, encoding="utf-8")
    registry = package / "registry" / "filters.py"
    text = registry.read_text(encoding="utf-8")
    start = text.index("FILTERS: dict[str, Filter] = {")
    end = text.index("\n    )\n}\n", start)  # the end of the tuple of entries
    entry = textwrap.indent(TOY_ENTRY.format(run="toy.run").strip(), " " * 8)
    text = text[:end] + "\n" + entry + "," + text[end:]
    text = text.replace(
        "from depthcore.kalman import (",
        "from depthcore.kalman import toy\nfrom depthcore.kalman import (",
        1,
    )
    registry.write_text(text, encoding="utf-8")


def test_a_new_filter_makes_stale_only_the_records_of_studies_that_run_every_filter(tmp_path):
    def edit(package):
        _add_toy_to_the_registry(package)
        # a docstring and a comment of the exact filter, which nearly every study runs
        bank = package / "exact" / "bank.py"
        text = bank.read_text(encoding="utf-8")
        bank.write_text(text.replace('"""', '"""Reworded. ', 1) + "\n# a comment\n", "utf-8")

    changed = _changed_in_a_copy(tmp_path, edit)
    # the atlas runs every registered filter (ALL_NAMES), and so does its cost probe
    assert {name.split("-")[0] for name in changed} == {"atlas", "probe_cost"}, changed
    for keys in changed.values():
        assert keys == ["code depthcore.kalman.toy:run", "filter toy"]


def test_a_change_to_a_studys_code_makes_its_records_stale_and_no_others(tmp_path):
    def edit(package):
        reference = package.parent / "depthbook" / "reference.py"
        text = reference.read_text(encoding="utf-8")
        start = text.index("def grid_moments(")
        body = text.index('"""', text.index('"""', start) + 3) + 3  # past its docstring
        reference.write_text(text[:body] + "\n    rho = float(rho)" + text[body:], "utf-8")

    changed = _changed_in_a_copy(tmp_path, edit)
    assert {name.split("-")[0] for name in changed} == {"grid_moments"}, changed
    for keys in changed.values():
        assert keys == ["code depthbook.reference:grid_moments"]
