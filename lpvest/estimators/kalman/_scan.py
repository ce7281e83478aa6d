"""Parallel-in-time evaluation of the exact LPV Kalman filter (4a)-(4e).

:func:`~lpvest.estimators.kalman.kalman_filter` runs this with
``method="scan"`` (and usually with ``"auto"``): the same filter as the
sample-by-sample recursion, computed with a few hundred batched numpy calls
over the whole trajectory instead of a dozen small calls per sample.

Decorrelation
-------------
The noises of one sample are correlated (``S != 0``), and the correlation
is between ``G w_t`` (state ``t -> t + 1``) and ``H v_t`` (output ``t``).
With ``e_t = H v_t = y_t - C x_t - D u_t`` and, as in
:mod:`lpvest.estimators`,

    J_t = G S H^T (H R H^T)^-1,   Abar_t = A - J_t C,
    G Qbar G^T = G Q G^T - J_t H S^T G^T   (Schur complement, >= 0),

the state equation is ``x_{t+1} = Abar_t x_t + c_t + eps_t`` with the known
input ``c_t = B u_t + J_t (y_t - D u_t)`` and ``eps_t = G w_t - J_t H v_t``,
which has covariance ``G Qbar G^T`` and is uncorrelated with ``H v_t`` (so
independent of ``x_t``, of ``y_0 .. y_t`` and of everything earlier). The
model is then a linear Gaussian state-space model with *uncorrelated* noises
``(eps_t, H v_t)`` and an input that depends on data already seen: given
``y_0 .. y_t``, ``c_t`` is a constant. Its filter is therefore the same
filter: ``x^_{t|t}``, ``P_{t|t}`` are the conditional moments of the same
``x_t`` given the same data, and

    x^_{t+1|t} = Abar_t x^_{t|t} + c_t,
    P_{t+1|t}  = Abar_t P_{t|t} Abar_t^T + G Qbar G^T              (ERRATA (9)),
    Omega_t    = C P_{t|t-1} C^T + H R H^T                          (4e),
    L_t        = P_{t|t-1} C^T Omega_t^-1                           (ERRATA (7)),
    K_t        = (A P_{t|t-1} C^T + G S H^T) Omega_t^-1 = Abar_t L_t + J_t   (4c),
    xi_t       = y_t - C x^_{t|t-1} - D u_t                         (4b).

(The last identity: ``Abar L + J = A L + J (I - C L)`` and
``J (I - C L) = J H R H^T Omega^-1 = G S H^T Omega^-1``.) This needs
``H R H^T`` positive definite at every sample; when it is not, the
decorrelation does not exist and the caller uses the sequential recursion.

Filtering elements (Särkkä & García-Fernández 2021)
---------------------------------------------------
The element of samples ``s .. t`` is ``(A, b, C, J, eta)`` with

    x_t | x_{s-1}, y_s .. y_t ~ N(A x_{s-1} + b, C),
    p(y_s .. y_t | x_{s-1}) ∝ exp(-x_{s-1}^T J x_{s-1} / 2 + eta^T x_{s-1}).

Sample ``t`` alone: with ``F = Abar_{t-1}``, ``Qe = G Qbar G^T_{t-1}``,
``m = c_{t-1}``, ``H = C_t``, ``R = H R H^T_t``, ``y' = y_t - D_t u_t``,
``S = H Qe H^T + R = chol chol^T``, ``K = Qe H^T S^-1``:

    A = (I - K H) F,   b = m + K (y' - H m),   C = Qe - K S K^T,
    J = V^T V,   eta = V^T v,   V = chol^-1 H F,   v = chol^-1 (y' - H m).

Sample 0 is the same with ``F = 0``, ``Qe = P0``, ``m = x0``: ``A = 0``,
``J = 0``, ``eta = 0``, ``(b, C) = (x^_{0|0}, P_{0|0})``. ``P0`` is never
inverted, so a singular or zero ``P0`` is fine. Two adjacent elements
combine by the associative operator (``W = (I + C_i J_j)^-1``; ``C_i J_j`` is
similar to a positive semidefinite matrix, so ``I + C_i J_j`` is invertible)

    A   = A_j W A_i,            b = A_j W (b_i + C_i eta_j) + b_j,
    C   = A_j W C_i A_j^T + C_j,
    eta = (W A_i)^T (eta_j - J_j b_i) + eta_i,   J = (W A_i)^T J_j A_i + J_i,

using ``(I + J_j C_i)^-1 = W^T`` (``C``, ``J`` symmetric): one solve with
``I + C_i J_j`` per combination, never an inverse. Every prefix
``(0 .. t)`` has ``A = 0`` and ``(b, C) = (x^_{t|t}, P_{t|t})``.

Schedule: a blocked scan
------------------------
The plain work-efficient scan (Blelloch; ``jax.lax.associative_scan``) takes
``2 log2 T`` levels of batched combinations. In numpy its cost is the
batched general solve with ``I + C_i J_j`` (LAPACK matrix by matrix, ~3 us
at ``n_x = 10``, thirty times a batched 10 x 10 product), twice per sample.
The schedule here needs that solve only ``~2 T / ell`` times:

1. *Reduce within blocks.* The samples are cut into ``nb`` blocks of ``ell``
   consecutive samples, and every block's element is accumulated left to
   right, all blocks at once (``ell`` batched steps). Adding one sample to
   the element of ``s .. t - 1`` is one step of a Kalman filter whose mean is
   an affine function ``A x_{s-1} + b`` of the block's initial state:
   ``A~ = F A``, ``b~ = F b + m``, ``C~ = F C F^T + Qe``,
   ``S = H C~ H^T + R = chol chol^T``, ``K = C~ H^T S^-1``, then
   ``A = (I - K H) A~``, ``b = b~ + K (y' - H b~)``, ``C = C~ - K S K^T``,
   ``J += V^T V``, ``eta += V^T v`` with ``V = chol^-1 H A~``,
   ``v = chol^-1 (y' - H b~)`` (this *is* the operator above with a
   one-sample right operand; it needs only the ``n_y x n_y`` factorisation
   of ``S``, which is ``>= H R H^T > 0``).
2. *Scan across blocks.* The work-efficient scan with the operator over the
   ``nb`` block elements gives ``x^_{s-1|s-1}``, ``P_{s-1|s-1}`` at every
   block start ``s``, hence ``x^_{s|s-1}``, ``P_{s|s-1}``.
3. *Filter within blocks.* From these, the filter in decorrelated form runs
   ``ell`` batched steps, all blocks at once, and writes every output: the
   Joseph form ``(I - L C) P (I - L C)^T + L H R H^T L^T`` for ``P_{t|t}``
   and ``Abar P_{t|t} Abar^T + G Qbar G^T`` for ``P_{t+1|t}`` (both positive
   semidefinite by construction), symmetrised.

``ell = 1`` is the plain scan, ``ell >= T`` the sequential filter in
decorrelated form. The default (:func:`block_length`, ``~ sqrt(T)``)
balances numpy's per-call overhead of steps 1 and 3 (``~ ell`` rounds of
calls) against the general combinations of step 2 (``~ T / ell``). No
inverse is formed, no jitter added; the small Cholesky factorisations and
triangular solves (``n_y <= 4``) run entry by entry over the whole stack
(:mod:`~lpvest.estimators.kalman._smallmat`, the kernel the sequential filter
uses too), and the decorrelation is the truncated filter's (5c), (5e)
(:func:`~lpvest.estimators.decorrelate`).

Accuracy
--------
The scan is exact, but its rounding errors are amplified by the
decorrelation: ``Abar = A - J C`` and ``c_t = ... + J y_t`` carry terms of
size ``amp = max_t ||J_t C_t||`` that cancel against the filtered
estimate, and the covariance goes through ``Abar P_{t|t} Abar^T``, whose
rounding is about ``eps amp^2`` of its size. When ``H R H^T`` is small next
to a strong cross-covariance (``|S|`` close to ``sqrt(Q R)``), ``amp`` is
large. :func:`scan_amplification` bounds it by
``max_t ||J_t||_F ||C_t||_F`` (two passes over the data).

Measured against the sequential recursion with the default blocks
(``benchmarks/bench_scan_accuracy.py``; the largest difference over every
output, relative to that output's largest entry). A scalar-output model
with correlation 0.9 between ``w`` and ``v``, ``amp`` set by scaling the
measurement noise, worst over ``T`` = 64, 256, 1024, 4096, 16384, 1e5
(OpenBLAS Haswell; Sandybridge and Nehalem for ``T <= 4096``, the same to
within a factor 1.5)::

    amp   <= 1     3.2      9.7      32       97       320      970      3200
    err   2.8e-15  1.9e-15  3.5e-14  5.2e-13  4.2e-12  5.6e-11  5.2e-10  7.7e-09

so ``err ~ 2 eps (1 + amp)^2`` at every ``T``: the error does not grow with
the length of the run. On random systems with 2 to 5 outputs there is a
second term, ``eps kappa`` with ``kappa = max_t cond(Omega_t)`` (up to
1.1e-12 at ``amp`` < 10 where ``kappa`` ~ 5e3, in the gains
``P C^T Omega^-1``): it is the conditioning of the filter problem, which
two backward-stable algorithms share, not an amplification of the scan's.
Over all cases (141 on Haswell with ``T`` up to 1e5, 108 each on
Sandybridge and Nehalem with ``T <= 4096``; amplifications up to 1e4),
``err <= c eps (kappa + (1 + amp)^2)`` with ``c <= 15``. The documented
accuracy, :func:`scan_error_bound`, is ``SCAN_ERROR_CONSTANT = 100`` times
``eps (kappa + (1 + amp)^2)``. ``kalman_filter(method="auto")`` takes the
scan only up to ``amp <=``
:data:`~lpvest.estimators.kalman.SCAN_MAX_AMPLIFICATION` ``= 30``, where
the scan's own term is at most 2.1e-11 (measured: 5.2e-13 on the
scalar model; 5.8e-12 on the random systems, ``kappa`` term included);
``method="scan"`` beyond it runs and warns (:class:`ScanAccuracyWarning`).
With ``S = 0``, ``J = 0`` and there is no amplification.

Blocks of one or two samples are worse: the general combinations then work
on single-sample elements, whose ``A`` and ``J`` are of the size of
``Abar`` and ``Abar^T C^T (H R H^T)^-1 C Abar``, and the error grows like
``eps amp^4`` (the plain scan, ``ell = 1``, at ``amp`` = 97 / 320 / 970:
8.5e-11 / 1.5e-8 / 6.4e-7 at ``T = 64``). Before :data:`MIN_BLOCK`,
``block_length`` chose such blocks for ``T`` below ~160, which is where the
error was largest; figures taken at ``T`` = 400 to 5000 missed it.

Runtime code: imports only numpy.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ...core._errors import NumericalError
from ...core._linalg import mT, sym
from ._decorrelation import decorrelate_matrices
from ._smallmat import FactorError, cholesky, lsolve, usolve

__all__ = [
    "Decorrelation",
    "MIN_BLOCK",
    "SCAN_ERROR_CONSTANT",
    "ScanAccuracyWarning",
    "ScanMoments",
    "block_length",
    "decorrelate_stack",
    "scan_amplification",
    "scan_error_bound",
    "scan_filter",
]

_EPS = float(np.finfo(float).eps)

#: The constant of the scan's documented accuracy (module notes, "Accuracy"):
#: every output of :func:`scan_filter` (default blocks) is within
#: ``SCAN_ERROR_CONSTANT * eps * (kappa + (1 + amp)^2)`` of the sequential
#: recursion, relative to the largest entry of that output, ``amp`` from
#: :func:`scan_amplification`, ``kappa = max_t cond(Omega_t)``. Measured
#: worst case 15 (module notes); the margin covers other BLAS kernels,
#: systems and schedules.
SCAN_ERROR_CONSTANT = 100.0


class ScanAccuracyWarning(UserWarning):
    """``kalman_filter(method="scan")`` was asked for where the scan's error
    amplification is above the gate of ``method="auto"``: the results may
    differ from the sequential recursion by more than its documented
    accuracy (the message gives the bound)."""


def scan_error_bound(amp: float, kappa: float = 1.0) -> float:
    """The scan's documented accuracy: the largest difference to the
    sequential recursion, relative to each output's largest entry,
    ``SCAN_ERROR_CONSTANT * eps * (kappa + (1 + amp)^2)``.

    ``amp``: :func:`scan_amplification`, the scan's own amplification;
    ``kappa``: ``max_t cond(Omega_t)``, the conditioning of the filter
    problem itself (two backward-stable computations of the gains
    ``P C^T Omega^-1`` differ by about ``eps kappa``, whatever the algorithm).

    Parameters
    ----------
    amp : float
        The error amplification of :func:`scan_amplification`.
    kappa : float, default 1.0
        ``max_t cond(Omega_t)``.

    Returns
    -------
    float
        The relative error bound.

    Examples
    --------
    >>> f"{scan_error_bound(0.0):.1e}", f"{scan_error_bound(30.0):.1e}", f"{scan_error_bound(30.0, 1e3):.1e}"
    ('4.4e-14', '2.1e-11', '4.4e-11')
    """
    return SCAN_ERROR_CONSTANT * _EPS * (float(kappa) + (1.0 + float(amp)) ** 2)


def _sym_into(x: np.ndarray, out: np.ndarray) -> None:
    """``out = (x + x^T) / 2`` (``out`` may be a strided view)."""
    np.add(x, mT(x), out=out)
    out *= 0.5


def _mv(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Stacked matrix-vector product ``M @ v`` for (..., r, c) and (..., c)."""
    return (M @ v[..., None])[..., 0]


