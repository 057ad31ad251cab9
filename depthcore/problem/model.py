"""The motion and measurement model of the paper, Eqs. (1), (3)-(5), (7), (9), (11), (20)-(22).

A point moves in the (x, y) plane with constant velocity ``(v, 1)``; its state
at time ``i`` is ``(x_i, y_i, v_i)``, with ``y`` the depth. The camera sees the
bearing ``x / y`` plus white Gaussian noise of standard deviation ``rho``.

Recommended import: ``from depthcore.problem import model``.

All functions act on the last axis of arrays of states, ``(3,)`` or ``(..., 3)``.
Besides the equations above, it draws tracks and their bearings (:func:`simulate`,
the package's one simulator) and checks bearings (:func:`measurements`,
:func:`measurements_batch`, :func:`valid_measurements`) and a filter's inputs
(:func:`batch_problem`, :func:`batch_inputs`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depthcore.problem import checks

#: The linear part of the motion G, Eq. (9).
F = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
F.setflags(write=False)

#: The constant part of the motion G, Eq. (9).
e = np.array([0.0, 1.0, 0.0])
e.setflags(write=False)

#: Number of measurements the paper's filters use.
N_MEASUREMENTS = 3


def G_linear(k: int) -> np.ndarray:
    """Linear part of ``G**k`` (``k`` may be negative), a ``(3, 3)`` array.

    Eqs. (1), (9): ``F**k = [[1, 0, k], [0, 1, 0], [0, 0, 1]]``.
    """
    return np.array([[1.0, 0.0, float(k)], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def G(x, k: int = 1) -> np.ndarray:
    """Eq. (1): move states ``k`` steps forward (backward for ``k < 0``).

    Parameters
    ----------
    x : array_like, shape (..., 3)
    k : int or array_like
        Time steps (broadcast with ``x.shape[:-1]``); ``G(x, -2)`` is ``G^{-2} x``.

    Returns
    -------
    ndarray, shape (..., 3)
        ``(x + k v, y + k, v)``.
    """
    x = np.asarray(x, dtype=float)
    if np.ndim(k) == 0:
        return np.stack([x[..., 0] + k * x[..., 2], x[..., 1] + k, x[..., 2]], axis=-1)
    moved = np.broadcast_arrays(x[..., 0] + k * x[..., 2], x[..., 1] + k, x[..., 2])
    return np.stack(moved, axis=-1)


def project(x) -> np.ndarray:
    """The noise-free image measurement ``x / y`` of states ``x`` (shape (..., 3))."""
    x = np.asarray(x, dtype=float)
    return x[..., 0] / x[..., 1]


def observation_vector(n) -> np.ndarray:
    """Eq. (11): gradient of the projection ``x / y`` at the state ``n``.

    Parameters
    ----------
    n : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
        ``h = (1 / n2, -n1 / n2**2, 0)``.
    """
    n = np.asarray(n, dtype=float)
    return np.stack([1.0 / n[..., 1], -n[..., 0] / n[..., 1] ** 2, np.zeros(n.shape[:-1])], axis=-1)


def log_likelihood(mu, x, rho, front: bool = False) -> np.ndarray:
    """Eq. (4): log density of one measurement ``mu`` given states ``x``.

    Parameters
    ----------
    mu : float or array_like broadcastable to ``x.shape[:-1]``
    x : array_like, shape (..., 3)
    rho : float or array_like broadcastable to ``x.shape[:-1]``
    front : bool
        If true, states with ``y <= 0`` get ``-inf``.

    Returns
    -------
    ndarray, shape x.shape[:-1]
        ``-log(sqrt(2 pi) rho) - (x / y - mu)**2 / (2 rho**2)``.
    """
    rho = checks.positive_array(rho, "rho") if np.ndim(rho) <= 1 else np.asarray(rho, float)
    if not np.all(rho > 0):
        raise ValueError(f"rho must be positive, got minimum {float(np.min(rho))}")
    x = np.asarray(x, dtype=float)
    if front:
        inside = x[..., 1] > 0
        x = np.where(inside[..., None], x, 1.0)
    r = project(x) - np.asarray(mu, dtype=float)
    log_l = -0.5 * np.log(2.0 * np.pi) - np.log(rho) - 0.5 * (r / rho) ** 2
    return np.where(inside, log_l, -np.inf) if front else log_l


def trajectory(x1, frames: int = N_MEASUREMENTS) -> np.ndarray:
    """States at times ``1 .. frames`` of a point whose state at time 1 is ``x1``.

    Returns
    -------
    ndarray, shape (frames, 3)
    """
    x1 = checks.finite_array(x1, "x1", (3,))
    return np.stack([G(x1, k) for k in range(frames)])


class Simulation(NamedTuple):
    """A simulated track: states (..., N, 3) ``(x_k, y_k, v_k)`` and bearings (..., N)."""

    states: np.ndarray
    mu: np.ndarray


def simulate(
    state,
    frames: int,
    rho,
    process_noise,
    rng: np.random.Generator,
    size: int | None = None,
    *,
    frame: int = N_MEASUREMENTS,
    steps=None,
) -> Simulation:
    """Draw a track of ``N`` frames through a given state, and its noisy bearings, Eqs. (1), (4).

    Up to ``frame`` the motion is Eq. (1)'s; from it on ``v_{k+1} = v_k + a_k``,
    ``a_k ~ N(0, q**2)`` (:mod:`depthcore.exact.bank`'s model), and ``mu_k = x_k / y_k +
    w_k``, ``w_k ~ N(0, rho**2)`` (Eq. (4)).

    Parameters
    ----------
    state : array_like, shape (..., 3)
        The state at frame ``frame``, in front of the camera at frame 1.
    frames : int
        ``N >= 1``.
    rho : float or array_like, shape (N,)
    process_noise : float
        Acceleration SD, >= 0 (per unit step).
    rng : numpy.random.Generator
        Draws the accelerations (``lead + (N - frame,)``, when ``q > 0``), then the
        bearing noise (``lead + (N,)``).
    size : int, optional
        Independent tracks from each ``state``; ``None`` for one.
    frame : int
        Default 3, the time of the paper's estimates.
    steps : array_like, shape (N - 1,), optional
        The depth's signed change between frames, nonzero (negative: the camera
        approaches the point, whose depth must stay positive); ``None``: all ones.

    Returns
    -------
    Simulation
        ``states`` of shape ``lead + (N, 3)`` and ``mu`` of shape ``lead + (N,)``,
        with ``lead = (size,) + state.shape[:-1]`` (without ``size`` if ``None``).
    """
    state = checks.finite_array(state, "state")
    if state.ndim < 1 or state.shape[-1] != 3:
        raise ValueError(f"state must have shape (..., 3), got shape {state.shape}")
    frame = checks.count(frame, "frame")
    frames = checks.count(frames, "frames")
    depth_1 = state[..., 1] - (frame - 1)
    if not np.all(depth_1 > 0):
        raise ValueError(
            f"state puts the point behind the camera: the depth at frame 1 must be > 0, "
            f"got minimum {float(np.min(depth_1)):.6g}"
        )
    rho = checks.positive_array(rho, "rho")
    if rho.ndim and rho.shape != (frames,):
        raise ValueError(f"rho must be a number or have shape ({frames},), got {rho.shape}")
    process_noise = checks.nonnegative_scalar(process_noise, "process_noise")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if size is not None:
        size = checks.count(size, "size")
    lead = ((size,) if size is not None else ()) + state.shape[:-1]
    if steps is None and not rho.ndim:
        return draw_track(state, frames, float(rho), process_noise, rng, lead, frame)
    steps = np.ones(frames - 1) if steps is None else checks.finite_array(steps, "steps")
    if steps.shape != (frames - 1,):
        raise ValueError(f"steps must have shape ({frames - 1},), got shape {steps.shape}")
    if np.any(steps == 0):
        raise ValueError("steps must be nonzero (the depth's signed change), got a zero step")
    elapsed = np.concatenate([[0.0], np.cumsum(steps)])
    nearest = np.min(elapsed) - elapsed[frame - 1] + state[..., 1]
    if not np.all(nearest > 0):
        raise ValueError(
            "state and steps bring the point to the camera: its depth must stay > 0 at every "
            f"frame, got minimum {float(np.min(nearest)):.6g}"
        )
    return _draw_uneven(state, rho, process_noise, rng, lead, frame, steps)


def _draw_uneven(state, rho, process_noise: float, rng, lead, frame: int, steps) -> Simulation:
    """:func:`simulate` with steps between frames and noise per frame, on checked inputs."""
    frames = len(steps) + 1
    elapsed = np.concatenate([[0.0], np.cumsum(steps)])
    t = elapsed - elapsed[frame - 1]  # depth travelled since the given frame
    n_noisy = max(frames - frame, 0)
    v = np.broadcast_to(state[..., 2, None], lead + (frames,)).copy()
    if process_noise > 0 and n_noisy:
        after = steps[frame - 1 :]  # the steps from the given frame on
        a = process_noise * np.sqrt(np.abs(after)) * rng.standard_normal(lead + (n_noisy,))
        v[..., frame:] += np.cumsum(a, axis=-1)
    # x_{k+1} = x_k + s_k v_k from the given frame on; backwards by the constant velocity
    moves = v[..., :-1] * steps
    x = np.concatenate([np.zeros(lead + (1,)), np.cumsum(moves, axis=-1)], axis=-1)
    x = state[..., 0, None] + x - x[..., frame - 1 : frame]
    y = np.broadcast_to(state[..., 1, None] + t, x.shape)
    states = np.stack([x, np.asarray(y, dtype=float), v], axis=-1)
    mu = x / y + rho * rng.standard_normal(lead + (frames,))
    return Simulation(states, mu)


def draw_track(state, frames: int, rho: float, process_noise: float, rng, lead, frame: int):
    """:func:`simulate` on checked inputs; ``lead`` is the tracks' leading shape."""
    k = np.arange(1, frames + 1) - frame  # frames from the given one
    n_noisy = max(frames - frame, 0)
    v = np.broadcast_to(state[..., 2, None], lead + (frames,))
    x = state[..., 0, None] + np.minimum(k, 0) * state[..., 2, None] + np.zeros(lead + (1,))
    if process_noise > 0 and n_noisy:
        a = process_noise * rng.standard_normal(lead + (n_noisy,))
        dv = np.cumsum(a, axis=-1)  # v_{frame + j} - v_frame, j = 1 .. n_noisy
        v_after = state[..., 2, None] + dv
        v = np.concatenate([v[..., : frames - n_noisy], v_after], axis=-1)
        # x_{frame + j} = x_frame + sum_{i < j} v_{frame + i}
        steps = np.concatenate([v[..., frame - 1 : frame], v_after[..., :-1]], axis=-1)
        x_after = state[..., 0, None] + np.cumsum(steps, axis=-1)
        x = np.concatenate([x[..., : frames - n_noisy], x_after], axis=-1)
    else:
        x = state[..., 0, None] + k * state[..., 2, None] + np.zeros(lead + (1,))
    y = np.broadcast_to(state[..., 1, None] + k, x.shape)
    states = np.stack([x, np.asarray(y, dtype=float), np.broadcast_to(v, x.shape)], axis=-1)
    mu = x / y + rho * rng.standard_normal(lead + (frames,))
    return Simulation(states, mu)


