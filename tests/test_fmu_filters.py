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


#: FMU -> (library estimator, FMU parameters, data, number of samples, step size)
FILTERS = {
    "CoxTothTruncationKalman": (_kalman, {}, _truncation_data, 60, 1.0),
    "CoxTothTruncationTruncatedKalman": (lambda: _truncated(4), {"tau": 4}, _truncation_data, 60, 1.0),
    # a short window (0.4 s) so that the test sees several refits in 700 samples
    "SridharLtvBSplineObserver": (_observer, {"window": 0.4, "hop": 0.1}, _sridhar_data, 700, 1e-3),
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
        np.testing.assert_array_equal(got["xhat"], want["xhat"])
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
