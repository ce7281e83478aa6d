"""Tasks of a sweep, what they return, and the in-process runner.

A sweep is a list of :class:`Task` (one co-simulation, one Monte Carlo
member, one design ...), each run by a module-level function
``fn(shared, task) -> TaskResult`` on data ``shared`` that every task reads
(the FMUs, a trajectory, a model). :func:`execute` wraps such a call the same
way on a Dask worker and in this process: an exception becomes a failed
:class:`Outcome` carrying its message, so one bad task never stops the others.

This module needs only lpvest's own dependencies (numpy, scipy, threadpoolctl):
the experiments import it whether or not the ``sweep`` extra (Dask, pyarrow,
zarr) is installed, and run their tasks through
:func:`map_tasks` serially or on an :class:`~lpvest.parallel.Engine`.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from ..core._errors import LpvestError

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

    from ._engine import Engine

S = TypeVar("S")  #: the type of the data every task of a run shares

__all__ = ["Task", "TaskResult", "Outcome", "SweepError", "execute", "map_tasks", "one_blas_thread", "task_seeds",
           "digest"]


def digest(identity: Mapping[str, object]) -> str:
    """SHA-256 of a JSON-able identity (keys sorted).

    Parameters
    ----------
    identity : mapping
        JSON-able data; values JSON cannot hold are written as ``str(value)``.

    Returns
    -------
    str
        The hex digest (64 characters).
    """
    return hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode()).hexdigest()


class SweepError(LpvestError, RuntimeError):
    """A sweep cannot run: an output folder holding another sweep, a task of
    an experiment that failed, a missing optional dependency, no cluster."""


@dataclass(frozen=True)
class Task:
    """One member of a sweep.

    Parameters
    ----------
    index : int
        Position in the sweep (0-based): parameter points outer, seeds inner.
    point : mapping, default {}
        The swept values of this task, by axis name (``{"truncated.tau": 3}``).
    seed : int or None, default None
        The seed key (member of ``seeds``), ``None`` without a seed axis.
    seed_values : mapping of str to int, default {}
        The 32-bit seeds this task gives to FMU parameters (``{"plant.seed":
        1234567}``), derived from :func:`task_seeds`.
    """

    index: int
    point: Mapping[str, Any] = field(default_factory=dict)
    seed: int | None = None
    seed_values: Mapping[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class TaskResult:
    """What a task function returns.

    Parameters
    ----------
    metrics : mapping of str to float, default {}
        Summary numbers (one column each in the summary table).
    signals : mapping of str to ndarray, default {}
        Arrays to keep (trajectories), each of the shape the study declares.
    value : object, optional
        Anything else for an in-process caller (a design, a fit); not stored.
    """

    metrics: Mapping[str, float] = field(default_factory=dict)
    signals: Mapping[str, np.ndarray] = field(default_factory=dict)
    value: Any = None


@dataclass(frozen=True)
class Outcome:
    """A task's result or its failure, with where and how long it ran.

    Parameters
    ----------
    index : int
        The task's :attr:`Task.index`.
    result : TaskResult or None
        What the task function returned; ``None`` if it failed.
    error : str or None
        ``"ExceptionType: message"`` (one line) if the task failed, else ``None``.
    seconds : float
        Wall-clock time of the task function, in seconds.
    worker : str
        Where it ran: the Dask worker's address, or ``host:pid`` in this process.
    """

    index: int
    result: TaskResult | None
    error: str | None
    seconds: float
    worker: str

    @property
    def ok(self) -> bool:
        return self.error is None


def task_seeds(root: int, spawn_index: int, names: Sequence[str]) -> dict[str, int]:
    """The 32-bit seeds of one task, one per name in ``names``.

    They come from ``numpy.random.SeedSequence(root).spawn(n)[spawn_index]``
    (the same as ``SeedSequence(root, spawn_key=(spawn_index,))``):
    ``generate_state(len(names), uint32)`` shifted right by one bit, so every
    value fits an FMI Integer (signed 32-bit, ``0 <= s < 2**31``). They depend
    on ``root``, ``spawn_index`` and the number of names only: never on the
    number of workers or on the order in which tasks run.

    Parameters
    ----------
    root : int
        Root entropy of the sweep's seed sequence.
    spawn_index : int
        The task's child of the root sequence.
    names : sequence of str
        The seeded FMU parameters (``"component.parameter"``).

    Returns
    -------
    dict of str to int
        One seed per name, ``0 <= s < 2**31``; empty if ``names`` is empty.

    Examples
    --------
    >>> task_seeds(2026, 0, ["plant.seed", "sched.seed"])
    {'plant.seed': 239621810, 'sched.seed': 388765903}
    """
    if not names:
        return {}
    state = np.random.SeedSequence(int(root), spawn_key=(int(spawn_index),)).generate_state(len(names), np.uint32)
    return {name: int(v >> 1) for name, v in zip(names, state, strict=True)}


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


def one_blas_thread() -> AbstractContextManager[object]:
    """A context manager that runs BLAS on one thread, as on a Dask worker
    (whose nanny sets ``OMP/OPENBLAS/MKL_NUM_THREADS=1``; see :func:`execute`).

    Every BLAS loaded when it is entered is limited: numpy's and scipy's, which
    are two libraries (numpy's and scipy's wheels each carry an OpenBLAS of their
    own), so scipy's is loaded first. A controller made earlier and kept would
    miss a BLAS loaded after it: scipy's kept its default threads, and a task
    run in this process differed from the same task on a worker in its last bits
    (the Sridhar GCV fit by 3e-11). Finding the libraries costs about 1.5 ms.

    Returns
    -------
    context manager
        ``with one_blas_thread(): ...`` (threadpoolctl's limit).
    """
    import scipy.linalg  # noqa: F401 - loads scipy's own BLAS, so that the limit covers it
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController().limit(limits=1, user_api="blas")


def execute(fn: Callable[[S, Task], TaskResult], shared: S, task: Task) -> Outcome:
    """Run ``fn(shared, task)``; an exception becomes a failed :class:`Outcome`
    whose ``error`` is ``"ExceptionType: message"`` (one line).

    The task runs with BLAS on one thread, as on a Dask worker (whose nanny
    sets ``OMP/OPENBLAS/MKL_NUM_THREADS=1``): a multithreaded BLAS splits its
    sums by thread and rounds them in another order, so without the limit a
    task run in this process could differ from the same task on a worker in
    its last bits (a least-squares fit amplifies that). With it, a task gives
    the same numbers wherever it runs.

    Parameters
    ----------
    fn : callable
        Module-level task function ``fn(shared, task) -> TaskResult``; any other
        return value is a failure (``TypeError``).
    shared : object
        Data every task reads, passed to ``fn`` as is.
    task : Task
        The task to run.

    Returns
    -------
    Outcome
        The result, or the failure's message, with the run time and worker name.
    """
    t0 = time.perf_counter()
    try:
        with one_blas_thread():
            result = fn(shared, task)
        if not isinstance(result, TaskResult):
            raise TypeError(f"{getattr(fn, '__name__', fn)} returned {type(result).__name__}, not a TaskResult")
        error = None
    except Exception as exc:  # noqa: BLE001 - a task's failure is data: recorded, the sweep goes on
        result = None
        text = " ".join(str(exc).split())
        error = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return Outcome(task.index, result, error, time.perf_counter() - t0, _worker_name())


def map_tasks(
    fn: Callable[[S, Task], TaskResult],
    shared: S,
    points: Sequence[Mapping[str, object] | Task],
    *,
    engine: Engine | None = None,
    progress: bool = False,
    desc: str = "tasks",
) -> list[TaskResult]:
    """Run ``fn`` over ``points`` and return the results in order, serially in
    this process (``engine=None``) or on a Dask :class:`~lpvest.parallel.Engine`.

    The experiments run their Monte Carlo members through this function: the
    same task function gives the same numbers either way.

    Parameters
    ----------
    fn : callable
        Module-level task function ``fn(shared, task) -> TaskResult``.
    shared : object
        Data every task reads, passed to ``fn`` as is.
    points : sequence of (mapping or Task)
        The tasks; a mapping (axis name -> value) becomes ``Task(i, point)``
        with ``i`` its position.
    engine : Engine or None, default None
        Dask engine to run on; ``None`` runs serially in this process.
    progress : bool, default False
        Show a progress bar.
    desc : str, default "tasks"
        Label of the progress bar and of the error message.

    Returns
    -------
    list of TaskResult
        The results, in the order of ``points``.

    Raises
    ------
    SweepError
        A task failed (its message names the task's point); the experiments
        treat any failure as an error.
    """
    tasks = [p if isinstance(p, Task) else Task(i, dict(p)) for i, p in enumerate(points)]
    if engine is None:
        from ..core._progress import progress_bar

        outcomes = {t.index: execute(fn, shared, t) for t in progress_bar(tasks, desc=desc, show=progress,
                                                                          leave=False, unit="task")}
    else:
        outcomes = engine.map(fn, shared, tasks, desc=desc, progress=progress)
    results = []
    for t in tasks:
        out = outcomes[t.index]
        if out.result is None:
            point = ", ".join(f"{k} = {v!r}" for k, v in t.point.items()) or f"task {t.index}"
            raise SweepError(f"{desc}: task {t.index} ({point}) failed: {out.error}")
        results.append(out.result)
    return results
