"""Experiments: importable, headless reproductions of the papers' examples.

The paper modules (``_cox_toth.py``, ``_peixoto.py``, ``_sridhar.py``) each
define ``EXPERIMENTS``, a sequence of :class:`Experiment`; :func:`registry`
collects them, and ``lpvest reproduce
NAME|all`` runs them. An experiment's ``run(out_dir, *, fmus=None,
progress=None, ...)`` returns an :class:`ExperimentResult` (a printable
table, JSON-able numbers, the figures it wrote, the paper-versus-ours rows of
the report, and the record of what ran through FMUs) and writes nothing when
``out_dir`` is ``None``. ``fmus`` is an
:class:`~lpvest.experiments.ExperimentFmus` (the FMU cache), a cache
folder, or ``None`` for the default cache; ``progress`` shows progress bars
(default: :func:`show_progress`).

What :mod:`~lpvest.experiments` needs to run experiments side by
side on Dask workers is declared with each: the FMUs it runs
(:attr:`Experiment.fmus`, built before any worker starts), the experiments
that share a computation and so run as one task (:attr:`Experiment.group`),
and, for an experiment made of many independent computations, its
:class:`Split` (:attr:`Experiment.split`): tasks that run anywhere, then a
last step on their results. An experiment whose Monte Carlo part a sweep file
can run on its own (``experiment = NAME`` in :mod:`lpvest.sweep`) holds it as
its :class:`ExperimentStudy` (:attr:`Experiment.study`);
:func:`experiment_studies` collects them.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core._errors import InternalError

if TYPE_CHECKING:
    from ..parallel._tasks import Task, TaskResult
    from ._fmus import FmuRun
    from ._studies import ExperimentStudy

__all__ = [
    "Experiment",
    "ExperimentResult",
    "Split",
    "registry",
    "show_progress",
    "write_results",
    "CoSimSpec",
    "ExperimentFmus",
    "ExperimentRun",
    "ReproduceInterrupted",
    "reproduce",
    "reproduce_all",
    "ExperimentStudy",
    "experiment_studies",
]


def show_progress(progress: bool | None, out_dir: Path | None) -> bool:
    """Whether an experiment shows progress bars: ``progress`` when given, else
    when it writes its files (a command-line run) and stderr is a terminal
    (never a stream of carriage returns into a log file).

    Parameters
    ----------
    progress : bool or None
        The caller's choice; ``None``: decide as above.
    out_dir : Path or None
        The experiment's output folder (``None``: a headless run).

    Returns
    -------
    bool
        Show progress bars.
    """
    if progress is not None:
        return bool(progress)
    return out_dir is not None and sys.stderr.isatty()


@dataclass(frozen=True)
class ExperimentResult:
    """What an experiment produced.

    Parameters
    ----------
    name : str
        Name of the experiment (:attr:`Experiment.name`).
    table : str
        Text table, paper next to ours.
    results : mapping
        JSON-able numbers (written to ``results.json`` by :func:`write_results`).
    figures : tuple of Path, default ()
        The figure files the experiment wrote.
    paper : tuple of (str, str, str), default ()
        Rows ``(quantity, paper, ours)`` of the report's paper-versus-ours table.
    fmu : FmuRun or None, default None
        What ran through FMUs and how it agrees with the library (``None``: no
        FMU part).
    """

    name: str
    table: str
    results: Mapping[str, object]
    figures: tuple[Path, ...] = field(default_factory=tuple)
    paper: tuple[tuple[str, str, str], ...] = field(default_factory=tuple)
    fmu: FmuRun | None = None


@dataclass(frozen=True)
class Split:
    """An experiment as independent tasks and a last step on their results:
    ``finish([fn(shared, task) for task in tasks])`` is the experiment's
    result, whichever process ran each task (:func:`~lpvest.parallel.map_tasks`
    gives the same numbers serially and on Dask workers).

    Parameters
    ----------
    fn : callable
        Module-level task function ``fn(shared, Task) -> TaskResult``.
    shared : object
        What every task reads (picklable).
    tasks : tuple of Task
        The tasks, in the order ``finish`` takes their results.
    finish : callable
        ``finish(results) -> ExperimentResult``, ``results`` the
        :class:`~lpvest.parallel.TaskResult` of each task in order; it
        writes the experiment's files.
    desc : str
        What the tasks are, for a progress bar (``"Example 2: rho sweep"``).
    labels : tuple of str
        What each task is, for a progress line (``"rho = 3"``).
    """

    fn: Callable[[Any, Task], TaskResult]
    shared: Any
    tasks: tuple[Task, ...]
    finish: Callable[[Sequence[TaskResult]], ExperimentResult]
    desc: str
    labels: tuple[str, ...]


@dataclass(frozen=True)
class Experiment:
    """A named, runnable experiment.

    ``run(out_dir, *, fmus=None, progress=None, **options)``; ``reduced`` holds
    the options of a quicker configuration (``lpvest reproduce all --quick``,
    the tests).

    Parameters
    ----------
    name : str
        Name for ``lpvest reproduce NAME``, unique over :func:`registry`.
    title : str
        One-line title, printed when the experiment runs.
    run : callable
        ``run(out_dir, *, fmus=None, progress=None, **options) -> ExperimentResult``.
    reduced : mapping, default {}
        Keyword options of the quicker configuration, passed to ``run``.
    fmus : tuple of str, default ()
        Identifiers of the FMUs it runs (:data:`~lpvest.experiments._fmus.CATALOG`):
        ``lpvest reproduce`` builds them before handing the experiment to a
        worker process, which may use no other.
    group : str, default ""
        Experiments of one group (registered one after another) share a
        computation made once per process, so they run as one task, in order;
        ``""``: none shared.
    split : callable or None, default None
        ``split(out_dir, *, fmus=None, progress=None, **options) -> Split``:
        the same experiment as independent tasks and a last step, which
        ``lpvest reproduce`` spreads over its workers; ``run`` is then
        ``split`` with the tasks run in order.
    study : ExperimentStudy or None, default None
        Its Monte Carlo (or design sweep) part as a study a sweep file can run
        (``experiment = NAME`` in :mod:`lpvest.sweep`), of the same name;
        ``None``: none.
    """

    name: str
    title: str
    run: Callable[..., ExperimentResult]
    reduced: Mapping[str, object] = field(default_factory=dict)
    fmus: tuple[str, ...] = ()
    group: str = ""
    split: Callable[..., Split] | None = None
    study: ExperimentStudy | None = None


def registry() -> dict[str, Experiment]:
    """Every experiment of every module in :mod:`lpvest.experiments`, by name.

    The paper modules are imported (on the first call: they import scipy and
    the FMU machinery) and their ``EXPERIMENTS`` collected, in module-name order.

    Returns
    -------
    dict of str to Experiment
        The experiments, keyed by :attr:`Experiment.name`.

    Raises
    ------
    InternalError
        If two experiments have the same name.
    """
    out: dict[str, Experiment] = {}
    from . import _cox_toth, _peixoto, _sridhar  # the modules that define experiments

    for module in (_cox_toth, _peixoto, _sridhar):
        for exp in module.EXPERIMENTS:
            if exp.name in out:
                raise InternalError(f"experiment name {exp.name!r} is defined twice")
            out[exp.name] = exp
    return out


def _jsonable(value: object) -> object:
    import numpy as np

    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def write_results(result: ExperimentResult, out_dir: Path) -> Path:
    """Write ``results.json`` for ``result`` into ``out_dir``.

    Parameters
    ----------
    result : ExperimentResult
        Its :attr:`~ExperimentResult.results`, plus ``fmu_cosimulation`` (the
        :attr:`~ExperimentResult.fmu` record) when it has an FMU part, are
        written; numpy arrays and scalars and paths are converted to JSON.
    out_dir : Path
        Folder to write into; created (with parents) if missing.

    Returns
    -------
    Path
        The file written, ``out_dir / "results.json"``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "results.json"
    data = dict(result.results)
    if result.fmu is not None:
        data["fmu_cosimulation"] = result.fmu.to_json()
    partial = path.with_name(".results.json.part")  # whole or not at all: an interruption leaves no half file
    partial.write_text(json.dumps(_jsonable(data), indent=2) + "\n", encoding="utf-8")
    partial.replace(path)
    return path

# the FMU cache and the runner, defined on top of the classes above
# isort: split
from ._fmus import (  # noqa: E402 - defined on top of the classes above
    CoSimSpec as CoSimSpec,
    ExperimentFmus as ExperimentFmus,
)
from ._reproduce import (  # noqa: E402 - defined on top of the classes above
    ExperimentRun as ExperimentRun,
    ReproduceInterrupted as ReproduceInterrupted,
    reproduce as reproduce,
    reproduce_all as reproduce_all,
)
from ._studies import (  # noqa: E402 - defined on top of registry above
    ExperimentStudy as ExperimentStudy,
    experiment_studies as experiment_studies,
)
