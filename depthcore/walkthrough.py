"""Small computations the book's pages show beside the paper's equations.

Recommended import: ``from depthcore import walkthrough``.

The book's pages hold no function definitions; what they compute beyond a call
into :mod:`depthcore.model`, :mod:`depthcore.optimal`,
:mod:`depthcore.second_order` or :mod:`depthcore.ekf` lives here, tested in
``tests/test_walkthrough.py``:

* :func:`vec`: a vector formatted as the book prints it;
* :func:`bayes_filter`: the recursion (2) with (3) and (4) run literally, one
  prediction (Chapman-Kolmogorov) and one measurement update (Bayes' rule)
  per measurement, as an independent route to the optimal density (6);
* :func:`numerical_gradient`, :func:`numerical_hessian`: central differences,
  to check the observation vector (11) and the Hessian ``J`` of (8);
* :func:`eq16_printed`, :func:`prior_exponent`, :func:`log_gaussian_integral_brute`:
  the pieces of the derivation of Eq. (16);
* :func:`theorem1_precision`: the inverse covariance of Eq. (24);
* :func:`trapezoid_depth_moments`: the depth moments by one trapezoid rule;
* :func:`depth_quantiles`: quantiles of the optimal depth marginal;
* :func:`filter_moments`, :func:`comparison`, :func:`comparison_texts`: the
  reported-versus-reproduced tables of the figure pages.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from . import _checks, model, optimal
from .ekf import ekf
from .gaussian import Gaussian
from .reproduce import reproduce
from .scenarios import REPORTED_DECIMALS, Scenario
from .second_order import noise_free_state, second_order

LogDensity = Callable[[np.ndarray], np.ndarray]

#: Rows of the figure pages' tables: (row id, filter, reading, support, label).
#: The optimal filter with Eq. (16) as derived and as printed; the second-order
#: filter with the covariance ``2 rho**2 J^{-1}`` of the expansion (8) and with
#: the printed ``rho**2 J^{-1}``; the EKF.
TABLE_ROWS = (
    ("opt", "optimal", "derived", "front", "optimal $p_o$"),
    ("opt_printed", "optimal", "printed", "front", "optimal, Eq. (16) as printed"),
    ("so", "second_order", "derived", "all", r"second order $p_s$, $2\rho^2 J^{-1}$"),
    ("so_printed", "second_order", "printed", "all", r"second order, $\rho^2 J^{-1}$ as printed"),
    ("ekf", "ekf", "printed", "all", "EKF $p_e$"),
)

#: Decimal places of the reproduced means and SDs in the book's tables.
DECIMALS = 4


def vec(values, decimals: int = 4) -> str:
    """A vector as the book prints it: ``"(1.2000, 6.0000, 1.2000)"``.

    Rounds first, so that a value that rounds to zero prints as ``0.0000``,
    never ``-0.0000``.

    Parameters
    ----------
    values : array_like, shape (n,)
    decimals : int
        Places after the decimal point, >= 0.
    """
    values = _checks.finite_array(values, "values")
    if values.ndim != 1:
        raise ValueError(f"values must be 1-D, got shape {values.shape}")
    if int(decimals) != decimals or decimals < 0:
        raise ValueError(f"decimals must be a non-negative integer, got {decimals!r}")
    decimals = int(decimals)
    return "(" + ", ".join(f"{v + 0.0:.{decimals}f}" for v in np.round(values, decimals)) + ")"


def bayes_filter(mu, rho: float, prior: Gaussian) -> list[LogDensity]:
    """Eqs. (2)-(4): the filtering densities after each measurement, by the recursion.

    Each step is a prediction and a measurement update. With the deterministic
    motion (3) the Chapman-Kolmogorov integral of the prediction collapses to
    ``p(x_k | I^{k-1}) = p(G^{-1} x_k | I^{k-1}) / |det F|`` with
    ``det F = 1``; the update multiplies by the likelihood (4) (Bayes' rule,
    up to the normalising constant ``c`` of (2)).

    Parameters
    ----------
    mu : array_like, shape (k,)
        Measurements ``mu_1 .. mu_k`` in time order.
    rho : float
        Noise standard deviation, > 0.
    prior : Gaussian
        Density of the state at time 1 before the first measurement.

    Returns
    -------
    list of callables
        Entry ``i`` maps states of shape ``(..., 3)`` at time ``i + 1`` to the
        unnormalised ``log p(x_{i+1} | I^{i+1})``, shape ``(...)``.
    """
    rho = _checks.positive_scalar(rho, "rho")
    mu = _checks.finite_array(mu, "mu")
    if mu.ndim != 1 or mu.size == 0:
        raise ValueError(f"mu must be a non-empty 1-D array, got shape {mu.shape}")
    log_det_F = float(np.log(abs(np.linalg.det(model.F))))
    densities: list[LogDensity] = []
    predicted: LogDensity = prior.logpdf  # p(x_1 | I^0)
    for k, mu_k in enumerate(mu.tolist()):
        if k:
            # Prediction: the integral of (2) with the delta (3).
            predicted = (lambda x, prev=densities[-1]: prev(model.G(x, -1)) - log_det_F)
        # Measurement update: Bayes' rule with the likelihood (4).
        densities.append(lambda x, pred=predicted, m=mu_k: model.log_likelihood(m, x, rho) + pred(x))
    return densities


def numerical_gradient(fun: Callable, x, step: float = 1e-6) -> np.ndarray:
    """Central-difference gradient of a scalar function of a state.

    Parameters
    ----------
    fun : callable
        Maps an array of shape ``(3,)`` to a float.
    x : array_like, shape (n,)
    step : float
        Difference step, > 0; the error is ``O(step**2)``.

    Returns
    -------
    ndarray, shape (n,)
    """
    x = _checks.finite_array(x, "x")
    step = _checks.positive_scalar(step, "step")
    eye = np.eye(x.size) * step
    return np.array([(fun(x + d) - fun(x - d)) / (2.0 * step) for d in eye])


def numerical_hessian(fun: Callable, x, step: float = 1e-4) -> np.ndarray:
    """Central-difference Hessian of a scalar function of a state.

    Uses ``(f(x+a+b) - f(x+a-b) - f(x-a+b) + f(x-a-b)) / (4 step**2)`` for the
    steps ``a, b`` along two axes; the error is ``O(step**2)``.

    Returns
    -------
    ndarray, shape (n, n)
        Symmetric.
    """
    x = _checks.finite_array(x, "x")
    step = _checks.positive_scalar(step, "step")
    eye = np.eye(x.size) * step
    H = np.array([[(fun(x + a + b) - fun(x + a - b) - fun(x - a + b) + fun(x - a - b))
                   / (4.0 * step**2) for b in eye] for a in eye])
    return 0.5 * (H + H.T)


def eq16_printed(coefficients) -> np.ndarray:
    """Eq. (16) as printed: ``log(exp(l^T M^{-1} l / 8) / sqrt(det M))`` from ``A .. E``.

    Parameters
    ----------
    coefficients : array_like, shape (n, 5)
        Columns ``A, B, C, D, E`` of Eq. (14) at ``n`` depths
        (:func:`depthcore.optimal.quadratic_coefficients`).

    Returns
    -------
    ndarray, shape (n,)
        The log of the printed ``p_oy`` without its constant ``c``.
    """
    A, B, C, D, E = np.asarray(coefficients, dtype=float).T
    det_M = A * C - B**2 / 4.0  # Eq. (15): M = [[A, B/2], [B/2, C]]
    # l^T M^{-1} l with M^{-1} = [[C, -B/2], [-B/2, A]] / det M, l = (D, E)
    quad = (C * D**2 - B * D * E + A * E**2) / det_M
    return quad / 8.0 - 0.5 * np.log(det_M)


def prior_exponent(y, mu, rho: float, prior: Gaussian) -> np.ndarray:
    """``K(y)``: the part of the exponent of (6) at depth ``y`` free of ``x`` and ``v``.

    At fixed ``y`` the log posterior (6) is
    ``-1/2 (A x**2 + B x v + C v**2 + D x + E v) - 1/2 K(y)`` up to a constant;
    ``K(y)`` is minus twice its value at ``x = v = 0``. Eq. (14) leaves it out.

    Parameters
    ----------
    y : array_like, shape (n,)
    mu, rho, prior
        As in :func:`depthcore.optimal.log_posterior`.

    Returns
    -------
    ndarray, shape (n,)
        ``K(y)``, up to an additive constant.
    """
    y = np.atleast_1d(_checks.finite_array(y, "y"))
    x = np.stack([np.zeros_like(y), y, np.zeros_like(y)], -1)
    return -2.0 * optimal.log_posterior(x, mu, rho, prior)


def log_gaussian_integral_brute(M, l, n: int = 801, width: float = 12.0) -> float:
    """``log`` of the integral of ``exp(-1/2 (u^T M u + l^T u))`` over the plane, by brute force.

    A tensor trapezoid rule on an ``n x n`` grid covering ``width`` standard
    deviations either side of the maximum along each principal axis: an
    independent check of the closed form ``2 pi exp(l^T M^{-1} l / 8) / sqrt(det M)``.

    Parameters
    ----------
    M : array_like, shape (2, 2)
        Symmetric positive definite, Eq. (15).
    l : array_like, shape (2,)
    n : int
        Grid points per axis.
    width : float
        Half-width of the grid in standard deviations.

    Returns
    -------
    float
    """
    M = _checks.covariance(M, "M", 2)
    l = _checks.finite_array(l, "l", (2,))
    vals, vecs = np.linalg.eigh(M)
    axes = vecs / np.sqrt(vals)  # columns: principal axes scaled to one SD
    s = np.linspace(-width, width, n)
    S = np.stack(np.meshgrid(s, s, indexing="ij"), -1)
    # The grid sits on the maximum; where it sits does not change the integral.
    centre = -0.5 * np.linalg.solve(M, l)
    u = centre + S @ axes.T
    exponent = -0.5 * (np.einsum("...i,ij,...j->...", u, M, u) + u @ l)
    top = float(np.max(exponent))
    h = s[1] - s[0]
    w = np.full(n, h)
    w[[0, -1]] *= 0.5
    total = float(np.einsum("i,j,ij->", w, w, np.exp(exponent - top)))
    return top + np.log(total) + float(np.log(abs(np.linalg.det(axes))))


def theorem1_precision(mu, rho: float, prior: Gaussian) -> np.ndarray:
    """Eq. (24): ``D^{-1}``, the inverse covariance of ``p_s`` written with EKF vectors.

    ``D^{-1} = (1/rho**2) sum_k (F^{k-3})^T h_k h_k^T F^{k-3} + (F^{-2})^T P^{-1} F^{-2}``,
    with ``h_k`` the observation vector (11) at ``G^{k-3} c``, the EKF's
    predicted mean at time ``k`` when the prior mean is ``G^{-2} c`` (Eq. (19)),
    and ``F^{k-3}`` the linear part of ``G^{k-3}``.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    rho = _checks.positive_scalar(rho, "rho")
    c = noise_free_state(mu)
    precision = np.zeros((3, 3))
    for k in (1, 2, 3):
        row = model.observation_vector(model.G(c, k - 3)) @ model.G_linear(k - 3)
        precision += np.outer(row, row) / rho**2
    F2 = model.G_linear(-2)
    return precision + F2.T @ np.linalg.solve(prior.cov, F2)


