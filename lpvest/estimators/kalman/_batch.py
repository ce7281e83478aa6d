"""The filter over a whole trajectory (:func:`kalman_filter`: sequential or the
parallel-in-time scan of :mod:`lpvest.estimators.kalman`) and the innovation-form
simulator (:func:`simulate_innovation_form`)."""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import numpy as np

from ...core._errors import ArgumentError, ArgumentTypeError, NumericalError, abbreviate
from ...core._validation import as_rng, as_signal
from ...systems._affine import AffineLPV, NoiseCovariance
from ...systems._innovation import innovation_step
from ._model import KalmanMatrices, KalmanModel, StepMatrices
from ._recursion import initial_moments, riccati_sweep
from ._scan import ScanAccuracyWarning, decorrelate_stack, scan_amplification, scan_error_bound, scan_filter
from ._smallmat import cholesky, lsolve

__all__ = [
    "KalmanResult",
    "InnovationFormData",
    "kalman_filter",
    "simulate_innovation_form",
    "SCAN_MIN_SAMPLES",
    "SCAN_MAX_AMPLIFICATION",
]

_LOG_2PI = math.log(2.0 * math.pi)

class KalmanResult(NamedTuple):
    """The exact filter over a trajectory of ``T`` samples; row ``t`` is time ``t``.

    Parameters
    ----------
    predicted_means : ndarray, shape (T + 1, n_x)
        ``x^_{t|t-1}``, t = 0..T.
    predicted_covariances : ndarray, shape (T + 1, n_x, n_x)
        ``P_{t|t-1}``.
    filtered_means : ndarray, shape (T, n_x)
        ``x^_{t|t}``.
    filtered_covariances : ndarray, shape (T, n_x, n_x)
        ``P_{t|t}``.
    predicted_outputs : ndarray, shape (T, n_y)
        ``C x^_{t|t-1} + D u_t``.
    innovations : ndarray, shape (T, n_y)
        ``xi_t``, (4b).
    innovation_covariances : ndarray, shape (T, n_y, n_y)
        ``Omega_t``, (4e).
    gains : ndarray, shape (T, n_x, n_y)
        Predictor gains ``K_t``, (4c).
    filter_gains : ndarray, shape (T, n_x, n_y)
        Filter gains ``L_t`` (ERRATA (7)).
    log_likelihood_terms : ndarray, shape (T,)
        ``log N(y_t; y^_t, Omega_t)``.
    log_likelihood : float
        ``log p(y_0, ..., y_{T-1})``, the sum of the terms.
    """

    predicted_means: np.ndarray
    predicted_covariances: np.ndarray
    filtered_means: np.ndarray
    filtered_covariances: np.ndarray
    predicted_outputs: np.ndarray
    innovations: np.ndarray
    innovation_covariances: np.ndarray
    gains: np.ndarray
    filter_gains: np.ndarray
    log_likelihood_terms: np.ndarray
    log_likelihood: float




SCAN_MIN_SAMPLES = 80

#: ``kalman_filter(method="auto")`` runs the sequential recursion when
#: ``amp = max_t ||J_t||_F ||C_t||_F`` (a bound of ``||J_t C_t||_F``) exceeds
#: this, ``J_t = G S H^T (H R H^T)^-1``: the decorrelated form amplifies
#: rounding errors by about ``amp^2`` (a nearly singular ``H R H^T`` next to
#: a strong cross-covariance), see :mod:`lpvest.estimators.kalman`,
#: "Accuracy". Up to this gate the scan's own part of its documented accuracy
#: (:func:`~lpvest.estimators.kalman._batch.scan_error_bound`,
#: ``100 eps (kappa + (1 + amp)^2)`` with ``kappa = max_t cond(Omega_t)``
#: the part any algorithm shares) is at most ``100 eps 31^2 = 2.1e-11``
#: relative to each output's size; beyond it, ``method="scan"`` runs but
#: warns (:class:`ScanAccuracyWarning`).
SCAN_MAX_AMPLIFICATION = 30.0

_METHODS = ("auto", "scan", "sequential")


