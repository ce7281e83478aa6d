"""The H-infinity program's own algebra (lpvest/design/_program.py): the dual bound on made-up
duals, the eigenvalue check that certifies a returned point, the solver fallback, and the
small rules around them. The designs themselves are checked against oracles in
tests/test_hinf_design.py."""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

import lpvest.design._lmis as lmis
import lpvest.design._program as program
import lpvest.design._search as search
from lpvest import load_system
from lpvest.core._errors import ArgumentError, ArgumentTypeError, DimensionError, LMIInfeasibleError, NonFiniteError
from lpvest.design import KIND_PD, KIND_ROBUST, HinfProgram
from lpvest.design._lmis import LMIBlock, multiplier
from lpvest.design._program import choose_solver

EPS = np.finfo(float).eps


def _values(P1, P2, P3, delta=2.0):
    """A solve's variables with one vertex (only what the check and the bound read)."""
    return {"P1": [np.atleast_2d(P1)], "P2": [np.atleast_2d(P2)], "P3": [np.atleast_2d(P3)], "delta": delta}


# -- the dual bound ----------------------------------------------------------------------


def test_the_dual_bound_is_delta_plus_each_lmi_inner_product_minus_each_lyapunov_one():
    """Weak duality for min delta s.t. M_i(x) << 0, P_j(x) >> 0: for duals Z_i, W_j >= 0 the
    Lagrangian delta + sum <Z_i, M_i> - sum <W_j, P_j> at the primal point is the bound."""
    M1 = np.array([[-1.0, 0.5], [0.5, -2.0]])
    M2 = np.array([[-3.0, 0.0], [0.0, -0.25]])
    Z1 = np.array([[0.5, 0.1], [0.1, 0.2]])
    Z2 = np.array([[0.125, 0.0], [0.0, 4.0]])
    values = _values([[2.0]], [[3.0]], [[0.5]], delta=7.0)
    P = np.array([[2.0, 0.5], [0.5, 3.0]])
    W = np.array([[0.25, -0.5], [-0.5, 1.0]])
    lmis = [LMIBlock("Phi_111", 0, 0, 0, M1), LMIBlock("Phi_112", 0, 0, 1, M2)]
    assert np.array_equal(program._lyapunov_matrices(values)[0], P)  # [[P1, P3], [P3^T, P2]]
    fake = SimpleNamespace(_problem=SimpleNamespace(constraints=[SimpleNamespace(dual_value=d) for d in (Z1, Z2, W)]))
    got = HinfProgram._dual_bound(fake, values, lmis)  # type: ignore[arg-type]
    # <Z1, M1> = -0.5 + 0.1 - 0.4 = -0.8; <Z2, M2> = -0.375 - 1 = -1.375; <W, P> = 0.5 - 0.5 + 3 = 3
    assert got == 7.0 - 0.8 - 1.375 - 3.0
    missing = SimpleNamespace(_problem=SimpleNamespace(constraints=[SimpleNamespace(dual_value=d)
                                                                    for d in (Z1, None, W)]))
    assert math.isnan(HinfProgram._dual_bound(missing, values, lmis))  # type: ignore[arg-type]


# -- the eigenvalue check ------------------------------------------------------------------


@pytest.fixture
def checked(monkeypatch):
    """HinfProgram._check with the LMIs replaced by given matrices: the check's own rules."""
    plant = load_system("peixoto-ex1").model()
    blocks: list[np.ndarray] = []
    monkeypatch.setattr(program, "lmi_matrices", lambda *a, **k: [LMIBlock(f"Phi_{i}", 0, 0, 0, m)
                                                                   for i, m in enumerate(blocks)])
    prog = SimpleNamespace(kind=KIND_PD)

    def run(values, *lmis):
        blocks[:] = lmis
        return HinfProgram._check(prog, plant, values, 1.0, 0.0)  # type: ignore[arg-type]

    return run


