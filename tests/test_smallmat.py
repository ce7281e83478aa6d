"""The one small-matrix kernel (lpvest/estimators/kalman/_smallmat.py), the one
decorrelation (kalman/_decorrelation.py) and the one innovation recursion
(systems/_innovation.py) against the copies they replaced (issue #22).

The replaced implementations are kept here, and only here, as oracles: where
the library promises the same numbers as before they are compared with
``np.array_equal``; where the order of a sum changed on purpose (the scan's
stacked factors for n_y >= 3) within a derived rounding bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lpvest import NotPositiveDefiniteError, NumericalError
from lpvest.core._linalg import mT
from lpvest.estimators import decorrelate
from lpvest.estimators.kalman import KalmanModel, covariance_step, simulate_innovation_form
from lpvest.estimators.kalman._decorrelation import decorrelate_matrices
from lpvest.estimators.kalman._model import KalmanMatrices
from lpvest.estimators.kalman._recursion import small_chol_inverse
from lpvest.estimators.kalman._scan import decorrelate_stack
from lpvest.estimators.kalman._smallmat import (
    SMALL_NY,
    SMALL_STACK,
    FactorError,
    chol_inverse,
    cholesky,
    lsolve,
    usolve,
)
from tests.kalman_helpers import random_schedule, random_system
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive


# ---------------------------------------------------------------------------
# the replaced implementations (oracles; the library no longer has them)
# ---------------------------------------------------------------------------
def old_small_chol_inverse(Omega: np.ndarray) -> tuple[np.ndarray, float]:
    """kalman/recursion.py before #22 (the error path is tested separately)."""
    a = Omega.tolist()
    m = len(a)
    L = [[0.0] * m for _ in range(m)]
    logdet = 0.0
    for i in range(m):
        Li = L[i]
        for j in range(i + 1):
            Lj = L[j]
            s = a[i][j]
            for k in range(j):
                s -= Li[k] * Lj[k]
            if i == j:
                assert 0.0 < s < math.inf
                Li[i] = math.sqrt(s)
                logdet += math.log(s)
            else:
                Li[j] = s / Lj[j]
    Ci = [[0.0] * m for _ in range(m)]
    for c in range(m):
        for i in range(c, m):
            Li = L[i]
            s = 1.0 if i == c else 0.0
            for k in range(c, i):
                s -= Li[k] * Ci[k][c]
            Ci[i][c] = s / Li[i]
    return np.array(Ci), logdet


def old_scan_chol(M: np.ndarray) -> np.ndarray:
    """kalman/scan.py ``_chol`` before #22 (positive definite input)."""
    m = M.shape[-1]
    if m == 1:
        return np.sqrt(M)
    if m > 4:
        return np.linalg.cholesky(M)
    L = np.zeros(M.shape)
    for j in range(m):
        Lj = L[..., j, :j]
        ljj = np.sqrt(M[..., j, j] - np.sum(Lj * Lj, axis=-1))
        L[..., j, j] = ljj
        for i in range(j + 1, m):
            L[..., i, j] = (M[..., i, j] - np.sum(L[..., i, :j] * Lj, axis=-1)) / ljj
    return L


