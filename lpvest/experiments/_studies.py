"""The experiments' studies: their Monte Carlo parts as sweeps.

A study is the part of a paper experiment that a sweep file can run on its
own (``experiment = NAME`` in :mod:`lpvest.sweep`): the same task functions
the experiment runs through :func:`~lpvest.parallel.map_tasks`, over axes and
seeds the sweep file may change, with the metrics and signals each task
returns. A paper module declares its study next to the experiment it belongs
to (:attr:`~lpvest.experiments.Experiment.study`), so the studies are the
experiments' registry (:func:`~lpvest.experiments.registry`) read once more:
:func:`experiment_studies`.

=========================  ==========================================  ======================================
experiment                 axes (defaults)                             per task
=========================  ==========================================  ======================================
``cox-toth-truncation``    ``filter`` (all of ``PREDICTION_FILTERS``)  ``runs`` Monte Carlo trajectories
                                                                       (options ``steps``, ``runs``,
                                                                       ``burn_in``, ``seed``)
``peixoto-example2``       ``rho`` (1 .. 21), ``epsilon`` (optional:   the best-epsilon search, or one design
                           else the best epsilon)                      at ``epsilon``
``sridhar-noisy``          seeds (20)                                  one 30 dB noise realization, two fits
=========================  ==========================================  ======================================

A study's ``prepare`` reads a sweep's spec through :class:`StudySpec` (what
:class:`lpvest.sweep.SweepSpec` offers), so this floor needs nothing of the
sweep floor above it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from ..core._errors import InternalError, ModelFileError
from ..parallel._prepared import Prepared
from ..parallel._tasks import Task, TaskResult
from . import registry

if TYPE_CHECKING:
    from ._fmus import ExperimentFmus

S = TypeVar("S")  #: the type of the data every task of a study shares

__all__ = ["ExperimentStudy", "StudyAxis", "StudySpec", "SelectedTask", "select_task", "experiment_studies",
           "study"]


class StudyAxis(Protocol):
    """A swept axis as a study reads it: its name and values."""

    @property
    def name(self) -> str:
        """The axis name (``"filter"``, ``"rho"``)."""

    @property
    def values(self) -> tuple[Any, ...]:
        """The swept values."""


class StudySpec(Protocol):
    """What a study's ``prepare`` reads of a sweep's spec
    (:class:`lpvest.sweep.SweepSpec` is one)."""

    @property
    def axes(self) -> Sequence[StudyAxis]:
        """Every swept axis."""

    @property
    def keep(self) -> tuple[str, ...]:
        """The signals each task keeps."""

    @property
    def metric_names(self) -> tuple[str, ...]:
        """The metrics kept (empty: all of the study's)."""

    @property
    def options(self) -> Mapping[str, Any]:
        """The study's options given in the sweep file (the defaults are not filled in)."""

    def error(self, where: str, message: str) -> Exception:
        """The error to raise for a mistake in the sweep file's field ``where``.

        Parameters
        ----------
        where : str
            The field (``"options.runs"``).
        message : str
            What is wrong with it.

        Returns
        -------
        Exception
            The error (not raised).
        """


@dataclass(frozen=True)
class ExperimentStudy:
    """The Monte Carlo (or design sweep) part of a paper experiment.

    Parameters
    ----------
    name : str
        The experiment's name (``experiment = NAME`` in a sweep file).
    title : str
        One line on what the study computes (``lpvest sweep --list``).
    prepare : callable
        ``prepare(spec, fmus) -> Prepared``: ``spec`` a :class:`StudySpec`
        (its defaults filled in), ``fmus`` the experiments' FMU cache (an
        :class:`~lpvest.experiments.ExperimentFmus`, its folder, or ``None``).
    axes : mapping of str to (tuple or None)
        Axis -> default values (``None``: optional, no default).
    seeds : int
        Default number of seeds (0: no seed axis).
    options : mapping
        Option -> default value.
    metrics : tuple of str
        Every metric a task returns, in column order.
    signals : tuple of str
        The signals a task can keep.
    """

    name: str
    title: str
    prepare: Callable[[StudySpec, ExperimentFmus], Prepared]
    axes: Mapping[str, tuple[Any, ...] | None]
    seeds: int
    options: Mapping[str, Any]
    metrics: tuple[str, ...]
    signals: tuple[str, ...]

    @property
    def seeded(self) -> bool:
        """Whether the study has a seed axis."""
        return self.seeds > 0


@dataclass(frozen=True)
class SelectedTask:
    """A task function whose metrics and signals are cut to a selection (picklable).

    Parameters
    ----------
    fn : callable
        Module-level task function ``fn(shared, Task) -> TaskResult``.
    metrics : tuple of str
        The metrics kept, in column order.
    signals : tuple of str
        The signals kept.
    """

    fn: Callable[[Any, Task], TaskResult]
    metrics: tuple[str, ...]
    signals: tuple[str, ...]

    def __call__(self, shared: Any, task: Task) -> TaskResult:
        r = self.fn(shared, task)
        return TaskResult({k: r.metrics[k] for k in self.metrics}, {k: r.signals[k] for k in self.signals})


def select_task(fn: Callable[[S, Task], TaskResult], spec: StudySpec, metrics: tuple[str, ...]) -> SelectedTask:
    """``fn`` returning the metrics and signals that ``spec`` selects.

    Parameters
    ----------
    fn : callable
        Module-level task function ``fn(shared, Task) -> TaskResult``.
    spec : StudySpec
        The sweep's spec: its :attr:`~StudySpec.metric_names` (empty: every
        one of ``metrics``) and its :attr:`~StudySpec.keep`.
    metrics : tuple of str
        Every metric of the study, in column order.

    Returns
    -------
    SelectedTask
        The task function to run.
    """
    return SelectedTask(fn, spec.metric_names or metrics, spec.keep)


@functools.cache
def experiment_studies() -> dict[str, ExperimentStudy]:
    """The studies of the registered experiments (``experiment = NAME`` in a sweep file).

    Returns
    -------
    dict of str to ExperimentStudy
        By name, in the order of :func:`~lpvest.experiments.registry`.

    Raises
    ------
    InternalError
        If an experiment holds a study of another name.
    """
    out = {}
    for name, exp in registry().items():
        if exp.study is not None:
            if exp.study.name != name:
                raise InternalError(f"experiment {name!r} holds the study {exp.study.name!r}")
            out[name] = exp.study
    return out


def study(name: str, *, where: str = "experiment") -> ExperimentStudy:
    """The study of the experiment ``name``.

    Parameters
    ----------
    name : str
        The experiment's name.
    where : str, default "experiment"
        What the error names (the sweep file and its field).

    Returns
    -------
    ExperimentStudy
        Its study.

    Raises
    ------
    ModelFileError
        If no registered experiment of that name has a study.
    """
    studies = experiment_studies()
    if name not in studies:
        raise ModelFileError(f"{where}: no experiment {name!r} to sweep (experiments: {', '.join(studies)})")
    return studies[name]
