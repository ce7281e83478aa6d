"""A small FMI 2.0 co-simulation driver over fmpy's FMU2Slave, for the tests."""

from __future__ import annotations

import atexit
import ctypes
import functools
import gc
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

_UNZIPPED: dict[tuple[str, int, int, int, int], str] = {}


@functools.cache
def _unzip_root() -> str:
    root = tempfile.mkdtemp(prefix="lpvest-test-unzipped-")
    atexit.register(shutil.rmtree, root, True)
    return root


def unzipped(path: str | Path) -> str:
    """The folder ``path`` is extracted to, once per process and per version of the file
    (its path, inode, size and change times), removed when the process ends. Instances made
    from one folder share the FMU's loaded library, as a host's instances do; a test that
    needs a private copy passes ``unzip`` to :class:`Driver`. (Extracting for every Driver
    left one folder per instance behind, 28 GB of them in /tmp after a day of runs.)"""
    st = os.stat(path)
    key = (os.path.abspath(path), st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    if key not in _UNZIPPED:
        _UNZIPPED[key] = extract(str(path), unzipdir=os.path.join(_unzip_root(), str(len(_UNZIPPED))))
    return _UNZIPPED[key]


class Driver:
    """One instance of an FMU: names instead of value references, the log kept,
    FMI calls that return their status instead of raising."""

    def __init__(self, path: str | Path, name: str = "instance", *, unzip: str | None = None,
                 logging_on: bool = False) -> None:
        self.path = str(path)
        self.md = read_model_description(self.path)
        self.unzip = unzip or unzipped(self.path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages: list[tuple[int, str, str]] = []
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)

        def logger(env, instance, status, category, message):  # noqa: ANN001
            self.messages.append((status, (category or b"").decode(), message.decode()))

        self._logger = fmi2CallbackLoggerTYPE(logger)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = self._logger
        callbacks.allocateMemory = ctypes.cast(None, type(callbacks.allocateMemory))
        callbacks.freeMemory = ctypes.cast(None, type(callbacks.freeMemory))
        self.fmu.instantiate(callbacks=callbacks, loggingOn=logging_on)

    def status(self, method, *args) -> int:  # noqa: ANN001, ANN002
        from fmpy.fmi1 import FMICallException

        try:
            method(*args)
            return 0
        except FMICallException as exc:
            return int(exc.status)

    def raw(self, function: str, *args) -> int:  # noqa: ANN002
        """The status an FMI function returns (warnings included)."""
        from fmpy.fmi1 import FMICallException

        try:
            return int(getattr(self.fmu, function)(self.fmu.component, *args))
        except FMICallException as exc:
            return int(exc.status)

    def initialize(self, start_time: float = 0.0, **params: float | int | bool | str) -> int:
        """setup, enter, set ``params``, exit: the most severe status."""
        st = self.raw("fmi2SetupExperiment", 0, 0.0, start_time, 0, 0.0)
        st = max(st, self.raw("fmi2EnterInitializationMode"))
        for name, value in params.items():
            st = max(st, self.set(name, value))
        return max(st, self.raw("fmi2ExitInitializationMode"))

    def set(self, name: str, value) -> int:  # noqa: ANN001
        t = self.types[name]
        setter = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
                  "Boolean": self.fmu.setBoolean, "String": self.fmu.setString}[t]
        return self.status(setter, [self.vr[name]], [value])

    def set_vector(self, base: str, values) -> int:  # noqa: ANN001
        values = np.atleast_1d(np.asarray(values, dtype=float))
        names = [f"{base}[{i + 1}]" for i in range(values.size)]
        return self.status(self.fmu.setReal, [self.vr[n] for n in names], [float(v) for v in values])

    def get(self, name: str):  # noqa: ANN201
        t = self.types[name]
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger,
                  "Boolean": self.fmu.getBoolean, "String": self.fmu.getString}[t]
        return getter([self.vr[name]])[0]

    def vector(self, base: str) -> np.ndarray:
        from lpvest.fmi._naming import parse_element

        names = sorted((n for n in self.vr if n.startswith(base + "[")), key=lambda n: parse_element(n)[1])
        if not names and base in self.vr:  # a scalar port: the variable is its name
            names = [base]
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))

    @property
    def step_size(self) -> float:
        """The default experiment's step: the sample time of a discrete-time FMU."""
        return float(self.md.defaultExperiment.stepSize)

    def step(self, t: float, h: float) -> int:
        return self.status(self.fmu.doStep, t, h)

    def errors(self) -> list[str]:
        """The messages logged at status fmi2Error or worse."""
        return [m for s, _, m in self.messages if s >= 3]

    def outputs(self, names: list[str]) -> np.ndarray:
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))

    def free(self) -> None:
        self.fmu.freeInstance()


def references_held(obj: object) -> int:
    """A lower bound of the references to ``obj``: those the garbage collector's containers
    hold (each found by ``gc.get_referrers``; a list's, tuple's or dict's counted one by one).

    Plain loops on purpose: a generator expression here would close over ``obj``, and its
    cell is one more referrer that ``gc.get_referrers`` finds, a reference counted that the
    caller's ``sys.getrefcount`` does not see (an upper bound by one, not a lower bound)."""
    count = 0
    for holder in gc.get_referrers(obj):
        if isinstance(holder, (list, tuple)):
            for item in holder:
                if item is obj:
                    count += 1
        elif isinstance(holder, dict):
            for item in holder.values():
                if item is obj:
                    count += 1
        else:
            count += 1
    return count
