"""The chapter on the linear model: the bank of Kalman filters and its particle filter.

Recommended import: ``from depthbook import beyond_linear``.

* :func:`rbpf_convergence` and :func:`rbpf_convergence_figure`: the
  Rao-Blackwellised particle filter's moments against the number of
  particles, from the exact bank of Kalman filters; :func:`rbpf_texts` the
  texts the chapter glues;
* :func:`bank_depth_figure` and :func:`smoothing_figure`: the bank's depth
  marginals and its filtered and smoothed track.
"""

from __future__ import annotations

import numpy as np

from depthbook.errors import rms_se
from depthbook.style import MIN_FONT, WIDTH, legend_below, log_bars, reference_rate, subplots
from depthcore.exact import posterior
from depthcore.particles import rbpf
from depthcore.problem import checks
from depthcore.registry.estimates import MOMENTS

# --- the Rao-Blackwellised particle filter against the exact bank ----------------------------


def rbpf_convergence(
    mu,
    rho,
    prior_mean,
    prior_cov,
    sizes,
    replicas: int,
    seed,
    process_noise=0.0,
    moves: int = rbpf.DEFAULT_MOVES,
) -> dict:
    """The Rao-Blackwellised particle filter's moments at the last frame against ``J``.

    For each number of particles ``J`` the filter (:func:`depthcore.particles.rbpf.run`)
    runs ``replicas`` independent clouds over the bearings, from its own child
    stream of ``seed``; each cloud's moments at frame ``N`` are compared with
    the exact posterior of the bank of Kalman filters (:func:`depthcore.exact.posterior.posterior`).

    Parameters
    ----------
    mu : array_like, shape (N,)
        The bearings of one track.
    rho, prior_mean, prior_cov, process_noise
        As for :func:`depthcore.exact.posterior.posterior`.
    sizes : array_like of int, shape (S,)
        Particles per cloud, each >= 2.
    replicas : int
        Independent clouds per size, >= 2.
    seed : int or numpy.random.SeedSequence
    moves : int
        Metropolis-Hastings steps per particle after each resampling.

    Returns
    -------
    dict
        ``"sizes"`` (S,), ``"replicas"``, ``"frames"`` (``N``); ``"exact"``:
        ``{moment: float}`` for :data:`~depthcore.registry.estimates.MOMENTS` and
        ``"exact_error"``: the
        bank's error estimates of the depth's and the velocity's moments
        (``{"depth": float, "velocity": float}``); ``"runs"``: ``{moment: (S,
        replicas)}``, each cloud's estimate; ``"mean"``, ``"se"`` and
        ``"rmse"``: ``{moment: (S,)}``, the mean over the clouds, its standard
        error (SD over the clouds / sqrt(replicas)), and the root-mean-square
        error of one cloud from the exact value.
    """
    sizes = checks.sizes(sizes)
    if np.any(sizes < 2):
        raise ValueError(f"sizes must be integers >= 2, got {sizes!r}")
    if isinstance(replicas, bool) or not isinstance(replicas, (int, np.integer)) or replicas < 2:
        raise ValueError(f"replicas must be an integer >= 2, got {replicas!r}")
    post = posterior.posterior(mu, rho, prior_mean, prior_cov, process_noise)
    if np.ndim(post.log_normaliser) != 0:
        raise ValueError(f"mu must have shape (N,) (one track), got shape {np.shape(mu)}")
    exact = {m: float(getattr(post, m)) for m in MOMENTS}
    runs = {m: [] for m in MOMENTS}
    for J, stream in zip(sizes, checks.spawn(seed, len(sizes)), strict=True):
        state = rbpf.run(
            mu,
            rho,
            prior_mean,
            prior_cov,
            int(J),
            np.random.default_rng(stream),
            process_noise=process_noise,
            replicas=int(replicas),
            moves=moves,
        )
        per_cloud = state.replica_moments()
        for m in MOMENTS:
            runs[m].append(getattr(per_cloud, m))
    runs = {m: np.array(v) for m, v in runs.items()}
    return {
        "sizes": sizes,
        "replicas": int(replicas),
        "frames": int(post.bank.frames),
        "exact": exact,
        "exact_error": {
            "depth": float(post.depth_error),
            "velocity": float(post.velocity_error),
        },
        "runs": runs,
        "mean": {m: np.mean(v, axis=1) for m, v in runs.items()},
        "se": {m: np.std(v, axis=1, ddof=1) / np.sqrt(replicas) for m, v in runs.items()},
        "rmse": {m: np.sqrt(np.mean((v - exact[m]) ** 2, axis=1)) for m, v in runs.items()},
    }


