"""H-infinity filter design by LMIs (Peixoto et al., 001_00f62b5a0c49ad87.txt).

Every certified design is checked against independent oracles
(tests/hinf_oracle.py): the paper scenario's error ratio, a search for the
worst-case l2 gain (exact on each fixed parameter sequence by the lifted
system's largest singular value), and the dissipation inequality of the proof
on a grid of (alpha_k, alpha_{k+1}).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math

import numpy as np
import pytest

from lpvest import LMIInfeasibleError, PolytopicLPV, load_system
from lpvest.core._errors import DimensionError, NonFiniteError
from lpvest.design import (
    KIND_PD,
    KIND_ROBUST,
    DesignAttempt,
    HinfDesign,
    HinfProgram,
    design_hinf,
    epsilon_curve,
    lmi_matrices,
    multiplier,
    search_epsilon,
)
from lpvest.design._lmis import canonical_phi
from lpvest.design._search import _search
from tests import hinf_oracle as oracle
from tests.hinf_misprint import printed_phi21
from tests.tolerances import LMI_RESOLVE_GAMMA_RTOL, roundoff


# ---------------------------------------------------------------------------
# plants and designs shared by the module (each design costs ~0.1 s, a search ~3 s)
# ---------------------------------------------------------------------------
def ex1():
    return load_system("peixoto-ex1").model()


def ex2(rho):
    return load_system("peixoto-ex2", parameters={"rho": rho}, allow_outside_range=True).model()


def random_stable_plant(seed=7, N=3, nx=3, ny=2, nz=2, nw=2):
    """A 3-vertex plant with ||A_i||_2 = 0.7: P = I proves stability under switching."""
    rng = np.random.default_rng(seed)
    data = oracle.random_plant_data(rng, N, nx, ny, nz, nw)
    data["A"] = np.array([0.7 * a / np.linalg.norm(a, 2) for a in data["A"]])
    return PolytopicLPV(data, name="random-3-vertex")


_CACHE: dict[str, tuple[PolytopicLPV, HinfDesign]] = {}


def get_design(name):
    if name not in _CACHE:
        if name == "ex1-pd-150":
            p = ex1()
            _CACHE[name] = (p, design_hinf(p, epsilon=150.0, kind=KIND_PD))
        elif name == "ex1-robust-150":
            p = ex1()
            _CACHE[name] = (p, design_hinf(p, epsilon=150.0, kind=KIND_ROBUST))
        elif name == "ex1-pd-best":
            p = ex1()
            _CACHE[name] = (p, search_epsilon(p, kind=KIND_PD).design)
        elif name == "ex1-robust-best":
            p = ex1()
            _CACHE[name] = (p, search_epsilon(p, kind=KIND_ROBUST).design)
        elif name == "ex2-rho21-best":
            p = ex2(21.0)
            _CACHE[name] = (p, search_epsilon(p, kind=KIND_PD).design)
        elif name == "random3-pd":
            p = random_stable_plant()
            _CACHE[name] = (p, design_hinf(p, epsilon=-0.5, kind=KIND_PD))
        elif name == "random3-robust":
            p = random_stable_plant()
            _CACHE[name] = (p, design_hinf(p, epsilon=math.inf, kind=KIND_ROBUST))
        else:  # pragma: no cover
            raise KeyError(name)
    return _CACHE[name]


DESIGNS = ["ex1-pd-150", "ex1-robust-150", "ex1-pd-best", "ex1-robust-best", "ex2-rho21-best",
           "random3-pd", "random3-robust"]


def scenario_alpha(plant, k):
    """The paper's scheduling theta_k = sin(0.25 k) (Figs. 1-2) through the
    plant's map; for the random 3-vertex plant three phase-shifted sinusoids."""
    if plant.simplex_map is not None:
        return plant.alpha_batch(np.sin(0.25 * k)[:, None])
    ph = 0.25 * k[:, None] + np.array([0.0, 2.0, 4.0]) * np.pi / 3
    return (1.0 + np.sin(ph)) / 3.0


# ---------------------------------------------------------------------------
# the LMIs: Finsler identity, printed blocks, Lemma 1
# ---------------------------------------------------------------------------
def _block_tol(plant, var, mult, blocks=1):
    """Two assemblies of the same LMI blocks (lpvest's and the oracle's): each
    entry is a sum of at most n = block size products of a variable, a plant
    matrix and a multiplier (|a|, |b|, epsilon, 1), each factor at most the
    largest entry of its kind; a few stages (products, He{.}, the sum of
    blocks ij + ji, ``blocks`` terms of a convex combination)."""
    data = max(float(np.max(np.abs(v))) for v in plant.vertices)
    vars_ = max(float(np.max(np.abs(np.asarray(x)))) for x in var.values())
    n = 4 * plant.nx + plant.nz + plant.nw
    size = max(1.0, data) * max(1.0, vars_) * max(1.0, *(abs(m) for m in mult)) * n
    return roundoff(size, 4 * blocks, n=n)


