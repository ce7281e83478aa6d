"""The filter FMUs against the lpvest library on the same data.

Each FMU is driven sample by sample through fmpy's FMU2Slave: the inputs of
sample k are set, the outputs read before fmi2DoStep (the estimates at k, no
one-step delay), then fmi2DoStep. The library's streaming filter, fed the
same samples, is the reference.
"""

from __future__ import annotations

import numpy as np
import pytest

from lpvest import load_system
from lpvest.estimators.base import StreamingEstimator
from tests.fmu_driver import Driver


def _truncation_data(T: int, seed: int = 3) -> dict[str, np.ndarray]:
    model = load_system("cox-toth-truncation").model()
    k = np.arange(T)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=seed).y
    return {"p": p, "u": u, "y": y}


def _kalman() -> StreamingEstimator:
    from lpvest.estimators.kalman import LPVKalmanFilter

    return LPVKalmanFilter(load_system("cox-toth-truncation").model())


def _truncated(tau: int = 4) -> StreamingEstimator:
    from lpvest.estimators.truncated import TruncatedKalmanFilter

    return TruncatedKalmanFilter(load_system("cox-toth-truncation").model(), tau, start="theorem")


def _sridhar_data(T: int) -> dict[str, np.ndarray]:
    io = load_system("sridhar-ltv").model()
    t = np.arange(T) * 1e-3
    traj = io.simulate(t)
    return {"u": traj.u[:, None], "y": traj.y[:, None]}


def _observer() -> StreamingEstimator:
    from lpvest.estimators.bspline import BSplineObserver, KernelModel, UnknownConstant, UnknownSpline

    io = load_system("sridhar-ltv").model()
    model = KernelModel.from_io(io, a0=UnknownSpline(18), a1=UnknownConstant())
    return BSplineObserver(model, dt=1e-3, window=0.4, hop=0.1, on_unidentifiable="hold")


def _peixoto_data(T: int) -> dict[str, np.ndarray]:
    plant = load_system("peixoto-ex1").model()
    k = np.arange(T)
    theta = np.sin(0.25 * k)[:, None]
    w = np.where(k >= 10, np.sin(0.5 * k) * np.exp(-0.1 * k), 0.0)[:, None]
    y = plant.simulate(plant.alpha_batch(theta), w).y
    return {"p": theta, "y": y}


def _hinf_from_fmu(name: str) -> StreamingEstimator:
    """The library's HinfFilter on the design the FMU carries (designed at build time)."""
    import zipfile

    from lpvest.design import HinfDesign
    from lpvest.estimators.hinf import HinfFilter

    with zipfile.ZipFile(FMU_PATHS[name]) as z:
        design = HinfDesign.from_json(z.read("resources/design.json").decode())
    plant = load_system("peixoto-ex1").model()
    return HinfFilter(design, simplex_map=plant.simplex_map if design.scheduled else None)


FMU_PATHS: dict[str, object] = {}


@pytest.fixture(autouse=True)
def _paths(fmus):
    FMU_PATHS.update(fmus.paths)


def _peixoto_robust_data(T: int) -> dict[str, np.ndarray]:
    return {"y": _peixoto_data(T)["y"]}


#: FMU -> (library estimator, FMU parameters, data, number of samples, step size)
FILTERS = {
    "CoxTothTruncationKalman": (_kalman, {}, _truncation_data, 60, 1.0),
    "CoxTothTruncationTruncatedKalman": (lambda: _truncated(4), {"tau": 4}, _truncation_data, 60, 1.0),
    # a short window (0.4 s) so that the test sees several refits in 700 samples
    "SridharLtvBSplineObserver": (_observer, {"window": 0.4, "hop": 0.1}, _sridhar_data, 700, 1e-3),
    "PeixotoEx1HinfPD": (lambda: _hinf_from_fmu("PeixotoEx1HinfPD"), {}, _peixoto_data, 60, 1.0),
    "PeixotoEx1HinfRobust": (lambda: _hinf_from_fmu("PeixotoEx1HinfRobust"), {}, _peixoto_robust_data, 60, 1.0),
}


def _feed(d: Driver, inputs: dict[str, np.ndarray], k: int) -> None:
    for name, arr in inputs.items():
        assert d.set_vector(name, arr[k]) == 0, d.errors()


def _read(d: Driver, est: StreamingEstimator) -> dict[str, np.ndarray]:
    return {p.name: d.vector(p.name).reshape(p.shape) for p in est.output_ports}


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_filter_fmu_gives_the_library_numbers(fmus, name):
    make, params, data, T, h = FILTERS[name]
    est = make()
    inputs = data(T)
    d = Driver(fmus[name])
    assert d.initialize(**params) == 0, d.errors()
    for k in range(T):
        _feed(d, inputs, k)
        got = _read(d, est)
        want = est.step({n: v[k] for n, v in inputs.items()})
        for port in est.output_ports:
            # the same operations in the same order: bit for bit
            assert np.array_equal(got[port.name], np.asarray(want[port.name]).reshape(port.shape)), (k, port.name)
        assert d.step(k * h, h) == 0, d.errors()
    d.free()


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_filter_fmu_state_round_trips(fmus, name):
    make, params, data, T, h = FILTERS[name]
    half = T // 2 if T < 100 else 450  # the observer: save mid-way, after its first refit
    inputs = data(T)
    est = make()

    def run(d: Driver, k0: int, k1: int) -> np.ndarray:
        rows = []
        for k in range(k0, k1):
            _feed(d, inputs, k)
            rows.append(np.concatenate([d.vector(p.name).ravel() for p in est.output_ports]))
            assert d.step(k * h, h) == 0
        return np.array(rows)

    d = Driver(fmus[name], "a")
    assert d.initialize(**params) == 0
    run(d, 0, half)
    state = d.fmu.getFMUstate()
    blob = d.fmu.serializeFMUstate(state)
    first = run(d, half, T)
    d.fmu.setFMUstate(state)
    assert np.array_equal(first, run(d, half, T))
    d.fmu.freeFMUstate(state)
    d.free()
    fresh = Driver(fmus[name], "b")
    assert fresh.initialize(**params) == 0
    restored = fresh.fmu.deSerializeFMUstate(blob)
    fresh.fmu.setFMUstate(restored)
    assert np.array_equal(first, run(fresh, half, T))
    fresh.fmu.freeFMUstate(restored)
    fresh.free()


