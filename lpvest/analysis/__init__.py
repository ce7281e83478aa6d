"""Analyses built on the estimators (no streaming state, no FMU).

Examples
--------
The frozen (steady-state) gain of the truncation example at ``p = 0.5``:

>>> import numpy as np
>>> from lpvest import load_system
>>> np.round(frozen_gains(load_system("cox-toth-truncation").model(), [[0.5]]), 4)
array([[[ 0.1098, -0.0124],
        [-0.0124,  0.0648]]])
"""

from ._fading_memory import (
    FilterComparison as FilterComparison,
    Monotonicity as Monotonicity,
    PredictionError as PredictionError,
    TruncationErrors as TruncationErrors,
    compare_filters as compare_filters,
    decay_rate as decay_rate,
    empirical_prediction_error as empirical_prediction_error,
    frozen_gains as frozen_gains,
    monotonicity as monotonicity,
    prediction_error_covariance as prediction_error_covariance,
    tau_needed as tau_needed,
    truncation_errors as truncation_errors,
)

__all__ = [
    "FilterComparison",
    "Monotonicity",
    "PredictionError",
    "TruncationErrors",
    "compare_filters",
    "decay_rate",
    "empirical_prediction_error",
    "frozen_gains",
    "monotonicity",
    "prediction_error_covariance",
    "tau_needed",
    "truncation_errors",
]
