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
import sys
import traceback
import warnings

import numpy as np

from depthcore import __version__
from depthcore.cli import atlas_command, parsing, priors, refusals, tracks
from depthcore.cli import cluster as cluster_options
from depthcore.cli import text as cli_text
from depthcore.problem import bearing_pairs, checks, frames
from depthcore.registry import online, track_files, track_runs
from depthcore.registry.filters import FILTERS, RBPF_REPLICAS, names
from depthcore.registry.tracking import PROCESS_NOISE_MAX, RHO_RANGE, track
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


def _cmd_reproduce(args) -> str:
    result = parsing.with_bar(
        "reproduce", "figure", lambda progress: reproduce.reproduce(progress=progress)
    )
    return cli_text.as_json(result) if args.json else cli_text.format_table(result)


def _cmd_estimate(args):
    held = _bearings(args)
    try:
        return _estimate(args, held)
    finally:  # a long track's file, read or not
        if held.reading is not None:
            held.reading.frames.close()


def _estimate(args, held):
    src = held.track or track_files.assemble(held.reading, held.first)  # a long track's start
    pairs = src.mu.ndim == 2
    if held.track is None:
        _refuse_long(args, held)
    if args.learn_noise:
        if args.rho is not None:
            raise ValueError("--rho: not used with --learn-noise, which estimates it; leave it out")
        if pairs:
            raise ValueError(
                "--learn-noise learns from the plane's bearings (mu or u) only; this track has "
                "pairs (a point in 3-D)"
            )
        rho = 1.0 if src.rho is None else src.rho  # a rho column: the relative noise levels
    else:
        rho = _noise(args, src)
    q = _check_process_noise(args.process_noise)
    if args.json and args.csv:
        raise ValueError("--csv: print JSON (--json) or CSV (--csv), not both")
    if not args.per_frame:
        parsing.refuse_ignored(args, "estimate without --per-frame", {"csv": "--csv"})
    gate = None if args.gate is None else tracks.check_gate(args.gate)
    steps = None if src.steps is None or np.all(src.steps == 1.0) else src.steps
    if held.track is not None:  # the bearings' refusals come before the prior's
        (bearing_pairs.check if pairs else frames.check)(src.mu, rho, steps)
    prior = priors.prior(src.mu, steps, args, PRIOR_MEAN_MAX, PRIOR_COV_RANGE)
    direction = {"direction": src.direction, "direction_given": args.direction is not None}
    stream_rho = None if src.rho is not None else rho
    if pairs:
        _refuse_for_pairs(args, gate)
    if held.track is None:
        return _streamed(args, held.reading.frames, stream_rho, prior, q, gate, direction)
    if pairs and args.per_frame:
        frames_in = track_runs.frames_of(src)
        return _streamed(args, frames_in, stream_rho, prior, q, gate, direction, "pairs")
    if pairs:
        return _pairs(args, src, rho, steps, prior, q, direction)
    learned = None
    if args.learn_noise:
        known_q = q if "process_noise" in getattr(args, "_given", ()) else None
        learned = track_runs.learn(src.mu, rho, prior, known_q, steps, gate)
        if not learned.converged:
            raise ValueError(
                f"--learn-noise: the likelihood of these {np.size(src.mu)} bearings has no "
                f"maximum the fit could reach (it stopped at rho = {learned.rho:.3g}, "
                f"q = {learned.process_noise:.3g}); give --rho, or --process-noise, or more frames"
            )
        rho = learned.rho * np.asarray(rho) if np.ndim(rho) else learned.rho
        q = learned.process_noise
        learned = track_runs.learned_json(learned, src.rho is not None, src.frames, src.times)
    if args.per_frame:
        return _per_frame(args, src, rho, steps, prior, q, gate, learned, direction)
    names = tuple(dict.fromkeys(args.filters))
    if len(names) != len(args.filters):
        raise ValueError("--filters: a filter is named more than once")
    summary = reproduce.summarize(
        src.mu, rho, prior, process_noise=q, smooth=args.smooth, names=names, steps=steps, gate=gate
    )
    summary |= _named_frames(summary, src) | direction
    if learned is not None:
        summary["learned"] = learned
    return _summary_text(args, summary, src, steps)


def _summary_text(args, summary: dict, src, steps) -> str:
    """The summary as JSON or a table, saying why ``c`` is undefined where it is."""
    if summary["c"] is None:
        summary["c_reason"] = track_runs.noise_free(src.mu, steps)[1]
    return (
        cli_text.as_json(summary)
        if args.json
        else cli_text.format_learned(summary) + cli_text.format_summary(summary)
    )