@pytest.mark.blas_sensitive
@pytest.mark.parametrize("robust", [False, True])
def test_lmis_are_q_plus_he_xg_on_random_data(rng, robust):
    """Every assembled LMI equals Q + He{X G} built from the proof (Finsler form)."""
    N, nx, ny, nz, nw = 3, 3, 2, 2, 2
    plant = PolytopicLPV(oracle.random_plant_data(rng, N, nx, ny, nz, nw))
    var = oracle.random_variables(rng, N, nx, ny, nz, nw, robust=robust)
    a, b = rng.standard_normal(2)
    lmis = lmi_matrices(plant, var, multiplier_ab=(a, b), robust=robust)
    assert len(lmis) == N * N * (N + 1) // 2
    data = [dict(zip(("A", "Bw", "Cz", "Dz", "Cy", "Dy"), (v[i] for v in plant.vertices), strict=True))
            for i in range(N)]

    def phi(i, j, nxt):  # Phi_ijl with l = nxt (the vertex of alpha_{k+1})
        f = 0 if robust else j
        v = {k: var[k][j] for k in ("X1", "X2", "X3", "X4", "X5", "X6")}
        v.update({k: var[k][f] for k in ("H", "Af", "Bf", "Cf", "Df")})
        Pn = (var["P1"][nxt], var["P2"][nxt], var["P3"][nxt])
        Pc = (var["P1"][j], var["P2"][j], var["P3"][j])
        return oracle.finsler_phi(data[i], v, Pn, Pc, var["delta"], a, b)

    tol = _block_tol(plant, var, (a, b))
    for blk in lmis:
        want = phi(blk.i, blk.i, blk.l) if blk.i == blk.j else phi(blk.i, blk.j, blk.l) + phi(blk.j, blk.i, blk.l)
        np.testing.assert_allclose(blk.matrix, want, rtol=0, atol=tol)
        np.testing.assert_array_equal(blk.matrix, blk.matrix.T)  # symmetric by construction


@pytest.mark.blas_sensitive
def test_printed_blocks_agree_except_phi21(rng):
    """At (a, b) = (epsilon, 1) our blocks are the printed ones with Phi_21 using
    P_{3,l} (alpha_{k+1}); the printed P_{3,j} is what tests/hinf_misprint.py builds."""
    N, nx, ny, nz, nw = 2, 2, 1, 2, 1
    plant = PolytopicLPV(oracle.random_plant_data(rng, N, nx, ny, nz, nw))
    var = oracle.random_variables(rng, N, nx, ny, nz, nw)
    eps = 150.0
    data = [dict(zip(("A", "Bw", "Cz", "Dz", "Cy", "Dy"), (v[i] for v in plant.vertices), strict=True))
            for i in range(N)]

    def printed(i, j, nxt, p3):
        v = {k: var[k][j] for k in var if k != "delta"}
        Pn = (var["P1"][nxt], var["P2"][nxt], var["P3"][nxt])
        Pc = (var["P1"][j], var["P2"][j], var["P3"][j])
        return oracle.printed_phi(data[i], v, Pn, Pc, var["delta"], eps, phi21_p3=p3)

    for misprint in (False, True):
        with printed_phi21() if misprint else contextlib.nullcontext():
            lmis = lmi_matrices(plant, var, epsilon=eps)
        for blk in lmis:
            def one(i, j, nxt):
                return printed(i, j, nxt, var["P3"][j] if misprint else var["P3"][nxt])  # noqa: B023

            want = one(blk.i, blk.i, blk.l) if blk.i == blk.j else one(blk.i, blk.j, blk.l) + one(blk.j, blk.i, blk.l)
            np.testing.assert_allclose(blk.matrix, want, rtol=0, atol=_block_tol(plant, var, (eps,)))
    # and the two differ exactly where P_{3,j} != P_{3,l}
    good = lmi_matrices(plant, var, epsilon=eps)
    with printed_phi21():
        bad = lmi_matrices(plant, var, epsilon=eps)
    diffs = [np.max(np.abs(g.matrix - b.matrix)) for g, b in zip(good, bad, strict=True)]
    assert [d > 0 for d in diffs] == [g.l != g.i or g.l != g.j for g in good]


@pytest.mark.blas_sensitive
def test_lemma1_combinations_reproduce_phi_of_alpha(rng):
    """sum_l a+_l [sum_i a_i^2 Phi_iil + sum_{i<j} a_i a_j (Phi_ijl + Phi_jil)]
    equals Q(alpha, alpha+) + He{X(alpha) G(alpha)} with interpolated data (4)."""
    N, nx, ny, nz, nw = 3, 2, 1, 2, 1
    plant = PolytopicLPV(oracle.random_plant_data(rng, N, nx, ny, nz, nw))
    var = oracle.random_variables(rng, N, nx, ny, nz, nw)
    a, b = multiplier(0.7)
    lmis = lmi_matrices(plant, var, multiplier_ab=(a, b))
    for _ in range(3):
        al, an = rng.dirichlet(np.ones(N)), rng.dirichlet(np.ones(N))
        total = sum(an[blk.l] * al[blk.i] * al[blk.j] * blk.matrix for blk in lmis)
        m = plant.at(al)
        d = dict(zip(("A", "Bw", "Cz", "Dz", "Cy", "Dy"), m, strict=True))

        def interp(name, w):
            return sum(w[i] * var[name][i] for i in range(N))

        v = {k: interp(k, al) for k in var if k != "delta"}
        Pn = tuple(interp(k, an) for k in ("P1", "P2", "P3"))
        Pc = tuple(interp(k, al) for k in ("P1", "P2", "P3"))
        want = oracle.finsler_phi(d, v, Pn, Pc, var["delta"], a, b)
        # the N^3 weighted blocks against the interpolated data and variables:
        # N^3 + 3 N more terms per entry (weights on the simplex)
        np.testing.assert_allclose(total, want, rtol=0, atol=_block_tol(plant, var, (a, b), blocks=N**3 + 3 * N))


