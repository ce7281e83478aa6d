"""The package's shape, checked on its sources: the floors of
docs/architecture.md (read from its table, so the picture and the check
cannot drift apart), imports that run downwards, no import cycle between
modules or packages, private implementation modules, and no private name
crossing a module boundary. (Static: every ``import`` statement counts,
inside functions too; imports under ``TYPE_CHECKING`` never run.)"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "lpvest"
ARCHITECTURE = ROOT.parent / "docs" / "architecture.md"


def _floors() -> dict[str, int]:
    """folder (or top-level module) name -> floor, from the table of docs/architecture.md."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    table = text.split("<!-- layers")[1].split("<!-- /layers -->")[0]
    floors = {}
    for floor, name in re.findall(r"^\|\s*(\d+)\s*\|\s*`([a-z_]+)(?:/|\.py)`", table, flags=re.M):
        floors[name] = int(floor)
    return floors


FLOORS = _floors()
TOP = max(FLOORS.values()) + 1  # the package root, lpvest/__init__.py


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _layer(name: str) -> int:
    """The floor of module ``name`` (-1: in no floor)."""
    parts = name.split(".")
    if parts == ["lpvest"]:
        return TOP
    if parts == ["lpvest", "_version"]:
        return 0
    return FLOORS.get(parts[1], -1)


