"""Build and validate the lpvest FMUs.

One FMU per (model, role), named ``<System><Role>.fmu`` (``PeixotoEx1Plant.fmu``).
For a system file the builder plans:

- ``Plant``: the file's default model if a streaming plant can run it, else the
  first model (in file order) that it can run (cox-toth-ex1: the default (21b)
  needs ``p_{t+1}`` in its gain, and (21a) has no state, so the plant realizes
  (21c), which gives the same ``y`` for the same ``u``, ``p``, ``e``);
  continuous-time LTV models get the integrating LTV plant;
- ``Scheduler``: for LPV models with a scheduling box (``p`` and, for a
  polytopic model, ``alpha``);
- ``Source``: for LPV models with an input ``u`` or a disturbance ``w``;
- one FMU per registered estimator kind that applies to the plant's model
  (:mod:`lpvest.fmi.registry`).

How an FMU is made (pythonfmu 0.7 conventions, done here so that the model
description can be completed): a staging folder becomes ``resources/``: the
role's slave script from ``fmus/``, a copy of the ``lpvest`` package (the FMU
runs where lpvest is not installed), pythonfmu's Python files, the model file,
the spec ``lpvest_fmu.json``, an optional design, ``requirements.txt`` and
``slavemodule.txt`` (the script's module name, read by pythonfmu's binary).
The slave is instantiated once with that folder as its resources to write the
model description (pythonfmu's ``to_xml``), which is then completed: declared
``min``/``max``, the inputs each output depends on, and ``InitialUnknowns``
(pythonfmu writes none). ``binaries/linux64/<id>.so`` is the lpvest status
bridge (``status_bridge.c``, compiled here with the C compiler) in front of
pythonfmu's export library; without a C compiler pythonfmu's library is used
as is (bad input then shows as fmi2Discard at the next fmi2DoStep, and a
Python exception as fmi2Fatal). ``binaries/win64`` carries pythonfmu's DLL.
"""

from __future__ import annotations

import atexit
import functools
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.dom.minidom import parseString
from xml.etree.ElementTree import Element, SubElement, tostring

from ..errors import LpvestError
from .naming import fmu_name
from .registry import EstimatorKind, estimator_kinds, resolve
from .spec import SPEC_FILE, SPEC_FORMAT

__all__ = [
    "FmuPlan",
    "BuildResult",
    "ValidationResult",
    "plan_system",
    "build_fmu",
    "build_fmus",
    "validate_fmus",
    "format_table",
    "scripts_dir",
    "status_bridge",
    "DEFAULT_OUT",
]

#: Default output folder of ``build_fmus.py`` / ``lpvest build`` (ignored by git).
DEFAULT_OUT = "fmu-build"

_INNER_LIBRARY = "lpvest-pythonfmu-export.so"


class BuildError(LpvestError, RuntimeError):
    """An FMU could not be built."""


