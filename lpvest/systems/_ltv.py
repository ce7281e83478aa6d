"""Continuous-time SISO linear time-varying systems (002_54d0f33f85fddffe.txt).

- :class:`LTVStateSpace`: ``x' = A(t) x + B(t) u``, ``y = C(t) x``, eq. (1).
- :class:`LTVInputOutput`: ``y^(n) + sum_{i<n} a_i(t) y^(i) + sum_{i<=m} b_i(t) u^(i) = 0``,
  eq. (3) with ``a_n = 1``; :meth:`LTVInputOutput.to_state_space` realises it.

Coefficients are :class:`TimeFunction` objects: formulas of ``t`` (with exact
symbolic derivatives) or Python callables.

- :class:`LTVSolution`: the solution from an initial state, integrated
  forward (DOP853) as later times are asked for. It is the model's one
  integration: :meth:`LTVStateSpace.simulate`, the streaming
  :class:`~lpvest.systems.LTVPlant` and the plant FMU all read it.

Examples
--------
>>> io = LTVInputOutput(a=["t**2 + 1", 1], b=["-1/(t + 1000)"])
>>> ss = io.to_state_space()
>>> ss.A(2.0)
array([[ 0.,  1.],
       [-5., -1.]])
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..core._errors import ArgumentError, DimensionError, ExpressionError, ModelFileError, abbreviate
from ..core._expressions import Expression, FormulaMatrix, FormulaVector
from ..core._validation import as_vector, check_finite
from ._text import number, time_value

if TYPE_CHECKING:
    from ..core._typing import ScipyObject

__all__ = ["TimeFunction", "LTVStateSpace", "LTVInputOutput", "LTVTrajectory", "LTVSolution"]


def _of_t(expr: Expression) -> Callable[[Any], Any]:
    """The formula ``expr`` as a function of ``t`` (a number or an array of times)."""

    def f(t: Any) -> Any:
        return expr.evaluate({"t": t})

    return f


@dataclass(frozen=True, eq=False)
class TimeFunction:
    """A scalar function of time: a formula of ``t`` or a Python callable.

    Formulas carry exact derivatives; a callable may be given its derivative,
    otherwise it is differentiated by the complex step (exact to round-off for
    functions built from analytic numpy operations).

    Build one with :meth:`of` or :meth:`from_callable`.

    Parameters
    ----------
    fn : callable
        ``t -> value``, called with a float array of times.
    text : str
        How the function is written (the formula, or ``<name>`` for a callable).
    expression : Expression or None, default None
        The formula of ``t`` when there is one (it gives exact derivatives).
    _derivative : callable or None, default None
        The derivative of a callable ``fn``, when known.
    """

    fn: Callable[[np.ndarray], np.ndarray]
    text: str
    expression: Expression | None = None
    _derivative: Callable[[np.ndarray], np.ndarray] | None = None

    @classmethod
    def of(cls, value: object) -> TimeFunction:
        """A :class:`TimeFunction` from a formula (``"t**2 + 1"``), a number, a
        callable of ``t`` or a :class:`TimeFunction`.

        Parameters
        ----------
        value : str, float, int, Expression, callable or TimeFunction
            A formula of ``t``, a constant, a callable of ``t``, or a
            :class:`TimeFunction` (returned as it is).

        Returns
        -------
        TimeFunction
            The function; a callable gets no derivative (see :meth:`derivative`).

        Raises
        ------
        ExpressionError
            ``value`` is none of these (e.g. a bool), or a formula uses a name
            other than ``t``.
        """
        if isinstance(value, TimeFunction):
            return value
        if isinstance(value, Expression):
            expr = value
        elif isinstance(value, str | int | float) and not isinstance(value, bool):
            expr = Expression.parse(value, allowed=["t"])
        elif callable(value):
            name = getattr(value, "__name__", "callable")
            return cls(value, f"<{name}>")
        else:
            raise ExpressionError(f"{abbreviate(value, 30)} is neither a formula of t, a number nor a callable")
        return cls(_of_t(expr), expr.text, expr)

    @classmethod
    def from_callable(
        cls, fn: Callable, *, derivative: Callable | None = None, name: str = ""
    ) -> TimeFunction:
        """A :class:`TimeFunction` from a Python callable, with its derivative when known.

        Parameters
        ----------
        fn : callable
            ``t -> value`` for a float array of times.
        derivative : callable, optional
            ``t -> fn'(t)``; without it :meth:`derivative` uses the complex step.
        name : str, default ""
            The text of the function (default ``<fn.__name__>``).

        Returns
        -------
        TimeFunction
            The function, without a formula.
        """
        return cls(fn, name or f"<{getattr(fn, '__name__', 'callable')}>", None, derivative)

    @property
    def is_constant(self) -> bool:
        return self.expression is not None and self.expression.is_constant

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        t_arr = np.asarray(t, dtype=float)
        return np.broadcast_to(np.asarray(self.fn(t_arr), dtype=float), t_arr.shape).copy()

    def at(self, t: float) -> float:
        """The value at one time: ``float(self(t))``, without array handling for a formula.

        Parameters
        ----------
        t : float
            The time.

        Returns
        -------
        float
            The value (the same number as ``self(t)``).
        """
        if self.expression is not None:
            return float(self.expression.evaluate({"t": float(t)}))
        return float(self(t))

    def derivative(self) -> TimeFunction:
        """The time derivative as a :class:`TimeFunction`.

        Returns
        -------
        TimeFunction
            The exact symbolic derivative of a formula; for a callable, the
            given derivative, else its complex-step derivative (which raises
            :class:`~lpvest.core.ExpressionError` when called if the callable
            does not take complex times).
        """
        if self.expression is not None:
            d = self.expression.derivative("t")
            return TimeFunction(_of_t(d), d.source, d)
        if self._derivative is not None:
            return TimeFunction.from_callable(self._derivative, name=f"d/dt {self.text}")

        def complex_step(t: np.ndarray, _f=self.fn) -> np.ndarray:
            h = 1e-20
            try:
                val = np.asarray(_f(np.asarray(t, dtype=float) + 1j * h))
            except TypeError as exc:
                raise ExpressionError(
                    f"cannot differentiate {self.text}: give its derivative explicitly"
                ) from exc
            if not np.iscomplexobj(val):
                raise ExpressionError(f"cannot differentiate {self.text}: give its derivative explicitly")
            return val.imag / h

        return TimeFunction.from_callable(complex_step, name=f"d/dt {self.text}")

    def __repr__(self) -> str:
        return f"TimeFunction({self.text!r})"


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a`` (a fresh copy) made read-only: a model's arrays are shared by whoever uses the model."""
    a.setflags(write=False)
    return a


