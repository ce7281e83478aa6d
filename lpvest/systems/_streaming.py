"""Plants for streaming use: one sample (or one communication step) at a time.

The classes here are streaming components (:mod:`lpvest.core`): named
:class:`~lpvest.core.Port` inputs and outputs, ``outputs(inputs)``
without state change (the values at the current sample, direct feedthrough
included), ``step(inputs)`` that returns the same values and advances,
``reset()``, and ``get_state``/``set_state`` of the whole state
(random-generator state included). The Plant FMUs are thin adapters over them.
Each sample is the model's own pure step (:meth:`PolytopicLPV.step`,
:meth:`AffineLPV.step`, :func:`~lpvest.systems._innovation.innovation_step`),
the one the batch ``simulate`` methods loop over: a Python loop over a plant
reproduces ``simulate`` to the bit (with the noise drawn one sample at a time).

- :class:`DiscretePlant` wraps a discrete-time :class:`~lpvest.systems.PolytopicLPV`,
  :class:`~lpvest.systems.AffineLPV`, causal :class:`~lpvest.systems.InnovationLPV`
  or :class:`~lpvest.systems.LPVInputOutput` (its memory of past ``y``, ``u``,
  ``e`` as the state).
- :class:`LTVPlant` wraps a continuous-time :class:`~lpvest.systems.LTVStateSpace`
  (or :class:`~lpvest.systems.LTVInputOutput`) and integrates over each step.

Noise convention (affine and innovation models, ``noise=True``): the stream
``lpvest.core.Stream(seed)`` (the same numbers in the native FMUs) first draws
the initial state when ``P0`` is not zero (``x0 + L_0 z``, ``L_0`` the
semidefinite Cholesky factor of ``P0``), then one vector per sample
``k = 0, 1, ...``: ``[w_k; v_k] = L z_k`` with ``L L^T = [[Q, S], [S^T, R]]``
(affine) or ``e_k = L z_k`` with ``L L^T = Omega`` (innovation; input-output:
``L = sqrt(noise_variance)``),
``z_k ~ N(0, I)`` (:meth:`lpvest.core.Stream.correlated`). With
``P0 = 0`` this is the sequence ``AffineLPV.simulate(p, u, rng=seed)``,
``InnovationLPV.simulate(p, u, rng=seed)`` and ``LPVInputOutput.simulate`` use, so the streaming plant and the
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

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..core._errors import DimensionError, ExpressionError
from ..core._protocol import Component, Port, TimedComponent
from ..core._rng import Stream
from ..core._validation import as_matrix, as_vector, check_positive_definite, check_simplex
from ._affine import AffineLPV
from ._innovation import InnovationLPV, LPVInputOutput, innovation_step
from ._ltv import LTVInputOutput, LTVSolution, LTVStateSpace, TimeFunction
from ._polytopic import PolytopicLPV

__all__ = ["DiscretePlant", "LTVPlant", "plant_supports"]


class _Rules:
    """How :class:`DiscretePlant` streams one kind of discrete-time model: its
    ports, its noise, its initial state and one sample (the model's own step)."""

    def __init__(self, model: Any) -> None:
        self.model = model

    def unsupported(self) -> str | None:
        """Why the model cannot be streamed, or ``None``."""
        return None

    def ports(self) -> tuple[list[Port], list[Port]]:
        raise NotImplementedError

    def noise_factor(self) -> np.ndarray | None:
        """``L`` with ``L L^T`` the covariance of the noise drawn per sample."""
        return None

    def initial_state(self, x0: np.ndarray | None, P0: np.ndarray | None, noise: bool,
                      rng: Stream) -> np.ndarray:
        return np.zeros(self.model.nx) if x0 is None else x0.copy()

    def check(self, val: dict[str, np.ndarray]) -> None:
        """Range checks of a sample (``val`` gains derived values): ``p`` in
        its box, then :meth:`derive`."""
        space = self.model.space
        if space is not None:  # None: a polytopic model scheduled by alpha itself
            space.check(val["p"])
        self.derive(val)

    def derive(self, val: dict[str, np.ndarray]) -> None:
        """:meth:`check` for a sample checked at the boundary (``p`` in its box):
        only the derived values and the checks the boundary cannot make."""

    def evaluate(self, x: np.ndarray, val: dict[str, np.ndarray], noise: np.ndarray,
                 no_u: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        raise NotImplementedError


def _scheduling_and_input(model: Any) -> list[Port]:
    ins = [Port("p", (model.n_p,), "scheduling")]
    if model.nu:
        ins.append(Port("u", (model.nu,), "input"))
    return ins


class _PolytopicRules(_Rules):
    model: PolytopicLPV

    def ports(self) -> tuple[list[Port], list[Port]]:
        m = self.model
        if m.simplex_map is None:
            sched = Port("alpha", (m.n_vertices,), "vertex weights")
        else:
            sched = Port("p", (m.simplex_map.space.dim,), "scheduling")
        ins = [sched] + ([Port("u", (m.nu,), "known input")] if m.known_input is not None else [])
        return (ins + [Port("w", (m.nw,), "disturbance")],
                [Port("y", (m.ny,), "measured output"), Port("z", (m.nz,), "signal to be estimated")])

    def derive(self, val: dict[str, np.ndarray]) -> None:
        if self.model.simplex_map is None:
            check_simplex(val["alpha"], "alpha")  # each weight in [0, 1] does not make a sum of 1
        else:
            val["alpha"] = self.model.simplex_map(val["p"])

    def evaluate(self, x: np.ndarray, val: dict[str, np.ndarray], noise: np.ndarray,
                 no_u: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        y, z, nxt = self.model.step(x, val["alpha"], val["w"], val.get("u"))
        return {"y": y, "z": z, "x": x.copy()}, nxt


class _AffineRules(_Rules):
    model: AffineLPV

    def ports(self) -> tuple[list[Port], list[Port]]:
        m = self.model
        ins = _scheduling_and_input(m) + [Port("w", (m.nw,), "process noise added to the drawn noise"),
                                          Port("v", (m.nv,), "measurement noise added to the drawn noise")]
        return ins, [Port("y", (m.ny,), "measured output")]

    def noise_factor(self) -> np.ndarray:
        return np.linalg.cholesky(self.model.noise.joint)

    def initial_state(self, x0: np.ndarray | None, P0: np.ndarray | None, noise: bool,
                      rng: Stream) -> np.ndarray:
        mean = self.model.x0 if x0 is None else x0
        if noise and P0 is not None and np.any(P0):
            return rng.gaussian_vector(mean, P0)
        return mean.copy()

    def evaluate(self, x: np.ndarray, val: dict[str, np.ndarray], noise: np.ndarray,
                 no_u: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        m = self.model
        nw = m.nw
        y, nxt = m.step(x, m.dependence.psi(val["p"], check=False), val.get("u", no_u),
                        val["w"] + noise[:nw], val["v"] + noise[nw:])
        return {"y": y, "x": x.copy()}, nxt


class _InnovationRules(_Rules):
    model: InnovationLPV

    def unsupported(self) -> str | None:
        back, ahead = self.model.window
        if back or ahead:
            used = ", ".join([f"p_(t-{back})"] * bool(back) + [f"p_(t+{ahead})"] * bool(ahead))
            return (
                f"its gain uses {used}; a streaming plant knows only p_t at sample t "
                "(use a realization with a gain of p_t, e.g. (21c))"
            )
        return None

    def ports(self) -> tuple[list[Port], list[Port]]:
        m = self.model
        ins = _scheduling_and_input(m) + [Port("e", (m.ny,), "innovation added to the drawn one")]
        return ins, [Port("y", (m.ny,), "measured output")]

    def noise_factor(self) -> np.ndarray:
        return np.linalg.cholesky(self.model.innovation_covariance)

    def initial_state(self, x0: np.ndarray | None, P0: np.ndarray | None, noise: bool,
                      rng: Stream) -> np.ndarray:
        return (self.model.x0 if x0 is None else x0).copy()

    def evaluate(self, x: np.ndarray, val: dict[str, np.ndarray], noise: np.ndarray,
                 no_u: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        m = self.model
        p = val["p"]
        K = m.K.evaluate(m.space.as_dict(p)).reshape(m.nx, m.ny)
        if not np.all(np.isfinite(K)):
            raise ExpressionError(f"the gain K is not finite at p = {p.tolist()}")
        y, nxt = innovation_step(m.dependence.evaluate(p, check=False), K, x, val.get("u", no_u), val["e"] + noise)
        return {"y": y, "x": x.copy()}, nxt


class _InputOutputRules(_Rules):
    """An input-output model ``y_t = e_t + sum a_i y_(t-1-i) + sum b_i u_(t-i)
    + sum c_i e_(t-1-i)`` streamed with its memory as the state: ``x_t`` =
    ``[y_(t-1), ..., y_(t-na), u_(t-1), ..., u_(t-nb+1), e_(t-1), ..., e_(t-nc)]``
    (zero: from rest, as :meth:`LPVInputOutput.simulate`)."""

    model: LPVInputOutput

    def ports(self) -> tuple[list[Port], list[Port]]:
        m = self.model
        ins = [Port("p", (m.n_p,), "scheduling")] + ([Port("u", (1,), "input")] if m.nu else [])
        return ins + [Port("e", (1,), "noise added to the drawn one")], [Port("y", (1,), "measured output")]

    def noise_factor(self) -> np.ndarray:
        return np.linalg.cholesky(np.array([[self.model.noise_variance]]))

    def evaluate(self, x: np.ndarray, val: dict[str, np.ndarray], noise: np.ndarray,
                 no_u: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        m = self.model
        p = val["p"]
        vals = m.space.as_dict(p)
        a, b, c = ([float(f.evaluate(vals)) for f in fs] for fs in (m.y_coefficients, m.u_coefficients,
                                                                      m.e_coefficients))
        if not all(math.isfinite(v) for v in (*a, *b, *c)):
            raise ExpressionError(f"the coefficients are not finite at p = {p.tolist()}")
        na, nb = len(a), len(b)
        ys, us, es = x[:na], x[na:na + max(nb - 1, 0)], x[na + max(nb - 1, 0):]
        u = float(val["u"][0]) if nb else 0.0
        e = float(val["e"][0] + noise[0])
        # the order of LPVInputOutput.simulate: e_t, then the y, u and e terms
        acc = e
        for i in range(na):
            acc += a[i] * ys[i]
        if nb:
            acc += b[0] * u
        for i in range(1, nb):
            acc += b[i] * us[i - 1]
        for i in range(len(c)):
            acc += c[i] * es[i]
        # shift each memory by one: the newest value first
        nxt = np.array([*([acc, *ys[:-1]] if na else []), *([u, *us[:-1]] if nb > 1 else []),
                        *([e, *es[:-1]] if c else [])], dtype=float)
        return {"y": np.array([acc]), "x": x.copy()}, nxt


#: The discrete-time model classes a DiscretePlant streams, and how.
_RULES: dict[type, type[_Rules]] = {
    PolytopicLPV: _PolytopicRules,
    AffineLPV: _AffineRules,
    InnovationLPV: _InnovationRules,
    LPVInputOutput: _InputOutputRules,
}


def _rules_for(model: object) -> _Rules | None:
    for cls in type(model).__mro__:
        if cls in _RULES:
            return _RULES[cls](model)
    return None


def plant_supports(model: object) -> str | None:
    """``None`` when :class:`DiscretePlant` or :class:`LTVPlant` can run ``model``,
    else the reason why not.

    Parameters
    ----------
    model : object
        A model of :mod:`lpvest.systems`.

    Returns
    -------
    str or None
        ``None``, or why neither plant streams ``model`` (e.g. an innovation
        form whose gain uses shifted scheduling).
    """
    rules = _rules_for(model)
    if rules is not None:
        return rules.unsupported()
    to_state_space = getattr(model, "to_state_space", None)
    if isinstance(model, LTVStateSpace) or to_state_space is not None:
        try:
            if to_state_space is not None:
                to_state_space()
        except DimensionError as exc:
            return str(exc)
        return None
    return f"{type(model).__name__} is no model a streaming plant runs"


class DiscretePlant(Component):
    """A discrete-time LPV plant, one sample at a time (see the module docs).

    Parameters
    ----------
    model : PolytopicLPV, AffineLPV, InnovationLPV or LPVInputOutput
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
    inputs ``p``, ``u``, ``e``; outputs ``y``, ``x``. Input-output: inputs
    ``p``, ``u`` (with input coefficients), ``e``; outputs ``y``, ``x`` (the
    memory ``[y_(t-1..t-na), u_(t-1..t-nb+1), e_(t-1..t-nc)]``, zero at rest).
    """

    def __init__(
        self,
        model: PolytopicLPV | AffineLPV | InnovationLPV | LPVInputOutput,
        *,
        noise: bool = False,
        seed: int = 0,
        x0: object | None = None,
        P0: object | None = None,
    ) -> None:
        rules = _rules_for(model)
        reason = plant_supports(model) if rules is None else rules.unsupported()
        if rules is None or reason is not None:
            why = reason or "it is continuous-time"
            raise ExpressionError(f"cannot stream this model as a discrete-time plant: {why}")
        self.model = model
        self._rules = rules
        self.noise = bool(noise)
        self.seed = int(seed)
        nx = model.nx
        self._x0 = None if x0 is None else as_vector(x0, "x0", nx)
        self._P0 = None
        if isinstance(model, AffineLPV):  # its initial state is drawn from N(x0, P0)
            self._P0 = model.P0 if P0 is None else check_positive_definite(
                as_matrix(P0, "P0", (nx, nx)), "P0", semidefinite=True)
        elif P0 is not None:
            raise DimensionError("P0 applies to an affine model only")
        ins, outs = rules.ports()
        self._chol = rules.noise_factor()
        self._sizes = tuple((p.name, p.size) for p in ins)
        self._no_u = np.zeros(0)
        super().__init__(tuple(ins), (*outs, Port("x", (nx,), "state", direct=False)))

    # -- the protocol -----------------------------------------------------------------
    def _reset(self) -> None:
        """Back to sample 0: initial state, generator re-seeded, first noise drawn."""
        self._rng = Stream(self.seed)
        self._k = 0
        self._x = np.asarray(self._rules.initial_state(self._x0, self._P0, self.noise, self._rng), dtype=float)
        self._noise = self._draw()

    def _draw(self) -> np.ndarray:
        """The model noise of the current sample (zeros without noise)."""
        if self._chol is None:
            return np.zeros(0)
        n = self._chol.shape[0]
        if not self.noise:
            return np.zeros(n)
        return self._rng.correlated(self._chol, 1)[0]

    def _read(self, inputs: Mapping[str, object]) -> dict[str, np.ndarray]:
        val = {}
        for name, size in self._sizes:
            if name not in inputs:
                raise DimensionError(f"input {name!r} is missing (inputs: {', '.join(self._in_names)})")
            val[name] = as_vector(inputs[name], name, size)
        self._rules.check(val)
        return val

    def _read_checked(self, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """:meth:`_read` of inputs checked at the boundary (:meth:`Component._read_checked`)."""
        val = {name: inputs[name] for name, _ in self._sizes}
        self._rules.derive(val)
        return val

    def _evaluate(self, val: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """The outputs at the current sample and the next state: the model's step."""
        return self._rules.evaluate(self._x, val, self._noise, self._no_u)

    def _commit(self, nxt: np.ndarray) -> None:
        self._x = nxt
        self._k += 1
        self._noise = self._draw()

    @property
    def sample(self) -> int:
        """The index ``k`` of the current sample."""
        return self._k

    def get_state(self) -> dict[str, object]:
        """A copy of the whole state, for :meth:`set_state`.

        Returns
        -------
        state : dict of str to object
            ``"x"``: the state (ndarray, shape (n_x,)), ``"k"``: the sample
            index (int), ``"noise"``: the model noise drawn for the current
            sample (ndarray), ``"rng"``: the stream's state (:attr:`lpvest.core.Stream.state`)
            (dict).
        """
        return {
            "x": self._x.copy(),
            "k": self._k,
            "noise": self._noise.copy(),
            "rng": self._rng.state,
        }

    def _set_state(self, state: Mapping[str, Any]) -> None:
        x = as_vector(state["x"], "state x", self.model.nx)
        noise = np.asarray(state["noise"], dtype=float)
        if noise.shape != self._noise.shape:
            raise DimensionError(f"state noise has shape {noise.shape}; expected {self._noise.shape}")
        rng = Stream(None)
        rng.state = state["rng"]
        self._x, self._k, self._noise, self._rng = x.copy(), int(state["k"]), noise.copy(), rng


class LTVPlant(TimedComponent):
    """A continuous-time SISO LTV plant integrated over each communication step.

    The state follows the model's :class:`~lpvest.systems.LTVSolution`:
    one DOP853 integration (``rtol``, ``atol``) kept from step to step, whose
    own steps do not depend on the communication points (a 1 ms step mostly
    costs one interpolation of the integrator's dense output), so any step
    size reads the same trajectory, accurate to the tolerances. A new
    integration starts where the applied input changes: at a step whose held
    input ``u`` differs from the last one (``use_model_input=False``), and
    after :meth:`set_state` of a state this plant did not reach itself. A
    saved state restores exactly (:meth:`get_state` records where the
    integration last started; the restored plant replays at most
    :attr:`~lpvest.systems.LTVSolution.RESTART` integrator steps from
    there).

    Input: with ``use_model_input=True`` (the default when the model declares an
    input, e.g. Sridhar et al.'s ``u = 120 sin t``) the plant applies that
    function of time exactly inside every step and ignores the input port; else
    the input port ``u`` is held constant over the step (zero-order hold).

    Ports: input ``u`` (1,); outputs ``y`` (1,) = ``C(t) x``, ``x`` (n,) and
    ``u_applied`` (1,), the input at the current time.

    Parameters
    ----------
    model : LTVStateSpace or LTVInputOutput
        The plant; an input-output model is realized by
        :meth:`~lpvest.systems.LTVInputOutput.to_state_space`.
    use_model_input : bool, optional
        Apply the model's input function rather than the port ``u`` (default:
        when the model declares one; ``True`` needs one).
    x0 : array_like, shape (n,), optional
        Initial state (default: the model's ``x0``, else zero).
    t0 : float, default 0.0
        Initial time.
    rtol : float, default 1e-12
        Relative tolerance of the integrator.
    atol : float, default 1e-14
        Absolute tolerance of the integrator.
    """

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
        inputs = (Port("u", (1,), "input, held over the step (use_model_input = false)"),)
        outputs = (Port("y", (1,), "output C(t) x(t)", direct=False), Port("x", (ss.n,), "state", direct=False),
                   Port("u_applied", (1,), "input applied at the current time", direct=not self.use_model_input))
        super().__init__(inputs, outputs, t0)

    @property
    def time(self) -> float:
        return self._t

    def _reset(self) -> None:
        self._t = self.t0
        self._x = self._x0.copy()
        self._solution: LTVSolution | None = None

    def _read(self, inputs: Mapping[str, object]) -> TimeFunction | float:
        if "u" not in inputs:
            raise DimensionError("input 'u' is missing (inputs: u)")
        u = float(as_vector(inputs["u"], "u", 1)[0])
        if self.use_model_input:
            assert self.model.input is not None
            return self.model.input
        return u

    def _evaluate(self, u: TimeFunction | float) -> tuple[dict[str, np.ndarray], TimeFunction | float]:
        u_now = u.at(self._t) if isinstance(u, TimeFunction) else u
        y = self.model.C(self._t) @ self._x
        return {"y": np.asarray(y, dtype=float).reshape(1), "x": self._x.copy(), "u_applied": np.array([u_now])}, u

    def _follows(self, u: TimeFunction | float) -> bool:
        """Whether the current integration applies ``u`` (the same function, or the same held value to the bit)."""
        sol = self._solution
        if sol is None:
            return False
        if isinstance(u, TimeFunction) or isinstance(sol.u, TimeFunction):
            return sol.u is u
        return float(sol.u).hex() == float(u).hex()

    def _commit(self, u: TimeFunction | float, t_end: float = 0.0) -> None:
        """Advance to ``t_end`` (the master's communication point) on the model's solution."""
        if not self._follows(u):
            self._solution = self.model.solution(self._t, self._x, u=u, rtol=self.rtol, atol=self.atol)
        assert self._solution is not None
        self._x = self._solution(t_end)
        self._t = t_end

    def get_state(self) -> dict[str, object]:
        """A copy of the whole state, for :meth:`set_state`.

        Returns
        -------
        state : dict of str to object
            ``"t"``: the current time (float), ``"x"``: the state (ndarray,
            shape (n,)); and, once the plant has stepped, where its integration
            last started: ``"anchor_t"`` (float), ``"anchor_x"`` (ndarray,
            shape (n,)) and ``"anchor_u"``, the held input it applies (float;
            NaN for the model's input function).
        """
        state: dict[str, object] = {"t": self._t, "x": self._x.copy()}
        sol = self._solution
        if sol is not None:
            t_a, x_a = sol.anchor
            state.update(anchor_t=t_a, anchor_x=x_a,
                         anchor_u=float("nan") if isinstance(sol.u, TimeFunction) else float(sol.u))
        return state

    def _set_state(self, state: Mapping[str, Any]) -> None:
        self._x = as_vector(state["x"], "state x", self.model.n).copy()
        self._t = float(state["t"])
        self._solution = None
        if "anchor_t" not in state:
            return  # the next step integrates from (t, x)
        u: TimeFunction | float
        if self.use_model_input:
            assert self.model.input is not None
            u = self.model.input
        else:
            u = float(state["anchor_u"])
            if not np.isfinite(u):
                return
        t_a = float(state["anchor_t"])
        x_a = as_vector(state["anchor_x"], "state anchor_x", self.model.n)
        if not t_a <= self._t:
            raise DimensionError(f"state anchor_t = {t_a!r} lies after the state's time t = {self._t!r}")
        sol = self.model.solution(t_a, x_a, u=u, rtol=self.rtol, atol=self.atol)
        # the same integration as the plant that saved the state: replay it, unless
        # the state is not on it (then the next step starts a new one at (t, x))
        if np.array_equal(sol(self._t), self._x):
            self._solution = sol