def kalman_filter(
    model: AffineLPV | KalmanModel,
    p: object,
    u: object | None,
    y: object,
    *,
    x0: object | None = None,
    P0: object | None = None,
    noise: NoiseCovariance | object | None = None,
    method: str = "auto",
) -> KalmanResult:
    """Run the exact filter (4a)-(4e) over a whole trajectory.

    The matrices for every sample are evaluated at once. Two algorithms give
    the same numbers to rounding: the scan's outputs are within
    :func:`~lpvest.estimators.kalman._batch.scan_error_bound` of the
    sequential recursion's (``100 eps (kappa + (1 + amp)^2)`` relative to
    each output's largest entry, ``kappa = max_t cond(Omega_t)``; the scan's
    own part is at most 2.1e-11 where ``"auto"`` takes it), and the tests
    hold both to a Gaussian-conditioning oracle within about
    ``50 eps cond(S_yy)`` plus that bound:

    - ``"sequential"``: the covariance recursion (:func:`covariance_step`,
      the streaming filter's kernel) runs sample by sample; means, filtered
      estimates and the log-likelihood follow for all samples together.
    - ``"scan"``: the parallel-in-time filter of Särkkä & García-Fernández
      (2021) on the decorrelated model, as a blocked associative scan of
      batched small-matrix operations
      (:mod:`lpvest.estimators.kalman`). It needs ``H R H^T`` positive
      definite at every sample (raises :class:`~lpvest.core.NumericalError`
      naming the first ``t`` where it is not). Where the error
      amplification ``amp = max_t ||J_t||_F ||C_t||_F`` is above
      :data:`SCAN_MAX_AMPLIFICATION` it still runs, but warns
      (:class:`ScanAccuracyWarning`, with the error bound).
    - ``"auto"`` (default): the scan, except when it does not apply or does
      not pay: ``H R H^T`` singular at some sample, fewer than
      :data:`SCAN_MIN_SAMPLES` samples, or ``amp`` above
      :data:`SCAN_MAX_AMPLIFICATION` (module notes of
      :mod:`~lpvest.estimators.kalman`); then the sequential
      recursion. (An empty trajectory has nothing to scan: every method
      returns the initial prediction.)

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance unless ``noise`` is given).
    p : array_like, shape (T, n_p)
        Scheduling trajectory (range-checked).
    u : array_like, shape (T, n_u), or None when n_u = 0
        Known input.
    y : array_like, shape (T, n_y)
        Measurements.
    x0, P0 : array_like, optional
        Initial mean and covariance (default: the model's). ``P0`` may be
        singular.
    noise : NoiseCovariance or array_like, optional
        The noise covariance to assume (default: the model's).
    method : {"auto", "scan", "sequential"}
        The algorithm (above).

    Returns
    -------
    KalmanResult
        Predicted and filtered moments, innovations, gains and the log-likelihood.

    Raises
    ------
    DimensionError, NonFiniteError, SchedulingRangeError, NotPositiveDefiniteError
        Bad input.
    NumericalError
        ``Omega_t`` is singular, or (``method="scan"``) ``H R H^T`` is; the
        message names ``t``.
    ArgumentError, ArgumentTypeError
        ``method`` is not one of the three names (they derive from
        ``ValueError`` and ``TypeError``).

    Warns
    -----
    ScanAccuracyWarning
        ``method="scan"`` where ``amp > SCAN_MAX_AMPLIFICATION``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> k = np.arange(200)
    >>> p = np.sin(0.25 * k)[:, None]
    >>> u = np.sin(0.1 * k)[:, None]
    >>> data = model.simulate(p, u, rng=0)
    >>> res = kalman_filter(model, p, u, data.y)
    >>> res.gains.shape, res.predicted_means.shape
    ((200, 2, 2), (201, 2))
    >>> seq = kalman_filter(model, p, u, data.y, method="sequential")
    >>> err = np.max(np.abs(res.predicted_covariances - seq.predicted_covariances))
    >>> bool(err < 1e-12 * np.max(np.abs(seq.predicted_covariances)))
    True
    """
    if not isinstance(method, str):
        raise ArgumentTypeError(f"method must be a string, one of {', '.join(map(repr, _METHODS))}; "
                                f"found {abbreviate(method, 30)}")
    if method not in _METHODS:
        raise ArgumentError(f"method must be one of {', '.join(map(repr, _METHODS))}; found {abbreviate(method, 30)}")
    km = model if isinstance(model, KalmanModel) and noise is None else KalmanModel(
        model.model if isinstance(model, KalmanModel) else model, noise=noise
    )
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    u = as_signal(u, "u", km.nu, T)
    y = as_signal(y, "y", km.ny, T)
    x, P = initial_moments(km, x0, P0)
    km.check_box_batch(p)
    if method == "scan" or (method == "auto" and T >= SCAN_MIN_SAMPLES):
        # the scan wants each matrix contiguous (the sequential kernel, one packed F)
        mats, AT = km._scan_matrices_batch(p)
        res = _kalman_filter_scan(mats, AT, u, y, x, P, strict=method == "scan")
        if res is not None:
            return res
    sms = km.step_matrices_batch(p, check=False)
    return _kalman_filter_sequential(km, sms, sms.readable(), u, y, x, P)


