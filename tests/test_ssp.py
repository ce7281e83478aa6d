"""The SSP export: the file fmpy and libcosim load and run, what each honours,
and how their Jacobi stepping changes the results compared with our master,
checked against the exact relation (lpvest/cosim/_ssp.py, module documentation)."""

from __future__ import annotations

import os
import zipfile

import numpy as np
import pytest

from lpvest import load_system
from lpvest.cli import main
from lpvest.core._signals import SchedulerComponent, SignalSpec, SourceComponent
from lpvest.cosim import Component, CoSimulation, CoSimulationError
from lpvest.cosim._ssp import DELAY, read_ssp, simulate_ssp, write_ssp
from lpvest.design import HinfDesign
from lpvest.estimators._hinf import HinfFilter
from lpvest.systems._streaming import DiscretePlant
from tests.tolerances import roundoff

H = 0.5  # communication step: not the FMUs' default experiment step (1), so it must come from the file
N = 60
OMEGA, PHASE = 0.3, 0.5  # not the scheduler's defaults (0.25, 0): the bindings must be applied
X0 = [0.5, -0.25]
CONNECTIONS = ["sched.p -> plant.p", "src.w -> plant.w", "sched.p -> filter.p", "plant.y -> filter.y"]


def _components(fmus, h=H, **sched):
    """The system; the discrete-time plant and filter sample every ``h`` (their parameter sample_time)."""
    return [
        Component("sched", fmus["PeixotoEx1Scheduler"], {"omega": [OMEGA], "phase": [PHASE], **sched}),
        Component("src", fmus["PeixotoEx1Source"], {"w.onset": 4.0}),
        Component("plant", fmus["PeixotoEx1Plant"], {"x0": X0, "sample_time": h}),
        Component("filter", fmus["PeixotoEx1HinfPD"], {"sample_time": h}),
    ]


@pytest.fixture(scope="module")
def ssp(fmus, tmp_path_factory):
    """The file for a Jacobi importer (the default): the filter's measurement_delay = 1 bound."""
    return write_ssp(tmp_path_factory.mktemp("ssp") / "peixoto.ssp", _components(fmus), CONNECTIONS,
                     step_size=H, stop_time=N * H, description="Peixoto et al. Example 1")


@pytest.fixture(scope="module")
def ssp_undelayed(fmus, tmp_path_factory):
    """The same system written with jacobi=False: the filter takes y as it comes."""
    return write_ssp(tmp_path_factory.mktemp("ssp") / "peixoto0.ssp", _components(fmus), CONNECTIONS,
                     step_size=H, stop_time=N * H, description="Peixoto et al. Example 1", jacobi=False)


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


def _jacobi(library, first: dict[str, float], *, delay: int = 0, m: int = 1, n: int = N) -> dict[str, np.ndarray]:
    """Jacobi stepping of the library components: every component steps from t_k
    with the inputs read after the previous step (``first`` at k = 0), and its
    outputs are read after the step: those with direct feedthrough (the plant's
    y, the filter's zhat) hold their value at the sample just consumed, the
    others (p, w, the states x and xf) are at t_(k+1) (lpvest.fmi._slave). The
    filter pairs its measurement ``delay`` samples late (MeasurementDelay); a
    step of ``m`` samples runs the plant and the filter ``m`` samples with their
    inputs held."""
    from lpvest.core._protocol import MeasurementDelay

    sched, src, plant, filt = library()
    if delay:
        filt = MeasurementDelay(filt, delay=delay)
    pin = {"p": np.array([first["p"]]), "w": np.array([first["w"]])}
    fin = {"p": np.array([first["p"]]), "y": np.array([first["y"]])}
    rows = []
    for k in range(n):
        sched.step({}, dt=m * H, t_end=(k + 1) * m * H)
        src.step({}, dt=m * H, t_end=(k + 1) * m * H)
        for _ in range(m):
            po = plant.step(pin)
            fo = filt.step(fin)
        so, wo = sched.outputs({}), src.outputs({})
        x, xf = plant.get_state()["x"], filt.outputs(fin)["xf"]
        rows.append(np.concatenate([so["p"], wo["w"], po["y"], x, fo["zhat"], xf]))
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
    assert sys_.parameters["plant"] == [("x0[1]", "Real", "0.5"), ("x0[2]", "Real", "-0.25"),
                                        ("sample_time", "Real", "0.5")]
    # the importers step in parallel: the filter's y (the plant's, with feedthrough) arrives one sample late
    assert sys_.parameters["filter"] == [("sample_time", "Real", "0.5"), ("measurement_delay", "Integer", "1")]
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


def test_fmpy_ignores_the_bindings_and_the_step_unless_told(fmus, ssp, tmp_path, monkeypatch):
    """fmpy.ssp.simulate_ssp as is: the SSD's parameter values are not applied
    (the scheduler runs with its default omega = 0.25, phase = 0; the plant and
    filter keep their sample time 1), and the step is whatever the caller passes.
    (Its failing run leaves its extractions: into this test's folder.)"""
    import tempfile

    from fmpy.fmi1 import FMICallException
    from fmpy.ssp.simulation import simulate_ssp as fmpy_simulate_ssp

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))

    res = fmpy_simulate_ssp(str(ssp), stop_time=4.0 - 0.25, step_size=1.0)
    t_after = np.arange(4) + 1.0  # fmpy reads the outputs after each step
    assert res.shape == (4,)
    # times accumulated over 4 steps (|dt| <= 4 eps t); sin is 1-Lipschitz and rounds once
    tol = roundoff(1.0 + t_after[-1], 4)
    np.testing.assert_allclose(res["sched.p[1]"], np.sin(0.25 * t_after), rtol=0, atol=tol)
    np.testing.assert_allclose(res["time"], t_after - 1.0, rtol=0, atol=tol)  # labelled with the step's start
    # the file's step with the FMUs' own sample time: the discrete-time plant refuses it (fmi2Error)
    with pytest.raises(FMICallException, match="fmi2DoStep failed with status 3"):
        fmpy_simulate_ssp(str(ssp), stop_time=4 * H - 0.25 * H, step_size=H)


@pytest.mark.parametrize("delay", [0, 1])
@pytest.mark.parametrize("importer", ["fmpy", "libcosim"])
def test_each_importer_runs_the_file_as_jacobi_stepping_predicts(ssp, ssp_undelayed, master, library, importer,
                                                                 delay):
    res = simulate_ssp(ssp if delay else ssp_undelayed, importer=importer)
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
    pred = _jacobi(library, first, delay=delay)
    for name, values in pred.items():
        # the FMUs run lpvest's own steps: the same stable recursions (plant,
        # filter: sums of <= 4 products per step) over N steps, no growth assumed
        tol = roundoff(float(np.max(np.abs(values))), N, n=4)
        np.testing.assert_allclose(res[name], values, rtol=0, atol=tol, err_msg=f"{importer}: {name}")


