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
  (:mod:`lpvest.fmi`).

How an FMU is made (pythonfmu 0.7 conventions, done here so that the model
description can be completed): a staging folder becomes ``resources/``: the
FMU's private package (:mod:`lpvest.fmi`: the modules of lpvest its
role script and factory import, under a build-unique name, with pythonfmu's
Python files, and the entry module named in ``slavemodule.txt``), the model
file, the spec ``lpvest_fmu.json``, an optional design (a given design file
is carried byte for byte; none is solved then), ``requirements.txt`` (from
the bundle) and ``manifest.json`` (every input and its SHA-256). The slave is
instantiated once from that folder to write the model description
(pythonfmu's ``to_xml``), which is then completed: declared ``min``/``max``,
the inputs each output depends on, ``InitialUnknowns`` (pythonfmu writes
none), ``variability="discrete"`` for the outputs of a discrete-time
component, a GUID derived from the manifest and no time stamp.
``binaries/linux64/<id>.so`` and ``binaries/win64/<id>.dll`` are the lpvest
status bridge (``status_bridge.c``) in front of pythonfmu's export library
(``lpvest-pythonfmu-export.so``/``.dll`` next to it): compiled here with the
C compiler for Linux, and cross-compiled with zig (the ``ziglang`` package of
the ``build`` extra) for Windows, or for Linux where no C compiler is. Without
a compiler for a platform, pythonfmu's library is used as is there, and the
build says so once (:class:`BuildWarning`): bad input then shows as
fmi2Discard at the next fmi2DoStep, and a Python exception as fmi2Fatal.
pythonfmu 0.7 ships no macOS binary, so an FMU has none.

Reproducible: the same inputs (model file, design, lpvest code, options,
pythonfmu, compilers) give a byte-identical ``.fmu``: zip entries in sorted
order with a fixed time stamp and permissions, no absolute path, no host name,
no time.

Examples
--------
>>> plans, skipped = plan_system("peixoto-ex1")
>>> [p.identifier for p in plans], skipped
(['PeixotoEx1Plant', 'PeixotoEx1Scheduler', 'PeixotoEx1Source', 'PeixotoEx1HinfPD', 'PeixotoEx1HinfRobust'], [])
>>> build_fmu(plans[0], "out")                                  # doctest: +SKIP
PosixPath('out/PeixotoEx1Plant.fmu')
"""

from __future__ import annotations

import atexit
import dataclasses
import functools
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict
from xml.dom.minidom import parseString
from xml.etree.ElementTree import Element, SubElement, tostring

from .._version import __version__
from ..core._errors import ArgumentError, LpvestError
from ..core._paths import user_cache_dir
from ._bundle import Bundle, SourceRoot, make_bundle
from ._naming import fmu_name
from ._parameters import GUID_FILE, SPEC_FILE, SPEC_FORMAT
from ._registry import EstimatorKind, estimator_kinds, resolve

if TYPE_CHECKING:
    from ._slave import LpvestSlave

__all__ = [
    "known_roles",
    "FmuPlan",
    "BuildResult",
    "BuildError",
    "ValidationResult",
    "plan_system",
    "build_fmu",
    "build_fmus",
    "validate_fmus",
    "format_table",
    "scripts_dir",
    "status_bridge",
    "bridge_note",
    "zig_version",
    "BuildWarning",
    "BRIDGE_PLATFORMS",
    "manifest_inputs",
    "write_zip_entry",
    "DEFAULT_OUT",
    "MANIFEST_FILE",
    "GUID_FILE",
]

#: Default output folder of ``build_fmus.py`` / ``lpvest build`` (ignored by git).
DEFAULT_OUT = "fmu-build"

#: The manifest in an FMU's resources folder: every input of the build and its SHA-256.
MANIFEST_FILE = "manifest.json"

#: The lpvest package an FMU carries modules of (this one).
_PACKAGE_DIR = Path(__file__).resolve().parent.parent
_MANIFEST_FORMAT = "lpvest-fmu-manifest-1"
#: Time stamp of every zip entry (the zip format's earliest date): builds do not depend on the clock.
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


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


class _PlanSource(TypedDict):
    """The fields of an :class:`FmuPlan` that every plan of one system shares."""

    system_path: Path
    system_name: str
    model_key: str


@dataclass(frozen=True)
class FmuPlan:
    """One FMU to build.

    Parameters
    ----------
    identifier : str
        The FMU's model identifier and file stem (``PeixotoEx1Plant``).
    role : str
        ``Plant``, ``Scheduler``, ``Source`` or an estimator kind's role.
    script : str
        File name of the role's slave script in :func:`scripts_dir`.
    system_path : Path
        The model file the FMU carries.
    system_name : str
        The system's name.
    model_key : str
        The model of the file the FMU runs.
    description : str
        The model description's ``description``.
    model_parameters : tuple of str, default ()
        The system file's parameters that become FMU parameters.
    requirements : tuple of str, default ()
        Third-party packages the role imports inside functions (module-level
        imports are found by the bundler).
    estimator : EstimatorKind or None, default None
        The estimator kind of an estimator role; None for the others.
    step_size : float, default 1.0
        The default experiment's step, which is the sample time of a
        discrete-time component.
    stop_time : float, default 100.0
        The default experiment's stop time.
    design : Path or None, default None
        A design file to carry instead of solving one at build time.
    design_options : tuple of (str, object), default ()
        Keyword arguments of the estimator's design function (``epsilon``,
        ``solver``), sorted by name.
    design_cache : Path or None, default None
        Folder of designs made at build time, reused by a rebuild; None: none
        kept.
    """

    identifier: str
    role: str
    script: str
    system_path: Path
    system_name: str
    model_key: str
    description: str
    model_parameters: tuple[str, ...] = ()
    requirements: tuple[str, ...] = ()
    estimator: EstimatorKind | None = None
    step_size: float = 1.0
    stop_time: float = 100.0
    design: Path | None = None
    #: keyword arguments of the estimator's design function (``epsilon``, ``solver``)
    design_options: tuple[tuple[str, object], ...] = ()
    #: folder of designs made at build time, reused by a rebuild (``None``: none kept)
    design_cache: Path | None = None


@dataclass(frozen=True)
class ValidationResult:
    """An FMU checked with ``fmpy.validation.validate_fmu``.

    Parameters
    ----------
    path : Path
        The FMU.
    inputs, outputs, parameters : int
        Its number of variables of each causality (0 when the model
        description cannot be read).
    size : int
        The file's size in bytes (0 for a file that is missing or not built).
    problems : list of str, default []
        What the validation found; empty for a valid FMU (:attr:`ok`).
    """

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
    """A plan, the FMU built from it, and its validation.

    Parameters
    ----------
    plan : FmuPlan
        What was to be built.
    validation : ValidationResult
        The FMU's validation; for an FMU that could not be built, its
        ``problems`` say why.
    """

    plan: FmuPlan
    validation: ValidationResult


# -- planning -----------------------------------------------------------------


def _estimator_step(kind: EstimatorKind, default: float) -> float:
    if kind.sample_time is None:
        return default
    for par in kind.parameters:
        if par.name == kind.sample_time:
            return float(par.start)
    raise BuildError(f"estimator {kind.role}: sample_time names {kind.sample_time!r}, which is not a parameter")


def known_roles() -> list[str]:
    """Every FMU role a build can make: the plant, its signal sources and each
    estimator kind (:func:`lpvest.fmi._build.estimator_kinds`)."""
    from ._registry import estimator_kinds

    return ["Plant", "Scheduler", "Source", *(k.role for k in estimator_kinds())]


def plan_system(
    source: str | Path,
    *,
    kinds: Sequence[EstimatorKind] | None = None,
    designs: Mapping[str, str | Path] | None = None,
) -> tuple[list[FmuPlan], list[str]]:
    """The FMUs to build for a system file (or an example's name), and notes on
    roles left out and why.

    Parameters
    ----------
    source : str or Path
        A system file, or the name of an example system (``"peixoto-ex1"``).
    kinds : sequence of EstimatorKind or None, optional
        The estimator kinds to plan for; None: every registered kind.
    designs : mapping of str to str or Path, or None, optional
        Maps a role (``HinfPD``) to a design file the FMU carries instead of
        solving at build time; without one, an example system's stored
        design (:func:`lpvest.systems.stored_design`) is used when there is
        one (and fits the plant).

    Returns
    -------
    plans : list of FmuPlan
        The plant first, then its Scheduler and Source when it has them, then
        the estimators; empty when no model of the file can be a plant.
    notes : list of str
        One line per role left out, and why.

    Raises
    ------
    ModelFileError
        No such file or example, or the file is not a valid model file.
    BuildError
        The system has no model file, a design was given for a role the
        system does not get, or an estimator kind names a sample-time
        parameter it does not have.
    """
    from ..systems import AffineLPV, InnovationLPV, LPVInputOutput, LTVInputOutput, LTVStateSpace, PolytopicLPV
    from ..systems._catalog import stored_design
    from ..systems._modelfile import load_system
    from ..systems._streaming import plant_supports

    system = load_system(source)
    if system.path is None:
        raise BuildError(f"{source}: a system needs a model file to be built into FMUs")
    stem = fmu_name(system.name)
    notes: list[str] = []
    # the default model, else the others in file order, state-space realizations
    # before input-output ones (a plant's state x is then the model's state)
    others = [k for k in system.models if k != system.default]
    order = [system.default] + sorted(others, key=lambda k: isinstance(system.models[k], LPVInputOutput))
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
    common = _PlanSource(system_path=system.path, system_name=system.name, model_key=key)
    plans: list[FmuPlan] = []
    if isinstance(model, LTVStateSpace | LTVInputOutput):
        plans.append(FmuPlan(f"{stem}Plant", "Plant", "lpvest_ltv_plant.py",
                             description=f"Plant: {title} (model {key!r}, continuous-time LTV)",
                             model_parameters=params, requirements=("scipy",),
                             step_size=0.1, stop_time=20.0, **common))
        notes.append(f"{system.name}: no Scheduler/Source (an LTV model depends on time; its input is a function of t)")
    else:
        kind = {PolytopicLPV: "polytopic", AffineLPV: "affine", InnovationLPV: "innovation",
                LPVInputOutput: "input-output"}[type(model)]
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
    given = {role: Path(path) for role, path in (designs or {}).items()}
    for ek in estimator_kinds() if kinds is None else kinds:
        reason = ek.unsupported(model) if ek.applies_to(model) else None
        if reason is not None:
            notes.append(f"{system.name}: model {key!r} gets no {ek.role}: {reason}")
        elif ek.applies_to(model):
            design = None
            if ek.design:
                design = given.pop(ek.role, None)
                if design is None:
                    design = stored_design(system.name, ek.role)
                    if design is not None and not _design_fits(design, model):
                        notes.append(f"{system.name}: the stored design {design.name} is for another plant; "
                                     f"{ek.role} is designed at build time")
                        design = None
            # a filter designed at build time is designed for the model at the
            # file's parameter values: those are then not FMU parameters
            plans.append(FmuPlan(f"{stem}{ek.role}", ek.role, "lpvest_estimator.py",
                                 description=ek.description or f"{ek.role} estimator for {title} (model {key!r})",
                                 model_parameters=() if ek.design else params, estimator=ek,
                                 requirements=tuple(ek.requirements),
                                 step_size=_estimator_step(ek, plans[0].step_size),
                                 stop_time=plans[0].stop_time, design=design, **common))
    if given:
        raise BuildError(f"{system.name}: a design was given for {', '.join(sorted(given))}, which this system "
                         "does not get (no such H-infinity filter role)")
    return plans, notes


def _design_fits(path: Path, model: object) -> bool:
    from ..core._errors import ModelFileError
    from ..design._result import HinfDesign
    from ..systems._polytopic import hinf_setting

    try:
        HinfDesign.from_json(path).check_model(hinf_setting(model), source=str(path))
    except ModelFileError:
        return False
    return True


# -- the status bridge ------------------------------------------------------------


#: The platforms (pythonfmu's folder names) the status bridge is built for, and zig's target for each.
BRIDGE_PLATFORMS: dict[str, str] = {"linux64": "x86_64-linux-gnu", "win64": "x86_64-windows-gnu"}
_SUFFIX = {"linux64": ".so", "win64": ".dll"}


class BuildWarning(UserWarning):
    """An FMU was built without a part it normally carries (the message says
    what is missing and what the FMU then lacks)."""


def _inner_library(platform: str) -> str:
    """The file name of pythonfmu's library behind the bridge in ``binaries/<platform>/``."""
    return "lpvest-pythonfmu-export" + _SUFFIX[platform]


def _cc() -> str | None:
    return os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")


@functools.cache
def zig_program() -> str | None:
    """The ``zig`` program of the ``ziglang`` package (the ``build`` extra; what
    ``python -m ziglang`` runs, called directly: no Python start per compiler
    call), or ``None`` when it is not installed."""
    import importlib.util

    spec = importlib.util.find_spec("ziglang")
    if spec is None or spec.origin is None:
        return None
    program = Path(spec.origin).parent / ("zig.exe" if sys.platform == "win32" else "zig")
    return str(program) if program.is_file() else None


def _zig_identity(lib: Path) -> str:
    """What the ``lib`` folder holds: the lines of the ``ziglang`` package's RECORD
    for the files under ``ziglang/lib/`` (each one's hash; see :func:`lib_record`),
    or, without a RECORD, every file's path and size."""
    import importlib.metadata

    try:
        record = importlib.metadata.distribution("ziglang").read_text("RECORD")
    except importlib.metadata.PackageNotFoundError:
        record = None
    lines = lib_record(record) if record else ""
    if lines:
        return lines
    return json.dumps(sorted((p.relative_to(lib).as_posix(), p.stat().st_size) for p in lib.rglob("*")
                             if p.is_file()))


def lib_record(record: str) -> str:
    """The lines of a ``ziglang`` RECORD that name a file of ``ziglang/lib/`` with
    its hash, sorted: the same in every environment with the same zig. The whole
    RECORD is not: it holds the ``python-zig`` launcher, whose hash covers the
    environment's own interpreter path, and bytecode files listed without a hash
    when pip compiled them."""
    kept = []
    for line in record.splitlines():
        path, _, rest = line.strip().partition(",")
        if path.startswith("ziglang/lib/") and rest.partition(",")[0]:  # a file with its hash
            kept.append(line.strip())
    return "\n".join(sorted(kept))


@functools.cache
def _zig_lib_dir() -> Path | None:
    """A copy of the ``ziglang`` package's ``lib`` folder at a path that stays the
    same for the same zig: ``$XDG_CACHE_HOME/lpvest/zig-lib/<version>-<digest>``
    (hard links where the file system allows, else a copy; made once, under a
    temporary name renamed into place, so no process sees half of it), or
    ``None`` when it cannot be made.

    zig keys what it compiled from its own ``lib`` folder (the C runtimes of
    Windows, macOS and Linux it builds on first use) by that folder's absolute
    path: each new virtual environment would build them again, about 75 s of
    CPU and 40 MB of zig's cache for the Windows one alone. Pointed at this
    folder (``ZIG_LIB_DIR``, see :func:`zig_environment`), every environment
    with the same zig reuses them. The digest covers every file's content (the
    package's RECORD of hashes), so a changed ``lib`` folder gets a folder of its own."""
    program = zig_program()
    version = zig_version()
    if program is None or version is None:
        return None
    lib = Path(program).parent / "lib"
    try:
        digest = hashlib.sha256(_zig_identity(lib).encode()).hexdigest()[:16]
        target = user_cache_dir("zig-lib", f"{version}-{digest}")
        if target.is_dir():
            return target
        target.parent.mkdir(parents=True, exist_ok=True)
        part = Path(tempfile.mkdtemp(prefix=f".{target.name}-", dir=target.parent))
        try:
            try:
                shutil.copytree(lib, part, dirs_exist_ok=True, copy_function=os.link)
            except OSError:  # another file system: a copy (about 240 MB, once per zig)
                shutil.copytree(lib, part, dirs_exist_ok=True)
            try:
                part.rename(target)
            except OSError:  # another process was first: its copy serves
                if not target.is_dir():
                    raise
        finally:
            shutil.rmtree(part, ignore_errors=True)
        return target
    except OSError:
        return None


def zig_environment() -> dict[str, str]:
    """The environment to run :func:`zig_program` in: this process's, with
    ``ZIG_LIB_DIR`` set to :func:`_zig_lib_dir`'s folder (unless the user set
    it), so that zig's cache serves every virtual environment."""
    env = dict(os.environ)
    if "ZIG_LIB_DIR" not in env:
        lib = _zig_lib_dir()
        if lib is not None:
            env["ZIG_LIB_DIR"] = str(lib)
    return env


@functools.cache
def zig_version() -> str | None:
    """The version of the ``ziglang`` package's compiler (the ``build`` extra),
    or ``None`` when it is not installed."""
    program = zig_program()
    if program is None:
        return None
    proc = subprocess.run([program, "version"], capture_output=True, text=True, check=False)
    return proc.stdout.strip() if proc.returncode == 0 and proc.stdout.strip() else None


def _bridge_command(platform: str, src: Path, out: Path) -> tuple[list[str], str] | None:
    """The command that compiles the bridge for ``platform`` and a description
    of its compiler (recorded in the manifest), or ``None``: on Linux the C
    compiler for linux64, else zig (:func:`zig_program`'s ``cc``) for any target."""
    inner = f'-DINNER_LIBRARY="{_inner_library(platform)}"'
    cc = _cc() if platform == "linux64" and sys.platform.startswith("linux") else None
    if cc is not None:
        # -ffile-prefix-map and no -g: nothing of the build folder ends up in the binary
        return ([*cc.split(), "-shared", "-fPIC", "-O2", "-fvisibility=hidden", f"-ffile-prefix-map={src.parent}=.",
                 inner, "-o", str(out), str(src), "-ldl", "-lpthread"], _compiler_version())
    zig, program = zig_version(), zig_program()
    if zig is None or program is None:
        return None
    # zig's output depends on its version, the flags and the source only (checked byte for byte by
    # tests/test_fmu_isolation.py, test_the_same_inputs_give_a_byte_identical_fmu); -s: no debug
    # information, no program database
    cmd = [program, "cc", "-target", BRIDGE_PLATFORMS[platform], "-shared", "-O2", "-s",
           inner, "-o", str(out), str(src)]
    if platform == "linux64":
        cmd[-4:-4] = ["-fPIC", "-fvisibility=hidden"]
        cmd += ["-ldl", "-lpthread"]
    return cmd, f"zig {zig}"


@functools.cache
def _compile_bridge(platform: str) -> tuple[Path, str] | None:
    src = Path(__file__).with_name("status_bridge.c")
    out_dir = Path(tempfile.mkdtemp(prefix="lpvest-bridge-"))
    atexit.register(shutil.rmtree, out_dir, True)
    out = out_dir / f"status_bridge{_SUFFIX[platform]}"
    found = _bridge_command(platform, src, out)
    if found is None:
        return None
    cmd, compiler = found
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=out_dir,
                          env=zig_environment() if cmd[0] == zig_program() else None)
    if proc.returncode != 0 or not out.is_file():
        raise BuildError(f"compiling the status bridge for {platform} failed ({' '.join(cmd)}):\n{proc.stderr}")
    return out, compiler


