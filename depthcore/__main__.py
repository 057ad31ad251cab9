"""The command line: ``python -m depthcore {reproduce,estimate,study,figures} ...``.

Bad input ends with a one-line message on stderr naming the argument and exit
status 2. Any other failure (out of memory, an overflow, a bug) ends with a
one-line message asking to rerun with ``--debug`` (which shows the traceback)
and exit status 1. Warnings never reach stderr: inside the command line they
are errors, reported like any other failure.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import traceback
import warnings
from pathlib import Path

import numpy as np

from . import __version__, _checks, report, reproduce, study
from .filters import ALL_NAMES
from .filters import NAMES as _STUDY_FILTERS
from .gaussian import PAPER_PRIOR_SCALE, Gaussian, paper_prior
from .model import noise_free_state
from .report import STUDY_LEGEND

#: Largest ``study --trials``: a limit on run time (the study streams its trials in
#: chunks, so its memory does not grow with their number).
MAX_TRIALS = 100_000

#: Numeric limits of the command line (the library itself accepts more).
RHO_RANGE = (1e-12, 1e3)
MU_MAX = 1e6
PRIOR_MEAN_MAX = 1e3
PRIOR_COV_RANGE = (1e-12, 1e12)
PROCESS_NOISE_MAX = 10.0
#: Most bearings of ``estimate --mu``: the filters' limit.
FRAMES_MAX = _checks.MAX_FRAMES

# A negative number in any notation (-1, -.5, -1e-1, -1E+3, -inf, -nan) is a
# value, not an option.
_NEGATIVE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.I)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE
        self._has_negative_number_optionals = []

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _check_limits(name: str, values, largest: float) -> None:
    """Refuse a value that is not finite or whose magnitude exceeds ``largest``."""
    v = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v.tolist()}")
    big = np.isfinite(v) & (np.abs(v) > largest)
    if np.any(big):
        raise ValueError(f"{name} must be at most {largest:g} in magnitude, got {v[big][0]:g}")


def _check_rho(rho: float) -> None:
    lo, hi = RHO_RANGE
    if np.isfinite(rho) and rho > 0 and not lo <= rho <= hi:
        raise ValueError(f"rho must be from {lo:g} to {hi:g}, got {rho:g}")


def _prior(mu, prior_mean, prior_cov) -> Gaussian:
    """The prior from the command line, defaulting to the paper's rule."""
    if prior_mean is not None:
        _check_limits("prior_mean", prior_mean, PRIOR_MEAN_MAX)
    if prior_cov is not None:
        _check_limits("prior_cov", prior_cov, PRIOR_COV_RANGE[1])
    if prior_mean is None:
        try:
            c = noise_free_state(mu[:3])
        except ValueError as exc:
            raise ValueError(
                f"{exc}; the paper's prior rule needs the noise-free solution of the first "
                "three bearings, so give --prior-mean"
            ) from None
        mean = paper_prior(c).mean
    else:
        mean = np.array(prior_mean)
    if prior_cov is None:
        cov = PAPER_PRIOR_SCALE * np.eye(3)
    elif len(prior_cov) == 1:
        if not prior_cov[0] > 0:
            raise ValueError(f"prior_cov must be positive definite; S = {prior_cov[0]} is not > 0")
        cov = prior_cov[0] * np.eye(3)
    elif len(prior_cov) == 9:
        cov = np.array(prior_cov).reshape(3, 3)
    else:
        raise ValueError(
            f"prior_cov takes 1 value (S I) or 9 (a 3 x 3 matrix), got {len(prior_cov)}"
        )
    try:
        prior = Gaussian(mean, cov)
    except ValueError as exc:
        raise ValueError(
            str(exc).replace("cov ", "prior_cov ", 1).replace("mean ", "prior_mean ", 1)
        ) from None
    smallest = np.linalg.eigvalsh(prior.cov)[0]
    if smallest < PRIOR_COV_RANGE[0]:
        raise ValueError(
            f"prior_cov must have eigenvalues of at least {PRIOR_COV_RANGE[0]:g}, got {smallest:g}"
        )
    return prior


