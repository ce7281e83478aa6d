"""`lpvest sweep` / lpvest.sweep: the same co-simulation over seeds and
parameters on Dask.

The reference of every engine run is a plain serial loop written here: one
:class:`~lpvest.cosim.CoSimulation` reset per seed (reset itself checked
against fresh instances), seeds from ``numpy.random.SeedSequence`` and the
metrics with numpy. The Monte Carlo parts of the experiments are checked
against the loop bodies of the serial experiment code, inlined here.

Dask clusters are module fixtures (started once, closed at the end), every
engine has an idle timeout, and the co-simulations are short (20 steps).
"""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from lpvest.cli import main
from lpvest.core._errors import ModelFileError
from lpvest.cosim import Component, CoSimulation, CoSimulationError, simulate
from lpvest.parallel._tasks import Task
from lpvest.sweep import (
    Engine,
    SweepError,
    SweepInterrupted,
    load_sweep,
    map_tasks,
    run_sweep,
    sweep_spec,
    task_seeds,
)
from lpvest.sweep._metrics import Metric, compute
from tests.interrupting import interrupt_at

ROOT = Path(__file__).resolve().parent.parent
ROOT_SEED = 2026
N_SEEDS = 200
STEPS = 20
TIMEOUT = 180.0  # seconds without a finished task before an engine gives up (never reached when healthy)

COSIM = """
title = "plant + scheduler + Kalman filter (test)"
step_size = 1.0
steps = {steps}
connections = ["sched.p -> plant.p", "sched.p -> kalman.p", "plant.y -> kalman.y"]

[components.sched]
fmu = "{sched}"
parameters = {{ kind = "random", rate = [0.2] }}

[components.plant]
fmu = "{plant}"
parameters = {{ noise = true }}

[components.kalman]
fmu = "{kalman}"
"""

SPEC = """
title = "Kalman filter over {n} seeds (test)"
cosim = "kalman.toml"
keep = ["plant.x", "kalman.xhat"]

[seeds]
count = {n}
root = {root}
parameters = ["plant.seed", "sched.seed"]

[metrics]
rms = {{ kind = "rms_error", estimate = "kalman.xhat", truth = "plant.x" }}
peak = {{ kind = "max_abs_error", estimate = "kalman.xhat", truth = "plant.x", start = 5 }}
trace_P = {{ kind = "final_trace", of = "kalman.P" }}
loglik = {{ kind = "final", of = "kalman.loglik" }}
"""


def _write(folder: Path, fmus, *, n: int = N_SEEDS, extra: str = "", name: str = "sweep.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "kalman.toml").write_text(COSIM.format(
        steps=STEPS, sched=fmus["CoxTothTruncationScheduler"], plant=fmus["CoxTothTruncationPlant"],
        kalman=fmus["CoxTothTruncationKalman"]))
    path = folder / name
    path.write_text(SPEC.format(n=n, root=ROOT_SEED) + extra)
    return path


@pytest.fixture(scope="module")
def spec_file(fmus, tmp_path_factory) -> Path:
    return _write(tmp_path_factory.mktemp("sweep-spec"), fmus)


@pytest.fixture(scope="module")
def small_spec_file(fmus, tmp_path_factory) -> Path:
    """The first 60 seeds of the same sweep (seed key k has the same noise in both)."""
    return _write(tmp_path_factory.mktemp("sweep-spec-60"), fmus, n=60)


def _same_rows(small, reference) -> None:
    """The summary of the 60-seed sweep is the first 60 rows of the 200-seed one, value for value."""
    assert small.summary.equals(reference.summary.slice(0, small.summary.num_rows))


@pytest.fixture(scope="module")
def engine2():
    with Engine(workers=2, idle_timeout=TIMEOUT) as engine:
        yield engine


@pytest.fixture(scope="module")
def one_worker(spec_file, tmp_path_factory):
    """The 200-seed sweep on a LocalCluster of one worker process: the reference run."""
    out = tmp_path_factory.mktemp("one-worker")
    with Engine(workers=1, idle_timeout=TIMEOUT) as engine:
        assert engine.n_workers == 1
        return run_sweep(spec_file, out, engine=engine, progress=False)


def _components(fmus) -> list[Component]:
    return [Component("sched", fmus["CoxTothTruncationScheduler"], {"kind": "random", "rate": [0.2]}),
            Component("plant", fmus["CoxTothTruncationPlant"], {"noise": True}),
            Component("kalman", fmus["CoxTothTruncationKalman"])]


