"""The lpvest status bridge (lpvest/fmi/status_bridge.c): its logic on Linux in
front of a stand-in for pythonfmu's library (tests/data/fake_inner.c), its
warning-free compilation for Linux and Windows, and the win64 binaries the
build cross-compiles with zig (docs/fmus.md, 6.)."""

from __future__ import annotations

import ctypes
import re
import shutil
import subprocess
import sys
import warnings
import zipfile
from pathlib import Path

import pytest

from lpvest.fmi import _build as build

ROOT = Path(__file__).resolve().parent.parent
SOURCE = ROOT / "lpvest" / "fmi" / "status_bridge.c"
CC = shutil.which("cc") or shutil.which("gcc")
needs_cc = pytest.mark.skipif(CC is None or not sys.platform.startswith("linux"), reason="needs a C compiler on Linux")
needs_zig = pytest.mark.skipif(build.zig_version() is None,
                               reason="needs ziglang (pip install 'lpvest[build]'), the C cross compiler")


def _cosim_functions() -> set[str]:
    """The functions of FMI 2.0 co-simulation, from the standard's header fmpy ships."""
    import fmpy

    header = (Path(fmpy.__file__).parent / "c-code" / "fmi2Functions.h").read_text()
    declared = re.findall(r"FMI2_Export\s+\w+TYPE\s+(fmi2\w+);", header)
    me_only = header.split("Functions for FMI2 for Model Exchange")[2].split("Functions for FMI2 for Co-Simulation")[0]
    return set(declared) - set(re.findall(r"FMI2_Export\s+\w+TYPE\s+(fmi2\w+);", me_only))


# -- the bridge's logic (Linux) ------------------------------------------------------------------

LOGGER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)


class _Callbacks(ctypes.Structure):
    _fields_ = [("logger", LOGGER), ("allocateMemory", ctypes.c_void_p), ("freeMemory", ctypes.c_void_p),
                ("stepFinished", ctypes.c_void_p), ("componentEnvironment", ctypes.c_void_p)]


def _resources(folder: Path, guid: str = "guid") -> Path:
    """A resources folder as the bridge checks it: slavemodule.txt, the module it names, the GUID."""
    folder.mkdir(parents=True)
    (folder / "slavemodule.txt").write_text("entry\n")
    (folder / "entry.py").write_text("# the slave\n")
    (folder / build.GUID_FILE).write_text(guid + "\n")
    return folder


@pytest.fixture
def bridge(tmp_path):
    """The bridge compiled as the build does, with the stand-in as its inner library."""
    if CC is None or not sys.platform.startswith("linux"):
        pytest.skip("needs a C compiler on Linux")
    built = build.status_bridge("linux64")
    assert built is not None
    lib_dir = tmp_path / "binaries"
    lib_dir.mkdir()
    shutil.copy(built, lib_dir / "Bridge.so")
    subprocess.run([CC, "-shared", "-fPIC", "-O2", "-o", str(lib_dir / "lpvest-pythonfmu-export.so"),
                    str(ROOT / "tests" / "data" / "fake_inner.c"), "-lm"], check=True)
    lib = ctypes.CDLL(str(lib_dir / "Bridge.so"))
    inner = ctypes.CDLL(str(lib_dir / "lpvest-pythonfmu-export.so"))
    messages: list[tuple[int, str]] = []
    logger = LOGGER(lambda env, name, status, category, text: messages.append((status, text.decode())))
    callbacks = _Callbacks(logger, None, None, None, None)
    lib.fmi2Instantiate.restype = ctypes.c_void_p
    lib.fmi2Instantiate.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_void_p,
                                    ctypes.c_int, ctypes.c_int]
    inner.fake_last_uri.restype = ctypes.c_char_p
    inner.fake_serialize_size.restype = ctypes.c_size_t
    state_p = ctypes.POINTER(ctypes.c_void_p)
    for fn, args in (("fmi2GetFMUstate", [state_p]), ("fmi2FreeFMUstate", [state_p]),
                     ("fmi2SetFMUstate", [ctypes.c_void_p]),
                     ("fmi2SerializedFMUstateSize", [ctypes.c_void_p, ctypes.POINTER(ctypes.c_size_t)]),
                     ("fmi2SerializeFMUstate", [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t]),
                     ("fmi2DeSerializeFMUstate", [ctypes.c_char_p, ctypes.c_size_t, state_p])):
        getattr(lib, fn).restype = ctypes.c_int
        getattr(lib, fn).argtypes = [ctypes.c_void_p, *args]
    for fn in ("fmi2DoStep", "fmi2SetReal", "fmi2Reset", "fmi2Terminate", "fmi2SetupExperiment"):
        getattr(lib, fn).restype = ctypes.c_int
    lib.fmi2FreeInstance.argtypes = [ctypes.c_void_p]
    lib.fmi2Reset.argtypes = lib.fmi2Terminate.argtypes = [ctypes.c_void_p]
    lib.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    lib.fmi2SetReal.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                                ctypes.POINTER(ctypes.c_double)]

    resources = _resources(tmp_path / "resources")

    def instantiate(logging_on: bool = True) -> int:
        return lib.fmi2Instantiate(b"i", 1, b"guid", resources.as_uri().encode(), ctypes.byref(callbacks), 0,
                                   int(logging_on))

    return lib, inner, messages, instantiate, callbacks


