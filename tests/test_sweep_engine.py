"""The sweep engine's handling of results (lpvest/parallel/_engine.py) against a stubbed Dask client.

The futures, their completion order and their statuses are scripted, so each case the engine
must handle (a result that arrives while its future is already lost, a task that could not run,
a caller that fails or is interrupted, a cluster that goes quiet) happens exactly once, without
a cluster and without timing. tests/test_sweep.py runs the engine on real clusters.
"""

from __future__ import annotations

import distributed
import pytest

import lpvest.parallel._engine as engine_module
from lpvest.parallel._engine import LOCAL_WORKER_CONFIG, Engine, require_sweep_extra
from lpvest.parallel._tasks import Outcome, SweepError, Task, TaskResult


class Future:
    def __init__(self, key: str, status: str = "finished") -> None:
        self.key, self.status, self.released = key, status, 0

    def release(self) -> None:
        self.released += 1


class Client:
    """Records what the engine submits, cancels and closes."""

    def __init__(self) -> None:
        self.submitted: list[tuple] = []
        self.futures: list[Future] = []
        self.cancelled: list[list[str]] = []
        self.shared: Future | None = None

    def submit(self, fn, value, *, key, pure):
        assert fn is engine_module._shared and fn(value) is value and pure is False
        self.shared = Future(key)
        self.submitted.append(("shared", key, value))
        return self.shared

    def map(self, run, tasks, **kw):
        assert run is engine_module._run and kw["pure"] is False and kw["shared"] is self.shared
        self.submitted.append(("tasks", kw["key"], kw["fn"]))
        self.mapped = list(tasks)
        self.futures = [Future(k) for k in kw["key"]]
        return self.futures

    def cancel(self, futures, force):
        assert force is True
        self.cancelled.append([f.key for f in futures])

    def scheduler_info(self, n_workers):
        assert n_workers == -1
        return {"workers": {"tcp://a": {}, "tcp://b": {}, "tcp://c": {}}}


class Completed:
    """``as_completed`` over scripted batches: a list of ``[(future index, value), ...]`` per call."""

    def __init__(self, client: Client, script: list[list[tuple[int, object]]]) -> None:
        self.client, self.script = client, list(script)

    def __call__(self, futures, *, with_results, raise_errors):
        assert with_results is True and raise_errors is False and futures is self.client.futures
        return self

    def is_empty(self) -> bool:
        return not self.script

    def next_batch(self, block):
        assert block is False
        batch = []
        for i, value, *status in self.script.pop(0):
            future = self.client.futures[i]
            if status:
                future.status = status[0]  # what the scheduler says by the time the value is read
            batch.append((future, value))
        return batch


def fn(shared, task):  # a task function (never called: the client is a stub)
    return TaskResult({})


def ok(index: int) -> Outcome:
    return Outcome(index, TaskResult({"x": float(index)}), None, 0.5, "tcp://w")


@pytest.fixture
def run(monkeypatch):
    """Engine.map on a stubbed client with a scripted completion."""
    clock = {"t": 0.0}
    monkeypatch.setattr(engine_module.time, "monotonic", lambda: clock["t"])
    monkeypatch.setattr(engine_module.time, "sleep", lambda s: clock.__setitem__("t", clock["t"] + s))

    def go(script, n=3, *, idle_timeout=None, on_outcome=None, **options):
        client = go.client = Client()
        monkeypatch.setattr(distributed, "as_completed", Completed(client, script))
        eng = Engine(idle_timeout=idle_timeout)
        eng._client = client
        tasks = [Task(i, {"a": i}) for i in range(n)]
        seen: list[Outcome] = []
        out = eng.map(fn, {"shared": 1}, tasks, on_outcome=on_outcome or seen.append, **options)
        return out, seen, client

    return go


def test_outcomes_are_handed_over_in_finishing_order_once_each_and_futures_released(run):
    out, seen, client = run([[], [(2, ok(2))], [], [], [(0, ok(0)), (1, ok(1))]])
    assert [o.index for o in seen] == [2, 0, 1] and out == {0: ok(0), 1: ok(1), 2: ok(2)}
    assert [f.released for f in client.futures] == [1, 1, 1] and client.shared.released == 1
    assert client.cancelled == []
    (_, shared_key, value), (_, keys, task_fn) = client.submitted
    assert value == {"shared": 1} and task_fn is fn
    run_id = shared_key.removeprefix("lpvest-shared-")
    assert len(run_id) == 12 and keys == [f"lpvest-task-{run_id}-{i}" for i in range(3)]