def status_bridge(platform: str = "linux64") -> Path | None:
    """The status bridge (``status_bridge.c``) compiled for ``platform``
    (``linux64`` or ``win64``), or ``None`` when no compiler for it is at hand:
    linux64 needs a C compiler on Linux or ziglang, win64 ziglang (the
    ``build`` extra). Compiled once per process."""
    if platform not in BRIDGE_PLATFORMS:
        raise ArgumentError(f"platform {platform!r}: the status bridge is built for "
                            f"{', '.join(BRIDGE_PLATFORMS)} only")
    found = _compile_bridge(platform)
    return None if found is None else found[0]


def _bridge_compiler(platform: str) -> str | None:
    found = _compile_bridge(platform)
    return None if found is None else found[1]


#: What an FMU lacks on a platform whose binary is pythonfmu's library as is.
_WITHOUT_BRIDGE = ("its {platform} binary is pythonfmu's library as is, without lpvest's status bridge: there "
                   "a rejected input returns fmi2OK and shows as fmi2Discard at the next fmi2DoStep, a refused "
                   "step is fmi2Discard (then reported as terminated), and with the tool's logging off no "
                   "message is shown (docs/fmus.md, 6.)")


def bridge_note(platform: str) -> str | None:
    """Why the FMUs built here lack the status bridge on ``platform`` and what
    they then lack, or ``None`` when they carry it."""
    if status_bridge(platform) is not None:
        return None
    if platform == "win64":
        missing = "the C cross compiler for Windows is missing (pip install 'lpvest[build]' installs ziglang)"
    elif sys.platform.startswith("linux"):
        missing = "no C compiler (cc, gcc or $CC) and no ziglang (pip install 'lpvest[build]')"
    else:
        missing = "not on Linux and no ziglang to cross-compile (pip install 'lpvest[build]')"
    return f"{missing}: " + _WITHOUT_BRIDGE.format(platform=platform)


