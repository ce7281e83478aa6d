"""Where a test run's CPU goes: an opt-in pytest plugin and its report.

``-p tests.cpu_timeline`` records, for every test, the worker that ran it, its
wall-clock span, and the CPU seconds of the test process (``self``) and of the
child processes it waited for (``child``: subprocesses, Dask workers shut down),
setup and teardown included, one JSON line per test in
``$LPVEST_CPU_TIMELINE/<worker>-<pid>.jsonl``. ``python -m tests.cpu_timeline DIR``
prints the CPU per worker and per file, costliest first (what ``RUN_FIRST`` in
tests/conftest.py is ranked by) and the costliest tests::

    LPVEST_CPU_TIMELINE=/tmp/tl ./dev test -p tests.cpu_timeline
    .venv/bin/python -m tests.cpu_timeline /tmp/tl

A child's CPU counts when it is reaped: a module-scoped Dask cluster's workers
count against the test during whose teardown they end, so per-file sums are
steadier than per-test figures.
"""

from __future__ import annotations

import collections
import json
import os
import resource
import sys
import time
from pathlib import Path
from typing import IO, Any

import pytest

_FILE: IO[str] | None = None


def _cpu() -> tuple[float, float]:
    me, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):  # noqa: ARG001 - hook signature
    global _FILE
    folder = os.environ.get("LPVEST_CPU_TIMELINE")
    if not folder:
        yield
        return
    if _FILE is None:
        Path(folder).mkdir(parents=True, exist_ok=True)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        _FILE = open(Path(folder) / f"{worker}-{os.getpid()}.jsonl", "a", buffering=1, encoding="utf-8")  # noqa: SIM115
    start, (me, children) = time.time(), _cpu()
    yield
    end, (me2, children2) = time.time(), _cpu()
    _FILE.write(json.dumps({"id": item.nodeid, "worker": os.environ.get("PYTEST_XDIST_WORKER", "main"),
                            "start": start, "end": end, "self": me2 - me, "child": children2 - children}) + "\n")


def pytest_unconfigure(config: pytest.Config) -> None:  # noqa: ARG001 - hook signature
    global _FILE
    if _FILE is not None:
        _FILE.close()
        _FILE = None


def report(folder: Path, most: int = 25) -> list[str]:
    """The CPU per worker, per file and the costliest tests of the records in ``folder``."""
    rows: list[dict[str, Any]] = [json.loads(line) for path in sorted(folder.glob("*.jsonl"))
                                  for line in path.read_text(encoding="utf-8").splitlines() if line]
    if not rows:
        return [f"{folder}: no records"]
    t0 = min(r["start"] for r in rows)
    lines = []
    workers: dict[str, list[dict[str, Any]]] = collections.defaultdict(list)
    files: dict[str, list[dict[str, Any]]] = collections.defaultdict(list)
    for r in rows:
        workers[r["worker"]].append(r)
        files[r["id"].split("::")[0]].append(r)

    def cpu(rs: list[dict[str, Any]]) -> float:
        return sum(r["self"] + r["child"] for r in rs)

    lines.append(f"{len(rows)} tests, {cpu(rows):.0f} CPU-s (test processes and the children they waited for)")
    for name, rs in sorted(workers.items()):
        lines.append(f"  {name}: {len(rs)} tests, {cpu(rs):.0f} CPU-s, "
                     f"{min(r['start'] for r in rs) - t0:.0f}-{max(r['end'] for r in rs) - t0:.0f} s")
    lines.append("per file, costliest first:")
    for name, rs in sorted(files.items(), key=lambda kv: -cpu(kv[1]))[:most]:
        lines.append(f"  {cpu(rs):7.1f} CPU-s  {max(r['end'] for r in rs) - min(r['start'] for r in rs):7.1f} s span"
                     f"  {name}")
    lines.append("per test, costliest first:")
    for r in sorted(rows, key=lambda r: -(r["self"] + r["child"]))[:most]:
        lines.append(f"  {r['self'] + r['child']:7.1f} CPU-s ({r['self']:.1f} + children {r['child']:.1f})  {r['id']}")
    return lines


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python -m tests.cpu_timeline DIR")
    print("\n".join(report(Path(sys.argv[1]))))