def bank_depth_figure(densities: dict, truth=None):
    """The bank's posterior depth density at its nodes after several frames.

    Parameters
    ----------
    densities : dict
        ``{frame: (depths, density)}``, each from :func:`depthcore.exact.posterior.node_density`
        of the posterior after that frame: the nodes as depths at that frame and
        the density there (arrays of shape (J,)).
    truth : dict, optional
        ``{frame: depth}``, the true depth at each frame, marked on the axis.

    Returns
    -------
    matplotlib.figure.Figure
        The density against the depth at each frame (one curve per frame, the
        nodes as dots), and the same curves against the depth minus the truth,
        on a logarithmic density axis.
    """
    import matplotlib.pyplot as plt

    if not densities:
        raise ValueError("densities must hold at least one frame")
    fig, axes = subplots(1, 2, figsize=(WIDTH, 4.2))
    colours = plt.cm.viridis(np.linspace(0.0, 0.9, len(densities)))
    for (frame, (depths, density)), colour in zip(densities.items(), colours, strict=True):
        order = np.argsort(depths)
        y, p = np.asarray(depths)[order], np.asarray(density)[order]
        keep = p > 1e-6 * np.max(p)
        label = f"after frame {frame}"
        axes[0].plot(y[keep], p[keep], "-", color=colour, linewidth=1.2, label=label)
        axes[0].plot(y[keep], p[keep], ".", color=colour, markersize=3)
        if truth is not None:
            axes[0].axvline(truth[frame], color=colour, linewidth=0.8, linestyle=":")
            axes[1].semilogy(y[keep] - truth[frame], p[keep], "-", color=colour, linewidth=1.2)
    axes[0].set_xlabel("depth $y_N$ at frame $N$ (dots: the nodes; dotted: the truth)")
    axes[0].set_ylabel("posterior density")
    axes[0].legend(frameon=False, fontsize=MIN_FONT)
    axes[0].set_title("(a)", fontsize=MIN_FONT)
    if truth is not None:
        axes[1].axvline(0.0, color="0.5", linewidth=0.8, linestyle=":")
        axes[1].set_xlabel("depth minus the true depth at frame $N$")
        axes[1].set_ylabel("posterior density (log scale)")
        axes[1].set_title("(b) about the truth", fontsize=MIN_FONT)
    else:
        axes[1].set_visible(False)
    return fig


def smoothing_figure(track, states, first: int = 1):
    """The depth and lateral position at every frame: filtered, fixed-lag and fixed-interval.

    Parameters
    ----------
    track : depthcore.exact.smoother.Track
        From :func:`depthcore.exact.smoother.track`.
    states : array_like, shape (N, 3)
        The true states ``(x_k, y_k, v_k)``.
    first : int
        The first frame drawn (the first frames' filtered SDs can dwarf the rest).

    Returns
    -------
    matplotlib.figure.Figure
        Two panels, the depth and the lateral position: each estimate minus the
        truth, with a band of two SDs about it.
    """
    from matplotlib.ticker import MaxNLocator

    states = np.asarray(states, dtype=float)
    N = states.shape[0]
    if not 1 <= first <= N:
        raise ValueError(f"first must be a frame from 1 to {N}, got {first!r}")
    frames = np.arange(first, N + 1)
    rows = slice(first - 1, N)
    series = (
        ("filtered", track.filtered, "tab:blue", "-"),
        (f"fixed-lag smoothed (lag {track.lag})", track.lagged, "tab:orange", "--"),
        ("fixed-interval smoothed", track.interval, "tab:green", "-"),
    )
    fig, axes = subplots(1, 2, figsize=(WIDTH, 4.2))
    names = ("(a) depth $y_k$", "(b) lateral position $x_k$")
    for ax, i, name in zip(axes, (1, 0), names, strict=True):
        for label, s, colour, style in series:
            err = s.mean[rows, i] - states[rows, i]
            sd = np.sqrt(s.cov[rows, i, i])
            ax.plot(frames, err, linestyle=style, color=colour, marker=".", label=label)
            ax.fill_between(frames, err - 2 * sd, err + 2 * sd, color=colour, alpha=0.15)
        ax.axhline(0.0, color="black", linewidth=0.8)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("frame $k$")
        ax.set_ylabel("estimate minus truth")
        ax.set_title(name, fontsize=MIN_FONT)
    legend_below(fig, axes[:1], ncol=3)
    return fig


