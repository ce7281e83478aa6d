"""Regression tests on exported FMUs: each example's co-simulation against the
references stored in tests/data/reference (regenerate: `lpvest regress --update`).

The tolerance of each reference and its reason are in
lpvest.experiments._references.REFERENCES (and in each file's header).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lpvest.experiments._references import (
    REFERENCES,
    check_reference,
    read_reference,
    regress,
    simulate_reference,
    write_reference,
)

REFERENCE_DIR = Path(__file__).parent / "data" / "reference"


@pytest.fixture(scope="module")
def runs(experiment_fmus):
    """Every reference's co-simulation, once."""
    return {ref.name: simulate_reference(ref, experiment_fmus) for ref in REFERENCES}


@pytest.mark.parametrize("ref", REFERENCES, ids=lambda r: r.name)
def test_cosimulation_matches_the_stored_reference(ref, runs):
    data, designs = runs[ref.name]
    checks = check_reference(ref, data, designs, REFERENCE_DIR)
    assert all(c.ok for c in checks), "\n".join(c.line() for c in checks)
    assert [c.name for c in checks[: 1 + len(ref.columns)]] == ["time", *ref.columns]
    assert len(checks) == 1 + len(ref.columns) + len(ref.designs)


@pytest.mark.parametrize("ref", REFERENCES, ids=lambda r: r.name)
def test_reference_files_are_small_and_self_describing(ref):
    path = REFERENCE_DIR / ref.filename
    columns, data, designs = read_reference(path)
    assert columns == ["time", *ref.columns]
    assert 100 <= data.shape[0] <= 300 and path.stat().st_size < 12_000  # a few hundred rows, a few KB
    assert np.all(np.isfinite(data))
    assert set(designs) == set(ref.designs) and all(len(d) == 64 for d in designs.values())
    head = path.read_text().splitlines()[:3]
    assert f"tolerance: {ref.tolerance:g}" in head[2] and "lpvest regress --update" in path.read_text()
    # the stored signals are not trivial: a reference of zeros would catch nothing
    assert all(np.max(np.abs(data[:, j])) > 1e-3 for j in range(1, data.shape[1]))


def test_a_changed_trajectory_fails(runs, tmp_path):
    """The comparison can fail: a reference perturbed by 10x its tolerance is caught,
    and another carried design is caught even when the trajectory is unchanged."""
    ref = next(r for r in REFERENCES if r.name == "peixoto-fig1")
    data, designs = runs[ref.name]
    write_reference(ref, data, designs, tmp_path)
    assert all(c.ok for c in check_reference(ref, data, designs, tmp_path))
    bad = data.copy()
    bad[50, 2] += 10 * ref.tolerance * np.max(np.abs(data[:, 2]))
    write_reference(ref, bad, designs, tmp_path)
    failed = [c.name for c in check_reference(ref, data, designs, tmp_path) if not c.ok]
    assert failed == [ref.columns[1]]
    write_reference(ref, data, {k: "0" * 64 for k in designs}, tmp_path)
    failed = [c.name for c in check_reference(ref, data, designs, tmp_path) if not c.ok]
    assert [f.split(" (")[0] for f in failed] == [f"design {name}" for name in ref.designs]


def test_regress_command_updates_then_passes(experiment_fmus, tmp_path):
    lines: list[str] = []
    assert regress(["cox-toth-example1"], update=True, directory=tmp_path, fmus=experiment_fmus,
                   echo=lines.append) == 0
    assert lines[0].startswith("wrote ") and (tmp_path / "cox-toth-example1.csv").is_file()
    lines.clear()
    assert regress(["cox-toth-example1"], directory=tmp_path, fmus=experiment_fmus, echo=lines.append) == 0
    assert lines[0] == "cox-toth-example1: ok"
    # a reference from another set-up fails with status 1
    text = (tmp_path / "cox-toth-example1.csv").read_text().splitlines()
    text[-1] = ",".join([text[-1].split(",")[0], "1.5", "2.5"])
    (tmp_path / "cox-toth-example1.csv").write_text("\n".join(text) + "\n")
    lines.clear()
    assert regress(["cox-toth-example1"], directory=tmp_path, fmus=experiment_fmus, echo=lines.append) == 1
    assert lines[0] == "cox-toth-example1: FAIL" and "lpvest regress --update" in lines[-1]
