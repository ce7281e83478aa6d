"""Tasks, seeds and the Dask engine that experiments and sweeps share.

A computation made of many independent members (a Monte Carlo run, a design
per parameter value, a co-simulation per seed) is a list of :class:`Task`,
each run by a module-level function ``fn(shared, task) -> TaskResult``.
:func:`map_tasks` runs them serially in this process or on an
:class:`Engine` (an embedded Dask ``LocalCluster`` of worker processes, or an
existing cluster) and gives the same numbers either way: every task runs with
BLAS on one thread (:func:`one_blas_thread`) and draws its seeds from the
task's own child of a seed sequence (:func:`task_seeds`), never from the
order in which tasks run. :func:`execute` turns a task's exception into a
failed :class:`Outcome`, so one bad task never stops the others.

:mod:`lpvest.experiments` runs its Monte Carlo parts through this package,
:mod:`lpvest.sweep` its sweeps; a study of either returns a
:class:`Prepared` (the task function, the shared data, the metric names).

Only numpy is needed to import it; Dask comes with the extra
``pip install 'lpvest[sweep]'`` and is imported when an :class:`Engine`
starts (:func:`require_sweep_extra`).

Examples
--------
>>> from lpvest.parallel import task_seeds
>>> task_seeds(2026, 0, ["plant.seed"])
{'plant.seed': 239621810}
>>> from lpvest.parallel import Engine, map_tasks
>>> with Engine(workers=2) as engine:                         # doctest: +SKIP
...     results = map_tasks(fn, shared, points, engine=engine)
"""

from __future__ import annotations

from ._engine import LOCAL_WORKER_CONFIG, Engine, require_sweep_extra
from ._prepared import Prepared
from ._tasks import (
    Outcome,
    SweepError,
    Task,
    TaskResult,
    digest,
    execute,
    map_tasks,
    one_blas_thread,
    task_seeds,
)

__all__ = [
    "Engine",
    "LOCAL_WORKER_CONFIG",
    "Outcome",
    "Prepared",
    "SweepError",
    "Task",
    "TaskResult",
    "digest",
    "execute",
    "map_tasks",
    "one_blas_thread",
    "require_sweep_extra",
    "task_seeds",
]