def old_scan_lsolve(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    m = L.shape[-1]
    if m == 1:
        return B / L
    if m > 4:
        return np.linalg.solve(L, B)
    X = np.empty(B.shape)
    for i in range(m):
        v = B[..., i, :]
        if i:
            v = v - (L[..., i : i + 1, :i] @ X[..., :i, :])[..., 0, :]
        X[..., i, :] = v / L[..., i, i, None]
    return X


def old_scan_usolve(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    m = L.shape[-1]
    if m == 1:
        return B / L
    if m > 4:
        return np.linalg.solve(mT(L), B)
    X = np.empty(B.shape)
    for i in range(m - 1, -1, -1):
        v = B[..., i, :]
        if i < m - 1:
            v = v - (mT(L[..., i + 1 :, i : i + 1]) @ X[..., i + 1 :, :])[..., 0, :]
        X[..., i, :] = v / L[..., i, i, None]
    return X


def old_truncated_decorrelate(m: KalmanMatrices) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """estimators/truncated.py ``decorrelate`` before #22."""
    if m.HRH.ndim == 2 and m.HRH.shape[0] <= 3:
        Ci, _ = old_small_chol_inverse(m.HRH)
        J = (Ci @ m.GSH.T).T @ Ci
    else:
        L = np.linalg.cholesky(m.HRH)
        J = mT(np.linalg.solve(mT(L), np.linalg.solve(L, mT(m.GSH))))
    Abar = m.A - J @ m.C
    GQG = m.GQG - J @ mT(m.GSH)
    return Abar, 0.5 * (GQG + mT(GQG)), J


def old_simulate_innovation_form(km, p, u, rng):
    """estimators/kalman/batch.py ``simulate_innovation_form``'s loop before #22."""
    from lpvest.estimators.kalman._recursion import riccati_sweep

    n, m = km.nx, km.ny
    T = p.shape[0]
    x, P = km.model.x0.copy(), km.model.P0.copy()
    sms = km.step_matrices_batch(p)
    _, _, Om, Gm = riccati_sweep(km, sms, P)
    K = Gm[:, :n]
    xi = np.einsum("tij,tj->ti", np.linalg.cholesky(Om), np.random.default_rng(rng).standard_normal((T, m)))
    mats = sms.readable()
    X = np.empty((T, n))
    Y = np.empty((T, m))
    for t in range(T):
        X[t] = x
        Y[t] = mats.C[t] @ x + mats.D[t] @ u[t] + xi[t]
        x = mats.A[t] @ x + mats.B[t] @ u[t] + K[t] @ xi[t]
    return X, Y, xi, K, Om


def spd(rng: np.random.Generator, shape: tuple[int, ...], m: int) -> np.ndarray:
    """Random symmetric positive definite matrices, condition numbers up to ~1e3."""
    B = rng.standard_normal((*shape, m, m + 2))
    return B @ mT(B) + 1e-3 * np.eye(m)


# ---------------------------------------------------------------------------
# the kernel: the same numbers as the copies it replaced
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("m", range(1, SMALL_NY + 1))
def test_small_inverse_factor_is_the_old_one_to_the_bit(rng, m):
    for _ in range(200):
        Om = spd(rng, (), m)
        Ci, logdet = small_chol_inverse(Om, None)
        ref, ref_logdet = old_small_chol_inverse(Om)
        assert np.array_equal(Ci, ref) and Ci.flags.c_contiguous
        assert logdet == ref_logdet
        Ci2, logdet2 = chol_inverse(Om)
        assert np.array_equal(Ci2, ref) and logdet2 == ref_logdet


@pytest.mark.parametrize("m", range(1, SMALL_STACK + 1))
def test_a_matrix_gets_the_same_factor_alone_and_in_a_stack(rng, m):
    M = spd(rng, (7, 5), m)
    L = cholesky(M)
    Ci, logdet = chol_inverse(M)
    for idx in np.ndindex(7, 5):
        one = M[idx][None]  # a stack of one: the recurrence for every m <= SMALL_STACK
        assert np.array_equal(cholesky(one)[0], L[idx])
        assert np.array_equal(chol_inverse(one)[0][0], Ci[idx])
        if m <= SMALL_NY:  # one matrix: the same recurrence in Python floats
            assert np.array_equal(cholesky(M[idx]), L[idx])
            assert np.array_equal(chol_inverse(M[idx])[0], Ci[idx])
            assert math.isclose(chol_inverse(M[idx])[1], logdet[idx], rel_tol=0, abs_tol=roundoff(1.0, 1, n=m))
    B = rng.standard_normal((7, 5, m, 3))
    X = lsolve(L, B)
    for idx in np.ndindex(7, 5):
        assert np.array_equal(lsolve(L[idx][None], B[idx][None])[0], X[idx])


@pytest.mark.parametrize("m", [1, 2, 5, 6])
def test_the_scans_stacked_factors_and_solves_are_the_old_ones_to_the_bit(rng, m):
    # sizes where every sum has at most one term (m <= 2) or LAPACK runs (m > SMALL_STACK)
    M = spd(rng, (300,), m)
    B = rng.standard_normal((300, m, 4))
    L = cholesky(M)
    assert np.array_equal(L, old_scan_chol(M))
    assert np.array_equal(lsolve(L, B), old_scan_lsolve(L, B))
    assert np.array_equal(usolve(L, B), old_scan_usolve(L, B))


@pytest.mark.parametrize("m", [3, 4])
def test_the_scans_stacked_factors_now_sum_in_index_order(rng, m):
    # the old stacked kernel summed the products first (np.sum, or a small matrix
    # product), then subtracted; the kernel subtracts them one by one, like the
    # Python-float kernel: two backward-stable evaluations of each entry, at most
    # m products, of size |L| |L^T| (<= the diagonal of M) or |L| |X| + |B|
    M = spd(rng, (300,), m)
    B = rng.standard_normal((300, m, 4))
    L, Lo = cholesky(M), old_scan_chol(M)
    scale = np.sqrt(np.max(np.abs(M), axis=(1, 2)))[:, None, None]
    kap = float(np.max(np.linalg.cond(M)))
    assert np.all(np.abs(L - Lo) <= roundoff(1.0, 1, n=m, amp=math.sqrt(kap)) * scale)
    X, Xo = lsolve(L, B), old_scan_lsolve(L, B)
    Y, Yo = usolve(L, B), old_scan_usolve(L, B)
    kl = float(np.max(np.linalg.cond(L)))
    assert np.max(np.abs(X - Xo)) <= roundoff(np.max(np.abs(Xo)), 1, n=m, amp=kl)
    assert np.max(np.abs(Y - Yo)) <= roundoff(np.max(np.abs(Yo)), 1, n=m, amp=kl)
    assert not np.array_equal(L, Lo)  # the order did change somewhere


@pytest.mark.parametrize("m", range(1, 7))
def test_factors_and_solves_are_right(rng, m):
    # L L^T = M and L X = B, L^T Y = B: residuals of backward-stable algorithms,
    # at most m products per entry, of the size of |L| |L^T| or |L| |X|
    for M in (spd(rng, (), m), spd(rng, (40,), m)):
        L = cholesky(M)
        assert np.all(np.triu(L, 1) == 0)
        size = np.abs(L) @ np.abs(mT(L))
        assert np.all(np.abs(L @ mT(L) - M) <= roundoff(1.0, 1, n=m) * size)
        B = rng.standard_normal((*M.shape[:-1], 2))
        X, Y = lsolve(L, B), usolve(L, B)
        assert np.all(np.abs(L @ X - B) <= roundoff(1.0, 1, n=m) * (np.abs(L) @ np.abs(X)))
        assert np.all(np.abs(mT(L) @ Y - B) <= roundoff(1.0, 1, n=m) * (np.abs(mT(L)) @ np.abs(Y)))


@pytest.mark.parametrize("m", range(SMALL_NY + 1, 7))
def test_one_large_matrix_goes_to_lapack_unchanged(rng, m):
    M = spd(rng, (), m)
    B = rng.standard_normal((m, 3))
    L = cholesky(M)
    assert np.array_equal(L, np.linalg.cholesky(M))
    assert np.array_equal(lsolve(L, B), np.linalg.solve(L, B))
    assert np.array_equal(usolve(L, B), np.linalg.solve(L.T, B))
    assert np.array_equal(cholesky(M[None], lapack=True)[0], np.linalg.cholesky(M))


# ---------------------------------------------------------------------------
# the kernel: failures
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("m", range(1, 7))
@pytest.mark.parametrize("stacked", [False, True])
def test_not_positive_definite_raises_a_typed_error_naming_the_first(rng, m, stacked):
    bad = spd(rng, (), m)
    bad[m - 1, m - 1] = -1.0  # the last pivot fails
    nan = spd(rng, (), m)
    nan[m - 1, 0] = np.nan
    for wrong in (bad, nan, np.zeros((m, m))):
        if stacked:
            M = spd(rng, (6,), m)
            M[4] = wrong
            M[5] = wrong
        else:
            M = wrong
        with pytest.raises(FactorError, match="^the matrix is not positive definite") as info:
            cholesky(M)
        assert isinstance(info.value, NumericalError)
        assert info.value.index == (4 if stacked else -1)
        if stacked and m <= SMALL_STACK or not stacked and m <= SMALL_NY:
            assert info.value.pivot is not None and str(info.value).endswith(
                f"Cholesky pivot {info.value.pivot} is {info.value.value:.3g}")
            if wrong is bad:
                assert info.value.pivot == m and info.value.value < 0
            with pytest.raises(FactorError, match=f"Cholesky pivot {info.value.pivot} is"):
                chol_inverse(M)
        else:
            assert info.value.pivot is None


def test_the_omega_message_is_unchanged():
    with pytest.raises(NumericalError, match=r"^the innovation covariance Omega_t is not positive definite "
                                             r"at t=7: Cholesky pivot 2 is -3$"):
        small_chol_inverse(np.array([[1.0, 2.0], [2.0, 1.0]]), 7)
    with pytest.raises(NumericalError, match=r"^the innovation covariance Omega_t is not positive definite: "
                                             r"Cholesky pivot 1 is nan$"):
        small_chol_inverse(np.array([[np.nan]]), None)


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5])
def test_a_singular_innovation_covariance_names_t_in_the_covariance_step(m):
    rng = np.random.default_rng(m)
    km = KalmanModel(random_system(rng, nx=2, ny=m, nu=1, nv=m))
    sm = km.step_matrices(np.zeros(km.n_p))
    F = sm.F.copy()
    F[4:, 2 + 1 + 4:] = 0.0  # H R H^T = 0 (rows 2 n_x on, columns n_x + n_u + 2 n_x on); P = 0: Omega_t = 0
    bad = type(sm)(F, sm.nx, sm.nu, sm.ny)
    detail = "Omega_t = 0" if m == 1 else ("Cholesky pivot 1 is 0" if m <= SMALL_NY else "smallest eigenvalue 0")
    with pytest.raises(NumericalError, match=f"Omega_t is not positive definite at t=3: {detail}"):
        covariance_step(np.zeros((2, 2)), bad, t=3)
    with pytest.raises(NumericalError, match="Omega_t is not positive definite at t=3: in stack element 1"):
        covariance_step(np.zeros((3, 2, 2)), type(sm)(np.stack([sm.F, F, F]), sm.nx, sm.nu, sm.ny), t=3)


