"""Truncated-memory LPV Kalman filter, Cox & Tóth Theorem 1 (with ERRATA (6a)).

The exact gain ``K_t`` (4c) depends on the whole scheduling past through
``P_{t|t-1}``. Its truncated-memory approximation ``K^(tau)_t`` restarts the
covariance recursion ``tau`` steps back, at ``s = t - tau``, from

    (6a)  P^_{s|s-1} = Abar_{s-1} P^_0 Abar_{s-1}^T + G(p_{s-1}) Qbar G(p_{s-1})^T

(ERRATA.md's correction), runs (4c)-(4e) for ``s, ..., t - 1`` and takes
(4c) with the result. So ``K^(tau)_t`` depends on ``p_{t-tau-1}, ..., p_t``
only. ``P^_0`` replaces the *posterior* ``P_{s-1|s-1}`` in ERRATA's (9),
``P_{s|s-1} = Abar P_{s-1|s-1} Abar^T + G Qbar G^T``.

Decorrelation, general form
---------------------------
(5a)-(5e) write ``G w_t`` as its minimum-variance estimate from the
measurement noise plus an uncorrelated remainder. The paper's ``H^-1``
presumes a square invertible ``H``; :func:`decorrelate` (written once, in
``kalman/_decorrelation.py``, and shared with the parallel scan) uses the
general form

    J_t = G S H^T (H R H^T)^-1,   Abar_t = A - J_t C,   (5c)
    G Qbar G^T := G (Q - S H^T (H R H^T)^-1 H S^T) G^T = G Q G^T - J_t H S^T G^T,   (5e)

needing only ``H R H^T`` invertible (``H`` of full row rank; (5g) needs it
anyway). For square invertible ``H`` this is exactly ``Qbar = Q - S R^-1 S^T``
and ``Abar = A - G S R^-1 H^-1 C``. When ``H R H^T`` is singular we refuse
(:class:`~lpvest.core.NotPositiveDefiniteError`) rather than use a
pseudo-inverse.

Before the restart point exists
-------------------------------
For ``t <= tau`` the restart point ``t - tau - 1`` lies before the first
sample, where the true initial covariance ``P0`` is known: the recursion then
starts from ``P_{0|-1} = P0`` at ``t = 0`` and ``K^(tau)_t = K_t`` exactly.
From ``t = tau + 1`` on, (6a) is used.

Start covariance ``P^_0``
-------------------------
- ``"theorem"``: ``fraction * alpha_2 / (alpha_2 beta_2 + 1) I``, inside the
  bound (6b), with ``alpha_2`` (lower bound of ``G Qbar G^T``) and ``beta_2``
  (upper bound of ``C^T (H R H^T)^-1 C``) taken over a grid of the
  scheduling box (:func:`assumption_bounds`). Then ``P^_0 <= P_{s-1|s-1}``
  (bound (8)), and Lemma 2's ordering ``P^(tau) <= P`` holds.
- ``"steady-state"``: the posterior steady-state covariance of the model
  frozen at ``start_p`` (:func:`steady_state`, scipy's DARE with the cross
  term), so that (6a) at ``p = start_p`` gives the steady-state prior.
- a matrix (n_x, n_x), positive semidefinite.

Runtime code (the filter) imports only numpy; :func:`steady_state` imports
scipy inside.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from ..core._errors import DimensionError, NonFiniteError, NotPositiveDefiniteError, NumericalError, abbreviate
from ..core._linalg import mT
from ..core._protocol import Component, Port
from ..core._validation import as_matrix, as_signal, as_vector, check_positive_definite
from ..systems._affine import AffineLPV, NoiseCovariance
from .kalman._decorrelation import decorrelate
from .kalman._model import KalmanMatrices, KalmanModel, StepMatrices
from .kalman._recursion import KalmanState, KalmanStep, covariance_step, initial_moments, kalman_step
from .kalman._smallmat import cholesky, lsolve
from .kalman._streaming import InputReader, input_ports

__all__ = [
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


class AssumptionBounds(NamedTuple):
    """The constants of (5f)-(5h) over a set of scheduling values, with
    ERRATA.md's reading: ``alpha_2, beta_1, delta_2`` lower bounds,
    ``alpha_1, beta_2, delta_1`` upper bounds.

    Parameters
    ----------
    alpha1 : float
        Max eigenvalue of ``G Qbar G^T``.
    alpha2 : float
        Min eigenvalue of ``G Qbar G^T``.
    beta1 : float
        Min eigenvalue of ``C^T (H R H^T)^-1 C``.
    beta2 : float
        Max eigenvalue of ``C^T (H R H^T)^-1 C``.
    delta1 : float
        Max eigenvalue of ``Abar^T Abar``.
    delta2 : float
        Min eigenvalue of ``Abar^T Abar``.
    points : int
        Number of scheduling values examined.
    """

    alpha1: float
    alpha2: float
    beta1: float
    beta2: float
    delta1: float
    delta2: float
    points: int

    @property
    def hold(self) -> bool:
        """True if every lower bound is positive (the assumptions of Theorem 1)."""
        return self.alpha2 > 0 and self.beta1 > 0 and self.delta2 > 0

    @property
    def posterior_lower_bound(self) -> float:
        """``alpha_2 / (alpha_2 beta_2 + 1)``: bound (8) on ``P_{t|t}`` (t >= 1)."""
        return self.alpha2 / (self.alpha2 * self.beta2 + 1.0)


def _grid(km: KalmanModel, grid: int) -> np.ndarray:
    space = km.model.space
    axes = [np.linspace(lo, hi, grid) for lo, hi in zip(space.lower, space.upper, strict=True)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.reshape(-1) for g in mesh], axis=1)


def assumption_bounds(
    model: AffineLPV | KalmanModel, p: object | None = None, *, grid: int = 21
) -> AssumptionBounds:
    """The constants of (5f)-(5h) over the scheduling values ``p`` (N, n_p),
    or over a ``grid``-point-per-axis grid of the box (corners included).

    A grid can miss an extreme between its points; ``p`` = the trajectory
    gives the theorem's constants for that trajectory exactly.

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (N, n_p), optional
        Scheduling values to examine (range-checked); default: the grid.
    grid : int, default 21
        Points per scheduling axis of the grid (``grid ** n_p`` values), used
        when ``p`` is None.

    Returns
    -------
    AssumptionBounds
        The extreme eigenvalues over the values examined.

    Raises
    ------
    SchedulingRangeError
        A value of ``p`` lies outside the scheduling box.
    NotPositiveDefiniteError
        ``H R H^T`` is singular at some value (``H`` not of full row rank).

    Examples
    --------
    >>> from lpvest import load_system
    >>> b = assumption_bounds(load_system("cox-toth-truncation").model())
    >>> b.hold
    True
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    pts = _grid(km, grid) if p is None else as_signal(p, "p", km.n_p)
    m = km.matrices_batch(pts)
    d = decorrelate(m)
    a = np.linalg.eigvalsh(d.GQbarG)
    L = cholesky(m.HRH, lapack=True)  # positive definite: decorrelate has factored it
    LiC = lsolve(L, m.C, lapack=True)  # C^T (HRH)^-1 C = (L^-1 C)^T (L^-1 C)
    b = np.linalg.eigvalsh(mT(LiC) @ LiC)
    dl = np.linalg.eigvalsh(mT(d.Abar) @ d.Abar)
    return AssumptionBounds(
        alpha1=float(a[:, -1].max()),
        alpha2=float(a[:, 0].min()),
        beta1=float(b[:, 0].min()),
        beta2=float(b[:, -1].max()),
        delta1=float(dl[:, -1].max()),
        delta2=float(dl[:, 0].min()),
        points=int(pts.shape[0]),
    )


