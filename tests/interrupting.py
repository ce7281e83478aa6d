"""Running a command until it reaches a moment, then signalling it: the
interruption tests' one way of synchronising (lpvest.core._interrupt's test hook,
``LPVEST_TEST_HOLD`` / ``LPVEST_TEST_READY``), never a delay."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT = 300.0  # seconds before a hung command is killed (never reached when the command works)


def _default_sigint() -> None:
    """In the child, before it runs: SIGINT at its default. A process started
    in the background by a shell without job control (``./dev test &``, a CI
    script) inherits SIGINT *ignored*, and Python keeps it ignored: the
    command then never sees the test's Ctrl-C and runs to its end (status 0)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def lpvest_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "lpvest.cli", *args]


def interrupt_at(cmd: list[str], moment: str, tmp_path: Path, *, signum: int = signal.SIGINT,
                 cwd: Path = ROOT, group: bool = False,
                 env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``cmd`` with the hook holding at ``moment``; send ``signum`` once it
    says it is there (``group``: to its whole process group, as a terminal's
    Ctrl-C does: the command runs in a new session; ``env``: variables added to
    this process's environment); return how it ended."""
    ready = tmp_path / f"ready-{moment}-{os.getpid()}-{len(list(tmp_path.iterdir()))}"
    env = {**os.environ, **(env or {}), "LPVEST_TEST_HOLD": moment, "LPVEST_TEST_READY": str(ready)}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=cwd,
                            start_new_session=group, preexec_fn=_default_sigint)
    try:
        # the event: the line in the ready file (or the command ending without reaching it)
        while proc.poll() is None and not (ready.is_file() and ready.read_text().endswith("\n")):
            try:
                proc.wait(timeout=0.01)  # a poll of the event, not a delay the result depends on
            except subprocess.TimeoutExpired:
                pass
        if proc.poll() is None:
            if group:
                os.killpg(proc.pid, signum)
            else:
                proc.send_signal(signum)
        stdout, stderr = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:  # pragma: no cover - only when the test fails
            os.killpg(proc.pid, signal.SIGKILL) if group else proc.kill()
            proc.communicate()
    assert ready.is_file(), f"the command never reached {moment}: {stderr}"
    return subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)
