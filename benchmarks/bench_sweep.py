"""Speed-up and per-task overhead of the sweep engine (Dask); a script, not a test.

    .venv/bin/python benchmarks/bench_sweep.py [--tasks 16] [--seconds 1.0] [--repeat 3]
                                               [--fmus DIR] [--out FILE.json]

The task: one co-simulation of the Cox & Toth truncation plant (own noise),
its random scheduler and the exact LPV Kalman filter FMU
(``CoxTothTruncation{Scheduler,Plant,Kalman}``), per-task seeds for the plant
and the scheduler, metrics and the state trajectories kept; the number of steps
is calibrated so that one task takes about ``--seconds`` in this process.
``--tasks`` such tasks (one sweep file, seeds only) run three ways:

1. **serial loop**: the task function (:func:`lpvest.sweep._studies.run_cosim_task`:
   the FMUs loaded at the first task, reset for each next one) called in a
   plain loop in this process: no engine, nothing written;
2. **engine, 1 worker**: :func:`lpvest.sweep.run_sweep` on a Dask
   ``LocalCluster`` of one worker process (started beforehand; its start-up is
   reported apart): the whole path, from reading and checking the spec
   (which loads the FMUs once in this process) to the Parquet summary and
   the Zarr trajectories;
3. **engine, 2 workers**: the same on two worker processes.

The three alternate ``--repeat`` times and the best time of each counts
(the machine is shared: a run that met someone else's job is not the
engine's time). Reported: the wall times, the per-task overhead of the engine,
``(1 worker - serial loop) / tasks``, also as a fraction of a task (target: at
most 5 % for one-second tasks), split into the engine's own part (the wall
time minus the tasks' durations measured inside the worker: scheduling,
transfer, writing the results) and the task's own speed in the worker process
against this one, and the speed-up of 2 workers against 1
(target: at least 1.7 on 2 cores). All runs give the same numbers (checked).
The load average is printed before and after.

The FMUs come from ``--fmus DIR`` (default ``fmu-build``); missing ones are
built there first.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

ROLES = ("Scheduler", "Plant", "Kalman")

COSIM = """
title = "benchmark: plant + scheduler + Kalman filter"
step_size = 1.0
steps = {steps}
connections = ["sched.p -> plant.p", "sched.p -> kalman.p", "plant.y -> kalman.y"]

[components.sched]
fmu = "{fmus}/CoxTothTruncationScheduler.fmu"
parameters = {{ kind = "random", rate = [0.2] }}

[components.plant]
fmu = "{fmus}/CoxTothTruncationPlant.fmu"
parameters = {{ noise = true }}

[components.kalman]
fmu = "{fmus}/CoxTothTruncationKalman.fmu"
"""

SPEC = """
title = "benchmark sweep"
cosim = "bench.toml"
keep = ["plant.x", "kalman.xhat"]

[seeds]
count = {tasks}
root = 1
parameters = ["plant.seed", "sched.seed"]

[metrics]
rms = {{ kind = "rms_error", estimate = "kalman.xhat", truth = "plant.x" }}
trace_P = {{ kind = "final_trace", of = "kalman.P" }}
"""


def fmu_folder(folder: Path) -> Path:
    if not all((folder / f"CoxTothTruncation{r}.fmu").is_file() for r in ROLES):
        from lpvest.fmi._build import build_fmus

        print(f"building the cox-toth-truncation FMUs into {folder} ...")
        build_fmus(["cox-toth-truncation"], folder, roles=list(ROLES))
    return folder.resolve()


def write_spec(folder: Path, fmus: Path, steps: int, tasks: int) -> Path:
    (folder / "bench.toml").write_text(COSIM.format(steps=steps, fmus=fmus))
    spec = folder / "sweep.toml"
    spec.write_text(SPEC.format(tasks=tasks))
    return spec


def serial_loop(spec_path: Path, *, loaded: bool = False) -> tuple[float, list[dict[str, float]]]:
    """(seconds, metrics) of the tasks in a plain loop; the FMUs are loaded at
    the first task, as a worker does, or before the clock starts (``loaded``)."""
    from lpvest.sweep import load_sweep
    from lpvest.sweep._studies import prepare, release_simulation

    spec = load_sweep(spec_path)
    prepared = prepare(spec, ship_fmus=False)
    tasks = spec.tasks()
    release_simulation()  # the loop loads the FMUs at its first task, as a worker does
    if loaded:
        prepared.fn(prepared.shared, tasks[0])
    t = time.perf_counter()
    metrics = [dict(prepared.fn(prepared.shared, task).metrics) for task in tasks]
    return time.perf_counter() - t, metrics


def task_seconds(out: Path) -> float:
    """The sum of the tasks' durations measured inside the workers."""
    import pyarrow.parquet as pq

    return float(sum(sum(pq.read_table(f, columns=["seconds"]).column("seconds").to_pylist())
                     for f in sorted((out / "parts").glob("*.parquet"))))