def noise_in_pixels(
    rho: float, image_size: int = 512, fov_deg: float = 30.0, small_angle: bool = True
) -> float:
    """The image error, in pixels, of a bearing error ``rho`` (radians).

    With ``small_angle`` (the paper's arithmetic) ``rho * image_size / fov``; without,
    ``focal * tan(rho)`` with ``focal = (image_size / 2) / tan(fov / 2)``. ``fov_deg`` is
    the horizontal field of view in (0, 180) degrees, ``image_size`` the width in pixels.
    """
    rho = checks.positive_scalar(rho, "rho")
    size = checks.positive_scalar(image_size, "image_size")
    fov = checks.positive_scalar(fov_deg, "fov_deg")
    if fov >= 180:
        raise ValueError(f"fov_deg must be below 180, got {fov}")
    fov = np.deg2rad(fov)
    if small_angle:
        return float(rho * size / fov)
    return float(size / 2 / np.tan(fov / 2) * np.tan(rho))


def bearings_from_pixels(u, cx, focal) -> np.ndarray:
    """The bearings ``mu = x / y`` of image columns ``u`` seen by a pinhole camera.

    ``mu = (u - cx) / focal`` (Eq. (4) without noise); a pixel noise ``s`` is ``rho = s /
    focal``. ``u`` (N,) columns in pixels, ``cx`` the principal point's column, ``focal``
    in pixels; returns (N,).
    """
    u = checks.finite_array(u, "u")
    if u.ndim != 1 or u.size == 0:
        raise ValueError(f"u must have shape (N,) with N >= 1, got shape {u.shape}")
    cx = checks.number(cx, "cx")
    focal = checks.positive_scalar(focal, "focal")
    with np.errstate(over="ignore", invalid="ignore"):
        mu = (u - cx) / focal
    if not np.all(np.isfinite(mu)):
        raise ValueError(
            f"focal is too small for these columns: (u - cx) / focal overflows, got {focal!r}"
        )
    return mu


