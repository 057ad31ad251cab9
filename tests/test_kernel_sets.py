"""The page checks as other processors would run them: tools/kernel_sets.py."""

from __future__ import annotations

import platform
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import kernel_sets  # noqa: E402


def test_the_kernel_is_read_from_the_machines_blas():
    assert kernel_sets.kernel("scipy-openblas 0.3.31.188.0, SkylakeX kernels") == "SkylakeX"
    assert kernel_sets.kernel("openblas 0.3.27, Haswell kernels") == "Haswell"


@pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS's x86-64 kernel sets")
def test_at_least_two_other_kernel_sets_and_numpys_baseline_run_here():
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "kernel_sets.py"), "--list"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    runs = [line for line in out.stdout.splitlines() if "skipped" not in line]
    blas = [line for line in runs if "OPENBLAS_CORETYPE=" in line]
    assert len(blas) >= 2 and len(set(blas)) == len(blas), out.stdout
    from depthbook.provenance import benchmarks

    native = kernel_sets.kernel(benchmarks.machine()["blas"])
    assert not any(line.endswith(f"={native}") for line in blas), (native, out.stdout)


def test_a_failure_under_one_set_fails_the_run_and_names_the_set():
    fail_under_haswell = (
        "import os, sys; sys.exit(os.environ.get('OPENBLAS_CORETYPE') == 'Haswell'"
        " or 'NPY_DISABLE_CPU_FEATURES' in os.environ)"
    )
    out = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "kernel_sets.py"),
            "--",
            sys.executable,
            "-c",
            fail_under_haswell,
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 1
    assert "failed under" in out.stderr and "NPY_DISABLE_CPU_FEATURES" in out.stderr


def test_ci_runs_the_page_checks_under_other_kernel_sets_after_make_test():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert ci.index("make test") < ci.index("make notebooks-kernels")
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = makefile.split("\nnotebooks-kernels:", 1)[1].split("\n\n", 1)[0]
    assert "tools/kernel_sets.py --" in recipe and "check_notebooks.py check" in recipe


def _machine(monkeypatch, native: str, flags: set[str]) -> None:
    """A processor with ``flags`` whose OpenBLAS picks ``native`` and runs whatever it is told."""

    def probe(env):
        core = env.get("OPENBLAS_CORETYPE", native)
        named = {"Prescott": "Katmai"}.get(core, core)
        return {"blas": f"openblas 0.3, {named} kernels", "baseline": ["X86_V2"], "found": []}

    monkeypatch.setattr(kernel_sets, "probe", probe)
    monkeypatch.setattr(kernel_sets, "cpu_flags", lambda: flags)
    monkeypatch.setattr(kernel_sets.platform, "machine", lambda: "x86_64")


AVX2 = {"sse4_2", "avx", "avx2", "fma", "pni"}


@pytest.mark.parametrize(
    "native, flags, chosen",
    [
        ("SkylakeX", AVX2 | set(kernel_sets.CORETYPES["SkylakeX"]), ["Nehalem", "Haswell"]),
        ("Haswell", AVX2, ["Nehalem", "Sandybridge"]),  # no AVX-512: a fallback stands in
        ("Zen", AVX2, ["Nehalem", "Sandybridge"]),  # Zen runs Haswell's kernels
        ("Nehalem", {"sse4_2", "pni"}, ["Prescott"]),  # too few: refused below
    ],
)
def test_two_other_kernel_sets_are_chosen_wherever_two_can_run(monkeypatch, native, flags, chosen):
    _machine(monkeypatch, native, flags)
    if len(chosen) < 2:
        with pytest.raises(RuntimeError, match="fewer than two OpenBLAS kernel sets"):
            kernel_sets.kernel_sets({})
        return
    sets, skipped = kernel_sets.kernel_sets({})
    assert [name.split("=")[1] for name, _ in sets] == chosen
    assert all(env["OPENBLAS_CORETYPE"] == name.split("=")[1] for name, env in sets)
    assert any("NPY_DISABLE_CPU_FEATURES (NumPy found nothing" in why for why in skipped)
