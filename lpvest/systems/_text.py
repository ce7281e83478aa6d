"""What the model classes share to write themselves: the tables of a model
file (``to_toml``, read back by :mod:`lpvest.systems`) and the text of
``lpvest systems show`` (``describe``).

Each model class owns its ``to_toml()`` and ``describe(key)``; these are the
pieces they are made of (numbers, matrices, affine dependences, formulas).
A part that has no text form (a Python callable) raises
:class:`~lpvest.core.ModelFileError` naming it.

Examples
--------
>>> import numpy as np
>>> matrix_table(np.array([[1, 0.5]]))
[[1.0, 0.5]]
>>> print(format_matrix(np.eye(2), indent="  "))
  [[1. 0.]
   [0. 1.]]
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..core._errors import ModelFileError
from ..core._expressions import Expression
from ..core._scheduling import BasisFunction, CallableBasis, FormulaBasis

if TYPE_CHECKING:
    from ._affine import AffineDependence
    from ._ltv import TimeFunction

__all__ = [
    "number",
    "matrix_table",
    "basis_name",
    "dependence_table",
    "formula_value",
    "time_value",
    "format_matrix",
    "describe_dependence",
]


def number(x: float) -> float:
    """A number as a model file writes it (a Python float).

    Parameters
    ----------
    x : float
        A number (a numpy scalar included).

    Returns
    -------
    float
        ``float(x)``.
    """
    return float(x)


def matrix_table(m: np.ndarray) -> list[list[float]]:
    """A matrix as a list of rows of floats.

    Parameters
    ----------
    m : array_like, shape (rows, cols)
        The matrix.

    Returns
    -------
    list of list of float
        Its rows.
    """
    return [[number(v) for v in row] for row in np.asarray(m)]


def basis_name(b: BasisFunction) -> str:
    """The name (a formula) of a basis function; a Python callable has none.

    Parameters
    ----------
    b : BasisFunction
        The basis function.

    Returns
    -------
    str
        Its name.

    Raises
    ------
    ModelFileError
        ``b`` is a Python callable.
    """
    if isinstance(b, CallableBasis):
        raise ModelFileError(
            f"basis function {b.name!r} is a Python callable and cannot be written to a model file"
        )
    return b.name


def dependence_table(dep: AffineDependence) -> dict[str, object]:
    """``basis``, ``bounds`` and one entry per matrix (a plain matrix when only
    the constant term is nonzero, else a table by basis function).

    Parameters
    ----------
    dep : AffineDependence
        The matrices and their basis.

    Returns
    -------
    dict of str to object
        ``basis`` (if any), ``bounds`` (declared bounds of formula basis
        functions, if any) and the matrices; a matrix with no columns (``B``,
        ``D`` without an input) is left out.

    Raises
    ------
    ModelFileError
        A basis function is a Python callable.
    """
    out: dict[str, object] = {}
    names = [basis_name(b) for b in dep.basis]
    if names:
        out["basis"] = names
    bounds = {
        b.name: [number(v) for v in b.declared_bounds]
        for b in dep.basis
        if isinstance(b, FormulaBasis) and b.declared_bounds is not None
    }
    if bounds:
        out["bounds"] = bounds
    for key, stack in dep.coefficients.items():
        if 0 in stack.shape[1:]:  # no known input: B and D have no columns, the file leaves them out
            continue
        nonzero = [i for i in range(stack.shape[0]) if i == 0 or np.any(stack[i])]
        if nonzero == [0]:
            out[key] = matrix_table(stack[0])
        else:
            out[key] = {dep.term_names[i]: matrix_table(stack[i]) for i in nonzero}
    return out


def formula_value(e: Expression) -> float | str:
    """A constant formula as its value, any other as its source text.

    Parameters
    ----------
    e : Expression
        The formula.

    Returns
    -------
    float or str
        Its value or its source text.
    """
    return e.value() if e.is_constant else e.source


def time_value(f: TimeFunction, what: str) -> float | str:
    """A function of time as a formula; a Python callable has none.

    Parameters
    ----------
    f : TimeFunction
        The function.
    what : str
        How the error message calls it (e.g. ``"input"``, ``"a[0]"``).

    Returns
    -------
    float or str
        :func:`formula_value` of its formula.

    Raises
    ------
    ModelFileError
        ``f`` is a Python callable.
    """
    if f.expression is None:
        raise ModelFileError(f"{what} is a Python callable and cannot be written to a model file")
    return formula_value(f.expression)


def format_matrix(m: np.ndarray, indent: str = "      ") -> str:
    """A matrix printed for a person, indented.

    Parameters
    ----------
    m : array_like
        The matrix (printed with 6 digits, small values suppressed).
    indent : str, default "      "
        Put before every line.

    Returns
    -------
    str
        The lines, joined by newlines.
    """
    text = np.array2string(np.asarray(m), precision=6, suppress_small=True, max_line_width=100)
    return "\n".join(indent + line for line in text.splitlines())


def describe_dependence(dep: AffineDependence) -> list[str]:
    """The basis and each nonzero coefficient matrix, for ``describe``.

    Parameters
    ----------
    dep : AffineDependence
        The matrices and their basis.

    Returns
    -------
    list of str
        The lines (a printed matrix is one item of several lines); the
        constant term of every matrix is always shown.
    """
    lines = [f"    basis: {', '.join(dep.term_names)}"]
    for name, stack in dep.coefficients.items():
        for i, term in enumerate(dep.term_names):
            if i == 0 or np.any(stack[i]):
                lines.append(f"    {name} [{term}]  {stack.shape[1]}x{stack.shape[2]}")
                lines.append(format_matrix(stack[i]))
    return lines
