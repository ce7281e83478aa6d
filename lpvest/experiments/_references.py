"""Regression references: small stored trajectories of each example's co-simulation.

Each :class:`Reference` is a short version of an experiment's co-simulation
(the same :class:`~lpvest.experiments.CoSimSpec` builder, fewer steps or
filters) and a few of its recorded outputs, stored as CSV in
``tests/data/reference/<name>.csv`` (a few hundred rows). The regression test
(``tests/test_regression.py``) builds the FMUs, co-simulates and compares every
column with the reference within ``tolerance * max |reference column|``; the
reason for each tolerance is stored in the file's header and in
:data:`REFERENCES`. The H-infinity filter FMUs carry the designs stored with
the example systems (``models/designs/``: data, not solved again), so their
references are as tight as the other numpy-only filters; each such reference
also stores the SHA-256 of the design its filter FMU carries.

Regenerate the references (after a deliberate change) with::

    lpvest regress --update                     # or: python -m lpvest.experiments --update

and compare without writing with ``lpvest regress``.

Examples
--------
>>> [r.name for r in REFERENCES]
['cox-toth-example1', 'cox-toth-truncation', 'peixoto-table1', 'peixoto-fig1', 'peixoto-example2', 'sridhar-ltv']
>>> checks = regress(["peixoto-table1"], fmus="out/fmu-cache")  # doctest: +SKIP
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core._errors import LpvestError, abbreviate, one_line, shorten
from ..core._interrupt import Interrupted, exit_status, handling_signals, hold
from ._fmus import CoSimSpec, ExperimentFmus, as_experiment_fmus

__all__ = [
    "Reference",
    "REFERENCES",
    "ColumnCheck",
    "reference_dir",
    "simulate_reference",
    "write_reference",
    "RegressInterrupted",
    "read_reference",
    "check_reference",
    "regress",
    "add_arguments",
    "main",
]

#: The command that regenerates the references (written into every file).
UPDATE_COMMAND = "lpvest regress --update"

_NUMERIC = ("numpy-only, stable discrete-time recursions with seeded noise: another BLAS kernel or platform rounds "
            "each step's sums of <= 6 products differently (<= 12 eps of their size), amplified by cond(Omega_t) "
            "<= 2.6 in the filters over their memory (the closed loop contracts: ~8 steps) and accumulated over at "
            "most the 200 steps in the plant: <= 4e-12 of scale (tests/tolerances.py); the file keeps 12 "
            "significant digits (<= 5e-12 of scale); 1e-10 is ten times both and still catches any change of "
            "model, signal, noise convention or filter")
_DESIGN = ("the filter FMUs carry the LMI designs stored in models/designs (data: the same matrices on every "
           "machine, never solved again), so the filter is a stable numpy recursion like the others: "
           + _NUMERIC[_NUMERIC.index("another BLAS"):]
           + "; the SHA-256 of each carried design is stored too")
_LTV = ("the plant integrates with scipy's DOP853 (rtol 1e-12, one integration kept from step to step) and the "
        "observer solves least-squares problems whose estimates move by ~1e-7 relative for a 1e-13 relative change "
        "of y, ~1e-5 for 2e-12 (measured, the second when the plant's integration changed): rounding in another "
        "LAPACK or summation order changes the plant at ~1e-14 of scale and the estimates at ~1e-8; 1e-7 of scale "
        "covers that and catches any change of the model, the kernel identity or the window logic (a change of "
        "the integration itself, e.g. its steps, moves the estimates by more: regenerate then)")


@dataclass(frozen=True)
class Reference:
    """One stored reference: which co-simulation, which columns, how close."""

    name: str
    title: str
    spec: Callable[[], CoSimSpec]
    columns: tuple[str, ...]  #: recorded variables (``"plant.y[1]"``)
    tolerance: float  #: allowed ``max |got - ref|`` as a fraction of ``max |ref|`` (per column)
    reason: str
    every: int = 1  #: keep every ``every``-th row
    designs: tuple[str, ...] = ()  #: filter components whose carried design (its SHA-256) is stored

    @property
    def filename(self) -> str:
        return f"{self.name}.csv"


def _example1() -> CoSimSpec:
    from ._cox_toth import example1_cosim

    return example1_cosim(200)


def _truncation() -> CoSimSpec:
    from ._cox_toth import truncation_cosim

    return truncation_cosim(200, taus=(2,))


def _table1() -> CoSimSpec:
    from ._peixoto import hinf_cosim

    return hinf_cosim([("pd", "PeixotoEx1HinfPD"), ("robust", "PeixotoEx1HinfRobust")])


def _fig1() -> CoSimSpec:
    from ._peixoto import hinf_cosim

    return hinf_cosim([("theorem1", "PeixotoEx1HinfPDEps150"), ("corollary1", "PeixotoEx1HinfRobustEps150")])


def _example2() -> CoSimSpec:
    from ._peixoto import example2_cosim

    return example2_cosim((1.0, 21.0))


def _sridhar() -> CoSimSpec:
    from ._sridhar import sridhar_cosim

    # 6 basis functions per 0.4 s window: a well-conditioned fit (a 1e-13
    # relative change of y moves a0 by ~1e-7 relative, so rounding moves it by
    # ~1e-10). With 18 per 0.4 s the same change moves a0 by ~7e-5: such a
    # reference would hold rounding noise, reproducible on one machine only.
    return sridhar_cosim(2.0, window=0.4, hop=0.1, n_basis=6)


#: The references, one per example's co-simulation.
REFERENCES: tuple[Reference, ...] = (
    Reference("cox-toth-example1", "Example 1: Scheduler, Source, Plant (21c), 200 samples", _example1,
              ("source.u[1]", "plant.y[1]"), 1e-10, _NUMERIC),
    Reference("cox-toth-truncation", "truncation model: Plant, Kalman, TruncatedKalman (tau = 2), 200 samples",
              _truncation, ("plant.y[1]", "kalman.xhat[1]", "trunc2.K[1,1]"), 1e-10, _NUMERIC),
    Reference("peixoto-table1", "Example 1, best-epsilon HinfPD and HinfRobust FMUs, Figs. 1-2 scenario", _table1,
              ("plant.z[1]", "pd.zhat[1]", "robust.zhat[1]"), 1e-10, _DESIGN, designs=("pd", "robust")),
    Reference("peixoto-fig1", "Example 1, epsilon = 150 filter FMUs (Fig. 1)", _fig1,
              ("theorem1.zhat[1]", "theorem1.zhat[2]", "corollary1.zhat[1]"), 1e-10, _DESIGN,
              designs=("theorem1", "corollary1")),
    Reference("peixoto-example2", "Example 2 at rho = 1 and 21: Plant and HinfPD FMUs", _example2,
              ("plant_rho1.z[1]", "pd_rho1.zhat[1]", "pd_rho21.zhat[1]"), 1e-10, _DESIGN,
              designs=("pd_rho1", "pd_rho21")),
    Reference("sridhar-ltv",
              "LTV plant and B-spline observer FMUs (window 0.4 s, 6 splines, hop 0.1 s), 2 s, every 10 ms",
              _sridhar, ("plant.y[1]", "observer.a0[1]", "observer.a1[1]"), 1e-7, _LTV, every=10),
)


def reference_dir() -> Path:
    """``tests/data/reference`` of the source checkout lpvest runs from."""
    path = Path(__file__).resolve().parent.parent.parent / "tests" / "data" / "reference"
    if not path.parent.is_dir():
        raise LpvestError(f"no source checkout around lpvest ({path.parent} does not exist): give --dir")
    return path


def _design_digest(path: Path) -> str:
    import hashlib
    import zipfile

    with zipfile.ZipFile(path) as z:
        return hashlib.sha256(z.read("resources/design.json")).hexdigest()


def simulate_reference(ref: Reference, fmus: ExperimentFmus) -> tuple[np.ndarray, dict[str, str]]:
    """Run the reference's co-simulation: the kept rows ``(time, columns...)``
    and the SHA-256 of the design each design-carrying filter component carries."""
    spec = ref.spec()
    res = spec.run(fmus, progress=False)
    missing = [c for c in ref.columns if c not in (res.dtype.names or ())]
    if missing:
        raise LpvestError(f"reference {ref.name}: the co-simulation records no {', '.join(missing)}")
    data = np.column_stack([res["time"], *(res[c] for c in ref.columns)])[:: ref.every]
    idents = {name: ident for name, ident, _ in spec.components}
    designs = {name: _design_digest(fmus.path(idents[name])) for name in ref.designs}
    return data, designs


def _csv_row(fields: Sequence[str]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="").writerow(fields)
    return buf.getvalue()


def write_reference(ref: Reference, data: np.ndarray, designs: dict[str, str], directory: str | Path) -> Path:
    """Write ``directory/<name>.csv``: comment lines (what, tolerance, reason,
    carried designs, how to regenerate), the column names, then the rows (12 significant digits)."""
    from .._version import __version__

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / ref.filename
    lines = [
        f"# lpvest regression reference {ref.name}: {ref.title}",
        f"# co-simulation: {ref.spec().describe()}; every {ref.every} row(s) kept",
        f"# tolerance: {ref.tolerance:g} of max |column|: {ref.reason}",
        *(f"# design {name} = sha256:{d}" for name, d in designs.items()),
        f"# written by lpvest {__version__}; regenerate with: {UPDATE_COMMAND}",
        _csv_row(("time", *ref.columns)),  # matrix elements hold commas: quoted
    ]
    lines += [",".join(f"{v:.12g}" for v in row) for row in data]
    # whole or not at all: an interruption (or a full disk) leaves the earlier file as it was
    partial = path.with_name(f".{path.name}.part")
    try:
        partial.write_text("\n".join(lines) + "\n", encoding="utf-8")
        hold("reference-part")  # the interruption tests' hook; nothing otherwise
        partial.replace(path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    return path


def read_reference(path: str | Path) -> tuple[list[str], np.ndarray, dict[str, str]]:
    """Column names, rows and stored design digests of a reference file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise LpvestError(f"{path}: cannot read the reference ({exc.strerror}); create it with "
                          f"{UPDATE_COMMAND}") from exc
    designs = {}
    body = []
    for line in text:
        if line.startswith("# design "):
            name, _, value = line[len("# design "):].partition(" = ")
            designs[name] = value.removeprefix("sha256:")
        elif line and not line.startswith("#"):
            body.append(line)
    columns = next(csv.reader([body[0]]))
    data = np.array([[float(v) for v in row.split(",")] for row in body[1:]])
    return columns, data, designs


