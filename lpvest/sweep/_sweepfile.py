"""Sweep description files (TOML): what ``lpvest sweep SPEC.toml`` runs.

A sweep is one co-simulation file (or a registered experiment) run once per
combination of its axes. Every error names the file and the field, in one
line (``sweep.toml: seeds.parameters[1]: ...``). The format, by example
(``examples/sweep_kalman.toml`` is a complete file)::

    title = "Kalman filter over 200 noise realisations"
    cosim = "cox_toth_kalman.toml"   # the co-simulation file (relative to this file), or
    # experiment = "sridhar-noisy"   #   a registered experiment (`lpvest sweep --list`)
    steps = 100                      # optional: override the co-simulation's number of steps
    # fmu_dir = "../fmu-build"       # optional: where the co-simulation's FMUs are (relative to this file)
    keep = ["plant.x", "kalman.xhat"]         # optional: trajectories to store (Zarr)

    [seeds]                          # optional: the Monte Carlo axis
    count = 200                      # seed keys 0 .. 199, or: keys = [0, 7, 19]
    root = 2026                      # entropy of numpy.random.SeedSequence (default 0)
    parameters = ["plant.seed", "sched.seed"]   # FMU Integer parameters given per-task seeds
    common = true                    # same noise at every parameter point (default true)

    [parameters]                     # optional: a grid (every combination)
    "truncated.tau" = [1, 3, 10]     # values of an FMU parameter; a list per value for a vector
    "sched.rate" = [[0.05], [0.2]]

    [[zip]]                          # optional, repeatable: lists varied together (equal lengths)
    "plant.x0" = [[0.0, 0.0], [1.0, -1.0]]
    "kalman.x0" = [[0.0, 0.0], [1.0, -1.0]]

    [metrics]                        # summary numbers per task (lpvest.sweep)
    rms_x = { kind = "rms_error", estimate = "kalman.xhat", truth = "plant.x", start = 20 }
    trace_P = { kind = "final_trace", of = "kalman.P" }

``seeds = 200`` and ``seeds = [0, 7]`` are short for ``count`` and ``keys``.
Tasks are numbered with the parameter points outer (grid axes in the order
written, the last fastest, then the zip groups) and the seeds inner. Task
``i`` with seed key ``s`` gives its seed parameters
:func:`~lpvest.sweep.task_seeds` ``(root, s)`` (``common = true``) or
``(root, i)`` (``common = false``): ``seeds = 200`` and ``seeds = [17]`` give
seed key 17 the same noise.

For an experiment, the axes, ``options`` and the metrics are the
experiment's (:mod:`lpvest.sweep`); ``metrics`` and ``keep`` are then
lists of the names it offers.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core._errors import ModelFileError
from ..core._toml import describe_value
from ..parallel._tasks import Task, task_seeds
from ._metrics import Metric, parse as parse_metric

if TYPE_CHECKING:
    from ..cosim._cosimfile import CoSimFile

__all__ = ["Axis", "Seeds", "SweepSpec", "with_defaults", "load_sweep", "sweep_spec"]

_TOP_KEYS = {"title", "description", "cosim", "experiment", "fmu_dir", "steps", "seeds", "parameters", "zip",
             "keep", "metrics", "options"}
_SEED_KEYS = {"count", "keys", "root", "parameters", "common"}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")



@dataclass(frozen=True)
class Axis:
    """A swept name and its values (scalars, or lists of numbers for a vector).

    Parameters
    ----------
    name : str
        An FMU parameter ``"component.variable"`` (co-simulation) or an axis
        name of the experiment.
    values : tuple
        The values, all of one kind: numbers, strings, booleans, or tuples of
        numbers (a vector parameter).
    """

    name: str
    values: tuple[Any, ...]


@dataclass(frozen=True)
class Seeds:
    """The seed axis: which keys, from which root, into which FMU parameters.

    Parameters
    ----------
    keys : tuple of int
        The seed keys (non-negative), one task per key and parameter point.
    root : int, default 0
        Entropy of the ``numpy.random.SeedSequence`` the seeds derive from.
    parameters : tuple of str, default ()
        FMU Integer parameters ``"component.variable"`` given per-task seeds
        (empty for an experiment, which seeds itself).
    common : bool, default True
        Derive the seeds from the seed key (same noise at every parameter
        point); ``False``: from the task index.
    """

    keys: tuple[int, ...]
    root: int = 0
    parameters: tuple[str, ...] = ()
    common: bool = True


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep description (see the module documentation).

    Build one with :func:`load_sweep` (a TOML file) or :func:`sweep_spec` (the
    same content as a dictionary).

    Parameters
    ----------
    origin : str
        The file (or ``"sweep spec"``), for messages.
    title : str
        The ``title`` of the file (may be empty).
    cosim : CoSimFile or None
        The co-simulation, or ``None`` for an experiment.
    experiment : str or None
        The registered experiment's name, or ``None`` for a co-simulation.
    grid : tuple of Axis, default ()
        The ``[parameters]`` axes, every combination swept (the last fastest).
    zips : tuple of tuple of Axis, default ()
        The ``[[zip]]`` groups: axes of equal length varied together.
    seeds : Seeds or None, default None
        The seed axis; ``None``: one task per parameter point.
    keep : tuple of str, default ()
        Trajectories to store.
    metrics : tuple of Metric, default ()
        Co-simulation metrics.
    metric_names : tuple of str, default ()
        Experiment metrics kept (empty: all).
    options : mapping, default {}
        Experiment options.
    """

    origin: str
    title: str
    cosim: CoSimFile | None
    experiment: str | None
    grid: tuple[Axis, ...] = ()
    zips: tuple[tuple[Axis, ...], ...] = ()
    seeds: Seeds | None = None
    keep: tuple[str, ...] = ()
    metrics: tuple[Metric, ...] = ()
    metric_names: tuple[str, ...] = ()
    options: Mapping[str, Any] = field(default_factory=dict)

    def error(self, where: str, message: str) -> ModelFileError:
        """The error to raise for a mistake in the field ``where``.

        Parameters
        ----------
        where : str
            The field (``"seeds.count"``, ``"metrics.rms_x"``).
        message : str
            What is wrong with it.

        Returns
        -------
        ModelFileError
            With the message ``"<origin>: <where>: <message>"`` (not raised).
        """
        return ModelFileError(f"{self.origin}: {where}: {message}")

    @property
    def axes(self) -> tuple[Axis, ...]:
        """Every parameter axis, grid first, then the zip groups."""
        return self.grid + tuple(a for group in self.zips for a in group)

    def points(self) -> list[dict[str, Any]]:
        """The parameter points in task order (the last grid axis fastest).

        Returns
        -------
        list of dict
            One dict per point, axis name -> value: the product of the grid
            axes and the zip groups (in that order); ``[{}]`` without axes.
        """
        pools: list[list[dict[str, Any]]] = [[{a.name: v} for v in a.values] for a in self.grid]
        for group in self.zips:
            n = len(group[0].values)
            pools.append([{a.name: a.values[i] for a in group} for i in range(n)])
        out = []
        for combo in itertools.product(*pools):
            point: dict[str, Any] = {}
            for part in combo:
                point.update(part)
            out.append(point)
        return out

    def tasks(self) -> list[Task]:
        """Every task: parameter points outer, seed keys inner.

        Returns
        -------
        list of Task
            ``Task(index, point, seed key, seed values)``; the seed values are
            :func:`~lpvest.sweep.task_seeds` ``(root, key)`` (``common``)
            or ``(root, index)``, empty without seed parameters.
        """
        points = self.points()
        keys: Sequence[int | None] = self.seeds.keys if self.seeds else (None,)
        names = self.seeds.parameters if self.seeds else ()
        out = []
        for p_i, point in enumerate(points):
            for s_i, key in enumerate(keys):
                index = p_i * len(keys) + s_i
                values = {}
                if key is not None and names:
                    spawn = key if self.seeds.common else index  # type: ignore[union-attr]
                    values = task_seeds(self.seeds.root, spawn, names)  # type: ignore[union-attr]
                out.append(Task(index, point, key, values))
        return out

    @property
    def n_tasks(self) -> int:
        n = len(self.seeds.keys) if self.seeds else 1
        for a in self.grid:
            n *= len(a.values)
        for g in self.zips:
            n *= len(g[0].values)
        return n

    def identity(self) -> dict[str, Any]:
        """What the results depend on in the spec (not the title): axes, seeds,
        metrics, kept signals, options (the study adds its own inputs).

        Returns
        -------
        dict
            JSON-able: ``grid``, ``zips``, ``seeds``, ``keep``, ``metrics``,
            ``metric_names`` and ``options``.
        """
        return {
            "grid": [[a.name, list(a.values)] for a in self.grid],
            "zips": [[[a.name, list(a.values)] for a in g] for g in self.zips],
            "seeds": None if self.seeds is None else {
                "keys": list(self.seeds.keys), "root": self.seeds.root,
                "parameters": list(self.seeds.parameters), "common": self.seeds.common},
            "keep": list(self.keep),
            "metrics": [[m.name, m.kind, dict(m.variables), m.start] for m in self.metrics],
            "metric_names": list(self.metric_names),
            "options": dict(self.options),
        }


