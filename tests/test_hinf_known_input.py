"""H-infinity filters for a model with general noise and a known input:
the conversion to Peixoto et al.'s setting (lpvest.systems._polytopic.hinf_setting)
and the exact compensation of u (module docs of lpvest.estimators._hinf)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._errors import ArgumentTypeError, DimensionError, ModelFileError
from lpvest.core._protocol import run_streaming
from lpvest.design import KIND_PD, KIND_ROBUST, design_hinf
from lpvest.estimators._hinf import HinfFilter, hinf_filter_batch
from lpvest.systems._modelfile import save_system
from lpvest.systems._polytopic import PolytopicLPV, hinf_setting
from tests import hinf_oracle as oracle
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel

_CACHE: dict = {}


def model():
    return load_system("cox-toth-truncation").model()  # affine, S != 0, G(p), H(p), one known input


def setup(kind):
    if kind not in _CACHE:
        plant = hinf_setting(model())
        _CACHE[kind] = (plant, design_hinf(plant, epsilon=1.0, kind=kind))
    return _CACHE[kind]


def test_the_setting_is_the_model_with_whitened_noise():
    m = model()
    plant = hinf_setting(m, z=[[1.0, -1.0]])
    assert (plant.n_vertices, plant.nx, plant.nw, plant.nz, plant.ny, plant.nu) == (2, 2, 4, 1, 2, 1)
    L = np.linalg.cholesky(m.noise.joint)
    np.testing.assert_allclose(L @ L.T, m.noise.joint, rtol=0, atol=roundoff(np.max(np.abs(m.noise.joint)), n=4))
    for p in np.linspace(-1.0, 1.0, 9):
        s = m.at([p])
        a = plant.matrices(plant.alpha([p]))
        # vertices combined by multilinear weights: sums of 2 products per entry, then the
        # model's own affine combination: a few roundings of the entries' size
        for got, want in ((a["A"], s.A), (a["Cy"], s.C), (a["Bu"], s.B), (a["Dyu"], s.D),
                          (a["Bw"], s.G @ L[:2]), (a["Dy"], s.H @ L[2:])):
            np.testing.assert_allclose(got, want, rtol=0, atol=roundoff(1.0 + np.max(np.abs(want)), 3, n=4))
        np.testing.assert_array_equal(a["Cz"], [[1.0, -1.0]])
        np.testing.assert_array_equal(a["Dz"], np.zeros((1, 4)))
        np.testing.assert_array_equal(a["Dzu"], np.zeros((1, 1)))
    # the noise [w; v] = L w~ has the model's covariance: Bw Bw^T = G Q G^T etc.
    s = m.at([0.3])
    a = plant.matrices(plant.alpha([0.3]))
    np.testing.assert_allclose(a["Bw"] @ a["Dy"].T, s.G @ m.noise.S @ s.H.T, rtol=0, atol=roundoff(1.0, 3, n=8))


@pytest.mark.parametrize("kind", [KIND_PD, KIND_ROBUST])
def test_the_estimation_error_does_not_depend_on_the_known_input(kind):
    plant, d = setup(kind)
    T = 120
    k = np.arange(float(T))
    p = np.sin(0.3 * k)[:, None]
    alpha = plant.alpha_batch(p)
    rng = np.random.default_rng(5)
    w = rng.standard_normal((T, plant.nw))
    u = 10.0 * rng.standard_normal((T, 1)) + 5.0 * np.sin(0.05 * k)[:, None]
    f = HinfFilter(d, simplex_map=plant.simplex_map, plant=plant)
    assert [q.name for q in f.input_ports] == ["p", "u", "y"]  # the robust filter too: A(p) varies
    with_u = plant.simulate(alpha, w, u=u)
    without = plant.simulate(alpha, w)
    out_u = run_streaming(f, {"p": p, "u": u, "y": with_u.y})
    f.reset()
    out_0 = run_streaming(f, {"p": p, "u": np.zeros_like(u), "y": without.y})
    e_u = with_u.z - out_u["zhat"]
    e_0 = without.z - out_0["zhat"]
    # the same error by two routes that differ by the u-driven parts (of the size of
    # the plant's state with u), cancelled in each step: per step sums of at most
    # 2 n_x + n_y + n_u products, T steps of stable recursions (no growth assumed)
    size = float(np.max(np.abs(with_u.x)) + np.max(np.abs(with_u.y)) + np.max(np.abs(out_u["zhat"])))
    assert size > 50 * float(np.max(np.abs(e_0)))  # u dominates the signals
    np.testing.assert_allclose(e_u, e_0, rtol=0, atol=roundoff(size, T, n=7))
    # the Proposition: e is the error of filter (2) on plant (1) without input (augmented system (3))
    err = oracle.simulate_error(plant, d, alpha, w)
    np.testing.assert_allclose(e_0, err, rtol=0, atol=roundoff(size, T, n=7))
    # the certified bound holds with the input: ||e||_2 < gamma ||w||_2 from zero initial state
    assert np.linalg.norm(e_u) < d.gamma * np.linalg.norm(w)


@pytest.mark.parametrize("kind", [KIND_PD, KIND_ROBUST])
def test_the_batch_filter_compensates_u_as_the_streaming_filter_does(kind):
    plant, d = setup(kind)
    T = 60
    rng = np.random.default_rng(11)
    p = rng.uniform(-1.0, 1.0, (T, 1))
    alpha = plant.alpha_batch(p)
    u = 3.0 * rng.standard_normal((T, 1))
    y = plant.simulate(alpha, rng.standard_normal((T, plant.nw)), u=u).y
    streamed = run_streaming(HinfFilter(d, simplex_map=plant.simplex_map, plant=plant), {"p": p, "u": u, "y": y})
    batch = hinf_filter_batch(d, y, alpha, plant=plant, u=u)
    np.testing.assert_array_equal(batch.zhat, streamed["zhat"])  # one computation, sample by sample
    np.testing.assert_array_equal(batch.xf, streamed["xf"])
    # without the plant, u is not compensated: another estimate (the old silent behaviour)
    assert not np.allclose(hinf_filter_batch(d, y, alpha).zhat, batch.zhat)
    with pytest.raises(DimensionError, match="has a known input: pass u"):
        hinf_filter_batch(d, y, alpha, plant=plant)
    with pytest.raises(DimensionError, match="pass the plant too"):
        hinf_filter_batch(d, y, alpha, u=u)
    with pytest.raises(DimensionError, match="needs alpha"):
        hinf_filter_batch(d, y, plant=plant, u=u)  # the response to u varies with p here, robust too


@pytest.mark.slow
@pytest.mark.parametrize("kind", [KIND_PD, KIND_ROBUST])
def test_gamma_is_above_the_worst_case_gain_found(kind):
    plant, d = setup(kind)
    gain, where = oracle.worst_case_gain(plant, d, np.random.default_rng(0), n_random=8)
    assert gain < d.gamma, f"worst case {gain:.6g} ({where}) above gamma {d.gamma:.6g}"


def test_a_filter_without_the_plant_ignores_u_and_a_wrong_plant_is_refused():
    plant, d = setup(KIND_PD)
    f = HinfFilter(d, simplex_map=plant.simplex_map)
    assert [q.name for q in f.input_ports] == ["p", "y"]
    other = hinf_setting(model(), z=[[1.0, 0.0]])
    with pytest.raises(ModelFileError, match="designed for a plant with nz = 2"):
        HinfFilter(d, plant=other)
    assert hinf_setting(plant) is plant  # a polytopic plant is in the setting already
    with pytest.raises(ArgumentTypeError, match="converts an AffineLPV"):
        hinf_setting(load_system("cox-toth-ex1").model())  # an innovation-form model


def test_polytopic_input_matrices_are_checked():
    plant, _ = setup(KIND_PD)
    v = {**plant.vertices._asdict()}
    with pytest.raises(DimensionError, match="needs Bu"):
        PolytopicLPV({**v, "Dyu": np.zeros((2, 2, 1))})
    with pytest.raises(DimensionError, match=r"Bu vertices have shape \(2, 3, 1\); expected \(2, 2, n_u\)"):
        PolytopicLPV({**v, "Bu": np.zeros((2, 3, 1))})
    with pytest.raises(DimensionError, match="has no known input"):
        PolytopicLPV(v).simulate(np.full((3, 2), 0.5), np.zeros((3, 4)), u=np.zeros((3, 1)))
    state_names = sorted(HinfFilter(setup(KIND_PD)[1], plant=plant).get_state())
    assert state_names == ["k", "xf", "xu"]


def test_model_files_choose_z_and_carry_known_input_matrices(tmp_path):
    text = (load_system("cox-toth-truncation").path.read_text(encoding="utf-8")
            + "Cz = [[1.0, 0.0]]\n")  # appended to [models.plant]: z = x_1
    path = tmp_path / "plant.toml"
    path.write_text(text, encoding="utf-8")
    m = load_system(path).model()
    np.testing.assert_array_equal(m.Cz, [[1.0, 0.0]])
    plant = hinf_setting(m)
    assert plant.nz == 1
    assert m.to_toml()["Cz"] == [[1.0, 0.0]]
    assert any("Cz (z = Cz x" in line for line in m.describe("plant"))
    # the polytopic form, with its input matrices, written to a model file and read back
    poly = tmp_path / "poly.toml"
    source = load_system(path)
    save_system(dataclasses.replace(source, models={"plant": plant}), poly)
    again = load_system(poly).model()
    assert again.nu == 1
    for a, b in zip((*again.vertices, *again.known_input), (*plant.vertices, *plant.known_input), strict=True):
        np.testing.assert_array_equal(a, b)
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("Cz = [[1.0, 0.0]]", "Cz = [[1.0, 0.0, 0.0]]"), encoding="utf-8")
    with pytest.raises(ModelFileError, match=r"models\.plant.*Cz"):
        load_system(bad)


def test_a_robust_filter_of_a_plant_whose_input_path_is_constant_takes_no_scheduling():
    varying, _ = setup(KIND_ROBUST)
    stacks = {n: np.broadcast_to(m[:1], m.shape).copy() for n, m in varying.vertex_stacks().items()}
    plant = PolytopicLPV(stacks, name="frozen")  # every vertex equal: nothing depends on alpha
    assert not plant.input_path_varies()
    d = design_hinf(plant, epsilon=1.0, kind=KIND_ROBUST)
    f = HinfFilter(d, plant=plant)
    assert [q.name for q in f.input_ports] == ["u", "y"]
    T = 60
    rng = np.random.default_rng(2)
    alpha = np.full((T, 2), 0.5)
    w = rng.standard_normal((T, plant.nw))
    u = 10.0 * rng.standard_normal((T, 1))
    with_u, without = plant.simulate(alpha, w, u=u), plant.simulate(alpha, w)
    e_u = with_u.z - run_streaming(f, {"u": u, "y": with_u.y})["zhat"]
    f.reset()
    e_0 = without.z - run_streaming(f, {"u": np.zeros_like(u), "y": without.y})["zhat"]
    # as in the scheduled case: the u-driven parts cancel, T steps of sums of <= 7 products
    size = float(np.max(np.abs(with_u.x)) + np.max(np.abs(with_u.y)) + np.max(np.abs(with_u.z)))
    np.testing.assert_allclose(e_u, e_0, rtol=0, atol=roundoff(size, T, n=7))
    # the batch filter takes no scheduling either, and computes what the streaming one does
    f.reset()
    streamed = run_streaming(f, {"u": u, "y": with_u.y})
    batch = hinf_filter_batch(d, with_u.y, plant=plant, u=u)
    np.testing.assert_array_equal(batch.zhat, streamed["zhat"])
    np.testing.assert_array_equal(batch.xf, streamed["xf"])


def test_a_polytopic_model_with_a_known_input_streams_and_evaluates_like_its_simulation(rng):
    from lpvest.systems._streaming import DiscretePlant

    plant = hinf_setting(model())
    # at / at_batch: the six matrices of (1), equal to the same entries of matrices()
    alpha = plant.alpha([0.4])
    at = plant.at(alpha)
    full = plant.matrices(alpha)
    for name in at._fields:
        np.testing.assert_array_equal(getattr(at, name), full[name])
    batch = plant.at_batch(np.stack([alpha, plant.alpha([-0.2])]))
    np.testing.assert_array_equal(batch.A[0], at.A)
    # the streaming plant (and so the Plant FMU) takes u, and reproduces simulate(u=...) to the bit
    T = 30
    p = rng.uniform(-1.0, 1.0, (T, 1))
    w, u = rng.standard_normal((T, plant.nw)), rng.standard_normal((T, plant.nu))
    sim = plant.simulate(plant.alpha_batch(p), w, u=u)
    streaming = DiscretePlant(plant)
    assert [q.name for q in streaming.input_ports] == ["p", "u", "w"]
    out = run_streaming(streaming, {"p": p, "u": u, "w": w})
    np.testing.assert_array_equal(out["y"], sim.y)
    np.testing.assert_array_equal(out["z"], sim.z)
    np.testing.assert_array_equal(out["x"], sim.x)


def with_feedthrough(plant: PolytopicLPV) -> PolytopicLPV:
    """The plant with a known input that also reaches y and z directly (Dyu, Dzu != 0, varying
    with alpha). The design matrices (A, Bw, Cz, Dz, Cy, Dy) are unchanged, so the designs of
    ``setup`` are designs for it (the design digest covers those only)."""
    stacks = dict(plant.vertex_stacks())
    stacks["Dyu"] = np.array([[[0.7], [-0.3]], [[1.5], [0.2]]])
    stacks["Dzu"] = np.array([[[0.4], [0.0]], [[-0.2], [1.0]]])
    return PolytopicLPV(stacks, simplex_map=plant.simplex_map, name="with-Dyu")


@pytest.mark.parametrize("kind", [KIND_PD, KIND_ROBUST])
def test_a_plant_with_direct_feedthrough_of_u_is_compensated_exactly(kind):
    """Dyu u reaches the measurement and Dzu u the estimated output in the same sample: the
    filter removes the first before (2) and adds the second back, so its error is still the
    error of (2) on the plant without input."""
    base, d = setup(kind)
    plant = with_feedthrough(base)
    T = 80
    rng = np.random.default_rng(8)
    p = rng.uniform(-1.0, 1.0, (T, 1))
    alpha = plant.alpha_batch(p)
    w = rng.standard_normal((T, plant.nw))
    u = 10.0 * rng.standard_normal((T, 1))
    with_u, without = plant.simulate(alpha, w, u=u), plant.simulate(alpha, w)
    # the feedthrough is there: y and z move with u in the same sample
    direct = np.einsum("kn,nij,kj->ki", alpha, plant.vertex_stacks()["Dyu"], u)
    assert np.max(np.abs(direct)) > 5.0
    f = HinfFilter(d, simplex_map=plant.simplex_map, plant=plant)
    out_u = run_streaming(f, {"p": p, "u": u, "y": with_u.y})
    f.reset()
    out_0 = run_streaming(f, {"p": p, "u": np.zeros_like(u), "y": without.y})
    e_u, e_0 = with_u.z - out_u["zhat"], without.z - out_0["zhat"]
    # as above: the u-driven parts cancel in each step, T steps of sums of at most 2 n_x + n_y + 2 n_u products
    size = float(np.max(np.abs(with_u.x)) + np.max(np.abs(with_u.y)) + np.max(np.abs(out_u["zhat"])))
    assert size > 50 * float(np.max(np.abs(e_0)))
    np.testing.assert_allclose(e_u, e_0, rtol=0, atol=roundoff(size, T, n=8))
    np.testing.assert_allclose(e_0, oracle.simulate_error(plant, d, alpha, w), rtol=0, atol=roundoff(size, T, n=8))
    assert np.linalg.norm(e_u) < d.gamma * np.linalg.norm(w)
    # the batch filter: the same computation, bit for bit
    batch = hinf_filter_batch(d, with_u.y, alpha, plant=plant, u=u)
    np.testing.assert_array_equal(batch.zhat, out_u["zhat"])
    np.testing.assert_array_equal(batch.xf, out_u["xf"])


def test_a_saved_state_carries_the_copy_of_the_response_to_u():
    base, d = setup(KIND_PD)
    plant = with_feedthrough(base)
    T = 20
    rng = np.random.default_rng(3)
    p, u = rng.uniform(-1.0, 1.0, (T, 1)), rng.standard_normal((T, 1))
    y = plant.simulate(plant.alpha_batch(p), rng.standard_normal((T, plant.nw)), u=u).y
    f = HinfFilter(d, simplex_map=plant.simplex_map, plant=plant)
    first = run_streaming(f, {"p": p[:10], "u": u[:10], "y": y[:10]})
    state = f.get_state()
    assert sorted(state) == ["k", "xf", "xu"] and state["k"] == 10 and np.any(state["xu"] != 0)
    rest = run_streaming(f, {"p": p[10:], "u": u[10:], "y": y[10:]})
    g = HinfFilter(d, simplex_map=plant.simplex_map, plant=plant)
    g.set_state(state)
    again = run_streaming(g, {"p": p[10:], "u": u[10:], "y": y[10:]})
    np.testing.assert_array_equal(again["zhat"], rest["zhat"])
    whole = hinf_filter_batch(d, y, plant.alpha_batch(p), plant=plant, u=u)
    np.testing.assert_array_equal(np.vstack([first["zhat"], rest["zhat"]]), whole.zhat)
    with pytest.raises(DimensionError, match=r"^a HinfFilter state needs 'xf', 'xu' and 'k'; found \['k', 'xf'\]$"):
        g.set_state({"xf": state["xf"], "k": 3})
    with pytest.raises(DimensionError, match=r"xu has shape \(3,\); expected \(2,\)"):
        g.set_state({**state, "xu": np.zeros(3)})
    with pytest.raises(DimensionError, match=r"^the sample counter k of a HinfFilter state must be >= 0; found -1$"):
        g.set_state({**state, "k": -1})
    np.testing.assert_array_equal(g.get_state()["xu"], f.get_state()["xu"])  # refused states change nothing
    with pytest.raises(DimensionError, match=r"inputs are \['p', 'u', 'y'\]; missing \['u'\], unknown \['w'\]"):
        g.step({"p": p[0], "w": u[0], "y": y[0]})
    with pytest.raises(DimensionError, match=r"u has shape \(2,\); expected \(1,\)"):
        g.step({"p": p[0], "u": np.zeros(2), "y": y[0]})
    with pytest.raises(ArgumentTypeError, match=r"^plant must be a PolytopicLPV; found AffineLPV$"):
        HinfFilter(d, plant=model())


def test_a_singular_or_exploding_filter_step_is_a_numerical_error():
    from lpvest.core._errors import NumericalError
    from lpvest.estimators._hinf import hinf_step

    _, d = setup(KIND_ROBUST)
    bad = dataclasses.replace(d, H=np.zeros_like(np.asarray(d.H)))
    with pytest.raises(NumericalError, match=r"^H\(alpha\) is singular at alpha = None: "):
        hinf_step(bad, np.zeros(d.nx), None, np.ones(d.ny))
    with pytest.raises(NumericalError, match=r"^the filter state became non-finite at alpha = None$"):
        hinf_step(dataclasses.replace(d, H=np.asarray(d.H) * 1e-300), np.full(d.nx, 1e10), None, np.ones(d.ny))
    step = hinf_step(d, np.ones(d.nx), None, np.ones(d.ny))
    m = d.matrices_at(None)
    np.testing.assert_array_equal(step.zhat, m.Cf @ np.ones(d.nx) + m.Df @ np.ones(d.ny))
    np.testing.assert_allclose(m.H @ step.xf_next, m.Af @ np.ones(d.nx) + m.Bf @ np.ones(d.ny), rtol=0,
                               atol=roundoff(float(np.abs(m.H).sum() + np.abs(m.Af).sum() + np.abs(m.Bf).sum()),
                                             4, n=2 * d.nx))


def test_inputs_of_the_wrong_shape_are_named_and_the_ports_describe_themselves():
    plant, d = setup(KIND_PD)
    T = 4
    alpha, y, u = np.full((T, 2), 0.5), np.zeros((T, 2)), np.zeros((T, 1))
    with pytest.raises(DimensionError, match=r"^u is the known input of a plant: pass the plant too \(plant=\.\.\.\), "
                                             r"or leave u out for a plant without one$"):
        hinf_filter_batch(d, y, alpha, u=u)
    for kw, name in (({"y": np.zeros((T, 3))}, "y"), ({"u": np.zeros((T, 2))}, "u"),
                     ({"alpha": np.full((T, 3), 1 / 3)}, "alpha"), ({"xf0": np.zeros(3)}, "xf0")):
        args = {"y": y, "alpha": alpha, "u": u, **kw}
        with pytest.raises(DimensionError, match=rf"^{name} has shape "):
            hinf_filter_batch(d, args.pop("y"), args.pop("alpha"), plant=plant, **args)
    with pytest.raises(ModelFileError, match=r"^parameter-dependent design: designed for a plant with nz = 2"):
        HinfFilter(d, plant=hinf_setting(model(), z=[[1.0, 0.0]]))
    f = HinfFilter(d, simplex_map=plant.simplex_map, plant=plant)
    assert [(q.name, q.shape, q.description) for q in f.input_ports] == [
        ("p", (1,), "physical scheduling"), ("u", (1,), "known input u_k (compensated)"),
        ("y", (2,), "measured output y_k")]
    g = HinfFilter(d, plant=plant)
    assert (g.input_ports[0].name, g.input_ports[0].description) == ("alpha", "scheduling on the unit simplex")
    with pytest.raises(DimensionError, match=r"^p has shape \(2,\); expected \(1,\)$"):
        f.step({"p": np.zeros(2), "u": np.zeros(1), "y": np.zeros(2)})


def test_a_singular_scheduled_filter_names_the_scheduling_point():
    from lpvest.core._errors import NumericalError
    from lpvest.estimators._hinf import hinf_step

    _, d = setup(KIND_PD)
    bad = dataclasses.replace(d, H=np.zeros_like(np.asarray(d.H)))
    with pytest.raises(NumericalError, match=r"^H\(alpha\) is singular at alpha = \[0\.25 0\.75\]: "):
        hinf_step(bad, np.zeros(d.nx), np.array([0.25, 0.75]), np.ones(d.ny))
    # the stepping filter names the point too, and a refused step leaves its state as it was
    f = HinfFilter(bad)
    f.set_state({"xf": np.ones(d.nx), "k": 3})
    with pytest.raises(NumericalError, match=r"^H\(alpha\) is singular at alpha = \[0\.25 0\.75\]: "):
        f.step({"alpha": np.array([0.25, 0.75]), "y": np.ones(d.ny)})
    state = f.get_state()
    np.testing.assert_array_equal(state["xf"], np.ones(d.nx))
    assert state["k"] == 3
