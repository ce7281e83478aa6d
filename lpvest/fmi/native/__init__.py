"""The native FMU backend: lpvest's discrete-time components as C.

- :mod:`lpvest.fmi.native`: model formulas compiled to the runtime's
  stack code (from the parsed tree, names checked);
- :mod:`lpvest.fmi.native`: what a role's FMU computes (model, formulas,
  design, the Python FMU's variable table) as one generated ``model_data.c``;
- :mod:`lpvest.fmi.native`: the FMU: sources, binaries for linux64, win64
  and darwin64 cross-compiled with zig, resources, model description;
- ``runtime/``: the C runtime (package data), written once: dense kernels, the
  random generator of :mod:`lpvest.core`, the formula machine, the roles and
  the FMI 2.0 co-simulation layer.
"""

from ._formulas import CompiledFormula as CompiledFormula, compile_formula as compile_formula

__all__ = ["CompiledFormula", "compile_formula"]
