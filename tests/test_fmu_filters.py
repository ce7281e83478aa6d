"""The filter FMUs against the lpvest library on the same data.

Each FMU is driven sample by sample through fmpy's FMU2Slave: the inputs of
sample k are set, the outputs read before fmi2DoStep (the estimates at k, no
one-step delay), then fmi2DoStep. The library's streaming filter, fed the
same samples, is the reference.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._protocol import Sampled as StreamingEstimator
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
    from lpvest.estimators._truncated import TruncatedKalmanFilter

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
    from lpvest.estimators._hinf import HinfFilter

    with zipfile.ZipFile(FMU_PATHS[name]) as z:
        design = HinfDesign.from_json(z.read("resources/design.json").decode())
    plant = load_system("peixoto-ex1").model()
    return HinfFilter(design, simplex_map=plant.simplex_map if design.scheduled else None)


def _hinf_known_input(name: str, system: str) -> StreamingEstimator:
    """The library's HinfFilter, compensating u, on the design an affine model's
    H-infinity FMU carries (the model in its H-infinity setting)."""
    import zipfile

    from lpvest.design import HinfDesign
    from lpvest.estimators._hinf import HinfFilter
    from lpvest.systems._polytopic import hinf_setting

    with zipfile.ZipFile(FMU_PATHS[name]) as z:
        design = HinfDesign.from_json(z.read("resources/design.json").decode())
    plant = hinf_setting(load_system(system).model())
    return HinfFilter(design, simplex_map=plant.simplex_map, plant=plant)  # A(p) varies: both kinds take p


def _affine_demo_data(T: int) -> dict[str, np.ndarray]:
    model = load_system(FMU_PATHS["affine_model"]).model()
    k = np.arange(T)
    p = np.column_stack([np.sin(0.25 * k), 1.0 + np.cos(0.1 * k)])
    u = np.sin(0.1 * k)[:, None]
    return {"p": p, "u": u, "y": model.simulate(p, u, rng=4).y}


FMU_PATHS: dict[str, object] = {}


@pytest.fixture(autouse=True)
def _paths(fmus):
    FMU_PATHS.update(fmus.paths)
    FMU_PATHS["affine_model"] = fmus.affine_model


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
    # a model with general noise and a known input: the filters in its H-infinity setting, u compensated
    "CoxTothTruncationHinfPD": (lambda: _hinf_known_input("CoxTothTruncationHinfPD", "cox-toth-truncation"), {},
                                _truncation_data, 60, 1.0),
    "CoxTothTruncationHinfRobust": (lambda: _hinf_known_input("CoxTothTruncationHinfRobust", "cox-toth-truncation"),
                                    {}, _truncation_data, 60, 1.0),
    "AffineDemoHinfPD": (lambda: _hinf_known_input("AffineDemoHinfPD", FMU_PATHS["affine_model"]), {},
                         _affine_demo_data, 60, 1.0),
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
    # the delay's samples are kept: at most 100,000 (2**31 - 1 was accepted by the Python FMU and
    # allocated or refused by the native one as the host's memory allowed)
    for delay in (-1, 100_001, 2**31 - 1):
        d = Driver(fmus["PeixotoEx1HinfPD"])
        assert d.initialize(measurement_delay=delay) == 3
        assert any(f"parameter measurement_delay = {delay} is outside its declared range [0, 100000]; value rejected"
                   in m for m in d.errors()), d.errors()
        d.free()


@pytest.mark.parametrize("name", ["CoxTothTruncationKalman", "PeixotoEx1HinfPD", "CoxTothTruncationHinfRobust"])
def test_a_filter_with_its_measurement_late_saves_and_restores_its_kept_samples(fmus, name):
    """With measurement_delay = 1 the FMU state holds the filter's state and the
    scheduling and input kept for the next measurement: saved mid-run (also right
    after the first step, before any measurement), restored in the instance and
    deserialized in a fresh one, the run continues identically."""
    make, params, data, T, h = FILTERS[name]
    est = make()
    inputs = data(T)
    late = dict(inputs)
    late["y"] = np.concatenate([inputs["y"][:1], inputs["y"][:-1]])

    def run(d: Driver, k0: int, k1: int) -> np.ndarray:
        rows = []
        for k in range(k0, k1):
            _feed(d, late, k)
            rows.append(np.concatenate([d.vector(p.name).ravel() for p in est.output_ports]))
            assert d.step(k * h, h) == 0, d.errors()
        return np.array(rows)

    for cut in (1, T // 2):
        d = Driver(fmus[name], "a")
        assert d.initialize(**params, measurement_delay=1) == 0
        run(d, 0, cut)
        state = d.fmu.getFMUstate()
        blob = d.fmu.serializeFMUstate(state)
        first = run(d, cut, T)
        d.fmu.setFMUstate(state)
        assert np.array_equal(first, run(d, cut, T))
        d.fmu.freeFMUstate(state)
        d.free()
        fresh = Driver(fmus[name], "b")
        assert fresh.initialize(**params, measurement_delay=1) == 0
        restored = fresh.fmu.deSerializeFMUstate(blob)
        fresh.fmu.setFMUstate(restored)
        assert np.array_equal(first, run(fresh, cut, T))
        fresh.fmu.freeFMUstate(restored)
        fresh.free()


def test_observer_fmu_refuses_a_step_that_is_not_a_whole_number_of_samples(fmus):
    """The observer's sample time is its parameter dt: a step of 1.5 dt is
    refused and consumes nothing; a step of 10 dt runs 10 samples with the
    inputs held, as the library observer stepped 10 times with those inputs."""
    make, params, data, T, h = FILTERS["SridharLtvBSplineObserver"]
    inputs = data(T)
    est = make()
    d = Driver(fmus["SridharLtvBSplineObserver"])
    assert d.initialize(**params) == 0
    for j in range(T // 10):
        _feed(d, inputs, 10 * j)
        if j == 3:
            assert d.step(10 * j * h, 1.5 * h) == 3
            assert any("the communication step h = 0.0015 is not a whole number of samples of the sample time "
                       "0.001 (a step runs m >= 1 samples; set the parameter dt)" in m for m in d.errors()), d.errors()
        assert d.step(10 * j * h, 10 * h) == 0, d.errors()
        for _ in range(10):
            want = est.step({n: v[10 * j] for n, v in inputs.items()})
        got = _read(d, est)
        for port in est.output_ports:  # feedthrough estimates hold the last sample's value
            assert np.array_equal(got[port.name], np.asarray(want[port.name]).reshape(port.shape)), (j, port.name)
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


# -- plain fmpy.simulate_fmu ------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_plain_simulate_fmu_gives_the_library_estimates_one_row_later(fmus, name):
    """``fmpy.simulate_fmu(fmu, input=recorded, output_interval=h)``: fmpy sets the
    inputs of sample k at t_k, steps, and records after the step at t_k + h,
    where every estimate (direct feedthrough) holds its sample-k value: the row
    at t_(k+1) is the library's estimate of sample k, and the row at t_0 (read
    after initialization, inputs of sample 0 set) is the estimate of sample 0.
    Same numbers to the bit: the FMU runs the library's code on the same samples."""
    from fmpy import simulate_fmu

    make, params, data, T, h = FILTERS[name]
    est = make()
    inputs = data(T)
    ins = [(f"{n}[{i + 1}]", v[:, i]) for n, v in inputs.items() for i in range(v.shape[1])]
    table = np.zeros(T, dtype=[("time", float)] + [(col, float) for col, _ in ins])
    table["time"] = np.arange(T) * h
    for col, values in ins:
        table[col] = values
    outputs = [(p, f"{p.name}[{i + 1}]" if p.shape else p.name) for p in est.output_ports
               for i in range(int(np.prod(p.shape)) if p.shape else 1) if len(p.shape) <= 1]
    res = simulate_fmu(str(fmus[name]), input=table, output_interval=h, stop_time=T * h, start_values=params,
                       output=[col for _, col in outputs])
    assert res.shape == (T + 1,)
    np.testing.assert_array_equal(res["time"], np.arange(T + 1) * h)
    want = {p.name: [] for p in est.output_ports}
    for k in range(T + 1):  # sample T: only the state-like outputs (they need no new inputs)
        sample = {n: v[min(k, T - 1)] for n, v in inputs.items()}
        out = est.step(sample) if k < T else est.outputs(sample)
        for p in est.output_ports:
            want[p.name].append(np.asarray(out[p.name], dtype=float).reshape(-1))
    for port, col in outputs:
        i = int(col.split("[")[1].rstrip("]")) - 1 if "[" in col else 0
        ref = np.array(want[port.name])[:, i]
        if port.direct:  # an estimate of sample k: held until the next inputs, recorded at t_(k+1)
            np.testing.assert_array_equal(res[col][1:], ref[:T], err_msg=col)
            assert res[col][0] == ref[0], col
        else:  # a state (the H-infinity filter's xf): at t_(k+1) it is already the state of sample k + 1
            np.testing.assert_array_equal(res[col], ref, err_msg=col)


