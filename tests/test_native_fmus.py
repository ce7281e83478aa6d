"""The native FMUs (lpvest.fmi.native) against the library and the Python FMUs.

Every discrete-time role is built with the native backend for every example
system, the affine demo and the own-plant example (tests/conftest_fmu.py,
``native_fmus``). Each FMU is driven sample by sample through fmpy's FMU2Slave
next to the library's component of its role (tests/native_reference.py: the
Python FMU's own ``make_component`` on the native FMU's resources), and the
outputs agree within a rounding bound derived for the role from the library's
run; the random streams agree bit for bit. The model descriptions, step
semantics, messages and FMU states are the Python FMUs'.
"""

from __future__ import annotations

import math
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from tests.fmu_driver import Driver
from tests.native_hosts import HostDriver
from tests.native_reference import EPS, FUNC_ULPS, SAFETY, _abs, _norm, gamma, reference, weights_error

# -- what a native FMU is ----------------------------------------------------------------


def test_every_discrete_time_role_is_built_natively(fmus, native_fmus):
    from fmpy import read_model_description

    native = {n for n, p in native_fmus.paths.items()
              if not read_model_description(str(p)).coSimulation.needsExecutionTool}
    roles = ("Plant", "Scheduler", "Source", "Kalman", "TruncatedKalman", "HinfPD", "HinfRobust")
    expected = {n for n in {*fmus.paths, *native_fmus.paths}
                if n.endswith(roles) and n != "SridharLtvPlant" and "MovingAverage" not in n}
    assert native == expected
    # the continuous-time LTV plant and the B-spline observer stay pythonfmu FMUs (docs/fmus.md)
    for name in ("SridharLtvPlant", "SridharLtvBSplineObserver"):
        assert read_model_description(str(native_fmus[name])).coSimulation.needsExecutionTool


def test_a_native_fmu_is_a_source_fmu_with_three_binaries(native_fmus):
    from lpvest.fmi.native._build import RUNTIME_DIR

    with zipfile.ZipFile(native_fmus["PeixotoEx1HinfPD"]) as z:
        names = set(z.namelist())
        desc = z.read("sources/buildDescription.xml").decode()
        md = z.read("modelDescription.xml").decode()
        # the runtime is the package's, byte for byte: only model_data.c is generated
        for f in sorted(RUNTIME_DIR.iterdir()):
            if f.suffix in (".c", ".h"):
                assert z.read(f"sources/{f.name}") == f.read_bytes(), f.name
    assert {"binaries/linux64/PeixotoEx1HinfPD.so", "binaries/win64/PeixotoEx1HinfPD.dll",
            "binaries/darwin64/PeixotoEx1HinfPD.dylib"} <= names
    sources = sorted(n[len("sources/"):] for n in names if n.startswith("sources/") and n.endswith(".c"))
    assert "model_data.c" in sources and "lpv_fmi2.c" in sources
    assert {"sources/fmi2Functions.h", "sources/lpv.h", "sources/lpv_core.h"} <= names
    for s in sources:  # listed for fmpy (FMI 2.0 SourceFiles) and in the build description
        assert f'<File name="{s}"/>' in md and f'<SourceFile name="{s}"/>' in desc
    assert {"resources/model.toml", "resources/design.json", "resources/manifest.json",
            "resources/lpvest_fmu.json"} <= names
    assert not any(n.endswith(".py") for n in names)  # no Python anywhere


def _variables(path: Path) -> list[tuple]:
    from fmpy import read_model_description

    md = read_model_description(str(path))
    out = []
    for v in md.modelVariables:
        out.append((v.name, v.valueReference, v.causality, v.variability, v.initial, v.description, v.type,
                     v.start, v.min, v.max))
    return out


def test_model_descriptions_declare_what_the_python_fmus_declare(fmus, native_fmus):
    import xml.etree.ElementTree as ET

    checked: set[str] = set()
    for name, path in native_fmus.paths.items():
        if name not in fmus.paths or name.startswith("Sridhar"):
            continue
        assert _variables(path) == _variables(fmus[name]), name
        trees = []
        for p in (path, fmus[name]):
            with zipfile.ZipFile(p) as z:
                trees.append(ET.fromstring(z.read("modelDescription.xml")))
        native, python = trees
        # the same structure (outputs, their dependencies, initial unknowns) and experiment
        for tag in ("ModelStructure", "DefaultExperiment", "LogCategories"):
            assert ET.tostring(native.find(tag)) == ET.tostring(python.find(tag)), (name, tag)
        cs_n, cs_p = native.find("CoSimulation").attrib, python.find("CoSimulation").attrib
        assert cs_n.pop("needsExecutionTool") == "false" and cs_p.pop("needsExecutionTool") == "true"
        assert cs_n == cs_p, name
        checked.add(name)
    roles = ("Plant", "Scheduler", "Source", "Kalman", "TruncatedKalman", "HinfPD", "HinfRobust")
    assert all(any(n.endswith(r) for n in checked) for r in roles)


# -- the binaries import nothing beyond the C library ----------------------------------------


def _elf_needed(data: bytes) -> list[str]:
    """DT_NEEDED of an x86-64 ELF shared library."""
    import struct

    assert data[:4] == b"\x7fELF" and data[4] == 2 and data[5] == 1
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum, _ = struct.unpack_from("<HHH", data, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]
    dyn = next(s for s in sections if s[1] == 6)  # SHT_DYNAMIC
    strtab = sections[dyn[6]]  # sh_link
    needed = []
    for off in range(dyn[4], dyn[4] + dyn[5], 16):
        tag, val = struct.unpack_from("<qQ", data, off)
        if tag == 1:  # DT_NEEDED
            end = data.index(b"\0", strtab[4] + val)
            needed.append(data[strtab[4] + val:end].decode())
    return needed


def _macho_dylibs(data: bytes) -> list[str]:
    """The LC_LOAD_DYLIB libraries of a 64-bit Mach-O file."""
    import struct

    magic, _, _, _, ncmds, _, _, _ = struct.unpack_from("<IiiIIIII", data, 0)
    assert magic == 0xFEEDFACF
    off, out = 32, []
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, off)
        if cmd in (0xC, 0x80000018):  # LC_LOAD_DYLIB, LC_LOAD_WEAK_DYLIB
            name_off, = struct.unpack_from("<I", data, off + 8)
            out.append(data[off + name_off:data.index(b"\0", off + name_off)].decode())
        off += size
    return out


def test_the_binaries_import_only_the_c_library_and_export_only_fmi(native_fmus):
    import pefile

    fmi2 = {"fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate", "fmi2FreeInstance",
            "fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate",
            "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
            "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
            "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
            "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
            "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
            "fmi2GetBooleanStatus", "fmi2GetStringStatus"}
    for name in ("PeixotoEx1Plant", "CoxTothTruncationTruncatedKalman", "AffineDemoHinfPD"):
        with zipfile.ZipFile(native_fmus[name]) as z:
            elf = z.read(f"binaries/linux64/{name}.so")
            dll = z.read(f"binaries/win64/{name}.dll")
            dylib = z.read(f"binaries/darwin64/{name}.dylib")
        assert set(_elf_needed(elf)) <= {"libc.so.6", "libm.so.6"}
        pe = pefile.PE(data=dll)
        assert pe.FILE_HEADER.Machine == 0x8664
        imported = {e.dll.decode().lower() for e in pe.DIRECTORY_ENTRY_IMPORT}
        assert imported <= {"kernel32.dll", "msvcrt.dll"} | {i for i in imported if i.startswith("api-ms-win-crt")}
        assert {e.name.decode() for e in pe.DIRECTORY_ENTRY_EXPORT.symbols} == fmi2
        assert _macho_dylibs(dylib) == ["/usr/lib/libSystem.B.dylib"]


