"""Dask worker preload of the embedded LocalCluster: the worker processes
ignore SIGINT, and keep their temporary files in their Dask work folder.

``Ctrl-C`` in a terminal reaches every process of the foreground group: the
client (lpvest sweep), which cancels the pending tasks, writes what finished
and closes the cluster, and the worker processes it started, which would die
with a traceback each before the client could close them. Only the client
acts on it.

What a worker unpacks or compiles (a co-simulation's FMUs, several MB each, the
status bridges) goes in the folder Dask gives the worker
(``dask-scratch-space/worker-*`` in the temporary folder). Its own clean-ups
remove these at exit, but a worker killed by its nanny (the cluster closed
while a task runs: after a Ctrl-C, when a sweep is interrupted) or by the
system never runs them. Dask removes that folder when the worker closes, and
purges the folder of a dead worker when the next worker starts there.
"""

from __future__ import annotations

import signal
import tempfile
from typing import Any

__all__: list[str] = []


def dask_setup(worker: Any) -> None:
    """Called by Dask in each new worker process (the main thread of its loop),
    before it runs a task."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    tempfile.tempdir = str(worker.local_directory)