def depth_quantiles(m: optimal.OptimalMarginals, probs, n: int = 20001) -> np.ndarray:
    """Quantiles of the optimal depth marginal ``p_oy`` (support ``y > 2``).

    The cumulative distribution is the trapezoid rule on a grid uniform in
    ``t = log(y - 2)`` from ``y - 2 = 1e-4`` to ``50 * (E y + 10 sd)``,
    inverted by linear interpolation.

    Parameters
    ----------
    m : OptimalMarginals
        From :func:`depthcore.optimal.marginals` with ``support="front"``.
    probs : array_like
        Probabilities in (0, 1).
    n : int
        Grid points.

    Returns
    -------
    ndarray, shape of ``probs``
    """
    if m.support != "front":
        raise ValueError(f"depth_quantiles needs support='front', got {m.support!r}")
    probs = _checks.finite_array(probs, "probs")
    if np.any((probs <= 0) | (probs >= 1)):
        raise ValueError(f"probs must lie in (0, 1), got {probs.tolist()}")
    t = np.linspace(np.log(1e-4), np.log(50.0 * (m.depth_mean + 10.0 * m.depth_sd)), n)
    d = np.exp(t)
    integrand = m.depth_pdf(2.0 + d) * d
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(t))])
    if not abs(cdf[-1] - 1.0) < 1e-6:
        raise RuntimeError(f"the depth marginal integrates to {cdf[-1]:.8f} on the grid, not 1")
    return np.interp(probs, cdf / cdf[-1], 2.0 + d)


