"""Scheduling variables: their declared range and the basis functions of p.

An affine LPV model depends on the scheduling vector ``p`` through scalar basis
functions ``psi_i(p)`` (000_dc6273d4fec795cd.txt, eq. (3)). The kinds offered:

- :class:`Monomial`: a component ``p_j`` or a product/power of components
  (``p1*p2``, ``theta^2``); its range over the box is computed exactly, so the
  conversion to polytopic form needs nothing more.
- :class:`FormulaBasis`: any formula of the components (``sin(theta)``);
  give its ``bounds`` over the box for the polytopic conversion.
- :class:`CallableBasis`: any Python callable ``f(p) -> float``; the same.

Examples
--------
>>> space = SchedulingSpace(("theta",), lower=[-1.0], upper=[1.0])
>>> psi = Monomial.parse("theta^2", space)
>>> psi(np.array([0.5])), psi.bounds(space)
(0.25, (0.0, 1.0))
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import product
from typing import Protocol, runtime_checkable

import numpy as np

from ._errors import DimensionError, ExpressionError, SchedulingRangeError, abbreviate, shorten
from ._expressions import Expression
from ._validation import as_vector, check_box, check_finite

__all__ = [
    "SchedulingSpace",
    "BasisFunction",
    "Monomial",
    "FormulaBasis",
    "CallableBasis",
    "parse_basis",
    "box_vertices",
]


@dataclass(frozen=True, eq=False)
class SchedulingSpace:
    """The declared range of the scheduling vector: a box with named components.

    Parameters
    ----------
    names : sequence of str, length n_p
        Component names, used in formulas and error messages.
    lower, upper : array_like, shape (n_p,)
        The box ``lower <= p <= upper``.
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray

    def __init__(self, names: Sequence[str], lower: Sequence[float], upper: Sequence[float]):
        names = tuple(str(n) for n in names)
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise ExpressionError(f"scheduling names are not unique: {abbreviate(dup, 30)} appears twice")
        for n in names:
            if not n.isidentifier() or n.startswith("__"):
                raise ExpressionError(f"scheduling name {abbreviate(n, 30)} is not a valid identifier")
        lo = as_vector(lower, "scheduling lower bound", len(names))
        hi = as_vector(upper, "scheduling upper bound", len(names))
        bad = np.flatnonzero(lo > hi)
        if bad.size:
            j = int(bad[0])
            raise SchedulingRangeError(
                f"scheduling range of {names[j]}: lower bound {lo[j]:g} exceeds upper bound {hi[j]:g}"
            )
        lo.setflags(write=False)
        hi.setflags(write=False)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def dim(self) -> int:
        return len(self.names)

    def check(self, p: np.ndarray, *, what: str = "scheduling value") -> np.ndarray:
        """Return ``p`` as a float vector; raise if it is NaN, of the wrong
        length or outside the box.

        Parameters
        ----------
        p : array_like
            One scheduling value, ``n_p`` numbers (any shape of that size is
            flattened).
        what : str, default "scheduling value"
            How the range error calls ``p`` (``"<what> <name> = <value> is
            outside its declared range [lo, hi]"``).

        Returns
        -------
        p : ndarray, shape (n_p,)
            ``p`` as a float vector (values within a relative tolerance of
            ``1e-12`` outside the box are accepted as they are, not clipped).

        Raises
        ------
        DimensionError
            ``p`` does not have ``n_p`` values.
        NonFiniteError
            ``p`` holds NaN or inf.
        SchedulingRangeError
            A component lies outside the box.
        """
        p = np.asarray(p, dtype=float).reshape(-1)
        if p.shape != (self.dim,):
            raise DimensionError(f"p has shape {p.shape}; expected ({self.dim},)")
        check_finite(p, "p")
        check_box(p, self.lower, self.upper, self.names, what=what)
        return p

    def contains(self, p: np.ndarray) -> bool:
        """Whether ``p`` has ``n_p`` values inside the box (:meth:`check` passes).

        Parameters
        ----------
        p : array_like
            One scheduling value, ``n_p`` numbers.

        Returns
        -------
        inside : bool
            ``False`` for a value of the wrong length or outside the box; a
            value holding NaN or inf raises :class:`~lpvest.core.NonFiniteError`.
        """
        try:
            self.check(p)
        except (SchedulingRangeError, DimensionError):
            return False
        return True

    def corners(self) -> np.ndarray:
        """The ``2**n_p`` box corners, shape ``(2**n_p, n_p)``; corner ``v`` takes
        the upper bound in component ``j`` when bit ``j`` of ``v`` is set.

        Returns
        -------
        corners : ndarray, shape (2**n_p, n_p)
            The corners, row ``v`` being corner ``v``.
        """
        return box_vertices(self.lower, self.upper)

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """``size`` points drawn uniformly from the box, shape ``(size, n_p)``.

        Parameters
        ----------
        rng : numpy.random.Generator
            The random generator drawn from (``rng.random``).
        size : int
            The number of points.

        Returns
        -------
        points : ndarray, shape (size, n_p)
            One point per row.
        """
        return self.lower + (self.upper - self.lower) * rng.random((size, self.dim))

    def as_dict(self, p: np.ndarray) -> dict[str, np.ndarray]:
        """Component values by name; ``p`` has shape ``(..., n_p)``.

        Parameters
        ----------
        p : array_like, shape (..., n_p)
            Scheduling values, one per row (the last axis holds the components).
            Not checked against the box.

        Returns
        -------
        values : dict of str to ndarray
            Component name to ``p[..., j]``, of shape ``p.shape[:-1]``.
        """
        p = np.asarray(p, dtype=float)
        return {n: p[..., j] for j, n in enumerate(self.names)}


