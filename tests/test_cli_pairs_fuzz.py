"""Fuzz estimate's points in 3-D and its priors: odd files of pairs and odd options.

Every case ends in an answer with finite numbers (strict JSON, a table or CSV) or a
one-line refusal with exit status 2; never a traceback, a warning or another status.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
import warnings

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import exit_status

#: A field of a random file of pairs: a number near a real track's, or something odd.
_FIELDS = st.one_of(
    st.floats(-0.5, 0.5).map(repr),
    st.floats(100.0, 500.0).map(repr),
    st.sampled_from(["", "nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "abc", "1e", " 0.1"]),
)

#: Options, each given at most once: some a pair's, some a prior's, some refused with pairs.
_OPTIONS = [
    ["--per-frame"],
    ["--cy", "1e12"],
    ["--prior-mean", "0", "10", "0"],
    ["--prior-mean", "0", "10", "0", "1", "0"],
    ["--prior-mean", "0", "1e300", "0", "1", "0"],
    ["--prior-cov", *np.eye(3).ravel().astype(str)],
    ["--prior-cov", *np.eye(5).ravel().astype(str)],
    ["--prior-cov", "1e-300"],
    ["--prior-depth", "10", "3"],
    ["--prior-depth", "inf", "3"],
    ["--smooth"],
    ["--gate", "0.01"],
    ["--learn-noise"],
    ["--filters", "ekf"],
    ["--filters", "optimal", "second_order"],
    ["--direction", "approaching"],
    ["--process-noise", "0.01"],
]


@st.composite
def _pair_files(draw):
    """A point's pairs over 3 to 10 frames, in bearings or pixels, then a few fields spoiled:
    an odd value, or one coordinate of a pair left out."""
    n = draw(st.integers(3, 10))
    y, v, w = draw(st.floats(3.0, 30.0)), draw(st.floats(-1.0, 1.0)), draw(st.floats(-1.0, 1.0))
    x, h = draw(st.floats(-0.8, 0.8)) * y, draw(st.floats(-0.8, 0.8)) * y
    e = np.arange(n)
    noise = np.array(draw(st.lists(st.floats(-0.01, 0.01), min_size=2 * n, max_size=2 * n)))
    pairs = np.stack([(x + v * e), (h + w * e)], -1) / (y + e)[:, None] + noise.reshape(n, 2)
    pixels = draw(st.booleans())
    columns = ["u", "v"] if pixels else ["mu", "nu"]
    cells = (np.array([320.0, 240.0]) + 500.0 * pairs) if pixels else pairs
    rows = [[repr(c) for c in row] for row in cells.tolist()]
    if draw(st.booleans()):
        columns, rows = ["frame", *columns], [[str(k + 1), *r] for k, r in enumerate(rows)]
    if draw(st.booleans()):
        columns, rows = [*columns, "rho"], [[*r, "0.01"] for r in rows]
    for _ in range(draw(st.integers(0, 2))):
        k, j = draw(st.integers(0, n - 1)), draw(st.integers(0, len(columns) - 1))
        rows[k][j] = draw(_FIELDS)
    return "\n".join(",".join(r) for r in [columns, *rows]) + "\n"


def _output(argv):
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = exit_status(argv)
    return status, out.getvalue(), err.getvalue()


def _finite(value) -> bool:
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, list):
        return all(_finite(v) for v in value)
    return not isinstance(value, float) or math.isfinite(value)


def _strict(text: str):
    def refuse(constant):
        raise AssertionError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def _answered_or_refused(argv, output: str) -> None:
    status, out, err = _output(argv)
    if status == 0:
        assert err == "", err
        if output == "json":
            assert _finite(_strict(out)), out
        elif output == "csv":
            rows = list(csv.reader(io.StringIO(out)))
            assert len(rows) >= 2 and all(len(r) == len(rows[0]) for r in rows), out
        else:
            assert "legend:" in out and " nan" not in out.lower(), out
        return
    assert status == 2, (status, err)
    assert out == "" and err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and "Warning" not in err, err


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    text=_pair_files(),
    options=st.lists(st.sampled_from(_OPTIONS), max_size=4, unique_by=lambda o: o[0]),
    output=st.sampled_from(["json", "csv", "table"]),
    draw_pixels=st.sampled_from([True, True, True, False]),
    draw_rho=st.sampled_from([True, True, True, False]),
)
def test_estimate_answers_or_refuses_any_file_of_pairs_in_one_line(
    text, options, output, draw_pixels, draw_rho
):
    flat = [a for o in options for a in o]
    if output == "csv" and "--per-frame" not in flat:
        output = "table"
    if text.startswith(("u", "frame,u")) and draw_pixels:
        flat = [
            "--focal",
            "500",
            "--cx",
            "320",
            *(["--cy", "240"] if "--cy" not in flat else []),
            *flat,
        ]
    if ",rho" not in text.split("\n")[0] and draw_rho:
        flat = ["--rho", "0.01", *flat]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "pairs.csv")
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        flags = {"json": ["--json"], "csv": ["--csv"], "table": []}[output]
        _answered_or_refused(["estimate", "--mu-file", path, *flat, *flags], output)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    text=_pair_files(),
    options=st.lists(st.sampled_from(_OPTIONS), max_size=3, unique_by=lambda o: o[0]),
    drop=st.booleans(),
)
def test_estimate_answers_or_refuses_any_mu_and_nu_in_one_line(text, options, drop):
    """The same pairs given as --mu and --nu (the first column's and the second's)."""
    rows = [r.split(",") for r in text.splitlines()[1:]]
    head = text.splitlines()[0].split(",")
    i = 1 if head[0] == "frame" else 0
    mu, nu = [r[i] or "nan" for r in rows], [r[i + 1] or "nan" for r in rows]
    flat = [a for o in options for a in o]
    argv = ["estimate", "--mu", *mu, "--nu", *nu[: len(nu) - drop], "--rho", "0.01", *flat]
    _answered_or_refused([*argv, "--json"], "json")
