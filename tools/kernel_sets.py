"""Run a command as other processors would: under OpenBLAS kernel sets other than this one's.

``make notebooks-kernels`` runs the page checks (``tools/check_notebooks.py check``) once
per set, so that a reference which holds what one processor's kernels print, and another's
do not, fails here rather than on a reader's machine:

* OpenBLAS's kernels of other processors (``OPENBLAS_CORETYPE``): ``Nehalem`` (SSE4.2,
  before AVX), ``Haswell`` (AVX2) and ``SkylakeX`` (AVX-512, where this processor has it),
  each skipped where it is this processor's own choice or cannot run here (``Sandybridge``
  and ``Prescott``, which OpenBLAS names ``Katmai``, stand in while fewer than two run);
* NumPy's own SIMD loops cut to the build's baseline (``NPY_DISABLE_CPU_FEATURES``: every
  feature NumPy found beyond it), with this processor's BLAS kernels.

Each set is probed first (a Python that loads NumPy under it and names the kernels it
runs); a set that this processor cannot run is named and skipped, and fewer than two
OpenBLAS sets besides the native one is an error. Outside x86-64 only the NumPy set runs.

Usage: ``python tools/kernel_sets.py [--list] -- COMMAND [ARG ...]``; exits non-zero when
the command fails under any set, naming the sets it failed under.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

from depthbook.provenance import benchmarks

#: OpenBLAS's kernel sets to try, each with the CPU flags (of /proc/cpuinfo) it needs.
CORETYPES = {
    "Nehalem": ("sse4_2",),
    "Haswell": ("avx2", "fma"),
    "SkylakeX": ("avx512f", "avx512bw", "avx512vl", "avx512dq", "avx512cd"),
}
#: Tried, in this order, only while fewer than two of :data:`CORETYPES` could run.
FALLBACKS = {"Sandybridge": ("avx",), "Prescott": ("pni",)}
#: Kernel sets OpenBLAS names otherwise, or that run the same kernels: by the name it reports.
SAME = {"katmai": "prescott", "zen": "haswell"}
#: The variable a set adds to the environment; the machine's own OPENBLAS_CORETYPE, where one
#: is set (on processors an older OpenBLAS mishandles), is kept as the native set.
NUMPY = "NPY_DISABLE_CPU_FEATURES"
#: What the probe prints: the kernels OpenBLAS runs and the SIMD features NumPy uses.
PROBE = """
import json, numpy
from depthbook.provenance import benchmarks
m = benchmarks.machine()
simd = numpy.show_config(mode="dicts").get("SIMD Extensions", {})
print(json.dumps({"blas": m["blas"], "baseline": simd.get("baseline", []),
                  "found": simd.get("found", [])}))
"""


def cpu_flags() -> set[str]:
    """The flags of this processor (Linux's /proc/cpuinfo), empty where it cannot be read."""
    return set(benchmarks.cpuinfo().get("flags", "").split())


def probe(env: dict) -> dict | None:
    """What NumPy and OpenBLAS run under ``env``; None when a Python cannot start under it."""
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=120
    )
    if out.returncode != 0:
        return None
    return json.loads(out.stdout.splitlines()[-1])


def kernel(blas: str) -> str:
    """The kernel set's name in :func:`depthbook.provenance.benchmarks.machine`'s ``blas``."""
    return blas.removesuffix(" kernels").rsplit(", ", 1)[-1]


def _same(name: str) -> str:
    """A kernel set's name, lower case, as the set whose kernels it runs (:data:`SAME`)."""
    return SAME.get(name.lower(), name.lower())


def kernel_sets(base: dict) -> tuple[list[tuple[str, dict]], list[str]]:
    """The sets to run under, each a name and its environment, and the sets skipped, why."""
    native = probe(base)
    if native is None:
        raise RuntimeError("a Python with NumPy and depthcore does not start here")
    sets, skipped = [], []
    x86 = platform.machine().lower() in ("x86_64", "amd64")
    flags, own = cpu_flags(), _same(kernel(native["blas"]))
    for name, needs in {**CORETYPES, **FALLBACKS}.items() if x86 else ():
        if name in FALLBACKS and len(sets) >= 2:
            break
        env = {**base, "OPENBLAS_CORETYPE": name}
        if _same(name) == own:
            skipped.append(f"{name} (this processor's own)")
        elif not set(needs) <= flags:
            skipped.append(f"{name} (needs {', '.join(sorted(set(needs) - flags))})")
        elif (seen := probe(env)) is None or _same(kernel(seen["blas"])) != _same(name):
            skipped.append(f"{name} (OpenBLAS did not run it here)")
        else:
            sets.append((f"OPENBLAS_CORETYPE={name}", env))
    if x86 and len(sets) < 2:
        raise RuntimeError(
            f"fewer than two OpenBLAS kernel sets besides this processor's: {'; '.join(skipped)}"
        )
    beyond = [f for f in native["found"] if f not in native["baseline"]]
    if beyond:
        features = " ".join(beyond)
        sets.append((f'{NUMPY}="{features}"', {**base, NUMPY: features}))
    else:
        skipped.append("NPY_DISABLE_CPU_FEATURES (NumPy found nothing beyond its baseline)")
    return sets, skipped


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="name the sets and run nothing")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- COMMAND [ARG ...]")
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command and not args.list:
        parser.error("a command to run is required, after --")
    base = {k: v for k, v in os.environ.items() if k != NUMPY}
    try:
        sets, skipped = kernel_sets(base)
    except RuntimeError as err:
        print(f"kernel sets: {err}", file=sys.stderr)
        return 1
    for why in skipped:
        print(f"kernel sets: skipped {why}", flush=True)
    failed = []
    for name, env in sets:
        if args.list:
            print(f"kernel sets: {name}")
            continue
        print(f"kernel sets: {' '.join(command)}  under {name}", flush=True)
        start = time.monotonic()
        status = subprocess.run(command, env=env).returncode
        print(
            f"kernel sets: under {name}: {'passed' if status == 0 else 'FAILED'} "
            f"({time.monotonic() - start:.0f} s)",
            flush=True,
        )
        if status != 0:
            failed.append(name)
    if failed:
        print(f"kernel sets: failed under {'; '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
