"""The truncated-memory Kalman filter (Cox & Toth Theorem 1, ERRATA (6a)) and
the fading-memory analysis."""

import doctest

import numpy as np
import pytest

from lpvest import (
    AffineLPV,
    DimensionError,
    Monomial,
    NonFiniteError,
    NotPositiveDefiniteError,
    NumericalError,
    SchedulingRangeError,
    SchedulingSpace,
    load_system,
)
from lpvest.analysis import _fading_memory as fading_memory
from lpvest.analysis._fading_memory import (
    decay_rate,
    empirical_prediction_error,
    frozen_gains,
    monotonicity,
    prediction_error_covariance,
    tau_needed,
    truncation_errors,
)
from lpvest.core._protocol import Sampled as StreamingEstimator, run_streaming
from lpvest.estimators import _truncated as truncated_module
from lpvest.estimators._truncated import (
    TruncatedKalmanFilter,
    assumption_bounds,
    decorrelate,
    start_covariance,
    steady_state,
    theorem_start_covariance,
)
from lpvest.estimators.kalman import KalmanModel, kalman_filter
from tests.kalman_helpers import memory_steps, random_schedule, random_system
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel


@pytest.fixture(scope="module")
def model():
    return load_system("cox-toth-truncation").model()


@pytest.fixture(scope="module")
def data(model):
    T = 120
    k = np.arange(T)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=4).y
    return p, u, y


def _literal_truncated_gain(model, p, t, tau, P_start):
    """K^(tau)_t written out from the paper with plain numpy (no lpvest kernel):
    (6a) as corrected in ERRATA.md, then (4c)-(4e)."""
    Q, S, R = model.noise.Q, model.noise.S, model.noise.R

    def riccati(P, pt):
        A, B, C, D, G, H = model.at(pt)
        Om = C @ P @ C.T + H @ R @ H.T
        K = (A @ P @ C.T + G @ S @ H.T) @ np.linalg.inv(Om)
        return A @ P @ A.T - K @ Om @ K.T + G @ Q @ G.T, K

    if t <= tau:
        P = model.P0
        for i in range(t):
            P, _ = riccati(P, p[i])
    else:
        s = t - tau
        A, B, C, D, G, H = model.at(p[s - 1])
        # general decorrelation: J = G S H^T (H R H^T)^-1; for square invertible H
        # this is G S R^-1 H^-1 of (5a)/(5c)
        J = G @ S @ H.T @ np.linalg.inv(H @ R @ H.T)
        Abar = A - J @ C
        Qbar = Q - S @ H.T @ np.linalg.inv(H @ R @ H.T) @ H @ S.T
        P = Abar @ P_start @ Abar.T + G @ Qbar @ G.T
        for i in range(s, t):
            P, _ = riccati(P, p[i])
    _, K = riccati(P, p[t])
    return K, P


# ---------------------------------------------------------------------------
# the decorrelated form and ERRATA's corrections, numerically
# ---------------------------------------------------------------------------
def test_square_h_decorrelation_is_the_papers(model):
    # (5c), (5e) with ERRATA: Abar = A - G S R^-1 H^-1 C, Qbar = Q - S R^-1 S^T
    km = KalmanModel(model)
    for pv in ([-1.0], [0.3], [1.0]):
        A, B, C, D, G, H = model.at(pv)
        Q, S, R = model.noise.Q, model.noise.S, model.noise.R
        d = decorrelate(km.matrices(pv))
        Ri = np.linalg.inv(R)
        J = G @ S @ Ri @ np.linalg.inv(H)
        # J by a Cholesky solve with H R H^T (library) and by inverses (here): each
        # within a few n eps cond(H R H^T) of J (Higham (7.2), (14.x)); then one
        # more stage of products, of the size of |A| + |J| |C| and |G| |Q| |G^T| + |J| |H R H^T| |J^T|
        kap = np.linalg.cond(H @ R @ H.T)
        size_a = np.max(np.abs(A) + np.abs(J) @ np.abs(C))
        size_q = np.max(np.abs(G) @ np.abs(Q) @ np.abs(G.T) + np.abs(J) @ np.abs(H @ R @ H.T) @ np.abs(J.T))
        np.testing.assert_allclose(d.Abar, A - J @ C, rtol=0, atol=roundoff(size_a, 4, n=2, amp=kap))
        np.testing.assert_allclose(d.GQbarG, G @ (Q - S @ Ri @ S.T) @ G.T, rtol=0,
                                   atol=roundoff(size_q, 5, n=2, amp=kap))


