"""The exact LPV Kalman filter in innovation form, Cox & Tóth (4a)-(4e).

For the affine LPV model with general noise (000_dc6273d4fec795cd.txt, (1)-(3))::

    x_{t+1} = A(p_t) x_t + B(p_t) u_t + G(p_t) w_t
    y_t     = C(p_t) x_t + D(p_t) u_t + H(p_t) v_t,     [w; v] ~ N(0, [[Q, S], [S^T, R]])

with ``x_0 ~ N(x0, P0)``, the one-step predictor in innovation form is

- (4b) ``xi_t = y_t - C x^_{t|t-1} - D u_t`` (innovation),
- (4e) ``Omega_t = C P_{t|t-1} C^T + H R H^T``,
- (4c) ``K_t = (A P_{t|t-1} C^T + G S H^T) Omega_t^-1``,
- (4a) ``x^_{t+1|t} = A x^_{t|t-1} + B u_t + K_t xi_t``,
- (4d) ``P_{t+1|t} = A P A^T - K_t Omega_t K_t^T + G Q G^T``,

all matrices at ``p_t``. The filtered estimate uses the *filter* gain
``L_t = P_{t|t-1} C^T Omega_t^-1`` (ERRATA (7)): ``x^_{t|t} = x^_{t|t-1} + L_t xi_t``.

Numerics
--------
With ``e = x_t - x^_{t|t-1}`` (covariance ``P``), the stacked vector
``z = [A e + G w_t; e; C e + H v_t]`` has covariance
``V = E P E^T + W``, ``E = [A; I; C]``,
``W = [[G Q G^T, 0, G S H^T], [0, 0, 0], [H S^T G^T, 0, H R H^T]]``.
Its blocks hold ``Omega_t`` and ``[A P C^T + G S H^T; P C^T]``, so
``[K_t; L_t] = V_{12} Omega_t^-1``; and for *any* gains, the prediction and
filter errors are ``[I_2n, -[K; L]] z``, so

    [[P_{t+1|t}, .], [., P_{t|t}]] = M V M^T,   M = [I_2n, -[K; L]],

which is the Joseph form of both updates: ``(A - K C) P (A - K C)^T +
[G, -K H] Sigma [G, -K H]^T`` (the paper's (32) with ERRATA's
``K Omega K^T``) and ``(I - L C) P (I - L C)^T + L H R H^T L^T``; positive
semidefinite by construction, then symmetrised.

- Gains come from the Cholesky factor of ``Omega_t`` (for ``n_y = 1`` a
  division by the positive scalar); a factor that fails raises
  :class:`~lpvest.core.NumericalError` naming ``t``. No inverse, no jitter.
- ``[E, [B; 0; D], W]`` is one matrix of degree two in the basis functions
  (``G Q G^T`` is quadratic); :class:`KalmanModel` packs its coefficients
  once, so a sample's matrices are one product ``z(p) @ coefficients``.
- One kernel (:func:`covariance_step`) serves the streaming filter, the
  sequential batch filter, the truncated filter and the fading-memory
  analysis.
- The batch filter :func:`kalman_filter` has a second algorithm, the
  parallel-in-time scan of Särkkä & García-Fernández (2021) on the
  decorrelated model (:mod:`lpvest.estimators.kalman`): the same numbers
  from a few hundred batched numpy calls instead of ~14 small calls per
  sample; ``method="auto"`` chooses.

Runtime code: imports only numpy.

Modules: :mod:`~lpvest.estimators.kalman` (the p-dependent matrices),
:mod:`~lpvest.estimators.kalman` (the kernel and one step),
:mod:`~lpvest.estimators.kalman` (a whole trajectory, the
innovation-form simulator), :mod:`~lpvest.estimators.kalman` (the
parallel-in-time form), :mod:`~lpvest.estimators.kalman` (the
streaming component).

Examples
--------
>>> import numpy as np
>>> from lpvest import load_system
>>> model = load_system("cox-toth-truncation").model()
>>> k = np.arange(50)
>>> p, u = np.sin(0.25 * k)[:, None], np.sin(0.1 * k)[:, None]
>>> y = model.simulate(p, u, rng=0).y
>>> res = kalman_filter(model, p, u, y)
>>> res.filtered_means.shape, round(res.log_likelihood, 4)
((50, 2), -111.2149)
"""

from __future__ import annotations

from ._batch import (
    SCAN_MAX_AMPLIFICATION,
    SCAN_MIN_SAMPLES,
    InnovationFormData,
    KalmanResult,
    kalman_filter,
    simulate_innovation_form,
)
from ._model import KalmanMatrices, KalmanModel, StepMatrices
from ._recursion import CovarianceStep, KalmanState, KalmanStep, covariance_step, kalman_step
from ._scan import ScanAccuracyWarning
from ._streaming import LPVKalmanFilter

__all__ = [
    "KalmanModel",
    "KalmanMatrices",
    "StepMatrices",
    "KalmanState",
    "CovarianceStep",
    "KalmanStep",
    "KalmanResult",
    "InnovationFormData",
    "covariance_step",
    "kalman_step",
    "kalman_filter",
    "simulate_innovation_form",
    "LPVKalmanFilter",
    "SCAN_MIN_SAMPLES",
    "SCAN_MAX_AMPLIFICATION",
    "ScanAccuracyWarning",
]
