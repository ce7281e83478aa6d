"""Small dense linear-algebra helpers shared by the models and estimators (numpy only).

:class:`MatrixStack` evaluates named matrices that are weighted sums
``M(c) = sum_i c_i M_i`` (the vertices of a polytopic model weighted by
``alpha``, the terms of an affine model weighted by ``[1, psi_1(p), ...]``, a
gain-scheduled filter's vertex matrices), all names at once: the matrices are
flattened side by side, so one sample costs ``n_terms`` multiply-adds over one
array instead of one ``tensordot`` per matrix. One sample (:meth:`MatrixStack.at`)
and a trajectory (:meth:`MatrixStack.at_batch`) perform the same elementwise
operations in the same order, so they give the same numbers to the bit: a
streaming component and a batch simulation built on it agree exactly.

>>> stack = MatrixStack({"A": np.array([[[1.0]], [[3.0]]]), "b": np.array([[1.0, 0.0], [0.0, 1.0]])})
>>> m = stack.at(np.array([0.25, 0.75]))
>>> m["A"], m["b"]
(array([[2.5]]), array([0.25, 0.75]))
>>> bool(np.array_equal(stack.at_batch(np.array([[0.25, 0.75]]))["A"][0], m["A"]))
True
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ._errors import DimensionError

__all__ = ["MatrixStack", "mT", "sym"]


class MatrixStack:
    """Named arrays ``M_i`` (each of shape ``(n_terms, *shape)``) and their
    weighted sums ``sum_i c_i M_i`` for all names at once (see the module docs).

    Parameters
    ----------
    named : mapping of str to ndarray, shape (n_terms, *shape)
        The terms ``M_i`` of each name along the first axis; every array has
        the same ``n_terms``, the trailing ``shape`` may differ between names.
        The arrays are copied (as float) into one read-only array.

    Raises
    ------
    DimensionError
        The arrays do not all have the same number of terms, or ``named`` is
        empty.
    """

    def __init__(self, named: Mapping[str, np.ndarray]) -> None:
        arrays = {k: np.asarray(v, dtype=float) for k, v in named.items()}
        terms = {a.shape[0] for a in arrays.values()}
        if len(terms) != 1:
            raise DimensionError(f"every stack needs the same number of terms; found {sorted(terms)}")
        self.n_terms = terms.pop()
        self.shapes = {k: a.shape[1:] for k, a in arrays.items()}
        self.slices: dict[str, slice] = {}
        start = 0
        for k, a in arrays.items():
            size = int(np.prod(a.shape[1:], dtype=int))
            self.slices[k] = slice(start, start + size)
            start += size
        self.flat = np.concatenate([a.reshape(self.n_terms, -1) for a in arrays.values()], axis=1) if arrays else (
            np.zeros((self.n_terms, 0)))
        self.flat.setflags(write=False)
        self._rows = [self.flat[i] for i in range(self.n_terms)]

    def at(self, c: np.ndarray) -> dict[str, np.ndarray]:
        """``sum_i c[i] M_i`` for every name (fresh arrays).

        Parameters
        ----------
        c : ndarray, shape (n_terms,)
            The weights (vertex weights ``alpha`` or ``[1, psi_1(p), ...]``).

        Returns
        -------
        dict of str to ndarray, shape (*shape)
            The weighted sum of each name, in the shape of its terms.
        """
        rows = self._rows
        acc = c[0] * rows[0]
        for i in range(1, self.n_terms):
            acc = acc + c[i] * rows[i]
        return {k: acc[s].reshape(self.shapes[k]) for k, s in self.slices.items()}

    def at_batch(self, c: np.ndarray) -> dict[str, np.ndarray]:
        """``sum_i c[t, i] M_i`` for every row ``t`` of ``c`` (shape ``(T, n_terms)``),
        each of shape ``(T, *shape)``; the same numbers as :meth:`at` row by row.

        Parameters
        ----------
        c : array_like, shape (T, n_terms)
            The weights of each sample, one row per sample.

        Returns
        -------
        dict of str to ndarray, shape (T, *shape)
            The weighted sums of each name, one per row of ``c``.
        """
        c = np.asarray(c, dtype=float)
        rows = self._rows
        acc = c[:, 0:1] * rows[0]
        for i in range(1, self.n_terms):
            acc = acc + c[:, i : i + 1] * rows[i]
        T = c.shape[0]
        return {k: acc[:, s].reshape((T, *self.shapes[k])) for k, s in self.slices.items()}


def mT(a: np.ndarray) -> np.ndarray:
    """The transpose of the last two axes (a stack of matrices).

    Parameters
    ----------
    a : ndarray, shape (..., m, n)
        A matrix or a stack of matrices.

    Returns
    -------
    ndarray, shape (..., n, m)
        ``a`` with its last two axes swapped (a view, not a copy).
    """
    return np.swapaxes(a, -1, -2)


def sym(a: np.ndarray) -> np.ndarray:
    """``(A + A^T) / 2`` over the last two axes.

    Parameters
    ----------
    a : ndarray, shape (..., n, n)
        A square matrix or a stack of them.

    Returns
    -------
    ndarray, shape (..., n, n)
        The symmetric part of each matrix (a new array).
    """
    return 0.5 * (a + mT(a))
