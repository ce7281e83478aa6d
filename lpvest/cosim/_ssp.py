"""A co-simulation as an SSP file (System Structure and Parameterization 1.0),
and running such a file with fmpy or libcosim.

:func:`write_ssp` writes the system of a :class:`~lpvest.cosim.CoSimulation`
(components, their parameter values, connections, the communication step) as
one ``.ssp`` archive::

    SystemStructure.ssd      the system: components, connectors, connections,
                             parameter values bound inline, default experiment
    resources/<FMU>.fmu      each FMU once (components may share one)

What the two importers make of it (checked by the tests):

=========================  ===============================  ==================================
                           ``fmpy.ssp.simulate_ssp``        libcosim (``libcosimpy``)
=========================  ===============================  ==================================
components, connections    yes                              yes
parameter bindings         **no**: it applies only the      yes (the first binding of each
(inline ``ParameterSet``)  ``parameter_set`` argument;      component; String values too)
                           :func:`simulate_ssp` passes the
                           SSD's values; String values
                           cannot be set (fmpy has no
                           setter for them: an error)
communication step         **no**: a ``step_size``          the ``com.opensimulationplatform``
                           argument (:func:`simulate_ssp`   annotation of the default
                           reads the SSD's annotation)      experiment (``FixedStepAlgorithm
                                                            baseStepSize``)
worker threads             not applicable (one thread)      ``FixedStepAlgorithm
                                                            numWorkerThreads`` (0: the calling
                                                            thread; absent: a pool)
start / stop time          arguments                        start time; the caller steps
stepping                   Jacobi, fixed order              Jacobi, in parallel or one FMU
                                                            after another (the same values)
initial inputs             0.0 for every connector          the outputs at the start time,
                                                            propagated through the connections
                                                            in initialization mode
recorded values            every connector after each       what an observer asks for, after
                           step, labelled with the step's   each step, at the step's end time
                           *start* time                     (one call per type)
variable types             Real, Integer, Boolean,          Real, Integer, Boolean, String;
                           Enumeration; **no** String       **no** Enumeration: its SSP parser
                           connector (it raises)            aborts the process on one
an input connector         **wired** to the source of the   keeps its start value
without a connection       connection looked at before it
                           (or an UnboundLocalError)
``source`` with ``%XX``    opened as written                decoded, then opened
=========================  ===============================  ==================================

:func:`simulate_ssp` checks a file against its FMUs and the importer before
it runs it, so that what the table marks **no** is one line naming the
component and the connector or parameter instead of a wrong result, a raw
``KeyError`` or a crashed process; it reads every Real, Integer, Boolean and
Enumeration output with its own type's call (a type's value references are
its own) and leaves String outputs out, as the master does. :func:`read_ssp`
decodes a ``source``'s percent-escapes before it checks that the name stays
inside the archive. :func:`write_ssp` names the FMUs in the archive without
characters that need escaping, so both importers open them.

Jacobi stepping (both importers): every component takes its step from ``t_k``
with the inputs that were read *after the previous step*, and the outputs are
read after the step. An output that does not depend on the component's inputs
at the same instant (a source's signal, a plant's state) arrives in time: a
scheduler's ``p`` read after its step to ``t_k`` is ``p_k``. An output with
direct feedthrough is read with the inputs still held from the step before:
the plant's ``y`` that reaches the filter in step ``k`` is
``y~_k = C_y(alpha_{k-1}) x_k + D_y(alpha_{k-1}) w_{k-1}`` instead of
``y_k = C_y(alpha_k) x_k + D_y(alpha_k) w_k``, and the filter estimate read
after step ``k`` is ``C_f(alpha_k) x~_{f,k+1} + D_f(alpha_k) y~_k`` with the
filter state driven by ``y~``. :class:`~lpvest.cosim.CoSimulation` orders its
calls by the connection graph instead, so ``y_k`` reaches the filter at
``t_k`` (no delay); ``tests/test_ssp.py`` measures the difference on
Peixoto et al.'s Example 1 and checks it against this relation exactly.

So :func:`write_ssp` (``jacobi=True``, the default) binds
``measurement_delay = 1`` for every filter whose measurement comes from such
an output: the filter then pairs ``y_k``, arriving in step ``k + 1``, with
``theta_k`` and the known input of sample ``k``
(:class:`~lpvest.core.MeasurementDelay`), and its estimate of sample
``k``, read after step ``k + 1``, is the estimate our master reads at
``t_k``: to the bit, with the certified bound intact.

Examples
--------
>>> from lpvest.cosim import Component
>>> path = write_ssp("system.ssp",                                        # doctest: +SKIP
...                  [Component("sched", "PeixotoEx1Scheduler.fmu"),
...                   Component("plant", "PeixotoEx1Plant.fmu")],
...                  ["sched.p -> plant.p"], step_size=1.0, stop_time=100.0)
>>> res = simulate_ssp(path, importer="libcosim")                        # doctest: +SKIP
"""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
import threading
import urllib.parse
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ..core._errors import abbreviate, shorten
from ..fmi._build import write_zip_entry
from ..fmi._parameters import SPEC_FILE
from ._errors import CoSimulationError
from ._master import Component, Connection, CoSimulation, whole_steps

if TYPE_CHECKING:
    from ..core._typing import FmpyModelDescription

__all__ = ["write_ssp", "read_ssp", "SspSystem", "simulate_ssp", "IMPORTERS"]

#: The importers :func:`simulate_ssp` can run a file with.
IMPORTERS = ("fmpy", "libcosim")

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
_OSP_TYPE = "com.opensimulationplatform"
#: The types of a connector or parameter value (SSP 1.0 also has Binary: not an FMI 2.0 type).
_TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _fmt(value: float) -> str:
    return repr(float(value))


#: What an archive member's name may hold besides letters and digits: no
#: character a URI would have to percent-encode (fmpy opens a source as
#: written, libcosim decodes it first).
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]")


