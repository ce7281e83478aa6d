"""Run experiments (``lpvest reproduce NAME|all``): each writes its figures and
``results.json`` into ``OUT/<name>/``, and ``all`` writes ``OUT/report.md``.

The FMUs come from an :class:`~lpvest.experiments.ExperimentFmus` cache
(``OUT/fmu-cache`` from the command line), built on first use and reused while
up to date.

**Side by side.** With ``workers`` (default: one per core) the experiments
run as tasks on the project's Dask engine (:class:`lpvest.parallel.Engine`, an
embedded ``LocalCluster`` of worker processes): one task per experiment, one
for each group of experiments that share a computation
(:attr:`~lpvest.experiments.Experiment.group`: the three Sridhar experiments
share one co-simulation), and one per task of a split experiment
(:attr:`~lpvest.experiments.Experiment.split`: Example 2's values of
``rho``), whose last step runs in this process when its tasks are done. The
FMUs the experiments declare (:attr:`~lpvest.experiments.Experiment.fmus`) are
checked first and the missing or stale ones built side by side on the
workers, each recorded in the cache's manifest by this process only; the
experiments' tasks then only read them.
Every task runs with BLAS on one thread, in this process too
(:func:`~lpvest.parallel.one_blas_thread`), so the numbers are the same,
bit for bit, whatever the number of workers, and so is the report (but for
the times it states). ``workers=0`` runs everything in this process, one
experiment after another; so does a run with a single task.

Progress: one line per finished task (``[ 3/27] peixoto-example2: rho = 3
(2.1 s)``), each experiment's output when it is complete, and no progress bars
from the workers. In this process, an experiment shows its own progress bars
only when stderr is a terminal.

Examples
--------
>>> from lpvest.experiments import reproduce_all
>>> runs = reproduce_all("out", reduced=True)                  # doctest: +SKIP
>>> [r.name for r in runs if not r.ok]                         # doctest: +SKIP
[]
>>> runs = reproduce_all("out", workers=0)   # in this process   # doctest: +SKIP
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import json
import os
import pickle
import secrets
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core._errors import ArgumentError, LpvestError, abbreviate
from ..core._interrupt import Interrupted, exit_status, hold
from ..core._paths import user_cache_dir
from ..parallel._tasks import Outcome, SweepError, Task, TaskResult, one_blas_thread
from . import Experiment, ExperimentResult, Split, write_results
from ._fmus import ExperimentFmus, as_experiment_fmus

if TYPE_CHECKING:
    from ..parallel._engine import Engine

__all__ = ["ExperimentRun", "ReproduceInterrupted", "reproduce", "reproduce_all", "default_workers"]


@dataclass(frozen=True)
class ExperimentRun:
    """One experiment as it ran: its result, where it wrote, how long it took
    (a split experiment: its tasks' times and its last step's, added up).

    Parameters
    ----------
    name : str
        The experiment's registered name.
    title : str
        Its title.
    result : ExperimentResult
        What it returned.
    folder : Path
        Where it wrote, ``out/<name>/``.
    results_path : Path
        Its ``results.json`` in ``folder``.
    seconds : float
        How long it ran.
    options : dict
        The keyword options it ran with: its reduced configuration
        (:attr:`Experiment.reduced`) when ``reduced`` was asked for, else
        empty.
    """

    name: str
    title: str
    result: ExperimentResult
    folder: Path
    results_path: Path
    seconds: float
    options: dict

    @property
    def ok(self) -> bool:
        """The FMU results agree with the library (True when there is no FMU part)."""
        return self.result.fmu is None or self.result.fmu.ok


class ReproduceInterrupted(Interrupted):
    """``Ctrl-C`` or SIGTERM stopped :func:`reproduce`: the experiments that
    finished wrote their ``results.json`` (each written whole, or not at all)
    and their resume record, the FMU cache keeps every FMU built so far, and a
    rerun reuses those FMUs and keeps the finished experiments (it runs the
    others: see :func:`reproduce`).

    Parameters
    ----------
    finished : sequence of ExperimentRun
        The experiments that finished and wrote their results, in order.
    names : sequence of str
        Every experiment of the run.
    out : Path
        The output folder (``out/<name>/results.json``).
    cache : Path
        The FMU cache's folder.
    signum : int
        The signal (SIGINT: Ctrl-C; SIGTERM); the command line exits with ``128 + signum``.
    report : bool
        The run was to write ``out/report.md`` too (``reproduce_all``); it did not.
    """

    def __init__(self, finished: Sequence[ExperimentRun], names: Sequence[str], out: Path, cache: Path, *,
                 signum: int, report: bool = False) -> None:
        super().__init__(signum)
        self.finished, self.names, self.out, self.cache = tuple(finished), tuple(names), out, cache
        self.report = report

    def with_report(self) -> ReproduceInterrupted:
        """The same interruption, of a run that was to write ``report.md``.

        Returns
        -------
        ReproduceInterrupted
            A copy with ``report`` true.
        """
        return ReproduceInterrupted(self.finished, self.names, self.out, self.cache, signum=self.signum,
                                    report=True)

    def __str__(self) -> str:
        done = [r.name for r in self.finished]
        if done:
            shown = ", ".join(done[:3]) + (f" and {len(done) - 3} more" if len(done) > 3 else "")
            kept = (f"kept the results of {len(done)} of {len(self.names)} experiment(s) ({shown}: "
                    f"{self.out}/NAME/results.json)")
        else:
            kept = f"none of the {len(self.names)} experiment(s) finished"
        return (kept + ("; report.md was not written" if self.report else "")
                + f"; the FMU cache {self.cache} keeps every FMU built so far; run the same command again: it "
                "reuses those FMUs and the finished experiments and runs the others")


def default_workers() -> int:
    """Worker processes of ``lpvest reproduce`` by default: one per core."""
    return os.cpu_count() or 1


def _check_workers(workers: int | None) -> int:
    if workers is None:
        return default_workers()
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ArgumentError(f"workers must be an integer >= 0 (0: in this process); found {workers!r}")
    return workers


def _groups(selected: Sequence[Experiment]) -> list[list[Experiment]]:
    """The experiments in runs of one :attr:`~Experiment.group` (``""``: each alone)."""
    out: list[list[Experiment]] = []
    for exp in selected:
        if exp.group and out and out[-1][0].group == exp.group and exp.split is None and out[-1][0].split is None:
            out[-1].append(exp)
        else:
            out.append([exp])
    return out


# -- what a worker runs ------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Run:
    """Experiments that run one after another in one task (one group)."""

    experiments: tuple[tuple[Experiment, Path, dict], ...]  #: (experiment, folder, options)
    fmus: ExperimentFmus  #: resolved: serves the declared FMUs only

    def label(self) -> str:
        return " + ".join(exp.name for exp, _, _ in self.experiments)


@dataclass(frozen=True)
class _Part:
    """One task of a split experiment."""

    name: str
    fn: Callable[[Any, Task], TaskResult]
    shared_key: str  #: the split's shared data in :class:`_Shared`
    task: Task
    label_text: str

    def label(self) -> str:
        return f"{self.name}: {self.label_text}"


@dataclass(frozen=True)
class _Shared:
    jobs: tuple[_Run | _Part, ...]
    split_data: dict[str, object] = field(default_factory=dict)  #: split name -> its shared data


def _run_experiments(run: _Run) -> list[tuple[str, ExperimentResult, float]]:
    out = []
    for exp, folder, options in run.experiments:
        t = time.perf_counter()
        result = exp.run(folder, fmus=run.fmus, progress=False, **options)
        out.append((exp.name, result, time.perf_counter() - t))
    return out


def reproduce_task(shared: _Shared, task: Task) -> TaskResult:
    """The task function of a parallel ``lpvest reproduce`` (a Dask worker runs
    it): ``task.index`` names a job of ``shared``, a group of experiments or one
    task of a split experiment."""
    job = shared.jobs[task.index]
    if isinstance(job, _Part):
        return job.fn(shared.split_data[job.shared_key], job.task)
    return TaskResult(value=_run_experiments(job))


# -- resuming --------------------------------------------------------------------------------------------
#: Next to an experiment's results.json: what a rerun needs to keep it instead of running it again.
RESUME_RECORD = ".resume.pickle"


_TAG = 32  #: bytes of the HMAC-SHA256 tag in front of a resume record


def _resume_secret() -> bytes | None:
    """The key that signs resume records: 32 random bytes in
    ``$XDG_CACHE_HOME/lpvest/resume.key`` (``~/.cache/...``), made on first use,
    readable by its owner only. A record is unpickled only when its tag is this
    key's: a record copied from someone else's output folder (a pickle runs code
    when loaded) or damaged is never loaded, and the experiment runs again.
    None when no such file can be made or read."""
    path = user_cache_dir("resume.key")
    try:
        if not path.is_file():
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".resume.key.")  # mode 0600
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(secrets.token_bytes(_TAG))
                os.link(tmp, path)  # whole or not at all; the first of two processes wins
            except FileExistsError:
                pass
            finally:
                os.unlink(tmp)
        secret = path.read_bytes()
        return secret if len(secret) == _TAG else None
    except OSError:
        return None


@functools.cache
def _source_digest() -> str:
    """SHA-256 of the lpvest package's Python sources (what an experiment's numbers are computed by)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def _resume_key(exp: Experiment, options: dict, cache: ExperimentFmus) -> str:
    """What an experiment's result depends on: the lpvest sources, its name and
    options, and what each of its FMUs is made of (:func:`lpvest.fmi.fingerprint`)."""
    from ..fmi._cache import fingerprint

    what = {"lpvest": _source_digest(), "experiment": exp.name, "options": options, "backend": cache.backend,
            "fmus": {ident: fingerprint(cache.plan(ident), cache.backend) for ident in exp.fmus}}
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=repr).encode()).hexdigest()