@functools.cache
def _warn_without_bridge(platform: str) -> None:
    """Say once per process, as a :class:`BuildWarning`, what an FMU lacks without the bridge."""
    import warnings

    note = bridge_note(platform)
    if note is not None:
        warnings.warn(note, BuildWarning, stacklevel=4)


@functools.cache
def _compiler_version() -> str:
    cc = _cc()
    if not cc:
        return "none"
    proc = subprocess.run([*cc.split(), "--version"], capture_output=True, text=True, check=False)
    return proc.stdout.splitlines()[0] if proc.returncode == 0 and proc.stdout else cc


# -- building -----------------------------------------------------------------------


def _roots(plan: FmuPlan) -> list[SourceRoot]:
    import pythonfmu

    roots = [
        SourceRoot("lpvest", _PACKAGE_DIR, "", skip=("_models",)),
        SourceRoot("lpvest._fmus", scripts_dir(), "_fmus"),
        SourceRoot("pythonfmu", Path(pythonfmu.__file__).resolve().parent, "_pythonfmu"),
    ]
    if plan.estimator is not None:
        for extra in plan.estimator.files:
            extra = Path(extra)
            name = extra.stem if extra.is_file() else extra.name
            if not name.isidentifier():
                raise BuildError(f"{extra}: an estimator module needs a name that is a Python identifier")
            roots.append(SourceRoot(name, extra.resolve(), f"_ext.{name}"))
    return roots


