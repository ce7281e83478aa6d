"""Factories of the estimator FMUs (named in :mod:`lpvest.fmi.registry`).

Each builds a :class:`~lpvest.estimators.base.StreamingEstimator` from the
model carried by the FMU, the optional build-time design and the FMU's
parameters. They import only what the filter needs at run time (numpy).
"""

from __future__ import annotations

from typing import Any

from ..errors import LpvestError

__all__ = ["kalman", "truncated_kalman"]

#: Start covariances of the truncated filter selectable from an FMU parameter.
TRUNCATED_STARTS = ("theorem", "steady-state")


def kalman(model: Any, *, design: Any = None) -> Any:
    """The exact LPV Kalman filter (Cox & Toth (4a)-(4e)) of an affine model."""
    from ..estimators.kalman import LPVKalmanFilter

    return LPVKalmanFilter(model)


def truncated_kalman(model: Any, *, design: Any = None, tau: int, start: str) -> Any:
    """The truncated-memory Kalman filter (Theorem 1, ERRATA (6a)) with memory ``tau``."""
    from ..estimators.truncated import TruncatedKalmanFilter

    if start not in TRUNCATED_STARTS:
        raise LpvestError(f"start = {start!r}; expected one of {', '.join(TRUNCATED_STARTS)}")
    return TruncatedKalmanFilter(model, int(tau), start=start)
