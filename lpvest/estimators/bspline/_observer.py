"""The sliding-window observer over streaming samples (:class:`BSplineObserver`).

Notes: :mod:`lpvest.estimators.bspline`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...core._errors import (
    DimensionError,
    IdentifiabilityError,
    NonFiniteError,
    SamplingError,
    abbreviate,
)
from ...core._protocol import Component, Port
from ...core._validation import as_vector, check_finite
from ._fit import check_options, fit_window
from ._model import COEFFICIENTS, KernelModel
from ._regression import build_plan

__all__ = ["BSplineObserver"]


# -- streaming: the sliding-window observer ------------------------------------------------------


def _samples_of(duration: float, dt: float, name: str) -> int:
    if isinstance(duration, bool) or not isinstance(duration, int | float) or not duration > 0 or duration == np.inf:
        raise DimensionError(f"{name} must be a positive duration in seconds; found {abbreviate(duration, 30)}")
    k = duration / dt
    if abs(k - round(k)) > 1e-6 * max(1.0, k):
        raise SamplingError(f"{name} = {abbreviate(duration, 30)} s is not a whole number of sample steps dt "
                            f"= {abbreviate(dt, 30)} s")
    return int(round(k))


#: BSplineObserver's pending step: u, y, the new fit's arrays (None: no refit) and the outputs.
_Pending = tuple[float, float, dict[str, np.ndarray] | None, dict[str, np.ndarray]]


class BSplineObserver(Component[tuple[float, float], _Pending]):
    """Sliding-window joint parameter and state estimator (the observer FMU's engine).

    Samples arrive at a fixed step ``dt`` (time is *not* an input: sample
    ``k`` is at ``t_k = t0 + k dt``; known coefficients are evaluated at these
    times). The window holds the last ``L = window / dt + 1`` samples. Once it
    is full, and then every ``hop`` seconds, the estimator is fitted on the
    window ``[t_k - window, t_k]`` (:func:`fit_kernel_model`).

    **Delay.** Estimates are reported at the window's inner point
    ``t_k - delay`` with the constant ``delay = window - report_index * dt``,
    ``report_index = round(report * (L - 1))`` (``report = 0.5``: the window's
    centre, ``delay = window / 2``), where the B-spline estimate is reliable
    (the paper's inner window). Between refits, sample ``k`` reports the last
    fit at ``t_k - delay``, which stays inside that fit's window because
    ``hop <= delay + dt``. ``valid`` is 0 until the first window is full
    (outputs 0 then); the first valid output comes at ``t0 + window``. The
    estimates at sample ``k`` already use ``y_k`` (no extra step of delay).

    Ports
    -----
    inputs: ``u`` (1,), ``y`` (1,).
    outputs: ``t_est`` (1,) the time the estimates refer to, ``yhat`` (1,)
    ``y_E(t_est)``, ``dyhat`` (1,) ``y_E'(t_est)``, ``xhat`` (2,) the state of
    :meth:`LTVInputOutput.to_state_space` (``x_1 = y``, ``x_2 = y' + b_1 u``),
    ``a0, a1, b0, b1`` (1,) each the coefficients at ``t_est`` (known ones
    echo their value), ``valid`` (1,) 1.0 when the estimates are current.

    Parameters
    ----------
    model : KernelModel
        Unknown splines must use ``"uniform"`` or ``"clamped"`` knots (they
        are placed per window) or window-relative explicit knots.
    dt : float
        Sample time (s).
    window : float
        Window length (s), a multiple of ``dt``.
    hop : float, optional
        Time between refits (s), a multiple of ``dt``; default ``dt`` (refit at
        every sample). At most ``delay + dt``.
    t0 : float, optional
        Time of the first sample.
    report : float, optional
        Position of the reporting point in the window, in ``[0, 1]``
        (default 0.5, the centre).
    penalty, difference_order, points, rank_rtol
        As in :func:`fit_kernel_model`.
    on_unidentifiable : {"raise", "hold"}, optional
        When a window is not identifiable: raise
        :class:`~lpvest.core.IdentifiabilityError` (default; the sample is
        rejected and the observer unchanged) or hold the last estimates with
        ``valid = 0``.

    Examples
    --------
    >>> import numpy as np
    >>> from lpvest import load_system
    >>> from lpvest.estimators.bspline import KernelModel, UnknownConstant
    >>> from lpvest.core import run_streaming
    >>> io = load_system("sridhar-ltv").model()
    >>> t = np.arange(0, 801) * 0.005
    >>> d = io.simulate(t)
    >>> obs = BSplineObserver(KernelModel.from_io(io, a1=UnknownConstant()), dt=0.005, window=2.0, hop=0.5)
    >>> out = run_streaming(obs, {"u": d.u[:, None], "y": d.y[:, None]})
    >>> obs.delay, bool(out["valid"][400, 0]), bool(out["valid"][399, 0])
    (1.0, True, False)
    >>> bool(abs(out["a1"][-1, 0] - 1.0) < 1e-6)
    True
    """

    def __init__(
        self,
        model: KernelModel,
        *,
        dt: float,
        window: float,
        hop: float | None = None,
        t0: float = 0.0,
        report: float = 0.5,
        penalty: float | str | None = None,
        difference_order: int = 2,
        points: int = 6,
        rank_rtol: float = 1e-9,
        on_unidentifiable: str = "raise",
    ) -> None:
        if not isinstance(model, KernelModel):
            raise DimensionError(f"model must be a KernelModel; found {type(model).__name__}")
        if not model.unknowns:
            raise IdentifiabilityError("the model has no unknown coefficient: nothing to estimate")
        if isinstance(dt, bool) or not isinstance(dt, int | float) or not np.isfinite(dt) or dt <= 0:
            raise DimensionError(f"dt must be a positive sample time; found {abbreviate(dt, 30)}")
        check_options(penalty, difference_order, rank_rtol)
        if on_unidentifiable not in ("raise", "hold"):
            raise DimensionError(f"on_unidentifiable must be 'raise' or 'hold'; found "
                                 f"{abbreviate(on_unidentifiable, 30)}")
        if not isinstance(report, int | float) or not 0.0 <= report <= 1.0:
            raise DimensionError(f"report must be a fraction in [0, 1]; found {abbreviate(report, 30)}")
        self.model = model
        self.dt = float(dt)
        self.t0 = float(t0)
        self.length = _samples_of(window, self.dt, "window") + 1
        self.hop = 1 if hop is None else _samples_of(hop, self.dt, "hop")
        self.report_index = int(round(report * (self.length - 1)))
        lag = self.length - 1 - self.report_index
        if self.hop > lag + 1:
            raise DimensionError(
                f"hop = {self.hop} samples exceeds delay + 1 = {lag + 1} samples: between refits the "
                "reporting point would leave the window (shorten the hop or move report towards 0)"
            )
        self.penalty = penalty
        self.rank_rtol = float(rank_rtol)
        self.on_unidentifiable = on_unidentifiable
        self._plan = build_plan(model, self.length, self.dt, points=points, difference_order=difference_order)
        if self.length < self._plan.n_unknowns:
            raise IdentifiabilityError(
                f"a window of {self.length} samples is too short for {self._plan.n_unknowns} unknown coefficients"
            )
        self._instants = np.arange(self.length)
        inputs = (Port("u", (1,), "known input u_k"), Port("y", (1,), "measured output y_k"))
        outputs = (
            Port("t_est", (1,), "time the estimates refer to: t_k - delay"),
            Port("yhat", (1,), "y_E(t_est), kernel identity (9)"),
            Port("dyhat", (1,), "y_E'(t_est), derivative identity (10)"),
            Port("xhat", (2,), "state (y, y' + b1 u) at t_est, (32)"),
            Port("a0", (1,), "a_0(t_est)"),
            Port("a1", (1,), "a_1(t_est)"),
            Port("b0", (1,), "b_0(t_est)"),
            Port("b1", (1,), "b_1(t_est)"),
            Port("valid", (1,), "1 when the estimates are current, 0 before the first full window"),
        )
        super().__init__(inputs, outputs)

    # -- protocol ----------------------------------------------------------------------------
    @property
    def delay(self) -> float:
        """Reporting delay (s): estimates at sample ``k`` refer to ``t_k - delay``."""
        return (self.length - 1 - self.report_index) * self.dt

    def _reset(self) -> None:
        self._k = 0
        self._stored: dict[str, np.ndarray] | None = None
        self._head = 0
        self._ring_u = np.zeros(self.length)
        self._ring_y = np.zeros(self.length)
        self._last_fit = -1
        self._valid = 0.0
        self._held = self._zero_outputs()

    def _zero_outputs(self) -> dict[str, np.ndarray]:
        out = {p.name: np.zeros(p.shape) for p in self.output_ports}
        out["t_est"][0] = self.t0 + self._k * self.dt - self.delay
        return out

    def _read(self, inputs: Mapping[str, object]) -> tuple[float, float]:
        missing = [p.name for p in self.input_ports if p.name not in inputs]
        if missing:
            raise DimensionError(f"missing input {missing[0]!r}; the observer needs u and y")
        vals = []
        for name in ("u", "y"):
            arr = np.asarray(inputs[name], dtype=float)
            if arr.size != 1 or arr.ndim > 1:
                raise DimensionError(f"{name} has shape {arr.shape}; expected (1,)")
            check_finite(arr, name)
            vals.append(float(arr.reshape(-1)[0]))
        return vals[0], vals[1]

    def _window(self, u: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """The last ``L - 1`` buffered samples followed by the current one."""
        order = (self._head + 2 + np.arange(self.length - 1)) % self.length  # oldest of the last L - 1 first
        return (
            np.concatenate([self._ring_u[order], [u]]),
            np.concatenate([self._ring_y[order], [y]]),
        )

    def _compute(self, u: float, y: float) -> tuple[dict[str, np.ndarray] | None, dict[str, np.ndarray]]:
        """(new fit arrays or None, outputs) for the current sample; no state change."""
        n_have = self._k + 1
        if n_have < self.length:
            return None, self._zero_outputs()
        if (n_have - self.length) % self.hop == 0:
            uw, yw = self._window(u, y)
            a = self.t0 + (self._k - self.length + 1) * self.dt
            try:
                fit = fit_window(
                    self._plan, a, uw, yw, penalty=self.penalty, instants=self._instants, rank_rtol=self.rank_rtol
                )
            except IdentifiabilityError:
                if self.on_unidentifiable == "raise":
                    raise
                held = {k: v.copy() for k, v in self._held.items()}
                held["valid"] = np.array([0.0])
                held["t_est"] = np.array([self.t0 + self._k * self.dt - self.delay])
                return {}, held
            lo, hi = self.report_index, self.report_index + self.hop
            arrays = {"y": fit.y[lo:hi].copy(), "dy": fit.dy[lo:hi].copy(), "x": fit.x[lo:hi].copy()}
            for n in COEFFICIENTS:
                arrays[n] = fit.values[n][lo:hi].copy()
            return arrays, self._report_stored(arrays, 0)
        offset = self._k - self._last_fit
        if self._stored is None or self._valid == 0.0:
            held = {k: v.copy() for k, v in self._held.items()}
            held["valid"] = np.array([0.0])
            held["t_est"] = np.array([self.t0 + self._k * self.dt - self.delay])
            return None, held
        return None, self._report_stored(self._stored, offset)

    def _report_stored(self, arrays: Mapping[str, np.ndarray], offset: int) -> dict[str, np.ndarray]:
        out = {
            "t_est": np.array([self.t0 + self._k * self.dt - self.delay]),
            "yhat": np.array([arrays["y"][offset]]),
            "dyhat": np.array([arrays["dy"][offset]]),
            "xhat": np.array(arrays["x"][offset]),
            "valid": np.array([1.0]),
        }
        for n in COEFFICIENTS:
            out[n] = np.array([arrays[n][offset]])
        return out

    def _evaluate(self, sample: tuple[float, float]) -> tuple[dict[str, np.ndarray], _Pending]:
        u, y = sample
        arrays, out = self._compute(u, y)
        return out, (u, y, arrays, out)

    def _commit(self, pending: _Pending) -> None:
        u, y, arrays, out = pending
        if arrays is not None:
            if arrays:  # a successful refit
                self._stored = arrays
                self._last_fit = self._k
                self._valid = 1.0
            else:  # an unidentifiable window, held
                self._valid = 0.0
        self._held = {k: v.copy() for k, v in out.items()}
        self._head = (self._head + 1) % self.length
        self._ring_u[self._head] = u
        self._ring_y[self._head] = y
        self._k += 1

    # -- state ---------------------------------------------------------------------------------
    def get_state(self) -> dict[str, Any]:
        """The whole state: sample counter, the window buffer (ring and head),
        the last fit's reporting arrays and the held outputs.

        Returns
        -------
        dict
            ``"k"``, ``"head"``, ``"last_fit"`` (int), ``"valid"`` (float),
            ``"ring_u"``, ``"ring_y"`` (L,), ``"fit_<n>"`` for ``n`` in ``y, dy,
            x, a0, a1, b0, b1`` (hop,) or (hop, 2) for ``x`` (zeros before the
            first fit), and ``"held_<port>"`` for every output port (copies).
        """
        state: dict[str, object] = {
            "k": self._k,
            "head": self._head,
            "ring_u": self._ring_u.copy(),
            "ring_y": self._ring_y.copy(),
            "last_fit": self._last_fit,
            "valid": self._valid,
        }
        stored = self._stored
        for n in ("y", "dy", "x", *COEFFICIENTS):
            empty = np.zeros((self.hop, 2) if n == "x" else self.hop)
            state[f"fit_{n}"] = empty if stored is None else stored[n].copy()
        for n, v in self._held.items():
            state[f"held_{n}"] = v.copy()
        return state

    def _set_state(self, state: Mapping[str, Any]) -> None:
        """Restore a state from :meth:`get_state` (checked for shape)."""
        try:
            ring_u = as_vector(state["ring_u"], "ring_u", self.length)
            ring_y = as_vector(state["ring_y"], "ring_y", self.length)
            stored = {}
            for n in ("y", "dy", "x", *COEFFICIENTS):
                arr = np.array(state[f"fit_{n}"], dtype=float)
                want = (self.hop, 2) if n == "x" else (self.hop,)
                if arr.shape != want:
                    raise DimensionError(f"fit_{n} has shape {arr.shape}; expected {want}")
                stored[n] = arr
            held = {p.name: np.array(state[f"held_{p.name}"], dtype=float).reshape(p.shape) for p in self.output_ports}
            k, head, last_fit = int(state["k"]), int(state["head"]), int(state["last_fit"])
            valid = float(state["valid"])
        except KeyError as exc:
            raise DimensionError(f"observer state is missing {exc.args[0]!r}") from exc
        if not (0 <= head < self.length and k >= 0 and -1 <= last_fit < max(k, 0) + 1):
            raise DimensionError("observer state is inconsistent (head, k, last_fit)")
        for name, arr in (("ring_u", ring_u), ("ring_y", ring_y)):
            if not np.all(np.isfinite(arr)):
                raise NonFiniteError(f"{name} holds a non-finite value")
        self._k, self._head, self._last_fit, self._valid = k, head, last_fit, valid
        self._ring_u, self._ring_y = ring_u.copy(), ring_y.copy()
        self._stored = stored if last_fit >= 0 else None
        self._held = held
