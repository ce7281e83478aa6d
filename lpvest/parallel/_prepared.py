"""A set of tasks ready to run: :class:`Prepared`.

What a sweep's preparation returns, whether it comes from a co-simulation
file (:mod:`lpvest.sweep`) or from a paper experiment's study
(:mod:`lpvest.experiments`): the task function, the data every task reads,
the metric names, the shapes of the kept signals, and the identity of what
the results depend on. It lives on this floor so that both can build it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._tasks import Task, TaskResult

__all__ = ["Prepared"]


@dataclass(frozen=True)
class Prepared:
    """A sweep ready to run: what each task calls and what it returns.

    Parameters
    ----------
    fn : callable
        Module-level task function ``fn(shared, Task) -> TaskResult``.
    shared : object
        What every task reads (picklable).
    metrics : tuple of str
        The metric names, in column order.
    signals : mapping, default {}
        Kept signal -> (shape per task, element labels).
    identity : mapping, default {}
        What the results depend on besides the sweep's own spec (JSON-able).
    time : ndarray or None, default None
        The first axis of every signal (co-simulation time), if any.
    description : str, default ""
        One line on what each task runs.
    """

    fn: Callable[[Any, Task], TaskResult]
    shared: Any
    metrics: tuple[str, ...]
    signals: Mapping[str, tuple[tuple[int, ...], tuple[str, ...]]] = field(default_factory=dict)
    identity: Mapping[str, object] = field(default_factory=dict)
    time: np.ndarray | None = None
    description: str = ""