def _cmd_reproduce(args) -> str:
    result = reproduce.reproduce()
    return json.dumps(result, indent=2) if args.json else report.format_table(result)


def _cmd_estimate(args) -> str:
    mu = np.array(args.mu)
    if len(mu) < 3:
        raise ValueError(f"mu takes at least 3 bearings (frames 1 .. N), got {len(mu)}")
    if len(mu) > FRAMES_MAX:
        raise ValueError(f"mu takes at most {FRAMES_MAX} bearings, got {len(mu)}")
    _check_limits("mu", mu, MU_MAX)
    _check_rho(args.rho)
    q = args.process_noise
    if not (np.isfinite(q) and 0 <= q <= PROCESS_NOISE_MAX):
        raise ValueError(f"process_noise must be from 0 to {PROCESS_NOISE_MAX:g}, got {q:g}")
    prior = _prior(mu, args.prior_mean, args.prior_cov)
    try:
        summary = reproduce.summarize(mu, args.rho, prior, process_noise=q, smooth=args.smooth)
    except ValueError as exc:
        if str(exc).startswith(("mu ", "rho ", "prior_mean ", "prior_cov ")):
            raise
        raise ValueError(f"mu, rho and the prior have no answer: {exc}") from None
    return json.dumps(summary, indent=2) if args.json else report.format_summary(summary)


def _check_out(out: str) -> Path:
    """The folder of ``figures --out``: refuses an empty path, a file, a path below a file."""
    if not out.strip():
        raise ValueError("out must be a folder, got an empty path")
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise ValueError(f"out must be a folder, but {out!r} is an existing file")
    for parent in path.parents:
        if parent.exists() and not parent.is_dir():
            raise ValueError(f"out must be a folder, but {str(parent)!r} in {out!r} is a file")
    return path


def _cmd_figures(args) -> str:
    out = _check_out(args.out)
    import matplotlib

    matplotlib.use("Agg")
    from . import figures

    paths = figures.save_all(out)
    return "\n".join(str(p) for p in paths) + "\n"


def _truth(values) -> np.ndarray:
    """``--truth``'s three numbers X Y V."""
    try:
        truth = np.array([float(v) for v in values])
    except ValueError:
        truth = None
    if truth is None or truth.shape != (3,):
        raise ValueError(f"truth must be 'prior' or three numbers X Y V, got {' '.join(values)}")
    return truth


def _cmd_study(args) -> str:
    if not 1 <= args.trials <= MAX_TRIALS:
        raise ValueError(
            f"trials must be a positive integer at most {MAX_TRIALS}, got {args.trials}"
        )
    if args.particles < 1:
        raise ValueError(f"particles must be a positive integer, got {args.particles}")
    if args.seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {args.seed}")
    _check_rho(args.rho)
    if not 3 <= args.frames <= FRAMES_MAX:
        raise ValueError(f"frames must be from 3 to {FRAMES_MAX}, got {args.frames}")
    q = args.process_noise
    if not (np.isfinite(q) and 0 <= q <= PROCESS_NOISE_MAX):
        raise ValueError(f"process_noise must be from 0 to {PROCESS_NOISE_MAX:g}, got {q:g}")
    names = tuple(args.filters)
    if q > 0 and args.filters == list(_STUDY_FILTERS):  # the default: those that can run
        names = tuple(n for n in names if study.FILTERS[n].with_process_noise)
    if args.truth == [study.PRIOR_TRUTH]:
        if args.prior == "paper":
            raise ValueError(
                "prior: --truth prior needs a fixed prior (the paper's rule centres the prior "
                "on each trial's own measurements, which is not a prior), got paper"
            )
        result = study.prior_study(
            rho=args.rho,
            trials=args.trials,
            seed=args.seed,
            frames=args.frames,
            process_noise=q,
        )
        return json.dumps(result, indent=2) if args.json else report.format_prior_study(result)
    truth = None
    if args.truth is not None:
        truth = _truth(args.truth)
        _check_limits("truth", truth, MU_MAX)
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=args.trials, desc="study", unit="trial", file=sys.stderr)

    def progress(done, total):
        if bar is not None:
            bar.total = total
            bar.update(done - bar.n)

    try:
        result = study.study(
            truth=truth,
            rho=args.rho,
            trials=args.trials,
            seed=args.seed,
            prior=args.prior or "paper",
            names=names,
            n_particles=args.particles,
            progress=progress,
            frames=args.frames,
            process_noise=q,
        )
    finally:
        if bar is not None:
            bar.close()
    return json.dumps(result, indent=2) if args.json else report.format_study(result)


