"""docs/own-plant.md, executed as written: every `$ lpvest ...` line of its
console blocks (through lpvest.cli.main), every TOML block that names its file
in a first-line comment (written to that file), every Python block (run), in
document order, in a folder holding a copy of examples/."""

from __future__ import annotations

import re
import shlex
import shutil
import zipfile
from pathlib import Path

import pytest

from lpvest.cli import main

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "own-plant.md"
BLOCK = re.compile(r"^```(\w+)\n(.*?)^```$", re.S | re.M)


def blocks() -> list[tuple[str, str]]:
    return [(m.group(1), m.group(2)) for m in BLOCK.finditer(DOC.read_text(encoding="utf-8"))]


def test_the_walkthrough_has_commands_a_cosimulation_file_and_python():
    kinds = [k for k, _ in blocks()]
    assert kinds.count("console") >= 4 and "python" in kinds
    named = [body.splitlines()[0] for k, body in blocks() if k == "toml" and body.startswith("# ")]
    assert named == ["# own_cosim.toml"]


@pytest.mark.slow
def test_the_walkthrough_runs_as_written(tmp_path, monkeypatch, capsys):
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    commands = 0
    for kind, body in blocks():
        if kind == "console":
            for line in body.splitlines():
                assert line.startswith("$ lpvest "), line
                args = shlex.split(line[2:])[1:]
                assert main(args) == 0, (line, capsys.readouterr())
                commands += 1
        elif kind == "toml" and body.startswith("# "):
            name = body.splitlines()[0][2:].strip()
            (tmp_path / name).write_text(body, encoding="utf-8")
        elif kind == "python":
            exec(compile(body, str(DOC), "exec"), {"__name__": "__walkthrough__"})  # noqa: S102 - our own doc
    assert commands == 7
    fmus = sorted(p.stem for p in (tmp_path / "fmu-own").glob("*.fmu"))
    assert fmus == sorted(f"OwnPlant{r}" for r in ("Plant", "Scheduler", "Source", "Kalman", "TruncatedKalman",
                                                     "HinfPD", "HinfRobust"))
    assert list((tmp_path / "out" / "own-sim").glob("*.csv"))
    assert list((tmp_path / "out" / "own-cosim").glob("*.csv"))
    with zipfile.ZipFile(tmp_path / "out" / "own.ssp") as z:
        assert "SystemStructure.ssd" in z.namelist()
    out = capsys.readouterr().out
    assert re.search(r"gamma = \d\.\d{4}, rms error = \d\.\d{4}", out)
    assert "7 FMU(s) in fmu-own, all valid" in out