CONNECTIONS = ["sched.p -> plant.p", "sched.p -> kalman.p", "plant.y -> kalman.y"]
RECORD = ["plant.x", "kalman.xhat", "kalman.P", "kalman.loglik"]


def _seeds(k: int) -> tuple[int, int]:
    """Seed key k: the k-th child of SeedSequence(root), two 32-bit words, >> 1 (FMI Integers are signed)."""
    child = np.random.SeedSequence(ROOT_SEED).spawn(N_SEEDS)[k]
    plant, sched = (int(v) >> 1 for v in child.generate_state(2, dtype=np.uint32))
    return plant, sched


def _serial_loop(fmus) -> dict[str, np.ndarray]:
    """The plain serial loop: one co-simulation per seed, metrics with numpy."""
    out: dict[str, list] = {k: [] for k in ("rms", "peak", "trace_P", "loglik", "x", "xhat")}
    with CoSimulation(_components(fmus), CONNECTIONS, step_size=1.0, record=RECORD) as sim:
        for k in range(N_SEEDS):
            plant_seed, sched_seed = _seeds(k)
            sim.reset({"plant": {"seed": plant_seed}, "sched": {"seed": sched_seed}})
            r = sim.run(STEPS)
            x = np.column_stack([r["plant.x[1]"], r["plant.x[2]"]])
            xhat = np.column_stack([r["kalman.xhat[1]"], r["kalman.xhat[2]"]])
            out["rms"].append(np.sqrt(np.mean((xhat - x) ** 2)))
            out["peak"].append(np.max(np.abs(xhat - x)[5:]))
            out["trace_P"].append(r["kalman.P[1,1]"][-1] + r["kalman.P[2,2]"][-1])
            out["loglik"].append(r["kalman.loglik"][-1])
            out["x"].append(x)
            out["xhat"].append(xhat)
    return {k: np.array(v) for k, v in out.items()}


# ---------------------------------------------------------------------------
# the engine against the serial loop
# ---------------------------------------------------------------------------
def test_reset_runs_the_same_instances_as_fresh_ones(fmus):
    with CoSimulation(_components(fmus), CONNECTIONS, step_size=1.0, record=RECORD) as sim:
        for k in (0, 1, 7):
            plant_seed, sched_seed = _seeds(k)
            sim.reset({"plant": {"seed": plant_seed}, "sched": {"seed": sched_seed}})
            again = sim.run(STEPS)
            comps = _components(fmus)
            comps[0] = Component("sched", comps[0].fmu, {**comps[0].parameters, "seed": sched_seed})
            comps[1] = Component("plant", comps[1].fmu, {**comps[1].parameters, "seed": plant_seed})
            fresh = simulate(comps, CONNECTIONS, step_size=1.0, n_steps=STEPS, record=RECORD)
            for name in fresh.dtype.names:
                np.testing.assert_array_equal(again[name], fresh[name], err_msg=name)
        with pytest.raises(CoSimulationError, match="call reset"):
            sim.run(STEPS)
        with pytest.raises(CoSimulationError, match="no component 'filter'"):
            sim.reset({"filter": {"tau": 1}})
        with pytest.raises(CoSimulationError, match="no variable 'sed'"):
            sim.reset({"plant": {"sed": 1}})


def test_task_seeds_are_the_seed_sequence_children():
    for k in (0, 3, 199):
        assert tuple(task_seeds(ROOT_SEED, k, ["plant.seed", "sched.seed"]).values()) == _seeds(k)
    values = [v for k in range(1000) for v in task_seeds(1, k, ["a", "b", "c"]).values()]
    assert min(values) >= 0 and max(values) < 2**31 and len(set(values)) == len(values)