def _kalman_filter_sequential(
    km: KalmanModel, sms: StepMatrices, mats: KalmanMatrices, u: np.ndarray, y: np.ndarray,
    x: np.ndarray, P: np.ndarray,
) -> KalmanResult:
    n, nu, m = km.nx, km.nu, km.ny
    T = y.shape[0]
    Pp, Pf, Om, Gm = riccati_sweep(km, sms, P)
    K = Gm[:, :n]
    L = Gm[:, n:]
    # means: x_{t+1} = (A - K C) x_t + B u + K (y - D u), one matrix-vector product per step
    Du = np.einsum("tij,tj->ti", mats.D, u) if nu else np.zeros((T, m))
    c = np.einsum("tij,tj->ti", K, y - Du)
    if nu:
        c += np.einsum("tij,tj->ti", mats.B, u)
    xs = [x]
    for Ft, ct in zip(mats.A - K @ mats.C, c, strict=True):
        x = Ft @ x
        x += ct
        xs.append(x)
    xp = np.array(xs)
    y_pred = np.einsum("tij,tj->ti", mats.C, xp[:T]) + Du
    xi = y - y_pred
    xf = xp[:T] + np.einsum("tij,tj->ti", L, xi)
    return _result(xp, Pp, xf, Pf, y_pred, xi, Om, K, L)


def _kalman_filter_scan(
    mats: KalmanMatrices, AT: np.ndarray, u: np.ndarray, y: np.ndarray, x: np.ndarray, P: np.ndarray,
    *, strict: bool,
) -> KalmanResult | None:
    """The scan (:mod:`.scan`); ``None`` when ``strict`` is false and
    the scan does not apply (``H R H^T`` singular somewhere, or the error
    amplification is above :data:`SCAN_MAX_AMPLIFICATION`). With ``strict``
    (``method="scan"``) an amplification above the gate warns
    (:class:`ScanAccuracyWarning`) and the scan runs."""
    T = y.shape[0]
    if T == 0:
        return None
    dec = decorrelate_stack(*mats, u, y, AT=AT)
    if isinstance(dec, int):
        if not strict:
            return None
        raise NumericalError(
            f"method='scan' needs H(p) R H(p)^T positive definite (the decorrelation "
            f"J = G S H^T (H R H^T)^-1); it is not at t={dec}: use method='sequential' or 'auto'"
        )
    amp = scan_amplification(dec, mats.C)
    if amp > SCAN_MAX_AMPLIFICATION:
        if not strict:
            return None
        warnings.warn(
            f"method='scan': the decorrelation amplifies rounding errors by about amp^2 with "
            f"amp = max_t ||J_t|| ||C_t|| = {amp:.3g} > {SCAN_MAX_AMPLIFICATION:g} (SCAN_MAX_AMPLIFICATION; "
            f"H R H^T is small next to the cross-covariance G S H^T): the results may differ from the "
            f"sequential recursion by up to ~{scan_error_bound(amp):.1g} relative; method='auto' or "
            f"'sequential' runs the sequential recursion",
            ScanAccuracyWarning,
            stacklevel=3,
        )
    s = scan_filter(dec, mats.C, mats.HRH, x, P)
    return KalmanResult(
        predicted_means=s.xp,
        predicted_covariances=s.Pp,
        filtered_means=s.xf,
        filtered_covariances=s.Pf,
        predicted_outputs=y - s.xi,
        innovations=s.xi,
        innovation_covariances=s.Omega,
        gains=s.K,
        filter_gains=s.L,
        log_likelihood_terms=s.log_likelihood_terms,
        log_likelihood=float(np.sum(s.log_likelihood_terms)),
    )


