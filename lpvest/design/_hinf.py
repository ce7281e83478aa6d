r"""H-infinity filter design by LMIs: Theorem 1 and Corollary 1 of Peixoto et al.

Paper: 001_00f62b5a0c49ad87.txt ("A novel H-infinity filter design condition for
discrete-time LPV systems"). For the polytopic plant (1) and the filter (2),
the LMIs (6)-(7) certify ``||e||_2 < gamma ||w||_2`` (zero initial state) for
every parameter sequence ``alpha_k`` on the simplex, varying arbitrarily fast.
:func:`design_hinf` solves them at a given ``epsilon``; :func:`search_epsilon`
finds the best ``epsilon`` over the whole real line (and its limit
``epsilon -> infinity``); :func:`epsilon_curve` gives ``gamma(epsilon)``.

How the LMIs are built (and where they differ from the printed text)
--------------------------------------------------------------------
Every block comes from the proof, which is Finsler's lemma: with
``zeta = (x_{k+1}, x_{f,k+1}, x_k, x_{f,k}, e_k, w_k)`` (block sizes
``nx, nx, nx, nx, nz, nw``), the closed loop (3) is ``G zeta = 0`` with ::

    G = [[-I,  0,  A,              0,   0,  Bw            ],   x_{k+1} = A x + Bw w
         [ 0, -H,  Bf Cy,          Af,  0,  Bf Dy         ],   H x_{f,k+1} = Af x_f + Bf y
         [ 0,  0,  Cz - Df Cy,    -Cf, -I,  Dz - Df Dy    ]]   e = z - z_f

and the dissipation inequality ``V(xi_{k+1}) - V(xi_k) + e'e - delta w'w < 0``
is ``zeta' Q zeta < 0`` with ``Q = diag(P(alpha_{k+1}), -P(alpha_k), I, -delta I)``,
``P = [[P1, P3], [P3', P2]]``. Finsler: ``Q + He{X G} < 0`` implies it on
``ker G``, for the multiplier ::

    X = [[X1, a I, 0], [X2, I, 0], [X3, b I, 0], [X4, 0, 0], [X5, 0, I], [X6, 0, 0]].

With ``(a, b) = (epsilon, 1)`` this is the paper's ``Phi`` block for block,
except ``Phi_21``: it is ``-X2 - eps H' + P3(alpha_{k+1})'`` (vertex ``l``),
not ``P_{3,j}'`` as printed (``test_hinf_design.py`` checks the identity on
random data, and shows that the printed block certifies a gamma far below the
filter's true worst-case gain).

Two further deviations, both sound:

* **Exact rescaling.** At large ``epsilon`` the printed LMIs are badly
  conditioned (the filter variables scale like ``1/epsilon`` and
  ``1/epsilon^2``). Take ``(a, b)`` with ``a / b = epsilon``, ``s = 1/b``, the
  congruence ``T = diag(I, sI, I, sI, I, I)`` and the change of variables
  ``P2 -> s^2 P2``, ``P3, X2, X4 -> s (.)``, ``H, Af -> s^2 (.)``,
  ``Bf, Cf -> s (.)`` (the others unchanged). Block by block, ``T Phi T`` of
  the paper's LMI at ``epsilon`` is the LMI above at ``(a, b)`` in the new
  variables (e.g. ``s (-X2 - eps H' + P3') = -X2^ - a H^' + P3^'`` and
  ``s (-H + ...) = -b H^ + ...``). ``T`` is nonsingular and the variable map is
  a bijection, ``T diag(P, P) T > 0`` iff ``P > 0``, and ``delta`` is
  untouched: both problems have the same feasible ``delta``, hence the same
  optimal ``gamma``. The new filter matrices are the same filter in the state
  coordinates ``x_f / s = b x_f`` (``H^-1 Af`` is unchanged, ``H^-1 Bf`` and
  ``Cf`` scale by ``1/s`` and ``s``): same input-output map, same ``gamma``.
  We use ``a = sin(phi)``, ``b = cos(phi)``, ``epsilon = tan(phi)``: every
  coefficient is at most 1 in size, and ``b = 0`` is the limit
  ``epsilon -> infinity`` (still a valid Finsler multiplier, so its ``gamma``
  is certified too). ``a`` and ``b`` enter as ``cp.Parameter`` (with the
  plant's vertex matrices), so a program compiles once (DPP) and serves every
  ``epsilon`` and every plant of the same dimensions. ``test_hinf_design.py``
  checks ``Phi_paper = T^-1 Phi T^-1`` at a solution and that both
  realizations filter identically.
* **P(alpha) > 0.** The proof needs ``V >= 0``; ``P1, P2 > 0`` alone do not
  give it (an unstable plant can satisfy the LMIs with an indefinite ``P``).
  We impose ``P_i > 0`` at each vertex. When the plant is stable under
  arbitrary switching this loses nothing: the LMIs then make ``V`` strictly
  decrease along every trajectory of a stable system, hence ``V > 0``.

**Dual bound.** Every solve also gives a lower bound on the best ``gamma``
at its ``epsilon`` (``gamma_lower`` of :class:`DesignAttempt` and
:class:`EpsilonCurve`). The bound is for the strict LMIs themselves (margin
0), which every certified design satisfies whatever margin it was solved
with. Write them as ``G_i(x) <= 0``, ``G_i`` affine (``M_i(x)`` for the LMIs,
``-P_j(x)`` for the Lyapunov matrices), and the program as ``min delta``. For
duals ``Z_i >= 0`` the Lagrangian ``L(x, Z) = delta(x) + sum_i <Z_i, G_i(x)>``
is affine in ``x``; at a dual-feasible ``Z`` (stationarity: its linear part
vanishes) it is the same number for every ``x``, the dual function ``g(Z)``,
and weak duality gives ``g(Z) <= delta`` at every feasible point. So
``L(x_k, Z_k)`` at the solver's returned pair is the bound, up to the solver's
dual residual. The solver's duals are those of the program with margin
``m``, whose dual function is ``g(Z) + m sum_i tr Z_i``: ``delta_k - L(x_k,
Z_k)`` is the complementarity gap plus ``m sum_i tr Z_i``, the first-order
cost of the margin (on Peixoto et al.'s Example 1 with Clarabel about 1e-8 and
1e-4 relative; on a 4-vertex plant with SCS about 1e-5 and 1e-6).
``tests/test_hinf_design.py`` checks the bound against solves with margins
10 and 100 times smaller. :func:`search_epsilon` uses it to tell a curve that
is flat to the solver's accuracy from one that slopes.

The Lemma 1 relaxation (``Phi_iil < 0``, ``Phi_ijl + Phi_jil < 0`` for
``i < j``) is applied for any number of vertices ``N``: ``N^2 (N + 1) / 2``
LMIs of size ``4 nx + nz + nw``. Strict inequalities are ``M << -margin I``.
Every returned point is checked: the eigenvalues of every assembled LMI and of
every ``P_i`` (numpy, float64) must be strictly negative / positive. A failed
check is retried with tighter solver settings, then raises
:class:`~lpvest.core.LMIInfeasibleError`.
"""

from __future__ import annotations

import contextlib
import functools
import math
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..core._errors import (
    ArgumentError,
    ArgumentTypeError,
    DimensionError,
    InternalError,
    LMIInfeasibleError,
    NonFiniteError,
    abbreviate,
)
from ..systems._affine import AffineLPV
from ..systems._polytopic import PolytopicLPV, hinf_setting
from ._result import KIND_PD, KIND_ROBUST, HinfDesign, model_digest

__all__ = [
    "design_hinf",
    "search_epsilon",
    "epsilon_curve",
    "HinfProgram",
    "EpsilonCurve",
    "EpsilonSearch",
    "multiplier",
    "lmi_matrices",
    "LMIBlock",
    "DesignAttempt",
    "DEFAULT_SOLVER",
    "DEFAULT_MARGIN",
    "AUTO_CLARABEL_MAX_ROWS",
    "choose_solver",
    "check_solver",
    "sdp_solvers",
]

#: Solver used unless told otherwise: ``"AUTO"`` picks by problem size (see
#: :func:`choose_solver`).
DEFAULT_SOLVER = "AUTO"
#: ``"AUTO"`` takes Clarabel up to this many scalar rows of PSD constraints,
#: SCS above.
AUTO_CLARABEL_MAX_ROWS = 4000
#: Strict LMIs are imposed as ``M << -DEFAULT_MARGIN * I`` (``P_i >> margin I``).
DEFAULT_MARGIN = 1e-6