def test_a_point_with_negative_lmis_and_positive_lyapunov_matrices_is_certified(checked):
    ok, lmi_margin, lyap_min, why, lmis = checked(_values(2.0, 3.0, 0.5), -np.eye(3), np.diag([-1.0, -0.5]))
    assert ok and why == "" and len(lmis) == 2
    assert lmi_margin == 0.5  # minus the largest LMI eigenvalue
    assert lyap_min == pytest.approx((5 - math.sqrt(2)) / 2, rel=4 * EPS)  # eig of [[2, .5], [.5, 3]]


@pytest.mark.parametrize(("P", "lyap"), [((1.0, 1.0, 2.0), -1.0),  # indefinite: eigenvalues 3 and -1
                                         ((1.0, 1.0, 1.0), 0.0),   # singular: not definite
                                         ((-1.0, -2.0, 0.0), -2.0)])
def test_an_indefinite_or_singular_lyapunov_matrix_is_refused(checked, P, lyap):
    ok, _, lyap_min, why, _ = checked(_values(*P), -np.eye(2))
    assert not ok
    assert lyap_min == pytest.approx(lyap, abs=8 * EPS)
    assert why.startswith("largest LMI eigenvalue -1 (Phi_0), smallest Lyapunov eigenvalue ")


def test_an_lmi_not_negative_beyond_rounding_is_refused_and_named(checked):
    values = _values(2.0, 3.0, 0.5)
    ok, margin, _, why, _ = checked(values, -np.eye(2), np.diag([-2.0, -1.0, 1e-3]), np.diag([-1.0, -2.0]))
    assert not ok and margin == -1e-3
    assert why.startswith("largest LMI eigenvalue 0.001 (Phi_1)")
    # within 100 eps of the largest eigenvalue's size is still not < 0: refused
    assert not checked(values, np.diag([-1.0, -50 * EPS]))[0]
    assert checked(values, np.diag([-1.0, -1000 * EPS]))[0]


def test_a_non_positive_gamma_squared_or_non_finite_values_are_refused(checked):
    assert not checked(_values(2.0, 3.0, 0.5, delta=0.0), -np.eye(2))[0]
    assert checked(_values(2.0, 3.0, 0.5, delta=1e-12), -np.eye(2))[0]
    for bad in (_values(2.0, np.nan, 0.5), _values(2.0, 3.0, 0.5, delta=math.inf)):
        assert checked(bad, -np.eye(2)) == (False, -math.inf, -math.inf, "the solver returned non-finite values", [])


# -- the solver fallback --------------------------------------------------------------------


@pytest.fixture(scope="module")
def ex1():
    return load_system("peixoto-ex1").model()


def test_an_auto_chosen_scs_point_that_fails_the_check_is_solved_by_clarabel(ex1, monkeypatch):
    """SCS stopped after a few iterations returns a point that fails the check, twice (the
    second time with the larger margin); a single design then falls back to Clarabel."""
    monkeypatch.setattr(program, "AUTO_CLARABEL_MAX_ROWS", 0)  # AUTO takes SCS at every size
    prog = HinfProgram.for_plant(ex1, kind=KIND_ROBUST, solver_options={"max_iters": 3})
    assert prog.solver == "SCS" and prog.auto
    res = prog.attempt(ex1, 150.0)
    assert res.design is not None and res.design.solver == "CLARABEL" and res.status == "optimal"
    assert res.design.plant == ex1.name == "peixoto-ex1/plant"  # a design names the model it was made for
    tried = res.detail.split("; ")
    assert tried[0].startswith("SCS margin 1.0e-06: ") and tried[1].startswith("SCS margin 3.0e-05: ")
    assert tried[2] == "CLARABEL margin 1.0e-06: optimal"
    # within a search (warm starts) there is no fallback: the search goes on with its other points
    with prog.warm_starts():
        res = prog.attempt(ex1, 150.0)
    assert res.design is None and math.isinf(res.gamma) and "CLARABEL" not in res.detail
    assert len(res.detail.split("; ")) == 2
    # SCS asked for by name: no fallback either
    named = HinfProgram.for_plant(ex1, kind=KIND_ROBUST, solver="scs", solver_options={"max_iters": 3})
    assert named.solver == "SCS" and not named.auto
    assert named.attempt(ex1, 150.0).design is None


