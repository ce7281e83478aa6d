"""What a sweep runs: a co-simulation file, or a registered experiment.

:func:`prepare` turns a :class:`~lpvest.sweep.SweepSpec` into a
:class:`Prepared` sweep: the task function, the data every task reads, the
metric names, the shapes of the kept signals, and the identity of what the
results depend on (its SHA-256 names the sweep in its output folder).

**A co-simulation file.** Everything is checked in this process before a
task runs (swept and seed parameters are settable variables of the right
type, kept signals and metric variables are outputs, every swept value is
accepted by the master), so a typo is one error, not a thousand failed tasks.
The FMUs are read once and travel with the shared data as bytes (a worker
writes each to its local folder once) or, with ``ship_fmus=False``, are read
by every worker from their paths (a shared file system). A worker builds the
:class:`~lpvest.cosim.CoSimulation` once and runs task after task on the same
instances, each after :meth:`~lpvest.cosim.CoSimulation.reset` with the
task's parameters and seeds (``fmi2Reset``: the state after instantiation);
after a failure it starts from fresh instances.

**Experiments** (:func:`experiment_studies`): the Monte Carlo parts of the
paper reproductions, the same task functions the experiments run
(:func:`~lpvest.parallel.map_tasks`).

=========================  ==========================================  ======================================
experiment                 axes (defaults)                             per task
=========================  ==========================================  ======================================
``cox-toth-truncation``    ``filter`` (all of ``PREDICTION_FILTERS``)  ``runs`` Monte Carlo trajectories
                                                                       (options ``steps``, ``runs``,
                                                                       ``burn_in``, ``seed``)
``sridhar-noisy``          seeds (20)                                  one 30 dB noise realization, two fits
``peixoto-example2``       ``rho`` (1 .. 21), ``epsilon`` (optional:   the best-epsilon search, or one design
                           else the best epsilon)                      at ``epsilon``
=========================  ==========================================  ======================================
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core._errors import ModelFileError
from ..parallel._tasks import Task, TaskResult, digest
from ._metrics import Metric, check as check_metric, compute as compute_metric, expand, select

if TYPE_CHECKING:
    from ._sweepfile import SweepSpec

__all__ = ["Prepared", "ExperimentStudy", "experiment_studies", "study", "prepare",
           "CosimPayload", "run_cosim_task", "release_simulation"]


@dataclass(frozen=True)
class Prepared:
    """A sweep ready to run: what each task calls and what it returns."""

    fn: Callable[[Any, Task], TaskResult]  #: module-level task function
    shared: Any  #: what every task reads
    metrics: tuple[str, ...]  #: metric names, in column order
    #: kept signal -> (shape per task, element labels)
    signals: Mapping[str, tuple[tuple[int, ...], tuple[str, ...]]] = field(default_factory=dict)
    identity: Mapping[str, Any] = field(default_factory=dict)  #: what the results depend on besides the spec
    time: np.ndarray | None = None  #: the first axis of every signal (co-simulation time), if any
    description: str = ""


# ---------------------------------------------------------------------------
# co-simulation files
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CosimPayload:
    """What a worker needs to run tasks of a co-simulation sweep."""

    digest: str  #: names the set-up (a worker keeps one simulation per digest)
    #: name, FMU sha256, parameters, feedthrough of each component
    components: tuple[tuple[str, str, Mapping[str, Any], bool | None], ...]
    fmu_bytes: Mapping[str, bytes]  #: sha256 -> the FMU (shipped), or empty
    fmu_paths: Mapping[str, str]  #: sha256 -> a path every worker can read (not shipped)
    connections: tuple[str, ...]
    step_size: float
    start_time: float
    n_steps: int
    record: tuple[str, ...]
    metrics: tuple[Metric, ...]
    keep: tuple[str, ...]


_WORKER: dict[str, Any] = {}


def _fmu_folder() -> Path:
    """A folder of this process for shipped FMUs: the Dask worker's local
    directory (removed with the worker), else a temporary folder."""
    if "folder" not in _WORKER:
        try:
            from distributed import get_worker

            base = Path(get_worker().local_directory)
        except (ImportError, ValueError):
            base = Path(tempfile.mkdtemp(prefix="lpvest-sweep-"))
        _WORKER["folder"] = base / "lpvest-fmus"
        _WORKER["folder"].mkdir(parents=True, exist_ok=True)
    return _WORKER["folder"]


def _fmu_path(payload: CosimPayload, sha: str) -> Path:
    if sha in payload.fmu_paths:
        return Path(payload.fmu_paths[sha])
    path = _fmu_folder() / f"{sha}.fmu"
    if not path.is_file():
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(payload.fmu_bytes[sha])
        tmp.replace(path)
    return path


def _simulation(payload: CosimPayload) -> Any:
    """This process's simulation of ``payload`` (built on first use)."""
    from ..cosim import Component, CoSimulation

    if _WORKER.get("digest") == payload.digest and _WORKER.get("sim") is not None:
        return _WORKER["sim"]
    release_simulation()
    comps = [Component(name, _fmu_path(payload, sha), dict(params), feed)
             for name, sha, params, feed in payload.components]
    sim = CoSimulation(comps, payload.connections, step_size=payload.step_size, start_time=payload.start_time,
                       record=payload.record)
    _WORKER["digest"], _WORKER["sim"] = payload.digest, sim
    return sim