@pytest.mark.blas_sensitive
def test_rescaling_is_exact():
    """The rescaled LMIs at (a, b) and the paper's at epsilon = a/b are the same
    up to the congruence T = diag(I, sI, I, sI, I, I), s = 1/b, and the two
    filter realizations give the same output."""
    plant = ex1()
    eps = 150.0
    prog = HinfProgram.for_plant(plant, kind=KIND_PD)
    design = prog.solve(plant, eps)
    hat = prog.last_variables()
    a, b = design.multiplier
    assert a / b == pytest.approx(eps, rel=roundoff(1.0, 2))  # (a, b) from epsilon: a couple of roundings
    s = 1.0 / b
    paper = {k: v for k, v in hat.items()}
    for k, p in (("P2", 2), ("P3", 1), ("X2", 1), ("X4", 1), ("H", 2), ("Af", 2), ("Bf", 1), ("Cf", 1)):
        paper[k] = [m / s**p for m in hat[k]]
    nx, nz, nw = plant.nx, plant.nz, plant.nw
    T = np.diag(np.concatenate([np.ones(nx), s * np.ones(nx), np.ones(nx), s * np.ones(nx), np.ones(nz + nw)]))
    Ti = np.linalg.inv(T)
    # the congruence and the variables' rescaling by powers of s: rounding of
    # the blocks (their own size) amplified by cond(T)^2 = s^2 (s >= 1 here)
    amp = max(s, 1 / s) ** 2
    for ours, theirs in zip(lmi_matrices(plant, hat, multiplier_ab=(a, b)),
                            lmi_matrices(plant, paper, epsilon=eps), strict=True):
        size = float(np.max(np.abs(theirs.matrix)))
        n = theirs.matrix.shape[0]
        np.testing.assert_allclose(theirs.matrix, Ti @ ours.matrix @ Ti, rtol=0, atol=roundoff(size, 4, n=n, amp=amp))
        assert np.max(np.linalg.eigvalsh(theirs.matrix)) < 0
    # the paper's variables are badly scaled (filter ~ 1/eps^2), ours are not
    assert np.max(np.abs(paper["H"])) < 1e-3 < np.max(np.abs(hat["H"]))
    # same filter: simulate both realizations on the paper scenario
    k = np.arange(60.0)
    alpha = scenario_alpha(plant, k)
    y = np.random.default_rng(0).standard_normal((60, 1))
    paper_design = dataclasses.replace(design, **{n: np.stack(paper[n]) for n in ("H", "Af", "Bf", "Cf", "Df")})
    from lpvest.estimators._hinf import hinf_filter_batch

    # two realizations of one stable filter, states scaled by powers of s: the
    # rescaled matrices carry rounding amplified by s^2, through 60 steps
    want = hinf_filter_batch(design, y, alpha).zhat
    np.testing.assert_allclose(hinf_filter_batch(paper_design, y, alpha).zhat, want, rtol=0,
                               atol=roundoff(float(np.max(np.abs(want))) + 1.0, 60, n=4, amp=amp))


# ---------------------------------------------------------------------------
# Table 1
# ---------------------------------------------------------------------------
def test_table1_theorem1():
    _, d = get_design("ex1-pd-150")
    assert d.gamma == pytest.approx(1.21, abs=0.01)  # paper Table 1 (printed to 2 decimals)
    assert d.status in ("optimal", "optimal_inaccurate") and d.lmi_margin > 0 and d.lyapunov_margin > 0


def test_table1_corollary1():
    _, d = get_design("ex1-robust-150")
    assert d.gamma == pytest.approx(8.18, rel=0.005)  # paper Table 1
    assert d.H.shape == (1, 2, 2) and not d.scheduled


def test_best_epsilon_beats_the_paper_and_a_grid():
    """The search over all real epsilon finds gamma no worse than epsilon = 150
    and within 0.5 % of the best of a dense grid (Corollary 1, Example 1)."""
    plant, best = get_design("ex1-robust-best")
    _, at150 = get_design("ex1-robust-150")
    assert best.gamma <= at150.gamma
    phis = np.linspace(-np.pi / 2, np.pi / 2, 61)[1:]
    grid = epsilon_curve(plant, np.append(np.tan(phis[:-1]), math.inf), kind=KIND_ROBUST)
    assert np.all(np.isfinite(grid.gamma))
    assert best.gamma <= 1.005 * float(np.min(grid.gamma))
    assert best.gamma == pytest.approx(8.016, abs=0.01)  # lpvest: epsilon ~ -0.02 (paper: 8.18 at 150)


def test_search_curve_is_exposed():
    plant = ex1()
    s = search_epsilon(plant, kind=KIND_PD, n_grid=8, n_refine=1)
    c = s.curve
    assert len(c.epsilon) == len(c.gamma) == len(c.status) == len(c.phi) == s.n_evaluations
    assert np.all(np.diff(c.phi) > 0) and c.phi[-1] == pytest.approx(np.pi / 2)
    assert math.isinf(c.epsilon[-1])
    assert c.best()[1] == s.design.gamma == min(c.gamma)
    with pytest.raises(ValueError, match="read-only"):
        c.gamma[0] = 0.0
    assert np.any(c.epsilon < 0) and np.any(c.epsilon > 0)