def test_the_solver_is_chosen_by_the_rows_of_the_lmis():
    # 6 LMIs of size 11 (396 rows), 40 of size 20 (8,400 rows); the bound is 4,000 rows
    assert choose_solver(2, 2, 2, 1) == "CLARABEL" and choose_solver(4, 3, 3, 5) == "SCS"
    # 3 vertices: 18 LMIs; size 14: 18 * 105 = 1,890 rows; size 21: 18 * 231 = 4,158
    assert choose_solver(3, 3, 1, 1) == "CLARABEL" and choose_solver(3, 4, 3, 2) == "SCS"
    assert choose_solver(3, 3, 9, 8, KIND_ROBUST) == choose_solver(3, 3, 9, 8)


# -- the multiplier and the arguments ---------------------------------------------------------


def test_the_multiplier_of_epsilon_is_a_unit_direction_and_phi_is_taken_modulo_pi():
    for eps in (-100.0, -1.0, 0.0, 0.5, 150.0):
        a, b = multiplier(eps)
        assert math.hypot(a, b) == pytest.approx(1.0, abs=2 * EPS) and b >= 0
        assert a / b == pytest.approx(eps, rel=4 * EPS)  # epsilon = a / b
    assert multiplier(math.inf) == multiplier(-math.inf) == (1.0, 0.0)
    with pytest.raises(NonFiniteError, match=r"^epsilon is NaN$"):
        multiplier(math.nan)
    for phi in (0.3, -1.2, 0.3 + math.pi, -1.2 - 2 * math.pi):
        a, b = lmis.ab_of_phi(phi)
        p = math.atan(lmis.epsilon_of_phi(phi))
        assert (a, b) == pytest.approx((math.sin(p), math.cos(p)), abs=8 * EPS)
    for phi in (math.pi / 2, -math.pi / 2, 3 * math.pi / 2):
        assert lmis.ab_of_phi(phi) == (1.0, 0.0) and lmis.epsilon_of_phi(phi) == math.inf


def test_programs_refuse_bad_dimensions_kinds_and_margins(ex1):
    with pytest.raises(DimensionError, match=r"^nx must be a positive integer; found 0$"):
        HinfProgram(2, 0, 1, 1, 1)
    with pytest.raises(DimensionError, match=r"^nw must be a positive integer; found True$"):
        HinfProgram(2, 2, 1, 1, True)
    with pytest.raises(ArgumentError, match=r"^kind must be 'parameter-dependent' or 'robust'; found 'pd'$"):
        HinfProgram(2, 2, 1, 1, 1, kind="pd")
    with pytest.raises(ArgumentError, match=r"found 'parameter-depen\.\.\.-name' \(45 characters\)$"):
        HinfProgram(2, 2, 1, 1, 1, kind="parameter-dependent-but-with-a-very-long-name")  # cut at 30
    with pytest.raises(ArgumentError, match=r"^margin must be a positive finite number; found 0$"):
        HinfProgram(2, 2, 1, 1, 1, margin=0)
    with pytest.raises(ArgumentError, match=r"^margin must be a positive finite number; found inf$"):
        HinfProgram(2, 2, 1, 1, 1, margin=math.inf)
    prog = HinfProgram(2, 2, 1, 2, 1)
    with pytest.raises(ArgumentError, match=r"^give exactly one of epsilon and phi$"):
        prog.attempt(ex1)
    with pytest.raises(ArgumentError, match=r"^give exactly one of epsilon and phi$"):
        prog.attempt(ex1, 1.0, phi=0.5)
    with pytest.raises(ArgumentTypeError, match=r"must be a PolytopicLPV or an AffineLPV .*; found str$"):
        prog.attempt("plant", 1.0)  # type: ignore[arg-type]
    other = load_system("peixoto-ex2").model()
    if (other.n_vertices, other.nx, other.ny, other.nz, other.nw) != (2, 2, 1, 2, 1):
        with pytest.raises(DimensionError, match=r"this program was compiled for \(2, 2, 1, 2, 1\)"):
            prog.attempt(other, 1.0)


