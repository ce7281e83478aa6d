"""Build a native FMU: the C runtime and the generated model data, as a source
FMU with binaries for Linux, Windows and macOS cross-compiled with zig.

What a native FMU holds:

- ``modelDescription.xml``: the variables of the Python FMU of the same role
  (the same slave writes both, :func:`lpvest.fmi._build.model_description_xml`),
  no execution tool needed, the source files listed (``SourceFiles``);
- ``sources/``: the runtime (``lpv_*.c``, ``lpv*.h``), the FMI 2.0 headers and
  the generated ``model_data.c``, with ``buildDescription.xml``:
  ``fmpy.build.build_platform_binary`` or a tool's own compiler builds it
  (C99; compile without floating-point contraction, ``-ffp-contract=off``, for
  random numbers bit for bit the library's);
- ``binaries/linux64/<id>.so``, ``binaries/win64/<id>.dll``,
  ``binaries/darwin64/<id>.dylib``: ``zig cc`` of the ``ziglang`` package (the ``build``
  extra, an exact version) at ``-O2``, the exported FMI functions only, linked
  against the C library alone (libc and libm on Linux, the C runtime and
  kernel32 on Windows, libSystem on macOS);
- ``resources/``: the model file, the design (H-infinity filters), the spec
  ``lpvest_fmu.json`` and ``manifest.json`` (every input and its SHA-256): for
  people and for the byte-identity check; the runtime reads none of them.

The same inputs give a byte-identical ``.fmu``: zip entries as the Python
builder writes them, the GUID derived from the manifest, zig's output a
function of its version, the flags and the sources (compiled under fixed
relative names, without debug information; the runtime's sources from a folder
of the user's cache named by their digest, so that zig's own cache serves them
to every later build).
"""

from __future__ import annotations

import atexit
import functools
import importlib.util
import json
import shutil
import subprocess
import sys
import tempfile
import tomllib
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any
from xml.etree.ElementTree import Element, SubElement

from ..._version import __version__
from ...core._paths import user_cache_dir
from .._build import (
    BuildError,
    FmuPlan,
    design_text,
    model_description_xml,
    plan_inputs,
    scripts_dir,
    sha256_hex,
    slave_class_name,
    write_fmu_zip,
    zig_environment,
    zig_program,
    zig_version,
)
from .._parameters import SPEC_FILE, SPEC_FORMAT
from ._export import NativeExportError, model_data_c, native_unsupported, parameter_entries, role_data

if TYPE_CHECKING:
    from .._slave import LpvestSlave

__all__ = ["build_native_fmu", "RUNTIME_DIR", "runtime_files", "NATIVE_PLATFORMS", "CFLAGS", "LDFLAGS",
           "native_manifest_inputs", "compile_binary"]

#: The C runtime (package data).
RUNTIME_DIR = Path(__file__).resolve().parent / "runtime"

#: FMI 2.0 platform folder -> (zig target, library suffix, extra compile flags, extra link flags).
NATIVE_PLATFORMS: dict[str, tuple[str, str, tuple[str, ...], tuple[str, ...]]] = {
    "linux64": ("x86_64-linux-gnu", ".so", ("-fPIC",), ("-lm",)),
    "win64": ("x86_64-windows-gnu", ".dll", (), ()),
    "darwin64": ("x86_64-macos", ".dylib", (), ()),
}

#: Compiler flags of every binary: C99, optimised, no contraction of a * b + c into
#: a fused multiply-add (the random normals are the library's bits), every
#: warning an error, only the FMI functions exported.
CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fvisibility=hidden", "-Wall", "-Wextra", "-Werror")
#: Link flags: a shared library without debug information.
LDFLAGS = ("-shared", "-s")

_MANIFEST_FORMAT = "lpvest-native-fmu-manifest-1"


def runtime_files() -> dict[str, bytes]:
    """The runtime's sources and headers by file name (sorted)."""
    return {f.name: f.read_bytes() for f in sorted(RUNTIME_DIR.iterdir()) if f.suffix in (".c", ".h")}


@functools.cache
def _runtime_digest() -> str:
    return sha256_hex(json.dumps({k: sha256_hex(v) for k, v in runtime_files().items()}, sort_keys=True).encode())


_NO_ZIG = "the native backend compiles with zig: pip install 'lpvest[build]' (the ziglang package)"


