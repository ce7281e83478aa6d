"""Ctrl-C (SIGINT) and SIGTERM during the long commands: the command stops,
exits 130 / 143, says in one line what it kept and how to go on, and keeps
nothing half-made.

Every test synchronises on an event, never on a delay: the command runs with
the test hook of :mod:`lpvest.core._interrupt` (``LPVEST_TEST_HOLD=MOMENT``), which
writes the moment to a file when the command reaches it and then waits; the
test sends the signal once the line is there. A held LMI solve waits on its
worker thread, exactly where a native solver (Clarabel) would be computing
without looking at Python's signals.
"""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import threading

import pyarrow.parquet as pq
import pytest

from lpvest.core._errors import shorten
from lpvest.core._interrupt import Interrupted, abandoned_calls, call_interruptibly, handling_signals
from lpvest.experiments._references import REFERENCES, read_reference
from tests.interrupting import ROOT, TIMEOUT, _default_sigint, interrupt_at, lpvest_command as _lpvest
from tests.test_sweep import _write


def _one_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.startswith("lpvest:")]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr, stderr
    return lines[0]


# ---------------------------------------------------------------------------
# H-infinity design and epsilon search
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(("signum", "status", "name"), [(signal.SIGINT, 130, "SIGINT"),
                                                         (signal.SIGTERM, 143, "SIGTERM")])
@pytest.mark.parametrize("how", [["--epsilon", "1"], ["--search"]])
def test_a_signal_during_a_design_solve_stops_it_and_writes_nothing(tmp_path, signum, status, name, how):
    out = tmp_path / "pd.json"
    res = interrupt_at(_lpvest("design", "peixoto-ex1", *how, "--out", str(out)), "solve", tmp_path, signum=signum)
    assert res.returncode == status, res.stderr
    line = _one_line(res.stderr)
    assert line.startswith(f"lpvest: interrupted ({name}): nothing was written"), line
    assert "run the same command again" in line
    assert not out.exists()


def test_an_interrupted_build_caches_no_design_and_leaves_no_partial_fmu(tmp_path):
    """... nor the status bridges it compiled before the design in the temporary
    folder: the command leaves with ``os._exit`` (the solve it abandoned runs on),
    after the clean-ups registered with atexit."""
    out = tmp_path / "fmus"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    res = interrupt_at(_lpvest("build", "--model", "examples/own_plant.toml", "--kinds", "Plant,HinfPD",
                               "--out", str(out)), "solve", tmp_path, env={"TMPDIR": str(scratch)})
    assert res.returncode == 130, res.stderr
    line = _one_line(res.stderr)
    assert "the interrupted one was not kept; run the same command again to resume" in line
    assert not (out / ".designs").exists() or not any((out / ".designs").iterdir())
    assert sorted(p.name for p in out.glob("*.fmu*")) == ["OwnPlantPlant.fmu"]  # built before the design; no .part
    assert not list(out.glob(".*.part"))
    assert not any(scratch.iterdir()), sorted(p.name for p in scratch.iterdir())


_SLOW_CLEAN_UP = """
import atexit, os, sys, threading
import lpvest.cli as cli

cli.main = lambda argv=None: 130  # a command interrupted while its solve runs on
cli.abandoned_calls = lambda: True

def slow_clean_up():
    with open(os.environ["LPVEST_TEST_READY"], "a") as f:
        f.write("clean-up\\n")
    threading.Event().wait(300)

atexit.register(slow_clean_up)
sys.exit(cli.run([]))
"""


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_second_signal_during_the_clean_ups_leaves_at_once_with_the_first_status(tmp_path, signum):
    """After an abandoned solve the command runs the atexit clean-ups before ``os._exit``; a
    second Ctrl-C or SIGTERM while one of them runs leaves at once with the status already
    chosen, with no traceback and not through the interpreter's shutdown."""
    res = interrupt_at([sys.executable, "-c", _SLOW_CLEAN_UP], "clean-up", tmp_path, signum=signum)
    assert res.returncode == 130, res.stderr
    assert res.stderr == "", res.stderr