def test_an_epsilon_curve_records_each_epsilon_and_its_angle(ex1):
    from lpvest.design import epsilon_curve, search_epsilon

    curve = epsilon_curve(ex1, [-0.5, 150.0, math.inf], kind=KIND_ROBUST)
    np.testing.assert_array_equal(curve.epsilon, [-0.5, 150.0, math.inf])
    np.testing.assert_array_equal(curve.phi, [math.atan(-0.5), math.atan(150.0), math.pi / 2])
    assert np.all(np.isfinite(curve.gamma[1:])) and curve.best()[1] == min(curve.gamma)
    with pytest.raises(ArgumentError, match=r"^n_grid must be an integer, at least 3; found 2$"):
        search_epsilon(ex1, kind=KIND_ROBUST, n_grid=2)


@pytest.mark.parametrize("n", [2, 3, 5])
def test_the_stability_check_covers_vertices_edges_the_barycentre_and_the_interior(n):
    """A(alpha) is checked on these points of the unit simplex before a design is tried: each on
    the simplex, every vertex, every edge finely, the barycentre and (beyond two vertices, where
    the edge is the whole simplex) 64 interior points."""
    pts = program._simplex_points(n)
    assert np.all(pts >= 0) and np.allclose(pts.sum(axis=1), 1.0, rtol=0, atol=4 * n * np.finfo(float).eps)
    per_edge = 101 if n <= 4 else 21
    edges = n * (n - 1) // 2
    interior = 64 if n > 2 else 0
    assert pts.shape == (n + edges * (per_edge - 2) + 1 + interior, n)
    np.testing.assert_array_equal(pts[:n], np.eye(n))
    on_edges = pts[n:n + edges * (per_edge - 2)]
    assert np.all(np.count_nonzero(on_edges, axis=1) == 2)
    assert len({tuple(np.flatnonzero(p)) for p in on_edges}) == edges  # every pair of vertices
    np.testing.assert_array_equal(pts[n + edges * (per_edge - 2)], np.full(n, 1.0 / n))
    assert np.all(pts[len(pts) - interior:] > 0)  # strictly inside
    assert len({tuple(p) for p in pts[len(pts) - interior:]}) == interior


def test_a_solves_lyapunov_blocks_are_symmetric_and_a_program_for_another_kind_is_refused(ex1):
    """P(alpha) = [[P1, P3], [P3^T, P2]] must be symmetric for its eigenvalue check (eigvalsh reads
    one triangle) to certify anything: P1 and P2 are symmetric variables, exactly."""
    from lpvest.design import design_hinf

    prog = HinfProgram.for_plant(ex1, kind=KIND_PD)
    assert prog.attempt(ex1, 1.0).design is not None
    for name in ("P1", "P2"):
        for var in prog._var[name]:
            assert np.array_equal(var.value, var.value.T), name
    with pytest.raises(ArgumentError, match=r"^the program is for a parameter-dependent filter, not "
                                            r"'robust_but_with..._here' \(42 characters\)$"):
        design_hinf(ex1, kind="robust_but_with_a_very_long_kind_name_here", program=prog, epsilon=1.0)


