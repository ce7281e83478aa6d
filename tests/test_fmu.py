"""The FMUs: validation, same numbers as the library, FMI behaviour, bad input.

Every FMU is driven step by step through fmpy's FMU2Slave (tests/fmu_driver.py)
and compared with an independent computation in the library (the batch
``simulate`` methods, the signals' formulas, another realization of the same
system).
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._rng import Stream
from lpvest.fmi._build import validate_fmus
from tests.fmu_driver import Driver
from tests.tolerances import roundoff

EXPECTED = {
    "CoxTothEx1Plant", "CoxTothEx1Scheduler", "CoxTothEx1Source",
    "CoxTothTruncationPlant", "CoxTothTruncationScheduler", "CoxTothTruncationSource",
    "CoxTothTruncationKalman", "CoxTothTruncationTruncatedKalman",
    "CoxTothTruncationHinfPD", "CoxTothTruncationHinfRobust",
    "PeixotoEx1Plant", "PeixotoEx1Scheduler", "PeixotoEx1Source", "PeixotoEx1HinfPD", "PeixotoEx1HinfRobust",
    "PeixotoEx2Plant", "PeixotoEx2Scheduler", "PeixotoEx2Source", "PeixotoEx2HinfPD", "PeixotoEx2HinfRobust",
    "SridharLtvPlant", "SridharLtvBSplineObserver",
    "AffineDemoPlant", "AffineDemoScheduler", "AffineDemoSource", "AffineDemoKalman", "AffineDemoTruncatedKalman",
    "AffineDemoHinfPD", "AffineDemoHinfRobust",
    "PeixotoEx1MovingAverage",
    "IoDemoPlant",
}


def theta(k):
    return np.sin(0.25 * np.asarray(k, dtype=float))


def paper_w(k):
    k = np.asarray(k, dtype=float)
    return np.where(k >= 10, np.sin(0.5 * k) * np.exp(-0.1 * k), 0.0)  # Peixoto et al., Section 4


def run_plant(d: Driver, inputs: dict[str, np.ndarray], outputs: list[str], h: float = 1.0) -> dict[str, np.ndarray]:
    """Set the inputs of each sample, read the outputs before fmi2DoStep, step."""
    T = len(next(iter(inputs.values())))
    rec = {o: [] for o in outputs}
    for k in range(T):
        for name, seq in inputs.items():
            assert d.set_vector(name, seq[k]) == 0
        for o in outputs:
            rec[o].append(d.vector(o))
        assert d.step(k * h, h) == 0, d.errors()
    return {o: np.array(v) for o, v in rec.items()}


# -- validation ------------------------------------------------------------------


def test_the_expected_fmus_are_built(fmus):
    assert set(fmus.paths) == EXPECTED


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_fmu_validates_with_zero_problems(fmus, name):
    (result,) = validate_fmus([fmus[name]])
    assert result.problems == []
    assert result.outputs > 0


def z_read(path, name):
    with zipfile.ZipFile(path) as z:
        return z.read(name)


def test_each_variable_description_names_its_element_once(fmus):
    """A variable's description is its port's, then the element's label once:
    HinfPD's scheduling input reads "physical scheduling (theta)", never with
    the label repeated (the port's description used to list the names too)."""
    import re

    for name, path in sorted(fmus.paths.items()):
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        for sv in root.iter("ScalarVariable"):
            text = sv.get("description") or ""
            assert not re.search(r"(\([^()]*\)) \1", text), (name, sv.get("name"), text)
    with zipfile.ZipFile(fmus["PeixotoEx1HinfPD"]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    described = {sv.get("name"): sv.get("description") for sv in root.iter("ScalarVariable")}
    assert described["p[1]"] == "physical scheduling (theta)"


def test_model_description_declares_ranges_dependencies_and_capabilities(fmus):
    with zipfile.ZipFile(fmus["PeixotoEx1Plant"]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
        names = z.namelist()
    cs = root.find("CoSimulation")
    assert cs.get("canGetAndSetFMUstate") == "true" and cs.get("canSerializeFMUstate") == "true"
    var = {sv.get("name"): (i + 1, sv) for i, sv in enumerate(root.iter("ScalarVariable"))}
    p = var["p[1]"][1].find("Real")
    assert (float(p.get("min")), float(p.get("max"))) == (-1.0, 1.0)  # theta in [-1, 1]
    deps = {u.get("index"): u.get("dependencies") for u in root.find("ModelStructure/Outputs")}
    inputs = sorted(str(var[n][0]) for n in ("p[1]", "w[1]"))
    assert deps[str(var["x[1]"][0])] == ""  # the state does not feed through
    assert sorted(deps[str(var["y[1]"][0])].split()) == inputs
    initial = {u.get("index") for u in root.find("ModelStructure/InitialUnknowns")}
    assert initial == set(deps)
    # the FMU's own copy of lpvest, under a build-unique name (lpvest.fmi._bundle), never the plain name
    # a model parameter with a declared range (models/peixoto_ex2.toml) declares it
    ex2 = ET.fromstring(z_read(fmus["PeixotoEx2Plant"], "modelDescription.xml"))
    (rho,) = [sv for sv in ex2.iter("ScalarVariable") if sv.get("name") == "rho"]
    assert (rho.get("causality"), float(rho.find("Real").get("min")), float(rho.find("Real").get("max"))) == (
        "parameter", 1.0, 21.0)
    assert "the paper's range" in rho.get("description")
    package = json.loads(z_read(fmus["PeixotoEx1Plant"], "resources/lpvest_fmu.json"))["package"]
    assert package.startswith("lpvest_") and f"resources/{package}/__init__.py" in names
    assert not any(n.startswith(("resources/lpvest/", "resources/pythonfmu/")) for n in names)
    assert "resources/requirements.txt" in names and "resources/manifest.json" in names
    assert "binaries/linux64/PeixotoEx1Plant.so" in names
    # a discrete-time plant: outputs piecewise constant, one fmi2DoStep per sample
    assert var["y[1]"][1].get("variability") == "discrete"
    assert cs.get("canHandleVariableCommunicationStepSize") == "false"
    assert root.find("DefaultExperiment").get("stepSize") == "1.0"


# -- same numbers as the library -------------------------------------------------------


@pytest.mark.parametrize(("name", "system", "rho"), [
    ("PeixotoEx1Plant", "peixoto-ex1", None),
    ("PeixotoEx2Plant", "peixoto-ex2", 5.0),
])
def test_polytopic_plant_is_bit_for_bit_the_library(fmus, name, system, rho):
    T = 120
    k = np.arange(T)
    d = Driver(fmus[name])
    assert d.initialize(**({"rho": rho} if rho is not None else {})) == 0
    got = run_plant(d, {"p": theta(k)[:, None], "w": paper_w(k)[:, None]}, ["y", "z", "x"])
    d.free()
    plant = load_system(system, parameters={"rho": rho} if rho is not None else None).model()
    ref = plant.simulate(plant.alpha_batch(theta(k)[:, None]), paper_w(k)[:, None])
    # the same operations as PolytopicLPV.simulate (batch einsum): bit for bit
    assert np.array_equal(got["y"], ref.y) and np.array_equal(got["z"], ref.z) and np.array_equal(got["x"], ref.x)


SHIFTED_BOX = """
[system]
name = "shifted-box"
title = "Peixoto Example 1 with its scheduling box moved to [1, 3]: 0 is outside"
default = "plant"

[scheduling]
names = ["theta"]
lower = [1.0]
upper = [3.0]

[models.plant]
type = "polytopic"
map = { kind = "formulas", alpha = ["(3 - theta)/2", "(theta - 1)/2"] }
vertex = [{ A = [[0.43, 0.0], [1.0, 0.48]], Bw = [[2.0], [0.1]] },
          { A = [[0.1, 0.9], [0.0, 0.05]], Bw = [[1.0], [0.1]] }]
common = { Cz = [[1.0, 0.0], [0.0, 1.0]], Dz = [[0.0], [0.0]], Cy = [[1.0, 0.0]], Dy = [[1.0]] }
"""


def test_an_input_starts_inside_its_range_and_the_checks_made_at_set_are_not_repeated(tmp_path):
    # FMI: min <= start <= max; an input starts at the point of its range nearest to 0,
    # and the component, which skips the checks fmi2SetReal made, never sees a value
    # outside the range (an unset input included)
    from fmpy import read_model_description

    from lpvest.fmi._build import build_fmus

    (tmp_path / "shifted.toml").write_text(SHIFTED_BOX)
    (result,), _ = build_fmus([tmp_path / "shifted.toml"], tmp_path / "out", roles=["Plant"])
    assert result.validation.problems == []
    path = tmp_path / "out" / "ShiftedBoxPlant.fmu"
    starts = {v.name: (float(v.start), v.min, v.max) for v in read_model_description(str(path)).modelVariables
              if v.causality == "input"}
    assert starts == {"p[1]": (1.0, "1.0", "3.0"), "w[1]": (0.0, None, None)}
    plant = load_system(tmp_path / "shifted.toml").model()
    T = 40
    p = 2.0 + np.sin(0.25 * np.arange(T))[:, None]
    w = paper_w(np.arange(T))[:, None]
    d = Driver(path)
    assert d.initialize() == 0
    y0 = d.vector("y")
    assert d.step(0.0, 1.0) == 0, d.errors()  # nothing set: the start values, p = 1, w = 0
    ys, xs = [y0], [np.zeros(2)]
    for k in range(T):
        d.set_vector("p", p[k])
        d.set_vector("w", w[k])
        ys.append(d.vector("y"))
        xs.append(d.vector("x"))
        assert d.step(k + 1.0, 1.0) == 0, d.errors()
    d.free()
    ref = plant.simulate(plant.alpha_batch(np.vstack([[1.0], p])), np.vstack([[0.0], w]))
    assert np.array_equal(np.array(ys), ref.y) and np.array_equal(np.array(xs), ref.x)


@pytest.mark.blas_sensitive
def test_affine_plant_with_drawn_noise_matches_simulate(fmus):
    model = load_system(fmus.affine_model).model()
    T = 150
    k = np.arange(T)
    p = np.c_[0.9 * np.sin(0.1 * k), 1.0 + np.cos(0.2 * k)]
    u = np.cos(0.3 * k)[:, None]
    d = Driver(fmus["AffineDemoPlant"])
    assert d.initialize(seed=3) == 0
    got = run_plant(d, {"p": p, "u": u, "w": np.zeros((T, 2)), "v": np.zeros((T, 1))}, ["y", "x"])
    d.free()
    ref = model.simulate(p, u, rng=3)
    # same draws; the noise product and the matrices are evaluated one row at a
    # time instead of in one batch (BLAS rounding): round-off only, per step
    # sums of <= n_x + n_u + n_w + 2 products, over T steps, no growth assumed
    _assert_same_recursion(got, ref, T)


@pytest.mark.blas_sensitive
def test_affine_plant_with_external_noise_matches_simulate(fmus, rng):
    model = load_system(fmus.affine_model).model()
    T = 100
    k = np.arange(T)
    p = np.c_[np.sin(0.3 * k), 1.0 + np.sin(0.05 * k)]
    u, w, v = rng.standard_normal((T, 1)), rng.standard_normal((T, 2)), rng.standard_normal((T, 1))
    d = Driver(fmus["AffineDemoPlant"])
    assert d.initialize(noise=False) == 0
    got = run_plant(d, {"p": p, "u": u, "w": w, "v": v}, ["y", "x"])
    d.free()
    ref = model.simulate(p, u, w=w, v=v)
    _assert_same_recursion(got, ref, T)


def _assert_same_recursion(got, ref, T):
    """A plant FMU against the library's batch simulation: the same recursion,
    rounded in another order (per step sums of at most 6 products: matrices
    from the basis, then A x + B u + G w and C x + D u + H v), over T steps
    with no growth assumed; relative to the trajectories' size."""
    for name in ("y", "x"):
        want = getattr(ref, name)
        np.testing.assert_allclose(got[name], want, rtol=0, atol=roundoff(np.max(np.abs(want)), 2 * T, n=6))


@pytest.mark.blas_sensitive
def test_cox_toth_plant_equals_the_input_output_realization(fmus, rng):
    """The plant realizes (21c); (21a) with the same u, p, e gives the same y
    (Cox & Toth: the three realizations agree to machine precision)."""
    system = load_system("cox-toth-ex1")
    T = 200
    k = np.arange(T)
    p = (0.5 + 0.4 * np.sin(0.3 * k))[:, None]
    u = rng.standard_normal((T, 1))
    d = Driver(fmus["CoxTothEx1Plant"])
    assert d.initialize(seed=11) == 0
    got = run_plant(d, {"p": p, "u": u, "e": np.zeros((T, 1))}, ["y", "x"])
    d.free()
    e = Stream(11).normal((T, 1))  # Omega = 1: the documented draw order
    ref_c = system.model("augmented").simulate(p, u, rng=11)
    assert np.array_equal(got["y"], ref_c.y)
    ref_a = system.model("io").simulate(p, u, e=e)
    # another realization of the same map: per step sums of <= 4 products, over
    # T steps (stable: no growth assumed)
    np.testing.assert_allclose(got["y"], ref_a.y, rtol=0, atol=roundoff(np.max(np.abs(ref_a.y)), T, n=4))


def test_ltv_plant_integrates_accurately_over_any_step(fmus):
    ss = load_system("sridhar-ltv").model().to_state_space()
    ref = ss.simulate(np.linspace(0.0, 10.0, 101))  # DOP853, rtol 1e-12, one solve with dense output
    scale = np.max(np.abs(ref.y))
    outs = {}
    for h in (0.1, 0.5):
        d = Driver(fmus["SridharLtvPlant"])
        assert d.initialize() == 0
        n = int(round(10.0 / h))
        ys, us = [], []
        for i in range(n + 1):
            ys.append(d.get("y[1]"))
            us.append(d.get("u_applied[1]"))
            if i < n:
                assert d.step(i * h, h) == 0
        d.free()
        outs[h] = np.array(ys)
        t = np.arange(n + 1) * h
        # t_i = i h here, a sum of up to n steps in the FMU: |dt| <= n eps t;
        # sin is 1-Lipschitz and rounds once; times the amplitude 120
        np.testing.assert_allclose(us, 120 * np.sin(t), rtol=0, atol=roundoff(120 * (1 + t[-1]), n))
    # the plant's integration (kept from step to step) and one batch solve_ivp run
    # differ by the integrator's local errors (rtol 1e-12): 1e-9 of the signal's
    # scale bounds that over the ~400 steps of each
    np.testing.assert_allclose(outs[0.1], ref.y, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(outs[0.5], ref.y[::5], rtol=0, atol=1e-9 * scale)


def test_ltv_plant_holds_its_input_when_asked(fmus):
    d = Driver(fmus["SridharLtvPlant"])
    assert d.initialize(use_model_input=False) == 0
    for i in range(5):
        assert d.set_vector("u", 0.0) == 0
        assert d.get("u_applied[1]") == 0.0
        assert d.step(0.2 * i, 0.2) == 0
    assert d.get("y[1]") == 0.0 and np.all(d.vector("x") == 0.0)  # at rest with u = 0
    assert d.set_vector("u", 3.0) == 0
    assert d.get("u_applied[1]") == 3.0
    d.free()


def test_scheduler_default_is_the_papers_sinusoid(fmus):
    d = Driver(fmus["PeixotoEx1Scheduler"])
    assert d.initialize() == 0
    p, alpha = [], []
    for k in range(60):
        p.append(d.get("p[1]"))
        alpha.append(d.vector("alpha"))
        assert d.step(float(k), 1.0) == 0
    d.free()
    p = np.array(p)
    # theta_k = sin(0.25 k): the argument (size <= 15) and sin round once each;
    # alpha = (1 -+ p) / 2 once more
    tol = roundoff(1.0 + 0.25 * 60, 1)
    np.testing.assert_allclose(p, theta(np.arange(60)), rtol=0, atol=tol)
    np.testing.assert_allclose(np.array(alpha), np.c_[(1 - p) / 2, (1 + p) / 2], rtol=0, atol=roundoff(1.0, 2))


def test_scheduler_random_kind_has_bounded_rate_and_is_seeded(fmus):
    from lpvest.core._signals import SignalSpec, sample_signal

    d = Driver(fmus["AffineDemoScheduler"])
    assert d.initialize(kind="random", seed=4, **{"rate[1]": 0.3, "rate[2]": 0.1}) == 0
    got = []
    for k in range(200):
        got.append(d.vector("p"))
        assert d.step(0.5 * k, 0.5) == 0
    d.free()
    got = np.array(got)
    assert np.all(np.abs(np.diff(got, axis=0)) <= np.array([0.3, 0.1]) * 0.5 + 1e-15)
    assert np.all(got >= [-1.0, 0.0]) and np.all(got <= [1.0, 2.0])
    spec = SignalSpec.build("random", 2, rate=[0.3, 0.1], offset=[0.0, 1.0], lower=[-1, 0], upper=[1, 2], seed=4)
    assert np.array_equal(got, sample_signal(spec, 0.5 * np.arange(200)))


def test_scheduler_table_is_piecewise_linear(fmus):
    d = Driver(fmus["PeixotoEx1Scheduler"])
    assert d.initialize(kind="table", table="0 -1; 10 1; 20 0.5") == 0
    got = []
    for k in range(30):
        got.append(d.get("p[1]"))
        assert d.step(float(k), 1.0) == 0
    d.free()
    # linear interpolation between table values of size <= 1: a few roundings
    np.testing.assert_allclose(got, np.interp(np.arange(30.0), [0, 10, 20], [-1, 1, 0.5]), rtol=0,
                               atol=roundoff(1.0, 3))


def test_source_default_is_the_papers_disturbance_and_gaussian_is_seeded(fmus):
    d = Driver(fmus["PeixotoEx1Source"])
    assert d.initialize() == 0
    w = []
    for k in range(40):
        w.append(d.get("w[1]"))
        assert d.step(float(k), 1.0) == 0
    d.free()
    # the paper's formula evaluated twice (exp, sin: one rounding each, a product)
    np.testing.assert_allclose(w, paper_w(np.arange(40)), rtol=roundoff(1.0, 3), atol=0)
    d = Driver(fmus["AffineDemoSource"])
    assert d.initialize(**{"u.kind": "gaussian", "u.seed": 9, "u.std[1]": 2.0}) == 0
    u = []
    for k in range(40):
        u.append(d.get("u[1]"))
        assert d.step(float(k), 1.0) == 0
    d.free()
    assert np.array_equal(u, 2.0 * Stream(9).normal((40, 1))[:, 0])


def test_moving_average_estimator_fmu_matches_the_protocol(fmus, rng):
    from tests.fmu_movavg import MovingAverage

    T, window = 30, 5
    y = rng.standard_normal(T)
    d = Driver(fmus["PeixotoEx1MovingAverage"])
    assert d.initialize(window=window) == 0
    got = run_plant(d, {"p": np.full((T, 1), 0.3), "y": y[:, None]}, ["yhat", "S"])
    d.free()
    for k in range(T):  # independent oracle: the mean of the last samples, y_k included
        win = y[max(0, k - window + 1): k + 1]
        # means of <= window terms, summed in another order: gamma_window of sum |terms|
        assert got["yhat"][k, 0] == pytest.approx(win.mean(), rel=0, abs=roundoff(np.mean(np.abs(win)), 1, n=window))
        assert got["S"][k, 0] == pytest.approx(np.mean(win**2), rel=roundoff(1.0, 2, n=window))
    est = MovingAverage(1, 1, window)
    ref = [est.step({"p": [0.3], "y": [v]})["yhat"][0] for v in y]
    assert np.array_equal(got["yhat"][:, 0], ref)  # the same code path: bit for bit


def test_matrix_ports_use_structured_names(fmus):
    from fmpy import read_model_description

    md_names = {v.name for v in read_model_description(str(fmus["PeixotoEx1MovingAverage"])).modelVariables}
    assert {"S[1,1]", "yhat[1]", "count", "p[1]", "y[1]", "window"} <= md_names


# -- FMI behaviour -----------------------------------------------------------------------------


def test_direct_feedthrough_reads_correctly_before_do_step(fmus):
    plant = load_system("peixoto-ex1").model()
    d = Driver(fmus["PeixotoEx1Plant"])
    assert d.initialize() == 0
    for k in range(15):
        d.set_vector("p", theta(k))
        d.set_vector("w", paper_w(k))
        d.step(float(k), 1.0)
    x = d.vector("x")
    for w in (0.7, -0.2):  # set the inputs of sample k, read before fmi2DoStep
        d.set_vector("p", 0.4)
        d.set_vector("w", w)
        m = plant.at(plant.alpha([0.4]))
        # C x + D w (3 products) from the same x, matrices from the same vertices
        size = float(np.max(np.abs(x))) + abs(w)
        np.testing.assert_allclose(d.vector("y"), m.Cy @ x + m.Dy @ [w], rtol=0, atol=roundoff(size, 2, n=3))
        np.testing.assert_allclose(d.vector("z"), m.Cz @ x + m.Dz @ [w], rtol=0, atol=roundoff(size, 2, n=3))
        assert np.array_equal(d.vector("x"), x)  # reading does not advance the state
    assert d.step(15.0, 1.0) == 0
    np.testing.assert_allclose(d.vector("x"), m.A @ x + m.Bw @ [-0.2], rtol=0,
                               atol=roundoff(float(np.max(np.abs(x))) + 0.3, 2, n=3))
    d.free()


def _drive(d: Driver, name: str, k0: int, n: int) -> np.ndarray:
    """n steps of deterministic inputs for the FMU ``name``; the outputs read at each."""
    md_out = [v.name for v in d.md.modelVariables if v.causality == "output"]
    h = 0.1 if name == "SridharLtvPlant" else 1.0
    rows = []
    for k in range(k0, k0 + n):
        if "Plant" in name and name != "SridharLtvPlant":
            d.set_vector("p", 0.5 + 0.3 * np.sin(k))
            for port in ("u", "w", "e", "v"):
                if f"{port}[1]" in d.vr:
                    d.set_vector(port, np.full(sum(n.startswith(port + "[") for n in d.vr), np.cos(k)))
        if name == "PeixotoEx1MovingAverage":
            d.set_vector("p", 0.1)
            d.set_vector("y", np.sin(k))
        rows.append(d.outputs(md_out))
        assert d.step(k * h, h) == 0, d.errors()
    return np.array(rows)


STATEFUL = {
    "CoxTothEx1Plant": {"seed": 5},  # random generator state
    "AffineDemoPlant": {"seed": 2},
    "PeixotoEx1Scheduler": {"kind": "random", "seed": 3},
    "AffineDemoSource": {"u.kind": "gaussian", "u.seed": 1, "w.kind": "gaussian"},
    "PeixotoEx1MovingAverage": {"window": 6},  # a window of samples
    "SridharLtvPlant": {},
}


@pytest.mark.parametrize("name", sorted(STATEFUL))
def test_state_get_set_and_serialize_continue_identically(fmus, name):
    d = Driver(fmus[name], "a")
    assert d.initialize(**STATEFUL[name]) == 0
    _drive(d, name, 0, 12)
    state = d.fmu.getFMUstate()
    blob = d.fmu.serializeFMUstate(state)
    first = _drive(d, name, 12, 10)
    d.fmu.setFMUstate(state)
    again = _drive(d, name, 12, 10)
    assert np.array_equal(first, again)
    d.fmu.freeFMUstate(state)
    d.free()
    fresh = Driver(fmus[name], "b")  # a new instance with default parameters
    assert fresh.initialize() == 0
    restored = fresh.fmu.deSerializeFMUstate(blob)
    fresh.fmu.setFMUstate(restored)
    assert np.array_equal(first, _drive(fresh, name, 12, 10))
    fresh.fmu.freeFMUstate(restored)
    fresh.free()


def test_reset_starts_over(fmus):
    d = Driver(fmus["CoxTothEx1Plant"])
    assert d.initialize(seed=8) == 0
    first = _drive(d, "CoxTothEx1Plant", 0, 10)
    assert d.status(d.fmu.reset) == 0
    assert d.get("seed") == 0  # parameters are back at their start values
    assert d.initialize(seed=8) == 0
    assert np.array_equal(first, _drive(d, "CoxTothEx1Plant", 0, 10))
    d.free()


def test_two_instances_side_by_side_are_independent(fmus):
    system = load_system("cox-toth-ex1")
    a, b = Driver(fmus["CoxTothEx1Plant"], "a"), Driver(fmus["CoxTothEx1Plant"], "b")
    assert a.initialize(seed=1) == 0 and b.initialize(seed=2) == 0
    T = 40
    p = (0.3 + 0.5 * np.cos(0.2 * np.arange(T)))[:, None]
    u = np.sin(np.arange(T))[:, None]
    ya, yb = [], []
    for k in range(T):  # interleaved, with different inputs
        for d, uk, out in ((a, u[k], ya), (b, -u[k], yb)):
            d.set_vector("p", p[k])
            d.set_vector("u", uk)
            d.set_vector("e", 0.0)
            out.append(d.get("y[1]"))
            assert d.step(float(k), 1.0) == 0
    a.free()
    b.free()
    model = system.model("augmented")
    assert np.array_equal(ya, model.simulate(p, u, rng=1).y[:, 0])
    assert np.array_equal(yb, model.simulate(p, -u, rng=2).y[:, 0])


# -- bad input ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("port", "value", "expected"), [
    ("w", math.nan, "input w[1] = nan is not finite"),
    ("p", math.inf, "input p[1] (theta) = inf is not finite"),
    ("p", 1.5, "input p[1] (theta) = 1.5 is outside its declared range [-1, 1]"),
])
def test_bad_input_is_fmi2error_naming_the_variable_and_the_state_is_kept(fmus, port, value, expected):
    plant = load_system("peixoto-ex1").model()
    d = Driver(fmus["PeixotoEx1Plant"])  # logging off: errors are still reported
    assert d.initialize() == 0
    for k in range(5):
        d.set_vector("p", theta(k))
        d.set_vector("w", paper_w(k))
        d.step(float(k), 1.0)
    x = d.vector("x")
    assert d.set_vector(port, value) == 3  # fmi2Error
    assert any(expected in m for m in d.errors()), d.errors()
    assert d.step(5.0, 1.0) == 3  # refuses to step on a rejected input
    assert any("fmi2DoStep refused" in m and f"{port}[1]" in m for m in d.errors())
    assert np.array_equal(d.vector("x"), x)
    # valid values again: the instance goes on from the kept state
    d.set_vector("p", theta(5))
    d.set_vector("w", paper_w(5))
    assert d.step(5.0, 1.0) == 0
    ref = plant.simulate(plant.alpha_batch(theta(np.arange(7))[:, None]), paper_w(np.arange(7))[:, None])
    assert np.array_equal(d.vector("x"), ref.x[6])
    d.free()


@pytest.mark.parametrize(("name", "params", "expected"), [
    ("PeixotoEx1Scheduler", {"amplitude[1]": 2.0},
     "amplitude[1] = 2 with offset[1] = 0 takes p[1] (theta) to [-2, 2], outside its declared range [-1, 1]"),
    ("PeixotoEx1Scheduler", {"kind": "triangle"}, "kind = 'triangle' is not a signal kind"),
    ("PeixotoEx1Scheduler", {"kind": "table", "table": "0 0.5; x 1"}, "table row 2"),
    ("PeixotoEx1Source", {"w.std[1]": -1.0, "w.kind": "gaussian"}, "w.std[1] = -1 must be >= 0"),
    ("CoxTothEx1Plant", {"seed": -1}, "parameter seed = -1 is outside its declared range [0, 2147483647]"),
    ("PeixotoEx1Plant", {"x0[2]": math.nan}, "parameter x0[2] = nan is not finite"),
    ("SridharLtvPlant", {"rtol": 0.0}, "parameter rtol = 0 is outside its declared range"),
    ("PeixotoEx2Plant", {"rho": 25.0}, "parameter rho = 25 is outside its declared range [1, 21]"),
    ("PeixotoEx1MovingAverage", {"window": 2000}, "window = 2000 must lie in [1, 1000]"),
])
def test_invalid_parameter_is_fmi2error_naming_it_and_the_instance_can_be_freed(fmus, name, params, expected):
    d = Driver(fmus[name])
    assert d.initialize(**params) == 3
    assert any(expected in m for m in d.errors()), d.errors()
    assert d.step(0.0, 1.0) == 3  # never initialized: no step
    assert any("fmi2DoStep refused" in m for m in d.errors())
    d.free()
    again = Driver(fmus[name])  # the process goes on: a new instance works
    assert again.initialize() == 0 and again.step(0.0, again.step_size) == 0
    again.free()


def test_wrong_use_is_reported_not_fatal(fmus):
    d = Driver(fmus["PeixotoEx1Plant"])
    assert d.initialize() == 0
    assert d.status(d.fmu.setReal, [d.vr["y[1]"]], [1.0]) == 3  # an output
    assert any("y[1] is an output" in m for m in d.errors())
    assert d.set("x0[1]", 1.0) == 3  # a fixed parameter after initialization
    assert any("x0[1] is fixed" in m for m in d.errors())
    assert d.status(d.fmu.getReal, [9999]) == 3
    assert d.step(0.0, 1.0) == 0  # none of it broke the instance
    d.free()


def test_requirements_list_what_the_fmu_imports(fmus):
    with zipfile.ZipFile(fmus["PeixotoEx1Plant"]) as z:
        assert z.read("resources/requirements.txt").decode().split() == ["numpy>=1.26"]
    with zipfile.ZipFile(fmus["SridharLtvPlant"]) as z:
        assert z.read("resources/requirements.txt").decode().split() == ["numpy>=1.26", "scipy>=1.11"]


# -- step semantics -------------------------------------------------------------------------------


@pytest.mark.parametrize(("case", "t", "h", "message"), [
    ("zero step", 3.0, 0.0, "the communication step h = 0 must be > 0"),
    ("negative step", 3.0, -1.0, "the communication step h = -1 must be > 0"),
    ("NaN step", 3.0, math.nan, "must be finite"),
    ("infinite time", math.inf, 1.0, "must be finite"),
    ("skipped point", 4.0, 1.0, "the communication point t = 4 is not the FMU's current time 3"),
    ("repeated point", 2.0, 1.0, "the communication point t = 2 is not the FMU's current time 3"),
    ("half a sample", 3.0, 0.5, "the communication step h = 0.5 is not a whole number of samples of the sample "
                                "time 1 (a step runs m >= 1 samples; set the parameter sample_time)"),
    ("two and a half samples", 3.0, 2.5, "the communication step h = 2.5 is not a whole number of samples"),
])
@pytest.mark.parametrize("name", ["PeixotoEx1Plant", "CoxTothTruncationKalman"])
def test_a_step_that_is_not_the_next_sample_is_an_error_and_consumes_nothing(fmus, name, case, t, h, message):
    from fmpy.fmi2 import fmi2LastSuccessfulTime

    d = Driver(fmus[name])
    assert d.initialize() == 0
    ports = [v for v in d.md.modelVariables if v.causality == "input"]

    def feed(k: int) -> None:  # some valid inputs of sample k
        for v in ports:
            mid = 0.5 * (float(v.min) + float(v.max)) if v.min is not None else 0.0
            assert d.set(v.name, mid + 0.1 * math.sin(k + v.valueReference)) == 0

    outputs = [v.name for v in d.md.modelVariables if v.causality == "output"]
    for k in range(3):
        feed(k)
        assert d.step(float(k), 1.0) == 0
    feed(3)
    before = d.outputs(outputs)
    assert d.step(t, h) == 3  # fmi2Error
    assert any(m.startswith(f"[{name}] fmi2DoStep refused") and message in m for m in d.errors()), d.errors()
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == 3.0
    assert np.array_equal(d.outputs(outputs), before)  # nothing consumed
    assert d.step(3.0, 1.0) == 0  # the valid step goes on
    # the same as an instance that never saw the bad step
    ref = Driver(fmus[name], "reference")
    assert ref.initialize() == 0
    d2, d = d, ref
    for k in range(4):
        feed(k)
        assert d.step(float(k), 1.0) == 0
    assert np.array_equal(d2.outputs(outputs), ref.outputs(outputs))
    d2.free()
    ref.free()


#: case -> (FMU, parameters): discrete-time FMUs, filters among them with the measurement one sample late
WHOLE_STEPS = {
    "plant": ("PeixotoEx1Plant", {}),
    "kalman": ("CoxTothTruncationKalman", {}),
    "kalman, measurement one sample late": ("CoxTothTruncationKalman", {"measurement_delay": 1}),
    "hinf, measurement one sample late": ("PeixotoEx1HinfPD", {"measurement_delay": 1}),
}  # the B-spline observer: test_observer_fmu_refuses_a_step_that_is_not_a_whole_number_of_samples


@pytest.mark.parametrize("case", sorted(WHOLE_STEPS))
def test_a_step_of_m_whole_samples_is_m_samples_with_the_inputs_held(fmus, case):
    """fmi2DoStep(t, m h) runs m samples with the inputs held (zero-order hold):
    afterwards every output reads what m one-sample steps with the same inputs
    give (a feedthrough output the value of the last sample consumed, the
    others their value at t + m h), to the bit, and the FMU's time is t + m h.
    Steps of different whole numbers of samples follow one another; with the
    measurement one sample late, each of the m samples pairs the held
    measurement with the held scheduling of the sample before."""
    from fmpy.fmi2 import fmi2LastSuccessfulTime

    name, params = WHOLE_STEPS[case]
    a, b = Driver(fmus[name], "a"), Driver(fmus[name], "b")
    assert a.initialize(**params) == 0 and b.initialize(**params) == 0
    h = a.step_size
    ports = [v for v in a.md.modelVariables if v.causality == "input"]
    outputs = [v.name for v in a.md.modelVariables if v.causality == "output"]
    t = 0
    for j, m in enumerate((3, 1, 2, 4, 5, 3)):
        for d in (a, b):
            for v in ports:
                mid = 0.5 * (float(v.min) + float(v.max)) if v.min is not None else 0.0
                assert d.set(v.name, mid + 0.3 * math.sin(j + v.valueReference)) == 0
        assert a.step(t * h, m * h) == 0, a.errors()
        for i in range(m):  # no input set in between: the same inputs again
            assert b.step((t + i) * h, h) == 0, b.errors()
        t += m
        assert np.array_equal(a.outputs(outputs), b.outputs(outputs)), (j, m)
        assert a.fmu.getRealStatus(fmi2LastSuccessfulTime) == pytest.approx(t * h, rel=1e-12)
    a.free()
    b.free()


def test_a_step_whose_later_sample_fails_is_refused_and_consumes_nothing(fmus):
    """A step of m samples is refused whole when one of its samples fails: here
    sample 2 of 2, whose output overflows (y_1 = C_y x_1 + D_y w with x_1 = B_w w,
    w = 1e308); nothing is consumed, and the step with a valid input goes on as
    in a fresh instance."""
    from fmpy.fmi2 import fmi2LastSuccessfulTime

    d = Driver(fmus["PeixotoEx1Plant"])
    assert d.initialize() == 0
    outputs = [v.name for v in d.md.modelVariables if v.causality == "output"]
    d.set_vector("p", 0.5)
    d.set_vector("w", 1e308)
    before = d.outputs(outputs)  # sample 0: y_0 = D_y w is finite
    assert np.all(np.isfinite(before))
    assert d.step(0.0, 2.0) == 3
    assert any("fmi2DoStep refused at t = 0 (h = 2, 2 samples): sample 2 of 2 (at t = 1): output y[1] is not "
               "finite (NaN or inf); nothing consumed" in m for m in d.errors()), d.errors()
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == 0.0
    assert np.array_equal(d.outputs(outputs), before)
    d.set_vector("w", 0.25)
    assert d.step(0.0, 2.0) == 0
    ref = Driver(fmus["PeixotoEx1Plant"], "reference")
    assert ref.initialize() == 0
    ref.set_vector("p", 0.5)
    ref.set_vector("w", 0.25)
    assert ref.step(0.0, 1.0) == 0 and ref.step(1.0, 1.0) == 0
    assert np.array_equal(d.outputs(outputs), ref.outputs(outputs))
    d.free()
    ref.free()


def test_no_step_and_no_input_after_terminate(fmus):
    from fmpy.fmi2 import fmi2LastSuccessfulTime

    d = Driver(fmus["PeixotoEx1Plant"])
    assert d.initialize() == 0
    assert d.step(0.0, 1.0) == 0
    assert d.raw("fmi2Terminate") == 0
    assert d.step(1.0, 1.0) == 3
    assert any("fmi2DoStep refused at t = 1 (h = 1): the FMU is terminated" in m for m in d.errors())
    assert d.set_vector("w", 1.0) == 3
    assert any("w[1] cannot be set after fmi2Terminate" in m for m in d.errors())
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == 1.0
    assert d.raw("fmi2Reset") == 0  # reset: a fresh instance, steps again
    assert d.initialize() == 0 and d.step(0.0, 1.0) == 0
    d.free()


def test_last_successful_time_follows_the_start_time_and_a_restored_state(fmus):
    from fmpy.fmi2 import fmi2LastSuccessfulTime

    d = Driver(fmus["PeixotoEx1Plant"])
    assert d.initialize(start_time=10.0) == 0
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == 10.0
    assert d.step(10.0, 1.0) == 0 and d.step(11.0, 1.0) == 0
    state = d.fmu.getFMUstate()
    assert d.step(12.0, 1.0) == 0
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == 13.0
    d.fmu.setFMUstate(state)
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == 12.0
    assert d.step(13.0, 1.0) == 3 and d.step(12.0, 1.0) == 0  # the restored time is the FMU's time
    d.fmu.freeFMUstate(state)
    d.free()


def test_an_output_that_would_be_inf_is_an_error_naming_it(fmus):
    """An overflow inside the component: numpy's warning reaches the FMI logger
    (fmi2Warning), reading the output is fmi2Error naming it, and the sample is
    not consumed."""
    d = Driver(fmus["PeixotoEx1Plant"])
    assert d.initialize() == 0
    for k in range(2):
        d.set_vector("p", 0.5)
        d.set_vector("w", 1e308)
        status = d.status(d.fmu.getReal, [d.vr["y[1]"]])
        if k == 0:
            assert status == 0 and d.step(0.0, 1.0) == 0  # y_0 = D_y w is finite, x_1 overflows
    assert status == 3
    assert any("output y[1] is not finite (NaN or inf) at t = 1" in m for m in d.errors()), d.errors()
    assert any(s == 1 and "numpy: floating-point overflow" in m for s, _, m in d.messages), d.messages
    assert d.step(1.0, 1.0) == 3
    state = d.fmu.getFMUstate()  # restored: still an error to read, still refused
    d.fmu.setFMUstate(state)
    d.fmu.freeFMUstate(state)
    assert d.status(d.fmu.getReal, [d.vr["y[1]"]]) == 3
    assert d.errors()[-1].endswith("output y[1] is not finite (NaN or inf) at t = 1")
    assert d.step(1.0, 1.0) == 3
    assert any("fmi2DoStep refused at t = 1 (h = 1): output y[1]" in m for m in d.errors())
    d.free()


def test_log_messages_are_capped(fmus):
    d = Driver(fmus["PeixotoEx1MovingAverage"])  # its error text is 4 kB long (tests/fmu_movavg.py)
    assert d.initialize(window=2000) == 3
    assert d.errors() and all(len(m) <= 1100 for m in d.errors())
    assert any("characters cut" in m for m in d.errors())
    d.free()


def test_discrete_time_fmus_declare_their_sample_time(fmus):
    """A step is a whole number of samples: the default experiment's step is the
    sample time, the FMU does not claim canHandleVariableCommunicationStepSize
    (a step that is not a whole number of samples is refused), and its outputs
    are piecewise constant."""
    for name in sorted(EXPECTED):
        root = ET.fromstring(z_read(fmus[name], "modelDescription.xml"))
        step = float(root.find("DefaultExperiment").get("stepSize"))
        cs = root.find("CoSimulation")
        variables = {sv.get("name"): sv for sv in root.iter("ScalarVariable")}
        outputs = [sv for sv in variables.values() if sv.get("causality") == "output"]
        if name.endswith(("Scheduler", "Source")) or name == "SridharLtvPlant":  # functions of time
            assert cs.get("canHandleVariableCommunicationStepSize") == "true", name
            assert all(sv.get("variability") is None for sv in outputs), name
        else:
            assert cs.get("canHandleVariableCommunicationStepSize") == "false", name
            assert all(sv.get("variability") == "discrete" for sv in outputs), name
            sample = "dt" if name.endswith("BSplineObserver") else "sample_time"
            assert float(variables[sample].find("Real").get("start")) == step, name


@pytest.mark.parametrize(("seed", "match"), [
    (2**40, r"seed: 1099511627776 is outside the range of an FMI Integer \[-2147483648, 2147483647\]"),
    (-(2**31) - 1, r"seed: -2147483649 is outside the range of an FMI Integer"),
    (math.inf, r"seed: expected an integer, found float inf"),
    (math.nan, r"seed: expected an integer, found float nan"),
])
def test_an_integer_parameter_outside_32_bits_is_an_error_not_a_wrap(fmus, seed, match):
    from lpvest.cosim import Component, CoSimulation, CoSimulationError

    with pytest.raises(CoSimulationError, match=match):
        CoSimulation([Component("plant", fmus["CoxTothEx1Plant"], {"seed": seed})], [], step_size=1.0)
    root = ET.fromstring(z_read(fmus["CoxTothEx1Plant"], "modelDescription.xml"))
    seed_var = next(sv for sv in root.iter("ScalarVariable") if sv.get("name") == "seed").find("Integer")
    assert (seed_var.get("min"), seed_var.get("max")) == ("0", "2147483647")
    with CoSimulation([Component("plant", fmus["CoxTothEx1Plant"], {"seed": 2**31 - 1})], [], step_size=1.0) as sim:
        assert sim.run(2).shape == (3,)


def test_affine_plant_draws_its_initial_state_from_its_x0_and_P0_parameters(fmus):
    """x_0 ~ N(x0, P0) from the FMU's parameters, drawn before the noise as
    AffineLPV.simulate draws it: the same seed, the same realization."""
    import dataclasses

    model = load_system(fmus.affine_model).model()
    x0, P0 = np.array([1.0, -0.5]), np.array([[0.5, 0.1], [0.1, 0.2]])
    T = 60
    k = np.arange(T)
    p = np.c_[0.9 * np.sin(0.1 * k), 1.0 + np.cos(0.2 * k)]
    u = np.cos(0.3 * k)[:, None]
    d = Driver(fmus["AffineDemoPlant"])
    params = {"x0[1]": x0[0], "x0[2]": x0[1], "P0[1,1]": P0[0, 0], "P0[1,2]": P0[0, 1], "P0[2,1]": P0[1, 0],
              "P0[2,2]": P0[1, 1]}
    assert d.initialize(seed=11, **params) == 0
    got = run_plant(d, {"p": p, "u": u, "w": np.zeros((T, 2)), "v": np.zeros((T, 1))}, ["y", "x"])
    d.free()
    ref = dataclasses.replace(model, x0=x0, P0=P0).simulate(p, u, rng=11)
    assert not np.allclose(ref.x[0], x0)  # drawn, not the mean
    # same draws; one row at a time instead of one batch (BLAS rounding): round-off only
    np.testing.assert_allclose(got["x"], ref.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(got["y"], ref.y, rtol=1e-12, atol=1e-14)


def test_every_user_cache_folder_follows_xdg_cache_home(monkeypatch, tmp_path):
    """The FMU cache, the native runtime's sources and reproduce's resume key all
    live under ``$XDG_CACHE_HOME/lpvest`` (one rule, lpvest.core._paths), and
    under ``~/.cache/lpvest`` when that variable is empty."""
    from lpvest.core._paths import user_cache_dir
    from lpvest.experiments._reproduce import _resume_secret
    from lpvest.fmi._cache import default_cache_dir
    from lpvest.fmi.native._build import _runtime_digest, _runtime_sources

    monkeypatch.delenv("LPVEST_FMU_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "lpvest" / "fmus"
    assert _runtime_sources(_runtime_digest()).parent == tmp_path / "xdg" / "lpvest" / "native-runtime"
    assert _resume_secret() == (tmp_path / "xdg" / "lpvest" / "resume.key").read_bytes()
    monkeypatch.setenv("XDG_CACHE_HOME", "")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert user_cache_dir("fmus") == default_cache_dir() == tmp_path / "home" / ".cache" / "lpvest" / "fmus"
