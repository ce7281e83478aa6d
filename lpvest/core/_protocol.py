"""The streaming protocol: one sample (or one communication step) at a time.

Every plant, filter, observer and signal of lpvest is a *streaming component*
with named :class:`Port` inputs and outputs:

- ``outputs(inputs)`` returns the component's outputs at the current sample
  for these inputs, **without changing it** (an FMU reports them right after
  its inputs are set, before ``fmi2DoStep``: direct feedthrough, no one-step
  delay);
- ``step(inputs)`` returns the same values and advances to the next sample
  (``fmi2DoStep``); a *timed* component (a signal of time, a continuous-time
  plant, an observer that keeps time) takes ``step(inputs, dt=h, t_end=t + h)``
  and ``reset(t0)``;
- ``reset()`` goes back to the initial state; ``get_state()``/``set_state()``
  copy the whole state (covariances, windows, counters, random generators) as
  a flat mapping of names to numpy arrays or Python scalars: what
  ``fmi2GetFMUstate`` and serialization store.

:class:`Sampled` and :class:`Timed` state this as typing Protocols.
:class:`Component` and :class:`TimedComponent` implement it once over three
methods a subclass writes: ``_read(inputs)`` (validate one sample: bad input
raises a typed :class:`~lpvest.core.LpvestError` before anything changes,
so a rejected sample leaves the component as it was), ``_evaluate(sample)``
(the outputs and whatever the step will need: no state change) and
``_commit(pending)`` (advance).

**Computing once.** A caller that asks for ``outputs`` and then calls
``step`` with the same inputs (the FMU adapter does so at every
communication point) does not pay for the sample twice: the evaluation is
kept, keyed on an exact fingerprint of the inputs (:func:`input_key`: names,
shapes and float64 bytes), and reused when the key matches and the state has
not changed since. A plain loop that only calls ``step`` never builds a key.
A key covers the exact values, so an input that would be rejected is never
served from the memo, and the reused values are the very numbers a fresh
evaluation gives.

**A measurement that arrives late.** A master that steps every component
in parallel (Jacobi: libcosim, fmpy's ``simulate_ssp``, most tools) passes
outputs read *after* the step, so a filter receives the measurement ``y`` of
sample ``k - 1`` together with the scheduling of sample ``k``.
:class:`MeasurementDelay` wraps any sampled component and pairs each late
input with the other inputs of its own sample, so the component runs on the
samples it was designed for, ``delay`` samples later.

This module is the bottom of the package: it imports only numpy and
:mod:`lpvest.core`.

Examples
--------
>>> class Counter(Component):
...     def __init__(self):
...         super().__init__((Port("u", (1,)),), (Port("total", (1,)),))
...     def _reset(self):
...         self.total = 0.0
...     def _read(self, inputs):
...         return float(inputs["u"][0])
...     def _evaluate(self, u):
...         return {"total": np.array([self.total + u])}, self.total + u
...     def _commit(self, total):
...         self.total = total
...     def get_state(self):
...         return {"total": self.total}
...     def _set_state(self, state):
...         self.total = float(state["total"])
>>> c = Counter()
>>> c.outputs({"u": [2.0]})["total"], c.step({"u": [2.0]})["total"], c.step({"u": [1.0]})["total"]
(array([2.]), array([2.]), array([3.]))
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Generic, Protocol, TypeVar, cast, runtime_checkable

import numpy as np

from ._errors import ArgumentError, ArgumentTypeError, DimensionError, abbreviate

#: What a component's ``_read`` gives its ``_evaluate`` (one checked sample).
SampleT = TypeVar("SampleT")
#: What a component's ``_evaluate`` prepares for its ``_commit``.
PendingT = TypeVar("PendingT")
#: :func:`input_key`: per input its name, shape and the bytes of its float64 values.
InputKey = tuple[tuple[str, tuple[int, ...], bytes], ...]

__all__ = [
    "Port",
    "Sampled",
    "Timed",
    "Component",
    "TimedComponent",
    "MeasurementDelay",
    "whole_samples",
    "input_key",
    "run_streaming",
]


@dataclass(frozen=True)
class Port:
    """A named input or output of a streaming component.

    ``shape`` is ``(n,)`` for a vector (FMI variables ``name[1]..name[n]``),
    ``(r, c)`` for a matrix (``name[1,1]..name[r,c]``) or ``()`` for a scalar.
    ``direct`` (outputs): the value at a sample depends on that sample's inputs
    (direct feedthrough, e.g. a filtered estimate); ``False`` for a value fixed
    by the past alone (a state ``x_k``), which an FMU can report at ``t_k + h``
    right after the step.

    Parameters
    ----------
    name : str
        The port's name (the FMI variable name, and the key in the mappings of
        inputs and outputs).
    shape : tuple of int
        ``(n,)``, ``(r, c)`` or ``()``, as above.
    description : str, default ""
        One line about the value (the FMI variable's description).
    direct : bool, default True
        Whether the output has direct feedthrough, as above.
    """

    name: str
    shape: tuple[int, ...]
    description: str = ""
    direct: bool = True

    @property
    def size(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1


@runtime_checkable
class Sampled(Protocol):
    """A discrete-time component: one ``step`` is one sample.

    Parameters
    ----------
    *args, **kwargs
        Not used: a Protocol cannot be instantiated. A class conforms by having
        the members below (``isinstance`` checks that they exist).
    """

    @property
    def input_ports(self) -> tuple[Port, ...]: ...

    @property
    def output_ports(self) -> tuple[Port, ...]: ...

    def reset(self) -> None:
        """Back to the initial state."""

    def outputs(self, inputs: Mapping[str, object]) -> dict[str, np.ndarray]:
        """Outputs at the current sample for these inputs; no state change.

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``).
        """
        ...

    def step(self, inputs: Mapping[str, object]) -> dict[str, np.ndarray]:
        """Consume the current sample: return :meth:`outputs` and advance.

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``).
        """
        ...

    def get_state(self) -> dict[str, object]:
        """A copy of the whole internal state (numpy arrays and scalars).

        Returns
        -------
        state : dict of str to object
            Names to numpy arrays or Python scalars, for :meth:`set_state`.
        """
        ...

    def set_state(self, state: Mapping[str, object]) -> None:
        """Restore a state from :meth:`get_state`.

        Parameters
        ----------
        state : mapping of str to object
            A state returned by :meth:`get_state` of a component of the same
            kind and dimensions.
        """


@runtime_checkable
class Timed(Protocol):
    """A component that keeps time: ``reset(t0)``, ``step(inputs, dt=h, t_end=t + h)``.

    Parameters
    ----------
    *args, **kwargs
        Not used: a Protocol cannot be instantiated. A class conforms by having
        the members below (``isinstance`` checks that they exist).
    """

    timed: bool

    @property
    def input_ports(self) -> tuple[Port, ...]: ...

    @property
    def output_ports(self) -> tuple[Port, ...]: ...

    def reset(self, t0: float = 0.0) -> None:
        """Back to the initial state at time ``t0``.

        Parameters
        ----------
        t0 : float, default 0.0
            The start time.
        """

    def outputs(self, inputs: Mapping[str, object]) -> dict[str, np.ndarray]:
        """Outputs at the current time for these inputs; no state change.

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``).
        """
        ...

    def step(self, inputs: Mapping[str, object], *, dt: float, t_end: float | None = None) -> dict[str, np.ndarray]:
        """Return :meth:`outputs` at the current time, then advance by ``dt`` (to ``t_end``).

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).
        dt : float
            The step size ``h`` (> 0).
        t_end : float or None, default None
            The time reached, ``t + h`` exactly as the master computes it;
            ``None``: the current time plus ``dt``.

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``).
        """
        ...

    def get_state(self) -> dict[str, object]:
        """A copy of the whole internal state, the time included.

        Returns
        -------
        state : dict of str to object
            Names to numpy arrays or Python scalars, for :meth:`set_state`.
        """
        ...

    def set_state(self, state: Mapping[str, object]) -> None:
        """Restore a state from :meth:`get_state`.

        Parameters
        ----------
        state : mapping of str to object
            A state returned by :meth:`get_state` of a component of the same
            kind and dimensions.
        """


def input_key(inputs: Mapping[str, object], names: tuple[str, ...] | None = None) -> InputKey | None:
    """An exact, hashable fingerprint of one sample's inputs: per input its
    name, shape and the bytes of its values as float64 (``names``: only these
    inputs, in this order; default every item of ``inputs``).

    Two inputs with equal keys validate alike and evaluate to the same numbers,
    so a component may reuse an evaluation made for an equal key. ``None`` when
    a value is missing or not numeric (the caller then evaluates, and raises its
    usual error).

    Parameters
    ----------
    inputs : mapping of str to array_like
        One sample's inputs by name.
    names : tuple of str or None, default None
        The inputs to fingerprint, in this order (other items of ``inputs`` are
        left out); ``None``: every item of ``inputs``, in its order.

    Returns
    -------
    key : tuple or None
        One ``(name, shape, bytes)`` triple per input, or ``None`` as above.

    Examples
    --------
    >>> input_key({"y": [1.0]}) == input_key({"y": np.array([1.0])})
    True
    >>> input_key({"y": [1.0]}) == input_key({"y": [[1.0]]})
    False
    """
    try:
        items = inputs.items() if names is None else [(n, inputs[n]) for n in names]
        key = []
        for name, value in items:
            a = value if type(value) is np.ndarray and value.dtype == np.float64 else np.asarray(value, dtype=float)
            key.append((name, a.shape, a.tobytes()))
        return tuple(key)
    except (KeyError, TypeError, ValueError, OverflowError):
        return None


class Component(ABC, Generic[SampleT, PendingT]):
    """The base of every sampled streaming component (see the module documentation).

    A subclass passes its ports to ``__init__``, then writes ``_reset``,
    ``_read``, ``_evaluate``, ``_commit``, ``get_state`` and ``_set_state``.
    ``__init__`` calls :meth:`reset` last, so a subclass sets what ``_reset``
    needs before calling it.

    Parameters
    ----------
    inputs : tuple of Port
        The input ports, in the order :meth:`outputs` fingerprints them
        (:func:`input_key`).
    outputs : tuple of Port
        The output ports.
    """

    timed: ClassVar[bool] = False

    def __init__(self, inputs: tuple[Port, ...], outputs: tuple[Port, ...]) -> None:
        self._in = tuple(inputs)
        self._out = tuple(outputs)
        self._in_names = tuple(p.name for p in self._in)
        self._memo: tuple[InputKey | None, dict[str, np.ndarray], PendingT] | None = None
        self.reset()

    # -- ports ------------------------------------------------------------------------
    @property
    def input_ports(self) -> tuple[Port, ...]:
        return self._in

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return self._out

    # -- what a subclass writes ----------------------------------------------------------
    @abstractmethod
    def _reset(self) -> None:
        """Set the initial state."""

    @abstractmethod
    def _read(self, inputs: Mapping[str, object]) -> SampleT:
        """One sample's inputs, checked (raise a typed error, change nothing)."""

    def _read_checked(self, inputs: Mapping[str, np.ndarray]) -> SampleT:
        """:meth:`_read` for inputs checked at the boundary (``prepare(checked=True)``).

        The caller guarantees every input port is present as a float64 array
        of the port's shape, every value finite, and every element of a port
        named ``p`` within the component's scheduling box (to the tolerance of
        :func:`lpvest.core.check_box`): what an FMU's ``fmi2SetReal``
        checks for each element against its declared range. A component
        overrides this to skip exactly those checks and keep the rest (a
        simplex sum, a covariance); the default reads as :meth:`_read` does.
        The sample must be the one :meth:`_read` would give, to the bit.
        """
        return self._read(inputs)

    @abstractmethod
    def _evaluate(self, sample: SampleT) -> tuple[dict[str, np.ndarray], PendingT]:
        """``(outputs, pending)`` for a checked sample; no state change."""

    @abstractmethod
    def _commit(self, pending: PendingT) -> None:
        """Advance to the next sample with what :meth:`_evaluate` prepared."""

    @abstractmethod
    def get_state(self) -> dict[str, object]:
        """A copy of the whole internal state.

        Returns
        -------
        state : dict of str to object
            Names to numpy arrays or Python scalars, for :meth:`set_state`.
        """

    @abstractmethod
    def _set_state(self, state: Mapping[str, object]) -> None:
        """Restore a state from :meth:`get_state` (checked)."""

    # -- the protocol --------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the initial state."""
        self._memo = None
        self._reset()

    def set_state(self, state: Mapping[str, object]) -> None:
        """Restore a state from :meth:`get_state`; a kept evaluation is dropped.

        Parameters
        ----------
        state : mapping of str to object
            A state returned by :meth:`get_state` of a component of the same
            kind and dimensions (checked by the subclass's ``_set_state``).
        """
        self._set_state(state)
        self._memo = None

    def outputs(self, inputs: Mapping[str, object]) -> dict[str, np.ndarray]:
        """The outputs at the current sample for these inputs; no state change
        (the evaluation is kept for a following :meth:`step` with the same inputs).

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``);
            copies, which the caller may modify.
        """
        key = input_key(inputs, self._in_names)
        memo = self._memo
        if key is None or memo is None or memo[0] != key:
            out, pending = self._evaluate(self._read(inputs))
            self._memo = None if key is None else (key, out, pending)
        else:
            out = memo[1]
        return {name: value.copy() for name, value in out.items()}

    def _take(self, inputs: Mapping[str, object]) -> tuple[dict[str, np.ndarray], PendingT]:
        memo = self._memo
        if memo is not None:
            self._memo = None
            # a key of None (kept by prepare(), or inputs that are missing or not
            # numeric) matches nothing: such inputs are read, and refused, as usual
            if memo[0] is not None and memo[0] == input_key(inputs, self._in_names):
                return memo[1], memo[2]
        return self._evaluate(self._read(inputs))

    def step(self, inputs: Mapping[str, object]) -> dict[str, np.ndarray]:
        """The outputs at the current sample; then advance to the next one.

        The evaluation kept by :meth:`outputs` is reused when ``inputs`` have the
        same :func:`input_key`; otherwise the sample is read and evaluated.

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``).
        """
        out, pending = self._take(inputs)
        self._commit(pending)
        return out

    def prepare(self, inputs: Mapping[str, object], *, checked: bool = False) -> dict[str, np.ndarray]:
        """Evaluate the current sample for a following :meth:`advance`, for a
        caller that guarantees these inputs stay unchanged (the FMU adapter):
        like :meth:`outputs`, without fingerprinting the inputs and without
        copying the outputs (the component's own arrays: do not modify them).

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).
        checked : bool, default False
            The caller has checked the inputs as :meth:`_read_checked` says
            (an FMU checks each element when it is set): the component skips
            those checks. The outputs are the same to the bit.

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (not copies).
        """
        # checked: the caller guarantees float64 arrays of the ports' shapes (see _read_checked)
        out, pending = self._evaluate(self._read_checked(cast(Mapping[str, np.ndarray], inputs)) if checked
                                      else self._read(inputs))
        self._memo = (None, out, pending)  # only advance() takes it: step() never reuses a None key
        return out

    def _kept(self) -> tuple[dict[str, np.ndarray], PendingT] | None:
        memo = self._memo
        self._memo = None
        return None if memo is None else (memo[1], memo[2])

    def advance(self) -> dict[str, np.ndarray] | None:
        """:meth:`step` with the inputs of the last :meth:`outputs` call, which the
        caller guarantees unchanged (the FMU adapter: no input was set since), so
        they are neither read nor fingerprinted again; ``None`` (and no step)
        when no evaluation is kept.

        Returns
        -------
        outputs : dict of str to ndarray or None
            The outputs of the kept evaluation (those :meth:`outputs` or
            :meth:`prepare` gave), or ``None``.
        """
        kept = self._kept()
        if kept is None:
            return None
        self._commit(kept[1])
        return kept[0]