class Decorrelation(NamedTuple):
    """The decorrelated model along a trajectory (module notes), stacked over ``t``.

    Parameters
    ----------
    AbarT : ndarray, shape (T, n_x, n_x)
        ``Abar^T = (A - J C)^T`` (transposed: see :func:`scan_filter`).
    GQbarG : ndarray, shape (T, n_x, n_x)
        ``G Q G^T - J H S^T G^T``.
    J : ndarray, shape (T, n_x, n_y)
        ``G S H^T (H R H^T)^-1``.
    c : ndarray, shape (T, n_x)
        ``B u + J (y - D u)``, the known input of the decorrelated state equation.
    y : ndarray, shape (T, n_y)
        ``y - D u``.
    """

    AbarT: np.ndarray
    GQbarG: np.ndarray
    J: np.ndarray
    c: np.ndarray
    y: np.ndarray


def decorrelate_stack(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    D: np.ndarray,
    GQG: np.ndarray,
    GSH: np.ndarray,
    HRH: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    *,
    AT: np.ndarray | None = None,
) -> Decorrelation | int:
    """The decorrelated model (module notes) along a trajectory, or the first
    ``t`` at which ``H R H^T`` is not (numerically) positive definite.

    ``Abar``, ``G Qbar G^T`` and ``J`` are the truncated filter's (5c), (5e)
    (:func:`~lpvest.estimators.kalman._decorrelation.decorrelate_matrices`,
    factored entry by entry over the stack); this adds the known input ``c``.
    All arguments are stacked over time (leading axis ``T``), in the layout of
    :class:`~lpvest.estimators.kalman.KalmanMatrices`; ``u`` (T, n_u), ``y``
    (T, n_y); ``AT``, optional, is ``A^T`` stored contiguously. With
    ``S = 0`` (``G S H^T = 0`` at every sample) ``J = 0`` and nothing is
    computed: ``Abar = A``, ``G Qbar G^T = G Q G^T`` (symmetrised).

    Parameters
    ----------
    A, B, C, D : ndarray, shape (T, n_x, n_x), (T, n_x, n_u), (T, n_y, n_x), (T, n_y, n_u)
        The model matrices of (1) at every sample.
    GQG : ndarray, shape (T, n_x, n_x)
        ``G Q G^T``.
    GSH : ndarray, shape (T, n_x, n_y)
        ``G S H^T``.
    HRH : ndarray, shape (T, n_y, n_y)
        ``H R H^T``.
    u : ndarray, shape (T, n_u)
        Inputs (``n_u = 0``: no input).
    y : ndarray, shape (T, n_y)
        Measurements.
    AT : ndarray, shape (T, n_x, n_x), optional
        ``A^T`` stored contiguously, returned as ``Abar^T`` when ``S = 0``
        (default: computed from ``A``).

    Returns
    -------
    Decorrelation or int
        The decorrelated model, or the first ``t`` at which ``H R H^T`` is
        not positive definite (or not finite).

    Examples
    --------
    >>> from lpvest import load_system
    >>> from lpvest.estimators.kalman import KalmanModel
    >>> model = load_system("cox-toth-truncation").model()
    >>> p = np.sin(0.25 * np.arange(100))[:, None]
    >>> u = np.ones((100, 1))
    >>> mats = KalmanModel(model).matrices_batch(p)
    >>> dec = decorrelate_stack(*mats, u, model.simulate(p, u, rng=0).y)
    >>> dec.AbarT.shape, round(scan_amplification(dec, mats.C), 3)
    ((100, 2, 2), 0.057)
    """
    try:
        d = decorrelate_matrices(A, C, GQG, GSH, HRH, recurrence=True)  # (5c), (5e)
    except FactorError as exc:
        return exc.index
    yd = y - _mv(D, u) if u.shape[1] else y
    if not np.any(GSH):  # J = 0: Abar = A, and the known input is B u
        AbarT = np.ascontiguousarray(mT(A)) if AT is None else AT
        c = _mv(B, u) if u.shape[1] else np.zeros((A.shape[0], A.shape[1]))
        return Decorrelation(AbarT, d.GQbarG, d.J, c, yd)
    c = _mv(d.J, yd)
    if u.shape[1]:
        c += _mv(B, u)
    return Decorrelation(np.ascontiguousarray(mT(d.Abar)), d.GQbarG, d.J, c, yd)


