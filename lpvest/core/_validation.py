"""Input validation shared by every public entry point.

Each check names the user's parameter and, for shapes, both the found and the
expected shape, e.g. ``"Q has shape (3, 2); expected (3, 3)"``. Symmetry and
definiteness are judged with tolerances relative to the matrix's own scale
(an absolute epsilon rejects valid, badly scaled input).

Examples
--------
>>> as_vector([1, 2], "x0", 2)
array([1., 2.])
>>> as_vector([1, 2, 3], "x0", 2)
Traceback (most recent call last):
...
lpvest.core._errors.DimensionError: x0 has shape (3,); expected (2,)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ._errors import (
    ArgumentError,
    ArgumentTypeError,
    DimensionError,
    NonFiniteError,
    NotPositiveDefiniteError,
    NumericalError,
    SchedulingRangeError,
    shorten,
)

__all__ = [
    "as_float_array",
    "as_matrix",
    "as_vector",
    "as_signal",
    "as_rng",
    "check_finite",
    "check_symmetric",
    "check_positive_definite",
    "check_box",
    "check_simplex",
    "SYMMETRY_RTOL",
    "SIMPLEX_ATOL",
]

#: Relative tolerance of the symmetry check: ``|M - M^T| <= SYMMETRY_RTOL * |M|``.
SYMMETRY_RTOL = 1e-10
#: Absolute tolerance for ``sum(alpha) == 1`` and ``alpha >= 0`` (alpha is O(1)).
SIMPLEX_ATOL = 1e-9

Shape = Sequence[int | None]


def _shape_text(shape: Sequence[int | None]) -> str:
    parts = ["*" if s is None else str(s) for s in shape]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def _check_shape(arr: np.ndarray, name: str, expected: Shape | None) -> None:
    if expected is None:
        return
    ok = arr.ndim == len(expected) and all(
        e is None or e == s for s, e in zip(arr.shape, expected, strict=True)
    )
    if not ok:
        raise DimensionError(
            f"{name} has shape {_shape_text(arr.shape)}; expected {_shape_text(expected)}"
        )


#: Arrays up to this size are checked element by element in Python floats
#: (faster than numpy's ufunc machinery for the few numbers of one sample).
_SMALL = 8


def _all_finite(arr: np.ndarray) -> bool:
    if arr.size <= _SMALL and arr.dtype.kind == "f":
        return all(map(math.isfinite, arr.ravel().tolist()))
    return bool(np.isfinite(arr).all())


def check_finite(arr: np.ndarray, name: str) -> np.ndarray:
    """Raise :class:`NonFiniteError` naming ``name`` (and the first bad index) if
    ``arr`` holds NaN or inf.

    Parameters
    ----------
    arr : array_like
        The values; only float and complex arrays are checked (an integer or
        object array passes as it is).
    name : str
        The user's name for it, used in the error message.

    Returns
    -------
    ndarray
        ``np.asarray(arr)``: ``arr`` itself when it is an ndarray, not a copy.

    Raises
    ------
    NonFiniteError
        ``arr`` holds NaN or inf.
    """
    arr = np.asarray(arr)
    if arr.dtype.kind in "fc" and not _all_finite(arr):
        bad = np.argwhere(~np.isfinite(arr))[0]
        where = "" if arr.ndim == 0 else f" at index {tuple(int(i) for i in bad)}"
        value = arr[tuple(bad)] if arr.ndim else arr
        raise NonFiniteError(f"{name} holds a non-finite value ({value}){where}")
    return arr


def as_float_array(value: object, name: str) -> np.ndarray:
    """``value`` as a float array (a copy), or a :class:`DimensionError` naming ``name``
    when it is not numeric.

    Parameters
    ----------
    value : array_like
        Any value ``numpy.array(value, dtype=float)`` accepts; any shape, no
        finiteness check.
    name : str
        The user's name for it, used in the error message.

    Returns
    -------
    ndarray
        A new float array of ``value``'s shape.

    Raises
    ------
    DimensionError
        ``value`` is not numeric, is ragged, or holds an integer beyond the
        float range.
    """
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:  # (OverflowError: an int beyond float)
        raise DimensionError(f"{name} is not a numeric array ({shorten(' '.join(str(exc).split()), 100)})"
                             ) from exc
    return arr


def as_matrix(value: object, name: str, shape: Shape | None = None) -> np.ndarray:
    """Return ``value`` as a finite 2-D float array of the expected ``shape``.

    Parameters
    ----------
    value : array_like, shape (r, c)
        The matrix. A scalar is accepted when ``shape == (1, 1)``.
    name : str
        The user's name for it, used in error messages.
    shape : sequence of int or None, optional
        Expected shape; ``None`` entries match any size.

    Returns
    -------
    ndarray, shape (r, c)
        A new float array.

    Raises
    ------
    DimensionError
        ``value`` is not numeric, not 2-D, or not of ``shape``.
    NonFiniteError
        ``value`` holds NaN or inf.
    """
    arr = as_float_array(value, name)
    if arr.ndim == 0 and shape is not None and tuple(shape) == (1, 1):
        arr = arr.reshape(1, 1)
    if arr.ndim != 2:
        exp = shape if shape is not None else (None, None)
        raise DimensionError(f"{name} has shape {_shape_text(arr.shape)}; expected {_shape_text(exp)}")
    _check_shape(arr, name, shape)
    return check_finite(arr, name)


def as_vector(value: object, name: str, length: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite 1-D float array (a scalar becomes length 1); always a copy.

    Parameters
    ----------
    value : array_like, shape (length,)
        The vector, or a scalar.
    name : str
        The user's name for it, used in error messages.
    length : int or None, optional
        Expected length; None accepts any.

    Returns
    -------
    ndarray, shape (length,)
        A new float array.

    Raises
    ------
    DimensionError
        ``value`` is not numeric, not 1-D (nor a scalar), or not of ``length``.
    NonFiniteError
        ``value`` holds NaN or inf.
    """
    if type(value) is np.ndarray and value.dtype == np.float64 and value.ndim == 1 and (
            length is None or value.shape[0] == length):
        return check_finite(value.copy(), name)  # the common case of one sample, without np.array's parsing
    arr = as_float_array(value, name)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    _check_shape(arr, name, (length,))
    return check_finite(arr, name)


