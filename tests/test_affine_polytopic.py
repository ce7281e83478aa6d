"""Affine LPV models, polytopic models and the exact affine-to-polytopic conversion."""

import numpy as np
import pytest

from lpvest import (
    AffineDependence,
    AffineLPV,
    CallableBasis,
    DimensionError,
    ExpressionError,
    Monomial,
    NotPositiveDefiniteError,
    PolytopicLPV,
    SchedulingRangeError,
    SchedulingSpace,
    affine_to_polytopic,
    load_system,
)
from lpvest.core._scheduling import parse_basis
from lpvest.core._validation import check_simplex
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel

SPACE2 = SchedulingSpace(["p1", "p2"], [-1.0, 0.5], [2.0, 3.0])


def _random_dependence(rng, basis, shapes):
    mats = {
        name: {term: rng.standard_normal(shape) for term in ["1", *[b.name for b in basis]]}
        for name, shape in shapes.items()
    }
    return AffineDependence.build(SPACE2, basis, mats), mats


BASES = {
    "components": lambda: [Monomial.parse("p1", SPACE2), Monomial.parse("p2", SPACE2)],
    "multiaffine product": lambda: [
        Monomial.parse("p1", SPACE2), Monomial.parse("p2", SPACE2), Monomial.parse("p1*p2", SPACE2)
    ],
    "powers": lambda: [Monomial.parse("p1^2", SPACE2), Monomial.parse("p1*p2^3", SPACE2)],
    "formula with bounds": lambda: [
        parse_basis("p1", SPACE2), parse_basis("sin(p2)", SPACE2, bounds=(-1.0, 1.0))
    ],
    "callable with bounds": lambda: [
        CallableBasis(lambda p: np.exp(-p[0] ** 2), "gauss", (0.0, 1.0)), parse_basis("p2", SPACE2)
    ],
}


@pytest.mark.parametrize("kind", list(BASES))
def test_conversion_reproduces_matrices_on_the_box(kind, rng):
    basis = BASES[kind]()
    dep, _ = _random_dependence(rng, basis, {"A": (3, 3), "B": (3, 2), "C": (1, 3)})
    vertices, mapping = affine_to_polytopic(dep)
    p = SPACE2.sample(rng, 200)
    p = np.vstack([p, SPACE2.corners()])
    alpha = mapping.evaluate(p)
    direct = dep.evaluate_batch(p)
    for t in range(p.shape[0]):
        check_simplex(alpha[t], "alpha")
    for name, stack in vertices.items():
        combo = np.einsum("ti,irc->trc", alpha, stack)
        # vertices (sums over the basis at the corners), the map alpha(p) and the
        # convex combination: three stages of at most n_vertices + n_basis + 1
        # terms, each of size <= max |vertex entry| (alpha on the simplex)
        n = stack.shape[0] + len(basis) + 1
        size = float(np.max(np.abs(stack))) + float(np.max(np.abs(direct[name])))
        np.testing.assert_allclose(combo, direct[name], rtol=0, atol=roundoff(size, 3, n=n))


def test_multiaffine_conversion_uses_component_corners(rng):
    dep, _ = _random_dependence(rng, BASES["multiaffine product"](), {"A": (2, 2)})
    vertices, mapping = affine_to_polytopic(dep)
    assert mapping.n_vertices == 4  # 2**n_p, not 2**n_psi = 8
    for v, corner in enumerate(SPACE2.corners()):
        want = dep.evaluate(corner)["A"]
        # one sum over the 3 basis terms + constant, in two arrangements
        np.testing.assert_allclose(vertices["A"][v], want, rtol=0, atol=roundoff(np.max(np.abs(want)) + 1.0, 1, n=4))


def test_monomial_bounds_are_exact():
    space = SchedulingSpace(["a", "b"], [-2.0, 0.5], [1.0, 3.0])
    assert Monomial.parse("a^2", space).bounds(space) == (0.0, 4.0)
    assert Monomial.parse("a^3", space).bounds(space) == (-8.0, 1.0)
    assert Monomial.parse("a*b", space).bounds(space) == (-6.0, 3.0)
    lo, hi = Monomial.parse("a^2*b", space).bounds(space)
    assert (lo, hi) == (0.0, 12.0)