@pytest.mark.slow
def test_two_workers_one_worker_and_a_serial_loop_give_the_same_summary(spec_file, engine2, one_worker, fmus,
                                                                        tmp_path):
    two = run_sweep(spec_file, tmp_path / "two", engine=engine2, progress=False)
    assert two.complete and one_worker.complete and two.ran == N_SEEDS
    # both workers ran tasks (else the comparison would not test distribution)
    workers = set(pq.read_table(tmp_path / "two" / "timing.parquet")["worker"].to_pylist())
    assert len(workers) == 2
    # bit for bit: the summary files are identical
    assert (tmp_path / "two" / "summary.parquet").read_bytes() == (one_worker.out / "summary.parquet").read_bytes()
    summary = two.summary
    assert summary.column_names == ["task", "seed", "plant.seed", "sched.seed", "rms", "peak", "trace_P", "loglik",
                                    "status", "error"]
    assert summary["task"].to_pylist() == list(range(N_SEEDS))
    assert summary["seed"].to_pylist() == list(range(N_SEEDS))
    assert set(summary["status"].to_pylist()) == {"ok"}
    assert [(p, s) for p, s in zip(summary["plant.seed"].to_pylist(), summary["sched.seed"].to_pylist(),
                                   strict=True)] == [_seeds(k) for k in range(N_SEEDS)]
    serial = _serial_loop(fmus)
    for m in ("rms", "peak", "trace_P", "loglik"):
        np.testing.assert_array_equal(summary[m].to_numpy(), serial[m], err_msg=m)
    # the kept trajectories: (task, step, element)
    traj = two.trajectories()
    np.testing.assert_array_equal(traj["plant.x"][:], serial["x"])
    np.testing.assert_array_equal(traj["kalman.xhat"][:], serial["xhat"])
    np.testing.assert_array_equal(traj["time"][:], np.arange(STEPS + 1.0))
    assert traj["plant.x"].attrs["elements"] == ["plant.x[1]", "plant.x[2]"]
    # a figure per metric: the histogram over the seeds (no parameter axis)
    assert [f.name for f in two.figures] == ["rms.png", "peak.png", "trace_P.png", "loglik.png"]
    assert all(f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for f in two.figures)


@pytest.mark.slow
def test_killing_a_worker_mid_sweep_still_records_every_task_exactly_once(small_spec_file, one_worker, tmp_path):
    """... and what the killed worker unpacked (the sweep's FMUs) is in its Dask
    work folder, which Dask purges when a worker or cluster next starts there."""
    import tempfile

    import dask

    killed: list[int] = []
    seen: list[int] = []
    n = 60
    scratch = tmp_path / "scratch"  # the workers' temporary folder (Dask's temporary-directory)
    scratch.mkdir()
    with dask.config.set({"temporary-directory": str(scratch)}), Engine(workers=2, idle_timeout=TIMEOUT) as engine:
        pids = engine.client.run(os.getpid)  # worker address -> process id
        victim = sorted(pids.values())[0]
        folders = engine.client.run(tempfile.gettempdir)
        assert sorted(folders.values()) == sorted(str(p) for p in (scratch / "dask-scratch-space").glob("worker-*")
                                                  if p.is_dir())

        def on_outcome(outcome):
            seen.append(outcome.index)
            if len(seen) == 10 and not killed:  # mid-sweep: 50 tasks to go
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)

        res = run_sweep(small_spec_file, tmp_path / "killed", engine=engine, progress=False, on_outcome=on_outcome,
                        flush_every=8)
    assert killed and sorted(seen) == list(range(n))  # every outcome handed over once
    with pytest.raises(ProcessLookupError):
        os.kill(victim, 0)  # the worker process is gone (its nanny started a new one)
    parts = pa.concat_tables([pq.read_table(p) for p in sorted((tmp_path / "killed" / "parts").glob("*.parquet"))])
    assert sorted(parts["task"].to_pylist()) == list(range(n))  # each task once on disk
    assert res.complete and not res.failures
    _same_rows(res, one_worker)
    assert [p.name for p in scratch.iterdir()] == ["dask-scratch-space"]
    # the killed worker's folder: purged when its nanny started the next worker, if no other
    # worker held Dask's lock then, else when the next cluster starts there (its scheduler
    # first, alone)
    victim_folder = Path(next(f for a, f in folders.items() if pids[a] == victim))
    with dask.config.set({"temporary-directory": str(scratch)}), Engine(workers=1, idle_timeout=TIMEOUT) as engine:
        engine.client.run(os.getpid)
        assert not victim_folder.exists()


@pytest.mark.slow
def test_a_sweep_on_an_existing_cluster_is_the_local_one_and_unpacks_in_the_workers_folders(
        small_spec_file, one_worker, tmp_path):
    """``scheduler=ADDRESS`` (README, "On a cluster"): a cluster lpvest did not start, so
    without lpvest's preload, its workers' temporary folder the system's. The rows are the
    local cluster's, bit for bit; the FMUs are shipped to and unpacked in the worker's Dask
    work folder, which Dask purges even after the worker was killed."""
    import tempfile

    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.CRITICAL) as cluster:
        res = run_sweep(small_spec_file, tmp_path / "out", scheduler=cluster.scheduler_address, progress=False)
        with Client(cluster) as client:
            (folder, temporary, names), = client.run(
                lambda dask_worker: (dask_worker.local_directory, tempfile.gettempdir(),
                                     sorted(p.name for p in Path(dask_worker.local_directory).iterdir()))).values()
    assert res.complete and not res.failures
    _same_rows(res, one_worker)
    assert Path(temporary) != Path(folder)  # no preload of lpvest's made it the temporary folder
    # the shipped FMUs, and the folder of the worker's cached simulation (it runs the next task)
    assert "lpvest-fmus" in names and sum(n.startswith("lpvest-cosim-") for n in names) == 1, names