def _named_frames(summary: dict, src: track_files.TrackFile) -> dict:
    """The summary's frames named by the track's numbers and times, never by their order."""
    label = tracks.labeller(src)
    out = {"frame_numbers": src.frames.tolist()}
    if src.times is not None:
        out["times"] = src.times.tolist()
    for f in summary["filters"].values():
        if "gated" in f:
            k = np.array(f["gated"], dtype=int) - 1
            f["gated"] = src.frames[k].tolist()
            if src.times is not None:
                f["gated_times"] = src.times[k].tolist()
    for name, reason in summary.get("not_run", {}).items():
        summary["not_run"][name] = track_runs.relabel(reason, label)
    if "smoothed" in summary:
        summary["smoothed"] = {"frame": out["frame_numbers"], **out, **summary["smoothed"]}
        del summary["smoothed"]["frame_numbers"]
    return out


def _bearings(args) -> track_files.Held:
    """The bearings of ``--mu`` or ``--mu-file`` (``NaN`` at a missing frame)."""
    args._words = {"prior": "--prior-mean"}  # the paper's rule: give the prior's mean instead
    if args.mu_file is None:
        parsing.refuse_ignored(args, "--mu (they convert a file's u and v columns)", _PIXEL_FLAGS)
        parsing.refuse_ignored(
            args, "--mu (it converts a file's time column)", {"speed": "--speed"}
        )
        track = tracks.from_values(args.mu, MU_MAX, args.steps, args.direction, STEP_RANGE, args.nu)
        return track_files.Held(track, None, None)
    parsing.refuse_ignored(
        args, "--mu-file (its step, travel or time column)", {"steps": "--steps"}
    )
    parsing.refuse_ignored(args, "--mu-file (its nu or v column)", {"nu": "--nu"})
    limits = track_files.Limits(MU_MAX, RHO_RANGE, STEP_RANGE, PIXELS_MAX)
    options = {k: getattr(args, k) for k in ("focal", "cx", "cy", "direction", "speed")}
    held = tracks.read_file(args.mu_file, limits, options)
    name = held.reading.name
    args._words |= {k: f"{name}: {column}" for k, column in track_files.LIBRARY_NAMES.items()}
    if held.track is not None:
        args._label = tracks.labeller(held.track)
    return held


#: The options that convert a file's column ``u`` of pixels into bearings.
_PIXEL_FLAGS = {"focal": "--focal", "cx": "--cx", "cy": "--cy"}


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


def _chosen(args) -> tuple:
    """``--filters`` of ``--per-frame``: those with a smoother (default: the optimal filter)."""
    if args.smooth:
        raise ValueError("--smooth: not used by --per-frame (it smooths already); leave it out")
    smoothed = names(smoothed=True)
    chosen = (
        parsing.named_once(args.filters, "--filters") if "filters" in args._given else ("optimal",)
    )
    without = [n for n in chosen if n not in smoothed]
    if without:
        raise ValueError(
            f"--filters: {without[0]} has no smoother; --per-frame takes {', '.join(smoothed)}"
        )
    return chosen


def _per_frame(args, src, rho, steps, prior, q, gate, learned, direction):
    """``estimate --per-frame``: every frame's state by the filters with a smoother."""
    chosen = _chosen(args)
    result = track_runs.per_frame(src.mu, rho, prior, q, chosen, steps, gate, src.frames, src.times)
    blocks = result.pop("filters")
    if learned is not None:
        if args.csv:
            raise ValueError("--csv: the learned noise levels have no CSV; use --json or the table")
        result["learned"] = learned
    return cli_text.per_frame_text(result | direction, blocks, _output(args))


def _refuse_for_pairs(args, gate) -> None:
    """Refuse what a track of pairs cannot have: a smoother frame by frame, a gate in the
    summary."""
    if args.smooth and args.per_frame:
        raise ValueError(
            "--smooth: --per-frame streams pairs (a point in 3-D) through the online filters, "
            "which do not smooth; leave it out"
        )
    if gate is not None and not args.per_frame:
        raise ValueError(
            "--gate: the summary of pairs (a point in 3-D) has no gate; --per-frame gates "
            "each frame's pair"
        )


