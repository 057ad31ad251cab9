"""Strategies and helpers shared by the core tests."""

import json

import numpy as np
from hypothesis import assume
from hypothesis import strategies as st

from depthcore.problem import model


@st.composite
def states(draw):
    """A state at time 3 whose point is in front of the camera at times 1-3 and
    whose three bearings are not collinear in time (|second difference| >= 1e-3)."""
    y = draw(st.floats(3.0, 40.0))
    x = draw(st.floats(-0.8, 0.8)) * y
    v = draw(st.floats(-2.0, 2.0))
    c = np.array([x, y, v])
    if abs(_second_difference(c)) < 1e-3:
        v = v + 0.5 if v < 1.5 else v - 0.5
        c = np.array([x, y, v])
    # the shift can land on another collinear triple (the point moving along its line
    # of sight); such draws are rejected rather than returned
    assume(abs(_second_difference(c)) >= 1e-3)
    return c


def _second_difference(c) -> float:
    mu = bearings(c)
    return mu[0] + mu[2] - 2 * mu[1]


def bearings(c):
    """The noise-free measurements (mu1, mu2, mu3) of a state ``c`` at time 3."""
    return np.array([model.project(model.G(c, k - 2)) for k in range(3)])


def exit_status(argv) -> int:
    """The exit status of ``python -m depthcore *argv``, run in this process."""
    from depthcore.cli.main import main

    try:
        return main(argv)
    except SystemExit as exc:  # argparse's refusals
        return exc.code


def run_cli(argv, capsys):
    """``(status, stdout, stderr)`` of ``python -m depthcore *argv`` run in this process."""
    status = exit_status(argv)
    out, err = capsys.readouterr()
    return status, out, err


def strict_json(text: str):
    """``text`` read as JSON, failing on ``NaN``, ``Infinity`` or ``-Infinity``."""

    def refuse(constant):
        raise AssertionError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def cli_json(argv, capsys):
    """The strict JSON the command line prints with ``--json``, nothing on stderr."""
    status, out, err = run_cli([*argv, "--json"], capsys)
    assert status == 0 and err == "", err
    return strict_json(out)


def cli_refused(argv, capsys, *words):
    """A refusal: status 2, one line on stderr naming ``words``, no traceback or warning."""
    status, out, err = run_cli(argv, capsys)
    assert status == 2 and out == "" and err.count("\n") == 1, (status, out, err)
    assert "Traceback" not in err and "Warning" not in err, err
    for w in words:
        assert w in err, err
    return err


#: The environment of a subprocess that runs an older x86-64 processor's kernels:
#: OpenBLAS's for an SSE4.2 processor, and NumPy's SIMD cut to its baseline.
OLDER_KERNELS = {
    "OPENBLAS_CORETYPE": "Nehalem",
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
}


def answer_or_one_line(run, **args):
    """``run(**args)`` with warnings as errors: its answer, or ``None`` where it refused in
    one line (a ``ValueError`` whose message has no line break)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return run(**args)
        except ValueError as exc:
            assert "\n" not in str(exc)
            return None
