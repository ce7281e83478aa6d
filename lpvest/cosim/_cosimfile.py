"""Co-simulation description files (TOML): what ``lpvest cosim FILE.toml`` runs.

A file names the FMUs, their parameter values, the connections, the
communication step and how long to run; :func:`load_cosim` checks it and
:meth:`CoSimFile.run` co-simulates it with :class:`lpvest.cosim.CoSimulation`
(execution order from the connection graph: no one-step delay). Every error
names the file and the field, in one line::

    examples/bad.toml: connections[2]: expected 'comp.output -> comp.input', found 'plant.y filter.y'

The format, by example (``examples/peixoto_ex1_hinf.toml`` is a complete file)::

    title = "Peixoto et al. Example 1 with the gain-scheduled H-infinity filter"
    step_size = 1.0                  # communication step h (time units of the FMUs)
    steps = 200                      # how long: a number of steps, or
    # stop_time = 200.0              #   a stop time (start_time + a whole number of steps)
    start_time = 0.0                 # optional, default 0
    fmu_dir = "../fmu-build"         # optional: where FMUs given by name are (relative to
                                     #   this file; `lpvest cosim --fmus DIR` overrides it)
    connections = [                  # "component.output -> component.input"; a vector
        "sched.p -> plant.p",        #   name connects every element (p[1], p[2], ...)
        "plant.y -> filter.y",
    ]
    record = ["plant.z", "filter.zhat"]          # optional; default: every output but Strings
    plots = [["plant.z[1]", "filter.zhat[1]"]]   # optional panels; default: one per vector

    [components.sched]               # one table per component; the key is its name
    fmu = "PeixotoEx1Scheduler"      # a built FMU by name (looked up as NAME.fmu in the
                                     #   FMU folder) or a path to an .fmu (relative to this file)
    parameters = { omega = [0.25] }  # optional start values (vectors as lists)
    # feedthrough = false            # optional: override the FMU's declared dependencies

Examples
--------
>>> spec = load_cosim("examples/peixoto_ex1_hinf.toml", fmu_dir="fmu-build")   # doctest: +SKIP
>>> result = spec.run()                                                        # doctest: +SKIP
>>> result.write_csv("out.csv"), result.plot("out.png")                       # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core._errors import ModelFileError, abbreviate, shorten
from ..core._plotting import save_figure
from ..core._toml import TomlReader, element_path, read_toml
from ._errors import CoSimulationError
from ._master import Component, Connection, CoSimulation, DiscardedStep, step_count

__all__ = ["CoSimFile", "CoSimResult", "load_cosim", "DEFAULT_FMU_DIR"]

#: Where FMUs named without a path are looked up when neither the file nor the
#: caller says (the default output folder of ``lpvest build``).
DEFAULT_FMU_DIR = "fmu-build"

#: The most steps a file may ask for: the master keeps every recorded value in
#: memory (8 bytes per variable and step).
MAX_STEPS = 100_000_000

def _path_text(path: Path, limit: int = 120) -> str:
    """A path for a message: as is, or shortened when longer than ``limit``."""
    text = str(path)
    return text if len(text) <= limit else abbreviate(text, limit)


def _is_file(path: Path) -> bool:
    """``path.is_file()``, and ``False`` for a name the system cannot even look
    up (too long, a NUL character)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


_TOP_KEYS = {"title", "description", "step_size", "steps", "stop_time", "start_time", "fmu_dir", "connections",
             "record", "plots", "components"}
_COMPONENT_KEYS = {"fmu", "parameters", "feedthrough"}



