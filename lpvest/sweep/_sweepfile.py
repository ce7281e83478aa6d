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

from ..core._errors import ModelFileError, shorten
from ..core._toml import TomlReader, describe_value, element_path
from ..parallel._tasks import Task, task_seeds
from ._metrics import METRIC_KINDS, Metric

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
        return TomlReader(self.origin).error(where, message)

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
                    spawn = key if self.seeds.common else index  # type: ignore[union-attr]  # names: seeds set
                    values = task_seeds(self.seeds.root, spawn, names)  # type: ignore[union-attr]  # names: seeds set
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


def _axes(r: TomlReader, value: Any, where: str, *, dotted: bool) -> list[Axis]:
    """The axes of a ``[parameters]`` or ``[[zip]]`` table: ``name = [values]``."""
    table = r.table(value, where, what="a table of name = [values]")
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
            raise r.error(w, "expected a parameter 'component.variable'")
        if not dotted and not _NAME.match(name):
            raise r.error(w, "expected an axis name of the experiment")
        r.array(values, w, what="a non-empty list of values", nonempty=True)
        kinds = set()
        for i, v in enumerate(values):
            if isinstance(v, list) and v and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
                kinds.add("vector")
            elif isinstance(v, bool | int | float | str):
                kinds.add({bool: "bool", str: "str"}.get(type(v), "number"))
            else:
                raise r.expected(element_path(w, i), "a number, string, boolean or a list of numbers", v)
        if len(kinds) > 1:
            raise r.error(w, f"mixes {' and '.join(sorted(kinds))} values (one kind per axis)")
        out.append(Axis(name, tuple(tuple(v) if isinstance(v, list) else v for v in values)))
    return out


def _names(r: TomlReader, value: Any, where: str, *, dotted: bool = True) -> tuple[str, ...]:
    """A list of distinct names: ``'component.variable'`` when ``dotted``."""
    what = "'component.variable'" if dotted else "a name"
    names = r.strings(value, where, what=what)
    for i, v in enumerate(names):
        if dotted and "." not in v:
            raise r.expected(element_path(where, i), what, v)
    if len(set(names)) != len(names):
        dup = next(v for v in names if names.count(v) > 1)
        raise r.error(where, f"{dup!r} is listed twice")
    return tuple(names)


def _seeds(r: TomlReader, value: Any, *, cosim: bool) -> Seeds:
    """The ``seeds`` axis: a count, a list of seed keys or a table."""
    if isinstance(value, int) and not isinstance(value, bool):
        value = {"count": value}
    elif isinstance(value, list):
        value = {"keys": value}
    table = r.table(value, "seeds", what="a count, a list of seed keys or a table")
    table.check_keys(_SEED_KEYS)
    if ("count" in table) == ("keys" in table):
        raise r.error("seeds", "give either count or keys (exactly one)")
    if "count" in table:
        keys = tuple(range(table.integer("count", minimum=1)))
    else:
        raw = table.array("keys", what="a non-empty list of integers", nonempty=True)
        keys = tuple(r.integer(k, element_path("seeds.keys", i), minimum=0) for i, k in enumerate(raw))
        if len(set(keys)) != len(keys):
            raise r.error("seeds.keys", f"seed key {next(k for k in keys if keys.count(k) > 1)} is listed twice")
    root = table.integer("root", 0, minimum=0)
    common = table.boolean("common", True)
    params: tuple[str, ...] = ()
    if cosim:
        params = _names(r, table.value("parameters", "the FMU Integer parameters that take the per-task seeds, "
                                                     "e.g. [\"plant.seed\"]"), "seeds.parameters")
        if not params:
            raise r.error("seeds.parameters", "expected at least one 'component.variable'")
    else:
        for key in ("parameters", "root", "common"):
            if key in table:
                raise r.error(f"seeds.{key}", "an experiment draws its noise from its own seeds "
                              "(only count or keys)")
    return Seeds(keys, root, params, common)


