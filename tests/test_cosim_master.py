"""The co-simulation master (lpvest/cosim/_master.py) in this process, over stand-in FMUs that
record every FMI call (tests/fake_fmu.py): the order of sets, gets and steps inside a step, the
values each component sees, failures, start values, reset and close. tests/test_cosim.py runs
the master over real FMUs."""

from __future__ import annotations

import gc
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lpvest.core._errors import shorten
from lpvest.cosim import AlgebraicLoopError, Component, CoSimulation, CoSimulationError, simulate
from lpvest.cosim._master import DiscardedStep, DiscardedStepWarning, step_count, whole_steps

from . import fake_fmu
from .fake_fmu import CALLS, FakeSlave, Model, write_fmu


class Src(Model):
    variables = [("y", "output", "Real", 0.0, ""), ("n", "output", "Integer", 0, ""),
                 ("on", "output", "Boolean", False, ""), ("k", "parameter", "Real", 1.0, None),
                 ("count", "parameter", "Integer", 0, None), ("flag", "parameter", "Boolean", False, None),
                 ("label", "parameter", "String", "a", None)]

    def outputs(self):
        self["y"] = self["k"] * self.time + self["count"]
        self["n"] = round(self.time * 10)
        self["on"] = self.time >= 0.25


class Gain(Model):
    variables = [("u", "input", "Real", 0.0, None), ("i", "input", "Integer", 0, None),
                 ("y", "output", "Real", 0.0, ["u"]), ("j", "output", "Integer", 0, ["i"]),
                 ("z", "output", "Real", 0.0, ""), ("k", "parameter", "Real", 2.0, None)]

    def outputs(self):
        self["y"] = self["k"] * self["u"]
        self["j"] = 2 * self["i"]
        self["z"] = -self.time


class Delay(Model):
    variables = [("u", "input", "Real", 0.0, None), ("x", "output", "Real", 0.0, "")]

    def step(self, t, h):
        self["x"] = self["u"]


class Vec(Model):
    variables = [("v[2]", "input", "Real", 0.0, None), ("v[1]", "input", "Real", 0.0, None),
                 ("w[1]", "output", "Real", 0.0, ["v[1]"]), ("w[2]", "output", "Real", 0.0, ["v[2]"]),
                 ("w", "parameter", "String", "vector w", None), ("s", "output", "String", "x", "")]

    def outputs(self):
        self["w[1]"], self["w[2]"] = 10 * self["v[1]"], 100 * self["v[2]"]


@pytest.fixture
def fmus(tmp_path, monkeypatch):
    monkeypatch.setattr("fmpy.fmi2.FMU2Slave", FakeSlave)
    monkeypatch.setattr(FakeSlave, "MODELS", {"Src": Src, "Gain": Gain, "Delay": Delay, "Vec": Vec})
    monkeypatch.setattr(FakeSlave, "FAIL", {})
    monkeypatch.setattr(FakeSlave, "MESSAGES", {})
    CALLS.clear()
    return {m.__name__.lower(): write_fmu(tmp_path, m.__name__, m.variables) for m in (Src, Gain, Delay, Vec)}


CHAIN = ["src.y -> gain.u", "src.n -> gain.i", "gain.y -> delay.u"]


def chain(fmus, **kw):
    comps = [Component("src", fmus["src"], {"k": 3.0}), Component("gain", fmus["gain"], {"k": 2.0}),
             Component("delay", fmus["delay"])]
    return CoSimulation(comps, CHAIN, step_size=0.1, **kw)


def steps_of(calls):
    """The calls between doSteps, per communication point (exchange, then the doSteps)."""
    out, cur = [], []
    for name, what, detail in calls:
        cur.append((name, what, detail))
        if what == "doStep" and name == "delay":
            out.append(cur)
            cur = []
    return out, cur


def test_a_chain_reads_each_output_after_setting_the_inputs_it_depends_on_in_the_same_step(fmus):
    with chain(fmus) as sim:
        assert sim.execution_order == ["get src: n, on, y", "set gain: i, u", "get gain: j, y, z",
                                       "set delay: u", "get delay: x"]
        CALLS.clear()
        res = sim.run(5)
    steps, last = steps_of(c for c in CALLS if c[1] in ("get", "set", "doStep"))
    assert len(steps) == 5
    for calls in steps[1:]:  # steps after the first: the exchange of t_k, then every doStep at t_k
        assert [(n, w) for n, w, _ in calls] == [
            ("src", "get"), ("src", "get"), ("src", "get"),  # Real y, Integer n, Boolean on: one call per type
            ("gain", "set"), ("gain", "set"),  # inputs first: every input of gain before any of its outputs
            ("gain", "get"), ("gain", "get"),
            ("delay", "set"), ("delay", "get"),
            ("src", "doStep"), ("gain", "doStep"), ("delay", "doStep")]
    assert [(n, w) for n, w, _ in last] == [("src", "get")] * 3 + [("gain", "set")] * 2 + [("gain", "get")] * 2 + [
        ("delay", "set"), ("delay", "get")]  # the last row: exchanged, recorded, no step
    t = np.arange(6) * 0.1
    np.testing.assert_array_equal(res["time"], t)
    np.testing.assert_array_equal(res["src.y"], 3.0 * t)
    np.testing.assert_array_equal(res["gain.y"], 2.0 * res["src.y"])  # same step: no one-step delay
    np.testing.assert_array_equal(res["gain.j"], 2 * np.round(t * 10))
    np.testing.assert_array_equal(res["src.on"], t >= 0.25)
    np.testing.assert_array_equal(res["delay.x"], np.r_[0.0, res["gain.y"][:-1]])  # a state: one step late
    np.testing.assert_array_equal(res["gain.z"], -t)
    assert res.dtype.names == ("time", "src.y", "src.n", "src.on", "gain.y", "gain.j", "gain.z", "delay.x")