def test_the_bridge_drains_what_a_constructor_logged_before_the_instance_can_be_freed(bridge):
    """pythonfmu frees an instance with queued messages through a destroyed
    logger; a slave's constructor (fmi2Instantiate, fmi2Reset) queues them. The
    bridge hands them on right after those calls, so none is queued at free."""
    lib, inner, messages, instantiate, _ = bridge
    c = instantiate()
    assert c and messages == [(0, "constructed")]
    lib.fmi2FreeInstance(c)  # instantiate -> free
    c = instantiate(logging_on=False)
    assert lib.fmi2Reset(c) == 0
    assert messages == [(0, "constructed")]  # with the host's logging off, status-OK messages are not shown
    lib.fmi2FreeInstance(c)  # reset -> free
    assert inner.fake_frees() == 2 and inner.fake_frees_with_queue() == 0


@needs_cc
def test_instances_made_from_several_threads_at_once_start_python_once(tmp_path):
    """A host that creates its first instances in parallel threads: one thread
    loads the inner library and starts the interpreter, the others wait (two
    Py_InitializeEx at once crash the host; the bridge had no lock). The C host
    of tests/data/bridge_threads.c stands in for CPython and counts the threads
    inside at once; every instance is made."""
    built = build.status_bridge("linux64")
    assert built is not None
    shutil.copy(built, tmp_path / "Bridge.so")
    subprocess.run([CC, "-shared", "-fPIC", "-O2", "-o", str(tmp_path / "lpvest-pythonfmu-export.so"),
                    str(ROOT / "tests" / "data" / "fake_inner.c"), "-lm"], check=True)
    host = tmp_path / "bridge_threads"
    subprocess.run([CC, "-O2", "-rdynamic", "-o", str(host), str(ROOT / "tests" / "data" / "bridge_threads.c"),
                    "-ldl", "-lpthread"], check=True)
    resources = _resources(tmp_path / "resources")
    proc = subprocess.run([str(host), str(tmp_path / "Bridge.so"), "guid", resources.as_uri(), "6"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["1", "1", "6"], proc.stdout + proc.stderr


def test_a_message_logged_at_error_makes_the_call_return_error(bridge):
    lib, _, messages, instantiate, _ = bridge
    c = instantiate(logging_on=False)
    vr, nan = (ctypes.c_uint * 1)(1), (ctypes.c_double * 1)(float("nan"))
    assert lib.fmi2SetReal(c, vr, 1, nan) == 3  # fmi2Error, though the inner library returned fmi2OK
    # shown whatever the logging setting, as a safe format string ('%' doubled)
    assert messages[-1] == (3, "input = nan is not finite; value rejected (100%%)")
    lib.fmi2FreeInstance(c)


def test_after_fmi2fatal_no_call_reaches_the_inner_library_and_free_is_safe(bridge):
    """After a Python exception pythonfmu has released the slave's objects:
    freeing its instance would release them again. The bridge refuses every
    further call with fmi2Fatal and frees only its own part."""
    lib, inner, messages, instantiate, _ = bridge
    c = instantiate()
    frees = inner.fake_frees()
    assert lib.fmi2DoStep(c, -1.0, 1.0, 1) == 4
    assert lib.fmi2DoStep(c, 0.0, 1.0, 1) == 4
    assert lib.fmi2Reset(c) == 4
    assert messages[-1][0] == 4 and "an earlier call failed with fmi2Fatal" in messages[-1][1]
    lib.fmi2FreeInstance(c)
    assert inner.fake_frees() == frees


@pytest.mark.parametrize(("kind", "damage", "says"), [
    (0, None, "this FMU supports co-simulation only"),  # fmi2ModelExchange
    (1, "null", "no resource location (NULL; FMI 2.0, 2.1.5"),
    (1, "http", "is not a file URI"),
    (1, "slavemodule.txt", "slavemodule.txt: is the FMU extracted whole?"),
    (1, "entry.py", "entry.py: is the FMU extracted whole?"),
    (1, build.GUID_FILE, f"{build.GUID_FILE}: is the FMU extracted whole?"),
    (1, "guid", "GUID guid does not match this FMU's {another}"),
])
def test_an_instance_pythonfmu_would_crash_on_is_refused_with_a_message(bridge, tmp_path, kind, damage, says):
    """pythonfmu's library crashes the host (a null Python callable) when it cannot import
    the slave from the resource location; the bridge checks the location first, and the
    type and GUID as the native FMUs do: NULL and one message at fmi2Error."""
    lib, inner, messages, _, callbacks = bridge
    folder = _resources(tmp_path / "r", guid="{another}" if damage == "guid" else "guid")
    if damage in ("slavemodule.txt", "entry.py", build.GUID_FILE):
        (folder / damage).unlink()
    uri = {"null": None, "http": b"http://example.com/r"}.get(damage, folder.as_uri().encode())
    before = inner.fake_last_uri()
    assert lib.fmi2Instantiate(b"i", kind, b"guid", uri, ctypes.byref(callbacks), 0, 0) is None
    assert len(messages) == 1 and messages[0][0] == 3, messages
    assert says.replace("%", "%%") in messages[0][1], messages
    assert inner.fake_last_uri() == before  # pythonfmu's library was not called


def test_the_resource_location_reaches_pythonfmu_decoded(bridge, tmp_path):
    """pythonfmu decodes only %20: a folder with a non-ASCII letter or a '%' in its name
    (percent-encoded by the host, as fmpy does) reaches it as the path itself."""
    lib, inner, messages, _, callbacks = bridge
    folder = _resources(tmp_path / "Jürgen's 100% FMUs" / "resources")
    for uri in (folder.as_uri(), "file:" + folder.as_posix(), "file://localhost" + folder.as_posix(),
                folder.as_uri() + "/"):
        c = lib.fmi2Instantiate(b"i", 1, b"guid", uri.encode(), ctypes.byref(callbacks), 0, 0)
        assert c, (uri, messages)
        assert inner.fake_last_uri().decode() == "file://" + folder.as_posix(), uri
        lib.fmi2FreeInstance(c)
    odd = _resources(tmp_path / "a%20b")  # pythonfmu would read a space: refused, named
    assert lib.fmi2Instantiate(b"i", 1, b"guid", odd.as_uri().encode(), ctypes.byref(callbacks), 0, 0) is None
    assert "which pythonfmu reads as a space" in messages[-1][1]


def test_fmu_states_are_serialized_into_the_buffer_the_host_gives_and_freed_to_null(bridge):
    """pythonfmu copies as many bytes as the buffer has out of a state (past its end for a
    larger buffer) and leaves a freed state's pointer set."""
    lib, inner, messages, instantiate, _ = bridge
    c = instantiate(logging_on=False)
    state = ctypes.c_void_p()
    assert lib.fmi2GetFMUstate(c, ctypes.byref(state)) == 0 and state.value
    size = ctypes.c_size_t()
    assert lib.fmi2SerializedFMUstateSize(c, state, ctypes.byref(size)) == 0 and size.value == 8
    buffer = ctypes.create_string_buffer(b"\xff" * 64, 64)
    assert lib.fmi2SerializeFMUstate(c, state, buffer, 64) == 0
    assert inner.fake_serialize_size() == 8 and buffer.raw == b"STATE-01" + b"\0" * 56
    assert lib.fmi2SerializeFMUstate(c, state, buffer, 7) == 3
    # the bridge's own messages start with the model identifier (its file name), as the slaves' do
    assert messages[-1] == (3, "[Bridge] fmi2SerializeFMUstate: the buffer holds 7 bytes, the state needs 8 "
                               "(fmi2SerializedFMUstateSize)")
    assert lib.fmi2GetFMUstate(c, ctypes.byref(state)) == 0  # an earlier state: freed, a new one made
    assert inner.fake_live_states() == 1
    assert lib.fmi2FreeFMUstate(c, ctypes.byref(state)) == 0 and state.value is None
    assert inner.fake_live_states() == 0
    assert lib.fmi2FreeFMUstate(c, ctypes.byref(state)) == 0  # a NULL state: nothing to free
    assert lib.fmi2FreeFMUstate(c, None) == 0 and inner.fake_live_states() == 0
    for call in (lambda: lib.fmi2SetFMUstate(c, None), lambda: lib.fmi2GetFMUstate(c, None),
                 lambda: lib.fmi2SerializedFMUstateSize(c, None, ctypes.byref(size)),
                 lambda: lib.fmi2SerializeFMUstate(c, None, buffer, 64),
                 lambda: lib.fmi2DeSerializeFMUstate(c, None, 8, ctypes.byref(state))):
        n = len(messages)
        assert call() == 3 and len(messages) == n + 1 and "a NULL argument" in messages[-1][1]
    lib.fmi2FreeInstance(c)


def test_bytes_that_do_not_begin_as_an_lpvest_state_are_refused_when_deserialized(bridge):
    """The native FMUs refuse bytes without their state's header at fmi2DeSerializeFMUstate;
    the bridge refuses bytes that do not begin as every state encode_state writes does, in
    the same words, and hands on those that do (the rest is checked at fmi2SetFMUstate)."""
    from lpvest.fmi._state import encode_state

    prefix = re.search(r'#define STATE_PREFIX "((?:[^"\\]|\\.)*)"', SOURCE.read_text())[1]
    prefix = prefix.encode().decode("unicode_escape").encode()
    assert encode_state({}).startswith(prefix) and encode_state({"x": [1.0]}).startswith(prefix)
    lib, inner, messages, instantiate, _ = bridge
    c = instantiate(logging_on=False)
    state = ctypes.c_void_p()
    for bad in (b"", b"abc", b"LPVSTAT2", prefix[:-1]):
        assert lib.fmi2DeSerializeFMUstate(c, bad, len(bad), ctypes.byref(state)) == 3, bad
        assert messages[-1] == (3, "[Bridge] fmi2DeSerializeFMUstate: ArgumentError: not a serialized lpvest FMU "
                                   "state"), bad
    good = encode_state({})
    assert lib.fmi2DeSerializeFMUstate(c, good, len(good), ctypes.byref(state)) == 0 and state.value
    assert lib.fmi2FreeFMUstate(c, ctypes.byref(state)) == 0
    lib.fmi2FreeInstance(c)


# -- compiling it ---------------------------------------------------------------------------------


@needs_cc
def test_the_bridge_compiles_without_warnings_for_linux(tmp_path):
    subprocess.run([CC, "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(tmp_path / "b.so"),
                    str(SOURCE), "-ldl"], check=True)


@needs_zig
@pytest.mark.parametrize("target", sorted(build.BRIDGE_PLATFORMS.values()))
def test_the_bridge_compiles_without_warnings_with_zig(tmp_path, target):
    out = tmp_path / ("b.dll" if "windows" in target else "b.so")
    subprocess.run([sys.executable, "-m", "ziglang", "cc", "-target", target, "-shared", "-O2", "-Wall", "-Wextra",
                    "-Werror", "-o", str(out), str(SOURCE)], check=True, cwd=tmp_path,
                   env=build.zig_environment())


# -- the win64 binaries of the built FMUs ---------------------------------------------------------


@needs_zig
def test_every_fmu_carries_a_win64_bridge_that_exports_every_fmi2_function(fmus):
    """Parsed with pefile: an x86-64 DLL exporting every FMI 2.0 co-simulation
    function, loading pythonfmu's DLL (carried next to it, unchanged) by name
    at run time, and importing no Python DLL itself."""
    import pefile
    import pythonfmu

    functions = _cosim_functions()
    assert len(functions) == 34 and "fmi2DoStep" in functions and "fmi2SetTime" not in functions
    theirs = (Path(pythonfmu.__file__).parent / "resources" / "binaries" / "win64" / "pythonfmu-export.dll")
    theirs_bytes = theirs.read_bytes()
    for name, path in sorted(fmus.paths.items()):
        with zipfile.ZipFile(path) as z:
            dll = z.read(f"binaries/win64/{name}.dll")
            assert z.read("binaries/win64/lpvest-pythonfmu-export.dll") == theirs_bytes
        pe = pefile.PE(data=dll)
        assert pe.is_dll() and pe.FILE_HEADER.Machine == pefile.MACHINE_TYPE["IMAGE_FILE_MACHINE_AMD64"]
        exported = {s.name.decode() for s in pe.DIRECTORY_ENTRY_EXPORT.symbols if s.name}
        assert functions <= exported, (name, functions - exported)
        imported = {entry.dll.decode().lower() for entry in pe.DIRECTORY_ENTRY_IMPORT}
        assert not {d for d in imported if d.startswith("python")}, imported
        assert b"lpvest-pythonfmu-export.dll" in dll


def test_without_a_compiler_the_build_says_once_what_the_fmu_lacks(monkeypatch, tmp_path):
    """Without ziglang: the win64 binary is pythonfmu's DLL as is, and one
    BuildWarning names what is missing and what the FMU then lacks."""
    import pythonfmu

    plans = {p.role: p for p in build.plan_system("peixoto-ex1")[0]}
    monkeypatch.setattr(build, "zig_version", lambda: None)
    build._compile_bridge.cache_clear()
    build._warn_without_bridge.cache_clear()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for role in ("Plant", "Scheduler"):
                build.build_fmu(plans[role], tmp_path)
        said = [w for w in caught if issubclass(w.category, build.BuildWarning)]
        assert len(said) == 1
        assert re.match(r"the C cross compiler for Windows is missing \(pip install 'lpvest\[build\]' installs "
                        r"ziglang\): its win64 binary is pythonfmu's library as is, without lpvest's status bridge",
                        str(said[0].message))
        assert "fmi2Discard" in str(said[0].message)
        theirs = (Path(pythonfmu.__file__).parent / "resources" / "binaries" / "win64" / "pythonfmu-export.dll")
        with zipfile.ZipFile(tmp_path / "PeixotoEx1Plant.fmu") as z:
            assert z.read("binaries/win64/PeixotoEx1Plant.dll") == theirs.read_bytes()
            assert "binaries/win64/lpvest-pythonfmu-export.dll" not in z.namelist()
    finally:
        build._compile_bridge.cache_clear()
        build._warn_without_bridge.cache_clear()
