"""The FMUs in other hosts: libcosim, a fresh Python without lpvest, a long run,
and the command line that builds and validates them."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import venv
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lpvest import load_system
from lpvest.cli import main
from tests import libcosim_driver
from tests.conftest_fmu import AFFINE_TOML
from tests.kalman_helpers import kalman_fmu_tolerance
from tests.test_fmu import EXPECTED, paper_w, theta
from tests.tolerances import roundoff

ROOT = Path(__file__).resolve().parent.parent

# -- libcosim: a second, independent importer ---------------------------------------------


def _cosim_run(fmu_paths: dict[str, Path], steps: int, step_size: float, script: str) -> dict:
    """Run libcosim in a subprocess (it keeps FMU libraries loaded for good)."""
    code = textwrap.dedent(f"""
        import json, sys
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimSlave import CosimLocalSlave
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimLogging import log_output_level, CosimLogLevel
        log_output_level(CosimLogLevel.ERROR)
        paths = {json.dumps({k: str(v) for k, v in fmu_paths.items()})}
        ex = CosimExecution.from_step_size(step_size=int(round({step_size} * 1e9)))
        idx = {{name: ex.add_local_slave(CosimLocalSlave(fmu_path=p, instance_name=name))
               for name, p in paths.items()}}
        refs = {{name: {{v.name.decode(): v.reference for v in ex.slave_variables(i)}} for name, i in idx.items()}}
        obs = CosimObserver.create_last_value()
        ex.add_observer(obs)
    """) + textwrap.dedent(script) + textwrap.dedent(f"""
        ok = ex.step({steps})
        out = {{"ok": bool(ok), "values": {{}}}}
        for name, i in idx.items():
            names = sorted(refs[name])
            reals = [n for n in names if "[" in n]
            out["values"][name] = dict(zip(reals, obs.last_real_values(i, [refs[name][n] for n in reals])))
        print("RESULT" + json.dumps(out))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))
    return json.loads(line[len("RESULT"):])


def test_every_fmu_loads_and_steps_in_libcosim(fmus):
    """Every FMU, one libcosim execution after another in one process, twice
    over (the same FMU instantiated again after its execution ended), each
    with its own sample time (the default experiment's step)."""
    names = sorted(EXPECTED)
    result = libcosim_driver.load_and_step({n: fmus[n] for n in names})
    assert result == {f"{r}:{n}": True for r in range(2) for n in names}


def test_libcosim_connects_scheduler_source_and_plant_like_the_library(fmus):
    """Scheduler -> Plant and Source -> Plant in libcosim: the plant's y equals the
    library simulation with theta_k = sin(0.25 k) and the paper's w."""
    script = """
        for port in ("p[1]",):
            ex.connect_real_variables(idx["sched"], refs["sched"][port], idx["plant"], refs["plant"][port])
        ex.connect_real_variables(idx["src"], refs["src"]["w[1]"], idx["plant"], refs["plant"]["w[1]"])
    """
    steps = 30
    result = _cosim_run({"sched": fmus["PeixotoEx1Scheduler"], "src": fmus["PeixotoEx1Source"],
                         "plant": fmus["PeixotoEx1Plant"]}, steps=steps, step_size=1.0, script=script)
    assert result["ok"]
    plant = load_system("peixoto-ex1").model()
    k = np.arange(steps + 1)
    ref = plant.simulate(plant.alpha_batch(theta(k)[:, None]), paper_w(k)[:, None])
    values = result["values"]
    # the plant got p_k and w_k in step k (x_steps right, no one-step delay)
    # the same recursion, another rounding order: sums of <= 4 products per step, 30 steps
    tol = roundoff(float(np.max(np.abs(ref.x))) + 2.0, steps, n=4)
    np.testing.assert_allclose([values["plant"]["x[1]"], values["plant"]["x[2]"]], ref.x[steps], rtol=0, atol=tol)
    # libcosim observes the outputs after the last step, before it passes the
    # new inputs on: y feeds through, so it holds the value of the sample just
    # consumed, y_(steps-1) (lpvest.fmi._slave, step semantics)
    assert values["plant"]["y[1]"] == pytest.approx(ref.y[steps - 1, 0], abs=tol)


# -- a long run: no growth in memory -------------------------------------------------------


