"""Every FMU runs its own bundled code, whatever else the process has loaded
(lpvest.fmi._bundle): plain fmpy loops over every FMU, with and without lpvest in
the host; builds of two lpvest versions side by side; what an FMU carries and
declares; byte-identical rebuilds; designs as data (lpvest design / build --design)."""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lpvest import load_system
from lpvest.cli import main
from lpvest.fmi._bundle import BundleError, SourceRoot, make_bundle
from tests.fmu_driver import Driver
from tests.test_fmu import paper_w, theta

ROOT = Path(__file__).resolve().parent.parent


def _read(path: Path, name: str) -> bytes:
    with zipfile.ZipFile(path) as z:
        return z.read(name)


def _run(code: str, *, cwd: Path | None = None, timeout: int = 900) -> dict:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                          check=False, cwd=cwd)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))
    return json.loads(line[len("RESULT"):])


# -- what an FMU carries -----------------------------------------------------------------------


@pytest.mark.parametrize(("name", "present", "absent", "requirements"), [
    ("PeixotoEx1Plant", ["lpvest.systems._streaming", "lpvest.fmi._slave", "pythonfmu.fmi2slave"],
     ["lpvest.cli", "lpvest.cosim", "lpvest.experiments._fmus", "lpvest.design._lmis", "lpvest.design._program",
      "lpvest.design._search", "lpvest.estimators.kalman", "lpvest.fmi._build", "lpvest.cosim._ssp"], ["numpy>=1.26"]),
    ("CoxTothTruncationKalman", ["lpvest.estimators.kalman", "lpvest.fmi.factories._kalman"],
     ["lpvest.estimators.bspline", "lpvest.estimators._truncated", "lpvest.design._lmis", "lpvest.design._program",
      "lpvest.design._search", "lpvest.cli"],
     ["numpy>=1.26"]),
    ("PeixotoEx1HinfPD", ["lpvest.estimators._hinf", "lpvest.design._result"],
     ["lpvest.design._lmis", "lpvest.design._program", "lpvest.design._search", "lpvest.fmi._designs",
      "lpvest.estimators.kalman"], ["numpy>=1.26"]),
    ("SridharLtvBSplineObserver", ["lpvest.estimators.bspline", "lpvest.estimators.bspline._kernels"],
     ["lpvest.estimators.kalman", "lpvest.cli"], ["numpy>=1.26", "scipy>=1.11"]),
])
def test_an_fmu_carries_what_its_component_imports_and_says_what_it_needs(fmus, name, present, absent,
                                                                          requirements):
    manifest = json.loads(_read(fmus[name], "resources/manifest.json"))
    modules = set(manifest["modules"])
    assert set(present) <= modules, set(present) - modules
    assert not set(absent) & modules, set(absent) & modules
    assert _read(fmus[name], "resources/requirements.txt").decode().split() == requirements
    # the manifest names every input with its hash, and no path or time
    inputs = manifest["inputs"]
    assert len(inputs["model_file_sha256"]) == 64 and inputs["bundle"]["package"].startswith("lpvest_")
    text = json.dumps(manifest)
    assert str(fmus.out) not in text and "/tmp" not in text and str(Path.home()) not in text


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "src"
    for rel, text in files.items():
        f = root / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(textwrap.dedent(text))
    return root


def test_bundling_renames_imports_on_the_same_lines_and_records_requirements(tmp_path):
    root = _tree(tmp_path, {
        "pkg/__init__.py": "from .a import f\n__version__ = '9'\n",
        "pkg/a.py": """\
            import numpy as np
            from pkg.b import (
                g,
            )
            import pkg.b as bee


            def f():
                import scipy.linalg  # only when called
                return g() + bee.g() + np.zeros(1)[0]
            """,
        "pkg/b.py": "def g():\n    return 1\n",
        "pkg/unused.py": "import cvxpy\n",
        "role.py": "from pkg.a import f\n\n\nclass Slave:\n    pass\n",
    })
    roots = [SourceRoot("pkg", root / "pkg", ""), SourceRoot("lpvest._fmus", root, "_fmus")]
    b = make_bundle(identifier="X", script="role", slave_class="Slave", start=["lpvest._fmus.role"], roots=roots,
                    version="9")
    assert b.package.startswith("lpvest_") and b.entry == b.package + "_entry"
    assert set(b.modules) == {"pkg", "pkg.a", "pkg.b", "lpvest._fmus.role"}  # not pkg.unused (cvxpy)
    assert b.requirements == ("numpy>=1.26",)
    assert b.lazy_imports == {"scipy": ("pkg.a",)}
    a = b.files[f"{b.package}/a.py"].decode()
    original = (root / "pkg" / "a.py").read_text()
    assert a.count("\n") == original.count("\n")  # tracebacks keep their line numbers
    assert f"from {b.package}.b import (" in a and f"import {b.package}.b as bee" in a
    assert b.files[f"{b.package}/__init__.py"].decode().startswith('"""lpvest 9, as carried by an lpvest FMU')
    assert "from .a import f" not in b.files[f"{b.package}/__init__.py"].decode()  # inits carried empty
    # the same sources give the same name; another source another
    again = make_bundle(identifier="X", script="role", slave_class="Slave", start=["lpvest._fmus.role"],
                        roots=roots, version="9")
    assert again.package == b.package and again.files == b.files
    (root / "pkg" / "b.py").write_text("def g():\n    return 2\n")
    other = make_bundle(identifier="X", script="role", slave_class="Slave", start=["lpvest._fmus.role"],
                        roots=roots, version="9")
    assert other.package != b.package