def test_jacobi_delay_against_our_master_exactly(ssp_undelayed, master, library, capsys):
    """libcosim (initialized like our master) against our master, with the exact
    relation: the plant runs identically and its y is read after each step
    holding the value of the sample it consumed (y_k); so the filter gets
    (theta_(k+1), y_k) in step k + 1 instead of (theta_(k+1), y_(k+1)): every
    measurement one sample late (the file written with jacobi=False, so the
    filter takes y as it comes)."""
    res = simulate_ssp(ssp_undelayed, importer="libcosim")
    x = np.column_stack([master["plant.x[1]"], master["plant.x[2]"]])
    w, p, y = master["src.w[1]"], master["sched.p[1]"], master["plant.y[1]"]
    # the plant gets p_k and w_k in step k: its state is our master's, and its y is y_k
    np.testing.assert_array_equal(np.column_stack([res["plant.x[1]"], res["plant.x[2]"]]), x[1:])
    # the same FMU code on the same inputs in this process: the plant is bit for bit our master's
    np.testing.assert_array_equal(res["plant.y[1]"], y[:-1])
    # the library filter on (theta_k, y_(k-1)) (y_(-1): the output at t_0, as libcosim initializes)
    y_late = np.concatenate([[y[0]], y[:-2]])
    _, _, _, filt = library()
    zhat = np.array([filt.step({"p": p[k:k + 1], "y": y_late[k:k + 1]})["zhat"] for k in range(N)])
    # the FMU runs lpvest's HinfFilter step: the same recursion (sums of <= 4
    # products per step) over N steps, possibly rounded in another order
    np.testing.assert_allclose(np.column_stack([res["filter.zhat[1]"], res["filter.zhat[2]"]]), zhat,
                               rtol=0, atol=roundoff(float(np.max(np.abs(zhat))), N, n=4))
    # how much it changes the estimate of the same sample, and the achieved l2
    # gain from w to the estimation error (certified bound gamma, for y_k in time)
    z = np.column_stack([master["plant.z[1]"], master["plant.z[2]"]])
    zhat_master = np.column_stack([master["filter.zhat[1]"], master["filter.zhat[2]"]])
    diff = np.max(np.abs(zhat - zhat_master[:-1]), axis=0)
    gain_master = np.linalg.norm(z[:-1] - zhat_master[:-1]) / np.linalg.norm(w)
    gain_jacobi = np.linalg.norm(z[:-1] - zhat) / np.linalg.norm(w)
    with capsys.disabled():
        print(f"\nJacobi (libcosim) vs our master, zhat: max difference {diff[0]:.3g}, {diff[1]:.3g}; "
              f"||z - zhat|| / ||w||: master {gain_master:.3f}, Jacobi {gain_jacobi:.3f}")
    assert np.all(diff > 1e-2)  # a visible change, not round-off
    assert gain_jacobi > gain_master


def test_with_the_measurement_delay_each_estimate_is_our_masters_one_step_later(ssp, master):
    """The file as written (measurement_delay = 1 bound) under libcosim, which
    initializes like our master: the filter pairs y_k, which arrives in step
    k + 1, with theta_k, so the estimate read after step k + 1 is our master's
    estimate of sample k, to the bit (the same FMU code on the same samples),
    and the state read after step k is our master's x_f,k; read after step 0
    (no measurement yet) the estimate is 0. (fmpy feeds 0.0 before the first
    step, here theta_0 = sin(0.5): its run is checked against the library's
    Jacobi stepping in test_each_importer_runs_the_file_as_jacobi_stepping_predicts.)"""
    res = simulate_ssp(ssp, importer="libcosim")
    zhat = np.column_stack([res["filter.zhat[1]"], res["filter.zhat[2]"]])
    assert np.array_equal(zhat[0], [0.0, 0.0])
    np.testing.assert_array_equal(zhat[1:], np.column_stack([master["filter.zhat[1]"], master["filter.zhat[2]"]])[:-2])
    np.testing.assert_array_equal(np.column_stack([res["filter.xf[1]"], res["filter.xf[2]"]]),
                                  np.column_stack([master["filter.xf[1]"], master["filter.xf[2]"]])[:-1])


