"""Estimators, each a streaming component (:mod:`lpvest.core`), so that one
FMU adapter serves them all:

- :mod:`~lpvest.estimators.kalman`: the exact LPV Kalman filter (Cox & Toth (4a)-(4e)),
  streaming and batch, and its parallel-in-time form (``_scan.py``);
- :class:`TruncatedKalmanFilter` and its analyses (``_truncated.py``): the truncated-memory
  filter (Theorem 1);
- :class:`HinfFilter` (``_hinf.py``): the H-infinity filter (2) of Peixoto et al. for a design;
- :mod:`~lpvest.estimators.bspline`: the B-spline joint parameter and state estimator of
  Sridhar et al.

Examples
--------
The streaming filters share one protocol (:mod:`lpvest.core`):

>>> from lpvest import load_system
>>> from lpvest.estimators.kalman import LPVKalmanFilter
>>> kf = LPVKalmanFilter(load_system("cox-toth-truncation").model())
>>> [p.name for p in kf.input_ports], kf.step({"p": [0.0], "u": [1.0], "y": [0.1, -0.2]})["xhat"].shape
(['p', 'u', 'y'], (2,))
"""

from ._hinf import (
    HinfFilter as HinfFilter,
    HinfRun as HinfRun,
    HinfStep as HinfStep,
    hinf_filter_batch as hinf_filter_batch,
    hinf_step as hinf_step,
    needs_scheduling as needs_scheduling,
)
from ._truncated import (
    AssumptionBounds as AssumptionBounds,
    SteadyState as SteadyState,
    TruncatedKalmanFilter as TruncatedKalmanFilter,
    assumption_bounds as assumption_bounds,
    restart_covariance as restart_covariance,
    start_covariance as start_covariance,
    steady_state as steady_state,
    theorem_start_covariance as theorem_start_covariance,
    truncated_prior as truncated_prior,
)
from .kalman._decorrelation import Decorrelated as Decorrelated, decorrelate as decorrelate

__all__ = [
    "HinfFilter",
    "HinfStep",
    "HinfRun",
    "hinf_step",
    "hinf_filter_batch",
    "needs_scheduling",
    "Decorrelated",
    "decorrelate",
    "AssumptionBounds",
    "assumption_bounds",
    "theorem_start_covariance",
    "SteadyState",
    "steady_state",
    "start_covariance",
    "restart_covariance",
    "truncated_prior",
    "TruncatedKalmanFilter",
]