@runtime_checkable
class BasisFunction(Protocol):
    """A scalar function ``psi(p)`` of the scheduling vector.

    Parameters
    ----------
    *args, **kwargs
        Not used: a Protocol cannot be instantiated. :class:`Monomial`,
        :class:`FormulaBasis` and :class:`CallableBasis` conform to it.
    """

    @property
    def name(self) -> str:
        """How the function is written (a formula)."""
        ...

    def __call__(self, p: np.ndarray) -> float: ...

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Vectorised evaluation, ``p`` of shape ``(T, n_p)`` -> ``(T,)``.

        Parameters
        ----------
        p : ndarray, shape (T, n_p)
            Scheduling values, one per row.

        Returns
        -------
        psi : ndarray, shape (T,)
            ``psi(p[k])`` for every row ``k``.
        """
        ...

    def bounds(self, space: SchedulingSpace) -> tuple[float, float]:
        """An interval that contains ``psi(p)`` for every ``p`` in ``space``.

        Parameters
        ----------
        space : SchedulingSpace
            The box of the scheduling values.

        Returns
        -------
        lower, upper : float
            The interval's ends.
        """
        ...


def _interval_power(lo: float, hi: float, k: int) -> tuple[float, float]:
    if k == 0:
        return 1.0, 1.0
    a, b = lo**k, hi**k
    if k % 2 == 0 and lo <= 0.0 <= hi:
        return 0.0, max(a, b)
    return min(a, b), max(a, b)


@dataclass(frozen=True)
class Monomial:
    """``psi(p) = prod_j p_j ** exponents[j]``; the exact range over a box is known.

    Parameters
    ----------
    exponents : tuple of int, length n_p
        Non-negative integer exponents.
    name : str
        Display name, e.g. ``"p1*p2"``; also its key in model files.
    """

    exponents: tuple[int, ...]
    name: str

    @classmethod
    def parse(cls, text: str, space: SchedulingSpace) -> Monomial:
        """The monomial written as ``text``, e.g. ``"p1*p2"`` or ``"theta^2"``.

        Parameters
        ----------
        text : str
            A product of powers (non-negative whole numbers) of the components,
            with coefficient 1; kept as the :attr:`name`.
        space : SchedulingSpace
            The scheduling components the formula may use.

        Returns
        -------
        Monomial
            The basis function, with one exponent per component of ``space``.

        Raises
        ------
        ExpressionError
            ``text`` is not a valid formula of the components, or not such a
            product (a constant included).
        """
        expr = Expression.parse(text, allowed=space.names)
        exps = expr.monomial_exponents(space.names)
        if exps is None or sum(exps) == 0:
            raise ExpressionError(
                f"basis function {abbreviate(text)} is not a product of powers of "
                f"{shorten(', '.join(space.names), 60)}"
            )
        return cls(exps, text)

    @classmethod
    def component(cls, j: int, space: SchedulingSpace) -> Monomial:
        """The basis function ``psi(p) = p_j`` (0-based ``j``).

        Parameters
        ----------
        j : int
            The component's index (0-based).
        space : SchedulingSpace
            The scheduling components; the name is ``space.names[j]``.

        Returns
        -------
        Monomial
            Exponent 1 for component ``j``, 0 for the others.
        """
        exps = tuple(1 if i == j else 0 for i in range(space.dim))
        return cls(exps, space.names[j])

    @property
    def is_multiaffine(self) -> bool:
        """True if every exponent is 0 or 1 (affine in each component)."""
        return all(e <= 1 for e in self.exponents)

    def __call__(self, p: np.ndarray) -> float:
        out = 1.0
        for pj, e in zip(p, self.exponents, strict=True):
            if e:
                out *= pj**e
        return float(out)

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Vectorised evaluation, ``p`` of shape ``(..., n_p)`` -> ``(...)``.

        Parameters
        ----------
        p : array_like, shape (..., n_p)
            Scheduling values, one per row (the last axis holds the components).

        Returns
        -------
        psi : ndarray, shape (...)
            ``prod_j p[..., j] ** exponents[j]``.
        """
        p = np.asarray(p, dtype=float)
        return np.prod(p ** np.asarray(self.exponents, dtype=float), axis=-1)

    def bounds(self, space: SchedulingSpace) -> tuple[float, float]:
        """The exact range of ``psi(p)`` over the box (interval arithmetic is
        exact here: every component appears in one factor).

        Parameters
        ----------
        space : SchedulingSpace
            The box; its components are those of ``p``, in order.

        Returns
        -------
        lower, upper : float
            The least and the greatest value of ``psi`` over the box.
        """
        lo, hi = 1.0, 1.0
        for j, e in enumerate(self.exponents):
            a, b = _interval_power(float(space.lower[j]), float(space.upper[j]), e)
            prods = (lo * a, lo * b, hi * a, hi * b)
            lo, hi = min(prods), max(prods)
        return lo, hi


