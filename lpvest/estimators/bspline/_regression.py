"""The regression of (28)-(30): the plan (everything that depends on the window's geometry,
not on the data) and the assembly of the least-squares system, dense or compressed segment
by segment (a TSQR).

Notes: :mod:`lpvest.estimators.bspline`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core._errors import (
    NonFiniteError,
    shorten,
)
from ...systems._ltv import TimeFunction
from ._basis import basis_rows, knot_span, spline_knots
from ._kernels import (
    FREE_MOMENTS,
    MOMENTS,
    SLOT_MOMENTS,
    ProductQuadrature,
    coefficient_terms,
    free_derivative,
    free_identity,
    moment_rows,
    product_quadrature,
    slot_identity,
    window_weight,
)
from ._model import COEFFICIENTS, KernelModel, Known, UnknownConstant, UnknownSpline

__all__ = [
    "RegressionPlan",
    "build_plan",
    "SIGNAL_OF",
    "KernelParts",
    "kernel_parts",
    "dense_system",
    "compressed_system",
]


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
class RegressionPlan:
    """What :func:`build_plan` prepares for a window of ``m`` samples: the
    quadrature, the columns of each unknown and the difference penalty.

    Parameters
    ----------
    model : KernelModel
        The coefficient declarations.
    quad : ProductQuadrature
        The rule on the window, in window coordinates (a = 0).
    blocks : tuple
        The columns of ``P`` of each unknown coefficient, in column order
        (the knots and basis values of a spline block).
    labels : tuple of str, length s
        The unknown each column multiplies (``"a0[k]"``, ``"a1"``, ...).
    penalty_matrix : ndarray, shape (rows, s)
        Difference penalty on the spline blocks (zero columns for constants).
    """

    model: KernelModel
    quad: ProductQuadrature
    blocks: tuple[_Block, ...]
    labels: tuple[str, ...]
    penalty_matrix: np.ndarray

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
    mu = knot_span(0.5 * (x[0] + x[-1]), knots, k)  # (P,)
    values = basis_rows(x, knots, k, mu).reshape(k, -1)
    dvalues = basis_rows(x, knots, k, mu, derivative=True).reshape(k, -1) if name[1] == "1" else None
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
    sample_mu = knot_span(samples, knots, k)
    sample_values = basis_rows(samples, knots, k, sample_mu)
    return _Block(
        name, col, n, spec, knots, piece_first, values, dvalues, jlo, jhi, width, band_slot, sample_mu - (k - 1),
        sample_values,
    )


def build_plan(model: KernelModel, m: int, h: float, *, points: int, difference_order: int) -> RegressionPlan:
    """The regression plan of ``model`` on a window of ``m`` samples ``h``
    apart: everything that depends on the window's geometry, not on the
    data (so the sliding observer builds it once).

    Parameters
    ----------
    model : KernelModel
        Which coefficients are known, constant or splines.
    m : int
        Samples in the window.
    h : float
        The sample interval.
    points : int
        Gauss-Legendre points per quadrature panel.
    difference_order : int
        Order of the P-spline difference penalty on each spline block.

    Returns
    -------
    RegressionPlan
        The quadrature, the columns of each unknown and their labels, and the penalty matrix.

    Examples
    --------
    >>> from lpvest.estimators.bspline import KernelModel, UnknownConstant, UnknownSpline
    >>> plan = build_plan(KernelModel(a0=UnknownSpline(6), a1=UnknownConstant(), b0=UnknownConstant(),
    ...                               b1=UnknownConstant()), 201, 0.01, points=6, difference_order=2)
    >>> plan.m, plan.n_unknowns, plan.labels[:2], plan.labels[-1]
    (201, 9, ('a0[0]', 'a0[1]'), 'b1')
    """
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
    return RegressionPlan(model, quad, tuple(blocks), tuple(labels), D)


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
SIGNAL_OF = {"a": "y", "b": "u"}


def _known_functions(model: KernelModel) -> dict[str, TimeFunction]:
    return {n: c.function for n in COEFFICIENTS if isinstance(c := model.coefficient(n), Known)}


@dataclass(frozen=True, eq=False)
class KernelParts:
    """The regression (29)-(30) on one window, in factored form.

    Parameters
    ----------
    quad : ProductQuadrature
        The rule on the window (absolute time).
    C : ndarray, shape (m,)
        ``C_[a,b](t)`` at the samples.
    y_nodes : ndarray, shape (N,)
        The output interpolated at the quadrature nodes.
    u_nodes : ndarray, shape (N,)
        The input interpolated at the quadrature nodes.
    moments : dict of str to (list, list)
        ``"y"``, ``"u"``: (F, B) rows of the signal (:func:`moment_rows`);
        ``"u"`` only when an unknown constant ``b`` coefficient needs it.
    known_ident : ndarray, shape (m,)
        Free part + known coefficients, identity (9), times C.
    known_deriv : ndarray, shape (m,)
        The same for the derivative identity (10).
    functions : dict of str to TimeFunction
        The known coefficients.
    dense : ndarray, shape (m, nd)
        Columns of the unknown constants, then q; divided by C.
    dense_cols : ndarray of int, shape (nd,)
        Their column index in [P, q].
    bands : tuple
        Kernel integrals of the basis functions of each spline block, in
        banded form (not divided by C).
    """

    quad: ProductQuadrature
    C: np.ndarray
    y_nodes: np.ndarray
    u_nodes: np.ndarray
    moments: dict[str, tuple[list[Any], list[Any]]]
    known_ident: np.ndarray
    known_deriv: np.ndarray
    functions: dict[str, TimeFunction]
    dense: np.ndarray
    dense_cols: np.ndarray
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


def kernel_parts(plan: RegressionPlan, a: float, u: np.ndarray, y: np.ndarray) -> KernelParts:
    """The data-dependent parts of the regression (29)-(30) on the window starting at ``a``.

    Parameters
    ----------
    plan : RegressionPlan
        From :func:`build_plan` for ``m`` samples.
    a : float
        Time of the window's first sample.
    u, y : ndarray, shape (m,)
        Input and output samples.

    Returns
    -------
    KernelParts
        The moments, the known part, the dense columns and the bands.

    Raises
    ------
    NonFiniteError
        A known coefficient (or its derivative) is not finite at a sample or
        node of the window.
    """
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
        F, B = moments[SIGNAL_OF[block.name[0]]]
        dense[:, k] = slot_identity(int(block.name[1]), F, B, T, R) / C
    dense[:, -1] = y - known / C
    dense_cols = np.array([b.col for b in const] + [plan.n_unknowns], dtype=np.int64)
    bands = tuple(
        _band(b, quad, y_nodes if b.name[0] == "a" else u_nodes) for b in plan.blocks if b.spline is not None
    )
    return KernelParts(quad, C, y_nodes, u_nodes, moments, known, known_d, funcs, dense, dense_cols, bands)


def dense_system(plan: RegressionPlan, parts: KernelParts) -> np.ndarray:
    """``[P, q]`` as one Fortran-ordered array of shape (m, s + 1).

    Parameters
    ----------
    plan : RegressionPlan
        The plan of the window.
    parts : KernelParts
        From :func:`kernel_parts` with ``plan``.

    Returns
    -------
    ndarray, shape (m, s + 1)
        ``P`` (every row divided by ``C``) and ``q`` as the last column.
    """
    quad = parts.quad
    t = quad.samples
    A = np.empty((quad.m, plan.n_unknowns + 1), order="F")
    for band in parts.bands:
        _band_columns(band, t - quad.a, quad.b - t, A)
        A[:, band.block.col : band.block.col + band.block.size] /= parts.C[:, None]
    A[:, parts.dense_cols] = parts.dense
    return A


def compressed_system(plan: RegressionPlan, parts: KernelParts, rows: np.ndarray | None) -> np.ndarray:
    """A matrix ``K`` with ``K^T K = A^T A`` for ``A = [P, q]`` restricted to the
    rows ``rows`` (``None``: all), by a QR of each segment's rows (see above).

    Parameters
    ----------
    plan : RegressionPlan
        The plan of the window.
    parts : KernelParts
        From :func:`kernel_parts` with ``plan``.
    rows : ndarray of int, or None
        The regression instants (sample indices); None: every sample.

    Returns
    -------
    K : ndarray, shape (rows_K, s + 1)
        The stacked triangular factors of the segments: per segment at most
        ``r`` rows, ``r`` about 10 (2 + the basis functions meeting it + the
        dense columns).
    """
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


