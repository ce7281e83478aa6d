"""The parallel-in-time (blocked associative scan) evaluation of the exact
filter, kalman_filter(method="scan"), and the method="auto" dispatch: against
the Gaussian-conditioning oracle, against the sequential recursion on long
trajectories, the fallbacks, and the errors. (Every batch test of
tests/test_kalman.py also runs with method="scan".)"""

import dataclasses
import doctest
import warnings

import numpy as np
import pytest

from lpvest import AffineLPV, Monomial, NumericalError, SchedulingSpace, load_system
from lpvest.estimators.kalman import (
    SCAN_MAX_AMPLIFICATION,
    SCAN_MIN_SAMPLES,
    KalmanModel,
    ScanAccuracyWarning,
    _batch as batch_module,
    _scan as scan_module,
    kalman_filter,
)
from lpvest.estimators.kalman._scan import (
    MIN_BLOCK,
    block_length,
    decorrelate_stack,
    scan_error_bound,
)
from tests.kalman_helpers import (
    amplification,
    kappa_omega,
    oracle,
    oracle_rtol,
    random_schedule,
    random_system,
    scan_rtol,
)

pytestmark = pytest.mark.blas_sensitive

FIELDS = [
    "predicted_means", "predicted_covariances", "filtered_means", "filtered_covariances",
    "predicted_outputs", "innovations", "innovation_covariances", "gains", "filter_gains",
    "log_likelihood_terms",
]


def _close(actual, desired, rel):
    # rel relative to the size of the quantity (the random systems reach
    # covariances of ~1e3)
    np.testing.assert_allclose(actual, desired, rtol=0, atol=rel * max(1.0, float(np.max(np.abs(desired)))))


def _check_against_oracle(model, p, u, y, res, *, amp=None, block=None, times=None):
    """Every output against the oracle within oracle_rtol (kalman_helpers):
    eps cond(S_yy), plus for the scan (amp given) its bound eps (1 + amp)^2
    and the short-block term for blocks < MIN_BLOCK."""
    orc = oracle(model, p, u)
    rel = oracle_rtol(orc.condition(), amp, block)
    T = p.shape[0]
    times = range(T) if times is None else times
    for t in [*times, T]:
        m, S = orc.predicted(y, t)
        _close(res.predicted_means[t], m, rel)
        _close(res.predicted_covariances[t], S, rel)
    for t in times:
        m, S = orc.filtered(y, t)
        _close(res.filtered_means[t], m, rel)
        _close(res.filtered_covariances[t], S, rel)
        my, Om = orc.output(y, t)
        _close(res.predicted_outputs[t], my, rel)
        _close(res.innovation_covariances[t], Om, rel)
        _close(res.gains[t], orc.gain(y, t), rel)
        # L_t = Cov(x_t, y_t | past) Omega_t^-1 = P_{t|t-1} C^T Omega^-1
        C = model.at(p[t]).C
        L = np.linalg.solve(Om, C @ orc.predicted(y, t)[1]).T
        _close(res.filter_gains[t], L, rel)
    # a sum of T n_y log-variances and squared whitened residuals, each to rel of its size
    ll_scale = T * model.ny + float(np.sum(np.abs(res.log_likelihood_terms)))
    assert res.log_likelihood == pytest.approx(orc.log_density(y), abs=rel * ll_scale)


def _explicit_scan(model, p, u, y, amp, **kw):
    """kalman_filter(method="scan"), which warns exactly when amp is beyond the gate."""
    if amp > SCAN_MAX_AMPLIFICATION:
        with pytest.warns(ScanAccuracyWarning):
            return kalman_filter(model, p, u, y, method="scan", **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScanAccuracyWarning)
        return kalman_filter(model, p, u, y, method="scan", **kw)


def _max_rel(a, b):
    """max |a - b| / max |b| over every field of two KalmanResults."""
    return max(
        float(np.max(np.abs(getattr(a, f) - getattr(b, f))) / np.max(np.abs(getattr(b, f)))) for f in FIELDS
    )


