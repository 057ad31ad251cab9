"""The command line: ``python -m depthcore {reproduce,estimate,study,figures} ...``.

Bad input ends with a one-line message on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from . import __version__, report, reproduce
from .filters import NAMES as _STUDY_FILTERS
from .gaussian import PAPER_PRIOR_SCALE, Gaussian, paper_prior
from .model import noise_free_state


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _prior(mu, prior_mean, prior_cov) -> Gaussian:
    """The prior from the command line, defaulting to the paper's rule."""
    c = noise_free_state(mu)
    default = paper_prior(c)
    mean = default.mean if prior_mean is None else np.array(prior_mean)
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
        return Gaussian(mean, cov)
    except ValueError as exc:
        raise ValueError(
            str(exc).replace("cov ", "prior_cov ", 1).replace("mean ", "prior_mean ", 1)
        ) from None


def _cmd_reproduce(args) -> str:
    result = reproduce.reproduce()
    return json.dumps(result, indent=2) if args.json else report.format_table(result)


def _cmd_estimate(args) -> str:
    mu = np.array(args.mu)
    summary = reproduce.summarize(mu, args.rho, _prior(mu, args.prior_mean, args.prior_cov))
    return json.dumps(summary, indent=2) if args.json else report.format_summary(summary)


def _cmd_figures(args) -> str:
    import matplotlib

    matplotlib.use("Agg")
    from . import figures

    paths = figures.save_all(args.out)
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
    from . import study

    progress = None
    if sys.stderr.isatty():

        def progress(done, total):
            sys.stderr.write(f"\rstudy: {done}/{total} trials" + ("\n" if done == total else ""))
            sys.stderr.flush()

    if args.truth == [study.PRIOR_TRUTH]:
        if args.prior == "paper":
            raise ValueError(
                "prior: --truth prior needs a fixed prior (the paper's rule centres the prior "
                "on each trial's own measurements, which is not a prior), got paper"
            )
        result = study.prior_study(rho=args.rho, trials=args.trials, seed=args.seed)
        return json.dumps(result, indent=2) if args.json else report.format_prior_study(result)
    truth = None if args.truth is None else _truth(args.truth)
    if args.particles < 1:
        raise ValueError(f"particles must be a positive integer, got {args.particles}")
    result = study.study(
        truth=truth,
        rho=args.rho,
        trials=args.trials,
        seed=args.seed,
        prior=args.prior or "paper",
        names=tuple(args.filters),
        n_particles=args.particles,
        progress=progress,
    )
    return json.dumps(result, indent=2) if args.json else report.format_study(result)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m depthcore``."""
    p = _Parser(prog="python -m depthcore", description=__doc__.splitlines()[0])
    p.add_argument("--version", action="version", version=f"depthcore {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser(
        "reproduce", help="moments of every filter for Figures 2-6, beside the paper's"
    )
    r.add_argument("--json", action="store_true", help="print JSON instead of a table")
    r.set_defaults(run=_cmd_reproduce)

    e = sub.add_parser("estimate", help="moments of every filter for any three measurements")
    e.add_argument(
        "--mu",
        type=float,
        nargs=3,
        required=True,
        metavar=("M1", "M2", "M3"),
        help="the measurements mu1 mu2 mu3 (tangents of the bearings)",
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
    e.add_argument("--json", action="store_true", help="print JSON instead of a table")
    e.set_defaults(run=_cmd_estimate)

    st = sub.add_parser("study", help="Monte Carlo study of every filter's error and calibration")
    st.add_argument("--trials", type=int, default=500, help="number of noise draws (default 500)")
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
        choices=_STUDY_FILTERS,
        metavar="NAME",
        help=f"filters to score (default all: {' '.join(_STUDY_FILTERS)})",
    )
    st.add_argument(
        "--particles", type=int, default=2000, help="particles per trial (default 2000)"
    )
    st.add_argument("--json", action="store_true", help="print JSON instead of a table")
    st.set_defaults(run=_cmd_study)

    f = sub.add_parser("figures", help="write Figures 2-6 as PDF, PNG and SVG")
    f.add_argument("--out", default="figures", help="output folder (default: figures)")
    f.set_defaults(run=_cmd_figures)
    return p


def main(argv=None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        text = args.run(args)
    except ValueError as exc:
        sys.stderr.write(f"python -m depthcore {args.command}: error: {exc}\n")
        return 2
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
