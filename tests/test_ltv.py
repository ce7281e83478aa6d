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


# -- the model's one integration (LTVSolution) ----------------------------------------------------


def _sridhar_by_hand(s, x):
    """Section V's state equations typed in by hand (independent of the formula machinery)."""
    return np.array([x[1], -(s**2 + 1) * x[0] - x[1] + 120 * np.sin(s) / (s + 1000)])


def _largest_growth(t):
    """G = max over s <= t of ||Phi(t, s)||_2 for Sridhar's homogeneous system, Phi from its
    fundamental matrix on the grid t (starting times every 250 samples): how much an error
    made at s has grown by t. For y'' + y' + w(t)^2 y = 0 with w^2 = t^2 + 1 the adiabatic
    invariant E/w (E = w^2 y^2 + y'^2) does not grow, so G ~ w_max / w_min = sqrt(401)."""
    from scipy.integrate import solve_ivp

    def F(s, p):
        return (np.array([[0.0, 1.0], [-(s**2 + 1), -1.0]]) @ p.reshape(2, 2)).ravel()

    phi = solve_ivp(F, (t[0], t[-1]), np.eye(2).ravel(), method="DOP853", t_eval=t, rtol=1e-12,
                    atol=1e-14).y.T.reshape(-1, 2, 2)
    # the Frobenius norm bounds the 2-norm from above
    return max(float(np.sqrt(np.max(np.sum((phi[i:] @ np.linalg.inv(phi[i])) ** 2, axis=(1, 2)))))
               for i in range(0, t.size, 250))


def test_solution_is_accurate_to_its_tolerance(system):
    """Sridhar's plant at 1 kHz over [0, 20] s (the experiments' data) against a
    tight-tolerance reference: the hand-typed equations by DOP853 at rtol 2.5e-14
    (scipy's floor, 100 eps) in one solve_ivp run."""
    from scipy.integrate import solve_ivp

    ss = system.model("io").to_state_space()
    t = np.arange(20001) * 1e-3
    ref = solve_ivp(_sridhar_by_hand, (0.0, 20.0), [0.0, 0.0], method="DOP853", t_eval=t, rtol=2.5e-14,
                    atol=1e-18)
    for rtol, atol in ((1e-12, 1e-14), (1e-8, 1e-10)):
        sol = ss.solution(0.0, [0.0, 0.0], u=ss.input, rtol=rtol, atol=atol)
        x = np.array([sol(tk) for tk in t])
        scale = float(np.max(np.abs(ref.y)))
        # method bound: each integrator step (and the interpolation of each sample inside
        # one, DOP853's 7th-order dense output) errs by at most its tolerance
        # rtol |x| + atol; the errors add up over the n steps, each grown by the flow by
        # at most G (computed), and the reference's own (~n_ref steps at 2.5e-14) likewise
        G = _largest_growth(t)
        n_ref = ref.nfev / 12
        bound = G * ((sol.n_steps + 1) * (rtol * scale + atol) + n_ref * (2.5e-14 * scale + 1e-18))
        np.testing.assert_allclose(x, ref.y.T, rtol=0, atol=bound)


def test_plant_reads_one_trajectory_whatever_the_step(system):
    """The integration's steps do not depend on the communication points: the
    plant stepped at 1 ms, at 50 ms and at irregular points gives, at each common
    time, the model's solution at that time, bit for bit."""
    from lpvest.systems._streaming import LTVPlant

    model = system.model("io")
    ss = model.to_state_space()
    grids = {"1 ms": np.arange(1, 4001) * 1e-3, "50 ms": np.arange(1, 81) * 0.05,
             "irregular": np.cumsum(np.random.default_rng(3).uniform(0.001, 0.3, 30))}
    for name, grid in grids.items():
        plant = LTVPlant(model)
        sol = ss.solution(0.0, [0.0, 0.0], u=model.input)
        for tk in grid:
            plant.step({"u": [0.0]}, dt=tk - plant.time, t_end=tk)
            assert np.array_equal(plant.outputs({"u": [0.0]})["x"], sol(tk)), (name, tk)
    # and the three grids' common times (multiples of 50 ms) agree: one trajectory
    a, b = LTVPlant(model), LTVPlant(model)
    for k in range(1, 81):
        for j in range(50):
            a.step({"u": [0.0]}, dt=1e-3, t_end=k * 0.05 if j == 49 else (50 * (k - 1) + j + 1) * 1e-3)
        b.step({"u": [0.0]}, dt=0.05, t_end=k * 0.05)
        assert np.array_equal(a.get_state()["x"], b.get_state()["x"])