@dataclass(frozen=True)
class CoSimFile:
    """A checked co-simulation description (see the module documentation).

    Build one with :func:`load_cosim`.

    Parameters
    ----------
    path : Path
        The file (for messages, the plot title, the SSP name).
    title : str
        The file's ``title`` (may be empty).
    components : tuple of Component
        The components, FMU paths resolved.
    connections : tuple of str
        The connections, ``"comp.output -> comp.input"``.
    step_size : float
        Communication step ``h``.
    n_steps : int
        Communication steps to run (``steps``, or from ``stop_time``).
    start_time : float
        Communication point ``t_0``.
    record : tuple of str or None
        Variables to record; ``None``: every output.
    plots : tuple of tuple of str
        Plot panels, each a tuple of variable names; empty: one per vector.
    fmu_dir : Path
        The folder FMUs given by name were looked up in.
    """

    path: Path
    title: str
    components: tuple[Component, ...]
    connections: tuple[str, ...]
    step_size: float
    n_steps: int
    start_time: float
    record: tuple[str, ...] | None
    plots: tuple[tuple[str, ...], ...]
    fmu_dir: Path

    @property
    def stop_time(self) -> float:
        return self.start_time + self.n_steps * self.step_size

    def error(self, where: str, message: str) -> ModelFileError:
        """The error to raise for a mistake in the field ``where`` of this file.

        Parameters
        ----------
        where : str
            The field (``"connections[2]"``); ``""`` for none.
        message : str
            What is wrong.

        Returns
        -------
        ModelFileError
            With the message ``"<path>: <where>: <message>"`` (not raised).
        """
        return TomlReader(self.path).error(where, message)

    def _reword(self, exc: CoSimulationError) -> ModelFileError:
        """A set-up or run error of the master, as an error of this file's field."""
        msg = str(exc)
        where = exc.where
        if where.startswith("components."):
            name = where.split(".")[1]
            msg = msg.removeprefix(f"component {name}: ")
        return self.error(where, msg)

    def simulation(self) -> CoSimulation:
        """The :class:`~lpvest.cosim.CoSimulation` of this file (instances
        created; close it, or use it in a ``with`` block).

        Returns
        -------
        CoSimulation
            The instantiated co-simulation, not run yet.

        Raises
        ------
        ModelFileError
            A set-up error of the master or a plotted variable that is not
            recorded, naming this file's field.
        """
        try:
            sim = CoSimulation(self.components, self.connections, step_size=self.step_size,
                               start_time=self.start_time, record=self.record)
        except CoSimulationError as exc:
            raise self._reword(exc) from exc
        try:
            self._check_plots(sim)
        except BaseException:
            sim.close()
            raise
        return sim

    def _check_plots(self, sim: CoSimulation) -> None:
        recorded = set(sim.recorded)
        for i, panel in enumerate(self.plots):
            for name in panel:
                if not _expand_recorded(name, recorded):
                    raise self.error(f"plots[{i + 1}]", f"{abbreviate(name)} is not recorded (see record)")

    def check(self) -> list[str]:
        """Check this file against the FMUs' model descriptions (variables,
        connections, types, parameter values, plots) without instantiating an
        FMU: :meth:`run` then fails only if an FMU rejects a value at run time.
        Returns the execution order.

        Returns
        -------
        list of str
            The per-step operations (:attr:`CoSimulation.execution_order`).

        Raises
        ------
        ModelFileError
            The first mistake found, naming this file's field.
        """
        try:
            sim = CoSimulation.check(self.components, self.connections, step_size=self.step_size,
                                     start_time=self.start_time, record=self.record)
        except CoSimulationError as exc:
            raise self._reword(exc) from exc
        self._check_plots(sim)
        return sim.execution_order

    def run(self, *, progress: bool | None = None) -> CoSimResult:
        """Co-simulate: ``n_steps`` steps from ``start_time``.

        Parameters
        ----------
        progress : bool, optional
            Show a progress bar; default: for more than 20,000 steps.

        Returns
        -------
        CoSimResult
            The recorded values, the run time and the execution order.

        Raises
        ------
        ModelFileError
            A set-up or run error of the master, naming this file's field.
        """
        with self.simulation() as sim:
            order = sim.execution_order
            t0 = time.perf_counter()
            try:
                data = sim.run(self.n_steps, progress=progress)
            except CoSimulationError as exc:
                raise self._reword(exc) from exc
            elapsed = time.perf_counter() - t0
        return CoSimResult(self, data, elapsed, order, sim.discarded, tuple(sim.not_recorded))

    def to_ssp(self, path: str | Path, *, worker_threads: int | None = 0) -> Path:
        """Write this system as an SSP file (:func:`lpvest.cosim.write_ssp`).

        The SSP's name is the file's stem, its description the title, its
        default experiment from ``start_time`` to :attr:`stop_time`.

        Parameters
        ----------
        path : os.PathLike or str
            The ``.ssp`` file to write (its folder is created).
        worker_threads : int or None, default 0
            libcosim's ``numWorkerThreads`` (0: the FMUs stepped in its
            calling thread; ``None``: not declared), as in
            :func:`~lpvest.cosim.write_ssp`.

        Returns
        -------
        Path
            ``path``.
        """
        from ._ssp import write_ssp

        try:
            return write_ssp(path, self.components, self.connections, step_size=self.step_size,
                             start_time=self.start_time, stop_time=self.stop_time,
                             name=self.path.stem, description=self.title or None, worker_threads=worker_threads)
        except CoSimulationError as exc:
            raise self._reword(exc) from exc


