"""Co-simulation: FMUs (and lpvest's own components) stepped together.

- :mod:`lpvest.cosim`: the fixed-step master over fmpy's ``FMU2Slave``
  (:class:`CoSimulation`, :func:`simulate`), zero-delay where outputs feed
  through;
- :mod:`lpvest.cosim`: co-simulation files (``lpvest cosim FILE.toml``:
  :func:`load_cosim`);
- :mod:`lpvest.cosim`: the SSP export and runs of an SSP by fmpy or
  libcosim (:func:`write_ssp`, :func:`read_ssp`, :func:`simulate_ssp`).

Examples
--------
>>> from lpvest.cosim import Component, CoSimulation
>>> plant = Component("plant", "out/PeixotoEx1Plant.fmu")        # doctest: +SKIP
"""

from __future__ import annotations

from ._cosimfile import CoSimFile, CoSimResult, load_cosim
from ._errors import AlgebraicLoopError, CoSimulationError
from ._master import (
    Component,
    Connection,
    CoSimulation,
    DiscardedStep,
    DiscardedStepWarning,
    simulate,
)
from ._ssp import read_ssp, simulate_ssp, write_ssp

__all__ = [
    "Component",
    "Connection",
    "CoSimulation",
    "CoSimulationError",
    "AlgebraicLoopError",
    "DiscardedStep",
    "DiscardedStepWarning",
    "simulate",
    "CoSimFile",
    "CoSimResult",
    "load_cosim",
    "read_ssp",
    "write_ssp",
    "simulate_ssp",
]