LONG_RUNS = {
    # FMU: (inputs, outputs read each step)
    "PeixotoEx1Plant": (["p[1]", "w[1]"], ["y[1]", "x[1]"]),
    "CoxTothTruncationKalman": (["p[1]", "u[1]", "y[1]", "y[2]"], ["xhat[1]", "xhat[2]", "P[1,1]", "innovation[1]"]),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LONG_RUNS))
def test_100000_steps_do_not_grow_memory(fmus, name):
    ins, outs = LONG_RUNS[name]
    code = textwrap.dedent(f"""
        import resource, sys
        sys.path.insert(0, {str(ROOT)!r})
        import numpy as np
        from tests.fmu_driver import Driver
        def rss():
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * resource.getpagesize()
        d = Driver({str(fmus[name])!r})
        assert d.initialize() == 0
        fmu, vin, vout = d.fmu, [d.vr[n] for n in {ins!r}], [d.vr[n] for n in {outs!r}]
        n_in = len(vin)
        marks = {{}}
        for k in range(100_000):
            v = [np.sin(0.25 * k)] + [np.sin(0.5 * k + i) * np.exp(-0.1 * (k % 50)) for i in range(n_in - 1)]
            fmu.setReal(vin, v)
            fmu.getReal(vout)
            fmu.doStep(float(k), 1.0)
            if k + 1 in (20_000, 100_000):
                marks[k + 1] = rss()
        d.free()
        print(marks[20_000], marks[100_000])
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    rss_20k, rss_100k = map(int, proc.stdout.split())
    growth = rss_100k - rss_20k
    print(f"{name}: RSS after 20,000 steps {rss_20k / 2**20:.1f} MiB, after 100,000 {rss_100k / 2**20:.1f} MiB")
    # 80,000 further steps: a leak of even 16 bytes per step would show as 1.2 MiB
    assert growth < 1 * 2**20


# -- a fresh Python without lpvest ------------------------------------------------------------


_FRESH_HOST = """
import json, os, sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

for absent in ("lpvest", *sys.argv[2:]):
    try:
        __import__(absent)
        sys.exit(f"{absent} is importable in the fresh environment")
    except ImportError:
        pass
job = json.loads(open(sys.argv[1]).read())
out = {}
for name, path in job["fmus"].items():
    md = read_model_description(path)
    h = float(md.defaultExperiment.stepSize)
    ins = [v for v in md.modelVariables if v.causality == "input"]
    outs = [v for v in md.modelVariables if v.causality == "output"]
    given = job["inputs"].get(name, {})
    unzip = extract(path, unzipdir=os.path.join(os.path.dirname(sys.argv[1]), "unzipped", name))  # the test's folder
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    rows = []
    for k in range(job["steps"]):
        values = []
        for v in ins:  # the given series, else the middle of the declared range, else the start value
            if v.name in given:
                values.append(given[v.name][k])
            elif v.min is not None and v.max is not None:
                values.append(0.5 * (float(v.min) + float(v.max)))
            else:
                values.append(float(v.start or 0.0))
        if ins:
            fmu.setReal([v.valueReference for v in ins], values)
        rows.append(fmu.getReal([v.valueReference for v in outs]))  # sample k, before the step
        fmu.doStep(k * h, h)
    fmu.terminate()
    fmu.freeInstance()
    out[name] = {v.name: [r[i] for r in rows] for i, v in enumerate(outs)}
print("RESULT" + json.dumps(out))
"""


def _requirements(path: Path) -> list[str]:
    with zipfile.ZipFile(path) as z:
        return z.read("resources/requirements.txt").decode().split()


@pytest.mark.slow
def test_fmus_run_in_a_fresh_virtual_environment_with_exactly_their_requirements(fmus, tmp_path):
    """Every FMU role in a fresh Python with fmpy (the host) and exactly the
    packages its requirements.txt lists: first every FMU that lists numpy
    only, with scipy absent; then scipy added, the FMUs that list it. lpvest
    is never importable there: each FMU runs the copy it carries."""
    env_dir = tmp_path / "fresh"
    # without pip: this process's pip installs into it (pip --python), so the environment holds
    # the requirements and nothing else (and ensurepip's 5 CPU-s are saved)
    venv.create(env_dir, with_pip=False)
    py = env_dir / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}

    def pip(*packages: str) -> None:
        # --no-compile: no bytecode for every module of scipy up front (Python compiles what it imports)
        proc = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--quiet", "--no-compile",
                               *packages], capture_output=True, text=True, timeout=600, check=False, env=env)
        assert proc.returncode == 0, proc.stderr[-3000:]

    one_per_role = {}
    for name in sorted(EXPECTED):
        if name != "PeixotoEx1MovingAverage":  # a test-only estimator (tests/fmu_movavg.py)
            one_per_role.setdefault(name.removeprefix("PeixotoEx1").removeprefix("CoxTothTruncation"), name)
    chosen = set(one_per_role.values()) | {"PeixotoEx1Plant", "PeixotoEx1HinfPD", "CoxTothTruncationKalman",
                                           "SridharLtvPlant", "SridharLtvBSplineObserver", "AffineDemoPlant"}
    groups: dict[tuple[str, ...], list[str]] = {}
    for name in sorted(chosen):
        groups.setdefault(tuple(_requirements(fmus[name])), []).append(name)
    assert set(groups) == {("numpy>=1.26",), ("numpy>=1.26", "scipy>=1.11")}, groups
    roles = {n.removeprefix("PeixotoEx1").removeprefix("CoxTothTruncation").removeprefix("SridharLtv")
             .removeprefix("AffineDemo") for n in chosen}
    assert roles >= {"Plant", "Scheduler", "Source", "Kalman", "TruncatedKalman", "HinfPD", "HinfRobust",
                     "BSplineObserver"}

    T = 40
    k = np.arange(T)
    plant = load_system("peixoto-ex1").model()
    ref = plant.simulate(plant.alpha_batch(theta(k)[:, None]), paper_w(k)[:, None])
    kf_model = load_system("cox-toth-truncation").model()
    kf_u = np.sin(0.1 * k)[:, None]
    kf_y = kf_model.simulate(theta(k)[:, None], kf_u, rng=1).y
    inputs = {
        "PeixotoEx1Plant": {"p[1]": theta(k).tolist(), "w[1]": paper_w(k).tolist()},
        "PeixotoEx1HinfPD": {"p[1]": theta(k).tolist(), "y[1]": ref.y[:, 0].tolist()},
        "CoxTothTruncationKalman": {"p[1]": theta(k).tolist(), "u[1]": kf_u[:, 0].tolist(),
                                    "y[1]": kf_y[:, 0].tolist(), "y[2]": kf_y[:, 1].tolist()},
    }
    host = tmp_path / "host.py"
    host.write_text(_FRESH_HOST)
    result: dict[str, dict[str, list[float]]] = {}
    pip("fmpy", "numpy>=1.26")
    for reqs in sorted(groups, key=len):
        extra = [r for r in reqs if not r.startswith("numpy")]
        if extra:
            pip(*extra)
        absent = ["pip"] if extra else ["pip", "scipy"]  # nothing beyond the requirements (and fmpy)
        job = tmp_path / f"job{len(reqs)}.json"
        job.write_text(json.dumps({"fmus": {n: str(fmus[n]) for n in groups[reqs]}, "inputs": inputs, "steps": T}))
        proc = subprocess.run([str(py), str(host), str(job), *absent], capture_output=True, text=True,
                              timeout=600, check=False, cwd=tmp_path, env=env)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
        result |= json.loads(next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))[len("RESULT"):])
    assert set(result) == chosen
    for name, columns in result.items():
        assert all(np.all(np.isfinite(c)) for c in columns.values()), name
    # the numbers are the library's: the same recursions, run by another numpy
    # (the fresh environment installs the newest allowed): sums of <= 4 products
    # per step over T steps, possibly rounded in another order
    np.testing.assert_allclose(result["PeixotoEx1Plant"]["y[1]"], ref.y[:, 0], rtol=0,
                               atol=roundoff(float(np.max(np.abs(ref.x))) + 2.0, T, n=4))
    ltv = load_system("sridhar-ltv").model().to_state_space().simulate(0.1 * np.arange(T))
    np.testing.assert_allclose(result["SridharLtvPlant"]["y[1]"], ltv.y, rtol=0, atol=1e-9 * np.max(np.abs(ltv.y)))
    from lpvest.estimators.kalman import kalman_filter

    kf = kalman_filter(kf_model, theta(k)[:, None], kf_u, kf_y)
    got = np.column_stack([result["CoxTothTruncationKalman"][f"xhat[{i}]"] for i in (1, 2)])
    np.testing.assert_allclose(got, kf.filtered_means, rtol=0,
                               atol=kalman_fmu_tolerance(kf_model, theta(k)[:, None], kf_u, kf_y, kf))
    # the H-infinity filter ran without cvxpy (not installed there): its design came from the FMU
    from lpvest.design import HinfDesign
    from lpvest.estimators._hinf import HinfFilter

    with zipfile.ZipFile(fmus["PeixotoEx1HinfPD"]) as z:
        design = HinfDesign.from_json(z.read("resources/design.json").decode())
    hf = HinfFilter(design, simplex_map=plant.simplex_map)
    zhat = np.array([hf.step({"p": theta(k)[i:i + 1], "y": ref.y[i]})["zhat"] for i in range(T)])
    got = np.column_stack([result["PeixotoEx1HinfPD"][f"zhat[{i}]"] for i in (1, 2)])
    np.testing.assert_allclose(got, zhat, rtol=0, atol=roundoff(float(np.max(np.abs(zhat))), T, n=4))


# -- command line ----------------------------------------------------------------------------


def test_lpvest_build_for_a_users_model_file(fmus, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["build", "--out", str(out), "--model", str(fmus.affine_model), "--epsilon", "1"]
    assert main(args) == 0
    captured = capsys.readouterr()
    text = captured.out
    # the plant, its signal sources, and every filter that applies to an affine model with
    # general noise: the H-infinity filters in its H-infinity setting (lpvest.hinf_setting)
    names = ("AffineDemoPlant.fmu", "AffineDemoScheduler.fmu", "AffineDemoSource.fmu",
             "AffineDemoKalman.fmu", "AffineDemoTruncatedKalman.fmu", "AffineDemoHinfPD.fmu",
             "AffineDemoHinfRobust.fmu")
    for name in names:
        assert (out / name).is_file()
        assert any(line.startswith(name) and line.rstrip().endswith("ok") for line in text.splitlines())
    assert f"{len(names)} FMU(s)" in text and "all valid" in text
    assert "building AffineDemoHinfPD (6/7)" in captured.err  # progress per FMU
    assert "AffineDemoHinfPD: designing (lpvest.fmi._designs:hinf_pd, epsilon = 1.0)" in captured.err
    # each design's gamma, epsilon and solver once; no progress bar into a redirected stream
    designed = [line for line in captured.err.splitlines() if line.startswith("AffineDemoHinfPD: designed: ")]
    assert len(designed) == 1 and re.fullmatch(r"AffineDemoHinfPD: designed: gamma = [0-9.e+-]+ at epsilon = 1 "
                                               r"\((CLARABEL|SCS), [0-9.]+ s\)", designed[0]), captured.err
    assert "\r" not in captured.err
    first = (out / "AffineDemoHinfPD.fmu").read_bytes()
    # a rebuild reuses the designs made at build time (out/.designs): no solve, the same FMU
    assert main(args + ["--kinds", "HinfPD"]) == 0
    err = capsys.readouterr().err
    assert "AffineDemoHinfPD: design reused from" in err and designed[0].split(": designed")[1] in err
    assert (out / "AffineDemoHinfPD.fmu").read_bytes() == first
    # --quiet: the table and the verdict, no progress lines
    assert main(args + ["--kinds", "HinfPD", "--quiet"]) == 0
    quiet = capsys.readouterr()
    assert quiet.err == "" and "1 FMU(s)" in quiet.out


@pytest.mark.slow
def test_two_builds_of_a_users_plant_with_an_epsilon_search_give_the_same_fmu_bytes(tmp_path):
    """Each build searches epsilon anew (no shared design cache): the FMU carries the design
    without the solver's timings (which differ from solve to solve), so the bytes agree.
    The search is the default one (grid, then Brent refinement of the best minima) on a
    grid of 6 angles instead of 24: the same code path at a quarter of the solves."""
    from lpvest.design import HinfDesign
    from lpvest.fmi._build import build_fmus

    model = Path(__file__).resolve().parent.parent / "examples" / "own_plant.toml"
    fmus = [build_fmus([model], tmp_path / f"build{i}", roles=["HinfPD"], design_options={"n_grid": 6})[0][0]
            .validation.path for i in (1, 2)]
    assert fmus[0].read_bytes() == fmus[1].read_bytes()
    with zipfile.ZipFile(fmus[0]) as z:
        text = z.read("resources/design.json").decode()
    assert "solve_time" not in text and "compile_time" not in text
    design = HinfDesign.from_json(text)  # still a design: the timings read as unknown
    assert np.isnan(design.solve_time) and np.isnan(design.compile_time) and np.isfinite(design.gamma)
    with zipfile.ZipFile(fmus[0]) as z:  # the manifest says which search made it
        assert json.loads(z.read("resources/manifest.json"))["inputs"]["estimator"]["design_options"] == {"n_grid": 6}
    cached = next((tmp_path / "build1" / ".designs").glob("*.json")).read_text()
    assert HinfDesign.from_json(cached).solve_time > 0  # the cache outside the FMU keeps them


def test_a_design_that_fails_leaves_the_other_fmus_built(tmp_path, capsys):
    # an unstable plant: no H-infinity filter exists, the Kalman filters do
    text = AFFINE_TOML.replace('A = { "1" = [[0.5, 0.1], [0.0, 0.4]]', 'A = { "1" = [[1.5, 0.1], [0.0, 0.4]]')
    model = tmp_path / "unstable.toml"
    model.write_text(text)
    out = tmp_path / "out"
    assert main(["build", "--out", str(out), "--model", str(model), "--kinds", "Plant,Kalman,HinfPD"]) == 1
    table = capsys.readouterr().out
    rows = {line.split()[0]: line for line in table.splitlines() if line.startswith("AffineDemo")}
    assert rows["AffineDemoPlant.fmu"].rstrip().endswith("ok") and rows["AffineDemoKalman.fmu"].rstrip().endswith("ok")
    assert "1 problem(s)" in rows["AffineDemoHinfPD.fmu"]
    assert "AffineDemoHinfPD.fmu: not built: LMIInfeasibleError" in table and "spectral radius" in table
    assert "3 FMU(s)" in table and "1 failed validation" in table


def test_build_fmus_script_builds_every_example(script_build):
    # the run's build by the script (tests/conftest_fmu.py; test_fmu_isolation.py compares its bytes)
    assert script_build.returncode == 0, script_build.stderr
    built = {p.stem for p in script_build.out.glob("*.fmu")}
    # the test suite's own systems (conftest_fmu.py) are not examples: AffineDemo, IoDemo, the moving average
    test_only = ("AffineDemo", "IoDemo", "PeixotoEx1MovingAverage")
    assert built == {n for n in EXPECTED if not n.startswith(test_only)}
    assert script_build.stdout.splitlines()[0].split() == ["FMU", "variables", "(in/out/par)", "size", "validation"]


def test_lpvest_validate_fails_on_a_broken_fmu(fmus, tmp_path, capsys):
    broken = tmp_path / "Broken.fmu"
    with zipfile.ZipFile(fmus["PeixotoEx1Plant"]) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b"<InitialUnknowns>", b"<InitialUnknowns>\n<Unknown index=\"1\"/>")
            dst.writestr(item, data)
    assert main(["validate", str(fmus["PeixotoEx1Plant"])]) == 0
    assert main(["validate", str(broken)]) == 1
    assert "InitialUnknowns" in capsys.readouterr().out


def test_lpvest_build_of_a_bad_model_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[system]\nname = 'bad'\n[models.m]\ntype = 'polytopic'\n")
    proc = subprocess.run([sys.executable, "-m", "lpvest.cli", "build", "--out", str(tmp_path), "--model", str(bad)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"lpvest: error: {bad}") and proc.stderr.count("\n") == 1


# -- a C host -----------------------------------------------------------------------------


def test_a_c_host_runs_the_fmu_with_libpython_preloaded(fmus, tmp_path):
    """What a non-Python host needs: libpython loaded first (LD_PRELOAD) and a
    Python path where numpy is found; without libpython the FMU says so."""
    import shutil
    import sysconfig

    cc = shutil.which("cc") or shutil.which("gcc")
    libpython = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("INSTSONAME") or "")
    if cc is None or not libpython.is_file():
        pytest.skip("needs a C compiler and a shared libpython")
    host = tmp_path / "c_host"
    subprocess.run([cc, "-O2", "-o", str(host), str(ROOT / "tests" / "data" / "c_host.c"), "-ldl", "-lm"], check=True)
    unzip = tmp_path / "fmu"
    with zipfile.ZipFile(fmus["PeixotoEx1Plant"]) as z:
        z.extractall(unzip)
    from fmpy import read_model_description

    md = read_model_description(str(fmus["PeixotoEx1Plant"]))
    vr = {v.name: str(v.valueReference) for v in md.modelVariables}
    args = [str(host), str(unzip), "PeixotoEx1Plant", md.guid, vr["p[1]"], vr["w[1]"], vr["y[1]"], "20"]
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONPATH", "PYTHONHOME")}
    bare = subprocess.run(args, capture_output=True, text=True, env=env, timeout=120, check=False)
    assert bare.returncode == 4 and "LD_PRELOAD" in bare.stdout
    site = str(Path(np.__file__).resolve().parent.parent)  # where numpy is installed
    env.update(LD_PRELOAD=str(libpython), PYTHONPATH=site)
    proc = subprocess.run(args, capture_output=True, text=True, env=env, timeout=120, check=False, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ys = [float(line.split()[2]) for line in proc.stdout.splitlines() if line.startswith("Y ")]
    plant = load_system("peixoto-ex1").model()
    k = np.arange(20)
    ref = plant.simulate(plant.alpha_batch(theta(k)[:, None]), np.full((20, 1), 0.3))
    assert np.array_equal(ys, ref.y[:, 0])
    assert "BADSTATUS 3" in proc.stdout and "p[1] (theta) = 1.5 is outside" in proc.stdout
    assert "FREED" in proc.stdout


def test_fmus_refuse_what_pythonfmu_would_crash_on_and_keep_fmu_states_in_bounds(fmus, tmp_path):
    """Through fmpy, in a process of its own (the defects crashed the host): an FMU extracted
    where pythonfmu cannot import the slave from (a non-ASCII letter and a '%' in the folder's
    name: it decodes only %20) runs; a wrong GUID, the model-exchange type and resources without
    slavemodule.txt are refused with a message; a state serialized into a larger buffer is
    itself followed by zeros (not the host's heap), into a smaller one refused; a freed state's
    pointer is NULL (docs/fmus.md, 6.)."""
    code = textwrap.dedent(f"""
        import ctypes, json, os, pathlib, sys
        sys.path.insert(0, {str(ROOT)!r})
        from fmpy import extract
        from tests.fmu_driver import Driver
        path, root = {str(fmus["PeixotoEx1Plant"])!r}, {str(tmp_path)!r}
        out = {{}}
        folder = extract(path, unzipdir=os.path.join(root, "Jürgen's 100% FMUs", "plant"))
        d = Driver(path, unzip=folder)
        out["odd folder"] = [d.initialize(), d.step(0.0, 1.0)]
        fmu, state = d.fmu, ctypes.c_void_p()
        out["get state"] = d.raw("fmi2GetFMUstate", ctypes.byref(state))
        size = ctypes.c_size_t()
        d.raw("fmi2SerializedFMUstateSize", state, ctypes.byref(size))
        n = size.value
        big = ctypes.create_string_buffer(b"\\xff" * (n + 4096), n + 4096)
        out["larger buffer"] = [d.raw("fmi2SerializeFMUstate", state, big, n + 4096), big.raw[n:] == bytes(4096)]
        small = ctypes.create_string_buffer(n - 1)
        out["smaller buffer"] = [d.raw("fmi2SerializeFMUstate", state, small, n - 1), d.messages[-1][2]]
        out["free state"] = [d.raw("fmi2FreeFMUstate", ctypes.byref(state)), state.value]
        d.free()
        probe = Driver(path, unzip=folder)
        uri = pathlib.Path(folder, "resources").as_uri().encode()
        for what, guid, kind in (("guid", "{{00000000-0000-0000-0000-000000000000}}", 1), ("type", probe.md.guid, 0)):
            got = probe.fmu.fmi2Instantiate(b"x", kind, guid.encode(), uri, ctypes.byref(probe.fmu.callbacks), 0, 0)
            out[what] = [got, probe.messages[-1][2]]
        probe.free()
        os.remove(os.path.join(folder, "resources", "slavemodule.txt"))
        try:
            Driver(path, unzip=folder)
            out["damaged"] = "instantiated"
        except Exception as exc:
            out["damaged"] = str(exc)
        print(json.dumps(out))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.splitlines()[-1])
    assert out["odd folder"] == [0, 0] and out["get state"] == 0
    assert out["larger buffer"] == [0, True]
    assert out["smaller buffer"][0] == 3 and "the buffer holds" in out["smaller buffer"][1]
    assert out["free state"] == [0, None]
    assert out["guid"][0] is None and "does not match this FMU's" in out["guid"][1]
    assert out["type"][0] is None and "co-simulation only" in out["type"][1]
    assert out["damaged"] == "Failed to instantiate model"