def _write_resume_record(run: ExperimentRun, key: str) -> None:
    """Whole or not at all, after ``results.json``: an experiment without one is run again."""
    path = run.folder / RESUME_RECORD
    partial = path.with_name(path.name + ".part")
    secret = _resume_secret()
    if secret is None:  # no private place for the key: nothing is kept, a rerun runs it again
        return
    digest = hashlib.sha256(run.results_path.read_bytes()).hexdigest()
    data = pickle.dumps({"key": key, "results_sha256": digest, "run": run})
    partial.write_bytes(hmac.new(secret, data, "sha256").digest() + data)
    partial.replace(path)


def _moved_to(run: ExperimentRun, folder: Path) -> ExperimentRun | None:
    """``run`` with its paths in ``folder``. The record names the folder as the
    command that wrote it had it (``--out out``, relative to where it ran); a
    rerun may name the same folder another way (absolute), or the folder may
    have been moved since: what the run wrote is looked for where it is now.
    None if the run names a file outside its folder (nothing to look for)."""
    try:
        results = folder / run.results_path.relative_to(run.folder)
        figures = tuple(folder / f.relative_to(run.folder) for f in run.result.figures)
    except ValueError:
        return None
    if results != folder / "results.json":
        return None
    return replace(run, folder=folder, results_path=results, result=replace(run.result, figures=figures))