def slave_class_name(script: Path) -> str:
    """The one slave class a role script defines (its name)."""
    import ast

    tree = ast.parse(script.read_text(encoding="utf-8"), str(script))
    classes = [n.name for n in tree.body if isinstance(n, ast.ClassDef)]
    if len(classes) != 1:
        raise BuildError(f"{script.name} must define exactly one slave class; found {len(classes)}")
    return classes[0]


def _bundle(plan: FmuPlan) -> Bundle:
    script = scripts_dir() / plan.script
    start = [f"lpvest._fmus.{Path(plan.script).stem}"]
    if plan.estimator is not None:
        start.append(plan.estimator.factory.partition(":")[0])
    return make_bundle(identifier=plan.identifier, script=Path(plan.script).stem,
                       slave_class=slave_class_name(script), start=start, roots=_roots(plan),
                       version=__version__, declared=plan.requirements)


def design_text(plan: FmuPlan, progress: Callable[[str], None] | None) -> tuple[str | bytes, str]:
    """The design the FMU carries (text or bytes) and where it came from: the
    plan's design file (checked against the model), a design kept from an
    earlier build, or one made now."""
    from ..design._result import without_timings
    from ..systems._modelfile import load_system
    from ._state import encode_state

    assert plan.estimator is not None and plan.estimator.design is not None
    model = load_system(plan.system_path).model(plan.model_key)
    if plan.design is not None:
        text = _check_design_file(plan, model)
        return text, f"file {plan.design.name}"  # carried as given: the same file, the same bytes
    options = dict(plan.design_options)
    settings = "".join(f", {k} = {v}" for k, v in sorted(options.items()))
    origin = f"designed at build time by {plan.estimator.design}{settings}"
    cached = _design_cache_file(plan)
    if cached is not None and cached.is_file():
        text = cached.read_text(encoding="utf-8")
        if progress is not None:
            progress(f"{plan.identifier}: design reused from {cached}{_design_summary(text)}")
        return without_timings(text), origin
    if progress is not None:
        progress(f"{plan.identifier}: designing ({plan.estimator.design}{settings})")
    design = resolve(plan.estimator.design)(model, progress=progress is not None, **options)
    made: str | bytes = design if isinstance(design, str) else encode_state(design)
    if progress is not None and isinstance(made, str):
        progress(f"{plan.identifier}: designed{_design_summary(made)}")
    if cached is not None and isinstance(made, str):
        cached.parent.mkdir(parents=True, exist_ok=True)
        partial = cached.with_suffix(".part")
        partial.write_text(made, encoding="utf-8")
        partial.replace(cached)  # with the solver's timings; the FMU carries the design without them
    return without_timings(made) if isinstance(made, str) else made, origin