def test_an_epsilon_search_with_no_certified_point_says_so_naming_the_program_and_the_plant(ex1, monkeypatch):
    """Every grid point's solve fails (a made-up infeasible attempt): the search raises with the
    program's kind and solver, the plant, how many epsilons were tried and the solves' detail."""
    tried = []

    def attempt(self, plant, epsilon=None, *, phi=None, **options):
        tried.append(phi)
        return program.DesignAttempt(None, "infeasible", math.inf, "made-up solve: infeasible")

    monkeypatch.setattr(HinfProgram, "attempt", attempt)
    with pytest.raises(LMIInfeasibleError) as info:
        search.search_epsilon(ex1, n_grid=6)
    assert str(info.value) == ("parameter-dependent H-infinity LMIs for peixoto-ex1/plant at every epsilon tried "
                               "(6 values), solver CLARABEL: no certified solution (made-up solve: infeasible)")
    assert info.value.status == "infeasible" and info.value.detail == "made-up solve: infeasible"
    # the grid: 6 angles phi = atan(epsilon) a sixth of pi apart, epsilon = inf (phi = pi/2) among them
    angles = np.sort(tried)
    assert len(tried) == 6 and angles[-1] == math.pi / 2
    np.testing.assert_allclose(np.diff(angles), math.pi / 6, rtol=0, atol=8 * EPS)


@pytest.mark.parametrize("solver", ["BOGUS", "OSQP", 3])
def test_a_solver_that_cannot_solve_lmis_is_refused_before_compiling(solver):
    """An unknown name, or an installed solver without semidefinite cones (OSQP): one
    ArgumentError naming the solvers that can, not cvxpy's SolverError after the compile."""
    from lpvest.design._program import sdp_solvers

    assert {"CLARABEL", "SCS"} <= set(sdp_solvers()) and "OSQP" not in sdp_solvers()
    with pytest.raises(ArgumentError, match=r"solver .*: expected AUTO or an installed cvxpy solver of "
                                            r"semidefinite programs \(CLARABEL, SCS"):
        HinfProgram(2, 2, 1, 1, 2, solver=solver)


def test_the_search_progress_bar_is_shown_only_when_asked_and_on_a_terminal(monkeypatch):
    """A bar of the designs solved out of the grid, on a terminal; never when not asked, and never
    into a redirected log (no carriage returns there)."""
    import io
    import sys

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    screen = Terminal()
    monkeypatch.setattr(sys, "stderr", screen)
    assert search._progress_bar(False, 7) is None
    bar = search._progress_bar(True, 7)
    bar.update(2)
    bar.close()
    assert bar.total == 7 and "epsilon search" in screen.getvalue() and "2/7" in screen.getvalue()
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a redirected log
    assert search._progress_bar(True, 7) is None


# -- what a failed design says, and what reaches the solver -------------------------------------------


def test_a_solver_given_as_a_list_is_refused_shown_cut_at_30_characters():
    """A tuple of solver names (one solver is meant) is refused before compiling, shown cut at 30
    characters like every culprit in lpvest's messages."""
    with pytest.raises(ArgumentError, match=r"^solver \('CLARABEL', 'SCS', 'MOSEK'\.\.\.: expected AUTO or an "
                                            r"installed cvxpy solver of semidefinite programs \(CLARABEL, "):
        HinfProgram(2, 2, 1, 1, 1, solver=("CLARABEL", "SCS", "MOSEK", "GUROBI"))


def test_the_lyapunov_check_certifies_only_beyond_100_eps_of_the_matrix_size(checked):
    """P(alpha) certified positive definite means its smallest eigenvalue exceeds rounding: 100 eps
    times its largest eigenvalue's size (at least 1), as the LMIs' side. At exactly that it is not
    certified; half an eps above it, it is (diagonal P: eigvalsh returns the diagonal exactly)."""
    assert not checked(_values(100 * EPS, 1.0, 0.0), -np.eye(2))[0]
    ok, _, lyap_min, _, _ = checked(_values(100.5 * EPS, 1.0, 0.0), -np.eye(2))
    assert ok and lyap_min == 100.5 * EPS
    # relative to the size: the same eigenvalue ratio for P = 4 diag(100.5 eps, 1)
    assert checked(_values(402 * EPS, 4.0, 0.0), -np.eye(2))[0]
    assert not checked(_values(400 * EPS, 4.0, 0.0), -np.eye(2))[0]