@pytest.mark.parametrize("kind", [KIND_PD, KIND_ROBUST])
@pytest.mark.parametrize("epsilon", [150.0, -0.02, 1.0])
def test_dual_bound_is_below_every_design_at_that_epsilon(kind, epsilon):
    """gamma_lower (weak duality at the solver's dual point) is a lower bound of
    the strict LMIs: no design at the same epsilon, whatever its margin, is
    better. Checked against solves with margins 10 and 100 times smaller (whose
    gamma moves down towards the bound by the margin's cost m sum tr Z)."""
    plant = ex1()
    at = HinfProgram.for_plant(plant, kind=kind).attempt(plant, epsilon)
    assert at.design is not None and 0 < at.gamma_lower <= at.gamma
    # the cost of the margin 1e-6 here: gamma - gamma_lower ~ 1e-6 sum tr Z / (2 gamma) ~ 1e-4 relative
    assert at.gamma - at.gamma_lower < 1e-3 * at.gamma
    for margin in (1e-7, 1e-8):
        finer = HinfProgram.for_plant(plant, kind=kind, margin=margin).attempt(plant, epsilon)
        assert finer.design is not None
        # both are solver answers: each within Clarabel's accuracy (tests/tolerances.py)
        assert at.gamma_lower <= finer.gamma * (1 + LMI_RESOLVE_GAMMA_RTOL)
        assert finer.gamma <= at.gamma * (1 + LMI_RESOLVE_GAMMA_RTOL)


def _fake_attempt(gamma, gamma_lower, status="optimal"):
    design = None if math.isinf(gamma) else object()
    return DesignAttempt(design, status, gamma, "", gamma_lower=gamma_lower)  # type: ignore[arg-type]


def _search_on(curve, n_grid=12):
    """_search on a synthetic gamma(phi): curve(phi) -> (gamma, gamma_lower)."""
    points = {}

    def evaluate(phi):
        key = canonical_phi(phi)
        if key not in points:
            points[key] = _fake_attempt(*curve(key))
        return points[key].gamma

    return _search(ex1(), None, evaluate, points, n_grid, 2, 1e-3)


def test_a_curve_flat_within_the_solver_accuracy_is_not_refined():
    # SCS-like noise: gamma scatters by 1e-4 above a flat optimum 1.0, each point's
    # dual bound at the optimum: the grid is all the search evaluates
    noise = np.random.default_rng(3)
    s = _search_on(lambda phi: (1.0 + 1e-4 * noise.random(), 1.0 - 1e-9))
    assert s.n_evaluations == 12
    # the same scatter without the bounds (a solver without duals): refined as before
    s = _search_on(lambda phi: (1.0 + 1e-4 * noise.random(), math.nan))
    assert s.n_evaluations > 12


def test_a_real_dip_is_refined_to_its_minimum():
    # intervals 1e-8 wide (Clarabel-like) on a curve with its minimum between grid points
    def curve(phi):
        g = 2.0 + (phi - 0.3) ** 2
        return g, g - 1e-8

    s = _search_on(curve)
    assert s.n_evaluations > 12
    best_epsilon, best_gamma = s.curve.best()
    assert math.atan(best_epsilon) == pytest.approx(0.3, abs=2e-3)  # xatol 1e-3 in phi
    assert best_gamma < 2.0 + 1e-5


@pytest.mark.parametrize(("status", "refined"), [("optimal; LMI check failed", False), ("infeasible", True)])
def test_a_failed_neighbour_is_no_evidence_but_an_infeasible_one_is(status, refined):
    # flat within accuracy except one grid point without a design: a failed solve says
    # nothing about gamma there; an infeasible point is a real rise of the curve
    step = math.pi / 12

    def curve(phi):
        if abs(phi - (-math.pi / 2 + 6 * step)) < 1e-12:
            return math.inf, math.nan
        return 1.0 + (1e-6 if abs(phi - (-math.pi / 2 + 5 * step)) < 1e-12 else 1e-5), 1.0

    points = {}

    def evaluate(phi):
        key = canonical_phi(phi)
        if key not in points:
            g, lo = curve(key)
            points[key] = _fake_attempt(g, lo, status if math.isinf(g) else "optimal")
        return points[key].gamma

    s = _search(ex1(), None, evaluate, points, 12, 2, 1e-3)
    assert (s.n_evaluations > 12) is refined


# ---------------------------------------------------------------------------
# search_epsilon's logic on made-up curves: a stand-in for the compiled program
# ---------------------------------------------------------------------------
class CurveProgram:
    """Stands in for a compiled :class:`HinfProgram` in :func:`search_epsilon`: each
    ``attempt`` reads a made-up ``gamma(phi)`` (no LMI is solved) and records the angle.

    ``curve(phi)`` gives ``gamma`` (``inf``: infeasible there), or ``(gamma, gamma_lower)``
    (by default the interval is 1e-8 wide, Clarabel-like); the "design" returned is the
    angle and the gamma it was made at."""

    kind = KIND_PD
    solver = "MADE-UP"

    def __init__(self, curve, status=lambda phi: "infeasible", detail=lambda phi: "made-up: infeasible"):
        self.curve, self.status, self.detail = curve, status, detail
        self.tried: list[float] = []
        self.warm = False

    def _check_dims(self, plant):
        assert isinstance(plant, PolytopicLPV)

    @contextlib.contextmanager
    def warm_starts(self):
        self.warm = True
        try:
            yield
        finally:
            self.warm = False

    def attempt(self, plant, epsilon=None, *, phi=None):
        assert self.warm  # inside warm starts
        if phi is None:  # (a, b) of epsilon: +-inf is phi = pi/2
            phi = math.pi / 2 if math.isinf(epsilon) else math.atan(epsilon)
        self.tried.append(phi)
        value = self.curve(phi)
        gamma, lower = value if isinstance(value, tuple) else (value, value - 1e-8)
        if math.isinf(gamma):
            return DesignAttempt(None, self.status(phi), math.inf, self.detail(phi))
        design = dataclasses.make_dataclass("MadeUpDesign", ["phi", "gamma"])(phi, gamma)
        return DesignAttempt(design, "optimal", gamma, "made-up: optimal", gamma_lower=lower)  # type: ignore[arg-type]


