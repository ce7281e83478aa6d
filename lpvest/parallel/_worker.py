"""Dask worker preload of the embedded LocalCluster: the worker processes
ignore SIGINT.

``Ctrl-C`` in a terminal reaches every process of the foreground group: the
client (lpvest sweep), which cancels the pending tasks, writes what finished
and closes the cluster, and the worker processes it started, which would die
with a traceback each before the client could close them. Only the client
acts on it.
"""

from __future__ import annotations

import signal
from typing import Any

__all__: list[str] = []


def dask_setup(worker: Any) -> None:
    """Called by Dask in each new worker process (the main thread of its loop)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
