"""The kernels (13)-(19) of Sridhar, Ghoshal & Michalska, evaluated literally.

An oracle for ``tests/test_bspline.py``, independent of the moment machinery
of :mod:`lpvest.estimators.bspline` (which never evaluates the kernels
pointwise): the paper's full kernels, including the part that depends on no
coefficient, and their ``t``-derivatives (the Leibniz-rule derivatives of
(12) and (15) the paper does not print; see ``lpvest/estimators/bspline/_kernels.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np


class KernelFunctions(NamedTuple):
    """The kernels (13)-(19) and their ``t``-derivatives at points ``(t, tau)``.

    Parameters
    ----------
    Ky : ndarray
        (18).
    Ku : ndarray
        (19).
    dKy : ndarray
        d/dt of (18) without the jump at tau = t.
    dKu : ndarray
        d/dt of (19).
    C : ndarray
        ``C_[a,b](t)``.
    """

    Ky: np.ndarray
    Ku: np.ndarray
    dKy: np.ndarray
    dKu: np.ndarray
    C: np.ndarray


def kernel_functions(
    t: np.ndarray | float,
    tau: np.ndarray | float,
    a: float,
    b: float,
    coefficients: dict[str, Callable[[np.ndarray], np.ndarray]],
) -> KernelFunctions:
    """The kernels (13)-(19) evaluated literally, pointwise.

    Parameters
    ----------
    t : array_like
        Times ``t`` (broadcast against ``tau``).
    tau : array_like
        Integration variable ``xi`` (for ``tau <= t``) or ``zeta`` (``tau > t``).
    a, b : float
        The window ``[a, b]``.
    coefficients : dict of str to callable
        ``a0, a1, da1, b0, b1, db1`` as callables of time (missing ones are zero).

    Returns
    -------
    KernelFunctions
        The kernels divided by ``C``, and ``C``, broadcast over ``t`` and ``tau``.
    """
    t = np.asarray(t, dtype=float)
    tau = np.asarray(tau, dtype=float)

    def get(name: str) -> np.ndarray:
        f = coefficients.get(name)
        return np.zeros_like(tau) if f is None else np.asarray(f(tau), dtype=float)

    a0, a1, da1 = get("a0"), get("a1"), get("da1")
    b0, b1, db1 = get("b0"), get("b1"), get("db1")
    s = tau - a
    r = b - tau
    KFy = 4 * s - s**2 * a1 + (t - tau) * (-2 + 2 * s * a1 + s**2 * da1 - s**2 * a0)  # (13)
    KFu = -(s**2) * b1 + (t - tau) * (2 * s * b1 + s**2 * db1 - s**2 * b0)  # (14)
    KBy = 4 * r + r**2 * a1 + (t - tau) * (2 + 2 * r * a1 - r**2 * da1 + r**2 * a0)  # (16)
    KBu = r**2 * b1 + (t - tau) * (2 * r * b1 - r**2 * db1 + r**2 * b0)  # (17)
    dKFy = -2 + 2 * s * a1 + s**2 * da1 - s**2 * a0
    dKFu = 2 * s * b1 + s**2 * db1 - s**2 * b0
    dKBy = 2 + 2 * r * a1 - r**2 * da1 + r**2 * a0
    dKBu = 2 * r * b1 - r**2 * db1 + r**2 * b0
    C = (t - a) ** 2 + (b - t) ** 2  # C_[a,b](t) of (18), (19)
    fwd = tau <= t
    return KernelFunctions(
        np.where(fwd, KFy, KBy) / C,
        np.where(fwd, KFu, KBu) / C,
        np.where(fwd, dKFy, dKBy) / C,
        np.where(fwd, dKFu, dKBu) / C,
        C,
    )
