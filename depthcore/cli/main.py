"""The command line: ``python -m depthcore {reproduce,estimate,study,atlas} ...``.

``depthcore/__main__.py`` calls :func:`main`.

Bad input ends with a one-line message on stderr in the user's words
(:mod:`depthcore.cli.refusals`) and exit status 2: a value out of range, a flag
given twice, a flag the chosen mode would ignore. A failure to write the output
ends with one line and exit status 1, as does any other failure, which asks to
rerun with ``--debug`` (which shows the traceback). Warnings are errors here.
The JSON output is strict: a number that cannot be estimated is ``null``, with
a ``<key>_reason`` beside it saying why. Long commands show a progress bar on
stderr when it is a terminal.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import traceback
import warnings

import numpy as np

from depthcore import __version__
from depthcore.cli import atlas_command, refusals, tracks
from depthcore.cli import cluster as cluster_options
from depthcore.cli import text as cli_text
from depthcore.problem import checks, frames
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, Gaussian
from depthcore.registry import track_files
from depthcore.registry.filters import FILTERS, RBPF_REPLICAS, names
from depthcore.registry.tracking import PROCESS_NOISE_MAX, RHO_RANGE, default_prior
from depthcore.studies import monte_carlo, reproduce, tasks
from depthcore.studies import trials as study_trials

#: Largest ``study --trials``: a limit on run time (trials stream in chunks).
MAX_TRIALS = 100_000

#: Most particles held in memory at once by ``study`` (a chunk's trials times the
#: particles per trial, times the Rao-Blackwellised filter's replicas): on five
#: frames about 0.2 GB in the importance sampler, 0.6 GB in the Rao-Blackwellised
#: filter, so the study stays below about 1 GB whatever ``--particles`` is.
PARTICLES_IN_FLIGHT = 1_000_000
#: Largest ``study --particles``: one trial must fit in :data:`PARTICLES_IN_FLIGHT`.
#: Time grows with trials times particles (about 1 s per 10**6 for the importance
#: sampler on five frames, 10 times that for the Rao-Blackwellised filter).
MAX_PARTICLES = PARTICLES_IN_FLIGHT // RBPF_REPLICAS
#: Smallest ``study --particles``: the weighted covariance of the three-dimensional
#: state, which the study scores, is singular with fewer.
MIN_PARTICLES = 4

#: Numeric limits of the command line (the library itself accepts more); ``RHO_RANGE``
#: and ``PROCESS_NOISE_MAX`` are those of :func:`depthcore.registry.tracking.track`.
MU_MAX = 1e6
PRIOR_MEAN_MAX = 1e3
PRIOR_COV_RANGE = (1e-12, 1e12)
#: Smallest positive ``--process-noise``: the smallest normal double, below which
#: the inverse of the noise overflows.
PROCESS_NOISE_MIN = checks.MIN_PROCESS_NOISE
#: The largest magnitude of ``estimate --focal`` and ``--cx``, in pixels.
PIXELS_MAX = 1e9
#: The range of a track file's ``step``: the depth's change between frames.
STEP_RANGE = (1e-6, 1e3)
#: Most bearings of ``estimate --mu``: the filters' limit.
FRAMES_MAX = checks.MAX_FRAMES

# A negative number in any notation (-1, -.5, -1e-1, -1E+3, -inf, -nan) is a value.
_NEGATIVE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.I)


class _Once:
    """Mixed into every option's action: refuses a second use; records in ``namespace._given``."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = namespace.__dict__.setdefault("_given", set())
        if self.dest in given:
            raise argparse.ArgumentError(self, "given more than once; give it once")
        given.add(self.dest)
        super().__call__(parser, namespace, values, option_string)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE
        self._has_negative_number_optionals = []

    def _add_action(self, action):
        if action.option_strings and not isinstance(
            action, (_Once, argparse._HelpAction, argparse._VersionAction)
        ):
            action.__class__ = type(f"Once{type(action).__name__}", (_Once, type(action)), {})
        return super()._add_action(action)

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {refusals.one_line(message)}\n")

    def _print_message(self, message, file=None):
        # argparse drops a failed write of --help or --version silently; report it
        if message and (file is None or file is sys.stdout):
            _write(message)
        else:
            super()._print_message(message, file)


