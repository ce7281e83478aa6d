"""Streaming plants (lpvest.systems._streaming) against the batch simulations."""

from __future__ import annotations

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._errors import DimensionError, ExpressionError, NonFiniteError, SchedulingRangeError
from lpvest.core._protocol import run_streaming
from lpvest.systems._streaming import DiscretePlant, LTVPlant, plant_supports
from tests.conftest_fmu import AFFINE_TOML
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel


def test_polytopic_plant_is_bit_for_bit_simulate(rng):
    plant = load_system("peixoto-ex2", parameters={"rho": 7.0}).model()
    T = 80
    p = rng.uniform(-1, 1, (T, 1))
    w = rng.standard_normal((T, 1))
    got = run_streaming(DiscretePlant(plant), {"p": p, "w": w})
    ref = plant.simulate(plant.alpha_batch(p), w)
    assert np.array_equal(got["y"], ref.y) and np.array_equal(got["z"], ref.z) and np.array_equal(got["x"], ref.x)


def test_affine_plant_noise_is_the_simulate_stream(tmp_path):
    path = tmp_path / "a.toml"
    path.write_text(AFFINE_TOML)
    model = load_system(path).model()
    T = 60
    k = np.arange(T)
    p = np.c_[np.sin(k), 1 + np.cos(k)]
    u = np.sin(0.1 * k)[:, None]
    got = run_streaming(DiscretePlant(model, noise=True, seed=4),
                        {"p": p, "u": u, "w": np.zeros((T, 2)), "v": np.zeros((T, 1))})
    ref = model.simulate(p, u, rng=4)
    # row vs batch BLAS products: the same recursion, per step sums of <= 6
    # products (matrices from the basis, then A x + B u + G w, C x + D u + H v),
    # over T steps with no growth assumed
    np.testing.assert_allclose(got["y"], ref.y, rtol=0, atol=roundoff(np.max(np.abs(ref.y)), 2 * T, n=6))


def test_outputs_do_not_change_the_state_and_bad_input_raises_before_any_change():
    plant = DiscretePlant(load_system("peixoto-ex1").model())
    plant.step({"p": [0.2], "w": [1.0]})
    state = plant.get_state()
    a = plant.outputs({"p": [0.3], "w": [0.5]})
    b = plant.outputs({"p": [0.3], "w": [0.5]})
    assert all(np.array_equal(a[n], b[n]) for n in a)
    with pytest.raises(SchedulingRangeError, match=r"theta = 1.2 is outside its declared range \[-1, 1\]"):
        plant.step({"p": [1.2], "w": [0.0]})
    with pytest.raises(NonFiniteError, match="w holds a non-finite value"):
        plant.step({"p": [0.0], "w": [np.nan]})
    with pytest.raises(DimensionError, match=r"w has shape \(2,\); expected \(1,\)"):
        plant.step({"p": [0.0], "w": [0.0, 1.0]})
    assert np.array_equal(plant.get_state()["x"], state["x"]) and plant.get_state()["k"] == state["k"]


def test_which_models_stream():
    system = load_system("cox-toth-ex1")
    assert plant_supports(system.model("augmented")) is None
    assert "p_(t+1)" in plant_supports(system.model("minimal"))
    assert plant_supports(system.model("io")) is None  # its memory of past y, u, e is the state
    with pytest.raises(ExpressionError, match="p_\\(t\\+1\\)"):
        DiscretePlant(system.model("minimal"))


def test_input_output_plant_is_bit_for_bit_simulate(rng):
    """(21a) streamed: y_t and the drawn e_t are LPVInputOutput.simulate's, to
    the bit, with the noise drawn (the same stream) and with e given; the state
    is the memory [y_(t-1), u_(t-1), e_(t-1)]; a saved state goes back exactly."""
    model = load_system("cox-toth-ex1").model("io")
    T = 120
    k = np.arange(T)
    p = (0.5 + 0.4 * np.sin(0.3 * k))[:, None]
    u = rng.standard_normal((T, 1))
    ref = model.simulate(p, u, rng=7)
    plant = DiscretePlant(model, noise=True, seed=7)
    assert [q.name for q in plant.input_ports] == ["p", "u", "e"] and model.nx == 3
    got = run_streaming(plant, {"p": p, "u": u, "e": np.zeros((T, 1))})
    assert np.array_equal(got["y"], ref.y)
    assert np.array_equal(got["x"][1:], np.column_stack([ref.y[:-1, 0], u[:-1, 0], ref.e[:-1, 0]]))
    e = rng.standard_normal((T, 1))
    plant = DiscretePlant(model)
    assert np.array_equal(run_streaming(plant, {"p": p, "u": u, "e": e})["y"], model.simulate(p, u, e=e).y)
    plant.reset()
    for t in range(5):
        plant.step({"p": p[t], "u": u[t], "e": e[t]})
    state = plant.get_state()
    first = [plant.step({"p": p[t], "u": u[t], "e": e[t]})["y"] for t in range(5, 9)]
    plant.set_state(state)
    assert np.array_equal([plant.step({"p": p[t], "u": u[t], "e": e[t]})["y"] for t in range(5, 9)], first)