@pytest.mark.parametrize("dims", [{"nx": 2, "ny": 2, "nv": 2}, {"nx": 3, "ny": 1, "nv": 2, "nw": 4}])
def test_errata_9_prior_from_posterior(dims):
    # ERRATA (9): P_{t+1|t} = Abar P_{t|t} Abar^T + G Qbar G^T, with the general
    # (H R H^T)^-1 form for a non-square H (n_v > n_y)
    rng = np.random.default_rng(31)
    m = random_system(rng, nu=1, **dims)
    T = 20
    p = random_schedule(m, rng, T)
    u = rng.standard_normal((T, 1))
    res = kalman_filter(m, p, u, m.simulate(p, u, rng=rng).y)
    d = decorrelate(KalmanModel(m).matrices_batch(p))
    P9 = d.Abar @ res.filtered_covariances @ np.swapaxes(d.Abar, 1, 2) + d.GQbarG
    # one step of two formulas from the same P_{t|t-1} (no accumulation over t):
    # Joseph form M V M^T (library) against (9) with Abar, Qbar from solves with
    # H R H^T (amplified by its condition number); terms of the size of
    # |Abar| |P_{t|t}| |Abar^T| + |G Q G^T| + |J| |H R H^T| |J^T|
    absT = np.abs(np.swapaxes(d.Abar, 1, 2))
    size = np.max(np.abs(d.Abar) @ np.abs(res.filtered_covariances) @ absT + np.abs(d.GQbarG)
                  + np.abs(res.predicted_covariances[1:]))
    kap = float(np.max(np.linalg.cond(KalmanModel(m).matrices_batch(p).HRH)))
    n = dims["nx"] + dims["ny"]
    np.testing.assert_allclose(P9, res.predicted_covariances[1:], rtol=0, atol=roundoff(size, 6, n=n, amp=kap))
    # (9) read literally as printed, Abar P Abar^T + Qbar (no G), is not it
    literal = d.Abar @ res.filtered_covariances @ np.swapaxes(d.Abar, 1, 2) + (
        m.noise.Q - m.noise.S @ np.linalg.solve(m.noise.R, m.noise.S.T)
    )[: dims["nx"], : dims["nx"]]
    assert np.max(np.abs(literal - res.predicted_covariances[1:])) > 1e-3


def test_exact_posterior_start_reproduces_the_exact_gain(model, data):
    # (6a) with P^_0 = the true P_{s-1|s-1} gives back P_{t|t-1} exactly: this pins
    # down the corrected (6a) (index s-1, G(p_{s-1}) Qbar G^T)
    from lpvest.estimators._truncated import truncated_prior

    p, u, y = data
    res = kalman_filter(model, p, u, y)
    sms = KalmanModel(model).step_matrices_batch(p)
    # tau + 1 Riccati steps (each a few stages of n = 2 n_x + n_y products, a
    # solve with Omega_t) in two arrangements, on covariances of size max |P|
    kap = float(np.max(np.linalg.cond(res.innovation_covariances)))
    size = float(np.max(np.abs(res.predicted_covariances)))
    for tau in (0, 1, 4):
        for t in range(tau + 1, 60, 7):
            win = [sms.at(i) for i in range(t - tau - 1, t)]
            P = truncated_prior(win, res.filtered_covariances[t - tau - 1], t=t)
            np.testing.assert_allclose(P, res.predicted_covariances[t], rtol=0,
                                       atol=roundoff(size, 4 * (tau + 1), n=6, amp=kap))