def _package(name: str) -> str:
    """The floor's folder of module ``name`` (``lpvest.cosim._master`` -> ``cosim``)."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else ""


def _modules() -> dict[str, Path]:
    """module name -> file, for every module of lpvest/ (not the role scripts, not the models)."""
    return {_module_name(p): p for p in ROOT.rglob("*.py") if "_fmus" not in p.parts and "_models" not in p.parts}


@functools.cache
def _imports() -> dict[str, list[tuple[str, int, list[str]]]]:
    """module -> [(imported lpvest module, line, names taken from it)]. Parsed when a
    test first asks, not at collection (every pytest process collects this file)."""
    modules = _modules()
    out: dict[str, list[tuple[str, int, list[str]]]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = []
        tree = ast.parse(path.read_text(encoding="utf-8"))
        typing_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If)
                       and "TYPE_CHECKING" in ast.unparse(block.test) for b in block.body for n in ast.walk(b)}
        for node in ast.walk(tree):
            if id(node) in typing_only:  # annotations only: never imported at run time
                continue
            if isinstance(node, ast.Import):
                found += [(a.name, node.lineno, []) for a in node.names if a.name.split(".")[0] == "lpvest"]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.split(".")[0] != "lpvest":
                    continue
                names = [a.name for a in node.names]
                submodules = [f"{target}.{n}" for n in names if f"{target}.{n}" in modules]
                found += [(s, node.lineno, []) for s in submodules]
                found.append((target, node.lineno, [n for n in names if f"{target}.{n}" not in modules]))
        out[name] = found
    return out



def test_the_floors_are_the_folders():
    # every folder (and top-level module) of lpvest/ has a floor in docs/architecture.md, and the
    # table names nothing that is not there
    present = {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    present |= {p.stem for p in ROOT.glob("*.py") if p.stem not in ("__init__", "_version")}
    assert present == set(FLOORS)
    assert len(set(FLOORS.values())) == len(FLOORS)  # one folder per floor: no two can lean on each other


def test_every_module_has_a_layer():
    assert [m for m in _imports() if _layer(m) < 0] == []


def test_imports_run_downwards():
    upward = [f"{m} (floor {_layer(m)}) imports {t} (floor {_layer(t)}) at line {line}"
              for m, found in _imports().items() if m != "lpvest" for t, line, _ in found
              if _layer(t) > _layer(m)]
    assert upward == []


def test_no_cycle_between_packages():
    graph: dict[str, set[str]] = {}
    for m, found in _imports().items():
        for t, _, _ in found:
            if _package(m) and _package(t) and _package(m) != _package(t):
                graph.setdefault(_package(m), set()).add(_package(t))
    both_ways = sorted(f"{a} <-> {b}" for a in graph for b in graph[a] if a < b and a in graph.get(b, ()))
    assert both_ways == []


def test_implementation_modules_are_private():
    # inside a package, every module but __init__ is private: the __init__ is the contract
    public = sorted(str(p.relative_to(ROOT)) for p in ROOT.rglob("*.py")
                    if p.parent != ROOT and p.name != "__init__.py" and not p.name.startswith("_"))
    assert public == []


def test_no_import_cycle():
    graph = {m: {t for t, _, _ in found if t in _imports() and t != m and not m.startswith(t + ".")}
             for m, found in _imports().items() if m != "lpvest"}
    # a package's __init__ re-exports its modules: an edge to the package is to what it holds
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append(path[path.index(nxt):] + [nxt] if nxt in path else [node, nxt])
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_no_private_name_crosses_a_module_boundary():
    crossing = [f"{m} takes {', '.join(n for n in names if n.startswith('_'))} from {t} (line {line})"
                for m, found in _imports().items() for t, line, names in found
                if any(n.startswith("_") and not n.startswith("__") for n in names)]
    assert crossing == []


@pytest.mark.parametrize("module", sorted(m for m in _modules() if m != "lpvest"))
def test_every_module_declares_its_public_names(module):
    path = ROOT.parent.joinpath(*module.split("."))
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    tree = ast.parse(path.read_text(encoding="utf-8"))
    assert any(isinstance(n, ast.Assign | ast.AnnAssign) and any(
        isinstance(t, ast.Name) and t.id == "__all__" for t in (n.targets if isinstance(n, ast.Assign) else [n.target]))
        for n in tree.body), f"{module} has no __all__"


# -- typing debt (issue #22: "Any and type: ignore at least halved, each remaining one with its reason") --
#: Lines of lpvest/ naming ``Any`` / carrying ``type: ignore`` before issue #22 (at 172ceba,
#: ``grep -rnw Any lpvest --include=*.py | wc -l`` and ``grep -rn "type: ignore" ...``).
ANY_LINES_BEFORE, IGNORE_LINES_BEFORE = 515, 48


def _library_lines() -> list[tuple[str, int, str]]:
    return [(str(p.relative_to(ROOT.parent)), i, line) for p in sorted(ROOT.rglob("*.py"))
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)]


def test_any_and_type_ignore_are_at_most_half_of_what_they_were():
    lines = _library_lines()
    any_lines = sum(1 for _, _, line in lines if re.search(r"\bAny\b", line))
    ignore_lines = sum(1 for _, _, line in lines if "type: ignore" in line)
    assert any_lines <= ANY_LINES_BEFORE // 2, any_lines
    assert ignore_lines <= IGNORE_LINES_BEFORE // 2, ignore_lines


def test_every_type_ignore_names_its_error_code_and_says_why():
    bare = [f"{path}:{i}" for path, i, line in _library_lines()
            if "type: ignore" in line and not re.search(r"type: ignore\[[-a-z, ]+\] +# \S", line)]
    assert bare == []


def test_the_costliest_test_files_run_first_and_each_listed_name_is_a_file():
    """tests/conftest.py's RUN_FIRST orders the files for xdist's load balance: a renamed file
    would silently fall back to pytest's order."""
    from types import SimpleNamespace

    from tests import conftest

    here = Path(__file__).parent
    assert [n for n in conftest.RUN_FIRST if not (here / n).is_file()] == []
    assert len(set(conftest.RUN_FIRST)) == len(conftest.RUN_FIRST)
    names = ["test_a.py", "test_sweep.py", "test_a.py", "test_native_hosts.py", "test_sweep.py"]
    items = [SimpleNamespace(path=here / n, name=f"{n}::{i}") for i, n in enumerate(names)]
    conftest.pytest_collection_modifyitems(None, None, items)
    assert [i.name for i in items] == ["test_native_hosts.py::3", "test_sweep.py::1", "test_sweep.py::4",
                                       "test_a.py::0", "test_a.py::2"]


def test_every_blas_sensitive_test_is_in_a_file_the_second_kernel_run_collects(request):
    """``./dev test`` reruns the blas_sensitive tests of the files that name the marker
    (``grep -lw blas_sensitive tests/test_*.py``): a test marked another way (a hook, a
    shared mark from another module) would silently miss the second kernel. Every
    pytest process collects every test, so the session's items are all of them."""
    marked = {item.path for item in request.session.items if item.get_closest_marker("blas_sensitive")}
    if not marked:
        pytest.skip("no blas_sensitive test collected with this one (run it with the suite)")
    missed = [p.name for p in marked if p.parent != Path(__file__).parent or not p.name.startswith("test_")
              or not re.search(r"\bblas_sensitive\b", p.read_text(encoding="utf-8"))]
    assert missed == []
    dev = (Path(__file__).parent.parent / "dev").read_text(encoding="utf-8")
    assert "grep -lw blas_sensitive tests/test_*.py" in dev