#: Solver settings used unless the caller overrides them: one thread is about
#: twice as fast as two for these small problems.
_DEFAULT_OPTIONS: dict[str, dict[str, Any]] = {"CLARABEL": {"max_threads": 1}}

#: A point that fails the check is solved again with the margin this much larger.
RETRY_MARGIN_FACTOR = 30.0

_ACCEPTED = ("optimal", "optimal_inaccurate")


def sdp_solvers() -> list[str]:
    """The installed cvxpy solvers that handle semidefinite constraints (the
    LMIs), e.g. ``["CLARABEL", "SCS"]``."""
    from cvxpy.reductions.solvers import defines

    return [name for name in defines.INSTALLED_CONIC_SOLVERS
            if any(c.__name__ in ("PSD", "SvecPSD") for c in defines.SOLVER_MAP_CONIC[name].SUPPORTED_CONSTRAINTS)]


def check_solver(solver: object) -> str:
    """``solver`` upper-cased if it is ``"AUTO"`` or an installed solver of
    semidefinite programs; else :class:`~lpvest.core.ArgumentError` naming
    them (before anything is compiled or solved).

    Examples
    --------
    >>> check_solver("clarabel")
    'CLARABEL'
    """
    name = str(solver).upper() if isinstance(solver, str) else ""
    known = sdp_solvers()
    if name != "AUTO" and name not in known:
        raise ArgumentError(f"solver {abbreviate(solver, 30)}: expected AUTO or an installed cvxpy solver of "
                            f"semidefinite programs ({', '.join(known) or 'none installed'})")
    return name


def choose_solver(n_vertices: int, nx: int, nz: int, nw: int, kind: str = KIND_PD) -> str:
    """The solver ``"AUTO"`` stands for, by the size of the LMI program.

    Clarabel (interior point, accurate to ~1e-8) factors at every iteration
    the KKT system of the primal problem, in which each LMI of size
    ``s = 4 nx + nz + nw`` is a dense block of ``s (s + 1) / 2`` rows and the
    decision variables (shared by many LMIs) couple the blocks: 0.1-0.3 s per
    design for Examples 1-2 (6 LMIs, 330-396 rows), 2 s for a 3-vertex,
    3-state plant (18 LMIs, 2,448 rows), but 38 s (17 iterations of 2.2 s) for
    a 3-state plant with 4 vertices (40 LMIs of size 20, 8,400 rows). The same
    problem in dual form costs 0.3 s per iteration, but its feasible set has
    no interior (the filter's state coordinates are free: the optimal set is
    unbounded) and Clarabel stops with a numerical error. SCS (first-order,
    one sparse factorization per solve) takes 0.5-2 s on the 4-vertex plant,
    with gamma within ~1e-4 (relative) of Clarabel's, and warm-starts along an
    epsilon search; where its answer fails the eigenvalue check, even with
    the larger margin, a single design falls back to Clarabel (a search goes
    on with its other points). Every design is certified by the eigenvalue
    check whichever solver made it.

    Parameters
    ----------
    n_vertices, nx, nz, nw : int
        Plant dimensions ``N, nx, nz, nw``: ``N^2 (N + 1) / 2`` LMIs of size ``s = 4 nx + nz + nw``
        (``ny`` does not enter).
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Filter kind; it does not change the choice (Theorem 1 and Corollary 1 have the same LMIs).

    Returns
    -------
    str
        ``"CLARABEL"`` when the LMIs have at most ``AUTO_CLARABEL_MAX_ROWS`` (4000) scalar rows
        ``s (s + 1) / 2`` in all, ``"SCS"`` above.

    Examples
    --------
    >>> choose_solver(2, 2, 2, 1)   # Peixoto Example 1: 6 LMIs of size 11
    'CLARABEL'
    >>> choose_solver(4, 3, 3, 5)   # 3 states, 4 vertices: 40 LMIs of size 20
    'SCS'
    """
    n_lmis = n_vertices * n_vertices * (n_vertices + 1) // 2
    size = 4 * nx + nz + nw
    rows = n_lmis * size * (size + 1) // 2
    return "CLARABEL" if rows <= AUTO_CLARABEL_MAX_ROWS else "SCS"


# ---------------------------------------------------------------------------
# epsilon <-> multiplier
# ---------------------------------------------------------------------------
def multiplier(epsilon: float) -> tuple[float, float]:
    """The normalized multiplier ``(a, b) = (sin phi, cos phi)``, ``phi = atan(epsilon)``.

    ``epsilon = a / b``; ``epsilon = +-inf`` gives ``(1, 0)``.

    Parameters
    ----------
    epsilon : float
        The paper's scalar: any real number, or ``+-math.inf``.

    Returns
    -------
    a : float
        ``sin phi = epsilon / sqrt(1 + epsilon^2)``.
    b : float
        ``cos phi = 1 / sqrt(1 + epsilon^2)``, in ``[0, 1]`` (0 for an infinite ``epsilon``).

    Raises
    ------
    NonFiniteError
        ``epsilon`` is NaN.

    Examples
    --------
    >>> multiplier(0.0)
    (0.0, 1.0)
    >>> multiplier(float("inf"))
    (1.0, 0.0)
    """
    eps = float(epsilon)
    if math.isnan(eps):
        raise NonFiniteError("epsilon is NaN")
    if math.isinf(eps):
        return (1.0, 0.0)
    r = math.hypot(1.0, eps)
    return (eps / r, 1.0 / r)


def _canonical_phi(phi: float) -> float:
    """``phi`` modulo pi, in ``(-pi/2, pi/2]``."""
    p = math.remainder(phi, math.pi)  # in [-pi/2, pi/2]
    return math.pi / 2 if p <= -math.pi / 2 + 1e-15 else p


def _epsilon_of_phi(phi: float) -> float:
    p = _canonical_phi(phi)
    return math.inf if abs(math.pi / 2 - p) < 1e-12 else math.tan(p)


def _ab_of_phi(phi: float) -> tuple[float, float]:
    p = _canonical_phi(phi)
    if abs(math.pi / 2 - p) < 1e-12:
        return (1.0, 0.0)
    return (math.sin(p), math.cos(p))


# ---------------------------------------------------------------------------
# the LMIs, written once for numpy arrays and for cvxpy expressions
# ---------------------------------------------------------------------------
def _xg_rows(d: Mapping[str, Any], v: Mapping[str, Any], a: Any, b: Any) -> list[list[Any]]:
    """The 6 x 6 blocks of ``X G`` (see the module documentation) for plant
    vertex data ``d`` (with ``aCy = a Cy`` etc. precomputed, so that cvxpy sees
    parameter x variable products only) and variables ``v`` of one vertex."""
    nx, nw = d["Bw"].shape
    nz = d["Cz"].shape[0]
    X1, X2, X3, X4, X5, X6 = (v[k] for k in ("X1", "X2", "X3", "X4", "X5", "X6"))
    H, Af, Bf, Cf, Df = (v[k] for k in ("H", "Af", "Bf", "Cf", "Df"))
    A, Bw, Cz, Dz, Cy, Dy = (d[k] for k in ("A", "Bw", "Cz", "Dz", "Cy", "Dy"))
    zxx, zxz = np.zeros((nx, nx)), np.zeros((nx, nz))
    zzx, zwx, zwz = np.zeros((nz, nx)), np.zeros((nw, nx)), np.zeros((nw, nz))
    return [
        [-X1, -a * H, X1 @ A + Bf @ d["aCy"], a * Af, zxz, X1 @ Bw + Bf @ d["aDy"]],
        [-X2, -H, X2 @ A + Bf @ Cy, Af, zxz, X2 @ Bw + Bf @ Dy],
        [-X3, -b * H, X3 @ A + Bf @ d["bCy"], b * Af, zxz, X3 @ Bw + Bf @ d["bDy"]],
        [-X4, zxx, X4 @ A, zxx, zxz, X4 @ Bw],
        [-X5, zzx, X5 @ A + Cz - Df @ Cy, -Cf, -np.eye(nz), X5 @ Bw + Dz - Df @ Dy],
        [-X6, zwx, X6 @ A, zwx, zwz, X6 @ Bw],
    ]


def _q_next(P1: Any, P2: Any, P3: Any, n_rest: int, bmat: Callable[[list[list[Any]]], Any]) -> Any:
    """``diag(P(alpha_{k+1}), 0)``: the ``V(xi_{k+1})`` part of ``Q``."""
    nx = P3.shape[0]
    z = np.zeros((2 * nx, n_rest))
    return bmat([[bmat([[P1, P3], [P3.T, P2]]), z], [z.T, np.zeros((n_rest, n_rest))]])


