"""The native FMUs in hosts with no Python: the C host (plain, and with the
runtime built from the source FMU under AddressSanitizer and
UndefinedBehaviorSanitizer), the win64 binary in the C host cross-compiled for
Windows under wine, libcosim, fmpy's simulate_fmu; the source FMU built by
fmpy; byte-identical builds."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from tests import libcosim_driver
from tests.native_hosts import HostDriver, sanitized_library, wine

#: one FMU of every role and model kind, the lifecycle and sanitizer runs use them
EVERY_ROLE = ["PeixotoEx1Plant", "CoxTothTruncationPlant", "CoxTothEx1Plant", "PeixotoEx1Scheduler",
              "AffineDemoSource", "CoxTothTruncationKalman", "CoxTothTruncationTruncatedKalman", "AffineDemoHinfPD",
              "PeixotoEx1HinfRobust", "IoDemoPlant"]


def _lifecycle_script(md) -> list[str]:  # noqa: ANN001
    """Every call sequence FMI 2.0 allows, and the wrong ones an FMU must
    survive, for one FMU (its value references from ``md``)."""
    ins = [v for v in md.modelVariables if v.causality == "input"]
    outs = " ".join(str(v.valueReference) for v in md.modelVariables if v.causality == "output")
    pars = [v for v in md.modelVariables if v.causality == "parameter"]
    set_inputs = []
    for k, v in enumerate(ins):
        lo = float(v.min) if v.min is not None else -1.0
        hi = float(v.max) if v.max is not None else 1.0
        set_inputs.append(f"set_real 0 {v.valueReference} {lo + (hi - lo) * (0.3 + 0.1 * (k % 5))!r}")
    if any(v.name.startswith("alpha[") for v in ins):
        set_inputs += [f"set_real 0 {v.valueReference} {1.0 / sum(1 for w in ins if w.name.startswith('alpha['))!r}"
                       for v in ins if v.name.startswith("alpha[")]
    step = [*set_inputs, f"get_real 0 {outs}"]
    real_par = next((v for v in pars if v.type == "Real"), None)
    lines = [
        "instantiate 0 a 1", "free 0",  # instantiate -> free
        "instantiate 0 a 0", "setup 0 0", "free 0",  # free in setup
        "instantiate 0 a 0", "setup 0 0", "enter 0", f"get_real 0 {outs}",  # outputs before init
        # a string the FMU returned, passed back in one call after another value for the same variable
        *(f"set_string_back 0 {v.valueReference} x" for v in pars if v.type == "String"), "free 0",
        "instantiate 0 a 1", "setup 0 0", "enter 0", "exit 0",
        *step, "step 0 0 1", *step, "get_state 0 0", "step 0 1 1", *step, "step 0 2 2",  # two samples at once
        "set_state 0 0", "time 0", "serialize 0 0", "replace 0 0", "set_state 0 0", *step, "step 0 1 1",
        "step 0 7 1", "step 0 2 0.5", "step 0 2 -1", "step 0 2 nan",  # refused steps
        *(f"set_real 0 {v.valueReference} nan" for v in ins[:1]),  # a bad input, then a step
        "step 0 2 1", *set_inputs, "step 0 2 1",
        *( [f"set_real 0 {real_par.valueReference} 1"] if real_par is not None else []),  # a parameter when fixed
        "get_real 0 999999", "get_integer 0 999999", "get_string 0 999999",  # unknown references
        "reset 0", "setup 0 0", "enter 0", "exit 0", *step, "step 0 0 1",  # reset and run again
        "instantiate 1 b 0", "setup 1 0", "enter 1", "exit 1", "step 1 0 1",  # a second instance
        "get_state 1 1", "free 1",  # freed with a state taken
        "terminate 0", "step 0 1 1", "free 0",  # terminate, a step after it, free
        "instantiate 0 c 0", "setup 0 0", "enter 0", "exit 0", "get_state 0 2", "free 0",
        "unload", "load", "instantiate 0 d 0", "setup 0 0", "enter 0", "exit 0", *step, "step 0 0 1", "free 0",
    ]
    return lines


def _run_script(exe_args: list[str], lines: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run(exe_args, input="\n".join(lines) + "\n", capture_output=True, text=True, env=env,
                          timeout=600, check=False)


@pytest.mark.parametrize("name", EVERY_ROLE)
def test_every_call_sequence_runs_clean_under_address_and_undefined_behaviour_sanitizers(native_fmus, name,
                                                                                         tmp_path):
    """The runtime and the FMU's model data, compiled from the source FMU's
    sources/ with -fsanitize=address,undefined, in the C host compiled the same
    way: every call sequence (instantiate -> free, free in setup, outputs before
    initialization, states, serialization, refused steps, bad input, reset, two
    instances, terminate, the library closed and opened again) with no memory
    error, no leak, no undefined behaviour."""
    from tests.native_hosts import host_exe

    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler with sanitizers (cc, gcc) on this machine")
    lib = sanitized_library(native_fmus[name], tmp_path)
    md = read_model_description(str(native_fmus[name]))
    env = {"ASAN_OPTIONS": "detect_leaks=1:exitcode=23", "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
    proc = _run_script([str(host_exe("sanitized")), str(lib), md.guid, "file:///nonexistent"],
                       _lifecycle_script(md), env)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "ERROR: AddressSanitizer" not in proc.stderr and "runtime error" not in proc.stderr, proc.stderr[-4000:]
    out = proc.stdout.splitlines()
    assert out[-1] == "DONE"
    statuses = [line.split() for line in out if line.startswith("STATUS")]
    # the refused steps and the bad calls are errors (3), everything else OK
    steps = [s[2] for s in statuses if s[1] == "step"]
    # four samples, then the refused steps (a Scheduler or Source, a function of time, takes h = 0.5)
    half = "0" if md.coSimulation.canHandleVariableCommunicationStepSize else "3"
    assert steps[:8] == ["0"] * 4 + ["3", half, "3", "3"]
    assert all(s[2] in ("0", "3") for s in statuses)
    if any(v.causality == "input" for v in md.modelVariables):  # the NaN input was rejected, named
        assert any(line.startswith("LOG 3") and "is not finite; value rejected" in line for line in out)


def _random_script(md, seed: int, calls: int) -> list[str]:  # noqa: ANN001
    """``calls`` random FMI calls on up to three instances of the FMU ``md`` describes:
    any order of the lifecycle calls, setters and getters of every type on any value
    reference (and unknown ones) with values in and out of range or not finite, steps
    from the FMU's time or not, of whole samples or not, FMU states taken, restored,
    serialized and freed. Only live instances are called (FMI gives a freed one no
    meaning), and an instance is made again after it was freed."""
    import random

    rnd = random.Random(seed)
    variables = list(md.modelVariables)
    ts = float(md.defaultExperiment.stepSize)
    reals = ["0", "-0", "0.25", "0.5", "-0.5", "1", "-1", "2", "3", "1e3", "1e308", "-1e308", "5e-324", "nan", "inf",
             "-inf"]
    strings = ["", "theorem", "steady-state", "zero", "constant", "sinusoid", "decaying", "gaussian", "table",
               "0 1; 1 2", "0 1 2; 1 2 3", "0 nan", "x", "%s%n"]
    live: set[int] = set()
    lines: list[str] = []

    def vr(kind: str) -> int:
        same = [v for v in variables if v.type == kind]
        r = rnd.random()
        if r < 0.1:
            return rnd.choice([len(variables) + 5, 999_999, 2**32 - 1])
        return rnd.choice(same if same and r < 0.8 else variables).valueReference

    for _ in range(calls):
        free = [i for i in range(3) if i not in live]
        if not live or (free and rnd.random() < 0.02):
            i = rnd.choice(free)
            lines.append(f"instantiate {i} fuzz{i} {rnd.randint(0, 1)}")
            live.add(i)
            continue
        i = rnd.choice(sorted(live))
        op = rnd.randrange(20)
        if op == 0:
            lines.append(f"setup {i} {rnd.choice(['0', '1', '-2', '1e9', 'nan'])}")
        elif op == 1:
            lines += [f"setup {i} 0", f"enter {i}", f"exit {i}"]
        elif op == 2:
            lines.append(rnd.choice([f"enter {i}", f"exit {i}", f"terminate {i}", f"reset {i}"]))
        elif op in (3, 4):
            lines.append(f"set_real {i} {vr('Real')} {rnd.choice(reals)}")
        elif op == 5:
            lines.append(f"set_integer {i} {vr('Integer')} {rnd.choice(['0', '1', '2', '-1', '200', '2147483647'])}")
        elif op == 6:
            lines.append(f"set_boolean {i} {vr('Boolean')} {rnd.choice(['0', '1', '2'])}")
        elif op == 7:
            lines.append(f"set_string {i} {vr('String')} {rnd.choice(strings)}")
        elif op in (8, 9):
            lines.append(f"get_real {i} " + " ".join(str(vr("Real")) for _ in range(rnd.randint(1, 6))))
        elif op == 10:
            lines.append(f"get_{rnd.choice(['integer', 'boolean', 'string'])} {i} "
                         f"{vr(rnd.choice(['Integer', 'Boolean', 'String']))}")
        elif op in (11, 12, 13):
            lines.append(f"step_here {i} {rnd.choice([1, 1, 1, 2, 3, 0.5, 0, -1]) * ts!r}")
        elif op == 14:
            lines.append(f"step {i} {rnd.choice([0, 1, 2, -1]) * ts!r} {ts!r}")
        elif op == 15:
            op_name = rnd.choice(["get_state", "get_state", "set_state", "free_state", "serialize", "replace"])
            lines.append(f"{op_name} {i} {rnd.randrange(3)}")
        elif op == 16:
            lines.append(f"time {i}")
        elif op == 17 and rnd.random() < 0.1:
            lines.append(f"free {i}")
            live.discard(i)
        else:
            lines.append(f"get_real {i} " + " ".join(str(v.valueReference) for v in variables
                                                      if v.causality == "output" and v.type == "Real"))
    return lines


@pytest.mark.parametrize("name", ["PeixotoEx1Plant", "CoxTothTruncationTruncatedKalman", "AffineDemoHinfPD",
                                  "PeixotoEx1Scheduler", "IoDemoPlant"])
def test_random_call_sequences_run_clean_under_address_and_undefined_behaviour_sanitizers(native_fmus, name,
                                                                                         tmp_path):
    """3,000 random FMI calls (seeded: the same every run) on up to three instances,
    in the C host with the runtime built under ASan and UBSan: no memory error, no
    leak, no undefined behaviour, every call answered fmi2OK, fmi2Warning or
    fmi2Error. (tests/test_fmu_differential.py checks what such sequences answer,
    against the Python FMU, in fmpy.)"""
    from tests.native_hosts import host_exe

    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler with sanitizers (cc, gcc) on this machine")
    lib = sanitized_library(native_fmus[name], tmp_path)
    md = read_model_description(str(native_fmus[name]))
    env = {"ASAN_OPTIONS": "detect_leaks=1:exitcode=23", "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
    script = _random_script(md, seed=sum(map(ord, name)), calls=3000)
    proc = _run_script([str(host_exe("sanitized")), str(lib), md.guid, "file:///nonexistent"], script, env)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "ERROR: AddressSanitizer" not in proc.stderr and "runtime error" not in proc.stderr, proc.stderr[-4000:]
    out = proc.stdout.splitlines()
    assert out[-1] == "DONE"
    statuses = [line.split() for line in out if line.startswith("STATUS")]
    assert len(statuses) == len(script)
    assert all(s[2] in ("0", "1", "3") for s in statuses), sorted({s[2] for s in statuses})
    # the sequences reach what they are for: steps taken and refused, states restored
    steps = [s[2] for s in statuses if s[1].startswith("step")]
    assert steps.count("0") >= 20 and steps.count("3") >= 20, (steps.count("0"), steps.count("3"))
    assert sum(s[1] == "set_state" and s[2] == "0" for s in statuses) >= 5


@pytest.mark.parametrize("name", EVERY_ROLE)
def test_the_c_host_runs_every_role_with_an_empty_environment(native_fmus, name):
    """The zig-built linux64 binary in the plain C host under ``env -i``: the
    lifecycle script runs to the end with the expected statuses, nothing on stderr."""
    from tests.native_hosts import host_exe

    md = read_model_description(str(native_fmus[name]))
    folder = Path(native_fmus[name]).with_suffix("")
    with zipfile.ZipFile(native_fmus[name]) as z:
        z.extractall(folder)
    lib = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    proc = _run_script(["env", "-i", str(host_exe("plain")), str(lib), md.guid, (folder / "resources").as_uri()],
                       _lifecycle_script(md), {})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert proc.stdout.splitlines()[-1] == "DONE"


# -- Windows: the win64 binary under wine ---------------------------------------------------------


NO_WINE = pytest.mark.skipif(wine() is None, reason="wine is not installed (apt-get install wine64): the win64 binary "
                                                    "is checked by its imports and exports only (test_native_fmus)")


@NO_WINE
@pytest.mark.parametrize("test, name", [("plant", "PeixotoEx1Plant"), ("plant", "CoxTothTruncationPlant"),
                                        ("kalman", "CoxTothTruncationKalman"), ("hinf", "AffineDemoHinfPD"),
                                        ("truncated", "steady-state, tau = 2")])
def test_the_win64_binary_gives_the_librarys_numbers_under_wine(native_fmus, test, name, tmp_path):
    """The C host cross-compiled for Windows (zig) runs the win64 DLL under wine;
    the numbers are checked against the library with the role's bound, as for
    the Linux binary (the C runtime's functions, msvcrt's, within FUNC_ULPS)."""
    from tests import test_native_fmus as t

    opened = []

    def opener(path: Path):
        d = HostDriver(path, kind="windows")
        opened.append(d)
        return d

    run = {"plant": t.test_plant_gives_the_librarys_numbers, "kalman": t.test_kalman_filter_gives_the_librarys_numbers,
           "hinf": t.test_hinf_filter_gives_the_librarys_numbers,
           "truncated": t.test_truncated_kalman_filter_gives_the_librarys_numbers}[test]
    try:
        run(native_fmus, opener, name, tmp_path)
    finally:
        for d in opened:
            d.close()


def _same_real(linux: str, windows: str) -> bool:
    """Two Reals the C hosts printed (``%.17g``) are the same: equal, both NaN (glibc
    prints ``-nan``, msvcrt ``-nan(ind)``), or within a relative 1e-9."""
    if "nan" in linux and "nan" in windows:
        return True
    a, b = float(linux), float(windows)
    return a == b or (np.isfinite(a) and np.isfinite(b) and abs(a - b) <= 1e-9 * max(abs(a), abs(b)))


@NO_WINE
@pytest.mark.parametrize("name", EVERY_ROLE)
def test_the_win64_binary_answers_random_call_sequences_as_the_linux64_binary(native_fmus, name):
    """The 3,000 random calls of the sanitizer test on the linux64 binary in the plain
    C host and on the win64 DLL in the C host cross-compiled for Windows, under wine:
    the same status and the same messages for every call, the same Integers, Strings,
    sizes and times, and Reals within a relative 1e-9 (msvcrt's sin, cos and exp may
    differ from glibc's in the last bits: the bound of test_fmu_differential, far above
    such differences carried through these runs' at most ~100 steps, far below what a
    wrong state or a skipped sample gives). The Windows binary has the error semantics
    of the Linux one, refusals included, not only its numbers on the good path."""
    from tests.native_hosts import host_exe, windows_host

    md = read_model_description(str(native_fmus[name]))
    folder = Path(native_fmus[name]).with_suffix("")
    with zipfile.ZipFile(native_fmus[name]) as z:
        z.extractall(folder)
    script = _random_script(md, seed=sum(map(ord, name)), calls=3000)
    so = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    linux = _run_script([str(host_exe("plain")), str(so), md.guid, (folder / "resources").as_uri()], script, {})
    cmd, env = windows_host(folder, md)
    windows = _run_script(cmd, script, env)
    assert linux.returncode == 0 and linux.stderr == "", linux.stderr[-4000:]
    assert windows.returncode == 0 and windows.stderr == "", windows.stderr[-4000:]
    a, b = linux.stdout.splitlines(), windows.stdout.splitlines()
    assert a[-1] == b[-1] == "DONE" and len(a) == len(b)
    assert sum(line.startswith("STATUS step") for line in a) >= 100  # the sequences reach the steps
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        if x.startswith("REAL ") and y.startswith("REAL "):
            xs, ys = x.split()[1:], y.split()[1:]
            same = len(xs) == len(ys) and all(map(_same_real, xs, ys))
        else:
            same = x == y
        assert same, f"line {i + 1} of the hosts' output: linux {x!r}, windows {y!r}"


# -- both backends in one C host: what a careless host passes -------------------------------------

#: Calls fmpy never makes (tests/test_fmu_differential.py runs the rest on both backends): names and
#: strings that are NULL or not UTF-8, statuses of every kind, log categories unknown or NULL, a
#: state deserialized over the one its variable holds. The FMU: a truncated Kalman filter (String
#: parameter ``start``, value reference 1).
CARELESS_HOST = [
    "instantiate 0 \\null 1", "instantiate 0 R\\xe9gulateur 1", "instantiate 0 \\xed\\xa0\\x80 1",
    "instantiate 0 \\x00 1", "instantiate 0 \\x20\\x09\\x0d 1", "instantiate 0 R\\xc3\\xa9gulateur 1",
    "instantiate 1 b 1 \\null",  # no resource location
    f"instantiate 1 b 1 = {{{'0' * 150}}}",  # another FMU's GUID, a long one: cut alike
    "debug 0 1 2 logAll nonsense", "debug 0 1 1 \\xff", "debug 0 1 2", "debug 0 1 1 logStatusError", "debug 0 1 0",
    "set_string 0 1 \\null", "get_string 0 1", "set_string 0 1 caf\\xe9", "get_string 0 1",
    "set_string 0 1 \\xf0\\x9f\\x98\\x80", "get_string 0 1", "set_string 0 1 steady-state",
    "set_string_back 0 1 zero", "get_string 0 1", "get_real 0 2147483653", "get_integer 0 4294967295",
    *(f"status 0 {kind} {which}" for kind in ("status", "integer", "string", "real", "boolean", "real_null",
                                               "boolean_null") for which in range(4)),
    "setup 0 0.5 nan", "setup 0 0.5 0.25", "setup 0 0.5 3.5", "enter 0", "exit 0", "step 0 0.5 1",
    "get_state 0 0", "replace 0 0",
    # NULL arguments of the state calls, a buffer one byte short, bytes that are no state
    *(f"state_null 0 {which} 0" for which in ("get", "set", "size_state", "size_out", "serialize_state",
                                              "serialize_buffer", "deserialize_bytes", "deserialize_out")),
    "serialize_short 0 0 1", "deserialize_text 0 1 abc", "deserialize_text 0 1 \\x00",
    "step 0 1.5 1", "set_state 0 0", "time 0", "status 0 real 2",
    "step 0 1.5 3", "step 0 1.5 2", "step 0 3.5 1", "free 0",  # past the stop time 3.5: refused
]


def _comparable(line: str) -> str:
    """A host's output line as both backends must print it: without the backend the version
    message names, the size of a serialized state (each backend's own format) and the FMU's
    GUID (each backend's own)."""
    line = re.sub(r"^(LOG 0 logAll \[\w+\] lpvest \S+) \(.*\)$", r"\1 (backend)", line)
    line = re.sub(r"does not match this FMU's \{[0-9a-f-]+\}$", "does not match this FMU's <its GUID>", line)
    # a buffer one byte short of a serialized state
    short = re.search(r"the buffer holds (\d+) bytes, the state needs (\d+) ", line)
    if short and int(short[2]) == int(short[1]) + 1:
        line = line.replace(short[0], "the buffer holds n - 1 bytes, the state needs n ")
    return re.sub(r"^SIZE \d+$", "SIZE n", line)


def _both_backends(fmus, native_fmus, name: str, script: list[str], tmp_path: Path,  # noqa: ANN001
                   env: dict[str, str] | None = None) -> tuple[list[str], list[str]]:
    """The C host's output of ``script`` on the Python FMU ``name`` (libpython preloaded) and
    on the native one."""
    from tests.lifecycle_host import c_env
    from tests.native_hosts import host_exe

    outs = []
    for backend, fmu, extra in (("python", fmus[name], c_env()), ("native", native_fmus[name], {})):
        md = read_model_description(str(fmu))
        folder = tmp_path / backend
        with zipfile.ZipFile(fmu) as z:
            z.extractall(folder)
        lib = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
        proc = _run_script([str(host_exe("plain")), str(lib), md.guid, (folder / "resources").as_uri()], script,
                           {**extra, **(env or {})})
        assert proc.returncode == 0 and proc.stdout.splitlines()[-1] == "DONE", (backend, proc.stderr[-3000:])
        outs.append([_comparable(line) for line in proc.stdout.splitlines()])
    return outs[0], outs[1]


def test_both_backends_answer_a_careless_c_host_alike(fmus, native_fmus, tmp_path):
    """What fmpy never passes, in the C host on the Python FMU (through the status bridge)
    and the native one: the same status and the same message for every call. pythonfmu
    crashed the host on an instance name that is not UTF-8 (Latin-1, a lone surrogate),
    answered fmi2Fatal with a NULL log category to such a string value and stored a NULL
    one as "None"; fmi2GetStatus said fmi2Error ("not supported") where FMI 2.0 (4.2.3)
    says fmi2Discard; the backends disagreed on unknown log categories; and the native
    fmi2DeSerializeFMUstate freed the state its output variable held, which the host
    then freed again. The backends also differed on an empty instance name, a NULL
    resource location, the NULL arguments of the state calls, a short buffer and bytes
    that are no state (found by a C-host review)."""
    python, native = _both_backends(fmus, native_fmus, "CoxTothTruncationTruncatedKalman", CARELESS_HOST, tmp_path)
    assert python == native, "\n".join(f"{a!r} | {b!r}" for a, b in zip(python, native, strict=False) if a != b)
    statuses = [line.split()[2] for line in native if line.startswith("STATUS")]
    # NULL, Latin-1, a surrogate, an empty name and one of white space refused; UTF-8 made; no
    # resource location refused
    assert statuses[:8] == ["null"] * 5 + ["0", "null", "null"]
    log = "LOG 3 logStatusError [CoxTothTruncationTruncatedKalman] "  # the bridge's messages too
    assert log + "fmi2Instantiate: no instance name (NULL)" in native
    assert native.count(log + "fmi2Instantiate: the instance name is not UTF-8 text") == 2
    assert native.count(log + "fmi2Instantiate: the instance name is empty or white space only (FMI 2.0, 2.1.5: "
                        "a non-empty name)") == 2
    assert ("LOG 1 logStatusWarning [CoxTothTruncationTruncatedKalman] fmi2SetDebugLogging: unknown log category "
            "(not UTF-8 text)") in native
    assert "STRING \U0001f600" in native  # four bytes of UTF-8 taken
    assert native.count("STRING theorem") == 2  # a NULL value and Latin-1 refused, nothing set
    assert native[native.index("STATUS set_string_back 0") + 1] == "STRING steady-state"  # the last one set
    # pythonfmu hands a value reference above 2**31 - 1 on as negative: named as the host gave it
    assert log + "fmi2GetReal: value reference 2147483653 is not a variable of this FMU" in python
    assert log + "fmi2Instantiate: no resource location (NULL; FMI 2.0, 2.1.5: the URI of the FMU's resources " \
        "folder)" in native
    assert log + "fmi2Instantiate: GUID {" + "0" * 99 + " does not match this FMU's <its GUID>" in native
    # every NULL argument of a state call named so, a short buffer with both sizes, no state's bytes
    assert native.count(log + "fmi2GetFMUstate: a NULL argument (a state, pointer or buffer)") == 1
    assert sum(line.startswith(log) and "FMUstate" in line and line.endswith(": a NULL argument (a state, pointer "
                                                                           "or buffer)") for line in native) == 8
    assert (log + "fmi2SerializeFMUstate: the buffer holds n - 1 bytes, the state needs n "
            "(fmi2SerializedFMUstateSize)") in native
    assert native.count(log + "fmi2DeSerializeFMUstate: ArgumentError: not a serialized lpvest FMU state") == 2
    assert "TIME 1.5" in native  # the restored time, after a state replaced by its deserialized copy
    assert statuses.count("2") == 3 * 4 + 3 + 3  # fmi2Discard: the statuses no FMU has
    # a stop time that is not a number or before the start refused; steps ending after it refused
    assert statuses[-6:] == ["0", "0", "3", "0", "3", "0"], native[-12:]  # time, status, 3 steps, free
    assert log + "fmi2SetupExperiment: ArgumentError: stop time 0.25 is before the start time 0.5" in native
    assert (log + "fmi2DoStep refused at t = 1.5 (h = 3): the step would end at t + h = 4.5, after the stop time "
            "3.5 (fmi2SetupExperiment; FMI 2.0, 2.1.6)") in native


#: String parameter values a message must quote as Python's repr does (escapes as \xHH)
ODD_STRINGS = ["it's\\x09\\xc2\\x85\\xc2\\xa0caf\\xc3\\xa9", "x" * 200, "\\xe2\\x80\\xa8" + "'\"" * 20,
               "\\xf0\\x9f\\x98\\x80\\x5c"]


def _decoded(text: str) -> str:
    return re.sub(r"\\x([0-9a-f]{2})", lambda m: chr(int(m[1], 16)), text).encode("latin-1").decode("utf-8")


def test_both_backends_quote_a_bad_string_parameter_alike(fmus, native_fmus, tmp_path):
    """A String parameter's bad value is quoted in the refusal as lpvest's abbreviate does,
    by both backends: a quote, a tab, a character Python escapes (U+0085, U+00A0, U+2028),
    others shown as they are, a long value cut in the middle with its length. The native
    runtime cut the Kalman start at 159 bytes with no word of it and quoted it in '%s'."""
    from lpvest.core._errors import abbreviate

    table = [("0", "table"), ("9", "0\\x091 2 \\xf0\\x9f\\x98\\x80; 1 2")]  # a row of 3 numbers and more
    # numbers and blanks are ASCII (Python's strip, \\s and float() took Unicode's: NBSP, \\x1c, an
    # ideographic space, NEL, an Arabic-Indic digit), at most 300 characters
    tables = [[("0", "table"), ("9", text)] for text in (
        "0\\xc2\\xa01; 1 2", "0\\x1c1; 1 2", "0 1\\xe3\\x80\\x80; 1 2", "0 1;\\xc2\\x85 1 2", "0 \\xd9\\xa1; 1 2",
        "0 " + "1" * 301 + "; 1 2")]
    cases = {"CoxTothTruncationTruncatedKalman": [[("1", v)] for v in ODD_STRINGS],
             "CoxTothTruncationScheduler": [[("0", v)] for v in ODD_STRINGS[:2]] + [table, *tables]}
    for name, instances in cases.items():
        script = []
        for sets in instances:  # an instance each, its strings set, initialized: refused
            script += ["instantiate 0 a 1", *(f"set_string 0 {vr} {value}" for vr, value in sets), "setup 0 0",
                       "enter 0", "exit 0", "free 0"]
        python, native = _both_backends(fmus, native_fmus, name, script, tmp_path / name)
        assert python == native, "\n".join(f"{a!r} | {b!r}" for a, b in zip(python, native, strict=False) if a != b)
        errors = [line for line in native if line.startswith("LOG 3 ")]
        if name.endswith("Kalman"):
            for [(_, value)] in instances:
                said = f"start = {abbreviate(_decoded(value), 30)}; expected one of theorem, steady-state"
                assert any(said in line for line in errors), (said, errors)
        else:
            for [(_, value)] in instances[:2]:
                said = f"kind = {abbreviate(_decoded(value), 30)} is not a signal kind"
                assert any(said in line for line in errors), (said, errors)
            assert any(f"table row 1 ({abbreviate('0' + chr(9) + '1 2 ' + chr(0x1f600), 30)}) has 4 numbers" in line
                       for line in errors), errors
            assert sum("table row" in line for line in errors) == 1 + len(tables), errors


@pytest.mark.skipif(shutil.which("localedef") is None, reason="needs localedef (glibc) to make a German locale")
def test_the_restored_time_is_read_the_same_in_a_locale_with_a_decimal_comma(fmus, native_fmus, tmp_path):
    """The status bridge read the time a Python slave states after fmi2SetFMUstate with strtod,
    which in a host whose locale writes a decimal comma read "1.5" as 1: fmi2LastSuccessfulTime
    was wrong with fmi2OK, and the host's next step from it was refused. Now both backends
    report 1,5 (printed by the host in that locale)."""
    locales = tmp_path / "locales"
    locales.mkdir()
    made = subprocess.run(["localedef", "-i", "de_DE", "-f", "UTF-8", str(locales / "de_DE.UTF-8")],
                          capture_output=True, text=True, check=False)
    if not (locales / "de_DE.UTF-8").exists():
        pytest.skip(f"localedef could not make de_DE.UTF-8: {made.stderr[-300:]}")
    script = ["instantiate 0 a 0", "setup 0 0.5", "enter 0", "exit 0", "step 0 0.5 1", "get_state 0 0",
              "step 0 1.5 1", "locale de_DE.UTF-8", "set_state 0 0", "time 0", "free 0"]
    python, native = _both_backends(fmus, native_fmus, "CoxTothTruncationTruncatedKalman", script, tmp_path,
                                    {"LOCPATH": str(locales)})
    assert "STATUS locale 0" in native and "TIME 1,5" in native
    assert python == native


# -- libcosim, fmpy's simulate_fmu -----------------------------------------------------------------


def test_every_native_fmu_loads_and_steps_in_libcosim(native_fmus):
    """Every native FMU, one libcosim execution after another in one process,
    twice over, each with its own sample time."""
    names = sorted(n for n, p in native_fmus.paths.items()
                   if not read_model_description(str(p)).coSimulation.needsExecutionTool)
    result = libcosim_driver.load_and_step({n: native_fmus[n] for n in names})
    assert result == {f"{r}:{n}": True for r in range(2) for n in names}


def test_libcosim_connects_the_native_scheduler_source_and_plant_like_the_library(native_fmus):
    """Scheduler -> Plant and Source -> Plant in libcosim with the native FMUs:
    the plant state and output equal the library's simulation (the bound of
    the Python FMUs' test: the same recursion in another order)."""
    from tests.test_fmu_hosts import test_libcosim_connects_scheduler_source_and_plant_like_the_library as run

    run(native_fmus)


@pytest.mark.parametrize("name", ["CoxTothTruncationKalman", "PeixotoEx1HinfPD"])
def test_plain_simulate_fmu_records_the_estimate_of_sample_k_one_row_later(native_fmus, name):
    """fmpy's simulate_fmu sets the inputs of sample k at t_k, steps and records
    at t_k + h: the row at t_(k+1) holds, to the bit, what the native filter
    outputs for sample k before its step (which test_native_fmus checks against
    the library), as for the Python FMUs."""
    from fmpy import simulate_fmu

    from tests.fmu_driver import Driver
    from tests.test_fmu_filters import FILTERS, FMU_PATHS

    FMU_PATHS.update(native_fmus.paths)
    make, params, data_fn, T, h = FILTERS[name]
    data = data_fn(T)
    names, cols = ["time"], [np.arange(T) * h]
    for port, arr in data.items():
        for i in range(arr.shape[1]):
            names.append(f"{port}[{i + 1}]")
            cols.append(arr[:, i])
    table = np.zeros(T, dtype=[(n, float) for n in names])
    for n, c in zip(names, cols, strict=True):
        table[n] = c
    outputs = [v.name for v in read_model_description(str(native_fmus[name])).modelVariables
               if v.causality == "output"]
    res = simulate_fmu(str(native_fmus[name]), input=table, output=outputs, output_interval=h, stop_time=T * h,
                       start_values=params)
    direct = [o for o in outputs if not o.startswith("xf[")]  # the H-infinity filter's state is at its row's time
    d = Driver(native_fmus[name])
    assert d.initialize(**params) == 0
    for k in range(T):
        for port, arr in data.items():
            d.set_vector(port, arr[k])
        before = d.outputs(outputs)
        assert d.step(k * h, h) == 0
        assert np.array_equal(np.array([res[o][k + 1] for o in direct]), before[:len(direct)]), k
        assert np.array_equal(np.array([res[o][k] for o in outputs[len(direct):]]), before[len(direct):]), k
    d.free()


# -- the source FMU, reproducible builds --------------------------------------------------------


@pytest.mark.skipif(shutil.which("cmake") is None, reason="fmpy builds source FMUs with cmake, which is missing")
@pytest.mark.parametrize("test, name", [("plant", "CoxTothEx1Plant"), ("hinf", "PeixotoEx1HinfPD")])
def test_the_source_fmu_builds_with_fmpy_and_gives_the_librarys_numbers(native_fmus, test, name, tmp_path):
    """sources/ and its build description are all a tool needs: fmpy's
    build_platform_binary compiles the linux64 binary with cmake and the host's
    compiler, and that binary gives the library's numbers (the role's bound)."""
    from fmpy.build import build_platform_binary

    from tests import test_native_fmus as t

    folder = tmp_path / "unzipped"
    with zipfile.ZipFile(native_fmus[name]) as z:
        z.extractall(folder)
    shutil.rmtree(folder / "binaries")
    (tmp_path / "build").mkdir()
    build_platform_binary(folder, tmp_path / "build")
    built = folder / "binaries" / "linux64" / f"{name}.so"
    assert built.is_file()
    rebuilt = tmp_path / f"{name}.fmu"
    with zipfile.ZipFile(rebuilt, "w") as z:
        for f in sorted(folder.rglob("*")):
            if f.is_file():
                z.write(f, f.relative_to(folder).as_posix())
    run = {"plant": t.test_plant_gives_the_librarys_numbers, "hinf": t.test_hinf_filter_gives_the_librarys_numbers}
    from tests.fmu_driver import Driver

    class Rebuilt:
        def __getitem__(self, key: str) -> Path:
            return rebuilt

    opened = []

    def opener(path: Path):
        d = Driver(path)
        opened.append(d)
        return d

    try:
        run[test](Rebuilt(), opener, name, tmp_path / "ref")
    finally:
        for d in opened:
            d.free()


def test_the_same_inputs_give_a_byte_identical_native_fmu(native_fmus, tmp_path):
    """Two builds of the same plans in two processes and two folders: the same
    bytes. One is the run's native set (tests/conftest_fmu.py, built in a test
    process), the other a build from scratch in a fresh process."""
    code = textwrap.dedent("""
        import sys
        from lpvest.fmi._build import build_fmu, plan_system
        plans, _ = plan_system("peixoto-ex1")
        for p in plans:
            if p.role in ("Plant", "HinfPD"):
                build_fmu(p, sys.argv[1], backend="native")
        plans, _ = plan_system("cox-toth-truncation")
        build_fmu(next(p for p in plans if p.role == "TruncatedKalman"), sys.argv[1], backend="native")
    """)
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "two")], check=True, capture_output=True)
    names = sorted(f.name for f in (tmp_path / "two").glob("*.fmu"))
    assert names == ["CoxTothTruncationTruncatedKalman.fmu", "PeixotoEx1HinfPD.fmu", "PeixotoEx1Plant.fmu"]
    for n in names:
        assert native_fmus[n.removesuffix(".fmu")].read_bytes() == (tmp_path / "two" / n).read_bytes(), n