def test_plant_state_restores_exactly(system):
    """get_state/set_state: a new plant restored from a state continues bit for bit,
    after the integration has restarted several times (anchor replayed), for the
    model's input and for a held input that changes; a state without its anchor
    (t and x only) continues within the integrator's tolerance."""
    from lpvest.systems._streaming import LTVPlant

    model = system.model("io")
    h = 0.01
    for use_model_input in (True, False):
        plant = LTVPlant(model, use_model_input=use_model_input)

        def u(k):
            return [np.round(np.sin(0.3 * k), 1)]  # held inputs that repeat and change

        for k in range(700):
            plant.step({"u": u(k)}, dt=h, t_end=(k + 1) * h)
        state = plant.get_state()
        # the integration has restarted since t = 0 (model input: every RESTART steps; held input: when it changed)
        assert 0 < state["anchor_t"] < state["t"]

        def run(p, k0):
            return np.array([p.step({"u": u(k)}, dt=h, t_end=(k + 1) * h)["x"] for k in range(k0, k0 + 200)])

        first = run(plant, 700)
        fresh = LTVPlant(model, use_model_input=use_model_input)
        fresh.set_state(state)
        assert np.array_equal(run(fresh, 700), first)
        bare = LTVPlant(model, use_model_input=use_model_input)
        bare.set_state({"t": state["t"], "x": state["x"]})
        # a new integration from (t, x) instead of the saved one: the two differ by
        # their local errors (rtol 1e-12 of the state's scale), over ~60 steps each
        scale = float(np.max(np.abs(first)))
        np.testing.assert_allclose(run(bare, 700), first, rtol=0, atol=1e-9 * scale)


def test_held_input_against_exact_discretisation():
    """x' = -x + u with u held over each step: x_{k+1} = e^{-h} x_k + (1 - e^{-h}) u_k exactly."""
    from lpvest.systems._ltv import LTVStateSpace
    from lpvest.systems._streaming import LTVPlant

    plant = LTVPlant(LTVStateSpace([[-1.0]], [[1.0]], [[1.0]]))
    h, x = 0.1, 0.0
    for k in range(50):
        uk = [1.0, 1.0, -2.0, 0.5][k % 4]
        got = plant.step({"u": [uk]}, dt=h, t_end=(k + 1) * h)["x"][0]
        assert got == pytest.approx(x, abs=1e-12)  # DOP853 at rtol 1e-12 on |x| <= 2, 50 steps
        x = np.exp(-h) * x + (1 - np.exp(-h)) * uk


def test_solution_errors():
    from lpvest import ArgumentError
    from lpvest.systems._ltv import LTVStateSpace

    sol = LTVStateSpace([["sqrt(1 - t)"]], [[0]], [[1]]).solution(0.0, [1.0], u=0.0)  # nan after t = 1
    # x = exp(2/3 (1 - (1 - t)^1.5)); DOP853 at rtol 1e-12 over a few steps
    assert sol(0.5)[0] == pytest.approx(np.exp(2 / 3 * (1 - 0.5**1.5)), rel=1e-10)
    with pytest.raises(ExpressionError, match=r"integration failed at t = 1: Required step size"):
        sol(2.0)
    sol = LTVStateSpace([[-1.0]], [[1.0]], [[1.0]]).solution(0.0, [1.0], u=0.0)
    sol(3.0)
    with pytest.raises(ArgumentError, match=r"t = 0.5 lies before the current integration step.*must not decrease"):
        sol(0.5)


def test_value_at_one_time_is_the_array_value():
    """TimeFunction.at (the plant's per-step path) gives the numbers __call__ gives, bit for bit."""
    t = np.random.default_rng(5).uniform(-20.0, 20.0, 2000)
    for f in (TimeFunction.of("120*sin(t)"), TimeFunction.of("t**2 + 1/(t + 1000)"), TimeFunction.of(2.5),
              TimeFunction.of(lambda s: np.exp(-s) * np.cos(s))):
        assert [f.at(float(tk)) for tk in t] == [float(f(tk)) for tk in t], f