class _Reader:
    def __init__(self, origin: str) -> None:
        self.origin = origin

    def error(self, where: str, message: str) -> ModelFileError:
        return ModelFileError(f"{self.origin}: {where}: {message}")

    def axes(self, table: Any, where: str, *, dotted: bool) -> list[Axis]:
        if not isinstance(table, Mapping):
            raise self.error(where, f"expected a table of name = [values], found {describe_value(table)}")
        flat: dict[str, Any] = {}

        def walk(t: Mapping, prefix: str) -> None:
            for k, v in t.items():
                name = f"{prefix}.{k}" if prefix else str(k)
                if isinstance(v, Mapping):
                    walk(v, name)
                else:
                    flat[name] = v

        walk(table, "")
        out = []
        for name, values in flat.items():
            w = f"{where}.{name}"
            if dotted and not re.match(r"^[A-Za-z_]\w*\.[^.\s].*$", name):
                raise self.error(w, "expected a parameter 'component.variable'")
            if not dotted and not _NAME.match(name):
                raise self.error(w, "expected an axis name of the experiment")
            if not isinstance(values, list) or not values:
                raise self.error(w, f"expected a non-empty list of values, found {describe_value(values)}")
            kinds = set()
            for i, v in enumerate(values):
                if isinstance(v, list):
                    if not v or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
                        raise self.error(f"{w}[{i + 1}]", f"expected a number, string, boolean or a list of "
                                         f"numbers, found {describe_value(v)} {v!r}")
                    kinds.add("vector")
                elif isinstance(v, bool | int | float | str):
                    kinds.add({bool: "bool", str: "str"}.get(type(v), "number"))
                else:
                    raise self.error(f"{w}[{i + 1}]", f"expected a number, string, boolean or a list of numbers, "
                                     f"found {describe_value(v)}")
            if len(kinds) > 1:
                raise self.error(w, f"mixes {' and '.join(sorted(kinds))} values (one kind per axis)")
            out.append(Axis(name, tuple(tuple(v) if isinstance(v, list) else v for v in values)))
        return out

    def strings(self, value: Any, where: str, *, dotted: bool = True) -> tuple[str, ...]:
        if not isinstance(value, list):
            raise self.error(where, f"expected a list of strings, found {describe_value(value)}")
        for i, v in enumerate(value):
            if not isinstance(v, str) or (dotted and "." not in v):
                what = "'component.variable'" if dotted else "a name"
                raise self.error(f"{where}[{i + 1}]", f"expected {what}, found {describe_value(v)}")
        if len(set(value)) != len(value):
            dup = next(v for v in value if value.count(v) > 1)
            raise self.error(where, f"{dup!r} is listed twice")
        return tuple(value)

    def seeds(self, value: Any, *, cosim: bool) -> Seeds:
        if isinstance(value, bool):
            raise self.error("seeds", "expected a count, a list of seed keys or a table, found "
                                      f"{describe_value(value)}")
        if isinstance(value, int):
            value = {"count": value}
        elif isinstance(value, list):
            value = {"keys": value}
        if not isinstance(value, Mapping):
            raise self.error("seeds", "expected a count, a list of seed keys or a table, found "
                                      f"{describe_value(value)}")
        unknown = sorted(set(value) - _SEED_KEYS)
        if unknown:
            raise self.error(f"seeds.{unknown[0]}", f"unknown key (expected one of: {', '.join(sorted(_SEED_KEYS))})")
        if ("count" in value) == ("keys" in value):
            raise self.error("seeds", "give either count or keys (exactly one)")
        if "count" in value:
            n = value["count"]
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:
                raise self.error("seeds.count", f"expected a positive integer, found {describe_value(n)}")
            keys = tuple(range(n))
        else:
            raw = value["keys"]
            if not isinstance(raw, list) or not raw:
                raise self.error("seeds.keys", f"expected a non-empty list of integers, found {describe_value(raw)}")
            for i, k in enumerate(raw):
                if isinstance(k, bool) or not isinstance(k, int) or k < 0:
                    raise self.error(f"seeds.keys[{i + 1}]",
                                     f"expected a non-negative integer, found {describe_value(k)}")
            if len(set(raw)) != len(raw):
                raise self.error("seeds.keys", f"seed key {next(k for k in raw if raw.count(k) > 1)} is listed twice")
            keys = tuple(raw)
        root = value.get("root", 0)
        if isinstance(root, bool) or not isinstance(root, int) or root < 0:
            raise self.error("seeds.root", f"expected a non-negative integer, found {describe_value(root)}")
        common = value.get("common", True)
        if not isinstance(common, bool):
            raise self.error("seeds.common", f"expected true or false, found {describe_value(common)}")
        params: tuple[str, ...] = ()
        if cosim:
            if "parameters" not in value:
                raise self.error("seeds.parameters", "missing (the FMU Integer parameters that take the per-task "
                                 "seeds, e.g. [\"plant.seed\"])")
            params = self.strings(value["parameters"], "seeds.parameters")
            if not params:
                raise self.error("seeds.parameters", "expected at least one 'component.variable'")
        else:
            for key in ("parameters", "root", "common"):
                if key in value:
                    raise self.error(f"seeds.{key}", "an experiment draws its noise from its own seeds "
                                     "(only count or keys)")
        return Seeds(keys, int(root), params, common)


