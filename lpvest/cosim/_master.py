"""A fixed-step co-simulation master over fmpy's ``FMU2Slave``.

Components and connections are given by variable name; the master derives an
execution order from the connection graph so that an output computed from an
input at communication point ``t_k`` reaches its consumers at the same
``t_k`` (no accidental one-step delay): at every step it sets and reads
variables in dependency order, records, then calls ``doStep`` on every
component. Direct feedthrough is read from each FMU's ``ModelStructure``
(an output without a ``dependencies`` list depends on every input, as FMI 2.0
says) and can be overridden per component. A cycle through feedthrough paths is
an algebraic loop and a clear error. The order is a pure function of that data
(``_graph.py``: :func:`~lpvest.cosim._graph.evaluation_order`).

Per step the master makes one ``fmi2SetReal`` and one ``fmi2GetReal`` per
component at most (value references looked up once; only outputs that are
connected or recorded are read), writes every value it reads into one numpy
array (a set whose sources lie next to each other there passes that memory to
the FMU as is), and records a row by one copy. Set-up errors carry the field
of a co-simulation file they are about (:attr:`CoSimulationError.where`).

Examples
--------
>>> sim = CoSimulation(
...     [Component("sched", "PeixotoEx1Scheduler.fmu"),
...      Component("plant", "PeixotoEx1Plant.fmu"),
...      Component("filter", "PeixotoEx1HinfPD.fmu")],
...     ["sched.alpha -> plant.alpha", "sched.alpha -> filter.alpha",
...      "plant.y -> filter.y"],
...     step_size=1.0)                                        # doctest: +SKIP
>>> result = sim.run(200)                                     # doctest: +SKIP
>>> result["time"], result["filter.zhat[1]"]                  # doctest: +SKIP
"""

from __future__ import annotations

import math
import re
import shutil
import sys
import tempfile
import warnings
import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from ..core._errors import LpvestError, abbreviate, shorten
from ..core._interrupt import interruptible, raise_if_pending
from ..core._toml import close_match, field_path
from ._errors import CoSimulationError
from ._graph import Block, batches, evaluation_order

if TYPE_CHECKING:
    from ..core._typing import FmpyFmu, FmpyModelDescription

T = TypeVar("T")
#: A start value as the Python type of its FMI type (see ``_convert``).
FmiValue = float | int | bool | str

__all__ = [
    "Component",
    "Connection",
    "CoSimulation",
    "DiscardedStep",
    "DiscardedStepWarning",
    "simulate",
    "whole_steps",
    "step_count",
]


class DiscardedStepWarning(UserWarning):
    """A component discarded a step (fmi2Discard): the run stopped there and
    its result ends at that step's communication point
    (:attr:`CoSimulation.discarded` tells more)."""


@dataclass(frozen=True)
class DiscardedStep:
    """Where a run stopped because a component's ``fmi2DoStep`` returned
    fmi2Discard (:attr:`CoSimulation.discarded`).

    Parameters
    ----------
    component : str
        The component that discarded the step.
    time : float
        The communication point ``t_k`` the discarded step started from: the
        result's last row.
    steps : int
        The steps completed (``k``; the result has ``k + 1`` rows).
    last_successful_time : float or None
        The component's ``fmi2LastSuccessfulTime`` (from ``time`` up to
        ``time`` plus a step); ``None``: it does not say.
    terminated : bool or None
        The component's ``fmi2Terminated``: it asks to end the simulation
        (``True``), or only could not complete this step (``False``);
        ``None``: it does not say.
    message : str
        The warning's text (one line, with the component's last message).
    """

    component: str
    time: float
    steps: int
    last_successful_time: float | None
    terminated: bool | None
    message: str


@dataclass(frozen=True)
class Component:
    """One FMU instance in a co-simulation.

    Parameters
    ----------
    name : str
        Instance name, used as prefix ``name.variable`` in connections and
        results (a Python identifier).
    fmu : str or Path
        The ``.fmu`` file.
    parameters : mapping or None, optional
        Start values of parameters (or any settable variable) by name
        (an Enumeration's by item name or value); ``None``: none.
    feedthrough : bool, optional
        Override the FMU's declared dependencies: ``False`` means no output
        depends on a current input (e.g. ``y = C x``), ``True`` every output
        does. Default: read from the FMU's model description.

    Raises
    ------
    CoSimulationError
        ``parameters`` is neither a mapping nor ``None``.
    """

    name: str
    fmu: str | Path
    parameters: Mapping[str, object] = field(default_factory=dict)
    feedthrough: bool | None = None

    def __post_init__(self) -> None:
        if self.parameters is None:
            object.__setattr__(self, "parameters", {})
        elif not isinstance(self.parameters, Mapping):
            raise CoSimulationError(
                f"component {abbreviate(self.name, 30)}: parameters: expected a mapping of variable names to start "
                f"values, found {type(self.parameters).__name__}", where=f"components.{abbreviate(self.name, 30)}")


@dataclass(frozen=True)
class Connection:
    """``source`` (``"comp.output"``) drives ``target`` (``"comp.input"``).

    A vector name (``"plant.y"``) connects every element ``y[1], y[2], ...``.

    Parameters
    ----------
    source : str
        The driving output, ``"comp.output"``.
    target : str
        The driven input, ``"comp.input"``.
    """

    source: str
    target: str

    @classmethod
    def parse(cls, spec: str | tuple[str, str] | Connection) -> Connection:
        """A connection from its text ``"comp.output -> comp.input"`` (or a pair).

        Parameters
        ----------
        spec : str or tuple of (str, str) or Connection
            ``"source -> target"`` (whitespace around the names is dropped),
            a pair ``(source, target)``, or a connection (returned as is).

        Returns
        -------
        Connection
            The connection; the names are not checked against any FMU.

        Raises
        ------
        CoSimulationError
            If the text is not two non-empty names separated by ``->``.
        """
        if isinstance(spec, Connection):
            return spec
        if isinstance(spec, tuple):
            return cls(*spec)
        parts = [s.strip() for s in str(spec).split("->")]
        if len(parts) != 2 or not all(parts):
            raise CoSimulationError(f"connection {abbreviate(spec)}: expected 'comp.output -> comp.input'")
        return cls(parts[0], parts[1])


