"""Shared fixtures: seeded randomness and small random systems."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: every random test is reproducible."""
    return np.random.default_rng(20261121)


@pytest.fixture(autouse=True)
def _fresh_bundle_caches_for_mutants() -> None:
    """Under mutation testing (``./dev mutate``: mutmut sets ``MUTANT_UNDER_TEST``), the
    bundler's per-process caches start empty for each test: mutmut forks each mutant's tests
    from a process that already ran them, whose caches hold what the unmutated functions
    computed, and would hide a mutant of ``_find_imports`` or ``_find_import_spans``."""
    import os

    if os.environ.get("MUTANT_UNDER_TEST"):
        from lpvest.fmi import _bundle

        _bundle._imports.cache_clear()
        _bundle._import_spans.cache_clear()


from hypothesis import HealthCheck, Phase, settings  # noqa: E402

# the FMU sets, built once per session (tests/conftest_fmu.py)
from .conftest_fmu import (  # noqa: E402
    experiment_fmus as experiment_fmus,
    fmus as fmus,
    foreign_fmus as foreign_fmus,
    native_fmus as native_fmus,
    script_build as script_build,
)

# -- property-based tests (hypothesis): fixed seed in CI ---------------------------------------
# derandomize: every run explores the same examples, so CI is reproducible; a
# failure found is then kept as a plain regression test. For a wider search
# set HYPOTHESIS_PROFILE=explore (random seed) and LPVEST_PROPERTY_SCALE=10.
settings.register_profile(
    "lpvest",
    derandomize=True,
    database=None,
    deadline=None,  # the CPU-time limit of tests/contract.py applies instead (not the machine's load)
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    # no explain phase: to explain a failure, hypothesis traces (sys.settrace; sys.monitoring
    # from Python 3.12) every example it runs after the first failure, shrinking included. Under
    # its tracer every Python line costs a call (tomllib's parse of a 200,001-character string:
    # 13 ms untraced, 137 ms traced), so the contract's CPU limit turned the shrinking of a real
    # failure (a two-line message) into ten "timeouts" that hid it (stop 31)
    phases=[phase for phase in Phase if phase is not Phase.explain],
)
settings.register_profile("explore", parent=settings.get_profile("lpvest"), derandomize=False)
settings.load_profile(__import__("os").environ.get("HYPOTHESIS_PROFILE", "lpvest"))


def pytest_terminal_summary(terminalreporter, exitstatus, config):  # noqa: ARG001 - pytest hook signature
    """The counts of the property-based input generators (tests/contract.py)."""
    import sys

    contract = sys.modules.get("tests.contract")
    lines = contract.report() if contract is not None else []
    if lines:
        terminalreporter.write_sep("-", "input contract: generated inputs (tests/test_properties.py)")
        for line in lines:
            terminalreporter.write_line(line)


@pytest.hookimpl(wrapper=True)
def pytest_collection(session):  # noqa: ARG001 - pytest hook signature
    """Collect with pytest's cache of rewritten test modules written, even under
    ``PYTHONDONTWRITEBYTECODE=1`` (as on our CI machine). pytest rewrites the
    assertions of every test module it imports and, by default, keeps the result
    next to the module (``tests/__pycache__/*-pytest-*.pyc``), but not where Python
    may write no bytecode: then every pytest process rewrote each test module it
    collected (59 in all) again, 8 of the 12 CPU seconds of a whole collection (``./dev test`` starts four collecting
    workers). It reads the cache in any case. Only for the collection: what the
    tests import and run later is left to the environment's rule (``./dev``
    compiles lpvest/ and tests/ itself)."""
    import sys

    before = sys.dont_write_bytecode
    sys.dont_write_bytecode = False
    try:
        return (yield)
    finally:
        sys.dont_write_bytecode = before


#: The test files that cost the most CPU, the costliest first (per-file CPU seconds, the test
#: process and the children it waited for, of a whole run on two xdist workers, 27 November,
#: zig's C runtimes already built: 55-150 s each for the first ten, 15-50 s for the rest; together
#: about three quarters of the suite's CPU; measured with tests/cpu_timeline.py:
#: ``LPVEST_CPU_TIMELINE=DIR ./dev test -p tests.cpu_timeline``, ``python -m tests.cpu_timeline DIR``).
#: ``./dev test`` passes ``--no-loadscope-reorder``, so pytest-xdist's ``--dist loadfile`` hands
#: whole files to the workers in this order (longest processing time first) instead of leaving
#: one worker alone on a late long file; xdist's default would order them by their number of
#: tests. The first two need no common FMU set between them: one worker builds the FMU sets
#: (the native set needs the Python one's designs) while the other solves LMIs. An order only:
#: every test still runs, and a name missing here runs after these, in pytest's order
#: (tests/test_architecture.py checks that each name is a file).
RUN_FIRST = (
    "test_native_hosts.py",
    "test_hinf_design.py",
    "test_interrupt.py",
    "test_sweep.py",
    "test_reproduce.py",
    "test_properties.py",
    "test_peixoto_experiments.py",
    "test_native_fmus.py",
    "test_fmu_hosts.py",
    "test_cli.py",
    "test_fmu_isolation.py",
    "test_fmu_lifecycle.py",
    "test_native_core.py",
    "test_fmu.py",
    "test_ssp.py",
    "test_progress.py",
    "test_hinf_known_input.py",
    "test_kalman.py",
    "test_kalman_scan.py",
    "test_walkthrough.py",
)


@pytest.hookimpl(tryfirst=True)  # before pytest-random-order's shuffle, when one is asked for
def pytest_collection_modifyitems(session, config, items):  # noqa: ARG001 - pytest hook signature
    """Run the costliest test files first (``RUN_FIRST``), the others after them in pytest's
    order; the order of the tests inside a file is kept."""
    rank = {name: i for i, name in enumerate(RUN_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(RUN_FIRST)))
