"""The native runtime's numerical core (runtime/lpv_linalg.c, lpv_rng.c, lpv_vm.c)
through ctypes, against the Python library: the random generator bit for bit,
the kernels the library writes in Python floats bit for bit, the others and
the formula machine within derived rounding bounds."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from lpvest.core._errors import ExpressionError, abbreviate
from lpvest.core._expressions import Expression
from lpvest.core._rng import Stream, log, lower_times, normal_quantile, psd_cholesky
from lpvest.estimators.kalman._recursion import small_chol_inverse
from lpvest.fmi.native._formulas import VM_STACK, compile_formula
from tests.native_helpers import RUNTIME_DIR, Formula, core_library, doubles, seeded
from tests.tolerances import roundoff

lib = core_library()


@pytest.mark.parametrize("seed", [0, 1, 7, 2026, 2**31 - 1, 2**32 - 1, 2**32, 2**70 + 5])
def test_raw_words_are_numpys_pcg64_bit_for_bit(seed):
    g = seeded(seed)
    raws = np.array([lib.lpv_pcg64_next(ctypes.byref(g)) for _ in range(2000)], dtype=np.uint64)
    assert np.array_equal(raws, np.random.default_rng(seed).bit_generator.random_raw(2000))


@pytest.mark.parametrize("seed", [0, 3, 2026, 2**31 - 1])
def test_normals_and_uniforms_are_the_librarys_bit_for_bit(seed):
    g = seeded(seed)
    z = np.array([lib.lpv_normal(ctypes.byref(g)) for _ in range(50_000)])
    assert z.tobytes() == Stream(seed).normal(50_000).tobytes()
    g = seeded(seed)
    u = np.array([lib.lpv_uniform(ctypes.byref(g)) for _ in range(5_000)])
    assert u.tobytes() == Stream(seed).uniform(5_000).tobytes()


def test_log_and_quantile_are_the_librarys_bit_for_bit():
    x = np.concatenate([np.exp(np.linspace(-744.0, 709.0, 4001)), np.random.default_rng(3).random(4000) + 1e-300,
                        [2.0**-1074, 0.5, 1.0, 2.0, 1.4142135623730951, 1.4142135623730954]])
    c = np.array([lib.lpv_log(float(v)) for v in x])
    assert c.tobytes() == log(x).tobytes()
    p = np.concatenate([((np.random.default_rng(4).bit_generator.random_raw(20000) >> np.uint64(12))
                         .astype(np.float64) + 0.5) * 2.0**-52, [2.0**-53, 1 - 2.0**-53, 0.5, 0.075, 0.925]])
    c = np.array([lib.lpv_normal_quantile(float(v)) for v in p])
    assert c.tobytes() == normal_quantile(p).tobytes()


def test_semidefinite_factor_and_lower_products_are_the_librarys_bit_for_bit(rng):
    for n in (1, 2, 3, 5):
        B = rng.standard_normal((n, max(1, n - 1)))
        P = B @ B.T  # semidefinite: rank n - 1
        L = (ctypes.c_double * (n * n))()
        lib.lpv_psd_cholesky(n, doubles(P), L)
        assert np.array(L).reshape(n, n).tobytes() == psd_cholesky(P).tobytes()
        z = rng.standard_normal(n)
        out = (ctypes.c_double * n)()
        lib.lpv_lower_times(n, doubles(psd_cholesky(P)), doubles(z), out)
        assert np.array(out).tobytes() == lower_times(psd_cholesky(P), z[None, :])[0].tobytes()


def test_small_cholesky_and_its_inverse_are_the_librarys_bit_for_bit(rng):
    for m in (1, 2, 3):
        B = rng.standard_normal((m, m + 2))
        Om = B @ B.T
        L = (ctypes.c_double * (m * m))()
        pivot, logdet = ctypes.c_double(), ctypes.c_double()
        assert lib.lpv_cholesky(m, doubles(Om), L, ctypes.byref(pivot), ctypes.byref(logdet)) == 0
        Ci = (ctypes.c_double * (m * m))()
        lib.lpv_lower_inverse(m, L, Ci)
        ref, ref_logdet = small_chol_inverse(Om, None)
        assert np.array(Ci).reshape(m, m).tobytes() == ref.tobytes()
        assert logdet.value == ref_logdet


def test_cholesky_names_the_first_bad_pivot():
    pivot = ctypes.c_double()
    A = np.array([[1.0, 2.0], [2.0, 1.0]])
    assert lib.lpv_cholesky(2, doubles(A), (ctypes.c_double * 4)(), ctypes.byref(pivot), None) == 2
    assert pivot.value == -3.0


def test_lu_solve_agrees_with_lapack_to_the_conditioning(rng):
    for n in (1, 2, 4, 7):
        A = rng.standard_normal((n, n)) + 0.5 * np.eye(n)
        b = rng.standard_normal((n, 2))
        a, rhs = doubles(A), doubles(b)
        assert lib.lpv_lu_solve(n, a, (ctypes.c_int * n)(), rhs, 2) == 0
        x = np.array(rhs).reshape(n, 2)
        ref = np.linalg.solve(A, b)
        # two backward-stable solves (partial pivoting): each within ~n eps cond(A) |x|
        # of the exact solution (Higham (9.4) with a growth factor ~1 for these matrices)
        tol = roundoff(np.abs(ref).max(), 2, n=n, amp=np.linalg.cond(A))
        assert np.abs(x - ref).max() <= tol
    singular = doubles(np.array([[1.0, 2.0], [2.0, 4.0]]))
    assert lib.lpv_lu_solve(2, singular, (ctypes.c_int * 2)(), doubles(np.ones(2)), 1) == 1


def test_jacobi_eigenvalues_agree_with_lapack(rng):
    for n in (1, 2, 3, 6):
        B = rng.standard_normal((n, n))
        A = B + B.T
        w = (ctypes.c_double * n)()
        assert lib.lpv_sym_eigenvalues(n, doubles(A), w, (ctypes.c_double * (2 * n * n))()) == 0
        # symmetric eigenvalues are perfectly conditioned: a backward error of
        # ~n eps ||A|| (both methods) moves each by at most that (Weyl)
        assert np.abs(np.array(w) - np.linalg.eigvalsh(A)).max() <= roundoff(np.linalg.norm(A, 2), 1, n=n)


def test_products_sum_in_index_order(rng):
    A, x = rng.standard_normal((3, 4)), rng.standard_normal(4)
    y = (ctypes.c_double * 3)()
    lib.lpv_matvec(3, 4, doubles(A), doubles(x), y)
    expected = [((A[i, 0] * x[0] + A[i, 1] * x[1]) + A[i, 2] * x[2]) + A[i, 3] * x[3] for i in range(3)]
    assert list(y) == expected
    B = rng.standard_normal((4, 2))
    C = (ctypes.c_double * 6)()
    lib.lpv_matmul(3, 4, 2, doubles(A), doubles(B), C)
    assert np.abs(np.array(C).reshape(3, 2) - A @ B).max() <= roundoff(np.abs(A).max() * np.abs(B).max(), 1, n=4)
    Ct = (ctypes.c_double * 6)()
    lib.lpv_matmul_bt(3, 4, 2, doubles(A), doubles(B.T), Ct)
    assert list(Ct) == list(C)


# -- the formula machine ----------------------------------------------------------------

#: Two float64 implementations of sin, exp, log, pow, ...: the C library's (glibc:
#: within 1 unit in the last place) and numpy's SIMD loops (SVML on AVX-512: within 4).
FUNC_ULPS = 4.0

_DERIV = {
    "sin": np.cos, "cos": lambda a: -np.sin(a), "tan": lambda a: 1 + np.tan(a) ** 2, "exp": np.exp,
    "log": lambda a: 1 / a, "sqrt": lambda a: 0.5 / np.sqrt(a), "sinh": np.cosh, "cosh": np.sinh,
    "tanh": lambda a: 1 - np.tanh(a) ** 2, "arctan": lambda a: 1 / (1 + a * a), "abs": np.sign,
}


def formula_bound(expr: Expression, values: dict[str, float], errors: dict[str, float] | None = None) -> float:
    """A first-order bound on the difference of two IEEE evaluations of ``expr``
    at ``values`` that differ in the functions (FUNC_ULPS each, pow included)
    and in the values themselves by up to ``errors`` (by name): propagated
    through every operation by its partial derivatives, plus one rounding where
    the operands already differ (Higham 3.1)."""
    import ast

    def walk(node: ast.AST) -> tuple[float, float]:
        if isinstance(node, ast.Constant):
            return float(node.value), 0.0
        if isinstance(node, ast.Name):
            return float(values[node.id]), float((errors or {}).get(node.id, 0.0))
        if isinstance(node, ast.UnaryOp):
            a, e = walk(node.operand)
            return (-a if isinstance(node.op, ast.USub) else a), e
        if isinstance(node, ast.Call):
            a, e = walk(node.args[0])
            name = node.func.id  # type: ignore[attr-defined]
            r = float(getattr(np, name)(a))
            d = max(abs(float(_DERIV[name](a))), abs(float(_DERIV[name](a + e))), abs(float(_DERIV[name](a - e))))
            return r, d * e + FUNC_ULPS * float(np.spacing(abs(r)))
        assert isinstance(node, ast.BinOp)
        (a, ea), (b, eb) = walk(node.left), walk(node.right)
        if isinstance(node.op, ast.Pow):
            r = float(np.power(a, b))
            da = abs(b * float(np.power(a, b - 1))) if a != 0 else 0.0
            db = abs(r * math.log(abs(a))) if a != 0 else 0.0
            return r, da * ea + db * eb + FUNC_ULPS * float(np.spacing(abs(r)))
        with np.errstate(all="ignore"):  # IEEE: a division by zero is inf, as the evaluations give
            x, y = np.float64(a), np.float64(b)
            r = float({ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply,
                       ast.Div: np.divide}[type(node.op)](x, y))
        if ea == eb == 0:
            return r, 0.0
        if isinstance(node.op, ast.Add | ast.Sub):
            e = ea + eb
        elif isinstance(node.op, ast.Mult):
            e = abs(b) * ea + abs(a) * eb + ea * eb
        else:
            e = (ea + abs(r) * eb) / (abs(b) - eb) if abs(b) > eb else math.inf
        return r, e + float(np.spacing(abs(r)))

    return walk(expr.tree.body)[1]


def evaluate_native(expr: Expression, names: list[str], values: dict[str, float]) -> float:
    c = compile_formula(expr, names)
    code = (ctypes.c_int32 * len(c.code))(*c.code)
    f = Formula(code, doubles(np.asarray(c.constants)))
    return lib.lpv_formula_eval(ctypes.byref(f), doubles(np.array([values[n] for n in names])))


#: + - * / and signs only: IEEE arithmetic, the same bits (a power is a function: numpy's SIMD
#: power and the C library's pow may differ in the last place, even for whole exponents)
ARITHMETIC = ["(1 - theta)/2", "(1 + theta)/2", "-0.05*rho", "x*y - y/x + 3*x*x*x", "-(x - -y) / (2 - x)",
              "1/(x - x)", "(x - x)/(y - y)", "+x - -y"]
FUNCTIONS = ["sin(x) + cos(y)", "exp(-x*y) * tan(x/3)", "log(abs(x) + 1) - sqrt(y*y + 1)",
             "sinh(x) / cosh(y) + tanh(x*y)", "arctan(x) * 120 * sin(x)", "x**y + y**x", "1/(t + 1000) - t**2",
             "x^2 + y**3", "x**0.5", "2**x - x**-2"]


def test_a_negative_number_to_a_fractional_power_is_nan_as_in_numpy():
    expr = Expression.parse("(-x)**0.5")
    assert math.isnan(evaluate_native(expr, ["x"], {"x": 2.0})) and math.isnan(float(expr.evaluate({"x": 2.0})))


@pytest.mark.parametrize("text", ARITHMETIC)
def test_arithmetic_formulas_are_the_librarys_bit_for_bit(text, rng):
    expr = Expression.parse(text)
    names = sorted(expr.names)
    for _ in range(50):
        values = {n: float(rng.uniform(0.1, 2.0)) for n in names}
        got = evaluate_native(expr, names, values)
        want = float(expr.evaluate(values))
        assert np.float64(got).tobytes() == np.float64(want).tobytes() or (math.isnan(got) and math.isnan(want))


@pytest.mark.parametrize("text", FUNCTIONS)
def test_formulas_with_functions_agree_within_their_derived_bound(text, rng):
    expr = Expression.parse(text)
    names = sorted(expr.names)
    for _ in range(50):
        values = {n: float(rng.uniform(0.1, 2.0)) for n in names}
        got = evaluate_native(expr, names, values)
        want = float(expr.evaluate(values))
        assert abs(got - want) <= formula_bound(expr, values)


def test_the_deepest_formula_the_language_allows_runs_within_the_stack():
    # nested to the parser's limit (lpvest.core._expressions.MAX_FORMULA_DEPTH), right-leaning: every
    # operand waits on the stack; the compiler counts the depth and the machine has room for it
    deep = Expression.parse("x*(" * 49 + "x" + ")" * 49)
    c = compile_formula(deep, ["x"])
    assert c.depth == 50 <= VM_STACK
    assert evaluate_native(deep, ["x"], {"x": 1.0}) == 1.0
    assert evaluate_native(deep, ["x"], {"x": 2.0}) == 2.0**50
    wide = Expression.parse("+".join(["x"] * 60))
    assert compile_formula(wide, ["x"]).depth == 2
    assert evaluate_native(wide, ["x"], {"x": 1.0}) == 60.0


def test_names_are_resolved_and_checked_when_compiled():
    with pytest.raises(ExpressionError, match=r"formula 'p \+ q': uses the name 'q', which is not a variable here "
                                               r"\(variables: p\) \(native FMU\)"):
        compile_formula(Expression.parse("p + q"), ["p"])
    with pytest.raises(ExpressionError, match="uses a shifted variable"):
        compile_formula(Expression.parse("shift(p, 1) * 2"), ["p"])


def _abbreviate_in_c(text: str, limit: int) -> str:
    out = ctypes.create_string_buffer(320)
    raw = text.encode("utf-8")
    lib.lpv_abbreviate(out, 320, raw, len(raw), limit)
    return out.value.decode("utf-8")


TEXTS = ["", "x", "theorem", "it's", 'say "x"', "it's \"x\"", "a\\b", "tab\there\nnew\rline", "\x00\x1f\x7f",
         "caf\xe9", "\x85\xa0\xad", "\u2028\u200b\ufeff\ue000", "\U0001f600 \U000e0041", "x" * 300,
         "\t" * 40, "'" * 50, "\U000e0041" * 3, "\x01" + "x" * 60 + "\x02", "é" * 100 + "'\"", "0 1; 1 2" * 20]


@pytest.mark.parametrize("text", TEXTS)
@pytest.mark.parametrize("limit", [1, 8, 30, 40])
def test_a_text_is_shown_in_messages_as_abbreviate_shows_it(text, limit):
    """The native FMUs' messages quote a String parameter (a signal kind, a table row, the
    Kalman start) as the Python FMUs do, with lpvest's abbreviate: Python's repr (the
    quotes it picks, its escapes, the characters it shows as they are), cut in the middle
    by the width the characters are shown in."""
    assert _abbreviate_in_c(text, limit) == abbreviate(text, limit)


@settings(max_examples=300)
@given(st.text(st.characters(exclude_categories=("Cn", "Cs")), max_size=80), st.integers(1, 40))
def test_any_assigned_text_is_shown_as_abbreviate_shows_it(text, limit):
    """As above, for any text of assigned characters (unassigned ones Python escapes by its
    Unicode version; the runtime shows them as they are)."""
    assert _abbreviate_in_c(text, limit) == abbreviate(text, limit)


def test_the_runtimes_table_of_characters_python_escapes_is_unicodedatas():
    """Every assigned character the running Python does not print is in the runtime's
    table, and every one in the table is one Python does not print (assigned or not): true
    of every Unicode version whose new format characters the table holds."""
    import re
    import sys
    import unicodedata

    source = (RUNTIME_DIR / "lpv_support.c").read_text()
    table = source[source.index("NOT_PRINTABLE[][2] = {"):source.index("};", source.index("NOT_PRINTABLE[][2]"))]
    ranges = [(int(a, 16), int(b, 16)) for a, b in re.findall(r"\{0x([0-9a-f]+), 0x([0-9a-f]+)\}", table)]
    in_table = bytearray(sys.maxunicode + 1)
    for a, b in ranges:
        in_table[a:b + 1] = b"\x01" * (b + 1 - a)
    printed_but_escaped = [hex(cp) for cp in range(0x80, sys.maxunicode + 1) if in_table[cp] and chr(cp).isprintable()]
    assert not printed_but_escaped, f"Unicode {unicodedata.unidata_version}: printed by Python: {printed_but_escaped}"
    missing = [hex(cp) for cp in range(0x80, sys.maxunicode + 1) if not in_table[cp] and not chr(cp).isprintable()
               and unicodedata.category(chr(cp)) not in ("Cn", "Cs")]
    assert not missing, f"Unicode {unicodedata.unidata_version}: escaped by Python, not in the table: {missing}"


@pytest.mark.parametrize("target", ["host", "x86_64-linux-gnu", "x86_64-windows-gnu", "x86_64-macos",
                                    "x86-linux-musl", "arm-linux-musleabihf"])
def test_every_runtime_source_compiles_without_a_warning(target, tmp_path):
    """C99 with -Wall -Wextra -Werror -pedantic: with the host's compiler (at
    -O0 and -O2, with and without AddressSanitizer and UndefinedBehaviorSanitizer,
    whose analyses warn about other things) and with zig for the three targets
    the FMUs ship, and two 32-bit ones a tool may compile sources/ for (a shift of
    a 32-bit size_t by 40 once hid there)."""
    import subprocess
    import sys

    from lpvest.fmi._build import zig_environment
    from tests.native_helpers import RUNTIME_DIR, c_compiler

    sources = sorted(str(f) for f in RUNTIME_DIR.glob("*.c"))
    base = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-ffp-contract=off", "-c"]
    if target == "host":
        variants = [["-O0"], ["-O2"], ["-O1", "-fsanitize=address,undefined"], ["-O3", "-fsanitize=undefined"]]
        commands = [[*c_compiler(), *base, *v] for v in variants]
    else:
        commands = [[sys.executable, "-m", "ziglang", "cc", "-target", target, *base, "-O2"]]
    for cmd in commands:
        for src in sources:
            proc = subprocess.run([*cmd, src, "-o", str(tmp_path / "x.o")], capture_output=True, text=True,
                                  cwd=RUNTIME_DIR, check=False, env=None if target == "host" else zig_environment())
            assert proc.returncode == 0 and "warning" not in proc.stderr, (cmd, src, proc.stderr)


def test_the_runtime_sources_sit_in_one_folder_per_runtime_in_the_users_cache(tmp_path, monkeypatch):
    """The folder zig compiles the runtime from is named by the runtime's digest
    in ``$XDG_CACHE_HOME/lpvest/native-runtime`` (so zig's cache, which keys on
    the sources' paths, serves later builds); it holds exactly the runtime's
    files, a damaged one is replaced, and without a writable cache a temporary
    folder of the process serves instead."""
    from lpvest.fmi.native import _build as nb

    files = nb.runtime_files()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    digest = nb._runtime_digest()
    folder = nb._runtime_sources(digest)
    assert folder == tmp_path / "cache" / "lpvest" / "native-runtime" / digest[:32]
    assert {f.name: f.read_bytes() for f in folder.iterdir()} == files
    assert nb._runtime_sources(digest) == folder  # found again, not rewritten
    assert [p.name for p in folder.parent.iterdir()] == [folder.name]  # nothing half-written left beside it

    damaged = folder / sorted(n for n in files if n.endswith(".c"))[0]
    damaged.write_bytes(b"int broken;\n")
    (folder / "lpv.h").unlink()
    assert nb._runtime_sources(digest) == folder
    assert {f.name: f.read_bytes() for f in folder.iterdir()} == files
    assert [p.name for p in folder.parent.iterdir()] == [folder.name]

    blocked = tmp_path / "not-a-folder"
    blocked.write_text("a file where the cache would go")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    elsewhere = nb._runtime_sources(digest)
    assert not elsewhere.is_relative_to(blocked) and {f.name: f.read_bytes() for f in elsewhere.iterdir()} == files


def test_zig_is_called_as_the_ziglang_packages_program():
    """What ``python -m ziglang`` runs, without a Python start per compiler call."""
    import subprocess
    import sys

    from lpvest.fmi._build import zig_program, zig_version

    if zig_version() is None:
        pytest.skip("needs ziglang (pip install 'lpvest[build]')")
    program = zig_program()
    assert program is not None
    proc = subprocess.run([sys.executable, "-m", "ziglang", "version"], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == zig_version() and subprocess.run(
        [program, "version"], capture_output=True, text=True, check=True).stdout == proc.stdout


def test_the_zig_lib_folders_name_is_the_same_in_every_environment_with_the_same_zig():
    """Two environments' RECORDs of one ziglang wheel differ in the launcher script (its
    hash covers the environment's interpreter path) and in the bytecode pip compiled (listed
    without a hash): the lib folder's identity ignores both, and sees a changed lib file."""
    from lpvest.fmi._build import lib_record

    lib = ["ziglang/lib/libc/mingw/crt/crtdll.c,sha256=AAAA,120", "ziglang/lib/std/std.zig,sha256=BBBB,80"]
    one = "\n".join(["../../../bin/python-zig,sha256=EcBz7ezG,176", "ziglang/__init__.py,sha256=CCCC,10", *lib,
                     "ziglang/__pycache__/__init__.cpython-311.pyc,,"])
    other = "\n".join(["../../../bin/python-zig,sha256=z1LMy05I,237", *reversed(lib),
                       "ziglang/lib/lldb/__pycache__/pretty_printers.cpython-311.pyc,,",
                       "ziglang/__init__.py,sha256=CCCC,10", ""])
    assert lib_record(one) == lib_record(other) == "\n".join(lib)
    changed = other.replace("sha256=BBBB,80", "sha256=DDDD,81")
    assert lib_record(changed) != lib_record(one)


