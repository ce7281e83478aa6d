"""FMI glue: building lpvest's FMUs and the common base of their slaves.

- :mod:`lpvest.fmi`: plan, build and validate the FMUs
  (``build_fmus.py``, ``lpvest build``, ``lpvest validate``);
- :mod:`lpvest.fmi`: the estimator kinds that get an FMU;
- :mod:`lpvest.fmi`: the pythonfmu base class of the slave scripts in
  ``fmus/`` (imports pythonfmu; only the FMUs and the builder import it);
- :mod:`lpvest.fmi`, :mod:`lpvest.fmi`, :mod:`lpvest.fmi`,
  :mod:`lpvest.fmi.factories`: numpy-only pieces the FMUs use at run time;
- :mod:`lpvest.fmi`: what an FMU carries and how it loads it;
- :mod:`lpvest.fmi.native`: the native backend (``backend="native"`` of
  :func:`lpvest.fmi.build_fmus`): every discrete-time role as C, one
  runtime in ``native/runtime/`` and a generated ``model_data.c`` per FMU.

Importing this package imports neither fmpy nor pythonfmu.
"""

from ._build import (
    DEFAULT_OUT as DEFAULT_OUT,
    BuildError as BuildError,
    BuildResult as BuildResult,
    BuildWarning as BuildWarning,
    FmuPlan as FmuPlan,
    ValidationResult as ValidationResult,
    build_fmu as build_fmu,
    build_fmus as build_fmus,
    plan_system as plan_system,
    validate_fmus as validate_fmus,
)
from ._cache import (
    FmuCache as FmuCache,
    FmuCacheError as FmuCacheError,
)
from ._naming import element_names as element_names, fmu_name as fmu_name
from ._parameters import Parameter as Parameter
from ._registry import ESTIMATOR_KINDS as ESTIMATOR_KINDS, EstimatorKind as EstimatorKind

__all__ = [
    "element_names",
    "fmu_name",
    "ESTIMATOR_KINDS",
    "EstimatorKind",
    "Parameter",
    "BuildError",
    "BuildResult",
    "BuildWarning",
    "DEFAULT_OUT",
    "FmuPlan",
    "ValidationResult",
    "build_fmu",
    "build_fmus",
    "plan_system",
    "validate_fmus",
    "FmuCache",
    "FmuCacheError",
]
