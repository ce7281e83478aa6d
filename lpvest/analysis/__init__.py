"""Analyses built on the estimators (no streaming state, no FMU)."""

from .fading_memory import (
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