def test_components_are_scheduled_by_dependency_not_by_the_order_given(fmus):
    comps = [Component("delay", fmus["delay"]), Component("gain", fmus["gain"]), Component("src", fmus["src"])]
    sim = CoSimulation.check(comps, ["gain.y -> delay.u", "src.y -> gain.u"], step_size=1.0,
                             record=["delay.x", "gain.y"])
    assert sim.execution_order == ["get delay: x", "get src: y", "set gain: u", "get gain: y", "set delay: u"]
    assert sim.recorded == ["delay.x", "gain.y"]


def test_a_declared_feedthrough_override_changes_the_schedule_and_breaks_a_loop(fmus):
    comps = [Component("a", fmus["gain"]), Component("b", fmus["gain"])]
    loop = ["a.y -> b.u", "b.y -> a.u"]
    with pytest.raises(AlgebraicLoopError, match=r"^algebraic loop: these variables depend on each other through "
                                                 r"direct feedthrough: a.u, a.y, b.u, b.y \(declare") as info:
        CoSimulation.check(comps, loop, step_size=1.0)
    assert info.value.where == "connections"
    comps[1] = Component("b", fmus["gain"], feedthrough=False)
    sim = CoSimulation.check(comps, loop, step_size=1.0)
    # b.y no longer depends on b.u: read first; a's outputs that depend on no connected input (j, z)
    # are ready at once, a.y only after a.u is set
    assert sim.execution_order == ["get a: j, z", "get b: j, y", "set a: u", "get a: y", "set b: u", "get b: z"]
    comps[0] = Component("a", fmus["gain"], feedthrough=True)
    comps[1] = Component("b", fmus["delay"], feedthrough=True)
    with pytest.raises(AlgebraicLoopError):
        CoSimulation.check(comps, ["a.y -> b.u", "b.x -> a.u"], step_size=1.0)


def test_vectors_connect_element_by_element_in_index_order(fmus):
    comps = [Component("src", fmus["src"]), Component("g", fmus["gain"]), Component("v", fmus["vec"])]
    with CoSimulation(comps, ["src.y -> v.v[1]", "g.z -> v.v[2]"], step_size=0.5, start_time=1.0,
                      record=["v.w", "src.y"]) as sim:
        assert sim.recorded == ["v.w[1]", "v.w[2]", "src.y"]
        res = sim.run(stop_time=2.0)
    np.testing.assert_array_equal(res["time"], [1.0, 1.5, 2.0])
    np.testing.assert_array_equal(res["v.w[1]"], 10 * res["src.y"])
    np.testing.assert_array_equal(res["v.w[2]"], -100 * res["time"])
    with pytest.raises(CoSimulationError, match=r"^recorded variable 'v.s' is a String; only Real, Integer") as info:
        CoSimulation.check(comps, [], step_size=1.0, record=["v.s"])
    assert info.value.where == "record[1]"
    with pytest.raises(CoSimulationError, match=r"connection src.y -> v.v: 1 source and 2 target elements") as info:
        CoSimulation.check(comps, ["src.y -> v.v"], step_size=1.0)
    assert info.value.where == "connections[1]"


@pytest.mark.parametrize(("start", "stop", "h", "n"), [(0.0, 0.0, 0.1, 0), (2.5, 2.5, 0.1, 0), (0.0, 0.3, 0.1, 3),
                                                       (1e6, 1e6 + 0.7, 0.1, 7), (-1.0, 1.0, 0.25, 8)])
def test_whole_steps_counts_within_rounding_and_zero_length_is_zero_steps(start, stop, h, n):
    assert whole_steps(start, stop, h) == n
    assert step_count(start, stop, h)[0] == n


def test_a_run_of_zero_length_initialises_and_records_one_row_without_a_step(fmus):
    with chain(fmus, start_time=2.0) as sim:
        CALLS.clear()
        res = sim.run(stop_time=2.0)
    assert len(res) == 1 and res["time"][0] == 2.0 and res["gain.y"][0] == 2.0 * 3.0 * 2.0
    assert not any(w == "doStep" for _, w, _ in CALLS)
    assert [w for n, w, _ in CALLS if n == "gain" and w not in ("get", "set")] == [
        "setupExperiment", "setReal", "enterInitializationMode", "exitInitializationMode", "terminate", "freeInstance"]
    assert ("gain", "setupExperiment", (2.0, 2.0)) in CALLS