def test_a_result_that_arrives_while_its_future_is_lost_is_the_result(run):
    """Its worker died after sending it: the future says "lost" (or "pending" while the scheduler
    recomputes it), but the value is the task's outcome, kept as it came, once."""
    out, seen, client = run([[(1, ok(1), "lost")], [(0, ok(0), "pending")]], n=2)
    assert out == {0: ok(0), 1: ok(1)} and seen == [ok(1), ok(0)]
    assert [f.released for f in client.futures] == [1, 1]
    # a lost future without a value: its status is the reason
    out, _, _ = run([[(0, None, "lost")]], n=1)
    assert out == {0: Outcome(0, None, "TaskError: lost", 0.0, "")}


def test_tasks_that_could_not_run_become_failed_outcomes_naming_why(run):
    class KilledWorker(Exception):
        pass

    killed = KilledWorker("attempted to run task\n  lpvest-task-x on 3 different workers")
    script = [[(0, (KilledWorker, killed, None))], [(1, distributed.client.FutureCancelledError("k", "reason"))],
              [(2, None)], [(3, ok(3))]]
    out, seen, client = run(script, n=4)
    assert out[0] == Outcome(0, None, "KilledWorker: attempted to run task lpvest-task-x on 3 different workers",
                             0.0, "")
    assert out[1].error.startswith("FutureCancelledError: ") and out[1].result is None
    assert out[2] == Outcome(2, None, "TaskError: finished", 0.0, "")  # no exception: the future's status
    assert out[3].ok and [o.ok for o in seen] == [False, False, False, True]


@pytest.mark.parametrize("error", [OSError("disk full"), KeyboardInterrupt()])
def test_a_failing_or_interrupted_caller_cancels_what_is_pending_and_the_error_propagates(run, error):
    calls = []

    def write(outcome):
        calls.append(outcome.index)
        if outcome.index == 1:
            raise error

    with pytest.raises(type(error)):
        run([[(0, ok(0))], [(1, ok(1))], [(2, ok(2))]], on_outcome=write)
    client = run.client
    run_id = client.shared.key.removeprefix("lpvest-shared-")
    # task 1's outcome was recorded before the caller failed: task 2 and the shared data are pending
    assert client.cancelled == [[f"lpvest-task-{run_id}-2", client.shared.key]] and calls == [0, 1]
    assert client.shared.released == 0


def test_no_finished_task_within_the_idle_timeout_is_an_error_saying_how_far_it_got(run):
    with pytest.raises(SweepError, match=r"^no task finished in 1.5 s \(1 of 3 done\)$"):
        run([[(0, ok(0))]] + [[]] * 200, idle_timeout=1.5)


def test_no_task_finished_from_the_start_within_the_idle_timeout_is_an_error_too(run):
    # no worker ever takes a task: the idle time counts from the call, before any result
    with pytest.raises(SweepError, match=r"^no task finished in 1.5 s \(0 of 3 done\)$"):
        run([[]] * 200, idle_timeout=1.5)


def test_waiting_longer_than_the_idle_timeout_in_total_is_not_idle(run):
    # 60 polls of 20 ms between each result: 1.2 s apart, each wait under the 1.5 s timeout
    script = [[(0, ok(0))]] + [[]] * 60 + [[(1, ok(1))]] + [[]] * 60 + [[(2, ok(2))]]
    out, _, _ = run(script, idle_timeout=1.5, progress=True)
    assert sorted(out) == [0, 1, 2]


def test_no_tasks_submit_nothing():
    eng = Engine()
    eng._client = Client()
    assert eng.map(fn, 1, []) == {} and eng._client.submitted == []


# -- the engine's life cycle ---------------------------------------------------------------


@pytest.mark.parametrize("workers", [0, -2, True, 1.5, "2"])
def test_a_worker_count_that_is_not_a_positive_integer_is_refused(workers):
    with pytest.raises(SweepError, match=r"^workers must be a positive integer; found "):
        Engine(workers=workers)


def test_a_scheduler_and_a_worker_count_together_are_refused():
    with pytest.raises(SweepError, match="^give workers for a local cluster or scheduler for an existing one, not "
                                         "both$"):
        Engine("tcp://127.0.0.1:1", workers=2)
    assert Engine(workers=3).workers == 3 and Engine(workers=1).workers == 1 and Engine().workers is None
    default = Engine()
    assert (default.scheduler, default.idle_timeout, default.start_timeout, default.quiet) == (None, None, 60.0, True)