class TimedComponent(Component[SampleT, PendingT]):
    """The base of every streaming component that keeps time: ``reset(t0)``,
    ``step(inputs, dt=h, t_end=t + h)`` (``t_end``: the master's communication
    point, free of the round-off of summed steps). ``_commit`` receives
    ``(pending, t_end)``.

    Parameters
    ----------
    inputs : tuple of Port
        The input ports, in the order :meth:`outputs` fingerprints them
        (:func:`input_key`).
    outputs : tuple of Port
        The output ports.
    t0 : float, default 0.0
        The start time (:meth:`reset` without an argument goes back to it).
    """

    timed: ClassVar[bool] = True

    def __init__(self, inputs: tuple[Port, ...], outputs: tuple[Port, ...], t0: float = 0.0) -> None:
        self.t0 = float(t0)
        super().__init__(inputs, outputs)

    def reset(self, t0: float | None = None) -> None:
        """Back to the initial state at time ``t0`` (default: the last start time).

        Parameters
        ----------
        t0 : float or None, default None
            The new start time, kept for later resets; ``None``: the last one.
        """
        if t0 is not None:
            self.t0 = float(t0)
        self._memo = None
        self._reset()

    @abstractmethod
    def _commit(self, pending: PendingT, t_end: float = 0.0) -> None:
        """Advance to ``t_end`` with what :meth:`_evaluate` prepared."""

    @property
    @abstractmethod
    def time(self) -> float:
        """The current time."""

    def step(  # type: ignore[override]  # the timed protocol: step(inputs, dt=h, t_end=t + h)
        self, inputs: Mapping[str, object], *, dt: float, t_end: float | None = None
    ) -> dict[str, np.ndarray]:
        """The outputs at the current time; then advance by ``dt`` (to ``t_end`` when given).

        Parameters
        ----------
        inputs : mapping of str to array_like
            One sample's value of every input port, by port name (shape
            ``port.shape``).
        dt : float
            The step size ``h`` (> 0).
        t_end : float or None, default None
            The time reached, ``t + h`` exactly as the master computes it;
            ``None``: the current time plus ``dt``.

        Returns
        -------
        outputs : dict of str to ndarray
            The value of every output port, by port name (shape ``port.shape``).

        Raises
        ------
        DimensionError
            ``dt`` is not positive and finite.
        """
        dt = float(dt)
        if not dt > 0 or not np.isfinite(dt):
            raise DimensionError(f"the step size must be positive and finite; found {dt!r}")
        out, pending = self._take(inputs)
        self._commit(pending, self.time + dt if t_end is None else float(t_end))
        return out

    def advance(self, *, dt: float = 0.0, t_end: float | None = None) -> dict[str, np.ndarray] | None:
        """:meth:`step` with the inputs of the last :meth:`outputs` call (see
        :meth:`Component.advance`); ``None`` (and no step) when none is kept.

        Parameters
        ----------
        dt : float, default 0.0
            The step size ``h``; unlike :meth:`step`, not checked.
        t_end : float or None, default None
            The time reached; ``None``: the current time plus ``dt``.

        Returns
        -------
        outputs : dict of str to ndarray or None
            The outputs of the kept evaluation, or ``None``.
        """
        kept = self._kept()
        if kept is None:
            return None
        self._commit(kept[1], self.time + float(dt) if t_end is None else float(t_end))
        return kept[0]