def release_simulation() -> None:
    """Close this process's cached simulation (the next task loads the FMUs anew)."""
    sim = _WORKER.pop("sim", None)
    _WORKER.pop("digest", None)
    if sim is not None:
        sim.close()


def _task_parameters(task: Task) -> dict[str, dict[str, Any]]:
    params: dict[str, dict[str, Any]] = {}
    for name, value in (*task.point.items(), *task.seed_values.items()):
        comp, _, var = name.partition(".")
        params.setdefault(comp, {})[var] = list(value) if isinstance(value, tuple) else value
    return params


def run_cosim_task(payload: CosimPayload, task: Task) -> TaskResult:
    """One co-simulation: the task's parameters and seeds as start values,
    ``n_steps`` steps, the metrics and the kept signals."""
    sim = _simulation(payload)
    try:
        sim.reset(_task_parameters(task))
        data = sim.run(payload.n_steps, on_discard="error")  # a task that stops early failed
    except BaseException:
        release_simulation()  # the next task starts from fresh instances
        raise
    metrics = {m.name: compute_metric(m, data) for m in payload.metrics}
    return TaskResult(metrics, {name: select(data, name) for name in payload.keep})


def _model_variables(path: Path) -> dict[str, tuple[str, str]]:
    """name -> (causality, type) of every variable of an FMU."""
    from fmpy import read_model_description

    md = read_model_description(str(path))
    return {v.name: (v.causality, v.type) for v in md.modelVariables}


def _file_sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _prepare_cosim(spec: SweepSpec, *, ship_fmus: bool) -> Prepared:
    from ..cosim import CoSimulationError

    cosim = spec.cosim
    assert cosim is not None
    comps = {c.name: c for c in cosim.components}
    variables = {name: _model_variables(Path(c.fmu)) for name, c in comps.items()}

    def resolve(name: str, where: str, *, settable: bool) -> list[str]:
        comp, _, var = name.partition(".")
        if comp not in comps:
            raise spec.error(where, f"no component {comp!r} in {cosim.path.name} (components: {', '.join(comps)})")
        names = expand(var, variables[comp])
        if not names:
            raise spec.error(where, f"{comp} ({Path(comps[comp].fmu).name}) has no variable {var!r}")
        for n in names:
            causality, typ = variables[comp][n]
            if settable and causality not in ("parameter", "input"):
                raise spec.error(where, f"{comp}.{n} is an {causality}; it cannot be set")
            if not settable and typ == "String":
                raise spec.error(where, f"{comp}.{n} is a String; only numbers can be recorded")
        return names

    for a in spec.axes:
        where = f"parameters.{a.name}" if a in spec.grid else f"zip.{a.name}"
        resolve(a.name, where, settable=True)
    if spec.seeds is not None:
        for i, name in enumerate(spec.seeds.parameters):
            where = f"seeds.parameters[{i + 1}]"
            (elem,) = resolve(name, where, settable=True)[:1]
            comp = name.partition(".")[0]
            if variables[comp][elem][1] != "Integer" or elem != name.partition(".")[2]:
                raise spec.error(where, f"{name} is not an Integer parameter (a seed is a 32-bit integer)")
    for i, name in enumerate(spec.keep):
        resolve(name, f"keep[{i + 1}]", settable=False)
    for m in spec.metrics:
        for role, name in m.variables.items():
            resolve(name, f"metrics.{m.name}.{role}", settable=False)
    record = tuple(dict.fromkeys([*spec.keep, *(n for m in spec.metrics for n in m.names())]))

    # the master checks the set-up, each metric's shapes and every swept value
    check_spec = replace(cosim, record=record, plots=())
    with check_spec.simulation() as sim:
        recorded = sim.recorded
        for m in spec.metrics:
            problem = check_metric(m, [r for r in recorded])
            if problem:
                raise spec.error(f"metrics.{m.name}", problem)
        for a in spec.axes:
            where = f"parameters.{a.name}" if a in spec.grid else f"zip.{a.name}"
            comp, _, var = a.name.partition(".")
            for j, value in enumerate(a.values):
                try:
                    sim.reset({comp: {var: list(value) if isinstance(value, tuple) else value}})
                except CoSimulationError as exc:
                    msg = str(exc).removeprefix(f"component {comp}: ")
                    raise spec.error(f"{where}[{j + 1}]", msg) from None

    shas = {c.name: _file_sha(Path(c.fmu)) for c in cosim.components}
    files = {shas[c.name]: Path(c.fmu) for c in cosim.components}
    identity = {
        "cosim": {
            "components": [[c.name, shas[c.name], {k: v for k, v in c.parameters.items()}, c.feedthrough]
                           for c in cosim.components],
            "connections": list(cosim.connections),
            "step_size": cosim.step_size,
            "start_time": cosim.start_time,
            "n_steps": cosim.n_steps,
        },
    }
    payload = CosimPayload(
        digest=digest(identity),
        components=tuple((c.name, shas[c.name], dict(c.parameters), c.feedthrough) for c in cosim.components),
        fmu_bytes={sha: p.read_bytes() for sha, p in files.items()} if ship_fmus else {},
        fmu_paths={} if ship_fmus else {sha: str(p.resolve()) for sha, p in files.items()},
        connections=tuple(cosim.connections),
        step_size=cosim.step_size,
        start_time=cosim.start_time,
        n_steps=cosim.n_steps,
        record=record,
        metrics=spec.metrics,
        keep=spec.keep,
    )
    rows = cosim.n_steps + 1
    signals = {}
    for name in spec.keep:
        labels = tuple(expand(name, recorded))
        signals[name] = ((rows, len(labels)), labels)
    time = cosim.start_time + np.arange(rows) * cosim.step_size
    n = len(cosim.components)
    return Prepared(run_cosim_task, payload, tuple(m.name for m in spec.metrics), signals, identity, time,
                    f"{cosim.path.name}: {n} FMUs, {cosim.n_steps} steps of {cosim.step_size:g}")