def test_string_parameters_libcosim_applies_them_fmpy_cannot(fmus, tmp_path):
    comps = _components(fmus, h=1.0, kind="constant", offset=[0.25])
    path = write_ssp(tmp_path / "const.ssp", comps, CONNECTIONS, step_size=1.0, stop_time=3.0)
    res = simulate_ssp(path, importer="libcosim")
    np.testing.assert_array_equal(res["sched.p[1]"], [0.25, 0.25, 0.25])
    with pytest.raises(CoSimulationError, match=r"fmpy's simulate_ssp cannot set the String parameter "
                                                r"sched\.kind = 'constant'"):
        simulate_ssp(path, importer="fmpy")
    # a String value equal to the FMU's start value needs no setting: fmpy runs
    same = write_ssp(tmp_path / "same.ssp", _components(fmus, h=1.0, kind="sinusoid"), CONNECTIONS, step_size=1.0,
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
    assert main(["cosim", str(example), "--fmus", str(fmus.out), "--ssp", str(out)]) == 0  # its own: replaced
    other = tmp_path / "ex.toml"
    other.write_text("a file given by mistake\n")
    assert main(["cosim", str(example), "--fmus", str(fmus.out), "--ssp", str(other)]) == 2
    from lpvest.core._errors import shorten

    assert capsys.readouterr().err.endswith(f"--ssp {shorten(str(other), 60)}: exists and is not an SSP file (only "
                                            "one is replaced); "
                                            "remove it or choose another name\n")
    assert other.read_text() == "a file given by mistake\n"
    assert ("omega[1]", "Real", "0.25") in system.parameters["sched"]
    assert simulate_ssp(out, importer="fmpy", n_steps=5).shape == (5,)


def test_the_command_line_declares_libcosims_worker_threads(fmus, tmp_path, capsys):
    from pathlib import Path

    example = Path(__file__).resolve().parent.parent / "examples" / "peixoto_ex1_hinf.toml"
    base = ["cosim", str(example), "--fmus", str(fmus.out)]
    for given, declared, said in (([], 0, "in libcosim's calling thread"), (["--worker-threads", "2"], 2,
                                  "on 2 libcosim threads"), (["--worker-threads", "none"], None,
                                                              "on libcosim's default thread pool")):
        out = tmp_path / f"{declared}.ssp"
        assert main([*base, "--ssp", str(out), *given]) == 0
        assert f", FMUs stepped {said}\n" in capsys.readouterr().out
        assert read_ssp(out).worker_threads == declared
    with pytest.raises(SystemExit) as info:
        main([*base, "--ssp", str(tmp_path / "bad.ssp"), "--worker-threads", "-1"])
    assert info.value.code == 2
    assert ("argument --worker-threads: expected 0 (the calling thread), a number of threads, or none; found '-1'"
            in capsys.readouterr().err)
    assert main([*base, "--worker-threads", "0", "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err == ("lpvest: error: --worker-threads sets the threads libcosim steps the FMUs of "
                                       "an SSP file on: give it with --ssp\n")
    assert not (tmp_path / "bad.ssp").exists() and not (tmp_path / "run").exists()


def test_the_readme_numbers_for_the_example_file(fmus, tmp_path):
    """README, SSP export: on examples/peixoto_ex1_hinf.toml fmpy and libcosim
    agree; ||z - zhat|| / ||w|| (each estimate against the z of its own sample)
    is 1.07 with our master, 1.60 with Jacobi stepping and the measurement taken
    as it comes (certified gamma = 1.21), and 1.07 again, our master's estimates
    to the bit, with the file as written (measurement_delay = 1)."""
    from pathlib import Path

    from lpvest.cosim._cosimfile import load_cosim

    spec = load_cosim(Path(__file__).resolve().parent.parent / "examples" / "peixoto_ex1_hinf.toml",
                      fmu_dir=fmus.out)
    m = spec.run().data
    w = np.linalg.norm(m["src.w[1]"])
    z = np.column_stack([m[f"plant.z[{i}]"] for i in (1, 2)])
    zhat_master = np.column_stack([m[f"filter.zhat[{i}]"] for i in (1, 2)])
    assert np.linalg.norm(z - zhat_master) / w == pytest.approx(1.07, abs=0.005)
    as_is = write_ssp(tmp_path / "as_is.ssp", spec.components, spec.connections, step_size=spec.step_size,
                      stop_time=spec.stop_time, jacobi=False)
    paired = spec.to_ssp(tmp_path / "example.ssp")
    for path, late in ((as_is, 0), (paired, 1)):
        f, lc = simulate_ssp(path, importer="fmpy"), simulate_ssp(path, importer="libcosim")
        for name in lc.dtype.names:
            np.testing.assert_array_equal(f[name], lc[name], err_msg=name)
        zhat = np.column_stack([lc[f"filter.zhat[{i}]"] for i in (1, 2)])
        if late:  # the estimate of sample k is read after step k + 1: against z_k
            np.testing.assert_array_equal(zhat[1:], zhat_master[:-2])
            assert np.linalg.norm(z[:-2] - zhat[1:]) / w == pytest.approx(1.07, abs=0.005)
        else:  # read after step k, from (theta_k, y_(k-1)): against z_k
            assert np.linalg.norm(z[:-1] - zhat) / w == pytest.approx(1.60, abs=0.005)
    with zipfile.ZipFile(fmus["PeixotoEx1HinfPD"]) as z_:
        assert HinfDesign.from_json(z_.read("resources/design.json").decode()).gamma == pytest.approx(1.21, abs=0.005)


def _paper_system(fmus, example: int, **filter_params) -> tuple[list[Component], list[str]]:
    """Figs. 1-2 of Peixoto et al. (theta_k = sin(0.25 k), w_k = sin(0.5 k) exp(-0.1 k)
    from k = 10, x_0 = 0) for Example 1 or 2 (rho = 1) with both H-infinity filters."""
    ex = f"PeixotoEx{example}"
    comps = [
        Component("sched", fmus[f"{ex}Scheduler"], {"kind": "sinusoid", "offset": [0.0], "amplitude": [1.0],
                                                    "omega": [0.25]}),
        Component("src", fmus[f"{ex}Source"], {"w.kind": "decaying", "w.amplitude": [1.0], "w.omega": [0.5],
                                               "w.decay": [0.1], "w.onset": 10.0}),
        Component("plant", fmus[f"{ex}Plant"]),
        Component("pd", fmus[f"{ex}HinfPD"], dict(filter_params)),
        Component("robust", fmus[f"{ex}HinfRobust"], dict(filter_params)),
    ]
    conns = ["sched.p -> plant.p", "src.w -> plant.w", "sched.p -> pd.p", "plant.y -> pd.y", "plant.y -> robust.y"]
    return comps, conns


@pytest.mark.parametrize("example", [1, 2])
def test_the_certified_bound_holds_under_jacobi_importers_with_the_delay(fmus, tmp_path, example, capsys):
    """Peixoto et al. Examples 1 and 2, both filters, under libcosim and fmpy's
    simulate_ssp: with the file as written (measurement_delay = 1) every
    estimate is our master's estimate of its own sample, to the bit (both
    importers: theta_0 = w_0 = x_0 = 0, so fmpy's 0.0 before the first step is
    the sample itself), and ||z - zhat|| / ||w|| <= gamma, each estimate against
    the z of its own sample and w over the samples estimated. Without the delay
    (jacobi=False) the ratios are printed next to them: the table of the issue."""
    steps = 100
    comps, conns = _paper_system(fmus, example)
    record = ["src.w", "plant.z", "pd.zhat", "robust.zhat"]
    with CoSimulation(comps, conns, step_size=1.0, record=record) as sim:
        m = sim.run(steps - 1)  # samples 0 .. steps - 1
    nz = sum(n.startswith("plant.z[") for n in m.dtype.names)

    def cols(res, base):
        return np.column_stack([res[f"{base}[{i + 1}]"] for i in range(nz)])

    z = cols(m, "plant.z")
    w = m["src.w[1]"]
    gammas = {}
    for f, role in (("pd", "HinfPD"), ("robust", "HinfRobust")):
        with zipfile.ZipFile(fmus[f"PeixotoEx{example}{role}"]) as zf:
            gammas[f] = HinfDesign.from_json(zf.read("resources/design.json").decode()).gamma
    ratio = {("master", f, 0): np.linalg.norm(z - cols(m, f"{f}.zhat")) / np.linalg.norm(w) for f in gammas}
    for jacobi in (False, True):
        path = write_ssp(tmp_path / f"ex{example}_{jacobi}.ssp", comps, conns, step_size=1.0, stop_time=float(steps),
                         jacobi=jacobi)
        for importer in ("libcosim", "fmpy"):
            res = simulate_ssp(path, importer=importer)
            np.testing.assert_array_equal(cols(res, "plant.z"), z)  # row k: z_k, held after step k
            for f, gamma in gammas.items():
                zhat = cols(res, f"{f}.zhat")
                if jacobi:  # row k + 1: the estimate of sample k
                    assert np.array_equal(zhat[0], np.zeros(nz))
                    np.testing.assert_array_equal(zhat[1:], cols(m, f"{f}.zhat")[:-1], err_msg=f"{importer} {f}")
                    r = np.linalg.norm(z[:-1] - zhat[1:]) / np.linalg.norm(w[:-1])
                    assert r <= gamma, (importer, f, r, gamma)
                else:  # row k: from (theta_k, y_(k-1))
                    r = np.linalg.norm(z - zhat) / np.linalg.norm(w)
                ratio[(importer, f, int(jacobi))] = r
    with capsys.disabled():
        print(f"\nPeixoto Example {example}: ||z - zhat|| / ||w||")
        for f, gamma in gammas.items():
            print(f"  {f:<7} gamma {gamma:.4f}  master {ratio[('master', f, 0)]:.4f}  " + "  ".join(
                f"{imp} delay {d}: {ratio[(imp, f, d)]:.4f}" for imp in ("libcosim", "fmpy") for d in (0, 1)))


def test_what_the_writer_binds_for_a_jacobi_importer(fmus, tmp_path):
    """measurement_delay = 1 for a filter whose measurement comes from a
    feedthrough output of a discrete-time FMU; nothing with jacobi=False, for a
    measurement from an FMU without feedthrough, or when the caller set it; a
    filter whose measurement or scheduling would arrive partly late cannot be
    paired by the parameter: a one-line error naming it."""
    comps = _components(fmus)

    def bound(path):
        return {c: dict((n, v) for n, _, v in vals) for c, vals in read_ssp(path).parameters.items()}

    assert bound(write_ssp(tmp_path / "a.ssp", comps, CONNECTIONS, step_size=H))["filter"][DELAY] == "1"
    assert DELAY not in bound(write_ssp(tmp_path / "b.ssp", comps, CONNECTIONS, step_size=H, jacobi=False))["filter"]
    # y recorded from a source (no feedthrough): in time
    recorded = ["sched.p -> filter.p", "src.w -> filter.y"]
    assert DELAY not in bound(write_ssp(tmp_path / "c.ssp", comps, recorded, step_size=H))["filter"]
    explicit = [*comps[:3], Component("filter", comps[3].fmu, {"sample_time": H, DELAY: 0})]
    assert bound(write_ssp(tmp_path / "d.ssp", explicit, CONNECTIONS, step_size=H))["filter"][DELAY] == "0"
    # the scheduling from a feedthrough output too: late as well, and no delay of y pairs that
    late_p = ["sched.p -> plant.p", "src.w -> plant.w", "plant.y -> filter.p", "plant.y -> filter.y"]
    with pytest.raises(CoSimulationError, match=r"^component filter: under Jacobi stepping y\[1\] would arrive one "
                                                r"sample late and p\[1\] would arrive one sample late too: no "
                                                r"measurement_delay pairs them; set measurement_delay in the "
                                                r"component's parameters to write the file anyway$"):
        write_ssp(tmp_path / "e.ssp", comps, late_p, step_size=H)
    assert not (tmp_path / "e.ssp").exists()
    # a two-element measurement, one element late and one in time
    two = [Component("src", fmus["CoxTothTruncationSource"]), Component("plant", fmus["CoxTothTruncationPlant"]),
           Component("kf", fmus["CoxTothTruncationKalman"])]
    mixed = ["plant.y[1] -> kf.y[1]", "src.u -> kf.y[2]"]
    with pytest.raises(CoSimulationError, match=r"component kf: under Jacobi stepping y\[1\] would arrive one "
                                                r"sample late and y\[2\] would arrive in time"):
        write_ssp(tmp_path / "f.ssp", two, mixed, step_size=1.0)


@pytest.mark.parametrize("importer", ["fmpy", "libcosim"])
def test_a_communication_step_of_two_samples_under_each_importer(fmus, tmp_path, master, library, importer):
    """The file's step is two samples of the plant and the filter: every FMU
    step runs two samples with the inputs held (zero-order hold), the filter
    pairing its measurement one sample late, as the library's Jacobi stepping
    with m = 2 predicts."""
    n = N // 2
    path = write_ssp(tmp_path / "two.ssp", _components(fmus), CONNECTIONS, step_size=2 * H, stop_time=n * 2 * H)
    res = simulate_ssp(path, importer=importer)
    assert res.shape == (n,)
    if importer == "fmpy":
        first = {"p": 0.0, "w": 0.0, "y": 0.0}
    else:
        first = {"p": master["sched.p[1]"][0], "w": master["src.w[1]"][0], "y": master["plant.y[1]"][0]}
    pred = _jacobi(library, first, delay=1, m=2, n=n)
    for name, values in pred.items():
        # as in test_each_importer_runs_the_file_as_jacobi_stepping_predicts, over 2 n samples
        tol = roundoff(float(np.max(np.abs(values))), 2 * n, n=4)
        np.testing.assert_allclose(res[name], values, rtol=0, atol=tol, err_msg=f"{importer}: {name}")


# -- reading an SSP file that is not ours (issue 12) ------------------------------------------------

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations" name="s" version="1.0">
  <ssd:System name="s">
    <ssd:Elements>
      <ssd:Component name="plant" source="SOURCE" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors><ssd:Connector name="y[1]" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="plant"><ssv:Parameters>
            <ssv:Parameter name="seed"><ssv:Integer value="SEED"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="STOP">
    <ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">
      <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="STEP"/></osp:Algorithm>
    </ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def _ssp_file(tmp_path, source="resources/Plant.fmu", seed="3", stop="10.0", step="1.0", members=None, threads=None):
    path = tmp_path / "hand.ssp"
    ssd = SSD.replace("SOURCE", source).replace("SEED", seed).replace("STOP", stop).replace("STEP", step)
    if threads is not None:
        ssd = ssd.replace(f'baseStepSize="{step}"', f'baseStepSize="{step}" numWorkerThreads="{threads}"')
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        for m in members if members is not None else ["resources/Plant.fmu"]:
            z.writestr(m, b"not read")
    return path


def test_a_hand_written_ssp_file_is_read(tmp_path):
    system = read_ssp(_ssp_file(tmp_path))
    assert system.components == {"plant": "resources/Plant.fmu"}
    assert system.parameters == {"plant": [("seed", "Integer", "3")]}
    assert (system.step_size, system.start_time, system.stop_time) == (1.0, 0.0, 10.0)
    assert system.worker_threads is None  # not declared: libcosim's default pool
    assert read_ssp(_ssp_file(tmp_path, threads=" 2 ")).worker_threads == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        # libcosim unpacks the archive and opens the source: '..' would reach outside its folder
        ({"source": "../evil.fmu", "members": ["../evil.fmu"]},
         r"component 'plant': source '\.\./evil\.fmu' is not a relative path inside the archive"),
        ({"source": "resources/../../evil.fmu"},
         r"component 'plant': source 'resources/\.\./\.\./evil\.fmu' is not a relative path"),
        ({"source": "/etc/evil.fmu"},
         r"component 'plant': source '/etc/evil\.fmu' is not a relative path inside the archive"),
        ({"source": "C:/evil.fmu"},
         r"component 'plant': source 'C:/evil\.fmu' is not a relative path inside the archive"),
        ({"source": "resources/Other.fmu"}, r"component 'plant': source 'resources/Other\.fmu' is not in the archive"),
        # a source is a URI reference, and libcosim decodes its percent-escapes
        # before it opens the file: checked after decoding (issue 19)
        ({"source": "%2e%2e/evil.fmu", "members": ["%2e%2e/evil.fmu"]},
         r"component 'plant': source '%2e%2e/evil\.fmu' \(decoded: '\.\./evil\.fmu'\) is not a relative path inside "
         r"the archive \(no '\.\.', no absolute path\)"),
        ({"source": "resources/%2E%2E/%2e%2e/evil.fmu", "members": ["resources/%2E%2E/%2e%2e/evil.fmu"]},
         r"component 'plant': source 'resources/%2E%2E/%2e%2e/evil\.fmu' \(decoded: 'resources/\.\./\.\./evil\.fmu'\) "
         r"is not a relative path"),
        ({"source": "resources/%252e%252e/%252e%252e/evil.fmu", "members": ["resources/%2e%2e/%2e%2e/evil.fmu"]},
         r"component 'plant': source 'resources/%252e%252e/%252e%252e/evil\.fmu' \(decoded: "
         r"'resources/\.\./\.\./evil\.fmu'\) is not a relative path"),  # safe for an importer that decodes twice
        ({"source": "..%2fevil.fmu", "members": ["../evil.fmu"]},
         r"component 'plant': source '\.\.%2fevil\.fmu' has a percent-escape that decodes to a path separator"),
        ({"source": "resources%5CPlant.fmu"},
         r"component 'plant': source 'resources%5CPlant\.fmu' has a percent-escape that decodes to a path separator"),
        ({"source": "resources/Pl%zzant.fmu"},
         r"component 'plant': source 'resources/Pl%zzant\.fmu' has a malformed percent-escape \(expected '%' and two "
         r"hexadecimal digits\)"),
        ({"source": "resources/%ff.fmu"}, r"component 'plant': source 'resources/%ff\.fmu' does not decode to UTF-8"),
        ({"source": "resources/My%20Plant.fmu", "members": ["resources/My%20Plant.fmu"]},
         r"component 'plant': source 'resources/My%20Plant\.fmu' \(decoded: 'resources/My Plant\.fmu'\) is not in the "
         r"archive"),
        ({"seed": "inf"}, r"component 'plant': parameter 'seed': expected an integer, found 'inf'"),
        ({"seed": "99999999999"},
         r"component 'plant': parameter 'seed': 99999999999 is outside the range of an FMI Integer"),
        ({"stop": "soon"}, r"DefaultExperiment stopTime: expected a number, found 'soon'"),
        ({"step": "-1"}, r"FixedStepAlgorithm baseStepSize: expected a positive number, found -1\.0"),
        ({"step": "nan"}, r"FixedStepAlgorithm baseStepSize: expected a positive number, found nan"),
        # libcosim reads an unsigned int and takes what it cannot parse (and -1) as its default pool, silently
        ({"threads": "-1"}, r"FixedStepAlgorithm numWorkerThreads: expected a whole number, found '-1'"),
        ({"threads": "1.5"}, r"FixedStepAlgorithm numWorkerThreads: expected a whole number, found '1\.5'"),
        ({"threads": "+2"}, r"FixedStepAlgorithm numWorkerThreads: expected a whole number, found '\+2'"),
        ({"threads": "1_000"}, r"FixedStepAlgorithm numWorkerThreads: expected a whole number, found '1_000'"),
        ({"threads": ""}, r"FixedStepAlgorithm numWorkerThreads: expected a whole number, found ''"),
        ({"threads": "4294967296"},
         r"FixedStepAlgorithm numWorkerThreads: expected a number from 0 to 2147483647, found 4294967296"),
    ],
)
def test_an_unsafe_or_malformed_ssp_file_is_one_line_naming_it(tmp_path, change, message):
    path = _ssp_file(tmp_path, **change)
    with pytest.raises(CoSimulationError, match=f"^{path}: {message}") as info:
        read_ssp(path)
    assert "\n" not in str(info.value)


