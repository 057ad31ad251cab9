"""Time ``import depthcore`` against ``import numpy``, each in fresh interpreters.

Prints the median wall time of each over several runs and the difference,
the cost of the package on top of NumPy (target: at most 0.15 s). Usage:
``python benchmarks/bench_import.py [--quick]``; the full run writes its record
``depthbook/provenance/benchmark_records/bench_import.json``
(:mod:`depthbook.provenance.benchmarks`),
``--quick`` (3 runs each) writes outside the committed records.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys

from depthbook.provenance import benchmarks

RUNS = 15
#: The depthcore modules that ``import depthcore`` loads (fingerprinted in the record).
MEASURES = (
    "__init__",
    "_paths",
    "problem",
    "problem.gaussian",
    "problem.model",
    "problem.scenarios",
    "problem.checks",
)
CODE = "import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"


def _time(module: str, runs: int) -> float:
    """Median seconds to import ``module`` in a fresh interpreter (NumPy imported first)."""
    times = []
    for _ in range(runs):
        code = (
            "import numpy; " + CODE.format(module=module)
            if module != "numpy"
            else CODE.format(module=module)
        )
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        )
        times.append(float(out.stdout))
    return statistics.median(times)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="3 runs each (not recorded)")
    args = p.parse_args(argv)
    runs = 3 if args.quick else RUNS
    numpy_time = _time("numpy", runs)
    extra = _time("depthcore", runs)
    print(f"{'import':<28} {'median time':>12}")
    print(f"{'numpy':<28} {numpy_time:>10.3f} s")
    print(f"{'depthcore, after numpy':<28} {extra:>10.3f} s")
    print(f"depthcore costs {extra:.3f} s on top of numpy (target: at most 0.150 s)")
    results = {"numpy_s": numpy_time, "depthcore_after_numpy_s": extra, "target_s": 0.15}
    path = benchmarks.write(__file__, MEASURES, {"runs": runs}, results, full=not args.quick)
    print(f"recorded in {path}")


if __name__ == "__main__":
    main()
