"""FMI 2.0 call sequences a host may make, driven in fmpy or libcosim (run as a
script in its own process by tests/test_fmu_lifecycle.py; the C host
tests/data/c_lifecycle.c drives the same sequences).

usage: python tests/lifecycle_host.py fmpy|libcosim JOB.json [SEQUENCE ...]
       python tests/lifecycle_host.py matrix FOLDER   (the create -> free matrix of its FMUs)

JOB.json holds, per FMU, what a host needs (unpacked folder, GUID, model
identifier, step size, input value references and values, output value
references). The script prints ``BEGIN <fmu> <sequence>`` (flushed) before each
sequence, so that a crash names the sequence it happened in, and at the end one
line ``RESULT <json>``: per FMU and sequence the statuses of the calls and the
outputs read.

Sequences (fmpy and the C host; op letters as in SEQUENCES): I instantiate,
F free, S setup experiment, E enter and X exit initialization mode, R run
three samples (set inputs, read outputs, step), T terminate, Z reset, B a
refused step (h = -1: fmi2Error, also before initialization). libcosim makes
its own calls; it has no reset (see LIBCOSIM_SEQUENCES).
"""

from __future__ import annotations

import gc
import json
import sys

#: name -> operations, each on the one instance of the FMU
SEQUENCES: dict[str, str] = {
    "instantiate-free": "IF",
    "setup-free": "ISF",
    "init-mode-free": "ISEF",
    "initialized-free": "ISEXF",
    "step-free": "ISEXRF",
    "terminate-free": "ISEXRTF",
    "error-free": "ISEXBF",
    "error-before-init-free": "IBF",
    "reset-free": "IZF",
    "reset-instantiated": "IZSEXRTF",
    "reset-init-mode": "ISEZSEXRTF",
    "reset-stepping": "ISEXRZSEXRTF",
    "reset-error": "ISEXBZSEXRTF",
    "reset-terminated": "ISEXRTZSEXRTF",
}
#: several instances of one FMU, created and freed out of order: (instance, op)
MANY: list[tuple[int, str]] = [
    (0, "I"), (1, "I"), (2, "I"), (0, "S"), (0, "E"), (0, "X"), (0, "R"), (1, "F"), (2, "S"), (2, "E"),
    (2, "X"), (2, "R"), (0, "F"), (3, "I"), (2, "Z"), (2, "F"), (3, "S"), (3, "E"), (3, "X"), (3, "R"),
    (3, "T"), (3, "F"),
]
#: libcosim: what an execution does with its slaves (it makes the calls: instantiate when a
#: slave is created, setup and initialization at the first step, terminate and free when the
#: execution is deleted). "connect-fail-free": an execution deleted after a refused connection,
#: before its first step (instantiate -> free). libcosim has no reset, and libcosimpy 0.0.6
#: ends the process (std::terminate on an uncaught cosim::error) when an FMU returns fmi2Error
#: during initialization, so "free after an error" is driven in fmpy and the C host only.
LIBCOSIM_SEQUENCES = ("instantiate-free", "step-free", "connect-fail-free")

STEPS = 3


