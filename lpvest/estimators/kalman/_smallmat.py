"""The one small-matrix kernel of the Kalman code: Cholesky factors of symmetric
positive definite matrices and triangular solves with them, for one matrix or a
stack (any leading axes).

The exact filter factors ``Omega_t`` (4e) once per sample, the decorrelation
(5c)/(5e) factors ``H R H^T``, the parallel scan factors stacks of both. These
matrices are ``n_y x n_y``, usually 1 to 3, where a LAPACK call costs more than
the arithmetic, so the textbook recurrences are written here once, entry by
entry, and run

- on Python floats for one matrix of size up to :data:`SMALL_NY`,
- on numpy arrays holding that entry of every matrix of a stack of size up to
  :data:`SMALL_STACK` (one elementwise operation per entry covers the stack),
- and LAPACK (:func:`numpy.linalg.cholesky`, :func:`numpy.linalg.solve`) above.

Both small forms perform the same IEEE operations (``-``, ``*``, ``/``,
``sqrt``, no fused multiply-add) in the same order, so a matrix gives the same
factor to the bit alone or inside a stack, whatever the BLAS. Sums run index
by index, ``s = a_ij; s -= l_ik l_jk`` for ``k = 0, 1, ...``: the order of the
Python-float kernel that the native runtime reproduces (``lpv_cholesky``).

A factorisation that fails raises :class:`FactorError` (a
:class:`~lpvest.core.NumericalError`) naming the pivot and, for a stack, the
first matrix that is not positive definite; callers translate it into their
own message. No jitter, no pseudo-inverse.

Runtime code: imports only numpy.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...core._errors import DimensionError, NumericalError

__all__ = ["FactorError", "SMALL_NY", "SMALL_STACK", "chol_inverse", "cholesky", "is_small", "lsolve", "usolve"]

#: Largest size of one matrix factored by the recurrence in Python floats
#: (above: LAPACK, which is faster from 4 on).
SMALL_NY = 3

#: Largest size of a stack of matrices factored by the recurrence vectorised
#: over the stack (numpy's batched LAPACK call costs about 0.3 us per matrix,
#: ten times a small matrix product).
SMALL_STACK = 4


class FactorError(NumericalError):
    """A Cholesky factorisation failed: the matrix is not (numerically)
    positive definite, or not finite.

    Parameters
    ----------
    index : int
        The first matrix of the stack that fails (flat index over the
        leading axes); -1 for one matrix.
    pivot : int or None
        The failing pivot, 1-based (the recurrence); None when LAPACK failed.
    value : float
        The failing pivot's value (nan when LAPACK failed).
    nonfinite : bool
        LAPACK returned a factor with non-finite entries.
    """

    def __init__(self, index: int, pivot: int | None, value: float, *, nonfinite: bool = False) -> None:
        self.index = index
        self.pivot = pivot
        self.value = value
        self.nonfinite = nonfinite
        where = "" if index < 0 else f" (stack element {index})"
        if pivot is not None:
            detail = f"Cholesky pivot {pivot} is {value:.3g}"
        else:
            detail = "its factor holds non-finite values" if nonfinite else "LAPACK's Cholesky factorisation failed"
        super().__init__(f"the matrix is not positive definite{where}: {detail}")


class _Pivot(Exception):
    """Internal: pivot ``i`` (0-based) of the recurrence is ``s``, not positive and finite."""

    def __init__(self, i: int, s: float | np.ndarray) -> None:
        self.i = i
        self.s = s


def is_small(M: np.ndarray) -> bool:
    """True if :func:`cholesky` factors ``M`` (one matrix or a stack) by the
    recurrence, False if by LAPACK (the rule of the module notes)."""
    return M.shape[-1] <= (SMALL_NY if M.ndim == 2 else SMALL_STACK)


# ---------------------------------------------------------------------------
# the recurrences, once: entries are Python floats (one matrix) or arrays
# holding that entry of every matrix of a stack
# ---------------------------------------------------------------------------
def _bad(s: float | np.ndarray) -> bool:
    if isinstance(s, float):
        return not 0.0 < s < math.inf
    return not bool(np.all((s > 0.0) & (s < math.inf)))


def _factor(a: list, m: int, sqrt: Any) -> tuple[list, list]:
    """The lower Cholesky factor of ``a`` (only its lower triangle is read),
    row by row, and its pivots ``l_ii^2``; raises :class:`_Pivot`."""
    L: list = [[0.0] * m for _ in range(m)]
    pivots = []
    for i in range(m):
        Li = L[i]
        for j in range(i + 1):
            Lj = L[j]
            s = a[i][j]
            for k in range(j):
                s = s - Li[k] * Lj[k]
            if i == j:
                if _bad(s):
                    raise _Pivot(i, s)
                Li[i] = sqrt(s)
                pivots.append(s)
            else:
                Li[j] = s / Lj[j]
    return L, pivots


def _forward(L: list, b: list, m: int) -> list:
    """``L^-1 b`` by forward substitution (``b``: the ``m`` rows)."""
    x: list = []
    for i in range(m):
        Li = L[i]
        s = b[i]
        for k in range(i):
            s = s - Li[k] * x[k]
        x.append(s / Li[i])
    return x


def _backward(L: list, b: list, m: int) -> list:
    """``L^-T b`` by back substitution (``b``: the ``m`` rows)."""
    x: list = [0.0] * m
    for i in range(m - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, m):
            s = s - L[k][i] * x[k]
        x[i] = s / L[i][i]
    return x


# ---------------------------------------------------------------------------
# the two forms
# ---------------------------------------------------------------------------
def _entries(M: np.ndarray) -> list:
    m = M.shape[-1]
    return [[M[..., i, j] for j in range(m)] for i in range(m)]


def _first_failing(M: np.ndarray, lapack: bool = False) -> FactorError:
    """The error naming the first matrix of a stack whose factorisation fails
    (the recurrence run on each matrix alone: the same arithmetic). Error path."""
    flat = M.reshape(-1, *M.shape[-2:])
    m = M.shape[-1]
    for k in range(flat.shape[0]):
        if is_small(M) and not lapack:
            try:
                _factor(flat[k].tolist(), m, math.sqrt)
            except _Pivot as p:
                return FactorError(k, p.i + 1, float(p.s))
        else:
            Mk = flat[k]
            if not np.all(np.isfinite(Mk)):
                return FactorError(k, None, math.nan, nonfinite=True)
            try:
                Lk = np.linalg.cholesky(Mk)
            except np.linalg.LinAlgError:
                return FactorError(k, None, math.nan)
            if not np.all(np.isfinite(Lk)):
                return FactorError(k, None, math.nan, nonfinite=True)
    return FactorError(0, None, math.nan)  # pragma: no cover - the stack failed, so one matrix does


def _small_factor(M: np.ndarray) -> tuple[list, list]:
    m = M.shape[-1]
    if M.ndim == 2:
        try:
            return _factor(M.tolist(), m, math.sqrt)
        except _Pivot as p:
            raise FactorError(-1, p.i + 1, float(p.s)) from None
    try:
        return _factor(_entries(M), m, np.sqrt)
    except _Pivot:
        raise _first_failing(M) from None


def _assemble(L: list, shape: tuple[int, ...]) -> np.ndarray:
    out = np.zeros(shape)
    for i, row in enumerate(L):
        for j in range(i + 1):
            out[..., i, j] = row[j]
    return out


def cholesky(M: np.ndarray, *, lapack: bool = False) -> np.ndarray:
    """Lower Cholesky factor of a symmetric positive definite matrix or of
    every matrix of a stack (only the lower triangle is read).

    Parameters
    ----------
    M : ndarray, shape (..., m, m)
        One matrix or a stack.
    lapack : bool, default False
        LAPACK whatever the size (a caller whose numbers have always come
        from LAPACK keeps them).

    Returns
    -------
    L : ndarray, shape (..., m, m)
        Lower triangular, ``L L^T = M``.

    Raises
    ------
    FactorError
        A matrix is not positive definite or not finite (the first one named).

    Examples
    --------
    >>> cholesky(np.array([[4.0, 2.0], [2.0, 5.0]]))
    array([[2., 0.],
           [1., 2.]])
    """
    if lapack or not is_small(M):
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise (_first_failing(M, lapack) if M.ndim > 2 else FactorError(-1, None, math.nan)) from None
        if not np.all(np.isfinite(L)):
            raise _first_failing(M, lapack) if M.ndim > 2 else FactorError(-1, None, math.nan, nonfinite=True)
        return L
    rows, _ = _small_factor(M)
    return np.array(rows) if M.ndim == 2 else _assemble(rows, M.shape)


def chol_inverse(M: np.ndarray) -> tuple[np.ndarray, float | np.ndarray]:
    """``chol(M)^-1`` and ``log det M`` of a small symmetric positive definite
    matrix or stack (``is_small(M)``): the factor by the recurrence, its
    inverse by forward substitution on the identity.

    Parameters
    ----------
    M : ndarray, shape (..., m, m)
        One matrix or a stack, ``m <= SMALL_NY`` (one) or ``<= SMALL_STACK`` (a stack).

    Returns
    -------
    Ci : ndarray, shape (..., m, m)
        ``chol(M)^-1``, lower triangular.
    logdet : float or ndarray, shape (...)
        ``log det M``, the sum of the logarithms of the pivots.

    Raises
    ------
    FactorError
        A matrix is not positive definite or not finite.
    DimensionError
        ``M`` is not small (use :func:`cholesky` and the solves).

    Examples
    --------
    >>> Ci, logdet = chol_inverse(np.array([[4.0, 2.0], [2.0, 5.0]]))
    >>> Ci, round(logdet, 6)
    (array([[ 0.5 ,  0.  ],
           [-0.25,  0.5 ]]), 2.772589)
    """
    if not is_small(M):
        raise DimensionError(f"chol_inverse takes matrices of size <= {SMALL_NY if M.ndim == 2 else SMALL_STACK} "
                             f"(one / a stack); found shape {M.shape}")
    m = M.shape[-1]
    L, pivots = _small_factor(M)
    cols = [_forward(L, [1.0 if i == c else 0.0 for i in range(m)], m) for c in range(m)]
    if M.ndim == 2:
        logdet = 0.0
        for s in pivots:
            logdet += math.log(s)
        return np.array([[cols[c][i] for c in range(m)] for i in range(m)]), logdet
    Ci = np.zeros(M.shape)
    for c, col in enumerate(cols):
        for i in range(c, m):
            Ci[..., i, c] = col[i]
    ld = np.log(pivots[0])
    for s in pivots[1:]:
        ld = ld + np.log(s)
    return Ci, ld


def _rows(L: np.ndarray, B: np.ndarray) -> tuple[list, list]:
    m = L.shape[-1]
    Le = [[L[..., i, k, None] for k in range(m)] for i in range(m)]
    return Le, [B[..., i, :] for i in range(m)]


def lsolve(L: np.ndarray, B: np.ndarray, *, lapack: bool = False) -> np.ndarray:
    """``L^-1 B`` for lower triangular factors from :func:`cholesky`: forward
    substitution (LAPACK's general solve where :func:`cholesky` used LAPACK).

    Parameters
    ----------
    L : ndarray, shape (..., m, m)
        Lower triangular factors.
    B : ndarray, shape (..., m, k)
        Right-hand sides.
    lapack : bool, default False
        LAPACK's general solve whatever the size (as :func:`cholesky`).

    Returns
    -------
    ndarray, shape (..., m, k)
        ``L^-1 B``.

    Examples
    --------
    >>> lsolve(np.array([[2.0, 0.0], [1.0, 2.0]]), np.array([[2.0], [3.0]]))
    array([[1.],
           [1.]])
    """
    if lapack or not is_small(L):
        return np.linalg.solve(L, B)
    Le, b = _rows(L, B)
    return np.stack(_forward(Le, b, L.shape[-1]), axis=-2)


def usolve(L: np.ndarray, B: np.ndarray, *, lapack: bool = False) -> np.ndarray:
    """``L^-T B`` for lower triangular factors from :func:`cholesky`: back
    substitution (LAPACK's general solve where :func:`cholesky` used LAPACK).

    Parameters
    ----------
    L : ndarray, shape (..., m, m)
        Lower triangular factors.
    B : ndarray, shape (..., m, k)
        Right-hand sides.
    lapack : bool, default False
        LAPACK's general solve whatever the size (as :func:`cholesky`).

    Returns
    -------
    ndarray, shape (..., m, k)
        ``L^-T B``.

    Examples
    --------
    >>> usolve(np.array([[2.0, 0.0], [1.0, 2.0]]), np.array([[3.0], [2.0]]))
    array([[1.],
           [1.]])
    """
    if lapack or not is_small(L):
        return np.linalg.solve(np.swapaxes(L, -1, -2), B)
    Le, b = _rows(L, B)
    return np.stack(_backward(Le, b, L.shape[-1]), axis=-2)