# -- the numbers: each role against the library -----------------------------------------------


@pytest.fixture(params=["fmpy", "C host"])
def open_fmu(request):
    """Opens an FMU in fmpy (FMU2Slave, in this process) or in the C host of
    tests/data/native_host.c (a process of its own with an empty environment:
    no Python)."""
    opened: list = []

    def open_(path: Path):
        d = Driver(path) if request.param == "fmpy" else HostDriver(path)
        opened.append(d)
        return d

    yield open_
    for d in opened:
        if isinstance(d, HostDriver):
            assert d.close() == 0, d.stderr
        else:
            d.free()


def _signals(space, T: int) -> np.ndarray:
    """A scheduling trajectory inside the box: each component a sinusoid of its own frequency."""
    k = np.arange(T)[:, None]
    j = np.arange(space.dim)[None, :]
    centre, half = (space.lower + space.upper) / 2, (space.upper - space.lower) / 2
    return centre + 0.95 * half * np.sin(0.25 * k / (1 + j) + j)


def _wave(T: int, n: int, scale: float = 1.0, phase: float = 0.0) -> np.ndarray:
    k = np.arange(T)[:, None]
    return scale * np.sin(0.3 * k + np.arange(n)[None, :] + phase)


def _drive(d: Driver, inputs: dict[str, np.ndarray], outputs: list[str], T: int, h: float = 1.0) -> dict:
    rec: dict[str, list] = {o: [] for o in outputs}
    for k in range(T):
        for name, seq in inputs.items():
            assert d.set_vector(name, seq[k]) == 0, d.errors()
        for o in outputs:
            rec[o].append(d.vector(o))
        assert d.step(k * h, h) == 0, d.errors()
    return {o: np.array(v) for o, v in rec.items()}


PLANTS = {
    "PeixotoEx1Plant": {},
    "PeixotoEx2Plant": {"rho": 17.0},  # a model parameter: the runtime evaluates its entries
    "CoxTothEx1Plant": {"noise": True, "seed": 3},  # innovation form
    "CoxTothTruncationPlant": {"noise": True, "seed": 5},  # affine: x_0 ~ N(x0, P0) drawn first
    "AffineDemoPlant": {"noise": True, "seed": 11},
    "OwnPlantPlant": {"noise": True, "seed": 2},
    "IoDemoPlant": {"noise": True, "seed": 8},  # input-output: its memory is the state
}


@pytest.mark.parametrize("name", sorted(PLANTS))
def test_plant_gives_the_librarys_numbers(native_fmus, open_fmu, name, tmp_path):
    """y, z, x of the native Plant against the library's DiscretePlant with the
    same inputs, parameters and seed. Bound: the state recursion
    x+ = A x + B u + G w carries each step's rounding on, e+ = |A| e + local,
    local = 2 gamma_n (|A| |x| + |B| |u| + |G| |w|) plus what a difference of
    the weights alpha(p) or psi(p) does (formulas with functions); the same for
    the outputs. The drawn noise (and x_0) are the same bits in both."""
    from lpvest.systems._affine import AffineLPV
    from lpvest.systems._innovation import LPVInputOutput
    from lpvest.systems._polytopic import PolytopicLPV
    from tests.test_native_core import formula_bound

    params = PLANTS[name]
    ref = reference(native_fmus[name], tmp_path, **params)
    plant = ref.component
    model = plant.model
    T = 80
    inputs = {}
    for port in plant.input_ports:
        if port.name == "p":
            inputs["p"] = _signals(model.space, T)
        else:
            inputs[port.name] = _wave(T, port.size, 0.2 if port.name in ("w", "v", "e") else 1.0, len(inputs))
    outs = [p.name for p in plant.output_ports]
    d = open_fmu(native_fmus[name])
    assert d.initialize(**params) == 0, d.errors()
    got = _drive(d, inputs, outs, T)
    # the library, step by step, with the bound propagated alongside
    e = np.zeros(model.nx)
    n = model.nx + getattr(model, "nu", 0) + max(getattr(model, "nw", 0), 1) + max(getattr(model, "nv", 0), 1) + 3
    g2 = 2 * gamma(n)
    for k in range(T):
        sample = {key: v[k] for key, v in inputs.items()}
        x = plant.get_state()["x"]
        noise = plant.get_state()["noise"]
        out = plant.step(sample)
        if isinstance(model, LPVInputOutput):
            # y = e + [a, b_1.., c] . memory + b_0 u, summed in the library's order; the
            # coefficients are the library's within their formulas' bound
            vals = dict(zip(model.space.names, (float(v) for v in sample["p"]), strict=True))
            forms = (*model.y_coefficients, *model.u_coefficients, *model.e_coefficients)
            co = np.array([float(f.evaluate(vals)) for f in forms])
            dco = np.array([formula_bound(f, vals) for f in forms])
            na, nb = len(model.y_coefficients), len(model.u_coefficients)
            keep = [i for i in range(len(forms)) if i != na]  # b_0 multiplies u_t, not the memory
            m = {"R": co[keep][None, :], "B0": co[na:na + 1][None, :nb], "I": np.eye(1)}
            dm = {"R": dco[keep][None, :], "B0": dco[na:na + 1][None, :nb]}
            u = sample.get("u", np.zeros(0))
            terms = {"y": ("R", "B0", "I")}
            vecs_by = {"y": (x, u, sample["e"] + noise)}
        elif isinstance(model, PolytopicLPV):
            alpha = model.simplex_map(sample["p"])
            m = model.matrices(alpha)
            dm = {key: np.tensordot(weights_error(model.simplex_map, sample["p"]), np.abs(v), axes=1)
                  for key, v in model.vertex_stacks().items()}
            terms = {"y": ("Cy", "Dy", "Dyu"), "z": ("Cz", "Dz", "Dzu"), "x": ("A", "Bw", "Bu")}
            w, u = sample["w"], sample.get("u", np.zeros(getattr(model, "nu", 0)))
            vecs = (x, w, u)
        else:
            psi = model.dependence.psi(sample["p"])
            m = model.dependence.at_psi(psi)
            from tests.native_reference import basis_error
            epsi = np.array([0.0] + [basis_error(b, sample["p"]) for b in model.dependence.basis])
            dm = {key: np.tensordot(epsi, np.abs(v), axes=1) for key, v in model.dependence.coefficients.items()}
            u = sample.get("u", np.zeros(model.nu))
            if isinstance(model, AffineLPV):
                wn, vn = sample["w"] + noise[:model.nw], sample["v"] + noise[model.nw:]
                terms = {"y": ("C", "D", "H"), "x": ("A", "B", "G")}
                vecs_by = {"y": (x, u, vn), "x": (x, u, wn)}
            else:
                en = sample["e"] + noise
                K = model.K.evaluate(model.space.as_dict(sample["p"])).reshape(model.nx, model.ny)
                m = dict(m, K=K, I=np.eye(model.ny))
                dm = dict(dm, K=np.zeros_like(K), I=np.zeros((model.ny, model.ny)))
                terms = {"y": ("C", "D", "I"), "x": ("A", "B", "K")}
                vecs_by = {"y": (x, u, en), "x": (x, u, en)}
        bounds = {}
        for key, (a, b, c) in terms.items():
            va, vb, vc = vecs if isinstance(model, PolytopicLPV) else vecs_by[key]
            mats = [m.get(s) for s in (a, b, c)]
            size = sum(_abs(M) @ np.abs(v) for M, v in zip(mats, (va, vb, vc), strict=True) if M is not None and M.size)
            weights = sum(dm[s] @ np.abs(v) for s, v in zip((a, b, c), (va, vb, vc), strict=True)
                          if s in dm and dm[s].size)
            carried = _abs(mats[0]) @ e
            bounds[key] = carried + g2 * size + weights
        if isinstance(model, LPVInputOutput):  # the memory shifts; of the new values only y differs
            nu_mem, nc = max(nb - 1, 0), len(model.e_coefficients)
            ey, eu, ee = e[:na], e[na:na + nu_mem], e[na + nu_mem:]
            bounds["x"] = np.concatenate([*([bounds["y"], ey[:-1]] if na else []),
                                          *([np.zeros(1), eu[:-1]] if nu_mem else []),
                                          *([np.zeros(1), ee[:-1]] if nc else [])])
        for o in outs:
            bound = e if o == "x" else bounds[o]
            assert np.all(np.abs(got[o][k] - out[o]) <= SAFETY * bound), (o, k, got[o][k] - out[o], bound)
        e = bounds["x"]
    assert np.abs(e).max() < 1e-6  # the bound stays a rounding bound (the plants are stable)