def _result(
    xp: np.ndarray, Pp: np.ndarray, xf: np.ndarray, Pf: np.ndarray, y_pred: np.ndarray, xi: np.ndarray,
    Om: np.ndarray, K: np.ndarray, L: np.ndarray,
) -> KalmanResult:
    terms = _loglik_terms(xi, Om)
    return KalmanResult(
        predicted_means=xp,
        predicted_covariances=Pp,
        filtered_means=xf,
        filtered_covariances=Pf,
        predicted_outputs=y_pred,
        innovations=xi,
        innovation_covariances=Om,
        gains=K,
        filter_gains=L,
        log_likelihood_terms=terms,
        log_likelihood=float(np.sum(terms)),
    )


def _loglik_terms(xi: np.ndarray, Omega: np.ndarray) -> np.ndarray:
    """``log N(xi_t; 0, Omega_t)`` for all t, by Cholesky factors."""
    m = xi.shape[1]
    if m == 1:
        w = Omega[:, 0, 0]
        return -0.5 * (_LOG_2PI + np.log(w) + xi[:, 0] ** 2 / w)
    chol = cholesky(Omega, lapack=True)  # each Omega_t was factored in the recursion
    z = lsolve(chol, xi[..., None], lapack=True)[..., 0]
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
    return -0.5 * (m * _LOG_2PI + logdet + np.sum(z * z, axis=1))


# ---------------------------------------------------------------------------
# innovation-form simulator
# ---------------------------------------------------------------------------
class InnovationFormData(NamedTuple):
    """Data generated from the innovation form (4); row ``t`` is time ``t``.

    Parameters
    ----------
    x : ndarray, shape (T, n_x)
        The innovation-form state ``x^_t`` of (4a).
    y : ndarray, shape (T, n_y)
        The outputs, (4b): ``y_t = C x^_t + D u_t + xi_t``.
    innovations : ndarray, shape (T, n_y)
        ``xi_t ~ N(0, Omega_t)``.
    gains : ndarray, shape (T, n_x, n_y)
        ``K_t``, (4c).
    innovation_covariances : ndarray, shape (T, n_y, n_y)
        ``Omega_t``, (4e).
    """

    x: np.ndarray
    y: np.ndarray
    innovations: np.ndarray
    gains: np.ndarray
    innovation_covariances: np.ndarray


def simulate_innovation_form(
    model: AffineLPV | KalmanModel,
    p: object,
    u: object | None = None,
    *,
    rng: np.random.Generator | int | None = None,
    x0: object | None = None,
    P0: object | None = None,
) -> InnovationFormData:
    """Generate data from the innovation form (4a)-(4b).

    ``K_t`` and ``Omega_t`` come from the Riccati recursion (4c)-(4e) started
    at ``P0``; ``xi_t ~ N(0, Omega_t)`` independent; the state starts at
    ``x0``. The output has the same distribution as the general-noise model
    (1) with ``x_0 ~ N(x0, P0)`` (Lemma 1).

    Parameters
    ----------
    model : AffineLPV or KalmanModel
        The model (a :class:`KalmanModel` brings its noise covariance).
    p : array_like, shape (T, n_p)
        Scheduling trajectory (range-checked).
    u : array_like, shape (T, n_u), optional (zero when omitted)
        Known input.
    rng : numpy.random.Generator or int, optional
        Random source or seed.
    x0, P0 : array_like, optional
        Initial mean and covariance (default: the model's).

    Returns
    -------
    InnovationFormData
        The states, outputs, innovations, gains ``K_t`` and ``Omega_t``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> data = simulate_innovation_form(model, np.zeros((50, 1)), np.ones((50, 1)), rng=1)
    >>> data.y.shape
    (50, 2)
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    n, nu, m = km.nx, km.nu, km.ny
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    u = as_signal(u if u is not None else np.zeros((T, nu)), "u", nu, T)
    x, P = initial_moments(km, x0, P0)
    sms = km.step_matrices_batch(p)
    _, _, Om, Gm = riccati_sweep(km, sms, P)
    K = Gm[:, :n]
    xi = np.einsum("tij,tj->ti", cholesky(Om, lapack=True), as_rng(rng).standard_normal((T, m)))
    mats = sms.readable()
    X = np.empty((T, n))
    Y = np.empty((T, m))
    for t in range(T):
        X[t] = x
        Y[t], x = innovation_step({"A": mats.A[t], "B": mats.B[t], "C": mats.C[t], "D": mats.D[t]},
                                  K[t], x, u[t], xi[t])
    return InnovationFormData(X, Y, xi, K, Om)