@pytest.mark.slow
def test_an_interrupted_sweep_resumes_from_disk_to_the_same_result(small_spec_file, engine2, one_worker, tmp_path):
    out = tmp_path / "interrupted"
    n = 60

    def stop_after_20(outcome, count=[0]):  # noqa: B006 - a counter
        count[0] += 1
        if count[0] == 20:
            raise KeyboardInterrupt

    with pytest.raises(SweepInterrupted, match="run the same sweep again to resume") as info:
        run_sweep(small_spec_file, out, engine=engine2, progress=False, on_outcome=stop_after_20, flush_every=8)
    assert info.value.finished == 20 and info.value.total == n
    import json

    header = json.loads((out / "sweep.json").read_text())
    assert header["complete"] is False and header["finished"] == 20
    assert pq.read_table(out / "summary.parquet").num_rows == 20
    res = run_sweep(small_spec_file, out, engine=engine2, progress=False)
    assert (res.resumed, res.ran, res.complete) == (20, n - 20, True)
    _same_rows(res, one_worker)
    np.testing.assert_array_equal(res.trajectories()["kalman.xhat"][:], one_worker.trajectories()["kalman.xhat"][:n])
    first = (out / "summary.parquet").read_bytes()
    again = run_sweep(small_spec_file, out, engine=engine2, progress=False)  # nothing left to run
    assert (again.resumed, again.ran) == (n, 0)
    assert (out / "summary.parquet").read_bytes() == first


def test_a_task_with_a_bad_parameter_is_recorded_with_its_message_and_the_others_complete(fmus, engine2, tmp_path):
    spec = _write(tmp_path, fmus, n=3, extra='\n[parameters]\n"kalman.P0" = [[1.0, 0.0, 0.0, 1.0], '
                                                 '[-1.0, 0.0, 0.0, 1.0], [2.0, 0.0, 0.0, 2.0]]\n')
    res = run_sweep(spec, tmp_path / "out", engine=engine2, progress=False)
    s = res.summary.to_pydict()
    assert s["task"] == list(range(9))
    assert s["kalman.P0"][3] == [-1.0, 0.0, 0.0, 1.0]
    assert s["status"] == ["ok"] * 3 + ["error"] * 3 + ["ok"] * 3
    for i in (3, 4, 5):
        assert s["error"][i].startswith("CoSimulationError: component kalman:")
        assert "P0 is not positive semidefinite: smallest eigenvalue -1" in s["error"][i]
        assert s["rms"][i] is None
        assert np.isnan(res.trajectories()["kalman.xhat"][i]).all()
    assert all(s["error"][i] is None and np.isfinite(s["rms"][i]) for i in (0, 1, 2, 6, 7, 8))
    assert [t for t, _ in res.failures] == [3, 4, 5]
    assert "task 3 failed: CoSimulationError" in res.report()
    # the figure over the swept axis leaves the failed point out and says so
    assert (tmp_path / "out" / "figures" / "rms.png").is_file()
    # a rerun retries nothing unless asked
    assert run_sweep(spec, tmp_path / "out", workers=0, progress=False).ran == 0
    assert run_sweep(spec, tmp_path / "out", workers=0, progress=False, retry_failed=True).ran == 3