def test_a_percent_encoded_source_names_the_decoded_member(tmp_path):
    system = read_ssp(_ssp_file(tmp_path, source="resources/My%20Plant.fmu", members=["resources/My Plant.fmu"]))
    assert system.components == {"plant": "resources/My Plant.fmu"}
    assert system.sources == {"plant": "resources/My%20Plant.fmu"}


def test_libcosim_is_never_given_a_source_outside_the_archive(tmp_path):
    """read_ssp accepted '%2e%2e/...' (not '..' as written), and libcosim,
    which decodes it, ran an FMU from outside the archive (issue 19)."""
    path = _ssp_file(tmp_path, source="%2e%2e/evil.fmu", members=["%2e%2e/evil.fmu"])
    with pytest.raises(CoSimulationError, match=rf"^{path}: component 'plant': source '%2e%2e/evil\.fmu' \(decoded: "
                                                r"'\.\./evil\.fmu'\) is not a relative path inside the archive"):
        simulate_ssp(path, importer="libcosim")


def test_an_ssp_file_that_is_not_a_zip_archive(tmp_path):
    path = tmp_path / "x.ssp"
    path.write_bytes(b"\x00\x01junk")
    with pytest.raises(CoSimulationError, match=f"^{path}: not an SSP file with a SystemStructure.ssd: "):
        read_ssp(path)


