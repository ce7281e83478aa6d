"""Hosts without Python for the native FMUs: the C host of tests/data/native_host.c,
compiled for Linux (plain, or with AddressSanitizer and UndefinedBehaviorSanitizer)
and for Windows (run under wine where it is installed), driven line by line
through a pipe with the interface of tests/fmu_driver.Driver."""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from lpvest.fmi._build import zig_environment
from tests.native_helpers import c_compiler

HOST_SOURCE = Path(__file__).resolve().parent / "data" / "native_host.c"
SANITIZERS = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer")


@functools.cache
def host_exe(kind: str = "plain") -> Path:
    """The C host compiled once per session: ``plain`` (cc), ``sanitized``
    (cc with ASan and UBSan) or ``windows`` (zig, x86_64-windows-gnu)."""
    out = Path(tempfile.mkdtemp(prefix="lpvest-host-"))
    atexit.register(shutil.rmtree, out, True)
    if kind == "windows":
        exe = out / "native_host.exe"
        cmd = [sys.executable, "-m", "ziglang", "cc", "-target", "x86_64-windows-gnu", "-std=c99", "-O2", "-Wall",
               "-Wextra", "-Werror", "-o", str(exe), str(HOST_SOURCE)]
    else:
        exe = out / "native_host"
        flags = SANITIZERS if kind == "sanitized" else ()
        cmd = [*c_compiler(), "-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-Werror", *flags, "-o", str(exe),
               str(HOST_SOURCE), "-ldl"]
    subprocess.run(cmd, check=True, capture_output=True, env=zig_environment() if kind == "windows" else None)
    return exe


def sanitized_library(fmu: Path, folder: Path) -> Path:
    """The FMU's source files (sources/ of the source FMU) compiled into a shared
    library with ASan and UBSan (cc), as a tool's own compiler would build them:
    each ``.c`` file to an object, then linked. An object is compiled once per
    process for the same file, headers and flags (:func:`_sanitized_object`): the
    FMUs share every runtime source and differ in ``model_data.c``, and compiling
    the runtime under the sanitizers again for each FMU was nine tenths of these
    tests' CPU."""
    with zipfile.ZipFile(fmu) as z:
        sources = [n for n in z.namelist() if n.startswith("sources/")]
        z.extractall(folder, sources)
    src = folder / "sources"
    headers = tuple(sorted((f.name, f.read_bytes()) for f in src.glob("*.h")))
    objects = [_sanitized_object(f.name, f.read_bytes(), headers) for f in sorted(src.glob("*.c"))]
    out = folder / f"{fmu.stem}.so"
    subprocess.run([*c_compiler(), "-shared", *SANITIZERS, "-o", str(out), *map(str, objects), "-lm"], check=True,
                   capture_output=True, cwd=src)
    return out


@functools.cache
def _sanitized_object(name: str, text: bytes, headers: tuple[tuple[str, bytes], ...]) -> Path:
    """``name`` (source ``text``, beside ``headers``) compiled with the sanitizers into
    an object file of this process's folder (removed at exit)."""
    folder = Path(tempfile.mkdtemp(prefix="lpvest-sanitized-"))
    atexit.register(shutil.rmtree, folder, True)
    for header, data in headers:
        (folder / header).write_bytes(data)
    (folder / name).write_bytes(text)
    obj = folder / (name + ".o")
    subprocess.run([*c_compiler(), "-std=c99", "-O1", "-g", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra",
                    "-Werror", *SANITIZERS, "-c", "-o", str(obj), name], check=True, capture_output=True, cwd=folder)
    return obj


def wine() -> str | None:
    """The wine program, or None."""
    return shutil.which("wine") or shutil.which("wine64")


def windows_host(folder: Path, md) -> tuple[list[str], dict[str, str]]:  # noqa: ANN001
    """The command and environment that run the C host cross-compiled for Windows
    under wine on the win64 DLL of the FMU unpacked in ``folder`` (``md``: its
    model description)."""
    wine_exe = wine()
    assert wine_exe is not None
    dll = folder / "binaries" / "win64" / f"{md.coSimulation.modelIdentifier}.dll"
    lib = "Z:" + str(dll).replace("/", "\\")
    env = {"WINEDEBUG": "-all", "HOME": os.environ.get("HOME", "/root"),
           "PATH": "/usr/bin:/bin"}  # wine itself needs its home and its programs
    return [wine_exe, str(host_exe("windows")), lib, md.guid, (folder / "resources").as_uri()], env


