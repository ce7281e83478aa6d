"""The engine of a sweep: tasks on a Dask cluster (dask.distributed).

By default an :class:`Engine` starts an embedded ``LocalCluster`` of worker
*processes*, one per core, one thread each (an FMU's Python runs in its
worker's interpreter; processes keep them apart and use every core). Given
the address of a running scheduler (``Engine("tcp://host:8786")``) it runs the
same tasks on that cluster instead; its workers need the same lpvest (and
fmpy) installed, the FMUs travel with the tasks.

How a sweep runs on it (:meth:`Engine.map`):

- The data every task reads (``shared``: the FMUs' bytes, a trajectory, a
  model) is submitted once, as the argument of one task; Dask copies its result
  to each worker once, and recomputes it if every copy is lost.
- One future per task. A task's exception is caught on the worker
  (:func:`~lpvest.parallel.execute`) and comes back as a failed outcome; a
  worker that dies takes no result with it: the scheduler runs its tasks
  again elsewhere (up to ``distributed.scheduler.allowed-failures`` deaths
  per task, then the task fails with ``KilledWorker``). Each task's outcome is
  handed over exactly once.
- Outcomes are handed to ``on_outcome`` in the order they finish; the caller
  writes them as they come.
- ``Ctrl-C`` (``KeyboardInterrupt``) cancels every pending task and re-raises.
  ``idle_timeout`` bounds the wait for the next task to finish.

**Quiet workers.** A co-simulation task calls into the FMUs through ctypes,
which releases the GIL at every call; each time another thread of the worker
wakes up (Dask's statistical profiler every 10 ms, the event-loop tick every
20 ms, the memory and system monitors) the task thread loses the GIL and waits
to get it back. In the default configuration that cost tasks 20-40 % of their
time here. The embedded cluster's workers therefore run with the profiler off
and the tick and monitors at one second (:data:`LOCAL_WORKER_CONFIG`): the
task thread is interrupted about 6 instead of 100 times a second. For a
cluster of your own, put the same settings in its Dask configuration.
"""

from __future__ import annotations

import logging
import os
import time
import uuid
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeVar

from ._tasks import Outcome, SweepError, Task, TaskResult, execute

if TYPE_CHECKING:
    from ..core._typing import DaskClient, DaskCluster

S = TypeVar("S")  #: the type of the data every task of a run shares

__all__ = ["Engine", "LOCAL_WORKER_CONFIG", "require_sweep_extra"]

#: Dask configuration of the embedded cluster's workers (see "Quiet workers" above).
LOCAL_WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def require_sweep_extra(*modules: str) -> None:
    """Import ``modules`` or raise a :class:`SweepError` saying how to install them.

    Parameters
    ----------
    *modules : str
        Module names of the ``sweep`` extra (``"distributed"``, ``"pyarrow"``).

    Raises
    ------
    SweepError
        If one of them cannot be imported (chained to its ``ImportError``).
    """
    import importlib

    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            raise SweepError(f"lpvest sweeps need {name} ({exc}); install the extra: pip install 'lpvest[sweep]'") \
                from exc


def _shared(value: S) -> S:
    """The shared data of a sweep, as a task's result (Dask keeps and copies it)."""
    return value


def _run(task: Task, fn: Callable[[S, Task], TaskResult], shared: S) -> Outcome:
    return execute(fn, shared, task)


