"""Shared fixtures: seeded randomness and small random systems."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: every random test is reproducible."""
    return np.random.default_rng(20261121)


from hypothesis import HealthCheck, settings  # noqa: E402

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