def _q_now(P1: Any, P2: Any, P3: Any, delta: Any, nz: int, nw: int, bmat: Callable[..., Any]) -> Any:
    """``diag(0, -P(alpha_k), I, -delta I)``: the rest of ``Q``."""
    nx = P3.shape[0]
    zxx = np.zeros((nx, nx))
    zxz, zxw, zzw = np.zeros((nx, nz)), np.zeros((nx, nw)), np.zeros((nz, nw))
    rows = [
        [zxx, zxx, zxx, zxx, zxz, zxw],
        [zxx, zxx, zxx, zxx, zxz, zxw],
        [zxx, zxx, -P1, -P3, zxz, zxw],
        [zxx, zxx, -P3.T, -P2, zxz, zxw],
        [zxz.T, zxz.T, zxz.T, zxz.T, np.eye(nz), zzw],
        [zxw.T, zxw.T, zxw.T, zxw.T, zzw.T, -delta * np.eye(nw)],
    ]
    return bmat(rows)


class LMIBlock(NamedTuple):
    """One LMI of (6)-(7): ``matrix < 0`` with ``matrix = Phi_iil`` (``i == j``)
    or ``Phi_ijl + Phi_jil`` (``i < j``); indices are 0-based.

    Parameters
    ----------
    label : str
        ``"Phi_iil"`` or ``"Phi_ijl + Phi_jil"`` with the paper's 1-based indices (e.g. ``"Phi_121 + Phi_211"``).
    i, j : int
        Vertices (``i <= j``) of ``alpha_k`` in Lemma 1's products ``alpha_i alpha_j``; in ``Phi_ijl`` the
        plant's matrices are those of vertex ``i`` and the decision variables (``X``, ``P(alpha_k)``, the
        filter's) those of vertex ``j``.
    l : int
        Vertex of ``alpha_{k+1}``: ``P(alpha_{k+1})`` is ``P_l``.
    matrix : ndarray or cvxpy expression, shape (4 nx + nz + nw, 4 nx + nz + nw)
        The symmetric matrix required to be negative definite (numpy for :func:`lmi_matrices`, cvxpy
        inside :class:`HinfProgram`).
    """

    label: str
    i: int
    j: int
    l: int  # noqa: E741 - the paper's index
    matrix: Any


def _lmis(
    data: Sequence[Mapping[str, Any]],
    var: Mapping[str, Any],
    a: Any,
    b: Any,
    *,
    robust: bool,
    bmat: Callable[..., Any],
) -> list[LMIBlock]:
    """The LMIs (6)-(7) after Lemma 1, each matrix required ``< 0``.

    ``var`` maps names to per-vertex lists (``P1, P2, P3, X1..X6`` of length
    ``N``; ``H, Af, Bf, Cf, Df`` of length ``N``, or 1 when ``robust``) and
    ``delta`` to the scalar. (``tests/hinf_misprint.py`` builds the paper's
    misprinted variant, ``P_{3,j}`` in ``Phi_21``, to document that trap.)
    """
    n = len(data)
    nx, nw = data[0]["Bw"].shape
    nz = data[0]["Cz"].shape[0]
    n_rest = 2 * nx + nz + nw

    def vertex_vars(j: int) -> dict[str, Any]:
        f = 0 if robust else j
        out = {k: var[k][j] for k in ("X1", "X2", "X3", "X4", "X5", "X6")}
        out.update({k: var[k][f] for k in ("H", "Af", "Bf", "Cf", "Df")})
        return out

    K: dict[tuple[int, int], Any] = {}
    for i in range(n):
        for j in range(n):
            L = bmat(_xg_rows(data[i], vertex_vars(j), a, b))
            K[i, j] = L + L.T
    Qc = [_q_now(var["P1"][j], var["P2"][j], var["P3"][j], var["delta"], nz, nw, bmat) for j in range(n)]

    def qn(j: int, nxt: int) -> Any:
        # P(alpha_{k+1}) at vertex nxt (the paper's l); the misprint puts P_{3,j} in Phi_21
        return _q_next(var["P1"][nxt], var["P2"][nxt], var["P3"][nxt], n_rest, bmat)

    out: list[LMIBlock] = []
    for l in range(n):  # noqa: E741 - the paper's index
        for i in range(n):
            out.append(LMIBlock(f"Phi_{i + 1}{i + 1}{l + 1}", i, i, l, qn(i, l) + Qc[i] + K[i, i]))
            for j in range(i + 1, n):
                phi_ijl = qn(j, l) + Qc[j] + K[i, j]
                phi_jil = qn(i, l) + Qc[i] + K[j, i]
                label = f"Phi_{i + 1}{j + 1}{l + 1} + Phi_{j + 1}{i + 1}{l + 1}"
                out.append(LMIBlock(label, i, j, l, phi_ijl + phi_jil))
    return out


def _vertex_data(plant: PolytopicLPV, a: float, b: float) -> list[dict[str, np.ndarray]]:
    v = plant.vertices
    out = []
    for i in range(plant.n_vertices):
        d = {"A": v.A[i], "Bw": v.Bw[i], "Cz": v.Cz[i], "Dz": v.Dz[i], "Cy": v.Cy[i], "Dy": v.Dy[i]}
        d.update(aCy=a * v.Cy[i], bCy=b * v.Cy[i], aDy=a * v.Dy[i], bDy=b * v.Dy[i])
        out.append(d)
    return out


def _np_bmat(rows: list[list[Any]]) -> np.ndarray:
    return np.block([[np.asarray(x, dtype=float) for x in row] for row in rows])


def lmi_matrices(
    plant: PolytopicLPV,
    variables: Mapping[str, Any],
    epsilon: float | None = None,
    *,
    multiplier_ab: tuple[float, float] | None = None,
    robust: bool = False,
) -> list[LMIBlock]:
    """The LMIs (6)-(7) (after Lemma 1) evaluated with numpy at given variables.

    Used to check a solver's answer, and by the tests. ``variables`` maps
    ``P1, P2, P3, X1..X6, H, Af, Bf, Cf, Df`` to per-vertex sequences and
    ``delta`` to a float. Give ``epsilon`` for the paper's form
    ``(a, b) = (epsilon, 1)``, or ``multiplier_ab`` for the rescaled form.

    Parameters
    ----------
    plant : PolytopicLPV
        The plant (1): its vertex matrices ``A, Bw, Cz, Dz, Cy, Dy``.
    variables : mapping
        ``P1, P2, P3, X1..X6`` -> ``N`` arrays each (vertex ``j`` at index ``j``); ``H, Af, Bf, Cf, Df`` ->
        ``N`` arrays each (only index 0 is used when ``robust``); ``delta`` -> float (``gamma^2``).
        :meth:`HinfProgram.last_variables` gives this mapping (in the rescaled coordinates).
    epsilon : float, optional
        The paper's scalar (finite), for the LMIs as printed, ``(a, b) = (epsilon, 1)``.
    multiplier_ab : (float, float), optional
        The rescaled multiplier ``(a, b) = (sin phi, cos phi)`` (:func:`multiplier`), for variables in the
        rescaled coordinates of the module documentation.
    robust : bool, default False
        Corollary 1: one set of filter matrices (index 0) at every vertex.

    Returns
    -------
    list of LMIBlock
        The ``N^2 (N + 1) / 2`` LMIs, numpy matrices of size ``4 nx + nz + nw``, ordered by ``l``, then
        ``i``, then ``j``; each must be negative definite.

    Raises
    ------
    ArgumentError
        Both or neither of ``epsilon`` and ``multiplier_ab`` are given.
    """
    if (epsilon is None) == (multiplier_ab is None):
        raise ArgumentError("give exactly one of epsilon and multiplier_ab")
    a, b = (float(epsilon), 1.0) if multiplier_ab is None else multiplier_ab  # type: ignore[arg-type]  # one is given
    var = {k: ([np.asarray(m, dtype=float) for m in v] if k != "delta" else float(v)) for k, v in variables.items()}
    return _lmis(_vertex_data(plant, a, b), var, a, b, robust=robust, bmat=_np_bmat)


