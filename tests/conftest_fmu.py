"""Shared pieces of the FMU tests: the FMU sets, each built once per run.

Under pytest-xdist (``./dev test`` runs ``pytest -n``) every worker is a
session of its own; each set is still built once per run: the first worker to
need it builds it into the run's shared temporary folder under a file lock
(the pattern of pytest-xdist's documentation, "Making session-scoped fixtures
execute only once"), the others wait for the lock and reuse what it built.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from lpvest.fmi._parameters import Parameter
from lpvest.fmi._registry import EstimatorKind

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: The walkthrough's own plant (docs/own-plant.md).
OWN_PLANT = HERE.parent / "examples" / "own_plant.toml"

#: A two-state affine LPV plant with general noise (S != 0), input u, two
#: scheduling components: the example systems hold no affine model.
AFFINE_TOML = """
[system]
name = "affine-demo"
title = "two-state affine LPV test plant with correlated noise"
default = "plant"

[scheduling]
names = ["p1", "p2"]
lower = [-1.0, 0.0]
upper = [1.0, 2.0]

[models.plant]
type = "affine"
A = { "1" = [[0.5, 0.1], [0.0, 0.4]], p1 = [[0.1, 0.0], [0.0, -0.1]], p2 = [[0.0, 0.05], [0.02, 0.0]] }
B = [[1.0], [0.5]]
C = { "1" = [[1.0, 0.0]], p2 = [[0.0, 0.3]] }
D = [[0.2]]
Q = [[0.1, 0.02], [0.02, 0.05]]
R = [[0.01]]
S = [[0.005], [0.0]]
"""

#: A SISO input-output model (Cox & Toth (21a)'s form) with functions in its
#: coefficients: the example systems stream a state-space realization instead.
IO_TOML = """
[system]
name = "io-demo"
title = "SISO LPV input-output test plant"
default = "io"

[scheduling]
names = ["p"]
lower = [-1.0]
upper = [1.0]

[models.io]
type = "lpv-io"
y = ["-0.5 * p", "0.1 * cos(p)"]
u = [0, "p", 0.2]
e = ["0.3 * sin(p)"]
noise_variance = 0.5
"""

#: The test-only estimator kind (a moving average, tests/fmu_movavg.py).
MOVING_AVERAGE = EstimatorKind(
    "MovingAverage",
    "fmu_movavg:build",
    models=("polytopic",),
    parameters=(Parameter("window", 4, "window length", minimum=1),),
    files=(HERE / "fmu_movavg.py",),
)


@dataclass(frozen=True)
class FmuSet:
    out: Path
    affine_model: Path
    paths: dict[str, Path]

    def __getitem__(self, name: str) -> Path:
        return self.paths[name]


    def to_json(self) -> dict[str, object]:
        return {"out": str(self.out), "affine_model": str(self.affine_model),
                "paths": {k: str(v) for k, v in self.paths.items()}}

    @classmethod
    def from_json(cls, data: dict) -> FmuSet:
        return cls(Path(data["out"]), Path(data["affine_model"]), {k: Path(v) for k, v in data["paths"].items()})


def built_once(factory: pytest.TempPathFactory, name: str, build: Callable[[Path], dict]) -> dict:
    """What ``build(folder)`` returns (JSON data), built once per test run.

    Without xdist: into a fresh temporary folder. Under xdist: into
    ``<the run's temporary folder>/<name>``, by the first worker that gets
    the file lock; the result is recorded next to it as JSON, and every other
    worker waits for the lock and reads the record. A build that raised records
    nothing: the next worker builds again (and reports its own error).

    ``$LPVEST_TEST_SHARED_DIR`` (set by ``./dev test`` for its two pytest runs,
    the second under another BLAS kernel, on the same code) takes the place of
    the run's folder: the second run reuses what the first built. An FMU's
    build does not depend on the BLAS kernel; running it does, and that is what
    the second run repeats."""
    shared = os.environ.get("LPVEST_TEST_SHARED_DIR")
    if not shared and os.environ.get("PYTEST_XDIST_WORKER") is None:
        return build(factory.mktemp(name))
    from filelock import FileLock

    # the folder the workers of one run (or the runs of one ./dev test) share
    root = Path(shared) if shared else factory.getbasetemp().parent
    record = root / f"{name}.json"
    with FileLock(root / f"{name}.lock"):
        if record.is_file():
            return json.loads(record.read_text(encoding="utf-8"))
        out = root / name
        shutil.rmtree(out, ignore_errors=True)  # what a failed build left
        out.mkdir()
        data = build(out)
        part = record.with_suffix(".json.part")
        part.write_text(json.dumps(data), encoding="utf-8")
        part.replace(record)
        return data


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> FmuSet:
    """Every example system's FMUs, the affine demo's, the input-output demo's
    plant, and the moving-average estimator FMU for peixoto-ex1, built once per
    run into a temporary folder."""
    return FmuSet.from_json(built_once(tmp_path_factory, "fmus", _build_fmus))


def _build_fmus(out: Path) -> dict:
    from lpvest.fmi._build import build_fmu, build_fmus, plan_system

    model = out / "affine_demo.toml"
    model.write_text(AFFINE_TOML)
    results, _ = build_fmus(None, out)
    # its H-infinity filters designed at one epsilon (a search of this 4-vertex plant takes minutes)
    results2, _ = build_fmus([model], out, design_options={"epsilon": 1.0})
    io = out / "io_demo.toml"
    io.write_text(IO_TOML)
    results3, _ = build_fmus([io], out, roles=["Plant"])
    paths = {r.plan.identifier: r.validation.path for r in results + results2 + results3}
    plans, _ = plan_system("peixoto-ex1", kinds=[MOVING_AVERAGE])
    est = next(p for p in plans if p.role == "MovingAverage")
    paths[est.identifier] = build_fmu(est, out)
    return FmuSet(out, model, paths).to_json()


@pytest.fixture(scope="session")
def experiment_fmus(fmus: FmuSet, tmp_path_factory: pytest.TempPathFactory):
    """The experiments' FMU cache for the run: the session's FMU set adopted
    (built from the current code), the rest of the catalog (the epsilon = 150
    and rho-variant H-infinity FMUs, from the stored designs: about a second
    each) built up front, so that no two xdist workers build into the folder."""
    from lpvest.experiments._fmus import CATALOG, ExperimentFmus

    def build(out: Path) -> dict:
        cache = ExperimentFmus(out)
        cache.adopt(fmus.paths)
        cache.paths(CATALOG)
        return {"directory": str(out)}

    return ExperimentFmus(built_once(tmp_path_factory, "experiment-fmus", build)["directory"])


@pytest.fixture(scope="session")
def foreign_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The foreign C FMUs of tests/foreign_fmus.py (AllTypes, Limited), built
    once per run."""
    from .foreign_fmus import MODELS, build_foreign_fmu, compiler

    if compiler() is None:
        pytest.skip("the foreign test FMUs need a C compiler (cc or gcc)")

    def build(out: Path) -> dict:
        return {name: str(build_foreign_fmu(name, out)) for name in MODELS}

    return {name: Path(path) for name, path in built_once(tmp_path_factory, "foreign-fmus", build).items()}