# ---------------------------------------------------------------------------
# the streaming truncated filter
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("tau", [0, 1, 3, 8])
@pytest.mark.parametrize("start", ["theorem", "zero"])
def test_truncated_filter_matches_the_literal_formula(model, data, tau, start):
    p, u, y = data
    P_start = np.zeros((2, 2)) if start == "zero" else theorem_start_covariance(model)
    tf = TruncatedKalmanFilter(model, tau, start=P_start if start == "zero" else "theorem")
    np.testing.assert_allclose(tf.start, P_start, rtol=0, atol=roundoff(np.max(np.abs(P_start)), 1))
    out = run_streaming(tf, {"p": p, "u": u, "y": y})
    # up to tau + 1 Riccati steps written two ways (Cholesky solves and Joseph
    # forms against inv(Omega) and (4d)): a few stages of n = 6 products per
    # step, amplified by cond(Omega_t), on gains of size max |K|
    ref = kalman_filter(model, p, u, y)
    kap = float(np.max(np.linalg.cond(ref.innovation_covariances)))
    size = float(np.max(np.abs(ref.gains))) + float(np.max(np.abs(ref.predicted_covariances)))
    for t in (0, tau, tau + 1, tau + 2, 40, 119):
        K, _ = _literal_truncated_gain(model, p, t, tau, P_start)
        np.testing.assert_allclose(out["K"][t], K, rtol=0, atol=roundoff(size, 5 * (min(t, tau) + 1), n=6, amp=kap))


def test_truncated_filter_equals_exact_for_t_up_to_tau_and_converges(model, data):
    p, u, y = data
    res = kalman_filter(model, p, u, y)
    kap = float(np.max(np.linalg.cond(res.innovation_covariances)))
    size_k = float(np.max(np.abs(res.gains))) + float(np.max(np.abs(res.predicted_covariances)))
    outs = {tau: run_streaming(TruncatedKalmanFilter(model, tau), {"p": p, "u": u, "y": y}) for tau in (2, 10, 25, 60)}
    errs = {tau: np.max(np.abs(out["K"] - res.gains), axis=(1, 2)) for tau, out in outs.items()}
    worst = [float(np.max(e)) for e in errs.values()]
    assert worst[0] > worst[1] > worst[2] > worst[3]
    # geometric decay at rate rho per step (~0.55); a rounding error made in one
    # Riccati step decays at the same rate, so the accumulated rounding of the
    # recursion is at most 1 / (1 - rho) steps' worth (a few stages of n = 6
    # products per step, amplified by cond(Omega_t))
    rho = (worst[2] / worst[1]) ** (1 / 15)
    assert rho < 0.7
    rounding = roundoff(size_k, 5 / (1 - rho), n=6, amp=kap)
    for tau, err in errs.items():
        # t <= tau: exact by construction, the same recursion from P0 (the batch
        # filter's loop and the streaming kernel): rounding only
        assert np.max(err[: tau + 1]) <= rounding
    # at tau = 60 the truncation error rho^60 worst[0] ~ 3e-16 is below rounding
    assert worst[0] > 1e-2 and worst[3] <= rounding + rho**60 * worst[0]
    # the same gains: means through 120 steps of the stable closed loop
    # A - K C, rounding of size |x| + |K| |y| per step; the loop contracts at
    # about sqrt(rho) (the Riccati difference contracts like its square)
    size_x = float(np.max(np.abs(res.predicted_means))) + float(np.max(np.abs(y))) * size_k
    np.testing.assert_allclose(outs[60]["xpred"], res.predicted_means[1:], rtol=0,
                               atol=roundoff(size_x, 5 / (1 - np.sqrt(rho)), n=6, amp=kap))


def test_truncated_matches_the_analysis(model, data):
    p, u, y = data
    err = truncation_errors(model, p, [3, 7])
    for i, tau in enumerate((3, 7)):
        out = run_streaming(TruncatedKalmanFilter(model, tau), {"p": p, "u": u, "y": y})
        # the same tau + 1 Riccati steps, batched (analysis) and one by one
        # (filter): rounding of a few stages per step, amplified by cond(Omega)
        size = float(np.max(np.abs(err.truncated_gains[i])))
        kap = float(np.max(np.linalg.cond(kalman_filter(model, p, u, y).innovation_covariances)))
        np.testing.assert_allclose(out["K"], err.truncated_gains[i], rtol=0,
                                   atol=roundoff(size, 5 * (tau + 1), n=6, amp=kap))


