"""The exact LPV Kalman filter (Cox & Toth (4a)-(4e)): oracle, statistics,
steady state, bad input, state handling."""

import doctest
import warnings

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
from lpvest.core._protocol import Sampled as StreamingEstimator, run_streaming
from lpvest.estimators import kalman as kalman_package
from lpvest.estimators.kalman import (
    SCAN_MAX_AMPLIFICATION,
    SCAN_MIN_SAMPLES,
    KalmanModel,
    KalmanState,
    LPVKalmanFilter,
    ScanAccuracyWarning,
    _streaming as streaming_module,
    kalman_filter,
    kalman_step,
    simulate_innovation_form,
)
from tests.kalman_helpers import (
    EPS,
    amplification,
    kappa_omega,
    oracle,
    oracle_rtol,
    random_schedule,
    random_system,
    scan_rtol,
)
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel

#: every batch test runs with both algorithms of kalman_filter (the "auto"
#: choice between them: tests/test_kalman_scan.py)
METHODS = ["sequential", "scan"]


@pytest.fixture(scope="module")
def truncation_model():
    return load_system("cox-toth-truncation").model()


# ---------------------------------------------------------------------------
# against the independent oracle (joint Gaussian of states and outputs)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "dims",
    [
        {"nx": 3, "ny": 2, "nu": 1},
        {"nx": 2, "ny": 1, "nu": 2},
        {"nx": 3, "ny": 2, "nu": 0, "nw": 2, "nv": 3},  # G, H not square
        {"nx": 4, "ny": 3, "nu": 1, "nw": 5, "nv": 3},
        {"nx": 3, "ny": 5, "nu": 1, "nw": 2, "nv": 6},  # n_y > 3: the LAPACK path
        {"nx": 2, "ny": 2, "nu": 1, "basis": "components"},  # psi_i = p_j, the fast path
        {"nx": 3, "ny": 1, "nu": 1, "basis": "formulas"},  # sin(p1), exp(-p2)
    ],
)
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("method", METHODS)
def test_filter_matches_gaussian_conditioning(dims, seed, method):
    rng = np.random.default_rng(1000 + seed)
    model = random_system(rng, **dims)
    T = 7
    p = random_schedule(model, rng, T)
    u = rng.standard_normal((T, model.nu))
    y = model.simulate(p, u, rng=rng).y
    orc = oracle(model, p, u)
    # the scan's rounding errors grow with its amplification (dims0, seed 0:
    # amp = 233, beyond SCAN_MAX_AMPLIFICATION: method="scan" warns)
    amp = amplification(model, p, u, y) if method == "scan" else None
    if amp is not None and amp > SCAN_MAX_AMPLIFICATION:
        with pytest.warns(ScanAccuracyWarning):
            res = kalman_filter(model, p, u if model.nu else None, y, method=method)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("error", ScanAccuracyWarning)
            res = kalman_filter(model, p, u if model.nu else None, y, method=method)
    rel = oracle_rtol(orc.condition(), amp)  # eps cond(S_yy), plus the scan's eps (1 + amp)^2: kalman_helpers

    def close(actual, desired):
        np.testing.assert_allclose(actual, desired, rtol=0, atol=rel * max(1.0, float(np.max(np.abs(desired)))))

    for t in range(T + 1):
        m, S = orc.predicted(y, t)
        close(res.predicted_means[t], m)
        close(res.predicted_covariances[t], S)
    for t in range(T):
        m, S = orc.filtered(y, t)
        close(res.filtered_means[t], m)
        close(res.filtered_covariances[t], S)
        my, Om = orc.output(y, t)
        close(res.predicted_outputs[t], my)
        close(res.innovation_covariances[t], Om)
        close(res.gains[t], orc.gain(y, t))
    # log p(y_0..y_{T-1}) against the oracle's Gaussian density: a sum of T n_y
    # log-variances and squared whitened residuals, each to rel of its size
    ll_scale = T * model.ny + float(np.sum(np.abs(res.log_likelihood_terms)))
    assert res.log_likelihood == pytest.approx(orc.log_density(y), abs=rel * ll_scale)
    # the streaming filter gives the same numbers. The sequential batch shares
    # its kernel (covariances, gains, Omega: the same operations, bit for bit)
    # but not its mean loop ((A - K C) x + B u + K (y - D u) against
    # A x + B u + K xi): per step the same sums in another order, a few n eps
    # of the terms' size (Higham, Accuracy and Stability, 3.1), accumulated
    # over T steps of a stable loop: 20 n T eps. The scan is another
    # algorithm: its own bound on top.
    tol = 20 * (model.nx + model.nu + model.ny) * T * EPS
    tol += scan_rtol(amp, kappa=kappa_omega(res)) if amp is not None else 0.0
    kf = LPVKalmanFilter(model)
    inputs = {"p": p, "y": y} | ({"u": u} if model.nu else {})
    out = run_streaming(kf, inputs)
    for key, field in [
        ("xpred", res.predicted_means[1:]), ("Ppred", res.predicted_covariances[1:]), ("xhat", res.filtered_means),
        ("P", res.filtered_covariances), ("K", res.gains), ("Omega", res.innovation_covariances),
        ("yhat", res.predicted_outputs), ("innovation", res.innovations),
    ]:
        np.testing.assert_allclose(out[key], field, rtol=0, atol=tol * max(1.0, float(np.max(np.abs(field)))))
    assert kf.log_likelihood == pytest.approx(res.log_likelihood, abs=tol * ll_scale)


