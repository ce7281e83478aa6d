r"""The H-infinity LMI program of Peixoto et al., compiled once: solver choice,
the eigenvalue check, margins and retries, warm starts, the dual bound.

:class:`HinfProgram` holds the LMIs of :mod:`lpvest.design._lmis` (Theorem 1,
or Corollary 1 for a robust filter) as a cvxpy problem whose plant and
multiplier are parameters; :func:`design_hinf` solves them at a given
``epsilon`` (through a per-process cache of compiled programs).
Strict inequalities are ``M << -margin I``. Every returned point is checked:
the eigenvalues of every assembled LMI and of every ``P_i`` (numpy, float64)
must be strictly negative / positive beyond rounding: by more than 100 eps
times the matrix's largest eigenvalue in magnitude (at least 1). A failed check
is retried with a margin ``RETRY_MARGIN_FACTOR`` times larger (then, for SCS
chosen by ``"AUTO"`` outside a search, solved by Clarabel), then raises
:class:`~lpvest.core.LMIInfeasibleError`.

**Dual bound.** Every solve also gives a lower bound on the best ``gamma``
at its ``epsilon`` (``gamma_lower`` of :class:`DesignAttempt` and
:class:`~lpvest.design.EpsilonCurve`). The bound is for the strict LMIs themselves (margin
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
10 and 100 times smaller. :func:`~lpvest.design.search_epsilon` uses it to tell a curve that
"""

from __future__ import annotations

import contextlib
import functools
import math
import signal
import threading
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core._errors import (
    ArgumentError,
    ArgumentTypeError,
    DimensionError,
    InternalError,
    LMIInfeasibleError,
    abbreviate,
)
from ..systems._affine import AffineLPV
from ..systems._polytopic import PolytopicLPV, hinf_setting
from ._lmis import LMIBlock, ab_of_phi, epsilon_of_phi, lmi_blocks, lmi_matrices, multiplier
from ._result import KIND_PD, KIND_ROBUST, HinfDesign, model_digest

if TYPE_CHECKING:
    from ..core._typing import CvxExpression, CvxSolver

__all__ = [
    "design_hinf",
    "HinfProgram",
    "DesignAttempt",
    "DEFAULT_SOLVER",
    "DEFAULT_MARGIN",
    "AUTO_CLARABEL_MAX_ROWS",
    "RETRY_MARGIN_FACTOR",
    "choose_solver",
    "check_solver",
    "sdp_solvers",
    "hinf_plant",
    "instability",
    "infeasible_message",
    "program_for",
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
_DEFAULT_OPTIONS: dict[str, dict[str, object]] = {"CLARABEL": {"max_threads": 1}}

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
        solver_options: Mapping[str, object] | None = None,
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
        self._abandoned: threading.Event | None = None  # set when an interrupted solve has ended
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

        def vars_(name: str, shape: tuple[int, int], count: int, **kw: bool) -> list[CvxExpression]:
            return [cp.Variable(shape, name=f"{name}_{i + 1}", **kw) for i in range(count)]

        self._var: dict[str, CvxExpression] = {  # name -> cvxpy variables per vertex (delta: one)
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
        lmis = lmi_blocks(
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
        plant = hinf_plant(plant)
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
        coordinates of :mod:`lpvest.design._lmis`; raises if none is available.

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

    def _solve_interruptibly(self, solver: str, options: Mapping[str, object]) -> None:
        """``problem.solve`` on a worker thread (:func:`lpvest.core.call_interruptibly`):
        Ctrl-C or SIGTERM stops the wait at once; the abandoned solve may still
        write into this program, which is then never used again (it leaves the
        program cache, and a later solve here first waits for it to end). SCS
        catches SIGINT itself and returns "interrupted": that is raised too."""
        from ..core._interrupt import call_interruptibly, hold

        if self._abandoned is not None:
            self._abandoned.wait()  # an interrupted solve still writes into the problem
            self._abandoned = None
        target = _interruptible_scs() if solver == "SCS" else solver

        def run() -> None:
            hold("solve")
            self._problem.solve(solver=target, **options)

        def abandon(finished: threading.Event) -> None:
            self._abandoned = finished
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
            a, b = ab_of_phi(phi)
            eps = epsilon_of_phi(phi)
        else:
            eps = float(epsilon)  # type: ignore[arg-type]  # not None: exactly one of epsilon, phi
            a, b = multiplier(eps)
            eps = abs(eps) if math.isinf(eps) else eps
        detail = instability(plant)
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
                infeasible_message(plant, self, f"epsilon = {epsilon:g}", res.detail), status=res.status,
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


def hinf_plant(plant: object) -> PolytopicLPV:
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


def instability(plant: PolytopicLPV) -> str | None:
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


def infeasible_message(plant: PolytopicLPV, prog: HinfProgram, where: str, detail: str) -> str:
    """One line: what failed, and the start of why (``LMIInfeasibleError.detail`` holds all of it)."""
    name = plant.name or "(unnamed plant)"
    reason = " ".join(detail.split())
    if len(reason) > 170:
        reason = reason[:167] + "..."
    return f"{prog.kind} H-infinity LMIs for {name} at {where}, solver {prog.solver}: no certified solution ({reason})"


#: SCS's status when its own SIGINT handler stopped it (``SCS_SIGINT`` in scs.h).
_SCS_SIGINT = -5


@functools.lru_cache(maxsize=1)
def _interruptible_scs() -> CvxSolver:
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

        def solve_via_data(self, data: dict[str, object], warm_start: bool, verbose: bool,
                           solver_opts: dict[str, object],
                           solver_cache: dict[str, object] | None = None) -> dict[str, object]:
            results = super().solve_via_data(data, warm_start, verbose, solver_opts, solver_cache)
            if results["info"]["status_val"] == _SCS_SIGINT:
                raise Interrupted(signal.SIGINT)
            return results

    return InterruptibleSCS()


@functools.lru_cache(maxsize=16)
def _cached_program(
    dims: tuple[int, int, int, int, int], kind: str, solver: str, margin: float, options: tuple[tuple[str, object], ...]
) -> HinfProgram:
    return HinfProgram(*dims, kind=kind, solver=solver, margin=margin, solver_options=dict(options))


def program_for(
    plant: PolytopicLPV,
    kind: str,
    solver: str,
    margin: float,
    solver_options: Mapping[str, object] | None,
    program: HinfProgram | None,
) -> HinfProgram:
    """``program`` checked against the plant and ``kind``, or else the cached
    program compiled for the plant's dimensions and these settings (checked first)."""
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
    solver_options: Mapping[str, object] | None = None,
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
    plant = hinf_plant(plant)
    prog = program_for(plant, kind, solver, margin, solver_options, program)
    return prog.solve(plant, epsilon)