def test_a_call_interrupted_while_it_runs_stays_abandoned_until_it_ends():
    """The call itself signals the main thread (which is then starting it or
    waiting for it): the interrupted call counts as running until it ends, so
    the command leaves with ``os._exit`` rather than through the interpreter's
    shutdown with a native solve still running, which aborted it now and then
    ("terminate called without an active exception"). On CPython 3.11 a
    ``Thread.join`` interrupted by the signal marks the thread as stopped."""
    release = threading.Event()

    def call() -> str:
        signal.pthread_kill(threading.main_thread().ident or 0, signal.SIGINT)
        release.wait()
        return "too late"

    abandoned: list[threading.Event] = []
    # a runner started in the background by a shell without job control ignores SIGINT
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with handling_signals(), pytest.raises(Interrupted, match="SIGINT"):
            call_interruptibly(call, on_abandon=abandoned.append)
        assert abandoned_calls()
        assert len(abandoned) == 1 and not abandoned[0].is_set()
    finally:
        release.set()
        signal.signal(signal.SIGINT, previous)
    abandoned[0].wait()
    assert not abandoned_calls()


def test_scs_stopped_by_its_own_sigint_handler_is_an_interruption_not_a_failed_point(tmp_path):
    """SCS catches SIGINT itself while it iterates and returns "interrupted",
    which cvxpy reports as a solver failure (a search would go on and cache a
    worse design). A program that never converges, SIGINT once it has started:
    wherever the signal lands (before SCS's handler is installed, or in it),
    the solve ends in a KeyboardInterrupt."""
    script = textwrap.dedent("""
        import os, sys, threading
        import cvxpy as cp, numpy as np
        from lpvest.core._interrupt import Interrupted, abandoned_calls, call_interruptibly, handling_signals
        from lpvest.design._program import _interruptible_scs

        n = 60
        rng = np.random.default_rng(0)
        C = rng.standard_normal((n, n))
        X = cp.Variable((n, n), symmetric=True)
        problem = cp.Problem(cp.Minimize(cp.trace((C + C.T) @ X) + cp.sum_squares(X)), [X >> 0, cp.trace(X) == 1])

        def solve():
            with open(sys.argv[1], "a") as f:
                f.write("solve\\n")
            problem.solve(solver=_interruptible_scs(), eps_abs=1e-300, eps_rel=1e-300, max_iters=2**31 - 1)

        with handling_signals():
            try:
                call_interruptibly(solve)
            except KeyboardInterrupt as exc:
                print("interrupted", type(exc).__name__, flush=True)
                # a solve abandoned in SCS (signal before its handler): leave as `lpvest` does
                os._exit(0) if abandoned_calls() else sys.exit(0)
        print("solved", problem.status)
        """)
    ready = tmp_path / "ready"
    proc = subprocess.Popen([sys.executable, "-c", script, str(ready)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, preexec_fn=_default_sigint)
    try:
        while proc.poll() is None and not (ready.is_file() and ready.read_text().endswith("\n")):
            try:
                proc.wait(timeout=0.01)
            except subprocess.TimeoutExpired:
                pass
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
    assert proc.returncode == 0, stderr
    # when the signal lands while SCS iterates, SCS prints "Failure:interrupted" (its C code, stdout)
    # first: 1 run in 50 under load did, and a signal sent seconds later always does
    assert stdout.splitlines()[-1] == "interrupted Interrupted", (stdout, stderr)
    assert set(stdout.splitlines()[:-1]) <= {"Failure:interrupted"}, (stdout, stderr)


# ---------------------------------------------------------------------------
# co-simulation and sweeps
# ---------------------------------------------------------------------------
@pytest.fixture
def cox_fmus(fmus):
    """cox-toth-truncation's Plant, Scheduler and Kalman FMUs: the run's FMU set
    (tests/conftest_fmu.py; these tests interrupt runs of them, not their build)."""
    return {name: fmus[name] for name in ("CoxTothTruncationPlant", "CoxTothTruncationScheduler",
                                          "CoxTothTruncationKalman")}


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_inside_an_fmu_step_stops_cosim_without_blaming_the_component(cox_fmus, tmp_path, signum, status):
    spec = _write(tmp_path / "spec", cox_fmus, n=2)
    out = tmp_path / "out"
    res = interrupt_at(_lpvest("cosim", str(spec.parent / "kalman.toml"), "--out", str(out)), "fmu-step",
                       tmp_path, signum=signum)
    assert res.returncode == status, res.stderr
    line = _one_line(res.stderr)
    assert "component" not in line and "fatal" not in line, line
    assert "no result was written" in line
    assert not list(out.glob("*.csv"))


def test_ctrl_c_in_a_task_of_an_in_process_sweep_records_no_failure_and_a_rerun_completes(cox_fmus, tmp_path):
    spec = _write(tmp_path / "spec", cox_fmus, n=3)
    out = tmp_path / "out"
    cmd = _lpvest("sweep", str(spec), "--out", str(out), "--workers", "0", "--no-progress", "--no-plot")
    res = interrupt_at(cmd, "fmu-step", tmp_path)
    assert res.returncode == 130, res.stderr
    line = _one_line(res.stderr)
    assert "interrupted: 0 of 3 tasks finished" in line and "run the same sweep again to resume" in line
    header = json.loads((out / "sweep.json").read_text())
    assert header["complete"] is False and header["failed"] == 0 and header["finished"] == 0
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, cwd=ROOT)
    assert rerun.returncode == 0, rerun.stderr
    assert pq.read_table(out / "summary.parquet")["status"].to_pylist() == ["ok"] * 3