def test_an_xml_declaration_with_an_unknown_encoding(tmp_path):
    # found by tests/test_properties.py: ElementTree raised LookupError
    path = _ssp_file(tmp_path)
    with zipfile.ZipFile(path) as z:
        ssd = z.read("SystemStructure.ssd").replace(b'encoding="UTF-8"', b'encoding="nan"')
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
    with pytest.raises(CoSimulationError, match=f"^{path}: not an SSP file with a SystemStructure.ssd: unknown "
                                                "encoding: nan$"):
        read_ssp(path)


# -- FMUs with every type, files of other tools (issue 19) -------------------------------------------------

FH = 0.5  # a power of two: every value below is exact
FN = 6


def _rewrite_ssd(path, change):
    """Apply ``change`` to the root of the SSP's SystemStructure.ssd, in place."""
    import xml.etree.ElementTree as ET

    from lpvest.cosim._ssp import NS

    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    root = ET.fromstring(members["SystemStructure.ssd"])
    change(root, NS)
    members["SystemStructure.ssd"] = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _keep_connectors(keep):
    """A change of the SSD: each component declares only the connectors in ``keep``, as another tool may write
    it (fmpy's simulate_ssp needs every declared input connected; it cannot exchange Strings; libcosim cannot
    read an Enumeration)."""

    def change(root, ns):
        for comp in root.findall("ssd:System/ssd:Elements/ssd:Component", ns):
            conns = comp.find("ssd:Connectors", ns)
            for c in list(conns):
                if c.get("name") not in keep[comp.get("name")]:
                    conns.remove(c)

    return change