@pytest.mark.parametrize("method", METHODS)
def test_oracle_catches_a_wrong_cross_covariance(rng, method):
    # the oracle test is able to fail: ignoring S gives different predictions
    model = random_system(rng, nx=2, ny=1, nu=1)
    T = 5
    p = random_schedule(model, rng, T)
    u = rng.standard_normal((T, 1))
    y = model.simulate(p, u, rng=rng).y
    noise = model.noise
    no_s = np.block([[noise.Q, 0 * noise.S], [0 * noise.S.T, noise.R]])
    res = kalman_filter(model, p, u, y, noise=no_s, method=method)
    m, _ = oracle(model, p, u).predicted(y, T)
    assert np.max(np.abs(res.predicted_means[T] - m)) > 1e-3


@pytest.mark.parametrize("method", METHODS)
def test_filtered_state_uses_the_filter_gain(truncation_model, rng, method):
    # ERRATA (7): P_{t|t} = (I - L C) P with L = P C^T Omega^-1, not the predictor gain K
    model = truncation_model
    T = 30
    p = np.sin(0.25 * np.arange(T))[:, None]
    u = rng.standard_normal((T, 1))
    y = model.simulate(p, u, rng=rng).y
    res = kalman_filter(model, p, u, y, method=method)
    for t in (0, 5, 29):
        C = model.at(p[t]).C
        P = res.predicted_covariances[t]
        Om = res.innovation_covariances[t]
        L = P @ C.T @ np.linalg.inv(Om)
        # the same L from the same P: Cholesky solves (library) against inv(Omega):
        # a few stages of n = 2 products, amplified by cond(Omega); the scan's
        # L and P_{t|t} come from its own P (its bound on top, amp = 0.06 here)
        kap = np.linalg.cond(Om)
        scan = scan_rtol(amplification(model, p, u, y), kappa=kappa_omega(res)) if method == "scan" else 0.0
        size_l = np.max(np.abs(P) @ np.abs(C.T) @ np.abs(np.linalg.inv(Om)))
        np.testing.assert_allclose(res.filter_gains[t], L, rtol=0,
                                   atol=roundoff(size_l, 4, n=2, amp=kap) + scan * np.max(np.abs(L)))
        # Joseph form (library) against (7): terms of size |P| + |L| |C| |P|
        size_p = np.max(np.abs(P) + np.abs(L) @ np.abs(C) @ np.abs(P))
        np.testing.assert_allclose(res.filtered_covariances[t], (np.eye(2) - L @ C) @ P, rtol=0,
                                   atol=roundoff(size_p, 6, n=2, amp=kap) + scan * np.max(np.abs(P)))
    # (7) as printed, with the predictor gain K_t, is a different matrix
    C, P = model.at(p[0]).C, res.predicted_covariances[0]
    wrong = (np.eye(2) - res.gains[0] @ C) @ P
    assert np.max(np.abs(wrong - res.filtered_covariances[0])) > 0.05


