"""Fading memory of the LPV Kalman recursion: how well the truncated gain
``K^(tau)_t`` (Cox & Tóth Theorem 1, Conjecture 1, with ERRATA (6a)) matches
the exact ``K_t``, and what the approximation costs in prediction error.

- :func:`truncation_errors`: ``||P_{t|t-1} - P^(tau)_{t|t-1}||_2`` and
  ``||K_t - K^(tau)_t||_2`` for every ``t`` and every ``tau`` in a list, for a
  model and a scheduling trajectory. All restart points are run together:
  ``tau_max`` stacked steps of the recursion, not ``T * tau`` single ones.
- :func:`monotonicity`: does the error decrease with ``tau`` (the sup over
  ``t``, and Conjecture 1's strict decrease for every ``t``)?
- :func:`tau_needed`, :func:`decay_rate`.
- :func:`prediction_error_covariance`: the exact covariance of the one-step
  output prediction error of the filter that uses a *given* gain sequence
  (Joseph form (32) holds for any gain), for the exact, truncated and
  frozen-gain filters; :func:`empirical_prediction_error` checks it by Monte
  Carlo; :func:`frozen_gains` gives the gain-scheduled steady-state gains
  ``K_inf(p_t)`` of the models frozen at each ``p_t``.

Norms are spectral (``||.||_2``), as in (6c) and (20b).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..core._errors import ArgumentError, ArgumentTypeError, DimensionError, NumericalError, abbreviate
from ..core._validation import as_rng, as_signal, check_finite
from ..estimators._truncated import restart_covariance, start_covariance
from ..estimators.kalman._model import KalmanModel
from ..estimators.kalman._recursion import covariance_step, initial_moments, riccati_sweep
from ..systems._affine import AffineLPV

__all__ = [
    "TruncationErrors",
    "truncation_errors",
    "Monotonicity",
    "monotonicity",
    "tau_needed",
    "decay_rate",
    "PredictionError",
    "prediction_error_covariance",
    "empirical_prediction_error",
    "frozen_gains",
    "FilterComparison",
    "compare_filters",
]


def _norm2(X: np.ndarray) -> np.ndarray:
    return np.linalg.norm(X, ord=2, axis=(-2, -1))


class TruncationErrors(NamedTuple):
    """Truncation errors along one scheduling trajectory of ``T`` samples.

    For ``t <= tau`` the truncated recursion starts from the true ``P0`` and is
    exact (error 0).

    Parameters
    ----------
    taus : ndarray of int, shape (n_tau,)
        Memories, increasing.
    P_error : ndarray, shape (n_tau, T)
        ``||P_{t|t-1} - P^(tau)_{t|t-1}||_2``.
    K_error : ndarray, shape (n_tau, T)
        ``||K_t - K^(tau)_t||_2``.
    max_P_error : ndarray, shape (n_tau,)
        Max of ``P_error`` over t.
    max_K_error : ndarray, shape (n_tau,)
        Max of ``K_error`` over t.
    min_ordering_eigenvalue : ndarray, shape (n_tau,)
        Min over t of ``lambda_min(P_{t|t-1} - P^(tau)_{t|t-1})`` (Lemma 2: >= 0).
    exact_gains : ndarray, shape (T, n_x, n_y)
        ``K_t``.
    exact_covariances : ndarray, shape (T, n_x, n_x)
        ``P_{t|t-1}``.
    truncated_gains : ndarray, shape (n_tau, T, n_x, n_y)
        ``K^(tau)_t``.
    start : ndarray, shape (n_x, n_x)
        ``P^_0`` of (6a).
    """

    taus: np.ndarray
    P_error: np.ndarray
    K_error: np.ndarray
    max_P_error: np.ndarray
    max_K_error: np.ndarray
    min_ordering_eigenvalue: np.ndarray
    exact_gains: np.ndarray
    exact_covariances: np.ndarray
    truncated_gains: np.ndarray
    start: np.ndarray


def truncation_errors(
    model: AffineLPV | KalmanModel,
    p: object,
    taus: Sequence[int],
    *,
    start: str | object = "theorem",
    start_p: object | None = None,
    start_fraction: float = 0.5,
    P0: object | None = None,
    progress: bool = False,
) -> TruncationErrors:
    """Errors of the truncated recursion against the exact one, every ``t`` and ``tau``.

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (T, n_p)
        Scheduling trajectory.
    taus : sequence of int
        Memories to evaluate (``>= 0``).
    start, start_p, start_fraction
        ``P^_0`` (see :func:`~lpvest.estimators.start_covariance`).
    P0 : array_like, optional
        ``P_{0|-1}`` (default: the model's).
    progress : bool
        Show a tqdm progress bar over ``tau``.

    Returns
    -------
    TruncationErrors
        The errors for every ``t`` and every listed ``tau`` (sorted, repeats removed), the exact and
        truncated gains and ``P^_0``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> p = np.sin(0.25 * np.arange(200))[:, None]
    >>> err = truncation_errors(model, p, [1, 5, 10])
    >>> bool(err.max_K_error[2] < err.max_K_error[0])
    True
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    tau_list = sorted({int(t) for t in taus})
    if not tau_list or tau_list[0] < 0:
        raise DimensionError(f"taus must be non-negative integers; found {list(taus)}")
    n, m = km.nx, km.ny
    _, P_init = initial_moments(km, None, P0)
    sms = km.step_matrices_batch(p)
    Pp, _, _, Gm = riccati_sweep(km, sms, P_init)
    K_exact = Gm[:, :n]
    P_exact = Pp[:T]
    P_start = start_covariance(km, start, start_p=start_p, start_fraction=start_fraction)

    n_tau = len(tau_list)
    P_err = np.zeros((n_tau, T))
    K_err = np.zeros((n_tau, T))
    min_eig = np.full(n_tau, np.inf)
    K_trunc = np.broadcast_to(K_exact, (n_tau, T, n, m)).copy()
    index = {tau: i for i, tau in enumerate(tau_list)}
    tau_max = tau_list[-1]
    if T >= 2:
        # restart at s - 1 = j for every j = 0..T-2 at once: after k steps the
        # stack holds P^(k)_{t|t-1} for t = j + 1 + k.
        P = restart_covariance(sms.window(0, T - 1).readable(), P_start)
        ks = range(min(tau_max, T - 2) + 1)
        if progress:
            from ..core._progress import progress_bar

            ks = progress_bar(ks, desc="truncation depth", unit="tau", show=True, leave=False)
        for k in ks:
            t0 = 1 + k  # times t0..T-1 are covered
            cs = covariance_step(P, sms.window(t0, T))
            if k in index:
                i = index[k]
                dP = P_exact[t0:] - P
                P_err[i, t0:] = _norm2(dP)
                K_err[i, t0:] = _norm2(K_exact[t0:] - cs.gains[:, :n])
                min_eig[i] = float(np.min(np.linalg.eigvalsh(dP)))
                K_trunc[i, t0:] = cs.gains[:, :n]
            P = cs.joint[:-1, :n, :n]
    for tau, i in index.items():  # t <= tau: exact by construction
        if tau >= T - 1:
            min_eig[i] = 0.0
    return TruncationErrors(
        taus=np.array(tau_list),
        P_error=P_err,
        K_error=K_err,
        max_P_error=P_err.max(axis=1),
        max_K_error=K_err.max(axis=1),
        min_ordering_eigenvalue=min_eig,
        exact_gains=K_exact,
        exact_covariances=P_exact,
        truncated_gains=K_trunc,
        start=P_start,
    )


class Monotonicity(NamedTuple):
    """Is the truncation error decreasing in ``tau``?

    Parameters
    ----------
    sup_monotone : bool
        ``max_t`` error never increases from one tau to the next listed one.
    sup_increases : tuple of (int, int)
        ``(tau, tau')`` pairs where it increases.
    pairs : int
        ``(t, tau)`` pairs compared for Conjecture 1 (tau and tau + 1 both
        listed, both errors above ``floor``).
    violations : int
        Pairs with ``error(tau + 1) >= error(tau)`` (Conjecture 1's strict
        decrease fails).
    worst : tuple of (int, int, float) or None
        ``(t, tau, error(tau + 1) / error(tau))`` of the largest ratio among
        violations; None without violations.
    floor : float
        Errors at or below this are round-off and not compared.
    """

    sup_monotone: bool
    sup_increases: tuple[tuple[int, int], ...]
    pairs: int
    violations: int
    worst: tuple[int, int, float] | None
    floor: float


def _check_which(which: object) -> None:
    if which not in ("K", "P"):
        raise DimensionError(f"which must be 'K' or 'P'; found {abbreviate(which, 30)}")


def monotonicity(errors: TruncationErrors, *, which: str = "K", floor: float = 1e-12) -> Monotonicity:
    """Check the decrease of ``||K_t - K^(tau)_t||`` (or of ``P``, ``which="P"``)
    in ``tau``: for the max over ``t``, and pointwise for every ``t`` where
    both ``tau`` and ``tau + 1`` are listed (Conjecture 1, (20b)).

    Errors at or below ``floor`` are round-off; pairs involving them are not
    compared.

    Parameters
    ----------
    errors : TruncationErrors
        From :func:`truncation_errors`.
    which : {"K", "P"}, default "K"
        The gain error ``||K_t - K^(tau)_t||`` or the covariance error
        ``||P_{t|t-1} - P^(tau)_{t|t-1}||``.
    floor : float, default 1e-12
        Errors at or below this are not compared.

    Returns
    -------
    Monotonicity
        The sup-over-``t`` check and Conjecture 1's pointwise count.

    Raises
    ------
    DimensionError
        ``which`` is neither ``"K"`` nor ``"P"``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> err = truncation_errors(model, np.sin(0.25 * np.arange(100))[:, None], range(12))
    >>> m = monotonicity(err)
    >>> m.sup_monotone, m.violations
    (True, 0)
    """
    _check_which(which)
    E = errors.K_error if which == "K" else errors.P_error
    sup = errors.max_K_error if which == "K" else errors.max_P_error
    taus = errors.taus
    incr = tuple(
        (int(taus[i]), int(taus[i + 1]))
        for i in range(len(taus) - 1)
        if sup[i + 1] > sup[i] and sup[i + 1] > floor
    )
    pairs = violations = 0
    worst: tuple[int, int, float] | None = None
    for i in range(len(taus) - 1):
        if taus[i + 1] != taus[i] + 1:
            continue
        a, b = E[i], E[i + 1]
        ok = (a > floor) & (b > floor)
        pairs += int(np.count_nonzero(ok))
        bad = ok & (b >= a)
        violations += int(np.count_nonzero(bad))
        if np.any(bad):
            ratio = np.where(bad, b / np.where(ok, a, 1.0), 0.0)
            t = int(np.argmax(ratio))
            if worst is None or ratio[t] > worst[2]:
                worst = (t, int(taus[i]), float(ratio[t]))
    return Monotonicity(not incr, incr, pairs, violations, worst, floor)


def tau_needed(errors: TruncationErrors, tol: float, *, which: str = "K") -> int | None:
    """Smallest listed ``tau`` from which ``max_t`` error stays below ``tol``
    for every larger listed ``tau`` (``None`` if never).

    Parameters
    ----------
    errors : TruncationErrors
        From :func:`truncation_errors`.
    tol : float
        Tolerance on ``max_t`` error (strict: below ``tol``).
    which : {"K", "P"}, default "K"
        The gain errors (``"K"``) or the covariance errors (``"P"``); anything
        else raises :class:`~lpvest.core.DimensionError`.

    Returns
    -------
    int or None
        The smallest such ``tau``, or None.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> err = truncation_errors(model, np.sin(0.25 * np.arange(200))[:, None], range(30))
    >>> tau_needed(err, 1e-3), tau_needed(err, 1e-30)
    (11, None)
    """
    _check_which(which)
    sup = errors.max_K_error if which == "K" else errors.max_P_error
    below = sup < tol
    for i in range(len(below)):
        if np.all(below[i:]):
            return int(errors.taus[i])
    return None


def decay_rate(errors: TruncationErrors, *, which: str = "K", floor: float = 1e-13) -> float:
    """Geometric rate ``rho`` of ``max_t error ~ c rho^tau`` (least squares on
    the logarithm over the listed ``tau`` with errors above ``floor``).

    Parameters
    ----------
    errors : TruncationErrors
        From :func:`truncation_errors`.
    which : {"K", "P"}, default "K"
        The gain errors (``"K"``) or the covariance errors (``"P"``); anything
        else raises :class:`~lpvest.core.DimensionError`.
    floor : float, default 1e-13
        Errors at or below this (round-off) are left out of the fit.

    Returns
    -------
    rho : float
        ``exp`` of the fitted slope; NaN when fewer than two errors are above
        ``floor``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> err = truncation_errors(model, np.sin(0.25 * np.arange(200))[:, None], range(40))
    >>> round(decay_rate(err), 2)
    0.55
    """
    _check_which(which)
    sup = errors.max_K_error if which == "K" else errors.max_P_error
    ok = sup > floor
    if np.count_nonzero(ok) < 2:
        return float("nan")
    slope = np.polyfit(errors.taus[ok].astype(float), np.log(sup[ok]), 1)[0]
    return float(np.exp(slope))


class PredictionError(NamedTuple):
    """Second moments of the one-step prediction error of a filter with given gains.

    Parameters
    ----------
    output : ndarray, shape (T, n_y, n_y)
        Covariance of ``y_t - yhat_t``.
    state : ndarray, shape (T + 1, n_x, n_x)
        Covariance of ``x_t - x^_{t|t-1}``.
    mean_trace : float
        Mean over ``t >= burn_in`` of ``trace(output[t])`` (NaN if no sample
        is left).
    """

    output: np.ndarray
    state: np.ndarray
    mean_trace: float


def prediction_error_covariance(
    model: AffineLPV | KalmanModel,
    p: object,
    gains: np.ndarray,
    *,
    P0: object | None = None,
    burn_in: int = 0,
) -> PredictionError:
    """Exact error covariances of the predictor ``x^_{t+1} = A x^ + B u + K_t (y_t - C x^ - D u)``
    for a given gain sequence (any gains; Joseph form (32)).

    With the exact gains this is ``Omega_t``; with ``K^(tau)_t`` or frozen
    gains it is what those filters really achieve on data from the model.

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (T, n_p)
        Scheduling trajectory (range-checked).
    gains : ndarray, shape (T, n_x, n_y)
        The predictor gains ``K_t``.
    P0 : array_like, optional
        Covariance of ``x_0`` (default: the model's).
    burn_in : int
        Samples left out of :attr:`PredictionError.mean_trace`.

    Returns
    -------
    PredictionError
        The output and state error covariances and their mean trace.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> p = np.zeros((50, 1))
    >>> K = frozen_gains(model, p)
    >>> pe = prediction_error_covariance(model, p, K, burn_in=10)
    >>> pe.output.shape
    (50, 2, 2)
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    n, m = km.nx, km.ny
    gains = np.asarray(gains, dtype=float)
    if gains.shape != (T, n, m):
        raise DimensionError(f"gains has shape {gains.shape}; expected ({T}, {n}, {m})")
    _, P = initial_moments(km, None, P0)
    sms = km.step_matrices_batch(p)
    out = np.empty((T, m, m))
    st = np.empty((T + 1, n, n))
    st[0] = P
    G = np.zeros((2 * n, m))
    for t in range(T):
        G[:n] = gains[t]
        cs = covariance_step(P, sms.at(t), t=t, gains=G)
        out[t] = cs.Omega
        P = cs.joint[:n, :n]
        st[t + 1] = P
    tr = np.trace(out[burn_in:], axis1=1, axis2=2)
    return PredictionError(out, st, float(np.mean(tr)) if tr.size else float("nan"))


def empirical_prediction_error(
    model: AffineLPV,
    p: object,
    u: object | None,
    gains: np.ndarray,
    *,
    runs: int,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """Monte Carlo estimate of the output prediction-error covariance of the
    predictor with the given gains: ``runs`` independent trajectories of the
    model (1) (initial state drawn from ``N(x0, P0)``), filtered together.

    Returns the sample covariances ``E[e_t e_t^T]``, shape (T, n_y, n_y).

    Parameters
    ----------
    model : AffineLPV
        The model simulated (its noise covariance, ``x0`` and ``P0``).
    p : array_like, shape (T, n_p)
        Scheduling trajectory.
    u : array_like, shape (T, n_u), or None
        Known input (None: zero).
    gains : ndarray, shape (T, n_x, n_y)
        The predictor gains ``K_t``; the predictor starts at ``x0``.
    runs : int
        Number of independent trajectories.
    rng : numpy.random.Generator or int or None, optional
        Random source or seed.

    Returns
    -------
    ndarray, shape (T, n_y, n_y)
        ``sum_runs e_t e_t^T / runs`` with ``e_t = y_t - yhat_t`` (the
        prediction error has mean zero, so this is its covariance).

    Raises
    ------
    ArgumentTypeError
        ``model`` is not an AffineLPV.
    ArgumentError
        ``runs`` is not a positive integer.
    DimensionError
        ``p``, ``u`` or ``gains`` has the wrong shape.
    NonFiniteError
        ``gains`` holds NaN or inf.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> p = np.zeros((20, 1))
    >>> empirical_prediction_error(model, p, None, frozen_gains(model, p), runs=100, rng=0).shape
    (20, 2, 2)
    """
    if not isinstance(model, AffineLPV):
        raise ArgumentTypeError(f"model must be an AffineLPV (it is simulated with its noise); found "
                                f"{type(model).__name__}")
    if isinstance(runs, bool) or not isinstance(runs, int | np.integer) or runs < 1:
        raise ArgumentError(f"runs must be a positive integer; found {abbreviate(runs, 30)}")
    km = KalmanModel(model)
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    n, nu, m = km.nx, km.nu, km.ny
    gains = check_finite(np.asarray(gains, dtype=float), "gains")
    if gains.shape != (T, n, m):
        raise DimensionError(f"gains has shape {gains.shape}; expected ({T}, {n}, {m})")
    u = as_signal(u if u is not None else np.zeros((T, nu)), "u", nu, T)
    gen = as_rng(rng)
    mats = model.at_batch(p)
    noise = model.noise
    Lj = np.linalg.cholesky(noise.joint)
    nw = noise.Q.shape[0]
    x = model.x0 + gen.standard_normal((runs, n)) @ _psd_factor(model.P0).T
    xh = np.broadcast_to(model.x0, (runs, n)).copy()
    out = np.empty((T, m, m))
    for t in range(T):
        z = gen.standard_normal((runs, Lj.shape[0])) @ Lj.T
        w, v = z[:, :nw], z[:, nw:]
        A, B, C, D, G, H = (mats[i][t] for i in range(6))
        y = x @ C.T + u[t] @ D.T + v @ H.T
        e = y - xh @ C.T - u[t] @ D.T
        out[t] = e.T @ e / runs
        xh = xh @ A.T + u[t] @ B.T + e @ gains[t].T
        x = x @ A.T + u[t] @ B.T + w @ G.T
    return out


def _psd_factor(P: np.ndarray) -> np.ndarray:
    """A factor ``F`` with ``F F^T = P`` for positive semidefinite ``P``."""
    lam, V = np.linalg.eigh(0.5 * (P + P.T))
    return V * np.sqrt(np.clip(lam, 0.0, None))


def frozen_gains(
    model: AffineLPV | KalmanModel, p: object, *, tol: float = 1e-13, max_iter: int = 20000
) -> np.ndarray:
    """``K_inf(p_t)``: the steady-state gain of the model frozen at each
    ``p_t``, shape (T, n_x, n_y).

    This is the static, p_t-only gain of an LTI Kalman design scheduled on
    ``p``; (4c) shows the exact gain is dynamic in ``p``. All frozen models are
    iterated together with the recursion (4c)-(4e) from ``P = I`` until the
    largest change of ``P`` is below ``tol`` times its size (the fixed point
    is the solution of the discrete Riccati equation with the cross term,
    which :func:`~lpvest.estimators.steady_state` gets from scipy).

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (T, n_p)
        Scheduling values (range-checked); repeated values are iterated once.
    tol : float, default 1e-13
        Relative tolerance on the change of ``P`` per step (relative to
        ``max(1, max |P|)``).
    max_iter : int, default 20000
        Largest number of steps of the recursion.

    Returns
    -------
    ndarray, shape (T, n_x, n_y)
        ``K_inf(p_t)`` for every row of ``p``.

    Raises
    ------
    NumericalError
        The iteration does not settle within ``max_iter`` steps (no
        stabilising solution for some frozen model).

    Examples
    --------
    >>> from lpvest import load_system
    >>> frozen_gains(load_system("cox-toth-truncation").model(), [[0.0], [0.5]]).shape
    (2, 2, 2)
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    p = as_signal(p, "p", km.n_p)
    uniq, inverse = np.unique(p, axis=0, return_inverse=True)
    n = km.nx
    sms = km.step_matrices_batch(uniq)
    P = np.broadcast_to(np.eye(n), (uniq.shape[0], n, n)).copy()
    for _ in range(max_iter):
        cs = covariance_step(P, sms)
        P_new = cs.joint[:, :n, :n]
        change = np.max(np.abs(P_new - P), axis=(1, 2))
        P = P_new
        size = np.max(np.abs(P), axis=(1, 2))
        if not np.all(size < 1e100):  # diverging (or NaN): no stabilising solution
            bad = int(np.argmax(~(size < 1e100)))
            raise NumericalError(
                f"the frozen Riccati recursion at p = {uniq[bad].tolist()} diverges: no stabilising solution"
            )
        if np.all(change <= tol * np.maximum(1.0, size)):
            return covariance_step(P, sms).gains[:, :n][inverse.reshape(-1)]
    bad = int(np.argmax(change))
    raise NumericalError(
        f"the frozen Riccati recursion at p = {uniq[bad].tolist()} did not settle in {max_iter} steps"
    )


class FilterComparison(NamedTuple):
    """One-step prediction-error variances of several filters on one trajectory.

    Parameters
    ----------
    names : tuple of str
        ``"exact"``, ``"truncated tau=..."``, ``"frozen K_inf(p_t)"``,
        ``"constant K_inf(p*)"``.
    gains : dict of str to ndarray, shape (T, n_x, n_y)
        Name -> gain sequence.
    errors : dict of str to PredictionError
        Name -> exact second moments.
    mean_trace : dict of str to float
        Name -> mean over ``t >= burn_in`` of ``trace var(y - yhat)``.
    excess : dict of str to float
        Name -> ``mean_trace / mean_trace["exact"] - 1``.
    """

    names: tuple[str, ...]
    gains: dict[str, np.ndarray]
    errors: dict[str, PredictionError]
    mean_trace: dict[str, float]
    excess: dict[str, float]


def compare_filters(
    model: AffineLPV | KalmanModel,
    p: object,
    taus: Sequence[int] = (0, 1, 2, 5, 10),
    *,
    start: str | object = "theorem",
    start_p: object | None = None,
    constant_p: object | None = None,
    burn_in: int = 0,
) -> FilterComparison:
    """Prediction-error variances of the exact filter, the truncated filters
    ``K^(tau)`` for each ``tau``, the frozen-gain filter ``K_inf(p_t)`` and
    (with ``constant_p``) the constant gain ``K_inf(constant_p)``.

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (T, n_p)
        Scheduling trajectory.
    taus : sequence of int, default (0, 1, 2, 5, 10)
        Memories of the truncated filters.
    start, start_p
        ``P^_0`` of the truncated filters
        (see :func:`~lpvest.estimators.start_covariance`).
    constant_p : array_like, shape (n_p,), optional
        Frozen scheduling value of a constant-gain filter (default: none).
    burn_in : int, default 0
        Samples left out of the mean traces.

    Returns
    -------
    FilterComparison
        Gains, exact prediction-error moments, mean traces and excess over
        the exact filter, per filter.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> cmp = compare_filters(model, np.sin(0.25 * np.arange(100))[:, None], [1], burn_in=20)
    >>> cmp.names
    ('exact', 'truncated tau=1', 'frozen K_inf(p_t)')
    >>> bool(cmp.excess["truncated tau=1"] > 0)
    True
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    p = as_signal(p, "p", km.n_p)
    tau_list = sorted({int(t) for t in taus})
    err = truncation_errors(km, p, tau_list, start=start, start_p=start_p)
    gains = {"exact": err.exact_gains}
    for i, tau in enumerate(tau_list):
        gains[f"truncated tau={tau}"] = err.truncated_gains[i]
    gains["frozen K_inf(p_t)"] = frozen_gains(km, p)
    if constant_p is not None:
        cp = as_signal(np.atleast_2d(np.asarray(constant_p, dtype=float)), "constant_p", km.n_p, 1)
        K = frozen_gains(km, cp)[0]
        gains[f"constant K_inf({', '.join(f'{v:g}' for v in cp[0])})"] = np.broadcast_to(K, err.exact_gains.shape)
    errors = {name: prediction_error_covariance(km, p, K, burn_in=burn_in) for name, K in gains.items()}
    mean = {name: e.mean_trace for name, e in errors.items()}
    excess = {name: v / mean["exact"] - 1.0 for name, v in mean.items()}
    return FilterComparison(tuple(gains), gains, errors, mean, excess)