def test_xdist_hands_out_the_files_in_collection_order_with_the_dev_scripts_options(tmp_path):
    """RUN_FIRST only orders the collection: pytest-xdist's ``--dist loadfile`` would
    reorder the files by their number of tests unless told not to. Run with the
    options ``./dev test`` gives xdist (read from the script), a file of one test
    placed first runs before a file of five."""
    import re
    import shlex
    import subprocess
    import sys

    dev = (Path(__file__).parent.parent / "dev").read_text(encoding="utf-8")
    xdist = shlex.split(re.search(r'XDIST=\((-n [^)]*)\)', dev).group(1))
    assert "--no-loadscope-reorder" in xdist
    (tmp_path / "test_many.py").write_text("".join(f"def test_{i}():\n    pass\n" for i in range(5)))
    (tmp_path / "test_one.py").write_text("def test_first():\n    pass\n")
    (tmp_path / "conftest.py").write_text(
        "def pytest_collection_modifyitems(session, config, items):\n"
        "    items.sort(key=lambda item: item.path.name != 'test_one.py')\n")
    xdist[xdist.index("-n") + 1] = "1"  # one worker: it runs the files in the order they are handed out
    proc = subprocess.run([sys.executable, "-m", "pytest", *xdist, "-v", "-p", "no:cacheprovider", "-p",
                           "no:randomly", "--rootdir", str(tmp_path), "-c", "/dev/null", str(tmp_path)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ran = re.findall(r"PASSED (?:\S+::)?(test_\w+)|(?:::)(test_\w+) PASSED", proc.stdout)
    order = [a or b for a, b in ran]
    assert order[0] == "test_first" and len(order) == 6, proc.stdout


def test_the_cpu_timeline_plugin_records_each_test_and_reports_per_file(tmp_path):
    """tests/cpu_timeline.py (what RUN_FIRST is ranked by): a test that waits for a
    child burning CPU is charged with the child's CPU, and the report ranks its file first."""
    import json
    import os
    import subprocess
    import sys

    from tests.cpu_timeline import report

    (tmp_path / "test_busy.py").write_text(
        "import subprocess, sys\n"
        "def test_child():\n"
        "    subprocess.run([sys.executable, '-c', 'import time\\nt = time.process_time()\\n"
        "while time.process_time() - t < 0.3: pass'], check=True)\n")
    (tmp_path / "test_idle.py").write_text("def test_nothing():\n    pass\n")
    root = Path(__file__).parent.parent
    env = {**os.environ, "LPVEST_CPU_TIMELINE": str(tmp_path / "tl"),
           "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "tests.cpu_timeline", "-p", "no:cacheprovider",
                           "-c", "/dev/null", "--rootdir", str(tmp_path), str(tmp_path)],
                          capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    records = {json.loads(line)["id"].split("::")[-1]: json.loads(line)
               for path in (tmp_path / "tl").glob("*.jsonl") for line in path.read_text().splitlines()}
    assert set(records) == {"test_child", "test_nothing"}
    assert records["test_child"]["child"] >= 0.3 and records["test_nothing"]["child"] < 0.3
    lines = report(tmp_path / "tl")
    files = lines[lines.index("per file, costliest first:") + 1:][:2]
    assert files[0].endswith("test_busy.py") and files[1].endswith("test_idle.py"), lines


def test_pytest_keeps_its_rewritten_test_modules_where_python_may_write_no_bytecode(tmp_path):
    """tests/conftest.py's collection hook: under ``PYTHONDONTWRITEBYTECODE=1`` (our CI
    machine's setting) pytest still keeps each collected test module's rewritten code, which
    every later pytest process reads instead of rewriting it (12 -> 4 CPU-s a collection). The
    hook, loaded from tests/conftest.py as a plugin, in a pytest run of a folder of its own; its
    cache goes under ``PYTHONPYCACHEPREFIX`` (pytest honours it). Without the hook that run
    writes no file there (checked by hand: the test fails without it)."""
    import os
    import subprocess
    import sys

    (tmp_path / "tests_here").mkdir()
    (tmp_path / "tests_here" / "test_kept.py").write_text("def test_one():\n    assert 1 + 1 == 2\n")
    root = Path(__file__).parent.parent
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPYCACHEPREFIX": str(tmp_path / "pyc"),
           "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "tests.conftest", "-p", "no:cacheprovider",
                           "-c", "/dev/null", "--rootdir", str(tmp_path), str(tmp_path / "tests_here")],
                          capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    written = [p.name for p in (tmp_path / "pyc").rglob("*.pyc")] if (tmp_path / "pyc").is_dir() else []
    assert [n for n in written if n.startswith("test_kept.")] == [
        f"test_kept.{sys.implementation.cache_tag}-pytest-{pytest.__version__}.pyc"], written


# -- the lazy contracts of lpvest/__init__.py and core/__init__.py (core/_lazy.py) --
def _block_names(package: str) -> dict[str, tuple[str, str]]:
    """The names the ``if TYPE_CHECKING or ...:`` block of a package ``__init__`` imports:
    name -> (absolute module, name there), read from the source (the oracle of the tests below)."""
    import importlib.util

    path = ROOT.parent.joinpath(*package.split("."), "__init__.py")
    table: dict[str, tuple[str, str]] = {}
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for stmt in node.body:
                if isinstance(stmt, ast.ImportFrom):
                    home = importlib.util.resolve_name("." * stmt.level + (stmt.module or ""), package)
                    table.update({a.asname or a.name: (home, a.name) for a in stmt.names})
    return table


_LAZY_CHECK = """
import importlib, json, sys
package = importlib.import_module(sys.argv[1])
before = sorted(m for m in sys.modules if m.startswith("lpvest"))
for name in package.__all__:  # every public name used: the first use runs the block
    getattr(package, name)
heavy = sorted(m for m in ("scipy", "cvxpy", "matplotlib", "fmpy", "dask", "pythonfmu") if m in sys.modules)
print(json.dumps({"before": before, "dir": dir(package), "heavy": heavy,
                  "cosim": vars(sys.modules["lpvest"]).get("cosim") is not None}))
"""


@pytest.mark.parametrize("package", ["lpvest", "lpvest.core"])
def test_a_lazy_init_imports_its_block_on_first_use_and_then_is_the_eager_package(package, tmp_path):
    """Importing the package imports no public name; the first use runs the block: every
    name of ``__all__`` is then the object its import names, ``dir`` lists them, an unknown
    name is an AttributeError, and still nothing but numpy is imported (the FMUs' rule)."""
    import importlib
    import json
    import subprocess
    import sys

    table = _block_names(package)
    module = importlib.import_module(package)
    # one list: the block is __all__ (but the version, imported at once)
    assert sorted(table) == sorted(n for n in module.__all__ if n != "__version__")
    for name, (home, attr) in table.items():
        assert getattr(module, name) is getattr(importlib.import_module(home), attr), name
    with pytest.raises(AttributeError, match=f"^module '{package}' has no attribute 'not_a_name'$"):
        module.not_a_name  # noqa: B018 - the attribute access is the test
    out = json.loads(subprocess.run([sys.executable, "-c", _LAZY_CHECK, package], capture_output=True, text=True,
                                    check=True, timeout=120).stdout)
    assert out["before"] == sorted({"lpvest", "lpvest._version", "lpvest.core", "lpvest.core._lazy", package})
    assert set(module.__all__) <= set(out["dir"])
    assert out["heavy"] == []
    assert out["cosim"] == (package == "lpvest")  # the block of lpvest imports from lpvest.cosim


def test_a_lazy_init_works_where_only_compiled_files_are_installed(tmp_path):
    """A sourceless install (``compileall -b``, as frozen applications ship): the block runs
    from the loader's code object, not from the source."""
    import compileall
    import shutil
    import subprocess
    import sys

    shutil.copytree(ROOT, tmp_path / "lpvest", ignore=shutil.ignore_patterns("__pycache__", "_fmus", "_models"))
    assert compileall.compile_dir(tmp_path / "lpvest", legacy=True, quiet=1)
    for source in (tmp_path / "lpvest").rglob("*.py"):
        source.unlink()
    code = ("import lpvest, lpvest.core\n"
            "assert lpvest.__file__.endswith('.pyc'), lpvest.__file__\n"
            "print(lpvest.PolytopicLPV.__module__, lpvest.core.SignalSpec.__module__, len(dir(lpvest)))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False,
                          cwd=tmp_path, env={**__import__("os").environ, "PYTHONPATH": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    modules, signals, n = proc.stdout.split()
    assert (modules, signals) == ("lpvest.systems._polytopic", "lpvest.core._signals") and int(n) > 100


def test_importing_the_command_line_imports_no_other_lpvest_package():
    """``import lpvest.cli`` (every ``lpvest`` command starts with it) loads the package's
    lazy ``__init__`` files and the two modules the command line needs before it parses its
    arguments: no model, co-simulation or design code."""
    import subprocess
    import sys

    code = "import sys, lpvest.cli\nprint(sorted(m for m in sys.modules if m.startswith('lpvest')))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         timeout=60).stdout.strip()
    assert out == str(["lpvest", "lpvest._version", "lpvest.cli", "lpvest.core", "lpvest.core._errors",
                       "lpvest.core._interrupt", "lpvest.core._lazy"]), out
