"""Time ``import depthcore`` against ``import numpy``, each in fresh interpreters.

Prints the median wall time of each over several runs and the difference,
the cost of the package on top of NumPy (target: at most 0.15 s).
"""

from __future__ import annotations

import statistics
import subprocess
import sys

RUNS = 15
CODE = "import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"


def _time(module: str) -> float:
    """Median seconds to import ``module`` in a fresh interpreter (NumPy imported first)."""
    times = []
    for _ in range(RUNS):
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


def main() -> None:
    numpy_time = _time("numpy")
    extra = _time("depthcore")
    print(f"{'import':<28} {'median time':>12}")
    print(f"{'numpy':<28} {numpy_time:>10.3f} s")
    print(f"{'depthcore, after numpy':<28} {extra:>10.3f} s")
    print(f"depthcore costs {extra:.3f} s on top of numpy (target: at most 0.150 s)")


if __name__ == "__main__":
    main()