def scan_amplification(dec: Decorrelation, C: np.ndarray) -> float:
    """``max_t ||J_t||_F ||C_t||_F``, an upper bound of ``max_t ||J_t C_t||_F``
    (equal for ``n_y = 1``): how much the decorrelated form amplifies
    rounding errors (module notes, "Accuracy"). Two passes over the data.

    Parameters
    ----------
    dec : Decorrelation
        From :func:`decorrelate_stack`.
    C : ndarray, shape (T, n_y, n_x)
        ``C(p_t)`` along the trajectory.

    Returns
    -------
    amp : float
        The bound; 0 when ``J = 0`` (``S = 0``) or ``T = 0``.
    """
    J = dec.J
    if not C.shape[0] or not np.any(J):  # S = 0: J = 0
        return 0.0
    sq = np.sum(J * J, axis=(1, 2)) * np.sum(C * C, axis=(1, 2))
    return float(np.sqrt(np.max(sq)))


class ScanMoments(NamedTuple):
    """Every quantity of the sequential filter, from :func:`scan_filter`.

    Parameters
    ----------
    xp : ndarray, shape (T + 1, n_x)
        ``x^_{t|t-1}``.
    Pp : ndarray, shape (T + 1, n_x, n_x)
        ``P_{t|t-1}``.
    xf : ndarray, shape (T, n_x)
        ``x^_{t|t}``.
    Pf : ndarray, shape (T, n_x, n_x)
        ``P_{t|t}``.
    xi : ndarray, shape (T, n_y)
        Innovations ``xi_t``, (4b).
    Omega : ndarray, shape (T, n_y, n_y)
        Innovation covariances ``Omega_t``, (4e).
    K : ndarray, shape (T, n_x, n_y)
        Predictor gains ``K_t``, (4c).
    L : ndarray, shape (T, n_x, n_y)
        Filter gains ``L_t`` (ERRATA (7)).
    log_likelihood_terms : ndarray, shape (T,)
        ``log N(xi_t; 0, Omega_t)``.
    """

    xp: np.ndarray
    Pp: np.ndarray
    xf: np.ndarray
    Pf: np.ndarray
    xi: np.ndarray
    Omega: np.ndarray
    K: np.ndarray
    L: np.ndarray
    log_likelihood_terms: np.ndarray