def _typed_system(foreign_fmus, tmp_path, importer, *, extras=True):
    """lim -> a -> b (tests/foreign_fmus.py) with Real, Integer and Boolean connections; with ``extras``, for
    fmpy an Enumeration parameter and output too, for libcosim String outputs."""
    a_params = {"gain": 3.0, "offset": -2, "invert": True}
    keep = {"lim": ["time_out", "counter"],
            "a": ["real_in", "int_in", "real_out", "int_out", "bool_out", "steps"],
            "b": ["real_in", "int_in", "bool_in", "real_out", "int_out", "bool_out", "steps"]}
    if extras and importer == "fmpy":
        a_params["floor_level"] = "mid"
        keep["a"].append("enum_out")
    elif extras:
        keep["a"].append("string_out")
        keep["b"].append("string_out")
    comps = [Component("lim", foreign_fmus["Limited"], {"last": 100}),
             Component("a", foreign_fmus["AllTypes"], a_params), Component("b", foreign_fmus["AllTypes"])]
    conns = ["lim.time_out -> a.real_in", "lim.counter -> a.int_in", "a.real_out -> b.real_in",
             "a.int_out -> b.int_in", "a.bool_out -> b.bool_in"]
    path = write_ssp(tmp_path / f"typed-{importer}.ssp", comps, conns, step_size=FH, stop_time=FN * FH)
    return _rewrite_ssd(path, _keep_connectors(keep))


@pytest.mark.parametrize("importer", ["fmpy", "libcosim"])
def test_outputs_of_every_type_are_read_with_their_own_type(foreign_fmus, tmp_path, importer):
    """Integer, Boolean and Enumeration outputs come out as numbers of their
    own variables. AllTypes' value references overlap across types: libcosim's
    real-valued read of the Integer output int_out (reference 2) returned the
    Real output real_out (reference 2) before. String outputs are left out,
    as the master leaves them out."""
    res = simulate_ssp(_typed_system(foreign_fmus, tmp_path, importer), importer=importer)
    names = ["lim.counter", "lim.time_out", "a.real_out", "a.int_out", "a.steps"]  # the FMUs' order
    names += ["a.enum_out", "a.bool_out"] if importer == "fmpy" else ["a.bool_out"]
    names += ["b.real_out", "b.int_out", "b.steps", "b.bool_out"]
    assert res.dtype.names == ("time", *names)
    # Jacobi (module documentation): row k is read after step k, whose inputs
    # were read after step k - 1; before the first step fmpy feeds 0 into every
    # input, libcosim the outputs at t_0 propagated
    t = np.arange(FN + 1) * FH  # t_0 .. t_N
    t_k = t[:-1]
    np.testing.assert_array_equal(res["time"], t[1:])
    np.testing.assert_array_equal(res["lim.time_out"], t[1:])
    np.testing.assert_array_equal(res["lim.counter"], np.floor(t[1:]))
    np.testing.assert_array_equal(res["a.real_out"], 3.0 * t_k)          # gain * time_out(t_k)
    np.testing.assert_array_equal(res["a.int_out"], np.floor(t_k) - 2)   # counter(t_k) + offset
    np.testing.assert_array_equal(res["a.bool_out"], np.ones(FN))        # false xor invert
    np.testing.assert_array_equal(res["a.steps"], np.arange(1.0, FN + 1))
    first_int, first_bool = (0.0, 0.0) if importer == "fmpy" else (-2.0, 1.0)
    np.testing.assert_array_equal(res["b.real_out"], 2.0 * np.concatenate([[0.0], res["a.real_out"][:-1]]))
    np.testing.assert_array_equal(res["b.int_out"], np.concatenate([[first_int], res["a.int_out"][:-1]]) + 1)
    np.testing.assert_array_equal(res["b.bool_out"], np.concatenate([[first_bool], res["a.bool_out"][:-1]]))
    if importer == "fmpy":
        np.testing.assert_array_equal(res["a.enum_out"], np.full(FN, 2.0))  # the bound item 'mid' applied


def test_enumerations_in_the_file_and_what_each_importer_makes_of_them(foreign_fmus, tmp_path):
    from fmpy.ssp.ssd import read_ssd

    comps = [Component("a", foreign_fmus["AllTypes"], {"floor_level": "high"}),
             Component("b", foreign_fmus["AllTypes"])]
    path = write_ssp(tmp_path / "enum.ssp", comps, ["a.enum_out -> b.enum_in"], step_size=FH, stop_time=FN * FH)
    read_ssd(str(path), validate=True)  # valid against SSP 1.0's schema (fmpy's copy)
    with zipfile.ZipFile(path) as z:
        xml = z.read("SystemStructure.ssd").decode()
    # SSP 1.0: a parameter value by item name, the type in the SSD's Enumerations
    assert '<ssv:Enumeration value="high" name="Level" />' in xml
    assert '<ssc:Enumeration name="Level" />' in xml
    assert ('<ssc:Enumeration name="Level">\n      <ssc:Item name="low" value="1" />\n      '
            '<ssc:Item name="mid" value="2" />\n      <ssc:Item name="high" value="3" />') in xml
    assert read_ssp(path).parameters["a"] == [("floor_level", "Enumeration", "high")]
    # libcosim's SSP parser aborts its process on an Enumeration; fmpy has no String calls
    with pytest.raises(CoSimulationError, match=rf"^{path}: component a: connector 'enum_in': libcosim does not see "
                                                r"Enumeration variables; run this file with fmpy$"):
        simulate_ssp(path, importer="libcosim")
    with pytest.raises(CoSimulationError, match=rf"^{path}: component a: connector 'string_in': fmpy's simulate_ssp "
                                                r"cannot exchange String variables; run this file with libcosim$"):
        simulate_ssp(path, importer="fmpy")
    # without the String connectors fmpy runs it, but feeds 0 into every input
    # before the first step: not an item of Level, and the FMU says so (one line)
    _rewrite_ssd(path, _keep_connectors({"a": ["enum_out"], "b": ["enum_in", "enum_out"]}))
    with pytest.raises(CoSimulationError, match=rf"^{path}: fmpy's simulate_ssp failed: FMICallException: "
                                                r"fmi2SetInteger failed with status 3 \(error\)\.$"):
        simulate_ssp(path, importer="fmpy")