@pytest.mark.parametrize(("text", "match"), [
    ("from pkg import f\n", r"takes f from a package __init__, which an FMU carries empty"),
    ("import pkg.b\n", r"'import pkg.b' binds the name 'pkg'"),
    ("import yaml\n", r"third-party packages lpvest cannot declare: yaml"),
    ("from pkg.nothere import x\n", r"imports 'pkg.nothere', which does not exist"),
])
def test_bundling_refuses_what_it_cannot_carry(tmp_path, text, match):
    root = _tree(tmp_path, {"pkg/__init__.py": "from .b import f\n", "pkg/b.py": "def f():\n    pass\n",
                            "role.py": text})
    roots = [SourceRoot("pkg", root / "pkg", ""), SourceRoot("lpvest._fmus", root, "_fmus")]
    with pytest.raises(BundleError, match=match):
        make_bundle(identifier="X", script="role", slave_class="S", start=["lpvest._fmus.role"], roots=roots,
                    version="1")


# -- plain fmpy loops in one process -------------------------------------------------------------


_LOOP = """
import importlib.abc, json, sys
blocked = {blocked}
class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "lpvest" or name.startswith("lpvest."):
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked by the test)")
        return None
blocker = Blocker()
if blocked:
    sys.meta_path.insert(0, blocker)
else:
    import lpvest.fmi.factories  # the host's own lpvest, imported before any FMU
from fmpy import read_model_description, simulate_fmu
paths = {paths}
out = {{}}
for order in ("forward", "reverse"):
    for name in (sorted(paths) if order == "forward" else sorted(paths, reverse=True)):
        md = read_model_description(paths[name])
        h = float(md.defaultExperiment.stepSize)
        res = simulate_fmu(paths[name], stop_time=8 * h, output_interval=h)
        out[order + ":" + name] = [[float(v) for v in row] for row in res[[n for n in res.dtype.names]][-1:]][0]
if blocked:
    sys.meta_path.remove(blocker)
import lpvest.fmi.factories._kalman, lpvest.fmi._build
out["host"] = [lpvest.__file__, lpvest.fmi.factories._kalman.__file__]
out["packages"] = sorted(m for m in sys.modules if m.startswith("lpvest_") and "." not in m)
print("RESULT" + json.dumps(out))
"""


@pytest.mark.slow
@pytest.mark.parametrize("blocked", [False, True], ids=["host-lpvest-imported", "host-without-lpvest"])
def test_simulate_fmu_over_every_fmu_in_one_process(fmus, blocked):
    names = [n for n in fmus.paths if n != "PeixotoEx1MovingAverage"]
    result = _run(_LOOP.format(blocked=blocked, paths=json.dumps({n: str(fmus[n]) for n in names})))
    for name in names:  # every FMU ran in both orders, to the same numbers
        assert result[f"forward:{name}"] == result[f"reverse:{name}"], name
        assert all(np.isfinite(result[f"forward:{name}"]))
    # the host's lpvest is its own, intact, importable afterwards
    assert result["host"][0] == str(ROOT / "lpvest" / "__init__.py")
    assert result["host"][1] == str(ROOT / "lpvest" / "fmi" / "factories" / "_kalman.py")
    # each FMU ran its own private package (shared only by FMUs that carry identical code)
    assert len(result["packages"]) >= 8