#: The FMI types the master exchanges and records (String variables are only
#: set, as start values), and the fmi2Get/fmi2Set call of each: an Enumeration
#: value is an fmi2Integer.
_TYPES = ("Real", "Integer", "Boolean", "Enumeration")
_CALL = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer", "Boolean": "Boolean", "String": "String"}
_CALLS = ("Real", "Integer", "Boolean")  #: the calls that exchange values at every step


@dataclass
class _Var:
    comp: int
    name: str
    vr: int
    type: str
    causality: str
    declared: str = ""  #: an Enumeration's type name
    items: tuple[tuple[str, int], ...] = ()  #: an Enumeration's items (name, value)


@dataclass
class _Unit:
    """An FMU instance and what the master knows about it."""

    spec: Component
    md: FmpyModelDescription
    fmu: FmpyFmu
    variables: dict[str, _Var]
    inputs: list[str]
    outputs: list[str]
    depends: dict[str, set[str]]  # output -> inputs it depends on
    log: list[str]
    funcs: dict[str, FmpyFmu] = field(default_factory=dict)  # the instance's fmi2 functions (ctypes)
    start_values: list[tuple[_Var, FmiValue, str]] = field(default_factory=list)  # (variable, value, parameter key)
    callbacks: FmpyFmu = None  #: the FMI callbacks given to instantiate (kept alive while the instance lives)


def _log_text(unit: _Unit) -> str:
    """The component's last message of status warning or worse (else its last
    message), on one line and shortened, for an error."""
    bad = [m for m in unit.log if not m.startswith("[OK]")]
    last = (bad or unit.log)[-1:]
    text = " ".join(" ".join(last).split())
    return (text if len(text) <= 200 else text[:197] + "...") or "no log message"


#: The range of an FMI 2.0 Integer (fmi2Integer is a 32-bit int).
_INT_RANGE = (-(2**31), 2**31 - 1)

#: fmi2Discard, the status of a step a component could not complete.
_DISCARD = 2


def _convert(
    value: object, fmi_type: str, what: str, where: str, items: Sequence[tuple[str, int]] = ()
) -> FmiValue:
    """A start value as the Python type of its FMI type (an Enumeration's:
    the value of the item given by name or value, among ``items``); a clear
    error otherwise."""
    kind = type(value).__name__
    shown = abbreviate(value, 30)
    if fmi_type == "Enumeration":
        names = dict(items)
        if isinstance(value, str) and value in names:
            return names[value]
        listed = shorten(", ".join(f"{n} = {v}" for n, v in items), 80)
        if not isinstance(value, str):
            number = _convert(value, "Integer", what, where)
            if not items or number in names.values():
                return number
        raise CoSimulationError(f"{what}: expected one of {listed} (a name or its value), found {kind} {shown}",
                                where=where)
    if fmi_type == "Real":
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
            raise CoSimulationError(f"{what}: expected a number, found {kind} {shown}", where=where)
        number = float(value)
        if not np.isfinite(number):
            raise CoSimulationError(f"{what}: expected a finite number, found {number}", where=where)
        return number
    if fmi_type == "Integer":
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating) \
                or not np.isfinite(value) or float(value) != int(value):
            raise CoSimulationError(f"{what}: expected an integer, found {kind} {shown}", where=where)
        if not _INT_RANGE[0] <= int(value) <= _INT_RANGE[1]:
            raise CoSimulationError(f"{what}: {shown} is outside the range of an FMI Integer "
                                    f"[{_INT_RANGE[0]}, {_INT_RANGE[1]}]", where=where)
        return int(value)
    if fmi_type == "Boolean":
        if not isinstance(value, bool | np.bool_):
            raise CoSimulationError(f"{what}: expected true or false, found {kind} {shown}", where=where)
        return bool(value)
    if not isinstance(value, str):
        raise CoSimulationError(f"{what}: expected a string, found {kind} {shown}", where=where)
    if "\x00" in value:
        raise CoSimulationError(f"{what}: a string may not hold a NUL character", where=where)
    return value


_DESCRIPTIONS: dict[tuple[str, int, int], FmpyModelDescription] = {}


def _model_description(path: Path, component: str, where: str) -> FmpyModelDescription:
    """fmpy's model description of the FMU at ``path`` (read once per file
    version: cached by path, size and modification time)."""
    from fmpy import read_model_description

    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if key not in _DESCRIPTIONS:
        try:
            md = read_model_description(str(path))
        except Exception as exc:  # fmpy raises plain exceptions for bad files
            text = shorten(" ".join(str(exc).split()), 80)
            raise CoSimulationError(f"component {component}: {path} is not a valid FMU: {text}", where=where) from exc
        if len(_DESCRIPTIONS) >= 64:
            _DESCRIPTIONS.pop(next(iter(_DESCRIPTIONS)))
        _DESCRIPTIONS[key] = md
    return _DESCRIPTIONS[key]


#: The index of an element of a vector or matrix variable, ``[2]`` or ``[1,2]``, at the end of its name.
_ELEMENT_INDEX = r"\[(\d+(?:,\d+)*)\]$"


def _expand(names: Iterable[str], base: str) -> list[str]:
    """Elements of a vector/matrix variable ``base`` in index order, or ``[base]``."""
    if base in names:
        return [base]
    pat = re.compile(re.escape(base) + _ELEMENT_INDEX)
    found = []
    for n in names:
        m = pat.match(n)
        if m:
            found.append((tuple(int(i) for i in m.group(1).split(",")), n))
    return [n for _, n in sorted(found)]


