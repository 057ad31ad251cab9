"""No committed reference holds what varies between machines.

``make notebooks`` compares each page's outputs, run on this machine, with its
reference ``book/_nbval/<page>.ipynb``, written on another. A reference must
therefore hold only what every machine computes alike. The scan below reads
every code cell's outputs (streams, and the ``text/plain``, ``text/markdown``,
``text/html`` and ``text/latex`` shown or glued), sanitised first by the
regexes of ``tests/nbval_sanitize.cfg`` as nbval sanitises them, and fails on

* a number below 1e-10 in absolute value written with its digits: a rounding
  residue, whose digits change with the processor and the BLAS kernels. A page
  asserts a bound instead and shows it, a power of ten with mantissa 1
  ("below 1e-12"); the smallest normal double, 2.2250738585072014e-308, is a
  constant;
* a processor or a BLAS kernel set named: this machine's
  (:func:`depthbook.provenance.benchmarks.machine`), or any of :data:`MACHINE_WORDS`;
* a timing of the run: a number of s, ms, µs, seconds or minutes, except a study
  record's own "computed on YYYY-MM-DD in N s"
  (:class:`depthbook.provenance.records.Recorded`), which the record fixes.

A code cell tagged ``from-records`` is exempt: what it shows is read from the
committed benchmark or study records, the same on every machine.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import check_notebooks  # noqa: E402  (the reader of nbval's sanitize file)

REFERENCES = sorted((ROOT / "book" / check_notebooks.REF_DIR_NAME).glob("*.ipynb"))
#: The tag of a cell whose outputs are read from records.
FROM_RECORDS = "from-records"
#: The outputs scanned, shown or glued (``application/papermill.record/<mime>``).
MIMES = ("text/plain", "text/markdown", "text/html", "text/latex")
GLUED = "application/papermill.record/"
#: Below this, a number's digits are rounding residue.
TINY = 1e-10
#: Numbers below :data:`TINY` that are constants, not residues.
CONSTANTS = ("2.2250738585072014e-308",)

#: Processor makers, models and families, and OpenBLAS's kernel sets (Prescott's
#: kernels are named Katmai).
MACHINE_WORDS = re.compile(
    r"\b(?:Intel|AMD|EPYC|Xeon|Opteron|Ryzen|Haswell|SkylakeX|Sandybridge|Prescott|Katmai"
    r"|Core2|Penryn|Dunnington|Cooperlake|SapphireRapids|Zen\d*|Bulldozer|Piledriver"
    r"|Steamroller|Excavator|Nehalem|Neoverse\w*|Graviton\d*)\b"
    r"|\bfamily\s+\d+,\s*model\b",
    re.IGNORECASE,
)
_SIGN = r"[-+−]?"
_MANTISSA = r"\d+(?:\.\d*)?|\.\d+"
#: Numbers whose value may be tiny: "1.6e-13", "5E-15", "0.00000000001",
#: "1.6 \times 10^{-13}", "1.6×10⁻¹³"; group ``m`` is the mantissa, ``e`` the exponent.
NUMBER = re.compile(
    rf"(?<![\w.]){_SIGN}(?P<m>{_MANTISSA})"
    r"(?:[eE](?P<e>[-+−]?\d+)"
    r"|\s*(?:\\times|\\cdot|×|·)\s*10\s*(?:\^\{?(?P<x>[-+−]?\d+)\}?|(?P<u>[⁻⁺]?[⁰¹²³⁴⁵⁶⁷⁸⁹]+)))?"
    r"(?![\w.])"
)
_SUPERSCRIPT = str.maketrans("⁻⁺⁰¹²³⁴⁵⁶⁷⁸⁹", "-+0123456789")
#: A timing: a number of seconds, milliseconds, microseconds or minutes.
TIMING = re.compile(
    r"(?<![\w.])\d+(?:\.\d+)?[ \u00a0\u202f]*"
    r"(?:s|ms|µs|μs|us|secs?|seconds?|minutes?|mins?)(?![\w-])"
)
#: What a study record read says of its computation (``Recorded.__str__``): the record's own.
RECORD_TIMING = re.compile(r"computed on \d{4}-\d{2}-\d{2} in \d+ s\b")
#: A duration the code states as a limit ("answers within 5 s"), a constant, not a timing.
STATED_LIMIT = re.compile(
    r"\b(?:within|at most|under|after|timeout of)\s+\d+(?:\.\d+)?\s*(?:s|ms|seconds?|minutes?)\b"
)


def machine_names() -> list[str]:
    """This machine's processor, as a benchmark record would name it."""
    from depthbook.provenance.benchmarks import machine

    info = machine()
    return [str(info[key]).strip() for key in ("cpu", "processor") if str(info[key]).strip()]