# ---------------------------------------------------------------------------
# the command line
# ---------------------------------------------------------------------------
def test_cli_runs_a_grid_in_process_and_plots_each_metric_over_the_axis(fmus, tmp_path, capsys):
    spec = _write(tmp_path, fmus, n=2, extra='\n[parameters]\n"sched.rate" = [[0.1], [0.4]]\n'
                                              '\n[[zip]]\n"kalman.x0" = [[0.0, 0.0], [1.0, 1.0]]\n'
                                              '"plant.x0" = [[0.0, 0.0], [1.0, 1.0]]\n')
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out), "--workers", "0", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "8 tasks (4 point(s) x 2 seed(s))" in text
    assert "rms      sched.rate = [0.1], kalman.x0 = [0, 0], plant.x0 = [0, 0]      2" in text
    table = pq.read_table(out / "summary.parquet")
    assert table["sched.rate"].to_pylist() == [[0.1]] * 4 + [[0.4]] * 4
    assert table["kalman.x0"].to_pylist()[:4] == [[0.0, 0.0], [0.0, 0.0], [1.0, 1.0], [1.0, 1.0]]
    assert table["seed"].to_pylist() == [0, 1] * 4
    # common random numbers: seed key k gets the same seeds at every point
    assert table["plant.seed"].to_pylist()[:2] == table["plant.seed"].to_pylist()[6:]
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["loglik.png", "peak.png", "rms.png",
                                                                   "trace_P.png"]


@pytest.mark.slow
def test_ctrl_c_on_the_command_line_cancels_cleanly_and_a_rerun_resumes(spec_file, one_worker, tmp_path):
    out = tmp_path / "cli"
    cmd = [sys.executable, "-m", "lpvest.cli", "sweep", str(spec_file), "--out", str(out), "--workers", "2",
           "--no-progress", "--no-plot"]
    # its own process group, as a shell job: Ctrl-C reaches the client and its workers. Sent once a
    # finished task is on disk and others are pending (the hook holds the client there): watching for
    # the first part file instead raced with the end of the sweep (the first part file can be the
    # last one, written when every task has finished; the signal then landed after the work was done)
    res = interrupt_at(cmd, "sweep-outcome", tmp_path, group=True)
    proc, stderr = res, res.stderr
    assert proc.returncode == 130, stderr
    assert "lpvest: interrupted:" in stderr and "run the same sweep again to resume" in stderr
    assert "Traceback" not in stderr  # the workers ignore SIGINT; the client closes them
    done = pq.read_table(out / "summary.parquet").num_rows
    assert 0 < done < N_SEEDS
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{done} finished earlier (resumed)" in rerun.stdout
    assert (out / "summary.parquet").read_bytes() == (one_worker.out / "summary.parquet").read_bytes()


# ---------------------------------------------------------------------------
# mistakes
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("extra, field, message", [
    ("", "seeds.parameters[1]", "plant (CoxTothTruncationPlant.fmu) has no variable 'sed'"),
    ("", "seeds.parameters[1]", "plant.x0 is not an Integer parameter"),
    ('[parameters]\n"kalman.tau" = [1, 2]\n', "parameters.kalman.tau", "has no variable 'tau'"),
    ('[parameters]\n"kalman.xhat" = [1.0]\n', "parameters.kalman.xhat", "is an output; it cannot be set"),
    ('[parameters]\n"sched.rate" = [0.1, "fast"]\n', "parameters.sched.rate", "mixes number and str values"),
    ('[parameters]\n"plant.x0" = [[1.0], [0.0, 0.0]]\n', "parameters.plant.x0[1]", "x0 has 2 element(s); 1 value"),
    ('[parameters]\n"sched.seed" = [1, 2]\n', "seeds.parameters", "sched.seed is also a swept parameter"),
    ('[[zip]]\n"plant.x0" = [[0.0, 0.0]]\n"kalman.x0" = [[0.0, 0.0], [1.0, 1.0]]\n', "zip[1].kalman.x0",
     "has 2 values; plant.x0 has 1"),
    ("[metrics]\nbad = { kind = \"rms_error\", estimate = \"kalman.xhat\", truth = \"sched.p\" }\n", "metrics.bad",
     "estimate 'kalman.xhat' has 2 element(s), truth 'sched.p' 1"),
    ("[metrics]\nbad = { kind = \"median\", of = \"kalman.xhat\" }\n", "metrics.bad.kind",
     "unknown metric kind 'median', did you mean 'mean'? (expected one of: rms_error, "),
    ("[metrics]\nbad = { kind = \"final_trace\", of = \"kalman.xhat\" }\n", "metrics.bad",
     "not a square matrix variable"),
    ("[metrics]\nbad = { kind = \"rms\", of = \"kalman.xhat\", start = -1 }\n", "metrics.bad.start",
     "expected a non-negative integer, found a number (-1)"),
])
def test_a_mistake_in_a_sweep_file_is_one_line_naming_the_field(fmus, tmp_path, extra, field, message):
    spec = _write(tmp_path, fmus, n=2)
    text = spec.read_text()
    if "sed'" in message:
        text = text.replace('"plant.seed"', '"plant.sed"')
    elif "x0 is not an Integer" in message:
        text = text.replace('"plant.seed"', '"plant.x0"')
    if extra.startswith("[metrics]"):
        text = text.replace("[metrics]\n", extra)
    else:
        text += extra
    spec.write_text(text)
    with pytest.raises(ModelFileError) as info:
        run_sweep(spec, tmp_path / "out", workers=0, progress=False)
    assert str(info.value).startswith(f"{spec}: {field}: ")
    assert message in str(info.value) and "\n" not in str(info.value)
    assert not (tmp_path / "out").exists()  # nothing runs, nothing is written


