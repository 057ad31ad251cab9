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

import numpy as np

from depthcore.cli import refusals
from depthcore.problem import checks
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
each of variance {PAPER_PRIOR_SCALE:g}. For pairs the height follows the same rule:
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
        type=float,
        nargs=2,
        metavar=("MEAN", "SD"),
        help="a range prior instead: the depth at the first frame ~ N(MEAN, SD**2), the rest "
        "by the paper's rule (below)",
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
    depthcore.problem.gaussian.Gaussian or depthcore.registry.track_runs.Prior

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
    if depth is not None:
        refusals.check_limits("--prior-depth", depth, largest)
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