#: The shortest block of :func:`block_length` (when ``T`` allows): blocks of
#: one or two samples leave the general combinations of step 2 working on
#: single-sample elements, whose ``A`` and ``J`` are of the size of ``Abar``
#: and ``Abar^T C^T R^-1 C Abar``; the scan's error then grows like
#: ``eps amp^4`` instead of ``eps amp^2`` (module notes, "Accuracy").
MIN_BLOCK = 8


def block_length(T: int, nx: int) -> int:
    """Samples per block of the blocked scan (module notes).

    Steps 1 and 3 cost about ``2 ell`` rounds of ~25 numpy calls; step 2 about
    ``T / ell`` general combinations (a batched LAPACK solve each, whose cost
    grows like ``n_x^2`` to ``n_x^3`` for small ``n_x``) and ``2 log2(T / ell)``
    rounds of calls. Balancing the two gives ``ell ~ sqrt(T * w(n_x))``; the
    constants were measured with ``benchmarks/bench_kalman.py``. Never
    shorter than :data:`MIN_BLOCK` (accuracy; it costs at most ~0.4 ms at
    ``T = 64``, measured with the same benchmark).

    Parameters
    ----------
    T : int
        Number of samples.
    nx : int
        State dimension ``n_x``.

    Returns
    -------
    ell : int
        Samples per block, ``1 <= ell <= max(1, T)``.
    """
    w = 0.02 + 0.001 * nx * nx  # relative cost of a general combination
    return max(1, min(T, max(MIN_BLOCK, round(math.sqrt(T * w)))))


