"""The decorrelated form (5c), (5e) of Cox & Tóth in the general form, written
once for one sample and for a stack: the truncated filter's restart (6a)
(:mod:`lpvest.estimators`) and the parallel scan
(:mod:`lpvest.estimators.kalman`) both call :func:`decorrelate_matrices`.

(5a)-(5e) write ``G w_t`` as its minimum-variance estimate from the
measurement noise plus an uncorrelated remainder. The paper's ``H^-1``
presumes a square invertible ``H``. In general the noise in ``y_t`` is
``e_t = H v_t`` with covariance ``H R H^T``, and

    E[G w_t | H v_t] = J_t H v_t,   J_t = G S H^T (H R H^T)^-1,
    Abar_t = A - J_t C,             (5c)
    G Qbar G^T := G Q G^T - J_t H S^T G^T,   (5e)

needing only ``H R H^T`` positive definite (``H`` of full row rank). ``J``
comes from the Cholesky factor of ``H R H^T``
(:mod:`~lpvest.estimators.kalman._smallmat`): for one sample with
``n_y <= SMALL_NY``, ``J = (chol^-1 (G S H^T)^T)^T chol^-1`` with the factor's
inverse in Python floats (the streaming truncated filter, the native runtime's
arithmetic); for a stack, LAPACK's factor and two solves (the numbers the
theorem's start covariance has always been computed with), or, with
``recurrence=True`` (the scan, where LAPACK's per-sample calls would double
the run time), the same formula as one sample, entry by entry over the stack. With ``S = 0``,
``J = 0``, ``Abar = A`` and ``G Qbar G^T = G Q G^T`` (symmetrised), without
products.

Runtime code: imports only numpy.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...core._errors import NotPositiveDefiniteError
from ...core._linalg import mT, sym
from ._model import KalmanMatrices
from ._smallmat import FactorError, chol_inverse, cholesky, is_small, lsolve, usolve

__all__ = ["Decorrelated", "decorrelate", "decorrelate_matrices"]


class Decorrelated(NamedTuple):
    """The decorrelated form (5c), (5e) at one sample or stacked (general ``H``).

    Stacked matrices give every field a leading axis ``T``.

    Parameters
    ----------
    Abar : ndarray, shape (n_x, n_x)
        ``A - J C``, (5c).
    GQbarG : ndarray, shape (n_x, n_x)
        ``G Qbar G^T``, (5e), symmetrised.
    J : ndarray, shape (n_x, n_y)
        ``G S H^T (H R H^T)^-1``.
    """

    Abar: np.ndarray
    GQbarG: np.ndarray
    J: np.ndarray


def decorrelate_matrices(
    A: np.ndarray, C: np.ndarray, GQG: np.ndarray, GSH: np.ndarray, HRH: np.ndarray, *, recurrence: bool = False
) -> Decorrelated:
    """(5c), (5e) from the matrices of one sample or of a stack (module notes).

    Parameters
    ----------
    A, C : ndarray, shape (..., n_x, n_x), (..., n_y, n_x)
        The model matrices of (1).
    GQG, GSH, HRH : ndarray, shape (..., n_x, n_x), (..., n_x, n_y), (..., n_y, n_y)
        ``G Q G^T``, ``G S H^T``, ``H R H^T``.
    recurrence : bool, default False
        Factor a stack with ``n_y <= SMALL_STACK`` by the kernel's recurrence
        too (the parallel scan: one elementwise operation per entry instead of
        a LAPACK call per sample; each sample then gets the numbers it gets
        alone) rather than by LAPACK.

    Returns
    -------
    Decorrelated
        ``Abar``, ``G Qbar G^T`` and ``J``, stacked like the input.

    Raises
    ------
    FactorError
        ``H R H^T`` is not positive definite (for a stack: the first sample
        that is not, ``index``).
    """
    if is_small(HRH) and (HRH.ndim == 2 or recurrence):
        Ci, _ = chol_inverse(HRH)
        if not np.any(GSH):
            return Decorrelated(A, sym(GQG), np.zeros(GSH.shape))
        J = mT(Ci @ mT(GSH)) @ Ci  # G S H^T chol^-T chol^-1
    else:
        L = cholesky(HRH, lapack=True)
        if not np.any(GSH):
            return Decorrelated(A, sym(GQG), np.zeros(GSH.shape))
        # J^T = (H R H^T)^-1 (G S H^T)^T by two solves with the factor
        J = mT(usolve(L, lsolve(L, mT(GSH), lapack=True), lapack=True))
    return Decorrelated(A - J @ C, sym(GQG - J @ mT(GSH)), J)


def decorrelate(m: KalmanMatrices, *, where: str = "") -> Decorrelated:
    """``Abar``, ``G Qbar G^T`` and ``J`` of (5c), (5e) in the general form
    (module notes); works on one sample or a stack.

    Parameters
    ----------
    m : KalmanMatrices
        The matrices at one ``p`` or stacked along time.
    where : str, default ""
        Appended to the error message (e.g. ``" at t=5"``).

    Returns
    -------
    Decorrelated
        ``Abar``, ``G Qbar G^T`` and ``J``, stacked like ``m``.

    Raises
    ------
    NotPositiveDefiniteError
        ``H R H^T`` is singular (``H`` not of full row rank).

    Examples
    --------
    >>> from lpvest import load_system
    >>> from lpvest.estimators.kalman import KalmanModel
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> d = decorrelate(km.matrices([0.0]))
    >>> bool(np.all(np.linalg.eigvalsh(d.GQbarG) > 0))
    True
    """
    try:
        return decorrelate_matrices(m.A, m.C, m.GQG, m.GSH, m.HRH)
    except FactorError as exc:
        raise NotPositiveDefiniteError(
            f"H(p) R H(p)^T is singular{where}: the decorrelated form (5c)/(5e) needs it "
            "invertible (H of full row rank)"
        ) from exc
