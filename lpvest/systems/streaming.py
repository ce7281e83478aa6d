"""Plants for streaming use: one sample (or one communication step) at a time.

The classes here follow the step protocol of the estimators
(:mod:`lpvest.estimators.base`): named :class:`~lpvest.estimators.base.Port`
inputs and outputs, ``outputs(inputs)`` without state change (the values at
the current sample, direct feedthrough included), ``step(inputs)`` that returns
the same values and advances, ``reset()``, and ``get_state``/``set_state`` of
the whole state (random-generator state included). The Plant FMUs are thin
adapters over them, and a Python loop over them reproduces the batch
``simulate`` methods of the models.

- :class:`DiscretePlant` wraps a discrete-time :class:`~lpvest.systems.PolytopicLPV`,
  :class:`~lpvest.systems.AffineLPV` or causal :class:`~lpvest.systems.InnovationLPV`.
- :class:`LTVPlant` wraps a continuous-time :class:`~lpvest.systems.LTVStateSpace`
  (or :class:`~lpvest.systems.LTVInputOutput`) and integrates over each step.

Noise convention (affine and innovation models, ``noise=True``): the generator
``numpy.random.default_rng(seed)`` first draws the initial state when ``P0``
is not zero, then one vector per sample ``k = 0, 1, ...``:
``[w_k; v_k] = L z_k`` with ``L L^T = [[Q, S], [S^T, R]]`` (affine) or
``e_k = L z_k`` with ``L L^T = Omega`` (innovation), ``z_k ~ N(0, I)``. With
``P0 = 0`` this is the sequence ``AffineLPV.simulate(p, u, rng=seed)`` and
``InnovationLPV.simulate(p, u, rng=seed)`` use, so the streaming plant and the
batch simulation agree. External noise inputs (``w``, ``v``, ``e``) are added
to the drawn noise.

Examples
--------
>>> from lpvest import load_system
>>> plant = DiscretePlant(load_system("peixoto-ex1").model())
>>> [p.name for p in plant.input_ports], [p.name for p in plant.output_ports]
(['p', 'w'], ['y', 'z', 'x'])
>>> out = plant.step({"p": [0.5], "w": [1.0]})
>>> out["y"], plant.outputs({"p": [0.5], "w": [0.0]})["x"]
(array([1.]), array([1.25, 0.1 ]))
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import DimensionError, ExpressionError
from ..estimators.base import Port, input_key
from ..validation import as_matrix, as_vector, check_positive_definite, check_simplex
from .affine import AffineLPV
from .innovation import InnovationLPV
from .ltv import LTVInputOutput, LTVStateSpace, TimeFunction
from .polytopic import PolytopicLPV

__all__ = ["DiscretePlant", "LTVPlant", "plant_supports"]


def plant_supports(model: object) -> str | None:
    """``None`` when :class:`DiscretePlant` or :class:`LTVPlant` can run ``model``,
    else the reason why not."""
    if isinstance(model, PolytopicLPV | AffineLPV | LTVStateSpace | LTVInputOutput):
        if isinstance(model, LTVInputOutput):
            try:
                model.to_state_space()
            except DimensionError as exc:
                return str(exc)
        return None
    if isinstance(model, InnovationLPV):
        back, ahead = model.window
        if back or ahead:
            used = ", ".join([f"p_(t-{back})"] * bool(back) + [f"p_(t+{ahead})"] * bool(ahead))
            return (
                f"its gain uses {used}; a streaming plant knows only p_t at sample t "
                "(use a realization with a gain of p_t, e.g. (21c))"
            )
        return None
    return f"{type(model).__name__} is an input-output model with no state to stream (use a state-space realization)"


def _check(inputs: Mapping[str, Any], ports: tuple[Port, ...]) -> dict[str, np.ndarray]:
    out = {}
    for port in ports:
        if port.name not in inputs:
            raise DimensionError(f"input {port.name!r} is missing (inputs: {', '.join(p.name for p in ports)})")
        out[port.name] = as_vector(inputs[port.name], port.name, port.size)
    return out


class DiscretePlant:
    """A discrete-time LPV plant, one sample at a time (see the module docs).

    Parameters
    ----------
    model : PolytopicLPV, AffineLPV or InnovationLPV
        An innovation-form model must have a gain of ``p_t`` only.
    noise : bool, keyword-only
        Draw the model's noise inside (affine and innovation models).
    seed : int, keyword-only
        Seed of the noise generator.
    x0 : array_like, shape (n_x,), optional
        Initial state (default: the model's). For an affine model with
        ``noise=True`` and a covariance ``P0 != 0``, the mean of the initial
        state, which is drawn from ``N(x0, P0)`` first, as
        ``AffineLPV.simulate`` does.
    P0 : array_like, shape (n_x, n_x), optional
        Covariance of the initial state of an affine model (default: the
        model's ``P0``).

    Ports
    -----
    polytopic: inputs ``p`` (or ``alpha`` without a scheduling map), ``w``;
    outputs ``y``, ``z``, ``x``. Affine: inputs ``p``, ``u`` (if ``n_u > 0``),
    ``w``, ``v`` (added to the drawn noise); outputs ``y``, ``x``. Innovation:
    inputs ``p``, ``u``, ``e``; outputs ``y``, ``x``.
    """

    timed = False

    def __init__(
        self,
        model: PolytopicLPV | AffineLPV | InnovationLPV,
        *,
        noise: bool = False,
        seed: int = 0,
        x0: object | None = None,
        P0: object | None = None,
    ) -> None:
        reason = plant_supports(model)
        if reason is not None or isinstance(model, LTVStateSpace | LTVInputOutput):
            why = reason or "it is continuous-time"
            raise ExpressionError(f"cannot stream this model as a discrete-time plant: {why}")
        self.model = model
        self.noise = bool(noise)
        self.seed = int(seed)
        nx = model.nx
        self._x0 = None if x0 is None else as_vector(x0, "x0", nx)
        self._P0 = None
        if isinstance(model, AffineLPV):
            self._P0 = model.P0 if P0 is None else check_positive_definite(
                as_matrix(P0, "P0", (nx, nx)), "P0", semidefinite=True)
        elif P0 is not None:
            raise DimensionError("P0 applies to an affine model only")
        if isinstance(model, PolytopicLPV):
            if model.simplex_map is None:
                sched = Port("alpha", (model.n_vertices,), "vertex weights")
            else:
                sched = Port("p", (model.space.dim,), "scheduling")
            self._inputs = (sched, Port("w", (model.nw,), "disturbance"))
            self._outputs = (
                Port("y", (model.ny,), "measured output"),
                Port("z", (model.nz,), "signal to be estimated"),
                Port("x", (nx,), "state", direct=False),
            )
            self._chol = None
        elif isinstance(model, AffineLPV):
            ins = [Port("p", (model.n_p,), "scheduling")]
            if model.nu:
                ins.append(Port("u", (model.nu,), "input"))
            ins += [Port("w", (model.nw,), "process noise added to the drawn noise"),
                    Port("v", (model.nv,), "measurement noise added to the drawn noise")]
            self._inputs = tuple(ins)
            self._outputs = (Port("y", (model.ny,), "measured output"), Port("x", (nx,), "state", direct=False))
            self._chol = np.linalg.cholesky(model.noise.joint)
        else:
            ins = [Port("p", (model.n_p,), "scheduling")]
            if model.nu:
                ins.append(Port("u", (model.nu,), "input"))
            ins.append(Port("e", (model.ny,), "innovation added to the drawn one"))
            self._inputs = tuple(ins)
            self._outputs = (Port("y", (model.ny,), "measured output"), Port("x", (nx,), "state", direct=False))
            self._chol = np.linalg.cholesky(model.innovation_covariance)
        self._input_names = tuple(p.name for p in self._inputs)
        self.reset()

    # -- protocol -------------------------------------------------------------
    @property
    def input_ports(self) -> tuple[Port, ...]:
        return self._inputs

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return self._outputs

    def reset(self) -> None:
        """Back to sample 0: initial state, generator re-seeded, first noise drawn."""
        model = self.model
        self._rng = np.random.default_rng(self.seed)
        self._k = 0
        if isinstance(model, AffineLPV):
            mean = model.x0 if self._x0 is None else self._x0
            x = mean.copy()
            if self.noise and self._P0 is not None and np.any(self._P0):
                x = self._rng.multivariate_normal(mean, self._P0)
        elif self._x0 is not None:
            x = self._x0.copy()
        elif isinstance(model, InnovationLPV):
            x = model.x0.copy()
        else:
            x = np.zeros(model.nx)
        self._x = np.asarray(x, dtype=float)
        self._noise = self._draw()
        self._memo: tuple[Any, dict[str, np.ndarray], dict[str, np.ndarray]] | None = None

    def _draw(self) -> np.ndarray:
        """The model noise of the current sample (zeros without noise)."""
        if self._chol is None:
            return np.zeros(0)
        n = self._chol.shape[0]
        if not self.noise:
            return np.zeros(n)
        return (self._rng.standard_normal((1, n)) @ self._chol.T)[0]

    def _evaluate(self, inputs: Mapping[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Checked inputs, the outputs at the current sample and the next state."""
        model = self.model
        val = _check(inputs, self._inputs)
        x = self._x
        if isinstance(model, PolytopicLPV):
            if model.simplex_map is None:
                alpha = val["alpha"]
                check_simplex(alpha, "alpha")
            else:
                alpha = model.alpha(val["p"])
            # the batch evaluation with one row: the same operations as simulate()
            m = model.at_batch(alpha[None, :], check=False)
            m = type(m)(*(mat[0] for mat in m))
            w = val["w"]
            out = {"y": m.Cy @ x + m.Dy @ w, "z": m.Cz @ x + m.Dz @ w, "x": x.copy()}
            nxt = m.A @ x + m.Bw @ w
        elif isinstance(model, AffineLPV):
            p = model.space.check(val["p"])
            m = model.at_batch(p[None, :], check=False)
            m = type(m)(*(mat[0] for mat in m))
            u = val.get("u", np.zeros(0))
            nw = model.nw
            w = val["w"] + self._noise[:nw]
            v = val["v"] + self._noise[nw:]
            out = {"y": m.C @ x + m.D @ u + m.H @ v, "x": x.copy()}
            nxt = m.A @ x + m.B @ u + m.G @ w
        else:
            p = model.space.check(val["p"])
            mats = model.dependence.evaluate(p, check=False)
            K = model.K.evaluate(model.space.as_dict(p)).reshape(model.nx, model.ny)
            if not np.all(np.isfinite(K)):
                raise ExpressionError(f"the gain K is not finite at p = {p.tolist()}")
            u = val.get("u", np.zeros(0))
            e = val["e"] + self._noise
            out = {"y": mats["C"] @ x + mats["D"] @ u + e, "x": x.copy()}
            nxt = mats["A"] @ x + mats["B"] @ u + K @ e
        return out, {"x": nxt}

    def outputs(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """The outputs at the current sample for these inputs; no state change.

        The evaluation is kept (keyed on the inputs, :func:`~lpvest.estimators.base.input_key`)
        for a following :meth:`step` with the same inputs."""
        key = input_key(inputs, self._input_names)
        memo = self._memo
        if key is None or memo is None or memo[0] != key:
            out, nxt = self._evaluate(inputs)
            memo = self._memo = (key, out, nxt) if key is not None else None
            if memo is None:
                return out
        return {name: value.copy() for name, value in memo[1].items()}

    def step(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """The outputs at the current sample; then advance to the next one."""
        memo = self._memo
        if memo is not None and memo[0] == input_key(inputs, self._input_names):
            out, nxt = memo[1], memo[2]
        else:
            out, nxt = self._evaluate(inputs)
        self._x = nxt["x"]
        self._k += 1
        self._noise = self._draw()
        self._memo = None
        return out

    @property
    def sample(self) -> int:
        """The index ``k`` of the current sample."""
        return self._k

    def get_state(self) -> dict[str, Any]:
        return {
            "x": self._x.copy(),
            "k": self._k,
            "noise": self._noise.copy(),
            "rng": self._rng.bit_generator.state,
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        x = as_vector(state["x"], "state x", self.model.nx)
        noise = np.asarray(state["noise"], dtype=float)
        if noise.shape != self._noise.shape:
            raise DimensionError(f"state noise has shape {noise.shape}; expected {self._noise.shape}")
        rng = np.random.default_rng()
        rng.bit_generator.state = state["rng"]
        self._x, self._k, self._noise, self._rng = x.copy(), int(state["k"]), noise.copy(), rng
        self._memo = None


class LTVPlant:
    """A continuous-time SISO LTV plant integrated over each communication step.

    The state is integrated with scipy's DOP853 (``rtol``, ``atol``) from the
    current time to the end of each step, restarted at every communication
    point, so any step size is accurate to the tolerances.

    Input: with ``use_model_input=True`` (the default when the model declares an
    input, e.g. Sridhar et al.'s ``u = 120 sin t``) the plant applies that
    function of time exactly inside every step and ignores the input port; else
    the input port ``u`` is held constant over the step (zero-order hold).

    Ports: input ``u`` (1,); outputs ``y`` (1,) = ``C(t) x``, ``x`` (n,) and
    ``u_applied`` (1,), the input at the current time.
    """

    timed = True

    def __init__(
        self,
        model: LTVStateSpace | LTVInputOutput,
        *,
        use_model_input: bool | None = None,
        x0: object | None = None,
        t0: float = 0.0,
        rtol: float = 1e-12,
        atol: float = 1e-14,
    ) -> None:
        ss = model.to_state_space() if isinstance(model, LTVInputOutput) else model
        if not isinstance(ss, LTVStateSpace):
            raise ExpressionError(f"LTVPlant needs an LTV model; found {type(model).__name__}")
        self.model = ss
        if use_model_input is None:
            use_model_input = ss.input is not None
        if use_model_input and ss.input is None:
            raise ExpressionError("use_model_input=True but the model declares no input function")
        self.use_model_input = bool(use_model_input)
        self.rtol, self.atol = float(rtol), float(atol)
        if x0 is not None:
            self._x0 = as_vector(x0, "x0", ss.n)
        else:
            self._x0 = ss.x0.copy() if ss.x0 is not None else np.zeros(ss.n)
        self.t0 = float(t0)
        self._inputs = (Port("u", (1,), "input, held over the step (use_model_input = false)"),)
        self._outputs = (Port("y", (1,), "output C(t) x(t)", direct=False), Port("x", (ss.n,), "state", direct=False),
                         Port("u_applied", (1,), "input applied at the current time",
                              direct=not self.use_model_input))
        self.reset()

    @property
    def input_ports(self) -> tuple[Port, ...]:
        return self._inputs

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return self._outputs

    @property
    def time(self) -> float:
        return self._t

    def reset(self, t0: float | None = None) -> None:
        if t0 is not None:
            self.t0 = float(t0)
        self._t = self.t0
        self._x = self._x0.copy()

    def _input(self, val: dict[str, np.ndarray]) -> TimeFunction | float:
        if self.use_model_input:
            assert self.model.input is not None
            return self.model.input
        return float(val["u"][0])

    def outputs(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        val = _check(inputs, self._inputs)
        u = self._input(val)
        u_now = float(u(self._t)) if isinstance(u, TimeFunction) else u
        y = self.model.C(self._t) @ self._x
        return {"y": np.asarray(y, dtype=float).reshape(1), "x": self._x.copy(), "u_applied": np.array([u_now])}

    def step(self, inputs: Mapping[str, Any], *, dt: float, t_end: float | None = None) -> dict[str, np.ndarray]:
        """The outputs at the current time; then integrate over ``dt > 0`` (to
        ``t_end`` when given: the master's communication point, free of the
        round-off of summed steps)."""
        from scipy.integrate import solve_ivp

        out = self.outputs(inputs)
        dt = float(dt)
        if not dt > 0 or not np.isfinite(dt):
            raise DimensionError(f"the step size must be positive and finite; found {dt}")
        u = self._input(_check(inputs, self._inputs))
        A, B = self.model.A, self.model.B
        if isinstance(u, TimeFunction):

            def rhs(t: float, x: np.ndarray) -> np.ndarray:
                return A(t) @ x + B(t)[:, 0] * float(u(t))
        else:

            def rhs(t: float, x: np.ndarray) -> np.ndarray:
                return A(t) @ x + B(t)[:, 0] * u

        t1 = self._t + dt if t_end is None else float(t_end)
        sol = solve_ivp(rhs, (self._t, t1), self._x, method="DOP853", rtol=self.rtol, atol=self.atol)
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            raise ExpressionError(f"integration from t = {self._t:g} to {t1:g} failed: {sol.message}")
        self._x = sol.y[:, -1].copy()
        self._t = t1
        return out

    def get_state(self) -> dict[str, Any]:
        return {"t": self._t, "x": self._x.copy()}

    def set_state(self, state: Mapping[str, Any]) -> None:
        self._x = as_vector(state["x"], "state x", self.model.n).copy()
        self._t = float(state["t"])
