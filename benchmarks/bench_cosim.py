"""Per-step cost of lpvest's streaming components and FMUs against minimal numpy loops; a script, not a test.

    .venv/bin/python benchmarks/bench_cosim.py [--steps 10000] [--repeat 3] [--fmus DIR]
                                               [--native-fmus DIR] [--profile] [--out FILE.json]

The system: Peixoto et al. Example 1, the scheduler (``theta = sin(0.25 t)``),
the source (``w_k = sin(0.5 k) exp(-0.1 k)`` from ``k = 10``), the plant and
the parameter-dependent H-infinity filter (the design the FMU carries), run
four ways, each recording ``p``, ``w``, ``y``, ``z``, ``zhat`` and ``xf`` at
every sample:

0. **minimal loop** (the reference): the same equations written for this
   benchmark in plain numpy, no checks, no ports, no dictionaries: the
   weights ``alpha = ((1 - theta)/2, (1 + theta)/2)``, the six plant matrices
   and the five filter matrices at ``alpha``, ``y, z``, ``zhat``, one solve
   with ``H(alpha)``, the next states;
1. **in-process**: lpvest's streaming components
   (:class:`lpvest.core._signals.SignalGenerator` for ``theta`` and ``w``,
   :class:`lpvest.systems._streaming.DiscretePlant`,
   :class:`lpvest.estimators._hinf.HinfFilter`) stepped in a plain Python loop;
2. **co-simulation**: the four FMUs (``PeixotoEx1Scheduler``, ``...Source``,
   ``...Plant``, ``...HinfPD``) under :class:`lpvest.cosim.CoSimulation` with
   unit step (the time of :meth:`~lpvest.cosim.CoSimulation.run` only);
3. **libcosim**: the same four FMUs connected in a libcosim execution (Jacobi
   stepping, so other numbers: only its time per step is reported), in a
   subprocess, in two configurations: **serial**, the FMUs stepped in the
   calling thread (``numWorkerThreads="0"`` on the fixed-step algorithm of an
   SSD, :data:`LIBCOSIM_CONFIGS` says why), the one the target is for; and
   **pool**, libcosimpy's default (``CosimExecution.from_step_size``: a pool of
   worker threads), for the record, which ``lpvest.cosim.write_ssp(...,
   worker_threads=None)`` gives too; ``write_ssp``'s default is serial. Both
   record the same values (checked).

Rows 2 and 3 run with the pythonfmu FMUs and with the native ones
(``lpvest build --backend native``: C, no Python in the step). libcosim also
runs four copies of a trivial foreign C FMU (``tests/data/foreign/all_types.c``,
unconnected) in both configurations: libcosim's own cost per step, which no
FMU can go below. Each native FMU is also stepped
alone in a bare C host (``benchmarks/native_step.c``): set inputs, doStep,
get outputs, and doStep alone.

And the Kalman filter alone: :class:`lpvest.estimators.kalman.LPVKalmanFilter`
stepped on the Cox & Toth truncation model against a minimal numpy step of
(4a)-(4e) that computes the same outputs (filtered and predicted moments,
innovation, gain, innovation covariance, log-likelihood).

Everything runs in this one process (libcosim in subprocesses), alternately, ``--repeat`` times; the
best time of each is reported per step, with the ratios to the minimal loop
(issue targets: in-process <= 2, co-simulation <= 4, Kalman step <= 1.5;
native FMUs: co-simulation <= 1, libcosim <= 0.25, HinfPD doStep in the C
host <= 0.5 us).
The in-process and co-simulation runs record the same numbers bit for bit,
the minimal loops agree with them to rounding (checked). ``--profile`` adds
a cProfile listing of one co-simulation run (the FMUs' Python code runs in
this interpreter, so it shows up there).

The FMUs come from ``--fmus DIR`` (default ``fmu-build``, as written by
``lpvest build``) and ``--native-fmus DIR`` (default ``fmu-build-native``,
``lpvest build --backend native``); missing ones are built there first.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

ROLES = ("Scheduler", "Source", "Plant", "HinfPD")
CONNECTIONS = [
    "sched.p -> plant.p",
    "src.w -> plant.w",
    "sched.p -> filter.p",
    "plant.y -> filter.y",
]
RECORD = ["sched.p", "src.w", "plant.y", "plant.z", "filter.zhat", "filter.xf"]


def fmu_paths(folder: Path, backend: str = "pythonfmu") -> dict[str, Path]:
    # absolute: libcosim's run names each FMU by a file URI, which a relative path cannot be
    folder = folder.resolve()
    paths = {role: folder / f"PeixotoEx1{role}.fmu" for role in ROLES}
    if not all(p.is_file() for p in paths.values()):
        from lpvest.fmi._build import build_fmus

        print(f"building the Peixoto Example 1 FMUs ({backend}) into {folder} ...")
        build_fmus(["peixoto-ex1"], folder, backend=backend)
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
    from lpvest.core._signals import SignalGenerator, SignalSpec
    from lpvest.design import HinfDesign
    from lpvest.estimators._hinf import HinfFilter
    from lpvest.systems._streaming import DiscretePlant

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


def minimal_loop(design_json: str, steps: int) -> tuple[np.ndarray, float]:
    """(recorded values (steps + 1, 9), run seconds): the same equations in plain
    numpy, written for this benchmark (no checks, no ports, no dictionaries)."""
    from lpvest import load_system

    v = load_system("peixoto-ex1").model().vertices
    d = json.loads(design_json)["filter"]
    A, Bw, Cz, Dz, Cy, Dy = (np.array(getattr(v, n)) for n in ("A", "Bw", "Cz", "Dz", "Cy", "Dy"))
    H, Af, Bf, Cf, Df = (np.array(d[n]) for n in ("H", "Af", "Bf", "Cf", "Df"))
    sin, exp = np.sin, np.exp
    x = np.zeros(A.shape[1])
    xf = np.zeros(H.shape[1])
    out = np.empty((steps + 1, 9))
    t0 = time.perf_counter()
    for k in range(steps + 1):
        th = sin(0.25 * k)
        a0, a1 = 0.5 * (1.0 - th), 0.5 * (1.0 + th)
        wk = sin(0.5 * k) * exp(-0.1 * k) if k >= 10 else 0.0
        y = (a0 * Cy[0] + a1 * Cy[1]) @ x + (a0 * Dy[0] + a1 * Dy[1])[:, 0] * wk
        z = (a0 * Cz[0] + a1 * Cz[1]) @ x + (a0 * Dz[0] + a1 * Dz[1])[:, 0] * wk
        zhat = (a0 * Cf[0] + a1 * Cf[1]) @ xf + (a0 * Df[0] + a1 * Df[1]) @ y
        row = out[k]
        row[0], row[1], row[2] = th, wk, y[0]
        row[3:5] = z
        row[5:7] = zhat
        row[7:9] = xf
        xf = np.linalg.solve(a0 * H[0] + a1 * H[1], (a0 * Af[0] + a1 * Af[1]) @ xf + (a0 * Bf[0] + a1 * Bf[1]) @ y)
        x = (a0 * A[0] + a1 * A[1]) @ x + (a0 * Bw[0] + a1 * Bw[1])[:, 0] * wk
    return out, time.perf_counter() - t0


def kalman_steps(steps: int) -> tuple[float, float, float]:
    """(lpvest seconds, minimal seconds, largest difference of xhat): the exact
    filter on the Cox & Toth truncation model, one step per sample."""
    from lpvest import load_system
    from lpvest.estimators.kalman import LPVKalmanFilter

    model = load_system("cox-toth-truncation").model()
    k = np.arange(steps)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=1).y
    kf = LPVKalmanFilter(model)
    samples = [{"p": p[i], "u": u[i], "y": y[i]} for i in range(steps)]
    t0 = time.perf_counter()
    lib = [kf.step(s)["xhat"] for s in samples]
    t_lib = time.perf_counter() - t0

    # the minimal step: matrices affine in p (the model's basis is [1, p]), (4a)-(4e) with S
    dep = model.dependence
    assert dep.term_names == ("1", "p")
    stacks = {n: np.array(dep.coefficients[n]) for n in ("A", "B", "C", "D", "G", "H")}
    Q, R, S = model.noise.Q, model.noise.R, model.noise.S
    x, P = model.x0.copy(), model.P0.copy()
    half_log_2pi = 0.5 * y.shape[1] * np.log(2 * np.pi)
    loglik = 0.0
    mine = []
    t0 = time.perf_counter()
    for i in range(steps):
        pi = p[i, 0]
        Am, Bm, Cm, Dm, Gm, Hm = (stacks[n][0] + pi * stacks[n][1] for n in ("A", "B", "C", "D", "G", "H"))
        e = y[i] - Cm @ x - Dm @ u[i]
        PC = P @ Cm.T
        Om = Cm @ PC + Hm @ R @ Hm.T
        Oinv = np.linalg.inv(Om)  # n_y x n_y: the leanest numpy way
        K = (Am @ PC + Gm @ S @ Hm.T) @ Oinv
        Lf = PC @ Oinv
        xhat = x + Lf @ e
        Pf = P - Lf @ PC.T
        loglik -= half_log_2pi + 0.5 * (np.linalg.slogdet(Om)[1] + e @ Oinv @ e)
        x = Am @ x + Bm @ u[i] + K @ e
        P = Am @ P @ Am.T + Gm @ Q @ Gm.T - K @ Om @ K.T
        P = 0.5 * (P + P.T)
        mine.append(xhat)
        del Pf
    t_min = time.perf_counter() - t0
    return t_lib, t_min, float(np.max(np.abs(np.array(lib) - np.array(mine))))


#: The libcosim runs' connections (instance names are the roles) and recorded outputs.
LIBCOSIM_LINKS = [("Scheduler", "p[1]", "Plant", "p[1]"), ("Scheduler", "p[1]", "HinfPD", "p[1]"),
                  ("Source", "w[1]", "Plant", "w[1]"), ("Plant", "y[1]", "HinfPD", "y[1]")]
LIBCOSIM_RECORD = [("Scheduler", "p[1]"), ("Source", "w[1]"), ("Plant", "y[1]"), ("Plant", "z[1]"), ("Plant", "z[2]"),
                   ("HinfPD", "zhat[1]"), ("HinfPD", "zhat[2]"), ("HinfPD", "xf[1]"), ("HinfPD", "xf[2]")]

#: libcosim's fixed-step algorithm as libcosimpy 0.0.6 creates it (``from_step_size``) steps the
#: FMUs on a pool of ``hardware_concurrency() - 1`` worker threads: every step queues one task per
#: FMU and waits on a condition variable, about 5 us of wake-ups per FMU and step on a 2-core
#: virtual machine (four trivial FMUs: 22 us per step) against 0.1 to 0.5 us of work in a native
#: FMU. libcosimpy has no argument for the pool's size, but an SSD read by
#: ``CosimExecution.from_ssp_file`` (no step size given) may set the algorithm's
#: ``numWorkerThreads``, and with 0 libcosim steps every FMU in the calling thread
#: (``utility::thread_pool::submit`` runs the task directly when the pool has no threads): the
#: same Jacobi stepping and the same numbers (checked), a twentieth of the time here.
#: :func:`lpvest.cosim.write_ssp` declares ``numWorkerThreads="0"`` by default (``worker_threads``);
#: this benchmark writes its own bare SSD instead, because the trivial FMUs (``AllTypes``) have an
#: Enumeration output, which ``write_ssp`` lists as a connector and libcosim's SSP parser aborts on,
#: and so that both configurations connect the same FMUs the same way (no bound parameters, no
#: ``measurement_delay``).
LIBCOSIM_CONFIGS = ("serial", "pool")

_LIBCOSIM_RUN = """
import json, sys, tempfile, time
from pathlib import Path
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave
log_output_level(CosimLogLevel.ERROR)
fmus, links, record, config, steps = json.loads(sys.argv[1])