def as_signal(
    value: object, name: str, width: int, length: int | None = None, *, finite: bool = True
) -> np.ndarray:
    """Return a sampled signal as an array of shape ``(length, width)``.

    A 1-D array is accepted for a scalar signal (``width == 1``); ``None`` with
    ``width == 0`` gives an empty ``(length, 0)`` signal.

    Parameters
    ----------
    value : array_like, shape (length, width), or None
        The samples, one row per sample.
    name : str
        The user's name for it, used in error messages.
    width : int
        Number of channels.
    length : int or None, optional
        Expected number of samples; None accepts any (and then ``None`` is
        not accepted for ``value``).
    finite : bool, default True
        Whether NaN and inf are refused.

    Returns
    -------
    ndarray, shape (length, width)
        A new float array (or the empty signal).

    Raises
    ------
    DimensionError
        ``value`` is None where an empty signal is not possible, is not
        numeric, or is not of shape ``(length, width)``.
    NonFiniteError
        ``finite`` is True and ``value`` holds NaN or inf.
    """
    if value is None:
        if width == 0 and length is not None:
            return np.zeros((length, 0))
        raise DimensionError(f"{name} is missing; expected shape {_shape_text((length, width))}")
    arr = as_float_array(value, name)
    if arr.ndim == 1 and width == 1:
        arr = arr[:, None]
    _check_shape(arr, name, (length, width))
    if finite:
        check_finite(arr, name)
    return arr