def trapezoid_depth_moments(mu, rho: float, prior: Gaussian, step: float,
                            t_range=(-8.0, 8.0), reading: str = "derived") -> tuple[float, float, int]:
    """Mean and SD of the optimal depth marginal by one trapezoid rule of a given step.

    The rule is applied in ``t = log(y - 2)`` (support ``y > 2``) on the nodes
    ``t_lo, t_lo + step, ...`` up to ``t_hi``, to the closed form of
    :func:`depthcore.optimal.conditional` times the Jacobian ``dy/dt = e^t``.
    This is the rule :func:`depthcore.optimal.marginals` refines by halving
    its step; with a fixed step it shows how fast the rule converges.

    Parameters
    ----------
    mu, rho, prior
        As in :func:`depthcore.optimal.log_posterior`.
    step : float
        Node spacing in ``t``, > 0.
    t_range : (float, float)
        First and last node; the default covers ``y - 2`` from 3e-4 to 3e3.
    reading : {"derived", "printed"}

    Returns
    -------
    mean, sd : float
    n_nodes : int
    """
    step = _checks.positive_scalar(step, "step")
    t_lo, t_hi = (float(t) for t in _checks.finite_array(t_range, "t_range", (2,)))
    if not t_hi > t_lo:
        raise ValueError(f"t_range must be increasing, got {(t_lo, t_hi)}")
    t = np.arange(t_lo, t_hi + step / 2, step)
    y = 2.0 + np.exp(t)
    log_w = optimal.conditional(y, mu, rho, prior, reading)[0] + t
    w = np.exp(log_w - np.max(log_w))
    mean = float(np.sum(w * y) / np.sum(w))
    return mean, float(np.sqrt(np.sum(w * (y - mean) ** 2) / np.sum(w))), int(t.size)


