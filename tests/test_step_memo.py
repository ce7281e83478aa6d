"""Computing a sample once: ``outputs`` then ``step`` with the same inputs reuse
one evaluation (what the FMU adapter does at every communication point), and
the reuse never changes a number or lets a bad input through."""

from __future__ import annotations

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._errors import DimensionError, NonFiniteError, SchedulingRangeError
from lpvest.core._protocol import input_key
from lpvest.core._signals import SchedulerComponent, SignalSpec
from lpvest.estimators._hinf import HinfFilter
from lpvest.systems._streaming import DiscretePlant
from tests.fmu_driver import Driver


@pytest.fixture(scope="module")
def plant_model():
    return load_system("peixoto-ex1").model()


@pytest.fixture(scope="module")
def design(plant_model):
    from lpvest.design import design_hinf

    return design_hinf(plant_model, epsilon=150.0)


def _inputs(rng, T):
    return rng.uniform(-1, 1, (T, 1)), rng.normal(size=(T, 1))


def test_input_key_is_exact_and_names_shapes():
    assert input_key({"y": [1.0]}) == input_key({"y": np.array([1.0])})
    assert input_key({"y": [1.0]}) != input_key({"y": [[1.0]]})
    assert input_key({"y": [1.0]}) != input_key({"z": [1.0]})
    assert input_key({"y": [1.0]}) != input_key({"y": [np.nextafter(1.0, 2.0)]})
    assert input_key({"y": [0.0]}) != input_key({"y": [-0.0]})  # a miss, never a wrong hit
    assert input_key({"p": [1.0], "y": [2.0]}, ("p",)) == input_key({"p": [1.0]})
    assert input_key({"y": ["a"]}) is None
    assert input_key({"y": [1.0]}, ("p",)) is None


def test_plant_outputs_then_step_is_bit_for_bit_step_alone(plant_model, rng):
    p, w = _inputs(rng, 60)
    a, b = DiscretePlant(plant_model), DiscretePlant(plant_model)
    for k in range(60):
        inp = {"p": p[k], "w": w[k]}
        if k % 3 == 1:  # a read with other inputs first: the step must not use it
            a.outputs({"p": -p[k], "w": w[k] + 1.0})
        seen = a.outputs(inp)
        stepped = a.step(inp)
        ref = b.step(inp)
        for name in ("y", "z", "x"):
            assert np.array_equal(seen[name], ref[name])
            assert np.array_equal(stepped[name], ref[name])
    assert np.array_equal(a.get_state()["x"], b.get_state()["x"])


def test_plant_step_with_other_inputs_after_a_read_uses_them(plant_model):
    a, b = DiscretePlant(plant_model), DiscretePlant(plant_model)
    a.outputs({"p": [0.5], "w": [1.0]})
    out = a.step({"p": [0.5], "w": [-2.0]})
    ref = b.step({"p": [0.5], "w": [-2.0]})
    assert np.array_equal(out["y"], ref["y"]) and np.array_equal(a.get_state()["x"], b.get_state()["x"])


def test_mutating_what_outputs_returned_does_not_reach_the_step(plant_model, design):
    plant, ref = DiscretePlant(plant_model), DiscretePlant(plant_model)
    inp = {"p": [0.2], "w": [1.0]}
    plant.step(inp), ref.step(inp)
    out = plant.outputs(inp)
    out["y"][:] = 99.0
    out["x"][:] = 99.0
    assert np.array_equal(plant.step(inp)["y"], ref.step(inp)["y"])
    assert np.array_equal(plant.get_state()["x"], ref.get_state()["x"])
    f = HinfFilter(design, simplex_map=plant_model.simplex_map)
    g = HinfFilter(design, simplex_map=plant_model.simplex_map)
    fi = {"p": [0.2], "y": [1.0]}
    f.step(fi), g.step(fi)
    f.outputs(fi)["zhat"][:] = 99.0
    assert np.array_equal(f.step(fi)["zhat"], g.step(fi)["zhat"])


def test_hinf_outputs_then_step_is_bit_for_bit_step_alone(plant_model, design, rng):
    p, y = _inputs(rng, 60)
    a = HinfFilter(design, simplex_map=plant_model.simplex_map)
    b = HinfFilter(design, simplex_map=plant_model.simplex_map)
    for k in range(60):
        inp = {"p": p[k], "y": y[k]}
        if k % 4 == 2:
            a.outputs({"p": p[k], "y": y[k] + 0.5})
        seen = a.outputs(inp)
        stepped = a.step(inp)
        ref = b.step(inp)
        assert np.array_equal(seen["zhat"], ref["zhat"]) and np.array_equal(stepped["zhat"], ref["zhat"])
        assert np.array_equal(seen["xf"], ref["xf"])
    assert np.array_equal(a.get_state()["xf"], b.get_state()["xf"])