class HostDriver:
    """One instance of an FMU in the C host (a process of its own, started with
    an empty environment: no PYTHONPATH, no LD_LIBRARY_PATH, nothing of
    Python's), with the methods of tests/fmu_driver.Driver the tests use."""

    def __init__(self, fmu: Path, *, kind: str = "plain", library: Path | None = None) -> None:
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.folder = Path(tempfile.mkdtemp(prefix="lpvest-hosted-"))
        with zipfile.ZipFile(fmu) as z:
            z.extractall(self.folder)
        ident = self.md.coSimulation.modelIdentifier
        uri = (self.folder / "resources").as_uri()
        env: dict[str, str] = {}
        if kind == "windows":
            cmd, env = windows_host(self.folder, self.md)
        else:
            lib = str(library or self.folder / "binaries" / "linux64" / f"{ident}.so")
            cmd = [str(host_exe(kind)), lib, self.md.guid, uri]
            if kind == "sanitized":
                env = {"ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0:exitcode=23",
                       "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1:exitcode=24"}
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env, bufsize=1)
        self.messages: list[tuple[int, str, str]] = []
        assert self.call("instantiate 0 host 0")[0] == 0, self.messages

    def call(self, line: str) -> tuple[int, list[str]]:
        """Send one script line; its status and the value lines it printed."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        cmd = line.split()[0]
        values: list[str] = []
        while True:
            out = self.proc.stdout.readline()
            if not out:
                raise RuntimeError(f"the host ended at {line!r}: {self.proc.stderr.read() if self.proc.stderr else ''}")
            out = out.rstrip("\n")
            if out.startswith("LOG "):
                _, status, category, message = out.split(" ", 3)
                self.messages.append((int(status), category, message))
            elif out.startswith("STATUS "):
                _, name, status = out.split(" ")
                assert name == cmd, (line, out)
                return (-1 if status == "null" else int(status)), values
            else:
                values.append(out)

    def initialize(self, start_time: float = 0.0, **params: float | int | bool | str) -> int:
        st = self.call(f"setup 0 {start_time!r}")[0]
        st = max(st, self.call("enter 0")[0])
        for name, value in params.items():
            st = max(st, self.set(name, value))
        return max(st, self.call("exit 0")[0])

    def set(self, name: str, value: float | int | bool | str) -> int:
        t = self.types[name]
        if t == "Real":
            return self.call(f"set_real 0 {self.vr[name]} {float(value)!r}")[0]
        if t == "String":
            return self.call(f"set_string 0 {self.vr[name]} {value}")[0]
        return self.call(f"set_{t.lower()} 0 {self.vr[name]} {int(value)}")[0]

    def set_vector(self, base: str, values) -> int:  # noqa: ANN001
        values = np.atleast_1d(np.asarray(values, dtype=float))
        return max(self.set(f"{base}[{i + 1}]", float(v)) for i, v in enumerate(values))

    def vector(self, base: str) -> np.ndarray:
        from lpvest.fmi._naming import parse_element

        names = sorted((n for n in self.vr if n.startswith(base + "[")), key=lambda n: parse_element(n)[1])
        if not names and base in self.vr:
            names = [base]
        _, lines = self.call("get_real 0 " + " ".join(str(self.vr[n]) for n in names))
        return np.array([float(v) for v in lines[0].split()[1:]])

    def step(self, t: float, h: float) -> int:
        return self.call(f"step 0 {t!r} {h!r}")[0]

    def errors(self) -> list[str]:
        return [m for s, _, m in self.messages if s >= 3]

    def close(self) -> int:
        """End the host (freeing the instance); its exit code."""
        assert self.proc.stdin is not None
        self.proc.stdin.write("free 0\n")
        self.proc.stdin.close()
        self.proc.wait(timeout=120)
        self.stderr = self.proc.stderr.read() if self.proc.stderr else ""
        shutil.rmtree(self.folder, ignore_errors=True)
        return self.proc.returncode