def test_input_output_plant_refuses_coefficients_that_are_not_finite():
    from lpvest import LPVInputOutput, SchedulingSpace

    model = LPVInputOutput(SchedulingSpace(["p"], [-1.0], [1.0]), ["1 / p"], [1.0])
    plant = DiscretePlant(model)
    with pytest.raises(ExpressionError, match=r"the coefficients are not finite at p = \[0.0\]"):
        plant.step({"p": [0.0], "u": [1.0], "e": [0.0]})


def test_ltv_plant_step_size_does_not_matter():
    model = load_system("sridhar-ltv").model()
    ys = {}
    for h in (0.05, 0.4):
        plant = LTVPlant(model)
        n = int(round(4.0 / h))
        for i in range(n):
            plant.step({"u": [0.0]}, dt=h, t_end=(i + 1) * h)
        ys[h] = plant.outputs({"u": [0.0]})["y"][0]
    ref = model.simulate(np.array([0.0, 4.0])).y[-1]
    # restarted vs one-run DOP853 at rtol 1e-12: agreement to 1e-9 of the scale
    assert ys[0.05] == pytest.approx(ref, abs=1e-9 * abs(ref))
    assert ys[0.4] == pytest.approx(ref, abs=1e-9 * abs(ref))


def test_library_simulation_and_streaming_plant_draw_the_same_realization():
    """With P0 != 0 and drawn noise, AffineLPV.simulate(rng=seed) and the
    streaming plant (what the Plant FMU runs, with x0 drawn) give the same
    trajectory: initial state first, then the noise sample by sample."""
    import numpy as np

    from lpvest import load_system
    from lpvest.systems._streaming import DiscretePlant

    model = load_system("cox-toth-truncation").model()
    assert np.any(model.P0)
    k = np.arange(50)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    ref = model.simulate(p, u, rng=11)
    plant = DiscretePlant(model, noise=True, seed=11)
    ys = [plant.step({"p": p[t], "u": u[t], "w": np.zeros(model.nw), "v": np.zeros(model.nv)})["y"]
          for t in range(50)]
    # the same recursion in two arrangements (as above), 50 steps
    np.testing.assert_allclose(np.array(ys), ref.y, rtol=0, atol=roundoff(np.max(np.abs(ref.y)), 2 * 50, n=6))


def test_run_streaming_names_what_is_wrong_with_its_sequences():
    from lpvest.core._signals import SignalSpec, SourceComponent

    plant = DiscretePlant(load_system("peixoto-ex1").model())
    with pytest.raises(DimensionError, match="different lengths"):
        run_streaming(plant, {"p": np.zeros((3, 1)), "w": np.zeros((4, 1))})
    with pytest.raises(DimensionError, match="give steps=T"):
        run_streaming(plant, {})
    with pytest.raises(DimensionError, match="steps = 5, but the input sequences have 3 samples"):
        run_streaming(plant, {"p": np.zeros((3, 1)), "w": np.zeros((3, 1))}, steps=5)
    with pytest.raises(DimensionError, match=r"found scalars for \['w'\]"):
        run_streaming(plant, {"p": np.zeros((3, 1)), "w": 0.0})
    with pytest.raises(TypeError, match="SourceComponent is timed"):
        run_streaming(SourceComponent({"w": SignalSpec.build("gaussian", 1, seed=2)}), {}, steps=3)
    out = run_streaming(plant, {"p": np.zeros((3, 1)), "w": np.ones((3, 1))}, steps=3)
    assert out["y"].shape == (3, plant.model.ny)