def _zig() -> str:
    version = zig_version()
    if version is None:
        raise BuildError(_NO_ZIG)
    return version


def _run_zig(args: list[str], cwd: Path, what: str) -> None:
    program = zig_program()
    if program is None:
        raise BuildError(_NO_ZIG)
    proc = subprocess.run([program, "cc", *args], cwd=cwd, capture_output=True, text=True, check=False,
                          env=zig_environment())
    if proc.returncode != 0:
        raise BuildError(f"{what} failed (zig cc {' '.join(args)}):\n{proc.stderr}")


def _runtime_sources(digest: str) -> Path:
    """A folder holding the runtime's sources, named by their ``digest``, in the
    user's cache (``$XDG_CACHE_HOME/lpvest/native-runtime``); a temporary one
    if that cannot be written.

    zig keeps what it compiled in its own cache, keyed by the sources' contents,
    the flags and the sources' absolute paths: a path that stays the same for the
    same runtime lets every later build (another process, another run) reuse the
    objects instead of compiling the runtime again for each platform (about 17 s
    of CPU). The folder is written under a temporary name and renamed into place,
    so that no process reads a half-written one; a damaged one (a file changed or
    missing) is replaced."""
    files = runtime_files()

    def holds_runtime(folder: Path) -> bool:
        return all((folder / n).is_file() and (folder / n).read_bytes() == t for n, t in files.items())

    base = user_cache_dir("native-runtime")
    folder = base / digest[:32]
    try:
        if holds_runtime(folder):
            return folder
        base.mkdir(parents=True, exist_ok=True)
        part = Path(tempfile.mkdtemp(prefix=f".{digest[:32]}-", dir=base))
        for name, text in files.items():
            (part / name).write_bytes(text)
        if folder.exists():  # damaged: set aside, then removed
            aside = Path(tempfile.mkdtemp(prefix=".damaged-", dir=base))
            folder.replace(aside / "runtime")
            shutil.rmtree(aside, ignore_errors=True)
        try:
            part.replace(folder)
        except OSError:  # put in place meanwhile by another process
            shutil.rmtree(part, ignore_errors=True)
            if not holds_runtime(folder):
                raise
        return folder
    except OSError:  # no writable cache: this process's own folder
        folder = Path(tempfile.mkdtemp(prefix="lpvest-runtime-"))
        atexit.register(shutil.rmtree, folder, True)
        for name, text in files.items():
            (folder / name).write_bytes(text)
        return folder


@functools.cache
def _runtime_objects(platform: str, digest: str) -> Path:
    """The runtime compiled for ``platform`` (object files in a folder kept for
    the process): the same for every FMU, so each build compiles only its model
    data and links. ``digest`` (the runtime's) keys the cache; the sources are
    compiled where :func:`_runtime_sources` keeps them (under fixed relative
    names, as before), so zig's cache serves a runtime it compiled before."""
    target, _, cflags, _ = NATIVE_PLATFORMS[platform]
    sources = _runtime_sources(digest)
    folder = Path(tempfile.mkdtemp(prefix=f"lpvest-runtime-{platform}-"))
    atexit.register(shutil.rmtree, folder, True)
    for name, text in runtime_files().items():
        if name.endswith(".h"):  # the model data includes them from here (-I)
            (folder / name).write_bytes(text)
    for name in sorted(n for n in runtime_files() if n.endswith(".c")):
        _run_zig(["-target", target, *CFLAGS, *cflags, "-c", name, "-o", str(folder / (name[:-2] + ".o"))], sources,
                 f"compiling the native runtime ({name}) for {platform}")
    return folder


