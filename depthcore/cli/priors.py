"""``estimate``'s prior in the user's words: ``--prior-mean``, ``--prior-cov``, ``--prior-depth``.

Recommended import: ``from depthcore.cli import priors``.

The prior is on ``(x, y, v)`` at the first frame, or on ``(x, y, v, h, w)`` for
a track of pairs (a point in 3-D). :func:`add_arguments` gives its options and
:func:`prior` checks them against the track and builds it; without one, the
paper's rule or the range prior of ``--prior-depth``
(:func:`depthcore.registry.track_runs.start_prior`), refused in one line that
says why where the rule has no noise-free state ``c`` to start from.
"""

from __future__ import annotations

import csv

import numpy as np

from depthcore.cli import refusals
from depthcore.problem import checks, depth_prior
from depthcore.problem.gaussian import PAPER_PRIOR_SCALE, Gaussian
from depthcore.registry import track_runs

#: The prior's rule without ``--prior-mean``, as ``estimate --help`` says it.
RULE = f"""\
The prior at the first frame. Without --prior-mean, the paper's rule: the
noise-free state of the first three bearings present, moved back to the first
frame with v = 0, N((x1, y1, 0), {PAPER_PRIOR_SCALE:g} I) (the paper's (c1 - 2 c3, c2 - 2, 0)
at unit steps). --prior-depth MEAN SD is a range prior for a track whose first
bearings say little: y1 ~ N(MEAN, SD**2), x1 = mu_a (MEAN + t_a) on the line of
sight of the first bearing present (mu_a, at the depth travelled t_a), v = 0,
each of variance {PAPER_PRIOR_SCALE:g}. --prior-depth FORM ... is a law of the depth
(log-uniform, range, inverse-depth or table) with the same rest given the depth
(x1's mean mu_a (y1 + t_a)): the optimal filter takes it as it is, the others its
mean and covariance. For pairs the height follows the same rule:
h1 = nu_a (y1 + t_a), w = 0, each of variance {PAPER_PRIOR_SCALE:g}; --prior-mean and
--prior-cov take 5 and 25 values, in the order (x, y, v, h, w)."""


def add_arguments(parser) -> None:
    """The prior's options of ``estimate``."""
    parser.add_argument(
        "--prior-mean",
        type=float,
        nargs="+",
        metavar="M",
        help="prior mean at the first frame: X Y V, or X Y V H W for pairs (default: the "
        "paper's rule, below)",
    )
    parser.add_argument(
        "--prior-cov",
        type=float,
        nargs="+",
        metavar="S",
        help=f"prior covariance: S for S I (default {PAPER_PRIOR_SCALE:g}), or 9 values row "
        "by row (25 for pairs)",
    )
    parser.add_argument(
        "--prior-depth",
        nargs="+",
        metavar="ARG",
        help="a prior on the depth at the first frame instead, the rest by the paper's rule "
        "(below): MEAN SD, the Gaussian N(MEAN, SD**2); or a law the exact filter takes as it "
        "is (the others take its mean and covariance): log-uniform LO HI; range MEAN SD [LO "
        "[HI]] (truncated to LO..HI, default 0..inf); inverse-depth W SD WLO WHI (1/depth ~ "
        "N(W, SD**2) truncated to WLO..WHI, WLO > 0); table FILE (CSV rows depth,density)",
    )


def prior(mu, steps, args, largest: float, cov_range: tuple):
    """The prior of ``args.prior_mean``, ``args.prior_cov`` and ``args.prior_depth``.

    Parameters
    ----------
    mu : ndarray, shape (N,) or (N, 2)
        The checked bearings, or pairs.
    steps : ndarray, shape (N - 1,), or None
    args : argparse.Namespace
    largest : float
        The largest magnitude of a mean (and of ``--prior-depth``'s numbers).
    cov_range : (float, float)
        The smallest eigenvalue and the largest magnitude of the covariance.

    Returns
    -------
    depthcore.problem.gaussian.Gaussian, depthcore.registry.track_runs.Prior or
    depthcore.problem.depth_prior.DepthPrior

    Raises
    ------
    ValueError
        One line naming the option, or saying why the paper's rule cannot start the track.
    """
    d = 5 if np.ndim(mu) == 2 else 3
    mean, cov, depth = args.prior_mean, args.prior_cov, args.prior_depth
    if depth is not None and (mean is not None or cov is not None):
        raise ValueError(
            "--prior-depth: a prior of its own; give it or --prior-mean and --prior-cov"
        )
    for flag, given, counts in (("--prior-mean", mean, (d,)), ("--prior-cov", cov, (1, d * d))):
        if given is not None and len(given) not in counts:
            raise ValueError(_count(flag, len(given), d))
        if given is not None:
            refusals.check_limits(flag, given, largest if flag == "--prior-mean" else cov_range[1])
    if depth is not None and depth[0] in LAWS:
        return _law(mu, steps, depth, largest)
    if depth is not None and not _is_number(depth[0]):
        raise ValueError(
            f"--prior-depth takes MEAN SD or a law named {', '.join(LAWS)}, got {depth[0]!r}"
        )
    if depth is not None:
        depth = _numbers(depth, 2, "MEAN SD", largest)
        if not (depth[0] > 0 and depth[1] ** 2 >= cov_range[0]):
            raise ValueError(
                "--prior-depth takes the depth's mean (> 0) and SD (at least "
                f"{np.sqrt(cov_range[0]):g}) at the first frame, got {depth[0]!r} {depth[1]!r}"
            )
    if mean is None:
        try:
            start = track_runs.start_prior(mu, steps, depth)
        except ValueError as exc:
            if depth is not None:
                raise
            raise ValueError(
                "--prior-mean or --prior-depth MEAN SD is needed: the paper's prior rule has "
                f"no noise-free state c to start from: {str(exc).removeprefix('prior is needed: ')}"
            ) from None
        mean, cov = start.mean, start.cov if cov is None else cov
    if cov is None or len(cov) == 1:
        scale = PAPER_PRIOR_SCALE if cov is None else cov[0]
        if not scale > 0:
            raise ValueError(f"--prior-cov must be positive definite; S = {scale!r} is not > 0")
        cov = scale * np.eye(d)
    mean = checks.finite_array(mean, "--prior-mean", (d,))
    cov = checks.covariance(np.reshape(cov, (d, d)), "--prior-cov", d)
    smallest = np.linalg.eigvalsh(cov)[0]
    if smallest < cov_range[0]:
        raise ValueError(
            f"--prior-cov must have eigenvalues of at least {cov_range[0]:g}, got {smallest!r}"
        )
    return Gaussian(mean, cov) if d == 3 else track_runs.Prior(mean, cov)