# ---------------------------------------------------------------------------
# statistics
# ---------------------------------------------------------------------------
def _normalized_innovations(model, p, u, runs, seed, noise=None, method="auto"):
    gen = np.random.default_rng(seed)
    out = []
    for _ in range(runs):
        y = model.simulate(p, u, rng=gen).y  # x_0 ~ N(x0, P0)
        res = kalman_filter(model, p, u, y, noise=noise, method=method)
        chol = np.linalg.cholesky(res.innovation_covariances)
        out.append(np.linalg.solve(chol, res.innovations[..., None])[..., 0])
    return np.array(out)  # (runs, T, ny)


@pytest.mark.parametrize("method", METHODS)
def test_normalized_innovations_are_white_with_unit_variance(truncation_model, method):
    # Seeded Monte Carlo, 300 runs x 60 samples x 2 outputs of the model with S != 0.
    # Pooled over runs and t, each entry of E[e_t e_t^T] is estimated from M = 18000
    # products: standard error sqrt(2/M) = 0.011 on the diagonal, sqrt(1/M) = 0.0075
    # off it and at lags 1..5. Tolerance 4.5 standard errors (two-sided false-alarm
    # probability 7e-6 per entry), and the seed is fixed.
    model = truncation_model
    runs, T = 300, 60
    k = np.arange(T)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    e = _normalized_innovations(model, p, u, runs, seed=11, method=method)
    M = runs * T
    cov0 = np.einsum("rti,rtj->ij", e, e) / M
    np.testing.assert_allclose(np.diag(cov0), 1.0, atol=4.5 * np.sqrt(2 / M))
    assert abs(cov0[0, 1]) < 4.5 * np.sqrt(1 / M)
    assert np.max(np.abs(e.mean(axis=(0, 1)))) < 4.5 * np.sqrt(1 / M)
    for lag in range(1, 6):
        n = runs * (T - lag)
        c = np.einsum("rti,rtj->ij", e[:, lag:], e[:, :-lag]) / n
        assert np.max(np.abs(c)) < 4.5 * np.sqrt(1 / n), (lag, c)


@pytest.mark.parametrize("method", METHODS)
def test_whiteness_check_detects_a_filter_that_ignores_s(method):
    # the statistical test above can fail: a filter that assumes S = 0 on data
    # with strong cross-correlation leaves a lag-1 correlation
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    model = AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A={"1": [[0.8]], "p": [[0.1]]}, C=[[1.0]], Q=[[1.0]], R=[[1.0]], S=[[0.9]],
    )
    runs, T = 200, 60
    p = np.sin(0.25 * np.arange(T))[:, None]
    wrong = np.array([[1.0, 0.0], [0.0, 1.0]])
    e = _normalized_innovations(model, p, None, runs, seed=5, noise=wrong, method=method)
    n = runs * (T - 1)
    c1 = float(np.einsum("rt,rt->", e[:, 1:, 0], e[:, :-1, 0]) / n)
    assert abs(c1) > 4.5 * np.sqrt(1 / n)
    good = _normalized_innovations(model, p, None, runs, seed=5, method=method)
    c1 = float(np.einsum("rt,rt->", good[:, 1:, 0], good[:, :-1, 0]) / n)
    assert abs(c1) < 4.5 * np.sqrt(1 / n)