def _copy_of_lpvest(tmp_path: Path, version: str) -> Path:
    """A source tree of lpvest with another version, whose plant adds 1000 to y."""
    tree = tmp_path / f"lpvest-{version}"
    for part in ("lpvest", "fmus", "models"):
        shutil.copytree(ROOT / part, tree / part, ignore=shutil.ignore_patterns("__pycache__"))
    init = tree / "lpvest" / "_version.py"
    text, n = re.subn(r'__version__ = "([^"]+)"', rf'__version__ = "\1+{version}"', init.read_text(), count=1)
    assert n == 1
    init.write_text(text)
    polytopic = tree / "lpvest" / "systems" / "_polytopic.py"
    code = polytopic.read_text()
    old = 'y, z, nxt = m["Cy"] @ x + m["Dy"] @ w,'
    assert old in code
    polytopic.write_text(code.replace(old, 'y, z, nxt = m["Cy"] @ x + m["Dy"] @ w + 1000.0,', 1))
    return tree


@pytest.mark.slow
def test_builds_of_two_lpvest_versions_run_side_by_side(fmus, tmp_path):
    tree = _copy_of_lpvest(tmp_path, "fake")
    out = tmp_path / "other"
    built = _run(textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(tree)!r})
        import lpvest
        from lpvest.fmi._build import build_fmu, plan_system
        plan = next(p for p in plan_system("peixoto-ex1")[0] if p.role == "Plant")
        print("RESULT" + json.dumps([lpvest.__version__, str(build_fmu(plan, {str(out)!r}))]))
    """))
    from lpvest import __version__

    assert built[0] == f"{__version__}+fake"
    ours, theirs = Driver(fmus["PeixotoEx1Plant"], "ours", logging_on=True), Driver(built[1], "theirs",
                                                                                     logging_on=True)
    assert ours.initialize() == 0 and theirs.initialize() == 0
    versions = []
    for d in (ours, theirs):
        said = [m for _, _, m in d.messages if m.startswith("[PeixotoEx1Plant] lpvest ")]
        assert len(said) == 1, d.messages
        versions.append(said[0].split()[2:])
    assert versions[0][0] == __version__ and versions[1][0] == built[0] != __version__
    assert versions[0][1] != versions[1][1]  # two private packages
    for k in range(10):  # stepped alternately in one process: each runs its own code
        for d in (ours, theirs):
            d.set_vector("p", theta(k))
            d.set_vector("w", paper_w(k))
        y_ours, y_theirs = ours.vector("y"), theirs.vector("y")
        assert y_theirs[0] == y_ours[0] + 1000.0
        assert ours.step(float(k), 1.0) == 0 and theirs.step(float(k), 1.0) == 0
    ours.free()
    theirs.free()
    plant = load_system("peixoto-ex1").model()
    ref = plant.simulate(plant.alpha_batch(theta(np.arange(10))[:, None]), paper_w(np.arange(10))[:, None])
    assert y_ours[0] == ref.y[9, 0]


# -- reproducible builds --------------------------------------------------------------------------


@pytest.mark.slow
def test_the_same_inputs_give_a_byte_identical_fmu(tmp_path):
    """Built here and in a fresh process (its own compile of the status bridge,
    other temporary folders): the same bytes, and no path or host name inside."""
    from lpvest.fmi._build import build_fmu, plan_system

    plans = {p.role: p for p in plan_system("peixoto-ex1")[0]}
    first = {role: build_fmu(plans[role], tmp_path / "a") for role in ("Plant", "HinfPD")}
    second = _run(textwrap.dedent(f"""
        import json
        from lpvest.fmi._build import build_fmu, plan_system
        plans = {{p.role: p for p in plan_system("peixoto-ex1")[0]}}
        out = {str(tmp_path / 'b')!r}
        print("RESULT" + json.dumps({{r: str(build_fmu(plans[r], out)) for r in ("Plant", "HinfPD")}}))
    """), cwd=tmp_path)
    host = socket.gethostname().encode()
    needles = [str(tmp_path).encode(), b"/tmp/", b"/lpvest-fmu-", b"/lpvest-bridge-", str(ROOT).encode()]
    for role, path in first.items():
        data = path.read_bytes()
        assert data == Path(second[role]).read_bytes(), role
        with zipfile.ZipFile(path) as z:
            assert all(info.date_time == (1980, 1, 1, 0, 0, 0) for info in z.infolist())
            assert [i.filename for i in z.infolist()] == sorted(i.filename for i in z.infolist())
            for info in z.infolist():
                content = z.read(info)
                # the host name in what the build writes (binaries are copied or compiled: paths only)
                text_file = not info.filename.startswith("binaries/")
                for needle in needles + ([host] if text_file and len(host) >= 4 else []):
                    assert needle not in content, (role, info.filename, needle)
    # the design came from models/designs: carried byte for byte
    stored = (ROOT / "models" / "designs" / "peixoto-ex1.HinfPD.json").read_bytes()
    assert _read(first["HinfPD"], "resources/design.json") == stored


@pytest.mark.parametrize("system", ["peixoto-ex1", "cox-toth-truncation"])
def test_both_backends_record_a_plan_alike(system):
    """The entries the pythonfmu and the native manifests both record are the
    same values, in the same order, for every plan: the plan's (identifier to
    design_sha256); the native estimator entry lacks only the Python
    requirements."""
    from lpvest.fmi._build import manifest_inputs, plan_system
    from lpvest.fmi.native._build import native_manifest_inputs

    plans = plan_system(system)[0]
    assert any(p.estimator is not None for p in plans)
    for plan in plans:
        for design in (None, '{"a design": 1}'):
            py = manifest_inputs(plan, design=design)
            native = native_manifest_inputs(plan, design)
            common = [k for k in py if k in native]
            assert common == [k for k in native if k in py] == [
                "identifier", "role", "system", "model_key", "description", "model_parameters", "step_size",
                "stop_time", "estimator", "lpvest_version", "model_file_sha256", "design_sha256"], plan.identifier
            for key in common:
                if key == "estimator" and plan.estimator is not None:
                    py_est, native_est = py[key], native[key]
                    assert "requirements" not in native_est and "requirements" in py_est
                    assert {k: v for k, v in py_est.items() if k != "requirements"} == native_est
                else:
                    assert py[key] == native[key], (plan.identifier, key)
            assert (py["design_sha256"] is None) == (design is None)


def test_every_example_fmu_rebuilt_elsewhere_is_byte_identical(fmus, script_build):
    """Every FMU ``lpvest build`` writes for the example systems (the session's
    set, built in a test process), built again from scratch in a fresh process
    into another folder (``build_fmus.py``, the run's script build of
    tests/conftest_fmu.py): the same bytes (issue 11: the same inputs give the
    same .fmu)."""
    assert script_build.returncode == 0, script_build.stderr
    second = {p.stem: p for p in script_build.out.glob("*.fmu")}
    assert len(second) >= 15 and set(second) <= set(fmus.paths)
    differ = [name for name, path in second.items() if Path(path).read_bytes() != fmus[name].read_bytes()]
    assert differ == []


# -- designs are data ------------------------------------------------------------------------------


def test_design_then_build_from_the_design_without_solving(tmp_path, capsys, monkeypatch):
    design = tmp_path / "pd150.json"
    assert main(["design", "peixoto-ex1", "--epsilon", "150", "--out", str(design)]) == 0
    out = capsys.readouterr().out
    assert "gamma = 1.21" in out and f"wrote {design}" in out
    doc = json.loads(design.read_text())
    assert doc["kind"] == "parameter-dependent" and len(doc["model_digest"]) == 64

    # building from the file never solves: the solver is not even importable
    import lpvest.design._program as program
    import lpvest.design._search as search

    def no_solver(*args, **kwargs):
        raise AssertionError("the build solved an LMI")

    monkeypatch.setattr(search, "search_epsilon", no_solver)
    monkeypatch.setattr(program, "design_hinf", no_solver)
    for folder in ("x", "y"):
        assert main(["build", "--model", "peixoto-ex1", "--kinds", "HinfPD", "--design", str(design),
                     "--out", str(tmp_path / folder)]) == 0
    built = [tmp_path / f / "PeixotoEx1HinfPD.fmu" for f in ("x", "y")]
    assert built[0].read_bytes() == built[1].read_bytes()
    assert _read(built[0], "resources/design.json") == design.read_bytes()
    assert sorted(p.name for p in (tmp_path / "x").glob("*.fmu")) == ["PeixotoEx1HinfPD.fmu"]


def test_a_design_for_another_plant_is_refused_in_one_line(tmp_path, capsys):
    design = tmp_path / "rho11.json"
    shutil.copy(ROOT / "models" / "designs" / "peixoto-ex2-rho11.HinfPD.json", design)
    assert main(["build", "--model", "peixoto-ex2", "--kinds", "HinfPD", "--design", str(design),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1].startswith(f"lpvest: error: {design}: designed for another plant (peixoto-ex2 (rho = 11)")
    assert sum(line.startswith("lpvest: error") for line in err) == 1
    assert main(["build", "--design", str(design), "--out", str(tmp_path / "out")]) == 2
    assert "--design needs exactly one --model" in capsys.readouterr().err


def test_stored_designs_fit_their_plants():
    """Each design stored with the examples fits the plant it is named for (the
    builder uses it instead of solving), and its certificate checks."""
    from lpvest.design._result import HinfDesign
    from lpvest.systems._catalog import stored_design
    from lpvest.systems._polytopic import hinf_setting

    found = sorted((ROOT / "models" / "designs").glob("*.json"))
    assert len(found) == 10
    for path in found:
        system, role = path.stem.split(".")
        base, _, rho = system.partition("-rho")
        params = {"rho": float(rho)} if rho else None
        plant = hinf_setting(load_system(base if rho else system, parameters=params).model())
        d = HinfDesign.from_json(path)
        d.check_model(plant, source=str(path))
        assert d.lmi_margin > 0 and d.lyapunov_margin > 0 and np.isfinite(d.gamma)
        if not rho:
            assert stored_design(system, role) == path


def test_an_fmu_built_where_lpvest_is_not_a_source_checkout_carries_the_same_code(tmp_path):
    """The bundle does not depend on where lpvest lives: the digest covers the
    sources, not their paths."""
    from lpvest.fmi._build import _bundle, plan_system

    plan = next(p for p in plan_system("peixoto-ex1")[0] if p.role == "Plant")
    here = _bundle(plan)
    tree = tmp_path / "copy"
    for part in ("lpvest", "fmus", "models"):
        shutil.copytree(ROOT / part, tree / part, ignore=shutil.ignore_patterns("__pycache__"))
    there = _run(textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(tree)!r})
        from lpvest.fmi._build import _bundle, plan_system
        plan = next(p for p in plan_system("peixoto-ex1")[0] if p.role == "Plant")
        print("RESULT" + json.dumps(_bundle(plan).package))
    """), cwd=tmp_path)
    assert there == here.package
    assert os.path.basename(str(tree)) not in json.dumps(list(here.files))