def _sinusoid_error(amplitude, omega, phase, decay, t) -> np.ndarray:
    """offset + amplitude sin(omega t + phase) [exp(-decay t)] evaluated twice:
    the argument is the same IEEE arithmetic, sin and exp differ by FUNC_ULPS
    each, then a product or two and a sum round (one unit each, the values
    already differing)."""
    s = np.sin(omega * t + phase)
    e = np.exp(-decay * t)
    a = np.abs(amplitude)
    value = a * np.abs(s) * e
    return a * FUNC_ULPS * np.spacing(np.abs(s)) * e + a * np.abs(s) * FUNC_ULPS * np.spacing(e) + 4 * np.spacing(
        value + 1.0)


SCHEDULES = [
    ("PeixotoEx1Scheduler", {}, None),  # the paper's theta_k = sin(0.25 k), and alpha
    ("PeixotoEx1Scheduler", {"kind": "decaying", "amplitude[1]": 0.9, "decay[1]": 0.02, "onset": 3.0}, None),
    ("PeixotoEx1Scheduler", {"kind": "random", "seed": 4, "rate[1]": 0.5}, "bits"),  # the stream's uniforms
    ("AffineDemoScheduler", {"kind": "table", "table": "0 -1 0; 7.5 1 2; 20 0.5 1"}, "bits"),
    ("OwnPlantScheduler", {"kind": "constant", "offset[1]": 0.25}, "bits"),
    ("CoxTothEx1Source", {"u.kind": "gaussian", "u.seed": 2026, "u.std[1]": 2.0}, "bits"),  # the stream's normals
    ("PeixotoEx1Source", {}, None),  # the paper's w_k = sin(0.5 k) exp(-0.1 k) from k = 10
    ("AffineDemoSource", {"u.kind": "random", "u.seed": 7, "w.kind": "sinusoid"}, None),
]


@pytest.mark.parametrize("name, params, exact", SCHEDULES)
def test_scheduler_and_source_give_the_librarys_signals(native_fmus, open_fmu, name, params, exact, tmp_path):
    """Random kinds (gaussian: lpvest.core._rng's normals, random: its uniforms),
    tables and constants are the library's bits; sinusoids agree within what
    two sin/exp evaluations may differ by, alpha = map(p) within the map's
    formula bound for that difference of p."""
    from tests.test_native_core import formula_bound

    ref = reference(native_fmus[name], tmp_path, **params)
    comp = ref.component
    T, h = 60, 0.5
    outs = [p.name for p in comp.output_ports]
    d = open_fmu(native_fmus[name])
    assert d.initialize(**params) == 0, d.errors()
    got = _drive(d, {}, outs, T, h)
    comp.reset(0.0)
    for k in range(T):
        t = k * h
        out = comp.step({}, dt=h, t_end=t + h)
        for o in outs:
            if exact or o == "u" and params.get("u.kind") == "random":
                assert got[o][k].tobytes() == out[o].tobytes(), (o, k)
                continue
            spec = (comp.signal if o in ("p", "alpha") else comp.signals[o])
            ep = _sinusoid_error(spec.amplitude, spec.omega, spec.phase, spec.decay if spec.kind == "decaying" else 0.0,
                                 t) if t >= spec.onset and spec.kind in ("sinusoid", "decaying") else 0.0 * spec.offset
            if o == "alpha":
                space = comp.space
                values = {n: float(v) for n, v in zip(space.names, out["p"], strict=True)}
                errors = {n: float(v) for n, v in zip(space.names, ep, strict=True)}
                bound = np.array([formula_bound(f, values, errors) for f in comp.simplex_map.formulas])
            else:
                bound = ep
            assert np.all(np.abs(got[o][k] - out[o]) <= SAFETY * bound), (o, k, got[o][k] - out[o], bound)


def _kalman_data(model, T: int, seed: int) -> dict[str, np.ndarray]:
    p = _signals(model.space, T)
    data = {"p": p}
    if model.nu:
        data["u"] = _wave(T, model.nu)
    data["y"] = model.simulate(p, data.get("u"), rng=seed).y
    return data


def _check_kalman(got: dict, T: int, steps: list, bounds: list) -> None:
    loglik = 0.0
    for k in range(T):
        for o, value in got.items():
            if o == "loglik":
                loglik += bounds[k]["loglik"]
                bound = loglik
            else:
                bound = bounds[k][o]
            ref = np.asarray(steps[k][o]).reshape(-1)
            assert np.abs(value[k] - ref).max() <= SAFETY * bound, (o, k, np.abs(value[k] - ref).max(), bound)


KALMANS = {
    "CoxTothTruncationKalman": {},
    "AffineDemoKalman": {"x0[1]": 0.5, "P0[1,1]": 2.0, "P0[2,2]": 0.5},
    "OwnPlantKalman": {},
}


@pytest.mark.parametrize("name", sorted(KALMANS))
def test_kalman_filter_gives_the_librarys_numbers(native_fmus, open_fmu, name, tmp_path):
    """Every output of the native Kalman FMU against LPVKalmanFilter on the
    same data. Bound: each step's rounding (tests/native_reference.py:
    kalman_step_bound, with cond(Omega_t)) carried on by the recursion's own
    sensitivity, the closed loop Phi = A - K C: delta P+ = Phi delta P Phi^T,
    delta x+ = Phi delta x + delta K xi (first order; Joseph form); the
    log-likelihood adds its steps' bounds."""
    from lpvest.estimators.kalman._recursion import KalmanState, kalman_step
    from tests.native_reference import kalman_step_bound, packed_error

    params = KALMANS[name]
    ref = reference(native_fmus[name], tmp_path, **params)
    kf = ref.component
    km = kf.kalman_model
    model = km.model
    T = 60
    data = _kalman_data(model, T, seed=9)
    outs = [p.name for p in kf.output_ports]
    d = open_fmu(native_fmus[name])
    assert d.initialize(**params) == 0, d.errors()
    got = _drive(d, data, outs, T)
    n, nu, m = km.nx, km.nu, km.ny
    e_x = e_P = 0.0
    steps, bounds = [], []
    for k in range(T):
        x, P = kf.state.x.copy(), kf.state.P.copy()
        p, u, y = data["p"][k], data["u"][k] if nu else np.zeros(0), data["y"][k]
        out = kf.step({"p": p, "u": u, "y": y} if nu else {"p": p, "y": y})
        step = kalman_step(KalmanState(x, P, k), km.step_matrices(p), u, y)  # the same step's quantities (pure)
        F = km.step_matrices(p).F
        e_F = packed_error(km, p)
        here = kalman_step_bound(step, F, P, x, u, n, nu, m, e_x, e_P, e_F)
        local = kalman_step_bound(step, F, P, x, u, n, nu, m, 0.0, 0.0, e_F)
        steps.append(out)
        bounds.append(here)
        Phi = F[:n, :n] - step.K @ F[2 * n:, :n]
        phi = float(np.linalg.norm(Phi, 2))
        e_P = phi**2 * e_P + local["next_P"]
        e_x = phi * e_x + (here["K"] - local["K"]) * float(np.abs(step.innovation).max()) + local["next_x"]
    _check_kalman(got, T, steps, bounds)
    assert max(b["xhat"] for b in bounds) < 1e-9  # a rounding bound: the recursion contracts