EXAMPLES = {
    "reproduce": """\
examples:
  python -m depthcore reproduce          the table of Figures 2-6 beside the paper
  python -m depthcore reproduce --json   the same as JSON""",
    "estimate": """\
examples:
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005
  python -m depthcore estimate --mu -1e-1 0 0.2 --rho 0.01 --prior-cov 100
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005 --prior-mean -1 4 0 --json
  python -m depthcore estimate --mu -0.3 0 0.2 0.33 0.43 --rho 0.005 --process-noise 0.01 --smooth

The noise-free state c is (x, y, v) at frame 3 (from the first three bearings);
the prior is at frame 1; every filter reports the state at the last frame N.""",
    "study": f"""\
examples:
  python -m depthcore study --trials 500 --seed 1
  python -m depthcore study --filters ekf ukf --rho 0.01 --json
  python -m depthcore study --frames 10 --process-noise 0.01 --trials 200

{STUDY_LEGEND}""",
    "figures": """\
examples:
  python -m depthcore figures --out figures""",
}
EXAMPLES["all"] = """\
examples:
  python -m depthcore reproduce
  python -m depthcore estimate --mu -0.3 0 0.2 --rho 0.005
  python -m depthcore study --trials 500 --seed 1
  python -m depthcore figures --out figures

`python -m depthcore COMMAND --help` shows each command's options and examples."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m depthcore``."""
    raw = argparse.RawDescriptionHelpFormatter
    p = _Parser(
        prog="python -m depthcore",
        description="Filter based estimates of depth (Maybank 1990): the paper's filters "
        "on any three bearings.",
        epilog=EXAMPLES["all"],
        formatter_class=raw,
    )
    p.add_argument("--version", action="version", version=f"depthcore {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--debug", action="store_true", help="show the traceback of an unexpected failure"
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser(
        "reproduce",
        parents=[common],
        formatter_class=raw,
        epilog=EXAMPLES["reproduce"],
        help="moments of every filter for Figures 2-6, beside the paper's",
    )
    r.add_argument("--json", action="store_true", help="print JSON instead of a table")
    r.set_defaults(run=_cmd_reproduce)

    e = sub.add_parser(
        "estimate",
        parents=[common],
        formatter_class=raw,
        epilog=EXAMPLES["estimate"],
        help="moments of every filter for any three measurements",
    )
    e.add_argument(
        "--mu",
        type=float,
        nargs="+",
        required=True,
        metavar="M",
        help="the measurements mu1 mu2 mu3 ... (tangents of the bearings at frames 1 .. N, N >= 3)",
    )
    e.add_argument("--rho", type=float, required=True, help="noise standard deviation, > 0")
    e.add_argument(
        "--prior-mean",
        type=float,
        nargs=3,
        metavar=("X", "Y", "V"),
        help="prior mean at time 1 (default: the paper's (c1 - 2 c3, c2 - 2, 0))",
    )
    e.add_argument(
        "--prior-cov",
        type=float,
        nargs="+",
        metavar="S",
        help="prior covariance: S for S I (default 1000), or 9 values row by row",
    )
    e.add_argument(
        "--process-noise",
        type=float,
        default=0.0,
        metavar="Q",
        help="SD of the velocity's change per frame (default 0: the paper's constant velocity)",
    )
    e.add_argument(
        "--smooth",
        action="store_true",
        help="also the optimal filter's smoothed depth and lateral position at every frame",
    )
    e.add_argument("--json", action="store_true", help="print JSON instead of a table")
    e.set_defaults(run=_cmd_estimate)

    st = sub.add_parser(
        "study",
        parents=[common],
        formatter_class=raw,
        epilog=EXAMPLES["study"],
        help="Monte Carlo study of every filter's error and calibration",
    )
    st.add_argument(
        "--trials",
        type=int,
        default=500,
        help=f"number of noise draws, 1 to {MAX_TRIALS} (default 500)",
    )
    st.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    st.add_argument(
        "--rho", type=float, default=1 / 200, help="noise standard deviation (default 1/200)"
    )
    st.add_argument(
        "--truth",
        nargs="+",
        metavar="X Y V | prior",
        help="true state at time 3 (default: Figure 2's c = (1.2, 6, 1.2)); 'prior': truths "
        "drawn from the fixed prior, N((-1.2, 4, 0), 1000 I) at time 1, to check the optimal "
        "filter's calibration",
    )
    st.add_argument(
        "--prior",
        choices=("paper", "fixed"),
        help="paper (default): the paper's rule on each trial's measurements; fixed: on the "
        "truth (the only choice with --truth prior)",
    )
    st.add_argument(
        "--filters",
        nargs="+",
        default=list(_STUDY_FILTERS),
        choices=ALL_NAMES,
        metavar="NAME",
        help=f"filters to score (default: {' '.join(_STUDY_FILTERS)}; also "
        f"{' '.join(n for n in ALL_NAMES if n not in _STUDY_FILTERS)}); only these run: "
        "the Hellinger distances need the optimal filter, their reference, so without "
        "'optimal' they are not computed (- in the table, null in JSON)",
    )
    st.add_argument(
        "--particles",
        type=int,
        default=study.PARTICLES,
        help=f"particles per trial (default {study.PARTICLES})",
    )
    st.add_argument(
        "--frames",
        type=int,
        default=3,
        metavar="N",
        help="frames per trial, 3 (default, the paper's) to "
        f"{FRAMES_MAX}: the truth moves on from time 3 to frame N and every filter is scored "
        "there",
    )
    st.add_argument(
        "--process-noise",
        type=float,
        default=0.0,
        metavar="Q",
        help="SD of the velocity's change per frame (default 0); with Q > 0 the filters that "
        "assume a constant velocity (particle) cannot be named",
    )
    st.add_argument("--json", action="store_true", help="print JSON instead of a table")
    st.set_defaults(run=_cmd_study)

    f = sub.add_parser(
        "figures",
        parents=[common],
        formatter_class=raw,
        epilog=EXAMPLES["figures"],
        help="write Figures 2-6 as PDF, PNG and SVG",
    )
    f.add_argument("--out", default="figures", help="output folder (default: figures)")
    f.set_defaults(run=_cmd_figures)
    return p


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv=None) -> int:
    """Run the command line; returns the exit status (0, 1 or 2)."""
    args = build_parser().parse_args(argv)
    prog = f"python -m depthcore {args.command}"
    try:
        # Warnings become errors here only: the warning filters are restored on
        # return, so library users are not affected.
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            text = args.run(args)
    except ValueError as exc:
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"{prog}: error: {_one_line(exc)}\n")
        return 2
    except Exception as exc:  # noqa: BLE001 - every failure is one line
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(
            f"{prog}: error: unexpected {type(exc).__name__}: {_one_line(exc)[:200]}"
            " (rerun with --debug to see the traceback)\n"
        )
        return 1
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