def test_zig_runs_with_its_lib_folder_at_a_path_that_stays_the_same(tmp_path, monkeypatch):
    """zig keys the C runtimes it builds from its ``lib`` folder (Windows' alone is
    ~75 s of CPU) by that folder's path: each virtual environment would build them
    again. lpvest runs zig with ``ZIG_LIB_DIR`` at one folder per zig in the user's
    cache, named by zig's version and the package's RECORD, holding the same files;
    a user's own ``ZIG_LIB_DIR`` is kept; where the cache cannot be written, zig
    runs as installed."""
    import functools
    import hashlib
    import importlib.metadata
    import subprocess
    from pathlib import Path

    from lpvest.fmi import _build

    if _build.zig_version() is None:
        pytest.skip("needs ziglang (pip install 'lpvest[build]')")
    monkeypatch.delenv("ZIG_LIB_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    # a fresh cache of the folder for this test: the process's own stays as it was
    monkeypatch.setattr(_build, "_zig_lib_dir", functools.cache(_build._zig_lib_dir.__wrapped__))
    env = _build.zig_environment()
    lib = Path(env["ZIG_LIB_DIR"])
    record = importlib.metadata.distribution("ziglang").read_text("RECORD")
    assert record
    # named by the hashes of the lib folder's files alone: the same in every environment
    files = sorted(line for line in record.splitlines() if line.startswith("ziglang/lib/") and ",sha256=" in line)
    assert len(files) > 1000
    digest = hashlib.sha256("\n".join(files).encode()).hexdigest()[:16]
    assert lib == tmp_path / "xdg" / "lpvest" / "zig-lib" / f"{_build.zig_version()}-{digest}"
    installed = Path(_build.zig_program()).parent / "lib"
    names = sorted(p.relative_to(installed) for p in installed.rglob("*") if p.is_file())
    assert names == sorted(p.relative_to(lib) for p in lib.rglob("*") if p.is_file())
    for name in names[:: max(1, len(names) // 50)]:  # ~50 files spread over the folder, byte for byte
        assert (lib / name).read_bytes() == (installed / name).read_bytes(), name
    assert [p.name for p in lib.parent.iterdir()] == [lib.name]  # no temporary folder left
    assert _build.zig_environment()["ZIG_LIB_DIR"] == str(lib)  # the same folder again
    proc = subprocess.run([_build.zig_program(), "env"], capture_output=True, text=True, check=True, env=env)
    assert str(lib) in proc.stdout  # zig takes it

    monkeypatch.setenv("ZIG_LIB_DIR", "/opt/my-zig-lib")
    assert _build.zig_environment()["ZIG_LIB_DIR"] == "/opt/my-zig-lib"
    monkeypatch.delenv("ZIG_LIB_DIR")
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("a file where the cache would go")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    _build._zig_lib_dir.cache_clear()
    assert "ZIG_LIB_DIR" not in _build.zig_environment()