@pytest.mark.parametrize("data, field, message", [
    ({"seeds": 3}, "cosim", "give either cosim"),
    ({"cosim": "kalman.toml", "experiment": "sridhar-noisy"}, "cosim", "exactly one"),
    ({"experiment": "nope"}, "experiment", "no experiment 'nope' to sweep"),
    ({"experiment": "peixoto-example2", "parameters": {"gamma": [1.0]}}, "parameters.gamma", "has no axis"),
    ({"experiment": "sridhar-noisy", "seeds": {"count": 2, "parameters": ["a.b"]}}, "seeds.parameters",
     "its own seeds"),
    ({"experiment": "cox-toth-truncation", "options": {"runs": "many"}}, "options.runs", "expected a number"),
    ({"experiment": "cox-toth-truncation", "options": {"sims": 3}}, "options.sims", "unknown key (expected one of: "),
    ({"experiment": "cox-toth-truncation", "metrics": ["gamma"]}, "metrics[1]", "has no metric 'gamma'"),
    ({"experiment": "cox-toth-truncation", "steps": 3}, "steps", "only a co-simulation"),
    ({"cosim": "kalman.toml", "seeds": {"count": 0, "parameters": ["plant.seed"]}}, "seeds.count",
     "expected a positive integer"),
    ({"cosim": "kalman.toml", "seeds": {"keys": [1, 1], "parameters": ["plant.seed"]}}, "seeds.keys",
     "listed twice"),
    ({"cosim": "kalman.toml", "keep": ["plant.x"], "steps": 0}, "steps", "expected a positive integer"),
    ({"cosim": "kalman.toml"}, "metrics", "name at least one metric or a kept signal"),
    ({"cosim": "kalman.toml", "keep": ["plant.x"], "options": {"a": 1}}, "options", "only an experiment"),
    ({"cosim": "kalman.toml", "keep": ["plant.x"], "sweeps": 3}, "sweeps", "unknown key"),
])
def test_sweep_spec_errors_name_the_field(fmus, tmp_path, data, field, message):
    _write(tmp_path, fmus)
    with pytest.raises(ModelFileError, match=rf"^s\.toml: {re.escape(field)}: .*{re.escape(message)}"):
        sweep_spec(data, origin="s.toml", base=tmp_path)


def test_a_folder_holding_another_sweep_is_refused(fmus, tmp_path):
    spec = _write(tmp_path, fmus, n=2)
    run_sweep(spec, tmp_path / "out", workers=0, progress=False, plot=False)
    other = _write(tmp_path, fmus, n=3, name="other.toml")
    with pytest.raises(SweepError, match=r"holds the results of a different sweep \(.*sweep.toml, digest .*overwrite"):
        run_sweep(other, tmp_path / "out", workers=0, progress=False)
    res = run_sweep(other, tmp_path / "out", workers=0, progress=False, plot=False, overwrite=True)
    assert res.ran == 3 and res.resumed == 0


