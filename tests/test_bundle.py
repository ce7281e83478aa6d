"""What an FMU carries (lpvest/fmi/_bundle.py), in this process: the import scan, the rewrite,
the private package's files, and the entry module's finder. The hygiene of many instances in
one host (sys.path, sys.modules, sys.meta_path) is tested through built FMUs elsewhere."""

from __future__ import annotations

import ctypes
import importlib.util
import re
import shutil
import sys
import textwrap
from pathlib import Path

import pytest

from lpvest.fmi._bundle import BUNDLE_FORMAT, Bundle, BundleError, SourceRoot, make_bundle
from tests.fmu_driver import references_held


def _tree(base: Path, files: dict[str, str]) -> Path:
    root = base / "src"
    for rel, text in files.items():
        f = root / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(textwrap.dedent(text))
    return root


def _bundle(root: Path, *, start=("lpvest._fmus.role",), extra_roots=(), **kw) -> Bundle:
    roots = [SourceRoot("pkg", root / "pkg", ""), SourceRoot("lpvest._fmus", root, "_fmus"), *extra_roots]
    return make_bundle(identifier=kw.pop("identifier", "X"), script="role", slave_class="Slave", start=list(start),
                       roots=roots, version="9", **kw)


PKG = {
    "pkg/__init__.py": "import numpy\n",
    "pkg/core/__init__.py": "",
    "pkg/core/a.py": """\
        from __future__ import annotations

        import os
        from typing import TYPE_CHECKING

        from . import b
        from .b import g
        from ..util import h

        if TYPE_CHECKING:
            import cvxpy
        try:
            import numpy as np
        except ImportError:
            np = None
        else:
            import scipy
        finally:
            pass
        with open(os.devnull):
            import tomllib
        for _ in ():
            import json
        while False:
            import csv


        class K:
            import dataclasses


        def f():
            import matplotlib  # only when called
            return g() + h()
        """,
    "pkg/core/b.py": "def g():\n    return 1\n",
    "pkg/util.py": "def h():\n    return 2\n",
    "role.py": "from pkg.core.a import f, K\n\n\nclass Slave:\n    value = f()\n",
}


def test_the_scan_follows_module_level_and_relative_imports_and_sorts_third_party_ones(tmp_path):
    root = _tree(tmp_path, PKG)
    b = _bundle(root)
    assert b.modules == ("lpvest._fmus.role", "pkg", "pkg.core", "pkg.core.a", "pkg.core.b",
                         "pkg.util")
    # numpy and scipy run at import (try/else); cvxpy only under TYPE_CHECKING; matplotlib in a function
    assert b.requirements == ("numpy>=1.26", "scipy>=1.11")
    assert b.lazy_imports == {"cvxpy": ("pkg.core.a",), "matplotlib": ("pkg.core.a",)}
    assert b.digest.startswith(b.package.removeprefix("lpvest_")) and len(b.digest) == 64
    p = b.package
    # every folder on the way is a package; the package __init__ files are carried empty
    assert {f"{p}/__init__.py", f"{p}/core/__init__.py", f"{p}/_fmus/__init__.py", f"{p}/core/a.py",
            f"{p}/core/b.py", f"{p}/util.py", f"{p}/_fmus/role.py", f"{b.entry}.py"} == set(b.files)
    assert b.files[f"{p}/__init__.py"] == (b'"""lpvest 9, as carried by an lpvest FMU: only the modules its '
                                           b'component imports;\npackage __init__ files are empty (see '
                                           b'lpvest.fmi._bundle)."""\n')
    assert b.files[f"{p}/core/__init__.py"] == (
        b'"""pkg.core, as carried by an lpvest FMU (empty: see lpvest.fmi._bundle)."""\n')
    # a folder root (no __init__.py of its own): a package made for the way
    made = f'"""{p}._fmus: part of an lpvest FMU\'s private package."""\n'
    assert b.files[f"{p}/_fmus/__init__.py"] == made.encode()
    assert b.files[f"{p}/_fmus/role.py"].decode() == PKG["role.py"].replace("from pkg.", f"from {p}.")
    assert b.files[f"{p}/core/a.py"].decode() == textwrap.dedent(PKG["pkg/core/a.py"])  # relative: unchanged
    entry = b.files[f"{b.entry}.py"].decode()
    assert f'_load("{p}")' in entry and f"from {p}._fmus.role import Slave as Slave" in entry
    assert "Entry module of the lpvest FMU X" in entry
    assert b.rename("pkg.core.a") == f"{p}.core.a" and b.rename("lpvest._fmus.role") == f"{p}._fmus.role"
    assert b.reference("pkg.util:h") == f"{p}.util:h"