def test_a_sweep_interrupted_while_finishing_is_not_complete_and_a_rerun_draws_the_figures(cox_fmus, tmp_path):
    spec = _write(tmp_path / "spec", cox_fmus, n=2)
    out = tmp_path / "out"
    cmd = _lpvest("sweep", str(spec), "--out", str(out), "--workers", "0", "--no-progress")
    res = interrupt_at(cmd, "sweep-finish", tmp_path, signum=signal.SIGTERM)
    assert res.returncode == 143, res.stderr
    line = _one_line(res.stderr)
    assert "interrupted while finishing: all 2 tasks are written" in line
    assert "run the same sweep again to write the summary and draw the figures" in line
    assert json.loads((out / "sweep.json").read_text())["complete"] is False
    assert not (out / "figures").exists() or not list((out / "figures").iterdir())
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, cwd=ROOT)
    assert rerun.returncode == 0, rerun.stderr
    assert "nothing to run: every task finished earlier" in rerun.stdout
    assert json.loads((out / "sweep.json").read_text())["complete"] is True
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["loglik.png", "peak.png", "rms.png",
                                                                   "trace_P.png"]


# ---------------------------------------------------------------------------
# reproduce
# ---------------------------------------------------------------------------
def _reproduce(experiment_fmus, out, *names):
    return _lpvest("reproduce", *names, "--quick", "--workers", "0", "--out", str(out), "--fmus",
                   str(experiment_fmus.directory))


def test_reproduce_interrupted_after_an_experiment_keeps_its_results_and_says_a_rerun_keeps_them(
        experiment_fmus, tmp_path):
    out = tmp_path / "out"
    res = interrupt_at(_reproduce(experiment_fmus, out, "all"), "experiment-written", tmp_path)
    assert res.returncode == 130, res.stderr
    assert _one_line(res.stderr) == (
        f"lpvest: interrupted (SIGINT): kept the results of 1 of 8 experiment(s) (cox-toth-example1: "
        f"{out}/NAME/results.json); report.md was not written; the FMU cache {experiment_fmus.directory} keeps "
        "every FMU built so far; run the same command again: it reuses those FMUs and the finished experiments "
        "and runs the others")
    assert json.loads((out / "cox-toth-example1" / "results.json").read_text())["fmu_cosimulation"]["ok"] is True
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*results.json*")) == [
        "cox-toth-example1/results.json"]  # no other experiment's, no half-written one
    assert not (out / "report.md").exists()


#: Three of the quickest experiments: the Dask workers, the interruption and the resume are the
#: same for any selection (``reproduce all --quick`` is tests/test_reproduce.py's), at a fifth of the CPU
_ON_WORKERS = ("cox-toth-example1", "cox-toth-truncation", "peixoto-fig1")


def _on_workers(experiment_fmus, out):
    """``reproduce`` of three experiments, ``--quick``, with the default ``--workers`` (Dask worker
    processes)."""
    return _lpvest("reproduce", *_ON_WORKERS, "--quick", "--out", str(out), "--fmus", str(experiment_fmus.directory))