def _design_summary(text: str) -> str:
    """``": gamma = ..., epsilon = ..., solver ... (... s)"`` of an H-infinity design's
    JSON text; empty for another format."""
    try:
        data = json.loads(text)
        eps = "inf" if data["epsilon"] is None else f"{data['epsilon']:.6g}"
        solver = data["solver"]
        seconds = f", {solver['solve_time']:.1f} s" if "solve_time" in solver else ""
        return f": gamma = {data['gamma']:.7g} at epsilon = {eps} ({solver['name']}{seconds})"
    except (ValueError, KeyError, TypeError):
        return ""


def _check_design_file(plan: FmuPlan, model: object = None) -> str:
    """The text of ``plan.design``, checked against the plan's model (its
    dimensions and digest); :class:`BuildError` or the design's own error."""
    from ..design._result import HinfDesign
    from ..systems._modelfile import load_system
    from ..systems._polytopic import hinf_setting

    assert plan.design is not None
    try:
        text = plan.design.read_text(encoding="utf-8")
    except OSError as exc:
        raise BuildError(f"{plan.design}: cannot be read: {exc.strerror}") from exc
    if model is None:
        model = load_system(plan.system_path).model(plan.model_key)
    HinfDesign.from_json(text).check_model(hinf_setting(model), source=str(plan.design), plant_name=plan.system_name)
    return text


def _design_cache_file(plan: FmuPlan) -> Path | None:
    """Where a design made at build time for ``plan`` is kept: named by the
    SHA-256 of what determines it (the model file's bytes, the model, the
    design function and its options, the lpvest version)."""
    if plan.design_cache is None or plan.estimator is None:
        return None
    key = json.dumps({"model_file_sha256": sha256_hex(Path(plan.system_path).read_bytes()), "model_key": plan.model_key,
                      "design": plan.estimator.design, "options": sorted(map(list, plan.design_options)),
                      "lpvest_version": __version__}, sort_keys=True, default=str)
    return plan.design_cache / f"{plan.identifier}-{sha256_hex(key.encode())[:16]}.json"


def manifest_inputs_version() -> str:
    """The version of the lpvest an FMU carries (this one)."""
    return __version__


def plan_inputs(plan: FmuPlan, design: str | bytes | None = None, *, requirements: bool) -> dict[str, object]:
    """The inputs of a build that both backends' manifests record, in this
    order: the plan, the estimator (with its Python ``requirements`` when
    asked: the native backend carries none), lpvest's version, and the
    SHA-256 of the model file and of the carried ``design``. No path, no time.

    Parameters
    ----------
    plan : FmuPlan
        The FMU to build.
    design : str or bytes, optional
        The design the FMU carries.
    requirements : bool
        Record the estimator's Python requirements.

    Returns
    -------
    dict
        The manifest entries, in the order the manifests write them.
    """
    est = None
    if plan.estimator is not None:
        est = plan.estimator.to_json() | {"design": plan.estimator.design, "models": list(plan.estimator.models)}
        if requirements:
            est["requirements"] = list(plan.estimator.requirements)
        if plan.design_options:
            est["design_options"] = {k: v for k, v in sorted(plan.design_options)}
    return {
        "identifier": plan.identifier,
        "role": plan.role,
        "system": plan.system_name,
        "model_key": plan.model_key,
        "description": plan.description,
        "model_parameters": list(plan.model_parameters),
        "step_size": plan.step_size,
        "stop_time": plan.stop_time,
        "estimator": est,
        "lpvest_version": __version__,
        "model_file_sha256": sha256_hex(Path(plan.system_path).read_bytes()),
        "design_sha256": None if design is None else sha256_hex(design.encode() if isinstance(design, str) else design),
    }


def manifest_inputs(
    plan: FmuPlan, bundle: Bundle | None = None, design: str | bytes | None = None
) -> dict[str, object]:
    """Every input of an FMU's build and its SHA-256 (what ``manifest.json``
    records and what an FMU cache compares): the plan, the model file, the
    carried code (the bundle digest), the design when one is carried, and the
    versions of pythonfmu and the C compiler. No path, no time."""
    import pythonfmu

    bundle = bundle or _bundle(plan)
    bridges = {}
    for platform in BRIDGE_PLATFORMS:
        bridge = status_bridge(platform)
        bridges[platform] = None if bridge is None else {"sha256": sha256_hex(bridge.read_bytes()),
                                                          "compiler": _bridge_compiler(platform)}
    return {
        **plan_inputs(plan, design, requirements=True),
        "design_file_sha256": None if plan.design is None else sha256_hex(plan.design.read_bytes()),
        "bundle": {"package": bundle.package, "digest": bundle.digest, "requirements": list(bundle.requirements)},
        "pythonfmu": pythonfmu.__version__,
        "status_bridges": bridges,
        "python": f"{sys.version_info.major}.{sys.version_info.minor}",
    }