@pytest.mark.parametrize(("stop", "match"), [
    (0.35, r"^stop_time = 0.35: expected start_time \(0\) \+ a whole number of steps of 0.1; found 3.5 steps$"),
    (-0.2, r"^stop_time = -0.2: expected start_time \(0\) \+ a whole number of steps of 0.1; found -2 steps$"),
    (float("inf"), r"^stop_time = inf: expected start_time \+ a whole number of steps of 0.1 \(more steps than"),
])
def test_a_stop_time_that_is_not_a_whole_number_of_steps_is_refused(stop, match):
    with pytest.raises(CoSimulationError, match=match):
        whole_steps(0.0, stop, 0.1)
    assert step_count(0.0, 0.3 + 1e-8, 0.1)[0] is None and step_count(0.0, 0.3 + 1e-11, 0.1)[0] == 3


def test_run_arguments_are_checked(fmus):
    with chain(fmus) as sim:
        with pytest.raises(CoSimulationError, match="^give n_steps or stop_time$"):
            sim.run()
        with pytest.raises(CoSimulationError, match="^give n_steps or stop_time$"):
            sim.run(2, stop_time=0.2)
        with pytest.raises(CoSimulationError, match="^n_steps must be non-negative; found -1$"):
            sim.run(-1)
        sim.run(1)
        with pytest.raises(CoSimulationError, match=r"^the co-simulation has run; call reset\(\) before"):
            sim.run(1)
    with pytest.raises(CoSimulationError, match="^the co-simulation is closed$"):
        sim.run(1)
    with pytest.raises(CoSimulationError, match="^the co-simulation is closed$"):
        sim.reset()
    with pytest.raises(CoSimulationError, match=r"^step_size must be positive; found 0$"):
        CoSimulation([], [], step_size=0)
    with pytest.raises(CoSimulationError, match=r"^step_size must be positive; found nan$"):
        CoSimulation.check([], [], step_size=float("nan"))


@pytest.mark.parametrize(("instance", "call", "status", "match", "where"), [
    ("gain", "doStep", 3, r"^component gain: doStep at t = 0 returned error \(\[ERROR\] doStep failed in gain "
                          r"100%\)$", "components.gain"),
    ("delay", "doStep", 4, r"^component delay: doStep at t = 0 returned fatal \(\[FATAL\] doStep failed in delay",
     "components.delay"),
    ("src", "get", 3, r"^component src: reading outputs during initialization at t = 0 returned error",
     "components.src"),
    ("gain", "set", 2, r"^component gain: setting inputs during initialization at t = 0 returned discard",
     "components.gain"),
    ("gain", "set", lambda: 3 if any(w == "doStep" for _, w, _ in CALLS) else 0,
     r"^component gain: setting inputs at t = 0.1 returned error \(\[ERROR\] set failed in gain 100%\)$",
     "components.gain"),
    ("gain", "exitInitializationMode", 3, r"^component gain: exitInitializationMode failed at t = 0: ",
     "components.gain"),
    ("src", "setReal", 3, r"^component src: setting k = 3.0 failed: .* \(\[ERROR\] setReal failed in src 100%\)$",
     "components.src.parameters.k"),
])
def test_a_failing_component_is_named_with_the_time_and_its_last_message(fmus, instance, call, status, match,
                                                                         where):
    with chain(fmus) as sim:
        FakeSlave.FAIL[(instance, call)] = status
        with pytest.raises(CoSimulationError, match=match) as info:
            sim.run(3)
        assert info.value.where == where


def test_a_warning_from_a_step_is_not_a_failure(fmus):
    FakeSlave.FAIL[("gain", "doStep")] = 1
    res = simulate([Component("src", fmus["src"]), Component("gain", fmus["gain"])], ["src.y -> gain.u"],
                   step_size=1.0, n_steps=3, record=["gain.y"])
    # a warning status still skips the fake's step, and the run goes on to its end
    assert len(res) == 4


def test_start_values_reach_each_variable_as_its_fmi_type(fmus):
    comp = Component("src", fmus["src"], {"k": np.float64(0.5), "count": 3.0, "flag": np.bool_(True), "label": "b"})
    with CoSimulation([comp], [], step_size=1.0) as sim:
        res = sim.run(1)
    sets = [(w, d) for n, w, d in CALLS if w.startswith("set") and w != "setupExperiment"]
    assert sets == [("setReal", {"k": 0.5}), ("setInteger", {"count": 3}), ("setBoolean", {"flag": True}),
                    ("setString", {"label": "b"})]
    assert [type(next(iter(d.values()))) for _, d in sets] == [float, int, bool, str]
    np.testing.assert_array_equal(res["src.y"], [3.0, 3.5])