def _count(flag: str, got: int, d: int) -> str:
    """The refusal of ``got`` values of ``flag`` for a state of ``d`` coordinates."""
    what = {
        "--prior-mean": f"{d} numbers {' '.join('XYVHW'[:d])}",
        "--prior-cov": f"1 value (S I) or {d * d} (a {d} x {d} matrix)",
    }[flag] + (" for pairs (a point in 3-D)" if d == 5 else "")
    other = " (a nu or v column, or --nu, makes pairs)" if d == 3 and got in (5, 25) else ""
    return f"{flag} takes {what}, got {got}{other}"


#: ``--prior-depth``'s laws: the numbers each takes after its name.
LAWS = {
    "log-uniform": (2, "LO HI"),
    "range": ((2, 3, 4), "MEAN SD [LO [HI]]"),
    "inverse-depth": (4, "W SD WLO WHI"),
    "table": (None, "FILE"),
}


def _numbers(values, counts, usage: str, largest: float) -> list:
    """``values`` (strings) as floats, as many as ``counts`` allows, else a one-line refusal."""
    counts = (counts,) if isinstance(counts, int) else counts
    if len(values) not in counts:
        raise ValueError(f"--prior-depth takes {usage}, got {_values(len(values))}")
    try:
        numbers = [float(v) for v in values]
    except ValueError:
        raise ValueError(
            f"--prior-depth takes {usage} as numbers, got {' '.join(values)}"
        ) from None
    refusals.check_limits("--prior-depth", numbers, largest)
    return numbers


def _table(path: str) -> tuple[list, list]:
    """A table's depths and densities from a CSV file of rows ``depth,density``."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = [r for r in csv.reader(handle) if r and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(
            f"--prior-depth table: cannot read {path}: {exc.strerror or exc}"
        ) from None
    try:
        pairs = [(float(a), float(b)) for a, b in (r[:2] for r in rows if len(r) >= 2)]
    except ValueError:
        rows = rows[1:]  # a header
        try:
            pairs = [(float(a), float(b)) for a, b in (r[:2] for r in rows if len(r) >= 2)]
        except ValueError:
            raise ValueError(f"--prior-depth table: {path} must hold rows depth,density") from None
    if len(pairs) < 2 or len(pairs) != len(rows):
        raise ValueError(f"--prior-depth table: {path} must hold at least 2 rows depth,density")
    return [p[0] for p in pairs], [p[1] for p in pairs]


def _law(mu, steps, given, largest: float) -> depth_prior.DepthPrior:
    """The law of ``--prior-depth FORM ...``, the rest given the depth by the paper's rule:
    ``x_1 = mu_a (y_1 + t_a)`` on the line of sight of the first bearing present and
    ``v = 0``, each with variance 1000."""
    if np.ndim(mu) == 2:
        raise ValueError("--prior-depth: a law of the depth is for bearings; pairs take MEAN SD")
    form, values = given[0], given[1:]
    counts, usage = LAWS[form]
    usage = f"{form} {usage}"
    s = np.ones(len(mu) - 1) if steps is None else np.asarray(steps, dtype=float)
    a = int(np.flatnonzero(~np.isnan(mu))[0])
    t_a = float(np.sum(s[:a]))
    lateral = depth_prior.Lateral(
        [mu[a] * t_a, 0.0], [mu[a], 0.0], PAPER_PRIOR_SCALE * np.eye(2), np.zeros((2, 2))
    )
    try:
        if form == "table":
            if len(values) != 1:
                raise ValueError(f"--prior-depth takes {usage}, got {_values(len(values))}")
            depths, density = _table(values[0])
            refusals.check_limits("--prior-depth", depths + density, largest)
            return depth_prior.table(depths, density, lateral)
        v = _numbers(values, counts, usage, largest)
        if form == "log-uniform":
            return depth_prior.log_uniform(*v, lateral)
        if form == "range":
            return depth_prior.range_prior(v[0], v[1], lateral, *v[2:])
        return depth_prior.inverse_depth(*v, lateral)
    except ValueError as exc:
        message = str(exc)
        raise ValueError(
            message if message.startswith("--prior-depth") else f"--prior-depth {form}: {message}"
        ) from None


def _values(n: int) -> str:
    return f"{n} value" + ("" if n == 1 else "s")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
