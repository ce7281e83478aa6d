"""The FMU slave base (lpvest/fmi/_slave.py) in this process: step rule, inputs, state, errors.

The slave runs from a resources folder written without bundling (tests/slave_harness.py), so a
change to slave.py is seen without a rebuild; tests/test_fmu.py checks the same conventions
through built FMUs and real FMI calls.
"""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from pythonfmu.enums import Fmi2Status

from lpvest.fmi._slave import MAX_MESSAGE
from lpvest.systems._modelfile import load_system

from .slave_harness import ERROR, OK, WARNING, Slave, edit_state, write_resources


def theta(k):
    return np.sin(0.25 * np.asarray(k, dtype=float))


def paper_w(k):
    k = np.asarray(k, dtype=float)
    return np.where(k >= 10, np.sin(0.5 * k) * np.exp(-0.1 * k), 0.0)  # Peixoto et al., Section 4


@pytest.fixture(scope="module")
def resources(tmp_path_factory):
    base = tmp_path_factory.mktemp("slave-resources")
    return {f"{s}{r}": write_resources(s, r, base / f"{s}-{r}")
            for s, r in [("peixoto-ex1", "Plant"), ("peixoto-ex1", "HinfPD"), ("cox-toth-truncation", "Kalman"),
                         ("peixoto-ex1", "Scheduler"), ("sridhar-ltv", "Plant"), ("sridhar-ltv", "BSplineObserver"),
                         ("peixoto-ex2", "Plant")]}


def plant(resources, **kw) -> Slave:
    return Slave(resources["peixoto-ex1Plant"], **kw)


def drive(s: Slave, t0: float, h: float, n: int, k0: int = 0, *, accumulate: bool = False) -> dict[str, np.ndarray]:
    """Inputs of sample k set at t_k, outputs read before the step, one step of h."""
    rec: dict[str, list] = {"y": [], "z": [], "x": []}
    t = t0 + k0 * h
    for k in range(k0, k0 + n):
        s.set_reals({"p[1]": float(theta(k)), "w[1]": float(paper_w(k))})
        for name, count in (("y", 1), ("z", 2), ("x", 2)):
            rec[name].append(s.get(*[f"{name}[{i + 1}]" for i in range(count)]))
        tk = t if accumulate else t0 + k * h
        assert s.step(tk, h), s.errors()
        t += h
    return {k: np.array(v) for k, v in rec.items()}


# -- the step rule ---------------------------------------------------------------------


@pytest.mark.parametrize("accumulate", [False, True])
@pytest.mark.parametrize("t0", [0.0, 1e6, -3.5e7])
def test_a_plant_far_from_t0_is_the_library_whatever_the_host_time_arithmetic(resources, t0, accumulate):
    """Communication points t0 + k h (an integer counter, lpvest.cosim) or t += h (fmpy's loop)
    are the FMU's time within the rule's relative tolerance, however far from 0."""
    s = plant(resources)
    assert s.initialize(t0, sample_time=0.1) == []
    T = 60
    got = drive(s, t0, 0.1, T, accumulate=accumulate)
    model = load_system("peixoto-ex1").model()
    k = np.arange(T)
    ref = model.simulate(model.alpha_batch(theta(k)[:, None]), paper_w(k)[:, None])
    assert np.array_equal(got["y"], ref.y) and np.array_equal(got["z"], ref.z) and np.array_equal(got["x"], ref.x)
    assert s.take_log() == []


@pytest.mark.parametrize(("t0", "h"), [(0.0, 0.1), (1e6, 0.1), (1e9, 0.5), (-2e10, 1.0)])
def test_far_from_t0_a_skipped_or_repeated_point_is_refused_and_consumes_nothing(resources, t0, h):
    a, b = plant(resources), plant(resources)
    for s in (a, b):
        assert s.initialize(t0, sample_time=h) == []
        drive(s, t0, h, 12)
    t = t0 + 12 * h
    a.set_reals({"p[1]": 0.3, "w[1]": 0.2})
    for bad_t, bad_h, why in [(t + h, h, "is not the FMU's current time"), (t - h, h, "is not the FMU's current time"),
                              (t, 1.5 * h, f"is not a whole number of samples of the sample time {h:g}"),
                              (t, 0.0, "must be > 0"),
                              (t, -h, "must be > 0"), (t, math.nan, "must be finite"),
                              (math.inf, h, "must be finite")]:
        assert not a.step(bad_t, bad_h)
        [message] = a.errors()
        assert why in message and "fmi2DoStep refused" in message
    # nothing consumed: the next valid step gives what an instance without the refusals gives
    b.set_reals({"p[1]": 0.3, "w[1]": 0.2})
    assert a.step(t, h) and b.step(t, h)
    assert a.get("x[1]", "x[2]", "y[1]") == b.get("x[1]", "x[2]", "y[1]")
    assert a.slave._time == t + h


@pytest.mark.parametrize("t0", [0.0, 1e9])
def test_a_step_of_several_samples_does_not_hide_a_skipped_sample(resources, t0):
    """A step of m samples from a point one sample off is refused: the time-match rule allows
    rounding, at most half a sample, whatever the length of the step."""
    h = 0.5
    s = plant(resources)
    assert s.initialize(t0, sample_time=h) == []
    drive(s, t0, h, 3)
    t = t0 + 3 * h
    for m in (2, 4, 8):
        for off in (h, -h):
            assert not s.step(t + off, m * h)
            [message] = s.errors()
            assert "is not the FMU's current time" in message
    assert s.step(t, 4 * h), s.errors()
    assert s.slave._time == t + 4 * h


def test_the_time_match_tolerance_is_relative_to_the_larger_time(resources):
    """A host's time that differs from the FMU's by rounding errors of its size is the same point."""
    t0, h = 1e9, 0.5
    s = plant(resources)
    assert s.initialize(t0, sample_time=h) == []
    assert s.step(t0 * (1 + 4e-16), h), s.errors()  # two ulps of t0 away
    assert s.step((t0 + h) * (1 - 1e-10), h), s.errors()  # 0.1 s: a host's time accumulated over 1e6 steps


def test_a_step_before_initialization_or_after_terminate_is_refused(resources):
    s = plant(resources)
    assert not s.step(0.0, 1.0)
    assert s.errors() == ["[PeixotoEx1Plant] fmi2DoStep refused at t = 0 (h = 1): the FMU is not initialized yet "
                          "(fmi2ExitInitializationMode)"]
    assert s.initialize() == []
    assert s.step(0.0, 1.0)
    s.slave.terminate()
    assert not s.step(1.0, 1.0)
    assert "the FMU is terminated" in s.errors()[0]
    s.set("p[1]", 0.5)
    assert "cannot be set after fmi2Terminate" in s.errors()[0]


def test_a_failed_initialization_refuses_every_step_and_says_why(resources):
    s = plant(resources)
    s.slave.setup_experiment(0.0)
    s.set("sample_time", 0.0)
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    [message] = s.errors()
    assert "sample_time = 0 must be > 0" in message
    assert not s.step(0.0, 1.0)
    assert "initialization failed: parameter sample_time = 0 must be > 0" in s.errors()[0]