def _interrupted_on_workers(experiment_fmus, out, tmp_path, signum, group):
    """:func:`_on_workers` stopped once an experiment is written; returns the kept experiment's name."""
    res = interrupt_at(_on_workers(experiment_fmus, out), "experiment-written", tmp_path, signum=signum, group=group)
    assert res.returncode == 128 + signum, res.stderr
    name = signal.Signals(signum).name
    line = _one_line(res.stderr)  # and no traceback: neither from this process nor from its workers
    m = re.fullmatch(
        rf"lpvest: interrupted \({name}\): kept the results of 1 of 3 experiment\(s\) \(([a-z0-9-]+): "
        rf"{re.escape(str(out))}/NAME/results\.json\); the FMU cache "  # no report: not 'all'
        rf"{re.escape(str(experiment_fmus.directory))} keeps every FMU built so far; run the same command again: it "
        "reuses those FMUs and the finished experiments and runs the others", line)
    assert m, line
    kept = m.group(1)  # whichever task finished first
    assert " task(s) on Dask LocalCluster, " in res.stdout, res.stdout  # it ran side by side
    data = json.loads((out / kept / "results.json").read_text())
    assert "fmu_cosimulation" not in data or data["fmu_cosimulation"]["ok"] is True
    # the kept experiment's results and resume record, whole; no other experiment's, no half-written
    # file of them (an experiment running on a worker may have written its figures or designs: a
    # folder without results.json is not a result, and a rerun writes it anew)
    assert sorted(p.relative_to(out).as_posix() for p in out.glob("*/*") if p.is_file()
                  and not p.parent.name.startswith("fmu-cache")
                  and (p.name == "results.json" or p.name.startswith(".results.json") or p.name.startswith(
                      ".resume.pickle"))) == [f"{kept}/.resume.pickle", f"{kept}/results.json"]
    assert not (out / "report.md").exists()
    return kept


@pytest.fixture(scope="module")
def interrupted_on_workers(experiment_fmus, tmp_path_factory):
    """:func:`_interrupted_on_workers` for a signal and its target, run once for the module (its
    checks included): ``(out, kept)``. The rerun test continues the Ctrl-C run's folder instead of
    interrupting a third run the same way (10 CPU-s); nothing checks the folder after that (a
    copy would not do: a resume record holds the paths of the run it kept)."""
    runs = {}

    def interrupted(signum, group):
        if (signum, group) not in runs:
            folder = tmp_path_factory.mktemp("on-workers")
            runs[signum, group] = (folder / "out", _interrupted_on_workers(experiment_fmus, folder / "out", folder,
                                                                           signum, group))
        return runs[signum, group]

    return interrupted


@pytest.mark.parametrize(("signum", "group"), [(signal.SIGINT, True), (signal.SIGTERM, False)],
                         ids=["ctrl-c-to-the-process-group", "sigterm-to-the-command"])
def test_reproduce_on_dask_workers_interrupted_keeps_the_finished_experiment(interrupted_on_workers, signum, group):
    """Ctrl-C in a terminal reaches the command and its Dask workers (its process group); a
    ``kill`` reaches the command only."""
    interrupted_on_workers(signum, group)


def test_reproduce_on_dask_workers_rerun_after_an_interruption_keeps_the_finished_experiment(
        interrupted_on_workers, experiment_fmus):
    out, kept = interrupted_on_workers(signal.SIGINT, True)
    cmd = _on_workers(experiment_fmus, out)
    results = out / kept / "results.json"
    before = results.read_bytes(), results.stat().st_mtime_ns
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, cwd=ROOT)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{kept}: finished earlier, kept ({results})" in rerun.stdout.splitlines()
    assert "2 experiment(s) as " in rerun.stdout  # the others only
    assert (results.read_bytes(), results.stat().st_mtime_ns) == before  # not run, not rewritten
    assert all((out / name / "results.json").is_file() for name in _ON_WORKERS)
    assert not (out / "report.md").exists()  # reproduce all's (tests/test_reproduce.py)


def test_reproduce_stopped_by_sigterm_inside_an_fmu_keeps_no_results(experiment_fmus, tmp_path):
    out = tmp_path / "out"
    res = interrupt_at(_reproduce(experiment_fmus, out, "cox-toth-example1"), "fmu-step", tmp_path,
                       signum=signal.SIGTERM)
    assert res.returncode == 143, res.stderr
    line = _one_line(res.stderr)
    assert line.startswith("lpvest: interrupted (SIGTERM): none of the 1 experiment(s) finished; the FMU cache "), \
        line
    assert "component" not in line and "fatal" not in line, line
    assert not list(out.rglob("*results.json*"))


# ---------------------------------------------------------------------------
# regress
# ---------------------------------------------------------------------------
_REFS = ("cox-toth-example1", "cox-toth-truncation")  # the two quickest references


def _regress(experiment_fmus, *args):
    return _lpvest("regress", *_REFS, "--fmus", str(experiment_fmus.directory), "--quiet", *args)


def _reference_copy(tmp_path):
    """A reference folder holding the stored files of _REFS, and their bytes."""
    folder = tmp_path / "reference"
    folder.mkdir()
    for name in _REFS:
        shutil.copyfile(ROOT / "tests" / "data" / "reference" / f"{name}.csv", folder / f"{name}.csv")
    return folder, {p.name: p.read_bytes() for p in folder.iterdir()}