@dataclass(frozen=True)
class ColumnCheck:
    """One column (or one carried design: difference 0 when it is the stored one) against its reference."""

    name: str
    max_abs_difference: float
    scale: float
    tolerance: float

    @property
    def ok(self) -> bool:
        return self.max_abs_difference <= self.tolerance * (self.scale if self.scale > 0 else 1.0)

    def line(self) -> str:
        return (f"{self.name}: max |difference| {self.max_abs_difference:.2e}, max |reference| {self.scale:.3g}, "
                f"tolerance {self.tolerance:g} -> " + ("ok" if self.ok else "FAIL"))


def check_reference(ref: Reference, data: np.ndarray, designs: dict[str, str],
                    directory: str | Path) -> list[ColumnCheck]:
    """Compare a fresh co-simulation with the stored reference."""
    columns, stored, stored_designs = read_reference(Path(directory) / ref.filename)
    want = ["time", *ref.columns]
    if columns != want or stored.shape != data.shape:
        raise LpvestError(f"reference {ref.name}: stored columns {columns} and shape {stored.shape}; the "
                          f"co-simulation gives {want} and {data.shape} (regenerate with {UPDATE_COMMAND})")
    checks = []
    for j, name in enumerate(want):
        ref_col = stored[:, j]
        diff = np.abs(data[:, j] - ref_col)
        worst = float(np.max(diff)) if np.all(np.isfinite(diff)) else float("inf")
        # times k h with a short decimal h: printed exactly by %.12g, off by the
        # rounding of k h (~eps of the largest time) only
        tol = 1e-12 if name == "time" else ref.tolerance
        checks.append(ColumnCheck(name, worst, float(np.max(np.abs(ref_col))), tol))
    for name, digest in designs.items():
        if name not in stored_designs:
            raise LpvestError(f"reference {ref.name}: no stored design for {name} (regenerate with {UPDATE_COMMAND})")
        same = digest == stored_designs[name]
        checks.append(ColumnCheck(f"design {name} (sha256 {digest[:12]}...)", 0.0 if same else float("inf"), 1.0,
                                  0.0))
    return checks