@pytest.mark.parametrize(("params", "match"), [
    ({"k": True}, r"^component src: k: expected a number, found bool True$"),
    ({"k": "1"}, r"^component src: k: expected a number, found str '1'$"),
    ({"k": float("nan")}, r"^component src: k: expected a finite number, found nan$"),
    ({"count": 2.5}, r"^component src: count: expected an integer, found float 2.5$"),
    ({"count": float("inf")}, r"^component src: count: expected an integer, found float inf$"),
    ({"count": 2**31}, r"^component src: count: 2147483648 is outside the range of an FMI Integer "
                       r"\[-2147483648, 2147483647\]$"),
    ({"count": -(2**31) - 1}, r"is outside the range of an FMI Integer"),
    ({"count": True}, r"^component src: count: expected an integer, found bool True$"),
    ({"count": "3"}, r"^component src: count: expected an integer, found str '3'$"),
    ({"k": "x" * 29}, r"^component src: k: expected a number, found str 'x{15}\.\.\.x{5}' \(29 characters\)$"),
    ({"flag": 1}, r"^component src: flag: expected true or false, found int 1$"),
    ({"label": 5}, r"^component src: label: expected a string, found int 5$"),
    ({"label": "a\x00b"}, r"^component src: label: a string may not hold a NUL character$"),
    ({"y": 1.0}, r"^component src: y is an output; it cannot be set$"),
    ({"nothere": 1.0}, r"^component src: no variable 'nothere' to set \(settable: count, flag, k, label\)$"),
    ({"kk": 1.0}, r"^component src: no variable 'kk' to set; did you mean 'k'\?$"),
    # any key, its field path quoted too:
    ({"\r": 1.0}, r"^component src: no variable '\\r' to set \(settable: count, flag, k, label\)$"),
    ({"k": [1.0, 2.0]}, r"^component src: k has 1 element\(s\); 2 value\(s\) given$"),
])
def test_a_bad_start_value_is_refused_at_set_up_naming_its_field(fmus, params, match):
    with pytest.raises(CoSimulationError, match=match) as info:
        CoSimulation.check([Component("src", fmus["src"], params)], [], step_size=1.0)
    key = next(iter(params))
    assert info.value.where == f"components.src.parameters.{key if key.isidentifier() else repr(key)}"
    assert CALLS == []  # nothing instantiated


def test_the_integer_range_bounds_are_accepted(fmus):
    for value in (2**31 - 1, -(2**31)):
        CoSimulation.check([Component("src", fmus["src"], {"count": value})], [], step_size=1.0)


def test_reset_reruns_the_same_instances_with_parameters_that_do_not_accumulate(fmus):
    with chain(fmus) as sim:
        first = sim.run(3)
        sim.reset({"src": {"k": 5.0}})
        changed = sim.run(3)
        sim.reset({"gain": {"k": -1.0}})
        again = sim.run(3)
        with pytest.raises(CoSimulationError, match=r"^reset: no component 'other' \(components: src, gain, "
                                                    r"delay\)$") as info:
            sim.reset({"other": {"k": 1.0}})
        assert info.value.where == "components"
        with pytest.raises(CoSimulationError, match="expected a number"):
            sim.reset({"src": {"k": "x"}})
        with pytest.raises(CoSimulationError, match="has run"):
            sim.run(1)  # a refused reset changes nothing
    np.testing.assert_array_equal(changed["src.y"], 5.0 * first["time"])
    np.testing.assert_array_equal(again["src.y"], first["src.y"])  # src's own k = 3 again
    np.testing.assert_array_equal(again["gain.y"], -first["src.y"])
    assert sum(1 for _, w, _ in CALLS if w == "reset") == 6 and sum(1 for _, w, _ in CALLS if w == "instantiate") == 3


def test_close_terminates_and_frees_every_instance_once(fmus):
    sim = chain(fmus)
    tmp = sim._tmp
    assert tmp.is_dir()
    sim.close()
    sim.close()
    assert [(n, w) for n, w, _ in CALLS if w in ("terminate", "freeInstance")] == [
        ("src", "terminate"), ("src", "freeInstance"), ("gain", "terminate"), ("gain", "freeInstance"),
        ("delay", "terminate"), ("delay", "freeInstance")]
    assert not tmp.exists()


_ALIVE_AT_EXIT = """
import pathlib, sys
import fmpy.fmi2
from tests.fake_fmu import FakeSlave, write_fmu
from tests.test_cosim_master import Src
fmpy.fmi2.FMU2Slave = FakeSlave
FakeSlave.MODELS = {"Src": Src}
from lpvest.cosim import Component, CoSimulation
import threading
sim = CoSimulation([Component("src", write_fmu(pathlib.Path(sys.argv[1]), "Src", Src.variables))], step_size=0.1)
print(sim._tmp, flush=True)
# held to the end by a daemon thread's frame, which the interpreter never releases: the
# simulation is never collected and __del__ never runs; only an exit hook removes its folder
threading.Thread(target=lambda kept=sim: threading.Event().wait(3600), daemon=True).start()
del sim
"""


def test_a_simulation_never_closed_removes_its_unpacked_fmus_when_collected_and_at_exit(fmus, tmp_path):
    """The unpacked FMUs go with the simulation even without close(): when it is collected,
    and at the interpreter's exit for one still alive then (a sweep worker's cached one), even
    one that is never collected (held by a daemon thread: __del__ alone left its folder)."""
    sim = chain(fmus)
    tmp = sim._tmp
    del sim
    gc.collect()
    assert not tmp.exists()
    assert sum(1 for _, w, _ in CALLS if w == "freeInstance") == 3
    proc = subprocess.run([sys.executable, "-c", _ALIVE_AT_EXIT, str(tmp_path)], capture_output=True, text=True,
                          timeout=120, check=False, cwd=Path(__file__).parents[1])
    assert proc.returncode == 0, proc.stderr[-3000:]
    kept = Path(proc.stdout.strip())
    assert kept.name.startswith("lpvest-cosim-") and not kept.exists()


