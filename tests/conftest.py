"""Shared fixtures: seeded randomness and small random systems."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: every random test is reproducible."""
    return np.random.default_rng(20261121)


# the FMU sets, built once per session (tests/conftest_fmu.py)
from .conftest_fmu import experiment_fmus as experiment_fmus, fmus as fmus  # noqa: E402
