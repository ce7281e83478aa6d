"""The common base of every lpvest FMU slave (pythonfmu, FMI 2.0 co-simulation).

A role script in ``fmus/`` subclasses :class:`LpvestSlave` and says three
things: its parameters (:meth:`LpvestSlave.declare`), how to build its
streaming component from them (:meth:`LpvestSlave.make_component`), and
optionally the declared range of an input and which inputs an output depends
on. The component follows the step protocol of
:mod:`lpvest.core` (ports, ``outputs(inputs)`` without state
change, ``step(inputs)``, ``reset``, ``get_state``/``set_state``); components
with ``timed = True`` take ``reset(t0)`` and ``step(inputs, dt=h, t_end=t + h)``.

What the base does for every FMU (docs/fmus.md states the conventions):

- ports become FMI variables with structured names (``y[1]``, ``P[1,1]``),
  inputs with start values, outputs listed (with their dependencies) by the
  builder, parameters with start values (variability ``fixed``);
- **step semantics.** A discrete-time component (not ``timed``) gets the
  parameter ``sample_time``: ``fmi2DoStep(t_k, h)`` with ``h = m sample_time``
  (``m >= 1`` whole, to the relative tolerance of communication points)
  runs the ``m`` samples ``k .. k + m - 1`` with the inputs held (zero-order
  hold). After ``fmi2SetReal`` of the inputs at ``t_k``, an
  output reads its value at sample ``k`` (computed on demand, before
  ``fmi2DoStep``: zero-delay masters use this). ``fmi2DoStep(t_k, h)``
  consumes its samples; until an input is set again, an output that depends
  on the inputs at the same instant (direct feedthrough: a filter's
  estimates, a plant's ``y``) holds its value of the last sample consumed,
  ``k + m - 1``, and an output that depends on none (a plant's state, a
  scheduler) reads its value at ``t_k + h``. So a host that reads after each
  one-sample step (``fmpy.simulate_fmu``, libcosim, SSP importers) records the
  estimate of sample ``k`` at ``t_k + h``. A step that is not a valid next
  step (``h <= 0`` or not finite, ``h`` not a whole number of samples, a
  communication point other than the FMU's time, after ``fmi2Terminate``,
  with an invalid input, a sample among the ``m`` that fails or has an
  output that is not finite) is refused with fmi2Error and a log line, and
  consumes nothing;
- bad input never raises into pythonfmu (that would be fmi2Fatal and leaves the
  instance unusable): a NaN/inf value, a value outside the declared range or an
  invalid parameter is rejected, logged at status fmi2Error with a message
  naming the variable, and the instance keeps its state; the lpvest status
  bridge (the FMU's binary) returns that status, so the host sees fmi2Error
  and can still free, reset or restore the instance. An output that would be
  NaN or inf is an fmi2Error naming it (and the step that would consume it is
  refused); numpy's floating-point warnings go to the FMI logger as
  fmi2Warning; every message is at most :data:`MAX_MESSAGE` characters;
- ``fmi2GetFMUstate``/``fmi2SetFMUstate`` and (de)serialization of the whole
  state: parameters, inputs, cached outputs, the component's state (with its
  random generator), time.

The FMU runs the copy of lpvest it carries under a build-unique name
(:mod:`lpvest.fmi`); this module imports pythonfmu's Python files from
their submodules so that the FMU can carry them too.
"""

from __future__ import annotations

import hashlib
import math
import struct
import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from pythonfmu.enums import Fmi2Causality, Fmi2Status, Fmi2Variability
from pythonfmu.fmi2slave import Fmi2Slave
from pythonfmu.variables import Boolean, Integer, Real, String

from .._version import __version__
from ..core._errors import ArgumentError
from ..core._interrupt import hold
from ..core._protocol import Component, Port, Sampled, Timed, whole_samples
from ._naming import element_names
from ._parameters import GUID_FILE, Parameter, read_spec
from ._state import copy_state, decode_state, encode_state

if TYPE_CHECKING:
    from ..systems._modelfile import Model, SystemFile

T = TypeVar("T")

__all__ = ["LpvestSlave", "MAX_MESSAGE", "INT32"]

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}

#: Longest log message (characters); a longer one is cut, saying how much was cut.
MAX_MESSAGE = 1000

#: The range of an FMI Integer (32-bit).
INT32 = (-(2**31), 2**31 - 1)

try:  # numpy >= 2: the floating-point error state is a context variable, set here with a prepared value
    # numpy's private API, deliberately (a prepared error state per FMU instance)
    from numpy._core._ufunc_config import _extobj_contextvar, _make_extobj  # type: ignore[attr-defined]  # not in numpy's stubs
except ImportError:  # pragma: no cover - numpy 1.x: np.errstate
    _extobj_contextvar = _make_extobj = None

#: A communication point matches the FMU's time when within this fraction of
#: ``max(|t|, h)`` (hosts accumulate time in floating point or in integer ticks),
#: and within half a sample (half the step ``h`` for a component that is a function
#: of time): far from 0 the fraction of ``|t|`` would exceed a sample, and a step of
#: several samples must not hide a skipped one.
_TIME_RTOL = 1e-9


#: The model files this FMU's instances loaded in this process, the last few: (the digest of the
#: file's bytes, the model parameter values) -> the loaded system (its models built with it).
#: fmi2Reset runs the slave's constructor again (a sweep resets the same instances for each
#: task), and each construction and each parameter set asked for the system and its model:
#: parsing the file and building the model again took half of a 20-step task. A loaded system
#: and its models cannot be changed once built (frozen dataclasses whose arrays are read-only),
#: so the instances of one FMU, wherever each was unpacked, share them; an edited file has
#: another digest and is read anew.
_LOADED: OrderedDict[tuple[bytes, tuple[tuple[str, float], ...]], SystemFile] = OrderedDict()
_LOADED_LOCK = threading.Lock()  # hosts step the instances of a co-simulation on threads of their own
#: How many loaded files are kept (a host with instances at several values of ``rho`` keeps them all).
_LOADED_MAX = 8


def _digest(path: Path) -> bytes | None:
    """The SHA-256 of the file's bytes; None when it cannot be read (then
    :func:`~lpvest.systems._modelfile.load_system` says why, naming the file)."""
    try:
        return hashlib.sha256(path.read_bytes()).digest()
    except OSError:
        return None