def test_the_fmus_are_unpacked_in_the_folder_given_and_removed_with_the_simulation(fmus, tmp_path):
    folder = tmp_path / "unpack"
    folder.mkdir()
    sim = chain(fmus, unpack_in=folder)
    made = sim._tmp
    assert made.parent == folder and made.name.startswith("lpvest-cosim-") and any(made.iterdir())
    sim.close()
    assert not made.exists() and not any(folder.iterdir())
    for bad in (tmp_path / "missing", str(tmp_path / "missing"), 3):
        with pytest.raises(CoSimulationError, match=r"^unpack_in must be an existing folder; found ") as info:
            chain(fmus, unpack_in=bad)
        assert info.value.where == "unpack_in"
    assert not (tmp_path / "missing").exists()


def test_a_failure_while_instantiating_frees_what_was_made(fmus):
    FakeSlave.FAIL[("gain", "instantiate")] = 3
    with pytest.raises(CoSimulationError, match=r"^component gain: instantiate failed: ") as info:
        chain(fmus)
    assert info.value.where == "components.gain"
    assert [(n, w) for n, w, _ in CALLS if w in ("terminate", "freeInstance")] == [
        ("src", "terminate"), ("src", "freeInstance")]


def test_the_hint_names_a_matrix_by_its_base_name_as_a_vector():
    """The hint of a name not found reads elements as the master reads them (_expand):
    ``P[1,2]`` is an element of ``P`` as ``xhat[1]`` is one of ``xhat``."""
    from lpvest.cosim._master import _Var, _variable_hint

    names = ["xhat[1]", "xhat[2]", "P[1,1]", "P[1,2]", "P[2,1]", "P[2,2]", "loglik"]
    outputs = {n: _Var(0, n, vr, "Real", "output") for vr, n in enumerate(names)}
    assert _variable_hint("qqqqq", outputs, "connection source") == " (outputs: P, loglik, xhat)"
    assert _variable_hint("PP", outputs, "connection source") == "; did you mean 'P'?"
    assert _variable_hint("xhatt", outputs, "connection source") == "; did you mean 'xhat'?"


def test_set_up_errors_name_the_connection_or_component(fmus, tmp_path):
    comps = [Component("src", fmus["src"]), Component("gain", fmus["gain"])]
    cases = [
        (["src.y"], r"^connection 'src.y': expected 'comp.output -> comp.input'$", "connections[1]"),
        (["src.y -> gain.nope"], r"^connection target 'gain.nope': gain has no variable 'nope' \(inputs: i, u\)$",
         "connections[1]"),
        (["src.yy -> gain.u"], r"^connection source 'src.yy': src has no variable 'yy'; did you mean 'y'\?$",
         "connections[1]"),
        (["src.y -> other.u"], r"^connection target 'other.u': no component 'other' \(components: src, gain, vec\)$",
         "connections[1]"),
        (["gain.y -> gain.u", "src.y -> gain.u"], r"^gain.u is driven twice \(by gain.y and src.y\)$",
         "connections[2]"),
        (["src.k -> gain.u"], r"^connection source src.k is not an output \(parameter\)$", "connections[1]"),
        (["src.y -> gain.y"], r"^connection target gain.y is not an input \(output\)$", "connections[1]"),
        (["src.n -> gain.u"], r"^connection src.n -> gain.u: types Integer and Real$", "connections[1]"),
        (["srcy -> gain.u"], r"^connection source 'srcy': expected 'component.variable'$", "connections[1]"),
        (["vec.s -> gain.u"], r"^connection vec.s -> gain.u: a String variable cannot be connected \(the master "
                              r"exchanges Real, Integer, Boolean and Enumeration values\)$", "connections[1]"),
    ]
    comps = [*comps, Component("vec", fmus["vec"])]
    for conns, match, where in cases:
        with pytest.raises(CoSimulationError, match=match) as info:
            CoSimulation.check(comps, conns, step_size=1.0)
        assert info.value.where == where
    with pytest.raises(CoSimulationError, match=r"^recorded variable 'srcy': expected 'component.variable'$") as info:
        CoSimulation.check(comps, [], step_size=1.0, record=["src.y", "srcy"])
    assert info.value.where == "record[2]"
    many = [Component(f"component_number_{i:02d}", fmus["src"]) for i in range(12)]
    known = ", ".join(c.name for c in many)
    with pytest.raises(CoSimulationError, match=r"^connection target 'other.u': no component 'other' \(components: "
                       + re.escape(shorten(known, 60)) + r"\)$"):  # the list cut to about 60 characters
        CoSimulation.check(many, ["component_number_00.y -> other.u"], step_size=1.0)
    assert Component("none", fmus["src"], None).parameters == {}
    with pytest.raises(CoSimulationError, match=r"^component names are not unique: \['src'\]$"):
        CoSimulation.check([comps[0], comps[0]], [], step_size=1.0)
    with pytest.raises(CoSimulationError, match=r"^component name '1x' is not an identifier$") as info:
        CoSimulation.check([Component("1x", fmus["src"])], [], step_size=1.0)
    assert info.value.where == "components.'1x'"
    with pytest.raises(CoSimulationError, match=r"^component m: .*missing.fmu does not exist$") as info:
        CoSimulation.check([Component("m", tmp_path / "missing.fmu")], [], step_size=1.0)
    assert info.value.where == "components.m.fmu"
    (tmp_path / "bad.fmu").write_bytes(b"not a zip")
    with pytest.raises(CoSimulationError, match=r"^component b: .*bad.fmu is not a valid FMU: File is not a zip "
                                                r"file$") as info:
        CoSimulation.check([Component("b", tmp_path / "bad.fmu")], [], step_size=1.0)
    assert info.value.where == "components.b.fmu"


