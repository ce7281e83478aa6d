"""The master with FMUs that lpvest did not make: the foreign C FMUs of
tests/foreign_fmus.py, with a variable of every FMI 2.0 type (AllTypes) and
one that discards a step at the end of its validity (Limited), as the FMI
Reference FMUs Feedthrough and Stair do."""

from __future__ import annotations

import numpy as np
import pytest

from lpvest.cli import main
from lpvest.cosim import Component, CoSimulation, CoSimulationError, DiscardedStepWarning, simulate
from tests.tolerances import roundoff

H = 0.5  # a power of two: the communication points and the FMUs' times are exact


def test_the_foreign_fmus_are_valid_fmi_2_0(foreign_fmus):
    from fmpy.validation import validate_fmu

    for name, path in foreign_fmus.items():
        assert validate_fmu(str(path)) == [], name


def _chain(foreign_fmus, last=100):
    """lim (time, whole time units) -> a -> b, every non-String type connected a -> b."""
    comps = [
        Component("lim", foreign_fmus["Limited"], {"last": last}),
        Component("a", foreign_fmus["AllTypes"],
                  {"gain": 3.0, "offset": -2, "floor_level": "mid", "invert": True, "prefix": "A:"}),
        Component("b", foreign_fmus["AllTypes"], {"floor_level": 1, "invert": True}),
    ]
    conns = ["lim.time_out -> a.real_in", "lim.counter -> a.int_in", "a.real_out -> b.real_in",
             "a.int_out -> b.int_in", "a.enum_out -> b.enum_in", "a.bool_out -> b.bool_in"]
    return comps, conns


def test_every_type_is_exchanged_and_recorded(foreign_fmus):
    """Integer, Boolean and Enumeration values reach their inputs in the same
    step and are recorded exactly, each read with its own type's call (the
    FMU's value references overlap across types, so a Real read of an Integer
    would return another variable); String outputs are left out, and said so."""
    comps, conns = _chain(foreign_fmus)
    with CoSimulation(comps, conns, step_size=H) as sim:
        assert sim.not_recorded == ["a.string_out", "b.string_out"]
        res = sim.run(12)
    t = np.arange(13) * H
    counter = np.floor(t)  # events at t = 1, 2, ...
    assert res.dtype.names == ("time", "lim.counter", "lim.time_out", "lim.y", "a.real_out", "a.int_out", "a.steps",
                               "a.enum_out", "a.bool_out", "b.real_out", "b.int_out", "b.steps", "b.enum_out",
                               "b.bool_out")
    # every value is exact: multiples of 0.5 times 3 and 2, small integers
    np.testing.assert_array_equal(res["lim.time_out"], t)
    np.testing.assert_array_equal(res["lim.counter"], counter)
    np.testing.assert_array_equal(res["a.real_out"], 3.0 * t)           # gain * real_in
    np.testing.assert_array_equal(res["a.int_out"], counter - 2)        # int_in + offset
    np.testing.assert_array_equal(res["b.real_out"], 2.0 * 3.0 * t)     # b's default gain 2
    np.testing.assert_array_equal(res["b.int_out"], counter - 2 + 1)    # b's default offset 1
    np.testing.assert_array_equal(res["a.enum_out"], np.full(13, 2.0))  # max(enum_in = low, floor = mid)
    np.testing.assert_array_equal(res["b.enum_out"], np.full(13, 2.0))  # max(mid, floor = low)
    np.testing.assert_array_equal(res["a.bool_out"], np.ones(13))       # false xor invert
    np.testing.assert_array_equal(res["b.bool_out"], np.zeros(13))      # true xor invert
    np.testing.assert_array_equal(res["a.steps"], np.arange(13.0))


