"""FMI glue: building lpvest's FMUs and the common base of their slaves.

- :mod:`lpvest.fmi.build`: plan, build and validate the FMUs
  (``build_fmus.py``, ``lpvest build``, ``lpvest validate``);
- :mod:`lpvest.fmi.registry`: the estimator kinds that get an FMU;
- :mod:`lpvest.fmi.slave`: the pythonfmu base class of the slave scripts in
  ``fmus/`` (imports pythonfmu; only the FMUs and the builder import it);
- :mod:`lpvest.fmi.naming`, :mod:`lpvest.fmi.spec`, :mod:`lpvest.fmi.state`,
  :mod:`lpvest.fmi.factories`: numpy-only pieces the FMUs use at run time;
- :mod:`lpvest.fmi.bundle`: what an FMU carries and how it loads it;
- :mod:`lpvest.fmi.native`: the native backend (``backend="native"`` of
  :func:`lpvest.fmi.build.build_fmus`): every discrete-time role as C, one
  runtime in ``native/runtime/`` and a generated ``model_data.c`` per FMU.

Importing this package imports neither fmpy nor pythonfmu.
"""

from .naming import element_names as element_names, fmu_name as fmu_name
from .registry import ESTIMATOR_KINDS as ESTIMATOR_KINDS, EstimatorKind as EstimatorKind
from .spec import Parameter as Parameter

__all__ = ["element_names", "fmu_name", "ESTIMATOR_KINDS", "EstimatorKind", "Parameter"]
