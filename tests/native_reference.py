"""The library's side of the native-FMU tests: the component a native FMU's
role runs in the library, driven alongside the FMU, and the rounding bounds the
comparison uses (derived per role: eps times an amplification computed from
the library's own run, tests/tolerances.py's model).

The reference component is built the way the Python FMU builds it: the role's
slave script (fmus/) instantiated on the native FMU's own resources (model
file, design, spec), then ``make_component`` with the FMU's parameter values.
"""

from __future__ import annotations

import importlib.util
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lpvest.fmi._build import scripts_dir, slave_class_name
from tests.tolerances import EPS

#: the role scripts (fmus/) of the native roles
SCRIPTS = {"Plant": "lpvest_plant.py", "Scheduler": "lpvest_scheduler.py", "Source": "lpvest_source.py"}

#: The safety factor of tests/tolerances.py (what the first-order model leaves out).
SAFETY = 10.0

#: Two float64 implementations of sin, exp, pow, ...: the C library's (glibc: within
#: 1 unit in the last place) and numpy's SIMD loops (SVML on AVX-512: within 4).
FUNC_ULPS = 4.0


def gamma(n: int) -> float:
    """Higham's gamma_n = n eps / (1 - n eps): a sum of n products in any order."""
    return n * EPS / (1.0 - n * EPS)


def _slave(resources: Path, role: str) -> Any:
    script = scripts_dir() / SCRIPTS.get(role, "lpvest_estimator.py")
    name = f"tests_native_reference_{script.stem}"
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, script)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[name] = module
    return getattr(module, slave_class_name(script))(instance_name="reference", resources=str(resources))


@dataclass
class Reference:
    """The library component of a native FMU's role, for its parameters."""

    role: str
    slave: Any
    component: Any
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def timed(self) -> bool:
        return bool(getattr(self.component, "timed", False))


def reference(fmu: Path, tmp: Path, **overrides: Any) -> Reference:
    """The library component of ``fmu``'s role with its parameters set to
    ``overrides`` (FMI names: ``x0[1]``, ``tau``, ``u.kind``, ...)."""
    import json

    folder = tmp / f"ref-{fmu.stem}"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    resources = folder / "resources"
    role = json.loads((resources / "lpvest_fmu.json").read_text())["role"]
    slave = _slave(resources, role)
    params = slave.parameters()
    for name, value in overrides.items():
        base, _, index = name.partition("[")
        if index:
            idx = tuple(int(i) - 1 for i in index.rstrip("]").split(","))
            arr = np.array(params[base], dtype=float)
            arr[idx] = value
            params[base] = arr
        else:
            params[name] = value
    return Reference(role, slave, slave.make_component(params), params)


# ---------------------------------------------------------------------------
# rounding bounds: how far two correct evaluations of a role may be apart
# ---------------------------------------------------------------------------
#
# The native runtime sums products in index order, the library leaves them to
# numpy (BLAS, any kernel): every sum of n products may differ by gamma_n times
# the sum of the absolute products, twice (Higham (3.5); tests/tolerances.py).
# Functions (sin, exp, pow in formulas) may differ by FUNC_ULPS units in the last
# place. A recursion carries what one step got wrong into the next: each bound
# below propagates the local differences through the role's own recursion with
# the norms of the library's run (first order), and SAFETY is the factor of
# tests/tolerances.py for what first order leaves out.


def _abs(m: np.ndarray) -> np.ndarray:
    return np.abs(np.asarray(m, dtype=float))


def _norm(m: np.ndarray) -> float:
    a = np.atleast_2d(np.asarray(m, dtype=float))
    return float(np.linalg.norm(a, np.inf)) if a.size else 0.0


def weights_error(simplex_map: Any, p: np.ndarray) -> np.ndarray:
    """A bound on the difference of two evaluations of a simplex map's weights at ``p``."""
    from lpvest.systems._polytopic import FormulaSimplexMap, MultilinearSimplexMap

    if simplex_map is None:
        return np.zeros(0)
    names = simplex_map.space.names
    values = {n: float(v) for n, v in zip(names, p, strict=True)}
    if isinstance(simplex_map, FormulaSimplexMap):
        from tests.test_native_core import formula_bound

        return np.array([formula_bound(f, values) for f in simplex_map.formulas])
    assert isinstance(simplex_map, MultilinearSimplexMap)
    c = np.array([basis(p) for basis in simplex_map.coordinates])
    ec = np.array([basis_error(b, p) for b in simplex_map.coordinates])
    lam = (c - simplex_map.lower) / (simplex_map.upper - simplex_map.lower)
    el = ec / (simplex_map.upper - simplex_map.lower) + 2 * EPS * (np.abs(lam) + 1)
    n = len(c)
    out = []
    for v in range(2**n):
        factors = [lam[j] if (v >> j) & 1 else 1 - lam[j] for j in range(n)]
        prod = float(np.prod(factors))
        rel = sum(el[j] / max(abs(factors[j]), 1e-300) for j in range(n)) + n * EPS
        out.append(abs(prod) * rel if prod != 0 else float(np.sum(el)))
    return np.array(out)