# ---------------------------------------------------------------------------
# the decorrelation, written once
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("ny", range(1, 6))
def test_the_decorrelation_is_the_truncated_filters_old_one_to_the_bit(ny):
    rng = np.random.default_rng(40 + ny)
    model = random_system(rng, nx=3, ny=ny, nu=1, nv=ny + 1, nw=2)
    km = KalmanModel(model)
    p = random_schedule(model, rng, 30)
    stack = km.matrices_batch(p)
    assert all(np.array_equal(a, b) for a, b in zip(decorrelate(stack), old_truncated_decorrelate(stack), strict=True))
    for t in range(30):
        one = km.matrices(p[t])
        assert all(np.array_equal(a, b) for a, b in zip(decorrelate(one), old_truncated_decorrelate(one),
                                                         strict=True))


@pytest.mark.parametrize("ny", range(1, SMALL_NY + 1))
def test_the_scans_decorrelation_gives_each_sample_its_own_numbers(ny):
    # recurrence=True (the scan) factors the stack entry by entry: every sample
    # gets exactly what the streaming truncated filter computes for it alone
    rng = np.random.default_rng(50 + ny)
    model = random_system(rng, nx=3, ny=ny, nu=1, nv=ny, nw=2)
    km = KalmanModel(model)
    p = random_schedule(model, rng, 40)
    s = km.matrices_batch(p)
    d = decorrelate_matrices(s.A, s.C, s.GQG, s.GSH, s.HRH, recurrence=True)
    u = rng.standard_normal((40, 1))
    y = rng.standard_normal((40, ny))
    dec = decorrelate_stack(*s, u, y)
    assert not isinstance(dec, int)
    for t in range(40):
        one = decorrelate(KalmanMatrices(*(a[t] for a in s)))  # sample t alone (the same matrices)
        assert all(np.array_equal(a[t], b) for a, b in zip(d, one, strict=True))
        assert np.array_equal(dec.AbarT[t], one.Abar.T) and np.array_equal(dec.J[t], one.J)
        assert np.array_equal(dec.c[t], one.J @ (y[t] - s.D[t] @ u[t]) + s.B[t] @ u[t])


