"""The output folder of a sweep: written as tasks finish, read back to resume.

::

    OUT/sweep.json           what ran: the spec's digest, axes, metrics, signals, counts, complete or not
    OUT/parts/part-*.parquet finished tasks (metrics, status, error, time, worker), appended in batches
    OUT/trajectories.zarr/   one array per kept signal, (tasks, *shape), NaN until a task has run; "time"
    OUT/summary.parquet      every finished task in task order: task, axes, seed, metrics, status, error
    OUT/timing.parquet       task, seconds, worker (not part of the summary: it varies from run to run)

The digest covers the spec (axes, seeds, metrics, kept signals, options), what
the study reads (a co-simulation's FMUs by SHA-256, its connections and steps;
an experiment's options and data), the metric and signal names, and lpvest's
version (not its code: after changing it, use a new folder or ``overwrite``).

A batch of outcomes is committed by writing its trajectories first and its
part file last (written to a temporary name, then renamed): a task is
finished when a part holds it. A rerun of the same spec (same digest) reads
the parts and runs only the tasks none of them holds; a different spec in the
same folder is refused unless ``overwrite`` (which removes the files above,
nothing else). Failed tasks are finished too: ``retry_failed`` runs them again
(the later part holding a task is the one that counts).

``summary.parquet`` is rebuilt from the parts at the end of every run, sorted
by task, with no column that depends on timing or workers: the same spec gives
the same file, byte for byte, whatever the number of workers, their order, or
how often the run was interrupted and resumed.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..parallel._prepared import Prepared
from ..parallel._tasks import Outcome, SweepError, Task
from ._sweepfile import Axis, SweepSpec

if TYPE_CHECKING:
    import zarr
    from numpy.typing import ArrayLike

    from ..core._typing import ArrowObject, ArrowTable

__all__ = ["SweepStore", "FORMAT"]

FORMAT = "lpvest-sweep/1"
_FILES = ("sweep.json", "summary.parquet", "timing.parquet")
_DIRS = ("parts", "trajectories.zarr", "figures")


def _arrow_type(axis: Axis) -> ArrowObject:
    import pyarrow as pa

    kinds = {type(v) for v in axis.values}
    if kinds <= {bool}:
        return pa.bool_()
    if kinds <= {int}:
        return pa.int64()
    if kinds <= {int, float}:
        return pa.float64()
    if kinds <= {str}:
        return pa.string()
    return pa.list_(pa.float64())


def _axis_value(axis: Axis, value: object) -> object:
    if isinstance(value, tuple):
        return [float(v) for v in value]
    if isinstance(value, int) and not isinstance(value, bool) and any(isinstance(v, float) for v in axis.values):
        return float(value)
    return value


class SweepStore:
    """The output folder of one sweep (see the module documentation).

    Parameters
    ----------
    out : str or Path
        The folder (created).
    spec, prepared, tasks, digest
        The sweep: its spec, its prepared form, every task, and the digest
        that names it.
    overwrite : bool
        Remove the results of another sweep in ``out`` instead of refusing.
    retry_failed : bool
        Treat failed tasks of an earlier run as not finished.
    flush_every, flush_seconds : int, float
        Commit a batch when it holds this many outcomes, or when the oldest
        waits this long.
    """

    def __init__(
        self,
        out: str | Path,
        spec: SweepSpec,
        prepared: Prepared,
        tasks: Sequence[Task],
        digest: str,
        *,
        overwrite: bool = False,
        retry_failed: bool = False,
        flush_every: int = 256,
        flush_seconds: float = 1.0,
    ) -> None:
        from ..parallel._engine import require_sweep_extra

        require_sweep_extra("pyarrow", "zarr")
        self.out = Path(out)
        self.spec, self.prepared, self.tasks, self.digest = spec, prepared, list(tasks), digest
        self.flush_every, self.flush_seconds = max(1, int(flush_every)), float(flush_seconds)
        self._buffer: list[Outcome] = []
        self._oldest = 0.0
        self._seq = 0
        self.rows: dict[int, dict[str, Any]] = {}  #: task -> its part row (finished tasks)
        self.resumed = 0  #: tasks finished by earlier runs
        self.notes: list[str] = []  #: what was found damaged on opening, and what is done about it
        self._open(overwrite, retry_failed)

    # -- opening --------------------------------------------------------------
    def _header(self) -> dict[str, Any]:
        spec, prep = self.spec, self.prepared
        return {
            "format": FORMAT,
            "digest": self.digest,
            "title": spec.title,
            "spec": spec.origin,
            "target": spec.cosim.path.name if spec.cosim is not None else spec.experiment,
            "description": prep.description,
            "tasks": len(self.tasks),
            "axes": [[a.name, [list(v) if isinstance(v, tuple) else v for v in a.values]] for a in spec.axes],
            "seeds": None if spec.seeds is None else {"keys": list(spec.seeds.keys), "root": spec.seeds.root,
                                                     "parameters": list(spec.seeds.parameters),
                                                     "common": spec.seeds.common},
            "metrics": list(prep.metrics),
            "signals": {k: {"shape": list(s), "elements": list(e)} for k, (s, e) in prep.signals.items()},
        }

    def _clear(self) -> None:
        for name in _FILES:
            (self.out / name).unlink(missing_ok=True)
        for name in _DIRS:
            shutil.rmtree(self.out / name, ignore_errors=True)

    def _open(self, overwrite: bool, retry_failed: bool) -> None:
        import pyarrow.parquet as pq

        header_path = self.out / "sweep.json"
        existing = header_path.is_file() or (self.out / "parts").is_dir()
        if existing:
            try:
                old = json.loads(header_path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                old = {}
            if not isinstance(old, dict):
                old = {}
            if not old and not overwrite and self._parts_are_ours():
                # sweep.json damaged (truncated, ...), but the parts record this sweep's digest:
                # it is rewritten below and the finished tasks are kept
                self.notes.append("sweep.json was damaged; rewritten from the part files (their digest is this "
                                  "sweep's)")
                old = {"format": FORMAT, "digest": self.digest}
            if old.get("format") != FORMAT or old.get("digest") != self.digest:
                if not overwrite:
                    what = f"a different sweep ({old.get('spec', '?')}, digest {str(old.get('digest', '?'))[:12]}" \
                        if old else "unreadable sweep files ("
                    if not old:
                        raise SweepError(f"{self.out}: sweep.json is damaged and no part file says which sweep "
                                         f"this folder holds (this one: {self.digest[:12]}): choose another output "
                                         "folder, or overwrite them")
                    raise SweepError(f"{self.out} holds the results of {what}; this one: {self.digest[:12]}): "
                                     "choose another output folder, or overwrite them")
                self._clear()
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "parts").mkdir(exist_ok=True)
        header = self._header() | {"complete": False}
        self._write_json(header)
        known = {t.index for t in self.tasks}
        for part in sorted((self.out / "parts").glob("part-*.parquet")):
            self._seq = max(self._seq, int(part.stem.split("-")[1]))
            problem = self._check_part(part)
            if problem is not None:
                # set aside (not read again, kept for a look); its tasks are run again
                part.replace(part.with_name(f"damaged-{part.name}"))
                _sidecar(part).unlink(missing_ok=True)
                self.notes.append(f"{part.relative_to(self.out)} is damaged ({problem}); its tasks are run again")
                continue
            for row in pq.read_table(part).to_pylist():
                if row["task"] in known:  # a later part (a retried task) replaces an earlier one
                    self.rows[row["task"]] = row
        if retry_failed:
            self.rows = {i: r for i, r in self.rows.items() if r["status"] == "ok"}
        self._open_trajectories()
        self._check_trajectories()
        self.resumed = len(self.rows)

    def _parts_are_ours(self) -> bool:
        """Whether some intact part file records this sweep's digest."""
        import pyarrow.parquet as pq

        for part in sorted((self.out / "parts").glob("part-*.parquet")):
            if self._check_part(part) is None:
                meta = pq.read_schema(part).metadata or {}
                return meta.get(b"lpvest_sweep_digest", b"").decode() == self.digest
        return False

    @staticmethod
    def _check_part(part: Path) -> str | None:
        """Why ``part`` cannot be trusted (its SHA-256 is not the one recorded
        when it was written, or none was), or None."""
        try:
            recorded = _sidecar(part).read_text(encoding="ascii").strip()
        except OSError:
            return "no SHA-256 was recorded for it"
        if _sha256(part) != recorded:
            return "its SHA-256 differs from the one recorded when it was written"
        return None

    def _check_trajectories(self) -> None:
        """Each finished task's kept signals against the SHA-256 its part
        recorded; a task whose rows differ or cannot be read is run again (its
        chunk rewritten: NaN until then)."""
        if self.group is None:
            return
        import zarr

        ok = sorted(i for i, r in self.rows.items() if r.get("trajectory_sha256"))
        if not ok:
            return
        damaged: dict[int, str] = {}
        for name in self.prepared.signals:
            array = self.group[name]
            assert isinstance(array, zarr.Array)
            step = int(array.chunks[0])
            for start in range(0, len(self.tasks), step):
                members = [i for i in ok if start <= i < start + step]
                if not members:
                    continue
                try:
                    block = np.asarray(array[start:start + step])
                except Exception as exc:  # noqa: BLE001 - a damaged chunk fails in the codec, however it fails
                    for i in members:
                        damaged.setdefault(i, f"{name}: cannot be read ({type(exc).__name__})")
                    self._reset_chunk(array, start, step)
                    continue
                bad = [i for i in members if _rows_sha256(self.prepared.signals, {name: block[i - start]}, name)
                       != self.rows[i]["trajectory_sha256"].get(name)]
                for i in bad:
                    damaged.setdefault(i, f"{name}: its values differ from those written")
        if damaged:
            first = min(damaged)
            self.notes.append(f"trajectories.zarr: {len(damaged)} task(s) damaged (task {first}: {damaged[first]}); "
                              "they are run again")
            for i in damaged:
                del self.rows[i]

    def _reset_chunk(self, array: zarr.Array, start: int, step: int) -> None:
        """Delete the stored chunk (it reads as NaN again); the tasks it held are run again."""
        key = "/".join(["c", str(start // step), *(["0"] * (array.ndim - 1))])
        path = self.out / "trajectories.zarr" / array.path / Path(key)
        path.unlink(missing_ok=True)

    def _open_trajectories(self) -> None:
        import zarr

        self.group = None
        if not self.prepared.signals:
            return
        path = self.out / "trajectories.zarr"
        n = len(self.tasks)
        if path.exists():
            self.group = zarr.open_group(str(path), mode="r+")
            return
        group = zarr.open_group(str(path), mode="w")
        group.attrs.update({"format": FORMAT, "digest": self.digest, "tasks": n,
                            "note": "first axis: task index (summary.parquet column task); NaN: not run or failed"})
        for name, (shape, labels) in self.prepared.signals.items():
            per_task = int(np.prod(shape)) * 8
            chunk = int(min(max(1, (4 << 20) // max(per_task, 1)), n, 256))
            arr = group.create_array(name, shape=(n, *shape), chunks=(chunk, *shape), dtype="f8", fill_value=np.nan)
            arr.attrs.update({"elements": list(labels)})
        if self.prepared.time is not None:
            t = np.asarray(self.prepared.time, dtype=float)
            arr = group.create_array("time", shape=t.shape, chunks=t.shape, dtype="f8")
            arr[:] = t
        self.group = group

    def _write_json(self, data: Mapping[str, object]) -> None:
        path = self.out / "sweep.json"
        tmp = path.with_suffix(f".json.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(data, indent=1, default=str) + "\n", encoding="utf-8")
        tmp.replace(path)

    # -- writing --------------------------------------------------------------
    def pending(self) -> list[Task]:
        """Tasks no earlier run finished."""
        return [t for t in self.tasks if t.index not in self.rows]

    def add(self, outcome: Outcome) -> None:
        """Take one outcome; commit the batch when it is due. A task already
        finished is ignored (each task is recorded exactly once)."""
        if outcome.index in self.rows or any(o.index == outcome.index for o in self._buffer):
            return
        if outcome.result is not None:
            problem = self._check_result(outcome)
            if problem:
                outcome = Outcome(outcome.index, None, problem, outcome.seconds, outcome.worker)
        if not self._buffer:
            self._oldest = time.monotonic()
        self._buffer.append(outcome)
        if len(self._buffer) >= self.flush_every or time.monotonic() - self._oldest >= self.flush_seconds:
            self.flush()

    def _check_result(self, outcome: Outcome) -> str | None:
        r = outcome.result
        assert r is not None
        missing = [m for m in self.prepared.metrics if m not in r.metrics]
        if missing:
            return f"SweepError: the task returned no metric {missing[0]!r}"
        for name, (shape, _) in self.prepared.signals.items():
            if name not in r.signals:
                return f"SweepError: the task returned no signal {name!r}"
            if np.shape(r.signals[name]) != tuple(shape):
                return f"SweepError: signal {name!r} has shape {np.shape(r.signals[name])}; expected {tuple(shape)}"
        return None

    def flush(self) -> None:
        """Commit the buffered outcomes: trajectories, then a part file."""
        import pyarrow as pa
        import pyarrow.parquet as pq
        import zarr

        if not self._buffer:
            return
        batch = sorted(self._buffer, key=lambda o: o.index)
        good = [o for o in batch if o.result is not None]
        if self.group is not None and good:
            idx = np.array([o.index for o in good])
            for name, (shape, _) in self.prepared.signals.items():
                rows = np.stack([np.asarray(o.result.signals[name], dtype=float).reshape(shape)  # type: ignore[union-attr]  # good: result not None
                                 for o in good])
                array = self.group[name]
                assert isinstance(array, zarr.Array)  # written by this store: one array per kept signal
                array.oindex[(idx, *(slice(None),) * len(shape))] = rows
        cols: dict[str, ArrowObject] = {
            "task": pa.array([o.index for o in batch], pa.int64()),
            "status": pa.array(["ok" if o.ok else "error" for o in batch], pa.string()),
            "error": pa.array([o.error for o in batch], pa.string()),
            "seconds": pa.array([o.seconds for o in batch], pa.float64()),
            "worker": pa.array([o.worker for o in batch], pa.string()),
        }
        for m in self.prepared.metrics:
            cols[m] = pa.array([None if o.result is None else float(o.result.metrics[m]) for o in batch],
                               pa.float64())
        # what each task's kept signals were when written, checked when a rerun resumes
        if self.prepared.signals:
            cols["trajectory_sha256"] = pa.array(
                [None if o.result is None else
                 {name: _rows_sha256(self.prepared.signals, o.result.signals, name) for name in self.prepared.signals}
                 for o in batch], pa.struct([(name, pa.string()) for name in self.prepared.signals]))
        table = pa.table(cols).replace_schema_metadata({"lpvest_sweep_digest": self.digest})
        self._seq += 1
        path = self.out / "parts" / f"part-{self._seq:06d}.parquet"
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        pq.write_table(table, tmp)
        # the part's SHA-256 next to it, written before the part is (a part without one is not trusted)
        side = _sidecar(path)
        side_tmp = side.with_name(side.name + f".{os.getpid()}.tmp")
        side_tmp.write_text(_sha256(tmp) + "\n", encoding="ascii")
        side_tmp.replace(side)
        tmp.replace(path)
        for row in table.to_pylist():
            self.rows[row["task"]] = row
        self._buffer.clear()

    def summary_table(self) -> ArrowTable:
        """Every finished task in task order (see the module documentation)."""
        import pyarrow as pa

        spec = self.spec
        done = sorted(self.rows)
        by_index = {t.index: t for t in self.tasks}
        tasks = [by_index[i] for i in done]
        cols: dict[str, ArrowObject] = {"task": pa.array(done, pa.int64())}
        for a in spec.axes:
            cols[a.name] = pa.array([_axis_value(a, t.point[a.name]) for t in tasks], _arrow_type(a))
        if spec.seeds is not None:
            cols["seed"] = pa.array([t.seed for t in tasks], pa.int64())
            for p in spec.seeds.parameters:
                cols[p] = pa.array([t.seed_values[p] for t in tasks], pa.int64())
        for m in self.prepared.metrics:
            cols[m] = pa.array([self.rows[i][m] for i in done], pa.float64())
        cols["status"] = pa.array([self.rows[i]["status"] for i in done], pa.string())
        cols["error"] = pa.array([self.rows[i]["error"] for i in done], pa.string())
        return pa.table(cols).replace_schema_metadata({"lpvest_metrics": json.dumps(self.metric_definitions())})

    def metric_definitions(self) -> dict[str, dict[str, object]]:
        """Each metric column's definition, kept in the summary's schema
        metadata (``lpvest_metrics``, JSON): a co-simulation metric's kind, the
        recorded variables it reads (estimate, truth, ...) and its first row;
        an experiment's metric names the experiment that defines it."""
        spec = {m.name: m for m in self.spec.metrics}
        out: dict[str, dict[str, object]] = {}
        for name in self.prepared.metrics:
            m = spec.get(name)
            out[name] = ({"kind": m.kind, **dict(m.variables), "start": m.start} if m is not None
                         else {"experiment": str(self.spec.experiment)})
        return out

    def finish(self, *, complete: bool, seconds: float, engine: str) -> ArrowTable:
        """Commit what is buffered; write ``summary.parquet``, ``timing.parquet``
        and ``sweep.json``; return the summary table."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.flush()
        table = self.summary_table()
        for name, t in (("summary.parquet", table), ("timing.parquet", pa.table({
                "task": pa.array(sorted(self.rows), pa.int64()),
                "seconds": pa.array([self.rows[i]["seconds"] for i in sorted(self.rows)], pa.float64()),
                "worker": pa.array([self.rows[i]["worker"] for i in sorted(self.rows)], pa.string())}))):
            path = self.out / name
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            pq.write_table(t, tmp)
            tmp.replace(path)
        failed = sum(r["status"] != "ok" for r in self.rows.values())
        self._finished = self._header() | {
            "complete": complete and len(self.rows) == len(self.tasks),
            "finished": len(self.rows), "failed": failed, "resumed": self.resumed,
            "last_run": {"seconds": round(seconds, 3), "engine": engine}}
        self._write_json(self._finished)
        return table

    def mark_complete(self) -> None:
        """``sweep.json`` says complete: every task is written and so is what
        follows them (the figures). Only after :meth:`finish` with
        ``complete=False`` and every task finished."""
        self._write_json(self._finished | {"complete": len(self.rows) == len(self.tasks)})


def _sidecar(part: Path) -> Path:
    """``part-000001.parquet.sha256``: the part's SHA-256, recorded when it was written."""
    return part.with_name(part.name + ".sha256")


def _sha256(path: Path) -> str:
    import hashlib

    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def _rows_sha256(
    signals: Mapping[str, tuple[tuple[int, ...], tuple[str, ...]]], values: Mapping[str, ArrayLike], name: str
) -> str:
    """SHA-256 of one task's values of the kept signal ``name`` (float64, little-endian, C order)."""
    import hashlib

    shape = tuple(signals[name][0])
    data = np.ascontiguousarray(np.asarray(values[name], dtype="<f8").reshape(shape))
    return hashlib.sha256(data.tobytes()).hexdigest()