def basis_error(basis: Any, p: np.ndarray) -> float:
    """A bound on the difference of two evaluations of a basis function at ``p``."""
    from lpvest.core._scheduling import FormulaBasis, Monomial

    if isinstance(basis, Monomial):  # products of powers: FUNC_ULPS per power, one rounding per product
        v = abs(basis(p))
        return (FUNC_ULPS + 1) * sum(1 for e in basis.exponents if e) * float(np.spacing(v)) if v else 0.0
    assert isinstance(basis, FormulaBasis)
    from tests.test_native_core import formula_bound

    return formula_bound(basis.expression, {n: float(v) for n, v in zip(basis.names, p, strict=True)})


def weighted_error(stacks: dict[str, np.ndarray], e_weights: np.ndarray) -> dict[str, np.ndarray]:
    """``sum_i e_i |M_i|`` per matrix: what a difference of the weights does to ``sum_i w_i M_i``."""
    return {k: np.tensordot(e_weights, np.abs(v), axes=1) for k, v in stacks.items()}


def covariance_step_bound(P: np.ndarray, F: np.ndarray, n: int, nu: int, m: int, e_P: float, e_F: float) -> dict:
    """The library's covariance step at (P, F) (lpvest.estimators.kalman._recursion)
    and first-order bounds on how far two evaluations may be apart when P and F
    already differ by e_P, e_F (infinity norms):

    - V = E P E^T + W: the products' rounding (2 gamma) plus E's and P's differences;
    - gains = V_12 Omega^-1 by Cholesky solves: Omega's inverse amplifies V's
      differences, and a backward-stable solve adds 2 gamma_m cond(Omega) |gains|;
    - PP = M V M^T, M = [I, -gains] (Joseph form): V's differences and the gains'.
    """
    from lpvest.estimators.kalman._model import StepMatrices
    from lpvest.estimators.kalman._recursion import covariance_step

    cs = covariance_step(P, StepMatrices(F, n, nu, m))
    n2 = 2 * n
    E, W = F[:, :n], F[:, n + nu:]
    V = E @ P @ E.T + W
    size_V = _norm(_abs(E) @ _abs(P) @ _abs(E).T + _abs(W))
    e_V = 2 * gamma(n + 1) * size_V + _norm(E) ** 2 * e_P + 2 * _norm(E) * _norm(P) * e_F + e_F
    Om = V[n2:, n2:]
    Om_inv = _norm(np.linalg.inv(Om))
    cond = Om_inv * _norm(Om)
    G = cs.gains
    e_G = Om_inv * (e_V + _norm(G) * e_V) + 2 * gamma(m + 1) * cond * _norm(G)
    M = np.concatenate((np.eye(n2), -G), axis=1)
    e_PP = (_norm(M) ** 2 * e_V + 2 * _norm(M) * _norm(V) * e_G
            + 2 * gamma(n2 + m + 1) * _norm(_abs(M) @ _abs(V) @ _abs(M).T))
    return {"cs": cs, "e_V": e_V, "e_G": e_G, "e_PP": e_PP, "Om_inv": Om_inv, "cond": cond, "V": V}


def kalman_step_bound(step: Any, F: np.ndarray, P: np.ndarray, x: np.ndarray, u: np.ndarray, n: int, nu: int,
                      m: int, e_x: float, e_P: float, e_F: float) -> dict:
    """Bounds on the outputs of one Kalman step (lpvest.estimators.kalman._recursion.kalman_step)
    and on the next state's difference, from the differences e_x, e_P, e_F it starts with."""
    c = covariance_step_bound(P, F, n, nu, m, e_P, e_F)
    xu = np.concatenate((x, u))
    Fa = F[:, :n + nu]
    e_h = _norm(Fa) * e_x + e_F * float(np.abs(xu).max(initial=0.0)) + 2 * gamma(n + nu) * float(
        (_abs(Fa) @ np.abs(xu)).max())
    xi = step.innovation
    G = c["cs"].gains
    e_xs = e_h + _norm(G) * e_h + c["e_G"] * float(np.abs(xi).max()) + 2 * gamma(m + 1) * float(
        (_abs(G) @ np.abs(xi)).max())
    Om_inv = c["Om_inv"]
    logdet = float(np.linalg.slogdet(step.Omega)[1])
    zz = float(xi @ np.linalg.solve(step.Omega, xi))
    e_ll = 0.5 * (m * Om_inv * c["e_V"] + 2 * gamma(m) * abs(logdet)
                  + 2 * Om_inv * float(np.abs(xi).sum()) * e_h + Om_inv ** 2 * float(np.abs(xi).sum()) ** 2 * c["e_V"]
                  + 2 * gamma(m + 1) * c["cond"] * abs(zz))
    return {"xhat": e_xs, "xpred": e_xs, "P": c["e_PP"], "Ppred": c["e_PP"], "yhat": e_h, "innovation": e_h,
            "K": c["e_G"], "Omega": c["e_V"], "loglik": e_ll, "next_x": e_xs, "next_P": c["e_PP"]}