def _grid(n_grid):
    """The search's grid: n_grid angles pi / n_grid apart, the last at pi/2 (epsilon = inf)."""
    step = math.pi / n_grid
    return np.array([-math.pi / 2 + step * (k + 1) for k in range(n_grid)])


def test_an_epsilon_curve_is_made_by_the_program_given():
    """epsilon_curve with a program solves with it (its own settings), at each epsilon in the
    order given; -inf is the one infinite epsilon, at phi = pi/2."""
    prog = CurveProgram(lambda phi: 2.0 + abs(phi - 0.3))
    c = epsilon_curve(ex1(), [2, -math.inf, 0.5], program=prog)
    phi = [math.atan(2.0), math.pi / 2, math.atan(0.5)]
    assert prog.tried == phi
    np.testing.assert_array_equal(c.epsilon, [2.0, math.inf, 0.5])
    np.testing.assert_array_equal(c.phi, phi)
    np.testing.assert_array_equal(c.gamma, [2.0 + abs(p - 0.3) for p in phi])
    np.testing.assert_array_equal(c.gamma_lower, c.gamma - 1e-8)
    assert c.status == ("optimal",) * 3


def _beyond(prog, n_grid, refined):
    """The angles tried after the grid that lie outside the Brent brackets (grid[k] - step,
    grid[k] + step) of the minima ``refined``: none when just those were refined."""
    grid, step = _grid(n_grid), math.pi / n_grid
    return [p for p in prog.tried[n_grid:] if not any(grid[k] - step < p < grid[k] + step for k in refined)]


def test_the_default_search_tries_24_grid_angles_then_finds_the_minimum_within_xatol():
    """The defaults (n_grid 24, n_refine 2, xatol 1e-3): the grid first, in order, then the
    minimum between two grid points found to xatol = 1e-3 in phi; the design returned is the
    one made at the best angle tried, and every angle tried is on the curve once. (A kink at
    the minimum: Brent's parabolas do not land on it at once, xatol decides when it stops.)"""
    prog = CurveProgram(lambda phi: 2.0 + abs(phi - 0.3))
    s = search_epsilon(ex1(), program=prog)
    explicit = CurveProgram(prog.curve)
    search_epsilon(ex1(), program=explicit, n_grid=24, n_refine=2, xatol=1e-3)
    assert prog.tried == explicit.tried  # the documented defaults
    np.testing.assert_array_equal(prog.tried[:24], _grid(24))
    assert len(prog.tried) > 24 and _beyond(prog, 24, [13]) == []  # grid[13] = 0.262, the only minimum
    best = s.curve.phi[np.argmin(s.curve.gamma)]
    assert abs(best - 0.3) <= 1e-3  # scipy's bounded Brent stops within xatol of the minimum
    assert s.design.phi == best and s.design.gamma == min(s.curve.gamma)  # type: ignore[attr-defined]
    assert s.n_evaluations == len(prog.tried) == len(set(prog.tried)) == len(s.curve.phi)
    np.testing.assert_array_equal(s.curve.phi, np.sort(prog.tried))
    np.testing.assert_array_equal(s.curve.gamma_lower, s.curve.gamma - 1e-8)  # each point's own dual bound


def test_xatol_sets_how_close_the_refinement_gets_and_what_it_costs():
    """xatol (radians of phi) is how close the refinement gets, each time within it; a
    tighter one costs more evaluations (a kink at the minimum, where Brent's parabolas
    cannot land on it at once)."""
    found, cost = [], []
    for xatol in (0.05, 1e-3, 1e-6):
        prog = CurveProgram(lambda phi: 2.0 + abs(phi - 0.3))
        s = search_epsilon(ex1(), program=prog, n_grid=12, n_refine=1, xatol=xatol)
        best = s.curve.phi[np.argmin(s.curve.gamma)]
        assert abs(best - 0.3) <= xatol
        found.append(abs(best - 0.3))
        cost.append(s.n_evaluations - 12)
    assert cost[0] < cost[1] < cost[2]


def _wells(depths):
    """Three narrow wells in gamma(phi), just right of grid points 3, 5 and 7 of a 12-angle grid,
    with these depths: the grid's local minima are exactly 3, 5 and 7 (humps at 4 and 6)."""
    centres = _grid(12)[[3, 5, 7]] + 0.03

    def curve(phi):
        return min(d + 40.0 * (phi - c) ** 2 for d, c in zip(depths, centres, strict=True))

    return curve, centres


@pytest.mark.parametrize(("n_refine", "refined"), [(None, {7, 3}), (1, {7}), (3, {3, 5, 7}), (0, set())])
def test_the_n_refine_deepest_grid_minima_are_refined_each_between_its_grid_neighbours(n_refine, refined):
    """Grid minima at 3, 5 and 7, the deepest at 7, then 3 (deeper than 5 although 5 sits
    between them): the n_refine deepest are refined, by default 2; every grid point no higher
    than its two grid neighbours is a minimum (5 too, though its neighbours' neighbours are
    lower); each refinement finds its well's bottom within xatol."""
    curve, centres = _wells((1.5, 2.0, 1.0))
    prog = CurveProgram(curve)
    options = {} if n_refine is None else {"n_refine": n_refine}
    s = search_epsilon(ex1(), program=prog, n_grid=12, **options)
    assert _beyond(prog, 12, refined) == []  # the brackets of 3, 5 and 7 do not overlap
    for k, c in zip((3, 5, 7), centres, strict=True):  # each refined well's bottom found, within xatol
        assert bool(min(abs(p - c) for p in prog.tried) <= 1e-3) is (k in refined)
    assert (s.n_evaluations == 12) is (not refined)