#: MeasurementDelay's sample: this step's on-time and late inputs.
_DelaySample = tuple[dict[str, np.ndarray], dict[str, np.ndarray]]
#: MeasurementDelay's pending step: the on-time inputs to keep, and what the wrapped component
#: commits (its pending step, or the paired inputs of a protocol-only component), None while waiting.
_DelayPending = tuple[dict[str, np.ndarray], tuple[object] | None]


class MeasurementDelay(Component[_DelaySample, _DelayPending]):
    """A sampled component whose measurement arrives ``delay`` samples late:
    each late input is paired with the other inputs of its own sample.

    At step ``j`` the wrapper receives the inputs named in ``late`` of sample
    ``j - delay`` (e.g. ``y_{j-1}``) and the others of sample ``j`` (e.g.
    ``p_j``, ``u_j``). It keeps the others of the last ``delay`` samples and
    hands ``component`` the sample ``j - delay`` whole (``p_{j-1}``,
    ``u_{j-1}``, ``y_{j-1}``): the component runs on exactly the samples it
    would get without the delay, in the same order, so its output at step
    ``j`` is, to the bit, its output for sample ``j - delay`` without the
    delay. A Kalman filter stays the exact filter, an H-infinity filter keeps
    its certified bound: nothing is approximated, the estimate of sample ``k``
    comes ``delay`` samples later.

    **Before the first measurement.** At the first ``delay`` steps no
    measurement of a sample has arrived (what the late inputs hold then
    belongs to no sample and is ignored, after the usual checks): the
    component is not stepped, and every output is 0. The scheduling and
    known inputs of those steps are kept for the samples they belong to.

    Each step's inputs are checked as they arrive, by the component's own
    checks (a bad value raises there, before anything changes), so the
    component's checks must not couple a late input with the others of the
    same step. ``delay = 0`` pairs every input with its own step: the
    component itself, to the bit. The wrapper takes over ``component`` and
    resets it; :meth:`get_state` holds the component's state and the kept
    inputs.

    Parameters
    ----------
    component : Sampled
        A sampled (not timed) streaming component, e.g.
        :class:`~lpvest.estimators.kalman.LPVKalmanFilter` or
        :class:`~lpvest.estimators.HinfFilter`.
    delay : int, default 1
        By how many samples the late inputs arrive late (``>= 0``).
    late : tuple of str, default ("y",)
        The input ports that arrive late (the measurement); the others arrive
        with their own sample.

    Raises
    ------
    ArgumentTypeError
        ``component`` is timed, or ``delay`` is not an integer.
    ArgumentError
        ``delay`` is negative, or ``late`` is empty or names no input of
        ``component``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> from lpvest.estimators.kalman import LPVKalmanFilter
    >>> model = load_system("cox-toth-truncation").model()
    >>> late = MeasurementDelay(LPVKalmanFilter(model), delay=1)
    >>> late.step({"p": [0.5], "u": [1.0], "y": [0.0, 0.0]})["xhat"]    # no measurement yet
    array([0., 0.])
    >>> a = late.step({"p": [0.1], "u": [0.0], "y": [0.3, -0.2]})["xhat"]   # y of sample 0, paired with p_0, u_0
    >>> b = LPVKalmanFilter(model).step({"p": [0.5], "u": [1.0], "y": [0.3, -0.2]})["xhat"]
    >>> bool((a == b).all())
    True
    """

    def __init__(self, component: Sampled, *, delay: int = 1, late: tuple[str, ...] = ("y",)) -> None:
        if isinstance(component, TimedComponent) or getattr(component, "timed", False):
            raise ArgumentTypeError(f"{type(component).__name__} keeps time (a timed component): a measurement "
                                    "delay pairs samples of a sampled component")
        if isinstance(delay, bool) or not isinstance(delay, int | np.integer):
            raise ArgumentTypeError(f"delay must be an integer number of samples; found {abbreviate(delay, 30)}")
        if delay < 0:
            raise ArgumentError(f"delay must be >= 0 samples; found {delay}")
        ports = tuple(component.input_ports)
        names = [p.name for p in ports]
        late = tuple(late)
        unknown = [n for n in late if n not in names]
        if not late or unknown:
            raise ArgumentError(f"late must name inputs of {type(component).__name__} ({', '.join(names)}); "
                                f"found {abbreviate(list(late), 60)}")
        self._inner = component
        self._inner_is_component = isinstance(component, Component)
        self._delay = int(delay)
        self._late = late
        self._on_time = tuple(p for p in ports if p.name not in late)
        self._late_ports = tuple(p for p in ports if p.name in late)
        ins = tuple(replace(p, description=f"{p.description} (arriving {self._delay} sample(s) late)".lstrip())
                    if p.name in late and self._delay else p for p in ports)
        self._queue: deque[dict[str, np.ndarray]] = deque()
        super().__init__(ins, tuple(component.output_ports))

    @property
    def component(self) -> Sampled:
        """The wrapped component (it runs on the paired samples)."""
        return self._inner

    @property
    def delay(self) -> int:
        """By how many samples the late inputs arrive late."""
        return self._delay

    @property
    def late(self) -> tuple[str, ...]:
        """The names of the late inputs."""
        return self._late

    @property
    def waiting(self) -> bool:
        """Whether no measurement has arrived yet (the first ``delay`` steps)."""
        return len(self._queue) < self._delay

    # -- the component (this module's protocol) ----------------------------------------
    def _reset(self) -> None:
        self._inner.reset()
        self._queue = deque()

    def _arrived(self, inputs: Mapping[str, object]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The checked inputs of this step as float64 copies: (on time, late)."""
        on_time = {p.name: np.array(inputs[p.name], dtype=float).reshape(p.shape) for p in self._on_time}
        late = {p.name: np.array(inputs[p.name], dtype=float).reshape(p.shape) for p in self._late_ports}
        return on_time, late

    def _read(self, inputs: Mapping[str, object]) -> _DelaySample:
        inner = self._inner
        if self._inner_is_component:
            cast(Component, inner)._read(inputs)  # the component's own checks, as they arrive
        else:
            inner.outputs(inputs)  # a component of the protocol only: its checks, no state change
        return self._arrived(inputs)

    def _read_checked(self, inputs: Mapping[str, np.ndarray]) -> _DelaySample:
        inner = self._inner
        if self._inner_is_component:
            cast(Component, inner)._read_checked(inputs)
        else:
            inner.outputs(inputs)
        return self._arrived(inputs)

    def _evaluate(self, sample: _DelaySample) -> tuple[dict[str, np.ndarray], _DelayPending]:
        on_time, late = sample
        if len(self._queue) < self._delay:  # no measurement of a sample yet
            return {p.name: np.zeros(p.shape) for p in self._out}, (on_time, None)
        paired = {**(self._queue[0] if self._delay else on_time), **late}
        if self._inner_is_component:
            inner = cast(Component, self._inner)
            # every value of the pair passed the component's checks when it arrived
            out, pending = inner._evaluate(inner._read_checked(paired))
            return out, (on_time, (pending,))
        return self._inner.outputs(paired), (on_time, (paired,))

    def _commit(self, pending: _DelayPending) -> None:
        on_time, inner_pending = pending
        if inner_pending is not None:
            if self._inner_is_component:
                inner = cast(Component, self._inner)
                inner._memo = None
                inner._commit(inner_pending[0])
            else:
                self._inner.step(cast("dict[str, np.ndarray]", inner_pending[0]))  # the paired inputs
        if self._delay:
            if len(self._queue) == self._delay:
                self._queue.popleft()
            self._queue.append(on_time)

    def get_state(self) -> dict[str, object]:
        """The component's state and the kept inputs.

        Returns
        -------
        state : dict
            ``"component"``: the wrapped component's :meth:`get_state`;
            ``"kept"``: how many samples' on-time inputs are kept (``<= delay``);
            ``"inputs"``: per on-time input port, those values stacked, oldest
            first (shape ``(kept, *port.shape)``).
        """
        n = len(self._queue)
        return {
            "component": self._inner.get_state(),
            "kept": n,
            "inputs": {p.name: np.array([k[p.name] for k in self._queue], dtype=float).reshape((n, *p.shape))
                       for p in self._on_time},
        }

    def _set_state(self, state: Mapping[str, Any]) -> None:
        try:
            n, values, inner = state["kept"], state["inputs"], state["component"]
        except (KeyError, TypeError):
            raise DimensionError("a MeasurementDelay state needs 'component', 'kept' and 'inputs'") from None
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 0 <= n <= self._delay:
            raise DimensionError(f"kept = {abbreviate(n, 30)} must be an integer in [0, delay = {self._delay}]")
        kept: deque[dict[str, np.ndarray]] = deque({} for _ in range(int(n)))
        for p in self._on_time:
            a = np.array(values.get(p.name) if isinstance(values, Mapping) else None, dtype=float)
            if a.shape != (n, *p.shape):
                raise DimensionError(f"kept inputs {p.name} have shape {a.shape}; expected {(int(n), *p.shape)}")
            for i in range(int(n)):
                kept[i][p.name] = a[i].copy()
        self._inner.set_state(inner)
        self._queue = kept


def whole_samples(h: float, sample_time: float, *, rtol: float = 1e-9) -> int | None:
    """How many samples a step ``h`` is: ``m = round(h / sample_time)`` when
    ``h`` is that whole number ``m >= 1`` of samples to ``rtol`` relative
    (``|h / sample_time - m| <= rtol * max(1, h / sample_time)``: the rule of
    communication points, which hosts accumulate in floating point), else
    ``None``. A ratio so large that ``rtol`` cannot tell ``m`` from ``m + 1``
    (``rtol * h / sample_time >= 1/2``) is ``None`` too.

    Parameters
    ----------
    h : float
        The step (a communication step size).
    sample_time : float
        The time between samples (> 0).
    rtol : float, default 1e-9
        The relative tolerance.

    Returns
    -------
    m : int or None
        The number of samples, ``>= 1``; ``None``: not a whole number of samples.

    Examples
    --------
    >>> whole_samples(3.0, 1.0), whole_samples(0.30000000000000004, 0.1), whole_samples(1.5, 1.0)
    (3, 3, None)
    >>> whole_samples(0.5, 1.0) is None, whole_samples(1e12, 1.0) is None
    (True, True)
    """
    ratio = float(h) / float(sample_time)
    if not math.isfinite(ratio) or not ratio > 0.5 or rtol * ratio >= 0.5:
        return None
    m = int(round(ratio))
    return m if abs(ratio - m) <= rtol * max(1.0, ratio) else None


def run_streaming(
    estimator: Sampled, inputs: Mapping[str, np.ndarray], *, steps: int | None = None
) -> dict[str, np.ndarray]:
    """Run a sampled component over whole input sequences (row ``k`` = sample ``k``)
    and stack its outputs, each of shape ``(T, *port.shape)``.

    Parameters
    ----------
    estimator : Sampled
        The component, stepped from its current state with ``step(inputs)``
        (no ``dt``: not a :class:`Timed` one).
    inputs : mapping of str to ndarray, shape (T, ...)
        Every input port's sequence by name, all of the same length ``T``.
    steps : int, optional
        ``T``, for a component without inputs (a source); when given with
        inputs it must equal their length.

    Returns
    -------
    outputs : dict of str to ndarray, shape (T, ...)
        Every output port's sequence by name; row ``k`` is the output of
        sample ``k``.

    Raises
    ------
    DimensionError
        The sequences differ in length or from ``steps``, or there are none
        and no ``steps``.
    TypeError
        ``estimator`` is a timed component (:class:`TimedComponent`: it steps
        by a ``dt``, call its ``step(inputs, dt=...)``).
    """
    if isinstance(estimator, TimedComponent):
        raise TypeError(f"run_streaming runs sampled components; {type(estimator).__name__} is timed "
                        "(it advances by a step size): call its step(inputs, dt=...) in a loop")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 0):
        raise DimensionError(f"steps must be a non-negative integer; found {steps!r}")
    lengths = {name: np.shape(v)[0] if np.ndim(v) else None for name, v in inputs.items()}
    if any(n is None for n in lengths.values()):
        raise DimensionError(f"every input needs a sequence (first axis: the sample); found scalars for "
                             f"{sorted(n for n, v in lengths.items() if v is None)}")
    if not lengths:
        if steps is None:
            raise DimensionError("no input sequences: give steps=T for a component without inputs")
        T = steps
    else:
        found = {n for n in lengths.values() if n is not None}  # (none is None: checked above)
        if len(found) != 1:
            raise DimensionError(f"input sequences have different lengths: {lengths}")
        T = int(found.pop())
        if steps is not None and steps != T:
            raise DimensionError(f"steps = {steps}, but the input sequences have {T} samples")
    out = {p.name: np.empty((T, *p.shape)) for p in estimator.output_ports}
    for k in range(T):
        res = estimator.step({name: np.asarray(v[k]) for name, v in inputs.items()})
        for name, arr in out.items():
            arr[k] = res[name]
    return out