# ---------------------------------------------------------------------------
# elements and the operator
# ---------------------------------------------------------------------------
class _General(NamedTuple):
    """Scan elements (module notes), stacked."""

    A: np.ndarray  # (N, n, n)
    b: np.ndarray  # (N, n)
    C: np.ndarray  # (N, n, n)
    J: np.ndarray  # (N, n, n)
    eta: np.ndarray  # (N, n)
    last: np.ndarray  # (N,) int: the last sample each element covers


def _fold(
    acc: _General | None,
    Ft: np.ndarray,
    Qe: np.ndarray,
    mvec: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    yd: np.ndarray,
    last: np.ndarray,
) -> _General:
    """``acc ⊗ element`` for the next sample of every block, as one step of a
    Kalman filter whose mean is an affine function of the block's initial
    state (module notes, step 1); ``acc = None`` is the identity element.
    ``Ft = F^T``; ``last`` is the sample absorbed (error messages).

    Products are arranged so that no right operand is a transposed view
    (numpy's batched ``X @ Y^T`` is twice as slow as ``X^T @ Y``)."""
    n = Ft.shape[-1]
    F = mT(Ft)
    if acc is None:
        Ap, bp, Cp = F, mvec, Qe
        J = np.zeros(Ft.shape)
        eta = np.zeros(mvec.shape)
    else:
        Ap = F @ acc.A
        bp = _mv(F, acc.b) + mvec
        Cp = F @ (acc.C @ Ft) + Qe
        J, eta = acc.J, acc.eta
    HC = H @ Cp
    S = sym(HC @ mT(H) + R)
    try:
        Ls = cholesky(S)
    except FactorError as exc:
        raise NumericalError(
            "the scan's conditional innovation covariance H C~ H^T + H R H^T is not positive "
            f"definite at t={int(last[exc.index])} (non-finite values?)"
        ) from None
    X = lsolve(Ls, np.concatenate((H @ Ap, (yd - _mv(H, bp))[..., None], HC), axis=-1))
    V = X[..., :n]  # chol^-1 H A~
    v = X[..., n]  # chol^-1 (y' - H b~)
    GT = X[..., n + 1 :]  # chol^-1 H C~
    Vt = mT(V)
    A2 = Ap - mT(GT) @ V  # (I - K H) A~
    b2 = bp + _mv(mT(GT), v)  # b~ + K (y' - H b~)
    C2 = Cp - mT(GT) @ GT  # C~ - K S K^T
    return _General(A2, b2, sym(C2), J + Vt @ V, eta + _mv(Vt, v), last)