def write_ssp(
    path: str | Path,
    components: Sequence[Component],
    connections: Sequence[str | tuple[str, str] | Connection] = (),
    *,
    step_size: float,
    start_time: float = 0.0,
    stop_time: float | None = None,
    name: str = "lpvest-system",
    description: str | None = None,
    jacobi: bool = True,
    worker_threads: int | None = 0,
) -> Path:
    """Write the system as an SSP archive at ``path`` and return the path.

    The FMUs are read (and the connections and parameter values checked) by a
    :class:`~lpvest.cosim.CoSimulation` first, so a file that is written is one
    the master can run; vector names expand to their elements (``"plant.y"``
    connects ``y[1], y[2], ...``; ``parameters={"x0": [1, 0]}`` binds
    ``x0[1]`` and ``x0[2]``). Each component lists every input and output of
    its FMU as a connector (an Enumeration's type in the SSD's
    ``Enumerations``, its parameter values by item name); the communication
    step is declared as libcosim's ``FixedStepAlgorithm`` annotation of the
    default experiment, with the number of threads libcosim steps the FMUs
    on (``worker_threads``). The same system gives a byte-identical file (the
    archive's members in a fixed order, with a fixed time stamp).

    **Measurement delay** (``jacobi=True``). The importers step every FMU in
    parallel (Jacobi), so an input fed by an output with direct feedthrough
    of a discrete-time FMU (a plant's ``y``) receives the value of the sample
    before. A filter FMU with the parameter ``measurement_delay`` whose
    measurement inputs (``y``) are fed so gets ``measurement_delay = 1``
    bound in the file: it pairs each measurement with the scheduling and
    known input of its own sample, and its estimate of sample ``k`` is read
    after step ``k + 1``. A value given in the component's parameters is kept
    as given.

    Parameters
    ----------
    path : os.PathLike or str
        The ``.ssp`` file to write (its folder is created).
    components : sequence of Component
        The FMU instances; each FMU file is stored once under ``resources/``.
    connections : sequence of str, (source, target) or Connection, default ()
        ``"plant.y -> filter.y"``; vectors connect element-wise.
    step_size : float
        Communication step, positive and finite.
    start_time : float, default 0.0
        Start time of the default experiment.
    stop_time : float, optional
        Stop time of the default experiment; ``None``: not declared.
    name : str, default "lpvest-system"
        Name of the system structure and of its system.
    description : str, optional
        The system's ``description`` attribute; ``None`` or empty: none.
    jacobi : bool, default True
        The file is for an importer that steps in parallel (Jacobi: libcosim,
        fmpy's ``simulate_ssp``, most tools): bind ``measurement_delay`` as
        above. ``False``: bind only the components' parameters (an importer
        that orders its calls by the connections, as
        :class:`~lpvest.cosim.CoSimulation` does).
    worker_threads : int or None, default 0
        The ``numWorkerThreads`` of libcosim's fixed-step algorithm: ``0``,
        libcosim steps the FMUs one after another in the thread that steps
        the execution; ``n > 0``, on a pool of ``n`` threads (libcosim makes
        at most the machine's cores less one); ``None``: not declared
        (libcosim's default: that many). Other importers ignore it. The
        values are the same either way (Jacobi stepping both); only the
        time differs. A pool costs a hand-off per FMU and step (about 5 us
        here) and pays off only when the FMUs' steps cost much more and can
        run at the same time. Neither holds for lpvest's FMUs: a native one
        takes 0.1 to a few us per step, and the pythonfmu ones run Python
        code, which their process's one interpreter runs one thread at a
        time (the GIL). Hence ``0`` (the four native Peixoto FMUs: 1.7
        instead of 31 us per step; the pythonfmu ones about half the time
        of the pool: docs/fmus.md); give ``None`` or ``n`` for FMUs with
        long steps that can run in parallel.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    CoSimulationError
        An invalid step size, ``worker_threads`` that is not a non-negative
        integer, or set-up (as :class:`~lpvest.cosim.CoSimulation`
        raises it), or, with ``jacobi``, a filter whose measurement inputs
        would arrive partly late, or with a scheduling or known input that
        arrives late too (no ``measurement_delay`` pairs those; set it in the
        component's parameters to write the file anyway).
    """
    from .._version import __version__

    if not step_size > 0 or not math.isfinite(step_size):
        raise CoSimulationError(f"step_size must be positive and finite; found {step_size}", where="step_size")
    if worker_threads is not None and (not isinstance(worker_threads, (int, np.integer))
                                       or isinstance(worker_threads, (bool, np.bool_))
                                       or not 0 <= worker_threads <= MAX_WORKER_THREADS):
        raise CoSimulationError(f"worker_threads must be None or a whole number from 0 to {MAX_WORKER_THREADS}; "
                                f"found {abbreviate(worker_threads, 30)}", where="worker_threads")
    path = Path(path)
    with CoSimulation(components, connections, step_size=step_size, start_time=start_time) as sim:
        units = sim._units
        links = [(units[s.comp].spec.name, s.name, units[d.comp].spec.name, d.name) for s, d in sim._links]
        delays = _jacobi_delays(sim) if jacobi else {}
        sources: dict[Path, str] = {}
        for u in units:
            fmu = Path(u.spec.fmu).resolve()
            if fmu not in sources:
                base = _UNSAFE.sub("_", fmu.stem)
                stem, n = base, 1
                while f"resources/{stem}.fmu" in sources.values():
                    n += 1
                    stem = f"{base}_{n}"
                sources[fmu] = f"resources/{stem}.fmu"
        enumerations: dict[str, tuple[tuple[str, int], ...]] = {}  # SSD name -> items
        enum_names: dict[tuple[str, tuple[tuple[str, int], ...]], str] = {}

        def enumeration(var: Any) -> str:
            """The SSD's name of an Enumeration variable's type (the FMU's,
            numbered when another FMU has a different type of that name)."""
            key = (var.declared, var.items)
            if key not in enum_names:
                ename, n = var.declared or "Enumeration", 1
                while ename in enumerations:
                    n += 1
                    ename = f"{var.declared or 'Enumeration'}_{n}"
                enumerations[ename], enum_names[key] = var.items, ename
            return enum_names[key]
        for prefix, uri in NS.items():
            ET.register_namespace(prefix, uri)
        root = ET.Element(_q("ssd", "SystemStructureDescription"),
                          {"name": name, "version": "1.0", "generationTool": f"lpvest {__version__}"})
        system = ET.SubElement(root, _q("ssd", "System"), {"name": name})
        if description:
            system.set("description", description)
        elements = ET.SubElement(system, _q("ssd", "Elements"))
        for u in units:
            comp = ET.SubElement(elements, _q("ssd", "Component"), {
                "name": u.spec.name, "type": "application/x-fmu-sharedlibrary",
                "source": sources[Path(u.spec.fmu).resolve()], "implementation": "CoSimulation",
            })
            conns = ET.SubElement(comp, _q("ssd", "Connectors"))
            for v in u.md.modelVariables:
                if v.causality in ("input", "output") and v.name in u.variables:
                    c = ET.SubElement(conns, _q("ssd", "Connector"), {"name": v.name, "kind": v.causality})
                    ET.SubElement(c, _q("ssc", v.type),
                                  {"name": enumeration(u.variables[v.name])} if v.type == "Enumeration" else {})
            bound = list(u.start_values)
            if u.spec.name in delays:
                bound.append((u.variables[DELAY], delays[u.spec.name], DELAY))
            if bound:
                bindings = ET.SubElement(comp, _q("ssd", "ParameterBindings"))
                binding = ET.SubElement(bindings, _q("ssd", "ParameterBinding"))
                values = ET.SubElement(binding, _q("ssd", "ParameterValues"))
                pset = ET.SubElement(values, _q("ssv", "ParameterSet"), {"version": "1.0", "name": u.spec.name})
                params = ET.SubElement(pset, _q("ssv", "Parameters"))
                for v, value, _ in bound:
                    p = ET.SubElement(params, _q("ssv", "Parameter"), {"name": v.name})
                    text = (_fmt(cast(float, value)) if v.type == "Real" else str(value).lower() if v.type == "Boolean"
                            else str(value))
                    if v.type == "Enumeration":  # SSP 1.0: the item's name
                        item = {i: n for n, i in v.items}.get(cast(int, value), text)
                        attrs = {"value": item, "name": enumeration(v)}
                    else:
                        attrs = {"value": text}
                    ET.SubElement(p, _q("ssv", v.type), attrs)
        if links:
            cs = ET.SubElement(system, _q("ssd", "Connections"))
            for a, av, b, bv in links:
                ET.SubElement(cs, _q("ssd", "Connection"),
                              {"startElement": a, "startConnector": av, "endElement": b, "endConnector": bv})
        if enumerations:
            enums = ET.SubElement(root, _q("ssd", "Enumerations"))
            for ename, items in enumerations.items():
                e = ET.SubElement(enums, _q("ssc", "Enumeration"), {"name": ename})
                for iname, ivalue in items:
                    ET.SubElement(e, _q("ssc", "Item"), {"name": iname, "value": str(ivalue)})
        exp = {"startTime": _fmt(start_time)}
        if stop_time is not None:
            exp["stopTime"] = _fmt(stop_time)
        default = ET.SubElement(root, _q("ssd", "DefaultExperiment"), exp)
        annotations = ET.SubElement(default, _q("ssd", "Annotations"))
        annotation = ET.SubElement(annotations, _q("ssc", "Annotation"), {"type": _OSP_TYPE})
        algorithm = ET.SubElement(annotation, _q("osp", "Algorithm"))
        fixed = {"baseStepSize": _fmt(step_size)}
        if worker_threads is not None:
            fixed["numWorkerThreads"] = str(int(worker_threads))
        ET.SubElement(algorithm, _q("osp", "FixedStepAlgorithm"), fixed)
        ET.indent(root)
        xml = ET.tostring(root, encoding="unicode", xml_declaration=False)
        path.parent.mkdir(parents=True, exist_ok=True)
        ssd = '<?xml version="1.0" encoding="UTF-8"?>\n' + xml + "\n"
        with zipfile.ZipFile(path, "w") as z:
            write_zip_entry(z, "SystemStructure.ssd", ssd.encode())
            for fmu, arc in sources.items():
                write_zip_entry(z, arc, fmu.read_bytes())
    return path