def scripts_dir() -> Path:
    """The folder of the slave scripts: ``fmus/`` next to the package in a
    source checkout, else the copy installed as ``lpvest._fmus``."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here.parent / "fmus", here / "_fmus"):
        if (candidate / "lpvest_plant.py").is_file():
            return candidate
    raise BuildError(f"the FMU slave scripts are missing (looked in {here.parent / 'fmus'})")


@dataclass(frozen=True)
class FmuPlan:
    """One FMU to build."""

    identifier: str
    role: str
    script: str
    system_path: Path
    system_name: str
    model_key: str
    description: str
    model_parameters: tuple[str, ...] = ()
    requirements: tuple[str, ...] = ("numpy>=1.26",)
    estimator: EstimatorKind | None = None
    step_size: float = 1.0
    stop_time: float = 100.0


@dataclass(frozen=True)
class ValidationResult:
    """An FMU checked with ``fmpy.validation.validate_fmu``."""

    path: Path
    inputs: int
    outputs: int
    parameters: int
    size: int
    problems: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def ok(self) -> bool:
        return not self.problems


@dataclass(frozen=True)
class BuildResult:
    """A plan, the FMU built from it, and its validation."""

    plan: FmuPlan
    validation: ValidationResult


# -- planning -----------------------------------------------------------------


def plan_system(
    source: str | Path, *, kinds: Sequence[EstimatorKind] | None = None
) -> tuple[list[FmuPlan], list[str]]:
    """The FMUs to build for a system file (or an example's name), and notes on
    roles left out and why."""
    from ..modelfile import load_system
    from ..systems import AffineLPV, InnovationLPV, LTVInputOutput, LTVStateSpace, PolytopicLPV
    from ..systems.streaming import plant_supports

    system = load_system(source)
    if system.path is None:
        raise BuildError(f"{source}: a system needs a model file to be built into FMUs")
    stem = fmu_name(system.name)
    notes: list[str] = []
    order = [system.default] + [k for k in system.models if k != system.default]
    key = None
    for k in order:
        reason = plant_supports(system.models[k])
        if reason is None:
            key = k
            break
        notes.append(f"{system.name}: model {k!r} gets no plant: {reason}")
    if key is None:
        return [], notes
    model = system.models[key]
    params = tuple(system.parameters)
    title = system.title or system.name
    common = {"system_path": system.path, "system_name": system.name, "model_key": key}
    plans: list[FmuPlan] = []
    if isinstance(model, LTVStateSpace | LTVInputOutput):
        plans.append(FmuPlan(f"{stem}Plant", "Plant", "lpvest_ltv_plant.py",
                             description=f"Plant: {title} (model {key!r}, continuous-time LTV)",
                             model_parameters=params, requirements=("numpy>=1.26", "scipy>=1.11"),
                             step_size=0.1, stop_time=20.0, **common))
        notes.append(f"{system.name}: no Scheduler/Source (an LTV model depends on time; its input is a function of t)")
    else:
        kind = {PolytopicLPV: "polytopic", AffineLPV: "affine", InnovationLPV: "innovation"}[type(model)]
        plans.append(FmuPlan(f"{stem}Plant", "Plant", "lpvest_plant.py",
                             description=f"Plant: {title} (model {key!r}, {kind} LPV)",
                             model_parameters=params, **common))
        if getattr(model, "space", None) is not None:
            plans.append(FmuPlan(f"{stem}Scheduler", "Scheduler", "lpvest_scheduler.py",
                                 description=f"Scheduling signal of {title}", **common))
        else:
            notes.append(f"{system.name}: no Scheduler (model {key!r} is scheduled by alpha itself)")
        if getattr(model, "nu", 0) or hasattr(model, "nw"):
            plans.append(FmuPlan(f"{stem}Source", "Source", "lpvest_source.py",
                                 description=f"Input u and disturbance w of {title}", **common))
    for ek in estimator_kinds() if kinds is None else kinds:
        reason = ek.unsupported(model) if ek.applies_to(model) else None
        if reason is not None:
            notes.append(f"{system.name}: model {key!r} gets no {ek.role}: {reason}")
        elif ek.applies_to(model):
            # a filter designed at build time is designed for the model at the
            # file's parameter values: those are then not FMU parameters
            plans.append(FmuPlan(f"{stem}{ek.role}", ek.role, "lpvest_estimator.py",
                                 description=ek.description or f"{ek.role} estimator for {title} (model {key!r})",
                                 model_parameters=() if ek.design else params, estimator=ek,
                                 step_size=plans[0].step_size, stop_time=plans[0].stop_time, **common))
    return plans, notes


# -- the status bridge ------------------------------------------------------------


@functools.cache
def status_bridge() -> Path | None:
    """The compiled status bridge for this platform, or ``None`` when there is
    no C compiler or the platform is not Linux (compiled once per process)."""
    if not sys.platform.startswith("linux"):
        return None
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        return None
    src = Path(__file__).with_name("status_bridge.c")
    out_dir = Path(tempfile.mkdtemp(prefix="lpvest-bridge-"))
    atexit.register(shutil.rmtree, out_dir, True)
    out = out_dir / "status_bridge.so"
    cmd = [*cc.split(), "-shared", "-fPIC", "-O2", "-fvisibility=hidden",
           f'-DINNER_LIBRARY="{_INNER_LIBRARY}"', "-o", str(out), str(src), "-ldl"]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise BuildError(f"compiling the status bridge failed ({' '.join(cmd)}):\n{proc.stderr}")
    return out


# -- building -----------------------------------------------------------------------


def _copy_lpvest(dest: Path) -> str:
    import lpvest

    src = Path(lpvest.__file__).resolve().parent
    shutil.copytree(
        src, dest / "lpvest",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.c", "_models", "_fmus"),
    )
    return lpvest.__version__


def _stage(plan: FmuPlan, staging: Path) -> None:
    import pythonfmu

    shutil.copy2(scripts_dir() / plan.script, staging / plan.script)
    version = _copy_lpvest(staging)
    fmu_pkg = staging / "pythonfmu"
    fmu_pkg.mkdir()
    for f in Path(pythonfmu.__file__).parent.glob("*.py"):
        shutil.copy2(f, fmu_pkg / f.name)
    shutil.copy2(plan.system_path, staging / "model.toml")
    (staging / "slavemodule.txt").write_text(Path(plan.script).stem)
    (staging / "requirements.txt").write_text("\n".join(plan.requirements) + "\n")
    spec: dict[str, Any] = {
        "format": SPEC_FORMAT,
        "identifier": plan.identifier,
        "role": plan.role,
        "description": plan.description,
        "lpvest_version": version,
        "system": plan.system_name,
        "model_file": "model.toml",
        "model_key": plan.model_key,
        "model_parameters": list(plan.model_parameters),
    }
    if plan.estimator is not None:
        spec["estimator"] = plan.estimator.to_json()
        for extra in plan.estimator.files:
            extra = Path(extra)
            if extra.is_dir():
                shutil.copytree(extra, staging / extra.name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            else:
                shutil.copy2(extra, staging / extra.name)
        if plan.estimator.design:
            from ..modelfile import load_system
            from .state import encode_state

            model = load_system(plan.system_path).model(plan.model_key)
            design = resolve(plan.estimator.design)(model)
            if isinstance(design, str):  # a JSON document (e.g. an HinfDesign): kept readable
                (staging / "design.json").write_text(design, encoding="utf-8")
                spec["design_format"] = "text"
            else:
                (staging / "design.json").write_bytes(encode_state(design))
            spec["design_file"] = "design.json"
    (staging / SPEC_FILE).write_text(json.dumps(spec, indent=2))


def _slave_class(script: Path) -> type:
    from pythonfmu import Fmi2Slave

    name = f"_lpvest_fmu_{script.stem}_{uuid.uuid4().hex}"
    spec = importlib.util.spec_from_file_location(name, script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    classes = [c for c in vars(module).values()
               if isinstance(c, type) and issubclass(c, Fmi2Slave) and c.__module__ == name]
    if len(classes) != 1:
        raise BuildError(f"{script.name} must define exactly one Fmi2Slave class; found {len(classes)}")
    return classes[0]


def _model_description(plan: FmuPlan, staging: Path) -> tuple[bytes, int, int, int]:
    from pythonfmu.default_experiment import DefaultExperiment

    # as at run time, resources/ is on sys.path while the slave is instantiated
    sys.path.insert(0, str(staging))
    try:
        cls = _slave_class(staging / plan.script)
        slave = cls(instance_name="lpvest-build", resources=str(staging))
    finally:
        sys.path.remove(str(staging))
        for name, module in list(sys.modules.items()):
            if str(getattr(module, "__file__", "") or "").startswith(str(staging)):
                del sys.modules[name]
    slave.default_experiment = DefaultExperiment(start_time=0.0, stop_time=plan.stop_time, step_size=plan.step_size)
    options = {
        "needsExecutionTool": True,  # a Python interpreter
        "canHandleVariableCommunicationStepSize": True,
        "canBeInstantiatedOnlyOncePerProcess": False,
        "canGetAndSetFMUstate": True,
        "canSerializeFMUstate": True,
    }
    root: Element = slave.to_xml(options)
    meta = slave.fmi_metadata()
    variables = root.find("ModelVariables")
    assert variables is not None
    counts = {"input": 0, "output": 0, "parameter": 0}
    for sv in variables.findall("ScalarVariable"):
        vr = int(sv.get("valueReference", "-1"))
        counts[sv.get("causality", "local")] = counts.get(sv.get("causality", "local"), 0) + 1
        lo, hi = meta["ranges"].get(vr, (None, None))
        typ = next(iter(sv))
        if lo is not None:
            typ.set("min", repr(float(lo)) if typ.tag == "Real" else str(int(lo)))
        if hi is not None:
            typ.set("max", repr(float(hi)) if typ.tag == "Real" else str(int(hi)))
    structure = root.find("ModelStructure")
    assert structure is not None
    outputs = structure.find("Outputs")
    if outputs is not None:
        initial = SubElement(structure, "InitialUnknowns")
        for unknown in outputs.findall("Unknown"):
            vr = int(unknown.get("index", "0")) - 1
            deps = meta["dependencies"].get(vr)
            if deps is not None:
                unknown.set("dependencies", " ".join(str(d + 1) for d in deps))
            SubElement(initial, "Unknown", {"index": unknown.get("index", "")})
    xml = parseString(tostring(root, "UTF-8")).toprettyxml(encoding="UTF-8")
    return xml, counts["input"], counts["output"], counts["parameter"]


def build_fmu(plan: FmuPlan, out_dir: str | Path) -> Path:
    """Build one FMU into ``out_dir`` (``<identifier>.fmu``); returns its path."""
    import pythonfmu

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{plan.identifier}.fmu"
    bridge = status_bridge()
    binaries = Path(pythonfmu.__file__).parent / "resources" / "binaries"
    with tempfile.TemporaryDirectory(prefix="lpvest-fmu-") as tmp:
        staging = Path(tmp) / "resources"
        staging.mkdir()
        _stage(plan, staging)
        xml, *_ = _model_description(plan, staging)
        partial = out / f".{plan.identifier}.fmu.part"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", xml)
            for f in sorted(staging.rglob("*")):
                if f.is_file() and "__pycache__" not in f.parts:
                    z.write(f, "resources/" + f.relative_to(staging).as_posix())
            for lib in sorted(binaries.rglob("*")):
                if not lib.is_file() or lib.suffix not in (".so", ".dll", ".dylib"):
                    continue
                platform = lib.parent.name
                name = f"binaries/{platform}/{plan.identifier}{lib.suffix}"
                if platform == "linux64" and bridge is not None:
                    z.write(bridge, name)
                    z.write(lib, f"binaries/{platform}/{_INNER_LIBRARY}")
                else:
                    z.write(lib, name)
        partial.replace(target)
    return target


def _systems(sources: Iterable[str | Path] | None) -> list[str | Path]:
    if sources is not None:
        return list(sources)
    from ..catalog import example_systems

    return [e.path for e in example_systems()]


def build_fmus(
    sources: Iterable[str | Path] | None = None,
    out_dir: str | Path = DEFAULT_OUT,
    *,
    kinds: Sequence[EstimatorKind] | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[BuildResult], list[str]]:
    """Build and validate the FMUs of the given system files (default: every
    example system). Returns the results and the planning notes."""
    results: list[BuildResult] = []
    notes: list[str] = []
    for source in _systems(sources):
        plans, more = plan_system(source, kinds=kinds)
        notes += more
        for plan in plans:
            if progress is not None:
                progress(plan.identifier)
            path = build_fmu(plan, out_dir)
            results.append(BuildResult(plan, validate_fmus([path])[0]))
    return results, notes


# -- validation ----------------------------------------------------------------------


def validate_fmus(paths: Iterable[str | Path]) -> list[ValidationResult]:
    """Check each FMU with ``fmpy.validation.validate_fmu`` (any problem is
    reported; a file that cannot be read is one problem)."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    out = []
    for p in paths:
        path = Path(p)
        if not path.is_file():
            out.append(ValidationResult(path, 0, 0, 0, 0, [f"{path}: no such file"]))
            continue
        problems = list(validate_fmu(str(path)))
        n_in = n_out = n_par = 0
        try:
            md = read_model_description(str(path))
            causes = [v.causality for v in md.modelVariables]
            n_in, n_out, n_par = causes.count("input"), causes.count("output"), causes.count("parameter")
            if md.coSimulation is None:
                problems.append("the FMU does not support co-simulation")
        except Exception as exc:  # noqa: BLE001 - reported as a problem
            problems.append(f"cannot read the model description: {exc}")
        out.append(ValidationResult(path, n_in, n_out, n_par, path.stat().st_size, problems))
    return out


def format_table(results: Sequence[ValidationResult]) -> str:
    """The table ``FMU | variables | size | validation``, then every problem."""
    rows = [("FMU", "variables (in/out/par)", "size", "validation")]
    for r in results:
        rows.append((
            r.name,
            f"{r.inputs + r.outputs + r.parameters} ({r.inputs}/{r.outputs}/{r.parameters})",
            f"{r.size / 1024:.0f} KiB",
            "ok" if r.ok else f"{len(r.problems)} problem(s)",
        ))
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    for r in results:
        lines += [f"{r.name}: {p}" for p in r.problems]
    return "\n".join(lines)