def check_symmetric(m: np.ndarray, name: str, *, rtol: float = SYMMETRY_RTOL) -> np.ndarray:
    """Raise unless ``m`` is square and symmetric relative to its own norm.

    Parameters
    ----------
    m : ndarray, shape (n, n)
        The matrix.
    name : str
        The user's name for it, used in error messages.
    rtol : float, default SYMMETRY_RTOL
        Largest accepted ``max |m - m^T|`` relative to ``max |m|``.

    Returns
    -------
    ndarray, shape (n, n)
        ``m`` itself (not symmetrised).

    Raises
    ------
    DimensionError
        ``m`` is not a square matrix.
    NonFiniteError
        ``m`` holds NaN or inf.
    NotPositiveDefiniteError
        ``m`` is not symmetric within ``rtol``.
    """
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise DimensionError(f"{name} has shape {_shape_text(m.shape)}; expected a square matrix")
    check_finite(m, name)
    scale = float(np.max(np.abs(m))) if m.size else 0.0
    # compared at unit scale (a power of two: exact), as m - m^T of entries near 1e308 would overflow
    e = math.frexp(scale)[1]
    asym = math.ldexp(float(np.max(np.abs(np.ldexp(m, -e) - np.ldexp(m.T, -e)))), e) if scale > 0 else 0.0
    if asym > rtol * scale:
        raise NotPositiveDefiniteError(
            f"{name} is not symmetric: max |{name} - {name}^T| = {asym:.3g} "
            f"exceeds {rtol:g} x max |{name}| = {rtol * scale:.3g}"
        )
    return m


def check_positive_definite(
    m: np.ndarray, name: str, *, semidefinite: bool = False, rtol: float | None = None
) -> np.ndarray:
    """Raise unless ``m`` is symmetric positive definite (or semidefinite).

    Definiteness is relative: the smallest eigenvalue must exceed
    ``rtol * max(|eigenvalue|)`` (default ``rtol = max(n, 10) * eps``); for
    ``semidefinite=True`` it must not be below ``-rtol * max(|eigenvalue|)``.
    The eigenvalues are computed at unit scale (``m`` times a power of two),
    so no entry overflows.

    Parameters
    ----------
    m : ndarray, shape (n, n)
        The matrix; symmetry is checked by :func:`check_symmetric` with its
        default tolerance.
    name : str
        The user's name for it, used in error messages.
    semidefinite : bool, default False
        Accept a positive semidefinite matrix (a zero matrix included).
    rtol : float or None, optional
        Relative eigenvalue tolerance; None: ``max(n, 10) * eps``.

    Returns
    -------
    ndarray, shape (n, n)
        The symmetrised matrix ``(m + m^T) / 2`` (``m`` itself when ``n == 0``).

    Raises
    ------
    DimensionError
        ``m`` is not a square matrix.
    NonFiniteError
        ``m`` holds NaN or inf.
    NotPositiveDefiniteError
        ``m`` is not symmetric, or not positive (semi)definite.
    NumericalError
        The eigenvalues could not be computed.
    """
    check_symmetric(m, name)
    n = m.shape[0]
    if n == 0:
        return m
    sym = 0.5 * m + 0.5 * m.T
    e = math.frexp(float(np.max(np.abs(sym))))[1]  # scaling by 2^-e is exact
    try:
        eig = np.ldexp(np.linalg.eigvalsh(np.ldexp(sym, -e)), e)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - eigvalsh of a finite symmetric matrix converges
        raise NumericalError(f"{name}: the eigenvalues of {name} could not be computed ({exc})") from None
    scale = float(np.max(np.abs(eig)))
    tol = (rtol if rtol is not None else max(n, 10) * np.finfo(float).eps) * scale
    lo = float(eig[0])
    if semidefinite:
        if lo < -tol:
            raise NotPositiveDefiniteError(
                f"{name} is not positive semidefinite: smallest eigenvalue {lo:.3g}"
            )
    elif scale == 0.0 or lo <= tol:
        raise NotPositiveDefiniteError(
            f"{name} is not positive definite: smallest eigenvalue {lo:.3g} "
            f"(largest {float(eig[-1]):.3g})"
        )
    return sym