#: The most worker threads a file may declare: libcosim reads the number as an
#: ``unsigned int`` and makes a pool of at most the machine's cores less one.
MAX_WORKER_THREADS = 2**31 - 1


#: The filter parameter :func:`write_ssp` binds for a Jacobi importer
#: (:data:`lpvest.fmi._registry.MEASUREMENT_DELAY`).
DELAY = "measurement_delay"


def _late_inputs(fmu: str | Path) -> tuple[str, ...]:
    """The input ports that ``measurement_delay`` pairs in an lpvest estimator
    FMU (its spec's ``late_inputs``); ``()`` for any other FMU."""
    try:
        with zipfile.ZipFile(fmu) as z:
            spec = json.loads(z.read(f"resources/{SPEC_FILE}"))
    except (KeyError, OSError, ValueError, zipfile.BadZipFile):
        return ()
    kind = spec.get("estimator") if isinstance(spec, dict) else None
    return tuple(kind.get("late_inputs") or ()) if isinstance(kind, dict) else ()


def _jacobi_delays(sim: CoSimulation) -> dict[str, int]:
    """Component -> the ``measurement_delay`` a Jacobi importer needs, for each
    filter that has the parameter (not set by the caller) and whose
    measurement inputs are fed by outputs that arrive one sample late: outputs
    with direct feedthrough of a discrete-time FMU, read after the step that
    consumed the sample."""
    units, out = sim._units, {}
    for i, u in enumerate(units):
        var = u.variables.get(DELAY)
        if var is None or var.causality != "parameter" or DELAY in u.spec.parameters:
            continue
        ports = _late_inputs(u.spec.fmu)
        if not ports:
            continue
        fed = {d.name: s for s, d in sim._links if d.comp == i}
        late = set()
        for name, src in fed.items():
            source = units[src.comp]
            discrete = next((v.variability == "discrete" for v in source.md.modelVariables if v.name == src.name),
                            False)
            if discrete and source.depends.get(src.name):
                late.add(name)
        if not late:
            continue
        measured = {n for n in fed if n.split("[")[0] in ports}
        if late != measured:
            early = sorted(measured - late)
            others = sorted(late - measured)
            what = (f"{', '.join(others)} would arrive one sample late too" if others
                    else f"{', '.join(early)} would arrive in time")
            raise CoSimulationError(
                f"component {u.spec.name}: under Jacobi stepping {', '.join(sorted(late & measured))} would "
                f"arrive one sample late and {what}: no {DELAY} pairs them; set {DELAY} in the component's "
                "parameters to write the file anyway", where=f"components.{u.spec.name}")
        out[u.spec.name] = 1
    return out


