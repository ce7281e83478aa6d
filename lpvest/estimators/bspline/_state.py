"""State reconstruction from the estimated coefficients, (4) / (32).

Notes: :mod:`lpvest.estimators.bspline`.
"""

from __future__ import annotations

import numpy as np

from ...core._errors import (
    DimensionError,
)
from ...core._validation import as_vector, check_finite
from ...systems._ltv import LTVStateSpace

__all__ = ["reconstruct_state"]


# -- state reconstruction, (4) / (32) ------------------------------------------------------------


def reconstruct_state(
    realization: LTVStateSpace, t: object, y: object, dy: object, u: object
) -> np.ndarray:
    """The state from the output and its derivative, (4) and (32) for ``n = 2``::

        x = [Gamma_0; Gamma_1]^-1 ([y; y'] - [0; Delta_11 u]),
        Gamma_0 = C,  Gamma_1 = C A + C',  Delta_11 = C B.

    Parameters
    ----------
    realization : LTVStateSpace
        A second-order realization. ``C'`` comes from its formulas, or by the
        complex step for callables; a callable that returns the same real
        matrix at nearby times (a constant map) has ``C' = 0``.
    t, y, dy, u : array_like, shape (m,)
        Times, the output ``y``, its derivative ``y'`` and the input ``u`` at those times.

    Returns
    -------
    ndarray, shape (m, 2)
        The state ``x(t_k)``, one row per time.

    Examples
    --------
    >>> from lpvest import load_system
    >>> ss = load_system("sridhar-ltv").model("state_space")
    >>> reconstruct_state(ss, [1.0], [0.3], [-0.2], [5.0]).round(12)
    array([[ 0.3, -0.2]])
    """
    times = as_vector(t, "t")
    m = times.size
    yy, dd, uu = (as_vector(v, n, m) for v, n in ((y, "y"), (dy, "dy"), (u, "u")))
    if realization.n != 2:
        raise DimensionError(f"reconstruct_state is for second-order realizations; this one has n = {realization.n}")
    fc = realization.formulas.get("C")
    if fc is not None:
        dC_of = fc.derivative("t")

        def dC(tt: float) -> np.ndarray:
            return dC_of.evaluate({"t": np.asarray(tt, dtype=float)})
    else:

        def dC(tt: float) -> np.ndarray:
            hh = 1e-20
            val = np.asarray(realization.C(tt + 1j * hh))  # type: ignore[arg-type]  # complex step: C takes complex t
            if np.iscomplexobj(val):
                return val.imag / hh
            # a callable that ignores its argument (e.g. the constant output map of
            # LTVInputOutput.to_state_space): constant if it is at nearby times
            step = 1e-3 * (1.0 + abs(tt))
            c0 = np.asarray(realization.C(tt), dtype=float)
            if all(np.array_equal(np.asarray(realization.C(tt + d), dtype=float), c0) for d in (-step, step)):
                return np.zeros_like(c0)
            raise DimensionError(
                "C(t) is a time-varying callable without complex-step support: give C as formulas of t"
            )

    x = np.empty((m, 2))
    for k, tk in enumerate(times):
        C = np.asarray(realization.C(tk), dtype=float)
        G = np.vstack([C, C @ realization.A(tk) + dC(tk)])
        rhs = np.array([yy[k], dd[k] - float((C @ realization.B(tk))[0, 0]) * uu[k]])
        x[k] = np.linalg.solve(G, rhs)
    check_finite(x, "reconstructed state")
    return x


