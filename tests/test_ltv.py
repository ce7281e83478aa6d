"""Continuous-time LTV models (Sridhar et al.)."""

import numpy as np
import pytest

from lpvest import DimensionError, ExpressionError, LTVInputOutput, TimeFunction, load_system
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel


@pytest.fixture(scope="module")
def system():
    return load_system("sridhar-ltv")


def _rk4(f, x0, t):
    """Classical RK4 on the grid t with 20 substeps: an integrator independent of scipy."""
    xs = [np.array(x0, float)]
    for a, b in zip(t[:-1], t[1:], strict=True):
        x = xs[-1]
        n = 20
        h = (b - a) / n
        s = a
        for _ in range(n):
            k1 = f(s, x)
            k2 = f(s + h / 2, x + h / 2 * k1)
            k3 = f(s + h / 2, x + h / 2 * k2)
            k4 = f(s + h, x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            s += h
        xs.append(x)
    return np.array(xs)


def test_sridhar_simulation_matches_independent_integration(system):
    # oracle: Section V's state equations typed in by hand, integrated by RK4
    def f(t, x):
        u = 120 * np.sin(t)
        return np.array([x[1], -(t**2 + 1) * x[0] - x[1] + u / (t + 1000)])

    t = np.linspace(0.0, 20.0, 2001)
    expect = _rk4(f, [0.0, 0.0], t)
    for key in ("io", "state_space"):
        traj = system.model(key).simulate(t)
        scale = np.max(np.abs(expect), axis=0)
        # RK4 with h = 5e-4 at |a0| <= 401: local error ~ (h*20)^5 -> ~1e-9 relative
        np.testing.assert_allclose(traj.x, expect, rtol=0, atol=1e-8 * scale.max())
        np.testing.assert_allclose(traj.y, traj.x[:, 0], rtol=0, atol=0)
        # the same formula on the same t: sin of an argument of size <= 20, times 120
        np.testing.assert_allclose(traj.u, 120 * np.sin(t), rtol=0, atol=roundoff(120 * (1 + t[-1]), 1))


def test_io_realization_equals_printed_state_space(system):
    io = system.model("io").to_state_space()
    ss = system.model("state_space")
    for t in np.linspace(0, 20, 9):
        # coefficient formulas (t^2 + 1, 1 / (t + 1000), ...) evaluated by two
        # expression paths: a few roundings of entries of size <= 401
        for got, want in ((io.A(t), ss.A(t)), (io.B(t), ss.B(t)), (io.C(t), ss.C(t))):
            np.testing.assert_allclose(got, want, rtol=0, atol=roundoff(np.max(np.abs(want)), 2))


def test_second_order_realization_with_input_derivative_against_lti_oracle():
    # constant coefficients: y'' + a1 y' + a0 y + b1 u' + b0 u = 0 is the LTI
    # system Y/U = -(b1 s + b0)/(s^2 + a1 s + a0). Our realization starts at
    # x = 0, i.e. y(0) = 0 and y'(0) = -b1 u(0), for which the Laplace
    # initial-condition terms cancel: y is the zero-state response. Oracle:
    # scipy's own realization (tf2ss) of that transfer function, integrated.
    from scipy import signal
    from scipy.integrate import solve_ivp

    a0, a1, b0, b1 = 4.0, 0.6, -2.0, 0.7
    io = LTVInputOutput(a=[a0, a1], b=[b0, b1], input="sin(2*t) + 0.5*cos(t)")
    t = np.linspace(0, 15, 301)
    traj = io.simulate(t)
    A, B, C, D = signal.tf2ss([-b1, -b0], [1.0, a1, a0])

    def u(s):
        return np.sin(2 * s) + 0.5 * np.cos(s)

    sol = solve_ivp(lambda s, x: A @ x + B[:, 0] * u(s), (0, 15), np.zeros(2), method="LSODA",
                    t_eval=t, rtol=1e-12, atol=1e-13)
    y_ref = (C @ sol.y)[0] + D[0, 0] * u(t)
    # method bound: both integrators at rtol 1e-12 (DOP853, LSODA) over 15 s of a
    # stable system (|y| <= ~1): their global errors ~1e-11; 1e-9 leaves a margin
    np.testing.assert_allclose(traj.y, y_ref, rtol=0, atol=1e-9)


def test_time_varying_b1_uses_its_derivative():
    # y = sin(t) solves y'' + y = 0 with b = [b0, b1] chosen to cancel: take
    # b1(t) = t, u = 1 => b1 u' = 0, b0 = 0: a consistency check of b1' entering B
    io = LTVInputOutput(a=[1.0, 0.0], b=[0.0, "t"], input=1.0)
    ss = io.to_state_space()
    t = 1.7
    # B = [-b1, a1 b1 + b1' - b0] = [-t, 1]
    np.testing.assert_allclose(ss.B(t), [[-1.7], [1.0]], rtol=0, atol=roundoff(1.7, 2))  # a few roundings


def test_callable_coefficients_and_complex_step_derivative():
    f = TimeFunction.of(lambda t: np.exp(-t) * np.sin(t))
    t = np.array([0.3, 1.1])
    # complex step: f'(t) = Im f(t + i h) / h with no cancellation, exact to the
    # rounding of the complex exp and sin (a few eps) plus O(h^2) (h = 1e-20: none)
    np.testing.assert_allclose(f.derivative()(t), np.exp(-t) * (np.cos(t) - np.sin(t)), rtol=roundoff(1.0, 4))
    g = TimeFunction.of(lambda t: np.abs(t - 1.0))  # not analytic: abs of a complex is real
    with pytest.raises(ExpressionError, match="give its derivative explicitly"):
        g.derivative()(1.0)


def test_ltv_errors():
    with pytest.raises(DimensionError, match="strictly proper"):
        LTVInputOutput(a=[1.0], b=[1.0, 2.0])
    io = LTVInputOutput(a=[1.0, 1.0, 1.0], b=[0.0, 1.0])
    with pytest.raises(DimensionError, match="implemented for inputs without derivatives"):
        io.to_state_space()
    with pytest.raises(DimensionError, match="strictly increasing"):
        LTVInputOutput(a=[1.0, 1.0], b=[1.0]).simulate([0.0, 0.0, 1.0])