def calibrate(folder: Path, fmus: Path, seconds: float) -> int:
    """Steps for a task of about ``seconds`` in this process (the FMUs' loading,
    once per process, not counted)."""
    steps = 200
    while True:
        spec = write_spec(folder, fmus, steps, 3)
        elapsed, _ = serial_loop(spec, loaded=True)
        per_task = elapsed / 3
        if per_task > 0.25 * seconds:
            return max(1, int(round(steps * seconds / per_task)))
        steps *= 4


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", type=int, default=16, help="tasks per run (default 16)")
    parser.add_argument("--seconds", type=float, default=1.0, help="duration of one task (default 1.0)")
    parser.add_argument("--repeat", type=int, default=3, 
                        help="alternate the runs this often, keep the best (default 3)")
    parser.add_argument("--fmus", default="fmu-build", help="FMU folder (default fmu-build)")
    parser.add_argument("--out", help="also write the figures as JSON")
    args = parser.parse_args()

    from lpvest.sweep import Engine, run_sweep

    fmus = fmu_folder(Path(args.fmus))
    work = Path(tempfile.mkdtemp(prefix="lpvest-bench-sweep-"))
    load_before = os.getloadavg()
    steps = calibrate(work, fmus, args.seconds)
    spec = write_spec(work, fmus, steps, args.tasks)
    print(f"task: plant + scheduler + Kalman FMUs, {steps} steps (about {args.seconds:g} s here); "
          f"{args.tasks} tasks; load average before {load_before[0]:.2f}")

    results = {"serial": float("inf"), "workers_1": float("inf"), "workers_2": float("inf")}
    starts: dict[int, float] = {}
    inside: dict[int, float] = {}
    for r in range(args.repeat):
        elapsed, serial_metrics = serial_loop(spec)
        results["serial"] = min(results["serial"], elapsed)
        for workers in (1, 2):
            t = time.perf_counter()
            with Engine(workers=workers) as engine:
                starts[workers] = time.perf_counter() - t
                t = time.perf_counter()
                res = run_sweep(spec, work / f"out-{workers}-{r}", engine=engine, progress=False, plot=False)
                wall = time.perf_counter() - t
                if wall < results[f"workers_{workers}"]:
                    results[f"workers_{workers}"] = wall
                    # the tasks' own time inside the workers (Outcome.seconds, written with each part)
                    inside[workers] = task_seconds(work / f"out-{workers}-{r}")
            assert res.complete and not res.failures
            got = res.summary.select(["rms", "trace_P"]).to_pylist()
            assert got == [{k: m[k] for k in ("rms", "trace_P")} for m in serial_metrics], "results differ"
        print(f"  run {r + 1}: serial {elapsed:.2f} s, best so far: 1 worker {results['workers_1']:.2f} s, "
              f"2 workers {results['workers_2']:.2f} s")
    serial = results["serial"]
    n = args.tasks
    per_task = serial / n
    overhead = (results["workers_1"] - serial) / n
    speedup = results["workers_1"] / results["workers_2"]
    load_after = os.getloadavg()
    print(f"serial loop        {serial:8.2f} s   ({per_task:.3f} s per task)")
    print(f"engine, 1 worker   {results['workers_1']:8.2f} s   (cluster start-up {starts[1]:.2f} s, not included)")
    print(f"engine, 2 workers  {results['workers_2']:8.2f} s   (cluster start-up {starts[2]:.2f} s, not included)")
    print(f"per-task overhead of the engine: {overhead * 1e3:+.1f} ms = {100 * overhead / per_task:+.2f} % of a "
          f"task (target <= 5 %)")
    own = (results["workers_1"] - inside[1]) / n
    print(f"  of which the engine itself (1 worker: wall time - the tasks' time inside the worker): "
          f"{own * 1e3:+.1f} ms = {100 * own / per_task:+.2f} % of a task; the rest is the task running "
          f"{100 * (inside[1] / serial - 1):+.1f} % slower or faster in the worker process than in this one")
    print(f"speed-up, 2 workers vs 1: {speedup:.2f}x (target >= 1.7x); load average after {load_after[0]:.2f}")
    print("the three runs give the same metrics (checked)")
    if args.out:
        Path(args.out).write_text(json.dumps({
            "steps": steps, "tasks": n, "task_seconds": per_task, **results,
            "startup_1": starts[1], "startup_2": starts[2], "overhead_per_task_s": overhead,
            "overhead_fraction": overhead / per_task, "speedup_2_vs_1": speedup,
            "engine_own_overhead_per_task_s": own, "task_seconds_inside_1_worker": inside[1],
            "load_before": load_before[0], "load_after": load_after[0]}, indent=1) + "\n")


if __name__ == "__main__":
    main()