TRUNCATED = {
    "theorem, tau = 3": ("CoxTothTruncationTruncatedKalman", {"tau": 3}),
    "steady-state, tau = 2": ("CoxTothTruncationTruncatedKalman",
                              {"tau": 2, "start": "steady-state", "start_p[1]": 0.4}),
    "default (theorem, tau = 10)": ("AffineDemoTruncatedKalman", {}),
    "own plant, steady-state": ("OwnPlantTruncatedKalman", {"tau": 4, "start": "steady-state"}),
}


@pytest.mark.parametrize("case", sorted(TRUNCATED))
def test_truncated_kalman_filter_gives_the_librarys_numbers(native_fmus, open_fmu, case, tmp_path):
    """The native TruncatedKalman FMU against TruncatedKalmanFilter. Its prior
    is recomputed each sample over the last tau + 1 samples (exact from P0 while
    t <= tau, else from (6a)): the bound runs that window's recursion with its
    local roundings, from the restart's bound (which includes the start
    covariance's: 0 for the theorem's, carried as data; for the steady state,
    scipy's and the runtime's Riccati solutions apart by dare_bound); then the
    step's outputs as for the exact filter, the estimate carried on by the
    truncated closed loop."""
    from lpvest.estimators._truncated import truncated_prior
    from lpvest.estimators.kalman._model import StepMatrices
    from lpvest.estimators.kalman._recursion import KalmanState, kalman_step
    from tests.native_reference import covariance_step_bound, dare_bound, kalman_step_bound, packed_error, restart_bound

    name, params = TRUNCATED[case]
    ref = reference(native_fmus[name], tmp_path, **params)
    tf = ref.component
    km = tf.kalman_model
    model = km.model
    tau = tf.tau
    T = 40
    data = _kalman_data(model, T, seed=6)
    outs = [p.name for p in tf.output_ports]
    d = open_fmu(native_fmus[name])
    assert d.initialize(**params) == 0, d.errors()
    got = _drive(d, data, outs, T)
    n, nu, m = km.nx, km.nu, km.ny
    start_p = ref.params.get("start_p")
    e_start = dare_bound(km, np.asarray(start_p, dtype=float)) if ref.params.get("start") == "steady-state" else 0.0
    e_x = 0.0
    window: list[np.ndarray] = []
    steps, bounds = [], []
    for t in range(T):
        x = tf.get_state()["x"]
        p, u, y = data["p"][t], data["u"][t] if nu else np.zeros(0), data["y"][t]
        # the prior and its bound, over the window
        if t <= tau:
            P, e_P, first = model.P0, 0.0, 0
        else:
            P, e_P = restart_bound(window[0], n, nu, m, tf.start, e_start)
            first = 1
        for F in window[first:]:
            c = covariance_step_bound(P, F, n, nu, m, 0.0, 0.0)
            gains = c["cs"].gains
            Phi = F[:n, :n] - gains[:n] @ F[2 * n:, :n]
            e_P = float(np.linalg.norm(Phi, 2)) ** 2 * e_P + c["e_PP"]
            P = c["cs"].joint[:n, :n]
        prior = truncated_prior([StepMatrices(F, n, nu, m) for F in window], tf.start,
                                P0=model.P0 if t <= tau else None, t=t)
        assert np.array_equal(prior, P)  # the bound's replay runs through the library's prior
        out = tf.step({"p": p, "u": u, "y": y} if nu else {"p": p, "y": y})
        step = kalman_step(KalmanState(x, prior, t), km.step_matrices(p), u, y)
        F = km.step_matrices(p).F
        e_F = packed_error(km, p)
        here = kalman_step_bound(step, F, prior, x, u, n, nu, m, e_x, e_P, e_F)
        local = kalman_step_bound(step, F, prior, x, u, n, nu, m, 0.0, 0.0, e_F)
        steps.append(out)
        bounds.append(here)
        Phi = F[:n, :n] - step.K @ F[2 * n:, :n]
        e_x = float(np.linalg.norm(Phi, 2)) * e_x + (here["K"] - local["K"]) * float(
            np.abs(step.innovation).max()) + local["next_x"]
        window = (window + [F])[-(tau + 1):]
    _check_kalman(got, T, steps, bounds)


def _hinf_data(fmu: Path, comp, T: int) -> dict[str, np.ndarray]:
    data = {}
    for port in comp.input_ports:
        if port.name == "p":
            data["p"] = _signals(comp.simplex_map.space, T)
        elif port.name == "alpha":
            a = 0.5 + 0.45 * np.sin(0.2 * np.arange(T))
            data["alpha"] = np.column_stack([a, 1 - a])
        else:
            data[port.name] = _wave(T, port.size, 1.0, len(data))
    return data


HINF = ["PeixotoEx1HinfPD", "PeixotoEx1HinfRobust", "PeixotoEx2HinfPD", "CoxTothTruncationHinfPD",
        "CoxTothTruncationHinfRobust", "AffineDemoHinfPD", "OwnPlantHinfRobust"]