def _grid_curve(values, lowers):
    """gamma(phi) through the given values (and dual bounds) at the 12 grid angles, linear
    between them."""
    grid = _grid(12)

    def curve(phi):
        k = int(np.argmin(np.abs(grid - phi)))
        if abs(grid[k] - phi) < 1e-12:
            return values[k], lowers[k]
        g = float(np.interp(phi, grid, values))
        return g, g - 1e-8

    return curve


def test_a_minimum_flat_with_its_two_grid_neighbours_is_not_refined_whatever_lies_beyond():
    """Grid points 4, 5, 6 are one constant gamma to the solver's accuracy (their intervals
    [gamma_lower, gamma] share 1.0): not refined, although point 7 beyond rises far above."""
    values = [1.0 + 0.5 * min(abs(j - 5), 12 - abs(j - 5)) for j in range(12)]
    values[4:7] = [1.0 + 1e-6, 1.0, 1.0 + 2e-6]
    lowers = [v - 1e-8 for v in values]
    lowers[4:7] = [1.0 - 1e-9] * 3
    prog = CurveProgram(_grid_curve(values, lowers))
    assert search_epsilon(ex1(), program=prog, n_grid=12).n_evaluations == 12


@pytest.mark.parametrize(("gap", "refined"), [(0.0, False), (2.0**-20, True)])
def test_intervals_that_only_touch_still_share_a_point_so_the_curve_is_flat_there(gap, refined):
    """The minimum's interval [0.75, 1.0] and its neighbours' [1.0, 1.25] share the point 1.0:
    flat (not refined); moved 2**-20 apart, they share none: a real dip, refined."""
    values = [1.25 + 0.5 * min(abs(j - 5), 12 - abs(j - 5)) for j in range(12)]
    lowers = [v - 1e-8 for v in values]
    values[5], lowers[5] = 1.0, 0.75
    lowers[4] = lowers[6] = 1.0 + gap
    prog = CurveProgram(_grid_curve(values, lowers))
    s = search_epsilon(ex1(), program=prog, n_grid=12)
    assert (s.n_evaluations > 12) is refined
    assert _beyond(prog, 12, [5]) == []


def test_a_minimum_beside_an_infeasible_stretch_is_found_and_the_infeasible_points_are_kept():
    """gamma ~ 20 with its minimum at phi = 0.3, no design above phi = 0.35 (inside the Brent
    bracket of the grid minimum): the refinement is not drawn into the infeasible stretch
    (infeasible counts as worse than every design), finds the minimum within xatol, and
    the curve keeps the infeasible angles tried with gamma inf, their status and no bound."""
    prog = CurveProgram(lambda phi: 20.0 + 100.0 * (phi - 0.3) ** 2 if phi <= 0.35 else math.inf)
    s = search_epsilon(ex1(), program=prog, n_grid=12)
    best = s.curve.phi[np.argmin(s.curve.gamma)]
    assert abs(best - 0.3) <= 1e-3 and s.design.phi == best  # type: ignore[attr-defined]
    infeasible = s.curve.phi > 0.35
    assert np.any(infeasible & ~np.isin(s.curve.phi, _grid(12)))  # Brent tried the stretch too
    assert np.all(np.isinf(s.curve.gamma[infeasible])) and np.all(np.isnan(s.curve.gamma_lower[infeasible]))
    assert {s.curve.status[i] for i in np.flatnonzero(infeasible)} == {"infeasible"}


def test_a_search_without_any_certified_point_names_every_status_and_reason():
    """No grid angle gives a design, for two reasons: the error names the number of epsilons
    tried, both statuses and both reasons (LMIInfeasibleError.status and .detail)."""
    half = lambda phi: phi < 0  # noqa: E731
    prog = CurveProgram(lambda phi: math.inf, status=lambda phi: "infeasible" if half(phi) else "solver_error",
                        detail=lambda phi: "made-up: infeasible" if half(phi) else "made-up: solver failed")
    with pytest.raises(LMIInfeasibleError) as info:
        search_epsilon(ex1(), program=prog, n_grid=6)
    assert str(info.value) == ("parameter-dependent H-infinity LMIs for peixoto-ex1/plant at every epsilon tried "
                               "(6 values), solver MADE-UP: no certified solution (made-up: infeasible; "
                               "made-up: solver failed)")
    assert info.value.status == "infeasible | solver_error"
    assert info.value.detail == "made-up: infeasible; made-up: solver failed"
    assert len(prog.tried) == 6  # the grid, nothing more


def test_the_search_shows_its_bar_only_when_asked_counting_designs_and_the_best_gamma(monkeypatch):
    """On a terminal: no bar by default; asked, a bar of the designs solved, out of the grid
    and then out of one more per refinement step, saying when it refines, the solver and the
    best gamma so far (what the final frame shows)."""
    import io
    import sys

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    screen = Terminal()
    monkeypatch.setattr(sys, "stderr", screen)
    search_epsilon(ex1(), program=CurveProgram(lambda phi: 2.0 + (phi - 0.3) ** 2), n_grid=12)
    assert screen.getvalue() == ""
    s = search_epsilon(ex1(), program=CurveProgram(lambda phi: 2.0 + (phi - 0.3) ** 2), n_grid=12, progress=True)
    frames = screen.getvalue().split("\r")[1:]
    n = s.n_evaluations
    assert frames[0].startswith("epsilon search: ") and " 0/12 " in frames[0]  # out of the grid first
    final = frames[-1]
    assert n > 12 and final.startswith("epsilon refine: ") and f" {n}/{n} " in final
    assert f"MADE-UP, best gamma {min(s.curve.gamma):.6g}" in final


