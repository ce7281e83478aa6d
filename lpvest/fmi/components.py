"""Streaming components of the Scheduler and Source FMUs.

They follow the step protocol of :mod:`lpvest.estimators.base` with
``timed = True`` (``reset(t0)``, ``step(inputs, dt=h, t_end=t + h)``): the value at the
current communication point is reported, then the signal moves to ``t + h``.
The signals themselves are :mod:`lpvest.signals`; numpy only.

Examples
--------
>>> from lpvest import load_system
>>> from lpvest.signals import SignalSpec
>>> plant = load_system("peixoto-ex1").model()
>>> sched = SchedulerComponent(SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=0.25), plant.space,
...                            plant.simplex_map)
>>> sched.reset(0.0)
>>> out = sched.step({}, dt=1.0)
>>> out["p"], out["alpha"], sched.outputs({})["p"]
(array([0.]), array([0.5, 0.5]), array([0.24740396]))
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..estimators.base import Port
from ..scheduling import SchedulingSpace
from ..signals import SignalError, SignalGenerator, SignalSpec

__all__ = ["SchedulerComponent", "SourceComponent"]


class SchedulerComponent:
    """The scheduling signal ``p`` (and ``alpha = map(p)`` for a polytopic model).

    The signal must stay inside the scheduling box: a specification that can
    leave it is rejected with an error naming the parameter.
    """

    timed = True

    def __init__(
        self, signal: SignalSpec, space: SchedulingSpace, simplex_map: Any = None, *, prefix: str = ""
    ) -> None:
        if signal.n != space.dim:
            raise SignalError(f"the scheduling signal has {signal.n} components; the model has {space.dim}")
        lo, hi = signal.bounds()
        for j, name in enumerate(space.names):
            tol = 1e-12 * max(1.0, abs(space.lower[j]), abs(space.upper[j]))
            if lo[j] >= space.lower[j] - tol and hi[j] <= space.upper[j] + tol:
                continue
            box = f"[{space.lower[j]:g}, {space.upper[j]:g}]"
            where = f"takes p[{j + 1}] ({name}) to [{lo[j]:.6g}, {hi[j]:.6g}], outside its declared range {box}"
            if signal.kind in ("sinusoid", "decaying"):
                culprit = (f"{prefix}amplitude[{j + 1}] = {signal.amplitude[j]:g} with "
                           f"{prefix}offset[{j + 1}] = {signal.offset[j]:g}")
            elif signal.kind == "constant":
                culprit = f"{prefix}offset[{j + 1}] = {signal.offset[j]:g}"
            elif signal.kind == "table":
                culprit = f"{prefix}table (column {j + 1})"
            else:
                culprit = f"{prefix}kind = {signal.kind!r} (std[{j + 1}] = {signal.std[j]:g})"
            raise SignalError(f"{culprit} {where}")
        if signal.kind == "random":
            # a random walk is clipped to its bounds: they must be the box
            if np.any(signal.lower < space.lower) or np.any(signal.upper > space.upper):
                raise SignalError(f"{prefix}lower/{prefix}upper of the random scheduling must lie in the box")
        self.signal = signal
        self.space = space
        self.simplex_map = simplex_map
        self._gen = SignalGenerator(signal)
        self._memo: dict[str, np.ndarray] | None = None
        ports = [Port("p", (space.dim,), "scheduling")]
        if simplex_map is not None:
            ports.append(Port("alpha", (simplex_map.n_vertices,), "vertex weights"))
        self._outputs = tuple(ports)

    @property
    def input_ports(self) -> tuple[Port, ...]:
        return ()

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return self._outputs

    def reset(self, t0: float = 0.0) -> None:
        self._gen.start(t0)
        self._memo = None

    def _evaluate(self) -> dict[str, np.ndarray]:
        p = np.clip(self._gen.value, self.space.lower, self.space.upper)
        out = {"p": p}
        if self.simplex_map is not None:
            out["alpha"] = np.asarray(self.simplex_map(p), dtype=float)
        return out

    def outputs(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """``p`` (and ``alpha``) at the current time; kept for the next :meth:`step`."""
        if self._memo is None:
            self._memo = self._evaluate()
        return {name: value.copy() for name, value in self._memo.items()}

    def step(self, inputs: Mapping[str, Any], *, dt: float, t_end: float | None = None) -> dict[str, np.ndarray]:
        out = self._memo if self._memo is not None else self._evaluate()
        self._gen.advance(self._gen.time + float(dt) if t_end is None else float(t_end))
        self._memo = None
        return out

    def get_state(self) -> dict[str, Any]:
        return self._gen.get_state()

    def set_state(self, state: Mapping[str, Any]) -> None:
        self._gen.set_state(dict(state))
        self._memo = None


class SourceComponent:
    """Named signals (e.g. ``u`` and ``w``), each with its own specification."""

    timed = True

    def __init__(self, signals: Mapping[str, SignalSpec], descriptions: Mapping[str, str] | None = None) -> None:
        self.signals = dict(signals)
        self._gens = {name: SignalGenerator(spec) for name, spec in self.signals.items()}
        desc = descriptions or {}
        self._outputs = tuple(Port(name, (spec.n,), desc.get(name, "")) for name, spec in self.signals.items())

    @property
    def input_ports(self) -> tuple[Port, ...]:
        return ()

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return self._outputs

    def reset(self, t0: float = 0.0) -> None:
        for gen in self._gens.values():
            gen.start(t0)

    def outputs(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        return {name: gen.value for name, gen in self._gens.items()}

    def step(self, inputs: Mapping[str, Any], *, dt: float, t_end: float | None = None) -> dict[str, np.ndarray]:
        out = self.outputs(inputs)
        for gen in self._gens.values():
            gen.advance(gen.time + float(dt) if t_end is None else float(t_end))
        return out

    def get_state(self) -> dict[str, Any]:
        return {name: gen.get_state() for name, gen in self._gens.items()}

    def set_state(self, state: Mapping[str, Any]) -> None:
        for name, gen in self._gens.items():
            gen.set_state(dict(state[name]))