@pytest.mark.parametrize("name", HINF)
def test_hinf_filter_gives_the_librarys_numbers(native_fmus, open_fmu, name, tmp_path):
    """zhat and xf of the native H-infinity FMU against HinfFilter on the same
    data. Bound: x_f+ = H^-1 (A_f x_f + B_f y), the solve backward stable
    (2 gamma_n cond(H)); a step's local difference s_j reaches sample k through
    the filter's own transition, |M_(k-1) ... M_(j+1)| s_j with M = H^-1 A_f
    (the products, not their absolute values: the designed coordinates make
    |H^-1 A_f| grow where the stable filter does not); the weights alpha(p)
    within their map's formula bound; with a known input, the copy of the
    plant's response x_u+ = A x_u + B_u u carried on by |A| and added to y and
    zhat."""
    from tests.native_reference import weights_error

    ref = reference(native_fmus[name], tmp_path)
    f = ref.component
    design, plant = f.design, f.plant
    T = 60
    data = _hinf_data(native_fmus[name], f, T)
    outs = [p.name for p in f.output_ports]
    d = open_fmu(native_fmus[name])
    assert d.initialize() == 0, d.errors()
    got = _drive(d, data, outs, T)
    nx = design.nx
    e_f = np.zeros(nx)
    carried: list[tuple[np.ndarray, np.ndarray]] = []  # (M_(k-1) ... M_(j+1), s_j)
    e_u = np.zeros(0 if plant is None else plant.nx)
    for k in range(T):
        sample = {key: v[k] for key, v in data.items()}
        state = f.get_state()
        xf = state["xf"]
        out = f.step(sample)
        if "p" in sample:
            alpha = f.simplex_map(sample["p"])
            e_alpha = weights_error(f.simplex_map, sample["p"])
        else:
            alpha, e_alpha = sample.get("alpha"), np.zeros(design.n_vertices)
        m = design.matrices_at(alpha if design.scheduled else None)
        dm = {key: (np.tensordot(e_alpha, np.abs(getattr(design, key)), axes=1) if design.scheduled
                    else np.zeros_like(getattr(m, key))) for key in ("H", "Af", "Bf", "Cf", "Df")}
        y = sample["y"]
        e_y = np.zeros_like(y)
        z_extra = np.zeros(design.nz)
        if plant is not None:
            xu, u = state["xu"], sample["u"]
            varies = plant.input_path_varies()
            a = plant.matrices(alpha if varies else np.eye(1, plant.n_vertices)[0])
            da = ({key: v for key, v in zip(("A", "Cz", "Cy", "Bu", "Dzu", "Dyu"), (
                np.tensordot(e_alpha, np.abs(plant.vertex_stacks()[key]), axes=1)
                for key in ("A", "Cz", "Cy", "Bu", "Dzu", "Dyu")), strict=True)} if varies
                  else {key: 0.0 for key in ("A", "Cz", "Cy", "Bu", "Dzu", "Dyu")})
            g = 2 * gamma(plant.nx + plant.nu + 2)
            y_w = y - a["Cy"] @ xu - a["Dyu"] @ u
            e_y = (_abs(a["Cy"]) @ e_u + g * (np.abs(y) + _abs(a["Cy"]) @ np.abs(xu) + _abs(a["Dyu"]) @ np.abs(u))
                   + np.abs(da["Cy"]) @ np.abs(xu) + np.abs(da["Dyu"]) @ np.abs(u))
            z_extra = (_abs(a["Cz"]) @ e_u + g * (_abs(a["Cz"]) @ np.abs(xu) + _abs(a["Dzu"]) @ np.abs(u))
                       + np.abs(da["Cz"]) @ np.abs(xu) + np.abs(da["Dzu"]) @ np.abs(u))
            e_u = (_abs(a["A"]) @ e_u + g * (_abs(a["A"]) @ np.abs(xu) + _abs(a["Bu"]) @ np.abs(u))
                   + np.abs(da["A"]) @ np.abs(xu) + np.abs(da["Bu"]) @ np.abs(u))
            y = y_w
        g = 2 * gamma(nx + design.ny + 2)
        z_f = m.Cf @ xf + m.Df @ y
        e_z = (_abs(m.Cf) @ e_f + _abs(m.Df) @ e_y + g * (_abs(m.Cf) @ np.abs(xf) + _abs(m.Df) @ np.abs(y))
               + dm["Cf"] @ np.abs(xf) + dm["Df"] @ np.abs(y) + z_extra + 2 * EPS * np.abs(z_f))
        assert np.all(np.abs(got["zhat"][k] - out["zhat"]) <= SAFETY * e_z), (k, got["zhat"][k] - out["zhat"], e_z)
        assert np.all(np.abs(got["xf"][k] - out["xf"]) <= SAFETY * e_f), (k, got["xf"][k] - out["xf"], e_f)
        Hi = np.linalg.inv(m.H)
        r = m.Af @ xf + m.Bf @ y
        local = (_abs(m.Bf) @ e_y + g * (_abs(m.Af) @ np.abs(xf) + _abs(m.Bf) @ np.abs(y))
                 + dm["Af"] @ np.abs(xf) + dm["Bf"] @ np.abs(y))
        nxt = Hi @ r
        cond = _norm(m.H) * _norm(Hi)
        s_k = _abs(Hi) @ (local + dm["H"] @ np.abs(nxt)) + 2 * gamma(nx) * cond * np.abs(nxt).max()
        M = Hi @ m.Af
        carried = [(M @ prod, s) for prod, s in carried] + [(np.eye(nx), s_k)]
        e_f = sum(np.abs(prod) @ s for prod, s in carried)
    assert e_f.max() < 1e-9  # a rounding bound: the certified filters are stable


# -- the same behaviour as the Python FMUs ------------------------------------------------------


def _both(fmus, native_fmus, name: str, script) -> list[tuple]:
    """Run ``script(driver)`` on the Python and the native FMU of ``name``: what
    it returns and the messages of status warning or worse (without the
    model-name prefix)."""
    out = []
    for path in (fmus[name], native_fmus[name]):
        d = Driver(path)
        result = script(d)
        messages = [(s, m.split("] ", 1)[-1]) for s, _, m in d.messages if s >= 1]
        d.free()
        out.append((result, messages))
    return out


def _init(d: Driver, **params):
    return d.initialize(**params)


