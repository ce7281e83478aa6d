"""lpvest: estimation for LPV and LTV systems, as Python and as FMI 2.0 FMUs.

The numerics import only numpy at import time (scipy, cvxpy, matplotlib and
fmpy are imported inside the functions that need them), so the FMUs that
carry this package run where only numpy is installed. The public names are
imported when first used (:mod:`lpvest.core._lazy`): ``import lpvest`` and
``import lpvest.<module>`` import nothing else, so the command line and every
worker process start quickly.

The public names, by concept: errors; model files, systems and
scheduling; signals and streaming plants; the exact and truncated Kalman
filters and their analyses; the H-infinity designs and filters; the B-spline
estimator of LTV systems; co-simulation files and SSP. The streaming protocol
is :mod:`lpvest.core`, FMUs are built by :mod:`lpvest.fmi`.

>>> import lpvest
>>> plant = lpvest.load_system("peixoto-ex1").model()
>>> plant.n_vertices
2
"""

from typing import TYPE_CHECKING

from ._version import __version__ as __version__
from .core._lazy import LOAD_EXPORTS, lazy_exports

# the public names: seen by type checkers; run on first use (core/_lazy.py)
if TYPE_CHECKING or globals().get(LOAD_EXPORTS, False):
    # -- errors (every deliberate error derives from LpvestError) ------------------------
    from .core import (
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
        SamplingError as SamplingError,
        SchedulingRangeError as SchedulingRangeError,
    )

    # -- model files, systems, scheduling and formulas -----------------------------------
    # isort: split
    from .core import (
        CallableBasis as CallableBasis,
        Expression as Expression,
        FormulaBasis as FormulaBasis,
        FormulaMatrix as FormulaMatrix,
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
        SystemFile as SystemFile,
        TimeFunction as TimeFunction,
        affine_to_polytopic as affine_to_polytopic,
        dump_system as dump_system,
        example_systems as example_systems,
        hinf_setting as hinf_setting,
        load_system as load_system,
        loads_system as loads_system,
        save_system as save_system,
    )

    # -- signals and streaming plants ----------------------------------------------------
    # isort: split
    from .core import SignalGenerator as SignalGenerator, SignalSpec as SignalSpec, sample_signal as sample_signal
    from .systems import DiscretePlant as DiscretePlant, LTVPlant as LTVPlant

    # -- Kalman filtering (Cox & Toth): exact, truncated memory, analyses ----------------
    # isort: split
    from .analysis import (
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
    from .estimators import (
        AssumptionBounds as AssumptionBounds,
        SteadyState as SteadyState,
        TruncatedKalmanFilter as TruncatedKalmanFilter,
        assumption_bounds as assumption_bounds,
        steady_state as steady_state,
        theorem_start_covariance as theorem_start_covariance,
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

    # -- H-infinity filtering (Peixoto et al.): LMI designs and the filters --------------
    # isort: split
    from .design import (
        EpsilonCurve as EpsilonCurve,
        EpsilonSearch as EpsilonSearch,
        HinfDesign as HinfDesign,
        HinfProgram as HinfProgram,
        design_hinf as design_hinf,
        epsilon_curve as epsilon_curve,
        search_epsilon as search_epsilon,
    )
    from .estimators import HinfFilter as HinfFilter, hinf_filter_batch as hinf_filter_batch

    # -- LTV estimation with B-splines (Sridhar et al.) ----------------------------------
    # isort: split
    from .estimators.bspline import (
        BSplineObserver as BSplineObserver,
        KernelFit as KernelFit,
        KernelIdentity as KernelIdentity,
        KernelModel as KernelModel,
        KernelRegression as KernelRegression,
        Known as Known,
        UnknownConstant as UnknownConstant,
        UnknownSpline as UnknownSpline,
        fit_kernel_model as fit_kernel_model,
        kernel_identity as kernel_identity,
        kernel_regression as kernel_regression,
        reconstruct_state as reconstruct_state,
    )

    # -- co-simulation files and SSP -----------------------------------------------------
    # isort: split
    from .cosim._cosimfile import CoSimFile as CoSimFile, CoSimResult as CoSimResult, load_cosim as load_cosim
    from .cosim._ssp import read_ssp as read_ssp, simulate_ssp as simulate_ssp, write_ssp as write_ssp
else:
    __getattr__, __dir__ = lazy_exports(__name__)


__all__ = [
    "__version__",
    # errors
    "LpvestError", "ArgumentError", "ArgumentTypeError", "DimensionError", "ExpressionError",
    "IdentifiabilityError", "InternalError", "LMIInfeasibleError", "ModelFileError", "NonFiniteError",
    "NotPositiveDefiniteError", "NumericalError", "OutputError", "SamplingError", "SchedulingRangeError",
    # model files, systems, scheduling, formulas
    "example_systems", "load_system", "loads_system", "dump_system", "save_system", "SystemFile",
    "AffineLPV", "AffineDependence", "NoiseCovariance", "PolytopicLPV", "FormulaSimplexMap",
    "MultilinearSimplexMap", "affine_to_polytopic", "hinf_setting", "InnovationLPV", "LPVInputOutput", "LTVStateSpace",
    "LTVInputOutput", "TimeFunction", "SchedulingSpace", "FormulaBasis", "CallableBasis", "Monomial",
    "Expression", "FormulaMatrix",
    # signals and streaming plants
    "SignalGenerator", "SignalSpec", "sample_signal", "DiscretePlant", "LTVPlant",
    # Kalman filtering
    "kalman_filter", "KalmanResult", "LPVKalmanFilter", "KalmanModel", "KalmanState", "KalmanStep",
    "kalman_step", "simulate_innovation_form", "InnovationFormData", "TruncatedKalmanFilter",
    "theorem_start_covariance", "steady_state", "SteadyState", "assumption_bounds", "AssumptionBounds",
    "truncation_errors", "TruncationErrors", "decay_rate", "tau_needed", "frozen_gains", "monotonicity",
    "prediction_error_covariance", "PredictionError", "compare_filters", "FilterComparison",
    # H-infinity filtering
    "design_hinf", "HinfDesign", "search_epsilon", "EpsilonSearch", "epsilon_curve", "EpsilonCurve",
    "HinfProgram", "HinfFilter", "hinf_filter_batch",
    # LTV estimation with B-splines
    "fit_kernel_model", "KernelFit", "KernelModel", "Known", "UnknownConstant", "UnknownSpline",
    "kernel_regression", "KernelRegression", "reconstruct_state", "BSplineObserver", "kernel_identity",
    "KernelIdentity",
    # co-simulation files and SSP
    "load_cosim", "CoSimFile", "CoSimResult", "read_ssp", "write_ssp", "simulate_ssp",
]