def test_the_log_names_the_last_problem_and_is_cut(fmus):
    from lpvest.cosim._master import _log_text

    unit = fake_fmu.Model()
    unit.log = ["[OK] fine", "[WARNING] first", "[OK] later"]
    assert _log_text(unit) == "[WARNING] first"
    unit.log = ["[OK] only  ok\n text"]
    assert _log_text(unit) == "[OK] only ok text"
    unit.log = []
    assert _log_text(unit) == "no log message"
    unit.log = ["[ERROR] " + "x" * 300]
    assert _log_text(unit) == ("[ERROR] " + "x" * 300)[:197] + "..."
    for n in (200, 201):  # at most 200 characters: a message of 200 is whole, one of 201 is cut
        unit.log = ["[ERROR] " + "x" * (n - 8)]
        assert _log_text(unit) == (unit.log[0] if n == 200 else unit.log[0][:197] + "...")


def test_simulate_is_construct_run_close_with_every_option(fmus, capsys):
    comps = [Component("src", fmus["src"], {"k": 2.0}), Component("gain", fmus["gain"])]
    res = simulate(comps, ["src.y -> gain.u"], step_size=0.5, stop_time=3.0, start_time=1.0, record=["gain.y"],
                   progress=True)
    assert res.dtype.names == ("time", "gain.y")
    np.testing.assert_array_equal(res["time"], [1.0, 1.5, 2.0, 2.5, 3.0])
    np.testing.assert_array_equal(res["gain.y"], 2.0 * 2.0 * res["time"])
    assert "co-simulation: 100%" in capsys.readouterr().err and CALLS[-1][1] == "freeInstance"
    res = simulate(comps, [], step_size=1.0, n_steps=2)
    assert res["time"].tolist() == [0.0, 1.0, 2.0] and "gain.y" in res.dtype.names
    assert capsys.readouterr().err == ""  # a short run shows no bar


def test_warnings_from_sets_gets_and_steps_are_logged_not_failures(fmus):
    FakeSlave.FAIL.update({("gain", "set"): 1, ("gain", "get"): 1, ("delay", "doStep"): 1})
    with chain(fmus) as sim:
        res = sim.run(2)
        log = sim._units[1].log
    assert len(res) == 3
    assert "[WARNING] set failed in gain 100%" in log and "[WARNING] get failed in gain 100%" in log


def test_an_fmu_that_cannot_be_loaded_or_initialised_is_named_with_the_reason(fmus, monkeypatch):
    monkeypatch.setattr(FakeSlave, "MODELS", {"Src": Src})  # no binary for Gain
    with pytest.raises(CoSimulationError, match=r"^component gain: .*Gain.fmu cannot be loaded: 'Gain'$") as info:
        CoSimulation([Component("src", fmus["src"]), Component("gain", fmus["gain"])], [], step_size=1.0)
    assert info.value.where == "components.gain.fmu"
    FakeSlave.FAIL[("src", "exitInitializationMode")] = RuntimeError("lost   the\n licence")
    with CoSimulation([Component("src", fmus["src"])], [], step_size=1.0) as sim:
        with pytest.raises(CoSimulationError, match=r"^component src: exitInitializationMode failed at t = 0: "
                                                    r"lost the licence \(no log message\)$"):
            sim.run(1)
    with pytest.raises(CoSimulationError, match=r"^step_size must be positive; found -1$") as info:
        CoSimulation([Component("src", fmus["src"])], [], step_size=-1)
    assert info.value.where == "step_size"


def test_a_ratio_near_one_step_is_whole_only_within_1e_9():
    assert step_count(0.0, 1.0 + 0.5e-9, 1.0)[0] == 1
    assert step_count(0.0, 1.0 + 1.5e-9, 1.0)[0] is None  # relative to max(1, ratio) = 1
    assert step_count(0.0, 100.0 + 50e-9, 1.0)[0] == 100 and step_count(0.0, 100.0 + 150e-9, 1.0)[0] is None


def test_an_input_can_be_given_a_start_value(fmus):
    with CoSimulation([Component("gain", fmus["gain"], {"u": 4.0, "k": 0.5})], [], step_size=1.0) as sim:
        res = sim.run(1)
    assert res["gain.y"].tolist() == [2.0, 2.0]


class Stopper(Model):
    """Discards the step from t = 0.3 (fmi2Discard), saying it asks to end the simulation."""

    variables = [("u", "input", "Real", 0.0, None), ("x", "output", "Real", 0.0, "")]
    terminated = True
    last_successful_time = 0.35

    def step(self, t, h):
        if t >= 0.3 - 1e-12:
            return 2  # fmi2Discard
        self["x"] = self["u"]
        return 0


class Mute(Stopper):
    """Discards as Stopper does, and answers no status query (fmi2Discard: not available)."""

    terminated = None
    last_successful_time = None