# ---------------------------------------------------------------------------
# against the oracle, every block length (block 1 = the plain scan)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "dims",
    [
        {"nx": 3, "ny": 2, "nu": 1},  # manual 2x2 Cholesky
        {"nx": 2, "ny": 1, "nu": 2},  # scalar path
        {"nx": 3, "ny": 2, "nu": 0, "nw": 2, "nv": 3},  # G, H not square, no input
        {"nx": 4, "ny": 3, "nu": 1, "nw": 5, "nv": 3},
        {"nx": 3, "ny": 5, "nu": 1, "nw": 2, "nv": 6},  # n_y = 5: the LAPACK path
    ],
)
def _well_conditioned_case(seed, dims, T):
    """A random system, schedule and data where the scan applies
    (amplification <= SCAN_MAX_AMPLIFICATION): the random H(p) of
    random_system is close to singular somewhere about one time in five,
    and that regime (where method="auto" runs the sequential recursion) is
    tested separately below. Deterministic: the first of seeds seed,
    seed + 100, ... that qualifies."""
    for k in range(20):
        rng = np.random.default_rng(seed + 100 * k)
        model = random_system(rng, **dims)
        p = random_schedule(model, rng, T)
        u = rng.standard_normal((T, model.nu))
        y = model.simulate(p, u, rng=rng).y
        if amplification(model, p, u, y) <= SCAN_MAX_AMPLIFICATION:
            return model, p, u, y
    raise AssertionError("no well-conditioned case found")


@pytest.mark.parametrize(
    "dims",
    [
        {"nx": 3, "ny": 2, "nu": 1},  # manual 2x2 Cholesky
        {"nx": 2, "ny": 1, "nu": 2},  # scalar path
        {"nx": 3, "ny": 2, "nu": 0, "nw": 2, "nv": 3},  # G, H not square, no input
        {"nx": 4, "ny": 3, "nu": 1, "nw": 5, "nv": 3},
        {"nx": 3, "ny": 5, "nu": 1, "nw": 2, "nv": 6},  # n_y = 5: the LAPACK path
    ],
)
@pytest.mark.parametrize("block", [1, 2, 3, 5, 13])
def test_scan_matches_gaussian_conditioning_for_every_block_length(dims, block, monkeypatch):
    # T = 13 cut into blocks of 1, 2, 3, 5 (last block short) and 13 (one block)
    monkeypatch.setattr(scan_module, "block_length", lambda T, nx: block)
    T = 13
    model, p, u, y = _well_conditioned_case(2000 + block, dims, T)
    amp = amplification(model, p, u, y)
    res = kalman_filter(model, p, u if model.nu else None, y, method="scan")
    _check_against_oracle(model, p, u, y, res, amp=amp, block=block)
    seq = kalman_filter(model, p, u if model.nu else None, y, method="sequential")
    _check_against_oracle(model, p, u, y, seq)  # the same standard for the sequential recursion
    assert _max_rel(res, seq) <= scan_rtol(amp, block, kappa_omega(seq))


@pytest.mark.parametrize("P0_kind", ["zero", "rank one"])
@pytest.mark.parametrize("block", [1, 4])
def test_scan_with_given_x0_and_singular_P0(P0_kind, block, monkeypatch):
    # the scan's first element never inverts P0: a zero or singular P0 is fine
    monkeypatch.setattr(scan_module, "block_length", lambda T, nx: block)
    rng = np.random.default_rng(7)
    model = random_system(rng, nx=3, ny=2, nu=1)
    v = rng.standard_normal(3)
    P0 = np.zeros((3, 3)) if P0_kind == "zero" else 2.0 * np.outer(v, v)
    x0 = np.array([1.0, -2.0, 0.5])
    given = dataclasses.replace(model, x0=x0, P0=P0)  # the oracle reads x0, P0 from the model
    T = 11
    p = random_schedule(model, rng, T)
    u = rng.standard_normal((T, 1))
    y = given.simulate(p, u, rng=rng).y
    amp = amplification(model, p, u, y)
    res = _explicit_scan(model, p, u, y, amp, x0=x0, P0=P0)
    _check_against_oracle(given, p, u, y, res, amp=amp, block=block)
    if P0_kind == "zero":
        np.testing.assert_array_equal(res.predicted_covariances[0], 0.0)
        np.testing.assert_allclose(res.filtered_means[0], x0, atol=0)  # y_0 says nothing new about x_0


