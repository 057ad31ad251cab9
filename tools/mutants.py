"""Apply hand-written mutants of the library one at a time and run the tests that should kill them.

Usage (from the repository root, with the project's virtual environment)::

    .venv/bin/python tools/mutants.py                  # every mutant
    .venv/bin/python tools/mutants.py coverage agrees  # mutants whose name contains a word
    .venv/bin/python tools/mutants.py --tests-from REV # the tests as they were at commit REV

Each mutant is one textual replacement in one library file (the text must
occur exactly once). For each, the tracked files are copied to a scratch
folder, the mutant is applied there (the working tree is never changed), and
the test module named beside it runs against the copy. A mutant is *killed*
when at least one test fails; the failing tests are listed. The table ends
with the number of survivors, and the exit status is 1 if any survived.

This is a development aid: it is not part of ``make test``.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: ``(name, library file, original text, mutated text, test module)``.
MUTANTS = [
    (
        "coverage threshold (every level)",
        "depthcore/studies/scores.py",
        "return np.abs(np.asarray(cdf, dtype=float) - 0.5) <= level / 2",
        "return np.abs(np.asarray(cdf, dtype=float) - 0.5) <= level / 2.1",
        "tests/test_study.py",
    ),
    (
        "coverage count (calibration curve)",
        "depthcore/studies/scores.py",
        "q: [float(self.covered[k, level[p]] / n) for p in CALIBRATION_LEVELS]",
        "q: [float(self.covered[k, level[p]] / (n + 1)) for p in CALIBRATION_LEVELS]",
        "tests/test_study.py",
    ),
    (
        "coverage centre",
        "depthcore/studies/scores.py",
        "return np.abs(np.asarray(cdf, dtype=float) - 0.5) <= level / 2",
        "return np.abs(np.asarray(cdf, dtype=float) - 0.49) <= level / 2",
        "tests/test_study.py",
    ),
    (
        "Gaussian velocity CDF variance: the depth's",
        "depthcore/registry/estimates.py",
        "ndtr((truths[:, 2] - mean[:, 2]) / np.sqrt(cov[:, 2, 2]))",
        "ndtr((truths[:, 2] - mean[:, 2]) / np.sqrt(cov[:, 1, 1]))",
        "tests/test_study.py",
    ),
    (
        "Gaussian velocity CDF variance: doubled",
        "depthcore/registry/estimates.py",
        "ndtr((truths[:, 2] - mean[:, 2]) / np.sqrt(cov[:, 2, 2]))",
        "ndtr((truths[:, 2] - mean[:, 2]) / np.sqrt(2 * cov[:, 2, 2]))",
        "tests/test_study.py",
    ),
    (
        "Gaussian depth CDF variance: no square root",
        "depthcore/registry/estimates.py",
        "ndtr((truths[:, 1] - mean[:, 1]) / np.sqrt(cov[:, 1, 1]))",
        "ndtr((truths[:, 1] - mean[:, 1]) / cov[:, 1, 1])",
        "tests/test_study.py",
    ),
    (
        "particle SD error: no factor 2",
        "depthcore/particles/resampling.py",
        "se_var / (2.0 * sd)",
        "se_var / sd",
        "tests/test_resampling.py",
    ),
    (
        "particle SD error: centred on the SD, not the variance",
        "depthcore/particles/resampling.py",
        "(d2 - sd[..., None] ** 2) ** 2",
        "(d2 - sd[..., None]) ** 2",
        "tests/test_resampling.py",
    ),
    (
        "particle mean error: weights not squared",
        "depthcore/particles/resampling.py",
        "se_mean = np.sqrt(np.sum(W**2 * d2, axis=-1))",
        "se_mean = np.sqrt(np.sum(W * d2, axis=-1) / W.shape[-1])",
        "tests/test_resampling.py",
    ),
    (
        "particle velocity errors taken from the depth",
        "depthcore/particles/importance.py",
        "*weighted_standard_errors(self.particles[..., 2], W),",
        "*weighted_standard_errors(self.particles[..., 1], W),",
        "tests/test_resampling.py",
    ),
    (
        "agrees-with-the-paper tolerance: a whole unit",
        "depthcore/studies/reproduce.py",
        "abs(value - printed) <= 0.5 * 10.0**-REPORTED_DECIMALS + 1e-12",
        "abs(value - printed) <= 1.0 * 10.0**-REPORTED_DECIMALS + 1e-12",
        "tests/test_reproduce.py",
    ),
    (
        "agrees-with-the-paper tolerance: one decimal fewer",
        "depthcore/studies/reproduce.py",
        "abs(value - printed) <= 0.5 * 10.0**-REPORTED_DECIMALS + 1e-12",
        "abs(value - printed) <= 0.5 * 10.0 ** -(REPORTED_DECIMALS - 1) + 1e-12",
        "tests/test_reproduce.py",
    ),
    (
        "agrees-with-the-paper tolerance: slack 1e-3",
        "depthcore/studies/reproduce.py",
        "abs(value - printed) <= 0.5 * 10.0**-REPORTED_DECIMALS + 1e-12",
        "abs(value - printed) <= 0.5 * 10.0**-REPORTED_DECIMALS + 1e-3",
        "tests/test_reproduce.py",
    ),
    (
        "figures 2-6 draw one filter's curve for all",
        "depthbook/paper.py",
        'ax.plot(curves["grid"], curves[name], linewidth=1.6, **STYLE[name])',
        'ax.plot(curves["grid"], curves[filters[0]], linewidth=1.6, **STYLE[name])',
        "tests/test_figures.py",
    ),
    (
        "figures 2-6 draw on a shifted grid",
        "depthbook/paper.py",
        "curves = reproduce.curves(s, np.linspace(lo, hi, n), filters=filters)",
        "curves = reproduce.curves(s, np.linspace(lo, hi, n) + 0.01, filters=filters)",
        "tests/test_figures.py",
    ),
    (
        "readings figure draws one reading twice",
        "depthbook/paper.py",
        "m = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading=reading)",
        'm = optimal.run(s.mu, s.rho, s.prior.mean, s.prior.cov, reading="derived")',
        "tests/test_figures.py",
    ),
    (
        "first-update figure draws 1-SD ellipses",
        "depthbook/beyond_filters.py",
        "*_ellipse(mean[:2], cov[:2, :2]).T,",
        "*_ellipse(mean[:2], cov[:2, :2], 1.0).T,",
        "tests/test_figures.py",
    ),
    (
        "first-update figure draws the sigma points' velocities",
        "depthbook/beyond_filters.py",
        "X[:, 1],\n        marker=",
        "X[:, 2],\n        marker=",
        "tests/test_figures.py",
    ),
    (
        "convergence figure's ideal line is sd / N",
        "depthbook/beyond_particles.py",
        'ideal = result["exact"][f"{quantity}_sd"] / np.sqrt(N)',
        'ideal = result["exact"][f"{quantity}_sd"] / N',
        "tests/test_figures.py",
    ),
    (
        "noise-study figure draws the coverage as the RMSE",
        "depthbook/beyond_sweeps.py",
        'for ax, score in zip(axes, ("coverage_68", "rmse"), strict=True):',
        'for ax, score in zip(axes, ("coverage_68", "coverage_68"), strict=True):',
        "tests/test_figures.py",
    ),
    (
        "profile figure without the factor 2",
        "depthbook/beyond_sweeps.py",
        "np.exp(-f / (2.0 * rho**2)),",
        "np.exp(-f / (rho**2)),",
        "tests/test_figures.py",
    ),
    (
        "calibration figure draws the depth for every quantity",
        "depthbook/beyond_study.py",
        'ax.plot(cal["levels"], cal[quantity],',
        'ax.plot(cal["levels"], cal["depth"],',
        "tests/test_figures.py",
    ),
    (
        "sweep figure draws the optimal filter's field for all",
        "depthbook/beyond_sweeps.py",
        'ax.plot(result[x], result[name][field], marker="o"',
        'ax.plot(result[x], result["optimal"][field], marker="o"',
        "tests/test_figures.py",
    ),
    (
        "a stale study record is read",
        "depthbook/provenance/records.py",
        'if not stale(record) and record["function"] == name:',
        'if record["function"] == name:',
        "tests/test_study_records.py",
    ),
    (
        "a recorded array loses its dtype",
        "depthbook/provenance/records.py",
        'dtype = np.dtype(value["__array__"])',
        "dtype = np.dtype(float)",
        "tests/test_study_records.py",
    ),
    (
        "two frames taken as a number of frames",
        "depthcore/problem/checks.py",
        "or not 3 <= value <= MAX_FRAMES",
        "or not 2 <= value <= MAX_FRAMES",
        "tests/test_checks.py",
    ),
    (
        "the paired coverage gap of compare at one level only",
        "depthcore/studies/pairs.py",
        "gap, se = coverage_gap_difference(m, c, n, p)",
        "gap, se = coverage_gap_difference(m, c, n, levels[0])",
        "tests/test_study_paired.py",
    ),
    (
        "quadrature range: no node before the first kept",
        "depthcore/exact/quadrature.py",
        "j_lo = _clip(np.where(active, first - 1, 0), 0, n - 1)",
        "j_lo = _clip(np.where(active, first, 0), 0, n - 1)",
        "tests/test_optimal.py",
    ),
    (
        "quadrature range: a scan point rounded inward",
        "depthcore/exact/quadrature.py",
        "np.floor(np.min(np.where(keep_scan, scan_index, np.inf), axis=1)),",
        "np.ceil(np.min(np.where(keep_scan, scan_index, np.inf), axis=1)),",
        "tests/test_optimal.py",
    ),
]


def _copy_tree(dest: Path, tests_from: str | None) -> None:
    files = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.split("\0")
    for name in filter(None, files):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    if tests_from:
        for name in filter(None, files):
            if name.startswith("tests/") and name.endswith(".py"):
                old = subprocess.run(
                    ["git", "show", f"{tests_from}:{name}"], cwd=ROOT, capture_output=True
                )
                if old.returncode == 0:
                    (dest / name).write_bytes(old.stdout)


def run_mutant(mutant, tests_from: str | None, workers: int) -> tuple[bool, list[str]]:
    """Apply one mutant in a scratch copy; return (killed, failing test ids)."""
    name, path, old, new, tests = mutant
    with tempfile.TemporaryDirectory(prefix="mutant-") as tmp:
        dest = Path(tmp)
        _copy_tree(dest, tests_from)
        text = (dest / path).read_text()
        if text.count(old) != 1:
            raise SystemExit(f"mutant {name!r}: the original text occurs {text.count(old)} times")
        (dest / path).write_text(text.replace(old, new))
        env = {**os.environ, "PYTHONPATH": str(dest), "MPLBACKEND": "Agg"}
        args = [sys.executable, "-m", "pytest", "-q", "-rf", "-p", "no:cacheprovider", tests]
        if workers > 1:
            args += ["-n", str(workers)]
        out = subprocess.run(args, cwd=dest, env=env, capture_output=True, text=True).stdout
        failed = re.findall(r"^FAILED (\S+)", out, flags=re.MULTILINE)
        if not failed and " passed" not in out:
            raise SystemExit(f"mutant {name!r}: pytest did not run:\n{out[-2000:]}")
        return bool(failed), failed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("words", nargs="*", help="run only mutants whose name contains a word")
    parser.add_argument("--tests-from", help="take tests/*.py from this git revision")
    parser.add_argument("-n", "--workers", type=int, default=2, help="pytest-xdist workers")
    args = parser.parse_args(argv)
    chosen = [m for m in MUTANTS if not args.words or any(w in m[0] for w in args.words)]
    survivors = 0
    for mutant in chosen:
        killed, failed = run_mutant(mutant, args.tests_from, args.workers)
        survivors += not killed
        print(f"{'KILLED ' if killed else 'SURVIVED'} {mutant[0]}  [{mutant[4]}]", flush=True)
        for test in failed:
            print(f"    {test}", flush=True)
    print(f"{len(chosen) - survivors} of {len(chosen)} mutants killed, {survivors} survived")
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