def _loaded(path: Path, digest: bytes | None, values: tuple[tuple[str, float], ...]) -> SystemFile:
    """The system file at ``path`` (whose bytes have the SHA-256 ``digest``) loaded with the
    model parameters ``values``: from :data:`_LOADED` when it holds the same bytes. A load is
    kept only when the file still has those bytes after it."""
    from ..systems._modelfile import load_system

    if digest is not None:
        with _LOADED_LOCK:
            found = _LOADED.get((digest, values))
            if found is not None:
                _LOADED.move_to_end((digest, values))
                return found
    found = load_system(path, parameters=dict(values))
    if digest is not None and _digest(path) == digest:
        with _LOADED_LOCK:
            _LOADED[digest, values] = found
            while len(_LOADED) > _LOADED_MAX:
                _LOADED.popitem(last=False)
    return found


def time_bits(t: float) -> str:
    """``t`` as the 16 lower-case hexadecimal digits of its IEEE 754 bits: how a
    slave states its time to the status bridge (category ``lpvest.time``), which
    reads them with strtoull, the same in every locale.

    >>> time_bits(1.25)
    '3ff4000000000000'
    """
    return f"{struct.unpack('<Q', struct.pack('<d', t))[0]:016x}"


def _num(value: float) -> str:
    """A number as short as it reads back exactly (``1.0000001``, ``-1``, ``0.3``)."""
    return repr(float(value)).removesuffix(".0")


class _WeakCall:
    """A bound method held through a weak reference to its object (a call after
    the object is gone does nothing)."""

    __slots__ = ("_ref",)

    def __init__(self, method: Callable[..., object]) -> None:
        self._ref = weakref.WeakMethod(method)

    def __call__(self, *args: object) -> None:
        method = self._ref()
        if method is not None:
            method(*args)


def _not_of_type(vr: int, e: _Element | None, fmi_type: str) -> str:
    """Why value reference ``vr`` (its element ``e``, or None) cannot be got or set as ``fmi_type``
    (the native runtime's words: check_vr in lpv_fmi2.c)."""
    vr &= 0xFFFF_FFFF  # an fmi2ValueReference (unsigned int): pythonfmu hands a large one on as negative
    if e is None:
        return f"value reference {vr} is not a variable of this FMU"
    article = "an" if fmi_type == "Integer" else "a"
    return f"value reference {vr} is the {e.fmi_type} variable {e.name}, not {article} {fmi_type} variable"


class _Element:
    """One FMI scalar variable of a port or parameter."""

    __slots__ = ("name", "kind", "owner", "index", "fmi_type", "minimum", "maximum", "label", "tol", "position")

    def __init__(self, name: str, kind: str, owner: str, index: int, fmi_type: str, label: str = "",
                 minimum: float | None = None, maximum: float | None = None) -> None:
        self.name, self.kind, self.owner, self.index, self.fmi_type = name, kind, owner, index, fmi_type
        self.minimum, self.maximum, self.label = minimum, maximum, label
        # inputs: the relative tolerance of lpvest.core.check_box; parameters: exact
        self.tol = 1e-12 * max(1.0, abs(minimum or 0.0), abs(maximum or 0.0)) if kind == "input" else 0.0
        self.position = -1  # outputs: index in the flat list of output values

    def what(self) -> str:
        return f"{self.kind} {self.name}" + (f" ({self.label})" if self.label else "")