def _without_link_time(dll: bytes) -> bytes:
    """A PE image with its link time (the COFF header's TimeDateStamp and those
    of its debug directory entries) set to 0, as a reproducible link (/Brepro in
    zig's own linker) leaves it: lld stamps the wall-clock time otherwise."""
    import struct

    data = bytearray(dll)
    pe = struct.unpack_from("<I", data, 0x3C)[0]
    if data[pe:pe + 4] != b"PE\0\0":
        raise BuildError("the win64 binary is not a PE image")
    struct.pack_into("<I", data, pe + 8, 0)
    n_sections = struct.unpack_from("<H", data, pe + 6)[0]
    opt = pe + 24
    opt_size = struct.unpack_from("<H", data, pe + 20)[0]
    sections = [struct.unpack_from("<8sIIII", data, opt + opt_size + 40 * i) for i in range(n_sections)]
    debug_rva, debug_size = struct.unpack_from("<II", data, opt + 112 + 6 * 8)  # PE32+: directory 6, debug
    for _, vsize, vaddr, rawsize, rawptr in sections:
        if debug_size and vaddr <= debug_rva < vaddr + max(vsize, rawsize):
            start = rawptr + debug_rva - vaddr
            for entry in range(start, start + debug_size, 28):
                struct.pack_into("<I", data, entry + 4, 0)
    return bytes(data)


def compile_binary(platform: str, folder: Path, identifier: str) -> bytes:
    """The FMU's library for ``platform``: ``model_data.c`` in ``folder``
    compiled with zig and linked with the runtime's objects; its bytes."""
    target, suffix, cflags, libs = NATIVE_PLATFORMS[platform]
    objects = _runtime_objects(platform, _runtime_digest())
    obj = f"model_data.{platform}.o"
    _run_zig(["-target", target, *CFLAGS, *cflags, f"-I{objects}", "-c", "model_data.c", "-o", obj], folder,
             f"compiling {identifier}'s model data for {platform}")
    runtime = sorted(str(o) for o in objects.glob("*.o"))
    out = f"{identifier}{suffix}"
    _run_zig(["-target", target, *LDFLAGS, "-o", out, obj, *runtime, *libs], folder,
             f"linking {identifier} for {platform}")
    data = (folder / out).read_bytes()
    if platform == "win64":
        data = _without_link_time(data)
    for leftover in folder.glob(f"{identifier}.*"):
        leftover.unlink()
    (folder / obj).unlink()
    return data


def native_manifest_inputs(plan: FmuPlan, design: str | bytes | None = None) -> dict[str, object]:
    """Every input of a native FMU's build and its SHA-256: the plan, the model
    file, the design, the runtime's sources, lpvest's version, zig and the
    flags. No path, no time."""
    return {
        "backend": "native",
        **plan_inputs(plan, design, requirements=False),
        "runtime_sha256": _runtime_digest(),
        "compiler": f"zig {_zig()}",
        "cflags": list(CFLAGS),
        "ldflags": list(LDFLAGS),
        "platforms": {k: [v[0], *v[2], *v[3]] for k, v in NATIVE_PLATFORMS.items()},
    }


def _load_slave(plan: FmuPlan, resources: Path) -> LpvestSlave:
    """The role script's slave class from the installed lpvest, instantiated on ``resources``."""
    script = scripts_dir() / plan.script
    name = f"lpvest_native_role_{script.stem}"
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, script)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[name] = module
    cls = getattr(module, slave_class_name(script))
    return cls(instance_name="lpvest-native-build", resources=str(resources))


def _model_table(plan: FmuPlan) -> Any:
    with open(plan.system_path, "rb") as f:
        doc = tomllib.load(f)
    return (doc.get("models") or {}).get(plan.model_key, {})


def _build_description(identifier: str, sources: list[str]) -> bytes:
    files = "\n".join(f'      <SourceFile name="{s}"/>' for s in sources)
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{identifier}" description="lpvest native runtime and its '
            f'model data; C99, compile without floating-point contraction (-ffp-contract=off)">\n'
            f'    <SourceFileSet language="C99">\n{files}\n    </SourceFileSet>\n'
            f'  </BuildConfiguration>\n</fmiBuildDescription>\n').encode()