def _pairs(args, src, rho, steps, prior, q, direction):
    """``estimate`` of a track of pairs, a point in 3-D: the filters that take them."""
    spatial = track_runs.spatial_names()
    names = parsing.named_once(args.filters, "--filters") if "filters" in args._given else spatial
    without = [n for n in names if n not in spatial]
    if without:
        raise ValueError(
            f"--filters: {without[0]} takes no pairs (a point in 3-D); {', '.join(spatial)} do"
        )
    summary = track_runs.summarize_pairs(src.mu, rho, prior, q, names, steps)
    if args.smooth:  # the exact filter's smoother of pairs, depthcore.exact.spatial.track
        sm = track(src.mu, rho, prior, q, steps=steps).smoothed
        keys = ("depth_mean", "depth_sd", "lateral_mean", "lateral_sd")
        summary["smoothed"] = {k: getattr(sm, k).tolist() for k in keys}
    summary["c"] = track_runs.noise_free(src.mu, steps)[0]
    summary["c"] = None if summary["c"] is None else summary["c"].tolist()
    return _summary_text(args, summary | _named_frames(summary, src) | direction, src, steps)


def _output(args) -> str:
    return "json" if args.json else "csv" if args.csv else "table"


def _refuse_long(args, held) -> None:
    """Refuse what a track past ``MAX_FRAMES`` frames cannot have: all but ``--per-frame``."""
    where = f"{held.reading.name}:{held.first[-1].line}: more than {FRAMES_MAX} frames"
    holds = f"holds the whole track, at most {FRAMES_MAX} frames"
    if not args.per_frame:
        raise track_files.FileRefusal(
            f"{where}: estimate's summary {holds}; --per-frame streams a longer one through "
            f"the online filters ({', '.join(online.NAMES)})"
        )
    for flag in ("--learn-noise", "--smooth"):
        if getattr(args, flag[2:].replace("-", "_")):
            raise track_files.FileRefusal(f"{where}: {flag} {holds}")
    streaming = [n for n in _chosen(args) if n not in online.NAMES]
    if streaming:
        raise ValueError(
            f"--filters: {streaming[0]} has no online form; past {FRAMES_MAX} frames "
            f"--per-frame streams the track through {', '.join(online.NAMES)}"
        )