def test_truncated_ports_and_state(model, data):
    p, u, y = data
    tf = TruncatedKalmanFilter(model, 4)
    assert isinstance(tf, StreamingEstimator)
    assert [(q.name, q.shape) for q in tf.input_ports] == [("p", (1,)), ("u", (1,)), ("y", (2,))]
    assert [(q.name, q.shape) for q in tf.output_ports] == [
        ("xhat", (2,)), ("P", (2, 2)), ("xpred", (2,)), ("yhat", (2,)),
        ("innovation", (2,)), ("K", (2, 2)), ("Omega", (2, 2)),
    ]
    for t in range(3):
        tf.step({"p": p[t], "u": u[t], "y": y[t]})
    early = tf.get_state()
    assert early["window_length"] == 3 and early["window_p"].shape == (5, 1)
    for t in range(3, 20):
        tf.step({"p": p[t], "u": u[t], "y": y[t]})
    saved = tf.get_state()
    assert saved["window_length"] == 5
    np.testing.assert_array_equal(saved["window_p"], p[15:20])
    first = [tf.step({"p": p[t], "u": u[t], "y": y[t]}) for t in range(20, 30)]
    tf.reset()
    tf.set_state(saved)
    second = [tf.step({"p": p[t], "u": u[t], "y": y[t]}) for t in range(20, 30)]
    for a, b in zip(first, second, strict=True):
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
    tf.set_state(early)  # a state from before the window filled
    assert tf.t == 3
    with pytest.raises(DimensionError, match="window_length = 2 does not fit t = 20"):
        tf.set_state(saved | {"window_length": 2})
    bad = saved | {"window_p": np.full((5, 1), 3.0)}
    with pytest.raises(SchedulingRangeError, match="outside its declared range"):
        tf.set_state(bad)
    assert tf.t == 3


def test_truncated_outputs_and_bad_samples_leave_the_state(model):
    tf = TruncatedKalmanFilter(model, 3)
    good = {"p": [0.3], "u": [1.0], "y": [0.2, -0.1]}
    for _ in range(5):
        tf.step(good)
    before = tf.get_state()
    tf.outputs(good)
    for bad, err in (
        ({"p": [2.0]}, SchedulingRangeError),
        ({"y": [np.nan, 0.0]}, NonFiniteError),
        ({"y": [1.0]}, DimensionError),
    ):
        with pytest.raises(err):
            tf.step(good | bad)
    after = tf.get_state()
    for k in before:
        np.testing.assert_array_equal(before[k], after[k])


def test_truncated_singular_omega_names_t():
    # C(p) = p [1, 1], H(p) = p: Omega_t = 0 at p = 0 whatever the covariance
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    m = AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A=0.5 * np.eye(2), C={"p": np.ones((1, 2))}, H={"p": [[1.0]]}, Q=np.eye(2), R=np.eye(1),
    )
    tf = TruncatedKalmanFilter(m, 2, start=np.eye(2))
    tf.step({"p": [0.5], "y": [1.0]})
    before = tf.get_state()
    with pytest.raises(NumericalError, match="Omega_t is not positive definite at t=1"):
        tf.step({"p": [0.0], "y": [1.0]})
    after = tf.get_state()
    for k in before:
        np.testing.assert_array_equal(before[k], after[k])


def test_truncated_constructor_errors(model):
    with pytest.raises(DimensionError, match="tau must be a non-negative integer; found -1"):
        TruncatedKalmanFilter(model, -1)
    with pytest.raises(DimensionError, match="tau must be a non-negative integer; found 2.5"):
        TruncatedKalmanFilter(model, 2.5)
    with pytest.raises(DimensionError, match="start='steady-state' needs start_p"):
        TruncatedKalmanFilter(model, 2, start="steady-state")
    with pytest.raises(DimensionError, match="start must be 'theorem', 'steady-state' or a matrix"):
        TruncatedKalmanFilter(model, 2, start="bogus")
    with pytest.raises(NotPositiveDefiniteError, match="start covariance is not positive semidefinite"):
        TruncatedKalmanFilter(model, 2, start=-np.eye(2))
    with pytest.raises(DimensionError, match="start_fraction must lie in"):
        TruncatedKalmanFilter(model, 2, start_fraction=1.0)


def test_theorem_start_needs_full_rank_process_noise():
    # (5f): G Qbar G^T > 0 fails for a rank-one G; (6b) admits no P^_0
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    m = AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A={"1": 0.5 * np.eye(2), "p": 0.1 * np.eye(2)}, C=np.eye(2), G=[[1.0], [0.0]], Q=[[1.0]], R=np.eye(2),
    )
    with pytest.raises(NotPositiveDefiniteError, match=r"assumption \(5f\) fails"):
        TruncatedKalmanFilter(m, 3)
    TruncatedKalmanFilter(m, 3, start="steady-state", start_p=[0.0])  # other starts still work


