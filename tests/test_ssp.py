"""The SSP export: the file fmpy and libcosim load and run, what each honours,
and how their Jacobi stepping changes the results compared with our master,
checked against the exact relation (lpvest/ssp.py, module documentation)."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from lpvest import load_system
from lpvest.cli import main
from lpvest.cosim import Component, CoSimulation, CoSimulationError
from lpvest.design import HinfDesign
from lpvest.estimators.hinf import HinfFilter
from lpvest.fmi.components import SchedulerComponent, SourceComponent
from lpvest.signals import SignalSpec
from lpvest.ssp import read_ssp, simulate_ssp, write_ssp
from lpvest.systems.streaming import DiscretePlant
from tests.tolerances import roundoff

H = 0.5  # communication step: not the FMUs' default experiment step (1), so it must come from the file
N = 60
OMEGA, PHASE = 0.3, 0.5  # not the scheduler's defaults (0.25, 0): the bindings must be applied
X0 = [0.5, -0.25]
CONNECTIONS = ["sched.p -> plant.p", "src.w -> plant.w", "sched.p -> filter.p", "plant.y -> filter.y"]


def _components(fmus, **sched):
    return [
        Component("sched", fmus["PeixotoEx1Scheduler"], {"omega": [OMEGA], "phase": [PHASE], **sched}),
        Component("src", fmus["PeixotoEx1Source"], {"w.onset": 4.0}),
        Component("plant", fmus["PeixotoEx1Plant"], {"x0": X0}),
        Component("filter", fmus["PeixotoEx1HinfPD"]),
    ]


@pytest.fixture(scope="module")
def ssp(fmus, tmp_path_factory):
    return write_ssp(tmp_path_factory.mktemp("ssp") / "peixoto.ssp", _components(fmus), CONNECTIONS,
                     step_size=H, stop_time=N * H, description="Peixoto et al. Example 1")


@pytest.fixture(scope="module")
def master(fmus):
    """Our master on the same system: p, w, the plant's state and y, the filter's zhat at t_0 .. t_N."""
    with CoSimulation(_components(fmus), CONNECTIONS, step_size=H,
                      record=["sched.p", "src.w", "plant.x", "plant.y", "plant.z", "filter.zhat", "filter.xf"]) as sim:
        return sim.run(N)


@pytest.fixture(scope="module")
def library(fmus):
    """Fresh library components, the same as inside the FMUs (an independent oracle)."""
    plant = load_system("peixoto-ex1").model()
    with zipfile.ZipFile(fmus["PeixotoEx1HinfPD"]) as z:
        design = HinfDesign.from_json(z.read("resources/design.json").decode())

    def make():
        sched = SchedulerComponent(SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=OMEGA, phase=PHASE),
                                   plant.space, plant.simplex_map)
        src = SourceComponent({"w": SignalSpec.build("decaying", 1, amplitude=1.0, omega=0.5, decay=0.1,
                                                     onset=4.0, seed=1)})
        sched.reset(0.0), src.reset(0.0)
        return sched, src, DiscretePlant(plant, x0=X0), HinfFilter(design, simplex_map=plant.simplex_map)

    return make


def _jacobi(library, first: dict[str, float]) -> dict[str, np.ndarray]:
    """Jacobi stepping of the library components: every component steps from t_k
    with the inputs read after the previous step (``first`` at k = 0), and its
    outputs are read after the step with those inputs held."""
    sched, src, plant, filt = library()
    pin = {"p": np.array([first["p"]]), "w": np.array([first["w"]])}
    fin = {"p": np.array([first["p"]]), "y": np.array([first["y"]])}
    rows = []
    for k in range(N):
        sched.step({}, dt=H, t_end=(k + 1) * H)
        src.step({}, dt=H, t_end=(k + 1) * H)
        plant.step(pin)
        filt.step(fin)
        so, wo, po, fo = sched.outputs({}), src.outputs({}), plant.outputs(pin), filt.outputs(fin)
        rows.append(np.concatenate([so["p"], wo["w"], po["y"], po["x"], fo["zhat"], fo["xf"]]))
        pin = {"p": so["p"], "w": wo["w"]}
        fin = {"p": so["p"], "y": po["y"]}
    a = np.array(rows)
    return {"sched.p[1]": a[:, 0], "src.w[1]": a[:, 1], "plant.y[1]": a[:, 2], "plant.x[1]": a[:, 3],
            "plant.x[2]": a[:, 4], "filter.zhat[1]": a[:, 5], "filter.zhat[2]": a[:, 6],
            "filter.xf[1]": a[:, 7], "filter.xf[2]": a[:, 8]}


def test_the_file_holds_the_system_the_step_and_the_bound_parameters(fmus, ssp):
    from fmpy.ssp.ssd import read_ssd

    with zipfile.ZipFile(ssp) as z:
        names = sorted(z.namelist())
        xml = z.read("SystemStructure.ssd").decode()
    assert names == ["SystemStructure.ssd", "resources/PeixotoEx1HinfPD.fmu", "resources/PeixotoEx1Plant.fmu",
                     "resources/PeixotoEx1Scheduler.fmu", "resources/PeixotoEx1Source.fmu"]
    read_ssd(str(ssp), validate=True)  # valid against SSP 1.0's schema (fmpy's copy)
    assert '<osp:FixedStepAlgorithm baseStepSize="0.5"' in xml
    sys_ = read_ssp(ssp)
    assert sys_.step_size == H and sys_.start_time == 0.0 and sys_.stop_time == N * H
    assert sys_.connections == [("sched.p[1]", "plant.p[1]"), ("src.w[1]", "plant.w[1]"),
                                ("sched.p[1]", "filter.p[1]"), ("plant.y[1]", "filter.y[1]")]
    assert sys_.parameters["sched"] == [("omega[1]", "Real", "0.3"), ("phase[1]", "Real", "0.5")]
    assert sys_.parameters["src"] == [("w.onset", "Real", "4.0")]
    assert sys_.parameters["plant"] == [("x0[1]", "Real", "0.5"), ("x0[2]", "Real", "-0.25")]
    assert sys_.outputs["filter"] == ["zhat[1]", "zhat[2]", "xf[1]", "xf[2]"]


def test_components_sharing_an_fmu_carry_it_once_and_bad_systems_are_not_written(fmus, tmp_path):
    comps = [Component("f1", fmus["PeixotoEx1HinfRobust"]), Component("f2", fmus["PeixotoEx1HinfRobust"])]
    path = write_ssp(tmp_path / "two.ssp", comps, [], step_size=1.0)
    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == ["SystemStructure.ssd", "resources/PeixotoEx1HinfRobust.fmu"]
    assert set(read_ssp(path).components.values()) == {"resources/PeixotoEx1HinfRobust.fmu"}
    with pytest.raises(CoSimulationError, match=r"connection source 'f1\.q': f1 has no variable 'q'"):
        write_ssp(tmp_path / "bad.ssp", comps, ["f1.q -> f2.y"], step_size=1.0)
    assert not (tmp_path / "bad.ssp").exists()


def test_fmpy_ignores_the_bindings_and_the_step_unless_told(fmus, ssp):
    """fmpy.ssp.simulate_ssp as is: the SSD's parameter values are not applied
    (the scheduler runs with its default omega = 0.25, phase = 0), and the step
    is whatever the caller passes."""
    from fmpy.ssp.simulation import simulate_ssp as fmpy_simulate_ssp

    res = fmpy_simulate_ssp(str(ssp), stop_time=4 * H - 0.25 * H, step_size=H)
    t_after = (np.arange(4) + 1) * H  # fmpy reads the outputs after each step
    assert res.shape == (4,)
    # times accumulated over 4 steps (|dt| <= 4 eps t); sin is 1-Lipschitz and rounds once
    tol = roundoff(1.0 + t_after[-1], 4)
    np.testing.assert_allclose(res["sched.p[1]"], np.sin(0.25 * t_after), rtol=0, atol=tol)
    np.testing.assert_allclose(res["time"], t_after - H, rtol=0, atol=tol)  # labelled with the step's start


@pytest.mark.parametrize("importer", ["fmpy", "libcosim"])
def test_each_importer_runs_the_file_as_jacobi_stepping_predicts(ssp, master, library, importer):
    res = simulate_ssp(ssp, importer=importer)
    assert res.shape == (N,)
    # time accumulated over N steps: |dt| <= N eps t; sin(omega t + phase) rounds
    # its argument and itself once each
    t_end = N * H
    np.testing.assert_allclose(res["time"], (np.arange(N) + 1) * H, rtol=0, atol=roundoff(t_end, N))
    # the file's parameters and step were applied: p after step k is sin(0.3 t_(k+1) + 0.5)
    np.testing.assert_allclose(res["sched.p[1]"], np.sin(OMEGA * res["time"] + PHASE), rtol=0,
                               atol=roundoff(1.0 + OMEGA * t_end + abs(PHASE), 2))
    # what each importer feeds in before the first step: fmpy 0.0 on every
    # connection; libcosim the outputs at t_0 propagated in initialization mode
    if importer == "fmpy":
        first = {"p": 0.0, "w": 0.0, "y": 0.0}
    else:
        first = {"p": master["sched.p[1]"][0], "w": master["src.w[1]"][0], "y": master["plant.y[1]"][0]}
    pred = _jacobi(library, first)
    for name, values in pred.items():
        # the FMUs run lpvest's own steps: the same stable recursions (plant,
        # filter: sums of <= 4 products per step) over N steps, no growth assumed
        tol = roundoff(float(np.max(np.abs(values))), N, n=4)
        np.testing.assert_allclose(res[name], values, rtol=0, atol=tol, err_msg=f"{importer}: {name}")


def test_jacobi_delay_against_our_master_exactly(ssp, master, library, capsys):
    """libcosim (initialized like our master) against our master, with the exact
    relation: the plant runs identically; the filter gets
    y~_k = C_y x_k + D_y w_(k-1) = y_k - (w_k - w_(k-1)) (Peixoto's C_y = [1, 0],
    D_y = 1 do not depend on theta) instead of y_k, and its estimate is read
    after its step with theta_k and y~_k still held."""
    res = simulate_ssp(ssp, importer="libcosim")
    x = np.column_stack([master["plant.x[1]"], master["plant.x[2]"]])
    w, p, y = master["src.w[1]"], master["sched.p[1]"], master["plant.y[1]"]
    # the plant gets p_k and w_k in step k: its state is our master's
    np.testing.assert_array_equal(np.column_stack([res["plant.x[1]"], res["plant.x[2]"]]), x[1:])
    # the y it passes on in step k + 1 (read after step k, inputs held)
    y_tilde = np.concatenate([[y[0]], x[1:, 0] + w[:-1]])
    # C_y x + D_y w (two products and a sum) against x_1 + w; and y - (w_k - w_(k-1)): a few roundings
    size = float(np.max(np.abs(x[:, 0])) + np.max(np.abs(w)))
    np.testing.assert_allclose(res["plant.y[1]"], y_tilde[1:], rtol=0, atol=roundoff(size, 1, n=2))
    np.testing.assert_allclose(y_tilde, y - np.concatenate([[0.0], np.diff(w)]), rtol=0,
                               atol=roundoff(size + np.max(np.abs(w)), 2, n=2))
    # the filter of the library on (theta_k, y~_k), read with the inputs held
    _, _, _, filt = library()
    zhat = []
    for k in range(N):
        inp = {"p": p[k:k + 1], "y": y_tilde[k:k + 1]}
        filt.step(inp)
        zhat.append(filt.outputs(inp)["zhat"])
    zhat = np.array(zhat)
    # the FMU runs lpvest's HinfFilter step: the same recursion over N steps
    np.testing.assert_allclose(np.column_stack([res["filter.zhat[1]"], res["filter.zhat[2]"]]), zhat,
                               rtol=0, atol=roundoff(float(np.max(np.abs(zhat))), N, n=4))
    # how much it changes the estimate at the same instant t_(k+1), and the
    # achieved l2 gain from w to the estimation error (certified bound gamma)
    z = np.column_stack([master["plant.z[1]"], master["plant.z[2]"]])
    zhat_master = np.column_stack([master["filter.zhat[1]"], master["filter.zhat[2]"]])
    diff = np.max(np.abs(zhat - zhat_master[1:]), axis=0)
    gain_master = np.linalg.norm(z[1:] - zhat_master[1:]) / np.linalg.norm(w)
    gain_jacobi = np.linalg.norm(z[1:] - zhat) / np.linalg.norm(w)
    with capsys.disabled():
        print(f"\nJacobi (libcosim) vs our master, zhat: max difference {diff[0]:.3g}, {diff[1]:.3g}; "
              f"||z - zhat|| / ||w||: master {gain_master:.3f}, Jacobi {gain_jacobi:.3f}")
    assert np.all(diff > 1e-2)  # a visible change, not round-off
    assert gain_jacobi > gain_master


def test_string_parameters_libcosim_applies_them_fmpy_cannot(fmus, tmp_path):
    comps = _components(fmus, kind="constant", offset=[0.25])
    path = write_ssp(tmp_path / "const.ssp", comps, CONNECTIONS, step_size=1.0, stop_time=3.0)
    res = simulate_ssp(path, importer="libcosim")
    np.testing.assert_array_equal(res["sched.p[1]"], [0.25, 0.25, 0.25])
    with pytest.raises(CoSimulationError, match=r"fmpy's simulate_ssp cannot set the String parameter "
                                                r"sched\.kind = 'constant'"):
        simulate_ssp(path, importer="fmpy")
    # a String value equal to the FMU's start value needs no setting: fmpy runs
    same = write_ssp(tmp_path / "same.ssp", _components(fmus, kind="sinusoid"), CONNECTIONS, step_size=1.0,
                     stop_time=3.0)
    assert simulate_ssp(same, importer="fmpy").shape == (3,)


def test_command_line_writes_the_ssp_of_a_cosim_file(fmus, tmp_path, capsys):
    from pathlib import Path

    example = Path(__file__).resolve().parent.parent / "examples" / "peixoto_ex1_hinf.toml"
    out = tmp_path / "ex.ssp"
    assert main(["cosim", str(example), "--fmus", str(fmus.out), "--ssp", str(out)]) == 0
    assert f"wrote {out}: 4 components, 4 connections, step 1, t = 0 .. 100" in capsys.readouterr().out
    system = read_ssp(out)
    assert system.stop_time == 100.0 and system.step_size == 1.0
    assert ("omega[1]", "Real", "0.25") in system.parameters["sched"]
    assert simulate_ssp(out, importer="fmpy", n_steps=5).shape == (5,)


def test_the_readme_numbers_for_the_example_file(fmus, tmp_path):
    """README, SSP export: on examples/peixoto_ex1_hinf.toml fmpy and libcosim
    agree, and ||z - zhat|| / ||w|| is 1.07 with our master, 1.60 with Jacobi
    stepping (certified gamma = 1.21)."""
    from pathlib import Path

    from lpvest.cosimfile import load_cosim

    spec = load_cosim(Path(__file__).resolve().parent.parent / "examples" / "peixoto_ex1_hinf.toml",
                      fmu_dir=fmus.out)
    m = spec.run().data
    path = spec.to_ssp(tmp_path / "example.ssp")
    f, lc = simulate_ssp(path, importer="fmpy"), simulate_ssp(path, importer="libcosim")
    for name in lc.dtype.names:
        np.testing.assert_array_equal(f[name], lc[name], err_msg=name)
    w = np.linalg.norm(m["src.w[1]"])
    e_master = np.column_stack([m[f"plant.z[{i}]"] - m[f"filter.zhat[{i}]"] for i in (1, 2)])
    e_jacobi = np.column_stack([m[f"plant.z[{i}]"][1:] - lc[f"filter.zhat[{i}]"] for i in (1, 2)])
    assert np.linalg.norm(e_master) / w == pytest.approx(1.07, abs=0.005)
    assert np.linalg.norm(e_jacobi) / w == pytest.approx(1.60, abs=0.005)
    with zipfile.ZipFile(fmus["PeixotoEx1HinfPD"]) as z:
        assert HinfDesign.from_json(z.read("resources/design.json").decode()).gamma == pytest.approx(1.21, abs=0.005)
