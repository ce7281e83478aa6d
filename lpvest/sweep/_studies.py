"""What a sweep runs: a co-simulation file, or a registered experiment's study.

:func:`prepare` turns a :class:`~lpvest.sweep.SweepSpec` into a
:class:`~lpvest.parallel.Prepared` sweep: the task function, the data every
task reads, the metric names, the shapes of the kept signals, and the
identity of what the results depend on (its SHA-256 names the sweep in its
output folder).

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

**Experiments** (``experiment = NAME``): the study the experiment holds
(:func:`lpvest.experiments.experiment_studies`), the Monte Carlo part of a
paper reproduction with the same task functions the experiment runs.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..experiments._studies import study
from ..parallel._prepared import Prepared
from ..parallel._tasks import Task, TaskResult, digest
from ._metrics import Metric, check as check_metric, compute as compute_metric, expand, select

if TYPE_CHECKING:
    from ..cosim._master import CoSimulation
    from ..experiments._fmus import ExperimentFmus
    from ._sweepfile import SweepSpec

__all__ = ["prepare", "CosimPayload", "run_cosim_task", "release_simulation"]


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


def _process_folder() -> Path:
    """This process's folder for its shipped and unpacked FMUs: the Dask
    worker's local directory (removed with the worker, and purged by Dask even
    after the worker was killed), else a temporary folder."""
    if "folder" not in _WORKER:
        try:
            from distributed import get_worker

            _WORKER["folder"] = Path(get_worker().local_directory)
        except (ImportError, ValueError):
            _WORKER["folder"] = Path(tempfile.mkdtemp(prefix="lpvest-sweep-"))
            atexit.register(shutil.rmtree, _WORKER["folder"], True)
    return _WORKER["folder"]


def _fmu_path(payload: CosimPayload, sha: str) -> Path:
    if sha in payload.fmu_paths:
        return Path(payload.fmu_paths[sha])
    folder = _process_folder() / "lpvest-fmus"
    folder.mkdir(exist_ok=True)
    path = folder / f"{sha}.fmu"
    if not path.is_file():
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(payload.fmu_bytes[sha])
        tmp.replace(path)
    return path


def _simulation(payload: CosimPayload) -> CoSimulation:
    """This process's simulation of ``payload`` (built on first use)."""
    from ..cosim import Component, CoSimulation

    if _WORKER.get("digest") == payload.digest and _WORKER.get("sim") is not None:
        return _WORKER["sim"]
    release_simulation()
    comps = [Component(name, _fmu_path(payload, sha), dict(params), feed)
             for name, sha, params, feed in payload.components]
    # on any cluster, not only lpvest's own (whose preload makes it the temporary folder)
    sim = CoSimulation(comps, payload.connections, step_size=payload.step_size, start_time=payload.start_time,
                       record=payload.record, unpack_in=_process_folder())
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


def prepare(spec: SweepSpec, *, fmus: ExperimentFmus | str | Path | None = None, ship_fmus: bool = True) -> Prepared:
    """The :class:`~lpvest.parallel.Prepared` sweep of ``spec`` (FMUs read, set-up checked).

    ``fmus``: the experiments' FMU cache (an
    :class:`~lpvest.experiments.ExperimentFmus` or its folder) for
    experiments that run FMUs; an experiment's spec goes to its study's
    ``prepare``.
    """
    if spec.cosim is not None:
        return _prepare_cosim(spec, ship_fmus=ship_fmus)
    return study(spec.experiment).prepare(spec, fmus)  # type: ignore[arg-type]  # set: cosim is None
