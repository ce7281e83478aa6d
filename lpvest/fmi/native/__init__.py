"""The native FMU backend: lpvest's discrete-time components as C.

- :mod:`lpvest.fmi.native.formulas`: model formulas compiled to the runtime's
  stack code (from the parsed tree, names checked);
- ``runtime/``: the C runtime (package data), written once: dense kernels, the
  random generator of :mod:`lpvest.rng`, the formula machine, the roles and
  the FMI 2.0 co-simulation layer.
"""

from .formulas import CompiledFormula as CompiledFormula, compile_formula as compile_formula

__all__ = ["CompiledFormula", "compile_formula"]
