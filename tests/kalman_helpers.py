"""Random affine LPV systems and an independent Gaussian-conditioning oracle
for the Kalman filter tests."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from lpvest import AffineLPV, Monomial, SchedulingSpace
from lpvest.core._scheduling import parse_basis
from lpvest.estimators.kalman import KalmanModel
from lpvest.estimators.kalman._scan import MIN_BLOCK, decorrelate_stack, scan_amplification, scan_error_bound
from tests.tolerances import EPS


def amplification(model: AffineLPV, p: np.ndarray, u: np.ndarray | None, y: np.ndarray) -> float:
    """The scan's error amplification ``max_t ||J_t||_F ||C_t||_F`` on these data."""
    mats = KalmanModel(model).matrices_batch(p)
    u = np.zeros((p.shape[0], 0)) if u is None or not model.nu else u
    return scan_amplification(decorrelate_stack(*mats, u, y), mats.C)


def kappa_omega(res) -> float:
    """``max_t cond(Omega_t)`` of a KalmanResult: the conditioning of the filter
    problem (the gains are ``P C^T Omega^-1``)."""
    return float(np.max(np.linalg.cond(res.innovation_covariances))) if len(res.innovation_covariances) else 1.0


def scan_rtol(amp: float, block: int | None = None, kappa: float = 1.0) -> float:
    """How far the scan may be from the sequential recursion, relative to each
    output's largest entry (both are the same exact filter, rounded
    differently).

    Default blocks (``>= MIN_BLOCK`` samples, or the whole run): the library's
    documented bound ``100 eps (kappa + (1 + amp)^2)``, ``kappa`` =
    :func:`kappa_omega` (lpvest.estimators.kalman._scan, "Accuracy"; measured worst constant 15
    over T = 64 .. 1e5, amp up to 1e4, OpenBLAS Haswell, Sandybridge and
    Nehalem, by benchmarks/bench_scan_accuracy.py). Shorter blocks (1 = the
    plain scan): the general combinations work on single-sample elements and
    the error grows like ``eps amp^4`` (measured constant <= 8 for blocks 1
    and 2, T = 64 and 1024, amp 10 to 1e3): ``100 eps (1 + amp)^4``, plus the
    default bound.
    """
    bound = scan_error_bound(amp, kappa)
    if block is not None and block < MIN_BLOCK:
        bound += 100 * EPS * (1.0 + amp) ** 4
    return bound


def memory_steps(model: AffineLPV, p: np.ndarray, gains: np.ndarray, *, power: int = 2) -> float:
    """How many steps' worth of rounding a covariance (``power=2``) or mean
    (``power=1``) recursion along these gains accumulates: with
    ``q = max_t ||A_t - K_t C_t||_2 < 1`` an error made at one step shrinks by
    ``q^power`` per step afterwards, so all of them add up to at most
    ``1 / (1 - q^power)`` of one step's; without such a contraction the
    ``T`` steps (no growth assumed, the recursions are stable)."""
    mats = KalmanModel(model).matrices_batch(p)
    q = float(np.max(np.linalg.norm(mats.A - gains @ mats.C, ord=2, axis=(1, 2))))
    T = p.shape[0]
    return T if q >= 1.0 else min(T, 1.0 / (1.0 - q**power))


def kalman_fmu_tolerance(model: AffineLPV, p: np.ndarray, u: np.ndarray | None, y: np.ndarray, res) -> float:
    """How far a Kalman FMU's (streaming) filtered means may be from
    ``kalman_filter`` on the same data (``res``): the streaming kernel and the
    batch loop round differently (a few stages of n = 2 n_x + n_y products per
    step, amplified by cond(Omega), accumulated over :func:`memory_steps` of
    the closed loop), and the batch filter may run the scan
    (:func:`scan_rtol` at these data's amp); relative to the size of the
    means plus |K| |y| (what each step adds)."""
    from tests.tolerances import roundoff

    kap = float(np.max(np.linalg.cond(res.innovation_covariances)))
    size = float(np.max(np.abs(res.filtered_means))) + float(np.max(np.abs(res.gains))) * float(np.max(np.abs(y)))
    steps = memory_steps(model, p, res.gains, power=1)
    n = 2 * model.nx + model.ny
    return roundoff(size, 5 * steps, n=n, amp=kap) + scan_rtol(amplification(model, p, u, y), kappa=kap) * size