# ---------------------------------------------------------------------------
# metrics
# ---------------------------------------------------------------------------
def test_metrics_against_numpy(rng):
    n = 30
    cols = {"time": np.arange(n + 1.0)}
    x, xh, w = rng.standard_normal((n + 1, 2)), rng.standard_normal((n + 1, 2)), rng.standard_normal((n + 1, 1))
    P = rng.standard_normal((n + 1, 2, 2))
    for i in range(2):
        cols[f"p.x[{i + 1}]"], cols[f"f.xhat[{i + 1}]"] = x[:, i], xh[:, i]
        for j in range(2):
            cols[f"f.P[{i + 1},{j + 1}]"] = P[:, i, j]
    cols["s.w[1]"] = w[:, 0]
    data = np.zeros(n + 1, dtype=[(k, "f8") for k in cols])
    for k, v in cols.items():
        data[k] = v

    def m(kind, start=0, **v):
        return compute(Metric("m", kind, v, start), data)

    e = xh - x
    assert m("rms_error", estimate="f.xhat", truth="p.x") == np.sqrt(np.mean(e**2))
    assert m("max_abs_error", 4, estimate="f.xhat", truth="p.x") == np.max(np.abs(e[4:]))
    assert m("energy_ratio", 2, estimate="f.xhat", truth="p.x", input="s.w") == \
        np.sqrt(np.sum(e[2:] ** 2)) / np.sqrt(np.sum(w[2:] ** 2))
    assert m("peak_ratio", estimate="f.xhat", truth="p.x", input="s.w") == np.max(np.abs(e)) / np.max(np.abs(w))
    assert m("final_trace", of="f.P") == P[-1, 0, 0] + P[-1, 1, 1]
    assert m("final", of="s.w[1]") == w[-1, 0]
    assert m("mean", 3, of="p.x") == np.mean(x[3:])
    assert m("rms", of="p.x[2]") == np.sqrt(np.mean(x[:, 1] ** 2))
    assert m("max_abs", of="f.P") == np.max(np.abs(P))


def test_seed_keys_and_common_random_numbers(fmus, tmp_path):
    _write(tmp_path, fmus)
    base = {"cosim": "kalman.toml", "keep": ["plant.x"], "parameters": {"sched.rate": [[0.1], [0.2]]}}
    common = sweep_spec(base | {"seeds": {"count": 3, "root": 5, "parameters": ["plant.seed"]}}, base=tmp_path)
    keys = sweep_spec(base | {"seeds": {"keys": [2], "root": 5, "parameters": ["plant.seed"]}}, base=tmp_path)
    each = sweep_spec(base | {"seeds": {"count": 3, "root": 5, "parameters": ["plant.seed"], "common": False}},
                      base=tmp_path)
    t = common.tasks()
    assert [(x.index, x.point["sched.rate"], x.seed) for x in t] == [
        (0, (0.1,), 0), (1, (0.1,), 1), (2, (0.1,), 2), (3, (0.2,), 0), (4, (0.2,), 1), (5, (0.2,), 2)]
    assert t[1].seed_values == t[4].seed_values == task_seeds(5, 1, ["plant.seed"])
    assert keys.tasks()[1].seed_values == t[5].seed_values  # seed key 2, alone, gets the same noise
    assert [x.seed_values for x in each.tasks()] == [task_seeds(5, i, ["plant.seed"]) for i in range(6)]


# ---------------------------------------------------------------------------
# the experiments' Monte Carlo through the sweep: the numbers of the serial code
# ---------------------------------------------------------------------------
def test_cox_toth_prediction_error_through_the_engine_is_the_serial_loop(engine2, tmp_path):
    from lpvest.analysis._fading_memory import empirical_prediction_error
    from lpvest.experiments._cox_toth import prediction_error_setup, prediction_error_task

    spec = tmp_path / "ct.toml"
    spec.write_text(textwrap.dedent("""
        experiment = "cox-toth-truncation"
        options = { steps = 80, runs = 300, burn_in = 20, seed = 3 }
        parameters = { filter = ["exact", "truncated tau=1", "frozen K_inf(p_t)"] }
        keep = ["monte_carlo_trace"]
    """))
    res = run_sweep(spec, tmp_path / "out", engine=engine2, progress=False)
    setup = prediction_error_setup(steps=80, runs=300, burn_in=20, seed=3)
    for row in res.summary.to_pylist():
        # the serial experiment's loop body (lpvest.experiments._cox_toth.run_truncation before the hook)
        emp = empirical_prediction_error(setup.model, setup.p, setup.u, setup.gains[row["filter"]], runs=300, rng=4)
        assert row["monte_carlo_mean_trace"] == float(np.mean(np.trace(emp[20:], axis1=1, axis2=2)))
        assert row["mean_trace"] == setup.mean_trace[row["filter"]]
        np.testing.assert_array_equal(res.trajectories()["monte_carlo_trace"][row["task"]],
                                      np.trace(emp, axis1=1, axis2=2))
    # map_tasks, which run_truncation calls, gives the same on the engine and in this process
    points = [{"filter": f} for f in ("exact", "constant K_inf(0)")]
    a = map_tasks(prediction_error_task, setup, points, engine=engine2)
    b = map_tasks(prediction_error_task, setup, points)
    assert [r.metrics for r in a] == [r.metrics for r in b]