def _fmpy_sequences(job: dict, names: list[str], every: bool) -> dict:
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    def call(fmu: FMU2Slave, function: str, *args) -> int:  # noqa: ANN002
        try:
            return int(getattr(fmu, function)(fmu.component, *args))
        except FMICallException as exc:
            return int(exc.status)

    def run(fmu: FMU2Slave, spec: dict, out: dict) -> list[int]:
        statuses = []
        for k in range(STEPS):
            if spec["inputs"]:
                try:
                    fmu.setReal([vr for vr, _ in spec["inputs"]], [v for _, v in spec["inputs"]])
                    statuses.append(0)
                except FMICallException as exc:
                    statuses.append(int(exc.status))
            out["outputs"].append(fmu.getReal(spec["outputs"]))
            statuses.append(call(fmu, "fmi2DoStep", k * spec["h"], spec["h"], 1))
        return [max(statuses)]

    def op(fmus: dict[int, FMU2Slave], i: int, letter: str, spec: dict, out: dict) -> list[int]:
        if letter == "I":
            fmus[i] = FMU2Slave(guid=spec["guid"], unzipDirectory=spec["unzip"],
                                modelIdentifier=spec["identifier"], instanceName=f"{spec['name']}-{i}")
            fmus[i].instantiate()
            return [0]
        fmu = fmus[i]
        if letter == "F":
            fmu.fmi2FreeInstance(fmu.component)
            fmu.freeLibrary()
            del fmus[i]
            return [0]
        if letter == "S":
            return [call(fmu, "fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0)]
        if letter == "E":
            return [call(fmu, "fmi2EnterInitializationMode")]
        if letter == "X":
            return [call(fmu, "fmi2ExitInitializationMode")]
        if letter == "R":
            return run(fmu, spec, out)
        if letter == "T":
            return [call(fmu, "fmi2Terminate")]
        if letter == "Z":
            return [call(fmu, "fmi2Reset")]
        if letter == "B":
            return [call(fmu, "fmi2DoStep", 0.0, -1.0, 1)]
        raise ValueError(letter)

    result: dict = {}
    for spec in job["fmus"]:
        result[spec["name"]] = {}
        for seq in names:
            print(f"BEGIN {spec['name']} {seq}", flush=True)
            out: dict = {"statuses": [], "outputs": []}
            fmus: dict[int, FMU2Slave] = {}
            steps = MANY if seq == "many" else [(0, c) for c in SEQUENCES[seq]]
            for i, letter in steps:
                out["statuses"] += op(fmus, i, letter, spec, out)
            result[spec["name"]][seq] = out
    if not every:
        return result
    # every FMU at once, created in order and freed interleaved, half of them run
    print("BEGIN * all-at-once", flush=True)
    fmus: dict[int, FMU2Slave] = {}
    out = {"statuses": [], "outputs": []}
    specs = job["fmus"]
    for i, spec in enumerate(specs):
        out["statuses"] += op(fmus, i, "I", spec, out)
    for i, spec in enumerate(specs):
        if i % 2 == 0:
            for letter in "SEXR":
                out["statuses"] += op(fmus, i, letter, spec, out)
    order = [i for i in range(len(specs)) if i % 2] [::-1] + [i for i in range(len(specs)) if not i % 2]
    for i in order:
        out["statuses"] += op(fmus, i, "F", specs[i], out)
    result["*"] = {"all-at-once": out}
    return result


def _libcosim_sequences(job: dict, names: list[str], every: bool) -> dict:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    result: dict = {}

    def execution(spec: dict, name: str) -> tuple:
        ex = CosimExecution.from_step_size(step_size=int(round(spec["h"] * 1e9)))
        slave = CosimLocalSlave(fmu_path=spec["path"], instance_name=name)  # instantiates the FMU
        index = ex.add_local_slave(slave)
        return ex, slave, index

    for spec in job["fmus"]:
        result[spec["name"]] = {}
        for seq in names:
            print(f"BEGIN {spec['name']} {seq}", flush=True)
            out: dict = {"ok": [], "outputs": []}
            ex, slave, index = execution(spec, f"{spec['name']}-{seq}")
            if seq == "step-free":
                obs = CosimObserver.create_last_value()
                ex.add_observer(obs)
                for vr, value in spec["inputs"]:
                    ex.real_initial_value(index, vr, value)
                out["ok"].append(bool(ex.step(STEPS)))
                out["outputs"].append(list(obs.last_real_values(index, spec["outputs"])))
            elif seq == "connect-fail-free":
                out["ok"].append(ex.connect_real_variables(index, 10**6, index, 10**6 + 1) == 0)  # 0: success
            del ex, slave
            gc.collect()
            result[spec["name"]][seq] = out
    if not every:
        return result
    # many executions and slaves alive at once, deleted in another order than created
    print("BEGIN * all-at-once", flush=True)
    alive = [execution(spec, f"{spec['name']}-all") for spec in job["fmus"]]
    ok = []
    for i, (ex, _, _) in enumerate(alive):
        if i % 2 == 0:
            ok.append(bool(ex.step(STEPS)))
    for i in [i for i in range(len(alive)) if i % 2][::-1] + [i for i in range(len(alive)) if not i % 2]:
        alive[i] = None  # type: ignore[call-overload]
        gc.collect()
    result["*"] = {"all-at-once": {"ok": ok}}
    return result


def make_job(paths: dict[str, str], folder: str) -> dict:
    """The job for the hosts: each FMU unpacked under ``folder``, its GUID,
    identifier and step, its inputs set to the middle of their declared range
    (else their start value), and its Real outputs (at most 64: the C
    host's limit)."""
    import os
    import zipfile

    from fmpy import read_model_description

    fmus = []
    for name in sorted(paths):
        md = read_model_description(paths[name])
        unzip = os.path.join(folder, name)
        with zipfile.ZipFile(paths[name]) as z:
            z.extractall(unzip)
        inputs, outputs = [], []
        for v in md.modelVariables:
            if v.type != "Real":
                continue
            if v.causality == "input":
                if v.min is not None and v.max is not None:
                    value = 0.5 * (float(v.min) + float(v.max))
                else:
                    value = float(v.start or 0.0)
                inputs.append([v.valueReference, value])
            elif v.causality == "output" and len(outputs) < 64:
                outputs.append(v.valueReference)
        fmus.append({"name": name, "path": paths[name], "unzip": unzip, "guid": md.guid,
                     "identifier": md.coSimulation.modelIdentifier, "h": float(md.defaultExperiment.stepSize),
                     "inputs": inputs, "outputs": outputs})
    return {"fmus": fmus}


def c_job(job: dict, sequences: dict[str, str] = SEQUENCES, *, many: bool = True) -> str:
    """The job as the C host reads it (tests/data/c_lifecycle.c)."""
    lines = []
    for f in job["fmus"]:
        assert not any(c.isspace() for c in f["unzip"] + f["guid"]), f["unzip"]
        ins = " ".join(f"{vr} {value!r}" for vr, value in f["inputs"])
        lines.append(f"FMU {f['name']} {f['unzip']} {f['identifier']} {f['guid']} {f['h']!r} {len(f['inputs'])} {ins} "
                     f"{len(f['outputs'])} {' '.join(map(str, f['outputs']))}")
    lines += [f"SEQ {name} {ops}" for name, ops in sequences.items()]
    if many:
        lines.append(f"MANY {len(MANY)} " + " ".join(f"{i}:{letter}" for i, letter in MANY))
    return "\n".join(lines) + "\n"


def _live_slaves() -> int:
    """Python objects of an FMU slave class still alive (after a garbage collection)."""
    gc.collect()
    return sum(1 for o in gc.get_objects() if any(c.__name__ == "Fmi2Slave" for c in type(o).__mro__[1:]))


def c_host(folder: str) -> str:
    """The C host (tests/data/c_lifecycle.c) compiled into ``folder``."""
    import os
    import shutil
    import subprocess

    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler")
    exe = os.path.join(folder, "c_lifecycle")
    src = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "c_lifecycle.c")
    subprocess.run([cc, "-O2", "-Wall", "-Wextra", "-Werror", "-o", exe, src, "-ldl"], check=True)
    return exe


def c_env() -> dict[str, str]:
    """The environment a C host needs for a Python FMU: libpython preloaded, numpy on the path."""
    import os
    import sysconfig

    import numpy as np

    libpython = os.path.join(sysconfig.get_config_var("LIBDIR") or "", sysconfig.get_config_var("INSTSONAME") or "")
    if not os.path.isfile(libpython):
        raise RuntimeError("no shared libpython")
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONPATH", "PYTHONHOME")}
    env.update(LD_PRELOAD=libpython, PYTHONPATH=os.path.dirname(os.path.dirname(os.path.abspath(np.__file__))))
    return env


def matrix(folder: str) -> str:
    """The create -> free matrix of every FMU in ``folder``: instantiate, then
    free, one process per host and FMU (a crash ends only its own)."""
    import glob
    import os
    import subprocess
    import tempfile

    paths = {os.path.basename(p)[:-4]: p for p in sorted(glob.glob(os.path.join(folder, "*.fmu")))}
    rows = [("FMU", "fmpy", "libcosim", "C host")]
    with tempfile.TemporaryDirectory() as tmp:
        exe, env = c_host(tmp), c_env()
        for name, path in paths.items():
            job = make_job({name: path}, os.path.join(tmp, "unz"))
            json_job = os.path.join(tmp, f"{name}.json")
            with open(json_job, "w", encoding="utf-8") as f:
                json.dump(job, f)
            text_job = os.path.join(tmp, f"{name}.txt")
            with open(text_job, "w", encoding="utf-8") as f:
                f.write(c_job(job, {"instantiate-free": "IF"}, many=False) + "PLAIN\n")
            cells = [name]
            for cmd, host_env in (([sys.executable, __file__, "fmpy", json_job, "instantiate-free"], None),
                                  ([sys.executable, __file__, "libcosim", json_job, "instantiate-free"], None),
                                  ([exe, text_job], env)):
                proc = subprocess.run(cmd, capture_output=True, text=True, env=host_env, check=False, timeout=600)
                survived = proc.returncode == 0 and ("RESULT" in proc.stdout or "DONE" in proc.stdout)
                cells.append("survived" if survived else f"crashed ({proc.returncode})")
            rows.append(tuple(cells))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows)


def main(argv: list[str]) -> int:
    if argv[:1] == ["matrix"]:
        print(matrix(argv[1]))
        return 0
    host, path, *names = argv
    job = json.loads(open(path, encoding="utf-8").read())
    if host == "fmpy":
        result = _fmpy_sequences(job, names or [*SEQUENCES, "many"], every=not names)
    elif host == "libcosim":
        result = _libcosim_sequences(job, names or list(LIBCOSIM_SEQUENCES), every=not names)
    else:
        raise SystemExit(f"unknown host {host!r}")
    result["live_slaves"] = _live_slaves()
    print("RESULT" + json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
