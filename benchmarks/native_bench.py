"""The native FMUs' side of bench_cosim.py and bench_kalman.py (a helper, not a script).

- :func:`build_native`: build native FMUs (``lpvest build --backend native``)
  into a folder, reusing the ones already there;
- :func:`step_times`: one native FMU stepped in a bare C host
  (``benchmarks/native_step.c``, compiled here with ``cc -O2``; no Python in
  that process): nanoseconds per sample of ``fmi2SetReal`` (every input) +
  ``fmi2DoStep`` + ``fmi2GetReal`` (every output), and of ``fmi2DoStep`` alone;
  :func:`host_run`: the same and the checksum of the outputs.
"""

from __future__ import annotations

import functools
import math
import shutil
import subprocess
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent


def build_native(sources: Sequence[str | Path], folder: Path, roles: Sequence[str] | None = None) -> dict[str, Path]:
    """The native FMUs of ``sources`` (example names or model files) in
    ``folder``, by identifier: built with the native backend when missing."""
    from lpvest.fmi._build import build_fmus, plan_system

    wanted = None if roles is None else set(roles)
    plans = [p for s in sources for p in plan_system(s)[0] if wanted is None or p.role in wanted]
    paths = {p.identifier: folder / f"{p.identifier}.fmu" for p in plans}
    if not all(p.is_file() for p in paths.values()):
        print(f"building {len(paths)} native FMU(s) into {folder} ...", flush=True)
        build_fmus(list(sources), folder, roles=roles, backend="native")
    return paths


@functools.cache
def _host() -> Path:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("the native step benchmark needs a C compiler (cc or gcc)")
    exe = Path(tempfile.mkdtemp(prefix="lpvest-bench-")) / "native_step"
    subprocess.run([cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(HERE / "native_step.c"),
                    "-ldl", "-lm"], check=True)
    return exe


def step_times(fmu: Path, steps: int = 100_000, repeat: int = 5) -> tuple[float, float]:
    """(ns per sample of set inputs + doStep + get outputs, ns per sample of
    doStep alone) for ``fmu`` in the C host, best of ``repeat``. Every input
    follows ``offset + amp sin(omega k)``: inside its declared range when it
    has one (the scheduling), ``sin(0.1 k)`` otherwise."""
    full, step, _ = host_run(fmu, steps, repeat)
    return full, step


def host_run(fmu: Path, steps: int = 100_000, repeat: int = 5) -> tuple[float, float, str]:
    """:func:`step_times` and the host's checksum of the outputs (the sum of
    every output over the set+step+get loop, as printed: 17 digits)."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    args = []
    for v in md.modelVariables:
        if v.causality == "input":
            lo, hi = (float(x) if x is not None else math.nan for x in (v.min, v.max))
            if math.isfinite(lo) and math.isfinite(hi):
                args.append(f"in:{v.valueReference}:{0.9 * (hi - lo) / 2!r}:0.25:{(hi + lo) / 2!r}")
            else:
                args.append(f"in:{v.valueReference}:1.0:0.1:0.0")
        elif v.causality == "output":
            args.append(f"out:{v.valueReference}")
    h = md.defaultExperiment.stepSize if md.defaultExperiment and md.defaultExperiment.stepSize else "1.0"
    with tempfile.TemporaryDirectory(prefix="lpvest-bench-fmu-") as tmp:
        with zipfile.ZipFile(fmu) as z:
            z.extractall(tmp)
        ident = md.coSimulation.modelIdentifier
        lib = Path(tmp) / "binaries" / "linux64" / f"{ident}.so"
        cmd = [str(_host()), str(lib), md.guid, (Path(tmp) / "resources").as_uri(), str(steps), str(repeat), str(h),
               *args]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True, env={}).stdout
    line = next(x for x in out.splitlines() if x.startswith("BENCH "))
    full, step, checksum = line.split()[1:4]
    return float(full), float(step), checksum