def _streamed(args, frames_in, rho, prior, q, gate, direction, why="long"):
    """``estimate --per-frame`` through the online filters, streamed: a track past
    ``MAX_FRAMES`` (``why`` ``"long"``) or of pairs (``"pairs"``), neither smoothed."""
    chosen = _chosen(args)
    rows = track_runs.streamed(frames_in, rho, prior, q, chosen, gate)
    count, blocks = tracks.spool(rows, chosen)
    head = {
        "frames": count,
        **({"coordinates": ["x", "y", "v", "h", "w"]} if len(prior.mean) == 5 else {}),
        "prior_mean": prior.mean.tolist(),
        "prior_cov": prior.cov.tolist(),
        "process_noise": q,
        "gate": gate,
        "smoothed": False,
        "smoothed_reason": {
            "long": f"the smoother holds the whole track, at most {FRAMES_MAX} frames",
            "pairs": "the online filters of pairs (a point in 3-D) do not smooth; --smooth without "
            "--per-frame smooths them",
        }[why],
    }
    return cli_text.per_frame_text(head | direction, blocks, _output(args))


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
    names = parsing.named_once(args.filters, "--filters")
    if q > 0 and "filters" not in getattr(args, "_given", ()):  # the default: those that can run
        names = tuple(n for n in names if FILTERS[n].with_process_noise)
    if args.truth == [monte_carlo.PRIOR_TRUTH]:
        parsing.refuse_ignored(
            args,
            "--truth prior (it checks the optimal filter alone, in this process)",
            {k: f"--{k}" for k in ("filters", "particles", "workers", "scheduler")},
        )
        if args.prior not in (None, "fixed"):
            raise ValueError(
                "--prior: --truth prior needs a fixed prior (the paper's rule is no prior; the "
                f"other forms draw truths about --truth X Y V), got {args.prior}"
            )
        result = parsing.with_bar(
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
        parsing.refuse_ignored(
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
        result = parsing.with_bar(
            "study", "trial", lambda p: monte_carlo.study(**options, progress=p, client=client)
        )
    return cli_text.as_json(result) if args.json else cli_text.format_study(result)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m depthcore``, with the registry's filters when built."""
    p = parsing.Parser(
        prog="python -m depthcore",
        description="Filter based estimates of depth (Maybank 1990): the paper's filters "
        f"on N >= 3 bearings (up to {FRAMES_MAX} frames, or any number streamed).",
        epilog=cli_text.EXAMPLES["all"],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"depthcore {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--debug", action="store_true", help="show the traceback of an unexpected failure"
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=parsing.Parser)
    r = parsing.command(
        sub, common, "reproduce", "moments of every filter for Figures 2-6, beside the paper's"
    )
    parsing.add_json(r, _cmd_reproduce)
    _add_estimate_arguments(sub, common)
    _add_study_arguments(sub, common)
    atlas = parsing.command(sub, common, "atlas", atlas_command.SUMMARY)
    atlas_command.add(atlas, parsing.with_bar, parsing.WriteError)
    return p


def _add_estimate_arguments(sub, common) -> None:
    """The command ``estimate`` and its options."""
    e = parsing.command(
        sub,
        common,
        "estimate",
        f"moments of every filter for any N >= 3 bearings (up to {FRAMES_MAX} frames, or any "
        "number streamed)",
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
    tracks.add_arguments(e, given)
    e.add_argument(
        "--rho",
        type=float,
        help=f"noise standard deviation, from {RHO_RANGE[0]:g} to {RHO_RANGE[1]:g} (needed "
        "unless the file has a rho column)",
    )
    priors.add_arguments(e)
    parsing.add_process_noise(e, ": the paper's constant velocity")
    e.add_argument(
        "--smooth",
        action="store_true",
        help="also the optimal filter's smoothed depth and lateral position at every frame",
    )
    parsing.add_filters(
        e,
        "filters to run, in this order",
        f"; with --per-frame those with a smoother, of {' '.join(names(smoothed=True))} "
        "(default: optimal)",
    )
    e.add_argument(
        "--per-frame",
        action="store_true",
        help="the filtered and smoothed depth, lateral position and velocity with their SDs at "
        "every frame (a track with missing frames, noise per frame or uneven steps needs it); "
        f"past {FRAMES_MAX} frames the filtered ones, streamed through the online filters",
    )
    e.add_argument(
        "--learn-noise",
        action="store_true",
        help="estimate rho and the process noise from the track by maximum likelihood (with "
        "--process-noise given: rho only; a rho column gives the frames' relative noise "
        "levels, and its scale is learned), with standard errors and the profile "
        "likelihood's intervals, and run the filters with them",
    )
    e.add_argument(
        "--gate",
        type=float,
        metavar="P",
        help="skip a bearing whose predictive tail probability is below P (a probability); "
        "with --learn-noise, also while learning",
    )
    e.add_argument(
        "--csv", action="store_true", help="with --per-frame: print CSV instead of a table"
    )
    parsing.add_json(e, _cmd_estimate)


def _add_study_arguments(sub, common) -> None:
    """The command ``study`` and its options."""
    st = parsing.command(
        sub, common, "study", "Monte Carlo study of every filter's error and calibration"
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
        choices=study_trials.PRIORS,
        help="paper (default): the paper's rule on each trial's measurements; fixed: on the "
        "truth (the only choice with --truth prior); range, log_uniform, inverse_depth: each "
        "trial's truth drawn from a prior of that form centred on the truth, the filters given "
        "its Gaussian",
    )
    parsing.add_filters(
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
    parsing.add_process_noise(
        st,
        "",
        "; with Q > 0 the filters that assume a constant velocity (particle) cannot be named",
    )
    cluster_options.add_arguments(st, "trials", "the same result, bit for bit")
    parsing.add_json(st, _cmd_study)


def _parse(argv) -> argparse.Namespace:
    """The parsed arguments; ``--help``, ``--version`` and refusals raise SystemExit."""
    return build_parser().parse_args(argv)


def main(argv=None) -> int:
    """Run the command line; returns the exit status (0, 1 or 2)."""
    try:
        args = _parse(argv)
    except parsing.WriteError as exc:
        sys.stderr.write(f"python -m depthcore: error: {exc}\n")
        return 1
    prog = f"python -m depthcore {args.command}"
    try:
        # Warnings become errors here only: the filters are restored on return.
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            text = args.run(args)
            for chunk in [text] if isinstance(text, str) else text:  # a long track: in chunks
                parsing.write(chunk)
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
        words, label = getattr(args, "_words", None), getattr(args, "_label", None)
        message = str(exc) if label is None else track_runs.relabel(str(exc), label)
        sys.stderr.write(f"{prog}: error: {refusals.users_words(args.command, message, words)}\n")
        return 2
    except parsing.WriteError as exc:
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