def tiny_numbers(text: str) -> list[str]:
    """The numbers in ``text`` below :data:`TINY` (not zero) that are not a bound or a constant.

    A bound is a power of ten with mantissa exactly 1, written ``1e-12``,
    ``10^{-12}`` or ``10⁻¹²``.
    """
    found = []
    for match in NUMBER.finditer(text):
        mantissa = match["m"]
        exponent = match["e"] or match["x"] or (match["u"] or "").translate(_SUPERSCRIPT)
        exponent = exponent.replace("−", "-")
        try:
            value = float(mantissa) * 10.0 ** int(exponent or 0)
        except (ValueError, OverflowError):
            continue
        if value == 0 or abs(value) >= TINY:
            continue
        written = match.group(0).lstrip("-+−")
        if written in CONSTANTS or (mantissa == "1" and exponent):
            continue
        found.append(match.group(0))
    return found


def texts(cell) -> list[str]:
    """The texts a code cell's outputs show or glue, in order."""
    found = []
    for output in cell.get("outputs", []):
        if output.get("output_type") == "stream":
            found.append(output.get("text", ""))
            continue
        for mime, content in output.get("data", {}).items():
            if mime.removeprefix(GLUED) in MIMES:
                found.append(content if isinstance(content, str) else "".join(content))
    return found


def sanitised(text: str, patterns: dict[str, str]) -> str:
    """``text`` with nbval's sanitize regexes applied, as nbval compares it."""
    for regex, replace in patterns.items():
        text = re.sub(regex, replace, text)
    return text


def machine_specific(nb, page: str, patterns: dict[str, str], names=()) -> list[str]:
    """What the code cells of ``nb`` show that varies between machines, one message each.

    Parameters
    ----------
    nb : nbformat.NotebookNode
        A reference notebook.
    page : str
        Its page's name, for the messages.
    patterns : dict of str to str
        nbval's sanitize regexes (:func:`check_notebooks.sanitize_patterns`).
    names : sequence of str
        This machine's processor names (:func:`machine_names`).
    """
    words = [MACHINE_WORDS] + [re.compile(re.escape(name)) for name in names if name]
    problems = []
    code = [cell for cell in nb.cells if cell.cell_type == "code"]
    for index, cell in enumerate(code, start=1):
        if FROM_RECORDS in cell.get("metadata", {}).get("tags", []):
            continue
        where = f"{page}: code cell {index}"
        for text in texts(cell):
            text = sanitised(text, patterns)
            for number in tiny_numbers(text):
                problems.append(f"{where}: a number below {TINY:g} with its digits: {number!r}")
            for word in words:
                for match in word.finditer(text):
                    problems.append(f"{where}: names the machine: {match.group(0)!r}")
            for match in TIMING.finditer(STATED_LIMIT.sub("", RECORD_TIMING.sub("", text))):
                problems.append(f"{where}: a timing of the run: {match.group(0)!r}")
    return list(dict.fromkeys(problems))


@pytest.fixture(scope="module")
def patterns():
    return check_notebooks.sanitize_patterns()


def test_there_are_references():
    assert len(REFERENCES) >= 20


@pytest.mark.parametrize("reference", REFERENCES, ids=lambda p: p.stem)
def test_a_reference_holds_nothing_of_the_machine(reference, patterns):
    nb = nbformat.read(reference, as_version=4)
    problems = machine_specific(nb, reference.stem, patterns, machine_names())
    assert not problems, "\n".join(problems)


def notebook(*cells):
    """A notebook of code cells, each ``(text printed, tags)``."""
    nb = nbformat.v4.new_notebook()
    for text, tags in cells:
        cell = nbformat.v4.new_code_cell("print(...)", metadata={"tags": list(tags)})
        cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=text)]
        nb.cells.append(cell)
    return nb