def _check_rho(rho: float) -> None:
    lo, hi = RHO_RANGE
    if not (math.isfinite(rho) and lo <= rho <= hi):
        raise ValueError(f"--rho must be from {lo:g} to {hi:g}, got {refusals.exact(rho)}")


def _check_process_noise(q: float) -> float:
    """``--process-noise``: 0, or from :data:`PROCESS_NOISE_MIN` to :data:`PROCESS_NOISE_MAX`."""
    if not (math.isfinite(q) and (q == 0 or PROCESS_NOISE_MIN <= q <= PROCESS_NOISE_MAX)):
        raise ValueError(
            f"--process-noise must be 0 or from {PROCESS_NOISE_MIN:g} to "
            f"{PROCESS_NOISE_MAX:g}, got {refusals.exact(q)}"
        )
    return q


def _prior(mu, prior_mean, prior_cov, steps=None) -> Gaussian:
    """The prior from the command line, defaulting to the paper's rule (``default_prior``)."""
    if prior_mean is not None:
        refusals.check_limits("--prior-mean", prior_mean, PRIOR_MEAN_MAX)
    if prior_cov is not None:
        refusals.check_limits("--prior-cov", prior_cov, PRIOR_COV_RANGE[1])
    if prior_mean is None:
        try:
            mean = default_prior(mu, steps).mean
        except ValueError as exc:
            raise ValueError(
                f"{exc}; the paper's prior rule needs the noise-free solution of the first "
                "three bearings present, so give --prior-mean"
            ) from None
    else:
        mean = np.array(prior_mean)
    if prior_cov is None:
        cov = PAPER_PRIOR_SCALE * np.eye(3)
    elif len(prior_cov) == 1:
        if not prior_cov[0] > 0:
            raise ValueError(
                "--prior-cov must be positive definite; "
                f"S = {refusals.exact(prior_cov[0])} is not > 0"
            )
        cov = prior_cov[0] * np.eye(3)
    elif len(prior_cov) == 9:
        cov = np.array(prior_cov).reshape(3, 3)
    else:
        raise ValueError(
            f"--prior-cov takes 1 value (S I) or 9 (a 3 x 3 matrix), got {len(prior_cov)}"
        )
    prior = Gaussian.prior(mean, cov, names=("--prior-mean", "--prior-cov"))
    smallest = np.linalg.eigvalsh(prior.cov)[0]
    if smallest < PRIOR_COV_RANGE[0]:
        raise ValueError(
            f"--prior-cov must have eigenvalues of at least {PRIOR_COV_RANGE[0]:g}, "
            f"got {smallest!r}"
        )
    return prior


def _bar(total: int, desc: str, unit: str):
    """A progress bar on stderr when it is a terminal and tqdm is installed, else ``None``."""
    if not sys.stderr.isatty():
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # the extra depthcore[plot] is not installed: no bar
        return None

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr)


def _progress(bar):
    """``progress(done, total)`` moving ``bar`` (or doing nothing without one)."""

    def progress(done, total):
        if bar is not None:
            bar.total = total
            bar.update(done - bar.n)

    return progress


def _with_bar(desc: str, unit: str, run):
    """``run(progress)`` with a progress bar named ``desc`` on stderr."""
    bar = _bar(None, desc, unit)
    try:
        return run(_progress(bar))
    finally:
        if bar is not None:
            bar.close()


def _cmd_reproduce(args) -> str:
    result = _with_bar(
        "reproduce", "figure", lambda progress: reproduce.reproduce(progress=progress)
    )
    return cli_text.as_json(result) if args.json else cli_text.format_table(result)