@dataclass(frozen=True)
class SspSystem:
    """What :func:`read_ssp` finds in an SSP file written by :func:`write_ssp`
    (or any flat SSP 1.0 system of FMUs).

    Parameters
    ----------
    name : str
        The system structure's name (``""`` if none).
    components : dict of str to str
        Component -> FMU inside the archive (its member name: the
        component's ``source`` with percent-escapes decoded).
    connections : list of tuple of (str, str)
        ``("comp.var", "comp.var")``, source then target.
    parameters : dict of str to list of tuple of (str, str, str)
        Component -> ``[(variable, type, value text)]`` of its first parameter binding.
    outputs : dict of str to list of str, default {}
        Component -> output connectors.
    step_size : float or None, default None
        The OSP FixedStepAlgorithm's ``baseStepSize``; ``None``: not declared.
    start_time : float, default 0.0
        Start time of the default experiment.
    stop_time : float or None, default None
        Stop time of the default experiment; ``None``: not declared.
    connectors : dict of str to list of tuple of (str, str, str), default {}
        Component -> ``[(name, kind, type)]`` of every connector, ``type``
        as declared (``"Real"``, ..., ``"Enumeration"``; ``""``: not declared).
    sources : dict of str to str, default {}
        Component -> its ``source`` as written (a URI reference).
    worker_threads : int or None, default None
        The OSP FixedStepAlgorithm's ``numWorkerThreads`` (0: libcosim steps
        the FMUs in its calling thread); ``None``: not declared.
    """

    name: str
    components: dict[str, str]
    connections: list[tuple[str, str]]
    parameters: dict[str, list[tuple[str, str, str]]]
    outputs: dict[str, list[str]] = field(default_factory=dict)
    step_size: float | None = None
    start_time: float = 0.0
    stop_time: float | None = None
    connectors: dict[str, list[tuple[str, str, str]]] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    worker_threads: int | None = None


#: The largest SystemStructure.ssd read (bytes): a description of a few
#: components is some kilobytes; the bound keeps a hostile archive from
#: unpacking gigabytes into memory.
MAX_SSD_BYTES = 16 * 2**20


def _ssp_error(path: Path, message: str) -> CoSimulationError:
    return CoSimulationError(f"{path}: {message}")


def _safe_member(source: str) -> bool:
    """An archive member name that stays inside the archive: relative, no
    ``..``, no drive or backslash (libcosim unpacks the SSP and opens it)."""
    if not source or "\\" in source or "\x00" in source or source.startswith("/") or ":" in source.split("/")[0]:
        return False
    return all(part not in ("", ".", "..") for part in source.split("/"))


_ESCAPE = re.compile(r"%([0-9A-Fa-f]{2})")


def _member(path: Path, where: str, source: str) -> str:
    """The archive member a component's ``source`` names: the URI reference
    with its percent-escapes decoded (libcosim decodes them before it opens
    the file). Refused: a malformed escape, an escape that decodes to a path
    separator, and a name that leaves the archive (``..``, absolute, a drive),
    checked after decoding, and again after every further decoding, so that
    no importer that decodes twice is led outside either."""
    shown = abbreviate(source, 60)
    member, text = None, source
    for _ in range(8):  # each round removes a level of '%25': a name holds few
        if text.count("%") != len(_ESCAPE.findall(text)):
            raise _ssp_error(path, f"{where}: source {shown} has a malformed percent-escape (expected '%' and two "
                                   "hexadecimal digits)")
        if any(chr(int(h, 16)) in "/\\" for h in _ESCAPE.findall(text)):
            raise _ssp_error(path, f"{where}: source {shown} has a percent-escape that decodes to a path separator")
        try:
            decoded = urllib.parse.unquote(text, errors="strict")
        except UnicodeDecodeError:
            raise _ssp_error(path, f"{where}: source {shown} does not decode to UTF-8 text") from None
        if not _safe_member(decoded):
            also = "" if decoded == source else f" (decoded: {abbreviate(decoded, 60)})"
            raise _ssp_error(path, f"{where}: source {shown}{also} is not a relative path inside the archive "
                                   "(no '..', no absolute path)")
        if member is None:
            member = decoded
        if decoded == text:
            return member
        text = decoded
    raise _ssp_error(path, f"{where}: source {shown} is percent-encoded too many times over")