class RegressInterrupted(Interrupted):
    """``Ctrl-C`` or SIGTERM stopped :func:`regress`. Every reference file is
    whole: one being rewritten keeps its earlier contents (it is written
    beside and renamed into place), and comparing writes nothing.

    Parameters
    ----------
    done : sequence of str
        The references rewritten (``update``) or compared before the signal, in order.
    names : sequence of str
        Every reference of the run.
    folder : Path
        The reference folder.
    update : bool
        The run rewrote the references (``--update``) rather than compared them.
    failed : sequence of str
        The compared references that failed.
    signum : int
        The signal (SIGINT: Ctrl-C; SIGTERM); the command line exits with ``128 + signum``.
    """

    def __init__(self, done: Sequence[str], names: Sequence[str], folder: Path, *, update: bool,
                 failed: Sequence[str] = (), signum: int) -> None:
        super().__init__(signum)
        self.done, self.names, self.folder = tuple(done), tuple(names), folder
        self.update, self.failed = update, tuple(failed)

    def __str__(self) -> str:
        n, total = len(self.done), len(self.names)
        shown = ", ".join(self.done[:3]) + (f" and {n - 3} more" if n > 3 else "")
        if self.update:
            kept = (f"rewrote {n} of {total} reference file(s) in {shorten(str(self.folder), 80)}"
                    + (f" ({shown})" if n else "") + "; every file is whole, the others keep their earlier "
                    "contents; run the same command again to rewrite them all")
        else:
            verdict = f", {len(self.failed)} failed ({', '.join(self.failed)})" if self.failed else ""
            kept = (f"compared {n} of {total} reference(s)" + (f" ({shown}{verdict})" if n else "")
                    + "; nothing was written; run the same command again to compare them all")
        return kept