@pytest.mark.parametrize(
    ("text", "found"),
    [
        ("largest entry of P_e^-1 P_s - I: 1.6e-13\n", "1.6e-13"),
        ("residue 3.1E-14 of the depth SD", "3.1E-14"),
        ("probability -5e-15", "-5e-15"),
        ("a sum of 0.000000000012", "0.000000000012"),
        ("$1.6 \\times 10^{-13}$", "1.6 \\times 10^{-13}"),
        ("1.6×10⁻¹³", "1.6×10⁻¹³"),
        ("run on an Intel Xeon", "Intel"),
        ("OpenBLAS 0.3.31, SkylakeX kernels", "SkylakeX"),
        ("AMD EPYC 7763, family 25, model 1", "AMD"),
        ("scipy-openblas 0.3.31, Katmai kernels", "Katmai"),
        ("the sweep took 3.2 s", "3.2 s"),
        ("12 ms per trial", "12 ms"),
        ("in 4 minutes", "4 minutes"),
    ],
)
def test_the_scan_finds_what_varies(text, found, patterns):
    problems = machine_specific(notebook((text, [])), "page", patterns)
    assert problems and repr(found) in "\n".join(problems), problems
    assert all(p.startswith("page: code cell 1: ") for p in problems)
    # the same output read from records is exempt
    assert machine_specific(notebook((text, [FROM_RECORDS])), "page", patterns) == []


@pytest.mark.parametrize(
    "text", ["refused unless it answers within 5 s", "a timeout of 30 s", "at most 2.5 seconds"]
)
def test_a_limit_the_code_states_is_no_timing(text, patterns):
    assert machine_specific(notebook((text, [])), "page", patterns) == []
    assert machine_specific(notebook((text + "; took 3.2 s", [])), "page", patterns)


def test_the_reference_test_fails_naming_page_cell_and_text(tmp_path, patterns):
    path = tmp_path / "page.ipynb"
    nb = notebook(("below 1e-12", []), ("records: 2.9e-16 SD on an Intel Xeon", [FROM_RECORDS]))
    nb.cells += notebook(("mismatch 1.6e-13 on an Intel Xeon; took 3.2 s", [])).cells
    nbformat.write(nb, path)
    with pytest.raises(AssertionError) as failure:
        test_a_reference_holds_nothing_of_the_machine(path, patterns)
    message = str(failure.value)
    for problem in (
        "page: code cell 3: a number below 1e-10 with its digits: '1.6e-13'",
        "page: code cell 3: names the machine: 'Intel'",
        "page: code cell 3: names the machine: 'Xeon'",
        "page: code cell 3: a timing of the run: '3.2 s'",
    ):
        assert problem in message
    assert "code cell 1" not in message and "code cell 2" not in message
    nbformat.write(notebook(("below 1e-12", []), ("took 3.2 s", [FROM_RECORDS])), path)
    test_a_reference_holds_nothing_of_the_machine(path, patterns)


def test_the_scan_names_this_machine(patterns):
    nb = notebook(("Built by a Frobnicator 9000 (rev 3)", []))
    assert machine_specific(nb, "page", patterns, ["Frobnicator 9000 (rev 3)"])
    assert machine_specific(nb, "page", patterns, []) == []


@pytest.mark.parametrize(
    "text",
    [
        "largest entry of P_e^-1 P_s - I: below 1e-12\n",
        "estimated error below 1E-12 of the depth SD, tail below 10^{-14}, 10⁻¹⁴",
        "the smallest normal double, 2.2250738585072014e-308",
        "read from its record depthbook/provenance/study_records/x.json, "
        "computed on 2025-01-31 in 42 s",
        "an error of 0.0 and 0e+00, a mean of 1.6e-3, 1e-3 of the SD",
        "Built on 2025-01-31 with depthcore 1.0 on an Intel Xeon, 0.2 s",
        "seeds 3 sigma 2 samples",
    ],
)
def test_the_scan_passes_what_every_machine_shows(text, patterns):
    assert machine_specific(notebook((text, [])), "page", patterns) == []


def test_the_scan_reads_glued_texts_and_names_the_cell(patterns):
    nb = notebook(("nothing here", []))
    cell = nbformat.v4.new_code_cell("glue(...)")
    cell.outputs = [
        nbformat.v4.new_output(
            "display_data",
            data={GLUED + "text/plain": "'3.1e-14'"},
            metadata={"scrapbook": {"name": "x", "mime_prefix": GLUED}},
        )
    ]
    nb.cells.append(cell)
    assert machine_specific(nb, "page", patterns) == [
        "page: code cell 2: a number below 1e-10 with its digits: '3.1e-14'"
    ]
