"""lpvest: estimation for LPV and LTV systems, as Python and as FMI 2.0 FMUs.

The numerics import only numpy at import time (scipy, cvxpy, matplotlib and
fmpy are imported inside the functions that need them), so the FMUs that
carry this package run where only numpy is installed.

>>> import lpvest
>>> plant = lpvest.load_system("peixoto-ex1").model()
>>> plant.n_vertices
2
"""

from ._version import __version__ as __version__
from .catalog import example_systems as example_systems
from .errors import (
    ArgumentError as ArgumentError,
    ArgumentTypeError as ArgumentTypeError,
    DimensionError as DimensionError,
    ExpressionError as ExpressionError,
    IdentifiabilityError as IdentifiabilityError,
    InternalError as InternalError,
    LMIInfeasibleError as LMIInfeasibleError,
    LpvestError as LpvestError,
    ModelFileError as ModelFileError,
    NonFiniteError as NonFiniteError,
    NotPositiveDefiniteError as NotPositiveDefiniteError,
    NumericalError as NumericalError,
    OutputError as OutputError,
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

# FMU area (isort places its two imports): test signals
from .signals import (
    SignalGenerator as SignalGenerator,
    SignalSpec as SignalSpec,
    sample_signal as sample_signal,
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

# B-spline (issue 5)
# isort: split
from .errors import SamplingError as SamplingError
from .estimators.bspline import (
    BSplineObserver as BSplineObserver,
    KernelFit as KernelFit,
    KernelModel as KernelModel,
    KernelRegression as KernelRegression,
    Known as Known,
    UnknownConstant as UnknownConstant,
    UnknownSpline as UnknownSpline,
    fit_kernel_model as fit_kernel_model,
    kernel_regression as kernel_regression,
    reconstruct_state as reconstruct_state,
)
from .estimators.bspline.kernels import KernelIdentity as KernelIdentity, kernel_identity as kernel_identity

# FMU area: streaming plants
from .systems.streaming import DiscretePlant as DiscretePlant, LTVPlant as LTVPlant

# Kalman (issue 3)
# isort: split
from .analysis.fading_memory import (
    FilterComparison as FilterComparison,
    PredictionError as PredictionError,
    TruncationErrors as TruncationErrors,
    compare_filters as compare_filters,
    decay_rate as decay_rate,
    frozen_gains as frozen_gains,
    monotonicity as monotonicity,
    prediction_error_covariance as prediction_error_covariance,
    tau_needed as tau_needed,
    truncation_errors as truncation_errors,
)
from .estimators.kalman import (
    InnovationFormData as InnovationFormData,
    KalmanModel as KalmanModel,
    KalmanResult as KalmanResult,
    KalmanState as KalmanState,
    KalmanStep as KalmanStep,
    LPVKalmanFilter as LPVKalmanFilter,
    kalman_filter as kalman_filter,
    kalman_step as kalman_step,
    simulate_innovation_form as simulate_innovation_form,
)
from .estimators.truncated import (
    AssumptionBounds as AssumptionBounds,
    SteadyState as SteadyState,
    TruncatedKalmanFilter as TruncatedKalmanFilter,
    assumption_bounds as assumption_bounds,
    steady_state as steady_state,
    theorem_start_covariance as theorem_start_covariance,
)

__all__ = [
    "__version__",
    "example_systems",
    "ArgumentError",
    "ArgumentTypeError",
    "InternalError",
    "OutputError",
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
    # B-spline (issue 5)
    "SamplingError",
    "BSplineObserver",
    "KernelFit",
    "KernelModel",
    "KernelRegression",
    "Known",
    "UnknownConstant",
    "UnknownSpline",
    "fit_kernel_model",
    "kernel_regression",
    "reconstruct_state",
    "KernelIdentity",
    "kernel_identity",
    # FMU area
    "SignalGenerator",
    "SignalSpec",
    "sample_signal",
    "DiscretePlant",
    "LTVPlant",
    # Kalman (issue 3)
    "FilterComparison",
    "PredictionError",
    "TruncationErrors",
    "compare_filters",
    "decay_rate",
    "frozen_gains",
    "monotonicity",
    "prediction_error_covariance",
    "tau_needed",
    "truncation_errors",
    "InnovationFormData",
    "KalmanModel",
    "KalmanResult",
    "KalmanState",
    "KalmanStep",
    "LPVKalmanFilter",
    "kalman_filter",
    "kalman_step",
    "simulate_innovation_form",
    "AssumptionBounds",
    "SteadyState",
    "TruncatedKalmanFilter",
    "assumption_bounds",
    "steady_state",
    "theorem_start_covariance",
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

# Co-simulation files and the SSP export (issue 7: lpvest cosim, SSP)
from .cosimfile import CoSimFile as CoSimFile, CoSimResult as CoSimResult, load_cosim as load_cosim  # noqa: E402
from .ssp import read_ssp as read_ssp, simulate_ssp as simulate_ssp, write_ssp as write_ssp  # noqa: E402

__all__ += [
    "CoSimFile",
    "CoSimResult",
    "load_cosim",
    "read_ssp",
    "simulate_ssp",
    "write_ssp",
]