def rbpf_convergence_figure(result: dict):
    """The Rao-Blackwellised particle filter's depth moments against the number of particles.

    Parameters
    ----------
    result : dict
        The clouds of :func:`depthbook.beyond_linear.rbpf_convergence`, with
        the exact bank's moments they are measured from.

    Returns
    -------
    matplotlib.figure.Figure
        Left: the RMS error of one cloud's depth mean and SD from the exact
        bank's, on log axes, beside the exact SD over ``sqrt(J)``, with bars of
        two standard errors either side (:func:`depthbook.errors.rms_se` of the
        clouds' errors), cut at a tenth of the point on the log axis. Right: each
        cloud's depth mean, and their average with two standard errors, about
        the exact value.
    """

    J = np.asarray(result["sizes"])
    exact = result["exact"]
    fig, axes = subplots(1, 2, figsize=(WIDTH, 4.2))
    ax = axes[0]
    for moment, fmt, colour, label in (
        ("depth_mean", "o-", "tab:purple", "depth mean"),
        ("depth_sd", "s--", "tab:orange", "depth SD"),
    ):
        y = np.asarray(result["rmse"][moment], dtype=float)
        _, se = rms_se(result["runs"][moment] - exact[moment], axis=1)
        ax.errorbar(J, y, yerr=log_bars(y, se), fmt=fmt, color=colour, capsize=2, label=label)
    reference_rate(ax, J, exact["depth_sd"] / np.sqrt(J), r"exact depth SD$/\sqrt{J}$")
    ax.set_xlabel("particles per cloud $J$")
    ax.set_ylabel("RMS error from the exact bank")
    ax.set_title("(a) RMS error", fontsize=MIN_FONT)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    ax = axes[1]
    runs = result["runs"]["depth_mean"] - exact["depth_mean"]
    for k, j in enumerate(J):
        ax.plot(np.full(runs.shape[1], j), runs[k], ".", color="0.6", markersize=4)
    ax.errorbar(
        J,
        result["mean"]["depth_mean"] - exact["depth_mean"],
        yerr=2 * result["se"]["depth_mean"],
        fmt="o",
        color="tab:purple",
        capsize=3,
        label="average of the clouds, 2 SE",
    )
    ax.axhline(0.0, color="black", linewidth=0.8, label="exact bank")
    ax.set_xscale("log")
    ax.set_xlabel("particles per cloud $J$")
    ax.set_ylabel(f"depth mean at frame {result['frames']} minus the exact one")
    ax.set_title("(b) each cloud's depth mean", fontsize=MIN_FONT)
    ax.legend(frameon=False, fontsize=MIN_FONT)
    return fig


# --- the book's pages as plain notebooks ---------------------------------------------------


def rbpf_texts(result: dict, prefix: str) -> dict:
    """Texts of the Rao-Blackwellised particle filter's convergence table, for glue.

    Parameters
    ----------
    result : dict
        :func:`depthbook.beyond_linear.rbpf_convergence`'s result.
    prefix : str
        Begins every key.

    Returns
    -------
    dict
        For row ``i`` (one number of particles): ``"<prefix>_<i>_J"``;
        ``"<prefix>_<i>_mean"`` and ``"<prefix>_<i>_sd"``, the clouds'
        average depth mean and SD with their standard errors (``"mean ± se"``,
        4 decimals); ``"<prefix>_<i>_rmse_mean"`` and ``"<prefix>_<i>_rmse_sd"``,
        one cloud's RMS errors of the depth mean and SD (2 significant digits).
        ``"<prefix>_exact_mean"`` and ``"<prefix>_exact_sd"``: the exact bank's
        depth mean and SD (4 decimals).
    """
    out = {
        f"{prefix}_exact_mean": f"{result['exact']['depth_mean']:.4f}",
        f"{prefix}_exact_sd": f"{result['exact']['depth_sd']:.4f}",
    }
    for i, J in enumerate(result["sizes"]):
        out[f"{prefix}_{i}_J"] = f"{int(J):,}"
        for key, moment in (("mean", "depth_mean"), ("sd", "depth_sd")):
            out[f"{prefix}_{i}_{key}"] = (
                f"{result['mean'][moment][i]:.4f} ± {result['se'][moment][i]:.4f}"
            )
            out[f"{prefix}_{i}_rmse_{key}"] = f"{result['rmse'][moment][i]:.2g}"
    return out