def test_a_failing_fmpy_run_leaves_no_extracted_file_or_fmu(foreign_fmus, tmp_path, monkeypatch):
    """fmpy's simulate_ssp removes its extractions of the file and of each FMU only when the
    run succeeds: the failing run of the test above left three folders in the temporary
    folder every time (two FMUs and the file). lpvest removes what a failed run left;
    a run on another thread is not touched."""
    import tempfile
    import threading

    comps = [Component("a", foreign_fmus["AllTypes"], {"floor_level": "high"}),
             Component("b", foreign_fmus["AllTypes"])]
    path = write_ssp(tmp_path / "enum.ssp", comps, ["a.enum_out -> b.enum_in"], step_size=FH, stop_time=FN * FH)
    _rewrite_ssd(path, _keep_connectors({"a": ["enum_out"], "b": ["enum_in", "enum_out"]}))
    ok = write_ssp(tmp_path / "ok.ssp", comps[:1], [], step_size=FH, stop_time=FN * FH)
    _rewrite_ssd(ok, _keep_connectors({"a": ["enum_out"]}))
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    for _ in range(2):
        with pytest.raises(CoSimulationError, match="fmpy's simulate_ssp failed: FMICallException"):
            simulate_ssp(path, importer="fmpy")
        assert sorted(os.listdir(scratch)) == []
    assert simulate_ssp(ok, importer="fmpy").shape == (FN,)
    assert sorted(os.listdir(scratch)) == []
    # a run inside another on this thread (an FMU whose step runs an SSP file) hands the
    # recording back to the outer run, with the outer run's folders untouched
    from lpvest.cosim import _ssp

    outer = ["the outer run's folder"]
    _ssp._FMPY_EXTRACTIONS.made = outer
    try:
        with pytest.raises(CoSimulationError, match="fmpy's simulate_ssp failed"):
            simulate_ssp(path, importer="fmpy")
        assert _ssp._FMPY_EXTRACTIONS.made is outer and outer == ["the outer run's folder"]
    finally:
        _ssp._FMPY_EXTRACTIONS.made = None
    assert sorted(os.listdir(scratch)) == []
    # fmpy's extract outside lpvest's call (another thread, plain fmpy) keeps what it made
    import fmpy.ssp.simulation

    made = []
    thread = threading.Thread(target=lambda: made.append(fmpy.ssp.simulation.extract(ok)))
    thread.start()
    thread.join()
    assert [os.path.basename(str(made[0]))] == os.listdir(scratch)


def _add_connector(component, name, kind, typ):
    def change(root, ns):
        import xml.etree.ElementTree as ET

        for comp in root.findall("ssd:System/ssd:Elements/ssd:Component", ns):
            if comp.get("name") == component:
                c = ET.SubElement(comp.find("ssd:Connectors", ns), f"{{{ns['ssd']}}}Connector",
                                  {"name": name, "kind": kind})
                ET.SubElement(c, f"{{{ns['ssc']}}}{typ}")

    return change


def _add_parameter(component, name, typ, value):
    def change(root, ns):
        import xml.etree.ElementTree as ET

        for comp in root.findall("ssd:System/ssd:Elements/ssd:Component", ns):
            if comp.get("name") == component:
                params = comp.find("ssd:ParameterBindings/ssd:ParameterBinding/ssd:ParameterValues/"
                                   "ssv:ParameterSet/ssv:Parameters", ns)
                p = ET.SubElement(params, f"{{{ns['ssv']}}}Parameter", {"name": name})
                ET.SubElement(p, f"{{{ns['ssv']}}}{typ}", {"value": value})

    return change


@pytest.mark.parametrize("importer", ["fmpy", "libcosim"])
@pytest.mark.parametrize(
    ("change", "message"),
    [
        # fmpy raised a raw KeyError for these two
        (_add_connector("lim", "y[3]", "output", "Real"),
         r"component lim: connector 'y\[3\]' \(output\): its FMU resources/Limited\.fmu has no variable 'y\[3\]'"),
        (_add_parameter("a", "gain2", "Real", "1.0"),
         r"component a: parameter 'gain2': its FMU resources/AllTypes\.fmu has no variable 'gain2'"),
        (_add_connector("lim", "u", "output", "Real"),
         r"component lim: connector 'u' has kind output, but the FMU's variable has causality input"),
        (_add_connector("b", "steps", "output", "Real"),
         r"component b: connector 'steps' is declared Real, but the FMU's variable has type Integer"),
        (_add_parameter("a", "offset", "Real", "1.5"),
         r"component a: parameter 'offset' is given as Real, but the FMU's variable has type Integer"),
    ],
)
def test_a_connector_or_parameter_the_fmu_lacks_is_one_line_naming_both(foreign_fmus, tmp_path, importer, change,
                                                                         message):
    path = _typed_system(foreign_fmus, tmp_path, importer)
    # libcosim's file keeps String outputs, fmpy's an Enumeration output: neither matters here
    _rewrite_ssd(path, change)
    with pytest.raises(CoSimulationError, match=f"^{path}: {message}$") as info:
        simulate_ssp(path, importer=importer)
    assert "\n" not in str(info.value)


def test_a_connection_to_an_undeclared_connector_is_refused_when_read(foreign_fmus, tmp_path):
    path = _typed_system(foreign_fmus, tmp_path, "libcosim")
    _rewrite_ssd(path, _keep_connectors({"lim": ["time_out"], "a": ["real_in", "real_out", "int_out", "bool_out"],
                                         "b": ["real_in", "int_in", "bool_in"]}))
    with pytest.raises(CoSimulationError, match=rf"^{path}: connection 2: component 'lim' has no connector 'counter'$"):
        read_ssp(path)


def test_fmpy_is_not_given_an_unconnected_input(foreign_fmus, tmp_path):
    """fmpy's simulate_ssp wires an input connector without a connection to the
    source of the connection it looked at before (l1.u got l1.time_out), or
    fails with UnboundLocalError: refused in one line; libcosim leaves it at its
    start value."""
    comps = [Component("l2", foreign_fmus["Limited"]), Component("l1", foreign_fmus["Limited"])]
    path = write_ssp(tmp_path / "two.ssp", comps, ["l1.time_out -> l2.u"], step_size=FH, stop_time=FN * FH)
    with pytest.raises(CoSimulationError, match=rf"^{path}: component l1: input connector 'u' is not connected, "
                                                r"and fmpy's simulate_ssp would feed it another connection's value; "
                                                r"connect it, or run this file with libcosim$"):
        simulate_ssp(path, importer="fmpy")
    res = simulate_ssp(path, importer="libcosim")
    np.testing.assert_array_equal(res["l1.y"], np.zeros(FN))
    np.testing.assert_array_equal(res["l2.y"], np.arange(FN) * FH)  # l1's time at the start of each step