def _finished_earlier(exp: Experiment, folder: Path, key: str) -> ExperimentRun | None:
    """The run an earlier command recorded in ``folder``, if it is the same
    computation (``key``) and its ``results.json`` and figures are the ones it
    wrote; else None (the experiment runs again and rewrites them)."""
    try:
        secret = _resume_secret()
        signed = (folder / RESUME_RECORD).read_bytes()
        tag, data = signed[:_TAG], signed[_TAG:]
        if secret is None or not hmac.compare_digest(tag, hmac.new(secret, data, "sha256").digest()):
            return None  # not written by this user's lpvest (or damaged): never unpickled
        record = pickle.loads(data)
        run = record["run"]
        if record["key"] != key or not isinstance(run, ExperimentRun) or run.name != exp.name:
            return None
        run = _moved_to(run, folder)
        if (run is None or hashlib.sha256(run.results_path.read_bytes()).hexdigest() != record["results_sha256"]
                or not all(f.is_file() for f in run.result.figures)):
            return None
        return run
    except (OSError, EOFError, KeyError, TypeError, AttributeError, ImportError, IndexError,
            pickle.UnpicklingError, ValueError):
        return None


# -- the driver ----------------------------------------------------------------------------------------
class _Reporter:
    """Writes and prints each experiment when it is complete; keeps the runs."""

    def __init__(self, out: Path, reduced: bool, say: Callable[[str], None], progress: bool | None = None) -> None:
        self.out, self.reduced, self.say, self.progress = out, reduced, say, progress
        self.runs: dict[str, ExperimentRun] = {}
        self.keys: dict[str, str] = {}  #: experiment name -> its resume key

    def options(self, exp: Experiment) -> dict:
        return dict(exp.reduced) if self.reduced else {}

    def header(self, exp: Experiment) -> str:
        options = self.options(exp)
        return f"== {exp.name}: {exp.title}" + (f" (reduced: {options})" if options else "")

    def done(self, exp: Experiment, result: ExperimentResult, seconds: float, *, header: bool) -> None:
        folder = self.out / exp.name
        if header:
            self.say(self.header(exp))
        self.say(result.table)
        if result.fmu is not None:
            self.say("\n".join(result.fmu.lines()))
        path = write_results(result, folder)
        self.say(f"wrote {path}" + "".join(f"\nwrote {f}" for f in result.figures))
        self.say(f"({seconds:.1f} s)")
        run = ExperimentRun(exp.name, exp.title, result, folder, path, seconds, self.options(exp))
        _write_resume_record(run, self.keys[exp.name])
        self.runs[exp.name] = run
        hold("experiment-written")  # the interruption tests' hook; nothing otherwise


