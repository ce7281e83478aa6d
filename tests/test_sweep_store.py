"""A sweep's output folder checks itself when a rerun opens it: each part file
against the SHA-256 recorded next to it when it was written, each finished
task's kept trajectories against the SHA-256 its part recorded. What is
damaged is named in one line and run again; the result is the same, byte for
byte, as an undamaged run's. A damaged sweep.json is rewritten from the parts
(which record the sweep's digest), keeping every finished task.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from lpvest.sweep import SweepError, run_sweep
from tests.test_sweep import _write

N = 6


@pytest.fixture(scope="module")
def clean(fmus, tmp_path_factory):
    # the session's FMUs (tests/conftest_fmu.py), as tests/test_sweep.py uses
    folder = tmp_path_factory.mktemp("store")
    spec = _write(folder / "spec", fmus, n=N)
    res = run_sweep(spec, folder / "clean", workers=0, progress=False, plot=False, flush_every=2)
    assert res.complete and not res.failures and len(list((folder / "clean" / "parts").glob("part-*.parquet"))) == 3
    return spec, res


def _copy(clean, tmp_path):
    spec, res = clean
    out = tmp_path / "out"
    shutil.copytree(res.out, out)
    return spec, res, out


def _same_as_clean(res, clean_res):
    assert res.complete and not res.failures
    assert (res.out / "summary.parquet").read_bytes() == (clean_res.out / "summary.parquet").read_bytes()
    for name in ("plant.x", "kalman.xhat"):
        np.testing.assert_array_equal(res.trajectories()[name][:], clean_res.trajectories()[name][:])


def test_a_truncated_part_file_is_named_set_aside_and_its_tasks_run_again(clean, tmp_path, capsys):
    spec, clean_res, out = _copy(clean, tmp_path)
    part = out / "parts" / "part-000002.parquet"
    part.write_bytes(part.read_bytes()[:100])
    res = run_sweep(spec, out, workers=0, progress=False, plot=False, flush_every=2)
    assert res.repaired == ("parts/part-000002.parquet is damaged (its SHA-256 differs from the one recorded when "
                            "it was written); its tasks are run again",)
    assert "lpvest: repaired: parts/part-000002.parquet is damaged" in capsys.readouterr().err
    assert (res.ran, res.resumed) == (2, N - 2)
    assert (out / "parts" / "damaged-part-000002.parquet").is_file()  # kept for a look, never read again
    _same_as_clean(res, clean_res)
    again = run_sweep(spec, out, workers=0, progress=False, plot=False)
    assert (again.ran, again.repaired) == (0, ())


@pytest.mark.parametrize("damage", ["swap", "truncate"])
def test_damaged_trajectory_chunks_are_found_and_their_tasks_run_again(clean, tmp_path, damage):
    spec, clean_res, out = _copy(clean, tmp_path)
    chunks = [out / "trajectories.zarr" / name / "c" / "0" / "0" / "0" for name in ("plant.x", "kalman.xhat")]
    assert all(c.is_file() for c in chunks)
    if damage == "swap":  # two arrays of the same shape: each reads the other's values without an error
        a, b = (c.read_bytes() for c in chunks)
        chunks[0].write_bytes(b)
        chunks[1].write_bytes(a)
        why = "plant.x: its values differ from those written"
    else:
        chunks[0].write_bytes(chunks[0].read_bytes()[:-7])
        why = "plant.x: cannot be read ("
    res = run_sweep(spec, out, workers=0, progress=False, plot=False)
    assert len(res.repaired) == 1
    assert res.repaired[0].startswith(f"trajectories.zarr: {N} task(s) damaged (task 0: {why}")
    assert res.repaired[0].endswith("they are run again")
    assert res.ran == N
    _same_as_clean(res, clean_res)


def test_a_truncated_sweep_json_keeps_the_finished_tasks(clean, tmp_path):
    spec, clean_res, out = _copy(clean, tmp_path)
    header = out / "sweep.json"
    header.write_text(header.read_text()[:40])
    res = run_sweep(spec, out, workers=0, progress=False, plot=False)
    assert res.repaired == ("sweep.json was damaged; rewritten from the part files (their digest is this sweep's)",)
    assert (res.ran, res.resumed) == (0, N)  # nothing thrown away
    assert json.loads(header.read_text())["complete"] is True
    _same_as_clean(res, clean_res)


def test_a_truncated_sweep_json_without_parts_of_this_sweep_is_refused_with_its_remedy(clean, tmp_path):
    spec, _, out = _copy(clean, tmp_path)
    (out / "sweep.json").write_text("{")
    for part in (out / "parts").glob("part-*.parquet.sha256"):
        part.unlink()  # no part can be trusted to say which sweep this is
    with pytest.raises(SweepError, match=r"sweep.json is damaged and no part file says which sweep this folder "
                                         r"holds \(this one: [0-9a-f]{12}\): choose another output folder, or "
                                         r"overwrite them"):
        run_sweep(spec, out, workers=0, progress=False, plot=False)


def test_the_summary_carries_each_metrics_definition_and_pandas_reads_it(clean):
    import pandas as pd
    import pyarrow.parquet as pq

    _, res = clean
    path = res.out / "summary.parquet"
    definitions = json.loads(pq.read_schema(path).metadata[b"lpvest_metrics"])
    # tests/test_sweep.py SPEC: the [metrics] table, as written
    assert definitions == {
        "rms": {"kind": "rms_error", "estimate": "kalman.xhat", "truth": "plant.x", "start": 0},
        "peak": {"kind": "max_abs_error", "estimate": "kalman.xhat", "truth": "plant.x", "start": 5},
        "trace_P": {"kind": "final_trace", "of": "kalman.P", "start": 0},
        "loglik": {"kind": "final", "of": "kalman.loglik", "start": 0},
    }
    frame = pd.read_parquet(path)  # pandas comes with the sweep extra
    assert list(frame["task"]) == list(range(N)) and frame["rms"].notna().all()