def test_the_same_system_gives_a_byte_identical_file(foreign_fmus, tmp_path):
    import os

    fmu = tmp_path / "Limited.fmu"
    fmu.write_bytes(foreign_fmus["Limited"].read_bytes())
    comps = [Component("lim", fmu, None), Component("a", foreign_fmus["AllTypes"], {"floor_level": "mid"})]
    first = write_ssp(tmp_path / "1.ssp", comps, ["lim.time_out -> a.real_in"], step_size=FH, stop_time=3.0)
    stat = fmu.stat()
    os.utime(fmu, ns=(stat.st_atime_ns, stat.st_mtime_ns + 86_400 * 10**9))  # the FMU copied a day later
    second = write_ssp(tmp_path / "2.ssp", comps, ["lim.time_out -> a.real_in"], step_size=FH, stop_time=3.0)
    assert first.read_bytes() == second.read_bytes()
    with zipfile.ZipFile(first) as z:
        assert {i.date_time for i in z.infolist()} == {(1980, 1, 1, 0, 0, 0)}  # no clock, no file time
        assert z.namelist() == ["SystemStructure.ssd", "resources/Limited.fmu", "resources/AllTypes.fmu"]


# -- libcosim's worker threads (issue 20) --------------------------------------------------------------


def _two_limited(foreign_fmus, tmp_path, name, **kwargs):
    """Two unconnected Limited FMUs (no Enumeration: libcosim reads them)."""
    comps = [Component("l1", foreign_fmus["Limited"], None), Component("l2", foreign_fmus["Limited"], None)]
    return write_ssp(tmp_path / name, comps, [], step_size=FH, stop_time=FN * FH, **kwargs)


@pytest.mark.parametrize("threads", ["default", 0, 3, None])
def test_the_worker_threads_are_declared_for_libcosim_and_read_back(foreign_fmus, tmp_path, threads):
    from fmpy.ssp.ssd import read_ssd

    path = _two_limited(foreign_fmus, tmp_path, "t.ssp", **({} if threads == "default" else
                                                             {"worker_threads": threads}))
    with zipfile.ZipFile(path) as z:
        xml = z.read("SystemStructure.ssd").decode()
    declared = 0 if threads == "default" else threads  # lpvest's FMUs step fastest in the calling thread
    if declared is None:
        assert "numWorkerThreads" not in xml
    else:
        assert f'<osp:FixedStepAlgorithm baseStepSize="0.5" numWorkerThreads="{declared}" />' in xml
    assert read_ssp(path).worker_threads == declared
    read_ssd(str(path), validate=True)  # still valid SSP 1.0 (fmpy's copy of the schema)


@pytest.mark.parametrize("threads", [-1, 1.5, True, "0", 2**31, np.float64(1.0)])
def test_worker_threads_that_are_not_a_whole_number_are_refused(foreign_fmus, tmp_path, threads):
    import re

    with pytest.raises(CoSimulationError, match=r"^worker_threads must be None or a whole number from 0 to "
                                                rf"2147483647; found {re.escape(repr(threads))}$") as info:
        _two_limited(foreign_fmus, tmp_path, "bad.ssp", worker_threads=threads)
    assert info.value.where == "worker_threads"
    assert not (tmp_path / "bad.ssp").exists()


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts the process's threads in /proc (Linux)")
def test_libcosim_makes_the_pool_the_file_declares(foreign_fmus, tmp_path):
    """libcosim reads the attribute as write_ssp writes it: 0 makes no thread,
    and the FMI calls run in the thread that steps the execution; n makes
    min(n, cores - 1) threads, as does no declaration (libcosim's default)."""
    import subprocess
    import sys

    script = ("import os, sys, threading\n"
              "from libcosimpy.CosimExecution import CosimExecution\n"
              "from libcosimpy.CosimLogging import log_output_level, CosimLogLevel\n"
              "log_output_level(CosimLogLevel.ERROR)\n"
              "before = len(os.listdir('/proc/self/task'))\n"
              "ex = CosimExecution.from_ssp_file(sys.argv[1])\n"
              "assert ex.step(3)\n"
              "print('THREADS', len(os.listdir('/proc/self/task')) - before)\n")
    pool = max((os.cpu_count() or 1) - 1, 0)
    for threads, made in ((0, 0), (1, min(1, pool)), (None, pool)):
        path = _two_limited(foreign_fmus, tmp_path, f"{threads}.ssp", worker_threads=threads)
        proc = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, check=False,
                              timeout=120)
        assert proc.returncode == 0, proc.stderr[-500:]
        assert f"THREADS {made}\n" in proc.stdout, (threads, proc.stdout)


def test_the_calling_thread_and_the_pool_give_the_same_values_bit_for_bit(fmus, ssp, tmp_path):
    """The Peixoto system written with worker_threads=0 (the ``ssp`` fixture,
    checked against Jacobi stepping in
    test_each_importer_runs_the_file_as_jacobi_stepping_predicts) and with
    libcosim's default pool: libcosim steps both the same (Jacobi: no FMU
    sees another's output of the same step), and fmpy ignores the attribute."""
    pool = write_ssp(tmp_path / "pool.ssp", _components(fmus), CONNECTIONS, step_size=H, stop_time=N * H,
                     description="Peixoto et al. Example 1", worker_threads=None)
    assert (read_ssp(ssp).worker_threads, read_ssp(pool).worker_threads) == (0, None)
    for importer in ("libcosim", "fmpy"):
        serial, pooled = simulate_ssp(ssp, importer=importer), simulate_ssp(pool, importer=importer)
        assert serial.dtype.names == pooled.dtype.names
        for name in serial.dtype.names:
            np.testing.assert_array_equal(serial[name], pooled[name], err_msg=f"{importer}: {name}")


def test_a_percent_encoded_source_runs_in_libcosim_and_is_refused_by_fmpy(foreign_fmus, tmp_path):
    """libcosim decodes a source's escapes (so read_ssp checks the decoded
    name); fmpy opens it as written, so it cannot run such a file."""
    path = _typed_system(foreign_fmus, tmp_path, "libcosim", extras=False)
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    members["resources/Lim ited.fmu"] = members.pop("resources/Limited.fmu")
    members["SystemStructure.ssd"] = members["SystemStructure.ssd"].replace(
        b'source="resources/Limited.fmu"', b'source="resources/Lim%20ited.fmu"')
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    assert read_ssp(path).components["lim"] == "resources/Lim ited.fmu"
    np.testing.assert_array_equal(simulate_ssp(path, importer="libcosim")["lim.time_out"], np.arange(1, FN + 1) * FH)
    with pytest.raises(CoSimulationError, match=rf"^{path}: component lim: fmpy's simulate_ssp cannot open the "
                                                r"percent-encoded source 'resources/Lim%20ited\.fmu'; run this file "
                                                r"with libcosim$"):
        simulate_ssp(path, importer="fmpy")