# ---------------------------------------------------------------------------
# the compiled program
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class DesignAttempt:
    """One solve of the LMIs at one ``epsilon`` (:meth:`HinfProgram.attempt`),
    which does not raise when no certified design is found.

    Parameters
    ----------
    design : HinfDesign or None
        The certified design; ``None`` when no solve gave one.
    status : str
        Final status: the solver's (cvxpy vocabulary; ``"solver_error"`` when the solver raised),
        ``"...; LMI check failed"``, or ``"infeasible"``.
    gamma : float
        The design's certified bound; ``inf`` when no certified design.
    detail : str, default ""
        Every solve tried and why it was rejected.
    gamma_lower : float, default nan
        The solver's dual bound on the best ``gamma`` at this epsilon and margin (module documentation,
        "Dual bound"); nan without a certified design or duals.
    """

    design: HinfDesign | None
    status: str
    gamma: float
    detail: str = ""
    gamma_lower: float = math.nan


class HinfProgram:
    """The LMI program of Theorem 1 (``kind="parameter-dependent"``) or
    Corollary 1 (``kind="robust"``) for plants of given dimensions, compiled once.

    The plant's vertex matrices and the multiplier ``(a, b)`` are
    ``cp.Parameter``: one program serves every ``epsilon`` and every plant of
    the same ``(N, nx, ny, nz, nw)`` (the Example 2 sweep over ``rho``
    compiles once). Not thread-safe (the parameters are shared).

    Parameters
    ----------
    n_vertices, nx, ny, nz, nw : int
        Plant dimensions.
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Theorem 1 (gain-scheduled filter) or Corollary 1 (robust filter).
    solver : str
        ``"AUTO"`` (default: :func:`choose_solver`) or a cvxpy solver name
        able to handle semidefinite constraints (``"CLARABEL"``, ``"SCS"``,
        ``"MOSEK"``, ...).
    margin : float
        Strict inequalities as ``M << -margin I``, ``P_i >> margin I``.
    solver_options : mapping, optional
        Extra keyword arguments for the solver.

    Examples
    --------
    >>> import lpvest
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> program = HinfProgram.for_plant(plant)
    >>> round(program.solve(plant, 150.0).gamma, 2)
    1.21
    """

    def __init__(
        self,
        n_vertices: int,
        nx: int,
        ny: int,
        nz: int,
        nw: int,
        *,
        kind: str = KIND_PD,
        solver: str = DEFAULT_SOLVER,
        margin: float = DEFAULT_MARGIN,
        solver_options: Mapping[str, Any] | None = None,
    ) -> None:
        import cvxpy as cp

        if kind not in (KIND_PD, KIND_ROBUST):
            raise ArgumentError(f"kind must be {KIND_PD!r} or {KIND_ROBUST!r}; found {abbreviate(kind, 30)}")
        dims = {"n_vertices": n_vertices, "nx": nx, "ny": ny, "nz": nz, "nw": nw}
        for name, value in dims.items():
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise DimensionError(f"{name} must be a positive integer; found {abbreviate(value, 30)}")
        _check_margin(margin)
        t0 = time.perf_counter()
        self.n_vertices, self.nx, self.ny, self.nz, self.nw = (int(v) for v in dims.values())
        self.kind = kind
        self.solver = check_solver(solver)
        self.auto = self.solver == "AUTO"  #: the solver was chosen by size (with a Clarabel fallback)
        if self.auto:
            self.solver = choose_solver(n_vertices, nx, nz, nw, kind)
        self._warm = False  # warm starts only inside a search (HinfProgram.warm_starts)
        self._abandoned: threading.Thread | None = None  # an interrupted solve, still running
        self._returned_point = False  # the last solve returned a point (last_variables)
        self.margin = float(margin)
        self.solver_options = dict(solver_options or {})
        N = self.n_vertices
        nf = 1 if kind == KIND_ROBUST else N

        self._a = cp.Parameter(name="a")
        self._b = cp.Parameter(name="b")
        self._margin = cp.Parameter(nonneg=True, name="margin", value=self.margin)
        shapes = {"A": (nx, nx), "Bw": (nx, nw), "Cz": (nz, nx), "Dz": (nz, nw), "Cy": (ny, nx), "Dy": (ny, nw)}
        shapes.update(aCy=(ny, nx), bCy=(ny, nx), aDy=(ny, nw), bDy=(ny, nw))
        self._data = [{k: cp.Parameter(s, name=f"{k}_{i + 1}") for k, s in shapes.items()} for i in range(N)]

        def vars_(name: str, shape: tuple[int, int], count: int, **kw: Any) -> list[Any]:
            return [cp.Variable(shape, name=f"{name}_{i + 1}", **kw) for i in range(count)]

        self._var: dict[str, Any] = {
            "P1": vars_("P1", (nx, nx), N, symmetric=True),
            "P2": vars_("P2", (nx, nx), N, symmetric=True),
            "P3": vars_("P3", (nx, nx), N),
            "X1": vars_("X1", (nx, nx), N),
            "X2": vars_("X2", (nx, nx), N),
            "X3": vars_("X3", (nx, nx), N),
            "X4": vars_("X4", (nx, nx), N),
            "X5": vars_("X5", (nz, nx), N),
            "X6": vars_("X6", (nw, nx), N),
            "H": vars_("H", (nx, nx), nf),
            "Af": vars_("Af", (nx, nx), nf),
            "Bf": vars_("Bf", (nx, ny), nf),
            "Cf": vars_("Cf", (nz, nx), nf),
            "Df": vars_("Df", (nz, ny), nf),
            "delta": cp.Variable(name="delta"),
        }
        lmis = _lmis(
            self._data, self._var, self._a, self._b,
            robust=(kind == KIND_ROBUST), bmat=cp.bmat,
        )
        size = 4 * nx + nz + nw
        constraints = [blk.matrix << -self._margin * np.eye(size) for blk in lmis]
        for j in range(N):
            P = cp.bmat([[self._var["P1"][j], self._var["P3"][j]], [self._var["P3"][j].T, self._var["P2"][j]]])
            constraints.append(P >> self._margin * np.eye(2 * nx))
        self.n_lmis = len(lmis)
        self._problem = cp.Problem(cp.Minimize(self._var["delta"]), constraints)
        if not self._problem.is_dpp():  # pragma: no cover - a construction bug, not user input
            raise InternalError("the H-infinity LMI program is not DPP (a bug in its construction)")
        # compile now (placeholder parameter values), so that every solve only
        # substitutes parameters: the compile time is paid once, here
        self._set_parameters({k: np.zeros((N, *sh)) for k, sh in shapes.items()}, 1.0, 0.0)
        self._problem.get_problem_data(self.solver)
        self.compile_time = time.perf_counter() - t0

    @classmethod
    def for_plant(cls, plant: PolytopicLPV | AffineLPV, **options: Any) -> HinfProgram:
        """A program for the dimensions of ``plant`` (options as in the constructor;
        an :class:`~lpvest.systems.AffineLPV` in its H-infinity setting).

        Parameters
        ----------
        plant : PolytopicLPV or AffineLPV
            The plant whose ``(N, nx, ny, nz, nw)`` the program is compiled for.
        **options
            Keyword arguments of the constructor: ``kind``, ``solver``, ``margin``, ``solver_options``.

        Returns
        -------
        HinfProgram
            A newly compiled program (not the cache that :func:`design_hinf` uses).
        """
        plant = _setting(plant)
        return cls(plant.n_vertices, plant.nx, plant.ny, plant.nz, plant.nw, **options)

    # -- parameters -----------------------------------------------------------------
    def _set_parameters(self, vertices: Mapping[str, np.ndarray], a: float, b: float) -> None:
        self._a.value = a
        self._b.value = b
        for i, d in enumerate(self._data):
            for k in ("A", "Bw", "Cz", "Dz", "Cy", "Dy"):
                d[k].value = vertices[k][i]
            d["aCy"].value = a * vertices["Cy"][i]
            d["bCy"].value = b * vertices["Cy"][i]
            d["aDy"].value = a * vertices["Dy"][i]
            d["bDy"].value = b * vertices["Dy"][i]

    def _check_dims(self, plant: PolytopicLPV) -> None:
        _check_plant(plant)
        have = (plant.n_vertices, plant.nx, plant.ny, plant.nz, plant.nw)
        want = (self.n_vertices, self.nx, self.ny, self.nz, self.nw)
        if have != want:
            raise DimensionError(
                f"plant has (N, nx, ny, nz, nw) = {have}; this program was compiled for {want}"
            )

    # -- solving --------------------------------------------------------------------
    def _values(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in self._var.items():
            if k == "delta":
                out[k] = float(v.value)
            else:
                out[k] = [np.array(x.value, dtype=float) for x in v]
        return out

    def last_variables(self) -> dict[str, Any]:
        """Every decision variable of the last solve (``P1, P2, P3, X1..X6``
        per vertex, the filter matrices, ``delta``), in the rescaled
        coordinates of the module documentation; raises if none is available.

        Returns
        -------
        dict
            ``P1, P2, P3, X1..X6`` -> lists of ``N`` ndarrays; ``H, Af, Bf, Cf, Df`` -> lists of ``N``
            ndarrays (1 for a robust program); ``delta`` -> float (``gamma^2``). The point the solver
            returned, whether or not it passed the eigenvalue check; the mapping :func:`lmi_matrices` takes.

        Raises
        ------
        LMIInfeasibleError
            No solve has returned a point (none yet, the last one found the LMIs
            infeasible, or the solver failed: cvxpy then keeps an earlier point).
        """
        if not self._returned_point or self._var["delta"].value is None:
            raise LMIInfeasibleError("the program has no solution yet", status=str(self._problem.status))
        return self._values()

    def _run_solver(self, solver: str) -> tuple[str, float, str]:
        """``(status, seconds, message)``: a solver failure is status ``"solver_error"``."""
        import cvxpy as cp

        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                # "Solution may be inaccurate": the status says so, and the check decides
                warnings.simplefilter("ignore", UserWarning)
                # warm_start=False: with cvxpy's default (True) a re-solve updates the
                # solver cached from this program's first solve (Clarabel's update()),
                # which keeps state from that solve, so a design depended on the
                # history of the compiled program (filter matrices up to ~1e-3 apart
                # on a flat optimum); a fresh solver per solve makes it a function of
                # the data alone
                # (inside warm_starts(), SCS starts from the previous point of
                # the same search, which began cold: still a function of the
                # data and the search alone)
                options = {"warm_start": self._warm and solver == "SCS", **_DEFAULT_OPTIONS.get(solver, {}),
                           **(self.solver_options if solver == self.solver else {})}
                self._solve_interruptibly(solver, options)
            status, message = str(self._problem.status), ""
        except cp.error.SolverError as exc:
            status, message = "solver_error", f" ({exc})"
        self._returned_point = status in _ACCEPTED
        return status, time.perf_counter() - t0, message

    def _solve_interruptibly(self, solver: str, options: Mapping[str, Any]) -> None:
        """``problem.solve`` on a worker thread (:func:`lpvest.core.call_interruptibly`):
        Ctrl-C or SIGTERM stops the wait at once; the abandoned solve may still
        write into this program, which is then never used again (it leaves the
        program cache, and a later solve here first waits for it to end). SCS
        catches SIGINT itself and returns "interrupted": that is raised too."""
        from ..core._interrupt import call_interruptibly, hold

        if self._abandoned is not None:
            self._abandoned.join()  # an interrupted solve still writes into the problem
            self._abandoned = None
        target = _interruptible_scs() if solver == "SCS" else solver

        def run() -> None:
            hold("solve")
            self._problem.solve(solver=target, **options)

        def abandon(thread: threading.Thread) -> None:
            self._abandoned = thread
            _cached_program.cache_clear()

        call_interruptibly(run, on_abandon=abandon)

    @contextlib.contextmanager
    def warm_starts(self) -> Iterator[None]:
        """Within this context a solve starts from the previous solve's point
        (SCS only: a first-order method gains from it; Clarabel's interior
        point does not), beginning cold: a search along epsilon, whose
        neighbouring points have nearby solutions, takes about half the time
        (0.85 s instead of 1.5 s per design on a 4-vertex, 3-state plant)."""
        cache = getattr(self._problem, "_solver_cache", None)
        if isinstance(cache, dict):
            cache.clear()  # the first solve of the search is cold
        self._warm = True
        try:
            yield
        finally:
            self._warm = False
            if isinstance(cache, dict):
                cache.clear()

    def _check(
        self, plant: PolytopicLPV, values: Mapping[str, Any], a: float, b: float
    ) -> tuple[bool, float, float, str, list[LMIBlock]]:
        """Eigenvalues of every LMI and of every P_i at ``values`` (and the LMIs evaluated there)."""
        if not all(np.all(np.isfinite(m)) for k, v in values.items() if k != "delta" for m in v) or not np.isfinite(
            values["delta"]
        ):
            return False, -math.inf, -math.inf, "the solver returned non-finite values", []
        lmis = lmi_matrices(plant, values, multiplier_ab=(a, b), robust=(self.kind == KIND_ROBUST))
        worst, worst_label = -math.inf, ""
        ok = True
        for label, *_, m in lmis:
            eig = np.linalg.eigvalsh(m)
            tol = 100.0 * np.finfo(float).eps * max(1.0, float(np.max(np.abs(eig))))
            if eig[-1] > worst:
                worst, worst_label = float(eig[-1]), label
            if not eig[-1] < -tol:
                ok = False
        lyap_min = math.inf
        for P in _lyapunov_matrices(values):
            eig = np.linalg.eigvalsh(0.5 * (P + P.T))
            lyap_min = min(lyap_min, float(eig[0]))
            if not eig[0] > 100.0 * np.finfo(float).eps * max(1.0, float(np.max(np.abs(eig)))):
                ok = False
        if values["delta"] <= 0:
            ok = False
        why = "" if ok else (
            f"largest LMI eigenvalue {worst:.3g} ({worst_label}), smallest Lyapunov eigenvalue {lyap_min:.3g}"
        )
        return ok, -worst, lyap_min, why, lmis

    def _dual_bound(self, values: Mapping[str, Any], lmis: Sequence[LMIBlock]) -> float:
        """Weak duality at the last solve's primal and dual points: a lower bound
        on ``delta`` of every design at the present ``epsilon`` (module
        documentation, "Dual bound"); nan when the solver gave no dual point."""
        duals = [c.dual_value for c in self._problem.constraints]
        if any(d is None for d in duals):
            return math.nan
        total = float(values["delta"])
        for blk, Z in zip(lmis, duals[: len(lmis)], strict=True):
            total += float(np.vdot(np.asarray(Z, dtype=float), np.asarray(blk.matrix, dtype=float)))
        for W, P in zip(duals[len(lmis):], _lyapunov_matrices(values), strict=True):
            total -= float(np.vdot(np.asarray(W, dtype=float), P))
        return total

    def attempt(self, plant: PolytopicLPV, epsilon: float | None = None, *, phi: float | None = None) -> DesignAttempt:
        """Solve at ``epsilon`` (or the angle ``phi = atan(epsilon)``) without
        raising on failure: the certified design or ``None`` and the status.

        Parameters
        ----------
        plant : PolytopicLPV
            The plant (1), of the program's dimensions.
        epsilon : float, optional
            The paper's scalar: any real number, or ``+-math.inf`` (both give ``(a, b) = (1, 0)``;
            the design records ``inf``).
        phi : float, optional
            The angle ``atan(epsilon)``, any real number (taken modulo pi); give exactly one of
            ``epsilon`` and ``phi``.

        Returns
        -------
        DesignAttempt
            The certified design and its ``gamma``, or ``None`` and ``gamma = inf``; status ``"infeasible"``
            without a solve when ``A(alpha)`` is not Schur somewhere on the simplex.
        """
        self._check_dims(plant)
        if (epsilon is None) == (phi is None):
            raise ArgumentError("give exactly one of epsilon and phi")
        if phi is not None:
            a, b = _ab_of_phi(phi)
            eps = _epsilon_of_phi(phi)
        else:
            eps = float(epsilon)  # type: ignore[arg-type]  # not None: exactly one of epsilon, phi
            a, b = multiplier(eps)
            eps = abs(eps) if math.isinf(eps) else eps
        detail = _instability(plant)
        if detail is not None:
            return DesignAttempt(None, "infeasible", math.inf, detail)
        self._set_parameters(plant.vertices._asdict(), a, b)
        attempts: list[str] = []
        status = ""
        elapsed = 0.0
        # first the requested margin; if the answer fails the check (solvers
        # stop within their tolerances, which may overshoot a small margin),
        # once more with a margin RETRY_MARGIN_FACTOR times larger; an SCS
        # answer chosen by "AUTO" that still fails is solved by Clarabel
        # (slower on large programs, but accurate to 1e-8), except within a
        # search, which goes on with its other points
        tries = [(self.solver, self.margin), (self.solver, self.margin * RETRY_MARGIN_FACTOR)]
        if self.auto and self.solver != "CLARABEL" and not self._warm:
            tries.append(("CLARABEL", self.margin))
        for solver, margin in tries:
            self._margin.value = margin
            status, more, message = self._run_solver(solver)
            elapsed += more
            label = f"{solver} margin {margin:.1e}: {status}{message}"
            if status in _ACCEPTED:
                values = self._values()
                ok, lmi_margin, lyap_margin, why, lmis = self._check(plant, values, a, b)
                if ok:
                    design = self._design(plant, values, eps, a, b, status, elapsed, lmi_margin, lyap_margin,
                                          solver)
                    lower = self._dual_bound(values, lmis)
                    return DesignAttempt(design, status, design.gamma, "; ".join([*attempts, label]),
                                         gamma_lower=math.sqrt(max(lower, 0.0)) if math.isfinite(lower) else math.nan)
                label += f", but the LMI check failed: {why}"
                status += "; LMI check failed"
            attempts.append(label)
            if status.startswith(("infeasible", "unbounded")):
                break
        return DesignAttempt(None, status, math.inf, "; ".join(attempts))

    def solve(self, plant: PolytopicLPV, epsilon: float) -> HinfDesign:
        """The design at ``epsilon`` (``math.inf`` allowed); raises
        :class:`~lpvest.core.LMIInfeasibleError` (``.status`` = the final
        solver status) when the LMIs are infeasible or the returned point fails
        the check even after the retry.

        Parameters
        ----------
        plant : PolytopicLPV
            The plant (1), of the program's dimensions.
        epsilon : float
            The paper's scalar: any real number, or ``+-math.inf``.

        Returns
        -------
        HinfDesign
            Certified: every LMI was checked by its eigenvalues at the returned point.
        """
        res = self.attempt(plant, epsilon)
        if res.design is None:
            raise LMIInfeasibleError(
                _infeasible_message(plant, self, f"epsilon = {epsilon:g}", res.detail), status=res.status,
                detail=res.detail,
            )
        return res.design

    def _design(
        self,
        plant: PolytopicLPV,
        values: Mapping[str, Any],
        eps: float,
        a: float,
        b: float,
        status: str,
        elapsed: float,
        lmi_margin: float,
        lyap_margin: float,
        solver: str,
    ) -> HinfDesign:
        lyap = np.stack(_lyapunov_matrices(values))
        lyap = 0.5 * (lyap + np.transpose(lyap, (0, 2, 1)))
        return HinfDesign(
            kind=self.kind,
            H=np.stack(values["H"]),
            Af=np.stack(values["Af"]),
            Bf=np.stack(values["Bf"]),
            Cf=np.stack(values["Cf"]),
            Df=np.stack(values["Df"]),
            gamma=math.sqrt(values["delta"]),
            epsilon=eps,
            multiplier=(a, b),
            lyapunov=lyap,
            solver=solver,
            status=status,
            compile_time=self.compile_time,
            solve_time=elapsed,
            lmi_margin=lmi_margin,
            lyapunov_margin=lyap_margin,
            n_lmis=self.n_lmis,
            nw=self.nw,
            plant=plant.name,
            model_digest=model_digest(plant),
        )


def _lyapunov_matrices(values: Mapping[str, Any]) -> list[np.ndarray]:
    """``P_j = [[P1_j, P3_j], [P3_j^T, P2_j]]`` per vertex, from a solve's variables."""
    return [np.block([[p1, p3], [p3.T, p2]])
            for p1, p2, p3 in zip(values["P1"], values["P2"], values["P3"], strict=True)]


def _check_margin(margin: object) -> None:
    if isinstance(margin, bool) or not isinstance(margin, int | float) or not 0 < margin < math.inf:
        raise ArgumentError(f"margin must be a positive finite number; found {abbreviate(margin, 30)}")


def _check_plant(plant: object) -> None:
    if not isinstance(plant, PolytopicLPV):
        raise ArgumentTypeError(
            f"the plant must be a PolytopicLPV or an AffineLPV (general noise, converted by "
            f"lpvest.hinf_setting); found {type(plant).__name__}"
        )


def _setting(plant: object) -> PolytopicLPV:
    """A model with general noise in the H-infinity setting (hinf_setting); a
    polytopic plant unchanged; anything else an error."""
    out = hinf_setting(plant) if isinstance(plant, AffineLPV) else plant
    _check_plant(out)
    assert isinstance(out, PolytopicLPV)
    return out


def _simplex_points(n_vertices: int) -> np.ndarray:
    """Points of the unit simplex where the plant's stability is checked: the
    vertices, every edge finely (an instability between two vertices is the
    common case), the barycentre and a fixed sample of the interior."""
    eye = np.eye(n_vertices)
    per_edge = 101 if n_vertices <= 4 else 21
    s = np.linspace(0.0, 1.0, per_edge)[1:-1, None]
    edges = [(1.0 - s) * eye[i] + s * eye[j] for i in range(n_vertices) for j in range(i + 1, n_vertices)]
    interior = np.random.default_rng(0).dirichlet(np.ones(n_vertices), size=64) if n_vertices > 2 else np.zeros((0, 2))
    return np.vstack([eye, *edges, np.full((1, n_vertices), 1.0 / n_vertices), interior])


def _instability(plant: PolytopicLPV) -> str | None:
    """Why no filter exists when ``A(alpha)`` is not Schur somewhere on the
    simplex (``None`` when it is Schur at every point checked).

    The LMIs (6)-(7), relaxed by Lemma 1, hold for every pair
    ``(alpha_k, alpha_(k+1))`` of the simplex; at ``alpha_k = alpha_(k+1) =
    alpha`` they are a Lyapunov inequality, with ``P(alpha) > 0``, for the
    block-triangular plant-filter matrix, whose diagonal holds ``A(alpha)``.
    So a spectral radius ``>= 1`` anywhere on the simplex makes them infeasible:
    a clear answer at once instead of a long search ending in a solver failure.
    """
    alpha = _simplex_points(plant.n_vertices)
    A = np.einsum("pi,irc->prc", alpha, plant.vertices.A)
    radius = np.max(np.abs(np.linalg.eigvals(A)), axis=1)
    bad = np.flatnonzero(radius >= 1.0)
    if not bad.size:
        return None
    k = int(bad[np.argmax(radius[bad])])
    if k < plant.n_vertices:
        return (f"not solved: vertex {k + 1} of the plant has spectral radius {radius[k]:.6g} >= 1, and the LMIs "
                f"(6)-(7) with P_i > 0 imply that every vertex A_i is Schur (at alpha_k = alpha_(k+1) = e_i they "
                f"are a Lyapunov inequality for the block-triangular plant-filter matrix)")
    at = ", ".join(f"{a:.3g}" for a in alpha[k])
    return (f"not solved: A(alpha) at alpha = ({at}) has spectral radius {radius[k]:.6g} >= 1 although every "
            "vertex is Schur; the LMIs imply A(alpha) Schur on the whole simplex (at alpha_k = alpha_(k+1) = alpha "
            "they are a Lyapunov inequality), so no filter exists")


def _infeasible_message(plant: PolytopicLPV, prog: HinfProgram, where: str, detail: str) -> str:
    """One line: what failed, and the start of why (``LMIInfeasibleError.detail`` holds all of it)."""
    name = plant.name or "(unnamed plant)"
    reason = " ".join(detail.split())
    if len(reason) > 170:
        reason = reason[:167] + "..."
    return f"{prog.kind} H-infinity LMIs for {name} at {where}, solver {prog.solver}: no certified solution ({reason})"


#: SCS's status when its own SIGINT handler stopped it (``SCS_SIGINT`` in scs.h).
_SCS_SIGINT = -5


@functools.lru_cache(maxsize=1)
def _interruptible_scs() -> Any:
    """cvxpy's SCS interface, except that a solve SCS stopped on SIGINT (its
    own handler catches the signal while it iterates, so Python's never runs)
    raises :class:`lpvest.core.Interrupted` instead of being one more
    failed point of a search (cvxpy reports it as a solver error). The same
    data, options and warm starts as ``solver="SCS"``."""
    from cvxpy.reductions.solvers.conic_solvers.scs_conif import SCS

    from ..core._interrupt import Interrupted

    class InterruptibleSCS(SCS):
        def name(self) -> str:
            return "LPVEST_SCS"

        def solve_via_data(self, data: Any, warm_start: bool, verbose: bool, solver_opts: Any,
                           solver_cache: Any = None) -> Any:
            results = super().solve_via_data(data, warm_start, verbose, solver_opts, solver_cache)
            if results["info"]["status_val"] == _SCS_SIGINT:
                raise Interrupted(signal.SIGINT)
            return results

    return InterruptibleSCS()


@functools.lru_cache(maxsize=16)
def _cached_program(
    dims: tuple[int, int, int, int, int], kind: str, solver: str, margin: float, options: tuple[tuple[str, Any], ...]
) -> HinfProgram:
    return HinfProgram(*dims, kind=kind, solver=solver, margin=margin, solver_options=dict(options))


def _program_for(
    plant: PolytopicLPV,
    kind: str,
    solver: str,
    margin: float,
    solver_options: Mapping[str, Any] | None,
    program: HinfProgram | None,
) -> HinfProgram:
    _check_plant(plant)
    if program is not None:
        program._check_dims(plant)
        if program.kind != kind:
            raise ArgumentError(f"the program is for a {program.kind} filter, not {abbreviate(kind, 30)}")
        return program
    if kind not in (KIND_PD, KIND_ROBUST):
        raise ArgumentError(f"kind must be {KIND_PD!r} or {KIND_ROBUST!r}; found {abbreviate(kind, 30)}")
    check_solver(solver)
    _check_margin(margin)
    dims = (plant.n_vertices, plant.nx, plant.ny, plant.nz, plant.nw)
    opts = tuple(sorted((solver_options or {}).items()))
    return _cached_program(dims, kind, str(solver).upper(), float(margin), opts)


# ---------------------------------------------------------------------------
# public entry points
# ---------------------------------------------------------------------------
def design_hinf(
    plant: PolytopicLPV | AffineLPV,
    *,
    epsilon: float,
    kind: str = KIND_PD,
    solver: str = DEFAULT_SOLVER,
    margin: float = DEFAULT_MARGIN,
    solver_options: Mapping[str, Any] | None = None,
    program: HinfProgram | None = None,
) -> HinfDesign:
    """Design the filter of Theorem 1 (``kind="parameter-dependent"``) or
    Corollary 1 (``kind="robust"``) at a given ``epsilon``.

    Parameters
    ----------
    plant : PolytopicLPV or AffineLPV
        The plant (1), any ``N``, ``nx``, ``ny``, ``nz``, ``nw``; a model with
        general noise is taken in its H-infinity setting
        (:func:`lpvest.systems.hinf_setting`).
    epsilon : float
        The paper's scalar; any real number, or ``math.inf``.
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Theorem 1 (gain-scheduled filter) or Corollary 1 (robust filter).
    solver : str
        ``"AUTO"`` (default: Clarabel or SCS by size, :func:`choose_solver`) or a cvxpy solver.
    margin : float
        Strictness margin of the LMIs.
    solver_options : mapping, optional
        Passed to the solver.
    program : HinfProgram, optional
        A compiled program to reuse (by default one is compiled for the plant's
        dimensions and cached for the process). Its ``kind`` must be ``kind``;
        its own solver, margin and options are used.

    Returns
    -------
    HinfDesign
        Certified: every LMI was checked by its eigenvalues at the returned point.

    Raises
    ------
    LMIInfeasibleError
        The LMIs are infeasible at ``epsilon`` (e.g. an unstable plant), or the
        solver's answer failed the check even after a retry; ``.status`` holds
        the solver status.

    Examples
    --------
    >>> import lpvest
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> d = design_hinf(plant, epsilon=150.0, kind="robust")
    >>> round(d.gamma, 1)
    8.2
    """
    plant = _setting(plant)
    prog = _program_for(plant, kind, solver, margin, solver_options, program)
    return prog.solve(plant, epsilon)


@dataclass(frozen=True, eq=False)
class EpsilonCurve:
    """``gamma(epsilon)`` sampled: the certified bound at each ``epsilon``.

    ``gamma`` is ``inf`` where no certified design exists (``status`` says why).
    ``phi = atan(epsilon)`` in ``(-pi/2, pi/2]`` (``epsilon = inf`` at ``pi/2``).
    ``gamma_lower`` is the solver's dual bound on the best ``gamma`` at each
    ``epsilon`` (module documentation, "Dual bound"): the best design at that
    ``epsilon`` lies in ``[gamma_lower, gamma]``, up to the solver's dual
    residual, so ``gamma - gamma_lower`` is how far each point may be from its
    own optimum (about 1e-8 relative with Clarabel, 1e-5 with SCS).

    Parameters
    ----------
    epsilon : ndarray, shape (M,)
        The sampled values of the paper's scalar.
    phi : ndarray, shape (M,)
        ``atan(epsilon)``.
    gamma : ndarray, shape (M,)
        The certified bound at each ``epsilon``; ``inf`` where no certified design exists.
    status : tuple of str, length M
        The final status of each solve (:attr:`DesignAttempt.status`).
    gamma_lower : ndarray, shape (M,)
        The dual bound at each ``epsilon``; nan where ``gamma`` is inf.
    """

    epsilon: np.ndarray
    phi: np.ndarray
    gamma: np.ndarray
    status: tuple[str, ...]
    gamma_lower: np.ndarray

    def __post_init__(self) -> None:
        for name in ("epsilon", "phi", "gamma", "gamma_lower"):  # read-only, as HinfDesign's arrays
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def best(self) -> tuple[float, float]:
        """``(epsilon, gamma)`` of the smallest sampled ``gamma``.

        Returns
        -------
        epsilon : float
            The ``epsilon`` of the first smallest ``gamma`` (of the first sample when every ``gamma`` is inf).
        gamma : float
            That ``gamma``.
        """
        k = int(np.argmin(self.gamma))
        return float(self.epsilon[k]), float(self.gamma[k])


@dataclass(frozen=True, eq=False)
class EpsilonSearch:
    """Result of :func:`search_epsilon`: the best design and every point tried.

    Parameters
    ----------
    design : HinfDesign
        The design at the evaluated ``epsilon`` with the smallest ``gamma``.
    curve : EpsilonCurve
        Every evaluated point, sorted by ``phi``.
    n_evaluations : int
        Epsilon values evaluated (a retry with a larger margin counts once).
    """

    design: HinfDesign
    curve: EpsilonCurve
    n_evaluations: int


def _curve(points: Mapping[float, DesignAttempt]) -> EpsilonCurve:
    phis = sorted(points)
    return EpsilonCurve(
        epsilon=np.array([_epsilon_of_phi(p) for p in phis]),
        phi=np.array([_canonical_phi(p) for p in phis]),
        gamma=np.array([points[p].gamma for p in phis]),
        status=tuple(points[p].status for p in phis),
        gamma_lower=np.array([points[p].gamma_lower for p in phis]),
    )


def epsilon_curve(
    plant: PolytopicLPV | AffineLPV,
    epsilons: Sequence[float] | np.ndarray,
    *,
    kind: str = KIND_PD,
    solver: str = DEFAULT_SOLVER,
    margin: float = DEFAULT_MARGIN,
    solver_options: Mapping[str, Any] | None = None,
    program: HinfProgram | None = None,
) -> EpsilonCurve:
    """``gamma(epsilon)`` at the given ``epsilons`` (one compiled program).

    Parameters
    ----------
    plant : PolytopicLPV or AffineLPV
        The plant (1); a model with general noise is taken in its H-infinity setting
        (:func:`lpvest.systems.hinf_setting`).
    epsilons : sequence of float or ndarray
        The values of ``epsilon`` (flattened, shape (M,)); any real number or ``+-math.inf``.
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Theorem 1 (gain-scheduled filter) or Corollary 1 (robust filter).
    solver : str, default DEFAULT_SOLVER ("AUTO")
        ``"AUTO"`` (Clarabel or SCS by size, :func:`choose_solver`) or a cvxpy solver name.
    margin : float, default DEFAULT_MARGIN (1e-6)
        Strictness margin of the LMIs: ``M << -margin I``, ``P_i >> margin I``.
    solver_options : mapping, optional
        Extra keyword arguments for the solver.
    program : HinfProgram, optional
        A compiled program to reuse (by default one is compiled for the plant's dimensions and cached for
        the process). Its ``kind`` must be ``kind``; its own solver, margin and options are used.

    Returns
    -------
    EpsilonCurve
        One point per ``epsilon``, in the given order; a point without a certified design has
        ``gamma = inf`` (no error is raised).

    Examples
    --------
    >>> import lpvest
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> c = epsilon_curve(plant, [1.0, 150.0])
    >>> c.gamma.shape
    (2,)
    """
    plant = _setting(plant)
    prog = _program_for(plant, kind, solver, margin, solver_options, program)
    eps = np.asarray(epsilons, dtype=float).ravel()
    with prog.warm_starts():
        out = [prog.attempt(plant, float(e)) for e in eps]
    return EpsilonCurve(
        epsilon=np.where(np.isinf(eps), math.inf, eps),  # -inf and inf are one multiplier: phi = pi/2
        phi=np.array([math.pi / 2 if math.isinf(e) else math.atan(e) for e in eps]),
        gamma=np.array([r.gamma for r in out]),
        status=tuple(r.status for r in out),
        gamma_lower=np.array([r.gamma_lower for r in out]),
    )


def search_epsilon(
    plant: PolytopicLPV | AffineLPV,
    *,
    kind: str = KIND_PD,
    n_grid: int = 24,
    n_refine: int = 2,
    xatol: float = 1e-3,
    solver: str = DEFAULT_SOLVER,
    margin: float = DEFAULT_MARGIN,
    solver_options: Mapping[str, Any] | None = None,
    program: HinfProgram | None = None,
    progress: bool = False,
) -> EpsilonSearch:
    """The best ``gamma`` over every real ``epsilon`` (and ``epsilon -> inf``).

    ``epsilon = tan(phi)`` maps the whole line plus infinity onto the circle
    ``phi in (-pi/2, pi/2]``, and the LMIs depend continuously on
    ``(sin phi, cos phi)`` (see the module documentation). The search
    evaluates a uniform grid of ``n_grid`` angles (both signs of epsilon,
    magnitudes from ``pi/n_grid`` (``pi/(2 n_grid)`` for an odd ``n_grid``; an
    even one includes ``epsilon = 0``) up to infinity), then refines the
    ``n_refine`` best local minima of the grid by a bounded Brent search
    (``scipy.optimize.minimize_scalar``) between their grid neighbours, to
    ``xatol`` in ``phi``. A minimum whose two neighbours are equal to it within
    the solver's accuracy (their intervals ``[gamma_lower, gamma]``, see
    :class:`EpsilonCurve`, share a point) is not refined: the curve is flat
    there to what the solver can tell. Every evaluation reuses the compiled program (and,
    with SCS, starts from the previous evaluation's point: the search starts
    cold, so its result depends on the plant and the settings alone).
    ``progress=True`` shows a progress bar (tqdm) of the designs solved.

    Parameters
    ----------
    plant : PolytopicLPV or AffineLPV
        The plant (1); a model with general noise is taken in its H-infinity setting
        (:func:`lpvest.systems.hinf_setting`).
    kind : {"parameter-dependent", "robust"}, default "parameter-dependent"
        Theorem 1 (gain-scheduled filter) or Corollary 1 (robust filter).
    n_grid : int, default 24
        Number of grid angles ``phi`` (at least 3), spaced ``pi / n_grid`` and ending at ``pi/2``
        (``epsilon = inf``).
    n_refine : int, default 2
        How many of the best local minima of the grid are refined (a minimum where the curve is flat to
        the solver's accuracy is skipped); 0: none.
    xatol : float, default 1e-3
        Absolute tolerance of the Brent search, in ``phi`` (radians).
    solver : str, default DEFAULT_SOLVER ("AUTO")
        ``"AUTO"`` (Clarabel or SCS by size, :func:`choose_solver`) or a cvxpy solver name.
    margin : float, default DEFAULT_MARGIN (1e-6)
        Strictness margin of the LMIs: ``M << -margin I``, ``P_i >> margin I``.
    solver_options : mapping, optional
        Extra keyword arguments for the solver.
    program : HinfProgram, optional
        A compiled program to reuse (by default one is compiled for the plant's dimensions and cached for
        the process). Its ``kind`` must be ``kind``; its own solver, margin and options are used.
    progress : bool, default False
        Show a tqdm progress bar.

    Returns
    -------
    EpsilonSearch
        ``design`` at the best ``epsilon`` found, ``curve`` of every evaluated
        point, ``n_evaluations``.

    Raises
    ------
    LMIInfeasibleError
        No grid point gives a certified design. Also raised at once, before any
        solve, when ``A(alpha)`` is not Schur somewhere on the simplex.

    Examples
    --------
    >>> import lpvest
    >>> plant = lpvest.load_system("peixoto-ex1").model()
    >>> best = search_epsilon(plant, kind="robust")
    >>> best.design.gamma < 8.18
    True
    """
    if isinstance(n_grid, bool) or not isinstance(n_grid, int) or n_grid < 3:
        raise ArgumentError(f"n_grid must be an integer, at least 3; found {abbreviate(n_grid, 30)}")
    plant = _setting(plant)
    prog = _program_for(plant, kind, solver, margin, solver_options, program)
    unstable = _instability(plant)
    if unstable is not None:  # no epsilon can help: say so at once
        raise LMIInfeasibleError(_infeasible_message(plant, prog, "every epsilon", unstable), status="infeasible",
                                 detail=unstable)
    points: dict[float, DesignAttempt] = {}
    bar = _progress_bar(progress, f"epsilon search ({prog.kind}, {prog.solver})", n_grid)

    def evaluate(phi: float) -> float:
        key = _canonical_phi(phi)
        if key not in points:
            points[key] = prog.attempt(plant, phi=key)
            if bar is not None:
                best = min(p.gamma for p in points.values())
                if bar.n >= bar.total:  # the grid is done: each refinement step adds one
                    bar.total = bar.n + 1
                    bar.set_description_str(f"epsilon search ({prog.kind}, {prog.solver}), refining", refresh=False)
                bar.set_postfix_str(f"best gamma {best:.6g}", refresh=False)
                bar.update(1)
        return points[key].gamma

    with prog.warm_starts(), contextlib.ExitStack() as stack:
        if bar is not None:
            stack.callback(bar.close)
        return _search(plant, prog, evaluate, points, n_grid, n_refine, xatol)


def _progress_bar(progress: bool, desc: str, total: int) -> Any:
    """A bar of the designs solved, out of ``total`` (the grid; a refinement
    raises it by one a step), with its ETA; it stays when done. Only on a
    terminal: never carriage returns into a redirected log."""
    import sys

    if not progress or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(desc=desc, total=total, unit="design", leave=True)


def _search(
    plant: PolytopicLPV,
    prog: HinfProgram,
    evaluate: Callable[[float], float],
    points: dict[float, DesignAttempt],
    n_grid: int,
    n_refine: int,
    xatol: float,
) -> EpsilonSearch:
    """The grid and the Brent refinements of :func:`search_epsilon`."""
    from scipy.optimize import minimize_scalar

    step = math.pi / n_grid
    grid = [-math.pi / 2 + step * (k + 1) for k in range(n_grid)]
    gam = [evaluate(p) for p in grid]
    finite = [g for g in gam if math.isfinite(g)]
    if not finite:
        tried = [points[_canonical_phi(p)] for p in grid]
        statuses = sorted({t.status for t in tried})
        detail = "; ".join(sorted({t.detail for t in tried}))
        raise LMIInfeasibleError(
            _infeasible_message(plant, prog, f"every epsilon tried ({n_grid} values)", detail),
            status=statuses[0] if len(statuses) == 1 else " | ".join(statuses), detail=detail,
        )
    penalty = 10.0 * max(finite) + 1.0
    minima = [
        k for k in range(n_grid)
        if math.isfinite(gam[k]) and gam[k] <= gam[k - 1] and gam[k] <= gam[(k + 1) % n_grid]
    ]
    minima.sort(key=lambda k: gam[k])

    def flat(k: int) -> bool:
        # the grid points k-1, k, k+1 are consistent with one constant gamma:
        # the intervals [gamma_lower, gamma] that hold each point's optimum share
        # a point. Refining there would chase the solver's tolerance (SCS's
        # 1e-5 makes a flat curve look rugged), not a better epsilon. A
        # neighbour whose solve failed (no certified design, but not proved
        # infeasible) tells nothing about the curve and is left out; an
        # infeasible neighbour is a real rise of the curve.
        tried = [points[_canonical_phi(grid[i % n_grid])] for i in (k - 1, k, k + 1)]
        if any(t.status.startswith("infeasible") for t in tried):
            return False
        known = [t for t in tried if math.isfinite(t.gamma)]
        if len(known) < 2 or not all(math.isfinite(t.gamma_lower) for t in known):
            return False
        return max(min(t.gamma, t.gamma_lower) for t in known) <= min(max(t.gamma, t.gamma_lower) for t in known)

    for k in [k for k in minima if not flat(k)][: max(0, n_refine)]:
        minimize_scalar(
            lambda p: min(evaluate(p), penalty),
            bounds=(grid[k] - step, grid[k] + step),
            method="bounded",
            options={"xatol": xatol},
        )
    best_phi = min(points, key=lambda p: points[p].gamma)
    design = points[best_phi].design
    assert design is not None
    return EpsilonSearch(design=design, curve=_curve(points), n_evaluations=len(points))