def theorem_start_covariance(
    model: AffineLPV | KalmanModel, p: object | None = None, *, fraction: float = 0.5, grid: int = 21
) -> np.ndarray:
    """The theorem's start ``P^_0 = fraction * alpha_2 / (alpha_2 beta_2 + 1) I``,
    strictly inside (6b) for ``0 < fraction < 1``.

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (N, n_p), optional
        Scheduling values for the constants ``alpha_2``, ``beta_2``
        (:func:`assumption_bounds`); default: a grid of the box.
    fraction : float, default 0.5
        Fraction of the bound (6b), in ``(0, 1)``.
    grid : int, default 21
        Grid points per scheduling axis, when ``p`` is None.

    Returns
    -------
    P_start : ndarray, shape (n_x, n_x)
        ``P^_0``, a positive multiple of the identity.

    Raises
    ------
    DimensionError
        ``fraction`` is not in ``(0, 1)``.
    NotPositiveDefiniteError
        ``G Qbar G^T`` is singular somewhere (``alpha_2 <= 0``, (5f) fails):
        the bound (6b) admits no positive definite ``P^_0``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> P0 = theorem_start_covariance(load_system("cox-toth-truncation").model())
    >>> bool(np.allclose(P0, P0[0, 0] * np.eye(2)) and P0[0, 0] > 0)
    True
    """
    if not 0.0 < fraction < 1.0:
        raise DimensionError(f"start_fraction must lie in (0, 1); found {fraction}")
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    b = assumption_bounds(km, p, grid=grid)
    if not b.alpha2 > 0:
        raise NotPositiveDefiniteError(
            f"G(p) Qbar G(p)^T is not positive definite on the scheduling range (smallest eigenvalue "
            f"{b.alpha2:.3g}): assumption (5f) fails and (6b) admits no start covariance; "
            "use start='steady-state' or give a matrix"
        )
    return fraction * b.posterior_lower_bound * np.eye(km.nx)


