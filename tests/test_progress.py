"""Progress bars as a user sees them: in a terminal of 80 or 40 columns each
frame of a bar keeps its count ``n/total`` and fits on one line; into a
redirected log no bar, only plain lines; ``--quiet`` none at all.

The terminal is a pseudo-terminal whose width is set with ``TIOCSWINSZ``:
what the command writes there is what a user's terminal would show, frame by
frame (tqdm redraws a bar after a carriage return).
"""

from __future__ import annotations

import fcntl
import os
import pty
import re
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from lpvest.core._progress import progress_bar

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT = 300.0  # seconds before a hung command is killed (never reached when the command works)
_ESCAPE = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")  # tqdm's cursor moves between nested bars


def _terminal(columns: int) -> tuple[int, int]:
    """A pseudo-terminal (controller, terminal) ``columns`` wide."""
    controller, terminal = pty.openpty()
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    return controller, terminal


def _read_all(controller: int) -> str:
    chunks = []
    while True:
        try:
            chunk = os.read(controller, 65536)
        except OSError:  # EIO: every process holding the terminal closed it
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(controller)
    return b"".join(chunks).decode("utf-8", errors="replace")


def run_in_terminal(argv: list[str], columns: int, tmp_path: Path) -> tuple[int, str, str]:
    """``lpvest ARGV`` with stderr on a terminal ``columns`` wide (stdout into a
    file): its status, what its terminal showed, its stdout."""
    controller, terminal = _terminal(columns)
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}  # the terminal's size only
    stdout = tmp_path / f"stdout-{columns}-{len(list(tmp_path.iterdir()))}"
    with stdout.open("w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "lpvest.cli", *argv], stdin=subprocess.DEVNULL, stdout=out,
                                stderr=terminal, env=env, cwd=ROOT)
        os.close(terminal)
        shown = _read_all(controller)
        status = proc.wait(timeout=TIMEOUT)
    return status, shown, stdout.read_text()


def frames(shown: str) -> list[str]:
    """Every state of every line the terminal showed: the text between
    carriage returns and newlines, without cursor moves and the spaces tqdm
    pads a shorter frame with."""
    return [f.rstrip() for f in re.split(r"[\r\n]", _ESCAPE.sub("", shown)) if f.strip()]


def _named(frame: str, desc: tuple[str, ...]) -> bool:
    """Whether ``frame`` is a frame of a bar described as one of ``desc`` (its
    description whole, or shortened to end in "…")."""
    short = re.match(r"(.*?)…: ", frame)
    return any(frame.startswith(f"{d}: ") or (short is not None and d.startswith(short.group(1))) for d in desc)


def assert_bars_keep_their_count(shown: str, desc: tuple[str, ...], columns: int) -> list[str]:
    """The frames of the bars described as ``desc``: at least one, each with its
    count ``n/total`` and narrower than the terminal (no wrapped line)."""
    bars = [f for f in frames(shown) if _named(f, desc)]
    assert bars, shown
    for frame in bars:
        assert re.search(r": .*\b\d+/\d+\b", frame), (columns, frame)
        assert len(frame) < columns, (columns, frame)
    return bars


@pytest.mark.parametrize("columns", [80, 40])
def test_the_epsilon_search_bar_shows_its_count_at_80_and_40_columns(tmp_path, columns):
    status, shown, stdout = run_in_terminal(["design", "peixoto-ex1", "--search", "--out",
                                             str(tmp_path / "pd.json")], columns, tmp_path)
    assert status == 0, shown
    bars = assert_bars_keep_their_count(shown, ("epsilon search", "epsilon refine"), columns)
    assert re.search(r"\b0/24\b", bars[0]), bars  # the grid first (tqdm skips frames drawn faster than 10 a second)
    assert re.search(r"^epsilon refine: .*\b(\d+)/\1\b", bars[-1]), bars  # the refinement, done; the bar stays
    assert "H-infinity filter, gamma = " in stdout