@pytest.mark.slow
def test_sridhar_noisy_through_the_engine_is_the_serial_experiment(engine2, experiment_fmus, tmp_path):
    from lpvest.experiments._sridhar import run_noisy

    serial = run_noisy(None, seeds=2, fmus=experiment_fmus)
    on_dask = run_noisy(None, seeds=2, fmus=experiment_fmus, engine=engine2)
    # a task runs with BLAS on one thread in this process as on a worker (lpvest.parallel._tasks.execute):
    # without that, the least-squares sums of a multithreaded BLAS round in another order and the
    # GCV fits moved by up to 3e-8 relative; with it, the same numbers bit for bit
    assert on_dask.results == serial.results
    spec = tmp_path / "sn.toml"
    spec.write_text('experiment = "sridhar-noisy"\nseeds = 2\nmetrics = ["a1", "gcv_a1"]\n')
    res = run_sweep(spec, tmp_path / "out", engine=engine2, fmus=experiment_fmus, progress=False)
    assert res.summary["a1"].to_pylist() == [r["a1"] for r in serial.results["per_seed"]]
    assert res.summary.column_names == ["task", "seed", "a1", "gcv_a1", "status", "error"]


@pytest.mark.slow
def test_peixoto_example2_through_the_engine_is_the_serial_sweep(engine2, tmp_path):
    from lpvest.design import KIND_PD, HinfProgram, design_hinf, search_epsilon
    from lpvest.systems._modelfile import load_system

    spec = tmp_path / "px.toml"
    spec.write_text('experiment = "peixoto-example2"\n[[zip]]\nrho = [3.0]\nepsilon = [-10.0]\n')
    fixed = run_sweep(spec, tmp_path / "fixed", engine=engine2, progress=False)
    spec.write_text('experiment = "peixoto-example2"\nparameters = { rho = [11.0] }\n')
    best = run_sweep(spec, tmp_path / "best", engine=engine2, progress=False)
    # the serial experiment's loop (run_example2 before the hook): one program, built for the first plant
    plant = load_system("peixoto-ex2", parameters={"rho": 11.0}).model()
    program = HinfProgram.for_plant(plant, kind=KIND_PD)
    s = search_epsilon(plant, kind=KIND_PD, program=program)
    row = best.summary.to_pylist()[0]
    assert (row["gamma"], row["design_epsilon"], row["n_evaluations"]) == (s.design.gamma, s.design.epsilon,
                                                                           s.n_evaluations)
    for row in fixed.summary.to_pylist():
        p = load_system("peixoto-ex2", parameters={"rho": row["rho"]}).model()
        assert row["gamma"] == design_hinf(p, epsilon=row["epsilon"], kind=KIND_PD, program=program).gamma


def test_map_tasks_names_the_failed_task():
    from lpvest.experiments._cox_toth import prediction_error_setup, prediction_error_task

    setup = prediction_error_setup(steps=10, runs=5, burn_in=2)
    with pytest.raises(SweepError, match=r"task 1 \(filter = 'kalman'\) failed: KeyError: .*no filter 'kalman'"):
        map_tasks(prediction_error_task, setup, [{"filter": "exact"}, {"filter": "kalman"}], desc="mc")
    assert [r.metrics["mean_trace"] for r in map_tasks(prediction_error_task, setup, [Task(0, {"filter": "exact"})])
            ] == [setup.mean_trace["exact"]]


def test_the_example_sweep_file_loads(fmus):
    spec = load_sweep(ROOT / "examples" / "sweep_kalman.toml", fmu_dir=fmus.out)
    assert spec.n_tasks == 400 and len(spec.tasks()) == 400
    assert [a.name for a in spec.axes] == ["truncated.tau"] and spec.cosim.n_steps == 200


@pytest.mark.parametrize("columns", [80, 40])
def test_the_sweep_bar_keeps_its_count_in_a_terminal_of_80_or_40_columns(fmus, tmp_path, columns):
    from tests.test_progress import assert_bars_keep_their_count, run_in_terminal

    spec = _write(tmp_path / "spec", fmus, n=3, name="kalman-seeds.toml")
    status, shown, stdout = run_in_terminal(["sweep", str(spec), "--out", str(tmp_path / "out"), "--workers", "0",
                                             "--no-plot"], columns, tmp_path)
    assert status == 0, shown
    bars = assert_bars_keep_their_count(shown, ("sweep kalman-seeds",), columns)
    assert re.search(r"\b0/3\b", bars[0]) and re.search(r"\b3/3\b", bars[-1]), bars
    assert "ran 3 task(s) in " in stdout, stdout