def _cmd_estimate(args) -> str:
    src = _bearings(args)
    learned = None
    if args.learn_noise:
        if args.rho is not None:
            raise ValueError("--rho: not used with --learn-noise, which estimates it; leave it out")
        rho = 1.0 if src.rho is None else src.rho  # a rho column: the relative noise levels
    else:
        rho = _noise(args, src)
    q = _check_process_noise(args.process_noise)
    if args.json and args.csv:
        raise ValueError("--csv: print JSON (--json) or CSV (--csv), not both")
    if not args.per_frame:
        _refuse_ignored(args, "estimate without --per-frame", {"csv": "--csv"})
    gate = None if args.gate is None else tracks.check_gate(args.gate)
    steps = None if src.steps is None or np.all(src.steps == 1.0) else src.steps
    frames.check(src.mu, rho, steps)  # the bearings' refusals come before the prior's
    prior = _prior(src.mu, args.prior_mean, args.prior_cov, steps)
    if args.learn_noise:
        known_q = q if "process_noise" in getattr(args, "_given", ()) else None
        learned = track_files.learn(src.mu, rho, prior, known_q, steps)
        rho = learned.rho * np.asarray(rho) if np.ndim(rho) else learned.rho
        q = learned.process_noise
    if args.per_frame:
        return _per_frame(args, src, rho, steps, prior, q, gate, learned)
    names = tuple(dict.fromkeys(args.filters))
    if len(names) != len(args.filters):
        raise ValueError("--filters: a filter is named more than once")
    summary = reproduce.summarize(
        src.mu, rho, prior, process_noise=q, smooth=args.smooth, names=names, steps=steps, gate=gate
    )
    if learned is not None:
        summary["learned"] = track_files.learned_json(learned)
    return (
        cli_text.as_json(summary)
        if args.json
        else cli_text.format_learned(summary) + cli_text.format_summary(summary)
    )


def _bearings(args) -> track_files.TrackFile:
    """The bearings of ``--mu`` or ``--mu-file`` (``NaN`` at a missing frame)."""
    if args.mu_file is None:
        _refuse_ignored(args, "--mu (they convert a file's u column)", _PIXEL_FLAGS)
        return tracks.from_values(args.mu, MU_MAX)
    limits = track_files.Limits(MU_MAX, RHO_RANGE, STEP_RANGE, PIXELS_MAX)
    src = tracks.read_file(args.mu_file, limits, args.focal, args.cx)
    args._words = {k: f"{src.name}: {column}" for k, column in track_files.LIBRARY_NAMES.items()}
    return src


#: The options that convert a file's column ``u`` of pixels into bearings.
_PIXEL_FLAGS = {"focal": "--focal", "cx": "--cx"}


def _noise(args, src: track_files.TrackFile):
    """``--rho``, or the file's ``rho`` column: a number or an array (N,)."""
    if src.rho is None:
        if args.rho is None:
            raise ValueError(f"--rho is needed{'' if src.name == '--mu' else ': no rho column'}")
        _check_rho(args.rho)
        return args.rho
    if args.rho is not None:
        raise ValueError(f"--rho: not used: {src.name} has a rho column; leave it out")
    return src.rho


def _per_frame(args, src, rho, steps, prior, q, gate, learned=None) -> str:
    """``estimate --per-frame``: every frame's state by the filters with a smoother."""
    if args.smooth:
        raise ValueError("--smooth: not used by --per-frame (it smooths already); leave it out")
    smoothed = names(smoothed=True)
    chosen = _named_once(args.filters, "--filters") if "filters" in args._given else ("optimal",)
    without = [n for n in chosen if n not in smoothed]
    if without:
        raise ValueError(
            f"--filters: {without[0]} has no smoother; --per-frame takes {', '.join(smoothed)}"
        )
    result = track_files.per_frame(src.mu, rho, prior, q, chosen, steps, gate, src.frames)
    if learned is not None:
        result["learned"] = track_files.learned_json(learned)
    if args.json:
        return cli_text.as_json(result)
    if args.csv:
        if learned is not None:
            raise ValueError("--csv: the learned noise levels have no CSV; use --json or the table")
        return cli_text.per_frame_csv(result)
    return cli_text.format_learned(result) + cli_text.format_per_frame(result)


def _named_once(values, option: str) -> tuple:
    """``values`` as a tuple; a ``ValueError`` naming those the option ``option`` repeats."""
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise ValueError(f"{option} names {', '.join(repeated)} more than once")
    return tuple(values)


