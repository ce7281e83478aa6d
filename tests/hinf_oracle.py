"""Independent oracles for the H-infinity tests.

Written from the paper's equations (001_00f62b5a0c49ad87.txt), not from
``lpvest.design``: the augmented system (3), the exact finite-horizon
worst-case gain of the lifted (block lower-triangular) map ``w -> e`` for a
fixed parameter sequence, the dissipation inequality of the proof, the Finsler
form ``Q + He{X G}`` and the printed blocks of ``Phi``.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np


# ---------------------------------------------------------------------------
# closed loop
# ---------------------------------------------------------------------------
def augmented(plant, design, alpha):
    """``(A, B, C, D)`` of the augmented system (3) at ``alpha`` (eq. (3))."""
    alpha = np.asarray(alpha, dtype=float)
    A, Bw, Cz, Dz, Cy, Dy = (np.tensordot(alpha, v, axes=1) for v in plant.vertices)
    if design.scheduled:
        H, Af, Bf, Cf, Df = (np.tensordot(alpha, getattr(design, n), axes=1) for n in ("H", "Af", "Bf", "Cf", "Df"))
    else:
        H, Af, Bf, Cf, Df = (getattr(design, n)[0] for n in ("H", "Af", "Bf", "Cf", "Df"))
    HiBf = np.linalg.solve(H, Bf)
    HiAf = np.linalg.solve(H, Af)
    nx = A.shape[0]
    Aa = np.block([[A, np.zeros((nx, HiAf.shape[0]))], [HiBf @ Cy, HiAf]])
    Ba = np.vstack([Bw, HiBf @ Dy])
    Ca = np.hstack([Cz - Df @ Cy, -Cf])
    Da = Dz - Df @ Dy
    return Aa, Ba, Ca, Da


def simulate_error(plant, design, alphas, w):
    """``e_k`` of (3) from ``xi_0 = 0``; ``alphas`` (T, N), ``w`` (T, nw)."""
    n = 2 * plant.nx
    xi = np.zeros(n)
    out = []
    for a, wk in zip(alphas, w, strict=True):
        A, B, C, D = augmented(plant, design, a)
        out.append(C @ xi + D @ wk)
        xi = A @ xi + B @ wk
    return np.array(out)


def lifted_gain(systems: Sequence[tuple[np.ndarray, ...]]) -> float:
    """Largest singular value of the lifted map ``(w_0..w_{T-1}) -> (e_0..e_{T-1})``
    of the time-varying system ``systems[k] = (A_k, B_k, C_k, D_k)`` from zero
    state: the exact worst case over disturbances on this horizon, hence a
    lower bound of the l2-induced gain of (3) for this parameter sequence."""
    T = len(systems)
    n, nw = systems[0][1].shape
    nz = systems[0][2].shape[0]
    M = np.zeros((T * nz, T * nw))
    S = np.zeros((n, T * nw))  # state response to every input sample so far
    for k, (A, B, C, D) in enumerate(systems):
        M[k * nz:(k + 1) * nz] = C @ S
        M[k * nz:(k + 1) * nz, k * nw:(k + 1) * nw] += D
        S = A @ S
        S[:, k * nw:(k + 1) * nw] += B
    return float(np.linalg.norm(M, 2))


def simplex_grid(n: int, steps: int) -> np.ndarray:
    """Every point of the simplex in R^n with coordinates in multiples of 1/steps."""
    pts = [np.array(c) / steps for c in itertools.product(range(steps + 1), repeat=n) if sum(c) == steps]
    return np.array(pts)


def worst_case_gain(plant, design, rng, *, horizon: int = 80, max_period: int | None = None, n_random: int = 20):
    """Search for the worst l2 gain of (3): frozen alpha on a simplex grid,
    every periodic vertex-switching word up to ``max_period`` (default 5 for
    two vertices, 3 for more: about 60 words), random vertex switching and
    random alpha sequences. Returns ``(gain, description)``."""
    N = plant.n_vertices
    if max_period is None:
        max_period = 5 if N == 2 else 3
    best, where = 0.0, ""
    vertex_sys = [augmented(plant, design, e) for e in np.eye(N)]

    def consider(g: float, what: str) -> None:
        nonlocal best, where
        if g > best:
            best, where = g, what

    for a in simplex_grid(N, 10 if N == 2 else 4):
        s = augmented(plant, design, a)
        consider(lifted_gain([s] * (2 * horizon)), f"frozen alpha {a}")
    for period in range(1, max_period + 1):
        for word in itertools.product(range(N), repeat=period):
            seq = [vertex_sys[i] for i in word] * (horizon // period + 1)
            consider(lifted_gain(seq[:horizon]), f"periodic switching {word}")
    for r in range(n_random):
        idx = rng.integers(0, N, size=horizon)
        consider(lifted_gain([vertex_sys[i] for i in idx]), f"random switching #{r}")
        alphas = rng.dirichlet(np.ones(N), size=horizon)
        consider(lifted_gain([augmented(plant, design, a) for a in alphas]), f"random alpha #{r}")
    return best, where


def dissipation_max_eig(plant, design, alpha, alpha_next) -> float:
    """Largest eigenvalue of the quadratic form of
    ``V(xi_{k+1}) - V(xi_k) + e'e - gamma^2 w'w`` in ``(xi_k, w_k)``, with
    ``V = xi' P(alpha) xi`` and the design's Lyapunov matrices."""
    A, B, C, D = augmented(plant, design, alpha)
    P = np.tensordot(np.asarray(alpha, dtype=float), design.lyapunov, axes=1)
    Pn = np.tensordot(np.asarray(alpha_next, dtype=float), design.lyapunov, axes=1)
    AB = np.hstack([A, B])
    CD = np.hstack([C, D])
    nw = B.shape[1]
    M = AB.T @ Pn @ AB + CD.T @ CD
    M[: A.shape[0], : A.shape[0]] -= P
    M[A.shape[0]:, A.shape[0]:] -= design.gamma**2 * np.eye(nw)
    return float(np.max(np.linalg.eigvalsh(0.5 * (M + M.T))))


# ---------------------------------------------------------------------------
# the LMI blocks, two independent ways
# ---------------------------------------------------------------------------
def finsler_phi(d, v, Pn, Pc, delta, a, b):
    """``Phi_ijl = Q + X G + (X G)^T`` built from the proof's matrices.

    ``d``: plant vertex i (A, Bw, Cz, Dz, Cy, Dy); ``v``: variables of vertex j
    (X1..X6, H, Af, Bf, Cf, Df); ``Pn = (P1, P2, P3)`` at alpha_{k+1} (vertex l),
    ``Pc`` at alpha_k (vertex j); multiplier column ``(a, 1, b)``.
    """
    A, Bw, Cz, Dz, Cy, Dy = (d[k] for k in ("A", "Bw", "Cz", "Dz", "Cy", "Dy"))
    nx, nw = Bw.shape
    nz = Cz.shape[0]
    Ix, Iz, Iw = np.eye(nx), np.eye(nz), np.eye(nw)
    Z = np.zeros
    P1n, P2n, P3n = Pn
    P1c, P2c, P3c = Pc
    # zeta = (x_{k+1}, x_{f,k+1}, x_k, x_{f,k}, e_k, w_k)
    Q = np.block([
        [P1n, P3n, Z((nx, nx)), Z((nx, nx)), Z((nx, nz)), Z((nx, nw))],
        [P3n.T, P2n, Z((nx, nx)), Z((nx, nx)), Z((nx, nz)), Z((nx, nw))],
        [Z((nx, nx)), Z((nx, nx)), -P1c, -P3c, Z((nx, nz)), Z((nx, nw))],
        [Z((nx, nx)), Z((nx, nx)), -P3c.T, -P2c, Z((nx, nz)), Z((nx, nw))],
        [Z((nz, nx)), Z((nz, nx)), Z((nz, nx)), Z((nz, nx)), Iz, Z((nz, nw))],
        [Z((nw, nx)), Z((nw, nx)), Z((nw, nx)), Z((nw, nx)), Z((nw, nz)), -delta * Iw],
    ])
    G = np.block([
        [-Ix, Z((nx, nx)), A, Z((nx, nx)), Z((nx, nz)), Bw],
        [Z((nx, nx)), -v["H"], v["Bf"] @ Cy, v["Af"], Z((nx, nz)), v["Bf"] @ Dy],
        [Z((nz, nx)), Z((nz, nx)), Cz - v["Df"] @ Cy, -v["Cf"], -Iz, Dz - v["Df"] @ Dy],
    ])
    X = np.block([
        [v["X1"], a * Ix, Z((nx, nz))],
        [v["X2"], Ix, Z((nx, nz))],
        [v["X3"], b * Ix, Z((nx, nz))],
        [v["X4"], Z((nx, nx)), Z((nx, nz))],
        [v["X5"], Z((nz, nx)), Iz],
        [v["X6"], Z((nw, nx)), Z((nw, nz))],
    ])
    XG = X @ G
    return Q + XG + XG.T


def printed_phi(d, v, Pn, Pc, delta, eps, *, phi21_p3):
    """``Phi_ijl`` block by block as printed in Theorem 1, except that
    ``Phi_21`` uses ``phi21_p3`` as its ``P_3`` (the paper prints ``P_{3,j}``)."""
    A, Bw, Cz, Dz, Cy, Dy = (d[k] for k in ("A", "Bw", "Cz", "Dz", "Cy", "Dy"))
    X1, X2, X3, X4, X5, X6 = (v[k] for k in ("X1", "X2", "X3", "X4", "X5", "X6"))
    H, Af, Bf, Cf, Df = (v[k] for k in ("H", "Af", "Bf", "Cf", "Df"))
    P1l, P2l, _ = Pn
    P1j, P2j, P3j = Pc
    nx, nw = Bw.shape
    nz = Cz.shape[0]

    def he(m):
        return m + m.T

    L = [[None] * 6 for _ in range(6)]
    L[0][0] = P1l - X1 - X1.T
    L[1][0] = -X2 - eps * H.T + phi21_p3.T
    L[1][1] = P2l - H - H.T
    L[2][0] = -X3 + (X1 @ A + eps * Bf @ Cy).T
    L[2][1] = -H + (X2 @ A + Bf @ Cy).T
    L[2][2] = -P1j + he(X3 @ A + Bf @ Cy)
    L[3][0] = -X4 + eps * Af.T
    L[3][1] = Af.T
    L[3][2] = X4 @ A + Af.T - P3j.T
    L[3][3] = -P2j
    L[4][0] = -X5
    L[4][1] = np.zeros((nz, nx))
    L[4][2] = X5 @ A + Cz - Df @ Cy
    L[4][3] = -Cf
    L[4][4] = -np.eye(nz)
    L[5][0] = -X6 + (X1 @ Bw + eps * Bf @ Dy).T
    L[5][1] = (X2 @ Bw + Bf @ Dy).T
    L[5][2] = X6 @ A + (X3 @ Bw + Bf @ Dy).T
    L[5][3] = Bw.T @ X4.T
    L[5][4] = (X5 @ Bw - Df @ Dy + Dz).T
    L[5][5] = he(X6 @ Bw) - delta * np.eye(nw)
    rows = [[L[r][c] if c <= r else L[c][r].T for c in range(6)] for r in range(6)]
    return np.block(rows)


def random_plant_data(rng, N, nx, ny, nz, nw):
    """Random vertex data (not necessarily stable) as a dict of stacks."""
    return {
        "A": rng.standard_normal((N, nx, nx)),
        "Bw": rng.standard_normal((N, nx, nw)),
        "Cz": rng.standard_normal((N, nz, nx)),
        "Dz": rng.standard_normal((N, nz, nw)),
        "Cy": rng.standard_normal((N, ny, nx)),
        "Dy": rng.standard_normal((N, ny, nw)),
    }


def random_variables(rng, N, nx, ny, nz, nw, *, robust=False):
    """Random values of every decision variable (P1, P2 symmetric)."""
    def sym(n):
        m = rng.standard_normal((n, n))
        return m + m.T

    nf = 1 if robust else N
    return {
        "P1": [sym(nx) for _ in range(N)],
        "P2": [sym(nx) for _ in range(N)],
        "P3": [rng.standard_normal((nx, nx)) for _ in range(N)],
        "X1": [rng.standard_normal((nx, nx)) for _ in range(N)],
        "X2": [rng.standard_normal((nx, nx)) for _ in range(N)],
        "X3": [rng.standard_normal((nx, nx)) for _ in range(N)],
        "X4": [rng.standard_normal((nx, nx)) for _ in range(N)],
        "X5": [rng.standard_normal((nz, nx)) for _ in range(N)],
        "X6": [rng.standard_normal((nw, nx)) for _ in range(N)],
        "H": [rng.standard_normal((nx, nx)) for _ in range(nf)],
        "Af": [rng.standard_normal((nx, nx)) for _ in range(nf)],
        "Bf": [rng.standard_normal((nx, ny)) for _ in range(nf)],
        "Cf": [rng.standard_normal((nz, nx)) for _ in range(nf)],
        "Df": [rng.standard_normal((nz, ny)) for _ in range(nf)],
        "delta": float(rng.uniform(0.5, 2.0)),
    }