@pytest.fixture
def stoppers(fmus, tmp_path, monkeypatch):
    monkeypatch.setitem(FakeSlave.MODELS, "Stopper", Stopper)
    monkeypatch.setitem(FakeSlave.MODELS, "Mute", Mute)
    return {"stopper": write_fmu(tmp_path, "Stopper", Stopper.variables),
            "mute": write_fmu(tmp_path, "Mute", Mute.variables)}


def test_a_discarded_step_stops_the_run_at_its_point_and_says_what_the_component_reported(fmus, stoppers):
    comps = [Component("src", fmus["src"], {"k": 3.0}), Component("stop", stoppers["stopper"])]
    with CoSimulation(comps, ["src.y -> stop.u"], step_size=0.1) as sim:
        with pytest.warns(DiscardedStepWarning) as caught:
            res = sim.run(10)
        message = ("component stop: doStep at t = 0.3 returned discard: it asks to end the simulation (last "
                   "successful time 0.35); the run stops at t = 0.3 after 3 of 10 steps (no log message)")
        assert [str(w.message) for w in caught] == [message]
        assert sim.discarded == DiscardedStep("stop", 3 * 0.1, 3, 0.35, True, message)  # t_3 = t_0 + 3 h
    # the rows up to the discarded step's point, each as a run of 3 steps gives them
    t = 0.0 + np.arange(4) * 0.1  # t_k = t_0 + k h, as the master computes them
    np.testing.assert_array_equal(res["time"], t)
    np.testing.assert_array_equal(res["stop.x"], [0.0, *(3.0 * t[:3])])  # x_{k+1} = u_k = y_k = 3 t_k
    assert res.dtype.names == ("time", "src.y", "src.n", "src.on", "stop.x")


def test_a_discard_from_a_component_that_does_not_say_why_and_on_discard_error(fmus, stoppers):
    comps = [Component("src", fmus["src"]), Component("mute", stoppers["mute"])]
    with pytest.warns(DiscardedStepWarning, match=r"^component mute: doStep at t = 0.3 returned discard: it does "
                      r"not say whether it asks to end the simulation; the run stops at t = 0.3 after 3 of 5 steps"):
        res = simulate(comps, ["src.y -> mute.u"], step_size=0.1, n_steps=5)
    assert len(res) == 4
    with pytest.raises(CoSimulationError, match=r"^component mute: doStep at t = 0.3 returned discard \("):
        simulate(comps, ["src.y -> mute.u"], step_size=0.1, n_steps=5, on_discard="error")


def test_a_long_run_on_a_terminal_of_40_columns_shows_a_bar_that_keeps_its_count(fmus, monkeypatch):
    """More than 20,000 steps and stderr a terminal: the master's bar, by
    default; 40 columns wide, each frame keeps n/20001 (tests/test_progress.py)."""
    from tests.test_progress import _read_all, _terminal, assert_bars_keep_their_count

    controller, terminal = _terminal(40)
    with open(terminal, "w", encoding="utf-8") as stream:
        monkeypatch.setattr(sys, "stderr", stream)
        res = simulate([Component("src", fmus["src"], {"k": 2.0})], [], step_size=1.0, n_steps=20_001)
        monkeypatch.setattr(sys, "stderr", sys.__stderr__)
    bars = assert_bars_keep_their_count(_read_all(controller), ("co-simulation",), 40)
    assert re.search(r"\b0/20001\b", bars[0]) and re.search(r"\b20001/20001\b", bars[-1]), bars
    assert len(res) == 20_002


# -- Enumeration variables, recorded parameters and inputs, long names, foreign log text ------------

MODE = [("off", 1), ("on", 2), ("auto", 5)]
LEVEL = [("low", 1), ("high", 2)]


class Switch(Model):
    """Its state is off until t = 0.5, then the mode it was given."""

    variables = [("mode", "parameter", "Enumeration:Mode", 1, None), ("state", "output", "Enumeration:Mode", 1, ""),
                 ("level", "output", "Enumeration:Level", 2, "")]

    def outputs(self):
        self["state"] = self["mode"] if self.time >= 0.5 else 1


class Relay(Model):
    variables = [("cmd", "input", "Enumeration:Mode", 1, None), ("echo", "output", "Enumeration:Mode", 1, ["cmd"])]

    def outputs(self):
        self["echo"] = self["cmd"]


@pytest.fixture
def enums(fmus, tmp_path, monkeypatch):
    monkeypatch.setitem(FakeSlave.MODELS, "Switch", Switch)
    monkeypatch.setitem(FakeSlave.MODELS, "Relay", Relay)
    return {"switch": write_fmu(tmp_path, "Switch", Switch.variables, {"Mode": MODE, "Level": LEVEL}),
            "relay": write_fmu(tmp_path, "Relay", Relay.variables, {"Mode": MODE})}


@pytest.mark.parametrize("given", ["auto", 5, np.int64(5)])
def test_an_enumeration_is_set_by_item_name_or_value_exchanged_and_recorded_exactly(enums, given):
    comps = [Component("sw", enums["switch"], {"mode": given}), Component("relay", enums["relay"])]
    with CoSimulation(comps, ["sw.state -> relay.cmd"], step_size=0.25) as sim:
        assert sim.recorded == ["sw.state", "sw.level", "relay.echo"]  # Enumeration outputs are recorded
        res = sim.run(4)
    sets = [d for n, w, d in CALLS if n == "sw" and w == "setInteger"]
    assert sets == [{"mode": 5}] and type(sets[0]["mode"]) is int  # an fmi2Integer, the item's value
    np.testing.assert_array_equal(res["sw.state"], [1, 1, 5, 5, 5])
    np.testing.assert_array_equal(res["relay.echo"], res["sw.state"])  # connected in the same step
    np.testing.assert_array_equal(res["sw.level"], [2] * 5)


