"""Factory of the BSplineObserver FMU: the sliding-window B-spline observer of
Sridhar et al. for a second-order LTV input-output model."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core._errors import LpvestError, SamplingError
from ...core._protocol import TimedComponent
from ...estimators.bspline._model import KernelModel, UnknownConstant, UnknownSpline
from ...estimators.bspline._observer import BSplineObserver

if TYPE_CHECKING:
    from ...systems._ltv import LTVInputOutput

__all__ = ["build", "SampledObserver", "coefficient"]


def coefficient(name: str, spec: str) -> UnknownConstant | UnknownSpline | None:
    """``"known"`` | ``"constant"`` | ``"spline:N"`` | ``"spline:N:ORDER"`` -> a declaration."""
    text = spec.strip().lower()
    if text == "known":
        return None
    if text == "constant":
        return UnknownConstant()
    parts = text.split(":")
    if parts[0] == "spline" and len(parts) in (2, 3) and all(p.isdigit() for p in parts[1:]):
        n = int(parts[1])
        order = int(parts[2]) if len(parts) == 3 else 3
        return UnknownSpline(n, order=order)
    raise LpvestError(f"{name} = {spec!r}; expected 'known', 'constant', 'spline:N' or 'spline:N:ORDER'")


class SampledObserver(TimedComponent):
    """The B-spline observer inside an FMU: one :meth:`step` is one sample, of
    the observer's sample time ``dt`` (the FMU runs a communication step of
    ``m`` whole samples as ``m`` steps with the inputs held, :mod:`lpvest.fmi`).

    Time comes from the communication points: the first sample is at the
    experiment's start time ``t0`` (:meth:`reset`), and every step states the
    point it starts at (``t_end - dt``), which must be the time of the
    observer's next sample, ``t0 + k dt`` (to round-off); a sample the FMU
    rejects is not counted, so the clock never drifts from the host's."""

    def __init__(self, build: Callable[[float], BSplineObserver], dt: float) -> None:
        self._build = build
        self.dt = float(dt)
        self._obs = build(0.0)
        super().__init__(self._obs.input_ports, self._obs.output_ports, 0.0)

    @property
    def time(self) -> float:
        """The time of the next sample, ``t0 + k dt``."""
        return self._obs.t0 + self._obs.get_state()["k"] * self.dt

    def _reset(self) -> None:
        if self.t0 != self._obs.t0:
            self._obs = self._build(self.t0)
        self._obs.reset()

    def _read(self, inputs: Mapping[str, object]) -> Mapping[str, object]:
        return inputs  # checked by the observer

    def _evaluate(self, inputs: Mapping[str, object]) -> tuple[dict[str, np.ndarray], Mapping[str, object]]:
        return self._obs.outputs(inputs), inputs  # the observer keeps its evaluation for the step

    def _commit(self, inputs: Mapping[str, object], t_end: float = 0.0) -> None:
        self._obs.step(inputs)  # step() checked that this is the observer's next sample

    def step(  # type: ignore[override]  # the timed protocol: step(inputs, dt=h, t_end=t + h)
        self, inputs: Mapping[str, object], *, dt: float, t_end: float | None = None
    ) -> dict[str, np.ndarray]:
        if abs(dt - self.dt) > 1e-9 * self.dt:
            raise SamplingError(
                f"step {dt!r} s differs from the observer's sample time dt = {self.dt!r} s "
                "(one step is one sample)"
            )
        expected = self.time
        t = (expected + dt if t_end is None else float(t_end)) - dt
        if not math.isclose(t, expected, rel_tol=1e-9, abs_tol=1e-9 * self.dt):
            raise SamplingError(
                f"the step starts at t = {t!r} s; the observer's next sample is at {expected!r} s"
            )
        return super().step(inputs, dt=dt, t_end=expected + dt if t_end is None else t_end)

    def advance(self, *, dt: float = 0.0, t_end: float | None = None) -> dict[str, np.ndarray] | None:
        """The FMU's fast path: not taken (the sample-time checks live in :meth:`step`)."""
        return None

    def get_state(self) -> dict[str, object]:
        return self._obs.get_state()

    def _set_state(self, state: Mapping[str, Any]) -> None:
        self._obs.set_state(state)


def build(
    model: LTVInputOutput,
    *,
    design: object = None,
    dt: float,
    window: float,
    hop: float,
    a0: str,
    a1: str,
    b0: str,
    b1: str,
    penalty: float,
) -> SampledObserver:
    """The sliding-window B-spline observer (Sridhar et al.) of a second-order
    LTV input-output model; each coefficient declared known, an unknown
    constant or an unknown B-spline per window; ``penalty`` < 0 chooses the
    P-spline penalty by GCV, 0 means none."""
    unknown = {}
    for name, spec in (("a0", a0), ("a1", a1), ("b0", b0), ("b1", b1)):
        decl = coefficient(name, spec)
        if decl is not None:
            unknown[name] = decl
    kernel_model = KernelModel.from_io(model, **unknown)
    pen: float | str | None = "gcv" if penalty < 0 else (None if penalty == 0 else float(penalty))

    def make(t0: float) -> BSplineObserver:
        return BSplineObserver(kernel_model, dt=dt, window=window, hop=hop, t0=t0, penalty=pen,
                               on_unidentifiable="hold")

    return SampledObserver(make, dt)