def test_an_unreachable_scheduler_is_a_sweep_error_naming_it(monkeypatch):
    made = []

    def client(address, timeout):
        made.append((address, timeout))
        raise OSError("Timed out trying to connect")

    monkeypatch.setattr(distributed, "Client", client)
    eng = Engine("tcp://127.0.0.1:9", start_timeout=2.5)
    with pytest.raises(SweepError, match=r"^cannot start or reach the Dask scheduler \(tcp://127.0.0.1:9\): "
                                         r"Timed out trying to connect$"):
        eng.start()
    assert made == [("tcp://127.0.0.1:9", 2.5)] and eng._client is None


def test_close_closes_client_then_cluster_once_even_when_closing_fails():
    closed = []

    class Closing:
        def __init__(self, name, fail):
            self.name, self.fail = name, fail

        def close(self, timeout):
            closed.append((self.name, timeout))
            if self.fail:
                raise RuntimeError("already gone")

    eng = Engine(start_timeout=7.0)
    eng._client, eng._cluster = Closing("client", True), Closing("cluster", True)
    eng.close()
    assert closed == [("client", 7.0), ("cluster", 7.0)] and eng._client is None and eng._cluster is None
    eng.close()
    assert len(closed) == 2


def test_a_started_engine_is_not_started_again_and_describes_where_it_runs():
    eng = Engine("tcp://sched:8786")
    eng._client = Client()
    assert eng.start() is eng and eng.client is eng._client
    assert eng.n_workers == 3 and eng.describe() == "Dask scheduler tcp://sched:8786, 3 worker(s)"
    local = Engine(workers=3)
    local._client = Client()
    assert local.describe() == "Dask LocalCluster, 3 worker process(es)"


def test_the_quiet_worker_settings_and_a_missing_extra():
    assert LOCAL_WORKER_CONFIG["distributed.worker.profile.enabled"] is False
    assert all(LOCAL_WORKER_CONFIG[k] == "1s" for k in LOCAL_WORKER_CONFIG if k.endswith("interval"))
    require_sweep_extra("json", "math")
    with pytest.raises(SweepError, match=r"^lpvest sweeps need lpvest_no_such_module \(No module named "
                                         r"'lpvest_no_such_module'\); install the extra: "
                                         r"pip install 'lpvest\[sweep\]'$"):
        require_sweep_extra("json", "lpvest_no_such_module")


@pytest.mark.parametrize(("workers", "quiet"), [(3, True), (None, False)])
def test_the_local_cluster_is_worker_processes_of_one_thread_each_quiet_and_configured(monkeypatch, workers, quiet):
    """The embedded cluster: one process per worker (an FMU's Python per interpreter), one thread
    each, the workers' preload that leaves Ctrl-C to the client, the quiet-worker settings in force
    while it starts, Dask's loggers at ERROR when quiet (the workers' at CRITICAL: after Ctrl-C on
    a loaded machine a worker's heartbeat fails as the cluster closes, with a traceback)."""
    import logging

    import dask

    made = {}

    class Cluster:
        def __init__(self, **kw):
            made["cluster"] = kw
            made["config"] = {k: dask.config.get(k) for k in LOCAL_WORKER_CONFIG}

        def close(self, timeout):
            made["closed"] = timeout

    def client(target, timeout):
        made["client"] = (target, timeout)
        return Client()

    monkeypatch.setattr(distributed, "LocalCluster", Cluster)
    monkeypatch.setattr(distributed, "Client", client)
    monkeypatch.setattr(engine_module.os, "cpu_count", lambda: 7)
    for name in ("distributed", "distributed.nanny", "distributed.worker", "distributed.scheduler"):
        monkeypatch.setattr(logging.getLogger(name), "level", logging.NOTSET)
    monkeypatch.setattr(logging.getLogger("tornado.application"), "filters", [])  # as in a fresh process
    eng = Engine(workers=workers, quiet=quiet, start_timeout=9.0).start()
    assert made["cluster"] == {"n_workers": workers or 7, "threads_per_worker": 1, "processes": True,
                               "dashboard_address": ":0", "preload": ["lpvest.parallel._worker"],
                               "silence_logs": logging.CRITICAL if quiet else logging.WARNING}
    assert made["config"] == LOCAL_WORKER_CONFIG
    assert made["client"][0] is eng._cluster and made["client"][1] == 9.0
    levels = {logging.getLogger(n).level for n in ("distributed", "distributed.nanny", "distributed.worker",
                                                     "distributed.scheduler")}
    assert levels == ({logging.ERROR} if quiet else {logging.NOTSET})
    # tornado's log of a gather the closing cluster abandoned is dropped, nothing else tornado logs
    tornado = logging.getLogger("tornado.application")
    assert any(not f.filter(logging.LogRecord("tornado.application", logging.ERROR, "", 0,
                                              "Exception in callback as_completed._track_future()", None, None))
               for f in tornado.filters)
    assert all(f.filter(logging.LogRecord("tornado.application", logging.ERROR, "", 0, "Uncaught exception",
                                          None, None)) for f in tornado.filters)
    eng.close()
    assert made["closed"] == 9.0


