"""FMUs for the co-simulation master's tests that run in this process: a ``.fmu`` holding only
its model description (what the master reads), and a stand-in for fmpy's ``FMU2Slave`` that
runs a small Python model and records every FMI call in order. The master calls the stand-in's
``_functions`` with the same ctypes arrays it hands fmpy's (value references, buffers), so what
it sets, reads and steps, and in which order, is what a real FMU would see."""

from __future__ import annotations

import zipfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

#: every FMI call of every stand-in instance: (instance name, function, details)
CALLS: list[tuple[str, str, Any]] = []

# name: (causality, type, start, dependencies of an output: None = all inputs, "" = none); the type of
# an Enumeration variable is "Enumeration:<declared type>" (a type of write_fmu's ``enumerations``)
Variables = list[tuple[str, str, str, Any, Any]]

_TAG = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "String": "String"}


def write_fmu(folder: Path, identifier: str, variables: Variables,
              enumerations: Mapping[str, Sequence[tuple[str, int]]] | None = None) -> Path:
    """``<identifier>.fmu`` with a modelDescription.xml only (value references 0, 1, ...);
    ``enumerations``: the Enumeration types it declares, by name, as their items (name, value)."""
    rows, outputs = [], []
    for vr, (name, causality, typ, start, _deps) in enumerate(variables):
        variability = {"parameter": "fixed", "input": "discrete", "output": "discrete"}[causality] \
            if typ != "String" else ("fixed" if causality == "parameter" else "discrete")
        initial = ' initial="exact"' if causality == "output" else ""
        value = str(start).lower() if typ == "Boolean" else start
        tag, _, declared = typ.partition(":")
        element = f'<{tag} declaredType="{declared}" start="{value}"/>' if declared else \
            f'<{_TAG[tag]} start="{value}"/>'
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
                    f'variability="{variability}"{initial}>{element}</ScalarVariable>')
    types = [f'    <SimpleType name="{n}"><Enumeration>'
             + "".join(f'<Item name="{i}" value="{v}"/>' for i, v in items) + "</Enumeration></SimpleType>"
             for n, items in (enumerations or {}).items()]
    index = {v[0]: i + 1 for i, v in enumerate(variables)}
    for name, causality, _typ, _start, deps in variables:
        if causality != "output":
            continue
        if deps is None:
            outputs.append(f'      <Unknown index="{index[name]}"/>')
        else:
            listed = " ".join(str(index[d]) for d in deps)
            outputs.append(f'      <Unknown index="{index[name]}" dependencies="{listed}"/>')
    xml = "\n".join([
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<fmiModelDescription fmiVersion="2.0" modelName="{identifier}" guid="{{{identifier}}}" '
        'variableNamingConvention="structured">',
        f'  <CoSimulation modelIdentifier="{identifier}" canHandleVariableCommunicationStepSize="true"/>',
        *(["  <TypeDefinitions>", *types, "  </TypeDefinitions>"] if types else []),
        "  <ModelVariables>", *rows, "  </ModelVariables>",
        "  <ModelStructure>", "    <Outputs>", *outputs, "    </Outputs>", "  </ModelStructure>",
        "</fmiModelDescription>", ""])
    path = folder / f"{identifier}.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", xml)
    return path


class Model:
    """A model behind a stand-in: values by value reference, ``outputs`` and ``step`` per model."""

    variables: Variables = []

    def __init__(self) -> None:
        self.values: dict[int, Any] = {vr: v[3] for vr, v in enumerate(self.variables)}
        self.names = {v[0]: vr for vr, v in enumerate(self.variables)}
        self.time = 0.0

    def __getitem__(self, name: str) -> Any:
        return self.values[self.names[name]]

    def __setitem__(self, name: str, value: Any) -> None:
        self.values[self.names[name]] = value

    def outputs(self) -> None:
        """Compute the outputs from the inputs and the state."""

    #: what fmi2GetBooleanStatus(fmi2Terminated) and fmi2GetRealStatus(fmi2LastSuccessfulTime)
    #: answer after a step (None: the query returns fmi2Discard, "not available", FMI 2.0 4.2.3)
    terminated: bool | None = None
    last_successful_time: float | None = None

    def step(self, t: float, h: float) -> int | None:
        """Advance from ``t`` by ``h``; a status other than 0 (fmi2OK) is what fmi2DoStep returns."""
        return 0


