"""Test signals: scheduling trajectories, inputs and disturbances.

One :class:`SignalSpec` describes an ``n``-component signal of one kind; a
:class:`SignalGenerator` produces it sample by sample (what the Scheduler and
Source FMUs do at each communication point) and :func:`sample_signal` gives a
whole trajectory at given times by running the same generator, so an FMU and a
Python experiment get the same numbers from the same specification.

Kinds (per component ``j``; ``t`` is the time of the communication point, and
``t = k`` for a discrete-time experiment with unit step):

============  ==============================================================
``zero``      ``0``
``constant``  ``offset``
``sinusoid``  ``offset + amplitude sin(omega t + phase)``
``decaying``  ``offset + amplitude sin(omega t + phase) exp(-decay t)``;
              Peixoto et al., Section 4: ``w_k = sin(0.5 k) exp(-0.1 k)``
              applied from ``k = 10`` (absolute ``k``, zero before the onset)
``gaussian``  ``offset + std * N(0, 1)``, a fresh seeded draw at every point
``random``    random walk with bounded rate: ``s <- clip(s + rate h U(-1, 1),
              lower, upper)`` at each step of length ``h``, from ``offset``
``table``     piecewise-linear in ``t`` through the rows ``(t_i, v_i)``,
              constant before the first and after the last row
============  ==============================================================

Before ``onset`` every kind except ``table`` holds ``offset`` (``0`` for
``zero``). Randomness comes from ``lpvest.core.Stream(seed)`` (the same numbers
in the native FMUs): ``gaussian`` draws ``n`` normals per point, ``random``
``n`` uniforms per step, ``U(-1, 1) = -1 + 2 u``.

Examples
--------
>>> spec = SignalSpec.build("decaying", 1, amplitude=1.0, omega=0.5, decay=0.1, onset=10)
>>> w = sample_signal(spec, np.arange(20.0))
>>> bool(w[9, 0] == 0.0), bool(np.isclose(w[10, 0], np.sin(5.0) * np.exp(-1.0)))
(True, True)
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ._errors import DimensionError, LpvestError, abbreviate
from ._protocol import Port, TimedComponent
from ._rng import Stream

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..systems._polytopic import SimplexMap
    from ._scheduling import SchedulingSpace

__all__ = [
    "SIGNAL_KINDS",
    "SignalSpec",
    "SignalGenerator",
    "SchedulerComponent",
    "SourceComponent",
    "SignalError",
    "sample_signal",
    "parse_table",
]

#: The signal kinds, in the order an FMU documents them.
SIGNAL_KINDS = ("zero", "constant", "sinusoid", "decaying", "gaussian", "random", "table")


class SignalError(LpvestError, ValueError):
    """A signal specification is invalid (the message names the parameter)."""


#: What separates a table's numbers besides ',' (C's isspace in the "C" locale)
_BLANKS = " \t\n\r\f\v"
#: The most characters a table's number may have (the native runtime's lpv_parse_float)
_LONGEST_NUMBER = 300


def parse_table(text: str, n: int, *, name: str = "table") -> tuple[np.ndarray, np.ndarray]:
    """Parse ``"t v_1 ... v_n; t v_1 ... v_n; ..."`` (rows separated by ``;`` or
    newlines, numbers by spaces or commas) into times ``(m,)`` and values ``(m, n)``.

    Parameters
    ----------
    text : str
        The rows, each a time and ``n`` values; empty rows are skipped.
    n : int
        The number of signal components (values per row).
    name : str, default "table"
        How errors call the table (e.g. the FMU parameter's name).

    Returns
    -------
    times : ndarray, shape (m,)
        The first column, strictly increasing.
    values : ndarray, shape (m, n)
        The other columns.

    Raises
    ------
    SignalError
        No rows, a row without ``n + 1`` numbers, a field that is not a number
        (numbers are ASCII, at most 300 characters, separated by ASCII white space
        or commas), a non-finite number, or times not strictly increasing.

    Examples
    --------
    >>> parse_table("0 0.5; 10, -0.5", 1)
    (array([ 0., 10.]), array([[ 0.5],
           [-0.5]]))
    """
    # ASCII white space and digits only, as the native FMUs read a table (str.strip, \s and
    # float() would take Unicode's too: "0\xa01" or an Arabic-Indic digit)
    rows = [r.strip(_BLANKS) for r in re.split(r"[;\n]", text or "") if r.strip(_BLANKS)]
    if not rows:
        raise SignalError(f"{name} is empty; expected rows 't v_1 ... v_{n}' separated by ';'")
    data = []
    for i, row in enumerate(rows):
        fields = [f for f in re.split(r"[, \t\n\r\f\v]+", row) if f]
        if len(fields) != n + 1:
            raise SignalError(
                f"{name} row {i + 1} ({abbreviate(row, 30)}) has {len(fields)} numbers; expected {n + 1} "
                f"(t and {n} values)"
            )
        try:
            if not all(f.isascii() and len(f) <= _LONGEST_NUMBER for f in fields):
                raise ValueError
            data.append([float(f) for f in fields])
        except ValueError:
            raise SignalError(
                f"{name} row {i + 1} ({abbreviate(row, 30)}) holds something that is not a number"
            ) from None
    arr = np.array(data)
    if not np.all(np.isfinite(arr)):
        raise SignalError(f"{name} holds a non-finite number")
    times = arr[:, 0]
    if np.any(np.diff(times) <= 0):
        raise SignalError(f"{name}: the times (first column) must be strictly increasing; found {times.tolist()}")
    return times, arr[:, 1:]


@dataclass(frozen=True, eq=False)
class SignalSpec:
    """An ``n``-component signal of one kind (see the module documentation).

    Build it with :meth:`build`, which checks every parameter and names the
    culprit (``prefix`` + parameter name + 1-based index) in its error.

    Parameters
    ----------
    kind : str
        One of :data:`SIGNAL_KINDS`.
    n : int
        The number of components.
    amplitude, omega, phase : ndarray, shape (n,)
        Of the ``sinusoid`` and ``decaying`` kinds: ``amplitude sin(omega t + phase)``
        (``omega`` in rad per unit of time, ``phase`` in rad).
    offset : ndarray, shape (n,)
        The value before ``onset``, the ``constant`` value, the centre of the
        ``sinusoid``, ``decaying`` and ``gaussian`` kinds and the start of the
        ``random`` walk.
    decay : ndarray, shape (n,)
        The rate of ``exp(-decay t)`` of the ``decaying`` kind.
    std : ndarray, shape (n,)
        The standard deviation of the ``gaussian`` kind (>= 0).
    rate : ndarray, shape (n,)
        The largest slope of the ``random`` walk (>= 0).
    lower, upper : ndarray, shape (n,)
        The bounds the ``random`` walk is clipped to (may be infinite).
    onset : float, default 0.0
        The time the signal starts at (``zero`` and ``table`` ignore it).
    seed : int, default 0
        The seed of the random kinds' stream (:class:`lpvest.core.Stream`).
    table_times : ndarray, shape (m,) or None, default None
        The ``table`` kind's strictly increasing times; ``None`` for other kinds.
    table_values : ndarray, shape (m, n) or None, default None
        The ``table`` kind's values at ``table_times``; ``None`` for other kinds.
    """

    kind: str
    n: int
    amplitude: np.ndarray
    omega: np.ndarray
    phase: np.ndarray
    offset: np.ndarray
    decay: np.ndarray
    std: np.ndarray
    rate: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    onset: float = 0.0
    seed: int = 0
    table_times: np.ndarray | None = None
    table_values: np.ndarray | None = None

    @classmethod
    def build(
        cls,
        kind: str,
        n: int,
        *,
        amplitude: ArrayLike = 1.0,
        omega: ArrayLike = 1.0,
        phase: ArrayLike = 0.0,
        offset: ArrayLike = 0.0,
        decay: ArrayLike = 0.0,
        std: ArrayLike = 1.0,
        rate: ArrayLike = 1.0,
        lower: ArrayLike = -np.inf,
        upper: ArrayLike = np.inf,
        onset: float = 0.0,
        seed: int = 0,
        table: str | tuple[Sequence[float], Sequence[Sequence[float]]] | None = None,
        prefix: str = "",
    ) -> SignalSpec:
        """Check and assemble a specification; scalars broadcast to ``n`` components.

        ``lower``/``upper`` bound the ``random`` kind (it starts at ``offset``
        clipped into them); ``table`` is the text :func:`parse_table` reads or
        a pair ``(times, values)``.

        Parameters
        ----------
        kind : str
            One of :data:`SIGNAL_KINDS`.
        n : int
            The number of components (>= 0).
        amplitude : array_like, shape (n,) or float, default 1.0
            Amplitude of the ``sinusoid`` and ``decaying`` kinds.
        omega : array_like, shape (n,) or float, default 1.0
            Angular frequency (rad per unit of time) of those kinds.
        phase : array_like, shape (n,) or float, default 0.0
            Phase (rad) of those kinds.
        offset : array_like, shape (n,) or float, default 0.0
            The value before ``onset`` and the centre or start value (see
            :class:`SignalSpec`).
        decay : array_like, shape (n,) or float, default 0.0
            Rate of ``exp(-decay t)`` of the ``decaying`` kind.
        std : array_like, shape (n,) or float, default 1.0
            Standard deviation of the ``gaussian`` kind (>= 0).
        rate : array_like, shape (n,) or float, default 1.0
            Largest slope of the ``random`` walk (>= 0).
        lower : array_like, shape (n,) or float, default -inf
            Lower bound of the ``random`` walk (may be ``-inf``; not NaN).
        upper : array_like, shape (n,) or float, default inf
            Upper bound of the ``random`` walk (may be ``inf``; not NaN); ``lower <= upper``.
        onset : float, default 0.0
            The time the signal starts at (finite).
        seed : int, default 0
            Seed of the random kinds (a non-negative integer).
        table : str or tuple of (array_like, array_like) or None, default None
            The rows of the ``table`` kind (required for it, ignored by the
            others): text, or ``(times, values)`` of shapes ``(m,)`` and ``(m, n)``.
        prefix : str, default ""
            Put before every parameter name in error messages (how an FMU names
            the parameters).

        Returns
        -------
        SignalSpec
            The checked specification; its arrays are read-only.

        Raises
        ------
        SignalError
            A parameter is invalid; the message names it.
        """
        if kind not in SIGNAL_KINDS:
            raise SignalError(
                f"{prefix}kind = {abbreviate(kind, 30)} is not a signal kind (one of {', '.join(SIGNAL_KINDS)})"
            )
        if n < 0:
            raise SignalError(f"a signal needs n >= 0 components; found {n}")

        def vec(value: ArrayLike, label: str, *, finite: bool = True, nonneg: bool = False) -> np.ndarray:
            try:
                arr = np.array(value, dtype=float)
            except (TypeError, ValueError):
                raise SignalError(f"{prefix}{label} = {abbreviate(value, 30)} is not a number") from None
            if arr.ndim == 0:
                arr = np.full(n, float(arr))
            if arr.shape != (n,):
                raise SignalError(f"{prefix}{label} has shape {arr.shape}; expected ({n},)")
            for j in range(n):
                v = arr[j]
                if np.isnan(v) or (finite and not np.isfinite(v)):
                    raise SignalError(f"{prefix}{label}[{j + 1}] = {v} is not finite")
                if nonneg and v < 0:
                    raise SignalError(f"{prefix}{label}[{j + 1}] = {v:g} must be >= 0")
            arr.setflags(write=False)
            return arr

        lo = vec(lower, "lower", finite=False)
        hi = vec(upper, "upper", finite=False)
        for j in range(n):
            if not lo[j] <= hi[j]:
                raise SignalError(f"{prefix}lower[{j + 1}] = {lo[j]:g} exceeds {prefix}upper[{j + 1}] = {hi[j]:g}")
        onset_f = float(onset)
        if not np.isfinite(onset_f):
            raise SignalError(f"{prefix}onset = {onset} is not finite")
        if isinstance(seed, bool) or int(seed) != seed or seed < 0:
            raise SignalError(f"{prefix}seed = {seed} must be a non-negative integer")
        t_times = t_values = None
        if kind == "table":
            if table is None:
                raise SignalError(f"{prefix}table is required for kind 'table'")
            if isinstance(table, str):
                t_times, t_values = parse_table(table, n, name=f"{prefix}table")
            else:
                t_times = np.asarray(table[0], dtype=float).reshape(-1)
                t_values = np.asarray(table[1], dtype=float).reshape(t_times.size, n)
                if np.any(np.diff(t_times) <= 0) or not np.all(np.isfinite(t_values)):
                    raise SignalError(f"{prefix}table needs increasing times and finite values")
            t_times.setflags(write=False)
            t_values.setflags(write=False)
        return cls(
            kind=kind,
            n=n,
            amplitude=vec(amplitude, "amplitude"),
            omega=vec(omega, "omega"),
            phase=vec(phase, "phase"),
            offset=vec(offset, "offset"),
            decay=vec(decay, "decay"),
            std=vec(std, "std", nonneg=True),
            rate=vec(rate, "rate", nonneg=True),
            lower=lo,
            upper=hi,
            onset=onset_f,
            seed=int(seed),
            table_times=t_times,
            table_values=t_values,
        )

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-component interval that holds every value the signal can take.

        Returns
        -------
        lower, upper : ndarray, shape (n,)
            The interval's ends; infinite for a ``gaussian`` component with
            ``std > 0``, a ``random`` one with ``rate > 0`` and infinite bounds,
            or a ``decaying`` one with ``decay < 0``.
        """
        if self.kind == "zero":
            z = np.zeros(self.n)
            return z, z.copy()
        off = self.offset
        if self.kind == "constant":
            return off.copy(), off.copy()
        if self.kind in ("sinusoid", "decaying"):
            a = np.abs(self.amplitude)
            if self.kind == "decaying":
                # |exp(-decay t)| <= exp(-decay onset) for t >= onset when decay >= 0
                scale = np.where(self.decay >= 0, np.exp(-self.decay * self.onset), np.inf)
                a = np.where(a == 0, 0.0, a * scale)
            return np.minimum(off, off - a), np.maximum(off, off + a)
        if self.kind == "gaussian":
            inf = np.where(self.std > 0, np.inf, 0.0)
            return off - inf, off + inf
        if self.kind == "random":
            start = np.clip(off, self.lower, self.upper)
            moving = self.rate > 0
            return np.where(moving, self.lower, start), np.where(moving, self.upper, start)
        assert self.table_values is not None
        return self.table_values.min(axis=0), self.table_values.max(axis=0)

    def deterministic_value(self, t: float) -> np.ndarray:
        """The value at time ``t`` of a deterministic kind.

        Parameters
        ----------
        t : float
            The time.

        Returns
        -------
        value : ndarray, shape (n,)
            The signal at ``t``. For the ``gaussian`` and ``random`` kinds (not
            checked) this is not their value; use :class:`SignalGenerator`.
        """
        if self.kind == "table":
            assert self.table_times is not None and self.table_values is not None
            return np.array([np.interp(t, self.table_times, self.table_values[:, j]) for j in range(self.n)])
        if self.kind == "zero":
            return np.zeros(self.n)
        if t < self.onset or self.kind == "constant":
            return self.offset.copy()
        s = self.amplitude * np.sin(self.omega * t + self.phase)
        if self.kind == "decaying":
            s = s * np.exp(-self.decay * t)
        return self.offset + s


class SignalGenerator:
    """Produces a :class:`SignalSpec` sample by sample.

    ``start(t0)`` (re)starts at time ``t0``; :attr:`value` is the value at the
    current time; ``advance(t)`` moves to the later time ``t``.
    ``get_state``/``set_state`` save and restore everything (time, value,
    generator state), so a restored generator continues identically.

    Parameters
    ----------
    spec : SignalSpec
        The signal; the generator starts at time 0.
    """

    def __init__(self, spec: SignalSpec) -> None:
        self.spec = spec
        self.start(0.0)

    def start(self, t0: float) -> None:
        """(Re)start at time ``t0``: the random generator is seeded again from
        ``spec.seed`` and :attr:`value` set to the value at ``t0`` (the
        ``random`` kind starts at ``offset`` clipped into ``[lower, upper]``).

        Parameters
        ----------
        t0 : float
            The start time.
        """
        spec = self.spec
        self._rng = Stream(spec.seed)
        self._t = float(t0)
        if spec.kind == "random":
            self._value = np.clip(spec.offset, spec.lower, spec.upper).astype(float)
        elif spec.kind == "gaussian":
            self._value = self._gaussian()
        else:
            self._value = spec.deterministic_value(self._t)

    def _gaussian(self) -> np.ndarray:
        spec = self.spec
        if self._t < spec.onset:
            return spec.offset.copy()
        return spec.offset + spec.std * self._rng.normal(spec.n)

    @property
    def time(self) -> float:
        return self._t

    @property
    def value(self) -> np.ndarray:
        return self._value.copy()

    def advance(self, t: float) -> np.ndarray:
        """Move to time ``t`` (>= the current time) and return the new value.

        Parameters
        ----------
        t : float
            The new time; equal to the current time is allowed (a ``random``
            walk then stays, a ``gaussian`` signal draws again).

        Returns
        -------
        value : ndarray, shape (n,)
            The value at ``t`` (a copy).

        Raises
        ------
        SignalError
            ``t`` is before the current time.
        """
        spec = self.spec
        t = float(t)
        if not t >= self._t:
            raise SignalError(f"signal time must not go back: from {self._t} to {t}")
        h = t - self._t
        self._t = t
        if spec.kind == "random":
            if t >= spec.onset:
                step = spec.rate * h * (-1.0 + 2.0 * self._rng.uniform(spec.n))
                self._value = np.clip(self._value + step, spec.lower, spec.upper)
        elif spec.kind == "gaussian":
            self._value = self._gaussian()
        else:
            self._value = spec.deterministic_value(t)
        return self.value

    def get_state(self) -> dict[str, object]:
        """A copy of the whole state, for :meth:`set_state`.

        Returns
        -------
        state : dict
            ``"t"``: the current time (float), ``"value"``: the current value
            (ndarray, shape (n,)), ``"rng"``: the random stream's state
            (:attr:`lpvest.core.Stream.state`, a dict).
        """
        return {"t": self._t, "value": self._value.copy(), "rng": self._rng.state}

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state from :meth:`get_state`; the generator continues as the
        one that gave it.

        Parameters
        ----------
        state : dict
            With the keys ``"t"``, ``"value"`` and ``"rng"`` of :meth:`get_state`.

        Raises
        ------
        DimensionError
            The value does not have ``spec.n`` components.
        """
        value = np.asarray(state["value"], dtype=float)
        if value.shape != (self.spec.n,):
            raise DimensionError(f"signal state value has shape {value.shape}; expected ({self.spec.n},)")
        self._t = float(state["t"])
        self._value = value.copy()
        rng = Stream(None)
        rng.state = state["rng"]
        self._rng = rng


def sample_signal(spec: SignalSpec, times: Sequence[float] | np.ndarray) -> np.ndarray:
    """The signal at increasing ``times`` (shape ``(T,)``), as an array ``(T, n)``:
    a :class:`SignalGenerator` started at ``times[0]`` and advanced to each time.

    Parameters
    ----------
    spec : SignalSpec
        The signal.
    times : array_like, shape (T,)
        Non-decreasing times (flattened).

    Returns
    -------
    values : ndarray, shape (T, n)
        Row ``i`` is the signal at ``times[i]``.

    Raises
    ------
    SignalError
        The times decrease.
    """
    t = np.asarray(times, dtype=float).reshape(-1)
    out = np.empty((t.size, spec.n))
    if t.size == 0:
        return out
    gen = SignalGenerator(spec)
    gen.start(t[0])
    out[0] = gen.value
    for i in range(1, t.size):
        out[i] = gen.advance(t[i])
    return out


# ---------------------------------------------------------------------------
# signals as streaming components (the Scheduler and Source FMUs)
# ---------------------------------------------------------------------------
class SchedulerComponent(TimedComponent):
    """The scheduling signal ``p`` (and ``alpha = map(p)`` for a polytopic model),
    a timed streaming component (:mod:`lpvest.core`): the value at the
    current time, then the signal moves to ``t + h``.

    The signal must stay inside the scheduling box: a specification that can
    leave it is rejected with an error naming the parameter (``prefix``: how
    the FMU names the parameters).

    Parameters
    ----------
    signal : SignalSpec
        The scheduling signal, one component per scheduling variable; the
        output ``p`` is its value clipped to the box.
    space : SchedulingSpace
        The model's scheduling box.
    simplex_map : SimplexMap or None, default None
        The map to the simplex of a polytopic model; given, the component also
        outputs ``alpha = simplex_map(p)``.
    prefix : str, default ""
        Put before the parameter names in error messages.

    Raises
    ------
    SignalError
        The signal's number of components is not the box's, or the signal can
        leave the box (for the ``random`` kind: its ``lower``/``upper`` do not
        lie in the box).

    Examples
    --------
    >>> from lpvest import load_system
    >>> plant = load_system("peixoto-ex1").model()
    >>> sched = SchedulerComponent(SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=0.25), plant.space,
    ...                            plant.simplex_map)
    >>> sched.reset(0.0)
    >>> out = sched.step({}, dt=1.0)
    >>> out["p"], out["alpha"], sched.outputs({})["p"]
    (array([0.]), array([0.5, 0.5]), array([0.24740396]))
    """

    def __init__(
        self, signal: SignalSpec, space: SchedulingSpace, simplex_map: SimplexMap | None = None, *, prefix: str = ""
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
        ports = [Port("p", (space.dim,), "scheduling", direct=False)]
        if simplex_map is not None:
            ports.append(Port("alpha", (simplex_map.n_vertices,), "vertex weights", direct=False))
        super().__init__((), tuple(ports))

    @property
    def time(self) -> float:
        return self._gen.time

    def _reset(self) -> None:
        self._gen.start(self.t0)

    def _read(self, inputs: Mapping[str, object]) -> None:
        return None

    def _evaluate(self, sample: None) -> tuple[dict[str, np.ndarray], None]:
        p = np.clip(self._gen.value, self.space.lower, self.space.upper)
        out = {"p": p}
        if self.simplex_map is not None:
            out["alpha"] = np.asarray(self.simplex_map(p), dtype=float)
        return out, None

    def _commit(self, pending: None, t_end: float = 0.0) -> None:
        self._gen.advance(t_end)

    def get_state(self) -> dict[str, object]:
        """A copy of the whole state (that of the signal's generator).

        Returns
        -------
        state : dict
            :meth:`SignalGenerator.get_state` of the signal.
        """
        return self._gen.get_state()

    def _set_state(self, state: Mapping[str, object]) -> None:
        self._gen.set_state(dict(state))


class SourceComponent(TimedComponent):
    """Named signals (e.g. ``u`` and ``w``), each with its own specification,
    as a timed streaming component (:mod:`lpvest.core`).

    Parameters
    ----------
    signals : dict of str to SignalSpec
        The output ports' names and signals, in port order; all are advanced
        together.
    descriptions : dict of str to str or None, default None
        The output ports' descriptions by name (empty for a name left out).
    """

    def __init__(self, signals: dict[str, SignalSpec], descriptions: dict[str, str] | None = None) -> None:
        self.signals = dict(signals)
        self._gens = {name: SignalGenerator(spec) for name, spec in self.signals.items()}
        desc = descriptions or {}
        outputs = tuple(Port(name, (spec.n,), desc.get(name, ""), direct=False) for name, spec in self.signals.items())
        super().__init__((), outputs)

    @property
    def time(self) -> float:
        return next(iter(self._gens.values())).time if self._gens else self.t0

    def _reset(self) -> None:
        for gen in self._gens.values():
            gen.start(self.t0)

    def _read(self, inputs: Mapping[str, object]) -> None:
        return None

    def _evaluate(self, sample: None) -> tuple[dict[str, np.ndarray], None]:
        return {name: gen.value for name, gen in self._gens.items()}, None

    def _commit(self, pending: None, t_end: float = 0.0) -> None:
        for gen in self._gens.values():
            gen.advance(t_end)

    def get_state(self) -> dict[str, object]:
        """A copy of the whole state (that of every signal's generator).

        Returns
        -------
        state : dict of str to dict
            Signal name to its :meth:`SignalGenerator.get_state`.
        """
        return {name: gen.get_state() for name, gen in self._gens.items()}

    def _set_state(self, state: Mapping[str, object]) -> None:
        for name, gen in self._gens.items():  # each value: its generator's state (a mapping)
            gen.set_state(dict(cast("Mapping[str, object]", state[name])))