def _short(op: str, limit: int = 4) -> str:
    """``"get kalman: a, b, c, d, e"`` -> ``"get kalman: a, b, ... (5)"``."""
    head, _, names = op.partition(": ")
    items = names.split(", ")
    return op if len(items) <= limit else f"{head}: {', '.join(items[:2])}, ... ({len(items)})"


def _expand_recorded(name: str, recorded: set[str]) -> list[str]:
    if name in recorded:
        return [name]
    return sorted((r for r in recorded if r.startswith(name + "[")), key=_element_order)


def _element_order(name: str) -> tuple:
    base, _, idx = name.partition("[")
    return (base, tuple(int(i) for i in idx.rstrip("]").split(",")) if idx else ())


@dataclass(frozen=True)
class CoSimResult:
    """The recorded values of a run of a :class:`CoSimFile`.

    Parameters
    ----------
    spec : CoSimFile
        The file that ran.
    data : ndarray, shape (n_steps + 1,)
        Structured array: ``"time"`` and ``"comp.var"`` columns.
    elapsed : float
        Seconds spent in the run (FMUs instantiated already).
    execution_order : list of str
        The per-step operations (:attr:`CoSimulation.execution_order`).
    discarded : DiscardedStep or None, default None
        Where the run stopped because a component discarded a step
        (:attr:`CoSimulation.discarded`); ``None``: it ran every step.
    not_recorded : tuple of str, default ()
        Outputs the default record leaves out (String outputs,
        :attr:`CoSimulation.not_recorded`).
    """

    spec: CoSimFile
    data: np.ndarray
    elapsed: float
    execution_order: list[str]
    discarded: DiscardedStep | None = None
    not_recorded: tuple[str, ...] = ()

    @property
    def names(self) -> list[str]:
        return [n for n in self.data.dtype.names or () if n != "time"]

    def write_csv(self, path: str | Path) -> Path:
        """``time`` and every recorded variable, full precision.

        Parameters
        ----------
        path : os.PathLike or str
            The CSV file to write (its folder is created): a header row of
            column names, then one row per communication point (``%.17g``).

        Returns
        -------
        Path
            ``path``.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)  # as plot() and write_ssp() do
        cols = ["time", *self.names]
        table = np.column_stack([self.data[c] for c in cols])
        np.savetxt(path, table, delimiter=",", header=",".join(cols), comments="", fmt="%.17g")
        return path

    def panels(self) -> list[tuple[str, list[str]]]:
        """(title, columns) of each plot panel: the file's ``plots``, else one per
        recorded vector (``plant.z`` holds ``plant.z[1]``, ``plant.z[2]``).

        Returns
        -------
        list of tuple of (str, list of str)
            ``(title, columns)`` per panel: the panel's names joined by ``", "``
            (or the vector's name) and the recorded columns it plots.
        """
        recorded = set(self.names)
        if self.spec.plots:
            out = []
            for panel in self.spec.plots:
                cols = [c for name in panel for c in _expand_recorded(name, recorded)]
                out.append((", ".join(panel), cols))
            return out
        groups: dict[str, list[str]] = {}
        for n in self.names:
            groups.setdefault(n.split("[", 1)[0], []).append(n)
        return list(groups.items())

    def plot(self, path: str | Path) -> Path:
        """One panel per group of variables (see :meth:`panels`), against time.

        Parameters
        ----------
        path : os.PathLike or str
            The figure file (PNG at 120 dpi; its folder is created), titled
            with the file's title, else its name.

        Returns
        -------
        Path
            ``path``.
        """
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        path = Path(path)
        panels = self.panels()
        fig, axes = plt.subplots(len(panels), 1, figsize=(8, 1.2 + 2.0 * len(panels)), sharex=True, squeeze=False)
        t = self.data["time"]
        for ax, (title, cols) in zip(axes[:, 0], panels, strict=True):
            for c in cols:
                ax.plot(t, self.data[c], label=c, linewidth=1.2)
            label = ", ".join(c.split(".", 1)[1] for c in cols) if cols else title
            ax.set_ylabel(label if len(label) <= 24 else "", fontsize="small")
            ax.legend(loc="upper right", fontsize="x-small", ncol=min(4, len(cols)))
            ax.grid(alpha=0.3)
        axes[-1, 0].set_xlabel("time")
        spec = self.spec
        return save_figure(fig, path, title=spec.title or spec.path.name, title_size="medium")

    def summary(self) -> str:
        """A few lines: what ran, how long, the execution order, each variable's range.

        Returns
        -------
        str
            The summary; one line per recorded variable with its min, max and rms.
        """
        spec = self.spec
        n = len(spec.components)
        lines = [
            f"co-simulated {spec.path.name}: {n} component{'s' * (n != 1)}, {spec.n_steps} steps of "
            f"{spec.step_size:g} (t = {spec.start_time:g} .. {spec.stop_time:g}) in {self.elapsed:.2f} s",
            "  each step: " + "; ".join(_short(op) for op in self.execution_order) + "; doStep each",
        ]
        stop = self.discarded
        if stop is not None:
            lines[0] = (f"co-simulated {spec.path.name}: {n} component{'s' * (n != 1)}, stopped after {stop.steps} "
                        f"of {spec.n_steps} steps of {spec.step_size:g} (t = {spec.start_time:g} .. {stop.time:g}: "
                        f"{stop.component} discarded the next step) in {self.elapsed:.2f} s")
        if self.not_recorded:
            lines.append(f"  not recorded (String outputs): {shorten(', '.join(self.not_recorded), 200)}")
        width = max((len(c) for c in self.names), default=0)
        for c in self.names:
            col = self.data[c]
            lines.append(f"  {c:<{width}}  min {np.min(col):>11.4g}  max {np.max(col):>11.4g}  "
                         f"rms {np.sqrt(np.mean(col ** 2)):>11.4g}")
        return "\n".join(lines)


# -- reading ------------------------------------------------------------------


def _variable(r: TomlReader, text: str, where: str, components: Sequence[str]) -> None:
    """``text`` names a variable of one of ``components``: ``comp.variable``."""
    comp, sep, name = text.partition(".")
    if not sep or not comp or not name:
        raise r.error(where, f"expected 'component.variable', found {abbreviate(text)}")
    if comp not in components:
        raise r.error(where, f"no component {abbreviate(comp, 24)} in {abbreviate(text)} "
                             f"(components: {shorten(', '.join(components), 60)})")


def load_cosim(path: str | Path, *, fmu_dir: str | Path | None = None) -> CoSimFile:
    """Read and check a co-simulation file (see the module documentation).

    Parameters
    ----------
    path : str or Path
        The TOML file.
    fmu_dir : str or Path, optional
        Where FMUs given by name are looked up (overrides the file's
        ``fmu_dir``; relative to the current directory). Default: the file's
        ``fmu_dir`` (relative to the file), else ``fmu-build``.

    Returns
    -------
    CoSimFile
        The checked description; FMU files exist, names and connections are
        well-formed (checked against the FMUs by :meth:`CoSimFile.check`).

    Raises
    ------
    ModelFileError
        One line naming the file and the field, e.g.
        ``run.toml: step_size: expected a positive number, found a number (-1.0)``.
    """
    path = Path(path)
    r = TomlReader(path)
    data = r.root(read_toml(path))
    data.check_keys(_TOP_KEYS)
    title = data.string("title", "")

    # timing
    h = data.number("step_size", positive=True)
    t0 = data.number("start_time", 0.0)
    if ("steps" in data) == ("stop_time" in data):
        raise r.error("steps", "give either steps or stop_time (exactly one)")
    if "steps" in data:
        n_steps = data.integer("steps", minimum=1)
        where_steps = "steps"
    else:
        stop = data.number("stop_time")
        count, ratio = step_count(t0, stop, h)
        if not math.isfinite(ratio):
            raise r.error("stop_time", f"expected start_time + a positive whole number of steps of {h:g}, "
                          f"found {stop!r} (more steps than a float can count)")
        if count is None or count < 1:
            raise r.error("stop_time", f"expected start_time + a positive whole number of steps of {h:g}, "
                          f"found {stop!r} ({ratio:.6g} steps)")
        n_steps = count
        where_steps = "stop_time"
    if n_steps > MAX_STEPS:
        raise r.error(where_steps,
                      f"{float(n_steps):.6g} steps: at most {MAX_STEPS:,} (the results are kept in memory)")
    if not math.isfinite(t0 + n_steps * h):
        raise r.error(where_steps, f"the stop time start_time + steps * step_size = {t0 + n_steps * h} "
                                   "is not a finite number")

    # components
    comps_raw = data.table("components", what="a table [components.NAME] per component")
    if not comps_raw:
        raise r.error("components", "expected at least one [components.NAME] table")
    if fmu_dir is not None:
        folder = Path(fmu_dir)
    elif "fmu_dir" in data:
        folder = path.parent / data.string("fmu_dir", what="a string (a folder)")
    else:
        folder = Path(DEFAULT_FMU_DIR)
    components = []
    for name in comps_raw:
        where = comps_raw.path(name)
        if not name.isidentifier():
            # the name is in the field path already (as a model file says of a parameter name)
            raise r.error(where, "is not a valid component name (expected a letter, then letters, digits, _)")
        spec = comps_raw.table(name)
        spec.check_keys(_COMPONENT_KEYS)
        fmu = spec.string("fmu", what="a built FMU's name or a path to an .fmu file")
        if not fmu:
            raise r.expected(spec.path("fmu"), "a built FMU's name or a path to an .fmu file", fmu)
        if fmu.lower().endswith(".fmu") or "/" in fmu or "\\" in fmu:
            fmu_path = path.parent / fmu
            if not _is_file(fmu_path):
                raise r.error(f"{where}.fmu", f"expected an FMU file, found no file {_path_text(fmu_path)}")
        else:
            fmu_path = folder / f"{fmu}.fmu"
            if not _is_file(fmu_path):
                shown = _path_text(folder, 80)
                name_shown = f"{fmu}.fmu" if len(fmu) <= 40 else abbreviate(f"{fmu}.fmu", 40)
                # the folder named once: a message's length must not grow twice with a long path
                raise r.error(f"{where}.fmu", f"no FMU {name_shown} in {shown} (build the FMUs into that "
                              f"folder with `lpvest build --out FOLDER`, or point --fmus or fmu_dir at theirs)")
        params = spec.table("parameters", required=False, what="a table of start values")
        for pname, value in params.items():
            if isinstance(value, dict) or (isinstance(value, list) and any(isinstance(v, dict | list)
                                                                           for v in value)):
                raise r.expected(params.path(pname), "a number, string, boolean or a list of them", value)
        feed = spec.boolean("feedthrough", None)
        components.append(Component(name, fmu_path, dict(params), feed))
    names = [c.name for c in components]

    # connections, record, plots
    connections: list[str] = []
    for i, text in enumerate(data.strings("connections", [])):
        where = element_path("connections", i)
        try:
            c = Connection.parse(text)
        except CoSimulationError:
            raise r.error(where, f"expected 'comp.output -> comp.input', found {abbreviate(text)}") from None
        _variable(r, c.source, where, names)
        _variable(r, c.target, where, names)
        connections.append(text)
    record = None
    if "record" in data:
        record = data.strings("record")
        for i, text in enumerate(record):
            _variable(r, text, element_path("record", i), names)
    plots: list[tuple[str, ...]] = []
    panels = data.array("plots", [], what="a list of panels (lists of variables)")
    for i, panel in enumerate(panels):
        where = element_path("plots", i)
        if not isinstance(panel, list) or not panel or not all(isinstance(v, str) for v in panel):
            raise r.expected(where, "a non-empty list of variable names", panel)
        for v in panel:
            _variable(r, v, where, names)
        plots.append(tuple(panel))
    return CoSimFile(path, title, tuple(components), tuple(connections), h, n_steps, t0,
                     None if record is None else tuple(record), tuple(plots), folder)
