"""Sweeps and Monte Carlo over co-simulations, on Dask.

The same co-simulation (a file of :mod:`lpvest.cosim`) or the Monte Carlo
part of a paper experiment, run over seeds and parameter values: one task per
combination, on an embedded Dask ``LocalCluster`` (one worker process per
core) or on an existing cluster, with the results written as tasks finish
(summary as Parquet, trajectories as Zarr) and a rerun resuming where the
last one stopped.

- the sweep file (axes, seeds, metrics, kept signals): :func:`load_sweep`;
- the summary metrics of a co-simulation: :class:`Metric`;
- a co-simulation file as tasks, or an experiment's study
  (:func:`experiment_studies`, from :mod:`lpvest.experiments`);
- the tasks, their seeds and the Dask engine, from :mod:`lpvest.parallel`
  (re-exported here: :class:`Engine`, :class:`Task`, :func:`map_tasks`, ...);
- the output folder and a figure per metric: :func:`run_sweep`.

Dask, pyarrow and zarr come with the extra ``pip install 'lpvest[sweep]'``;
they are imported when a sweep runs, not with this package.

Examples
--------
>>> from lpvest.sweep import run_sweep
>>> res = run_sweep("examples/sweep_kalman.toml", "out/sweep")     # doctest: +SKIP
>>> print(res.report())                                            # doctest: +SKIP
"""

from __future__ import annotations

from ..experiments._studies import experiment_studies as experiment_studies
from ..parallel._engine import (
    LOCAL_WORKER_CONFIG as LOCAL_WORKER_CONFIG,
    Engine as Engine,
)
from ..parallel._tasks import (
    Outcome as Outcome,
    SweepError as SweepError,
    Task as Task,
    TaskResult as TaskResult,
    execute as execute,
    map_tasks as map_tasks,
    one_blas_thread as one_blas_thread,
    task_seeds as task_seeds,
)
from ._metrics import METRIC_KINDS as METRIC_KINDS, Metric as Metric
from ._run import SweepInterrupted as SweepInterrupted, SweepResult as SweepResult, run_sweep as run_sweep
from ._sweepfile import (
    Axis as Axis,
    Seeds as Seeds,
    SweepSpec as SweepSpec,
    load_sweep as load_sweep,
    sweep_spec as sweep_spec,
)

__all__ = [
    "Axis",
    "Engine",
    "METRIC_KINDS",
    "Metric",
    "Outcome",
    "Seeds",
    "SweepError",
    "SweepInterrupted",
    "SweepResult",
    "SweepSpec",
    "Task",
    "TaskResult",
    "experiment_studies",
    "load_sweep",
    "map_tasks",
    "run_sweep",
    "sweep_spec",
    "task_seeds",
    "LOCAL_WORKER_CONFIG",
    "execute",
    "one_blas_thread",
]