def build_native_fmu(plan: FmuPlan, out_dir: str | Path, *, progress: Callable[[str], None] | None = None) -> Path:
    """Build ``plan``'s FMU with the native backend into ``out_dir`` (``<identifier>.fmu``).

    Parameters
    ----------
    plan : FmuPlan
        A plan of :func:`lpvest.fmi.plan_system`.
    out_dir : str or Path
        The output folder (created).
    progress : callable, optional
        Called with a message while a design is made.

    Returns
    -------
    Path
        The FMU.

    Raises
    ------
    BuildError
        The role has no native runtime, the model cannot be exported (a
        model parameter the runtime cannot follow, a Python basis function),
        or zig is missing or fails.
    """
    reason = native_unsupported(plan.role, plan.script)
    if reason is not None:
        raise BuildError(f"{plan.identifier}: {reason}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{plan.identifier}.fmu"
    with tempfile.TemporaryDirectory(prefix="lpvest-native-") as tmp:
        staging = Path(tmp) / "resources"
        staging.mkdir()
        shutil.copyfile(plan.system_path, staging / "model.toml")
        spec: dict[str, object] = {
            "format": SPEC_FORMAT, "identifier": plan.identifier, "role": plan.role, "description": plan.description,
            "lpvest_version": __version__, "backend": "native", "system": plan.system_name,
            "model_file": "model.toml", "model_key": plan.model_key, "model_parameters": list(plan.model_parameters),
            "sample_time": plan.step_size,
        }
        design: str | bytes | None = None
        if plan.estimator is not None:
            spec["estimator"] = plan.estimator.to_json()
            if plan.estimator.design:
                design, origin = design_text(plan, progress)
                if isinstance(design, str):
                    (staging / "design.json").write_text(design, encoding="utf-8")
                    spec["design_format"] = "text"
                else:
                    (staging / "design.json").write_bytes(design)
                spec["design_file"] = "design.json"
                spec["design_origin"] = origin
        (staging / SPEC_FILE).write_text(json.dumps(spec, indent=2) + "\n")
        manifest = {"format": _MANIFEST_FORMAT, "inputs": native_manifest_inputs(plan, design)}
        manifest_text = json.dumps(manifest, indent=1, sort_keys=True) + "\n"
        guid = "{" + str(uuid.UUID(hex=sha256_hex(manifest_text.encode())[:32])) + "}"

        slave = _load_slave(plan, staging)
        table = slave.variable_table()
        params = slave.parameters()
        try:
            component = slave.make_component(params)
            data = role_data(plan.role, component)
            declared = {p.name: p for p in table["parameters"]}
            model_params = [n for n in plan.model_parameters if n in declared]
            entries = parameter_entries(
                plan.identifier, plan.role, slave.make_component, params, model_params,
                {n: (declared[n].minimum, declared[n].maximum) for n in model_params}, _model_table(plan))
        except NativeExportError as exc:
            raise BuildError(str(exc)) from exc
        late = tuple((plan.estimator.to_json().get("late_inputs") or ()) if plan.estimator is not None else ())
        c_text = model_data_c(
            identifier=plan.identifier, guid=guid, version=__version__, role=plan.role, table=table, data=data,
            late_inputs=late, model_params=model_params, entries=entries,
            header=f"lpvest native FMU {plan.identifier}: model data (generated by lpvest {__version__}; do not edit)\n"
                   f"{plan.description}")
        sources = runtime_files()
        sources["model_data.c"] = c_text.encode()
        src_dir = Path(tmp) / "sources"
        src_dir.mkdir()
        for name, text in sources.items():
            (src_dir / name).write_bytes(text)
        c_files = sorted(n for n in sources if n.endswith(".c"))
        binaries = {platform: compile_binary(platform, src_dir, plan.identifier) for platform in NATIVE_PLATFORMS}

        def finish(root: Element) -> None:
            root.set("generationTool", f"lpvest {__version__} native runtime")
            cs = root.find("CoSimulation")
            assert cs is not None
            cs.set("needsExecutionTool", "false")
            files = SubElement(cs, "SourceFiles")
            for name in c_files:
                SubElement(files, "File", {"name": name})

        xml, *_ = model_description_xml(plan, slave, guid, native=True, finish=finish)
        (staging / "manifest.json").write_text(manifest_text, encoding="utf-8")
        entries_zip: dict[str, tuple[bytes, bool]] = {"modelDescription.xml": (xml, False)}
        for f in sorted(staging.iterdir()):
            entries_zip[f"resources/{f.name}"] = (f.read_bytes(), False)
        for name, text in sources.items():
            entries_zip[f"sources/{name}"] = (text, False)
        entries_zip["sources/buildDescription.xml"] = (_build_description(plan.identifier, c_files), False)
        for platform, data_bytes in binaries.items():
            suffix = NATIVE_PLATFORMS[platform][1]
            entries_zip[f"binaries/{platform}/{plan.identifier}{suffix}"] = (data_bytes, True)
        write_fmu_zip(target, entries_zip)
    return target
