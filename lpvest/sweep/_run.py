"""Run a sweep: :func:`run_sweep` (``lpvest sweep SPEC.toml``).

Examples
--------
>>> from lpvest.sweep import run_sweep
>>> res = run_sweep("examples/sweep_kalman.toml", "out/sweep")              # doctest: +SKIP
>>> res.summary.to_pandas().groupby("sched.rate")["rms_x"].mean()           # doctest: +SKIP
>>> run_sweep("examples/sweep_kalman.toml", "out/sweep", scheduler="tcp://10.0.0.5:8786")  # doctest: +SKIP
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core._interrupt import exit_status, hold, holds, interruptible
from ..parallel._engine import Engine
from ..parallel._tasks import Outcome, SweepError, digest, execute
from ._store import FORMAT, SweepStore
from ._studies import prepare
from ._sweepfile import SweepSpec, load_sweep

if TYPE_CHECKING:
    import zarr

    from ..core._typing import ArrowTable
    from ..experiments._fmus import ExperimentFmus

__all__ = ["run_sweep", "SweepResult", "SweepInterrupted"]


class SweepInterrupted(KeyboardInterrupt):
    """``Ctrl-C`` stopped a sweep: pending tasks were cancelled, finished ones
    are on disk, and a rerun of the same spec resumes.

    Parameters
    ----------
    out : Path
        The sweep's output folder.
    finished : int
        Tasks finished and written (including earlier runs').
    total : int
        Tasks of the sweep.
    signum : int
        The signal (SIGINT: Ctrl-C; SIGTERM); the command line exits with ``128 + signum``.
    finishing : bool
        Every task was written; the summary or the figures were not (a rerun makes them).
    """

    def __init__(self, out: Path, finished: int, total: int, *, signum: int = signal.SIGINT,
                 finishing: bool = False) -> None:
        if finishing:
            text = (f"interrupted while finishing: all {total} tasks are written to {out}; "
                    "run the same sweep again to write the summary and draw the figures")
        else:
            text = (f"interrupted: {finished} of {total} tasks finished and written to {out}; "
                    "run the same sweep again to resume")
        super().__init__(text)
        self.out, self.finished, self.total, self.signum = out, finished, total, int(signum)


@dataclass(frozen=True)
class SweepResult:
    """What a sweep wrote and how it went.

    Parameters
    ----------
    out : Path
        The output folder.
    spec : SweepSpec
        The sweep that ran.
    summary : pyarrow.Table
        Task, axes, seed, metrics, status, error (``summary.parquet``).
    metrics : tuple of str
        Metric names, in column order.
    n_tasks : int
        Tasks of the sweep.
    ran : int
        Tasks run by this call.
    resumed : int
        Tasks finished by earlier runs (skipped).
    complete : bool
        Whether every task has finished (failed ones included).
    seconds : float
        Wall-clock time of this call, in seconds.
    engine : str
        Where the tasks ran (the engine's description, ``"in this process, no
        Dask"`` or ``"nothing to run"``).
    description : str
        One line on what each task runs (from the study).
    figures : tuple of Path, default ()
        The metric figures written (``out/figures/<metric>.png``).
    repaired : tuple of str, default ()
        What the rerun found damaged in ``out`` (a part file, trajectories
        whose SHA-256 differs from the one recorded) and ran again, one line each.
    """

    out: Path
    spec: SweepSpec
    summary: ArrowTable
    metrics: tuple[str, ...]
    n_tasks: int
    ran: int
    resumed: int
    complete: bool
    seconds: float
    engine: str
    description: str
    figures: tuple[Path, ...] = ()
    repaired: tuple[str, ...] = ()

    @property
    def failures(self) -> list[tuple[int, str]]:
        """``(task, error)`` of every failed task."""
        return [(r["task"], r["error"]) for r in self.summary.select(["task", "status", "error"]).to_pylist()
                if r["status"] != "ok"]

    def trajectories(self) -> zarr.Group | None:
        """The kept signals (a ``zarr.Group``: one array per signal, first axis the task), or None.

        Returns
        -------
        zarr.Group or None
            ``out/trajectories.zarr`` opened read-only; ``None`` if the sweep
            kept no signals.
        """
        import zarr

        path = self.out / "trajectories.zarr"
        return zarr.open_group(str(path), mode="r") if path.exists() else None

    def report(self, *, max_failures: int = 5) -> str:
        """A few lines: what ran, where, each metric's mean and spread per point.

        Parameters
        ----------
        max_failures : int, default 5
            Failed tasks listed with their error; the rest are counted.

        Returns
        -------
        str
            The report, one string of several lines.
        """
        from ._plot import metric_statistics

        spec = self.spec
        n_points = len(spec.points())
        n_seeds = len(spec.seeds.keys) if spec.seeds else 1
        shape = f"{n_points} point(s) x {n_seeds} seed(s)" if spec.seeds else f"{n_points} point(s)"
        lines = [f"sweep {spec.origin}: {self.description}; {self.n_tasks} tasks ({shape})"]
        lines += [f"repaired: {note}" for note in self.repaired]
        if self.ran:
            lines.append(f"ran {self.ran} task(s) in {self.seconds:.1f} s ({self.engine}); {self.resumed} "
                         f"finished earlier (resumed); {len(self.failures)} failed")
        else:
            lines.append(f"nothing to run: every task finished earlier ({len(self.failures)} failed; "
                         "--retry-failed runs them again)")
        if self.metrics and self.summary.num_rows:
            label_w = 0
            table = []
            for m in self.metrics:
                for st in metric_statistics(self.summary, spec, m):
                    point = ", ".join(f"{k} = {_fmt(v)}" for k, v in st["point"].items()) or "-"
                    label_w = max(label_w, len(point))
                    table.append((m, point, st))
            mw = max(len(m) for m in self.metrics)
            if spec.seeds is None:  # one task per point: its value
                lines.append(f"{'metric':<{mw}}  {'point':<{label_w}}  {'value':>13}")
                lines += [f"{m:<{mw}}  {point:<{label_w}}  " + (f"{st['mean']:>13.7g}" if st["ok"] else
                                                                 f"{'failed':>13}") for m, point, st in table]
                table = []
            else:
                lines.append(f"{'metric':<{mw}}  {'point':<{label_w}}  {'ok':>5}  {'mean':>11}  {'std':>10}  "
                             f"{'min':>11}  {'max':>11}")
            for m, point, st in table:
                if st["ok"]:
                    lines.append(f"{m:<{mw}}  {point:<{label_w}}  {st['ok']:>5}  {st['mean']:>11.5g}  "
                                 f"{st['std']:>10.3g}  {st['min']:>11.5g}  {st['max']:>11.5g}")
                else:
                    lines.append(f"{m:<{mw}}  {point:<{label_w}}  {0:>5}  {'-':>11}")
        for task, error in self.failures[:max_failures]:
            lines.append(f"task {task} failed: {error}")
        if len(self.failures) > max_failures:
            lines.append(f"... and {len(self.failures) - max_failures} more failed task(s) (summary.parquet)")
        wrote = [f"{self.out / 'summary.parquet'} ({self.summary.num_rows} rows)"]
        if (self.out / "trajectories.zarr").exists():
            wrote.append(str(self.out / "trajectories.zarr"))
        lines.append("wrote " + ", ".join(wrote))
        for f in self.figures:
            lines.append(f"wrote {f}")
        if not self.complete:
            lines.append(f"incomplete: {self.summary.num_rows} of {self.n_tasks} tasks finished")
        return "\n".join(lines)


def _fmt(v: object) -> str:
    if isinstance(v, tuple):
        return "[" + ", ".join(f"{x:g}" for x in v) + "]"
    return f"{v:g}" if isinstance(v, float) else str(v)


@interruptible
def run_sweep(
    spec: SweepSpec | str | Path,
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    engine: Engine | None = None,
    fmus: str | Path | ExperimentFmus | None = None,
    ship_fmus: bool = True,
    overwrite: bool = False,
    retry_failed: bool = False,
    progress: bool | None = None,
    plot: bool = True,
    on_outcome: Callable[[Outcome], None] | None = None,
    idle_timeout: float | None = None,
    flush_every: int = 256,
    flush_seconds: float = 1.0,
) -> SweepResult:
    """Run a sweep into the folder ``out`` (see :mod:`lpvest.sweep`).

    Parameters
    ----------
    spec : SweepSpec, str or Path
        The sweep (a :class:`~lpvest.sweep.SweepSpec` or a sweep file).
    out : str or Path
        Output folder (:mod:`lpvest.sweep`). A rerun of the same spec
        into it runs only the tasks not finished yet.
    scheduler : str, optional
        Address of a running Dask scheduler; default: a ``LocalCluster``.
    workers : int, optional
        Worker processes of the ``LocalCluster`` (default: one per core);
        ``0`` runs the tasks in this process, one after another (no Dask).
    engine : Engine, optional
        A started :class:`~lpvest.sweep.Engine` to use (and leave open)
        instead of ``scheduler``/``workers``.
    fmus : str, Path or ExperimentFmus, optional
        The folder of a co-simulation's FMUs (when ``spec`` is a file;
        overrides its ``fmu_dir``), or the experiments' FMU cache.
    ship_fmus : bool
        Send the FMUs to the workers (default); ``False``: workers read them
        from their paths (a shared file system).
    overwrite : bool
        Replace the results of a different sweep in ``out`` (else refused).
    retry_failed : bool
        Run the failed tasks of an earlier run again.
    progress : bool, optional
        A progress bar (default: when stderr is a terminal).
    plot : bool
        Write ``out/figures/<metric>.png``.
    on_outcome : callable, optional
        Called in this process with each task's
        :class:`~lpvest.sweep.Outcome` as it finishes (after it is recorded).
    idle_timeout : float, optional
        Give up when no task finishes for this many seconds.
    flush_every, flush_seconds : int, float
        How often finished tasks are committed to disk.

    Returns
    -------
    SweepResult
        What was written and how it went (:meth:`SweepResult.report`).

    Raises
    ------
    ModelFileError
        A mistake in the spec (one line naming the field).
    SweepError
        ``out`` holds another sweep, the cluster cannot be reached.
    SweepInterrupted
        ``Ctrl-C``: the finished tasks are written; run again to resume.
    """
    t0 = time.perf_counter()
    if not isinstance(spec, SweepSpec):
        path = Path(spec)
        is_cosim = "cosim" in _peek(path)
        spec = load_sweep(path, fmu_dir=fmus if is_cosim and isinstance(fmus, str | Path) else None)
    if workers is not None and workers == 0 and (scheduler is not None or engine is not None):
        raise SweepError("workers = 0 runs in this process; it takes no scheduler or engine")
    prepared = prepare(spec, fmus=fmus if spec.experiment is not None else None, ship_fmus=ship_fmus)
    tasks = spec.tasks()
    from .._version import __version__

    key = digest({"format": FORMAT, "lpvest": __version__, "spec": spec.identity(), "study": prepared.identity,
                  "metrics": list(prepared.metrics),
                  "signals": {k: [list(shape), list(labels)] for k, (shape, labels) in prepared.signals.items()}})
    store = SweepStore(out, spec, prepared, tasks, key, overwrite=overwrite, retry_failed=retry_failed,
                       flush_every=flush_every, flush_seconds=flush_seconds)
    pending = store.pending()
    for note in store.notes:  # at once, in case the run is interrupted before its report
        print(f"lpvest: repaired: {note}", file=sys.stderr, flush=True)
    show = sys.stderr.isatty() if progress is None else progress
    desc = f"sweep {Path(spec.origin).stem}"

    def record(outcome: Outcome) -> None:
        store.add(outcome)
        if on_outcome is not None:
            on_outcome(outcome)
        if holds("sweep-outcome"):  # the interruption tests' hook: a task is on disk, more are pending
            store.flush()
            hold("sweep-outcome")

    own = None
    label = "in this process, no Dask"
    try:
        if pending and workers == 0:
            from ..core._progress import progress_bar

            for task in progress_bar(pending, desc=desc, unit="task", show=show):
                record(execute(prepared.fn, prepared.shared, task))
        elif pending:
            if engine is None:
                own = engine = Engine(scheduler, workers=workers, idle_timeout=idle_timeout).start()
            label = engine.describe()
            engine.map(prepared.fn, prepared.shared, pending, on_outcome=record, progress=show, desc=desc)
        elif engine is not None:
            label = engine.describe()
        else:
            label = "nothing to run"
    except KeyboardInterrupt as exc:
        store.finish(complete=False, seconds=time.perf_counter() - t0, engine=label)
        raise SweepInterrupted(Path(out), len(store.rows), len(tasks), signum=exit_status(exc) - 128) from None
    except BaseException:
        store.finish(complete=False, seconds=time.perf_counter() - t0, engine=label)
        raise
    finally:
        if own is not None:
            own.close()
    seconds = time.perf_counter() - t0
    drawing = plot and bool(prepared.metrics)
    figures: tuple[Path, ...] = ()
    try:
        # with figures to draw, sweep.json says complete only once they are drawn too
        summary = store.finish(complete=not drawing, seconds=seconds, engine=label)
        if drawing:
            hold("sweep-finish")
            if summary.num_rows:
                from ._plot import plot_metrics

                figures = tuple(plot_metrics(summary, spec, prepared.metrics, Path(out) / "figures"))
            store.mark_complete()
    except KeyboardInterrupt as exc:
        raise SweepInterrupted(Path(out), len(store.rows), len(tasks), signum=exit_status(exc) - 128,
                               finishing=True) from None
    return SweepResult(Path(out), spec, summary, prepared.metrics, len(tasks), len(store.rows) - store.resumed,
                       store.resumed, len(store.rows) == len(tasks), seconds, label, prepared.description, figures,
                       tuple(store.notes))


def _peek(path: Path) -> dict[str, Any]:
    from ..core._toml import read_toml

    return read_toml(path)