@pytest.mark.parametrize(("name", "port", "value", "expected"), [
    ("CoxTothTruncationKalman", "y", np.nan, r"y\[1\]"),
    ("CoxTothTruncationKalman", "p", 1.5, r"p\[1\].*outside its declared range"),
    ("CoxTothTruncationTruncatedKalman", "y", np.inf, r"y\[1\]"),
    ("PeixotoEx1HinfPD", "p", -1.01, r"p\[1\].*outside its declared range"),
    ("PeixotoEx1HinfRobust", "y", np.nan, r"y\[1\]"),
])
def test_bad_sample_is_fmi2error_and_the_filter_continues_unharmed(fmus, name, port, value, expected):
    make, params, data, _, _ = FILTERS[name]
    inputs = data(12)
    est = make()
    d = Driver(fmus[name])
    assert d.initialize(**params) == 0
    for k in range(12):
        _feed(d, inputs, k)
        if k == 6:  # a rejected sample, then the good one again
            bad = inputs[port][k].copy()
            bad[0] = value
            assert d.set_vector(port, bad) == 3
            assert any(__import__("re").search(expected, m) for m in d.errors()), d.errors()
            assert d.step(float(k), 1.0) >= 2  # no step on a rejected sample
            _feed(d, inputs, k)
        got = _read(d, est)
        want = est.step({n: v[k] for n, v in inputs.items()})
        for out in est.output_ports:
            np.testing.assert_array_equal(got[out.name], np.asarray(want[out.name]).reshape(out.shape))
        assert d.step(float(k), 1.0) == 0, d.errors()
    d.free()


def test_invalid_filter_parameter_is_fmi2error(fmus):
    d = Driver(fmus["CoxTothTruncationTruncatedKalman"])
    status = d.initialize(start="sometimes")
    assert status == 3
    assert any("start" in m and "sometimes" in m for m in d.errors()), d.errors()
    d.free()


def test_observer_fmu_refuses_a_communication_step_other_than_dt(fmus):
    d = Driver(fmus["SridharLtvBSplineObserver"])
    assert d.initialize() == 0
    d.set_vector("u", 0.0)
    d.set_vector("y", 0.0)
    assert d.step(0.0, 0.01) >= 2
    assert any("communication step 0.01 s differs from the observer's sample time dt = 0.001 s" in m
               for m in d.errors()), d.errors()
    d.free()


@pytest.mark.parametrize(("param", "value", "expected"), [
    ("a0", "spline", "a0 = 'spline'; expected 'known', 'constant', 'spline:N' or 'spline:N:ORDER'"),
    ("a1", "known", "no unknown"),
])
def test_observer_fmu_invalid_declaration_is_fmi2error(fmus, param, value, expected):
    d = Driver(fmus["SridharLtvBSplineObserver"])
    params = {param: value}
    if param == "a1":
        params["a0"] = "known"
    assert d.initialize(**params) == 3
    assert any(expected in m for m in d.errors()), d.errors()
    d.free()


def test_hinf_fmu_design_is_certified_and_model_is_fixed(fmus):
    """The design carried by the FMU is the best-epsilon design (gamma as the
    library finds it); rho of Example 2 is not a parameter of its filter FMUs,
    whose design holds for the build-time rho only."""
    import zipfile

    from lpvest.design import HinfDesign

    with zipfile.ZipFile(fmus["PeixotoEx1HinfPD"]) as z:
        d = HinfDesign.from_json(z.read("resources/design.json").decode())
    assert d.kind == "parameter-dependent"
    assert d.lmi_margin > 0 and d.lyapunov_margin > 0
    assert d.gamma == pytest.approx(1.2137, abs=2e-4)  # best epsilon (Table 1 best row)
    plant_vars = {v.name for v in Driver(fmus["PeixotoEx2Plant"]).md.modelVariables}
    filt_vars = {v.name for v in Driver(fmus["PeixotoEx2HinfPD"]).md.modelVariables}
    assert "rho" in plant_vars and "rho" not in filt_vars


def test_recording_a_vector_that_shares_its_name_with_a_string_parameter(fmus):
    """The observer FMU has a String parameter ``a0`` (its declaration) and an
    output ``a0[1]`` (the estimate): recording ``obs.a0`` means the estimate;
    a name that selects only a String is an error, not a silently empty record."""
    from lpvest.cosim import Component, CoSimulation, CoSimulationError

    comps = [Component("obs", fmus["SridharLtvBSplineObserver"])]
    with CoSimulation(comps, [], step_size=1e-3, record=["obs.a0", "obs.valid"]) as sim:
        assert sim.recorded == ["obs.a0[1]", "obs.valid[1]"]
    sched = [Component("sched", fmus["PeixotoEx1Scheduler"])]
    with pytest.raises(CoSimulationError, match="recorded variable 'sched.kind' is a String"):
        CoSimulation(sched, [], step_size=1.0, record=["sched.kind"])
