"""The errors of a co-simulation: a failed component or an invalid set-up
(:class:`CoSimulationError`), and a loop through direct feedthrough
(:class:`AlgebraicLoopError`, raised by the ordering in ``_graph.py``)."""

from __future__ import annotations

from ..core._errors import LpvestError

__all__ = ["CoSimulationError", "AlgebraicLoopError"]


class CoSimulationError(LpvestError, RuntimeError):
    """A component failed, or the set-up is invalid (names, types, units).

    Parameters
    ----------
    message : str
        The error message.
    where : str, default ""
        The field the error is about (stored as :attr:`where`, see below).

    Attributes
    ----------
    where : str
        What in the set-up the error is about, in the terms of a co-simulation
        file (:mod:`lpvest.cosim`): ``"connections[2]"`` (1-based),
        ``"components.plant"``, ``"components.plant.parameters.x0"``,
        ``"record[1]"``, ``"step_size"``; ``""`` when it is about no one field.
    """

    def __init__(self, message: str, *, where: str = "") -> None:
        super().__init__(message)
        self.where = where


class AlgebraicLoopError(CoSimulationError):
    """The connections close a loop through direct-feedthrough paths.

    Parameters
    ----------
    message : str
        The error message (names the variables on the loop).
    where : str, default ""
        The field the error is about (``"connections"`` when raised by the master).
    """