def test_an_explicit_record_of_every_type_and_the_refusals(foreign_fmus):
    comps, conns = _chain(foreign_fmus)
    with CoSimulation(comps, conns, step_size=H, record=["b.enum_out", "a.bool_out", "b.int_out"]) as sim:
        assert sim.recorded == ["b.enum_out", "a.bool_out", "b.int_out"] and sim.not_recorded == []
        res = sim.run(2)
    np.testing.assert_array_equal(res["b.enum_out"], [2.0, 2.0, 2.0])
    with pytest.raises(CoSimulationError, match=r"recorded variable 'a\.string_out' is a String; only Real, Integer, "
                                                r"Boolean and Enumeration variables can be recorded") as info:
        CoSimulation.check(comps, conns, step_size=H, record=["a.string_out"])
    assert info.value.where == "record[1]"
    with pytest.raises(CoSimulationError, match=r"connection a\.string_out -> b\.string_in: a String variable cannot "
                                                r"be connected") as info:
        CoSimulation.check(comps, ["a.string_out -> b.string_in"], step_size=H)
    assert info.value.where == "connections[1]"
    with pytest.raises(CoSimulationError, match=r"connection a\.enum_out -> b\.int_in: types Enumeration and Integer"):
        CoSimulation.check(comps, ["a.enum_out -> b.enum_in", "a.enum_out -> b.int_in"], step_size=H)


@pytest.mark.parametrize("value", [7, "top", True, 2.5])
def test_an_enumeration_start_value_is_an_item_name_or_value(foreign_fmus, value):
    comp = Component("a", foreign_fmus["AllTypes"], {"floor_level": value})
    shown = repr(value) if isinstance(value, str) else str(value)
    message = (r"component a: floor_level: expected an integer, found bool True" if value is True
               else r"component a: floor_level: expected an integer, found float 2\.5" if value == 2.5
               else rf"component a: floor_level: expected one of low = 1, mid = 2, high = 3 \(a name or its value\), "
                    rf"found {type(value).__name__} {shown}")
    with pytest.raises(CoSimulationError, match=f"^{message}$") as info:
        CoSimulation.check([comp], [], step_size=H)
    assert info.value.where == "components.a.parameters.floor_level"


def test_a_component_without_parameters_may_say_none(foreign_fmus):
    res = simulate([Component("a", foreign_fmus["AllTypes"], None)], [], step_size=H, n_steps=2)
    np.testing.assert_array_equal(res["a.int_out"], [1.0, 1.0, 1.0])  # int_in 0 + default offset 1
    with pytest.raises(CoSimulationError, match=r"^component 'a': parameters: expected a mapping of variable names "
                                                r"to start values, found list$"):
        Component("a", foreign_fmus["AllTypes"], [1.0])  # type: ignore[arg-type]


# -- fmi2Discard ------------------------------------------------------------------------------------------


def test_a_discarded_step_ends_the_run_cleanly_where_fmpy_does(foreign_fmus):
    """Limited discards the step that reaches t = 5 (last = 5): from t = 4.8
    with h = 0.3, its last successful time 5 lies inside the step. The run
    stops with a warning, keeps the rows up to t = 4.8, and they are fmpy's
    (whose simulate_fmu also ends cleanly there, with one more row at the
    component's last successful time, which a master of several components
    cannot have)."""
    from fmpy import simulate_fmu

    h, n = 0.3, 30
    comps = [Component("lim", foreign_fmus["Limited"]),
             Component("a", foreign_fmus["AllTypes"], {"gain": -1.0})]  # downstream: stepped, then closed
    with CoSimulation(comps, ["lim.time_out -> a.real_in"], step_size=h) as sim:
        with pytest.warns(DiscardedStepWarning, match=r"^component lim: doStep at t = 4\.8 returned discard: it asks "
                                                      r"to end the simulation \(last successful time 5\); the run "
                                                      r"stops at t = 4\.8 after 16 of 30 steps \(\[DISCARD\] counter "
                                                      r"reached 5 at t = 5: the end of this model's validity\)$"):
            res = sim.run(n)
        stop = sim.discarded
        assert stop is not None
        assert (stop.component, stop.steps, stop.last_successful_time, stop.terminated) == ("lim", 16, 5.0, True)
        assert stop.time == 16 * h
        np.testing.assert_array_equal(res["time"], np.arange(17) * h)
        # a run after reset() may ask for every step instead
        sim.reset({"lim": {"last": 2}})
        assert sim.discarded is None
        with pytest.raises(CoSimulationError, match=r"^component lim: doStep at t = 1\.8 returned discard "
                                                    r"\(\[DISCARD\] counter reached 2 at t = 2: "):
            sim.run(n, on_discard="error")
    ref = simulate_fmu(str(foreign_fmus["Limited"]), stop_time=n * h, output_interval=h)
    assert ref["time"][-1] == 5.0 and ref["counter"][-1] == 5  # fmpy's extra row
    np.testing.assert_array_equal(res["lim.counter"], ref["counter"][:-1])
    # the times: ours t0 + k h; fmpy's and the FMU's sums of k steps (k roundings of at most 5)
    np.testing.assert_allclose(res["lim.time_out"], ref["time_out"][:-1], rtol=0, atol=roundoff(5.0, n))
    np.testing.assert_array_equal(res["a.real_out"], -res["lim.time_out"])