# -- sys.path, sys.meta_path and sys.modules over many instances ----------------------------------

_INSTANCES = """
import json, os, sys, zipfile
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
path, folder, n = {path!r}, {folder!r}, {n}
md = read_model_description(path)
copies = []
for i in range(3):  # instances of three unpacked copies, in turn (fmpy's simulate_fmu unpacks each time)
    copies.append(os.path.join(folder, f"copy{{i}}"))
    with zipfile.ZipFile(path) as z:
        z.extractall(copies[-1])
def snapshot():
    return {{"path": list(sys.path), "meta_path": [id(f) for f in sys.meta_path],
            "finders": [getattr(f, "package", None) for f in sys.meta_path],
            "modules": {{name: id(m) for name, m in sys.modules.items()}}}}
def instance(k):
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=copies[k % 3], modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=f"i{{k}}")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(0.0, float(md.defaultExperiment.stepSize))
    fmu.terminate()
    fmu.freeInstance()
before = snapshot()
instance(0)
first = snapshot()
for k in range(1, n):
    instance(k)
print("RESULT" + json.dumps({{"before": before, "first": first, "last": snapshot()}}))
"""


@pytest.mark.slow
def test_sys_path_meta_path_and_modules_do_not_change_over_300_instances(fmus, tmp_path):
    """300 instances of an FMU (three unpacked copies in turn, each instance run
    for a step and freed): sys.path, sys.meta_path and sys.modules are the same
    objects after the 300th instance as after the 1st. What the first load may
    change, by design: the FMU's private package is added to sys.modules with
    its entry module, one finder serving that package goes on sys.meta_path, and
    the standard-library and numpy/scipy modules its code imports are loaded.
    Nothing that was there before changes, and sys.path is the host's."""
    name = "SridharLtvBSplineObserver"  # numpy and scipy, imported partly inside functions
    package = json.loads(_read(fmus[name], "resources/manifest.json"))["inputs"]["bundle"]["package"]
    result = _run(_INSTANCES.format(path=str(fmus[name]), folder=str(tmp_path), n=300))
    before, first, last = result["before"], result["first"], result["last"]
    assert last == first
    assert first["path"] == before["path"]
    assert first["meta_path"][1:] == before["meta_path"] and first["finders"][0] == package
    for module, ident in before["modules"].items():
        assert first["modules"].get(module) == ident, module
    allowed = set(sys.stdlib_module_names) | {"numpy", "scipy"}
    added = set(first["modules"]) - set(before["modules"])
    own = {m for m in added if m in (package, package + "_entry") or m.startswith(package + ".")}
    assert f"{package}._fmus.lpvest_estimator" in own
    assert {m for m in added - own if m.split(".")[0] not in allowed} == set()