def execution():
    if config == "serial":
        with tempfile.TemporaryDirectory(prefix="lpvest-bench-ssd-") as tmp:  # read when the execution is made
            ssd = Path(tmp) / "SystemStructure.ssd"
            elements = "".join(f'<ssd:Component name="{name}" source="{Path(p).as_uri()}"/>'
                               for name, p in fmus.items())
            ssd.write_text(
                '<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
                'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
                'xmlns:osp="https://opensimulationplatform.com/SSP/OSPAnnotations" name="bench" version="1.0">'
                f'<ssd:System name="bench"><ssd:Elements>{elements}</ssd:Elements></ssd:System>'
                '<ssd:DefaultExperiment><ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">'
                '<osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="1" numWorkerThreads="0"/></osp:Algorithm>'
                '</ssc:Annotation></ssd:Annotations></ssd:DefaultExperiment></ssd:SystemStructureDescription>')
            ex = CosimExecution.from_ssp_file(tmp)
        idx = {name: ex.slave_index_from_instance_name(name) for name in fmus}
    else:
        ex = CosimExecution.from_step_size(step_size=int(1e9))
        idx = {name: ex.add_local_slave(CosimLocalSlave(fmu_path=p, instance_name=name)) for name, p in fmus.items()}
    refs = {name: {v.name.decode(): v.reference for v in ex.slave_variables(i)} for name, i in idx.items()}
    for src, out, dst, inp in links:
        ex.connect_real_variables(idx[src], refs[src][out], idx[dst], refs[dst][inp])
    return ex, idx, refs