def filter_moments(s: Scenario, quantity: str | None = None) -> dict:
    """Mean and SD of each filter's marginal for a scenario (the code's default readings).

    Parameters
    ----------
    s : Scenario
    quantity : {"depth", "velocity"}, optional
        Defaults to the one the paper plots for ``s``.

    Returns
    -------
    dict
        ``{"optimal": (mean, sd), "second_order": (mean, sd), "ekf": (mean, sd)}``.
    """
    quantity = quantity or s.quantity
    if quantity not in ("depth", "velocity"):
        raise ValueError(f"quantity must be 'depth' or 'velocity', got {quantity!r}")
    prior = s.prior
    m = optimal.marginals(s.mu, s.rho, prior)
    comp = {"depth": "y", "velocity": "v"}[quantity]
    return {
        "optimal": ((m.depth_mean, m.depth_sd) if quantity == "depth"
                    else (m.velocity_mean, m.velocity_sd)),
        "second_order": second_order(s.mu, s.rho, prior).marginal(comp),
        "ekf": ekf(s.mu, s.rho, prior).posterior.marginal(comp),
    }


def comparison(key: str) -> list[dict]:
    """The rows of a figure page's table: the paper's numbers beside ours.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.

    Returns
    -------
    list of dict
        One per entry of :data:`TABLE_ROWS`, with ``id``, ``label``,
        ``quantity``, ``mean``, ``sd``, ``reported_mean``, ``reported_sd``
        (``None`` where the paper prints nothing), ``mean_matches`` and
        ``sd_matches`` (agreement at the paper's printed precision, or ``None``).
    """
    (sc,) = reproduce([key])["scenarios"]
    quantity = {"fig4": "velocity"}.get(key, "depth")
    out = []
    for row_id, filt, reading, support, label in TABLE_ROWS:
        (row,) = [r for r in sc["rows"] if (r["filter"], r["reading"], r["support"], r["quantity"])
                  == (filt, reading, support, quantity)]
        out.append({"id": row_id, "label": label, "quantity": quantity,
                    **{k: row[k] for k in ("mean", "sd", "reported_mean", "reported_sd",
                                           "mean_matches", "sd_matches")}})
    return out


