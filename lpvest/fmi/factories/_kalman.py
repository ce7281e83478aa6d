"""Factory of the Kalman FMU: the exact LPV Kalman filter (Cox & Toth (4a)-(4e))."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...estimators.kalman._streaming import LPVKalmanFilter

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ...systems._affine import AffineLPV

__all__ = ["build"]


def build(
    model: AffineLPV, *, design: object = None, x0: ArrayLike | None = None, P0: ArrayLike | None = None
) -> LPVKalmanFilter:
    """The exact LPV Kalman filter of an affine model, started from ``x0``, ``P0``
    (the mean and covariance of ``x_0``; default: the model's)."""
    return LPVKalmanFilter(model, x0=None if x0 is None else np.asarray(x0, dtype=float),
                           P0=None if P0 is None else np.asarray(P0, dtype=float))