def _combine(i: _General, j: _General) -> _General:
    """The associative operator ``i ⊗ j`` (module notes), batched."""
    n = i.A.shape[-1]
    M = i.C @ j.J
    M += np.eye(n)
    rhs = np.concatenate((i.A, (i.b + _mv(i.C, j.eta))[..., None], i.C), axis=-1)
    try:
        X = np.linalg.solve(M, rhs)
    except np.linalg.LinAlgError:
        k = next((k for k in range(M.shape[0]) if not _solvable(M[k])), 0)
        raise NumericalError(
            "the scan's combination matrix I + C_i J_j is singular when joining samples up to "
            f"t={int(i.last[k])} with samples up to t={int(j.last[k])} (non-finite or overflowing values)"
        ) from None
    WA = X[..., :n]
    Wb = X[..., n]
    WC = X[..., n + 1 :]
    Aj = j.A
    WAt = mT(WA)
    return _General(
        A=Aj @ WA,
        b=_mv(Aj, Wb) + j.b,
        C=sym(Aj @ WC @ mT(Aj) + j.C),
        J=sym(WAt @ j.J @ i.A + i.J),
        eta=_mv(WAt, j.eta - _mv(j.J, i.b)) + i.eta,
        last=j.last,
    )


def _solvable(M: np.ndarray) -> bool:
    try:
        np.linalg.solve(M, np.ones(M.shape[0]))
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(np.isfinite(M)))


def _take(g: _General, s: slice) -> _General:
    return _General(*(a[s] for a in g))


def _combine_prefix(b: np.ndarray, C: np.ndarray, j: _General) -> tuple[np.ndarray, np.ndarray]:
    """``i ⊗ j`` when ``i`` is a prefix (``A_i = 0``, ``J_i = 0``,
    ``eta_i = 0``): only ``b`` and ``C`` (the filtered moments) are needed,
    from one solve with ``n_x + 1`` right-hand sides."""
    n = C.shape[-1]
    M = C @ j.J
    M += np.eye(n)
    try:
        X = np.linalg.solve(M, np.concatenate(((b + _mv(C, j.eta))[..., None], C), axis=-1))
    except np.linalg.LinAlgError:
        k = next((k for k in range(M.shape[0]) if not _solvable(M[k])), 0)
        raise NumericalError(
            "the scan's combination matrix I + C_i J_j is singular when joining the samples up to "
            f"t={int(j.last[k])} to their prefix (non-finite or overflowing values)"
        ) from None
    Aj = j.A
    return _mv(Aj, X[..., 0]) + j.b, sym(Aj @ X[..., 1:] @ mT(Aj) + j.C)