# ---------------------------------------------------------------------------
# experiments
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ExperimentStudy:
    """The Monte Carlo (or design sweep) part of a paper experiment."""

    name: str
    title: str
    prepare: Callable[[SweepSpec, Any], Prepared]  #: (spec, FMU cache) -> Prepared
    axes: Mapping[str, tuple[Any, ...] | None]  #: axis -> default values (None: optional, no default)
    seeds: int  #: default number of seeds (0: no seed axis)
    options: Mapping[str, Any]  #: option -> default
    metrics: tuple[str, ...]
    signals: tuple[str, ...]

    @property
    def seeded(self) -> bool:
        return self.seeds > 0


def _select_metrics(spec: SweepSpec, all_metrics: tuple[str, ...]) -> tuple[str, ...]:
    return spec.metric_names or all_metrics


def _cox_toth_prepare(spec: SweepSpec, fmus: Any) -> Prepared:
    from .._version import __version__
    from ..experiments._cox_toth import prediction_error_setup, prediction_error_task

    opts = {**STUDIES_OPTIONS["cox-toth-truncation"], **spec.options}
    for key, low in (("steps", 2), ("runs", 1), ("burn_in", 0), ("seed", 0)):
        if opts[key] < low:
            raise spec.error(f"options.{key}", f"expected an integer >= {low}, found {opts[key]!r}")
    if opts["burn_in"] >= opts["steps"]:
        raise spec.error("options.burn_in", f"expected fewer than steps = {opts['steps']}, found {opts['burn_in']}")
    setup = prediction_error_setup(steps=opts["steps"], runs=opts["runs"], burn_in=opts["burn_in"],
                                   seed=opts["seed"])
    for a in spec.axes:
        for j, v in enumerate(a.values):
            if v not in setup.gains:
                raise spec.error(f"parameters.filter[{j + 1}]", f"no filter {v!r} (filters: {', '.join(setup.gains)})")
    steps = opts["steps"]
    signals = {s: ((steps,), ()) for s in spec.keep}
    return Prepared(_experiment_task(prediction_error_task, spec), setup, _select_metrics(spec, _COX_METRICS),
                    signals, {"experiment": "cox-toth-truncation", "lpvest": __version__, "options": opts},
                    np.arange(steps, dtype=float),
                    f"Cox & Toth prediction-error moments: {opts['runs']} Monte Carlo runs per filter, "
                    f"{steps} samples")