def _truth(values) -> np.ndarray:
    """``--truth``'s three numbers X Y V."""
    try:
        truth = np.array([float(v) for v in values])
    except ValueError:
        truth = None
    if truth is None or truth.shape != (3,):
        raise ValueError(
            f"--truth must be 'prior' or three numbers X Y V, got {' '.join(values)!r}"
        )
    return truth


def _refuse_ignored(args, mode: str, flags: dict) -> None:
    """Refuse the flags of ``flags`` (dest: flag) that the user gave but ``mode`` ignores."""
    given = [flag for dest, flag in flags.items() if dest in getattr(args, "_given", ())]
    if given:
        raise ValueError(
            f"{' and '.join(given)}: not used by {mode}; "
            f"leave {'them' if len(given) > 1 else 'it'} out"
        )


def _chunk(names, particles: int) -> int:
    """Trials per chunk of the study: :data:`study.CHUNK`, fewer with many particles."""
    held = particles * max(RBPF_REPLICAS if n == "rbpf" else 1 for n in names)
    return max(1, min(monte_carlo.CHUNK, PARTICLES_IN_FLIGHT // held))


def _cmd_study(args) -> str:
    if not 1 <= args.trials <= MAX_TRIALS:
        raise ValueError(
            f"--trials must be a positive integer at most {MAX_TRIALS}, got {args.trials}"
        )
    if not MIN_PARTICLES <= args.particles <= MAX_PARTICLES:
        raise ValueError(
            f"--particles must be from {MIN_PARTICLES} (a covariance of the state (x, y, v) "
            f"needs 4) to {MAX_PARTICLES} (the study holds at most {PARTICLES_IN_FLIGHT} "
            f"particles in memory, about 1 GB), got {args.particles}"
        )
    if args.seed < 0:
        raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
    _check_rho(args.rho)
    checks.frames(args.frames, "--frames")
    q = _check_process_noise(args.process_noise)
    names = _named_once(args.filters, "--filters")
    if q > 0 and "filters" not in getattr(args, "_given", ()):  # the default: those that can run
        names = tuple(n for n in names if FILTERS[n].with_process_noise)
    if args.truth == [monte_carlo.PRIOR_TRUTH]:
        _refuse_ignored(
            args,
            "--truth prior (it checks the optimal filter alone, in this process)",
            {k: f"--{k}" for k in ("filters", "particles", "workers", "scheduler")},
        )
        if args.prior not in (None, "fixed"):
            raise ValueError(
                "--prior: --truth prior needs a fixed prior (the paper's rule is no prior; the "
                f"other forms draw truths about --truth X Y V), got {args.prior}"
            )
        result = _with_bar(
            "study",
            "trial",
            lambda progress: monte_carlo.prior_study(
                rho=args.rho,
                trials=args.trials,
                seed=args.seed,
                frames=args.frames,
                process_noise=q,
                progress=progress,
            ),
        )
        return cli_text.as_json(result) if args.json else cli_text.format_prior_study(result)
    if not any(FILTERS[n].random for n in names):
        _refuse_ignored(
            args,
            f"the filters {' '.join(names)}, which draw no particles",
            {"particles": "--particles"},
        )
    truth = None
    if args.truth is not None:
        truth = _truth(args.truth)
        refusals.check_limits("--truth", truth, MU_MAX)
    if args.workers is not None and args.scheduler is not None:
        raise ValueError("--workers and --scheduler: give one (a local cluster, or a running one)")
    workers = None if args.workers is None else cluster_options.workers(args.workers)
    options = dict(
        truth=truth, rho=args.rho, trials=args.trials, seed=args.seed, prior=args.prior or "paper"
    )
    options.update(names=names, n_particles=args.particles, chunk=_chunk(names, args.particles))
    options.update(frames=args.frames, process_noise=q)
    with tasks.cluster(workers, args.scheduler) as client:
        result = _with_bar(
            "study", "trial", lambda p: monte_carlo.study(**options, progress=p, client=client)
        )
    return cli_text.as_json(result) if args.json else cli_text.format_study(result)


class _WriteError(Exception):
    """The output could not be written: one line, exit status 1."""


def _write(text: str) -> None:
    """Write ``text`` to standard output, raising :class:`_WriteError` if it cannot."""
    stream = sys.stdout
    if stream is None:
        raise _WriteError("cannot write the output: standard output is closed")
    try:
        stream.write(text)
        stream.flush()
    except (OSError, ValueError) as exc:
        # nothing more may reach the broken stream, not even at exit
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, stream.fileno())
        except (OSError, ValueError):
            pass
        reason = getattr(exc, "strerror", None) or str(exc)
        raise _WriteError(f"cannot write the output to standard output: {reason}") from None


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m depthcore``, with the registry's filters when built."""
    p = _Parser(
        prog="python -m depthcore",
        description="Filter based estimates of depth (Maybank 1990): the paper's filters "
        f"on N >= 3 bearings (up to {FRAMES_MAX} frames).",
        epilog=cli_text.EXAMPLES["all"],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"depthcore {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--debug", action="store_true", help="show the traceback of an unexpected failure"
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = _command(
        sub, common, "reproduce", "moments of every filter for Figures 2-6, beside the paper's"
    )
    _add_json(r, _cmd_reproduce)
    _add_estimate_arguments(sub, common)
    _add_study_arguments(sub, common)
    atlas_command.add(_command(sub, common, "atlas", atlas_command.SUMMARY), _with_bar, _WriteError)
    return p


def _command(sub, common, name: str, summary: str) -> argparse.ArgumentParser:
    """The parser of command ``name``: ``summary`` its help and, as a sentence, its description.

    ``name`` is a key of ``cli_text.EXAMPLES`` (the epilog); ``summary`` one
    line, lower case, without a full stop.
    """
    return sub.add_parser(
        name,
        parents=[common],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=cli_text.EXAMPLES[name],
        help=summary,
        description=f"{summary[0].upper()}{summary[1:]}.",
    )


def _add_json(parser: argparse.ArgumentParser, run) -> None:
    """The last option of a command that prints a table, ``--json``, and what the command runs."""
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.set_defaults(run=run)


def _add_filters(parser: argparse.ArgumentParser, what: str, note: str = "") -> None:
    """``--filters`` (the registry's defaults): ``what`` begins the help, ``note`` ends it."""
    every, defaults = names(), names(default=True)
    parser.add_argument(
        "--filters",
        nargs="+",
        default=list(defaults),
        choices=every,
        metavar="NAME",
        help=f"{what} (default: {' '.join(defaults)}; also "
        f"{' '.join(n for n in every if n not in defaults)}){note}",
    )


def _add_process_noise(parser: argparse.ArgumentParser, default: str, note: str = "") -> None:
    """``--process-noise``, 0 by default: ``default`` says what 0 means, ``note`` ends its help."""
    parser.add_argument(
        "--process-noise",
        type=float,
        default=0.0,
        metavar="Q",
        help=f"SD of the velocity's change per frame (default 0{default}){note}",
    )


def _add_estimate_arguments(sub, common) -> None:
    """The command ``estimate`` and its options."""
    e = _command(
        sub,
        common,
        "estimate",
        f"moments of every filter for any N >= 3 bearings (up to {FRAMES_MAX} frames)",
    )
    given = e.add_mutually_exclusive_group(required=True)
    given.add_argument(
        "--mu",
        type=float,
        nargs="+",
        metavar="M",
        help="the measurements mu1 mu2 mu3 ... (tangents of the bearings at frames 1 .. N, "
        f"3 <= N <= {FRAMES_MAX}; magnitudes up to {MU_MAX:g}; nan: a missing frame, "
        "with --per-frame)",
    )
    given.add_argument(
        "--mu-file",
        metavar="FILE",
        help="read the bearings from a CSV file instead (- for standard input; its format below)",
    )
    e.add_argument(
        "--focal",
        type=float,
        metavar="F",
        help="the focal length in pixels, for a file's column u of pixels",
    )
    e.add_argument(
        "--cx",
        type=float,
        metavar="C",
        help="the principal point's column in pixels, for a file's column u",
    )
    e.add_argument(
        "--rho",
        type=float,
        help=f"noise standard deviation, from {RHO_RANGE[0]:g} to {RHO_RANGE[1]:g} (needed "
        "unless the file has a rho column)",
    )
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
    _add_process_noise(e, ": the paper's constant velocity")
    e.add_argument(
        "--smooth",
        action="store_true",
        help="also the optimal filter's smoothed depth and lateral position at every frame",
    )
    _add_filters(
        e,
        "filters to run, in this order",
        f"; with --per-frame those with a smoother, of {' '.join(names(smoothed=True))} "
        "(default: optimal)",
    )
    e.add_argument(
        "--per-frame",
        action="store_true",
        help="the filtered and smoothed depth, lateral position and velocity with their SDs at "
        "every frame (a track with missing frames, noise per frame or uneven steps needs it)",
    )
    e.add_argument(
        "--learn-noise",
        action="store_true",
        help="estimate rho and the process noise from the track by maximum likelihood (with "
        "--process-noise given: rho only; a rho column gives the frames' relative noise "
        "levels), with standard errors, and run the filters with them",
    )
    e.add_argument(
        "--gate",
        type=float,
        metavar="P",
        help="skip a bearing whose predictive tail probability is below P (a probability)",
    )
    e.add_argument(
        "--csv", action="store_true", help="with --per-frame: print CSV instead of a table"
    )
    _add_json(e, _cmd_estimate)


def _add_study_arguments(sub, common) -> None:
    """The command ``study`` and its options."""
    st = _command(sub, common, "study", "Monte Carlo study of every filter's error and calibration")
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
        choices=study_trials.PRIORS,
        help="paper (default): the paper's rule on each trial's measurements; fixed: on the "
        "truth (the only choice with --truth prior); range, log_uniform, inverse_depth: each "
        "trial's truth drawn from a prior of that form centred on the truth, the filters given "
        "its Gaussian",
    )
    _add_filters(
        st,
        "filters to score",
        "; only these run: the Hellinger distances need the optimal filter, their reference, "
        "so without 'optimal' they are not computed (- in the table, null in JSON)",
    )
    st.add_argument(
        "--particles",
        type=int,
        default=study_trials.PARTICLES,
        help=f"particles per trial of the filters that draw them, {MIN_PARTICLES} to "
        f"{MAX_PARTICLES} "
        f"(default {study_trials.PARTICLES})",
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
    _add_process_noise(
        st,
        "",
        "; with Q > 0 the filters that assume a constant velocity (particle) cannot be named",
    )
    cluster_options.add_arguments(st, "trials", "the same result, bit for bit")
    _add_json(st, _cmd_study)


def _parse(argv) -> argparse.Namespace:
    """The parsed arguments; ``--help``, ``--version`` and refusals raise SystemExit."""
    return build_parser().parse_args(argv)


def main(argv=None) -> int:
    """Run the command line; returns the exit status (0, 1 or 2)."""
    try:
        args = _parse(argv)
    except _WriteError as exc:
        sys.stderr.write(f"python -m depthcore: error: {exc}\n")
        return 1
    prog = f"python -m depthcore {args.command}"
    try:
        # Warnings become errors here only: the filters are restored on return.
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            text = args.run(args)
        _write(text)
    except np.linalg.LinAlgError:
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"{prog}: error: {refusals.SINGULAR[args.command]}\n")
        return 2
    except track_files.FileRefusal as exc:
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"{prog}: error: {refusals.one_line(exc)}\n")
        return 2
    except ValueError as exc:
        if args.debug:
            traceback.print_exc()
        words = getattr(args, "_words", None)
        sys.stderr.write(f"{prog}: error: {refusals.users_words(args.command, str(exc), words)}\n")
        return 2
    except _WriteError as exc:
        sys.stderr.write(f"{prog}: error: {exc}\n")
        return 1
    except KeyboardInterrupt:
        sys.stderr.write(f"{prog}: interrupted\n")
        return 130
    except Exception as exc:  # noqa: BLE001 - every failure is one line
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(
            f"{prog}: error: unexpected {type(exc).__name__}: {refusals.one_line(exc)[:200]}"
            " (rerun with --debug to see the traceback)\n"
        )
        return 1
    return 0
