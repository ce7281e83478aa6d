"""The H-infinity filter (2) of Peixoto et al. running on streaming data.

::

    x_{f,k+1} = H(alpha_k)^{-1} (A_f(alpha_k) x_{f,k} + B_f(alpha_k) y_k)
    z_{f,k}   = C_f(alpha_k) x_{f,k} + D_f(alpha_k) y_k

(001_00f62b5a0c49ad87.txt, eq. (2)) with the matrices of a
:class:`~lpvest.design.HinfDesign`; ``H(alpha)^{-1}`` is applied by a
linear solve. ``z_{f,k}`` uses ``y_k`` (direct feedthrough), so
:meth:`HinfFilter.outputs` reports it at sample ``k`` before the state advances.
Only numpy is imported: this module runs inside the filter FMU.

Ports (the FMU variables ``name[1]..name[n]``):

============  =====================  =========================================
port          shape                  when
============  =====================  =========================================
``alpha``     (N,)  input            parameter-dependent filter, default
``p``         (n_p,) input           parameter-dependent filter built with the
                                     plant's simplex map (physical scheduling,
                                     range-checked, mapped to ``alpha``)
``y``         (n_y,) input           always
``zhat``      (n_z,) output          ``z_{f,k}``, the estimate of ``z_k``
``xf``        (n_x,) output          the filter state ``x_{f,k}`` (in the
                                     design's coordinates)
============  =====================  =========================================

A robust filter (Corollary 1) has constant matrices and no scheduling input.

Known inputs
------------
Peixoto et al.'s plant (1) has no known input. For a plant with one
(:class:`~lpvest.systems.PolytopicLPV` with ``Bu``, ``Dzu``, ``Dyu``)
the filter runs, next to (2), a copy of the plant driven by ``u`` alone and
feeds (2) with the measurement minus that copy's output::

    x_{u,k+1} = A(alpha_k) x_{u,k} + Bu(alpha_k) u_k                     (x_{u,0} = 0)
    y~_k      = y_k - Cy(alpha_k) x_{u,k} - Dyu(alpha_k) u_k
    (2) on y~: x_{f,k+1} = H^-1 (Af x_{f,k} + Bf y~_k),  z_{f,k} = Cf x_{f,k} + Df y~_k
    zhat_k    = Cz(alpha_k) x_{u,k} + Dzu(alpha_k) u_k + z_{f,k}

**Proposition.** For every parameter sequence ``alpha_k`` on the simplex,
every input ``u`` and disturbance ``w``, the estimation error
``e_k = z_k - zhat_k`` equals the error of filter (2) on the plant without
input, (1), driven by the same ``w`` from ``x_0``; so ``e`` does not depend on
``u``, and a design certified by Theorem 1 (or Corollary 1) for (1) gives
``||e||_2 < gamma ||w||_2`` (``x_0 = 0``) for the plant with input too.

*Proof.* The plant is linear in ``(x_0, u, w)`` for a fixed ``alpha``
sequence, so ``x = x_u + x_w`` with ``x_w`` the state of (1) driven by ``w``
from ``x_0`` and ``x_u`` the state driven by ``u`` from zero, which is the
filter's copy. Then ``y~ = Cy x_w + Dy w`` is exactly the output of (1),
``z - Cz x_u - Dzu u = Cz x_w + Dz w`` its ``z``, and ``e = z_w - z_f``
is the error of (2) on (1). The LMIs involve only ``A, Bw, Cz, Dz, Cy, Dy``
(no condition on the input matrices is needed). QED

The copy runs open loop, so it needs ``A(alpha)`` stable, which the LMIs
imply (:func:`lpvest.design._program.instability`). It needs ``alpha``, so a
robust filter for a plant whose input path depends on ``alpha`` takes the
scheduling input as well; its gains stay constant. ``test_hinf_filter.py``
checks ``e`` with and without ``u`` to rounding and the certified gamma on
the worst-case-gain oracle.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from ..core._errors import ArgumentTypeError, DimensionError, NumericalError
from ..core._linalg import MatrixStack
from ..core._protocol import Component, Port
from ..core._validation import as_signal, as_vector, check_simplex
from ..design._result import FilterMatrices, HinfDesign
from ..systems._polytopic import POLYTOPIC_INPUT_MATRICES, PolytopicLPV, SimplexMap

__all__ = ["HinfFilter", "HinfStep", "HinfRun", "hinf_step", "hinf_filter_batch", "needs_scheduling"]


class HinfStep(NamedTuple):
    """One step of filter (2).

    Parameters
    ----------
    zhat : ndarray, shape (n_z,)
        ``z_{f,k}``.
    xf_next : ndarray, shape (n_x,)
        ``x_{f,k+1}``.
    """

    zhat: np.ndarray
    xf_next: np.ndarray


class HinfRun(NamedTuple):
    """Filter (2) over a whole record; row ``k`` is sample ``k``.

    Parameters
    ----------
    zhat : ndarray, shape (T, n_z)
        ``z_{f,k}``, the estimates of ``z_k``.
    xf : ndarray, shape (T, n_x)
        ``x_{f,k}`` (before the update with ``y_k``).
    """

    zhat: np.ndarray
    xf: np.ndarray


def hinf_step(design: HinfDesign, xf: np.ndarray, alpha: np.ndarray | None, y: np.ndarray) -> HinfStep:
    """One step of (2) for validated inputs: ``alpha`` on the simplex (ignored
    by a robust design), ``y`` of shape (n_y,), ``xf`` of shape (n_x,).

    Raises :class:`~lpvest.core.NumericalError` if ``H(alpha)`` is singular
    (it cannot be for a certified design: ``H + H^T > P_2 > 0``).

    Parameters
    ----------
    design : HinfDesign
        The filter design (its matrices at ``alpha``).
    xf : ndarray, shape (n_x,)
        Filter state ``x_{f,k}``.
    alpha : ndarray, shape (N,), or None
        Scheduling weights ``alpha_k`` on the unit simplex; None (or ignored)
        for a robust design.
    y : ndarray, shape (n_y,)
        Measurement ``y_k``.

    Returns
    -------
    HinfStep
        ``z_{f,k}`` and ``x_{f,k+1}``.

    Raises
    ------
    NumericalError
        ``H(alpha)`` is singular, or the new state is not finite.
    """
    return _step_with(design.matrices_at(alpha), xf, alpha, y)


def _step_with(
    m: FilterMatrices, xf: np.ndarray, alpha: np.ndarray | None, y: np.ndarray, zhat: np.ndarray | None = None
) -> HinfStep:
    """:func:`hinf_step` with the matrices at ``alpha`` (and ``zhat``) already evaluated."""
    if zhat is None:
        zhat = m.Cf @ xf + m.Df @ y
    try:
        nxt = np.linalg.solve(m.H, m.Af @ xf + m.Bf @ y)
    except np.linalg.LinAlgError as exc:
        raise NumericalError(f"H(alpha) is singular at alpha = {alpha}: {exc}") from exc
    if not np.all(np.isfinite(nxt)):
        raise NumericalError(f"the filter state became non-finite at alpha = {alpha}")
    return HinfStep(zhat, nxt)


def hinf_filter_batch(
    design: HinfDesign,
    y: object,
    alpha: object | None = None,
    *,
    xf0: object | None = None,
    plant: PolytopicLPV | None = None,
    u: object | None = None,
) -> HinfRun:
    """Run filter (2) over a record ``y`` (T, n_y) with ``alpha`` (T, N)
    (``None`` for a robust design), from ``xf0`` (default zero); with the
    ``plant`` and its known input ``u``, the response to ``u`` is compensated
    exactly as :class:`HinfFilter` does (same numbers to the bit).

    Parameters
    ----------
    design : HinfDesign
        The filter design.
    y : array_like, shape (T, n_y)
        Measurements ``y_k``.
    alpha : array_like, shape (T, N), optional
        Scheduling weights, each row on the unit simplex (checked); required
        by a parameter-dependent design, or when the plant's response to ``u``
        varies with ``alpha`` (:func:`needs_scheduling`); otherwise ignored.
    xf0 : array_like, shape (n_x,), optional
        Initial filter state ``x_{f,0}`` (default zero).
    plant : PolytopicLPV, optional
        The plant of the design, when it has a known input (module
        documentation: the filter runs the plant's response to ``u`` beside
        (2), so that its error does not depend on ``u``).
    u : array_like, shape (T, n_u), optional
        The known input; required with a ``plant`` that has one.

    Returns
    -------
    HinfRun
        ``z^_k`` (``z_{f,k}`` plus, with a known input, the response to ``u``)
        and ``x_{f,k}`` for every sample.

    Raises
    ------
    DimensionError
        Wrong shapes, ``alpha`` missing where it is needed, ``u`` missing for a
        plant with a known input or given without one.
    ArgumentTypeError
        ``plant`` is not a PolytopicLPV, or not the design's plant.
    SchedulingRangeError
        A row of ``alpha`` is not on the simplex.
    NumericalError
        ``H(alpha_k)`` is singular, or the state becomes non-finite.

    Examples
    --------
    >>> import numpy as np, lpvest
    >>> from lpvest.design import design_hinf
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> d = design_hinf(plant, epsilon=150.0, kind="robust")
    >>> run = hinf_filter_batch(d, np.ones((5, 1)))
    >>> run.zhat.shape
    (5, 2)
    """
    yy = as_signal(y, "y", design.ny)
    T = yy.shape[0]
    plant = _input_plant(design, plant)
    if plant is None and u is not None:
        raise DimensionError("u is the known input of a plant: pass the plant too (plant=...), "
                             "or leave u out for a plant without one")
    uu = None
    if plant is not None:
        if u is None:
            raise DimensionError(f"plant {plant.name or '(unnamed)'} has a known input: pass u of shape ({T}, "
                                 f"{plant.nu})")
        uu = as_signal(u, "u", plant.nu, T)
    aa = None
    if needs_scheduling(design, plant):
        if alpha is None:
            raise DimensionError(f"a {design.kind} filter needs alpha of shape ({T}, {design.n_vertices})")
        aa = as_signal(alpha, "alpha", design.n_vertices, T)
        for k in range(T):
            check_simplex(aa[k], f"alpha at k={k}")
    x = np.zeros(design.nx) if xf0 is None else as_vector(xf0, "xf0", design.nx)
    Z = np.empty((T, design.nz))
    X = np.empty((T, design.nx))
    gains = aa if design.scheduled else None
    path = None if plant is None else _InputPath(plant, design.n_vertices)
    xu = np.zeros(0 if plant is None else plant.nx)
    for k in range(T):
        X[k] = x
        g = None if gains is None else gains[k]
        if path is None:
            Z[k], x = hinf_step(design, x, g, yy[k])
        else:
            assert uu is not None  # a plant with a known input was given u (checked above)
            a = path.at(None if aa is None else aa[k])
            z_f, x = hinf_step(design, x, g, path.without_input(a, xu, uu[k], yy[k]))
            Z[k] = path.estimate(a, xu, uu[k], z_f)
            xu = path.next_state(a, xu, uu[k])
    return HinfRun(Z, X)


def _input_plant(design: HinfDesign, plant: object) -> PolytopicLPV | None:
    """``plant`` checked against ``design``; None when it has no known input."""
    if plant is None:
        return None
    if not isinstance(plant, PolytopicLPV):
        raise ArgumentTypeError(f"plant must be a PolytopicLPV; found {type(plant).__name__}")
    design.check_model(plant, source=f"{design.kind} design")
    return plant if plant.known_input is not None else None


class _InputPath:
    """The plant matrices of the filter's copy of the response to a known input
    (only those it needs), evaluated once when they do not depend on alpha."""

    def __init__(self, plant: PolytopicLPV, n_vertices: int) -> None:
        stacks = plant.vertex_stacks()
        self._stack = MatrixStack({n: stacks[n] for n in _U_PATH})
        self._fixed = None if plant.input_path_varies() else self._stack.at(np.eye(1, n_vertices)[0])

    def at(self, alpha: np.ndarray | None) -> dict[str, np.ndarray]:
        if self._fixed is not None:
            return self._fixed
        assert alpha is not None  # the path varies: the filter is scheduled (needs_scheduling)
        return self._stack.at(alpha)

    @staticmethod
    def without_input(a: Mapping[str, np.ndarray], xu: np.ndarray, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The measurement of the plant without input: ``y - Cy x_u - Dyu u``."""
        return y - a["Cy"] @ xu - a["Dyu"] @ u

    @staticmethod
    def estimate(a: Mapping[str, np.ndarray], xu: np.ndarray, u: np.ndarray, z_f: np.ndarray) -> np.ndarray:
        """``z^ = Cz x_u + Dzu u + z_f``: the response to ``u`` added back."""
        return a["Cz"] @ xu + a["Dzu"] @ u + z_f

    @staticmethod
    def next_state(a: Mapping[str, np.ndarray], xu: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``x_u+ = A x_u + Bu u``."""
        return a["A"] @ xu + a["Bu"] @ u


#: The plant matrices of the filter's copy of the response to a known input.
_U_PATH = ("A", "Cz", "Cy", *POLYTOPIC_INPUT_MATRICES)


def needs_scheduling(design: HinfDesign, plant: PolytopicLPV | None = None) -> bool:
    """Whether the filter of ``design`` needs ``alpha`` (or ``p``): its gains
    are scheduled, or it compensates the known input of ``plant``, whose
    response varies with ``alpha``.

    Parameters
    ----------
    design : HinfDesign
        The filter design.
    plant : PolytopicLPV, optional
        The plant whose known input the filter compensates (None: no input).

    Returns
    -------
    bool
        True when the filter takes a scheduling input.
    """
    return design.scheduled or (plant is not None and plant.known_input is not None and plant.input_path_varies())


#: HinfFilter's sample: (alpha or None, y, u or None).
_Sample = tuple[np.ndarray | None, np.ndarray, np.ndarray | None]
#: HinfFilter's pending step: the matrices, alpha, y (without u's response), zhat (of the filter part), and the
#: known-input path's matrices and u (None without a known input).
_Pending = tuple[FilterMatrices, np.ndarray | None, np.ndarray, np.ndarray, dict[str, np.ndarray] | None,
                 np.ndarray | None]


class HinfFilter(Component[_Sample, _Pending]):
    """Streaming H-infinity filter (2), a streaming component (:mod:`lpvest.core`)
    over the pure step :func:`hinf_step`.

    Parameters
    ----------
    design : HinfDesign
        From :func:`lpvest.design.design_hinf` / :func:`~lpvest.design.search_epsilon`,
        or :meth:`HinfDesign.from_json`.
    simplex_map : SimplexMap, optional
        The plant's map from the physical scheduling ``p`` to ``alpha``
        (``plant.simplex_map``). When given, the scheduling input port is ``p``
        (checked against the scheduling box) instead of ``alpha``. Only for a
        filter with a scheduling input.
    xf0 : array_like, shape (n_x,), optional
        Initial filter state (default zero).
    plant : PolytopicLPV, optional
        The plant, when it has a known input ``u``: the filter then takes
        ``u`` and compensates it exactly (see *Known inputs* in the module
        documentation); the design must be for this plant.

    Examples
    --------
    >>> import numpy as np, lpvest
    >>> from lpvest.design import design_hinf
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> f = HinfFilter(design_hinf(plant, epsilon=150.0), simplex_map=plant.simplex_map)
    >>> [p.name for p in f.input_ports], [p.name for p in f.output_ports]
    (['p', 'y'], ['zhat', 'xf'])
    >>> f.step({"p": np.array([0.5]), "y": np.array([1.0])})["zhat"].shape
    (2,)
    """

    def __init__(
        self,
        design: HinfDesign,
        *,
        simplex_map: SimplexMap | None = None,
        xf0: object | None = None,
        plant: PolytopicLPV | None = None,
    ) -> None:
        if not isinstance(design, HinfDesign):
            raise ArgumentTypeError(f"design must be an HinfDesign; found {type(design).__name__}")
        plant = _input_plant(design, plant)
        #: the plant whose known input the filter compensates (None: no input)
        self.plant = plant
        #: the filter needs alpha: its gains are scheduled, or the input path varies
        self.scheduled = needs_scheduling(design, plant)
        # the plant's response to u: only the matrices it needs
        self._u_path = None if plant is None else _InputPath(plant, design.n_vertices)
        if simplex_map is not None:
            if not self.scheduled:
                raise ArgumentTypeError("a robust filter takes no scheduling input: do not pass simplex_map")
            if simplex_map.n_vertices != design.n_vertices:
                raise DimensionError(
                    f"the simplex map gives {simplex_map.n_vertices} weights; the design has "
                    f"{design.n_vertices} vertices"
                )
        self.design = design
        self.simplex_map = simplex_map
        self._xf0 = np.zeros(design.nx) if xf0 is None else as_vector(xf0, "xf0", design.nx).copy()
        ports = []
        if self.scheduled:
            if simplex_map is None:
                ports.append(Port("alpha", (design.n_vertices,), "scheduling on the unit simplex"))
            else:
                # the elements' names are their labels (an FMU's p[1] reads "physical scheduling (theta)")
                ports.append(Port("p", (simplex_map.space.dim,), "physical scheduling"))
        if plant is not None:
            ports.append(Port("u", (plant.nu,), "known input u_k (compensated)"))
        ports.append(Port("y", (design.ny,), "measured output y_k"))
        outputs = (
            Port("zhat", (design.nz,), "estimate z_f,k of z_k"),
            Port("xf", (design.nx,), "filter state x_f,k", direct=False),
        )
        super().__init__(tuple(ports), outputs)

    def _reset(self) -> None:
        """Back to the initial filter state."""
        self._xf = self._xf0.copy()
        self._xu = np.zeros(0 if self.plant is None else self.plant.nx)
        self._k = 0

    def _read(self, inputs: Mapping[str, object]) -> tuple[np.ndarray | None, np.ndarray, np.ndarray | None]:
        missing = [n for n in self._in_names if n not in inputs]
        if missing or len(inputs) != len(self._in_names):
            unknown = sorted(set(inputs) - set(self._in_names))
            raise DimensionError(
                f"HinfFilter ({self.design.kind}) inputs are {sorted(self._in_names)}; "
                f"missing {missing}, unknown {unknown}"
            )
        # the checks an FMU makes element by element; _read_checked does the rest
        checked = {"y": as_vector(inputs["y"], "y", self.design.ny)}
        if self.plant is not None:
            checked["u"] = as_vector(inputs["u"], "u", self.plant.nu)
        if self.scheduled:
            if self.simplex_map is None:
                checked["alpha"] = as_vector(inputs["alpha"], "alpha", self.design.n_vertices)
            else:
                space = self.simplex_map.space
                checked["p"] = space.check(as_vector(inputs["p"], "p", space.dim))
        return self._read_checked(checked)

    def _read_checked(
        self, inputs: Mapping[str, np.ndarray]
    ) -> tuple[np.ndarray | None, np.ndarray, np.ndarray | None]:
        """:meth:`_read` of inputs checked at the boundary (:meth:`Component._read_checked`)."""
        u = None if self.plant is None else inputs["u"]
        alpha: np.ndarray | None = None
        if self.scheduled:
            if self.simplex_map is None:
                alpha = inputs["alpha"]
                check_simplex(alpha, "alpha")  # each weight in [0, 1] does not make a sum of 1
            else:
                alpha = np.asarray(self.simplex_map(inputs["p"]), dtype=float)  # on the simplex by construction
        return alpha, inputs["y"], u

    def _evaluate(
        self, sample: tuple[np.ndarray | None, np.ndarray, np.ndarray | None]
    ) -> tuple[dict[str, np.ndarray], _Pending]:
        """``zhat`` and ``xf`` at the current sample; the matrices are kept for the step."""
        alpha, y, u = sample
        m = self.design.matrices_at(alpha if self.design.scheduled else None, check=False)
        if self.plant is None:
            zhat = m.Cf @ self._xf + m.Df @ y
            return {"zhat": zhat, "xf": self._xf.copy()}, (m, alpha, y, zhat, None, None)
        path = self._u_path
        assert path is not None and u is not None
        a = path.at(alpha)
        y_w = path.without_input(a, self._xu, u, y)
        z_f = m.Cf @ self._xf + m.Df @ y_w
        zhat = path.estimate(a, self._xu, u, z_f)
        return {"zhat": zhat, "xf": self._xf.copy()}, (m, alpha, y_w, z_f, a, u)

    def _commit(self, pending: _Pending) -> None:
        m, alpha, y, zhat, a, u = pending
        self._xf = _step_with(m, self._xf, alpha, y, zhat).xf_next
        if a is not None and u is not None:  # (both or neither: see _evaluate)
            self._xu = _InputPath.next_state(a, self._xu, u)
        self._k += 1

    def get_state(self) -> dict[str, object]:
        """``{"xf": x_f,k, "k": k}`` and, with a known input, ``"xu"``: the
        state of the filter's copy of the plant driven by ``u`` (copies).

        Returns
        -------
        dict
            ``"xf"`` (n_x,) the filter state, ``"k"`` (int) the sample
            counter and, with a known input, ``"xu"`` (the plant's n_x,).
        """
        out: dict[str, object] = {"xf": self._xf.copy(), "k": self._k}
        if self.plant is not None:
            out["xu"] = self._xu.copy()
        return out

    def _set_state(self, state: Mapping[str, Any]) -> None:
        """Restore a state from :meth:`get_state`."""
        need = ["xf", "xu", "k"] if self.plant is not None else ["xf", "k"]
        if any(n not in state for n in need):
            names = ", ".join(repr(n) for n in need[:-1]) + f" and {need[-1]!r}"
            raise DimensionError(f"a HinfFilter state needs {names}; found {sorted(state)}")
        xf = as_vector(state["xf"], "xf", self.design.nx).copy()
        k = int(state["k"])
        if k < 0:
            raise DimensionError(f"the sample counter k of a HinfFilter state must be >= 0; found {k}")
        if self.plant is not None:
            self._xu = as_vector(state["xu"], "xu", self.plant.nx).copy()
        self._xf, self._k = xf, k