def test_regress_update_interrupted_between_references_keeps_each_file_whole(experiment_fmus, tmp_path):
    folder, before = _reference_copy(tmp_path)
    (folder / "cox-toth-example1.csv").write_text("# a stale reference\n")  # to be rewritten
    res = interrupt_at(_regress(experiment_fmus, "--update", "--dir", str(folder)), "reference-written", tmp_path,
                       signum=signal.SIGTERM)
    assert res.returncode == 143, res.stderr
    # the folder as every message shows a path, shortened to about 80 characters (pytest's
    # temporary folders differ in length from machine to machine)
    assert _one_line(res.stderr) == (
        f"lpvest: interrupted (SIGTERM): rewrote 1 of 2 reference file(s) in {shorten(str(folder), 80)} "
        "(cox-toth-example1); every "
        "file is whole, the others keep their earlier contents; run the same command again to rewrite them all")
    assert sorted(p.name for p in folder.iterdir()) == ["cox-toth-example1.csv", "cox-toth-truncation.csv"]
    assert (folder / "cox-toth-truncation.csv").read_bytes() == before["cox-toth-truncation.csv"]
    ref = next(r for r in REFERENCES if r.name == "cox-toth-example1")
    columns, data, _ = read_reference(folder / ref.filename)  # the new file, whole: every row of the run
    assert columns == ["time", *ref.columns]
    assert data.shape == read_reference(ROOT / "tests" / "data" / "reference" / ref.filename)[1].shape


@pytest.mark.parametrize(("signum", "status", "name"), [(signal.SIGINT, 130, "SIGINT"),
                                                         (signal.SIGTERM, 143, "SIGTERM")])
def test_regress_update_interrupted_while_writing_a_reference_leaves_the_earlier_file(
        experiment_fmus, tmp_path, signum, status, name):
    folder, before = _reference_copy(tmp_path)
    res = interrupt_at(_regress(experiment_fmus, "--update", "--dir", str(folder)), "reference-part", tmp_path,
                       signum=signum)
    assert res.returncode == status, res.stderr
    assert _one_line(res.stderr).startswith(f"lpvest: interrupted ({name}): rewrote 0 of 2 reference file(s) in ")
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # no half file, no .part left


def test_the_reference_module_interrupted_says_in_one_line_what_it_kept(experiment_fmus, tmp_path):
    """``python -m lpvest.experiments._references`` (regress without the command line):
    the same handling, under its own name: exit 143, every file whole, one line."""
    folder, before = _reference_copy(tmp_path)
    cmd = [sys.executable, "-m", "lpvest.experiments._references", *_REFS, "--update", "--dir", str(folder),
           "--fmus", str(experiment_fmus.directory), "--quiet"]
    res = interrupt_at(cmd, "reference-written", tmp_path, signum=signal.SIGTERM)
    assert res.returncode == 143, res.stderr
    assert "Traceback" not in res.stderr, res.stderr
    assert res.stderr.strip().splitlines() == [
        f"python -m lpvest.experiments._references: interrupted (SIGTERM): rewrote 1 of 2 reference file(s) in "
        f"{shorten(str(folder), 80)} (cox-toth-example1); every file is whole, the others keep their earlier "
        "contents; run the same command again to rewrite them all"], res.stderr
    assert (folder / "cox-toth-truncation.csv").read_bytes() == before["cox-toth-truncation.csv"]


def test_the_reference_module_refuses_a_missing_folder_in_one_line(tmp_path):
    res = subprocess.run([sys.executable, "-m", "lpvest.experiments._references", "--dir", str(tmp_path / "nosuch")],
                         capture_output=True, text=True, timeout=TIMEOUT, cwd=ROOT)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip().splitlines() == [
        f"python -m lpvest.experiments._references: error: no reference folder {shorten(str(tmp_path / 'nosuch'), 80)}"
        " (write one with lpvest regress --update --dir FOLDER)"], res.stderr


def test_regress_interrupted_inside_an_fmu_writes_nothing(experiment_fmus, tmp_path):
    folder, before = _reference_copy(tmp_path)
    res = interrupt_at(_regress(experiment_fmus, "--dir", str(folder)), "fmu-step", tmp_path)
    assert res.returncode == 130, res.stderr
    line = _one_line(res.stderr)
    assert line == ("lpvest: interrupted (SIGINT): compared 0 of 2 reference(s); nothing was written; run the same "
                    "command again to compare them all"), line
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