class LpvestSlave(Fmi2Slave):
    """Base class of the lpvest slaves (see the module documentation)."""

    author = "lpvest"
    license = "MIT"

    # -- what a role script provides --------------------------------------------
    def declare(self) -> list[Parameter]:
        """The FMU's parameters (with start values)."""
        return []

    def make_component(self, params: Mapping[str, Any]) -> Any:
        """The streaming component for these parameter values."""
        raise NotImplementedError

    def input_range(self, port: Port, index: int) -> tuple[float | None, float | None, str]:
        """Declared ``(min, max, label)`` of element ``index`` of an input port."""
        return None, None, ""

    def output_range(self, port: Port, index: int) -> tuple[float | None, float | None, str]:
        """Declared ``(min, max, label)`` of element ``index`` of an output port."""
        return None, None, ""

    def output_dependencies(self, port: Port) -> list[str] | None:
        """Names of the input ports an output depends on at the same instant
        (``None``: all of them; default: all, or none for a port with
        ``direct = False``)."""
        return None if getattr(port, "direct", True) else []

    # -- helpers for role scripts ------------------------------------------------------
    def system(self, params: Mapping[str, Any] | None = None) -> SystemFile:
        """The system file carried in ``resources/``, loaded with the model
        parameters among ``params`` (e.g. ``rho``; without them, at the file's values).
        The file is read once per construction of the instance (to know its bytes: an
        instance's resources do not change while it lives; a reset constructs it again)."""
        path = Path(self.resources) / self.spec["model_file"]
        if "_model_digest" not in self.__dict__:
            self._model_digest = _digest(path)
        names = self.spec.get("model_parameters", [])
        values = tuple((n, float(params[n])) for n in names if params is not None and n in params)
        return _loaded(path, self._model_digest, values)

    def model(self, params: Mapping[str, Any] | None = None) -> Model:
        """The model this FMU was built for (see :meth:`system`)."""
        return self.system(params).model(self.spec["model_key"])

    def model_parameters(self) -> list[Parameter]:
        """The model file's ``[parameters]`` as FMU parameters."""
        system = self.system()
        out = []
        for n, v in system.parameters.items():
            if n not in self.spec.get("model_parameters", []):
                continue
            rng = system.parameter_ranges.get(n)
            what = f"model parameter {n} of {system.name}" + (f": {rng.description}" if rng and rng.description else "")
            out.append(Parameter(n, float(v), what, minimum=rng.lower if rng else None,
                                 maximum=rng.upper if rng else None))
        return out

    def scheduling_range(self, port: Port, index: int) -> tuple[float | None, float | None, str]:
        """The declared range of ``p[j]`` (the model's scheduling box) and of
        ``alpha[i]`` ([0, 1]); nothing for other ports."""
        if port.name == "alpha":
            return 0.0, 1.0, f"weight of vertex {index + 1}"
        if port.name == "p":
            space = getattr(self.model(), "space", None)
            if space is not None:
                return float(space.lower[index]), float(space.upper[index]), space.names[index]
        return None, None, ""

    # -- construction -------------------------------------------------------------
    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        self.spec = read_spec(self.resources)
        self.modelName = self.spec["identifier"]
        try:  # what binds the FMU states to this build (None while the build itself instantiates it)
            self._guid: str | None = (Path(self.resources) / GUID_FILE).read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            self._guid = None
        self.description = self.spec.get("description", "")
        self.version = __version__
        # which code runs this FMU: its own copy of lpvest (lpvest.fmi), named here
        self._log(Fmi2Status.ok, f"lpvest {__version__} ({__name__.rpartition('.fmi.')[0]})")
        self._elements: dict[int, _Element] = {}
        self._invalid: dict[str, str] = {}
        self._entered = False  # fmi2EnterInitializationMode was called (a reset constructs the slave anew)
        self._params: dict[str, Any] = {}
        self._param_defs: dict[str, Parameter] = {}
        for par in self.declare():
            self._add_parameter(par)
        component = self.make_component(self.parameters())
        self._timed = bool(getattr(component, "timed", False))
        # the parameter that is the sample time: a step runs a whole number of samples (None: a function of time)
        self._sample_time: str | None = (
            "sample_time" if not self._timed else (self.spec.get("estimator") or {}).get("sample_time"))
        self._whole: tuple[float, object, int | None] = (math.nan, math.nan, None)  # (h, sample time, samples)
        if not self._timed:
            h = float(self.spec.get("sample_time", 1.0))
            self._add_parameter(Parameter("sample_time", h, "time between samples (s): a communication step of "
                                          "m whole samples (m >= 1) runs m samples, the inputs held", minimum=0.0))
        self._input_ports = tuple(component.input_ports)
        self._output_ports = tuple(component.output_ports)
        self._inputs = {p.name: np.zeros(p.shape) for p in self._input_ports}
        self._n_outputs = 0
        for port in self._input_ports:
            self._add_port(port, "input")
        # each input starts at the point of its declared range nearest to 0 (its
        # start value in the model description: FMI wants min <= start <= max)
        for e in self._elements.values():
            if e.kind == "input":
                lo = -math.inf if e.minimum is None else e.minimum
                hi = math.inf if e.maximum is None else e.maximum
                self._inputs[e.owner].reshape(-1)[e.index] = min(max(0.0, lo), hi)
        # per input variable: (flat view of its port's array, index, lowest, highest accepted value)
        self._input_targets: dict[int, tuple[np.ndarray, int, float, float]] = {
            vr: (self._inputs[e.owner].reshape(-1), e.index,
                 -math.inf if e.minimum is None else e.minimum - e.tol,
                 math.inf if e.maximum is None else e.maximum + e.tol)
            for vr, e in self._elements.items() if e.kind == "input"}
        # every input value within its declared range (then the component skips the
        # checks fmi2SetReal made: prepare(checked=True)); None: not known yet. Values
        # enter only through the checks of fmi2SetReal (a rejected one is not stored)
        # or a restored state, so once true it stays true until a state is restored;
        # the initial zeros may lie outside a range that excludes 0.
        self._inputs_in_range: bool | None = None
        for port in self._output_ports:
            self._add_port(port, "output")
        self._feedthrough = self._direct_outputs(component)
        self._nonfinite: str | None = None
        self._store_outputs({p.name: np.full(p.shape, np.nan) for p in self._output_ports}, check=False)
        # fmi2GetReal of outputs only (what a master does every step): per list of
        # value references, the positions in the flat output list (bounded cache)
        self._output_reads: dict[tuple[int, ...], list[int]] = {}
        self._step_inputs: dict[str, np.ndarray] | None = None
        self._held: dict[str, np.ndarray] | None = None  # feedthrough outputs of the sample just consumed
        self._component: Any = None
        self._advance: Callable[..., dict[str, np.ndarray] | None] | None = None
        self._prepare: Callable[..., dict[str, np.ndarray]] | None = None
        self._preview: Any = None
        self._initialized = False
        self._terminated = False
        self._init_error = "the FMU is not initialized yet (fmi2ExitInitializationMode)"
        self._dirty = True
        self._time = 0.0
        self._start_time = 0.0
        self._stop_time: float | None = None  # fmi2SetupExperiment's, when defined: no step ends after it
        # pythonfmu 0.7 passes queued messages to the host at the end of each FMI call, but not
        # at the end of fmi2Instantiate or fmi2Reset (the two calls that run this constructor);
        # its fmi2FreeInstance then flushes what is still queued through a logger it has already
        # destroyed, and the host crashes (instantiate -> free). So nothing logged here stays in
        # the queue: it is logged at fmi2SetupExperiment (docs/fmus.md, 6.).
        self._construction_log = list(self.log_queue)
        del self.log_queue[:]

    def _direct_outputs(self, component: Sampled | Timed) -> tuple[str, ...]:
        """The outputs that depend on an input at the same instant: they hold their
        value after a step until inputs are set (the model description declares
        the dependencies of the default configuration, which includes these)."""
        if not tuple(component.input_ports):
            return ()
        return tuple(p.name for p in component.output_ports if getattr(p, "direct", True))

    @property
    def resources_path(self) -> Path:
        return Path(self.resources)

    # -- variables --------------------------------------------------------------------
    def _register(self, element: _Element, **kwargs: object) -> None:
        cls = _TYPES[element.fmi_type]
        var = cls(element.name, **kwargs)
        var.getter = lambda e=element: self._get_element(e)
        if element.kind != "output":
            var.setter = lambda value, e=element: self._set_element(e, value)
        self.register_variable(var)
        self._elements[var.value_reference] = element

    def _add_parameter(self, par: Parameter) -> None:
        if par.name in self._param_defs:
            raise ArgumentError(f"parameter {par.name!r} is declared twice")
        minimum, maximum = par.minimum, par.maximum
        if par.fmi_type == "Integer":
            # an FMI Integer is 32-bit: declare it, so that no value wraps silently
            minimum = INT32[0] if minimum is None else max(int(minimum), INT32[0])
            maximum = INT32[1] if maximum is None else min(int(maximum), INT32[1])
            if not minimum <= int(par.start) <= maximum:
                raise ArgumentError(f"parameter {par.name}: start {par.start} is outside [{minimum}, {maximum}]")
        self._param_defs[par.name] = par
        if par.shape:
            self._params[par.name] = np.array(par.start, dtype=float).reshape(par.shape)
            names = element_names(par.name, par.shape)
        else:
            self._params[par.name] = par.start
            names = [par.name]
        for i, name in enumerate(names):
            element = _Element(name, "parameter", par.name, i, par.fmi_type, minimum=minimum, maximum=maximum)
            self._register(
                element,
                causality=Fmi2Causality.parameter,
                variability=Fmi2Variability.fixed,
                description=par.description or None,
            )

    def _add_port(self, port: Port, kind: str) -> None:
        for i, name in enumerate(element_names(port.name, tuple(port.shape))):
            lo, hi, label = (self.input_range if kind == "input" else self.output_range)(port, i)
            element = _Element(name, kind, port.name, i, "Real", label, lo, hi)
            if kind == "output":
                element.position = self._n_outputs
                self._n_outputs += 1
            desc = " ".join(x for x in (port.description, f"({label})" if label else "") if x) or None
            causality = Fmi2Causality.input if kind == "input" else Fmi2Causality.output
            self._register(element, causality=causality, description=desc)

    def variable_table(self) -> dict[str, Any]:
        """For the native backend's exporter (:mod:`lpvest.fmi.native`): what
        this FMU's variables are, so that the native FMU of the role declares and
        checks exactly these.

        Returns
        -------
        dict
            ``"variables"``: per value reference (in order) a dict with
            ``name``, ``kind`` (``parameter``/``input``/``output``),
            ``owner`` (its parameter or port), ``index`` (element in it),
            ``type`` (``Real``, ...), ``minimum``, ``maximum``, ``tol``
            (the accepted excess over the range) and ``what`` (how messages
            name it); ``"parameters"``: the :class:`Parameter` definitions in
            declaration order; ``"inputs"``/``"outputs"``: the ports;
            ``"timed"``; ``"sample_time"``: the parameter that is the sample
            time, or ``None``.
        """
        variables = []
        for vr in sorted(self._elements):
            e = self._elements[vr]
            variables.append({"name": e.name, "kind": e.kind, "owner": e.owner, "index": e.index,
                              "type": e.fmi_type, "minimum": e.minimum, "maximum": e.maximum, "tol": e.tol,
                              "what": e.what()})
        return {"variables": variables, "parameters": list(self._param_defs.values()),
                "inputs": list(self._input_ports), "outputs": list(self._output_ports),
                "timed": self._timed, "sample_time": self._sample_time}

    def fmi_metadata(self) -> dict[str, Any]:
        """For the builder: per variable its declared range, per output the
        inputs it depends on (value references), whether the component keeps
        time itself (``timed``) or samples at every step (then its outputs
        are piecewise constant: variability ``discrete``)."""
        by_port: dict[str, list[int]] = {}
        for vr, e in self._elements.items():
            if e.kind == "input":
                by_port.setdefault(e.owner, []).append(vr)
        ranges = {vr: (e.minimum, e.maximum) for vr, e in self._elements.items()
                  if e.minimum is not None or e.maximum is not None}
        deps: dict[int, list[int]] = {}
        ports = {p.name: p for p in self._output_ports}
        for vr, e in self._elements.items():
            if e.kind == "output":
                names = self.output_dependencies(ports[e.owner])
                if names is None:
                    names = list(by_port)
                deps[vr] = sorted(v for n in names for v in by_port.get(n, []))
        return {"ranges": ranges, "dependencies": deps, "timed": self._timed}

    # -- values -----------------------------------------------------------------------
    def parameters(self) -> dict[str, Any]:
        """The current parameter values (vectors as arrays)."""
        return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self._params.items()}

    def _get_element(self, e: _Element) -> Any:
        if e.kind == "parameter":
            value = self._params[e.owner]
            return float(value.reshape(-1)[e.index]) if isinstance(value, np.ndarray) else value
        if e.kind == "input":
            return float(self._inputs[e.owner].reshape(-1)[e.index])
        return self._output_values[e.position]

    def _reject(self, e: _Element, message: str) -> None:
        self._invalid[e.name] = message
        self._log(Fmi2Status.error, message)

    def _set_element(self, e: _Element, value: float | int | bool | str) -> None:
        if self._terminated:
            self._log(Fmi2Status.error, f"{e.what()} cannot be set after fmi2Terminate (reset the instance)")
            return
        if e.kind == "parameter" and self._initialized:
            self._log(Fmi2Status.error, f"{e.what()} is fixed: it can be set only before fmi2ExitInitializationMode")
            return
        if e.fmi_type == "Real":
            value = float(value)
            if not math.isfinite(value):
                self._reject(e, f"{e.what()} = {value} is not finite; value rejected")
                return
            tol = e.tol
            below = e.minimum is not None and value < e.minimum - tol
            if below or (e.maximum is not None and value > e.maximum + tol):
                lo = "-inf" if e.minimum is None else _num(e.minimum)
                hi = "inf" if e.maximum is None else _num(e.maximum)
                self._reject(e, f"{e.what()} = {_num(value)} is outside its declared range [{lo}, {hi}]; "
                             "value rejected")
                return
        elif e.fmi_type == "Integer":
            value = int(value)
            if (e.minimum is not None and value < e.minimum) or (e.maximum is not None and value > e.maximum):
                bounds = f"[{'-inf' if e.minimum is None else e.minimum}, {'inf' if e.maximum is None else e.maximum}]"
                self._reject(e, f"{e.what()} = {value} is outside its declared range {bounds}; value rejected")
                return
        elif e.fmi_type == "Boolean":
            value = bool(value)
        else:
            value = str(value)
        if self._invalid:
            self._invalid.pop(e.name, None)
        if e.kind == "parameter":
            current = self._params[e.owner]
            if isinstance(current, np.ndarray):
                current.reshape(-1)[e.index] = value
            else:
                self._params[e.owner] = value
            self._preview = None
        else:
            self._inputs[e.owner].flat[e.index] = value
            self._held = None  # the inputs of the next sample are arriving
        self._dirty = True
        self._step_inputs = None

    def _input_dict(self) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in self._inputs.items()}

    def _preview_component(self) -> Any:
        """The component outputs are computed with: the configured one after
        initialization, else one built from the current parameters."""
        if self._initialized:
            return self._component
        if self._preview is None:
            self._preview = self.make_component(self.parameters())
            self._reset_component(self._preview, self._start_time)
        return self._preview

    @staticmethod
    def _reset_component(component: Any, t0: float) -> None:
        if getattr(component, "timed", False):
            component.reset(t0)
        else:
            component.reset()

    def _store_outputs(self, values: Mapping[str, np.ndarray], *, check: bool = True) -> None:
        """Keep a copy of the component's outputs, and the flat list of their
        values in the order of the output variables (what fmi2GetReal reads).
        With ``check``, a value that is not finite is remembered (named in
        :attr:`_nonfinite`): reading it is an error, and so is consuming the sample."""
        outputs = {}
        flat: list[float] = []
        for p in self._output_ports:
            a = np.asarray(values[p.name], dtype=float).reshape(p.shape)  # the component's own arrays
            outputs[p.name] = a
            flat += a.ravel().tolist()
        self._outputs, self._output_values = outputs, flat
        bad = []
        if check and not all(map(math.isfinite, flat)):  # Python floats: cheaper than numpy for a few values
            names = [n for p in self._output_ports for n in element_names(p.name, tuple(p.shape))]
            bad = [n for n, v in zip(names, flat, strict=True) if not math.isfinite(v)]
        self._nonfinite = (f"output {', '.join(bad[:5])}{' ...' if len(bad) > 5 else ''} is not finite "
                           f"(NaN or inf) at t = {_num(self._time)}") if bad else None

    def _fp_warning(self, kind: str, flag: int) -> None:
        self._log(Fmi2Status.warning, f"numpy: floating-point {kind} at t = {_num(self._time)}")

    def _compute(self, fn: Callable[[], T]) -> T:
        """Run component code with numpy's floating-point warnings sent to the FMI logger.

        What ``np.errstate(over/invalid/divide="call", under="ignore", call=...)``
        does, with the error state prepared once per instance: entering
        ``np.errstate`` builds it anew each time, which cost about a tenth of a
        co-simulation step (two FMI calls per component and step)."""
        if _extobj_contextvar is None:  # pragma: no cover - numpy 1.x
            with np.errstate(over="call", invalid="call", divide="call", under="ignore", call=self._fp_warning):
                return fn()
        extobj = self.__dict__.get("_extobj")
        if extobj is None:
            # the callback holds the slave weakly: numpy keeps it in a capsule, which the garbage
            # collector cannot look into, so a bound method there made every slave that ever
            # computed immortal (an instance leaked per fmi2FreeInstance)
            extobj = self._extobj = _make_extobj(call=_WeakCall(self._fp_warning), over="call", invalid="call",
                                                 divide="call", under="ignore")
        token = _extobj_contextvar.set(extobj)
        try:
            return fn()
        finally:
            _extobj_contextvar.reset(token)

    def _refresh(self) -> None:
        """Compute the outputs when inputs, parameters or the state changed
        (call it under :meth:`_compute`). An input rejected since was not stored: the
        outputs follow the stored (valid) inputs."""
        if not self._dirty:
            return
        component = self._preview_component()
        held = self._held
        if held is None:
            # the same copy of the inputs is handed to step() when nothing is set in between
            inputs = self._input_dict()
            prepare = self._prepare if component is self._component else None
            if prepare is not None:
                checked = self._inputs_in_range
                if not checked:
                    checked = self._inputs_in_range = all(
                        lo <= arr[i] <= hi for arr, i, lo, hi in self._input_targets.values())
                values: Mapping[str, np.ndarray] = prepare(inputs, checked=checked)
            else:
                values = component.outputs(inputs)
            self._step_inputs = inputs
        elif len(held) == len(self._output_ports):
            values = held  # every output holds its value until inputs are set: nothing to compute
        else:
            # outputs with no feedthrough at the new time; the others hold
            stale = self._input_dict()
            values = {**component.outputs(stale), **held}
        self._dirty = False
        self._store_outputs(values)

    # -- logging and the error barrier -----------------------------------------------
    def _log(self, status: Fmi2Status, message: str) -> None:
        if len(message) > MAX_MESSAGE:
            cut = len(message) - (MAX_MESSAGE - 40)
            message = message[: MAX_MESSAGE - 40] + f" ... ({cut} characters cut)"
        # pythonfmu hands the text to the host logger as a format string: escape '%'
        self.log(f"[{self.modelName}] {message}".replace("%", "%%"), status)

    def _fail(self, where: str, exc: BaseException) -> None:
        self._log(Fmi2Status.error, f"{where}: {type(exc).__name__}: {exc}")

    def _guard(self, where: str, fn: Callable[[], T], default: T) -> T:
        try:
            return fn()
        except Exception as exc:  # noqa: BLE001 - nothing may reach pythonfmu (fmi2Fatal)
            self._fail(where, exc)
            return default

    # -- FMI entry points (none of them raises) --------------------------------------
    def setup_experiment(
        self, start_time: float, stop_time: float | None = None, tolerance: float | None = None
    ) -> None:
        if self._construction_log:
            self.log_queue[:0] = self._construction_log
            self._construction_log = []

        def run() -> None:
            if self._refused_out_of_state("fmi2SetupExperiment", entering=True):
                return
            t0 = float(start_time)
            if not math.isfinite(t0):
                raise ArgumentError(f"start time {t0} is not finite")
            t1 = None if stop_time is None else float(stop_time)
            if t1 is not None and math.isnan(t1):
                raise ArgumentError("stop time nan is not a number")
            if t1 is not None and t1 < t0:
                raise ArgumentError(f"stop time {t1} is before the start time {t0}")
            self._start_time, self._stop_time = t0, t1
            self._time = t0
            self._preview = None
            self._dirty = True

        self._guard("fmi2SetupExperiment", run, None)

    def _refused_out_of_state(self, fn: str, *, entering: bool) -> bool:
        """Whether the initialization call ``fn`` is out of its FMI state (fmi2SetupExperiment,
        fmi2EnterInitializationMode: not after fmi2EnterInitializationMode;
        fmi2ExitInitializationMode: once, after it); if so the reason is logged at fmi2Error
        (the native runtime's words: refused_out_of_state in lpv_fmi2.c)."""
        why = self._lifecycle_problem(entering=entering)
        if why:
            self._log(Fmi2Status.error, f"{fn}: {why}")
        return why is not None

    def _lifecycle_problem(self, *, entering: bool) -> str | None:
        """Why a call of the initialization is out of its FMI state (:meth:`_refused_out_of_state`),
        or None."""
        if self._terminated:
            return "the FMU is terminated (fmi2Terminate was called; reset or free the instance)"
        if self._initialized:
            return ("the FMU is initialized already (fmi2ExitInitializationMode was called; reset the instance to "
                    "initialize it again)")
        if entering and self._entered:
            return "the FMU is in initialization mode already (fmi2EnterInitializationMode was called)"
        if not entering and not self._entered:
            return "the FMU is not in initialization mode (call fmi2EnterInitializationMode first)"
        return None

    def enter_initialization_mode(self) -> None:
        if not self._refused_out_of_state("fmi2EnterInitializationMode", entering=True):
            self._entered = True

    def exit_initialization_mode(self) -> None:
        if self._refused_out_of_state("fmi2ExitInitializationMode", entering=False):
            return

        def run() -> None:
            if self._invalid:
                raise ArgumentError("invalid values were set: " + "; ".join(self._invalid.values()))
            if not self._timed and not self._params["sample_time"] > 0:
                raise ArgumentError(f"parameter sample_time = {_num(self._params['sample_time'])} must be > 0")
            component = self.make_component(self.parameters())
            ports_in = tuple((p.name, tuple(p.shape)) for p in component.input_ports)
            ports_out = tuple((p.name, tuple(p.shape)) for p in component.output_ports)
            if ports_in != tuple((p.name, tuple(p.shape)) for p in self._input_ports) or ports_out != tuple(
                (p.name, tuple(p.shape)) for p in self._output_ports
            ):
                raise ArgumentError("these parameters change the FMU's inputs or outputs; rebuild the FMU instead")
            self._reset_component(component, self._start_time)
            self._component = component
            self._advance = component.advance if isinstance(component, Component) else None
            self._prepare = component.prepare if isinstance(component, Component) else None
            self._feedthrough = self._direct_outputs(component)
            self._time = self._start_time
            self._initialized = True
            self._preview = None
            self._held = None
            self._dirty = True

        try:
            run()
        except Exception as exc:  # noqa: BLE001
            self._initialized = False
            self._init_error = f"initialization failed: {exc}"
            self._log(Fmi2Status.error, f"fmi2ExitInitializationMode: {exc}")

    def terminate(self) -> None:
        self._terminated = True

    def _step_problem(self, t: float, h: float) -> str | None:
        """Why ``fmi2DoStep(t, h)`` is not a valid next step, or ``None``."""
        if self._terminated:
            return "the FMU is terminated (fmi2Terminate was called; reset or free the instance)"
        if not self._initialized:
            return self._init_error
        if not (math.isfinite(t) and math.isfinite(h)):
            return f"the communication point t = {_num(t)} and step h = {_num(h)} must be finite"
        if h <= 0:
            return f"the communication step h = {_num(h)} must be > 0"
        unit = h if self._sample_time is None else min(h, self._sample_length())
        if abs(t - self._time) > min(_TIME_RTOL * max(abs(t), abs(self._time), h), 0.5 * unit):
            return (f"the communication point t = {_num(t)} is not the FMU's current time {_num(self._time)} "
                    "(a skipped or repeated point; restore a state with fmi2SetFMUstate to go back)")
        if self._stop_time is not None and t + h - self._stop_time > min(
                _TIME_RTOL * max(abs(t + h), abs(self._stop_time), h), 0.5 * unit):
            return (f"the step would end at t + h = {_num(t + h)}, after the stop time {_num(self._stop_time)} "
                    "(fmi2SetupExperiment; FMI 2.0, 2.1.6)")
        if self._sample_time is not None and self._samples_in(h) is None:
            ts = self._sample_length()
            if _TIME_RTOL * (h / ts) >= 0.5:  # whole_samples cannot tell m from m + 1 any more
                return (f"the communication step h = {_num(h)} is {_num(h / ts)} samples of the sample time "
                        f"{_num(ts)}, more than one step runs (fewer than 500000000 = 0.5 / 1e-9, the relative "
                        "time tolerance; split it into shorter steps)")
            return (f"the communication step h = {_num(h)} is not a whole number of samples of the sample time "
                    f"{_num(ts)} (a step runs m >= 1 samples; set the parameter {self._sample_time})")
        if self._invalid:
            return (f"invalid input(s) {', '.join(self._invalid)} (set valid values, restore a state with "
                    "fmi2SetFMUstate, or reset)")
        return None

    def _samples_in(self, h: float) -> int | None:
        """How many samples the step ``h`` runs (``h = m`` times the sample time,
        :func:`lpvest.core.whole_samples`); ``None``: not a whole number.
        A component that is a function of time (no sample time) runs one step."""
        if self._sample_time is None:
            return 1
        ts = self._params[self._sample_time]
        last = self._whole  # the last answer: a master steps by the same h again and again
        if last[0] == h and last[1] == ts:
            return last[2]
        m = whole_samples(h, float(ts), rtol=_TIME_RTOL)
        self._whole = (h, ts, m)
        return m

    def _sample_length(self) -> float:
        """The sample time (the value of the parameter :attr:`_sample_time` names)."""
        assert self._sample_time is not None
        return float(self._params[self._sample_time])

    def do_step(self, current_time: float, step_size: float) -> bool:
        try:
            return bool(self._compute(lambda: self._do_step(float(current_time), float(step_size))))
        except Exception as exc:  # noqa: BLE001
            self._fail(f"fmi2DoStep at t = {_num(current_time)}", exc)
            return False

    def _do_step(self, t: float, h: float) -> bool:
        hold("fmu-step")  # the interruption tests' hook (lpvest.core); nothing otherwise
        problem = self._step_problem(t, h)
        if problem is None:
            if self._held is not None:
                # no input was set since the last step: this sample has the same inputs
                self._held = None
                self._dirty = True
            # the outputs of this sample (and the inputs step() reuses): refused when not finite
            self._refresh()
            problem = self._nonfinite
        if problem is not None:
            self._log(Fmi2Status.error, f"fmi2DoStep refused at t = {_num(t)} (h = {_num(h)}): {problem}")
            return False
        component = self._component
        inputs = self._step_inputs
        current = self._outputs
        self._step_inputs = None
        m = self._samples_in(h)
        assert m is not None  # checked by _step_problem
        saved = component.get_state() if m > 1 else None  # a refused sample of the m consumes none of them
        # a timed component with a sample time (the B-spline observer) takes its m samples one by one
        h1 = h if m == 1 else self._sample_length()
        # the outputs were computed for these very inputs: the component takes the step it kept
        advanced = inputs is not None and self._advance is not None and (
            self._advance(dt=h1, t_end=t + h1 if m > 1 else t + h) if self._timed else self._advance()) is not None
        if not advanced:
            inputs = inputs if inputs is not None else self._input_dict()
            if self._timed:
                component.step(inputs, dt=h1, t_end=t + h1 if m > 1 else t + h)
            else:
                component.step(inputs)
        if m > 1:
            assert saved is not None
            held = inputs if inputs is not None else self._input_dict()
            last = self._more_samples(t, h, m, held, saved)
            if last is None:
                self._dirty = True  # the sample-k outputs are computed again (the same numbers)
                return False
            current = last
        self._time = t + h
        # feedthrough outputs hold the value of the sample just consumed; with none, nothing holds
        self._held = {name: current[name] for name in self._feedthrough} if self._feedthrough else None
        self._dirty = True
        return True

    def _more_samples(self, t: float, h: float, m: int, inputs: dict[str, np.ndarray],
                      saved: Mapping[str, object]) -> dict[str, np.ndarray] | None:
        """Samples 2..m of a step of m samples, the inputs held (zero-order hold):
        the outputs of the last one, or ``None`` (logged) when one of them fails
        or has an output that is not finite; the component is then put back to
        ``saved``, its state before the step, so the step consumes nothing."""
        component = self._component
        checked = bool(self._inputs_in_range)
        ts = self._sample_length()
        problem = None
        values: Mapping[str, np.ndarray] = {}
        for i in range(1, m):
            try:
                if self._timed:  # the sample of t + i ts, ending at the master's point t + h after the last
                    values = component.step(inputs, dt=ts, t_end=t + h if i == m - 1 else t + (i + 1) * ts)
                elif self._prepare is not None and self._advance is not None:
                    values = self._prepare(inputs, checked=checked)
                    self._advance()
                else:
                    values = component.step(inputs)
            except Exception as exc:  # noqa: BLE001 - logged below, nothing reaches pythonfmu
                problem = f"{type(exc).__name__}: {exc}"
            else:
                bad = self._not_finite(values)
                if bad:
                    problem = f"output {', '.join(bad[:5])}{' ...' if len(bad) > 5 else ''} is not finite (NaN or inf)"
            if problem is not None:
                component.set_state(saved)
                self._log(Fmi2Status.error, f"fmi2DoStep refused at t = {_num(t)} (h = {_num(h)}, {m} samples): "
                          f"sample {i + 1} of {m} (at t = {_num(t + i * ts)}): {problem}; nothing consumed")
                return None
        return dict(values)

    def _not_finite(self, values: Mapping[str, np.ndarray]) -> list[str]:
        """The output variables among ``values`` (by port) that are NaN or inf."""
        bad = []
        for p in self._output_ports:
            a = np.asarray(values[p.name], dtype=float).reshape(-1)
            if not np.isfinite(a).all():
                names = element_names(p.name, tuple(p.shape))
                bad += [n for n, v in zip(names, a.tolist(), strict=True) if not math.isfinite(v)]
        return bad

    def _get(self, vrs: list[int], fmi_type: str, nan: Any) -> list[Any]:
        found = [self._elements.get(vr) for vr in vrs]
        elements: list[_Element] = []
        for vr, e in zip(vrs, found, strict=True):
            if e is None or e.fmi_type != fmi_type:
                self._log(Fmi2Status.error, f"fmi2Get{fmi_type}: {_not_of_type(vr, e, fmi_type)}")
                return [nan] * len(vrs)
            elements.append(e)
        if any(e.kind == "output" for e in elements):
            self._guard(f"fmi2Get{fmi_type} (computing the outputs)", lambda: self._compute(self._refresh), None)
            if self._nonfinite is not None:
                self._log(Fmi2Status.error, f"fmi2Get{fmi_type}: {self._nonfinite}")
        return [self._get_element(e) for e in elements]

    def get_real(self, vrs: list[int]) -> list[float]:
        # fast path: outputs only (checked once per list of value references)
        key = tuple(vrs)
        positions = self._output_reads.get(key)
        if positions is None:
            elements = [self._elements.get(vr) for vr in vrs]
            if not elements or not all(e is not None and e.kind == "output" for e in elements):
                return self._guard("fmi2GetReal", lambda: self._get(vrs, "Real", math.nan), [math.nan] * len(vrs))
            if len(self._output_reads) >= 256:
                self._output_reads.clear()
            positions = self._output_reads[key] = [e.position for e in elements if e is not None]  # (all are)
        if self._dirty:
            try:
                self._compute(self._refresh)
            except Exception as exc:  # noqa: BLE001 - nothing may reach pythonfmu (fmi2Fatal)
                self._fail("fmi2GetReal (computing the outputs)", exc)
        values = self._output_values
        if self._nonfinite is not None:
            self._log(Fmi2Status.error, f"fmi2GetReal: {self._nonfinite}")
        return [values[i] for i in positions]

    def get_integer(self, vrs: list[int]) -> list[int]:
        return self._guard("fmi2GetInteger", lambda: self._get(vrs, "Integer", 0), [0] * len(vrs))

    def get_boolean(self, vrs: list[int]) -> list[bool]:
        return self._guard("fmi2GetBoolean", lambda: self._get(vrs, "Boolean", False), [False] * len(vrs))

    def get_string(self, vrs: list[int]) -> list[str]:
        return self._guard("fmi2GetString", lambda: self._get(vrs, "String", ""), [""] * len(vrs))

    def _set(self, vrs: list[int], values: Sequence[float | int | bool | str], fmi_type: str) -> None:
        for vr, value in zip(vrs, values, strict=True):
            e = self._elements.get(vr)
            if e is None or e.fmi_type != fmi_type:
                self._log(Fmi2Status.error, f"fmi2Set{fmi_type}: {_not_of_type(vr, e, fmi_type)}")
                continue
            if e.kind == "output":
                self._log(Fmi2Status.error, f"fmi2Set{fmi_type}: {e.name} is an output; it cannot be set")
                continue
            self._set_element(e, value)

    def set_real(self, vrs: list[int], values: list[float]) -> None:
        try:
            # fast path (what a master does every step): inputs only, each finite and in its range;
            # a call of no elements sets nothing (FMI 2.0, 2.1.7), so the held outputs stay
            targets = self._input_targets
            if vrs and self._initialized and not self._terminated and not self._invalid:
                found = [targets.get(vr) for vr in vrs]
                if all(t is not None and math.isfinite(v) and t[2] <= v <= t[3]
                       for t, v in zip(found, values, strict=True)):
                    for t, v in zip(found, values, strict=True):
                        t[0][t[1]] = v  # type: ignore[index]  # t is not None: checked just above (hot path)
                    self._held = None
                    self._dirty = True
                    self._step_inputs = None
                    return
            self._set(vrs, values, "Real")
        except Exception as exc:  # noqa: BLE001 - nothing may reach pythonfmu (fmi2Fatal)
            self._fail("fmi2SetReal", exc)

    def set_integer(self, vrs: list[int], values: list[int]) -> None:
        self._guard("fmi2SetInteger", lambda: self._set(vrs, values, "Integer"), None)

    def set_boolean(self, vrs: list[int], values: list[bool]) -> None:
        self._guard("fmi2SetBoolean", lambda: self._set(vrs, values, "Boolean"), None)

    def set_string(self, vrs: list[int], values: list[str]) -> None:
        self._guard("fmi2SetString", lambda: self._set(vrs, values, "String"), None)

    # -- FMU state ---------------------------------------------------------------------
    def _snapshot(self) -> dict[str, object]:
        return {
            "identifier": self.modelName,
            "guid": self._guid,
            "params": copy_state(self._params),
            "inputs": copy_state(self._inputs),
            "outputs": copy_state(self._outputs),
            "held": copy_state(self._held),
            "invalid": dict(self._invalid),
            "initialized": self._initialized,
            "terminated": self._terminated,
            "init_error": self._init_error,
            "dirty": self._dirty,
            "time": self._time,
            "start_time": self._start_time,
            "component": self._component.get_state() if self._initialized else None,
        }

    def _get_fmu_state(self) -> bytes:
        """The whole state, already serialized (pythonfmu keeps it as the opaque
        fmi2FMUstate and hands it to :meth:`_fmu_state_to_bytes`)."""
        return self._guard("fmi2GetFMUstate", lambda: encode_state(self._snapshot()), b"")

    def _set_fmu_state(self, state: bytes) -> None:
        def run() -> None:
            snap = decode_state(bytes(state))
            if snap.get("identifier") != self.modelName or snap.get("guid") != self._guid:
                raise ArgumentError(f"the state belongs to {snap.get('identifier')!r}, not to {self.modelName!r}"
                                    + (" (another build of it)" if snap.get("identifier") == self.modelName else ""))
            params = snap["params"]
            if set(params) != set(self._params):
                raise ArgumentError("the state's parameters do not match this FMU")
            # every field read before anything is assigned: a refused state changes nothing
            inputs = {k: np.asarray(snap["inputs"][k], dtype=float).reshape(v.shape) for k, v in self._inputs.items()}
            outputs = {
                k: np.asarray(snap["outputs"][k], dtype=float).reshape(v.shape) for k, v in self._outputs.items()
            }
            held = snap.get("held")
            if held is not None:
                held = {k: np.asarray(held[k], dtype=float).reshape(self._outputs[k].shape) for k in self._feedthrough}
            invalid = {str(k): str(v) for k, v in dict(snap["invalid"]).items()}
            initialized, terminated = bool(snap["initialized"]), bool(snap.get("terminated", False))
            init_error, dirty = str(snap["init_error"]), bool(snap["dirty"])
            time, start_time = float(snap["time"]), float(snap["start_time"])
            if not (math.isfinite(time) and math.isfinite(start_time)):
                raise ArgumentError(f"the state's time ({time}, started at {start_time}) is not finite")
            component = None
            if initialized:
                component = self.make_component(params)
                component.set_state(snap["component"])
            self._advance = component.advance if isinstance(component, Component) else None
            self._prepare = component.prepare if isinstance(component, Component) else None
            self._params = params
            for name, value in inputs.items():  # in place: the fast set_real writes into these arrays
                self._inputs[name][...] = value
            self._inputs_in_range = None
            self._time, self._start_time = time, start_time
            # outputs to compute again are checked then; the restored ones (not dirty) now: a step
            # refused for an output that is not finite stays refused after a restore
            self._store_outputs(outputs, check=not dirty)
            self._held = held
            self._step_inputs = None
            self._invalid = invalid
            self._initialized, self._terminated = initialized, terminated
            self._init_error, self._dirty = init_error, dirty
            self._component = component
            self._preview = None
            # the status bridge reports this time as fmi2LastSuccessfulTime (lpvest/fmi/status_bridge.c),
            # sent as the 16 hexadecimal digits of its bits: strtod would read "1.25" as 1 in a host
            # whose locale writes a decimal comma
            self.log(time_bits(self._time), Fmi2Status.ok, "lpvest.time")

        self._guard("fmi2SetFMUstate", run, None)

    @staticmethod
    def _fmu_state_to_bytes(state: object) -> bytes:
        return bytes(state) if isinstance(state, bytes | bytearray) else b""

    @staticmethod
    def _fmu_state_from_bytes(state: bytes) -> bytes:
        return bytes(state)