def test_decorrelation_needs_invertible_hrh():
    # H(p) = p: H R H^T = 0 at p = 0, where (6a) cannot be formed
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    m = AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A=0.5 * np.eye(2), C=np.eye(2), H={"p": np.eye(2)}, Q=np.eye(2), R=np.eye(2), P0=np.eye(2),
    )
    tf = TruncatedKalmanFilter(m, 1, start=np.eye(2))
    for pv in (0.0, 0.5):
        tf.step({"p": [pv], "y": [0.0, 0.0]})
    with pytest.raises(NotPositiveDefiniteError, match=r"H\(p\) R H\(p\)\^T is singular at t=0"):
        tf.step({"p": [0.5], "y": [0.0, 0.0]})
    assert tf.t == 2


# ---------------------------------------------------------------------------
# start covariances
# ---------------------------------------------------------------------------
def test_theorem_start_is_below_the_posterior(model, data):
    # (6b) and (8): P^_0 < alpha_2/(alpha_2 beta_2 + 1) I <= P_{t|t} for t >= 1
    p, u, y = data
    b = assumption_bounds(model)
    assert b.hold
    P0 = theorem_start_covariance(model)
    np.testing.assert_allclose(P0, 0.5 * b.posterior_lower_bound * np.eye(2), rtol=roundoff(1.0, 1))  # a product
    res = kalman_filter(model, p, u, y)
    lam = np.linalg.eigvalsh(res.filtered_covariances[1:])
    assert lam.min() >= b.posterior_lower_bound
    # the grid bounds bracket the ones along the trajectory
    bt = assumption_bounds(model, p)
    assert b.alpha2 <= bt.alpha2 and b.beta2 >= bt.beta2 and b.beta1 <= bt.beta1


def test_lemma2_ordering_for_the_theorem_start(model, data):
    # Lemma 2: 0 <= P - P^(tau) for a start below the posterior covariance
    p, _, _ = data
    err = truncation_errors(model, p, [0, 1, 2, 5, 10])
    # 0 up to the rounding of the two covariances: up to tau + 1 = 11 Riccati
    # steps of a few stages of n = 6 products, amplified by cond(Omega)
    res = kalman_filter(model, p, data[1], data[2])
    kap = float(np.max(np.linalg.cond(res.innovation_covariances)))
    rounding = roundoff(float(np.max(np.abs(res.predicted_covariances))), 5 * 11, n=6, amp=kap)
    assert np.all(err.min_ordering_eigenvalue >= -rounding)
    too_big = truncation_errors(model, p, [1, 2], start=np.eye(2))
    assert np.all(too_big.min_ordering_eigenvalue < -1e-4)


def test_steady_state_start_reproduces_the_dare_at_constant_p(model):
    from scipy.linalg import solve_discrete_are

    pv = np.array([0.4])
    A, B, C, D, G, H = model.at(pv)
    Q, S, R = model.noise.Q, model.noise.S, model.noise.R
    P = solve_discrete_are(A.T, C.T, G @ Q @ G.T, H @ R @ H.T, s=G @ S @ H.T)
    ss = steady_state(model, pv)
    # both solve the DARE with scipy, from data rounded differently (the
    # library evaluates G Q G^T ... from packed coefficients): the solution
    # moves by ~ delta cond(Omega) / (1 - rho^2) for data perturbed by delta
    # (rho: spectral radius of the closed loop A - K C; the closed-loop
    # Lyapunov operator), delta a few stages of n = 2 n_x + n_y products
    Om = C @ P @ C.T + H @ R @ H.T
    K = (A @ P @ C.T + G @ S @ H.T) @ np.linalg.inv(Om)
    rho = max(abs(np.linalg.eigvals(A - K @ C)))
    amp = np.linalg.cond(Om) / (1 - rho**2)
    np.testing.assert_allclose(ss.P_pred, P, rtol=0, atol=roundoff(np.max(np.abs(P)), 5, n=6, amp=amp))
    np.testing.assert_allclose(ss.K, K, rtol=0, atol=roundoff(np.max(np.abs(K)), 5, n=6, amp=amp))
    # at constant p the steady-state posterior start makes K^(tau) = K_inf for
    # every tau: tau + 1 = 3 Riccati steps from the fixed point, each moving
    # it by rounding only
    T = 30
    p = np.tile(pv, (T, 1))
    tf = TruncatedKalmanFilter(model, 2, start="steady-state", start_p=pv, P0=P)
    out = run_streaming(tf, {"p": p, "u": np.zeros((T, 1)), "y": np.zeros((T, 2))})
    np.testing.assert_allclose(out["K"], np.broadcast_to(ss.K, (T, 2, 2)), rtol=0,
                               atol=roundoff(np.max(np.abs(K)), 5 * 3, n=6, amp=amp))
    np.testing.assert_allclose(start_covariance(model, "steady-state", start_p=pv), ss.P_filt, rtol=0,
                               atol=roundoff(np.max(np.abs(ss.P_filt)), 1))  # the same computation


