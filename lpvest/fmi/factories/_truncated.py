"""Factory of the TruncatedKalman FMU: the truncated-memory LPV Kalman filter
(Cox & Toth Theorem 1 with ERRATA (6a))."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...core._errors import LpvestError, abbreviate
from ...core._validation import check_box
from ...estimators._truncated import TruncatedKalmanFilter

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ...systems._affine import AffineLPV

__all__ = ["build", "STARTS"]

#: Start covariances of the restarted recursion selectable from the FMU parameter ``start``.
STARTS = ("theorem", "steady-state")


def build(
    model: AffineLPV, *, design: object = None, tau: int, start: str, start_p: ArrayLike | None = None
) -> TruncatedKalmanFilter:
    """The truncated filter with memory ``tau``; ``start = "steady-state"`` starts
    the restarted recursion from the steady-state covariance of the model frozen
    at the scheduling value ``start_p`` (scipy's DARE)."""
    if start not in STARTS:
        raise LpvestError(f"start = {abbreviate(start, 30)}; expected one of {', '.join(STARTS)}")
    p = None if start_p is None else np.asarray(start_p, dtype=float)
    if start == "steady-state" and p is not None and p.shape == (model.space.dim,):
        # named as the FMU parameter it is (the filter's own check says "scheduling value p1")
        space = model.space
        check_box(p, space.lower, space.upper,
                  [f"start_p[{j + 1}] (scheduling variable {n})" for j, n in enumerate(space.names)], what="parameter")
    return TruncatedKalmanFilter(model, int(tau), start=start, start_p=p if start == "steady-state" else None)