@pytest.mark.parametrize(("given", "match"), [
    ("dim", r"^component sw: mode: expected one of off = 1, on = 2, auto = 5 \(a name or its value\), found str "
            r"'dim'$"),
    (3, r"^component sw: mode: expected one of off = 1, on = 2, auto = 5 \(a name or its value\), found int 3$"),
    (True, r"^component sw: mode: expected an integer, found bool True$"),
    (2.5, r"^component sw: mode: expected an integer, found float 2.5$"),
])
def test_an_enumeration_value_that_is_not_one_of_its_items_is_refused_listing_them(enums, given, match):
    with pytest.raises(CoSimulationError, match=match) as info:
        CoSimulation.check([Component("sw", enums["switch"], {"mode": given})], [], step_size=1.0)
    assert info.value.where == "components.sw.parameters.mode"


def test_enumerations_of_different_types_are_not_connected(enums):
    comps = [Component("sw", enums["switch"]), Component("relay", enums["relay"])]
    with pytest.raises(CoSimulationError, match=r"^connection sw.level -> relay.cmd: Enumeration types 'Level' and "
                                                r"'Mode'$") as info:
        CoSimulation.check(comps, ["sw.state -> relay.cmd", "sw.level -> relay.cmd"], step_size=1.0)
    assert info.value.where == "connections[2]"


def test_a_vector_start_value_is_checked_element_by_element_as_given(fmus):
    with pytest.raises(CoSimulationError, match=r"^component vec: v\[2\]: expected a number, found bool True$") as info:
        CoSimulation.check([Component("vec", fmus["vec"], {"v": [0.5, True]})], [], step_size=1.0)
    assert info.value.where == "components.vec.parameters.v"
    with CoSimulation([Component("vec", fmus["vec"], {"v": np.array([0.5, 2])})], [], step_size=1.0) as sim:
        res = sim.run(1)
    np.testing.assert_array_equal(res["vec.w[1]"], [5.0, 5.0])
    np.testing.assert_array_equal(res["vec.w[2]"], [200.0, 200.0])


def test_a_recorded_input_or_parameter_is_read_after_the_sets_of_each_step(fmus):
    comps = [Component("src", fmus["src"], {"k": 3.0, "count": 2}), Component("gain", fmus["gain"], {"k": 0.5})]
    with CoSimulation(comps, ["src.y -> gain.u"], step_size=0.5,
                      record=["gain.u", "gain.y", "gain.k", "src.count", "src.flag"]) as sim:
        res = sim.run(3)
    t = np.arange(4) * 0.5
    np.testing.assert_array_equal(res["gain.u"], 3.0 * t + 2)  # the input as set at t_k, not one step late
    np.testing.assert_array_equal(res["gain.y"], 0.5 * res["gain.u"])
    np.testing.assert_array_equal(res["gain.k"], [0.5] * 4)
    np.testing.assert_array_equal(res["src.count"], [2] * 4)
    np.testing.assert_array_equal(res["src.flag"], [0.0] * 4)
    with pytest.raises(CoSimulationError, match=r"^recorded variable 'src.label' is a String; only Real, Integer, "
                                                r"Boolean and Enumeration variables can be recorded$") as info:
        CoSimulation.check(comps, [], step_size=1.0, record=["gain.y", "src.label"])
    assert info.value.where == "record[2]"


def test_a_long_component_name_is_cut_in_the_field_an_error_names(fmus):
    bad = "9" + "x" * 39  # not an identifier; 40 characters
    cut = "'9xxxxxxxxxxxxxx...xxxxx' (40 characters)"  # about 30 characters
    with pytest.raises(CoSimulationError, match=rf"^component name {re.escape(cut)} is not an identifier$") as info:
        CoSimulation.check([Component(bad, fmus["src"])], [], step_size=1.0)
    assert info.value.where == f"components.{cut}"
    name = "component_" + "x" * 30
    cut = "'component_xxxxx...xxxxx' (40 characters)"
    with pytest.raises(CoSimulationError, match=rf"^component {re.escape(cut)}: parameters: expected a mapping of "
                                                r"variable names to start values, found list$") as info:
        Component(name, fmus["src"], [("k", 1.0)])  # type: ignore[arg-type]
    assert info.value.where == f"components.{cut}"


def test_a_log_message_that_is_not_utf_8_reaches_the_error_with_its_bad_bytes_replaced(fmus):
    FakeSlave.FAIL[("gain", "doStep")] = 3
    FakeSlave.MESSAGES[("gain", "doStep")] = b"temp\xe9rature 100%% out of range"  # Latin-1, not UTF-8
    with chain(fmus) as sim:
        with pytest.raises(CoSimulationError, match=r"^component gain: doStep at t = 0 returned error \(\[ERROR\] "
                                                    "temp\ufffdrature 100% out of range\\)$"):
            sim.run(2)
