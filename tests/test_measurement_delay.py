"""A measurement that arrives late (lpvest.core._protocol.MeasurementDelay), against
the library on the properly aligned data.

The oracle is the undelayed component fed the samples as they belong together
(p_k, u_k, y_k): the delayed one, fed what a Jacobi master delivers (p_j, u_j
and y_(j-d)), must output at step j exactly what the undelayed one outputs for
sample j - d. Exactly, to the bit: it runs the same code on the same numbers
(each sample's values are paired, copied and handed over unchanged), so any
difference at all would be a pairing error.
"""

from __future__ import annotations

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._errors import ArgumentError, ArgumentTypeError, DimensionError, NonFiniteError, SchedulingRangeError
from lpvest.core._protocol import MeasurementDelay, run_streaming
from lpvest.core._signals import SchedulerComponent, SignalSpec
from lpvest.design import HinfDesign
from lpvest.estimators._hinf import HinfFilter
from lpvest.estimators._truncated import TruncatedKalmanFilter
from lpvest.estimators.kalman import LPVKalmanFilter
from lpvest.fmi._registry import MEASUREMENT_DELAY, EstimatorKind, build_estimator, estimator_kinds
from lpvest.fmi._state import decode_state, encode_state
from lpvest.systems._catalog import stored_design
from lpvest.systems._polytopic import hinf_setting
from tests.fmu_movavg import MovingAverage

T = 40


def _design(system: str, role: str) -> HinfDesign:
    path = stored_design(system, role)
    assert path is not None
    return HinfDesign.from_json(path.read_text())


def _truncation_data(rng) -> dict[str, np.ndarray]:
    model = load_system("cox-toth-truncation").model()
    k = np.arange(T)
    p, u = np.sin(0.25 * k)[:, None], np.sin(0.1 * k)[:, None]
    return {"p": p, "u": u, "y": model.simulate(p, u, rng=rng).y}


def _peixoto_data(rng, *, scheduled: bool = True) -> dict[str, np.ndarray]:
    plant = load_system("peixoto-ex1").model()
    theta = rng.uniform(-1, 1, (T, 1))
    y = plant.simulate(plant.alpha_batch(theta), rng.standard_normal((T, 1))).y
    return {"p": theta, "y": y} if scheduled else {"y": y}


def _kalman():
    return LPVKalmanFilter(load_system("cox-toth-truncation").model())


def _truncated():
    return TruncatedKalmanFilter(load_system("cox-toth-truncation").model(), 4)


def _hinf_pd():
    return HinfFilter(_design("peixoto-ex1", "HinfPD"), simplex_map=load_system("peixoto-ex1").model().simplex_map)


def _hinf_robust():
    return HinfFilter(_design("peixoto-ex1", "HinfRobust"))


def _hinf_known_input():
    plant = hinf_setting(load_system("cox-toth-truncation").model())
    return HinfFilter(_design("cox-toth-truncation", "HinfPD"), simplex_map=plant.simplex_map, plant=plant)


def _moving_average():  # a component of the protocol only (no Component base): the public-protocol path
    return MovingAverage(2, 1, 3)


#: name -> (component factory, data)
FILTERS = {
    "kalman": (_kalman, _truncation_data),
    "truncated": (_truncated, _truncation_data),
    "hinf-pd": (_hinf_pd, _peixoto_data),
    "hinf-robust": (_hinf_robust, lambda rng: _peixoto_data(rng, scheduled=False)),
    "hinf-known-input": (_hinf_known_input, _truncation_data),
    "moving-average": (_moving_average, _truncation_data),
}


def _late(data: dict[str, np.ndarray], d: int, fill: float = 0.0) -> dict[str, np.ndarray]:
    """What a master delivers when y arrives d samples late: row j holds p_j, u_j
    and y_(j-d) (rows j < d: ``fill``, no sample's measurement)."""
    out = dict(data)
    y = data["y"]
    out["y"] = np.concatenate([np.full((d, y.shape[1]), fill), y[: len(y) - d]]) if d else y
    return out