@pytest.mark.parametrize("method", METHODS)
def test_constant_scheduling_converges_to_the_dare_gain(rng, method):
    from scipy.linalg import solve_discrete_are

    model = random_system(rng, nx=3, ny=2, nu=1)
    p0 = np.array([0.4, 1.1])
    T = 400
    p = np.tile(p0, (T, 1))
    y = model.simulate(p, np.zeros((T, 1)), rng=rng).y
    res = kalman_filter(model, p, np.zeros((T, 1)), y, method=method)
    A, B, C, D, G, H = model.at(p0)
    Q, S, R = model.noise.Q, model.noise.S, model.noise.R
    P = solve_discrete_are(A.T, C.T, G @ Q @ G.T, H @ R @ H.T, s=G @ S @ H.T)
    Om = C @ P @ C.T + H @ R @ H.T
    K = (A @ P @ C.T + G @ S @ H.T) @ np.linalg.inv(Om)
    # The recursion converges like rho^(2t), rho the spectral radius of the
    # closed loop A - K C: after T = 400 steps that is below rounding. What is
    # left is the DARE's conditioning: a perturbation of size delta in one step
    # moves the fixed point by ~delta / (1 - rho^2) (the closed-loop Lyapunov
    # operator), and each step's rounding is amplified by cond(Omega). Both
    # scipy's Schur method and the recursion are backward stable, so they
    # differ by ~eps cond(Omega) / (1 - rho^2) of |P| (|K|), a few stages of
    # n = 2 n_x + n_y products; the scan adds its own bound.
    rho = max(abs(np.linalg.eigvals(A - K @ C)))
    assert rho ** (2 * T) < EPS
    amp = np.linalg.cond(Om) / (1 - rho**2)
    scan = scan_rtol(amplification(model, p, np.zeros((T, 1)), y), kappa=kappa_omega(res)) if method == "scan" else 0.0
    for got, want in ((res.predicted_covariances[-1], P), (res.gains[-1], K)):
        size = np.max(np.abs(want))
        np.testing.assert_allclose(got, want, rtol=0, atol=roundoff(size, 5, n=8, amp=amp) + scan * size)


# ---------------------------------------------------------------------------
# innovation-form simulator
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_innovation_simulator_is_inverted_by_the_filter(truncation_model, method):
    model = truncation_model
    T = 80
    p = np.sin(0.25 * np.arange(T))[:, None]
    u = np.cos(0.1 * np.arange(T))[:, None]
    sim = simulate_innovation_form(model, p, u, rng=3)
    res = kalman_filter(model, p, u, sim.y, method=method)
    if method == "sequential":
        # the simulator runs the filter's own Riccati sweep: the same gains, bit for bit
        np.testing.assert_array_equal(res.gains, sim.gains)
        scan = 0.0
    else:
        scan = scan_rtol(amplification(model, p, u, sim.y), kappa=kappa_omega(res))
        np.testing.assert_allclose(res.gains, sim.gains, rtol=0, atol=scan * np.max(np.abs(sim.gains)))
    # means: (4a) run forward by the simulator and by the filter from y, the same
    # sums in another order per step (|A||x| + |B||u| + |K||xi|, n = 4 products),
    # through T = 80 steps of the stable closed loop (no growth: at most T steps' worth)
    size = np.max(np.abs(sim.x)) + np.max(np.abs(u)) + np.max(np.abs(sim.gains)) * np.max(np.abs(sim.innovations))
    tol = roundoff(size, T, n=4) + scan * size
    np.testing.assert_allclose(res.innovations, sim.innovations, rtol=0, atol=tol)
    np.testing.assert_allclose(res.predicted_means[:T], sim.x, rtol=0, atol=tol)
    again = simulate_innovation_form(model, p, u, rng=3)
    np.testing.assert_array_equal(again.y, sim.y)


def test_innovation_simulator_has_the_distribution_of_the_general_model(rng):
    # Lemma 1: data from (4) and from (1) have the same Gaussian law. Compare the
    # sample covariance of the stacked outputs over N runs with the oracle's.
    # Each entry's standard error is at most sqrt((S_ii S_jj + S_ij^2)/N); tolerance
    # 5 standard errors.
    model = random_system(rng, nx=2, ny=1, nu=1)
    T, N = 5, 4000
    p = random_schedule(model, rng, T)
    u = rng.standard_normal((T, 1))
    gen = np.random.default_rng(99)
    Y = np.empty((N, T))
    for i in range(N):
        Y[i] = simulate_innovation_form(model, p, u, rng=gen).y[:, 0]
    orc = oracle(model, p, u)
    Ny = np.vstack(orc.Ny)
    S = Ny @ orc.Sz @ Ny.T
    d = np.sqrt(np.diag(S))
    se = np.sqrt((np.outer(d, d) ** 2 + S**2) / N)
    np.testing.assert_array_less(np.abs(np.cov(Y.T) - S), 5 * se)  # statistical: 5 standard errors, fixed seed
    np.testing.assert_array_less(np.abs(Y.mean(axis=0) - orc.mean_y[:, 0]), 5 * d / np.sqrt(N))


