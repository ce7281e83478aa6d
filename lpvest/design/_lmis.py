r"""The LMIs of Theorem 1 and Corollary 1 of Peixoto et al., written once for
numpy arrays and for cvxpy expressions.

Paper: 001_00f62b5a0c49ad87.txt ("A novel H-infinity filter design condition for
discrete-time LPV systems"). For the polytopic plant (1) and the filter (2),
the LMIs (6)-(7) certify ``||e||_2 < gamma ||w||_2`` (zero initial state) for
every parameter sequence ``alpha_k`` on the simplex, varying arbitrarily fast.
This module is their algebra: the multiplier ``(a, b)`` of ``epsilon``, the
blocks of the LMIs over a generic ``bmat`` (numpy here, cvxpy in
:mod:`lpvest.design._program`, which compiles and solves them), and
:func:`lmi_matrices`, the LMIs at given variables. :mod:`lpvest.design._search`
finds the best ``epsilon``.

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

The Lemma 1 relaxation (``Phi_iil < 0``, ``Phi_ijl + Phi_jil < 0`` for
``i < j``) is applied for any number of vertices ``N``: ``N^2 (N + 1) / 2``
LMIs of size ``4 nx + nz + nw``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..core._errors import ArgumentError, NonFiniteError
from ..systems._polytopic import PolytopicLPV

if TYPE_CHECKING:
    from typing import TypeAlias

    from ..core._typing import CvxExpression

    #: A block of the LMIs: an ndarray, or a cvxpy expression in the program.
    Block: TypeAlias = np.ndarray | CvxExpression
    #: The multiplier's ``a`` or ``b``: a float, or a cvxpy parameter in the program.
    Scalar: TypeAlias = float | CvxExpression
    #: Assembles a block matrix from rows of blocks: ``numpy.block`` or ``cvxpy.bmat``.
    Bmat: TypeAlias = Callable[[list[list[Block]]], Block]

__all__ = [
    "multiplier",
    "canonical_phi",
    "epsilon_of_phi",
    "ab_of_phi",
    "LMIBlock",
    "lmi_blocks",
    "lmi_matrices",
]


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


def canonical_phi(phi: float) -> float:
    """``phi`` modulo pi, in ``(-pi/2, pi/2]``."""
    p = math.remainder(phi, math.pi)  # in [-pi/2, pi/2]
    return math.pi / 2 if p <= -math.pi / 2 + 1e-15 else p


def epsilon_of_phi(phi: float) -> float:
    """``tan(phi)`` for ``phi`` modulo pi; ``inf`` at ``pi/2`` (the limit ``epsilon -> infinity``)."""
    p = canonical_phi(phi)
    return math.inf if abs(math.pi / 2 - p) < 1e-12 else math.tan(p)


def ab_of_phi(phi: float) -> tuple[float, float]:
    """The multiplier ``(a, b) = (sin phi, cos phi)`` for ``phi`` modulo pi (``(1, 0)`` at ``pi/2``)."""
    p = canonical_phi(phi)
    if abs(math.pi / 2 - p) < 1e-12:
        return (1.0, 0.0)
    return (math.sin(p), math.cos(p))


# ---------------------------------------------------------------------------
# the LMIs, written once for numpy arrays and for cvxpy expressions
# ---------------------------------------------------------------------------
def _xg_rows(d: Mapping[str, Block], v: Mapping[str, Block], a: Scalar, b: Scalar) -> list[list[Block]]:
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


def _q_next(P1: Block, P2: Block, P3: Block, n_rest: int, bmat: Bmat) -> Block:
    """``diag(P(alpha_{k+1}), 0)``: the ``V(xi_{k+1})`` part of ``Q``."""
    nx = P3.shape[0]
    z = np.zeros((2 * nx, n_rest))
    return bmat([[bmat([[P1, P3], [P3.T, P2]]), z], [z.T, np.zeros((n_rest, n_rest))]])


def _q_now(P1: Block, P2: Block, P3: Block, delta: Scalar, nz: int, nw: int, bmat: Bmat) -> Block:
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
        inside :class:`~lpvest.design.HinfProgram`).
    """

    label: str
    i: int
    j: int
    l: int  # noqa: E741 - the paper's index
    matrix: Block


def lmi_blocks(
    data: Sequence[Mapping[str, Block]],
    var: Mapping[str, Block],
    a: Scalar,
    b: Scalar,
    *,
    robust: bool,
    bmat: Bmat,
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

    def vertex_vars(j: int) -> dict[str, Block]:
        f = 0 if robust else j
        out = {k: var[k][j] for k in ("X1", "X2", "X3", "X4", "X5", "X6")}
        out.update({k: var[k][f] for k in ("H", "Af", "Bf", "Cf", "Df")})
        return out

    K: dict[tuple[int, int], Block] = {}
    for i in range(n):
        for j in range(n):
            L = bmat(_xg_rows(data[i], vertex_vars(j), a, b))
            K[i, j] = L + L.T
    Qc = [_q_now(var["P1"][j], var["P2"][j], var["P3"][j], var["delta"], nz, nw, bmat) for j in range(n)]

    def qn(j: int, nxt: int) -> Block:
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


def _np_bmat(rows: list[list[Block]]) -> np.ndarray:
    return np.block([[np.asarray(x, dtype=float) for x in row] for row in rows])


def lmi_matrices(
    plant: PolytopicLPV,
    variables: Mapping[str, Block],
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
        :meth:`~lpvest.design.HinfProgram.last_variables` gives this mapping (in the rescaled coordinates).
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
    return lmi_blocks(_vertex_data(plant, a, b), var, a, b, robust=robust, bmat=_np_bmat)