def test_non_monomial_without_bounds_cannot_be_converted(rng):
    dep, _ = _random_dependence(rng, [parse_basis("sin(p1)", SPACE2)], {"A": (2, 2)})
    with pytest.raises(ExpressionError, match="'sin\\(p1\\)' is not a monomial: give its bounds"):
        affine_to_polytopic(dep)


def test_a_basis_function_may_not_use_shift_and_shift_by_zero_is_the_variable():
    with pytest.raises(ExpressionError, match=r"may not use shift\(\); it depends on p_t only"):
        parse_basis("shift(p1, 1)", SPACE2)
    # shift(p1, 0) was accepted and then needed a value for 'shift(p1, 0)' at evaluation
    b = parse_basis("sin(shift(p1, 0))", SPACE2, bounds=(-1.0, 1.0))
    p = np.array([[0.3, 1.0], [-0.7, 0.5]])
    assert np.array_equal(b.evaluate(p), parse_basis("sin(p1)", SPACE2, bounds=(-1.0, 1.0)).evaluate(p))


def test_peixoto_printed_vertices_equal_conversion_of_system_10():
    plant = load_system("peixoto-ex1").model()
    assert plant.affine is not None
    vertices, mapping = affine_to_polytopic(plant.affine)
    # the printed decimals against coefficient +- coefficient: one rounding
    # each of numbers of size <= 2
    for name in ("A", "Bw", "Cz", "Dz", "Cy", "Dy"):
        np.testing.assert_allclose(vertices[name], getattr(plant.vertices, name), rtol=0, atol=roundoff(2.0, 1))
    # and the paper's map alpha_1 = (1 - theta)/2 is the conversion's map
    theta = np.linspace(-1, 1, 21)[:, None]
    np.testing.assert_allclose(mapping.evaluate(theta), plant.simplex_map.evaluate(theta), rtol=0,
                               atol=roundoff(1.0, 2))
    np.testing.assert_allclose(plant.alpha_batch(theta)[:, 0], (1 - theta[:, 0]) / 2, rtol=0, atol=roundoff(1.0, 2))


def test_peixoto_dz_is_2x1():
    plant = load_system("peixoto-ex1").model()
    assert plant.vertices.Dz.shape == (2, 2, 1)  # ERRATA: printed 2x2, n_w = 1


def test_polytopic_simulation_matches_affine_system_10(rng):
    # oracle: system (10) written out by hand from the paper
    plant = load_system("peixoto-ex1").model()
    T = 40
    theta = np.sin(0.25 * np.arange(T))
    w = rng.standard_normal(T)
    traj = plant.simulate(plant.alpha_batch(theta[:, None]), w[:, None])
    # per step: matrices from the vertices (4 terms) against the printed
    # formula, then A x + Bw w (3 terms); over T steps with no growth assumed
    size = float(np.max(np.abs(traj.x))) + 1.5 * float(np.max(np.abs(w)))
    tol = roundoff(size, 2 * T, n=4)
    x = np.zeros(2)
    for k in range(T):
        th = theta[k]
        A = np.array([[0.265 - 0.165 * th, 0.45 * (1 + th)], [0.5 * (1 - th), 0.265 - 0.215 * th]])
        Bw = np.array([1.5 - 0.5 * th, 0.1])
        np.testing.assert_allclose(traj.x[k], x, rtol=0, atol=tol)
        np.testing.assert_allclose(traj.y[k], x[0] + w[k], rtol=0, atol=tol)
        x = A @ x + Bw * w[k]


def test_alpha_off_simplex_and_theta_out_of_range_are_rejected():
    plant = load_system("peixoto-ex1").model()
    with pytest.raises(SchedulingRangeError, match="alpha\\[2\\] = -0.2 < 0"):
        plant.at([1.2, -0.2])
    with pytest.raises(SchedulingRangeError, match="theta = 1.5 is outside its declared range \\[-1, 1\\]"):
        plant.alpha([1.5])
    with pytest.raises(DimensionError, match="alpha has shape \\(3,\\); expected \\(2,\\)"):
        plant.at([0.2, 0.3, 0.5])