def whole_steps(start_time: float, stop_time: float, step_size: float) -> int:
    """The number of steps of ``step_size`` from ``start_time`` to ``stop_time``,
    which must be a whole number (to 1e-9 relative), as in a co-simulation file.

    Parameters
    ----------
    start_time, stop_time : float
        The interval.
    step_size : float
        The communication step (> 0).

    Returns
    -------
    int
        ``(stop_time - start_time) / step_size``, rounded; at least 0.

    Raises
    ------
    CoSimulationError
        ``stop_time`` is not finite, before ``start_time``, or not a whole
        number of steps after it.

    Examples
    --------
    >>> whole_steps(0.0, 0.3, 0.1)
    3
    """
    n, ratio = step_count(start_time, stop_time, step_size)
    if not math.isfinite(ratio):
        raise CoSimulationError(f"stop_time = {stop_time!r}: expected start_time + a whole number of steps of "
                                f"{step_size:g} (more steps than a float can count)")
    if n is None or n < 0:
        raise CoSimulationError(f"stop_time = {stop_time!r}: expected start_time ({start_time:g}) + a whole "
                                f"number of steps of {step_size:g}; found {ratio:.6g} steps")
    return n


#: The variables a message lists when a name is not found, by what was asked for: the
#: list's label and the causalities it holds (any, for what is not here: a recorded variable).
_HINT_LISTS: dict[str, tuple[str, tuple[str, ...]]] = {
    "connection source": ("outputs", ("output",)),
    "connection target": ("inputs", ("input",)),
    "to set": ("settable", ("parameter", "input")),
}


def _variable_hint(name: str, variables: Mapping[str, _Var], asked: str) -> str:
    """What follows "has no variable NAME" in a message: the closest of the FMU's
    variables (a vector or matrix by its base name, ``w`` for ``w[1]``, ``P`` for
    ``P[1,2]``, as :func:`_expand` reads them) when one is close (``; did you mean
    'y'?``), else those of the kind ``asked`` for (a connection's source: the
    outputs; its target: the inputs; a start value: the parameters and inputs; a
    recorded variable: any): `` (outputs: w, y)``."""
    def base(n: str) -> str:
        return re.sub(_ELEMENT_INDEX, "", n)

    close = close_match(name, sorted({base(n) for n in variables}))
    if close is not None:
        return f"; did you mean {abbreviate(close, 30)}?"
    label, causalities = _HINT_LISTS.get(asked, ("variables", ()))
    names = sorted({base(n) for n, v in variables.items() if not causalities or v.causality in causalities})
    return f" ({label}: {shorten(', '.join(names), 60)})" if names else f" (it has no {label})"


def _parameter_field(component: str, name: str) -> str:
    """The field of a start value, ``components.C.parameters.NAME``, with the key
    written as the TOML files' messages write it (:func:`~lpvest.core._toml.key_text`:
    bare when plain, else quoted and shortened, so a message stays one line)."""
    return field_path(f"components.{component}.parameters", name)


def step_count(start_time: float, stop_time: float, step_size: float) -> tuple[int | None, float]:
    """``(n, ratio)``: ``ratio = (stop_time - start_time) / step_size`` and
    ``n`` the whole number it is (to 1e-9 relative), or ``None`` when it is
    not one (or not finite). The one rule of :func:`whole_steps` and of
    co-simulation files.

    Parameters
    ----------
    start_time, stop_time : float
        The interval.
    step_size : float
        The communication step (> 0).

    Returns
    -------
    n : int or None
        The number of steps, possibly negative; ``None``: not a whole number.
    ratio : float
        The number of steps as a float.
    """
    ratio = (float(stop_time) - float(start_time)) / float(step_size)
    if not math.isfinite(ratio):
        return None, ratio
    n = int(round(ratio))
    return (n if abs(ratio - n) <= 1e-9 * max(1.0, abs(ratio)) else None), ratio



