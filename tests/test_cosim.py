"""The co-simulation master, on small test FMUs built with pythonfmu."""

import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

from lpvest.cosim import (
    AlgebraicLoopError,
    Component,
    CoSimulation,
    CoSimulationError,
    DiscardedStepWarning,
    simulate,
)
from lpvest.fmi._build import GUID_FILE, _inner_library, bridge_note, status_bridge
from tests.tolerances import roundoff

SCRIPTS = Path(__file__).parent / "fmu_scripts"


def _behind_the_status_bridge(fmu: Path) -> None:
    """Put lpvest's status bridge in front of pythonfmu's library in ``fmu``, as every lpvest
    FMU has it. pythonfmu 0.7's library, when still loaded at exit, reads its interpreter
    state after the C++ exit handlers freed it (``finalizePythonInterpreter`` from its
    ``__attribute__((destructor))``): heap corruption, and now and then an abort of the
    whole pytest process after every test passed. Whether the library is still loaded at
    exit depends on its interpreter thread's timing; the bridge keeps it loaded and
    finalizes it first (``atexit``), so the exit is the same every time."""
    bridge = status_bridge("linux64")
    if bridge is None:
        pytest.skip("no C compiler (cc or zig) for lpvest's status bridge: " + str(bridge_note("linux64")))
    with zipfile.ZipFile(fmu) as z:
        entries = [(info, z.read(info)) for info in z.infolist()]
        guid = ElementTree.fromstring(z.read("modelDescription.xml")).get("guid")
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in entries:
            if info.filename.startswith("binaries/linux64/") and info.filename.endswith(".so"):
                z.writestr(f"binaries/linux64/{_inner_library('linux64')}", data)
                data = bridge.read_bytes()
            z.writestr(info, data)
        z.writestr(f"resources/{GUID_FILE}", guid + "\n")  # what the bridge checks the host's GUID against


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    from pythonfmu import FmuBuilder

    out = tmp_path_factory.mktemp("cosim_fmus")
    built = {}
    for name in ("ramp", "gain", "accumulator", "failing"):
        path = Path(FmuBuilder.build_FMU(SCRIPTS / f"{name}.py", dest=out))
        _behind_the_status_bridge(path)
        built[name] = path
    return built


def test_chain_has_no_one_step_delay(fmus):
    comps = [Component("g", fmus["gain"], {"k": 3.0}), Component("r", fmus["ramp"], {"slope": 0.5})]
    res = simulate(comps, ["r.y -> g.u[1]", "r.y -> g.u[2]"], step_size=0.1, n_steps=10)
    t = np.arange(11) * 0.1
    # t_k = k h, rounded once here and once or twice by the master and the
    # FMUs, then one product: a few eps of max |t| times the gain
    tol = roundoff(1.5 * t[-1], 2)
    np.testing.assert_allclose(res["time"], t, rtol=0, atol=tol)
    np.testing.assert_allclose(res["r.y"], 0.5 * t, rtol=0, atol=tol)
    # the gain sees r.y at the same t_k (component order in the list does not matter)
    np.testing.assert_allclose(res["g.y[1]"], 1.5 * t, rtol=0, atol=tol)
    np.testing.assert_allclose(res["g.y[2]"], 1.5 * t, rtol=0, atol=tol)


def test_vector_connection_and_execution_order(fmus):
    comps = [Component("a", fmus["gain"], {"k": 2.0}), Component("b", fmus["gain"], {"k": 10.0}),
             Component("r", fmus["ramp"])]
    with CoSimulation(comps, ["r.y -> a.u[1]", "r.y -> a.u[2]", "a.y -> b.u"], step_size=1.0) as sim:
        order = sim.execution_order
        res = sim.run(4)
    assert order.index("get r: y") < order.index("set a: u[1], u[2]") < order.index("get a: y[1], y[2]")
    assert order.index("get a: y[1], y[2]") < order.index("set b: u[1], u[2]")
    np.testing.assert_allclose(res["b.y[2]"], 20.0 * np.arange(5), rtol=0, atol=roundoff(80.0, 3))  # 3 products


def test_algebraic_loop_is_reported(fmus):
    comps = [Component("acc", fmus["accumulator"]), Component("g", fmus["gain"], {"k": 0.5})]
    conns = ["acc.y -> g.u[1]", "g.y[1] -> acc.u"]
    with pytest.raises(AlgebraicLoopError, match="algebraic loop: .*acc.u.*g.u\\[1\\]"):
        CoSimulation(comps, conns, step_size=1.0)


def test_loop_through_a_state_runs_when_feedthrough_is_declared(fmus):
    comps = [Component("acc", fmus["accumulator"], {"x0": 1.0}, feedthrough=False),
             Component("g", fmus["gain"], {"k": 0.5})]
    res = simulate(comps, ["acc.y -> g.u[1]", "g.y[1] -> acc.u"], step_size=1.0, n_steps=6)
    # 6 steps of x + 0.5 x (two roundings each): relative 2 eps per step
    np.testing.assert_allclose(res["acc.y"], 1.5 ** np.arange(7), rtol=roundoff(1.0, 6), atol=0)
    np.testing.assert_allclose(res["g.y[1]"], 0.5 * 1.5 ** np.arange(7), rtol=roundoff(1.0, 7), atol=0)