def test_auto_on_a_long_trajectory_matches_the_oracle(spy):
    # T >= SCAN_MIN_SAMPLES: auto takes the scan, with the default block length;
    # against the oracle at some samples (it conditions on up to 140 outputs)
    T = SCAN_MIN_SAMPLES + 6
    model, p, u, y = _well_conditioned_case(77, {"nx": 2, "ny": 2, "nu": 1, "nv": 2}, T)
    res = kalman_filter(model, p, u, y)
    assert spy == [1]
    amp = amplification(model, p, u, y)
    _check_against_oracle(model, p, u, y, res, amp=amp, times=[0, 1, 2, 17, 31, 52, T - 2, T - 1])


# ---------------------------------------------------------------------------
# long trajectories: no loss of accuracy against the sequential recursion
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["cox-toth-truncation", "random"])
def test_long_trajectory_scan_equals_sequential(case):
    # T = 5000 with S != 0. The two algorithms round differently; they agree
    # within the scan's documented bound scan_rtol(amp) (default blocks) and
    # the short-block bound for the plain scan.
    T = 5000
    k = np.arange(T)
    if case == "random":
        rng = np.random.default_rng(3)
        model = random_system(rng, nx=3, ny=2, nu=0, nw=2, nv=3)
        p = random_schedule(model, rng, T)
        u = None
    else:
        model = load_system("cox-toth-truncation").model()
        p = np.sin(0.25 * k)[:, None]
        u = np.sin(0.1 * k)[:, None]
    y = model.simulate(p, u, rng=11).y
    amp = amplification(model, p, u, y)  # 0.06 and 56 (beyond the gate: method="scan" warns)
    scan = _explicit_scan(model, p, u, y, amp)
    seq = kalman_filter(model, p, u, y, method="sequential")
    rel = scan_rtol(amp, kappa=kappa_omega(seq))
    assert _max_rel(scan, seq) <= rel
    # the sum of T terms, each within rel of the largest term
    assert scan.log_likelihood == pytest.approx(
        seq.log_likelihood, abs=T * rel * float(np.max(np.abs(seq.log_likelihood_terms)))
    )
    # and the plain scan (block 1, 2 log2 T levels) as well
    km = KalmanModel(model)
    mats = km.matrices_batch(p)
    dec = decorrelate_stack(*mats, np.zeros((T, 0)) if u is None else u, y)
    plain = scan_module.scan_filter(dec, mats.C, mats.HRH, model.x0, model.P0, block=1)
    rel = scan_rtol(amp, block=1, kappa=kappa_omega(seq))
    assert np.max(np.abs(plain.Pp - seq.predicted_covariances)) <= rel * np.max(np.abs(seq.predicted_covariances))
    assert np.max(np.abs(plain.xp - seq.predicted_means)) <= rel * np.max(np.abs(seq.predicted_means))


# ---------------------------------------------------------------------------
# method="auto": which algorithm runs
# ---------------------------------------------------------------------------
@pytest.fixture
def spy(monkeypatch):
    calls = []
    original = batch_module.scan_filter
    monkeypatch.setattr(batch_module, "scan_filter", lambda *a, **k: calls.append(1) or original(*a, **k))
    return calls


def test_auto_dispatch(truncation_model_data, spy):
    model, p, u, y = truncation_model_data
    short = SCAN_MIN_SAMPLES - 1
    res = kalman_filter(model, p[:short], u[:short], y[:short])
    assert spy == []  # too short: the sequential recursion, bit for bit
    seq = kalman_filter(model, p[:short], u[:short], y[:short], method="sequential")
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(res, f), getattr(seq, f))
    kalman_filter(model, p[: short + 1], u[: short + 1], y[: short + 1])
    assert spy == [1]
    kalman_filter(model, p[:5], u[:5], y[:5], method="scan")  # explicit: whatever the length
    assert spy == [1, 1]
    kalman_filter(model, p, u, y, method="sequential")
    assert spy == [1, 1]


