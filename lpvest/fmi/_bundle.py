"""What an lpvest FMU carries, and how it loads it without touching the host.

pythonfmu runs an FMU's Python slave inside the host's interpreter when the
host is Python (fmpy, libcosimpy, a Dask worker), or inside the one interpreter
a C host loaded: every FMU of a process shares ``sys.modules``. If each FMU
carried ``lpvest`` under its plain name, the first one loaded would serve all
later ones, a host's own ``lpvest`` would shadow or be shadowed by the bundled
copies, and deleting the first FMU's unpacked folder (fmpy does, after
``simulate_fmu``) would break every lazy import of the others. So an FMU
carries:

- a **private package** ``lpvest_<digest>`` in ``resources/``: the modules of
  ``lpvest`` its component imports (the static import closure of its slave
  script and factory, nothing else), pythonfmu's Python files as the
  subpackage ``_pythonfmu``, the role script as ``_fmus.<script>`` and extra
  estimator modules as ``_ext.<name>``. Absolute imports of ``lpvest``,
  ``pythonfmu`` and the extra modules are rewritten to the private names (on
  the same lines, so tracebacks point at the right line); package
  ``__init__`` files are replaced by empty ones, so importing one module does
  not import its siblings (the version is in ``_version``). ``<digest>`` is
  a SHA-256 of the carried sources: two FMUs share the name only when they
  carry the same code, and then sharing their modules is harmless;
- an **entry module** ``lpvest_<digest>_entry.py`` (named in
  ``slavemodule.txt``, imported by pythonfmu's binary): it reads every source
  of the private package into memory, installs a finder on ``sys.meta_path``
  that serves exactly that package from memory, takes ``resources/`` back off
  ``sys.path``, and imports the slave class. Once loaded, the package never
  touches the disk again: a later deletion of the folder, a second instance
  unpacked elsewhere, or any other lpvest (installed, imported, or bundled in
  another FMU of another version) cannot change what this FMU runs, and the
  FMU cannot change theirs.

``requirements.txt`` is derived from the same closure: the third-party
packages imported at module level by a carried module, plus what the role
declares for code it imports inside functions (scipy for the integrating LTV
plant, the B-spline observer and the truncated filter's steady-state start).
Third-party imports found only inside functions are recorded in the manifest.

This module imports only the standard library.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import io
import sys
import tokenize
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..core._errors import LpvestError

__all__ = ["Bundle", "BundleError", "SourceRoot", "make_bundle", "KNOWN_REQUIREMENTS", "BUNDLE_FORMAT"]

#: Version of the bundle layout (part of every digest).
BUNDLE_FORMAT = "lpvest-bundle-2"

#: The requirement line written for each third-party package an FMU may import.
KNOWN_REQUIREMENTS: dict[str, str] = {"numpy": "numpy>=1.26", "scipy": "scipy>=1.11"}


class BundleError(LpvestError, RuntimeError):
    """The code an FMU would carry breaks a bundling rule (named in the message)."""


@dataclass(frozen=True)
class SourceRoot:
    """A top-level name whose modules an FMU may carry, and where they are.

    ``name`` is the dotted name the code imports (``lpvest``, ``pythonfmu``,
    ``lpvest._fmus``, ``fmu_movavg``); ``path`` a package folder or a single
    ``.py`` file; ``target`` the name inside the private package (``""`` for
    the package itself, ``"_pythonfmu"``, ``"_fmus"``, ``"_ext.fmu_movavg"``).
    """

    name: str
    path: Path
    target: str
    skip: tuple[str, ...] = ()


@dataclass(frozen=True)
class _Module:
    name: str  # original dotted name
    path: Path
    is_package: bool
    text: str


@dataclass(frozen=True)
class Bundle:
    """The private package of one FMU (see the module documentation)."""

    package: str
    entry: str
    files: Mapping[str, bytes]
    modules: tuple[str, ...]
    requirements: tuple[str, ...]
    lazy_imports: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    digest: str = ""
    roots: tuple[SourceRoot, ...] = ()

    def rename(self, dotted: str) -> str:
        """The private name of an original dotted module name (``lpvest.fmi``
        -> ``lpvest_<digest>.fmi.slave``)."""
        renamed = _rename(dotted, self.roots, self.package)
        if renamed is None:
            raise BundleError(f"{dotted!r} is not a module this FMU carries")
        return renamed

    def reference(self, target: str) -> str:
        """``"module:function"`` with the module renamed into the private package."""
        module, sep, name = target.partition(":")
        if not sep:
            raise BundleError(f"{target!r} is not of the form 'module:function'")
        return f"{self.rename(module)}:{name}"


# -- module discovery -------------------------------------------------------------


def _root_of(name: str, roots: Sequence[SourceRoot]) -> SourceRoot | None:
    best = None
    for root in roots:
        if name == root.name or name.startswith(root.name + "."):
            if best is None or len(root.name) > len(best.name):
                best = root
    return best


def _rename(name: str, roots: Sequence[SourceRoot], package: str) -> str | None:
    root = _root_of(name, roots)
    if root is None:
        return None
    rest = name[len(root.name):]
    head = package + ("." + root.target if root.target else "")
    return head + rest


def _locate(name: str, roots: Sequence[SourceRoot]) -> _Module | None:
    root = _root_of(name, roots)
    if root is None:
        return None
    parts = name[len(root.name):].lstrip(".").split(".") if name != root.name else []
    if parts and parts[0] in root.skip:
        return None
    base = root.path
    if base.is_file():
        if parts:
            return None
        return _Module(name, base, False, base.read_text(encoding="utf-8"))
    path = base.joinpath(*parts)
    if (path / "__init__.py").is_file():
        return _Module(name, path / "__init__.py", True, (path / "__init__.py").read_text(encoding="utf-8"))
    if parts and path.with_suffix(".py").is_file():
        f = path.with_suffix(".py")
        return _Module(name, f, False, f.read_text(encoding="utf-8"))
    return None


def _absolute(node: ast.ImportFrom, module: _Module) -> str:
    if not node.level:
        return node.module or ""
    package = module.name if module.is_package else module.name.rpartition(".")[0]
    parts = package.split(".") if package else []  # a top-level module has no package to be relative to
    if node.level - 1 > len(parts) - 1:
        raise BundleError(f"{module.path}: relative import beyond the top-level package")
    base = parts[: len(parts) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _module_level_nodes(tree: ast.Module) -> set[int]:
    """ids of the import nodes that run when the module is imported (not inside
    a function, not under ``if TYPE_CHECKING:``)."""
    found: set[int] = set()

    def visit(body: Iterable[ast.stmt]) -> None:
        for stmt in body:
            if isinstance(stmt, ast.Import | ast.ImportFrom):
                found.add(id(stmt))
            elif isinstance(stmt, ast.If):
                test = stmt.test
                if isinstance(test, ast.Name) and test.id == "TYPE_CHECKING" or (
                    isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
                ):
                    visit(stmt.orelse)
                    continue
                visit(stmt.body)
                visit(stmt.orelse)
            elif isinstance(stmt, ast.Try):
                visit(stmt.body)
                for handler in stmt.handlers:
                    visit(handler.body)
                visit(stmt.orelse)
                visit(stmt.finalbody)
            elif isinstance(stmt, ast.With | ast.For | ast.While):
                visit(stmt.body)
                visit(getattr(stmt, "orelse", []))
            elif isinstance(stmt, ast.ClassDef):
                visit(stmt.body)

    visit(tree.body)
    return found


def _find_imports(text: str, filename: str) -> tuple[tuple[ast.Import | ast.ImportFrom, bool], ...]:
    """The import statements of a module's source, in ``ast.walk`` order, each
    with whether it runs when the module is imported (kept per source text by
    :func:`_imports`)."""
    tree = ast.parse(text, filename)
    eager = _module_level_nodes(tree)
    return tuple((node, id(node) in eager) for node in ast.walk(tree) if isinstance(node, ast.Import | ast.ImportFrom))


#: :func:`_find_imports` kept per source text for the process: every FMU of a build or of a
#: cache check carries most of the same modules, and parsing them again for each was most of
#: the time of fingerprinting the experiments' 23 FMUs (6 s of CPU). Wrapped by assignment,
#: not decorated: mutation testing (mutmut) leaves decorated functions out.
_imports = functools.cache(_find_imports)


@dataclass
class _Scan:
    carried: dict[str, _Module] = field(default_factory=dict)
    hard: dict[str, set[str]] = field(default_factory=dict)  # third-party -> modules importing it at module level
    lazy: dict[str, set[str]] = field(default_factory=dict)  # third-party -> modules importing it in functions


def _scan(start: Sequence[str], roots: Sequence[SourceRoot]) -> _Scan:
    scan = _Scan()
    todo = list(start)
    stdlib = sys.stdlib_module_names  # __future__ included
    while todo:
        name = todo.pop()
        if name in scan.carried:
            continue
        module = _locate(name, roots)
        if module is None:
            raise BundleError(f"cannot find the module {name!r} to carry in the FMU")
        scan.carried[name] = module
        parent = name.rpartition(".")[0]
        if parent and _root_of(parent, roots) is not None and _locate(parent, roots) is not None:
            todo.append(parent)
        if module.is_package:
            continue  # carried as an empty package: its imports are not run
        for node, eager in _imports(module.text, str(module.path)):
            targets: list[tuple[str, list[str] | None]]
            if isinstance(node, ast.Import):
                targets = [(a.name, None) for a in node.names]
            else:
                targets = [(_absolute(node, module), [a.name for a in node.names])]
            for target, names in targets:
                top = target.split(".")[0]
                if _root_of(target, roots) is None:
                    if top in stdlib or not top:
                        continue
                    (scan.hard if eager else scan.lazy).setdefault(top, set()).add(name)
                    continue
                found = _locate(target, roots)
                if found is None:
                    raise BundleError(f"{module.path}:{node.lineno}: imports {target!r}, which does not exist")
                todo.append(target)
                for n in names or ():
                    if n == "*":
                        raise BundleError(f"{module.path}:{node.lineno}: 'import *' cannot be carried into an FMU")
                    sub = _locate(f"{target}.{n}", roots)
                    if sub is not None:
                        todo.append(sub.name)
                    elif found.is_package:
                        raise BundleError(
                            f"{module.path}:{node.lineno}: 'from {target} import {n}' takes {n} from a package "
                            f"__init__, which an FMU carries empty; import it from the module that defines it"
                        )
    return scan


# -- rewriting ------------------------------------------------------------------------


def _rewrite(module: _Module, roots: Sequence[SourceRoot], package: str) -> str:
    """The source with absolute imports of carried names renamed, on the same lines."""
    spans = _import_spans(module.text, str(module.path), tuple(roots))
    if not spans:
        return module.text
    lines = module.text.splitlines(keepends=True)
    for line, start, end, name in reversed(spans):
        new = _rename(name, roots, package)
        assert new is not None  # a span names a carried module
        row = lines[line - 1]
        lines[line - 1] = row[:start] + new + row[end:]
    return "".join(lines)


def _find_import_spans(text: str, filename: str,
                       roots: tuple[SourceRoot, ...]) -> tuple[tuple[int, int, int, str], ...]:
    """Where a module's source names a carried module in an absolute import:
    ``(line, start column, end column, dotted name)``, in source order (kept per
    source text by :func:`_import_spans`)."""
    starts: set[tuple[int, int]] = set()  # (line, column) of each import statement to rewrite
    for node, _ in _imports(text, filename):
        if isinstance(node, ast.ImportFrom) and not node.level and node.module:
            if _root_of(node.module, roots) is not None:
                starts.add((node.lineno, node.col_offset))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if _root_of(alias.name, roots) is not None:
                    if alias.asname is None:
                        raise BundleError(
                            f"{filename}:{node.lineno}: 'import {alias.name}' binds the name "
                            f"{alias.name.split('.')[0]!r}, which an FMU renames; write "
                            f"'from {alias.name.rpartition('.')[0] or alias.name} import ...' or 'import ... as ...'"
                        )
                    starts.add((node.lineno, node.col_offset))
    if not starts:
        return ()
    tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    spans: list[tuple[int, int, int, str]] = []
    i = 0
    while i < len(tokens):
        tok = tokens[i]
        if tok.type == tokenize.NAME and tok.string in ("from", "import") and tok.start in starts:
            # a dotted name follows (from X.Y import ... / import X.Y as Z, A.B as C)
            j = i + 1
            while j < len(tokens) and tokens[j].type != tokenize.NEWLINE:
                if tokens[j].type == tokenize.NAME and tokens[j].string not in ("as", "import"):
                    k = j
                    dotted = [tokens[k]]
                    while (k + 2 < len(tokens) and tokens[k + 1].string == "."
                           and tokens[k + 2].type == tokenize.NAME):
                        k += 2
                        dotted.append(tokens[k])
                    name = ".".join(t.string for t in dotted)
                    prev = tokens[j - 1].string
                    if _root_of(name, roots) is not None and prev in ("from", "import", ","):
                        first, last = dotted[0], dotted[-1]
                        if first.start[0] != last.end[0]:
                            raise BundleError(f"{filename}:{first.start[0]}: a module name split over lines")
                        spans.append((first.start[0], first.start[1], last.end[1], name))
                    j = k + 1
                    if tok.string == "from":
                        break  # only the module of 'from X import ...'
                    continue
                j += 1
            i = j
            continue
        i += 1
    return tuple(sorted(spans))


#: :func:`_find_import_spans` kept per source text for the process, as :func:`_imports` is: the
#: spans do not depend on the FMU's private package name, and tokenizing every carried module
#: again for each FMU was half the time of bundling one (every fingerprint of the FMU cache
#: bundles). Wrapped by assignment for mutation testing, as :func:`_imports` is.
_import_spans = functools.lru_cache(maxsize=1024)(_find_import_spans)


# -- the entry module ------------------------------------------------------------------

_ENTRY = '''"""Entry module of the lpvest FMU {identifier} (written by lpvest's builder).

pythonfmu imports this module by the name in slavemodule.txt. It loads the
FMU's private copy of lpvest, the package {package} next to this file, into
memory under that build-unique name (see lpvest.fmi._bundle), and exposes the
slave class. Nothing else in the process is changed: no other module is
replaced, and resources/ is taken back off sys.path.
"""

import sys

# pythonfmu's binary (findClass) executes this file again at every
# instantiation, with this module's namespace as globals and a fresh dict as
# locals, and then releases a reference to that namespace which it never took
# (PyModule_GetDict's reference is borrowed): without one taken for it, the
# namespace is freed after a few instances and the host crashes (seen with
# libcosim). So each such execution takes one bare reference (Py_IncRef),
# owned by no object, which findClass's release then gives back. A reference
# held by an object instead (a list in this namespace, until bundle format 2)
# is released a second time when the interpreter, at its end, clears the
# modules still alive: the namespace was freed while this module still used
# it (heap corruption at the exit of a host that had instantiated an FMU a
# few times). An import (locals are the globals) releases nothing: nothing
# is taken then.
if locals() is not globals():
    import ctypes

    ctypes.pythonapi.Py_IncRef(ctypes.py_object(globals()))
    del ctypes


def _unlist(entry):
    """Take back off sys.path the resources folder pythonfmu's binary inserted
    at sys.path[0] before executing this module (it does so at every
    instantiation, for the folder of that instance's unpacked copy, which
    need not be this module's): sys.path[0] is removed when it is a
    resources folder of this FMU, and only then."""
    import os

    first = sys.path[0] if sys.path else None
    if isinstance(first, str) and os.path.isfile(os.path.join(first, "slavemodule.txt")) and os.path.isfile(
        os.path.join(first, entry)
    ):
        del sys.path[0]


def _load(package):
    if package in sys.modules:
        return
    import importlib.abc
    import importlib.util
    import os

    here = os.path.dirname(os.path.abspath(__file__))
    sources = {{}}
    for folder, subfolders, names in os.walk(os.path.join(here, package)):
        subfolders.sort()
        for name in sorted(names):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                parts = os.path.relpath(path, here)[:-3].split(os.sep)
                is_package = parts[-1] == "__init__"
                if is_package:
                    parts = parts[:-1]
                with open(path, "rb") as f:
                    sources[".".join(parts)] = (path, f.read(), is_package)

    class Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
        """Serves the modules of one FMU's private package from memory."""

        def __init__(self):
            self.package = package

        def find_spec(self, fullname, path=None, target=None):
            found = sources.get(fullname)
            if found is None:
                return None
            return importlib.util.spec_from_loader(fullname, self, origin=found[0], is_package=found[2])

        def create_module(self, spec):
            return None

        def exec_module(self, module):
            path, source, _ = sources[module.__spec__.name]
            module.__file__ = path
            exec(compile(source, path, "exec"), module.__dict__)

    sys.meta_path.insert(0, Finder())


_unlist("{entry}.py")
_load("{package}")

from {package}._fmus.{script} import {cls} as {cls}  # noqa: E402
'''


def _digest(modules: Mapping[str, _Module], roots: Sequence[SourceRoot]) -> str:
    """The bundle's identity: its format, its roots, every module's text, and the entry
    module's template (a change to it alone gives new package names, and the FMU cache,
    which keys on this digest, builds again)."""
    h = hashlib.sha256(BUNDLE_FORMAT.encode() + b"\0")
    h.update(hashlib.sha256(_ENTRY.encode()).digest())
    for root in sorted(roots, key=lambda r: r.name):
        h.update(f"{root.name}->{root.target}\0".encode())
    for name in sorted(modules):
        m = modules[name]
        h.update(name.encode() + b"\0" + (b"P" if m.is_package else b"M") + b"\0")
        h.update(hashlib.sha256(m.text.encode()).digest())
    return h.hexdigest()


def _init_text(module: _Module, root: SourceRoot, version: str) -> str:
    if module.name == root.name and root.target == "":
        return (f'"""lpvest {version}, as carried by an lpvest FMU: only the modules its component imports;\n'
                f'package __init__ files are empty (see lpvest.fmi._bundle)."""\n')
    return f'"""{module.name}, as carried by an lpvest FMU (empty: see lpvest.fmi._bundle)."""\n'


def make_bundle(
    *,
    identifier: str,
    script: str,
    slave_class: str,
    start: Sequence[str],
    roots: Sequence[SourceRoot],
    version: str,
    declared: Iterable[str] = (),
) -> Bundle:
    """The private package of one FMU.

    Parameters
    ----------
    identifier : str
        The FMU's model identifier (named in the entry module's docstring).
    script : str
        The role script's module name under ``lpvest._fmus`` (``lpvest_plant``).
    slave_class : str
        The slave class the role script defines.
    start : sequence of str
        Original dotted names of the modules the component needs (the role
        script, the factory module, ...): the closure is computed from these.
    roots : sequence of SourceRoot
        Where carried names come from (``lpvest``, ``pythonfmu``, extra modules).
    version : str
        The lpvest version (named in the private package's docstring).
    declared : iterable of str
        Third-party packages the role needs beyond its module-level imports.
    """
    scan = _scan(start, roots)
    package = "lpvest_" + _digest(scan.carried, roots)[:16]
    entry = package + "_entry"
    files: dict[str, bytes] = {}
    for name, module in sorted(scan.carried.items()):
        renamed = _rename(name, roots, package)
        assert renamed is not None
        parts = renamed.split(".")
        rel = "/".join(parts) + ("/__init__.py" if module.is_package else ".py")
        root = _root_of(name, roots)
        assert root is not None
        text = _init_text(module, root, version) if module.is_package else _rewrite(module, roots, package)
        files[rel] = text.encode("utf-8")
    # every folder on the way is a package
    for rel in list(files):
        parts = rel.split("/")[:-1]
        for i in range(1, len(parts) + 1):
            init = "/".join(parts[:i]) + "/__init__.py"
            if init not in files:
                files[init] = f'"""{".".join(parts[:i])}: part of an lpvest FMU\'s private package."""\n'.encode()
    files[f"{entry}.py"] = _ENTRY.format(identifier=identifier, package=package, entry=entry, script=script,
                                         cls=slave_class).encode("utf-8")
    needed = set(scan.hard) | set(declared)
    unknown = sorted(n for n in needed if n not in KNOWN_REQUIREMENTS)
    if unknown:
        where = "; ".join(f"{n} (imported by {', '.join(sorted(scan.hard.get(n, {'the role'})))})" for n in unknown)
        raise BundleError(f"{identifier}: the FMU would need third-party packages lpvest cannot declare: {where}")
    requirements = tuple(KNOWN_REQUIREMENTS[n] for n in sorted(needed))
    lazy = {n: tuple(sorted(mods)) for n, mods in sorted(scan.lazy.items()) if n not in needed}
    return Bundle(package, entry, dict(sorted(files.items())), tuple(sorted(scan.carried)), requirements, lazy,
                  _digest(scan.carried, roots), tuple(roots))
