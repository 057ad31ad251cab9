"""The package needs NumPy and SciPy alone: every module imports, and every filter runs,
with matplotlib, tqdm, Dask, Stone Soup and the book's package out of reach."""

from __future__ import annotations

import json
import subprocess
import sys

#: What the core must not need: the extras' packages and the book's own.
BLOCKED = ("matplotlib", "tqdm", "dask", "distributed", "stonesoup", "depthbook")

BLOCKER = f"""
import importlib.abc, sys
BLOCKED = {BLOCKED!r}
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ImportError(f"blocked: {{name}}")
sys.meta_path.insert(0, Block())
"""

CHECK = """
import importlib, json
import depthcore
from depthcore import SCENARIOS
from depthcore.registry.filters import ALL_NAMES, FILTERS
from depthcore.cli.main import main

imported = []
for name in depthcore.MODULES:
    if name.startswith("depthcore.stonesoup"):
        continue  # the bridge to Stone Soup is an extra of its own
    importlib.import_module(name)
    imported.append(name)
s = SCENARIOS["fig2"]
depths = {}
for name in ALL_NAMES:
    f = FILTERS[name]
    options = {"rng": 1, "n_particles": 200} if f.random else {}
    depths[name] = float(f(s.mu, s.rho, s.prior.mean, s.prior.cov, **options).depth_mean)
status = main(["estimate", "--mu", "-0.3", "0", "0.2", "--rho", "0.005", "--json"])
print()
print(json.dumps({"imported": imported, "depths": depths, "status": status}))
"""


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def test_the_blocker_blocks():
    done = _run(BLOCKER + "import matplotlib")
    assert done.returncode != 0 and "blocked: matplotlib" in done.stderr


def test_every_module_imports_and_every_filter_runs_without_the_extras():
    done = _run(BLOCKER + CHECK)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["status"] == 0
    assert "depthcore.cli.main" in got["imported"] and len(got["imported"]) >= 60
    from depthcore.registry.filters import ALL_NAMES

    assert sorted(got["depths"]) == sorted(ALL_NAMES)
    assert all(d == d and abs(d) < 1e6 for d in got["depths"].values())