@pytest.fixture(scope="module")
def truncation_model_data():
    model = load_system("cox-toth-truncation").model()
    T = 2 * SCAN_MIN_SAMPLES
    k = np.arange(T)
    p = np.sin(0.25 * k)[:, None]
    u = np.sin(0.1 * k)[:, None]
    return model, p, u, model.simulate(p, u, rng=5).y


def _vanishing_h_model():
    # H(p) = p I: H R H^T = 0 at p = 0, while C P C^T > 0 keeps Omega_t positive definite
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    return AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A=[[0.7, 0.2], [-0.1, 0.5]], C=[[1.0, 0.5], [0.0, 1.0]], H={"p": np.eye(2)},
        Q=np.eye(2), R=0.5 * np.eye(2), S=0.2 * np.eye(2), P0=np.eye(2),
    )


def test_auto_falls_back_when_h_r_h_is_singular(spy):
    model = _vanishing_h_model()
    T = 90
    p = 0.5 + 0.4 * np.sin(0.3 * np.arange(T))[:, None]  # |J| = 0.4 / p <= 4 ...
    p[40] = 0.0  # ... but at t = 40 H R H^T = 0
    y = model.simulate(p, None, rng=2).y
    res = kalman_filter(model, p, None, y)
    assert spy == []  # the decorrelation does not exist at t = 40
    seq = kalman_filter(model, p, None, y, method="sequential")
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(res, f), getattr(seq, f))
    assert np.all(np.linalg.eigvalsh(res.innovation_covariances[40]) > 0.1)  # the filter itself is fine
    with pytest.raises(NumericalError, match=r"method='scan' needs H\(p\) R H\(p\)\^T positive definite .* at t=40"):
        kalman_filter(model, p, None, y, method="scan")
    # without the zero the scan runs and agrees
    p[40] = 0.3
    y = model.simulate(p, None, rng=2).y
    amp = amplification(model, p, None, y)
    seq = kalman_filter(model, p, None, y, method="sequential")
    assert _max_rel(kalman_filter(model, p, None, y), seq) <= scan_rtol(amp, kappa=kappa_omega(seq))
    assert spy == [1]


def _near_singular_noise_model(r):
    # scalar output with measurement noise variance r^2 and S close to sqrt(Q R):
    # J = G S H^T (H R H^T)^-1 ~ 1/r, the decorrelated form amplifies rounding errors
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    q = np.diag([1.0, 0.5])
    s = 0.9 * np.array([[1.0], [0.0]]) * r
    return AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A={"1": [[0.6, 0.3], [-0.2, 0.5]], "p": [[0.1, 0.0], [0.0, 0.1]]}, C=[[1.0, 0.4]],
        Q=q, R=[[r * r]], S=s, P0=np.eye(2),
    )


def test_auto_falls_back_when_the_error_amplification_is_large(spy):
    T = 400
    p = np.sin(0.25 * np.arange(T))[:, None]
    model = _near_singular_noise_model(3e-3)
    y = model.simulate(p, None, rng=4).y
    amp = amplification(model, p, None, y)
    assert amp > SCAN_MAX_AMPLIFICATION
    res = kalman_filter(model, p, None, y)
    assert spy == []
    seq = kalman_filter(model, p, None, y, method="sequential")
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(res, f), getattr(seq, f))
    # explicitly asked for, the scan still runs, with a warning that gives the
    # reason and the bound; its error grows like eps * amp^2 (module notes):
    # here amp = 320, within the documented bound
    with pytest.warns(ScanAccuracyWarning, match=r"amp = max_t \|\|J_t\|\| \|\|C_t\|\| = 32\d > 30 .* up to ~2e-09"):
        scan = kalman_filter(model, p, None, y, method="scan")
    assert spy == [1]
    assert _max_rel(scan, seq) <= scan_rtol(amp, kappa=kappa_omega(seq))
    # a well-conditioned version of the same model: auto takes the scan
    model = _near_singular_noise_model(0.5)
    y = model.simulate(p, None, rng=4).y
    kalman_filter(model, p, None, y)
    assert spy == [1, 1]


