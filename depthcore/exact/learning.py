"""The noise levels learned from tracks: the bearing and process noise by maximum likelihood.

Recommended import: ``from depthcore.exact import learning``.

Textbook 19.1.2 (learning): the model's parameters, here the bearing noise SD
``rho`` (Eq. (4)) and the process noise SD ``q`` (the velocity's random walk,
:mod:`depthcore.problem.frames`), are estimated from one track or several by
maximising the marginal likelihood of the bearings,

    log p(mu_1 .. mu_N | rho, q) = log integral_{y_1 > 0} N(y_1; m_y, P_yy) L(y_1; rho, q) dy_1,

summed over the tracks (gaps, uneven steps, ``rho_k = rho weights_k``), where
``L(y_1)`` is the Kalman filters' likelihood (:mod:`depthcore.exact.bank`,
textbook 19.2.3), integrated by the depth quadrature of
:mod:`depthcore.exact.posterior`.

Two routes to the same estimate:

* ``method="ml"``: Newton's method on ``log rho`` and ``log q`` (central
  differences) on depth nodes held fixed, re-placed at the estimate until it stays
  put; the observed information gives the standard errors, ``se(rho) = rho se(log rho)``.
* ``method="em"``: EM (textbook Section 7.8) with the depth and trajectory hidden.
  The E-step is :func:`depthcore.exact.e_step.expectations` (the smoother, textbook
  19.2.6); the M-step is
  in closed form (Eq. (4) and the velocity's random walk):

      rho**2 = mean over present frames of E[(mu_k - x_k / y_k)**2] / w_k**2,
      q**2   = mean over steps of E[(v_{k+1} - v_k)**2] / abs(s_k),

  with ``w_k`` the relative noise levels and ``s_k`` the (signed) steps; its fixed point is
  the maximum-likelihood estimate.

When the likelihood does not rise from ``q = 0`` (constant velocity, Eq. (1)) the
estimate is ``q = 0`` at the boundary, with a one-sided upper bound
(:func:`_q_upper`) in place of a standard error.

References
----------
.. [prince2012] S. J. D. Prince, *Computer Vision: Models, Learning, and
   Inference*, chapter 19, sections 19.1.2 (learning) and 19.2.6 (smoothing).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import optimize, stats
from scipy.special import logsumexp

from depthcore.exact import e_step, online
from depthcore.exact import posterior as exact_posterior
from depthcore.exact.bank import lateral_filter, run_bank
from depthcore.problem import checks, frames, predictive
from depthcore.problem.depth_prior import DepthPrior, stand_in

#: The parameters, by name, the bearing noise SD and the process noise SD.
NAMES = ("rho", "process_noise")
#: The methods of :func:`fit`.
METHODS = ("ml", "em")
#: The fewest present bearings a track needs (three fit a constant-velocity track exactly).
MIN_BEARINGS = 4

#: Central-difference step in the log parameters.
_H = 1e-4
#: Newton's method stops when no log parameter moves by more than this.
_STEP_TOL = 1e-7
#: Node placements stop when the estimate moves by less than this between them.
_ROUND_TOL = 1e-6
_MAX_ROUNDS = 10
_MAX_NEWTON = 100
#: The largest Newton step in a log parameter (a factor e**2).
_MAX_STEP = 2.0
#: Starting values of ``q`` tried, as multiples of the prior's velocity SD.
_Q_STARTS = 10.0 ** np.arange(-4.0, 1.0)


class Fit(NamedTuple):
    """The noise levels estimated from tracks (:func:`fit`).

    Attributes
    ----------
    rho : float
    process_noise : float
        The estimates (or given values).
    rho_se : float or None
    process_noise_se : float or None
        Standard errors (delta method); ``None`` if given or at the boundary ``q = 0``.
    rho_interval : tuple or None
    process_noise_interval : tuple or None
        The interval at ``level``: Wald's on the log scale or the profile
        likelihood's; ``(0, upper)`` at the boundary; ``None`` if given.
    log_likelihood : float
        ``log p(mu | rho, q)`` at the estimate, summed over the tracks.
    iterations : int
        Newton steps or EM iterations.
    converged : bool
    method : str
    estimated : tuple of str
        From :data:`NAMES`.
    at_boundary : bool
    covariance : ndarray, shape (p, p)
        The inverse observed information of the estimated log parameters.
    level : float
    note : str
    gated : ndarray of bool, shape (B, N), or None
        With a gate, the bearings it skipped (left out of the fit); ``None`` without one.
    """

    rho: float
    process_noise: float
    rho_se: float | None
    process_noise_se: float | None
    rho_interval: tuple | None
    process_noise_interval: tuple | None
    log_likelihood: float
    iterations: int
    converged: bool
    method: str
    estimated: tuple
    at_boundary: bool
    covariance: np.ndarray
    level: float
    note: str
    gated: np.ndarray | None = None


class _Tracks(NamedTuple):
    """Checked tracks, flattened to ``B`` rows."""

    mu: np.ndarray  # (B, N), NaN at a missing frame
    present: np.ndarray  # (B, N)
    weights: np.ndarray  # (B, N): rho_k = rho * weights_k, 1 at a missing frame
    steps: np.ndarray  # (B, N - 1)
    mean: np.ndarray  # (B, 3)
    cov: np.ndarray  # (B, 3, 3)
    law: DepthPrior | None = None  # in place of the Gaussian (mean, cov its moments)

    @property
    def elapsed(self) -> np.ndarray:
        zero = np.zeros(self.steps.shape[:-1] + (1,))
        return np.concatenate([zero, np.cumsum(self.steps, axis=-1)], axis=-1)

    @property
    def unit_steps(self):
        """The steps, or ``None`` when they are all ones (the paper's frames)."""
        return None if np.all(self.steps == 1.0) else self.steps

    def frame_rho(self, rho: float):
        """The noise SD at every frame, ``rho weights_k`` (B, N), or ``None`` for ``rho`` at all."""
        return None if np.all(self.weights == 1.0) else rho * self.weights


# --- checks ------------------------------------------------------------------------------


def _tracks(mu, prior_mean, prior_cov, steps, weights, law=None) -> _Tracks:
    if law is not None:
        prior_mean, prior_cov = stand_in(law, prior_mean, prior_cov)
    mu = checks.as_float(mu, "mu")
    if mu.ndim not in (1, 2):
        raise ValueError(f"mu must have shape (N,) or (B, N), got shape {mu.shape}")
    mu = np.atleast_2d(mu)
    if weights is not None:
        weights = checks.as_float(weights, "weights")
        if weights.shape not in (mu.shape[-1:], mu.shape):
            raise ValueError(
                f"weights must have shape ({mu.shape[-1]},) or {mu.shape}, got {weights.shape}"
            )
        weights = np.broadcast_to(weights, mu.shape)
        if not np.all(np.isnan(mu) | (np.isfinite(weights) & (weights > 0))):
            raise ValueError("weights must be finite and positive at every present frame")
    track = frames.check(mu, 1.0 if weights is None else weights, steps)
    B = mu.shape[0]
    prior_mean = checks.finite_array(prior_mean, "prior_mean")
    if prior_mean.shape not in ((3,), (B, 3)):
        raise ValueError(f"prior_mean must have shape (3,) or ({B}, 3), got {prior_mean.shape}")
    prior_cov = checks.finite_array(prior_cov, "prior_cov")
    if prior_cov.shape not in ((3, 3), (B, 3, 3)):
        raise ValueError(f"prior_cov must have shape (3, 3) or ({B}, 3, 3), got {prior_cov.shape}")
    prior_cov = checks.covariances(prior_cov, "prior_cov", 3)
    return _Tracks(
        mu=track.mu,
        present=track.present,
        weights=np.array(track.rho),
        steps=np.array(track.steps),
        mean=np.broadcast_to(prior_mean, (B, 3)).copy(),
        cov=np.broadcast_to(prior_cov, (B, 3, 3)).copy(),
        law=law,
    )


def _level(level) -> float:
    level = checks.number(level, "level")
    if not 0.5 <= level < 1.0:
        raise ValueError(f"level must be in [0.5, 1), got {level!r}")
    return level


# --- the likelihood ----------------------------------------------------------------------


def _place(tracks: _Tracks, rho: float, q: float, rtol: float, history: bool = False):
    """The exact posterior of every track at ``(rho, q)``, nodes placed by the depth quadrature."""
    frame_rho = tracks.frame_rho(rho)
    return exact_posterior.posterior(
        tracks.mu,
        rho if frame_rho is None else frame_rho,
        tracks.mean,
        tracks.cov,
        q,
        rtol=rtol,
        history=history,
        steps=tracks.unit_steps,
        law=tracks.law,
    )


def _on_nodes(tracks: _Tracks, nodes, log_w, rho: float, q: float) -> float:
    """``sum_b log sum_j w_bj N(y_j; m_y, P_yy) L(y_j)`` on fixed nodes and log weights (B, J)."""
    frame_rho = tracks.frame_rho(rho)
    log_weight = lateral_filter(
        nodes,
        tracks.mu,
        np.asarray(rho),
        np.asarray(q),
        tracks.mean,
        tracks.cov,
        tracks.unit_steps,
        frame_rho,
        tracks.law,
    )[0]
    return float(np.sum(logsumexp(log_w + log_weight, axis=-1)))


def log_likelihood(
    mu,
    prior_mean,
    prior_cov,
    rho,
    process_noise=0.0,
    steps=None,
    weights=None,
    rtol=1e-10,
    law=None,
) -> float:
    """``log p(mu | rho, q)`` summed over the tracks (module docstring, textbook 19.1.2).

    The arguments are :func:`fit`'s, with ``rho`` (> 0) and ``process_noise`` (>= 0) given.
    """
    tracks = _tracks(mu, prior_mean, prior_cov, steps, weights, law)
    rho = checks.positive_scalar(rho, "rho")
    q = checks.process_noise(process_noise)
    rtol = checks.positive_scalar(rtol, "rtol")
    return float(np.sum(_place(tracks, rho, q, rtol).log_normaliser))


# --- Newton's method on fixed nodes ------------------------------------------------------


def _derivatives(f, theta):
    """``f``, its gradient and Hessian at ``theta`` (p,) by central differences of step ``_H``."""
    p = theta.size
    f0 = f(theta)
    e = np.eye(p) * _H
    plus = np.array([f(theta + e[i]) for i in range(p)])
    minus = np.array([f(theta - e[i]) for i in range(p)])
    g = (plus - minus) / (2.0 * _H)
    H = np.diag((plus - 2.0 * f0 + minus) / _H**2)
    for i in range(p):
        for j in range(i + 1, p):
            d = (
                f(theta + e[i] + e[j])
                - f(theta + e[i] - e[j])
                - f(theta - e[i] + e[j])
                + f(theta - e[i] - e[j])
            ) / (4.0 * _H**2)
            H[i, j] = H[j, i] = d
    return f0, g, H


def _newton(f, theta):
    """Maximise ``f`` from ``theta`` (p,) by Newton steps: ``theta, f, H, steps, settled``."""
    theta = np.array(theta, dtype=float)
    for it in range(1, _MAX_NEWTON + 1):
        f0, g, H = _derivatives(f, theta)
        # Newton's step on -H with its eigenvalues' absolute values: an ascent direction
        lam, V = np.linalg.eigh(-H)
        lam = np.maximum(np.abs(lam), 1e-8 * max(float(np.max(np.abs(lam))), 1e-300))
        d = V @ ((V.T @ g) / lam)
        d *= min(1.0, _MAX_STEP / max(float(np.max(np.abs(d))), 1e-300))
        t = 1.0
        for _ in range(40):
            new = theta + t * d
            f1 = f(new)
            if f1 >= f0 - 1e-12 * abs(f0):
                break
            t /= 2.0
        else:
            return theta, f0, H, it, True  # no ascent left at this precision
        moved = float(np.max(np.abs(new - theta)))
        theta = new
        if moved <= _STEP_TOL:
            return theta, f1, H, it, True
    return theta, f(theta), _derivatives(f, theta)[2], _MAX_NEWTON, False


class _Problem:
    """The log-likelihood as a function of the estimated log parameters."""

    def __init__(self, tracks, rho, q, free, rtol):
        self.tracks, self.free, self.rtol = tracks, free, rtol
        self.fixed = {"rho": rho, "process_noise": q}

    def values(self, theta):
        v = dict(self.fixed)
        for name, t in zip(self.free, theta, strict=True):
            v[name] = float(np.exp(t))
        return v["rho"], v["process_noise"]

    def on_nodes(self, rho, q):
        post = _place(self.tracks, rho, q, self.rtol)
        nodes, log_w = post.bank.nodes, post.log_weights
        return lambda theta: _on_nodes(self.tracks, nodes, log_w, *self.values(theta))

    def maximise(self, theta):
        """Newton on fixed nodes, nodes re-placed at the estimate until it stays put."""
        theta = np.array(theta, dtype=float)
        steps, converged = 0, False
        for _ in range(_MAX_ROUNDS):
            f = self.on_nodes(*self.values(theta))
            new, value, H, it, ok = _newton(f, theta)
            steps += it
            moved = float(np.max(np.abs(new - theta))) if theta.size else 0.0
            theta = new
            if moved <= _ROUND_TOL:
                converged = ok
                break
        return theta, value, H, steps, converged, f


# --- the fit -----------------------------------------------------------------------------


def _rho_start(tracks: _Tracks) -> float:
    """A rough ``rho``: the RMS second difference of the bearings over ``sqrt(6)``."""
    d2 = np.diff(tracks.mu, n=2, axis=-1) / tracks.weights[..., 1:-1]
    d2 = d2[np.isfinite(d2)]
    value = float(np.sqrt(np.mean(d2**2) / 6.0)) if d2.size else 0.0
    return value if value > 0 else 1e-3


def _q_scale(tracks: _Tracks) -> float:
    return float(np.sqrt(np.mean(tracks.cov[:, 2, 2])))


def _known(value, name):
    if value is None:
        return None
    if name == "rho":
        return checks.positive_scalar(value, "rho")
    return checks.process_noise(value, name)


def _enough(tracks: _Tracks, free):
    most = int(np.max(np.sum(tracks.present, axis=-1)))
    if most < MIN_BEARINGS:
        name = ", ".join(free)
        raise ValueError(
            f"{name}: estimating it needs a track with at least {MIN_BEARINGS} bearings "
            f"present (three fit any constant-velocity track exactly), got at most {most}"
        )


def fit(
    mu,
    prior_mean,
    prior_cov,
    rho=None,
    process_noise=None,
    steps=None,
    weights=None,
    method: str = "ml",
    intervals: str = "profile",
    level: float = 0.95,
    rtol: float = 1e-10,
    tol: float = 1e-10,
    max_iter: int = 2000,
    gate=None,
    law=None,
) -> Fit:
    """Estimate the bearing noise ``rho`` and/or the process noise ``q`` from tracks (19.1.2).

    Parameters
    ----------
    mu : array_like, shape (N,) or (B, N)
        ``NaN``: a missing frame.
    prior_mean : array_like, shape (3,) or (B, 3)
    prior_cov : array_like, shape (3, 3) or (B, 3, 3)
    rho : float or None
        ``None`` to estimate it.
    process_noise : float or None
        ``q``: ``None`` to estimate it.
    steps : array_like, shape (N - 1,) or (B, N - 1), optional
    weights : array_like, shape (N,) or (B, N), optional
        The frames' relative noise levels, ``rho_k = rho weights_k``.
    method : {"ml", "em"}
        See the module docstring.
    intervals : {"profile", "wald"}
        The profile likelihood's interval (default): where the likelihood stays
        within the chi-squared quantile down to ``q = 0`` its lower end is 0, so it
        covers a process noise at the boundary; or Wald's on the log scale.
    level : float
        In [0.5, 1).
    rtol : float
        The depth quadrature's tolerance.
    tol, max_iter
        EM's tolerance in the log parameters and most iterations.
    gate : float or None
        Skip outliers while learning (:mod:`depthcore.problem.predictive`): the exact
        filter at the estimate reports each bearing's tail probability; those below
        ``gate`` are left out and the noise levels fitted again, until no more are
        skipped (:attr:`Fit.gated`), so that an outlier does not inflate ``rho``.
    law : depthcore.problem.depth_prior.DepthPrior, optional
        A prior with any law of the depth in place of the Gaussian (``prior_mean`` and
        ``prior_cov`` then ``None`` or its moments), as the exact filter takes it.

    Returns
    -------
    Fit

    Raises
    ------
    ValueError
        Nothing to estimate, too few bearings, invalid arguments.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if intervals not in ("wald", "profile"):
        raise ValueError(f"intervals must be 'wald' or 'profile', got {intervals!r}")
    level = _level(level)
    rtol = checks.positive_scalar(rtol, "rtol")
    tol = checks.positive_scalar(tol, "tol")
    max_iter = checks.count(max_iter, "max_iter")
    tracks = _tracks(mu, prior_mean, prior_cov, steps, weights, law)
    rho_k, q_k = _known(rho, "rho"), _known(process_noise, "process_noise")
    free = tuple(n for n, v in zip(NAMES, (rho_k, q_k), strict=True) if v is None)
    if not free:
        raise ValueError("rho, process_noise: both are given; give None for one to estimate it")
    _enough(tracks, free)
    gate = predictive.gate(gate)

    def fitted(tracks):
        if method == "em":
            return _fit_em(tracks, rho_k, q_k, free, level, intervals, rtol, tol, max_iter)
        return _fit_ml(tracks, rho_k, q_k, free, level, intervals, rtol)

    result = fitted(tracks)
    if gate is None:
        return result
    skipped = np.zeros(tracks.mu.shape, dtype=bool)
    for _ in range(_GATE_ROUNDS):
        post = _place(tracks, result.rho, result.process_noise, rtol)
        new = online.track_updates(post.bank, gate, rtol).gated
        if not np.any(new):
            break
        skipped |= new
        mu = np.where(skipped, np.nan, tracks.mu)
        tracks = tracks._replace(mu=mu, present=~np.isnan(mu))
        few = np.sum(tracks.present, axis=-1) < frames.MIN_PRESENT
        if np.any(few):
            raise ValueError(
                f"gate: at {gate:g} it leaves track {int(np.argmax(few))} with fewer than "
                f"{frames.MIN_PRESENT} bearings; give a smaller gate or none"
            )
        _enough(tracks, free)
        result = fitted(tracks)
    note = f"{result.note}; the gate at {gate:g} skipped {int(skipped.sum())} bearings"
    return result._replace(gated=skipped, note=note)


#: The most rounds of fitting and gating (each skips at least one more bearing).
_GATE_ROUNDS = 10


def _fit_ml(tracks, rho_k, q_k, free, level, intervals, rtol) -> Fit:
    rho0 = _rho_start(tracks) if rho_k is None else rho_k
    if "process_noise" not in free:
        pr = _Problem(tracks, rho0, q_k, free, rtol)
        theta, _, H, it, ok, f = pr.maximise(np.log([rho0]))
        return _result(pr, theta, H, f, it, ok, "ml", level, intervals, False)
    # q free: first q = 0, then whether the likelihood rises from there
    rest = tuple(n for n in free if n != "process_noise")
    pr0 = _Problem(tracks, rho0, 0.0, rest, rtol)
    it0, ok0 = 0, True
    if rest:
        theta0, _, H0, it0, ok0, f0 = pr0.maximise(np.log([rho0]))
    else:
        theta0, H0, f0 = np.zeros(0), np.zeros((0, 0)), pr0.on_nodes(rho0, 0.0)
    rho_hat0 = pr0.values(theta0)[0]
    pr = _Problem(tracks, rho_hat0 if rho_k is None else rho_k, None, free, rtol)
    g = pr.on_nodes(rho_hat0, 0.0)
    base = np.log([rho_hat0]) if rest else np.zeros(0)
    ell0 = f0(theta0)
    scale = _q_scale(tracks)
    starts = [np.concatenate([base, [np.log(c * scale)]]) for c in _Q_STARTS]
    values = [g(s) for s in starts]
    best = int(np.argmax(values))
    if values[best] > ell0 + 1e-9 * max(1.0, abs(ell0)):
        theta, ell, H, it, ok, f = pr.maximise(starts[best])
        if ell > ell0 and np.exp(theta[-1]) > 1e-8 * scale:
            return _result(pr, theta, H, f, it0 + it, ok, "ml", level, intervals, False)
    # the boundary: q = 0
    pr0.fixed["rho"] = rho_hat0
    return _boundary(pr0, theta0, H0, f0, it0, ok0, level, intervals, tracks, rho_k, rtol)


def _result(pr, theta, H, f, iterations, converged, method, level, intervals, boundary) -> Fit:
    rho, q = pr.values(theta)
    try:
        cov = np.linalg.inv(-H) if theta.size else np.zeros((0, 0))
        se_log = np.sqrt(np.diag(cov)) if np.all(np.diag(cov) > 0) else None
    except np.linalg.LinAlgError:
        cov, se_log = np.full_like(H, np.inf), None
    ses, ints = {}, {}
    z = float(stats.norm.ppf(0.5 + level / 2.0))
    for i, name in enumerate(pr.free):
        value = float(np.exp(theta[i]))
        if se_log is None:
            ses[name], ints[name] = None, None
            continue
        ses[name] = value * float(se_log[i])
        if intervals == "wald":
            ints[name] = (
                value * float(np.exp(-z * se_log[i])),
                value * float(np.exp(z * se_log[i])),
            )
        else:
            ints[name] = _profile(pr, f, theta, i, level, float(se_log[i]))
    ell = float(f(theta))  # on nodes placed within _ROUND_TOL of the estimate
    estimated = tuple(pr.free)
    words = ", ".join(f"{n} = {v:.6g}" for n, v in zip(NAMES, (rho, q), strict=True))
    note = (
        f"{method.upper()} estimate of {', '.join(estimated)} from {pr.tracks.mu.shape[0]} "
        f"track(s): {words}" + ("" if converged else "; not converged")
    )
    return Fit(
        rho=rho,
        process_noise=q,
        rho_se=ses.get("rho"),
        process_noise_se=ses.get("process_noise"),
        rho_interval=ints.get("rho"),
        process_noise_interval=ints.get("process_noise"),
        log_likelihood=ell,
        iterations=int(iterations),
        converged=bool(converged),
        method=method,
        estimated=estimated,
        at_boundary=boundary,
        covariance=cov,
        level=level,
        note=note,
    )


def _boundary(pr0, theta0, H0, f0, iterations, converged, level, intervals, tracks, rho_k, rtol):
    """The fit with ``q = 0`` at the boundary, with its one-sided upper bound on ``q``."""
    base = _result(pr0, theta0, H0, f0, iterations, converged, "ml", level, intervals, True)
    upper = _q_upper(pr0, theta0, f0, level, tracks)
    bound = "no finite bound found" if upper is None else f"q <= {upper:.6g}"
    return base._replace(
        estimated=(*pr0.free, "process_noise"),
        process_noise_interval=None if upper is None else (0.0, upper),
        note=(
            f"ML estimate q = 0 at the boundary (the likelihood does not rise from constant "
            f"velocity), one-sided {level:g} bound {bound}; rho = {base.rho:.6g}"
        ),
    )


def _q_upper(pr0, theta0, f0, level, tracks):
    """The one-sided upper bound on ``q`` at the boundary ``q = 0``.

    Where the profile log-likelihood of ``q`` falls ``c / 2`` below its value at
    ``q = 0``, ``c`` the ``2 level - 1`` quantile of chi-squared with one degree of
    freedom (the boundary's 50:50 mixture); ``None`` if it does not.
    """
    c = float(stats.chi2.ppf(2.0 * level - 1.0, 1))
    target = f0(theta0) - c / 2.0
    rho_hat = pr0.values(theta0)[0]
    pr = _Problem(tracks, rho_hat, None, (*pr0.free, "process_noise"), pr0.rtol)
    g = pr.on_nodes(rho_hat, 0.0)

    def profile(log_q):
        if not pr0.free:
            return g(np.array([log_q]))
        return _newton(lambda t: g(np.array([t[0], log_q])), theta0)[1]

    scale = _q_scale(tracks)
    lo, hi = np.log(1e-8 * scale), np.log(scale) - 4.0
    while profile(hi) > target:
        hi += 2.0
        if hi > np.log(scale) + 12.0:
            return None
    return float(np.exp(optimize.brentq(lambda t: profile(t) - target, lo, hi, xtol=1e-10)))


def _profile(pr, f, theta, i, level, se):
    """The profile-likelihood interval of parameter ``i`` at ``level`` on fixed nodes ``f``."""
    c = float(stats.chi2.ppf(level, 1))
    top = f(theta)
    others = [j for j in range(theta.size) if j != i]

    def profile(t):
        if not others:
            return f(np.array([t]))
        start = theta[others]

        def inner(u):
            th = theta.copy()
            th[i], th[others] = t, u
            return f(th)

        return _newton(inner, start)[1]

    ends = []
    for sign in (-1.0, 1.0):
        width = 2.0 * max(se, 1e-6)
        while profile(theta[i] + sign * width) > top - c / 2.0:
            width *= 2.0
            if width > 40.0:
                break
        edge = theta[i] + sign * width
        if profile(edge) > top - c / 2.0:
            ends.append(0.0 if sign < 0 else np.inf)
            continue
        t = optimize.brentq(lambda t: profile(t) - (top - c / 2.0), theta[i], edge, xtol=1e-10)
        ends.append(float(np.exp(t)))
    return tuple(ends)


# --- EM -----------------------------------------------------------------------------------


#: EM re-places the depth nodes when a parameter has moved by this (in log) since placed.
_EM_REPLACE = 0.05


def _fit_em(tracks, rho_k, q_k, free, level, intervals, rtol, tol, max_iter) -> Fit:
    """EM from a rough start; the E-step on depth nodes placed at recent parameters.

    The nodes are re-placed after a move of :data:`_EM_REPLACE` and when EM settles,
    so it stops only on nodes placed at its estimate.
    """
    rho = _rho_start(tracks) if rho_k is None else rho_k
    q = (0.1 * _q_scale(tracks)) if q_k is None else q_k
    n_frames = int(np.sum(tracks.present))
    n_steps = int(tracks.steps.size)
    converged, it, anchor, fresh = False, 0, None, False
    while it < max_iter:
        it += 1
        here = np.log([rho, q if q > 0 else 1.0])
        if anchor is None or np.max(np.abs(here - anchor)) > _EM_REPLACE:
            post = _place(tracks, rho, q, rtol)
            nodes, log_w, anchor, fresh = post.bank.nodes, post.log_weights, here, True
        frame_rho = tracks.frame_rho(rho)
        bank = run_bank(
            nodes,
            tracks.mu,
            np.asarray(rho) if frame_rho is None else frame_rho,
            np.asarray(q),
            tracks.mean,
            tracks.cov,
            True,
            tracks.unit_steps,
            frame_rho,
            tracks.law,
        )
        meas, motion = e_step.expectations(bank, log_w, tracks)
        new_rho = float(np.sqrt(np.sum(meas) / n_frames)) if rho_k is None else rho
        new_q = float(np.sqrt(np.sum(motion) / n_steps)) if q_k is None else q
        moved = max(abs(np.log(new_rho / rho)), abs(np.log(new_q / q)) if q_k is None else 0.0)
        rho, q = new_rho, new_q
        if moved <= tol:
            if fresh:
                converged = True
                break
            anchor = None  # settled on old nodes: once more on nodes placed here
        fresh = False
    pr = _Problem(tracks, rho, q, free, rtol)
    theta = np.log([{"rho": rho, "process_noise": q}[n] for n in free])
    f = pr.on_nodes(rho, q)
    H = _derivatives(f, theta)[2]
    return _result(pr, theta, H, f, it, converged, "em", level, intervals, False)
