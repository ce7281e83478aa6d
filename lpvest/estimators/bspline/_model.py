"""The coefficient declarations of (11) (:class:`Known`, :class:`UnknownConstant`,
:class:`UnknownSpline`) and the model they make (:class:`KernelModel`).

Notes: :mod:`lpvest.estimators.bspline`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ...core._errors import (
    DimensionError,
    ExpressionError,
    abbreviate,
)
from ...core._validation import as_vector
from ...systems._ltv import LTVInputOutput, TimeFunction

__all__ = ["COEFFICIENTS", "Known", "UnknownConstant", "UnknownSpline", "Coefficient", "KernelModel"]


#: The coefficients of (11), in this order.
COEFFICIENTS = ("a0", "a1", "b0", "b1")

# -- coefficient declarations ------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Known:
    """A known coefficient: a :class:`~lpvest.systems.TimeFunction`, a
    formula of ``t``, a number or a callable. Its derivative (needed for
    ``a_1``, ``b_1``) comes from :meth:`TimeFunction.derivative`.

    Parameters
    ----------
    value : TimeFunction, str, float or callable
        The coefficient as a function of ``t`` (:meth:`TimeFunction.of`):
        a formula of ``t`` (``"-1/(t + 1000)"``), a number or a callable.

    Raises
    ------
    ExpressionError
        ``value`` is none of these, or a formula that does not parse.
    """

    function: TimeFunction

    def __init__(self, value: object) -> None:
        object.__setattr__(self, "function", TimeFunction.of(value))

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

    Parameters
    ----------
    a0 : Known, UnknownConstant, UnknownSpline, str, float or callable
        ``a_0(t)``, the coefficient of ``y``.
    a1 : Known, UnknownConstant, UnknownSpline, str, float or callable
        ``a_1(t)``, the coefficient of ``y'``; a spline needs order >= 2.
    b0 : Known, UnknownConstant, UnknownSpline, str, float or callable, default 0.0
        ``b_0(t)``, the coefficient of ``u``.
    b1 : Known, UnknownConstant, UnknownSpline, str, float or callable, default 0.0
        ``b_1(t)``, the coefficient of ``u'``; a spline needs order >= 2.

    Raises
    ------
    ExpressionError
        A value is not a coefficient declaration, formula, number or callable.
    DimensionError
        ``a1`` or ``b1`` is a B-spline of order 1 (no derivative for (10)).

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
        except those given as keywords (``a0=UnknownSpline(86)``, ...).

        Parameters
        ----------
        io : LTVInputOutput
            A second-order input-output model (11); ``b`` coefficients it
            lacks are zero.
        **unknown : Coefficient
            Declarations replacing the model's coefficients, by name
            (``a0``, ``a1``, ``b0``, ``b1``).

        Returns
        -------
        KernelModel
            The model with ``io``'s coefficients as :class:`Known`, except those given.

        Raises
        ------
        DimensionError
            ``io`` is not of order 2, or a keyword is not a coefficient name.
        """
        if io.order != 2:
            raise DimensionError(
                f"the kernel estimator is for second-order systems (11); the model has order {io.order}"
            )
        bad = sorted(set(unknown) - set(COEFFICIENTS))
        if bad:
            raise DimensionError(f"unknown coefficient name {abbreviate(bad[0], 30)}; expected one of "
                                 f"{', '.join(COEFFICIENTS)}")
        b = (*io.b, *(TimeFunction.of(0.0) for _ in range(2 - len(io.b))))
        known: dict[str, object] = {"a0": io.a[0], "a1": io.a[1], "b0": b[0], "b1": b[1]}
        known.update(unknown)
        return cls(**known)

    def coefficient(self, name: str) -> Coefficient:
        """The declaration of one coefficient.

        Parameters
        ----------
        name : {"a0", "a1", "b0", "b1"}
            The coefficient of (11).

        Returns
        -------
        Known, UnknownConstant or UnknownSpline
            Its declaration.
        """
        return getattr(self, name)

    @property
    def unknowns(self) -> tuple[str, ...]:
        """Names of the unknown coefficients, in the order of the columns of ``P``."""
        return tuple(n for n in COEFFICIENTS if not isinstance(getattr(self, n), Known))

    def n_unknowns(self) -> int:
        """Number of unknown scalar coefficients (the paper's ``2n`` in ``rank P = 2n``).

        Returns
        -------
        int
            ``n_basis`` per unknown spline plus one per unknown constant (the
            number of columns of ``P``).
        """
        total = 0
        for n in self.unknowns:
            c = getattr(self, n)
            total += c.n_basis if isinstance(c, UnknownSpline) else 1
        return total