def load_sweep(path: str | Path, *, fmu_dir: str | Path | None = None) -> SweepSpec:
    """Read and check a sweep file (see the module documentation).

    Parameters
    ----------
    path : str or Path
        The TOML file.
    fmu_dir : str or Path, optional
        Folder of the co-simulation's FMUs (overrides the files' ``fmu_dir``).

    Returns
    -------
    SweepSpec
        The checked sweep; relative paths in the file start from its folder.

    Raises
    ------
    ModelFileError
        One line naming the file and the field.
    """
    from ..core._toml import read_toml

    path = Path(path)
    return sweep_spec(read_toml(path), origin=str(path), base=path.parent, fmu_dir=fmu_dir)


def sweep_spec(
    data: Mapping[str, Any],
    *,
    origin: str = "sweep spec",
    base: str | Path = ".",
    fmu_dir: str | Path | None = None,
) -> SweepSpec:
    """A :class:`SweepSpec` from a dictionary with the keys of a sweep file.

    ``base`` is the folder that relative paths (``cosim``, ``fmu_dir``) start
    from; ``origin`` names the description in messages.

    Parameters
    ----------
    data : mapping
        The keys of a sweep file (see the module documentation).
    origin : str, default "sweep spec"
        Name of the description in error messages.
    base : os.PathLike or str, default "."
        Folder that the relative paths ``cosim`` and ``fmu_dir`` start from.
    fmu_dir : os.PathLike or str or None, default None
        Folder of the co-simulation's FMUs; overrides ``data["fmu_dir"]``
        (which is relative to ``base``).

    Returns
    -------
    SweepSpec
        The checked sweep; for an experiment, with its default axes and
        seeds where ``data`` gives none (:func:`with_defaults`).

    Raises
    ------
    ModelFileError
        One line naming ``origin`` and the field.

    Examples
    --------
    >>> spec = sweep_spec({"cosim": "examples/cox_toth_kalman.toml", "seeds": {"count": 4,
    ...     "parameters": ["plant.seed"]}, "metrics": {"rms": {"kind": "rms_error",
    ...     "estimate": "kalman.xhat", "truth": "plant.x"}}})       # doctest: +SKIP
    >>> spec.n_tasks                                                 # doctest: +SKIP
    4
    """
    from ..cosim._cosimfile import load_cosim

    r = _Reader(origin)
    base = Path(base)
    if not isinstance(data, Mapping):
        raise ModelFileError(f"{origin}: expected a table, found {describe_value(data)}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise r.error(unknown[0], f"unknown key (expected one of: {', '.join(sorted(_TOP_KEYS))})")
    title = data.get("title", "")
    if not isinstance(title, str):
        raise r.error("title", f"expected a string, found {describe_value(title)}")
    if ("cosim" in data) == ("experiment" in data):
        raise r.error("cosim", "give either cosim (a co-simulation file) or experiment (a registered "
                      "experiment), exactly one")
    cosim = None
    experiment = None
    if "cosim" in data:
        if not isinstance(data["cosim"], str):
            raise r.error("cosim", f"expected a co-simulation file (a path), found {describe_value(data['cosim'])}")
        for key in ("options",):
            if key in data:
                raise r.error(key, "only an experiment takes options")
        folder = fmu_dir
        if folder is None and "fmu_dir" in data:
            if not isinstance(data["fmu_dir"], str):
                raise r.error("fmu_dir", f"expected a folder (a path), found {describe_value(data['fmu_dir'])}")
            folder = base / data["fmu_dir"]
        cosim = load_cosim(base / data["cosim"], fmu_dir=folder)
        if "steps" in data:
            steps = data["steps"]
            if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
                raise r.error("steps", f"expected a positive integer, found {describe_value(steps)}")
            cosim = replace(cosim, n_steps=steps)
    else:
        from ..experiments._studies import study

        name = data["experiment"]
        if not isinstance(name, str):
            raise r.error("experiment", f"expected an experiment name, found {describe_value(name)}")
        for key in ("steps", "fmu_dir"):
            if key in data:
                raise r.error(key, "only a co-simulation takes this key (an experiment has options)")
        study(name, where=f"{origin}: experiment")  # known?
        experiment = name

    seeds = r.seeds(data["seeds"], cosim=cosim is not None) if "seeds" in data else None
    grid = tuple(r.axes(data["parameters"], "parameters", dotted=cosim is not None)) if "parameters" in data else ()
    zips: list[tuple[Axis, ...]] = []
    if "zip" in data:
        groups = data["zip"]
        if isinstance(groups, Mapping):
            groups = [groups]
        if not isinstance(groups, list):
            raise r.error("zip", f"expected tables [[zip]] of lists of equal length, found {describe_value(groups)}")
        for i, g in enumerate(groups):
            where = f"zip[{i + 1}]"
            axes = tuple(r.axes(g, where, dotted=cosim is not None))
            if not axes:
                raise r.error(where, "expected at least one name = [values]")
            n = len(axes[0].values)
            for a in axes[1:]:
                if len(a.values) != n:
                    raise r.error(f"{where}.{a.name}", f"has {len(a.values)} values; {axes[0].name} has {n} "
                                  "(zipped lists have equal lengths)")
            zips.append(axes)
    names = [a.name for a in grid] + [a.name for g in zips for a in g]
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise r.error("parameters", f"{name} is swept twice")
        seen.add(name)
    if seeds is not None:
        for p in seeds.parameters:
            if p in seen:
                raise r.error("seeds.parameters", f"{p} is also a swept parameter")

    keep: tuple[str, ...] = ()
    if "keep" in data:
        keep = r.strings(data["keep"], "keep", dotted=cosim is not None)
    metrics: list[Metric] = []
    metric_names: tuple[str, ...] = ()
    options: dict[str, Any] = {}
    if cosim is not None:
        table = data.get("metrics", {})
        if not isinstance(table, Mapping):
            raise r.error("metrics", f"expected a table of name = {{ kind = ..., ... }}, found {describe_value(table)}")
        for name, t in table.items():
            where = f"metrics.{name}"
            if not _NAME.match(name) or name in ("task", "seed", "status", "error"):
                raise r.error(where, "expected a metric name (letters, digits, _; not task, seed, status, error)")
            m = parse_metric(name, t, where)
            if isinstance(m, str):
                raise r.error(where, m)
            metrics.append(m)
        if not metrics and not keep:
            raise r.error("metrics", "missing: name at least one metric or a kept signal (keep)")
    else:
        from ..experiments._studies import study

        st = study(experiment)  # type: ignore[arg-type]
        if "metrics" in data:
            metric_names = r.strings(data["metrics"], "metrics", dotted=False)
            for i, m in enumerate(metric_names):
                if m not in st.metrics:
                    raise r.error(f"metrics[{i + 1}]", f"{experiment} has no metric {m!r} "
                                  f"(metrics: {', '.join(st.metrics)})")
        for i, s in enumerate(keep):
            if s not in st.signals:
                raise r.error(f"keep[{i + 1}]", f"{experiment} keeps no signal {s!r} "
                              f"(signals: {', '.join(st.signals) or 'none'})")
        for a in (*grid, *(a for g in zips for a in g)):
            if a.name not in st.axes:
                raise r.error(f"parameters.{a.name}", f"{experiment} has no axis {a.name!r} "
                              f"(axes: {', '.join(st.axes) or 'none'})")
        if seeds is not None and not st.seeded:
            raise r.error("seeds", f"{experiment} has no seed axis")
        raw = data.get("options", {})
        if not isinstance(raw, Mapping):
            raise r.error("options", f"expected a table, found {describe_value(raw)}")
        for key, value in raw.items():
            if key not in st.options:
                raise r.error(f"options.{key}", f"unknown option of {experiment} "
                              f"(options: {', '.join(st.options) or 'none'})")
            default = st.options[key]
            if isinstance(value, bool) != isinstance(default, bool) or not isinstance(value, type(default)) \
                    and not (isinstance(default, float) and isinstance(value, int)):
                raise r.error(f"options.{key}",
                              f"expected {describe_value(default).split(' (')[0]}, found {describe_value(value)}")
            options[key] = value
    spec = SweepSpec(origin, title, cosim, experiment, grid, tuple(zips), seeds, keep, tuple(metrics),
                     metric_names, options)
    if experiment is not None:
        spec = with_defaults(spec)
    return spec


def with_defaults(spec: SweepSpec) -> SweepSpec:
    """An experiment's spec with its default axes and seeds where the file gives none.

    Parameters
    ----------
    spec : SweepSpec
        A checked spec.

    Returns
    -------
    SweepSpec
        ``spec`` with the experiment's default axes appended to the grid and
        its default seed keys when it is seeded and ``spec`` has no seeds;
        ``spec`` itself for a co-simulation.
    """
    if spec.experiment is None:
        return spec
    from ..experiments._studies import study

    st = study(spec.experiment)
    given = {a.name for a in spec.axes}
    grid = list(spec.grid)
    for name, values in st.axes.items():
        if name not in given and values is not None:
            grid.append(Axis(name, tuple(values)))
    seeds = spec.seeds
    if seeds is None and st.seeded:
        seeds = Seeds(tuple(range(st.seeds)))
    return replace(spec, grid=tuple(grid), seeds=seeds)