@pytest.mark.parametrize(("r", "admitted"), [(0.04, True), (0.025, False)])
def test_auto_gate_is_the_documented_amplification(spy, r, admitted):
    # amp ~ 0.97 / r: 24 just inside SCAN_MAX_AMPLIFICATION = 30, 39 just outside
    T = 200
    p = np.sin(0.25 * np.arange(T))[:, None]
    model = _near_singular_noise_model(r)
    y = model.simulate(p, None, rng=4).y
    amp = amplification(model, p, None, y)
    assert (amp <= SCAN_MAX_AMPLIFICATION) == admitted
    kalman_filter(model, p, None, y)
    assert spy == ([1] if admitted else [])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        kalman_filter(model, p, None, y, method="scan")
    assert [w.category for w in caught] == ([] if admitted else [ScanAccuracyWarning])


@pytest.mark.parametrize("T", [64, 1000, 20000])
@pytest.mark.parametrize("r", [1.0, 0.1, 0.03, 3e-3])
def test_scan_error_within_the_documented_bound(T, r):
    # The scan's documented accuracy (kalman_scan, "Accuracy"): within
    # scan_error_bound(amp, kappa) = 100 eps (kappa + (1 + amp)^2) of the sequential recursion
    # (n_y = 1: kappa = cond(Omega_t) = 1),
    # relative to each output's size, at every T (the worst case is at small
    # T: before MIN_BLOCK, T = 64 ran the plain scan, whose error grows like
    # eps amp^4: 1.5e-8 here at amp = 320, against the bound's 2.3e-9).
    # amp ~ 1, 10, 32, 320.
    p = np.sin(0.25 * np.arange(T))[:, None]
    model = _near_singular_noise_model(r)
    y = model.simulate(p, None, rng=T).y
    amp = amplification(model, p, None, y)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ScanAccuracyWarning)  # r = 3e-3: beyond the gate
        scan = kalman_filter(model, p, None, y, method="scan")
    seq = kalman_filter(model, p, None, y, method="sequential")
    assert _max_rel(scan, seq) <= scan_error_bound(amp, kappa_omega(seq))


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("method", "error", "match"),
    [
        ("fast", ValueError, r"method must be one of 'auto', 'scan', 'sequential'; found 'fast'"),
        ("Scan", ValueError, "found 'Scan'"),
        (None, TypeError, "method must be a string"),
        (1, TypeError, "found 1"),
    ],
)
def test_method_validation(truncation_model_data, method, error, match):
    model, p, u, y = truncation_model_data
    with pytest.raises(error, match=match):
        kalman_filter(model, p, u, y, method=method)


@pytest.mark.parametrize("method", ["sequential", "scan"])
def test_overflow_names_the_sample(method):
    # C(p) = 1e160 p: at the one sample with p != 0, C P C^T overflows
    space = SchedulingSpace(["p"], [-1.0], [1.0])
    model = AffineLPV.from_matrices(
        space, [Monomial.component(0, space)],
        A=0.5 * np.eye(2), C={"1": [[1.0, 0.0]], "p": [[1e160, 1e160]]}, Q=np.eye(2), R=[[1.0]], P0=np.eye(2),
    )
    T = 80
    p = np.zeros((T, 1))
    p[37] = 1.0
    y = np.zeros((T, 1))
    with np.errstate(all="ignore"), pytest.raises(NumericalError, match="not positive definite at t=37"):
        kalman_filter(model, p, None, y, method=method)


def test_block_length_rule():
    assert block_length(1, 2) == 1
    assert block_length(64, 2) == MIN_BLOCK  # never the plain scan's amp^4 error when T allows
    assert block_length(2000, 2) < block_length(2000, 10) < block_length(20000, 10)
    assert all(1 <= block_length(T, n) <= T for T in (1, 5, 64, 5000) for n in (1, 4, 30))


def test_docstring_examples_run():
    failures, tried = doctest.testmod(scan_module, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0