_ALIVE_AT_EXIT = """
import gc, json, os, sys
from tests.fmu_driver import Driver, references_held

path, unzip, n = {path!r}, {unzip!r}, {n}
for k in range(n):
    d = Driver(path, f"i{{k}}", unzip=unzip)
    d.initialize()
    d.step(0.0, d.step_size)
    d.free()
with open(os.path.join(unzip, "resources", "slavemodule.txt")) as f:
    entry = sys.modules[f.read().strip()]
namespace = entry.__dict__
gc.collect()
held = references_held(namespace)  # a lower bound of the references to the namespace
print("RESULT" + json.dumps({{"refcount": sys.getrefcount(namespace) - 1, "held": held}}), flush=True)
# the entry module stays alive to the interpreter's end (in the test suite's processes
# hypothesis's cache of the local modules' constants keeps it), which then clears its namespace
namespace["_alive_at_exit"] = entry
"""


def test_a_host_that_ends_with_the_entry_module_alive_after_many_instances_exits_cleanly(fmus, tmp_path):
    """Twelve instances of one FMU, then the host ends with the FMU's entry module still
    alive: the interpreter clears that module's namespace at its end, and the process exits
    0. pythonfmu 0.7's findClass releases a reference to the entry module's namespace at
    every instantiation that it never took; the entry used to keep one per execution in a
    list inside that namespace, which the clearing released all at once, freeing the
    namespace while the module still used it: heap corruption at exit ("corrupted
    double-linked list", status 134, in a pytest worker after all its tests passed, when
    hypothesis, whose cache of the local modules' constants holds every module loaded
    from outside site-packages, ran after FMU tests). Under Python's debug allocator
    (freed memory overwritten) that use after free crashes the process every time; the
    namespace's reference count covered fewer references than it had (one fewer per
    instance after the first)."""
    name = "PeixotoEx1Plant"
    from fmpy import extract

    unzip = str(extract(str(fmus[name]), unzipdir=str(tmp_path / "unz")))
    code = _ALIVE_AT_EXIT.format(path=str(fmus[name]), unzip=unzip, n=12)
    env = {**os.environ, "PYTHONMALLOC": "debug"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False,
                          cwd=ROOT, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    assert "Fatal Python error" not in proc.stderr and "corrupted" not in proc.stderr, proc.stderr[-4000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("RESULT"))
    counts = json.loads(line[len("RESULT"):])
    assert counts["refcount"] >= counts["held"], counts


def test_a_build_in_the_process_of_a_live_fmu_of_the_same_bundle_leaves_it_working(fmus, tmp_path):
    """Building an FMU instantiates its slave once in the building process and then unloads the
    bundle's modules. When an FMU of the same bundle (the same sources, so the same package name)
    was already running in that process, the build unloaded its modules too: its next fmi2Reset
    (which runs the constructor, with its deferred imports, again) made second copies of lpvest's
    classes and failed fatally ("AffineLPV is no model a streaming plant runs"). It surfaced as
    in-process sweeps failing after another test built the same FMUs on the same xdist worker."""
    result = _run(textwrap.dedent(f"""
        import json
        from tests.fmu_driver import Driver
        from lpvest.fmi._build import build_fmu, plan_system

        d = Driver({str(fmus["CoxTothTruncationPlant"])!r}, "live")
        first = [d.initialize(), d.step(0.0, d.step_size)]
        plan = next(p for p in plan_system("cox-toth-truncation")[0] if p.identifier == "CoxTothTruncationPlant")
        build_fmu(plan, {str(tmp_path / "again")!r})
        again = [d.status(d.fmu.reset), d.initialize(), d.step(0.0, d.step_size)]
        print("RESULT" + json.dumps({{"first": first, "again": again, "errors": d.errors()}}))
        d.free()
    """), cwd=ROOT)
    assert result == {"first": [0, 0], "again": [0, 0, 0], "errors": []}