@pytest.mark.parametrize("name", sorted(n for n in FILTERS if "BSplineObserver" not in n))
def test_with_measurement_delay_simulate_fmu_gives_the_library_estimates_two_rows_later(fmus, name):
    """A Jacobi master's alignment, fed to plain ``fmpy.simulate_fmu``: the row
    at t_k holds p_k (and u_k) but y_(k-1) (the row at t_0: y_0 again, as
    libcosim initializes it). With ``measurement_delay = 1`` the filter pairs
    y_(k-1) with p_(k-1), u_(k-1) and its estimate of sample k - 1 is read
    after the step from t_k, in the row at t_(k+1): the library's undelayed
    estimate of sample k - 1, bit for bit. Rows t_0 and t_1 (no measurement
    yet) read 0; a state (xf) at t_(k+1) is the undelayed state of sample k."""
    from fmpy import simulate_fmu

    make, params, data, T, h = FILTERS[name]
    est = make()
    inputs = data(T)
    late = dict(inputs)
    late["y"] = np.concatenate([inputs["y"][:1], inputs["y"][:-1]])
    ins = [(f"{n}[{i + 1}]", v[:, i]) for n, v in late.items() for i in range(v.shape[1])]
    table = np.zeros(T, dtype=[("time", float)] + [(col, float) for col, _ in ins])
    table["time"] = np.arange(T) * h
    for col, values in ins:
        table[col] = values
    outputs = [(p, f"{p.name}[{i + 1}]" if p.shape else p.name) for p in est.output_ports
               for i in range(int(np.prod(p.shape)) if p.shape else 1) if len(p.shape) <= 1]
    res = simulate_fmu(str(fmus[name]), input=table, output_interval=h, stop_time=T * h,
                       start_values={**params, "measurement_delay": 1}, output=[col for _, col in outputs])
    assert res.shape == (T + 1,)
    want = {p.name: [] for p in est.output_ports}
    for k in range(T):
        out = est.step({n: v[k] for n, v in inputs.items()})
        for p in est.output_ports:
            want[p.name].append(np.asarray(out[p.name], dtype=float).reshape(-1))
    for port, col in outputs:
        i = int(col.split("[")[1].rstrip("]")) - 1 if "[" in col else 0
        ref = np.array(want[port.name])[:, i]
        if port.direct:
            assert res[col][0] == 0 and res[col][1] == 0, col
            np.testing.assert_array_equal(res[col][2:], ref[: T - 1], err_msg=col)
        else:
            assert res[col][0] == 0, col
            np.testing.assert_array_equal(res[col][1:], ref, err_msg=col)