def _stage(plan: FmuPlan, staging: Path, progress: Callable[[str], None] | None) -> tuple[Bundle, dict[str, object]]:
    """Write ``resources/`` into ``staging``; returns the bundle and the manifest."""
    bundle = _bundle(plan)
    for rel, data in bundle.files.items():
        target = staging / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    shutil.copyfile(plan.system_path, staging / "model.toml")
    (staging / "slavemodule.txt").write_text(bundle.entry)
    (staging / "requirements.txt").write_text("".join(r + "\n" for r in bundle.requirements))
    spec: dict[str, object] = {
        "format": SPEC_FORMAT,
        "identifier": plan.identifier,
        "role": plan.role,
        "description": plan.description,
        "lpvest_version": manifest_inputs_version(),
        "package": bundle.package,
        "system": plan.system_name,
        "model_file": "model.toml",
        "model_key": plan.model_key,
        "model_parameters": list(plan.model_parameters),
        "sample_time": plan.step_size,
    }
    design: str | bytes | None = None
    if plan.estimator is not None:
        spec["estimator"] = plan.estimator.to_json() | {"factory": bundle.reference(plan.estimator.factory)}
        if plan.estimator.design:
            design, origin = design_text(plan, progress)
            if isinstance(design, str):  # a JSON document (e.g. an HinfDesign): kept readable
                (staging / "design.json").write_text(design, encoding="utf-8")
                spec["design_format"] = "text"
            else:
                (staging / "design.json").write_bytes(design)
            spec["design_file"] = "design.json"
            spec["design_origin"] = origin
    (staging / SPEC_FILE).write_text(json.dumps(spec, indent=2) + "\n")
    manifest: dict[str, object] = {
        "format": _MANIFEST_FORMAT,
        "inputs": manifest_inputs(plan, bundle, design),
        "modules": list(bundle.modules),
        "imported_only_inside_functions": {k: list(v) for k, v in bundle.lazy_imports.items()},
    }
    return bundle, manifest


def _instantiate(bundle: Bundle, staging: Path) -> LpvestSlave:
    """The slave, instantiated from ``staging`` as pythonfmu would (then unloaded)."""
    import importlib.util

    entry = staging / f"{bundle.entry}.py"
    spec = importlib.util.spec_from_file_location(bundle.entry, entry)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    path_before, meta_before, modules_before = list(sys.path), list(sys.meta_path), set(sys.modules)
    sys.path.insert(0, str(staging))
    try:
        spec.loader.exec_module(module)
        classes = [c for c in vars(module).values() if isinstance(c, type) and c.__module__.startswith(bundle.package)]
        if len(classes) != 1:
            raise BuildError(f"{entry.name} must expose exactly one slave class; found {len(classes)}")
        return classes[0](instance_name="lpvest-build", resources=str(staging))
    finally:
        # unload what this call loaded, and only that: an FMU of the same bundle (the same package
        # name: the same sources) loaded in this process before keeps its modules, else its next
        # deferred import (fmi2Reset runs the constructor again) would load second copies of its
        # classes beside the objects it holds
        sys.path[:] = path_before
        sys.meta_path[:] = meta_before
        for name in list(sys.modules):
            if name not in modules_before and (
                name in (bundle.package, bundle.entry) or name.startswith(bundle.package + ".")
            ):
                del sys.modules[name]


def _model_description(plan: FmuPlan, bundle: Bundle, staging: Path, guid: str) -> tuple[bytes, int, int, int]:
    return model_description_xml(plan, _instantiate(bundle, staging), guid)


def model_description_xml(
    plan: FmuPlan, slave: LpvestSlave, guid: str, *, native: bool = False,
    finish: Callable[[Element], None] | None = None,
) -> tuple[bytes, int, int, int]:
    """The model description of ``plan``'s FMU from its instantiated slave
    (pythonfmu's ``to_xml``, completed: declared ranges, dependencies,
    ``InitialUnknowns``, discrete outputs, ``guid``, no time stamp), and its
    numbers of inputs, outputs and parameters.

    ``native``: the same variables for the native backend's FMU
    (:mod:`lpvest.fmi.native`), which needs no execution tool; ``finish``
    completes the root element before it is written (the native builder lists
    the source files there).
    """
    meta = slave.fmi_metadata()
    from pythonfmu.default_experiment import DefaultExperiment

    slave.default_experiment = DefaultExperiment(start_time=0.0, stop_time=plan.stop_time, step_size=plan.step_size)
    options = {
        "needsExecutionTool": not native,  # a Python interpreter
        # a discrete-time component steps by its sample time only
        "canHandleVariableCommunicationStepSize": meta["timed"] and (
            plan.estimator is None or plan.estimator.sample_time is None),
        "canBeInstantiatedOnlyOncePerProcess": False,
        "canGetAndSetFMUstate": True,
        "canSerializeFMUstate": True,
    }
    root: Element = slave.to_xml(options)
    root.set("guid", guid)
    root.attrib.pop("generationDateAndTime", None)
    root.set("version", str(slave.version or ""))
    variables = root.find("ModelVariables")
    assert variables is not None
    counts = {"input": 0, "output": 0, "parameter": 0}
    sampled = not meta["timed"] or (plan.estimator is not None and plan.estimator.sample_time is not None)
    for sv in variables.findall("ScalarVariable"):
        vr = int(sv.get("valueReference", "-1"))
        causality = sv.get("causality", "local")
        counts[causality] = counts.get(causality, 0) + 1
        if causality == "output" and sampled:
            sv.set("variability", "discrete")  # piecewise constant between samples
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
    if finish is not None:
        finish(root)
    xml = parseString(tostring(root, "UTF-8")).toprettyxml(encoding="UTF-8")
    return xml, counts["input"], counts["output"], counts["parameter"]


def write_fmu_zip(target: Path, entries: Mapping[str, tuple[bytes, bool]]) -> Path:
    """Write an FMU (a zip file) reproducibly: entries sorted by name, a fixed
    time stamp and permissions (``entries``: name -> (bytes, executable)),
    through a partial file renamed at the end."""
    partial = target.with_name(f".{target.name}.part")
    with zipfile.ZipFile(partial, "w") as z:
        for name in sorted(entries):
            data, executable = entries[name]
            write_zip_entry(z, name, data, executable)
    partial.replace(target)
    return target