# the values: the first 40 steps, with an observer, in an execution of their own
ex, idx, refs = execution()
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
values = []
for _ in range(40):
    ex.step(1)
    values += [obs.last_real_values(idx[name], [refs[name][v]])[0] for name, v in record]
print("VALUES", json.dumps(values))
# the time: no observer
ex, idx, refs = execution()
ex.step(10)
t = time.perf_counter()
ex.step(steps)
print("RESULT", (time.perf_counter() - t) / steps)
"""


def libcosim_per_step(fmus: dict[str, Path], steps: int, config: str,
                      links: list[tuple[str, str, str, str]] = LIBCOSIM_LINKS,
                      record: list[tuple[str, str]] = LIBCOSIM_RECORD) -> tuple[float, list[float]]:
    """(seconds per step, the ``record`` values after each of the first 40
    steps) of the FMUs ``fmus`` (instance name -> file) with the connections
    ``links`` in a libcosim execution, in a subprocess; ``config``:
    ``"serial"`` or ``"pool"`` (see :data:`LIBCOSIM_CONFIGS`). The time is of
    an execution without an observer, after 10 steps to warm up."""
    import subprocess

    arg = json.dumps([{n: str(p) for n, p in fmus.items()}, links, record, config, steps])
    out = subprocess.run([sys.executable, "-c", _LIBCOSIM_RUN, arg], capture_output=True, text=True, timeout=1800,
                         check=True).stdout.splitlines()
    per_step = float(next(x for x in out if x.startswith("RESULT ")).split()[1])
    return per_step, json.loads(next(x for x in out if x.startswith("VALUES "))[len("VALUES "):])


def trivial_fmus() -> dict[str, Path]:
    """Four copies of a trivial foreign C FMU (``AllTypes``, tests/data/foreign:
    a step that does nothing), unconnected: libcosim's own cost per step."""
    import tempfile

    sys.path.insert(0, str(HERE.parent))
    from tests.foreign_fmus import build_foreign_fmu

    fmu = build_foreign_fmu("AllTypes", Path(tempfile.mkdtemp(prefix="lpvest-bench-")))
    return {f"c{i}": fmu for i in range(4)}


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
    parser.add_argument("--native-fmus", default="fmu-build-native",
                        help="folder of the native FMUs (default fmu-build-native)")
    parser.add_argument("--profile", action="store_true", help="print a cProfile listing of one co-simulation")
    parser.add_argument("--out", help="write the measurements as JSON")
    args = parser.parse_args()

    sys.path.insert(0, str(HERE))
    from native_bench import step_times

    paths = fmu_paths(Path(args.fmus))
    native = fmu_paths(Path(args.native_fmus), "native")
    with zipfile.ZipFile(paths["HinfPD"]) as z:
        design_json = z.read("resources/design.json").decode()
    with zipfile.ZipFile(native["HinfPD"]) as z:
        assert z.read("resources/design.json").decode() == design_json, "the two HinfPD FMUs carry other designs"

    co_runs, co_setup, nat_runs, ip_runs, min_runs, kf_lib, kf_min = [], [], [], [], [], [], []
    # libcosim: the native and the trivial FMUs in both configurations, the pythonfmu ones serial
    lc_cases = {f"{kind} {config}": (kind, config) for kind in ("native", "floor", "pythonfmu")
                for config in LIBCOSIM_CONFIGS}
    lc_fmus = {"native": native, "pythonfmu": paths, "floor": trivial_fmus()}
    lc_runs: dict[str, list[float]] = {case: [] for case in lc_cases}
    lc_values: dict[str, list[float]] = {}
    co_out = nat_out = ip_out = min_out = None
    kf_diff = 0.0
    for _ in range(args.repeat):
        min_out, run = minimal_loop(design_json, args.steps)
        min_runs.append(run)
        co_out, setup, run = cosimulation(paths, args.steps)
        co_runs.append(run)
        co_setup.append(setup)
        nat_out, _, run = cosimulation(native, args.steps)
        nat_runs.append(run)
        ip_out, run = in_process(design_json, args.steps)
        ip_runs.append(run)
        lib, mine, kf_diff = kalman_steps(min(args.steps, 5000))
        kf_lib.append(lib)
        kf_min.append(mine)
        for case, (kind, config) in lc_cases.items():
            if kind == "floor":
                run, lc_values[case] = libcosim_per_step(lc_fmus[kind], args.steps, config, links=[], record=[])
            else:
                run, lc_values[case] = libcosim_per_step(lc_fmus[kind], args.steps, config)
            lc_runs[case].append(run)
    c_host = {role: step_times(native[role], steps=max(args.steps * 10, 10_000), repeat=5) for role in ROLES}
    assert co_out is not None and nat_out is not None and ip_out is not None and min_out is not None
    identical = bool(np.array_equal(co_out, ip_out))
    # the minimal loop sums the vertex matrices in another order: rounding only
    agree = float(np.max(np.abs(min_out - ip_out)))
    # the native FMUs: the same equations in C (tests/test_native_fmus.py derives the bounds per role)
    nat_agree = float(np.max(np.abs(nat_out - ip_out)))
    n = args.steps + 1  # samples recorded (the last one without a step)
    co_us, nat_us, ip_us, min_us = (min(r) / n * 1e6 for r in (co_runs, nat_runs, ip_runs, min_runs))
    lc_us = {case: min(r) * 1e6 for case, r in lc_runs.items()}
    # the thread pool and the calling thread step the same Jacobi co-simulation
    lc_same = all(lc_values[f"{kind} serial"] == lc_values[f"{kind} pool"] for kind in ("native", "pythonfmu"))
    kf_n = min(args.steps, 5000)
    kf_lib_us, kf_min_us = min(kf_lib) / kf_n * 1e6, min(kf_min) / kf_n * 1e6

    def ratio(us: float, target: str = "") -> str:
        return f"{us:8.1f} us/step   {us / min_us:5.2f} x minimal" + (f" (target <= {target})" if target else "")

    print(f"Peixoto Example 1, scheduler + source + plant + HinfPD, {args.steps} steps, best of {args.repeat}")
    print(f"  minimal numpy loop (reference):               {min_us:8.1f} us/step")
    print(f"  in-process (lpvest components):               {ratio(ip_us, '2')}")
    print(f"  co-simulation, lpvest.cosim, pythonfmu FMUs:  {ratio(co_us, '4')} (set-up {min(co_setup):.2f} s)")
    print(f"  co-simulation, lpvest.cosim, native FMUs:     {ratio(nat_us, '1')}")
    print("  libcosim (Jacobi, a subprocess each), serial: numWorkerThreads=0; pool: libcosimpy's default")
    print(f"  libcosim serial, pythonfmu:                   {ratio(lc_us['pythonfmu serial'])}")
    print(f"  libcosim serial, native:                      {ratio(lc_us['native serial'], '0.25')}")
    print(f"  libcosim serial, four trivial C FMUs (floor): {ratio(lc_us['floor serial'])}")
    print(f"  libcosim pool, pythonfmu:                     {ratio(lc_us['pythonfmu pool'])}")
    print(f"  libcosim pool, native:                        {ratio(lc_us['native pool'])}")
    print(f"  libcosim pool, four trivial C FMUs (floor):   {ratio(lc_us['floor pool'])}")
    print(f"  libcosim serial and pool record the same values: {lc_same}")
    print(f"  identical results in-process vs co-simulation: {identical}" + ("" if identical else
          f" (largest difference {np.max(np.abs(co_out - ip_out)):.3g})") + f"; minimal loop within {agree:.1e}; "
          f"native FMUs within {nat_agree:.1e}")
    print("native FMUs alone in a bare C host (benchmarks/native_step.c), ns per sample:")
    for role, (full, step) in c_host.items():
        target = " (target <= 500)" if role == "HinfPD" else ""
        print(f"  {role:<10} set + doStep + get {full:8.0f}   doStep {step:8.0f}{target}")
    print(f"Kalman filter (Cox & Toth truncation model), {kf_n} steps")
    print(f"  minimal numpy (4a)-(4e) step:          {kf_min_us:8.1f} us/step")
    print(f"  LPVKalmanFilter.step:                  {kf_lib_us:8.1f} us/step   {kf_lib_us / kf_min_us:5.2f} x minimal "
          f"(target <= 1.5); xhat within {kf_diff:.1e}")
    if args.out:
        Path(args.out).write_text(json.dumps({
            "steps": args.steps, "repeat": args.repeat, "minimal_us_per_step": min_us,
            "cosim_us_per_step": co_us, "inprocess_us_per_step": ip_us,
            "libcosim_us_per_step": lc_us["pythonfmu serial"],
            "inprocess_ratio": ip_us / min_us, "cosim_ratio": co_us / min_us, "cosim_setup_s": min(co_setup),
            "identical": identical, "minimal_agreement": agree, "kalman_us_per_step": kf_lib_us,
            "kalman_minimal_us_per_step": kf_min_us, "kalman_ratio": kf_lib_us / kf_min_us,
            "native_cosim_us_per_step": nat_us, "native_cosim_ratio": nat_us / min_us,
            "native_agreement": nat_agree, "libcosim_us": lc_us, "libcosim_serial_equals_pool": lc_same,
            "libcosim_ratio": {k: v / min_us for k, v in lc_us.items()},
            "c_host_ns": {role: {"set_step_get": full, "step": step} for role, (full, step) in c_host.items()},
        }, indent=2))
    if args.profile:
        profile(paths, args.steps)
    scale = max(1.0, float(np.max(np.abs(ip_out))))
    return 0 if lc_same and identical and agree < 1e-12 and kf_diff < 1e-12 and nat_agree <= 1e-12 * scale else 1


if __name__ == "__main__":
    raise SystemExit(main())