@pytest.mark.parametrize(("name", "delay"), [("CoxTothTruncationKalman", 0), ("PeixotoEx1HinfPD", 1)])
def test_simulate_fmu_with_a_step_of_two_samples_holds_the_inputs(fmus, name, delay):
    """``fmpy.simulate_fmu(..., step_size=2 h)`` on a filter of sample time h:
    every step sets the inputs at t_(2j) and runs samples 2j and 2j + 1 with
    them (zero-order hold); the row at t_(2j+2) is the library's output after
    those two samples, bit for bit, with the measurement one sample late too."""
    from fmpy import simulate_fmu

    from lpvest.core._protocol import MeasurementDelay

    make, params, data, T, h = FILTERS[name]
    est = make() if not delay else MeasurementDelay(make(), delay=delay)
    inputs = data(T)
    ins = [(f"{n}[{i + 1}]", v[:, i]) for n, v in inputs.items() for i in range(v.shape[1])]
    table = np.zeros(T, dtype=[("time", float)] + [(col, float) for col, _ in ins])
    table["time"] = np.arange(T) * h
    for col, values in ins:
        table[col] = values
    cols = [f"{p.name}[{i + 1}]" for p in est.output_ports if len(p.shape) == 1 for i in range(p.shape[0])]
    res = simulate_fmu(str(fmus[name]), input=table, step_size=2 * h, output_interval=2 * h, stop_time=T * h,
                       start_values={**params, "measurement_delay": delay}, output=cols)
    assert res.shape == (T // 2 + 1,)
    np.testing.assert_array_equal(res["time"], np.arange(T // 2 + 1) * 2 * h)
    for j in range(T // 2):
        row = {n: v[2 * j] for n, v in inputs.items()}
        est.step(row)
        out = est.step(row)
        after = est.outputs(row)  # a state (xf) is read at the step's end time
        got = np.array([res[c][j + 1] for c in cols])
        want = np.concatenate([np.asarray((out if p.direct else after)[p.name]).reshape(-1)
                               for p in est.output_ports if len(p.shape) == 1])
        assert np.array_equal(got, want), j


def test_observer_resynchronises_after_a_rejected_sample(fmus):
    """The B-spline observer keeps time from the communication points: a sample
    whose y is rejected (NaN) is not consumed, fmi2DoStep is refused, the last
    successful time stays where it was, and after the valid sample is set again
    the observer goes on exactly as the library fed the valid samples."""
    from fmpy.fmi2 import fmi2LastSuccessfulTime

    make, params, data, T, h = FILTERS["SridharLtvBSplineObserver"]
    inputs = data(T)
    est = make()
    d = Driver(fmus["SridharLtvBSplineObserver"])
    assert d.initialize(**params) == 0
    for k in range(T):
        _feed(d, inputs, k)
        if k in (300, 450):  # one rejected sample before the first refit, one after
            assert d.set_vector("y", np.nan) == 3
            assert d.step(k * h, h) == 3
            assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == pytest.approx(k * h, rel=0, abs=1e-12)
            assert d.step((k + 1) * h, h) == 3  # nor can the host skip it
            _feed(d, inputs, k)
        got = _read(d, est)
        want = est.step({n: v[k] for n, v in inputs.items()})
        for port in est.output_ports:
            assert np.array_equal(got[port.name], np.asarray(want[port.name]).reshape(port.shape)), (k, port.name)
        assert d.step(k * h, h) == 0, d.errors()
    assert d.fmu.getRealStatus(fmi2LastSuccessfulTime) == pytest.approx(T * h, rel=1e-12)
    assert any(re.search(r"refused at t = 0\.(301|30099)\d* .*is not the FMU's current time 0\.(3|299)", m)
               for m in d.errors()), d.errors()
    d.free()


def test_kalman_fmu_takes_x0_and_P0_and_reports_gain_and_log_likelihood(fmus):
    from lpvest.estimators.kalman import LPVKalmanFilter, kalman_filter

    model = load_system("cox-toth-truncation").model()
    T = 40
    data = _truncation_data(T)
    x0, P0 = np.array([0.3, -0.2]), np.array([[2.0, 0.3], [0.3, 0.5]])
    d = Driver(fmus["CoxTothTruncationKalman"])
    params = {"x0[1]": x0[0], "x0[2]": x0[1], "P0[1,1]": 2.0, "P0[1,2]": 0.3, "P0[2,1]": 0.3, "P0[2,2]": 0.5}
    assert d.initialize(**params) == 0
    kf = LPVKalmanFilter(model, x0=x0, P0=P0)
    for k in range(T):
        _feed(d, data, k)
        want = kf.step({n: v[k] for n, v in data.items()})
        assert np.array_equal(d.vector("K").reshape(2, 2), want["K"])
        assert d.get("loglik") == float(want["loglik"])
        assert d.step(float(k), 1.0) == 0
    d.free()
    # the log-likelihood output is the batch filter's (another algorithm: round-off)
    batch = kalman_filter(model, data["p"], data["u"], data["y"], x0=x0, P0=P0, method="sequential")
    assert float(want["loglik"]) == pytest.approx(batch.log_likelihood, rel=1e-12)


def test_truncated_kalman_fmu_steady_state_start(fmus):
    from lpvest.estimators._truncated import TruncatedKalmanFilter

    model = load_system("cox-toth-truncation").model()
    T = 30
    data = _truncation_data(T)
    d = Driver(fmus["CoxTothTruncationTruncatedKalman"])
    assert d.initialize(tau=3, start="steady-state", **{"start_p[1]": 0.2}) == 0, d.errors()
    tf = TruncatedKalmanFilter(model, 3, start="steady-state", start_p=[0.2])
    theorem = TruncatedKalmanFilter(model, 3, start="theorem")
    differs = False
    for k in range(T):
        _feed(d, data, k)
        sample = {n: v[k] for n, v in data.items()}
        want = tf.step(sample)
        differs |= not np.array_equal(want["K"], theorem.step(sample)["K"])
        assert np.array_equal(d.vector("K").reshape(2, 2), want["K"])
        assert d.step(float(k), 1.0) == 0
    assert differs  # the start matters: this is not the theorem start again
    d.free()


def test_the_readme_simulate_fmu_example_runs(fmus):
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    block = text.split("### Driving a filter FMU with plain `fmpy.simulate_fmu`", 1)[1]
    block = block.split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(block.replace('"fmu-build/', f'"{fmus.out.as_posix()}/'), "README.md", "exec"), {})