@pytest.mark.parametrize("ny", [1, 2, 3, 4, 5])
def test_a_singular_h_r_h_is_refused_alike_everywhere(ny):
    rng = np.random.default_rng(60 + ny)
    model = random_system(rng, nx=2, ny=ny, nu=1, nv=ny)
    km = KalmanModel(model)
    p = random_schedule(model, rng, 12)
    s = km.matrices_batch(p)
    HRH = s.HRH.copy()
    HRH[[5, 9]] = 0.0
    s = s._replace(HRH=HRH)
    msg = r"^H\(p\) R H\(p\)\^T is singular at t=5: the decorrelated form \(5c\)/\(5e\) needs it invertible"
    one = KalmanMatrices(*(a[5] for a in s))
    for m in (one, s):
        with pytest.raises(NotPositiveDefiniteError, match=msg):
            decorrelate(m, where=" at t=5")
    assert decorrelate_stack(*s, np.zeros((12, 1)), np.zeros((12, ny))) == 5


def test_no_cross_covariance_is_no_correction(rng):
    model = random_system(rng, nx=3, ny=2, nu=1, nv=2)
    km = KalmanModel(model)
    s = km.matrices_batch(random_schedule(model, rng, 10))
    s = s._replace(GSH=np.zeros_like(s.GSH))
    for recurrence in (False, True):
        d = decorrelate_matrices(s.A, s.C, s.GQG, s.GSH, s.HRH, recurrence=recurrence)
        assert np.array_equal(d.Abar, s.A) and not np.any(d.J)
        assert np.array_equal(d.GQbarG, 0.5 * (s.GQG + mT(s.GQG)))


# ---------------------------------------------------------------------------
# the innovation recursion, written once
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("ny", [1, 2, 4])
def test_the_innovation_form_simulation_is_the_old_loop_to_the_bit(ny):
    rng = np.random.default_rng(70 + ny)
    model = random_system(rng, nx=3, ny=ny, nu=2, nv=ny)
    km = KalmanModel(model)
    p = random_schedule(model, rng, 60)
    u = rng.standard_normal((60, 2))
    got = simulate_innovation_form(km, p, u, rng=9)
    want = old_simulate_innovation_form(km, p, u, 9)
    assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