def test_solver_options_reach_the_solver_and_a_failed_design_lists_every_solve(ex1):
    """Clarabel stopped after 2 iterations (its max_iter): no design, the solver's status, and
    each solve tried (the requested margin, then the larger one) with its status."""
    prog = HinfProgram.for_plant(ex1, kind=KIND_ROBUST, solver="clarabel", solver_options={"max_iter": 2})
    res = prog.attempt(ex1, 150.0)
    assert res.design is None and math.isinf(res.gamma) and math.isnan(res.gamma_lower)
    assert res.status == "user_limit"
    assert res.detail == "CLARABEL margin 1.0e-06: user_limit; CLARABEL margin 3.0e-05: user_limit"
    # a search compiles its program with the same options: every point fails the same way
    tried = r"at every epsilon tried \(3 values\), solver CLARABEL: no certified solution \(CLARABEL margin 1\.0e-06: "
    with pytest.raises(LMIInfeasibleError, match=tried + "user_limit; ") as info:
        search.search_epsilon(ex1, kind=KIND_ROBUST, n_grid=3, solver="clarabel", solver_options={"max_iter": 2})
    assert info.value.status == "user_limit"


def test_a_point_the_check_refuses_keeps_the_solvers_status_and_says_why(ex1):
    """Clarabel with tolerances of 0.1 says "optimal" at a point that violates the LMIs by far more
    than rounding: refused at both margins, the status says the solver's word and the check's,
    the detail each solve with the largest LMI eigenvalue found."""
    prog = HinfProgram.for_plant(ex1, kind=KIND_ROBUST, solver="CLARABEL",
                                 solver_options={"tol_gap_abs": 0.1, "tol_gap_rel": 0.1, "tol_feas": 0.1})
    res = prog.attempt(ex1, 150.0)
    assert res.design is None and res.status == "optimal; LMI check failed"
    why = (r"optimal, but the LMI check failed: largest LMI eigenvalue \d\S* \(Phi_\d+\), "
           r"smallest Lyapunov eigenvalue \S+")
    assert re.fullmatch(f"CLARABEL margin 1.0e-06: {why}; CLARABEL margin 3.0e-05: {why}", res.detail), res.detail


def test_minus_infinity_is_recorded_as_the_one_infinite_epsilon(ex1):
    """epsilon = -inf and +inf are one multiplier (a, b) = (1, 0): the design records inf."""
    d = HinfProgram.for_plant(ex1, kind=KIND_ROBUST).attempt(ex1, -math.inf).design
    assert d is not None and d.epsilon == math.inf and d.multiplier == (1.0, 0.0)


def test_an_scs_solve_stopped_by_its_own_sigint_handler_interrupts_the_design(ex1, monkeypatch):
    """SCS catches SIGINT itself and returns "interrupted" (status -5), which cvxpy would report as
    a solver error, one more failed point of a search: a program solving with SCS raises
    Interrupted instead. (SCS's answer made "interrupted" here, tests/test_interrupt.py sends a
    real signal to the solver on its own.)"""
    import scs

    from lpvest.core._interrupt import Interrupted

    solve = scs.solve

    def interrupted(*args, **kwargs):
        out = solve(*args, **{**kwargs, "max_iters": 1})
        out["info"].update(status="interrupted", status_val=program._SCS_SIGINT)
        return out

    monkeypatch.setattr(scs, "solve", interrupted)
    prog = HinfProgram.for_plant(ex1, kind=KIND_ROBUST, solver="SCS")
    with pytest.raises(Interrupted, match="SIGINT"):
        prog.attempt(ex1, 150.0)
