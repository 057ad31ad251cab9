"""Input checks shared by the public functions.

Every check raises :class:`ValueError` whose message names the offending
argument and says what is wrong with it, so that bad input never turns into a
NaN or a silently wrong answer further down.
"""

from __future__ import annotations

import numpy as np

#: Triples whose second difference ``|mu1 + mu3 - 2 mu2|`` is at or below this
#: value are treated as degenerate: the three bearings are (numerically)
#: collinear in time and no finite depth explains them.
DEGENERACY_TOL = 1e-12

#: The most frames (bearings per problem) the filters accept. Every filter's
#: cost grows at least linearly with the frames, and the second-order
#: approximation with process noise solves a dense least-squares problem over
#: the whole trajectory, whose cost grows like the cube of the frames.
MAX_FRAMES = 1_000


#: The dtype kinds a numeric argument may have: booleans are refused with the rest
#: (``True`` is not a noise level), as are complex, object, text, bytes and times.
_NUMERIC_KINDS = "iuf"

_KIND_NAMES = {
    "b": "boolean",
    "c": "complex",
    "O": "object",
    "U": "text",
    "S": "bytes",
    "V": "structured",
    "M": "datetime",
    "m": "timedelta",
}


def as_float(value, name: str) -> np.ndarray:
    """``value`` as a float array: the one conversion of every public function's numbers.

    Accepts a number, a 0-d array, a (nested) list or an array of integers or
    floats. Refuses, naming ``name`` and the kind, complex numbers (whose
    imaginary part would be dropped), booleans, objects (``None``, ``Decimal``,
    ragged lists), text and bytes (``"0.1"`` is not a number here) and times.

    Returns
    -------
    ndarray of float, the shape of ``value``
    """
    if isinstance(value, np.ndarray):
        arr = value
    else:
        try:
            arr = np.asarray(value)
        except (TypeError, ValueError):  # ragged nested lists
            raise ValueError(
                f"{name} must be numeric, got a ragged or mixed {type(value).__name__}"
            ) from None
    kind = arr.dtype.kind
    if kind not in _NUMERIC_KINDS:
        what = _KIND_NAMES.get(kind, str(arr.dtype))
        raise ValueError(
            f"{name} must be numeric (real integers or floats), got {what} values "
            f"(dtype {arr.dtype})"
        )
    return arr.astype(float, copy=False)


