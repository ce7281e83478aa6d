"""LPV models in innovation form with a given gain, and LPV input-output models.

:class:`InnovationLPV` is (4a)-(4b) of 000_dc6273d4fec795cd.txt with the gain
given rather than computed::

    x_{t+1} = A(p_t) x_t + B(p_t) u_t + K_t e_t,   y_t = C(p_t) x_t + D(p_t) u_t + e_t,

with ``e_t ~ N(0, Omega)``. The same ``e`` drives state and output, so it does
not fit :class:`~lpvest.systems.AffineLPV` (its joint covariance would be
singular). ``K_t`` is a matrix of formulas that may depend rationally on
shifted scheduling values, as in realization (21b) where
``K_t = (1 - p_{t+1}) / p_{t+1}``; a constant ``K`` gives (21c).

:class:`LPVInputOutput` is the SISO difference equation (21a)::

    y_t = sum_{i>=1} a_i(p_t) y_{t-i} + sum_{i>=0} b_i(p_t) u_{t-i} + e_t + sum_{i>=1} c_i(p_t) e_{t-i}.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core._errors import DimensionError, ExpressionError, NumericalError, abbreviate, shorten
from ..core._expressions import Expression, FormulaMatrix, shift_name
from ..core._rng import as_stream
from ..core._scheduling import SchedulingSpace
from ..core._validation import as_matrix, as_signal, as_vector, check_positive_definite
from ._affine import AffineDependence
from ._text import dependence_table, describe_dependence, format_matrix, formula_value, matrix_table, number

__all__ = [
    "InnovationLPV",
    "LPVInputOutput",
    "InnovationTrajectory",
    "scheduling_window",
    "innovation_step",
    "innovation_inverse_step",
]


class InnovationTrajectory(NamedTuple):
    """A simulated trajectory; row ``t`` holds time ``t``.

    Parameters
    ----------
    x : ndarray, shape (T, n_x)
        States ``x_t`` (shape (T, 0) for input-output models).
    y : ndarray, shape (T, n_y)
        Outputs ``y_t``.
    e : ndarray, shape (T, n_y)
        Innovations ``e_t``.
    """

    x: np.ndarray
    y: np.ndarray
    e: np.ndarray


def scheduling_window(shifts: dict[str, set[int]]) -> tuple[int, int]:
    """``(lookback, lookahead)``: how many scheduling samples before ``t`` and
    after ``t`` a set of formulas needs.

    Parameters
    ----------
    shifts : dict of str to set of int
        For each variable, the time shifts ``k`` it is used with (``p_{t+k}``;
        ``FormulaMatrix.shifts``).

    Returns
    -------
    lookback : int
        ``max(0, -min k)`` (0 when no shift is negative).
    lookahead : int
        ``max(0, max k)`` (0 when no shift is positive).
    """
    ks = [k for s in shifts.values() for k in s] or [0]
    return max(0, -min(ks)), max(0, max(ks))


def innovation_step(
    m: Mapping[str, np.ndarray], K: np.ndarray, x: np.ndarray, u: np.ndarray, e: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One sample of the innovation form (4a)-(4b), a pure function:
    ``(y_t, x_{t+1})`` with ``y_t = C x_t + D u_t + e_t`` and
    ``x_{t+1} = A x_t + B u_t + K_t e_t`` (``m``: the matrices ``A, B, C, D`` at
    ``p_t``; ``K``: the gain ``K_t``).

    The one place the recursion is written: :meth:`InnovationLPV.simulate`,
    the streaming plant, the Plant FMU and the Kalman filter's innovation-form
    simulation call it.

    Parameters
    ----------
    m : mapping of str to ndarray
        ``A`` (n_x, n_x), ``B`` (n_x, n_u), ``C`` (n_y, n_x) and ``D`` (n_y, n_u) at ``p_t``.
    K : ndarray, shape (n_x, n_y)
        The gain ``K_t``.
    x : ndarray, shape (n_x,)
        The state ``x_t``.
    u : ndarray, shape (n_u,)
        The input ``u_t``.
    e : ndarray, shape (n_y,)
        The innovation ``e_t``.

    Returns
    -------
    y : ndarray, shape (n_y,)
        The output ``y_t``.
    x_next : ndarray, shape (n_x,)
        The next state ``x_{t+1}``.
    """
    return m["C"] @ x + m["D"] @ u + e, m["A"] @ x + m["B"] @ u + K @ e