def test_steady_state_without_a_solution():
    # an unstable mode that no output sees: no stabilising DARE solution
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    m = AffineLPV.from_matrices(
        space, [Monomial.component(0, space)], A=np.diag([2.0, 0.5]), C=[[0.0, 1.0]], Q=np.eye(2), R=[[1.0]],
    )
    with pytest.raises(NumericalError, match=r"no stabilising steady-state Riccati solution at p = \[0.0\]"):
        steady_state(m, [0.0])
    with pytest.raises(NumericalError, match=r"recursion at p = \[0.0\] diverges: no stabilising solution"):
        frozen_gains(m, np.zeros((3, 1)))


# ---------------------------------------------------------------------------
# fading-memory analysis
# ---------------------------------------------------------------------------
def test_truncation_errors_against_the_literal_formula(model, data):
    p, _, _ = data
    err = truncation_errors(model, p, [0, 2, 6])
    P_start = err.start
    ex = kalman_filter(model, p, data[1], data[2])
    Kex = ex.gains
    # tau + 1 Riccati steps two ways (a few stages of n = 6 products per step,
    # amplified by cond(Omega)); the exact gain's rounding accumulates over at
    # most memory_steps (the closed loop contracts) of the same size
    kap = float(np.max(np.linalg.cond(ex.innovation_covariances)))
    size = float(np.max(np.abs(Kex))) + float(np.max(np.abs(ex.predicted_covariances)))
    steps_ex = memory_steps(model, p, Kex)
    for i, tau in enumerate((0, 2, 6)):
        for t in (0, tau, tau + 1, 50, 119):
            K, P = _literal_truncated_gain(model, p, t, tau, P_start)
            tol = roundoff(size, 5 * (min(t, tau) + 1), n=6, amp=kap)
            np.testing.assert_allclose(err.truncated_gains[i, t], K, rtol=0, atol=tol)
            tol_ex = tol + roundoff(size, 5 * steps_ex, n=6, amp=kap)
            assert err.K_error[i, t] == pytest.approx(np.linalg.norm(Kex[t] - K, 2), abs=tol_ex)
    assert np.all(err.K_error[2, :7] == 0.0)


def test_random_system_truncation_converges():
    rng = np.random.default_rng(8)
    m = random_system(rng, nx=3, ny=2, nu=1)
    p = random_schedule(m, rng, 150)
    err = truncation_errors(m, p, range(0, 41, 5), start="steady-state", start_p=[0.0, 0.5])
    assert err.max_K_error[0] > 1e-3
    # convergence, not rounding: ten orders of magnitude over 40 steps of memory
    # (a geometric rate below 0.56 per step)
    assert err.max_K_error[-1] < 1e-10 * err.max_K_error[0]