def regress(
    names: Sequence[str] = (),
    *,
    update: bool = False,
    directory: str | Path | None = None,
    fmus: ExperimentFmus | str | Path | None = None,
    echo: Callable[[str], None] = print,
) -> int:
    """Compare the references ``names`` (default: all) with fresh co-simulations,
    or rewrite them (``update``); returns the exit status (1: a comparison failed).
    SIGINT or SIGTERM (within :func:`lpvest.core.handling_signals`, as on the
    command line; a plain ``KeyboardInterrupt`` too) raises
    :class:`RegressInterrupted`, which says what was kept."""
    folder = Path(directory) if directory else reference_dir()
    cache = as_experiment_fmus(fmus)
    unknown = set(names) - {r.name for r in REFERENCES}
    if unknown:
        raise LpvestError(f"no reference {abbreviate(sorted(unknown)[0], 30)} (known: "
                          f"{', '.join(r.name for r in REFERENCES)})")
    selected = [r for r in REFERENCES if not names or r.name in names]
    if not update:  # refused before any FMU is built or co-simulated
        if not folder.is_dir():
            raise LpvestError(f"no reference folder {shorten(str(folder), 80)} (write one with {UPDATE_COMMAND} "
                              f"--dir FOLDER)")
        missing = [r.filename for r in selected if not (folder / r.filename).is_file()]
        if missing:
            raise LpvestError(f"{shorten(str(folder), 80)}: no reference file {missing[0]} ({len(missing)} of "
                              f"{len(selected)} missing; write them with {UPDATE_COMMAND})")
    failed: list[str] = []
    done: list[str] = []
    try:
        for ref in selected:
            data, designs = simulate_reference(ref, cache)
            if update:
                path = write_reference(ref, data, designs, folder)
                done.append(ref.name)
                echo(f"wrote {path} ({data.shape[0]} rows, {path.stat().st_size / 1024:.1f} KiB)")
                hold("reference-written")  # the interruption tests' hook; nothing otherwise
                continue
            checks = check_reference(ref, data, designs, folder)
            ok = all(c.ok for c in checks)
            done.append(ref.name)
            echo(f"{ref.name}: " + ("ok" if ok else "FAIL"))
            for c in checks:
                echo(f"  {c.line()}")
            if not ok:
                failed.append(ref.name)
    except KeyboardInterrupt as exc:
        raise RegressInterrupted(done, [r.name for r in selected], folder, update=update, failed=failed,
                                 signum=exit_status(exc) - 128) from None
    if failed:
        echo(f"regression failures: {', '.join(failed)} (after a deliberate change: {UPDATE_COMMAND})")
        return 1
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lpvest regress`` (and of this module's ``main``)."""
    parser.add_argument("names", nargs="*", help="references to run (default: all)")
    parser.add_argument("--update", action="store_true", help="rewrite the reference files from a fresh run")
    parser.add_argument("--dir", help="reference folder (default: tests/data/reference of the source checkout)")
    parser.add_argument("--fmus", metavar="DIR",
                        help="FMU cache folder (default: $LPVEST_FMU_CACHE or ~/.cache/lpvest/fmus)")
    parser.add_argument("--quiet", action="store_true", help="no FMU build lines (results and errors only)")


#: The program name of :func:`main`'s messages.
PROG = "python -m lpvest.experiments._references"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m lpvest.experiments._references [--update] [--dir DIR] [--fmus DIR] [NAME...]``:
    :func:`regress` as ``lpvest regress`` runs it, for a checkout without the command.
    Its exit status: 0, 1 (a comparison failed), 2 (a one-line error), 130/143
    (SIGINT/SIGTERM: one line says what was kept, as the command line does)."""
    parser = argparse.ArgumentParser(prog=PROG, description="Compare (or --update) the stored regression "
                                                            "references.")
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        with handling_signals():  # Ctrl-C and SIGTERM raise Interrupted (exit 130, 143)
            cache = as_experiment_fmus(args.fmus)
            if not args.quiet:
                cache.progress = lambda msg: print(msg, file=sys.stderr, flush=True)
            return regress(args.names, update=args.update, directory=args.dir, fmus=cache)
    except (LpvestError, OSError) as exc:  # the user's input, or a file the system refuses
        print(f"{PROG}: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except RegressInterrupted as exc:  # what was rewritten or compared, how to go on: one line
        print(f"{PROG}: interrupted ({exc.name}): {exc}", file=sys.stderr)
        return exit_status(exc)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