@pytest.mark.parametrize("delay", [1, 2, 3])
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_the_estimate_of_sample_k_at_step_k_plus_delay_is_the_undelayed_one_to_the_bit(name, delay, rng):
    make, data = FILTERS[name]
    inputs = {k: v for k, v in data(rng).items() if k in {p.name for p in make().input_ports}}
    want = run_streaming(make(), inputs)
    late = MeasurementDelay(make(), delay=delay)
    got = run_streaming(late, _late(inputs, delay, fill=0.5))  # what arrives before the first y is ignored
    for port in late.output_ports:
        # before the first measurement every output is 0; then sample j - delay
        assert np.array_equal(got[port.name][:delay], np.zeros((delay, *port.shape))), port.name
        assert np.array_equal(got[port.name][delay:], want[port.name][: T - delay]), port.name


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_delay_zero_is_the_component_itself(name, rng):
    make, data = FILTERS[name]
    inputs = {k: v for k, v in data(rng).items() if k in {p.name for p in make().input_ports}}
    want, got = run_streaming(make(), inputs), run_streaming(MeasurementDelay(make(), delay=0), inputs)
    assert all(np.array_equal(got[n], want[n]) for n in want)


def test_the_scheduling_and_input_of_a_step_go_with_the_measurement_of_their_own_sample(rng):
    """Each y is paired with the p and u that arrived with the sample it belongs
    to, not with those of the step it arrives in: changing p_j, u_j changes the
    estimate of sample j (one step later), never that of sample j - 1."""
    data = _truncation_data(rng)
    late = MeasurementDelay(_kalman())
    late.step({"p": data["p"][0], "u": data["u"][0], "y": data["y"][0]})
    a = late.outputs({"p": data["p"][1], "u": data["u"][1], "y": data["y"][0]})
    b = late.outputs({"p": -data["p"][1], "u": 3.0 * data["u"][1], "y": data["y"][0]})
    assert all(np.array_equal(a[n], b[n]) for n in a)  # the estimate of sample 0 uses p_0, u_0 only
    ref = _kalman().step({"p": data["p"][0], "u": data["u"][0], "y": data["y"][0]})
    assert all(np.array_equal(a[n], ref[n]) for n in a)


def test_outputs_change_nothing_and_a_state_round_trip_continues_identically(rng):
    """outputs() changes nothing; get_state()/set_state() (also through the FMU
    state's serialization) mid-run, while waiting for the first measurement and
    after, continue exactly as the uninterrupted run."""
    inputs = _late(_peixoto_data(rng), 2)
    rows = [{n: v[k] for n, v in inputs.items()} for k in range(T)]
    ref = [MeasurementDelay(_hinf_pd(), delay=2).step(rows[0])]
    full = MeasurementDelay(_hinf_pd(), delay=2)
    want = [full.step(r) for r in rows]
    for cut in (1, 2, 7):
        a = MeasurementDelay(_hinf_pd(), delay=2)
        for r in rows[:cut]:
            a.step(r)
        a.outputs(rows[cut])
        a.outputs({"p": [0.9], "y": [5.0]})
        state = decode_state(encode_state(a.get_state()))
        b = MeasurementDelay(_hinf_pd(), delay=2)
        b.set_state(state)
        assert b.waiting == (cut < 2)
        got = [b.step(r) for r in rows[cut:]]
        for g, w in zip(got, want[cut:], strict=True):
            assert all(np.array_equal(g[n], w[n]) for n in w)
    assert np.array_equal(ref[0]["zhat"], np.zeros(2))


def test_a_bad_sample_is_refused_when_it_arrives_and_changes_nothing(rng):
    """Inputs are checked as they arrive, by the component's own checks: a p
    outside the box or a NaN y raises its typed error at the step where it
    arrives (also while waiting for the first measurement), and the run goes
    on as if it had never been offered."""
    data = _late(_truncation_data(rng), 1)
    rows = [{n: v[k] for n, v in data.items()} for k in range(T)]
    want = run_streaming(MeasurementDelay(_kalman()), data)
    late = MeasurementDelay(_kalman())
    got = []
    for k, row in enumerate(rows):
        if k in (0, 5):
            with pytest.raises(SchedulingRangeError, match=r"scheduling value at t=\d+: .* outside"):
                late.step({**row, "p": np.array([1.5])})
            with pytest.raises(NonFiniteError, match="y at t="):
                late.step({**row, "y": np.array([np.nan, 0.0])})
            with pytest.raises(DimensionError, match=r"input 'u' is missing"):
                late.step({"p": row["p"], "y": row["y"]})
        got.append(late.step(row)["xhat"])
    assert np.array_equal(np.array(got), want["xhat"])