@pytest.fixture(scope="session")
def native_fmus(fmus: FmuSet, tmp_path_factory: pytest.TempPathFactory) -> FmuSet:
    """The native backend's FMUs of the same systems (every example, the affine
    demo with its designs at epsilon = 1, the own-plant example at epsilon = 1,
    the input-output demo's plant),
    built once per run into a temporary folder; the designs made for the Python
    set are reused (the same design cache)."""

    def build(out: Path) -> dict:
        from lpvest.fmi._build import DESIGN_CACHE, build_fmus

        if (fmus.out / DESIGN_CACHE).is_dir():
            shutil.copytree(fmus.out / DESIGN_CACHE, out / DESIGN_CACHE)
        results, _ = build_fmus(None, out, backend="native")
        results2, _ = build_fmus([fmus.affine_model, OWN_PLANT], out, design_options={"epsilon": 1.0},
                                 backend="native")
        results3, _ = build_fmus([fmus.out / "io_demo.toml"], out, roles=["Plant"], backend="native")
        done = results + results2 + results3
        paths = {r.plan.identifier: r.validation.path for r in done}
        problems = {r.plan.identifier: r.validation.problems for r in done if r.validation.problems}
        assert not problems, problems
        return FmuSet(out, fmus.affine_model, paths).to_json()

    return FmuSet.from_json(built_once(tmp_path_factory, "native-fmus", build))


@dataclass(frozen=True)
class ScriptBuild:
    """What ``python build_fmus.py --out OUT`` did: its exit status, its output, the folder."""

    returncode: int
    stdout: str
    stderr: str
    out: Path


@pytest.fixture(scope="session")
def script_build(tmp_path_factory: pytest.TempPathFactory) -> ScriptBuild:
    """Every example system's FMUs built from scratch by ``build_fmus.py`` in a
    fresh process (in the repository, into a folder of its own), once per run:
    tests/test_fmu_hosts.py checks the script, tests/test_fmu_isolation.py that
    its FMUs have the bytes of the session's set (built in another process)."""

    def build(out: Path) -> dict:
        proc = subprocess.run([sys.executable, str(ROOT / "build_fmus.py"), "--out", str(out)], capture_output=True,
                              text=True, timeout=600, check=False, cwd=ROOT)
        return {"returncode": proc.returncode, "stdout": proc.stdout, "stderr": proc.stderr, "out": str(out)}

    data = built_once(tmp_path_factory, "script-build", build)
    return ScriptBuild(data["returncode"], data["stdout"], data["stderr"], Path(data["out"]))