def test_a_read_never_lets_a_bad_input_through_and_state_changes_drop_the_memo(plant_model, design):
    f = HinfFilter(design, simplex_map=plant_model.simplex_map)
    f.outputs({"p": [0.3], "y": [1.0]})
    with pytest.raises(SchedulingRangeError, match="theta"):
        f.step({"p": [1.5], "y": [1.0]})
    with pytest.raises(NonFiniteError, match="y"):
        f.step({"p": [0.3], "y": [np.nan]})
    assert f.get_state()["k"] == 0  # nothing changed
    # the memo belongs to the state it was computed in
    before = f.get_state()
    z0 = f.outputs({"p": [0.3], "y": [1.0]})["zhat"]
    f.step({"p": [0.3], "y": [1.0]})
    z1 = f.outputs({"p": [0.3], "y": [1.0]})["zhat"]
    assert not np.array_equal(z0, z1)
    f.set_state(before)
    assert np.array_equal(f.outputs({"p": [0.3], "y": [1.0]})["zhat"], z0)
    plant = DiscretePlant(plant_model)
    plant.step({"p": [0.3], "w": [1.0]})
    y1 = plant.outputs({"p": [0.3], "w": [1.0]})["y"]
    plant.reset()
    assert not np.array_equal(plant.outputs({"p": [0.3], "w": [1.0]})["y"], y1)


def test_a_step_after_prepare_reads_its_own_inputs(plant_model, design):
    # prepare() keeps its evaluation under no key: step() with missing or
    # non-numeric inputs (whose key is None as well) must read them and refuse them
    f = HinfFilter(design, simplex_map=plant_model.simplex_map)
    f.prepare({"p": [0.3], "y": [1.0]})
    with pytest.raises(DimensionError, match="missing"):
        f.step({})
    with pytest.raises(DimensionError):
        f.step({"p": [0.3], "y": ["one"]})
    assert f.get_state()["k"] == 0
    out = f.step({"p": [0.3], "y": [1.0]})
    assert f.get_state()["k"] == 1 and out["zhat"].shape == (design.nz,)


def test_prepare_checked_skips_only_the_checks_made_at_the_boundary(plant_model, design, rng):
    # inputs checked as an FMU checks them (finite, in range): the same numbers, to the bit
    p, w = _inputs(rng, 20)
    pairs = [(DiscretePlant(plant_model), DiscretePlant(plant_model)),
             (HinfFilter(design, simplex_map=plant_model.simplex_map),
              HinfFilter(design, simplex_map=plant_model.simplex_map))]
    for k in range(20):
        for checked, plain in pairs:
            names = [q.name for q in plain.input_ports]
            sample = {n: np.array(p[k] if n == "p" else w[k]) for n in names}
            a = checked.prepare(dict(sample), checked=True)
            b = plain.prepare(dict(sample))
            assert all(np.array_equal(a[n], b[n]) for n in b)
            checked.advance()
            plain.advance()
    # what the boundary does not check is still checked: weights of an FMU input are
    # each in [0, 1], but their sum is the component's to check
    polytopic = plant_model.__class__(plant_model.vertex_stacks(), name="no-map")
    f = HinfFilter(design)
    for comp, inputs in ((DiscretePlant(polytopic), {"alpha": np.array([0.7, 0.7]), "w": np.zeros(1)}),
                         (f, {"alpha": np.array([0.7, 0.7]), "y": np.zeros(1)})):
        with pytest.raises(SchedulingRangeError, match="alpha"):
            comp.prepare(inputs, checked=True)


def test_scheduler_outputs_then_step_reports_the_same_values(plant_model):
    spec = SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=0.25)
    a = SchedulerComponent(spec, plant_model.space, plant_model.simplex_map)
    b = SchedulerComponent(spec, plant_model.space, plant_model.simplex_map)
    a.reset(0.0), b.reset(0.0)
    for k in range(20):
        seen = a.outputs({})
        seen["p"][:] = 5.0  # the caller's copy
        out, ref = a.step({}, dt=1.0, t_end=k + 1.0), b.step({}, dt=1.0, t_end=k + 1.0)
        assert np.array_equal(out["p"], ref["p"]) and np.array_equal(out["alpha"], ref["alpha"])
    state = a.get_state()
    before = a.outputs({})["p"]
    a.step({}, dt=1.0)
    a.set_state(state)
    assert np.array_equal(a.outputs({})["p"], before)


@pytest.mark.parametrize("name", ["PeixotoEx1Plant", "PeixotoEx1HinfPD"])
def test_fmu_steps_with_the_inputs_set_after_the_last_read(fmus, plant_model, name):
    """Set, read, set other inputs, fmi2DoStep without reading: the step uses the
    inputs set last (the evaluation kept for the read is not reused)."""
    import zipfile

    from lpvest.design import HinfDesign

    d = Driver(fmus[name])
    assert d.initialize() == 0
    if name == "PeixotoEx1Plant":
        ref = DiscretePlant(plant_model)
        port, state = "w", "x"
    else:
        with zipfile.ZipFile(fmus[name]) as z:
            ref = HinfFilter(HinfDesign.from_json(z.read("resources/design.json").decode()),
                             simplex_map=plant_model.simplex_map)
        port, state = "y", "xf"
    for k in range(5):
        d.set_vector("p", 0.3)
        d.set_vector(port, 1.0 + k)
        d.vector(state)
        d.vector("zhat" if name.endswith("HinfPD") else "y")  # computes the outputs for these inputs
        d.set_vector(port, -2.0 * k)
        assert d.step(float(k), 1.0) == 0
        ref.step({"p": [0.3], port: [-2.0 * k]})
        key = "xf" if name.endswith("HinfPD") else "x"
        assert np.array_equal(d.vector(state), ref.get_state()[key])
    d.free()