def _in_process(groups: list[list[Experiment]], cache: ExperimentFmus, rep: _Reporter) -> None:
    for group in groups:
        for exp in group:
            rep.say(rep.header(exp))
            folder = rep.out / exp.name
            t = time.perf_counter()
            with one_blas_thread():
                result = exp.run(folder, fmus=cache, progress=rep.progress, **rep.options(exp))
            rep.done(exp, result, time.perf_counter() - t, header=False)


def build_task(cache: ExperimentFmus, task: Task) -> TaskResult:
    """Build one FMU of ``cache`` (``task.point["fmu"]``) on a worker; this
    process records it (:meth:`~lpvest.fmi.FmuCache.record`)."""
    return TaskResult(value=cache.build_file(task.point["fmu"]))


def _build_on_workers(engine: Engine, cache: ExperimentFmus, needed: list[str], say: Callable[[str], None]) -> None:
    """Build the missing or stale FMUs of ``needed`` side by side, recorded here one by one."""
    stale = cache.stale(needed)
    if not stale:
        return
    say(f"building {len(stale)} FMU(s) into {cache.directory} on {engine.describe()}")
    tell = cache.progress or (lambda _text: None)

    def on_outcome(outcome: Outcome) -> None:
        identifier = stale[outcome.index]
        if outcome.result is None:
            raise SweepError(f"building {identifier} failed: {outcome.error}")
        cache.record(identifier, outcome.result.value)
        tell(f"built {identifier} ({outcome.seconds:.1f} s)")

    engine.map(build_task, cache, [Task(i, {"fmu": ident}) for i, ident in enumerate(stale)], on_outcome=on_outcome)


def _on_workers(groups: list[list[Experiment]], cache: ExperimentFmus, rep: _Reporter, workers: int) -> None:
    from ..parallel._engine import Engine

    with Engine(workers=workers) as engine:
        _run_on(engine, groups, cache, rep)