def _number(path: Path, where: str, text: str | None, *, positive: bool = False) -> float:
    try:
        value = float(text)  # type: ignore[arg-type]  # None raises the TypeError caught below
    except (TypeError, ValueError):
        raise _ssp_error(path, f"{where}: expected a number, found {abbreviate(text, 30)}") from None
    if not math.isfinite(value) or (positive and not value > 0):
        raise _ssp_error(path, f"{where}: expected a {'positive' if positive else 'finite'} number, found {value!r}")
    return value


def _checked_value(path: Path, where: str, typ: str, text: str) -> str:
    """A parameter value as written in the SSD, checked against its type."""
    if typ == "Real":
        _number(path, where, text)
    elif typ == "Integer":
        try:
            value = int(text.strip())
        except ValueError:
            raise _ssp_error(path, f"{where}: expected an integer, found {abbreviate(text, 30)}") from None
        if not -(2**31) <= value < 2**31:
            raise _ssp_error(path, f"{where}: {value} is outside the range of an FMI Integer")
    elif typ == "Boolean" and text.strip().lower() not in ("true", "false", "1", "0"):
        raise _ssp_error(path, f"{where}: expected true or false, found {abbreviate(text, 30)}")
    elif typ == "Enumeration" and not text:
        raise _ssp_error(path, f"{where}: expected the name of an enumeration item, found ''")
    return text