def packed_error(km: Any, p: np.ndarray) -> float:
    """F(p) = z(p) @ packed computed twice: gamma_{n_z} |z| |packed| (twice), plus the basis functions' differences."""
    packed, pairs, _ = km.packing
    z = np.array(km.z(p))
    ez = np.zeros_like(z)
    k = len(km.model.basis)
    psi = z[1:1 + k]
    epsi = np.array([basis_error(b, p) for b in km.model.basis])
    ez[1:1 + k] = epsi
    for r, (i, j) in enumerate(pairs):
        ez[1 + k + r] = abs(psi[j - 1]) * epsi[i - 1] + abs(psi[i - 1]) * epsi[j - 1] + 2 * EPS * abs(z[1 + k + r])
    return float((2 * gamma(len(z)) * (np.abs(z) @ np.abs(packed)) + ez @ np.abs(packed)).max())


def restart_bound(F: np.ndarray, n: int, nu: int, m: int, P_start: np.ndarray, e_start: float) -> tuple[np.ndarray,
                                                                                                       float]:
    """(6a) with ERRATA, Abar P^_0 Abar^T + G Qbar G^T at the oldest kept sample
    (lpvest.estimators._truncated.restart_covariance), and a bound on two
    evaluations' difference: J = G S H^T (H R H^T)^-1 by a Cholesky solve
    (2 gamma_m cond(HRH) |J|), Abar = A - J C, the products, and P^_0's own
    difference e_start carried by |Abar|^2."""
    from lpvest.estimators._truncated import decorrelate, restart_covariance
    from lpvest.estimators.kalman._model import StepMatrices

    km = StepMatrices(F, n, nu, m).readable()
    P = restart_covariance(km, P_start)
    d = decorrelate(km)
    cond = _norm(km.HRH) * _norm(np.linalg.inv(km.HRH))
    e_J = 2 * gamma(m + 1) * cond * _norm(d.J)
    e_Abar = e_J * _norm(km.C) + 2 * gamma(m) * _norm(_abs(d.J) @ _abs(km.C))
    e_GQ = e_J * _norm(km.GSH) + 2 * gamma(m) * _norm(_abs(d.J) @ _abs(km.GSH).T)
    size = _norm(_abs(d.Abar) @ _abs(P_start) @ _abs(d.Abar).T) + _norm(d.GQbarG)
    e = (2 * gamma(2 * n + 1) * size + 2 * _norm(d.Abar) * _norm(P_start) * e_Abar + e_GQ
         + _norm(d.Abar) ** 2 * e_start)
    return P, e


def dare_bound(km: Any, p: np.ndarray) -> float:
    """How far two backward-stable solutions of the filter's Riccati equation at
    ``p`` (scipy's, the runtime's doubling) may be apart, then carried through
    the covariance step to the posterior P^_0 = steady_state(...).P_filt.

    The solution X of X = A X A^T - (A X C^T + S) Omega^-1 (...)^T + Q is
    perturbed, to first order, by the inverse of X -> X - Phi X Phi^T (Phi the
    closed loop) applied to the residual: |delta X| <= ||(I - Phi (x) Phi)^-1||
    times a residual of n eps times the sizes of the terms (Higham 16, the
    Lyapunov operator's condition), for each solver."""
    from lpvest.estimators._truncated import steady_state

    ss = steady_state(km, p)
    m = km.matrices(p)
    n = km.nx
    X = ss.P_pred
    Phi = m.A - ss.K @ m.C
    kappa = float(np.linalg.norm(np.linalg.inv(np.eye(n * n) - np.kron(Phi, Phi)), 2))
    residual = 2 * gamma(4 * n) * (_norm(m.A) ** 2 * _norm(X) + _norm(m.GQG) + _norm(ss.K) ** 2 * _norm(ss.Omega))
    e_X = kappa * residual
    F = km.step_matrices(p).F
    return covariance_step_bound(X, F, n, km.nu, km.ny, e_X, 0.0)["e_PP"]