# -- inputs ----------------------------------------------------------------------------


@pytest.mark.parametrize(("value", "why"), [(math.nan, "p[1] (theta) = nan is not finite"),
                                            (1.5, "p[1] (theta) = 1.5 is outside its declared range [-1, 1]"),
                                            (-1.0 - 1e-9, "is outside its declared range [-1, 1]")])
def test_a_bad_input_is_rejected_naming_it_and_the_state_is_kept(resources, value, why):
    s, ref = plant(resources), plant(resources)
    for x in (s, ref):
        assert x.initialize() == []
        drive(x, 0.0, 1.0, 5)
    s.set_reals({"p[1]": 0.2, "w[1]": 0.1})
    s.set("p[1]", value)
    [message] = s.errors()
    assert why in message and "value rejected" in message
    assert s.get("p[1]") == [0.2]  # the rejected value is not stored
    assert not s.step(5.0, 1.0)
    assert "invalid input(s) p[1]" in s.errors()[0]
    s.set("p[1]", 0.2)  # a valid value clears the complaint
    ref.set_reals({"p[1]": 0.2, "w[1]": 0.1})
    assert s.step(5.0, 1.0) and ref.step(5.0, 1.0)
    assert s.get("x[1]", "x[2]") == ref.get("x[1]", "x[2]")


def test_an_input_on_its_bound_within_the_relative_tolerance_is_accepted(resources):
    s = plant(resources)
    assert s.initialize() == []
    s.set_reals({"p[1]": 1.0 + 5e-13, "w[1]": 0.0})  # inside check_box's relative tolerance 1e-12
    assert s.errors() == []
    assert s.get("p[1]") == [1.0 + 5e-13]
    assert s.step(0.0, 1.0), s.errors()


def test_a_restored_state_with_an_input_out_of_range_is_checked_again(resources):
    """Inputs checked at fmi2SetReal are not checked again by the component; a restored state's
    inputs did not pass through fmi2SetReal, so they are: an out-of-range p is an error, never a
    sample silently computed outside the scheduling box."""
    s = plant(resources)
    assert s.initialize() == []
    s.set_reals({"p[1]": 0.5, "w[1]": 0.0})
    good = s.get("y[1]")  # the inputs are now known to be in range
    assert math.isfinite(good[0])
    state = s.get_state()
    bad = edit_state(state, inputs={"p": np.array([3.0]), "w": np.array([0.0])}, dirty=True)
    s.set_state(bad)
    s.take_log()
    s.get("y[1]")
    errors = s.errors()
    assert errors and "theta" in errors[0] and "3" in errors[0]
    assert not s.step(0.0, 1.0)
    assert s.errors()
    s.set_state(state)  # the good state runs again
    assert s.get("y[1]") == good and s.step(0.0, 1.0)


# -- outputs ---------------------------------------------------------------------------


def test_feedthrough_outputs_hold_after_a_step_and_states_move_on(resources):
    s = plant(resources)
    assert s.initialize() == []
    drive(s, 0.0, 1.0, 15)
    s.set_reals({"p[1]": 0.4, "w[1]": -0.2})
    y, z, x = s.get("y[1]"), s.get("z[1]", "z[2]"), s.get("x[1]", "x[2]")
    assert s.step(15.0, 1.0)
    model = load_system("peixoto-ex1").model()
    m = model.at(model.alpha([0.4]))
    assert s.get("y[1]") == y and s.get("z[1]", "z[2]") == z  # the sample just consumed
    x_next = s.get("x[1]", "x[2]")
    size = max(map(abs, x)) + 0.2
    np.testing.assert_allclose(x_next, m.A @ x + m.Bw @ [-0.2], rtol=0, atol=8 * np.finfo(float).eps * size)
    # a second step with no input set: the same inputs again (a held sample)
    assert s.step(16.0, 1.0)
    np.testing.assert_allclose(s.get("x[1]", "x[2]"), m.A @ x_next + m.Bw @ [-0.2], rtol=0,
                               atol=8 * np.finfo(float).eps * (max(map(abs, x_next)) + 0.2))


def test_a_filter_reads_its_estimate_before_the_step_and_holds_it_after(resources):
    f = Slave(resources["peixoto-ex1HinfPD"])
    assert f.initialize() == []
    seen = []
    for k in range(6):
        f.set_reals({"p[1]": float(theta(k)), "y[1]": math.cos(k)})
        before = f.get("zhat[1]", "zhat[2]")
        assert f.step(float(k), 1.0)
        assert f.get("zhat[1]", "zhat[2]") == before
        seen.append(before)
    from lpvest.design._result import HinfDesign
    from lpvest.estimators._hinf import HinfFilter

    design = HinfDesign.from_json((resources["peixoto-ex1HinfPD"] / "design.json").read_text())
    lib = HinfFilter(design, simplex_map=load_system("peixoto-ex1").model().simplex_map)
    ref = [lib.step({"p": [float(theta(k))], "y": [math.cos(k)]})["zhat"].tolist() for k in range(6)]
    assert seen == ref


def test_an_output_that_would_be_inf_is_an_error_naming_it_and_numpy_warnings_are_logged(resources):
    s = plant(resources)
    s.slave.setup_experiment(0.0)
    s.set("x0[1]", 1.5e308)
    s.set("x0[2]", 1.5e308)
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    assert s.errors() == []
    s.set_reals({"p[1]": -1.0, "w[1]": 0.0})  # vertex 1: x2 <- x1 + 0.48 x2 overflows
    assert s.step(0.0, 1.0)
    assert s.take_log() == [(WARNING, "[PeixotoEx1Plant] numpy: floating-point overflow at t = 0")]
    assert s.get("x[2]") == [math.inf]
    log = s.take_log()
    assert log[:-1] and all(m == (WARNING, "[PeixotoEx1Plant] numpy: floating-point invalid value at t = 1")
                            for m in log[:-1])  # inf - inf in the outputs (0 * inf)
    assert log[-1][0] == ERROR and log[-1][1].startswith("[PeixotoEx1Plant] fmi2GetReal: output ")
    assert "x[2] is not finite (NaN or inf) at t = 1" in log[-1][1]
    assert not s.step(1.0, 1.0)
    assert "fmi2DoStep refused at t = 1 (h = 1): output " in s.errors()[-1]


def test_wrong_variable_use_is_an_error_never_an_exception(resources):
    s = plant(resources)
    assert s.initialize() == []
    assert math.isnan(s.slave.get_real([10_000])[0])
    assert "fmi2GetReal: value reference 10000 is not a variable of this FMU" in s.errors()[0]
    assert s.slave.get_integer([s.vr["p[1]"]]) == [0]
    assert f"value reference {s.vr['p[1]']} is the Real variable p[1], not an Integer variable" in s.errors()[0]
    s.slave.set_real([s.vr["y[1]"]], [1.0])
    assert "y[1] is an output; it cannot be set" in s.errors()[0]
    s.slave.set_real([s.vr["sample_time"]], [2.0])
    assert "is fixed: it can be set only before fmi2ExitInitializationMode" in s.errors()[0]
    assert s.get("sample_time") == [1.0]


