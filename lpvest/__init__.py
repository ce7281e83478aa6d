"""lpvest: estimation for LPV and LTV systems, as Python and as FMI 2.0 FMUs.

The numerics import only numpy at import time (scipy, cvxpy, matplotlib and
fmpy are imported inside the functions that need them), so the FMUs that
carry this package run where only numpy is installed.

>>> import lpvest
>>> plant = lpvest.load_system("peixoto-ex1").model()
>>> plant.n_vertices
2
"""

__version__ = "0.1.0"

from .catalog import example_systems as example_systems
from .errors import (
    DimensionError as DimensionError,
    ExpressionError as ExpressionError,
    IdentifiabilityError as IdentifiabilityError,
    LMIInfeasibleError as LMIInfeasibleError,
    LpvestError as LpvestError,
    ModelFileError as ModelFileError,
    NonFiniteError as NonFiniteError,
    NotPositiveDefiniteError as NotPositiveDefiniteError,
    NumericalError as NumericalError,
    SchedulingRangeError as SchedulingRangeError,
)
from .expressions import Expression as Expression, FormulaMatrix as FormulaMatrix
from .modelfile import (
    SystemFile as SystemFile,
    dump_system as dump_system,
    load_system as load_system,
    loads_system as loads_system,
    save_system as save_system,
)
from .scheduling import (
    CallableBasis as CallableBasis,
    FormulaBasis as FormulaBasis,
    Monomial as Monomial,
    SchedulingSpace as SchedulingSpace,
)
from .systems import (
    AffineDependence as AffineDependence,
    AffineLPV as AffineLPV,
    FormulaSimplexMap as FormulaSimplexMap,
    InnovationLPV as InnovationLPV,
    LPVInputOutput as LPVInputOutput,
    LTVInputOutput as LTVInputOutput,
    LTVStateSpace as LTVStateSpace,
    MultilinearSimplexMap as MultilinearSimplexMap,
    NoiseCovariance as NoiseCovariance,
    PolytopicLPV as PolytopicLPV,
    TimeFunction as TimeFunction,
    affine_to_polytopic as affine_to_polytopic,
)

__all__ = [
    "__version__",
    "example_systems",
    "DimensionError",
    "ExpressionError",
    "IdentifiabilityError",
    "LMIInfeasibleError",
    "LpvestError",
    "ModelFileError",
    "NonFiniteError",
    "NotPositiveDefiniteError",
    "NumericalError",
    "SchedulingRangeError",
    "Expression",
    "FormulaMatrix",
    "SystemFile",
    "dump_system",
    "load_system",
    "loads_system",
    "save_system",
    "CallableBasis",
    "FormulaBasis",
    "Monomial",
    "SchedulingSpace",
    "AffineDependence",
    "AffineLPV",
    "FormulaSimplexMap",
    "InnovationLPV",
    "LPVInputOutput",
    "LTVInputOutput",
    "LTVStateSpace",
    "MultilinearSimplexMap",
    "NoiseCovariance",
    "PolytopicLPV",
    "TimeFunction",
    "affine_to_polytopic",
]

# H-infinity (issue 4)
from .design import (
    EpsilonCurve as EpsilonCurve,
    EpsilonSearch as EpsilonSearch,
    HinfDesign as HinfDesign,
    HinfProgram as HinfProgram,
    design_hinf as design_hinf,
    epsilon_curve as epsilon_curve,
    search_epsilon as search_epsilon,
)
from .estimators.hinf import HinfFilter as HinfFilter, hinf_filter_batch as hinf_filter_batch

__all__ += [
    "EpsilonCurve",
    "EpsilonSearch",
    "HinfDesign",
    "HinfProgram",
    "design_hinf",
    "epsilon_curve",
    "search_epsilon",
    "HinfFilter",
    "hinf_filter_batch",
]
