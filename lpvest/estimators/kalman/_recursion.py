"""The kernel of the exact filter: one sample's gains and Joseph-form covariances
(:func:`covariance_step`), one step of the filter (:func:`kalman_step`) and the covariance
recursion alone along a trajectory (:func:`riccati_sweep`); notes: :mod:`lpvest.estimators.kalman`."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ...core._errors import NumericalError
from ...core._linalg import mT
from ...core._validation import as_matrix, as_vector, check_positive_definite
from ._model import KalmanModel, StepMatrices
from ._smallmat import SMALL_NY, FactorError, chol_inverse, cholesky, lsolve, usolve

__all__ = [
    "CovarianceStep",
    "KalmanState",
    "KalmanStep",
    "covariance_step",
    "kalman_step",
    "initial_moments",
    "riccati_sweep",
    "small_chol_inverse",
]

_LOG_2PI = math.log(2.0 * math.pi)

# ---------------------------------------------------------------------------
# the kernel
# ---------------------------------------------------------------------------
class CovarianceStep(NamedTuple):
    """What :func:`covariance_step` computes at one sample (or a stack).

    For a stack the arrays and ``logdet`` have a leading axis ``N`` (``whitened`` is None).

    Parameters
    ----------
    Omega : ndarray, shape (n_y, n_y)
        ``Omega_t``, (4e).
    gains : ndarray, shape (2 n_x, n_y)
        ``[K_t; L_t]``, (4c) and ERRATA (7) (or the gains given to
        :func:`covariance_step`).
    joint : ndarray, shape (2 n_x, 2 n_x)
        Symmetric; blocks ``[:n, :n] = P_{t+1|t}``, ``[n:, n:] = P_{t|t}``.
    whitened : ndarray, shape (n_y,), or None
        ``chol(Omega)^-1 rhs`` when ``rhs`` was given, else None.
    logdet : float or ndarray, shape (N,)
        ``log det Omega_t``.
    """

    Omega: np.ndarray
    gains: np.ndarray
    joint: np.ndarray
    whitened: np.ndarray | None
    logdet: float | np.ndarray


def _singular(t: int | None, detail: str) -> NumericalError:
    where = "" if t is None else f" at t={t}"
    return NumericalError(f"the innovation covariance Omega_t is not positive definite{where}: {detail}")


_EYE: dict[int, np.ndarray] = {}


def _eye(k: int) -> np.ndarray:
    e = _EYE.get(k)
    if e is None:
        e = np.eye(k)
        e.setflags(write=False)
        _EYE[k] = e
    return e


def small_chol_inverse(Omega: np.ndarray, t: int | None) -> tuple[np.ndarray, float]:
    """``chol^-1`` and ``log det`` of a small ``Omega_t`` (``n_y <= SMALL_NY``):
    :func:`~lpvest.estimators.kalman._smallmat.chol_inverse` in Python floats,
    its failure named as ``Omega_t``'s.

    Parameters
    ----------
    Omega : ndarray, shape (m, m)
        Symmetric positive definite matrix (only its lower triangle is read).
    t : int or None
        Time index, named in errors (None: none named).

    Returns
    -------
    Ci : ndarray, shape (m, m)
        ``chol(Omega)^-1``, lower triangular.
    logdet : float
        ``log det Omega``.

    Raises
    ------
    NumericalError
        A Cholesky pivot is not positive and finite (``Omega`` not positive
        definite, or non-finite).
    """
    try:
        Ci, logdet = chol_inverse(Omega)
    except FactorError as exc:
        raise _singular(t, f"Cholesky pivot {exc.pivot} is {exc.value:.3g}") from None
    return Ci, float(logdet)


def covariance_step(
    P: np.ndarray,
    sm: StepMatrices,
    *,
    t: int | None = None,
    gains: np.ndarray | None = None,
    rhs: np.ndarray | None = None,
) -> CovarianceStep:
    """Gains and Joseph-form covariances from ``P_{t|t-1}``; pure.

    ``V = E P E^T + W`` (module notes) gives ``Omega_t`` (4e) and the optimal
    gains ``[K_t; L_t] = V_12 Omega_t^-1`` ((4c), ERRATA (7)), by Cholesky
    solves; ``M V M^T`` with ``M = [I, -[K; L]]`` gives ``P_{t+1|t}`` and
    ``P_{t|t}`` in Joseph form ((32) with ERRATA), symmetrised. The Joseph
    forms hold for any gains, so ``gains`` may be given (a suboptimal filter):
    the covariances are then the true error covariances of that filter.

    Parameters
    ----------
    P : ndarray, shape (n_x, n_x) or (N, n_x, n_x)
        ``P_{t|t-1}`` (one, or a stack).
    sm : StepMatrices
        Matrices at ``p_t``, stacked like ``P``.
    t : int, optional
        Time index, named in errors.
    gains : ndarray, shape (2 n_x, n_y) or (N, 2 n_x, n_y), optional
        ``[K; L]`` to use instead of the optimal ones.
    rhs : ndarray, shape (n_y,), optional
        A vector to whiten, ``chol(Omega)^-1 rhs`` (one solve shared with
        the gains); unstacked use only.

    Returns
    -------
    CovarianceStep
        ``Omega_t``, the gains, the joint covariance of ``P_{t+1|t}`` and
        ``P_{t|t}``, the whitened ``rhs`` and ``log det Omega_t``, stacked
        like ``P``.

    Raises
    ------
    NumericalError
        ``Omega_t`` is not positive definite (singular, or non-finite).

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> cs = covariance_step(np.eye(2), km.step_matrices([0.3]))
    >>> cs.gains.shape, cs.joint.shape
    ((4, 2), (4, 4))
    """
    if P.ndim > 2:
        return _covariance_step_stack(P, sm, t, gains)
    n, m = sm.nx, sm.ny
    F = sm.F
    n2 = 2 * n
    E = F[:, :n]
    V = E @ P @ E.T
    V += F[:, n + sm.nu :]
    whitened = None
    if m == 1:
        w = float(V[n2, n2])
        if not 0.0 < w < math.inf:
            raise _singular(t, f"Omega_t = {w:.6g}")
        if gains is None:
            gains = V[:n2, n2:] / w
        if rhs is not None:
            whitened = rhs / math.sqrt(w)
        logdet = math.log(w)
    elif m <= SMALL_NY:
        # tiny Omega: its Cholesky factor and the factor's inverse (forward
        # substitution on I) in Python floats beat two LAPACK calls
        Ci, logdet = small_chol_inverse(V[n2:, n2:], t)
        if gains is None:
            Z = Ci @ V[n2:, :n2]  # chol^-1 V_21
            gains = Z.T @ Ci  # V_12 chol^-T chol^-1 = V_12 Omega^-1
        if rhs is not None:
            whitened = Ci @ rhs
    else:
        Omega = V[n2:, n2:]
        try:
            chol = cholesky(Omega)
        except FactorError as exc:
            if exc.nonfinite:
                raise _singular(t, "it holds non-finite values") from exc
            raise _singular(t, f"smallest eigenvalue {np.linalg.eigvalsh(Omega)[0]:.3g}") from exc
        logdet = 2.0 * float(np.sum(np.log(np.diagonal(chol))))
        if gains is None:
            # one forward substitution: chol^-1 [V_21, I, rhs]; then
            # [K; L] = V_12 chol^-T chol^-1 = (chol^-1 V_21)^T chol^-1
            parts = [V[n2:, :n2], _eye(m)]
            if rhs is not None:
                parts.append(rhs[:, None])
            Z = lsolve(chol, np.concatenate(parts, axis=1))
            gains = Z[:, :n2].T @ Z[:, n2 : n2 + m]
            if rhs is not None:
                whitened = Z[:, -1]
        elif rhs is not None:
            whitened = lsolve(chol, rhs[:, None])[:, 0]
    M = np.concatenate((_eye(n2), -gains), axis=1)
    PP = M @ V @ M.T
    PP = PP + PP.T
    PP *= 0.5
    return CovarianceStep(V[n2:, n2:], gains, PP, whitened, logdet)


def _covariance_step_stack(
    P: np.ndarray, sm: StepMatrices, t: int | None, gains: np.ndarray | None
) -> CovarianceStep:
    n = sm.nx
    n2 = 2 * n
    F = sm.F
    E = F[..., :n]
    V = E @ P @ mT(E) + F[..., n + sm.nu :]
    Omega = V[..., n2:, n2:]
    try:
        chol = cholesky(Omega, lapack=True)  # LAPACK, as this path always has: the same numbers
    except FactorError as exc:
        raise _singular(t, "it holds non-finite values" if exc.nonfinite else f"in stack element {exc.index}") from exc
    if gains is None:
        gains = mT(usolve(chol, lsolve(chol, V[..., n2:, :n2], lapack=True), lapack=True))
    M = np.concatenate((np.broadcast_to(_eye(n2), (*gains.shape[:-2], n2, n2)), -gains), axis=-1)
    PP = M @ V @ mT(M)
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    return CovarianceStep(Omega, gains, 0.5 * (PP + mT(PP)), None, logdet)


# ---------------------------------------------------------------------------
# one sample
# ---------------------------------------------------------------------------
class KalmanState(NamedTuple):
    """The predictor's state before sample ``t``: ``x^_{t|t-1}``, ``P_{t|t-1}``.

    Parameters
    ----------
    x : ndarray, shape (n_x,)
        ``x^_{t|t-1}``.
    P : ndarray, shape (n_x, n_x)
        ``P_{t|t-1}``.
    t : int, default 0
        Index of the next sample.
    """

    x: np.ndarray
    P: np.ndarray
    t: int = 0


class KalmanStep(NamedTuple):
    """Everything the filter computes from sample ``t``.

    Parameters
    ----------
    t : int
        The sample's time index.
    y_pred : ndarray, shape (n_y,)
        ``C x^_{t|t-1} + D u_t``.
    innovation : ndarray, shape (n_y,)
        ``xi_t``, (4b).
    Omega : ndarray, shape (n_y, n_y)
        ``Omega_t``, (4e).
    K : ndarray, shape (n_x, n_y)
        Predictor gain ``K_t``, (4c).
    L : ndarray, shape (n_x, n_y)
        Filter gain ``L_t = P C^T Omega^-1``.
    x_filt : ndarray, shape (n_x,)
        ``x^_{t|t}``.
    P_filt : ndarray, shape (n_x, n_x)
        ``P_{t|t}``.
    next : KalmanState
        ``x^_{t+1|t}``, ``P_{t+1|t}`` ((4a), (4d)), ``t + 1``.
    log_likelihood : float
        ``log N(y_t; y_pred, Omega_t)``.
    """

    t: int
    y_pred: np.ndarray
    innovation: np.ndarray
    Omega: np.ndarray
    K: np.ndarray
    L: np.ndarray
    x_filt: np.ndarray
    P_filt: np.ndarray
    next: KalmanState
    log_likelihood: float


def kalman_step(
    state: KalmanState,
    sm: StepMatrices,
    u: np.ndarray,
    y: np.ndarray,
    *,
    gains: np.ndarray | None = None,
) -> KalmanStep:
    """One sample of (4a)-(4e) plus the filtered estimate; pure.

    Parameters
    ----------
    state : KalmanState
        ``x^_{t|t-1}``, ``P_{t|t-1}``, ``t``.
    sm : StepMatrices
        Matrices at ``p_t`` (:meth:`KalmanModel.step_matrices`).
    u : ndarray, shape (n_u,)
        Input ``u_t`` (empty when ``n_u = 0``).
    y : ndarray, shape (n_y,)
        Measurement ``y_t``.
    gains : ndarray, shape (2 n_x, n_y), optional
        ``[K; L]`` to use instead of the optimal gains from ``state.P``.

    Returns
    -------
    KalmanStep
        The prediction, innovation, gains, filtered estimate, next state and
        the sample's log-likelihood term.

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> s0 = KalmanState(km.model.x0, km.model.P0)
    >>> out = kalman_step(s0, km.step_matrices([0.0]), np.zeros(1), np.array([0.1, -0.2]))
    >>> out.next.t, out.K.shape
    (1, (2, 2))
    """
    n, nu, m = sm.nx, sm.nu, sm.ny
    F = sm.F
    if nu:
        h = F[:, : n + nu] @ np.concatenate((state.x, u))  # [A x + B u; x; C x + D u]
    else:
        h = F[:, :n] @ state.x
    n2 = 2 * n
    y_pred = h[n2:]
    xi = y - y_pred
    cs = covariance_step(state.P, sm, t=state.t, gains=gains, rhs=xi)
    G = cs.gains
    xs = h[:n2] + G @ xi  # [x^_{t+1|t}; x^_{t|t}]
    z = cs.whitened
    assert z is not None
    ll = -0.5 * (m * _LOG_2PI + cs.logdet + float(z @ z))
    PP = cs.joint
    return KalmanStep(
        t=state.t,
        y_pred=y_pred,
        innovation=xi,
        Omega=cs.Omega,
        K=G[:n],
        L=G[n:],
        x_filt=xs[n:],
        P_filt=PP[n:, n:],
        next=KalmanState(xs[:n], PP[:n, :n], state.t + 1),
        log_likelihood=float(ll),
    )


# ---------------------------------------------------------------------------
# whole trajectories
# ---------------------------------------------------------------------------


def initial_moments(km: KalmanModel, x0: object | None, P0: object | None) -> tuple[np.ndarray, np.ndarray]:
    """The initial mean and covariance of ``x_0``, validated (the model's when not given).

    Parameters
    ----------
    km : KalmanModel
        The compiled model (its ``model.x0``, ``model.P0`` are the defaults).
    x0 : array_like, shape (n_x,), or None
        Initial mean ``x^_{0|-1}``; None: the model's ``x0``.
    P0 : array_like, shape (n_x, n_x), or None
        Initial covariance ``P_{0|-1}``, positive semidefinite (may be
        singular); None: the model's ``P0``.

    Returns
    -------
    x : ndarray, shape (n_x,)
        The initial mean (the model's is copied).
    P : ndarray, shape (n_x, n_x)
        The initial covariance (a copy).

    Raises
    ------
    DimensionError, NonFiniteError, NotPositiveDefiniteError
        ``x0`` or ``P0`` has the wrong shape, non-finite values, or ``P0`` is
        not symmetric positive semidefinite.
    """
    n = km.nx
    x = km.model.x0.copy() if x0 is None else as_vector(x0, "x0", n)
    if P0 is None:
        P = km.model.P0.copy()
    else:
        P = check_positive_definite(as_matrix(P0, "P0", (n, n)), "P0", semidefinite=True).copy()
    return x, P


def riccati_sweep(
    km: KalmanModel, sms: StepMatrices, P0: np.ndarray, *, t0: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The covariance recursion alone along stacked matrices (the only part
    of the filter that must run sample by sample): returns ``P_{t|t-1}``
    (T + 1), ``P_{t|t}`` (T), ``Omega_t`` (T), ``[K_t; L_t]`` (T).

    Parameters
    ----------
    km : KalmanModel
        The compiled model (for the dimensions).
    sms : StepMatrices
        The matrices of ``T`` samples, stacked (:meth:`KalmanModel.step_matrices_batch`).
    P0 : ndarray, shape (n_x, n_x)
        ``P_{t0|t0-1}``, the prior covariance of the first sample.
    t0 : int, default 0
        Time index of the first sample (named in errors).

    Returns
    -------
    P_pred : ndarray, shape (T + 1, n_x, n_x)
        ``P_{t|t-1}`` (row 0 is ``P0``).
    P_filt : ndarray, shape (T, n_x, n_x)
        ``P_{t|t}``.
    Omega : ndarray, shape (T, n_y, n_y)
        ``Omega_t``, (4e).
    gains : ndarray, shape (T, 2 n_x, n_y)
        ``[K_t; L_t]``, (4c) and ERRATA (7).

    Raises
    ------
    NumericalError
        ``Omega_t`` is not positive definite at some ``t`` (named).
    """
    T = sms.F.shape[0]
    n, nu, m = km.nx, km.nu, km.ny
    Pp = np.empty((T + 1, n, n))
    Pf = np.empty((T, n, n))
    Om = np.empty((T, m, m))
    Gm = np.empty((T, 2 * n, m))
    P = P0
    Pp[0] = P
    step = covariance_step
    for t, F in enumerate(sms.F):
        cs = step(P, StepMatrices(F, n, nu, m), t=t0 + t)
        PP = cs.joint
        P = PP[:n, :n]
        Pp[t + 1] = P
        Pf[t] = PP[n:, n:]
        Om[t] = cs.Omega
        Gm[t] = cs.gains
    return Pp, Pf, Om, Gm


#: ``kalman_filter(method="auto")`` runs the sequential recursion for fewer
#: samples than this: the scan's fixed cost of a few hundred numpy calls is
#: then not recovered (measured with ``benchmarks/bench_kalman.py``: with
#: blocks of at least :data:`~lpvest.estimators.kalman._scan.MIN_BLOCK`
#: samples, for accuracy, the two break even between 64 and 96 samples for
#: n_x = 2 and 10: 1.5 / 1.7 ms at 64, 2.0 / 1.7 ms at 96).
#: There is no rule on n_x: per sample the scan does fewer flops than the
#: sequential kernel, and it was faster at every n_x measured (2 to 100).