def oracle_rtol(kappa: float, amp: float | None = None, block: int | None = None) -> float:
    """How far a filter output may be from the Gaussian-conditioning oracle,
    relative to ``max(1, max |oracle value|)``.

    The oracle solves with the joint output covariance ``S_yy`` (``T n_y``
    square): its forward error is about ``eps cond(S_yy)`` (``kappa``) times
    the size of the result (Higham (7.2)). The sequential filter's own error
    is of the order of eps for these short stable runs. Together
    ``50 eps (kappa + 1)`` (measured: <= 1.6 eps (kappa + 1) on the 14 cases
    of test_kalman's oracle test). The scan (``amp`` given) adds its own
    bound against the sequential recursion, :func:`scan_rtol`, with
    ``kappa``: every ``Omega_t`` is a Schur complement of a leading block of
    ``S_yy``, so ``cond(Omega_t) <= cond(S_yy)``.
    """
    tol = 50 * EPS * (kappa + 1.0)
    if amp is not None:
        tol += scan_rtol(amp, block, kappa)
    return tol


def random_system(
    rng: np.random.Generator,
    *,
    nx: int = 3,
    ny: int = 2,
    nu: int = 1,
    nw: int | None = None,
    nv: int | None = None,
    P0_scale: float = 1.0,
    basis: str = "monomials",
) -> AffineLPV:
    """A random model with two scheduling variables and basis ``p1, p2, p1*p2``
    (``basis="monomials"``), ``p1, p2`` (``"components"``) or ``sin(p1),
    exp(p2)`` (``"formulas"``): every matrix, G and H included, depends on p;
    S != 0; Sigma and P0 positive definite; x0 != 0."""
    nw = nx if nw is None else nw
    nv = ny if nv is None else nv
    space = SchedulingSpace(["p1", "p2"], [-1.0, -0.5], [1.0, 2.0])
    if basis == "monomials":
        basis_fns = [Monomial.parse("p1", space), Monomial.parse("p2", space), Monomial.parse("p1*p2", space)]
    elif basis == "components":
        basis_fns = [Monomial.component(0, space), Monomial.component(1, space)]
    else:
        basis_fns = [parse_basis("sin(p1)", space), parse_basis("exp(-p2)", space)]
    basis = basis_fns

    def aff(r: int, c: int, s0: float, s1: float) -> dict[str, np.ndarray]:
        out = {"1": s0 * rng.standard_normal((r, c))}
        for b in basis:
            out[b.name] = s1 * rng.standard_normal((r, c))
        return out

    A = aff(nx, nx, 0.4, 0.1)
    F = rng.standard_normal((nw + nv, nw + nv))
    joint = F @ F.T + 0.5 * np.eye(nw + nv)
    Pf = rng.standard_normal((nx, nx))
    return AffineLPV.from_matrices(
        space,
        basis,
        A=A,
        B=aff(nx, nu, 1.0, 0.3),
        C=aff(ny, nx, 1.0, 0.3),
        D=aff(ny, nu, 0.5, 0.2),
        G=aff(nx, nw, 0.8, 0.2),
        H=aff(ny, nv, 0.8, 0.2),
        Q=joint[:nw, :nw],
        R=joint[nw:, nw:],
        S=joint[:nw, nw:],
        x0=rng.standard_normal(nx),
        P0=P0_scale * (Pf @ Pf.T + 0.2 * np.eye(nx)),
    )


def random_schedule(model: AffineLPV, rng: np.random.Generator, T: int) -> np.ndarray:
    return model.space.sample(rng, T)