# ---------------------------------------------------------------------------
# every design: scenario, worst case, dissipation
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", DESIGNS)
def test_paper_scenario_ratio_below_gamma(name):
    plant, d = get_design(name)
    k = np.arange(100.0)
    alpha = scenario_alpha(plant, k)
    w = np.where(k >= 10, np.sin(0.5 * k) * np.exp(-0.1 * k), 0.0)[:, None] * np.ones((1, plant.nw))
    e = oracle.simulate_error(plant, d, alpha, w)
    assert np.linalg.norm(e) / np.linalg.norm(w) <= d.gamma


@pytest.mark.parametrize("name", DESIGNS)
def test_worst_case_gain_below_gamma(name, rng):
    plant, d = get_design(name)
    gain, where = oracle.worst_case_gain(plant, d, rng)
    print(f"{name}: worst gain found {gain:.6g} ({where}), gamma {d.gamma:.6g}")
    assert gain <= d.gamma, f"{name}: gain {gain} at {where} exceeds gamma {d.gamma}"


@pytest.mark.parametrize("name", DESIGNS)
def test_dissipation_inequality_on_alpha_grid(name):
    plant, d = get_design(name)
    grid = oracle.simplex_grid(plant.n_vertices, 10 if plant.n_vertices == 2 else 4)
    worst = max(oracle.dissipation_max_eig(plant, d, a, an) for a in grid for an in grid)
    assert worst < 0
    assert np.all(np.linalg.eigvalsh(d.lyapunov) > 0)


def test_printed_phi21_certifies_a_false_gamma(rng):
    """The trap: with the printed Phi_21 (P_{3,j}) the robust design for Example 1
    reports gamma ~ 2.63, but vertex switching drives the filter's gain far above."""
    plant = ex1()
    with printed_phi21():
        prog = HinfProgram.for_plant(plant, kind=KIND_ROBUST)
        d = prog.solve(plant, 150.0)
    assert d.gamma == pytest.approx(2.63, abs=0.02)
    gain, where = oracle.worst_case_gain(plant, d, rng, max_period=4, n_random=0)
    assert gain > 4 * d.gamma, where  # > 10: the "certificate" is false
    assert gain > get_design("ex1-robust-150")[1].gamma  # even above the true certified bound 8.17


# ---------------------------------------------------------------------------
# JSON
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["ex1-pd-150", "ex1-robust-best"])
def test_json_round_trip(name, tmp_path):
    _, d = get_design(name)
    path = tmp_path / "design.json"
    text = d.to_json(path)
    for back in (HinfDesign.from_json(path), HinfDesign.from_json(text)):
        for field in ("H", "Af", "Bf", "Cf", "Df", "lyapunov"):
            np.testing.assert_array_equal(getattr(back, field), getattr(d, field))
        for field in ("kind", "gamma", "epsilon", "multiplier", "solver", "status", "compile_time",
                      "solve_time", "lmi_margin", "lyapunov_margin", "n_lmis", "nw", "plant"):
            assert getattr(back, field) == getattr(d, field), field


def test_json_infinite_epsilon_and_errors(tmp_path):
    from lpvest.core._errors import ModelFileError

    _, d = get_design("random3-robust")
    assert math.isinf(d.epsilon) and d.multiplier == (1.0, 0.0)
    import json

    data = json.loads(d.to_json())
    assert data["epsilon"] is None
    assert math.isinf(HinfDesign.from_json(d.to_json()).epsilon)
    with pytest.raises(ModelFileError, match="not valid JSON"):
        HinfDesign.from_json("{not json")
    with pytest.raises(ModelFileError, match="not an lpvest H-infinity design"):
        HinfDesign.from_json('{"format": "other"}')
    data["filter"]["Bf"] = [[[1.0]]]
    with pytest.raises(ModelFileError, match="Bf has shape"):
        HinfDesign.from_dict(data)
    del data["gamma"]
    with pytest.raises(ModelFileError, match="missing field 'gamma'"):
        HinfDesign.from_dict(data)
    with pytest.raises(ModelFileError, match="cannot be read"):
        HinfDesign.from_json(tmp_path / "missing.json")


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
def test_unstable_plant_raises_infeasible():
    plant = ex2(22.0)  # vertex 1 has an eigenvalue below -1 for rho > 21.4
    with pytest.raises(LMIInfeasibleError, match="vertex 1 of the plant has spectral radius 1.03") as info:
        design_hinf(plant, epsilon=1.0)
    assert info.value.status == "infeasible"
    with pytest.raises(LMIInfeasibleError,
                       match=r"at every epsilon, solver CLARABEL: no certified solution \(not solved: vertex") as info:
        search_epsilon(plant, n_grid=4)
    assert info.value.status == "infeasible"


def test_switching_unstable_plant_is_infeasible_with_the_solver_status():
    """Each frozen vertex is nilpotent (Schur), but switching between them is
    unstable (A_1 A_2 has eigenvalue 2.25): no certificate can exist; the error
    carries the solver's status."""
    c = 1.5
    plant = PolytopicLPV({
        "A": [[[0, c], [0, 0]], [[0, 0], [c, 0]]], "Bw": [[[1], [0]], [[1], [0]]],
        "Cz": [[[1, 0]], [[1, 0]]], "Dz": [[[0]], [[0]]], "Cy": [[[0, 1]], [[0, 1]]], "Dy": [[[1]], [[1]]],
    }, name="switching-unstable")
    for kind in (KIND_PD, KIND_ROBUST):
        with pytest.raises(LMIInfeasibleError, match="switching-unstable at epsilon = 0") as info:
            design_hinf(plant, epsilon=0.0, kind=kind)
        assert info.value.status in ("infeasible", "infeasible_inaccurate", "solver_error")