# ---------------------------------------------------------------------------
# the streaming protocol
# ---------------------------------------------------------------------------
def test_ports(truncation_model):
    kf = LPVKalmanFilter(truncation_model)
    assert isinstance(kf, StreamingEstimator)
    assert [(q.name, q.shape) for q in kf.input_ports] == [("p", (1,)), ("u", (1,)), ("y", (2,))]
    assert [(q.name, q.shape) for q in kf.output_ports] == [
        ("xhat", (2,)), ("P", (2, 2)), ("xpred", (2,)), ("Ppred", (2, 2)),
        ("yhat", (2,)), ("innovation", (2,)), ("K", (2, 2)), ("Omega", (2, 2)), ("loglik", ()),
    ]
    no_input = LPVKalmanFilter(random_system(np.random.default_rng(0), nu=0))
    assert [q.name for q in no_input.input_ports] == ["p", "y"]


def test_outputs_do_not_change_the_state(truncation_model, monkeypatch):
    calls = []
    original = streaming_module.kalman_step
    monkeypatch.setattr(streaming_module, "kalman_step", lambda *a, **k: calls.append(1) or original(*a, **k))
    kf = LPVKalmanFilter(truncation_model)
    sample = {"p": [0.3], "u": [1.0], "y": [0.2, -0.1]}
    before = kf.get_state()
    a = kf.outputs(sample)
    b = kf.outputs(sample)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    _assert_same_state(kf.get_state(), before)
    assert len(calls) == 1  # the second outputs() of the same sample reuses the first
    c = kf.step(sample)  # the FMU's outputs-then-doStep: step reuses the computed sample
    assert len(calls) == 1
    for k in a:
        np.testing.assert_array_equal(a[k], c[k])
    assert kf.t == 1
    # outputs() followed by step() with different inputs uses the new inputs
    kf2 = LPVKalmanFilter(truncation_model)
    kf2.outputs(sample)
    d = kf2.step({"p": [0.3], "u": [1.0], "y": [0.5, -0.1]})
    assert not np.allclose(d["xhat"], c["xhat"])


def test_process_and_peek_expose_the_gains(truncation_model):
    kf = LPVKalmanFilter(truncation_model)
    peek = kf.peek([0.2], [1.0], [0.1, 0.3])
    assert kf.t == 0
    step = kf.process([0.2], [1.0], [0.1, 0.3])
    np.testing.assert_array_equal(peek.K, step.K)
    np.testing.assert_array_equal(peek.Omega, step.Omega)
    assert step.L.shape == (2, 2) and step.next.t == 1
    assert kf.log_likelihood == step.log_likelihood  # 0 + the one term: exact


def test_state_round_trip(truncation_model, rng):
    model = truncation_model
    T = 30
    p = np.sin(0.25 * np.arange(T))[:, None]
    u = rng.standard_normal((T, 1))
    y = model.simulate(p, u, rng=rng).y
    kf = LPVKalmanFilter(model)
    for t in range(10):
        kf.step({"p": p[t], "u": u[t], "y": y[t]})
    saved = kf.get_state()
    first = [kf.step({"p": p[t], "u": u[t], "y": y[t]}) for t in range(10, T)]
    kf.reset()
    assert kf.t == 0 and kf.log_likelihood == 0.0
    kf.set_state(saved)
    second = [kf.step({"p": p[t], "u": u[t], "y": y[t]}) for t in range(10, T)]
    for a, b in zip(first, second, strict=True):
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
    assert kf.t == T
    saved["x"][0] = 123.0  # get_state returns copies
    assert kf.get_state()["x"][0] != 123.0


def test_set_state_rejects_bad_states(truncation_model):
    kf = LPVKalmanFilter(truncation_model)
    good = kf.get_state()
    with pytest.raises(DimensionError, match=r"state x has shape \(3,\); expected \(2,\)"):
        kf.set_state(good | {"x": np.zeros(3)})
    with pytest.raises(NotPositiveDefiniteError, match="state P is not positive semidefinite"):
        kf.set_state(good | {"P": -np.eye(2)})
    with pytest.raises(DimensionError, match="state is missing 'P'"):
        kf.set_state({k: v for k, v in good.items() if k != "P"})
    with pytest.raises(NonFiniteError, match="state x holds a non-finite value"):
        kf.set_state(good | {"x": np.array([np.nan, 0.0])})
    _assert_same_state(kf.get_state(), good)


