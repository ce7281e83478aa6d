"""Double-sided kernel representation of second-order SISO LTV systems.

Sridhar, Ghoshal & Michalska (002_54d0f33f85fddffe.txt), Section II: the
input-output equation (11)

    y'' + a_1(t) y' + a_0(t) y + b_1(t) u' + b_0(t) u = 0

multiplied by ``(xi - a)^2`` (forward) or ``(b - zeta)^2`` (backward) and
integrated twice gives (12) and (15); their sum divided by
``C(t) = (t - a)^2 + (b - t)^2`` is the kernel identity (9) with the kernels
(13)-(19). Differentiating (12) and (15) in ``t`` (Leibniz rule; the paper
does not print these) gives the derivative identity (10) for ``n = 2``::

    C y' = (2 (t - a) - 2 (b - t)) y(t) - C a_1(t) y(t) - C b_1(t) u(t)
           + int_a^t  d/dt K_Fy(t, xi)   y dxi   + int_a^t  d/dt K_Fu(t, xi)   u dxi
           + int_t^b  d/dt K_By(t, zeta) y dzeta + int_t^b  d/dt K_Bu(t, zeta) u dzeta

    d/dt K_Fy = -2 + 2 (xi - a) a_1 + (xi - a)^2 a_1' - (xi - a)^2 a_0
    d/dt K_By =  2 + 2 (b - zeta) a_1 - (b - zeta)^2 a_1' + (b - zeta)^2 a_0

(and the same for ``u`` with ``b_1``, ``b_0`` and without the constants).

Every kernel is a polynomial in ``t`` and in ``s = xi - a`` (``r = b - zeta``)
times a coefficient (or its derivative). With ``T = t - a``, ``R = b - t``, the
forward moments ``F_k(t) = int_a^t s^k phi(xi) v(xi) dxi`` and backward moments
``B_k(t) = int_t^b r^k phi(zeta) v(zeta) dzeta`` (``k <= 3``), the kernel
integrals are short combinations (:func:`slot_identity`,
:func:`slot_derivative`)::

    free part       6 F_1 - 2 T F_0 + 6 B_1 - 2 R B_0            (phi = 1, v = y)
    a_0 (or b_0)   -T F_2 + F_3 + B_3 - R B_2                    (phi = a_0, v = y)
    a_1 (or b_1)   -3 F_2 + 2 T F_1 + 3 B_2 - 2 R B_1            (phi = a_1)
                   + T F'_2 - F'_3 - B'_3 + R B'_2               (phi = a_1')

So one pass of *cumulative* quadrature per function gives the kernel
integrals at every sample at once.

Quadrature (:class:`ProductQuadrature`)
---------------------------------------
A product rule on the uniformly sampled data: on each sample interval the
signal (``y`` or ``u``) is replaced by the Lagrange polynomial through the
``points`` nearest samples (a centred stencil, shifted inwards at the ends of
the data); its product with the known weight (``s^k`` times a B-spline, a
known coefficient or 1) is integrated by ``points / 2``-point Gauss-Legendre
on each piece between consecutive *breakpoints* (the samples and the B-spline
knots, so the rule never straddles a knot where a B-spline's derivative
jumps). Both approximations are of order ``points``: the interpolation error
is ``O(h^points)`` and the ``q``-point Gauss rule's ``O(h^(2q))``, so every
cumulative integral has a global error ``O(h^points)`` for smooth data
(``points = 6``, the default: sixth order). Data that are a polynomial of
degree below ``points`` are interpolated exactly.

Examples
--------
>>> import numpy as np
>>> t = np.linspace(0.0, 2.0, 201)
>>> quad = product_quadrature(0.0, 0.01, t.size)
>>> F, B = quad.cumulative(quad.interpolate(np.cos(t)))
>>> bool(abs(F[0, -1] - np.sin(2.0)) < 1e-12)  # int_0^2 cos = sin 2
True
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from ...core._errors import DimensionError, SamplingError, abbreviate
from ...core._validation import as_vector

__all__ = [
    "ProductQuadrature",
    "product_quadrature",
    "cumulate",
    "moment_rows",
    "KernelIdentity",
    "kernel_identity",
    "slot_identity",
    "slot_derivative",
    "free_identity",
    "free_derivative",
    "coefficient_terms",
    "finish_identity",
    "window_weight",
    "check_uniform_samples",
    "SAMPLING_RTOL",
    "MOMENTS",
    "SLOT_MOMENTS",
    "FREE_MOMENTS",
]

#: Moments ``F[k]`` (or ``B[k]``) of one integrand, indexed by the power ``k``
#: (a list of arrays over the samples, or a stacked array).
Moments = Sequence[np.ndarray] | np.ndarray
#: ``t - a`` or ``b - t``: at every sample (an array) or at one point.
Span = np.ndarray | float

#: Number of moments ``s^0 .. s^3`` the kernels (13)-(17) need.
MOMENTS = 4
#: The moments ``k`` (of ``phi v``) that :func:`slot_identity` and
#: :func:`slot_derivative` read, by order (those of ``phi' v`` are ``SLOT_MOMENTS[0]``).
SLOT_MOMENTS = {0: range(2, 4), 1: range(1, 3)}
#: The moments of ``y`` that :func:`free_identity` and :func:`free_derivative` read.
FREE_MOMENTS = range(0, 2)


@dataclass(frozen=True, eq=False)
class ProductQuadrature:
    """Cumulative product quadrature on ``m`` uniform samples ``a + j h``.

    Build it with :func:`product_quadrature`. The window is cut into ``P``
    *pieces* at the samples and the breakpoints: pieces ``0 .. m - 2`` are the
    sample intervals (cut short at their first breakpoint, if any), the others
    the rest of the split intervals. Each piece holds ``q = points / 2`` Gauss
    nodes. Node arrays have length ``N = q P`` and hold the first node of every
    piece, then the second, ...: node ``g = i P + p`` is node ``i`` of piece
    ``p`` (they reshape to ``(q, P)``).

    Parameters
    ----------
    a, h : float
        First sample time and sample spacing; the window is ``[a, b]``,
        ``b = a + (m - 1) h``.
    m : int
        Number of samples.
    points : int
        Interpolation stencil (even); the rule's order.
    x : ndarray, shape (N,)
        Quadrature nodes (absolute time).
    weights : ndarray, shape (N,)
        Gauss weights (they sum to ``b - a``).
    moment_weights : ndarray, shape (2, 4, N)
        ``weights * (x - a)^k`` (forward, ``[0, k]``) and ``weights * (b - x)^k``
        (backward, ``[1, k]``), ``k = 0..3``.
    piece_interval : ndarray of int, shape (P,)
        Sample interval ``j`` (``a + j h <= x <= a + (j + 1) h``) of each piece:
        ``j`` for piece ``j < m - 1``.
    stencil : ndarray of int, shape (P,)
        First sample of each piece's interpolation stencil (``points`` samples,
        centred on the piece's interval, shifted inwards at the ends).
    lagrange : ndarray, shape (points, q)
        Lagrange weights of the nodes of a *regular* piece (a whole interval,
        not split, with a centred stencil; they all have the same nodes relative
        to their stencil): ``v(x) ~ sum_l lagrange[l, i] v[stencil[p] + l]``
        for node ``i`` of piece ``p``.
    irregular : ndarray of int, shape (P_irr,)
        The other pieces (split intervals and the ``points / 2 - 1`` intervals
        at each end).
    irregular_lagrange : ndarray, shape (points, q, P_irr)
        Their Lagrange weights.
    """

    a: float
    h: float
    m: int
    points: int
    x: np.ndarray
    weights: np.ndarray
    moment_weights: np.ndarray
    piece_interval: np.ndarray
    stencil: np.ndarray
    lagrange: np.ndarray
    irregular: np.ndarray
    irregular_lagrange: np.ndarray

    @property
    def b(self) -> float:
        return self.a + (self.m - 1) * self.h

    @property
    def samples(self) -> np.ndarray:
        """Sample times ``a + j h``, shape (m,)."""
        return self.a + self.h * np.arange(self.m)

    @property
    def nodes_per_piece(self) -> int:
        """``q``, the Gauss nodes on each piece."""
        return self.points // 2

    @property
    def interval(self) -> np.ndarray:
        """Sample interval of each node, shape (N,)."""
        return np.tile(self.piece_interval, self.nodes_per_piece)


    def shifted(self, a: float) -> ProductQuadrature:
        """The same rule on the window starting at ``a`` (same ``h`` and ``m``;
        every weight is invariant under the shift).

        Parameters
        ----------
        a : float
            The new first sample time.

        Returns
        -------
        ProductQuadrature
            A copy with ``a`` and the nodes ``x`` shifted.
        """
        return replace(self, a=float(a), x=self.x + (float(a) - self.a))

    def interpolate(self, v: np.ndarray) -> np.ndarray:
        """Samples ``v`` (shape (m,)) interpolated at the nodes, shape (N,).

        Parameters
        ----------
        v : ndarray, shape (m,)
            Signal samples at ``a + j h``.

        Returns
        -------
        ndarray, shape (N,)
            The Lagrange interpolant of each piece's stencil at its nodes.
        """
        q, points = self.nodes_per_piece, self.points
        out = np.empty((q, self.piece_interval.size))
        # the regular pieces among the whole intervals c .. m - points + c
        # (stencil j - c): slices of v, then the irregular ones overwritten
        c = points // 2 - 1
        n = self.m - points + 1
        term = np.empty(n)
        for i in range(q):
            row = np.multiply(self.lagrange[0, i], v[:n], out=out[i, c : c + n])
            for ell in range(1, points):
                row += np.multiply(self.lagrange[ell, i], v[ell : ell + n], out=term)
        first = self.stencil[self.irregular]
        irregular = self.irregular_lagrange[0] * v[first]
        for ell in range(1, points):
            irregular += self.irregular_lagrange[ell] * v[first + ell]
        out[:, self.irregular] = irregular
        return out.ravel()

    def piece_moments(self, f: np.ndarray, moments: range = range(MOMENTS)) -> np.ndarray:
        """Integrals of ``f`` (given at the nodes) times ``(x - a)^k`` and
        ``(b - x)^k`` over each piece, ``k`` in ``moments`` (a range):
        shape (2, len(moments), ..., P) for ``f`` of shape (..., N).

        Parameters
        ----------
        f : ndarray, shape (..., N)
            Integrand at the nodes.
        moments : range, default range(4)
            The powers ``k`` (within ``0..3``).

        Returns
        -------
        ndarray, shape (2, len(moments), ..., P)
            ``[0, kk]``: forward moments (``(x - a)^k``), ``[1, kk]``: backward
            (``(b - x)^k``), for ``k = moments[kk]``, per piece.
        """
        q = self.nodes_per_piece
        fq = f.reshape(-1, q, f.shape[-1] // q)  # (rows, q, P)
        P = fq.shape[-1]
        out = np.empty((2, len(moments), fq.shape[0], P))
        term = np.empty(P)
        # row by row into one output: large temporaries cost more than the arithmetic
        for d in range(2):
            for kk, k in enumerate(moments):
                w = self.moment_weights[d, k].reshape(q, P)
                for row, fr in enumerate(fq):
                    o = np.multiply(w[0], fr[0], out=out[d, kk, row])
                    for i in range(1, q):
                        o += np.multiply(w[i], fr[i], out=term)
        return out.reshape(2, len(moments), *f.shape[:-1], P)

    def cumulative(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forward and backward moments of ``f`` (given at the nodes).

        Returns ``F, B``, each of shape (4, m):
        ``F[k, j] = int_a^{t_j} (x - a)^k f dx``,
        ``B[k, j] = int_{t_j}^b (b - x)^k f dx``.

        Parameters
        ----------
        f : ndarray, shape (N,)
            Integrand at the nodes.

        Returns
        -------
        F : ndarray, shape (4, m)
            Forward moments at the samples.
        B : ndarray, shape (4, m)
            Backward moments at the samples.
        """
        per_interval = self.interval_sums(self.piece_moments(f))
        return cumulate(per_interval[0], per_interval[1])

    def cumulative_rows(self, f: np.ndarray, moments: range) -> tuple[list[Any], list[Any]]:
        """:meth:`cumulative` for the moments ``k`` in ``moments`` only (a range):
        ``F, B`` are lists indexed by ``k = 0..3`` holding the rows, shape (m,),
        and ``None`` for the moments not computed.

        Parameters
        ----------
        f : ndarray, shape (N,)
            Integrand at the nodes.
        moments : range
            The powers ``k`` to compute (within ``0..3``).

        Returns
        -------
        F : list of (ndarray, shape (m,), or None), length 4
            Forward moments by ``k``.
        B : list of (ndarray, shape (m,), or None), length 4
            Backward moments by ``k``.
        """
        per_interval = self.interval_sums(self.piece_moments(f, moments))
        F, B = cumulate(per_interval[0], per_interval[1])
        return moment_rows(moments, F), moment_rows(moments, B)

    def interval_sums(self, pieces: np.ndarray) -> np.ndarray:
        """Per-piece values (..., P) summed per sample interval, (..., m - 1);
        ``pieces`` is overwritten.

        Parameters
        ----------
        pieces : ndarray, shape (..., P)
            Per-piece values; pieces ``0 .. m - 2`` are the sample intervals.

        Returns
        -------
        ndarray, shape (..., m - 1)
            A view of ``pieces`` with the split pieces added to their intervals.
        """
        J = self.m - 1
        out = pieces[..., :J]
        if pieces.shape[-1] > J:
            # along the first axis of moved views (writes land in ``out``): numpy's
            # stubs before 2.5 refuse an index tuple such as ``(..., idx)``
            np.add.at(np.moveaxis(out, -1, 0), self.piece_interval[J:],
                      np.moveaxis(pieces[..., J:], -1, 0))
        return out


