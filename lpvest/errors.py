"""The exception family of lpvest.

Every error lpvest raises on purpose derives from :class:`LpvestError` and from
the built-in exception a caller would expect (``ValueError`` for bad input,
``ArithmeticError`` for a numerical failure, ``RuntimeError`` for a failed
solver), so ``except ValueError`` keeps working for code that does not know
about lpvest.
"""

from __future__ import annotations

__all__ = [
    "LpvestError",
    "DimensionError",
    "NonFiniteError",
    "NotPositiveDefiniteError",
    "SchedulingRangeError",
    "ExpressionError",
    "ModelFileError",
    "IdentifiabilityError",
    "NumericalError",
    "LMIInfeasibleError",
    "SamplingError",
]


class LpvestError(Exception):
    """Base class of every error raised by lpvest on purpose."""


class DimensionError(LpvestError, ValueError):
    """An array has the wrong shape, e.g. ``"Q has shape (3, 2); expected (3, 3)"``."""


class NonFiniteError(LpvestError, ValueError):
    """An input holds NaN or inf."""


class NotPositiveDefiniteError(LpvestError, ValueError):
    """A matrix that must be symmetric positive (semi)definite is not."""


class SchedulingRangeError(LpvestError, ValueError):
    """A scheduling value lies outside the declared range (box or simplex)."""


class ExpressionError(LpvestError, ValueError):
    """A formula in a model (basis function, coefficient, map) is not valid."""


class ModelFileError(LpvestError, ValueError):
    """A model file cannot be read; the message names the file and the field."""


class IdentifiabilityError(LpvestError, ValueError):
    """The data do not determine the unknowns (rank deficiency)."""


class NumericalError(LpvestError, ArithmeticError):
    """A numerical operation failed, e.g. a singular innovation covariance."""


class LMIInfeasibleError(LpvestError, RuntimeError):
    """An LMI problem is infeasible or the solver's answer fails the check.

    Attributes
    ----------
    status : str
        The solver status string (``problem.status`` in cvxpy).
    """

    def __init__(self, message: str, *, status: str = "") -> None:
        super().__init__(message)
        self.status = status


class SamplingError(LpvestError, ValueError):
    """Sample times are not strictly increasing or not uniformly spaced where a
    method needs a uniform grid (e.g. the B-spline kernel estimator)."""
