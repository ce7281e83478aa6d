"""Per-step cost of the co-simulation against the same computation in-process; a script, not a test.

    .venv/bin/python benchmarks/bench_cosim.py [--steps 10000] [--repeat 3] [--fmus DIR]
                                               [--profile] [--out FILE.json]

The system: Peixoto et al. Example 1, the scheduler (``theta = sin(0.25 t)``),
the source (``w_k = sin(0.5 k) exp(-0.1 k)`` from ``k = 10``), the plant and
the parameter-dependent H-infinity filter (the design the FMU carries):

1. **co-simulation**: the four FMUs (``PeixotoEx1Scheduler``, ``...Source``,
   ``...Plant``, ``...HinfPD``) under :class:`lpvest.cosim.CoSimulation` with
   unit step, recording ``p``, ``w``, ``y``, ``z``, ``zhat`` and ``xf`` at every
   communication point; the time of :meth:`~lpvest.cosim.CoSimulation.run`
   only (unpacking and instantiation are reported apart);
2. **in-process**: the same streaming components of the library
   (:class:`lpvest.signals.SignalGenerator` for ``theta`` and ``w``,
   :class:`lpvest.systems.streaming.DiscretePlant`,
   :class:`lpvest.estimators.hinf.HinfFilter`) stepped in a plain Python loop
   that records the same values into a preallocated array: each component is
   stepped once per sample (``step`` returns the outputs of the sample), no
   extra work.

Both run in this one process, alternately, ``--repeat`` times; the best time
of each is reported, per step, with the ratio co-simulation / in-process
(target: at most 2). The two record the same numbers bit for bit (checked).
``--profile`` adds a cProfile listing of one co-simulation run (the FMUs'
Python code runs in this interpreter, so it shows up there).

The FMUs come from ``--fmus DIR`` (default ``fmu-build``, as written by
``lpvest build``); missing ones are built there first.
"""

from __future__ import annotations

import argparse
import json
import time
import zipfile
from pathlib import Path

import numpy as np

ROLES = ("Scheduler", "Source", "Plant", "HinfPD")
CONNECTIONS = [
    "sched.p -> plant.p",
    "src.w -> plant.w",
    "sched.p -> filter.p",
    "plant.y -> filter.y",
]
RECORD = ["sched.p", "src.w", "plant.y", "plant.z", "filter.zhat", "filter.xf"]


def fmu_paths(folder: Path) -> dict[str, Path]:
    paths = {role: folder / f"PeixotoEx1{role}.fmu" for role in ROLES}
    if not all(p.is_file() for p in paths.values()):
        from lpvest.fmi.build import build_fmus

        print(f"building the Peixoto Example 1 FMUs into {folder} ...")
        build_fmus(["peixoto-ex1"], folder)
    return paths


def cosimulation(paths: dict[str, Path], steps: int) -> tuple[np.ndarray, float, float]:
    """(recorded values (steps + 1, 9), set-up seconds, run seconds)."""
    from lpvest.cosim import Component, CoSimulation

    t0 = time.perf_counter()
    sim = CoSimulation(
        [Component("sched", paths["Scheduler"]), Component("src", paths["Source"]),
         Component("plant", paths["Plant"]), Component("filter", paths["HinfPD"])],
        CONNECTIONS, step_size=1.0, record=RECORD,
    )
    t1 = time.perf_counter()
    try:
        res = sim.run(steps, progress=False)
    finally:
        t2 = time.perf_counter()
        sim.close()
    names = [n for n in res.dtype.names if n != "time"]
    return np.column_stack([res[n] for n in names]), t1 - t0, t2 - t1


def in_process(design_json: str, steps: int) -> tuple[np.ndarray, float]:
    """(recorded values (steps + 1, 9), run seconds): the library's streaming
    components in a Python loop, the same signals as the FMUs' defaults."""
    from lpvest import load_system
    from lpvest.design import HinfDesign
    from lpvest.estimators.hinf import HinfFilter
    from lpvest.signals import SignalGenerator, SignalSpec
    from lpvest.systems.streaming import DiscretePlant

    plant_model = load_system("peixoto-ex1").model()
    theta = SignalGenerator(SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=0.25, offset=0.0))
    w = SignalGenerator(SignalSpec.build("decaying", 1, amplitude=1.0, omega=0.5, decay=0.1, onset=10.0, seed=1))
    plant = DiscretePlant(plant_model, x0=[0.0, 0.0])
    filt = HinfFilter(HinfDesign.from_json(design_json), simplex_map=plant_model.simplex_map)
    out = np.empty((steps + 1, 9))
    t0 = time.perf_counter()
    theta.start(0.0)
    w.start(0.0)
    for k in range(steps + 1):
        p, wk = theta.value, w.value
        po = plant.step({"p": p, "w": wk})
        fo = filt.step({"p": p, "y": po["y"]})
        row = out[k]
        row[0], row[1], row[2] = p[0], wk[0], po["y"][0]
        row[3:5] = po["z"]
        row[5:7] = fo["zhat"]
        row[7:9] = fo["xf"]
        theta.advance(k + 1.0)
        w.advance(k + 1.0)
    return out, time.perf_counter() - t0


def profile(paths: dict[str, Path], steps: int) -> None:
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.enable()
    cosimulation(paths, steps)
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(25)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=10_000, help="communication steps (default 10000)")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each side (default 3; the best counts)")
    parser.add_argument("--fmus", default="fmu-build", help="folder of the built FMUs (default fmu-build)")
    parser.add_argument("--profile", action="store_true", help="print a cProfile listing of one co-simulation")
    parser.add_argument("--out", help="write the measurements as JSON")
    args = parser.parse_args()

    paths = fmu_paths(Path(args.fmus))
    with zipfile.ZipFile(paths["HinfPD"]) as z:
        design_json = z.read("resources/design.json").decode()

    co_runs, co_setup, ip_runs = [], [], []
    co_out = ip_out = None
    for _ in range(args.repeat):
        co_out, setup, run = cosimulation(paths, args.steps)
        co_runs.append(run)
        co_setup.append(setup)
        ip_out, run = in_process(design_json, args.steps)
        ip_runs.append(run)
    assert co_out is not None and ip_out is not None
    identical = bool(np.array_equal(co_out, ip_out))
    n = args.steps + 1  # samples recorded (the last one without a step)
    co_us = min(co_runs) / n * 1e6
    ip_us = min(ip_runs) / n * 1e6
    ratio = co_us / ip_us
    print(f"Peixoto Example 1, scheduler + source + plant + HinfPD, {args.steps} steps, best of {args.repeat}")
    print(f"  co-simulation (4 FMUs, lpvest.cosim): {co_us:8.1f} us/step   (set-up {min(co_setup):.2f} s)")
    print(f"  in-process (library, Python loop):    {ip_us:8.1f} us/step")
    print(f"  ratio co-simulation / in-process:     {ratio:8.2f}   (target <= 2)")
    print(f"  identical results: {identical}" + ("" if identical else
          f" (largest difference {np.max(np.abs(co_out - ip_out)):.3g})"))
    if args.out:
        Path(args.out).write_text(json.dumps({
            "steps": args.steps, "repeat": args.repeat, "cosim_us_per_step": co_us, "inprocess_us_per_step": ip_us,
            "ratio": ratio, "cosim_setup_s": min(co_setup), "identical": identical,
            "cosim_runs_s": co_runs, "inprocess_runs_s": ip_runs,
        }, indent=2))
    if args.profile:
        profile(paths, args.steps)
    return 0 if identical else 1


if __name__ == "__main__":
    raise SystemExit(main())