def test_initial_state_overrides(truncation_model):
    x0 = np.array([1.0, -2.0])
    kf = LPVKalmanFilter(truncation_model, x0=x0, P0=0.5 * np.eye(2))
    np.testing.assert_array_equal(kf.state.x, x0)
    np.testing.assert_array_equal(kf.state.P, 0.5 * np.eye(2))
    default = LPVKalmanFilter(truncation_model)
    np.testing.assert_array_equal(default.state.P, truncation_model.P0)


# ---------------------------------------------------------------------------
# bad input: a typed error, and the state is not touched
# ---------------------------------------------------------------------------
def _assert_same_state(a, b):
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


GOOD = {"p": [0.3], "u": [1.0], "y": [0.2, -0.1]}


@pytest.mark.parametrize(
    ("bad", "error", "match"),
    [
        ({"y": [0.2, -0.1, 0.0]}, DimensionError, r"y has shape \(3,\); expected \(2,\)"),
        ({"p": [0.3, 0.1]}, DimensionError, r"p has shape \(2,\); expected \(1,\)"),
        ({"u": [[1.0]]}, DimensionError, r"u has shape \(1, 1\); expected \(1,\)"),
        ({"y": "abc"}, DimensionError, "y is not a numeric array"),
        ({"y": [np.nan, 0.0]}, NonFiniteError, r"y at t=3 holds a non-finite value \(nan\) at index \(0,\)"),
        ({"u": [np.inf]}, NonFiniteError, r"u at t=3 holds a non-finite value \(inf\)"),
        ({"p": [np.nan]}, NonFiniteError, "p at t=3 holds a non-finite value"),
        ({"p": [1.5]}, SchedulingRangeError,
         r"scheduling value at t=3: p = 1.5 is outside its declared range \[-1, 1\]"),
        ({"p": [-1.0000001]}, SchedulingRangeError, "outside its declared range"),
        ({"z": [1.0]}, DimensionError, "unknown input 'z'; the inputs are p, u, y"),
    ],
)
def test_bad_sample_raises_and_leaves_the_filter_unchanged(truncation_model, bad, error, match):
    kf = LPVKalmanFilter(truncation_model)
    ref = LPVKalmanFilter(truncation_model)
    for f in (kf, ref):
        for _ in range(3):
            f.step(GOOD)
    before = kf.get_state()
    for method in (kf.step, kf.outputs):
        with pytest.raises(error, match=match):
            method(GOOD | bad)
        _assert_same_state(kf.get_state(), before)
    a, b = kf.step(GOOD), ref.step(GOOD)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


def test_missing_input(truncation_model):
    kf = LPVKalmanFilter(truncation_model)
    with pytest.raises(DimensionError, match="input 'y' is missing; the inputs are p, u, y"):
        kf.step({"p": [0.0], "u": [0.0]})
    assert kf.t == 0


def _singular_model(ny):
    # C(p) = p C1, H(p) = p I: at p = 0, Omega_t = 0 whatever P is
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    return AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A=0.5 * np.eye(2), C={"p": np.ones((ny, 2))}, H={"p": np.eye(ny)},
        Q=np.eye(2), R=np.eye(ny), S=0.1 * np.ones((2, ny)), P0=np.eye(2),
    )