def read_ssp(path: str | Path) -> SspSystem:
    """The system, parameter values and default experiment of an SSP file.

    Every FMU a component names must be a member of the archive given by a
    relative name without ``..`` (an importer unpacks the archive and opens
    it), checked after its percent-escapes are decoded (a ``source`` is a URI
    reference; an escape may not stand for a path separator); every
    connection joins declared connectors; numbers and parameter values must
    parse as their types. Anything else raises
    :class:`~lpvest.cosim.CoSimulationError` naming the file and the element.

    Parameters
    ----------
    path : os.PathLike or str
        The ``.ssp`` archive; its ``SystemStructure.ssd`` is read (at most
        :data:`MAX_SSD_BYTES`).

    Returns
    -------
    SspSystem
        The components, connections, parameter values, connectors and default
        experiment.

    Raises
    ------
    CoSimulationError
        The file is not such an SSP file (one line: the file and the element).
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as z:
            members = set(z.namelist())
            info = z.getinfo("SystemStructure.ssd")
            if info.file_size > MAX_SSD_BYTES:
                raise _ssp_error(path, f"SystemStructure.ssd has {info.file_size:,} bytes; at most "
                                       f"{MAX_SSD_BYTES:,} are read")
            root = ET.fromstring(z.read(info))
    except CoSimulationError:
        raise
    except (OSError, KeyError, ValueError, LookupError, zipfile.BadZipFile, ET.ParseError, EOFError,
            RuntimeError) as exc:  # (LookupError: an XML declaration naming an unknown encoding)
        text = shorten(" ".join(str(exc).split()), 80)
        raise _ssp_error(path, f"not an SSP file with a SystemStructure.ssd: {text}") from exc
    system = root.find("ssd:System", NS)
    if system is None:
        raise _ssp_error(path, "SystemStructure.ssd has no System")
    components: dict[str, str] = {}
    sources: dict[str, str] = {}
    parameters: dict[str, list[tuple[str, str, str]]] = {}
    outputs: dict[str, list[str]] = {}
    connectors: dict[str, list[tuple[str, str, str]]] = {}
    for i, c in enumerate(system.findall("ssd:Elements/ssd:Component", NS)):
        cname = c.get("name", "")
        where = f"component {abbreviate(cname, 30)}" if cname else f"component {i + 1}"
        if not cname or cname in components:
            raise _ssp_error(path, f"{where}: expected a unique, non-empty name")
        source = c.get("source", "")
        member = _member(path, where, source)
        if member not in members:
            also = "" if member == source else f" (decoded: {abbreviate(member, 60)})"
            raise _ssp_error(path, f"{where}: source {abbreviate(source, 60)}{also} is not in the archive")
        components[cname], sources[cname] = member, source
        declared = []
        for j, k in enumerate(c.findall("ssd:Connectors/ssd:Connector", NS)):
            kname = k.get("name", "")
            if not kname:
                raise _ssp_error(path, f"{where}: connector {j + 1}: expected a name")
            typ = next((t for t in _TYPES if k.find(f"ssc:{t}", NS) is not None), "")
            declared.append((kname, k.get("kind", ""), typ))
        connectors[cname] = declared
        outputs[cname] = [n for n, kind, _ in declared if kind == "output"]
        values = []
        binding = c.find("ssd:ParameterBindings/ssd:ParameterBinding", NS)
        if binding is not None:
            for p in binding.findall("ssd:ParameterValues/ssv:ParameterSet/ssv:Parameters/ssv:Parameter", NS):
                for typ in _TYPES:
                    e = p.find(f"ssv:{typ}", NS)
                    if e is not None:
                        name = p.get("name", "")
                        text = _checked_value(path, f"{where}: parameter {abbreviate(name, 30)}", typ,
                                              e.get("value", ""))
                        values.append((name, typ, text))
        parameters[cname] = values
    connections = []
    for i, c in enumerate(system.findall("ssd:Connections/ssd:Connection", NS)):
        ends = [c.get(k) for k in ("startElement", "startConnector", "endElement", "endConnector")]
        if not all(ends):
            raise _ssp_error(path, f"connection {i + 1}: expected startElement, startConnector, endElement and "
                                   "endConnector")
        for element, connector in ((ends[0], ends[1]), (ends[2], ends[3])):
            if element not in components:
                raise _ssp_error(path, f"connection {i + 1}: no component {abbreviate(element, 30)}")
            if all(connector != n for n, _, _ in connectors[element]):  # fmpy would raise a KeyError
                raise _ssp_error(path, f"connection {i + 1}: component {abbreviate(element, 30)} has no connector "
                                       f"{abbreviate(connector, 40)}")
        connections.append((f"{ends[0]}.{ends[1]}", f"{ends[2]}.{ends[3]}"))
    step, threads = None, None
    start, stop = 0.0, None
    exp = root.find("ssd:DefaultExperiment", NS)
    if exp is not None:
        start = _number(path, "DefaultExperiment startTime", exp.get("startTime", "0"))
        if exp.get("stopTime") is not None:
            stop = _number(path, "DefaultExperiment stopTime", exp.get("stopTime"))
        for a in exp.findall("ssd:Annotations/ssc:Annotation", NS):
            if a.get("type") == _OSP_TYPE:
                alg = a.find("osp:Algorithm/osp:FixedStepAlgorithm", NS)
                if alg is not None and alg.get("baseStepSize") is not None:
                    step = _number(path, "FixedStepAlgorithm baseStepSize", alg.get("baseStepSize"), positive=True)
                if alg is not None and alg.get("numWorkerThreads") is not None:
                    threads = _worker_threads(path, alg.get("numWorkerThreads", ""))
    return SspSystem(root.get("name", ""), components, connections, parameters, outputs, step, start, stop,
                     connectors, sources, threads)


def _worker_threads(path: Path, text: str) -> int:
    """A FixedStepAlgorithm's ``numWorkerThreads``: digits for a number from 0
    to :data:`MAX_WORKER_THREADS`. libcosim reads it as an ``unsigned int``
    and takes ``-1`` (4294967295) and text it cannot parse as its default
    pool, silently: a file that asks for the calling thread and does not get
    it."""
    where = "FixedStepAlgorithm numWorkerThreads"
    if not re.fullmatch(r"[0-9]+", text.strip()):  # what libcosim parses as an unsigned int, and nothing else
        raise _ssp_error(path, f"{where}: expected a whole number, found {abbreviate(text, 30)}")
    value = int(text)
    if not 0 <= value <= MAX_WORKER_THREADS:
        raise _ssp_error(path, f"{where}: expected a number from 0 to {MAX_WORKER_THREADS}, found {value}")
    return value


def _typed(typ: str, text: str) -> float | int | bool | str:
    if typ == "Real":
        return float(text)
    if typ == "Integer":
        return int(text)
    if typ == "Boolean":
        return text.strip().lower() in ("true", "1")
    return text


#: The output types :func:`simulate_ssp` records (as the master does: String
#: outputs are left out, the result holds numbers), and what each importer
#: can exchange (fmpy has no String calls; libcosim does not see an FMU's
#: Enumeration variables).
_RECORDED = ("Real", "Integer", "Boolean", "Enumeration")
_EXCHANGED = {"fmpy": ("Real", "Integer", "Boolean", "Enumeration"),
              "libcosim": ("Real", "Integer", "Boolean", "String")}


def simulate_ssp(
    path: str | Path,
    *,
    importer: str = "fmpy",
    n_steps: int | None = None,
    stop_time: float | None = None,
) -> np.ndarray:
    """Run an SSP file with another co-simulation master.

    The file is checked against its FMUs first: every connector and bound
    parameter must be a variable of the component's FMU, of the declared type
    and kind, and one the importer can exchange (fmpy has no String calls;
    libcosim does not see Enumeration variables); a mistake is one line
    naming the component and the connector or parameter.

    Parameters
    ----------
    path : str or Path
        An SSP file (e.g. from :func:`write_ssp`).
    importer : {"fmpy", "libcosim"}
        ``"fmpy"``: ``fmpy.ssp.simulate_ssp`` in this process, given the
        file's step size and parameter values (it reads neither itself);
        the folders it extracts the file and the FMUs into are removed when
        the run fails too (fmpy removes them only after a run that succeeds).
        ``"libcosim"``: ``libcosimpy`` (the ``test`` extra) in a subprocess
        (libcosim keeps the FMUs' libraries loaded), configured by the file
        alone (``CosimExecution.from_ssp_file`` without a step size, so the
        file's fixed-step algorithm is the one that runs, with its
        ``numWorkerThreads`` if it declares one).
    n_steps, stop_time : optional
        How far to run (default: the file's stop time).

    Returns
    -------
    numpy structured array
        ``"time"`` and every Real, Integer, Boolean and Enumeration output
        connector as ``"comp.var"`` (floats; String outputs are left out, as
        :class:`~lpvest.cosim.CoSimulation` leaves them out), one row per
        step, the values read *after* the step: row ``k`` holds the outputs
        at ``t_{k+1}``, and its ``"time"`` is ``t_{k+1}`` (fmpy labels that
        row ``t_k``; the label is corrected here so both importers agree).

    Raises
    ------
    CoSimulationError
        An invalid file (:func:`read_ssp`), a connector or parameter that does
        not match the FMU or that the importer cannot exchange, no step size
        or stop time, or a failed run.

    The stepping is each importer's own (Jacobi, see the module documentation).
    """
    if importer not in IMPORTERS:
        raise CoSimulationError(f"importer {abbreviate(importer, 30)}: expected one of {', '.join(IMPORTERS)}")
    path = Path(path)
    system = read_ssp(path)
    if system.step_size is None:
        raise CoSimulationError(f"{path}: the SSD declares no step size (OSP FixedStepAlgorithm baseStepSize)")
    h, t0 = system.step_size, system.start_time
    if n_steps is None:
        end = stop_time if stop_time is not None else system.stop_time
        if end is None:
            raise CoSimulationError(f"{path}: no stop time in the file; give n_steps or stop_time")
        if (end - t0) / h > 1e9:
            raise CoSimulationError(f"{path}: from {t0:g} to {end:g} in steps of {h:g}: too many steps")
        n_steps = whole_steps(t0, end, h)
    if n_steps < 1:
        raise CoSimulationError(f"n_steps must be at least 1; found {n_steps}")
    variables = _fmu_variables(path, system)
    _check_against_fmus(path, system, variables, importer)
    recorded = {c: [n for n, kind, _ in conns if kind == "output" and variables[c][n].type in _RECORDED]
                for c, conns in system.connectors.items()}
    if importer == "fmpy":
        values = _run_fmpy(path, system, variables, n_steps)
    else:
        values = _run_libcosim(path, {c: [(n, variables[c][n].type) for n in names] for c, names in recorded.items()},
                               n_steps)
    names = [f"{c}.{n}" for c, outs in recorded.items() for n in outs]
    out = np.empty(n_steps, dtype=[("time", "f8")] + [(n, "f8") for n in names])
    out["time"] = t0 + np.arange(1, n_steps + 1) * h
    for n in names:
        out[n] = values[n]
    return out


def _fmu_variables(path: Path, system: SspSystem) -> dict[str, dict[str, FmpyModelDescription]]:
    """Component -> {name: fmpy's ScalarVariable} of its FMU, each FMU in the
    archive read once."""
    from fmpy import read_model_description

    by_member: dict[str, dict[str, FmpyModelDescription]] = {}
    with tempfile.TemporaryDirectory(prefix="lpvest-ssp-") as tmp, zipfile.ZipFile(path) as z:
        for comp, member in system.components.items():
            if member not in by_member:
                try:
                    fmu = z.extract(member, tmp)
                    md = read_model_description(fmu, validate=False)
                except Exception as exc:  # fmpy raises plain exceptions for a bad FMU
                    text = shorten(" ".join(str(exc).split()), 80)
                    raise CoSimulationError(f"{path}: component {comp}: {member} is not a valid FMU: {text}") from exc
                by_member[member] = {v.name: v for v in md.modelVariables}
    return {comp: by_member[member] for comp, member in system.components.items()}


def _check_against_fmus(
    path: Path, system: SspSystem, variables: dict[str, dict[str, FmpyModelDescription]], importer: str
) -> None:
    """Every connector and bound parameter is a variable of its component's
    FMU, of the declared kind and type, which the importer can exchange."""
    def variable(comp: str, name: str, what: str) -> FmpyModelDescription:
        v = variables[comp].get(name)
        if v is None:
            raise CoSimulationError(f"{what}: its FMU {system.components[comp]} has no variable "
                                    f"{abbreviate(name, 40)}")
        return v

    exchanged = _EXCHANGED[importer]
    for comp, conns in system.connectors.items():
        for name, kind, typ in conns:
            what = f"{path}: component {comp}: connector {abbreviate(name, 40)}"
            v = variable(comp, name, f"{what} ({kind or 'no kind'})")
            if kind in ("input", "output") and v.causality != kind:
                raise CoSimulationError(f"{what} has kind {kind}, but the FMU's variable has causality {v.causality}")
            if typ and typ != v.type:
                raise CoSimulationError(f"{what} is declared {typ}, but the FMU's variable has type {v.type}")
            if v.type not in exchanged:
                raise CoSimulationError(f"{what}: {_CANNOT[importer]} {v.type} variables; run this file with "
                                        f"{'libcosim' if importer == 'fmpy' else 'fmpy'}")
    if importer == "fmpy":
        # fmpy wires an input connector without a connection to the source of
        # the connection it looked at before (or fails): refused, not run wrong
        driven = {target for _, target in system.connections}
        for comp, conns in system.connectors.items():
            for name, kind, _ in conns:
                if kind == "input" and f"{comp}.{name}" not in driven:
                    raise CoSimulationError(f"{path}: component {comp}: input connector {abbreviate(name, 40)} is not "
                                            "connected, and fmpy's simulate_ssp would feed it another connection's "
                                            "value; connect it, or run this file with libcosim")
        for comp, source in system.sources.items():
            if source != system.components[comp]:  # fmpy opens the source as written
                raise CoSimulationError(f"{path}: component {comp}: fmpy's simulate_ssp cannot open the "
                                        f"percent-encoded source {abbreviate(source, 60)}; run this file with libcosim")
    for comp, values in system.parameters.items():
        for name, typ, text in values:
            what = f"{path}: component {comp}: parameter {abbreviate(name, 40)}"
            v = variable(comp, name, what)
            if typ != v.type:
                raise CoSimulationError(f"{what} is given as {typ}, but the FMU's variable has type {v.type}")
            if typ == "Enumeration":
                if importer == "libcosim":  # its SSP parser aborts the process on an Enumeration value
                    raise CoSimulationError(f"{what}: {_CANNOT[importer]} Enumeration variables; run this file "
                                            "with fmpy")
                _item_value(path, comp, v, text)


_CANNOT = {"fmpy": "fmpy's simulate_ssp cannot exchange", "libcosim": "libcosim does not see"}


def _item_value(path: Path, comp: str, variable: FmpyModelDescription, text: str) -> int:
    """The value of the Enumeration item named ``text`` of an FMU's variable."""
    items = {i.name: int(i.value) for i in variable.declaredType.items} if variable.declaredType else {}
    if text not in items:
        listed = shorten(", ".join(items), 60)
        raise CoSimulationError(f"{path}: component {comp}: parameter {abbreviate(variable.name, 40)}: "
                                f"{abbreviate(text, 30)} is not an item of its type (items: {listed})")
    return items[text]


#: The folders fmpy's ``extract`` made for the calling thread inside :func:`_run_fmpy` (see :func:`_fmpy_ssp`).
_FMPY_EXTRACTIONS = threading.local()
_FMPY_WRAP_LOCK = threading.Lock()
_fmpy_recording_extract: Callable[..., object] | None = None  # the wrapper _fmpy_ssp installed


def _fmpy_ssp() -> ModuleType:
    """``fmpy.ssp.simulation``, its ``extract`` wrapped once per process to record the
    temporary folders it makes while :func:`_run_fmpy` runs on the calling thread.
    fmpy's ``simulate_ssp`` removes the SSP's and the FMUs' extractions only when a
    run succeeds: a failing run (an FMU's error status, a bad value) left them in
    the temporary folder, one per FMU and one for the file, every time. The wrapper
    changes nothing else: same arguments, same folder, same result; another
    thread's calls, or calls outside :func:`_run_fmpy`, are not recorded."""
    global _fmpy_recording_extract
    import fmpy.ssp.simulation as simulation

    with _FMPY_WRAP_LOCK:
        original = getattr(simulation, "extract", None)
        if original is not None and original is not _fmpy_recording_extract:
            # any signature: a folder of its own is one fmpy asked for without unzipdir
            def extract(*args: object, **kwargs: object) -> object:
                folder = original(*args, **kwargs)
                made = getattr(_FMPY_EXTRACTIONS, "made", None)
                if made is not None and len(args) < 2 and kwargs.get("unzipdir") is None:
                    made.append(folder)
                return folder

            simulation.extract = _fmpy_recording_extract = extract
    return simulation


def _run_fmpy(path: Path, system: SspSystem, variables: dict[str, dict[str, FmpyModelDescription]],
              n_steps: int) -> dict[str, np.ndarray]:
    from fmpy.ssp.ssd import Parameter, ParameterSet

    fmpy_simulate = _fmpy_ssp().simulate_ssp

    params = []
    for comp, values in system.parameters.items():
        for name, typ, text in values:
            if typ == "String":
                # fmpy has no setter for String variables: a value equal to the
                # FMU's start value needs none; any other cannot be applied
                if variables[comp][name].start == text:
                    continue
                raise CoSimulationError(
                    f"{path}: fmpy's simulate_ssp cannot set the String parameter {comp}.{name} = {text!r} "
                    "(it has no setter for String variables); run this file with libcosim"
                )
            value = _item_value(path, comp, variables[comp][name], text) if typ == "Enumeration" \
                else _typed(typ, text)
            params.append(Parameter(name=f"{comp}.{name}", type=typ, value=value))
    h, t0 = system.step_size, system.start_time
    assert h is not None
    # fmpy steps while time < stop_time with time += h: stop half a step early
    # so that exactly n_steps are taken whatever the round-off
    made: list[object] = []  # fmpy's folders (a Path in fmpy 0.3.2x)
    outer = getattr(_FMPY_EXTRACTIONS, "made", None)  # a run on this thread around this one (an FMU's step)
    _FMPY_EXTRACTIONS.made = made
    try:
        res = fmpy_simulate(str(path), start_time=t0, stop_time=t0 + (n_steps - 0.5) * h, step_size=h,
                            parameter_set=ParameterSet(parameters=params) if params else None)
    except Exception as exc:  # fmpy raises plain exceptions (an FMU's error status, a file it cannot read)
        text = shorten(" ".join(str(exc).split()), 120)
        raise CoSimulationError(f"{path}: fmpy's simulate_ssp failed: {type(exc).__name__}: {text}") from exc
    finally:
        _FMPY_EXTRACTIONS.made = outer
        for folder in made:  # what a failed run left (a finished one removed its own)
            shutil.rmtree(str(folder), ignore_errors=True)
    if res.shape[0] != n_steps:
        raise CoSimulationError(f"fmpy took {res.shape[0]} steps; expected {n_steps}")
    return {n: np.asarray(res[n], dtype=float) for n in res.dtype.names if n != "time"}


_LIBCOSIM_SCRIPT = """
import json, sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimLogging import log_output_level, CosimLogLevel
log_output_level(CosimLogLevel.ERROR)
path, n_steps, wanted = sys.argv[1], int(sys.argv[2]), json.loads(sys.argv[3])
ex = CosimExecution.from_ssp_file(path)
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
index = {ex.slave_infos()[i].name.decode(): ex.slave_infos()[i].index for i in range(ex.num_slaves())}
# each type has its own value references (and its own observer call): read by type
readers = {"Real": obs.last_real_values, "Integer": obs.last_integer_values, "Boolean": obs.last_boolean_values}
refs = {}
for comp, outputs in wanted.items():
    byname = {v.name.decode(): v.reference for v in ex.slave_variables(index[comp])}
    for typ in readers:
        names = [n for n, t in outputs if t == typ]
        if names:
            refs.setdefault(comp, []).append((typ, names, [byname[n] for n in names]))
rows = []
for k in range(n_steps):
    if not ex.step(1):
        sys.exit(f"libcosim failed at step {k}: {ex.status()}")
    rows.append({f"{comp}.{n}": float(x) for comp, groups in refs.items() for typ, names, r in groups
                 for n, x in zip(names, readers[typ](index[comp], r))})
print("RESULT" + json.dumps(rows))
"""


def _run_libcosim(path: Path, wanted: dict[str, list[tuple[str, str]]], n_steps: int) -> dict[str, np.ndarray]:
    """Run the file in libcosim; ``wanted``: component -> [(output, FMI type)] to read after each step."""
    try:
        import libcosimpy  # noqa: F401 - checked here, used in the subprocess
    except ImportError as exc:
        raise CoSimulationError("libcosim is not installed (pip install libcosimpy)") from exc
    wanted = {c: outs for c, outs in wanted.items() if outs}
    with tempfile.TemporaryDirectory(prefix="lpvest-libcosim-") as tmp:
        proc = subprocess.run(
            [sys.executable, "-c", textwrap.dedent(_LIBCOSIM_SCRIPT), str(Path(path).resolve()), str(n_steps),
             json.dumps(wanted)],
            capture_output=True, text=True, check=False, cwd=tmp, timeout=3600,
        )
    line = next((x for x in proc.stdout.splitlines() if x.startswith("RESULT")), None)
    if proc.returncode != 0 or line is None:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise CoSimulationError(f"{path}: libcosim failed (exit status {proc.returncode}): " + " | ".join(tail))
    rows = json.loads(line[len("RESULT"):])
    return {f"{c}.{n}": np.array([r[f"{c}.{n}"] for r in rows]) for c, outs in wanted.items() for n, _ in outs}
