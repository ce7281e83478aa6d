"""The exact filter as a streaming component (:class:`LPVKalmanFilter`), and the
fast reading of one sample's inputs it shares with the truncated filter."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ...core._errors import DimensionError, NonFiniteError, abbreviate
from ...core._protocol import Component, Port
from ...core._validation import as_matrix, as_vector, check_finite, check_positive_definite
from ...systems._affine import AffineLPV, NoiseCovariance
from ._model import KalmanModel
from ._recursion import KalmanState, KalmanStep, initial_moments, kalman_step

__all__ = ["LPVKalmanFilter", "InputReader", "input_ports"]

# ---------------------------------------------------------------------------
# streaming
# ---------------------------------------------------------------------------
class InputReader:
    """Fast validation of one sample's inputs (p, u, y) for a streaming filter.

    Parameters
    ----------
    km : KalmanModel
        The compiled model: its dimensions and scheduling box. The input
        ``u`` is expected only when ``n_u > 0``.
    """

    def __init__(self, km: KalmanModel) -> None:
        self.km = km
        self.names = ("p", "u", "y") if km.nu else ("p", "y")
        self.sizes = {"p": km.n_p, "u": km.nu, "y": km.ny}
        self._nu = km.nu
        self._keys = frozenset(self.names)

    def _vec(self, inputs: Mapping[str, object], name: str) -> np.ndarray:
        try:
            value = inputs[name]
        except KeyError:
            raise DimensionError(
                f"input {name!r} is missing; the inputs are {', '.join(self.names)}"
            ) from None
        try:
            a = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            a = None
        n = self.sizes[name]
        if a is None or a.shape != (n,):
            a = as_vector(value, name, n)
        return a

    def read(self, inputs: Mapping[str, object], t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Validate one sample's inputs: names, shapes, finite values and the scheduling range.

        Parameters
        ----------
        inputs : mapping of str to array_like
            ``"p"`` (n_p,), ``"y"`` (n_y,) and, when ``n_u > 0``, ``"u"`` (n_u,).
        t : int
            Time index of the sample, named in errors.

        Returns
        -------
        p : ndarray, shape (n_p,)
            Scheduling vector, inside the box.
        u : ndarray, shape (n_u,)
            Input (a shared read-only empty array when ``n_u = 0``).
        y : ndarray, shape (n_y,)
            Measurement.

        Raises
        ------
        DimensionError
            An input is missing or unknown, or has the wrong shape.
        NonFiniteError
            An input holds NaN or inf.
        SchedulingRangeError
            ``p`` lies outside the scheduling box.
        """
        if len(inputs) != len(self.names) or not self._keys.issuperset(inputs):
            extra = sorted(set(inputs) - self._keys)
            if extra:
                raise DimensionError(f"unknown input {abbreviate(extra[0], 30)}; the inputs are "
                                     f"{', '.join(self.names)}")
        p = self._vec(inputs, "p")
        y = self._vec(inputs, "y")
        u = self._vec(inputs, "u") if self._nu else _EMPTY
        total = sum(p.tolist()) + sum(y.tolist()) + (sum(u.tolist()) if self._nu else 0.0)
        if not math.isfinite(total):  # NaN/inf somewhere (or an overflowing sum)
            for name, arr in (("p", p), ("u", u), ("y", y)):
                check_finite(arr, f"{name} at t={t}")
        self.km.check_p(p, t)
        return p, u, y


_EMPTY = np.zeros(0)
_EMPTY.setflags(write=False)


def input_ports(km: KalmanModel) -> tuple[Port, ...]:
    """The input ports of a streaming Kalman filter of ``km``.

    Parameters
    ----------
    km : KalmanModel
        The compiled model (its dimensions).

    Returns
    -------
    tuple of Port
        ``p`` (n_p,), ``u`` (n_u,) only if ``n_u > 0``, and ``y`` (n_y,).
    """
    ports = [Port("p", (km.n_p,), "scheduling p_t")]
    if km.nu:
        ports.append(Port("u", (km.nu,), "input u_t"))
    ports.append(Port("y", (km.ny,), "measurement y_t"))
    return tuple(ports)