def test_what_a_measurement_delay_accepts():
    with pytest.raises(ArgumentTypeError, match="SchedulerComponent keeps time .* pairs samples of a sampled"):
        plant = load_system("peixoto-ex1").model()
        MeasurementDelay(SchedulerComponent(SignalSpec.build("zero", 1), plant.space))
    with pytest.raises(ArgumentError, match="delay must be >= 0 samples; found -1"):
        MeasurementDelay(_kalman(), delay=-1)
    for bad in (1.5, True, "1"):
        with pytest.raises(ArgumentTypeError, match="delay must be an integer number of samples"):
            MeasurementDelay(_kalman(), delay=bad)  # type: ignore[arg-type]
    for late in (("q",), ()):
        with pytest.raises(ArgumentError, match=r"late must name inputs of LPVKalmanFilter \(p, u, y\)"):
            MeasurementDelay(_kalman(), late=late)
    late = MeasurementDelay(_kalman(), delay=2)
    assert (late.delay, late.late, [p.name for p in late.input_ports]) == (2, ("y",), ["p", "u", "y"])
    assert late.input_ports[2].description == "measurement y_t (arriving 2 sample(s) late)"
    assert late.output_ports == _kalman().output_ports


@pytest.mark.parametrize(("state", "match"), [
    ({"kept": 3}, "a MeasurementDelay state needs 'component', 'kept' and 'inputs'"),
    ({"kept": 2, "inputs": {}, "component": None}, r"kept = 2 must be an integer in \[0, delay = 1\]"),
    ({"kept": 1, "inputs": {"p": np.zeros((1, 1))}, "component": None},
     r"kept inputs u have shape \(\); expected \(1, 1\)"),
    ({"kept": 1, "inputs": {"p": np.zeros((1, 2)), "u": np.zeros((1, 1))}, "component": None},
     r"kept inputs p have shape \(1, 2\); expected \(1, 1\)"),
])
def test_a_state_that_does_not_fit_is_refused_and_changes_nothing(state, match):
    late = MeasurementDelay(_kalman())
    late.step({"p": [0.1], "u": [0.2], "y": [0.0, 0.0]})
    before = late.get_state()
    with pytest.raises(DimensionError, match=match):
        late.set_state(state)
    after = late.get_state()
    assert after["kept"] == before["kept"] and np.array_equal(after["inputs"]["p"], before["inputs"]["p"])


def test_every_sampled_filter_fmu_has_the_parameter_and_the_observer_none():
    """The FMU roles Kalman, TruncatedKalman, HinfPD and HinfRobust have late
    measurements (their plants' y feeds through); the B-spline observer does
    not (its plant's y(t) = C(t) x(t) does not), and a timed estimator cannot."""
    kinds = {k.role: k for k in estimator_kinds()}
    assert {r: k.late_inputs for r, k in kinds.items()} == {
        "Kalman": ("y",), "TruncatedKalman": ("y",), "HinfPD": ("y",), "HinfRobust": ("y",), "BSplineObserver": ()}
    assert MEASUREMENT_DELAY.name == "measurement_delay" and MEASUREMENT_DELAY.fmi_type == "Integer"
    assert MEASUREMENT_DELAY.start == 0 and MEASUREMENT_DELAY.minimum == 0
    with pytest.raises(ArgumentError, match="estimator X: a timed estimator .* cannot have late inputs"):
        EstimatorKind("X", "m:f", sample_time="dt", late_inputs=("y",))
    kind = kinds["Kalman"].to_json()
    model = load_system("cox-toth-truncation").model()
    params = {"x0": model.x0, "P0": model.P0}
    assert isinstance(build_estimator(kind, model, None, {**params, "measurement_delay": 0}), LPVKalmanFilter)
    late = build_estimator(kind, model, None, {**params, "measurement_delay": 1})
    assert isinstance(late, MeasurementDelay) and (late.delay, late.late) == (1, ("y",))
    assert isinstance(late.component, LPVKalmanFilter)
