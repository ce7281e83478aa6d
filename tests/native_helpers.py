"""Helpers of the native-backend tests: the C runtime compiled for ctypes, a C compiler."""

from __future__ import annotations

import atexit
import ctypes
import functools
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import lpvest.fmi.native

#: The C runtime (package data of lpvest.fmi.native).
RUNTIME_DIR = Path(lpvest.fmi.native.__file__).resolve().parent / "runtime"

#: The numerical core of the runtime (no FMI layer, no model data), and its support functions.
CORE = ("lpv_linalg.c", "lpv_rng.c", "lpv_vm.c", "lpv_support.c")
#: The flags the FMUs are built with (lpvest.fmi.native._build.CFLAGS), for a test library.
TEST_FLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror", "-fPIC", "-shared",
              "-fvisibility=hidden", "-DLPV_TEST_EXPORTS")


def c_compiler() -> list[str]:
    """The host's C compiler (cc, gcc), else zig's."""
    for name in ("cc", "gcc", "clang"):
        found = shutil.which(name)
        if found:
            return [found]
    return [sys.executable, "-m", "ziglang", "cc"]


@functools.cache
def core_library() -> ctypes.CDLL:
    """The runtime's numerical core as a shared library (compiled once per session)."""
    folder = Path(tempfile.mkdtemp(prefix="lpvest-core-"))
    atexit.register(shutil.rmtree, folder, True)
    out = folder / "lpvcore.so"
    cmd = [*c_compiler(), *TEST_FLAGS, "-o", str(out), *(str(RUNTIME_DIR / f) for f in CORE), "-lm"]
    subprocess.run(cmd, check=True, capture_output=True)
    lib = ctypes.CDLL(str(out))
    d, i, u64 = ctypes.c_double, ctypes.c_int, ctypes.c_uint64
    dp = ctypes.POINTER(ctypes.c_double)
    lib.lpv_pcg64_next.restype = u64
    lib.lpv_uniform.restype = d
    lib.lpv_normal.restype = d
    lib.lpv_normal_quantile.restype = d
    lib.lpv_normal_quantile.argtypes = [d]
    lib.lpv_log.restype = d
    lib.lpv_log.argtypes = [d]
    lib.lpv_formula_eval.restype = d
    lib.lpv_cholesky.argtypes = [i, dp, dp, dp, dp]
    lib.lpv_cholesky.restype = i
    lib.lpv_lu_solve.restype = i
    lib.lpv_sym_eigenvalues.restype = i
    lib.lpv_abbreviate.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_size_t, i]
    lib.lpv_abbreviate.restype = None
    return lib


class Pcg64(ctypes.Structure):
    """``lpv_pcg64`` (runtime/lpv_core.h)."""

    _fields_ = [("state_hi", ctypes.c_uint64), ("state_lo", ctypes.c_uint64), ("inc_hi", ctypes.c_uint64),
                ("inc_lo", ctypes.c_uint64)]


class Formula(ctypes.Structure):
    """``lpv_formula`` (runtime/lpv_core.h)."""

    _fields_ = [("code", ctypes.POINTER(ctypes.c_int32)), ("constants", ctypes.POINTER(ctypes.c_double))]


def doubles(a: np.ndarray) -> ctypes.Array:
    """A ctypes copy of a float array (flattened, row-major)."""
    flat = np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
    return (ctypes.c_double * max(1, flat.size))(*flat.tolist())


def seeded(seed: int) -> Pcg64:
    """A runtime generator seeded with ``seed`` (any non-negative integer: its 32-bit words)."""
    words = []
    n = int(seed)
    while True:
        words.append(n & 0xFFFFFFFF)
        n >>= 32
        if n == 0:
            break
    g = Pcg64()
    core_library().lpv_pcg64_seed(ctypes.byref(g), (ctypes.c_uint32 * len(words))(*words), len(words))
    return g
