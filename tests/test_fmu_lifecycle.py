"""Every call sequence FMI 2.0 allows leaves the host running, in fmpy, libcosim
and a bare C host, for every FMU of the session set (docs/fmus.md, 6.).

One subprocess per host runs every sequence on every FMU (tests/lifecycle_host.py,
tests/data/c_lifecycle.c) and reports JSON; a crash names the sequence it
happened in (the last ``BEGIN`` line)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from tests.lifecycle_host import MANY, SEQUENCES, STEPS, c_env, c_host, c_job, make_job

HOST = Path(__file__).with_name("lifecycle_host.py")


@pytest.fixture(scope="module")
def job(fmus, tmp_path_factory):
    folder = tmp_path_factory.mktemp("lifecycle")
    job = make_job({name: str(path) for name, path in fmus.paths.items()}, str(folder / "unz"))
    path = folder / "job.json"
    path.write_text(json.dumps(job))
    return folder, job


def _run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:  # noqa: ANN003
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900, check=False, **kwargs)
    began = [line for line in proc.stdout.splitlines() if line.startswith("BEGIN")]
    assert proc.returncode == 0, (f"the host ended with {proc.returncode} in {began[-1] if began else 'start-up'}\n"
                                  + proc.stdout[-1500:] + proc.stderr[-3000:])
    return proc


def _expected_statuses(ops: str) -> list[int]:
    """fmi2OK for every call but the refused step (B): fmi2Error."""
    return [3 if op == "B" else 0 for op in ops]


def _check_runs(name: str, seq: str, ops: str, got: dict, fresh: list) -> None:
    assert got["statuses"] == _expected_statuses(ops), (name, seq, got["statuses"])
    runs = ops.count("R")
    assert len(got["outputs"]) == runs * STEPS, (name, seq)
    # after a reset, or in another instance, a run gives a fresh instance's numbers, to the bit
    for r in range(runs):
        assert got["outputs"][r * STEPS:(r + 1) * STEPS] == fresh, (name, seq, r)


def _check_sequences(job: dict, result: dict) -> None:
    for spec in job["fmus"]:
        name = spec["name"]
        fresh = result[name]["terminate-free"]["outputs"]
        assert len(fresh) == STEPS
        for seq, ops in SEQUENCES.items():
            _check_runs(name, seq, ops, result[name][seq], fresh)
        _check_runs(name, "many", "".join(op for _, op in MANY), result[name]["many"], fresh)
    # every FMU at once: instantiated in order, every other one run, freed interleaved
    n = len(job["fmus"])
    everyone = result["*"]["all-at-once"]
    assert everyone["statuses"] == [0] * (n + 4 * ((n + 1) // 2) + n)
    expected = [row for i, spec in enumerate(job["fmus"]) if i % 2 == 0
                for row in result[spec["name"]]["terminate-free"]["outputs"]]
    assert everyone["outputs"] == expected


def test_every_call_sequence_in_fmpy(job):
    """fmpy's FMU2Slave (the raw FMI calls): instantiate -> free, -> setup -> free,
    free in initialization mode, after an error, after terminate, reset in every
    state (then a run gives a fresh instance's numbers), several instances of an
    FMU created and freed out of order, every FMU alive at once. No slave object
    outlives its fmi2FreeInstance."""
    folder, spec = job
    proc = _run([sys.executable, str(HOST), "fmpy", str(folder / "job.json")])
    result = json.loads(next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))[len("RESULT"):])
    _check_sequences(spec, result)
    assert result["live_slaves"] == 0


def test_every_call_sequence_in_a_c_host(job, tmp_path):
    """The same sequences from a C host (dlopen, libpython preloaded), then the
    first FMU's library closed, opened again and run."""
    folder, spec = job
    try:
        exe, env = c_host(str(tmp_path)), c_env()
    except RuntimeError as exc:
        pytest.skip(f"a C host needs a C compiler and a shared libpython: {exc}")
    text = tmp_path / "job.txt"
    text.write_text(c_job(spec))
    proc = _run([exe, str(text)], env=env, cwd=tmp_path)
    assert proc.stdout.rstrip().endswith("DONE")
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    result: dict = {}
    for row in rows:
        result.setdefault(row["fmu"], {})[row["seq"]] = row
    _check_sequences(spec, result)
    first = spec["fmus"][0]["name"]
    _check_runs(first, "reload", "ISEXRTF", result[first]["reload"], result[first]["terminate-free"]["outputs"])


def test_libcosim_executions_deleted_at_any_point(job):
    """libcosim makes its own calls: a slave created and its execution deleted
    before the first step (also after a refused connection: instantiate -> free),
    an execution stepped and deleted (terminate -> free), every FMU in its own
    execution, all alive at once and deleted in another order."""
    folder, spec = job
    proc = _run([sys.executable, str(HOST), "libcosim", str(folder / "job.json")])
    result = json.loads(next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))[len("RESULT"):])
    for fmu in spec["fmus"]:
        got = result[fmu["name"]]
        assert got["instantiate-free"] == {"ok": [], "outputs": []}
        assert got["connect-fail-free"]["ok"] == [False]  # the connection was refused; then deleted
        assert got["step-free"]["ok"] == [True]
        outputs = got["step-free"]["outputs"][0]
        assert len(outputs) == len(fmu["outputs"]) and all(map(math.isfinite, outputs))
    assert result["*"]["all-at-once"]["ok"] == [True] * ((len(spec["fmus"]) + 1) // 2)
    assert result["live_slaves"] == 0