def test_declared_packages_become_requirements_and_unknown_ones_are_refused(tmp_path):
    root = _tree(tmp_path, PKG)
    b = _bundle(root, declared=["scipy", "numpy"])
    assert b.requirements == ("numpy>=1.26", "scipy>=1.11")
    with pytest.raises(BundleError, match=r"^X: the FMU would need third-party packages lpvest cannot declare: "
                                          r"cvxpy \(imported by the role\)$"):
        _bundle(root, declared=["cvxpy"])
    (root / "pkg" / "util.py").write_text("import yaml\nimport zarr\n\n\ndef h():\n    return 2\n")
    with pytest.raises(BundleError, match=r"cannot declare: yaml \(imported by pkg.util\); zarr \(imported by "
                                          r"pkg.util\)$"):
        _bundle(root)


def test_names_outside_the_roots_and_malformed_references_are_refused(tmp_path):
    b = _bundle(_tree(tmp_path, PKG))
    with pytest.raises(BundleError, match=r"^'other.mod' is not a module this FMU carries$"):
        b.rename("other.mod")
    with pytest.raises(BundleError, match=r"^'pkg.util.h' is not of the form 'module:function'$"):
        b.reference("pkg.util.h")
    with pytest.raises(BundleError, match=r"^'pkgx' is not a module this FMU carries$"):
        b.rename("pkgx")  # a prefix of a root's name is not that root


def test_the_digest_names_the_code_and_where_it_goes(tmp_path):
    root = _tree(tmp_path, PKG)
    a = _bundle(root)
    assert _bundle(root).package == a.package  # the same sources: the same name
    assert _bundle(root, identifier="Y").package == a.package  # the FMU's name is not part of the code
    (root / "pkg" / "util.py").write_text("def h():\n    return 3\n")
    assert _bundle(root).package != a.package
    assert BUNDLE_FORMAT == "lpvest-bundle-2"


def test_a_changed_entry_module_template_gives_new_package_names(tmp_path, monkeypatch):
    """The entry module (what pythonfmu runs) is part of the digest: a fix to it alone
    gives every FMU a new package name, so no cache keeps serving the old entry."""
    import lpvest.fmi._bundle as bundle

    root = _tree(tmp_path, PKG)
    before = _bundle(root).package
    monkeypatch.setattr(bundle, "_ENTRY", bundle._ENTRY + "# changed\n")
    assert _bundle(root).package != before


@pytest.mark.parametrize(("files", "match"), [
    ({"role.py": "from ...pkg import f\n"}, r"role.py: relative import beyond the top-level package"),
    ({"role.py": "from pkg.core import b, nothere\n"},
     r"role.py:1: 'from pkg.core import nothere' takes nothere from a package __init__"),
    ({"role.py": "from pkg.util import *\n"}, r"role.py:1: 'import \*' cannot be carried into an FMU"),
    ({"role.py": "import pkg.util, os\n"}, r"role.py:1: 'import pkg.util' binds the name 'pkg', which an FMU "
                                            r"renames; write 'from pkg import ...' or 'import ... as ...'"),
    ({"role.py": "import pkg as p\n"}, r"role.py:1: 'import pkg' binds the name 'pkg'|^$"),
    ({"role.py": "from pkg.gone import x\n"}, r"role.py:1: imports 'pkg.gone', which does not exist"),
    ({"role.py": "from pkg . \\\n  util import h\n"}, r"role.py:1: a module name split over lines"),
])
def test_what_cannot_be_carried_is_refused_naming_file_and_line(tmp_path, files, match):
    tree = dict(PKG)
    tree.update(files)
    root = _tree(tmp_path, tree)
    if files["role.py"] == "import pkg as p\n":
        b = _bundle(root)  # an alias binds no renamed name: carried, and renamed
        assert b.files[f"{b.package}/_fmus/role.py"].decode() == f"import {b.package} as p\n"
        return
    with pytest.raises(BundleError, match=match):
        _bundle(root)