def finite_array(value, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a float array (:func:`as_float`), checking shape and finiteness.

    A non-finite array is refused with its values, or with their count beyond ten entries.
    """
    arr = as_float(value, name)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        if arr.size <= 10:
            raise ValueError(f"{name} must be finite, got {arr.tolist()}")
        raise ValueError(
            f"{name} must be finite, got {int(np.sum(~np.isfinite(arr)))} non-finite entries"
        )
    return arr


def number(value, name: str) -> float:
    """A finite number given as a number, a 0-d array or a list or array of one value."""
    arr = finite_array(value, name)
    if arr.size != 1:
        raise ValueError(f"{name} must be a number, got shape {arr.shape}")
    return float(arr.reshape(()))


def positive_scalar(value, name: str) -> float:
    """Return ``value`` (a :func:`number`) as a float, checking that it is finite and > 0."""
    x = number(value, name)
    if not x > 0:
        raise ValueError(f"{name} must be positive, got {x!r}")
    return x


def probability(value, name: str) -> float:
    """A level or probability ``p`` strictly between 0 and 1, as a float.

    Parameters
    ----------
    value : float
        A real number (not a bool), ``0 < p < 1``; NaN and infinities are refused.
    name : str
        The argument's name, for the message.

    Returns
    -------
    float
    """
    kind = np.asarray(value).dtype.kind if np.ndim(value) == 0 else ""
    p = float(value) if kind in _NUMERIC_KINDS else float("nan")
    if not 0.0 < p < 1.0:
        raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
    return p


def nonnegative_scalar(value, name: str) -> float:
    """Return ``value`` (a :func:`number`) as a float, checking that it is finite and >= 0."""
    x = number(value, name)
    if not x >= 0:
        raise ValueError(f"{name} must be >= 0, got {x!r}")
    return x


#: The smallest positive process noise, the smallest normal double. Below it the
#: noise's inverse, which the filters' information forms hold, overflows.
MIN_PROCESS_NOISE = float(np.finfo(float).tiny)


def process_noise(value, name: str = "process_noise") -> float:
    """A process noise SD (a :func:`number`): 0, or from :data:`MIN_PROCESS_NOISE` on."""
    q = nonnegative_scalar(value, name)
    if 0.0 < q < MIN_PROCESS_NOISE:
        raise ValueError(
            f"{name} must be 0 or at least {MIN_PROCESS_NOISE!r} (the smallest normal "
            f"double: the inverse of a smaller noise overflows), got {q!r}"
        )
    return q


def nonnegative_batch(value, name: str, batch: tuple[int, ...]) -> np.ndarray:
    """Return ``value`` as a float array of shape ``()`` or ``batch``, finite and >= 0."""
    arr = finite_array(value, name)
    if arr.ndim and arr.shape != batch:
        raise ValueError(f"{name} must be a scalar or have shape {batch}, got shape {arr.shape}")
    if not np.all(arr >= 0):
        raise ValueError(f"{name} must be >= 0, got minimum {float(np.min(arr)):.6g}")
    return arr


def nonempty(values: np.ndarray, name: str) -> np.ndarray:
    """``values`` (an array) itself, refused when it holds nothing."""
    if np.size(values) == 0:
        raise ValueError(f"{name} must hold at least one value, got none")
    return values


def positive_array(value, name: str) -> np.ndarray:
    """Return ``value`` as a float array (scalar or 1-D), checking every entry is finite and > 0."""
    arr = finite_array(value, name)
    if arr.ndim > 1:
        raise ValueError(f"{name} must be a scalar or 1-D, got shape {arr.shape}")
    if not np.all(arr > 0):
        raise ValueError(f"{name} must be positive, got {arr.tolist()}")
    return arr


def covariance(value, name: str, dim: int) -> np.ndarray:
    """Return ``value`` as a symmetric positive-definite ``(dim, dim)`` array."""
    arr = finite_array(value, name, (dim, dim))
    scale = max(np.max(np.abs(arr)), np.finfo(float).tiny)
    if np.max(np.abs(arr - arr.T)) > 1e-10 * scale:
        raise ValueError(f"{name} must be symmetric, got {arr.tolist()}")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ValueError(
            f"{name} must be positive definite; eigenvalues are {np.linalg.eigvalsh(arr).tolist()}"
        ) from None
    return 0.5 * (arr + arr.T)


def batch_index(flat_index: int, batch: tuple[int, ...]) -> str:
    """``[i]`` or ``[i, j]``: the position of a flat row in a batch of shape ``batch``."""
    return "[" + ", ".join(str(int(i)) for i in np.unravel_index(flat_index, batch)) + "]"


def three_frames(mu, name: str = "mu") -> np.ndarray:
    """Check that ``mu`` holds the paper's three bearings per problem, shape ``(..., 3)``.

    For the functions whose formulas are those of three frames (Eqs. (5)-(7), (14)-(16)).
    """
    arr = finite_array(mu, name)
    if arr.ndim < 1 or arr.shape[-1] != 3:
        raise ValueError(
            f"{name} must have shape (..., 3), the paper's three frames, got shape {arr.shape}"
        )
    return arr


def frame_rows(arr: np.ndarray, name: str, unit: str) -> np.ndarray:
    """``arr`` itself, refused unless of shape ``(..., N)``, ``3 <= N <= MAX_FRAMES``, non-empty.

    ``unit`` names what ``N`` counts in the refusals (``"frames"``, ``"bearings"``).
    """
    if arr.ndim < 1 or arr.shape[-1] < 3:
        raise ValueError(
            f"{name} must have shape (..., N) with N >= 3 {unit} per problem, got shape {arr.shape}"
        )
    if arr.size == 0:
        raise ValueError(f"{name} must hold at least one problem, got an empty batch {arr.shape}")
    if arr.shape[-1] > MAX_FRAMES:
        raise ValueError(
            f"{name} has {arr.shape[-1]} {unit} per problem, more than the "
            f"{MAX_FRAMES} frames the filters accept"
        )
    return arr


def covariances(value, name: str, dim: int = 3) -> np.ndarray:
    """Check symmetric positive-definite matrices of shape ``(..., dim, dim)``.

    The first offending matrix is named with its index, e.g. ``prior_cov[2]``;
    returns the symmetrised array.
    """
    arr = finite_array(value, name)
    if arr.ndim < 2 or arr.shape[-2:] != (dim, dim):
        raise ValueError(f"{name} must have shape (..., {dim}, {dim}), got shape {arr.shape}")
    batch = arr.shape[:-2]
    flat = arr.reshape(-1, dim, dim)
    scale = np.maximum(np.max(np.abs(flat), axis=(1, 2)), np.finfo(float).tiny)
    asymmetric = np.max(np.abs(flat - np.swapaxes(flat, 1, 2)), axis=(1, 2)) > 1e-10 * scale
    sym = 0.5 * (flat + np.swapaxes(flat, 1, 2))
    # a symmetric matrix is positive definite iff its Cholesky factor exists: test each at once
    definite = np.all(np.linalg.eigvalsh(sym) > 0, axis=1) if len(sym) else np.ones(0, bool)
    bad = asymmetric | ~definite
    if np.any(bad):
        i = int(np.argmax(bad))
        covariance(flat[i], name + (batch_index(i, batch) if batch else ""), dim)
        raise ValueError(
            f"{name}{batch_index(i, batch) if batch else ''} must be positive definite; "
            f"eigenvalues are {np.linalg.eigvalsh(sym[i]).tolist()}"
        )
    return sym.reshape(arr.shape)


def broadcasts(shape: tuple[int, ...], target: tuple[int, ...]) -> bool:
    """Whether an array of ``shape`` broadcasts to ``target`` (and to nothing larger)."""
    try:
        return np.broadcast_shapes(shape, target) == target
    except ValueError:
        return False


def seed_sequence(seed, name: str = "seed") -> np.random.SeedSequence:
    """Return ``seed`` (an int >= 0 or a :class:`numpy.random.SeedSequence`) as a SeedSequence."""
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(
            f"{name} must be a non-negative integer or a numpy.random.SeedSequence, got {seed!r}"
        )
    return np.random.SeedSequence(int(seed))


def generator(rng, name: str = "rng") -> np.random.Generator:
    """Return ``rng`` as a Generator: a Generator as is, a SeedSequence or int seeds a new one."""
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(seed_sequence(rng, name))


def spawn(seed, n: int) -> list[np.random.SeedSequence]:
    """The first ``n`` children of ``seed`` (int or SeedSequence), without spawning from it.

    ``SeedSequence.spawn`` counts the children it has given; this does not, so
    the same ``seed`` always gives the same children.
    """
    seed = seed_sequence(seed)
    return [
        np.random.SeedSequence(
            seed.entropy, spawn_key=seed.spawn_key + (i,), pool_size=seed.pool_size
        )
        for i in range(n)
    ]


def nonnegative_count(value, name: str) -> int:
    """Return ``value`` as an int, checking that it is an integer >= 0."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    return int(value)


def count(value, name: str) -> int:
    """Return ``value`` as an int, checking that it is an integer >= 1."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def frames(value, name: str = "frames") -> int:
    """Return ``value`` as an int, checking that it is a number of frames, 3 to MAX_FRAMES."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, np.integer))
        or not 3 <= value <= MAX_FRAMES
    ):
        shown = value.item() if isinstance(value, np.generic) else value
        raise ValueError(f"{name} must be an integer from 3 to {MAX_FRAMES}, got {shown!r}")
    return int(value)


def sizes(sizes) -> np.ndarray:
    """Numbers of particles, checked: positive integers, at least one.

    Parameters
    ----------
    sizes : int or array_like of int, shape (S,)

    Returns
    -------
    ndarray of int, shape (S,)

    Raises
    ------
    ValueError
        Naming ``sizes`` when they are not positive integers.
    """
    sizes = np.atleast_1d(np.asarray(sizes))
    if (
        sizes.ndim != 1
        or sizes.size < 1
        or not np.issubdtype(sizes.dtype, np.integer)
        or np.any(sizes < 1)
    ):
        raise ValueError(f"sizes must be positive integers, got {sizes!r}")
    return sizes.astype(int)