def check_box(
    p: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    names: Sequence[str],
    *,
    what: str = "scheduling value",
    rtol: float = 1e-12,
) -> None:
    """Raise :class:`SchedulingRangeError` if a component of ``p`` lies outside
    ``[lower, upper]`` (with a tolerance relative to the bounds' magnitude).

    Parameters
    ----------
    p : ndarray, shape (n_p,)
        One value. NaN is not caught here (it compares false): check
        finiteness first.
    lower, upper : ndarray, shape (n_p,)
        The bounds of each component.
    names : sequence of str, length n_p
        The components' names, used in the error message.
    what : str, default "scheduling value"
        How the message calls ``p`` (``"<what> <name> = <value> is outside
        its declared range [lo, hi]"``).
    rtol : float, default 1e-12
        Component ``j`` may lie ``rtol * max(1, |lower_j|, |upper_j|)``
        outside its bounds.

    Raises
    ------
    SchedulingRangeError
        A component lies outside its bounds (the first such is named).
    """
    if p.size <= _SMALL:  # one sample: Python floats (NaN compares False: it falls to the full check)
        if all(lo - rtol * max(1.0, abs(lo), abs(hi)) <= v <= hi + rtol * max(1.0, abs(lo), abs(hi))
               for v, lo, hi in zip(p.tolist(), lower.tolist(), upper.tolist(), strict=True)):
            return
    tol = rtol * np.maximum(1.0, np.maximum(np.abs(lower), np.abs(upper)))
    bad = (p < lower - tol) | (p > upper + tol)
    if np.any(bad):
        j = int(np.argmax(bad))
        # the value with the digits that show why (1 + 1e-7 as 1.0000001, not as 1)
        value = float(p[j])
        shown = f"{value:g}" if float(f"{value:g}") == value else repr(value)
        raise SchedulingRangeError(
            f"{what} {names[j]} = {shown} is outside its declared range "
            f"[{lower[j]:.6g}, {upper[j]:.6g}]"
        )


def check_simplex(alpha: np.ndarray, name: str = "alpha", *, atol: float = SIMPLEX_ATOL) -> None:
    """Raise :class:`SchedulingRangeError` unless ``alpha`` lies on the unit
    simplex (``alpha >= 0``, ``sum(alpha) == 1``, within ``atol``).

    Parameters
    ----------
    alpha : ndarray, shape (n_v,)
        The vertex weights of one sample.
    name : str, default "alpha"
        The user's name for it, used in error messages.
    atol : float, default SIMPLEX_ATOL
        Absolute tolerance of both conditions.

    Raises
    ------
    NonFiniteError
        ``alpha`` holds NaN or inf.
    SchedulingRangeError
        A weight is negative, or the weights do not sum to 1.
    """
    check_finite(alpha, name)
    if alpha.size <= _SMALL:
        values = alpha.tolist()
        if min(values) >= -atol and abs(math.fsum(values) - 1.0) <= atol:
            return
    if np.any(alpha < -atol):
        i = int(np.argmin(alpha))
        raise SchedulingRangeError(
            f"{name} is not on the unit simplex: {name}[{i + 1}] = {alpha[i]:.6g} < 0"
        )
    total = float(np.sum(alpha))
    if abs(total - 1.0) > atol:
        raise SchedulingRangeError(
            f"{name} is not on the unit simplex: its entries sum to {total:.12g}, not 1"
        )


def as_rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    """A :class:`numpy.random.Generator` from a generator, a seed or ``None``
    (fresh entropy).

    Parameters
    ----------
    rng : numpy.random.Generator or int or None
        A generator (used as it is), a non-negative integer seed, or None.

    Returns
    -------
    numpy.random.Generator
        ``rng`` itself, or ``numpy.random.default_rng(rng)``.

    Raises
    ------
    ArgumentError
        ``rng`` is a negative integer.
    ArgumentTypeError
        ``rng`` is of another type (a bool included).
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or (isinstance(rng, int | np.integer) and not isinstance(rng, bool)):
        if rng is not None and rng < 0:
            raise ArgumentError(f"rng: a seed must be a non-negative integer; found {rng}")
        return np.random.default_rng(rng)
    raise ArgumentTypeError(f"rng must be a numpy Generator, an integer seed or None, not {type(rng).__name__}")
