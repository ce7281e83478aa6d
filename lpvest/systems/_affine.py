"""Affine LPV models: matrices affine in basis functions of the scheduling vector.

:class:`AffineDependence` holds a set of named matrices
``M(p) = M_0 + sum_i M_i psi_i(p)`` over a scheduling box; :class:`AffineLPV`
is the discrete-time LPV state-space model with general noise of
000_dc6273d4fec795cd.txt, eqs. (1)-(3)::

    x_{t+1} = A(p_t) x_t + B(p_t) u_t + G(p_t) w_t
    y_t     = C(p_t) x_t + D(p_t) u_t + H(p_t) v_t,   [w; v] ~ N(0, [[Q, S], [S^T, R]])
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..core._errors import DimensionError, ExpressionError, abbreviate
from ..core._expressions import Expression
from ..core._linalg import MatrixStack
from ..core._rng import Stream, as_stream
from ..core._scheduling import BasisFunction, SchedulingSpace
from ..core._validation import as_matrix, as_signal, as_vector, check_positive_definite
from ._text import dependence_table, describe_dependence, format_matrix, matrix_table, number

__all__ = [
    "AffineDependence",
    "AffineLPV",
    "NoiseCovariance",
    "StateSpaceMatrices",
    "LPVTrajectory",
    "CONSTANT_TERM",
]

#: The key of the constant term ``M_0`` in coefficient mappings and model files.
CONSTANT_TERM = "1"

MatrixSpec = np.ndarray | Sequence | Mapping[str, object]


def _canonical(term: str) -> str:
    return Expression.parse(term).source


@dataclass(frozen=True, eq=False)
class AffineDependence:
    """Named matrices affine in basis functions of ``p`` over a scheduling box.

    ``coefficients[name]`` has shape ``(1 + n_psi, rows, cols)``: the constant
    term first, then one matrix per basis function (zeros where a matrix does
    not depend on that function).

    Parameters
    ----------
    space : SchedulingSpace
        The box of scheduling vectors ``p`` the matrices are defined on.
    basis : tuple of BasisFunction, length n_psi
        The basis functions ``psi_i(p)``, with distinct names.
    coefficients : mapping of str to ndarray, shape (1 + n_psi, rows, cols)
        The coefficient stack of each named matrix, as above (made read-only).

    Examples
    --------
    >>> from lpvest.core import SchedulingSpace, Monomial
    >>> space = SchedulingSpace(["theta"], [-1], [1])
    >>> dep = AffineDependence.build(space, [Monomial.component(0, space)],
    ...     {"A": {"1": [[0.5]], "theta": [[0.25]]}})
    >>> dep.evaluate([1.0])["A"]
    array([[0.75]])
    """

    space: SchedulingSpace
    basis: tuple[BasisFunction, ...]
    coefficients: Mapping[str, np.ndarray]
    if TYPE_CHECKING:  # not a field: set in __post_init__ (a frozen class); declared for the type checker only
        _stack: MatrixStack = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n_terms = 1 + len(self.basis)
        names = [b.name for b in self.basis]
        if len(set(names)) != len(names):
            raise ExpressionError(f"basis functions are not unique: {names}")
        for key, stack in self.coefficients.items():
            if stack.ndim != 3 or stack.shape[0] != n_terms:
                raise DimensionError(
                    f"coefficients of {key} have shape {stack.shape}; "
                    f"expected ({n_terms}, rows, cols)"
                )
            stack.setflags(write=False)
        # every matrix at once, the same operations for one sample and a trajectory
        object.__setattr__(self, "_stack", MatrixStack(self.coefficients))

    # -- construction ---------------------------------------------------------
    @classmethod
    def build(
        cls,
        space: SchedulingSpace,
        basis: Sequence[BasisFunction],
        matrices: Mapping[str, MatrixSpec],
        shapes: Mapping[str, tuple[int | None, int | None]] | None = None,
    ) -> AffineDependence:
        """Build from readable specifications.

        Parameters
        ----------
        space : SchedulingSpace
            The box of scheduling vectors ``p``.
        basis : sequence of BasisFunction, length n_psi
            The basis functions ``psi_i(p)``, with distinct names.
        matrices : mapping of str to array_like or mapping
            Each matrix is either an array (constant in ``p``) or a mapping from
            term names (``"1"`` for the constant term, or a basis function's
            name) to coefficient matrices; absent terms are zero.
        shapes : mapping of str to (rows, cols), optional
            Expected shapes (``None`` = any) checked with the matrix's name.

        Returns
        -------
        AffineDependence
            Every matrix as a stack of ``1 + n_psi`` coefficient matrices.
        """
        basis = tuple(basis)
        index = {CONSTANT_TERM: 0}
        for i, b in enumerate(basis):
            index[b.name] = i + 1
            try:
                index.setdefault(_canonical(b.name), i + 1)
            except ExpressionError:
                pass
        coeffs: dict[str, np.ndarray] = {}
        for key, spec in matrices.items():
            shape = (shapes or {}).get(key)
            if isinstance(spec, Mapping):
                terms: dict[int, np.ndarray] = {}
                for term, value in spec.items():
                    pos = index.get(str(term))
                    if pos is None:
                        try:
                            pos = index.get(_canonical(str(term)))
                        except ExpressionError:
                            pos = None
                    if pos is None:
                        known = ", ".join([CONSTANT_TERM] + [b.name for b in basis])
                        raise ExpressionError(
                            f"{key}: term {abbreviate(term, 30)} is not a basis function (known: {known})"
                        )
                    if pos in terms:
                        raise ExpressionError(f"{key}: term {abbreviate(term, 30)} is given twice")
                    label = f"{key}[{term}]"
                    terms[pos] = as_matrix(value, label, shape)
                    shape = terms[pos].shape
                if not terms:
                    raise DimensionError(f"{key} has no terms")
                # shape is now the last term's shape (ints); mypy still sees the given (int | None) pair
                stack = np.zeros((1 + len(basis), *shape))  # type: ignore[misc]  # see above
                for pos, m in terms.items():
                    stack[pos] = m
            else:
                m = as_matrix(spec, key, shape)
                stack = np.zeros((1 + len(basis), *m.shape))
                stack[0] = m
            coeffs[key] = stack
        return cls(space, basis, coeffs)

    # -- evaluation -----------------------------------------------------------
    @property
    def term_names(self) -> tuple[str, ...]:
        return (CONSTANT_TERM, *(b.name for b in self.basis))

    def shape(self, name: str) -> tuple[int, int]:
        """The shape of one matrix.

        Parameters
        ----------
        name : str
            A key of :attr:`coefficients`.

        Returns
        -------
        tuple of int
            ``(rows, cols)`` of the matrix ``name``.
        """
        return self._stack.shapes[name]

    def psi(self, p: np.ndarray, *, check: bool = True) -> np.ndarray:
        """``[1, psi_1(p), ..., psi_n(p)]`` for one scheduling vector.

        Parameters
        ----------
        p : array_like, shape (n_p,)
            The scheduling vector.
        check : bool, default True
            Check ``p`` first (``n_p`` finite values inside the box,
            :meth:`SchedulingSpace.check`); ``False`` uses it as given.

        Returns
        -------
        psi : ndarray, shape (1 + n_psi,)
            The constant 1, then the value of each basis function at ``p``.
        """
        p = self.space.check(p) if check else np.asarray(p, dtype=float)
        out = np.empty(1 + len(self.basis))
        out[0] = 1.0
        for i, b in enumerate(self.basis):
            out[i + 1] = b(p)
        return out

    def psi_batch(self, p: np.ndarray, *, check: bool = True) -> np.ndarray:
        """``psi`` for a trajectory ``p`` of shape ``(T, n_p)``, shape ``(T, 1 + n_psi)``.

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            The scheduling trajectory (shape (T,) when ``n_p = 1``); its shape
            and finiteness are always checked.
        check : bool, default True
            Also check that every sample lies in the box.

        Returns
        -------
        psi : ndarray, shape (T, 1 + n_psi)
            Row ``t`` is :meth:`psi` of ``p[t]``.
        """
        p = as_signal(p, "p", self.space.dim)
        if check:
            for t in range(p.shape[0]):
                self.space.check(p[t], what=f"scheduling value at t={t}:")
        out = np.empty((p.shape[0], 1 + len(self.basis)))
        out[:, 0] = 1.0
        for i, b in enumerate(self.basis):
            out[:, i + 1] = b.evaluate(p)
        return out

    def evaluate(self, p: np.ndarray, *, check: bool = True) -> dict[str, np.ndarray]:
        """Every matrix at one scheduling vector ``p`` (all at once, :class:`~lpvest.core.MatrixStack`).

        Parameters
        ----------
        p : array_like, shape (n_p,)
            The scheduling vector.
        check : bool, default True
            Check ``p`` first, as :meth:`psi` does.

        Returns
        -------
        dict of str to ndarray, shape (rows, cols)
            ``M(p)`` for every name of :attr:`coefficients` (fresh arrays).
        """
        return self.at_psi(self.psi(p, check=check))

    def at_psi(self, psi: np.ndarray) -> dict[str, np.ndarray]:
        """Every matrix for given basis values ``psi = [1, psi_1(p), ...]`` (:meth:`psi`).

        Parameters
        ----------
        psi : ndarray, shape (1 + n_psi,)
            The weights of the coefficient matrices (not checked; entry 0 is
            the constant term's).

        Returns
        -------
        dict of str to ndarray, shape (rows, cols)
            ``sum_i psi[i] M_i`` for every name of :attr:`coefficients` (fresh arrays).
        """
        return self._stack.at(psi)

    def evaluate_batch(self, p: np.ndarray, *, check: bool = True) -> dict[str, np.ndarray]:
        """Every matrix along a trajectory ``p`` (T, n_p): arrays ``(T, rows, cols)``;
        row ``t`` is :meth:`evaluate` of ``p[t]`` to the bit.

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            The scheduling trajectory.
        check : bool, default True
            Check that every sample lies in the box (:meth:`psi_batch`).

        Returns
        -------
        dict of str to ndarray, shape (T, rows, cols)
            Every matrix of :attr:`coefficients` along ``p``.
        """
        return self._stack.at_batch(self.psi_batch(p, check=check))

    def subset(self, names: Sequence[str]) -> AffineDependence:
        """The dependence restricted to ``names``.

        Parameters
        ----------
        names : sequence of str
            Keys of :attr:`coefficients` to keep, in this order.

        Returns
        -------
        AffineDependence
            The same space and basis with only those matrices (their
            coefficient arrays shared, not copied).
        """
        return AffineDependence(self.space, self.basis, {n: self.coefficients[n] for n in names})


class StateSpaceMatrices(NamedTuple):
    """The matrices of (1) at one scheduling value (or stacked along time).

    Parameters
    ----------
    A : ndarray, shape (n_x, n_x) or (T, n_x, n_x)
        State matrix ``A(p)``.
    B : ndarray, shape (n_x, n_u) or (T, n_x, n_u)
        Input matrix ``B(p)`` (no columns without an input).
    C : ndarray, shape (n_y, n_x) or (T, n_y, n_x)
        Output matrix ``C(p)``.
    D : ndarray, shape (n_y, n_u) or (T, n_y, n_u)
        Feedthrough matrix ``D(p)``.
    G : ndarray, shape (n_x, n_w) or (T, n_x, n_w)
        Process-noise matrix ``G(p)``.
    H : ndarray, shape (n_y, n_v) or (T, n_y, n_v)
        Measurement-noise matrix ``H(p)``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    G: np.ndarray
    H: np.ndarray


class LPVTrajectory(NamedTuple):
    """A simulated trajectory; row ``t`` holds time ``t``.

    Parameters
    ----------
    x : ndarray, shape (T, n_x)
        States ``x_t``.
    y : ndarray, shape (T, n_y)
        Outputs ``y_t``.
    w : ndarray, shape (T, n_w)
        Process noise ``w_t``.
    v : ndarray, shape (T, n_v)
        Measurement noise ``v_t``.
    """

    x: np.ndarray
    y: np.ndarray
    w: np.ndarray
    v: np.ndarray


@dataclass(frozen=True, eq=False)
class NoiseCovariance:
    """Joint covariance ``[[Q, S], [S^T, R]]`` of ``(w_t, v_t)``, eq. (2).

    The joint matrix must be symmetric positive definite (checked with a
    tolerance relative to its scale).

    Parameters
    ----------
    Q : array_like, shape (n_w, n_w)
        Covariance of the process noise ``w_t`` (positive definite).
    R : array_like, shape (n_v, n_v)
        Covariance of the measurement noise ``v_t`` (positive definite).
    S : array_like, shape (n_w, n_v), optional
        Cross-covariance ``E[w_t v_t^T]`` (default zero).
    """

    Q: np.ndarray
    S: np.ndarray
    R: np.ndarray

    def __init__(self, Q: object, R: object, S: object | None = None) -> None:
        q = as_matrix(Q, "Q")
        r = as_matrix(R, "R")
        if q.shape[0] != q.shape[1]:
            raise DimensionError(f"Q has shape {q.shape}; expected a square matrix")
        if r.shape[0] != r.shape[1]:
            raise DimensionError(f"R has shape {r.shape}; expected a square matrix")
        s = np.zeros((q.shape[0], r.shape[0])) if S is None else as_matrix(S, "S", (q.shape[0], r.shape[0]))
        joint = np.block([[q, s], [s.T, r]])
        check_positive_definite(q, "Q")
        check_positive_definite(r, "R")
        check_positive_definite(joint, "the joint noise covariance [[Q, S], [S^T, R]]")
        for name, m in (("Q", q), ("S", s), ("R", r)):
            m.setflags(write=False)
            object.__setattr__(self, name, m)

    @property
    def joint(self) -> np.ndarray:
        return np.block([[self.Q, self.S], [self.S.T, self.R]])

    def sample(self, rng: Stream | np.random.Generator | int, size: int) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``size`` samples of ``(w, v)``.

        Each sample is ``[w; v] = L z`` with ``L L^T = [[Q, S], [S^T, R]]``
        (Cholesky) and ``z ~ N(0, I)`` from lpvest's stream
        (:meth:`lpvest.core.Stream.correlated`).

        Parameters
        ----------
        rng : lpvest.core.Stream, numpy.random.Generator or int
            The random source (``size`` standard normal vectors of length
            ``n_w + n_v`` are drawn from it; a Generator or seed as
            :func:`lpvest.core.as_stream` takes it).
        size : int
            The number of samples.

        Returns
        -------
        w : ndarray, shape (size, n_w)
            Process noise samples.
        v : ndarray, shape (size, n_v)
            Measurement noise samples.
        """
        L = np.linalg.cholesky(self.joint)
        z = as_stream(rng).correlated(L, size)
        nw = self.Q.shape[0]
        return z[:, :nw], z[:, nw:]


_MATRIX_NAMES = ("A", "B", "C", "D", "G", "H")


@dataclass(frozen=True, eq=False)
class AffineLPV:
    """Discrete-time LPV state-space model with general noise, eqs. (1)-(3) of
    000_dc6273d4fec795cd.txt.

    Build one with :meth:`from_matrices`. ``x0`` and ``P0`` are the mean and
    covariance of the initial state (default: known zero state, as the paper
    assumes).

    Parameters
    ----------
    dependence : AffineDependence
        ``A, B, C, D, G, H`` affine in the basis functions of ``p`` (all six,
        of consistent shapes).
    noise : NoiseCovariance
        The joint covariance of ``(w_t, v_t)``, eq. (2).
    x0 : ndarray, shape (n_x,)
        Mean of the initial state.
    P0 : ndarray, shape (n_x, n_x)
        Covariance of the initial state.
    name : str, default ""
        The model's name in error messages (a model file gives ``system/key``).
    Cz : ndarray, shape (n_z, n_x) or None, default None
        ``Cz`` of the signal ``z = Cz x`` the H-infinity filters estimate
        (:func:`lpvest.systems.hinf_setting`); ``None``: every state.

    Examples
    --------
    >>> from lpvest.core import SchedulingSpace, Monomial
    >>> space = SchedulingSpace(["p"], [-1], [1])
    >>> model = AffineLPV.from_matrices(space, [Monomial.component(0, space)],
    ...     A={"1": [[0.5]], "p": [[0.2]]}, C=[[1.0]], Q=[[0.1]], R=[[0.01]])
    >>> model.at([0.5]).A
    array([[0.6]])
    >>> traj = model.simulate(np.full((100, 1), 0.5), rng=0)
    >>> traj.y.shape
    (100, 1)
    """

    dependence: AffineDependence
    noise: NoiseCovariance
    x0: np.ndarray
    P0: np.ndarray
    name: str = ""
    Cz: np.ndarray | None = None

    def __post_init__(self) -> None:
        dep = self.dependence
        missing = [n for n in _MATRIX_NAMES if n not in dep.coefficients]
        if missing:
            raise DimensionError(f"AffineLPV needs matrices {missing}")
        nx = dep.shape("A")[0]
        nu = dep.shape("B")[1]
        ny = dep.shape("C")[0]
        nw, nv = self.noise.Q.shape[0], self.noise.R.shape[0]
        expected = {
            "A": (nx, nx),
            "B": (nx, nu),
            "C": (ny, nx),
            "D": (ny, nu),
            "G": (nx, nw),
            "H": (ny, nv),
        }
        for n, shp in expected.items():
            if dep.shape(n) != shp:
                raise DimensionError(f"{n} has shape {dep.shape(n)}; expected {shp}")
        if self.x0.shape != (nx,):
            raise DimensionError(f"x0 has shape {self.x0.shape}; expected ({nx},)")
        if self.P0.shape != (nx, nx):
            raise DimensionError(f"P0 has shape {self.P0.shape}; expected ({nx}, {nx})")
        if self.Cz is not None and (self.Cz.ndim != 2 or self.Cz.shape[1] != nx or self.Cz.shape[0] < 1):
            raise DimensionError(f"Cz has shape {self.Cz.shape}; expected (n_z, {nx})")

    @classmethod
    def from_matrices(
        cls,
        space: SchedulingSpace,
        basis: Sequence[BasisFunction],
        *,
        A: MatrixSpec,
        C: MatrixSpec,
        Q: object,
        R: object,
        B: MatrixSpec | None = None,
        D: MatrixSpec | None = None,
        G: MatrixSpec | None = None,
        H: MatrixSpec | None = None,
        S: object | None = None,
        x0: object | None = None,
        P0: object | None = None,
        name: str = "",
        Cz: object | None = None,
    ) -> AffineLPV:
        """Build the model; each matrix is an array (constant) or a mapping of
        term name to coefficient (see :meth:`AffineDependence.build`).

        Defaults: no input (``B``, ``D`` with zero columns), ``G = I``,
        ``H = I``, ``S = 0``, ``x0 = 0``, ``P0 = 0``, ``Cz``: every state is
        what an H-infinity filter estimates.

        Parameters
        ----------
        space : SchedulingSpace
            The box of scheduling vectors ``p``.
        basis : sequence of BasisFunction, length n_psi
            The basis functions ``psi_i(p)`` the matrices are affine in.
        A : array_like or mapping, shape (n_x, n_x)
            State matrix ``A(p)``.
        C : array_like or mapping, shape (n_y, n_x)
            Output matrix ``C(p)``.
        Q : array_like, shape (n_w, n_w)
            Process noise covariance, eq. (2).
        R : array_like, shape (n_v, n_v)
            Measurement noise covariance, eq. (2).
        B : array_like or mapping, shape (n_x, n_u), optional
            Input matrix ``B(p)``; ``n_u`` is its number of columns (else that
            of ``D``, else 0).
        D : array_like or mapping, shape (n_y, n_u), optional
            Feedthrough matrix ``D(p)`` (default zero).
        G : array_like or mapping, shape (n_x, n_w), optional
            Process-noise matrix ``G(p)`` (default the identity, which needs
            ``n_w = n_x``).
        H : array_like or mapping, shape (n_y, n_v), optional
            Measurement-noise matrix ``H(p)`` (default the identity, which
            needs ``n_v = n_y``).
        S : array_like, shape (n_w, n_v), optional
            Cross-covariance of ``w_t`` and ``v_t`` (default zero).
        x0 : array_like, shape (n_x,), optional
            Mean of the initial state (default zero).
        P0 : array_like, shape (n_x, n_x), optional
            Covariance of the initial state, positive semidefinite (default
            zero: a known initial state).
        name : str, default ""
            The model's name in error messages.
        Cz : array_like, shape (n_z, n_x), optional
            The signal ``z = Cz x`` the H-infinity filters estimate.

        Returns
        -------
        AffineLPV
            The checked model.
        """
        noise = NoiseCovariance(Q, R, S)
        nw, nv = noise.Q.shape[0], noise.R.shape[0]
        pre = AffineDependence.build(space, basis, {"A": A, "C": C})
        nx, ny = pre.shape("A")[0], pre.shape("C")[0]
        if pre.shape("A") != (nx, nx):
            raise DimensionError(f"A has shape {pre.shape('A')}; expected a square matrix")
        if B is not None:
            nu = AffineDependence.build(space, basis, {"B": B}, {"B": (nx, None)}).shape("B")[1]
        elif D is not None:
            nu = AffineDependence.build(space, basis, {"D": D}, {"D": (ny, None)}).shape("D")[1]
        else:
            nu = 0
        specs = {
            "A": A,
            "B": np.zeros((nx, nu)) if B is None else B,
            "C": C,
            "D": np.zeros((ny, nu)) if D is None else D,
            "G": np.eye(nx) if G is None else G,
            "H": np.eye(ny) if H is None else H,
        }
        shapes = {
            "A": (nx, nx),
            "B": (nx, nu),
            "C": (ny, nx),
            "D": (ny, nu),
            "G": (nx, nw),
            "H": (ny, nv),
        }
        dep = AffineDependence.build(space, basis, specs, shapes)
        x0v = np.zeros(nx) if x0 is None else as_vector(x0, "x0", nx)
        P0m = np.zeros((nx, nx)) if P0 is None else as_matrix(P0, "P0", (nx, nx))
        if P0 is not None:
            P0m = check_positive_definite(P0m, "P0", semidefinite=True)
        Czm = None if Cz is None else as_matrix(Cz, "Cz", (None, nx))
        for m in (x0v, P0m, Czm):  # fresh copies, shared by whoever uses the model: read-only
            if m is not None:
                m.setflags(write=False)
        return cls(dep, noise, x0v, P0m, name, Czm)

    # -- dimensions -----------------------------------------------------------
    @property
    def space(self) -> SchedulingSpace:
        return self.dependence.space

    @property
    def basis(self) -> tuple[BasisFunction, ...]:
        return self.dependence.basis

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
    def nw(self) -> int:
        return self.noise.Q.shape[0]

    @property
    def nv(self) -> int:
        return self.noise.R.shape[0]

    @property
    def n_p(self) -> int:
        return self.space.dim

    # -- evaluation -----------------------------------------------------------
    def at(self, p: object, *, check: bool = True) -> StateSpaceMatrices:
        """The matrices at one scheduling vector ``p`` (range-checked).

        Parameters
        ----------
        p : array_like, shape (n_p,)
            The scheduling vector.
        check : bool, default True
            Check ``p`` (``n_p`` finite values inside the box); ``False``
            skips every check.

        Returns
        -------
        StateSpaceMatrices
            ``A, B, C, D, G, H`` at ``p``.
        """
        m = self.dependence.evaluate(np.asarray(p, dtype=float), check=check)
        return StateSpaceMatrices(*(m[n] for n in _MATRIX_NAMES))

    def at_batch(self, p: object, *, check: bool = True) -> StateSpaceMatrices:
        """The matrices along a scheduling trajectory ``p`` of shape (T, n_p),
        each stacked to shape ``(T, rows, cols)``.

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            The scheduling trajectory (its shape and finiteness always checked).
        check : bool, default True
            Also check that every sample lies in the box.

        Returns
        -------
        StateSpaceMatrices
            ``A, B, C, D, G, H`` along ``p``, each of shape ``(T, rows, cols)``.
        """
        m = self.dependence.evaluate_batch(np.asarray(p, dtype=float), check=check)
        return StateSpaceMatrices(*(m[n] for n in _MATRIX_NAMES))

    # -- simulation -----------------------------------------------------------
    def simulate(
        self,
        p: object,
        u: object | None = None,
        *,
        w: object | None = None,
        v: object | None = None,
        x0: object | None = None,
        rng: np.random.Generator | int | None = None,
    ) -> LPVTrajectory:
        """Simulate (1) along the scheduling trajectory ``p``.

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            Scheduling trajectory (each sample range-checked).
        u : array_like, shape (T, n_u), optional
            Input (zero when omitted).
        w, v : array_like, shapes (T, n_w) and (T, n_v), optional
            Noise sequences; both or neither. When omitted they are drawn from
            ``N(0, Sigma)`` with ``rng``.
        x0 : array_like, shape (n_x,), optional
            Initial state. Default: the model's mean ``x0`` when the noise is
            given, a draw from ``N(x0, P0)`` when the noise is drawn.
        rng : numpy.random.Generator or int, optional
            Random source (or its seed) for the noise and the initial state;
            not used when ``w`` and ``v`` are given. ``None``: fresh entropy.

        Returns
        -------
        LPVTrajectory
            The states and outputs at ``t = 0..T-1`` and the noise that
            drove them (given or drawn).
        """
        p = as_signal(p, "p", self.n_p)
        T = p.shape[0]
        u = as_signal(u if u is not None else np.zeros((T, self.nu)), "u", self.nu, T)
        if (w is None) != (v is None):
            raise DimensionError("give both noise sequences w and v, or neither")
        if w is None:
            # the initial state first, then the noise in time order: the same
            # draws as the streaming plant (lpvest.systems.DiscretePlant)
            gen = as_stream(rng)
            if x0 is None:
                x0 = gen.gaussian_vector(self.x0, self.P0) if np.any(self.P0) else self.x0
            w, v = self.noise.sample(gen, T)
        else:
            w = as_signal(w, "w", self.nw, T)
            v = as_signal(v, "v", self.nv, T)
        x = self.x0 if x0 is None else as_vector(x0, "x0", self.nx)
        psi = self.dependence.psi_batch(p)  # range-checked
        X = np.empty((T, self.nx))
        Y = np.empty((T, self.ny))
        for t in range(T):
            X[t] = x
            Y[t], x = self.step(x, psi[t], u[t], w[t], v[t])
        return LPVTrajectory(X, Y, np.asarray(w), np.asarray(v))

    def step(
        self, x: np.ndarray, psi: np.ndarray, u: np.ndarray, w: np.ndarray, v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """One sample of (1)-(2), a pure function: ``(y_t, x_{t+1})`` from the
        state ``x_t`` (n_x,), the basis values ``psi_t = [1, psi_1(p_t), ...]``
        (:meth:`AffineDependence.psi`), the input ``u_t`` and the noise ``w_t``,
        ``v_t``.

        :meth:`simulate`, the streaming plant and the Plant FMU all call it.

        Parameters
        ----------
        x : ndarray, shape (n_x,)
            The state ``x_t``.
        psi : ndarray, shape (1 + n_psi,)
            The basis values ``psi_t`` (not checked).
        u : ndarray, shape (n_u,)
            The input ``u_t``.
        w : ndarray, shape (n_w,)
            The process noise ``w_t``.
        v : ndarray, shape (n_v,)
            The measurement noise ``v_t``.

        Returns
        -------
        y : ndarray, shape (n_y,)
            The output ``y_t``.
        x_next : ndarray, shape (n_x,)
            The next state ``x_{t+1}``.
        """
        m = self.dependence.at_psi(psi)
        return m["C"] @ x + m["D"] @ u + m["H"] @ v, m["A"] @ x + m["B"] @ u + m["G"] @ w


    # -- text forms ---------------------------------------------------------------------
    def to_toml(self) -> dict[str, object]:
        """This model as the ``[models.KEY]`` table of a model file (:mod:`lpvest.systems`).

        Returns
        -------
        dict of str to object
            ``type = "affine"``, the basis and matrices
            (:func:`~lpvest.systems._affine.dependence_table`), ``Q``, ``R``,
            ``S``, ``x0``, ``P0`` and, when set, ``Cz``.
        """
        out: dict[str, object] = {"type": "affine", **dependence_table(self.dependence)}
        out.update(Q=matrix_table(self.noise.Q), R=matrix_table(self.noise.R), S=matrix_table(self.noise.S))
        out.update(x0=[number(v) for v in self.x0], P0=matrix_table(self.P0))
        if self.Cz is not None:
            out["Cz"] = matrix_table(self.Cz)
        return out

    def describe(self, key: str) -> list[str]:
        """Lines for a person (``lpvest systems show``): type, dimensions, matrices.

        Parameters
        ----------
        key : str
            The model's key in its model file, named in the first line.

        Returns
        -------
        list of str
            The lines, indented, without line ends.
        """
        lines = [f"  model {key}: affine LPV with general noise (Cox & Toth (1)-(3))",
                 f"    n_x={self.nx} n_u={self.nu} n_y={self.ny} n_w={self.nw} n_v={self.nv} n_p={self.n_p}"]
        lines += describe_dependence(self.dependence)
        for name in ("Q", "S", "R"):
            lines += [f"    {name}", format_matrix(getattr(self.noise, name))]
        if self.Cz is not None:
            lines += ["    Cz (z = Cz x, estimated by the H-infinity filters)", format_matrix(self.Cz)]
        return lines