def _input_and_x0_table(u: TimeFunction | None, x0: np.ndarray | None) -> dict[str, object]:
    """The optional ``input`` and ``x0`` entries of an LTV model's table."""
    out: dict[str, object] = {}
    if u is not None:
        out["input"] = time_value(u, "input")
    if x0 is not None:
        out["x0"] = [number(v) for v in x0]
    return out


def _input_and_x0_lines(u: TimeFunction | None, x0: np.ndarray | None) -> list[str]:
    """The optional input and initial-state lines of an LTV model's description."""
    lines = []
    if u is not None:
        lines.append(f"    input u(t) = {u.text}")
    if x0 is not None:
        lines.append(f"    x(0) = {x0.tolist()}")
    return lines


class LTVTrajectory(NamedTuple):
    """A simulated continuous-time trajectory at the sample times ``t``.

    Parameters
    ----------
    t : ndarray, shape (T,)
        Sample times.
    x : ndarray, shape (T, n)
        States ``x(t)``.
    y : ndarray, shape (T,)
        Output ``y(t)``.
    u : ndarray, shape (T,)
        Input ``u(t)``.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    u: np.ndarray


MatrixFunction = Callable[[float], np.ndarray]


def _matrix_function(spec: object, name: str) -> tuple[MatrixFunction, FormulaMatrix | None]:
    if callable(spec) and not isinstance(spec, FormulaMatrix):
        return (lambda t, _f=spec: np.asarray(_f(t), dtype=float)), None
    fm = spec if isinstance(spec, FormulaMatrix) else FormulaMatrix.parse(spec, name=name, allowed=["t"])
    return (lambda t, _m=fm: _m.evaluate({"t": np.asarray(t, dtype=float)})), fm


#: ``x' = f(t, x)``: the right-hand side of a realization for one input.
VectorField = Callable[[float, np.ndarray], np.ndarray]


@dataclass(frozen=True, eq=False)
class _Coefficients:
    """``A(t)`` and ``B(t)`` of a realization as a function of the values of a
    few scalar functions of time.

    ``functions`` are evaluated together, by one compiled expression when each
    is a formula (:class:`~lpvest.core.FormulaVector`: one evaluation
    per time instead of one per entry), and ``assemble(values)`` forms both
    matrices from their values. A model file's matrices of formulas and the
    companion form of an input-output equation each give one.
    """

    functions: tuple[TimeFunction, ...]
    assemble: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

    def evaluator(self, *extra: TimeFunction) -> Callable[[float], np.ndarray]:
        """``t -> `` the values of ``functions`` and then ``extra`` at one time ``t``."""
        fs = self.functions + extra
        exprs = [f.expression for f in fs]
        if all(e is not None for e in exprs):
            vec = FormulaVector([e for e in exprs if e is not None])  # (none is)

            def values(t: float) -> np.ndarray:
                return vec.evaluate({"t": float(t)})
        else:

            def values(t: float) -> np.ndarray:
                tt = np.asarray(float(t))
                return np.array([float(f(tt)) for f in fs])

        return values

    @classmethod
    def of_matrices(cls, A: FormulaMatrix, B: FormulaMatrix) -> _Coefficients:
        """The coefficients of matrices of formulas: their non-constant entries."""
        functions: list[TimeFunction] = []
        templates, slots = [], []
        for m in (A, B):
            base = np.zeros(m.shape)
            flat = []
            for i, row in enumerate(m.entries):
                for j, e in enumerate(row):
                    if e.is_constant:
                        base[i, j] = e.value()
                    else:
                        flat.append(i * m.shape[1] + j)
                        functions.append(TimeFunction(_of_t(e), e.text, e))
            templates.append(base)
            slots.append(np.array(flat, dtype=np.intp))
        (a0, b0), (sa, sb) = templates, slots
        na = sa.size

        def assemble(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            a, b = a0.copy(), b0.copy()
            a.flat[sa] = v[:na]
            b.flat[sb] = v[na:na + sb.size]
            return a, b

        return cls(tuple(functions), assemble)


@dataclass(frozen=True, eq=False)
class LTVStateSpace:
    """``x' = A(t) x + B(t) u``, ``y = C(t) x`` (SISO), eq. (1).

    ``A``, ``B``, ``C`` are matrices of formulas of ``t`` (lists of rows) or
    callables ``t -> array``. ``input`` (a :class:`TimeFunction`) and ``x0``
    are the default input and initial state for :meth:`simulate`.

    Parameters
    ----------
    A : sequence of sequence of formula, FormulaMatrix or callable
        ``A(t)``, shape (n, n); ``n`` is read from ``A(0)``.
    B : sequence of sequence of formula, FormulaMatrix or callable
        ``B(t)``, shape (n, 1).
    C : sequence of sequence of formula, FormulaMatrix or callable
        ``C(t)``, shape (1, n).
    input : formula, number or callable, optional
        Default input ``u(t)`` of :meth:`simulate` (default: none, zero input).
    x0 : array_like, shape (n,), optional
        Default initial state of :meth:`simulate` (default: none, zero state).
    name : str, default ""
        The model's name (a model file gives ``system/key``).
    """

    A: MatrixFunction
    B: MatrixFunction
    C: MatrixFunction
    n: int
    formulas: dict[str, FormulaMatrix | None]
    input: TimeFunction | None = None
    x0: np.ndarray | None = None
    name: str = ""
    #: A(t) and B(t) from a few scalar functions evaluated together (None: A and B are callables)
    _coefficients: _Coefficients | None = None

    def __init__(
        self,
        A: object,
        B: object,
        C: object,
        *,
        input: object | None = None,  # noqa: A002 (the paper's name)
        x0: object | None = None,
        name: str = "",
    ) -> None:
        fa, ma = _matrix_function(A, "A")
        fb, mb = _matrix_function(B, "B")
        fc, mc = _matrix_function(C, "C")
        a0 = fa(0.0)
        n = a0.shape[0]
        for label, f, shp in (("A", fa, (n, n)), ("B", fb, (n, 1)), ("C", fc, (1, n))):
            val = np.asarray(f(0.0))
            if val.shape != shp:
                raise DimensionError(f"{label}(t) has shape {val.shape}; expected {shp}")
        object.__setattr__(self, "A", fa)
        object.__setattr__(self, "B", fb)
        object.__setattr__(self, "C", fc)
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "formulas", {"A": ma, "B": mb, "C": mc})
        object.__setattr__(self, "input", None if input is None else TimeFunction.of(input))
        object.__setattr__(self, "x0", None if x0 is None else _read_only(as_vector(x0, "x0", n)))
        object.__setattr__(self, "name", name)
        plan = _Coefficients.of_matrices(ma, mb) if ma is not None and mb is not None else None
        object.__setattr__(self, "_coefficients", plan)

    @classmethod
    def _realization(
        cls, coefficients: _Coefficients, C: object, *, input: object | None,  # noqa: A002
        x0: object | None, name: str,
    ) -> LTVStateSpace:
        """A realization whose ``A(t)`` and ``B(t)`` are assembled from ``coefficients``."""
        values = coefficients.evaluator()
        assemble = coefficients.assemble

        def A(t: float) -> np.ndarray:
            return assemble(values(t))[0]

        def B(t: float) -> np.ndarray:
            return assemble(values(t))[1]

        model = cls(A, B, C, input=input, x0=x0, name=name)
        object.__setattr__(model, "_coefficients", coefficients)
        return model

    def field(self, u: TimeFunction | float) -> VectorField:
        """The right-hand side ``f(t, x) = A(t) x + B(t) u(t)`` for the input ``u``.

        The coefficients of a realization of formulas and a formula input are
        evaluated by one compiled expression per time (the same numbers as
        :attr:`A`, :attr:`B` and ``u`` give one by one).

        Parameters
        ----------
        u : TimeFunction or float
            The input: a function of time, or a constant (an input held over a step).

        Returns
        -------
        callable
            ``f(t, x)``: ``t`` a float, ``x`` of shape (n,); returns shape (n,).
        """
        plan = self._coefficients
        if plan is None:
            A, B = self.A, self.B
            if isinstance(u, TimeFunction):

                def f(t: float, x: np.ndarray) -> np.ndarray:
                    return A(t) @ x + B(t)[:, 0] * float(u(t))
            else:
                held = float(u)

                def f(t: float, x: np.ndarray) -> np.ndarray:
                    return A(t) @ x + B(t)[:, 0] * held

            return f
        assemble = plan.assemble
        if isinstance(u, TimeFunction):
            values = plan.evaluator(u)
            k = len(plan.functions)

            def f(t: float, x: np.ndarray) -> np.ndarray:
                v = values(t)
                a, b = assemble(v)
                return a @ x + b[:, 0] * float(v[k])
        else:
            values = plan.evaluator()
            held = float(u)

            def f(t: float, x: np.ndarray) -> np.ndarray:
                a, b = assemble(values(t))
                return a @ x + b[:, 0] * held

        return f

    def solution(
        self, t0: float, x0: object, *, u: TimeFunction | float, rtol: float = 1e-12, atol: float = 1e-14
    ) -> LTVSolution:
        """The solution from ``x(t0) = x0`` under the input ``u`` (:class:`LTVSolution`).

        Parameters
        ----------
        t0 : float
            Initial time.
        x0 : array_like, shape (n,)
            State at ``t0``.
        u : TimeFunction or float
            The input: a function of time, or a constant.
        rtol : float, default 1e-12
            Relative tolerance of the integrator.
        atol : float, default 1e-14
            Absolute tolerance of the integrator.

        Returns
        -------
        LTVSolution
            ``x(t)`` for ``t >= t0``, integrated as later times are asked for.
        """
        return LTVSolution(self, t0, x0, u=u, rtol=rtol, atol=atol)

    def simulate(
        self,
        t: object,
        *,
        u: object | None = None,
        x0: object | None = None,
        rtol: float = 1e-12,
        atol: float = 1e-14,
    ) -> LTVTrajectory:
        """Integrate with scipy's DOP853 at tight tolerances.

        Parameters
        ----------
        t : array_like, shape (T,)
            Increasing sample times; integration starts at ``t[0]``.
        u : formula, number or callable, optional
            Input ``u(t)`` (default: the model's ``input``, else zero).
        x0 : array_like, shape (n,), optional
            State at ``t[0]`` (default: the model's ``x0``, else zero).
        rtol : float, default 1e-12
            Relative tolerance of the integrator.
        atol : float, default 1e-14
            Absolute tolerance of the integrator.

        Returns
        -------
        LTVTrajectory
            ``t``, the states, ``y = C(t) x`` and ``u(t)`` at the sample times.

        Raises
        ------
        DimensionError
            ``t`` has fewer than two samples or is not strictly increasing.
        ExpressionError
            The integration fails.
        """
        from scipy.integrate import solve_ivp

        times = as_vector(t, "t")
        if times.size < 2 or np.any(np.diff(times) <= 0):
            raise DimensionError("t must hold at least two strictly increasing sample times")
        uf = TimeFunction.of(u) if u is not None else (self.input or TimeFunction.of(0.0))
        x_init = as_vector(x0, "x0", self.n) if x0 is not None else (
            self.x0 if self.x0 is not None else np.zeros(self.n)
        )

        sol = solve_ivp(
            self.field(uf), (times[0], times[-1]), x_init, method="DOP853", t_eval=times, rtol=rtol, atol=atol
        )
        if not sol.success:
            raise ExpressionError(f"integration failed: {sol.message}")
        X = sol.y.T
        Y = np.einsum("trc,tc->t", np.stack([self.C(tt) for tt in times]), X)
        U = uf(times)
        check_finite(X, "simulated state")
        return LTVTrajectory(times, X, Y, U)


    # -- text forms ---------------------------------------------------------------------
    def to_toml(self) -> dict[str, object]:
        """This model as the ``[models.KEY]`` table of a model file (:mod:`lpvest.systems`).

        Returns
        -------
        dict of str to object
            ``type = "ltv-ss"``, ``A``, ``B`` and ``C`` as rows of numbers and
            formula text and, when set, ``input`` and ``x0``.

        Raises
        ------
        ModelFileError
            A matrix or the input is a Python callable.
        """
        out: dict[str, object] = {"type": "ltv-ss"}
        for n in ("A", "B", "C"):
            fm = self.formulas[n]
            if fm is None:
                raise ModelFileError(f"{n}(t) is a Python callable and cannot be written to a model file")
            out[n] = fm.to_list()
        return out | _input_and_x0_table(self.input, self.x0)

    def describe(self, key: str) -> list[str]:
        """Lines for a person (``lpvest systems show``).

        Parameters
        ----------
        key : str
            The model's key in its model file, named in the first line.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        lines = [f"  model {key}: continuous-time LTV state space, n = {self.n}"]
        for name, fm in self.formulas.items():
            lines.append(f"    {name}(t) = {fm.to_list() if fm is not None else '<callable>'}")
        return lines + _input_and_x0_lines(self.input, self.x0)


class LTVSolution:
    """``x(t)`` of ``x' = A(t) x + B(t) u(t)``, ``x(t0) = x0``, for ``t >= t0``:
    one DOP853 integration (:class:`scipy.integrate.DOP853`) advanced as later
    times are asked for and kept between them.

    ``x(t)`` is the end point of the step that reaches ``t`` when ``t`` is one,
    else that step's dense output (DOP853's 7th-order interpolant, accurate to
    the integrator's tolerance). The integration has no end time, so its steps
    do not depend on the times asked for: ``x(t)`` is a function of ``t0``,
    ``x0``, ``u``, ``rtol``, ``atol`` and ``t`` alone, the same whichever other
    times were asked for before (a 1 ms and a 0.1 s communication step read the
    same trajectory). A step of the integrator typically spans many
    communication steps (Sridhar et al.'s plant at ``rtol = 1e-12``: ~27 ms),
    so a communication step mostly costs one interpolation.

    Every :attr:`RESTART` steps the integration starts anew from the end point
    of its last step, the new :attr:`anchor`. A solution started from a saved
    anchor (``model.solution(*anchor, ...)``) therefore reaches any later time
    in at most :attr:`RESTART` steps and gives the same numbers, bit for bit:
    this is how a plant restores a saved state.

    Times must not decrease: a time before the current step of the integration
    is refused.

    Parameters
    ----------
    model : LTVStateSpace
        The system.
    t0 : float
        Initial time.
    x0 : array_like, shape (n,)
        State at ``t0``.
    u : TimeFunction or float
        The input: a function of time, or a constant.
    rtol : float, default 1e-12
        Relative tolerance of the integrator.
    atol : float, default 1e-14
        Absolute tolerance of the integrator.

    Examples
    --------
    >>> io = LTVInputOutput(a=[1.0, 0.0], b=[0.0], x0=[0.0, 1.0])  # y'' + y = 0: y = sin t
    >>> sol = io.to_state_space().solution(0.0, [0.0, 1.0], u=0.0)
    >>> bool(abs(sol(1.0)[0] - np.sin(1.0)) < 1e-10), bool(abs(sol(2.5)[0] - np.sin(2.5)) < 1e-10)
    (True, True)
    """

    #: steps between two restarts of the integration (the longest replay of a restore)
    RESTART = 128

    def __init__(
        self,
        model: LTVStateSpace,
        t0: float,
        x0: object,
        *,
        u: TimeFunction | float,
        rtol: float = 1e-12,
        atol: float = 1e-14,
    ) -> None:
        self.model = model
        self.u = u
        self.rtol, self.atol = float(rtol), float(atol)
        self._field = model.field(u)
        #: integrator steps taken so far, over every restart
        self.n_steps = 0
        self._restart(float(t0), as_vector(x0, "x0", model.n))

    def _restart(self, t0: float, x0: np.ndarray) -> None:
        self._anchor = (t0, x0)
        self._solver: ScipyObject = None  # created at the first step
        self._steps = 0
        self._dense: ScipyObject = None  # the dense output of the current step, once asked for

    @property
    def anchor(self) -> tuple[float, np.ndarray]:
        """``(t, x)`` where the current run of the integration started (a copy)."""
        return self._anchor[0], self._anchor[1].copy()

    @property
    def t_reached(self) -> float:
        """The end of the integration's last step (its start time before the first)."""
        return self._anchor[0] if self._solver is None else float(self._solver.t)

    def _step(self) -> None:
        from scipy.integrate import DOP853

        s = self._solver
        if s is not None and self._steps == self.RESTART:
            self._restart(float(s.t), s.y.copy())
            s = None
        if s is None:
            t0, x0 = self._anchor
            s = self._solver = DOP853(self._field, t0, x0, np.inf, rtol=self.rtol, atol=self.atol)
        with np.errstate(over="ignore", invalid="ignore"):  # a failing step says why below
            message = s.step()
        if s.status == "failed" or not np.all(np.isfinite(s.y)):
            why = message or "the state is not finite"
            raise ExpressionError(f"integration failed at t = {s.t:g}: {why}")
        self._steps += 1
        self.n_steps += 1
        self._dense = None

    def __call__(self, t: float) -> np.ndarray:
        """``x(t)``, integrating forward as far as ``t`` needs.

        Parameters
        ----------
        t : float
            A time at or after the start of the integration's current step.

        Returns
        -------
        ndarray, shape (n,)
            The state at ``t`` (a new array).

        Raises
        ------
        ArgumentError
            ``t`` lies before the integration's current step (times must not decrease).
        ExpressionError
            The integration fails (a step size below the floating-point
            resolution, or a state that is not finite).
        """
        t = float(t)
        t0, x0 = self._anchor
        if t == t0:
            return x0.copy()
        s = self._solver
        start = t0 if s is None or s.t_old is None else float(s.t_old)
        if not t > start:
            raise ArgumentError(f"t = {t!r} lies before the current integration step, which starts at {start!r}: "
                                "times must not decrease")
        while self._solver is None or self._solver.t < t:
            self._step()
        s = self._solver
        if t == s.t:
            return s.y.copy()
        if self._dense is None:
            self._dense = s.dense_output()
        return np.asarray(self._dense(t), dtype=float)


@dataclass(frozen=True, eq=False)
class LTVInputOutput:
    """The input-output equation (3) with ``a_n = 1``.

    Parameters
    ----------
    a : sequence, length n
        ``a_0(t), ..., a_{n-1}(t)`` (formulas of ``t``, numbers or callables).
    b : sequence, length m + 1 <= n
        ``b_0(t), ..., b_m(t)``.
    input : formula or callable, optional
        Default input for simulation (Sridhar: ``"120*sin(t)"``).
    x0 : array_like, shape (n,), optional
        Default initial state of the realization :meth:`to_state_space`.
    name : str, default ""
        The model's name (a model file gives ``system/key``).
    """

    a: tuple[TimeFunction, ...]
    b: tuple[TimeFunction, ...]
    input: TimeFunction | None = None
    x0: np.ndarray | None = None
    name: str = ""

    def __init__(
        self,
        a: Sequence[object],
        b: Sequence[object],
        *,
        input: object | None = None,  # noqa: A002
        x0: object | None = None,
        name: str = "",
    ) -> None:
        a_f = tuple(TimeFunction.of(v) for v in a)
        b_f = tuple(TimeFunction.of(v) for v in b)
        if len(a_f) < 1:
            raise DimensionError("a needs at least a_0 (the order n = len(a) must be >= 1)")
        if len(b_f) > len(a_f):
            raise DimensionError(
                f"b has {len(b_f)} coefficients b_0..b_{len(b_f) - 1}; the system is strictly "
                f"proper, so at most n = {len(a_f)}"
            )
        object.__setattr__(self, "a", a_f)
        object.__setattr__(self, "b", b_f)
        object.__setattr__(self, "input", None if input is None else TimeFunction.of(input))
        object.__setattr__(self, "x0", None if x0 is None else _read_only(as_vector(x0, "x0", len(a_f))))
        object.__setattr__(self, "name", name)

    @property
    def order(self) -> int:
        return len(self.a)

    def to_state_space(self) -> LTVStateSpace:
        """A state-space realization with ``x_1 = y``.

        - Input without derivatives (``b = [b_0]``), any order: phase-variable
          form ``x_k = y^(k-1)``, ``x_n' = -sum a_i x_{i+1} - b_0 u``.
        - Order 2 with ``b_1``: ``x_2 = y' + b_1 u``, so that
          ``x_1' = x_2 - b_1 u`` and
          ``x_2' = -a_0 x_1 - a_1 x_2 + (a_1 b_1 + b_1' - b_0) u``.

        Returns
        -------
        LTVStateSpace
            The realization, with this model's ``input``, ``x0`` and ``name``.

        Raises
        ------
        DimensionError
            The input has derivatives beyond these cases (``b_1`` with an order
            other than 2, or ``b_2`` and higher).
        """
        n = self.order
        a = self.a
        b = self.b + tuple(TimeFunction.of(0.0) for _ in range(max(0, 1 - len(self.b))))
        if len(b) > 2 or (len(b) == 2 and n != 2):
            raise DimensionError(
                "a state-space realization is implemented for inputs without derivatives "
                "(b = [b_0]) of any order and for order 2 with b_1"
            )

        upper = (np.arange(n - 1), np.arange(1, n))
        if len(b) == 1 or n == 1:
            functions = (*a, b[0])

            def assemble(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                m = np.zeros((n, n))
                m[upper] = 1.0
                m[n - 1, :] = -v[:n]
                col = np.zeros((n, 1))
                col[n - 1, 0] = -v[n]
                return m, col
        else:
            functions = (a[0], a[1], b[0], b[1], b[1].derivative())

            def assemble(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                a0, a1, b0, b1, db1 = v[:5]
                return np.array([[0.0, 1.0], [-a0, -a1]]), np.array([[-b1], [a1 * b1 + db1 - b0]])

        c_row = np.zeros((1, n))
        c_row[0, 0] = 1.0
        return LTVStateSpace._realization(
            _Coefficients(functions, assemble), lambda t: c_row, input=self.input, x0=self.x0, name=self.name
        )

    def simulate(self, t: object, **kwargs: object) -> LTVTrajectory:
        """Simulate through :meth:`to_state_space` (same arguments as
        :meth:`LTVStateSpace.simulate`).

        Parameters
        ----------
        t : array_like, shape (T,)
            Increasing sample times.
        **kwargs
            ``u``, ``x0``, ``rtol``, ``atol`` of :meth:`LTVStateSpace.simulate`.

        Returns
        -------
        LTVTrajectory
            The trajectory; ``x`` holds the realization's states (``x_1 = y``).
        """
        return self.to_state_space().simulate(t, **kwargs)  # type: ignore[arg-type]  # the same keywords, checked there


    # -- text forms ---------------------------------------------------------------------
    def to_toml(self) -> dict[str, object]:
        """This model as the ``[models.KEY]`` table of a model file (:mod:`lpvest.systems`).

        Returns
        -------
        dict of str to object
            ``type = "ltv-io"``, the coefficients ``a`` and ``b`` (numbers or
            formula text) and, when set, ``input`` and ``x0``.

        Raises
        ------
        ModelFileError
            A coefficient or the input is a Python callable.
        """
        out: dict[str, object] = {
            "type": "ltv-io",
            "a": [time_value(f, f"a[{i}]") for i, f in enumerate(self.a)],
            "b": [time_value(f, f"b[{i}]") for i, f in enumerate(self.b)],
        }
        return out | _input_and_x0_table(self.input, self.x0)

    def describe(self, key: str) -> list[str]:
        """Lines for a person (``lpvest systems show``): the differential equation.

        Parameters
        ----------
        key : str
            The model's key in its model file, named in the first line.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        n = self.order
        lines = [f"  model {key}: continuous-time LTV input-output, order {n}",
                 "    y^(" + str(n) + ") + " + " + ".join(f"({f.text}) y^({i})" for i, f in enumerate(self.a))
                 + " + " + " + ".join(f"({f.text}) u^({i})" for i, f in enumerate(self.b)) + " = 0"]
        return lines + _input_and_x0_lines(self.input, self.x0)
