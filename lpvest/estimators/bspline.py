"""Joint parameter and state estimation for LTV systems with B-splines.

Sridhar, Ghoshal & Michalska (002_54d0f33f85fddffe.txt), Sections III-IV, for
the second-order SISO input-output equation (11)::

    y'' + a_1(t) y' + a_0(t) y + b_1(t) u' + b_0(t) u = 0.

Each coefficient is declared :class:`Known` (a
:class:`~lpvest.systems.ltv.TimeFunction`), :class:`UnknownConstant` or
:class:`UnknownSpline` (a B-spline expansion (23)). The kernel identity (9)
with the kernels (13)-(19) is linear in the unknowns, so at every regression
instant ``t_j``::

    q(t_j) = y(t_j) - r_0(t_j) / C(t_j) = h(t_j) beta                   (28)-(30)

where ``r_0`` collects the kernel integrals that depend on no unknown (the
part of the kernel from the leading coefficient of ``y''``, which (24)/(28)
omit (ERRATA.md), and every known coefficient) and ``C = (t - a)^2 +
(b - t)^2``. The columns of ``h`` are kernel integrals of ``B_k y``,
``B_k' y``, ``B_k u``, ... computed by the cumulative product quadrature of
:mod:`lpvest.estimators.kernels` at *every* sample (the default regression
instants). The least-squares problem is solved by Householder QR of the
column-scaled ``[P, q]`` (no normal equations), optionally with a P-spline
difference penalty whose weight is given or chosen by generalized
cross-validation (GCV). ``P`` (``m x s``, dense) is never formed: between
consecutive starts of the B-splines' supports its rows lie in a space of
dimension about 10, so each such segment is first reduced by a small QR and
only the stacked triangular factors enter the final QR (a TSQR; see
:func:`_compressed_system`). :func:`kernel_regression` returns the dense ``P``.
The rank of ``P`` must equal the number of unknowns (practical
identifiability, Definition 1; the paper's "rank P = 2n"), otherwise
:class:`~lpvest.errors.IdentifiabilityError` names the coefficients the data
do not determine.

With the estimated coefficients, ``y_E`` and ``y_E'`` follow from (9) and the
derivative identity (10) (the derivative kernels, obtained by differentiating
(12) and (15) in ``t``; see :mod:`lpvest.estimators.kernels`), and the state
from (32) (:func:`reconstruct_state`; for the realization
:meth:`~lpvest.systems.ltv.LTVInputOutput.to_state_space`,
``x = (y_E, y_E' + b_1 u)``).

:class:`BSplineObserver` runs the estimator on a sliding window over streaming
samples (a streaming component, :mod:`lpvest.protocol`).

Examples
--------
>>> import numpy as np
>>> from lpvest import load_system
>>> io = load_system("sridhar-ltv").model()
>>> t = np.linspace(0.0, 10.0, 5001)
>>> data = io.simulate(t)
>>> model = KernelModel(a0=UnknownSpline(20), a1=UnknownConstant(), b0=io.b[0])
>>> fit = fit_kernel_model(model, t, data.u, data.y)
>>> round(fit.constants["a1"], 6)
1.0
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ..errors import (
    DimensionError,
    ExpressionError,
    IdentifiabilityError,
    NonFiniteError,
    SamplingError,
    abbreviate,
    shorten,
)
from ..protocol import Component, Port
from ..systems.ltv import LTVInputOutput, LTVStateSpace, TimeFunction
from ..validation import as_vector, check_finite
from .kernels import (
    FREE_MOMENTS,
    MOMENTS,
    SLOT_MOMENTS,
    ProductQuadrature,
    check_uniform_samples as _check_samples,
    coefficient_terms,
    finish_identity,
    free_derivative,
    free_identity,
    moment_rows,
    product_quadrature,
    slot_derivative,
    slot_identity,
    window_weight,
)

__all__ = [
    "COEFFICIENTS",
    "Known",
    "UnknownConstant",
    "UnknownSpline",
    "KernelModel",
    "KernelFit",
    "fit_kernel_model",
    "KernelRegression",
    "kernel_regression",
    "bspline_basis",
    "spline_knots",
    "reconstruct_state",
    "BSplineObserver",
    "observer_supports",
]

#: The coefficients of (11), in this order.
COEFFICIENTS = ("a0", "a1", "b0", "b1")

# -- coefficient declarations ------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Known:
    """A known coefficient: a :class:`~lpvest.systems.ltv.TimeFunction`, a
    formula of ``t``, a number or a callable. Its derivative (needed for
    ``a_1``, ``b_1``) comes from :meth:`TimeFunction.derivative`."""

    function: TimeFunction

    def __init__(self, value: object) -> None:
        object.__setattr__(self, "function", TimeFunction.of(value))  # type: ignore[arg-type]

    def __repr__(self) -> str:
        return f"Known({self.function.text!r})"


@dataclass(frozen=True)
class UnknownConstant:
    """An unknown constant coefficient."""


@dataclass(frozen=True, eq=False)
class UnknownSpline:
    """An unknown coefficient expanded in ``n_basis`` B-splines, (23).

    Parameters
    ----------
    n_basis : int
        Number of B-spline basis functions (the paper's ``n``), at least ``order``.
    order : int, optional
        B-spline order (degree + 1; the paper's ``p``): 3 = quadratic (default).
        Order 1 (piecewise constant) is for ``a_0`` and ``b_0`` only: the
        kernels of ``a_1`` and ``b_1`` need their derivative (10), which a
        piecewise constant function does not have at its knots.
    knots : {"uniform", "clamped"} or array_like, optional
        ``"uniform"`` (default, the paper's "uniform knot sequence"): equally
        spaced knots extended beyond the window so that the splines cover it
        (``n_basis - order + 1`` knot intervals across ``[a, b]``);
        ``"clamped"``: the end knots repeated ``order`` times; or an explicit
        non-decreasing knot vector of length ``n_basis + order`` *relative to
        the window start* (time minus ``a``) that covers the window.
    """

    n_basis: int
    order: int = 3
    knots: str | tuple[float, ...] = "uniform"

    def __init__(self, n_basis: int, order: int = 3, knots: str | Sequence[float] | np.ndarray = "uniform") -> None:
        if isinstance(n_basis, bool) or not isinstance(n_basis, int | np.integer):
            raise DimensionError(f"n_basis must be an integer; found {abbreviate(n_basis, 30)}")
        if isinstance(order, bool) or not isinstance(order, int | np.integer) or not 1 <= order <= 8:
            raise DimensionError(f"order must be an integer in [1, 8]; found {abbreviate(order, 30)}")
        if n_basis < order:
            raise DimensionError(f"n_basis = {n_basis} B-splines of order {order}: need n_basis >= order")
        if isinstance(knots, str):
            if knots not in ("uniform", "clamped"):
                raise DimensionError(
                    f"knots must be 'uniform', 'clamped' or a knot vector; found {abbreviate(knots, 30)}"
                )
            kn: str | tuple[float, ...] = knots
        else:
            arr = as_vector(knots, "knots", int(n_basis) + int(order))
            if np.any(np.diff(arr) < 0):
                raise DimensionError("knots must be non-decreasing")
            kn = tuple(float(v) for v in arr)
        object.__setattr__(self, "n_basis", int(n_basis))
        object.__setattr__(self, "order", int(order))
        object.__setattr__(self, "knots", kn)

    def __repr__(self) -> str:
        k = self.knots if isinstance(self.knots, str) else "<explicit>"
        return f"UnknownSpline(n_basis={self.n_basis}, order={self.order}, knots={k!r})"


Coefficient = Known | UnknownConstant | UnknownSpline


def _as_coefficient(value: object, name: str) -> Coefficient:
    if isinstance(value, Known | UnknownConstant | UnknownSpline):
        return value
    try:
        return Known(value)
    except ExpressionError as exc:
        raise ExpressionError(
            f"{name}: expected Known(...), UnknownConstant(), UnknownSpline(...), a formula of t, "
            f"a number or a callable ({exc})"
        ) from exc


@dataclass(frozen=True, eq=False)
class KernelModel:
    """Which coefficients of (11) are known and how the unknown ones are represented.

    Each of ``a0, a1, b0, b1`` is :class:`Known` (or anything
    :meth:`TimeFunction.of` accepts: a formula, a number, a callable),
    :class:`UnknownConstant` or :class:`UnknownSpline`. ``b1`` defaults to 0
    (no input derivative) and ``b0`` to 0 (no input).

    Examples
    --------
    >>> KernelModel(a0=UnknownSpline(86), a1=UnknownConstant(), b0="-1/(t + 1000)").unknowns
    ('a0', 'a1')
    """

    a0: Coefficient
    a1: Coefficient
    b0: Coefficient = field(default_factory=lambda: Known(0.0))
    b1: Coefficient = field(default_factory=lambda: Known(0.0))

    def __init__(self, a0: object, a1: object, b0: object = 0.0, b1: object = 0.0) -> None:
        for name, value in zip(COEFFICIENTS, (a0, a1, b0, b1), strict=True):
            coefficient = _as_coefficient(value, name)
            if name[1] == "1" and isinstance(coefficient, UnknownSpline) and coefficient.order < 2:
                raise DimensionError(
                    f"{name}: a B-spline of order 1 (piecewise constant) has no derivative, which the kernels of "
                    f"{name} need (10); use order 2 or more"
                )
            object.__setattr__(self, name, coefficient)

    @classmethod
    def from_io(cls, io: LTVInputOutput, **unknown: Coefficient) -> KernelModel:
        """The coefficients of a second-order :class:`LTVInputOutput` as known,
        except those given as keywords (``a0=UnknownSpline(86)``, ...)."""
        if io.order != 2:
            raise DimensionError(
                f"the kernel estimator is for second-order systems (11); the model has order {io.order}"
            )
        bad = sorted(set(unknown) - set(COEFFICIENTS))
        if bad:
            raise DimensionError(f"unknown coefficient name {abbreviate(bad[0], 30)}; expected one of "
                                 f"{', '.join(COEFFICIENTS)}")
        b = (*io.b, *(TimeFunction.of(0.0) for _ in range(2 - len(io.b))))
        known = {"a0": io.a[0], "a1": io.a[1], "b0": b[0], "b1": b[1]}
        known.update(unknown)
        return cls(**known)

    def coefficient(self, name: str) -> Coefficient:
        return getattr(self, name)

    @property
    def unknowns(self) -> tuple[str, ...]:
        """Names of the unknown coefficients, in the order of the columns of ``P``."""
        return tuple(n for n in COEFFICIENTS if not isinstance(getattr(self, n), Known))

    def n_unknowns(self) -> int:
        """Number of unknown scalar coefficients (the paper's ``2n`` in ``rank P = 2n``)."""
        total = 0
        for n in self.unknowns:
            c = getattr(self, n)
            total += c.n_basis if isinstance(c, UnknownSpline) else 1
        return total


# -- B-spline basis ------------------------------------------------------------------------------


def spline_knots(spec: UnknownSpline, length: float) -> np.ndarray:
    """The knot vector of ``spec`` on the window ``[0, length]`` (window coordinates).

    ``"uniform"``: ``t_i = (i - order + 1) * delta``, ``i = 0 .. n_basis + order - 1``,
    ``delta = length / (n_basis - order + 1)``, so that ``[t_{order-1}, t_{n_basis}]
    = [0, length]``.

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


def _span(x: np.ndarray, knots: np.ndarray, order: int) -> np.ndarray:
    """Knot span ``mu`` of each ``x`` (``knots[mu] <= x < knots[mu + 1]``, clipped
    to the spans of the basis): the non-zero B-splines there are ``mu - order + 1 .. mu``."""
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


def _basis_rows(
    x: np.ndarray, knots: np.ndarray, order: int, mu: np.ndarray, *, derivative: bool = False
) -> np.ndarray:
    """The ``order`` B-splines non-zero in the spans ``mu`` (or their derivatives
    (22)) at ``x``: row ``r`` holds ``B_{mu - order + 1 + r}``, shape (order, *x.shape)
    (``mu`` broadcasts against ``x``)."""
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
    order : int
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
    mu = _span(x, knots, order)
    rows = _basis_rows(x, knots, order, mu, derivative=derivative)
    return mu - (order - 1), np.ascontiguousarray(rows.T)


# -- the regression plan (everything that depends on the window geometry, not on the data) -----


@dataclass(frozen=True, eq=False)
class _Block:
    """Columns of ``P`` belonging to one unknown coefficient.

    For a spline block, the *band* of ``B_i`` is the sample intervals where it
    is non-zero, ``jlo[i] .. jhi[i]``; band arrays are (n, width) (intervals
    ``jlo[i] .. jlo[i] + width - 1``, zero beyond ``jhi[i]``).
    """

    name: str
    col: int  #: first column
    size: int
    spline: UnknownSpline | None = None
    knots: np.ndarray | None = None  #: window coordinates
    piece_first: np.ndarray | None = None  #: (P,) first non-zero basis function on each piece
    values: np.ndarray | None = None  #: (order, N) row r: B_{first + r} at the nodes
    dvalues: np.ndarray | None = None  #: (order, N) their derivatives, slot-1 coefficients only
    jlo: np.ndarray | None = None  #: (n_basis,) first interval of each band
    jhi: np.ndarray | None = None  #: (n_basis,) last interval of each band
    width: int = 0  #: band width (intervals): max(jhi - jlo) + 1
    band_slot: np.ndarray | None = None  #: (order * P,) flat (basis, interval - jlo) slot of (r, piece)
    sample_first: np.ndarray | None = None  #: (m,) first non-zero basis at each sample
    sample_values: np.ndarray | None = None  #: (order, m) basis values at the samples


@dataclass(frozen=True, eq=False)
class _Plan:
    model: KernelModel
    quad: ProductQuadrature  #: window coordinates (a = 0)
    blocks: tuple[_Block, ...]
    labels: tuple[str, ...]
    penalty_matrix: np.ndarray  #: (rows, s) difference penalty on the spline blocks

    @property
    def m(self) -> int:
        return self.quad.m

    @property
    def n_unknowns(self) -> int:
        return len(self.labels)


def _difference_matrix(n: int, order: int) -> np.ndarray:
    return np.diff(np.eye(n), n=order, axis=0) if order < n else np.zeros((0, n))


def _spline_block(name: str, col: int, spec: UnknownSpline, quad: ProductQuadrature, length: float) -> _Block:
    """The geometry of one spline block: the basis at the nodes and the samples, and its bands."""
    knots = spline_knots(spec, length)
    n, k = spec.n_basis, spec.order
    m, q = quad.m, quad.nodes_per_piece
    P = quad.piece_interval.size
    # the knots inside the window are piece edges, so each piece lies in one knot span
    x = quad.x.reshape(q, P)
    mu = _span(0.5 * (x[0] + x[-1]), knots, k)  # (P,)
    values = _basis_rows(x, knots, k, mu).reshape(k, -1)
    dvalues = _basis_rows(x, knots, k, mu, derivative=True).reshape(k, -1) if name[1] == "1" else None
    piece_first = mu - (k - 1)
    # the band of B_i: the intervals of the pieces whose span has B_i among its
    # k non-zero B-splines; on the whole intervals (pieces 0 .. m - 2, in order)
    # a run found by bisection, extended by the pieces that split intervals
    basis = np.arange(n)
    whole = piece_first[: m - 1]
    jlo = np.searchsorted(whole + (k - 1), basis, side="left")
    jhi = np.searchsorted(whole, basis, side="right") - 1
    none = jlo > jhi
    jlo[none], jhi[none] = m - 1, -1
    owner = piece_first[m - 1 :] + np.arange(k)[:, None]  # (k, split pieces)
    np.minimum.at(jlo, owner, np.broadcast_to(quad.piece_interval[m - 1 :], owner.shape))
    np.maximum.at(jhi, owner, np.broadcast_to(quad.piece_interval[m - 1 :], owner.shape))
    empty = jhi < jlo  # support outside the window: a zero column, reported by the rank check
    jlo[empty] = np.clip(np.floor(knots[:n][empty] / quad.h), 0, m - 2).astype(np.int64)
    jhi[empty] = jlo[empty]
    width = int(max(1, np.max(jhi - jlo + 1)))
    # piece p adds to B_{first_p + r} on interval j_p: slot (first_p + r, j_p - jlo) of the band array
    owner = piece_first + np.arange(k)[:, None]  # (k, P)
    band_slot = (owner * width + (quad.piece_interval - jlo[owner])).ravel()
    samples = quad.samples
    sample_mu = _span(samples, knots, k)
    sample_values = _basis_rows(samples, knots, k, sample_mu)
    return _Block(
        name, col, n, spec, knots, piece_first, values, dvalues, jlo, jhi, width, band_slot, sample_mu - (k - 1),
        sample_values,
    )


def _build_plan(model: KernelModel, m: int, h: float, *, points: int, difference_order: int) -> _Plan:
    length = (m - 1) * h
    knot_sets = []
    for name in model.unknowns:
        c = model.coefficient(name)
        if isinstance(c, UnknownSpline):
            knot_sets.append(spline_knots(c, length))
    breakpoints = np.concatenate(knot_sets) if knot_sets else np.zeros(0)
    quad = product_quadrature(0.0, h, m, breakpoints=breakpoints, points=points)
    blocks: list[_Block] = []
    labels: list[str] = []
    pen_rows: list[tuple[int, np.ndarray]] = []
    col = 0
    for name in model.unknowns:
        c = model.coefficient(name)
        if isinstance(c, UnknownConstant):
            blocks.append(_Block(name, col, 1))
            labels.append(name)
            col += 1
            continue
        assert isinstance(c, UnknownSpline)
        blocks.append(_spline_block(name, col, c, quad, length))
        n = c.n_basis
        labels.extend(f"{name}[{i}]" for i in range(n))
        pen_rows.append((col, _difference_matrix(n, difference_order)))
        col += n
    D = np.zeros((sum(r.shape[0] for _, r in pen_rows), col))
    row = 0
    for c0, Dk in pen_rows:
        D[row : row + Dk.shape[0], c0 : c0 + Dk.shape[1]] = Dk
        row += Dk.shape[0]
    return _Plan(model, quad, tuple(blocks), tuple(labels), D)


# -- assembly ------------------------------------------------------------------------------------
#
# The columns of P (29)-(30) for one B-spline basis function B_i are kernel
# integrals of B_i y (and B_i' y for a_1, B_i u / B_i' u for the b's). B_i is
# non-zero on the sample intervals jlo_i .. jlo_i + width - 1 (its band), so its
# forward moments vanish before the band and are constant after it, and its
# backward moments the other way round. Because the kernels are linear in t,
# the column is c0 + c1 R(t) before the band, c0' + c1' T(t) after it
# (T = t - a, R = b - t = (b - a) - T), and cumulative band sums in between.
#
# Two consequences: the columns are cheap to form (one pass over each band:
# the pieces' moments, rearranged into one row per basis function and
# cumulated), and on a run of samples (a "segment") every row of P lies in the
# span of [1/C, R/C, the columns of the few basis functions whose band meets
# the segment, the dense columns]. The solve uses this: each segment's rows
# are reduced by a small QR (TSQR), and only the stacked R factors, a few rows
# per segment, enter the final QR. That is O(m r^2) with r ~ 10 instead of
# O(m s^2) for s = 87 unknowns, with the same orthogonal-transformation
# stability as a QR of the full P.


@dataclass(frozen=True, eq=False)
class _Band:
    """Kernel integrals of the basis functions of one spline block (not divided by C)."""

    block: _Block
    mid: np.ndarray  #: (n, width + 1): values at samples jlo_i .. jlo_i + width
    c0b: np.ndarray  #: (n,): column = c0b + c1b R before the band
    c1b: np.ndarray
    c0a: np.ndarray  #: (n,): column = c0a + c1a T after the band
    c1a: np.ndarray


def _band_moments(
    block: _Block, quad: ProductQuadrature, values: np.ndarray, v_nodes: np.ndarray, moments: range
) -> tuple[list[Any], ...]:
    """Moments of ``B_i v`` (``values``: ``B_i`` or ``B_i'`` at the nodes) at the band
    samples, (n, width + 1) rows, and over the whole band, (n,) rows (:func:`moment_rows`)."""
    assert block.band_slot is not None
    n, L, K = block.size, block.width, len(moments)
    k_order, q = values.shape[0], quad.nodes_per_piece
    basis = values.reshape(k_order, q, -1)
    F, B = np.empty((K, n, L + 1)), np.empty((K, n, L + 1))
    weighted = np.empty_like(v_nodes)
    pieces = np.empty(basis.shape[::2])  # (order, P): B_{first + r} v times the moment weight, per piece
    term = np.empty(pieces.shape[1])
    # one moment at a time (large temporaries cost more than the arithmetic here)
    for d, out in ((0, F), (1, B)):
        for kk, k in enumerate(moments):
            wv = np.multiply(quad.moment_weights[d, k], v_nodes, out=weighted).reshape(q, -1)
            for r in range(k_order):
                row = np.multiply(wv[0], basis[r, 0], out=pieces[r])
                for i in range(1, q):
                    row += np.multiply(wv[i], basis[r, i], out=term)
            # per basis function and interval of its band (the pieces of a split interval add up)
            per_interval = np.bincount(block.band_slot, weights=pieces.ravel(), minlength=n * L).reshape(n, L)
            if d == 0:  # forward: the intervals before each band sample
                out[kk, :, 0] = 0.0
                np.cumsum(per_interval, axis=1, out=out[kk, :, 1:])
            else:  # backward: those after it
                out[kk, :, -1] = 0.0
                np.cumsum(per_interval[:, ::-1], axis=1, out=out[kk, :, -2::-1])
    return (
        moment_rows(moments, F), moment_rows(moments, B),
        moment_rows(moments, F[:, :, -1]), moment_rows(moments, B[:, :, 0]),
    )


def _band(block: _Block, quad: ProductQuadrature, v_nodes: np.ndarray) -> _Band:
    """Band moments of every basis function of ``block`` and its column formulas."""
    assert block.values is not None and block.jlo is not None
    n, L, m, h = block.size, block.width, quad.m, quad.h
    order = int(block.name[1])
    F, B, Ft, Bt = _band_moments(block, quad, block.values, v_nodes, SLOT_MOMENTS[order])
    Fd = Bd = Fdt = Bdt = None
    if order == 1 and block.dvalues is not None:
        Fd, Bd, Fdt, Bdt = _band_moments(block, quad, block.dvalues, v_nodes, SLOT_MOMENTS[0])
    zero = np.zeros((MOMENTS, n))
    j = block.jlo[:, None] + np.arange(L + 1)
    mid = slot_identity(order, F, B, j * h, (m - 1 - j) * h, Fd, Bd)
    zd = None if Fd is None else zero
    c0b = slot_identity(order, zero, Bt, 0.0, 0.0, zd, Bdt)
    c1b = slot_identity(order, zero, Bt, 0.0, 1.0, zd, Bdt) - c0b
    c0a = slot_identity(order, Ft, zero, 0.0, 0.0, Fdt, zd)
    c1a = slot_identity(order, Ft, zero, 1.0, 0.0, Fdt, zd) - c0a
    return _Band(block, mid, c0b, c1b, c0a, c1a)


def _band_columns(band: _Band, T: np.ndarray, R: np.ndarray, out: np.ndarray) -> None:
    """Write the dense columns of a spline block into ``out`` (Fortran order)."""
    block = band.block
    assert block.jlo is not None
    m, L = T.size, block.width
    for i in range(block.size):
        j0 = int(block.jlo[i])
        j1 = min(j0 + L, m - 1)
        col = out[:, block.col + i]
        if j0 > 0:
            np.multiply(R[:j0], band.c1b[i], out=col[:j0])
            col[:j0] += band.c0b[i]
        col[j0 : j1 + 1] = band.mid[i, : j1 - j0 + 1]
        if j1 < m - 1:
            np.multiply(T[j1 + 1 :], band.c1a[i], out=col[j1 + 1 :])
            col[j1 + 1 :] += band.c0a[i]


#: The signal each coefficient multiplies: a_i -> y, b_i -> u.
_SIGNAL = {"a": "y", "b": "u"}


def _known_functions(model: KernelModel) -> dict[str, TimeFunction]:
    return {n: model.coefficient(n).function for n in COEFFICIENTS if isinstance(model.coefficient(n), Known)}


@dataclass(frozen=True, eq=False)
class _Parts:
    """The regression (29)-(30) on one window, in factored form."""

    quad: ProductQuadrature
    C: np.ndarray  #: (m,) C_[a,b](t)
    y_nodes: np.ndarray
    u_nodes: np.ndarray
    moments: dict[str, tuple[list[Any], list[Any]]]  #: "y", "u": (F, B) rows of the signal (moment_rows)
    known_ident: np.ndarray  #: free part + known coefficients, identity (9), times C
    known_deriv: np.ndarray  #: the same for the derivative identity (10)
    functions: dict[str, TimeFunction]  #: the known coefficients
    dense: np.ndarray  #: (m, nd) columns of the unknown constants, then q; divided by C
    dense_cols: np.ndarray  #: (nd,) their column index in [P, q]
    bands: tuple[_Band, ...]


def _check_known(
    name: str, f: TimeFunction, samples: np.ndarray, nodes: np.ndarray, phi: np.ndarray, dphi: np.ndarray | None
) -> None:
    """A known coefficient (and the derivative the kernels use) must be finite
    at every sample and quadrature node of the window: a pole there (``b0 =
    1/(t - 2)`` at ``t = 2``) is a clear error, not an infinite estimate."""
    for what, values, where in ((name, phi, nodes), (f"{name}'", dphi, nodes),
                                (name, None if f.is_constant else f(samples), samples)):
        if values is None:
            continue
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise NonFiniteError(
                f"the known coefficient {what} = {shorten(f.text, 40)} is {values[bad[0]]} at "
                f"t = {where[bad[0]]:.10g} (in the window [{samples[0]:.6g}, {samples[-1]:.6g}]); "
                "expected finite values"
            )


def _hull(*moments: range) -> range:
    """The smallest range of moments holding all of ``moments``."""
    return range(min(r.start for r in moments), max(r.stop for r in moments))


def _parts(plan: _Plan, a: float, u: np.ndarray, y: np.ndarray) -> _Parts:
    quad = plan.quad.shifted(a)
    t = quad.samples
    T = t - a
    R = quad.b - t
    C = window_weight(t, a, quad.b)
    y_nodes = quad.interpolate(y)
    u_nodes = quad.interpolate(u)
    # the moments of y (and u) that the free part and the unknown constants read
    const = [b for b in plan.blocks if b.spline is None]
    y_const = [SLOT_MOMENTS[int(b.name[1])] for b in const if b.name[0] == "a"]
    u_const = [SLOT_MOMENTS[int(b.name[1])] for b in const if b.name[0] == "b"]
    moments = {"y": quad.cumulative_rows(y_nodes, _hull(FREE_MOMENTS, *y_const))}
    if u_const:
        moments["u"] = quad.cumulative_rows(u_nodes, _hull(*u_const))
    Fy, By = moments["y"]
    known = free_identity(Fy, By, T, R)
    known_d = free_derivative(Fy, By)
    funcs = _known_functions(plan.model)
    for name, f in funcs.items():
        phi = f(quad.x)
        dphi = f.derivative()(quad.x) if name[1] == "1" and not f.is_constant else None
        _check_known(name, f, t, quad.x, phi, dphi)
        if not np.any(phi) and (dphi is None or not np.any(dphi)):
            continue
        ident, deriv = coefficient_terms(quad, int(name[1]), phi, dphi, y_nodes if name[0] == "a" else u_nodes)
        known, known_d = known + ident, known_d + deriv
    dense = np.empty((quad.m, len(const) + 1), order="F")
    for k, block in enumerate(const):
        F, B = moments[_SIGNAL[block.name[0]]]
        dense[:, k] = slot_identity(int(block.name[1]), F, B, T, R) / C
    dense[:, -1] = y - known / C
    dense_cols = np.array([b.col for b in const] + [plan.n_unknowns], dtype=np.int64)
    bands = tuple(
        _band(b, quad, y_nodes if b.name[0] == "a" else u_nodes) for b in plan.blocks if b.spline is not None
    )
    return _Parts(quad, C, y_nodes, u_nodes, moments, known, known_d, funcs, dense, dense_cols, bands)


def _dense_system(plan: _Plan, parts: _Parts) -> np.ndarray:
    """``[P, q]`` as one Fortran-ordered array of shape (m, s + 1)."""
    quad = parts.quad
    t = quad.samples
    A = np.empty((quad.m, plan.n_unknowns + 1), order="F")
    for band in parts.bands:
        _band_columns(band, t - quad.a, quad.b - t, A)
        A[:, band.block.col : band.block.col + band.block.size] /= parts.C[:, None]
    A[:, parts.dense_cols] = parts.dense
    return A


def _compressed_system(plan: _Plan, parts: _Parts, rows: np.ndarray | None) -> np.ndarray:
    """A matrix ``K`` with ``K^T K = A^T A`` for ``A = [P, q]`` restricted to the
    rows ``rows`` (``None``: all), by a QR of each segment's rows (see above)."""
    quad = parts.quad
    m = quad.m
    s = plan.n_unknowns
    length = quad.b - quad.a
    t = quad.samples
    T, R = t - quad.a, quad.b - t
    inv_c = 1.0 / parts.C
    # segments run from one band start to the next (of any spline block): a
    # segment meets the bands of about `order` + 1 basis functions per block
    edges = [np.array([0, m])]
    for band in parts.bands:
        assert band.block.jlo is not None
        edges.append(band.block.jlo)
    e = np.unique(np.clip(np.concatenate(edges), 0, m))
    # split long segments (the row partition is free within a segment) so that
    # padding every segment to the longest one costs at most about 5 m rows
    chunk = max(32, 4 * -(-m // max(e.size - 1, 1)))
    pieces = -(-np.diff(e) // chunk)
    within = np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    starts = np.repeat(e[:-1], pieces) + chunk * within
    ends = np.minimum(np.append(starts[1:], m), np.repeat(e[1:], pieces))
    K = starts.size
    lens = ends - starts
    Lseg = int(np.max(lens))
    # the rows of each segment, padded with copies of its last row (weight 0)
    idx = np.minimum(starts[:, None] + np.arange(Lseg), (ends - 1)[:, None])
    valid = np.arange(Lseg) < lens[:, None]
    if rows is not None:
        mask = np.zeros(m, dtype=bool)
        mask[rows] = True
        valid &= mask[idx]
    w = valid.astype(float)
    weight = inv_c[idx] * w  # rows of P are divided by C
    # the basis functions whose band (samples jlo_i .. jhi_i + 1) meets each segment: a run of i
    slots = []
    for band in parts.bands:
        block = band.block
        assert block.jlo is not None and block.jhi is not None
        i_first = np.searchsorted(block.jhi + 1, starts, side="left")
        i_last = np.searchsorted(block.jlo, ends - 1, side="right") - 1
        count = np.maximum(i_last - i_first + 1, 0)
        slots.append((band, i_first, count, int(np.max(count)) if count.size else 0))
    n_band = sum(c for *_, c in slots)
    nd = parts.dense.shape[1]
    r = 2 + n_band + nd
    W = np.zeros((K, Lseg, r))
    W[:, :, 0] = weight
    W[:, :, 1] = R[idx] * weight
    M = np.zeros((K, r, s + 1))
    col = 2
    ks = np.arange(K)
    for band, i_first, count, nmax in slots:
        block = band.block
        assert block.jlo is not None and block.jhi is not None
        jlo, L, n = block.jlo, block.width, block.size
        # the other columns are linear in 1/C, R/C on the segment: the segment
        # lies before their band or after it
        before = (ends - 1)[:, None] < jlo[None, :]
        after = starts[:, None] > (block.jhi + 1)[None, :]
        cols = slice(block.col, block.col + n)
        M[:, 0, cols] = np.where(before, band.c0b, 0.0) + np.where(after, band.c0a + length * band.c1a, 0.0)
        M[:, 1, cols] = np.where(before, band.c1b, 0.0) - np.where(after, band.c1a, 0.0)
        for slot in range(nmax):
            ok = slot < count
            i = np.where(ok, i_first + slot, 0)[:, None]
            off = idx - jlo[i]  # the column: band values (mid) on its band, linear before and after
            column = np.take(band.mid, i * (L + 1) + np.clip(off, 0, L))
            if np.any(off < 0):
                column = np.where(off < 0, band.c1b[i] * R[idx] + band.c0b[i], column)
            if np.any(off > L):
                column = np.where(off > L, band.c1a[i] * T[idx] + band.c0a[i], column)
            np.multiply(column, weight * ok[:, None], out=W[:, :, col])
            M[ks[ok], col, block.col + i[ok, 0]] = 1.0
            col += 1
    for k in range(nd):
        W[:, :, col + k] = parts.dense[:, k][idx] * w
    M[:, np.arange(col, r), parts.dense_cols] = 1.0
    Rk = np.linalg.qr(W, mode="r")
    return (Rk @ M).reshape(-1, s + 1)


# -- the solve -----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class KernelFit:
    """The result of :func:`fit_kernel_model` on one window ``[a, b]``.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Sample times.
    window : tuple of float
        ``(a, b)``.
    y, dy : ndarray, shape (m,)
        ``y_E`` from (9) and ``y_E'`` from the derivative identity (10), with
        the estimated coefficients.
    x : ndarray, shape (m, 2)
        State of the realization :meth:`LTVInputOutput.to_state_space`
        (``x_1 = y``, ``x_2 = y' + b_1 u``), (32).
    values : dict of str to ndarray, shape (m,)
        ``a0, a1, b0, b1`` (known or estimated) at the samples.
    coefficients : dict of str to TimeFunction
        All four coefficients as functions of time (estimated splines as
        scipy ``BSpline`` objects with their exact derivative).
    constants : dict of str to float
        The estimated unknown constants.
    splines : dict of str to scipy.interpolate.BSpline
        The estimated B-spline coefficients (absolute time).
    beta : ndarray, shape (s,)
        All unknown scalar coefficients, labelled by ``labels``.
    labels : tuple of str
        ``"a0[k]"`` for spline coefficients, ``"a1"`` for a constant.
    residual_rms : float
        Root mean square of ``q - P beta`` over the regression instants.
    penalty : float
        Penalty weight ``lambda`` used (0: plain least squares).
    edf : float
        Effective degrees of freedom (trace of the hat matrix; ``s`` without penalty).
    gcv : float
        GCV score ``m * RSS / (m - edf)^2`` at ``penalty``.
    singular_values : ndarray, shape (s,)
        Singular values of the column-scaled ``P`` (identifiability margin).
    instants : ndarray of int
        Sample indices used as regression instants.
    """

    t: np.ndarray
    window: tuple[float, float]
    y: np.ndarray
    dy: np.ndarray
    x: np.ndarray
    values: dict[str, np.ndarray]
    coefficients: dict[str, TimeFunction]
    constants: dict[str, float]
    splines: dict[str, Any]
    beta: np.ndarray
    labels: tuple[str, ...]
    residual_rms: float
    penalty: float
    edf: float
    gcv: float
    singular_values: np.ndarray
    instants: np.ndarray

    @property
    def condition(self) -> float:
        """Condition number of the column-scaled ``P``."""
        return float(self.singular_values[0] / self.singular_values[-1])


def _instant_indices(instants: object, m: int) -> np.ndarray:
    if instants is None:
        return np.arange(m)
    if isinstance(instants, int | np.integer) and not isinstance(instants, bool):
        if instants < 1:
            raise DimensionError(f"instants (a stride) must be >= 1; found {instants}")
        return np.arange(0, m, int(instants))
    idx = np.asarray(instants)
    if idx.ndim != 1 or idx.dtype.kind not in "iu":
        raise DimensionError(f"instants must be None, a stride or a 1-D array of sample indices; found "
                             f"{abbreviate(instants, 30)}")
    if idx.size and (idx.min() < 0 or idx.max() >= m):
        raise DimensionError(f"instants hold sample indices outside [0, {m - 1}]")
    if np.unique(idx).size != idx.size:
        raise DimensionError("instants must be distinct sample indices")
    return np.sort(idx)


def _unidentifiable_message(plan: _Plan, participation: np.ndarray, reason: str) -> str:
    names = []
    for block in plan.blocks:
        part = participation[block.col : block.col + block.size]
        if np.any(part):
            if block.spline is None:
                names.append(block.name)
            else:
                idx = np.flatnonzero(part)
                which = ", ".join(str(i) for i in idx[:8]) + (", ..." if idx.size > 8 else "")
                names.append(f"{block.name} (B-spline basis functions {which})")
    return f"{reason}; the data do not determine: {'; '.join(names)} (practical identifiability, Definition 1)"


def _check_excitation(plan: _Plan, u: np.ndarray, y: np.ndarray) -> None:
    """The coefficients of a signal that is zero (to round-off, relative to its
    own peak) on every sample farther than one interpolation stencil from the
    window's ends are not determined by the data.

    Every kernel vanishes at both ends (as ``s^2``, ``r^2`` for ``a_0``, ``b_0``
    and as ``s``, ``r`` for ``a_1``, ``b_1``), and within a stencil of an end
    the quadrature sees the signal only through the interpolation of those few
    samples: such a column of ``P`` is nonzero (about ``(h / L)^2`` of a
    column of a signal spread over the window, so the rank test of the scaled
    ``P`` passes it) but it is quadrature error, not information. Example: an
    input nonzero at the last sample only (an input switched on as the window
    ends) gave ``b0 = -0.006`` for a true ``-9``.
    """
    m, edge = plan.m, plan.quad.points
    eps = np.finfo(float).eps
    for letter, name, v in (("a", "output y", y), ("b", "input u", u)):
        names = [b.name for b in plan.blocks if b.name[0] == letter]
        peak = float(np.max(np.abs(v))) if v.size else 0.0
        if not names or peak == 0.0:  # a zero signal: its columns of P are zero, reported below
            continue
        interior = float(np.max(np.abs(v[edge : m - edge]))) if m > 2 * edge else 0.0
        if interior <= m * eps * peak:
            raise IdentifiabilityError(
                f"the {name} is zero except within {edge} samples of the window's ends (where the kernels "
                f"vanish; what remains there is quadrature error); the data do not determine: "
                f"{', '.join(names)} (practical identifiability, Definition 1)"
            )


def _rank_check(plan: _Plan, R: np.ndarray, rtol: float) -> np.ndarray:
    """Singular values of the scaled ``P`` (from its R factor); raise when the rank is deficient."""
    s = R.shape[1]
    sv = np.linalg.svd(R, compute_uv=False)
    if sv[-1] <= rtol * sv[0]:
        _, sv, vt = np.linalg.svd(R)  # the null space names the coefficients
        null = vt[sv <= rtol * sv[0]]
        part = np.max(null**2, axis=0) > 0.05 / s
        raise IdentifiabilityError(
            _unidentifiable_message(
                plan, part, f"rank P = {int(np.sum(sv > rtol * sv[0]))} < {s} unknowns "
                f"(singular value ratio {sv[-1] / sv[0]:.3g} <= rank_rtol = {rtol:g})"
            )
        )
    return sv


def _penalized_solve(R: np.ndarray, z: np.ndarray, D: np.ndarray, lam: float) -> tuple[np.ndarray, float]:
    """Minimise ``|z - R g|^2 + lam |D g|^2``; return ``g`` and the trace of the hat matrix."""
    from scipy.linalg import solve_triangular

    s = R.shape[1]
    if lam == 0.0 or D.shape[0] == 0:
        return solve_triangular(R, z), float(s)
    M = np.vstack([R, np.sqrt(lam) * D])
    Q2, R2 = np.linalg.qr(M)
    g = solve_triangular(R2, Q2[:s].T @ z)
    return g, float(np.sum(Q2[:s] ** 2))


def _choose_penalty(R: np.ndarray, z: np.ndarray, rho2: float, D: np.ndarray, m: int) -> float:
    """The GCV choice of lambda: a log grid, then golden-section refinement.

    The score comes from one SVD (Demmler-Reinsch form): with ``h = R g`` the
    problem is ``min |z - h|^2 + lam |S h|^2``, ``S = D R^-1 = U diag(sigma) V^T``,
    so in the coordinates ``V^T`` each component of ``V^T z`` is shrunk by
    ``1 / (1 + lam sigma_i^2)``: the residual and the trace of the hat matrix
    are sums over ``i``, O(s) per lambda. (The fit at the chosen lambda is then
    solved by :func:`_penalized_solve`, a QR.)
    """
    from scipy.linalg import solve_triangular

    s = R.shape[1]
    scale = float(np.sum(R**2) / max(np.sum(D**2), 1e-300))
    sigma2 = np.zeros(s)
    zhat2 = z**2
    if D.shape[0]:
        V, sigma, _ = np.linalg.svd(solve_triangular(R, D.T, trans="T"))  # S^T = V diag(sigma) U^T
        sigma2[: sigma.size] = sigma**2
        zhat2 = (V.T @ z) ** 2

    def gcv(log_lam: float) -> float:
        keep = 1.0 / (1.0 + scale * 10.0**log_lam * sigma2)
        rss = float(np.sum((1.0 - keep) ** 2 * zhat2)) + rho2
        edf = float(np.sum(keep))
        return m * rss / max(m - edf, 1e-12) ** 2

    grid = np.linspace(-14.0, 4.0, 37)
    scores = np.array([gcv(v) for v in grid])
    k = int(np.argmin(scores))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    fc, fd = gcv(c), gcv(d)
    for _ in range(30):
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - ratio * (hi - lo)
            fc = gcv(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + ratio * (hi - lo)
            fd = gcv(d)
    best = min([(fc, c), (fd, d), (scores[k], grid[k])])
    return scale * 10.0 ** best[1]


def _combine(values: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """``sum_r values[r] * coef[r]`` over the rows of (order, N) arrays."""
    out = values[0] * coef[0]
    for r in range(1, values.shape[0]):
        out += values[r] * coef[r]
    return out


def _fitted(
    plan: _Plan, terms: _Parts, beta: np.ndarray, u: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, TimeFunction], dict[str, float], dict[str, Any], np.ndarray, np.ndarray]:
    """Every coefficient (known or estimated) at the samples and as a function,
    and ``y_E``, ``y_E'`` from (9), (10) with the estimated coefficients."""
    from scipy.interpolate import BSpline

    quad = terms.quad
    t = quad.samples
    T, R = t - quad.a, quad.b - t
    sample_values = {name: f(t) for name, f in terms.functions.items()}
    functions = dict(terms.functions)
    constants: dict[str, float] = {}
    splines: dict[str, Any] = {}
    ident = terms.known_ident.copy()
    deriv = terms.known_deriv.copy()
    for block in plan.blocks:
        coef = beta[block.col : block.col + block.size]
        order = int(block.name[1])
        if block.spline is None:
            value = float(coef[0])
            constants[block.name] = value
            sample_values[block.name] = np.full(quad.m, value)
            functions[block.name] = TimeFunction.of(value)
            F, B = terms.moments[_SIGNAL[block.name[0]]]
            ident += value * slot_identity(order, F, B, T, R)
            deriv += value * slot_derivative(order, F, B)
            continue
        assert block.piece_first is not None and block.values is not None and block.knots is not None
        k = block.spline.order
        # the coefficients of the non-zero B-splines at each node
        q = quad.nodes_per_piece
        at_pieces = coef[block.piece_first + np.arange(k)[:, None]]  # (k, P)
        phi = _combine(block.values.reshape(k, q, -1), at_pieces[:, None]).ravel()
        dphi = None
        if block.dvalues is not None:
            dphi = _combine(block.dvalues.reshape(k, q, -1), at_pieces[:, None]).ravel()
        v_nodes = terms.y_nodes if block.name[0] == "a" else terms.u_nodes
        di, dd = coefficient_terms(quad, order, phi, dphi, v_nodes)
        ident += di
        deriv += dd
        assert block.sample_first is not None and block.sample_values is not None
        sample_values[block.name] = _combine(block.sample_values, coef[block.sample_first + np.arange(k)[:, None]])
        spline = BSpline(block.knots + quad.a, coef.copy(), k - 1, extrapolate=True)
        splines[block.name] = spline
        # (order 1: piecewise constant, derivative zero between the knots)
        derivative = spline.derivative() if k > 1 else (lambda x: np.zeros_like(np.asarray(x, dtype=float)))
        functions[block.name] = TimeFunction.from_callable(
            spline, derivative=derivative, name=f"B-spline estimate of {block.name}"
        )
    y_e, dy_e = finish_identity(quad, ident, deriv, sample_values["a1"], sample_values["b1"], u)
    return sample_values, functions, constants, splines, y_e, dy_e


def _fit(
    plan: _Plan,
    a: float,
    u: np.ndarray,
    y: np.ndarray,
    *,
    penalty: float | str | None,
    instants: np.ndarray,
    rank_rtol: float,
) -> KernelFit:
    from scipy.linalg import qr

    _check_excitation(plan, u, y)
    parts = _parts(plan, a, u, y)
    s = plan.n_unknowns
    mi = instants.size
    if mi < s:
        raise IdentifiabilityError(
            f"{mi} regression instants for {s} unknown coefficients: need at least {s} (Definition 1, m >= 2n)"
        )
    A = _compressed_system(plan, parts, None if mi == plan.m else instants)
    scale = np.sqrt(np.einsum("ij,ij->j", A[:, :s], A[:, :s]))
    if not (np.all(np.isfinite(scale)) and np.all(np.isfinite(A[:, s]))):
        raise NonFiniteError(
            "the kernel regression holds non-finite values: check that the known coefficients are finite on "
            f"the window [{parts.quad.a:.6g}, {parts.quad.b:.6g}]"
        )
    tiny = scale <= 1e-300 + 1e-14 * float(np.max(scale))
    if np.any(tiny):
        raise IdentifiabilityError(
            _unidentifiable_message(plan, tiny, "columns of P are zero (the data do not excite these coefficients)")
        )
    A[:, :s] /= scale
    (_, _), Raug = qr(A, mode="raw", overwrite_a=True, check_finite=False)
    R = Raug[:s, :s]
    z = Raug[:s, s]
    rho2 = float(Raug[s, s] ** 2) if Raug.shape[0] > s else 0.0
    sv = _rank_check(plan, R, rank_rtol)
    D = plan.penalty_matrix / scale
    if penalty is None or penalty == 0.0:
        lam = 0.0
    elif isinstance(penalty, str):
        lam = _choose_penalty(R, z, rho2, D, mi)
    else:
        lam = float(penalty)
    g, edf = _penalized_solve(R, z, D, lam)
    rss = float(np.sum((z - R @ g) ** 2)) + rho2
    gcv = mi * rss / max(mi - edf, 1e-12) ** 2
    beta = g / scale
    values, functions, constants, splines, y_e, dy_e = _fitted(plan, parts, beta, u)
    x = np.column_stack([y_e, dy_e + values["b1"] * u])
    return KernelFit(
        t=parts.quad.samples,
        window=(parts.quad.a, parts.quad.b),
        y=y_e,
        dy=dy_e,
        x=x,
        values=values,
        coefficients=functions,
        constants=constants,
        splines=splines,
        beta=beta,
        labels=plan.labels,
        residual_rms=float(np.sqrt(rss / mi)),
        penalty=lam,
        edf=edf,
        gcv=float(gcv),
        singular_values=sv,
        instants=instants,
    )


def _check_options(penalty: object, difference_order: int, rank_rtol: float) -> None:
    if penalty is not None and not (isinstance(penalty, str) and penalty == "gcv"):
        if isinstance(penalty, bool) or not isinstance(penalty, int | float) or not np.isfinite(penalty) or penalty < 0:
            raise DimensionError(f"penalty must be None, 'gcv' or a finite lambda >= 0; found "
                                 f"{abbreviate(penalty, 30)}")
    if isinstance(difference_order, bool) or not isinstance(difference_order, int) or difference_order < 1:
        raise DimensionError(f"difference_order must be an integer >= 1; found {abbreviate(difference_order, 30)}")
    if not 0 < rank_rtol < 1:
        raise DimensionError(f"rank_rtol must lie in (0, 1); found {abbreviate(rank_rtol, 30)}")


def fit_kernel_model(
    model: KernelModel,
    t: object,
    u: object,
    y: object,
    *,
    penalty: float | str | None = None,
    difference_order: int = 2,
    instants: int | Sequence[int] | np.ndarray | None = None,
    points: int = 6,
    rank_rtol: float = 1e-9,
) -> KernelFit:
    """Estimate the unknown coefficients and the state on one window, (28)-(32).

    Parameters
    ----------
    model : KernelModel
        Which coefficients are known, constant or B-splines.
    t : array_like, shape (m,)
        Uniformly spaced sample times; the estimation window is ``[t[0], t[-1]]``.
    u, y : array_like, shape (m,)
        Known input and measured output at ``t``.
    penalty : None, float or "gcv", optional
        P-spline penalty: the objective is
        ``sum_j (q_j - P_j beta)^2 + lambda * sum |Delta^d beta_spline|^2`` over
        the regression instants and the B-spline blocks (constants are not
        penalised). ``None`` (default): plain least squares; a number: that
        ``lambda``; ``"gcv"``: ``lambda`` minimising the GCV score.
    difference_order : int, optional
        ``d`` of the difference penalty (default 2).
    instants : None, int or array of int, optional
        Regression instants: every sample (default), every k-th sample, or
        these sample indices.
    points : int, optional
        Order of the cumulative product quadrature (even, default 6; see
        :mod:`lpvest.estimators.kernels`).
    rank_rtol : float, optional
        ``P`` (column-scaled) is rank deficient when its smallest singular
        value is at most ``rank_rtol`` times the largest.

    Returns
    -------
    KernelFit

    Raises
    ------
    NonFiniteError
        NaN or inf in ``t``, ``u`` or ``y``.
    SamplingError
        ``t`` not strictly increasing or not uniformly spaced.
    DimensionError
        Wrong lengths, or fewer samples than the quadrature stencil.
    IdentifiabilityError
        Fewer regression instants than unknowns, or ``rank P`` below the
        number of unknowns (Definition 1); the message names the coefficients.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 6.0, 3001)
    >>> y = np.exp(-0.5 * t) * np.sin(2 * t)     # y'' + y' + 4.25 y = 0
    >>> fit = fit_kernel_model(KernelModel(a0=UnknownConstant(), a1=UnknownConstant()), t, 0 * t, y)
    >>> round(fit.constants["a0"], 8), round(fit.constants["a1"], 8)
    (4.25, 1.0)
    """
    if not isinstance(model, KernelModel):
        raise DimensionError(f"model must be a KernelModel; found {type(model).__name__}")
    _check_options(penalty, difference_order, rank_rtol)
    times, h = _check_samples(t, "t")
    uu = as_vector(u, "u", times.size)
    yy = as_vector(y, "y", times.size)
    if not model.unknowns:
        raise IdentifiabilityError("the model has no unknown coefficient: nothing to estimate")
    plan = _build_plan(model, times.size, h, points=points, difference_order=difference_order)
    idx = _instant_indices(instants, times.size)
    return _fit(plan, float(times[0]), uu, yy, penalty=penalty, instants=idx, rank_rtol=rank_rtol)


def observer_supports(model: object) -> str | None:
    """Why :class:`BSplineObserver` cannot estimate ``model`` (``None`` when
    it can): the kernel identity (9) is for second-order input-output models."""
    if not isinstance(model, LTVInputOutput):
        return f"the B-spline observer needs an ltv-io model, not a {type(model).__name__}"
    if model.order != 2:
        return f"the B-spline observer is for second-order models (11); this one has order {model.order}"
    return None


class KernelRegression(NamedTuple):
    """The linear system (29)-(30) ``q = P beta`` at every sample."""

    t: np.ndarray  #: sample times, shape (m,)
    P: np.ndarray  #: shape (m, s): kernel integrals of the basis functions, divided by C
    q: np.ndarray  #: shape (m,): ``y - r_0 / C`` (known part on the left-hand side)
    labels: tuple[str, ...]  #: the unknown each column multiplies


def kernel_regression(
    model: KernelModel, t: object, u: object, y: object, *, points: int = 6
) -> KernelRegression:
    """The regression matrix ``P`` and target ``q`` of (29)-(30), dense.

    :func:`fit_kernel_model` never forms ``P`` (it reduces it segment by
    segment); this is for inspection and for checking the solve.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 6.0, 601)
    >>> y = np.exp(-0.5 * t) * np.sin(2 * t)     # y'' + y' + 4.25 y = 0
    >>> reg = kernel_regression(KernelModel(a0=UnknownConstant(), a1=1.0), t, 0 * t, y)
    >>> reg.P.shape, reg.labels
    ((601, 1), ('a0',))
    >>> beta = np.linalg.lstsq(reg.P, reg.q, rcond=None)[0]
    >>> round(float(beta[0]), 8)
    4.25
    """
    if not isinstance(model, KernelModel):
        raise DimensionError(f"model must be a KernelModel; found {type(model).__name__}")
    times, h = _check_samples(t, "t")
    uu = as_vector(u, "u", times.size)
    yy = as_vector(y, "y", times.size)
    if not model.unknowns:
        raise IdentifiabilityError("the model has no unknown coefficient: nothing to estimate")
    plan = _build_plan(model, times.size, h, points=points, difference_order=2)
    A = _dense_system(plan, _parts(plan, float(times[0]), uu, yy))
    s = plan.n_unknowns
    return KernelRegression(plan.quad.shifted(float(times[0])).samples, np.ascontiguousarray(A[:, :s]),
                            A[:, s].copy(), plan.labels)


# -- state reconstruction, (4) / (32) ------------------------------------------------------------


def reconstruct_state(
    realization: LTVStateSpace, t: object, y: object, dy: object, u: object
) -> np.ndarray:
    """The state from the output and its derivative, (4) and (32) for ``n = 2``::

        x = [Gamma_0; Gamma_1]^-1 ([y; y'] - [0; Delta_11 u]),
        Gamma_0 = C,  Gamma_1 = C A + C',  Delta_11 = C B.

    Parameters
    ----------
    realization : LTVStateSpace
        A second-order realization. ``C'`` comes from its formulas, or by the
        complex step for callables; a callable that returns the same real
        matrix at nearby times (a constant map) has ``C' = 0``.
    t, y, dy, u : array_like, shape (m,)

    Returns
    -------
    ndarray, shape (m, 2)

    Examples
    --------
    >>> from lpvest import load_system
    >>> ss = load_system("sridhar-ltv").model("state_space")
    >>> reconstruct_state(ss, [1.0], [0.3], [-0.2], [5.0]).round(12)
    array([[ 0.3, -0.2]])
    """
    times = as_vector(t, "t")
    m = times.size
    yy, dd, uu = (as_vector(v, n, m) for v, n in ((y, "y"), (dy, "dy"), (u, "u")))
    if realization.n != 2:
        raise DimensionError(f"reconstruct_state is for second-order realizations; this one has n = {realization.n}")
    fc = realization.formulas.get("C")
    if fc is not None:
        dC_of = fc.derivative("t")

        def dC(tt: float) -> np.ndarray:
            return dC_of.evaluate({"t": np.asarray(tt, dtype=float)})
    else:

        def dC(tt: float) -> np.ndarray:
            hh = 1e-20
            val = np.asarray(realization.C(tt + 1j * hh))  # type: ignore[arg-type]
            if np.iscomplexobj(val):
                return val.imag / hh
            # a callable that ignores its argument (e.g. the constant output map of
            # LTVInputOutput.to_state_space): constant if it is at nearby times
            step = 1e-3 * (1.0 + abs(tt))
            c0 = np.asarray(realization.C(tt), dtype=float)
            if all(np.array_equal(np.asarray(realization.C(tt + d), dtype=float), c0) for d in (-step, step)):
                return np.zeros_like(c0)
            raise DimensionError(
                "C(t) is a time-varying callable without complex-step support: give C as formulas of t"
            )

    x = np.empty((m, 2))
    for k, tk in enumerate(times):
        C = np.asarray(realization.C(tk), dtype=float)
        G = np.vstack([C, C @ realization.A(tk) + dC(tk)])
        rhs = np.array([yy[k], dd[k] - float((C @ realization.B(tk))[0, 0]) * uu[k]])
        x[k] = np.linalg.solve(G, rhs)
    check_finite(x, "reconstructed state")
    return x


# -- streaming: the sliding-window observer ------------------------------------------------------


def _samples_of(duration: float, dt: float, name: str) -> int:
    if isinstance(duration, bool) or not isinstance(duration, int | float) or not duration > 0 or duration == np.inf:
        raise DimensionError(f"{name} must be a positive duration in seconds; found {abbreviate(duration, 30)}")
    k = duration / dt
    if abs(k - round(k)) > 1e-6 * max(1.0, k):
        raise SamplingError(f"{name} = {abbreviate(duration, 30)} s is not a whole number of sample steps dt "
                            f"= {abbreviate(dt, 30)} s")
    return int(round(k))


class BSplineObserver(Component):
    """Sliding-window joint parameter and state estimator (the observer FMU's engine).

    Samples arrive at a fixed step ``dt`` (time is *not* an input: sample
    ``k`` is at ``t_k = t0 + k dt``; known coefficients are evaluated at these
    times). The window holds the last ``L = window / dt + 1`` samples. Once it
    is full, and then every ``hop`` seconds, the estimator is fitted on the
    window ``[t_k - window, t_k]`` (:func:`fit_kernel_model`).

    **Delay.** Estimates are reported at the window's inner point
    ``t_k - delay`` with the constant ``delay = window - report_index * dt``,
    ``report_index = round(report * (L - 1))`` (``report = 0.5``: the window's
    centre, ``delay = window / 2``), where the B-spline estimate is reliable
    (the paper's inner window). Between refits, sample ``k`` reports the last
    fit at ``t_k - delay``, which stays inside that fit's window because
    ``hop <= delay + dt``. ``valid`` is 0 until the first window is full
    (outputs 0 then); the first valid output comes at ``t0 + window``. The
    estimates at sample ``k`` already use ``y_k`` (no extra step of delay).

    Ports
    -----
    inputs: ``u`` (1,), ``y`` (1,).
    outputs: ``t_est`` (1,) the time the estimates refer to, ``yhat`` (1,)
    ``y_E(t_est)``, ``dyhat`` (1,) ``y_E'(t_est)``, ``xhat`` (2,) the state of
    :meth:`LTVInputOutput.to_state_space` (``x_1 = y``, ``x_2 = y' + b_1 u``),
    ``a0, a1, b0, b1`` (1,) each the coefficients at ``t_est`` (known ones
    echo their value), ``valid`` (1,) 1.0 when the estimates are current.

    Parameters
    ----------
    model : KernelModel
        Unknown splines must use ``"uniform"`` or ``"clamped"`` knots (they
        are placed per window) or window-relative explicit knots.
    dt : float
        Sample time (s).
    window : float
        Window length (s), a multiple of ``dt``.
    hop : float, optional
        Time between refits (s), a multiple of ``dt``; default ``dt`` (refit at
        every sample). At most ``delay + dt``.
    t0 : float, optional
        Time of the first sample.
    report : float, optional
        Position of the reporting point in the window, in ``[0, 1]``
        (default 0.5, the centre).
    penalty, difference_order, points, rank_rtol
        As in :func:`fit_kernel_model`.
    on_unidentifiable : {"raise", "hold"}, optional
        When a window is not identifiable: raise
        :class:`~lpvest.errors.IdentifiabilityError` (default; the sample is
        rejected and the observer unchanged) or hold the last estimates with
        ``valid = 0``.

    Examples
    --------
    >>> import numpy as np
    >>> from lpvest import load_system
    >>> from lpvest.protocol import run_streaming
    >>> io = load_system("sridhar-ltv").model()
    >>> t = np.arange(0, 801) * 0.005
    >>> d = io.simulate(t)
    >>> obs = BSplineObserver(KernelModel.from_io(io, a1=UnknownConstant()), dt=0.005, window=2.0, hop=0.5)
    >>> out = run_streaming(obs, {"u": d.u[:, None], "y": d.y[:, None]})
    >>> obs.delay, bool(out["valid"][400, 0]), bool(out["valid"][399, 0])
    (1.0, True, False)
    >>> bool(abs(out["a1"][-1, 0] - 1.0) < 1e-6)
    True
    """

    def __init__(
        self,
        model: KernelModel,
        *,
        dt: float,
        window: float,
        hop: float | None = None,
        t0: float = 0.0,
        report: float = 0.5,
        penalty: float | str | None = None,
        difference_order: int = 2,
        points: int = 6,
        rank_rtol: float = 1e-9,
        on_unidentifiable: str = "raise",
    ) -> None:
        if not isinstance(model, KernelModel):
            raise DimensionError(f"model must be a KernelModel; found {type(model).__name__}")
        if not model.unknowns:
            raise IdentifiabilityError("the model has no unknown coefficient: nothing to estimate")
        if isinstance(dt, bool) or not isinstance(dt, int | float) or not np.isfinite(dt) or dt <= 0:
            raise DimensionError(f"dt must be a positive sample time; found {abbreviate(dt, 30)}")
        _check_options(penalty, difference_order, rank_rtol)
        if on_unidentifiable not in ("raise", "hold"):
            raise DimensionError(f"on_unidentifiable must be 'raise' or 'hold'; found "
                                 f"{abbreviate(on_unidentifiable, 30)}")
        if not isinstance(report, int | float) or not 0.0 <= report <= 1.0:
            raise DimensionError(f"report must be a fraction in [0, 1]; found {abbreviate(report, 30)}")
        self.model = model
        self.dt = float(dt)
        self.t0 = float(t0)
        self.length = _samples_of(window, self.dt, "window") + 1
        self.hop = 1 if hop is None else _samples_of(hop, self.dt, "hop")
        self.report_index = int(round(report * (self.length - 1)))
        lag = self.length - 1 - self.report_index
        if self.hop > lag + 1:
            raise DimensionError(
                f"hop = {self.hop} samples exceeds delay + 1 = {lag + 1} samples: between refits the "
                "reporting point would leave the window (shorten the hop or move report towards 0)"
            )
        self.penalty = penalty
        self.rank_rtol = float(rank_rtol)
        self.on_unidentifiable = on_unidentifiable
        self._plan = _build_plan(model, self.length, self.dt, points=points, difference_order=difference_order)
        if self.length < self._plan.n_unknowns:
            raise IdentifiabilityError(
                f"a window of {self.length} samples is too short for {self._plan.n_unknowns} unknown coefficients"
            )
        self._instants = np.arange(self.length)
        inputs = (Port("u", (1,), "known input u_k"), Port("y", (1,), "measured output y_k"))
        outputs = (
            Port("t_est", (1,), "time the estimates refer to: t_k - delay"),
            Port("yhat", (1,), "y_E(t_est), kernel identity (9)"),
            Port("dyhat", (1,), "y_E'(t_est), derivative identity (10)"),
            Port("xhat", (2,), "state (y, y' + b1 u) at t_est, (32)"),
            Port("a0", (1,), "a_0(t_est)"),
            Port("a1", (1,), "a_1(t_est)"),
            Port("b0", (1,), "b_0(t_est)"),
            Port("b1", (1,), "b_1(t_est)"),
            Port("valid", (1,), "1 when the estimates are current, 0 before the first full window"),
        )
        super().__init__(inputs, outputs)

    # -- protocol ----------------------------------------------------------------------------
    @property
    def delay(self) -> float:
        """Reporting delay (s): estimates at sample ``k`` refer to ``t_k - delay``."""
        return (self.length - 1 - self.report_index) * self.dt

    def _reset(self) -> None:
        self._k = 0
        self._stored: dict[str, np.ndarray] | None = None
        self._head = 0
        self._ring_u = np.zeros(self.length)
        self._ring_y = np.zeros(self.length)
        self._last_fit = -1
        self._valid = 0.0
        self._held = self._zero_outputs()

    def _zero_outputs(self) -> dict[str, np.ndarray]:
        out = {p.name: np.zeros(p.shape) for p in self.output_ports}
        out["t_est"][0] = self.t0 + self._k * self.dt - self.delay
        return out

    def _read(self, inputs: Mapping[str, np.ndarray]) -> tuple[float, float]:
        missing = [p.name for p in self.input_ports if p.name not in inputs]
        if missing:
            raise DimensionError(f"missing input {missing[0]!r}; the observer needs u and y")
        vals = []
        for name in ("u", "y"):
            arr = np.asarray(inputs[name], dtype=float)
            if arr.size != 1 or arr.ndim > 1:
                raise DimensionError(f"{name} has shape {arr.shape}; expected (1,)")
            check_finite(arr, name)
            vals.append(float(arr.reshape(-1)[0]))
        return vals[0], vals[1]

    def _window(self, u: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """The last ``L - 1`` buffered samples followed by the current one."""
        order = (self._head + 2 + np.arange(self.length - 1)) % self.length  # oldest of the last L - 1 first
        return (
            np.concatenate([self._ring_u[order], [u]]),
            np.concatenate([self._ring_y[order], [y]]),
        )

    def _compute(self, u: float, y: float) -> tuple[dict[str, np.ndarray] | None, dict[str, np.ndarray]]:
        """(new fit arrays or None, outputs) for the current sample; no state change."""
        n_have = self._k + 1
        if n_have < self.length:
            return None, self._zero_outputs()
        if (n_have - self.length) % self.hop == 0:
            uw, yw = self._window(u, y)
            a = self.t0 + (self._k - self.length + 1) * self.dt
            try:
                fit = _fit(
                    self._plan, a, uw, yw, penalty=self.penalty, instants=self._instants, rank_rtol=self.rank_rtol
                )
            except IdentifiabilityError:
                if self.on_unidentifiable == "raise":
                    raise
                held = {k: v.copy() for k, v in self._held.items()}
                held["valid"] = np.array([0.0])
                held["t_est"] = np.array([self.t0 + self._k * self.dt - self.delay])
                return {}, held
            lo, hi = self.report_index, self.report_index + self.hop
            arrays = {"y": fit.y[lo:hi].copy(), "dy": fit.dy[lo:hi].copy(), "x": fit.x[lo:hi].copy()}
            for n in COEFFICIENTS:
                arrays[n] = fit.values[n][lo:hi].copy()
            return arrays, self._report_stored(arrays, 0)
        offset = self._k - self._last_fit
        if self._stored is None or self._valid == 0.0:
            held = {k: v.copy() for k, v in self._held.items()}
            held["valid"] = np.array([0.0])
            held["t_est"] = np.array([self.t0 + self._k * self.dt - self.delay])
            return None, held
        return None, self._report_stored(self._stored, offset)

    def _report_stored(self, arrays: Mapping[str, np.ndarray], offset: int) -> dict[str, np.ndarray]:
        out = {
            "t_est": np.array([self.t0 + self._k * self.dt - self.delay]),
            "yhat": np.array([arrays["y"][offset]]),
            "dyhat": np.array([arrays["dy"][offset]]),
            "xhat": np.array(arrays["x"][offset]),
            "valid": np.array([1.0]),
        }
        for n in COEFFICIENTS:
            out[n] = np.array([arrays[n][offset]])
        return out

    def _evaluate(self, sample: tuple[float, float]) -> tuple[dict[str, np.ndarray], Any]:
        u, y = sample
        arrays, out = self._compute(u, y)
        return out, (u, y, arrays, out)

    def _commit(self, pending: Any) -> None:
        u, y, arrays, out = pending
        if arrays is not None:
            if arrays:  # a successful refit
                self._stored = arrays
                self._last_fit = self._k
                self._valid = 1.0
            else:  # an unidentifiable window, held
                self._valid = 0.0
        self._held = {k: v.copy() for k, v in out.items()}
        self._head = (self._head + 1) % self.length
        self._ring_u[self._head] = u
        self._ring_y[self._head] = y
        self._k += 1

    # -- state ---------------------------------------------------------------------------------
    def get_state(self) -> dict[str, Any]:
        """The whole state: sample counter, the window buffer (ring and head),
        the last fit's reporting arrays and the held outputs."""
        state: dict[str, Any] = {
            "k": self._k,
            "head": self._head,
            "ring_u": self._ring_u.copy(),
            "ring_y": self._ring_y.copy(),
            "last_fit": self._last_fit,
            "valid": self._valid,
        }
        stored = self._stored
        for n in ("y", "dy", "x", *COEFFICIENTS):
            empty = np.zeros((self.hop, 2) if n == "x" else self.hop)
            state[f"fit_{n}"] = empty if stored is None else stored[n].copy()
        for n, v in self._held.items():
            state[f"held_{n}"] = v.copy()
        return state

    def _set_state(self, state: Mapping[str, Any]) -> None:
        """Restore a state from :meth:`get_state` (checked for shape)."""
        try:
            ring_u = as_vector(state["ring_u"], "ring_u", self.length)
            ring_y = as_vector(state["ring_y"], "ring_y", self.length)
            stored = {}
            for n in ("y", "dy", "x", *COEFFICIENTS):
                arr = np.array(state[f"fit_{n}"], dtype=float)
                want = (self.hop, 2) if n == "x" else (self.hop,)
                if arr.shape != want:
                    raise DimensionError(f"fit_{n} has shape {arr.shape}; expected {want}")
                stored[n] = arr
            held = {p.name: np.array(state[f"held_{p.name}"], dtype=float).reshape(p.shape) for p in self.output_ports}
            k, head, last_fit = int(state["k"]), int(state["head"]), int(state["last_fit"])
            valid = float(state["valid"])
        except KeyError as exc:
            raise DimensionError(f"observer state is missing {exc.args[0]!r}") from exc
        if not (0 <= head < self.length and k >= 0 and -1 <= last_fit < max(k, 0) + 1):
            raise DimensionError("observer state is inconsistent (head, k, last_fit)")
        for name, arr in (("ring_u", ring_u), ("ring_y", ring_y)):
            if not np.all(np.isfinite(arr)):
                raise NonFiniteError(f"{name} holds a non-finite value")
        self._k, self._head, self._last_fit, self._valid = k, head, last_fit, valid
        self._ring_u, self._ring_y = ring_u.copy(), ring_y.copy()
        self._stored = stored if last_fit >= 0 else None
        self._held = held