def test_a_discard_without_a_request_to_terminate_also_stops_the_run(foreign_fmus):
    """fmi2Terminated false: the FMU could not complete the step. A fixed-step
    master cannot retry a shorter one; it stops the same way and says why."""
    comp = Component("lim", foreign_fmus["Limited"], {"last": 2, "terminate": False})
    with pytest.warns(DiscardedStepWarning, match=r"^component lim: doStep at t = 1\.5 returned discard: it could not "
                                                  r"complete the step \(last successful time 2\); the run stops at "
                                                  r"t = 1\.5 after 3 of 8 steps"):
        res = simulate([comp], [], step_size=H, n_steps=8)
    np.testing.assert_array_equal(res["lim.counter"], [0.0, 0.0, 1.0, 1.0])


# -- the command line ---------------------------------------------------------------------------------------


def _file(tmp_path, foreign_fmus, body):
    for name, path in foreign_fmus.items():
        (tmp_path / f"{name}.fmu").write_bytes(path.read_bytes())
    path = tmp_path / "run.toml"
    path.write_text(f'step_size = {H}\nsteps = 10\nfmu_dir = "."\n' + body)
    return path


def test_lpvest_cosim_records_an_enumeration_output_by_default(foreign_fmus, tmp_path, capsys):
    """The Reference FMU Feedthrough case: an Enumeration output and the default record."""
    path = _file(tmp_path, foreign_fmus, '[components.a]\nfmu = "AllTypes"\nparameters = { floor_level = "high" }\n')
    assert main(["cosim", str(path), "--out", str(tmp_path / "out"), "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "  not recorded (String outputs): a.string_out" in out
    table = np.genfromtxt(tmp_path / "out" / "run.csv", delimiter=",", names=True)
    assert table.dtype.names == ("time", "areal_out", "aint_out", "asteps", "aenum_out", "abool_out")
    np.testing.assert_array_equal(table["aenum_out"], np.full(11, 3.0))


def test_lpvest_cosim_stops_at_a_discarded_step_with_a_one_line_warning(foreign_fmus, tmp_path, capsys):
    path = _file(tmp_path, foreign_fmus, '[components.lim]\nfmu = "Limited"\nparameters = { last = 3 }\n')
    assert main(["cosim", str(path), "--out", str(tmp_path / "out"), "--no-plot"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ("lpvest: warning: component lim: doStep at t = 2.5 returned discard: it asks to end the "
                            "simulation (last successful time 3); the run stops at t = 2.5 after 5 of 10 steps "
                            "([DISCARD] counter reached 3 at t = 3: the end of this model's validity)\n")
    assert "co-simulated run.toml: 1 component, stopped after 5 of 10 steps of 0.5 (t = 0 .. 2.5: lim discarded " \
           "the next step)" in captured.out
    table = np.genfromtxt(tmp_path / "out" / "run.csv", delimiter=",", names=True)
    np.testing.assert_array_equal(table["time"], np.arange(6) * H)


def test_lpvest_cosim_names_a_bad_enumeration_value_in_one_line(foreign_fmus, tmp_path, capsys):
    path = _file(tmp_path, foreign_fmus, '[components.a]\nfmu = "AllTypes"\nparameters = { floor_level = "top" }\n')
    assert main(["cosim", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err == (f"lpvest: error: {path}: components.a.parameters.floor_level: floor_level: expected one of "
                   "low = 1, mid = 2, high = 3 (a name or its value), found str 'top'\n")