class LPVKalmanFilter(Component):
    """The exact LPV Kalman filter (4a)-(4e) as a streaming estimator.

    Follows the streaming protocol (:mod:`lpvest.core`).

    Inputs (per sample ``t``): ``p`` (n_p,), ``u`` (n_u,) only if n_u > 0,
    ``y`` (n_y,).

    Outputs: ``xhat`` (n_x,) filtered ``x^_{t|t}``; ``P`` (n_x, n_x) its
    covariance ``P_{t|t}``; ``xpred`` (n_x,) ``x^_{t+1|t}``; ``Ppred``
    (n_x, n_x) ``P_{t+1|t}``; ``yhat`` (n_y,) ``C x^_{t|t-1} + D u_t``;
    ``innovation`` (n_y,) ``xi_t``; ``K`` (n_x, n_y) ``K_t``; ``Omega``
    (n_y, n_y) ``Omega_t``; ``loglik`` (scalar) ``log p(y_0, ..., y_t)``, the
    log-likelihood of the samples up to and including this one.

    Parameters
    ----------
    model : AffineLPV
        The affine LPV model (1).
    x0, P0 : array_like, optional
        Initial mean and covariance of ``x_0`` (default: the model's ``x0``,
        ``P0``).
    noise : NoiseCovariance or array_like, optional
        The noise covariance the filter assumes (default: the model's).

    Examples
    --------
    >>> from lpvest import load_system
    >>> kf = LPVKalmanFilter(load_system("cox-toth-truncation").model())
    >>> out = kf.step({"p": [0.0], "u": [1.0], "y": [0.1, -0.2]})
    >>> out["xhat"].shape, kf.t
    ((2,), 1)
    """

    def __init__(
        self,
        model: AffineLPV,
        *,
        x0: object | None = None,
        P0: object | None = None,
        noise: NoiseCovariance | object | None = None,
    ) -> None:
        self._km = KalmanModel(model, noise=noise)
        self._x0, self._P0 = initial_moments(self._km, x0, P0)
        self._x0.setflags(write=False)
        self._P0.setflags(write=False)
        self._reader = InputReader(self._km)
        n, m = self._km.nx, self._km.ny
        super().__init__(input_ports(self._km), (
            Port("xhat", (n,), "filtered state x_{t|t}"),
            Port("P", (n, n), "covariance P_{t|t} of xhat"),
            Port("xpred", (n,), "predicted state x_{t+1|t}"),
            Port("Ppred", (n, n), "covariance P_{t+1|t} of xpred"),
            Port("yhat", (m,), "one-step output prediction C x_{t|t-1} + D u_t"),
            Port("innovation", (m,), "innovation xi_t = y_t - yhat"),
            Port("K", (n, m), "predictor gain K_t (4c)"),
            Port("Omega", (m, m), "innovation covariance Omega_t (4e)"),
            Port("loglik", (), "log-likelihood log p(y_0..y_t) of the samples up to this one"),
        ))

    @property
    def kalman_model(self) -> KalmanModel:
        return self._km

    @property
    def state(self) -> KalmanState:
        """``x^_{t|t-1}``, ``P_{t|t-1}`` and ``t`` of the next sample."""
        return self._state

    @property
    def t(self) -> int:
        return self._state.t

    @property
    def log_likelihood(self) -> float:
        """``log p(y_0, ..., y_{t-1})`` of the samples consumed so far."""
        return self._loglik

    # -- the component (lpvest.core) ------------------------------------------------
    def _reset(self) -> None:
        """Back to ``x^_{0|-1} = x0``, ``P_{0|-1} = P0``, ``t = 0``."""
        self._state = KalmanState(self._x0, self._P0, 0)
        self._loglik = 0.0

    def _read(self, inputs: Mapping[str, object]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._reader.read(inputs, self._state.t)

    def _evaluate(self, sample: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[dict[str, np.ndarray],
                                                                                  KalmanStep]:
        p, u, y = sample
        r = kalman_step(self._state, self._km.step_matrices_unchecked(p), u, y)
        return {
            "xhat": r.x_filt,
            "P": r.P_filt,
            "xpred": r.next.x,
            "Ppred": r.next.P,
            "yhat": r.y_pred,
            "innovation": r.innovation,
            "K": r.K,
            "Omega": r.Omega,
            "loglik": np.array(self._loglik + r.log_likelihood),
        }, r

    def _commit(self, res: KalmanStep) -> None:
        nxt = res.next
        nxt.x.setflags(write=False)
        nxt.P.setflags(write=False)
        self._state = nxt
        self._loglik += res.log_likelihood

    # -- the whole step --------------------------------------------------------------
    def _inputs(self, p: object, u: object | None, y: object) -> dict[str, object]:
        return {"p": p, "y": y} if not self._km.nu else {"p": p, "u": u, "y": y}

    def process(self, p: object, u: object | None, y: object) -> KalmanStep:
        """Consume sample ``t`` and advance; returns every quantity of the step
        (``K_t``, ``Omega_t``, ``L_t``, ...).

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
            The step's quantities; ``next`` is the filter's new :attr:`state`.
        """
        _, res = self._take(self._inputs(p, u, y))
        self._commit(res)
        return res

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
        return self._evaluate(self._read(self._inputs(p, u, y)))[1]

    # -- state -----------------------------------------------------------------------
    def get_state(self) -> dict[str, object]:
        """A copy of the whole internal state (for :meth:`set_state`).

        Returns
        -------
        dict
            ``"x"`` (n_x,) ``x^_{t|t-1}``, ``"P"`` (n_x, n_x) ``P_{t|t-1}``
            (copies), ``"t"`` (int) the next sample's index and
            ``"log_likelihood"`` (float) of the samples consumed so far.
        """
        st = self._state
        return {"x": st.x.copy(), "P": st.P.copy(), "t": int(st.t), "log_likelihood": float(self._loglik)}

    def _set_state(self, state: Mapping[str, Any]) -> None:
        n = self._km.nx
        try:
            x = as_vector(state["x"], "state x", n)
            P = as_matrix(state["P"], "state P", (n, n))
            t = int(state["t"])
            ll = float(state["log_likelihood"])
        except KeyError as exc:
            raise DimensionError(f"state is missing {exc.args[0]!r}") from None
        P = check_positive_definite(P, "state P", semidefinite=True)
        if t < 0:
            raise DimensionError(f"state t = {t} is negative")
        if not math.isfinite(ll):
            raise NonFiniteError(f"state log_likelihood is {ll}")
        x.setflags(write=False)
        P.setflags(write=False)
        self._state = KalmanState(x, P, t)
        self._loglik = ll