def test_failed_check_is_an_error_not_a_result():
    """The solver is selectable; SCS (first order) stops at points that violate
    the LMIs by more than the margin, here as in the issue's report: they are
    rejected (twice, with the retry), never reported as a gamma."""
    plant = ex1()
    with pytest.raises(LMIInfeasibleError, match="solver SCS: no certified solution.*LMI check failed") as info:
        design_hinf(plant, epsilon=150.0, solver="SCS", solver_options={"max_iters": 2000})
    assert info.value.status.endswith("; LMI check failed")


def test_wrong_dimensions_and_types():
    prog = HinfProgram.for_plant(ex1())
    with pytest.raises(DimensionError, match=r"plant has \(N, nx, ny, nz, nw\) = \(3, 3, 2, 2, 2\); this program"):
        prog.solve(random_stable_plant(), 1.0)
    with pytest.raises(DimensionError, match=r"program was compiled for"):
        design_hinf(random_stable_plant(), epsilon=1.0, program=prog)
    with pytest.raises(TypeError, match="must be a PolytopicLPV"):
        design_hinf(np.eye(2), epsilon=1.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="kind must be"):
        design_hinf(ex1(), epsilon=1.0, kind="gain-scheduled")
    with pytest.raises(NonFiniteError, match="epsilon is NaN"):
        design_hinf(ex1(), epsilon=float("nan"))
    _, d = get_design("ex1-pd-150")
    with pytest.raises(DimensionError, match=r"Df has shape \(2, 2, 1\); expected \(2, 2, 3\)"):
        dataclasses.replace(d, Bf=np.zeros((2, 2, 3)))
    with pytest.raises(DimensionError, match="a robust design needs 1 set"):
        dataclasses.replace(d, kind=KIND_ROBUST)
    for bad in ("2", 2.5, True, 0):
        with pytest.raises(DimensionError, match="n_vertices must be a positive integer"):
            HinfProgram(bad, 2, 1, 2, 1)  # type: ignore[arg-type]


def test_last_variables_are_never_an_earlier_solve_after_a_solver_failure(monkeypatch):
    import cvxpy as cp

    plant = ex1()
    prog = HinfProgram.for_plant(plant, kind=KIND_ROBUST)
    with pytest.raises(LMIInfeasibleError, match="no solution yet"):
        prog.last_variables()
    prog.solve(plant, 1.0)
    assert prog.last_variables()["delta"] > 0

    def fail(*args, **kwargs):
        raise cp.error.SolverError("simulated failure")

    monkeypatch.setattr(prog._problem, "solve", fail)
    attempt = prog.attempt(plant, 2.0)
    assert attempt.design is None and "simulated failure" in attempt.detail
    # cvxpy keeps the variables of the solve at epsilon = 1: not this program's last answer
    with pytest.raises(LMIInfeasibleError, match="no solution yet"):
        prog.last_variables()


def test_both_infinities_of_epsilon_are_the_one_multiplier_at_phi_pi_over_2():
    c = epsilon_curve(ex1(), [-math.inf, math.inf], kind=KIND_ROBUST)
    assert list(c.epsilon) == [math.inf, math.inf] and list(c.phi) == [math.pi / 2] * 2
    assert c.gamma[0] == c.gamma[1]


def test_a_plant_unstable_inside_the_polytope_is_refused_at_once():
    # every vertex is Schur (spectral radius 0.5) but A(alpha) at the midpoint has eigenvalue 2: the
    # search took 38 s and ended in "solver_error ... try another solver"; the LMIs imply A(alpha) Schur on
    # the whole simplex, so the answer is known before any solve
    plant = PolytopicLPV({
        "A": [[[0.5, 3.0], [0.0, 0.5]], [[0.5, 0.0], [3.0, 0.5]]], "Bw": [[[1], [0]], [[1], [0]]],
        "Cz": [[[1, 0]], [[1, 0]]], "Dz": [[[0]], [[0]]], "Cy": [[[0, 1]], [[0, 1]]], "Dy": [[[1]], [[1]]],
    }, name="unstable-inside")
    assert max(np.max(np.abs(np.linalg.eigvals(a))) for a in plant.vertices.A) == 0.5
    for call in (lambda: search_epsilon(plant), lambda: design_hinf(plant, epsilon=1.0, kind=KIND_ROBUST)):
        with pytest.raises(LMIInfeasibleError, match=r"for unstable-inside at .*: no certified solution \(not solved: "
                                                     r"A\(alpha\) at alpha = \(0\.5, 0\.5\) has spectral radius 2 >= 1 "
                                                     r"although every vertex is Schur") as info:
            call()
        assert info.value.status == "infeasible"
        assert len(str(info.value)) <= 300 and "\n" not in str(info.value)
        assert "so no filter exists" in info.value.detail


def test_errors_from_a_design_name_the_system_and_model():
    # issue 12: the message named the model key "plant" only, not which file's plant
    plant = load_system("peixoto-ex2", parameters={"rho": 22.0}, allow_outside_range=True).model()
    with pytest.raises(LMIInfeasibleError, match=r"^parameter-dependent H-infinity LMIs for peixoto-ex2/plant at "
                                                 r"epsilon = 1, solver CLARABEL: no certified solution \(not solved: "
                                                 r"vertex 1 of the plant has spectral radius 1\.03"):
        design_hinf(plant, epsilon=1.0)