def _metric(r: TomlReader, name: str, value: Any, where: str) -> Metric:
    """A :class:`Metric` from its table ``{ kind = ..., ... }`` in ``[metrics]``."""
    table = r.table(value, where, what="a table { kind = ..., ... }")
    kind = table.choice("kind", METRIC_KINDS, noun="metric kind")
    keys, takes_start = METRIC_KINDS[kind]
    table.check_keys({"kind", *keys, *(("start",) if takes_start else ())})
    variables = {}
    for key in keys:
        what = "a recorded variable 'component.variable'"
        variables[key] = table.string(key, what=what)
        if "." not in variables[key]:
            raise r.expected(table.path(key), what, variables[key])
    return Metric(name, kind, variables, table.integer("start", 0, minimum=0))


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

    r = TomlReader(origin)
    base = Path(base)
    top = r.root(data)
    top.check_keys(_TOP_KEYS)
    title = top.string("title", "")
    if ("cosim" in top) == ("experiment" in top):
        raise r.error("cosim", "give either cosim (a co-simulation file) or experiment (a registered "
                      "experiment), exactly one")
    cosim = None
    experiment = None
    if "cosim" in top:
        file = top.string("cosim", what="a co-simulation file (a path)")
        for key in ("options",):
            if key in top:
                raise r.error(key, "only an experiment takes options")
        folder = fmu_dir
        if folder is None and "fmu_dir" in top:
            folder = base / top.string("fmu_dir", what="a folder (a path)")
        path = base / file
        if not path.is_file():  # said here: which file names it, and where it was looked for
            shown = shorten(str(path), 80)
            raise r.error("cosim", f"{shown} is a folder, not a co-simulation file" if path.is_dir() else
                          f"no co-simulation file {shown} (a path relative to this sweep file)")
        cosim = load_cosim(base / file, fmu_dir=folder)
        if "steps" in top:
            cosim = replace(cosim, n_steps=top.integer("steps", minimum=1))
    else:
        from ..experiments._studies import study

        name = top.string("experiment", what="an experiment name")
        for key in ("steps", "fmu_dir"):
            if key in top:
                raise r.error(key, "only a co-simulation takes this key (an experiment has options)")
        study(name, where=f"{origin}: experiment")  # known?
        experiment = name

    seeds = _seeds(r, top["seeds"], cosim=cosim is not None) if "seeds" in top else None
    grid = tuple(_axes(r, top["parameters"], "parameters", dotted=cosim is not None)) if "parameters" in top else ()
    zips: list[tuple[Axis, ...]] = []
    if "zip" in top:
        groups = top["zip"]
        if isinstance(groups, Mapping):
            groups = [groups]
        r.array(groups, "zip", what="tables [[zip]] of lists of equal length")
        for i, g in enumerate(groups):
            where = element_path("zip", i)
            axes = tuple(_axes(r, g, where, dotted=cosim is not None))
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
    if "keep" in top:
        keep = _names(r, top["keep"], "keep", dotted=cosim is not None)
    metrics: list[Metric] = []
    metric_names: tuple[str, ...] = ()
    options: dict[str, Any] = {}
    if cosim is not None:
        table = top.table("metrics", required=False, what="a table of name = { kind = ..., ... }")
        for name, t in table.items():
            where = table.path(name)
            if not _NAME.match(name) or name in ("task", "seed", "status", "error"):
                raise r.error(where, "expected a metric name (letters, digits, _; not task, seed, status, error)")
            metrics.append(_metric(r, name, t, where))
        if not metrics and not keep:
            raise r.error("metrics", "missing: name at least one metric or a kept signal (keep)")
    else:
        from ..experiments._studies import study

        st = study(experiment)  # type: ignore[arg-type]  # a str: cosim is None here
        if "metrics" in top:
            metric_names = _names(r, top["metrics"], "metrics", dotted=False)
            for i, m in enumerate(metric_names):
                if m not in st.metrics:
                    raise r.error(element_path("metrics", i), f"{experiment} has no metric {m!r} "
                                  f"(metrics: {', '.join(st.metrics)})")
        for i, s in enumerate(keep):
            if s not in st.signals:
                raise r.error(element_path("keep", i), f"{experiment} keeps no signal {s!r} "
                              f"(signals: {', '.join(st.signals) or 'none'})")
        for a in (*grid, *(a for g in zips for a in g)):
            if a.name not in st.axes:
                raise r.error(f"parameters.{a.name}", f"{experiment} has no axis {a.name!r} "
                              f"(axes: {', '.join(st.axes) or 'none'})")
        if seeds is not None and not st.seeded:
            raise r.error("seeds", f"{experiment} has no seed axis")
        raw = top.table("options", required=False)
        raw.check_keys(st.options)
        for key, value in raw.items():
            default = st.options[key]
            if isinstance(value, bool) != isinstance(default, bool) or not isinstance(value, type(default)) \
                    and not (isinstance(default, float) and isinstance(value, int)):
                raise r.expected(raw.path(key), describe_value(default).split(" (")[0], value)
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
