"""``python -m depthbook figures``: the paper's figures as files, and its one-line refusals."""

from __future__ import annotations

import inspect

import pytest

from depthbook import paper
from depthbook.__main__ import FORMATS, main, parser


def status(argv) -> int:
    """The exit status of ``python -m depthbook *argv``, run in this process."""
    try:
        return main(argv)
    except SystemExit as exc:  # argparse's refusals
        return exc.code


def test_writes_each_figure_in_the_formats_named(tmp_path, capsys):
    # (all three by default: `make downloads` writes them, tests/book/test_downloads.py checks)
    assert status(["figures", "--out", str(tmp_path), "--format", "svg"]) == 0
    expected = [f"figure{n}{x}.svg" for n in range(2, 7) for x in ("", "-extended")]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(expected)
    assert capsys.readouterr().out.split() == [str(tmp_path / name) for name in expected]


def test_the_formats_are_those_the_figures_are_written_in_by_default():
    assert inspect.signature(paper.save_all).parameters["formats"].default == FORMATS
    assert parser().parse_args(["figures"]).formats is None  # then FORMATS
    with pytest.raises(SystemExit):
        parser().parse_args(["figures", "--format", "jpg"])


def test_refuses_a_format_named_twice_or_unknown(tmp_path, capsys):
    argv = ["figures", "--out", str(tmp_path), "--format", "svg", "png", "svg"]
    assert status(argv) == 2 and not any(tmp_path.iterdir())
    out, err = capsys.readouterr()
    assert out == "" and err.strip().splitlines() == [
        "python -m depthbook: error: --format names svg more than once"
    ]
    assert status(["figures", "--out", str(tmp_path), "--format", "jpg"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "invalid choice: 'jpg'" in err


@pytest.mark.parametrize(
    "out", ["", "   ", "{file}", "{file}/below", "{file}/below/deeper"], ids=str
)
def test_refuses_files_and_empty_paths(out, tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    assert status(["figures", "--out", out.format(file=f)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert "out must be a folder" in captured.err
    assert list(tmp_path.iterdir()) == [f]


@pytest.mark.parametrize(
    "out", ["/proc/depthbook-figures", "/proc/self/a/b", "/proc/self", "/dev/null/x", "/dev/full/x"]
)
def test_a_folder_that_cannot_be_made_ends_in_one_line(out, capsys):
    code = status(["figures", "--out", out])
    captured = capsys.readouterr()
    assert code in (1, 2) and captured.out == ""
    assert captured.err.count("\n") == 1 and "--out" in captured.err, captured.err