class SteadyState(NamedTuple):
    """The stationary Kalman filter of the model frozen at one ``p``.

    Parameters
    ----------
    P_pred : ndarray, shape (n_x, n_x)
        Prior ``P_inf`` (the DARE solution).
    P_filt : ndarray, shape (n_x, n_x)
        Posterior ``P_inf - L Omega L^T`` (Joseph form).
    K : ndarray, shape (n_x, n_y)
        Predictor gain (4c).
    L : ndarray, shape (n_x, n_y)
        Filter gain.
    Omega : ndarray, shape (n_y, n_y)
        Innovation covariance (4e) at ``P_inf``.
    """

    P_pred: np.ndarray
    P_filt: np.ndarray
    K: np.ndarray
    L: np.ndarray
    Omega: np.ndarray


def steady_state(model: AffineLPV | KalmanModel, p: object) -> SteadyState:
    """Steady state of (4c)-(4e) for the model frozen at ``p`` (scipy's
    ``solve_discrete_are`` with the cross term ``s = G S H^T``).

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (n_p,)
        The frozen scheduling value (range-checked).

    Returns
    -------
    SteadyState
        ``P_inf``, the posterior covariance, the gains and ``Omega``.

    Raises
    ------
    NumericalError
        The Riccati equation has no stabilising solution at ``p``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> ss = steady_state(load_system("cox-toth-truncation").model(), [0.0])
    >>> ss.K.shape
    (2, 2)
    """
    from scipy.linalg import solve_discrete_are

    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    pv = as_vector(p, "p", km.n_p)
    m = km.matrices(pv)
    try:
        P = solve_discrete_are(m.A.T, m.C.T, m.GQG, m.HRH, s=m.GSH)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise NumericalError(f"no stabilising steady-state Riccati solution at p = {pv.tolist()}: {exc}") from exc
    if not np.all(np.isfinite(P)):
        raise NumericalError(f"no stabilising steady-state Riccati solution at p = {pv.tolist()}")
    P = 0.5 * (P + P.T)
    cs = covariance_step(P, km.step_matrices(pv))
    n = km.nx
    return SteadyState(P, cs.joint[n:, n:], cs.gains[:n], cs.gains[n:], cs.Omega)


