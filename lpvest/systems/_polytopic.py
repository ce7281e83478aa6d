"""Polytopic LPV models (001_00f62b5a0c49ad87.txt, eq. (1)) and the exact
conversion of affine dependence on a box to polytopic vertices.

::

    x_{k+1} = A(alpha_k) x_k + Bw(alpha_k) w_k
    z_k     = Cz(alpha_k) x_k + Dz(alpha_k) w_k
    y_k     = Cy(alpha_k) x_k + Dy(alpha_k) w_k,   M(alpha) = sum_i alpha_i M_i,

with ``alpha_k`` on the unit simplex. A :class:`SimplexMap` computes ``alpha``
from the physical scheduling (``alpha_1 = (1 - theta)/2`` in Example 1).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, Protocol, runtime_checkable

import numpy as np

from ..core._errors import ArgumentTypeError, DimensionError, ExpressionError, ModelFileError, SchedulingRangeError
from ..core._expressions import Expression, FormulaVector
from ..core._linalg import MatrixStack
from ..core._scheduling import BasisFunction, Monomial, SchedulingSpace, box_vertices
from ..core._validation import as_float_array, as_matrix, as_signal, as_vector, check_simplex
from ._affine import AffineDependence, AffineLPV
from ._text import (
    basis_name,
    dependence_table,
    describe_dependence,
    format_matrix,
    formula_value,
    matrix_table,
    number,
)

__all__ = [
    "PolytopicLPV",
    "PolytopicMatrices",
    "PolytopicTrajectory",
    "SimplexMap",
    "FormulaSimplexMap",
    "MultilinearSimplexMap",
    "affine_to_polytopic",
    "POLYTOPIC_MATRICES",
    "POLYTOPIC_INPUT_MATRICES",
    "PolytopicInput",
    "hinf_setting",
]

#: Matrix names of the polytopic model, in the order of eq. (1).
POLYTOPIC_MATRICES = ("A", "Bw", "Cz", "Dz", "Cy", "Dy")
#: Optional matrices of a known input ``u`` (not in the paper's (1)):
#: ``x+ = ... + Bu u``, ``z = ... + Dzu u``, ``y = ... + Dyu u``. ``Bu`` gives
#: the input; ``Dzu`` and ``Dyu`` are zero unless given.
POLYTOPIC_INPUT_MATRICES = ("Bu", "Dzu", "Dyu")


class PolytopicMatrices(NamedTuple):
    """The matrices of (1) at one ``alpha`` (or the vertex stacks, shape (N, r, c)).

    Stacked along a trajectory by :meth:`PolytopicLPV.at_batch` (shape (T, r, c)).

    Parameters
    ----------
    A : ndarray, shape (n_x, n_x)
        State matrix ``A(alpha)``.
    Bw : ndarray, shape (n_x, n_w)
        Disturbance matrix ``Bw(alpha)``.
    Cz : ndarray, shape (n_z, n_x)
        Matrix ``Cz(alpha)`` of the signal to be estimated ``z``.
    Dz : ndarray, shape (n_z, n_w)
        Disturbance feedthrough ``Dz(alpha)`` to ``z``.
    Cy : ndarray, shape (n_y, n_x)
        Matrix ``Cy(alpha)`` of the measured output ``y``.
    Dy : ndarray, shape (n_y, n_w)
        Disturbance feedthrough ``Dy(alpha)`` to ``y``.
    """

    A: np.ndarray
    Bw: np.ndarray
    Cz: np.ndarray
    Dz: np.ndarray
    Cy: np.ndarray
    Dy: np.ndarray


class PolytopicInput(NamedTuple):
    """The vertex stacks of a known input's matrices, shape (N, rows, n_u).

    Parameters
    ----------
    Bu : ndarray, shape (N, n_x, n_u)
        Input matrix of the state, ``x+ = ... + Bu u``.
    Dzu : ndarray, shape (N, n_z, n_u)
        Input feedthrough to ``z``.
    Dyu : ndarray, shape (N, n_y, n_u)
        Input feedthrough to ``y``.
    """

    Bu: np.ndarray
    Dzu: np.ndarray
    Dyu: np.ndarray


class PolytopicTrajectory(NamedTuple):
    """A simulated trajectory; row ``k`` holds time ``k``.

    Parameters
    ----------
    x : ndarray, shape (T, n_x)
        States ``x_k``.
    z : ndarray, shape (T, n_z)
        Signal to be estimated ``z_k``.
    y : ndarray, shape (T, n_y)
        Measured output ``y_k``.
    """

    x: np.ndarray
    z: np.ndarray
    y: np.ndarray


@runtime_checkable
class SimplexMap(Protocol):
    """Maps the physical scheduling vector to ``alpha`` on the unit simplex.

    Parameters
    ----------
    *args, **kwargs
        Not used: a Protocol cannot be instantiated. A class conforms by having
        the members below (``isinstance`` checks that they exist).
    """

    @property
    def space(self) -> SchedulingSpace: ...

    @property
    def n_vertices(self) -> int: ...

    def __call__(self, p: np.ndarray) -> np.ndarray: ...

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Vectorised: ``p`` of shape ``(T, n_p)`` -> ``alpha`` of shape ``(T, N)``.

        Parameters
        ----------
        p : ndarray, shape (T, n_p)
            Scheduling vectors, one per row.

        Returns
        -------
        alpha : ndarray, shape (T, N)
            The vertex weights of each row.
        """
        ...


