"""B-spline kernel estimator (Sridhar, Ghoshal & Michalska; issue 5)."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from lpvest import (
    BSplineObserver,
    DimensionError,
    ExpressionError,
    IdentifiabilityError,
    KernelModel,
    Known,
    LTVInputOutput,
    LTVStateSpace,
    NonFiniteError,
    SamplingError,
    UnknownConstant,
    UnknownSpline,
    fit_kernel_model,
    kernel_identity,
    kernel_regression,
    load_system,
    reconstruct_state,
)
from lpvest.core._protocol import Sampled as StreamingEstimator, run_streaming
from lpvest.estimators import bspline as bs
from lpvest.estimators.bspline import (
    _basis as basis,
    _fit as fit,
    _kernels as kernels,
    _model as model,
    _observer as observer,
    _regression as regression,
    _state as state,
)
from tests import kernel_oracle
from tests.tolerances import EPS, lstsq_rtol, roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel


def _assert_lstsq_close(beta, beta_ref, P, q):
    """Two least-squares solutions of min |q - P b| (lpvest's segment-wise QR,
    numpy's lstsq) agree within Wedin's bound (tests/tolerances.lstsq_rtol)
    in column-scaled coordinates: both are Householder-based, so their
    backward errors are small column by column (Higham, Thm 19.4) and the
    scaled condition number applies. Returns the bound."""
    d = np.linalg.norm(P, axis=0)
    Ps = P / d
    cond = np.linalg.cond(Ps)
    r = q - P @ beta_ref
    ratio = np.linalg.norm(r) / (np.linalg.norm(Ps, 2) * np.linalg.norm(d * beta_ref))
    rel = lstsq_rtol(cond, ratio, P.shape[1])
    assert np.linalg.norm(d * (beta - beta_ref)) <= rel * np.linalg.norm(d * beta_ref)
    return rel

# -- shared data -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sridhar():
    return load_system("sridhar-ltv").model()


@pytest.fixture(scope="module")
def traj20(sridhar):
    """Section V-A data: [0, 20] s at 1 kHz from x(0) = 0."""
    return sridhar.simulate(np.linspace(0.0, 20.0, 20001))


@pytest.fixture(scope="module")
def traj9(sridhar):
    """Section V-B data: [0, 9] s at 1 kHz."""
    return sridhar.simulate(np.linspace(0.0, 9.0, 9001))


@pytest.fixture(scope="module")
def noiseless_fit(sridhar, traj20):
    model = KernelModel.from_io(sridhar, a0=UnknownSpline(86, order=3), a1=UnknownConstant())
    return fit_kernel_model(model, traj20.t, traj20.u, traj20.y)


# A manufactured solution of (11) with every coefficient time-varying: y, u,
# a0, a1, b1 are chosen, b0 is solved from (11). No simulator involved.
def _y(t):
    return np.sin(1.3 * t) + 0.5 * np.cos(0.7 * t) + 0.2


def _dy(t):
    return 1.3 * np.cos(1.3 * t) - 0.35 * np.sin(0.7 * t)


def _ddy(t):
    return -1.69 * np.sin(1.3 * t) - 0.245 * np.cos(0.7 * t)


def _u(t):
    return 2.0 + np.cos(t)


def _du(t):
    return -np.sin(t)


def _a0(t):
    return t**2 + 1.0


def _a1(t):
    return 1.0 + 0.2 * np.sin(t)


def _da1(t):
    return 0.2 * np.cos(t)


def _b1(t):
    return 0.3 * np.cos(0.5 * t)


def _db1(t):
    return -0.15 * np.sin(0.5 * t)


def _b0(t):
    return -(_ddy(t) + _a1(t) * _dy(t) + _a0(t) * _y(t) + _b1(t) * _du(t)) / _u(t)


MANUFACTURED = {"a0": _a0, "a1": _a1, "da1": _da1, "b0": _b0, "b1": _b1, "db1": _db1}


# -- B-spline basis ----------------------------------------------------------------------------


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("kind", ["uniform", "clamped", "explicit"])
def test_bspline_basis_matches_scipy(order, kind):
    from scipy.interpolate import BSpline

    if kind == "explicit":  # non-uniform, extended beyond the window, with a double knot inside
        n = 9
        base = 5.0 * np.linspace(0.0, 1.0, n - order + 2) ** 1.5
        if order > 2:  # a double knot (a kink for quadratics, a jump in B' for cubics)
            base[3] = base[2]
        knots = np.concatenate([-0.4 * np.arange(order - 1, 0, -1), base, 5.0 + 0.4 * np.arange(1, order)])
        spec = UnknownSpline(n, order, knots=knots)
    else:
        spec = UnknownSpline(9, order, knots=kind)
    knots = bs.spline_knots(spec, 5.0)
    x = np.linspace(0.0, 5.0, 1001)
    first, vals = bs.bspline_basis(x, knots, order)
    dfirst, dvals = bs.bspline_basis(x, knots, order, derivative=True)
    dense = np.zeros((x.size, spec.n_basis))
    ddense = np.zeros((x.size, spec.n_basis))
    rows = np.arange(x.size)
    for r in range(order):
        dense[rows, first + r] = vals[:, r]
        ddense[rows, dfirst + r] = dvals[:, r]
    # Cox-de Boor: `order` stages of convex combinations with weights
    # (x - t_i) / (t_{i+k} - t_i), whose rounding is relative to |x| / h
    # (h the smallest positive knot spacing); the derivative divides by
    # spacings once more: (order - 1) / h
    gaps = np.diff(knots)
    h = float(np.min(gaps[gaps > 0]))
    amp = float(np.max(np.abs(knots))) / h
    tol = roundoff(1.0, order, n=2, amp=amp)
    for i in range(spec.n_basis):
        c = np.zeros(spec.n_basis)
        c[i] = 1.0
        ref = BSpline(knots, c, order - 1, extrapolate=True)
        np.testing.assert_allclose(dense[:, i], ref(x), rtol=0, atol=tol)
        if order > 1:
            np.testing.assert_allclose(ddense[:, i], ref.derivative()(x), rtol=0, atol=tol * (order - 1) / h)
    np.testing.assert_allclose(dense.sum(axis=1), 1.0, rtol=0, atol=order * tol)  # partition of unity on the window


def test_uniform_knots_cover_the_window_as_the_paper_says():
    # n = 86 quadratic B-splines on [0, 20]: 84 knot intervals of 20/84 across the window
    knots = bs.spline_knots(UnknownSpline(86, 3), 20.0)
    assert knots.size == 89
    # each knot a + k h rounded once or twice (size 20), a difference of two: 4 eps 20
    assert knots[2] == 0.0 and knots[86] == pytest.approx(20.0, abs=roundoff(20.0, 1))
    np.testing.assert_allclose(np.diff(knots), 20.0 / 84, rtol=0, atol=roundoff(20.0, 2))


# -- quadrature --------------------------------------------------------------------------------


@pytest.mark.parametrize("points", [4, 6])
def test_cumulative_quadrature_order(points):
    # oracle: scipy's adaptive quad on the analytic integrand, split at the knots
    from scipy.integrate import quad

    knots = np.array([-0.5, 0.0, 0.45, 0.9, 1.3, 1.75, 2.2, 2.7])
    order = 3

    def weight(x):
        first, vals = bs.bspline_basis(np.atleast_1d(x), knots, order)
        return np.where(first == 2, vals[:, 0], 0.0) + np.where(first == 1, vals[:, 1], 0.0) + np.where(
            first == 0, vals[:, 2], 0.0
        )  # B_2

    def f(x):
        return np.cos(5 * x) + 0.3 * x

    b = 2.0
    exact_F = [quad(lambda x, k=k: (x**k) * weight(x)[0] * f(x), 0, b, points=knots[1:-1], epsabs=1e-14,
                    epsrel=1e-13, limit=200)[0] for k in range(4)]
    exact_B = [quad(lambda x, k=k: ((b - x) ** k) * weight(x)[0] * f(x), 0, b, points=knots[1:-1], epsabs=1e-14,
                    epsrel=1e-13, limit=200)[0] for k in range(4)]
    errors = []
    for m in (41, 81, 161):
        t = np.linspace(0.0, b, m)
        q = kernels.product_quadrature(0.0, t[1] - t[0], m, breakpoints=knots, points=points)
        F, B = q.cumulative(weight(q.x) * q.interpolate(f(t)))
        errors.append(max(np.max(np.abs(F[:, -1] - exact_F)), np.max(np.abs(B[:, 0] - exact_B))))
        # forward and backward moments over the whole window agree at the ends:
        # the same q.x.size weighted terms summed in two orders (their absolute sum
        # is at most the integral of |B_2 f| <= b max |f|)
        size = b * float(np.max(np.abs(f(q.x))))
        np.testing.assert_allclose(F[0, -1], B[0, 0], rtol=0, atol=roundoff(size, 2, n=q.x.size))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # observed order of convergence: the rule is of order `points`
    assert np.all(rates > points - 0.6), (errors, rates)


def test_quadrature_is_exact_for_polynomial_data():
    # data of degree < points are interpolated exactly; with weight 1 (degree
    # 5 integrand) the 3-point Gauss rule is exact too
    t = np.linspace(-1.0, 1.5, 26)
    q = kernels.product_quadrature(-1.0, t[1] - t[0], t.size, breakpoints=[0.123, 0.77], points=6)
    data = t**5 - 2 * t**2
    F, _ = q.cumulative(q.interpolate(data))
    exact = (t**6 - 1.0) / 6 - 2 * (t**3 + 1.0) / 3
    # exact rule: rounding only, of the interpolation (6-point Lagrange weights,
    # Lebesgue constant < 4 on the interior nodes) and of the cumulative sum of
    # q.x.size terms of size <= h max |data|
    size = (t[-1] - t[0]) * float(np.max(np.abs(data)))
    np.testing.assert_allclose(F[0], exact, rtol=0, atol=roundoff(size, 3, n=q.x.size, amp=4.0))


def test_quadrature_moments_with_several_breakpoints_in_one_interval():
    # three breakpoints in one sample interval (four pieces), one on a sample
    # and one within 1e-9 h of a sample (both ignored), one outside; the data
    # are quadratic, so every moment's integrand has degree <= 5 and the
    # 3-point Gauss rule is exact. Oracle: the polynomials integrated exactly.
    from numpy.polynomial import polynomial as pn

    a, b = -1.0, 1.5
    t = np.linspace(a, b, 26)  # h = 0.1
    q = kernels.product_quadrature(a, t[1] - t[0], t.size, breakpoints=[0.123, 0.1234, 0.17, 0.7, 0.9 + 1e-12, 2.0])
    assert q.x.size == 3 * (t.size - 1 + 3)
    f = [2.0, -1.0, 0.5]
    F, B = q.cumulative(q.interpolate(pn.polyval(t, f)))
    # exact rule: rounding only, of cumulative sums of q.x.size terms of size
    # <= h (b - a)^k max |f| (3-point interpolation, Lebesgue constant < 2)
    fmax = float(np.max(np.abs(pn.polyval(q.x, f))))
    for k in range(4):
        forward = pn.polyint(pn.polymul(pn.polypow([-a, 1.0], k), f))  # of (x - a)^k f
        backward = pn.polyint(pn.polymul(pn.polypow([b, -1.0], k), f))  # of (b - x)^k f
        tol = roundoff((b - a) ** (k + 1) * fmax, 3, n=q.x.size, amp=2.0)
        np.testing.assert_allclose(F[k], pn.polyval(t, forward) - pn.polyval(a, forward), rtol=0, atol=tol)
        np.testing.assert_allclose(B[k], pn.polyval(b, backward) - pn.polyval(t, backward), rtol=0, atol=tol)


# -- the kernel identities (9), (10) --------------------------------------------------------------


def test_printed_kernels_reproduce_y_and_derived_derivative_kernels_reproduce_dy():
    # Oracle independent of the moment machinery: the kernels (13)-(19) as
    # printed (plus our t-derivatives of (12), (15)), integrated by scipy's
    # adaptive quad against the analytic y, u of a manufactured solution.
    from scipy.integrate import quad

    a, b = 0.5, 6.5
    for t0 in (a, 1.7, 3.5, 5.9, b):
        def ky(tau, t0=t0):
            return kernel_oracle.kernel_functions(t0, tau, a, b, MANUFACTURED)

        pts = [t0] if a < t0 < b else None
        iy = quad(lambda s: ky(s).Ky * _y(s), a, b, points=pts, epsabs=1e-13, limit=200)[0]
        iu = quad(lambda s: ky(s).Ku * _u(s), a, b, points=pts, epsabs=1e-13, limit=200)[0]
        # (9); method bound: two quad integrals with error estimates <= epsabs
        # 1e-13 each (scipy's estimate, for smooth integrands split at t0), a
        # hundredfold margin since quad's estimate is not a bound
        assert iy + iu == pytest.approx(_y(t0), abs=1e-11)
        C = (t0 - a) ** 2 + (b - t0) ** 2
        diy = quad(lambda s: ky(s).dKy * _y(s), a, b, points=pts, epsabs=1e-13, limit=200)[0]
        diu = quad(lambda s: ky(s).dKu * _u(s), a, b, points=pts, epsabs=1e-13, limit=200)[0]
        f_y = (2 * (t0 - a) - 2 * (b - t0)) / C - _a1(t0)
        f_u = -_b1(t0)
        # (10); the same method bound, with the derivative kernels (larger by 1 / C)
        assert f_y * _y(t0) + f_u * _u(t0) + diy + diu == pytest.approx(_dy(t0), abs=1e-10)


def test_kernel_identity_manufactured_solution():
    t = np.linspace(0.5, 6.5, 3001)
    a = [_a0, Known(lambda s: 1.0 + 0.2 * np.sin(s)).function]
    b1 = lpvest_tf(_b1, _db1)
    out = kernel_identity(t, _u(t), _y(t), a=a, b=[_b0, b1])
    # method bound: the product quadrature of order 6 at h = 2 ms on smooth
    # data (error ~ h^6 times the data's 6th derivative, ~1e-13 here; rounding
    # of the moment sums over 3000 samples, ~n eps |y|, is of the same order)
    np.testing.assert_allclose(out.y, _y(t), rtol=0, atol=1e-11)
    np.testing.assert_allclose(out.dy, _dy(t), rtol=0, atol=1e-10)


def lpvest_tf(fn, dfn):
    from lpvest import TimeFunction

    return TimeFunction.from_callable(fn, derivative=dfn)


def test_kernel_identity_with_true_coefficients_reproduces_sridhar_output(sridhar, traj20):
    # issue 5: (9) with the true coefficients reproduces y to 1e-10, and the
    # derivative identity reproduces y' = x_2
    out = kernel_identity(traj20.t, traj20.u, traj20.y, a=sridhar.a, b=sridhar.b)
    # method bound: the data come from DOP853 (rtol 1e-12), the quadrature is of
    # order `points` at h = 1 ms; rounding (~n eps |y| ~ 1e-12 over 20000 samples) is far below
    assert np.max(np.abs(out.y - traj20.y)) < 1e-10
    assert np.max(np.abs(out.dy - traj20.x[:, 1])) < 1e-9


# -- estimation: exact recovery ------------------------------------------------------------------
#
# The tolerances of the recovery tests are method bounds, not rounding: the
# data are exact (closed forms, or DOP853 at rtol 1e-12), the kernel
# integrals are exact only up to the quadrature (order `points` in h), and
# the least-squares fit amplifies that by its condition number
# (fit.condition, 1e2 to 2e4 here); the values were measured, and each
# tolerance is about ten times the measured error. Rounding moves the
# coefficients by eps times the condition number, < 4e-12 relative, which
# the noiseless-recovery test checks is far inside its tolerances.


def test_noiseless_recovery_sridhar(traj20, noiseless_fit):
    # issue 5 (paper Section V-A prints a1 = 0.9617): noiseless data at 1 kHz
    # must give a1 within 1e-6 and a0 = t^2 + 1 (in the spline space) to 1e-6
    fit = noiseless_fit
    t = traj20.t
    inner = (t >= 5.0) & (t <= 15.0)
    assert abs(fit.constants["a1"] - 1.0) < 1e-6
    # rounding moves the coefficients by ~eps cond (Higham (20.1)): four orders inside 1e-6
    assert 100 * EPS * fit.condition < 1e-8
    rel = np.abs(fit.values["a0"][inner] - (t[inner] ** 2 + 1)) / (t[inner] ** 2 + 1)
    assert np.max(rel) < 1e-6
    # the state: (9) and (10) with the estimated coefficients, x = (y, y') since b1 = 0
    assert np.max(np.abs(fit.y[inner] - traj20.y[inner])) < 1e-10
    assert np.max(np.abs(fit.dy[inner] - traj20.x[inner, 1])) < 1e-9
    np.testing.assert_allclose(fit.x[inner], traj20.x[inner], rtol=0, atol=1e-9)
    # the estimated spline object agrees with the values and differentiates exactly
    spline = fit.coefficients["a0"]
    # the same spline through scipy's de Boor and lpvest's basis: the basis
    # values' rounding is relative to |t| / h (h = 20 / 84; see the basis test),
    # three non-negative terms of one sign (a0 > 0): no cancellation
    h = 20.0 / 84
    np.testing.assert_allclose(spline(t[inner]), fit.values["a0"][inner], rtol=roundoff(1.0, 3, n=3, amp=20.0 / h))
    # method bound: the fit's 1e-6 relative error, differentiated (divided by ~h)
    np.testing.assert_allclose(spline.derivative()(t[inner]), 2 * t[inner], rtol=1e-5)
    assert fit.edf == 87 and fit.penalty == 0.0
    assert fit.labels[:2] == ("a0[0]", "a0[1]") and fit.labels[-1] == "a1"


@pytest.mark.parametrize("x0", [[0.0, 0.0], [0.05, -0.3], [-1.0, 2.0]])
def test_estimate_does_not_depend_on_the_initial_state(sridhar, x0):
    # the paper leaves x(0) unstated; the kernel representation needs none
    t = np.linspace(0.0, 8.0, 4001)
    d = sridhar.simulate(t, x0=x0)
    model = KernelModel.from_io(sridhar, a0=UnknownSpline(30), a1=UnknownConstant())
    fit = fit_kernel_model(model, t, d.u, d.y)
    assert abs(fit.constants["a1"] - 1.0) < 1e-8
    inner = (t >= 2.0) & (t <= 6.0)
    assert np.max(np.abs(fit.values["a0"][inner] / (t[inner] ** 2 + 1) - 1)) < 1e-8
    np.testing.assert_allclose(fit.x[inner], d.x[inner], atol=1e-9 * max(1.0, np.max(np.abs(d.x))))


def test_damped_oscillator_closed_form():
    # oracle: y = exp(-t/2) sin(2 t) solves y'' + y' + 4.25 y = 0 exactly
    t = np.linspace(0.0, 6.0, 3001)
    y = np.exp(-0.5 * t) * np.sin(2 * t)
    fit = fit_kernel_model(KernelModel(a0=UnknownConstant(), a1=UnknownConstant()), t, np.zeros_like(t), y)
    assert fit.constants["a0"] == pytest.approx(4.25, abs=1e-9)
    assert fit.constants["a1"] == pytest.approx(1.0, abs=1e-9)
    dy = np.exp(-0.5 * t) * (2 * np.cos(2 * t) - 0.5 * np.sin(2 * t))
    np.testing.assert_allclose(fit.dy, dy, rtol=0, atol=1e-9)


def test_lti_with_input_derivative_all_constants_unknown():
    # oracle: known constants of an LTI system with b1 != 0; the state of the
    # realization x2 = y' + b1 u from the independent simulation
    io = LTVInputOutput(a=[4.0, 0.6], b=[-2.0, 0.7], input="sin(2*t) + 0.5*cos(t)")
    t = np.linspace(0.0, 15.0, 3001)
    d = io.simulate(t)
    model = KernelModel(a0=UnknownConstant(), a1=UnknownConstant(), b0=UnknownConstant(), b1=UnknownConstant())
    fit = fit_kernel_model(model, t, d.u, d.y)
    for name, value in {"a0": 4.0, "a1": 0.6, "b0": -2.0, "b1": 0.7}.items():
        assert fit.constants[name] == pytest.approx(value, abs=1e-9), name
    np.testing.assert_allclose(fit.x, d.x, rtol=0, atol=1e-9)
    # (32) through the general formula with the model's realization
    x = reconstruct_state(io.to_state_space(), t, fit.y, fit.dy, d.u)
    np.testing.assert_allclose(x, d.x, rtol=0, atol=1e-9)


def test_time_varying_spline_coefficients_on_manufactured_data():
    # every coefficient time-varying; a0 quadratic and a1 = 1 + 0.2 t linear
    # are in the spline spaces; b0, b1 known. Data from the closed-form y.
    def a1(t):
        return 1.0 + 0.2 * t

    def b0(t):
        return -(_ddy(t) + a1(t) * _dy(t) + _a0(t) * _y(t) + _b1(t) * _du(t)) / _u(t)

    t = np.linspace(0.5, 6.5, 3001)
    model = KernelModel(
        a0=UnknownSpline(8), a1=UnknownSpline(5), b0=b0, b1=lpvest_tf(_b1, _db1)
    )
    fit = fit_kernel_model(model, t, _u(t), _y(t))
    np.testing.assert_allclose(fit.values["a0"], _a0(t), rtol=1e-8)
    np.testing.assert_allclose(fit.values["a1"], a1(t), rtol=1e-8)
    np.testing.assert_allclose(fit.dy, _dy(t), atol=1e-8)


def test_unknown_b_splines_recover_input_coefficients():
    io = LTVInputOutput(a=["t**2 + 1", 1.0], b=["-(1 + 0.1*t)", 0.4], input="120*sin(t) + 30*cos(2.3*t)")
    t = np.linspace(0.0, 8.0, 4001)
    d = io.simulate(t)
    model = KernelModel.from_io(io, b0=UnknownSpline(6, order=2), b1=UnknownConstant())
    fit = fit_kernel_model(model, t, d.u, d.y)
    np.testing.assert_allclose(fit.values["b0"], -(1 + 0.1 * t), rtol=1e-7)
    assert fit.constants["b1"] == pytest.approx(0.4, abs=1e-8)
    np.testing.assert_allclose(fit.x, d.x, atol=1e-8)


def test_solve_matches_dense_least_squares_oracle(sridhar, traj9):
    # the segment-wise QR against numpy's lstsq on the dense P of (29)-(30)
    model = KernelModel.from_io(sridhar, a0=UnknownSpline(16), a1=UnknownConstant())
    rng = np.random.default_rng(3)
    y = traj9.y + 1e-3 * rng.standard_normal(traj9.y.size)
    reg = kernel_regression(model, traj9.t, traj9.u, y)
    assert reg.P.shape == (9001, 17) and reg.labels[-1] == "a1"
    beta_ref = np.linalg.lstsq(reg.P, reg.q, rcond=None)[0]
    fit = fit_kernel_model(model, traj9.t, traj9.u, y)
    rel = _assert_lstsq_close(fit.beta, beta_ref, reg.P, reg.q)
    resid = reg.q - reg.P @ beta_ref
    # the residual moves by |P| |d beta| (the scaled solution's bound times its
    # size, through rows of P D^-1 of norm <= ||P D^-1||), plus the rounding
    # of q - P beta (n + 1 terms of size |q| + |P| |beta|)
    d = np.linalg.norm(reg.P, axis=0)
    dr = rel * np.linalg.norm(reg.P / d, 2) * np.linalg.norm(d * beta_ref)
    dr += roundoff(np.max(np.abs(reg.q) + np.abs(reg.P) @ np.abs(beta_ref)), 1, n=reg.P.shape[1] + 1)
    assert fit.residual_rms == pytest.approx(np.sqrt(np.mean(resid**2)), abs=dr)
    # y_E is (9) with the estimated coefficients: y - (q - P beta)
    np.testing.assert_allclose(fit.y, y - resid, rtol=0, atol=dr + roundoff(np.max(np.abs(y)), 1))
    # a subset of instants: the same as lstsq on those rows
    rows = np.arange(0, 9001, 5)
    fit5 = fit_kernel_model(model, traj9.t, traj9.u, y, instants=5)
    beta5 = np.linalg.lstsq(reg.P[rows], reg.q[rows], rcond=None)[0]
    _assert_lstsq_close(fit5.beta, beta5, reg.P[rows], reg.q[rows])
    np.testing.assert_array_equal(fit5.instants, rows)


def test_solve_with_clustered_knots_and_two_spline_blocks(sridhar, traj9):
    # uneven segments (knots clustered near 2 s, a long gap after 5 s) and two
    # spline blocks with different knots: the segment-wise QR against lstsq
    order = 3
    base = np.array([0.0, 1.9, 1.95, 2.0, 2.05, 2.1, 5.0, 9.0])
    knots = np.concatenate([[-0.2, -0.1], base, [9.1, 9.2]])
    model = KernelModel.from_io(
        sridhar, a0=UnknownSpline(knots.size - order, order, knots=knots), a1=UnknownSpline(4, order=2)
    )
    rng = np.random.default_rng(11)
    y = traj9.y + 1e-3 * rng.standard_normal(traj9.y.size)
    reg = kernel_regression(model, traj9.t, traj9.u, y)
    beta_ref = np.linalg.lstsq(reg.P, reg.q, rcond=None)[0]
    fit = fit_kernel_model(model, traj9.t, traj9.u, y)
    _assert_lstsq_close(fit.beta, beta_ref, reg.P, reg.q)


def test_regression_columns_against_the_printed_kernels_with_split_intervals():
    # Oracle independent of the moment machinery: a column of P is the a0 part
    # of the printed kernel (18) with a0 = B_i, integrated by scipy's adaptive
    # quad against the analytic y. The knots put two breakpoints into one
    # sample interval, a double knot on a sample and a knot just off one.
    from scipy.integrate import quad
    from scipy.interpolate import BSpline

    a, b = 0.5, 6.5
    t = np.linspace(a, b, 601)  # h = 0.01
    knots = np.array([-0.4, -0.2, 0.0, 1.2034, 1.2071, 3.0, 3.0, 4.5137, 6.0, 6.2, 6.4])  # relative to a
    n = knots.size - 3
    model = KernelModel(a0=UnknownSpline(n, 3, knots=knots), a1=_a1, b0=1.0, b1=lpvest_tf(_b1, _db1))
    reg = kernel_regression(model, t, _u(t), _y(t))
    inside = knots[(knots > 0) & (knots < b - a)] + a
    for i in (1, 3, 4, 6):
        basis = BSpline(knots + a, np.eye(n)[i], 2, extrapolate=False)

        def a0_part(s, t0, basis=basis):
            with_bi = kernel_oracle.kernel_functions(t0, s, a, b, {"a0": lambda x: np.nan_to_num(basis(x))}).Ky
            return (with_bi - kernel_oracle.kernel_functions(t0, s, a, b, {}).Ky) * _y(s)

        for j in (0, 120, 121, 300, 451, 600):
            pts = sorted({*inside, *([t[j]] if a < t[j] < b else [])})
            ref = quad(a0_part, a, b, args=(t[j],), points=pts, epsabs=1e-15, epsrel=1e-13, limit=400)[0]
            # quad's error estimate <= epsabs 1e-15 / epsrel 1e-13 against the
            # 6-point product rule exact for these piecewise polynomials (rounding)
            assert reg.P[j, i] == pytest.approx(ref, abs=1e-13), (i, j)
    # and the segment-wise solve agrees with lstsq on this P
    rng = np.random.default_rng(2)
    y = _y(t) + 1e-4 * rng.standard_normal(t.size)
    reg = kernel_regression(model, t, _u(t), y)
    beta_ref = np.linalg.lstsq(reg.P, reg.q, rcond=None)[0]
    fit = fit_kernel_model(model, t, _u(t), y)
    _assert_lstsq_close(fit.beta, beta_ref, reg.P, reg.q)


def test_penalty_matches_augmented_least_squares_and_gcv(sridhar, traj9):
    model = KernelModel.from_io(sridhar, a0=UnknownSpline(16), a1=UnknownConstant())
    rng = np.random.default_rng(5)
    y = traj9.y + 5e-4 * rng.standard_normal(traj9.y.size)
    reg = kernel_regression(model, traj9.t, traj9.u, y)
    D = np.zeros((14, 17))
    D[:, :16] = np.diff(np.eye(16), 2, axis=0)
    lam = 1e-5
    # oracle: min |q - P b|^2 + lam |D b|^2 as one stacked lstsq
    Pa, qa = np.vstack([reg.P, np.sqrt(lam) * D]), np.concatenate([reg.q, np.zeros(14)])
    ref = np.linalg.lstsq(Pa, qa, rcond=None)[0]
    fit = fit_kernel_model(model, traj9.t, traj9.u, y, penalty=lam)
    _assert_lstsq_close(fit.beta, ref, Pa, qa)
    assert fit.penalty == lam and 2 < fit.edf < 17
    # a huge penalty forces second differences to zero: a0 becomes linear in t
    stiff = fit_kernel_model(model, traj9.t, traj9.u, y, penalty=1e12)
    coef = stiff.splines["a0"].c
    assert np.max(np.abs(np.diff(coef, 2))) < 1e-6 * np.max(np.abs(coef))
    # GCV: the chosen lambda scores no worse than plain LS or the huge penalty
    gcv = fit_kernel_model(model, traj9.t, traj9.u, y, penalty="gcv")
    plain = fit_kernel_model(model, traj9.t, traj9.u, y)
    assert gcv.gcv <= plain.gcv * (1 + 1e-12)
    assert gcv.gcv <= stiff.gcv
    assert gcv.penalty > 0


# -- noise ---------------------------------------------------------------------------------------


def test_noisy_twenty_seeds(sridhar, traj9, rng):
    # issue 5 (paper Section V-B prints a1 = 0.8321): 30 dB output noise,
    # 20 seeded realizations: mean a1 within 0.02 of 1, mean max relative
    # error of a0 on [1.5, 7.5] at most 0.06
    model = KernelModel.from_io(sridhar, a0=UnknownSpline(16, order=3), a1=UnknownConstant())
    t = traj9.t
    inner = (t >= 1.5) & (t <= 7.5)
    sigma = np.sqrt(np.mean(traj9.y**2) / 10 ** (30 / 10))
    a1, err = [], []
    for _ in range(20):
        fit = fit_kernel_model(model, t, traj9.u, traj9.y + sigma * rng.standard_normal(t.size))
        a1.append(fit.constants["a1"])
        err.append(np.max(np.abs(fit.values["a0"][inner] - (t[inner] ** 2 + 1)) / (t[inner] ** 2 + 1)))
    assert abs(np.mean(a1) - 1.0) < 0.02
    assert np.mean(err) <= 0.06
    # the paper's 0.8321 is 17 % off; ours stays within a few percent on every seed
    assert np.max(np.abs(np.array(a1) - 1.0)) < 0.05


# -- bad input and identifiability ----------------------------------------------------------------


@pytest.fixture
def small():
    io = load_system("sridhar-ltv").model()
    t = np.linspace(0.0, 4.0, 401)
    return io, t, io.simulate(t)


def test_nan_sample_is_rejected(small):
    io, t, d = small
    y = d.y.copy()
    y[17] = np.nan
    model = KernelModel.from_io(io, a1=UnknownConstant())
    with pytest.raises(NonFiniteError, match=r"y holds a non-finite value \(nan\) at index \(17,\)"):
        fit_kernel_model(model, t, d.u, y)
    with pytest.raises(NonFiniteError, match="u holds a non-finite"):
        fit_kernel_model(model, t, np.where(t > 1, np.inf, d.u), d.y)


def test_non_uniform_and_non_increasing_times_are_rejected(small):
    io, t, d = small
    model = KernelModel.from_io(io, a1=UnknownConstant())
    t2 = t.copy()
    t2[100] += 1e-4
    with pytest.raises(SamplingError, match="not uniformly sampled: step 99"):
        fit_kernel_model(model, t2, d.u, d.y)
    with pytest.raises(SamplingError, match="not strictly increasing"):
        fit_kernel_model(model, t[::-1], d.u, d.y)


def test_too_short_and_mismatched_data_are_rejected(small):
    io, t, d = small
    model = KernelModel.from_io(io, a1=UnknownConstant())
    with pytest.raises(DimensionError, match="the data have 5 samples; the 6-point quadrature needs at least 6"):
        fit_kernel_model(model, t[:5], d.u[:5], d.y[:5])
    with pytest.raises(DimensionError, match="t has 1 sample"):
        fit_kernel_model(model, t[:1], d.u[:1], d.y[:1])
    with pytest.raises(DimensionError, match=r"u has shape \(400,\); expected \(401,\)"):
        fit_kernel_model(model, t, d.u[:-1], d.y)


def test_too_few_samples_for_the_unknowns(small):
    io, t, d = small
    model = KernelModel.from_io(io, a0=UnknownSpline(30), a1=UnknownConstant())
    with pytest.raises(IdentifiabilityError, match="20 regression instants for 31 unknown coefficients"):
        fit_kernel_model(model, t[:20], d.u[:20], d.y[:20])
    with pytest.raises(IdentifiabilityError, match="14 regression instants for 31 unknown"):
        fit_kernel_model(model, t, d.u, d.y, instants=30)


def test_unidentifiable_input_coefficient_without_input(small):
    # u = 0: the data say nothing about b0
    io, t, d = small
    free = LTVInputOutput(a=io.a, b=[0.0], x0=[1.0, 0.0])
    y = free.simulate(t).y
    model = KernelModel(a0="t**2 + 1", a1=UnknownConstant(), b0=UnknownConstant())
    with pytest.raises(IdentifiabilityError, match=r"columns of P are zero .* do not determine: b0 \(practical"):
        fit_kernel_model(model, t, np.zeros_like(t), y)


def test_unidentifiable_single_exponential_names_both_coefficients():
    # y = exp(-t) satisfies y'' + a1 y' + a0 y = 0 for every a0 = a1 - 1
    t = np.linspace(0.0, 3.0, 601)
    model = KernelModel(a0=UnknownConstant(), a1=UnknownConstant())
    with pytest.raises(IdentifiabilityError, match=r"rank P = 1 < 2 unknowns .* do not determine: a0; a1"):
        fit_kernel_model(model, t, np.zeros_like(t), np.exp(-t))


def test_spline_basis_outside_the_data_is_named(small):
    io, t, d = small
    knots = np.array([-1.0, -0.5, 0.0, 1.0, 2.0, 3.0, 4.0, 9.0, 9.5, 10.0])  # basis 6 lives in (4, 10)
    model = KernelModel.from_io(io, a0=UnknownSpline(7, 3, knots=knots), a1=UnknownConstant())
    with pytest.raises(IdentifiabilityError, match=r"a0 \(B-spline basis functions 6\)"):
        fit_kernel_model(model, t, d.u, d.y)


def test_option_and_declaration_errors(small):
    io, t, d = small
    model = KernelModel.from_io(io, a1=UnknownConstant())
    with pytest.raises(DimensionError, match="penalty must be None, 'gcv' or a finite lambda >= 0"):
        fit_kernel_model(model, t, d.u, d.y, penalty=-1.0)
    for bad in (np.bool_(True), np.float64("nan"), "1e-3"):
        with pytest.raises(DimensionError, match="penalty must be None"):
            fit_kernel_model(model, t, d.u, d.y, penalty=bad)
    # a numpy scalar is a number like any other (np.int64 was refused, np.float64 accepted)
    a = fit_kernel_model(model, t, d.u, d.y, penalty=np.int64(1))
    b = fit_kernel_model(model, t, d.u, d.y, penalty=1.0)
    np.testing.assert_array_equal(a.beta, b.beta)
    with pytest.raises(DimensionError, match="points .* must be an even integer"):
        fit_kernel_model(model, t, d.u, d.y, points=5)
    with pytest.raises(DimensionError, match="n_basis = 2 B-splines of order 3: need n_basis >= order"):
        UnknownSpline(2, 3)
    with pytest.raises(DimensionError, match="knots must be 'uniform', 'clamped' or a knot vector"):
        UnknownSpline(5, 3, knots="periodic")
    with pytest.raises(DimensionError, match=r"explicit knots cover \[0, 3\]"):
        fit_kernel_model(KernelModel.from_io(io, a0=UnknownSpline(4, 2, knots=[-1, 0, 1, 2, 3, 3])), t, d.u, d.y)
    with pytest.raises(ExpressionError, match=r"a1: expected Known\(...\), UnknownConstant\(\)"):
        KernelModel(a0=UnknownConstant(), a1="t +* 2")
    with pytest.raises(ExpressionError, match="b0: .*unknown name 'x'"):
        KernelModel(a0=UnknownConstant(), a1=1.0, b0="x**2")
    with pytest.raises(DimensionError, match="unknown coefficient name 'c0'"):
        KernelModel.from_io(io, c0=UnknownConstant())
    with pytest.raises(DimensionError, match="second-order systems"):
        KernelModel.from_io(LTVInputOutput(a=[1.0], b=[1.0]))
    with pytest.raises(IdentifiabilityError, match="no unknown coefficient"):
        fit_kernel_model(KernelModel.from_io(io), t, d.u, d.y)
    with pytest.raises(NonFiniteError, match=r"the known coefficient a0 = sqrt\(t - 2\) is nan at t = 0\.00112"):
        fit_kernel_model(KernelModel(a0="sqrt(t - 2)", a1=UnknownConstant()), t, d.u, d.y)


# -- state reconstruction (4) / (32) ----------------------------------------------------------------


def test_reconstruct_state_printed_and_time_varying_output_map(sridhar, traj9):
    # the printed state space of Section V: x = (y, y')
    ss = load_system("sridhar-ltv").model("state_space")
    x = reconstruct_state(ss, traj9.t[::500], traj9.y[::500], traj9.x[::500, 1], traj9.u[::500])
    # x = (y, y' + b1 u), b1 = 0: a couple of roundings of terms of size |x|
    np.testing.assert_allclose(x, traj9.x[::500], rtol=0, atol=roundoff(np.max(np.abs(traj9.x)), 1, n=2))
    # a realization with a time-varying C: z = T(t) x with T = [[1, 0], [t, 1]]
    # (so C_z = [1, 0], A_z = T A T^-1 + T' T^-1, B_z = T B); oracle: z = T x
    def A(t):
        Tm = np.array([[1.0, 0.0], [t, 1.0]])
        Ti = np.array([[1.0, 0.0], [-t, 1.0]])
        A0 = np.array([[0.0, 1.0], [-(t**2 + 1), -1.0]])
        return Tm @ A0 @ Ti + np.array([[0.0, 0.0], [1.0, 0.0]]) @ Ti

    def B(t):
        return np.array([[1.0, 0.0], [t, 1.0]]) @ np.array([[0.0], [1.0 / (t + 1000)]])

    zs = LTVStateSpace(A, B, [[1, 0]])
    k = slice(None, None, 700)
    z = reconstruct_state(zs, traj9.t[k], traj9.y[k], traj9.x[k, 1], traj9.u[k])
    z_ref = np.column_stack([traj9.x[k, 0], traj9.t[k] * traj9.x[k, 0] + traj9.x[k, 1]])
    # a few stages of 2-term products of size |t| |x| + |x| (T(t), its inverse, C')
    size = float(np.max(np.abs(traj9.t[k, None]) * np.abs(traj9.x[k]) + np.abs(traj9.x[k])))
    np.testing.assert_allclose(z, z_ref, rtol=0, atol=roundoff(size, 3, n=2))


# -- the streaming observer ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def stream():
    io = load_system("sridhar-ltv").model()
    dt = 0.005
    t = np.arange(1201) * dt
    return io, dt, t, io.simulate(t)


def _observer(io, dt, **kw):
    model = KernelModel.from_io(io, a0=UnknownSpline(12), a1=UnknownConstant())
    return BSplineObserver(model, dt=dt, window=kw.pop("window", 2.0), hop=kw.pop("hop", 0.25), **kw)


def test_observer_protocol_ports_and_delay(stream):
    io, dt, t, d = stream
    obs = _observer(io, dt)
    assert isinstance(obs, StreamingEstimator)
    assert [p.name for p in obs.input_ports] == ["u", "y"]
    assert [(p.name, p.shape) for p in obs.output_ports] == [
        ("t_est", (1,)), ("yhat", (1,)), ("dyhat", (1,)), ("xhat", (2,)),
        ("a0", (1,)), ("a1", (1,)), ("b0", (1,)), ("b1", (1,)), ("valid", (1,)),
    ]
    assert obs.delay == pytest.approx(1.0) and obs.length == 401 and obs.hop == 50
    out = run_streaming(obs, {"u": d.u[:, None], "y": d.y[:, None]})
    valid = out["valid"][:, 0]
    assert np.all(valid[:400] == 0) and np.all(valid[400:] == 1)
    assert np.all(out["a1"][:400] == 0)
    k = np.arange(400, t.size)
    j = k - 200  # delay 1 s = 200 samples
    # t_est = t_k - delay: two roundings of times <= 6 s
    np.testing.assert_allclose(out["t_est"][k, 0], t[j], rtol=0, atol=roundoff(6.0, 2))
    # method bounds (dt = 5 ms quadrature, fit conditioning), as in the recovery tests above
    np.testing.assert_allclose(out["a1"][k, 0], 1.0, atol=1e-7)
    np.testing.assert_allclose(out["a0"][k, 0], t[j] ** 2 + 1, rtol=1e-7)
    # method bounds, as in the kernel-identity tests (dt = 5 ms, smooth data)
    np.testing.assert_allclose(out["yhat"][k, 0], d.y[j], atol=1e-11)
    np.testing.assert_allclose(out["xhat"][k], d.x[j], atol=1e-10)
    # a known coefficient's formula at t_est: a sum and a division (and t_est's rounding, relative 1e-3 of it)
    np.testing.assert_allclose(out["b0"][k, 0], -1.0 / (t[j] + 1000), rtol=roundoff(1.0, 3))


def test_observer_equals_batch_estimator_on_the_same_window(stream):
    io, dt, t, d = stream
    obs = _observer(io, dt)
    out = run_streaming(obs, {"u": d.u[:900, None], "y": d.y[:900, None]})
    model = KernelModel.from_io(io, a0=UnknownSpline(12), a1=UnknownConstant())
    for last in (400, 850):  # refits at sample 400 + k * 50
        window = slice(last - 400, last + 1)
        fit = fit_kernel_model(model, t[window], d.u[window], d.y[window])
        for offset in (0, 49):
            k = last + offset
            if k >= 900:
                continue
            assert out["a1"][k, 0] == fit.constants["a1"]
            assert out["a0"][k, 0] == fit.values["a0"][200 + offset]
            assert out["yhat"][k, 0] == fit.y[200 + offset]
            assert out["dyhat"][k, 0] == fit.dy[200 + offset]


def test_observer_state_round_trip_and_rejected_sample(stream):
    io, dt, t, d = stream
    obs = _observer(io, dt)
    inputs = {"u": d.u[:, None], "y": d.y[:, None]}
    for k in range(523):
        obs.step({"u": inputs["u"][k], "y": inputs["y"][k]})
    state = obs.get_state()
    assert state["ring_u"].shape == (401,) and state["k"] == 523
    # a NaN sample raises and changes nothing
    with pytest.raises(NonFiniteError, match="y holds a non-finite"):
        obs.step({"u": inputs["u"][523], "y": np.array([np.nan])})
    after = obs.get_state()
    for key, value in state.items():
        np.testing.assert_array_equal(after[key], value, err_msg=key)
    rest = [obs.step({"u": inputs["u"][k], "y": inputs["y"][k]}) for k in range(523, 700)]
    clone = _observer(io, dt)
    clone.set_state(state)
    again = [clone.step({"u": inputs["u"][k], "y": inputs["y"][k]}) for k in range(523, 700)]
    for r1, r2 in zip(rest, again, strict=True):
        for name in r1:
            np.testing.assert_array_equal(r1[name], r2[name])
    # outputs() does not advance
    before = clone.get_state()
    clone.outputs({"u": inputs["u"][700], "y": inputs["y"][700]})
    assert clone.get_state()["k"] == before["k"]
    with pytest.raises(DimensionError, match=r"observer state is missing 'ring_y'"):
        clone.set_state({k: v for k, v in state.items() if k != "ring_y"})
    with pytest.raises(DimensionError, match=r"ring_u has shape \(3,\); expected \(401,\)"):
        clone.set_state(state | {"ring_u": np.zeros(3)})


def test_observer_holds_through_unidentifiable_windows():
    # the input starts at t = 3 s: before that, windows with unknown b0 see u = 0
    def u(t):
        return np.where(t > 3, np.sin(2 * t) * (t - 3) ** 3, 0.0)

    io = LTVInputOutput(a=["t**2 + 1", 1.0], b=[-0.5], input=u)
    dt = 0.01
    t = np.arange(1001) * dt
    d = io.simulate(t)
    model = KernelModel.from_io(io, a0=UnknownSpline(8), b0=UnknownConstant())
    obs = BSplineObserver(model, dt=dt, window=2.0, hop=0.5, on_unidentifiable="hold")
    out = run_streaming(obs, {"u": d.u[:, None], "y": d.y[:, None]})
    valid = out["valid"][:, 0]
    assert np.all(valid[:350] == 0)  # windows ending before 3.5 s hold
    assert np.all(valid[550:] == 1)
    np.testing.assert_allclose(out["b0"][550:, 0], -0.5, atol=1e-6)
    strict = BSplineObserver(model, dt=dt, window=2.0, hop=0.5)
    with pytest.raises(IdentifiabilityError, match="b0"):
        run_streaming(strict, {"u": d.u[:, None], "y": d.y[:, None]})


def test_observer_configuration_errors(stream):
    io, dt, _, _ = stream
    with pytest.raises(DimensionError, match="hop = 250 samples exceeds delay \\+ 1 = 201 samples"):
        _observer(io, dt, hop=1.25)
    with pytest.raises(SamplingError, match="window = 2.0012 s is not a whole number of sample steps"):
        _observer(io, dt, window=2.0012)
    with pytest.raises(IdentifiabilityError, match="too short for 13 unknown"):
        _observer(io, 0.5, window=5.5, hop=0.5)
    with pytest.raises(DimensionError, match=r"y has shape \(2,\); expected \(1,\)"):
        _observer(io, dt).outputs({"u": np.array([1.0]), "y": np.array([1.0, 2.0])})


# -- runnable docstring examples -----------------------------------------------------------------


@pytest.mark.parametrize("module", [bs, kernels, model, basis, regression, fit, state, observer],
                         ids=lambda m: m.__name__)
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


# -- edge cases that gave a wrong answer instead of an error (issue 12) -----------------------------


@pytest.mark.parametrize("nonzero", [1, 3, 6])
def test_an_input_only_at_the_window_end_does_not_determine_b0(nonzero):
    # y'' + y' + 4.25 y - 9 u = 0 with u = 0 but at the last samples: inside the window y is the free
    # response, and b0's column of P is quadrature error (1e-8 of the others): the estimate was
    # b0 = -0.006 for the true -9, and the observer FMU called it valid
    t = np.linspace(0.0, 4.0, 4001)
    y = np.exp(-0.5 * t) * np.sin(2 * t)
    u = np.zeros_like(t)
    u[-nonzero:] = 1.0
    model = KernelModel(a0=UnknownConstant(), a1=UnknownConstant(), b0=UnknownConstant())
    with pytest.raises(IdentifiabilityError, match=r"^the input u is zero except within 6 samples of the window's "
                                                   r"ends .* do not determine: b0 \(practical identifiability"):
        fit_kernel_model(model, t, u, y)
    u[-nonzero:] = 0.0
    u[0] = 1.0  # the other end: the same
    with pytest.raises(IdentifiabilityError, match="do not determine: b0"):
        fit_kernel_model(model, t, u, y)


def test_an_input_reaching_into_the_window_determines_b0(small):
    # the control: the same check passes an input that is nonzero beyond the end stencils
    io, t, d = small
    u = np.where(t > t[-1] - 40 * (t[1] - t[0]), d.u, 0.0)
    assert np.count_nonzero(u[6:-6]) > 30
    model = KernelModel.from_io(io, b0=UnknownConstant())
    fit_kernel_model(model, t, d.u, d.y)  # whole input: accepted
    with pytest.raises(IdentifiabilityError, match="the input u is zero except"):
        fit_kernel_model(model, t, np.where(np.arange(t.size) >= t.size - 6, d.u, 0.0), d.y)


def test_the_observer_reports_windows_whose_input_starts_at_their_end_invalid():
    dt = 0.01
    io = LTVInputOutput(a=["t**2 + 1", 1.0], b=[-9.0], input=lambda t: np.where(t >= 1.995, 1.0, 0.0))
    t = np.arange(250) * dt  # one full window, [0, 2] (the next ends at 2.5)
    d = io.simulate(t)
    model = KernelModel.from_io(io, b0=UnknownConstant())
    obs = BSplineObserver(model, dt=dt, window=2.0, hop=0.5, on_unidentifiable="hold")
    out = run_streaming(obs, {"u": d.u[:, None], "y": d.y[:, None]})
    assert d.u[199] == 0.0 and d.u[200] == 1.0  # the window [0, 2] sees the input at its last sample only
    assert np.all(out["valid"][:, 0] == 0)
    with pytest.raises(IdentifiabilityError, match="the input u is zero except within 6 samples"):
        run_streaming(BSplineObserver(model, dt=dt, window=2.0, hop=0.5), {"u": d.u[:, None], "y": d.y[:, None]})


def test_a_spline_of_order_1_recovers_a_piecewise_constant_a0():
    # UnknownSpline(order=1) was accepted and then always crashed inside scipy (the derivative of a
    # degree-0 spline); oracle: noiseless exact recovery of an a0 that jumps at a knot
    io = LTVInputOutput(a=[lambda t: np.where(np.asarray(t) < 2.0, 4.0, 6.0), 1.0], b=[-2.0], input="sin(3*t)",
                        x0=[1.0, 0.0])
    t = np.linspace(0.0, 4.0, 4001)
    d = io.simulate(t)
    fit = fit_kernel_model(KernelModel(a0=UnknownSpline(4, order=1), a1=UnknownConstant(), b0=UnknownConstant()),
                           t, d.u, d.y)
    np.testing.assert_allclose(fit.beta, [4.0, 4.0, 6.0, 6.0, 1.0, -2.0], rtol=0, atol=1e-8)  # DOP853 at rtol 1e-12
    np.testing.assert_array_equal(fit.coefficients["a0"].derivative()(np.array([1.0, 3.0])), [0.0, 0.0])


@pytest.mark.parametrize("name", ["a1", "b1"])
def test_a_spline_of_order_1_is_refused_where_its_derivative_is_needed(name):
    coefficients = {"a0": UnknownConstant(), "a1": 1.0, name: UnknownSpline(4, order=1)}
    with pytest.raises(DimensionError, match=rf"^{name}: a B-spline of order 1 \(piecewise constant\) has no "
                                             rf"derivative, which the kernels of {name} need \(10\); use order 2"):
        KernelModel(**coefficients)


@pytest.mark.parametrize(("coefficient", "formula"), [("b0", "1/(t - 2)"), ("a1", "1/(t - 2)"), ("a0", "log(t - 1)")])
def test_a_known_coefficient_that_is_not_finite_at_a_sample_is_named(coefficient, formula):
    # b0 = 1/(t - 2) went through to the result as inf at t = 2
    t = np.linspace(0.0, 4.0, 4001)
    y = np.exp(-0.5 * t) * np.sin(2 * t)
    known = {"a0": UnknownConstant(), "a1": UnknownConstant(), "b0": UnknownConstant()}
    known[coefficient] = formula
    with pytest.raises(NonFiniteError, match=rf"^the known coefficient {coefficient} = .* is -?(inf|nan) at t = "):
        fit_kernel_model(KernelModel(**known), t, np.sin(3 * t), y)


def test_the_build_plan_of_a_third_order_model_has_no_observer(tmp_path):
    # `lpvest build --model` wrote the plant and then failed on the observer (order 3)
    from lpvest.estimators.bspline import observer_supports
    from lpvest.fmi._build import plan_system

    path = tmp_path / "third.toml"
    path.write_text('[system]\nname = "third"\ntitle = "a third-order LTV model"\n'
                    '[models.io]\ntype = "ltv-io"\na = ["t + 1", 3, 3]\nb = [1]\ninput = "sin(t)"\n')
    plans, notes = plan_system(path)
    assert [p.role for p in plans] == ["Plant"]
    assert "third: model 'io' gets no BSplineObserver: the B-spline observer is for second-order models (11); " \
           "this one has order 3" in notes
    assert observer_supports(load_system("sridhar-ltv").model()) is None
    assert observer_supports(load_system("sridhar-ltv").model("state_space")).startswith("the B-spline observer "
                                                                                         "needs an ltv-io model")