def test_polytopic_vertex_shapes_checked():
    A = np.zeros((2, 2, 2))
    good = dict(A=A, Bw=np.zeros((2, 2, 1)), Cz=np.zeros((2, 1, 2)), Dz=np.zeros((2, 1, 1)),
                Cy=np.zeros((2, 1, 2)), Dy=np.zeros((2, 1, 1)))
    PolytopicLPV(good)
    bad = dict(good, Dz=np.zeros((2, 2, 2)))
    with pytest.raises(DimensionError, match=r"Dz vertices have shape \(2, 2, 2\); expected \(2, 1, 1\)"):
        PolytopicLPV(bad)


def _affine_model(**over):
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    kw = dict(A={"1": [[0.5, 0.1], [0.0, 0.3]], "p": [[0.1, 0.0], [0.0, -0.2]]},
              B=[[1.0], [0.0]], C={"1": [[1.0, 0.0]], "p": [[0.0, 0.5]]}, D=[[0.0]],
              G={"1": np.eye(2), "p": 0.1 * np.eye(2)}, H=[[1.0]],
              Q=[[0.2, 0.05], [0.05, 0.1]], R=[[0.05]], S=[[0.02], [0.01]])
    kw.update(over)
    return AffineLPV.from_matrices(space, [Monomial.component(0, space)], **kw)


def test_affine_lpv_evaluation():
    m = _affine_model()
    mats = m.at([0.4])
    # coefficient + 0.4 coefficient against the decimal: two roundings of numbers <= 1.04
    np.testing.assert_allclose(mats.A, [[0.54, 0.1], [0.0, 0.22]], rtol=0, atol=roundoff(1.04, 1))
    np.testing.assert_allclose(mats.C, [[1.0, 0.2]], rtol=0, atol=roundoff(1.04, 1))
    np.testing.assert_allclose(mats.G, 1.04 * np.eye(2), rtol=0, atol=roundoff(1.04, 1))
    assert (m.nx, m.nu, m.ny, m.nw, m.nv, m.n_p) == (2, 1, 1, 2, 1, 1)


def test_affine_lpv_noise_has_the_declared_joint_covariance():
    m = _affine_model()
    w, v = m.noise.sample(np.random.default_rng(3), 200_000)
    emp = np.cov(np.hstack([w, v]).T)
    # 200k samples: standard error of a covariance entry ~ 0.2/sqrt(2e5) ~ 5e-4
    np.testing.assert_allclose(emp, m.noise.joint, atol=3e-3)  # statistical: 6 standard errors, fixed seed


def test_affine_lpv_simulation_with_given_noise(rng):
    m = _affine_model()
    T = 30
    p = rng.uniform(-1, 1, (T, 1))
    u = rng.standard_normal((T, 1))
    w = rng.standard_normal((T, 2))
    v = rng.standard_normal((T, 1))
    traj = m.simulate(p, u, w=w, v=v)
    # the same recursion in another arrangement: per step sums of <= 4 products
    # of matrix entries (<= 1.04 here) with x, u, w, v; over T steps with no
    # growth assumed
    size = sum(float(np.max(np.abs(a))) for a in (traj.x, u, w, v))
    tol = roundoff(size, T, n=4)
    x = np.zeros(2)
    for t in range(T):  # eqs. (1a)-(1b) with the matrices from at()
        M = m.at(p[t])
        np.testing.assert_allclose(traj.y[t], M.C @ x + M.D @ u[t] + M.H @ v[t], rtol=0, atol=tol)
        x = M.A @ x + M.B @ u[t] + M.G @ w[t]


def test_affine_lpv_errors():
    with pytest.raises(DimensionError, match=r"^Q has shape \(3, 2\); expected a square matrix$"):
        _affine_model(Q=np.zeros((3, 2)))
    with pytest.raises(DimensionError, match=r"^G has shape \(2, 3\); expected \(2, 2\)$"):
        _affine_model(G=np.zeros((2, 3)))
    with pytest.raises(NotPositiveDefiniteError, match="joint noise covariance .* is not positive definite"):
        _affine_model(Q=[[1.0, 0.0], [0.0, 1.0]], R=[[1.0]], S=[[1.0], [0.0]])
    with pytest.raises(ExpressionError, match="term 'q' is not a basis function"):
        _affine_model(A={"1": np.eye(2), "q": np.eye(2)})
    m = _affine_model()
    with pytest.raises(SchedulingRangeError, match="p = 1.2 is outside"):
        m.at([1.2])
    with pytest.raises(DimensionError, match="give both noise sequences"):
        m.simulate(np.zeros((5, 1)), w=np.zeros((5, 2)))