def start_covariance(
    model: AffineLPV | KalmanModel,
    start: str | object = "theorem",
    *,
    start_p: object | None = None,
    start_fraction: float = 0.5,
    start_grid: int = 21,
) -> np.ndarray:
    """``P^_0`` for (6a): ``"theorem"``, ``"steady-state"`` (at ``start_p``)
    or a positive semidefinite matrix (module notes).

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    start : {"theorem", "steady-state"} or array_like, shape (n_x, n_x), default "theorem"
        How ``P^_0`` is chosen: :func:`theorem_start_covariance` on a grid,
        the posterior covariance of :func:`steady_state` at ``start_p``, or
        this matrix (positive semidefinite).
    start_p : array_like, shape (n_p,), optional
        Frozen scheduling value; required for ``start="steady-state"``.
    start_fraction : float, default 0.5
        ``fraction`` of :func:`theorem_start_covariance`.
    start_grid : int, default 21
        ``grid`` of :func:`theorem_start_covariance`.

    Returns
    -------
    P_start : ndarray, shape (n_x, n_x)
        ``P^_0``.

    Raises
    ------
    DimensionError
        ``start`` is an unknown name, ``"steady-state"`` without ``start_p``,
        or a matrix of the wrong shape.
    NotPositiveDefiniteError
        The matrix is not positive semidefinite, or (``"theorem"``) (5f) fails.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> start_covariance(model, "steady-state", start_p=[0.0]).shape
    (2, 2)
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    if isinstance(start, str):
        if start == "theorem":
            return theorem_start_covariance(km, fraction=start_fraction, grid=start_grid)
        if start == "steady-state":
            if start_p is None:
                raise DimensionError("start='steady-state' needs start_p, the frozen scheduling value")
            return steady_state(km, start_p).P_filt
        raise DimensionError(f"start must be 'theorem', 'steady-state' or a matrix; found {abbreviate(start, 30)}")
    n = km.nx
    return check_positive_definite(as_matrix(start, "start covariance", (n, n)), "start covariance", semidefinite=True)


def restart_covariance(m: KalmanMatrices, P_start: np.ndarray, *, where: str = "") -> np.ndarray:
    """(6a) with ERRATA: ``Abar P^_0 Abar^T + G Qbar G^T`` at ``p_{s-1}``
    (``m`` may be a stack).

    Parameters
    ----------
    m : KalmanMatrices
        The matrices at ``p_{s-1}`` (or stacked along time).
    P_start : ndarray, shape (n_x, n_x)
        ``P^_0``.
    where : str, default ""
        Appended to the error message of :func:`decorrelate`.

    Returns
    -------
    ndarray, shape (n_x, n_x) or (T, n_x, n_x)
        ``P^_{s|s-1}``, symmetrised.

    Raises
    ------
    NotPositiveDefiniteError
        ``H R H^T`` is singular.

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> restart_covariance(km.matrices([0.2]), np.zeros((2, 2))).shape
    (2, 2)
    """
    d = decorrelate(m, where=where)
    P = d.Abar @ P_start @ mT(d.Abar) + d.GQbarG
    return 0.5 * (P + mT(P))


def truncated_prior(
    window: Sequence[StepMatrices],
    P_start: np.ndarray,
    *,
    P0: np.ndarray | None = None,
    t: int | None = None,
) -> np.ndarray:
    """``P^(tau)_{t|t-1}`` from the matrices of the samples before ``t``; O(len(window)).

    Parameters
    ----------
    window : sequence of StepMatrices, length k
        Without ``P0``: samples ``t - tau - 1, ..., t - 1`` (``k = tau + 1``);
        the recursion starts from (6a) at the first of them and runs (4c)-(4e)
        over the other ``tau``. With ``P0``: samples ``0, ..., t - 1``
        (``t = k <= tau``); the recursion starts from ``P_{0|-1} = P0`` (exact).
    P_start : ndarray, shape (n_x, n_x)
        ``P^_0`` of (6a).
    P0 : ndarray, shape (n_x, n_x), optional
        ``P_{0|-1}``, the true initial covariance; given for ``t <= tau``
        (the recursion is then exact).
    t : int, optional
        Time of the prior (named in errors).

    Returns
    -------
    ndarray, shape (n_x, n_x)
        ``P^(tau)_{t|t-1}`` (with ``P0``: the exact ``P_{t|t-1}``).

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> window = [km.step_matrices([v]) for v in (0.1, 0.2, 0.3)]  # p_{t-3}, p_{t-2}, p_{t-1}
    >>> truncated_prior(window, np.zeros((2, 2)), t=10).shape  # P^(2)_{10|9}
    (2, 2)
    """
    k = len(window)
    if P0 is not None:
        P, first = P0, 0
    else:
        if k == 0:
            raise DimensionError("the truncated recursion needs at least the sample before t")
        where = "" if t is None else f" at t={t - k}"
        P = restart_covariance(window[0].readable(), P_start, where=where)
        first = 1
    n = window[0].nx if k else P.shape[0]
    for i in range(first, k):
        P = covariance_step(P, window[i], t=None if t is None else t - k + i).joint[:n, :n]
    return P


class TruncatedKalmanFilter(Component):
    """The Kalman filter with the truncated-memory gain ``K^(tau)_t``
    (Theorem 1, (6a) as corrected in ERRATA.md), streaming.

    Per sample it re-runs the covariance recursion over a rolling window of
    the last ``tau + 1`` samples' matrices: cost O(tau), no re-running of
    history. For ``t <= tau`` the gain is the exact one (module notes).

    Inputs: ``p`` (n_p,), ``u`` (n_u,) only if n_u > 0, ``y`` (n_y,).

    Outputs: ``xhat`` (n_x,) ``x^_{t|t} = x^_{t|t-1} + L^(tau)_t xi_t``;
    ``P`` (n_x, n_x) the truncated recursion's ``P^(tau)_{t|t}`` (the filter's
    own covariance, not the error covariance of this suboptimal filter);
    ``xpred`` (n_x,) ``x^_{t+1|t} = A x^ + B u + K^(tau)_t xi_t``; ``yhat``
    (n_y,); ``innovation`` (n_y,); ``K`` (n_x, n_y) ``K^(tau)_t``; ``Omega``
    (n_y, n_y) ``Omega^(tau)_t``.

    Parameters
    ----------
    model : AffineLPV
        The affine LPV model (1).
    tau : int
        Memory, ``tau >= 0``.
    start : "theorem", "steady-state" or array_like (n_x, n_x)
        ``P^_0`` (module notes).
    start_p : array_like (n_p,), optional
        Frozen scheduling value for ``start="steady-state"``.
    start_fraction : float
        For ``start="theorem"``: ``P^_0 = fraction * alpha_2/(alpha_2 beta_2 + 1) I``.
    start_grid : int
        Grid points per scheduling axis for the theorem's constants.
    x0, P0, noise
        As for :class:`~lpvest.estimators.kalman.LPVKalmanFilter`.

    Examples
    --------
    >>> from lpvest import load_system
    >>> tf = TruncatedKalmanFilter(load_system("cox-toth-truncation").model(), 5)
    >>> out = tf.step({"p": [0.0], "u": [1.0], "y": [0.1, -0.2]})
    >>> sorted(out)
    ['K', 'Omega', 'P', 'innovation', 'xhat', 'xpred', 'yhat']
    """

    def __init__(
        self,
        model: AffineLPV,
        tau: int,
        *,
        start: str | object = "theorem",
        start_p: object | None = None,
        start_fraction: float = 0.5,
        start_grid: int = 21,
        x0: object | None = None,
        P0: object | None = None,
        noise: NoiseCovariance | object | None = None,
    ) -> None:
        if isinstance(tau, bool) or not isinstance(tau, int | np.integer) or tau < 0:
            raise DimensionError(f"tau must be a non-negative integer; found {abbreviate(tau, 30)}")
        self._tau = int(tau)
        self._km = KalmanModel(model, noise=noise)
        self._x0, self._P0 = initial_moments(self._km, x0, P0)
        self._start = start_covariance(
            self._km, start, start_p=start_p, start_fraction=start_fraction, start_grid=start_grid
        )
        for arr in (self._x0, self._P0, self._start):
            arr.setflags(write=False)
        self._reader = InputReader(self._km)
        n, m = self._km.nx, self._km.ny
        super().__init__(input_ports(self._km), (
            Port("xhat", (n,), "filtered state x_{t|t} with the truncated gain"),
            Port("P", (n, n), "truncated recursion's covariance P^(tau)_{t|t}"),
            Port("xpred", (n,), "predicted state x_{t+1|t} with K^(tau)_t"),
            Port("yhat", (m,), "one-step output prediction"),
            Port("innovation", (m,), "y_t - yhat"),
            Port("K", (n, m), "truncated predictor gain K^(tau)_t"),
            Port("Omega", (m, m), "Omega^(tau)_t from the truncated recursion"),
        ))

    @property
    def tau(self) -> int:
        return self._tau

    @property
    def kalman_model(self) -> KalmanModel:
        """The compiled model the recursion runs on."""
        return self._km

    @property
    def start(self) -> np.ndarray:
        """``P^_0`` of (6a)."""
        return self._start

    @property
    def t(self) -> int:
        return self._t

    @property
    def log_likelihood(self) -> float:
        """Sum of ``log N(y_t; yhat_t, Omega^(tau)_t)`` so far (a quasi-likelihood:
        ``Omega^(tau)`` is the truncated recursion's, not the true one)."""
        return self._loglik

    # -- the component (lpvest.core) ------------------------------------------------
    def _reset(self) -> None:
        self._x = self._x0
        self._t = 0
        self._loglik = 0.0
        self._window: deque[tuple[np.ndarray, StepMatrices]] = deque(maxlen=self._tau + 1)

    def _prior(self) -> np.ndarray:
        win = [w[1] for w in self._window]
        if self._t <= self._tau:
            return truncated_prior(win, self._start, P0=self._P0, t=self._t)
        return truncated_prior(win, self._start, t=self._t)

    def _read(self, inputs: Mapping[str, object]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._reader.read(inputs, self._t)

    def _evaluate(self, sample: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[
            dict[str, np.ndarray], tuple[KalmanStep, StepMatrices, np.ndarray]]:
        p, u, y = sample
        sm = self._km.step_matrices_unchecked(p)
        r = kalman_step(KalmanState(self._x, self._prior(), self._t), sm, u, y)
        out = {
            "xhat": r.x_filt,
            "P": r.P_filt,
            "xpred": r.next.x,
            "yhat": r.y_pred,
            "innovation": r.innovation,
            "K": r.K,
            "Omega": r.Omega,
        }
        return out, (r, sm, p)

    def _commit(self, pending: tuple[KalmanStep, StepMatrices, np.ndarray]) -> None:
        res, sm, p = pending
        x = res.next.x
        x.setflags(write=False)
        self._x = x
        self._window.append((p.copy(), sm))
        self._t += 1
        self._loglik += res.log_likelihood

    # -- the whole step --------------------------------------------------------------
    def _inputs(self, p: object, u: object | None, y: object) -> dict[str, object]:
        return {"p": p, "y": y} if not self._km.nu else {"p": p, "u": u, "y": y}

    def process(self, p: object, u: object | None, y: object) -> KalmanStep:
        """Consume sample ``t`` and advance; the full step (``K^(tau)_t``, ...).

        Parameters
        ----------
        p : array_like, shape (n_p,)
            Scheduling ``p_t`` (range-checked).
        u : array_like, shape (n_u,), or None
            Input ``u_t``; ignored (may be None) when ``n_u = 0``.
        y : array_like, shape (n_y,)
            Measurement ``y_t``.

        Returns
        -------
        KalmanStep
            The step with the truncated gains ``K^(tau)_t``, ``L^(tau)_t``;
            its ``P_filt``, ``Omega`` and ``next.P`` are the truncated
            recursion's.
        """
        _, pending = self._take(self._inputs(p, u, y))
        self._commit(pending)
        return pending[0]

    def peek(self, p: object, u: object | None, y: object) -> KalmanStep:
        """Like :meth:`process` without changing the filter.

        Parameters
        ----------
        p : array_like, shape (n_p,)
            Scheduling ``p_t`` (range-checked).
        u : array_like, shape (n_u,), or None
            Input ``u_t``; ignored (may be None) when ``n_u = 0``.
        y : array_like, shape (n_y,)
            Measurement ``y_t``.

        Returns
        -------
        KalmanStep
            What :meth:`process` would return for this sample.
        """
        return self._evaluate(self._read(self._inputs(p, u, y)))[1][0]

    def get_state(self) -> dict[str, object]:
        """``x``, ``t``, ``log_likelihood`` and the window of the last
        ``window_length <= tau + 1`` scheduling values (``window_p``, padded
        with zeros to ``(tau + 1, n_p)``, oldest first).

        Returns
        -------
        dict
            ``"x"`` (n_x,) ``x^_{t|t-1}`` (a copy), ``"t"`` (int),
            ``"log_likelihood"`` (float), ``"window_p"`` (tau + 1, n_p) and
            ``"window_length"`` (int).
        """
        wp = np.zeros((self._tau + 1, self._km.n_p))
        for i, (p, _) in enumerate(self._window):
            wp[i] = p
        return {
            "x": self._x.copy(),
            "t": int(self._t),
            "log_likelihood": float(self._loglik),
            "window_p": wp,
            "window_length": len(self._window),
        }

    def _set_state(self, state: Mapping[str, Any]) -> None:
        km = self._km
        try:
            x = as_vector(state["x"], "state x", km.nx)
            t = int(state["t"])
            ll = float(state["log_likelihood"])
            k = int(state["window_length"])
            wp = as_matrix(state["window_p"], "state window_p", (self._tau + 1, km.n_p))
        except KeyError as exc:
            raise DimensionError(f"state is missing {exc.args[0]!r}") from None
        if t < 0 or k != min(t, self._tau + 1):
            raise DimensionError(f"state window_length = {k} does not fit t = {t} and tau = {self._tau}")
        if not math.isfinite(ll):
            raise NonFiniteError(f"state log_likelihood is {ll}")
        window: deque[tuple[np.ndarray, StepMatrices]] = deque(maxlen=self._tau + 1)
        for i in range(k):
            window.append((wp[i].copy(), km.step_matrices(wp[i])))
        x.setflags(write=False)
        self._x, self._t, self._loglik, self._window = x, t, ll, window