SCENARIOS = {
    "an input outside its range, then a step": (
        "PeixotoEx1Plant", lambda d: (_init(d), d.set("p[1]", 2.0), d.step(0.0, 1.0))),
    "a NaN input": ("PeixotoEx1Plant", lambda d: (_init(d), d.set("p[1]", math.nan), d.set("w[1]", math.inf))),
    "a step before initialization": ("PeixotoEx1Plant", lambda d: (d.step(0.0, 1.0),)),
    "a parameter after initialization": ("PeixotoEx1Plant", lambda d: (_init(d), d.set("x0[1]", 1.0))),
    "steps that are not the next sample": ("PeixotoEx1Plant", lambda d: (
        _init(d), d.step(0.0, 0.5), d.step(0.0, -1.0), d.step(3.0, 1.0), d.step(0.0, math.inf), d.step(0.0, 0.0))),
    "a sample skipped inside a longer step far from t = 0": ("PeixotoEx1HinfPD", lambda d: (
        d.initialize(2e6, sample_time=1e-3), d.step(2e6 + 1e-3, 1e-3), d.step(2e6 + 1e-3, 4e-3),
        d.step(2e6, 4e-3))),
    "a skipped or repeated point far from t = 0": ("PeixotoEx1Plant", lambda d: (
        d.initialize(1e9, sample_time=0.5), d.step(1e9, 0.5), d.step(1e9 + 1.0, 0.5), d.step(1e9, 0.5),
        d.step(1e9 + 0.5, 0.5))),
    "after fmi2Terminate": ("PeixotoEx1Plant", lambda d: (
        _init(d), d.raw("fmi2Terminate"), d.step(0.0, 1.0), d.set("p[1]", 0.1))),
    "a model parameter outside its range": ("PeixotoEx2Plant", lambda d: (_init(d, rho=30.0),)),
    "an unknown signal kind": ("PeixotoEx1Scheduler", lambda d: (_init(d, kind="foo"),)),
    "a schedule leaving the box": ("PeixotoEx1Scheduler", lambda d: (_init(d, **{"amplitude[1]": 3.0}),)),
    "a gaussian schedule": ("PeixotoEx1Scheduler", lambda d: (_init(d, kind="gaussian"),)),
    "a table with repeated times": ("PeixotoEx1Source", lambda d: (
        _init(d, **{"w.kind": "table", "w.table": "0 1; 0 2"}),)),
    "a table row too long": ("PeixotoEx1Source", lambda d: (_init(d, **{"w.kind": "table", "w.table": "0 1 3"}),)),
    "a table field not a number": ("PeixotoEx1Source", lambda d: (
        _init(d, **{"w.kind": "table", "w.table": "0 x; 1 1"}),)),
    "a negative standard deviation": ("CoxTothTruncationSource", lambda d: (
        _init(d, **{"u.kind": "gaussian", "u.std[1]": -1.0}),)),
    "P0 not positive semidefinite": ("CoxTothTruncationKalman", lambda d: (_init(d, **{"P0[1,1]": -1.0}),)),
    "P0 not symmetric": ("CoxTothTruncationKalman", lambda d: (_init(d, **{"P0[1,2]": 0.5}),)),
    "an unknown start": ("CoxTothTruncationTruncatedKalman", lambda d: (_init(d, start="foo"),)),
    "a start point outside the box": ("CoxTothTruncationTruncatedKalman", lambda d: (
        _init(d, start="steady-state", **{"start_p[1]": 2.0}),)),
    "invalid inputs, then a step": ("CoxTothTruncationKalman", lambda d: (
        _init(d), d.set("p[1]", 5.0), d.set("u[1]", math.inf), d.step(0.0, 1.0), d.set("p[1]", 0.5),
        d.set("u[1]", 1.0), d.step(0.0, 1.0), bool(np.isfinite(d.vector("xhat")).all()))),
    "setting an output": ("PeixotoEx1Plant", lambda d: (_init(d), d.set("y[1]", 1.0))),
    "an input-output plant's memory and a bad input": ("IoDemoPlant", lambda d: (
        _init(d, **{"x0[1]": 1.0, "x0[5]": -2.0}), d.set("p[1]", 0.4), d.set("u[1]", 1.0), d.vector("y").tolist(),
        d.step(0.0, 1.0), d.vector("x").tolist(), d.set("p[1]", -1.5), d.step(1.0, 1.0))),
    "sample_time 0": ("PeixotoEx1Plant", lambda d: (_init(d, sample_time=0.0),)),
    "a step of whole samples, then not": ("PeixotoEx1HinfPD", lambda d: (
        _init(d), d.set("p[1]", 0.3), d.set("y[1]", 1.0), d.step(0.0, 3.0), d.step(3.0, 2.5))),
    "a measurement two samples late": ("PeixotoEx1HinfPD", lambda d: (
        _init(d, measurement_delay=2), d.set("y[1]", 1.0), d.vector("zhat").tolist(), d.step(0.0, 1.0),
        d.vector("zhat").tolist(), d.step(1.0, 1.0), d.step(2.0, 1.0), bool(np.any(d.vector("zhat") != 0)))),
    "a null array to every getter and setter": ("PeixotoEx1Plant", lambda d: (_init(d), *(
        d.raw(f"fmi2{op}{kind}", None, 1, None) for op in ("Get", "Set")
        for kind in ("Real", "Integer", "Boolean", "String")))),
    "the initialization out of its order": ("CoxTothTruncationKalman", lambda d: (
        d.raw("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0), d.raw("fmi2EnterInitializationMode"),
        d.raw("fmi2EnterInitializationMode"), d.raw("fmi2SetupExperiment", 0, 0.0, 5.0, 0, 0.0),
        d.raw("fmi2ExitInitializationMode"), d.set("p[1]", 0.5), d.set("y[1]", 1.0), d.step(0.0, 1.0),
        d.fmu.getRealStatus(2), d.raw("fmi2ExitInitializationMode"),  # fmi2LastSuccessfulTime: 1
        d.raw("fmi2SetupExperiment", 0, 0.0, 100.0, 0, 0.0), d.raw("fmi2EnterInitializationMode"),
        d.fmu.getRealStatus(2), d.step(1.0, 1.0),  # still 1: neither restarted nor moved
        d.raw("fmi2Terminate"), d.raw("fmi2ExitInitializationMode"),
        d.raw("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0))),
    "fmi2ExitInitializationMode before fmi2EnterInitializationMode": ("PeixotoEx1Plant", lambda d: (
        d.raw("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0), d.raw("fmi2ExitInitializationMode"), d.step(0.0, 1.0),
        d.raw("fmi2EnterInitializationMode"), d.raw("fmi2ExitInitializationMode"), d.step(0.0, 1.0))),
    "a step of more samples than one step runs, and a NaN time": ("PeixotoEx1Plant", lambda d: (
        _init(d), d.step(0.0, 1e9), d.step(math.nan, 1.0))),
    "value references of another type or of no variable": ("PeixotoEx1Plant", lambda d: (
        _init(d), d.status(d.fmu.getInteger, [d.vr["p[1]"]]), d.status(d.fmu.setBoolean, [d.vr["x0[1]"]], [True]),
        d.status(d.fmu.getReal, [999_999]), d.status(d.fmu.setString, [d.vr["sample_time"]], ["1"]))),
    "outputs read after an input was rejected": ("PeixotoEx1HinfPD", lambda d: (
        _init(d), d.set("p[1]", 0.3), d.set("y[1]", 1.0), d.step(0.0, 1.0), d.set("p[1]", 5.0), d.set("y[1]", 2.0),
        d.vector("zhat").tolist() == (d.set("p[1]", 0.3), d.vector("zhat").tolist())[1])),  # not stale: True
    "outputs read before initialization": ("CoxTothTruncationPlant", lambda d: (
        d.raw("fmi2SetupExperiment", 0, 0.0, 0.0, 0, 0.0), d.raw("fmi2EnterInitializationMode"),
        d.set("p[1]", 0.5), bool(np.isfinite(d.vector("y")).all()))),
}


@pytest.mark.parametrize("case", sorted(SCENARIOS))
def test_the_same_statuses_and_messages_as_the_python_fmu(fmus, native_fmus, case):
    """Bad input, refused steps, invalid parameters, whole-sample steps and a late
    measurement: the native FMU returns the statuses and logs the messages the
    Python FMU of its role does, word for word."""
    name, script = SCENARIOS[case]
    python, native = _both(fmus, native_fmus, name, script)
    assert native == python
    if case == "outputs read after an input was rejected":  # they follow the stored inputs (were stale)
        assert python[0][-1] is True
    if case.startswith("a step of more samples"):  # (was "not a whole number of samples", and "t = nan")
        assert python[1][:2] == [
            (3, "fmi2DoStep refused at t = 0 (h = 1000000000): the communication step h = 1000000000 is 1000000000 "
                "samples of the sample time 1, more than one step runs (fewer than 500000000 = 0.5 / 1e-9, the "
                "relative time tolerance; split it into shorter steps)"),
            (3, "fmi2DoStep refused at t = nan (h = 1): the communication point t = nan and step h = 1 must be "
                "finite")]
    if case == "a start point outside the box":  # named as the parameter it is (was "scheduling value p")
        assert python[1] == [(3, "fmi2ExitInitializationMode: parameter start_p[1] (scheduling variable p) = 2 is "
                                 "outside its declared range [-1, 1]")]
    if case.startswith("value references of another type"):  # (was "is not a Integer variable")
        vr = {v.name: v.valueReference for v in read_model_description(str(fmus[name])).modelVariables}
        assert [m for _, m in python[1]] == [
            f"fmi2GetInteger: value reference {vr['p[1]']} is the Real variable p[1], not an Integer variable",
            f"fmi2SetBoolean: value reference {vr['x0[1]']} is the Real variable x0[1], not a Boolean variable",
            "fmi2GetReal: value reference 999999 is not a variable of this FMU",
            f"fmi2SetString: value reference {vr['sample_time']} is the Real variable sample_time, not a String "
            "variable"]
    if case.startswith("fmi2ExitInitializationMode before"):  # refused (was fmi2OK: found by the fuzzer)
        assert python[0] == (0, 3, 3, 0, 0, 0)
    assert any(s >= 3 for s, _ in python[1]) or case.startswith(("a measurement", "outputs read"))


def test_initialization_calls_out_of_their_fmi_state_are_refused_and_change_nothing(fmus):
    """A second fmi2EnterInitializationMode, fmi2SetupExperiment after it, a second
    fmi2ExitInitializationMode (it restarted the filter), fmi2SetupExperiment mid-run (it
    moved the time) and after fmi2Terminate: fmi2Error, nothing changed (both backends: the
    scenario above)."""
    name, script = SCENARIOS["the initialization out of its order"]
    d = Driver(fmus[name])
    assert script(d) == (0, 0, 3, 3, 0, 0, 0, 0, 1.0, 3, 3, 3, 1.0, 0, 0, 3, 3)
    assert f"[{name}] fmi2SetupExperiment: the FMU is initialized already (fmi2ExitInitializationMode was called; " \
           "reset the instance to initialize it again)" in d.errors()
    d.free()


def _run(d: Driver, data: dict[str, np.ndarray], outs: list[str], k0: int, n: int, h: float = 1.0) -> np.ndarray:
    rows = []
    for k in range(k0, k0 + n):
        for name, seq in data.items():
            assert d.set_vector(name, seq[k]) == 0
        rows.append(np.concatenate([d.vector(o) for o in outs]))
        assert d.step(k * h, h) == 0, d.errors()
    return np.array(rows)


def _fnv1a(data: bytes) -> int:
    """The checksum a native FMU state ends with (lpv_fmi2.c, checksum)."""
    h = 14695981039346656037
    for b in data:
        h = ((h ^ b) * 1099511628211) % 2**64
    return h


@pytest.mark.parametrize("name", ["CoxTothTruncationPlant", "CoxTothTruncationTruncatedKalman", "AffineDemoHinfPD",
                                  "CoxTothEx1Source", "PeixotoEx1Scheduler"])
def test_fmu_states_restore_and_serialize_exactly(native_fmus, name, tmp_path):
    """fmi2GetFMUstate / fmi2SetFMUstate go back exactly (random generators,
    a truncated filter's window, held outputs and all), and a serialized state
    continues identically in a fresh instance."""
    import ctypes

    ref = reference(native_fmus[name], tmp_path)
    comp = ref.component
    T = 30
    if not comp.input_ports:
        data = {}
    elif name.endswith("Plant"):
        data = {p.name: (_signals(comp.model.space, T) if p.name == "p" else _wave(T, p.size, 0.1))
                for p in comp.input_ports}
    else:
        data = _kalman_data(comp.kalman_model.model, T, 2) if "Kalman" in name else _hinf_data(
            native_fmus[name], comp, T)
    outs = [p.name for p in comp.output_ports]
    params = {"noise": True, "seed": 3} if name.endswith("Plant") else (
        {"u.kind": "gaussian"} if name.endswith("Source") else ({"kind": "random"} if "Scheduler" in name else {}))
    d = Driver(native_fmus[name])
    assert d.initialize(**params) == 0
    _run(d, data, outs, 0, 10)
    state = d.fmu.getFMUstate()
    first = _run(d, data, outs, 10, 15)
    d.fmu.setFMUstate(state)
    assert d.fmu.getRealStatus(2) == 10.0  # fmi2LastSuccessfulTime: the restored time
    assert np.array_equal(_run(d, data, outs, 10, 15), first)
    blob = d.fmu.serializeFMUstate(state)
    d.fmu.freeFMUstate(state)
    e = Driver(native_fmus[name], "second")
    assert e.initialize(**params) == 0
    restored = e.fmu.deSerializeFMUstate(blob)
    e.fmu.setFMUstate(restored)
    e.fmu.freeFMUstate(restored)
    assert np.array_equal(_run(e, data, outs, 10, 15), first)
    # a damaged state is refused, and the instance goes on unharmed
    bad = e.fmu.deSerializeFMUstate(bytes(blob[:40]) + b"\x00" * 8)
    assert e.raw("fmi2SetFMUstate", bad) == 3
    assert "not a serialized lpvest FMU state" in e.errors()[-1]
    e.fmu.freeFMUstate(bad)
    # one byte of a number changed (the checksum, FNV-1a of the bytes before it, no longer fits)
    bad = e.fmu.deSerializeFMUstate(bytes(blob[:-20]) + bytes([blob[-20] ^ 1]) + bytes(blob[-19:]))
    assert e.raw("fmi2SetFMUstate", bad) == 3
    assert e.errors()[-1].endswith("not a serialized lpvest FMU state (it is damaged: its checksum does not match)")
    e.fmu.freeFMUstate(bad)
    if name == "CoxTothTruncationTruncatedKalman":
        # a state whose window indices or sample counter are damaged (a segfault at the next
        # step before): refused, named. At t = 10 (tau = 10) the component's state holds the
        # sample counter t, the log-likelihood, the window's count and its head: 10, ., 10, 0
        ten, zero = struct.pack("<d", 10.0), struct.pack("<d", 0.0)
        at = [i for i in range(len(blob) - 32) if blob[i:i + 8] == ten and blob[i + 16:i + 32] == ten + zero]
        assert len(at) == 1, at
        for offset, value, says in ((24, 1e5, "the state's window (10 samples from 100000) does not fit tau = 10"),
                                    (16, 11.5, "the state's window (11.5 samples from 0) does not fit tau = 10"),
                                    (0, math.nan, "the state's sample counter nan is not a whole number >= 0")):
            i = at[0] + offset
            changed = bytes(blob[:i]) + struct.pack("<d", value) + bytes(blob[i + 8:-8])
            bad = e.fmu.deSerializeFMUstate(changed + struct.pack("<Q", _fnv1a(changed)))  # well formed
            assert e.raw("fmi2SetFMUstate", bad) == 3
            assert e.errors()[-1].endswith(says), e.errors()[-1]
            e.fmu.freeFMUstate(bad)
    assert e.step(25.0, 1.0) == 0
    d.free(), e.free()
    del ctypes


@pytest.mark.parametrize("name", ["CoxTothTruncationKalman", "PeixotoEx2HinfPD", "OwnPlantPlant"])
def test_a_step_of_m_samples_is_m_samples_with_the_inputs_held(native_fmus, name, tmp_path):
    """fmi2DoStep(t, 3 h) runs three samples with the inputs held: the same
    numbers, to the bit, as three one-sample steps with the same inputs."""
    ref = reference(native_fmus[name], tmp_path)
    comp = ref.component
    T = 12
    if name.endswith("Plant"):
        data = {p.name: (_signals(comp.model.space, T) if p.name == "p" else _wave(T, p.size, 0.1))
                for p in comp.input_ports}
    elif "Kalman" in name:
        data = _kalman_data(comp.kalman_model.model, T, 3)
    else:
        data = _hinf_data(native_fmus[name], comp, T)
    held = {k: np.repeat(v[::3], 3, axis=0) for k, v in data.items()}
    outs = [p.name for p in comp.output_ports]
    one, three = Driver(native_fmus[name]), Driver(native_fmus[name])
    assert one.initialize() == 0 and three.initialize() == 0
    singles = _run(one, held, outs, 0, T)
    for j in range(T // 3):
        for key, seq in data.items():
            assert three.set_vector(key, seq[3 * j]) == 0
        assert np.array_equal(np.concatenate([three.vector(o) for o in outs]), singles[3 * j])
        assert three.step(3.0 * j, 3.0) == 0, three.errors()
        direct = [p.name for p in comp.output_ports if p.direct]
        # after the step the outputs with direct feedthrough hold the value of the last sample consumed
        for o in direct:
            assert np.array_equal(three.vector(o), one_outputs(singles, outs, comp, o)[3 * j + 2])


def one_outputs(rows: np.ndarray, outs: list[str], comp, name: str) -> np.ndarray:
    """Column block of output port ``name`` in rows of concatenated outputs."""
    pos = 0
    for p in comp.output_ports:
        if p.name == name:
            return rows[:, pos:pos + p.size]
        pos += p.size
    raise KeyError(name)


@pytest.mark.parametrize("name", ["CoxTothTruncationTruncatedKalman", "PeixotoEx1HinfPD"])
def test_a_late_measurement_is_paired_with_its_own_sample(native_fmus, name, tmp_path):
    """measurement_delay = d: at step j the FMU gets y of sample j - d with the
    other inputs of sample j, and outputs, to the bit, what it outputs without
    the delay at sample j - d (every output 0 before the first pair)."""
    ref = reference(native_fmus[name], tmp_path)
    comp = ref.component
    T, delay = 20, 2
    data = _kalman_data(comp.kalman_model.model, T, 4) if "Kalman" in name else _hinf_data(native_fmus[name], comp, T)
    late = {k: (np.concatenate([np.zeros((delay, v.shape[1])), v[:-delay]]) if k == "y" else v)
            for k, v in data.items()}
    outs = [p.name for p in comp.output_ports]
    plain, delayed = Driver(native_fmus[name]), Driver(native_fmus[name])
    assert plain.initialize() == 0 and delayed.initialize(measurement_delay=delay) == 0
    a = _run(plain, data, outs, 0, T)
    b = _run(delayed, late, outs, 0, T)
    assert np.array_equal(b[:delay], np.zeros_like(b[:delay]))
    assert np.array_equal(b[delay:], a[:-delay])


def test_reset_starts_over_and_instances_are_independent(native_fmus):
    name = "CoxTothTruncationPlant"
    p = _signals(__import__("lpvest").load_system("cox-toth-truncation").model().space, 20)
    data = {"p": p, "u": _wave(20, 1), "w": _wave(20, 2, 0.1), "v": _wave(20, 2, 0.1)}
    a, b = Driver(native_fmus[name], "a"), Driver(native_fmus[name], "b")
    assert a.initialize(noise=True, seed=8) == 0 and b.initialize(noise=True, seed=8) == 0
    ra = _run(a, data, ["y", "x"], 0, 10)
    assert a.raw("fmi2Reset") == 0
    assert a.initialize(noise=True, seed=8) == 0
    rb = _run(b, data, ["y", "x"], 0, 10)  # b ran nothing meanwhile: a's run did not touch it
    assert np.array_equal(_run(a, data, ["y", "x"], 0, 10), ra) and np.array_equal(rb, ra)


# -- the backend option: CLI, cache, reproduce -------------------------------------------


def test_an_output_that_is_not_finite_stays_an_error_after_a_restored_state(native_fmus):
    """A step refused for an output that is not finite was accepted after fmi2GetFMUstate and
    fmi2SetFMUstate (the restored outputs were not checked again): as in the Python FMU's test
    (tests/test_fmu.py), it stays refused, and reading it stays an error."""
    d = Driver(native_fmus["PeixotoEx1Plant"])
    assert d.initialize() == 0
    d.set_vector("p", 0.5)
    d.set_vector("w", 1e308)
    assert d.step(0.0, 1.0) == 0  # y_0 = D_y w is finite, x_1 overflows
    assert d.step(1.0, 1.0) == 3
    state = d.fmu.getFMUstate()
    d.fmu.setFMUstate(state)
    d.fmu.freeFMUstate(state)
    assert d.status(d.fmu.getReal, [d.vr["y[1]"]]) == 3
    assert d.errors()[-1].endswith("output y[1] is not finite (NaN or inf) at t = 1")
    assert d.step(1.0, 1.0) == 3
    d.free()


def test_a_model_with_more_model_parameters_than_the_runtime_holds_is_refused_at_build(tmp_path):
    """The runtime holds 64 model parameters per instance (formulas index them): a 65th was
    read from the memory after them, silently (a review's finding). The build refuses it."""
    from lpvest.fmi._build import BuildError, build_fmus
    from lpvest.fmi.native._export import MAX_MODEL_PARAMS

    n = MAX_MODEL_PARAMS + 1
    names = [f"k{i}" for i in range(1, n + 1)]
    a22 = '"0.1 + 0.001*(' + " + ".join(names) + ')"'
    vertex = f"""
[[models.plant.vertex]]
A = [[0.5, 0.0], [0.0, {a22}]]
Bw = [[1.0], [1.0]]
Cy = [[1.0, 1.0]]
Cz = [[1.0, 0.0]]
Dy = [[0.0]]
Dz = [[0.0]]
"""
    model = tmp_path / "many.toml"
    model.write_text("[system]\nname = \"many\"\ntitle = \"many parameters\"\ndefault = \"plant\"\n\n[parameters]\n"
                     + "".join(f'{k} = {{ value = 0.0, lower = -1.0, upper = 1.0, description = "{k}" }}\n'
                               for k in names)
                     + '\n[scheduling]\nnames = ["theta"]\nlower = [-1.0]\nupper = [1.0]\n\n[models.plant]\n'
                     + 'type = "polytopic"\n\n[models.plant.map]\nkind = "formulas"\n'
                     + 'alpha = ["(1 - theta)/2", "(1 + theta)/2"]\n' + vertex + vertex)
    with pytest.raises(BuildError, match=rf"ManyPlant: {n} model parameters; a native FMU takes at most 64 \(build it "
                                                r"with the pythonfmu backend\)"):
        build_fmus([model], tmp_path, roles=["Plant"], backend="native")
    assert not list(tmp_path.glob("*.fmu"))


def test_lpvest_build_backend_native(native_fmus, tmp_path, capsys):
    from fmpy import read_model_description

    from lpvest.cli import main
    from tests.conftest_fmu import OWN_PLANT

    assert main(["build", "--backend", "native", "--model", str(OWN_PLANT), "--kinds", "Plant,Kalman",
                 "--out", str(tmp_path)]) == 0
    built = sorted(p.name for p in tmp_path.glob("*.fmu"))
    assert len(built) == 2 and all(n.endswith(("Plant.fmu", "Kalman.fmu")) for n in built)
    for name in built:
        assert not read_model_description(str(tmp_path / name)).coSimulation.needsExecutionTool
        # the same bytes as the session's native build of the same plan
        assert (tmp_path / name).read_bytes() == native_fmus[name[:-4]].read_bytes()
    with pytest.raises(SystemExit):
        main(["build", "--backend", "cython", "--out", str(tmp_path)])
    assert "invalid choice: 'cython'" in capsys.readouterr().err


def test_reproduce_with_the_native_backend(native_fmus, tmp_path):
    from lpvest.core._errors import ArgumentError
    from lpvest.experiments._fmus import ExperimentFmus, as_experiment_fmus
    from lpvest.experiments._reproduce import reproduce

    cache = ExperimentFmus(tmp_path / "cache", backend="native")
    cache.adopt(native_fmus.paths)
    runs = reproduce(["cox-toth-truncation", "peixoto-fig1"], tmp_path, fmus=cache, reduced=True)
    # every FMU quantity agrees with the library within the report's tolerance (1e-12 of scale)
    assert all(r.ok for r in runs) and {r.name for r in runs} == {"cox-toth-truncation", "peixoto-fig1"}
    assert sorted(cache.built) == ["PeixotoEx1HinfPDEps150", "PeixotoEx1HinfRobustEps150"]  # not adopted
    assert "(native backend)" in cache.summary()
    with zipfile.ZipFile(cache["PeixotoEx1HinfPDEps150"]) as z:
        assert "binaries/linux64/PeixotoEx1HinfPDEps150.so" in z.namelist()
    # a role the native backend supports, built by the cache itself: native, no Python inside (the cache
    # once built every FMU with pythonfmu and recorded it under the native fingerprint)
    fresh = ExperimentFmus(tmp_path / "fresh", backend="native")
    with zipfile.ZipFile(fresh["PeixotoEx1Scheduler"]) as z:
        assert "binaries/linux64/PeixotoEx1Scheduler.so" in z.namelist()
        assert [n for n in z.namelist() if n.endswith(".py")] == []
    with pytest.raises(ArgumentError, match="builds with backend 'native', not 'pythonfmu'"):
        as_experiment_fmus(cache, backend="pythonfmu")
    with pytest.raises(ArgumentError, match="backend 'cython' is not one of pythonfmu, native"):
        ExperimentFmus(tmp_path / "other", backend="cython")