def test_monotonicity_and_tau_needed(model, data):
    p, _, _ = data
    err = truncation_errors(model, p, range(0, 31))
    mono = monotonicity(err)
    assert mono.sup_monotone and mono.pairs > 1000
    assert mono.violations == 0  # theorem start, this example: Conjecture 1 holds
    ss = truncation_errors(model, p, range(0, 31), start="steady-state", start_p=[0.0])
    m2 = monotonicity(ss)
    assert m2.violations > 0  # not for every start and every t (ERRATA)
    t, tau, ratio = m2.worst
    assert ratio >= 1.0 and ss.K_error[tau + 1, t] >= ss.K_error[tau, t]
    n1, n6 = tau_needed(err, 1e-3), tau_needed(err, 1e-6)
    assert err.max_K_error[n1] < 1e-3 <= err.max_K_error[n1 - 1]
    assert err.max_K_error[n6] < 1e-6 <= err.max_K_error[n6 - 1]
    assert tau_needed(err, 1e-30) is None
    model_p = (model, p[:5])
    K = frozen_gains(*model_p)
    with pytest.raises(DimensionError, match=r"gains has shape \(4, 2, 2\); expected \(5, 2, 2\)"):
        empirical_prediction_error(*model_p, None, K[:4], runs=10)
    for runs in (0, 2.5, True):
        with pytest.raises(ValueError, match="runs must be a positive integer"):
            empirical_prediction_error(*model_p, None, K, runs=runs)
    with pytest.raises(TypeError, match="model must be an AffineLPV"):
        empirical_prediction_error(load_system("cox-toth-ex1").model(), p[:5], None, K, runs=10)
    for fn in (tau_needed, decay_rate, monotonicity):  # "k" is not "K": an error, not the P errors
        args = (err, 1e-3) if fn is tau_needed else (err,)
        with pytest.raises(DimensionError, match="which must be 'K' or 'P'; found 'k'"):
            fn(*args, which="k")


def test_monotonicity_on_a_made_up_curve():
    # a constructed error table: sup increases at tau 2 -> 3; pointwise one violation
    E = np.array([[0.0, 1.0, 1.0], [0.0, 0.5, 0.6], [0.0, 0.1, 0.05], [0.0, 0.2, 0.01]])
    err = fading_memory.TruncationErrors(
        np.arange(4), E, E, E.max(axis=1), E.max(axis=1), np.zeros(4),
        np.zeros((3, 1, 1)), np.zeros((3, 1, 1)), np.zeros((4, 3, 1, 1)), np.zeros((1, 1)),
    )
    m = monotonicity(err)
    assert not m.sup_monotone and m.sup_increases == ((2, 3),)
    assert m.pairs == 6 and m.violations == 1 and m.worst == (1, 2, pytest.approx(2.0, rel=roundoff(1.0, 1)))


def test_prediction_error_of_the_exact_gain_is_omega(model, data):
    p, u, y = data
    res = kalman_filter(model, p, u, y)
    pe = prediction_error_covariance(model, p, res.gains)
    # the same covariances by the given-gain recursion and by the Riccati
    # recursion: a few stages of n = 6 products per step, amplified by
    # cond(Omega), accumulated over memory_steps of the contracting closed loop
    kap = float(np.max(np.linalg.cond(res.innovation_covariances)))
    steps = memory_steps(model, p, res.gains)
    for got, want in ((pe.output, res.innovation_covariances), (pe.state, res.predicted_covariances)):
        np.testing.assert_allclose(got, want, rtol=0, atol=roundoff(np.max(np.abs(want)), 5 * steps, n=6, amp=kap))


def test_prediction_error_matches_monte_carlo(model):
    # The exact second moments of a suboptimal (frozen-gain) predictor against
    # simulation: 16 independent batches of 250 trajectories; the standard error
    # of the mean of trace E[e e^T] over t comes from the spread of the batch
    # means; tolerance 5 standard errors (the seeds are fixed).
    T = 40
    p = np.sin(0.25 * np.arange(T))[:, None]
    u = np.ones((T, 1))
    K = frozen_gains(model, p)
    a = float(np.mean(np.trace(prediction_error_covariance(model, p, K).output, axis1=1, axis2=2)))
    means = [
        float(np.mean(np.trace(empirical_prediction_error(model, p, u, K, runs=250, rng=100 + i), axis1=1, axis2=2)))
        for i in range(16)
    ]
    se = float(np.std(means, ddof=1) / np.sqrt(len(means)))
    assert se < 0.01 * a
    assert abs(np.mean(means) - a) < 5 * se
    # the same check rejects the moments of a different gain sequence
    wrong = float(np.mean(np.trace(prediction_error_covariance(model, p, 0.5 * K).output, axis1=1, axis2=2)))
    assert abs(np.mean(means) - wrong) > 5 * se
    # and the Kalman gain is optimal at every t
    exact = prediction_error_covariance(model, p, kalman_filter(model, p, u, np.zeros((T, 2))).gains)
    frozen = prediction_error_covariance(model, p, K)
    rounding = roundoff(float(np.max(np.abs(frozen.output))), 5 * memory_steps(model, p, K), n=6)
    assert np.all(np.trace(exact.output, axis1=1, axis2=2) <= np.trace(frozen.output, axis1=1, axis2=2) + rounding)