def comparison_texts(key: str, rows: list[dict]) -> dict[str, str]:
    """The numbers of :func:`comparison` as the strings the book shows, keyed for glue.

    Keys are ``f"{key}_{row id}_{field}"`` with fields ``mean``, ``sd`` (ours,
    :data:`DECIMALS` places), ``paper_mean``, ``paper_sd`` (the paper's
    precision, or an em dash where it prints nothing) and ``agrees``.
    """
    texts = {}
    for row in rows:
        name = f"{key}_{row['id']}"
        texts[f"{name}_mean"] = f"{row['mean']:.{DECIMALS}f}"
        texts[f"{name}_sd"] = f"{row['sd']:.{DECIMALS}f}"
        for field in ("mean", "sd"):
            value = row[f"reported_{field}"]
            texts[f"{name}_paper_{field}"] = "—" if value is None else f"{value:.{REPORTED_DECIMALS}f}"
        texts[f"{name}_agrees"] = _agreement(row["mean_matches"], row["sd_matches"])
    return texts


def _agreement(mean_matches, sd_matches) -> str:
    if mean_matches is None:
        return "—"
    return {(True, True): "yes", (True, False): "mean only",
            (False, True): "SD only", (False, False): "no"}[(mean_matches, sd_matches)]


def readings_figure(key: str, y_max: float = 150.0, n: int = 1201):
    """The optimal depth marginal of a figure under both readings of Eq. (16).

    Draws ``p_oy`` computed from Eq. (6) (``reading="derived"``) and from
    Eq. (16) as printed, which drops the factor ``exp(-K(y) / 2)``
    (``reading="printed"``), each normalised over ``y > 2``, with their means
    marked.

    Parameters
    ----------
    key : str
        ``"fig2"`` ... ``"fig6"``.
    y_max : float
        Upper end of the depth axis (> 2).
    n : int
        Grid points.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    from .scenarios import SCENARIOS

    s = SCENARIOS[key]
    y_max = _checks.positive_scalar(y_max - 2.0, "y_max - 2") + 2.0
    y = np.linspace(2.0, y_max, n)[1:]
    fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
    styles = {"derived": ("black", "-", "from Eq. (6)"),
              "printed": ("tab:orange", "--", "Eq. (16) as printed")}
    for reading, (color, linestyle, label) in styles.items():
        m = optimal.marginals(s.mu, s.rho, s.prior, reading=reading)
        ax.plot(y, m.depth_pdf(y), color=color, linestyle=linestyle, linewidth=1.6,
                label=f"{label} (mean {m.depth_mean:.2f})")
        ax.axvline(m.depth_mean, color=color, linestyle=":", linewidth=1.0)
    ax.set_xlabel("depth $y$ at time 3")
    ax.set_ylabel("optimal marginal density of $y$")
    ax.set_xlim(0.0, y_max)
    ax.set_ylim(bottom=0.0)
    ax.legend(frameon=False)
    ax.set_title(f"Figure {s.figure}'s measurements: the optimal depth marginal, two readings",
                 fontsize=10)
    return fig