def test_a_missing_start_module_and_skipped_folders_are_not_carried(tmp_path):
    root = _tree(tmp_path, PKG)
    with pytest.raises(BundleError, match=r"^cannot find the module 'lpvest._fmus.nothere' to carry in the FMU$"):
        _bundle(root, start=["lpvest._fmus.nothere"])
    skip = [SourceRoot("pkg", root / "pkg", "", skip=("util",)), SourceRoot("lpvest._fmus", root, "_fmus")]
    with pytest.raises(BundleError, match=r"imports 'pkg.util', which does not exist"):
        make_bundle(identifier="X", script="role", slave_class="Slave", start=["lpvest._fmus.role"], roots=skip,
                    version="9")


def test_imports_are_renamed_token_by_token_on_their_own_lines(tmp_path):
    role = textwrap.dedent("""\
        import os, pkg.util as u, pkg.core.b as bee
        from pkg.core.a import (
            f,
        )
        from pkg.util import h  # pkg.util stays in comments
        text = "from pkg.util import h"
        import extmod as e


        class Slave:
            pass
        """)
    root = _tree(tmp_path, {**PKG, "role.py": role, "extmod.py": "X = 1\n"})
    ext = SourceRoot("extmod", root / "extmod.py", "_ext.extmod")
    b = _bundle(root, extra_roots=[ext])
    p = b.package
    assert b.files[f"{p}/_fmus/role.py"].decode() == (
        role.replace("import os, pkg.util as u, pkg.core.b as bee",
                     f"import os, {p}.util as u, {p}.core.b as bee")
        .replace("from pkg.core.a import (", f"from {p}.core.a import (")
        .replace("from pkg.util import h  #", f"from {p}.util import h  #")
        .replace("import extmod as e", f"import {p}._ext.extmod as e"))
    assert f"{p}/_ext/extmod.py" in b.files and f"{p}/_ext/__init__.py" in b.files
    assert b.files[f"{p}/_ext/__init__.py"] == f'"""{p}._ext: part of an lpvest FMU\'s private package."""\n'.encode()
    assert b.rename("extmod") == f"{p}._ext.extmod"


def test_a_single_file_root_carries_only_itself_and_the_longest_root_wins(tmp_path):
    root = _tree(tmp_path, {**PKG, "role.py": "from extmod import X\n", "extmod.py": "X = 1\n"})
    ext = SourceRoot("extmod", root / "extmod.py", "_ext.extmod")
    b = _bundle(root, extra_roots=[ext])
    assert "extmod" in b.modules
    root2 = _tree(tmp_path / "two", {**PKG, "role.py": "from extmod.sub import X\n", "extmod.py": "X = 1\n"})
    with pytest.raises(BundleError, match=r"imports 'extmod.sub', which does not exist"):
        _bundle(root2, extra_roots=[SourceRoot("extmod", root2 / "extmod.py", "_ext.extmod")])
    # "lpvest._fmus" (longer) wins over "lpvest" for lpvest._fmus.role
    lp = SourceRoot("lpvest", root / "pkg", "")
    b2 = make_bundle(identifier="X", script="role", slave_class="Slave", start=["lpvest._fmus.role"],
                     roots=[SourceRoot("lpvest._fmus", root, "_fmus"), lp, ext], version="9")
    assert "lpvest._fmus.role" in b2.modules and b2.rename("lpvest._fmus.role").endswith("._fmus.role")


# -- the entry module: the private package served from memory ----------------------------------


ROLE = """\
from pkg.core.a import f


class Slave:
    def value(self):
        from pkg.util import h  # a lazy import, served from memory
        return f() + h()
"""