def sha256_hex(data: bytes) -> str:
    """The SHA-256 of ``data`` in hex (what manifests record)."""
    return hashlib.sha256(data).hexdigest()


def write_zip_entry(z: zipfile.ZipFile, name: str, data: bytes, executable: bool = False) -> None:
    """Write ``data`` as the member ``name`` of ``z`` so that the archive
    depends on nothing but the members and their order: a fixed time stamp
    (1980-01-01), Unix permissions 0644 (0755 when ``executable``), deflate at
    level 6, zlib's default (level 9 made an FMU 0.4 % smaller for two and a half
    times the time: 0.1 s of each FMU build, most of it in the binaries). The FMU builder and the SSP writer
    (:func:`lpvest.cosim.write_ssp`) write every member so.

    Parameters
    ----------
    z : zipfile.ZipFile
        An archive open for writing.
    name : str
        The member's name (``/``-separated).
    data : bytes
        Its content.
    executable : bool, default False
        Mark it executable (a shared library).
    """
    info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.create_system = 3  # Unix: the permissions below are honoured
    info.external_attr = (0o755 if executable else 0o644) << 16
    z.writestr(info, data, compresslevel=6)


#: The FMU backends, by the function that builds one FMU (``"module:function"``, as the
#: estimator registry names factories, so that this module imports neither backend's
#: machinery): ``pythonfmu`` (the default) and ``native`` (C, :mod:`lpvest.fmi.native`).
BACKENDS: dict[str, str] = {
    "pythonfmu": "lpvest.fmi._build:build_fmu",
    "native": "lpvest.fmi.native._build:build_native_fmu",
}
#: ``role, script -> reason or None``: which roles the native backend builds
_NATIVE_SUPPORT = "lpvest.fmi.native._export:native_unsupported"


def check_backend(backend: str) -> str:
    """``backend`` if it is one of :data:`BACKENDS`, else an :class:`ArgumentError` naming them."""
    if backend not in BACKENDS:
        raise ArgumentError(f"backend {backend!r} is not one of {', '.join(BACKENDS)}")
    return backend


def backend_of(plan: FmuPlan, backend: str) -> str:
    """The backend that builds ``plan`` when ``backend`` is asked for: the
    native backend builds every discrete-time role; the continuous-time LTV
    plant and the B-spline observer stay pythonfmu FMUs."""
    if check_backend(backend) == "native" and resolve(_NATIVE_SUPPORT)(plan.role, plan.script) is not None:
        return "pythonfmu"
    return backend


def build_fmu(
    plan: FmuPlan, out_dir: str | Path, *, progress: Callable[[str], None] | None = None, backend: str = "pythonfmu"
) -> Path:
    """Build one FMU into ``out_dir`` (``<identifier>.fmu``); returns its path.

    The same inputs give a byte-identical file (see the module documentation).

    Parameters
    ----------
    plan : FmuPlan
        What to build (:func:`plan_system`).
    out_dir : str or Path
        The output folder (created); the FMU replaces a file of the same name
        only once it is complete.
    progress : callable or None, optional
        Called with a message on the design's progress; None: silent.
    backend : str, default "pythonfmu"
        ``"pythonfmu"`` or ``"native"`` (:data:`BACKENDS`; a role without a
        native runtime is refused there, :func:`backend_of`).

    Returns
    -------
    Path
        The FMU, ``out_dir/<identifier>.fmu``.

    Raises
    ------
    ArgumentError
        ``backend`` is not one of :data:`BACKENDS`.
    BuildError
        The FMU cannot be made (slave scripts missing, a status bridge that
        does not compile, a role the native backend does not build, ...).
    LpvestError
        The plan's design file does not fit the model, or the design made at
        build time fails (e.g. :class:`~lpvest.core.LMIInfeasibleError`).
    """
    if check_backend(backend) != "pythonfmu":
        return Path(resolve(BACKENDS[backend])(plan, out_dir, progress=progress))
    import pythonfmu

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{plan.identifier}.fmu"
    binaries = Path(pythonfmu.__file__).parent / "resources" / "binaries"
    with tempfile.TemporaryDirectory(prefix="lpvest-fmu-") as tmp:
        staging = Path(tmp) / "resources"
        staging.mkdir()
        bundle, manifest = _stage(plan, staging, progress)
        manifest_text = json.dumps(manifest, indent=1, sort_keys=True) + "\n"
        guid = "{" + str(uuid.UUID(hex=sha256_hex(manifest_text.encode())[:32])) + "}"
        xml, *_ = _model_description(plan, bundle, staging, guid)
        (staging / MANIFEST_FILE).write_text(manifest_text, encoding="utf-8")
        # what the status bridge compares the host's GUID with (it has no SHA-256 to derive it)
        (staging / GUID_FILE).write_text(guid + "\n", encoding="ascii")
        entries: dict[str, tuple[bytes, bool]] = {"modelDescription.xml": (xml, False)}
        for f in staging.rglob("*"):
            if f.is_file() and "__pycache__" not in f.parts:
                entries["resources/" + f.relative_to(staging).as_posix()] = (f.read_bytes(), False)
        for lib in binaries.rglob("*"):
            if not lib.is_file() or lib.suffix not in (".so", ".dll", ".dylib"):
                continue
            platform = lib.parent.name
            name = f"binaries/{platform}/{plan.identifier}{lib.suffix}"
            bridge = status_bridge(platform) if platform in BRIDGE_PLATFORMS else None
            if bridge is not None:
                entries[name] = (bridge.read_bytes(), True)
                entries[f"binaries/{platform}/{_inner_library(platform)}"] = (lib.read_bytes(), True)
            else:
                if platform in BRIDGE_PLATFORMS:
                    _warn_without_bridge(platform)
                entries[name] = (lib.read_bytes(), True)
        partial = out / f".{plan.identifier}.fmu.part"
        try:
            with zipfile.ZipFile(partial, "w") as z:
                for name in sorted(entries):
                    data, executable = entries[name]
                    write_zip_entry(z, name, data, executable)
            partial.replace(target)
        except BaseException:  # Ctrl-C, a full disk: no half-written FMU is left behind
            partial.unlink(missing_ok=True)
            raise
    return target