def _prefix_scan(el: _General) -> tuple[np.ndarray, np.ndarray]:
    """``b`` and ``C`` of the inclusive prefixes ``el[0] ⊗ ... ⊗ el[k]`` (the
    filtered moments at the end of element ``k``; ``el[0]`` must be a prefix
    itself) by the work-efficient recursive scan: ``log2 N`` levels of
    batched :func:`_combine` going up, ``log2 N`` of the cheaper
    :func:`_combine_prefix` coming down."""
    N = el.A.shape[0]
    if N < 2:
        return el.b, el.C
    pairs = _combine(_take(el, slice(0, N - 1, 2)), _take(el, slice(1, N, 2)))
    ob, oC = _prefix_scan(pairs)  # prefixes ending at 1, 3, 5, ...
    rest = _take(el, slice(2, N, 2))
    r = rest.A.shape[0]
    eb, eC = _combine_prefix(ob[:r], oC[:r], rest)  # ending at 2, 4, ...
    b = np.empty(el.b.shape)
    C = np.empty(el.C.shape)
    b[0], C[0] = el.b[0], el.C[0]
    b[1::2], C[1::2] = ob, oC
    b[2::2], C[2::2] = eb, eC
    return b, C


# ---------------------------------------------------------------------------
# the filter
# ---------------------------------------------------------------------------
def scan_filter(
    dec: Decorrelation,
    C: np.ndarray,
    HRH: np.ndarray,
    x0: np.ndarray,
    P0: np.ndarray,
    *,
    block: int | None = None,
) -> ScanMoments:
    """The exact filter by the blocked parallel scan (module notes).

    Parameters
    ----------
    dec : Decorrelation
        From :func:`decorrelate_stack`.
    C : ndarray, shape (T, n_y, n_x)
        ``C(p_t)`` along the trajectory.
    HRH : ndarray, shape (T, n_y, n_y)
        ``H R H^T`` (positive definite: :func:`decorrelate_stack` succeeded).
    x0, P0 : ndarray
        ``x^_{0|-1}``, ``P_{0|-1}`` (``P0`` positive semidefinite; may be singular).
    block : int, optional
        Samples per block (default :func:`block_length`); 1 is the plain
        scan.

    Returns
    -------
    ScanMoments
        The predicted and filtered moments, innovations, ``Omega_t``, the
        gains and the log-likelihood terms.

    Raises
    ------
    NumericalError
        A factorisation failed or values stopped being finite; the message
        names the sample.

    Examples
    --------
    >>> from lpvest import load_system
    >>> from lpvest.estimators.kalman import KalmanModel, kalman_filter
    >>> model = load_system("cox-toth-truncation").model()
    >>> p = np.sin(0.25 * np.arange(100))[:, None]
    >>> u = np.ones((100, 1))
    >>> y = model.simulate(p, u, rng=0).y
    >>> mats = KalmanModel(model).matrices_batch(p)
    >>> out = scan_filter(decorrelate_stack(*mats, u, y), mats.C, mats.HRH, model.x0, model.P0, block=8)
    >>> seq = kalman_filter(model, p, u, y, method="sequential")
    >>> bool(np.max(np.abs(out.Pp - seq.predicted_covariances)) < 1e-14)
    True
    """
    T, m, n = C.shape
    ell = block_length(T, n) if block is None else max(1, min(int(block), T))
    nb = -(-T // ell)  # number of blocks; the last may be short
    AbarT, GQbarG, Jd, c, yd = dec
    # Block k holds samples k ell .. k ell + ell - 1, so position j of every
    # block is the strided view a[j::ell] (the short last block drops out of
    # it by itself).

    # step 1: block elements (blocks 0 .. nb-2; the last block's is never needed)
    full = (nb - 1) * ell
    starts_x = np.empty((nb, n))
    starts_P = np.empty((nb, n, n))
    starts_x[0] = x0
    starts_P[0] = P0
    if nb > 1:
        # sample k ell (j = 0) enters from x_{k ell - 1}; block 0's from the prior (element 0)
        first = slice(ell - 1, full - 1, ell)
        acc = _fold(
            None,
            np.concatenate((np.zeros((1, n, n)), AbarT[first])),
            np.concatenate((P0[None], GQbarG[first])),
            np.concatenate((x0[None], c[first])),
            C[0:full:ell], HRH[0:full:ell], yd[0:full:ell],
            np.arange(0, full, ell),
        )
        for j in range(1, ell):
            prev = slice(j - 1, full, ell)
            cur = slice(j, full, ell)
            acc = _fold(acc, AbarT[prev], GQbarG[prev], c[prev], C[cur], HRH[cur], yd[cur], acc.last + 1)
        acc = acc._replace(J=sym(acc.J))  # J + V^T V: symmetric up to rounding
        # step 2: scan across blocks; prefix k = filtered moments at the end of block k
        pb, pC = _prefix_scan(acc)
        s = np.arange(1, nb) * ell  # block starts
        AT = AbarT[s - 1]
        starts_x[1:] = _mv(mT(AT), pb) + c[s - 1]
        starts_P[1:] = sym(mT(AT) @ (pC @ AT) + GQbarG[s - 1])

    # step 3: the filter within every block, all blocks at once; results are
    # written straight into the outputs (strided views, no copies)
    xp = np.empty((T + 1, n))
    Pp = np.empty((T + 1, n, n))
    xf = np.empty((T, n))
    Pf = np.empty((T, n, n))
    xi_ = np.empty((T, m))
    Om_ = np.empty((T, m, m))
    KT_ = np.empty((T, m, n))
    LT_ = np.empty((T, m, n))
    xp[0:T:ell] = starts_x
    Pp[0:T:ell] = starts_P
    last_len = T - (nb - 1) * ell
    eye = np.eye(n)
    for j in range(ell):
        sl = slice(j, T, ell)
        Cj, Rj, AjT = C[sl], HRH[sl], AbarT[sl]
        x, P = xp[sl], Pp[sl]
        CP = Cj @ P
        Om = CP @ mT(Cj)
        Om += Rj
        if m > 1:
            Om = sym(Om)
        Om_[sl] = Om
        try:
            if m == 1:  # a positive finite scalar; no factor needed
                if not (np.all(Om > 0.0) and np.all(np.isfinite(Om))):
                    cholesky(Om)  # raises, naming the first
            else:
                Lo = cholesky(Om)
        except FactorError as exc:
            raise NumericalError(
                f"the innovation covariance Omega_t is not positive definite at t={exc.index * ell + j}"
            ) from None
        xi = yd[sl] - _mv(Cj, x)
        xi_[sl] = xi
        if m == 1:
            LT = CP / Om
        else:
            LT = usolve(Lo, lsolve(Lo, CP))  # Omega^-1 C P = L^T
        LT_[sl] = LT
        KT_[sl] = LT @ AjT  # K^T = (Abar L + J)^T; J added below
        x_f = x + _mv(mT(LT), xi)
        xf[sl] = x_f
        ILt = mT(Cj) @ LT
        np.subtract(eye, ILt, out=ILt)  # (I - L C)^T
        P_f = mT(ILt) @ (P @ ILt)  # Joseph form
        P_f += mT(LT) @ (Rj @ LT)
        _sym_into(P_f, Pf[sl])
        # prediction to sample j + 1 of every block; for j = ell - 1 that is
        # the next block's start (known from step 2) except after the last block
        if j < ell - 1:
            nxt = slice(j + 1, T + 1, ell)
        elif last_len == ell:
            nxt = slice(T, T + 1)
            AjT, x_f, sl = AjT[-1:], x_f[-1:], slice(T - 1, T)
        else:
            break
        xp[nxt] = _mv(mT(AjT), x_f) + c[sl]
        Pn = mT(AjT) @ (Pf[sl] @ AjT)
        Pn += GQbarG[sl]
        _sym_into(Pn, Pp[nxt])
    KT_ += mT(Jd)
    if not np.all(np.isfinite(Pp[T])):  # every other P_{t|t-1} went through a factorisation
        raise NumericalError(f"the predicted covariance P_{{t|t-1}} is not finite at t={T}")
    # log N(xi_t; 0, Omega_t) for all t at once (each Omega_t was factored above)
    try:
        Lo = cholesky(Om_)
    except FactorError as exc:  # pragma: no cover - the same factorisations succeeded in the loop
        raise NumericalError(f"the innovation covariance Omega_t is not positive definite at t={exc.index}") from None
    z = lsolve(Lo, xi_[..., None])[..., 0]
    logdet = 2.0 * np.sum(np.log(np.diagonal(Lo, axis1=-2, axis2=-1)), axis=-1)
    ll = -0.5 * (m * math.log(2.0 * math.pi) + logdet + np.sum(z * z, axis=-1))
    out = ScanMoments(
        xp=xp, Pp=Pp, xf=xf, Pf=Pf, xi=xi_, Omega=Om_, K=mT(KT_), L=mT(LT_), log_likelihood_terms=ll
    )
    return out