def test_log_messages_are_capped_and_percent_signs_survive_the_format_string(resources):
    s = plant(resources)
    s.take_log()
    s.slave._log(Fmi2Status.error, "x" * 5000)
    [(status, text)] = s.take_log()
    assert status == ERROR and len(text) <= MAX_MESSAGE + len("[PeixotoEx1Plant] ") and text.endswith("cut)")
    s.slave._log(Fmi2Status.ok, "100% done")
    assert s.take_log() == [(OK, "[PeixotoEx1Plant] 100%% done")]


# -- state -----------------------------------------------------------------------------


def test_a_restored_state_continues_identically_and_a_foreign_state_is_refused(resources):
    a = Slave(resources["cox-toth-truncationKalman"])
    assert a.initialize() == []
    outputs = ["xhat[1]", "xhat[2]", "P[1,1]", "loglik"]

    def run(s, k0, n):
        rows = []
        for k in range(k0, k0 + n):
            s.set_reals({"p[1]": math.sin(k) * 0.5, "u[1]": math.cos(k), "y[1]": 0.1 * k, "y[2]": -0.2})
            rows.append(s.get(*outputs))
            assert s.step(float(k), 1.0), s.errors()
        return rows

    run(a, 0, 5)
    state = a.get_state()
    first = run(a, 5, 5)
    a.set_state(state)
    assert [m for m in a.take_log() if m[0] >= WARNING] == []
    assert run(a, 5, 5) == first
    b = Slave(resources["cox-toth-truncationKalman"], name="b")
    b.set_state(state)  # into a fresh instance
    assert run(b, 5, 5) == first
    p = plant(resources)
    p.set_state(state)
    assert "the state belongs to 'CoxTothTruncationKalman', not to 'PeixotoEx1Plant'" in p.errors()[0]
    p.set_state(edit_state(p.get_state(), params={"other": 1.0}))
    assert "the state's parameters do not match this FMU" in p.errors()[0]
    # another build of the same FMU (its GUID differs), damaged bytes, a field that does not
    # read: refused, and nothing of the refused state is applied (b goes on as before)
    mid = b.get_state()
    after = run(b, 10, 3)
    b.set_state(mid)
    for bad, says in ((edit_state(mid, guid="{another}"),
                       "the state belongs to 'CoxTothTruncationKalman', not to 'CoxTothTruncationKalman' "
                       "(another build of it)"),
                      (mid.replace(b'"time": 10.0', b'"time": 11.0'),
                       "not a serialized lpvest FMU state (it is damaged: its SHA-256 does not match)"),
                      (mid[: len(mid) // 2], "not a serialized lpvest FMU state: "),
                      (edit_state(mid, invalid=7, inputs=edit_inputs(mid)), "TypeError: 'int' object is not iterable"),
                      (edit_state(mid, time=math.nan), "the state's time (nan, started at 0.0) is not finite")):
        b.take_log()
        b.set_state(bad)
        errors = b.errors()
        assert len(errors) == 1 and says in errors[0], (says, errors)
    assert run(b, 10, 3) == after


def edit_inputs(state: bytes) -> dict:
    """The state's inputs, every value changed (to see that none is applied)."""
    from lpvest.fmi._state import decode_state

    return {k: np.asarray(v) + 123.0 for k, v in decode_state(state)["inputs"].items()}


# -- non-Real variables and the model description's metadata -------------------------------


def test_string_integer_and_boolean_parameters_are_set_read_and_checked(resources, tmp_path):
    s = Slave(resources["peixoto-ex1Scheduler"])
    assert s.get("kind") == ["sinusoid"] and s.get("seed") == [0]
    s.slave.setup_experiment(0.0)
    s.set("kind", "constant")
    s.set("seed", 7)
    assert s.get("kind") == ["constant"] and s.get("seed") == [7]
    s.set("seed", 2**31)
    assert s.errors() == ["[PeixotoEx1Scheduler] parameter seed = 2147483648 is outside its declared range "
                          "[0, 2147483647]; value rejected"]
    assert s.get("seed") == [7]
    s.set("seed", 8)  # a valid value clears the complaint
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    assert s.errors() == []
    s.set("kind", "random")
    assert s.errors() == ["[PeixotoEx1Scheduler] parameter kind is fixed: it can be set only before "
                          "fmi2ExitInitializationMode"]
    assert s.get("kind") == ["constant"]
    plant_dir = write_resources("cox-toth-truncation", "Plant", tmp_path / "ct")
    p = Slave(plant_dir)
    assert p.get("noise") == [True]
    p.slave.set_boolean([p.vr["noise"]], [False])
    assert p.get("noise") == [False] and p.slave.parameters()["noise"] is False
    p.slave.set_string([p.vr["noise"]], ["x"])
    assert p.errors() == [f"[CoxTothTruncationPlant] fmi2SetString: value reference {p.vr['noise']} is the "
                          "Boolean variable noise, not a String variable"]
    assert p.slave.get_boolean([p.vr["seed"]]) == [False] and p.slave.get_string([p.vr["seed"]]) == [""]
    assert f"value reference {p.vr['seed']} is the Integer variable seed, not a Boolean variable" in p.errors()[0]


def test_the_metadata_declares_ranges_dependencies_and_sampling(resources):
    s = plant(resources)
    meta = s.slave.fmi_metadata()
    assert meta["timed"] is False
    assert meta["ranges"][s.vr["p[1]"]] == (-1.0, 1.0) and meta["ranges"][s.vr["sample_time"]] == (0.0, None)
    assert s.vr["w[1]"] not in meta["ranges"]
    inputs = sorted([s.vr["p[1]"], s.vr["w[1]"]])
    assert meta["dependencies"][s.vr["y[1]"]] == inputs and meta["dependencies"][s.vr["z[2]"]] == inputs
    assert meta["dependencies"][s.vr["x[1]"]] == []  # a state depends on no input at the same instant
    assert set(meta["dependencies"]) == {s.vr[n] for n in ("y[1]", "z[1]", "z[2]", "x[1]", "x[2]")}
    f = Slave(resources["peixoto-ex1HinfPD"])
    fm = f.slave.fmi_metadata()
    assert fm["dependencies"][f.vr["zhat[1]"]] == sorted([f.vr["p[1]"], f.vr["y[1]"]])
    assert fm["dependencies"][f.vr["xf[2]"]] == []
    sched = Slave(resources["peixoto-ex1Scheduler"])
    assert all(d == [] for d in sched.slave.fmi_metadata()["dependencies"].values())  # no inputs at all


def test_the_model_description_declares_each_variable(resources):
    import xml.etree.ElementTree as ET

    s = plant(resources)
    md = s.slave.to_xml()
    assert md.get("modelName") == "PeixotoEx1Plant" and md.get("description").startswith("Plant: ")
    declared = {v.get("name"): (v.get("causality"), v.get("variability"), v.get("description"), v[0].get("start"))
                for v in md.iter("ScalarVariable")}
    assert declared["p[1]"] == ("input", None, "scheduling (theta)", "0")
    assert declared["w[1]"][:2] == ("input", None) and declared["w[1]"][3] == "0"
    assert declared["y[1]"][:2] == ("output", None) and declared["x[2]"][:2] == ("output", None)
    assert declared["sample_time"] == ("parameter", "fixed", "time between samples (s): a communication step of "
                                       "m whole samples (m >= 1) runs m samples, the inputs held", "1")
    assert declared["x0[2]"][:2] == ("parameter", "fixed")
    assert ET.tostring(md).count(b"<ScalarVariable") == len(s.vr) == 10


def test_outputs_read_before_initialization_come_from_the_start_values(resources):
    s = plant(resources)
    model = load_system("peixoto-ex1").model()
    m = model.at(model.alpha([0.0]))  # p starts at 0, the point of [-1, 1] nearest 0
    x0 = np.array([float(v) for v in s.get("x0[1]", "x0[2]")])  # the parameter's start value
    assert s.get("y[1]") == (m.Cy @ x0).tolist() and s.get("x[1]", "x[2]") == x0.tolist()
    s.set("x0[1]", 2.0)  # a parameter changes the preview
    assert s.get("x[1]") == [2.0] and s.get("y[1]") == (m.Cy @ [2.0, x0[1]]).tolist()


def test_a_host_that_skips_setup_or_rounds_the_first_point_still_steps(resources):
    s = plant(resources)
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()  # no fmi2SetupExperiment: start time 0
    assert s.errors() == []
    assert s.step(1e-12, 1.0), s.errors()  # 1e-12 is 0 to the rule's 1e-9 of the step
    assert s.step(1.0 + 1e-12, 1.0), s.errors()


def test_every_invalid_value_is_named_when_initialization_fails(resources):
    s = plant(resources)
    s.slave.setup_experiment(0.0)
    s.set("sample_time", -1.0)
    s.set("x0[1]", math.inf)
    s.take_log()
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    assert s.errors() == ["[PeixotoEx1Plant] fmi2ExitInitializationMode: invalid values were set: parameter "
                          "sample_time = -1 is outside its declared range [0, inf]; value rejected; parameter "
                          "x0[1] = inf is not finite; value rejected"]


def test_a_spec_without_a_sample_time_samples_every_second(tmp_path):
    import json

    folder = write_resources("peixoto-ex1", "Plant", tmp_path / "r")
    spec = json.loads((folder / "lpvest_fmu.json").read_text())
    del spec["sample_time"]
    (folder / "lpvest_fmu.json").write_text(json.dumps(spec))
    s = Slave(folder)
    assert s.get("sample_time") == [1.0]


# -- timed components, several samples per step, model parameters ---------------------------


@pytest.mark.parametrize("read_before_step", [True, False])
def test_a_timed_scheduler_far_from_t0_is_the_library_signal_at_the_hosts_points(resources, read_before_step):
    """A function of time (no sample time) ends each step exactly at the host's point t + h, not at
    its own sum of steps: far from 0 the two differ in the last bits of p = sin(0.25 t)."""
    from lpvest.core._signals import SchedulerComponent, SignalSpec

    t0, h, n = 1e6, 0.1, 40
    s = Slave(resources["peixoto-ex1Scheduler"])
    assert s.initialize(t0) == []
    plant_model = load_system("peixoto-ex1").model()
    ref = SchedulerComponent(SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=0.25), plant_model.space,
                             plant_model.simplex_map)
    ref.reset(t0)
    got, want = [], []
    for k in range(n):
        t = t0 + k * h  # the host's points: an integer counter
        if read_before_step or k == n - 1:
            got.append(s.get("p[1]", "alpha[1]", "alpha[2]"))
            out = ref.outputs({})
            want.append([*out["p"].tolist(), *out["alpha"].tolist()])
        assert s.step(t, h), s.errors()
        ref.step({}, dt=h, t_end=t + h)
    assert got == want
    assert s.take_log() == []


def test_a_timed_plant_stepped_without_reading_its_outputs_takes_the_inputs_set(resources):
    """A host that sets the inputs and steps without reading any output (the outputs are not
    computed before the step) moves the plant as one that reads them each time."""
    a, b = Slave(resources["sridhar-ltvPlant"]), Slave(resources["sridhar-ltvPlant"], name="b")
    for s in (a, b):
        assert s.initialize(0.0, use_model_input=False) == []
    for k in range(6):
        u = math.cos(k)
        a.set_reals({"u[1]": u})
        b.set_reals({"u[1]": u})
        assert b.get("u_applied[1]") == [u]
        assert a.step(0.1 * k, 0.1), a.errors()
        assert b.step(0.1 * k, 0.1), b.errors()
    assert a.get("x[1]", "x[2]") == b.get("x[1]", "x[2]")
    assert a.get("x[1]", "x[2]") != [0.0, 0.0]  # the inputs moved it


def test_a_step_of_several_samples_of_a_timed_observer_is_that_many_steps_of_one(resources):
    """The B-spline observer has a sample time: a communication step of m samples runs m samples,
    the inputs held, as m steps of one sample do."""
    a, b = Slave(resources["sridhar-ltvBSplineObserver"]), Slave(resources["sridhar-ltvBSplineObserver"], name="b")
    for s in (a, b):
        assert s.initialize(0.0, window=0.2, hop=0.05) == []
    dt, m = 0.001, 4
    names = ["t_est[1]", "yhat[1]", "xhat[1]", "xhat[2]", "valid[1]"]
    for j in range(100):
        u, y = math.sin(3.0 * j * m * dt), math.cos(2.0 * j * m * dt)
        a.set_reals({"u[1]": u, "y[1]": y})
        assert a.step(j * m * dt, m * dt), a.errors()
        for i in range(m):
            b.set_reals({"u[1]": u, "y[1]": y})
            assert b.step((j * m + i) * dt, dt), b.errors()
    got = a.get(*names)
    assert got[-1] == 1.0  # the observer has estimates
    np.testing.assert_array_equal(got, b.get(*names))


def test_a_sample_of_a_long_step_that_fails_names_every_bad_output_and_consumes_nothing(resources):
    """A step of several samples whose second sample overflows is refused naming the sample and
    the outputs that are not finite; the instance stays where it was."""
    s = plant(resources)
    s.slave.setup_experiment(0.0)
    s.set("x0[1]", 1.5e308)
    s.set("x0[2]", 1.5e308)
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    s.set_reals({"p[1]": -1.0, "w[1]": 0.0})
    before = s.get("x[1]", "x[2]")
    s.take_log()
    assert not s.step(0.0, 3.0)
    errors = s.errors()
    # vertex 1: A = [[0.43, 0], [1, 0.48]]: sample 2 has x1 = 0.43 * 1.5e308 (finite) and x2 = inf;
    # z = x and y = x1 + 0 * x2 = nan (0 * inf): every output but x1
    assert errors == ["[PeixotoEx1Plant] fmi2DoStep refused at t = 0 (h = 3, 3 samples): sample 2 of 3 (at t = 1): "
                      "output y[1], z[1], z[2], x[2] is not finite (NaN or inf); nothing consumed"]
    assert s.get("x[1]", "x[2]") == before and s.slave._time == 0.0
    assert s.step(0.0, 1.0), s.errors()  # one sample still goes


def test_a_value_a_host_cannot_pass_as_a_real_is_an_error_naming_the_call(resources):
    s = plant(resources)
    assert s.initialize() == []
    s.slave.set_real([s.vr["w[1]"]], ["fast"])
    [message] = s.errors()
    assert message.startswith("[PeixotoEx1Plant] fmi2SetReal: TypeError: ")


def test_an_input_set_before_initialization_is_checked_with_the_relative_tolerance(resources):
    s = plant(resources)
    s.slave.setup_experiment(0.0)
    s.set("p[1]", 1.0 + 5e-13)  # inside the relative tolerance 1e-12 of the bound 1
    assert s.errors() == []
    s.set("p[1]", 1.0 + 5e-12)
    assert s.errors() == ["[PeixotoEx1Plant] input p[1] (theta) = 1.000000000005 is outside its declared range "
                          "[-1, 1]; value rejected"]


def test_the_step_rule_says_how_to_go_back_to_an_earlier_point(resources):
    s = plant(resources)
    assert s.initialize() == []
    assert s.step(0.0, 1.0)
    assert not s.step(0.0, 1.0)
    assert s.errors() == ["[PeixotoEx1Plant] fmi2DoStep refused at t = 0 (h = 1): the communication point t = 0 is "
                          "not the FMU's current time 1 (a skipped or repeated point; restore a state with "
                          "fmi2SetFMUstate to go back)"]


def test_a_model_parameter_is_an_fmu_parameter_that_changes_the_plant(resources):
    """peixoto-ex2's plant has the model parameter rho: the FMU declares it with the model file's
    value, and a value set before initialization gives the plant of the library at that rho."""
    s = Slave(resources["peixoto-ex2Plant"])
    system = load_system("peixoto-ex2")
    assert s.get("rho") == [float(system.parameters["rho"])]
    rho = float(system.parameters["rho"]) + 2.0  # inside its declared range [1, 21]
    assert s.initialize(rho=rho) == []
    k = np.arange(8)
    p = 0.5 * np.sin(0.25 * k)
    got = []
    for j in k:
        s.set_reals({"p[1]": float(p[j]), "w[1]": float(paper_w(j + 10))})
        got.append(s.get("y[1]"))
        assert s.step(float(j), 1.0), s.errors()
    model = load_system("peixoto-ex2", parameters={"rho": rho}).model()
    ref = model.simulate(model.alpha_batch(p[:, None]), paper_w(k + 10)[:, None])
    assert np.array_equal(np.array(got), ref.y)
    default = system.model()
    assert not np.array_equal(default.simulate(default.alpha_batch(p[:, None]), paper_w(k + 10)[:, None]).y, ref.y)


def test_the_instances_of_an_fmu_share_its_loaded_model_file_until_it_or_rho_changes(tmp_path, monkeypatch):
    """fmi2Reset runs the slave's constructor again (a sweep resets the same instances for each
    task): the model file is read and parsed once per process for the same bytes and model
    parameter values, the model built once from it, wherever the FMU was unpacked; another rho,
    or an edited file, loads again."""
    from collections import OrderedDict

    import lpvest.fmi._slave as slave_module
    import lpvest.systems._modelfile as modelfile
    from lpvest.core._errors import ModelFileError

    monkeypatch.setattr(slave_module, "_LOADED", OrderedDict())  # not what other tests loaded
    folder = write_resources("peixoto-ex2", "Plant", tmp_path / "res")
    loads: list[dict[str, float]] = []
    real_load = modelfile.load_system

    def counted(path, parameters=None):
        loads.append(dict(parameters or {}))
        return real_load(path, parameters=parameters)

    monkeypatch.setattr(modelfile, "load_system", counted)
    first = Slave(folder)  # the declarations: the file's values; the initialization: the parameters'
    assert first.initialize() == [] and loads == [{}, {"rho": 1.0}]
    again = Slave(folder)  # what fmi2Reset does: the constructor once more
    assert again.initialize() == [] and loads == [{}, {"rho": 1.0}]
    assert again.slave.model({"rho": 1.0}) is first.slave.model({"rho": 1.0, "seed": 3})
    assert again.slave.model() is first.slave.model({"seed": 3})
    elsewhere = shutil.copytree(folder, tmp_path / "unpacked-elsewhere")  # another unpacked copy of the FMU
    assert Slave(elsewhere).initialize() == [] and loads == [{}, {"rho": 1.0}]
    rho = Slave(folder)
    assert rho.initialize(rho=13.0) == [] and loads == [{}, {"rho": 1.0}, {"rho": 13.0}]
    assert rho.slave.model({"rho": 13.0}) is not first.slave.model({"rho": 1.0})
    assert rho.slave.system({"rho": 13.0}).parameters["rho"] == 13.0
    model_file = folder / "model.toml"
    model_file.write_text(model_file.read_text() + "\n# edited\n")
    assert Slave(folder).initialize() == [] and loads == [{}, {"rho": 1.0}, {"rho": 13.0}, {}, {"rho": 1.0}]
    for value in range(1, 12):  # a host with instances at many values keeps the last few
        assert Slave(folder).initialize(rho=float(value)) == []
    assert len(slave_module._LOADED) == slave_module._LOADED_MAX
    gone = Slave(folder)
    model_file.unlink()  # a folder removed under a live instance: a typed error naming the file
    with pytest.raises(ModelFileError, match=r"res/model\.toml: no such model file"):
        gone.slave.system({"rho": 2.5})


def test_a_restored_state_tells_the_status_bridge_its_time(resources):
    """fmi2GetRealStatus(fmi2LastSuccessfulTime) after fmi2SetFMUstate is the restored time: the
    slave states it in a message of the category the status bridge consumes (status_bridge.c)."""
    s = plant(resources)
    assert s.initialize(2.5, sample_time=0.5) == []
    drive(s, 2.5, 0.5, 3)
    state = s.get_state()
    drive(s, 2.5, 0.5, 2, k0=3)
    s.slave.log_queue.clear()
    s.set_state(state)
    assert [(m.category, m.msg) for m in s.slave.log_queue] == [("lpvest.time", "4010000000000000")]  # 4.0


def test_many_outputs_that_are_not_finite_are_named_five_then_an_ellipsis(resources):
    k = Slave(resources["cox-toth-truncationKalman"])
    assert k.initialize(0.0, **{"x0[1]": 1.7e308, "x0[2]": -1.7e308}) == []
    k.set_reals({"p[1]": 1.0, "u[1]": 0.0, "y[1]": -1.7e308, "y[2]": 1.7e308})
    names = [n for n in k.vr if k.slave._elements[k.vr[n]].kind == "output"]
    values = k.get(*names)
    bad = [n for n, v in zip(names, values, strict=True) if not math.isfinite(v)]
    assert len(bad) > 5
    assert k.errors()[-1] == (f"[CoxTothTruncationKalman] fmi2GetReal: output {', '.join(bad[:5])} ... is not finite "
                              "(NaN or inf) at t = 0")


def test_the_range_tolerance_is_relative_to_the_bounds_of_a_wide_range(tmp_path):
    """A scheduling box [0, 1e6]: a value 5e-7 above 1e6 is rounding (1e-12 of the bound) and
    accepted, 2e-6 above is outside; before and after initialization alike."""
    model = tmp_path / "wide.toml"
    model.write_text("""
[system]
name = "wide"
title = "a one-state polytopic plant scheduled over [0, 1e6]"
[scheduling]
names = ["theta"]
lower = [0.0]
upper = [1e6]
[models.plant]
type = "polytopic"
[models.plant.map]
kind = "formulas"
alpha = ["1 - theta/1e6", "theta/1e6"]
[[models.plant.vertex]]
A = [[0.5]]
[[models.plant.vertex]]
A = [[0.1]]
[models.plant.common]
Bw = [[1.0]]
Cz = [[1.0]]
Dz = [[0.0]]
Cy = [[1.0]]
Dy = [[1.0]]
""")
    s = Slave(write_resources(str(model), "Plant", tmp_path / "r"))
    s.slave.setup_experiment(0.0)
    s.set("p[1]", 1e6 + 5e-7)
    assert s.errors() == []
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    for value in (1e6 + 5e-7, 1e6 + 2e-6):
        s.set("p[1]", value)
    assert s.errors() == [f"[{s.slave.modelName}] input p[1] (theta) = 1000000.000002 is outside its declared range "
                          "[0, 1000000]; value rejected"]
    assert s.get("p[1]") == [1e6 + 5e-7]


# -- a component that is not an lpvest Component (duck-typed) -------------------------------


class _Duck:
    """A component that is not an :class:`lpvest.core._protocol.Component`: ports, ``outputs``,
    ``step``, ``reset`` and its state only (no ``prepare``/``advance``, no ``timed``). ``fail``:
    ``("raise" | "nan", n)`` makes its n-th step raise or return NaN outputs."""

    def __init__(self, inner, extra: bool, fail):
        from lpvest.core._protocol import Port

        self.inner, self.fail, self.steps, self.extra = inner, fail, 0, extra
        self.input_ports = tuple(inner.input_ports)
        self.output_ports = tuple(inner.output_ports) + ((Port("extra", (1,), "one more: y again"),) if extra else ())

    def _with_extra(self, out):
        return {**out, "extra": out["y"].copy()} if self.extra else out

    def outputs(self, inputs):
        return self._with_extra(self.inner.outputs(inputs))

    def step(self, inputs):
        self.steps += 1
        if self.fail == ("raise", self.steps):
            raise ValueError(f"step {self.steps} went wrong")
        out = self._with_extra(self.inner.step(inputs))
        return {k: np.full_like(v, np.nan) for k, v in out.items()} if self.fail == ("nan", self.steps) else out

    def reset(self):
        self.inner.reset()
        self.steps = 0

    def get_state(self):
        return self.inner.get_state(), self.steps

    def set_state(self, state):
        self.inner.set_state(state[0])
        self.steps = state[1]


def foreign(resources, fail=None, name: str = "foreign", extra: bool = False) -> Slave:
    """peixoto-ex1's plant slave whose component is a :class:`_Duck`, with parameters more:
    ``limit`` (an Integer with only a maximum), ``gain`` (a Real with only a maximum) and
    ``extra`` (one output more: other ports; ``extra``: its start value, the FMU's ports)."""
    from lpvest.fmi._parameters import Parameter

    from .slave_harness import _script

    class ForeignPlant(_script("lpvest_plant.py").LpvestPlant):
        def declare(self):
            return [*super().declare(), Parameter("limit", 3, "an Integer with only a maximum", maximum=5),
                    Parameter("gain", 1.0, "a Real with only a maximum", maximum=2.0),
                    Parameter("extra", extra, "one output more (other ports: another FMU)")]

        def make_component(self, params):
            return _Duck(super().make_component(params), params["extra"], fail)

    s = Slave.__new__(Slave)
    s.slave = ForeignPlant(instance_name=name, resources=str(resources["peixoto-ex1Plant"]))
    s.vr = {v.name: vr for vr, v in s.slave.vars.items()}
    return s


def test_a_component_that_is_not_an_lpvest_component_runs_a_step_of_m_samples_as_m_steps(resources):
    a, b, ref = foreign(resources), foreign(resources, name="b"), plant(resources)
    for s in (a, b, ref):
        assert s.initialize() == []
    for j in range(4):
        inputs = {"p[1]": float(theta(j)), "w[1]": float(paper_w(j + 10))}
        a.set_reals(inputs)
        assert a.step(3.0 * j, 3.0), a.errors()
        for i in range(3):
            for s in (b, ref):
                s.set_reals(inputs)
                assert s.step(3.0 * j + i, 1.0), s.errors()
    assert a.get("x[1]", "x[2]") == b.get("x[1]", "x[2]") == ref.get("x[1]", "x[2]")


@pytest.mark.parametrize(("fail", "why"), [(("raise", 2), "ValueError: step 2 went wrong"),
                                           (("nan", 2), "output y[1], z[1], z[2], x[1], x[2] is not finite "
                                                        "(NaN or inf)")])
def test_a_foreign_components_failing_later_sample_is_named_and_consumes_nothing(resources, fail, why):
    s, ref = foreign(resources, fail), plant(resources)
    for x in (s, ref):
        assert x.initialize() == []
        x.set_reals({"p[1]": 0.5, "w[1]": 0.25})
    assert not s.step(0.0, 3.0)
    assert s.errors() == [f"[PeixotoEx1Plant] fmi2DoStep refused at t = 0 (h = 3, 3 samples): sample 2 of 3 "
                          f"(at t = 1): {why}; nothing consumed"]
    assert s.slave._time == 0.0 and s.get("x[1]", "x[2]") == ref.get("x[1]", "x[2]")


def test_six_outputs_of_a_later_sample_that_are_not_finite_are_named_five_then_an_ellipsis(resources):
    """The message names at most five outputs and says when there are more: a sixth is not dropped
    silently (the six outputs of a foreign plant with one output more, all NaN in sample 2)."""
    s = foreign(resources, ("nan", 2), extra=True)
    assert [v.name for v in s.slave.vars.values() if s.slave._elements[v.value_reference].kind == "output"] == [
        "y[1]", "z[1]", "z[2]", "x[1]", "x[2]", "extra[1]"]
    assert s.initialize() == []
    s.set_reals({"p[1]": 0.5, "w[1]": 0.25})
    assert not s.step(0.0, 3.0)
    assert s.errors() == ["[PeixotoEx1Plant] fmi2DoStep refused at t = 0 (h = 3, 3 samples): sample 2 of 3 (at t = 1): "
                          "output y[1], z[1], z[2], x[1], x[2] ... is not finite (NaN or inf); nothing consumed"]


def test_parameters_are_checked_against_a_one_sided_range_and_may_not_change_the_ports(resources):
    s = foreign(resources)
    s.slave.setup_experiment(0.0)
    s.set("limit", 7)
    # an FMI Integer is 32 bits: without a declared minimum, the range starts at -2**31
    assert s.errors() == ["[PeixotoEx1Plant] parameter limit = 7 is outside its declared range [-2147483648, 5]; "
                          "value rejected"]
    s.set("gain", 2.5)  # a Real without a minimum: the range starts at -inf
    assert s.errors() == ["[PeixotoEx1Plant] parameter gain = 2.5 is outside its declared range [-inf, 2]; "
                          "value rejected"]
    s.slave.set_integer([s.vr["limit"]], [math.nan])  # what no FMI Integer can hold: an error, not a crash
    assert s.errors() == ["[PeixotoEx1Plant] fmi2SetInteger: ValueError: cannot convert float NaN to integer"]
    s.set("gain", -1e300)
    s.set("limit", 5)
    s.set("extra", True)
    s.slave.enter_initialization_mode()
    s.slave.exit_initialization_mode()
    assert s.errors() == ["[PeixotoEx1Plant] fmi2ExitInitializationMode: these parameters change the FMU's inputs "
                          "or outputs; rebuild the FMU instead"]
    assert not s.step(0.0, 1.0)


# -- what the native exporter and a host read of the variables ------------------------------


def test_the_variable_table_lists_every_variable_with_its_range_and_name_in_messages(resources):
    """What the native backend's exporter declares and checks (lpvest.fmi.native), and the
    descriptions a host shows: the port's, with the element's label when it has one."""
    s = plant(resources)
    table = s.slave.variable_table()
    rows = [(v["name"], v["kind"], v["owner"], v["index"], v["type"], v["minimum"], v["maximum"], v["tol"], v["what"])
            for v in table["variables"]]
    assert rows == [
        ("x0[1]", "parameter", "x0", 0, "Real", None, None, 0.0, "parameter x0[1]"),
        ("x0[2]", "parameter", "x0", 1, "Real", None, None, 0.0, "parameter x0[2]"),
        ("sample_time", "parameter", "sample_time", 0, "Real", 0.0, None, 0.0, "parameter sample_time"),
        ("p[1]", "input", "p", 0, "Real", -1.0, 1.0, 1e-12, "input p[1] (theta)"),
        ("w[1]", "input", "w", 0, "Real", None, None, 1e-12, "input w[1]"),
        ("y[1]", "output", "y", 0, "Real", None, None, 0.0, "output y[1]"),
        ("z[1]", "output", "z", 0, "Real", None, None, 0.0, "output z[1]"),
        ("z[2]", "output", "z", 1, "Real", None, None, 0.0, "output z[2]"),
        ("x[1]", "output", "x", 0, "Real", None, None, 0.0, "output x[1]"),
        ("x[2]", "output", "x", 1, "Real", None, None, 0.0, "output x[2]")]
    assert [v["name"] for v in table["variables"]] == [s.slave.vars[vr].name for vr in sorted(s.slave.vars)]
    assert [p.name for p in table["parameters"]] == ["x0", "sample_time"]
    assert [p.name for p in table["inputs"]] == ["p", "w"] and [p.name for p in table["outputs"]] == ["y", "z", "x"]
    assert table["timed"] is False and table["sample_time"] == "sample_time"
    descriptions = {v.name: v.description for v in s.slave.vars.values()}
    assert descriptions["p[1]"] == "scheduling (theta)" and descriptions["w[1]"] == "disturbance"
    assert descriptions["y[1]"] == "measured output" and descriptions["x[2]"] == "state"  # outputs: no range


def test_a_model_parameter_carries_its_declared_range_and_description(resources):
    s = Slave(resources["peixoto-ex2Plant"])
    [rho] = [v for v in s.slave.variable_table()["variables"] if v["name"] == "rho"]
    assert (rho["kind"], rho["minimum"], rho["maximum"]) == ("parameter", 1.0, 21.0)
    assert s.slave.vars[s.vr["rho"]].description == (
        "model parameter rho of peixoto-ex2: A_1[2,2] = -0.05 rho; the paper's range (unstable beyond 21.4)")
    s.slave.setup_experiment(0.0)
    s.set("rho", 22.0)
    assert s.errors() == ["[PeixotoEx2Plant] parameter rho = 22 is outside its declared range [1, 21]; value rejected"]


def test_reading_an_input_and_an_output_in_one_call_gives_the_output_of_the_inputs_just_set(resources):
    a, b = plant(resources), plant(resources)
    for s in (a, b):
        assert s.initialize() == []
        s.set_reals({"p[1]": 0.5, "w[1]": 0.25})
        assert s.step(0.0, 1.0), s.errors()
        s.set_reals({"p[1]": 0.5, "w[1]": 0.75})
    assert a.slave.get_real([a.vr["w[1]"], a.vr["y[1]"]]) == [0.75, *b.get("y[1]")]
    assert a.errors() == []


def test_a_step_refused_for_several_invalid_inputs_names_each(resources):
    s = plant(resources)
    assert s.initialize() == []
    s.set_reals({"p[1]": 5.0, "w[1]": math.nan})
    assert len(s.errors()) == 2
    assert not s.step(0.0, 1.0)
    assert s.errors() == ["[PeixotoEx1Plant] fmi2DoStep refused at t = 0 (h = 1): invalid input(s) p[1], w[1] (set "
                          "valid values, restore a state with fmi2SetFMUstate, or reset)"]


OUTS = ["y[1]", "z[1]", "z[2]", "x[1]", "x[2]"]


def test_a_restored_state_steps_on_with_the_inputs_it_held(resources):
    """After a step the plant holds its inputs (zero-order hold): a state taken then, restored,
    and stepped without setting inputs gives the outputs of the original's next step."""
    s = plant(resources)
    assert s.initialize() == []
    for k in range(3):
        s.set_reals({"p[1]": 0.3 * k, "w[1]": 0.5 + k})
        assert s.step(float(k), 1.0), s.errors()
    state, held = s.get_state(), s.get(*OUTS)
    assert s.step(3.0, 1.0), s.errors()
    after = s.get(*OUTS)
    assert after[:3] != held[:3]  # y, z depend on the new state: the test can tell them apart
    s.set_state(state)
    assert s.get(*OUTS) == held
    assert s.step(3.0, 1.0), s.errors()
    assert s.get(*OUTS) == after


def test_inputs_set_again_after_a_rejected_one_are_the_next_samples_inputs(resources):
    """A rejected input sends later sets through the checked path; once corrected, the
    outputs and the step are those of an instance that never saw the bad value."""
    a, b = plant(resources), plant(resources)
    for s in (a, b):
        assert s.initialize() == []
        s.set_reals({"p[1]": 0.5, "w[1]": 0.25})
        assert s.step(0.0, 1.0), s.errors()
    a.set_reals({"p[1]": 5.0})
    assert a.errors() == ["[PeixotoEx1Plant] input p[1] (theta) = 5 is outside its declared range [-1, 1]; "
                          "value rejected"]
    for s in (a, b):
        s.set_reals({"p[1]": -0.5, "w[1]": 0.75})
    assert a.get(*OUTS) == b.get(*OUTS)
    assert a.step(1.0, 1.0) and b.step(1.0, 1.0), a.errors()
    assert a.get(*OUTS) == b.get(*OUTS) and a.errors() == []


# -- a timed component with a sample time, a plant for a system's second model, alpha's range ----


def sampled_ltv_plant(folder, ts: float) -> Slave:
    """sridhar-ltv's plant as a timed component with a sample time: its spec names the parameter
    ``ts`` as the sample time, as the B-spline observer's spec names ``dt``, so that a step of m
    samples runs m samples (the model's input u = 120 sin t applied inside each)."""
    import json

    from lpvest.fmi._parameters import SPEC_FILE, Parameter

    from .slave_harness import _script

    folder = write_resources("sridhar-ltv", "Plant", folder)
    spec = json.loads((folder / SPEC_FILE).read_text())
    spec["estimator"] = {"sample_time": "ts"}
    (folder / SPEC_FILE).write_text(json.dumps(spec))

    class SampledLtvPlant(_script("lpvest_ltv_plant.py").LpvestLtvPlant):
        def declare(self):
            return [*super().declare(), Parameter("ts", ts, "sample time (s)", minimum=0.0)]

    s = Slave.__new__(Slave)
    s.slave = SampledLtvPlant(instance_name="sampled", resources=str(folder))
    s.vr = {v.name: vr for vr, v in s.slave.vars.items()}
    return s


# (sample time, host step, steps, whether ending at t + 3 ts instead moves the state beyond rounding:
# by one ulp of t, 1e-16 s, it moves the state by about an ulp, which another rounding may not show;
# by 1e-11 s, by some 2e5 ulps)
@pytest.mark.parametrize(("ts", "h", "n", "apart"), [(0.1, 0.3, 3, False), (0.03333333333, 0.1, 4, True)])
def test_a_timed_component_with_a_sample_time_ends_a_step_of_m_samples_at_the_hosts_point(tmp_path, ts, h, n,
                                                                                          apart):
    """A step of m = 3 samples: the component takes samples 1 .. m-1 to t + i ts and ends the
    last at the host's point t + h, where the next step starts, not at t + m ts. The two differ
    in the last bits when m ts is rounded otherwise than h (ts = 0.1, h = 0.3: 3 * 0.1 =
    0.30000000000000004), and by 1e-11 s when h is m samples only to the communication-point
    tolerance (a sample time of 1/30 s written to 11 digits, host steps of 0.1 s); the plant's
    state is the solution at the end point, computed here as the library's plant does it at the
    host's points, to the bit. (sridhar-ltv's own plant has no
    sample time: a step there is one step of a function of time, whatever h, and never runs the
    samples of a long step; the B-spline observer takes the end point only to check, to 1e-9,
    that a sample is its next one.)"""
    from lpvest.systems._streaming import LTVPlant

    s = sampled_ltv_plant(tmp_path / "r", ts)
    assert s.initialize(0.0) == []
    model = load_system("sridhar-ltv").model(s.slave.spec["model_key"])
    ref, summed = LTVPlant(model), LTVPlant(model)
    for p in (ref, summed):
        p.reset(0.0)
    for k in range(n):
        t = k * h  # the host's points
        assert s.step(t, h), s.errors()
        for i in range(1, 4):
            ref.step({"u": [0.0]}, dt=ts, t_end=t + h if i == 3 else t + i * ts)
            summed.step({"u": [0.0]}, dt=ts, t_end=t + i * ts)
    assert t + h != t + 3 * ts  # the last step's two ends differ
    got = s.get("x[1]", "x[2]", "y[1]")
    want = ref.outputs({"u": [0.0]})
    assert got == [*want["x"].tolist(), *want["y"].tolist()]
    if apart:  # the end of a step is seen in the state
        assert got[:2] != summed.get_state()["x"].tolist()
    assert s.slave._time == t + h


def test_the_plant_of_a_system_whose_default_model_gets_none_is_the_model_the_builder_chose(tmp_path):
    """cox-toth-ex1's default model, (21b), has a gain in p_{t+1} and gets no plant: the builder
    makes the plant of (21c), ``augmented``, and the FMU is that model's plant, also when it is
    made again from the parameters set (here at initialization)."""
    from lpvest.systems._streaming import DiscretePlant

    s = Slave(write_resources("cox-toth-ex1", "Plant", tmp_path / "r"))
    assert s.slave.spec["model_key"] == "augmented" != load_system("cox-toth-ex1").default
    assert s.initialize(0.0, noise=False, **{"x0[1]": 0.5, "x0[2]": -0.25}) == []  # e is the input e
    ref = DiscretePlant(load_system("cox-toth-ex1").model("augmented"), x0=[0.5, -0.25])
    for k in range(5):
        inputs = {"p": [float(theta(k))], "u": [math.cos(k)], "e": [0.1 * k]}
        s.set_reals({"p[1]": inputs["p"][0], "u[1]": inputs["u"][0], "e[1]": inputs["e"][0]})
        out = ref.step(inputs)
        assert s.get("y[1]") == out["y"].tolist()
        assert s.step(float(k), 1.0), s.errors()
    assert s.get("x[1]", "x[2]") == ref.outputs({"p": [0.0], "u": [0.0], "e": [0.0]})["x"].tolist()


def test_a_schedulers_vertex_weights_are_declared_in_0_1_with_their_vertex(resources):
    s = Slave(resources["peixoto-ex1Scheduler"])
    table = s.slave.variable_table()["variables"]
    rows = {v["name"]: (v["kind"], v["minimum"], v["maximum"], v["what"]) for v in table}
    assert rows["alpha[1]"] == ("output", 0.0, 1.0, "output alpha[1] (weight of vertex 1)")
    assert rows["alpha[2]"] == ("output", 0.0, 1.0, "output alpha[2] (weight of vertex 2)")
    assert rows["p[1]"] == ("output", -1.0, 1.0, "output p[1] (theta)")
    assert s.slave.vars[s.vr["alpha[2]"]].description == "vertex weights (weight of vertex 2)"