class _AbandonedGathers(logging.Filter):
    """Drops tornado's log of an ``as_completed`` callback whose gather failed
    because the cluster closed under it: after an interruption (or an error)
    the engine cancels the pending tasks and closes the cluster while results
    may still be on their way; that failure is expected and its traceback,
    printed after "interrupted", was only noise (and made the Ctrl-C test of
    ``lpvest sweep`` fail on a loaded machine: "Traceback" in stderr)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "as_completed._track_future" not in record.getMessage()


_ABANDONED_GATHERS = _AbandonedGathers()


class Engine:
    """Where sweep tasks run: an embedded ``LocalCluster`` or an existing Dask cluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running Dask scheduler (``"tcp://10.0.0.5:8786"``). Default:
        start a ``LocalCluster`` in this process and close it with the engine.
    workers : int, optional
        Worker processes of the ``LocalCluster`` (default: one per core,
        ``os.cpu_count()``); not used with ``scheduler``.
    idle_timeout : float, optional
        Seconds to wait for the next task to finish before giving up
        (:class:`~lpvest.parallel.SweepError`); default: no limit.
    start_timeout : float
        Seconds to wait for the cluster to start, or to connect to it.
    quiet : bool
        Silence Dask's log messages below ERROR in this process (a killed
        worker, a restart), and below CRITICAL in the local cluster's worker
        processes: a worker's errors are the tasks' (recorded as their
        outcome) or the cluster closing under it (its heartbeat failing after
        Ctrl-C, on a loaded machine), which is no news.

    Examples
    --------
    >>> with Engine(workers=2) as engine:                          # doctest: +SKIP
    ...     outcomes = engine.map(fn, shared, tasks)
    >>> with Engine("tcp://scheduler:8786") as engine: ...        # doctest: +SKIP
    """

    def __init__(
        self,
        scheduler: str | None = None,
        *,
        workers: int | None = None,
        idle_timeout: float | None = None,
        start_timeout: float = 60.0,
        quiet: bool = True,
    ) -> None:
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise SweepError(f"workers must be a positive integer; found {workers!r}")
        if scheduler is not None and workers is not None:
            raise SweepError("give workers for a local cluster or scheduler for an existing one, not both")
        self.scheduler = scheduler
        self.workers = workers
        self.idle_timeout = idle_timeout
        self.start_timeout = start_timeout
        self.quiet = quiet
        self._client: DaskClient | None = None
        self._cluster: DaskCluster | None = None

    # -- life cycle -----------------------------------------------------------
    @property
    def client(self) -> DaskClient:
        """The ``distributed.Client`` (the cluster is started on first use)."""
        if self._client is None:
            self.start()
        return self._client

    def start(self) -> Engine:
        """Start the local cluster (or connect to the scheduler); nothing if started already.

        Returns
        -------
        Engine
            This engine, started (so that ``Engine(...).start()`` chains).

        Raises
        ------
        SweepError
            The cluster did not start, or the scheduler cannot be reached, within
            ``start_timeout``; or dask.distributed is not installed.
        """
        if self._client is not None:
            return self
        require_sweep_extra("distributed")
        import dask
        from distributed import Client, LocalCluster

        if self.quiet:
            for name in ("distributed", "distributed.nanny", "distributed.worker", "distributed.scheduler"):
                logging.getLogger(name).setLevel(logging.ERROR)
        tornado_log = logging.getLogger("tornado.application")
        if _ABANDONED_GATHERS not in tornado_log.filters:
            tornado_log.addFilter(_ABANDONED_GATHERS)
        try:
            if self.scheduler is None:
                n = self.workers or os.cpu_count() or 1
                # the workers ignore SIGINT: Ctrl-C is the client's to handle (lpvest.parallel._worker)
                with dask.config.set(LOCAL_WORKER_CONFIG):
                    self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                 dashboard_address=":0", preload=["lpvest.parallel._worker"],
                                                 silence_logs=logging.CRITICAL if self.quiet else logging.WARNING)
                self._client = Client(self._cluster, timeout=self.start_timeout)
            else:
                self._client = Client(self.scheduler, timeout=self.start_timeout)
        except OSError as exc:
            self.close()
            where = self.scheduler or "a local cluster"
            raise SweepError(f"cannot start or reach the Dask scheduler ({where}): {exc}") from exc
        return self

    @property
    def n_workers(self) -> int:
        """Workers the scheduler knows now."""
        return len(self.client.scheduler_info(n_workers=-1)["workers"])

    def close(self) -> None:
        """Close the client, and the local cluster if this engine started it."""
        client, cluster = self._client, self._cluster
        self._client = self._cluster = None
        if client is not None:
            try:
                client.close(timeout=self.start_timeout)
            except Exception:  # noqa: BLE001 - closing after a failure: go on to the cluster
                pass
        if cluster is not None:
            try:
                cluster.close(timeout=self.start_timeout)
            except Exception:  # noqa: BLE001
                pass

    def __enter__(self) -> Engine:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> str:
        """Where the tasks run, in a few words (the cluster is started if it is not yet).

        Returns
        -------
        str
            ``"Dask LocalCluster, 2 worker process(es)"`` or
            ``"Dask scheduler tcp://...: 8 worker(s)"``.
        """
        if self.scheduler is None:
            return f"Dask LocalCluster, {self.n_workers} worker process(es)"
        return f"Dask scheduler {self.scheduler}, {self.n_workers} worker(s)"

    # -- running --------------------------------------------------------------
    def map(
        self,
        fn: Callable[[S, Task], TaskResult],
        shared: S,
        tasks: Sequence[Task],
        *,
        on_outcome: Callable[[Outcome], None] | None = None,
        progress: bool = False,
        desc: str = "tasks",
    ) -> dict[int, Outcome]:
        """Run ``fn(shared, task)`` for every task; return the outcomes by task index.

        Parameters
        ----------
        fn : callable ``(shared, Task) -> TaskResult``
            The task function: a module-level function importable on the
            workers. An exception it raises becomes the task's failed outcome.
        shared : object
            Data every task reads (picklable); sent to each worker once.
        tasks : sequence of Task
            The tasks to run (their ``index`` keys the result).
        on_outcome : callable ``(Outcome) -> None``, optional
            Called in this process once per task, in the order they finish (an
            exception from it cancels the rest and propagates); a sweep writes
            each outcome here.
        progress : bool, default False
            Show a progress bar (tqdm) of the finished tasks, with the failed count.
        desc : str, default "tasks"
            The progress bar's label.

        Returns
        -------
        dict of int to Outcome
            Every task's outcome, by task index: its result, or the error that
            stopped it (its own exception, or ``KilledWorker`` when its workers
            died too often).

        Raises
        ------
        KeyboardInterrupt
            ``Ctrl-C``: the pending tasks are cancelled first.
        SweepError
            No task finished within ``idle_timeout``.
        """
        from distributed import as_completed

        from ..core._progress import progress_bar

        client = self.client
        if not tasks:
            return {}
        run_id = uuid.uuid4().hex[:12]
        shared_future = client.submit(_shared, shared, key=f"lpvest-shared-{run_id}", pure=False)
        futures = client.map(_run, list(tasks), fn=fn, shared=shared_future,
                             key=[f"lpvest-task-{run_id}-{t.index}" for t in tasks], pure=False)
        index_of = {f.key: t.index for f, t in zip(futures, tasks, strict=True)}
        outcomes: dict[int, Outcome] = {}
        bar = progress_bar(desc=desc, total=len(tasks), unit="task", show=progress, smoothing=0.05)
        failed = 0
        ac = as_completed(futures, with_results=True, raise_errors=False)
        last = time.monotonic()
        try:
            while not ac.is_empty():
                batch = ac.next_batch(block=False)
                if not batch:
                    if self.idle_timeout is not None and time.monotonic() - last > self.idle_timeout:
                        raise SweepError(f"no task finished in {self.idle_timeout:g} s "
                                         f"({len(outcomes)} of {len(tasks)} done)")
                    time.sleep(0.02)
                    continue
                last = time.monotonic()
                for future, value in batch:
                    index = index_of[future.key]
                    if index in outcomes:  # pragma: no cover - as_completed yields a future once
                        continue
                    if isinstance(value, Outcome):
                        # the result arrived; the future's status may already say
                        # otherwise (its worker died after sending it: "lost" or
                        # "pending" while the scheduler recomputes it)
                        outcome = value
                    else:  # the task could not run: KilledWorker, cancelled, lost data
                        exc = value[1] if isinstance(value, tuple) and len(value) == 3 else value
                        text = " ".join(str(exc).split()) if exc is not None else future.status
                        name = type(exc).__name__ if isinstance(exc, BaseException) else "TaskError"
                        outcome = Outcome(index, None, f"{name}: {text}", 0.0, "")
                    outcomes[index] = outcome
                    failed += not outcome.ok
                    if on_outcome is not None:
                        on_outcome(outcome)
                    bar.update(1)
                    if failed:
                        bar.set_postfix(failed=failed, refresh=False)
                    future.release()
        except BaseException:
            client.cancel([f for f in futures if index_of[f.key] not in outcomes] + [shared_future], force=True)
            raise
        finally:
            bar.close()
        shared_future.release()
        return outcomes