class FakeSlave:
    """Stands in for ``fmpy.fmi2.FMU2Slave``; ``MODELS`` maps a model identifier to its class."""

    MODELS: dict[str, type[Model]] = {}
    #: (instance name, function) -> status a call returns instead of running (or an exception it raises)
    FAIL: dict[tuple[str, str], Any] = {}
    #: (instance name, function) -> the bytes a failing call logs (default: "<function> failed in <instance> 100%%")
    MESSAGES: dict[tuple[str, str], bytes] = {}

    def __init__(self, guid: str, unzipDirectory: str, modelIdentifier: str, instanceName: str) -> None:
        self.name, self.identifier = instanceName, modelIdentifier
        assert Path(unzipDirectory, "modelDescription.xml").is_file() and guid == f"{{{modelIdentifier}}}"
        self.model: Model = self.MODELS[modelIdentifier]()
        self.component: Any = None
        self.logger: Any = None
        self._functions: dict[str, Callable[..., int]] = {
            "fmi2GetReal": self._get, "fmi2GetInteger": self._get, "fmi2GetBoolean": self._get,
            "fmi2SetReal": self._set, "fmi2SetInteger": self._set, "fmi2SetBoolean": self._set,
            "fmi2DoStep": self._do_step,
            "fmi2GetBooleanStatus": self._boolean_status, "fmi2GetRealStatus": self._real_status,
        }

    def _record(self, what: str, detail: Any = None) -> int:
        CALLS.append((self.name, what, detail))
        status = self.FAIL.get((self.name, what), 0)
        if callable(status) and not isinstance(status, BaseException):
            status = status()  # a status that depends on the calls so far
        if isinstance(status, BaseException):
            raise status
        if status and self.logger is not None:
            message = self.MESSAGES.get((self.name, what), f"{what} failed in {self.name} 100%%".encode())
            self.logger(None, None, status, b"logStatusError", message)
        return status

    def _get(self, component: Any, vrs: Any, n: int, buf: Any) -> int:
        assert component is self.component
        self.model.outputs()
        names = [self.model.variables[vrs[i]][0] for i in range(n)]
        for i in range(n):
            buf[i] = self.model.values[vrs[i]]
        return self._record("get", names)

    def _set(self, component: Any, vrs: Any, n: int, buf: Any) -> int:
        assert component is self.component
        names = []
        for i in range(n):
            self.model.values[vrs[i]] = buf[i]
            names.append(self.model.variables[vrs[i]][0])
        return self._record("set", names)

    def _do_step(self, component: Any, t: float, h: float, flag: int) -> int:
        assert component is self.component and flag == 1
        status = self._record("doStep", t)
        if status:
            return status
        status = self.model.step(t, h) or 0
        if status:
            return status
        self.model.time = t + h
        return 0

    def _boolean_status(self, component: Any, kind: int, out: Any) -> int:
        assert component is self.component
        self._record("getBooleanStatus", kind)
        if self.model.terminated is None:
            return 2
        out._obj.value = self.model.terminated  # out is ctypes.byref(fmi2Boolean)
        return 0

    def _real_status(self, component: Any, kind: int, out: Any) -> int:
        assert component is self.component
        self._record("getRealStatus", kind)
        if self.model.last_successful_time is None:
            return 2
        out._obj.value = self.model.last_successful_time
        return 0

    # the object methods the master calls (fmpy raises on an error status; so do these)
    def instantiate(self, callbacks: Any, loggingOn: bool) -> None:
        self.logger = callbacks.logger
        status = self._record("instantiate")
        self._raise(status)
        self.component = object()  # fmpy keeps no instance when fmi2Instantiate fails

    def _raise(self, status: int) -> None:
        if status > 1:
            from fmpy.fmi1 import FMICallException

            raise FMICallException(function="fake", status=status)

    def setupExperiment(self, startTime: float, stopTime: float | None = None) -> None:
        self.model.time = startTime
        self._raise(self._record("setupExperiment", (startTime, stopTime)))

    def enterInitializationMode(self) -> None:
        self._raise(self._record("enterInitializationMode"))

    def exitInitializationMode(self) -> None:
        self._raise(self._record("exitInitializationMode"))

    def _setter(self, what: str, vrs: list[int], values: list[Any]) -> None:
        for vr, v in zip(vrs, values, strict=True):
            self.model.values[vr] = v
        self._raise(self._record(what, dict(zip([self.model.variables[v][0] for v in vrs], values, strict=True))))

    def setReal(self, vrs: list[int], values: list[float]) -> None:
        self._setter("setReal", vrs, values)

    def setInteger(self, vrs: list[int], values: list[int]) -> None:
        self._setter("setInteger", vrs, values)

    def setBoolean(self, vrs: list[int], values: list[bool]) -> None:
        self._setter("setBoolean", vrs, values)

    def setString(self, vrs: list[int], values: list[str]) -> None:
        self._setter("setString", vrs, values)

    def reset(self) -> None:
        self.model = type(self.model)()
        self._raise(self._record("reset"))

    def terminate(self) -> None:
        self._raise(self._record("terminate"))

    def freeInstance(self) -> None:
        self._record("freeInstance")
        self.component = None
