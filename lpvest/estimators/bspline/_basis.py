"""The B-spline basis (23): knots, the nonzero basis functions at a point, the basis matrix.

Notes: :mod:`lpvest.estimators.bspline`.
"""

from __future__ import annotations

import numpy as np

from ...core._errors import (
    DimensionError,
)
from ._model import UnknownSpline

__all__ = ["spline_knots", "knot_span", "basis_rows", "bspline_basis"]


# -- B-spline basis ------------------------------------------------------------------------------


def spline_knots(spec: UnknownSpline, length: float) -> np.ndarray:
    """The knot vector of ``spec`` on the window ``[0, length]`` (window coordinates).

    ``"uniform"``: ``t_i = (i - order + 1) * delta``, ``i = 0 .. n_basis + order - 1``,
    ``delta = length / (n_basis - order + 1)``, so that ``[t_{order-1}, t_{n_basis}]
    = [0, length]``.

    Parameters
    ----------
    spec : UnknownSpline
        The spline declaration: ``n_basis``, ``order`` and the knot rule.
    length : float
        Window length ``b - a``.

    Returns
    -------
    knots : ndarray, shape (n_basis + order,)
        Non-decreasing knots, relative to the window start.

    Raises
    ------
    DimensionError
        Explicit knots that do not cover ``[0, length]``.

    Examples
    --------
    >>> spline_knots(UnknownSpline(5, order=3), 3.0)
    array([-2., -1.,  0.,  1.,  2.,  3.,  4.,  5.])
    """
    n, k = spec.n_basis, spec.order
    if isinstance(spec.knots, str):
        if spec.knots == "uniform":
            delta = length / (n - k + 1)
            return (np.arange(n + k) - (k - 1)) * delta
        inner = np.linspace(0.0, length, n - k + 2)[1:-1]
        return np.concatenate([np.zeros(k), inner, np.full(k, float(length))])
    knots = np.asarray(spec.knots, dtype=float)
    tol = 1e-12 * max(1.0, abs(length))
    if knots[k - 1] > tol or knots[n] < length - tol or knots[n] <= knots[k - 1]:
        raise DimensionError(
            f"the explicit knots cover [{knots[k - 1]:.6g}, {knots[n]:.6g}] (knots[order-1], knots[n_basis], "
            f"relative to the window start); the window needs [0, {length:.6g}]"
        )
    return knots


def knot_span(x: np.ndarray, knots: np.ndarray, order: int) -> np.ndarray:
    """Knot span ``mu`` of each ``x`` (``knots[mu] <= x < knots[mu + 1]``, clipped
    to the spans of the basis): the non-zero B-splines there are ``mu - order + 1 .. mu``.

    Parameters
    ----------
    x : ndarray
        Points (any shape).
    knots : ndarray, shape (n_basis + order,)
        Non-decreasing knot vector.
    order : int
        B-spline order (degree + 1).

    Returns
    -------
    mu : ndarray of int, shape like ``x``
        Span indices, in ``[order - 1, n_basis - 1]``.
    """
    return np.clip(np.searchsorted(knots, x, side="right") - 1, order - 1, knots.size - order - 1)


def _nonzero_basis(x: np.ndarray, knots: np.ndarray, mu: np.ndarray, degree: int) -> np.ndarray:
    """Cox-de Boor: values of ``B_{mu-degree+r, degree}(x)``, ``r = 0..degree``, shape
    (degree + 1, *x.shape) (``mu`` broadcasts against ``x``)."""
    N = np.empty((degree + 1, *x.shape))
    N[0] = 1.0
    left = [x - knots[mu + 1 - j] for j in range(1, degree + 1)]  # left[j - 1]
    right = [knots[mu + j] - x for j in range(1, degree + 1)]  # right[j - 1]
    for j in range(1, degree + 1):
        saved = np.zeros(x.shape)
        for r in range(j):
            temp = N[r] / (right[r] + left[j - r - 1])
            N[r] = saved + right[r] * temp
            saved = left[j - r - 1] * temp
        N[j] = saved
    return N


def basis_rows(
    x: np.ndarray, knots: np.ndarray, order: int, mu: np.ndarray, *, derivative: bool = False
) -> np.ndarray:
    """The ``order`` B-splines non-zero in the spans ``mu`` (or their derivatives
    (22)) at ``x``: row ``r`` holds ``B_{mu - order + 1 + r}``, shape (order, *x.shape)
    (``mu`` broadcasts against ``x``).

    Parameters
    ----------
    x : ndarray
        Points (any shape).
    knots : ndarray, shape (n_basis + order,)
        Non-decreasing knot vector.
    order : int
        B-spline order (degree + 1).
    mu : ndarray of int
        Knot span of each point (:func:`knot_span`), broadcasting against ``x``.
    derivative : bool, default False
        Return the derivatives ``B_i'`` (zero for order 1).

    Returns
    -------
    ndarray, shape (order, *x.shape)
        Row ``r``: ``B_{mu - order + 1 + r}(x)`` (or its derivative).
    """
    degree = order - 1
    if not derivative:
        return _nonzero_basis(x, knots, mu, degree)
    out = np.zeros((order, *x.shape))
    if degree == 0:
        return out
    lower = _nonzero_basis(x, knots, mu, degree - 1)  # B_{mu-degree+1+r, degree-1}
    first = mu - degree
    for r in range(order):
        i = first + r
        if r >= 1:
            den = knots[i + degree] - knots[i]
            out[r] += np.where(den > 0, degree / np.where(den > 0, den, 1.0), 0.0) * lower[r - 1]
        if r <= degree - 1:
            den = knots[i + degree + 1] - knots[i + 1]
            out[r] -= np.where(den > 0, degree / np.where(den > 0, den, 1.0), 0.0) * lower[r]
    return out


def bspline_basis(
    x: np.ndarray, knots: np.ndarray, order: int, *, derivative: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The ``order`` B-splines that are non-zero at each ``x`` (Cox-de Boor
    recursion, Section II-C), or their derivatives (22).

    Parameters
    ----------
    x : ndarray, shape (N,)
        Points inside ``[knots[order-1], knots[-order]]``.
    knots : ndarray, shape (n_basis + order,)
        Non-decreasing knot vector.
    order : int
        B-spline order (degree + 1).
    derivative : bool, optional
        Return ``B_i'`` instead of ``B_i``.

    Returns
    -------
    first : ndarray of int, shape (N,)
        Index of the first basis function non-zero at ``x``.
    values : ndarray, shape (N, order)
        ``values[g, r]`` is ``B_{first[g] + r}(x[g])`` (or its derivative).

    Examples
    --------
    >>> first, vals = bspline_basis(np.array([0.5]), np.arange(6.0) - 2, 3)
    >>> first, vals.round(4)
    (array([0]), array([[0.125, 0.75 , 0.125]]))
    """
    x = np.asarray(x, dtype=float)
    mu = knot_span(x, knots, order)
    rows = basis_rows(x, knots, order, mu, derivative=derivative)
    return mu - (order - 1), np.ascontiguousarray(rows.T)