class CoSimulation:
    """Fixed-step co-simulation of FMI 2.0 co-simulation FMUs.

    The instances are created at construction and freed by :meth:`close`
    (or a ``with`` block).

    Parameters
    ----------
    components : sequence of Component
        The FMU instances; names unique Python identifiers.
    connections : sequence of str, (source, target) or Connection
        ``"plant.y -> filter.y"``; vectors connect element-wise.
    step_size : float
        Communication step ``h``; communication points are ``t_k = t_0 + k h``
        with an integer step counter (no accumulated round-off).
    start_time : float, default 0.0
        Communication point ``t_0``.
    record : sequence of str, optional
        Variables to record (``"comp.var"``, vectors expand; Real, Integer,
        Boolean or Enumeration). Default: every output of every component but
        String ones (:attr:`not_recorded`).
    unpack_in : str or Path, optional
        An existing folder in which the FMUs are unpacked (into a new folder
        ``lpvest-cosim-*`` that :meth:`close` removes). Default: the system's
        temporary folder. A sweep's Dask worker gives its own work folder,
        which Dask purges even after the worker was killed.

    Raises
    ------
    CoSimulationError
        An invalid set-up (with :attr:`CoSimulationError.where`), or an FMU
        that cannot be loaded or instantiated.
    AlgebraicLoopError
        The connections close a loop through direct feedthrough.
    """

    def __init__(
        self,
        components: Sequence[Component],
        connections: Sequence[str | tuple[str, str] | Connection] = (),
        *,
        step_size: float,
        start_time: float = 0.0,
        record: Sequence[str] | None = None,
        unpack_in: str | Path | None = None,
    ) -> None:
        if not step_size > 0:
            raise CoSimulationError(f"step_size must be positive; found {step_size}", where="step_size")
        if unpack_in is not None and not (isinstance(unpack_in, str | Path) and Path(unpack_in).is_dir()):
            raise CoSimulationError(f"unpack_in must be an existing folder; found {abbreviate(unpack_in, 60)}",
                                    where="unpack_in")
        self.step_size = float(step_size)
        self.start_time = float(start_time)
        self._tmp = Path(tempfile.mkdtemp(prefix="lpvest-cosim-", dir=unpack_in))
        # the unpacked FMUs go with the simulation: on close(), when it is collected, or at the
        # interpreter's exit for one still alive (a worker's cached simulation)
        self._remove_tmp = weakref.finalize(self, shutil.rmtree, self._tmp, True)
        self._units: list[_Unit] = []
        self._closed = False
        self._ran = False  # run() consumed the instances; reset() before running again
        #: Where the last run stopped on a discarded step; ``None``: it ran every step.
        self.discarded: DiscardedStep | None = None
        self._components = tuple(components)  # as constructed: reset() starts from them
        try:
            self._setup(components, connections, record)
            for unit in self._units:
                self._open(unit)
            self._instantiate()
        except BaseException:
            self.close()
            raise

    @classmethod
    def check(
        cls,
        components: Sequence[Component],
        connections: Sequence[str | tuple[str, str] | Connection] = (),
        *,
        step_size: float,
        start_time: float = 0.0,
        record: Sequence[str] | None = None,
    ) -> CoSimulation:
        """Every check the constructor makes (FMU files, names, connections,
        types, algebraic loops, parameter values against each FMU's model
        description) without instantiating an FMU. Raises
        :class:`CoSimulationError` as the constructor would; returns the
        checked set-up for inspection (:attr:`execution_order`,
        :attr:`recorded`), which cannot :meth:`run`.

        Parameters
        ----------
        components : sequence of Component
            As for the constructor.
        connections : sequence of str, (source, target) or Connection
            As for the constructor.
        step_size : float
            As for the constructor.
        start_time : float, default 0.0
            As for the constructor.
        record : sequence of str, optional
            As for the constructor.

        Returns
        -------
        CoSimulation
            The checked set-up, closed (no instance).
        """
        if not step_size > 0:
            raise CoSimulationError(f"step_size must be positive; found {step_size}", where="step_size")
        sim = cls.__new__(cls)
        sim._closed = True  # nothing to free
        sim.discarded = None
        sim._units = []
        sim.step_size, sim.start_time = float(step_size), float(start_time)
        sim._setup(components, connections, record)
        return sim

    def _setup(
        self,
        components: Sequence[Component],
        connections: Sequence[str | tuple[str, str] | Connection],
        record: Sequence[str] | None,
    ) -> None:
        """Read the model descriptions and check the set-up (no instance yet)."""
        names = [c.name for c in components]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise CoSimulationError(f"component names are not unique: {abbreviate(sorted(dup))}", where="components")
        for n in names:
            if not isinstance(n, str) or not n.isidentifier():
                raise CoSimulationError(f"component name {abbreviate(n, 30)} is not an identifier",
                                        where=f"components.{abbreviate(n, 30)}")
        for i, c in enumerate(components):
            self._units.append(self._describe(i, c))
        self._links = self._connect(connections)
        self._not_recorded: list[_Var] = []
        self._record = self._record_list(record)
        self._schedule = self._order()
        for unit in self._units:
            self._check_parameters(unit)

    # -- set-up ---------------------------------------------------------------
    def _describe(self, index: int, spec: Component) -> _Unit:
        """What the model description of the component's FMU says."""
        path = Path(spec.fmu)
        where = f"components.{spec.name}.fmu"
        if not path.is_file():
            raise CoSimulationError(f"component {spec.name}: FMU file {path} does not exist", where=where)
        md = _model_description(path, spec.name, where)
        if md.fmiVersion != "2.0" or md.coSimulation is None:
            raise CoSimulationError(f"component {spec.name}: {path} is not an FMI 2.0 co-simulation FMU", where=where)
        variables: dict[str, _Var] = {}
        for v in md.modelVariables:
            if v.type in _CALL:
                declared = v.declaredType
                items = tuple((i.name, int(i.value)) for i in declared.items) \
                    if v.type == "Enumeration" and declared is not None else ()
                variables[v.name] = _Var(index, v.name, v.valueReference, v.type, v.causality,
                                         declared.name if declared is not None else "", items)
        inputs = [v.name for v in md.modelVariables if v.causality == "input"]
        outputs = [v.name for v in md.modelVariables if v.causality == "output"]
        depends: dict[str, set[str]] = {}
        listed = {u.variable.name: u for u in md.outputs}
        for o in outputs:
            if spec.feedthrough is not None:
                depends[o] = set(inputs) if spec.feedthrough else set()
            elif o in listed and listed[o].dependencies is not None:
                depends[o] = {d.name for d in listed[o].dependencies if d.causality == "input"}
            else:
                depends[o] = set(inputs)  # FMI 2.0: no list = depends on all
        return _Unit(spec, md, None, variables, inputs, outputs, depends, [])

    def _open(self, unit: _Unit) -> None:
        """Unpack the component's FMU and load its binary."""
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave

        spec, md = unit.spec, unit.md
        try:
            unzip = extract(str(spec.fmu), unzipdir=str(self._tmp / spec.name))
            unit.fmu = FMU2Slave(
                guid=md.guid,
                unzipDirectory=unzip,
                modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName=spec.name,
            )
        except Exception as exc:  # fmpy raises plain exceptions for a missing binary, a bad archive
            text = shorten(" ".join(str(exc).split()), 80)
            raise CoSimulationError(f"component {spec.name}: {spec.fmu} cannot be loaded: {text}",
                                    where=f"components.{spec.name}.fmu") from exc

    def _var(self, qualified: str, what: str, where: str = "") -> list[_Var]:
        comp, sep, name = qualified.partition(".")
        if not sep:
            raise CoSimulationError(f"{what} {abbreviate(qualified)}: expected 'component.variable'", where=where)
        unit = next((u for u in self._units if u.spec.name == comp), None)
        if unit is None:
            known = ", ".join(u.spec.name for u in self._units)
            raise CoSimulationError(f"{what} {abbreviate(qualified)}: no component {abbreviate(comp, 24)} "
                                    f"(components: {shorten(known, 60)})", where=where)
        elems = _expand(unit.variables, name)
        if not elems:
            raise CoSimulationError(f"{what} {abbreviate(qualified)}: {comp} has no variable {abbreviate(name, 24)}"
                                    f"{_variable_hint(name, unit.variables, what)}", where=where)
        if len(elems) == 1 and elems[0] == name and unit.variables[name].type not in _TYPES:
            # a String variable and a vector of the same base name (the observer's
            # parameter a0 and its output a0[1]): the numeric vector is meant
            vector = _expand([n for n in unit.variables if n != name], name)
            if vector:
                elems = vector
        return [unit.variables[e] for e in elems]

    def _connect(self, connections: Sequence[str | tuple[str, str] | Connection]) -> list[tuple[_Var, _Var]]:
        links: list[tuple[_Var, _Var]] = []
        driven: dict[tuple[int, str], str] = {}
        for i, spec in enumerate(connections):
            where = f"connections[{i + 1}]"
            try:
                links += self._link(Connection.parse(spec), driven)
            except CoSimulationError as exc:
                if exc.where:
                    raise
                raise CoSimulationError(str(exc), where=where) from None
        return links

    def _link(self, c: Connection, driven: dict[tuple[int, str], str]) -> list[tuple[_Var, _Var]]:
        links: list[tuple[_Var, _Var]] = []
        src = self._var(c.source, "connection source")
        dst = self._var(c.target, "connection target")
        if len(src) != len(dst):
            raise CoSimulationError(
                f"connection {c.source} -> {c.target}: {len(src)} source and {len(dst)} target elements"
            )
        for s, d in zip(src, dst, strict=True):
            sname = f"{self._units[s.comp].spec.name}.{s.name}"
            dname = f"{self._units[d.comp].spec.name}.{d.name}"
            if s.causality != "output":
                raise CoSimulationError(f"connection source {sname} is not an output ({s.causality})")
            if d.causality != "input":
                raise CoSimulationError(f"connection target {dname} is not an input ({d.causality})")
            if s.type == "String" or d.type == "String":
                raise CoSimulationError(f"connection {sname} -> {dname}: a String variable cannot be connected "
                                        "(the master exchanges Real, Integer, Boolean and Enumeration values)")
            if s.type != d.type:
                raise CoSimulationError(f"connection {sname} -> {dname}: types {s.type} and {d.type}")
            if s.type == "Enumeration" and s.declared != d.declared:
                raise CoSimulationError(f"connection {sname} -> {dname}: Enumeration types "
                                        f"{abbreviate(s.declared, 30)} and {abbreviate(d.declared, 30)}")
            key = (d.comp, d.name)
            if key in driven:
                raise CoSimulationError(f"{dname} is driven twice (by {driven[key]} and {sname})")
            driven[key] = sname
            links.append((s, d))
        return links

    def _order(self) -> list[tuple[str, int, list[Any]]]:
        """Operations per step: ``("get", comp, [_Var, ...])`` reads outputs, ``("set",
        comp, links)`` copies upstream values into inputs, in dependency order
        (:func:`~lpvest.cosim._graph.evaluation_order`); outputs that are neither
        connected nor recorded are not read."""
        blocks = [Block(u.spec.name, u.depends) for u in self._units]
        order = evaluation_order(blocks, [((s.comp, s.name), (d.comp, d.name)) for s, d in self._links])
        link_of = {(d.comp, d.name): (s, d) for s, d in self._links}
        needed = {(s.comp, s.name) for s, _ in self._links} | {(v.comp, v.name) for v in self._record}
        return [
            (b.op, b.component,
             [link_of[b.component, n] if b.op == "set" else self._units[b.component].variables[n] for n in b.names])
            for b in batches(order, connected=link_of.keys(), read=needed)
        ]

    def _record_list(self, record: Sequence[str] | None) -> list[_Var]:
        if record is None:
            outputs = [u.variables[o] for u in self._units for o in u.outputs if o in u.variables]
            self._not_recorded = [v for v in outputs if v.type not in _TYPES]
            return [v for v in outputs if v.type in _TYPES]
        out: list[_Var] = []
        seen: set[tuple[int, str]] = set()
        for i, r in enumerate(record):
            found = self._var(r, "recorded variable", f"record[{i + 1}]")
            numeric = [v for v in found if v.type in _TYPES]
            if not numeric:
                raise CoSimulationError(
                    f"recorded variable {abbreviate(r)} is a {found[0].type}; only Real, Integer, Boolean and "
                    "Enumeration variables can be recorded", where=f"record[{i + 1}]")
            for v in numeric:
                if (v.comp, v.name) not in seen:
                    seen.add((v.comp, v.name))
                    out.append(v)
        return out

    def _check_parameters(self, unit: _Unit) -> None:
        """Every start value names settable variables and fits their type."""
        name = unit.spec.name
        values: list[tuple[_Var, FmiValue, str]] = []
        for par, value in unit.spec.parameters.items():
            where = _parameter_field(name, par)
            elems = _expand(unit.variables, par)
            if not elems:
                raise CoSimulationError(f"component {name}: no variable {abbreviate(par, 30)} to set"
                                        f"{_variable_hint(par, unit.variables, 'to set')}", where=where)
            items = value if isinstance(value, list | tuple | np.ndarray) else [value]
            flat = np.asarray(items, dtype=object).ravel().tolist()
            if len(flat) != len(elems):
                raise CoSimulationError(
                    f"component {name}: {par} has {len(elems)} element(s); {len(flat)} value(s) given", where=where
                )
            for e, val in zip(elems, flat, strict=True):
                v = unit.variables[e]
                if v.causality not in ("parameter", "input"):
                    raise CoSimulationError(f"component {name}: {e} is an {v.causality}; it cannot be set",
                                            where=where)
                values.append((v, _convert(val, v.type, f"component {name}: {e}", where, v.items), par))
        unit.start_values = values

    def _instantiate(self) -> None:
        from fmpy import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )

        # One logger per instance, called by the FMU directly. (fmpy's
        # addLoggerProxy, which would format printf-style arguments, keeps a
        # single global callback: with several instances, or any FMU
        # instantiated later in the process, messages would reach the wrong log.)
        # Messages arrive as format strings: lpvest FMUs double every '%'.
        for unit in self._units:

            def logger(_env, _inst, status, category, message, _log=unit.log):
                label = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][status] if 0 <= status < 6 else "?"
                text = (message or b"").decode("utf-8", "replace").replace("%%", "%")
                _log.append(f"[{label}] {text}")
                del _log[:-50]

            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(logger)
            callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            unit.callbacks = callbacks
            self._call(
                unit, "instantiate", lambda u=unit, cb=callbacks: u.fmu.instantiate(callbacks=cb, loggingOn=True)
            )
            unit.funcs = {n: unit.fmu._functions[n] for n in ("fmi2GetReal", "fmi2SetReal", "fmi2DoStep")}

    # -- running --------------------------------------------------------------
    def _call(
        self, unit: _Unit, what: str, fn: Callable[..., T], t: float | None = None, *, where: str | None = None
    ) -> T:
        from fmpy.fmi1 import FMICallException

        try:
            return fn()
        except (FMICallException, OSError, Exception) as exc:
            raise_if_pending()  # a signal's KeyboardInterrupt, swallowed by the FMU: not its failure
            if isinstance(exc, LpvestError):
                raise
            at = "" if t is None else f" at t = {t:g}"
            log = _log_text(unit)
            raise CoSimulationError(f"component {unit.spec.name}: {what} failed{at}: "
                                    f"{shorten(' '.join(str(exc).split()), 60)} ({log})",
                                    where=f"components.{unit.spec.name}" if where is None else where) from exc

    def _set_start_values(self, unit: _Unit) -> None:
        setters = {"Real": unit.fmu.setReal, "Integer": unit.fmu.setInteger,
                   "Boolean": unit.fmu.setBoolean, "String": unit.fmu.setString}
        for v, x, par in unit.start_values:
            self._call(unit, f"setting {v.name} = {abbreviate(x, 30)}",
                       lambda s=setters[_CALL[v.type]], r=v.vr, x=x: s([r], [x]),
                       where=_parameter_field(unit.spec.name, par))

    @interruptible
    def run(
        self,
        n_steps: int | None = None,
        *,
        stop_time: float | None = None,
        progress: bool | None = None,
        on_discard: str = "stop",
    ) -> np.ndarray:
        """Initialise and run ``n_steps`` communication steps (or up to
        ``stop_time``); return the recorded variables at ``t_0 .. t_N`` as a
        structured array with a ``"time"`` field (``N + 1`` rows).

        A component whose ``fmi2DoStep`` returns fmi2Discard could not complete
        the step (an FMU valid only up to some time asks to end the simulation
        so: ``fmi2Terminated``). A fixed-step master cannot retry a shorter
        step, so the run stops there, as FMI 2.0 leaves it to the master: the
        result ends with the row of the communication point ``t_k`` the step
        started from (every component completed it), a
        :class:`DiscardedStepWarning` says so, and :attr:`discarded` tells who,
        when, the component's ``fmi2LastSuccessfulTime`` and whether it asked
        to terminate. ``on_discard="error"`` raises instead, for callers that
        need every step.

        A tqdm progress bar is shown when ``progress`` is true (default: for
        runs longer than 20,000 steps).

        Parameters
        ----------
        n_steps : int, optional
            Communication steps to run (``0``: initialise only, one row).
        stop_time : float, optional
            Run up to ``stop_time``, which must be ``start_time`` plus a whole
            number of steps (:func:`whole_steps`); give exactly one of
            ``n_steps`` and ``stop_time``.
        progress : bool, optional
            Show a progress bar; default: for more than 20,000 steps.
        on_discard : {"stop", "error"}, default "stop"
            What a discarded step does: stop the run with a warning, or raise
            :class:`CoSimulationError`.

        Returns
        -------
        ndarray, shape (N + 1,)
            Structured array of float fields: ``"time"`` (``t_0 + k h``), then
            one per recorded element, ``"comp.var"`` (:attr:`recorded`);
            Integer, Boolean (0, 1) and Enumeration values are exact. After a
            discarded step ``k``: ``k + 1`` rows.

        Raises
        ------
        CoSimulationError
            The co-simulation is closed or has run (:meth:`reset` first), the
            step count is invalid, or a component failed: a call returned
            fmi2Error or fmi2Fatal, a get or set fmi2Discard, or
            ``fmi2DoStep`` fmi2Discard with ``on_discard="error"``.

        Warns
        -----
        DiscardedStepWarning
            A component discarded a step: the run stopped there.
        """
        if self._closed:
            raise CoSimulationError("the co-simulation is closed")
        if self._ran:
            raise CoSimulationError("the co-simulation has run; call reset() before running it again")
        if (n_steps is None) == (stop_time is None):
            raise CoSimulationError("give n_steps or stop_time")
        if n_steps is None:
            n_steps = whole_steps(self.start_time, stop_time, self.step_size)  # type: ignore[arg-type]  # not None: one of the two is given
        if n_steps < 0:
            raise CoSimulationError(f"n_steps must be non-negative; found {n_steps}")
        if on_discard not in ("stop", "error"):
            raise CoSimulationError(f"on_discard must be 'stop' or 'error'; found {abbreviate(on_discard, 30)}")
        self.discarded = None
        h, t0 = self.step_size, self.start_time
        t_end = t0 + n_steps * h
        self._ran = True
        for unit in self._units:
            self._call(unit, "setupExperiment", lambda u=unit: u.fmu.setupExperiment(startTime=t0, stopTime=t_end))
            self._set_start_values(unit)
            self._call(unit, "enterInitializationMode", unit.fmu.enterInitializationMode)
        plan = self._plan()
        self._exchange(plan, t0, initial=True)
        for unit in self._units:
            self._call(unit, "exitInitializationMode", unit.fmu.exitInitializationMode, t0)
        # recorded values: one row per communication point, copied from the
        # value store in one operation (Real) or element-wise (Integer, Boolean)
        store = self._store
        rec_cols = [self._values[(v.comp, v.name)] for v in self._record]
        data = np.empty((n_steps + 1, store.size))
        extra = [(i, buf, j) for i, (buf, j) in enumerate(rec_cols) if buf is not self._store_c]
        extra_data = np.empty((n_steps + 1, len(extra))) if extra else None
        steppers = [(u.funcs["fmi2DoStep"], u.fmu.component, u) for u in self._units]
        # by default a bar for long runs, and only on a terminal (never carriage returns into a log)
        show = progress if progress is not None else n_steps > 20_000 and sys.stderr.isatty()
        bar = None
        if show:
            from ..core._progress import progress_bar

            bar = progress_bar(desc="co-simulation", total=n_steps, unit="step", show=True)
        exchange = self._exchange
        last = n_steps  # the last row: n_steps, or the step a component discarded
        try:
            for k in range(n_steps + 1):
                t = t0 + k * h
                if k > 0:
                    exchange(plan, t)
                data[k] = store
                if extra_data is not None:
                    row = extra_data[k]
                    for col, (_, buf, j) in enumerate(extra):
                        row[col] = buf[j]
                if k == n_steps:
                    break
                for do_step, component, unit in steppers:
                    status = do_step(component, t, h, 1)
                    if status > 1:
                        if status != _DISCARD or on_discard == "error":
                            self._fail(unit, "doStep", status, t)
                        self.discarded = self._discard(unit, t, k, n_steps)
                        break
                if self.discarded is not None:
                    last = k
                    break
                if bar is not None:
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()
        dtype = [("time", "f8")] + [(f"{self._units[v.comp].spec.name}.{v.name}", "f8") for v in self._record]
        out = np.empty(last + 1, dtype=dtype)
        out["time"] = t0 + np.arange(last + 1) * h
        extra_col = {i: col for col, (i, _, _) in enumerate(extra)}
        for i, (name, _) in enumerate(dtype[1:]):
            if i in extra_col:
                out[name] = extra_data[: last + 1, extra_col[i]]  # type: ignore[index]  # an array whenever extra is not empty
            else:
                out[name] = data[: last + 1, rec_cols[i][1]]
        return out

    def _discard(self, unit: _Unit, t: float, k: int, n_steps: int) -> DiscardedStep:
        """What a discarded step of ``unit`` from ``t_k = t`` tells (its
        status queries; ``None`` where the FMU does not answer), warned about."""
        from ctypes import byref

        from fmpy.fmi2 import fmi2Boolean, fmi2LastSuccessfulTime, fmi2Real, fmi2Terminated

        flag, time = fmi2Boolean(0), fmi2Real(0.0)
        funcs, comp = unit.fmu._functions, unit.fmu.component
        terminated = bool(flag.value) if funcs["fmi2GetBooleanStatus"](comp, fmi2Terminated, byref(flag)) <= 1 \
            else None
        last = time.value if funcs["fmi2GetRealStatus"](comp, fmi2LastSuccessfulTime, byref(time)) <= 1 else None
        name = unit.spec.name
        why = {True: "it asks to end the simulation", False: "it could not complete the step",
               None: "it does not say whether it asks to end the simulation"}[terminated]
        reached = "" if last is None else f" (last successful time {last:g})"
        message = (f"component {name}: doStep at t = {t:g} returned discard: {why}{reached}; the run stops at "
                   f"t = {t:g} after {k} of {n_steps} steps ({_log_text(unit)})")
        warnings.warn(message, DiscardedStepWarning, stacklevel=3)
        return DiscardedStep(name, t, k, last, terminated, message)

    def _fail(self, unit: _Unit, what: str, status: int, t: float) -> None:
        raise_if_pending()  # a signal's KeyboardInterrupt raised inside the FMU (pythonfmu: fatal)
        label = ["ok", "warning", "discard", "error", "fatal", "pending"][status] if 0 <= status < 6 else "?"
        log = _log_text(unit)
        raise CoSimulationError(f"component {unit.spec.name}: {what} at t = {t:g} returned {label} ({log})",
                                where=f"components.{unit.spec.name}")

    def _plan(self) -> list[tuple]:
        """The per-step FMI calls with their value references and buffers.

        Every Real value read (for a connection or for the record) lands in one
        numpy array, the value store: each ``fmi2GetReal`` writes straight into
        its slice of it. A set whose sources are consecutive in the store passes
        that slice itself to ``fmi2SetReal`` (no copy); other sets copy their
        sources into a buffer of their own first.
        """
        from fmpy.fmi2 import fmi2Boolean, fmi2Integer, fmi2Real, fmi2ValueReference

        ctype = {"Real": fmi2Real, "Integer": fmi2Integer, "Boolean": fmi2Boolean}
        # the gets: for connections in schedule order, then recorded-only ones
        gets: list[tuple[int, str, list[_Var]]] = []
        for op, comp, items in self._schedule:
            if op == "get":
                for typ in _CALLS:
                    vars_ = [v for v in items if _CALL[v.type] == typ]
                    if vars_:
                        gets.append((comp, typ, vars_))
        seen = {(v.comp, v.name) for _, _, vs in gets for v in vs}
        extra: dict[tuple[int, str], list[_Var]] = {}
        for v in self._record:
            if (v.comp, v.name) not in seen:
                seen.add((v.comp, v.name))
                extra.setdefault((v.comp, _CALL[v.type]), []).append(v)
        n_real = sum(len(vs) for _, typ, vs in gets if typ == "Real")
        n_real += sum(len(vs) for (_, typ), vs in extra.items() if typ == "Real")
        self._store = store = np.zeros(max(n_real, 1))
        self._store_c = store_c = (fmi2Real * store.size).from_buffer(store)
        self._values: dict[tuple[int, str], tuple[Any, int]] = {}  # (comp, var) -> (buffer, index)
        offset = 0

        def get_op(comp: int, typ: str, vars_: list[_Var]) -> tuple:
            nonlocal offset
            unit = self._units[comp]
            n = len(vars_)
            vrs = (fmi2ValueReference * n)(*[v.vr for v in vars_])
            if typ == "Real":
                buf = (fmi2Real * n).from_buffer(store, offset * store.itemsize)
                for j, v in enumerate(vars_):
                    self._values[(comp, v.name)] = (store_c, offset + j)
                offset += n
            else:
                buf = (ctype[typ] * n)()
                for j, v in enumerate(vars_):
                    self._values[(comp, v.name)] = (buf, j)
            return ("get", unit, unit.fmu._functions[f"fmi2Get{typ}"], vrs, n, buf, ())

        ops: list[tuple[Any, ...]] = []
        get_iter = iter(gets)
        for op, comp, items in self._schedule:
            if op == "get":
                for typ in _CALLS:
                    if any(_CALL[v.type] == typ for v in items):
                        ops.append(get_op(*next(get_iter)))
            else:
                ops.append(("set", comp, items))
        # recorded variables that are not read for a connection: after every
        # set (they may depend on inputs)
        for (comp, typ), vars_ in extra.items():
            ops.append(get_op(comp, typ, vars_))
        plan: list[tuple[Any, ...]] = []
        for entry in ops:
            if entry[0] == "get":
                plan.append(entry)
                continue
            _, comp, items = entry
            unit = self._units[comp]
            for typ in _CALLS:
                links = [it for it in items if _CALL[it[1].type] == typ]
                if not links:
                    continue
                n = len(links)
                vrs = (fmi2ValueReference * n)(*[d.vr for _, d in links])
                sources = [self._values[(s.comp, s.name)] for s, _ in links]
                fn = unit.fmu._functions[f"fmi2Set{typ}"]
                first = sources[0][1]
                if typ == "Real" and all(b is store_c and i == first + j for j, (b, i) in enumerate(sources)):
                    buf = (fmi2Real * n).from_buffer(store, first * store.itemsize)
                    copies: tuple = ()
                else:
                    buf = (ctype[typ] * n)()
                    copies = tuple((j, b, i) for j, (b, i) in enumerate(sources))
                plan.append(("set", unit, fn, vrs, n, buf, copies))
        return [(op, unit, fn, unit.fmu.component, vrs, n, buf, copies) for op, unit, fn, vrs, n, buf, copies in plan]

    def _exchange(self, plan: list[tuple], t: float, *, initial: bool = False) -> None:
        for op, unit, fn, component, vrs, n, buf, copies in plan:
            for j, sbuf, si in copies:
                buf[j] = sbuf[si]
            status = fn(component, vrs, n, buf)
            if status > 1:
                what = "reading outputs" if op == "get" else "setting inputs"
                self._fail(unit, what + (" during initialization" if initial else ""), status, t)

    def reset(self, parameters: Mapping[str, Mapping[str, object]] | None = None) -> None:
        """Return every instance to its state after instantiation
        (``fmi2Reset``), so that :meth:`run` can run again without loading the
        FMUs anew (a sweep runs many tasks on the instances of one worker).

        Parameters
        ----------
        parameters : mapping, optional
            Start values per component, ``{"plant": {"seed": 4}}``, over the
            components' own ``parameters`` (a name given here replaces the
            component's value; the rest are the component's). They do not
            accumulate: each reset starts from the components as constructed.
            Checked as at construction; on an error nothing is changed.

        Raises
        ------
        CoSimulationError
            An unknown component or variable, a value of the wrong type, or
            an instance that cannot be reset.
        """
        if self._closed:
            raise CoSimulationError("the co-simulation is closed")
        parameters = dict(parameters or {})
        names = [u.spec.name for u in self._units]
        for comp in parameters:
            if comp not in names:
                raise CoSimulationError(f"reset: no component {comp!r} (components: {', '.join(names)})",
                                        where="components")
        saved = [(u.spec, u.start_values) for u in self._units]
        try:
            for unit, spec in zip(self._units, self._components, strict=True):
                extra = parameters.get(spec.name)
                unit.spec = spec if not extra else replace(spec, parameters={**spec.parameters, **extra})
                self._check_parameters(unit)
        except BaseException:
            for unit, (spec, values) in zip(self._units, saved, strict=True):
                unit.spec, unit.start_values = spec, values
            raise
        for unit in self._units:
            self._call(unit, "reset", unit.fmu.reset)
        self._ran = False
        self.discarded = None

    # -- inspection and clean-up ----------------------------------------------
    @property
    def recorded(self) -> list[str]:
        """The recorded variables, ``"comp.var"`` per element (the result's columns after ``"time"``)."""
        return [f"{self._units[v.comp].spec.name}.{v.name}" for v in self._record]

    @property
    def not_recorded(self) -> list[str]:
        """The outputs the default record leaves out, ``"comp.var"``: String
        outputs (the result holds numbers). Empty when ``record`` was given."""
        return [f"{self._units[v.comp].spec.name}.{v.name}" for v in self._not_recorded]

    @property
    def execution_order(self) -> list[str]:
        """The per-step operations, e.g. ``["get sched: p[1]", "set plant: p[1]", ...]``."""
        out = []
        for op, comp, items in self._schedule:
            name = self._units[comp].spec.name
            vars_ = [it.name if op == "get" else it[1].name for it in items]
            out.append(f"{op} {name}: {', '.join(vars_)}")
        return out

    def close(self) -> None:
        """Terminate and free every instance; remove the unpacked FMUs."""
        if self._closed:
            return
        self._closed = True
        for unit in getattr(self, "_units", []):
            comp = getattr(unit.fmu, "component", None)
            if comp is not None:
                try:
                    unit.fmu.terminate()
                except Exception:  # noqa: BLE001 - already failed; freeing matters more
                    pass
                try:
                    unit.fmu.freeInstance()
                except Exception:  # noqa: BLE001
                    pass
        self._remove_tmp()

    def __enter__(self) -> CoSimulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - safety net
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass


def simulate(
    components: Sequence[Component],
    connections: Sequence[str | tuple[str, str] | Connection],
    *,
    step_size: float,
    n_steps: int | None = None,
    stop_time: float | None = None,
    start_time: float = 0.0,
    record: Sequence[str] | None = None,
    progress: bool | None = None,
    on_discard: str = "stop",
) -> np.ndarray:
    """Build, run and close a :class:`CoSimulation` in one call.

    Parameters
    ----------
    components : sequence of Component
        The FMU instances.
    connections : sequence of str, (source, target) or Connection
        ``"plant.y -> filter.y"``; vectors connect element-wise.
    step_size : float
        Communication step ``h``.
    n_steps : int, optional
        Communication steps to run; give exactly one of ``n_steps`` and
        ``stop_time``.
    stop_time : float, optional
        Run up to this time instead (rounded to whole steps).
    start_time : float, default 0.0
        Communication point ``t_0``.
    record : sequence of str, optional
        Variables to record (``"comp.var"``); default: every output but String ones.
    progress : bool, optional
        Show a progress bar; default: for more than 20,000 steps.
    on_discard : {"stop", "error"}, default "stop"
        A discarded step stops the run with a :class:`DiscardedStepWarning`
        (fewer rows), or raises (see :meth:`CoSimulation.run`).

    Returns
    -------
    ndarray, shape (N + 1,)
        The recorded values, as :meth:`CoSimulation.run` returns them.
    """
    with CoSimulation(components, connections, step_size=step_size, start_time=start_time, record=record) as sim:
        return sim.run(n_steps, stop_time=stop_time, progress=progress, on_discard=on_discard)