def test_frozen_gains_are_steady_state_gains(model):
    # fixed-point iteration of all frozen models against scipy's DARE
    p = np.array([[0.0], [0.5], [0.0], [-0.9]])
    K = frozen_gains(model, p)
    np.testing.assert_array_equal(K[0], K[2])
    for t in range(4):
        np.testing.assert_allclose(K[t], steady_state(model, p[t]).K, rtol=0, atol=_frozen_gain_tol(model, p[t]))


def _frozen_gain_tol(model, pv):
    """How far frozen_gains' fixed-point iteration may stop from scipy's DARE
    solution at p: the iteration stops when the largest change of P is below
    tol max(1, |P|) (frozen_gains' tol); it converges at rate rho^2 (rho the
    spectral radius of the closed loop), so the distance left is at most
    change / (1 - rho^2); the gain moves by |dP| |C| (|A| + |K| |C|) /
    lambda_min(Omega). Plus both solutions' rounding, amplified by the DARE's
    conditioning cond(Omega) / (1 - rho^2)."""
    import inspect

    stop = inspect.signature(frozen_gains).parameters["tol"].default
    ss = steady_state(model, pv)
    A, B, C, D, G, H = model.at(pv)
    Om = C @ ss.P_pred @ C.T + H @ model.noise.R @ H.T
    rho = max(abs(np.linalg.eigvals(A - ss.K @ C)))
    dP = stop * max(1.0, float(np.max(np.abs(ss.P_pred)))) / (1 - rho**2)
    nrm = np.linalg.norm
    dK = dP * nrm(C, 2) * (nrm(A, 2) + nrm(ss.K, 2) * nrm(C, 2)) / np.linalg.eigvalsh(Om)[0]
    return dK + roundoff(np.max(np.abs(ss.K)), 5, n=6, amp=np.linalg.cond(Om) / (1 - rho**2))


def test_analysis_input_errors(model):
    p = np.zeros((10, 1))
    with pytest.raises(DimensionError, match="taus must be non-negative integers"):
        truncation_errors(model, p, [-1, 2])
    with pytest.raises(DimensionError, match=r"gains has shape \(10, 2, 1\); expected \(10, 2, 2\)"):
        prediction_error_covariance(model, p, np.zeros((10, 2, 1)))


def test_docstring_examples_run():
    for mod in (truncated_module, fading_memory):
        failures, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
        assert tried > 0 and failures == 0


def test_compare_filters(model):
    from lpvest import compare_filters

    p = np.sin(0.25 * np.arange(150))[:, None]
    cmp = compare_filters(model, p, [0, 3, 40], constant_p=[0.5], burn_in=30)
    assert cmp.names == (
        "exact", "truncated tau=0", "truncated tau=3", "truncated tau=40", "frozen K_inf(p_t)", "constant K_inf(0.5)"
    )
    assert cmp.excess["exact"] == 0.0
    # excess = mean trace / exact mean trace - 1: each mean trace to the rounding
    # of the covariance recursions (a few stages of n = 6 products per step,
    # amplified by cond(Omega), over memory_steps of the contracting closed
    # loop); at tau = 40 the truncation error (rate ~0.55^2 per step) is far below
    exact = kalman_filter(model, p, np.zeros((150, 1)), np.zeros((150, 2)))
    kap = float(np.max(np.linalg.cond(exact.innovation_covariances)))
    rounding = 2 * roundoff(1.0, 5 * memory_steps(model, p, exact.gains), n=6, amp=kap)
    assert abs(cmp.excess["truncated tau=40"]) <= rounding
    assert cmp.excess["truncated tau=0"] > cmp.excess["truncated tau=3"] > 0
    assert min(cmp.excess.values()) >= -rounding  # nothing beats the Kalman filter
    np.testing.assert_allclose(cmp.gains["constant K_inf(0.5)"][7], steady_state(model, [0.5]).K, rtol=0,
                               atol=_frozen_gain_tol(model, np.array([0.5])))