class Oracle(NamedTuple):
    """Moments of the joint Gaussian of states and outputs, by brute force."""

    mean_x: np.ndarray  # (T + 1, nx)
    mean_y: np.ndarray  # (T, ny)
    Mx: list  # x_t = mean_x[t] + Mx[t] (z - mu_z): linear maps (nx, nz)
    Ny: list  # y_t = mean_y[t] + Ny[t] (z - mu_z): (ny, nz)
    Sz: np.ndarray  # covariance of z

    def _cond(self, rows: np.ndarray, mean: np.ndarray, y: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """E and Cov of (mean + rows (z - mu)) given y_0..y_{k-1}."""
        if k == 0:
            return mean, rows @ self.Sz @ rows.T
        Ny = np.vstack(self.Ny[:k])
        Syy = Ny @ self.Sz @ Ny.T
        Sxy = rows @ self.Sz @ Ny.T
        resid = (y[:k] - self.mean_y[:k]).reshape(-1)
        gain = np.linalg.solve(Syy, Sxy.T).T
        return mean + gain @ resid, rows @ self.Sz @ rows.T - gain @ Sxy.T

    def predicted(self, y: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
        """E and Cov of x_t given y_0..y_{t-1}."""
        return self._cond(self.Mx[t], self.mean_x[t], y, t)

    def filtered(self, y: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
        """E and Cov of x_t given y_0..y_t."""
        return self._cond(self.Mx[t], self.mean_x[t], y, t + 1)

    def output(self, y: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
        """E and Cov of y_t given y_0..y_{t-1} (Omega_t)."""
        return self._cond(self.Ny[t], self.mean_y[t], y, t)

    def gain(self, y: np.ndarray, t: int) -> np.ndarray:
        """K_t = Cov(x_{t+1}, y_t | y_0..y_{t-1}) Omega_t^-1."""
        rows = np.vstack([self.Mx[t + 1], self.Ny[t]])
        mean = np.concatenate([self.mean_x[t + 1], self.mean_y[t]])
        _, S = self._cond(rows, mean, y, t)
        nx = self.Mx[0].shape[0]
        return np.linalg.solve(S[nx:, nx:], S[nx:, :nx]).T

    def condition(self) -> float:
        """2-norm condition number of the joint output covariance ``S_yy``
        (every conditioning set of the oracle is a leading block of it, whose
        condition number is no larger: eigenvalue interlacing)."""
        Ny = np.vstack(self.Ny)
        return float(np.linalg.cond(Ny @ self.Sz @ Ny.T))

    def log_density(self, y: np.ndarray) -> float:
        Ny = np.vstack(self.Ny)
        S = Ny @ self.Sz @ Ny.T
        r = (y - self.mean_y).reshape(-1)
        sign, logdet = np.linalg.slogdet(S)
        assert sign > 0
        return float(-0.5 * (r.size * np.log(2 * np.pi) + logdet + r @ np.linalg.solve(S, r)))


def oracle(model: AffineLPV, p: np.ndarray, u: np.ndarray) -> Oracle:
    """Stack z = [x_0, w_0, v_0, ..., w_{T-1}, v_{T-1}] ~ N(mu_z, blockdiag(P0, Sigma, ...)),
    write every x_t and y_t as an affine function of z by running (1) on the
    matrices, never on the filter."""
    T = p.shape[0]
    nx, nw, nv = model.nx, model.nw, model.nv
    nz = nx + T * (nw + nv)
    Sz = np.zeros((nz, nz))
    Sz[:nx, :nx] = model.P0
    for t in range(T):
        a = nx + t * (nw + nv)
        Sz[a : a + nw + nv, a : a + nw + nv] = model.noise.joint
    M = np.zeros((nx, nz))
    M[:, :nx] = np.eye(nx)
    mx = model.x0.copy()
    mean_x, mean_y, Mx, Ny = [mx], [], [M], []
    for t in range(T):
        A, B, C, D, G, H = model.at(p[t])
        a = nx + t * (nw + nv)
        Ew = np.zeros((nw, nz))
        Ew[:, a : a + nw] = np.eye(nw)
        Ev = np.zeros((nv, nz))
        Ev[:, a + nw : a + nw + nv] = np.eye(nv)
        Ny.append(C @ M + H @ Ev)
        mean_y.append(C @ mx + D @ u[t])
        M = A @ M + G @ Ew
        mx = A @ mx + B @ u[t]
        Mx.append(M)
        mean_x.append(mx)
    return Oracle(np.array(mean_x), np.array(mean_y), Mx, Ny, Sz)