@pytest.mark.parametrize("ny", [1, 2, 4])  # scalar, small and LAPACK Cholesky paths
def test_singular_innovation_covariance_names_t(ny):
    model = _singular_model(ny)
    kf = LPVKalmanFilter(model)
    for _ in range(2):
        kf.step({"p": [0.5], "y": np.ones(ny)})
    before = kf.get_state()
    with pytest.raises(NumericalError, match="Omega_t is not positive definite at t=2"):
        kf.step({"p": [0.0], "y": np.ones(ny)})
    _assert_same_state(kf.get_state(), before)
    T = SCAN_MIN_SAMPLES + 10  # long enough for method="auto" to consider the scan
    p = np.full((T, 1), 0.5)
    p[3] = 0.0
    y = np.ones((T, ny))
    for method in ("sequential", "auto"):  # auto: H R H^T is singular, the scan does not apply
        with pytest.raises(NumericalError, match="Omega_t is not positive definite at t=3"):
            kalman_filter(model, p, None, y, method=method)
    with pytest.raises(NumericalError, match=r"method='scan' needs H\(p\) R H\(p\)\^T positive definite .* "
                       r"it is not at t=3: use method='sequential' or 'auto'"):
        kalman_filter(model, p, None, y, method="scan")


@pytest.mark.parametrize("method", METHODS)
def test_non_positive_definite_noise_covariance(truncation_model, method):
    joint = truncation_model.noise.joint.copy()
    joint[0, 2] = joint[2, 0] = 1.0  # |S_11| > sqrt(Q_11 R_11): Sigma indefinite
    msg = r"the joint noise covariance Sigma = \[\[Q, S\], \[S\^T, R\]\] is not positive definite"
    with pytest.raises(NotPositiveDefiniteError, match=msg):
        LPVKalmanFilter(truncation_model, noise=joint)
    p = np.zeros((3, 1))
    with pytest.raises(NotPositiveDefiniteError, match="the joint noise covariance"):
        kalman_filter(truncation_model, p, np.zeros((3, 1)), np.zeros((3, 2)), noise=joint, method=method)
    with pytest.raises(DimensionError, match=r"noise covariance Sigma has shape \(3, 3\); expected \(4, 4\)"):
        LPVKalmanFilter(truncation_model, noise=np.eye(3))


def test_bad_initial_covariance_and_model(truncation_model):
    with pytest.raises(NotPositiveDefiniteError, match="P0 is not positive semidefinite"):
        LPVKalmanFilter(truncation_model, P0=np.diag([1.0, -1.0]))
    with pytest.raises(DimensionError, match=r"x0 has shape \(3,\); expected \(2,\)"):
        LPVKalmanFilter(truncation_model, x0=np.zeros(3))
    with pytest.raises(TypeError, match="needs an AffineLPV model, not InnovationLPV"):
        LPVKalmanFilter(load_system("cox-toth-ex1").model("minimal"))


@pytest.mark.parametrize("method", METHODS)
def test_batch_bad_input(truncation_model, method):
    T = 6
    p = np.zeros((T, 1))
    u = np.zeros((T, 1))
    y = np.zeros((T, 2))
    with pytest.raises(DimensionError, match=r"y has shape \(6, 3\); expected \(6, 2\)"):
        kalman_filter(truncation_model, p, u, np.zeros((T, 3)), method=method)
    with pytest.raises(DimensionError, match=r"u has shape \(5, 1\); expected \(6, 1\)"):
        kalman_filter(truncation_model, p, u[:5], y, method=method)
    bad = y.copy()
    bad[4, 1] = np.inf
    with pytest.raises(NonFiniteError, match=r"y holds a non-finite value \(inf\) at index \(4, 1\)"):
        kalman_filter(truncation_model, p, u, bad, method=method)
    pb = p.copy()
    pb[2] = 3.0
    with pytest.raises(SchedulingRangeError, match="scheduling value at t=2: p = 3 is outside"):
        kalman_filter(truncation_model, pb, u, y, method=method)


def test_kalman_step_is_pure(truncation_model):
    km = KalmanModel(truncation_model)
    s0 = KalmanState(truncation_model.x0.copy(), truncation_model.P0.copy())
    sm = km.step_matrices([0.1])
    F = sm.F.copy()
    a = kalman_step(s0, sm, np.ones(1), np.ones(2))
    b = kalman_step(s0, sm, np.ones(1), np.ones(2))
    np.testing.assert_array_equal(a.next.P, b.next.P)
    np.testing.assert_array_equal(sm.F, F)
    np.testing.assert_array_equal(s0.P, truncation_model.P0)


@pytest.mark.parametrize("module", ["_model", "_recursion", "_batch", "_streaming"])
def test_docstring_examples_run(module):
    failures, tried = doctest.testmod(getattr(kalman_package, module), optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0