def test_stop_time_and_integer_step_counter(fmus):
    res = simulate([Component("r", fmus["ramp"])], [], step_size=0.1, stop_time=1000.0)
    assert res.shape == (10001,)
    assert res["time"][-1] == 1000.0  # k * h, not a sum of 10,000 steps
    assert res["time"][3] == 3 * 0.1
    # a stop time between communication points is refused, as in a co-simulation file
    # (it was rounded to the nearest step without a word)
    with pytest.raises(CoSimulationError, match=r"stop_time = 1000.05: expected start_time \(0\) \+ a whole "
                                                r"number of steps of 0.1; found 10000.5 steps"):
        simulate([Component("r", fmus["ramp"])], [], step_size=0.1, stop_time=1000.05)
    with pytest.raises(CoSimulationError, match="more steps than a float can count"):
        simulate([Component("r", fmus["ramp"])], [], step_size=0.1, stop_time=float("inf"))


@pytest.mark.parametrize(
    ("conn", "match"),
    [
        ("r.y -> q.u", "no component 'q'"),
        ("r.z -> g.u[1]", "r has no variable 'z'"),
        ("g.u[1] -> g.u[2]", "source g.u\\[1\\] is not an output"),
        ("r.y -> g.u", "1 source and 2 target elements"),
        ("r.y g.u", "expected 'comp.output -> comp.input'"),
    ],
)
def test_setup_errors(fmus, conn, match):
    comps = [Component("g", fmus["gain"]), Component("r", fmus["ramp"])]
    with pytest.raises(CoSimulationError, match=match):
        CoSimulation(comps, [conn], step_size=1.0)


def test_driven_twice_and_bad_parameter(fmus):
    comps = [Component("g", fmus["gain"]), Component("r", fmus["ramp"]), Component("s", fmus["ramp"])]
    with pytest.raises(CoSimulationError, match="g.u\\[1\\] is driven twice"):
        CoSimulation(comps, ["r.y -> g.u[1]", "s.y -> g.u[1]"], step_size=1.0)
    with pytest.raises(CoSimulationError, match="no variable 'gain' to set"):
        simulate([Component("g", fmus["gain"], {"gain": 1.0})], [], step_size=1.0, n_steps=1)


def test_component_failure_names_component_time_and_log(fmus):
    comps = [Component("f", fmus["failing"], {"fail_at": 3.0})]
    # do_step() returning False is fmi2Discard (the message logged is a warning): the run stops
    # there (the rows up to t = 3 kept), and the warning quotes the component's log
    with pytest.warns(DiscardedStepWarning, match=r"component f: doStep at t = 3 returned discard: .*; the run "
                                                  r"stops at t = 3 after 3 of 10 steps \(\[WARNING\] deliberate "
                                                  r"failure for the test\)"):
        res = simulate(comps, [], step_size=1.0, n_steps=10)
    np.testing.assert_array_equal(res["time"], [0.0, 1.0, 2.0, 3.0])
    # a caller that needs every step gets the error instead
    with pytest.raises(
        CoSimulationError,
        match=r"component f: doStep at t = 3 returned discard \(\[WARNING\] deliberate failure for the test\)",
    ):
        simulate(comps, [], step_size=1.0, n_steps=10, on_discard="error")


def test_each_instance_keeps_its_own_log(fmus):
    """A component's message reaches its own log even when other FMUs are
    instantiated after it (fmpy's logger proxy keeps one global callback)."""
    comps = [Component("f", fmus["failing"], {"fail_at": 2.0}), Component("r", fmus["ramp"]),
             Component("g", fmus["gain"])]
    with pytest.raises(CoSimulationError, match=r"component f: doStep at t = 2 returned discard "
                                                r"\(\[WARNING\] deliberate failure for the test\)"):
        simulate(comps, ["r.y -> g.u[1]"], step_size=1.0, n_steps=5, on_discard="error")


def test_only_connected_or_recorded_outputs_are_read(fmus):
    comps = [Component("g", fmus["gain"], {"k": 3.0}), Component("r", fmus["ramp"])]
    with CoSimulation(comps, ["r.y -> g.u[2]"], step_size=1.0, record=["g.y[2]", "g.u[2]"]) as sim:
        assert sim.execution_order == ["get r: y", "set g: u[2]", "get g: y[2]"]
        assert sim.recorded == ["g.y[2]", "g.u[2]"]
        res = sim.run(3)
    np.testing.assert_array_equal(res["g.y[2]"], 3.0 * res["g.u[2]"])
    np.testing.assert_array_equal(res["g.u[2]"], np.arange(4.0))


@pytest.mark.parametrize(
    ("params", "where", "match"),
    [
        ({"k": "fast"}, "components.g.parameters.k", "component g: k: expected a number, found str 'fast'"),
        ({"k": True}, "components.g.parameters.k", "component g: k: expected a number, found bool True"),
        ({"y": [1.0, 2.0]}, "components.g.parameters.y", r"component g: y\[1\] is an output; it cannot be set"),
        ({"u": [1.0]}, "components.g.parameters.u", r"component g: u has 2 element\(s\); 1 value\(s\) given"),
    ],
)
def test_start_values_are_checked_at_set_up_and_name_their_field(fmus, params, where, match):
    with pytest.raises(CoSimulationError, match=match) as info:
        CoSimulation([Component("g", fmus["gain"], params)], [], step_size=1.0)
    assert info.value.where == where


def test_setup_errors_name_the_connection(fmus):
    comps = [Component("g", fmus["gain"]), Component("r", fmus["ramp"])]
    with pytest.raises(CoSimulationError, match="r has no variable 'z'") as info:
        CoSimulation(comps, ["r.y -> g.u[1]", "r.z -> g.u[2]"], step_size=1.0)
    assert info.value.where == "connections[2]"
    with pytest.raises(CoSimulationError, match="no component 'q'") as info:
        CoSimulation(comps, [], step_size=1.0, record=["r.y", "q.y"])
    assert info.value.where == "record[2]"