@dataclass(frozen=True)
class FormulaBasis:
    """``psi(p)`` given as a formula of the scheduling components.

    ``bounds`` (an interval containing the range over the box) is needed only
    for the conversion to polytopic form.

    Parameters
    ----------
    expression : Expression
        The formula, of the names in ``names``.
    names : tuple of str, length n_p
        The scheduling component names, in the order of the columns of ``p``.
    declared_bounds : tuple of (float, float) or None, default None
        An interval containing ``psi(p)`` over the box (not checked); ``None``:
        unknown (:meth:`bounds` raises).
    name : str, default ""
        How the function is written; empty: the expression's text.
    """

    expression: Expression
    names: tuple[str, ...]
    declared_bounds: tuple[float, float] | None = None
    name: str = field(default="")

    def __post_init__(self) -> None:
        if not self.name:
            object.__setattr__(self, "name", self.expression.text)

    def __call__(self, p: np.ndarray) -> float:
        return float(self.evaluate(np.asarray(p, dtype=float)[None, :])[0])

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Vectorised evaluation, ``p`` of shape ``(..., n_p)`` -> ``(...)``.

        Parameters
        ----------
        p : array_like, shape (..., n_p)
            Scheduling values, one per row (the last axis holds the components).

        Returns
        -------
        psi : ndarray, shape (...)
            The formula's value at every row (a constant broadcast to that shape).
        """
        p = np.asarray(p, dtype=float)
        vals = {n: p[..., j] for j, n in enumerate(self.names)}
        return np.broadcast_to(self.expression.evaluate(vals), p.shape[:-1]).astype(float)

    def bounds(self, space: SchedulingSpace) -> tuple[float, float]:
        """The declared interval containing ``psi(p)`` over the box.

        Parameters
        ----------
        space : SchedulingSpace
            The box (not used: the declared bounds are returned as given).

        Returns
        -------
        lower, upper : float
            :attr:`declared_bounds`.

        Raises
        ------
        ExpressionError
            No bounds were declared.
        """
        if self.declared_bounds is None:
            raise ExpressionError(
                f"basis function {abbreviate(self.name)} is not a monomial: give its bounds over the "
                "scheduling box to convert the model to polytopic form"
            )
        return self.declared_bounds


@dataclass(frozen=True)
class CallableBasis:
    """``psi(p) = fn(p)`` for any Python callable of the scheduling vector.

    Not storable in a model file. ``bounds`` is needed only for the conversion
    to polytopic form.

    Parameters
    ----------
    fn : callable
        ``fn(p) -> float`` for one scheduling value ``p`` of shape ``(n_p,)``.
    name : str
        How the function is called in messages and displays.
    declared_bounds : tuple of (float, float) or None, default None
        An interval containing ``fn(p)`` over the box (not checked); ``None``:
        unknown (:meth:`bounds` raises).
    """

    fn: Callable[[np.ndarray], float]
    name: str
    declared_bounds: tuple[float, float] | None = None

    def __call__(self, p: np.ndarray) -> float:
        return float(self.fn(np.asarray(p, dtype=float)))

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Evaluation row by row (one call of ``fn`` per row), ``p`` of shape
        ``(..., n_p)`` -> ``(...)``.

        Parameters
        ----------
        p : array_like, shape (..., n_p)
            Scheduling values, one per row (the last axis holds the components).

        Returns
        -------
        psi : ndarray, shape (...)
            ``fn`` at every row, as float.
        """
        p = np.asarray(p, dtype=float)
        return np.array([self(row) for row in p.reshape(-1, p.shape[-1])]).reshape(p.shape[:-1])

    def bounds(self, space: SchedulingSpace) -> tuple[float, float]:
        """The declared interval containing ``psi(p)`` over the box.

        Parameters
        ----------
        space : SchedulingSpace
            The box (not used: the declared bounds are returned as given).

        Returns
        -------
        lower, upper : float
            :attr:`declared_bounds`.

        Raises
        ------
        ExpressionError
            No bounds were declared.
        """
        if self.declared_bounds is None:
            raise ExpressionError(
                f"basis function {abbreviate(self.name)} is a Python callable: give its bounds over "
                "the scheduling box to convert the model to polytopic form"
            )
        return self.declared_bounds


