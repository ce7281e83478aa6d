"""Estimators: every one follows the :class:`~lpvest.estimators.base.StreamingEstimator`
protocol, so that one FMU adapter serves them all."""

from .base import (
    Port as Port,
    StreamingEstimator as StreamingEstimator,
    run_streaming as run_streaming,
)

__all__ = ["Port", "StreamingEstimator", "run_streaming"]