#: Sub-folder of the output folder where designs made at build time are kept.
DESIGN_CACHE = ".designs"


def _systems(sources: Iterable[str | Path] | None) -> list[str | Path]:
    if sources is not None:
        return list(sources)
    from ..systems._catalog import example_systems

    return [e.path for e in example_systems()]


def build_fmus(
    sources: Iterable[str | Path] | None = None,
    out_dir: str | Path = DEFAULT_OUT,
    *,
    kinds: Sequence[EstimatorKind] | None = None,
    roles: Iterable[str] | None = None,
    designs: Mapping[str, str | Path] | None = None,
    progress: Callable[[str], None] | None = None,
    design_options: Mapping[str, object] | None = None,
    backend: str = "pythonfmu",
    bar: bool = False,
) -> tuple[list[BuildResult], list[str]]:
    """Build and validate the FMUs of the given system files (default: every
    example system). Returns the results and the planning notes.

    Designs made at build time are kept in ``out_dir/.designs`` and reused by
    a rebuild with the same model file, options and lpvest version. An FMU
    whose design fails at build time (no certified design, ...) is a result
    with the reason as its problem; the others are built and validated.

    Parameters
    ----------
    sources : iterable of str or Path, or None, optional
        System files or example names; None: every example system.
    out_dir : str or Path, default DEFAULT_OUT
        The output folder (created).
    kinds : sequence of EstimatorKind or None, optional
        The estimator kinds to plan for; None: every registered kind.
    roles : iterable of str or None, optional
        Keep only the FMUs of these roles (``Plant``, ``HinfPD``, ...); None:
        all.
    designs : mapping of str to str or Path, or None, optional
        Maps a role to a design file to carry (see :func:`plan_system`).
    progress : callable or None, optional
        Called with a message before each FMU and on a design's progress;
        None: silent.
    design_options : mapping of str to object, or None, optional
        Keyword arguments of the design functions of filters designed at
        build time (``epsilon``: design there instead of searching;
        ``solver``; ``n_grid``: the search's number of grid angles).
    backend : str, default "pythonfmu"
        ``"pythonfmu"`` or ``"native"``: every discrete-time role as C; the
        roles the native backend does not build (the continuous-time LTV
        plant, the B-spline observer) are pythonfmu FMUs, with a note.
    bar : bool, default False
        A progress bar over the FMUs on stderr, when stderr is a terminal
        (never into a log); ``progress``'s messages are then written above it.

    Returns
    -------
    results : list of BuildResult
        One per planned FMU, in order.
    notes : list of str
        The planning notes, and one line per FMU built by another backend
        than ``backend``.

    Raises
    ------
    ArgumentError
        ``backend`` is not one of :data:`BACKENDS`.
    ModelFileError
        A source is no model file or example, or a given design file does
        not fit its plant.
    BuildError
        Planning or building fails for a reason other than a design made at
        build time (see :func:`plan_system`, :func:`build_fmu`).
    """
    from ..core._errors import LpvestError
    from ..core._progress import on_terminal, progress_bar

    check_backend(backend)
    results: list[BuildResult] = []
    notes: list[str] = []
    wanted = None if roles is None else set(roles)
    options = tuple(sorted((design_options or {}).items()))
    cache = Path(out_dir) / DESIGN_CACHE
    every: list[list[FmuPlan]] = []  # every system planned (and its design files checked) before any build
    for source in _systems(sources):
        plans, more = plan_system(source, kinds=kinds, designs=designs)
        notes += more
        if wanted is not None:
            plans = [p for p in plans if p.role in wanted]
        for plan in plans:  # a design file for another plant is refused before anything is built
            if plan.design is not None and plan.estimator is not None:
                _check_design_file(plan)
        every.append(plans)
    meter = progress_bar(desc="build", unit="FMU", total=sum(map(len, every)), show=bar and on_terminal())
    say = progress
    if progress is not None and not meter.disable:  # the lines above the bar, which stays at the bottom
        def say(text: str) -> None:
            meter.write(text, file=sys.stderr)
    try:
        for plans in every:
            for n, plan in enumerate(plans, 1):
                solving = plan.estimator is not None and bool(plan.estimator.design) and plan.design is None
                if solving:
                    plan = dataclasses.replace(plan, design_options=options, design_cache=cache)
                used = backend_of(plan, backend)
                if used != backend:
                    notes.append(f"{plan.identifier}: {resolve(_NATIVE_SUPPORT)(plan.role, plan.script)}")
                if say is not None:
                    say(f"building {plan.identifier} ({n}/{len(plans)})")
                meter.set_postfix_str(plan.identifier)
                try:
                    path = build_fmu(plan, out_dir, progress=say, backend=used)
                except LpvestError as exc:
                    if not solving:  # a bad input (a design file for another plant, ...): one error, as always
                        raise
                    # the design failed (no certified solution, ...): the other FMUs are still built
                    text = " ".join(str(exc).split())
                    failed = ValidationResult(Path(out_dir) / f"{plan.identifier}.fmu", 0, 0, 0, 0,
                                              [f"not built: {type(exc).__name__}: {text}"])
                    results.append(BuildResult(plan, failed))
                else:
                    results.append(BuildResult(plan, validate_fmus([path])[0]))
                meter.update(1)
    finally:
        meter.close()
    return results, notes


# -- validation ----------------------------------------------------------------------


def validate_fmus(paths: Iterable[str | Path]) -> list[ValidationResult]:
    """Check each FMU with ``fmpy.validation.validate_fmu`` (any problem is
    reported; a file that cannot be read is one problem).

    Parameters
    ----------
    paths : iterable of str or Path
        The FMU files.

    Returns
    -------
    list of ValidationResult
        One per path, in order; a missing file gives a result with the
        problem ``"<path>: no such file"``.
    """
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
