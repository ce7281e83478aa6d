"""Shared pieces of the FMU tests: the FMU set built once per session."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from lpvest.fmi._parameters import Parameter
from lpvest.fmi._registry import EstimatorKind

HERE = Path(__file__).resolve().parent
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


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> FmuSet:
    """Every example system's FMUs, the affine demo's, the input-output demo's
    plant, and the moving-average estimator FMU for peixoto-ex1, built once
    into a temporary folder."""
    from lpvest.fmi._build import build_fmu, build_fmus, plan_system

    out = tmp_path_factory.mktemp("fmus")
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
    return FmuSet(out, model, paths)


@pytest.fixture(scope="session")
def experiment_fmus(fmus: FmuSet, tmp_path_factory: pytest.TempPathFactory):
    """The experiments' FMU cache for the session: the session's FMU set
    adopted (built from the current code), the rest (the epsilon = 150 and
    rho-variant H-infinity FMUs) built on first use."""
    from lpvest.experiments._fmus import ExperimentFmus

    cache = ExperimentFmus(tmp_path_factory.mktemp("experiment-fmus"))
    cache.adopt(fmus.paths)
    return cache


@pytest.fixture(scope="session")
def foreign_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The foreign C FMUs of tests/foreign_fmus.py (AllTypes, Limited), built
    once per session."""
    from .foreign_fmus import MODELS, build_foreign_fmu, compiler

    if compiler() is None:
        pytest.skip("the foreign test FMUs need a C compiler (cc or gcc)")
    out = tmp_path_factory.mktemp("foreign-fmus")
    return {name: build_foreign_fmu(name, out) for name in MODELS}


@pytest.fixture(scope="session")
def native_fmus(fmus: FmuSet, tmp_path_factory: pytest.TempPathFactory) -> FmuSet:
    """The native backend's FMUs of the same systems (every example, the affine
    demo with its designs at epsilon = 1, the own-plant example at epsilon = 1,
    the input-output demo's plant),
    built once into a temporary folder; the designs made for the Python set are
    reused (the same design cache)."""
    import shutil

    from lpvest.fmi._build import DESIGN_CACHE, build_fmus

    out = tmp_path_factory.mktemp("native-fmus")
    if (fmus.out / DESIGN_CACHE).is_dir():
        shutil.copytree(fmus.out / DESIGN_CACHE, out / DESIGN_CACHE)
    results, _ = build_fmus(None, out, backend="native")
    results2, _ = build_fmus([fmus.affine_model, OWN_PLANT], out, design_options={"epsilon": 1.0}, backend="native")
    results3, _ = build_fmus([fmus.out / "io_demo.toml"], out, roles=["Plant"], backend="native")
    done = results + results2 + results3
    paths = {r.plan.identifier: r.validation.path for r in done}
    problems = {r.plan.identifier: r.validation.problems for r in done if r.validation.problems}
    assert not problems, problems
    return FmuSet(out, fmus.affine_model, paths)