@pytest.mark.parametrize("columns", [80, 40])
def test_build_shows_a_bar_over_the_fmus_with_the_lines_above_it(tmp_path, columns):
    out = tmp_path / "fmus"
    status, shown, stdout = run_in_terminal(["build", "--model", "examples/own_plant.toml", "--kinds",
                                             "Plant,Scheduler", "--out", str(out)], columns, tmp_path)
    assert status == 0, shown
    bars = assert_bars_keep_their_count(shown, ("build",), columns)
    assert re.search(r"\b0/2\b", bars[0]) and re.search(r"\b2/2\b", bars[-1]), bars
    lines = [f for f in frames(shown) if not _named(f, ("build",))]
    assert lines == ["building OwnPlantPlant (1/2)", "building OwnPlantScheduler (2/2)"], shown
    assert "2 FMU(s) in " in stdout


def test_build_into_a_log_writes_lines_and_no_bar_and_quiet_writes_neither(tmp_path):
    out = tmp_path / "fmus"
    argv = [sys.executable, "-m", "lpvest.cli", "build", "--model", "examples/own_plant.toml", "--kinds", "Plant",
            "--out", str(out)]
    logged = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=TIMEOUT)
    assert logged.returncode == 0, logged.stderr
    assert logged.stderr == "building OwnPlantPlant (1/1)\n"  # no carriage return, no bar
    status, shown, stdout = run_in_terminal(argv[3:] + ["--quiet"], 80, tmp_path)
    assert status == 0 and shown == "", shown
    assert "1 FMU(s) in " in stdout


#: The bars of the commands, as each makes them (description, unit, total, postfix):
#: build, design and build's epsilon search, cosim, sweep (in this process or on Dask, with
#: its failures), and reproduce's experiments (their Monte Carlo and task bars).
BARS = [
    ("build", "FMU", 31, "PeixotoEx2HinfRobust"),
    ("epsilon search", "design", 24, "CLARABEL, best gamma 0.7343780"),
    ("epsilon refine", "design", 31, "SCS, best gamma 1.213710"),
    ("co-simulation", "step", 21_000, None),
    ("sweep sweep_kalman", "task", 400, "failed=3"),
    ("prediction error (Monte Carlo)", "task", 1000, None),
    ("Example 2: rho sweep", "task", 21, None),
    ("sridhar-noisy seeds", "task", 20, None),
    ("truncation depth", "tau", 10_000, None),
]


@pytest.mark.parametrize("columns", [80, 40, 20])
@pytest.mark.parametrize(("desc", "unit", "total", "postfix"), BARS)
def test_every_bar_keeps_its_count_in_a_narrow_terminal(monkeypatch, columns, desc, unit, total, postfix):
    """The bar lpvest makes (:func:`lpvest.core._progress.progress_bar`), on a
    terminal of the given width, at its start, midway and at its end."""
    controller, terminal = _terminal(columns)
    with open(terminal, "w", encoding="utf-8", closefd=True) as stream:
        monkeypatch.setattr(sys, "stderr", stream)
        bar = progress_bar(desc=desc, unit=unit, total=total, mininterval=0)
        if postfix:
            bar.set_postfix_str(postfix)
        for step in (1, total // 2 - 1, total - total // 2):
            bar.update(step)
        bar.close()
        monkeypatch.undo()
    shown = _read_all(controller)
    bars = assert_bars_keep_their_count(shown, (desc,), columns)
    counts = [re.search(r"\b(\d+)/(\d+)\b", f).groups() for f in bars]
    assert {int(n) for n, _ in counts} >= {0, 1, total // 2, total} and {int(t) for _, t in counts} == {total}


def test_no_bar_is_drawn_into_a_log_unless_asked(capsys):
    bar = progress_bar(desc="build", unit="FMU", total=3)
    bar.update(3)
    bar.close()
    assert bar.disable and capsys.readouterr().err == ""
    bar = progress_bar(desc="build", unit="FMU", total=3, show=True)  # the Python API's progress=True
    bar.update(3)
    bar.close()
    assert "build: 100%" in capsys.readouterr().err


def test_every_bar_of_lpvest_is_made_by_progress_bar():
    """One constructor for every bar: a tqdm made elsewhere would show
    nothing of its count in a narrow terminal again."""
    library = ROOT / "lpvest"
    elsewhere = [str(p.relative_to(ROOT)) for p in library.rglob("*.py")
                 if p.name != "_progress.py" and re.search(r"^\s*(from|import) tqdm", p.read_text(), re.MULTILINE)]
    assert elsewhere == []