def innovation_inverse_step(
    m: Mapping[str, np.ndarray], K: np.ndarray, x: np.ndarray, u: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The innovation form run on data, a pure function: ``(e_t, x_{t+1})`` with
    ``e_t = y_t - C x_t - D u_t`` and ``x_{t+1} = A x_t + B u_t + K_t e_t``
    (the same recursion as :func:`innovation_step`, solved for ``e_t``).

    Parameters
    ----------
    m : mapping of str to ndarray
        ``A`` (n_x, n_x), ``B`` (n_x, n_u), ``C`` (n_y, n_x) and ``D`` (n_y, n_u) at ``p_t``.
    K : ndarray, shape (n_x, n_y)
        The gain ``K_t``.
    x : ndarray, shape (n_x,)
        The state ``x_t``.
    u : ndarray, shape (n_u,)
        The input ``u_t``.
    y : ndarray, shape (n_y,)
        The measured output ``y_t``.

    Returns
    -------
    e : ndarray, shape (n_y,)
        The innovation ``e_t``.
    x_next : ndarray, shape (n_x,)
        The next state ``x_{t+1}``.
    """
    e = y - m["C"] @ x - m["D"] @ u
    return e, m["A"] @ x + m["B"] @ u + K @ e


def _window_values(space: SchedulingSpace, p: np.ndarray, lookback: int, T: int) -> dict:
    """Values of every (shifted) scheduling name along ``t = 0..T-1``; ``p`` holds
    ``lookback`` samples before ``t = 0``."""
    vals = {}
    for j, n in enumerate(space.names):
        for k in range(-lookback, p.shape[0] - lookback - T + 1):
            seg = p[lookback + k : lookback + k + T, j]
            vals[n if k == 0 else shift_name(n, k)] = seg
    return vals


@dataclass(frozen=True, eq=False)
class InnovationLPV:
    """LPV state-space model in innovation form with a given gain formula.

    Parameters
    ----------
    dependence : AffineDependence
        ``A, B, C, D`` affine in basis functions of ``p_t``.
    K : FormulaMatrix, shape (n_x, n_y)
        The gain; its formulas may use ``shift(p, k)`` for ``p_{t+k}``.
    innovation_covariance : array_like, shape (n_y, n_y)
        ``Omega``, positive definite.
    x0 : array_like, shape (n_x,), optional
        Initial state (default zero).
    name : str, default ""
        The model's name (a model file gives ``system/key``).
    """

    dependence: AffineDependence
    K: FormulaMatrix
    innovation_covariance: np.ndarray
    x0: np.ndarray
    name: str = ""

    def __init__(
        self,
        dependence: AffineDependence,
        K: FormulaMatrix,
        innovation_covariance: object,
        x0: object | None = None,
        name: str = "",
    ) -> None:
        for n in ("A", "B", "C", "D"):
            if n not in dependence.coefficients:
                raise DimensionError(f"InnovationLPV needs matrix {n}")
        nx = dependence.shape("A")[0]
        ny = dependence.shape("C")[0]
        nu = dependence.shape("B")[1]
        expected = {"A": (nx, nx), "B": (nx, nu), "C": (ny, nx), "D": (ny, nu)}
        for n, shp in expected.items():
            if dependence.shape(n) != shp:
                raise DimensionError(f"{n} has shape {dependence.shape(n)}; expected {shp}")
        if K.shape != (nx, ny):
            raise DimensionError(f"K has shape {K.shape}; expected ({nx}, {ny})")
        unknown = set(K.shifts) - set(dependence.space.names)
        if unknown:
            raise ExpressionError(f"K uses unknown name {abbreviate(sorted(unknown)[0], 30)}")
        omega = check_positive_definite(
            as_matrix(innovation_covariance, "innovation covariance", (ny, ny)),
            "innovation covariance",
        )
        x0v = np.zeros(nx) if x0 is None else as_vector(x0, "x0", nx)
        for m in (omega, x0v):  # fresh copies, shared by whoever uses the model: read-only
            m.setflags(write=False)
        object.__setattr__(self, "dependence", dependence)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "innovation_covariance", omega)
        object.__setattr__(self, "x0", x0v)
        object.__setattr__(self, "name", name)

    @property
    def space(self) -> SchedulingSpace:
        return self.dependence.space

    @property
    def nx(self) -> int:
        return self.dependence.shape("A")[0]

    @property
    def nu(self) -> int:
        return self.dependence.shape("B")[1]

    @property
    def ny(self) -> int:
        return self.dependence.shape("C")[0]

    @property
    def n_p(self) -> int:
        return self.space.dim

    @property
    def window(self) -> tuple[int, int]:
        """``(lookback, lookahead)`` scheduling samples the gain needs."""
        return scheduling_window(self.K.shifts)

    def simulate(
        self,
        p: object,
        u: object | None = None,
        *,
        e: object | None = None,
        x0: object | None = None,
        rng: np.random.Generator | int | None = None,
    ) -> InnovationTrajectory:
        """Simulate for ``T`` steps.

        Parameters
        ----------
        p : array_like, shape (lookback + T + lookahead, n_p)
            Scheduling trajectory, with the samples the gain needs before
            ``t = 0`` and after ``t = T - 1`` (see :attr:`window`; for (21b)
            one extra sample at the end). Every sample is range-checked.
        u : array_like, shape (T, n_u), optional
            Input (zero when omitted).
        e : array_like, shape (T, n_y), optional
            Innovations; drawn from ``N(0, Omega)`` with ``rng`` when omitted.
        x0 : array_like, shape (n_x,), optional
            Initial state (default: the model's ``x0``).
        rng : numpy.random.Generator or int, optional
            Random source (or its seed) for the innovations; not used when
            ``e`` is given. ``None``: fresh entropy.

        Returns
        -------
        InnovationTrajectory
            The states, outputs and innovations at ``t = 0..T-1``.
        """
        back, ahead = self.window
        p = as_signal(p, "p", self.n_p)
        T = p.shape[0] - back - ahead
        if T < 1:
            raise DimensionError(
                f"p has {p.shape[0]} samples; the gain needs {back} before and {ahead} after "
                "the simulated steps"
            )
        for t in range(p.shape[0]):
            self.space.check(p[t], what=f"scheduling value at sample {t}:")
        u = as_signal(u if u is not None else np.zeros((T, self.nu)), "u", self.nu, T)
        if e is None:
            L = np.linalg.cholesky(self.innovation_covariance)
            e = as_stream(rng).correlated(L, T)
        else:
            e = as_signal(e, "e", self.ny, T)
        m, K = self._along(p, T)
        x = self.x0 if x0 is None else as_vector(x0, "x0", self.nx)
        X = np.empty((T, self.nx))
        Y = np.empty((T, self.ny))
        for t in range(T):
            X[t] = x
            Y[t], x = innovation_step({k: v[t] for k, v in m.items()}, K[t], x, u[t], e[t])
        return InnovationTrajectory(X, Y, np.asarray(e))

    def innovations(self, p: object, u: object | None, y: object) -> np.ndarray:
        """The innovations ``e_t`` that give the outputs ``y`` (T, n_y) from
        ``x_0 = x0`` (:func:`innovation_inverse_step`); ``p`` as in :meth:`simulate`.

        Parameters
        ----------
        p : array_like, shape (lookback + T + lookahead, n_p)
            Scheduling trajectory with the gain's window (shape and finiteness
            checked; the range is not).
        u : array_like, shape (T, n_u) or None
            Input (``None``: zero).
        y : array_like, shape (T, n_y)
            The measured outputs.

        Returns
        -------
        e : ndarray, shape (T, n_y)
            The innovations ``e_t``.
        """
        back, ahead = self.window
        p = as_signal(p, "p", self.n_p)
        y = np.asarray(y, dtype=float)
        T = y.shape[0]
        y = as_signal(y, "y", self.ny, T)
        if p.shape[0] != back + T + ahead:
            raise DimensionError(f"p has {p.shape[0]} samples; {T} outputs need {back + T + ahead}")
        u = as_signal(u if u is not None else np.zeros((T, self.nu)), "u", self.nu, T)
        m, K = self._along(p, T)
        x = self.x0.copy()
        e = np.empty_like(y)
        for t in range(T):
            e[t], x = innovation_inverse_step({k: v[t] for k, v in m.items()}, K[t], x, u[t], y[t])
        return e

    def _along(self, p: np.ndarray, T: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """The matrices and the gain along ``t = 0..T-1`` (``p`` with its window)."""
        back = self.window[0]
        m = self.dependence.evaluate_batch(p[back : back + T], check=False)
        K = self.K.evaluate(_window_values(self.space, p, back, T))
        K = np.broadcast_to(K, (T, self.nx, self.ny))
        if not np.all(np.isfinite(K)):
            t, i, j = (int(v) for v in np.argwhere(~np.isfinite(K))[0])
            at = ", ".join(f"{n} = {float(v)!r}" for n, v in zip(self.space.names, p[back + t], strict=True))
            raise NumericalError(
                f"the gain K is not finite at t={t} (K[{i + 1},{j + 1}] = {abbreviate(self.K.entries[i][j].text)}, "
                f"scheduling {shorten(at, 80)}): the realization is not defined there"
            )
        return m, K


    # -- text forms ---------------------------------------------------------------------
    def to_toml(self) -> dict[str, object]:
        """This model as the ``[models.KEY]`` table of a model file (:mod:`lpvest.systems`).

        Returns
        -------
        dict of str to object
            ``type = "innovation"``, the basis and matrices
            (:func:`~lpvest.systems._affine.dependence_table`), ``K`` (numbers
            and formula text), ``innovation_covariance`` and ``x0``.
        """
        out: dict[str, object] = {"type": "innovation", **dependence_table(self.dependence)}
        out["K"] = self.K.to_list()
        out["innovation_covariance"] = matrix_table(self.innovation_covariance)
        out["x0"] = [number(v) for v in self.x0]
        return out

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
        back, ahead = self.window
        lines = [f"  model {key}: LPV innovation form with given gain",
                 f"    n_x={self.nx} n_u={self.nu} n_y={self.ny}; gain uses p_(t-{back})..p_(t+{ahead})"]
        lines += describe_dependence(self.dependence)
        lines += ["    K = " + str(self.K.to_list()), "    innovation covariance",
                  format_matrix(self.innovation_covariance)]
        return lines


@dataclass(frozen=True, eq=False)
class LPVInputOutput:
    """SISO LPV input-output (ARMAX-type) model with scheduling-dependent
    coefficients, e.g. (21a): ``y = ["-p"]``, ``u = [0, "p"]``, ``e = [1]``.

    Parameters
    ----------
    space : SchedulingSpace
        The box of scheduling vectors ``p``; the coefficients are formulas of
        its component names at time ``t`` (no shifts).
    y_coefficients : sequence of formula
        ``a_1, a_2, ...``: coefficients of ``y_{t-1}, y_{t-2}, ...``.
    u_coefficients : sequence of formula
        ``b_0, b_1, ...``: coefficients of ``u_t, u_{t-1}, ...``.
    e_coefficients : sequence of formula, optional
        ``c_1, c_2, ...``: coefficients of ``e_{t-1}, ...`` (``e_t`` has 1;
        default none).
    noise_variance : float, default 1.0
        Variance of the white noise ``e_t`` (positive).
    name : str, default ""
        The model's name (a model file gives ``system/key``).
    """

    space: SchedulingSpace
    y_coefficients: tuple[Expression, ...]
    u_coefficients: tuple[Expression, ...]
    e_coefficients: tuple[Expression, ...]
    noise_variance: float
    name: str = ""

    def __init__(
        self,
        space: SchedulingSpace,
        y_coefficients: Sequence[str | float | Expression],
        u_coefficients: Sequence[str | float | Expression],
        e_coefficients: Sequence[str | float | Expression] = (),
        noise_variance: float = 1.0,
        name: str = "",
    ) -> None:
        def parse(seq: Sequence, label: str) -> tuple[Expression, ...]:
            out = []
            for i, c in enumerate(seq):
                ex = c if isinstance(c, Expression) else Expression.parse(c, allowed=space.names)
                if any(k != 0 for ks in ex.shifts.values() for k in ks):
                    raise ExpressionError(f"{label}[{i}] = {abbreviate(ex.text)}: coefficients depend on p_t only")
                out.append(ex)
            return tuple(out)

        var = float(noise_variance)
        if not var > 0 or not np.isfinite(var):
            raise ExpressionError(f"noise_variance must be positive; found {noise_variance}")
        object.__setattr__(self, "space", space)
        object.__setattr__(self, "y_coefficients", parse(y_coefficients, "y"))
        object.__setattr__(self, "u_coefficients", parse(u_coefficients, "u"))
        object.__setattr__(self, "e_coefficients", parse(e_coefficients, "e"))
        object.__setattr__(self, "noise_variance", var)
        object.__setattr__(self, "name", name)

    @property
    def n_p(self) -> int:
        """Number of scheduling components."""
        return self.space.dim

    @property
    def nu(self) -> int:
        """1 when the model has input coefficients, else 0 (SISO)."""
        return 1 if self.u_coefficients else 0

    @property
    def ny(self) -> int:
        """1 (SISO)."""
        return 1

    @property
    def nx(self) -> int:
        """The memory a streaming realization keeps
        (:class:`lpvest.systems.DiscretePlant`): the past outputs
        ``y_(t-1..t-na)``, inputs ``u_(t-1..t-nb+1)`` and noise
        ``e_(t-1..t-nc)``, ``na + max(nb - 1, 0) + nc`` values."""
        return len(self.y_coefficients) + max(len(self.u_coefficients) - 1, 0) + len(self.e_coefficients)

    def simulate(
        self,
        p: object,
        u: object,
        *,
        e: object | None = None,
        rng: np.random.Generator | int | None = None,
    ) -> InnovationTrajectory:
        """Simulate from rest (all signals zero before ``t = 0``).

        ``p`` (T, n_p), ``u`` (T,) or (T, 1), ``e`` (T,) or (T, 1) (drawn from
        ``N(0, noise_variance)`` with ``rng`` when omitted).

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            Scheduling trajectory (every sample range-checked).
        u : array_like, shape (T,) or (T, 1)
            Input ``u_t``.
        e : array_like, shape (T,) or (T, 1), optional
            Noise ``e_t``.
        rng : numpy.random.Generator or int, optional
            Random source (or its seed) for ``e``; not used when ``e`` is
            given. ``None``: fresh entropy.

        Returns
        -------
        InnovationTrajectory
            ``x`` of shape (T, 0) (no state), ``y`` and ``e`` of shape (T, 1).
        """
        p = as_signal(p, "p", self.space.dim)
        T = p.shape[0]
        for t in range(T):
            self.space.check(p[t], what=f"scheduling value at t={t}:")
        u = as_signal(u, "u", 1, T)[:, 0]
        ev: np.ndarray = (as_stream(rng).normal(T) * np.sqrt(self.noise_variance) if e is None
                          else as_signal(e, "e", 1, T)[:, 0])
        vals = self.space.as_dict(p)

        def coeffs(seq: tuple[Expression, ...]) -> np.ndarray:
            return np.array([np.broadcast_to(c.evaluate(vals), (T,)) for c in seq]).reshape(len(seq), T)

        a, b, c = coeffs(self.y_coefficients), coeffs(self.u_coefficients), coeffs(self.e_coefficients)
        y = np.zeros(T)
        for t in range(T):
            acc = ev[t]
            for i in range(a.shape[0]):
                if t - 1 - i >= 0:
                    acc += a[i, t] * y[t - 1 - i]
            for i in range(b.shape[0]):
                if t - i >= 0:
                    acc += b[i, t] * u[t - i]
            for i in range(c.shape[0]):
                if t - 1 - i >= 0:
                    acc += c[i, t] * ev[t - 1 - i]
            y[t] = acc
        return InnovationTrajectory(np.zeros((T, 0)), y[:, None], ev[:, None])


    # -- text forms ---------------------------------------------------------------------
    def to_toml(self) -> dict[str, object]:
        """This model as the ``[models.KEY]`` table of a model file (:mod:`lpvest.systems`).

        Returns
        -------
        dict of str to object
            ``type = "lpv-io"``, the coefficient lists ``y``, ``u`` and ``e``
            (numbers or formula text) and ``noise_variance``.
        """
        return {
            "type": "lpv-io",
            "y": [formula_value(c) for c in self.y_coefficients],
            "u": [formula_value(c) for c in self.u_coefficients],
            "e": [formula_value(c) for c in self.e_coefficients],
            "noise_variance": self.noise_variance,
        }

    def describe(self, key: str) -> list[str]:
        """Lines for a person (``lpvest systems show``): the difference equation.

        Parameters
        ----------
        key : str
            The model's key in its model file, named in the first line.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        terms = [f"({c.text}) y[t-{i + 1}]" for i, c in enumerate(self.y_coefficients)]
        terms += [f"({c.text}) u[t-{i}]" for i, c in enumerate(self.u_coefficients)]
        terms += ["e[t]"] + [f"({c.text}) e[t-{i + 1}]" for i, c in enumerate(self.e_coefficients)]
        return [f"  model {key}: LPV input-output (SISO)", "    y[t] = " + " + ".join(terms),
                f"    noise variance {self.noise_variance:g}"]