def _sridhar_prepare(spec: SweepSpec, fmus: Any) -> Prepared:
    from .._version import __version__
    from ..experiments._fmus import as_experiment_fmus
    from ..experiments._sridhar import NOISY_METRICS, noisy_seed_task, noisy_setup, sridhar_data

    setup = noisy_setup(sridhar_data(as_experiment_fmus(fmus), progress=False))
    data_sha = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in
                                       (setup.t, setup.u, setup.y, setup.x, setup.batch_y))).hexdigest()
    signals = {s: ((setup.t.size,), ()) for s in spec.keep}
    return Prepared(_experiment_task(noisy_seed_task, spec), setup, _select_metrics(spec, NOISY_METRICS), signals,
                    {"experiment": "sridhar-noisy", "lpvest": __version__, "data": data_sha}, setup.t,
                    "Sridhar et al. V-B: 30 dB output noise on the plant FMU's samples over [0, 9] s, "
                    "two fits per seed")


def _peixoto_prepare(spec: SweepSpec, fmus: Any) -> Prepared:
    from .._version import __version__
    from ..experiments._peixoto import example2_task

    return Prepared(_experiment_task(example2_task, spec), None, _select_metrics(spec, _PEIXOTO_METRICS), {},
                    {"experiment": "peixoto-example2", "lpvest": __version__}, None,
                    "Peixoto et al. Example 2: Theorem 1 per rho (best epsilon, or the given epsilon)")


@dataclass(frozen=True)
class _Selected:
    """A task function whose metrics are cut to a selection (picklable)."""

    fn: Callable[[Any, Task], TaskResult]
    metrics: tuple[str, ...]
    signals: tuple[str, ...]

    def __call__(self, shared: Any, task: Task) -> TaskResult:
        r = self.fn(shared, task)
        return TaskResult({k: r.metrics[k] for k in self.metrics}, {k: r.signals[k] for k in self.signals})


def _experiment_task(fn: Callable[[Any, Task], TaskResult], spec: SweepSpec) -> Callable[[Any, Task], TaskResult]:
    st = study(spec.experiment)  # type: ignore[arg-type]
    return _Selected(fn, spec.metric_names or st.metrics, spec.keep)


_COX_METRICS = ("mean_trace", "monte_carlo_mean_trace", "relative_difference")
_PEIXOTO_METRICS = ("gamma", "design_epsilon", "n_evaluations")
STUDIES_OPTIONS: dict[str, dict[str, Any]] = {
    "cox-toth-truncation": {"steps": 300, "runs": 2000, "burn_in": 50, "seed": 7},
}


def _prediction_filters() -> tuple[str, ...]:
    from ..experiments._cox_toth import PREDICTION_FILTERS

    return PREDICTION_FILTERS


def _noisy_metrics() -> tuple[str, ...]:
    from ..experiments._sridhar import NOISY_METRICS

    return NOISY_METRICS


@functools.cache
def experiment_studies() -> dict[str, ExperimentStudy]:
    """The registered experiment studies (``experiment = NAME`` in a sweep file), by name."""
    return {s.name: s for s in (
        ExperimentStudy("cox-toth-truncation", "Cox & Toth: prediction-error variance of exact, truncated and "
                        "frozen-gain filters, Monte Carlo against the exact moments", _cox_toth_prepare,
                        {"filter": _prediction_filters()}, 0, STUDIES_OPTIONS["cox-toth-truncation"], _COX_METRICS,
                        ("monte_carlo_trace", "exact_trace")),
        ExperimentStudy("sridhar-noisy", "Sridhar et al. V-B: B-spline fits under 30 dB output noise, per seed",
                        _sridhar_prepare, {}, 20, {}, _noisy_metrics(), ("a0", "y", "dy")),
        ExperimentStudy("peixoto-example2", "Peixoto et al. Example 2: gamma of Theorem 1 over rho (and epsilon)",
                        _peixoto_prepare, {"rho": tuple(float(r) for r in range(1, 22)), "epsilon": None}, 0, {},
                        _PEIXOTO_METRICS, ()),
    )}


def study(name: str, *, where: str = "experiment") -> ExperimentStudy:
    """The registered experiment study ``name``."""
    studies = experiment_studies()
    if name not in studies:
        raise ModelFileError(f"{where}: no experiment {name!r} to sweep (experiments: {', '.join(studies)})")
    return studies[name]


def prepare(spec: SweepSpec, *, fmus: Any = None, ship_fmus: bool = True) -> Prepared:
    """The :class:`Prepared` sweep of ``spec`` (FMUs read, set-up checked).

    ``fmus``: the experiments' FMU cache (an
    :class:`~lpvest.experiments.ExperimentFmus` or its folder) for
    experiments that run FMUs.
    """
    if spec.cosim is not None:
        return _prepare_cosim(spec, ship_fmus=ship_fmus)
    return study(spec.experiment).prepare(spec, fmus)  # type: ignore[arg-type]