def parse_basis(
    text: str, space: SchedulingSpace, *, bounds: tuple[float, float] | None = None
) -> BasisFunction:
    """A basis function from its model-file text: a :class:`Monomial` when the
    formula is a product of powers of the components, else a
    :class:`FormulaBasis` (with optional ``bounds``).

    Parameters
    ----------
    text : str
        The formula of the scheduling components; it may not use ``shift``.
    space : SchedulingSpace
        The scheduling components the formula may use.
    bounds : tuple of (float, float) or None, default None
        An interval containing the function's range over the box (from the
        file's ``bounds`` table). Given, the result is a :class:`FormulaBasis`
        with these bounds even for a product of powers.

    Returns
    -------
    BasisFunction
        A :class:`Monomial` or a :class:`FormulaBasis` named ``text``.

    Raises
    ------
    ExpressionError
        ``text`` is not a valid formula of the components, uses ``shift`` with
        a non-zero shift, or is constant.
    """
    expr = Expression.parse(text, allowed=space.names)
    if expr.shifts and any(k != 0 for ks in expr.shifts.values() for k in ks):
        raise ExpressionError(f"basis function {abbreviate(text)} may not use shift(); it depends on p_t only")
    exps = expr.monomial_exponents(space.names)
    if exps is not None and sum(exps) > 0 and bounds is None:
        return Monomial(exps, text)
    if expr.is_constant:
        raise ExpressionError(f"basis function {abbreviate(text)} is constant; use the constant term '1'")
    return FormulaBasis(expr, space.names, bounds, text)


def box_vertices(lower: Sequence[float] | np.ndarray, upper: Sequence[float] | np.ndarray) -> np.ndarray:
    """Corners of a box in the bit order of :meth:`SchedulingSpace.corners`.

    Parameters
    ----------
    lower, upper : array_like, shape (n,)
        The box ``lower <= p <= upper``.

    Returns
    -------
    corners : ndarray, shape (2**n, n)
        Corner ``v`` takes ``upper[j]`` where bit ``j`` of ``v`` is set, else
        ``lower[j]``.
    """
    n = len(lower)
    rows = []
    for bits in product((0, 1), repeat=n):
        bits = bits[::-1]  # bit j of v is component j
        rows.append([upper[j] if bits[j] else lower[j] for j in range(n)])
    return np.array(rows, dtype=float).reshape(2**n, n)