def moment_rows(moments: range, values: np.ndarray) -> list[Any]:
    """The moments ``k`` in ``moments`` (``values``, shape (len(moments), ...)) as a
    list indexed by ``k = 0..3``, ``None`` for the others (what :func:`slot_identity`
    and the other kernel combinations read).

    Parameters
    ----------
    moments : range
        The powers ``k`` held by ``values`` (within ``0..3``).
    values : ndarray, shape (len(moments), ...)
        Row ``k - moments.start`` is moment ``k``.

    Returns
    -------
    list of (ndarray or None), length 4
        Entry ``k``: the moment ``k`` (a view) or None.
    """
    return [values[k - moments.start] if k in moments else None for k in range(MOMENTS)]


def cumulate(IF: np.ndarray, IB: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-interval integrals (..., L) to moments at the ``L + 1`` bounding
    points: ``F`` sums the intervals to the left of a point, ``B`` those to
    its right. Returns arrays of shape (..., L + 1).

    Parameters
    ----------
    IF : ndarray, shape (..., L)
        Per-interval integrals of the forward moments.
    IB : ndarray, shape (..., L)
        Per-interval integrals of the backward moments.

    Returns
    -------
    F : ndarray, shape (..., L + 1)
        Cumulative sums from the left (``F[..., 0] = 0``).
    B : ndarray, shape (..., L + 1)
        Cumulative sums from the right (``B[..., -1] = 0``).
    """
    shape = (*IF.shape[:-1], IF.shape[-1] + 1)
    F = np.empty(shape)
    B = np.empty(shape)
    F[..., 0] = 0.0
    B[..., -1] = 0.0
    np.cumsum(IF, axis=-1, out=F[..., 1:])
    np.cumsum(IB[..., ::-1], axis=-1, out=B[..., -2::-1])
    return F, B


@functools.lru_cache(maxsize=8)
def _gauss_legendre(q: int) -> tuple[np.ndarray, np.ndarray]:
    """``q``-point Gauss-Legendre nodes and weights on [-1, 1] (read-only)."""
    gx, gw = np.polynomial.legendre.leggauss(q)
    gx.flags.writeable = False
    gw.flags.writeable = False
    return gx, gw


def product_quadrature(
    a: float, h: float, m: int, *, breakpoints: Sequence[float] | np.ndarray = (), points: int = 6
) -> ProductQuadrature:
    """Build the cumulative product quadrature of the module docstring.

    Parameters
    ----------
    a, h : float
        First sample time and uniform spacing (``h > 0``).
    m : int
        Number of samples (at least ``points``).
    breakpoints : array_like, optional
        Extra breakpoints (B-spline knots); those strictly inside ``(a, b)``
        and not on a sample split their interval.
    points : int, optional
        Interpolation stencil, even, ``2 <= points <= 12``; the rule is of
        order ``points`` (default 6).

    Returns
    -------
    ProductQuadrature
        The nodes, weights and interpolation stencils of the rule.

    Raises
    ------
    DimensionError
        ``points`` is not an even integer in ``[2, 12]``, ``h`` is not
        positive and finite, or ``m < points``.

    Examples
    --------
    >>> q = product_quadrature(0.0, 0.5, 5, breakpoints=[0.75], points=4)
    >>> q.x.size  # 4 intervals + 1 split, 2 Gauss nodes per piece
    10
    """
    if isinstance(points, bool) or not isinstance(points, int | np.integer) or not 2 <= points <= 12 or points % 2:
        raise DimensionError(f"points (interpolation stencil) must be an even integer in [2, 12]; found "
                             f"{abbreviate(points, 30)}")
    if not h > 0 or not np.isfinite(h):
        raise DimensionError(f"the sample spacing must be positive and finite; found {abbreviate(h, 30)}")
    if m < points:
        raise DimensionError(
            f"the data have {m} samples; the {points}-point quadrature needs at least {points}"
        )
    samples = a + h * np.arange(m)
    b = samples[-1]
    bp = np.asarray(breakpoints, dtype=float).ravel()
    rel = (bp - a) / h
    inside = np.unique(bp[(bp > a) & (bp < b) & (np.abs(rel - np.round(rel)) > 1e-9)])
    # the pieces: the sample intervals, cut short at their first breakpoint,
    # then from each breakpoint to the next one in its interval or to its end
    split = np.searchsorted(samples, inside, side="right") - 1  # the interval of each breakpoint
    first = np.ones(inside.size, dtype=bool)
    first[1:] = split[1:] != split[:-1]
    last = np.ones(inside.size, dtype=bool)
    last[:-1] = first[1:]
    right = samples[1:].copy()
    right[split[first]] = inside[first]
    left = np.concatenate([samples[:-1], inside])
    right = np.concatenate([right, np.where(last, samples[split + 1], np.append(inside[1:], b))])
    piece_interval = np.concatenate([np.arange(m - 1), split])
    q = points // 2
    gx, gw = _gauss_legendre(q)
    half = 0.5 * (right - left)
    mid = 0.5 * (right + left)
    x = (mid + half * gx[:, None]).ravel()  # node i of every piece, then node i + 1
    w = (half * gw[:, None]).ravel()
    moment_weights = np.empty((2, MOMENTS, x.size))
    for direction, dist in enumerate((x - a, b - x)):
        moment_weights[direction, 0] = w
        for k in range(1, MOMENTS):
            np.multiply(w, dist**k, out=moment_weights[direction, k])
    # interpolation stencils: centred on the piece's interval, shifted inwards at the ends
    c = points // 2 - 1
    stencil = np.clip(piece_interval - c, 0, m - points)
    # a whole interval with a centred stencil has its nodes at c + (1 + gx) / 2
    # samples from the stencil's start: one set of weights serves them all
    regular = np.zeros(piece_interval.size, dtype=bool)
    regular[c : m - points + c + 1] = True
    regular[split] = False
    irregular = np.flatnonzero(~regular)
    pos = (x.reshape(q, -1)[:, irregular] - samples[stencil[irregular]]) / h
    return ProductQuadrature(
        float(a), float(h), int(m), int(points), x, w, moment_weights, piece_interval, stencil,
        _lagrange_weights(c + 0.5 * (1.0 + gx), points), irregular, _lagrange_weights(pos, points),
    )


def _lagrange_weights(pos: np.ndarray, points: int) -> np.ndarray:
    """``L_l(pos) = prod_{j != l} (pos - j) / (l - j)``, ``l = 0 .. points - 1``:
    shape (points, *pos.shape); ``pos`` (in samples from the stencil's start)
    lies strictly between two samples, so it is never an integer."""
    total = pos.copy()  # prod_j (pos - j)
    for j in range(1, points):
        total *= pos - j
    out = np.empty((points, *pos.shape))
    for ell in range(points):
        denominator = float(np.prod([ell - j for j in range(points) if j != ell]))
        np.divide(total, (pos - ell) * denominator, out=out[ell])
    return out


#: Relative tolerance of the uniform-sampling check: ``|t[j+1] - t[j] - h| <= tol * h``.
SAMPLING_RTOL = 1e-6


def check_uniform_samples(t: object, name: str = "t") -> tuple[np.ndarray, float]:
    """Finite, strictly increasing, uniformly spaced sample times; returns ``(t, h)``.

    Raises :class:`~lpvest.core.NonFiniteError` (NaN/inf),
    :class:`~lpvest.core.DimensionError` (fewer than 2 samples) or
    :class:`~lpvest.core.SamplingError` (not increasing, or a step deviating
    from the mean step by more than ``SAMPLING_RTOL`` relative).

    Parameters
    ----------
    t : array_like, shape (m,)
        Sample times.
    name : str, default "t"
        Name of ``t`` in error messages.

    Returns
    -------
    t : ndarray, shape (m,)
        The times as floats.
    h : float
        The mean step ``(t[-1] - t[0]) / (m - 1)``.
    """
    times = as_vector(t, name)
    if times.size < 2:
        raise DimensionError(f"{name} has {times.size} sample(s); at least 2 are needed")
    d = np.diff(times)
    if np.any(d <= 0):
        j = int(np.argmax(d <= 0))
        raise SamplingError(f"{name} is not strictly increasing: {name}[{j + 1}] = "
                            f"{abbreviate(times[j + 1], 30)} <= {name}[{j}]")
    h = (times[-1] - times[0]) / (times.size - 1)
    dev = np.abs(d - h)
    if np.max(dev) > SAMPLING_RTOL * h:
        j = int(np.argmax(dev))
        raise SamplingError(
            f"{name} is not uniformly sampled: step {j} is {d[j]:.9g}, the mean step is {h:.9g} "
            f"(relative tolerance {SAMPLING_RTOL:g}); the kernel quadrature needs a uniform grid"
        )
    return times, float(h)


# -- the kernel integrals as combinations of moments -----------------------------------------


def free_identity(F: Moments, B: Moments, T: Span, R: Span) -> np.ndarray:
    """Kernel part depending on no coefficient (ERRATA: missing from (24)/(28)):
    ``int_a^t [4 s - 2 (t - xi)] y + int_t^b [4 r + 2 (t - zeta)] y``;
    ``F, B`` are the moments of ``y``.

    Parameters
    ----------
    F, B : sequence of ndarray or ndarray
        Forward and backward moments of ``y``, indexed by ``k``; ``k = 0, 1`` are read.
    T, R : ndarray or float
        ``t - a`` and ``b - t``.

    Returns
    -------
    ndarray
        ``6 F_1 - 2 T F_0 + 6 B_1 - 2 R B_0`` (not divided by ``C``).
    """
    return 6.0 * F[1] - 2.0 * T * F[0] + 6.0 * B[1] - 2.0 * R * B[0]


def free_derivative(F: Moments, B: Moments) -> np.ndarray:
    """``t``-derivative of the integrals of :func:`free_identity` without the
    boundary terms (those are ``(2T - 2R) y(t)``).

    Parameters
    ----------
    F, B : sequence of ndarray or ndarray
        Forward and backward moments of ``y``, indexed by ``k``; ``k = 0`` is read.

    Returns
    -------
    ndarray
        ``-2 F_0 + 2 B_0``.
    """
    return -2.0 * F[0] + 2.0 * B[0]


def slot_identity(
    order: int, F: Moments, B: Moments, T: Span, R: Span,
    Fd: Moments | None = None, Bd: Moments | None = None,
) -> np.ndarray:
    """Kernel integrals of one coefficient: ``order`` 0 (``a_0``/``b_0``) or 1
    (``a_1``/``b_1``); ``F, B`` moments of ``phi v``, ``Fd, Bd`` of ``phi' v``
    (``None``: ``phi' = 0``). Works elementwise on broadcastable arrays.

    Parameters
    ----------
    order : {0, 1}
        The derivative of the signal the coefficient multiplies.
    F, B : sequence of ndarray or ndarray
        Forward and backward moments of ``phi v``, indexed by ``k``.
    T, R : ndarray or float
        ``t - a`` and ``b - t``.
    Fd, Bd : sequence of ndarray or ndarray, optional
        Moments of ``phi' v`` (order 1 only).

    Returns
    -------
    ndarray
        The kernel integrals (module notes), not divided by ``C``.
    """
    if order == 0:
        return -T * F[2] + F[3] + B[3] - R * B[2]
    out = -3.0 * F[2] + 2.0 * T * F[1] + 3.0 * B[2] - 2.0 * R * B[1]
    if Fd is not None and Bd is not None:
        out = out + T * Fd[2] - Fd[3] - Bd[3] + R * Bd[2]
    return out


def slot_derivative(
    order: int, F: Moments, B: Moments, Fd: Moments | None = None, Bd: Moments | None = None
) -> np.ndarray:
    """``t``-derivative of the integrals of :func:`slot_identity` without the
    boundary terms (those are ``-C phi(t) v(t)`` for order 1, none for 0).

    Parameters
    ----------
    order : {0, 1}
        The derivative of the signal the coefficient multiplies.
    F, B : sequence of ndarray or ndarray
        Forward and backward moments of ``phi v``, indexed by ``k``.
    Fd, Bd : sequence of ndarray or ndarray, optional
        Moments of ``phi' v`` (order 1 only; ``None``: ``phi' = 0``).

    Returns
    -------
    ndarray
        The derivative part, not divided by ``C``.
    """
    if order == 0:
        return -F[2] + B[2]
    out = 2.0 * F[1] + 2.0 * B[1]
    if Fd is not None and Bd is not None:
        out = out + Fd[2] - Bd[2]
    return out


def window_weight(t: np.ndarray, a: float, b: float) -> np.ndarray:
    """``C_[a,b](t) = (t - a)^2 + (b - t)^2`` of (18), (19).

    Parameters
    ----------
    t : ndarray
        Times.
    a, b : float
        The window ``[a, b]``.

    Returns
    -------
    ndarray, shape like ``t``
        ``C_[a,b](t)``, positive for ``a < b``.
    """
    return (t - a) ** 2 + (b - t) ** 2


# -- the identity (9)/(10) with known coefficients --------------------------------------------


class KernelIdentity(NamedTuple):
    """Right-hand sides of (9) and (10) at the samples.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Sample times.
    y : ndarray, shape (m,)
        ``int K_y y + int K_u u``, (9).
    dy : ndarray, shape (m,)
        The derivative identity (10) with ``y(t)`` from ``y`` above.
    """

    t: np.ndarray
    y: np.ndarray
    dy: np.ndarray


CoefficientLike = object  # a TimeFunction, a formula, a number or a callable


def coefficient_terms(
    quad: ProductQuadrature, order: int, phi: np.ndarray, dphi: np.ndarray | None, v_nodes: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Kernel integrals of one coefficient ``phi`` (values at the nodes; its
    derivative ``dphi`` for order 1, ``None`` if zero) acting on the signal
    ``v``: the identity part and the derivative part (without boundary terms),
    each of shape (m,), not yet divided by ``C``.

    Parameters
    ----------
    quad : ProductQuadrature
        The rule on the window.
    order : {0, 1}
        0 for ``a_0``/``b_0``, 1 for ``a_1``/``b_1``.
    phi : ndarray, shape (N,)
        The coefficient at the nodes.
    dphi : ndarray, shape (N,), or None
        Its derivative at the nodes (order 1; None or all zero: ``phi' = 0``).
    v_nodes : ndarray, shape (N,)
        The signal (``y`` or ``u``) at the nodes.

    Returns
    -------
    ident : ndarray, shape (m,)
        Identity part, (9).
    deriv : ndarray, shape (m,)
        Derivative part, (10), without boundary terms.
    """
    t = quad.samples
    T, R = t - quad.a, quad.b - t
    F, B = quad.cumulative_rows(phi * v_nodes, SLOT_MOMENTS[order])
    Fd = Bd = None
    if order == 1 and dphi is not None and np.any(dphi != 0.0):
        Fd, Bd = quad.cumulative_rows(dphi * v_nodes, SLOT_MOMENTS[0])
    return slot_identity(order, F, B, T, R, Fd, Bd), slot_derivative(order, F, B, Fd, Bd)


def finish_identity(
    quad: ProductQuadrature,
    ident: np.ndarray,
    deriv: np.ndarray,
    a1: np.ndarray,
    b1: np.ndarray,
    u: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``y_E = ident / C`` (9) and ``y_E' = deriv / C + ((2T - 2R) / C - a_1) y_E
    - b_1 u`` (10), with ``a_1, b_1, u`` at the samples.

    Parameters
    ----------
    quad : ProductQuadrature
        The rule on the window.
    ident : ndarray, shape (m,)
        Sum of the identity parts (free part and every coefficient), times ``C``.
    deriv : ndarray, shape (m,)
        Sum of the derivative parts without boundary terms.
    a1, b1 : ndarray, shape (m,)
        ``a_1``, ``b_1`` at the samples.
    u : ndarray, shape (m,)
        The input at the samples.

    Returns
    -------
    y_e : ndarray, shape (m,)
        ``y_E``, (9).
    dy_e : ndarray, shape (m,)
        ``y_E'``, (10).
    """
    t = quad.samples
    T, R = t - quad.a, quad.b - t
    C = window_weight(t, quad.a, quad.b)
    y_e = ident / C
    dy_e = deriv / C + ((2.0 * T - 2.0 * R) / C - a1) * y_e - b1 * u
    return y_e, dy_e


def kernel_identity(
    t: object,
    u: object,
    y: object,
    a: Sequence[CoefficientLike],
    b: Sequence[CoefficientLike] = (),
    *,
    points: int = 6,
) -> KernelIdentity:
    """Evaluate the kernel identities (9) and (10) with *known* coefficients.

    Parameters
    ----------
    t : array_like, shape (m,)
        Uniform sample times; the window is ``[t[0], t[-1]]``.
    u, y : array_like, shape (m,)
        Input and output samples.
    a : sequence of length 2
        ``a_0(t), a_1(t)`` (:class:`~lpvest.systems.TimeFunction`,
        formula, number or callable); ``a_1'`` comes from
        :meth:`TimeFunction.derivative`.
    b : sequence of length <= 2, optional
        ``b_0(t), b_1(t)`` (missing ones are zero).
    points : int, optional
        Quadrature order (:func:`product_quadrature`).

    Returns
    -------
    KernelIdentity
        ``y``: the right-hand side of (9), equal to the data ``y`` up to the
        quadrature error when the coefficients are the system's; ``dy``: the
        derivative identity (10), equal to ``y'``.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 5, 2001)
    >>> y = np.exp(-t) * np.sin(2 * t)  # y'' + 2 y' + 5 y = 0
    >>> out = kernel_identity(t, np.zeros_like(t), y, a=[5.0, 2.0])
    >>> bool(np.max(np.abs(out.y - y)) < 1e-12)
    True
    """
    from ...systems._ltv import TimeFunction

    times, h = check_uniform_samples(t, "t")
    uu = as_vector(u, "u", times.size)
    yy = as_vector(y, "y", times.size)
    if len(a) != 2 or len(b) > 2:
        raise DimensionError(
            f"kernel_identity is for second-order systems (11): a needs (a_0, a_1) and b at most "
            f"(b_0, b_1); found {len(a)} a and {len(b)} b coefficients"
        )
    funcs = {
        "a0": TimeFunction.of(a[0]),
        "a1": TimeFunction.of(a[1]),
        "b0": TimeFunction.of(b[0] if len(b) > 0 else 0.0),
        "b1": TimeFunction.of(b[1] if len(b) > 1 else 0.0),
    }
    quad = product_quadrature(times[0], h, times.size, points=points)
    samples = quad.samples
    y_nodes, u_nodes = quad.interpolate(yy), quad.interpolate(uu)
    F, B = quad.cumulative(y_nodes)
    ident = free_identity(F, B, samples - quad.a, quad.b - samples)
    deriv = free_derivative(F, B)
    for name, f in funcs.items():
        order = int(name[1])
        di, dd = coefficient_terms(
            quad, order, f(quad.x), f.derivative()(quad.x) if order == 1 else None,
            y_nodes if name[0] == "a" else u_nodes,
        )
        ident, deriv = ident + di, deriv + dd
    y_e, dy_e = finish_identity(quad, ident, deriv, funcs["a1"](samples), funcs["b1"](samples), uu)
    return KernelIdentity(samples, y_e, dy_e)