def _run_on(engine: Engine, groups: list[list[Experiment]], cache: ExperimentFmus, rep: _Reporter) -> None:
    needed = list(dict.fromkeys(name for group in groups for exp in group for name in exp.fmus))
    _build_on_workers(engine, cache, needed, rep.say)
    view = cache.resolved(needed)  # every one checked or built: the workers only read them
    jobs: list[_Run | _Part] = []
    split_data: dict[str, object] = {}
    splits: dict[str, tuple[Experiment, Split]] = {}
    for group in groups:
        if group[0].split is None:
            jobs.append(_Run(tuple((exp, rep.out / exp.name, rep.options(exp)) for exp in group), view))
    for group in groups:  # the many small tasks last: they even out the workers' loads at the end
        exp = group[0]
        if exp.split is not None:
            split = exp.split(rep.out / exp.name, fmus=view, progress=False, **rep.options(exp))
            splits[exp.name] = (exp, split)
            split_data[exp.name] = split.shared
            jobs += [_Part(exp.name, split.fn, exp.name, t, label)
                     for t, label in zip(split.tasks, split.labels, strict=True)]
    by_name = {exp.name: exp for group in groups for exp in group}
    parts: dict[str, dict[int, Outcome]] = {name: {} for name in splits}
    finished = [0]

    def on_outcome(outcome: Outcome) -> None:
        job = jobs[outcome.index]
        finished[0] += 1
        rep.say(f"[{finished[0]:>{len(str(len(jobs)))}}/{len(jobs)}] {job.label()} ({outcome.seconds:.1f} s)")
        if outcome.result is None:
            raise SweepError(f"{job.label()} failed: {outcome.error}")
        if isinstance(job, _Run):
            for name, result, seconds in outcome.result.value:
                rep.done(by_name[name], result, seconds, header=True)
            return
        done = parts[job.name]
        done[job.task.index] = outcome
        exp, split = splits[job.name]
        if len(done) == len(split.tasks):
            t = time.perf_counter()
            with one_blas_thread():
                result = split.finish([done[task.index].result for task in split.tasks])  # type: ignore[misc]  # all done: none None
            seconds = sum(o.seconds for o in done.values()) + time.perf_counter() - t
            rep.done(exp, result, seconds, header=True)

    rep.say(f"{len(by_name)} experiment(s) as {len(jobs)} task(s) on {engine.describe()}")
    engine.map(reproduce_task, _Shared(tuple(jobs), split_data), [Task(i) for i in range(len(jobs))],
               on_outcome=on_outcome)


def reproduce(
    names: Sequence[str],
    out: str | Path,
    *,
    fmus: ExperimentFmus | str | Path | None = None,
    reduced: bool = False,
    echo: Callable[[str], None] | None = None,
    backend: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
) -> list[ExperimentRun]:
    """Run the experiments ``names`` into ``out/<name>/``.

    Parameters
    ----------
    names : sequence of str
        Registered experiment names (:func:`~lpvest.experiments.registry`).
    out : str or Path
        The output folder; each experiment writes into ``out/<name>/``.
    fmus : ExperimentFmus, str, Path or None, default None
        The FMU cache (or its folder; ``None``: the default cache).
    reduced : bool, default False
        Use each experiment's quicker configuration (:attr:`Experiment.reduced`).
    echo : callable, optional
        Receives the printable output: tables, FMU agreement, files written,
        and (side by side) one line per finished task.
    backend : str or None, default None
        The FMUs' backend (``"pythonfmu"`` or ``"native"``,
        :data:`lpvest.fmi._build.BACKENDS`; default: the given cache's, else
        ``"pythonfmu"``).
    workers : int or None, default None
        Dask worker processes (default: one per core, :func:`default_workers`);
        ``0``: every experiment in this process, one after another. The
        numbers are the same either way.
    progress : bool or None, default None
        The progress bars of experiments run in this process
        (:func:`~lpvest.experiments.show_progress`; None: on a terminal);
        tasks on workers never show any.

    Returns
    -------
    list of ExperimentRun
        One per experiment, in the order of ``names``.

    Raises
    ------
    LpvestError
        An unknown experiment name.
    ArgumentError
        ``workers`` is not an integer >= 0.
    SweepError
        An experiment failed on a worker (the message names it), or Dask
        (the ``sweep`` extra) is missing.
    ReproduceInterrupted
        SIGINT or SIGTERM (within :func:`lpvest.core.handling_signals`, as
        on the command line; a plain ``KeyboardInterrupt`` too): it names the
        experiments that finished.
    """
    from . import registry  # looked up at call time

    n_workers = _check_workers(workers)
    experiments = registry()
    unknown = [n for n in names if n not in experiments]
    if unknown:
        raise LpvestError(f"no experiment {abbreviate(unknown[0], 30)} (known: {', '.join(experiments) or 'none'})")
    cache = as_experiment_fmus(fmus, backend=backend)
    rep = _Reporter(Path(out), reduced, echo or (lambda _text: None), progress)
    groups: list[list[Experiment]] = []
    try:
        for group in _groups([experiments[n] for n in names]):
            todo = []
            for exp in group:
                rep.keys[exp.name] = _resume_key(exp, rep.options(exp), cache)
                run = _finished_earlier(exp, rep.out / exp.name, rep.keys[exp.name])
                if run is None:
                    todo.append(exp)
                else:
                    rep.runs[run.name] = run
                    rep.say(f"{run.name}: finished earlier, kept ({run.results_path})")
            if todo:  # a group's members not kept run together, as they share a computation
                groups.append(todo)
        parallel = n_workers > 0 and (len(groups) > 1 or any(g[0].split is not None for g in groups))
        if parallel:
            _on_workers(groups, cache, rep, n_workers)
        elif groups:
            _in_process(groups, cache, rep)
    except KeyboardInterrupt as exc:
        finished = [rep.runs[n] for n in names if n in rep.runs]
        raise ReproduceInterrupted(finished, names, Path(out), Path(cache.directory),
                                   signum=exit_status(exc) - 128) from None
    return [rep.runs[n] for n in names]


