"""Named types for objects of libraries that ship no type information.

cvxpy, fmpy, pythonfmu, dask/distributed, scipy and pyarrow have neither stubs nor a
``py.typed`` marker (see the mypy overrides in ``pyproject.toml``), so their
objects are untyped to a type checker. Each alias below names one such kind of
object, so that a signature says what it takes, and every untyped name of this
kind is defined in one place. Only for those libraries' objects: lpvest's own data has
real types. Import these names under ``if TYPE_CHECKING:`` only.
"""

from __future__ import annotations

from typing import Any, TypeAlias

__all__ = [
    "CvxExpression",
    "CvxSolver",
    "FmpyModelDescription",
    "FmpyFmu",
    "DaskClient",
    "DaskCluster",
    "ScipyObject",
    "ArrowTable",
    "ArrowObject",
]

#: A cvxpy variable, parameter, expression or constraint.
CvxExpression: TypeAlias = Any  # cvxpy ships no type information (no py.typed)
#: A cvxpy solver interface (a ``cvxpy.reductions.solvers`` class or instance).
CvxSolver: TypeAlias = Any  # cvxpy ships no type information (no py.typed)
#: An ``fmpy.model_description.ModelDescription`` (or one of its parts).
FmpyModelDescription: TypeAlias = Any  # fmpy ships no type information (no py.typed)
#: An fmpy FMU instance (``fmpy.fmi2.FMU2Slave``), its callbacks or functions.
FmpyFmu: TypeAlias = Any  # fmpy ships no type information (no py.typed)
#: A ``distributed.Client``.
DaskClient: TypeAlias = Any  # dask/distributed ship no type information (no py.typed)
#: A Dask cluster (``distributed.LocalCluster``).
DaskCluster: TypeAlias = Any  # dask/distributed ship no type information (no py.typed)
#: A scipy object (an ``integrate`` ODE solver, its dense output, ...).
ScipyObject: TypeAlias = Any  # scipy ships no type information (no py.typed)
#: A ``pyarrow.Table``.
ArrowTable: TypeAlias = Any  # pyarrow ships no type information (no py.typed)
#: A pyarrow array or data type.
ArrowObject: TypeAlias = Any  # pyarrow ships no type information (no py.typed)