def _validation_points(space: SchedulingSpace, per_axis: int = 5) -> np.ndarray:
    """Box corners plus a regular grid (at most ~4000 points)."""
    per_axis = max(2, min(per_axis, int(4000 ** (1.0 / max(space.dim, 1)))))
    axes = [np.linspace(lo, hi, per_axis) for lo, hi in zip(space.lower, space.upper, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, space.dim)
    return np.vstack([space.corners(), grid])


@dataclass(frozen=True, eq=False)
class FormulaSimplexMap:
    """``alpha_i = f_i(p)`` given as formulas of the scheduling components.

    Checked at construction on the box corners and a grid: ``alpha >= 0`` and
    ``sum(alpha) == 1`` (exact for formulas affine in ``p``).

    Parameters
    ----------
    space : SchedulingSpace
        The box of scheduling vectors ``p``; the formulas use its component names.
    formulas : sequence of str or Expression, length N
        ``f_1, ..., f_N``, at least one (text is parsed with the names of ``space``).

    Examples
    --------
    >>> space = SchedulingSpace(["theta"], [-1], [1])
    >>> m = FormulaSimplexMap(space, ["(1 - theta)/2", "(1 + theta)/2"])
    >>> m(np.array([0.5]))
    array([0.25, 0.75])
    """

    space: SchedulingSpace
    formulas: tuple[Expression, ...]
    if TYPE_CHECKING:  # not fields: set in __init__ (a frozen class); declared for the type checker only
        _vector: FormulaVector = field(init=False, repr=False)
        _last: tuple[bytes, np.ndarray] | None = field(init=False, repr=False)  #: the last p (bytes) and alpha

    def __init__(self, space: SchedulingSpace, formulas: Sequence[str | Expression]) -> None:
        exprs = tuple(
            f if isinstance(f, Expression) else Expression.parse(f, allowed=space.names)
            for f in formulas
        )
        if len(exprs) < 1:
            raise ExpressionError("a simplex map needs at least one formula")
        object.__setattr__(self, "space", space)
        object.__setattr__(self, "formulas", exprs)
        object.__setattr__(self, "_vector", FormulaVector(exprs))
        object.__setattr__(self, "_last", None)
        pts = _validation_points(space)
        alpha = self.evaluate(pts)
        for k in range(pts.shape[0]):
            try:
                check_simplex(alpha[k], "alpha")
            except SchedulingRangeError as exc:
                where = ", ".join(f"{n} = {v:g}" for n, v in zip(space.names, pts[k], strict=True))
                raise SchedulingRangeError(f"simplex map at {where}: {exc}") from exc

    @property
    def n_vertices(self) -> int:
        return len(self.formulas)

    def __call__(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=float).reshape(-1)
        # a plant and its filter map the same p in one sample: the last value is kept
        key = p.tobytes()
        last = self._last
        if last is not None and last[0] == key:
            return last[1].copy()
        alpha = np.asarray(self._vector.evaluate(
            {n: float(v) for n, v in zip(self.space.names, p, strict=True)}), dtype=np.float64)
        object.__setattr__(self, "_last", (key, alpha))
        return alpha.copy()

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Vectorised: ``alpha`` for every scheduling vector of ``p`` (not range-checked).

        Parameters
        ----------
        p : array_like, shape (..., n_p)
            Scheduling vectors along the last axis, e.g. a trajectory (T, n_p).

        Returns
        -------
        alpha : ndarray, shape (..., N)
            The weights ``f_i(p)``.
        """
        p = np.asarray(p, dtype=float)
        out = self._vector.evaluate(self.space.as_dict(p))
        return np.broadcast_to(out, (*p.shape[:-1], self.n_vertices)).astype(float)


    def to_toml(self) -> dict[str, object]:
        """The ``map`` table of a model file.

        Returns
        -------
        dict of str to object
            ``kind = "formulas"`` and ``alpha``, one formula per weight (a
            number for a constant one).
        """
        return {"kind": "formulas", "alpha": [formula_value(f) for f in self.formulas]}

    def describe(self) -> list[str]:
        """Lines for a person: one formula per weight.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        return [f"    alpha_{i + 1} = {f.text}" for i, f in enumerate(self.formulas)]


@dataclass(frozen=True, eq=False)
class MultilinearSimplexMap:
    """Multilinear interpolation weights on a box of coordinates ``c(p)``.

    With ``lambda_j = (c_j - lower_j) / (upper_j - lower_j)``, vertex ``v`` gets
    ``alpha_v = prod_j (lambda_j if bit j of v else 1 - lambda_j)``: vertex 0
    is the all-lower corner. The coordinates are basis functions of ``p``
    (components for a multi-affine model).

    Parameters
    ----------
    space : SchedulingSpace
        The box of scheduling vectors ``p``.
    coordinates : sequence of BasisFunction, length n_c
        The coordinates ``c_j(p)``.
    lower, upper : array_like, shape (n_c,)
        The box of the coordinates, ``lower_j < upper_j``; ``alpha`` is on the
        simplex while ``c(p)`` stays in it.
    """

    space: SchedulingSpace
    coordinates: tuple[BasisFunction, ...]
    lower: np.ndarray
    upper: np.ndarray

    def __init__(
        self,
        space: SchedulingSpace,
        coordinates: Sequence[BasisFunction],
        lower: Sequence[float] | np.ndarray,
        upper: Sequence[float] | np.ndarray,
    ) -> None:
        coords = tuple(coordinates)
        lo = as_vector(lower, "multilinear map lower bound", len(coords))
        hi = as_vector(upper, "multilinear map upper bound", len(coords))
        flat = np.flatnonzero(~(hi > lo))
        if flat.size:
            j = int(flat[0])
            raise ExpressionError(
                f"coordinate {coords[j].name!r} of the multilinear map does not vary over the "
                f"scheduling box (range [{lo[j]:g}, {hi[j]:g}]); fold it into the constant term"
            )
        object.__setattr__(self, "space", space)
        object.__setattr__(self, "coordinates", coords)
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    @property
    def n_vertices(self) -> int:
        return 2 ** len(self.coordinates)

    def vertex_coordinates(self) -> np.ndarray:
        """Coordinates of each vertex, shape ``(N, n_c)``.

        Returns
        -------
        ndarray, shape (2**n_c, n_c)
            Row ``v`` takes ``upper[j]`` where bit ``j`` of ``v`` is set, else
            ``lower[j]`` (:func:`~lpvest.core.box_vertices`).
        """
        return box_vertices(self.lower, self.upper)

    def __call__(self, p: np.ndarray) -> np.ndarray:
        return self.evaluate(np.asarray(p, dtype=float).reshape(1, -1))[0]

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        """Vectorised: ``alpha`` for every row of ``p`` (not range-checked: a
        coordinate outside ``[lower, upper]`` gives negative weights).

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            Scheduling vectors, one per row.

        Returns
        -------
        alpha : ndarray, shape (T, 2**n_c)
            The multilinear weights of each row.
        """
        p = np.asarray(p, dtype=float)
        lam = np.stack([c.evaluate(p) for c in self.coordinates], axis=-1)
        lam = (lam - self.lower) / (self.upper - self.lower)
        n = len(self.coordinates)
        alpha = np.ones((*p.shape[:-1], 2**n))
        for v in range(2**n):
            for j in range(n):
                alpha[..., v] *= lam[..., j] if (v >> j) & 1 else 1.0 - lam[..., j]
        return alpha


    def to_toml(self) -> dict[str, object]:
        """The ``map`` table of a model file.

        Returns
        -------
        dict of str to object
            ``kind = "multilinear"``, ``over`` (the coordinates' names),
            ``lower`` and ``upper``.
        """
        return {
            "kind": "multilinear",
            "over": [basis_name(c) for c in self.coordinates],
            "lower": [number(v) for v in self.lower],
            "upper": [number(v) for v in self.upper],
        }

    def describe(self) -> list[str]:
        """Lines for a person: the coordinates the weights are multilinear in.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        return [f"    alpha: multilinear weights over ({', '.join(c.name for c in self.coordinates)})"]


def affine_to_polytopic(
    dependence: AffineDependence,
) -> tuple[dict[str, np.ndarray], MultilinearSimplexMap]:
    """Exact polytopic form of matrices affine in ``psi(p)`` on a box.

    If every basis function is a multi-affine monomial (each component to the
    power 0 or 1: ``p1``, ``p1*p2``), the vertices are the matrices at the
    corners of the box of the components that occur, with multilinear weights
    in ``p`` (``2**(components used)`` vertices). Otherwise the vertices are
    taken on the box of basis-function values ``[min psi_i, max psi_i]``, with
    multilinear weights in ``psi(p)`` (``2**n_psi`` vertices); non-monomial
    basis functions must then declare their bounds.

    In both cases ``M(p) == sum_v alpha_v(p) M_v`` holds exactly (to
    round-off) for every ``p`` in the box and ``alpha(p)`` is on the simplex.

    Parameters
    ----------
    dependence : AffineDependence
        The matrices, with at least one basis function.

    Returns
    -------
    vertices : dict of str to ndarray, shape (N, rows, cols)
        Every matrix of ``dependence`` at each vertex ``v``.
    simplex_map : MultilinearSimplexMap
        The weights ``alpha(p)`` of the vertices.
    """
    space, basis = dependence.space, dependence.basis
    if not basis:
        raise ExpressionError("the matrices do not depend on the scheduling: nothing to convert")
    multiaffine = all(isinstance(b, Monomial) and b.is_multiaffine for b in basis)
    if multiaffine:
        # every b is a Monomial (multiaffine)
        used = sorted({j for b in basis if isinstance(b, Monomial) for j, e in enumerate(b.exponents) if e})
        coords: list[BasisFunction] = [Monomial.component(j, space) for j in used]
        lo = space.lower[used]
        hi = space.upper[used]
        mapping = MultilinearSimplexMap(space, coords, lo, hi)
        # the vertex p: used components at the box corner, others anywhere (unused)
        corners = np.tile((space.lower + space.upper) / 2.0, (mapping.n_vertices, 1))
        corners[:, used] = mapping.vertex_coordinates()
        psi = dependence.psi_batch(corners, check=False)
    else:
        bounds = [b.bounds(space) for b in basis]
        lo = np.array([b[0] for b in bounds])
        hi = np.array([b[1] for b in bounds])
        mapping = MultilinearSimplexMap(space, basis, lo, hi)
        vc = mapping.vertex_coordinates()
        psi = np.hstack([np.ones((vc.shape[0], 1)), vc])
    vertices = {
        name: np.einsum("vk,krc->vrc", psi, stack) for name, stack in dependence.coefficients.items()
    }
    return vertices, mapping


@dataclass(frozen=True, eq=False)
class PolytopicLPV:
    """Polytopic LPV model, eq. (1) of 001_00f62b5a0c49ad87.txt.

    Parameters
    ----------
    vertices : mapping of str to array_like, shape (N, rows, cols)
        Vertex stacks of ``A, Bw, Cz, Dz, Cy, Dy``; optionally ``Bu`` (and
        ``Dzu``, ``Dyu``, zero unless given) of a known input ``u``
        (:data:`POLYTOPIC_INPUT_MATRICES`), which the H-infinity filters
        compensate exactly (:class:`~lpvest.estimators.HinfFilter`).
    simplex_map : SimplexMap, optional
        Map from the physical scheduling to ``alpha``; ``None`` when the model is
        scheduled by ``alpha`` itself.
    affine : AffineDependence, optional
        The same system stated as affine in the physical scheduling (e.g.
        system (10)), kept for reference and checks.
    parameters : mapping, optional
        Named model parameters the matrices were built with (e.g. ``rho``).
    name : str, default ""
        The model's name in error messages (a model file gives ``system/key``).

    Examples
    --------
    >>> from lpvest import load_system
    >>> plant = load_system("peixoto-ex1").model()
    >>> plant.n_vertices, plant.nx, plant.nw, plant.nz, plant.ny
    (2, 2, 1, 2, 1)
    >>> plant.alpha([0.0])
    array([0.5, 0.5])
    """

    vertices: PolytopicMatrices
    known_input: PolytopicInput | None = None  #: ``None`` when the model has no known input
    simplex_map: SimplexMap | None = None
    affine: AffineDependence | None = None
    parameters: Mapping[str, float] = field(default_factory=dict)
    name: str = ""

    def __init__(
        self,
        vertices: Mapping[str, object] | PolytopicMatrices,
        simplex_map: SimplexMap | None = None,
        affine: AffineDependence | None = None,
        parameters: Mapping[str, float] | None = None,
        name: str = "",
    ) -> None:
        vmap = vertices._asdict() if isinstance(vertices, PolytopicMatrices) else dict(vertices)
        missing = [n for n in POLYTOPIC_MATRICES if n not in vmap]
        unknown = [n for n in vmap if n not in (*POLYTOPIC_MATRICES, *POLYTOPIC_INPUT_MATRICES)]
        if missing or unknown:
            raise DimensionError(
                f"polytopic vertices need exactly {list(POLYTOPIC_MATRICES)} (and optionally "
                f"{list(POLYTOPIC_INPUT_MATRICES)}); missing {missing}, unknown {unknown}"
            )
        if any(n in vmap for n in POLYTOPIC_INPUT_MATRICES) and "Bu" not in vmap:
            raise DimensionError("a known input needs Bu (Dzu and Dyu are zero unless given)")
        stacks = {}
        for n in POLYTOPIC_MATRICES:
            arr = np.array(as_float_array(vmap[n], f"{n} vertices"))
            if arr.ndim != 3:
                raise DimensionError(f"{n} vertices have shape {arr.shape}; expected (N, rows, cols)")
            stacks[n] = arr
        N = stacks["A"].shape[0]
        nx = stacks["A"].shape[1]
        nw = stacks["Bw"].shape[2]
        nz = stacks["Cz"].shape[1]
        ny = stacks["Cy"].shape[1]
        expected = {
            "A": (N, nx, nx),
            "Bw": (N, nx, nw),
            "Cz": (N, nz, nx),
            "Dz": (N, nz, nw),
            "Cy": (N, ny, nx),
            "Dy": (N, ny, nw),
        }
        known = None
        if "Bu" in vmap:
            bu = np.array(as_float_array(vmap["Bu"], "Bu vertices"))
            if bu.ndim != 3 or bu.shape[:2] != (N, nx) or bu.shape[2] < 1:
                raise DimensionError(f"Bu vertices have shape {bu.shape}; expected ({N}, {nx}, n_u)")
            nu = bu.shape[2]
            inputs = {"Bu": bu}
            for n, rows in (("Dzu", nz), ("Dyu", ny)):
                inputs[n] = (np.array(as_float_array(vmap[n], f"{n} vertices")) if n in vmap
                             else np.zeros((N, rows, nu)))
            expected.update(Bu=(N, nx, nu), Dzu=(N, nz, nu), Dyu=(N, ny, nu))
            stacks.update(inputs)
        for n, shp in expected.items():
            if stacks[n].shape != shp:
                raise DimensionError(f"{n} vertices have shape {stacks[n].shape}; expected {shp}")
            as_matrix(stacks[n].reshape(N * shp[1], shp[2]), f"{n} vertices")  # finite check
            stacks[n].setflags(write=False)
        if "Bu" in stacks:
            known = PolytopicInput(*(stacks.pop(n) for n in POLYTOPIC_INPUT_MATRICES))
        if simplex_map is not None and simplex_map.n_vertices != N:
            raise DimensionError(
                f"the simplex map gives {simplex_map.n_vertices} weights; the model has {N} vertices"
            )
        object.__setattr__(self, "vertices", PolytopicMatrices(**stacks))
        object.__setattr__(self, "known_input", known)
        self._stack: MatrixStack
        object.__setattr__(self, "_stack", MatrixStack({**stacks, **({} if known is None else known._asdict())}))
        object.__setattr__(self, "simplex_map", simplex_map)
        object.__setattr__(self, "affine", affine)
        object.__setattr__(self, "parameters", dict(parameters or {}))
        object.__setattr__(self, "name", name)

    @classmethod
    def from_affine(
        cls,
        dependence: AffineDependence,
        *,
        parameters: Mapping[str, float] | None = None,
        name: str = "",
    ) -> PolytopicLPV:
        """The exact polytopic form of a system stated as affine in ``p``
        (see :func:`affine_to_polytopic`); keeps the affine form.

        Parameters
        ----------
        dependence : AffineDependence
            ``A, Bw, Cz, Dz, Cy, Dy`` (and optionally ``Bu``, ``Dzu``, ``Dyu``)
            affine in at least one basis function of ``p``; other matrices are
            kept in the affine form only.
        parameters : mapping of str to float, optional
            Named model parameters the matrices were built with.
        name : str, default ""
            The model's name in error messages.

        Returns
        -------
        PolytopicLPV
            With a :class:`MultilinearSimplexMap` and ``dependence`` as its
            affine form.
        """
        names = [n for n in (*POLYTOPIC_MATRICES, *POLYTOPIC_INPUT_MATRICES) if n in dependence.coefficients]
        vertices, mapping = affine_to_polytopic(dependence.subset(names))
        return cls(vertices, mapping, dependence, parameters, name)

    # -- dimensions -----------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return self.vertices.A.shape[0]

    @property
    def nx(self) -> int:
        return self.vertices.A.shape[1]

    @property
    def nw(self) -> int:
        return self.vertices.Bw.shape[2]

    @property
    def nz(self) -> int:
        return self.vertices.Cz.shape[1]

    @property
    def ny(self) -> int:
        return self.vertices.Cy.shape[1]

    @property
    def nu(self) -> int:
        """Dimension of the known input ``u`` (0 without one)."""
        return 0 if self.known_input is None else self.known_input.Bu.shape[2]

    def vertex_stacks(self) -> dict[str, np.ndarray]:
        """Every vertex stack by name, the known input's included (the
        ``vertices`` argument that rebuilds this model).

        Returns
        -------
        dict of str to ndarray, shape (N, rows, cols)
            ``A, Bw, Cz, Dz, Cy, Dy`` and, with a known input, ``Bu, Dzu, Dyu``.
        """
        return {**self.vertices._asdict(), **({} if self.known_input is None else self.known_input._asdict())}

    def input_path_varies(self) -> bool:
        """True when the response to ``u`` depends on ``alpha``: a filter
        that compensates ``u`` then needs ``alpha`` (even a robust one).

        Returns
        -------
        bool
            ``False`` without a known input; else whether any of ``A, Cz, Cy,
            Bu, Dzu, Dyu`` differs between the vertices.
        """
        if self.known_input is None:
            return False
        stacks = (self.vertices.A, self.vertices.Cz, self.vertices.Cy, *self.known_input)
        return any(not np.array_equal(s, np.broadcast_to(s[0], s.shape)) for s in stacks)

    def matrices(self, alpha: np.ndarray) -> dict[str, np.ndarray]:
        """Every matrix at ``alpha`` (not checked to lie on the simplex: see
        :meth:`at`), the known input's included: ``A, Bw, Cz, Dz, Cy, Dy[, Bu, Dzu, Dyu]``.

        Parameters
        ----------
        alpha : ndarray, shape (N,)
            The vertex weights, used as given (not checked here).

        Returns
        -------
        dict of str to ndarray, shape (rows, cols)
            ``sum_i alpha_i M_i`` for every matrix (fresh arrays).
        """
        return self._stack.at(alpha)

    @property
    def space(self) -> SchedulingSpace | None:
        return None if self.simplex_map is None else self.simplex_map.space

    # -- evaluation -----------------------------------------------------------
    def alpha(self, p: object) -> np.ndarray:
        """``alpha`` for the physical scheduling ``p`` (range-checked).

        Parameters
        ----------
        p : array_like, shape (n_p,)
            The physical scheduling vector.

        Returns
        -------
        alpha : ndarray, shape (N,)
            The vertex weights of the simplex map.

        Raises
        ------
        SchedulingRangeError
            The model has no simplex map, or ``p`` is outside the box.
        """
        if self.simplex_map is None:
            raise SchedulingRangeError(
                f"model {self.name or '(unnamed)'} has no map from a physical scheduling to alpha"
            )
        pv = self.simplex_map.space.check(np.asarray(p, dtype=float))
        return self.simplex_map(pv)

    def alpha_batch(self, p: object) -> np.ndarray:
        """``alpha`` along a scheduling trajectory ``p`` of shape (T, n_p).

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            The physical scheduling trajectory (every sample range-checked).

        Returns
        -------
        alpha : ndarray, shape (T, N)
            The vertex weights of each sample.

        Raises
        ------
        SchedulingRangeError
            The model has no simplex map, or a sample is outside the box.
        """
        if self.simplex_map is None:
            raise SchedulingRangeError(
                f"model {self.name or '(unnamed)'} has no map from a physical scheduling to alpha"
            )
        space = self.simplex_map.space
        pt = as_signal(p, "p", space.dim)
        for t in range(pt.shape[0]):
            space.check(pt[t], what=f"scheduling value at t={t}:")
        return self.simplex_map.evaluate(pt)

    def at(self, alpha: object, *, check: bool = True) -> PolytopicMatrices:
        """The matrices at one ``alpha`` (checked to lie on the simplex).

        Parameters
        ----------
        alpha : array_like, shape (N,)
            The vertex weights (length and finiteness always checked).
        check : bool, default True
            Check that ``alpha`` is on the unit simplex.

        Returns
        -------
        PolytopicMatrices
            ``A, Bw, Cz, Dz, Cy, Dy`` at ``alpha`` (the known-input matrices: :meth:`matrices`).
        """
        a = as_vector(alpha, "alpha", self.n_vertices)
        if check:
            check_simplex(a, "alpha")
        m = self._stack.at(a)
        return PolytopicMatrices(*(m[k] for k in PolytopicMatrices._fields))

    def at_batch(self, alpha: object, *, check: bool = True) -> PolytopicMatrices:
        """The matrices along ``alpha`` of shape (T, N), stacked (T, rows, cols);
        row ``k`` is :meth:`at` of ``alpha[k]`` to the bit.

        Parameters
        ----------
        alpha : array_like, shape (T, N)
            The vertex weights along time (shape and finiteness always checked).
        check : bool, default True
            Check that every row is on the unit simplex.

        Returns
        -------
        PolytopicMatrices
            ``A, Bw, Cz, Dz, Cy, Dy`` along ``alpha``, each of shape ``(T, rows, cols)``.
        """
        a = as_signal(alpha, "alpha", self.n_vertices)
        if check:
            for t in range(a.shape[0]):
                check_simplex(a[t], f"alpha at k={t}")
        m = self._stack.at_batch(a)
        return PolytopicMatrices(*(m[k] for k in PolytopicMatrices._fields))

    def step(
        self, x: np.ndarray, alpha: np.ndarray, w: np.ndarray, u: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One sample of (1), a pure function: ``(y_k, z_k, x_{k+1})`` from the
        state ``x_k`` (n_x,), the weights ``alpha_k`` (N,) (unchecked: on the
        simplex), the disturbance ``w_k`` (n_w,) and, for a model with a known
        input, ``u_k`` (n_u,).

        :meth:`simulate`, the streaming plant and the Plant FMU all call it.

        Parameters
        ----------
        x : ndarray, shape (n_x,)
            The state ``x_k``.
        alpha : ndarray, shape (N,)
            The vertex weights ``alpha_k`` (not checked).
        w : ndarray, shape (n_w,)
            The disturbance ``w_k``.
        u : ndarray, shape (n_u,), optional
            The known input ``u_k``; ``None`` (or a model without a known
            input) leaves the input terms out.

        Returns
        -------
        y : ndarray, shape (n_y,)
            The measured output ``y_k``.
        z : ndarray, shape (n_z,)
            The signal to be estimated ``z_k``.
        x_next : ndarray, shape (n_x,)
            The next state ``x_{k+1}``.
        """
        m = self._stack.at(alpha)
        y, z, nxt = m["Cy"] @ x + m["Dy"] @ w, m["Cz"] @ x + m["Dz"] @ w, m["A"] @ x + m["Bw"] @ w
        if u is not None and self.known_input is not None:
            y, z, nxt = y + m["Dyu"] @ u, z + m["Dzu"] @ u, nxt + m["Bu"] @ u
        return y, z, nxt

    def simulate(
        self, alpha: object, w: object, *, x0: object | None = None, u: object | None = None
    ) -> PolytopicTrajectory:
        """Simulate (1) for ``alpha`` (T, N), disturbance ``w`` (T, n_w) and,
        for a model with a known input, ``u`` (T, n_u; default zero), from
        ``x0`` (default zero): :meth:`step` sample by sample.

        Parameters
        ----------
        alpha : array_like, shape (T, N)
            The vertex weights (every row checked to lie on the simplex).
        w : array_like, shape (T, n_w)
            The disturbance.
        x0 : array_like, shape (n_x,), optional
            The initial state (default zero).
        u : array_like, shape (T, n_u), optional
            The known input (default zero); only for a model with one.

        Returns
        -------
        PolytopicTrajectory
            ``x``, ``z`` and ``y`` at ``k = 0..T-1``.

        Raises
        ------
        DimensionError
            ``u`` is given for a model without a known input, or a shape is wrong.
        """
        a = as_signal(alpha, "alpha", self.n_vertices)
        for t in range(a.shape[0]):
            check_simplex(a[t], f"alpha at k={t}")
        T = a.shape[0]
        w = as_signal(w, "w", self.nw, T)
        if u is not None and self.known_input is None:
            raise DimensionError(f"model {self.name or '(unnamed)'} has no known input: do not pass u")
        uu = None if u is None else as_signal(u, "u", self.nu, T)
        x = np.zeros(self.nx) if x0 is None else as_vector(x0, "x0", self.nx)
        X = np.empty((T, self.nx))
        Z = np.empty((T, self.nz))
        Y = np.empty((T, self.ny))
        for k in range(T):
            X[k] = x
            Y[k], Z[k], x = self.step(x, a[k], w[k], None if uu is None else uu[k])
        return PolytopicTrajectory(X, Z, Y)


    # -- text forms ---------------------------------------------------------------------
    def to_toml(self) -> dict[str, object]:
        """This model as the ``[models.KEY]`` table of a model file (:mod:`lpvest.systems`).

        Returns
        -------
        dict of str to object
            ``type = "polytopic"``, the simplex map's ``map`` table (when there
            is a map), one ``vertex`` table per vertex and, when kept, the
            ``affine`` form.

        Raises
        ------
        ModelFileError
            The simplex map (or a basis function of the affine form) has no
            text form.
        """
        out: dict[str, object] = {"type": "polytopic"}
        if self.simplex_map is not None:
            to_toml = getattr(self.simplex_map, "to_toml", None)
            if to_toml is None:
                raise ModelFileError(f"simplex map {type(self.simplex_map).__name__} cannot be written to a "
                                     "model file")
            out["map"] = to_toml()
        out["vertex"] = [{n: matrix_table(m[i]) for n, m in self.vertex_stacks().items()}
                         for i in range(self.n_vertices)]
        if self.affine is not None:
            out["affine"] = dependence_table(self.affine)
        return out

    def describe(self, key: str) -> list[str]:
        """Lines for a person (``lpvest systems show``): vertices, map, affine form.

        Parameters
        ----------
        key : str
            The model's key in its model file, named in the first line.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        lines = [f"  model {key}: polytopic LPV (Peixoto et al. (1)), N={self.n_vertices} vertices",
                 f"    n_x={self.nx} n_w={self.nw} n_z={self.nz} n_y={self.ny}"
                 + (f" n_u={self.nu} (known input)" if self.nu else "")]
        if self.parameters:
            lines.append("    parameters: " + ", ".join(f"{k} = {v:g}" for k, v in self.parameters.items()))
        m = self.simplex_map
        if m is None:
            lines.append("    scheduling: alpha itself (no physical scheduling map)")
        elif hasattr(m, "describe"):
            lines += m.describe()
        else:
            lines.append(f"    alpha: {type(m).__name__}")
        for i in range(self.n_vertices):
            lines.append(f"    vertex {i + 1}:")
            for name, stack in self.vertex_stacks().items():
                lines += [f"      {name}  {stack.shape[1]}x{stack.shape[2]}", format_matrix(stack[i], "        ")]
        if self.affine is not None:
            lines.append("    affine form:")
            lines += describe_dependence(self.affine)
        return lines


def hinf_setting(model: object, *, z: object | None = None, name: str = "") -> PolytopicLPV:
    r"""The H-infinity setting of Peixoto et al. for a model with general noise
    (a :class:`PolytopicLPV` is in it already: returned unchanged).

    The model (Cox & Toth (1)-(3))::

        x+ = A(p) x + B(p) u + G(p) w,    y = C(p) x + D(p) u + H(p) v,
        [w; v] ~ N(0, Sigma),  Sigma = [[Q, S], [S^T, R]] > 0,

    has its noise written as ``[w; v] = L w~`` with ``L L^T = Sigma``
    (Cholesky) and ``w~`` of identity covariance, so that ::

        Bw = G L_w,  Dy = H L_v     (L_w, L_v: the first n_w and the last n_v rows of L)
        z  = Cz x,   Dz = 0         (Cz = z, default the identity: every state)
        Bu = B,  Dyu = D,  Dzu = 0  (the known input, compensated by the filter)

    and the bound a design certifies, ``||z - z_hat||_2 < gamma ||w~||_2``,
    is in units in which the noise is white with unit intensity (the
    correlation S included). The matrices stay affine in the basis functions
    of ``p`` (``L`` is constant), so the polytopic form is exact
    (:func:`affine_to_polytopic`, ``2^k`` vertices for ``k`` scheduling
    components). ``x0``, ``P0`` and the Gaussian law do not enter: an
    H-infinity filter assumes only bounded energy.

    Parameters
    ----------
    model : AffineLPV or PolytopicLPV
        The model; a :class:`PolytopicLPV` only without ``z`` and ``name``.
    z : array_like, shape (n_z, n_x), optional
        Which combination of states the filter estimates (default: the
        model's ``Cz``, model-file key ``Cz``; without one every state).
    name : str, optional
        Name of the polytopic model (default: the model's).

    Returns
    -------
    PolytopicLPV
        The model in the H-infinity setting, with ``w~`` as its disturbance
        (``n_w + n_v`` components) and ``u`` as its known input (when
        ``n_u > 0``); without a basis function, one vertex and no simplex map.

    Raises
    ------
    ArgumentTypeError
        ``model`` is not an :class:`AffineLPV` (nor a :class:`PolytopicLPV`
        without ``z`` and ``name``).

    Examples
    --------
    >>> from lpvest import load_system
    >>> plant = hinf_setting(load_system("cox-toth-truncation").model(), z=[[1.0, 0.0]])
    >>> plant.n_vertices, plant.nx, plant.nw, plant.nz, plant.ny, plant.nu
    (2, 2, 4, 1, 2, 1)
    """
    if isinstance(model, PolytopicLPV) and z is None and not name:
        return model
    if not isinstance(model, AffineLPV):
        raise ArgumentTypeError(f"hinf_setting converts an AffineLPV (general noise); found {type(model).__name__}")
    dep = model.dependence
    if z is None:
        z = model.Cz
    Cz = np.eye(model.nx) if z is None else as_matrix(z, "z", (None, model.nx))
    L = np.linalg.cholesky(model.noise.joint)  # exists: the joint covariance is checked positive definite
    nw = model.nw
    coeffs = dep.coefficients
    n_terms = coeffs["A"].shape[0]
    n_noise = L.shape[0]

    def const(m: np.ndarray) -> np.ndarray:
        out = np.zeros((n_terms, *m.shape))
        out[0] = m
        return out

    matrices = {
        "A": coeffs["A"],
        "Bw": coeffs["G"] @ L[:nw],
        "Cz": const(Cz),
        "Dz": np.zeros((n_terms, Cz.shape[0], n_noise)),
        "Cy": coeffs["C"],
        "Dy": coeffs["H"] @ L[nw:],
    }
    if model.nu:
        matrices.update(Bu=coeffs["B"], Dzu=np.zeros((n_terms, Cz.shape[0], model.nu)), Dyu=coeffs["D"])
    converted = AffineDependence(dep.space, dep.basis, matrices)
    if not dep.basis:
        vertices = {k: v[:1] for k, v in matrices.items()}
        return PolytopicLPV(vertices, None, converted, name=name or model.name)
    return PolytopicLPV.from_affine(converted, name=name or model.name)