def test_the_entry_module_loads_the_package_from_memory_and_restores_sys_path(tmp_path):
    root = _tree(tmp_path, {**PKG, "role.py": ROLE})
    b = _bundle(root)
    res = tmp_path / "resources"
    for rel, data in b.files.items():
        (res / rel).parent.mkdir(parents=True, exist_ok=True)
        (res / rel).write_bytes(data)
    (res / "slavemodule.txt").write_text(b.entry)  # as in an FMU's resources/ (the entry checks for it)
    path_before, meta_before = list(sys.path), list(sys.meta_path)
    sys.path.insert(0, str(res))  # pythonfmu puts resources/ on sys.path
    try:
        spec = importlib.util.spec_from_file_location(b.entry, res / f"{b.entry}.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        assert sys.path == path_before  # resources/ taken back off
        finders = [f for f in sys.meta_path if getattr(f, "package", None) == b.package]
        assert len(finders) == 1 and sys.meta_path[0] is finders[0]
        finder = finders[0]
        assert finder.find_spec("pkg.util") is None and finder.find_spec("json") is None
        spec_a = finder.find_spec(f"{b.package}.core.a")
        assert spec_a.origin == str(res / b.package / "core" / "a.py") and not spec_a.submodule_search_locations
        assert finder.find_spec(b.package).submodule_search_locations is not None  # a package
        shutil.rmtree(res)  # the package never touches the disk again
        assert module.Slave().value() == 5  # f() = g() + h() = 3, plus h()
        util = sys.modules[f"{b.package}.util"]
        assert util.__file__ == str(res / b.package / "util.py") and util.__spec__.loader is finder
        assert "pkg" not in sys.modules and "pkg.util" not in sys.modules  # nothing under the plain names
        # pythonfmu's findClass executes the entry again for each instance, with the module's
        # namespace as globals and fresh locals: the package is loaded once
        code = compile(b.files[f"{b.entry}.py"], module.__file__, "exec")
        namespace = module.__dict__
        before = sys.getrefcount(namespace)
        exec(code, namespace, {})
        assert [f for f in sys.meta_path if getattr(f, "package", None) == b.package] == [finder]
        # findClass then releases a reference to the namespace it never took (pythonfmu 0.7):
        # the entry took exactly that one, owned by nothing (a container would release it
        # when the interpreter clears the module at exit: a double free)
        assert sys.getrefcount(namespace) == before + 1
        ctypes.pythonapi.Py_DecRef(ctypes.py_object(namespace))  # findClass's release
        assert sys.getrefcount(namespace) == before
        assert sys.getrefcount(namespace) - 1 >= references_held(namespace)
        exec(code, namespace)  # an import (locals are the globals) releases nothing: takes nothing
        assert sys.getrefcount(namespace) == before
    finally:
        sys.path[:] = path_before
        sys.meta_path[:] = meta_before
        for name in list(sys.modules):
            if name == b.entry or name == b.package or name.startswith(b.package + "."):
                del sys.modules[name]


def test_a_module_level_if_on_a_flag_runs_its_imports_and_every_name_of_an_import_is_followed(tmp_path):
    files = {**PKG, "pkg/util.py": "FLAG = True\nif FLAG:\n    import scipy.linalg\n\n\ndef h():\n    return 2\n",
             "role.py": "import numpy as np, pkg.util as u\n\n\nclass Slave:\n    pass\n"}
    b = _bundle(_tree(tmp_path, files))
    assert "pkg.util" in b.modules  # named after a third-party module on the same line
    assert b.requirements == ("numpy>=1.26", "scipy>=1.11")  # `if FLAG:` runs at import: scipy is needed


def test_yield_from_and_raise_from_are_not_imports(tmp_path):
    role = textwrap.dedent("""\
        import extmod as extmod


        def g():
            yield from extmod.X
            raise ValueError("x") from extmod.E


        class Slave:
            pass
        """)
    root = _tree(tmp_path, {**PKG, "role.py": role, "extmod.py": "X = [1]\nE = None\n"})
    b = _bundle(root, extra_roots=[SourceRoot("extmod", root / "extmod.py", "_ext.extmod")])
    text = b.files[f"{b.package}/_fmus/role.py"].decode()
    assert text == role.replace("import extmod as extmod", f"import {b.package}._ext.extmod as extmod")


def test_a_package_and_a_module_of_the_same_text_are_different_code(tmp_path):
    as_module = _tree(tmp_path / "m", {**PKG, "role.py": "import pkg.util as u\n"})
    files = {k: v for k, v in PKG.items() if k != "pkg/util.py"}
    as_package = _tree(tmp_path / "p", {**files, "pkg/util/__init__.py": PKG["pkg/util.py"],
                                        "role.py": "import pkg.util as u\n"})
    a, b = _bundle(as_module), _bundle(as_package)
    assert f"{a.package}/util.py" in a.files and f"{b.package}/util/__init__.py" in b.files
    assert a.package != b.package


def test_a_reference_splits_at_the_first_colon(tmp_path):
    b = _bundle(_tree(tmp_path, PKG))
    assert b.reference("pkg.util:h:x") == f"{b.package}.util:h:x"


# -- what the whole-module mutation run found untested (docs/mutation.md) ------------------------


def test_a_typing_dot_type_checking_block_is_not_run_and_other_attribute_tests_and_loop_elses_are(tmp_path):
    util = textwrap.dedent("""\
        import sys
        import typing

        if typing.TYPE_CHECKING:
            import cvxpy
        if sys.flags.optimize:
            import scipy
        for _ in ():
            pass
        else:
            import yaml
        while False:
            pass
        else:
            import zarr


        def h():
            return 2
        """)
    root = _tree(tmp_path, {**PKG, "pkg/util.py": util, "role.py": "from pkg.util import h\n"})
    # what a loop's else imports runs at import: both are needed, and lpvest cannot declare either
    with pytest.raises(BundleError, match=r"cannot declare: yaml \(imported by pkg.util\); zarr \(imported by "
                                          r"pkg.util\)$"):
        _bundle(root)
    (root / "pkg" / "util.py").write_text(util.replace("import yaml", "pass").replace("import zarr", "pass"))
    b = _bundle(root)
    assert b.requirements == ("scipy>=1.11",)  # `if sys.flags.optimize:` may run: scipy is needed
    assert b.lazy_imports == {"cvxpy": ("pkg.util",)}  # only for the type checker


def test_the_packages_on_the_way_to_a_module_are_carried_and_the_name_has_16_hex_digits(tmp_path):
    files = {**PKG, "pkg/deep/__init__.py": "import yaml\n", "pkg/deep/er/__init__.py": "import zarr\n",
             "pkg/deep/er/mod.py": "X = 1\n", "role.py": "from pkg.deep.er.mod import X\n"}
    b = _bundle(_tree(tmp_path, files))
    assert b.modules == ("lpvest._fmus.role", "pkg", "pkg.deep", "pkg.deep.er", "pkg.deep.er.mod")
    p = b.package
    for name in ("pkg.deep", "pkg.deep.er"):  # carried empty: their imports (yaml, zarr) are not needed
        rel = f"{p}/{name.removeprefix('pkg.').replace('.', '/')}/__init__.py"
        assert b.files[rel].decode() == f'"""{name}, as carried by an lpvest FMU (empty: see lpvest.fmi._bundle)."""\n'
    assert b.requirements == ()
    assert p == "lpvest_" + b.digest[:16] and all(c in "0123456789abcdef" for c in b.digest)  # docs/fmus.md


def test_a_role_that_imports_no_package_module_still_gets_the_private_package(tmp_path):
    b = _bundle(_tree(tmp_path, {**PKG, "role.py": "import os\n\n\nclass Slave:\n    pass\n"}))
    assert b.modules == ("lpvest._fmus.role",)
    p = b.package
    assert set(b.files) == {f"{p}/__init__.py", f"{p}/_fmus/__init__.py", f"{p}/_fmus/role.py", f"{b.entry}.py"}
    assert b.files[f"{p}/__init__.py"] == f'"""{p}: part of an lpvest FMU\'s private package."""\n'.encode()


def test_a_carried_name_after_a_standard_library_one_on_one_line_is_followed(tmp_path):
    root = _tree(tmp_path, {**PKG, "role.py": "import os, pkg.util as u\nimport numpy, pkg.core.b as bee\n"})
    b = _bundle(root)
    assert b.modules == ("lpvest._fmus.role", "pkg", "pkg.core", "pkg.core.b", "pkg.util")
    assert b.requirements == ("numpy>=1.26",)
    assert b.files[f"{b.package}/_fmus/role.py"].decode() == (
        f"import os, {b.package}.util as u\nimport numpy, {b.package}.core.b as bee\n")


def test_a_module_whose_name_starts_with_capital_letters_is_found(tmp_path):
    root = _tree(tmp_path, {**PKG, "pkg/XYmod.py": "Z = 1\n", "role.py": "from pkg.XYmod import Z\n"})
    b = _bundle(root)
    assert "pkg.XYmod" in b.modules and f"{b.package}/XYmod.py" in b.files


def test_only_the_module_of_a_from_import_is_renamed_not_a_name_spelt_like_a_root(tmp_path):
    root = _tree(tmp_path, {**PKG, "pkg/names.py": "extmod = 1\npkg = 2\n", "extmod.py": "X = 1\n",
                            "role.py": "from pkg.names import extmod, pkg\n"})
    b = _bundle(root, extra_roots=[SourceRoot("extmod", root / "extmod.py", "_ext.extmod")])
    assert b.files[f"{b.package}/_fmus/role.py"].decode() == f"from {b.package}.names import extmod, pkg\n"


def test_a_dotted_root_renames_a_module_two_levels_under_it(tmp_path):
    # the roots here are "pkg" and "lpvest._fmus", not "lpvest": only the whole dotted name is a root
    role = "from lpvest._fmus.helpers.tool import T\nimport lpvest._fmus.helpers.tool as t\n"
    root = _tree(tmp_path, {**PKG, "helpers/tool.py": "T = 1\n", "role.py": role})
    b = _bundle(root)
    assert "lpvest._fmus.helpers.tool" in b.modules
    p = b.package
    assert b.files[f"{p}/_fmus/role.py"].decode() == (
        f"from {p}._fmus.helpers.tool import T\nimport {p}._fmus.helpers.tool as t\n")


def test_a_plain_import_of_a_deep_module_is_refused_suggesting_its_package(tmp_path):
    root = _tree(tmp_path, {**PKG, "role.py": "import pkg.core.b\n"})
    with pytest.raises(BundleError, match=r"role.py:1: 'import pkg.core.b' binds the name 'pkg', which an FMU "
                                          r"renames; write 'from pkg.core import ...' or 'import ... as ...'$"):
        _bundle(root)


def test_a_single_file_root_names_its_file_in_errors_and_refuses_relative_imports(tmp_path):
    root = _tree(tmp_path, {**PKG, "role.py": "import extmod as e\n", "extmod.py": "from pkg.util import *\n"})
    ext = [SourceRoot("extmod", root / "extmod.py", "_ext.extmod")]
    where = re.escape(str(root / "extmod.py"))
    with pytest.raises(BundleError, match=r"^" + where + r":1: 'import \*' cannot be carried"):
        _bundle(root, extra_roots=ext)
    # a top-level module has no package to be relative to (Python refuses it too)
    for text in ("from . import sibling\n", "from .sibling import x\n"):
        (root / "extmod.py").write_text(text)
        with pytest.raises(BundleError, match=r"^" + where + r": relative import beyond the top-level package$"):
            _bundle(root, extra_roots=ext)


def test_a_carried_module_that_does_not_parse_is_named_in_the_syntax_error(tmp_path):
    root = _tree(tmp_path, {**PKG, "pkg/util.py": "def h(:\n    return 2\n"})
    with pytest.raises(SyntaxError, match=r"invalid syntax|was never closed") as err:
        _bundle(root)
    assert err.value.filename == str(root / "pkg" / "util.py") and err.value.lineno == 1


def test_a_package_imported_by_several_modules_names_them_all_when_refused(tmp_path):
    root = _tree(tmp_path, {**PKG, "pkg/util.py": "import yaml\n\n\ndef h():\n    return 2\n",
                            "pkg/core/b.py": "import yaml\n\n\ndef g():\n    return 1\n"})
    with pytest.raises(BundleError, match=r"cannot declare: yaml \(imported by pkg.core.b, pkg.util\)$"):
        _bundle(root)


def test_a_reference_to_a_root_itself_keeps_everything_after_the_first_colon(tmp_path):
    b = _bundle(_tree(tmp_path, PKG))
    assert b.reference("pkg:main") == f"{b.package}:main"
    assert b.reference("pkg:main:x") == f"{b.package}:main:x"