def reproduce_all(
    out: str | Path,
    *,
    fmus: ExperimentFmus | str | Path | None = None,
    reduced: bool = False,
    echo: Callable[[str], None] | None = None,
    backend: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
) -> list[ExperimentRun]:
    """Every registered experiment (:func:`reproduce`), then ``out/report.md``
    (:func:`lpvest.experiments._report.write_report`).

    Parameters
    ----------
    out : str or Path
        The output folder; each experiment writes into ``out/<name>/``.
    fmus : ExperimentFmus, str, Path or None, default None
        The FMU cache (or its folder); None: ``out/fmu-cache``
        (``out/fmu-cache-native`` for ``backend="native"``).
    reduced : bool, default False
        Use each experiment's quicker configuration (:attr:`Experiment.reduced`).
    echo : callable, optional
        Receives the printable output, as in :func:`reproduce`, then the
        report's path.
    backend : str or None, default None
        The FMUs' backend (``"pythonfmu"`` or ``"native"``; default: the
        given cache's, else ``"pythonfmu"``).
    workers : int or None, default None
        Dask worker processes, as in :func:`reproduce`.
    progress : bool or None, default None
        Progress bars, as in :func:`reproduce`.

    Returns
    -------
    list of ExperimentRun
        One per registered experiment, in the registry's order.

    Raises
    ------
    ArgumentError
        ``backend`` is unknown or not the given cache's, or ``workers`` is
        not an integer >= 0.
    SweepError
        An experiment failed on a worker, or Dask (the ``sweep`` extra) is
        missing.
    ReproduceInterrupted
        SIGINT or SIGTERM, as in :func:`reproduce`; ``report.md`` is not written.
    """
    from . import registry
    from ._report import write_report

    out = Path(out)
    default = out / ("fmu-cache" if backend in (None, "pythonfmu") else f"fmu-cache-{backend}")
    cache = as_experiment_fmus(default if fmus is None else fmus, backend=backend)
    t = time.perf_counter()
    try:
        runs = reproduce(list(registry()), out, fmus=cache, reduced=reduced, echo=echo, backend=backend,
                         workers=workers, progress=progress)
    except ReproduceInterrupted as exc:
        raise exc.with_report() from None
    path = write_report(runs, out, fmus=cache, seconds=time.perf_counter() - t, reduced=reduced)
    if echo is not None:
        echo(f"wrote {path}")
    return runs
