"""The streaming H-infinity filter (2) and its step protocol."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._errors import DimensionError, NonFiniteError, SchedulingRangeError
from lpvest.core._protocol import Sampled as StreamingEstimator, run_streaming
from lpvest.design import KIND_PD, KIND_ROBUST, design_hinf
from lpvest.estimators._hinf import HinfFilter, hinf_filter_batch
from tests import hinf_oracle as oracle
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel

_DESIGNS = {}


def setup(kind):
    if kind not in _DESIGNS:
        plant = load_system("peixoto-ex1").model()
        _DESIGNS[kind] = (plant, design_hinf(plant, epsilon=150.0, kind=kind))
    return _DESIGNS[kind]


def scenario(plant, T=80, seed=None):
    k = np.arange(float(T))
    theta = np.sin(0.25 * k)
    alpha = plant.alpha_batch(theta[:, None])
    if seed is None:
        w = np.where(k >= 10, np.sin(0.5 * k) * np.exp(-0.1 * k), 0.0)[:, None]
    else:
        w = np.random.default_rng(seed).standard_normal((T, 1))
    traj = plant.simulate(alpha, w)
    return theta, alpha, w, traj


@pytest.mark.parametrize("kind", [KIND_PD, KIND_ROBUST])
def test_streaming_filter_matches_the_augmented_system(kind):
    """z - zhat from the streaming filter equals e_k of the augmented system (3)."""
    plant, d = setup(kind)
    theta, alpha, w, traj = scenario(plant, seed=3)
    f = HinfFilter(d)
    assert isinstance(f, StreamingEstimator)
    inputs = {"y": traj.y} if kind == KIND_ROBUST else {"alpha": alpha, "y": traj.y}
    out = run_streaming(f, inputs)
    e = traj.z - out["zhat"]
    # the augmented system (3) against plant simulation minus filter: the same
    # stable recursions in another arrangement, per step sums of <= 2 n_x + n_y
    # products of the size of the states, over T steps (no growth assumed)
    size = float(np.max(np.abs(traj.z)) + np.max(np.abs(out["zhat"])) + np.max(np.abs(out["xf"])))
    size += float(np.max(np.abs(traj.x)))
    T = len(w)
    np.testing.assert_allclose(e, oracle.simulate_error(plant, d, alpha, w), rtol=0, atol=roundoff(size, T, n=5))
    batch = hinf_filter_batch(d, traj.y, None if kind == KIND_ROBUST else alpha)
    np.testing.assert_array_equal(batch.zhat, out["zhat"])
    np.testing.assert_array_equal(batch.xf, out["xf"])


def test_physical_scheduling_port_gives_the_same_estimates():
    plant, d = setup(KIND_PD)
    theta, alpha, _, traj = scenario(plant)
    by_alpha = run_streaming(HinfFilter(d), {"alpha": alpha, "y": traj.y})
    by_p = run_streaming(HinfFilter(d, simplex_map=plant.simplex_map), {"p": theta[:, None], "y": traj.y})
    np.testing.assert_array_equal(by_alpha["zhat"], by_p["zhat"])


def test_ports():
    plant, pd = setup(KIND_PD)
    _, rob = setup(KIND_ROBUST)
    f = HinfFilter(pd)
    assert [(p.name, p.shape) for p in f.input_ports] == [("alpha", (2,)), ("y", (1,))]
    assert [(p.name, p.shape) for p in f.output_ports] == [("zhat", (2,)), ("xf", (2,))]
    # what an FMU's variables are described as
    assert [p.description for p in f.input_ports] == ["scheduling on the unit simplex", "measured output y_k"]
    assert [p.description for p in f.output_ports] == ["estimate z_f,k of z_k", "filter state x_f,k"]
    f = HinfFilter(pd, simplex_map=plant.simplex_map)
    assert [(p.name, p.shape) for p in f.input_ports] == [("p", (1,)), ("y", (1,))]
    f = HinfFilter(rob)
    assert [(p.name, p.shape) for p in f.input_ports] == [("y", (1,))]
    assert [(p.name, p.shape) for p in f.output_ports] == [("zhat", (2,)), ("xf", (2,))]


def test_outputs_do_not_change_state_and_feed_y_through():
    plant, d = setup(KIND_PD)
    _, alpha, _, traj = scenario(plant)
    f = HinfFilter(d)
    for k in range(5):
        f.step({"alpha": alpha[k], "y": traj.y[k]})
    before = f.get_state()
    inp = {"alpha": alpha[5], "y": traj.y[5]}
    o1 = f.outputs(inp)
    o2 = f.outputs(inp)
    np.testing.assert_array_equal(o1["zhat"], o2["zhat"])
    np.testing.assert_array_equal(f.get_state()["xf"], before["xf"])
    # direct feedthrough: zhat_k moves with y_k by D_f(alpha_k)
    o3 = f.outputs({"alpha": alpha[5], "y": traj.y[5] + 1.0})
    Df = np.tensordot(alpha[5], d.Df, axes=1)
    # a difference of two outputs of size |zhat| (+ |Df|): two roundings of each
    size = float(np.max(np.abs(o3["zhat"])) + np.max(np.abs(o1["zhat"])))
    np.testing.assert_allclose(o3["zhat"] - o1["zhat"], Df[:, 0], rtol=0, atol=roundoff(size, 2, n=4))
    s = f.step(inp)
    np.testing.assert_array_equal(s["zhat"], o1["zhat"])
    assert f.get_state()["k"] == 6


def test_state_round_trip_and_reset():
    plant, d = setup(KIND_PD)
    _, alpha, _, traj = scenario(plant)
    f = HinfFilter(d)
    for k in range(10):
        f.step({"alpha": alpha[k], "y": traj.y[k]})
    saved = f.get_state()
    first = [f.step({"alpha": alpha[k], "y": traj.y[k]})["zhat"] for k in range(10, 15)]
    f.set_state(saved)
    again = [f.step({"alpha": alpha[k], "y": traj.y[k]})["zhat"] for k in range(10, 15)]
    np.testing.assert_array_equal(first, again)
    f.reset()
    assert f.get_state()["k"] == 0 and not np.any(f.get_state()["xf"])
    fresh = f.get_state()
    f.step({"alpha": alpha[0], "y": traj.y[0]})
    f.set_state(fresh)  # the state of a filter that has not stepped yet (k = 0) is a state too
    assert f.get_state()["k"] == 0
    np.testing.assert_array_equal(f.step({"alpha": alpha[0], "y": traj.y[0]})["zhat"],
                                  HinfFilter(d).step({"alpha": alpha[0], "y": traj.y[0]})["zhat"])
    with pytest.raises(DimensionError, match="needs 'xf' and 'k'"):
        f.set_state({"xf": np.zeros(2)})
    with pytest.raises(DimensionError, match=r"xf has shape \(3,\); expected \(2,\)"):
        f.set_state({"xf": np.zeros(3), "k": 1})


def test_bad_input_raises_before_any_state_change():
    plant, d = setup(KIND_PD)
    f = HinfFilter(d)
    f.step({"alpha": np.array([0.3, 0.7]), "y": np.array([1.0])})
    state = f.get_state()
    bad = [
        ({"alpha": np.array([0.6, 0.6]), "y": np.array([1.0])}, SchedulingRangeError, "sum to 1.2"),
        ({"alpha": np.array([1.2, -0.2]), "y": np.array([1.0])}, SchedulingRangeError, r"alpha\[2\] = -0.2 < 0"),
        ({"alpha": np.array([0.5, 0.5]), "y": np.array([1.0, 2.0])}, DimensionError, r"y has shape \(2,\)"),
        ({"alpha": np.array([0.5, 0.5]), "y": np.array([np.nan])}, NonFiniteError, "y holds a non-finite"),
        ({"alpha": np.array([0.5, 0.5, 0.0]), "y": np.array([1.0])}, DimensionError, r"alpha has shape \(3,\)"),
        ({"y": np.array([1.0])}, DimensionError, r"missing \['alpha'\]"),
        ({"alpha": np.array([0.5, 0.5]), "y": np.array([1.0]), "u": np.array([0.0])}, DimensionError,
         r"unknown \['u'\]"),
    ]
    for inputs, exc, match in bad:
        for method in (f.outputs, f.step):
            with pytest.raises(exc, match=match):
                method(inputs)
        assert f.get_state()["k"] == state["k"]
        np.testing.assert_array_equal(f.get_state()["xf"], state["xf"])
    g = HinfFilter(d, simplex_map=plant.simplex_map)
    with pytest.raises(SchedulingRangeError, match=r"theta = 1.5 is outside its declared range \[-1, 1\]"):
        g.step({"p": np.array([1.5]), "y": np.array([1.0])})
    assert g.get_state()["k"] == 0


def test_bad_construction():
    plant, pd = setup(KIND_PD)
    _, rob = setup(KIND_ROBUST)
    with pytest.raises(TypeError, match="^a robust filter takes no scheduling input: do not pass simplex_map$"):
        HinfFilter(rob, simplex_map=plant.simplex_map)
    ex2 = load_system("peixoto-ex2").model()
    three = type(ex2.simplex_map)(ex2.simplex_map.space, ["(1 - theta)/4", "(1 + theta)/4", "1/2"])
    with pytest.raises(DimensionError, match="the simplex map gives 3 weights; the design has 2 vertices"):
        HinfFilter(pd, simplex_map=three)
    with pytest.raises(DimensionError, match=r"xf0 has shape \(3,\)"):
        HinfFilter(pd, xf0=np.zeros(3))
    with pytest.raises(TypeError, match="must be an HinfDesign"):
        HinfFilter(object())  # type: ignore[arg-type]
    with pytest.raises(DimensionError, match="needs alpha"):
        hinf_filter_batch(pd, np.zeros((4, 1)))
    with pytest.raises(SchedulingRangeError, match="alpha at k=1"):
        hinf_filter_batch(pd, np.zeros((2, 1)), np.array([[0.5, 0.5], [0.9, 0.9]]))
    with pytest.raises(DimensionError, match=r"^alpha has shape \(2, 3\); expected \(2, 2\)$"):
        hinf_filter_batch(pd, np.zeros((2, 1)), np.full((2, 3), 1.0 / 3.0))  # weights of 3 vertices, on a simplex


def test_runtime_needs_only_numpy(tmp_path):
    """Loading the design JSON and running the filter works with cvxpy and scipy
    unavailable (as inside the filter FMU)."""
    plant, d = setup(KIND_PD)
    path = tmp_path / "design.json"
    d.to_json(path)
    _, alpha, _, traj = scenario(plant, T=20)
    np.save(tmp_path / "alpha.npy", alpha)
    np.save(tmp_path / "y.npy", traj.y)
    expected = hinf_filter_batch(d, traj.y, alpha).zhat
    np.save(tmp_path / "expected.npy", expected)
    code = f"""
import sys
for name in ("cvxpy", "scipy", "matplotlib", "clarabel"):
    sys.modules[name] = None  # any import of these now fails
import numpy as np
from lpvest.design._result import HinfDesign
from lpvest.estimators._hinf import HinfFilter
from lpvest.core._protocol import run_streaming
d = HinfDesign.from_json(r"{path}")
out = run_streaming(HinfFilter(d), {{"alpha": np.load(r"{tmp_path / 'alpha.npy'}"),
                                      "y": np.load(r"{tmp_path / 'y.npy'}")}})
assert np.array_equal(out["zhat"], np.load(r"{tmp_path / 'expected.npy'}"))
print("ok")
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "ok"