def test_the_preload_the_engine_names_is_a_module_that_leaves_ctrl_c_to_the_client(tmp_path, monkeypatch):
    """The engine names its workers' preload by a string (above), which no import checks: that
    module exists and its ``dask_setup`` (what Dask calls in each new worker) ignores SIGINT and
    makes the worker's Dask folder the process's temporary folder (tests/test_sweep.py: a killed
    worker leaves nothing)."""
    import importlib
    import signal
    import tempfile
    from types import SimpleNamespace

    module = importlib.import_module("lpvest.parallel._worker")
    previous = signal.getsignal(signal.SIGINT)
    monkeypatch.setattr(tempfile, "tempdir", tempfile.tempdir)  # restored after the test
    try:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        module.dask_setup(SimpleNamespace(local_directory=tmp_path))
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        assert tempfile.gettempdir() == str(tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_local_cluster_that_cannot_start_is_a_sweep_error(monkeypatch):
    def cluster(**kw):
        raise OSError("no free port")

    monkeypatch.setattr(distributed, "LocalCluster", cluster)
    with pytest.raises(SweepError, match=r"^cannot start or reach the Dask scheduler \(a local cluster\): "
                                         r"no free port$"):
        Engine(workers=1).start()


def test_the_progress_bar_counts_tasks_and_failures_only_when_asked(run, capsys):
    failed = Outcome(1, None, "ValueError: bad", 0.1, "w")
    run([[(0, ok(0))], [(1, failed)], [(2, ok(2))]])
    assert capsys.readouterr().err == ""  # no bar by default
    run([[(0, ok(0))], [(1, failed)], [(2, ok(2))]], progress=True)
    err = capsys.readouterr().err
    assert "tasks: 100%" in err and "3/3" in err and "failed=1" in err and "task/s" in err


def test_each_task_is_submitted_and_run_by_the_task_function_on_the_shared_data(run):
    _, _, client = run([[(0, ok(0))], [(1, ok(1))]], n=2)
    assert client.mapped == [Task(0, {"a": 0}), Task(1, {"a": 1})]
    out = engine_module._run(Task(4, {"a": 4}), lambda shared, task: TaskResult({"v": shared * task.index}), 2.5)
    assert out.index == 4 and out.ok and out.result == TaskResult({"v": 10.0})


def test_one_blas_thread_limits_numpys_and_scipys_blas_in_this_process():
    """A task run in this process must compute as on a Dask worker, whose BLAS has one thread.
    numpy's and scipy's wheels each carry an OpenBLAS; one_blas_thread kept a controller made
    before scipy's was loaded, so scipy's kept its threads in this process: the serial and the
    Dask runs of sridhar-noisy differed by 3e-11 when the tests ran without
    OPENBLAS_NUM_THREADS=1. Checked in a process with two BLAS threads by default that has
    not loaded scipy before the limit is entered (as a worker's first task)."""
    import json
    import os
    import subprocess
    import sys

    script = """
import json
import numpy
from lpvest.parallel import one_blas_thread
from threadpoolctl import threadpool_info
with one_blas_thread():
    import scipy.linalg
    inside = [(i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]
after = [(i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]
print(json.dumps([inside, after]))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    env["OPENBLAS_NUM_THREADS"] = "2"
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    inside, after = json.loads(proc.stdout)
    assert inside and all(threads == 1 for _, threads in inside), inside
    if os.cpu_count() and os.cpu_count() > 1:  # the limit is lifted after (OpenBLAS keeps to the cores)
        assert all(threads == 2 for _, threads in after), after