# --- the misfit of three measurements, Eqs. (5), (7), (20)-(22) ---------------------------------


def noise_free_state(mu) -> np.ndarray:
    """Eq. (7): the state ``c`` at time 3 with ``f(c) = 0``.

    Parameters
    ----------
    mu : array_like, shape (3,)
        Checked by :func:`measurements`.

    Returns
    -------
    ndarray, shape (3,)
        ``c = (c1, c2, c3)``: position ``(c1, c2)``, velocity ``(c3, 1)``.
    """
    return noise_free_states_unchecked(measurements(mu))


def noise_free_states_unchecked(mu) -> np.ndarray:
    """Eq. (7) for triples ``mu`` of shape (..., 3), unchecked (NaN or inf where degenerate)."""
    mu1, mu2, mu3 = np.moveaxis(np.asarray(mu, dtype=float), -1, 0)
    d = mu3 + mu1 - 2.0 * mu2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # documented NaN, inf
        return np.stack(
            [
                2.0 * mu3 * (mu1 - mu2) / d,
                noise_free_depth_unchecked(mu),
                (2.0 * mu1 * mu3 - mu2 * mu3 - mu1 * mu2) / d,
            ],
            axis=-1,
        )


def noise_free_depth_unchecked(mu) -> np.ndarray:
    """``c2`` of Eq. (7), the noise-free depth at time 3, for triples ``mu`` of shape (..., 3).

    ``c2 = 2 (mu1 - mu2) / (mu1 + mu3 - 2 mu2)``, unchecked; shape ``mu.shape[:-1]``.
    """
    mu1, mu2, mu3 = np.moveaxis(np.asarray(mu, dtype=float), -1, 0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # documented NaN, inf
        return 2.0 * (mu1 - mu2) / (mu3 + mu1 - 2.0 * mu2)


def residuals(x, mu) -> np.ndarray:
    """The terms of Eq. (5) before squaring, in time order, for ``N >= 1`` bearings.

    Parameters
    ----------
    x : array_like, shape (..., 3)
        States at the last frame ``N`` (time 3 for the paper's triple).
    mu : array_like, shape (N,) or broadcastable to ``x.shape[:-1] + (N,)``

    Returns
    -------
    ndarray, shape (..., N)
        ``r_k = project(G^{k-N} x) - mu_k``; for a triple,
        ``((x - 2v)/(y - 2) - mu1, (x - v)/(y - 1) - mu2, x/y - mu3)``.
    """
    x = np.asarray(x, dtype=float)
    mu = np.asarray(mu, dtype=float)
    back = np.arange(mu.shape[-1]) - (mu.shape[-1] - 1.0)  # k - N for frames k = 1 .. N
    return project(G(x[..., None, :], back)) - mu


def f(x, mu) -> np.ndarray:
    """Eq. (5): the sum of squared residuals, shape ``x.shape[:-1]``."""
    return np.sum(residuals(x, mu) ** 2, axis=-1)


def residual_gradients(x, frames: int = N_MEASUREMENTS) -> np.ndarray:
    """Eqs. (20)-(22): gradients of the residuals at states ``x``, rows in time order.

    Row ``k`` is ``h(G^{k-N+1} x) F^{k-N+1}``, Eq. (11) pulled back to the last frame.
    ``x`` (..., 3) at the last frame, ``frames`` ``N``; returns (..., N, 3).
    """
    x = np.asarray(x, dtype=float)
    back = np.arange(frames) - (frames - 1.0)  # k - N for frames k = 1 .. N
    h = observation_vector(G(x[..., None, :], back))  # (..., N, 3), third column 0
    h[..., 2] = back * h[..., 0]  # times F^{k-N}: d(x + (k - N) v)/dv = k - N
    return h


def noise_free_states(mu) -> np.ndarray:
    """Eq. (7) for a batch of triples ``mu`` of shape ``(B, 3)``; returns ``(B, 3)``.

    Each row is checked as in :func:`noise_free_state`.
    """
    mu = checks.finite_array(mu, "mu")
    if mu.ndim != 2 or mu.shape[1] != 3:
        raise ValueError(f"mu must have shape (B, 3), got shape {mu.shape}")
    d = mu[:, 2] + mu[:, 0] - 2.0 * mu[:, 1]
    bad = np.abs(d) <= checks.DEGENERACY_TOL
    if np.any(bad):
        measurements(mu[np.argmax(bad)], f"mu[{int(np.argmax(bad))}]")
    c = noise_free_states_unchecked(mu)
    behind = ~(c[:, 1] > 2.0)
    if np.any(behind):
        i = int(np.argmax(behind))
        measurements(mu[i], f"mu[{i}]")
    return c


# --- the least misfit at each depth ----------------------------------------------------------


def profile_misfit(mu, depths) -> np.ndarray:
    """The least misfit ``f`` (Eq. (5)) of the measurements over states with a given depth.

    Linear least squares in ``(x3, v)`` at each depth ``y3 > 2`` of ``depths`` (n,);
    ``exp(-f / (2 rho**2))`` is the depth's profile likelihood. Returns (n,).
    """
    mu = measurements(mu)
    y3 = np.atleast_1d(checks.finite_array(depths, "depths"))
    if y3.ndim != 1 or np.any(y3 <= 2.0):
        raise ValueError("depths must be a 1-D array of depths > 2 at time 3")
    back = np.array([2.0, 1.0, 0.0])  # 3 - i for i = 1, 2, 3
    yi = y3[:, None] - back  # (n, 3): depth at times 1..3
    A = np.stack([1.0 / yi, -back / yi], axis=-1)  # (n, 3, 2): bearings = A @ (x3, v)
    AtA = np.einsum("nij,nik->njk", A, A)
    Atb = np.einsum("nij,i->nj", A, mu)
    xv = np.linalg.solve(AtA, Atb[..., None])[..., 0]
    r = mu - np.einsum("nij,nj->ni", A, xv)
    return np.sum(r**2, axis=-1)


def far_misfit(mu) -> float:
    """The limit of :func:`profile_misfit` at infinite depth, ``(mu1 - 2 mu2 + mu3)**2 / 6``.

    Far away the bearings are linear in time: the misfit is along ``(1, -2, 1) / sqrt(6)``.
    """
    mu = measurements(mu)
    return float((mu[0] - 2.0 * mu[1] + mu[2]) ** 2 / 6.0)


# --- checks of the bearings ---------------------------------------------------------


def measurements(mu, name: str = "mu") -> np.ndarray:
    """Check a triple ``(mu1, mu2, mu3)`` of image measurements.

    The triple must be finite, not degenerate (see ``depthcore.problem.checks.DEGENERACY_TOL``), and
    its noise-free solution, Eq. (7), must lie in front of the camera at all
    three times: depth ``c2 - 2 > 0`` at the first frame.
    """
    arr = checks.finite_array(mu, name, (3,))
    second_difference = arr[0] + arr[2] - 2.0 * arr[1]
    if abs(second_difference) <= checks.DEGENERACY_TOL:
        raise ValueError(
            f"{name} is degenerate: mu1 + mu3 - 2*mu2 = {second_difference:.3g}, "
            "so no finite depth explains the three measurements"
        )
    depth_first = noise_free_depth_unchecked(arr) - 2.0
    if not depth_first > 0:
        raise ValueError(
            f"{name} puts the point behind the camera: its noise-free depth at the "
            f"first frame is c2 - 2 = {depth_first:.6g}, which is not positive"
        )
    return arr


def valid_measurements(mu) -> np.ndarray:
    """Which triples of ``mu`` (..., 3) :func:`measurements` accepts, without raising.

    Returns a boolean array of shape ``mu.shape[:-1]``.
    """
    arr = np.asarray(mu, dtype=float)
    d = arr[..., 0] + arr[..., 2] - 2.0 * arr[..., 1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        depth_first = noise_free_depth_unchecked(arr) - 2.0
    return (
        np.all(np.isfinite(arr), axis=-1) & (np.abs(d) > checks.DEGENERACY_TOL) & (depth_first > 0)
    )


def measurements_batch(mu, name: str = "mu") -> np.ndarray:
    """Check bearings of shape ``(..., N)``, ``3 <= N <= MAX_FRAMES``, row by row.

    With ``N = 3`` each triple as :func:`measurements`; with ``N > 3`` a row is refused
    only when every second difference is within ``depthcore.problem.checks.DEGENERACY_TOL``
    (bearings affine in time). The first offending row is named, e.g. ``mu[4]``.
    """
    arr = checks.frame_rows(checks.finite_array(mu, name), name, "bearings")
    batch = arr.shape[:-1]
    n_frames = arr.shape[-1]
    flat = arr.reshape(-1, n_frames)
    if n_frames > 3:
        second = flat[:, :-2] + flat[:, 2:] - 2.0 * flat[:, 1:-1]
        degenerate = ~np.any(np.abs(second) > checks.DEGENERACY_TOL, axis=1)
        if np.any(degenerate):
            i = int(np.argmax(degenerate))
            where = name + (checks.batch_index(i, batch) if batch else "")
            raise ValueError(
                f"{where} is degenerate: every second difference mu_k - 2*mu_(k+1) + mu_(k+2) "
                f"is at most {checks.DEGENERACY_TOL:g} in magnitude, so no finite depth explains "
                "the bearings"
            )
        return arr
    bad = ~valid_measurements(flat)
    if np.any(bad):
        i = int(np.argmax(bad))
        measurements(flat[i], name + (checks.batch_index(i, batch) if batch else ""))
    return arr


def batch_problem(mu, rho, prior_mean, prior_cov, triples: bool = True):
    """The checks shared by the batched filters: measurements, noise and prior.

    Parameters
    ----------
    mu : array_like, shape (..., N), or (..., K) when ``triples`` is false
        Checked by :func:`measurements_batch`; otherwise any finite bearings.
    rho : float or array_like, shape ``mu.shape[:-1]``
    prior_mean : array_like, broadcastable to ``mu.shape``
    prior_cov : array_like, broadcastable to ``mu.shape + (3,)``
        Checked by :func:`depthcore.problem.checks.covariances`.

    Returns
    -------
    mu, rho, prior_mean, prior_cov : ndarray
        As float arrays (the covariances symmetrised), not broadcast.
    """
    if triples:
        mu = measurements_batch(mu, "mu")
    else:
        mu = checks.finite_array(mu, "mu")
        if mu.ndim < 1 or mu.shape[-1] < 1:
            raise ValueError(f"mu must have shape (..., n_measurements), got shape {mu.shape}")
        if mu.size == 0:
            raise ValueError(f"mu must hold at least one problem, got an empty batch {mu.shape}")
    batch = mu.shape[:-1]
    rho = checks.finite_array(rho, "rho")
    if rho.ndim and rho.shape != batch:
        raise ValueError(f"rho must be a scalar or have shape {batch}, got shape {rho.shape}")
    if not np.all(rho > 0):
        raise ValueError(f"rho must be positive, got {rho.tolist()}")
    prior_mean = checks.finite_array(prior_mean, "prior_mean")
    if (
        prior_mean.ndim < 1
        or prior_mean.shape[-1] != 3
        or not checks.broadcasts(prior_mean.shape, batch + (3,))
    ):
        allowed = "(3,)" + (f" or {batch + (3,)}" if batch else "")
        raise ValueError(f"prior_mean must have shape {allowed}, got {prior_mean.shape}")
    prior_cov = checks.covariances(prior_cov, "prior_cov", 3)
    if not checks.broadcasts(prior_cov.shape, batch + (3, 3)):
        allowed = "(3, 3)" + (f" or {batch + (3, 3)}" if batch else "")
        raise ValueError(f"prior_cov must have shape {allowed}, got {prior_cov.shape}")
    return mu, rho, prior_mean, prior_cov


def batch_inputs(mu, rho, prior_mean, prior_cov, triples: bool = True):
    """:func:`depthcore.problem.model.batch_problem`, with the priors broadcast to the batch.

    Returns
    -------
    mu : ndarray, shape (..., N) or (..., K)
    rho : ndarray, shape () or (...)
    prior_mean : ndarray, shape (..., 3)
    prior_cov : ndarray, shape (..., 3, 3)
        Read-only broadcast views of the priors.
    """
    mu, rho, prior_mean, prior_cov = batch_problem(mu, rho, prior_mean, prior_cov, triples)
    batch = mu.shape[:-1]
    return (
        mu,
        rho,
        np.broadcast_to(prior_mean, batch + (3,)),
        np.broadcast_to(prior_cov, batch + (3, 3)),
    )
